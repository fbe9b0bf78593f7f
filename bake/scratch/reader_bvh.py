"""The reader sprite's BVH query: ``bvh ray (ox) (oy) (oz) (dx) (dy) (dz)`` for the layout the
bake wrote (docs/formats-bvh.md), proven against ``bake.bvh.traverse.trace_one`` in the real
Scratch VM (tests/scratch/test_scratch_readers.py). Generated only when the bake wrote a BVH."""

from __future__ import annotations

from . import blocks as B
from . import reader_mesh as RM
from .blocks import add, and_, div, eq, floor, gt, item, lt, mod, mul, not_, or_, sub, var

BIG = 1e300  # "no limit" for the ray's farthest distance (docs/formats-bvh.md)


def _le(a, b) -> B.Boolean:
    return not_(gt(a, b))


def _ge(a, b) -> B.Boolean:
    return not_(lt(a, b))


def bvh_part(r) -> None:
    s = r.spec.bvh
    assert s is not None
    BARY_LO, BARY_HI = s.bary
    nodes, tris, ids = r.lst(s.nodes), r.lst(s.tris), r.lst(s.ids)
    o = [r.v(f"_o{a}") for a in "xyz"]
    d = [r.v(f"_d{a}") for a in "xyz"]
    inv = [r.v(f"_i{a}") for a in "xyz"]
    near = [r.v(f"_s{a}") for a in "xyz"]
    best, hit = r.v("_best"), r.v("_hit")
    tn, tf, n, f, bh = (r.v(x) for x in ("_tn", "_tf", "_n", "_f", "_bh"))
    for name in ("hit t", "hit tri", "hit u", "hit v", "hit slot"):
        r.v(name)

    def box_test(get) -> list[B.Node]:
        """``get(k)`` -> expression for box value b(k), k an expression 1..6. Sets _bh, _tn."""
        body = [
            r.set("_tn", mul(sub(get(add(1, near[0])), o[0]), inv[0])),
            r.set("_tf", mul(sub(get(sub(4, near[0])), o[0]), inv[0])),
        ]
        for a in (1, 2):
            body += [
                r.set("_n", mul(sub(get(add(1 + a, near[a])), o[a]), inv[a])),
                r.set("_f", mul(sub(get(sub(4 + a, near[a])), o[a]), inv[a])),
                B.if_(gt(n, tn), [r.set("_tn", n)]),
                B.if_(lt(f, tf), [r.set("_tf", f)]),
            ]
        body.append(B.if_(and_(and_(_le(tn, tf), _ge(tf, 0)), _le(tn, best)),
                          [r.set("_bh", 1)], [r.set("_bh", 0)]))
        return body

    p = r.v("_p")
    if s.layout != "quantised":  # boxes read from the nodes
        r.define("_bvh box at %s", ["p"], box_test(lambda k: item(add(B.arg("p"), sub(k, 1)), nodes)))
    if s.layout != "binary":  # a box in a list (the root's; every quantised box, decoded)
        box = r.lst("_bvh box", [0] * 6)
        r.define("_bvh box", [], box_test(lambda k: item(k, box)))

    # Möller-Trumbore, double-sided, exactly the order of docs/formats-bvh.md; the inside test
    # has the reference's tolerance (u >= -1e-09 ...: typed-in numbers, no extra blocks)
    kk = r.v("_tk")
    V = {}
    for ci in range(3):
        for a, axis in enumerate("xyz"):
            V[(ci, a)] = r.v(f"_v{ci}{axis}")
    e1 = [r.v(f"_e1{a}") for a in "xyz"]
    e2 = [r.v(f"_e2{a}") for a in "xyz"]
    pv = [r.v(f"_pv{a}") for a in "xyz"]
    sv = [r.v(f"_s{a}v") for a in "xyz"]
    qv = [r.v(f"_q{a}") for a in "xyz"]
    det, tinv, u, vv, t = (r.v(x) for x in ("_det", "_inv", "_u", "_v", "_t"))

    def dot3(a, b3):
        return add(add(mul(a[0], b3[0]), mul(a[1], b3[1])), mul(a[2], b3[2]))

    tri_body: list[B.Node] = [r.set("_tk", mul(sub(B.arg("s"), 1), 9))]
    for ci in range(3):
        for a, axis in enumerate("xyz"):
            tri_body.append(r.set(f"_v{ci}{axis}", item(add(kk, 3 * ci + a + 1), tris)))
    for a, axis in enumerate("xyz"):
        tri_body.append(r.set(f"_e1{axis}", sub(V[(1, a)], V[(0, a)])))
    for a, axis in enumerate("xyz"):
        tri_body.append(r.set(f"_e2{axis}", sub(V[(2, a)], V[(0, a)])))
    tri_body += [
        r.set("_pvx", sub(mul(d[1], e2[2]), mul(d[2], e2[1]))),
        r.set("_pvy", sub(mul(d[2], e2[0]), mul(d[0], e2[2]))),
        r.set("_pvz", sub(mul(d[0], e2[1]), mul(d[1], e2[0]))),
        r.set("_det", dot3(e1, pv)),
        B.if_(gt(mul(det, det), mul(1e-12, mul(dot3(e1, e1), dot3(pv, pv)))), [
            r.set("_inv", div(1, det)),
            r.set("_sxv", sub(o[0], V[(0, 0)])),
            r.set("_syv", sub(o[1], V[(0, 1)])),
            r.set("_szv", sub(o[2], V[(0, 2)])),
            r.set("_u", mul(dot3(sv, pv), tinv)),
            B.if_(and_(_ge(u, BARY_LO), _le(u, BARY_HI)), [
                r.set("_qx", sub(mul(sv[1], e1[2]), mul(sv[2], e1[1]))),
                r.set("_qy", sub(mul(sv[2], e1[0]), mul(sv[0], e1[2]))),
                r.set("_qz", sub(mul(sv[0], e1[1]), mul(sv[1], e1[0]))),
                r.set("_v", mul(dot3(d, qv), tinv)),
                B.if_(and_(_ge(vv, BARY_LO), _le(add(u, vv), BARY_HI)), [
                    r.set("_t", mul(dot3(e2, qv), tinv)),
                    B.if_(and_(gt(t, 0), lt(t, best)), [
                        r.set("_best", t), r.set("_hit", B.arg("s")),
                        r.set("hit u", u), r.set("hit v", vv),
                    ]),
                ]),
            ]),
        ]),
    ]
    r.define("_bvh triangle %s", ["s"], tri_body)

    setup: list[B.Node] = []
    for a, axis in enumerate("xyz"):
        setup += [r.set(f"_o{axis}", B.arg(f"o{axis}")), r.set(f"_d{axis}", B.arg(f"d{axis}"))]
    for a, axis in enumerate("xyz"):
        setup += [
            B.if_(lt(B.abs_(d[a]), 1e-30), [r.set(f"_i{axis}", 1e30)], [r.set(f"_i{axis}", div(1, d[a]))]),
            B.if_(lt(inv[a], 0), [r.set(f"_s{axis}", 3)], [r.set(f"_s{axis}", 0)]),
        ]
    setup += [r.set("_best", BIG), r.set("_hit", 0), r.set("hit u", 0), r.set("hit v", 0)]

    sl, link = r.v("_sl"), r.v("_link")
    if s.layout == "binary":
        walk = [
            r.set("_p", 1),
            B.repeat_until(gt(p, B.list_length(nodes)), [
                B.call("_bvh box at %s", p),
                r.set("_link", item(add(p, 6), nodes)),
                B.if_(eq(bh, 1), [
                    B.if_(gt(link, 0), [
                        r.set("_sl", floor(div(link, 16))),
                        B.repeat(mod(link, 16), [B.call("_bvh triangle %s", sl), r.change("_sl", 1)]),
                    ]),
                    r.change("_p", 7),
                ], [
                    B.if_(lt(link, 0), [r.set("_p", sub(0, link))], [r.change("_p", 7)]),
                ]),
            ]),
        ]
    else:
        walk = _bvh_wide_walk(r, s, p)
    finish = [
        B.if_(gt(hit, 0), [
            r.set("hit slot", hit), r.set("hit tri", item(hit, ids)), r.set("hit t", best),
        ], [
            r.set("hit slot", 0), r.set("hit tri", 0), r.set("hit t", -1),
            r.set("hit u", 0), r.set("hit v", 0),
        ]),
    ]
    r.define("bvh ray %s %s %s %s %s %s", ["ox", "oy", "oz", "dx", "dy", "dz"], setup + walk + finish)


