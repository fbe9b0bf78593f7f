"""The hidden-geometry stage (bake/mesh/hidden/, docs/hidden.md), against independent references:
the numpy z-buffer of bake/render.py (no Embree) from the same eyes and from held-out ones, and
scenes whose answer is known by construction (a box inside a box, a room, glass, a back face, a
shadow caster)."""

from __future__ import annotations

import numpy as np
import pytest

from bake import config as config_mod
from bake import pipeline
from bake.config import HiddenBox, HiddenConfig, LightConfig, LightingConfig
from bake.errors import ConfigError
from bake.mesh.hidden import regions
from bake.mesh.hidden.stage import HiddenJob, keep_triangles, stage
from bake.mesh.hidden.visibility import Visibility
from bake.render import Camera, render
from bake.scene import Material, Scene, make_scene

from conftest import corpus_path


# ----------------------------------------------------------------------------- scenes
def box(lo, hi, inward: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """12 triangles of an axis-aligned box, fronts facing out (or in)."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    v = np.array([[x, y, z] for x in (lo[0], hi[0]) for y in (lo[1], hi[1]) for z in (lo[2], hi[2])])
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    t = np.array([tri for a, b, c, d in quads for tri in ((a, b, c), (a, c, d))])
    c = 0.5 * (lo + hi)
    p = v[t]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    out = np.einsum("ij,ij->i", n, p.mean(axis=1) - c) > 0
    want = ~out if not inward else out  # flip those facing the wrong way
    t[want] = t[want][:, ::-1]
    return v, t


def quad(corners) -> tuple[np.ndarray, np.ndarray]:
    return np.asarray(corners, float), np.array([[0, 1, 2], [0, 2, 3]])


def merge(*parts, materials=None):
    pos, tris, mat = [], [], []
    off = 0
    for i, (v, t) in enumerate(parts):
        pos.append(v)
        tris.append(t + off)
        mat.append(np.full(len(t), 0 if materials is None else materials[i]))
        off += len(v)
    return np.concatenate(pos), np.concatenate(tris), np.concatenate(mat)


def scene_of(*parts, materials=None, mats=None):
    p, t, m = merge(*parts, materials=materials)
    return make_scene(p, t, tri_material=m, materials=mats)


def run(scene, **kw):
    kw.setdefault("holdout_eyes", 16)
    kw.setdefault("holdout_pixels", 32)
    lighting = kw.pop("lighting", None)
    return stage(scene, HiddenJob(hidden=HiddenConfig(enabled=True, **kw), lighting=lighting))


def assert_same_picture(s, tri, seed):
    """A z-buffer of the triangles ``tri`` (corner positions) draws the depths of the whole scene
    ``s`` from 8 outside eyes (bar pixel centres on a cut edge, which may fall either way)."""
    c, r = regions.bounding_sphere(s.positions)
    for d in regions.sphere_eyes(8, np.random.default_rng(seed)):
        cam = Camera(tuple(c + 2.5 * r * d), tuple(c), fov=50.0, width=120, height=120)
        a, b = render(cam, s.triangle_vertices()), render(cam, tri)
        same = np.isclose(a.depth, b.depth, rtol=1e-9, atol=1e-9) | (np.isinf(a.depth) & np.isinf(b.depth))
        assert same.mean() > 0.995


def kept_ids(scene, out) -> set[int]:
    """Input triangle numbers the output kept (matched by corner positions)."""
    key = lambda s: [tuple(np.round(c, 9).ravel()) for c in s.triangle_vertices()]
    have = set(key(out))
    return {i for i, k in enumerate(key(scene)) if k in have}


def zbuffer_seen(tri, eye, two_sided=None, size=256) -> set[int]:
    """Triangles the numpy z-buffer shows around ``eye`` (six 90-degree views)."""
    seen: set[int] = set()
    for f in np.vstack([np.eye(3), -np.eye(3)]):
        up = (0, 0, 1) if abs(f[1]) > 0.5 else (0, 1, 0)
        cam = Camera(tuple(eye), tuple(np.asarray(eye) + f), fov=90.0, width=size, height=size, up=up, near=1e-6)
        img = render(cam, tri, two_sided=two_sided)
        seen |= set(np.unique(img.tri_id[img.tri_id >= 0]).tolist())
    return seen


def numpy_sees(tri: np.ndarray, eye, t: int, n: int = 20000) -> bool:
    """Whether some of ``n`` points of triangle ``t`` (random, and just inside its corners) is the
    nearest front-facing hit of its ray from ``eye``: float64 Moller-Trumbore over every triangle."""
    eye = np.asarray(eye, float)
    w = np.random.default_rng(t).dirichlet([1, 1, 1], n)
    w = np.concatenate([w, 0.998 * np.eye(3) + 0.001])
    q = w @ tri[t]
    d = q - eye
    v0, e1, e2 = tri[:, 0], tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]
    front = np.einsum("ij,ij->i", np.cross(e1, e2), eye - v0) > 0
    if not front[t]:
        return False
    best = np.full(len(q), np.inf)
    who = np.full(len(q), -1)
    for k in np.flatnonzero(front):
        pv = np.cross(d, e2[k])
        det = pv @ e1[k]
        tv = eye - v0[k]
        u = (pv @ tv) / det
        qv = np.cross(tv, e1[k])
        v = (qv @ d.T) / det
        dist = (qv @ e2[k]) / det
        hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (dist > 0) & (dist < best)
        best[hit], who[hit] = dist[hit], k
    return bool((who == t).any())


# ----------------------------------------------------------------------------- what is dropped
def test_a_box_inside_a_box_is_dropped_from_outside():
    s = scene_of(box([-1, -1, -1], [1, 1, 1]), box([-0.3, -0.3, -0.3], [0.3, 0.3, 0.3]))
    out, rec = run(s)
    assert kept_ids(s, out) == set(range(12))
    assert out.n_triangles == 12 and out.n_vertices == 8
    assert rec.details["dropped"] == 12 and rec.accuracy["wrong_pixels"] == 0
    # an open outer box (its top missing) shows the inner one's top through the opening
    v, t = box([-1, -1, -1], [1, 1, 1])
    top = np.all(v[t][:, :, 1] == 1, axis=1)
    iv, it = box([-0.3, -0.3, -0.3], [0.3, 0.3, 0.3])
    inner_top = {10 + i for i in np.flatnonzero(np.all(iv[it][:, :, 1] == 0.3, axis=1))}
    s2 = scene_of((v, t[~top]), (iv, it))
    out2, rec2 = run(s2)
    assert len(inner_top) == 2 and inner_top <= kept_ids(s2, out2)
    assert rec2.accuracy["wrong_pixels"] == 0


def test_kept_triangles_are_what_a_zbuffer_sees_from_the_same_eyes():
    """Points region: the eyes are known exactly, so the numpy z-buffer (no Embree) from them is
    the reference: everything it shows is kept, and nothing it never shows is."""
    rng = np.random.default_rng(5)
    parts = [box(c - s, c + s) for c, s in ((rng.uniform(-2, 2, 3), rng.uniform(0.3, 0.8, 3)) for _ in range(7))]
    parts.append(box([-4, -4, -4], [4, 4, 4], inward=True))  # a room around them
    s = scene_of(*parts)
    eyes = [[3.5, 3.5, 3.5], [-3.5, 0.2, 3.0], [0.0, -3.6, -3.2]]
    out, rec = run(s, outside=False, points=eyes, samples=8)
    tri = s.triangle_vertices()
    ref = set().union(*(zbuffer_seen(tri, e) for e in eyes))
    got = kept_ids(s, out)
    assert ref <= got  # every triangle the reference sees is kept
    # and what it keeps beyond them shows in less than a pixel: a float64 ray finds it
    assert all(any(numpy_sees(tri, e, t) for e in eyes) for t in got - ref)
    assert len(got) < s.n_triangles  # the scene does hide something


def test_held_out_outside_eyes_show_no_dropped_triangle_in_a_zbuffer():
    rng = np.random.default_rng(11)
    parts = [box(c - s, c + s) for c, s in ((rng.uniform(-1, 1, 3), rng.uniform(0.2, 0.7, 3)) for _ in range(12))]
    s = scene_of(*parts)
    out, rec = run(s, eyes=48)
    dropped = sorted(set(range(s.n_triangles)) - kept_ids(s, out))
    assert dropped  # overlapping boxes hide faces inside each other
    c, r = regions.bounding_sphere(s.positions)
    for d in regions.sphere_eyes(40, np.random.default_rng(99)):
        eye = c + 2.5 * r * d
        cam = Camera(tuple(eye), tuple(c), fov=60.0, width=160, height=160)
        img = render(cam, s.triangle_vertices())
        assert not np.isin(img.tri_id, dropped).any()


def shaft_block(h: float = 0.05, rows: int = 20):
    """A closed block [-1, 1]^3 with a square shaft 2h wide sunk from its top to y = 0 (walls in
    ``rows`` rows of quads, facing into the shaft, a floor at the bottom), and a small closed box
    inside the solid part. The deep rows and the floor show only to eyes within a few degrees of
    the shaft's axis: through a gap, as the insides of a CAD assembly do."""
    tris, want = [], []

    def quad_(a, b, c, d, n):
        tris.extend([(a, b, c), (a, c, d)])
        want.extend([n, n])

    O = [(-1, 1, -1), (1, 1, -1), (1, 1, 1), (-1, 1, 1)]
    H = [(-h, 1, -h), (h, 1, -h), (h, 1, h), (-h, 1, h)]
    for i in range(4):  # the top, a ring around the shaft sharing its corners
        quad_(O[i], O[(i + 1) % 4], H[(i + 1) % 4], H[i], (0, 1, 0))
    ys = np.linspace(1, 0, rows + 1)
    for a, b in zip(ys[:-1], ys[1:]):
        quad_((h, a, -h), (h, a, h), (h, b, h), (h, b, -h), (-1, 0, 0))
        quad_((-h, a, -h), (-h, a, h), (-h, b, h), (-h, b, -h), (1, 0, 0))
        quad_((-h, a, h), (h, a, h), (h, b, h), (-h, b, h), (0, 0, -1))
        quad_((-h, a, -h), (h, a, -h), (h, b, -h), (-h, b, -h), (0, 0, 1))
    quad_((-h, 0, -h), (h, 0, -h), (h, 0, h), (-h, 0, h), (0, 1, 0))  # the floor
    for sg in (-1, 1):
        quad_((sg, -1, -1), (sg, -1, 1), (sg, 1, 1), (sg, 1, -1), (sg, 0, 0))
        quad_((-1, -1, sg), (1, -1, sg), (1, 1, sg), (-1, 1, sg), (0, 0, sg))
    quad_((-1, -1, -1), (1, -1, -1), (1, -1, 1), (-1, -1, 1), (0, -1, 0))
    p = np.array(tris, float)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    flip = np.einsum("ij,ij->i", n, np.array(want, float)) < 0
    p[flip] = p[flip][:, ::-1]
    inner = box([0.4, -0.7, 0.4], [0.7, -0.4, 0.7])
    return scene_of((p.reshape(-1, 3), np.arange(3 * len(p)).reshape(-1, 3)), inner)


def test_what_shows_only_through_a_gap_is_kept(monkeypatch):
    """The walls deep in a narrow shaft and its floor show only to eyes within a few degrees of
    its axis (as parts of 2CylinderEngine show through the gaps between other parts): the rounds
    aimed from eyes around the ones that saw a neighbour (witnesses) follow them down, so every
    triangle the numpy z-buffer shows from above the shaft is kept, and the box inside the
    solid block is still dropped. Without those eyes (the random refinement rounds alone) most
    of the shaft is dropped."""
    s = shaft_block()
    inner = set(range(s.n_triangles - 12, s.n_triangles))
    tri = s.triangle_vertices()
    shown: set[int] = set()
    for deg in (0.0, 1.0, 2.0):
        a = np.radians(deg)
        cam = Camera((3 * np.sin(a), 1 + 2 * np.cos(a), 0.0), (0.0, 0.5, 0.0), fov=6.0, width=160, height=160,
                     up=(0, 0, 1), near=1e-6)
        img = render(cam, tri)
        shown |= set(np.unique(img.tri_id[img.tri_id >= 0]).tolist())
    floor = {s.n_triangles - 12 - 12, s.n_triangles - 12 - 11}
    assert floor <= shown and not shown & inner
    for seed in (0, 1):
        out, rec = run(s, seed=seed)
        got = kept_ids(s, out)
        assert shown <= got, sorted(shown - got)
        assert not got & inner
        assert any(r["directed_seen"] for r in rec.details["rounds"][1:])
    from bake.mesh.hidden import stage as stage_mod

    monkeypatch.setattr(stage_mod, "DIRECTED_EYES", 0)
    monkeypatch.setattr(stage_mod, "DIRECTED_ROUNDS", 0)
    out, _ = run(s)
    assert len(shown - kept_ids(s, out)) > 20 and floor - kept_ids(s, out)


def test_a_room_keeps_every_wall_an_inside_eye_sees():
    """The Cornell box from an inside box region: every triangle a held-out inside eye sees in the
    z-buffer is kept; the record's own held-out check agrees (no wrong pixel)."""
    from bake.importers.stage import stage as import_stage
    from bake.config import ImportJob
    from bake.mesh.triangulate import stage as triangulate
    from bake.config import TriangulateConfig

    p = corpus_path("cornell_box_tinyobj", "cornell_box.obj")
    s, _ = import_stage(Scene(), ImportJob(path=p))
    s, _ = triangulate(s, TriangulateConfig())
    lo, hi = s.bounds()
    size = hi - lo
    inner = HiddenBox(min=list(lo + 0.2 * size), max=list(hi - 0.2 * size))
    out, rec = run(s, outside=False, boxes=[inner], eyes=32)
    assert rec.accuracy["wrong_pixels"] == 0
    got = kept_ids(s, out)
    rng = np.random.default_rng(3)
    for eye in regions.box_eyes(np.array(inner.min), np.array(inner.max), 6, rng):
        assert zbuffer_seen(s.triangle_vertices(), eye, size=128) <= got


def test_a_room_drops_what_lies_under_its_floor():
    room = box([-5, 0, -5], [5, 4, 5], inward=True)
    under = box([-1, -3, -1], [1, -1, 1])  # a cellar block outside the room, under the floor
    s = scene_of(room, under)
    out, rec = run(s, outside=False, boxes=[HiddenBox(min=[-4, 0.5, -4], max=[4, 3.5, 4])], eyes=16)
    assert kept_ids(s, out) == set(range(12))
    # from outside, the near walls show their backs (culled) and the far walls their fronts, and
    # the block under the floor is in plain sight: nothing is dropped
    out2, _ = run(s)
    assert out2.n_triangles == 24


# ----------------------------------------------------------------------------- decisions
def test_a_triangle_behind_glass_is_kept_and_glass_inside_a_box_is_dropped():
    glass = Material("glass", color=(0.8, 0.9, 1.0, 0.4))
    wall = quad([[-1, -1, 0], [-1, 1, 0], [1, 1, 0], [1, -1, 0]])  # faces -z (towards the eye)
    behind = quad([[-0.2, -0.2, 1], [-0.2, 0.2, 1], [0.2, 0.2, 1], [0.2, -0.2, 1]])
    eye = [[0, 0, -3]]
    opaque = scene_of(wall, behind)
    out, _ = run(opaque, outside=False, points=eye)
    assert kept_ids(opaque, out) == {0, 1}  # an opaque wall hides it
    clear = scene_of(wall, behind, materials=[1, 0], mats=(Material("paint"), glass))
    out, rec = run(clear, outside=False, points=eye)
    assert kept_ids(clear, out) == {0, 1, 2, 3} and rec.details["see_through_materials"] == ["glass"]
    # glass that is itself inside a closed opaque box is hidden like anything else
    inside = scene_of(box([-2, -2, -2], [2, 2, 2]), wall, materials=[0, 1], mats=(Material("paint"), glass))
    out, _ = run(inside)
    assert kept_ids(inside, out) == set(range(12))


def test_back_faces_hide_nothing_unless_two_sided():
    # the big quad faces +z, away from the eye at z = -3: culled, so the small one behind shows
    away = quad([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]])
    behind = quad([[-0.2, -0.2, 1], [-0.2, 0.2, 1], [0.2, 0.2, 1], [0.2, -0.2, 1]])
    eye = [[0, 0, -3]]
    s = scene_of(away, behind)
    p = s.triangle_vertices()
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert np.all(n[:2, 2] > 0) and np.all(n[2:, 2] < 0)  # as constructed
    out, _ = run(s, outside=False, points=eye)
    assert kept_ids(s, out) == {2, 3}
    two = scene_of(away, behind, materials=[1, 0], mats=(Material("a"), Material("cloth", double_sided=True)))
    out, _ = run(two, outside=False, points=eye)
    assert kept_ids(two, out) == {0, 1}
    out, _ = run(s, outside=False, points=eye, back_faces="drawn")
    assert kept_ids(s, out) == {0, 1}


