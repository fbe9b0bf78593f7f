"""Ctrl-C during simplify (issue 18, item 3): exit 130 every time, no crash, outputs untouched.

The simplify stage spreads its biggest KD-tree queries over Python worker threads (scipy's
``cKDTree.query(..., workers=-1)``). Before the fix, Ctrl-C raised KeyboardInterrupt inside the
join of those threads: the main thread unwound and freed the arrays the workers were still
writing, and the process died with SIGSEGV after printing "bake: interrupted" (3 of 8 tries in
the issue). Both tests send a real SIGINT to a real subprocess:

* one interrupts a large threaded query directly (deterministic: before the fix it crashed
  every time);
* one interrupts ``bake run`` as a user would, at several moments spread over the simplify
  stage, and checks the exit status, stderr and that the previous outputs are byte for byte
  what they were.
"""

from __future__ import annotations

import hashlib
import json
import os
import re
import pty
import select
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest

from conftest import REPO, corpus_path, sigint_default

CRASH = ("Fatal Python error", "Segmentation fault", "core dumped")


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(REPO) + os.pathsep + env.get("PYTHONPATH", "")
    env["PYTHONFAULTHANDLER"] = "1"  # a crash prints "Fatal Python error" (and is seen below)
    env["BAKE_PROGRESS_AFTER"] = "0"  # the progress bar names each stage as it starts
    return env


def test_sigint_during_a_threaded_query_exits_cleanly(tmp_path):
    child = tmp_path / "child.py"
    child.write_text(
        "import sys\n"
        "import numpy as np\n"
        "from scipy.spatial import cKDTree\n"
        "from bake.mesh.simplify.error import _kd_query\n"
        "rng = np.random.default_rng(0)\n"
        "tree = cKDTree(rng.random((300000, 3)))\n"
        "P = rng.random((400000, 3))\n"
        "print('ready', flush=True)\n"
        "try:\n"
        "    while True:\n"
        "        _kd_query(tree, P, True, k=8)  # the stage's threaded query, long enough to be hit\n"
        "except KeyboardInterrupt:\n"
        "    print('interrupted', file=sys.stderr)\n"
        "    sys.exit(130)\n")
    for delay in (0.3, 0.7, 1.1):
        p = subprocess.Popen([sys.executable, str(child)], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                             env=_env(), cwd=tmp_path, preexec_fn=sigint_default)
        assert p.stdout.readline().strip() == b"ready"
        time.sleep(delay)
        p.send_signal(signal.SIGINT)
        _, err = p.communicate(timeout=120)
        err = err.decode(errors="replace")
        assert p.returncode == 130 and "interrupted" in err, (delay, p.returncode, err[-800:])
        assert not any(c in err for c in CRASH), err[-800:]


def _snapshot(folder: Path) -> dict:
    return {str(f.relative_to(folder)): hashlib.sha256(f.read_bytes()).hexdigest()
            for f in sorted(folder.rglob("*")) if f.is_file()}


class _Terminal:
    """``bake run`` on a pseudo-terminal, as a user at a terminal runs it: bake shows its
    "bake: <stage> ..." status line there, so the test sees when simplify starts."""

    def __init__(self, argv: list[str], cwd: Path):
        master, slave = pty.openpty()
        self.p = subprocess.Popen(argv, stdin=slave, stdout=slave, stderr=slave, env=_env(), cwd=cwd,
                                  close_fds=True, preexec_fn=sigint_default)
        os.close(slave)
        self.fd = master
        self.text = ""

    def read(self, seconds: float) -> str:
        end = time.monotonic() + seconds
        while True:
            left = end - time.monotonic()
            if left <= 0:
                return self.text
            r, _, _ = select.select([self.fd], [], [], left)
            if not r:
                return self.text
            try:
                chunk = os.read(self.fd, 65536)
            except OSError:  # the child closed the terminal
                return self.text
            if not chunk:
                return self.text
            self.text += chunk.decode(errors="replace")

    @property
    def plain(self) -> str:
        """What was printed, without the terminal's colour and cursor codes."""
        return re.sub(r"\x1b\[[0-9;?]*[A-Za-z]", "", self.text)

    def wait_for(self, needle: str, timeout: float) -> bool:
        end = time.monotonic() + timeout
        while needle not in self.plain and time.monotonic() < end and self.p.poll() is None:
            self.read(0.05)
        return needle in self.plain

    def finish(self, timeout: float = 900) -> int:
        end = time.monotonic() + timeout
        while self.p.poll() is None and time.monotonic() < end:
            self.read(0.1)
        self.read(0.2)
        os.close(self.fd)
        return self.p.wait(timeout=5)


@pytest.mark.corpus
def test_ctrl_c_during_simplify_exits_130_and_leaves_outputs(tmp_path):
    model = corpus_path("stanford_bunny_res1_obj", "stanford-bunny.obj")
    config = tmp_path / "bunny.toml"
    config.write_text(f'[input]\npath = "{model.as_posix()}"\n\n'
                      "[mesh.simplify]\nenabled = true\ntarget_triangles = 2000\nerror_samples = 60000\n"
                      '[cache]\ndir = "none"\n')  # every rerun simplifies again (no stage cache)
    out = tmp_path / "out"
    bake = [sys.executable, "-c", "import sys; from bake.cli import main; sys.exit(main())", "run", str(config),
            "--out", str(out)]
    done = subprocess.run(bake, capture_output=True, env=_env(), cwd=tmp_path, timeout=900)
    assert done.returncode == 0, done.stderr.decode()[-2000:]
    length = next(st["seconds"] for st in json.loads((out / "report.json").read_text())["stages"]
                  if st["name"] == "simplify")
    snapshot = _snapshot(out)
    assert snapshot
    hits = 0
    for f in (0.05, 0.2, 0.35, 0.5, 0.65, 0.8):
        term = _Terminal(bake, tmp_path)
        assert term.wait_for("bake: simplify", 300), term.text[-2000:]
        seen = len(term.plain)
        term.read(f * length)
        during = "bake: export" not in term.plain[seen:] and term.p.poll() is None
        term.p.send_signal(signal.SIGINT)  # what Ctrl-C at the terminal sends
        code = term.finish()
        if code == 0 and not during:
            # the signal came after this bake had finished (a rerun on a machine whose load
            # dropped can be faster than the first run that set the timing): not a miss of the
            # interrupt handling, but no hit either (the count below still asks for 4 of 6)
            assert "bake: interrupted" not in term.plain, term.plain[-1500:]
            continue
        hits += during
        assert code == 130, (f, code, term.text[-1500:])
        assert "bake: interrupted" in term.plain and not any(c in term.plain for c in CRASH), term.plain[-1500:]
        if during:
            assert _snapshot(out) == snapshot, f"outputs changed by a bake interrupted at {f:.0%} of simplify"
    assert hits >= 4, f"only {hits} of 6 interrupts landed during simplify"
    assert not list(tmp_path.glob("core*"))
