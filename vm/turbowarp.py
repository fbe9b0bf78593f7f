"""Python side of the TurboWarp harness (vm/player.js): run .sb3 files in TurboWarp's real player
in headless Chromium, compiled or interpreted; the stage image, the seconds, the errors.

Tests and benchmarks import it with the vm folder on the path::

    sys.path.insert(0, str(REPO / "vm"))
    import turbowarp

    why = turbowarp.unavailable()            # None, or why it cannot run here (skip with it)
    res = turbowarp.run(["a.sb3", "b.sb3"], modes=("compiled", "interpreted"), repeat=3)
    for r in res.results:                    # one per project and mode, in that order
        r.id, r.mode, r.seconds, r.step_seconds   # per run: green flag -> every script stopped
        r.image                              # (360, 480, 3) uint8 stage after the last run
        r.problems()                         # errors, a script still running, a blank stage

``run`` raises :class:`PlayerError` when the harness itself fails (not when a project does: that
is in ``r.errors``). See vm/README.md.
"""

from __future__ import annotations

import functools
import io
import json
import os
import shutil
import subprocess
import tempfile
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Sequence

import numpy as np

VM_DIR = Path(__file__).resolve().parent
PLAYER_JS = VM_DIR / "player.js"
PACKAGES = ("@turbowarp/packager", "puppeteer-core")


class PlayerError(RuntimeError):
    pass


def chromium(install: bool | None = None) -> str | None:
    """Debian's chromium: found on PATH (or $CHROMIUM), else installed with apt-get when this
    runs as root (as `make test` on CI does; BAKE_TEST_INSTALL_CHROMIUM=0 turns that off)."""
    given = os.environ.get("CHROMIUM")
    if given and os.access(given, os.X_OK):
        return given
    found = shutil.which("chromium") or shutil.which("chromium-browser")
    if install is None:
        install = os.environ.get("BAKE_TEST_INSTALL_CHROMIUM", "1") != "0"
    if found or not install:
        return found
    if hasattr(os, "geteuid") and os.geteuid() == 0 and shutil.which("apt-get"):
        env = dict(os.environ, DEBIAN_FRONTEND="noninteractive")
        try:
            subprocess.run(["apt-get", "update", "-qq"], env=env, capture_output=True, timeout=300)
            subprocess.run(["apt-get", "install", "-y", "-qq", "chromium"], env=env, capture_output=True,
                           timeout=900)
        except (OSError, subprocess.TimeoutExpired):
            return None
    return shutil.which("chromium")


@functools.lru_cache(maxsize=1)
def unavailable() -> str | None:
    """Why TurboWarp cannot run here (node, the pinned npm packages, chromium), or None. Installs
    what is missing the way `make test` does: `npm ci --prefix vm`, Debian's chromium."""
    node, npm = shutil.which("node"), shutil.which("npm")
    if node is None:
        return "node is not installed (the TurboWarp tests need Node 18+ and npm)"
    if not all((VM_DIR / "node_modules" / p / "package.json").is_file() for p in PACKAGES):
        if npm is None:
            return "npm is not installed and vm/node_modules lacks the TurboWarp packages (run `make vm/node_modules`)"
        try:
            r = subprocess.run([npm, "ci", "--prefix", str(VM_DIR), "--no-audit", "--no-fund"],
                               capture_output=True, text=True, timeout=900)
        except (OSError, subprocess.TimeoutExpired) as e:
            return f"`npm ci --prefix vm` failed: {e}"
        if r.returncode != 0:
            return f"`npm ci --prefix vm` failed: {r.stderr.strip().splitlines()[-1:]}"
    if chromium() is None:
        return "chromium is not installed and could not be installed (apt-get install chromium, as root)"
    return None


