"""The reference reader sprite: custom blocks, generated here, that read scratch-bake's lists.

Authors can copy these blocks into their own engines. Every block is a custom block with "run
without screen refresh" (warp) on. Outputs go to variables and lists of the sprite; temporaries
start with ``_``. Each reader is proven in the real Scratch VM against the Python reference named
in the last column (tests/scratch/).

==========================================  ===================================  ======================
custom block                                what it does                         Python reference
==========================================  ===================================  ======================
``load triangle (t)``                       corners of triangle t into ``x1 y1   the mesh lists
                                            z1 .. z3``, its colour into ``tri
                                            color``
``set camera (x) (y) (z) (yaw) (pitch)``    camera position and angles (deg)
``project vertices``                        every vertex into the lists ``_px    :func:`project`
                                            _py _pz`` (screen x, y, depth)
``bsp walk (x) (y) (z)``                    painter's order (back to front) for  ``bake.bsp.traverse.
                                            an eye into ``draw order``; single-  draw_order``
                                            sided triangles facing away are
                                            left out (``mat two-sided`` says
                                            which materials are two-sided)
``draw triangle (t)``                       fills triangle t with the pen: flat  painter's raster
                                            colour, scanlines at whole y,
                                            clipped to the stage
``render``                                  erase all, project, ``draw order``   painter's raster
                                            = BSP walk from the camera (list
                                            order without a BSP tree), draw
``bvh ray (ox) (oy) (oz) (dx) (dy) (dz)``   closest hit: ``hit tri`` (scene      ``bake.bvh.traverse.
                                            triangle; 0 on a miss), ``hit t``    trace_one``
                                            (-1 on a miss), ``hit u``, ``hit
                                            v``, ``hit slot``
``decode textimage (text)``                 TextImage v0 -> ``ti colors`` (one   ``bake.textures.
                                            colour number per pixel, bottom row  textimage.decode``
                                            first; ARGB with A >= 1 when the
                                            text has alpha), ``ti width``,
                                            ``ti height``
==========================================  ===================================  ======================

Values typed into blocks are text in Scratch, so an output set to a typed-in number (``hit tri``
on a miss: ``0``) holds the text "0"; Scratch compares and computes with it as a number.

TextImage characters are turned into numbers case-sensitively with costume names: the sprite has
one costume per alphabet character ("!" .. "~", costume #1 .. #94), and ``switch costume to
(letter)`` matches names with ``===`` (scratch.md 4a; ``item # of`` would not tell "A" from "a").

The camera model (the pen renderer and :func:`project` below, which mirrors it bit for bit):
the frame is x right, y up, z into the screen; the camera at ``(cx, cy, cz)`` turned ``yaw``
degrees about y (positive turns right) and then ``pitch`` degrees about its x axis (positive looks
up). With ``d = p - c``: ``x' = dx*cos(yaw) - dz*sin(yaw)``, ``z' = dx*sin(yaw) + dz*cos(yaw)``,
``y'' = dy*cos(pitch) - z'*sin(pitch)``, ``z'' = dy*sin(pitch) + z'*cos(pitch)``; screen
``(focal*x'/z'', focal*y''/z'')``. Scratch's ``sin``/``cos`` take degrees and round to 10
decimals; the reference does the same. A triangle with a corner at depth <= ``near`` is not
drawn; ``cull backfaces`` = 1 also skips triangles that are counter-clockwise on screen (the BSP
walk already culls in 3D, so it is 0 by default).

What the blocks cost in scratch-vm (blocks executed per frame / per ray / per pixel):
``benchmarks/bench_scratch_vm.py``.
"""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from . import sb3
from .textimage import ALPHABET, VOLUMES
from . import blocks as B
from .blocks import add, div, eq, floor, gt, item, lt, mod, mul, not_, or_, and_, sub, var

# Empty costume for the reader (2x2 transparent; one asset shared by every alphabet costume).
EMPTY_SVG = sb3.SPRITE_SVG

BIG = 1e300  # "no limit" for the ray's farthest distance (docs/formats-bvh.md)


# --------------------------------------------------------------------------- specs
@dataclass
class MeshNames:
    verts: str = "verts"
    tris: str = "tris"
    mat_colors: str | None = "mat colors"
    tri_colors: str | None = "tri colors"


