"""Wavefront OBJ (+ MTL) importer: our own vectorised parser; n-gons are kept as polygons.

The file is read in blocks of whole lines (:data:`BLOCK_SIZE`, 4 MB; a line continued with a
backslash stays in one block) and each block is tokenised with numpy (no Python loop per vertex
or face line): byte classes -> token spans -> the line of each token -> the keyword of each line.
Compact arrays per block (positions, UVs, resolved indices, materials) are concatenated at the
end, so memory stays near the size of the result; line numbers, relative indices, ``usemtl``,
errors and warnings are carried across blocks and come out exactly as for one block.
``v``/``vt`` numbers are converted in one call per directive kind; face corners (``v``,
``v/vt``, ``v//vn``, ``v/vt/vn``, mixed freely, negative = relative) are validated byte-wise,
then converted in one call, with a sentinel for empty fields. Relative indices are resolved
with the number of ``v``/``vt`` lines above each face line (the count before the block plus a
searchsorted on line numbers), and materials by searchsorted over the ``usemtl`` lines. Only "other" lines (``usemtl``, ``mtllib``,
unknown directives) are visited one by one, and MTL files (small) are read line by line.

Rules (what this importer decides, so the report and tests can rely on it):

* Lines: ``\\n``, ``\\r\\n`` or bare ``\\r`` endings; bytes up to 0x20 (space, tab, CR, ...)
  separate tokens; a backslash at the end of a line continues it on the next (``wallhole.obj``
  does this); ``#`` starts a comment (also after data on a line;
  a ``#`` inside a token such as ``1.#IND`` is not a comment). A UTF-8 BOM is skipped. A file
  with NUL bytes or many control bytes is not text: :class:`InputError`.
* ``v x y z`` -- 3 values: a position. 4 values: ``x y z w``; ``w`` (a rational weight, only
  meaningful for free-form curves) is ignored, as in corpus ``vertex_w_component``.
  6 values: ``x y z r g b`` (MeshLab and trimesh's exporter write this, as does the corpus
  ``obj_vertex_colors``; trimesh's loader reads columns 4-6 the same way); 7 values: ``x y z r g b a``. Colours in [0, 1] are taken as they are; if any
  colour value is above 1 and all are whole numbers they are read as 0-255 and divided by 255;
  anything else outside [0, 1] is clipped (warning). Vertices without colour in a file where
  others have one get white (warning). 5 or more than 7 values: position only (warning).
  Fewer than 3: :class:`InputError`.
* ``vt u [v [w]]``: ``v`` defaults to 0, ``w`` is ignored; OBJ convention kept (v up).
  ``vn x y z`` lines are checked as strictly (numbers, three of them, finite) and then dropped:
  normals are recomputed downstream.
* Positions, colours, texture coordinates and normals must be finite: NaN/Inf (including MSVC's
  ``1.#IND``/``1.#INF``) is an :class:`InputError` naming the first few lines, as is a position
  beyond ``scene.MAX_COORDINATE`` (1e30). A malformed
  number on a ``v``/``vt``/``vn``/``f`` line is an :class:`InputError` naming file and line.
* Faces: index 0, an index out of range (positive indices may refer to vertices defined later
  in the file; negative ones count back from the line) or fewer than 3 corners make a bad face:
  :class:`InputError` when ``job.strict``, else the face is dropped with one warning giving the
  count and the first lines. Normal indices (``v//vn``, ``v/vt/vn``) are checked the same way
  against the ``vn`` lines, though the normals themselves are unused.
* ``poly_uvs`` is per corner when any kept corner has a ``vt``; corners without one get (0, 0)
  and a warning. No ``vt`` on any kept corner: ``None``.
* ``usemtl``: faces use the last ``usemtl`` above them; faces before any ``usemtl`` (or after an
  empty ``usemtl``) use a material named ``default``. ``scene.materials`` holds exactly the
  materials that kept faces use, in order of first use; MTL materials never used are dropped
  (their names are listed in ``details["materials_unused"]``). A ``usemtl`` name no MTL defines
  gets a default-coloured material of that name (one warning). With no faces at all the scene
  keeps the one default material.
* ``mtllib``: one or more files relative to the OBJ (a name with spaces is tried whole first);
  backslashes are accepted; a missing file falls back to the same base name next to the OBJ,
  then to a case-insensitive match; still missing: a warning and default colours. Like glTF
  URIs, MTL and texture files must lie in the OBJ's folder (or below it): a path that leaves it
  (``..``, absolute, a symbolic link pointing out) is not read (a warning; the same base name next
  to the OBJ is still tried).
* MTL: ``newmtl`` (rest of the line, trimmed), ``Kd`` (rgb; one value = grey; ``spectral``/``xyz``
  forms are ignored with a warning; clipped to [0, 1]), ``d`` (alpha, ``-halo`` skipped) and
  ``Tr`` (alpha = 1 - Tr, used only when the material has no ``d``). ``Tr 1`` would make the
  material invisible, yet MeshLab and other exporters write ``Tr 1.000000`` for opaque textured
  materials (corpus ``fuze_textured``, ``capsule_textured``), so ``Tr 1`` alone is read as
  opaque, with a warning.
  ``map_Kd``: options (``-s 1 1 1``, ``-bm 2`` ...) are skipped, the rest of the line is the file
  name (spaces kept, backslashes accepted, surrounding quotes removed), resolved relative to the
  .mtl like ``mtllib``; :attr:`Material.texture` is the absolute path when the file exists,
  else a warning. A malformed MTL number is a warning naming the MTL line. The first
  definition of a material name wins. Other MTL statements are ignored.
* Names (materials, ``mtllib``/``map_Kd`` files) are decoded as UTF-8, falling back to Latin-1
  per line (corpus ``house_max2obj_walls``), with a warning. (A Latin-1 *file name* is then
  looked up as the UTF-8 encoding of that text, so such a texture may be reported missing.)
* ``o``/``g``/``s``/``mg`` are accepted and ignored (counted in details); ``l``/``p`` are skipped
  and counted in a warning; free-form and unknown directives are counted in one warning.
* An empty file or one without faces gives a scene with 0 polygons and a warning.
"""

from __future__ import annotations

import os
import re
import time
import warnings
from pathlib import Path

import numpy as np

from ..config import ImportJob
from ..errors import InputError
from ..record import StageRecord
from ..scene import DEFAULT_MATERIAL, MAX_COORDINATE, Material, Scene, SourceInfo

__all__ = ["load"]

# line kinds
_EMPTY, _OTHER, _V, _VT, _VN, _F, _L, _P, _GROUP = range(9)

_BOM = b"\xef\xbb\xbf"
# byte classes of face corner tokens
_C_BAD, _C_DIGIT, _C_SLASH, _C_SIGN, _C_SPACE = range(5)
_CORNER_LUT = np.full(256, _C_BAD, np.uint8)
_CORNER_LUT[48:58] = _C_DIGIT
_CORNER_LUT[47] = _C_SLASH
_CORNER_LUT[[43, 45]] = _C_SIGN
_CORNER_LUT[32] = _C_SPACE
_ABSENT = 10 ** 18  # stands for an empty field ("1//3"); real fields have at most 18 characters
_ABSENT_B = str(_ABSENT).encode()
_WS_TO_SPACE = bytes.maketrans(bytes(range(33)), b" " * 33)
_MSVC_SPECIAL = re.compile(rb"[+-]?\d*\.?\d*#(IND|INF|QNAN|SNAN)\d*", re.IGNORECASE)
_FIRST_LINES = 5  # how many line numbers a message lists
# bytes per parse block (whole lines). Memory is the output arrays plus about 25 times this
# (4 MB: a 263 MB OBJ peaks at 0.63 GB; 4-16 MB parse at the same speed); tests set it tiny to
# show the block boundaries change nothing
BLOCK_SIZE = 4 * 1024 * 1024
_HEAD_BYTES = 65536  # the start of the file checked for control bytes
_SCAN_BYTES = 4 * 1024 * 1024  # chunks when only looking through the file (NUL, newline kind)

# directives that are fine to ignore silently
_IGNORED = {"mg", "maplib", "usemap", "lod", "shadow_obj", "trace_obj", "bevel", "c_interp",
            "d_interp", "ctech", "stech"}
