"""How far a simplified surface is from the original: the symmetric Hausdorff distance,
measured on a dense deterministic sample that is refined where the distance peaks.

The sample
----------
For each direction X -> Y (original -> simplified, simplified -> original) the points on X are
a regular grid over every triangle (:func:`surface_grid`): each triangle's edges are cut into
``n = 2**k`` equal parts, ``k`` chosen per triangle so the grid spacing is about the same
everywhere, and the points are the grid's nodes (``(n + 1)(n + 2) / 2`` per triangle). So every
vertex is a point, every edge carries points at its dyadic fractions (shared by the two
triangles along it: both compute them from the edge's own ends, so they coincide exactly), and
the inside of every triangle is covered evenly. The spacing is set so the grid has about
``points`` nodes; on a fine original whose triangles are smaller than that spacing the grid is
just the vertices. The grid's small triangles ("cells") are kept for the next step.

Refinement
----------
Peaks of the distance often sit on a triangle's edge or between two of the other mesh's
triangles, where the distance rises to a sharp ridge; a grid finds the ridge but not its top.
So, ``rounds`` times, the ``seeds`` largest distances at least a cell apart are taken and every
cell that has one of them as a corner is cut into four (edge midpoints, again shared exactly
between neighbours), and the new points are measured. Each round halves the spacing where the
distance peaks, so after the stage's ``ROUNDS`` (12) the worst places are sampled 4,096 times
finer than the rest.
On the simplified side the cells around the places closest to the original's farthest points
(within ``PIT_SHARE`` of the original -> simplified maximum) are cut in every round too: over a
narrow pit of the original the simplified side's distance peaks above the pit, often between
grid points whose distances are lower than elsewhere, where the largest-distance seeds never go
(the shuffled bunny at 10%: 3% low without it, against the independent measurement).

A cell is cut only if it may hold a distance above ``KEEP_SHARE`` (80%) of the largest distance
made exact so far. The bound is proven: the distance to one triangle is convex, so over a cell
it is at most the linear interpolation of its values at the cell's corners, and the distance to
Y is at most the distance to any one of its triangles; a cell's bound is the largest value, over
the cell, of the smallest of those interpolations for the three triangles of Y closest to its
corners (a small linear programme, :func:`envelope_bound`; with one triangle it is the largest
corner distance, the bound this measure used before, which is never lower). Cells left uncut hold
no point above 80% of the reported maximum, so what the stage's repairs and peak rounds look
at (distances within 80% of the maximum) is sampled as densely as before; the cut cells are
fewer (the bunny to 2,000 triangles: 40,243 new points instead of 104,099 on the original's
side, the same maximum). The stage cuts this way on the original's side only (its measure of
the simplified side, and its local repairs, cut every cell around their seeds).

Distances
---------
Every point's distance to Y comes from :class:`~bake.mesh.simplify.error.SurfaceIndex` (exact
point-triangle distances from libigl's AABB tree). The largest ones are checked again against
every triangle of Y that could be closer (``SurfaceIndex.exact``), until the largest checked
distance is at least every value left: the maximum reported is the exact distance at a point
of the sample. It is a *sampled* maximum: the true maximum over the surface can only be
larger, by at most how much the distance grows between samples; it is not called exact.
tests/mesh/test_simplify_measure.py and test_simplify_targets.py compare it with an independent
measurement (tests/mesh/simplify_reference.py: MeshLab's Hausdorff filter on 100,000 to 150,000
points, refined around its worst samples).

The mean of each direction is the area-weighted mean over the grid (each cell counts its area
times the mean of its corners), before refinement.

A proven bound
--------------
:func:`certify` goes on from a measure: every cell whose bound is above ``share`` times the
largest exact distance found is cut, largest bound first, and the new points are measured, until
no such cell is left or a budget of points is spent. Its cuts cut a cell's long edges only (a
needle of a cell into three, a flat one into two: :func:`_split`), so the budget goes on the
cells' area, not on the length of thin triangles. The largest bound of any cell is then an
upper bound of the distance at *every* point of X (up to floating-point rounding), not a sample
(``Directed.bound``); where it finished, the sampled maximum is within ``share`` of the true
one. Cutting where the bound is high also finds the peaks the seeds missed (the CSG model at 2%:
a peak near the tip of a sliver, 7.6% above the sampled maximum). The stage does this on its
final result (``error_bound``).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from scipy.spatial import cKDTree

from .error import SurfaceIndex, _pair_dist2, _verify

__all__ = ["surface_grid", "SurfaceGrid", "Directed", "HausdorffResult", "directed", "original_side", "hausdorff",
           "certify", "bound_hausdorff", "envelope_bound"]

# finest grid level per triangle: at most 2**_MAX_LEVEL parts per edge before refinement
_MAX_LEVEL = 6
# refinement levels below the grid (midpoints: positions stay exact fractions of 2**_KEY_LEVEL)
_KEY_LEVEL = _MAX_LEVEL + 16
# the points taken per refinement round, and the rounds
SEEDS = 256
ROUNDS = 12
# the simplified surface's grid cuts every triangle into at least 4**MIN_LEVEL_SIMPLIFIED cells:
# its corners are often the original's own vertices (distance 0), the peaks lie inside
MIN_LEVEL_SIMPLIFIED = 1
# ... and has this many points per triangle if that is more than the stage's ``points`` (at most
# four times as many): the bunny at 10%, 6,945 triangles, had its peak over a narrow pit 4-6% low
# with the 20,000 points of the default; 80,000 find it
POINTS_PER_SIMPLIFIED = 12
# ... and where the 4x cap below bites, every triangle is cut into at least 4**CAPPED_MIN_LEVEL
# cells (at least 15 nodes, shared; the bunny at 50%, 34,725 triangles, had 2.4 points each under
# the cap and its maximum 6.1% low, between grid points of a triangle that never became a seed)
CAPPED_MIN_LEVEL = 2
# separate places where the distance peaks, kept for the stage's repairs
PEAKS = 64
# the original's points within this share of the a -> b maximum mark places where the simplified
# side's distance may peak (hausdorff: extra refinement there)
PIT_SHARE = 0.9
PIT_PLACES = 16  # at most this many such places (the largest, a grid cell apart)
# cells are cut only where they may hold a distance above this share of the largest measured so
# far (a proven bound, see directed()): the maximum is unchanged, and so is every distance the
# stage's repairs and peak rounds look at (within 80% of the maximum)
KEEP_SHARE = 0.8
# points made exact per round for that bound
_LB_POINTS = 64
# the certification (certify()): cells cut per round, at most this many rounds
_CERT_BATCH = 16384
_CERT_ROUNDS = 64
# the proven bound's cuts leave a cell's edges shorter than this share of its longest whole (_split)
_UNCUT = 0.6


@dataclass
class SurfaceGrid:
    P: np.ndarray  # (n, 3) points
    tri: np.ndarray  # (n,) a triangle of the mesh the point lies on
    cells: np.ndarray  # (c, 3) point ids of the grid's small triangles
    cell_tri: np.ndarray  # (c,) the mesh triangle each cell lies in
    cell_area: np.ndarray  # (c,)
    spacing: float  # the target spacing (grid edges are between 0.5x and 1x of it on big triangles)
    keys: np.ndarray  # (n,) exact ids of the points (see surface_grid)
    levels: np.ndarray  # (T,) parts per edge of each triangle (a power of two)


def _tri_edges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Undirected edges (E, 2) with lo < hi, the edge of each triangle side (T, 3) (sides ab,
    bc, ca) and whether the side runs lo -> hi (T, 3)."""
    a = F.reshape(-1)
    b = F[:, [1, 2, 0]].reshape(-1)
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    n = int(F.max()) + 1 if len(F) else 1
    key, inv = np.unique(lo * n + hi, return_inverse=True)
    edges = np.stack([key // n, key % n], axis=1)
    return edges, inv.reshape(-1, 3), (a < b).reshape(-1, 3)


def _grid_spacing(longest: np.ndarray, n_vertices: int, points: int, max_level: int, min_level: int = 0) -> float:
    """A spacing for which the grid has about ``points`` nodes (bisection on its logarithm)."""
    if points <= n_vertices or len(longest) == 0:
        return float(longest.max()) if len(longest) else 1.0

    def count(s: float) -> float:
        k = np.clip(np.ceil(np.log2(np.maximum(longest / s, 1.0))), min_level, max(max_level, min_level))
        n = 2.0 ** k
        return n_vertices + float(((n - 1) * (n - 2) / 2 + 1.5 * (n - 1)).sum())

    lo, hi = float(longest.max()) / 2 ** (max_level + 1), float(longest.max())
    if count(lo) <= points:
        return lo
    for _ in range(40):
        mid = np.sqrt(lo * hi)
        if count(mid) > points:
            lo = mid
        else:
            hi = mid
        if hi <= lo * 1.01:
            break
    return hi


def surface_grid(V: np.ndarray, F: np.ndarray, points: int, max_level: int = _MAX_LEVEL,
                 spacing: float | None = None, min_level: int = 0) -> SurfaceGrid:
    """About ``points`` grid nodes over the mesh (every vertex among them); see the module
    docstring. Point keys: a vertex is its own id; an edge point is ``nV + edge * (M + 1) + q``
    for the point ``q / M`` of the way from the edge's lower-numbered end (``M = 2**_KEY_LEVEL``);
    an inside point gets a key of its own above those."""
    V = np.asarray(V, np.float64)
    F = np.asarray(F, np.int64).reshape(-1, 3)
    nV = len(V)
    T = len(F)
    if T == 0:
        z = np.zeros(0, np.int64)
        return SurfaceGrid(np.zeros((0, 3)), z, np.zeros((0, 3), np.int64), z, np.zeros(0), 0.0, z, z)
    C = V[F]
    el = np.linalg.norm(C - C[:, [1, 2, 0]], axis=2)  # sides ab, bc, ca
    longest = el.max(axis=1)
    used = np.unique(F)
    s = _grid_spacing(longest, len(used), points, max_level, min_level) if spacing is None else float(spacing)
    level = np.clip(np.ceil(np.log2(np.maximum(longest / max(s, 1e-300), 1.0))), min_level,
                    max(max_level, min_level)).astype(np.int64)
    if not level.any():  # every triangle is smaller than the spacing: the grid is the vertices
        remap = np.zeros(nV, np.int64)
        remap[used] = np.arange(len(used))
        cells = remap[F]
        area = 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1)
        tri = np.zeros(len(used), np.int64)
        tri[cells.ravel()] = np.repeat(np.arange(T), 3)
        # the grid's spacing is then the mesh's own: its median edge
        return SurfaceGrid(P=V[used], tri=tri, cells=cells, cell_tri=np.arange(T), cell_area=area,
                           spacing=float(np.median(el)), keys=used, levels=np.ones(T, np.int64))
    edges, side_edge, side_fwd = _tri_edges(F)
    M = 1 << _KEY_LEVEL
    inside_base = nV + len(edges) * (M + 1)
    keys_l, pos_l, tri_l, cells_l, ctri_l = [], [], [], [], []
    n_inside = 0
    for k in np.unique(level):
        n = 1 << int(k)
        g = np.flatnonzero(level == k)
        ii, jj = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = ii + jj <= n
        li, lj = ii[keep], jj[keep]  # barycentric (1 - i/n - j/n, i/n, j/n) on (a, b, c)
        npts = len(li)
        local = np.full((n + 1, n + 1), -1, np.int64)
        local[li, lj] = np.arange(npts)
        # cells: up (i,j)(i+1,j)(i,j+1); down (i+1,j)(i+1,j+1)(i,j+1)
        ui, uj = np.nonzero(np.add.outer(np.arange(n), np.arange(n)) <= n - 1)
        up = np.stack([local[ui, uj], local[ui + 1, uj], local[ui, uj + 1]], axis=1)
        di, dj = np.nonzero(np.add.outer(np.arange(n), np.arange(n)) <= n - 2)
        down = np.stack([local[di + 1, dj], local[di + 1, dj + 1], local[di, dj + 1]], axis=1)
        lcells = np.concatenate([up, down])
        G = len(g)
        Fg = F[g]
        key = np.empty((G, npts), np.int64)
        pos = np.empty((G, npts, 3))
        # inside
        ins = (li > 0) & (lj > 0) & (li + lj < n)
        bary = np.stack([1.0 - (li + lj) / n, li / n, lj / n], axis=1)
        pos[:] = np.einsum("pk,gkd->gpd", bary, C[g])
        m_in = int(ins.sum())
        key[:, ins] = inside_base + n_inside + np.arange(G * m_in).reshape(G, m_in)
        n_inside += G * m_in
        # corners
        for (ci, cj), c in (((0, 0), 0), ((n, 0), 1), ((0, n), 2)):
            p = local[ci, cj]
            key[:, p] = Fg[:, c]
            pos[:, p] = V[Fg[:, c]]
        # edges: side 0 = ab (j == 0, t = i/n from a), 1 = bc (i + j == n, t = j/n from b),
        # 2 = ca (i == 0, t = (n - j)/n from c)
        for side, sel, t_num in ((0, (lj == 0) & (li > 0) & (li < n), li),
                                 (1, (li + lj == n) & (li > 0) & (lj > 0), lj),
                                 (2, (li == 0) & (lj > 0) & (lj < n), n - lj)):
            if not sel.any():
                continue
            e = side_edge[g, side]
            fwd = side_fwd[g, side]
            q = (t_num[sel] * (M // n))[None, :]
            q = np.where(fwd[:, None], q, M - q)
            key[:, sel] = nV + e[:, None] * (M + 1) + q
            lo_v, hi_v = edges[e, 0], edges[e, 1]
            t = q / M
            pos[:, sel] = V[lo_v][:, None, :] + t[:, :, None] * (V[hi_v] - V[lo_v])[:, None, :]
        keys_l.append(key.reshape(-1))
        pos_l.append(pos.reshape(-1, 3))
        tri_l.append(np.repeat(g, npts))
        cells_l.append((lcells[None, :, :] + (np.arange(G) * npts)[:, None, None]).reshape(-1, 3)
                       + sum(len(x) for x in keys_l[:-1]))
        ctri_l.append(np.repeat(g, len(lcells)))
    keys = np.concatenate(keys_l)
    uk, first, inv = np.unique(keys, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    P = np.concatenate(pos_l)[first]
    tri = np.concatenate(tri_l)[first]
    cells = inv[np.concatenate(cells_l)]
    cell_tri = np.concatenate(ctri_l)
    cc = P[cells]
    area = 0.5 * np.linalg.norm(np.cross(cc[:, 1] - cc[:, 0], cc[:, 2] - cc[:, 0]), axis=1)
    return SurfaceGrid(P=P, tri=tri, cells=cells, cell_tri=cell_tri, cell_area=area, spacing=float(s), keys=uk,
                       levels=(1 << level))


@dataclass
class Directed:
    max: float
    mean: float
    worst: np.ndarray  # the point of X where the max was found
    worst_tri: int  # a triangle of X holding it
    grid_points: int  # points of the grid
    refine_points: int  # points added around the peaks
    exact: bool  # the max is the exact distance at its point (False: verification ran out of budget)
    top_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))  # verified, largest first
    top_dists: np.ndarray = field(default_factory=lambda: np.zeros(0))
    top_tris: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    nearest: np.ndarray | None = None  # (grid points,) closest triangle of Y per grid point
    spacing: float = 0.0
    # the largest distances at separate places (one per box of the grid spacing; upper bounds,
    # largest first) and the triangle of X each lies on: where the error peaks
    peak_points: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    peak_dists: np.ndarray = field(default_factory=lambda: np.zeros(0))
    peak_tris: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    tri_max: np.ndarray | None = None  # (T,) the largest distance found on each triangle of X
    # every point measured (grid and refinement): distances (upper bounds, the largest exact),
    # the triangle of X it lies on, the closest triangle of Y found
    all_points: np.ndarray | None = None
    all_dists: np.ndarray | None = None
    all_tris: np.ndarray | None = None
    all_nearest: np.ndarray | None = None
    # a proven upper bound of the distance at any point of X (nan: not proven; see certify())
    bound: float = float("nan")
    certification: dict | None = None  # what proving it took: cells cut, points added, rounds
    state: dict | None = field(default=None, repr=False)  # the cells and points, to go on from


def _distinct_top(P: np.ndarray, d: np.ndarray, k: int, apart: float) -> np.ndarray:
    """Ids of up to ``k`` of the largest ``d`` with no two in one box of side ``apart`` (a grid
    hash: vectorised, deterministic)."""
    if len(d) == 0:
        return np.zeros(0, np.int64)
    full = min(len(d), 64 * k)
    # the largest 4k first: if their first k boxes are all found before the smallest distance
    # taken (so no tie at that distance can be missing from the prefix), the answer is the
    # same as from all 64k
    m = min(full, 4 * k)
    while True:
        cand = np.argpartition(-d, m - 1)[:m] if m < len(d) else np.arange(len(d))
        cand = cand[np.lexsort((cand, -d[cand]))]
        box = np.floor(P[cand] / max(apart, 1e-300)).astype(np.int64)
        box -= box.min(axis=0)
        span = box.max(axis=0) + 1
        flat = (box[:, 0] * span[1] + box[:, 1]) * span[2] + box[:, 2]
        _, first = np.unique(flat, return_index=True)
        first.sort()
        if m == full or (len(first) >= k and d[cand[first[k - 1]]] > d[cand[-1]]):
            return cand[first[:k]]
        m = full


def _append(st: dict, name: str, add: np.ndarray) -> None:
    """``st[name] = concatenate([st[name], add])``, amortised: ``st[name]`` is a view of the
    first rows of a buffer (``st["_" + name]``) that doubles when full."""
    cur = st[name]
    n, k = len(cur), len(add)
    buf = st.get("_" + name)
    if buf is None or cur.base is not buf or n + k > len(buf):  # (not a view of it: start a new one)
        buf = np.empty((max(2 * (n + k), 1024),) + cur.shape[1:], cur.dtype)
        buf[:n] = cur
        st["_" + name] = buf
    buf[n:n + k] = add
    st[name] = buf[:n + k]


def envelope_bound(D: np.ndarray) -> np.ndarray:
    """The largest value over a triangle (cell) of the lower envelope of three affine functions,
    given at its corners: ``D[c, i, j]`` is function ``j`` at corner ``i`` of cell ``c``
    (``(s, 3, 3)``). Returns ``(s,)``: ``max over the cell of min_j L_j``, where ``L_j`` is the
    linear interpolation of ``D[c, :, j]``. This is a small linear programme (maximise ``z`` with
    ``z <= L_j`` on the triangle); its optimum lies at a vertex of the arrangement, so it is the
    largest of the envelope's values at the corners, where two functions cross on an edge, and
    where all three meet inside (tests/mesh/test_simplify_bound.py checks it against an LP
    solver)."""
    D = np.asarray(D, np.float64)
    s = len(D)
    best = D.min(axis=2).max(axis=1)  # the corners
    for j, k in ((0, 1), (0, 2), (1, 2)):
        g = D[:, :, j] - D[:, :, k]
        for i1, i2 in ((0, 1), (1, 2), (2, 0)):
            a, b = g[:, i1], g[:, i2]
            ok = a * b < 0  # the two functions cross inside this edge
            t = np.where(ok, a / np.where(ok, a - b, 1.0), 0.0)
            val = ((1.0 - t)[:, None] * D[:, i1, :] + t[:, None] * D[:, i2, :]).min(axis=1)
            best = np.where(ok, np.maximum(best, val), best)
    # all three equal inside: lambda . (D[:, 1] - D[:, 0]) = lambda . (D[:, 2] - D[:, 0]) = 0,
    # sum(lambda) = 1
    M = np.stack([D[:, :, 1] - D[:, :, 0], D[:, :, 2] - D[:, :, 0], np.ones((s, 3))], axis=1)
    det = np.linalg.det(M) if s else np.zeros(0)
    okd = np.abs(det) > 1e-300
    lam = np.zeros((s, 3))
    if okd.any():
        rhs = np.zeros((int(okd.sum()), 3, 1))
        rhs[:, 2] = 1.0
        lam[okd] = np.linalg.solve(M[okd], rhs)[..., 0]
    ok = okd & (lam >= 0).all(axis=1)
    val = np.einsum("si,sij->sj", lam, D).min(axis=1)
    return np.where(ok, np.maximum(best, val), best)


def _split(st: dict, index_y: SurfaceIndex, sel: np.ndarray, thin: bool = False) -> np.ndarray:
    """Cut the cells ``sel`` into four at their edges' midpoints (midpoints shared with
    neighbours cut before). With ``thin`` (the proven bound's cuts, :func:`_certify`), only
    their long edges are cut: an edge shorter than ``_UNCUT`` (0.6) of the cell's longest stays
    whole, so a needle of a cell (one short edge) gets three children (the tip's, and its wide end
    cut in two along the shorter diagonal) and a flat cell (one long edge) two. Every child's
    longest edge is then at most 0.8 of its parent's (half with four children), so the bounds
    shrink about as fast (:func:`_cell_bounds` grows with a cell's size) for far fewer points on
    long thin triangles: a needle cut k times is 3**k cells instead of 4**k. The children go to
    the end of ``st["cells"]``: the four-way cuts first (corner a's, b's, c's and the middle
    blocks, each in ``sel``'s order), then the flat cells' and the needles'. Returns the ids of
    the new points."""
    cells, ctri, allP = st["cells"], st["ctri"], st["P"]
    n_pts = len(allP)
    c = cells[sel]
    # edge k runs from corner k to corner k + 1; which are cut
    cut = np.ones((len(sel), 3), bool)
    if thin:
        e2 = np.stack([np.einsum("ij,ij->i", d, d) for d in
                       (allP[c[:, 1]] - allP[c[:, 0]], allP[c[:, 2]] - allP[c[:, 1]], allP[c[:, 0]] - allP[c[:, 2]])], 1)
        cut = e2 >= (_UNCUT * _UNCUT) * e2.max(axis=1, keepdims=True)
    ncut = cut.sum(axis=1)
    # turn the corners so the one cut edge is edge 0, or the one whole edge is edge 2
    r = np.zeros(len(sel), np.int64)
    one, two = ncut == 1, ncut == 2
    r[one] = np.argmax(cut[one], axis=1)
    r[two] = (np.argmin(cut[two], axis=1) + 1) % 3
    c = np.take_along_axis(c, (np.arange(3)[None, :] + r[:, None]) % 3, axis=1)
    four, flat, needle = np.flatnonzero(ncut == 3), np.flatnonzero(one), np.flatnonzero(two)
    # the edges cut: edge 0 of every cell, edge 1 of four-way and needle cells, edge 2 of four-way
    e1 = np.sort(np.concatenate([four, needle]))
    a = np.concatenate([c[:, 0], c[e1, 1], c[four, 2]])
    b = np.concatenate([c[:, 1], c[e1, 2], c[four, 0]])
    owner = np.concatenate([np.arange(len(sel)), e1, four])
    lo, hi = np.minimum(a, b), np.maximum(a, b)
    uk, inv = np.unique(lo * (1 << 31) + hi, return_inverse=True)
    mk, mi = st["mid_keys"], st["mid_ids"]
    pos = np.searchsorted(mk, uk)
    have = (pos < len(mk)) & (mk[np.minimum(pos, max(len(mk) - 1, 0))] == uk) if len(mk) else \
        np.zeros(len(uk), bool)
    ids = np.empty(len(uk), np.int64)
    ids[have] = mi[pos[have]]
    new = np.flatnonzero(~have)
    ids[new] = n_pts + np.arange(len(new))
    ulo, uhi = uk[new] >> 31, uk[new] & ((1 << 31) - 1)
    Pn = 0.5 * (allP[ulo] + allP[uhi])
    tn = np.empty(len(uk), np.int64)  # the triangle of X a midpoint lies in
    tn[inv] = ctri[sel][owner]
    dn, nn = index_y.distance(Pn)
    for name, add in (("P", Pn), ("D", dn), ("T", tn[new]), ("N", nn)):
        _append(st, name, add)
    # both key lists are sorted and share no key: merge them
    at = np.searchsorted(mk, uk[new])
    st["mid_keys"] = np.insert(mk, at, uk[new])
    st["mid_ids"] = np.insert(mi, at, ids[new])
    m = np.full((len(sel), 3), -1, np.int64)  # the midpoint of each cut edge
    mids = ids[inv]
    n, k1 = len(sel), len(e1)
    m[:, 0] = mids[:n]
    m[e1, 1] = mids[n:n + k1]
    m[four, 2] = mids[n + k1:]
    A, B, Cc = c[:, 0], c[:, 1], c[:, 2]
    f, fl, nd = four, flat, needle
    # a needle's wide end (A, m0, m1, C) is cut along its shorter diagonal
    P = st["P"]
    short = ((P[A[nd]] - P[m[nd, 1]]) ** 2).sum(axis=1) <= ((P[m[nd, 0]] - P[Cc[nd]]) ** 2).sum(axis=1)
    q1 = np.where(short[:, None], np.stack([A[nd], m[nd, 0], m[nd, 1]], 1), np.stack([A[nd], m[nd, 0], Cc[nd]], 1))
    q2 = np.where(short[:, None], np.stack([A[nd], m[nd, 1], Cc[nd]], 1), np.stack([m[nd, 0], m[nd, 1], Cc[nd]], 1))
    kids = np.concatenate([np.stack([A[f], m[f, 0], m[f, 2]], 1), np.stack([m[f, 0], B[f], m[f, 1]], 1),
                           np.stack([m[f, 2], m[f, 1], Cc[f]], 1), np.stack([m[f, 0], m[f, 1], m[f, 2]], 1),
                           np.stack([A[fl], m[fl, 0], Cc[fl]], 1), np.stack([m[fl, 0], B[fl], Cc[fl]], 1),
                           np.stack([m[nd, 0], B[nd], m[nd, 1]], 1), q1, q2])
    parent = sel[np.concatenate([np.tile(f, 4), np.tile(fl, 2), np.tile(nd, 3)])]
    keep = np.ones(len(cells), bool)
    keep[sel] = False
    st["cells"] = np.concatenate([cells[keep], kids])
    st["ctri"] = np.concatenate([ctri[keep], ctri[parent]])
    if st.get("bound") is not None:
        # the certification's bounds follow the cells; a child's bound is at most its parent's
        # (the parent's bound holds over all of it), kept as a cap on what it computes
        st["cap"] = np.concatenate([st["cap"][keep], st["bound"][parent]])
        st["bound"] = np.concatenate([st["bound"][keep], np.full(len(kids), np.nan)])
    return n_pts + np.arange(len(new))


def _cell_bounds(st: dict, index_y: SurfaceIndex, sel: np.ndarray) -> np.ndarray:
    """A proven upper bound of the distance to Y over each cell ``sel``. The distance to one
    triangle of Y is convex, so over a cell it is at most the linear interpolation of its values
    at the cell's corners, and the distance to Y is at most the smallest of those for the
    triangles closest to the three corners: the bound is the largest value of that lower
    envelope over the cell (:func:`envelope_bound`; exact point-triangle distances at the
    corners). Cells with a corner that found no triangle get infinity."""
    if len(sel) == 0:
        return np.zeros(0)
    c = st["cells"][sel]
    near_c = st["N"][c]
    allP = st["P"]
    bound = np.empty(len(sel))
    # one closest triangle for all three corners: the largest corner distance to it
    one = (near_c[:, 0] == near_c[:, 1]) & (near_c[:, 1] == near_c[:, 2])
    if one.any():
        cu = c[one].ravel()
        d2 = _pair_dist2(allP[cu], np.take(index_y.table, np.maximum(near_c[one].ravel(), 0), axis=1))
        bound[one] = np.sqrt(d2.reshape(-1, 3).max(axis=1))
    many = np.flatnonzero(~one)
    if len(many):
        c, nc = c[many], near_c[many]
        # the nine (corner, closest triangle of a corner) pairs of each cell; neighbouring cells
        # share most of them, so each distinct pair is measured once
        nT = np.int64(len(index_y.F))
        pt = np.repeat(c, 3, axis=1)  # (s, 9): column 3 i + j pairs corner i ...
        tr = np.maximum(np.tile(nc, (1, 3)), 0)  # ... with the closest triangle of corner j
        uk, inv = np.unique(pt.ravel() * nT + tr.ravel(), return_inverse=True)
        d2 = _pair_dist2(allP[uk // nT], np.take(index_y.table, uk % nT, axis=1))
        bound[many] = envelope_bound(np.sqrt(d2[inv.reshape(-1)].reshape(-1, 3, 3)))
    bound[(near_c < 0).any(axis=1)] = np.inf
    return bound


def _raise_lb(st: dict, index_y: SurfaceIndex, ids: np.ndarray) -> None:
    """Make the largest distances among the points ``ids`` exact (a few, in place) and raise
    ``st["lb"]``, the largest distance made exact so far (a lower bound of the maximum)."""
    D = st["D"]
    ids = ids[D[ids] > st["lb"]]
    if len(ids) == 0:
        return
    if len(ids) > _LB_POINTS:
        ids = ids[np.argpartition(-D[ids], _LB_POINTS - 1)[:_LB_POINTS]]
    D[ids], _ = index_y.exact(st["P"][ids], D[ids])
    st["lb"] = max(st["lb"], float(D[ids].max()))


def _certify(st: dict, index_y: SurfaceIndex, share: float, budget: int, floor: float = 0.0) -> None:
    """Cut, largest bound first, every cell whose proven bound (:func:`_cell_bounds`, at most
    its parent's) is above ``share`` times the largest exact distance found and above ``floor``,
    until none is left or the next cuts could pass ``budget`` new points (a cut adds at most
    three); ``st["bound"]`` then bounds every cell, and its maximum the true maximum over X."""
    if st.get("bound") is None:
        st["bound"] = np.full(len(st["cells"]), np.nan)
        st["cap"] = np.full(len(st["cells"]), np.inf)
    cert = st.setdefault("cert", {"cells_cut": 0, "points": 0, "rounds": 0})
    _raise_lb(st, index_y, np.arange(len(st["P"])))

    def open_cells() -> np.ndarray:
        """Bound the cells not bounded yet (new children); the cells still above the target."""
        todo = np.flatnonzero(np.isnan(st["bound"]))
        st["bound"][todo] = np.minimum(_cell_bounds(st, index_y, todo), st["cap"][todo])
        return np.flatnonzero(st["bound"] > max(share * st["lb"], floor))

    open_ = open_cells()
    for _ in range(_CERT_ROUNDS):
        room = (budget - cert["points"]) // 3
        if len(open_) == 0 or room <= 0:
            break
        take = np.sort(open_[np.argsort(-st["bound"][open_], kind="stable")[:min(_CERT_BATCH, room)]])
        new = _split(st, index_y, take, thin=True)
        cert["cells_cut"] += len(take)
        cert["points"] += len(new)
        cert["rounds"] += 1
        _raise_lb(st, index_y, new)
        open_ = open_cells()
    cert["open_cells"] = int(len(open_))


def directed(index_y: SurfaceIndex, grid: SurfaceGrid, *, seeds: int = SEEDS, rounds: int = ROUNDS,
             verify: bool = True, straddling: bool = False, prune: bool = True,
             extra: tuple[np.ndarray, np.ndarray] | None = None) -> Directed:
    """The distances from the grid's points (on X) to Y, refined around the peaks; see the
    module docstring. With ``straddling``, every cell whose corners are closest to different
    triangles of Y is cut once before the refinement (the distance to one triangle is convex
    over a cell, largest at a corner; only where the closest triangle changes can it peak
    inside). With ``prune``, cells are cut only where they may hold a distance above
    KEEP_SHARE of the largest distance made exact so far (the stage's local repairs, which
    compare small patches triangle by triangle, cut every cell around their seeds).

    ``extra``: (points on X, their triangles of X) where a peak is suspected; in every round the
    cells around them are cut too, whatever their distances (:func:`hausdorff` passes the
    places on the simplified surface closest to the original's farthest points).

    :func:`certify` goes on from the result to a proven upper bound of the maximum."""
    P = grid.P
    if len(P) == 0 or len(index_y.F) == 0:
        inf = 0.0 if len(P) == 0 else float("inf")
        return Directed(inf, inf, np.zeros(3), -1, len(P), 0, True, bound=inf)
    d, near = index_y.distance(P)
    # area-weighted mean over the grid's cells
    w = grid.cell_area
    mean = float((w * d[grid.cells].mean(axis=1)).sum() / w.sum()) if w.sum() > 0 else float(d.mean())
    st = {"cells": grid.cells, "ctri": grid.cell_tri, "P": P, "D": d, "T": grid.tri, "N": near,
          "mid_keys": np.zeros(0, np.int64), "mid_ids": np.zeros(0, np.int64), "lb": 0.0, "bound": None,
          "grid": grid, "near": near, "mean": mean, "verify": verify, "index": index_y}

    def can_rise(sel: np.ndarray) -> np.ndarray:
        """The cells ``sel`` that may hold a distance above KEEP_SHARE of the largest distance
        made exact so far (:func:`_cell_bounds`; the distances are upper bounds, some far above
        the truth: the share is taken of the largest made exact, a lower bound of the maximum)."""
        if len(sel) == 0 or not prune:
            return sel
        return sel[_cell_bounds(st, index_y, sel) > KEEP_SHARE * st["lb"]]

    if prune:
        _raise_lb(st, index_y, np.arange(len(P)))
    if straddling:
        N = st["N"][st["cells"]]
        _split(st, index_y, can_rise(np.flatnonzero((N[:, 0] != N[:, 1]) | (N[:, 1] != N[:, 2]))))
    apart = grid.spacing
    pool = np.arange(len(st["P"]))  # where the next seeds are looked for: the last seeds and new points
    for r in range(rounds):
        # many places for the first rounds, fewer (the best of them) for the deeper ones
        allP, allD = st["P"], st["D"]
        top = pool[_distinct_top(allP[pool], allD[pool], max(seeds >> (r // 2), min(seeds, 32)), apart)]
        hot = np.zeros(len(allP), bool)
        hot[top] = True
        if extra is not None and len(extra[0]):
            # the points of the extra places' triangles nearest to each place: their cells are cut
            ids = np.flatnonzero(np.isin(st["T"], extra[1]))
            if len(ids):
                _, nn = cKDTree(allP[ids]).query(extra[0], k=min(3, len(ids)))
                hot[ids[np.asarray(nn).ravel()]] = True
        cells = st["cells"]
        sel = can_rise(np.flatnonzero(hot[cells[:, 0]] | hot[cells[:, 1]] | hot[cells[:, 2]]))
        if len(sel) == 0:
            break
        pool = np.concatenate([top, _split(st, index_y, sel)])
        if prune:
            _raise_lb(st, index_y, pool)
    return _result(st, index_y)


def certify(d: Directed, share: float, points: int, floor: float = 0.0) -> Directed:
    """``d`` with a proven upper bound of its maximum: every cell whose bound
    (:func:`_cell_bounds`) is above ``share`` times the largest exact distance found, and above
    ``floor``, is cut, largest bound first, until none is left or ``points`` new points would be
    passed. ``Directed.bound`` is then the largest bound of any cell: the distance to Y at any
    point of X is at most that (up to floating-point rounding); it is at most
    ``max(share * max, floor)`` when it finished (``certification["open_cells"] == 0``)."""
    if d.state is None:
        return d
    # a copy that shares no buffer with ``d`` (its distances are made exact in place)
    st = {k: v for k, v in d.state.items() if not k.startswith("_")}
    st["D"] = st["D"].copy()
    for k in ("bound", "cap"):
        if st.get(k) is not None:
            st[k] = st[k].copy()
    if "cert" in st:
        st["cert"] = dict(st["cert"])
    _certify(st, st["index"], share, points, floor)
    return _result(st, st["index"])


def _result(st: dict, index_y: SurfaceIndex) -> Directed:
    grid, near = st["grid"], st["near"]
    allP, D, allT, allN = st["P"], st["D"].copy(), st["T"], st["N"]
    n_pts = len(allP)
    if st["verify"]:
        tops, exact = _verify(allP, D, index_y)
    else:  # upper bounds (the repairs compare before and after with the same index)
        tops, exact = np.argsort(-D, kind="stable")[:1], False
    i = int(tops[0])
    pk = _distinct_top(allP, D, PEAKS, 0.5 * grid.spacing)
    tri_max = np.zeros(int(grid.cell_tri.max()) + 1 if len(grid.cell_tri) else 0)
    np.maximum.at(tri_max, allT, D)
    bound, cert = float("nan"), None
    if st.get("bound") is not None:
        # the sampled max is exact at its point (below every bound), or an upper bound itself
        bound = max(float(st["bound"].max()) if len(st["bound"]) else 0.0, float(D[i]) if not exact else 0.0)
        cert = dict(st.get("cert", {}))
    return Directed(max=float(D[i]), mean=st["mean"], worst=allP[i].copy(), worst_tri=int(allT[i]),
                    grid_points=len(grid.P), refine_points=n_pts - len(grid.P), exact=bool(exact),
                    top_points=allP[tops], top_dists=D[tops], top_tris=allT[tops], nearest=near,
                    spacing=grid.spacing, peak_points=allP[pk], peak_dists=D[pk], peak_tris=allT[pk],
                    tri_max=tri_max, all_points=allP, all_dists=D, all_tris=allT, all_nearest=allN,
                    bound=bound, certification=cert, state=st)


def _pit_places(ab: Directed, index_b: SurfaceIndex) -> tuple[np.ndarray, np.ndarray] | None:
    """The places on B closest to A's farthest points: A's measured points within
    PIT_SHARE of the a -> b maximum (at most PIT_PLACES, a grid cell apart), and their closest
    points and triangles on B."""
    if ab.all_points is None or not np.isfinite(ab.max) or ab.max <= 0:
        return None
    sel = np.flatnonzero(ab.all_dists >= PIT_SHARE * ab.max)
    if len(sel) == 0:
        return None
    sel = sel[_distinct_top(ab.all_points[sel], ab.all_dists[sel], PIT_PLACES, ab.spacing)]
    _, tri, cp = index_b.query(ab.all_points[sel])
    ok = tri >= 0
    return cp[ok], tri[ok]


@dataclass
class HausdorffResult:
    max: float  # absolute units, the larger directed max
    mean: float  # mean of the two directions' area-weighted means
    max_a_to_b: float  # original -> simplified (features cut off)
    max_b_to_a: float  # simplified -> original (bulges)
    mean_a_to_b: float
    mean_b_to_a: float
    worst_point: np.ndarray
    points: int  # grid points measured, both directions
    refine_points: int  # points added around the peaks, both directions
    a_to_b: Directed | None = None
    b_to_a: Directed | None = None
    exact: bool = True  # both maxima are exact distances at their points (see Directed.exact)

    @property
    def bound(self) -> float:
        """A proven upper bound of the symmetric maximum (nan where a direction has none)."""
        if self.a_to_b is None or self.b_to_a is None:
            return float("nan")
        b = (self.a_to_b.bound, self.b_to_a.bound)
        return float("nan") if any(np.isnan(x) for x in b) else max(b)

    @property
    def top_points(self) -> np.ndarray:
        return np.concatenate([self.a_to_b.top_points, self.b_to_a.top_points]) if self.a_to_b else np.zeros((0, 3))

    @property
    def top_dists(self) -> np.ndarray:
        return np.concatenate([self.a_to_b.top_dists, self.b_to_a.top_dists]) if self.a_to_b else np.zeros(0)


def original_side(index_b: SurfaceIndex, grid_a: SurfaceGrid, *, seeds: int = SEEDS, rounds: int = ROUNDS,
                  straddling: bool = True) -> Directed:
    """The original -> simplified direction of :func:`hausdorff` on its own (the original's
    side is cheap to measure, the simplified mesh is small: with ``straddling`` its cells that
    straddle two triangles of the simplified mesh and may hold more than KEEP_SHARE of the
    maximum are cut once, and it takes four times the seeds)."""
    return directed(index_b, grid_a, seeds=4 * seeds, rounds=rounds, straddling=straddling)


def simplified_grid(n_triangles: int, points: int) -> tuple[int, int]:
    """The simplified side's grid: (points, least level per triangle). ``POINTS_PER_SIMPLIFIED``
    per triangle where that is more than ``points``, at most four times ``points``; where that cap
    bites, every triangle at least at level ``CAPPED_MIN_LEVEL`` (the grid then grows past the cap
    with the triangle count)."""
    want = POINTS_PER_SIMPLIFIED * n_triangles
    if want > 4 * points:
        return 4 * points, max(MIN_LEVEL_SIMPLIFIED, CAPPED_MIN_LEVEL)
    return max(points, want), MIN_LEVEL_SIMPLIFIED


def hausdorff(Va: np.ndarray, Fa: np.ndarray, Vb: np.ndarray, Fb: np.ndarray, *, points: int = 20000,
              index_a: SurfaceIndex | None = None, grid_a: SurfaceGrid | None = None,
              index_b: SurfaceIndex | None = None, seeds: int = SEEDS, rounds: int = ROUNDS,
              straddling: bool = True, a_to_b: Directed | None = None) -> HausdorffResult:
    """Symmetric Hausdorff distance between surface A (original) and B (simplified), each
    direction on a grid of about ``points`` points refined around its peaks. ``a_to_b``: that
    direction already measured (:func:`original_side` with the same index, grid and options)."""
    Fa = np.asarray(Fa, np.int64).reshape(-1, 3)
    Fb = np.asarray(Fb, np.int64).reshape(-1, 3)
    if len(Fa) == 0 or len(Fb) == 0:
        inf = 0.0 if len(Fa) == len(Fb) else float("inf")
        return HausdorffResult(inf, inf, inf, inf, inf, inf, np.zeros(3), 0, 0)
    ia = index_a if index_a is not None else SurfaceIndex(Va, Fa)
    ib = index_b if index_b is not None else SurfaceIndex(Vb, Fb)
    ga = grid_a if grid_a is not None else surface_grid(Va, Fa, points)
    # the simplified side: POINTS_PER_SIMPLIFIED points per triangle (peaks over the original's
    # narrow pits hide under big triangles between coarser grid points), at most 4x ``points``
    # and then every triangle cut at least CAPPED_MIN_LEVEL times
    n_b, level_b = simplified_grid(len(Fb), points)
    gb = surface_grid(Vb, Fb, n_b, min_level=level_b)
    ab = a_to_b if a_to_b is not None else original_side(ib, ga, seeds=seeds, rounds=rounds, straddling=straddling)
    # (the simplified side's cells are cut around its seeds only, as before: its bound, to one
    # small triangle of the original, is too loose to leave many out, and costs a tenth)
    # a peak of the simplified side over a narrow pit of the original can sit between grid points
    # on a triangle whose grid shows only part of it (bunny shuffled, 10%: 3% low without this):
    # it lies above the pit, where the original's farthest points are closest to the simplified
    # surface, so the refinement also cuts around those places
    ba = directed(ia, gb, seeds=seeds, rounds=rounds, prune=False, extra=_pit_places(ab, ib))
    return _symmetric(ab, ba)


def _symmetric(ab: Directed, ba: Directed) -> HausdorffResult:
    worst = ab.worst if ab.max >= ba.max else ba.worst
    return HausdorffResult(max=max(ab.max, ba.max), mean=0.5 * (ab.mean + ba.mean), max_a_to_b=ab.max,
                           max_b_to_a=ba.max, mean_a_to_b=ab.mean, mean_b_to_a=ba.mean, worst_point=worst,
                           points=ab.grid_points + ba.grid_points, refine_points=ab.refine_points + ba.refine_points,
                           a_to_b=ab, b_to_a=ba, exact=ab.exact and ba.exact)


def bound_hausdorff(h: HausdorffResult, share: float, points: int, floor: float = 0.0,
                    both: bool = True) -> HausdorffResult:
    """``h`` with a proven upper bound of the original -> simplified maximum and (``both``) of the
    other direction's (:func:`certify`, at most ``points`` new points per direction)."""
    if h.a_to_b is None or h.b_to_a is None:
        return h
    return _symmetric(certify(h.a_to_b, share, points, floor),
                      certify(h.b_to_a, share, points, floor) if both else h.b_to_a)
