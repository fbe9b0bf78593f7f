"""The reader sprite's TextImage decoder: ``decode textimage (text)`` -> ``ti colors``, ``ti width``,
``ti height`` (docs/formats-textures.md), proven against ``bake.scratch.textimage.decode`` in the
real Scratch VM (tests/scratch/test_scratch_textimage.py). Generated only when the bake wrote
TextImage strings; it needs the sprite's 94 alphabet costumes (:func:`alphabet_costumes`)."""

from __future__ import annotations

from . import blocks as B
from . import sb3
from .blocks import add, and_, div, eq, floor, gt, item, lt, mod, mul, not_, or_, sub, var
from .textimage import ALPHABET, VOLUMES

# the decoder's lists (declared by textimage_part)
_OUT, _HDR, _PX, _ALPHA, _TABLE, _VOL = "ti colors", "_ti header", "_ti px", "_ti a", "_ti hash", "_ti volumes"

# Empty costume for the alphabet (2x2 transparent; one asset shared by every costume).
EMPTY_SVG = sb3.SPRITE_SVG


def alphabet_costumes(minimal: bool = False) -> list[sb3.Costume]:
    """One costume per TextImage character ("!" .. "~", costume #1 .. #94): ``switch costume to
    (letter)`` matches names case-sensitively (scratch.md 4a), so a character's costume number is
    its value + 1."""
    asset = sb3.Asset(EMPTY_SVG, "svg")
    return [sb3.Costume(ch, asset, 1, (1.0, 1.0), minimal=minimal) for ch in ALPHABET]


def textimage_part(r) -> None:
    """The blocks of ``decode textimage (text)``: the character readers, the opcodes of the RGB8
    and A8 streams, the streams, then the header and the block itself. The lists and variables
    are declared here first, in the order the sprite keeps them; the parts read them by name."""
    r.alphabet = True
    r.v("_ts", ""), r.v("_tp"), r.v("_tc")
    for name in (_OUT, _HDR, _PX, _ALPHA, _TABLE):
        r.lst(name)
    vols: list[int] = []
    for (oy, ou, ov), _dims in VOLUMES:
        vols += [oy, ou, ov]
    r.lst(_VOL, vols)
    r.v("ti width"), r.v("ti height")
    r.v("_tok", ""), r.v("_ti i"), r.v("_ti k"), r.v("_rest", "")
    r.v("_tend"), r.v("_tcount"), r.v("_tvf")
    r.v("_top2"), r.v("_trn"), r.v("_tval")
    r.v("_tr"), r.v("_tg"), r.v("_tb")
    r.v("_tdy"), r.v("_tdu"), r.v("_tdv"), r.v("_tidx")
    r.v("_td0"), r.v("_td1"), r.v("_td2")
    _char_blocks(r)
    _op_blocks(r)
    _stream_blocks(r)
    _decode_block(r)


def _char_blocks(r) -> None:
    """``_ti char`` reads the next character's value into ``_tc``; ``_ti rest (s)`` puts the rest
    of a header token into ``_rest``."""
    s, pos, rest = var("_ts"), var("_tp"), var("_rest")

    # one character -> its value 0..93 (case-sensitive: costume names)
    r.define("_ti char", [], [
        B.switch_costume(B.letter_of(pos, s)),
        r.set("_tc", sub(B.costume_number(), 1)),
        r.change("_tp", 1),
    ])
    # the text after the first two characters of a header token ("x:12" -> "12")
    r.define("_ti rest %s", ["s"], [
        r.set("_rest", ""), r.set("_ti j", 3),
        B.repeat(sub(B.length_of(B.arg("s")), 2), [
            r.set("_rest", B.join(rest, B.letter_of(var("_ti j"), B.arg("s")))), r.change("_ti j", 1)]),
    ])


