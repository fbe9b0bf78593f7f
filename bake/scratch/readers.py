"""The reference reader sprite: custom blocks, generated here, that read scratch-bake's lists.

Only what the bake wrote is generated (the spec, built by ``bake.scratch.project.reader_spec``
from the lists, decides): the renderer when there is a mesh, the BSP walk when there is a BSP
tree, the ray query for the one BVH layout written (``reader_bvh.py``), the TextImage decoder
and its 94 costumes only when TextImage strings were written (``reader_textimage.py``). Other
modules add parts through :attr:`ReaderSpec.parts` (a callable given the :class:`ReaderBuilder`).

Authors can copy these blocks into their own engines. Every block is a custom block with "run
without screen refresh" (warp) on. Outputs go to variables and lists of the sprite; temporaries
start with ``_``. Each reader is proven in the real Scratch VM against the Python reference named
in the last column (tests/scratch/), and the whole project in TurboWarp's player (tests/player/).

==========================================  ===================================  ======================
custom block                                what it does                         Python reference
==========================================  ===================================  ======================
(variables)                                 the camera: ``cam x``, ``cam y``,
                                            ``cam z``, ``cam yaw``, ``cam pitch``
                                            (degrees), ``focal``, ``near``
``project vertices``                        every vertex into the lists ``_px    :func:`project`,
                                            _py _pz`` (screen x, y, depth over   :func:`safe_frame`
                                            focal);
                                            ``_safe`` true when the whole model is
                                            in front of ``near`` and where the
                                            pen can draw
``bsp walk``                                painter's order (back to front) for  ``bake.bsp.traverse.
                                            the eye at ``cam x``, ``cam y``,     draw_ranges``
                                            ``cam z``: ``(first, n)`` pairs of
                                            triangle ranges into ``draw ranges``
``render``                                  erase all, project, walk (the whole  painter's raster
                                            list without a BSP tree), fill every
                                            triangle that faces the camera on
                                            screen with the pen, in that order
``fill triangle``                           (called by ``render``) the fan of    (the filler test,
                                            the triangle whose projected corners tests/scratch)
                                            ``render`` read (``_ax .. _by``, c at
                                            ``_b``), in its colour
``load triangle (t)``                       (.sprite3, into-project) corners of  the mesh lists
                                            triangle t into ``x1 y1 z1 .. z3``,
                                            its colour into ``tri color``
``bvh ray (ox) (oy) (oz) (dx) (dy) (dz)``   closest hit: ``hit tri`` (scene      ``bake.bvh.traverse.
                                            triangle; 0 on a miss), ``hit t``    trace_one``
                                            (-1 on a miss), ``hit u``, ``hit
                                            v``, ``hit slot``
``camera ray (sx) (sy)``                    (``export.green_flag = "bvh"``) the  ``bake.outputs.
                                            camera's ray through stage point     bvh_view.view_rays``
                                            (sx, sy): ``ray dx``, ``ray dy``,
                                            ``ray dz`` (origin ``cam x/y/z``)
``bvh view``                                (the same) one ``bvh ray`` per cell  ``bake.outputs.
                                            of ``bvh cell`` stage pixels, a pen  bvh_view.bvh_view``
                                            dot of the hit triangle's colour
``decode textimage (text)``                 TextImage v0 -> ``ti colors``,       ``bake.textures.
                                            ``ti width``, ``ti height``          textimage.decode``
==========================================  ===================================  ======================

The camera model (the pen renderer and :func:`project` below, which mirrors it bit for bit):
the frame is x right, y up, z into the screen; the camera at ``(cx, cy, cz)`` turned ``yaw``
degrees about y (positive turns right) and then ``pitch`` degrees about its x axis (positive looks
up). With ``d = p - c``: ``x' = dx*cos(yaw) - dz*sin(yaw)``, ``z' = dx*sin(yaw) + dz*cos(yaw)``,
``y'' = dy*cos(pitch) - z'*sin(pitch)``, ``z'' = dy*sin(pitch) + z'*cos(pitch)``; the stage
position is ``focal * (x', y'') / z''``, computed as ``((dx*cos(yaw) - dz*sin(yaw)) / w,
(dy*cos(pitch) - z'*sin(pitch)) / w)`` with ``w = z'' / focal = dy*(sin(pitch)/focal) +
z'*(cos(pitch)/focal)`` (``_pz`` keeps ``w``). Scratch's ``sin``/``cos`` take degrees
and round to 10 decimals; the reference does the same. ``bake.render.Camera.yaw_pitch`` is the
same camera for the numpy rasterizer (report.html's "green flag" preview).

The frame (``render``): a triangle is drawn when it is clockwise on the stage (it faces the camera:
``((bx-ax)*(cy-ay)) - ((by-ay)*(cx-ax)) < 0`` on the projected corners; two-sided materials are
drawn either way) and its corners are *usable*: deeper than ``near`` and within 4000 pixels of the
stage centre in x and y (the sprite wears a transparent 8192 x 8192 costume, so Scratch's
fencing, which keeps a costume's bounds on the stage, never moves the pen there; lines beyond
the stage are simply not seen). A frame is *safe* when the model's bounding sphere (baked in as
numbers) is in front of ``near`` and its picture within those 4000 pixels; only an unsafe frame
tests each vertex (an unusable one's screen x in ``_px`` becomes 1e9, and a triangle whose corners'
``|x|`` sum to more than 3 x 4000 is not drawn). The pen's colour is set only when it changes
(``_pc``: the last colour set this frame). With pen size ``w`` (``ReaderSpec.pen_size``, 2.5) the
filler draws a fan of ``k = ceiling(L / (w - 1))`` lines from the first corner ``a`` to the middles
``q1 .. qk`` of ``k`` equal pieces of the opposite edge ``b-c`` (``L`` its length), walked ``q1, a,
q2, q3, a, q4, q5, a, ...``: ``floor((3k - 1) / 2)`` lines. No point of the triangle is farther
than ``(w - 1) / 2`` from a line (a point on the way from ``a`` to a point ``x`` of ``b-c``, a
fraction ``s`` along, is within ``s |x - q|`` of the line to the nearest ``q``, and ``|x - q| <= L /
2k <= (w - 1) / 2``), so the pen, ``w / 2`` wide on each side, paints everything within half a
pixel of the triangle, and no line leaves it: no outline is needed. (Pen size 2 needs a line per
pixel of ``L``, 2.5 one per 1.5 pixels; the wider pen reaches a quarter of a pixel farther out of
the triangle, which the player suite's agreement with the preview bounds.) The BSP stage puts each triangle's corner opposite its shortest edge first
(``bake.bsp.stage.apex_first``), so ``L`` is short and the fan has few lines (one for a needle,
``L <= w - 1``); one and two lines are drawn without the loop.

What the blocks cost (blocks executed per frame in scratch-vm, seconds in TurboWarp):
``benchmarks/bench_player.py``; per ray and per pixel: ``benchmarks/bench_scratch_vm.py``.
"""

