"""The reader sprite as data (no VM): complete, valid, deterministic, and refusing what cannot work."""

from __future__ import annotations

import json

import pytest

from bake.bvh.traverse import BARY_HI, BARY_LO
from bake.scratch import sb3
from bake.scratch import blocks as B
from bake.scratch import readers
from bake.scratch.project import auto_camera, look_at
from bake.scratch.textimage import ALPHABET

DATA = {"verts": [0, 0, 0, 1, 0, 0, 0, 1, 0], "tris": [1, 2, 3, 1], "mat colors": [255],
        "bvh nodes": [0], "bvh tris": [0] * 9, "bvh tri ids": [1]}


def _procs(target):
    return {b["mutation"]["proccode"] for b in target.blocks.values()
            if isinstance(b, dict) and b["opcode"] == "procedures_prototype"}


@pytest.mark.parametrize("layout", ["binary", "wide4", "quantised"])
def test_reader_is_complete_valid_and_deterministic(layout):
    spec = readers.ReaderSpec(mesh=readers.MeshNames(tri_colors=None), textimage=True, helpers=True,
                              bvh=readers.BVHSpec(bary=(BARY_LO, BARY_HI), layout=layout, bits=4),
                              bounds=readers.bounding_sphere(DATA["verts"]))
    a = readers.reader_target(spec, "Reader", stage_lists=list(DATA), demo=True)
    b = readers.reader_target(spec, "Reader", stage_lists=list(DATA), demo=True)
    assert json.dumps(a.to_json()) == json.dumps(b.to_json())
    assert _procs(a) >= {"load triangle %s", "project vertices", "render", "bvh ray %s %s %s %s %s %s",
                         "decode textimage %s"}
    data, pj = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=DATA), a])
    project, assets = sb3.load_project(data)
    assert sb3.validate_project(project, assets, project_json_bytes=pj) == []
    sprite = project["targets"][1]
    # one costume per TextImage character, in alphabet order (costume k + 1 is character k, which
    # the decoders rely on), sharing one asset, then the pen's fence costume
    assert [c["name"] for c in sprite["costumes"]] == list(ALPHABET) + ["fence"]
    assert len({c["md5ext"] for c in sprite["costumes"][:-1]}) == 1 and len(assets) == 3
    # the reader's own names never take a data list's name
    own = {v[0] for v in sprite["lists"].values()} | {v[0] for v in sprite["variables"].values()}
    assert not own & set(DATA)
    # every list it reads is the stage's (same id)
    stage_ids = {v[0]: k for k, v in project["targets"][0]["lists"].items()}
    for blk in sprite["blocks"].values():
        f = blk.get("fields", {}).get("LIST") if isinstance(blk, dict) else None
        if f and f[0] in stage_ids:
            assert f[1] == stage_ids[f[0]]


def test_reader_parts_follow_the_spec():
    only_ti = readers.reader_target(readers.ReaderSpec(mesh=None, bvh=None, textimage=True), "R")
    procs = _procs(only_ti)
    assert "decode textimage %s" in procs and all(p.startswith("_ti ") for p in procs - {"decode textimage %s"})
    no_ti = readers.reader_target(readers.ReaderSpec(mesh=readers.MeshNames(tri_colors=None)), "R", local_lists=DATA)
    assert "decode textimage %s" not in _procs(no_ti) and [c.name for c in no_ti.costumes] == ["fence"]
    assert {"bvh nodes", "verts"} <= set(no_ti.lists)  # local data lists (the .sprite3 case)
    assert not any(p.startswith(("bvh", "_bvh", "bsp", "load triangle")) for p in _procs(no_ti))
    # one BVH layout: the quantised reader has no binary walk's per-node box test
    quant = readers.reader_target(readers.ReaderSpec(mesh=None, bvh=readers.BVHSpec(bary=(BARY_LO, BARY_HI))), "R",
                                  local_lists=DATA)
    binary = readers.reader_target(readers.ReaderSpec(mesh=None, bvh=readers.BVHSpec(bary=(BARY_LO, BARY_HI),
                                                                                     layout="binary")), "R",
                                   local_lists=DATA)
    assert "_bvh box at %s" in _procs(binary) and len(binary.blocks) < len(quant.blocks)
    # parts added by other modules are generated after the built-in ones, and run at the green flag
    def part(r):
        r.define("hello", [], [r.set("greeting", 1)])
        r.at_flag([B.call("hello")])
    extra = readers.reader_target(readers.ReaderSpec(mesh=readers.MeshNames(tri_colors=None), parts=[part]), "R",
                                  local_lists=DATA, demo=True)
    assert "hello" in _procs(extra) and "greeting" in extra.variables


def test_reader_refuses_lists_that_are_not_there():
    with pytest.raises(B.BlockError, match="not in the project: verts, tris"):
        readers.reader_target(readers.ReaderSpec(), "R", stage_lists=["mat colors", "tri colors"])


def test_cameras_look_at_the_model():
    verts = [[0, 0, 0], [2, 1, 4], [-1, 3, 2]]
    cam = auto_camera(verts)
    px, py, pz = readers.project(verts, cam)
    assert (pz > 0).all() and (abs(px) < 240).all() and (abs(py) < 180).all()
    c = look_at([5, 5, 5], [1, 2, 3])
    x, y, z = readers.project([[1, 2, 3]], c)
    assert abs(x[0]) < 0.5 and abs(y[0]) < 0.5 and z[0] > 0  # the target lands mid-stage


def test_scratch_trig_rounds_like_scratch():
    # parseFloat(Math.sin(pi * n / 180).toFixed(10)): 30 degrees is exactly 0.5, 180 gives 0
    assert readers.scratch_sin(30) == 0.5 and readers.scratch_sin(180) == 0.0 and readers.scratch_cos(90) == 0.0
    assert readers.scratch_cos(60) == 0.5 and readers.scratch_sin(-30) == -0.5
