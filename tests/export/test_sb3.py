"""Scratch archives: what we write validates, is deterministic, and untrusted archives are read safely."""

import hashlib
import io
import json
import zipfile

import pytest

from bake.errors import InputError
from bake.export import sb3


def lists():
    return {"verts": [0, 1.5, -2, 3], "names": ["a", "b,c", "\"q"]}


def test_written_project_validates_and_round_trips(tmp_path):
    data, pj_bytes = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists()), sb3.Target("Mesh")])
    p = tmp_path / "x.sb3"
    p.write_bytes(data)
    project, assets = sb3.load_project(p)
    assert sb3.validate_project(project, assets) == []
    stage = project["targets"][0]
    assert {v[0]: v[1] for v in stage["lists"].values()} == lists()
    assert len(json.dumps(project, separators=(",", ":"), ensure_ascii=False).encode()) == pj_bytes
    for c in stage["costumes"]:
        assert hashlib.md5(assets[c["md5ext"]]).hexdigest() == c["assetId"]


def test_deterministic_bytes():
    a = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists())])[0]
    b = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists())])[0]
    assert a == b


def test_sprite3_validates(tmp_path):
    p = tmp_path / "m.sprite3"
    p.write_bytes(sb3.write_sprite3(sb3.Target("Mesh", lists=lists())))
    entries = sb3.read_archive(p)
    sprite = json.loads(entries.pop("sprite.json"))
    assert sb3.validate_sprite(sprite, entries) == []
    assert sprite["isStage"] is False and sprite["name"] == "Mesh"


def test_validator_reports_every_problem():
    project = sb3.project_json([sb3.Target("Stage", is_stage=True, lists={"a": [1, float("nan")]}),
                                sb3.Target("S", lists={"b": [[1]]})])
    project["targets"][1]["costumes"] = []
    project["targets"][0]["costumes"][0]["assetId"] = "xyz"
    project["meta"]["semver"] = "2.0.0"
    problems = sb3.validate_project(project, assets={})
    text = "\n".join(problems)
    assert "semver" in text and "assetId" in text and "needs at least one costume" in text
    assert "nan" in text and "[1]" in text and len(problems) >= 5


def _zip(entries, tmp_path, name="in.sb3", compress=zipfile.ZIP_DEFLATED):
    p = tmp_path / name
    with zipfile.ZipFile(p, "w", compression=compress) as z:
        for n, d in entries.items():
            z.writestr(n, d)
    return p


def test_untrusted_archives_refused_with_the_limit_named(tmp_path):
    with pytest.raises(InputError, match="outside the archive root"):
        sb3.read_archive(_zip({"../evil.txt": b"x", "project.json": b"{}"}, tmp_path))
    bomb = _zip({"project.json": b"{}", "big.bin": b"\0" * (8 << 20)}, tmp_path, "bomb.sb3")
    with pytest.raises(InputError, match="compression ratio"):
        sb3.read_archive(bomb)
    with pytest.raises(InputError, match="entries"):
        sb3.read_archive(_zip({f"{i}.txt": b"" for i in range(20)}, tmp_path, "many.sb3"), max_entries=10)
    notzip = tmp_path / "no.sb3"
    notzip.write_bytes(b"not a zip")
    with pytest.raises(InputError, match="not a Scratch project archive"):
        sb3.read_archive(notzip)
    with pytest.raises(InputError, match="uncompresses"):
        sb3.read_archive(_zip({"a": b"1" * 1000, "b": b"2" * 1000}, tmp_path, "t.sb3"), max_total=1500)


def test_project_in_subfolder_is_found(tmp_path):
    p = _zip({"proj/project.json": json.dumps(sb3.project_json([sb3.Target("Stage", is_stage=True)])),
              "proj/" + sb3.Asset(sb3.BACKDROP_SVG, "svg").md5ext: sb3.BACKDROP_SVG}, tmp_path)
    project, assets = sb3.load_project(p)
    assert sb3.validate_project(project, assets) == []
