"""The green flag's BVH view (``export.green_flag = "bvh"``): ``camera ray`` and ``bvh view`` in
the real Scratch VM against ``bake.outputs.bvh_view``, and the Python view against the numpy
rasterizer.

* ``camera ray (sx) (sy)``: bit for bit the direction of ``bvh_view.view_rays``;
* ``bvh view`` (the green flag): one pen dot per cell whose ray hits, at the cell's centre, of the
  pen size ``view_pen_size(cell)`` and the colour the Python view gives the cell (the hit
  triangle's ``tri colors`` item, or its material's ``mat colors`` item, read through the layout the
  bake wrote: per-coordinate lists with 0-based indices, a soup), no dot for a cell that misses;
* the Python view's rays invert the reader's projection (a ray through a vertex's projected point
  reaches that vertex, and nothing nearer is hit where the vertex is seen), and each cell's hit
  triangle, numbered as the written ``tris`` (after the BSP's reorder), is the one a
  double-sided depth-buffer render of the written mesh shows at the cell's centre.
"""

from __future__ import annotations

import dataclasses
import json

import numpy as np
import pytest

from bake import config
from bake.errors import ConfigError
from bake.outputs import bvh_view as BV
from bake.outputs import preview
from bake.render import render
from bake.scratch import readers, sb3
from bake.scratch.project import book_lists, reader_spec
from conftest import corpus_path
from scratch_models import bake, project_lists
from vm_harness import call, camera_vars, vm  # noqa: F401

LIGHT = {"enabled": True, "target": "triangle", "ambient": [0.1, 0.1, 0.1],
         "lights": [{"kind": "point", "position": [278.0, 450.0, -280.0], "radius": 30.0, "intensity": 2.0e5}]}
# (name, model, sections, cell): every colour source, every BVH layout, the layouts of docs/engines.md
CASES = [
    ("cornell lit bsp", ("cornell_box_tinyobj", "cornell_box.obj"),
     {"lighting": LIGHT, "bsp": {"enabled": True}, "bvh": {"enabled": True}}, 30),
    ("cornell x y z", ("cornell_box_tinyobj", "cornell_box.obj"),
     {"bvh": {"enabled": True, "layout": "binary"},
      "export": {"names": {"vertices": ["X", "Y", "Z"], "triangles": ["tri a", "tri b", "tri c", "tri mat"]},
                 "index_base": 0}}, 24),
    ("cornell soup", ("cornell_box_tinyobj", "cornell_box.obj"),
     {"bvh": {"enabled": True, "layout": "wide4"}, "export": {"faces": "soup"}}, 45),
    ("suzanne", ("suzanne_obj", "suzanne.obj"), {"bvh": {"enabled": True, "quant_bits": 3}}, 40),
]
# stage points for ``camera ray`` (the cells' centres are among them: half-integers, integers)
POINTS = [(0.0, 0.0), (-236.0, 176.0), (239.5, -179.5), (12.25, -97.125), (-0.1, 1e-7), (200.0, 150.0)]
ODD_CAMERA = readers.Camera(x=1.5, y=-2.25, z=-7.0, yaw=37.31, pitch=-12.7, focal=251.5)


def _export(cfg) -> dict:
    return {"names": dataclasses.asdict(cfg.names), "faces": cfg.faces, "index_base": cfg.index_base}


@pytest.fixture(scope="module")
def baked(tmp_path_factory, vm):  # noqa: F811
    tmp = tmp_path_factory.mktemp("bvh view")
    cases, jobs = [], []
    for k, (name, model, sections, cell) in enumerate(CASES):
        sections = {**sections, "export": {**sections.get("export", {}), "green_flag": "bvh", "bvh_cell": cell}}
        res = bake(corpus_path(*model), **sections)
        files = res.scene.artefacts.outputs
        stem = next(n for n in files if n.endswith(".sb3"))[:-4]
        path = tmp / f"{k}.sb3"
        path.write_bytes(files[f"{stem}.sb3"])
        (tmp / f"{k}.sprite3").write_bytes(files[f"{stem}.sprite3"])
        lists = project_lists(files[f"{stem}.sb3"])
        spec = reader_spec(res.scene, res.config.export, lists)
        art = res.scene.artefacts.bvh
        view = BV.bvh_view(lists, spec.camera, cell, art.encoded.layout, art.encoded.bits, names=art.lists,
                           export=_export(res.config.export))
        runs = [{"greenFlag": True, "pen": True, "read": {"lists": [], "variables": ["bvh cell"]}}]
        runs += [call("Mesh", "camera ray %s %s", x, y, variables=["ray dx", "ray dy", "ray dz"],
                      set=camera_vars(ODD_CAMERA)) for x, y in POINTS]
        jobs.append({"load": str(path), "runs": runs, "validate": [str(path), str(tmp / f"{k}.sprite3")]})
        cases.append({"name": name, "res": res, "lists": lists, "spec": spec, "view": view, "cell": cell,
                      "files": files, "stem": stem})
    for case, out in zip(cases, vm({"jobs": jobs}, timeout=600)["jobs"]):
        case["vm"] = out
    return cases


