"""Lightmap machinery (bake/textures/lightmap.py) against independent references.

* rasterisation: the conservative (triangle, texel) pairs equal the pairs whose exact clipped
  overlap area (Sutherland-Hodgman, written here) is positive; inside samples equal a brute-force
  lattice count; every sample lies on its triangle and in its texel;
* splat / dilate / bilinear: a per-sample loop, scipy's binary dilation, exactness on linear data;
* xatlas: subprocess results are cached by mesh hash and identical when recomputed; a real
  xatlas segfault, a hang and a too-large mesh are reported as StageError, never a crash; a
  model 1e-3 or 2^-30 the usual size gets the atlas of an ordinary-sized one (xatlas sees it
  multiplied by a power of two), ordinary models reach xatlas exactly as before;
* Cornell box and house: every non-degenerate triangle gets texels, no texel is shared by two
  charts, a smooth closed-form "lighting" comes back from the lightmap within one texel of
  gradient, and seams after stitching differ by <= 2/255;
* push-out: samples start inside closed boxes and end outside; with the real lighting kernels a
  sunlit floor shows no dark fringe at a thick wall, and no light leaks under one-sided walls
  into a closed room (and both artefacts do appear with push-out off, so the tests can fail).
"""

from __future__ import annotations

import dataclasses
import sys
import time

import numpy as np
import pytest
import trimesh
from scipy import ndimage

from bake import pipeline
from bake.config import LightConfig, LightingConfig, LightmapConfig
from bake.errors import StageError
from bake.scene import make_scene
from bake.lighting.lightmap import light_function
from bake.lighting.rays import Tracer
from bake.textures import lightmap as lm
from conftest import corpus_path
from meshgen import merge


def tracer_for(scene):
    """The Embree tracer the lighting stage passes for push-out."""
    return Tracer(scene.positions, scene.triangles, threads=0, scale=scene.scale())


SUN = np.array([-0.5, -1.0, 0.0])
COS_SUN = 1.0 / np.sqrt(1.25)  # n . l for the ground and SUN


# --------------------------------------------------------------------------------------------
# geometry


