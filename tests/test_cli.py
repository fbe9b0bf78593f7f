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
    svg = stem.with_suffix(".samples.svg").read_text()
    assert svg.startswith("<svg ") and "lighting.ao.samples" in svg
    assert "updated" in stdout and "report.html" in stdout
    page = (out / "report.html").read_text()
    # the bake's report shows the sweep, its plot embedded as the SVG the sweep wrote
    import base64

    assert "alt='sweep lighting.ao.samples' src='data:image/svg+xml;base64," \
        + base64.b64encode(svg.encode()).decode() + "'" in page
    code, _, err = run(["sweep", str(model), "--vary", "bsp.enabled=1,2"], capsys)
    assert code == 2 and "numeric" in err


# --------------------------------------------------------------------------- output paths (issue 18, item 5)
def bake_subprocess(args, cwd=None, prefix=()):
    return subprocess.run([*prefix, sys.executable, "-m", "bake.cli", *map(str, args)], capture_output=True,
                          text=True, cwd=cwd, timeout=300)


def one_error_line(r, status, *names):
    assert r.returncode == status, (r.returncode, r.stderr)
    assert "Traceback" not in r.stderr and r.stderr.count("\n") == 1, r.stderr
    assert r.stderr.startswith("bake: error: ")
    for n in names:
        assert str(n) in r.stderr, (n, r.stderr)
    return r.stderr


def test_output_path_mistakes_exit_2_naming_the_path_before_baking(tmp_path):
    model = grid_obj(tmp_path / "grid.obj", 2)
    afile = tmp_path / "afile"
    afile.write_text("mine")
    r = bake_subprocess(["run", model, "--out", afile])
    assert "names a file, not a folder" in one_error_line(r, 2, afile)
    r = bake_subprocess(["run", model, "--out", afile / "sub"])
    assert "is a file, not a folder" in one_error_line(r, 2, afile)
    assert afile.read_text() == "mine"
    folder = tmp_path / "adir"
    folder.mkdir()
    out = tmp_path / "o"
    r = bake_subprocess(["run", model, "--out", out, "--depfile", folder])
    assert "--depfile names a folder" in one_error_line(r, 2, folder)
    assert not out.exists(), "the bake ran although its depfile could not be written"
    # a depfile that would overwrite the model
    r = bake_subprocess(["run", model, "--out", out, "--depfile", model])
    one_error_line(r, 2, model)
    assert not out.exists() and model.read_text().startswith("mtllib")


def test_refusing_to_overwrite_an_input_exits_2_and_leaves_nothing(tmp_path):
    model = grid_obj(tmp_path / "grid.obj", 2)
    out = tmp_path / "o"
    assert bake_subprocess(["run", model, "--out", out, "--quiet"]).returncode == 0
    # bake into the .sb3 this very bake writes: known before the bake
    r = bake_subprocess(["run", model, "--out", out, "--set", f'export.into="{out / "grid.sb3"}"'])
    assert "refusing to overwrite the input file" in one_error_line(r, 2, out / "grid.sb3")
    # a texture where the bake writes its costume: found by the importer, refused before anything is written
    tex = tmp_path / "m" / "assets" / "tex_paint.png"
    tex.parent.mkdir(parents=True)
    from PIL import Image
    Image.fromarray(np.full((2, 2, 3), 90, np.uint8)).save(tex)
    obj = (tmp_path / "m" / "m.obj")
    obj.write_text("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 0 1\nusemtl paint\nf 1/1 2/2 3/3\n")
    (tmp_path / "m" / "m.mtl").write_text("newmtl paint\nKd 1 1 1\nmap_Kd assets/tex_paint.png\n")
    before = sorted(p.name for p in (tmp_path / "m").rglob("*"))
    r = bake_subprocess(["run", obj, "--out", tmp_path / "m", "--set", "textures.enabled=true"])
    assert "refusing to overwrite the input file" in one_error_line(r, 2, tex)
    assert sorted(p.name for p in (tmp_path / "m").rglob("*")) == before, "something was written (lists/?)"


