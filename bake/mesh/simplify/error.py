"""Closest-triangle queries, exact distances and flip checks for the simplify stage (the
Hausdorff measure itself, its sample and refinement, is in measure.py).

Distances
---------
:meth:`SurfaceIndex.distance` (and :meth:`SurfaceIndex.query`) are exact: libigl's AABB tree
over the mesh's triangles (``igl.AABB.squared_distance``, compiled; built on the first query)
gives every point its closest triangle and squared distance. It replaced a KD-tree of points
on the triangles whose candidates, with a walk to edge neighbours, gave upper bounds: exact for
all but a few points in ten thousand (8 of 200,000 points near the bunny, which missed by up to
0.13% of its diagonal). The simplify stage on the bunny to 2,000 triangles went from 3.70 s to
2.41 s with it (benchmarks/results/simplify_speed.json, side by side, best of 3).

A :class:`SurfaceIndex` still holds a scipy KD-tree over points on every triangle (its
centroid, for small and mid-size meshes three points near its corners, and area-weighted
samples up to ``density``; tree and query points in Z-order), built only when a caller wants
what it gives: ``k`` candidate triangles per point (:meth:`SurfaceIndex._candidates`, used by
the flip check, which compares normals of the nearly closest triangles) and the triangles
within a radius (:meth:`SurfaceIndex.near`).

:meth:`SurfaceIndex.exact` measures every triangle whose bounding sphere comes within a given
upper bound of a point (for meshes of up to 20,000 triangles every (point, triangle) pair's
sphere bound is tested directly, for bigger ones a ball query over the centroids finds them).
:func:`_verify` uses it on the largest distances of a measurement, in blocks, until the largest
exact value is at least every value left; with exact distances from the AABB tree that is the
first block, and it stays as the check that the maximum reported is exact at its point (it is
the largest value left, an upper bound, and says so, if that needs more than 1.5M
point-triangle pairs). tests/mesh/test_simplify_error.py checks these against brute force.

The KD-tree queries run on all cores (scipy's worker threads); Ctrl-C is held back until they
are done (bake/interrupt.py).

Flips
-----
:func:`flip_check`: an output triangle is *flipped* when its normal has turned by more than
90 degrees from the original surface it stands for, in two views that must agree:

1. (per triangle) the original surface is sampled on the output triangle itself: a fixed (not
   random) low-discrepancy pattern of points, about ``samples`` in all spread by area and at
   least three per triangle (centroid first), each takes the unit normal of the closest
   original triangle (among original triangles equally close within ``tol`` the best-agreeing
   one, so coincident double-sided faces pair up). The triangle is a *suspect* when its normal
   points against the sum of those normals.
2. (suspects only) the original triangles around a suspect vote, area-weighted, for the output
   triangle closest to their centroid (again best-agreeing among near-ties). A suspect is
   flipped unless those that chose it face its way on balance; one that got no vote (folded
   over a neighbour that agrees better) stays flipped.

View 1 alone calls triangles flipped that stand inside a thin part, between two opposite
sheets, at strong reductions (spot and the teapot at 1%); view 2 alone is what this module did
before and costs a query of every original triangle against the output; together they cost a
query of the output's samples against the original plus a little per suspect. Triangles
whose area is zero within the scene's tolerance (``(1e-6 * diagonal)^2``, or sine of the
largest angle below 1e-9) have no reliable normal: they are never called flipped, and original
ones do not vote. Triangles whose view-1 votes cancel (sum below 5% of their count: standing
edge-on between two sheets) are not judged. Coplanar triangles fanned differently over a flat
area therefore see the flat area's normal and are not flips. View 1 depends only on a
triangle's corners and the original mesh, so a re-check measures only triangles it has not
seen before (after a repair, a refit, or in the next attempt).

The module also answers "which triangle is closest" for carrying attributes and for the refit,
and holds the edge topology checks the simplify stage reports.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree
from scipy.spatial.distance import cdist

from ...interrupt import deferred_interrupt

__all__ = ["SurfaceIndex", "sample_surface", "point_triangle_distance", "triangle_normals", "triangle_areas",
           "topology", "edge_counts", "flip_check", "FlipResult", "reliable_normals", "triangle_pattern",
           "bounding_spheres"]

# meshes of at most this many triangles are searched exhaustively
_BRUTE = 8
# query points handled per chunk (bounds the temporaries: ~16 floats per point-triangle pair)
_CHUNK = 1 << 16
# KD-tree queries of fewer points than this run on one thread (starting threads costs more)
_THREADED = 4096
# exact point-triangle pairs one verification of a maximum may measure (the bunny at 1% needs
# under 3,000; a soup of large intersecting triangles, whose candidate bounds are loose, needs
# millions: past this budget the max is reported as the largest bound left, an upper bound)
_VERIFY_PAIRS = 1_500_000
# meshes of at most this many triangles are verified by testing every (point, triangle) pair's
# bounding-sphere bound (vectorised) instead of ball queries
# distances within this fraction of the diagonal of each other are equal for the verification
# (float64 rounding of distances computed from coordinates of that size is about 1e-16)
_ROUNDING = 1e-12
_EXACT_BRUTE = 20_000
# a triangle whose double area is below this fraction of the squared bbox diagonal (or whose
# largest angle has a sine below _SLIVER_SINE) has no reliable normal
_AREA_TOL = 1e-12
_SLIVER_SINE = 1e-9
# the R2 low-discrepancy sequence (Roberts 2018): fixed sample patterns on each triangle
_R2 = (0.7548776662466927, 0.5698402909980532)


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


def reliable_normals(V: np.ndarray, F: np.ndarray, scale: float) -> np.ndarray:
    """(T,) bool: triangles whose normal means something (not zero-area within the scene's
    tolerance, not a sliver whose largest angle has a sine below 1e-9)."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    if len(F) == 0:
        return np.zeros(0, bool)
    a, b, c = V[F[:, 0]], V[F[:, 1]], V[F[:, 2]]
    dbl = np.linalg.norm(np.cross(b - a, c - a), axis=1)
    longest = np.maximum(np.maximum(((b - a) ** 2).sum(1), ((c - a) ** 2).sum(1)), ((c - b) ** 2).sum(1))
    return (dbl > 2.0 * _AREA_TOL * scale * scale) & (dbl > _SLIVER_SINE * longest)


