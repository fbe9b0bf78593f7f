"""Triangles that pass through each other: where a painter's order must cut, whatever the tree.

Two triangles *cross* when an edge of one passes through the other's inside (its ends on
opposite sides of the other's plane, each more than the tolerance off it, meeting the plane more
than the tolerance inside the other's edges) and each has corners more than the tolerance on
both sides of the other's plane. Then each has parts strictly in front of and behind the other's
plane, each may hide the other (bake/bsp/build.py's "may hide" relation both ways, at the same
tolerance), and no order of the two whole triangles is right from every eye: one of them is cut
(the tree keeps a fragment whole only where a piece would be a sliver below ``min_area`` or
would collapse on the written grid). Triangles that share an edge (two corners, by position)
are never a pair; triangles that share one corner are a pair when the edge of one opposite that
corner passes through the other (a surface folded through itself, an eye that touches the head at
a corner and passes through it); triangles that only touch, or pass within the tolerance, are
not.

The pairs to check come from a uniform grid over the faces' boxes (cells the size of the median
box; a face spanning more than ``_MAX_CELLS`` cells is paired by its box with every face, in
blocks), so the work follows the faces' sizes and not the scene's extent (a far-off floor does
not crowd the model into a few cells), and the pairs and the box comparisons are made in chunks
of at most ``_CHUNK`` entries. A pair is kept only if the two boxes overlap, the two triangles straddle each other's
planes, and an edge passes through; all in float64, vectorised.

The BSP stage reports the count (``crossing`` in its record) and a warning: parts modelled to
pass through each other (eyes sunk into a head, walls through walls) cost cuts that parts that
touch or sit apart do not (docs/formats-bsp.md, Known limits).
"""

from __future__ import annotations

import numpy as np

_MAX_CELLS = 64  # a face over more grid cells than this is paired by boxes (see the docstring)
_CHUNK = 1 << 22  # entries per temporary array (pairs, or boxes compared)