def test_shadow_casters_of_a_lit_bake_are_kept():
    floor = quad([[-5, 0, -5], [-5, 0, 5], [5, 0, 5], [5, 0, -5]])  # faces +y
    roof = quad([[-1, 2, -1], [-1, 2, 1], [1, 2, 1], [1, 2, -1]])  # faces +y: the eye below sees its back
    s = scene_of(floor, roof)
    p = s.triangle_vertices()
    assert np.all(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])[:, 1] > 0)
    eye = [[0, 1, -4]]
    out, rec = run(s, outside=False, points=eye)
    assert kept_ids(s, out) == {0, 1}  # unlit: the roof is never seen
    sun = LightingConfig(enabled=True, lights=[LightConfig(kind="sun", direction=[0.0, -1.0, 0.0])])
    out, rec = run(s, outside=False, points=eye, lighting=sun)
    assert kept_ids(s, out) == {0, 1, 2, 3} and rec.details["casters_kept"] == 2
    # a sun from below the floor: the roof shadows nothing that is kept
    low = LightingConfig(enabled=True, lights=[LightConfig(kind="sun", direction=[0.0, 1.0, 0.0])])
    out, _ = run(s, outside=False, points=eye, lighting=low)
    assert kept_ids(s, out) == {0, 1}
    # the registry hands the stage the lighting section only when the bake is lit and casters are kept
    cfg = config_mod.load(None, ["mesh.hidden.enabled=true", "lighting.enabled=true"])
    from bake.mesh.hidden.stage import job
    assert job(cfg).lighting is cfg.lighting
    cfg.mesh.hidden.keep_casters = False
    assert job(cfg).lighting is None


