"""The stage cache: each stage's output scene, stored under a key that hashes everything it depends on.

A bake is a chain of pure stages ``(scene, section) -> (scene, record)``, so the scene after stage
*i* is determined by the tool, the input files and the config sections of stages 1..i. The key of
stage *i* chains exactly that::

    root    = H(cache format, tool fingerprint)
    base_i  = H(key_{i-1} (root for the first stage), stage name, canonical JSON of its section)
    key_i   = H(base_i, sha256 of every file the stage read, names of the model files in their folders)

The *tool fingerprint* hashes the bytes of every ``bake/**/*.py`` file, the versions of the
libraries that compute results (numpy, scipy, embreex, meshoptimizer, xatlas, ...), the Python
version and the machine type: a code change invalidates everything, a version number alone would
not. A stage's *files* are what it added to ``Scene.source.files_read`` (the model, .mtl, textures,
glTF buffers, ``textures.texture``, the project of ``export.into``) plus material texture paths; which
files a stage reads is only known once it ran, so ``<base>.deps`` (a small manifest) remembers the
list from the last run and the lookup hashes those files' current bytes. A stage that now reads
other files (an edited .mtl naming another texture) changed one of the listed files, so its key
changes and it runs again. The names of the ``.mtl``/``.bin``/image files in each folder a stage read
from are part of the key too, so a texture or .mtl that was missing and appears later is noticed.

A bake loads the entry of the deepest stage whose key it can build and finds, and runs the rest
(`bake.pipeline.run`); a cold stage's output is stored. Entries hold the records of every stage up
to theirs, so the report of a cached bake has the same counts, accuracy figures and warnings.

**Entry format** (written here, read here, nothing else): a fixed magic and format number, a JSON
header (key, stage, tool fingerprint, the object tree), 64-byte aligned raw array and bytes blobs,
and a SHA-256 of everything before it. No pickle: decoding builds only JSON values, numpy arrays
from raw bytes (never ``dtype=object``), ``pathlib.Path``, and instances of dataclasses (and
references to plain functions) defined in ``bake.*`` modules, filled attribute by attribute without
calling their constructors. A file that fails any check (truncated, bit-flipped, another key,
another tool version, an unknown class) is ignored with a warning and recomputed; it cannot run
code. The checksum detects damage, it is not a signature: whoever can write the cache folder can
also write the outputs. Encoding is deterministic (dicts in insertion order, sets sorted).

Stores: a folder (``<out>/.bake-cache/stages`` by default, ``cache.dir`` to share one, ``"none"``
for none) with a size cap (``cache.max_mb``): past it the least recently used entries are deleted
(a hit touches its entry); or memory (what ``bake sweep`` uses when the folder cache is off).

**Memos** (:class:`Memo`, in the same store and format): parts of a stage's work keyed by less than
the stage's key, reused when the stage must run again -- the lighting trace (not the exposure or
tone map), the BSP tree (not the colours), the previews' geometry. The stage names what the part
depends on; the bake gets the same bytes as a cold one.
"""

from __future__ import annotations

import contextlib
import contextvars
import dataclasses
import functools
import hashlib
import importlib
import json
import os
import platform
import struct
import sys
import time
import types
from dataclasses import dataclass
from pathlib import Path, PurePath
from typing import Any, Iterable

import numpy as np

from . import __version__
from .files import write_atomic

FORMAT = 1
MAGIC = b"SBAKE-STAGE\x00"
_HEAD = struct.Struct("<12sIQ")  # magic, format, header length
_ALIGN = 64
ENTRY_SUFFIX = ".stage"
DEPS_SUFFIX = ".deps"
TMP_SUFFIX = ".cache-tmp"
SUBDIR = Path(".bake-cache") / "stages"
# folder listings that are part of a key: the files a model may name (case-insensitively)
LISTED_SUFFIXES = frozenset({".mtl", ".bin", ".png", ".jpg", ".jpeg", ".gif", ".bmp", ".tga", ".webp",
                             ".tif", ".tiff", ".ktx2", ".dds", ".obj", ".gltf", ".glb"})