def _overlap(lo: np.ndarray, hi: np.ndarray, a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return ((lo[a] <= hi[b]) & (lo[b] <= hi[a])).all(axis=1)


def _pairs_in_groups(key: np.ndarray, face: np.ndarray, lo: np.ndarray, hi: np.ndarray) -> list[np.ndarray]:
    """Pairs of faces that share a key (a grid cell) and whose boxes overlap; entries sorted by
    key. Generated a run of entries at a time, at most about _CHUNK pairs each."""
    n = len(key)
    if n < 2:
        return []
    brk = np.flatnonzero(key[1:] != key[:-1]) + 1
    end = np.repeat(np.concatenate([brk, [n]]), np.diff(np.concatenate([[0], brk, [n]])))
    after = end - np.arange(n) - 1  # partners after each entry in its cell
    out = []
    cum = np.cumsum(after)
    s = 0
    while s < n:
        # entries s .. e-1: about _CHUNK pairs (at least one entry)
        e = max(s + 1, int(np.searchsorted(cum, (cum[s - 1] if s else 0) + _CHUNK, side="right")))
        e = min(e, n)
        cnt = after[s:e]
        tot = int(cnt.sum())
        if tot:
            i = np.repeat(np.arange(s, e), cnt)
            j = i + 1 + (np.arange(tot) - np.repeat(np.cumsum(cnt) - cnt, cnt))
            a, b = face[i], face[j]  # (distinct: a face has one entry per cell)
            keep = _overlap(lo, hi, a, b)
            out.append(np.stack([np.minimum(a, b)[keep], np.maximum(a, b)[keep]], axis=1))
        s = e
    return out


def _candidate_pairs(lo: np.ndarray, hi: np.ndarray, tol: float) -> np.ndarray:
    """(k, 2) index pairs (a < b, unique, sorted) whose boxes ``lo``/``hi`` overlap once grown by
    ``tol``."""
    lo = np.asarray(lo, np.float64) - tol
    hi = np.asarray(hi, np.float64) + tol
    n = len(lo)
    if n < 2:
        return np.zeros((0, 2), np.int64)
    ext = (hi - lo).max(axis=1)
    h = float(np.median(ext))
    if not h > 0:
        h = float(ext.max()) or 1.0
    origin = lo.min(axis=0)
    i0 = np.floor((lo - origin) / h)
    i1 = np.floor((hi - origin) / h)
    span = i1 - i0 + 1
    big = span.prod(axis=1) > _MAX_CELLS
    out = []
    # faces over a few cells: one entry per cell, pairs within each cell
    small = np.flatnonzero(~big)
    if len(small):
        sp = span[small].astype(np.int64)
        cnt = sp.prod(axis=1)
        face = np.repeat(small, cnt)
        k = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        spf = np.repeat(sp, cnt, axis=0)
        base = np.repeat(i0[small].astype(np.int64), cnt, axis=0)
        cell = base + np.stack([k % spf[:, 0], (k // spf[:, 0]) % spf[:, 1], k // (spf[:, 0] * spf[:, 1])], axis=1)
        dims = cell.max(axis=0) + 1
        if float(dims[0]) * float(dims[1]) * float(dims[2]) < 2.0 ** 62:
            key = (cell[:, 0] * dims[1] + cell[:, 1]) * dims[2] + cell[:, 2]
        else:  # a grid too large for one int64 key: number the cells
            key = np.unique(cell, axis=0, return_inverse=True)[1].reshape(-1)
        o = np.argsort(key, kind="stable")  # (entries come in face order: kept within a cell)
        out += _pairs_in_groups(key[o], face[o], lo, hi)
    # faces over many cells: against every face by boxes, a block of them at a time
    bigs = np.flatnonzero(big)
    if len(bigs):
        rows = max(1, _CHUNK // n)
        every = np.arange(n)
        for s in range(0, len(bigs), rows):
            a = bigs[s:s + rows]
            ov = ((lo[a][:, None, :] <= hi[None, :, :]) & (lo[None, :, :] <= hi[a][:, None, :])).all(axis=2)
            ia, ib = np.nonzero(ov)
            ia, ib = a[ia], every[ib]
            keep = ia != ib
            out.append(np.stack([np.minimum(ia, ib)[keep], np.maximum(ia, ib)[keep]], axis=1))
    if not out:
        return np.zeros((0, 2), np.int64)
    P = np.concatenate(out)
    u = np.sort(P[:, 0] * np.int64(n) + P[:, 1])
    u = u[np.concatenate([[True], u[1:] != u[:-1]])] if len(u) else u
    return np.stack([u // n, u % n], axis=1)


def _unit_normals(T: np.ndarray) -> np.ndarray:
    """Unit normals of the triangles ``T`` (k, 3, 3); zero for a triangle with no area (it then
    straddles nothing and nothing passes through it)."""
    n = np.cross(T[:, 1] - T[:, 0], T[:, 2] - T[:, 0])
    ln = np.linalg.norm(n, axis=1)
    return n / np.where(ln > 0, ln, np.inf)[:, None]


def _straddles(T: np.ndarray, nT: np.ndarray, E: np.ndarray, tol: float) -> np.ndarray:
    """Per pair: has triangle ``E[i]`` corners more than ``tol`` on both sides of ``T[i]``'s
    plane (unit normal ``nT[i]``)?"""
    d = np.einsum("ikj,ij->ik", E - T[:, :1], nT)
    return (d.max(axis=1) > tol) & (d.min(axis=1) < -tol)


def _edge_through(T: np.ndarray, nT: np.ndarray, E: np.ndarray, tol: float) -> np.ndarray:
    """Per pair: does an edge of triangle ``E[i]`` pass through the inside of ``T[i]`` (unit
    normal ``nT[i]``), by more than ``tol`` on every side?"""
    # inward normals of T's edges, in its plane
    en = [np.cross(nT, T[:, (u + 1) % 3] - T[:, u]) for u in range(3)]
    en = [x / np.maximum(np.linalg.norm(x, axis=1), 1e-300)[:, None] for x in en]
    hit = np.zeros(len(T), bool)
    for k in range(3):
        p, q = E[:, k], E[:, (k + 1) % 3]
        dp = np.einsum("ij,ij->i", p - T[:, 0], nT)
        dq = np.einsum("ij,ij->i", q - T[:, 0], nT)
        through = ((dp > tol) & (dq < -tol)) | ((dp < -tol) & (dq > tol))
        t = np.where(through, dp / np.where(through, dp - dq, 1.0), 0.0)
        X = p + t[:, None] * (q - p)
        for u in range(3):
            through &= np.einsum("ij,ij->i", X - T[:, u], en[u]) > tol
        hit |= through
    return hit


def _crosses(A: np.ndarray, B: np.ndarray, tol: float) -> np.ndarray:
    """Per pair of triangles (``(k, 3, 3)`` corners each): do they cross (module docstring)?"""
    nA, nB = _unit_normals(A), _unit_normals(B)
    both = _straddles(A, nA, B, tol) & _straddles(B, nB, A, tol)
    i = np.flatnonzero(both)
    hit = np.zeros(len(A), bool)
    hit[i] = _edge_through(A[i], nA[i], B[i], tol) | _edge_through(B[i], nB[i], A[i], tol)
    return hit


def _position_ids(V: np.ndarray) -> np.ndarray:
    """Per vertex, an id shared by the vertices at the same position."""
    return np.unique(np.asarray(V, np.float64), axis=0, return_inverse=True)[1].reshape(-1)


def crossing_pairs(V: np.ndarray, F: np.ndarray, tol: float, ids: np.ndarray | None = None) -> np.ndarray:
    """(k, 2) pairs of triangle ids (each row sorted, rows sorted) that cross (module
    docstring); ``tol`` in the units of ``V``; ``ids``: :func:`_position_ids` of ``V`` if known."""
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
    Cl = C[live]
    P = _candidate_pairs(Cl.min(axis=1), Cl.max(axis=1), tol)
    if len(P) == 0:
        return none
    # corners shared by position: neighbours across an edge cannot cross (each has a corner on
    # the other's plane, the shared edge, and its third on one side of it), the test skips them
    K = (_position_ids(V) if ids is None else ids)[F[live]]
    found = []
    for s in range(0, len(P), _CHUNK // 16):
        Q = P[s:s + _CHUNK // 16]
        Q = Q[(K[Q[:, 0]][:, :, None] == K[Q[:, 1]][:, None, :]).any(axis=2).sum(axis=1) < 2]
        found.append(live[Q[_crosses(Cl[Q[:, 0]], Cl[Q[:, 1]], tol)]])
    out = np.sort(np.concatenate(found), axis=1)
    return out[np.lexsort((out[:, 1], out[:, 0]))]


def parts(V: np.ndarray, F: np.ndarray, ids: np.ndarray | None = None) -> np.ndarray:
    """Per triangle, its connected part (triangles joined through edges whose ends are at the
    same positions), numbered from 0 in order of each part's first triangle; ``ids``:
    :func:`_position_ids` of ``V`` if known."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    T = len(F)
    if T == 0:
        return np.zeros(0, np.int64)
    K = (_position_ids(V) if ids is None else ids)[F]
    e = np.sort(np.concatenate([K[:, [0, 1]], K[:, [1, 2]], K[:, [2, 0]]]), axis=1)
    tri = np.tile(np.arange(T), 3)
    o = np.lexsort((tri, e[:, 1], e[:, 0]))
    e, tri = e[o], tri[o]
    same = (e[1:] == e[:-1]).all(axis=1)  # consecutive entries of one edge: join their triangles
    from scipy.sparse import coo_matrix  # (imported here: a bake that reuses its tree needs no scipy)
    from scipy.sparse.csgraph import connected_components

    g = coo_matrix((np.ones(int(same.sum()), np.int8), (tri[:-1][same], tri[1:][same])), shape=(T, T))
    _, lab = connected_components(g, directed=False)
    _, first, inv = np.unique(lab, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv.reshape(-1)]


def summary(V: np.ndarray, F: np.ndarray, tol: float) -> dict:
    """The record's ``crossing`` figures: pairs, the triangles in them, the connected parts
    they lie in, and how many pairs lie within one part (a surface through itself)."""
    ids = _position_ids(V)
    P = crossing_pairs(V, F, tol, ids)
    if len(P) == 0:
        return {"pairs": 0, "triangles": 0, "parts": 0, "pairs_within_one_part": 0}
    lab = parts(V, F, ids)
    return {"pairs": int(len(P)), "triangles": int(len(np.unique(P))),
            "parts": int(len(np.unique(lab[P]))),
            "pairs_within_one_part": int((lab[P[:, 0]] == lab[P[:, 1]]).sum())}


__all__ = ["crossing_pairs", "parts", "summary"]
