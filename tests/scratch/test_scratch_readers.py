"""The reader sprite in the real Scratch VM, against our Python references.

Corpus models and a generated triangle soup are baked through the real pipeline (BVH on, every
layout); the .sb3 and .sprite3 the export stage writes are validated by scratch-parser, loaded into
scratch-vm, and the reader's custom blocks are run headless. They must give:

* ``load triangle`` (in the .sprite3): exactly the corners and colour in the lists;
* ``bvh ray``: bit for bit the hit (triangle, t, u, v) of ``bake.bvh.traverse.trace_one`` run on the
  lists as written, for rays that hit, graze, miss, run along axes and start inside;
* ``project vertices``: bit for bit ``readers.project`` (Scratch's degree trig, 10-decimal rounding);
* ``render``: pen strokes that, rasterised, show at every unambiguous pixel the colour of the
  triangle a painter's-algorithm rasterisation of the projected triangles (Python) shows there.
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest

from bake.bvh.traverse import BARY_HI, BARY_LO, trace_one
from bake.scratch import sb3
from bake.scratch import readers
from bake.scratch.project import reader_spec
from bake.scratch.colors import decode_numbers
from conftest import corpus_path
from scratch_models import bake, cameras, check_render, encoded_from_lists, project_lists, rays, soup_obj
from vm_harness import call, camera_vars, vm  # noqa: F401

BAKES = [  # (model, layout, quant bits)
    ("cube", "binary", 6), ("cube", "quantised", 6),
    ("suzanne", "binary", 6), ("suzanne", "wide4", 6), ("suzanne", "quantised", 6), ("suzanne", "quantised", 3),
    ("soup", "binary", 6), ("soup", "wide4", 6), ("soup", "quantised", 5),
]
RAYS_PER_BAKE = 12
LOAD_T = 3


def _model(name, tmp):
    if name == "cube":
        return corpus_path("cube_quads_mtl", "cube.obj")
    if name == "suzanne":
        return corpus_path("suzanne_obj", "suzanne.obj")
    return soup_obj(tmp / "soup.obj")


@pytest.fixture(scope="module")
def baked(tmp_path_factory, vm):
    """Bake everything, run everything in the VM in one Node process, keep the answers."""
    tmp = tmp_path_factory.mktemp("readers")
    cases, jobs = [], []
    for k, (model, layout, bits) in enumerate(BAKES):
        res = bake(_model(model, tmp), bvh={"enabled": True, "layout": layout, "quant_bits": bits})
        files = res.scene.artefacts.outputs
        stem = next(n for n in files if n.endswith(".sb3"))[:-4]
        sb3_path = tmp / f"{k}-{stem}.sb3"
        sprite_path = tmp / f"{k}-{stem}.sprite3"
        sb3_path.write_bytes(files[f"{stem}.sb3"])
        sprite_path.write_bytes(files[f"{stem}.sprite3"])
        lists = project_lists(files[f"{stem}.sb3"])
        spec = reader_spec(res.scene, res.config.export, lists)
        assert spec.bvh is not None and spec.bvh.layout == layout
        enc = encoded_from_lists(res.scene.artefacts.bvh.encoded, lists, spec.bvh)
        rs = rays(lists["verts"], lists["tris"], RAYS_PER_BAKE, seed=k)
        n_tris = len(lists["tris"]) // 4
        ts = [1, n_tris, 1 + (7 * k) % n_tris][:LOAD_T]
        loads = [call("Mesh", "load triangle %s", t, variables=["x1", "y1", "z1", "x2", "y2", "z2", "x3", "y3",
                                                                  "z3", "tri color"]) for t in ts]
        ray_runs = [call("Mesh", "bvh ray %s %s %s %s %s %s", *o, *d,
                         variables=["hit tri", "hit t", "hit u", "hit v", "hit slot"]) for o, d in rs]
        jobs.append({"load": str(sb3_path), "runs": ray_runs})
        # the .sprite3 on its own (added to an empty project, as "Upload Sprite" does), with the
        # authors' helper block
        jobs.append({"load": str(sprite_path), "runs": loads + ray_runs[:4]})
        cases.append({"bake": (model, layout, bits), "lists": lists, "enc": enc, "rays": rs, "ts": ts,
                      "sb3": sb3_path, "sprite3": sprite_path, "spec": spec, "result": res})
    render_case = _render_jobs(tmp, cases[4], jobs)
    out = vm({"jobs": jobs}, timeout=600)["jobs"]
    for k, case in enumerate(cases):
        case["vm"], case["vm_sprite"] = out[2 * k], out[2 * k + 1]
    render_case["vm"] = out[2 * len(cases):]
    return cases, render_case


# --------------------------------------------------------------------------- validity
def test_every_written_project_and_sprite_passes_scratch_parser(baked):
    cases, render = baked
    for case in cases:
        for res, path in ((case["vm"], case["sb3"]), (case["vm_sprite"], case["sprite3"])):
            assert res["validation"] == [{"file": str(path), "ok": True, "projectVersion": 3}], res["validation"]
            project, assets = (sb3.load_project(path) if path.suffix == ".sb3" else (None, None))
            if project is not None:
                assert sb3.validate_project(project, assets) == []
    for res in render["vm"]:
        assert all(v["ok"] for v in res["validation"])


# --------------------------------------------------------------------------- mesh
@pytest.mark.parametrize("k", range(len(BAKES)), ids=["-".join(map(str, b)) for b in BAKES])
def test_load_triangle_reads_the_lists(baked, k):
    case = baked[0][k]
    verts = np.asarray(case["lists"]["verts"], np.float64).reshape(-1, 3)
    tris = np.asarray(case["lists"]["tris"]).reshape(-1, 4)
    colours = case["lists"].get("tri colors") or case["lists"]["mat colors"]
    for t, run in zip(case["ts"], case["vm_sprite"]["runs"][:LOAD_T]):
        v = run["variables"]
        corners = verts[tris[t - 1, :3] - 1]
        for c in range(3):
            assert [v[f"x{c + 1}"], v[f"y{c + 1}"], v[f"z{c + 1}"]] == corners[c].tolist()
        want = colours[t - 1] if "tri colors" in case["lists"] else colours[tris[t - 1, 3] - 1]
        assert v["tri color"] == want


# --------------------------------------------------------------------------- BVH
def _check_rays(case, runs, rays_):
    """Every ray's run of the block against the Python traversal; the hits."""
    assert len(rays_) and len(runs) >= len(rays_), (len(runs), len(rays_))  # (zip would stop short)
    hits = 0
    for (o, d), run in zip(rays_, runs):
        t, slot0, tri_id, u, v, _reads = trace_one(case["enc"], o, d, tmax=readers.BIG)
        got = run["variables"]
        # a miss sets "hit tri" with a typed-in 0, which Scratch stores as the text "0"
        assert float(got["hit tri"]) == tri_id, (o, d)
        if tri_id:
            hits += 1
            assert (got["hit t"], got["hit u"], got["hit v"], got["hit slot"]) == (t, u, v, slot0 + 1), (o, d)
    return hits


