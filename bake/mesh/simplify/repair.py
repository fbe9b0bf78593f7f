"""Local repairs of a simplified mesh where its error peaks, and the locks that keep borders.

The library decides which vertices stay; its error metric (quadrics) tracks the mean distance
well but misses a few places where the distance to the original peaks: a fin of thin
triangles standing across the surface, a sharp crease left where the original has a rounded
fillet, a border chord cutting across a hole. Those few places set the Hausdorff maximum (on
the bunny at 1%, 11 of 695 triangles are within 30% of it), so they are repaired one by one:

* :func:`border_locks`: the input's open borders and seams (material edges, UV seams) are
  chains of edges; each chain is simplified on its own with Douglas-Peucker at a tolerance,
  and the vertices that keeps are locked for the library, so no border chord strays further
  than that from the input's border.
* :func:`flip_edges`: an edge between two triangles is turned (the quad's other diagonal) when
  that lowers the error measured over the two triangles (both directions, see
  :class:`LocalError`) and both new triangles face the way the two old ones did. Tried on every
  edge with a sharp dihedral (fins, folds, creases) and on every edge of a triangle where the
  error peaks.
* :func:`polish`: the free corners of the triangles where the error peaks are moved to lower
  the local *maximum*: the distances from points on the triangles around a corner to the
  original, and from the original's points that those triangles stand for, are linearised
  around the current position (distance along the direction to the closest point) and the
  largest is minimised with Lawson's iteratively reweighted least squares (a Chebyshev fit);
  a move that would turn a triangle around is shortened, and a move is kept only if the
  measured local maximum drops.

:func:`folds` counts pairs of neighbouring triangles whose normals point against each other
(dot below -0.9): a fold is a surface doubled back on itself, which the flip check (normal
against the original) does not see when both triangles of the fold lean the same way.

Right after the library, triangles turned against the input (the flip check) are repaired by
:func:`edge_flip_repair` (turning the edge a flipped triangle shares with a neighbour) and
:func:`relocate_repair` (moving a free corner to the middle of its neighbours on the input
surface); :func:`repair_cost` is the error around what they changed, before and after, on which
the stage keeps or undoes them.
"""

from __future__ import annotations

import numpy as np

from .error import FlipResult, SurfaceIndex, _pair_dist2, _tri_table, triangle_pattern
from .fit import plane_barycentric

__all__ = ["border_chains", "border_locks", "LocalError", "flip_edges", "polish", "folds", "FOLD_DOT",
           "edge_flip_repair", "relocate_repair", "repair_cost"]

# neighbouring triangles whose unit normals have a dot product below this are a fold
FOLD_DOT = -0.9
# barycentric grid on each triangle for local errors: 6 parts per edge (28 points: corners,
# edge points and inside points)
_LOCAL_N = 6


def _local_pattern(n: int = _LOCAL_N) -> np.ndarray:
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    i, j = i[keep], j[keep]
    return np.stack([1.0 - (i + j) / n, i / n, j / n], axis=1)


_BARY = _local_pattern()


