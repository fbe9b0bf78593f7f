"""The smaller things a new author hit (issue 18, item 9): what the terminal says was written, the
.sprite3's name, an emptied assets/ folder, report.md's counts, Hausdorff units, list files that
Scratch's list import reads whole, and report.html's sweep hint that works for the bake at hand."""

import csv
import io
import json
import re
import shlex
import subprocess
import sys
from pathlib import Path

import numpy as np
from PIL import Image

from bake import cli
from bake.scratch import sb3 as sb3_mod

QUADS = ("mtllib m.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nv 0 0 1\nv 1 0 1\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\n"
         "usemtl wood\nf 1/1 2/2 3/3 4/4\nf 1/1 2/2 6/3 5/4\n")


def textured(folder: Path) -> Path:
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "m.obj").write_text(QUADS)
    (folder / "m.mtl").write_text("newmtl wood\nKd 1 1 1\nmap_Kd wood.png\n")
    rng = np.random.default_rng(1)
    Image.fromarray(rng.integers(0, 255, (8, 8, 3), dtype=np.uint8)).save(folder / "wood.png")
    return folder / "m.obj"


def run(capsys, *argv):
    code = cli.main([str(a) for a in argv])
    cap = capsys.readouterr()
    return code, cap.out, cap.err


def test_wrote_line_names_the_projects_and_the_bake_into(tmp_path, capsys):
    model = textured(tmp_path / "m")
    data, _ = sb3_mod.write_sb3([sb3_mod.Target("Stage", is_stage=True), sb3_mod.Target("Engine", layer_order=1)])
    (tmp_path / "engine.sb3").write_bytes(data)
    code, out, err = run(capsys, "run", model, "--out", tmp_path / "o", "--set", "textures.enabled=true",
                         "--set", f'export.into="{tmp_path / "engine.sb3"}"', "--set", "export.sb3_name=demo.sb3")
    assert code == 0, err
    wrote = [ln for ln in out.splitlines() if ln.strip().startswith("wrote")]
    assert len(wrote) == 2, out
    assert wrote[0].startswith(f"  wrote {tmp_path / 'o'}/: demo.sb3, demo.sprite3, lists.json, lists/ (")
    assert "assets/ (1 PNG)" in wrote[0] and wrote[0].endswith("report.md, report.json, report.html")
    assert wrote[1] == f"  wrote {tmp_path / 'o' / 'engine-m.sb3'}: {tmp_path / 'engine.sb3'} with these lists in 'Stage'"
    # the .sprite3 follows export.sb3_name, and every file named is there
    for name in ("demo.sb3", "demo.sprite3", "engine-m.sb3", "lists.json"):
        assert (tmp_path / "o" / name).is_file(), name
    assert not (tmp_path / "o" / "m.sprite3").exists()


def test_an_emptied_assets_folder_is_removed_on_rebake(tmp_path, capsys):
    model = textured(tmp_path / "m")
    out = tmp_path / "o"
    (out).mkdir()
    (out / "notes.txt").write_text("mine")
    assert run(capsys, "run", model, "--out", out, "--quiet", "--set", "textures.enabled=true")[0] == 0
    assert [p.name for p in (out / "assets").iterdir()] == ["tex_wood.png"]
    (out / "lists" / "mine.txt").write_text("a user's file in a folder of ours")
    assert run(capsys, "run", model, "--out", out, "--quiet", "--set", "textures.enabled=false")[0] == 0
    assert not (out / "assets").exists(), "an empty assets/ stayed behind"
    assert (out / "lists" / "mine.txt").read_text().startswith("a user's")  # a folder with a user's file stays
    assert (out / "notes.txt").read_text() == "mine"
    rep = json.loads((out / "report.json").read_text())
    assert rep["outputs"]["assets/tex_wood.png"] == "removed"


def test_report_md_counts_and_terminal_hausdorff_units(tmp_path, capsys):
    n = 12
    x, z = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    lines = [f"v {a} {0.2 * np.sin(5 * a + 3 * b)} {b}" for a, b in zip(x.ravel(), z.ravel())]
    i = np.arange(n * n).reshape(n, n) + 1
    lines += [f"f {a} {b} {c} {d}" for a, b, c, d in zip(i[:-1, :-1].ravel(), i[1:, :-1].ravel(),
                                                         i[1:, 1:].ravel(), i[:-1, 1:].ravel())]
    (tmp_path / "g.obj").write_text("\n".join(lines))
    code, out, err = run(capsys, "run", tmp_path / "g.obj", "--out", tmp_path / "o", "--set",
                         "mesh.simplify.enabled=true", "--set", "mesh.simplify.target_ratio=0.5")
    assert code == 0, err
    md = (tmp_path / "o" / "report.md").read_text()
    stages = md.split("## Stages", 1)[1].split("## Effects", 1)[0]
    rows = {r.split("|")[1].strip(): r for r in stages.splitlines() if r.startswith("| ")}
    assert "| – |" in rows["import"] and "polygons 121" in rows["import"], rows["import"]
    assert "polygons 121" in rows["transform"].split("|")[3] and "triangles 0" not in rows["transform"]
    assert "% of the diagonal" in rows["simplify"]
    simp = next(ln for ln in out.splitlines() if ln.strip().startswith("simplify"))
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    hmax = next(s for s in rep["stages"] if s["name"] == "simplify")["accuracy"]["hausdorff_max"]
    assert f"hausdorff_max={100 * hmax:.3g}%" in simp and "% of the bounding-box diagonal" in simp, simp


