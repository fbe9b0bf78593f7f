"""Small helpers for meshes that tests build in code (shared by the test folders)."""

from __future__ import annotations

import numpy as np


def merge(*parts: tuple[np.ndarray, np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
    """Concatenate ``(vertices, triangles)`` parts into one mesh, offsetting the indices."""
    vs, ts, off = [], [], 0
    for v, t in parts:
        vs.append(np.asarray(v))
        ts.append(np.asarray(t) + off)
        off += len(v)
    return np.concatenate(vs), np.concatenate(ts)


def heightfield(n: int, z=None) -> tuple[np.ndarray, np.ndarray]:
    """The unit square as an n x n grid of vertices (vertex ``i * n + j`` at x = i/(n-1),
    y = j/(n-1)), two triangles per cell, at height ``z(x, y)`` (0 without it)."""
    x, y = np.meshgrid(np.linspace(0, 1, n), np.linspace(0, 1, n), indexing="ij")
    h = np.zeros_like(x) if z is None else z(x, y)
    V = np.stack([x.ravel(), y.ravel(), h.ravel()], axis=1)
    k = np.arange(n * n).reshape(n, n)
    a, b, c, d = k[:-1, :-1].ravel(), k[1:, :-1].ravel(), k[1:, 1:].ravel(), k[:-1, 1:].ravel()
    return V, np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
