"""Property-based tests (hypothesis) on hard geometry, each against an independent reference.

* Polygons with corners nearly collinear (on an edge, or 1e-15..1e-9 off it) and nearly
  coplanar (out-of-plane noise from 1e-12 up to the non-planar tolerance), at random poses:
  triangulate gives n - 2 triangles that keep the area and never face against the polygon
  (reference: SVD plane + shoelace), and clean then only drops triangles of (near) zero area.
* Triangle soups with duplicated, flipped, coplanar-overlapping and intersecting faces, slivers and
  near-duplicate vertices: clean equals a brute-force reimplementation of its contract (union-find
  weld on all pairs, lowest index kept, degenerate triangles dropped).
* The same soups through the BVH: the exported lists, traversed as the Scratch script does, give
  exactly brute force over the list triangles, for rays at vertices, edges, grazing the planes and
  random ones.
* Lighting on soups full of slivers and zero-area triangles: colours are finite and in range.
* Rays from inside a closed mesh through its shared vertices and edges always hit (the ray test's
  barycentric tolerance; docs/reliability.md item 4).
* Earcut at collinear corners after a rotation: n - 2 proper triangles, never a zero-area ear
  (the edge-flip repair; docs/reliability.md item 5).
"""

from __future__ import annotations

import numpy as np
import pytest
from hypothesis import HealthCheck, assume, given, settings
from hypothesis import strategies as st

from bake.config import BVHConfig, CleanConfig, LightConfig, LightingConfig, TriangulateConfig
from bake.mesh import clean as clean_mod
from bake.mesh import triangulate as tri_mod
from bake.scene import make_scene
from rel_util import rotation

SETTINGS = settings(max_examples=40, deadline=None, suppress_health_check=[HealthCheck.too_slow])


# --------------------------------------------------------------------------- references
def svd_frame(points: np.ndarray):
    c = points.mean(0)
    _, sv, vt = np.linalg.svd(points - c)
    return c, vt[0], vt[1], vt[2], sv