# MTL statements we read or knowingly ignore
_MTL_KNOWN = {"newmtl", "kd", "d", "tr", "map_kd", "ka", "ks", "ke", "ns", "ni", "illum", "tf",
              "sharpness", "map_ka", "map_ks", "map_ns", "map_d", "map_bump", "bump", "disp",
              "decal", "refl", "norm", "pr", "pm", "ps", "pc", "pcr", "aniso", "anisor", "map_pr",
              "map_pm", "map_ps", "map_ke", "map_refl", "map_norm"}
# map_* options and how many arguments they take (-o/-s/-t take 1 to 3 numbers)
_MAP_OPTIONS = {"-blendu": 1, "-blendv": 1, "-boost": 1, "-mm": 2, "-o": 3, "-s": 3, "-t": 3,
                "-texres": 1, "-clamp": 1, "-bm": 1, "-imfchan": 1, "-type": 1, "-cc": 1}
_VAR_OPTIONS = {"-o", "-s", "-t"}


# --------------------------------------------------------------------------- entry point
def load(job: ImportJob, *, block_size: int | None = None) -> tuple[Scene, StageRecord]:
    """Read ``job.path`` (OBJ + its MTL files) into a scene with polygons (n-gons kept).

    The file is parsed in blocks of whole lines of about ``block_size`` bytes (default
    :data:`BLOCK_SIZE`); the result, warnings and errors do not depend on the block size."""
    t0 = time.perf_counter()
    path = Path(job.path)
    rec = StageRecord(name="import")
    p = _Parser(path, bool(job.strict), rec)
    try:
        f = open(path, "rb")
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror or e}", path=path) from None
    with f:
        reader = _Reader(f, path, BLOCK_SIZE if block_size is None else block_size)
        for block, final in reader.blocks():
            p.feed(block, reader.nlb, final)
    scene = p.finish()
    sizes = scene.poly_sizes
    cnt = np.bincount(sizes) if len(sizes) else np.zeros(0, np.int64)
    rec.details.update({
        "format": "obj",
        "polygon_sizes": {str(int(s)): int(cnt[s]) for s in np.flatnonzero(cnt)},
        "vertices": scene.n_vertices,
        "polygons": scene.n_polygons,
        "materials": [m.name for m in scene.materials],
        "files_read": [str(f) for f in scene.source.files_read],
    })
    rec.details.update(p.details)
    rec.counts_out = {"polygons": scene.n_polygons, "triangles": 0, "vertices": scene.n_vertices,
                      "materials": len(scene.materials), "uv_corners": int(p.details["uv_corners"])}
    rec.seconds = time.perf_counter() - t0
    return scene, rec


def _control_bytes(head: bytes) -> str | None:
    """Why the first bytes of a file do not look like text (None if they do)."""
    arr = np.frombuffer(head, np.uint8)
    if len(arr):
        ctrl = ((arr < 32) & ~np.isin(arr, (9, 10, 11, 12, 13, 26))) | (arr == 127)
        n = int(ctrl.sum())
        if n >= 8 and n > 0.01 * len(arr):
            return (f"not a text file ({n} control bytes in the first {len(arr)}); expected "
                    f"Wavefront OBJ text")
    return None


def _decode(b: bytes) -> tuple[str, bool]:
    """UTF-8, else Latin-1 (never fails). Returns (text, used_fallback)."""
    try:
        return b.decode("utf-8"), False
    except UnicodeDecodeError:
        return b.decode("latin-1"), True


def _lines_list(lines: np.ndarray) -> str:
    shown = ", ".join(str(int(x)) for x in lines[:_FIRST_LINES])
    return shown + (", ..." if len(lines) > _FIRST_LINES else "")


def _excl_cumsum(a: np.ndarray) -> np.ndarray:
    out = np.zeros(len(a), dtype=np.int64)
    if len(a) > 1:
        np.cumsum(a[:-1], out=out[1:])
    return out


def _concat(parts: list[np.ndarray], empty_shape: tuple, dtype) -> np.ndarray:
    """The blocks' arrays as one (the list is emptied, so each part can be freed)."""
    if not parts:
        return np.zeros(empty_shape, dtype)
    out = parts[0] if len(parts) == 1 else np.concatenate(parts)
    parts.clear()
    return out


class _Lines:
    """How many lines something concerns, and the first few of them (for a message)."""

    __slots__ = ("n", "first")

    def __init__(self) -> None:
        self.n = 0
        self.first: list[int] = []

    def add(self, lines, n: int | None = None) -> None:
        """``lines`` (the first few, at least), of ``n`` in all (default: as many as given)."""
        self.n += len(lines) if n is None else n
        room = _FIRST_LINES + 1 - len(self.first)  # one more than shown: "..." or not
        if room > 0:
            self.first.extend(int(x) for x in lines[:room])

    def text(self) -> str:
        return _lines_list(np.array(self.first, dtype=np.int64))


# --------------------------------------------------------------------------- reading in blocks
class _Reader:
    """The file's bytes as blocks of whole logical lines.

    The checks of the whole-file reader come first, in its order: UTF-16, a NUL byte anywhere
    (checked on every chunk read, with its offset in the file), control bytes in the first 64 KiB
    (raised only once the rest of the file is known to hold no NUL). The UTF-8 BOM is dropped.
    The newline byte is decided for the whole file, as before: LF, or CR when the file has CRs
    but no LF at all. A block ends just after a newline that does not end a continued line
    (backslash + newline), so every logical line lies in one block; the last block (``final``)
    is the rest of the file, with or without a newline at its end.
    """

    def __init__(self, f, path: Path, block_size: int):
        self.f, self.path = f, path
        self.size = max(int(block_size), 1)
        self.offset = 0  # bytes read so far
        self.eof = False
        head = self._read(_HEAD_BYTES, check_nul=False)
        if head[:2] in (b"\xff\xfe", b"\xfe\xff"):
            raise InputError("UTF-16 text is not supported; save the OBJ as UTF-8 or ASCII", path=path)
        self._nul(head, 0)
        why = _control_bytes(head)
        if why:
            while self._read(_SCAN_BYTES):  # a NUL byte later in the file is reported first
                pass
            raise InputError(why, path=path)
        if head.startswith(_BOM):
            head = head[3:]
        if b"\n" in head:
            self.nlb = 10
        elif self.eof:
            self.nlb = 13 if b"\r" in head else 10
        else:
            self.nlb, head = self._scan_newlines(head)
        self.head = head

    def _nul(self, chunk: bytes, offset: int) -> None:
        nul = chunk.find(b"\x00")
        if nul >= 0:
            raise InputError(f"not a text file (NUL byte at offset {offset + nul}); expected "
                             f"Wavefront OBJ text", path=self.path)

    def _read(self, n: int, check_nul: bool = True) -> bytes:
        """Up to ``n`` bytes (fewer only at the end of the file)."""
        parts, got = [], 0
        while got < n and not self.eof:
            try:
                chunk = self.f.read(n - got)
            except OSError as e:
                raise InputError(f"cannot read file: {e.strerror or e}", path=self.path) from None
            if not chunk:
                self.eof = True
                break
            parts.append(chunk)
            got += len(chunk)
        data = parts[0] if len(parts) == 1 else b"".join(parts)
        if check_nul:
            self._nul(data, self.offset)
        self.offset += len(data)
        return data

    def _scan_newlines(self, head: bytes) -> tuple[int, bytes]:
        """The newline byte when the first 64 KiB have no LF: look through the rest of the file
        (and come back), or keep the whole file if it cannot seek."""
        cr, lf = b"\r" in head, False
        if self.f.seekable():
            pos, offset, eof = self.f.tell(), self.offset, self.eof
            while not lf:
                chunk = self._read(_SCAN_BYTES)
                if not chunk:
                    break
                lf, cr = b"\n" in chunk, cr or b"\r" in chunk
            self.f.seek(pos)
            self.offset, self.eof = offset, eof
        else:
            rest = []
            while chunk := self._read(_SCAN_BYTES):
                rest.append(chunk)
            head = b"".join([head, *rest])
            lf, cr = b"\n" in head, b"\r" in head
        return (10 if lf or not cr else 13), head

    def blocks(self):
        """Yield (block, final) pairs."""
        buf, self.head = self.head, b""
        start = 0  # buf[:start] is done
        size = self.size
        while True:
            left = len(buf) - start
            if left < size and not self.eof:
                buf, start = buf[start:] + self._read(size - left), 0
                continue
            if self.eof and left <= size:
                yield buf[start:], True
                return
            cut = _cut(buf, start, start + size, self.nlb)
            if cut:
                yield buf[start:cut], False
                start = cut
            elif self.eof:
                yield buf[start:], True
                return
            else:  # one logical line longer than a block: take more
                buf, start = buf[start:] + self._read(size), 0


