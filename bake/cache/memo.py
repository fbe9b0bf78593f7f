"""Memos of work inside stages (:class:`Memo`): parts of a stage's work keyed by less than the
stage's key, reused when the stage must run again -- the lighting trace (not the exposure or tone
map), the BSP tree (not the colours), the previews' geometry. They are entries of the stage
cache's store, in the same format. The stage names what the part depends on; the bake gets the
same bytes as a cold one. The running stage finds its memo store with :func:`active_memo`.
"""

from __future__ import annotations

import contextlib
import contextvars
from typing import Any

from . import keys
from .format import FORMAT, CacheError, Unsupported, content_digest, decode_entry, encode_entry
from .keys import digest
from .store import ENTRY_SUFFIX


class Memo:
    """Results that a stage (or the report) can reuse when the stage must run again but part of its
    work depends on less than the stage's key: the BSP tree, which depends on the geometry and the
    merge groups and not on the lit colours (bake/bsp/stage.py); the previews' renders, which
    depend on the written geometry, the draw order and the camera and not on the colours
    (bake/outputs/preview.py). The caller names everything the result depends on
    (:meth:`key`: the cache format, the tool fingerprint, a kind and those values' digest). Memos
    are entries of the stage cache's store (same format, checks, size cap and LRU); a damaged one
    is dropped with a warning and recomputed."""

    def __init__(self, store: Any):
        self.store = store
        self.warnings: list[str] = []
        self.reused: list[str] = []
        self.stored: list[str] = []

    def key(self, kind: str, *parts: Any) -> str:
        return digest("memo", FORMAT, keys.tool_fingerprint(), kind, content_digest(*parts))

    def _where(self, name: str) -> str:
        root = getattr(self.store, "root", None)
        return str(root / name) if root is not None else name

    def get(self, kind: str, key: str, accept: Any = None, what: str = "") -> Any:
        """The memo stored under ``key``, or None. ``accept(payload)`` gives the value to use, or
        None for a payload that is not what this memo holds (then it is dropped with a warning
        naming ``what``). The caller says when it really used one (:meth:`used`)."""
        name = key + ENTRY_SUFFIX
        try:
            buf = self.store.read(name)
            if buf is None:
                return None
            out = decode_entry(buf, key, "memo " + kind)
        except (CacheError, OSError, ValueError, TypeError, AttributeError) as e:
            self.forget(kind, key, str(e))
            return None
        if accept is not None:
            out = accept(out)
            if out is None:
                self.forget(kind, key, f"does not hold {what}")
        return out

    def used(self, kind: str) -> None:
        """A memo of ``kind`` was reused (``report.json``: ``cache.memos_reused``)."""
        self.reused.append(kind)

    def forget(self, kind: str, key: str, why: str) -> None:
        name = key + ENTRY_SUFFIX
        self.warnings.append(f"stage cache: the {kind} memo {self._where(name)} {why}; ignored, computed again")
        self.store.remove(name)

    def put(self, kind: str, key: str, payload: Any) -> None:
        try:
            self.store.write(key + ENTRY_SUFFIX, encode_entry(key, "memo " + kind, payload))
            self.stored.append(kind)
        except (Unsupported, RecursionError) as e:
            self.warnings.append(f"stage cache: the {kind} memo holds {e}; not cached")
        except OSError as e:
            self.warnings.append(f"stage cache: cannot write to {self.store.describe()} ({e.strerror or e}); "
                                 "not cached")

    def take_warnings(self) -> list[str]:
        out, self.warnings = self.warnings, []
        return out


_ACTIVE_MEMO: "contextvars.ContextVar[Memo | None]" = contextvars.ContextVar("bake_memo", default=None)


def active_memo() -> Memo | None:
    """The memo store of the stage that is running (None: no cache, or a stage whose time a sweep
    measures)."""
    return _ACTIVE_MEMO.get()


@contextlib.contextmanager
def using_memo(memo: Memo | None):
    token = _ACTIVE_MEMO.set(memo)
    try:
        yield memo
    finally:
        _ACTIVE_MEMO.reset(token)