@dataclass
class BVHSpec:
    """The BVH lists (docs/formats-bvh.md). ``bary`` is the inside test's (low, high) bound on the
    barycentrics, the one the Python reference uses (``bake.bvh.traverse.BARY_LO/HI``; the BVH
    stage puts it in its artefact), so the blocks find exactly the reference's hits."""

    bary: tuple[float, float]
    layout: str = "quantised"  # binary | wide4 | quantised
    bits: int = 6
    nodes: str = "bvh nodes"
    tris: str = "bvh tris"
    ids: str = "bvh tri ids"


@dataclass
class BSPSpec:
    """The BSP lists (``bake/bsp/encode.py``, docs/formats-bsp.md) and which materials are
    two-sided (1-based material -> drawn from both sides; written into the sprite as the list
    ``mat two-sided``, since the lists themselves do not say)."""

    nodes: str = "bsp nodes"
    planes: str = "bsp planes"
    two_sided: list[int] = field(default_factory=list)  # per material: 1 two-sided, 0 not


@dataclass
class Camera:
    x: float = 0.0
    y: float = 0.0
    z: float = -5.0
    yaw: float = 0.0
    pitch: float = 0.0
    focal: float = 300.0
    near: float = 0.01


@dataclass
class ReaderSpec:
    """What the reader sprite reads. ``mesh=None`` leaves out the mesh blocks and the renderer;
    ``bvh=None`` the ray query; ``textimage=False`` the decoder (and its 94 costumes)."""

    mesh: MeshNames | None = field(default_factory=MeshNames)
    bvh: BVHSpec | None = None
    bsp: BSPSpec | None = None
    textimage: bool = True
    renderer: bool = True
    camera: Camera = field(default_factory=Camera)
    cull_backfaces: bool = False
    pen_size: float = 2.0
    loader: Any = None  # a bake.scratch.loader.LoaderSpec: unpack packed lists at the green flag

    def lists_read(self) -> list[str]:
        """The data lists the blocks read (they must exist in the project)."""
        out: list[str] = []
        if self.mesh:
            out += [self.mesh.verts, self.mesh.tris]
            out += [n for n in (self.mesh.mat_colors, self.mesh.tri_colors) if n]
        if self.bvh:
            out += [self.bvh.nodes, self.bvh.tris, self.bvh.ids]
        if self.bsp and self.mesh:
            out += [self.bsp.nodes, self.bsp.planes]
        if self.loader:
            out += [self.loader.packed]
        return out


# --------------------------------------------------------------------------- python mirrors
def scratch_sin(deg: float) -> float:
    """Scratch's ``sin`` of degrees: ``parseFloat(Math.sin(pi * n / 180).toFixed(10))``
    (scratch3_operators.js); ``toFixed`` rounds the exact binary value half away from zero."""
    return _to_fixed10(math.sin((math.pi * float(deg)) / 180))


def scratch_cos(deg: float) -> float:
    return _to_fixed10(math.cos((math.pi * float(deg)) / 180))


def _to_fixed10(x: float) -> float:
    return float(Decimal(x).quantize(Decimal("1e-10"), rounding=ROUND_HALF_UP))


def _sc(deg: float) -> tuple[float, float]:
    return scratch_sin(deg), scratch_cos(deg)


def project(verts: np.ndarray, cam: Camera) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Screen x, y and depth of ``(N, 3)`` vertices, with exactly the reader's arithmetic."""
    sy_, cy_ = _sc(cam.yaw)
    sp_, cp_ = _sc(cam.pitch)
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    dx = v[:, 0] - cam.x
    dy = v[:, 1] - cam.y
    dz = v[:, 2] - cam.z
    x1 = dx * cy_ - dz * sy_
    z1 = dx * sy_ + dz * cy_
    y2 = dy * cp_ - z1 * sp_
    z2 = dy * sp_ + z1 * cp_
    with np.errstate(divide="ignore", invalid="ignore"):
        px = (cam.focal * x1) / z2
        py = (cam.focal * y2) / z2
    return px, py, z2


