"""The engine check of ``export.into`` (bake/scratch/engine.py, issue 39 item 2): small engines
written here, in code, each with one way a merge leaves it broken; the bake says so (a warning
naming the lists, exit 4 under --strict) and reports which blocks read each list, and the
author's file is never changed."""

from __future__ import annotations

import json


from bake import cli
from bake.scratch import blocks as B
from bake.scratch import engine, sb3
from conftest import corpus_path

MODEL = corpus_path("cube_quads_mtl", "cube.obj")


def _write(path, stage_lists, sprite_lists, script, *, sprite_vars=("i",)):
    scope = B.Scope("Engine", variables=list(sprite_vars), stage_lists=list(stage_lists),
                    lists=list(sprite_lists))
    b = B.Builder(scope)
    b.when_flag(script)
    stage = sb3.Target("Stage", is_stage=True, lists=dict(stage_lists))
    sprite = sb3.Target("Engine", variables={v: 0 for v in sprite_vars}, lists=dict(sprite_lists),
                        blocks=b.build(), layer_order=1)
    path.write_bytes(sb3.write_sb3([stage, sprite])[0])
    return path


def _bake(tmp_path, engine_path, *sets, strict=False):
    out = tmp_path / "out"
    args = ["run", str(MODEL), "--out", str(out), "--quiet", "--set", f'export.into="{engine_path.as_posix()}"']
    for s in sets:
        args += ["--set", s]
    code = cli.main(args + (["--strict"] if strict else []))
    rep = json.loads((out / "report.json").read_text()) if (out / "report.json").exists() else None
    return code, rep


def _export(rep):
    return next(s for s in rep["stages"] if s["name"] == "export")


def _draw_xyz():
    """Reads X, Y and Z in step (a per-coordinate engine)."""
    return [B.set_var("i", 1),
            B.repeat(B.list_length("X"), [B.goto_xy(B.item(B.var("i"), "X"), B.item(B.var("i"), "Y")),
                                          B.change_var("i", B.item(B.var("i"), "Z")), B.change_var("i", 1)])]


def test_parallel_lists_left_behind_are_named(tmp_path):
    eight = list(range(8))
    path = _write(tmp_path / "xyz.sb3", {"X": eight, "Y": eight, "Z": eight, "neighbours": eight}, {}, _draw_xyz())
    before = path.read_bytes()
    code, rep = _bake(tmp_path, path, 'export.names.vertices="X"')
    assert code == 0 and path.read_bytes() == before
    eng = _export(rep)["details"]["into"]["engine"]
    assert eng["parallel"] == {"X": ["Y", "Z", "neighbours"]}
    assert eng["lists"]["X"]["read_by"] == [{"sprite": "Engine", "blocks": 2}] and eng["lists"]["X"]["replaced"]
    assert rep["engine"] == eng  # report.json's engine section
    page = (tmp_path / "out" / "report.html").read_text()
    assert "Your engine: which blocks read the lists" in page and "Engine (2 blocks)" in page
    warned = [w for w in _export(rep)["warnings"] if "beside it" in w]
    assert len(warned) == 1 and all(f"'{n}'" in warned[0] for n in ("Y", "Z", "neighbours"))
    # the same under --strict is a problem: exit 4
    code, _ = _bake(tmp_path, path, 'export.names.vertices="X"', strict=True)
    assert code == 4