@pytest.mark.parametrize("k", range(len(CASES)), ids=[c[0] for c in CASES])
def test_the_green_flag_paints_the_python_view(baked, k):
    case = baked[k]
    out, view = case["vm"], case["view"]
    assert all(v["ok"] for v in out["validation"]), out["validation"]
    run = out["runs"][0]
    assert run["done"] and float(run["variables"]["bvh cell"]) == case["cell"]
    dots = np.asarray(run["pen"], np.float64)
    hit = view.hit
    assert 0.05 < hit.mean() < 0.95, hit.mean()  # both the model and the empty stage
    gx, gy = np.meshgrid(view.sx, view.sy)
    assert len(dots) == int(hit.sum())
    # one dot (no line) per hit cell, in the blocks' order: rows from the top, left to right
    assert np.array_equal(dots[:, 0], dots[:, 2]) and np.array_equal(dots[:, 1], dots[:, 3])
    assert np.array_equal(dots[:, :2], np.c_[gx[hit], gy[hit]])
    assert np.all(dots[:, 4] == BV.view_pen_size(case["cell"]))
    # the pen keeps colours as HSV: a channel may come back one level off
    assert np.abs(dots[:, 5:8] - view.rgb[hit]).max() <= 1
    assert np.all(dots[:, 8] == 255)


@pytest.mark.parametrize("k", range(len(CASES)), ids=[c[0] for c in CASES])
def test_camera_ray_is_the_python_ray_bit_for_bit(baked, k):
    runs = baked[k]["vm"]["runs"][1:]
    xs, ys = np.array(POINTS).T
    want = BV.view_rays(ODD_CAMERA, xs, ys)
    for (x, y), run, d in zip(POINTS, runs, want):
        got = [run["variables"][f"ray d{a}"] for a in "xyz"]
        assert got == d.tolist(), (x, y)


def test_the_colours_come_from_each_layouts_lists(baked):
    """The lit Cornell box's colours are its ``tri colors``; unlit, its materials', read at
    the hit triangle's material item through 0-based per-coordinate lists and through a soup's
    material list."""
    by = {c["name"]: c for c in baked}
    assert by["cornell lit bsp"]["view"].colours == "tri colors"
    for name in ("cornell x y z", "cornell soup", "suzanne"):
        case = by[name]
        assert case["view"].colours == "mat colors" and "tri colors" not in case["lists"]
    for name, least in (("cornell lit bsp", 3), ("cornell x y z", 2), ("cornell soup", 2)):
        view = by[name]["view"]  # (from outside, unlit: the white ceiling and the green wall)
        assert len(np.unique(view.rgb[view.hit], axis=0)) >= least, name


def test_the_sprite3_carries_the_view_and_the_default_does_not(baked, tmp_path):
    case = baked[0]
    sprite = case["files"][f"{case['stem']}.sprite3"]
    import io
    import zipfile

    with zipfile.ZipFile(io.BytesIO(sprite)) as z:
        target = json.loads(z.read("sprite.json"))
    codes = {b["mutation"]["proccode"] for b in target["blocks"].values()
             if isinstance(b, dict) and b.get("opcode") == "procedures_prototype"}
    assert {"bvh view", "camera ray %s %s", "bvh ray %s %s %s %s %s %s", "render"} <= codes
    # no green-flag script in the .sprite3
    assert not any(isinstance(b, dict) and b.get("opcode") == "event_whenflagclicked"
                   for b in target["blocks"].values())


