"""Three small Scratch 3D engines, written the way authors write theirs (issue 39, item 4).

Each is an .sb3 of a white stage that owns the engine's model lists (holding a placeholder
triangle, as an author's project does before a bake) and one hidden sprite, ``Engine``, whose
green-flag script sets the camera and calls ``render`` (a custom block run without screen
refresh). ``render`` projects the vertices, then draws the triangles in list order with the pen,
skipping those not clockwise on the stage, each filled with its colour. Only the layout of the
model lists differs:

* :func:`per_coordinate_engine`: ``X``, ``Y``, ``Z`` (one number per vertex), 0-based corner
  lists ``tri a``, ``tri b``, ``tri c``, ``tri mat`` (the material, 0-based) and ``tri col`` (a
  colour per triangle);
* :func:`soup_engine`: ``tri xyz`` (x1, y1, z1, x2, ... z3: nine numbers per triangle, no shared
  vertices), ``tri mat`` (1-based) and ``tri col``;
* :func:`interleaved_engine`: the book's layout, ``verts`` (x, y, z per vertex), ``tris`` (v1, v2,
  v3, material; 1-based) and ``mat colors``.

The first two colour a triangle from its ``tri col`` item, or, when that list is empty, from its
material's ``mat colors`` item (so every list the bake writes is read).

The camera is the scratch-bake reader's (bake/scratch/readers.py's docstring): at ``(cam x, cam
y, cam z)``, turned ``cam yaw`` degrees about y and then ``cam pitch`` degrees about its x axis;
with ``d = p - cam``: ``x' = dx cos(yaw) - dz sin(yaw)``, ``z' = dx sin(yaw) + dz cos(yaw)``,
``y'' = dy cos(pitch) - z' sin(pitch)``, ``z'' = dy sin(pitch) + z' cos(pitch)``, and the stage
point is ``focal (x', y'') / z''``. Scratch's ``sin`` and ``cos`` take degrees.

A triangle is filled with a fan of lines from corner a to ``n + 1`` points spread evenly along
the edge b-c, ``n = ceiling(|b - c|)``, so neighbouring points are at most one pixel apart: every
point of the triangle is within half a pixel of a line, and the pen (size 2) paints it.

These engines share no code with the bake's reader sprite; they are built with the bake's
block builder only (``bake.scratch.blocks``, ``bake.scratch.sb3``).
"""

from __future__ import annotations

from typing import Any, Sequence

from bake.scratch import blocks as B
from bake.scratch import sb3
from bake.scratch.blocks import add, div, item, lt, mul, sub, var

SPRITE = "Engine"
PEN_SIZE = 2
CAMERA = ("cam x", "cam y", "cam z", "cam yaw", "cam pitch", "focal")

#: the stage lists of each engine before a bake: one placeholder triangle, as an author has while
#: building the engine (the bake replaces every one of them)
PER_COORDINATE_LISTS = {"X": [0, 1, 0], "Y": [0, 0, 1], "Z": [0, 0, 0], "tri a": [0], "tri b": [1],
                        "tri c": [2], "tri mat": [0], "tri col": [16711680], "mat colors": [8421504]}
SOUP_LISTS = {"tri xyz": [0, 0, 0, 0, 1, 0, 1, 0, 0], "tri mat": [1], "tri col": [16711680],
              "mat colors": [8421504]}
INTERLEAVED_LISTS = {"verts": [0, 0, 0, 0, 1, 0, 1, 0, 0], "tris": [1, 2, 3, 1], "mat colors": [8421504]}


def _camera_values(cam: Any) -> dict[str, float]:
    """``cam``: a :class:`bake.scratch.readers.Camera` (x, y, z, yaw, pitch, focal)."""
    return {"cam x": cam.x, "cam y": cam.y, "cam z": cam.z, "cam yaw": cam.yaw, "cam pitch": cam.pitch,
            "focal": cam.focal}


