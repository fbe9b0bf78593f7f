"""Written .sb3 files in TurboWarp's real player (its compiler and its interpreter, the WebGL
renderer with the pen layer) in headless Chromium (vm/player.js, vm/turbowarp.py).

The green flag is pressed, the scripts must finish without a console or page error and leave a
picture, and the stage must agree with report.html's "green flag" preview, rendered by the numpy
rasterizer with the reader's own camera model (``bake.outputs.preview.stage_view``):

* at every *interior* pixel (the preview shows the same triangle in the 5 x 5 pixels around it)
  the colour is the triangle's within one level per channel: the pen keeps colours as HSV, and
  the round trip moves a channel by at most one (measured: 0 or 1 everywhere, both models);
* of the *covered* pixels (the preview shows a triangle at the pixel and its 8 neighbours), at
  least ``COVERED_WITHIN_1`` show, within one level, the preview's colour at the pixel or a
  neighbour. The rest are the antialiased ends of pen strokes, which blend two neighbouring
  triangles' colours. Measured here: 0.95 for the demo, 0.91 for the lit teapot (the pen outline
  of many 1-2 pixel triangles); the threshold 0.85 leaves room for swiftshader and pen-width
  rounding, and a mirrored or shifted picture scores far below it (the test checks that);
* no interior pixel is left blank, and no pixel farther than 2 pixels from every triangle is painted.
"""

from __future__ import annotations

import json
import sys
from pathlib import Path

import numpy as np
import pytest

from bake import cli, config, pipeline
from bake.outputs import preview
from bake.scratch import blocks as B
from bake.scratch import backdrop, sb3
from bake.scratch.project import auto_camera
from conftest import CORPUS

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "vm"))
import turbowarp  # noqa: E402

COVERED_WITHIN_1 = 0.85

TEAPOT = {"lighting": {"enabled": True, "target": "triangle", "ambient": [0.2, 0.2, 0.25],
                       "lights": [{"kind": "sun", "direction": [0.5, -1, -0.4]}]},
          "bsp": {"enabled": True}}


def bake_to(model: Path, out: Path, sections: dict) -> Path:
    data = {"input": {"path": str(model)}, **sections}
    res = pipeline.run(config.load(data=data))
    out.mkdir(parents=True, exist_ok=True)
    files = res.scene.artefacts.outputs
    name = next(n for n in files if n.endswith(".sb3"))
    (out / name).write_bytes(files[name])
    (out / "lists.json").write_bytes(files["lists.json"])  # the lists as written (packed ones too)
    return out / name


# layouts for authors' engines (docs/engines.md): the reader draws from the lists as written
PER_COORDINATE = {"names": {"vertices": ["X", "Y", "Z"], "triangles": ["tri a", "tri b", "tri c", "tri mat"]},
                  "index_base": 0}
SOUP_XYZ = {"faces": "soup", "names": {"vertices": ["X", "Y", "Z"]}}
LAYOUTS = {"suzanne x y z": PER_COORDINATE, "teapot soup": SOUP_XYZ}


def _preview(sb3_path: Path, export: dict | None = None):
    project, assets = sb3.load_project(sb3_path)
    lists = {n: items for t in project["targets"] for n, items in (t.get("lists") or {}).values()}
    if (sb3_path.parent / "lists.json").exists():  # (a packed list is empty in the project)
        lists.update(json.loads((sb3_path.parent / "lists.json").read_text())["lists"])
    sprite = next(t for t in project["targets"] if t["name"] == "Mesh")
    two = lists.get("mat two-sided") or [0] * len(lists.get("mat colors", []))
    export = export or {"names": {}}
    report = {"config": {"export": export}, "materials": [{"double_sided": bool(x)} for x in two]}
    mesh = preview.mesh_from_lists(lists, report)
    mesh.backdrop = backdrop.from_project(project, assets)  # what the stage shows where nothing is drawn
    cam = auto_camera(mesh.verts)
    variables = {n: v for n, v in sprite["variables"].values()}
    assert [variables["cam x"], variables["cam yaw"]] == [cam.x, cam.yaw]  # the green flag's camera
    return (*preview.stage_view(mesh, cam), mesh.backdrop)


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    why = turbowarp.unavailable()
    if why:
        pytest.skip(why)
    tmp = tmp_path_factory.mktemp("player")
    projects = []
    assert cli.main(["demo", "--out", str(tmp / "demo"), "--quiet"]) == 0
    projects.append(("demo", tmp / "demo" / "demo.sb3"))
    teapot = CORPUS / "teapot_obj" / "teapot.obj"
    if teapot.exists():
        projects.append(("teapot", bake_to(teapot, tmp / "teapot", TEAPOT)))
        # the lit BSP teapot from soup lists (x, y, z per corner), packed: the walk's ranges over
        # corners, the loader rebuilding split lists
        projects.append(("teapot soup", bake_to(teapot, tmp / "teapot soup",
                                                {**TEAPOT, "export": {**SOUP_XYZ, "pack": True}})))
    suzanne = CORPUS / "suzanne_obj" / "suzanne.obj"
    if suzanne.exists():  # no BSP tree, material colours: the list's order, culled on the stage
        projects.append(("suzanne", bake_to(suzanne, tmp / "suzanne", {})))
        projects.append(("suzanne x y z", bake_to(suzanne, tmp / "suzanne xyz", {"export": PER_COORDINATE})))
    box = CORPUS / "box_textured_gltf_separate" / "BoxTextured.gltf"
    if box.exists():  # textured by default; white and unlit with its texture off (a dark backdrop)
        # the flat filler on a textured model (the textured filler: test_textured.py)
        projects.append(("box", bake_to(box, tmp / "box", {"export": {"texel_size": 0}})))
        projects.append(("white box", bake_to(box, tmp / "white", {"textures": {"enabled": False}})))
    run = turbowarp.run(projects, modes=("compiled", "interpreted"), repeat=1)
    return {"run": run, "projects": dict(projects), "previews": {k: _preview(p, LAYOUTS.get(k)) for k, p in projects}}


