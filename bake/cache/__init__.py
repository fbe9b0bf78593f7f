"""The stage cache: each stage's output scene, stored under a key that hashes everything it depends on.

A bake is a chain of pure stages, so the scene after a stage is determined by the tool, the input
files and the config sections of the stages up to it. A bake loads the entry of the deepest stage
whose key it can build and finds, and runs the rest (``bake.pipeline.run``); a cold stage's output
is stored. Parts of a stage's work that depend on less than the stage's key (the lighting trace,
the BSP tree, the previews' geometry) are memos in the same store.

Which module does what:

* ``keys.py``: what a key hashes -- the tool fingerprint (every ``bake/**/*.py`` file, the
  libraries' versions, Python, the machine), file and folder-listing digests, canonical config
  sections, and :func:`~bake.cache.keys.digest`, which chains them.
* ``format.py``: the entry format (:func:`encode_entry`, :func:`decode_entry`: magic, a JSON
  header, aligned raw blobs, a checksum; no pickle), :class:`CacheError` for an entry that cannot
  be used, :class:`Unsupported` for a value it does not store, and :func:`content_digest`.
* ``store.py``: where entries live: :class:`DiskStore` (a folder with a size cap, least recently
  used dropped; ``SUBDIR`` in the output folder by default) and :class:`MemoryStore`.
* ``session.py``: :class:`StageCache` (the store a config asks for) and the ``Session`` of one
  bake: the key chain, the ``.deps`` manifests of what stages read, which entry to load, what to
  store.
* ``memo.py``: :class:`Memo`, memos of work inside stages, and the memo store of the running
  stage (:func:`active_memo`, :func:`using_memo`).

The pipeline uses :class:`StageCache`, :class:`Memo` and :func:`using_memo`; stages use
:func:`active_memo`, :func:`content_digest` and :class:`Unsupported`.
"""

from __future__ import annotations

from .format import CacheError, Unsupported, content_digest, decode_entry, encode_entry
from .memo import Memo, active_memo, using_memo
from .session import StageCache
from .store import DEPS_SUFFIX, ENTRY_SUFFIX, SUBDIR, DiskStore, MemoryStore

__all__ = ["CacheError", "DEPS_SUFFIX", "DiskStore", "ENTRY_SUFFIX", "Memo", "MemoryStore", "SUBDIR", "StageCache",
           "Unsupported", "active_memo", "content_digest", "decode_entry", "encode_entry", "using_memo"]