# ----------------------------------------------------------------------------- the proof
def test_wrong_pixels_match_a_zbuffer_count():
    """Drop a triangle that shows and the held-out figure counts its pixels as a z-buffer does."""
    s = scene_of(box([-1, -1, -1], [1, 1, 1]), box([1.5, -0.5, -0.5], [2.5, 0.5, 0.5]))
    tri = s.triangle_vertices()
    vis = Visibility(s.positions, s.triangles, two_sided=np.zeros(24, bool), see_through=np.zeros(24, bool))
    c, r = regions.bounding_sphere(s.positions)
    eye = c + np.array([0.3, 0.4, -2.5]) * r
    P = 200
    d = vis.view_directions(eye, c, r, P)
    dropped = np.zeros(24, bool)
    dropped[[0, 1, 2, 3, 12, 13]] = True
    got = vis.pixels(eye[None, :], [d], dropped)
    s_ = r / np.linalg.norm(c - eye)
    half = s_ / np.sqrt(1 - s_ * s_)
    cam = Camera(tuple(eye), tuple(c), width=P, height=P, focal_px=P / 2 / half, near=1e-6)
    img = render(cam, tri)
    ref_wrong = int(np.isin(img.tri_id, np.flatnonzero(dropped)).sum())
    ref_covered = int((img.tri_id >= 0).sum())
    assert ref_wrong > 500
    assert abs(got["wrong"] - ref_wrong) <= 0.02 * ref_wrong
    assert abs(got["covered"] - ref_covered) <= 0.02 * ref_covered