# --------------------------------------------------------------------------- borders and seams
def border_chains(F: np.ndarray, seam_edges: np.ndarray | None = None) -> tuple[list[np.ndarray], np.ndarray]:
    """The chains of open border edges (and of ``seam_edges`` (E, 2), vertex pairs) of a mesh:
    (list of vertex arrays: open chains end to end, closed loops without the repeat, ends
    (vertices where the chains meet or stop: where not exactly two of these edges meet))."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    a = F.ravel()
    b = F[:, [1, 2, 0]].ravel()
    n = int(F.max()) + 1 if len(F) else 1
    key = np.minimum(a, b) * n + np.maximum(a, b)
    u, cnt = np.unique(key, return_counts=True)
    ek = u[cnt == 1]
    if seam_edges is not None and len(seam_edges):
        s = np.asarray(seam_edges, np.int64)
        ek = np.union1d(ek, np.minimum(s[:, 0], s[:, 1]) * n + np.maximum(s[:, 0], s[:, 1]))
    if len(ek) == 0:
        return [], np.zeros(0, np.int64)
    e = np.stack([ek // n, ek % n], axis=1)
    deg = np.bincount(e.ravel(), minlength=n)
    ends = np.flatnonzero((deg > 0) & (deg != 2))
    # adjacency (CSR) of the edge graph
    src = np.concatenate([e[:, 0], e[:, 1]])
    dst = np.concatenate([e[:, 1], e[:, 0]])
    eid = np.concatenate([np.arange(len(e)), np.arange(len(e))])
    order = np.argsort(src, kind="stable")
    src, dst, eid = src[order], dst[order], eid[order]
    start = np.searchsorted(src, np.arange(n + 1))
    used = np.zeros(len(e), bool)
    chains: list[np.ndarray] = []
    is_end = np.zeros(n, bool)
    is_end[ends] = True

    def walk(v0: int, first_edge: int) -> list[int]:
        out = [v0]
        v, ed = v0, first_edge
        while True:
            used[ed] = True
            w = int(e[ed, 0] + e[ed, 1] - v)
            out.append(w)
            if is_end[w] or w == v0:
                return out
            nxt = -1
            for k in range(start[w], start[w + 1]):
                if not used[eid[k]]:
                    nxt = int(eid[k])
                    break
            if nxt < 0:
                return out
            v, ed = w, nxt

    for v0 in ends.tolist():  # open chains, from each end
        for k in range(start[v0], start[v0 + 1]):
            if not used[eid[k]]:
                chains.append(np.asarray(walk(v0, int(eid[k])), np.int64))
    for ed in np.flatnonzero(~used).tolist():  # closed loops
        if not used[ed]:
            c = walk(int(e[ed, 0]), ed)
            chains.append(np.asarray(c[:-1] if c[-1] == c[0] else c, np.int64))
    return chains, ends


def border_locks(V: np.ndarray, chains: list[np.ndarray], ends: np.ndarray, tol: float, n: int,
                 budget: int | None = None) -> np.ndarray:
    """(n,) vertices to lock so each chain, simplified to them, stays within ``tol`` of itself
    (Douglas-Peucker over all chains at once: the chord that strays furthest is split first, at
    its furthest vertex, until every chord is within ``tol`` or ``budget`` vertices are locked).
    An open chain's two ends are always kept (chains of at most 3 vertices: all of them)."""
    import heapq

    lock = np.zeros(n, bool)
    ends_set = set(np.asarray(ends).tolist())
    heap: list = []
    polys: list[np.ndarray] = []

    def push(ci: int, i: int, j: int) -> None:
        if j - i < 2:
            return
        Q = polys[ci]
        a, ab = Q[i], Q[j] - Q[i]
        L = float(ab @ ab)
        X = Q[i + 1:j] - a
        t = np.clip((X @ ab) / L, 0.0, 1.0) if L > 0 else np.zeros(len(X))
        d = np.linalg.norm(X - t[:, None] * ab, axis=1)
        k = int(np.argmax(d))
        if d[k] > tol:
            heapq.heappush(heap, (-float(d[k]), ci, i, j, i + 1 + k))

    for c in chains:
        if len(c) <= 3:
            lock[c] = True
            continue
        closed = c[0] not in ends_set and c[-1] not in ends_set
        P = V[c]
        ci = len(polys)
        if closed:
            far = int(np.argmax(np.linalg.norm(P - P[0], axis=1)))
            polys.append(np.concatenate([P, P[:1]]))
            lock[c[[0, far]]] = True
            push(ci, 0, far)
            push(ci, far, len(c))
        else:
            polys.append(P)
            lock[c[[0, -1]]] = True
            push(ci, 0, len(c) - 1)
    order = {i: c for i, c in enumerate([c for c in chains if len(c) > 3])}
    count = int(lock.sum())
    while heap and (budget is None or count < budget):
        _, ci, i, j, m = heapq.heappop(heap)
        c = order[ci]
        v = c[m % len(c)]
        if not lock[v]:
            lock[v] = True
            count += 1
        push(ci, i, m)
        push(ci, m, j)
    return lock


