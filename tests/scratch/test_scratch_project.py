"""Bakes that write Scratch projects, end to end through the CLI, checked in the real VM:

* ``export.into``: an author's engine (its own script reads the global list ``verts``) gets our
  lists; in scratch-vm its script now reads the new data, the reader sprite added next to it reads
  the stage lists, scratch-parser accepts the result; the input file is untouched, listed in the
  depfile, and protected from being overwritten.
* ``bake demo`` writes ``demo.sb3``, whose green flag draws the model with the pen, in the order of
  the BSP walk from its camera.
"""

from __future__ import annotations

import json
import zipfile

import pytest

from bake import cli
from bake.bsp.traverse import draw_ranges
from bake.scratch import readers, sb3
from bake.scratch import blocks as B
from conftest import corpus_path
from vm_harness import call, vm  # noqa: F401


def _engine(path):
    """An author's project: global lists verts/tris with old data; sprite Engine sums verts."""
    scope = B.Scope("Engine", variables=["total", "i"], stage_lists=["verts", "tris"])
    b = B.Builder(scope)
    b.define("sum verts", [], [
        B.set_var("total", 0), B.set_var("i", 1),
        B.repeat(B.list_length("verts"), [B.change_var("total", B.item(B.var("i"), "verts")),
                                          B.change_var("i", 1)]),
    ])
    stage = sb3.Target("Stage", is_stage=True, lists={"verts": [100, 200], "tris": [1, 1, 1, 1]})
    engine = sb3.Target("Engine", variables={"total": 0, "i": 0}, blocks=b.build(), layer_order=1)
    path.write_bytes(sb3.write_sb3([stage, engine])[0])
    return path


def test_bake_into_an_authors_project(tmp_path, vm, capsys):
    model = corpus_path("cube_quads_mtl", "cube.obj")
    proj_dir = tmp_path / "proj"
    proj_dir.mkdir()
    engine = _engine(proj_dir / "engine.sb3")
    original = engine.read_bytes()
    cfg = proj_dir / "bake.toml"
    cfg.write_text(f'[input]\npath = "{model.as_posix()}"\n[bvh]\nenabled = true\n'
                   '[export]\ninto = "engine.sb3"\ninto_reader = true\n')
    out = tmp_path / "out"
    dep = tmp_path / "bake.d"
    assert cli.main(["run", str(cfg), "--out", str(out), "--depfile", str(dep), "--quiet"]) == 0
    merged = out / "engine-cube.sb3"
    assert merged.is_file() and engine.read_bytes() == original
    assert str(engine.resolve()) in dep.read_text()
    rep = json.loads((out / "report.json").read_text())
    export = next(s for s in rep["stages"] if s["name"] == "export")
    with zipfile.ZipFile(merged) as z:
        assert export["details"]["project_json_bytes"] == z.getinfo("project.json").file_size
    pj = next(x for x in rep["limits"] if x["name"].startswith("project.json"))
    assert pj["value"] == export["details"]["project_json_bytes"]

    lists = {name: items for t in sb3.load_project(merged)[0]["targets"]
             for name, items in t.get("lists", {}).values()}
    res = vm({"load": str(merged), "runs": [
        call("Engine", "sum verts", variables=["total"]),
        call("Mesh", "load triangle %s", 2, variables=["x1", "y1", "z1"]),
        call("Mesh", "bvh ray %s %s %s %s %s %s", 0.3, 0.2, -9, 0, 0, 1, variables=["hit tri"]),
    ]})
    assert res["validation"][0]["ok"], res["validation"]
    assert res["runs"][0]["variables"]["total"] == pytest.approx(sum(lists["verts"]))
    v = res["runs"][1]["variables"]
    k = 3 * (lists["tris"][4] - 1)
    assert [v["x1"], v["y1"], v["z1"]] == lists["verts"][k:k + 3]
    assert float(res["runs"][2]["variables"]["hit tri"]) > 0  # a ray through the cube hits it

    # the input can never be the output
    cfg.write_text(f'[input]\npath = "{model.as_posix()}"\n[export]\ninto = "engine.sb3"\n'
                   'into_name = "engine.sb3"\n')
    assert cli.main(["run", str(cfg), "--out", str(proj_dir), "--quiet"]) != 0
    assert "refusing to overwrite" in capsys.readouterr().err
    assert engine.read_bytes() == original
    # a sprite that does not exist is named
    cfg.write_text(f'[input]\npath = "{model.as_posix()}"\n[export]\ninto = "engine.sb3"\ninto_target = "Hero"\n')
    assert cli.main(["run", str(cfg), "--out", str(out), "--quiet"]) == 3
    assert "no sprite named 'Hero'" in capsys.readouterr().err


