"""Putting outputs on disk: atomically, only when their bytes change, nothing half-written.

Every file is written to a temporary name in its own folder, flushed, and renamed over the
target (``os.replace`` is atomic on POSIX). A file whose bytes are unchanged is not touched,
so ``make`` sees an unchanged timestamp. A manifest (``.bake-manifest.json``) remembers what the
last bake wrote, so files a previous bake wrote and this one no longer produces are removed —
files the user put in the folder are never touched.
"""

from __future__ import annotations

import json
import os
import tempfile
from pathlib import Path

from ..errors import BakeError

MANIFEST = ".bake-manifest.json"


def write_atomic(path: Path, data: bytes) -> bool:
    """Write ``data`` to ``path`` atomically. Returns False if the file already had these bytes."""
    try:
        if path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data:
            return False
    except OSError:
        pass
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=".tmp", dir=path.parent)
    try:
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        try:
            os.unlink(tmp)
        except OSError:
            pass
        raise
    return True


def _safe_join(root: Path, rel: str) -> Path:
    p = (root / rel).resolve()
    if root.resolve() not in p.parents and p != root.resolve():
        raise BakeError(f"refusing to write outside the output folder: {rel}")
    return p


def write_outputs(out_dir: Path, files: dict[str, bytes], *, protect: set[Path] | None = None,
                  also_ours: tuple[str, ...] = ()) -> dict[str, str]:
    """Write ``files`` (relative path -> bytes) under ``out_dir``. Returns path -> "written" |
    "unchanged" | "removed". ``protect`` holds input files that must never be overwritten;
    ``also_ours`` names files written separately (the report) that the manifest lists and
    that must not be removed as stale."""
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    protect = {p.resolve() for p in (protect or set())}
    status: dict[str, str] = {}
    for rel in sorted(files):
        target = _safe_join(out_dir, rel)
        if target in protect:
            raise BakeError(f"refusing to overwrite the input file {target} (choose another --out)")
        status[rel] = "written" if write_atomic(target, files[rel]) else "unchanged"
    # remove what the previous bake wrote and this one did not
    man = out_dir / MANIFEST
    try:
        previous = json.loads(man.read_text("utf-8")).get("files", [])
    except (OSError, ValueError, AttributeError):
        previous = []
    for rel in previous:
        if isinstance(rel, str) and rel not in files and rel not in also_ours:
            try:
                p = _safe_join(out_dir, rel)
                if p.is_file() and p not in protect:
                    p.unlink()
                    status[rel] = "removed"
            except (OSError, BakeError):
                pass
    write_atomic(man, json.dumps({"files": sorted(set(files) | set(also_ours))}, indent=1).encode())
    return status


def make_escape(p: str | Path) -> str:
    return str(p).replace("\\", "\\\\").replace(" ", "\\ ").replace("#", "\\#").replace("$", "$$")


def depfile_text(targets: list[Path], deps: list[Path]) -> str:
    """Make-style dependency rule: every target depends on every input read."""
    t = " ".join(make_escape(p) for p in targets)
    d = " \\\n  ".join(make_escape(p) for p in deps)
    # empty rules for each dependency so a deleted input does not break make
    phony = "".join(f"\n{make_escape(p)}:\n" for p in deps)
    return f"{t}: \\\n  {d}\n{phony}"
