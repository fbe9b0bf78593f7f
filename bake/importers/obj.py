"""Wavefront OBJ (+ MTL) importer: our own vectorised parser; n-gons are kept as polygons.

The whole file is read as bytes and tokenised once with numpy (no Python loop per vertex or
face line): byte classes -> token spans -> the line of each token -> the keyword of each line.
``v``/``vt`` numbers are converted in one call per directive kind; face corners (``v``,
``v/vt``, ``v//vn``, ``v/vt/vn``, mixed freely, negative = relative) are validated byte-wise,
then converted in one call, with a sentinel for empty fields. Relative indices are resolved
with the number of ``v``/``vt`` lines above each face line (searchsorted on line numbers), and
materials by searchsorted over the ``usemtl`` lines. Only "other" lines (``usemtl``, ``mtllib``,
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
  ``vn`` lines are counted, not parsed (normals are recomputed downstream).
* Positions, colours and texture coordinates must be finite: NaN/Inf (including MSVC's
  ``1.#IND``/``1.#INF``) is an :class:`InputError` naming the first few lines, as is a position
  beyond ``scene.MAX_COORDINATE`` (1e30). A malformed
  number on a ``v``/``vt``/``f`` line is an :class:`InputError` naming file and line.
* Faces: index 0, an index out of range (positive indices may refer to vertices defined later
  in the file; negative ones count back from the line) or fewer than 3 corners make a bad face:
  :class:`InputError` when ``job.strict``, else the face is dropped with one warning giving the
  count and the first lines. ``vn`` indices are checked for syntax only (normals are unused).
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
def load(job: ImportJob) -> tuple[Scene, StageRecord]:
    """Read ``job.path`` (OBJ + its MTL files) into a scene with polygons (n-gons kept)."""
    t0 = time.perf_counter()
    path = Path(job.path)
    rec = StageRecord(name="import")
    try:
        raw = path.read_bytes()
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror or e}", path=path) from None
    _check_text(raw, path)
    p = _Parser(raw, path, bool(job.strict), rec)
    scene = p.run()
    sizes = scene.poly_sizes
    uniq, cnt = np.unique(sizes, return_counts=True) if len(sizes) else (np.zeros(0, int), [])
    rec.details.update({
        "format": "obj",
        "polygon_sizes": {str(int(s)): int(c) for s, c in zip(uniq, cnt)},
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


def _check_text(raw: bytes, path: Path) -> None:
    if raw[:2] in (b"\xff\xfe", b"\xfe\xff"):
        raise InputError("UTF-16 text is not supported; save the OBJ as UTF-8 or ASCII", path=path)
    nul = raw.find(b"\x00")
    if nul >= 0:
        raise InputError(f"not a text file (NUL byte at offset {nul}); expected Wavefront OBJ text",
                         path=path)
    head = np.frombuffer(raw[:65536], np.uint8)
    if len(head):
        ctrl = ((head < 32) & ~np.isin(head, (9, 10, 11, 12, 13, 26))) | (head == 127)
        n = int(ctrl.sum())
        if n >= 8 and n > 0.01 * len(head):
            raise InputError(f"not a text file ({n} control bytes in the first {len(head)}); "
                             f"expected Wavefront OBJ text", path=path)


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


# --------------------------------------------------------------------------- tokeniser
class _Tokens:
    """Token spans of a whole file and the logical line each belongs to (numpy arrays)."""

    def __init__(self, raw: bytes):
        if raw.startswith(_BOM):
            raw = raw[3:]
        nlb = 10 if (b"\n" in raw or b"\r" not in raw) else 13  # bare-CR files
        data = raw + bytes([nlb]) + b" "  # last line terminated; a spare byte for look-ahead
        self.data = data
        arr = np.frombuffer(data, np.uint8)
        self.arr = arr
        ws = arr <= 32  # whitespace: space, tab, CR, VT, FF (and other control bytes)
        nlmask = arr == nlb
        phys_nl = np.flatnonzero(nlmask)
        self.clean = arr  # the bytes with continuation backslashes made spaces
        if b"\\" in raw:  # line continuation: backslash + end of line is whitespace
            bs = np.flatnonzero(arr[:-2] == 92)
            c1 = bs[arr[bs + 1] == nlb]
            c2 = bs[(arr[bs + 1] == 13) & (arr[bs + 2] == 10)] if nlb == 10 else bs[:0]
            # a backslash at the very end of the file continues nothing: the newline after it is
            # the one appended above, which must stay (else the last line has no terminator)
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
        ends = np.flatnonzero(en)
        # token starts and logical newlines in one sorted array: a token's line is the number
        # of newlines before it
        ev = np.flatnonzero(st | nlmask)
        ev_nl = nlmask[ev]
        nl = ev[ev_nl]
        line_of_ev = np.cumsum(ev_nl)
        tok_ev = ~ev_nl
        starts = ev[tok_ev]
        tline = line_of_ev[tok_ev]
        self.n_lines = len(nl)
        if len(nl) == len(phys_nl):
            self.line_no = np.arange(1, len(nl) + 1, dtype=np.int64)
        else:
            line_start = np.concatenate([[0], nl[:-1] + 1])
            self.line_no = np.searchsorted(phys_nl, line_start) + 1  # 1-based physical line
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
    return arr[_ranges(starts, ends + 1)].tobytes().translate(_WS_TO_SPACE)


# --------------------------------------------------------------------------- parser
class _Parser:
    def __init__(self, raw: bytes, path: Path, strict: bool, rec: StageRecord):
        self.path = path
        self.strict = strict
        self.rec = rec
        self.t = _Tokens(raw)
        self.details: dict = {}
        self.files: list[Path] = [Path(os.path.abspath(path))]
        self.latin1_lines: list[int] = []

    def err(self, msg: str, line: int | None = None, path: Path | None = None) -> InputError:
        return InputError(msg, path=path or self.path, line=line)

    # ------------------------------------------------------------------ numbers
    def _floats(self, kind: int, what: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """All numbers on lines of ``kind``: (values, values per line, line indices)."""
        t = self.t
        s, e, tl = t.data_tokens(kind)
        lines = t.lines_of(kind)
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
                        line = int(t.line_no[tl[i]])
                        raise self.err(f"malformed number '{_decode(tok)[0]}' in a '{what}' line "
                                       f"(expected a decimal number)", line) from None
        return vals, counts, lines

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

    def _nonfinite(self, bad_rows: np.ndarray, lines: np.ndarray, what: str) -> None:
        if bad_rows.any():
            ln = self.t.line_no[lines[bad_rows]]
            raise self.err(f"{what} are NaN or infinite on {int(bad_rows.sum())} line(s): "
                           f"{_lines_list(ln)}", int(ln[0]))

    def vertices(self) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
        vals, counts, lines = self._floats(_V, "v")
        ln = self.t.line_no
        few = counts < 3
        if few.any():
            i = int(np.argmax(few))
            raise self.err(f"vertex needs x y z, got {int(counts[i])} value(s)", int(ln[lines[i]]))
        odd = (counts == 5) | (counts > 7)
        if odd.any():
            self.rec.warn(f"{int(odd.sum())} 'v' line(s) have {int(counts[odd][0])} values (expected "
                          f"3, 4, 6 or 7); extra values ignored (lines {_lines_list(ln[lines[odd]])})")
        rows = self._rows(vals, counts, 7)
        has_col = (counts == 6) | (counts == 7)
        has_a = counts == 7
        used = np.zeros_like(rows, dtype=bool)
        used[:, :3] = True
        used[has_col, 3:6] = True
        used[has_a, 6] = True
        self._nonfinite((~np.isfinite(rows) & used).any(axis=1), lines, "vertex values")
        huge = (np.abs(rows[:, :3]) > MAX_COORDINATE).any(axis=1)
        if huge.any():
            ln = self.t.line_no[lines[huge]]
            raise self.err(f"vertex coordinates beyond +-{MAX_COORDINATE:g} (the range bake supports) on "
                           f"{int(huge.sum())} line(s): {_lines_list(ln)}", int(ln[0]))
        pos = np.ascontiguousarray(rows[:, :3], dtype=np.float64)
        colors = None
        if has_col.any():
            col = np.ones((len(rows), 4))
            col[has_col, :3] = rows[has_col, 3:6]
            col[has_a, 3] = rows[has_a, 6]
            given = np.concatenate([rows[has_col, 3:6].ravel(), rows[has_a, 6]])
            self.details["vertex_color_scale"] = "0-1"
            if given.max() > 1.0 and (given == np.round(given)).all() and given.min() >= 0:
                col[has_col, :3] /= 255.0
                col[has_a, 3] /= 255.0
                self.details["vertex_color_scale"] = "0-255"
            elif given.max() > 1.0 or given.min() < 0.0:
                self.rec.warn(f"vertex colours outside [0, 1] (from {given.min():g} to "
                              f"{given.max():g}) were clipped")
            np.clip(col, 0.0, 1.0, out=col)
            if not has_col.all():
                self.rec.warn(f"{int((~has_col).sum())} of {len(rows)} vertices have no colour; "
                              f"they get white")
            colors = col
        self.details["vertex_colors"] = colors is not None
        return pos, colors, lines

    def texcoords(self) -> tuple[np.ndarray, np.ndarray]:
        vals, counts, lines = self._floats(_VT, "vt")
        ln = self.t.line_no
        if (counts < 1).any():
            i = int(np.argmax(counts < 1))
            raise self.err("texture coordinate needs u [v [w]], got no values", int(ln[lines[i]]))
        if (counts > 3).any():
            self.rec.warn(f"{int((counts > 3).sum())} 'vt' line(s) have more than 3 values; extra "
                          f"values ignored (lines {_lines_list(ln[lines[counts > 3]])})")
        rows = self._rows(vals, counts, 2)
        used = np.ones_like(rows, dtype=bool)
        used[counts < 2, 1] = False
        self._nonfinite((~np.isfinite(rows) & used).any(axis=1), lines, "texture coordinates")
        return np.ascontiguousarray(rows, dtype=np.float64), lines

    # ------------------------------------------------------------------ faces
    def corners(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Face lines, corners per face, corner index fields (C, 3) int64 and presence (C, 3).

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
        if bad.any():
            i = int(np.argmax(bad))
            raise self.err(f"malformed face corner '{t.token(int(s[i]), int(e[i]))}' (expected v, "
                           f"v/vt, v//vn or v/vt/vn with integer indices)", int(t.line_no[tl[i]]))
        if len(sl):
            buf = buf.replace(b"//", b"/" + _ABSENT_B + b"/").replace(b"/ ", b"/" + _ABSENT_B + b" ")
            buf = buf.replace(b"/", b" ")
        vals = np.fromstring(buf, dtype=np.int64, sep=" ")
        if len(vals) != C + int(nsl.sum()):  # cannot happen after validation; never guess
            raise self.err("could not parse face indices", int(t.line_no[tl[0]]))
        off = np.arange(C, dtype=np.int64) + _excl_cumsum(nsl)
        for k in range(3):
            m = nsl >= k
            v = vals[off[m] + k]
            idx[m, k] = np.where(v == _ABSENT, 0, v)
            has[m, k] = v != _ABSENT
        return flines, sizes, idx, has

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

    # ------------------------------------------------------------------ main
    def run(self) -> Scene:
        t = self.t
        rec = self.rec
        positions, colors, vlines = self.vertices()
        uvs, vtlines = self.texcoords()
        flines, sizes, idx, has = self.corners()
        NV, NT, NF = len(positions), len(uvs), len(flines)
        self.details.update({"texcoords": NT, "normals": int((t.line_kind == _VN).sum())})
        other = self.other_lines()

        # ---- resolve indices
        face_of = np.repeat(np.arange(NF, dtype=np.int64), sizes)
        vbefore = np.searchsorted(vlines, flines)[face_of]
        tbefore = np.searchsorted(vtlines, flines)[face_of]
        vres, vzero, voor = self.resolve(idx[:, 0], has[:, 0], vbefore, NV)
        badc = vzero | voor
        if has[:, 1].any():
            tres, tzero, toor = self.resolve(idx[:, 1], has[:, 1], tbefore, NT)
            badc |= tzero | toor
        else:
            tres = np.zeros(len(idx), np.int64)
            tzero = toor = np.zeros(len(idx), bool)
        badf = (sizes < 3) | (np.bincount(face_of[badc], minlength=NF) > 0)
        dropped = int(badf.sum())
        if dropped:
            order = np.flatnonzero(badf)
            f0 = int(order[0])
            c0 = int(_excl_cumsum(sizes)[f0])
            if sizes[f0] < 3:
                why = f"face has fewer than 3 vertices ({int(sizes[f0])} given)"
            else:
                why = (self.face_problem(c0, int(sizes[f0]), idx[:, 0], vzero, voor, vbefore,
                                         NV, "index", "vertices")
                       or self.face_problem(c0, int(sizes[f0]), idx[:, 1], tzero, toor, tbefore,
                                            NT, "texture index", "texture coordinates"))
            line = int(t.line_no[flines[f0]])
            if self.strict:
                raise self.err(why, line)
            rec.warn(f"dropped {dropped} bad face(s) (index 0, index out of range or fewer than 3 "
                     f"vertices) at lines {_lines_list(t.line_no[flines[order]])}; first, line "
                     f"{line}: {why}")
        keepc = ~badf[face_of] if dropped else slice(None)
        sizes_k = sizes[~badf] if dropped else sizes
        poly_indices = vres[keepc]
        has_t = has[keepc, 1]
        poly_uvs = None
        self.details["uv_corners"] = int(has_t.sum())
        if has_t.any():
            poly_uvs = np.where(has_t[:, None], uvs[tres[keepc]], 0.0)
            if not has_t.all():
                rec.warn(f"{int((~has_t).sum())} of {len(has_t)} face corners have no texture "
                         f"coordinate (vt); they get UV (0, 0)")
        self.details["dropped_faces"] = dropped

        # ---- materials
        mtl = self.materials_from(other["mtllib"])
        use_lines = np.array([ln for ln, _ in other["usemtl"]], dtype=np.int64)
        names: list[str] = []
        name_id: dict[str, int] = {}
        occ = []
        for _, nm in other["usemtl"]:
            nm = nm or "default"
            if nm not in name_id:
                name_id[nm] = len(names)
                names.append(nm)
            occ.append(name_id[nm])
        occ_arr = np.array(occ, dtype=np.int64)
        if "default" not in name_id:
            name_id["default"] = len(names)
            names.append("default")
        o = np.searchsorted(use_lines, flines[~badf], side="right") - 1
        face_name = np.where(o >= 0, occ_arr[np.maximum(o, 0)] if len(occ_arr) else 0,
                             name_id["default"])
        if len(face_name):
            u, first = np.unique(face_name, return_index=True)
            used = u[np.argsort(first, kind="stable")]
            lut = np.zeros(len(names), np.int64)
            lut[used] = np.arange(len(used))
            poly_material = lut[face_name]
            used_names = [names[i] for i in used]
        else:
            poly_material = np.zeros(0, np.int64)
            used_names = []
        materials, unknown = [], []
        for nm in used_names:
            if nm in mtl:
                materials.append(mtl[nm])
            elif nm == "default":
                materials.append(DEFAULT_MATERIAL)
            else:
                unknown.append(nm)
                materials.append(Material(name=nm))
        if unknown:
            shown = ", ".join(repr(n) for n in unknown[:_FIRST_LINES])
            more = ", ..." if len(unknown) > _FIRST_LINES else ""
            rec.warn(f"{len(unknown)} material(s) used by faces are not defined in any loaded .mtl: "
                     f"{shown}{more}; they get the default colour")
        self.details["materials_unused"] = sorted(n for n in mtl if n not in set(used_names))
        if not materials:
            materials = [DEFAULT_MATERIAL]
        for m in materials:
            if m.texture is not None and m.texture not in self.files:
                self.files.append(m.texture)

        if len(sizes_k) == 0:
            rec.warn("no faces in file" if NF == 0 else "no faces left after dropping bad faces")
        if self.latin1_lines:
            rec.warn(f"names on {len(self.latin1_lines)} line(s) are not UTF-8 and were decoded as "
                     f"Latin-1 (lines {_lines_list(np.array(self.latin1_lines))})")
        return Scene(
            positions=positions,
            poly_sizes=sizes_k.astype(np.int64),
            poly_indices=poly_indices.astype(np.int64),
            poly_material=poly_material.astype(np.int64),
            poly_uvs=poly_uvs,
            vertex_colors=colors,
            materials=tuple(materials),
            source=SourceInfo(path=self.files[0], files_read=tuple(self.files), format="obj"),
        )

    def other_lines(self) -> dict:
        """Walk the lines that are not v/vt/vn/f/o/g/s: usemtl, mtllib, l/p, unknown."""
        t = self.t
        out: dict = {"usemtl": [], "mtllib": []}
        unknown: dict[str, list[int]] = {}
        kinds = t.line_kind
        lines = np.flatnonzero(kinds == _OTHER)
        data = t.clean.tobytes() if t.clean is not t.arr else t.data
        names: dict[bytes, tuple[str, bool]] = {}  # decoded once per distinct name
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
                    self.latin1_lines.append(ln)
                if kw == b"usemtl":
                    out["usemtl"].append((line, text))
                else:
                    out["mtllib"].append((ln, text))
            else:
                k = _decode(kw)[0]
                if k not in _IGNORED:
                    unknown.setdefault(k, []).append(ln)
        groups = int((kinds == _GROUP).sum())
        self.details["groups_objects_smoothing_lines"] = groups
        n_l, n_p = int((kinds == _L).sum()), int((kinds == _P).sum())
        if n_l or n_p:
            self.rec.warn(f"skipped {n_l} line element(s) ('l') and {n_p} point element(s) ('p'); "
                          f"only faces are imported")
        self.details["skipped_elements"] = {"l": n_l, "p": n_p}
        if unknown:
            parts = [f"'{k}' x{len(v)} (first at line {v[0]})" for k, v in sorted(unknown.items())]
            self.rec.warn(f"ignored {sum(len(v) for v in unknown.values())} line(s) with unsupported "
                          f"or unknown directives: {', '.join(parts)}")
        self.details["unknown_directives"] = {k: len(v) for k, v in sorted(unknown.items())}
        return out

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
                    why = (f"outside the model's folder ({outside[0]}), not read" if outside else
                           "not found")
                    self.rec.warn(f"material library {why}: '{name}' ({self.path}:{ln}); "
                                  f"default colours used")
                    continue
                if p in seen:
                    continue
                seen.add(p)
                self.files.append(p)
                for nm, m in _parse_mtl(p, self.rec, root=base).items():
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


def _parse_mtl(path: Path, rec: StageRecord, root: Path | None = None) -> dict[str, Material]:
    """Read one MTL file: newmtl, Kd, d, Tr, map_Kd (see the module docstring). Textures must lie
    in ``root`` (the OBJ's folder; default the MTL's)."""
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