@pytest.mark.parametrize("k", range(len(BAKES)), ids=["-".join(map(str, b)) for b in BAKES])
def test_bvh_query_matches_the_python_traversal_bit_for_bit(baked, k):
    case = baked[0][k]
    hits = _check_rays(case, case["vm"]["runs"], case["rays"])
    assert hits >= RAYS_PER_BAKE // 4  # the aimed rays hit: the comparison is not all misses
    # the sprite's own copy of the block, on the first four rays (each compared, hit or miss)
    _check_rays(case, case["vm_sprite"]["runs"][LOAD_T:], case["rays"][:4])


# (x, y): hit? for the ray (x, y, -1) + t (0, 0, 1) at the triangle (0,0,0) (1,0,0) (0,1,0), where
# u = x, v = y: 5e-10 outside an edge hits, 2e-9 outside misses (as tests/bvh/test_traverse.py)
TOLERANCE_RAYS = {(0.25, 0.25): True, (0.0, 0.0): True, (-5e-10, 0.5): True, (0.5, -5e-10): True,
                  (0.5, 0.5 + 5e-10): True, (-5e-10, -5e-10): True, (-2e-9, 0.5): False, (0.5, -2e-9): False,
                  (0.5, 0.5 + 2e-9): False, (-2e-9, -2e-9): False}


