"""glTF 2.0 / GLB container reading: JSON, structural checks, buffers, views, accessors, images.

:class:`GltfDocument` owns one file. Opening it parses the GLB container (or plain JSON) and
checks every reference and byte range in the JSON up front, so a malformed file fails with a
one-line :class:`~bake.errors.InputError` naming the object (``accessors[3]``,
``meshes[0].primitives[1]``) before any data is touched. Buffers and images are read lazily:
only the ones the chosen scene uses are opened, and every opened file is listed in
``files_read``.

Accessors are decoded with numpy (byteStride, normalised integers, sparse substitution); float
results are float64 and checked for NaN/Inf. URIs must be ``data:`` URIs or relative paths that
stay inside the model's folder.
"""

from __future__ import annotations

import base64
import binascii
import json
import os
import re
import struct
import urllib.parse
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError

# componentType -> (numpy little-endian dtype, byte size)
COMPONENTS: dict[int, np.dtype] = {
    5120: np.dtype("<i1"), 5121: np.dtype("<u1"), 5122: np.dtype("<i2"),
    5123: np.dtype("<u2"), 5125: np.dtype("<u4"), 5126: np.dtype("<f4"),
}
INDEX_COMPONENTS = (5121, 5123, 5125)
TYPE_SIZES = {"SCALAR": 1, "VEC2": 2, "VEC3": 3, "VEC4": 4, "MAT2": 4, "MAT3": 9, "MAT4": 16}

GLB_MAGIC = b"glTF"
CHUNK_JSON = 0x4E4F534A
CHUNK_BIN = 0x004E4942

# An accessor without a bufferView is all zeros (plus sparse values); cap what such an accessor
# may allocate so a hostile count cannot exhaust memory.
MAX_ZERO_ELEMENTS = 1 << 27

MESHOPT_EXTENSIONS = ("EXT_meshopt_compression", "KHR_meshopt_compression")

_SCHEME = re.compile(r"^[A-Za-z][A-Za-z0-9+.\-]*:")


@dataclass(frozen=True)
class ImageRef:
    """Where a glTF image's bytes are: an external file (absolute path) or embedded bytes."""

    path: Path | None = None
    data: bytes | None = None
    mime: str = ""
    missing: bool = False  # an external file that does not exist


def _is_int(v: Any) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _as_int(v: Any) -> int | None:
    """A JSON integer (``4`` or ``4.0``, as JSON Schema allows) or None; floats beyond 2**53
    are not exact integers and count as invalid."""
    if _is_int(v):
        return v
    if isinstance(v, float) and v.is_integer() and abs(v) < 2.0 ** 53:
        return int(v)
    return None


def _is_num(v: Any) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool)


