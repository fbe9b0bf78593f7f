"""Packed lists: numeric Scratch lists as short strings that the project decodes at the green flag.

A list in project.json is a JSON array of decimal numbers: about 3.3 bits per byte. A packed list
is one string of printable ASCII, about 6.5 bits per byte, and the values inside it are coded by
what they are (deltas, palette indices, first-use vertex indices, constants), so a list takes a
fraction of its bytes. The loader blocks (``bake/scratch/loader.py``) rebuild exactly the plain
list, item for item; :func:`unpack` here is their Python mirror, step for step, and counts the
blocks the real VM executes (tests/scratch/test_pack_vm.py proves both in scratch-vm).

Format (version 1; docs/formats.md "Packed lists")
-------------------------------------------------

Symbols are the 92 characters ``!`` .. ``~`` without ``"`` and ``\\`` (they cost two bytes in
JSON); a symbol's value is its place in :data:`ALPHABET` (0..91). Numbers are *varints* with a
parameter ``T`` (1..91): symbols below ``T`` end a number, symbols ``T`` and up are continuation
digits (base ``C = 92 - T``, bijective), so ``n`` is one symbol when ``n < T``, two when
``n < T*(C + 1)`` and so on. Reading: ``a = 0; s = next; while s >= T: a = a*C + s - T + 1;
s = next; n = a*T + s``.

A packed list is the text ``sbpk1`` followed by varints with ``T = 46``: the CRC-32 of the list
name (UTF-8) and everything after the CRC; the name's length in UTF-16 units and the name itself;
the number of sections; per section its rows and stride (columns) and its column groups, each a
header (mode, width, T, decimals d, zigzag(q0), palette size P, P zigzag palette entries) followed
by its codes row by row (the group's varint parameter T); last, the sum of all codes. A list is
one section, or two when it starts with a prefix of another shape (a BVH's root box).

Column modes (every value is an integer ``q``; the item is ``q / 10^d``, exact in double
precision because both are whole numbers below 2^53, so it is the same number the plain list's
decimal text reads as):

=======  =========  =============================================================================
mode     name       item from the code n
=======  =========  =============================================================================
0        const      q0 (no codes)
1        offset     q0 + n
2        delta      the previous value + q0 + unzigzag(n)
3        index      n = 0: m + 1 (m, the highest index so far, is shared by the list's index
                    columns and becomes m + 1); else m + 1 - n. Width > 1: adjacent columns.
4        palette    palette[n + 1]
=======  =========  =============================================================================

``zigzag(q) = 2q`` for ``q >= 0``, ``-2q - 1`` below. With vertices numbered in the order the
triangles first use them, a new vertex costs one symbol and a recent one a few. The loader checks
the sum and that the text ended exactly there; :func:`unpack` also checks the CRC, so an edited or
truncated string is an error naming the list. docs/formats.md "Packed lists" is the reference.
"""

from __future__ import annotations

import functools
import json
import zlib
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

ALPHABET = "".join(chr(c) for c in range(33, 127) if chr(c) not in '"\\')
BASE = len(ALPHABET)  # 92
MAGIC = "sbpk1"
HEADER_T = 46
CONST, OFFSET, DELTA, INDEX, PALETTE = range(5)
MODE_NAMES = ("const", "offset", "delta", "index", "palette")
MAX_DECIMALS = 15
MAX_Q = 2 ** 53  # integers above this are not exact doubles
_SYM = {ch: i for i, ch in enumerate(ALPHABET)}
_SYM_ARRAY = np.full(128, -1, np.int64)
for _i, _ch in enumerate(ALPHABET):
    _SYM_ARRAY[ord(_ch)] = _i


class PackError(ValueError):
    """A packed list that cannot be decoded (truncated, edited, not ours); names the list."""

    def __init__(self, name: str, message: str):
        super().__init__(f"packed list '{name}': {message}")
        self.list_name = name