def box(lo, hi):
    """Closed box, 12 triangles, outward normals."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    v = lo + c * (hi - lo)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    t = np.array([tri for a, b, cc, d in quads for tri in ((a, b, cc), (a, cc, d))])
    p = v[t]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", n, p.mean(axis=1) - (lo + hi) / 2) < 0
    t[flip] = t[flip][:, ::-1]
    return v, t


def ground(half):
    v = np.array([[-half, 0, -half], [half, 0, -half], [half, 0, half], [-half, 0, half]], float)
    return v, np.array([[0, 2, 1], [0, 3, 2]])  # normal +y


def thick_room(wall=0.35, half=1.0, height=1.2):
    """Ground plane + a closed room of thick walls (closed boxes) and a roof."""
    i = half - wall
    parts = [ground(3.0), box([-half, 0, i], [half, height, half]), box([-half, 0, -half], [half, height, -i]),
             box([-half, 0, -half], [-i, height, half]), box([i, 0, -half], [half, height, half]),
             box([-half, height, -half], [half, height + 0.2, half])]
    return make_scene(*merge(*parts))


def thin_room(half=1.0, height=1.2):
    """Ground plane + a room of one-sided walls and ceiling facing inwards (Cornell-box style)."""
    v, t = box([-half, 0, -half], [half, height, half])
    p = v[t]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    t = t[~(n[:, 1] < -0.5)][:, ::-1]  # no bottom face, normals inwards
    return make_scene(*merge(ground(3.0), (v, t)))


def flat_atlas(xy, W, H):
    """An Atlas and matching scene from texel-space triangles (world = (x, y, 0))."""
    xy = np.asarray(xy, float)
    T = len(xy)
    uv = np.stack([xy[..., 0] / W, 1.0 - xy[..., 1] / H], axis=-1)
    atlas = lm.Atlas(width=W, height=H, tri_uvs=uv, chart=np.arange(T), key="test")
    pos = np.concatenate([xy.reshape(-1, 2), np.zeros((3 * T, 1))], axis=1)
    return atlas, make_scene(pos, np.arange(3 * T).reshape(T, 3))


def clip_area(tri, x0, y0):
    """Exact area of a triangle clipped to the unit square at (x0, y0) (Sutherland-Hodgman)."""
    poly = [np.asarray(p, float) for p in tri]
    for axis, bound, low in ((0, x0, True), (0, x0 + 1, False), (1, y0, True), (1, y0 + 1, False)):
        out = []
        for k in range(len(poly)):
            p, q = poly[k], poly[(k + 1) % len(poly)]
            pin = p[axis] >= bound if low else p[axis] <= bound
            qin = q[axis] >= bound if low else q[axis] <= bound
            if pin:
                out.append(p)
            if pin != qin:
                out.append(p + (bound - p[axis]) / (q[axis] - p[axis]) * (q - p))
        poly = out
        if len(poly) < 3:
            return 0.0
    a = np.array(poly)
    return 0.5 * abs(np.dot(a[:, 0], np.roll(a[:, 1], -1)) - np.dot(a[:, 1], np.roll(a[:, 0], -1)))


def random_triangles(rng, n, W, H, snap=False):
    c = rng.uniform([1, 1], [W - 1, H - 1], size=(n, 1, 2))
    size = rng.choice([0.3, 1.5, 4.0], size=(n, 1, 1))
    xy = np.clip(c + rng.normal(size=(n, 3, 2)) * size, 0.0, [W, H])
    if snap:  # vertices on texel lines / centres: the touching cases
        xy = np.round(xy * 2) / 2
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    a2 = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    return xy[np.abs(a2) > 1e-3]


# --------------------------------------------------------------------------------------------
# rasterisation


@pytest.mark.parametrize("snap", [False, True], ids=["random", "on_texel_lines"])
def test_cover_equals_exact_clipping(snap):
    rng = np.random.default_rng(7 + snap)
    W, H = 14, 11
    xy = random_triangles(rng, 60, W, H, snap)
    atlas, _ = flat_atlas(xy, W, H)
    t, x = lm.cover(atlas)
    got = set(zip(t.tolist(), x.tolist()))
    want, tiny = set(), set()
    for k, tri in enumerate(xy):  # brute force over every texel
        for ty in range(H):
            for tx in range(W):
                a = clip_area(tri, tx, ty)
                if a > 1e-7:
                    want.add((k, ty * W + tx))
                elif a > 0:
                    tiny.add((k, ty * W + tx))
    assert want <= got
    assert got - want <= tiny  # only pairs with a (numerically) zero overlap may differ
    assert len(want) > 200


def test_samples_on_triangle_in_texel_and_lattice_count():
    rng = np.random.default_rng(3)
    W, H = 16, 12
    xy = random_triangles(rng, 40, W, H)
    atlas, scene = flat_atlas(xy, W, H)
    s = 3
    smp = lm.texel_samples(scene, atlas, supersample=s)
    p = smp.points[:, :2]
    tx, ty = smp.texel_index % W, smp.texel_index // W
    assert np.all(smp.points[:, 2] == 0)
    # on the triangle: barycentrics >= 0 (independent solve)
    tri = xy[smp.tri_ids]
    M = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=2)
    w = np.linalg.solve(M, (p - tri[:, 0])[..., None])[..., 0]
    assert (w >= -1e-9).all() and (w.sum(axis=1) <= 1 + 1e-9).all()
    # inside samples lie in their texel; clamped ones within one texel diagonal of its centre
    ins = smp.inside
    assert np.all((p[ins, 0] >= tx[ins]) & (p[ins, 0] <= tx[ins] + 1))
    assert np.all((p[ins, 1] >= ty[ins]) & (p[ins, 1] <= ty[ins] + 1))
    d = np.hypot(p[~ins, 0] - tx[~ins] - 0.5, p[~ins, 1] - ty[~ins] - 0.5)
    assert (d <= np.sqrt(0.5) + 1e-9).all()
    assert np.allclose(smp.weights[ins], 1 / s**2) and np.allclose(smp.weights[~ins], lm.EDGE_WEIGHT)
    # inside samples per triangle = lattice points (j + (a + 0.5)/s) inside it, counted by brute force
    g = (np.arange(W * s) + 0.5) / s
    gy = (np.arange(H * s) + 0.5) / s
    X, Y = np.meshgrid(g, gy)
    q = np.stack([X.ravel(), Y.ravel()], axis=1)
    for k in range(len(xy)):
        a, b, c = xy[k]
        m = np.array([b - a, c - a]).T
        ww = np.linalg.solve(m, (q - a).T).T
        inside = (ww >= 0).all(axis=1) & (ww.sum(axis=1) <= 1)
        assert inside.sum() == np.sum(ins & (smp.tri_ids == k)), k
    # every pair of cover() has samples, nothing else does
    t, x = lm.cover(atlas)
    assert set(zip(t.tolist(), x.tolist())) == set(zip(smp.tri_ids.tolist(), smp.texel_index.tolist()))


def test_splat_dilate_bilinear():
    rng = np.random.default_rng(5)
    W, H = 9, 7
    atlas = lm.Atlas(width=W, height=H, tri_uvs=np.zeros((0, 3, 2)), chart=np.zeros(0, np.int64), key="t")
    n = 300
    texel = rng.integers(0, W * H // 2, n)
    w = rng.uniform(0.01, 1.0, n)
    v = rng.normal(size=(n, 3))
    img = lm.splat(v, texel, w, atlas)
    ref = np.zeros((W * H, 3))
    tot = np.zeros(W * H)
    for i in range(n):  # the obvious loop
        ref[texel[i]] += w[i] * v[i]
        tot[texel[i]] += w[i]
    has = tot > 0
    ref[has] /= tot[has, None]
    assert np.allclose(img.reshape(-1, 3), ref)
    mask = lm.texel_mask(texel, w, atlas)
    assert np.array_equal(mask.ravel(), has)
    # dilation: the 8-connected rings, filled with values between their neighbours'
    for px in (1, 2):
        out, m2 = lm.dilate(img, mask, px)
        assert np.array_equal(m2, ndimage.binary_dilation(mask, np.ones((3, 3), bool), iterations=px))
        assert np.array_equal(out[mask], img[mask])
        assert out[m2].min() >= img[mask].min() - 1e-12 and out[m2].max() <= img[mask].max() + 1e-12
    const, _ = lm.dilate(np.where(mask[..., None], 0.25, 0.0), mask, 3)
    assert np.allclose(const[ndimage.binary_dilation(mask, np.ones((3, 3), bool), iterations=3)], 0.25)
    # bilinear lookups reproduce a linear function of texel centres exactly (inside the image)
    yy, xx = np.mgrid[0:H, 0:W] + 0.5
    lin = 0.3 * xx - 0.7 * yy + 2.0
    pts = rng.uniform([0.5, 0.5], [W - 0.5, H - 0.5], size=(200, 2))
    uv = np.stack([pts[:, 0] / W, 1 - pts[:, 1] / H], axis=1)
    assert np.allclose(lm.bilinear(lin, uv), 0.3 * pts[:, 0] - 0.7 * pts[:, 1] + 2.0)


# --------------------------------------------------------------------------------------------
# xatlas in a subprocess


def _cfg(tmp_path, **kw):
    return LightmapConfig(enabled=True, cache_dir=str(tmp_path / "cache"), **kw)


def test_unwrap_cache_and_determinism(tmp_path):
    m = trimesh.creation.torus(1.0, 0.4, major_sections=24, minor_sections=12)
    scene = make_scene(np.asarray(m.vertices, float) + 1e4, m.faces)  # far from the origin
    cfg = _cfg(tmp_path, resolution=128)
    a = lm.unwrap(scene, cfg)
    assert not a.cached and a.n_triangles == scene.n_triangles and a.mapped.all()
    assert np.isfinite(a.tri_uvs).all() and a.tri_uvs.min() >= 0 and a.tri_uvs.max() <= 1
    b = lm.unwrap(scene, cfg)
    assert b.cached and b.key == a.key
    c = lm.unwrap(scene, cfg, cache_dir=None)  # a fresh xatlas run
    for other in (b, c):
        assert np.array_equal(other.tri_uvs, a.tri_uvs) and np.array_equal(other.chart, a.chart)
        assert (other.width, other.height) == (a.width, a.height)
    # charts are what they say: triangles of one chart share UVs along shared edges
    assert a.chart.max() + 1 == a.chart_count
    # the key follows the mesh's shape (not its place: xatlas sees it centred)
    assert lm.unwrap(scene.replace(positions=scene.positions + 1.0), cfg).key == a.key
    bent = scene.positions.copy()
    bent[0] += 0.01
    assert lm.unwrap(scene.replace(positions=bent), cfg).key != a.key


def test_unwrap_refuses_too_many_triangles(tmp_path, monkeypatch):
    monkeypatch.setattr(lm, "WORKER_COMMAND", [sys.executable, "-c", "raise SystemExit(9)"])
    m = trimesh.creation.icosphere(3)
    with pytest.raises(StageError, match="max_triangles = 100"):
        lm.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path, max_triangles=100))


def test_real_xatlas_segfault_is_reported(tmp_path):
    # xatlas 0.0.9-0.0.11 crash in PackCharts on a perfectly smooth subdivided icosphere
    m = trimesh.creation.icosphere(6)
    t = time.perf_counter()
    try:
        lm.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path, timeout=60))
    except StageError as e:
        assert "crashed (SIG" in str(e) and "81920 triangles" in str(e)
    else:
        pytest.skip(f"xatlas {lm.xatlas_version()} does not crash on this mesh")
    assert time.perf_counter() - t < 60


def test_a_crash_once_is_run_again_and_a_crash_twice_is_reported(tmp_path, monkeypatch):
    """A worker killed by a signal on its first run is started once more; the second run's atlas
    is the one a clean run gives (the same UVs), and the retry is named. Two crashes: an error."""
    m = trimesh.creation.box(extents=(2, 1, 1))
    scene = make_scene(m.vertices, m.faces)
    clean = lm.unwrap(scene, _cfg(tmp_path), cache_dir=None)
    assert clean.retried_after == ""
    marker = tmp_path / "crashed-once"
    script = ("import os, runpy, signal, sys\n"
              f"m = {str(marker)!r}\n"
              "if not os.path.exists(m):\n"
              "    open(m, 'w').close(); os.kill(os.getpid(), signal.SIGSEGV)\n"
              f"sys.argv = [{str(lm.WORKER)!r}] + sys.argv[1:]\n"
              f"runpy.run_path({str(lm.WORKER)!r}, run_name='__main__')\n")
    monkeypatch.setattr(lm, "WORKER_COMMAND", [sys.executable, "-c", script])
    again = lm.unwrap(scene, _cfg(tmp_path), cache_dir=None)
    assert marker.exists() and again.retried_after == "SIGSEGV"
    assert np.array_equal(again.tri_uvs, clean.tri_uvs)
    monkeypatch.setattr(lm, "WORKER_COMMAND", [sys.executable, "-c",
                                               "import os, signal; os.kill(os.getpid(), signal.SIGABRT)"])
    with pytest.raises(StageError, match=r"crashed \(SIGABRT\) on this mesh \(12 triangles\), twice"):
        lm.unwrap(scene, _cfg(tmp_path), cache_dir=None)


def test_hanging_worker_is_stopped(tmp_path, monkeypatch):
    monkeypatch.setattr(lm, "WORKER_COMMAND", [sys.executable, "-c", "import time; time.sleep(60)"])
    m = trimesh.creation.box()
    t = time.perf_counter()
    with pytest.raises(StageError, match="did not finish within textures.lightmap.timeout = 1"):
        lm.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path, timeout=1.0))
    assert time.perf_counter() - t < 10


def test_failing_worker_message(tmp_path, monkeypatch):
    script = "import sys; print('xatlas failed: boom', file=sys.stderr); sys.exit(3)"
    monkeypatch.setattr(lm, "WORKER_COMMAND", [sys.executable, "-c", script])
    m = trimesh.creation.box()
    with pytest.raises(StageError, match="xatlas failed: boom"):
        lm.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path))


# --------------------------------------------------------------------------------------------
# xatlas works in absolute units: what it is handed


def _torus(scale=1.0, shift=0.0):
    m = trimesh.creation.torus(1.0, 0.4, major_sections=24, minor_sections=12)  # 2.8 across
    return make_scene(np.asarray(m.vertices, float) * scale + shift, m.faces)


def test_xatlas_scale_is_a_power_of_two_outside_the_ordinary_sizes():
    lo, hi = lm.XATLAS_PLAIN_EXTENTS
    for e in (lo, 1.5, 2.8, 559.2, hi):
        assert lm.xatlas_scale(e) == 1.0
    for e in (0.0, -1.0, float("inf"), float("nan")):
        assert lm.xatlas_scale(e) == 1.0
    t = 2.0 ** lm.XATLAS_TARGET_EXPONENT
    for e in (1e-30, 7.4e-6, 0.0074, 0.5, np.nextafter(lo, 0), np.nextafter(hi, np.inf), 7.4e3, 1e5, 2e30):
        k = lm.xatlas_scale(e)
        assert np.log2(k) == round(np.log2(k)) and t <= e * k < 2 * t, e
    # options in model units are converted; those in texels or without a unit are not
    cfg = LightmapConfig(texels_per_unit=12.0, max_chart_area=3.0, resolution=128, padding=3)
    assert lm.xatlas_options(cfg, 1.0) == {
        "chart": {"max_cost": 2.0, "normal_deviation_weight": 2.0, "max_chart_area": 3.0},
        "pack": {"resolution": 128, "padding": 3, "bilinear": True, "rotate_charts": True, "texels_per_unit": 12.0}}
    big = lm.xatlas_options(cfg, 2.0 ** 15)
    assert big["pack"]["texels_per_unit"] == 12.0 / 2 ** 15 and big["chart"]["max_chart_area"] == 3.0 * 2 ** 30
    assert {k: v for k, v in big["pack"].items() if k != "texels_per_unit"} == \
        {k: v for k, v in lm.xatlas_options(cfg)["pack"].items() if k != "texels_per_unit"}


def test_ordinary_models_reach_xatlas_exactly_as_before():
    """A model of ordinary size is handed to xatlas centred in float64, then cast: the bytes (and
    so the cache key and the atlas) of the unwrap before xatlas_scale existed."""
    scene = _torus(shift=1e4)
    p32, idx, used, scale = lm._mesh_for_xatlas(scene)
    p = scene.positions[used]
    assert scale == 1.0
    assert np.array_equal(p32, (p - 0.5 * (p.min(axis=0) + p.max(axis=0))).astype(np.float32))


def test_atlas_does_not_depend_on_the_model_units(tmp_path):
    cfg = _cfg(tmp_path, resolution=64)
    unit = lm.unwrap(_torus(64.0), cfg)  # 179 across: a size xatlas handles well, given as it is
    assert unit.xatlas_scale == 1.0 and unit.mapped.all()
    # 1e-3: xatlas alone called most triangles degenerate (its epsilons are absolute: 14x14 atlas);
    # now it sees the model at about the size above. Not bit for bit (1e-3 is no power of two, and
    # the last bits decide some of xatlas's chart growing on this symmetric mesh), but alike.
    milli = lm.unwrap(_torus(1e-3, shift=5e-3), cfg)
    assert milli.xatlas_scale == 2.0 ** 16 and milli.mapped.all()
    for got, ref in ((milli.width, unit.width), (milli.height, unit.height), (milli.chart_count, unit.chart_count)):
        assert abs(got - ref) <= 0.15 * ref, (got, ref)
    assert milli.texels_per_unit == pytest.approx(64e3 * unit.texels_per_unit, rel=0.01)  # per model unit
    # models a power of two apart are the same input to xatlas: one cache entry, the same atlas
    a = lm.unwrap(_torus(2.0 ** -20), cfg)
    b = lm.unwrap(_torus(2.0 ** -30), cfg)
    assert b.cached and b.key == a.key and a.mapped.all()
    assert np.array_equal(a.tri_uvs, b.tri_uvs) and (a.width, a.height) == (b.width, b.height)
    assert b.texels_per_unit == a.texels_per_unit * 2 ** 10
    huge = lm.unwrap(_torus(2.0 ** 40), cfg)
    assert huge.key == a.key and huge.texels_per_unit == a.texels_per_unit * 2.0 ** -60
    # texels_per_unit is in model units whatever the size (exact: powers of two)
    fixed = lm.unwrap(_torus(1e-3), _cfg(tmp_path, resolution=128, texels_per_unit=16e3))
    assert fixed.texels_per_unit == 16e3 and fixed.mapped.all()
    h = lm.texel_world_size(_torus(1e-3), fixed)
    assert np.median(h) == pytest.approx(1 / 16e3, rel=0.1)


# --------------------------------------------------------------------------------------------
# Cornell box and house with a closed-form lighting function


def _smooth_light(scene):
    lo, hi = scene.bounds()
    size = float((hi - lo).max())
    k = np.array([2.0, 1.5, 1.0]) / size  # a few waves across the model

    def f(p, n, t):
        q = p - lo
        return np.stack([0.5 + 0.4 * np.sin(k[0] * q[:, 0] + 1.0),
                         0.5 + 0.4 * np.cos(k[1] * q[:, 1] + k[2] * q[:, 2]),
                         (q @ np.ones(3)) / (3 * size)], axis=1)

    grad = np.sqrt(np.sum((np.array([0.4 * k[0], 0.4 * np.hypot(k[1], k[2]), np.sqrt(3) / (3 * size)]) ** 2)))
    return f, grad, size


def _surface_points(scene, atlas, n, rng):
    _, area = lm.face_normals(scene.positions, scene.triangles)
    ok = atlas.mapped & (area > 0)
    p = area * ok / (area * ok).sum()
    t = rng.choice(len(p), size=n, p=p)
    r = rng.uniform(size=(n, 2))
    flip = r.sum(axis=1) > 1
    r[flip] = 1 - r[flip]
    bary = np.stack([1 - r.sum(axis=1), r[:, 0], r[:, 1]], axis=1)
    pts = np.einsum("nk,nkd->nd", bary, scene.positions[scene.triangles[t]])
    uv = np.einsum("nk,nkd->nd", bary, atlas.tri_uvs[t])
    return t, pts, uv


@pytest.mark.corpus
@pytest.mark.parametrize("name,file", [("cornell_box_tinyobj", "cornell_box.obj"),
                                       ("house_max2obj_walls", "regr01.obj")])
def test_corpus_lightmap_machinery(name, file, tmp_path):
    cfg = pipeline.load_config_for(corpus_path(name, file))
    scene = pipeline.run(cfg, until="clean").scene
    lcfg = _cfg(tmp_path)
    atlas = lm.unwrap(scene, lcfg)
    f, grad, size = _smooth_light(scene)
    res = lm.bake(scene, atlas, f, lcfg, tracer=tracer_for(scene))
    figs = res.figures
    _, area = lm.face_normals(scene.positions, scene.triangles)
    # only degenerate triangles are left out by xatlas; every other one has texels
    assert np.all(area[~atlas.mapped] <= 1e-9 * size * size)
    assert figs["triangles_without_samples"] == 0
    assert figs["texels_two_charts"] == 0
    # (the atlas now stays within the resolution asked, 256: the house's 2,706 triangles and their
    # padding fill 26% of it, where the 409 x 411 xatlas grew to before held 30%+)
    assert max(atlas.width, atlas.height) <= lcfg.resolution
    assert 0.2 < figs["coverage"] < 1.0 and figs["coverage"] <= atlas.utilization + 0.2
    # the lightmap gives the function back within about a texel of its gradient
    h = lm.texel_world_size(scene, atlas)
    rng = np.random.default_rng(1)
    t, pts, uv = _surface_points(scene, atlas, 4000, rng)
    err = np.abs(lm.bilinear(res.image, uv) - f(pts, None, t)).max(axis=1)
    bound = 1.5 * grad * h[t]
    assert np.mean(err <= bound) > 0.99, (np.quantile(err / bound, [0.5, 0.99, 1.0]))
    # seams: after stitching, both sides agree within 2/255 (and stitching did the work)
    assert figs["seam_error"] <= 2 / 255
    if figs["seam_edges_smooth"]:
        assert figs["seam_error"] < figs["seam_error_before"]
    assert figs["samples_pushed"] > 0  # blocks standing on floors / walls on the ground
    # deterministic: the same bake again gives the same image bit for bit
    again = lm.bake(scene, lm.unwrap(scene, lcfg), f, lcfg, tracer=tracer_for(scene))
    assert np.array_equal(again.image, res.image)


def test_stitching_fixes_seams_on_a_smooth_surface(tmp_path):
    # an open tube: xatlas must cut it somewhere, and the cut runs across a smooth surface
    n, rings = 48, 4
    ang = 2 * np.pi * np.arange(n) / n
    v = np.array([[np.cos(a), y, np.sin(a)] for y in np.linspace(0, 2, rings + 1) for a in ang])
    t = []
    for r in range(rings):
        for i in range(n):
            a0, a1 = r * n + i, r * n + (i + 1) % n
            t += [[a0, a1 + n, a1], [a0, a0 + n, a1 + n]]
    scene = make_scene(v, np.array(t))
    cfg = _cfg(tmp_path, resolution=48, padding=2)
    atlas = lm.unwrap(scene, cfg)
    seams = lm.seam_edges(scene, atlas)
    assert seams.smooth.sum() >= 1

    def f(p, nrm, tri):  # smooth in space: any jump at the cut is the lightmap's doing
        return (0.5 + 0.4 * np.sin(2.0 * p[:, 0] + 1.0) * np.cos(1.5 * p[:, 1]) + 0.1 * p[:, 2])[:, None]

    raw = lm.bake(scene, atlas, f, dataclasses.replace(cfg, stitch_seams=False), tracer=tracer_for(scene))
    fixed = lm.bake(scene, atlas, f, cfg, tracer=tracer_for(scene))
    assert raw.figures["seam_error"] > 2 / 255  # visible without stitching
    assert fixed.figures["seam_error"] <= 0.25 * raw.figures["seam_error"]
    assert fixed.figures["seam_error"] <= 2 / 255
    # stitching only moves texels near seams, and not far
    changed = np.abs(fixed.image - raw.image)[..., 0] > 1e-12
    assert changed.sum() < 0.3 * raw.mask.sum()
    assert np.abs(fixed.image - raw.image).max() < 0.25


# --------------------------------------------------------------------------------------------
# push-out and leaks


def test_push_out_leaves_closed_boxes(tmp_path):
    v, t = merge(ground(2.0), box([-0.5, 0.0, -0.5], [0.5, 0.6, 0.5]), box([0.8, -0.2, 0.8], [1.4, 0.3, 1.4]))
    scene = make_scene(v, t)
    atlas = lm.unwrap(scene, _cfg(tmp_path, resolution=128))
    plain = lm.texel_samples(scene, atlas, supersample=2)
    pushed = lm.texel_samples(scene, atlas, supersample=2, push=True, tracer=tracer_for(scene))

    def inside(p):
        a = np.all((p > [-0.5, 0.0, -0.5]) & (p < [0.5, 0.6, 0.5]), axis=1)
        b = np.all((p > [0.8, -0.2, 0.8]) & (p < [1.4, 0.3, 1.4]), axis=1)
        return a | b

    lift = 1e-6 * scene.scale()  # the tracer's offset along the normal decides "above the ground"
    before = inside(plain.points + plain.normals * lift)
    after = inside(pushed.points + pushed.normals * lift)
    assert before.sum() > 100  # ground texels under the boxes
    # horizontal distance of each sample to the nearest side wall of the box it is in
    x, z = plain.points[:, 0], plain.points[:, 2]
    da = np.minimum.reduce([x + 0.5, 0.5 - x, z + 0.5, 0.5 - z])
    db = np.minimum.reduce([x - 0.8, 1.4 - x, z - 0.8, 1.4 - z])
    dist = np.where(np.abs(x) < 0.5 + 1e-9, da, db)
    r = plain.texel_size[plain.tri_ids] * lm.PUSH_RADIUS
    near = before & (dist < 0.9 * r)  # some tangent ray (every 45 deg, 22.5 deg off axis) reaches a wall
    deep = before & (dist > r)  # no ray is long enough: left alone (such texels are never seen)
    assert near.sum() > 50 and deep.sum() > 50
    assert not after[near].any() and pushed.pushed[near].all()
    assert after[deep].all() and not pushed.pushed[deep].any()
    moved = np.linalg.norm(pushed.points - plain.points, axis=1)
    assert np.all(moved[pushed.pushed] <= 2 * r[pushed.pushed] + 1e-9)
    assert np.all(moved[~pushed.pushed] == 0)
    on_ground = plain.tri_ids < 2
    assert not pushed.pushed[on_ground & ~before].any()  # the open ground stays where it is
    # box B's sides just under the ground are behind it (the ground's back face): moved above it
    y = plain.points[:, 1]
    under = ~on_ground & (y < 0) & (y > -0.9 * r) & (plain.normals[:, 1] == 0)
    assert under.sum() > 10 and pushed.pushed[under].all() and (pushed.points[under, 1] > 0).all()


def _ground_uv(scene, atlas, pts):
    out = np.full((len(pts), 2), np.nan)
    for k in range(2):  # the ground is triangles 0 and 1
        a, b, c = scene.positions[scene.triangles[k]]
        M = np.stack([b - a, c - a], axis=1)[[0, 2]]
        w = np.linalg.solve(M, (pts - a)[:, [0, 2]].T).T
        bary = np.stack([1 - w.sum(axis=1), w[:, 0], w[:, 1]], axis=1)
        ins = (bary >= -1e-12).all(axis=1)
        out[ins] = np.einsum("nk,kd->nd", bary[ins], atlas.tri_uvs[k])
    assert np.isfinite(out).all()
    return out


def _sun_bake(scene, atlas, cfg):
    light = LightingConfig(enabled=True, lights=[LightConfig(kind="sun", direction=SUN.tolist(), angle=0.0)],
                           color_space="linear", vertex_output="light")
    light.shadows.samples = 1
    shade, _ = light_function(scene, light, output="light", samples_per_texel=cfg.supersample ** 2)
    return lm.bake(scene, atlas, shade, cfg, tracer=tracer_for(scene)).image[:, :, 0]


def test_no_shadow_fringe_at_thick_walls_with_real_lighting(tmp_path):
    scene = thick_room()
    cfg = _cfg(tmp_path, resolution=256, texels_per_unit=12.0)
    atlas = lm.unwrap(scene, cfg)
    h = 1 / 12
    z = np.linspace(-0.5, 0.5, 41)
    sunny = np.stack([np.full_like(z, 1 + 0.5 * h), np.zeros_like(z), z], axis=1)  # half a texel off the wall
    g = np.linspace(-0.65 + 0.5 * h, 0.65 - 0.5 * h, 25)
    X, Z = np.meshgrid(g, g)
    room = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], axis=1)
    img = _sun_bake(scene, atlas, cfg)
    assert np.abs(lm.bilinear(img, _ground_uv(scene, atlas, sunny)) - COS_SUN).max() <= 2 / 255
    assert lm.bilinear(img, _ground_uv(scene, atlas, room)).max() <= 2 / 255  # the closed room is dark
    # without push-out the texels under the wall's foot darken the sunny ground next to it
    raw = _sun_bake(scene, atlas, dataclasses.replace(cfg, push_out=False))
    assert lm.bilinear(raw, _ground_uv(scene, atlas, sunny)).min() < COS_SUN - 0.1


def test_no_light_leak_under_one_sided_walls_with_real_lighting(tmp_path):
    scene = thin_room()
    cfg = _cfg(tmp_path, resolution=256, texels_per_unit=12.0)
    atlas = lm.unwrap(scene, cfg)
    h = 1 / 12
    g = np.linspace(-1 + 0.5 * h, 1 - 0.5 * h, 41)  # the whole floor, up to half a texel from the walls
    X, Z = np.meshgrid(g, g)
    room = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], axis=1)
    img = _sun_bake(scene, atlas, cfg)
    assert lm.bilinear(img, _ground_uv(scene, atlas, room)).max() <= 2 / 255
    far = np.stack([np.full_like(g, 2.5), np.zeros_like(g), g], axis=1)  # open ground is lit
    assert np.abs(lm.bilinear(img, _ground_uv(scene, atlas, far)) - COS_SUN).max() <= 2 / 255
    raw = _sun_bake(scene, atlas, dataclasses.replace(cfg, push_out=False))
    assert lm.bilinear(raw, _ground_uv(scene, atlas, room)).max() > 0.2  # the leak push-out prevents