@dataclass
class Result:
    id: str
    file: str
    mode: str  # "compiled" | "interpreted"
    runs: list[dict]
    errors: list[str]
    stage: tuple[int, int] | None
    snapshot: str | None
    lists: dict[str, list] = field(default_factory=dict)
    variables: dict[str, Any] = field(default_factory=dict)
    runtime_options: dict[str, Any] = field(default_factory=dict)  # the VM's, after the last run
    image: np.ndarray | None = None  # (H, W, 3) uint8, the stage after the last run

    @property
    def seconds(self) -> list[float]:
        """Per run: green flag (or call) to the end of the step after which no script ran."""
        return [r["seconds"] for r in self.runs]

    @property
    def step_seconds(self) -> list[float]:
        """Per run: the time spent inside those steps (no waiting for frames, no redraws)."""
        return [r["stepSeconds"] for r in self.runs]

    @property
    def done(self) -> bool:
        return bool(self.runs) and all(r["done"] and r["running"] == 0 for r in self.runs)

    def blank(self) -> bool:
        """Nothing but one colour on the stage, the backdrop's (or no image)."""
        return self.image is None or not np.any(np.any(self.image != self.image[0, 0], axis=2))

    def problems(self) -> list[str]:
        """What a person would call broken: errors, a script still running, a blank stage."""
        out = list(self.errors)
        if not self.runs:
            out.append("the project did not run")
        elif not self.done:
            out.append(f"a script was still running ({self.runs[-1]['running'] if self.runs else '?'} threads)")
        if self.blank():
            out.append("the stage is blank")
        return out


@dataclass
class Run:
    versions: dict[str, Any]
    results: list[Result]

    def get(self, id: str, mode: str) -> Result:
        return next(r for r in self.results if r.id == id and r.mode == mode)


def run(projects: Sequence[str | Path | tuple[str, str | Path]], *, modes: Sequence[str] = ("compiled", "interpreted"),
        repeat: int = 1, action: dict | None = None, read: dict | None = None, timeout_ms: int = 120_000,
        snapshots: str | Path | None = None, timeout: float = 3600, interleave: bool = False) -> Run:
    """Run each project (a path, or ``(id, path)``) in each mode, ``repeat`` times; the stage image
    after the last run. ``action``: ``{"greenFlag": True}`` (default) or ``{"call": {"target",
    "proccode", "args"}}``; ``read``: ``{"target", "lists", "variables"}`` read after the last run.
    ``interleave``: open every page first, then run each once per round, so that timings of
    different projects are taken side by side under the same machine load."""
    items = [(p[0], Path(p[1])) if isinstance(p, tuple) else (Path(p).stem, Path(p)) for p in projects]
    with tempfile.TemporaryDirectory(prefix="bake-tw-") as tmp:
        plan = {"projects": [{"file": str(p.resolve()), "id": i} for i, p in items], "modes": list(modes),
                "repeat": int(repeat), "timeoutMs": int(timeout_ms), "interleave": bool(interleave),
                "snapshots": str(Path(snapshots).resolve()) if snapshots else str(Path(tmp) / "shots")}
        if action:
            plan["action"] = action
        if read:
            plan["read"] = read
        exe = chromium()
        if exe:
            plan["chromium"] = exe
        r = subprocess.run(["node", str(PLAYER_JS), "--plan", "-"], input=json.dumps(plan), capture_output=True,
                           text=True, timeout=timeout, cwd=str(VM_DIR))
        if not r.stdout.strip():
            raise PlayerError(f"vm/player.js printed nothing (exit {r.returncode}): {r.stderr[-2000:]}")
        out = json.loads(r.stdout)
        if out.get("error"):
            raise PlayerError(f"vm/player.js failed: {out['error']}")
        results = []
        for x in out["results"]:
            res = Result(id=x["id"], file=x["file"], mode=x["mode"], runs=x["runs"], errors=x["errors"],
                         stage=tuple(x["stage"]) if x.get("stage") else None,
                         snapshot=x["snapshot"] if snapshots else None, lists=x.get("lists") or {},
                         variables=x.get("variables") or {}, runtime_options=x.get("runtimeOptions") or {})
            if x.get("snapshot") and Path(x["snapshot"]).is_file():
                res.image = read_png(Path(x["snapshot"]).read_bytes())
            results.append(res)
    return Run(versions=out["versions"], results=results)


def read_png(data: bytes) -> np.ndarray:
    """(H, W, 3) uint8 of a stage snapshot, composited on white (the canvas may be transparent
    where nothing is drawn; TurboWarp's stage shows white there)."""
    from PIL import Image

    im = Image.open(io.BytesIO(data)).convert("RGBA")
    a = np.asarray(im).astype(np.float64)
    rgb, alpha = a[..., :3], a[..., 3:4] / 255.0
    return np.clip(np.rint(rgb * alpha + 255.0 * (1 - alpha)), 0, 255).astype(np.uint8)
