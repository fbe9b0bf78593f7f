"""The command line end to end: run, demo, inspect, overrides, exit statuses, determinism."""

import json
import subprocess
import sys

import numpy as np
import pytest

from bake import cli

QUAD_GRID = None


def grid_obj(path, n, mtl=True):
    """An n x n grid of quads in the xz plane, written as an OBJ (+ MTL)."""
    xs = np.linspace(0, 1, n + 1)
    lines = ["mtllib grid.mtl"] if mtl else []
    lines += [f"v {x} 0 {z}" for x in xs for z in xs]
    lines.append("usemtl green")
    i = np.arange(n)[:, None] * (n + 1) + np.arange(n)[None, :] + 1
    quads = np.stack([i, i + 1, i + n + 2, i + n + 1], axis=-1).reshape(-1, 4)
    lines += ["f " + " ".join(map(str, q)) for q in quads.tolist()]
    path.write_text("\n".join(lines))
    if mtl:
        path.with_name("grid.mtl").write_text("newmtl green\nKd 0 1 0\n")
    return path


def run(args, capsys):
    code = cli.main(args)
    out = capsys.readouterr()
    return code, out.out, out.err


def test_run_model_writes_lists_and_report(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 3)
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o")], capsys)
    assert code == 0, err
    assert "grid.obj: 18 triangles, 16 vertices" in out
    rep = json.loads((tmp_path / "o/report.json").read_text())
    assert set(rep) >= {"scene", "stages", "lists", "limits", "effects", "tool", "report_version"}
    assert [s["name"] for s in rep["stages"]] == ["import", "transform", "triangulate", "clean", "export"]
    skipped = {e["name"]: e["reason"] for e in rep["effects"] if not e["ran"]}
    assert skipped["bsp"] == "bsp.enabled = false"
    assert rep["lists"]["mat colors"]["items"] == 1
    assert (tmp_path / "o/lists/mat_colors.txt").read_text() == "65280"
    lists = json.loads((tmp_path / "o/lists.json").read_text())["lists"]
    assert len(lists["verts"]) == 48 and len(lists["tris"]) == 72
    assert "| tris | 72 | 4 |" in (tmp_path / "o/report.md").read_text()


def test_same_input_gives_byte_identical_lists(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 5)
    for d in ("a", "b"):
        assert run(["run", str(model), "--out", str(tmp_path / d), "--quiet"], capsys)[0] == 0
    for rel in ("lists.json", "lists/verts.txt", "lists/tris.txt", "lists/mat_colors.txt"):
        assert (tmp_path / "a" / rel).read_bytes() == (tmp_path / "b" / rel).read_bytes()


def test_quads_option_and_override(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 2)
    code, _, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--quiet",
                        "--set", "export.faces=quads"], capsys)
    assert code == 0, err
    lists = json.loads((tmp_path / "o/lists.json").read_text())["lists"]
    assert len(lists["quads"]) == 4 * 5 and lists["tris"] == []


def test_config_file_and_unknown_key(tmp_path, capsys):
    grid_obj(tmp_path / "grid.obj", 2)
    cfg = tmp_path / "bake.toml"
    cfg.write_text('[input]\npath = "grid.obj"\n[export]\nprecison = 3\n')
    code, _, err = run(["run", str(cfg), "--out", str(tmp_path / "o")], capsys)
    assert code == 2
    assert err.strip() == (f"bake: error: {cfg}:4: key 'export.precison': unknown key; "
                           "did you mean 'export.precision'?")
    assert not (tmp_path / "o").exists()


def test_missing_and_bad_inputs_exit_3_one_line(tmp_path, capsys):
    code, _, err = run(["run", str(tmp_path / "nope.obj")], capsys)
    assert code == 3 and err.count("\n") == 1 and "nope.obj" in err
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 7\n")
    code, _, err = run(["run", str(bad), "--out", str(tmp_path / "o")], capsys)
    assert code == 3 and "bad.obj:4" in err and err.count("\n") == 1
    assert not (tmp_path / "o" / "lists.json").exists()


def test_strict_limit_exit_4_still_writes_report(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 160, mtl=False)  # 51,200 triangles -> 204,800 tris items
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--strict"], capsys)
    assert code == 4, err
    assert "list 'tris' items" in err
    rep = json.loads((tmp_path / "o/report.json").read_text())
    bad = [lim for lim in rep["limits"] if not lim["ok"]]
    assert [lim["name"] for lim in bad] == ["list 'tris' items"]
    code, _, _ = run(["run", str(model), "--out", str(tmp_path / "o"), "--quiet"], capsys)
    assert code == 0  # without --strict an exceeded limit is a warning in the report