def test_the_record_counts_wrong_pixels_when_too_few_rays_decide():
    """A shard on top of a box, decided by one eye under the box: dropped, and the held-out proof
    (not the eye that decided) finds its pixels; with the default eyes it is kept and the proof
    finds none."""
    big = box([-1, -1, -1], [1, 1, 1])
    shard = (np.array([[0.0, 1.01, 0.0], [0.2, 1.01, 0.0], [0.0, 1.01, 0.2]]), np.array([[0, 2, 1]]))
    s = scene_of(big, shard)
    p = s.triangle_vertices()
    assert np.cross(p[12, 1] - p[12, 0], p[12, 2] - p[12, 0])[1] > 0  # faces up, away from the box
    below = [seed for seed in range(8)
             if regions.eyes([regions.Region("outside", "outside")], s.positions, 1,
                             np.random.default_rng([seed, 1]))[0][0, 1] < -1.2]
    assert below  # a seed whose one eye is well under the box
    out, rec = run(s, eyes=1, samples=1, refine=0, seed=below[0], holdout_eyes=32, holdout_pixels=64)
    assert 12 not in kept_ids(s, out)
    assert rec.accuracy["wrong_pixels"] > 0 and rec.details["holdout"]["dropped_triangles_seen"] >= 1
    assert any("held-out" in w for w in rec.warnings)
    out, rec = run(s, holdout_eyes=32, holdout_pixels=64)
    assert 12 in kept_ids(s, out) and rec.accuracy["wrong_pixels"] == 0