def shoelace(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def vec_areas(tri: np.ndarray) -> np.ndarray:
    return 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


# --------------------------------------------------------------------------- polygons
@st.composite
def hard_polygons(draw):
    """A simple star-shaped polygon with extra corners on (or within ``eps`` of) its edges, posed
    at random, with optional out-of-plane noise. Returns (3-D points, unit normal, area, noise)."""
    n = draw(st.integers(3, 16))
    gaps = np.array(draw(st.lists(st.floats(1.0, 10.0), min_size=n, max_size=n)))
    gaps = gaps / gaps.sum() * 2 * np.pi
    for _ in range(n):  # no gap of pi or more (else the polygon can wind the other way round)
        over = gaps > 0.9 * np.pi
        if not over.any():
            break
        gaps[~over] += (gaps[over] - 0.9 * np.pi).sum() / (~over).sum()
        gaps[over] = 0.9 * np.pi
    ang = np.cumsum(gaps)
    r = np.array(draw(st.lists(st.floats(0.2, 1.0), min_size=n, max_size=n)))
    xy = np.stack([r * np.cos(ang), r * np.sin(ang)], 1)
    k = draw(st.integers(0, n))  # corners inserted on edges
    eps = draw(st.sampled_from([0.0, 1e-15, 1e-12, 1e-9]))
    pts = []
    where = set(draw(st.lists(st.integers(0, n - 1), min_size=k, max_size=k, unique=True)))
    for i in range(n):
        pts.append(xy[i])
        if i in where:
            a, b = xy[i], xy[(i + 1) % n]
            t = draw(st.floats(0.1, 0.9))
            e = b - a
            out = np.array([e[1], -e[0]]) / np.linalg.norm(e)  # outward for a CCW star
            pts.append(a + t * e + eps * draw(st.sampled_from([-1.0, 1.0])) * out)
    xy = np.array(pts)
    area = abs(shoelace(xy))
    noise = draw(st.sampled_from([0.0, 1e-12, 1e-8, 1e-5]))
    z = noise * np.array(draw(st.lists(st.floats(-1, 1), min_size=len(xy), max_size=len(xy))))
    R = rotation(draw(st.integers(0, 10 ** 6)))
    scale = draw(st.sampled_from([1e-3, 1.0, 1e3]))
    offset = np.array(draw(st.sampled_from([(0, 0, 0), (1e5, -1e5, 3e4)])), float)
    p3 = (np.c_[xy, z] * scale) @ R.T + offset
    return p3, R[:, 2], area * scale * scale, noise


@SETTINGS
@given(hard_polygons())
def test_nearly_collinear_and_nearly_coplanar_polygons(poly):
    pts, normal, area, noise = poly
    n = len(pts)
    scene = make_scene(pts, polygons=[list(range(n))])
    out, rec = tri_mod.stage(scene, TriangulateConfig())
    assert out.n_triangles == n - 2
    tri = out.triangle_vertices()
    assert set(np.unique(out.triangles)) <= set(range(n))
    size = float(np.ptp(pts, axis=0).max())
    va = vec_areas(tri)
    along = va @ normal
    # the pose itself is rounded: at 1e5 a coordinate carries ~1.5e-11 absolute error (8 ulps of
    # slack), which for a 4e-4 polygon is 4e-8 of its size; plus the out-of-plane noise
    ulp = np.spacing(float(np.abs(pts).max()))
    slack = (1e-9 + 10 * noise) * size * size + 8 * ulp * size
    assert along.min() >= -slack, "a triangle faces against the polygon"
    assert abs(along.sum() - area) <= slack * n + 1e-9 * area
    # clean drops only triangles of (near) zero area, so the surface stays
    cleaned, crec = clean_mod.stage(out, CleanConfig())
    kept = np.linalg.norm(vec_areas(cleaned.triangle_vertices()), axis=1).sum()
    assert abs(kept - area) <= slack * n + 1e-9 * area


def test_earcut_zero_area_ears_at_collinear_corners():
    """A comb whose inner baseline has four collinear corners, rotated: triangulate promises
    n - 2 proper triangles. Earcut cuts ~zero-area ears there (20 of 40 rotations before the
    fix, docs/reliability.md item 5); triangulate repairs them by edge flips."""
    comb = [(0, 0), (5, 0), (5, 3), (4, 3), (4, 1), (3, 1), (3, 3), (2, 3), (2, 1), (1, 1), (1, 3), (0, 3)]
    xy = np.array(comb, float) * 0.5
    bad = 0
    for seed in range(40):
        p = np.c_[xy, np.zeros(len(xy))] @ rotation(seed).T
        out, _ = tri_mod.stage(make_scene(p, polygons=[list(range(len(p)))]), TriangulateConfig())
        a = np.linalg.norm(vec_areas(out.triangle_vertices()), axis=1)
        bad += int((a <= 1e-12 * 6.25).any() or len(a) != len(p) - 2)
    assert bad == 0, f"{bad} of 40 rotations of the comb get a zero-area earcut triangle"


# --------------------------------------------------------------------------- triangle soups
@st.composite
def soups(draw):
    """Random triangles plus the hard kinds: duplicates, flipped copies, coplanar overlaps,
    intersecting pairs, slivers, near-duplicate vertices, repeated indices, collinear corners."""
    rng = np.random.default_rng(draw(st.integers(0, 2 ** 32 - 1)))
    m = draw(st.integers(2, 25))
    V = list(rng.uniform(-1, 1, (3 * m, 3)))
    T = [[3 * i, 3 * i + 1, 3 * i + 2] for i in range(m)]
    for _ in range(draw(st.integers(0, 12))):
        kind = draw(st.sampled_from(["dup", "flip", "coplanar", "cross", "sliver", "near", "repeat", "line"]))
        t = T[draw(st.integers(0, len(T) - 1))]
        a, b, c = (np.asarray(V[i]) for i in t)
        base = len(V)
        if kind == "dup":
            T.append(list(t))
        elif kind == "flip":
            T.append([t[0], t[2], t[1]])
        elif kind == "coplanar":  # a triangle in the same plane, overlapping
            w = rng.dirichlet([1, 1, 1], 3)
            V += list(w @ np.stack([a, b, c]))
            T.append([base, base + 1, base + 2])
        elif kind == "cross":  # through the triangle's interior
            p = (a + b + c) / 3
            nrm = np.cross(b - a, c - a)
            nrm = nrm / (np.linalg.norm(nrm) or 1)
            V += [p + nrm * 0.3, p - nrm * 0.3, p + (b - a) * 0.7]
            T.append([base, base + 1, base + 2])
        elif kind == "sliver":  # a corner within 1e-7..1e-3 of the opposite edge
            h = 10.0 ** rng.uniform(-7, -3)
            nrm = np.cross(b - a, c - a)
            nrm = nrm / (np.linalg.norm(nrm) or 1)
            V += [a, b, 0.5 * (a + b) + h * nrm]
            T.append([base, base + 1, base + 2])
        elif kind == "near":  # a copy with every vertex moved by 1e-10 .. 1e-6
            h = 10.0 ** rng.uniform(-10, -6)
            V += list(np.stack([a, b, c]) + rng.normal(size=(3, 3)) * h)
            T.append([base, base + 1, base + 2])
        elif kind == "repeat":
            T.append([t[0], t[0], t[1]])
        else:
            V += [a, 0.5 * (a + b), b]
            T.append([base, base + 1, base + 2])
    return np.array(V, float), np.array(T, np.int64)


def reference_clean(V, T, tol, min_area):
    """Brute force over all pairs: union-find welding of vertices within ``tol`` (transitive),
    each group at its lowest index; drop triangles with a repeated index or area < min_area;
    drop unused vertices. Returns the kept triangles as coordinates (K, 3, 3) and the kept vertices."""
    n = len(V)
    parent = list(range(n))

    def find(i):
        while parent[i] != i:
            parent[i] = parent[parent[i]]
            i = parent[i]
        return i

    d = np.sqrt(((V[:, None, :] - V[None, :, :]) ** 2).sum(-1))
    for i, j in zip(*np.nonzero(np.triu(d <= tol, 1))):
        ri, rj = find(i), find(j)
        if ri != rj:
            parent[max(ri, rj)] = min(ri, rj)
    rep = np.array([find(i) for i in range(n)])
    lowest = {}
    for i in range(n):
        lowest.setdefault(rep[i], i)
    W = np.array([lowest[rep[i]] for i in range(n)])
    T2 = W[T]
    rep_idx = (T2[:, 0] == T2[:, 1]) | (T2[:, 1] == T2[:, 2]) | (T2[:, 0] == T2[:, 2])
    P = V[T2]
    area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    keep = ~rep_idx & (area >= min_area)
    return P[keep], V[np.unique(T2[keep])]


@SETTINGS
@given(soups(), st.sampled_from([1e-7, 1e-5]), st.sampled_from([1e-14, 1e-8]))
def test_clean_equals_brute_force_reference_on_soups(soup, weld, area_tol):
    V, T = soup
    scene = make_scene(V, T)
    out, rec = clean_mod.stage(scene, CleanConfig(weld_tolerance=weld, area_tolerance=area_tol))
    s = scene.scale()
    want_tri, want_v = reference_clean(V, T, weld * s, area_tol * s * s)
    got_tri = out.triangle_vertices()
    np.testing.assert_array_equal(got_tri, want_tri)  # same triangles, same order, same coordinates
    np.testing.assert_array_equal(out.positions[np.unique(out.triangles)] if out.n_triangles else
                                  np.zeros((0, 3)), want_v if len(want_v) else np.zeros((0, 3)))
    out.validate()


# --------------------------------------------------------------------------- BVH
def _rays(tri: np.ndarray, rng, n: int):
    """Rays at vertices, along edges, grazing triangle planes, and random; unit directions."""
    P = tri.reshape(-1, 3)
    lo, hi = P.min(0), P.max(0)
    c = (lo + hi) / 2
    size = float(np.linalg.norm(hi - lo)) or 1.0
    T = len(tri)
    k = rng.integers(0, T, n)
    kind = rng.integers(0, 4, n)
    w = rng.dirichlet([1, 1, 1], n)
    w[kind == 0] = np.eye(3)[rng.integers(0, 3, (kind == 0).sum())]  # a vertex
    e = rng.random((kind == 1).sum())
    w[kind == 1] = np.c_[e, 1 - e, np.zeros_like(e)]  # an edge
    target = np.einsum("nk,nkd->nd", w, tri[k])
    o = c + rng.normal(size=(n, 3)) * size
    d = target - o
    graze = kind == 2  # in the plane of the target triangle, towards a point on it
    nrm = np.cross(tri[k, 1] - tri[k, 0], tri[k, 2] - tri[k, 0])
    nn = np.linalg.norm(nrm, axis=1)
    ok = graze & (nn > 0)
    nrm[ok] /= nn[ok, None]
    d[ok] -= (d[ok] * nrm[ok]).sum(1)[:, None] * nrm[ok]
    d[ok] += nrm[ok] * size * 10.0 ** rng.uniform(-12, -6, ok.sum())[:, None]
    o[ok] = target[ok] - d[ok]
    d[kind == 3] = rng.normal(size=((kind == 3).sum(), 3))
    ln = np.linalg.norm(d, axis=1)
    d[ln == 0] = [1.0, 0, 0]
    return o, d / np.linalg.norm(d, axis=1, keepdims=True)


@SETTINGS
@given(soups(), st.sampled_from(["binary", "wide4", "quantised"]), st.sampled_from([0, 5]),
       st.integers(0, 2 ** 32 - 1))
def test_bvh_lists_equal_brute_force_on_soups_and_near_degenerate_rays(soup, layout, precision, seed):
    from bake.bvh import stage as bvh_stage
    from bake.bvh.traverse import brute_force, trace

    V, T = soup
    scene = make_scene(V, T)
    out, rec = bvh_stage.stage(scene, BVHConfig(enabled=True, layout=layout, precision=precision, leaf_size=2))
    enc = out.artefacts.bvh.encoded
    slots = enc.tris.reshape(-1, 3, 3)
    assume(len(slots) > 0)
    o, d = _rays(slots, np.random.default_rng(seed), 300)
    h = trace(enc, o, d)
    bt, bi, _, _ = brute_force(slots, o, d)
    np.testing.assert_array_equal(h.t, bt)  # bit for bit: the same arithmetic, no lost hits
    tie = (h.slot != bi) & np.isfinite(bt)
    assert np.array_equal(h.slot >= 0, bi >= 0)
    if tie.any():  # another slot at exactly the same t (a duplicate or touching triangle)
        assert np.array_equal(bt[tie], h.t[tie])
    ids = np.asarray(enc.ids)
    assert (h.tri[h.hit] == ids[h.slot[h.hit]]).all()
    assert set(ids.tolist()) <= set(range(1, len(T) + 1))


@pytest.mark.parametrize("layout", ["binary", "wide4", "quantised"])
def test_rays_through_shared_edges_of_a_closed_mesh_always_hit(layout):
    """From inside a closed icosphere every ray must hit it, also rays aimed exactly at the list's
    vertices and edges (as a vertex-lit ray tracer or a shadow ray to a vertex does). A plain
    barycentric test let ~4% of them slip between the two triangles of an edge (Moller-Trumbore in
    float64 computes u = -1e-17 on both sides); the test's tolerance (u >= -1e-9 ...) closes that."""
    import trimesh

    from bake.bvh import stage as bvh_stage
    from bake.bvh.traverse import trace

    leaks = total = 0
    for seed in range(16):
        rng = np.random.default_rng(seed)
        m = trimesh.creation.icosphere(subdivisions=2)
        V = m.vertices @ rotation(seed).T * rng.uniform(0.5, 3) + rng.normal(size=3) * (10 if seed % 2 else 1e4)
        out, _ = bvh_stage.stage(make_scene(V, m.faces), BVHConfig(enabled=True, layout=layout))
        enc = out.artefacts.bvh.encoded
        tl = enc.tris.reshape(-1, 3, 3)
        c = tl.reshape(-1, 3).mean(0)
        targets = np.concatenate([tl.reshape(-1, 3), tl[:, 0] + rng.random((len(tl), 1)) * (tl[:, 1] - tl[:, 0])])
        d = targets - c
        d /= np.linalg.norm(d, axis=1, keepdims=True)
        h = trace(enc, np.broadcast_to(c, d.shape), d)
        leaks += int((~h.hit).sum())
        total += len(d)
    assert leaks == 0, f"{leaks} of {total} rays from inside a closed mesh through its vertices/edges hit nothing"


# --------------------------------------------------------------------------- lighting
@settings(max_examples=12, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(soups(), st.integers(0, 3))
def test_lighting_on_soups_with_slivers_is_finite_and_in_range(soup, seed):
    from bake.lighting import stage as light_stage

    V, T = soup
    scene = make_scene(V, T)
    cfg = LightingConfig(enabled=True, threads=1, seed=seed, ambient=[0.2, 0.2, 0.2])
    cfg.ao.enabled, cfg.ao.samples = True, 16
    cfg.sky.enabled, cfg.sky.samples = True, 16
    cfg.lights = [LightConfig(kind="sun", direction=[0.2, -1.0, 0.1], angle=1.0)]
    out, rec = light_stage.stage(scene, cfg)
    for a in (out.vertex_colors, out.face_colors):
        assert a is not None and np.isfinite(a).all() and (a >= 0).all() and (a <= 1).all()
    lr = out.artefacts.lighting
    assert np.isfinite(lr.vertex_irradiance).all() and np.isfinite(lr.face_irradiance).all()


# --------------------------------------------------------------------------- lighting at any size
def test_lighting_is_bit_identical_for_power_of_two_scales():
    """The tracer hands Embree the scene scaled by a power of two to about unit size, so a scene
    scaled by 2^k is traced exactly like the original (before the fix, AO vanished from ~1e14 up
    and from ~1e-20 down: Embree misses hits at such magnitudes)."""
    from bake.lighting import stage as light_stage

    rng = np.random.default_rng(3)
    V = rng.uniform(-1, 1, (60, 3))
    T = rng.integers(0, 60, (80, 3))
    T = T[(T[:, 0] != T[:, 1]) & (T[:, 1] != T[:, 2]) & (T[:, 0] != T[:, 2])]
    cfg = LightingConfig(enabled=True, threads=1, ambient=[0.3, 0.3, 0.3],
                         lights=[LightConfig(kind="sun", direction=[-0.3, -1.0, 0.2], angle=2.0)])
    cfg.ao.enabled, cfg.ao.samples = True, 32
    cfg.shadows.samples = 8
    ref = light_stage.stage(make_scene(V, T), cfg)[0].artefacts.lighting.vertex_irradiance
    assert ref.min() < 0.5 * ref.max()  # there is occlusion to lose
    for k in (-80, -40, 40, 80):
        got = light_stage.stage(make_scene(V * 2.0 ** k, T), cfg)[0].artefacts.lighting.vertex_irradiance
        np.testing.assert_array_equal(got, ref)


# --------------------------------------------------------------------------- BSP and simplify on soups
@settings(max_examples=25, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(soups())
def test_bsp_on_soups_keeps_the_surface(soup):
    """BSP only cuts: the fragments' total area is the input's (less fragments below min_area,
    which the record counts), every fragment lies in the plane of its source triangle."""
    from bake import config as config_mod
    from bake.bsp import stage as bsp_stage
    from bake.mesh.clean import triangle_areas

    V, T = soup
    scene, _ = clean_mod.stage(make_scene(V, T), CleanConfig())
    assume(scene.n_triangles > 0)
    cfg = config_mod.load(None, data={"bsp": {"enabled": True}}).bsp
    out, rec = bsp_stage.stage(scene, cfg)
    out.validate()
    a_in = triangle_areas(scene.positions, scene.triangles).sum()
    a_out = triangle_areas(out.positions, out.triangles).sum()
    d2 = scene.scale() ** 2
    lost = rec.details.get("kept_whole", 0)
    assert abs(a_out - a_in) <= 1e-9 * a_in + 1e-9 * d2 * (1 + lost)
    src = out.artefacts.bsp.source_triangle
    P = scene.triangle_vertices()[src]
    n = np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0])
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    off = np.abs(np.einsum("tkd,td->tk", out.triangle_vertices() - P[:, :1], n)).max()
    assert off <= 1e-6 * scene.scale()


@pytest.mark.slow
@settings(max_examples=6, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(soups())
def test_simplify_on_soups_gives_a_valid_scene_or_a_clear_error(soup):
    from bake import config as config_mod
    from bake.errors import BakeError
    from bake.mesh.simplify import stage as simp

    V, T = soup
    scene, _ = clean_mod.stage(make_scene(V, T), CleanConfig())
    assume(scene.n_triangles > 2)
    # measure_error off: with it, a 10-triangle soup takes ~5 s (reported); the checks here are ours
    cfg = config_mod.load(None, data={"mesh": {"simplify": {"enabled": True, "target_ratio": 0.5,
                                                             "measure_error": False}}}).mesh.simplify
    try:
        out, rec = simp.stage(scene, cfg)
    except BakeError:
        return
    out.validate()
    assert 0 < out.n_triangles <= scene.n_triangles