# --------------------------------------------------------------------------- local errors
class LocalError:
    """Two-sided errors over a few triangles of the simplified mesh B: points of a fixed grid on
    each triangle against the original (``index_a``), and the original's points that stand for
    those triangles (``a_points`` with ``a_tri``: the triangle of B each is closest to) against
    them. Distances are the index's (upper bounds, exact unless its candidates miss)."""

    def __init__(self, index_a: SurfaceIndex, a_points: np.ndarray, a_tri: np.ndarray, n_tri: int,
                 spacing: float = 0.0):
        self.ia = index_a
        self.P = np.asarray(a_points, np.float64)
        # > 0: points on the triangles are a grid at this spacing, refined around the largest
        # distances (measure.directed), not the fixed pattern
        self.spacing = float(spacing)
        self.set_assignment(a_tri, n_tri)

    def set_assignment(self, a_tri: np.ndarray, n_tri: int) -> None:
        self.a_tri = np.asarray(a_tri, np.int64).copy()
        self.n_tri = n_tri
        self._csr()

    def _csr(self) -> None:
        ok = self.a_tri >= 0
        ids = np.flatnonzero(ok)
        order = ids[np.argsort(self.a_tri[ids], kind="stable")]
        self.order = order
        self.start = np.searchsorted(self.a_tri[order], np.arange(self.n_tri + 1))

    def points_of(self, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """(point ids, position of their triangle in ``tris``) of the original's points that
        stand for the triangles ``tris``."""
        tris = np.asarray(tris, np.int64)
        cnt = self.start[tris + 1] - self.start[tris]
        rows = np.repeat(np.arange(len(tris)), cnt)
        offs = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        return self.order[np.repeat(self.start[tris], cnt) + offs], rows

    def patches(self, C: np.ndarray, patch: np.ndarray, pts: np.ndarray, pts_patch: np.ndarray,
                n_patch: int, sample: np.ndarray | None = None) -> np.ndarray:
        """Local max per patch: triangles with corners ``C`` (m, 3, 3), each in patch
        ``patch[i]``; original points ``pts`` (ids) each in patch ``pts_patch[j]`` (measured
        against every triangle of its patch). Points on the triangles are measured against
        the original only for the triangles ``sample`` (a mask; default all)."""
        out = np.zeros(n_patch)
        if len(C):
            own = np.arange(len(C)) if sample is None else np.flatnonzero(sample)
            P = np.einsum("pk,mkd->mpd", _BARY, C[own]).reshape(-1, 3)
            d, _ = self.ia.distance(P)
            per = d.reshape(len(own), -1).max(axis=1)
            if self.spacing > 0 and len(own):
                from .measure import directed, surface_grid
                g = surface_grid(C[own].reshape(-1, 3), np.arange(3 * len(own)).reshape(-1, 3), 0,
                                 spacing=self.spacing)
                dd = directed(self.ia, g, seeds=max(8, min(32, len(own))), rounds=6, verify=False, prune=False)
                per = np.maximum(per, dd.tri_max[:len(own)] if len(dd.tri_max) >= len(own) else
                                 np.pad(dd.tri_max, (0, len(own) - len(dd.tri_max))))
            np.maximum.at(out, patch[own], per)
        if len(pts) and len(C):
            # pairs (point, triangle of its patch)
            order = np.argsort(patch, kind="stable")
            first = np.searchsorted(patch[order], np.arange(n_patch + 1))
            cnt = first[pts_patch + 1] - first[pts_patch]
            pr = np.repeat(np.arange(len(pts)), cnt)
            offs = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
            tr = order[np.repeat(first[pts_patch], cnt) + offs]
            table = _tri_table(C[:, 0], C[:, 1], C[:, 2])
            d2 = _pair_dist2(self.P[pts[pr]], np.take(table, tr, axis=1))
            best = np.full(len(pts), np.inf)
            np.minimum.at(best, pr, d2)
            np.maximum.at(out, pts_patch, np.sqrt(np.where(np.isfinite(best), best, 0.0)))
        return out


    def surface_normals(self, P: np.ndarray) -> np.ndarray:
        """Unit normals of the original's triangles closest to the points ``P``."""
        _, tri = self.ia.distance(P)
        return self.ia.normals[:, np.maximum(tri, 0)].T * (tri >= 0)[:, None]

    def triangles(self, V: np.ndarray, F: np.ndarray, tris: np.ndarray) -> np.ndarray:
        """Local error of each triangle ``tris`` of (V, F): points on it against the original,
        and the original's points that stand for it against it and the triangles across its
        edges."""
        tris = np.asarray(tris, np.int64)
        if len(tris) == 0:
            return np.zeros(0)
        nbr = edge_neighbours(F)
        nb = nbr[tris]  # (k, 3), -1 where open
        rows = np.concatenate([np.arange(len(tris)), np.repeat(np.arange(len(tris)), 3)])
        tt = np.concatenate([tris, nb.ravel()])
        ok = tt >= 0
        rows, tt = rows[ok], tt[ok]
        sample = np.zeros(len(tt), bool)
        sample[:len(tris)] = True  # the first len(tris) entries are the triangles themselves (all >= 0)
        pts, prow = self.points_of(tris)
        return self.patches(V[F[tt]], rows, pts, prow, len(tris), sample=sample)


def edge_pairs(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The half-edges (k, k+1) of every triangle as flat arrays ``a -> b`` (index 3t + k), and
    the pairs ``(h1, h2)`` of half-edges on an edge shared by exactly two triangles."""
    a = F.ravel()
    b = F[:, [1, 2, 0]].ravel()
    n = int(F.max()) + 1 if len(F) else 1
    key = np.minimum(a, b) * n + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    same = ks[1:] == ks[:-1]
    # exactly two: not also equal to the neighbours beyond
    two = same.copy()
    two[1:] &= ~same[:-1]
    two[:-1] &= ~same[1:]
    i = np.flatnonzero(two)
    return a, b, order[i], order[i + 1]


def edge_neighbours(F: np.ndarray) -> np.ndarray:
    """(t, 3) the triangle across each side (k, k+1) of each triangle (-1: open or shared by
    more than two)."""
    _a, _b, h1, h2 = edge_pairs(F)
    nbr = np.full(3 * len(F), -1, np.int64)
    nbr[h1] = h2 // 3
    nbr[h2] = h1 // 3
    return nbr.reshape(-1, 3)


# --------------------------------------------------------------------------- edge flips
def _interior_edges(F: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Edges shared by exactly two triangles running opposite ways: (t, u, side of t, side of u)
    (side k = corners k, k+1)."""
    a, b, h1, h2 = edge_pairs(F)
    ok = a[h1] == b[h2]  # opposite directions (consistently oriented)
    h1, h2 = h1[ok], h2[ok]
    return h1 // 3, h2 // 3, h1 % 3, h2 % 3


def _normals(V: np.ndarray, F: np.ndarray) -> np.ndarray:
    return np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])