def _bvh_wide_walk(r, s, p: B.VarRef) -> list[B.Node]:
    nodes = s.nodes
    quant = s.layout == "quantised"
    stride = 7 if quant else 27
    M = 2 ** s.bits
    Q = float(M - 2) if M > 2 else 1.0
    frame, box = r.lst("_bvh frame", [0] * 6), r.lst("_bvh box", [0] * 6)
    stack = r.lst("_bvh stack")
    ftn, fptr, fbox = r.lst("_bvh found tn"), r.lst("_bvh found ptr"), r.lst("_bvh found box")
    m, j, ni, nl, code, w, sl = (r.v(x) for x in ("_m", "_j", "_ni", "_nl", "_code", "_w", "_sl"))
    bh, best, tn = var("_bh"), var("_best"), var("_tn")
    cvars = [r.v(f"_c{a}") for a in "xyz"]
    kk, kbest = r.v("_kk"), r.v("_kbest")

    child: list[B.Node] = [
        r.set("_code", mod(m, 16)),
        r.set("_m", floor(div(m, 16))),
    ]
    if quant:
        child.append(r.set("_w", item(add(add(p, 3), j), nodes)))
        qs = []
        for k in range(6):
            child += [r.set(f"_q{k}", mod(w, M)), r.set("_w", floor(div(w, M)))]
            qs.append(var(f"_q{k}"))
            r.v(f"_q{k}")
        for k in range(6):
            a = k % 3
            child.append(B.replace_item(box, k + 1, add(item(a + 1, frame), mul(qs[k], cvars[a]))))
        child.append(B.call("_bvh box"))
    else:
        child.append(B.call("_bvh box at %s", add(add(p, 3), mul(6, j))))
    remember: list[B.Node] = [B.add_to(ftn, tn),
                              B.add_to(fptr, add(item(add(p, 1), nodes), mul(ni, stride)))]
    if quant:
        remember += [B.add_to(fbox, item(k, box)) for k in range(1, 7)]
    child += [
        B.if_(eq(code, 15), [
            B.if_(eq(bh, 1), remember),
            r.change("_ni", 1),
        ], [
            B.if_(eq(bh, 1), [
                r.set("_sl", add(item(add(p, 2), nodes), nl)),
                B.repeat(code, [B.call("_bvh triangle %s", sl), r.change("_sl", 1)]),
            ]),
            r.change("_nl", code),
        ]),
        r.change("_j", 1),
    ]
    # push the remembered children farthest first (ties: the later child first), culling by best
    push_one: list[B.Node] = [
        r.set("_kbest", 1), r.set("_kk", 2),
        B.repeat(sub(B.list_length(ftn), 1), [
            B.if_(not_(lt(item(kk, ftn), item(kbest, ftn))), [r.set("_kbest", kk)]),
            r.change("_kk", 1),
        ]),
        B.if_(_le(item(kbest, ftn), best),
              ([B.add_to(stack, item(add(mul(6, sub(kbest, 1)), k), fbox)) for k in range(1, 7)] if quant else [])
              + [B.add_to(stack, item(kbest, fptr)), B.add_to(stack, item(kbest, ftn))]),
        B.delete_item(ftn, kbest), B.delete_item(fptr, kbest),
    ]
    if quant:
        push_one += [B.delete_item(fbox, add(mul(6, sub(kbest, 1)), 1)) for _ in range(6)]
    last = B.list_length(stack)
    pop_frame = ([*(x for k in range(6, 0, -1) for x in (B.replace_item(frame, k, item(last, stack)),
                                                          B.delete_item(stack, "last")))] if quant else [])
    pop = [
        r.set("_p", 0),
        B.repeat_until(or_(gt(p, 0), eq(B.list_length(stack), 0)), [
            r.set("_tn", item(last, stack)), B.delete_item(stack, "last"),
            B.if_(_le(tn, best), [
                r.set("_p", item(last, stack)), B.delete_item(stack, "last"),
                *pop_frame,
            ], [B.delete_item(stack, "last") for _ in range(7 if quant else 1)]),
        ]),
    ]
    per_node: list[B.Node] = [
        r.set("_m", item(p, nodes)), r.set("_j", 0), r.set("_ni", 0), r.set("_nl", 0),
    ]
    if quant:
        per_node += [r.set(f"_c{a}", div(sub(item(4 + k, frame), item(1 + k, frame)), Q))
                     for k, a in enumerate("xyz")]
    per_node += [
        B.delete_all(ftn), B.delete_all(fptr), B.delete_all(fbox),
        B.repeat_until(eq(m, 0), child),
        B.repeat(B.list_length(ftn), push_one),
        *pop,
    ]
    return [
        B.delete_all(stack),
        r.set("_p", 0),
        B.if_(gt(B.list_length(nodes), 0), [
            *[B.replace_item(frame, k, item(k, nodes)) for k in range(1, 7)],
            *[B.replace_item(box, k, item(k, frame)) for k in range(1, 7)],
            B.call("_bvh box"),
            B.if_(eq(bh, 1), [r.set("_p", 7)]),
        ]),
        B.repeat_until(eq(p, 0), per_node),
    ]