from __future__ import annotations

import math
from decimal import ROUND_HALF_UP, Decimal
from dataclasses import dataclass, field
from typing import Any, Callable, Sequence

import numpy as np

from . import sb3
from . import blocks as B
from .blocks import add, div, eq, gt, item, lt, mul, not_, and_, sub, var
from .reader_bvh import BIG, bvh_part, bvh_view_part
from .reader_mesh import colour as _colour, index as _index, triangle_walk as _triangle_walk
from .reader_texture import TextureSpec, cell_fill, load_blocks
from .reader_textimage import alphabet_costumes, textimage_part

__all__ = ["MeshNames", "BVHSpec", "BSPSpec", "Camera", "ReaderSpec", "ReaderBuilder", "reader_target",
           "project", "scratch_sin", "scratch_cos", "bounding_sphere", "safe_frame", "drawn", "BIG"]

#: characters of the reader's own variable and list ids (Scratch's are 20; ours appear in every
#: variable block, so short ids keep the sprite small; derived from the names, never random, and
#: unique within the sprite: :func:`bake.scratch.sb3.data_ids`)
VAR_ID_LENGTH = 4


# --------------------------------------------------------------------------- specs
@dataclass
class MeshNames:
    """The mesh lists the renderer reads, in the layout the bake wrote (bake/scratch/layout.py):
    ``verts`` one list (x, y, z interleaved) or one per component (x, y, z); ``tris`` one list
    (v1, v2, v3, material) or four; ``index_base`` the first vertex and material number (1 or 0);
    ``soup``: ``verts`` holds each triangle's corners (one list of 9 numbers a triangle, or x, y, z
    per corner, or 9 lists x1 .. z3) and ``tris`` its material number."""

    verts: str | tuple[str, ...] = "verts"
    tris: str | tuple[str, ...] = "tris"
    mat_colors: str | None = "mat colors"
    tri_colors: str | None = "tri colors"
    two_sided: str = "mat two-sided"  # read from the project when the bake wrote it, else the sprite's own
    index_base: int = 1
    soup: bool = False

    def data_lists(self) -> list[str]:
        """The vertex and triangle lists, one name each."""
        return [*_names(self.verts), *_names(self.tris)]


def _names(value: str | Sequence[str]) -> list[str]:
    return [value] if isinstance(value, str) else list(value)


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
    """The BSP lists (``bake/bsp/encode.py``, docs/formats-bsp.md)."""

    nodes: str = "bsp nodes"
    planes: str = "bsp planes"


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
    """What the reader sprite reads and holds. ``mesh=None`` leaves out the mesh blocks and the
    renderer; ``bvh=None`` the ray query; ``textimage=False`` the decoder (and its 94 costumes).
    ``two_sided``: per material (1-based order), 1 when drawn from both sides (the sprite keeps it
    as the list ``mat two-sided`` only when some material is). ``bounds``: the model's bounding
    sphere ``(centre, radius)`` (:func:`bounding_sphere`; None: every frame is unsafe).
    ``bvh_view``: a cell size in stage pixels adds ``camera ray`` and ``bvh view`` (reader_bvh.py;
    with a mesh, its renderer and a BVH), which the green flag then calls instead of ``render``.
    ``helpers``: also ``load triangle`` (for authors copying blocks). ``parts``: more generators,
    each called with the :class:`ReaderBuilder` after the built-in ones."""

    mesh: MeshNames | None = field(default_factory=MeshNames)
    bvh: BVHSpec | None = None
    bsp: BSPSpec | None = None
    textimage: bool = False
    renderer: bool = True
    camera: Camera = field(default_factory=Camera)
    two_sided: list[int] = field(default_factory=list)
    bounds: tuple[tuple[float, float, float], float] | None = None
    helpers: bool = False
    pen_size: float = 2.5  # the flat filler's: its fan's lines are pen_size - 1 apart at b-c
    bvh_view: int | None = None
    parts: list[Callable[["ReaderBuilder"], None]] = field(default_factory=list)
    # the textured filler (reader_texture.py): with it, every triangle is drawn by cells
    texture: TextureSpec | None = None

    def lists_read(self) -> list[str]:
        """The data lists the blocks read (they must exist in the project)."""
        out: list[str] = []
        if self.mesh:
            out += self.mesh.data_lists()
            out += [n for n in (self.mesh.mat_colors, self.mesh.tri_colors) if n]
        if self.bvh:
            out += [self.bvh.nodes, self.bvh.tris, self.bvh.ids]
        if self.bsp and self.mesh:
            out += [self.bsp.nodes, self.bsp.planes]
        if self.texture and self.mesh and self.renderer:
            out += self.texture.lists_read()
        out += [n for p in self.parts for n in getattr(p, "lists_read", lambda: [])()]
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
    """Screen x, y and depth over focal (``_pz``: depth / ``focal``) of ``(N, 3)`` vertices, with
    exactly the reader's arithmetic."""
    sy_, cy_ = _sc(cam.yaw)
    sp_, cp_ = _sc(cam.pitch)
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    dx = v[:, 0] - cam.x
    dy = v[:, 1] - cam.y
    dz = v[:, 2] - cam.z
    f = float(cam.focal)
    z1 = dx * sy_ + dz * cy_
    w = dy * (sp_ / f) + z1 * (cp_ / f)  # depth / focal: the screen's scale is in the divisor
    with np.errstate(divide="ignore", invalid="ignore"):
        px = (dx * cy_ - dz * sy_) / w
        py = (dy * cp_ - z1 * sp_) / w
    return px, py, w