def flip_edges(V: np.ndarray, F: np.ndarray, region: np.ndarray, tri_uvs: np.ndarray | None, fixed_edges: set | None,
               le: LocalError, candidates: np.ndarray | None = None, sharp: float = 0.3,
               gain: float = 0.97) -> int:
    """Turn edges (in place in ``F``, ``tri_uvs`` and ``le``'s assignment) where that lowers the
    local error (see the module docstring). Candidates: edges whose two triangles' normals have
    a dot product below ``sharp``, plus every edge of the triangles ``candidates``. Returns the
    number of edges turned."""
    if len(F) < 2:
        return 0
    t, u, st, su = _interior_edges(F)
    if len(t) == 0:
        return 0
    N = _normals(V, F)
    ln = np.linalg.norm(N, axis=1)
    Nu = np.divide(N, ln[:, None], out=np.zeros_like(N), where=ln[:, None] > 0)
    dots = np.einsum("ij,ij->i", Nu[t], Nu[u])
    pick = dots < sharp
    if candidates is not None and len(candidates):
        hot = np.zeros(len(F), bool)
        hot[candidates] = True
        pick |= hot[t] | hot[u]
    pick &= region[t] == region[u]
    idx = np.flatnonzero(pick)
    if len(idx) == 0:
        return 0
    t, u, st, su, dots = t[idx], u[idx], st[idx], su[idx], dots[idx]
    p = F[t, st]
    q = F[t, (st + 1) % 3]
    r = F[t, (st + 2) % 3]
    d = F[u, (su + 2) % 3]
    ok = (r != d)
    if tri_uvs is not None:  # a UV seam along the edge: not turned
        uvp_t, uvq_t = tri_uvs[t, st], tri_uvs[t, (st + 1) % 3]
        uvq_u, uvp_u = tri_uvs[u, su], tri_uvs[u, (su + 1) % 3]
        ok &= (uvp_t == uvp_u).all(axis=1) & (uvq_t == uvq_u).all(axis=1)
    if fixed_edges:
        n = len(V)
        ok &= ~np.isin(np.minimum(p, q) * n + np.maximum(p, q), np.fromiter(fixed_edges, np.int64, len(fixed_edges)))
    # the new diagonal r-d must not be an edge already
    n = len(V)
    a = F.ravel()
    b = F[:, [1, 2, 0]].ravel()
    existing = np.unique(np.minimum(a, b) * n + np.maximum(a, b))
    nk = np.minimum(r, d) * n + np.maximum(r, d)
    pos = np.searchsorted(existing, nk)
    ok &= ~((pos < len(existing)) & (existing[np.minimum(pos, len(existing) - 1)] == nk))
    # both new triangles face the way the pair did
    t1 = np.stack([p, d, r], axis=1)
    t2 = np.stack([d, q, r], axis=1)
    ref = N[t] + N[u]
    n1, n2 = _normals(V, t1), _normals(V, t2)
    is_fold = dots < FOLD_DOT
    ok &= is_fold | ((np.einsum("ij,ij->i", n1, ref) > 0) & (np.einsum("ij,ij->i", n2, ref) > 0))
    # and with the original surface under them (a fold's own normals cancel: this decides)
    r1, r2 = le.surface_normals(V[t1].mean(axis=1)), le.surface_normals(V[t2].mean(axis=1))
    ok &= (np.einsum("ij,ij->i", n1, r1) > 0) & (np.einsum("ij,ij->i", n2, r2) > 0)
    idx = np.flatnonzero(ok)
    if len(idx) == 0:
        return 0
    fold = is_fold[idx]
    t, u, st, su, p, q, r, d, t1, t2 = (x[idx] for x in (t, u, st, su, p, q, r, d, t1, t2))
    m = len(t)
    # local error before and after, both triangles together as one patch
    pts, rows = le.points_of(np.concatenate([t, u]))
    pp = rows % m
    old_C = np.concatenate([V[F[t]], V[F[u]]])
    new_C = np.concatenate([V[t1], V[t2]])
    patch = np.concatenate([np.arange(m), np.arange(m)])
    e_old = le.patches(old_C, patch, pts, pp, m)
    e_new = le.patches(new_C, patch, pts, pp, m)
    # a fold is undone unless that costs more than 10% of the local error
    good = np.flatnonzero((e_new < gain * e_old) | (fold & (e_new <= 1.1 * e_old)))
    if len(good) == 0:
        return 0
    good = good[np.argsort(e_new[good] - e_old[good], kind="stable")]  # biggest drop first
    touched = np.zeros(len(F), bool)
    turned = 0
    applied = []
    F_old = F.copy()
    uv_old = None if tri_uvs is None else tri_uvs.copy()
    for k in good.tolist():
        if touched[t[k]] or touched[u[k]]:
            continue
        applied.append(k)
        if tri_uvs is not None:
            uv = {int(F[t[k], j]): tri_uvs[t[k], j].copy() for j in range(3)}
            uv[int(d[k])] = tri_uvs[u[k], (su[k] + 2) % 3].copy()
            tri_uvs[t[k]] = [uv[int(x)] for x in t1[k]]
            tri_uvs[u[k]] = [uv[int(x)] for x in t2[k]]
        F[t[k]] = t1[k]
        F[u[k]] = t2[k]
        touched[t[k]] = touched[u[k]] = True
        turned += 1
    if turned:
        # a turn that makes a new fold with a neighbour is undone
        before = {tuple(x) for x in folds(V, F_old).tolist()}
        new = [x for x in folds(V, F).tolist() if tuple(x) not in before]
        if new:
            bad_tri = np.zeros(len(F), bool)
            bad_tri[np.asarray(new).ravel()] = True
            keep_k = []
            for k in applied:
                if bad_tri[t[k]] or bad_tri[u[k]]:
                    F[t[k]], F[u[k]] = F_old[t[k]], F_old[u[k]]
                    if tri_uvs is not None:
                        tri_uvs[t[k]], tri_uvs[u[k]] = uv_old[t[k]], uv_old[u[k]]
                    touched[t[k]] = touched[u[k]] = False
                    turned -= 1
                else:
                    keep_k.append(k)
            applied = keep_k
    if turned:
        # the original's points of a turned pair go to whichever new triangle is closer
        moved, rows = le.points_of(np.flatnonzero(touched))
        if len(moved):
            tt = np.flatnonzero(touched)[rows]
            partner = np.full(len(F), -1, np.int64)
            done = np.asarray(applied, np.int64)
            partner[t[done]] = u[done]
            partner[u[done]] = t[done]
            other = partner[tt]
            ca, cb = V[F[tt]], V[F[np.maximum(other, 0)]]
            da = _pair_dist2(le.P[moved], _tri_table(ca[:, 0], ca[:, 1], ca[:, 2]))
            db = _pair_dist2(le.P[moved], _tri_table(cb[:, 0], cb[:, 1], cb[:, 2]))
            le.a_tri[moved] = np.where((other >= 0) & (db < da), other, tt)
            le._csr()
    return turned


