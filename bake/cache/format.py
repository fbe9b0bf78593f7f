"""The stage cache's entry format: written here (:func:`encode_entry`), read here
(:func:`decode_entry`), nothing else.

A fixed magic and format number, a JSON header (key, stage, tool fingerprint, the object tree),
64-byte aligned raw array and bytes blobs, and a SHA-256 of everything before it. No pickle:
decoding builds only JSON values, numpy arrays from raw bytes (never ``dtype=object``),
``pathlib.Path``, and instances of dataclasses (and references to plain functions) defined in
``bake.*`` modules, filled attribute by attribute without calling their constructors. Those are
named by ``module:qualname`` (:func:`_qualified`, :func:`_resolve`), so moving a class to another
module changes the names its entries hold (the tool fingerprint changes with it, so entries of an
older version are not read). A file that fails any check (truncated, bit-flipped, another key,
another tool version, an unknown class) is a :class:`CacheError` (the caller ignores it with a
warning and recomputes); it cannot run code. The checksum detects damage, it is not a signature:
whoever can write the cache folder can also write the outputs. Encoding is deterministic (dicts in
insertion order, sets sorted), so :func:`content_digest` of the encoding names equal values.
"""

from __future__ import annotations

import dataclasses
import hashlib
import importlib
import json
import struct
import types
from pathlib import Path, PurePath
from typing import Any

import numpy as np

from . import keys

FORMAT = 1
MAGIC = b"SBAKE-STAGE\x00"
_HEAD = struct.Struct("<12sIQ")  # magic, format, header length
_ALIGN = 64


class CacheError(Exception):
    """An entry that cannot be used (the message says why); the bake recomputes instead."""


class Unsupported(Exception):
    """A value the entry format does not store (the stage is then not cached)."""


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
    header = json.dumps({"key": key, "stage": stage, "tool": keys.tool_fingerprint(), "blobs": offsets, "tree": tree},
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
    if header.get("tool") != keys.tool_fingerprint():
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