#: how far from the stage centre the pen may go: Scratch keeps a sprite's costume bounds on the
#: stage ("fencing"), so the renderer wears a transparent 8192 x 8192 costume (FENCE_SVG), which
#: lets it reach 4096 + 240 - 15 pixels right or left (and as far up or down) before fencing moves it
SAFE_X = SAFE_Y = 4000
UNUSABLE_X = 1e9  # an unusable vertex's screen x in an unsafe frame (far beyond 3 * SAFE_X)
FENCE = 8192
FENCE_SVG = (f'<svg xmlns="http://www.w3.org/2000/svg" width="{FENCE}" height="{FENCE}" '
             f'viewBox="0 0 {FENCE} {FENCE}"></svg>').encode()


def bounding_sphere(verts: Sequence[float] | np.ndarray) -> tuple[tuple[float, float, float], float]:
    """A sphere around the model for the safe-frame test: the bounding box's centre, the distance
    to the farthest vertex, both rounded outwards to 6 significant digits (they become literals)."""
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    if not len(v):
        return (0.0, 0.0, 0.0), 0.0
    c = np.array([float(f"{x:.6g}") for x in (v.min(0) + v.max(0)) / 2])
    rad = float(np.sqrt(((v - c) ** 2).sum(1)).max())
    rad = float(f"{rad * (1 + 1e-5) + 1e-300:.6g}")
    return (float(c[0]), float(c[1]), float(c[2])), rad


def usable(px, py, pz, near: float, focal: float) -> np.ndarray:
    """Per vertex (``pz``: depth / focal, as :func:`project` gives it): in front of ``near`` and
    where the pen can go (the reader's test)."""
    return (pz > near / focal) & (np.abs(px) < SAFE_X) & (np.abs(py) < SAFE_Y)


def safe_frame(cam: Camera, bounds: tuple[tuple[float, float, float], float] | None) -> bool:
    """The reader's ``_safe`` for this camera and bounding sphere (its arithmetic)."""
    if bounds is None:
        return False
    (qx, qy, qz), rad = bounds
    sy_, cy_ = _sc(cam.yaw)
    sp_, cp_ = _sc(cam.pitch)
    dx, dy, dz = qx - cam.x, qy - cam.y, qz - cam.z
    depth = (dy * sp_ + (dx * sy_ + dz * cy_) * cp_) - rad
    return bool(depth > cam.near and cam.focal * (math.sqrt((dx * dx + dy * dy) + dz * dz) + rad) < SAFE_X * depth)


def drawn(verts, tris, cam: Camera, two_sided: Sequence[int] = ()) -> np.ndarray:
    """Per triangle (0-based): does ``render`` fill it (faces the camera on the stage, or is
    two-sided, and every corner usable)? The reader's arithmetic, bit for bit."""
    px, py, pz = project(verts, cam)
    t = np.asarray(tris, np.int64).reshape(-1, 4)
    i = t[:, :3] - 1
    ax, ay, bx, by, cx, cy = px[i[:, 0]], py[i[:, 0]], px[i[:, 1]], py[i[:, 1]], px[i[:, 2]], py[i[:, 2]]
    a = ((bx - ax) * (cy - ay)) - ((by - ay) * (cx - ax))
    two = np.asarray(list(two_sided) + [0], np.int64)[np.clip(t[:, 3] - 1, 0, max(len(two_sided), 0))] == 1 \
        if len(two_sided) else np.zeros(len(t), bool)
    a = np.where(two, -np.abs(a), a)
    ok = usable(px, py, pz, cam.near, cam.focal)
    return (a < 0) & ok[i].all(1)