def _read_only_mount_prefix(folder):
    """``unshare -m`` + a read-only bind mount of ``folder``: a real EROFS even for root."""
    import shutil
    if shutil.which("unshare") is None:
        pytest.skip("unshare is not installed")
    probe = subprocess.run(["unshare", "-m", "sh", "-c", f"mount --bind -o ro '{folder}' '{folder}'"],
                           capture_output=True, text=True)
    if probe.returncode != 0:
        pytest.skip(f"cannot make a read-only mount here: {probe.stderr.strip()}")
    return ["unshare", "-m", "sh", "-c", f"mount --bind -o ro '{folder}' '{folder}' && exec \"$0\" \"$@\""]


def test_read_only_output_folder_exits_2_naming_the_folder(tmp_path):
    model = grid_obj(tmp_path / "grid.obj", 2)
    out = tmp_path / "ro"
    out.mkdir()
    prefix = _read_only_mount_prefix(out)
    r = bake_subprocess(["run", model, "--out", out], prefix=prefix)
    assert "read-only" in one_error_line(r, 2, out)
    r = bake_subprocess(["run", model, "--out", out / "sub"], prefix=prefix)
    assert "read-only" in one_error_line(r, 2, out)


# --------------------------------------------------------------------------- bake sweep (issue 18, item 8)
def test_sweep_shows_progress_as_it_goes_and_a_readable_header(tmp_path):
    import time as _time
    model = grid_obj(tmp_path / "grid.obj", 12)
    proc = subprocess.Popen([sys.executable, "-m", "bake.cli", "sweep", str(model), "--vary",
                             "export.precision=2,3,4", "--out", str(tmp_path / "o")],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True)
    t0 = _time.perf_counter()
    arrivals = []
    for line in proc.stderr:  # read as the lines come
        arrivals.append((_time.perf_counter() - t0, line.rstrip("\n")))
    out = proc.stdout.read()
    proc.wait(timeout=300)
    end = _time.perf_counter() - t0
    assert proc.returncode == 0, arrivals
    msgs = [m for _, m in arrivals]
    bakes = [m for m in msgs if "bake " in m and "/3:" in m]
    assert [b.split("] ", 1)[1] for b in bakes] == [f"bake {i}/3: export.precision = {v}"
                                                   for i, v in ((1, 2), (2, 3), (3, 4))], msgs
    assert any("warm-up" in m for m in msgs) and any("comparing" in m for m in msgs), msgs
    assert arrivals[0][0] < end / 2, (arrivals, end)  # the first line came early, not at the end
    header = out.splitlines()[0]
    assert header == "sweep export.precision: reference = the bake at the highest value (4)", header
    assert "{" not in out, out
    # --quiet: nothing on stderr
    r = subprocess.run([sys.executable, "-m", "bake.cli", "sweep", str(model), "--vary", "export.precision=2,3",
                        "--out", str(tmp_path / "o"), "--quiet"], capture_output=True, text=True, timeout=300)
    assert r.returncode == 0 and r.stderr == "" and r.stdout == "", (r.stdout, r.stderr)


# --------------------------------------------------------------------------- README (issue 18, item 9)
def test_readme_worked_example_is_what_a_run_prints(tmp_path):
    """README's Suzanne example, run for real: the same lines but for the times."""
    import re
    from pathlib import Path

    from conftest import corpus_path

    model = corpus_path("suzanne_obj", "suzanne.obj")
    readme = (Path(__file__).resolve().parent.parent / "README.md").read_text()
    cmd = re.search(r"```sh\n\.venv/bin/bake (run \S+suzanne\.obj --out (\S+))\n```", readme)
    shown = re.search(r"```\n(suzanne\.obj: .*?)```", readme, re.S).group(1)
    assert cmd, "the example's command is not in README.md"
    r = subprocess.run([sys.executable, "-m", "bake.cli", "run", str(model), "--out", cmd.group(2)],
                       capture_output=True, text=True, cwd=tmp_path, timeout=300)
    assert r.returncode == 0, r.stderr

    def masked(text):
        return [re.sub(r"\d+\.\d+ s\b", "# s", ln) for ln in text.strip().splitlines()]
    assert masked(r.stdout) == masked(shown)
