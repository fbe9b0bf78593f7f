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


TMP_SUFFIX = ".bake-tmp"


def _same_bytes(path: Path, data: bytes) -> bool:
    try:
        return path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data
    except OSError:
        return False


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _umask()  # read once, at import (setting it is process-wide)


def _stage_temp(path: Path, data: bytes) -> Path:
    """Write ``data`` next to ``path`` under a temporary name, flushed to disk. The file gets the
    mode the target has, or a new file's usual mode (0o666 minus the umask) -- not mkstemp's 0o600,
    which the rename would otherwise hand on to the output."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        mode = path.stat().st_mode & 0o7777
    except OSError:
        mode = 0o666 & ~_UMASK
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=TMP_SUFFIX, dir=path.parent)
    try:
        try:
            os.fchmod(fd, mode)
        except OSError:  # a file system without modes keeps what it has
            pass
        with os.fdopen(fd, "wb") as f:
            f.write(data)
            f.flush()
            os.fsync(f.fileno())
    except BaseException:
        _unlink(Path(tmp))
        raise
    return Path(tmp)


def _unlink(p: Path) -> None:
    try:
        p.unlink()
    except OSError:
        pass


def write_atomic(path: Path, data: bytes) -> bool:
    """Write ``data`` to ``path`` atomically. Returns False if the file already had these bytes."""
    if _same_bytes(path, data):
        return False
    tmp = _stage_temp(path, data)
    try:
        os.replace(tmp, path)
    except BaseException:
        _unlink(tmp)
        raise
    return True


def remove_orphan_temps(out_dir: Path) -> int:
    """Temporary files left by a bake that was killed mid-write."""
    n = 0
    for p in Path(out_dir).rglob(f".*{TMP_SUFFIX}"):
        _unlink(p)
        n += 1
    return n


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
    remove_orphan_temps(out_dir)
    status: dict[str, str] = {}
    # phase 1: every changed file is written in full under a temporary name
    staged: list[tuple[Path, Path]] = []
    try:
        for rel in sorted(files):
            target = _safe_join(out_dir, rel)
            if target in protect:
                raise BakeError(f"refusing to overwrite the input file {target} (choose another --out)")
            if _same_bytes(target, files[rel]):
                status[rel] = "unchanged"
                continue
            staged.append((_stage_temp(target, files[rel]), target))
            status[rel] = "written"
        # phase 2: renames only (each atomic; together they take microseconds)
        for tmp, target in staged:
            os.replace(tmp, target)
    finally:
        for tmp, _ in staged:
            if tmp.exists():
                _unlink(tmp)
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
