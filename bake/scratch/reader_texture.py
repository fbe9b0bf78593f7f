"""The reader sprite's textured filler: a triangle drawn cell by cell, each cell's colour the
nearest texel of its texture (a material texture through ``tri uvs``, or the lightmap through
``lightmap uvs``) at the cell's centre, perspective-correct. Generated only when the bake wrote a
texture (a colour list or a TextImage string) or a lightmap for the drawn triangles; its Python
model, cell for cell, is ``bake.outputs.cells`` (report.html's green-flag preview of a textured
bake), and the player suite compares the two in TurboWarp (docs/formats-textures.md, "Drawing a
textured triangle").

The frame is a grid of square cells of ``cell`` stage pixels (``export.texel_size``), the first
at the stage's top-left corner (centres: :func:`grid`). A cell belongs to a triangle when its centre is inside it: for
each cell row whose centre ``Y`` is within the triangle's height, the span ``[xl, xr]`` where the
row's centre line crosses the triangle's edges (an edge ``P -> Q`` with ``P.y != Q.y`` and ``Y``
between them, ends included, crosses at ``P.x + (Y - P.y) * (Q.x - P.x) / (Q.y - P.y)``), and the
cells whose centre ``X`` lies in it. Perspective: ``q = 1 / w`` (``w``: the projected depth over
focal, ``_pz``), ``U = u * W * q`` and ``V = v * H * q`` are affine on the screen; each triangle
sets up their steps per stage unit in x and y from its corners, each row starts them at its first
cell and each cell adds ``cell`` times the x step. A cell's texel is column ``floor(U / q) mod W``
and row ``floor(V / q) mod H`` (repeat addressing), row 0 the first row of the colour list.

Cells of one colour next to each other in a row are drawn as one run: with pen size 1, along the
centres of the run's pixel rows, from its first pixel's centre to its last: scratch-render's pen
covers the pixels whose centres the stroke passes through fully, and a pixel one farther by about
1% (measured in TurboWarp), so each pixel of the run is painted, and a neighbour drawn earlier
keeps its colour within a few levels. A triangle without a texture (a material
without one) is drawn the same way in its flat colour, one run per row.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

from . import blocks as B
from .blocks import add, div, eq, gt, item, lt, mul, not_, sub, var

STAGE_W, STAGE_H = 480, 360


def grid(cell: int) -> tuple[float, float]:
    """(D, C): the centre of cell column i is at stage x ``cell * i + D``, of cell row j (from the
    top) at stage y ``C - cell * j``. scratch-render's pen draws pixel (row r, column c) of the
    480 x 360 stage centred on stage (c - 240, 179 - r) (measured in TurboWarp: a pen-size-1 line
    along y = 80 covers one pixel row, along y = 80.5 two rows by half), so a cell of ``cell`` x
    ``cell`` pixels is centred half a cell less half a pixel from its first pixel's centre."""
    h = (cell - 1) / 2.0
    return h - STAGE_W / 2, (STAGE_H / 2 - 1) - h


@dataclass
class TextureSource:
    """One texture as the project holds it: a colour list (``kind = "list"``, ``W * H`` colour
    numbers) or a TextImage string (``kind = "textimage"``, item 1 of the list), ``W`` x ``H``
    texels, the first row of the list at the image's bottom (``first_row = "bottom"``) or top."""

    kind: str
    list: str
    width: int
    height: int
    first_row: str = "bottom"


@dataclass
class TextureSpec:
    """What the textured filler reads. ``sources``: the textures, in the order they are loaded
    into the sprite's ``_tex``; ``material_source``: per material (1-based order), the source's
    index (0-based) or -1 for a flat colour; ``uvs``: the per-triangle UV list (6 numbers a
    triangle, corners in the triangle list's order: ``tri uvs`` or ``lightmap uvs``); ``cell``:
    the cell size in stage pixels."""

    sources: list[TextureSource]
    material_source: list[int]
    uvs: str
    cell: int = 2
    offsets: list[int] = field(default_factory=list)

    def __post_init__(self) -> None:
        self.offsets = []
        off = 0
        for s in self.sources:
            self.offsets.append(off)
            off += s.width * s.height

    def to_json(self) -> dict:
        return {"cell": self.cell, "uvs": self.uvs, "material_source": list(self.material_source),
                "sources": [{"kind": s.kind, "list": s.list, "width": s.width, "height": s.height,
                             "first_row": s.first_row} for s in self.sources]}

    @classmethod
    def from_json(cls, d: dict) -> "TextureSpec":
        return cls([TextureSource(**s) for s in d["sources"]], list(d["material_source"]), d["uvs"], int(d["cell"]))

    def lists_read(self) -> list[str]:
        return [self.uvs] + [s.list for s in self.sources]

    def tables(self) -> tuple[list[int], list[int], list[int], list[int]]:
        """Per material: the texture's first item in ``_tex`` less one (-1: flat), its width,
        height, and whether its rows run from the top (1) or the bottom (0)."""
        off, w, h, top = [], [], [], []
        for k in self.material_source:
            if k < 0:
                off.append(-1), w.append(1), h.append(1), top.append(0)
            else:
                s = self.sources[k]
                off.append(self.offsets[k]), w.append(s.width), h.append(s.height)
                top.append(1 if s.first_row == "top" else 0)
        return off, w, h, top


