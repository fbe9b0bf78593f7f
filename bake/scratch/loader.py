"""The loader blocks: rebuild packed lists (``bake/scratch/pack.py``) inside Scratch at the green flag.

The project stores each packed list as one string item of the list ``packed lists`` (in the
order of :attr:`LoaderSpec.lists`) and the documented list itself empty. ``unpack lists`` (run
by the reader's green-flag script before anything reads the lists) decodes every item with the
generic decoder ``_pk unpack (text)`` into ``_pk out`` and copies it into its list. The decoder
reads any packed list (the modes and parameters are in its header), so an author can copy these
blocks into an engine once and keep re-baking the data.

==============================  ===================================================================
custom block                    what it does
==============================  ===================================================================
``unpack lists``                every packed list into its list; ``unpacked`` = 1 when done,
                                ``unpack error`` = "" or which list failed and why (that list is
                                left empty, never half-decoded)
``clear unpacked lists``        empties the lists ``unpack lists`` filled (click it before saving
                                the project in the editor, so project.json stays small)
``_pk unpack (text)``           one packed text into ``_pk out`` (``_pk error`` = "" or why not)
``_pk num``                     the next header varint (T = 46) into ``_pkn``
==============================  ===================================================================

Symbols are read case-sensitively through costume names, as the TextImage decoder does
(``switch costume to (letter)`` matches names with ``===``; ``item # of`` would not tell "A"
from "a", shared/docs/scratch.md 4a): the sprite's costumes are the 94 characters ``!`` .. ``~``
and ``_pk sym`` maps a costume number to its symbol value. The text gets a ``!`` (symbol 0, a
final digit for every T) appended before decoding, so a truncated text can never keep a varint
loop going: reading past the end repeats it. Every loop is bounded by the header's counts, which
are checked against the text's length first; the section loop needs no bound of its own, as each
section reads symbols and, past the end, reads a zero width and fails.

The blocks are written in the lighter encoding of packed projects (``ReaderBuilder.compact``:
:class:`bake.scratch.blocks.Builder` ``compact``, minimal alphabet costumes): issue 41 measured
them and the alphabet costumes as more than a third of a 2,000-triangle model's project.json.

:func:`decode_cost` gives the blocks these scripts execute for a list (the count ``vm/run.js``
reports), from what :func:`bake.scratch.pack.unpack` saw; tests/scratch/test_pack_vm.py checks it.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from . import blocks as B
from .blocks import add, div, eq, gt, item, lt, mod, mul, or_, sub, var
from .pack import BASE, HEADER_T, MAGIC, DecodeCost, costume_symbols

PACKED_LIST = "packed lists"
ERROR_VAR = "unpack error"
DONE_VAR = "unpacked"
MAX_STRIDE = 4096


@dataclass
class LoaderSpec:
    """Which packed item goes to which list: ``lists[k]`` is the list that item k + 1 of
    ``packed`` rebuilds."""

    lists: list[str] = field(default_factory=list)
    packed: str = PACKED_LIST


def add_loader(r: Any, spec: LoaderSpec) -> None:
    """Define the loader's custom blocks on a reader under construction
    (:class:`bake.scratch.readers.ReaderBuilder`: ``v``, ``lst``, ``set``, ``change``, ``define``)."""
    S, p, s, a, n = r.v("_pkS", ""), r.v("_pkp"), r.v("_pks"), r.v("_pka"), r.v("_pkn")
    T, C, h, m, c = r.v("_pkT"), r.v("_pkC"), r.v("_pkh"), r.v("_pkm"), r.v("_pkc")
    z, mode, k, w = r.v("_pkz"), r.v("_pkmode"), r.v("_pkk"), r.v("_pkw")
    q0, sc, acc = r.v("_pkq0"), r.v("_pksc"), r.v("_pkacc")
    rows, stride, L, i, gT = r.v("_pkR"), r.v("_pkSt"), r.v("_pkL"), r.v("_pki"), r.v("_pkgT")
    base = r.v("_pkb")
    r.v("_pkns")
    err = r.v("_pk error", "")
    r.v(ERROR_VAR, "")
    r.v(DONE_VAR, 0)
    sym = r.lst("_pk sym", costume_symbols())
    out, pal = r.lst("_pk out"), r.lst("_pk pal")
    names = r.lst("_pk names", list(spec.lists))
    packed = r.lst(spec.packed)
    for name in spec.lists:
        r.lst(name)

    read = [  # one symbol into _pks
        B.switch_costume(B.letter_of(p, S)),
        r.set("_pks", item(B.costume_number(), sym)),
        r.change("_pkp", 1),
    ]
    # the varint at _pkp with parameter _pkT (_pkC = 92 - _pkT) into _pkn
    r.define("_pk read", [], [
        *read,
        B.if_(lt(s, T), [r.set("_pkn", s)], [
            r.set("_pka", 0),
            B.repeat_until(lt(s, T), [
                r.set("_pka", add(add(mul(a, C), sub(s, T)), 1)),
                *read,
            ]),
            r.set("_pkn", add(mul(a, T), s)),
        ]),
    ])
    # a header varint (T = 46)
    r.define("_pk num", [], [r.set("_pkT", HEADER_T), r.set("_pkC", BASE - HEADER_T), B.call("_pk read")])
    num, rd = B.call("_pk num"), B.call("_pk read")
    # the zigzag value of _pkn into _pkz
    r.define("_pk unzig", [], [
        B.if_(eq(mod(n, 2), 0), [r.set("_pkz", div(n, 2))], [r.set("_pkz", sub(0, div(add(n, 1), 2)))])])
    unzig = B.call("_pk unzig")

    def fail(msg: str) -> list[B.Node]:
        return [r.set("_pk error", msg), B.stop("this script")]

    code = [rd, r.change("_pkh", n)]
    group = [
        # header: mode, width, T, decimals, zigzag q0, palette size, palette
        num, r.set("_pkmode", n), num, r.set("_pkw", n),
        num, r.set("_pkgT", n),
        num, r.set("_pksc", B.mathop("10 ^", n)),
        num, unzig, r.set("_pkq0", z),
        B.delete_all(pal), num,
        B.if_(or_(or_(lt(gT, 1), lt(w, 1)), gt(n, L)), fail("bad group header")),
        B.repeat(n, [num, unzig, B.add_to(pal, div(z, sc))]),
        r.set("_pkT", gT), r.set("_pkC", sub(BASE, gT)),  # the group's T for _pk read
        r.set("_pkc", add(base, k)), r.set("_pkacc", 0), r.set("_pkz", 0),
        B.if_(eq(mode, 3), [  # index: w columns, row by row
            B.repeat(rows, [
                B.repeat(w, [
                    *code,
                    B.if_(eq(n, 0), [r.change("_pkm", 1), B.replace_item(out, c, m)],
                          [B.replace_item(out, c, sub(add(m, 1), n))]),
                    r.change("_pkc", 1),
                ]),
                r.change("_pkc", sub(stride, w)),
            ]),
        ], [B.if_(eq(mode, 4), [  # palette
            B.repeat(rows, [*code, B.replace_item(out, c, item(add(n, 1), pal)), r.change("_pkc", stride)]),
        ], [  # const (0): q0; offset (1): q0 + code; delta (2): the last + q0 + unzigzag(code)
            B.repeat(rows, [
                B.if_(gt(mode, 0), [*code, B.if_(eq(mode, 2), [unzig], [r.set("_pkz", n)])]),
                B.if_(lt(mode, 2), [r.set("_pkacc", 0)]),
                r.change("_pkacc", add(q0, z)),
                B.replace_item(out, c, div(acc, sc)),
                r.change("_pkc", stride),
            ]),
        ])]),
        r.change("_pkk", w),
    ]
    section = [
        num, r.set("_pkR", n), num, r.set("_pkSt", n),
        B.if_(or_(lt(stride, 1), gt(add(base, mul(rows, stride)), add(mul(L, 10), 1000000))), fail("bad size")),
        B.repeat(mul(rows, stride), [B.add_to(out, 0)]),
        r.set("_pkk", 1),
        B.repeat_until(gt(k, stride), group),
        r.change("_pkb", mul(rows, stride)),
    ]
    r.define("_pk unpack %s", ["text"], [
        r.set("_pk error", ""),
        B.delete_all(out),
        r.set("_pkL", B.length_of(B.arg("text"))),
        r.set("_pkS", B.join(B.arg("text"), "!")),
        r.set("_pkp", len(MAGIC) + 1),
        num,  # the CRC (for bake check; not checked here)
        num, r.change("_pkp", n),  # the name
        num, r.set("_pkns", n),  # (no bound needed: each section reads symbols or fails)
        r.set("_pkh", 0), r.set("_pkm", 0), r.set("_pkb", 0),
        B.repeat(var("_pkns"), section),
        num,
        B.if_(or_(not_eq(n, h), not_eq(p, add(L, 1))), fail("the text is truncated or was edited")),
        B.if_(lt(B.list_length(out), base),
              fail("more items than vanilla Scratch's `add to list` allows (200,000; TurboWarp has no limit)")),
    ])
    # every packed text into its list (an empty item leaves its list alone)
    copy: list[B.Node] = []
    for j, name in enumerate(spec.lists, start=1):
        copy.append(B.if_(eq(i, j), [B.delete_all(name), B.repeat(B.list_length(out), [
            r.change("_pkk", 1), B.add_to(name, item(k, out))])]))
    r.define("unpack lists", [], [
        r.set(ERROR_VAR, ""), r.set(DONE_VAR, 0), r.set("_pki", 1),
        B.repeat(B.list_length(packed), [
            B.if_(not_eq(item(i, packed), ""), [
                B.call("_pk unpack %s", item(i, packed)),
                B.if_(eq(err, ""), [r.set("_pkk", 0), *copy],
                      [r.set(ERROR_VAR, B.join(item(i, names), B.join(": ", err)))]),
            ]),
            r.change("_pki", 1),
        ]),
        B.delete_all(out), B.delete_all(pal), r.set(DONE_VAR, 1),
    ])
    r.define("clear unpacked lists", [], [B.delete_all(x) for x in spec.lists] + [r.set(DONE_VAR, 0)])


@dataclass
class LoaderPart:
    """The loader as a reader part (``ReaderSpec.parts``): its blocks, the 94 character
    costumes, ``unpack lists`` at the green flag before the render, and the render only when
    every list unpacked (``unpack error`` = "")."""

    spec: LoaderSpec

    def __call__(self, r: Any) -> None:
        add_loader(r, self.spec)
        r.alphabet = True
        r.compact = True
        r.at_flag([B.call("unpack lists")])
        r.flag_guard = eq(var(ERROR_VAR), "")

    def lists_read(self) -> list[str]:
        return lists_read(self.spec)


def not_eq(a: Any, b: Any) -> B.Boolean:
    return B.not_(eq(a, b))


def lists_read(spec: LoaderSpec) -> list[str]:
    return [spec.packed]


# --------------------------------------------------------------------------- cost
def _varints(n: int, slow: int, cont: int) -> int:
    """``_pk read`` n times (call and definition included), ``slow`` of them with continuation
    symbols, ``cont`` continuation symbols in all: 16 blocks for a one-symbol varint, 25 + 21 per
    continuation symbol otherwise."""
    return 16 * n + 9 * slow + 21 * cont


UNPACK_LISTS_FIXED = 10  # ``unpack lists`` itself: its call, the first and last sets, the loop's end


def decode_cost(cost: DecodeCost, n_lists: int = 1) -> int:
    """Blocks the VM executes (as ``vm/run.js`` counts them: every block run, reporters and
    variable reads included, a custom block call as two) for one list in ``unpack lists`` (of
    ``n_lists`` packed lists): the call of ``_pk unpack``, the decoding and the copy into the
    list. The whole ``unpack lists`` is the sum over the lists + :data:`UNPACK_LISTS_FIXED`."""
    N = cost.items
    total = 4 * cost.header_varints + _varints(cost.header_varints, cost.header_slow, cost.header_continuation)
    total += _varints(cost.body_varints, cost.body_slow, cost.body_continuation)
    total += 9 * cost.header_zigzag + 2 * cost.header_negative  # _pk unzig in the header
    total += 37 + 2 * len(cost.sections)  # _pk unpack's fixed part
    for rows, stride in cost.sections:  # a section's header, presizing _pk out, its group loop
        total += 30 + 5 * rows * stride
    total += 4 * len(cost.groups)
    total += 15 + 3 * n_lists + 6 * N  # in unpack lists: the item test, the dispatch, the copy
    for mode, w, new, P, R in cost.groups:
        total += 38 + 2 * (P + 1) + 4 * P
        if mode == "index":
            codes = R * w
            total += 2 * (R + 1) + R * (2 * (w + 1) + 4) + 6 * codes + 4 * new + 6 * (codes - new)
            continue
        total += 3
        if mode == "palette":
            total += 2 * (R + 1) + 9 * R
        elif mode == "const":
            total += 2 * (R + 1) + 18 * R
        elif mode == "offset":
            total += 2 * (R + 1) + 25 * R
        else:  # delta, with _pk unzig per row
            total += 2 * (R + 1) + 22 * R + 9 * R
    total += 2 * cost.body_negative
    return total


def total_cost(costs: list[DecodeCost]) -> int:
    """Blocks ``unpack lists`` executes for these lists (in this order)."""
    return UNPACK_LISTS_FIXED + sum(decode_cost(c, len(costs)) for c in costs)