def test_split_vertex_lists_replace_x_y_z_and_name_only_the_lists_left_beside_them(tmp_path):
    """export.names.vertices = ["X", "Y", "Z"] writes all three coordinates: the engine's per-vertex
    colour and size lists, of the old length, are the parallel lists left behind; Y and Z are not."""
    five = list(range(5))  # (the cube has 8 vertices)
    path = _write(tmp_path / "xyz.sb3", {"X": five, "Y": five, "Z": five, "colour": five, "size": five}, {},
                  _draw_xyz() + [B.set_var("i", B.item(1, "colour")), B.set_var("i", B.item(1, "size"))])
    code, rep = _bake(tmp_path, path, 'export.names.vertices=["X", "Y", "Z"]')
    eng = _export(rep)["details"]["into"]["engine"]
    assert code == 0 and eng["parallel"] == {"X": ["colour", "size"], "Y": ["colour", "size"],
                                             "Z": ["colour", "size"]}
    assert all(eng["lists"][n]["replaced"] for n in "XYZ") and "X" not in eng["unread"]
    warned = [w for w in _export(rep)["warnings"] if "beside it" in w]
    assert warned and all("'colour'" in w and "'size'" in w and "'Y'" not in w.split("beside")[1] for w in warned)


def test_numbers_written_over_text_records_are_named(tmp_path):
    """Seen in a public renderer: its 'Model' list holds one JSON array per vertex, which its
    blocks parse; a soup baked into it is read by name and replaced, but holds bare numbers the
    engine cannot parse. The check says so; numbers over numbers say nothing."""
    records = ['["1","2","3","0","0",0,1,0]', '["4","5","6","1","0",0,1,0]']
    path = _write(tmp_path / "records.sb3", {"Model": records, "verts": ["1", "2.5", ""]}, {},
                  [B.set_var("i", B.item(1, "Model")), B.set_var("i", B.item(1, "verts"))])
    code, rep = _bake(tmp_path, path, 'export.names.triangles="Model"', "export.faces=\"soup\"")
    eng = _export(rep)["details"]["into"]["engine"]
    assert code == 0 and eng["text_replaced"] == {"Model": records[0]}
    line = next(w for w in _export(rep)["warnings"] if "held text items" in w)
    assert "'Model'" in line and "'verts'" not in line
    code, _ = _bake(tmp_path, path, 'export.names.triangles="Model"', "export.faces=\"soup\"", strict=True)
    assert code == 4


def test_a_list_no_block_reads_is_named_and_a_read_one_is_not(tmp_path):
    path = _write(tmp_path / "points.sb3", {"verts": [1, 2, 3]}, {},
                  [B.set_var("i", B.item(1, "verts"))])
    code, rep = _bake(tmp_path, path)
    eng = _export(rep)["details"]["into"]["engine"]
    assert "verts" not in eng["unread"] and "tris" in eng["unread"] and "mat colors" in eng["unread"]
    line = next(w for w in _export(rep)["warnings"] if "no block of the project reads" in w)
    assert "'tris'" in line and "'verts'" not in line
    # with the reader sprite added, the lists are read (by it): nothing to say
    code, rep = _bake(tmp_path, path, "export.into_reader=true")
    assert _export(rep)["details"]["into"]["engine"]["unread"] == []
    assert not any("no block of the project reads" in w for w in _export(rep)["warnings"])


def test_a_green_flag_delete_all_before_any_read_is_named(tmp_path):
    path = _write(tmp_path / "wipe.sb3", {"verts": [1, 2, 3]}, {},
                  [B.delete_all("verts"), B.set_var("i", B.list_length("verts"))])
    code, rep = _bake(tmp_path, path)
    eng = _export(rep)["details"]["into"]["engine"]
    assert eng["emptied_at_start"] == [{"sprite": "Engine", "list": "verts"}]
    assert any("empties 'verts'" in w for w in _export(rep)["warnings"])
    # read first, emptied after: the engine saw the items; nothing to say
    path = _write(tmp_path / "late.sb3", {"verts": [1, 2, 3]}, {},
                  [B.set_var("i", B.list_length("verts")), B.delete_all("verts")])
    code, rep = _bake(tmp_path, path)
    assert _export(rep)["details"]["into"]["engine"]["emptied_at_start"] == []