# --------------------------------------------------------------------------- Python only
def _flag_calls(project: dict) -> list[str]:
    """The custom blocks the reader's green-flag script calls (its own stack and its ifs')."""
    sprite = next(t for t in project["targets"] if t["name"] == "Mesh")
    blocks = sprite["blocks"]
    out: list[str] = []

    def walk(bid):
        while bid:
            b = blocks[bid]
            if b["opcode"] == "procedures_call":
                out.append(b["mutation"]["proccode"])
            for key in ("SUBSTACK", "SUBSTACK2"):
                if key in b.get("inputs", {}):
                    walk(b["inputs"][key][1])
            bid = b.get("next")

    for bid, b in blocks.items():
        if isinstance(b, dict) and b.get("opcode") == "event_whenflagclicked":
            walk(b.get("next"))
    return out


def test_green_flag_bvh_without_a_bvh_warns_and_draws_the_raster():
    res = bake(corpus_path("cube_quads_mtl", "cube.obj"), export={"green_flag": "bvh"})
    export = next(r for r in res.records if r.name == "export")
    assert any("export.green_flag" in w and "no BVH" in w and "render" in w for w in export.warnings), export.warnings
    files = res.scene.artefacts.outputs
    project, _ = sb3.load_project(files[next(n for n in files if n.endswith(".sb3"))])
    assert "render" in _flag_calls(project) and "bvh view" not in json.dumps(project)


def test_bvh_cell_is_checked():
    for bad in (2, 61, 0):
        with pytest.raises(ConfigError) as e:
            config.load(data={"input": {"path": "x.obj"}, "export": {"bvh_cell": bad}})
        assert "bvh_cell" in str(e.value)
    with pytest.raises(ConfigError):
        config.load(data={"input": {"path": "x.obj"}, "export": {"green_flag": "rays"}})
    assert config.load(data={"input": {"path": "x.obj"}, "export": {"bvh_cell": 3}}).export.bvh_cell == 3


def test_the_default_green_flag_renders(baked):
    """Without the key the green flag calls ``render`` (and the project has no view blocks); with
    it, ``bvh view``."""
    res = bake(corpus_path("cube_quads_mtl", "cube.obj"), bvh={"enabled": True})
    files = res.scene.artefacts.outputs
    project, _ = sb3.load_project(files[next(n for n in files if n.endswith(".sb3"))])
    assert _flag_calls(project) == ["render"] and "camera ray" not in json.dumps(project)
    project, _ = sb3.load_project(baked[0]["files"][f"{baked[0]['stem']}.sb3"])
    assert _flag_calls(project) == ["bvh view"]


def test_a_ray_through_a_projected_vertex_reaches_the_vertex(baked):
    """The view's rays invert the reader's projection: the ray through the projected point of a
    corner (as ``bvh tris`` holds it) passes it within 1e-9 of its distance at t = its depth over
    focal, and hits nothing farther (but at a few silhouette corners); where the corner is in
    sight it is the hit, on a triangle that has it."""
    for case in baked:
        cam, view = case["spec"].camera, case["view"]
        lists = case["lists"]
        art = case["res"].scene.artefacts.bvh
        corners = np.asarray(lists[art.lists["tris"]], np.float64).reshape(-1, 3, 3)
        pts = np.unique(corners.reshape(-1, 3), axis=0)
        px, py, w = readers.project(pts, cam)
        ok = (w > 0) & (np.abs(px) < 240) & (np.abs(py) < 180)
        assert ok.mean() > 0.9
        d = BV.view_rays(cam, px[ok], py[ok])
        enc = BV.encoded_from_lists(lists, art.encoded.layout, art.encoded.bits, art.lists)
        from bake.bvh.traverse import trace

        hits = trace(enc, np.tile([cam.x, cam.y, cam.z], (len(d), 1)), d)
        t, want = hits.t, w[ok]
        # the ray passes the corner within 1e-9 of its distance (the rounded sine and cosine)
        eye = np.array([cam.x, cam.y, cam.z])
        rel = pts[ok] - eye
        off = np.linalg.norm(np.cross(rel, d), axis=1) / np.linalg.norm(d, axis=1)
        dist = np.linalg.norm(rel, axis=1)
        assert np.all(off <= 1e-9 * dist), (case["name"], (off / dist).max())
        # so it meets the mesh at the corner or before it: all but a few silhouette corners (Suzanne:
        # 2 of 505), which that 1e-9 can put just outside every triangle at the corner (it is more
        # than the 1e-9 barycentric tolerance of a triangle 1/100 of the distance across)
        far = t > want * (1 + 1e-9)
        assert far.mean() <= 0.01 and np.all(hits.tri > 0), (case["name"], far.sum())
        seen = np.abs(t - want) <= 1e-9 * want
        assert seen.sum() >= 5 and seen.mean() > 0.2, (case["name"], seen.mean())  # (the box hides its inside)
        # the corner hit is a corner of the slot's triangle
        slot = corners[hits.slot[seen]]
        p = pts[ok][seen]
        assert np.all(np.min(np.abs(slot - p[:, None, :]).max(2), axis=1) == 0)
        # and the hit point is the corner, to the rounding of the inversion
        at = np.array([cam.x, cam.y, cam.z]) + t[seen, None] * d[seen]
        diag = float(np.linalg.norm(pts.max(0) - pts.min(0)))
        assert np.abs(at - p).max() < 1e-7 * diag