# --------------------------------------------------------------------------- building
class ReaderBuilder:
    """What a part generator writes into: the sprite's variables, lists and custom blocks.

    ``v(name, init)`` declares a variable of the sprite and returns its reporter; ``lst(name,
    init)`` a list (a data list of the project is used as it is); ``set``/``change`` are the
    variable blocks (declaring the variable); ``define(proccode, args, body)`` adds a custom
    block (warp on); ``at_flag(nodes)`` adds blocks to the green-flag script of the .sb3, which
    runs them before it renders (and renders only if ``flag_guard``, when a part sets one);
    ``has(proccode)`` says whether a block is already defined; ``alphabet = True`` gives the sprite
    the 94 character costumes (costume k + 1 is ``"!" .. "~"``[k], read case-sensitively by
    ``switch costume to (letter)``)."""

    def __init__(self, spec: ReaderSpec, scope_lists: dict[str, str], stage_lists: dict[str, str],
                 target: str):
        self.spec = spec
        self.target = target
        self.vars: dict[str, Any] = {}
        self.local_lists: dict[str, list] = {}
        self.scope_lists = dict(scope_lists)
        self.stage_lists = dict(stage_lists)
        self.procs: list[tuple[str, list[str], list[B.Node]]] = []
        self.flag: list[B.Node] = []
        self.flag_guard: B.Boolean | None = None  # the green flag renders only when this holds
        self.alphabet = False  # a part reads characters through the 94 alphabet costumes
        # the lighter encoding of packed projects (issue 41): minimal alphabet costumes and
        # compact blocks (:class:`bake.scratch.blocks.Builder` ``compact``)
        self.compact = False

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

    def has(self, proccode: str) -> bool:
        return any(p == proccode for p, _, _ in self.procs)

    def at_flag(self, nodes: list[B.Node]) -> None:
        self.flag.extend(nodes)


def _le(a, b) -> B.Boolean:
    """a <= b  (Scratch has no <=: not (a > b))."""
    return not_(gt(a, b))


def _two_sided(spec: ReaderSpec) -> bool:
    return any(int(x) for x in spec.two_sided)


# ---- mesh helper (authors' block)
def _load_triangle(r: ReaderBuilder) -> None:
    m = r.spec.mesh
    t = B.arg("t")
    base = r.v("_b")
    split_verts = not isinstance(m.verts, str)
    body: list[B.Node] = []
    if m.soup:  # _i<k>: where corner k's numbers start (interleaved: the item before them)
        if not split_verts:
            body += [r.set(f"_i{k}", add(mul(9, sub(t, 1)), 3 * (k - 1))) for k in (1, 2, 3)]
        elif len(m.verts) == 3:
            body += [r.set(f"_i{k}", add(mul(3, sub(t, 1)), k)) for k in (1, 2, 3)]
        material = _index(m, item(t, m.tris))
    elif isinstance(m.tris, str):
        body.append(r.set("_b", mul(4, sub(t, 1))))
        for k in (1, 2, 3):
            number = item(add(base, k), m.tris)
            if split_verts:
                body.append(r.set(f"_i{k}", _index(m, number)))
            else:  # the item before vertex v's x: 3 * (v - 1)
                body.append(r.set(f"_i{k}", mul(3, sub(number, 1)) if m.index_base == 1 else mul(3, number)))
        material = _index(m, item(add(base, 4), m.tris))
    else:
        for k in (1, 2, 3):
            number = _index(m, item(t, m.tris[k - 1]))
            body.append(r.set(f"_i{k}", number if split_verts else mul(3, sub(number, 1))))
        material = _index(m, item(t, m.tris[3]))
    for k in (1, 2, 3):
        ik = r.v(f"_i{k}")
        for a, axis in enumerate("xyz"):
            if not split_verts:
                value = item(add(ik, a + 1), m.verts)
            elif len(m.verts) == 9:
                value = item(t, m.verts[3 * (k - 1) + a])
            else:
                value = item(ik, m.verts[a])
            body.append(r.set(f"{axis}{k}", value))
    body.append(r.set("tri color", _colour(r, t, material)))
    r.define("load triangle %s", ["t"], body)