# ----------------------------------------------------------------------------- the stage's rules
def test_deterministic_for_any_thread_count():
    rng = np.random.default_rng(2)
    parts = [box(c - 0.4, c + 0.4) for c in rng.uniform(-1, 1, (20, 3))]
    s = scene_of(*parts)
    a, ra = run(s, threads=1)
    b, rb = run(s, threads=2)
    c, _ = run(s, threads=2)
    for x in (b, c):
        assert np.array_equal(a.positions, x.positions) and np.array_equal(a.triangles, x.triangles)
    assert ra.details["rounds"] == rb.details["rounds"] and ra.accuracy == rb.accuracy
    d, _ = run(s, seed=1)
    assert d.n_triangles > 0


def test_work_item_size_changes_nothing(monkeypatch):
    # the random numbers belong to fixed generator chunks (CHUNK_RAYS), not to the work items the
    # threads take (DECIDE_CHUNK_RAYS): items of any size give the same rays, so the same answer
    from bake.mesh.hidden import visibility

    rng = np.random.default_rng(3)
    s = scene_of(*[box(c - 0.4, c + 0.4) for c in rng.uniform(-1, 1, (12, 3))])
    outs = []
    for size in (1 << 6, 1 << 11, visibility.CHUNK_RAYS * 4):
        monkeypatch.setattr(visibility, "DECIDE_CHUNK_RAYS", size)
        out, rec = run(s, threads=2)
        outs.append((out, rec.details["rounds"], rec.details["rays"]))
    assert outs[0][0].n_triangles < s.n_triangles  # something is hidden: the rounds do work
    for out, rounds, rays in outs[1:]:
        assert np.array_equal(out.positions, outs[0][0].positions)
        assert np.array_equal(out.triangles, outs[0][0].triangles)
        assert rounds == outs[0][1] and rays == outs[0][2]


def test_polygons_and_attributes_follow_the_kept_triangles():
    outer = box([-1, -1, -1], [1, 1, 1])
    inner = box([-0.3, -0.3, -0.3], [0.3, 0.3, 0.3])
    p, t, m = merge(outer, inner)
    s = make_scene(p, t, tri_material=m)
    # polygons: the outer box as 6 quads (triangles 2i, 2i + 1 of the box share a diagonal), the
    # inner one as 12 triangles
    quads = [[t[2 * i][0], t[2 * i][1], t[2 * i][2], t[2 * i + 1][2]] for i in range(6)]
    polys = quads + [list(x) for x in t[12:]]
    s = s.replace(poly_sizes=np.array([len(q) for q in polys]), poly_indices=np.concatenate(polys),
                  poly_material=np.zeros(len(polys), np.int64),
                  tri_polygon=np.r_[np.repeat(np.arange(6), 2), 6 + np.arange(12)],
                  face_colors=np.tile(np.linspace(0, 1, 24)[:, None], (1, 4)))
    s.validate()
    keep = np.zeros(24, bool)
    keep[:12] = True
    keep[0] = False  # quad 0 loses one triangle; the inner box goes
    out = keep_triangles(s, keep)
    out.validate()
    assert out.n_triangles == 11 and out.n_vertices == 8 and out.n_polygons == 6
    assert out.tri_polygon[0] == -1 and list(out.tri_polygon[1:]) == list(np.repeat(np.arange(1, 6), 2))
    assert np.allclose(out.triangle_vertices(), s.triangle_vertices()[keep])
    assert np.array_equal(out.face_colors, s.face_colors[keep])
    # the polygons left still name the same places
    assert np.allclose(out.positions[out.poly_indices], s.positions[np.concatenate(quads)])