# libraries whose results end up in a scene
_LIBRARIES = ("numpy", "scipy", "pillow", "embreex", "fast-simplification", "pymeshlab", "libigl",
              "meshoptimizer", "xatlas", "DracoPy", "mapbox-earcut")


class CacheError(Exception):
    """An entry that cannot be used (the message says why); the bake recomputes instead."""


class Unsupported(Exception):
    """A value the entry format does not store (the stage is then not cached)."""


# --------------------------------------------------------------------------- hashing
def _h(*parts: Any) -> str:
    h = hashlib.sha256()
    for p in parts:
        b = p if isinstance(p, bytes) else json.dumps(p, sort_keys=True, separators=(",", ":"),
                                                       ensure_ascii=False).encode("utf-8")
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)
    return h.hexdigest()


@functools.lru_cache(maxsize=None)
def tool_fingerprint() -> str:
    """What the code that computes a scene is: this package's source bytes, the libraries'
    versions, Python and the machine type (computed once per process)."""
    return fingerprint_of(Path(__file__).resolve().parent)


def fingerprint_of(root: Path) -> str:
    """:func:`tool_fingerprint` of the package in ``root``."""
    from importlib import metadata

    h = hashlib.sha256()
    h.update(f"scratch-bake {__version__}; python {sys.version_info[0]}.{sys.version_info[1]}; "
             f"{platform.machine()}; {sys.byteorder}\n".encode())
    for name in _LIBRARIES:
        try:
            v = metadata.version(name)
        except metadata.PackageNotFoundError:
            v = "-"
        h.update(f"{name}=={v}\n".encode())
    for p in sorted(Path(root).rglob("*.py")):
        h.update(p.relative_to(root).as_posix().encode() + b"\n")
        h.update(hashlib.sha256(p.read_bytes()).digest())
    return h.hexdigest()


def canonical(section: Any) -> Any:
    """A config section as plain JSON data (TOML names; internal fields such as the output folder
    left out): what a stage's key hashes."""
    from .config import to_dict

    return to_dict(section)


def file_digest(path: str | Path) -> str:
    try:
        with open(path, "rb") as f:
            return hashlib.file_digest(f, "sha256").hexdigest() if hasattr(hashlib, "file_digest") \
                else hashlib.sha256(f.read()).hexdigest()
    except FileNotFoundError:
        return "missing"
    except OSError as e:
        return f"unreadable ({e.errno})"


def listing_digest(folder: str | Path) -> str:
    """The names (as written) of the files in ``folder`` that a model could name."""
    try:
        names = sorted(n for n in os.listdir(folder) if os.path.splitext(n)[1].lower() in LISTED_SUFFIXES)
    except OSError as e:
        return f"unlistable ({e.errno})"
    return _h(names)


# --------------------------------------------------------------------------- encoding
def _pad(n: int) -> int:
    return -n % _ALIGN