def _broadcast_project() -> dict:
    """A green flag that broadcasts "setup"; the receiver empties verts; another script reads it."""
    flag = {"opcode": "event_whenflagclicked", "next": "b", "parent": None, "inputs": {}, "fields": {},
            "shadow": False, "topLevel": True, "x": 0, "y": 0}
    send = {"opcode": "event_broadcastandwait", "next": "r", "parent": "f",
            "inputs": {"BROADCAST_INPUT": [1, [11, "setup", "m1"]]}, "fields": {}, "shadow": False,
            "topLevel": False}
    read = {"opcode": "data_lengthoflist", "next": None, "parent": "b", "inputs": {},
            "fields": {"LIST": ["verts", "L1"]}, "shadow": False, "topLevel": False}
    hat = {"opcode": "event_whenbroadcastreceived", "next": "d", "parent": None, "inputs": {},
           "fields": {"BROADCAST_OPTION": ["setup", "m1"]}, "shadow": False, "topLevel": True, "x": 0, "y": 200}
    wipe = {"opcode": "data_deletealloflist", "next": None, "parent": "h", "inputs": {},
            "fields": {"LIST": ["verts", "L1"]}, "shadow": False, "topLevel": False}
    stage = {"isStage": True, "name": "Stage", "lists": {"L1": ["verts", [1, 2, 3]]},
             "broadcasts": {"m1": "setup"}, "blocks": {}}
    sprite = {"isStage": False, "name": "Engine", "lists": {},
              "blocks": {"f": flag, "b": send, "r": read, "h": hat, "d": wipe}}
    return {"targets": [stage, sprite]}


def test_the_check_follows_broadcasts_in_the_order_they_run():
    proj = _broadcast_project()
    found = engine.check(proj, "Stage", {"verts": 24}, reader_added=False)
    assert found["emptied_at_start"] == [{"sprite": "Engine", "list": "verts"}]
    assert found["lists"]["verts"]["read_by"] == [{"sprite": "Engine", "blocks": 1}]
    assert found["lists"]["verts"]["emptied_by"] == [{"sprite": "Engine", "blocks": 1}]
    # the read before the broadcast: the engine saw the items first
    blocks = proj["targets"][1]["blocks"]
    blocks["f"]["next"], blocks["r"]["next"], blocks["b"]["next"] = "r", "b", None
    assert engine.check(proj, "Stage", {"verts": 24}, reader_added=False)["emptied_at_start"] == []


def test_a_sprite_list_hides_the_stage_list_of_its_name():
    proj = _broadcast_project()
    sprite = proj["targets"][1]
    sprite["lists"] = {"S1": ["verts", [9]]}
    for b in sprite["blocks"].values():
        if "LIST" in b["fields"]:
            b["fields"]["LIST"] = ["verts", "S1"]
    found = engine.check(proj, "Stage", {"verts": 24}, reader_added=False)
    # the engine's blocks use its own 'verts'; the stage list the bake wrote is read by none
    assert found["lists"]["verts"]["read_by"] == [] and found["unread"] == ["verts"]
    assert found["emptied_at_start"] == []


def test_a_clean_merge_says_nothing(tmp_path):
    """The book's interleaved engine reading every list the bake writes: no warning."""
    names = ["verts", "tris", "mat colors"]
    path = _write(tmp_path / "book.sb3", {n: [] for n in names}, {},
                  [B.set_var("i", B.list_length(n)) for n in names])
    code, rep = _bake(tmp_path, path, "export.sb3=false", "export.sprite3=false", strict=True)
    eng = _export(rep)["details"]["into"]["engine"]
    assert code == 0 and eng["warnings"] == [] and eng["parallel"] == {}
    assert {n: eng["lists"][n]["read_by"][0]["blocks"] for n in names} == {n: 1 for n in names}