# --------------------------------------------------------------------------- shared blocks
def _project_block(b: B.Builder) -> None:
    """``project (x) (y) (z)``: the stage point of a model point into ``sx``, ``sy``."""
    x, y, z = B.arg("x"), B.arg("y"), B.arg("z")
    dx, dy, dz, x1, z1 = (var(n) for n in ("dx", "dy", "dz", "x1", "z1"))
    b.define("project %s %s %s", ["x", "y", "z"], [
        B.set_var("dx", sub(x, var("cam x"))),
        B.set_var("dy", sub(y, var("cam y"))),
        B.set_var("dz", sub(z, var("cam z"))),
        B.set_var("x1", sub(mul(dx, var("cos yaw")), mul(dz, var("sin yaw")))),
        B.set_var("z1", add(mul(dx, var("sin yaw")), mul(dz, var("cos yaw")))),
        B.set_var("y2", sub(mul(dy, var("cos pitch")), mul(z1, var("sin pitch")))),
        B.set_var("z2", add(mul(dy, var("sin pitch")), mul(z1, var("cos pitch")))),
        B.set_var("sx", div(mul(var("focal"), x1), var("z2"))),
        B.set_var("sy", div(mul(var("focal"), var("y2")), var("z2"))),
    ])


def _fill_block(b: B.Builder) -> None:
    """``fill (ax) (ay) (bx) (by) (cx) (cy) colour (c)``: the triangle when it is clockwise on the
    stage (it faces the camera), a fan of lines from a to points along b-c at most 1 pixel apart."""
    ax, ay, bx, by, cx, cy, c = (B.arg(n) for n in ("ax", "ay", "bx", "by", "cx", "cy", "c"))
    n, i = var("n"), var("i")
    area = sub(mul(sub(bx, ax), sub(cy, ay)), mul(sub(by, ay), sub(cx, ax)))
    ex, ey = sub(cx, bx), sub(cy, by)
    b.define("fill %s %s %s %s %s %s colour %s", ["ax", "ay", "bx", "by", "cx", "cy", "c"], [
        B.if_(lt(area, 0), [
            B.set_pen_color(c),
            B.set_var("n", B.mathop("ceiling", B.sqrt(add(mul(ex, ex), mul(ey, ey))))),
            B.if_(lt(n, 1), [B.set_var("n", 1)]),  # b = c: one line, a to b
            B.set_var("i", 0),
            B.goto_xy(ax, ay),
            B.pen_down(),
            B.repeat(add(n, 1), [
                B.goto_xy(add(bx, mul(ex, div(i, n))), add(by, mul(ey, div(i, n)))),
                B.goto_xy(ax, ay),
                B.change_var("i", 1),
            ]),
            B.pen_up(),
        ]),
    ])


def _start() -> list[B.Node]:
    """The start of ``render``: a clean stage, the pen, the camera's sines and cosines."""
    return [
        B.hide(), B.pen_up(), B.pen_clear(), B.set_pen_size(PEN_SIZE),
        B.set_var("sin yaw", B.mathop("sin", var("cam yaw"))), B.set_var("cos yaw", B.mathop("cos", var("cam yaw"))),
        B.set_var("sin pitch", B.mathop("sin", var("cam pitch"))),
        B.set_var("cos pitch", B.mathop("cos", var("cam pitch"))),
    ]


def _project_all(count: B.Node, x: B.Node, y: B.Node, z: B.Node, step: int) -> list[B.Node]:
    """Every vertex into the sprite's lists ``screen x`` and ``screen y`` (``x``, ``y``, ``z``:
    reporters of vertex ``v``'s coordinates; ``v`` steps by ``step``)."""
    return [
        B.delete_all("screen x"), B.delete_all("screen y"),
        B.set_var("v", 1),
        B.repeat(count, [
            B.call("project %s %s %s", x, y, z),
            B.add_to("screen x", var("sx")), B.add_to("screen y", var("sy")),
            B.change_var("v", step),
        ]),
    ]


def _fill_corners(a: B.Node, b: B.Node, c: B.Node, colour: B.Node) -> B.Node:
    """``fill`` with the screen points of vertices a, b, c (1-based items of ``screen x``/``y``)."""
    return B.call("fill %s %s %s %s %s %s colour %s", item(a, "screen x"), item(a, "screen y"),
                  item(b, "screen x"), item(b, "screen y"), item(c, "screen x"), item(c, "screen y"), colour)


def _colour(t: B.Node, material: B.Node) -> B.Node:
    """Set ``colour``: triangle t's ``tri col`` item, or its material's ``mat colors`` item
    (``material``: its 1-based number) when ``tri col`` is empty."""
    return B.if_(B.gt(B.list_length("tri col"), 0), [B.set_var("colour", item(t, "tri col"))],
                 [B.set_var("colour", item(material, "mat colors"))])