def _op_blocks(r) -> None:
    """``_ti emit (c)`` adds a pixel; ``_ti rgb op (op)`` and ``_ti a8 op (op)`` decode one opcode
    of an RGB8 or A8 stream."""
    px, alpha, table, vol = _PX, _ALPHA, _TABLE, _VOL
    W, end, vf, val, c = var("ti width"), var("_tend"), var("_tvf"), var("_tval"), var("_tc")
    R, G, Bv = var("_tr"), var("_tg"), var("_tb")
    dY, dU, dV, idx = var("_tdy"), var("_tdu"), var("_tdv"), var("_tidx")
    d0, d1, d2 = var("_td0"), var("_td1"), var("_td2")

    def prev(kexpr, lst: str) -> B.Node:
        """value emitted kexpr pixels ago (0 before the start) -> _tval"""
        return B.if_(gt(kexpr, B.list_length(lst)), [r.set("_tval", 0)],
                     [r.set("_tval", item(add(sub(B.list_length(lst), kexpr), 1), lst))])

    # emit a colour: append, then update the hash table
    r.define("_ti emit %s", ["c"], [
        B.add_to(px, B.arg("c")),
        r.set("_tr", floor(div(B.arg("c"), 65536))),
        r.set("_tg", mod(floor(div(B.arg("c"), 256)), 256)),
        r.set("_tb", mod(B.arg("c"), 256)),
        B.replace_item(table, add(mod(add(add(mul(3, R), mul(5, G)), mul(7, Bv)), 94), 1), B.arg("c")),
    ])
    o = B.arg("op")
    r.define("_ti rgb op %s", ["op"], [
        B.if_(lt(o, 21), [
            r.set("_tval", mul(o, 830584)),
            B.call("_ti char"), r.change("_tval", mul(c, 8836)),
            B.call("_ti char"), r.change("_tval", mul(c, 94)),
            B.call("_ti char"), r.change("_tval", c),
            B.call("_ti emit %s", mod(val, 16777216)),
        ], [B.if_(and_(gt(o, 21), lt(o, 26)), [
            B.if_(eq(o, 22), [prev(1, px)], [
                B.if_(eq(o, 23), [prev(vf, px)], [
                    B.if_(eq(o, 24), [prev(W, px)], [prev(add(W, 1), px)])])]),
            B.call("_ti emit %s", val),
        ], [B.if_(eq(o, 26), [
            B.call("_ti char"),
            B.call("_ti emit %s", item(add(c, 1), table)),
        ], [B.if_(and_(gt(o, 27), lt(o, 91)), [
            r.set("_tidx", sub(o, 28)),
            r.set("_tdy", item(add(mul(3, idx), 1), vol)),
            r.set("_tdu", item(add(mul(3, idx), 2), vol)),
            r.set("_tdv", item(add(mul(3, idx), 3), vol)),
            B.if_(lt(idx, 45), [
                r.set("_td0", 5), r.set("_td1", 4), r.set("_td2", 4),
                B.call("_ti char"), r.set("_tidx", c),
            ], [
                r.set("_td0", 21), r.set("_td1", 20), r.set("_td2", 20),
                B.call("_ti char"), r.set("_tidx", mul(c, 94)),
                B.call("_ti char"), r.change("_tidx", c),
            ]),
            r.change("_tdy", mod(floor(div(idx, mul(d1, d2))), d0)),
            r.change("_tdu", mod(floor(div(idx, d2)), d1)),
            r.change("_tdv", mod(idx, d2)),
            prev(1, px),
            r.set("_tr", add(floor(div(val, 65536)), add(dV, dY))),
            r.set("_tg", add(mod(floor(div(val, 256)), 256), dY)),
            r.set("_tb", add(mod(val, 256), add(dU, dY))),
            B.call("_ti emit %s", add(add(mul(R, 65536), mul(G, 256)), Bv)),
        ], [
            # unknown opcode: stop this stream
            r.set("_tp", add(end, 1)),
        ])])])]),
    ])
    r.define("_ti a8 op %s", ["op"], [
        B.if_(lt(o, 3), [
            r.set("_tval", mul(o, 94)), B.call("_ti char"), r.change("_tval", c),
        ], [B.if_(lt(o, 7), [
            B.if_(eq(o, 3), [prev(1, alpha)], [
                B.if_(eq(o, 4), [prev(vf, alpha)], [
                    B.if_(eq(o, 5), [prev(W, alpha)], [prev(add(W, 1), alpha)])])]),
        ], [
            prev(1, alpha),
            B.if_(lt(o, 51), [r.set("_tval", mod(add(val, sub(o, 7)), 256))],
                  [r.set("_tval", mod(sub(val, sub(o, 50)), 256))]),
        ])]),
        B.add_to(alpha, val),
    ])


def _stream_blocks(r) -> None:
    """``_ti rgb8 (start) (length)`` and ``_ti a8 (start) (length)``: one stream of the text, its
    runs expanded, into ``_ti px`` or ``_ti a``."""
    px, alpha, table = _PX, _ALPHA, _TABLE
    pos, c, end, cnt = var("_tp"), var("_tc"), var("_tend"), var("_tcount")
    op2, rn = var("_top2"), var("_trn")

    def stream(kind: str, lst: str, rle: int) -> list[B.Node]:
        opc = f"_ti {kind} op %s"
        return [
            B.repeat_until(or_(not_(lt(B.list_length(lst), cnt)), gt(pos, end)), [
                B.call("_ti char"),
                B.if_(eq(c, rle), [
                    B.call("_ti char"), r.set("_top2", c),
                    B.call("_ti char"), r.set("_trn", c),
                    B.repeat(rn, [B.call(opc, op2)]),
                ], [B.call(opc, c)]),
            ]),
        ]

    r.define("_ti rgb8 %s %s", ["start", "length"], [
        B.delete_all(px), B.delete_all(table), B.repeat(94, [B.add_to(table, 0)]),
        r.set("_tp", B.arg("start")), r.set("_tend", sub(add(B.arg("start"), B.arg("length")), 1)),
        *stream("rgb", px, 27),
    ])
    r.define("_ti a8 %s %s", ["start", "length"], [
        B.delete_all(alpha),
        r.set("_tp", B.arg("start")), r.set("_tend", sub(add(B.arg("start"), B.arg("length")), 1)),
        *stream("a8", alpha, 7),
    ])


