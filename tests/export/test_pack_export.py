"""The export's list choice (what is written, what is left out and why), first-use vertex order,
and export.pack as the report, `bake check` and `export.into` see it."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bake import cli, config, pipeline
from bake.errors import InputError
from bake.scratch import pack as P
from bake.scratch import sb3
from bake.scratch.check import check
from conftest import corpus_path


def run(model, **sections):
    data = {"input": {"path": str(model)}}
    data.update(sections)
    return pipeline.run(config.load(data=data))


def outputs(res):
    files = res.scene.artefacts.outputs
    lists = json.loads(files["lists.json"])["lists"]
    export = next(r for r in res.records if r.name == "export")
    return files, lists, export


LIT = {"enabled": True, "ambient": [0.2, 0.2, 0.2], "lights": [{"kind": "sun", "direction": [0.3, -1, 0.5]}]}


# --------------------------------------------------------------------------- list choice
def test_lit_bake_writes_triangle_colours_not_both():
    model = corpus_path("suzanne_obj", "suzanne.obj")
    res = run(model, lighting=LIT)
    files, lists, export = outputs(res)
    assert "tri colors" in lists and "vert colors" not in lists
    left = {e["list"]: e for e in export.details["lists_left_out"]}
    assert left["vert colors"]["key"] == "export.vertex_colors" and "tri colors" in left["vert colors"]["reason"]
    md = (cli_report(res))
    assert "## Lists left out" in md and "vert colors" in md and "export.vertex_colors" in md
    # asked for: written, with the same colours the scene has per vertex
    res2 = run(model, lighting=LIT, export={"vertex_colors": "yes"})
    _, lists2, export2 = outputs(res2)
    assert len(lists2["vert colors"]) == len(lists2["verts"]) // 3
    assert not export2.details["lists_left_out"]


def test_vertex_colours_alone_are_written():
    model = corpus_path("cube_vertex_colors_glb", "cubevc.glb")
    _, lists, export = outputs(run(model))
    assert "vert colors" in lists and "tri colors" not in lists
    assert not [e for e in export.details["lists_left_out"] if e["list"] == "vert colors"]


def test_uvs_only_with_a_texture_in_the_project():
    """Duck.glb is textured: with the textures stage off nothing in the project could be sampled,
    so `tri uvs` (60% of its list bytes) is left out and the report says why and how."""
    model = corpus_path("duck_glb", "Duck.glb")
    files, lists, export = outputs(run(model, textures={"enabled": False}))
    assert "tri uvs" not in lists
    left = {e["list"]: e for e in export.details["lists_left_out"]}
    assert "textures.enabled" in left["tri uvs"]["reason"]
    _, lists_t, export_t = outputs(run(model, textures={"enabled": True, "max_size": 8}))
    assert len(lists_t["tri uvs"]) == 6 * (len(lists_t["tris"]) // 4)
    assert not [e for e in export_t.details["lists_left_out"] if e["list"] == "tri uvs"]
    _, lists_y, _ = outputs(run(model, textures={"enabled": False}, export={"uvs": "yes"}))
    assert "tri uvs" in lists_y


def cli_report(res) -> str:
    from bake.outputs import report

    return report.to_markdown(report.build(res))


# --------------------------------------------------------------------------- vertex order
def test_first_use_vertex_order_is_the_same_mesh():
    model = corpus_path("suzanne_obj", "suzanne.obj")
    _, a, _ = outputs(run(model))
    _, b, _ = outputs(run(model, export={"vertex_order": "scene"}))

    def corners(lists):
        v = np.asarray(lists["verts"]).reshape(-1, 3)
        t = np.asarray(lists["tris"]).reshape(-1, 4)
        return [tuple(map(tuple, v[row[:3] - 1])) + (int(row[3]),) for row in t]

    assert corners(a) == corners(b)  # the same triangles, corners and materials in the same order
    assert sorted(a["verts"]) == sorted(b["verts"])
    idx = np.asarray(a["tris"]).reshape(-1, 4)[:, :3].ravel()
    first = np.unique(idx, return_index=True)[1]
    assert np.all(np.diff(idx[np.sort(first)]) == 1) and idx[0] == 1  # vertices numbered by first use
    assert P.index_codes(idx) is not None


# --------------------------------------------------------------------------- packing in the export
def test_pack_keeps_files_plain_and_reports_sizes(tmp_path):
    model = corpus_path("suzanne_obj", "suzanne.obj")
    res = run(model, lighting=LIT, bsp={"enabled": True}, export={"pack": True})
    files, lists, export = outputs(res)
    pk = export.details["pack"]
    names = [r["list"] for r in pk["lists"]]
    assert names == ["verts", "tris", "tri colors", "bsp nodes", "bsp planes"]
    assert pk["packed_bytes"] < 0.5 * pk["plain_bytes"]
    # list files stay plain, the project holds the packed texts
    assert files["lists/verts.txt"].decode().split("\n")[:2] == [repr(x) if isinstance(x, float) else str(x)
                                                               for x in lists["verts"][:2]]
    project, _ = sb3.load_project(files["suzanne.sb3"])
    stage = {e[0]: e[1] for e in project["targets"][0]["lists"].values()}
    assert stage["verts"] == [] and len(stage["packed lists"]) == len(names)
    for name, text in zip(names, stage["packed lists"]):
        assert P.unpack(text, name).items == lists[name]
    # report.json: packed bytes, plain bytes and decode blocks per list
    from bake.outputs import report

    rep = report.build(res)
    assert rep["lists"]["verts"]["packed"]["decode_blocks"] > 0
    assert rep["lists"]["verts"]["bytes"] < rep["lists"]["verts"]["plain_bytes"]
    md = report.to_markdown(rep)
    assert "## Packed lists" in md and "index×3" in md


def test_pack_max_items_leaves_long_lists_plain():
    model = corpus_path("suzanne_obj", "suzanne.obj")
    res = run(model, export={"pack": True, "pack_max_items": 2000})
    _, lists, export = outputs(res)
    packed = {r["list"] for r in export.details["pack"]["lists"]}
    assert "verts" in packed and "tris" not in packed and len(lists["tris"]) > 2000
    why = [e for e in export.effects if e["name"] == "pack 'tris'"][0]["reason"]
    assert "export.pack_max_items" in why and "200,000" in why


def test_bake_check_shows_packed_lists_and_names_bad_ones(tmp_path, capsys):
    model = corpus_path("suzanne_obj", "suzanne.obj")
    files, lists, export = outputs(run(model, export={"pack": True}))
    p = tmp_path / "s.sb3"
    p.write_bytes(files["suzanne.sb3"])
    rep = check(p)
    rows = {r["list"]: r for r in rep["packed"]}
    assert rows["verts"]["items"] == len(lists["verts"])
    assert rep["decode_blocks"] == export.details["pack"]["decode_blocks"]
    assert cli.main(["check", str(p)]) == 0
    assert "packed lists" in capsys.readouterr().out
    # a truncated text: exit 3, one line naming the list
    project, assets = sb3.load_project(p)
    for e in project["targets"][0]["lists"].values():
        if e[0] == "packed lists":
            e[1][1] = e[1][1][:-10]
    bad = tmp_path / "bad.sb3"
    bad.write_bytes(sb3._zip({"project.json": sb3.dumps(project).encode(), **assets}))
    assert cli.main(["check", str(bad)]) == 3
    err = capsys.readouterr().err
    assert "packed list 'tris'" in err and "bad.sb3" in err and len(err.strip().splitlines()) == 1


def test_into_checks_the_projects_packed_texts(tmp_path):
    """export.into reads the author's project: a bad packed text in it (a list this bake does not
    replace) is an error naming the list; a good one is kept."""
    model = corpus_path("cornell_box_tinyobj", "cornell_box.obj")
    other = P.pack("old verts", [1.5, 2.5, 3.5] * 50, 3).text
    for text, ok in ((other, True), (other[:-3], False)):
        proj = tmp_path / ("good.sb3" if ok else "bad.sb3")
        proj.write_bytes(sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists={"engine data": [text]})])[0])
        cfg = {"pack": True, "into": str(proj), "into_name": "out.sb3"}
        if ok:
            files, lists, _ = outputs(run(model, export=cfg))
            project, _ = sb3.load_project(files["out.sb3"])
            stage = {e[0]: e[1] for e in project["targets"][0]["lists"].values()}
            assert stage["engine data"] == [text] and stage["verts"] == []
            assert any(t["name"] == "Mesh" for t in project["targets"])  # the loader sprite came along
        else:
            with pytest.raises(InputError, match="packed list 'old verts'"):
                run(model, export=cfg)


def test_into_a_sprite_stays_plain_and_empties_old_packed_texts(tmp_path):
    model = corpus_path("cornell_box_tinyobj", "cornell_box.obj")
    proj = tmp_path / "engine.sb3"
    proj.write_bytes(sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists={"packed lists": ["x"]}),
                                    sb3.Target("Engine")])[0])
    res = run(model, export={"pack": True, "into": str(proj), "into_target": "Engine", "into_name": "o.sb3"})
    files, lists, export = outputs(res)
    assert any("into_target" in w for w in export.warnings)
    project, _ = sb3.load_project(files["o.sb3"])
    eng = next(t for t in project["targets"] if t["name"] == "Engine")
    assert {e[0]: e[1] for e in eng["lists"].values()}["verts"] == lists["verts"]
    # plain bake into the stage of a project that held packed texts: they are emptied, so an old
    # loader cannot overwrite the fresh lists at the green flag
    res = run(model, export={"into": str(proj), "into_name": "p.sb3"})
    project, _ = sb3.load_project(res.scene.artefacts.outputs["p.sb3"])
    stage = {e[0]: e[1] for e in project["targets"][0]["lists"].values()}
    assert stage["packed lists"] == [] and stage["verts"] == outputs(res)[1]["verts"]


def test_position_error_bound_is_reported_and_holds():
    """report.json's export accuracy: the rounding bound (half the step, over the diagonal), and
    every written coordinate is within it of the scene's."""
    model = corpus_path("suzanne_obj", "suzanne.obj")
    for prec in (2, 4):
        res = run(model, export={"precision": prec, "vertex_order": "scene"})
        _, lists, export = outputs(res)
        pos = export.details["positions"]
        diag = res.scene.scale()
        assert export.accuracy["position_error"] == pytest.approx(pos["max_error"] / diag)
        assert pos["step"] <= diag * 10.0 ** -prec < 10 * pos["step"]
        written = np.asarray(lists["verts"]).reshape(-1, 3)
        err = np.abs(written - res.scene.positions).max()
        assert 0 < err <= pos["max_error"] * (1 + 1e-9)
    from bake.sweep import error_of

    assert error_of("export.precision")[0] == "position_error"