def _engine(stage_lists: dict[str, list], draw: list[B.Node], cam: Any, extra: Sequence[str] = ()) -> bytes:
    """The .sb3: the stage with ``stage_lists``; the sprite's green flag sets the camera and
    calls ``render`` (``_start``, then ``draw``)."""
    variables = list(CAMERA) + ["sin yaw", "cos yaw", "sin pitch", "cos pitch", "dx", "dy", "dz", "x1", "z1", "y2",
                                "z2", "sx", "sy", "n", "i", "v", "t", "colour", *extra]
    own_lists = ["screen x", "screen y"]
    var_ids, list_ids = sb3.data_ids(SPRITE, variables, own_lists)
    _, stage_ids = sb3.data_ids("Stage", [], list(stage_lists))
    b = B.Builder(B.Scope(SPRITE, variables=var_ids, lists=list_ids, stage_lists=stage_ids))
    _project_block(b)
    _fill_block(b)
    b.define("render", [], _start() + draw)
    b.when_flag([B.set_var(k, v) for k, v in _camera_values(cam).items()] + [B.call("render")])
    stage = sb3.Target("Stage", is_stage=True, lists={k: list(v) for k, v in stage_lists.items()})
    sprite = sb3.Target(SPRITE, variables={n: 0 for n in variables}, lists={n: [] for n in own_lists},
                        blocks=b.build(), layer_order=1, visible=False)
    data, _ = sb3.write_sb3([stage, sprite])
    return data


# --------------------------------------------------------------------------- the three engines
def per_coordinate_engine(cam: Any) -> bytes:
    """Lists ``X``, ``Y``, ``Z``; 0-based ``tri a``, ``tri b``, ``tri c``, ``tri mat``; ``tri col``."""
    v, t = var("v"), var("t")
    draw = _project_all(B.list_length("X"), item(v, "X"), item(v, "Y"), item(v, "Z"), 1) + [
        B.set_var("t", 1),
        B.repeat(B.list_length("tri mat"), [
            _colour(t, add(item(t, "tri mat"), 1)),
            _fill_corners(add(item(t, "tri a"), 1), add(item(t, "tri b"), 1), add(item(t, "tri c"), 1),
                          var("colour")),
            B.change_var("t", 1),
        ]),
    ]
    return _engine(PER_COORDINATE_LISTS, draw, cam)


def soup_engine(cam: Any) -> bytes:
    """List ``tri xyz`` (nine numbers per triangle), ``tri mat`` (1-based), ``tri col``: each
    corner is projected where the triangle is drawn."""
    k, t = var("k"), var("t")

    def corner(j: int) -> B.Node:  # corner j (0, 1, 2) of the triangle at item k
        return B.call("project %s %s %s", item(add(k, 3 * j), "tri xyz"), item(add(k, 3 * j + 1), "tri xyz"),
                      item(add(k, 3 * j + 2), "tri xyz"))

    draw = [
        B.set_var("t", 1), B.set_var("k", 1),
        B.repeat(div(B.list_length("tri xyz"), 9), [
            _colour(t, item(t, "tri mat")),
            corner(0), B.set_var("ax", var("sx")), B.set_var("ay", var("sy")),
            corner(1), B.set_var("bx", var("sx")), B.set_var("by", var("sy")),
            corner(2),
            B.call("fill %s %s %s %s %s %s colour %s", var("ax"), var("ay"), var("bx"), var("by"), var("sx"),
                   var("sy"), var("colour")),
            B.change_var("t", 1), B.change_var("k", 9),
        ]),
    ]
    return _engine(SOUP_LISTS, draw, cam, extra=("k", "ax", "ay", "bx", "by"))


def interleaved_engine(cam: Any) -> bytes:
    """The book's lists: ``verts`` (x, y, z per vertex), ``tris`` (v1, v2, v3, material; 1-based),
    ``mat colors``."""
    v, t = var("v"), var("t")
    draw = _project_all(div(B.list_length("verts"), 3), item(v, "verts"), item(add(v, 1), "verts"),
                        item(add(v, 2), "verts"), 3) + [
        B.set_var("t", 1),
        B.repeat(div(B.list_length("tris"), 4), [
            _fill_corners(item(t, "tris"), item(add(t, 1), "tris"), item(add(t, 2), "tris"),
                          item(item(add(t, 3), "tris"), "mat colors")),
            B.change_var("t", 4),
        ]),
    ]
    return _engine(INTERLEAVED_LISTS, draw, cam)


ENGINES = {"per-coordinate": per_coordinate_engine, "soup": soup_engine, "interleaved": interleaved_engine}
