"""How far a simplified surface is from the original: sampled symmetric Hausdorff distance.

Both directions are measured: points on the original surface against the simplified one
(features that were cut off) and points on the simplified surface against the original
(triangles that bulge out). Query points are every vertex of the sampled mesh plus
``samples`` area-weighted random points (seeded, so the figure is reproducible).

Distances are exact point-to-triangle distances. The triangles tried for each query point are
the owners of its ``k`` nearest neighbours among dense samples of the target surface (a
scipy KD-tree over every triangle's centroid and corners plus area-weighted points), so a
reported distance is never below the true one and exceeds it by at most the local sample
spacing, which only happens when none of those ``k`` samples lies on the closest triangle.
The module also answers "which triangle is closest" for carrying attributes, and holds the
checks the simplify stage reports: flipped triangles and edge topology.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

__all__ = ["SurfaceIndex", "sample_surface", "point_triangle_distance", "hausdorff", "HausdorffResult",
           "triangle_normals", "triangle_areas", "topology",
           "edge_counts", "flipped_triangles", "flip_votes"]


def triangle_areas(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    if len(F) == 0:
        return np.zeros(0)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    return 0.5 * np.linalg.norm(np.cross(b - a, c - a), axis=1)


def triangle_normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """Unit normals (zero for degenerate triangles)."""
    if len(F) == 0:
        return np.zeros((0, 3))
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    n = np.cross(b - a, c - a)
    ln = np.linalg.norm(n, axis=1, keepdims=True)
    return np.divide(n, ln, out=np.zeros_like(n), where=ln > 0)


def sample_surface(V: np.ndarray, F: np.ndarray, n: int, rng: np.random.Generator
                   ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``n`` area-weighted random points: (points (n,3), triangle ids (n,), barycentrics (n,3))."""
    area = triangle_areas(V, F)
    total = float(area.sum())
    if n <= 0 or len(F) == 0:
        return np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros((0, 3))
    if total > 0:
        cdf = np.cumsum(area) / total
        tri = np.searchsorted(cdf, rng.random(n), side="right")
        tri = np.minimum(tri, len(F) - 1)
    else:  # everything degenerate: spread over triangles uniformly
        tri = rng.integers(0, len(F), n)
    r1 = np.sqrt(rng.random(n))
    r2 = rng.random(n)
    bary = np.stack([1.0 - r1, r1 * (1.0 - r2), r1 * r2], axis=1)
    pts = np.einsum("nk,nkd->nd", bary, V[F[tri]])
    return pts, tri.astype(np.int64), bary


