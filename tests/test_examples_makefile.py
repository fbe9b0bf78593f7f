"""examples/Makefile with real make: bakes every model, then rebuilds only what changed."""

import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import pytest

REPO = Path(__file__).resolve().parent.parent
BAKE = Path(sys.executable).with_name("bake")

CUBE = """mtllib {name}.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
usemtl paint
f 1 4 3 2
f 5 6 7 8
f 1 2 6 5
f 2 3 7 6
f 3 4 8 7
f 4 1 5 8
"""


def make(tmp, *args):
    return subprocess.run(["make", "-f", str(REPO / "examples" / "Makefile"), f"MODELS_DIR={tmp / 'models'}",
                           f"OUT={tmp / 'out'}", f"BAKE={BAKE}", *args],
                          capture_output=True, text=True, cwd=tmp, timeout=300)


@pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed")
@pytest.mark.skipif(not BAKE.exists(), reason="the bake console script is not installed in this environment")
def test_makefile_rebuilds_only_what_changed(tmp_path):
    models = tmp_path / "models"
    models.mkdir()
    for name, colour in (("a", "1 0 0"), ("b", "0 0 1")):
        (models / f"{name}.obj").write_text(CUBE.format(name=name))
        (models / f"{name}.mtl").write_text(f"newmtl paint\nKd {colour}\n")
    r = make(tmp_path)
    assert r.returncode == 0, r.stderr
    ra, rb = tmp_path / "out/a/report.json", tmp_path / "out/b/report.json"
    assert ra.exists() and rb.exists()
    assert (tmp_path / "out/a/lists/verts.txt").read_text().count("\n") == 23  # 8 vertices x 3, no trailing newline
    dep = (tmp_path / "out/a.d").read_text()
    assert "a.obj" in dep and "a.mtl" in dep

    # nothing changed: make does nothing
    r = make(tmp_path, "-q")
    assert r.returncode == 0, "make -q says something is out of date"

    # a material edit rebakes only that model; its colour list changes, the vertex list is not rewritten
    verts_a = tmp_path / "out/a/lists/verts.txt"
    old_verts_mtime = verts_a.stat().st_mtime_ns
    old_b = rb.stat().st_mtime_ns
    time.sleep(1.1)
    (models / "a.mtl").write_text("newmtl paint\nKd 0 1 0\n")
    r = make(tmp_path)
    assert r.returncode == 0, r.stderr
    assert rb.stat().st_mtime_ns == old_b, "model b was rebaked although nothing it reads changed"
    assert (tmp_path / "out/a/lists/mat_colors.txt").read_text() == str(255 * 256)
    assert verts_a.stat().st_mtime_ns == old_verts_mtime, "unchanged list was rewritten"
    assert make(tmp_path, "-q").returncode == 0