# --------------------------------------------------------------------------- building
class _Reader:
    def __init__(self, spec: ReaderSpec, scope_lists: dict[str, str], stage_lists: dict[str, str],
                 target: str):
        self.spec = spec
        self.target = target
        self.vars: dict[str, Any] = {}
        self.local_lists: dict[str, list] = {}
        self.scope_lists = dict(scope_lists)
        self.stage_lists = dict(stage_lists)
        self.procs: list[tuple[str, list[str], list[B.Node]]] = []

    def v(self, name: str, init: Any = 0) -> B.VarRef:
        self.vars.setdefault(name, init)
        return var(name)

    def lst(self, name: str, init: Sequence[Any] = ()) -> str:
        if name not in self.scope_lists and name not in self.stage_lists:
            self.local_lists.setdefault(name, list(init))
        return name

    def set(self, name: str, value: Any) -> B.Node:
        self.vars.setdefault(name, 0)
        return B.set_var(name, value)

    def change(self, name: str, value: Any) -> B.Node:
        self.vars.setdefault(name, 0)
        return B.change_var(name, value)

    def define(self, proccode: str, args: list[str], body: list[B.Node]) -> None:
        self.procs.append((proccode, args, body))


def _le(a, b) -> B.Boolean:
    """a <= b  (Scratch has no <=: not (a > b))."""
    return not_(gt(a, b))


def _ge(a, b) -> B.Boolean:
    return not_(lt(a, b))


# ---- mesh
def _mesh_blocks(r: _Reader) -> None:
    m = r.spec.mesh
    assert m is not None
    r.lst(m.verts)
    r.lst(m.tris)
    t = B.arg("t")
    base = r.v("_b")
    body: list[B.Node] = [r.set("_b", mul(4, sub(t, 1)))]
    for k in (1, 2, 3):
        body.append(r.set(f"_i{k}", mul(3, sub(item(add(base, k), m.tris), 1))))
    for k in (1, 2, 3):
        ik = r.v(f"_i{k}")
        for a, axis in enumerate("xyz"):
            body.append(r.set(f"{axis}{k}", item(add(ik, a + 1), m.verts)))
    if m.tri_colors:
        r.lst(m.tri_colors)
        body.append(r.set("tri color", item(t, m.tri_colors)))
    elif m.mat_colors:
        r.lst(m.mat_colors)
        body.append(r.set("tri color", item(item(add(base, 4), m.tris), m.mat_colors)))
    else:
        body.append(r.set("tri color", 0))
    r.define("load triangle %s", ["t"], body)


