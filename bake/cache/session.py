"""The stage cache during a bake: which entries to load and which to store.

A bake is a chain of pure stages ``(scene, section) -> (scene, record)``, so the scene after stage
*i* is determined by the tool, the input files and the config sections of stages 1..i. The key of
stage *i* chains exactly that (the digests are ``keys.py``'s)::

    root    = H(cache format, tool fingerprint)
    base_i  = H(key_{i-1} (root for the first stage), stage name, canonical JSON of its section)
    key_i   = H(base_i, sha256 of every file the stage read, names of the model files in their folders)

A stage's *files* are what it added to ``Scene.source.files_read`` (the model, .mtl, textures,
glTF buffers, ``textures.texture``, the project of ``export.into``) plus material texture paths;
which files a stage reads is only known once it ran, so ``<base>.deps`` (a small manifest)
remembers the list from the last run and the lookup hashes those files' current bytes. A stage
that now reads other files (an edited .mtl naming another texture) changed one of the listed
files, so its key changes and it runs again. The names of the ``.mtl``/``.bin``/image files in
each folder a stage read from are part of the key too, so a texture or .mtl that was missing and
appears later is noticed.

A bake loads the entry of the deepest stage whose key it can build and finds
(:meth:`Session.load_deepest`), and runs the rest (``bake.pipeline.run``); a cold stage's output
is stored (:meth:`Session.store_stage`). Entries hold the records of every stage up to theirs, so
the report of a cached bake has the same counts, accuracy figures and warnings.
"""

from __future__ import annotations

import json
import os
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable

from . import keys
from .format import FORMAT, CacheError, Unsupported, decode_entry, encode_entry
from .keys import canonical, digest, file_digest, listing_digest
from .store import DEPS_SUFFIX, ENTRY_SUFFIX, SUBDIR, DiskStore, MemoryStore


@dataclass
class Step:
    """One stage on the key chain of a bake."""

    name: str
    base: str
    key: str | None  # None: no manifest yet (the stage never ran with this base)
    covered: frozenset[str]  # files whose bytes are in this key (this stage's and earlier ones')


@dataclass
class Hit:
    index: int  # the stage whose entry was loaded
    scene: Any
    records: list
    seconds: float


@dataclass
class StageCache:
    """One cache (a folder or memory). :meth:`session` starts a bake's walk along the chain."""

    store: Any

    @classmethod
    def for_config(cls, cfg: Any) -> "StageCache | None":
        """The folder cache a config asks for: ``cache.dir`` (relative to the config file), else
        ``<output folder>/.bake-cache/stages`` when the bake has an output folder; None for
        ``cache.dir = "none"`` or no folder."""
        c = cfg.cache
        d = c.dir.strip()
        if d.lower() == "none":
            return None
        if d:
            root = Path(d).expanduser()
            if not root.is_absolute():
                root = Path(cfg.base_dir) / root
        elif cfg.out_dir is not None:  # a failed first bake into a new folder must not create it
            return cls(DiskStore(Path(cfg.out_dir) / SUBDIR, int(c.max_mb * 1024 * 1024),
                                 lazy=Path(cfg.out_dir) / SUBDIR, label=SUBDIR.as_posix()))  # (the report names it within the folder)
        else:
            return None
        return cls(DiskStore(root, int(c.max_mb * 1024 * 1024)))

    @classmethod
    def in_memory(cls) -> "StageCache":
        return cls(MemoryStore())

    def session(self) -> "Session":
        return Session(self.store)