def costume_symbols() -> list[int]:
    """Symbol value of each of the reader's 94 alphabet costumes ``!`` .. ``~`` (costume k is
    ``chr(32 + k)``); ``"`` and ``\\`` are not symbols and read as 0 (the sum check catches them)."""
    return [_SYM.get(chr(32 + k), 0) for k in range(1, 95)]


# --------------------------------------------------------------------------- varints
def zigzag(q: np.ndarray) -> np.ndarray:
    q = np.asarray(q, np.int64)
    return np.where(q >= 0, 2 * q, -2 * q - 1)


def unzigzag(n: int) -> int:
    return n // 2 if n % 2 == 0 else -(n + 1) // 2


@functools.lru_cache(maxsize=None)
def _limits(C: int) -> np.ndarray:
    """acc needs k continuation digits when acc <= C + C^2 + ... + C^k (bijective base C)."""
    out, total, power = [], 0, 1
    while total < (1 << 62):
        power *= C
        total += power
        out.append(min(total, (1 << 63) - 1))
    return np.array(out, np.int64)


def varint_lengths(n: np.ndarray, T: int) -> np.ndarray:
    """Symbols each value of ``n`` (>= 0) takes as a varint with parameter ``T``."""
    n = np.asarray(n, np.int64)
    C = BASE - T
    acc = n // T
    if C == 1:
        return 1 + acc
    k = np.searchsorted(_limits(C), acc, side="left").astype(np.int64) + 1
    return 1 + np.where(acc > 0, k, 0)


def best_t(n: np.ndarray) -> tuple[int, int]:
    """The varint parameter that codes ``n`` in the fewest symbols: (T, symbols). A value takes
    one symbol, plus one for each threshold ``T * (1 + C + ... + C^(j-1))`` it reaches."""
    n = np.sort(np.asarray(n, np.int64).ravel())
    if n.size == 0:
        return HEADER_T, 0
    top = int(n[-1])
    best = None
    for T in range(1, BASE):
        C = BASE - T
        if C == 1 and top // T > 1000:
            continue
        size, span, power = n.size, 1, 1
        while T * span <= top:
            size += n.size - int(np.searchsorted(n, T * span, side="left"))
            power *= C
            span += power
        if best is None or size < best[1]:
            best = (T, size)
    return best