def test_bvh_triangle_test_tolerance_in_the_vm(vm, tmp_path):  # noqa: F811
    """The reader's typed-in tolerance (-1e-09, 1.000000001) is the reference's, bit for bit:
    rays just inside and just outside the widened triangle, every layout."""
    from bake.bvh import stage as bvh_stage
    from bake.config import BVHConfig
    from bake.scene import make_scene

    sc = make_scene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
    rs = [([x, y, -1.0], [0.0, 0.0, 1.0]) for x, y in TOLERANCE_RAYS]
    jobs, encs = [], []
    for layout in ("binary", "wide4", "quantised"):
        out, _ = bvh_stage.stage(sc, BVHConfig(enabled=True, layout=layout))
        enc = out.artefacts.bvh.encoded
        lists = {"bvh nodes": enc.nodes.tolist(), "bvh tris": enc.tris.tolist(), "bvh tri ids": enc.ids.tolist()}
        spec = readers.ReaderSpec(mesh=None, bvh=readers.BVHSpec(bary=(BARY_LO, BARY_HI), layout=layout, bits=enc.bits), textimage=False)
        sprite = readers.reader_target(spec, "Mesh", stage_lists=list(lists))
        data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists), sprite])
        path = tmp_path / f"tol-{layout}.sb3"
        path.write_bytes(data)
        jobs.append({"load": str(path), "runs": [call("Mesh", "bvh ray %s %s %s %s %s %s", *o, *d,
                                                      variables=["hit tri", "hit t", "hit u", "hit v", "hit slot"])
                                                 for o, d in rs]})
        encs.append(enc)
    for enc, res in zip(encs, vm({"jobs": jobs})["jobs"]):
        hits = _check_rays({"enc": enc}, res["runs"], rs)
        assert hits == sum(TOLERANCE_RAYS.values())


# --------------------------------------------------------------------------- renderer
def _render_jobs(tmp, case, jobs):
    """Suzanne with a random colour per triangle (so a pixel's colour names its triangle), rendered
    in list order (no BSP tree) from two cameras."""
    lists = dict(case["lists"])
    n = len(lists["tris"]) // 4
    rng = np.random.default_rng(7)
    lists["tri colors"] = [int(c) for c in rng.choice(np.arange(1 << 24), n, replace=False)]
    out = {"lists": lists, "files": []}
    spec = readers.ReaderSpec(mesh=readers.MeshNames(tri_colors="tri colors"), bvh=None, textimage=False,
                              bounds=readers.bounding_sphere(lists["verts"]))
    sprite = readers.reader_target(spec, "Mesh", stage_lists=list(lists))
    data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists), sprite])
    p = tmp / "render.sb3"
    p.write_bytes(data)
    for cam in cameras(lists["verts"]):
        jobs.append({"load": str(p), "runs": [
            call("Mesh", "render", lists=["_px", "_py", "_pz"], pen=True, set=camera_vars(cam))]})
        out["files"].append(cam)
    return out


def test_renderer_draws_the_painters_picture(baked):
    _cases, render = baked
    lists = render["lists"]
    verts = np.asarray(lists["verts"], np.float64)
    tris = np.asarray(lists["tris"], np.int64).reshape(-1, 4)
    colours = decode_numbers(lists["tri colors"])[:, :3].astype(int)
    for cam, res in zip(render["files"], render["vm"]):
        run = res["runs"][0]
        assert run["done"]
        px, py, pz = readers.project(verts, cam)
        # projection: bit for bit, including Scratch's rounded degree trig
        assert run["lists"]["_px"] == px.tolist() and run["lists"]["_py"] == py.tolist()
        assert run["lists"]["_pz"] == pz.tolist()
        shown = readers.drawn(verts, lists["tris"], cam)
        assert 0 < shown.sum() < len(tris)  # back faces culled on the stage
        order = [t for t in range(1, len(tris) + 1) if shown[t - 1]]  # no BSP: list order
        check_render(run["pen"], px, py, pz, tris, order, colours, cam.near / cam.focal, False)