def _continued(buf: bytes, p: int, nlb: int) -> bool:
    """The newline at ``p`` continues its line (backslash + newline)."""
    return (p >= 1 and buf[p - 1] == 92) or (nlb == 10 and p >= 2 and buf[p - 1] == 13
                                             and buf[p - 2] == 92)


def _free_newlines(buf: bytes, lo: int, hi: int, nlb: int) -> np.ndarray:
    """Positions in [lo, hi) of the newlines that do not continue their line."""
    arr = np.frombuffer(buf, np.uint8)
    p = np.flatnonzero(arr[lo:hi] == nlb) + lo
    b1 = arr[np.maximum(p - 1, 0)]
    cont = (p >= 1) & (b1 == 92)
    if nlb == 10:
        cont |= (p >= 2) & (b1 == 13) & (arr[np.maximum(p - 2, 0)] == 92)
    return p[~cont]


def _cut(buf: bytes, start: int, limit: int, nlb: int) -> int:
    """Where to end the block that starts at ``start``: just after the last newline before
    ``limit`` that does not continue its line, else after the first such one from ``limit`` on;
    0 if there is none. (The byte before ``start`` is a newline that continues nothing.)"""
    nl = b"\n" if nlb == 10 else b"\r"
    p = buf.rfind(nl, start, limit)
    if p >= 0 and _continued(buf, p, nlb):
        free = _free_newlines(buf, start, p, nlb)
        p = int(free[-1]) if len(free) else -1
    if p >= 0:
        return p + 1
    p = buf.find(nl, limit)
    if p >= 0 and _continued(buf, p, nlb):
        free = _free_newlines(buf, p, len(buf), nlb)
        p = int(free[0]) if len(free) else -1
    return p + 1 if p >= 0 else 0


