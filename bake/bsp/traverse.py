"""The reference traversal: reads the exported lists the way the Scratch script does.

:func:`draw_ranges` is a line-by-line model of the reader sprite's ``bsp walk`` block (and of the
pseudo-blocks in docs/formats-bsp.md): it only uses the flat ``bsp nodes`` and ``bsp planes``
lists, 1-based items, records read item by item and an explicit stack list with a 0 at the
bottom. It gives the painter's order as ranges of the exported triangle list; the walk does no
back-face culling (a renderer skips faces turned away, on screen or in 3D).
:func:`draw_order` expands the ranges and, with ``cull``, drops the single-sided triangles that
face away from the eye, as a renderer does.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np


def _item(lst: Sequence, i: int):
    """Scratch's ``item (i) of [list]`` (1-based)."""
    return lst[int(i) - 1]


def draw_ranges(nodes: Sequence[float], planes: Sequence[float], eye: Sequence[float], *,
                max_stack: int | None = None) -> list[tuple[int, int]]:
    """``(first, n)`` ranges of triangles (1-based) in the order the painter draws them, back to
    front, for an eye at ``eye``: what the ``bsp walk`` block appends to ``draw ranges``."""
    ex, ey, ez = (float(v) for v in eye)
    out: list[tuple[int, int]] = []
    stack: list[int] = [0]  # the 0 at the bottom ends the walk
    r = 1 if len(nodes) > 0 else 0

    def pop() -> int:
        return stack.pop()  # set r to (item (last) of stack); delete (last) of stack

    deepest = 1
    while r != 0:
        if r < 0:  # a ready-made range at item -r: first, n
            out.append((int(_item(nodes, -r)), int(_item(nodes, -r + 1))))
            r = pop()
            continue
        T = int(_item(nodes, r))
        if T == 0:  # leaf
            out.append((int(_item(nodes, r + 1)), int(_item(nodes, r + 2))))
            r = pop()
        elif T == 1:  # peel: the first part now, the rest after the child
            out.append((int(_item(nodes, r + 1)), int(_item(nodes, r + 2))))
            stack.append(-3 - r)
            r = r + 5
        else:  # split on the plane whose d is item T of the planes
            a, b, c, d = (float(_item(planes, T - k)) for k in (3, 2, 1, 0))
            B = int(_item(nodes, r + 1))  # B < 0: no front child (the back one at -B); B = 0: no back child
            if ((a * ex + b * ey) + c * ez) - d >= 0:  # eye in front (or on the plane)
                if not B < 0:
                    stack.append(r + 6)  # the front child, drawn last
                if int(_item(nodes, r + 3)) > 0:
                    stack.append(-2 - r)  # then the coplanar triangles seen from the front
                r = pop() if B == 0 else abs(B)  # the back child first, at once
            else:  # eye behind
                if B != 0:
                    stack.append(abs(B))  # the back child, drawn last
                if int(_item(nodes, r + 5)) > 0:
                    stack.append(-4 - r)  # then the coplanar triangles seen from the back
                r = pop() if B < 0 else r + 6  # the front child first, at once
        deepest = max(deepest, len(stack))
        if max_stack is not None and deepest > max_stack:
            raise RuntimeError(f"stack grew to {deepest} > {max_stack}")
    return out


def draw_order(nodes: Sequence[float], planes: Sequence[float], eye: Sequence[float],
               tris: Sequence[float] | None = None, verts: Sequence[float] | None = None,
               double_sided: Sequence[bool] | None = None, *, cull: bool = True,
               facing: np.ndarray | None = None, max_stack: int | None = None) -> list[int]:
    """Triangle numbers (1-based) in the order the painter draws them, back to front.

    ``nodes``/``planes``: the flat lists. With ``cull`` (the default) single-sided triangles facing
    away from the eye are left out, as a renderer does: ``tris``/``verts`` are the flat exported
    mesh lists (v1, v2, v3, material; x, y, z) and ``double_sided[m]`` says whether material m
    (1-based, so index m - 1) is drawn from both sides; or pass ``facing`` (from
    :func:`facing_flags` for this eye). With ``cull=False`` every triangle of the walk is listed."""
    order = [t for first, n in draw_ranges(nodes, planes, eye, max_stack=max_stack)
             for t in range(first, first + n)]
    if not cull or not order:
        return order
    if facing is None:
        if tris is None or verts is None:
            raise ValueError("culling needs tris and verts (or facing)")
        facing = facing_flags(tris, verts, eye, double_sided)
    return [t for t in order if facing[t - 1]]


def facing_flags(tris: Sequence[float], verts: Sequence[float], eye, double_sided: Sequence[bool] | None = None
                 ) -> np.ndarray:
    """Per triangle (0-based): drawn for this eye (its front faces it, or it is two-sided). The
    front faces the eye when ``n . (eye - a) > 0`` with ``n = (b - a) x (c - a)`` for corners
    ``a, b, c`` in list order (docs/formats-bsp.md)."""
    t = np.asarray(tris, np.int64).reshape(-1, 4)
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    p = v[t[:, :3] - 1]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    f = np.einsum("ij,ij->i", n, np.asarray(eye, np.float64) - p[:, 0]) > 0
    if double_sided is not None:
        f |= np.asarray(double_sided, bool)[t[:, 3] - 1]
    return f
