"""Small geometric steps shared by the stages: cutting polygons by planes (the BSP's splits,
``bake/bsp/split.py``, and the hidden stage's trimming, ``bake/mesh/hidden/trim.py``) and the
tangents of a direction (the textures' texel samples, the hidden stage's eyes and rays)."""

from __future__ import annotations

import numpy as np


def edge_crossings(d: np.ndarray, count: np.ndarray) -> tuple[np.ndarray, ...]:
    """Where the edges of convex polygons cross a plane, all polygons at once.

    ``d`` (n, K): the signed distance of each corner to the plane (corners ``k >= count`` are
    padding); ``count`` (n,): the corners of each polygon, edge ``k`` running from corner ``k`` to
    corner ``k + 1`` (mod ``count``). Returns ``(valid, cross, ia, ib, t)``, each (n, K): corner
    ``k`` is a real one, edge ``k`` has its ends strictly on opposite sides, and its crossing is
    corner ``ia`` + ``t`` x (corner ``ib`` - corner ``ia``), where ``ia`` is the end on the positive
    side. Computing the new corner from the positive end towards the negative one makes the two
    polygons sharing an edge (or the two pieces of one cut) get bit-identical corners."""
    K = d.shape[1]
    k = np.arange(K)[None, :]
    valid = k < count[:, None]
    nxt = (k + 1) % np.maximum(count, 1)[:, None]
    cross = valid & (d * np.take_along_axis(d, nxt, axis=1) < 0)
    pos_first = d > 0
    ia = np.where(pos_first, k, nxt)
    ib = np.where(pos_first, nxt, k)
    da = np.take_along_axis(d, ia, axis=1)
    db = np.take_along_axis(d, ib, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(cross, da / (da - db), 0.0)
    return valid, cross, ia, ib, t


def corners_at(x: np.ndarray, i: np.ndarray) -> np.ndarray:
    """``x`` (n, K, c) per-corner values taken at corner indices ``i`` (n, m)."""
    return np.take_along_axis(x, i[..., None], axis=1)


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two tangents per unit normal (P, 3) (deterministic): the first is unit, the cross product
    of the normal with x (or with y when the normal is close to x); the second, normal x first."""
    n = np.asarray(normals, dtype=np.float64)
    helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(n, helper)
    ln = np.linalg.norm(t, axis=1)
    t = np.divide(t, ln[:, None], out=np.tile([[1.0, 0.0, 0.0]], (len(n), 1)), where=ln[:, None] > 0)
    return t, np.cross(n, t)


__all__ = ["edge_crossings", "corners_at", "tangent_frames"]
