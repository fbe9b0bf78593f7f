"""Putting a file on disk whole: the one atomic writer of outputs, caches, sweeps and lightmap caches.

A file is written to a temporary name in its own folder and renamed over the target
(``os.replace`` is atomic on POSIX), so a reader sees the old bytes or the new, never a part. A
file whose bytes are unchanged is not touched (``make`` sees an unchanged timestamp). The file gets
the target's mode, or a new file's usual mode (0o666 minus the umask), not mkstemp's 0o600.
:func:`signals_held` holds SIGINT, SIGTERM and SIGHUP while a set of renames completes.
"""

from __future__ import annotations

import contextlib
import os
import signal
import tempfile
import threading
from pathlib import Path
from typing import Iterable, Iterator

TMP_SUFFIX = ".bake-tmp"


def same_bytes(path: Path, data: bytes) -> bool:
    try:
        return path.is_file() and path.stat().st_size == len(data) and path.read_bytes() == data
    except OSError:
        return False


def _umask() -> int:
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


_UMASK = _umask()  # read once, at import (setting it is process-wide)


def stage_temp(path: Path, data: bytes | Iterable[bytes], *, suffix: str = TMP_SUFFIX, sync: bool = True,
               keep_mode: bool = True) -> Path:
    """Write ``data`` (bytes, or chunks of them) next to ``path`` under a temporary name ending in
    ``suffix``, flushed to disk when ``sync``. The file gets the mode the target has (``keep_mode``),
    or a new file's usual mode (0o666 minus the umask) -- not mkstemp's 0o600, which the rename
    would otherwise hand on to the output."""
    path.parent.mkdir(parents=True, exist_ok=True)
    try:
        if not keep_mode:
            raise OSError
        mode = path.stat().st_mode & 0o7777
    except OSError:
        mode = 0o666 & ~_UMASK
    fd, tmp = tempfile.mkstemp(prefix=f".{path.name}.", suffix=suffix, dir=path.parent)
    try:
        try:
            os.fchmod(fd, mode)
        except OSError:  # a file system without modes keeps what it has
            pass
        with os.fdopen(fd, "wb") as f:
            for chunk in ([data] if isinstance(data, (bytes, bytearray, memoryview)) else data):
                f.write(chunk)
            if sync:
                f.flush()
                os.fsync(f.fileno())
    except BaseException:
        unlink_quietly(Path(tmp))
        raise
    return Path(tmp)


def unlink_quietly(p: Path) -> None:
    try:
        p.unlink()
    except OSError:
        pass


def write_atomic(path: Path, data: bytes | Iterable[bytes], *, suffix: str = TMP_SUFFIX, sync: bool = True,
                 keep_mode: bool = True) -> bool:
    """Write ``data`` to ``path`` atomically. Returns False if the file already had these bytes
    (compared when ``data`` is one bytes object; chunks are always written: the stage cache's
    entries, whose names are their contents' keys). ``suffix``, ``sync``, ``keep_mode``: as
    :func:`stage_temp`."""
    whole = isinstance(data, (bytes, bytearray))
    if whole and same_bytes(path, bytes(data)):
        return False
    tmp = stage_temp(path, data, suffix=suffix, sync=sync, keep_mode=keep_mode)
    try:
        os.replace(tmp, path)
    except BaseException:
        unlink_quietly(tmp)
        raise
    return True


def remove_orphan_temps(out_dir: Path) -> int:
    """Temporary files left by a bake that was killed mid-write."""
    n = 0
    for p in Path(out_dir).rglob(f".*{TMP_SUFFIX}"):
        unlink_quietly(p)
        n += 1
    return n


# --------------------------------------------------------------------------- signals
HELD_SIGNALS = tuple(s for s in (getattr(signal, n, None) for n in ("SIGINT", "SIGTERM", "SIGHUP")) if s)


@contextlib.contextmanager
def signals_held() -> Iterator[None]:
    """Hold SIGINT, SIGTERM and SIGHUP until the block is done, then deliver the first one that
    came (Python runs signal handlers in the main thread whichever thread the kernel picked, so
    replacing the handlers holds them all). Off the main thread: no change."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    got: list[int] = []
    old = {}
    try:
        for s in HELD_SIGNALS:
            old[s] = signal.signal(s, lambda n, _f: got.append(n))
        yield
    finally:
        for s, h in old.items():
            signal.signal(s, h)
        if got:
            signal.raise_signal(got[0])