class _Encoder:
    def __init__(self) -> None:
        self.blobs: list[bytes] = []
        self.memo: dict[int, int] = {}
        self.alive: list[Any] = []  # ids stay unique while encoding

    def _remember(self, o: Any) -> int:
        i = len(self.memo)
        self.memo[id(o)] = i
        self.alive.append(o)
        return i

    def _blob(self, data: bytes) -> int:
        self.blobs.append(data)
        return len(self.blobs) - 1

    def enc(self, o: Any) -> Any:
        t = type(o)
        if o is None or t is bool or t is int or t is str:
            return o
        if t is float:
            return o  # json writes repr(): exact, NaN and Infinity included
        ref = self.memo.get(id(o))
        if ref is not None:
            return ["r", ref]
        if t is tuple:
            return ["t", [self.enc(v) for v in o]]
        if t is list:
            i = self._remember(o)
            return ["l", i, [self.enc(v) for v in o]]
        if t is dict:
            i = self._remember(o)
            flat: list[Any] = []
            for k, v in o.items():
                flat.append(self.enc(k))
                flat.append(self.enc(v))
            return ["d", i, flat]
        if t is set or t is frozenset:
            i = self._remember(o)
            items = sorted((self.enc(v) for v in o), key=lambda e: json.dumps(e, sort_keys=True))
            return ["S" if t is set else "Z", i, items]
        if t is bytes or t is bytearray:
            i = self._remember(o)
            return ["b" if t is bytes else "B", i, self._blob(bytes(o))]
        if t is np.ndarray:
            return self._array(o)
        if isinstance(o, np.generic):
            if o.dtype.hasobject or o.dtype.kind not in "biufc":
                raise Unsupported(f"numpy scalar of type {o.dtype}")
            v = o.item()
            return ["n", o.dtype.str, [v.real, v.imag] if isinstance(v, complex) else v]
        if isinstance(o, PurePath):
            return ["p", str(o)]
        if isinstance(o, types.FunctionType):
            return ["f", _qualified(o, function=True)]
        if dataclasses.is_dataclass(o) and not isinstance(o, type):
            name = _qualified(t, function=False)
            i = self._remember(o)
            attrs = vars(o) if hasattr(o, "__dict__") else {f.name: getattr(o, f.name)
                                                          for f in dataclasses.fields(o)}
            flat = []
            for k, v in attrs.items():
                flat.append(k)
                flat.append(self.enc(v))
            return ["o", i, name, flat]
        raise Unsupported(f"a {t.__module__}.{t.__qualname__}")

    def _array(self, a: np.ndarray) -> list:
        if a.dtype.hasobject:
            raise Unsupported("a numpy array of Python objects")
        i = self._remember(a)
        if a.flags.c_contiguous:
            order, data = "C", a
        elif a.flags.f_contiguous:
            order, data = "F", a.T  # keep the memory layout: numpy's reductions round by it
        else:
            order, data = "C", np.ascontiguousarray(a)
        descr = np.lib.format.dtype_to_descr(a.dtype)
        return ["a", i, self._blob(np.ascontiguousarray(data).tobytes()), descr, list(a.shape), order]


def _qualified(o: Any, *, function: bool) -> str:
    mod, qual = getattr(o, "__module__", "") or "", getattr(o, "__qualname__", "")
    if not (mod == "bake" or mod.startswith("bake.")) or "<" in qual:
        raise Unsupported(f"{'function' if function else 'object'} {mod}.{qual} (only dataclasses and "
                          "module-level functions of bake.* are stored)")
    name = f"{mod}:{qual}"
    if _resolve(name, function=function) is not o:
        raise Unsupported(f"{mod}.{qual} is not reachable by its name")
    return name


def _resolve(name: str, *, function: bool) -> Any:
    """A dataclass or function of a ``bake.*`` module by ``module:qualname``, or CacheError."""
    mod, _, qual = name.partition(":")
    parts = mod.split(".")
    if parts[0] != "bake" or not all(p.isidentifier() for p in parts) or not qual or \
            not all(p.isidentifier() and not p.startswith("__") for p in qual.split(".")):
        raise CacheError(f"names {name!r}, not a scratch-bake type")
    try:
        obj: Any = importlib.import_module(mod)
        for p in qual.split("."):
            obj = getattr(obj, p)
    except (ImportError, AttributeError):
        raise CacheError(f"names {name!r}, which this version does not have") from None
    if function:
        ok = isinstance(obj, types.FunctionType)
    else:
        ok = isinstance(obj, type) and dataclasses.is_dataclass(obj)
    if not ok or obj.__module__ != mod or obj.__qualname__ != qual:
        raise CacheError(f"names {name!r}, which is not a stored {'function' if function else 'dataclass'}")
    return obj