# --------------------------------------------------------------------------- vertex polish
def _ring(F: np.ndarray, n: int) -> tuple[np.ndarray, np.ndarray]:
    """(order, start): triangles around vertex v are order[start[v]:start[v+1]] // 3 ... as
    corner ids (triangle * 3 + corner)."""
    flat = F.ravel()
    order = np.argsort(flat, kind="stable")
    start = np.searchsorted(flat[order], np.arange(n + 1))
    return order, start


def polish(V: np.ndarray, F: np.ndarray, fixed: np.ndarray, le: LocalError, verts: np.ndarray,
           iterations: int = 25, passes: int = 1, ref: np.ndarray | None = None,
           tri_error: np.ndarray | None = None) -> tuple[int, float]:
    """Move the vertices ``verts`` (in place in ``V``) to lower the local maximum error around
    each (see the module docstring). Vertices sharing a triangle are moved in different
    batches. A move keeps every triangle around the vertex facing the way it did and, where
    ``ref`` (t, 3) gives the normal of the original under a triangle, facing with it. A move is
    kept if the local maximum around the vertex drops below what it was (``tri_error``: each
    triangle's error as known; else measured here). Returns (vertices moved, largest local max
    left among them)."""
    verts = np.asarray(verts, np.int64)
    verts = verts[~fixed[verts]]
    if len(verts) == 0 or len(F) == 0:
        return 0, 0.0
    corner_order, start = _ring(F, len(V))
    moved_total = 0
    worst = 0.0
    for _ in range(passes):
        # batches of vertices that share no triangle (greedy colouring)
        remaining = verts.copy()
        while len(remaining):
            taken_tri = np.zeros(len(F), bool)
            batch = []
            rest = []
            for v in remaining.tolist():
                ring = corner_order[start[v]:start[v + 1]] // 3
                if taken_tri[ring].any():
                    rest.append(v)
                else:
                    taken_tri[ring] = True
                    batch.append(v)
            m, w = _polish_batch(V, F, np.asarray(batch, np.int64), corner_order, start, le, iterations, ref,
                                 tri_error)
            moved_total += m
            worst = max(worst, w)
            remaining = np.asarray(rest, np.int64)
    return moved_total, worst


