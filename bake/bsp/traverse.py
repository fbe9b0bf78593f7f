"""The reference traversal: reads the exported lists the way the Scratch script does.

It only uses what a Scratch project has: the flat ``bsp nodes`` and ``bsp planes`` lists, the
exported triangle list (``tris``: v1, v2, v3, material, 1-based) and vertex list (``verts``), and
which materials are double-sided. Indices are 1-based, records are read item by item, and the
stack is an explicit list — a line-by-line model of the pseudo-blocks in docs/formats-bsp.md.
"""

from __future__ import annotations

from typing import Sequence

import numpy as np


def _item(lst: Sequence, i: int):
    """Scratch's ``item (i) of [list]`` (1-based)."""
    return lst[int(i) - 1]


def draw_order(nodes: Sequence[float], planes: Sequence[float], eye: Sequence[float],
               tris: Sequence[float] | None = None, verts: Sequence[float] | None = None,
               double_sided: Sequence[bool] | None = None, *, cull: bool = True,
               facing: np.ndarray | None = None, max_stack: int | None = None) -> list[int]:
    """Triangle numbers (1-based) in the order the painter draws them, back to front.

    ``nodes``/``planes``: the flat lists. ``tris``/``verts``: flat exported mesh lists, used for
    back-face culling in leaves (a single-sided triangle facing away is skipped, as the Scratch
    renderer does); ``double_sided[m]`` for material m (1-based list, so index m - 1). With
    ``cull=False`` leaves draw every triangle (``tris`` may then be None). ``facing``: the
    result of :func:`facing_flags` for this eye, instead of testing triangles one by one."""
    ex, ey, ez = (float(v) for v in eye)
    order: list[int] = []

    def faces_eye(t: int) -> bool:
        if not cull:
            return True
        if facing is not None:
            return bool(facing[t - 1])
        base = (t - 1) * 4
        v = [int(_item(tris, base + k)) for k in (1, 2, 3)]
        mat = int(_item(tris, base + 4))
        if double_sided is not None and double_sided[mat - 1]:
            return True
        p = [[float(_item(verts, (vi - 1) * 3 + k)) for k in (1, 2, 3)] for vi in v]
        ux, uy, uz = p[1][0] - p[0][0], p[1][1] - p[0][1], p[1][2] - p[0][2]
        wx, wy, wz = p[2][0] - p[0][0], p[2][1] - p[0][1], p[2][2] - p[0][2]
        nx, ny, nz = uy * wz - uz * wy, uz * wx - ux * wz, ux * wy - uy * wx
        return nx * (ex - p[0][0]) + ny * (ey - p[0][1]) + nz * (ez - p[0][2]) > 0

    def draw(first: int, n: int, culled: bool) -> None:
        for t in range(int(first), int(first) + int(n)):
            if not culled or faces_eye(t):
                order.append(t)

    def side(r: int) -> bool:
        """Eye in front of (or on) the plane of split record r."""
        p = abs(int(_item(nodes, r))) - 1
        a, b, c, d = (float(_item(planes, (p - 1) * 4 + k)) for k in (1, 2, 3, 4))
        return a * ex + b * ey + c * ez - d >= 0

    if len(nodes) == 0:
        return order
    stack: list[int] = [1]
    deepest = 1
    while stack:
        r = stack.pop()  # item (length of stack) of stack; delete (length of stack) of stack
        if r < 0:  # deferred drawing of record -r
            r = -r
            T = int(_item(nodes, r))
            if T == 1:  # suffix of a peel record
                draw(_item(nodes, r + 1) + _item(nodes, r + 2), _item(nodes, r + 3), True)
                continue
            first = int(_item(nodes, r + 2))
            nA = int(_item(nodes, r + 3))
            if T > 0:
                nD, nB = 0, int(_item(nodes, r + 4))
            else:
                nD, nB = int(_item(nodes, r + 4)), int(_item(nodes, r + 5))
            if side(r):
                draw(first, nA + nD, False)
            else:
                draw(first + nA, nD + nB, False)
            continue
        T = int(_item(nodes, r))
        if T == 0:
            draw(_item(nodes, r + 1), _item(nodes, r + 2), True)
        elif T == 1:
            draw(_item(nodes, r + 1), _item(nodes, r + 2), True)
            stack.append(-r)
            stack.append(r + 4)
        else:
            size = 5 if T > 0 else 6
            B = int(_item(nodes, r + 1))
            front = r + size if B >= 0 else 0
            back = B if B > 0 else (-B if B < 0 else 0)
            if side(r):
                near, far = front, back
            else:
                near, far = back, front
            if near:
                stack.append(near)
            stack.append(-r)
            if far:
                stack.append(far)
        deepest = max(deepest, len(stack))
        if max_stack is not None and deepest > max_stack:
            raise RuntimeError(f"stack grew to {deepest} > {max_stack}")
    return order


def facing_flags(tris: Sequence[float], verts: Sequence[float], eye, double_sided: Sequence[bool] | None = None
                 ) -> np.ndarray:
    """Per triangle (0-based): drawn by a culled range for this eye (faces it, or two-sided).
    The same test as :func:`draw_order`'s, vectorised; pass it as ``facing`` to skip the
    per-triangle arithmetic in Python."""
    t = np.asarray(tris, np.int64).reshape(-1, 4)
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    p = v[t[:, :3] - 1]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    f = np.einsum("ij,ij->i", n, np.asarray(eye, np.float64) - p[:, 0]) > 0
    if double_sided is not None:
        f |= np.asarray(double_sided, bool)[t[:, 3] - 1]
    return f