class _Decoder:
    def __init__(self, buf: np.ndarray, blobs: list[tuple[int, int]]):
        self.buf = buf
        self.blobs = blobs
        self.table: dict[int, Any] = {}

    def _put(self, i: Any, o: Any) -> None:
        if not isinstance(i, int) or isinstance(i, bool) or i in self.table:
            raise CacheError("bad object number")
        self.table[i] = o

    def _bytes(self, b: Any) -> np.ndarray:
        if not isinstance(b, int) or isinstance(b, bool) or not 0 <= b < len(self.blobs):
            raise CacheError("bad blob number")
        off, n = self.blobs[b]
        return self.buf[off:off + n]

    def dec(self, n: Any) -> Any:
        if n is None or isinstance(n, (bool, int, float, str)):
            return n
        if not isinstance(n, list) or not n or not isinstance(n[0], str):
            raise CacheError("bad node")
        tag = n[0]
        if tag == "r" and len(n) == 2:
            if n[1] not in self.table:
                raise CacheError("reference to an unknown object")
            return self.table[n[1]]
        if tag == "t" and len(n) == 2 and isinstance(n[1], list):
            return tuple(self.dec(v) for v in n[1])
        if tag == "l" and len(n) == 3 and isinstance(n[2], list):
            out: list = []
            self._put(n[1], out)
            out.extend(self.dec(v) for v in n[2])
            return out
        if tag == "d" and len(n) == 3 and isinstance(n[2], list) and len(n[2]) % 2 == 0:
            d: dict = {}
            self._put(n[1], d)
            it = iter(n[2])
            for k in it:
                d[self.dec(k)] = self.dec(next(it))
            return d
        if tag in ("S", "Z") and len(n) == 3 and isinstance(n[2], list):
            items = [self.dec(v) for v in n[2]]
            s = set(items) if tag == "S" else frozenset(items)
            self._put(n[1], s)
            return s
        if tag in ("b", "B") and len(n) == 3:
            raw = self._bytes(n[2]).tobytes()
            o = raw if tag == "b" else bytearray(raw)
            self._put(n[1], o)
            return o
        if tag == "a" and len(n) == 6:
            return self._array(n)
        if tag == "n" and len(n) == 3 and isinstance(n[1], str):
            dt = np.dtype(n[1])
            if dt.kind not in "biufc":
                raise CacheError("bad numpy scalar")
            v = complex(*n[2]) if dt.kind == "c" else n[2]
            return dt.type(v)
        if tag == "p" and len(n) == 2 and isinstance(n[1], str):
            return Path(n[1])
        if tag == "f" and len(n) == 2 and isinstance(n[1], str):
            return _resolve(n[1], function=True)
        if tag == "o" and len(n) == 4 and isinstance(n[2], str) and isinstance(n[3], list) and len(n[3]) % 2 == 0:
            cls = _resolve(n[2], function=False)
            obj = object.__new__(cls)  # no constructor runs
            self._put(n[1], obj)
            it = iter(n[3])
            for k in it:
                if not isinstance(k, str) or not k.isidentifier() or k.startswith("__"):
                    raise CacheError("bad attribute name")
                object.__setattr__(obj, k, self.dec(next(it)))
            return obj
        raise CacheError(f"unknown node {tag!r}")

    def _array(self, n: list) -> np.ndarray:
        _, i, b, descr, shape, order = n
        try:
            dt = np.lib.format.descr_to_dtype(descr if isinstance(descr, str) else _tuples(descr))
        except (TypeError, ValueError, KeyError):
            raise CacheError("bad array type") from None
        if dt.hasobject or not isinstance(shape, list) or order not in ("C", "F") or \
                not all(isinstance(s, int) and not isinstance(s, bool) and s >= 0 for s in shape):
            raise CacheError("bad array")
        raw = self._bytes(b)
        count = int(np.prod(shape, dtype=np.int64)) if shape else 1
        if count * dt.itemsize != len(raw):
            raise CacheError("array size does not match its data")
        flat = raw.view(dt) if dt.itemsize else np.zeros(count, dt)
        a = flat.reshape(shape) if order == "C" else flat.reshape(shape[::-1]).T
        self._put(i, a)
        return a


def _tuples(descr: Any) -> Any:
    """JSON turned the structured dtype's tuples into lists."""
    if isinstance(descr, list):
        return [tuple(_tuples(x) for x in d) if isinstance(d, list) else d for d in descr]
    return descr