def test_off_by_default_and_config_errors_name_the_key():
    cfg = config_mod.load(None, [])
    assert cfg.mesh.hidden.enabled is False
    on = {spec.name: run_ for spec, run_, _ in pipeline.plan(cfg)}
    assert on["hidden"] is False
    names = [spec.name for spec, _, _ in pipeline.plan(cfg)]
    assert names.index("clean") < names.index("hidden") < names.index("simplify") < names.index("lighting")
    for sets, words in ((["mesh.hidden.outside=false"], ("mesh.hidden.outside", "view region is empty")),
                        (["mesh.hidden.points=[[1, 2]]"], ("mesh.hidden.points[0]", "[x, y, z]")),
                        (["mesh.hidden.eyes=0"], ("mesh.hidden.eyes", "between 1 and 100000")),
                        (["mesh.hidden.back_faces=\"both\""], ("mesh.hidden.back_faces", "'culled'")),
                        (["mesh.hidden.samples=0"], ("mesh.hidden.samples", "between 1 and 64")),
                        (["mesh.hidden.trim_most=-1"], ("mesh.hidden.trim_most", "0 (no limit) or more"))):
        with pytest.raises(ConfigError) as e:
            config_mod.load(None, sets)
        text = str(e.value)
        assert all(w in text for w in words), text


def test_a_box_region_is_checked_in_a_config_file(tmp_path):
    p = tmp_path / "c.toml"
    p.write_text('[mesh.hidden]\nenabled = true\n\n[[mesh.hidden.boxes]]\nmin = [0, 0, 0]\nmax = [1, -1, 1]\n')
    with pytest.raises(ConfigError) as e:
        config_mod.load(p)
    assert "mesh.hidden.boxes[0].max" in str(e.value) and "line" in str(e.value).lower() or "c.toml" in str(e.value)
    p.write_text('[mesh.hidden]\nenabled = true\n\n[[mesh.hidden.boxes]]\nmin = [0, 0, 0]\nmax = [1, 1, 1]\n')
    cfg = config_mod.load(p)
    assert cfg.mesh.hidden.boxes[0].max == [1.0, 1.0, 1.0]


def test_nothing_seen_is_an_error_naming_the_region():
    s = scene_of(box([-1, -1, -1], [1, 1, 1]))
    with pytest.raises(ConfigError) as e:
        run(s, outside=False, points=[[0, 0, 0]])  # inside a closed box: only backs
    assert "no triangle is seen" in str(e.value)
    out, _ = run(s, outside=False, points=[[0, 0, 0]], back_faces="drawn")
    assert out.n_triangles == 12


def test_suzanne_from_outside_drops_only_what_is_inside_its_head():
    p = corpus_path("suzanne_obj", "suzanne.obj")
    cfg = pipeline.load_config_for(p, ["mesh.hidden.enabled=true", "export.enabled=false",
                                       "mesh.hidden.holdout_eyes=48"])
    res = pipeline.run(cfg, cache=None)
    rec = next(r for r in res.records if r.name == "hidden")
    assert rec.counts_out["triangles"] < rec.counts_in["triangles"]
    assert rec.accuracy["wrong_pixels"] == 0
    assert rec.details["holdout"]["pixels_showing_the_model"] > 10_000


def test_the_reader_camera_region_is_the_green_flag_eye():
    """``camera = true`` alone: one eye where the reader's green flag puts its camera; the kept
    triangles are what the z-buffer shows from there."""
    from bake.scratch.project import auto_camera

    rng = np.random.default_rng(8)
    parts = [box(c - 0.35, c + 0.35) for c in rng.uniform(-1, 1, (10, 3))]
    s = scene_of(*parts)
    out, rec = run(s, outside=False, camera=True, samples=4)
    cam = auto_camera(out.positions[out.used_vertex_mask()])  # what the written lists frame
    eye = [cam.x, cam.y, cam.z]
    assert rec.details["camera_eye"] == pytest.approx(eye, abs=0)
    tri = s.triangle_vertices()
    got, ref = kept_ids(s, out), zbuffer_seen(tri, eye)
    assert ref <= got and all(numpy_sees(tri, eye, t) for t in got - ref)
    assert not any(numpy_sees(tri, eye, t, 2000) for t in set(range(s.n_triangles)) - got)
    assert out.n_triangles < s.n_triangles


