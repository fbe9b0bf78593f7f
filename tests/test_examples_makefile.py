"""examples/Makefile with real make, run as a user runs it: relative paths from the project folder.

Every kind of dependency is touched in turn -- the .mtl, a texture, a texture that was missing at
bake time and is added later (in a folder that did not exist either), a glTF's .bin, a config and
the model a config names -- and each time ``make -q`` must see the one model out of date, ``make``
must rebake it alone, and then have nothing left to do.
"""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

REPO = Path(__file__).resolve().parent.parent
BAKE = Path(sys.executable).with_name("bake")

pytestmark = [pytest.mark.skipif(shutil.which("make") is None, reason="make is not installed"),
              pytest.mark.skipif(not BAKE.exists(), reason="the bake console script is not installed")]

CUBE = """mtllib {name}.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
v 1 0 1
v 1 1 1
v 0 1 1
vt 0 0
vt 1 0
vt 1 1
vt 0 1
usemtl paint
f 1/1 4/4 3/3 2/2
f 5/1 6/2 7/3 8/4
f 1/1 2/2 6/3 5/4
f 2/1 3/2 7/3 6/4
f 3/1 4/2 8/3 7/4
f 4/1 1/2 5/3 8/4
"""


def png(path: Path, value: int) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    Image.fromarray(np.full((4, 4, 3), value, np.uint8)).save(path)


def gltf_with_bin(folder: Path, name: str) -> None:
    """A textured triangle: NAME.gltf, NAME.bin (positions, UVs, indices) and NAME.png."""
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.float32)
    uv = np.array([[0, 0], [1, 0], [0, 1]], np.float32)
    idx = np.array([0, 1, 2, 0], np.uint16)  # padded to 4 bytes
    blob = pos.tobytes() + uv.tobytes() + idx.tobytes()
    (folder / f"{name}.bin").write_bytes(blob)
    png(folder / f"{name}.png", 200)
    doc = {
        "asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}], "nodes": [{"mesh": 0}],
        "buffers": [{"uri": f"{name}.bin", "byteLength": len(blob)}],
        "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                        {"buffer": 0, "byteOffset": 36, "byteLength": 24},
                        {"buffer": 0, "byteOffset": 60, "byteLength": 6}],
        "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                       "min": [0, 0, 0], "max": [1, 1, 0]},
                      {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"},
                      {"bufferView": 2, "componentType": 5123, "count": 3, "type": "SCALAR"}],
        "images": [{"uri": f"{name}.png"}], "textures": [{"source": 0}],
        "materials": [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
        "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "indices": 2,
                                    "material": 0}]}],
    }
    (folder / f"{name}.gltf").write_text(json.dumps(doc))