# ---- camera, projection, pen renderer
def _camera_blocks(r: _Reader) -> None:
    m = r.spec.mesh
    cam = r.spec.camera
    for n, val in (("cam x", cam.x), ("cam y", cam.y), ("cam z", cam.z), ("cam yaw", cam.yaw),
                   ("cam pitch", cam.pitch), ("focal", cam.focal), ("near", cam.near)):
        r.v(n, val)
    r.v("cull backfaces", 1 if r.spec.cull_backfaces else 0)
    r.define("set camera %s %s %s %s %s", ["x", "y", "z", "yaw", "pitch"], [
        r.set("cam x", B.arg("x")), r.set("cam y", B.arg("y")), r.set("cam z", B.arg("z")),
        r.set("cam yaw", B.arg("yaw")), r.set("cam pitch", B.arg("pitch")),
    ])
    px, py, pz = r.lst("_px"), r.lst("_py"), r.lst("_pz")
    i = r.v("_i")
    dx, dy, dz, x1, z1, y2, z2 = (r.v(n) for n in ("_dx", "_dy", "_dz", "_x1", "_z1", "_y2", "_z2"))
    syw, cyw, spt, cpt = (r.v(n) for n in ("_syaw", "_cyaw", "_spitch", "_cpitch"))
    r.define("project vertices", [], [
        r.set("_syaw", B.mathop("sin", var("cam yaw"))), r.set("_cyaw", B.mathop("cos", var("cam yaw"))),
        r.set("_spitch", B.mathop("sin", var("cam pitch"))), r.set("_cpitch", B.mathop("cos", var("cam pitch"))),
        B.delete_all(px), B.delete_all(py), B.delete_all(pz),
        r.set("_i", 1),
        B.repeat(div(B.list_length(m.verts), 3), [
            r.set("_dx", sub(item(i, m.verts), var("cam x"))),
            r.set("_dy", sub(item(add(i, 1), m.verts), var("cam y"))),
            r.set("_dz", sub(item(add(i, 2), m.verts), var("cam z"))),
            r.set("_x1", sub(mul(dx, cyw), mul(dz, syw))),
            r.set("_z1", add(mul(dx, syw), mul(dz, cyw))),
            r.set("_y2", sub(mul(dy, cpt), mul(z1, spt))),
            r.set("_z2", add(mul(dy, spt), mul(z1, cpt))),
            B.add_to(px, div(mul(var("focal"), x1), z2)),
            B.add_to(py, div(mul(var("focal"), y2), z2)),
            B.add_to(pz, z2),
            r.change("_i", 3),
        ]),
    ])

    # draw triangle (t): scanline fill of the projected triangle, rows at whole y, clipped to the
    # stage (the sprite is fenced to the stage in the editor, so we never move it far outside)
    t = B.arg("t")
    ax, ay, bx, by, cx, cy, tmp = (r.v(n) for n in ("_ax", "_ay", "_bx", "_by", "_cx", "_cy", "_tmp"))
    ry, xl, xs, x0, xe = (r.v(n) for n in ("_ry", "_xl", "_xs", "_x0", "_x1s"))
    b = r.v("_b")

    def swap(p: str, q: str) -> list[B.Node]:
        return [r.set("_tmp", var(p)), r.set(p, var(q)), r.set(q, tmp)]

    def corner(k: int) -> list[B.Node]:
        name = "abc"[k - 1]
        ik = r.v(f"_i{k}")
        return [r.set(f"_i{k}", item(add(b, k), m.tris)),
                r.set(f"_{name}x", item(ik, px)), r.set(f"_{name}y", item(ik, py))]

    near = var("near")
    visible = and_(and_(gt(item(var("_i1"), pz), near), gt(item(var("_i2"), pz), near)),
                   gt(item(var("_i3"), pz), near))
    area = sub(mul(sub(bx, ax), sub(cy, ay)), mul(sub(by, ay), sub(cx, ax)))
    row = [
        # x on the long edge a-c and on the short edge (a-b below b, b-c from b up)
        r.set("_xl", add(ax, div(mul(sub(cx, ax), sub(ry, ay)), sub(cy, ay)))),
        B.if_(lt(ry, by),
              [r.set("_xs", add(ax, div(mul(sub(bx, ax), sub(ry, ay)), sub(by, ay))))],
              [B.if_(eq(cy, by), [r.set("_xs", bx)],
                     [r.set("_xs", add(bx, div(mul(sub(cx, bx), sub(ry, by)), sub(cy, by))))])]),
        B.if_(lt(xs, xl), swap("_xs", "_xl")),
        r.set("_x0", xl), r.set("_x1s", xs),
        B.if_(lt(x0, -240), [r.set("_x0", -240)]),
        B.if_(gt(xe, 240), [r.set("_x1s", 240)]),
        B.if_(_le(x0, xe), [B.goto_xy(x0, ry), B.pen_down(), B.goto_xy(xe, ry), B.pen_up()]),
        r.change("_ry", 1),
    ]
    r.define("draw triangle %s", ["t"], [
        r.set("_b", mul(4, sub(t, 1))),
        *corner(1), *corner(2), *corner(3),
        B.if_(visible, [
            B.if_(or_(eq(var("cull backfaces"), 0), lt(area, 0)), [
                # sort the corners by y: a lowest, c highest
                B.if_(lt(by, ay), swap("_ax", "_bx") + swap("_ay", "_by")),
                B.if_(lt(cy, by), swap("_bx", "_cx") + swap("_by", "_cy")),
                B.if_(lt(by, ay), swap("_ax", "_bx") + swap("_ay", "_by")),
                B.if_(gt(cy, ay), [
                    r.set("_ry", B.mathop("ceiling", ay)),
                    B.if_(lt(ry, -180), [r.set("_ry", -180)]),
                    r.set("_ytop", B.mathop("floor", cy)),
                    B.if_(gt(var("_ytop"), 180), [r.set("_ytop", 180)]),
                    B.if_(_le(ry, var("_ytop")), [
                        _load_color(r, t),
                        B.repeat(add(sub(var("_ytop"), ry), 1), row),
                    ]),
                ]),
            ]),
        ]),
    ])

    order = r.lst("draw order")
    k = r.v("_k")
    walk: list[B.Node]
    if r.spec.bsp is not None:
        _bsp_blocks(r)
        walk = [B.call("bsp walk %s %s %s", var("cam x"), var("cam y"), var("cam z"))]
    else:
        walk = [B.delete_all(order), r.set("_k", 1),
                B.repeat(div(B.list_length(m.tris), 4), [B.add_to(order, k), r.change("_k", 1)])]
    r.define("render", [], [
        B.hide(), B.pen_up(), B.pen_clear(), B.set_pen_size(r.spec.pen_size),
        B.call("project vertices"),
        *walk,
        r.set("_k", 1),
        B.repeat(B.list_length(order), [B.call("draw triangle %s", item(k, order)), r.change("_k", 1)]),
    ])


