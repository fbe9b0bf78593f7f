"""Lightmap seams: UV seams (an edge shared by two triangles whose lightmap UVs differ) on smooth
geometry (dihedral angle <= ``SEAM_MAX_ANGLE``) are sampled on both sides (:func:`seam_edges`),
and a sparse least-squares solve moves the texels under those samples so that bilinear lookups
agree across the seam while staying close to their values (:func:`stitch_seams`).
:func:`seam_error` measures what is left.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..scene import Scene
from .atlas import Atlas
from .texels import bilinear_stencil, face_normals

SEAM_MAX_ANGLE = 30.0  # degrees: UV seams across sharper creases are left alone
SEAM_WEIGHT = 8.0  # least-squares weight of a seam sample against a texel's own value
PAD_WEIGHT = 0.05  # ... and of a padding texel (its value only matters for filtering)


@dataclass
class Seams:
    """Points sampled along UV seams: the same surface point seen from both sides."""

    xy_a: np.ndarray  # (n, 2) texel-space position on side A
    xy_b: np.ndarray  # (n, 2) ... on side B
    edge: np.ndarray  # (n,) seam edge id of each point
    tri_a: np.ndarray  # (E,) triangle of side A of each seam edge
    tri_b: np.ndarray  # (E,)
    smooth: np.ndarray  # (E,) dihedral angle <= SEAM_MAX_ANGLE
    count_all: int = 0  # UV seam edges (any angle)


def seam_edges(scene: Scene, atlas: Atlas, *, max_angle: float = SEAM_MAX_ANGLE,
               per_texel: float = 2.0) -> Seams:
    """Mesh edges shared by two mapped triangles (matched by vertex *position*, so split vertices
    still match) whose lightmap UVs differ at either end, sampled ``per_texel`` times per texel of
    the longer side (at least 2 points, at most 256)."""
    tris = scene.triangles
    T = len(tris)
    _, gid = np.unique(scene.positions, axis=0, return_inverse=True)
    g = gid.reshape(-1)[tris]  # (T, 3) geometric vertex ids
    xy = atlas.texel_xy()
    k0 = np.tile(np.arange(3), T)
    t = np.repeat(np.arange(T), 3)
    k1 = (k0 + 1) % 3
    va, vb = g[t, k0], g[t, k1]
    lo, hi = np.minimum(va, vb), np.maximum(va, vb)
    ok = atlas.mapped[t] & (va != vb)
    order = np.lexsort((t, hi, lo))
    order = order[ok[order]]
    L, Hh = lo[order], hi[order]
    same_next = (L[1:] == L[:-1]) & (Hh[1:] == Hh[:-1])
    # exactly two half-edges per edge: i, i+1 equal, and not part of a longer run
    run_start = np.ones(len(order), bool)
    run_start[1:] = ~same_next
    run_id = np.cumsum(run_start) - 1
    run_len = np.bincount(run_id)
    first = np.flatnonzero(run_start & (run_len[run_id] == 2))
    ea, eb = order[first], order[first + 1]
    ta, tb = t[ea], t[eb]
    # side A corners in its own order; side B's UV at the same geometric vertices
    a0, a1 = xy[ta, k0[ea]], xy[ta, k1[ea]]
    b_at = {0: xy[tb, k0[eb]], 1: xy[tb, k1[eb]]}
    flip = va[ea] != va[eb]  # B runs the other way
    b0 = np.where(flip[:, None], b_at[1], b_at[0])
    b1 = np.where(flip[:, None], b_at[0], b_at[1])
    differ = (np.abs(a0 - b0).max(axis=1) > 1e-6) | (np.abs(a1 - b1).max(axis=1) > 1e-6)
    fn, _ = face_normals(scene.positions, tris)
    cosang = np.einsum("ij,ij->i", fn[ta], fn[tb])
    sel = np.flatnonzero(differ)
    smooth = cosang[sel] >= math.cos(math.radians(max_angle))
    a0, a1, b0, b1 = a0[sel], a1[sel], b0[sel], b1[sel]
    la = np.linalg.norm(a1 - a0, axis=1)
    lb = np.linalg.norm(b1 - b0, axis=1)
    n = np.clip(np.ceil(per_texel * np.maximum(la, lb)), 2, 256).astype(np.int64)
    e = np.repeat(np.arange(len(sel)), n)
    k = np.arange(len(e)) - np.repeat(np.cumsum(n) - n, n)
    s = ((k + 0.5) / n[e])[:, None]
    return Seams(xy_a=a0[e] + s * (a1 - a0)[e], xy_b=b0[e] + s * (b1 - b0)[e], edge=e,
                 tri_a=ta[sel], tri_b=tb[sel], smooth=smooth, count_all=int(len(sel)))


def seam_error(image: np.ndarray, atlas: Atlas, seams: Seams, *, smooth_only: bool = True) -> dict:
    """Bilinear lookups on both sides of each seam point: max and mean of the largest channel
    difference (the image's units), over smooth seams (or all)."""
    img = np.asarray(image, dtype=np.float64)
    H, W = img.shape[:2]
    flat = img.reshape(H * W, -1)
    keep = seams.smooth[seams.edge] if smooth_only else np.ones(len(seams.edge), bool)
    if not keep.any():
        return {"points": 0, "max": 0.0, "mean": 0.0}
    ia, wa = bilinear_stencil(seams.xy_a[keep], W, H)
    ib, wb = bilinear_stencil(seams.xy_b[keep], W, H)
    d = np.abs(np.einsum("nk,nkc->nc", wa, flat[ia]) - np.einsum("nk,nkc->nc", wb, flat[ib])).max(axis=1)
    return {"points": int(keep.sum()), "max": float(d.max()), "mean": float(d.mean())}


def stitch_seams(image: np.ndarray, mask: np.ndarray, atlas: Atlas, seams: Seams, *,
                 seam_weight: float = SEAM_WEIGHT, pad_weight: float = PAD_WEIGHT) -> np.ndarray:
    """Least squares over the texels under smooth seams' bilinear stencils:

        minimise  sum_texels  w_i^2 (x_i - x0_i)^2  +  seam_weight^2 sum_points (B_a x - B_b x)^2

    with ``w_i = 1`` for covered texels and ``pad_weight`` for padding texels (``mask`` False).
    One sparse Cholesky-like solve (SuperLU) for all channels. Other texels are unchanged.
    """
    img = np.array(image, dtype=np.float64)
    one = img.ndim == 2
    if one:
        img = img[:, :, None]
    H, W, C = img.shape
    keep = seams.smooth[seams.edge]
    if not keep.any():
        return img[:, :, 0] if one else img
    ia, wa = bilinear_stencil(seams.xy_a[keep], W, H)
    ib, wb = bilinear_stencil(seams.xy_b[keep], W, H)
    cols = np.concatenate([ia, ib], axis=1)  # (n, 8) texel ids
    vals = np.concatenate([wa, -wb], axis=1)
    var, inv = np.unique(cols.ravel(), return_inverse=True)
    n = len(cols)
    from scipy import sparse  # (imported here: only a lightmap's seams need it)
    from scipy.sparse import linalg as sparse_linalg

    S = sparse.csr_matrix((vals.ravel() * seam_weight, (np.repeat(np.arange(n), 8), inv)),
                          shape=(n, len(var)))
    flat = img.reshape(H * W, C)
    wdat = np.where(np.asarray(mask).reshape(-1)[var], 1.0, pad_weight) ** 2
    A = (S.T @ S + sparse.diags(wdat)).tocsc()
    rhs = wdat[:, None] * flat[var]
    x = sparse_linalg.splu(A).solve(rhs)
    flat = flat.copy()
    flat[var] = x
    out = flat.reshape(H, W, C)
    return out[:, :, 0] if one else out