def test_demo_script_and_reader_without_bvh(baked):
    """The fresh .sb3's green flag renders from the camera the bake chose; the reader holds only
    what the bake wrote (no TextImage decoder, no alphabet costumes, one BVH layout)."""
    case = baked[0][2]
    with open(case["sb3"], "rb") as f:
        project, _ = sb3.load_project(f.read())
    sprite = next(t for t in project["targets"] if t["name"] == "Mesh")
    assert sprite["visible"] is False and [c["name"] for c in sprite["costumes"]] == ["fence"]
    flags = [b for b in sprite["blocks"].values() if isinstance(b, dict) and b["opcode"] == "event_whenflagclicked"]
    assert len(flags) == 1
    names = {b["mutation"]["proccode"] for b in sprite["blocks"].values()
             if isinstance(b, dict) and b["opcode"] == "procedures_prototype"}
    assert {"render", "project vertices", "bvh ray %s %s %s %s %s %s"} <= names
    assert not names & {"decode textimage %s", "load triangle %s"}
    assert json.dumps(project["extensions"]) == '["pen"]'


def _filler_triangles(rng) -> np.ndarray:
    """(T, 3, 2) stage-pixel triangles, clockwise on the stage (drawn), first corner opposite the
    shortest edge (as the BSP stage writes them): needles (that edge 0.05-1.5 pixels: one line with
    pen size 2.5, and just over), two lines (up to 3 pixels, and just over), and fans of every length
    3-12 of both parities (the edge up to 18 pixels)."""
    tris = []
    shorts = list(np.linspace(0.05, 1.5, 12)) + [1.0 + 1e-9, 1.5 + 1e-9, 1.51, 2.0, 3.0, 3.0 + 1e-9]
    shorts += list(rng.uniform(1.5, 18.0, 40)) + [4.5, 6.0, 7.5, 9.0, 10.5, 12.0, 13.5, 15.0, 16.5, 18.0]
    for k, L in enumerate(shorts):
        h = float(rng.uniform(max(L, 1.5), 40.0)) if k % 5 else float(rng.uniform(L, L + 2.0))
        ang = float(rng.uniform(0, 2 * np.pi))
        u, w = np.array([np.cos(ang), np.sin(ang)]), np.array([-np.sin(ang), np.cos(ang)])
        off = float(rng.uniform(-0.3, 0.3)) * L  # where a's foot falls along b-c
        col, row = k % 8, k // 8
        centre = np.array([-200.0 + 55.0 * col, -150.0 + 50.0 * row])
        b = centre - 0.5 * L * u
        c = centre + 0.5 * L * u
        a = centre + off * u + h * w
        t = np.array([a, b, c])
        area2 = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if area2 > 0:
            t = np.array([a, c, b])
        tris.append(t)
    return np.array(tris)