# ---- BSP
def _bsp_blocks(r: _Reader) -> None:
    """``bsp walk (x) (y) (z)``: the painter's order for an eye, into ``draw order`` (back to
    front), single-sided triangles facing away left out. The walk of docs/formats-bsp.md with an
    explicit stack (a record's item number to visit, or its negated item number for "draw its
    coplanar triangles now"), with the arithmetic of its Python model
    ``bake.bsp.traverse.draw_order``: the plane test is ``((a*x + b*y) + c*z) - d >= 0``. The lists
    do not say which materials are two-sided, so the sprite carries ``mat two-sided``."""
    m, s = r.spec.mesh, r.spec.bsp
    nodes, planes = r.lst(s.nodes), r.lst(s.planes)
    order, stack = r.lst("draw order"), r.lst("_bsp stack")
    two = r.lst("mat two-sided", list(s.two_sided))
    ex, ey, ez = r.v("_ex"), r.v("_ey"), r.v("_ez")
    rr, T, bb, first, na, nd, nb = (r.v(x) for x in ("_r", "_T", "_B", "_first", "_nA", "_nD", "_nB"))
    front, near, far, faces, t = r.v("_front"), r.v("_near"), r.v("_far"), r.v("_faces"), r.v("_bt")
    pl = r.v("_pl")

    # eye in front of (or on) the plane of split record (r): a*x + b*y + c*z - d >= 0
    r.define("_bsp side %s", ["r"], [
        r.set("_pl", mul(sub(B.abs_(item(B.arg("r"), nodes)), 2), 4)),
        B.if_(lt(sub(add(add(mul(item(add(pl, 1), planes), ex), mul(item(add(pl, 2), planes), ey)),
                         mul(item(add(pl, 3), planes), ez)), item(add(pl, 4), planes)), 0),
              [r.set("_front", 0)], [r.set("_front", 1)]),
    ])
    # triangle (t) faces the eye, or its material is two-sided
    P = [[r.v(f"_b{c}{a}") for a in "xyz"] for c in range(3)]
    u = [r.v(f"_bu{a}") for a in "xyz"]
    w = [r.v(f"_bw{a}") for a in "xyz"]
    nv = [r.v(f"_bn{a}") for a in "xyz"]
    tb = r.v("_tb4")
    faces_body: list[B.Node] = [r.set("_tb4", mul(sub(B.arg("t"), 1), 4))]
    faces_body.append(B.if_(eq(item(item(add(tb, 4), m.tris), two), 1), [r.set("_faces", 1)], [
        *[r.set(f"_b{c}{a}", item(add(mul(sub(item(add(tb, c + 1), m.tris), 1), 3), k + 1), m.verts))
          for c in range(3) for k, a in enumerate("xyz")],
        *[r.set(f"_bu{a}", sub(P[1][k], P[0][k])) for k, a in enumerate("xyz")],
        *[r.set(f"_bw{a}", sub(P[2][k], P[0][k])) for k, a in enumerate("xyz")],
        r.set("_bnx", sub(mul(u[1], w[2]), mul(u[2], w[1]))),
        r.set("_bny", sub(mul(u[2], w[0]), mul(u[0], w[2]))),
        r.set("_bnz", sub(mul(u[0], w[1]), mul(u[1], w[0]))),
        B.if_(gt(add(add(mul(nv[0], sub(ex, P[0][0])), mul(nv[1], sub(ey, P[0][1]))), mul(nv[2], sub(ez, P[0][2]))), 0),
              [r.set("_faces", 1)], [r.set("_faces", 0)]),
    ]))
    r.define("_bsp faces %s", ["t"], faces_body)
    # draw triangles first .. first + n - 1 (culled: only those facing the eye)
    r.define("_bsp draw %s %s %s", ["first", "n", "culled"], [
        r.set("_bt", B.arg("first")),
        B.repeat(B.arg("n"), [
            B.if_(eq(B.arg("culled"), 1), [
                B.call("_bsp faces %s", t),
                B.if_(eq(faces, 1), [B.add_to(order, t)]),
            ], [B.add_to(order, t)]),
            r.change("_bt", 1),
        ]),
    ])
    item_r = lambda k: item(add(rr, k), nodes)  # noqa: E731
    deferred = [
        r.set("_r", sub(0, rr)),
        r.set("_T", item(rr, nodes)),
        B.if_(eq(T, 1), [B.call("_bsp draw %s %s %s", add(item_r(1), item_r(2)), item_r(3), 1)], [
            r.set("_first", item_r(2)), r.set("_nA", item_r(3)),
            B.if_(gt(T, 0), [r.set("_nD", 0), r.set("_nB", item_r(4))],
                  [r.set("_nD", item_r(4)), r.set("_nB", item_r(5))]),
            B.call("_bsp side %s", rr),
            B.if_(eq(front, 1), [B.call("_bsp draw %s %s %s", first, add(na, nd), 0)],
                  [B.call("_bsp draw %s %s %s", add(first, na), add(nd, nb), 0)]),
        ]),
    ]
    visit = [
        r.set("_T", item(rr, nodes)),
        B.if_(eq(T, 0), [B.call("_bsp draw %s %s %s", item_r(1), item_r(2), 1)], [
            B.if_(eq(T, 1), [
                B.call("_bsp draw %s %s %s", item_r(1), item_r(2), 1),
                B.add_to(stack, sub(0, rr)), B.add_to(stack, add(rr, 4)),
            ], [
                r.set("_B", item_r(1)),
                B.if_(lt(bb, 0), [r.set("_near", 0)],  # _near holds the front child for now
                      [B.if_(gt(T, 0), [r.set("_near", add(rr, 5))], [r.set("_near", add(rr, 6))])]),
                B.if_(gt(bb, 0), [r.set("_far", bb)], [B.if_(lt(bb, 0), [r.set("_far", sub(0, bb))],
                                                               [r.set("_far", 0)])]),
                B.call("_bsp side %s", rr),
                B.if_(eq(front, 0), [  # eye behind: the back child is near
                    r.set("_T", near), r.set("_near", far), r.set("_far", T)]),
                B.if_(gt(near, 0), [B.add_to(stack, near)]),
                B.add_to(stack, sub(0, rr)),
                B.if_(gt(far, 0), [B.add_to(stack, far)]),
            ]),
        ]),
    ]
    r.define("bsp walk %s %s %s", ["x", "y", "z"], [
        r.set("_ex", B.arg("x")), r.set("_ey", B.arg("y")), r.set("_ez", B.arg("z")),
        B.delete_all(order), B.delete_all(stack),
        B.if_(gt(B.list_length(nodes), 0), [B.add_to(stack, 1)]),
        B.repeat_until(eq(B.list_length(stack), 0), [
            r.set("_r", item("last", stack)), B.delete_item(stack, "last"),
            B.if_(lt(rr, 0), deferred, visit),
        ]),
    ])


