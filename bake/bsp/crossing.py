"""Triangles that pass through each other: where a painter's order must cut, whatever the tree.

Two triangles *cross* when an edge of one passes through the other's inside: its ends lie on
opposite sides of the other's plane, each more than the tolerance off it, at a point more than
the tolerance inside the other's edges. Then each triangle has parts strictly in front of and
behind the other's plane, each may hide the other (bake/bsp/build.py's "may hide" relation both
ways), and no order of the two whole triangles is right from every eye: one of them is cut.
Triangles that share a corner (by position) are never a pair; triangles that only touch, or
pass within the tolerance, are not either.

Which faces to test comes, in meshes of 1,500 triangles or more, from MeshLab's per-face
self-intersection selection (``compute_selection_by_self_intersections_per_face``, compiled,
0.4 s for 69k triangles): it selects every face that intersects another it shares no vertex
with, so a superset of the faces in crossing pairs (tests/bsp/test_crossing.py checks the same
pairs come out without it). The pairs among the faces to test are found with a sweep of their
boxes along x and checked here in float64 with the tree's tolerance.

The BSP stage reports the count (``crossing`` in its record) and a warning: parts modelled to
pass through each other (eyes sunk into a head, walls through walls) cost cuts that parts that
touch or sit apart do not (docs/formats-bsp.md, Known limits).
"""

from __future__ import annotations

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components

_BLOCK = 512  # faces per block of the box sweep
# below this many triangles every face goes to the sweep (Suzanne's 968: 0.06 s), which is
# cheaper than loading MeshLab (about 0.2 s); above, MeshLab's selection first (the 69k bunny:
# 0.4 s against 6.7 s for every face)
_PREFILTER_FROM = 1500


def _candidate_pairs(lo: np.ndarray, hi: np.ndarray, tol: float) -> np.ndarray:
    """(k, 2) index pairs (a < b) whose boxes ``lo``/``hi`` overlap (grown by ``tol``): a sweep
    along x, a block of boxes at a time against the boxes that start before the block's last
    end."""
    n = len(lo)
    o = np.argsort(lo[:, 0], kind="stable")
    lo_s, hi_s = lo[o], hi[o]
    out = []
    for s in range(0, n, _BLOCK):
        e = min(n, s + _BLOCK)
        stop = int(np.searchsorted(lo_s[:, 0], hi_s[s:e, 0].max() + tol, side="right"))
        a = np.arange(s, e)
        b = np.arange(s, max(stop, e))
        ov = ((lo_s[a][:, None, :] <= hi_s[b][None, :, :] + tol) &
              (lo_s[b][None, :, :] <= hi_s[a][:, None, :] + tol)).all(axis=2)
        ia, ib = np.nonzero(ov)
        ia, ib = a[ia], b[ib]
        keep = ia < ib
        out.append(np.stack([o[ia[keep]], o[ib[keep]]], axis=1))
    P = np.concatenate(out) if out else np.zeros((0, 2), np.int64)
    return np.sort(P, axis=1)


def _edge_through(T: np.ndarray, E: np.ndarray, tol: float) -> np.ndarray:
    """Per pair: does an edge of triangle ``E[i]`` pass through the inside of ``T[i]``
    (``(k, 3, 3)`` corners each), by more than ``tol`` on every side?"""
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    ln = np.linalg.norm(n, axis=1)
    ok_t = ln > 0
    n = n / np.where(ok_t, ln, 1.0)[:, None]
    # inward normals of T's edges, in its plane
    en = [np.cross(n, T[:, (u + 1) % 3] - T[:, u]) for u in range(3)]
    en = [x / np.maximum(np.linalg.norm(x, axis=1), 1e-300)[:, None] for x in en]
    hit = np.zeros(len(T), bool)
    for k in range(3):
        p, q = E[:, k], E[:, (k + 1) % 3]
        dp = np.einsum("ij,ij->i", p - T[:, 0], n)
        dq = np.einsum("ij,ij->i", q - T[:, 0], n)
        through = ok_t & (((dp > tol) & (dq < -tol)) | ((dp < -tol) & (dq > tol)))
        t = np.where(through, dp / np.where(through, dp - dq, 1.0), 0.0)
        X = p + t[:, None] * (q - p)
        for u in range(3):
            through &= np.einsum("ij,ij->i", X - T[:, u], en[u]) > tol
        hit |= through
    return hit


