"""Convex polygon fragments and robust, vectorised splitting by planes.

The BSP builder never works on triangle fans after a split: a fragment is a convex polygon (the
piece of one *source face* that lies in a cell), kept as a polygon until the very end, where it is
fanned into ``k - 2`` triangles. Cutting a polygon adds at most one corner per piece, so a cut
costs +2 triangles (+1 through a corner, 0 along a diagonal), never +4 as for two fan triangles.
A source face is one input triangle, or several coplanar input triangles merged into one convex
polygon (``merge.py``).

Storage is padded: ``pos[f, :count[f]]`` are the corners in order and the slots after them repeat
corner 0, so ``min``/``max`` over the corner axis and the fan area formula need no masks. Each
corner carries its attributes (UV, vertex colour: interpolated linearly along cut edges) and the
index of the scene vertex it is (``-1`` for a vertex made by a cut).

Coordinates are *normalised* (centred on the bbox centre, divided by the bbox diagonal), so every
tolerance is a fraction of the scene size and nothing depends on where the scene sits or its size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..geometry import corners_at, edge_crossings


MIN_COS_TILT = np.cos(np.radians(30.0))  # a face tilted further is not in a plane's coplanar group


@dataclass
class SplitResult:
    """Fragment ids after classifying (and cutting) a batch of fragments, each by its own plane.
    ``owner`` arrays give, for each id, the position of the plane/node it was classified by."""

    front: np.ndarray
    front_owner: np.ndarray
    back: np.ndarray
    back_owner: np.ndarray
    on: np.ndarray  # coplanar fragments
    on_owner: np.ndarray
    on_side: np.ndarray  # 0: seen from the front (normal along the plane's), 1: from the back, 2: both
    splits: int  # fragments cut in two
    kept_whole: int  # straddling fragments not cut because a piece would be below min area
    grid_kept: int = 0  # ... of them, because a piece snapped to the grid would be collapsed or tilted


class Tape:
    """Where every cut corner's attributes came from, so they can be computed again for other
    attribute values without building the tree again (bake/bsp/stage.py reuses a tree when only
    the vertex colours changed).

    Attribute channel ``ch`` holds an id instead of an attribute: the input corners are ids
    0 .. n0 - 1; each corner a cut makes gets the next id, and the tape records its two parent
    ids and the cut parameter ``t`` (the new corner is ``a + t * (b - a)``, computed exactly as
    :func:`_cut` computes it). Every other step only moves attributes (gathers, padding, fans),
    so :meth:`replay` on the same input values gives the same bits as the build."""

    def __init__(self, ch: int, n0: int):
        self.ch = ch
        self.n0 = n0
        self.next = n0
        self.batches: list[tuple[int, np.ndarray, np.ndarray, np.ndarray]] = []

    def record(self, Aa: np.ndarray, Ab: np.ndarray, t: np.ndarray, cross: np.ndarray, Ai: np.ndarray) -> None:
        n = int(cross.sum())
        if not n:
            return
        a = Aa[..., self.ch][cross].astype(np.int64)
        b = Ab[..., self.ch][cross].astype(np.int64)
        view = Ai[..., self.ch]
        view[cross] = np.arange(self.next, self.next + n, dtype=np.float64)
        self.batches.append((self.next, a, b, np.array(t[..., 0][cross], np.float64)))
        self.next += n

    def state(self) -> dict:
        return {"ch": self.ch, "n0": self.n0, "next": self.next, "batches": list(self.batches)}

    @staticmethod
    def replay(state: dict, base: np.ndarray) -> np.ndarray:
        """(ids, C) values of every id for input corner values ``base`` (n0, C)."""
        vals = np.empty((state["next"], base.shape[1]))
        vals[:state["n0"]] = base
        for start, a, b, t in state["batches"]:
            va, vb = vals[a], vals[b]
            vals[start:start + len(a)] = va + t[:, None] * (vb - va)
        return vals


class FaceStore:
    """An append-only set of convex fragments of source faces.

    ``src_plane[s]`` is source face s's exact plane (unit normal, offset; normal 0 when the face is
    degenerate), ``src_two_sided[s]`` whether it is visible from both sides."""

    def __init__(self, pos: np.ndarray, count: np.ndarray, attr: np.ndarray, vid: np.ndarray,
                 src_plane: np.ndarray, src_degenerate: np.ndarray, src_two_sided: np.ndarray):
        S, K = pos.shape[:2]
        self.K = K
        self.A = attr.shape[2]
        cap = max(16, int(S * 2))
        self.pos = np.zeros((cap, K, 3))
        self.attr = np.zeros((cap, K, self.A))
        self.vid = np.full((cap, K), -1, np.int64)
        self.count = np.zeros(cap, np.int64)
        self.src = np.zeros(cap, np.int64)
        self.whole = np.zeros(cap, bool)
        self.n = 0
        self.grid = None  # (center, scale, decimals): cut vertices snapped to the written grid
        self.tape: Tape | None = None  # records where cut corners' attributes came from
        self.src_plane = np.asarray(src_plane, np.float64)
        self.src_degenerate = np.asarray(src_degenerate, bool)
        self.src_two_sided = np.asarray(src_two_sided, bool)
        k = np.arange(K)[None, :] < np.asarray(count)[:, None]
        # a point of each source plane shared by all its fragments (so they share one plane)
        self.src_center = (pos * k[..., None]).sum(1) / np.maximum(np.asarray(count), 1)[:, None]
        self.append(pos, attr, vid, count, np.arange(S), whole=True)

    def child(self, ids: np.ndarray) -> "FaceStore":
        """A new store with the same source faces holding copies of fragments ``ids`` (in order,
        as its fragments 0 .. len(ids) - 1)."""
        c = object.__new__(FaceStore)
        c.K, c.A = self.K, self.A
        cap = max(16, 2 * len(ids))
        c.pos = np.zeros((cap, self.K, 3))
        c.attr = np.zeros((cap, self.K, self.A))
        c.vid = np.full((cap, self.K), -1, np.int64)
        c.count = np.zeros(cap, np.int64)
        c.src = np.zeros(cap, np.int64)
        c.whole = np.zeros(cap, bool)
        c.n = 0
        c.src_plane, c.src_degenerate, c.src_two_sided = self.src_plane, self.src_degenerate, self.src_two_sided
        c.src_center = self.src_center
        c.grid = self.grid
        c.tape = self.tape
        c.append(self.pos[ids], self.attr[ids], self.vid[ids], self.count[ids], self.src[ids])
        c.whole[:len(ids)] = self.whole[ids]
        return c

    # ------------------------------------------------------------------ storage
    def _grow(self, need_n: int, need_k: int) -> None:
        if need_k > self.K:
            extra = need_k - self.K
            self.pos = np.concatenate([self.pos, np.repeat(self.pos[:, :1], extra, 1)], 1)
            self.attr = np.concatenate([self.attr, np.repeat(self.attr[:, :1], extra, 1)], 1)
            self.vid = np.concatenate([self.vid, np.repeat(self.vid[:, :1], extra, 1)], 1)
            self.K = need_k
        cap = len(self.count)
        if need_n > cap:
            extra = max(need_n, int(cap * 1.6)) - cap
            self.pos = np.concatenate([self.pos, np.zeros((extra, self.K, 3))])
            self.attr = np.concatenate([self.attr, np.zeros((extra, self.K, self.A))])
            self.vid = np.concatenate([self.vid, np.full((extra, self.K), -1, np.int64)])
            self.count = np.concatenate([self.count, np.zeros(extra, np.int64)])
            self.src = np.concatenate([self.src, np.zeros(extra, np.int64)])
            self.whole = np.concatenate([self.whole, np.zeros(extra, bool)])

    def append(self, pos, attr, vid, count, src, whole: bool = False) -> np.ndarray:
        m, k = pos.shape[:2]
        if m == 0:
            return np.zeros(0, np.int64)
        self._grow(self.n + m, k)
        if k < self.K:  # pad with corner 0
            pad = self.K - k
            pos = np.concatenate([pos, np.repeat(pos[:, :1], pad, 1)], 1)
            attr = np.concatenate([attr, np.repeat(attr[:, :1], pad, 1)], 1)
            vid = np.concatenate([vid, np.repeat(vid[:, :1], pad, 1)], 1)
        sl = slice(self.n, self.n + m)
        self.pos[sl] = pos
        self.attr[sl] = attr
        self.vid[sl] = vid
        self.count[sl] = count
        self.src[sl] = src
        self.whole[sl] = whole
        idx = np.arange(self.n, self.n + m)
        self.n += m
        return idx

    def snap(self, P: np.ndarray) -> np.ndarray:
        """Normalised points moved to the nearest point of the written grid (no grid: unchanged)."""
        if self.grid is None:
            return P
        center, scale, dec = self.grid
        w = np.round(P * scale + center, dec)
        return (w - center) / scale

    # ------------------------------------------------------------------ queries
    def planes_of(self, idx: np.ndarray) -> np.ndarray:
        return self.src_plane[self.src[idx]]

    def degenerate_of(self, idx: np.ndarray) -> np.ndarray:
        return self.src_degenerate[self.src[idx]]

    def two_sided_of(self, idx: np.ndarray) -> np.ndarray:
        return self.src_two_sided[self.src[idx]]

    def area_of(self, idx: np.ndarray) -> np.ndarray:
        return polygon_area(self.pos[idx])

    def triangles_of(self, idx: np.ndarray) -> np.ndarray:
        return self.count[idx] - 2


def polygon_area(pos: np.ndarray) -> np.ndarray:
    """Area of padded convex polygons ``(m, K, 3)`` (padding repeats corner 0)."""
    if pos.shape[1] < 3 or len(pos) == 0:
        return np.zeros(len(pos))
    e = pos[:, 1:] - pos[:, :1]
    cr = np.cross(e[:, :-1], e[:, 1:]).sum(1)
    return 0.5 * np.linalg.norm(cr, axis=1)


def distances(pos: np.ndarray, planes: np.ndarray, eps: float) -> np.ndarray:
    """``(m, K)`` distances of each fragment's corners to its own plane ``planes[i]``, with
    corners within ``eps`` snapped to 0."""
    d = np.einsum("mkc,mc->mk", pos, planes[:, :3]) - planes[:, 3:4]
    d[np.abs(d) <= eps] = 0.0
    return d


def classify(d: np.ndarray, degenerate: np.ndarray, count: np.ndarray) -> np.ndarray:
    """Side of each fragment from its snapped corner distances: 0 front, 1 back, 2 on,
    3 straddling. Degenerate fragments are never cut: they take the side of their centroid."""
    mn, mx = d.min(1), d.max(1)
    lab = np.full(len(d), 3, np.int8)
    lab[(mn >= 0) & (mx > 0)] = 0
    lab[(mx <= 0) & (mn < 0)] = 1
    lab[(mn == 0) & (mx == 0)] = 2
    ds = degenerate & (lab == 3)
    if ds.any():
        k = np.arange(d.shape[1])[None, :] < count[:, None]
        mean = (d * k).sum(1) / count
        lab[ds] = np.where(mean[ds] >= 0, 0, 1)
    return lab


def split_faces(store: FaceStore, idx: np.ndarray, planes: np.ndarray, owner: np.ndarray, eps: float,
                min_area: float) -> SplitResult:
    """Classify fragments ``idx`` (fragment ``idx[i]`` against ``planes[owner[i]]``) and cut the
    ones that straddle their plane.

    A corner within ``eps`` of the plane counts as on it (snapped), so a cut through a vertex gives
    two pieces and no sliver. A straddling fragment is kept whole (on the side holding more of its
    area) when one piece would be smaller than ``min_area``.
    """
    idx = np.asarray(idx, np.int64)
    owner = np.asarray(owner, np.int64)
    pl = planes[owner]
    d = distances(store.pos[idx], pl, eps)
    lab = classify(d, store.degenerate_of(idx), store.count[idx])

    # a fragment within eps of the plane but tilted from it (a sliver, or a face rounding has
    # tilted) is not one of the plane's coplanar faces: it goes with the side of its middle and is
    # drawn, culled by its own facing, in that child
    on = lab == 2
    if on.any():
        oi = np.flatnonzero(on)
        cosang = np.einsum("ij,ij->i", store.planes_of(idx[oi])[:, :3], pl[oi, :3])
        tilt = oi[np.abs(cosang) < MIN_COS_TILT]
        if len(tilt):
            k = np.arange(store.K)[None, :] < store.count[idx[tilt]][:, None]
            mid = (store.pos[idx[tilt]] * k[..., None]).sum(1) / store.count[idx[tilt]][:, None]
            lab[tilt] = np.where(np.einsum("ij,ij->i", mid, pl[tilt, :3]) - pl[tilt, 3] >= 0, 0, 1)
            on = lab == 2
    fn = store.planes_of(idx[on])[:, :3]
    aligned = np.einsum("ij,ij->i", fn, pl[on, :3]) >= 0
    side = np.where(aligned, 0, 1).astype(np.int8)
    side[store.two_sided_of(idx[on])] = 2

    f_ids, f_own = [idx[lab == 0]], [owner[lab == 0]]
    b_ids, b_own = [idx[lab == 1]], [owner[lab == 1]]
    splits = kept = grid_kept = 0
    s = np.flatnonzero(lab == 3)
    if len(s):
        fi, fo, bi, bo, splits, kept, grid_kept = _cut(store, idx[s], owner[s], d[s], min_area)
        f_ids.append(fi)
        f_own.append(fo)
        b_ids.append(bi)
        b_own.append(bo)
    return SplitResult(np.concatenate(f_ids), np.concatenate(f_own), np.concatenate(b_ids),
                       np.concatenate(b_own), idx[on], owner[on], side, splits, kept, grid_kept)


def _cut(store: FaceStore, idx: np.ndarray, owner: np.ndarray, d: np.ndarray, min_area: float):
    m = len(idx)
    K = store.K
    P, A, Vd = store.pos[idx], store.attr[idx], store.vid[idx]
    cnt = store.count[idx]
    # the new corner is computed from the positive corner towards the negative one, so two
    # fragments sharing the edge make bit-identical vertices (no crack, exact weld)
    valid, cross, ia, ib, t = edge_crossings(d, cnt)
    t = t[..., None]
    Pa, Pb = corners_at(P, ia), corners_at(P, ib)
    Aa, Ab = corners_at(A, ia), corners_at(A, ib)
    Pi = store.snap(Pa + t * (Pb - Pa))  # on the grid the positions are written on
    Ai = Aa + t * (Ab - Aa)
    if store.tape is not None:
        store.tape.record(Aa, Ab, t, cross, Ai)

    candP = np.stack([P, Pi], axis=2).reshape(m, 2 * K, 3)
    candA = np.stack([A, Ai], axis=2).reshape(m, 2 * K, store.A)
    candV = np.stack([Vd, np.full_like(Vd, -1)], axis=2).reshape(m, 2 * K)
    keep_f = np.stack([valid & (d >= 0), cross], axis=2).reshape(m, 2 * K)
    keep_b = np.stack([valid & (d <= 0), cross], axis=2).reshape(m, 2 * K)
    fP, fA, fV, fc = _compact(candP, candA, candV, keep_f)
    bP, bA, bV, bc = _compact(candP, candA, candV, keep_b)
    fa, ba = polygon_area(fP), polygon_area(bP)
    ok = (fa >= min_area) & (ba >= min_area)
    grid_bad = 0
    if store.grid is not None:
        # pieces as written: straight corners dropped, fanned from their best corner; a cut
        # whose piece is still collapsed, flipped or tilted is not made
        nrm = store.planes_of(idx)[:, :3]
        gstep = 10.0 ** -store.grid[2] / store.grid[1]
        good = np.ones(m, bool)
        out = []
        for Q, QA, QV, qc in ((fP, fA, fV, fc), (bP, bA, bV, bc)):
            Q, QA, QV, qc, g = clean_pieces(Q, QA, QV, qc, nrm, gstep)
            out.append((Q, QA, QV, qc))
            good &= g
        (fP, fA, fV, fc), (bP, bA, bV, bc) = out
        grid_bad = int((ok & ~good).sum())
        ok &= good
    whole_front = ~ok & (fa >= ba)
    whole_back = ~ok & (fa < ba)
    src = store.src[idx]
    nf = store.append(fP[ok], fA[ok], fV[ok], fc[ok], src[ok])
    nb = store.append(bP[ok], bA[ok], bV[ok], bc[ok], src[ok])
    front = np.concatenate([idx[whole_front], nf])
    front_o = np.concatenate([owner[whole_front], owner[ok]])
    back = np.concatenate([idx[whole_back], nb])
    back_o = np.concatenate([owner[whole_back], owner[ok]])
    return front, front_o, back, back_o, int(ok.sum()), int((~ok).sum()), grid_bad


def clean_pieces(P, A, V, cnt, nrm, step):
    """Pieces whose corners sit on the written grid: corners that are straight (closer than a
    grid step to the line through their neighbours) or turned the wrong way are dropped, then
    each piece is rotated so that its fan from corner 0 is the best one. Returns the pieces and
    whether each is good: at least 3 corners, and every fan triangle with positive area and a
    normal within 30 degrees of the source plane's ``nrm``."""
    m, K = P.shape[:2]
    k = np.arange(K)[None, :]
    for _ in range(K):
        valid = k < cnt[:, None]
        prv = np.take_along_axis(P, ((k - 1) % np.maximum(cnt, 1)[:, None])[..., None], 1)
        nxt = np.take_along_axis(P, ((k + 1) % np.maximum(cnt, 1)[:, None])[..., None], 1)
        turn = np.einsum("mkc,mc->mk", np.cross(P - prv, nxt - P), nrm)
        base = np.linalg.norm(nxt - prv, axis=2)
        height = turn / np.maximum(base, 1e-300)
        cand = valid & (height < step) & (cnt[:, None] > 3)
        if not cand.any():
            break
        # one corner per piece and round, the straightest (the next one may no longer be straight)
        worst = np.argmin(np.where(cand, height, np.inf), axis=1)
        drop = cand.any(1)[:, None] & (k == worst[:, None])
        keep = valid & ~drop
        order = np.argsort(~keep, axis=1, kind="stable")
        cnt = keep.sum(1)
        order = np.where(k < cnt[:, None], order, order[:, :1])
        P = np.take_along_axis(P, order[..., None], 1)
        A = np.take_along_axis(A, order[..., None], 1)
        V = np.take_along_axis(V, order, 1)
    # the best fan apex: the one whose worst triangle is least tilted
    valid = k < cnt[:, None]
    best_q = np.full(m, -np.inf)
    best_r = np.zeros(m, np.int64)
    for r in range(K):
        q = np.full(m, np.inf)
        apex = P[:, r] if r < K else P[:, 0]
        for i in range(1, K - 1):
            b = np.take_along_axis(P, ((r + i) % np.maximum(cnt, 1))[:, None, None].repeat(3, 2), 1)[:, 0]
            c = np.take_along_axis(P, ((r + i + 1) % np.maximum(cnt, 1))[:, None, None].repeat(3, 2), 1)[:, 0]
            n = np.cross(b - apex, c - apex)
            ln = np.linalg.norm(n, axis=1)
            cos = np.where(ln > 0, np.einsum("mc,mc->m", n, nrm) / np.maximum(ln, 1e-300), -1.0)
            q = np.where(i < cnt - 1, np.minimum(q, cos), q)
        q = np.where(r < cnt, q, -np.inf)
        # a clear margin, so float noise never picks another corner for an equally good fan
        # (a triangle's three fans are one triangle): the same input gives the same corners
        better = q > best_q + 1e-6
        best_q[better] = q[better]
        best_r[better] = r
    rot = (k + best_r[:, None]) % np.maximum(cnt, 1)[:, None]
    rot = np.where(valid, rot, rot[:, :1])
    P = np.take_along_axis(P, rot[..., None], 1)
    A = np.take_along_axis(A, rot[..., None], 1)
    V = np.take_along_axis(V, rot, 1)
    good = (cnt >= 3) & (best_q >= MIN_COS_TILT)
    return P, A, V, cnt, good