def _load_color(r: _Reader, t: B.Node) -> B.Node:
    m = r.spec.mesh
    if m.tri_colors:
        return B.set_pen_color(item(t, m.tri_colors))
    if m.mat_colors:
        return B.set_pen_color(item(item(add(var("_b"), 4), m.tris), m.mat_colors))
    return B.set_pen_color("#808080")


# ---- BVH
def _bvh_blocks(r: _Reader) -> None:
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
    box = r.lst("_bvh box", [0] * 6)
    r.define("_bvh box at %s", ["p"], box_test(lambda k: item(add(B.arg("p"), sub(k, 1)), nodes)))
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


def _bvh_wide_walk(r: _Reader, s: BVHSpec, p: B.VarRef) -> list[B.Node]:
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


# ---- TextImage
def _textimage_blocks(r: _Reader) -> None:
    s, pos, c = r.v("_ts", ""), r.v("_tp"), r.v("_tc")
    out = r.lst("ti colors")
    hdr = r.lst("_ti header")
    px, alpha = r.lst("_ti px"), r.lst("_ti a")
    table = r.lst("_ti hash")
    vols: list[int] = []
    for (oy, ou, ov), _dims in VOLUMES:
        vols += [oy, ou, ov]
    vol = r.lst("_ti volumes", vols)
    W, H = r.v("ti width"), r.v("ti height")
    tok, i, k, rest = r.v("_tok", ""), r.v("_ti i"), r.v("_ti k"), r.v("_rest", "")
    end, cnt, vf = r.v("_tend"), r.v("_tcount"), r.v("_tvf")
    op, op2, rn, val = r.v("_top"), r.v("_top2"), r.v("_trn"), r.v("_tval")
    R, G, Bv = r.v("_tr"), r.v("_tg"), r.v("_tb")
    dY, dU, dV, idx = r.v("_tdy"), r.v("_tdu"), r.v("_tdv"), r.v("_tidx")
    d0, d1, d2 = r.v("_td0"), r.v("_td1"), r.v("_td2")

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