# --------------------------------------------------------------------------- tokeniser
class _Tokens:
    """Token spans of one block and the logical line each belongs to (numpy arrays).

    ``block`` holds whole lines (see :class:`_Reader`); ``phys0`` is the number of physical
    lines before it, so ``line_no`` gives line numbers in the file. Line indices (``tline``,
    ``lines_of`` ...) count the block's logical lines from 0."""

    def __init__(self, block: bytes, nlb: int, final: bool = True, phys0: int = 0):
        # the last line terminated (the file's may not be); a spare byte for look-ahead
        data = b"".join((block, bytes((nlb, 32)) if final else b" "))
        self.data = data
        arr = np.frombuffer(data, np.uint8)
        self.arr = arr
        ws = arr <= 32  # whitespace: space, tab, CR, VT, FF (and other control bytes)
        nlmask = arr == nlb
        phys_nl = np.flatnonzero(nlmask)
        self.n_phys = len(phys_nl)
        self.clean = arr  # the bytes with continuation backslashes made spaces
        if b"\\" in block:  # line continuation: backslash + end of line is whitespace
            bs = np.flatnonzero(arr[:-2] == 92)
            c1 = bs[arr[bs + 1] == nlb]
            c2 = bs[(arr[bs + 1] == 13) & (arr[bs + 2] == 10)] if nlb == 10 else bs[:0]
            # a backslash at the very end of the file continues nothing: the newline after it is
            # the one appended above, which must stay (else the last line has no terminator).
            # (A block that is not the last ends with a newline that continues nothing.)
            end = len(data) - 2
            c1, c2 = c1[c1 + 1 < end], c2[c2 + 2 < end]
            if len(c1) or len(c2):
                ws = ws.copy()
                nlmask = nlmask.copy()
                ws[c1] = ws[c2] = True
                nlmask[c1 + 1] = nlmask[c2 + 2] = False
                self.clean = arr.copy()
                self.clean[c1] = self.clean[c2] = 32
        # token starts (a non-space after a space) and ends, in one pass each
        st = np.empty(len(arr), bool)
        st[0] = not ws[0]
        np.greater(ws[:-1], ws[1:], out=st[1:])
        en = np.empty(len(arr), bool)
        en[0] = False
        np.less(ws[:-1], ws[1:], out=en[1:])
        del ws
        ends = np.flatnonzero(en)
        del en
        # token starts and logical newlines in one sorted array: a token's line is the number
        # of newlines before it
        st |= nlmask
        ev = np.flatnonzero(st)
        del st
        ev_nl = nlmask[ev]
        nl = ev[ev_nl]
        line_of_ev = np.cumsum(ev_nl)
        tok_ev = ~ev_nl
        starts = ev[tok_ev]
        tline = line_of_ev[tok_ev]
        del ev, ev_nl, line_of_ev, tok_ev
        self.n_lines = len(nl)
        if len(nl) == len(phys_nl):
            self.line_no = np.arange(phys0 + 1, phys0 + len(nl) + 1, dtype=np.int64)
        else:
            line_start = np.concatenate([[0], nl[:-1] + 1])
            self.line_no = np.searchsorted(phys_nl, line_start) + (phys0 + 1)  # physical line
        del nl, phys_nl, nlmask
        hashes = np.flatnonzero(arr[starts] == 35)
        if len(hashes):  # drop comment tokens and everything after them on their line
            stop = np.searchsorted(tline, tline[hashes], side="right")
            keep = np.ones(len(starts), bool)
            keep[_ranges(hashes, stop)] = False
            starts, ends, tline = starts[keep], ends[keep], tline[keep]
        self.starts, self.ends, self.tline = starts, ends, tline
        first = np.ones(len(starts), bool)
        first[1:] = tline[1:] != tline[:-1]
        last = np.ones(len(starts), bool)
        last[:-1] = first[1:]
        self.first = first
        # per line: keyword span and the end of the last token (for "rest of line")
        fs, fe, fl = starts[first], ends[first], tline[first]
        self.kw_start = np.zeros(self.n_lines, np.int64)
        self.kw_end = np.zeros(self.n_lines, np.int64)
        self.line_end = np.zeros(self.n_lines, np.int64)
        self.kw_start[fl], self.kw_end[fl] = fs, fe
        self.line_end[tline[last]] = ends[last]
        kind = np.full(len(fs), _OTHER, np.int8)
        flen = fe - fs
        b0, b1 = arr[fs], arr[fs + 1]
        one = flen == 1
        two = flen == 2
        kind[one & (b0 == ord("v"))] = _V
        kind[one & (b0 == ord("f"))] = _F
        kind[one & (b0 == ord("l"))] = _L
        kind[one & (b0 == ord("p"))] = _P
        kind[one & np.isin(b0, (ord("o"), ord("g"), ord("s")))] = _GROUP
        kind[two & (b0 == ord("v")) & (b1 == ord("t"))] = _VT
        kind[two & (b0 == ord("v")) & (b1 == ord("n"))] = _VN
        self.line_kind = np.full(self.n_lines, _EMPTY, np.int8)
        self.line_kind[fl] = kind
        self.tkind = np.where(first, _EMPTY, self.line_kind[tline]).astype(np.int8)  # data tokens

    def lines_of(self, kind: int) -> np.ndarray:
        return np.flatnonzero(self.line_kind == kind)

    def data_tokens(self, kind: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(starts, ends, line) of the tokens after the keyword on lines of ``kind``."""
        sel = self.tkind == kind
        return self.starts[sel], self.ends[sel], self.tline[sel]

    def token(self, s: int, e: int) -> str:
        return _decode(self.clean[s:e].tobytes())[0]


def _ranges(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Concatenation of ``arange(lo[i], hi[i])`` for all i."""
    n = hi - lo
    tot = int(n.sum())
    return np.arange(tot, dtype=np.int64) + np.repeat(lo - _excl_cumsum(n), n)


def _gather(arr: np.ndarray, starts: np.ndarray, ends: np.ndarray) -> bytes:
    """The bytes of the given token spans, each with the one (whitespace) byte that follows it."""
    # spans [start, end] do not overlap: +1 at a start and -1 after the end, summed, is a mask
    d = np.zeros(len(arr) + 1, np.int8)
    d[starts] = 1
    d[ends + 1] -= 1
    mask = np.cumsum(d[:-1], dtype=np.int8).view(bool)
    return arr[mask].tobytes().translate(_WS_TO_SPACE)


# --------------------------------------------------------------------------- parser
# Errors, in the order the checks run over the whole file: the first kind found anywhere wins,
# and within a kind the first line (or, for NaN / range, all lines counted).
(_E_V_NUMBER, _E_V_FEW, _E_V_NONFINITE, _E_V_HUGE, _E_VT_NUMBER, _E_VT_EMPTY, _E_VT_NONFINITE,
 _E_VN_NUMBER, _E_VN_FEW, _E_VN_NONFINITE, _E_CORNER, _E_CORNER_PARSE) = range(1, 13)
_NO_ERROR = 100


class _Parser:
    """Feed it the blocks in order (:meth:`feed`), then :meth:`finish` for the scene.

    Each block is tokenised and parsed on its own; what crosses blocks is carried explicitly:
    physical line count (line numbers), ``v``/``vt`` counts (relative indices), the current
    ``usemtl``, and for messages the first error of each kind and counts with first lines.
    Compact arrays per block (positions, UVs, face sizes, resolved indices, materials) are
    concatenated at the end. Errors are raised at the end, in the whole-file order (a later
    block may hold one that comes first); once a block has an error, later blocks are only
    searched for errors that would come before it.
    """

    def __init__(self, path: Path, strict: bool, rec: StageRecord):
        self.path = path
        self.strict = strict
        self.rec = rec
        self.t: _Tokens | None = None
        self.details: dict = {}
        self.files: list[Path] = [Path(os.path.abspath(path))]
        self.missing: list[Path] = []  # named and not found (for --depfile)
        self.phys = 0  # physical lines in the blocks so far
        self.nv = self.nt = self.nf = self.nvn = 0  # v, vt, f, vn lines so far
        self.best = _NO_ERROR  # the first error kind found so far
        self.errors: dict[int, tuple[str, int]] = {}
        self.nonfinite_v, self.huge_v, self.nonfinite_vt = _Lines(), _Lines(), _Lines()
        self.nonfinite_vn = _Lines()
        self.bad_normals = _Lines()  # face lines naming a normal that is not there (a warning)
        # for warnings
        self.odd_v, self.odd_v_values = _Lines(), 0
        self.many_vt = _Lines()
        self.latin1 = _Lines()
        self.unknown: dict[str, list[int]] = {}  # directive -> [count, first line]
        self.groups = self.n_l = self.n_p = 0
        self.mtllibs: list[tuple[int, str]] = []
        self.name_cache: dict[bytes, tuple[str, bool]] = {}  # decoded once per distinct name
        self.names: list[str] = []
        self.name_id: dict[str, int] = {}
        self.current = self._name("default")  # the material of the next face
        # vertex colours: (first vertex, rows (n, 4), has rgb, has alpha) of blocks with colours
        self.col_blocks: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []
        self.col_min, self.col_max, self.col_whole = np.inf, -np.inf, True
        self.col_vertices = 0
        # per block
        self.pos: list[np.ndarray] = []
        self.uv: list[np.ndarray] = []
        self.sizes: list[np.ndarray] = []
        self.vres: list[np.ndarray] = []  # 0-based vertex index; -1: index 0 / before the file
        self.tres: list[np.ndarray | None] = []  # the same for vt; -2: no vt; None: none at all
        self.nres: list[np.ndarray | None] = []  # the same for vn (checked, then not used)
        self.fmat: list[np.ndarray] = []  # material id per face
        self.fline: list[np.ndarray | None] = []  # line numbers, kept for blocks with bad faces
        self.fstart: list[int] = []  # first face of each block
        self.first_bad: tuple | None = None  # the first face found bad within its block

    def err(self, msg: str, line: int | None = None, path: Path | None = None) -> InputError:
        return InputError(msg, path=path or self.path, line=line)

    def _fail(self, kind: int, msg: str, line: int) -> None:
        if kind not in self.errors:
            self.errors[kind] = (msg, line)
        self.best = min(self.best, kind)

    def _count(self, kind: int, acc: _Lines, lines: np.ndarray) -> None:
        acc.add(lines)
        self.best = min(self.best, kind)

    def _name(self, name: str) -> int:
        if name not in self.name_id:
            self.name_id[name] = len(self.names)
            self.names.append(name)
        return self.name_id[name]

    # ------------------------------------------------------------------ one block
    def feed(self, block: bytes, nlb: int, final: bool) -> None:
        if self.best <= _E_V_NUMBER:
            return  # nothing in a later block comes first (a NUL byte is the reader's)
        t = self.t = _Tokens(block, nlb, final, self.phys)
        self.phys += t.n_phys
        vlines, vtlines, vnlines = t.lines_of(_V), t.lines_of(_VT), t.lines_of(_VN)
        nv0, nt0, nn0 = self.nv, self.nt, self.nvn
        self.nv += len(vlines)
        self.nt += len(vtlines)
        self.nvn += len(vnlines)
        self.vertices(vlines, nv0)
        if self.best > _E_VT_NUMBER:
            self.texcoords(vtlines)
        if self.best > _E_VN_NUMBER:
            self.normals(vnlines)
        faces = self.corners() if self.best > _E_CORNER else None
        if self.best == _NO_ERROR:
            uses = self.other_lines()
            self.faces(faces, vlines, nv0, vtlines, nt0, uses, vnlines, nn0)
        else:  # an error will be raised: the arrays are not needed
            for lst in (self.pos, self.uv, self.sizes, self.vres, self.tres, self.nres, self.fmat, self.fline,
                        self.col_blocks):
                lst.clear()
        self.t = None

    # ------------------------------------------------------------------ numbers
    def _floats(self, kind: int, what: str, lines: np.ndarray, err: int
                ) -> tuple[np.ndarray, np.ndarray] | None:
        """All numbers on lines of ``kind``: (values, values per line); None after a malformed
        number (recorded as error ``err``)."""
        t = self.t
        s, e, tl = t.data_tokens(kind)
        counts = np.bincount(np.searchsorted(lines, tl), minlength=len(lines)).astype(np.int64)
        buf = _gather(t.clean, s, e)
        try:  # numpy >= 2.3 raises on anything that is not whitespace-separated numbers
            with warnings.catch_warnings():
                warnings.simplefilter("error", DeprecationWarning)  # older numpy only warns
                vals = np.fromstring(buf, dtype=np.float64, sep=" ")
            if len(vals) != len(s):
                raise ValueError("token count")
        except (ValueError, DeprecationWarning):
            toks = buf.split()
            vals = np.empty(len(toks), np.float64)
            for i, tok in enumerate(toks):  # error path only: find the bad token(s)
                try:
                    if b"_" in tok:
                        raise ValueError
                    vals[i] = float(tok)
                except ValueError:
                    if _MSVC_SPECIAL.fullmatch(tok):
                        vals[i] = np.nan  # reported below as a non-finite value
                    else:
                        self._fail(err, f"malformed number '{_decode(tok)[0]}' in a '{what}' line "
                                        f"(expected a decimal number)", int(t.line_no[tl[i]]))
                        return None
        return vals, counts

    @staticmethod
    def _rows(vals: np.ndarray, counts: np.ndarray, width: int) -> np.ndarray:
        """Ragged per-line values as an (n, width) array padded with 0."""
        n = len(counts)
        if n and (counts == counts[0]).all():  # the usual case: every line has k values
            k = int(counts[0])
            r = vals.reshape(n, k)
            if k >= width:
                return r[:, :width]
            out = np.zeros((n, width))
            out[:, :k] = r
            return out
        out = np.zeros((n, width))
        c = np.minimum(counts, width)
        row = np.repeat(np.arange(n), c)
        col = np.arange(int(c.sum())) - np.repeat(_excl_cumsum(c), c)
        src = np.repeat(_excl_cumsum(counts), c) + col
        out[row, col] = vals[src]
        return out

    def _xyz(self, pattern, tag: str, lines: np.ndarray, e_number: int, e_few: int, what: str):
        """The numbers of lines that need at least x y z (``v``, ``vn``): (values, count per line,
        the file's line numbers), or None once an error is recorded."""
        got = self._floats(pattern, tag, lines, e_number)
        if got is None:
            return None
        vals, counts = got
        ln = self.t.line_no
        few = counts < 3
        if few.any():
            i = int(np.argmax(few))
            self._fail(e_few, f"{what} needs x y z, got {int(counts[i])} value(s)", int(ln[lines[i]]))
            return None
        return vals, counts, ln

    def vertices(self, lines: np.ndarray, first: int) -> None:
        got = self._xyz(_V, "v", lines, _E_V_NUMBER, _E_V_FEW, "vertex")
        if got is None:
            return
        vals, counts, ln = got
        if self.best < _E_V_NONFINITE:
            return
        odd = (counts == 5) | (counts > 7)
        if odd.any():
            if not self.odd_v.n:
                self.odd_v_values = int(counts[odd][0])
            self.odd_v.add(ln[lines[odd]])
        rows = self._rows(vals, counts, 7)
        has_col = (counts == 6) | (counts == 7)
        has_a = counts == 7
        used = np.zeros_like(rows, dtype=bool)
        used[:, :3] = True
        used[has_col, 3:6] = True
        used[has_a, 6] = True
        bad = (~np.isfinite(rows) & used).any(axis=1)
        if bad.any():
            self._count(_E_V_NONFINITE, self.nonfinite_v, ln[lines[bad]])
            return
        if self.best < _E_V_HUGE:
            return
        huge = (np.abs(rows[:, :3]) > MAX_COORDINATE).any(axis=1)
        if huge.any():
            self._count(_E_V_HUGE, self.huge_v, ln[lines[huge]])
            return
        if self.best < _NO_ERROR:
            return
        self.pos.append(np.ascontiguousarray(rows[:, :3], dtype=np.float64))
        if has_col.any():
            col = np.ones((len(rows), 4))
            col[has_col, :3] = rows[has_col, 3:6]
            col[has_a, 3] = rows[has_a, 6]
            given = np.concatenate([rows[has_col, 3:6].ravel(), rows[has_a, 6]])
            self.col_min = min(self.col_min, float(given.min()))
            self.col_max = max(self.col_max, float(given.max()))
            self.col_whole = self.col_whole and bool((given == np.round(given)).all())
            self.col_vertices += int(has_col.sum())
            self.col_blocks.append((first, col, has_col, has_a))

    def texcoords(self, lines: np.ndarray) -> None:
        got = self._floats(_VT, "vt", lines, _E_VT_NUMBER)
        if got is None:
            return
        vals, counts = got
        ln = self.t.line_no
        if (counts < 1).any():
            i = int(np.argmax(counts < 1))
            self._fail(_E_VT_EMPTY, "texture coordinate needs u [v [w]], got no values",
                       int(ln[lines[i]]))
            return
        if self.best < _E_VT_NONFINITE:
            return
        many = counts > 3
        if many.any():
            self.many_vt.add(ln[lines[many]])
        rows = self._rows(vals, counts, 2)
        used = np.ones_like(rows, dtype=bool)
        used[counts < 2, 1] = False
        bad = (~np.isfinite(rows) & used).any(axis=1)
        if bad.any():
            self._count(_E_VT_NONFINITE, self.nonfinite_vt, ln[lines[bad]])
            return
        if self.best == _NO_ERROR:
            self.uv.append(np.ascontiguousarray(rows, dtype=np.float64))

    def normals(self, lines: np.ndarray) -> None:
        """``vn x y z`` lines are checked like ``vt`` lines (bake recomputes normals and keeps
        none of them): a malformed number, fewer than three values or a NaN is an error."""
        got = self._xyz(_VN, "vn", lines, _E_VN_NUMBER, _E_VN_FEW, "vertex normal")
        if got is None:
            return
        vals, counts, ln = got
        if self.best < _E_VN_NONFINITE:
            return
        bad = ~np.isfinite(self._rows(vals, counts, 3)).all(axis=1)
        if bad.any():
            self._count(_E_VN_NONFINITE, self.nonfinite_vn, ln[lines[bad]])

    # ------------------------------------------------------------------ faces
    def corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray] | None:
        """Face lines, corners per face, corner index fields (C, 3) int64 and presence (C, 3);
        None after a malformed corner (recorded).

        Corner tokens are validated byte-wise (digits, one leading sign per field, at most two
        '/', no empty vertex field, at most 18 characters per field), then empty fields get a
        sentinel, '/' becomes a separator and all fields are converted in one call.
        """
        t = self.t
        s, e, tl = t.data_tokens(_F)
        flines = t.lines_of(_F)
        sizes = np.bincount(np.searchsorted(flines, tl), minlength=len(flines)).astype(np.int64)
        C = len(s)
        idx = np.zeros((C, 3), np.int64)
        has = np.zeros((C, 3), bool)
        if C == 0:
            return flines, sizes, idx, has
        buf = _gather(t.clean, s, e)
        cb = _CORNER_LUT[np.frombuffer(buf, np.uint8)]
        tstart = np.arange(C, dtype=np.int64) + _excl_cumsum(e - s)
        bad = np.zeros(C, bool)

        def mark(pos: np.ndarray) -> None:
            if len(pos):
                bad[np.searchsorted(tstart, pos, side="right") - 1] = True

        mark(np.flatnonzero(cb == _C_BAD))
        sg = np.flatnonzero(cb == _C_SIGN)
        if len(sg):  # a sign must start a field and be followed by a digit
            prev = np.where(sg > 0, cb[np.maximum(sg - 1, 0)], _C_SPACE)
            mark(sg[((prev != _C_SLASH) & (prev != _C_SPACE)) | (cb[sg + 1] != _C_DIGIT)])
        sl = np.flatnonzero(cb == _C_SLASH)
        nsl = np.bincount(np.searchsorted(tstart, sl, side="right") - 1, minlength=C)
        bad |= nsl > 2
        if len(sl):  # the vertex field must not be empty ("/2", "//3")
            mark(sl[cb[sl - 1] == _C_SPACE])
        seps = np.flatnonzero((cb == _C_SLASH) | (cb == _C_SPACE))
        flen = np.diff(seps, prepend=-1) - 1
        mark(seps[flen > 18])
        del cb, seps, flen
        if bad.any():
            i = int(np.argmax(bad))
            self._fail(_E_CORNER, f"malformed face corner '{t.token(int(s[i]), int(e[i]))}' "
                                  f"(expected v, v/vt, v//vn or v/vt/vn with integer indices)",
                       int(t.line_no[tl[i]]))
            return None
        if len(sl):
            buf = buf.replace(b"//", b"/" + _ABSENT_B + b"/").replace(b"/ ", b"/" + _ABSENT_B + b" ")
            buf = buf.replace(b"/", b" ")
        vals = np.fromstring(buf, dtype=np.int64, sep=" ")
        del buf
        if len(vals) != C + int(nsl.sum()):  # cannot happen after validation; never guess
            self._fail(_E_CORNER_PARSE, "could not parse face indices", int(t.line_no[tl[0]]))
            return None
        if not len(sl):  # the usual "f 1 2 3": vertex indices only
            idx[:, 0] = np.where(vals == _ABSENT, 0, vals)
            has[:, 0] = vals != _ABSENT
            return flines, sizes, idx, has
        off = np.arange(C, dtype=np.int64) + _excl_cumsum(nsl)
        for k in range(3):
            m = nsl >= k
            v = vals[off[m] + k]
            idx[m, k] = np.where(v == _ABSENT, 0, v)
            has[m, k] = v != _ABSENT
        return flines, sizes, idx, has

    def faces(self, faces, vlines: np.ndarray, nv0: int, vtlines: np.ndarray, nt0: int,
              uses: list[tuple[int, str]], vnlines: np.ndarray, nn0: int) -> None:
        """Resolve this block's corners against the ``v``/``vt`` lines so far (relative indices
        and indices 0 are final here; an index beyond the file's last vertex is known only at
        the end) and give each face its material."""
        flines, sizes, idx, has = faces
        nfb = len(flines)
        f0 = self.nf
        self.nf += nfb
        self.fstart.append(f0)
        if uses:
            ul = np.array([ln for ln, _ in uses], dtype=np.int64)
            occ = np.array([self._name(nm or "default") for _, nm in uses], dtype=np.int32)
            o = np.searchsorted(ul, flines, side="right") - 1
            fmat = np.where(o >= 0, occ[np.maximum(o, 0)], np.int32(self.current)).astype(np.int32)
            self.current = int(occ[-1])
        else:
            fmat = np.full(nfb, self.current, np.int32)
        face_of = np.repeat(np.arange(nfb, dtype=np.int64), sizes)
        vbefore = (nv0 + np.searchsorted(vlines, flines))[face_of]
        raw, present = idx[:, 0], has[:, 0]
        vres = np.where(raw > 0, raw - 1, vbefore + raw)
        bad = present & ((raw == 0) | (vres < 0))  # index 0, or relative and before the file
        vres[bad] = -1
        if not present.all():
            vres[~present] = 0
        tres = tbefore = None
        if has[:, 1].any():
            tbefore = (nt0 + np.searchsorted(vtlines, flines))[face_of]
            traw, tp = idx[:, 1], has[:, 1]
            tres = np.where(traw > 0, traw - 1, tbefore + traw)
            tbad = tp & ((traw == 0) | (tres < 0))
            tres[tbad] = -1
            tres[~tp] = -2
            bad |= tbad
        nres = None
        if has[:, 2].any():  # normal indices: checked, but a bad one only warns (normals are unused)
            nbefore = (nn0 + np.searchsorted(vnlines, flines))[face_of]
            nraw, np_ = idx[:, 2], has[:, 2]
            nres = np.where(nraw > 0, nraw - 1, nbefore + nraw)
            nres[np_ & ((nraw == 0) | (nres < 0))] = -1
            nres[~np_] = -2
            self.bad_normals.add(self.t.line_no[flines[np.unique(face_of[nres == -1])]])
            nres = np.where(nres == -1, -2, nres)  # (counted; beyond the file's vn lines: at the end)
        badf = sizes < 3
        if bad.any():
            badf[face_of[bad]] = True
        del face_of, bad
        # faces that may point past the file's last vertex / vt (known at the end)
        ahead = ((len(vres) and int(vres.max()) >= self.nv)
                 or (tres is not None and len(tres) and int(tres.max()) >= self.nt)
                 or (nres is not None and len(nres) and int(nres.max()) >= self.nvn))
        anybad = bool(badf.any())
        self.fline.append(self.t.line_no[flines] if anybad or ahead else None)
        if anybad and self.first_bad is None:
            f = int(np.argmax(badf))
            c0 = int(_excl_cumsum(sizes)[f])
            c1 = c0 + int(sizes[f])
            tb = tbefore[c0:c1].copy() if tbefore is not None else np.zeros(c1 - c0, np.int64)
            self.first_bad = (f0 + f, idx[c0:c1].copy(), has[c0:c1].copy(), vbefore[c0:c1].copy(), tb)
        self.sizes.append(sizes)
        self.vres.append(vres)
        self.tres.append(tres)
        self.nres.append(nres)
        self.fmat.append(fmat)

    def resolve(self, raw: np.ndarray, present: np.ndarray, before: np.ndarray, total: int
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """0-based indices, and masks of zero / out-of-range entries (only where present)."""
        res = np.where(raw > 0, raw - 1, before + raw)
        zero = present & (raw == 0)
        oor = present & ~zero & ((res < 0) | (res >= total))
        res = np.where(present & ~zero & ~oor, res, 0)
        return res, zero, oor

    @staticmethod
    def face_problem(corner0: int, size: int, raw: np.ndarray, zero: np.ndarray, oor: np.ndarray,
                     before: np.ndarray, total: int, what: str, unit: str) -> str | None:
        """Why the face whose corners start at ``corner0`` is bad (None if these indices are fine)."""
        for j in range(size):
            c = corner0 + j
            if zero[c]:
                return f"face {what} 0 is invalid (OBJ indices start at 1)"
            if oor[c]:
                r = int(raw[c])
                if r < 0:
                    return (f"face {what} {r} is out of range ({int(before[c])} {unit} defined "
                            f"before this line)")
                return f"face {what} {r} is out of range (file has {total} {unit})"
        return None

    def _face_line(self, face: int) -> int:
        b = int(np.searchsorted(self.fstart, face, side="right")) - 1
        return int(self.fline[b][face - self.fstart[b]])

    def _why(self, face: int, size: int, c0: int, vres: np.ndarray, tres: np.ndarray | None,
             NV: int, NT: int) -> str:
        """Why the first bad face is bad (the whole-file parser's message)."""
        if size < 3:
            return f"face has fewer than 3 vertices ({size} given)"
        if self.first_bad is not None and self.first_bad[0] == face:
            _, idx, has, vbefore, tbefore = self.first_bad
            vraw, traw = idx[:, 0], idx[:, 1]
            _, vzero, voor = self.resolve(vraw, has[:, 0], vbefore, NV)
            _, tzero, toor = self.resolve(traw, has[:, 1], tbefore, NT)
        else:  # bad only because an index lies beyond the end of the file
            v = vres[c0:c0 + size]
            vraw, vzero, voor, vbefore = v + 1, np.zeros(size, bool), v >= NV, v
            if tres is None:
                traw = tbefore = np.zeros(size, np.int64)
                tzero = toor = np.zeros(size, bool)
            else:
                tc = tres[c0:c0 + size]
                traw, tzero, toor, tbefore = tc + 1, np.zeros(size, bool), tc >= NT, tc
        return (self.face_problem(0, size, vraw, vzero, voor, vbefore, NV, "index", "vertices")
                or self.face_problem(0, size, traw, tzero, toor, tbefore, NT, "texture index",
                                     "texture coordinates")
                or "")

    # ------------------------------------------------------------------ the end
    def _raise_first_error(self) -> None:
        kind = self.best
        if kind == _NO_ERROR:
            return
        acc = {_E_V_NONFINITE: (self.nonfinite_v, "vertex values"),
               _E_VT_NONFINITE: (self.nonfinite_vt, "texture coordinates"),
               _E_VN_NONFINITE: (self.nonfinite_vn, "vertex normals")}
        if kind in acc:
            lines, what = acc[kind]
            raise self.err(f"{what} are NaN or infinite on {lines.n} line(s): {lines.text()}",
                           lines.first[0])
        if kind == _E_V_HUGE:
            lines = self.huge_v
            raise self.err(f"vertex coordinates beyond +-{MAX_COORDINATE:g} (the range bake supports) on "
                           f"{lines.n} line(s): {lines.text()}", lines.first[0])
        msg, line = self.errors[kind]
        raise self.err(msg, line)

    def _vertex_colors(self, NV: int) -> np.ndarray | None:
        colors = None
        if self.col_blocks:
            self.details["vertex_color_scale"] = "0-1"
            scale = self.col_max > 1.0 and self.col_whole and self.col_min >= 0
            if scale:
                self.details["vertex_color_scale"] = "0-255"
            elif self.col_max > 1.0 or self.col_min < 0.0:
                self.rec.warn(f"vertex colours outside [0, 1] (from {self.col_min:g} to "
                              f"{self.col_max:g}) were clipped")
            colors = np.ones((NV, 4))
            for first, col, has_col, has_a in self.col_blocks:
                if scale:
                    col[has_col, :3] /= 255.0
                    col[has_a, 3] /= 255.0
                colors[first:first + len(col)] = col
            self.col_blocks.clear()
            np.clip(colors, 0.0, 1.0, out=colors)
            if self.col_vertices < NV:
                self.rec.warn(f"{NV - self.col_vertices} of {NV} vertices have no colour; "
                              f"they get white")
        self.details["vertex_colors"] = colors is not None
        return colors

    def finish(self) -> Scene:
        self._raise_first_error()
        rec = self.rec
        NV, NT, NF = self.nv, self.nt, self.nf
        if self.odd_v.n:
            rec.warn(f"{self.odd_v.n} 'v' line(s) have {self.odd_v_values} values (expected "
                     f"3, 4, 6 or 7); extra values ignored (lines {self.odd_v.text()})")
        positions = _concat(self.pos, (0, 3), np.float64)
        colors = self._vertex_colors(NV)
        if self.many_vt.n:
            rec.warn(f"{self.many_vt.n} 'vt' line(s) have more than 3 values; extra "
                     f"values ignored (lines {self.many_vt.text()})")
        uvs = _concat(self.uv, (0, 2), np.float64)
        self.details.update({"texcoords": NT, "normals": self.nvn})
        self.details["groups_objects_smoothing_lines"] = self.groups
        if self.n_l or self.n_p:
            rec.warn(f"skipped {self.n_l} line element(s) ('l') and {self.n_p} point element(s) "
                     f"('p'); only faces are imported")
        self.details["skipped_elements"] = {"l": self.n_l, "p": self.n_p}
        unknown = self.unknown
        if unknown:
            parts = [f"'{k}' x{v[0]} (first at line {v[1]})" for k, v in sorted(unknown.items())]
            rec.warn(f"ignored {sum(v[0] for v in unknown.values())} line(s) with unsupported "
                     f"or unknown directives: {', '.join(parts)}")
        self.details["unknown_directives"] = {k: v[0] for k, v in sorted(unknown.items())}

        # ---- faces: indices beyond the end of the file, bad faces
        sizes = _concat(self.sizes, (0,), np.int64)
        tres = None
        if any(x is not None for x in self.tres):
            tres = np.concatenate([np.full(len(v), -2, np.int64) if x is None else x
                                   for v, x in zip(self.vres, self.tres)])
        self.tres.clear()
        nres = None
        if any(x is not None for x in self.nres):
            nres = np.concatenate([np.full(len(v), -2, np.int64) if x is None else x
                                   for v, x in zip(self.vres, self.nres)])
        self.nres.clear()
        vres = _concat(self.vres, (0,), np.int64)
        badc = vres < 0
        badc |= vres >= NV
        if tres is not None:
            badc |= tres == -1
            badc |= tres >= NT
        if nres is not None and (nres >= self.nvn).any():  # normals named past the file's last vn
            faces_of = np.searchsorted(np.cumsum(sizes), np.flatnonzero(nres >= self.nvn), side="right")
            self.bad_normals.add(np.array([self._face_line(int(f)) for f in np.unique(faces_of)[:_FIRST_LINES + 1]]),
                                 n=len(np.unique(faces_of)))
        if self.bad_normals.n:
            rec.warn(f"{self.bad_normals.n} face(s) name a normal (v//vn, v/vt/vn) that is 0 or beyond the file's "
                     f"{self.nvn} 'vn' line(s) (lines {self.bad_normals.text()}); normals are not used (bake "
                     "computes its own), so the faces are kept")
        badf = sizes < 3
        cend = None
        if badc.any():
            cend = np.cumsum(sizes)
            badf[np.searchsorted(cend, np.flatnonzero(badc), side="right")] = True
        del badc
        dropped = int(np.count_nonzero(badf))
        if dropped:
            order = np.flatnonzero(badf)
            f0 = int(order[0])
            c0 = int(cend[f0] - sizes[f0]) if cend is not None else int(sizes[:f0].sum())
            why = self._why(f0, int(sizes[f0]), c0, vres, tres, NV, NT)
            line = self._face_line(f0)
            if self.strict:
                raise self.err(why, line)
            shown = np.array([self._face_line(int(f)) for f in order[:_FIRST_LINES + 1]])
            rec.warn(f"dropped {dropped} bad face(s) (index 0, index out of range or fewer than 3 "
                     f"vertices) at lines {_lines_list(shown)}; first, line {line}: {why}")
            del order
        keepf = ~badf if dropped else slice(None)
        keepc = np.repeat(~badf, sizes) if dropped else slice(None)
        del badf
        sizes_k = sizes[keepf] if dropped else sizes
        poly_indices = vres[keepc] if dropped else vres
        del vres
        poly_uvs = None
        if tres is not None:
            tk = tres[keepc] if dropped else tres
            del tres
            has_t = tk != -2
            n_t = int(np.count_nonzero(has_t))
        else:
            has_t, n_t = None, 0
        self.details["uv_corners"] = n_t
        if n_t:
            all_t = n_t == len(has_t)
            poly_uvs = uvs[tk if all_t else np.where(has_t, tk, 0)]
            del tk
            if not all_t:
                poly_uvs[~has_t] = 0.0
                rec.warn(f"{len(has_t) - n_t} of {len(has_t)} face corners have no texture "
                         f"coordinate (vt); they get UV (0, 0)")
        del has_t
        self.details["dropped_faces"] = dropped
        fmat = _concat(self.fmat, (0,), np.int32)
        self.fmat.clear()
        if dropped:
            fmat = fmat[keepf]

        # ---- materials
        mtl = self.materials_from(self.mtllibs)
        names = self.names
        if len(fmat):  # materials in order of first use (faces come in runs of one material)
            heads = fmat[np.concatenate([[0], np.flatnonzero(fmat[1:] != fmat[:-1]) + 1])]
            u, first = np.unique(heads, return_index=True)
            used = u[np.argsort(first, kind="stable")]
            lut = np.zeros(len(names), np.int64)
            lut[used] = np.arange(len(used))
            poly_material = lut[fmat]
            used_names = [names[i] for i in used]
        else:
            poly_material = np.zeros(0, np.int64)
            used_names = []
        del fmat
        materials, unknown_m = [], []
        for nm in used_names:
            if nm in mtl:
                materials.append(mtl[nm])
            elif nm == "default":
                materials.append(DEFAULT_MATERIAL)
            else:
                unknown_m.append(nm)
                materials.append(Material(name=nm))
        if unknown_m:
            shown = ", ".join(repr(n) for n in unknown_m[:_FIRST_LINES])
            more = ", ..." if len(unknown_m) > _FIRST_LINES else ""
            rec.warn(f"{len(unknown_m)} material(s) used by faces are not defined in any loaded "
                     f".mtl: {shown}{more}; they get the default colour")
        self.details["materials_unused"] = sorted(n for n in mtl if n not in set(used_names))
        if not materials:
            materials = [DEFAULT_MATERIAL]
        for m in materials:
            if m.texture is not None and m.texture not in self.files:
                self.files.append(m.texture)

        if len(sizes_k) == 0:
            rec.warn("no faces in file" if NF == 0 else "no faces left after dropping bad faces")
        if self.latin1.n:
            rec.warn(f"names on {self.latin1.n} line(s) of {self.path} are not UTF-8 and were decoded as "
                     f"Latin-1 (lines {self.latin1.text()})")
        return Scene(
            positions=positions,
            poly_sizes=sizes_k.astype(np.int64, copy=False),
            poly_indices=poly_indices.astype(np.int64, copy=False),
            poly_material=poly_material.astype(np.int64, copy=False),
            poly_uvs=poly_uvs,
            vertex_colors=colors,
            materials=tuple(materials),
            source=SourceInfo(path=self.files[0], files_read=tuple(self.files), format="obj",
                              files_missing=tuple(dict.fromkeys(self.missing))),
        )

    def other_lines(self) -> list[tuple[int, str]]:
        """Walk this block's lines that are not v/vt/vn/f/o/g/s: usemtl, mtllib, l/p, unknown.
        Returns the ``usemtl`` lines (index in the block, name)."""
        t = self.t
        uses: list[tuple[int, str]] = []
        kinds = t.line_kind
        lines = np.flatnonzero(kinds == _OTHER)
        if len(lines):
            data = t.clean.tobytes() if t.clean is not t.arr else t.data
            names = self.name_cache
            unknown = self.unknown
            latin1: list[int] = []
            for line, ks, ke, le, ln in zip(lines.tolist(), t.kw_start[lines].tolist(),
                                            t.kw_end[lines].tolist(), t.line_end[lines].tolist(),
                                            t.line_no[lines].tolist()):
                kw = data[ks:ke]
                if kw == b"usemtl" or kw == b"mtllib":
                    rest = data[ke:le].strip()
                    if rest not in names:
                        names[rest] = _decode(rest)
                    text, fb = names[rest]
                    if fb:
                        latin1.append(ln)
                    if kw == b"usemtl":
                        uses.append((line, text))
                    else:
                        self.mtllibs.append((ln, text))
                else:
                    k = _decode(kw)[0]
                    if k not in _IGNORED:
                        if k in unknown:
                            unknown[k][0] += 1
                        else:
                            unknown[k] = [1, ln]
            self.latin1.add(latin1)
        self.groups += int(np.count_nonzero(kinds == _GROUP))
        self.n_l += int(np.count_nonzero(kinds == _L))
        self.n_p += int(np.count_nonzero(kinds == _P))
        return uses

    # ------------------------------------------------------------------ MTL
    def materials_from(self, mtllibs: list[tuple[int, str]]) -> dict[str, Material]:
        base = Path(os.path.abspath(self.path)).parent
        mats: dict[str, Material] = {}
        seen: set[Path] = set()
        for ln, text in mtllibs:
            if not text:
                self.rec.warn(f"{self.path}:{ln}: 'mtllib' without a file name")
                continue
            whole: list[Path] = []
            found = _find_file(base, text, outside=whole)
            cands = [(text, found, whole)] if found or len(text.split()) == 1 else []
            for n in ([] if cands else text.split()):
                outside: list[Path] = []
                cands.append((n, _find_file(base, n, outside=outside), outside or whole))
            for name, p, outside in cands:
                if p is None:
                    if not outside:
                        self.missing.extend(_looked_for(base, name))
                    why = (f"outside the model's folder ({outside[0]}), not read" if outside else
                           "not found")
                    self.rec.warn(f"material library {why}: '{name}' ({self.path}:{ln}); "
                                  f"default colours used")
                    continue
                if p in seen:
                    continue
                seen.add(p)
                self.files.append(p)
                for nm, m in _parse_mtl(p, self.rec, root=base, missing=self.missing).items():
                    if nm in mats:
                        self.rec.warn(f"material '{nm}' is defined again in {p}; the first "
                                      f"definition is kept")
                    else:
                        mats[nm] = m
        return mats


def _is_file(p: Path) -> bool:
    """``Path.is_file`` that is False, not an exception, for names the OS refuses (too long...)."""
    try:
        return p.is_file()
    except (OSError, ValueError):
        return False


def _inside(path: Path, root: Path) -> bool:
    """``path`` (symbolic links followed) lies in ``root`` or below it."""
    try:
        return Path(os.path.realpath(path)).is_relative_to(os.path.realpath(root))
    except (OSError, ValueError):
        return False


def _find_file(base: Path, name: str, root: Path | None = None,
               outside: list[Path] | None = None) -> Path | None:
    """Find ``name`` (relative to ``base``, backslashes accepted): as written, then its base name
    next to ``base``, then a case-insensitive match there. Only files inside ``root`` (the OBJ's
    folder; default ``base``) count, as for glTF URIs: a path that leaves it (``..``, absolute, a
    symbolic link pointing out) is not read, and is appended to ``outside`` when it exists."""
    name = name.strip().strip('"').replace("\\", "/")
    if not name:
        return None
    root = base if root is None else root
    p = Path(name)
    cands = [p if p.is_absolute() else base / p, base / p.name]
    for c in cands:
        if _is_file(c):
            if _inside(c, root):
                return Path(os.path.normpath(c))
            if outside is not None:
                outside.append(Path(os.path.normpath(c)))
    low = p.name.lower()
    try:
        for entry in sorted(os.listdir(base)):
            if entry.lower() == low and _is_file(base / entry) and _inside(base / entry, root):
                return Path(os.path.normpath(base / entry))
    except OSError:
        pass
    return None


def _looked_for(base: Path, name: str) -> list[Path]:
    """Where :func:`_find_file` looked for ``name``: as written, and its base name next to ``base``."""
    p = Path(name.strip().strip('"').replace("\\", "/"))
    if not p.name:
        return []
    return list(dict.fromkeys([Path(os.path.normpath(p if p.is_absolute() else base / p)), base / p.name]))


def _parse_mtl(path: Path, rec: StageRecord, root: Path | None = None,
               missing: list[Path] | None = None) -> dict[str, Material]:
    """Read one MTL file: newmtl, Kd, d, Tr, map_Kd (see the module docstring). Textures must lie
    in ``root`` (the OBJ's folder; default the MTL's). A texture not found is appended to
    ``missing`` (where it was looked for)."""
    try:
        raw = path.read_bytes()
    except OSError as e:
        rec.warn(f"cannot read material library {path}: {e.strerror or e}")
        return {}
    if b"\x00" in raw:
        rec.warn(f"material library {path} is not a text file; default colours used")
        return {}
    if raw.startswith(_BOM):
        raw = raw[3:]
    base = path.parent
    out: dict[str, Material] = {}
    cur: dict | None = None
    latin1: list[int] = []
    order: list[dict] = []

    def bad(ln: int, msg: str) -> None:
        rec.warn(f"{path}:{ln}: {msg}; statement ignored")

    def nums(ln: int, toks: list[str], kw: str) -> list[float] | None:
        try:
            v = [float(x) for x in toks]
        except ValueError:
            bad(ln, f"malformed number in '{kw}'")
            return None
        if not all(np.isfinite(v)):
            bad(ln, f"non-finite value in '{kw}'")
            return None
        return v

    text_lines = raw.replace(b"\r\n", b"\n").replace(b"\r", b"\n").split(b"\n")
    for i, bline in enumerate(text_lines, 1):
        line, fb = _decode(bline)
        s = line.strip()
        if not s or s.startswith("#"):
            continue
        parts = s.split(None, 1)
        kw = parts[0].lower()
        rest = parts[1].strip() if len(parts) > 1 else ""
        if kw not in ("newmtl", "map_kd") and "#" in rest:
            rest = rest.split("#", 1)[0].strip()
        if kw == "newmtl":
            if fb:
                latin1.append(i)
            if not rest:
                bad(i, "'newmtl' without a name")
                cur = None
                continue
            cur = {"name": rest, "line": i}
            order.append(cur)
            continue
        if kw not in _MTL_KNOWN:
            continue
        if cur is None:
            if kw in ("kd", "d", "tr", "map_kd"):
                bad(i, f"'{parts[0]}' before any 'newmtl'")
            continue
        toks = rest.split()
        if kw == "kd":
            if toks and toks[0].lower() in ("spectral", "xyz"):
                bad(i, f"'Kd {toks[0]}' colours are not supported")
                continue
            v = nums(i, toks, "Kd")
            if v is None:
                continue
            if len(v) == 1:
                v = v * 3
            if len(v) != 3:
                bad(i, f"'Kd' needs 1 or 3 numbers, got {len(v)}")
                continue
            cur["kd"] = (v, i)
        elif kw in ("d", "tr"):
            toks = [x for x in toks if x.lower() != "-halo"]
            v = nums(i, toks, parts[0])
            if v is None:
                continue
            if len(v) != 1:
                bad(i, f"'{parts[0]}' needs 1 number, got {len(v)}")
                continue
            cur[kw] = (v[0], i)
        elif kw == "map_kd":
            if fb:
                latin1.append(i)
            cur["map_kd"] = (_map_file_name(rest), i)

    for m in order:
        name = m["name"]
        if name in out:
            rec.warn(f"{path}:{m['line']}: material '{name}' is defined twice; the first is kept")
            continue
        r, g, b = 0.8, 0.8, 0.8
        if "kd" in m:
            v, ln = m["kd"]
            if min(v) < 0 or max(v) > 1:
                rec.warn(f"{path}:{ln}: Kd of '{name}' outside [0, 1] was clipped")
            r, g, b = (float(np.clip(x, 0.0, 1.0)) for x in v)
        a = 1.0
        if "d" in m:
            a, ln = m["d"]
        elif "tr" in m:
            tr, ln = m["tr"]
            if tr == 1.0:
                rec.warn(f"{path}:{ln}: 'Tr 1' in '{name}' read as opaque (MeshLab and others write Tr "
                         f"as opacity; by the MTL spec it would make the material invisible)")
                a = 1.0
            else:
                a = 1.0 - tr
        if not 0.0 <= a <= 1.0:
            rec.warn(f"{path}:{ln}: alpha of '{name}' outside [0, 1] was clipped")
            a = float(np.clip(a, 0.0, 1.0))
        tex = None
        if "map_kd" in m:
            fname, ln = m["map_kd"]
            if not fname:
                rec.warn(f"{path}:{ln}: 'map_Kd' without a file name in '{name}'")
            else:
                outside: list[Path] = []
                tex = _find_file(base, fname, root=root or base, outside=outside)
                if tex is None and not outside and missing is not None:
                    missing.extend(_looked_for(base, fname))
                if tex is None:
                    why = f"outside the model's folder ({outside[0]}), not read" if outside else "not found"
                    rec.warn(f"texture {why}: '{fname}' (material '{name}', {path}:{ln}); "
                             f"material colour used")
        out[name] = Material(name=name, color=(r, g, b, float(a)), texture=tex)
    if latin1:
        rec.warn(f"names on {len(latin1)} line(s) of {path} are not UTF-8 and were decoded as "
                 f"Latin-1 (lines {_lines_list(np.array(latin1))})")
    return out


def _map_file_name(rest: str) -> str:
    """The file name of a ``map_*`` statement: options skipped, spaces inside the name kept."""
    toks = list(re.finditer(r"\S+", rest))
    i = 0
    while i < len(toks):
        opt = toks[i].group().lower()
        if not opt.startswith("-") or _is_number(opt):
            break
        nargs = _MAP_OPTIONS.get(opt, 0)
        i += 1
        if opt in _VAR_OPTIONS:
            taken = 0
            while taken < nargs and i < len(toks) - 1 and _is_number(toks[i].group()):
                i += 1
                taken += 1
        else:
            i += min(nargs, max(len(toks) - 1 - i, 0))
    if i >= len(toks):
        return ""
    name = rest[toks[i].start():].strip()
    if len(name) >= 2 and name[0] == name[-1] == '"':
        name = name[1:-1]
    return name


def _is_number(s: str) -> bool:
    try:
        float(s)
        return True
    except ValueError:
        return False