def test_filler_covers_each_triangle_within_half_a_pixel_with_the_fewest_lines(vm, tmp_path):  # noqa: F811
    """Each triangle the renderer fills: every point of it lies within (w - 1) / 2 of one of its
    pen lines (w: the pen size, 2.5; the pen paints w / 2 on each side, so everything within half a
    pixel of the triangle is painted), no line leaves it, and it costs the lines the filler's rule
    says: a fan of k = ceiling(L / (w - 1)) lines to the opposite edge (length L), walked in
    floor((3k - 1) / 2) lines, one for a needle (L <= w - 1) (the lines counted from the strokes
    scratch-vm's pen made)."""
    cam = readers.Camera()  # at (0, 0, -5) looking along +z, focal 300: a point (x, y, 0) is at 60 (x, y)
    tri_px = _filler_triangles(np.random.default_rng(11))
    T = len(tri_px)
    verts = np.concatenate([tri_px / 60.0, np.zeros((T, 3, 1))], axis=2).reshape(-1, 3)
    lists = {"verts": [float(x) for x in verts.ravel()],
             "tris": [int(x) for t in range(T) for x in (3 * t + 1, 3 * t + 2, 3 * t + 3, 1)],
             # pairs of neighbours share a colour: the filler sets the pen's colour only when it changes
             "tri colors": [int(c) for c in np.repeat(np.random.default_rng(5).choice(1 << 24, T, replace=False), 2)[:T]]}
    spec = readers.ReaderSpec(mesh=readers.MeshNames(mat_colors=None, tri_colors="tri colors"), bvh=None, textimage=False,
                              bounds=readers.bounding_sphere(lists["verts"]))
    sprite = readers.reader_target(spec, "Mesh", stage_lists=list(lists))
    data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists), sprite])
    path = tmp_path / "filler.sb3"
    path.write_bytes(data)
    # _pc, the colour the filler last gave the pen, is left holding the first triangle's colour while
    # the pen is still the default blue: the frame must not trust a value from before it
    init = dict(camera_vars(cam), _pc=lists["tri colors"][0])
    run = vm({"load": str(path), "runs": [call("Mesh", "render", pen=True, set=init)]})["runs"][0]
    assert run["done"]
    px, py, _ = readers.project(verts, cam)
    P = np.stack([px, py], axis=1).reshape(T, 3, 2)
    assert np.abs(P - tri_px).max() < 1e-9  # the design is what the stage shows
    assert readers.drawn(verts, lists["tris"], cam).all()
    # one group of strokes per triangle, each opened by pen down's dot at its first corner
    strokes = np.array(run["pen"], np.float64)
    pen = spec.pen_size
    assert pen == 2.5 and (strokes[:, 4] == pen).all()
    dot = (strokes[:, 0] == strokes[:, 2]) & (strokes[:, 1] == strokes[:, 3])
    starts = np.flatnonzero(dot)
    assert len(starts) == T
    groups = np.split(strokes, starts[1:])
    w = np.linspace(0, 1, 41)
    bary = np.array([(x, y, 1 - x - y) for x in w for y in w if x + y <= 1 + 1e-12])
    bary = np.clip(bary, 0, 1)
    lines_needed = 0
    ks = []
    for t, g in enumerate(groups):
        A, B, C = P[t]
        seg = g[1:, :4]
        # every stroke in the triangle's colour (the pen's HSV round trip moves a channel by <= 1)
        rgb = np.array([(lists["tri colors"][t] >> s) & 255 for s in (16, 8, 0)])
        assert np.abs(g[:, 5:8] - rgb).max() <= 2, (t, g[:, 5:8].tolist(), rgb)
        # cost: the rule, counted independently of the blocks; the pen goes down at the first
        # point of the fan, in the middle of the first of the k pieces of b-c
        k = max(1, math.ceil(math.sqrt(float(((C - B) ** 2).sum())) / (pen - 1)))
        assert np.abs(g[0, :2] - (B + (C - B) / (2 * k))).max() < 1e-9, t
        want = (3 * k - 1) // 2
        assert len(seg) == want, (t, len(seg), want)
        L2 = float(((C - B) ** 2).sum())
        lines_needed += want
        # no line leaves the triangle (to 1e-9 of a pixel)
        ends = seg.reshape(-1, 2)
        e0, e1 = B - A, C - A
        det = e0[0] * e1[1] - e0[1] * e1[0]
        s = ((ends[:, 0] - A[0]) * e1[1] - (ends[:, 1] - A[1]) * e1[0]) / det
        r = (e0[0] * (ends[:, 1] - A[1]) - e0[1] * (ends[:, 0] - A[0])) / det
        scale = max(1.0, float(np.abs(P[t]).max()))
        assert (s >= -1e-9 * scale).all() and (r >= -1e-9 * scale).all() and (s + r <= 1 + 1e-9 * scale).all(), t
        # every point of the triangle within half a pixel of a line
        Q = bary @ P[t]
        p0, d = seg[:, None, :2], seg[:, None, 2:] - seg[:, None, :2]
        dd = (d * d).sum(-1)
        along = np.clip(((Q[None] - p0) * d).sum(-1) / np.where(dd > 0, dd, 1), 0, 1)
        dist = np.sqrt((((p0 + along[..., None] * d) - Q[None]) ** 2).sum(-1)).min(axis=0)
        assert dist.max() <= (pen - 1) / 2 + 1e-9, (t, float(dist.max()), float(math.sqrt(L2)))
        ks.append(k)
    assert lines_needed == len(strokes) - T
    assert set(range(1, 13)) <= set(ks)  # every path of the filler: one line, two, fans of both parities