# --------------------------------------------------------------------------- public API
def reader_target(spec: ReaderSpec, name: str = "Reader", *, local_lists: dict[str, list] | None = None,
                  stage_lists: dict[str, str] | Sequence[str] = (), layer_order: int = 1,
                  demo: bool = False) -> sb3.Target:
    """The reader sprite as a :class:`bake.scratch.sb3.Target`.

    ``local_lists``: data lists stored in the sprite itself (name -> items), e.g. for a
    .sprite3. ``stage_lists``: names (or name -> id) of data lists that live on the stage.
    Every list in ``spec.lists_read()`` must be in one of them. ``demo`` adds a green-flag
    script that renders the model from the default camera."""
    local_lists = dict(local_lists or {})
    stage_ids = dict(stage_lists) if isinstance(stage_lists, dict) else \
        {n: sb3.stable_id("Stage", "list", n) for n in stage_lists}
    missing = [n for n in spec.lists_read() if n not in local_lists and n not in stage_ids]
    if missing:
        raise B.BlockError(f"the reader reads lists that are not in the project: {', '.join(missing)}")
    r = _Reader(spec, {n: sb3.stable_id(name, "list", n) for n in local_lists}, stage_ids, name)
    if spec.mesh:
        _mesh_blocks(r)
        if spec.renderer:
            _camera_blocks(r)
    if spec.bvh:
        _bvh_blocks(r)
    if spec.textimage:
        _textimage_blocks(r)
    if spec.loader:
        from . import loader

        loader.add_loader(r, spec.loader)
    all_local = dict(local_lists)
    for k, v in r.local_lists.items():
        if k in all_local:
            raise B.BlockError(f"list {k!r} is used by the reader itself")
        all_local[k] = v
    scope = B.Scope(name, variables=list(r.vars), lists=list(all_local), stage_lists=stage_ids)
    b = B.Builder(scope)
    for proccode, args, body in r.procs:
        b.define(proccode, args, body)
    unpack = [B.call("unpack lists")] if spec.loader else []
    if demo and spec.mesh and spec.renderer:
        cam = spec.camera
        draw = [B.call("set camera %s %s %s %s %s", cam.x, cam.y, cam.z, cam.yaw, cam.pitch), B.call("render")]
        b.when_flag(unpack + ([B.if_(eq(var("unpack error"), ""), draw)] if unpack else draw))
    elif unpack:
        b.when_flag(unpack)
    costumes = []
    if spec.textimage or spec.loader:
        asset = sb3.Asset(EMPTY_SVG, "svg")
        costumes = [sb3.Costume(ch, asset, 1, (1.0, 1.0)) for ch in ALPHABET]
    return sb3.Target(name, lists=all_local, variables=dict(r.vars), costumes=costumes,
                      blocks=b.build(), layer_order=layer_order, visible=False)
