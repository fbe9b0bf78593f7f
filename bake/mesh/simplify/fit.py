"""Refit a simplified mesh's vertex positions to the original surface (least squares).

Edge collapse decides the connectivity; where the kept vertices sit is then a linear problem.
Each round pairs points with their closest points on the other surface, both ways:

* points on the original (its vertices and area-weighted samples) with their closest point on
  the simplified mesh, written as barycentric weights of that triangle's corners;
* area-weighted points on the simplified mesh with their closest point on the original;

and solves, for the free vertices, the sparse least-squares problem
``sum |sum_j w_j v_j - target|^2 + kappa * sum_edges |(v_a - v_b) - (v0_a - v0_b)|^2``
(the second term keeps the displacement smooth, not the edges short). This is the distance
energy of Hoppe et al., "Mesh Optimization" (SIGGRAPH 1993) with the connectivity held fixed;
the code here is ours. A vertex whose move would turn any of its triangles over (its normal
against the normal before the fit) is put back, so the fit never adds a flipped triangle.
Fixed vertices (open borders, material edges) do not move.
"""

from __future__ import annotations

import numpy as np
import scipy.sparse as sp
from scipy.sparse.linalg import spsolve

from .error import SurfaceIndex, sample_surface

__all__ = ["refit", "barycentric"]


def barycentric(P: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (n, 3) of points in (or projected onto) triangles ABC, clipped
    into the triangle."""
    b = plane_barycentric(P, A, B, C)
    return np.clip(b, 0.0, 1.0) / np.clip(b, 0.0, 1.0).sum(axis=1, keepdims=True).clip(1e-300)


def plane_barycentric(P: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Barycentric coordinates (n, 3) of points projected onto the planes of triangles ABC (not
    clipped; a degenerate triangle gives its centre)."""
    v0, v1, v2 = B - A, C - A, P - A
    d00 = np.einsum("ij,ij->i", v0, v0)
    d01 = np.einsum("ij,ij->i", v0, v1)
    d11 = np.einsum("ij,ij->i", v1, v1)
    d20 = np.einsum("ij,ij->i", v2, v0)
    d21 = np.einsum("ij,ij->i", v2, v1)
    den = d00 * d11 - d01 * d01
    ok = den > 0
    den = np.where(ok, den, 1.0)
    v = np.where(ok, (d11 * d20 - d01 * d21) / den, 1.0 / 3.0)
    w = np.where(ok, (d00 * d21 - d01 * d20) / den, 1.0 / 3.0)
    return np.stack([1.0 - v - w, v, w], axis=1)


def _normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


def refit(V: np.ndarray, F: np.ndarray, fixed: np.ndarray, index_a: SurfaceIndex, points_a: np.ndarray, *,
          iterations: int = 3, kappa: float = 1e-3, samples_b: int = 20000, seed: int = 0,
          emphasis: float = 0.0) -> tuple[np.ndarray, dict]:
    """New positions for ``V`` (only vertices used by ``F`` and not ``fixed`` move)."""
    V0 = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64)
    nv = len(V0)
    info = {"rounds": 0, "reverted_vertices": 0}
    if iterations <= 0 or len(F) == 0 or len(points_a) == 0:
        return V0.copy(), info
    used = np.zeros(nv, bool)
    used[F.ravel()] = True
    free = used & ~np.asarray(fixed, bool)
    if not free.any():
        return V0.copy(), info
    rng = np.random.default_rng(seed)
    n_ref = _normals(V0, F)
    edges = np.unique(np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1), axis=0)
    ne = len(edges)
    Vc = V0.copy()
    reverted_total = np.zeros(nv, bool)
    for it in range(iterations):
        ib = SurfaceIndex(Vc, F, seed=seed + 7)
        da, tb, qb = ib.query(points_a)
        wb = barycentric(qb, Vc[F[tb, 0]], Vc[F[tb, 1]], Vc[F[tb, 2]])
        yb, ty, wy = sample_surface(Vc, F, samples_b, rng)
        db, _, qa = index_a.query(yb)
        na, nb = len(points_a), len(yb)
        # rows far from the other surface weigh more after the first round (an iteratively
        # reweighted fit that leans from the mean towards the maximum distance)
        if emphasis > 0 and it > 0:
            dist = np.concatenate([da, db])
            ref = float(np.mean(dist)) or 1.0
            rw = np.sqrt(1.0 + (dist / ref) ** emphasis)
        else:
            rw = np.ones(na + nb)
        rows = np.concatenate([np.repeat(np.arange(na), 3), na + np.repeat(np.arange(nb), 3)])
        cols = np.concatenate([F[tb].ravel(), F[ty].ravel()])
        vals = np.concatenate([wb.ravel(), wy.ravel()]) * np.repeat(rw, 3)
        A = sp.csr_matrix((vals, (rows, cols)), shape=(na + nb, nv))
        rhs = np.concatenate([points_a, qa]) * rw[:, None]
        s = np.sqrt(kappa * (na + nb) / max(ne, 1))
        er = np.arange(ne)
        S = sp.csr_matrix((np.r_[np.full(ne, s), np.full(ne, -s)], (np.r_[er, er], np.r_[edges[:, 0], edges[:, 1]])),
                          shape=(ne, nv))
        srhs = s * (V0[edges[:, 0]] - V0[edges[:, 1]])
        # a small pull towards the current position keeps every free vertex determined
        eps = 1e-6 * (na + nb) / max(int(free.sum()), 1)
        M = sp.vstack([A, S]).tocsc()
        R = np.concatenate([rhs, srhs])
        fi = np.flatnonzero(free)
        Mf = M[:, fi]
        Rf = R - M[:, ~free] @ Vc[~free]
        N = (Mf.T @ Mf + eps * sp.identity(len(fi), format="csc")).tocsc()
        sol = spsolve(N, Mf.T @ Rf + eps * Vc[fi])
        if sol.ndim == 1:
            sol = sol.reshape(-1, 3)
        if not np.isfinite(sol).all():
            break
        Vn = Vc.copy()
        Vn[fi] = sol
        # never turn a triangle over (against the simplifier's own normal) or collapse it
        for _ in range(32):
            n_new = _normals(Vn, F)
            bad = np.einsum("ij,ij->i", n_new, n_ref) <= 0.0
            bad &= np.linalg.norm(n_ref, axis=1) > 0
            if not bad.any():
                break
            back = np.unique(F[bad].ravel())
            back = back[free[back]]
            if len(back) == 0:
                break
            reverted_total[back] = True
            Vn[back] = Vc[back]
        Vc = Vn
        info["rounds"] += 1
    info["reverted_vertices"] = int(reverted_total.sum())
    return Vc, info