def test_the_camera_region_follows_the_camera_the_written_lists_give():
    """The reader frames the vertices it is given, so dropping triangles moves the green flag's
    camera (Suzanne from its camera alone: the kept part is smaller than the model). The stage
    decides again from each place the camera moves to: the camera of what it keeps is the one it
    decided for, and everything the z-buffer shows from there is kept. (Deciding from the first
    camera alone dropped 12 triangles this one shows.)"""
    from bake.scratch.project import auto_camera
    from bake.importers.stage import stage as import_stage
    from bake.config import ImportJob

    from bake.mesh.triangulate import stage as triangulate
    from bake.config import TriangulateConfig

    s, _ = import_stage(Scene(), ImportJob(path=corpus_path("suzanne_obj", "suzanne.obj")))
    s, _ = triangulate(s, TriangulateConfig())
    out, rec = run(s, outside=False, camera=True)
    assert rec.details["camera_moves"] >= 1 and out.n_triangles < s.n_triangles
    cam = auto_camera(out.positions[out.used_vertex_mask()])
    eye = [cam.x, cam.y, cam.z]
    assert rec.details["camera_eye"] == pytest.approx(eye, abs=0)
    assert zbuffer_seen(s.triangle_vertices(), eye, size=256) <= kept_ids(s, out)


# ----------------------------------------------------------------------------- trimming
def test_cut_pieces_tile_the_triangle_and_keep_to_one_side_of_each_plane():
    from bake.mesh.hidden import trim

    tri = (np.array([[0, 0, 0], [4, 0, 0], [0, 4, 0.0]]), np.array([[0, 1, 2]]))
    wall_x = quad([[1, -1, -1], [1, -1, 1], [1, 5, 1], [1, 5, -1]])
    wall_y = quad([[-1, 2.5, -1], [5, 2.5, -1], [5, 2.5, 1], [-1, 2.5, 1]])
    s = scene_of(tri, wall_x, wall_y)
    pairs = trim.crossing(s, 1e-9)
    assert {0} <= set(pairs.ravel()) and len(pairs) == 6  # the triangle crosses 4, the walls each other
    pieces = trim.cut(s, pairs, 1e-9)
    mine = pieces["src"] == 0
    P = np.einsum("fkc,fcx->fkx", pieces["bary"][mine], s.triangle_vertices()[[0]].repeat(mine.sum(), 0))
    area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    assert area.sum() == pytest.approx(8.0, rel=1e-12)
    for axis, at in ((0, 1.0), (1, 2.5)):  # every piece on one side of x = 1 and of y = 2.5
        d = P[:, :, axis] - at
        assert np.all((d.max(axis=1) <= 1e-12) | (d.min(axis=1) >= -1e-12))


def test_trimming_drops_the_inside_of_a_peg_and_leaves_the_picture_as_it_was():
    """A peg half sunk through a box's top: with trim, what is inside the box goes, the kept peg
    area is its outside part (analytic), no crossing is left, and a z-buffer from outside eyes
    draws the same depths as before."""
    from bake.bsp.crossing import crossing_pairs

    base = box([-2, -2, -2], [2, 2, 2])
    peg = box([-0.5, 1.0, -0.5], [0.5, 3.0, 0.5])  # from y = 1 (inside) to y = 3 (outside)
    s = scene_of(base, peg)
    assert len(crossing_pairs(s.positions, s.triangles, 1e-9)) > 0
    plain, _ = run(s)
    out, rec = run(s, trim=True, trim_most=0, holdout_eyes=32)
    assert rec.accuracy["wrong_pixels"] == 0 and rec.details["trim"]["pieces_dropped"] > 0
    assert len(crossing_pairs(out.positions, out.triangles, 1e-9)) == 0
    tri = out.triangle_vertices()
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    peg_part = np.all(np.abs(tri[:, :, [0, 2]]) <= 0.5 + 1e-12, axis=(1, 2)) & np.all(tri[:, :, 1] >= 2 - 1e-12, axis=1)
    # the peg's outside: 4 sides of 1 x 1 and its top; the box top loses the 1 x 1 hole
    assert area[peg_part].sum() == pytest.approx(4 * 1.0 + 1.0, rel=1e-9)
    assert area.sum() == pytest.approx(6 * 16 - 1 + 5, rel=1e-9)
    # without trimming only the peg's bottom (inside the box) goes: every crossing triangle shows a part
    assert plain.n_triangles == s.n_triangles - 2
    assert_same_picture(s, tri, seed=4)