def encode_entry(key: str, stage: str, payload: Any) -> list[bytes]:
    """The entry as chunks to write (header, padding, blobs, checksum)."""
    e = _Encoder()
    tree = e.enc(payload)
    offsets, pos = [], 0
    for b in e.blobs:
        pos += _pad(pos)
        offsets.append([pos, len(b)])
        pos += len(b)
    header = json.dumps({"key": key, "stage": stage, "tool": tool_fingerprint(), "blobs": offsets, "tree": tree},
                        separators=(",", ":"), ensure_ascii=False).encode("utf-8")
    head = _HEAD.pack(MAGIC, FORMAT, len(header))
    chunks = [head, header, b"\0" * _pad(len(head) + len(header))]
    pos = 0
    for b, (off, n) in zip(e.blobs, offsets):
        chunks.append(b"\0" * (off - pos))
        chunks.append(b)
        pos = off + n
    h = hashlib.sha256()
    for c in chunks:
        h.update(c)
    chunks.append(h.digest())
    return chunks


def decode_entry(buf: np.ndarray, key: str, stage: str) -> Any:
    """An entry read into ``buf`` (uint8) back to its payload; CacheError says what is wrong."""
    n = len(buf)
    if n < _HEAD.size + 32:
        raise CacheError("is truncated")
    magic, fmt, hlen = _HEAD.unpack(buf[:_HEAD.size].tobytes())
    if magic != MAGIC:
        raise CacheError("is not a stage cache entry")
    if fmt != FORMAT:
        raise CacheError(f"has cache format {fmt}, this version reads {FORMAT}")
    if hashlib.sha256(memoryview(buf[:n - 32])).digest() != buf[n - 32:].tobytes():
        raise CacheError("is damaged (checksum mismatch)")
    start = _HEAD.size + hlen
    if start > n - 32:
        raise CacheError("is truncated")
    try:
        header = json.loads(buf[_HEAD.size:start].tobytes().decode("utf-8"))
    except (UnicodeDecodeError, ValueError):
        raise CacheError("has an unreadable header") from None
    if not isinstance(header, dict):
        raise CacheError("has an unreadable header")
    if header.get("key") != key or header.get("stage") != stage:
        raise CacheError(f"belongs to another key ({str(header.get('stage'))} {str(header.get('key'))[:12]})")
    if header.get("tool") != tool_fingerprint():
        raise CacheError("was written by another version of scratch-bake")
    base = start + _pad(start)
    end = n - 32
    blobs = []
    for b in header.get("blobs", []):
        if not (isinstance(b, list) and len(b) == 2 and all(isinstance(x, int) and x >= 0 for x in b)
                and base + b[0] + b[1] <= end):
            raise CacheError("has a blob outside the file")
        blobs.append((base + b[0], b[1]))
    try:
        return _Decoder(buf, blobs).dec(header.get("tree"))
    except RecursionError:
        raise CacheError("is nested too deeply") from None


# --------------------------------------------------------------------------- stores
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


# --------------------------------------------------------------------------- the cache
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
        elif c.out_dir is not None:  # a failed first bake into a new folder must not create it
            return cls(DiskStore(Path(c.out_dir) / SUBDIR, int(c.max_mb * 1024 * 1024),
                                 lazy=Path(c.out_dir) / SUBDIR, label=SUBDIR.as_posix()))  # (the report names it within the folder)
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
        self.root = _h("scratch-bake stage cache", FORMAT, tool_fingerprint())
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
        return _h("stage", prev or self.root, name, canonical(section))

    def key(self, base: str, files: Iterable[str], dirs: Iterable[str]) -> str:
        return _h(base, [[f, self._digest(f)] for f in files], [[d, self._listing(d)] for d in dirs])

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
    from .record import StageRecord
    from .scene import Scene

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


# --------------------------------------------------------------------------- memos
def content_digest(*parts: Any) -> str:
    """SHA-256 of values the entry format can store (arrays by dtype, shape, layout and bytes;
    floats exactly): equal digests, equal values."""
    e = _Encoder()
    tree = e.enc(list(parts))
    h = hashlib.sha256(json.dumps(tree, separators=(",", ":"), ensure_ascii=False).encode("utf-8"))
    for b in e.blobs:
        h.update(len(b).to_bytes(8, "little"))
        h.update(b)
    return h.hexdigest()


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
        return _h("memo", FORMAT, tool_fingerprint(), kind, content_digest(*parts))

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