def test_each_cell_shows_the_triangle_a_depth_buffer_shows():
    """The hit triangle's number is the written ``tris`` order, also after the BSP stage reorders
    (and splits) triangles: a double-sided depth-buffer render of the written mesh (the numpy
    rasterizer, the reader's camera) shows that triangle at the cell's centre (odd cells: the
    sample pixel's centre is the cell's; cells of 5 and 9). The lit Cornell box and the bunny, each
    with a BSP tree."""
    cases = [(("cornell_box_tinyobj", "cornell_box.obj"), {"lighting": LIGHT, "bsp": {"enabled": True}}),
             (("stanford_bunny_res1_obj", "stanford-bunny.obj"),
              {"mesh": {"simplify": {"enabled": True, "target_triangles": 600, "method": "meshopt", "fit_iterations": 0,
                                     "refine_rounds": 0, "peak_rounds": 0}},
               "bsp": {"enabled": True}, "bvh": {"enabled": True, "layout": "binary"}})]
    for model, sections in cases:
        res = bake(corpus_path(*model), **{"bvh": {"enabled": True}, **sections})
        assert res.scene.artefacts.bsp is not None
        lists = json.loads(res.scene.artefacts.outputs["lists.json"])["lists"]
        spec = reader_spec(res.scene, res.config.export, lists)
        art = res.scene.artefacts.bvh
        book = book_lists(res.config.export, lists)
        verts = np.asarray(book["vertices"], np.float64).reshape(-1, 3)
        tris = np.asarray(book["triangles"], np.int64).reshape(-1, 4)[:, :3] - 1
        im = render(preview.stage_camera(spec.camera, 480), verts[tris], mode="zbuffer",
                    two_sided=np.ones(len(tris), bool))
        for cell in (5, 9):
            view = BV.bvh_view(lists, spec.camera, cell, art.encoded.layout, art.encoded.bits, names=art.lists)
            r, c, on = view.samples()
            shown = im.tri_id[r[on], c[on]] + 1
            agree = (shown == view.tri[on]).mean()
            # (a cell centre on an edge between two triangles may go either way)
            assert agree >= 0.99 and view.hit.mean() > 0.05, (model, cell, agree)  # (measured: 1.0)


def test_report_html_shows_the_view_beside_the_green_flag(tmp_path):
    """report.html's green-flag row has the BVH view, the Python picture of the lists as written
    (bake report re-renders it from the folder); without the key it has none."""
    import base64
    import io

    from PIL import Image

    from bake import cli
    from bake.outputs import html

    model = corpus_path("cornell_box_tinyobj", "cornell_box.obj")
    out = tmp_path / "out"
    assert cli.main(["run", str(model), "--out", str(out), "--quiet", "--set", "bvh.enabled=true",
                     "--set", 'export.green_flag="bvh"', "--set", "export.bvh_cell=12"]) == 0
    page, info = html.build(out)
    lists = json.loads((out / "lists.json").read_text())["lists"]
    report = json.loads((out / "report.json").read_text())
    view = BV.view_from_report(lists, report)
    assert view is not None and view.cell == 12 and info["bvh_view"] == view.to_json()
    i = page.index("BVH view (the green flag's)")
    src = page.rfind("src='data:image/png;base64,", 0, i) + len("src='data:image/png;base64,")
    img = np.asarray(Image.open(io.BytesIO(base64.b64decode(page[src:page.index("'", src)]))).convert("RGB"))
    mesh = preview.mesh_from_lists(lists, report)
    assert np.array_equal(img, view.stage(mesh.backdrop))
    assert cli.main(["run", str(model), "--out", str(tmp_path / "plain"), "--quiet", "--set", "bvh.enabled=true"]) == 0
    page, info = html.build(tmp_path / "plain")
    assert info["bvh_view"] is None and "BVH view" not in page