def _decode_block(r) -> None:
    """``decode textimage (text)``: the header, then the main layer (RGB8, A8 as grey, or black)
    and the alpha layer combined into ``ti colors``."""
    out, hdr, px, alpha = _OUT, _HDR, _PX, _ALPHA
    s, tok, i, k, rest = var("_ts"), var("_tok"), var("_ti i"), var("_ti k"), var("_rest")
    W, H, cnt, val = var("ti width"), var("ti height"), var("_tcount"), var("_tval")

    # header: tokens up to the first "|"
    mtype, mstart, mlen = r.v("_tmtype", ""), r.v("_tmstart"), r.v("_tmlen")
    astart, alen, cur = r.v("_tastart"), r.v("_talen"), r.v("_tcur")
    nl = r.v("_tnl")
    letter = B.letter_of(i, s)
    tok1, tok2 = B.letter_of(1, tok), B.letter_of(2, tok)
    layer = [
        r.set("_tok", item(add(k, 1), hdr)),  # purpose
        B.if_(eq(tok, "main"), [
            r.set("_tmtype", item(add(k, 2), hdr)), r.set("_tmstart", cur),
            r.set("_tmlen", item(add(k, 4), hdr))]),
        B.if_(eq(tok, "alpha"), [r.set("_tastart", cur), r.set("_talen", item(add(k, 4), hdr))]),
        r.change("_tcur", item(add(k, 4), hdr)),
        r.change("_ti k", 4),
    ]
    r.define("decode textimage %s", ["text"], [
        r.set("_ts", B.arg("text")),
        B.delete_all(out), B.delete_all(hdr), B.delete_all(px), B.delete_all(alpha),
        r.set("_tok", ""), r.set("_ti i", 1),
        B.repeat_until(or_(eq(letter, "|"), gt(i, B.length_of(s))), [
            B.if_(eq(letter, ","), [B.add_to(hdr, tok), r.set("_tok", "")],
                  [r.set("_tok", B.join(tok, letter))]),
            r.change("_ti i", 1),
        ]),
        B.add_to(hdr, tok),
        r.set("_tcur", add(i, 1)),
        r.set("ti width", 0), r.set("ti height", 0), r.set("_tmtype", ""), r.set("_tastart", 0),
        r.set("_ti k", 1),
        B.repeat_until(gt(k, B.list_length(hdr)), [
            r.set("_tok", item(k, hdr)),
            B.if_(eq(tok2, ":"), [
                B.if_(eq(tok1, "x"), [B.call("_ti rest %s", tok), r.set("ti width", rest)]),
                B.if_(eq(tok1, "y"), [B.call("_ti rest %s", tok), r.set("ti height", rest)]),
                B.if_(eq(tok1, "p"), [
                    B.call("_ti rest %s", tok), r.set("_tnl", div(rest, 4)),
                    B.repeat(nl, layer),
                ]),
            ]),
            r.change("_ti k", 1),
        ]),
        r.set("_tcount", mul(W, H)),
        B.if_(eq(W, 1), [r.set("_tvf", 3)], [r.set("_tvf", sub(W, 1))]),
        B.if_(eq(mtype, "RGB8"), [B.call("_ti rgb8 %s %s", mstart, mlen)], [
            B.delete_all(px),
            B.if_(eq(mtype, "A8"), [
                B.call("_ti a8 %s %s", mstart, mlen),
                r.set("_ti i", 1),
                B.repeat(B.list_length(alpha), [
                    B.add_to(px, mul(item(i, alpha), 65793)), r.change("_ti i", 1)]),
            ], [B.repeat(cnt, [B.add_to(px, 0)])]),
        ]),
        B.if_(gt(astart, 0), [
            B.call("_ti a8 %s %s", astart, alen),
            r.set("_ti i", 1),
            B.repeat(cnt, [
                r.set("_tval", item(i, alpha)),
                B.if_(lt(val, 1), [r.set("_tval", 1)]),
                B.add_to(out, add(mul(val, 16777216), item(i, px))),
                r.change("_ti i", 1),
            ]),
        ], [
            r.set("_ti i", 1),
            B.repeat(cnt, [B.add_to(out, item(i, px)), r.change("_ti i", 1)]),
        ]),
        B.switch_costume(ALPHABET[0]),
    ])