def gui_import(path: Path) -> list[str]:
    """What Scratch 3's list import makes of a file (scratch-gui src/lib/import-csv.js): a .txt is
    split at a comma or tab when its first, middle and last lines split into the same number (> 1)
    of fields -- then only one column is kept; a .csv goes through a CSV parser (RFC 4180, here
    Python's csv module) and, with one column, is read without a prompt."""
    text = path.read_text("utf-8")
    lines = re.split(r"\r\n|[\r\n]", text)
    while lines and not lines[-1]:
        lines.pop()
    if path.suffix == ".txt":
        for d in (",", "\t"):
            counts = {len(lines[k].split(d)) for k in (0, len(lines) // 2, len(lines) - 1)} if lines else {1}
            if len(counts) == 1 and counts.pop() > 1:
                raise AssertionError(f"{path.name}: the import would ask for a column (split at {d!r})")
        return lines
    rows = list(csv.reader(io.StringIO("\n".join(lines))))
    assert all(len(r) == 1 for r in rows), f"{path.name}: {max(len(r) for r in rows)} columns"
    return [r[0] for r in rows]


def test_every_list_file_imports_whole_in_scratch(tmp_path, capsys):
    model = textured(tmp_path / "m")
    out = tmp_path / "o"
    assert run(capsys, "run", model, "--out", out, "--quiet", "--set", "textures.enabled=true",
               "--set", 'export.color_format="hex"')[0] == 0
    lists = json.loads((out / "lists.json").read_text())["lists"]
    rep = json.loads((out / "report.json").read_text())
    files = sorted(p for p in (out / "lists").iterdir())
    assert any(p.suffix == ".csv" for p in files), "the TextImage list should be a .csv"
    for name, info in rep["lists"].items():
        got = gui_import(out / info["file"])
        want = [v if isinstance(v, str) else format(v) for v in lists[name]]
        assert len(got) == len(want), name
        if isinstance(lists[name][0], str):
            assert got == want, name  # strings (TextImage, hex colours) come back exactly
        else:
            assert np.allclose([float(g) for g in got], lists[name]), name


def test_report_html_sweep_hint_works_for_the_bake_at_hand(tmp_path, capsys):
    (tmp_path / "t.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n")
    for name, sets in (("plain", []), ("simplified", ["--set", "mesh.simplify.enabled=true",
                                                      "--set", "mesh.simplify.target_triangles=4"])):
        out = tmp_path / name
        assert run(capsys, "run", tmp_path / "t.obj", "--out", out, "--quiet", *sets)[0] == 0
        page = (out / "report.html").read_text()
        m = re.search(r"No sweep yet\. In this folder run for example <code>([^<]+)</code>", page)
        assert m, "no hint"
        import html as html_mod
        argv = shlex.split(html_mod.unescape(m.group(1)))
        assert argv[:2] == ["bake", "sweep"] and argv[-2:] == ["--out", "."], argv
        if name == "simplified":
            assert any(a.startswith("mesh.simplify.target_triangles=") for a in argv), argv
        r = subprocess.run([sys.executable, "-m", "bake.cli", *argv[1:], "--quiet"], capture_output=True,
                           text=True, timeout=600, cwd=out)
        assert r.returncode == 0, (argv, r.stderr)
        assert "alt='sweep " in (out / "report.html").read_text()  # and the report shows it


def test_bake_into_warns_of_lists_an_earlier_bake_left_there(tmp_path, capsys):
    """A user's review: baking a plain model into an engine that holds an earlier bake's BSP tree
    and colour lists replaced verts/tris but silently kept 'bsp nodes', 'bsp planes' and 'tri
    colors' of the old model. The bake now names every such list it leaves (the stage's and the
    target sprite's; not another sprite's, not the author's own lists) and keeps them untouched."""
    model = textured(tmp_path / "m")
    old = {"bsp nodes": [1, 2, 3], "bsp planes": [0.5], "tri colors": [7], "my list": [1], "verts": [0, 0, 0],
           "lightmap uvs": []}  # (an empty list of a bake's name holds no earlier model: not named)
    data, _ = sb3_mod.write_sb3([sb3_mod.Target("Stage", is_stage=True, lists=dict(old)),
                                 sb3_mod.Target("Other", layer_order=1, lists={"bvh nodes": [1]})])
    (tmp_path / "engine.sb3").write_bytes(data)
    code, out, err = run(capsys, "run", model, "--out", tmp_path / "o",
                         "--set", f'export.into="{tmp_path / "engine.sb3"}"')
    assert code == 0, err
    baked = set(json.loads((tmp_path / "o" / "lists.json").read_text())["lists"])
    stale = sorted({"bsp nodes", "bsp planes", "tri colors"} - baked)
    assert "bsp nodes" in stale and "verts" in baked
    want = "keeps list(s) an earlier bake wrote and this one does not: " + ", ".join(repr(n) for n in stale)
    assert want + ";" in out + err, out + err
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    export = next(s for s in rep["stages"] if s["name"] == "export")
    assert export["details"]["into"]["stale_lists"] == stale
    proj, _ = sb3_mod.load_project(tmp_path / "o" / "engine-m.sb3")
    stage = next(t for t in proj["targets"] if t["isStage"])
    lists = {n: v for n, v in stage["lists"].values()}
    assert all(lists[n] == old[n] for n in stale) and lists["my list"] == [1]