def test_every_project_runs_without_errors_and_draws(played):
    run = played["run"]
    assert run.versions["@turbowarp/packager"] == "3.13.0"
    assert len(run.results) == 2 * len(played["projects"])
    for r in run.results:
        assert r.problems() == [], f"{r.id} {r.mode}: {r.problems()}"
        assert r.stage == (480, 360) and r.image.shape == (360, 480, 3)
        assert r.runs[0]["seconds"] > 0


def test_turbowarp_applies_the_projects_settings_comment(played):
    """The fresh .sb3 stores fencing = false as TurboWarp's settings comment (export.turbowarp_fencing,
    default false): TurboWarp's runtime must have it in force, its other options untouched."""
    for r in played["run"].results:
        assert r.runtime_options.get("fencing") is False, f"{r.id} {r.mode}: {r.runtime_options}"
        assert r.runtime_options.get("maxClones") == 300  # Scratch's clone limit: still TurboWarp's default


def test_the_stage_agrees_with_the_green_flag_preview(played):
    for r in played["run"].results:
        view, painter, bg = played["previews"][r.id]
        a = preview.stage_agreement(r.image, view, painter, background=bg)
        assert a["interior_pixels"] > 100 and a["covered_inner_pixels"] > 5000, a
        assert a["within_1"] == 1.0, f"{r.id} {r.mode}: {a}"
        assert a["covered_within_1"] >= COVERED_WITHIN_1, f"{r.id} {r.mode}: {a}"
        assert a["interior_left_blank"] == 0 and a["empty_painted"] == 0, f"{r.id} {r.mode}: {a}"


def test_an_unlit_white_model_shows_on_its_stage(played):
    """White triangles, unlit: the stage's backdrop is dark, and TurboWarp's stage shows the box
    (on the white stage it was blank: every pixel 255)."""
    if "white box" not in played["projects"]:
        pytest.skip("the corpus's BoxTextured.gltf is not there")
    _, painter, bg = played["previews"]["white box"]
    assert bg == backdrop.DARK
    for mode in ("compiled", "interpreted"):
        img = played["run"].get("white box", mode).image
        far = np.abs(img.astype(int) - np.asarray(bg)).max(axis=2) > 100
        assert far.mean() > 0.2 and far[painter.tri_id >= 0].mean() > 0.95, mode


def test_compiled_and_interpreted_draw_the_same_picture(played):
    run = played["run"]
    for pid in played["projects"]:
        a, b = run.get(pid, "compiled").image, run.get(pid, "interpreted").image
        assert np.array_equal(a, b), f"{pid}: {(a != b).any(2).sum()} pixels differ"


def test_a_mirrored_or_shifted_stage_fails_the_agreement(played):
    """The check can fail: the teapot's spout is on the right; mirrored, it is not."""
    pid = "teapot" if "teapot" in played["projects"] else "demo"
    r = played["run"].get(pid, "compiled")
    view, painter, bg = played["previews"][pid]
    for bad in (np.ascontiguousarray(r.image[:, ::-1]), np.roll(r.image, 3, axis=1)):
        a = preview.stage_agreement(bad, view, painter, background=bg)
        assert a["covered_within_1"] < COVERED_WITHIN_1 or a["within_1"] < 1.0 or a["empty_painted"] > 0