# --------------------------------------------------------------------------- the BVH view
#: sqrt(2), typed into the pen-size block (the double JavaScript reads back is exactly this one)
SQRT2 = 1.4142135623730951


def view_pen_size(cell: float) -> float:
    """The pen size of the BVH view's dots for cells of ``cell`` stage pixels, computed as the
    block does: ``((cell - 1) * sqrt 2) + 1``. A dot is a disc of that diameter around the cell's
    centre; the pen paints it fully to ``(size - 1) / 2`` from the centre (its antialiased edge
    is one pixel wide), which reaches the centre of the cell's farthest pixel; its edge ends
    ``(size + 1) / 2`` from the centre, short of every pixel of a neighbouring cell that the
    picture is read at (docs/formats-bvh.md, "The BVH view")."""
    return ((cell - 1) * SQRT2) + 1


def view_grid(cell: float) -> tuple[int, int]:
    """(rows, columns) of the BVH view: ``ceiling(360 / cell)`` by ``ceiling(480 / cell)`` (the
    last row and column may reach past the stage's edge)."""
    import math

    return math.ceil(360 / cell), math.ceil(480 / cell)


def _material_of(r, t) -> B.Reporter:
    """The reporter of triangle t's material item number (1-based) in the mesh lists as written."""
    m = r.spec.mesh
    walk = RM.triangle_walk(m)
    if walk == "book":
        return RM.index(m, item(mul(t, 4), m.tris))
    if walk == "split":
        return RM.index(m, item(t, m.tris[3]))
    return RM.index(m, item(t, m.tris))