def _selected(V: np.ndarray, F: np.ndarray, live: np.ndarray) -> np.ndarray:
    """The faces ``live`` that MeshLab finds intersecting a face they share no vertex with;
    all of them if MeshLab fails on the mesh (the selection only saves time)."""
    try:
        import pymeshlab

        ms = pymeshlab.MeshSet()
        ms.add_mesh(pymeshlab.Mesh(vertex_matrix=V, face_matrix=F[live].astype(np.int32)))
        ms.compute_selection_by_self_intersections_per_face()
        return live[np.flatnonzero(ms.current_mesh().face_selection_array())]
    except Exception:  # noqa: BLE001 -- any failure of the library: test every face instead
        return live


def crossing_pairs(V: np.ndarray, F: np.ndarray, tol: float) -> np.ndarray:
    """(k, 2) sorted pairs of triangle ids (rows sorted) that cross (module docstring); ``tol``
    in the units of ``V``."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64).reshape(-1, 3)
    none = np.zeros((0, 2), np.int64)
    if len(F) < 2:
        return none
    C = V[F]
    area2 = np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1)
    live = np.flatnonzero(area2 > 0)  # a triangle with no area crosses nothing
    if len(live) < 2:
        return none
    sel = live if len(live) < _PREFILTER_FROM else _selected(V, F, live)
    if len(sel) < 2:
        return none
    Cs = C[sel]
    P = _candidate_pairs(Cs.min(axis=1), Cs.max(axis=1), tol)
    if len(P) == 0:
        return none
    # corners shared by position
    _, vid = np.unique(V, axis=0, return_inverse=True)
    K = vid.reshape(-1)[F[sel]]
    share = (K[P[:, 0]][:, :, None] == K[P[:, 1]][:, None, :]).any(axis=(1, 2))
    P = P[~share]
    A, B = Cs[P[:, 0]], Cs[P[:, 1]]
    hit = _edge_through(A, B, tol) | _edge_through(B, A, tol)
    out = sel[P[hit]]
    out = np.sort(out, axis=1)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def parts(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Per triangle, its connected part (triangles joined through edges whose ends are at the
    same positions), numbered from 0 in order of each part's first triangle."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    T = len(F)
    if T == 0:
        return np.zeros(0, np.int64)
    _, vid = np.unique(np.asarray(V, np.float64), axis=0, return_inverse=True)
    K = vid.reshape(-1)[F]
    e = np.sort(np.concatenate([K[:, [0, 1]], K[:, [1, 2]], K[:, [2, 0]]]), axis=1)
    tri = np.tile(np.arange(T), 3)
    o = np.lexsort((tri, e[:, 1], e[:, 0]))
    e, tri = e[o], tri[o]
    same = (e[1:] == e[:-1]).all(axis=1)  # consecutive entries of one edge: join their triangles
    g = coo_matrix((np.ones(int(same.sum()), np.int8), (tri[:-1][same], tri[1:][same])), shape=(T, T))
    _, lab = connected_components(g, directed=False)
    _, first, inv = np.unique(lab, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv.reshape(-1)]


def summary(V: np.ndarray, F: np.ndarray, tol: float) -> dict:
    """The record's ``crossing`` figures: pairs, the triangles in them, the connected parts
    they lie in, and how many pairs lie within one part (a surface through itself)."""
    P = crossing_pairs(V, F, tol)
    if len(P) == 0:
        return {"pairs": 0, "triangles": 0, "parts": 0, "pairs_within_one_part": 0}
    lab = parts(V, F)
    return {"pairs": int(len(P)), "triangles": int(len(np.unique(P))),
            "parts": int(len(np.unique(lab[P]))),
            "pairs_within_one_part": int((lab[P[:, 0]] == lab[P[:, 1]]).sum())}


__all__ = ["crossing_pairs", "parts", "summary"]