class GltfDocument:
    """One glTF/GLB file: its JSON, binary chunk and lazily loaded buffers."""

    def __init__(self, path: Path, raw: bytes, fmt_hint: str = "auto"):
        self.path = Path(path)
        self.folder = self.path.parent
        self.files_read: list[Path] = [self.path]
        self.files_missing: list[Path] = []  # images named and not found (for --depfile)
        self.bin_chunk: bytes | None = None
        self.warnings: list[str] = []
        self.is_glb = raw[:4] == GLB_MAGIC
        if not self.is_glb and (fmt_hint == "glb" or (fmt_hint == "auto"
                                                       and self.path.suffix.lower() == ".glb")):
            raise self.error(f"not a GLB file: bad magic {bytes(raw[:4])!r} (expected b'glTF')")
        text = self._read_glb(raw) if self.is_glb else raw
        self.json = self._parse_json(text)
        self._buffers: dict[int, memoryview | None] = {}
        self._accessor_cache: dict[int, np.ndarray] = {}
        self._check_version()
        self._validate()

    # ------------------------------------------------------------------ errors
    def error(self, message: str, where: str | None = None) -> InputError:
        return InputError(f"{where}: {message}" if where else message, path=self.path)

    @property
    def format(self) -> str:
        return "glb" if self.is_glb else "gltf"

    # ------------------------------------------------------------------ container
    def _read_glb(self, raw: bytes) -> bytes:
        n = len(raw)
        if n < 12:
            raise self.error(f"truncated GLB: {n} bytes, the header alone needs 12")
        _, version, length = struct.unpack_from("<4sII", raw, 0)
        if version != 2:
            raise self.error(f"GLB version {version} is not supported (glTF 2.0 GLB is version 2)")
        if length > n:
            raise self.error(f"truncated GLB: the header says {length} bytes but the file has {n}")
        if length < 20:
            raise self.error(f"GLB header length {length} leaves no room for the JSON chunk")
        pos = 12
        json_chunk: bytes | None = None
        while pos < length:
            if pos + 8 > length:
                raise self.error(f"truncated GLB: chunk header at byte {pos} is cut off")
            clen, ctype = struct.unpack_from("<II", raw, pos)
            start, end = pos + 8, pos + 8 + clen
            if end > length:
                raise self.error(f"truncated GLB: chunk at byte {pos} needs {clen} bytes, "
                                 f"only {length - start} left")
            if json_chunk is None:
                if ctype != CHUNK_JSON:
                    raise self.error(f"GLB: first chunk has type 0x{ctype:08x}, expected JSON")
                json_chunk = bytes(raw[start:end])
            elif ctype == CHUNK_BIN and self.bin_chunk is None:
                self.bin_chunk = bytes(raw[start:end])
            pos = end + (-clen % 4 if end + (-clen % 4) <= length else 0)
        if json_chunk is None:
            raise self.error("GLB has no JSON chunk")
        return json_chunk

    def _parse_json(self, text: bytes) -> dict:
        where = "JSON chunk" if self.is_glb else None
        try:
            s = text.decode("utf-8")
        except UnicodeDecodeError as e:
            raise self.error(f"not UTF-8 text (byte {e.start})", where) from None
        s = s.lstrip("\ufeff").rstrip("\x00 \t\r\n")
        try:
            doc = json.loads(s)
        except json.JSONDecodeError as e:
            raise self.error(f"not valid JSON: {e.msg} (line {e.lineno}, column {e.colno})",
                             where) from None
        except RecursionError:
            raise self.error("not valid JSON: nested too deeply", where) from None
        if not isinstance(doc, dict):
            raise self.error(f"the top level must be a JSON object, got {type(doc).__name__}", where)
        return doc

    def _check_version(self) -> None:
        asset = self.json.get("asset")
        if asset is None:
            self.warnings.append("no 'asset' object (required by glTF 2.0); reading it as 2.0")
            return
        if not isinstance(asset, dict):
            raise self.error("must be an object", "asset")
        version = asset.get("version")
        if version is None:
            self.warnings.append("asset.version is missing; reading the file as glTF 2.0")
            return
        if not isinstance(version, str) or not version.split(".")[0] == "2":
            raise self.error(f"glTF version {version!r} is not supported (only 2.x)", "asset.version")

    # ------------------------------------------------------------------ JSON helpers
    def array(self, name: str) -> list[dict]:
        """A top-level array of objects (``[]`` when absent)."""
        v = self.json.get(name, [])
        if not isinstance(v, list) or not all(isinstance(x, dict) for x in v):
            raise self.error("must be an array of objects", name)
        return v

    def ref(self, obj: dict, key: str, where: str, kind: str, *, required: bool = False,
            target: list | None = None) -> int | None:
        """An index property pointing into the top-level array ``kind``; checked in range."""
        if key not in obj:
            if required:
                raise self.error(f"missing '{key}'", where)
            return None
        items = self.array(kind) if target is None else target
        v = _as_int(obj[key])
        if v is None:
            raise self.error(f"{key} must be an index into {kind}, got {obj[key]!r}", where)
        if not 0 <= v < len(items):
            raise self.error(f"{key} = {v} out of range: no {kind}[{v}] (the file has "
                             f"{len(items)})", where)
        obj[key] = v
        return v

    def integer(self, obj: dict, key: str, where: str, default: int | None = None, *,
                lo: int = 0, hi: int | None = None) -> int:
        if key not in obj:
            if default is None:
                raise self.error(f"missing '{key}'", where)
            return default
        v = _as_int(obj[key])
        if v is None:
            if isinstance(obj[key], float) and np.isfinite(obj[key]) and obj[key].is_integer():
                raise self.error(f"{key} = {obj[key]!r} is out of range", where)
            raise self.error(f"{key} must be an integer, got {obj[key]!r}", where)
        if v < lo or (hi is not None and v > hi):
            rng = f">= {lo}" if hi is None else f"between {lo} and {hi}"
            raise self.error(f"{key} = {v} is out of range (must be {rng})", where)
        obj[key] = v
        return v

    def numbers(self, obj: dict, key: str, where: str, n: int, default: Any) -> tuple[float, ...]:
        if key not in obj:
            return tuple(float(x) for x in default)
        v = obj[key]
        if not isinstance(v, list) or len(v) != n or not all(_is_num(x) for x in v):
            raise self.error(f"{key} must be an array of {n} numbers, got {v!r}"[:200], where)
        out = tuple(float(x) for x in v)
        if not all(np.isfinite(out)):
            raise self.error(f"{key} has NaN/Inf values", where)
        return out

    def number(self, obj: dict, key: str, where: str, default: float) -> float:
        if key not in obj:
            return float(default)
        v = obj[key]
        if not _is_num(v) or not np.isfinite(float(v)):
            raise self.error(f"{key} must be a finite number, got {v!r}", where)
        return float(v)

    def dict_(self, obj: dict, key: str, where: str) -> dict:
        v = obj.get(key, {})
        if not isinstance(v, dict):
            raise self.error(f"{key} must be an object", where)
        return v

    def extension(self, obj: dict, name: str, where: str) -> dict | None:
        ext = self.dict_(obj, "extensions", where)
        v = ext.get(name)
        if v is None:
            return None
        if not isinstance(v, dict):
            raise self.error(f"extensions.{name} must be an object", where)
        return v

    # ------------------------------------------------------------------ validation
    def _validate(self) -> None:
        """Check every index and byte range the JSON declares (no data read yet)."""
        j = self.json
        for name in ("extensionsUsed", "extensionsRequired"):
            v = j.get(name, [])
            if not isinstance(v, list) or not all(isinstance(x, str) for x in v):
                raise self.error("must be an array of strings", name)
        buffers = self.array("buffers")
        for i, b in enumerate(buffers):
            w = f"buffers[{i}]"
            self.integer(b, "byteLength", w)
            if "uri" in b:
                if not isinstance(b["uri"], str):
                    raise self.error("uri must be a string", w)
                if not b["uri"].startswith("data:"):
                    self.resolve_uri(b["uri"], w)
        views = self.array("bufferViews")
        for i, v in enumerate(views):
            w = f"bufferViews[{i}]"
            bi = self.ref(v, "buffer", w, "buffers", required=True)
            off = self.integer(v, "byteOffset", w, 0)
            ln = self.integer(v, "byteLength", w, lo=1)
            if "byteStride" in v:
                self.integer(v, "byteStride", w, lo=1, hi=252)
            blen = buffers[bi]["byteLength"]
            if off + ln > blen:
                raise self.error(f"bytes {off}..{off + ln} run past the end of buffers[{bi}] "
                                 f"(byteLength {blen})", w)
        for i, a in enumerate(self.array("accessors")):
            self._validate_accessor(i, a, views)
        images = self.array("images")
        for i, im in enumerate(images):
            w = f"images[{i}]"
            if "uri" in im:
                if not isinstance(im["uri"], str):
                    raise self.error("uri must be a string", w)
                if not im["uri"].startswith("data:"):
                    self.resolve_uri(im["uri"], w)
            else:
                self.ref(im, "bufferView", w, "bufferViews")
        for i, t in enumerate(self.array("textures")):
            self.ref(t, "source", f"textures[{i}]", "images")
        for i, m in enumerate(self.array("materials")):
            w = f"materials[{i}]"
            pbr = self.dict_(m, "pbrMetallicRoughness", w)
            tex = self.dict_(pbr, "baseColorTexture", w + ".pbrMetallicRoughness")
            if tex:
                self.ref(tex, "index", w + ".pbrMetallicRoughness.baseColorTexture", "textures",
                         required=True)
        for i, mesh in enumerate(self.array("meshes")):
            self._validate_mesh(i, mesh)
        nodes = self.array("nodes")
        for i, n in enumerate(nodes):
            w = f"nodes[{i}]"
            self.ref(n, "mesh", w, "meshes")
            ch = n.get("children", [])
            if not isinstance(ch, list):
                raise self.error("children must be an array of node indices", w)
            for k in range(len(ch)):
                ch[k] = self.ref({"children": ch[k]}, "children", w, "nodes", target=nodes)
        for i, s in enumerate(self.array("scenes")):
            sn = s.get("nodes", [])
            if not isinstance(sn, list):
                raise self.error("nodes must be an array of node indices", f"scenes[{i}]")
            for k in range(len(sn)):
                sn[k] = self.ref({"nodes": sn[k]}, "nodes", f"scenes[{i}]", "nodes", target=nodes)
        if "scene" in j:
            self.ref(j, "scene", "glTF", "scenes")

    def _validate_accessor(self, i: int, a: dict, views: list[dict]) -> None:
        w = f"accessors[{i}]"
        ct = a.get("componentType")
        if _as_int(ct) not in COMPONENTS:
            raise self.error(f"componentType {ct!r} is not one of {sorted(COMPONENTS)}", w)
        a["componentType"] = ct = _as_int(ct)
        typ = a.get("type")
        if typ not in TYPE_SIZES:
            raise self.error(f"type {typ!r} is not one of {', '.join(TYPE_SIZES)}", w)
        count = self.integer(a, "count", w, lo=1)
        if "normalized" in a and not isinstance(a["normalized"], bool):
            raise self.error("normalized must be true or false", w)
        elem = TYPE_SIZES[typ] * COMPONENTS[ct].itemsize
        bv = self.ref(a, "bufferView", w, "bufferViews")
        off = self.integer(a, "byteOffset", w, 0)
        if bv is not None:
            view = views[bv]
            stride = view.get("byteStride", elem)
            if stride < elem:
                raise self.error(f"bufferViews[{bv}].byteStride {stride} is smaller than one "
                                 f"{typ} element ({elem} bytes)", w)
            need = off + stride * (count - 1) + elem
            if need > view["byteLength"]:
                raise self.error(f"{count} elements need {need} bytes but bufferViews[{bv}] has "
                                 f"{view['byteLength']}", w)
        elif count * TYPE_SIZES[typ] > MAX_ZERO_ELEMENTS and "sparse" not in a:
            raise self.error(f"count {count} is too large for an accessor without a bufferView", w)
        if "sparse" in a:
            sp = a["sparse"]
            ws = w + ".sparse"
            if not isinstance(sp, dict):
                raise self.error("must be an object", ws)
            if bv is None and count * TYPE_SIZES[typ] > MAX_ZERO_ELEMENTS:
                raise self.error(f"count {count} is too large for an accessor without a "
                                 f"bufferView", w)
            scount = self.integer(sp, "count", ws, lo=1, hi=count)
            idx, val = sp.get("indices"), sp.get("values")
            if not isinstance(idx, dict) or not isinstance(val, dict):
                raise self.error("needs 'indices' and 'values' objects", ws)
            ict = idx.get("componentType")
            if _as_int(ict) not in INDEX_COMPONENTS:
                raise self.error(f"indices.componentType {ict!r} must be one of "
                                 f"{list(INDEX_COMPONENTS)}", ws)
            idx["componentType"] = ict = _as_int(ict)
            for part, obj, size in (("indices", idx, COMPONENTS[ict].itemsize * scount),
                                    ("values", val, elem * scount)):
                pv = self.ref(obj, "bufferView", f"{ws}.{part}", "bufferViews", required=True)
                poff = self.integer(obj, "byteOffset", f"{ws}.{part}", 0)
                if poff + size > views[pv]["byteLength"]:
                    raise self.error(f"{scount} entries need {poff + size} bytes but "
                                     f"bufferViews[{pv}] has {views[pv]['byteLength']}",
                                     f"{ws}.{part}")

    def _validate_mesh(self, i: int, mesh: dict) -> None:
        w = f"meshes[{i}]"
        prims = mesh.get("primitives")
        if not isinstance(prims, list) or not all(isinstance(p, dict) for p in prims):
            raise self.error("primitives must be an array of objects", w)
        for k, p in enumerate(prims):
            wp = f"{w}.primitives[{k}]"
            attrs = p.get("attributes", {})
            if not isinstance(attrs, dict):
                raise self.error("attributes must be an object", wp)
            for sem in attrs:
                self.ref(attrs, sem, wp + ".attributes", "accessors")
            self.ref(p, "indices", wp, "accessors")
            self.ref(p, "material", wp, "materials")
            mode = self.integer(p, "mode", wp, 4)
            if mode > 6:
                raise self.error(f"mode {mode} is not a glTF primitive mode (0..6)", wp)
            targets = p.get("targets", [])
            if not isinstance(targets, list) or not all(isinstance(t, dict) for t in targets):
                raise self.error("targets must be an array of objects", wp)
            for t, tg in enumerate(targets):
                for sem in tg:
                    self.ref(tg, sem, f"{wp}.targets[{t}]", "accessors")
            draco = self.extension(p, "KHR_draco_mesh_compression", wp)
            if draco is not None:
                wd = wp + ".extensions.KHR_draco_mesh_compression"
                self.ref(draco, "bufferView", wd, "bufferViews", required=True)
                da = draco.get("attributes", {})
                if not isinstance(da, dict) or not all(_is_int(v) and v >= 0 for v in da.values()):
                    raise self.error("attributes must map names to Draco attribute ids", wd)

    # ------------------------------------------------------------------ URIs and buffers
    def resolve_uri(self, uri: str, where: str) -> Path:
        """An external (non-data:) URI as an absolute path inside the model's folder."""
        shown = uri if len(uri) <= 80 else uri[:77] + "..."
        if _SCHEME.match(uri) and not re.match(r"^[A-Za-z]:[\\/]", uri):
            raise self.error(f"uri '{shown}' is a URL; only files beside the model and data: "
                             f"URIs are read", where)
        rel = urllib.parse.unquote(uri).replace("\\", "/")
        if "\x00" in rel:
            raise self.error(f"uri '{shown}' contains a NUL character", where)
        if rel.startswith("/") or re.match(r"^[A-Za-z]:/", rel) or Path(rel).is_absolute():
            raise self.error(f"uri '{shown}' is an absolute path; it must be relative to the "
                             f"model's folder", where)
        folder = self.folder.absolute()
        target = Path(os.path.normpath(folder / rel))
        try:
            inside = target.resolve().is_relative_to(folder.resolve())
        except (OSError, RuntimeError):
            inside = False
        if not inside or ".." in Path(os.path.relpath(target, folder)).parts:
            raise self.error(f"uri '{shown}' points outside the model's folder", where)
        return target

    def _data_uri(self, uri: str, where: str) -> bytes:
        head, sep, payload = uri.partition(",")
        if not sep:
            raise self.error("data: URI has no ',' before its data", where)
        if head.endswith(";base64"):
            s = re.sub(r"\s+", "", payload)
            s += "=" * (-len(s) % 4)
            try:
                return base64.b64decode(s, validate=True)
            except (binascii.Error, ValueError):
                raise self.error("data: URI is not valid base64", where) from None
        return urllib.parse.unquote_to_bytes(payload)

    def _remember(self, p: Path) -> None:
        if p not in self.files_read:
            self.files_read.append(p)

    def buffer(self, i: int) -> memoryview | None:
        """The bytes of buffers[i] (exactly byteLength), or None for a meshopt fallback buffer."""
        if i in self._buffers:
            return self._buffers[i]
        b = self.array("buffers")[i]
        w = f"buffers[{i}]"
        blen = b["byteLength"]
        uri = b.get("uri")
        data: bytes | None
        if uri is None:
            fallback = any((self.extension(b, e, w) or {}).get("fallback") for e in MESHOPT_EXTENSIONS)
            if fallback:
                self._buffers[i] = None
                return None
            if not self.is_glb or i != 0 or self.bin_chunk is None:
                raise self.error("has no uri and there is no GLB binary chunk for it", w)
            data, what = self.bin_chunk, "the GLB binary chunk"
        elif uri.startswith("data:"):
            data, what = self._data_uri(uri, w), "its data: URI"
        else:
            p = self.resolve_uri(uri, w)
            try:
                data = p.read_bytes()
            except FileNotFoundError:
                raise self.error(f"file '{uri}' not found (looked in {self.folder})", w) from None
            except OSError as e:
                raise self.error(f"cannot read '{uri}': {e.strerror}", w) from None
            self._remember(p)
            what = f"'{uri}'"
        if len(data) < blen:
            raise self.error(f"byteLength is {blen} but {what} has only {len(data)} bytes", w)
        mv = memoryview(data)[:blen]
        self._buffers[i] = mv
        return mv

    def view(self, i: int, where: str) -> memoryview:
        v = self.array("bufferViews")[i]
        data = self.buffer(v["buffer"])
        for e in MESHOPT_EXTENSIONS:
            if self.extension(v, e, f"bufferViews[{i}]") is not None and data is None:
                raise self.error(f"bufferViews[{i}] is compressed with {e} (meshopt), which bake "
                                 f"cannot decode; decompress the file first (e.g. gltf-transform "
                                 f"copy or gltfpack -noq)", where)
        if data is None:
            raise self.error(f"bufferViews[{i}] points into a buffer without data", where)
        off = v.get("byteOffset", 0)
        return data[off:off + v["byteLength"]]

    # ------------------------------------------------------------------ accessors
    def accessor_info(self, i: int) -> tuple[int, str, int, bool]:
        a = self.array("accessors")[i]
        return a["componentType"], a["type"], a["count"], bool(a.get("normalized", False))

    def raw_accessor(self, i: int, where: str) -> np.ndarray:
        """accessors[i] as a (count, components) array in its stored dtype (read-only copy)."""
        if i in self._accessor_cache:
            return self._accessor_cache[i]
        a = self.array("accessors")[i]
        dt = COMPONENTS[a["componentType"]]
        ncomp = TYPE_SIZES[a["type"]]
        count = a["count"]
        wa = f"{where}: accessors[{i}]" if where else f"accessors[{i}]"
        if "bufferView" in a:
            bv = a["bufferView"]
            view = self.view(bv, wa)
            stride = self.array("bufferViews")[bv].get("byteStride", ncomp * dt.itemsize)
            arr = np.ndarray((count, ncomp), dtype=dt, buffer=view, offset=a.get("byteOffset", 0),
                             strides=(stride, dt.itemsize))
            out = arr.astype(dt.newbyteorder("="), copy=True)
        else:
            out = np.zeros((count, ncomp), dtype=dt.newbyteorder("="))
        sp = a.get("sparse")
        if sp is not None:
            scount = sp["count"]
            idt = COMPONENTS[sp["indices"]["componentType"]]
            iv = self.view(sp["indices"]["bufferView"], wa + ".sparse.indices")
            sidx = np.ndarray((scount,), dtype=idt, buffer=iv,
                              offset=sp["indices"].get("byteOffset", 0)).astype(np.int64)
            vv = self.view(sp["values"]["bufferView"], wa + ".sparse.values")
            vals = np.ndarray((scount, ncomp), dtype=dt, buffer=vv,
                              offset=sp["values"].get("byteOffset", 0))
            if scount and int(sidx.max()) >= count:
                raise self.error(f"sparse index {int(sidx.max())} out of range ({count} elements)",
                                 wa)
            out[sidx] = vals
        out.setflags(write=False)
        self._accessor_cache[i] = out
        return out

    def floats(self, i: int, where: str, *, components: tuple[int, ...] | None = None,
               force_normalized: bool = False) -> np.ndarray:
        """accessors[i] as float64 (normalised integers mapped to [0, 1] / [-1, 1]), finite."""
        ct, typ, _, normalized = self.accessor_info(i)
        ncomp = TYPE_SIZES[typ]
        if components is not None and (typ.startswith("MAT") or ncomp not in components):
            want = " or ".join("SCALAR" if c == 1 else f"VEC{c}" for c in components)
            raise self.error(f"accessors[{i}] has type {typ}, expected {want}", where)
        raw = self.raw_accessor(i, where)
        out = to_float(raw, ct, normalized or force_normalized)
        if ct == 5126:
            bad = ~np.isfinite(out)
            if bad.any():
                first = int(np.argmax(bad.any(axis=1)))
                raise self.error(f"accessors[{i}] has NaN/Inf values (first at element {first})",
                                 where)
        return out

    def indices(self, i: int, where: str) -> np.ndarray:
        ct, typ, _, _ = self.accessor_info(i)
        if typ != "SCALAR" or ct not in INDEX_COMPONENTS:
            raise self.error(f"index accessors[{i}] must be SCALAR unsigned byte/short/int, got "
                             f"{typ} componentType {ct}", where)
        return self.raw_accessor(i, where)[:, 0].astype(np.int64)

    # ------------------------------------------------------------------ images
    def image(self, i: int) -> ImageRef:
        im = self.array("images")[i]
        w = f"images[{i}]"
        mime = im.get("mimeType", "") if isinstance(im.get("mimeType", ""), str) else ""
        if "uri" in im:
            uri = im["uri"]
            if uri.startswith("data:"):
                head = uri[5:].partition(",")[0]
                return ImageRef(data=self._data_uri(uri, w), mime=mime or head.split(";")[0])
            p = self.resolve_uri(uri, w)
            try:
                found = p.is_file()
            except OSError as e:  # e.g. a name longer than the file system allows
                shown = uri if len(uri) <= 80 else uri[:77] + "..."
                raise self.error(f"uri '{shown}' cannot be used: {e.strerror}", w) from None
            if not found:
                if p not in self.files_missing:
                    self.files_missing.append(p)
                return ImageRef(path=p, mime=mime, missing=True)
            self._remember(p)
            return ImageRef(path=p, mime=mime)
        if "bufferView" in im:
            return ImageRef(data=bytes(self.view(im["bufferView"], w)), mime=mime)
        raise self.error("has neither uri nor bufferView", w)