def point_triangle_distance(P: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Exact distance from points ``P`` to triangles ``ABC`` (all (..., 3), broadcast), and the
    closest points. Degenerate triangles fall back to their edges."""
    ab, ac = B - A, C - A
    n = np.cross(ab, ac)
    nn = np.einsum("...d,...d->...", n, n)
    ap = P - A
    # barycentric coordinates of the projection onto the plane
    with np.errstate(invalid="ignore", divide="ignore"):
        inv = np.where(nn > 0, 1.0 / np.where(nn > 0, nn, 1.0), 0.0)
        v = np.einsum("...d,...d->...", np.cross(ap, ac), n) * inv
        w = np.einsum("...d,...d->...", np.cross(ab, ap), n) * inv
    u = 1.0 - v - w
    inside = (nn > 0) & (u >= 0) & (v >= 0) & (w >= 0)
    proj = A + v[..., None] * ab + w[..., None] * ac

    def seg(p0: np.ndarray, p1: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        d = p1 - p0
        dd = np.einsum("...d,...d->...", d, d)
        t = np.einsum("...d,...d->...", P - p0, d) / np.where(dd > 0, dd, 1.0)
        t = np.clip(np.where(dd > 0, t, 0.0), 0.0, 1.0)
        q = p0 + t[..., None] * d
        return np.einsum("...d,...d->...", P - q, P - q), q

    d1, q1 = seg(A, B)
    d2, q2 = seg(B, C)
    d3, q3 = seg(C, A)
    best = d1.copy()
    q = q1.copy()
    m = d2 < best
    best = np.where(m, d2, best)
    q = np.where(m[..., None], q2, q)
    m = d3 < best
    best = np.where(m, d3, best)
    q = np.where(m[..., None], q3, q)
    q = np.where(inside[..., None], proj, q)
    diff = P - q
    return np.sqrt(np.einsum("...d,...d->...", diff, diff)), q


class SurfaceIndex:
    """Closest-triangle queries against one triangle mesh."""

    def __init__(self, V: np.ndarray, F: np.ndarray, *, density: int = 50_000, k: int = 4, seed: int = 0):
        self.V = np.asarray(V, np.float64)
        self.F = np.asarray(F, np.int64).reshape(-1, 3)
        self.k = k
        if len(self.F) == 0:
            self.tree = None
            return
        rng = np.random.default_rng(seed)
        tri_pts = self.V[self.F]
        # centroids and points near each corner (inside the triangle, so each belongs to one owner)
        cent = tri_pts.mean(axis=1)
        near = 0.9 * tri_pts + 0.1 * cent[:, None, :]
        extra = max(0, density - 4 * len(self.F))
        rp, rt, _ = sample_surface(self.V, self.F, extra, rng)
        self.points = np.concatenate([cent, near.reshape(-1, 3), rp])
        self.owner = np.concatenate([np.arange(len(self.F)), np.repeat(np.arange(len(self.F)), 3), rt])
        self.tree = cKDTree(self.points)
        self.centers = cent
        self.radii = np.linalg.norm(tri_pts - cent[:, None, :], axis=2).max(axis=1)

    def exact(self, P: np.ndarray, upper: np.ndarray, chunk: int = 32) -> tuple[np.ndarray, np.ndarray]:
        """Exact distances and closest triangles for a few points, given upper bounds: every
        triangle whose bounding sphere comes within ``upper`` of a point is measured."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        dist = np.asarray(upper, np.float64).copy()
        tri = np.full(len(P), -1, np.int64)
        for s in range(0, len(P), chunk):
            p = P[s:s + chunk]
            lb = np.linalg.norm(p[:, None, :] - self.centers[None, :, :], axis=2) - self.radii[None, :]
            rows, tris = np.nonzero(lb <= dist[s:s + chunk, None] * (1 + 1e-12) + 1e-300)
            if len(rows) == 0:
                continue
            tv = self.V[self.F[tris]]
            d, _ = point_triangle_distance(p[rows], tv[:, 0], tv[:, 1], tv[:, 2])
            best = np.full(len(p), np.inf)
            np.minimum.at(best, rows, d)
            upd = best <= dist[s:s + chunk]
            ok = np.flatnonzero(upd)
            dist[s + ok] = best[ok]
            hit = d == best[rows]
            tri[s + rows[hit]] = tris[hit]
        return dist, tri

    def candidates(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(point index, candidate triangle, exact distance) for every distinct candidate pair."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        m = len(P)
        if self.tree is None or m == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros(0)
        k = int(min(self.k, len(self.points)))
        _, nb = self.tree.query(P, k=k, workers=-1)
        cand = np.sort(self.owner[nb.reshape(m, k)], axis=1)
        # the k samples mostly share one or two owners: measure each (point, triangle) once
        keep = np.ones_like(cand, dtype=bool)
        keep[:, 1:] = cand[:, 1:] != cand[:, :-1]
        rows, cols = np.nonzero(keep)
        tris = cand[rows, cols]
        tv = self.V[self.F[tris]]
        d, _ = point_triangle_distance(P[rows], tv[:, 0], tv[:, 1], tv[:, 2])
        return rows, tris, d

    def query(self, P: np.ndarray, chunk: int = 65536) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(distances (n,), closest triangle (n,), closest points (n,3)); distances are upper
        bounds that are exact unless the KD-tree candidates miss the closest triangle."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        n = len(P)
        if self.tree is None or n == 0:
            return np.full(n, np.inf), np.full(n, -1, np.int64), np.full((n, 3), np.nan)
        dist = np.empty(n)
        tri = np.empty(n, np.int64)
        cp = np.empty((n, 3))
        for s in range(0, n, chunk):
            p = P[s:s + chunk]
            m = len(p)
            rows, tris, d = self.candidates(p)
            starts = np.flatnonzero(np.r_[True, rows[1:] != rows[:-1]])
            dmin = np.minimum.reduceat(d, starts)
            hit = d == np.repeat(dmin, np.diff(np.r_[starts, len(rows)]))
            idx = np.flatnonzero(hit)
            first = idx[np.r_[True, rows[idx[1:]] != rows[idx[:-1]]]]
            tv = self.V[self.F[tris[first]]]
            _, q = point_triangle_distance(p, tv[:, 0], tv[:, 1], tv[:, 2])
            dist[s:s + m] = dmin
            tri[s:s + m] = tris[first]
            cp[s:s + m] = q
        return dist, tri, cp


@dataclass
class HausdorffResult:
    max: float  # absolute units
    mean: float  # mean of the two directions' area-weighted means
    max_a_to_b: float  # original -> simplified (features cut off)
    max_b_to_a: float  # simplified -> original (bulges)
    mean_a_to_b: float
    mean_b_to_a: float
    worst_point: np.ndarray  # where the max was found
    samples: int


def _directed(Vq: np.ndarray, Fq: np.ndarray, index: SurfaceIndex, samples: int, rng: np.random.Generator
              ) -> tuple[float, float, np.ndarray]:
    pts, _, _ = sample_surface(Vq, Fq, samples, rng)
    used = np.unique(Fq.ravel()) if len(Fq) else np.zeros(0, np.int64)
    all_p = np.concatenate([pts, Vq[used]])
    if len(all_p) == 0:
        return 0.0, 0.0, np.zeros(3)
    all_d, _, _ = index.query(all_p)
    # The KD-tree pass gives upper bounds; make the largest ones exact until the maximum is a
    # verified distance (every other point's true distance is below its bound, so below it).
    verified = np.zeros(len(all_d), bool)
    for _ in range(64):
        i = int(np.argmax(all_d))
        if verified[i]:
            break
        top = np.argsort(-all_d, kind="stable")[:64]
        top = top[~verified[top]]
        all_d[top], _ = index.exact(all_p[top], all_d[top])
        verified[top] = True
    mean = float(all_d[:len(pts)].mean()) if len(pts) else 0.0
    i = int(np.argmax(all_d))
    return float(all_d[i]), mean, all_p[i]


def hausdorff(Va: np.ndarray, Fa: np.ndarray, Vb: np.ndarray, Fb: np.ndarray, *, samples: int = 20000,
              seed: int = 0, index_a: SurfaceIndex | None = None) -> HausdorffResult:
    """Symmetric sampled Hausdorff distance between surface A (original) and B (simplified)."""
    Fa = np.asarray(Fa, np.int64).reshape(-1, 3)
    Fb = np.asarray(Fb, np.int64).reshape(-1, 3)
    if len(Fa) == 0 or len(Fb) == 0:
        inf = 0.0 if len(Fa) == len(Fb) else float("inf")
        return HausdorffResult(inf, inf, inf, inf, inf, inf, np.zeros(3), 0)
    rng = np.random.default_rng(seed)
    ia = index_a if index_a is not None else SurfaceIndex(Va, Fa, seed=seed)
    ib = SurfaceIndex(Vb, Fb, seed=seed + 1)
    mab, meab, pab = _directed(Va, Fa, ib, samples, rng)
    mba, meba, pba = _directed(Vb, Fb, ia, samples, rng)
    worst = pab if mab >= mba else pba
    return HausdorffResult(max(mab, mba), 0.5 * (meab + meba), mab, mba, meab, meba, worst, samples)


# --------------------------------------------------------------------------- topology checks
def edge_counts(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges (E, 2) sorted, how many triangles use each, and how many of those use
    it in the direction lo -> hi (an edge of a consistently oriented manifold has 1 each way)."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    if len(F) == 0:
        return np.zeros((0, 2), np.int64), np.zeros(0, np.int64), np.zeros(0, np.int64)
    d = np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]])
    forward = d[:, 0] < d[:, 1]
    lo, hi = d.min(axis=1), d.max(axis=1)
    n = int(hi.max()) + 1
    key, inv, cnt = np.unique(lo * n + hi, return_inverse=True, return_counts=True)
    edges = np.stack([key // n, key % n], axis=1)
    fwd = np.bincount(inv.ravel(), weights=forward, minlength=len(edges)).astype(np.int64)
    return edges, cnt, fwd


def topology(F: np.ndarray) -> dict[str, int]:
    """Counts: open (border) edges, non-manifold edges (used by more than two triangles),
    edges two triangles traverse in the same direction (orientation flips between
    neighbours), and triangles with a repeated corner."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    edges, cnt, fwd = edge_counts(F)
    rep = int(((F[:, 0] == F[:, 1]) | (F[:, 1] == F[:, 2]) | (F[:, 0] == F[:, 2])).sum()) if len(F) else 0
    return {
        "open_edges": int((cnt == 1).sum()),
        "nonmanifold_edges": int((cnt > 2).sum()),
        "misoriented_edges": int(((cnt == 2) & (fwd != 1)).sum()),
        "repeated_corner_triangles": rep,
    }


def flipped_triangles(Va: np.ndarray, Fa: np.ndarray, Vo: np.ndarray, Fo: np.ndarray, tolerance: float,
                      index_a: SurfaceIndex | None = None) -> np.ndarray:
    """See :func:`flip_votes`; only the mask."""
    return flip_votes(Va, Fa, Vo, Fo, tolerance, index_a)[0]


def flip_votes(Va: np.ndarray, Fa: np.ndarray, Vo: np.ndarray, Fo: np.ndarray, tolerance: float,
               index_a: SurfaceIndex | None = None, samples: int = 20000, seed: int = 0,
               ignore: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Output triangles that face away from the original surface they stand for, and for each
    original triangle the output triangle closest to its centroid (-1 if none).

    The original surface votes: area-weighted random points (each carrying the normal of the
    triangle it lies on) and every triangle's centroid (weighted by its area, at most one
    point's share, so tiny triangles count and big ones cannot outvote from a single spot) go to
    the output triangle closest to them; among output triangles within ``tolerance`` of the
    closest, the best-agreeing wins, so coincident double-sided faces pair up. An output
    triangle is flipped when its normal points against the sum of its votes; one that got no
    vote is judged against the original triangles closest to its own centroid.

    ``ignore`` marks original triangles whose orientation cannot be judged this way (found by
    running the check on the original against itself: coincident opposite faces, overlapping
    internal walls); they do not vote."""
    Fa = np.asarray(Fa, np.int64).reshape(-1, 3)
    Fo = np.asarray(Fo, np.int64).reshape(-1, 3)
    if len(Fo) == 0 or len(Fa) == 0:
        return np.zeros(len(Fo), bool), np.full(len(Fa), -1, np.int64)
    n_out = triangle_normals(Vo, Fo)
    a_area = triangle_areas(Va, Fa)
    a_norm = triangle_normals(Va, Fa)
    ib = SurfaceIndex(Vo, Fo, density=max(50_000, 2 * samples), k=16 if len(Fo) <= 20_000 else 8, seed=seed + 11)
    rng = np.random.default_rng(seed)
    sp, st, _ = sample_surface(Va, Fa, samples, rng)
    share = float(a_area.sum()) / max(samples, 1)
    pts = np.concatenate([Va[Fa].mean(axis=1), sp])
    src = np.concatenate([np.arange(len(Fa)), st])
    weight = np.concatenate([np.minimum(a_area, share), np.full(len(sp), share)])
    rows, tris, d = ib.candidates(pts)
    dmin = np.full(len(pts), np.inf)
    np.minimum.at(dmin, rows, d)
    ok = d <= dmin[rows] + tolerance
    rows, tris = rows[ok], tris[ok]
    dots = np.einsum("ij,ij->i", a_norm[src[rows]], n_out[tris])
    # per point: the agreeing-most candidate (rows are grouped, ascending)
    order = np.lexsort((-dots, rows))
    rows, tris = rows[order], tris[order]
    first = np.r_[True, rows[1:] != rows[:-1]]
    rows, tris = rows[first], tris[first]
    if ignore is not None:
        keep = ~np.asarray(ignore, bool)[src[rows]]
        rows_all, tris_all = rows, tris
        rows, tris = rows[keep], tris[keep]
    votes = np.zeros((len(Fo), 3))
    np.add.at(votes, tris, a_norm[src[rows]] * weight[rows, None])
    r_all, t_all = (rows_all, tris_all) if ignore is not None else (rows, tris)
    cen = r_all < len(Fa)
    voted_for = np.full(len(Fa), -1, np.int64)
    voted_for[r_all[cen]] = t_all[cen]
    got = np.linalg.norm(votes, axis=1) > 0
    flipped = got & (np.einsum("ij,ij->i", votes, n_out) < 0)
    lonely = np.flatnonzero(~got)
    if len(lonely):
        ia = index_a if index_a is not None else SurfaceIndex(Va, Fa)
        r2, t2, d2 = ia.candidates(Vo[Fo[lonely]].mean(axis=1))
        dm = np.full(len(lonely), np.inf)
        np.minimum.at(dm, r2, d2)
        near = d2 <= dm[r2] + tolerance
        if ignore is not None:
            near &= ~np.asarray(ignore, bool)[t2]
        dd = np.einsum("ij,ij->i", n_out[lonely[r2]], a_norm[t2])
        best = np.full(len(lonely), -np.inf)
        np.maximum.at(best, r2[near], dd[near])
        flipped[lonely] = np.isfinite(best) & (best < -1e-9)
    degenerate = np.linalg.norm(n_out, axis=1) == 0
    return flipped & ~degenerate, voted_for