def _polish_batch(V, F, batch, corner_order, start, le: LocalError, iterations: int,
                  ref: np.ndarray | None, tri_error: np.ndarray | None) -> tuple[int, float]:
    nb = len(batch)
    # each vertex's ring (triangle, the vertex's corner in it)
    cnt = start[batch + 1] - start[batch]
    rv = np.repeat(np.arange(nb), cnt)
    offs = np.arange(cnt.sum()) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    corners = corner_order[np.repeat(start[batch], cnt) + offs]
    rt, rk = corners // 3, corners % 3
    x0 = V[batch].copy()
    C0 = V[F[rt]]
    if tri_error is not None:
        e_before = np.zeros(nb)
        np.maximum.at(e_before, rv, tri_error[rt])
    else:
        e_before = le.patches(C0, rv, *_patch_points(le, rt, rv), nb)
    # residual rows: b->a points of the ring triangles, a->b points standing for them
    nbary = len(_BARY)
    s_tri = np.repeat(np.arange(len(rt)), nbary)
    s_w = np.tile(_BARY, (len(rt), 1))
    S = np.einsum("mk,mkd->md", s_w, C0[s_tri])
    _, _, Q = le.ia.query(S)
    wv = s_w[np.arange(len(s_w)), rk[s_tri]]  # the moving vertex's weight
    rows_v = rv[s_tri]
    dirs = S - Q
    pa, prow = _patch_points(le, rt, rv)
    if len(pa):
        # closest point of each original point on its own triangle (of the ring)
        own = le.a_tri[pa]
        pos_in_ring = _position_in(rt, rv, own, prow)
        okp = pos_in_ring >= 0
        pa, prow, pos_in_ring = pa[okp], prow[okp], pos_in_ring[okp]
        Ct = C0[pos_in_ring]
        _, cp = _pair_dist2(le.P[pa], _tri_table(Ct[:, 0], Ct[:, 1], Ct[:, 2]), want_point=True)
        bw = _barycentric(cp, Ct)
        wa = bw[np.arange(len(bw)), rk[pos_in_ring]]
        S2, Q2 = cp, le.P[pa]
        rows_v = np.concatenate([rows_v, prow])
        wv = np.concatenate([wv, wa])
        S = np.concatenate([S, S2])
        Q = np.concatenate([Q, Q2])
        dirs = np.concatenate([dirs, S2 - Q2])
    ln = np.linalg.norm(dirs, axis=1)
    u = np.divide(dirs, ln[:, None], out=np.zeros_like(dirs), where=ln[:, None] > 0)
    # r_i(x) = g_i . x + h_i, with g_i = w_i u_i and h_i = u_i . (S_i - w_i x0 - Q_i)
    g = wv[:, None] * u
    h = np.einsum("ij,ij->i", u, S - wv[:, None] * x0[rows_v] - Q)
    # Lawson: minimise max |r_i| by reweighted least squares (per vertex)
    scale = np.maximum(e_before, 1e-300)
    lam = 1e-3
    weight = np.ones(len(g))
    x = x0.copy()
    for _ in range(iterations):
        A = np.zeros((nb, 3, 3))
        b = np.zeros((nb, 3))
        wg = weight[:, None] * g
        for i in range(3):
            b[:, i] = np.bincount(rows_v, weights=-(weight * h) * g[:, i], minlength=nb)
            for j in range(i, 3):
                A[:, i, j] = A[:, j, i] = np.bincount(rows_v, weights=wg[:, i] * g[:, j], minlength=nb)
        tot = np.bincount(rows_v, weights=weight, minlength=nb)
        reg = lam * np.maximum(tot, 1e-300)[:, None, None] * np.eye(3)
        A += reg
        b += lam * np.maximum(tot, 1e-300)[:, None] * x0
        x = np.linalg.solve(A, b[:, :, None])[:, :, 0]
        r = np.abs(np.einsum("ij,ij->i", g, x[rows_v]) + h)
        weight = weight * (r / scale[rows_v] + 1e-12)
        wsum = np.bincount(rows_v, weights=weight, minlength=nb)
        weight = weight / np.maximum(wsum[rows_v], 1e-300)
    # keep every ring triangle facing its old way (shorten the move until it does)
    n_old = _normals(V, F[rt])
    n_ref = None
    if ref is not None:
        n_ref = ref[rt]
        # only where the old triangle faced with it (a triangle already against it is the flip
        # repair's business)
        n_ref = np.where((np.einsum("ij,ij->i", n_ref, n_old) > 0)[:, None], n_ref, 0.0)
    step = np.ones(nb)
    for _ in range(8):
        xs = x0 + step[:, None] * (x - x0)
        Cn = C0.copy()
        Cn[np.arange(len(rt)), rk] = xs[rv]
        n_new = np.cross(Cn[:, 1] - Cn[:, 0], Cn[:, 2] - Cn[:, 0])
        bad = np.einsum("ij,ij->i", n_new, n_old) <= 0.1 * np.einsum("ij,ij->i", n_old, n_old)
        if n_ref is not None:
            bad |= np.einsum("ij,ij->i", n_new, n_ref) < 0
        badv = np.bincount(rv[bad], minlength=nb) > 0
        if not badv.any():
            break
        step[badv] *= 0.5
    xs = x0 + step[:, None] * (x - x0)
    Cn = C0.copy()
    Cn[np.arange(len(rt)), rk] = xs[rv]
    e_after = le.patches(Cn, rv, *_patch_points(le, rt, rv), nb)
    keep = (e_after < e_before) & (step > 1.0 / 200)
    V[batch[keep]] = xs[keep]
    return int(keep.sum()), float(np.where(keep, e_after, e_before).max()) if nb else 0.0


