"""The OBJ parser: each block's lines (:mod:`bake.importers.obj_lines`) to compact arrays, and
the bookkeeping of errors and warnings across blocks.

``v``/``vt`` numbers are converted in one call per directive kind; face corners (``v``,
``v/vt``, ``v//vn``, ``v/vt/vn``, mixed freely, negative = relative) are validated byte-wise,
then converted in one call, with a sentinel for empty fields. Relative indices are resolved
with the number of ``v``/``vt`` lines above each face line (the count before the block plus a
searchsorted on line numbers), and materials by searchsorted over the ``usemtl`` lines. Only
"other" lines (``usemtl``, ``mtllib``, unknown directives) are visited one by one. Line
numbers, relative indices, ``usemtl``, errors and warnings are carried across blocks and come
out exactly as for one block; :mod:`bake.importers.obj` builds the scene from what the parser
collected. The rules are listed there.
"""

from __future__ import annotations

import os
import re
import warnings
from pathlib import Path

import numpy as np

from ..errors import InputError
from ..record import StageRecord
from ..scene import MAX_COORDINATE
from .obj_lines import (_F, _GROUP, _L, _OTHER, _P, _V, _VN, _VT, _FIRST_LINES, _Tokens, _decode,
                        _excl_cumsum, _gather, _lines_list)

# byte classes of face corner tokens
_C_BAD, _C_DIGIT, _C_SLASH, _C_SIGN, _C_SPACE = range(5)
_CORNER_LUT = np.full(256, _C_BAD, np.uint8)
_CORNER_LUT[48:58] = _C_DIGIT
_CORNER_LUT[47] = _C_SLASH
_CORNER_LUT[[43, 45]] = _C_SIGN
_CORNER_LUT[32] = _C_SPACE
_ABSENT = 10 ** 18  # stands for an empty field ("1//3"); real fields have at most 18 characters
_ABSENT_B = str(_ABSENT).encode()
_MSVC_SPECIAL = re.compile(rb"[+-]?\d*\.?\d*#(IND|INF|QNAN|SNAN)\d*", re.IGNORECASE)

# directives that are fine to ignore silently
_IGNORED = {"mg", "maplib", "usemap", "lod", "shadow_obj", "trace_obj", "bevel", "c_interp",
            "d_interp", "ctech", "stech"}


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


# --------------------------------------------------------------------------- parser
# Errors, in the order the checks run over the whole file: the first kind found anywhere wins,
# and within a kind the first line (or, for NaN / range, all lines counted).
(_E_V_NUMBER, _E_V_FEW, _E_V_NONFINITE, _E_V_HUGE, _E_VT_NUMBER, _E_VT_EMPTY, _E_VT_NONFINITE,
 _E_VN_NUMBER, _E_VN_FEW, _E_VN_NONFINITE, _E_CORNER, _E_CORNER_PARSE) = range(1, 13)
_NO_ERROR = 100


class _Parser:
    """Feed it the blocks in order (:meth:`feed`); then :func:`bake.importers.obj.load` raises the
    first error (:meth:`raise_first_error`) and builds the scene from what was collected.

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

    # ------------------------------------------------------------------ other lines
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

    # ------------------------------------------------------------------ at the end
    def raise_first_error(self) -> None:
        """The error that comes first in the whole file, if any (:class:`InputError`)."""
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

    def face_line(self, face: int) -> int:
        """The line of face ``face`` (numbered over the whole file). Asked only of bad faces: their
        blocks kept their face lines (a bad face, or an index that may lie past the file's end)."""
        b = int(np.searchsorted(self.fstart, face, side="right")) - 1
        return int(self.fline[b][face - self.fstart[b]])

    def why_bad(self, face: int, size: int, c0: int, vres: np.ndarray, tres: np.ndarray | None,
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
