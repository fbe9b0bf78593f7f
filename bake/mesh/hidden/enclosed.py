"""Triangles no outside eye can see, by proof rather than sampling: those inside a closed,
opaque, two-sided part (docs/hidden.md, "Enclosed triangles").

A *shell* is a part (triangles joined through shared corners, by position) whose edges are each
used by an even number of its triangles (a closed surface, so a point off it is inside or outside
by the parity of the crossings of any ray from the point), every triangle two-sided and opaque.
Every path from outside a shell to a point inside it crosses the shell, and the first crossing
from the eye's side is a triangle drawn from that side that stops the ray: nothing inside a shell
shows to an eye outside it. The outside region's eyes are outside every part's convex hull, so
outside every shell.

A triangle is *enclosed* by a shell when no triangle of the shell comes near it (their bounding
boxes, grown by a tolerance, do not meet: then the triangle does not meet the shell's surface, so
all of it is on one side) and its centroid is inside (an odd count of crossings of the shell,
along each of ``len(DIRECTIONS)`` fixed rays: all must agree, so one ray through an edge (counted
twice or not at all) cannot make a triangle enclosed). Rays count every hit to the end (no
culling, nothing stops them), each continuation from just past the hit, at most ``MAX_HITS``
hits (a ray that needs more decides nothing).
"""

from __future__ import annotations

import numpy as np

from ...bsp.crossing import _candidate_pairs

DIRECTIONS = np.array([[0.5377, 0.8012, 0.2625], [-0.7071, 0.3127, 0.6342], [0.1893, -0.4102, -0.8921]])
DIRECTIONS = DIRECTIONS / np.linalg.norm(DIRECTIONS, axis=1, keepdims=True)
MAX_HITS = 512


def parts(corners: np.ndarray) -> tuple[int, np.ndarray]:
    """(number of parts, part of each triangle): triangles joined through shared corners."""
    import scipy.sparse as sp
    from scipy.sparse.csgraph import connected_components

    V = int(corners.max()) + 1
    a = corners.ravel()
    b = np.roll(corners, 1, axis=1).ravel()
    g = sp.coo_matrix((np.ones(len(a), np.int8), (a, b)), shape=(V, V))
    n, lab = connected_components(g, directed=False)
    return int(n), lab[corners[:, 0]]


def shells(corners: np.ndarray, part: np.ndarray, n_parts: int, two_sided: np.ndarray,
           see_through: np.ndarray) -> np.ndarray:
    """(n_parts,) bool: the parts that are shells (closed, every triangle two-sided and opaque)."""
    e = np.concatenate([corners[:, [0, 1]], corners[:, [1, 2]], corners[:, [2, 0]]])
    e = np.sort(e, axis=1)
    V = int(corners.max()) + 1
    key = e[:, 0] * V + e[:, 1]
    _, inv, cnt = np.unique(key, return_inverse=True, return_counts=True)
    odd = (cnt % 2 == 1)[inv.ravel()]
    T = len(corners)
    ok = np.ones(n_parts, bool)
    ok[part[np.tile(np.arange(T), 3)[odd]]] = False
    ok[part[~two_sided | see_through]] = False
    return ok


def enclosed(vis, corners: np.ndarray, test: np.ndarray, tol: float) -> tuple[np.ndarray, dict]:
    """(T,) bool: the triangles of ``test`` (ids) enclosed by a shell (module docstring), and counts."""
    T = vis.T
    out = np.zeros(T, bool)
    n_parts, part = parts(corners)
    shell = shells(corners, part, n_parts, vis.two_sided, vis.see_through)
    info = {"parts": n_parts, "shells": int(shell.sum()), "tested": int(len(test)), "enclosed": 0}
    test = np.asarray(test, np.int64)
    if not shell.any() or len(test) == 0:
        return out, info
    # near: (triangle, shell) pairs whose boxes meet (the triangle may touch the shell's surface)
    c = vis.corners
    pairs = _candidate_pairs(c.min(axis=1), c.max(axis=1), tol)
    a, b = np.concatenate([pairs[:, 0], pairs[:, 1]]), np.concatenate([pairs[:, 1], pairs[:, 0]])
    keep = shell[part[b]]
    near = np.unique(a[keep] * n_parts + part[b[keep]])
    # parity of each shell's crossings along each direction from the centroids of the tested
    p = c[test].mean(axis=1)
    odd_all = None
    for d in DIRECTIONS:
        ray, prim = _all_hits(vis, p, d)
        s = shell[part[prim]]
        key = ray[s] * n_parts + part[prim[s]]
        k, cnt = np.unique(key, return_counts=True)
        odd = k[cnt % 2 == 1]
        odd_all = odd if odd_all is None else np.intersect1d(odd_all, odd, assume_unique=True)
    i, K = odd_all // n_parts, odd_all % n_parts
    t = test[i]
    good = (K != part[t]) & ~np.isin(t * n_parts + K, near)
    out[t[good]] = True
    info["enclosed"] = int(out.sum())
    return out, info


def _all_hits(vis, p: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(ray, triangle) of every hit of rays from world points ``p`` along unit ``d`` (shared), to the
    end; a ray with more than MAX_HITS hits is dropped (its hits are not returned)."""
    tr = vis.tracer
    n = len(p)
    idx = np.arange(n)
    start = tr.to_local(p)
    d32 = np.ascontiguousarray(np.broadcast_to(d.astype(np.float32), (n, 3)))
    rays, prims = [], []
    for _ in range(MAX_HITS):
        if len(idx) == 0:
            break
        h = tr.intersect(start.astype(np.float32), d32[:len(idx)])
        vis.rays += len(idx)
        prim = np.asarray(h["prim"], np.int64)
        hit = np.flatnonzero((prim >= 0) & (prim < vis.T))
        rays.append(idx[hit])
        prims.append(prim[hit])
        idx, start = idx[hit], start[hit]
        at = start + np.asarray(h["t"], np.float64)[hit][:, None] * d[None, :]
        start = at + tr.epsilon(at)[:, None] * d[None, :]
    ray, prim = np.concatenate(rays), np.concatenate(prims)
    if len(idx):  # still going: undecided
        bad = np.isin(ray, idx)
        ray, prim = ray[~bad], prim[~bad]
    return ray, prim


__all__ = ["enclosed", "shells", "parts", "DIRECTIONS", "MAX_HITS"]