def make(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    """The Makefile as a user runs it from the project folder: relative MODELS_DIR and OUT."""
    return subprocess.run(["make", "-f", str(REPO / "examples" / "Makefile"), "MODELS_DIR=models", "OUT=out",
                           f"BAKE={BAKE}", "BAKE_FLAGS=--quiet --set textures.enabled=true", *args],
                          capture_output=True, text=True, cwd=cwd, timeout=600)


def reports(cwd: Path) -> dict[str, int]:
    return {p.parent.name: p.stat().st_mtime_ns for p in sorted((cwd / "out").glob("*/report.json"))}


def later(fn) -> None:
    """Edit after a pause long enough for any file system's timestamps to tell it apart."""
    time.sleep(1.05)
    fn()


@pytest.fixture
def project(tmp_path):
    m = tmp_path / "models"
    m.mkdir()
    (m / "spider.obj").write_text(CUBE.format(name="spider"))
    (m / "spider.mtl").write_text("newmtl paint\nKd 1 0 0\nmap_Kd spider.png\n")
    png(m / "spider.png", 40)
    (m / "ghost.obj").write_text(CUBE.format(name="ghost"))  # its texture is not there yet
    (m / "ghost.mtl").write_text("newmtl paint\nKd 1 1 1\nmap_Kd textures/ghost.png\n")
    gltf_with_bin(m, "duck")
    (m / "plain.obj").write_text(CUBE.format(name="plain").replace("mtllib plain.mtl\n", ""))
    # a config beside the model of the same name is baked instead of the model alone
    (m / "lit.toml").write_text('[input]\npath = "lit.obj"\n[export]\nprecision = 4\n')
    (m / "lit.obj").write_text(CUBE.format(name="none").replace("mtllib none.mtl\n", ""))
    return tmp_path


def rebakes_only(cwd: Path, name: str, edit) -> None:
    """After ``edit``: make -q says out of date, make rebakes ``name`` alone, then nothing to do."""
    before = reports(cwd)
    later(edit)
    assert make(cwd, "-q").returncode == 1, f"make -q does not see {name} out of date"
    r = make(cwd)
    assert r.returncode == 0, r.stderr
    after = reports(cwd)
    changed = sorted(k for k in after if after[k] != before.get(k))
    assert changed == [name], f"expected only {name} to rebake, got {changed}"
    q = make(cwd, "-q")
    assert q.returncode == 0, f"still out of date after rebaking {name}: {make(cwd, '-n').stdout}"


def test_makefile_with_relative_paths_rebakes_on_every_kind_of_dependency(project):
    cwd = project
    r = make(cwd)
    assert r.returncode == 0, r.stderr
    assert sorted(reports(cwd)) == ["duck", "ghost", "lit", "plain", "spider"]
    # the depfile names the target exactly as the Makefile does (a relative path), else make sees two targets
    dep = (cwd / "out" / "spider.d").read_text()
    assert dep.startswith("out/spider/report.json:"), dep.splitlines()[0]
    assert make(cwd, "-q").returncode == 0, "make -q says something is out of date right after make"

    rebakes_only(cwd, "spider", lambda: (cwd / "models/spider.mtl").write_text(
        "newmtl paint\nKd 0 1 0\nmap_Kd spider.png\n"))
    rebakes_only(cwd, "spider", lambda: png(cwd / "models/spider.png", 90))
    rebakes_only(cwd, "duck", lambda: (cwd / "models/duck.bin").write_bytes((cwd / "models/duck.bin").read_bytes()))
    rebakes_only(cwd, "duck", lambda: png(cwd / "models/duck.png", 10))
    rebakes_only(cwd, "lit", lambda: (cwd / "models/lit.toml").write_text(
        '[input]\npath = "lit.obj"\n[export]\nprecision = 3\n'))
    assert json.loads((cwd / "out/lit/report.json").read_text())["config"]["export"]["precision"] == 3
    rebakes_only(cwd, "lit", lambda: os.utime(cwd / "models/lit.obj"))
    # the missing texture is named by its own path, not its folder: a new model beside it bakes
    # alone (the folder's time changes; ghost does not rebake), and the texture's arrival (with the
    # folder it is in) rebakes ghost, which now uses it
    dep = (cwd / "out/ghost.d").read_text()
    assert f"$(wildcard {(cwd / 'models/textures/ghost.png').resolve()})" in dep
    assert not any(line.strip(" \\:") == str((cwd / "models").resolve()) for line in dep.splitlines())
    rebakes_only(cwd, "newcomer", lambda: (cwd / "models/newcomer.obj").write_text(
        CUBE.format(name="none").replace("mtllib none.mtl\n", "")))
    rebakes_only(cwd, "ghost", lambda: png(cwd / "models/textures/ghost.png", 30))
    assert "textures/ghost.png" in (cwd / "out/ghost.d").read_text()
    rebakes_only(cwd, "ghost", lambda: png(cwd / "models/textures/ghost.png", 60))


def test_makefile_rebuilds_only_what_changed_and_keeps_unchanged_lists(project):
    cwd = project
    assert make(cwd).returncode == 0
    verts = cwd / "out/spider/lists/verts.txt"
    old_verts = verts.stat().st_mtime_ns
    rebakes_only(cwd, "spider", lambda: (cwd / "models/spider.mtl").write_text(
        "newmtl paint\nKd 0 0 1\nmap_Kd spider.png\n"))
    assert verts.stat().st_mtime_ns == old_verts, "an unchanged list was rewritten"