def _compact(P, A, V, keep):
    """Move kept slots to the front of each row; pad with the row's first corner."""
    cnt = keep.sum(1)
    order = np.argsort(~keep, axis=1, kind="stable")
    kmax = max(3, int(cnt.max())) if len(cnt) else 3
    order = order[:, :kmax]
    slot = np.arange(kmax)[None, :]
    order = np.where(slot < cnt[:, None], order, order[:, :1])
    return (np.take_along_axis(P, order[..., None], 1), np.take_along_axis(A, order[..., None], 1),
            np.take_along_axis(V, order, 1), cnt)


def triangle_store(tri_pos: np.ndarray, min_area: float, *, attr: np.ndarray | None = None,
                   vid: np.ndarray | None = None, two_sided: np.ndarray | None = None) -> FaceStore:
    """A store whose source faces are single triangles ``(T, 3, 3)`` (normalised coordinates)."""
    T = len(tri_pos)
    plane, degen = face_planes(tri_pos, np.full(T, 3), min_area)
    return FaceStore(tri_pos, np.full(T, 3), np.zeros((T, 3, 0)) if attr is None else attr,
                     np.full((T, 3), -1, np.int64) if vid is None else vid, plane, degen,
                     np.zeros(T, bool) if two_sided is None else two_sided)


def face_planes(pos: np.ndarray, count: np.ndarray, min_area: float) -> tuple[np.ndarray, np.ndarray]:
    """Exact planes (unit normal, offset through the centroid) of padded convex polygons, and
    which are degenerate (area <= min_area; normal 0)."""
    e = pos[:, 1:] - pos[:, :1]
    cr = np.cross(e[:, :-1], e[:, 1:]).sum(1) if pos.shape[1] >= 3 else np.zeros((len(pos), 3))
    ln = np.linalg.norm(cr, axis=1)
    degen = 0.5 * ln <= min_area
    nrm = np.zeros_like(cr)
    ok = ~degen
    nrm[ok] = cr[ok] / ln[ok, None]
    k = np.arange(pos.shape[1])[None, :] < count[:, None]
    cen = (pos * k[..., None]).sum(1) / count[:, None]
    return np.concatenate([nrm, np.einsum("ij,ij->i", nrm, cen)[:, None]], 1), degen
