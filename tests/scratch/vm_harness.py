"""Run projects in the real Scratch VM (vm/run.js: scratch-vm 5.0.300 + scratch-parser 6.0.1, Node).

Tests that need it take the ``vm`` fixture: it skips with the reason when ``node``/``npm`` are
missing or the pinned packages cannot be installed (``make vm/node_modules`` runs
``npm ci --prefix vm``; if that has not happened, the fixture tries it once).
"""

from __future__ import annotations

import functools
import json
import shutil
import subprocess
from pathlib import Path
from typing import Any

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[2]
VM_DIR = REPO / "vm"
RUN_JS = VM_DIR / "run.js"


@functools.lru_cache(maxsize=1)
def vm_unavailable() -> str | None:
    """Why the VM cannot run here, or None."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None:
        return "node is not installed (the Scratch VM tests need Node 18+ and npm)"
    if not (VM_DIR / "node_modules" / "scratch-vm").is_dir() or not (VM_DIR / "node_modules" / "scratch-parser").is_dir():
        if npm is None:
            return "npm is not installed and vm/node_modules is missing (run `make vm/node_modules`)"
        try:
            r = subprocess.run([npm, "ci", "--prefix", str(VM_DIR), "--no-audit", "--no-fund"],
                               capture_output=True, text=True, timeout=600)
        except (OSError, subprocess.TimeoutExpired) as e:
            return f"`npm ci --prefix vm` failed: {e}"
        if r.returncode != 0:
            return f"`npm ci --prefix vm` failed: {r.stderr.strip().splitlines()[-1:]}"
    try:
        out = subprocess.run([node, "--version"], capture_output=True, text=True, timeout=30).stdout
    except (OSError, subprocess.TimeoutExpired) as e:
        return f"node does not run: {e}"
    major = int(out.strip().lstrip("v").split(".")[0] or 0)
    if major < 18:
        return f"node {out.strip()} is too old (18+ needed)"
    return None


@pytest.fixture(scope="module")
def vm():
    reason = vm_unavailable()
    if reason:
        pytest.skip(reason)
    return run_plan


def run_plan(plan: dict[str, Any], timeout: float = 300) -> dict[str, Any]:
    """Run a plan (or ``{"jobs": [...]}``) through vm/run.js and return its JSON output."""
    r = subprocess.run(["node", str(RUN_JS), "--plan", "-"], input=json.dumps(plan), capture_output=True,
                       text=True, timeout=timeout, cwd=str(REPO))
    if not r.stdout.strip():
        raise AssertionError(f"vm/run.js printed nothing (exit {r.returncode}): {r.stderr[-2000:]}")
    out = json.loads(r.stdout)
    for res in out.get("jobs", [out]):
        if res.get("error"):
            raise AssertionError(f"vm/run.js failed: {res['error']}")
    return out


def call(target: str, proccode: str, *args: Any, lists: list[str] | None = None,
         variables: list[str] | None = None, pen: bool = False, set: dict[str, Any] | None = None) -> dict[str, Any]:
    """One run of a plan: set variables of the target (``set``), call a custom block, then read
    the given lists/variables."""
    run = {"call": {"target": target, "proccode": proccode, "args": [_arg(a) for a in args]},
           "read": {"lists": lists or [], "variables": variables or []}, "pen": pen}
    if set:
        run["set"] = {"target": target, "variables": {k: _arg(v) for k, v in set.items()}}
    return run


def camera_vars(cam) -> dict[str, Any]:
    """The reader's camera variables for a ``bake.scratch.readers.Camera``."""
    return {"cam x": cam.x, "cam y": cam.y, "cam z": cam.z, "cam yaw": cam.yaw, "cam pitch": cam.pitch,
            "focal": cam.focal, "near": cam.near}


def eye_vars(eye) -> dict[str, Any]:
    return {"cam x": float(eye[0]), "cam y": float(eye[1]), "cam z": float(eye[2])}


def _arg(a: Any) -> str:
    if isinstance(a, (float, np.floating)):
        return repr(float(a))
    if isinstance(a, (int, np.integer)):
        return str(int(a))
    return str(a)