def encode_varints(n: np.ndarray, T: int) -> list[np.ndarray]:
    """The symbols of each value (a list of int arrays would be slow: returns a (N, k) array
    padded with -1 and the lengths), as ``[table, lengths]``."""
    n = np.asarray(n, np.int64)
    C = BASE - T
    acc, term = np.divmod(n, T)
    digits = []
    a = acc.copy()
    while (a > 0).any():
        live = a > 0
        a1 = np.where(live, a - 1, 0)
        d = np.where(live, a1 % C, -1)
        a = np.where(live, a1 // C, 0)
        digits.append(d)
    k = len(digits)
    table = np.full((len(n), k + 1), -1, np.int64)
    for j, d in enumerate(digits):  # digits come least significant first: write them backwards
        table[:, k - 1 - j] = np.where(d >= 0, d + T, -1)
    table[:, k] = term
    return [table, (table >= 0).sum(axis=1)]


def varint_text(values: Sequence[int], T: int = HEADER_T) -> str:
    if not len(values):
        return ""
    table, _ = encode_varints(np.array([int(v) for v in values], np.int64), T)
    flat = table.ravel()
    return "".join(ALPHABET[s] for s in flat[flat >= 0].tolist())


# --------------------------------------------------------------------------- columns
@dataclass
class Column:
    """A group of ``width`` adjacent columns coded one way (width > 1 only for index mode)."""

    mode: int
    decimals: int = 0
    T: int = HEADER_T
    q0: int = 0  # const value or offset
    palette: list[int] = field(default_factory=list)
    codes: np.ndarray | None = None  # data codes, row-major within the group (None for const)
    symbols: int = 0  # data symbols
    width: int = 1

    def header(self) -> list[int]:
        """The group's header fields (varints with T = 46): mode, width, T, decimals,
        zigzag(q0), palette size, the palette (zigzag)."""
        pal = [int(z) for z in zigzag(np.array(self.palette, np.int64))] if self.palette else []
        return [self.mode, self.width, self.T if self.mode != CONST else 1, self.decimals,
                int(zigzag(np.array([self.q0]))[0]), len(pal), *pal]

    def header_symbols(self) -> int:
        return int(varint_lengths(np.array(self.header(), np.int64), HEADER_T).sum())

    def cost(self) -> int:
        return self.symbols + self.header_symbols()


def decimals_of(values: np.ndarray) -> tuple[int, np.ndarray] | None:
    """The fewest decimals ``d`` with every value exactly ``q / 10^d`` for integers ``q`` below
    2^53 (the same double a JSON reader makes of the plain list's text), and those ``q``."""
    v = np.asarray(values, np.float64)
    if v.size == 0:
        return 0, np.zeros(0, np.int64)
    if not np.isfinite(v).all():
        return None
    for d in range(MAX_DECIMALS + 1):
        f = float(10 ** d)
        with np.errstate(over="ignore", invalid="ignore"):
            q = np.rint(v * f)
        if not (np.abs(q) < MAX_Q).all():
            return None
        if np.array_equal(q / f, v):
            return d, q.astype(np.int64)
    return None


def _t_and_size(codes: np.ndarray, fixed_t: int | None) -> tuple[int, int]:
    if fixed_t is None:
        return best_t(codes)
    return fixed_t, int(varint_lengths(codes, fixed_t).sum())


def column_choices(q: np.ndarray, decimals: int, allow: frozenset = frozenset(range(5)),
                   fixed_t: int | None = None) -> list[Column]:
    """Every way to code one column (const when all values agree; else offset, delta, palette).
    ``allow`` / ``fixed_t`` restrict the choice (the benchmark measures each idea alone)."""
    out: list[Column] = []
    if (q.size == 0 or (q == q[0]).all()) and CONST in allow:
        return [Column(CONST, decimals, q0=int(q[0]) if q.size else 0, codes=None, symbols=0)]
    lo = int(q.min()) if q.size else 0
    codes = q - lo
    T, size = _t_and_size(codes, fixed_t)
    out.append(Column(OFFSET, decimals, T, q0=lo, codes=codes, symbols=size))
    if DELTA in allow:
        codes = zigzag(np.diff(q, prepend=0))
        T, size = _t_and_size(codes, fixed_t)
        out.append(Column(DELTA, decimals, T, codes=codes, symbols=size))
    if PALETTE in allow and q.size:
        vals, inv, counts = np.unique(q, return_inverse=True, return_counts=True)
        if len(vals) <= max(1, q.size // 2):
            order = np.lexsort((vals, -counts))  # most frequent first (ties: smaller value)
            rank = np.empty(len(vals), np.int64)
            rank[order] = np.arange(len(vals))
            codes = rank[inv.ravel()]
            T, size = _t_and_size(codes, fixed_t)
            out.append(Column(PALETTE, decimals, T, palette=[int(x) for x in vals[order]], codes=codes,
                              symbols=size))
    return out


def index_codes(v: np.ndarray) -> np.ndarray | None:
    """Codes of 1-based indices in first-use order (None if an index skips ahead)."""
    v = np.asarray(v, np.int64)
    if v.size == 0:
        return v
    prev = np.concatenate([[0], np.maximum.accumulate(v)[:-1]])
    if (v > prev + 1).any() or (v < 1).any():
        return None
    return np.where(v == prev + 1, 0, prev - v + 1)


# --------------------------------------------------------------------------- packing
@dataclass
class Packed:
    """One packed list."""

    name: str
    text: str
    rows: int
    stride: int
    columns: list[Column]  # the column groups, left to right
    items: int

    @property
    def chars(self) -> int:
        return len(self.text)

    def describe(self) -> list[dict[str, Any]]:
        return [{"mode": MODE_NAMES[c.mode], "columns": c.width, "T": c.T if c.mode != CONST else None,
                 "decimals": c.decimals, "symbols": c.symbols,
                 **({"palette": len(c.palette)} if c.mode == PALETTE else {})} for c in self.columns]


def _utf16_len(s: str) -> int:
    return len(s.encode("utf-16-le")) // 2


def _groups(grid: np.ndarray, qs: list, index_columns: Sequence[int], modes: dict[int, int] | None,
            allow: frozenset, fixed_t: int | None) -> list[Column]:
    """The cheapest column groups for one section (rows x columns of q at their decimals)."""
    R, S = grid.shape
    singles: list[Column] = []
    for c in range(S):
        d, q = qs[c]
        choices = column_choices(q, d, allow, fixed_t)
        if modes and c in modes:
            choices = [ch for ch in choices if ch.mode == modes[c]] or choices
        singles.append(min(choices, key=lambda ch: (ch.cost(), ch.mode)))
    groups: list[tuple[int, Column]] = [(c, singles[c]) for c in range(S)]  # (first column, group)
    idx = sorted(set(c for c in index_columns if 0 <= c < S))
    if idx and R and idx == list(range(idx[0], idx[-1] + 1)) and all(qs[c][0] == 0 for c in idx) \
            and not (modes and any(c in modes for c in idx)) and INDEX in allow:
        flat = np.stack([qs[c][1] for c in idx], axis=1).ravel()
        codes = index_codes(flat)
        if codes is not None:
            T, size = _t_and_size(codes, fixed_t)
            col = Column(INDEX, 0, T, codes=codes, symbols=size, width=len(idx))
            if col.cost() < sum(singles[c].cost() for c in idx):
                groups = [(c, g) for c, g in groups if c < idx[0]] + [(idx[0], col)] + \
                         [(c, g) for c, g in groups if c > idx[-1]]
    return [g for _, g in groups]


def pack(name: str, values: Sequence[Any], stride: int = 1, *, prefix: int = 0,
         index_columns: Sequence[int] = (), modes: dict[int, int] | None = None,
         allow: Sequence[int] = tuple(range(5)), fixed_t: int | None = None) -> Packed | None:
    """Pack a numeric list (the items as a JSON reader reads the plain list: ints and floats).

    The list is ``prefix`` items (a section of one column, e.g. a BVH's root box) and then rows of
    ``stride`` items (one section). ``index_columns``: adjacent columns holding 1-based indices
    in first-use order (coded as one index group when that is shorter). ``modes``: force a mode
    per column; ``allow``: the column modes that may be used (offset always can); ``fixed_t``: one
    varint parameter for every group instead of the best per group (both for the benchmark's
    ablations). Returns None when the list cannot be packed exactly (strings, non-decimal floats,
    ints past 2^53)."""
    items = list(values)
    if any(isinstance(x, (str, bool)) or x is None for x in items):
        return None
    n = len(items)
    if any(isinstance(x, int) and abs(x) >= MAX_Q for x in items):
        return None
    arr = np.asarray(items, np.float64) if n else np.zeros(0)
    if n and not np.isfinite(arr).all():
        return None
    prefix = prefix if 0 < prefix < n else 0
    rest = n - prefix
    S = stride if stride and stride > 0 and rest % stride == 0 and rest else 1
    sections = ([(arr[:prefix].reshape(prefix, 1), ())] if prefix else []) + \
        [(arr[prefix:].reshape(rest // S, S), index_columns)]
    parts = [varint_text([_utf16_len(name)]) + name + varint_text([len(sections)])]
    total = 0
    alphabet = np.array(list(ALPHABET))
    columns: list[Column] = []
    for grid, idx in sections:
        qs = []
        for c in range(grid.shape[1]):
            dq = decimals_of(grid[:, c])
            if dq is None:
                return None
            qs.append(dq)
        groups = _groups(grid, qs, idx, modes if grid.shape[1] == S else None, frozenset(allow), fixed_t)
        columns += groups
        parts.append(varint_text(list(grid.shape)))
        for col in groups:  # each group: its header, then its codes
            parts.append(varint_text(col.header()))
            if col.mode == CONST or col.codes is None or not len(col.codes):
                continue
            table, _ = encode_varints(col.codes, col.T)
            flat = table.ravel()
            parts.append("".join(alphabet[flat[flat >= 0]].tolist()))
            if float(np.asarray(col.codes).sum(dtype=np.float64)) >= MAX_Q:
                return None  # the loader's check sum would not be exact
            total += int(np.asarray(col.codes).sum())
    if total >= MAX_Q:
        return None
    body = "".join(parts) + varint_text([total])
    crc = zlib.crc32(name.encode("utf-8") + body.encode("utf-8"))
    return Packed(name, MAGIC + varint_text([crc]) + body, rest // S, S, columns, n)


# --------------------------------------------------------------------------- unpacking
@dataclass
class DecodeCost:
    """What the loader does for one list: the inputs of :func:`bake.scratch.loader.decode_cost`."""

    header_varints: int = 0  # varints read by ``_pk num`` (header fields, palettes, the sum)
    header_slow: int = 0  # of those, the ones of more than one symbol
    header_continuation: int = 0  # symbols read after a varint's first
    body_varints: int = 0  # varints read in the body
    body_slow: int = 0
    body_continuation: int = 0
    header_zigzag: int = 0  # zigzag values decoded in the header (const, offset, palette entries)
    header_negative: int = 0  # of those, the negative ones
    body_negative: int = 0  # negative deltas
    groups: list = field(default_factory=list)  # (mode name, width, new-vertex codes, palette size, rows)
    sections: list = field(default_factory=list)  # (rows, stride) of each section
    rows: int = 0  # of the last section
    stride: int = 0
    chars: int = 0

    @property
    def items(self) -> int:
        return sum(R * S for R, S in self.sections)


@dataclass
class Unpacked:
    """What :func:`unpack` found: the items and what decoding them costs."""

    name: str
    items: list
    rows: int
    stride: int
    modes: list[str]
    chars: int
    cost: DecodeCost


class _Reader:
    """Reads the header's varints one by one (the body's are decoded a group at a time)."""

    def __init__(self, name: str, text: str, syms: np.ndarray, start: int, cost: DecodeCost):
        self.name, self.text, self.syms, self.p = name, text, syms, start
        self.cost = cost

    def varint(self, T: int) -> int:
        C = BASE - T
        a = 0
        digits = 0
        while True:
            if self.p >= len(self.syms):
                raise PackError(self.name, f"the text ends too early (at character {self.p + 1})")
            s = int(self.syms[self.p])
            self.p += 1
            if s < 0:
                raise PackError(self.name, f"character {self.text[self.p - 1]!r} at {self.p} is not a packed symbol")
            if s < T:
                break
            a = a * C + s - T + 1
            digits += 1
            if digits > 12:
                raise PackError(self.name, f"a number at character {self.p} is too long")
        self.cost.header_varints += 1
        self.cost.header_slow += digits > 0
        self.cost.header_continuation += digits
        return a * T + s

    def bounded(self, T: int, hi: int, what: str, lo: int = 0) -> int:
        v = self.varint(T)
        if not lo <= v <= hi:
            raise PackError(self.name, f"{what} {v} is out of range ({lo}..{hi})")
        return v

    def zig(self) -> int:
        n = self.varint(HEADER_T)
        self.cost.header_zigzag += 1
        self.cost.header_negative += n % 2
        return unzigzag(n)

    def body(self, T: int, count: int) -> np.ndarray:
        """``count`` varints with parameter T from here, as an int64 array."""
        if count == 0:
            return np.zeros(0, np.int64)
        rest = self.syms[self.p:]
        if (rest < 0).any():
            bad = self.p + int(np.flatnonzero(rest < 0)[0])
            # only an error if the bad character is inside this group's varints
            rest = rest[:bad - self.p]
            if (rest < T).sum() < count:
                raise PackError(self.name, f"character {self.text[bad]!r} at {bad + 1} is not a packed symbol")
        ends = np.flatnonzero(rest < T)
        if len(ends) < count:
            raise PackError(self.name, "the text ends too early (inside the data)")
        ends = ends[:count]
        starts = np.concatenate([[0], ends[:-1] + 1])
        k = ends - starts  # continuation symbols of each varint
        if k.max(initial=0) > 12:
            raise PackError(self.name, "a number in the data is too long")
        C = BASE - T
        a = np.zeros(count, np.int64)
        for j in range(int(k.max(initial=0))):
            live = k > j
            d = rest[np.where(live, starts + j, 0)] - T + 1
            a = np.where(live, a * C + d, a)
        vals = a * T + rest[ends]
        self.p += int(ends[-1]) + 1
        self.cost.body_varints += count
        self.cost.body_slow += int((k > 0).sum())
        self.cost.body_continuation += int(k.sum())
        return vals


def header_name(text: Any) -> str | None:
    """The list name written in a packed text (None if it is not one)."""
    if not isinstance(text, str) or not text.startswith(MAGIC):
        return None
    try:
        r = _Reader("?", text, _symbols(text[:64]), len(MAGIC), DecodeCost())
        r.varint(HEADER_T)
        n = r.varint(HEADER_T)
        u16 = text[r.p:].encode("utf-16-le", errors="surrogatepass")[:2 * n]
        name = u16.decode("utf-16-le")
        return name if len(u16) == 2 * n else None
    except (PackError, UnicodeDecodeError):
        return None


def _symbols(text: str) -> np.ndarray:
    """Symbol values of a text's characters (-1: not a symbol)."""
    codes = np.frombuffer(text.encode("utf-32-le", errors="surrogatepass"), np.uint32).astype(np.int64)
    return np.where(codes < 128, _SYM_ARRAY[np.minimum(codes, 127)], -1)


def packed_bytes(name: str, text: str) -> int:
    """Bytes a packed list adds to project.json: its text as an item of the packed list (with a
    comma) and its own list, now empty."""
    from .numbers import project_json_bytes

    return len(json.dumps(text, ensure_ascii=False).encode("utf-8")) + 1 + project_json_bytes(name, "[]")


def is_packed(item: Any) -> bool:
    return isinstance(item, str) and item.startswith(MAGIC)


def unpack(text: Any, name: str | None = None, *, max_items: int = 50_000_000) -> Unpacked:
    """Decode a packed list as the loader blocks do (the same arithmetic, the same checks) and
    count what they do; raises :class:`PackError` naming the list for anything that is not a
    whole, unedited packed list (checked with its CRC as well)."""
    label = name or header_name(text) or "?"
    if not isinstance(text, str) or not text.startswith(MAGIC):
        raise PackError(label, f"does not start with {MAGIC!r} (not a scratch-bake packed list)")
    cost = DecodeCost(chars=len(text))
    syms = _symbols(text)
    r = _Reader(label, text, syms, len(MAGIC), cost)
    crc = r.varint(HEADER_T)
    body_start = r.p
    nlen = r.bounded(HEADER_T, 10_000, "name length")
    u16 = text[r.p:].encode("utf-16-le", errors="surrogatepass")
    if len(u16) < 2 * nlen:
        raise PackError(label, "the text ends inside the name")
    try:
        written = u16[:2 * nlen].decode("utf-16-le")
    except UnicodeDecodeError:
        raise PackError(label, "the name is cut inside a character") from None
    r.p += len(written)
    if name is not None and written != name:
        raise PackError(label, f"holds the list '{written}'")
    label = r.name = written
    try:
        whole = written.encode("utf-8") + text[body_start:].encode("utf-8")
    except UnicodeEncodeError:
        raise PackError(label, "holds characters that are not text") from None
    if zlib.crc32(whole) != crc:
        raise PackError(label, "the check sum does not match: the text was truncated or edited")
    nsec = r.bounded(HEADER_T, 8, "section count")
    items: list = []
    groups: list[Column] = []
    m = 0
    total = 0
    R = S = 0
    for _ in range(nsec):
        R = r.bounded(HEADER_T, max_items, "row count")
        S = r.bounded(HEADER_T, 4096, "stride", 1)
        if len(items) + R * S > min(max_items, 10 * len(text) + 1_000_000):  # the loader's bound too
            raise PackError(label, f"{len(items) + R * S} items is more than the text can hold")
        grid = np.zeros((R, S), np.float64)
        ints = np.zeros(S, bool)
        c0 = 0
        while c0 < S:
            col = Column(r.bounded(HEADER_T, 4, "column mode"))
            col.width = r.bounded(HEADER_T, S - c0, "width", 1)
            col.T = r.bounded(HEADER_T, BASE - 1, "T", 1)
            col.decimals = r.bounded(HEADER_T, MAX_DECIMALS, "decimals")
            col.q0 = r.zig()
            P = r.bounded(HEADER_T, len(text), "palette size")
            col.palette = [r.zig() for _ in range(P)]
            if col.mode != INDEX and col.width != 1:
                raise PackError(label, f"a {MODE_NAMES[col.mode]} group {col.width} columns wide")
            if (col.mode == PALETTE) != (P > 0) and R:
                raise PackError(label, "a palette where there should be none, or none where there should be one")
            groups.append(col)
            mode, w, sc = col.mode, col.width, 10 ** col.decimals
            new = 0
            if mode == CONST:
                q = np.full(R, col.q0, np.int64)
            else:
                n = r.body(col.T, R * w)
                if float(n.sum(dtype=np.float64)) >= MAX_Q:
                    raise PackError(label, "the codes sum past 2^53")
                total += int(n.sum())
                if mode == INDEX:
                    zero = n == 0
                    m_after = m + np.cumsum(zero)
                    q = np.where(zero, m_after, m_after + 1 - n)
                    if len(q) and q.min() < 1:
                        raise PackError(label, "an index code points before the first item")
                    new = int(zero.sum())
                    m = int(m_after[-1]) if len(q) else m
                elif mode == OFFSET:
                    q = col.q0 + n
                elif mode == DELTA:
                    cost.body_negative += int((n % 2).sum())
                    q = np.cumsum(col.q0 + np.where(n % 2 == 0, n // 2, -(n + 1) // 2))
                else:
                    if len(n) and n.max() >= P:
                        raise PackError(label, f"a palette code is past the palette ({P})")
                    q = np.array(col.palette, np.int64)[n] if len(n) else n
            q = np.asarray(q, np.int64).reshape(R, w)
            if (np.abs(q) >= MAX_Q).any():
                raise PackError(label, "a value is too large to be exact")
            grid[:, c0:c0 + w] = q / float(sc) if sc != 1 else q
            ints[c0:c0 + w] = sc == 1
            cost.groups.append((MODE_NAMES[mode], w, new, P, R))
            c0 += w
        cols = [grid[:, c].astype(np.int64).tolist() if ints[c] else grid[:, c].tolist() for c in range(S)]
        items += [v for row in zip(*cols) for v in row] if S > 1 else (cols[0] if S else [])
        cost.sections.append((R, S))
    check = r.varint(HEADER_T)
    if check != total:
        raise PackError(label, "the sum of the codes does not match")
    if r.p != len(text):
        raise PackError(label, f"{len(text) - r.p} characters left over after the last item")
    cost.rows, cost.stride = R, S
    return Unpacked(label, items, R, S, [MODE_NAMES[c.mode] for c in groups], len(text), cost)
