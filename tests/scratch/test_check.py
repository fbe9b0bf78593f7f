"""`bake check PROJECT.sb3`: the bytes of every list, blocks and assets, against the limits."""

import json

from bake import cli
from bake.scratch import sb3
from bake.scratch.check import check


def write(tmp_path, lists, name="p.sb3"):
    data, pj = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists), sb3.Target("S")])
    p = tmp_path / name
    p.write_bytes(data)
    return p, pj


def test_rows_match_the_project(tmp_path):
    p, pj = write(tmp_path, {"big": list(range(1000)), "small": [1, 2, 3]})
    rep = check(p)
    assert rep["project_json_bytes"] == pj and rep["problems"] == []
    rows = {r["name"]: r for r in rep["items"] if r["kind"] == "list"}
    assert rows["big"]["items"] == 1000 and rows["small"]["items"] == 3
    # a list's bytes are its "id":["name",[items]] entry in project.json
    assert rows["big"]["bytes"] == len(json.dumps(list(range(1000)), separators=(",", ":"))) + \
        len('"":["big",]') + 20
    assert rep["items"][0]["name"] == "big"  # biggest first
    assert all(lim["ok"] for lim in rep["limits"])


def test_limits_and_exit_codes(tmp_path, capsys):
    p, _ = write(tmp_path, {"huge": [0] * 200_001})
    rep = check(p)
    bad = [lim["name"] for lim in rep["limits"] if not lim["ok"]]
    assert bad == ["list 'huge' (Stage) items"]
    assert cli.main(["check", str(p)]) == 0
    out = capsys.readouterr().out
    assert "LIMIT EXCEEDED: list 'huge' (Stage) items" in out and "list 'huge'" in out
    assert cli.main(["check", str(p), "--strict"]) == 4
    bad_zip = tmp_path / "bad.sb3"
    bad_zip.write_bytes(b"PK\x03\x04 not really")
    assert cli.main(["check", str(bad_zip)]) == 3
    assert "bad.sb3" in capsys.readouterr().err