def test_bake_check_with_a_bakes_lists_checks_an_engine_without_merging(tmp_path, capsys):
    eight = list(range(8))
    path = _write(tmp_path / "xyz.sb3", {"X": eight, "Y": eight, "Z": eight}, {}, _draw_xyz())
    before = path.read_bytes()
    out = tmp_path / "out"
    assert cli.main(["run", str(MODEL), "--out", str(out), "--quiet", "--set", 'export.names.vertices="X"']) == 0
    capsys.readouterr()
    assert cli.main(["check", str(path), "--with", str(out / "lists.json")]) == 0
    text = capsys.readouterr().out
    assert "engine: 'X' read by Engine (2)" in text and "'Y', 'Z' beside it" in text
    assert cli.main(["check", str(path), "--with", str(out / "lists.json"), "--strict"]) == 4
    capsys.readouterr()
    assert cli.main(["check", str(path), "--with", str(out / "lists.json"), "--json"]) == 0
    rep = json.loads(capsys.readouterr().out)
    assert rep["engine"]["parallel"] == {"X": ["Y", "Z"]} and path.read_bytes() == before
    # a file that is not a bake's lists.json, and a sprite that is not there
    (tmp_path / "bad.json").write_text("[1, 2]")
    assert cli.main(["check", str(path), "--with", str(tmp_path / "bad.json")]) == 3
    assert cli.main(["check", str(path), "--with", str(out / "lists.json"), "--into-target", "Nope"]) == 2


def test_a_malformed_project_is_checked_without_hanging_or_crashing():
    """Blocks chained in a circle, fields and inputs of the wrong type, a target that is not an
    object: the check reads what it can."""
    proj = _broadcast_project()
    blocks = proj["targets"][1]["blocks"]
    blocks["r"]["next"] = "b"  # b -> r -> b -> ...
    blocks["d"]["inputs"] = ["not", "a", "dict"]
    blocks["x"] = {"opcode": "data_itemoflist", "fields": "LIST", "topLevel": False}
    proj["targets"].append("not a target")
    found = engine.check(proj, "Stage", {"verts": 24}, reader_added=False)
    assert found["lists"]["verts"]["read_by"] == [{"sprite": "Engine", "blocks": 1}]


def test_a_list_read_through_an_extension_menu_or_named_in_text_is_not_called_unread():
    """Seen in a public TurboWarp renderer (potential1energy/Scratch3D's 3D_Renderer.sb3): its sprite
    hands its 'Model' list to a custom block by name ("Load Vertices | List: Model") and to a JSON
    extension through a list menu holding the list's id. Written here in code, the same shapes."""
    call = {"opcode": "procedures_call", "next": None, "parent": None, "topLevel": True,
            "inputs": {"arg": [1, [10, "Model"]]}, "fields": {},
            "mutation": {"proccode": "Load Vertices | List: %s"}}
    menu = {"opcode": "someJSON_menu_get_list", "next": None, "parent": None, "topLevel": True,
            "inputs": {}, "fields": {"get_list": ["LM", None]}, "shadow": True}
    var = {"opcode": "data_setvariableto", "next": None, "parent": None, "topLevel": True,
           "inputs": {"VALUE": [1, [10, "0"]]}, "fields": {"VARIABLE": ["Model", "V1"]}}
    sprite = {"isStage": False, "name": "Renderer", "lists": {"LM": ["Model", [1, 2, 3]]},
              "blocks": {"c": call, "m": menu, "v": var}}
    proj = {"targets": [{"isStage": True, "name": "Stage", "lists": {}, "blocks": {}}, sprite]}
    found = engine.check(proj, "Renderer", {"Model": 24, "tris": 8}, reader_added=False)
    assert found["lists"]["Model"]["read_by"] == [{"sprite": "Renderer", "blocks": 1}]  # the menu, not the variable
    assert found["lists"]["Model"]["named_by"] == [{"sprite": "Renderer", "blocks": 1}]
    assert found["unread"] == ["tris"]
    del sprite["blocks"]["m"]  # named in text only: not said to be unread either
    assert engine.check(proj, "Renderer", {"Model": 24}, reader_added=False)["unread"] == []
