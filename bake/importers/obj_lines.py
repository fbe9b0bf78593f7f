"""The OBJ file as blocks of whole lines, and each block's tokens (numpy, no Python loop per line).

The file is read in blocks of whole lines (:class:`_Reader`; a line continued with a backslash
stays in one block) and each block is tokenised with numpy (:class:`_Tokens`): byte classes ->
token spans -> the line of each token -> the keyword of each line. The rules these follow (line
endings, continuation, comments, what is not text) are listed in :mod:`bake.importers.obj`; the
parser of the lines is :mod:`bake.importers.obj_parse`.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from ..errors import InputError

# line kinds
_EMPTY, _OTHER, _V, _VT, _VN, _F, _L, _P, _GROUP = range(9)

_BOM = b"\xef\xbb\xbf"
_WS_TO_SPACE = bytes.maketrans(bytes(range(33)), b" " * 33)
_FIRST_LINES = 5  # how many line numbers a message lists
_HEAD_BYTES = 65536  # the start of the file checked for control bytes
_SCAN_BYTES = 4 * 1024 * 1024  # chunks when only looking through the file (NUL, newline kind)


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
