"""Lightmap machinery (bake/textures/lightmap.py and the modules it names) on real geometry.

* Cornell box and house: every non-degenerate triangle gets texels, no texel is shared by two
  charts, a smooth closed-form "lighting" comes back from the lightmap within one texel of
  gradient, and seams after stitching differ by <= 2/255;
* push-out: samples start inside closed boxes and end outside; with the real lighting kernels a
  sunlit floor shows no dark fringe at a thick wall, and no light leaks under one-sided walls
  into a closed room (and both artefacts do appear with push-out off, so the tests can fail).

The rasteriser, splat and dilate against references: test_texels.py; xatlas in its subprocess
and in absolute units: test_unwrap.py.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

from bake import pipeline
from bake.config import LightConfig, LightingConfig, LightmapConfig
from bake.scene import make_scene
from bake.lighting.lightmap import light_function
from bake.lighting.rays import Tracer
from bake.textures import lightmap as lm
from bake.textures.seams import seam_edges
from bake.textures.texels import PUSH_RADIUS, bilinear, face_normals, texel_samples, texel_world_size
from bake.textures.unwrap import unwrap
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


def _cfg(tmp_path, **kw):
    return LightmapConfig(enabled=True, cache_dir=str(tmp_path / "cache"), **kw)


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
    _, area = face_normals(scene.positions, scene.triangles)
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
    atlas = unwrap(scene, lcfg)
    f, grad, size = _smooth_light(scene)
    res = lm.bake(scene, atlas, f, lcfg, tracer=tracer_for(scene))
    figs = res.figures
    _, area = face_normals(scene.positions, scene.triangles)
    # only degenerate triangles are left out by xatlas; every other one has texels
    assert np.all(area[~atlas.mapped] <= 1e-9 * size * size)
    assert figs["triangles_without_samples"] == 0
    assert figs["texels_two_charts"] == 0
    # (the atlas now stays within the resolution asked, 256: the house's 2,706 triangles and their
    # padding fill 26% of it, where the 409 x 411 xatlas grew to before held 30%+)
    assert max(atlas.width, atlas.height) <= lcfg.resolution
    assert 0.2 < figs["coverage"] < 1.0 and figs["coverage"] <= atlas.utilization + 0.2
    # the lightmap gives the function back within about a texel of its gradient
    h = texel_world_size(scene, atlas)
    rng = np.random.default_rng(1)
    t, pts, uv = _surface_points(scene, atlas, 4000, rng)
    err = np.abs(bilinear(res.image, uv) - f(pts, None, t)).max(axis=1)
    bound = 1.5 * grad * h[t]
    assert np.mean(err <= bound) > 0.99, (np.quantile(err / bound, [0.5, 0.99, 1.0]))
    # seams: after stitching, both sides agree within 2/255 (and stitching did the work)
    assert figs["seam_error"] <= 2 / 255
    if figs["seam_edges_smooth"]:
        assert figs["seam_error"] < figs["seam_error_before"]
    assert figs["samples_pushed"] > 0  # blocks standing on floors / walls on the ground
    # deterministic: the same bake again gives the same image bit for bit
    again = lm.bake(scene, unwrap(scene, lcfg), f, lcfg, tracer=tracer_for(scene))
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
    atlas = unwrap(scene, cfg)
    seams = seam_edges(scene, atlas)
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
    atlas = unwrap(scene, _cfg(tmp_path, resolution=128))
    plain = texel_samples(scene, atlas, supersample=2)
    pushed = texel_samples(scene, atlas, supersample=2, push=True, tracer=tracer_for(scene))

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
    r = plain.texel_size[plain.tri_ids] * PUSH_RADIUS
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
    atlas = unwrap(scene, cfg)
    h = 1 / 12
    z = np.linspace(-0.5, 0.5, 41)
    sunny = np.stack([np.full_like(z, 1 + 0.5 * h), np.zeros_like(z), z], axis=1)  # half a texel off the wall
    g = np.linspace(-0.65 + 0.5 * h, 0.65 - 0.5 * h, 25)
    X, Z = np.meshgrid(g, g)
    room = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], axis=1)
    img = _sun_bake(scene, atlas, cfg)
    assert np.abs(bilinear(img, _ground_uv(scene, atlas, sunny)) - COS_SUN).max() <= 2 / 255
    assert bilinear(img, _ground_uv(scene, atlas, room)).max() <= 2 / 255  # the closed room is dark
    # without push-out the texels under the wall's foot darken the sunny ground next to it
    raw = _sun_bake(scene, atlas, dataclasses.replace(cfg, push_out=False))
    assert bilinear(raw, _ground_uv(scene, atlas, sunny)).min() < COS_SUN - 0.1


def test_no_light_leak_under_one_sided_walls_with_real_lighting(tmp_path):
    scene = thin_room()
    cfg = _cfg(tmp_path, resolution=256, texels_per_unit=12.0)
    atlas = unwrap(scene, cfg)
    h = 1 / 12
    g = np.linspace(-1 + 0.5 * h, 1 - 0.5 * h, 41)  # the whole floor, up to half a texel from the walls
    X, Z = np.meshgrid(g, g)
    room = np.stack([X.ravel(), np.zeros(X.size), Z.ravel()], axis=1)
    img = _sun_bake(scene, atlas, cfg)
    assert bilinear(img, _ground_uv(scene, atlas, room)).max() <= 2 / 255
    far = np.stack([np.full_like(g, 2.5), np.zeros_like(g), g], axis=1)  # open ground is lit
    assert np.abs(bilinear(img, _ground_uv(scene, atlas, far)) - COS_SUN).max() <= 2 / 255
    raw = _sun_bake(scene, atlas, dataclasses.replace(cfg, push_out=False))
    assert bilinear(raw, _ground_uv(scene, atlas, room)).max() > 0.2  # the leak push-out prevents