class Session:
    """One bake's use of the cache: the key chain, the lookup and the stores."""

    def __init__(self, store: Any):
        self.store = store
        self.started_ns = time.time_ns()  # inputs modified after this are not trusted to be cached
        self.root = digest("scratch-bake stage cache", FORMAT, keys.tool_fingerprint())
        self._digests: dict[str, str] = {}
        self._stats: dict[str, tuple] = {}  # (mtime, size, inode) when the digest was taken
        self._listings: dict[str, str] = {}
        self.warnings: list[str] = []
        self.stored: list[str] = []
        self.broken = False  # an input changed during the bake: store nothing more

    # ------------------------------------------------------------ keys
    def _digest(self, path: str) -> str:
        d = self._digests.get(path)
        if d is None:
            self._stats[path] = _stat(path)
            d = self._digests[path] = file_digest(path)
        return d

    def _changed(self, path: str) -> bool:
        """Did ``path`` change while this bake used it? Its (mtime, size, inode) moved since its
        digest was taken, or (a file first hashed after the stage that read it) it was modified
        after the bake started (an mtime in the future is clock skew, not a change)."""
        now = _stat(path)
        if path in self._stats:
            return now != self._stats[path]
        return now is not None and self.started_ns <= now[0] <= time.time_ns()

    def _listing(self, folder: str) -> str:
        d = self._listings.get(folder)
        if d is None:
            d = self._listings[folder] = listing_digest(folder)
        return d

    def base(self, prev: str | None, name: str, section: Any) -> str:
        return digest("stage", prev or self.root, name, canonical(section))

    def key(self, base: str, files: Iterable[str], dirs: Iterable[str]) -> str:
        return digest(base, [[f, self._digest(f)] for f in files], [[d, self._listing(d)] for d in dirs])

    def _read_deps(self, base: str) -> dict | None:
        name = base + DEPS_SUFFIX
        try:
            buf = self.store.read(name)
        except (OSError, CacheError) as e:
            self.warnings.append(f"stage cache: cannot read {name} ({e}); ignored")
            return None
        if buf is None:
            return None
        try:
            d = json.loads(buf.tobytes().decode("utf-8"))
            if not (isinstance(d, dict) and d.get("format") == FORMAT and d.get("base") == base
                    and all(isinstance(x, str) for x in d.get("files", [None]))
                    and all(isinstance(x, str) for x in d.get("dirs", [None]))):
                raise ValueError("not a manifest of this key")
        except (UnicodeDecodeError, ValueError) as e:
            self.warnings.append(f"stage cache: {self._where(name)} is not a valid manifest ({e}); ignored")
            self.store.remove(name)
            return None
        return d

    def _where(self, name: str) -> str:
        root = getattr(self.store, "root", None)
        return str(root / name) if root is not None else name

    def plan(self, stages: list[tuple[str, Any]]) -> list[Step]:
        """The chain as far as keys can be built: one step per stage until a stage without a
        manifest (it must run to say what it reads), included with ``key = None``."""
        steps: list[Step] = []
        prev: str | None = None
        covered: frozenset[str] = frozenset()
        for name, section in stages:
            base = self.base(prev, name, section)
            deps = self._read_deps(base)
            if deps is None:
                steps.append(Step(name, base, None, covered))
                break
            covered = covered | set(deps["files"])
            key = self.key(base, deps["files"], deps["dirs"])
            steps.append(Step(name, base, key, covered))
            prev = key
        return steps

    # ------------------------------------------------------------ lookup
    def load_deepest(self, steps: list[Step], limit: int) -> Hit | None:
        """The entry of the deepest step before ``limit`` that loads; bad entries are removed
        with a warning and the next shallower one is tried."""
        for i in range(min(limit, len(steps)) - 1, -1, -1):
            st = steps[i]
            if st.key is None:
                continue
            t = time.perf_counter()
            name = st.key + ENTRY_SUFFIX
            try:
                buf = self.store.read(name)
                if buf is None:
                    continue
                payload = decode_entry(buf, st.key, st.name)
                if not (isinstance(payload, dict) and isinstance(payload.get("records"), list)
                        and len(payload["records"]) >= 1 and payload.get("scene") is not None):
                    raise CacheError("does not hold a scene and its records")
                _check_payload(payload, [s.name for s in steps[:i + 1]])
            except (CacheError, OSError, ValueError, TypeError, AttributeError) as e:
                self.warnings.append(f"stage cache: the {st.name} entry {self._where(name)} {e}; ignored, "
                                     f"the stage runs again")
                self.store.remove(name)
                continue
            return Hit(i, payload["scene"], payload["records"], time.perf_counter() - t)
        return None

    # ------------------------------------------------------------ store
    def deferred(self) -> bool:
        return bool(getattr(self.store, "pending", None))

    def deps_of(self, scene: Any, covered: frozenset[str]) -> list[str]:
        """Files the scene says were read or looked for and not found (and material textures) not
        already in the chain: a missing file's digest is "missing" until it appears."""
        paths = {os.path.abspath(p) for p in getattr(scene.source, "files_read", ())}
        paths |= {os.path.abspath(p) for p in getattr(scene.source, "files_missing", ())}
        paths |= {os.path.abspath(m.texture) for m in scene.materials if getattr(m, "texture", None)}
        return sorted(paths - covered)

    def store_stage(self, name: str, base: str, covered: frozenset[str], scene: Any,
                    records: list) -> tuple[str | None, frozenset[str], str | None]:
        """Store a stage that just ran. Returns (its key, the files covered so far, a warning)."""
        if self.broken:
            return None, covered, None
        files = self.deps_of(scene, covered)
        for f in files:
            if self._changed(f):
                self.broken = True
                return None, covered, (f"stage cache: {f} changed during the bake; this bake's stages from "
                                       f"{name} on are not cached")
        dirs = sorted({os.path.dirname(f) for f in files})
        key = self.key(base, files, dirs)
        covered = covered | set(files)
        warning = None
        try:
            chunks = encode_entry(key, name, {"scene": scene, "records": records})
        except (Unsupported, RecursionError) as e:
            return key, covered, f"stage cache: the {name} stage's output holds {e}; not cached"
        manifest = json.dumps({"format": FORMAT, "base": base, "stage": name, "files": files, "dirs": dirs},
                              indent=1).encode("utf-8")
        try:
            self.store.write(key + ENTRY_SUFFIX, chunks)
            self.store.write(base + DEPS_SUFFIX, [manifest])
            self.stored.append(name)
        except OSError as e:
            warning = f"stage cache: cannot write to {self.store.describe()} ({e.strerror or e}); not cached"
        return key, covered, warning

    def finish(self) -> list[str]:
        """The bake succeeded: write what waited, then keep the store under its cap. Returns the
        names of the entries dropped."""
        try:
            self.store.flush()
        except OSError as e:
            self.warnings.append(f"stage cache: cannot write to {self.store.describe()} ({e.strerror or e}); "
                                 "not cached")
            self.stored.clear()
        try:
            return self.store.trim()
        except OSError:
            return []


def _stat(path: str) -> tuple | None:
    try:
        st = os.stat(path)
    except OSError:
        return None
    return (st.st_mtime_ns, st.st_size, st.st_ino)


def _check_payload(payload: dict, names: list[str]) -> None:
    """The loaded objects are what the pipeline's stages return (not merely well-formed data): a
    consistent scene and one record per stage of the chain so far."""
    from ..record import StageRecord
    from ..scene import Scene

    scene = payload["scene"]
    if not isinstance(scene, Scene):
        raise CacheError("does not hold a scene")
    recs = payload["records"]
    if not all(isinstance(r, StageRecord) for r in recs) or [r.name for r in recs] != names:
        raise CacheError("does not hold the records of this chain of stages")
    try:
        scene.validate()
    except AssertionError as e:
        raise CacheError(f"holds an inconsistent scene ({e or 'validate failed'})") from None
