"""Which materials are two-sided is a documented list, ``mat two-sided`` (issue 17, item 2):
one item per material in ``mat colors`` order, 1 two-sided, 0 single-sided."""

from __future__ import annotations

import io
import json
import zipfile

import numpy as np

from bake import config as config_mod
from bake.config import ExportConfig
from bake.export.stage import stage
from bake.pipeline import run
from bake.scene import Material, make_scene


def _scene(flags):
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], float)
    tris = np.array([[0, 1, 2], [1, 3, 2], [0, 2, 1]])
    mats = tuple(Material(f"m{i}", color=(0.5, 0.5, 0.5, 1.0), double_sided=f) for i, f in enumerate(flags))
    return make_scene(pos, tris, materials=mats, tri_material=np.arange(3) % len(flags))


def _lists(scene, **kw):
    out, _ = stage(scene, ExportConfig(sb3=False, sprite3=False, **kw))
    files = out.artefacts.outputs
    doc = json.loads(files["lists.json"])
    return files, doc


def test_two_sided_materials_are_a_list_in_lists_and_lists_json():
    files, doc = _lists(_scene([False, True, False]))
    assert doc["lists"]["mat two-sided"] == [0, 1, 0]
    assert len(doc["lists"]["mat two-sided"]) == len(doc["lists"]["mat colors"])
    assert doc["info"]["mat two-sided"]["stride"] == 1 and "two-sided" in doc["info"]["mat two-sided"]["doc"]
    assert files["lists/mat_two-sided.txt"] == b"0\n1\n0"


def test_written_when_asked_or_when_it_matters_only():
    _, doc = _lists(_scene([False, False, False]))
    assert "mat two-sided" not in doc["lists"]  # no two-sided material, no BSP: all single-sided
    _, doc = _lists(_scene([False, False]), two_sided="yes")
    assert doc["lists"]["mat two-sided"] == [0, 0]
    _, doc = _lists(_scene([True]), two_sided="no")
    assert "mat two-sided" not in doc["lists"]
    _, doc = _lists(_scene([True, False]), names=config_mod.ListNames(two_sided="sides"))
    assert doc["lists"]["sides"] == [1, 0]


def test_a_bsp_bake_writes_it_and_the_reader_sprite_reads_the_exported_list(tmp_path):
    obj = tmp_path / "m.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    cfg = config_mod.load(None, ["bsp.enabled=true"])
    cfg.input.path = str(obj)
    res = run(cfg)
    files = res.scene.artefacts.outputs
    assert json.loads(files["lists.json"])["lists"]["mat two-sided"] == [0]
    pj = json.loads(zipfile.ZipFile(io.BytesIO(files["m.sb3"])).read("project.json"))
    stage_lists = [v[0] for t in pj["targets"] if t["isStage"] for v in t["lists"].values()]
    sprite_lists = [v[0] for t in pj["targets"] if not t["isStage"] for v in t["lists"].values()]
    assert "mat two-sided" in stage_lists and "mat two-sided" not in sprite_lists  # one copy, ours