def test_trimming_cuts_only_where_the_crossings_are():
    """Three pegs half sunk through a slab's top: the top's two triangles are crossed by twelve
    peg sides. Cut by whole planes, every side's line runs across the whole top (56 triangles
    kept on it); cut only where a crossing is and joined again by outline, the top (a square with
    three square holes, at least 16 + 2 x 3 - 2 = 20 triangles) takes at most 24. The picture is
    the same, the kept area is the visible one, and no crossing is left."""
    from bake.bsp.crossing import crossing_pairs

    slab = box([-4, -1, -4], [4, 1, 4])
    centres = ((-2.0, 1.0), (1.5, -2.0), (2.0, 2.5))
    pegs = [box([x - 0.5, 0.5, z - 0.5], [x + 0.5, 2.0, z + 0.5]) for x, z in centres]
    s = scene_of(slab, *pegs)
    out, rec = run(s, trim=True, trim_most=0, holdout_eyes=32)
    assert rec.accuracy["wrong_pixels"] == 0
    assert len(crossing_pairs(out.positions, out.triangles, 1e-9)) == 0
    tri = out.triangle_vertices()
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    top = np.all(np.abs(tri[:, :, 1] - 1.0) <= 1e-12, axis=1)
    # the slab: 2 x 64 + 4 x 16, its top less three 1 x 1 holes; each peg: 4 sides of 1 x 1 and a top
    assert area[top].sum() == pytest.approx(64 - 3, rel=1e-12)
    assert area.sum() == pytest.approx(2 * 64 + 4 * 16 - 3 + 3 * 5, rel=1e-12)
    assert 20 <= top.sum() <= 24
    assert_same_picture(s, tri, seed=5)


def test_a_source_whose_kept_part_takes_more_than_trim_most_triangles_is_written_whole():
    """The slab and pegs above with the default ``trim_most = 3``: the slab's top, a square with
    three holes (at least 20 triangles), is written as its own two triangles again; the peg sides
    (2 triangles each for what shows) stay trimmed, so nothing crosses, and the picture is the same."""
    from bake.bsp.crossing import crossing_pairs

    slab = box([-4, -1, -4], [4, 1, 4])
    pegs = [box([x - 0.5, 0.5, z - 0.5], [x + 0.5, 2.0, z + 0.5]) for x, z in ((-2.0, 1.0), (1.5, -2.0), (2.0, 2.5))]
    s = scene_of(slab, *pegs)
    assert HiddenConfig().trim_most == 3
    out, rec = run(s, trim=True, holdout_eyes=32)
    full, _ = run(s, trim=True, trim_most=0, holdout_eyes=32)
    assert rec.accuracy["wrong_pixels"] == 0 and rec.details["trim"]["written_whole"] == 2
    tri = out.triangle_vertices()
    top = np.all(np.abs(tri[:, :, 1] - 1.0) <= 1e-12, axis=1)
    assert top.sum() == 2 and out.n_triangles < full.n_triangles
    assert len(crossing_pairs(out.positions, out.triangles, 1e-9)) == 0
    area = 0.5 * np.linalg.norm(np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]), axis=1)
    assert area[top].sum() == pytest.approx(64.0, rel=1e-12)
    assert_same_picture(s, tri, seed=5)


def test_outline_joins_pieces_across_a_cut_that_stops_inside_them():
    """The kept pieces of the triangle (0,0) (4,0) (0,4): the part x <= 1 and the part 1 <= x <= 2
    cut again at y = 1 (a cut clipped to its crossing, so the piece x <= 1 has no corner at (1, 1):
    a T-junction). Their outline is one loop, (0,0) (2,0) (2,2) (0,4) once the corners it goes
    straight through are left out: two triangles for the six pieces, of the same area."""
    from bake.mesh.hidden import trim

    v = np.array([[0, 0], [4, 0], [0, 4], [1, 0], [2, 0], [2, 1], [2, 2], [1, 3], [1, 1]], float)
    pos = np.c_[v, np.zeros(len(v))]
    polys = [[0, 3, 7, 2], [3, 4, 5, 8], [8, 5, 6, 7]]  # x <= 1; x in [1, 2] below and above y = 1
    fans = [[p[0], p[i], p[i + 1]] for p in polys for i in (1, 2)]
    union = make_scene(pos, np.array([[0, 1, 2]] + fans))
    keep = np.array([False] + [True] * 6)
    source = np.array([-1] + [0] * 6)
    out, keep2, redrawn, owner = trim.outline(union, keep, 1, source, 4.0)
    assert redrawn == 1 and not keep2[:7].any() and keep2[7:].sum() == 2 and np.all(owner[7:] == 0)
    tri = out.triangle_vertices()[keep2]
    area = 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])[:, 2]
    assert np.all(area > 0) and area.sum() == pytest.approx(6.0, rel=1e-12)


def test_trimming_is_deterministic_and_off_by_default():
    assert HiddenConfig().trim is False
    rng = np.random.default_rng(6)
    parts = [box(c - 0.5, c + 0.5) for c in rng.uniform(-0.8, 0.8, (6, 3))]
    s = scene_of(*parts)
    a, ra = run(s, trim=True, threads=1)
    b, rb = run(s, trim=True, threads=2)
    assert np.array_equal(a.positions, b.positions) and np.array_equal(a.triangles, b.triangles)
    assert ra.details["trim"] == rb.details["trim"]