def bvh_view_part(r) -> None:
    """``camera ray (sx) (sy)``: the direction of the camera's ray through stage point (sx, sy)
    into ``ray dx``, ``ray dy``, ``ray dz`` (its origin is ``cam x, cam y, cam z``); ``bvh view``:
    one such ray through the centre of every cell of ``bvh cell`` x ``bvh cell`` stage pixels
    (rows from the top, left to right), traced with ``bvh ray``, and a pen dot of
    :func:`view_pen_size` at the centre of every cell whose ray hits, in the hit triangle's colour
    (``tri colors``, else its material's ``mat colors``); cells that miss are not painted.

    The ray inverts the reader's projection (readers.py, "The camera model"): with ``s, c`` Scratch's
    sine and cosine of ``cam yaw`` and ``sp, cp`` of ``cam pitch``, the camera's right is
    ``(c, 0, -s)``, its up ``(-s*sp, cp, -c*sp)`` and its forward ``(s*cp, sp, c*cp)``, and the ray
    is ``right*sx + up*sy + forward*focal``, computed as
    ``dx = ((c*sx) - ((s*sp)*sy)) + ((s*cp)*focal)``, ``dy = (cp*sy) + (sp*focal)``,
    ``dz = ((0 - (s*sx)) - ((c*sp)*sy)) + ((c*cp)*focal)``: the point at depth ``z''`` along it
    projects back onto (sx, sy) (up to the 1e-10 by which the rounded sine and cosine miss
    ``s^2 + c^2 = 1``). The Python reference, with the same arithmetic in the same order, is
    ``bake.outputs.bvh_view``."""
    cell = r.v("bvh cell", r.spec.bvh_view)
    for n in ("ray dx", "ray dy", "ray dz"):
        r.v(n)
    s, c, sp, cp = (r.v(n) for n in ("_gs", "_gc", "_gsp", "_gcp"))
    focal = var("focal")
    sx, sy = B.arg("sx"), B.arg("sy")
    r.define("camera ray %s %s", ["sx", "sy"], [
        r.set("_gs", B.mathop("sin", var("cam yaw"))), r.set("_gc", B.mathop("cos", var("cam yaw"))),
        r.set("_gsp", B.mathop("sin", var("cam pitch"))), r.set("_gcp", B.mathop("cos", var("cam pitch"))),
        r.set("ray dx", add(sub(mul(c, sx), mul(mul(s, sp), sy)), mul(mul(s, cp), focal))),
        r.set("ray dy", add(mul(cp, sy), mul(sp, focal))),
        r.set("ray dz", add(sub(sub(0, mul(s, sx)), mul(mul(c, sp), sy)), mul(mul(c, cp), focal))),
    ])
    gx, gy = r.v("_gx"), r.v("_gy")
    colour, last = r.v("_c"), r.v("_pc")
    hit = var("hit tri")
    paint = [
        r.set("_c", RM.colour(r, hit, _material_of(r, hit))),
        B.if_(eq(colour, last), [], [B.set_pen_color(colour), r.set("_pc", colour)]),
        B.goto_xy(gx, gy), B.pen_down(), B.pen_up(),
    ]
    r.define("bvh view", [], [
        B.hide(), B.pen_up(), B.pen_clear(), B.switch_costume("fence"),
        B.set_pen_size(add(mul(sub(cell, 1), SQRT2), 1)), r.set("_pc", ""),
        r.set("_gy", sub(180, div(cell, 2))),
        B.repeat(B.mathop("ceiling", div(360, cell)), [
            r.set("_gx", sub(div(cell, 2), 240)),
            B.repeat(B.mathop("ceiling", div(480, cell)), [
                B.call("camera ray %s %s", gx, gy),
                B.call("bvh ray %s %s %s %s %s %s", var("cam x"), var("cam y"), var("cam z"),
                       var("ray dx"), var("ray dy"), var("ray dz")),
                B.if_(gt(hit, 0), paint),
                r.change("_gx", cell),
            ]),
            r.change("_gy", sub(0, cell)),
        ]),
    ])