def to_float(raw: np.ndarray, component_type: int, normalized: bool) -> np.ndarray:
    """Stored values -> float64; normalised integers per the glTF rules."""
    out = raw.astype(np.float64)
    if normalized and component_type != 5126:
        info = np.iinfo(COMPONENTS[component_type])
        out /= float(info.max)
        if info.min < 0:
            np.maximum(out, -1.0, out=out)
    return out


def open_document(path: Path, fmt_hint: str = "auto") -> GltfDocument:
    try:
        raw = Path(path).read_bytes()
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror}", path=path) from None
    return GltfDocument(Path(path), raw, fmt_hint)


# --------------------------------------------------------------------------- Draco
def decode_draco(doc: GltfDocument, prim: dict, where: str) -> tuple[dict[str, np.ndarray],
                                                                     np.ndarray]:
    """Decode a KHR_draco_mesh_compression primitive: (semantic -> (n, c) float64, (T*3,) ints)."""
    ext = prim["extensions"]["KHR_draco_mesh_compression"]
    wd = where + ".extensions.KHR_draco_mesh_compression"
    try:
        import DracoPy
    except ImportError:
        raise doc.error("uses KHR_draco_mesh_compression; install DracoPy (pip install DracoPy) "
                        "to read Draco-compressed meshes", where) from None
    data = bytes(doc.view(ext["bufferView"], wd))
    try:
        mesh = DracoPy.decode(data)
    except Exception as e:  # the decoder raises its own types for corrupt data
        raise doc.error(f"Draco data could not be decoded ({type(e).__name__}: {e})", wd) from None
    faces = getattr(mesh, "faces", None)
    if faces is None:
        raise doc.error("Draco data holds a point cloud, not a mesh", wd)
    attrs: dict[str, np.ndarray] = {}
    prim_attrs = prim.get("attributes", {})
    for sem, uid in ext.get("attributes", {}).items():
        att = mesh.get_attribute_by_unique_id(uid)
        if att is None:
            raise doc.error(f"attribute {sem}: no Draco attribute with id {uid}", wd)
        arr = np.asarray(att["data"])
        if arr.ndim == 1:
            arr = arr.reshape(len(arr), -1)
        if sem in prim_attrs:
            ct, _, _, normalized = doc.accessor_info(prim_attrs[sem])
            if np.issubdtype(arr.dtype, np.integer):
                arr = to_float(arr.astype(COMPONENTS[ct]), ct, normalized)
        arr = np.asarray(arr, dtype=np.float64)
        if not np.isfinite(arr).all():
            raise doc.error(f"decoded {sem} has NaN/Inf values", wd)
        attrs[sem] = arr
    return attrs, np.asarray(faces, dtype=np.int64).reshape(-1)
