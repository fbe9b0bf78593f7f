"""Nothing is lost, nothing outside is touched.

* A bake killed with SIGKILL at random moments (seeded) leaves every output file byte-equal to
  the previous bake's or the new bake's version, never truncated or missing; a rerun finishes the
  job and equals a clean bake.
* Reruns are byte-identical (every stage on, two threads or one); unchanged files keep their
  timestamps; outputs get the usual file mode (0o666 minus the umask).
* The depfile lists every input the bake opened (model, .mtl, .bin, images, config, the project
  baked into), checked against the files actually opened.
* A bake reads only inside the model's folder (and the config's, the project baked into) and writes
  only inside the output folder: every open/replace/unlink/mkdir is recorded, and the input folder
  is compared with a snapshot (bytes, modes, mtimes) taken before.
"""

from __future__ import annotations

import builtins
import io
import json
import os
import random
import re
import shutil
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from bake.scratch import sb3 as sb3_mod
from rel_util import gltf_triangles, run_cli, write_gltf, write_obj


# --------------------------------------------------------------------------- fixtures
def grid(n: int, phase: float = 0.0):
    """An (n x n) height-field of quads: positions, quads (0-based)."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n))
    z = 0.1 * np.sin(6 * x + phase) * np.cos(5 * y)
    pos = np.stack([x.ravel(), z.ravel(), y.ravel()], 1)
    i = np.arange(n * n).reshape(n, n)
    quads = np.stack([i[:-1, :-1], i[1:, :-1], i[1:, 1:], i[:-1, 1:]], -1).reshape(-1, 4)
    return pos, quads


def snapshot(folder: Path) -> dict[str, bytes]:
    """The outputs (not the caches in .bake-cache/: tests/test_cache.py and textures/test_stage.py)."""
    return {str(p.relative_to(folder)): p.read_bytes() for p in sorted(folder.rglob("*"))
            if p.is_file() and ".bake-cache" not in p.relative_to(folder).parts}


def stat_snapshot(folder: Path) -> dict[str, tuple]:
    return {str(p.relative_to(folder)): (p.read_bytes(), p.stat().st_mode, p.stat().st_mtime_ns)
            for p in sorted(folder.rglob("*"))}


def strip_timings(report_json: bytes) -> dict:
    """report.json without what may differ between bakes: timings and the written/unchanged status."""
    def walk(o):
        if isinstance(o, dict):
            return {k: walk(v) for k, v in o.items() if k not in ("seconds", "outputs", "timing")
                    and not k.endswith("_seconds")}
        if isinstance(o, list):
            return [walk(v) for v in o]
        return o
    return walk(json.loads(report_json))


def comparable_one(name: str, data: bytes) -> object:
    """The bytes, except for the reports: their timings are replaced (a truncated report still
    fails: JSON does not parse, the Markdown loses its tail)."""
    if name == "report.json":
        return strip_timings(data)
    if name in ("report.md", "report.html"):  # (report.html: timings and the time bars' widths)
        return re.sub(rb"\d+\.\d+", b"#", data)
    return data


def comparable(files: dict[str, bytes]) -> dict[str, object]:
    return {k: comparable_one(k, v) for k, v in files.items()}


def bake_cmd(model: Path, out: Path, *extra: str) -> list[str]:
    return _bake_cmd(model, out, *extra)


def _bake_cmd(model: Path, out: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "bake.cli", "run", str(model), "--out", str(out), "--quiet",
            "--set", "bvh.enabled=true", *extra]


# =========================================================================== SIGKILL
@pytest.mark.slow
def test_sigkill_at_random_moments_never_loses_or_truncates_outputs(tmp_path):
    # (without the stage cache, whose report says which stages it served: a rerun would report
    # differently; tests/test_cache.py kills bakes and re-bakes from what they cached)
    def bake_cmd(model, out):
        return _bake_cmd(model, out, "--set", 'cache.dir="none"')

    rng = random.Random(20261122)
    model = tmp_path / "model" / "m.obj"
    pos, quads = grid(45)
    write_obj(model, pos, quads)
    out = tmp_path / "out"
    subprocess.run(bake_cmd(model, out), check=True, timeout=300)
    old = snapshot(out)
    # the new version of the model changes every list
    pos2, _ = grid(45, phase=1.0)
    write_obj(model, pos2 * 1.5, quads)
    ref = tmp_path / "ref"
    t0 = time.perf_counter()
    subprocess.run(bake_cmd(model, ref), check=True, timeout=300)
    duration = time.perf_counter() - t0
    new = snapshot(ref)
    assert set(old) == set(new)
    assert {"lists/verts.txt", "lists/bvh_tris.txt", "lists.json", "m.sb3", "report.json"} <= \
        {k for k in old if old[k] != new[k]}

    outcomes = []
    for _ in range(6):
        shutil.rmtree(out)  # back to the previous bake's outputs
        out.mkdir()
        for k, v in old.items():
            (out / k).parent.mkdir(parents=True, exist_ok=True)
            (out / k).write_bytes(v)
        delay = rng.uniform(0.3, 1.1) * duration
        proc = subprocess.Popen(bake_cmd(model, out), stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
        time.sleep(delay)
        proc.send_signal(signal.SIGKILL)
        proc.wait(timeout=60)
        got = {k: v for k, v in snapshot(out).items() if not k.endswith(".bake-tmp")}
        # every output is there, complete, in one of the two versions
        assert set(got) == set(old), sorted(set(got) ^ set(old))
        kinds = []
        for k, v in got.items():
            c = comparable_one(k, v)
            is_old, is_new = c == comparable_one(k, old[k]), c == comparable_one(k, new[k])
            assert is_old or is_new, f"{k} is neither the old nor the new version ({len(v)} bytes)"
            kinds.append("new" if is_new and not is_old else "old")
        outcomes.append((round(delay, 2), proc.returncode, kinds.count("new")))
        # the rerun finishes the job: equal to the clean bake, orphan temporaries removed
        subprocess.run(bake_cmd(model, out), check=True, timeout=300)
        after = snapshot(out)
        assert not [k for k in after if k.endswith(".bake-tmp")]
        assert comparable(after) == comparable(new)
    print("kills (delay s, status, files already new):", outcomes)
    assert all(rc == -signal.SIGKILL for _, rc, _ in outcomes if rc is not None and rc != 0)


# =========================================================================== reruns
def textured_scene(folder: Path, extra: str = "") -> Path:
    """An OBJ + MTL + PNG model with two materials and a config turning every stage on."""
    pos, quads = grid(12)
    mats = np.where(np.arange(len(quads)) % 3 == 0, 1, 0)
    write_obj(folder / "m.obj", pos, quads, materials=["red", "tex"], poly_material=mats, mtllib="m.mtl")
    text = (folder / "m.obj").read_text().replace("\nf ", "\nvt 0.5 0.5\nf ", 1)
    (folder / "m.obj").write_text(text)
    (folder / "m.mtl").write_text("newmtl red\nKd 1 0 0\nnewmtl tex\nKd 1 1 1\nmap_Kd tex.png\n")
    Image.fromarray(np.arange(48, dtype=np.uint8).reshape(4, 4, 3)).save(folder / "tex.png")
    cfg = folder / "bake.toml"
    cfg.write_text('[input]\npath = "m.obj"\n[bvh]\nenabled = true\n[textures]\nenabled = true\n'
                   '[lighting]\nenabled = true\n'
                   '[lighting.ao]\nenabled = true\nsamples = 16\n[[lighting.lights]]\nkind = "sun"\n'
                   'direction = [-0.3, -1.0, 0.2]\n' + extra)
    return cfg


LIGHTMAP = ('[textures.lightmap]\nenabled = true\nresolution = 32\n')  # the default xatlas cache


def test_reruns_are_byte_identical_and_unchanged_files_keep_their_time(tmp_path, capsys):
    cfg = textured_scene(tmp_path / "model")
    a, b = tmp_path / "a", tmp_path / "b"
    assert run_cli(["run", cfg, "--out", a, "--quiet", "--set", "lighting.threads=2"], capsys)[0] == 0
    assert run_cli(["run", cfg, "--out", b, "--quiet", "--set", "lighting.threads=1"], capsys)[0] == 0
    sa, sb = snapshot(a), snapshot(b)
    assert sa.keys() == sb.keys() and {"m.sb3", "m.sprite3", "lists.json", "lists/tri_colors.txt",
                                       "lists/bvh_nodes.txt"} <= set(sa)
    for k in sa:
        if k not in ("report.json", "report.md", "report.html"):
            assert sa[k] == sb[k], f"{k} differs between two bakes"
    # report.html: the same page but for the timings (and the width of the time bars)
    assert comparable_one("report.html", sa["report.html"]) == comparable_one("report.html", sb["report.html"])
    # report.json differs only in timings and where it states the thread count
    ra, rb = strip_timings(sa["report.json"]), strip_timings(sb["report.json"])
    for r in (ra, rb):
        r["config"]["lighting"].pop("threads")
        next(st for st in r["stages"] if st["name"] == "lighting")["details"].pop("threads")
    assert ra == rb
    # baking again into the same folder rewrites nothing but the reports
    before = {p: p.stat().st_mtime_ns for p in a.rglob("*")  # (a cache hit touches its entry: LRU)
              if p.is_file() and ".bake-cache" not in p.relative_to(a).parts}
    time.sleep(0.02)
    assert run_cli(["run", cfg, "--out", a, "--quiet", "--set", "lighting.threads=2"], capsys)[0] == 0
    rep = json.loads((a / "report.json").read_text())
    assert set(rep["outputs"].values()) == {"unchanged"}
    changed = [p.name for p in before if p.stat().st_mtime_ns != before[p]]
    assert sorted(changed) == ["report.html", "report.json", "report.md"], changed  # they carry timings
    # files are created with the usual mode, not mkstemp's private 0o600
    mask = os.umask(0o022)
    os.umask(mask)
    modes = {p.name: p.stat().st_mode & 0o777 for p in a.rglob("*") if p.is_file()}
    assert set(modes.values()) == {0o666 & ~mask}, modes


# =========================================================================== depfile and reads
class Recorder:
    """Records every path opened for reading or writing, renamed, removed or created."""

    def __init__(self, monkeypatch):
        self.reads: list[Path] = []
        self.writes: list[Path] = []
        real_open, real_os_open = builtins.open, os.open
        real_replace, real_rename, real_unlink = os.replace, os.rename, os.unlink
        real_mkdir, real_rmdir = os.mkdir, os.rmdir

        def p(x, dir_fd=None) -> Path:
            x = os.fsdecode(x)
            if dir_fd is not None and not os.path.isabs(x):  # e.g. shutil.rmtree's unlink(name, dir_fd=)
                return Path(os.readlink(f"/proc/self/fd/{dir_fd}")) / x
            return Path(os.path.abspath(x))

        def rec_open(file, mode="r", *a, **k):
            if isinstance(file, (str, bytes, os.PathLike)):
                (self.writes if any(c in mode for c in "wax+") else self.reads).append(p(file))
            return real_open(file, mode, *a, **k)

        def rec_os_open(path, flags, *a, **k):
            w = flags & (os.O_WRONLY | os.O_RDWR | os.O_CREAT | os.O_TRUNC | os.O_APPEND)
            (self.writes if w else self.reads).append(p(path, k.get("dir_fd")))
            return real_os_open(path, flags, *a, **k)

        def two(real):
            def f(src, dst, *a, **k):
                self.writes += [p(src), p(dst)]
                return real(src, dst, *a, **k)
            return f

        def one(real):
            def f(path, *a, **k):
                self.writes.append(p(path, k.get("dir_fd")))
                return real(path, *a, **k)
            return f

        monkeypatch.setattr(builtins, "open", rec_open)
        monkeypatch.setattr(io, "open", rec_open)
        monkeypatch.setattr(os, "open", rec_os_open)
        monkeypatch.setattr(os, "replace", two(real_replace))
        monkeypatch.setattr(os, "rename", two(real_rename))
        monkeypatch.setattr(os, "unlink", one(real_unlink))
        monkeypatch.setattr(os, "remove", one(real_unlink))
        monkeypatch.setattr(os, "mkdir", one(real_mkdir))
        monkeypatch.setattr(os, "rmdir", one(real_rmdir))


def parse_depfile(text: str) -> tuple[list[Path], list[Path]]:
    rule = text.split("\n\n")[0].replace("\\\n", " ")
    targets, deps = rule.split(": ", 1)
    unesc = [t.replace("\\ ", "\0") for t in (targets, deps)]
    split = [[Path(x.replace("\0", " ").replace("$$", "$").replace("\\#", "#")) for x in u.split()] for u in unesc]
    return split[0], split[1]


def _outside(paths, *roots: Path) -> list[Path]:
    roots_r = [r.resolve() for r in roots]
    return [q for q in paths if not any(q.resolve() == r or r in q.resolve().parents for r in roots_r)]


def _author_project(path: Path) -> None:
    data, _ = sb3_mod.write_sb3([sb3_mod.Target("Stage", is_stage=True, lists={"verts": [0]}),
                                 sb3_mod.Target("Engine", layer_order=1)])
    path.write_bytes(data)


@pytest.mark.parametrize("kind", ["obj_config", "gltf_external", "obj_lightmap"])
def test_reads_and_writes_stay_in_their_folders_and_depfile_lists_every_input(tmp_path, capsys, monkeypatch,
                                                                              kind):
    model_dir = tmp_path / "model"
    model_dir.mkdir()
    decoy = tmp_path / "elsewhere"
    decoy.mkdir()
    (decoy / "m.mtl").write_text("newmtl red\nKd 0 1 0\n")  # same names as the real inputs
    (decoy / "m.bin").write_bytes(b"\0" * 64)
    author = tmp_path / "author"
    author.mkdir()
    _author_project(author / "engine.sb3")
    extra: list[str] = []
    if kind.startswith("obj"):
        target = textured_scene(model_dir, LIGHTMAP if kind == "obj_lightmap" else "")
        inputs = {model_dir / n for n in ("m.obj", "m.mtl", "tex.png", "bake.toml")}
        if kind == "obj_lightmap":
            extra = ["--set", 'lighting.target="lightmap"']
    else:
        pos, quads = grid(8)
        tris = np.concatenate([quads[:, [0, 1, 2]], quads[:, [0, 2, 3]]])
        doc, buf = gltf_triangles(pos, tris, uvs=pos[:, [0, 2]])
        Image.fromarray(np.full((2, 2, 3), 200, np.uint8)).save(model_dir / "base.png")
        doc["images"] = [{"uri": "base.png"}]
        doc["textures"] = [{"source": 0}]
        doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
        doc["meshes"][0]["primitives"][0]["material"] = 0
        target = write_gltf(model_dir / "m.gltf", doc, buf, embed=False, bin_name="m.bin")
        inputs = {model_dir / n for n in ("m.gltf", "m.bin", "base.png")}
        extra = ["--set", "textures.enabled=true", "--set", "bsp.enabled=true"]
    inputs.add(author / "engine.sb3")
    for f in list(model_dir.iterdir()) + [author / "engine.sb3"]:
        f.chmod(0o444)
    before = stat_snapshot(model_dir), stat_snapshot(author), stat_snapshot(decoy)
    out = tmp_path / "out"
    dep = out / "bake.d"
    rec = Recorder(monkeypatch)
    temp_before = set(Path(tempfile.gettempdir()).iterdir())
    code, _, err = run_cli(["run", target, "--out", out, "--quiet", "--depfile", dep, "--set",
                            f'export.into="{author / "engine.sb3"}"', "--set", "export.into_target=\"Engine\"",
                            *extra], capsys)
    monkeypatch.undo()
    assert code == 0, err
    assert (stat_snapshot(model_dir), stat_snapshot(author), stat_snapshot(decoy)) == before
    # the recorder sees what a bake does (else the checks below prove nothing)
    assert target.resolve() in {q.resolve() for q in rec.reads}
    assert (out / "lists.json").resolve() in {q.resolve() for q in rec.writes}
    # writes: only inside the output folder, or scratch files in the temp folder that are gone again
    tmp_root = Path(tempfile.gettempdir())
    stray = [q for q in _outside(rec.writes, out) if q.exists() or tmp_root.resolve() not in q.resolve().parents]
    assert not stray, stray
    assert set(tmp_root.iterdir()) <= temp_before | {tmp_root / "pytest-of-root"}, "left in the temp folder"
    # reads under the test folder: only the inputs (nothing from the decoy folder) and our outputs
    under = [q for q in rec.reads if tmp_path.resolve() in q.resolve().parents]
    assert not _outside(under, model_dir, author, out), _outside(under, model_dir, author, out)
    opened_inputs = {q.resolve() for q in under if not _outside([q], model_dir, author)}
    # the depfile: every input opened is a dependency, and every dependency is a real input
    targets, deps = parse_depfile(dep.read_text())
    deps_r = {d.resolve() for d in deps}
    assert opened_inputs <= deps_r, opened_inputs - deps_r
    assert deps_r == {q.resolve() for q in inputs}, deps_r ^ {q.resolve() for q in inputs}
    assert (out / "report.json").resolve() in {t.resolve() for t in targets}
    assert (out / "engine-m.sb3").is_file()
    rep = json.loads((out / "report.json").read_text())
    ran = {e["name"] for e in rep["effects"] if e.get("ran")}
    assert {"textures", "export"} <= ran, ran  # the texture was really read
    if kind == "obj_lightmap":
        assert "lightmap" in json.dumps(rep["lists"]), "no lightmap lists"
        # the default xatlas cache is inside the output folder, and not an output (never listed or removed)
        assert len(list((out / ".bake-cache" / "xatlas").rglob("*.npz"))) == 1
        listed = json.loads((out / ".bake-manifest.json").read_text())["files"]
        assert not [f for f in [*rep["outputs"], *listed] if ".bake-cache" in f]