def _patch_points(le: LocalError, rt: np.ndarray, rv: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    pts, rows = le.points_of(rt)
    return pts, rv[rows]


def _position_in(rt: np.ndarray, rv: np.ndarray, tri: np.ndarray, row: np.ndarray) -> np.ndarray:
    """For each (triangle, ring row), the index into ``rt`` of that triangle in that ring (-1)."""
    big = int(max(rt.max() if len(rt) else 0, tri.max() if len(tri) else 0)) + 1
    key = rv * big + rt
    order = np.argsort(key, kind="stable")
    ks = key[order]
    q = row * big + tri
    pos = np.searchsorted(ks, q)
    ok = (pos < len(ks)) & (ks[np.minimum(pos, len(ks) - 1)] == q)
    return np.where(ok, order[np.minimum(pos, len(ks) - 1)], -1)


def _barycentric(P: np.ndarray, C: np.ndarray) -> np.ndarray:
    return plane_barycentric(P, C[:, 0], C[:, 1], C[:, 2])


# --------------------------------------------------------------------------- folds
def folds(V: np.ndarray, F: np.ndarray, dot: float = FOLD_DOT) -> np.ndarray:
    """(k, 2) pairs of triangles sharing an edge whose unit normals have a dot product below
    ``dot`` (zero-area triangles have no normal and are never in a fold)."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    if len(F) < 2:
        return np.zeros((0, 2), np.int64)
    a = F.ravel()
    b = F[:, [1, 2, 0]].ravel()
    n = int(F.max()) + 1
    key = np.minimum(a, b) * n + np.maximum(a, b)
    order = np.argsort(key, kind="stable")
    ks = key[order]
    # every pair of half-edges on the same edge (edges with more than two triangles: each pair)
    starts = np.flatnonzero(np.r_[True, ks[1:] != ks[:-1]])
    sizes = np.diff(np.r_[starts, len(ks)])
    ts, us = [], []
    for k in np.unique(sizes[sizes >= 2]).tolist():  # (a few distinct sizes: 2, and 3 or 4 where non-manifold)
        s0 = starts[sizes == k]
        i, j = np.triu_indices(k, 1)
        ts.append(order[(s0[:, None] + i[None]).ravel()] // 3)
        us.append(order[(s0[:, None] + j[None]).ravel()] // 3)
    if not ts:
        return np.zeros((0, 2), np.int64)
    t, u = np.concatenate(ts), np.concatenate(us)
    N = _normals(V, F)
    ln = np.linalg.norm(N, axis=1)
    Nu = np.divide(N, ln[:, None], out=np.zeros_like(N), where=ln[:, None] > 0)
    d = np.einsum("ij,ij->i", Nu[t], Nu[u])
    bad = (d < dot) & (ln[t] > 0) & (ln[u] > 0) & (t != u)
    pairs = np.stack([t[bad], u[bad]], axis=1)
    return np.unique(np.sort(pairs, axis=1), axis=0) if len(pairs) else pairs


# --------------------------------------------------------------------------- flipped triangles
def edge_flip_repair(V: np.ndarray, F: np.ndarray, region: np.ndarray, tri_uvs: np.ndarray | None,
                     fr: FlipResult, limit: int = 256) -> int:
    """Turn the shared edge of a flipped triangle and a neighbour (in place) when both new
    triangles then face the way the input surface under the pair does. Only edges inside one
    region and off UV seams are turned, so materials and UVs stay valid. Works on the few
    flipped triangles only (at most ``limit``). Returns how many edges were turned."""
    flipped, ref = fr.flipped, fr.ref
    # directed edge -> triangle
    n = max(int(F.max()) + 1, 1)
    d_key = np.concatenate([F[:, 0] * n + F[:, 1], F[:, 1] * n + F[:, 2], F[:, 2] * n + F[:, 0]])
    d_tri = np.tile(np.arange(len(F)), 3)
    order = np.argsort(d_key, kind="stable")
    d_key, d_tri = d_key[order], d_tri[order]

    def owner(p: int, q: int) -> int:
        k = p * n + q
        i = np.searchsorted(d_key, k)
        if i < len(d_key) and d_key[i] == k and (i + 1 == len(d_key) or d_key[i + 1] != k):
            return int(d_tri[i])
        return -1

    def nrm(tri: np.ndarray) -> np.ndarray:
        return np.cross(V[tri[1]] - V[tri[0]], V[tri[2]] - V[tri[0]])

    turned = 0
    touched = np.zeros(len(F), bool)
    for t in np.flatnonzero(flipped)[:limit]:
        if touched[t]:
            continue
        best = None
        for k in range(3):
            p, q, r = F[t, k], F[t, (k + 1) % 3], F[t, (k + 2) % 3]
            u = owner(q, p)
            if u < 0 or touched[u] or region[u] != region[t]:
                continue
            ku = int(np.flatnonzero(F[u] == q)[0])  # u = (q, p, d) rotated
            if F[u, (ku + 1) % 3] != p:
                continue
            d = F[u, (ku + 2) % 3]
            if d == r or owner(r, d) >= 0 or owner(d, r) >= 0:
                continue
            if tri_uvs is not None:
                uv_t = {F[t, j]: tri_uvs[t, j] for j in range(3)}
                uv_u = {F[u, j]: tri_uvs[u, j] for j in range(3)}
                if not (np.array_equal(uv_t[p], uv_u[p]) and np.array_equal(uv_t[q], uv_u[q])):
                    continue  # a UV seam runs along this edge
            t1 = np.array([p, d, r])
            t2 = np.array([d, q, r])
            rn = ref[t] + ref[u]
            score = min(float(nrm(t1) @ rn), float(nrm(t2) @ rn))
            if score > 0 and (best is None or score > best[0]):
                best = (score, u, t1, t2, k, ku)
        if best is None:
            continue
        _, u, t1, t2, k, ku = best
        if tri_uvs is not None:
            uv = {F[t, j]: tri_uvs[t, j].copy() for j in range(3)}
            uv.update({F[u, (ku + 2) % 3]: tri_uvs[u, (ku + 2) % 3].copy()})
            tri_uvs[t] = [uv[x] for x in t1]
            tri_uvs[u] = [uv[x] for x in t2]
        F[t], F[u] = t1, t2
        touched[t] = touched[u] = True
        turned += 1
    return turned


def relocate_repair(V: np.ndarray, F: np.ndarray, fixed: np.ndarray, fr: FlipResult, index_a: SurfaceIndex,
                    limit: int = 256) -> int:
    """Unfold a flipped triangle by moving one of its free corners (in place) to the centre of
    its neighbours, put back onto the input surface (closest point), when every triangle
    around that corner then faces the way the input under it does. Returns vertices moved."""
    flipped = fr.flipped
    ref = fr.ref.copy()
    no_vote = np.linalg.norm(ref, axis=1) == 0
    ref[no_vote] = np.cross(V[F[no_vote, 1]] - V[F[no_vote, 0]], V[F[no_vote, 2]] - V[F[no_vote, 0]])
    ref[flipped & no_vote] *= -1.0
    # vertex -> incident triangles (CSR)
    order = np.argsort(F.ravel(), kind="stable")
    starts = np.searchsorted(F.ravel()[order], np.arange(len(V) + 1))
    moved = 0
    for t in np.flatnonzero(flipped)[:limit]:
        for v in F[t]:
            if fixed[v]:
                continue
            ring_t = order[starts[v]:starts[v + 1]] // 3
            ring_v = np.unique(F[ring_t].ravel())
            ring_v = ring_v[ring_v != v]
            if len(ring_v) == 0:
                continue
            c = V[ring_v].mean(axis=0)
            _, _, cp = index_a.query(c[None])
            done = False
            for cand in (cp[0], c):
                old = V[v].copy()
                V[v] = cand
                tri = F[ring_t]
                n = np.cross(V[tri[:, 1]] - V[tri[:, 0]], V[tri[:, 2]] - V[tri[:, 0]])
                if (np.einsum("ij,ij->i", n, ref[ring_t]) > 0).all():
                    moved += 1
                    done = True
                    break
                V[v] = old
            if done:
                break
    return moved


def repair_cost(index_a: SurfaceIndex, V0: np.ndarray, F0: np.ndarray, V1: np.ndarray, F1: np.ndarray
                ) -> tuple[float, float]:
    """Two-sided error of a repaired result (V1, F1) and of what it was before (V0, F0; same
    triangle count), over the triangles the repair changed and the ring around them: points on
    those triangles against the input, and the input vertices under them against those
    triangles (KD-tree bounds, the same for both). Cheap: a repair touches a few triangles."""
    changed = np.flatnonzero((V0[F0] != V1[F1]).any(axis=(1, 2)))
    if len(changed) == 0:
        return 0.0, 0.0
    verts = np.unique(np.concatenate([F0[changed].ravel(), F1[changed].ravel()]))
    ring = np.flatnonzero(np.isin(F0, verts).any(axis=1) | np.isin(F1, verts).any(axis=1))
    tid, bary = triangle_pattern(np.full(len(ring), 7, np.int64))
    pts, under = [], []
    for Vx, Fx in ((V0, F0[ring]), (V1, F1[ring])):
        C = Vx[Fx]
        P = np.concatenate([np.einsum("nk,nkd->nd", bary, C[tid]), C.reshape(-1, 3)])
        d, t = index_a.distance(P)
        pts.append(d)
        under.append(t)
    qa = index_a.V[np.unique(index_a.F[np.concatenate(under)].ravel())]
    out = []
    for (Vx, Fx), d_ba in zip(((V0, F0[ring]), (V1, F1[ring])), pts):
        d_ab, _ = SurfaceIndex(Vx, Fx, density=0).distance(qa)
        out.append(max(float(d_ba.max()), float(d_ab.max())))
    return out[0], out[1]