def test_demo_writes_a_project_that_draws_the_sample(tmp_path, vm):
    out = tmp_path / "bake-demo"
    assert cli.main(["demo", "--out", str(out), "--quiet"]) == 0
    demo = out / "demo.sb3"
    res = vm({"load": str(demo), "runs": [{"greenFlag": True, "pen": True,
                                             "read": {"lists": ["draw ranges"], "variables": ["_safe"]}}]})
    assert res["validation"][0]["ok"]
    run = res["runs"][0]
    assert run["done"]
    project, _ = sb3.load_project(demo)
    lists = {name: items for t in project["targets"] for name, items in t["lists"].values()}
    sprite = next(t for t in project["targets"] if t["name"] == "Mesh")
    cam = {name: value for name, value in sprite["variables"].values()}
    # the sample is baked with a BSP tree: the order is the BSP walk from the green flag's camera
    eye = [cam["cam x"], cam["cam y"], cam["cam z"]]
    want = draw_ranges(lists["bsp nodes"], lists["bsp planes"], eye)
    assert [int(x) for x in run["lists"]["draw ranges"]] == [x for r in want for x in r]
    rcam = readers.Camera(cam["cam x"], cam["cam y"], cam["cam z"], cam["cam yaw"], cam["cam pitch"], cam["focal"],
                          cam["near"])
    shown = readers.drawn(lists["verts"], lists["tris"], rcam)
    assert 0 < shown.sum() < len(lists["tris"]) // 4  # back faces culled
    assert int(float(run["variables"]["_safe"])) == 1  # the green flag's camera frames the model: a safe frame
    strokes = run["pen"]
    xs = [s[0] for s in strokes] + [s[2] for s in strokes]
    ys = [s[1] for s in strokes] + [s[3] for s in strokes]
    # the model fills a good part of the stage and stays on it
    assert len(strokes) > 1000
    assert max(xs) - min(xs) > 150 and max(ys) - min(ys) > 100
    assert -240 <= min(xs) and max(xs) <= 240 and -180 <= min(ys) and max(ys) <= 180
    assert len({tuple(s[5:8]) for s in strokes}) >= 3  # several materials' colours


def test_reader_off_and_reader_needing_the_stage(tmp_path):
    """export.reader = false writes the plain sprite; into_reader with a sprite target is skipped
    with a warning (a sprite cannot read another sprite's lists)."""
    from scratch_models import bake

    model = corpus_path("cube_quads_mtl", "cube.obj")
    res = bake(model, export={"reader": False})
    files = res.scene.artefacts.outputs
    project, _ = sb3.load_project(files["cube.sb3"])
    assert project["targets"][1]["blocks"] == {} and project["extensions"] == []
    sprite, _ = sb3.load_sprite(files["cube.sprite3"])
    assert sprite["blocks"] == {} and {v[0] for v in sprite["lists"].values()} == {"verts", "tris", "mat colors"}

    stage = sb3.Target("Stage", is_stage=True)
    engine = tmp_path / "e.sb3"
    engine.write_bytes(sb3.write_sb3([stage, sb3.Target("Hero", layer_order=1)])[0])
    res = bake(model, export={"into": str(engine), "into_target": "Hero", "into_reader": True})
    export = next(r for r in res.records if r.name == "export")
    assert any("into_reader" in w for w in export.warnings)
    project, _ = sb3.load_project(res.scene.artefacts.outputs["e-cube.sb3"])
    assert [t["name"] for t in project["targets"]] == ["Stage", "Hero"]
    assert {v[0] for v in project["targets"][1]["lists"].values()} == {"verts", "tris", "mat colors"}
    assert engine.resolve() in [p.resolve() for p in res.scene.source.files_read]


def test_turbowarp_fencing_setting_only_in_the_fresh_project(tmp_path):
    """By default the fresh .sb3 stores TurboWarp's settings comment turning fencing off (parsed
    here the way TurboWarp parses it); the .sprite3 and an export.into project never get it, and
    export.turbowarp_fencing = true leaves it out. tests/player/test_turbowarp.py checks that
    TurboWarp itself applies it."""
    from scratch_models import bake

    model = corpus_path("cube_quads_mtl", "cube.obj")
    engine = _engine(tmp_path / "engine.sb3")
    res = bake(model, export={"into": str(engine)})
    files = res.scene.artefacts.outputs
    project, _ = sb3.load_project(files["cube.sb3"])
    stage = project["targets"][0]
    assert sb3.turbowarp_settings(stage["comments"]) == {"runtimeOptions": {"fencing": False}}
    line = stage["comments"][sb3.TW_CONFIG_COMMENT_ID]["text"].split("\n")[-1]
    assert line.endswith(" // _twconfig_") and json.loads(line[:-len(" // _twconfig_")])["runtimeOptions"] == {
        "fencing": False}
    assert all(t["comments"] == {} for t in project["targets"][1:])
    sprite, _ = sb3.load_sprite(files["cube.sprite3"])
    assert sprite["comments"] == {}
    merged, _ = sb3.load_project(files["engine-cube.sb3"])
    assert all(sb3.turbowarp_settings(t.get("comments") or {}) is None for t in merged["targets"])
    res = bake(model, export={"turbowarp_fencing": True})
    project, _ = sb3.load_project(res.scene.artefacts.outputs["cube.sb3"])
    assert project["targets"][0]["comments"] == {}