def test_problems_are_reported(tmp_path):
    """A script that never stops, a blank stage and a missing asset are each reported."""
    why = turbowarp.unavailable()
    if why:
        pytest.skip(why)
    stage = sb3.Target("Stage", is_stage=True)
    s = B.Scope("S", variables=["n"])
    b = B.Builder(s)
    b.when_flag([B.forever([B.change_var("n", 1)])])
    forever, _ = sb3.write_sb3([stage, sb3.Target("S", variables={"n": 0}, blocks=b.build(), layer_order=1)])
    blank, _ = sb3.write_sb3([stage, sb3.Target("S", layer_order=1)])
    (tmp_path / "forever.sb3").write_bytes(forever)
    (tmp_path / "blank.sb3").write_bytes(blank)
    # an .sb3 whose sprite costume is missing from the archive: refused before packaging (the
    # packager would download it), reported
    import io
    import zipfile

    src = zipfile.ZipFile(io.BytesIO(blank))
    with zipfile.ZipFile(tmp_path / "missing.sb3", "w") as z:
        project = json.loads(src.read("project.json"))
        keep = {c["md5ext"] for c in project["targets"][0]["costumes"]}
        for name in src.namelist():
            if name == "project.json" or name in keep:
                z.writestr(name, src.read(name))
        gone = project["targets"][1]["costumes"][0]["md5ext"]
        assert gone not in keep
    run = turbowarp.run([tmp_path / "forever.sb3", tmp_path / "blank.sb3", tmp_path / "missing.sb3"],
                        modes=("compiled",), timeout_ms=3000)
    fv, bl, mi = run.results
    assert not fv.done and any("still running" in p for p in fv.problems())
    assert bl.done and bl.errors == [] and bl.problems() == ["the stage is blank"]
    assert any("asset missing from the archive" in e and gone in e for e in mi.errors), mi.errors
    assert mi.runs == [] and mi.problems()


def test_an_unsafe_frame_draws_the_usable_triangles(played, tmp_path):
    """The green-flag frame made unsafe in TurboWarp: the camera's focal length 30 times the green
    flag's and turned 24 degrees left, so that the model's picture reaches far beyond 4000 pixels
    to the right while its left silhouette crosses the stage. ``_safe`` is false, vertices beyond
    the pen's reach are marked through their screen x, and the stage, compiled and interpreted
    alike, agrees with the preview of exactly the triangles ``readers.drawn`` says the reader
    fills (a triangle drawn with a marked corner paints the empty part of the stage)."""
    import dataclasses
    import zipfile

    from bake.scratch import readers

    pid = "teapot" if "teapot" in played["projects"] else "demo"
    project, assets = sb3.load_project(played["projects"][pid])
    bg = backdrop.from_project(project, assets)
    lists = {n: items for t in project["targets"] for n, items in (t.get("lists") or {}).values()}
    cam = auto_camera(lists["verts"])
    cam = dataclasses.replace(cam, focal=cam.focal * 30, yaw=cam.yaw - 24)
    px, py, pz = readers.project(np.asarray(lists["verts"], np.float64).reshape(-1, 3), cam)
    ok = readers.usable(px, py, pz, cam.near, cam.focal)
    assert not readers.safe_frame(cam, readers.bounding_sphere(lists["verts"])) and (~ok).any() and ok.any()
    # the same project with the Mesh sprite's focal variable and the green flag's yaw changed
    src = zipfile.ZipFile(played["projects"][pid])
    sprite = next(t for t in project["targets"] if t["name"] == "Mesh")
    for v in sprite["variables"].values():
        if v[0] == "focal":
            v[1] = cam.focal
    sets = [b for b in sprite["blocks"].values() if isinstance(b, dict) and b["opcode"] == "data_setvariableto"
            and b["fields"]["VARIABLE"][0] == "cam yaw"]
    assert len(sets) == 1
    sets[0]["inputs"]["VALUE"] = [1, [10, repr(cam.yaw)]]
    path = tmp_path / "unsafe.sb3"
    with zipfile.ZipFile(path, "w") as z:
        for name in src.namelist():
            z.writestr(name, sb3.dumps(project) if name == "project.json" else src.read(name))
    run = turbowarp.run([("unsafe", path)], modes=("compiled", "interpreted"),
                        read={"target": "Mesh", "variables": ["_safe", "cam yaw", "focal"]})
    # the preview of the drawn triangles only: the others collapsed to their first corner (no
    # area, and the tree's triangle numbers stay)
    two = lists.get("mat two-sided") or []
    keep = readers.drawn(lists["verts"], lists["tris"], cam, two)
    assert keep.any() and not keep.all()
    t = np.asarray(lists["tris"], np.int64).reshape(-1, 4).copy()
    t[~keep, 1] = t[~keep, 2] = t[~keep, 0]
    sub = dict(lists, tris=[int(x) for x in t.ravel()])
    report = {"config": {"export": {"names": {}}},
              "materials": [{"double_sided": bool(x)} for x in (two or [0] * len(lists.get("mat colors", [])))]}
    mesh = preview.mesh_from_lists(sub, report)
    mesh.backdrop = bg
    view, painter = preview.stage_view(mesh, cam)
    assert 0.1 < (painter.tri_id < 0).mean() < 0.9  # both model and empty stage in view
    for r in run.results:
        assert r.problems() == [], f"{r.mode}: {r.problems()}"
        assert str(r.variables.get("_safe")).lower() in ("false", "0"), r.variables
        assert float(r.variables["cam yaw"]) == cam.yaw and float(r.variables["focal"]) == cam.focal
        a = preview.stage_agreement(r.image, view, painter, background=bg)
        assert a["interior_pixels"] > 1000, a
        assert a["within_1"] == 1.0 and a["interior_left_blank"] == 0 and a["empty_painted"] == 0, f"{r.mode}: {a}"
    assert np.array_equal(run.get("unsafe", "compiled").image, run.get("unsafe", "interpreted").image)