# ---- camera and projection
def _camera_blocks(r: ReaderBuilder) -> None:
    m = r.spec.mesh
    cam = r.spec.camera
    for n, val in (("cam x", cam.x), ("cam y", cam.y), ("cam z", cam.z), ("cam yaw", cam.yaw),
                   ("cam pitch", cam.pitch), ("focal", cam.focal), ("near", cam.near)):
        r.v(n, val)
    px, py, pz = r.lst("_px"), r.lst("_py"), r.lst("_pz")
    i = r.v("_i")
    dx, dy, dz, z1, z2 = (r.v(n) for n in ("_dx", "_dy", "_dz", "_z1", "_z2"))
    syw, cyw, spt, cpt = (r.v(n) for n in ("_syaw", "_cyaw", "_spitch", "_cpitch"))
    near = r.v("near")
    # the points to project, one loop step at a time: (x, y, z) reporters of each, and the step of _i
    V = m.verts
    if isinstance(V, str):  # x, y, z interleaved (a vertex, or a soup's corner, every 3 items)
        nverts = div(B.list_length(V), 3)
        points, step = [(item(i, V), item(add(i, 1), V), item(add(i, 2), V))], 3
    else:  # one list per component: x, y, z (a vertex or a corner), or a soup's x1 .. z3 per triangle
        nverts = B.list_length(V[0])
        points, step = [tuple(item(i, V[3 * c + a]) for a in range(3)) for c in range(len(V) // 3)], 1
    npoints = nverts if len(points) == 1 else B.list_length(px)

    def usable(v):  # vertex v in front of near, and no farther from the centre than the pen may go
        return and_(gt(item(v, pz), div(near, var("focal"))),
                    and_(lt(B.abs_(item(v, px)), SAFE_X), lt(B.abs_(item(v, py)), SAFE_Y)))

    # the safe-frame test: the model's bounding sphere (centre, radius: spec.bounds) is in front of
    # near and its picture within SAFE_X of the centre (_safe: true or false); in an unsafe frame
    # an unusable vertex's screen x becomes UNUSABLE_X, which the filler tests
    (qx, qy, qz), rad = r.spec.bounds if r.spec.bounds is not None else ((0.0, 0.0, 0.0), BIG)
    depth = sub(z2, rad)  # the sphere's nearest depth
    safe = [
        r.set("_dx", sub(qx, var("cam x"))), r.set("_dy", sub(qy, var("cam y"))), r.set("_dz", sub(qz, var("cam z"))),
        r.set("_z2", add(mul(dy, spt), mul(add(mul(dx, syw), mul(dz, cyw)), cpt))),
        # |screen x| <= focal * (distance + radius) / (depth - radius), the same for y
        r.set("_safe", and_(gt(depth, near), lt(mul(var("focal"), add(B.sqrt(add(add(mul(dx, dx), mul(dy, dy)), mul(dz, dz))), rad)),
                                                 mul(SAFE_X, depth)))),
        B.if_(eq(var("_safe"), 0), [
            r.set("_i", 1),
            B.repeat(npoints, [B.if_(not_(usable(i)), [B.replace_item(px, i, UNUSABLE_X)]), r.change("_i", 1)]),
        ]),
    ]
    r.define("project vertices", [], [
        r.set("_syaw", B.mathop("sin", var("cam yaw"))), r.set("_cyaw", B.mathop("cos", var("cam yaw"))),
        r.set("_spitch", B.mathop("sin", var("cam pitch"))), r.set("_cpitch", B.mathop("cos", var("cam pitch"))),
        # the screen's scale folded into the depth: w = depth / focal, from sin / focal, cos / focal
        r.set("_spf", div(spt, var("focal"))), r.set("_cpf", div(cpt, var("focal"))),
        B.delete_all(px), B.delete_all(py), B.delete_all(pz),
        r.set("_i", 1), r.set("_nv", nverts),
        B.repeat(var("_nv"), [*(node for x, y, z in points for node in (
            r.set("_dx", sub(x, var("cam x"))),
            r.set("_dy", sub(y, var("cam y"))),
            r.set("_dz", sub(z, var("cam z"))),
            r.set("_z1", add(mul(dx, syw), mul(dz, cyw))),
            r.set("_z2", add(mul(dy, var("_spf")), mul(z1, var("_cpf")))),
            B.add_to(pz, z2),
            B.add_to(px, div(sub(mul(dx, cyw), mul(dz, syw)), z2)),
            B.add_to(py, div(sub(mul(dy, cpt), mul(z1, spt)), z2)))),
            r.change("_i", step),
        ]),
        *safe,
    ])


# ---- the frame
def _triangle_and_material(m: Any, walk: str, b: Any) -> tuple[Any, Any]:
    """The filler's triangle number and its material (reporters) when ``_b`` (``b``) stands at
    corner c's item (book, soup) or is the triangle (split): see :func:`_fill_blocks`."""
    if walk == "book":
        return div(add(b, 1), 4), _index(m, item(add(b, 1), m.tris))
    if walk == "split":
        return b, _index(m, item(b, m.tris[3]))
    t = div(b, 3)
    return t, _index(m, item(t, m.tris))


def _fill_blocks(r: ReaderBuilder, check_usable: bool = True) -> list[B.Node]:
    """Fill the triangle whose ``tris`` items start at item ``_b`` (see the module docstring;
    :func:`_triangle_walk` for the other layouts). ``check_usable``: the blocks for an unsafe
    frame (a corner may be unusable); the frame runs the copy without the test when ``_safe``."""
    if r.spec.texture is not None:
        return _textured_fill_blocks(r)
    m = r.spec.mesh
    walk = _triangle_walk(m)
    px, py = "_px", "_py"
    b = r.v("_b")
    ax, ay, bx, by = (r.v(n) for n in ("_ax", "_ay", "_bx", "_by"))
    a2 = r.v("_a")

    def point(k):  # the item number of corner k's projected point
        return b if walk == "soup" else _index(m, item(b, m.tris if walk == "book" else m.tris[k - 1]))

    # book: corner a's items are read at _b, b's at _b + 1, c's at _b + 2: _b steps along the record
    # (one change instead of an add per corner and no index variables) and ends at c's item.
    # soup: the same along the corners' projected points; split: _b is the triangle.
    # Corners a and b go into variables; c's x and y are read where they are used (once in the
    # facing test, once more only when the triangle is drawn): cheaper than a variable for a
    # triangle turned away, which is most of them.
    load: list[B.Node] = []
    for k, (nx, ny) in ((1, ("_ax", "_ay")), (2, ("_bx", "_by"))):
        load += [r.set(nx, item(point(k), px)), r.set(ny, item(point(k), py))]
        if walk != "split":
            load.append(r.change("_b", 1))

    def cx():
        return item(point(3), px)

    def cy():
        return item(point(3), py)

    t, material = _triangle_and_material(m, walk, b)
    # faces the camera: ((bx-ax)*(cy-ay)) - ((by-ay)*(cx-ax)) < 0, i.e. the first product is the
    # smaller (a difference of doubles is negative exactly when the first is smaller)
    first, second = mul(sub(bx, ax), sub(cy(), ay)), mul(sub(by, ay), sub(cx(), ax))
    if _two_sided(r.spec):
        two = r.lst(m.two_sided, [int(x) for x in r.spec.two_sided])
        load += [r.set("_a", sub(first, second)),
                 B.if_(eq(item(material, two), 1), [r.set("_a", sub(0, B.abs_(a2)))])]
        faces = lt(a2, 0)
    else:
        faces = lt(first, second)
    # the pen's colour is set only when it changes (a colour set costs TurboWarp more than the test)
    c, pc = r.v("_c"), r.v("_pc")
    colour = [r.set("_c", _colour(r, t, material)),
              B.if_(eq(c, pc), [], [B.set_pen_color(c), r.set("_pc", c)])]
    spacing = float(r.spec.pen_size) - 1  # the fan's lines at b-c (see the module docstring)
    if not spacing > 0:
        raise B.BlockError(f"the filler needs a pen size above 1, not {r.spec.pen_size}")
    # a fan of k = ceiling(L / spacing) lines from a to the middles of k equal pieces of b-c (L = |b-c|),
    # walked q1, a, q2, q3, a, q4, q5, a, ... (see the module docstring); one and two lines (most
    # triangles) without the loop
    dx, dy, n, x, y = (r.v(q) for q in ("_dx", "_dy", "_n", "_x", "_y"))
    one = [B.goto_xy(add(bx, div(dx, 2)), add(by, div(dy, 2))), B.pen_down(), B.goto_xy(ax, ay)]
    two = [B.goto_xy(add(bx, div(dx, 4)), add(by, div(dy, 4))), B.pen_down(), B.goto_xy(ax, ay),
           B.goto_xy(add(bx, mul(dx, 0.75)), add(by, mul(dy, 0.75)))]
    many = [
        r.set("_dx", div(dx, n)), r.set("_dy", div(dy, n)),
        r.set("_x", add(bx, div(dx, 2))), r.set("_y", add(by, div(dy, 2))),
        B.goto_xy(x, y), B.pen_down(), B.goto_xy(ax, ay),
        # floor((k - 1) / 2) pairs (repeat rounds (k - 2) / 2 half up), then with k - 1 odd the
        # last point, from a
        r.set("_p", div(sub(n, 2), 2)),
        B.repeat(r.v("_p"), [
            r.change("_x", dx), r.change("_y", dy), B.goto_xy(x, y),
            r.change("_x", dx), r.change("_y", dy), B.goto_xy(x, y), B.goto_xy(ax, ay)]),
        B.if_(eq(B.mod(n, 2), 0), [r.change("_x", dx), r.change("_y", dy), B.goto_xy(x, y)]),
    ]
    fill = [
        *colour,
        r.set("_dx", sub(cx(), bx)), r.set("_dy", sub(cy(), by)),
        # k > 2, k = 2, k = 1, told from L^2 (ceiling and square root only for a fan)
        r.set("_n", add(mul(dx, dx), mul(dy, dy))),
        B.if_(gt(n, 4 * spacing * spacing),
              [r.set("_n", B.mathop("ceiling", B.sqrt(n) if spacing == 1 else div(B.sqrt(n), spacing))), *many],
              [B.if_(gt(n, spacing * spacing), two, one)]),
        B.pen_up(),
    ]
    # the drawing is a custom block of its own, so that the frame's two copies of the loop (a safe
    # frame's and an unsafe one's) share it: two blocks a triangle drawn, not a second copy
    if not r.has("fill triangle"):
        r.define("fill triangle", [], fill)
    fill = [B.call("fill triangle")]
    if check_usable:
        # an unusable corner's x is UNUSABLE_X; usable ones are within SAFE_X of the centre, so the
        # sum of |x| is below 3 * SAFE_X exactly when all three are usable
        unusable = gt(add(add(B.abs_(ax), B.abs_(bx)), B.abs_(cx())), 3 * SAFE_X)
        fill = [B.if_(not_(unusable), fill)]
    return load + [B.if_(faces, fill)]


def _textured_fill_blocks(r: ReaderBuilder) -> list[B.Node]:
    """The textured filler's triangle (reader_texture.cell_fill): the corners' vertex numbers in
    ``_va .. _vc``, their screen points in ``_ax .. _cy``, the facing and usable tests."""
    m = r.spec.mesh
    walk = _triangle_walk(m)
    px, py = "_px", "_py"
    b = r.v("_b")
    ax, ay, bx, by, cx, cy = (r.v(n) for n in ("_ax", "_ay", "_bx", "_by", "_cx", "_cy"))
    a2 = r.v("_a")
    load: list[B.Node] = []
    corners = []  # each corner's projected point, kept for its depth
    for k, name in ((1, "a"), (2, "b"), (3, "c")):
        point = b if walk == "soup" else _index(m, item(b, m.tris if walk == "book" else m.tris[k - 1]))
        load.append(r.set(f"_v{name}", point))
        point = r.v(f"_v{name}")
        corners.append(point)
        load += [r.set(f"_{name}x", item(point, px)), r.set(f"_{name}y", item(point, py))]
        if k < 3 and walk != "split":
            load.append(r.change("_b", 1))
    t, material = _triangle_and_material(m, walk, b)
    load.append(r.set("_a", sub(mul(sub(bx, ax), sub(cy, ay)), mul(sub(by, ay), sub(cx, ax)))))
    if _two_sided(r.spec):
        two = r.lst(m.two_sided, [int(x) for x in r.spec.two_sided])
        load.append(B.if_(eq(item(material, two), 1), [r.set("_a", sub(0, B.abs_(a2)))]))
    unusable = gt(add(add(B.abs_(ax), B.abs_(bx)), B.abs_(cx)), 3 * SAFE_X)
    load.append(B.if_(eq(var("_safe"), 0), [B.if_(unusable, [r.set("_a", 0)])]))
    fill = cell_fill(r, r.spec.texture, t, material, _colour(r, t, material), corners)
    return load + [B.if_(lt(a2, 0), fill)]


def _render_blocks(r: ReaderBuilder) -> None:
    m = r.spec.mesh
    k = r.v("_k")
    walk = _triangle_walk(m)
    step = 2 if walk == "book" else 1  # to the next triangle's first item (the fill moved 2 in book and soup)
    textured = r.spec.texture is not None
    start = [B.hide(), B.pen_up(), B.pen_clear(), B.set_pen_size(1 if textured else r.spec.pen_size),
             r.set("_pc", "")]
    if textured:  # the textures' colours into _tex, once
        r.define("load textures", [], load_blocks(r, r.spec.texture))
        start.append(B.if_(eq(B.list_length(r.lst("_tex")), 0), [B.call("load textures")]))
    # a decoder (TextImage, packed lists) may have switched costumes; the pen needs the fence
    start.append(B.switch_costume("fence"))
    start.append(B.call("project vertices"))
    # loop counts go into variables first: a repeat evaluates its count at every turn
    nt = r.v("_nt")

    def frame(fill: list[B.Node]) -> list[B.Node]:
        if r.spec.bsp is not None:
            ranges = r.lst("draw ranges")
            return [
                r.set("_k", 1),
                r.set("_nr", div(B.list_length(ranges), 2)),
                B.repeat(r.v("_nr"), [
                    r.set("_b", {"book": lambda f: sub(mul(f, 4), 3), "split": lambda f: f,
                                 "soup": lambda f: sub(mul(f, 3), 2)}[walk](item(k, ranges))),
                    r.set("_nt", item(add(k, 1), ranges)),
                    B.repeat(nt, [*fill, r.change("_b", step)]),
                    r.change("_k", 2),
                ]),
            ]
        # no tree: the list's order
        count = {"book": lambda: div(B.list_length(m.tris), 4), "split": lambda: B.list_length(m.tris[0]),
                 "soup": lambda: B.list_length(m.tris)}[walk]()
        return [r.set("_b", 1), r.set("_nt", count), B.repeat(nt, [*fill, r.change("_b", step)])]

    walk_first = [B.call("bsp walk")] if r.spec.bsp is not None else []
    if textured:
        body = frame(_fill_blocks(r))
    else:  # a safe frame skips the usable test (every corner is usable)
        body = [B.if_(eq(var("_safe"), 0), frame(_fill_blocks(r, True)), frame(_fill_blocks(r, False)))]
    r.define("render", [], start + walk_first + body)


# ---- BSP
def _bsp_blocks(r: ReaderBuilder) -> None:
    """``bsp walk``: the painter's order for the eye at (``cam x``, ``cam y``, ``cam z``), as
    ``(first, n)`` pairs in ``draw ranges`` (back to front). The walk of docs/formats-bsp.md with
    an explicit stack (a 0 at the bottom ends it; a record's item number to visit, or the negated
    item of a ready-made range), with the arithmetic of its Python model
    ``bake.bsp.traverse.draw_ranges``: the eye is in front when ``((a*x + b*y) + c*z) - d >= 0``,
    tested as ``not (((a*x + b*y) + c*z) < d)`` (the same for every pair of doubles)."""
    s = r.spec.bsp
    nodes, planes = r.lst(s.nodes), r.lst(s.planes)
    ranges, stack = r.lst("draw ranges"), r.lst("_bsp stack")
    for n, val in (("cam x", r.spec.camera.x), ("cam y", r.spec.camera.y), ("cam z", r.spec.camera.z)):
        r.v(n, val)
    rr, T, bb = (r.v(x) for x in ("_r", "_T", "_B"))

    def at(k):  # item (r + k) of nodes
        return item(add(rr, k), nodes)

    def plane(k):  # item (T - k) of planes
        return item(sub(T, k), planes)

    # the eye is behind the plane when ((a*x + b*y) + c*z) < d, which is exactly the Python
    # model's ((a*x + b*y) + c*z) - d < 0 (a difference of doubles is 0 only when they are equal)
    behind = lt(add(add(mul(plane(3), var("cam x")), mul(plane(2), var("cam y"))), mul(plane(1), var("cam z"))),
                item(T, planes))

    def pop():  # the next record or range to visit: the top of the stack
        return [r.set("_r", item("last", stack)), B.delete_item(stack, "last")]

    def emit(first, n):  # a range into draw ranges
        return [B.add_to(ranges, item(first, nodes)), B.add_to(ranges, item(n, nodes))]

    # a split record: B (item r + 1) says which children there are: the front child is the
    # record at r + 6 unless B < 0, the back child at |B| unless B = 0. The near side is pushed
    # (drawn last), then the coplanar range on the eye's side (its first at item g - 1, its count
    # at g), and the far side is visited at once (or the stack popped when there is none).
    def side(near_push, g, far):
        return [*near_push,
                B.if_(gt(at(g), 0), [B.add_to(stack, sub(1 - g, rr))]),
                *far]

    split = [
        r.set("_B", at(1)),
        B.if_(behind,
              # eye behind: the back child near, the front child far, the range at r + 4
              side([B.if_(not_(eq(bb, 0)), [B.add_to(stack, B.abs_(bb))])], 5,
                   [B.if_(lt(bb, 0), pop(), [r.set("_r", add(rr, 6))])]),
              # eye in front (or on the plane): the front child near, the back child far, the range at r + 2
              side([B.if_(not_(lt(bb, 0)), [B.add_to(stack, add(rr, 6))])], 3,
                   [B.if_(eq(bb, 0), pop(), [r.set("_r", B.abs_(bb))])])),
    ]
    r.define("bsp walk", [], [
        B.delete_all(ranges), B.delete_all(stack), B.add_to(stack, 0),
        r.set("_r", 0),
        B.if_(gt(B.list_length(nodes), 0), [r.set("_r", 1)]),
        B.repeat_until(eq(rr, 0), [
            B.if_(gt(rr, 0), [
                r.set("_T", item(rr, nodes)),
                B.if_(lt(T, 2), [  # a leaf or a peel: its (first) range now
                    *emit(add(rr, 1), add(rr, 2)),
                    B.if_(eq(T, 1), [B.add_to(stack, sub(-3, rr)), r.set("_r", add(rr, 5))], pop()),
                ], split),
            ], [*emit(sub(0, rr), sub(1, rr)), *pop()]),  # r < 0: the ready-made range at item -r
        ]),
    ])


# --------------------------------------------------------------------------- public API
def _builtin_parts(spec: ReaderSpec) -> list[Callable[[ReaderBuilder], None]]:
    parts: list[Callable[[ReaderBuilder], None]] = []
    if spec.mesh:
        if spec.helpers:
            parts.append(_load_triangle)
        if spec.bsp is not None:
            parts.append(_bsp_blocks)
        if spec.renderer:
            parts += [_camera_blocks, _render_blocks]
    if spec.bvh:
        parts.append(bvh_part)
        if spec.bvh_view and spec.mesh and spec.renderer:
            parts.append(bvh_view_part)
    if spec.textimage:
        parts.append(textimage_part)
    return parts


def reader_target(spec: ReaderSpec, name: str = "Reader", *, local_lists: dict[str, list] | None = None,
                  stage_lists: dict[str, str] | Sequence[str] = (), layer_order: int = 1,
                  demo: bool = False) -> sb3.Target:
    """The reader sprite as a :class:`bake.scratch.sb3.Target`.

    ``local_lists``: data lists stored in the sprite itself (name -> items), e.g. for a
    .sprite3. ``stage_lists``: names (or name -> id) of data lists that live on the stage.
    Every list in ``spec.lists_read()`` must be in one of them. ``demo`` adds a green-flag
    script: the parts' ``at_flag`` blocks, then it renders the model from the spec's camera."""
    local_lists = dict(local_lists or {})
    stage_ids = dict(stage_lists) if isinstance(stage_lists, dict) else \
        {n: sb3.stable_id("Stage", "list", n) for n in stage_lists}
    missing = [n for n in spec.lists_read() if n not in local_lists and n not in stage_ids]
    if missing:
        raise B.BlockError(f"the reader reads lists that are not in the project: {', '.join(missing)}")
    r = ReaderBuilder(spec, {n: sb3.stable_id(name, "list", n, length=VAR_ID_LENGTH) for n in local_lists},
                      stage_ids, name)
    for part in _builtin_parts(spec) + list(spec.parts):
        part(r)
    all_local = dict(local_lists)
    for k, v in r.local_lists.items():
        if k in all_local:
            raise B.BlockError(f"list {k!r} is used by the reader itself")
        all_local[k] = v
    var_ids, list_ids = sb3.data_ids(name, list(r.vars), list(all_local), length=VAR_ID_LENGTH,
                                     taken=list(stage_ids.values()))
    scope = B.Scope(name, variables=var_ids, lists=list_ids, stage_lists=stage_ids)
    b = B.Builder(scope, compact=r.compact)
    for proccode, args, body in r.procs:
        b.define(proccode, args, body)
    if demo:
        script = list(r.flag)
        if spec.mesh and spec.renderer:
            cam = spec.camera
            draw = [B.set_var("cam x", cam.x), B.set_var("cam y", cam.y), B.set_var("cam z", cam.z),
                    B.set_var("cam yaw", cam.yaw), B.set_var("cam pitch", cam.pitch),
                    B.call("bvh view" if r.has("bvh view") else "render")]
            script += [B.if_(r.flag_guard, draw)] if r.flag_guard is not None else draw
        if script:
            b.when_flag(script)
    # the alphabet first (costume k + 1 is character k: the decoders read costume numbers), the
    # pen's fence costume after it
    costumes = alphabet_costumes(minimal=r.compact) if r.alphabet else []
    if spec.mesh and spec.renderer:
        costumes.append(sb3.Costume("fence", sb3.Asset(FENCE_SVG, "svg"), 1, (FENCE / 2, FENCE / 2)))
    return sb3.Target(name, lists=all_local, variables=dict(r.vars), costumes=costumes,
                      blocks=b.build(), layer_order=layer_order, visible=False, id_length=VAR_ID_LENGTH)