def load_blocks(r: Any, spec: TextureSpec) -> list[B.Node]:
    """Green-flag blocks that put every texture's colours into ``_tex`` (TextImage strings
    decoded by ``decode textimage``)."""
    tex = r.lst("_tex")
    i = r.v("_ti")
    out: list[B.Node] = [B.delete_all(tex)]
    for s in spec.sources:
        if s.kind == "textimage":
            out += [B.call("decode textimage %s", item(1, s.list)), r.set("_ti", 1),
                    B.repeat(mul(var("ti width"), var("ti height")),
                             [B.add_to(tex, item(i, "ti colors")), r.change("_ti", 1)])]
        else:
            out += [r.set("_ti", 1), B.repeat(B.list_length(s.list), [B.add_to(tex, item(i, s.list)),
                                                                      r.change("_ti", 1)])]
    return out


def _run(r: Any, cell: int, colour: Any, x0: Any, x1: Any, y: Any) -> list[B.Node]:
    """Paint the cells of one row from centre ``x0`` to centre ``x1`` (row centre ``y``) in
    ``colour``: pen size 1 along each pixel row, from the first pixel centre to the last."""
    h = (cell - 1) / 2.0  # from a cell's centre to its outermost pixel centres
    xa, xb = sub(x0, h), add(x1, h)
    nodes: list[B.Node] = [B.set_pen_color(colour), B.pen_up()]
    for k in range(cell):  # pixel rows top to bottom, walked as a zigzag (the turns are the run's own pixels)
        yk = add(y, h - k) if h - k else y
        if k == 0:
            nodes += [B.goto_xy(xa, yk), B.pen_down(), B.goto_xy(xb, yk)]
        else:
            nodes += [B.goto_xy(xb if k % 2 else xa, yk), B.goto_xy(xa if k % 2 else xb, yk)]
    nodes.append(B.pen_up())
    return nodes


