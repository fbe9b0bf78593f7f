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