def test_all_black_lit_bake_warns_and_strict_exits_4(tmp_path, capsys):
    """Issue 17, item 1: a lit bake with nothing lighting the scene says so in the summary and
    the report, and --strict fails it with exit status 4 (outputs still written)."""
    model = grid_obj(tmp_path / "grid.obj", 3)
    args = ["run", str(model), "--out", str(tmp_path / "o"), "--set", "lighting.enabled=true"]
    code, out, err = run(args, capsys)
    assert code == 0, err
    assert "PROBLEM: every lit colour is black: no light source" in out
    assert "1 PROBLEM(S) (--strict fails the bake)" in out
    rep = json.loads((tmp_path / "o/report.json").read_text())
    assert rep["problems"] == [{"stage": "lighting", "message": rep["problems"][0]["message"]}]
    names = {e["name"]: e for e in rep["effects"]}
    assert not names["lighting.light sources"]["ran"] and names["lighting.all black"]["ran"]
    assert set(json.loads((tmp_path / "o/lists.json").read_text())["lists"]["tri colors"]) == {0}
    code, out, err = run(args + ["--strict"], capsys)
    assert code == 4 and "problem(s) under --strict" in err and "every lit colour is black" in err
    assert (tmp_path / "o/report.json").exists()
    code, out, err = run(args + ["--strict", "--set", "lighting.ambient=[0.5, 0.5, 0.5]"], capsys)
    assert code == 0 and "PROBLEM" not in out, err


def test_inspect(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 3)
    code, out, err = run(["inspect", str(model), "--json"], capsys)
    assert code == 0, err
    data = json.loads(out)
    assert data["polygons_by_size"] == {"4": 9} and data["triangles"] == 18
    assert data["lists"]["tris"]["items"] == 72
    assert data["materials"][0]["name"] == "green"


def test_demo_bakes_bundled_sample(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(["demo", "--quiet"], capsys)
    assert code == 0, err
    rep = json.loads((tmp_path / "bake-demo/report.json").read_text())
    assert rep["scene"]["triangles"] > 500
    assert rep["input"]["path"].endswith("demo_scene.obj")


def test_console_script_and_debug_flag(tmp_path):
    bad = tmp_path / "bad.obj"
    bad.write_text("v 0 0 nan\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    r = subprocess.run([sys.executable, "-m", "bake.cli", "run", str(bad), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True)
    assert r.returncode == 3 and "Traceback" not in r.stderr and "bad.obj:1" in r.stderr
    r = subprocess.run([sys.executable, "-m", "bake.cli", "run", str(bad), "--out", str(tmp_path / "o"), "--debug"],
                       capture_output=True, text=True)
    assert r.returncode == 3 and "Traceback" in r.stderr


def test_sweep_command_writes_table_and_plot(tmp_path, capsys):
    from bake.cli import sample_config_path
    model = sample_config_path().with_name("demo_scene.obj")
    out = tmp_path / "sw"
    sets = ["--set", "lighting.enabled=true", "--set", "lighting.ao.enabled=true"]
    code, _, err = run(["run", str(model), "--out", str(out), "--quiet", *sets], capsys)
    assert code == 0, err
    code, stdout, err = run(["sweep", str(model), "--vary", "lighting.ao.samples=4,16,64", "--out", str(out),
                             *sets], capsys)
    assert code == 0, err
    stem = out / "sweeps" / "lighting.ao.samples"
    table = json.loads(stem.with_suffix(".samples.json").read_text())
    rows = {r["value"]: r for r in table["rows"]}
    assert set(rows) == {4, 16, 64} and rows[64]["rmse"] == 0.0
    assert rows[4]["rmse"] > rows[16]["rmse"] > 0  # error falls with samples against the 64-spp reference
    assert rows[4]["rays"] < rows[16]["rays"] < rows[64]["rays"]
    assert stem.with_suffix(".samples.png").read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"
    assert "updated" in stdout and "report.html" in stdout
    page = (out / "report.html").read_text()
    assert "alt='sweep lighting.ao.samples'" in page  # the bake's report shows the sweep
    code, _, err = run(["sweep", str(model), "--vary", "bsp.enabled=1,2"], capsys)
    assert code == 2 and "numeric" in err
