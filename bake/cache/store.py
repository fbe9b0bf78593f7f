"""Where stage cache entries live: a folder (:class:`DiskStore`: ``<out>/.bake-cache/stages`` by
default, ``cache.dir`` to share one, ``"none"`` for none) with a size cap (``cache.max_mb``):
past it the least recently used entries are deleted (a hit touches its entry); or memory
(:class:`MemoryStore`: what ``bake sweep`` uses when the folder cache is off). A store holds
entries (``<key>.stage``) and the manifests of what stages read (``<base>.deps``) as opaque bytes;
``format.py`` says what is in them.
"""

from __future__ import annotations

import os
import time
from pathlib import Path

import numpy as np

from ..files import write_atomic
from .format import CacheError

ENTRY_SUFFIX = ".stage"
DEPS_SUFFIX = ".deps"
TMP_SUFFIX = ".cache-tmp"
SUBDIR = Path(".bake-cache") / "stages"


class DiskStore:
    """Entries and manifests as files in one folder, least recently used dropped past ``max_bytes``.

    ``lazy``: a folder (the output folder's cache) that, while it does not exist, must not be
    created by a bake that fails: writes wait in memory (readable) until :meth:`flush`, which
    ``output.finish`` calls once the outputs are written."""

    def __init__(self, root: Path, max_bytes: int, lazy: Path | None = None, label: str | None = None):
        self.root = Path(root)
        self.max_bytes = int(max_bytes)
        self.label = label or str(self.root)
        self.pending: list[tuple[str, list[bytes]]] | None = [] if lazy is not None and not Path(lazy).exists() \
            else None

    def describe(self) -> str:
        return self.label

    def _path(self, name: str) -> Path:
        return self.root / name

    def read(self, name: str) -> np.ndarray | None:
        for n, chunks in reversed(self.pending or []):
            if n == name:
                return np.frombuffer(bytearray(b"".join(chunks)), np.uint8)
        p = self._path(name)
        try:
            with open(p, "rb") as f:
                size = os.fstat(f.fileno()).st_size
                buf = np.empty(size, np.uint8)
                if f.readinto(memoryview(buf)) != size:
                    raise CacheError("is truncated")
        except FileNotFoundError:
            return None
        try:
            os.utime(p)  # least recently used goes first
        except OSError:
            pass
        return buf

    def write(self, name: str, chunks: list[bytes]) -> None:
        if self.pending is not None:
            self.pending.append((name, chunks))
            return
        # (not flushed to disk: an entry lost to a crash is computed again)
        write_atomic(self._path(name), chunks, suffix=TMP_SUFFIX, sync=False, keep_mode=False)

    def remove(self, name: str) -> None:
        try:
            self._path(name).unlink()
        except OSError:
            pass

    def flush(self) -> None:
        """Write what waited for the bake to succeed."""
        pending, self.pending = self.pending, None
        for name, chunks in pending or []:
            self.write(name, chunks)

    def trim(self) -> list[str]:
        """Delete least recently used files until the folder is within its cap (and temporary files
        of killed bakes older than an hour). Returns the names deleted."""
        try:
            items = list(os.scandir(self.root))
        except OSError:
            return []
        files, gone, now = [], [], time.time()
        for e in items:
            try:
                st = e.stat(follow_symlinks=False)
            except OSError:
                continue
            if e.name.endswith(TMP_SUFFIX):
                if now - st.st_mtime > 3600:
                    self.remove(e.name)
                continue
            if e.is_file(follow_symlinks=False) and e.name.endswith((ENTRY_SUFFIX, DEPS_SUFFIX)):
                files.append((st.st_mtime_ns, e.name, st.st_size))
        total = sum(f[2] for f in files)
        for _, name, size in sorted(files):
            if total <= self.max_bytes:
                break
            self.remove(name)
            gone.append(name)
            total -= size
        return gone


class MemoryStore:
    """The same as :class:`DiskStore`, in memory (one process: ``bake sweep`` with the cache off)."""

    def __init__(self) -> None:
        self.files: dict[str, bytes] = {}

    def describe(self) -> str:
        return "memory"

    def read(self, name: str) -> np.ndarray | None:
        b = self.files.get(name)
        return None if b is None else np.frombuffer(bytearray(b), np.uint8)

    def write(self, name: str, chunks: list[bytes]) -> None:
        self.files[name] = b"".join(chunks)

    def remove(self, name: str) -> None:
        self.files.pop(name, None)

    def flush(self) -> None:
        pass

    def trim(self) -> list[str]:
        return []