def cell_fill(r: Any, spec: TextureSpec, t: Any, material: Any, flat: Any, corners: list[Any]) -> list[B.Node]:
    """The blocks that fill one front-facing triangle (number ``t``, ``material`` its 1-based
    material, ``flat`` its flat colour) by cells. ``corners``: the reporters of its corners'
    projected points (items of ``_px``, ``_py``, ``_pz``), in the triangle list's order; the
    corners' screen x, y are in ``_ax .. _cy`` already."""
    s = spec.cell
    D, C = grid(s)
    pz = "_pz"
    off_l, tw_l, th_l, top_l = spec.tables()
    offs = r.lst("_toff", off_l)
    tws = r.lst("_tw", tw_l)
    ths = r.lst("_th", th_l)
    tex = r.lst("_tex")
    V = {n: r.v(n) for n in ("_ax", "_ay", "_bx", "_by", "_cx", "_cy", "_toff", "_tw", "_th", "_m", "_ub",
                             "_qa", "_qb", "_qc", "_Ua", "_Ub", "_Uc", "_Va", "_Vb", "_Vc",
                             "_qx", "_qy", "_Ux", "_Uy", "_Vx", "_Vy", "_q", "_U", "_V",
                             "_j", "_j1", "_Y", "_xl", "_xr", "_i0", "_i1", "_X", "_rs", "_rc", "_c",
                             "_den", "_qs", "_Us", "_Vs", "_o1", "_Tx", "_Ty", "_Mx", "_My", "_Bx", "_By", "_sx",
                             "_sL", "_dL", "_sS", "_dS", "_je", "_xL", "_xS", "_ll", "_dl", "_dr", "_ts")}
    ax, ay, bx, by, cx, cy = (V[n] for n in ("_ax", "_ay", "_bx", "_by", "_cx", "_cy"))
    den = V["_den"]  # twice the signed area (b - a) x (c - a)
    setup: list[B.Node] = [
        r.set("_m", material),
        r.set("_toff", item(V["_m"], offs)),
    ]
    # the textured triangle's attributes at its corners and their steps per stage unit
    tex_setup: list[B.Node] = [r.set("_tw", item(V["_m"], tws)), r.set("_th", item(V["_m"], ths)),
                               r.set("_ub", mul(6, sub(t, 1))),
                               r.set("_den", sub(mul(sub(bx, ax), sub(cy, ay)), mul(sub(by, ay), sub(cx, ax))))]
    for k, (name, point) in enumerate(zip("abc", corners)):
        u = item(add(V["_ub"], 2 * k + 1), spec.uvs)
        v = item(add(V["_ub"], 2 * k + 2), spec.uvs)
        tex_setup += [r.set(f"_q{name}", div(1, item(point, pz))),
                      r.set(f"_U{name}", mul(mul(u, V["_tw"]), V[f"_q{name}"])),
                      r.set(f"_V{name}", mul(mul(v, V["_th"]), V[f"_q{name}"]))]
    if any(src.first_row == "top" for src in spec.sources):  # rows from the top: v runs down the list
        tops = r.lst("_ttop", top_l)
        tex_setup.append(B.if_(eq(item(V["_m"], tops), 1), [
            r.set(f"_V{n}", mul(mul(sub(1, item(add(V["_ub"], 2 * k + 2), spec.uvs)), V["_th"]), V[f"_q{n}"]))
            for k, n in enumerate("abc")]))
    for f in ("q", "U", "V"):
        fa, fb, fc = V[f"_{f}a"], V[f"_{f}b"], V[f"_{f}c"]
        tex_setup += [
            r.set(f"_{f}x", div(sub(mul(sub(fb, fa), sub(cy, ay)), mul(sub(fc, fa), sub(by, ay))), den)),
            r.set(f"_{f}y", div(sub(mul(sub(fc, fa), sub(bx, ax)), mul(sub(fb, fa), sub(cx, ax))), den)),
            r.set(f"_{f}s", mul(V[f"_{f}x"], s)),  # the step from one cell to the next
        ]
    tex_setup.append(r.set("_o1", add(V["_toff"], 1)))
    # the cell rows: row j's centre is Y = C - s * j (j = 0 at the top: :func:`grid`). The corners
    # sorted top (T), middle (M), bottom (B) by stage y; the long edge T-B bounds every row, the
    # short edge T-M the rows with Y >= M.y (the upper half, when T is above M), M-B the rows below.
    # Each edge's x is set at a half's first row and stepped by its slope times -s per row.
    rows_max = STAGE_H // s - 1
    sort: list[B.Node] = [r.set("_Tx", ax), r.set("_Ty", ay), r.set("_Mx", bx), r.set("_My", by),
                          r.set("_Bx", cx), r.set("_By", cy)]
    for hi, lo in (("T", "M"), ("M", "B"), ("T", "M")):  # bubble the highest y up (ties keep their order)
        sort.append(B.if_(gt(V[f"_{lo}y"], V[f"_{hi}y"]), [
            r.set("_sx", V[f"_{hi}x"]), r.set(f"_{hi}x", V[f"_{lo}x"]), r.set(f"_{lo}x", V["_sx"]),
            r.set("_sx", V[f"_{hi}y"]), r.set(f"_{hi}y", V[f"_{lo}y"]), r.set(f"_{lo}y", V["_sx"])]))
    Tx, Ty, Mx, My, Bx, By = (V[n] for n in ("_Tx", "_Ty", "_Mx", "_My", "_Bx", "_By"))
    walk = [
        r.set("_sL", div(sub(Bx, Tx), sub(By, Ty))), r.set("_dL", mul(V["_sL"], -s)),
        # the last row of the upper half (Y >= M.y; none when T and M are level)
        B.if_(gt(Ty, My), [r.set("_je", B.mathop("floor", div(sub(C, My), s)))],
              [r.set("_je", sub(B.mathop("ceiling", div(sub(C, My), s)), 1))]),
        # the long edge is on the left of both halves when it passes left of the middle corner
        B.if_(lt(add(Tx, mul(sub(My, Ty), V["_sL"])), Mx), [r.set("_ll", 1)], [r.set("_ll", 0)]),
    ]
    Y, X = V["_Y"], V["_X"]
    last = add(mul(s, V["_i1"]), D)
    # textured: q, U, V at the first cell (from their values at x = 0 on this row), then the
    # cells left to right, runs of one colour
    q, U, Vv = V["_q"], V["_U"], V["_V"]
    texel = item(add(add(mul(B.mod(B.floor(div(Vv, q)), V["_th"]), V["_tw"]), B.mod(B.floor(div(U, q)), V["_tw"])),
                     V["_o1"]), tex)
    tex_cells = [r.set(f"_{f}", add(add(V[f"_{f}a"], mul(V[f"_{f}x"], sub(X, ax))), mul(V[f"_{f}y"], sub(Y, ay))))
                 for f in ("q", "U", "V")] + [
        r.set("_rs", X), r.set("_rc", ""),
        B.repeat(add(sub(V["_i1"], V["_i0"]), 1), [
            r.set("_c", texel),
            B.if_(eq(V["_c"], V["_rc"]), [], [
                B.if_(eq(V["_rc"], ""), [], _run(r, s, V["_rc"], V["_rs"], sub(X, s), Y)),
                r.set("_rs", X), r.set("_rc", V["_c"])]),
            r.change("_X", s), r.change("_q", V["_qs"]), r.change("_U", V["_Us"]), r.change("_V", V["_Vs"]),
        ]),
        *_run(r, s, V["_rc"], V["_rs"], sub(X, s), Y),
    ]

    def row(textured: bool) -> list[B.Node]:
        """One cell row: its cells between the left and right edges, then every walker one row down."""
        body = [
            r.set("_i0", B.mathop("ceiling", div(sub(V["_xl"], D), s))),
            r.set("_i1", B.mathop("floor", div(sub(V["_xr"], D), s))),
            B.if_(lt(V["_i0"], 0), [r.set("_i0", 0)]),
            B.if_(gt(V["_i1"], STAGE_W // s - 1), [r.set("_i1", STAGE_W // s - 1)]),
            r.set("_X", add(mul(s, V["_i0"]), D)),
            B.if_(not_(lt(V["_i1"], V["_i0"])), [
                # (textured) the texture's set-up at the triangle's first row with cells: most
                # small triangles have none
                B.if_(eq(V["_ts"], 0), [*tex_setup, r.set("_ts", 1)]), *tex_cells] if textured else
                _run(r, s, flat, X, last, Y)),
            r.change("_Y", -s), r.change("_xl", V["_dl"]), r.change("_xr", V["_dr"]),
        ]
        return body

    def half(first: Any, end: Any, px_: Any, py_: Any, qx_: Any, qy_: Any) -> list[B.Node]:
        """The rows first .. end (clamped to the stage), between the long edge and the short edge
        p-q; each edge's x set at the first row and stepped by its slope times -s."""
        return [
            r.set("_j", first), B.if_(lt(V["_j"], 0), [r.set("_j", 0)]),
            r.set("_j1", end), B.if_(gt(V["_j1"], rows_max), [r.set("_j1", rows_max)]),
            B.if_(not_(lt(V["_j1"], V["_j"])), [
                r.set("_Y", sub(C, mul(s, V["_j"]))),
                r.set("_xL", add(Tx, mul(sub(Y, Ty), V["_sL"]))),
                r.set("_sS", div(sub(qx_, px_), sub(qy_, py_))), r.set("_dS", mul(V["_sS"], -s)),
                r.set("_xS", add(px_, mul(sub(Y, py_), V["_sS"]))),
                B.if_(eq(V["_ll"], 1),
                      [r.set("_xl", V["_xL"]), r.set("_dl", V["_dL"]), r.set("_xr", V["_xS"]), r.set("_dr", V["_dS"])],
                      [r.set("_xl", V["_xS"]), r.set("_dl", V["_dS"]), r.set("_xr", V["_xL"]), r.set("_dr", V["_dL"])]),
                B.if_(lt(V["_toff"], 0), [B.repeat(add(sub(V["_j1"], V["_j"]), 1), row(False))],
                      [B.repeat(add(sub(V["_j1"], V["_j"]), 1), row(True))]),
            ]),
        ]

    upper = half(B.mathop("ceiling", div(sub(C, Ty), s)), V["_je"], Tx, Ty, Mx, My)
    lower = half(add(V["_je"], 1), B.mathop("floor", div(sub(C, By), s)), Mx, My, Bx, By)
    # nothing to do for a triangle between two cell rows
    rows_any = not_(gt(B.mathop("ceiling", div(sub(C, Ty), s)), B.mathop("floor", div(sub(C, By), s))))
    return sort + [B.if_(rows_any, [*setup, r.set("_ts", 0), *walk, *upper, *lower])]
