"""Ctrl-C (and SIGTERM) during a rebake: every output file is the previous bake's, or the whole
folder is the new bake's -- report.html, report.md, report.json and the depfile included.

A real ``bake run`` in a subprocess rebakes a folder with ``--set export.precision=3`` (which
changes every list, the projects and the reports) and gets SIGINT at several moments spread over
the bake, and once at the exact moment the first output file changes on disk (the moment the old
writer renamed the lists while report.html was still being rendered). After each, the folder is
compared file by file with a snapshot of the old bake and of a clean new bake.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from rel_util import write_obj
from test_rel_nothing_lost import comparable_one as _comparable, grid, snapshot
from conftest import sigint_default

pytestmark = pytest.mark.slow


def bake_cmd(model: Path, out: Path, dep: Path, *extra: str) -> list[str]:
    return [sys.executable, "-m", "bake.cli", "run", str(model), "--out", str(out), "--quiet",
            "--depfile", str(dep), "--set", "bvh.enabled=true", "--set", "bsp.enabled=true",
            "--set", 'cache.dir="none"', *extra]  # (a rebake from the stage cache reports it: not the clean bake's report)


NEW = ("--set", "export.precision=3")


def comparable_one(rel: str, data: bytes) -> object:
    """The bytes, or a report without its timings (``out/report.json`` compares as report.json)."""
    return _comparable(rel.removeprefix("out/"), data)


def restore(folder: Path, files: dict[str, bytes]) -> None:
    shutil.rmtree(folder, ignore_errors=True)
    for k, v in files.items():
        (folder / k).parent.mkdir(parents=True, exist_ok=True)
        (folder / k).write_bytes(v)


def state(got: dict[str, bytes], old: dict[str, bytes], new: dict[str, bytes]) -> str:
    """"old" or "new" when every file is that version, else a description of the mix."""
    if set(got) == set(old) and all(comparable_one(k, got[k]) == comparable_one(k, old[k]) for k in got):
        return "old"
    if set(got) == set(new) and all(comparable_one(k, got[k]) == comparable_one(k, new[k]) for k in got):
        return "new"
    kinds = {}
    for k in sorted(set(got) | set(old) | set(new)):
        if k not in got:
            kinds[k] = "missing"
        elif k in old and comparable_one(k, got[k]) == comparable_one(k, old[k]):
            kinds[k] = "old"
        elif k in new and comparable_one(k, got[k]) == comparable_one(k, new[k]):
            kinds[k] = "new"
        else:
            kinds[k] = "neither"
    return f"mixed: {kinds}"


@pytest.fixture(scope="module")
def rebake(tmp_path_factory):
    """The model, the old bake's folder (+ depfile) and the new bake's, and how long a bake takes."""
    tmp = tmp_path_factory.mktemp("interrupt")
    model = tmp / "model" / "m.obj"
    pos, quads = grid(40)
    write_obj(model, pos, quads)
    work = tmp / "work"
    work.mkdir()
    subprocess.run(bake_cmd(model, work / "out", work / "out.d"), check=True, timeout=300)
    old = snapshot(work)
    t0 = time.perf_counter()
    subprocess.run(bake_cmd(model, work / "out", work / "out.d", *NEW), check=True, timeout=300)
    duration = time.perf_counter() - t0
    new = snapshot(work)
    changed = {k for k in old if k in new and old[k] != new[k]}
    assert {"out/report.html", "out/report.md", "out/report.json", "out/lists.json", "out/lists/verts.txt",
            "out/m.sb3"} <= changed
    assert "out.d" in old
    return model, work, old, new, duration


def interrupt(model: Path, work: Path, old: dict, when, sig=signal.SIGINT) -> tuple[int, str]:
    """Rebake over the old folder and send ``sig`` at ``when`` (seconds, or a callable that
    returns once the moment has come). Returns (exit status, stderr)."""
    restore(work, old)
    proc = subprocess.Popen(bake_cmd(model, work / "out", work / "out.d", *NEW), stdout=subprocess.DEVNULL,
                            stderr=subprocess.PIPE, text=True, preexec_fn=sigint_default)
    if callable(when):
        when(proc)
    else:
        time.sleep(when)
    proc.send_signal(sig)
    _, err = proc.communicate(timeout=120)
    return proc.returncode, err


def _check(work: Path, old: dict, new: dict, code: int, err: str, expect_code: int) -> str:
    got = snapshot(work)
    assert not [k for k in got if k.endswith(".bake-tmp")], "temporary files left behind"
    kind = state(got, old, new)
    assert kind in ("old", "new"), kind
    if code == 0:  # the signal came after the bake had finished
        assert kind == "new"
    elif kind == "old" or "interrupted" in err or "terminated" in err:
        # Python's own handler may see a signal sent before bake.cli was imported (-2)
        assert code in (expect_code, -signal.SIGINT, -signal.SIGTERM), (code, err)
        assert "Traceback" not in err or code < 0, err
    if "before any output was written" in err:
        assert kind == "old", err  # what the message says is true
    if "after the outputs were written" in err:
        assert kind == "new", err
    return kind


def test_sigint_at_several_moments_leaves_the_folder_old_or_new(rebake):
    model, work, old, new, duration = rebake
    seen = []
    for frac in (0.15, 0.35, 0.55, 0.7, 0.8, 0.9, 0.97):
        code, err = interrupt(model, work, old, frac * duration)
        seen.append((frac, code, _check(work, old, new, code, err, 130)))
    print("SIGINT (fraction of the bake, exit status, folder):", seen)
    assert any(code == 130 for _, code, _ in seen), seen  # the interrupt did land during bakes


def test_sigint_as_the_first_output_changes_leaves_the_folder_new(rebake):
    """The moment the old writer got wrong: lists renamed, report.html still being rendered."""
    model, work, old, new, _ = rebake
    watched = work / "out" / "lists.json"

    def first_change(proc):
        before = old["out/lists.json"]
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                if watched.read_bytes() != before:
                    return
            except OSError:
                pass
            time.sleep(0.0005)

    code, err = interrupt(model, work, old, first_change)
    kind = _check(work, old, new, code, err, 130)
    assert kind == "new", kind


def _first_temp_file(work: Path):
    def wait(proc):
        deadline = time.monotonic() + 300
        while time.monotonic() < deadline and proc.poll() is None:
            try:
                if any(n.endswith(".bake-tmp") for _, _, names in os.walk(work / "out") for n in names):
                    return
            except OSError:  # a file went while we looked
                pass
            time.sleep(0.0005)
    return wait


def test_sigint_while_outputs_are_staged_leaves_the_folder_old(rebake):
    model, work, old, new, _ = rebake
    code, err = interrupt(model, work, old, _first_temp_file(work))
    kind = _check(work, old, new, code, err, 130)
    print("SIGINT at the first temporary file:", code, kind)


def test_sigterm_cleans_up_like_ctrl_c(rebake):
    model, work, old, new, duration = rebake
    code, err = interrupt(model, work, old, 0.4 * duration, sig=signal.SIGTERM)
    kind = _check(work, old, new, code, err, 128 + signal.SIGTERM)
    if code not in (0, -signal.SIGTERM):
        assert code == 143 and "terminated" in err, (code, err)
    print("SIGTERM:", code, kind)