def bounding_spheres(C: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Spheres around triangles given by their corners (T, 3, 3): centroids (T, 3) and the
    distance to the farthest corner (T,)."""
    cen = C.mean(axis=1)
    return cen, np.sqrt(((C - cen[:, None, :]) ** 2).sum(axis=2).max(axis=1))


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


# --------------------------------------------------------------------------- point-triangle distance
def _tri_table(A: np.ndarray, B: np.ndarray, C: np.ndarray) -> np.ndarray:
    """Per-triangle constants (16, T): A, AB, AC, unit normal, AB.AB, AB.AC, AC.AC and
    1 / (AB.AB AC.AC - (AB.AC)^2) (0 for triangles too thin for barycentrics: edges only)."""
    e0, e1 = B - A, C - A
    n = np.cross(e0, e1)
    ln = np.linalg.norm(n, axis=1)
    nh = np.divide(n, ln[:, None], out=np.zeros_like(n), where=ln[:, None] > 0)
    d00 = np.einsum("ij,ij->i", e0, e0)
    d01 = np.einsum("ij,ij->i", e0, e1)
    d11 = np.einsum("ij,ij->i", e1, e1)
    den = d00 * d11 - d01 * d01
    ok = den > 1e-14 * d00 * d11
    inv = np.divide(1.0, den, out=np.zeros_like(den), where=ok)
    return np.ascontiguousarray(np.concatenate([A.T, e0.T, e1.T, nh.T, d00[None], d01[None], d11[None], inv[None]]))


def _pair_dist2(P: np.ndarray, D: np.ndarray, want_point: bool = False):
    """Squared exact distances from points P (m,3) to triangles given by their table columns D
    (16, m); with ``want_point`` also the closest points (m,3)."""
    px, py, pz = P[:, 0] - D[0], P[:, 1] - D[1], P[:, 2] - D[2]  # A -> P
    e0x, e0y, e0z, e1x, e1y, e1z = D[3], D[4], D[5], D[6], D[7], D[8]
    d00, d01, d11, inv = D[12], D[13], D[14], D[15]
    d20 = px * e0x + py * e0y + pz * e0z
    d21 = px * e1x + py * e1y + pz * e1z
    v = (d11 * d20 - d01 * d21) * inv
    w = (d00 * d21 - d01 * d20) * inv
    inside = (inv > 0) & (v >= 0) & (w >= 0) & (v + w <= 1)
    h = px * D[9] + py * D[10] + pz * D[11]
    with np.errstate(invalid="ignore", divide="ignore"):
        # edge AB
        t0 = np.clip(np.where(d00 > 0, d20 / d00, 0.0), 0.0, 1.0)
        qx, qy, qz = px - t0 * e0x, py - t0 * e0y, pz - t0 * e0z
        best = qx * qx + qy * qy + qz * qz
        # edge AC
        t1 = np.clip(np.where(d11 > 0, d21 / d11, 0.0), 0.0, 1.0)
        qx, qy, qz = px - t1 * e1x, py - t1 * e1y, pz - t1 * e1z
        dd = qx * qx + qy * qy + qz * qz
        pick1 = dd < best
        best = np.minimum(best, dd)
        # edge BC
        e2x, e2y, e2z = e1x - e0x, e1y - e0y, e1z - e0z
        bx, by, bz = px - e0x, py - e0y, pz - e0z
        d22 = e2x * e2x + e2y * e2y + e2z * e2z
        t2 = np.clip(np.where(d22 > 0, (bx * e2x + by * e2y + bz * e2z) / d22, 0.0), 0.0, 1.0)
        qx, qy, qz = bx - t2 * e2x, by - t2 * e2y, bz - t2 * e2z
        dd = qx * qx + qy * qy + qz * qz
        pick2 = dd < best
        best = np.minimum(best, dd)
    d2 = np.where(inside, h * h, best)
    if not want_point:
        return d2
    # closest point as A + s AB + r AC
    s = np.where(pick2, 1.0 - t2, np.where(pick1, 0.0, t0))
    r = np.where(pick2, t2, np.where(pick1, t1, 0.0))
    s = np.where(inside, v, s)
    r = np.where(inside, w, r)
    q = np.stack([D[0] + s * e0x + r * e1x, D[1] + s * e0y + r * e1y, D[2] + s * e0z + r * e1z], axis=1)
    return d2, q


def point_triangle_distance(P: np.ndarray, A: np.ndarray, B: np.ndarray, C: np.ndarray
                            ) -> tuple[np.ndarray, np.ndarray]:
    """Exact distance from points ``P`` to triangles ``ABC`` (all (..., 3), broadcast), and the
    closest points. Degenerate triangles fall back to their edges."""
    P, A, B, C = np.broadcast_arrays(*(np.asarray(x, np.float64) for x in (P, A, B, C)))
    shape = P.shape[:-1]
    P, A, B, C = (x.reshape(-1, 3) for x in (P, A, B, C))
    d2, q = _pair_dist2(P, _tri_table(A, B, C), want_point=True)
    # distance from the closest point itself (the expanded forms lose digits next to an edge)
    diff = P - q
    d = np.sqrt(np.einsum("ij,ij->i", diff, diff))
    return d.reshape(shape), q.reshape(shape + (3,))


# --------------------------------------------------------------------------- closest-triangle index
def _kd_query(tree: cKDTree, P: np.ndarray, threaded: bool, **kw):
    """``tree.query`` on one thread, or on all cores for big queries. scipy runs those on
    Python threads it joins; Ctrl-C is held back until they are done (bake/interrupt.py), so an
    interrupt never frees arrays the workers are still writing."""
    if not threaded:
        return tree.query(P, workers=1, **kw)
    with deferred_interrupt():
        return tree.query(P, workers=-1, **kw)


# tile_long: triangles whose longest edge is over _TILE_LONG x the median are cut into pieces whose
# edges are at most that long (at most _TILE_MAX_CUTS parts per edge)
_TILE_LONG = 4.0
_TILE_MAX_CUTS = 64


def tile_long(V: np.ndarray, F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray | None]:
    """(vertices, triangles, piece -> triangle) where each triangle whose longest edge is over
    _TILE_LONG times the median longest edge is cut into k x k pieces (k = its longest edge over
    that length, rounded up: its edges cut into k equal parts, the pieces the triangles of that
    grid); the others are kept as they are. None for the map when no triangle is long: (V, F)."""
    T = len(F)
    if T < 64:
        return V, F, None
    C = V[F]
    longest = np.linalg.norm(C[:, [1, 2, 0]] - C, axis=2).max(axis=1)
    limit = _TILE_LONG * float(np.median(longest))
    if not limit > 0:
        return V, F, None
    k = np.minimum(np.ceil(longest / limit), _TILE_MAX_CUTS).astype(np.int64)
    k[~np.isfinite(longest)] = 1
    if (k <= 1).all():
        return V, F, None
    out_v, out_f, out_of = [V], [F[k <= 1]], [np.flatnonzero(k <= 1)]
    base = len(V)
    for kk in np.unique(k[k > 1]).tolist():
        sel = np.flatnonzero(k == kk)
        i, j = np.meshgrid(np.arange(kk + 1), np.arange(kk + 1), indexing="ij")
        ok = i + j <= kk
        i, j = i[ok], j[ok]  # lattice points (i, j): barycentrics ((kk - i - j), i, j) / kk
        node = np.full((kk + 1, kk + 1), -1, np.int64)
        node[i, j] = np.arange(len(i))
        a, b = np.meshgrid(np.arange(kk), np.arange(kk), indexing="ij")
        up = a + b <= kk - 1
        down = a + b <= kk - 2
        pieces = np.concatenate([
            np.stack([node[a[up], b[up]], node[a[up] + 1, b[up]], node[a[up], b[up] + 1]], axis=1),
            np.stack([node[a[down] + 1, b[down]], node[a[down] + 1, b[down] + 1], node[a[down], b[down] + 1]],
                     axis=1)])
        w = np.stack([kk - i - j, i, j], axis=1) / kk
        pts = np.einsum("pk,tkd->tpd", w, C[sel]).reshape(-1, 3)
        out_v.append(pts)
        out_f.append((pieces[None] + (base + np.arange(len(sel)) * len(i))[:, None, None]).reshape(-1, 3))
        out_of.append(np.repeat(sel, len(pieces)))
        base += len(pts)
    return np.concatenate(out_v), np.concatenate(out_f), np.concatenate(out_of)


def _spread10(x: np.ndarray) -> np.ndarray:
    x = (x | (x << 16)) & 0x030000FF
    x = (x | (x << 8)) & 0x0300F00F
    x = (x | (x << 4)) & 0x030C30C3
    return (x | (x << 2)) & 0x09249249


def _morton(P: np.ndarray, lo: np.ndarray, span: float) -> np.ndarray:
    """30-bit Morton (Z-order) codes of points on a 1024^3 grid over the box ``lo + [0, span]^3``."""
    g = np.clip(((P - lo) * (1023.0 / span)), 0, 1023).astype(np.int64)
    return _spread10(g[:, 0]) | (_spread10(g[:, 1]) << 1) | (_spread10(g[:, 2]) << 2)


class SurfaceIndex:
    """Closest-triangle queries against one triangle mesh."""

    def __init__(self, V: np.ndarray, F: np.ndarray, *, density: int = 50_000, k: int = 4, seed: int = 0,
                 scale: float | None = None, corners: bool = True):
        self.V = np.asarray(V, np.float64)
        self.F = np.asarray(F, np.int64).reshape(-1, 3)
        self.k = k
        T = len(self.F)
        self._ball = None
        self._query_cache: dict = {}
        self._igl = None
        if T == 0:
            self._tree = None
            return
        tri_pts = self.V[self.F]
        self.table = _tri_table(tri_pts[:, 0], tri_pts[:, 1], tri_pts[:, 2])
        if scale is None:
            used = self.V[np.unique(self.F)]
            scale = float(np.linalg.norm(used.max(0) - used.min(0)))
        self.scale = float(scale)
        cent, self.radii = bounding_spheres(tri_pts)
        self._sampling = (corners, density, seed)
        self._tree = self._points = self._owner = None
        self.centers = cent
        self.area = 0.5 * np.linalg.norm(np.cross(tri_pts[:, 1] - tri_pts[:, 0], tri_pts[:, 2] - tri_pts[:, 0]),
                                         axis=1)
        self.total_area = float(self.area.sum())
        self._reliable = None

    def _build_points(self) -> None:
        """The KD-tree over points on the triangles (built on first use: a query that only
        wants distances goes to the AABB tree and never needs it)."""
        corners, density, seed = self._sampling
        T = len(self.F)
        tri_pts = self.V[self.F]
        cent = self.centers
        parts, owners = [cent], [np.arange(T)]
        if corners and T <= 250_000:
            # points near each corner (inside the triangle, so each belongs to one owner)
            near = 0.9 * tri_pts + 0.1 * cent[:, None, :]
            parts.append(near.reshape(-1, 3))
            owners.append(np.repeat(np.arange(T), 3))
        # extra area-weighted points: up to ``density`` in all, at most ~64 per triangle
        # (but 8192 in all for small meshes)
        extra = max(0, min(density, max(64 * T, 8192)) - sum(len(p) for p in parts))
        if extra:
            rp, rt, _ = sample_surface(self.V, self.F, extra, np.random.default_rng(seed))
            parts.append(rp)
            owners.append(rt)
        pts = np.concatenate(parts) if len(parts) > 1 else cent
        self._lo = pts.min(axis=0)
        self._span = float(max((pts.max(axis=0) - self._lo).max(), 1e-300))
        # tree points and (in _candidates) query points in Z-order: queries that follow each
        # other walk the same nodes, which halves the KD-tree time
        order = np.argsort(_morton(pts, self._lo, self._span))
        self._points = pts[order]
        self._owner = np.concatenate(owners)[order] if len(owners) > 1 else order
        self._tree = cKDTree(self._points, balanced_tree=False, compact_nodes=False)

    @property
    def tree(self):
        """The KD-tree over points on the triangles (None for a mesh without triangles)."""
        if self._tree is None and len(self.F):
            self._build_points()
        return self._tree

    @property
    def points(self) -> np.ndarray:
        self.tree
        return self._points

    @property
    def owner(self) -> np.ndarray:
        self.tree
        return self._owner

    @property
    def normals(self) -> np.ndarray:
        """(3, T) unit normals (zero for degenerate triangles)."""
        return self.table[9:12]

    @property
    def reliable(self) -> np.ndarray:
        if self._reliable is None:
            self._reliable = reliable_normals(self.V, self.F, self.scale)
        return self._reliable

    def _candidates(self, P: np.ndarray):
        """(m, k) candidate triangles (duplicates in a row replaced by -1) and squared exact
        distances (inf where -1). Meshes of at most ``_BRUTE`` triangles: every triangle is a
        candidate."""
        m = len(P)
        T = len(self.F)
        if T <= _BRUTE:  # a handful of triangles: every one is a candidate
            cand = np.broadcast_to(np.arange(T), (m, T)).copy()
            d2 = np.empty(m * T)
            step = 4096
            for s in range(0, m, step):
                p = P[s:s + step]
                d2[s * T:(s + len(p)) * T] = _pair_dist2(np.repeat(p, T, axis=0),
                                                         np.take(self.table, np.tile(np.arange(T), len(p)), axis=1))
            return cand, d2.reshape(m, T)
        k = int(min(self.k, len(self.points)))
        z = np.argsort(_morton(P, self._lo, self._span))
        _, nb = _kd_query(self.tree, P[z], m >= _THREADED, k=k)
        cand = np.empty((m, k), np.int64)
        cand[z] = self.owner[nb.reshape(m, k)]
        cand.sort(axis=1)
        dup = np.zeros_like(cand, dtype=bool)
        dup[:, 1:] = cand[:, 1:] == cand[:, :-1]
        cand[dup] = -1
        keep = np.flatnonzero(~dup.ravel())
        d2 = np.full(m * k, np.inf)
        rows = keep // k
        d2[keep] = _pair_dist2(P[rows], np.take(self.table, cand.ravel()[keep], axis=1))
        return cand, d2.reshape(m, k)

    def _aabb(self):
        """libigl's AABB tree over the triangles (built on first use), and the triangle each of
        its pieces belongs to (None: the pieces are the triangles). Triangles much longer than
        most (CAD cylinders' long slivers, fans) are cut into pieces first (:func:`tile_long`):
        a long triangle's box overlaps everything along it, and a query visits every box that
        could hold its answer (the 2CylinderEngine's 110k triangles answered 2.3x faster cut, the
        bunny's were left whole). Distances are to the same surface: the pieces tile it."""
        if self._igl is None:
            import igl

            self.V, self.F = np.ascontiguousarray(self.V), np.ascontiguousarray(self.F)
            Vt, Ft, self._piece_of = tile_long(self.V, self.F)
            self._tree_mesh = (self.V, self.F) if self._piece_of is None else (Vt, Ft)
            self._igl = igl.AABB()
            self._igl.init(*self._tree_mesh)
        return self._igl

    def distance(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(distances (n,), closest triangle (n,)): exact, from libigl's AABB tree."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        n = len(P)
        if len(self.F) == 0 or n == 0:
            return np.full(n, np.inf), np.full(n, -1, np.int64)
        dist = np.empty(n)
        tri = np.empty(n, np.int64)
        tree = self._aabb()
        Vt, Ft = self._tree_mesh
        for s in range(0, n, _CHUNK):
            d2, t, _ = tree.squared_distance(Vt, Ft, np.ascontiguousarray(P[s:s + _CHUNK]))
            dist[s:s + len(d2)] = np.sqrt(d2)
            tri[s:s + len(d2)] = t if self._piece_of is None else self._piece_of[t]
        return dist, tri

    def query(self, P: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(distances (n,), closest triangle (n,), closest points (n,3)); exact distances
        (:meth:`distance`), the closest point computed on the triangle named."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        n = len(P)
        dist, tri = self.distance(P)
        if len(self.F) == 0 or n == 0:
            return dist, tri, np.full((n, 3), np.nan)
        cp = np.empty((n, 3))
        for s in range(0, n, _CHUNK):
            _, cp[s:s + _CHUNK] = _pair_dist2(P[s:s + _CHUNK], np.take(self.table, tri[s:s + _CHUNK], axis=1),
                                              want_point=True)
        return dist, tri, cp

    def _ball_index(self):
        if self._ball is None:
            R = float(np.quantile(self.radii, 0.99))
            small = np.flatnonzero(self.radii <= R)
            big = np.flatnonzero(self.radii > R)
            self._ball = (R, small, cKDTree(self.centers[small], balanced_tree=False, compact_nodes=False), big)
        return self._ball

    def near(self, P: np.ndarray, radius: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point index, triangle) for every triangle whose bounding sphere comes within
        ``radius`` of a point: each pair once, in no promised order (the K-nearest queries'
        pairs, then the dense blocks'); callers sort what they use."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        radius = np.broadcast_to(np.asarray(radius, np.float64), (len(P),))
        if len(self.F) == 0 or len(P) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        _, small, _, big = self._ball_index()
        rows, tris, full = self._near_knn(P, radius, (32, 1024))
        # points whose ball holds more than that are tested against every small triangle, and
        # every point against the big ones (a distance table: cheaper than a KD-tree query for
        # thousands of neighbours, which is what soups of big overlapping triangles ask)
        parts = [(rows, tris), self._near_dense(P, radius, full, small),
                 self._near_dense(P, radius, np.arange(len(P)), big)]
        return np.concatenate([r for r, _ in parts]), np.concatenate([t for _, t in parts])

    def near_set(self, P: np.ndarray, radius: np.ndarray) -> np.ndarray:
        """The triangles :meth:`near` pairs with any of the points (sorted ids), without listing
        the pairs: where balls are large (soups of big overlapping triangles put every triangle
        within reach of every point) each triangle is tested only until one point reaches it."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        radius = np.broadcast_to(np.asarray(radius, np.float64), (len(P),))
        if len(self.F) == 0 or len(P) == 0:
            return np.zeros(0, np.int64)
        _, small, _, big = self._ball_index()
        _, tris, full = self._near_knn(P, radius, (32,))
        hit = np.zeros(len(self.F), bool)
        hit[tris] = True
        for pts, cand in ((full, small), (np.arange(len(P)), big)):
            cand = cand[~hit[cand]]
            step = max(1, (1 << 20) // max(len(cand), 1))
            for s in range(0, len(pts), step):
                if len(cand) == 0:
                    break
                _, t = self._near_dense(P, radius, pts[s:s + step], cand)
                hit[t] = True
                cand = cand[~hit[cand]]
        return np.flatnonzero(hit)

    def _near_knn(self, P: np.ndarray, radius: np.ndarray, ks: tuple[int, ...]
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """:meth:`near`'s pairs among the small triangles whose centroids are the K nearest
        within reach of each point (K in ``ks`` in turn, for the points that had K); returns
        (rows, triangles, the points that had the last K: their balls may hold more)."""
        R, small, ctree, _ = self._ball_index()
        reach = radius + R
        rows_l, tris_l = [np.zeros(0, np.int64)], [np.zeros(0, np.int64)]
        todo = np.arange(len(P))
        for K in ks:
            if len(todo) == 0:
                break
            K = min(K, len(small))
            rt = reach[todo]
            dd, ii = _kd_query(ctree, P[todo], len(todo) >= _THREADED, k=K,
                               distance_upper_bound=float(rt.max()) * (1 + 1e-12))
            dd, ii = dd.reshape(len(todo), K), ii.reshape(len(todo), K)
            within = dd <= rt[:, None]
            full = within[:, -1] & (K < len(small))
            hit = within & ~full[:, None]
            r, c = np.nonzero(hit)
            rows_l.append(todo[r])
            tris_l.append(small[ii[r, c]])
            todo = todo[full]
        rows = np.concatenate(rows_l)
        tris = np.concatenate(tris_l)
        lb = np.linalg.norm(P[rows] - self.centers[tris], axis=1) - self.radii[tris]
        sel = lb <= radius[rows] * (1 + 1e-12) + 1e-300
        return rows[sel], tris[sel], todo

    def _near_dense(self, P: np.ndarray, radius: np.ndarray, pts: np.ndarray, tris: np.ndarray
                    ) -> tuple[np.ndarray, np.ndarray]:
        """:meth:`near`'s pairs between points ``pts`` and triangles ``tris``, every pair tested
        (a distance table, in blocks of about a million pairs; row-major order)."""
        if len(pts) == 0 or len(tris) == 0:
            return np.zeros(0, np.int64), np.zeros(0, np.int64)
        C, rad = self.centers[tris], self.radii[tris]
        step = max(1, (1 << 20) // len(tris))
        rows_l, tris_l = [], []
        for s in range(0, len(pts), step):
            p = pts[s:s + step]
            ok = cdist(P[p], C) - rad[None] <= radius[p, None] * (1 + 1e-12) + 1e-300
            r, c = np.nonzero(ok)
            rows_l.append(p[r])
            tris_l.append(tris[c])
        return np.concatenate(rows_l), np.concatenate(tris_l)

    def near_chunks(self, P: np.ndarray, radius: np.ndarray, max_pairs: int = 1 << 22):
        """:meth:`near` over consecutive chunks of the points, sized so a chunk yields about
        ``max_pairs`` pairs (measured on the chunk before): yields (first point of the chunk,
        rows within the chunk, triangles). Keeps memory bounded where balls are large (soups of
        big overlapping triangles put every triangle within reach of every point)."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        radius = np.broadcast_to(np.asarray(radius, np.float64), (len(P),))
        i, step = 0, 64
        while i < len(P):
            rows, tris = self.near(P[i:i + step], radius[i:i + step])
            yield i, rows, tris
            per = max(len(rows) / max(min(step, len(P) - i), 1), 1.0)
            i += step
            step = int(np.clip(max_pairs / per, 1, 1 << 16))

    def exact(self, P: np.ndarray, upper: np.ndarray, stats: dict | None = None
              ) -> tuple[np.ndarray, np.ndarray]:
        """Exact distances and closest triangles for a few points, given upper bounds: every
        triangle whose bounding sphere (centroid, radius) comes within ``upper`` of a point is
        measured. Small triangles are found with a ball query over their centroids, the few
        largest (radius above the 99th percentile) are always measured. ``stats["pairs"]`` (if
        given) is increased by the point-triangle pairs measured."""
        P = np.asarray(P, np.float64).reshape(-1, 3)
        dist = np.asarray(upper, np.float64).copy()
        tri = np.full(len(P), -1, np.int64)
        if len(self.F) == 0 or len(P) == 0:
            return dist, tri
        T = len(self.F)
        if T <= _EXACT_BRUTE:
            # few triangles: test every (point, triangle) pair's bounding-sphere bound and
            # measure the pairs it cannot rule out (no ball queries: big triangles of CAD-like
            # meshes make those slow)
            step = max(1, (1 << 20) // T)
            for s0 in range(0, len(P), step):
                p = P[s0:s0 + step]
                lb = np.linalg.norm(p[:, None, :] - self.centers[None], axis=2) - self.radii[None]
                r, t = np.nonzero(lb <= dist[s0:s0 + step, None] * (1 + 1e-12) + 1e-300)
                if stats is not None:
                    stats["pairs"] = stats.get("pairs", 0) + len(r)
                if len(r) == 0:
                    continue
                d = np.sqrt(_pair_dist2(p[r], np.take(self.table, t, axis=1)))
                order = np.lexsort((t, d, r))
                r, t, d = r[order], t[order], d[order]
                first = np.r_[True, r[1:] != r[:-1]]
                r, t, d = r[first] + s0, t[first], d[first]
                upd = (d < dist[r]) | ((d == dist[r]) & ((tri[r] < 0) | (t < tri[r])))
                dist[r[upd]] = d[upd]
                tri[r[upd]] = t[upd]
            return dist, tri
        for i0, rows, tris in self.near_chunks(P, dist.copy()):
            if stats is not None:
                stats["pairs"] = stats.get("pairs", 0) + len(rows)
            rows = rows + i0
            for s in range(0, len(rows), 1 << 20):
                r, t = rows[s:s + (1 << 20)], tris[s:s + (1 << 20)]
                d = np.sqrt(_pair_dist2(P[r], np.take(self.table, t, axis=1)))
                # lowest distance per row; ties -> lowest triangle id (deterministic)
                order = np.lexsort((t, d, r))
                r, t, d = r[order], t[order], d[order]
                first = np.r_[True, r[1:] != r[:-1]]
                r, t, d = r[first], t[first], d[first]
                upd = (d < dist[r]) | ((d == dist[r]) & ((tri[r] < 0) | (t < tri[r])))
                dist[r[upd]] = d[upd]
                tri[r[upd]] = t[upd]
        return dist, tri


# --------------------------------------------------------------------------- verification
def _verify(Q: np.ndarray, d: np.ndarray, index: SurfaceIndex, budget: int = _VERIFY_PAIRS
            ) -> tuple[np.ndarray, bool]:
    """Make the largest upper bounds ``d`` (in place) exact, in blocks down the sorted bounds
    (64 points, doubling to 4096), until the largest exact value is at least every bound left
    (every other point's true distance is below its bound, so below it). Returns the verified
    points, largest first, and whether that max is exact: when the blocks have measured more
    than ``budget`` point-triangle pairs the rest stays unverified, and the point with the
    largest bound left is put first among them if its bound exceeds every exact value (the
    reported max is then an upper bound of the true max over the points)."""
    order = np.argsort(-d, kind="stable")
    best = -1.0
    done, size = 0, 64
    stats: dict = {}
    exact = True
    # bounds within rounding of the largest exact value cannot beat it by more than rounding
    # (a flat result on its flat input: every distance about 1e-16, thousands of bounds tied)
    tie = _ROUNDING * (index.scale if len(index.F) else 0.0)
    while done < len(order):
        blk = order[done:done + size]
        if best >= d[blk[0]] - tie:
            break
        if stats.get("pairs", 0) > budget:
            exact = False
            break
        d[blk], _ = index.exact(Q[blk], d[blk], stats)
        best = max(best, float(d[blk].max()))
        done += len(blk)
        size = min(2 * size, 4096)
    tops = order[:done]
    tops = tops[np.argsort(-d[tops], kind="stable")]
    if not exact:
        rest = order[done]  # the largest bound not verified
        if d[rest] > best:
            tops = np.concatenate([[rest], tops])
    return tops, exact


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


# --------------------------------------------------------------------------- flips
@dataclass
class FlipResult:
    flipped: np.ndarray  # (t,) bool
    ref: np.ndarray  # (t, 3) reference normal of the original under each triangle, times its area
    under: np.ndarray  # (t,) original triangle closest to each triangle's centroid (-1: none)
    unreliable: np.ndarray  # (t,) no reliable normal (zero area within tolerance): never flipped
    corners: np.ndarray  # (t, 3, 3) the corners judged (for re-checks)
    checked: int  # triangles measured by this call (the rest were taken from the previous one)
    suspect: np.ndarray | None = None  # (t,) first-pass verdict (per triangle; reused by re-checks)
    reach: np.ndarray | None = None  # (t,) farthest of a triangle's sample points from the original
    # the second opinion's pairing, per original triangle: the output triangle it votes for (-1:
    # not paired yet) and how far its centroid is from the output (reused by re-checks, _confirm)
    voted: np.ndarray | None = None
    voted_dist: np.ndarray | None = None


def triangle_pattern(counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(triangle id per point, barycentrics (n, 3)): ``counts[t]`` points of the R2 sequence
    folded into each triangle; the first point of every triangle is its centroid."""
    tid = np.repeat(np.arange(len(counts)), counts)
    starts = np.cumsum(counts) - counts
    i = np.arange(len(tid)) - starts[tid]
    a = np.modf(1.0 / 3.0 + i * _R2[0])[0]
    b = np.modf(1.0 / 3.0 + i * _R2[1])[0]
    fold = a + b > 1.0
    a = np.where(fold, 1.0 - a, a)
    b = np.where(fold, 1.0 - b, b)
    return tid, np.stack([1.0 - a - b, a, b], axis=1)


def flip_check(index_a: SurfaceIndex, Vo: np.ndarray, Fo: np.ndarray, *, samples: int = 20000,
               tol: float | None = None, scale: float | None = None, prev: FlipResult | None = None,
               max_per_triangle: int = 64) -> FlipResult:
    """Output triangles (``Vo``, ``Fo``) that face against the original surface (``index_a``)
    they stand for; see the module docstring. With ``prev`` (an earlier result against the same
    original, with the same ``samples``), only triangles whose corners are not among ``prev``'s
    are measured: a verdict depends on nothing but the triangle's corners."""
    Vo = np.asarray(Vo, np.float64)
    Fo = np.asarray(Fo, np.int64).reshape(-1, 3)
    t = len(Fo)
    corners = Vo[Fo]
    scale = index_a.scale if scale is None else float(scale)
    tol = 1e-6 * scale if tol is None else float(tol)
    res = FlipResult(np.zeros(t, bool), np.zeros((t, 3)), np.full(t, -1, np.int64), np.zeros(t, bool),
                     corners, 0, np.zeros(t, bool), np.zeros(t))
    if t == 0 or len(index_a.F) == 0:
        return res
    if prev is not None and len(prev.corners):
        if len(prev.corners) == t:  # the same triangles, some moved (repairs, refit)
            src = np.arange(t)
            src[(corners != prev.corners).any(axis=(1, 2))] = -1
        else:  # another result: triangles with identical corners get identical verdicts
            both = np.concatenate([prev.corners.reshape(-1, 9), corners.reshape(-1, 9)]) + 0.0  # -0.0 -> 0.0
            _, inv = np.unique(both, axis=0, return_inverse=True)
            inv = inv.reshape(-1)
            owner = np.full(int(inv.max()) + 1, -1, np.int64)
            owner[inv[:len(prev.corners)]] = np.arange(len(prev.corners))
            src = owner[inv[len(prev.corners):]]
        have = src >= 0
        todo = np.flatnonzero(~have)
        res.suspect[have] = prev.suspect[src[have]]
        res.reach[have] = prev.reach[src[have]]
        res.ref[have] = prev.ref[src[have]]
        res.under[have] = prev.under[src[have]]
        res.unreliable[have] = prev.unreliable[src[have]]
    else:
        todo = np.arange(t)
    res.checked = int(len(todo))
    if len(todo):
        _first_pass(index_a, corners, todo, res, samples, tol, scale, max_per_triangle)
    same = prev is not None and len(prev.corners) == t and prev.voted is not None
    _confirm(index_a, Vo, Fo, res, samples, tol, prev if same else None, todo)
    return res


def _first_pass(index_a: SurfaceIndex, corners: np.ndarray, todo: np.ndarray, res: FlipResult, samples: int,
                tol: float, scale: float, max_per_triangle: int) -> None:
    """Per-triangle verdicts for triangles ``todo`` (in place in ``res``): the normals of the
    original triangles closest to points sampled on each."""
    C = corners[todo]
    n = np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0])
    dbl = np.linalg.norm(n, axis=1)
    nh = np.divide(n, dbl[:, None], out=np.zeros_like(n), where=dbl[:, None] > 0)
    ok = reliable_normals(C.reshape(-1, 3), np.arange(3 * len(C)).reshape(-1, 3), scale)
    # points per triangle: ~``samples`` over the original's area, at least 3 (centroid first)
    share = max(index_a.total_area, 1e-300) / max(samples, 1)
    counts = np.clip(np.ceil(0.5 * dbl / share), 3, max_per_triangle).astype(np.int64)
    tid, bary = triangle_pattern(counts)
    a_n = index_a.normals
    a_ok = index_a.reliable
    votes = np.zeros((len(todo), 3))
    reach = np.zeros(len(todo))
    under = np.full(len(todo), -1, np.int64)
    first_pt = np.cumsum(counts) - counts
    for s in range(0, len(tid), _CHUNK):
        ti, bi = tid[s:s + _CHUNK], bary[s:s + _CHUNK]
        P = np.einsum("nk,nkd->nd", bi, C[ti])
        cand, d2 = index_a._candidates(P)
        d = np.sqrt(d2)
        valid = cand >= 0
        ci = np.where(valid, cand, 0)
        rel = valid & a_ok[ci]
        dr = np.where(rel, d, np.inf)
        dmin = dr.min(axis=1, keepdims=True)
        near = rel & (dr <= dmin + tol)
        dots = (a_n[0][ci] * nh[ti, 0, None] + a_n[1][ci] * nh[ti, 1, None] + a_n[2][ci] * nh[ti, 2, None])
        score = np.where(near, dots, -np.inf)
        j = np.argmax(score, axis=1)
        r = np.arange(len(P))
        has = near[r, j]
        chosen = ci[r, j]
        np.add.at(votes, ti[has], a_n[:, chosen[has]].T)
        np.maximum.at(reach, ti, np.where(np.isfinite(dmin[:, 0]), dmin[:, 0], 0.0))
        # the original triangle under each centroid (first point of its triangle)
        isfirst = np.flatnonzero(np.isin(s + r, first_pt))
        jj = np.argmin(np.where(valid, d, np.inf), axis=1)
        under[ti[isfirst]] = np.where(has[isfirst], chosen[isfirst], ci[isfirst, jj[isfirst]])
    vn = np.linalg.norm(votes, axis=1)
    judged = ok & (vn >= 0.05 * counts)
    res.suspect[todo] = judged & (np.einsum("ij,ij->i", votes, nh) < 0.0)
    res.reach[todo] = reach
    res.ref[todo] = votes / counts[:, None] * (0.5 * dbl)[:, None]
    res.under[todo] = under
    res.unreliable[todo] = ~ok


def _votes_for(index_a: SurfaceIndex, Vo: np.ndarray, Fo: np.ndarray, orig: np.ndarray, tol: float,
               prev: FlipResult | None, moved: np.ndarray, res: FlipResult) -> None:
    """``res.voted`` / ``res.voted_dist`` for the original triangles ``orig``: the output triangle
    closest to each centroid (best-agreeing among those within ``tol``). From ``prev`` (the same
    triangles, ``moved`` ones moved) a pairing stands when the triangle it names did not move and
    no moved triangle came within its distance (then none can be closer): only the others are
    paired again (a repair or a refine round moves a few triangles of thousands)."""
    Ta = len(index_a.F)
    if res.voted is None:
        res.voted = np.full(Ta, -1, np.int64) if prev is None else prev.voted.copy()
        res.voted_dist = np.full(Ta, np.inf) if prev is None else prev.voted_dist.copy()
        if prev is not None and len(moved):
            known = np.flatnonzero(res.voted >= 0)
            hit = np.zeros(len(Fo), bool)
            hit[moved] = True
            stale = hit[res.voted[known]]
            d_moved, _ = SurfaceIndex(Vo, Fo[moved], density=0).distance(index_a.centers[known])
            stale |= d_moved <= res.voted_dist[known] + tol
            res.voted[known[stale]] = -1
    todo = orig[res.voted[orig] < 0]
    if len(todo) == 0:
        return
    ib = SurfaceIndex(Vo, Fo, seed=11, density=0)
    n_out = ib.normals
    a_n = index_a.normals[:, todo]
    cand, d2 = ib._candidates(index_a.centers[todo])
    d = np.sqrt(d2)
    valid = cand >= 0
    ci = np.where(valid, cand, 0)
    dmin = d.min(axis=1, keepdims=True)
    near = valid & (d <= dmin + tol)
    dots = a_n[0][:, None] * n_out[0][ci] + a_n[1][:, None] * n_out[1][ci] + a_n[2][:, None] * n_out[2][ci]
    j = np.argmax(np.where(near, dots, -np.inf), axis=1)
    res.voted[todo] = ci[np.arange(len(todo)), j]
    res.voted_dist[todo] = dmin[:, 0]


def _confirm(index_a: SurfaceIndex, Vo: np.ndarray, Fo: np.ndarray, res: FlipResult, samples: int,
             tol: float, prev: FlipResult | None = None, moved: np.ndarray | None = None) -> None:
    """Second opinion on the suspects, from the other side: the original triangles around a
    suspect vote (centroids, area-weighted, capped at one sample's share) for the output
    triangle closest to them (best-agreeing among those within ``tol``). A suspect is flipped
    unless the original triangles that it is closest to face its way: a triangle buried
    between two opposite sheets of a thin part (closest to both, standing for neither) is not
    a flip; a triangle folded over its neighbour gets no votes (the neighbour agrees better)
    and stays flipped."""
    sus = np.flatnonzero(res.suspect)
    res.flipped[:] = False
    if prev is not None:  # (the pairings carry on even through a check without suspects)
        _votes_for(index_a, Vo, Fo, np.zeros(0, np.int64), tol, prev,
                   np.zeros(0, np.int64) if moved is None else moved, res)
    if len(sus) == 0:
        return
    cen, rad = bounding_spheres(res.corners[sus])
    orig = index_a.near_set(cen, rad + res.reach[sus] + tol)
    orig = orig[index_a.reliable[orig]]
    if len(orig) == 0:
        res.flipped[sus] = True
        return
    _votes_for(index_a, Vo, Fo, orig, tol, None, np.zeros(0, np.int64), res)
    a_n = index_a.normals[:, orig]
    chosen = res.voted[orig]
    share = index_a.total_area / max(samples, 1)
    w = np.minimum(index_a.area[orig], share)
    pos = np.full(len(Fo), -1, np.int64)
    pos[sus] = np.arange(len(sus))
    mine = pos[chosen] >= 0
    votes = np.zeros((len(sus), 3))
    np.add.at(votes, pos[chosen[mine]], (a_n[:, mine] * w[mine]).T)
    got = np.linalg.norm(votes, axis=1) > 0
    C = res.corners[sus]
    n_sus = np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0])  # (only its sign against the votes counts)
    against = np.einsum("ij,ij->i", votes, n_sus) < 0.0
    res.flipped[sus] = ~got | against
