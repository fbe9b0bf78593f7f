"""Building the BSP tree: priority peeling, candidate planes, scoring, splitting.

Every node of the tree draws, in order: a *prefix* of fragments in a fixed order, then — if it
has a plane — its far child, the fragments lying in the plane that face the eye, its near child,
and last a *suffix* in a fixed order. A node without a plane is a *leaf*.

The fixed orders rest on one fact. Face ``i`` can hide face ``j`` (both facing the eye) if and
only if part of ``j`` lies strictly behind plane ``i`` and part of ``i`` strictly in front of
plane ``j``. (The ray meets ``i`` where it crosses plane ``i``, so anything it meets later is
behind that plane; it meets ``j`` where it crosses plane ``j``, so anything it met before is in
front of it. Conversely, for such points ``p`` on ``i`` and ``q`` on ``j``, an eye on the line
``q -> p`` beyond ``p`` sees ``p`` hide ``q``.) So in a set of fragments, one that hides nothing
else in the set can be drawn before all of it, from every eye; one that nothing else can hide can
be drawn after all of it. Peeling those from both ends, alternately, leaves a *core* lying on or
between cycles of the "may hide" graph — only the core needs a plane. If nothing is left the set
is a leaf: the priority clusters of Schumacker et al. (a convex or a concave piece of surface has
no edge at all). Double-sided faces add the other three facing combinations; degenerate faces
hide nothing. Sets above ``leaf_max`` peel only the faces of their convex hull (cheap).

Candidate planes of a core: face planes (sampled), *edge planes* (through an edge of one fragment
and a corner of another: along existing edges, between the two faces of the edge), and gap/axis
planes. Large nodes score them on a sample of their fragments and rescore the best few exactly.
Optionally (``ensemble`` > 1) each small node is built to the end from several of its best
planes and the cheapest subtree is grafted in. Planes equal after rounding share one offset
(``_Builder.share``), so they share one written entry.

The builder works one *level* at a time: every open node of a depth is tested, scored and split
together with array operations (a Python loop per level and per candidate slot, never per face).
Everything is in normalised coordinates (see ``split.py``).
"""

from __future__ import annotations

import bisect
import dataclasses
import time
from dataclasses import dataclass, field

import numpy as np


from .split import FaceStore, split_faces


@dataclass
class BuildOptions:
    candidates: int = 64  # candidate planes per node (0 = every face of the node)
    split_weight: float = 4.0  # per triangle a cut adds (qbsp-style 8 per cut fragment)
    balance_weight: float = 0.5
    coplanar_weight: float = 0.0
    seed: int = 0
    leaves: str = "priority"  # "none" (classic), "convex", "priority"
    leaf_max: int = 128  # largest set tested for a priority leaf (the test is O(n^2))
    axis_planes: bool = False  # also try the three axis planes through the node's median
    gap_planes: bool = True  # and the most balanced axis-aligned plane that cuts nothing
    epsilon: float = 1e-6  # on-plane tolerance, fraction of the scene diagonal
    min_area: float = 1e-12  # smallest fragment, fraction of diagonal^2
    plane_decimals: int = 6  # plane normals rounded to this many decimals
    max_levels: int = 100000
    split_cost: str = "triangles"  # what a cut costs: triangles added (2, 1 through a corner, 0
    # along a diagonal) or "pieces" (1 per fragment cut, the classic count)
    hull_peel: bool = True  # peel the convex-hull faces of sets larger than leaf_max
    peeled_candidates: bool = True  # planes of peeled fragments are candidates for the core
    edge_planes: int = 256  # planes through an edge of one fragment and a corner of another
    edge_plane_cost: float = 0.3  # ... used only where their cuts add <= this many triangles per fragment
    score_sample: int = 512  # larger nodes pre-score candidates on this many fragments ...
    score_refine: int = 4  # ... and rescore their best few exactly
    ensemble: int = 8  # nodes of at most ensemble_max fragments are built this many times ...
    ensemble_max: int = 64  # ... and the cheapest subtree is kept (ensemble 1: off) ...
    # the thorough search (ensembles, thorough_edge_factor x edge_planes) in scenes of at most
    # thorough_faces source faces (0: never); bigger scenes are built greedily
    thorough_faces: int = 8000
    thorough_edge_factor: int = 1
    fragments: str = "polygons"  # "fans": triangulate every cut piece at once (for comparison)


@dataclass
class Tree:
    """Node n draws, in this order: its *prefix* fragments (fixed order), then — if it has a
    plane — the far child, its coplanar fragments facing the eye, the near child, and last its
    *suffix* fragments (fixed order). A node without a plane is a leaf (prefix only)."""

    store: FaceStore
    plane: np.ndarray  # (N, 4) normalised plane of each split node (NaN row: no plane)
    world_plane: np.ndarray  # (N, 4) the same plane in world units, quantised
    front: np.ndarray  # (N,) child node or -1
    back: np.ndarray
    depth: np.ndarray  # (N,)
    sizes: np.ndarray  # (N,) fragments in each node's set when it was opened
    on_ids: np.ndarray  # coplanar fragments of split nodes ...
    on_node: np.ndarray  # ... their node
    on_side: np.ndarray  # ... 0 seen from the front, 1 from the back, 2 two-sided
    pre_ids: np.ndarray  # prefix fragments, grouped by node, in draw order ...
    pre_node: np.ndarray
    suf_ids: np.ndarray  # suffix fragments, grouped by node, in draw order ...
    suf_node: np.ndarray
    stats: dict = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return len(self.front)

    @property
    def has_plane(self) -> np.ndarray:
        return ~np.isnan(self.plane[:, 0])

    def fragments(self) -> np.ndarray:
        return np.concatenate([self.on_ids, self.pre_ids, self.suf_ids])


# ---------------------------------------------------------------------------- priority leaves
def _segments(owner: np.ndarray, n_nodes: int):
    sizes = np.bincount(owner, minlength=n_nodes)
    starts = np.zeros(n_nodes + 1, np.int64)
    np.cumsum(sizes, out=starts[1:])
    return sizes, starts


def hide_graph(store: FaceStore, table: np.ndarray, eps: float) -> np.ndarray:
    """``(B, m, m)`` bool for ``B`` sets of fragment ids (``table``, -1 = padding):
    ``M[b, i, j]`` = fragment i may hide fragment j (from some eye, facing respected)."""
    B, m = table.shape
    valid = table >= 0
    ids = np.where(valid, table, 0)
    cnt = store.count[ids]
    K = int(cnt.max())
    P = store.pos[ids, :K].astype(np.float32)  # (B, m, K, 3)
    pl = store.planes_of(ids).astype(np.float32)  # (B, m, 4)
    e = np.float32(eps)
    beh = inf = None  # [b, i, j]: part of j behind / in front of plane i
    for k in range(K):
        Dk = np.matmul(pl[..., :3], P[:, :, k].transpose(0, 2, 1)) - pl[..., 3][:, :, None]
        if beh is None:
            beh, inf = Dk < -e, Dk > e
        else:
            beh |= Dk < -e
            inf |= Dk > e
    M = beh & inf.transpose(0, 2, 1)
    ts = store.two_sided_of(ids) & valid
    if ts.any():
        M |= ts[:, :, None] & inf & inf.transpose(0, 2, 1)
        M |= ts[:, None, :] & beh & beh.transpose(0, 2, 1)
        M |= (ts[:, :, None] & ts[:, None, :]) & inf & beh.transpose(0, 2, 1)
    live = valid & ~store.degenerate_of(ids)
    M &= live[:, :, None] & live[:, None, :]
    M &= ~np.eye(m, dtype=bool)[None]
    return M


def peel(M: np.ndarray, valid: np.ndarray):
    """Peel ``(B, m, m)`` "may hide" graphs from both ends, alternating until nothing moves.

    A fragment that hides nothing still in the set can be drawn before all of it (*prefix*); one
    that nothing still in the set can hide can be drawn after all of it (*suffix*). Returns
    (status: 0 core / 1 prefix / 2 suffix / -1 padding, key: prefix drawn by increasing key,
    suffix by decreasing key). What is left (the core) lies on or between cycles."""
    B, m = valid.shape
    Mf = M.astype(np.float32)
    MT = np.ascontiguousarray(Mf.transpose(0, 2, 1))
    rem = valid.copy()
    status = np.where(valid, 0, -1).astype(np.int8)
    key = np.zeros((B, m), np.int64)
    counter = 0
    while True:
        moved = False
        for mat, code in ((Mf, 1), (MT, 2)):
            cnt = np.matmul(mat, rem[..., None].astype(np.float32))[..., 0]
            while True:
                ready = rem & (cnt == 0)
                if not ready.any():
                    break
                status[ready] = code
                key[ready] = counter
                counter += 1
                rem &= ~ready
                cnt -= np.matmul(mat, ready[..., None].astype(np.float32))[..., 0]
                moved = True
        if not moved or not rem.any():
            break
    return status, key


def priority_peel(store: FaceStore, fids: np.ndarray, starts: np.ndarray, nodes: np.ndarray,
                  eps: float, mode: str, budget: int = 3_000_000):
    """Test open nodes ``nodes`` (their fragments are ``fids[starts[a]:starts[a+1]]``).

    Returns per fragment (status 0 core / 1 prefix / 2 suffix, draw key). A node whose fragments
    are all prefix is a leaf. ``mode`` "convex": only sets with no edge at all are leaves, and
    nothing is peeled."""
    L = len(fids)
    key = np.zeros(L, np.int64)
    status = np.zeros(L, np.int8)
    if len(nodes) == 0:
        return status, key
    sizes = starts[nodes + 1] - starts[nodes]
    bucket = np.maximum(4, 2 ** np.ceil(np.log2(np.maximum(sizes, 1))).astype(np.int64))
    K = store.K
    for m in np.unique(bucket):
        sel = np.flatnonzero(bucket == m)
        step = max(1, budget // int(m * m * K))
        for s in range(0, len(sel), step):
            part = sel[s:s + step]
            a = nodes[part]
            rows = np.arange(m)[None, :]
            pos = starts[a][:, None] + rows
            valid = rows < sizes[part][:, None]
            table = np.where(valid, fids[np.minimum(pos, L - 1)], -1)
            M = hide_graph(store, table, eps)
            if mode == "convex":
                free = ~M.any((1, 2))
                st = np.where(valid & free[:, None], 1, 0).astype(np.int8)
                k = np.zeros(table.shape, np.int64)
            else:
                st, k = peel(M, valid)
                if mode == "acyclic":  # leaves only: a set with a cycle is not peeled at all
                    st = np.where((st == 0).any(1, keepdims=True) & valid, 0, st).astype(np.int8)
            status[pos[valid]] = st[valid]
            key[pos[valid]] = k[valid]
    return status, key


def hull_peel(store: FaceStore, ids: np.ndarray, eps: float, hull_above: int = 500, probes: int = 48) -> np.ndarray:
    """Cheap peeling for sets too large for the graph: a single-sided fragment with every corner
    of the set on or behind its plane (a face of the set's convex hull) cannot be hidden by
    anything in the set, so it can be drawn last (status 2); one with every corner on or in
    front of its plane hides nothing, so it can be drawn first (status 1). Degenerate fragments
    hide nothing and cannot be seen (1). Such fragments never hide one another."""
    # the set's distinct corners: padding dropped, scene vertices once
    real = np.arange(store.K)[None, :] < store.count[ids][:, None]
    vid = store.vid[ids][real]
    P = store.pos[ids][real]
    old = vid >= 0
    _, first = np.unique(vid[old], return_index=True)
    P = np.concatenate([P[old][first], P[~old]])
    pl = store.planes_of(ids)
    status = np.zeros(len(ids), np.int8)
    deg = store.degenerate_of(ids)
    status[deg] = 1
    cand = ~deg & ~store.two_sided_of(ids)
    if not cand.any():
        return status
    H = P
    if len(P) > hull_above:  # only the hull's corners matter for a plane's extreme distances
        try:
            from scipy.spatial import ConvexHull  # (imported here: a bake that reuses its tree needs no scipy)

            H = P[ConvexHull(P).vertices]
        except Exception:  # flat or degenerate point set: keep every point
            H = P
    c = np.flatnonzero(cand)
    if len(H) > 3 * probes:
        # a few corners reject most fragments cheaply; survivors are checked against all
        probe = H[np.linspace(0, len(H) - 1, probes).astype(np.int64)]
        d = pl[c, :3] @ probe.T - pl[c, 3:4]
        c = c[(d.max(1) <= eps) | (d.min(1) >= -eps)]
    step = max(1, 4_000_000 // max(1, len(H)))
    for s in range(0, len(c), step):
        j = c[s:s + step]
        d = pl[j, :3] @ H.T - pl[j, 3:4]
        status[j[d.max(1) <= eps]] = 2
        status[j[d.min(1) >= -eps]] = 1
    return status


KIND_FACE, KIND_EDGE, KIND_GAP, KIND_AXIS = 0, 1, 2, 3
#: nodes with at least this many (fragment, candidate) pairs are scored as one block
_BLOCK_PAIRS = 1024

KIND_NAMES = {KIND_FACE: "face_planes", KIND_EDGE: "edge_planes", KIND_GAP: "gap_planes", KIND_AXIS: "axis_planes"}


# ---------------------------------------------------------------------------- the builder
class _Builder:
    def __init__(self, store: FaceStore, opt: BuildOptions, center: np.ndarray, scale: float):
        self.store = store
        self.opt = opt
        self.center = center
        self.scale = scale
        # world offsets keep plane_decimals + 2 significant digits of the scene size
        self.offset_decimals = int(opt.plane_decimals + 2 - np.floor(np.log10(scale)))
        self.n_nodes = 0
        self.planes = np.full((16, 4), np.nan)
        self.world = np.full((16, 4), np.nan)
        self.front = np.full(16, -1, np.int64)
        self.back = np.full(16, -1, np.int64)
        self.depth = np.zeros(16, np.int64)
        self.sizes = np.zeros(16, np.int64)
        self.on = ([], [], [])
        self.pre = ([], [])
        self.suf = ([], [])
        self.stats = {"splits": 0, "kept_whole": 0, "levels": 0, "leaf_seconds": 0.0,
                      "choose_seconds": 0.0, "split_seconds": 0.0, "peeled": 0, "convex_leaves": 0,
                      "gap_planes": 0, "axis_planes": 0, "face_planes": 0, "edge_planes": 0,
                      "exact_planes": 0, "ensembles": 0, "ensemble_seconds": 0.0, "shared_planes": 0}
        self.registry: dict[tuple, list] = {}  # canonical rounded normal -> sorted world offsets used

    def new_nodes(self, k: int, depth: int, sizes: np.ndarray) -> np.ndarray:
        first = self.n_nodes
        if first + k > len(self.front):
            cap = max(first + k, 2 * len(self.front))
            grow = cap - len(self.front)
            self.planes = np.concatenate([self.planes, np.full((grow, 4), np.nan)])
            self.world = np.concatenate([self.world, np.full((grow, 4), np.nan)])
            self.front = np.concatenate([self.front, np.full(grow, -1, np.int64)])
            self.back = np.concatenate([self.back, np.full(grow, -1, np.int64)])
            self.depth = np.concatenate([self.depth, np.zeros(grow, np.int64)])
            self.sizes = np.concatenate([self.sizes, np.zeros(grow, np.int64)])
        self.depth[first:first + k] = depth
        self.sizes[first:first + k] = sizes
        self.n_nodes = first + k
        return np.arange(first, first + k)

    def share(self, planes: np.ndarray, world: np.ndarray, found: np.ndarray):
        """Planes of this level that are one plane with a plane used before (or with each other):
        same rounded normal (either orientation), offsets within half the tolerance. They take
        the first one's offset, so they share one ``bsp planes`` entry and the tree is built with
        exactly the plane that is written. Returns the planes, changed in place."""
        tol = 0.5 * self.opt.epsilon * self.scale
        for a in np.flatnonzero(found):
            n, d = world[a, :3], world[a, 3]
            nz = np.flatnonzero(n)
            if len(nz) == 0:
                continue
            s = 1.0 if n[nz[0]] > 0 else -1.0
            key = tuple((n * s + 0.0).tolist())
            offs = self.registry.setdefault(key, [])
            cd = d * s
            i = bisect.bisect_left(offs, cd)
            near = [o for o in offs[max(0, i - 1):i + 1] if abs(o - cd) <= tol]
            if near:
                best = min(near, key=lambda o: abs(o - cd))
                if best != cd:
                    world[a, 3] = best * s + 0.0
                    planes[a, 3] = (world[a, 3] - n @ self.center) / self.scale
                    self.stats["shared_planes"] += 1
            else:
                offs.insert(i, cd)
        return planes, world

    def quantise(self, n: np.ndarray, point: np.ndarray):
        """Planes with normals rounded to ``plane_decimals`` through ``point`` (normalised), the
        offset rounded to a scene-relative unit in world coordinates. Returns normalised (k, 4)
        and world (k, 4) planes; the two describe the same plane up to float rounding."""
        nq = np.round(n, self.opt.plane_decimals) + 0.0
        d = np.einsum("ij,ij->i", nq, point)
        dw = d * self.scale + nq @ self.center
        dw = np.round(dw, self.offset_decimals) + 0.0
        dn = (dw - nq @ self.center) / self.scale
        return np.concatenate([nq, dn[:, None]], 1), np.concatenate([nq, dw[:, None]], 1)

    # ------------------------------------------------------------------ candidates
    def candidates(self, fids, owner, starts, rng, P, cnt, pool, pool_owner):
        """Candidate planes of every open node as one flat list: (node, normalised plane, world
        plane, kind). Kinds: face planes of sampled fragments (and of fragments peeled off the
        node), edge planes (through an edge of one fragment and a corner of another), gap and
        axis planes."""
        st, opt = self.store, self.opt
        A = len(starts) - 1
        sizes = starts[1:] - starts[:-1]
        out = []

        def add(nd, n, point, kind, ok=None):
            if ok is not None:
                nd, n, point = nd[ok], n[ok], point[ok]
            if len(nd):
                pl, wo = self.quantise(n, point)
                out.append((nd, pl, wo, np.full(len(nd), kind, np.int8)))

        # face planes: up to `candidates` fragments per node, sampled without replacement
        pool_sizes = np.bincount(pool_owner, minlength=A)
        pool_starts = np.concatenate([[0], np.cumsum(pool_sizes)])
        C = int(pool_sizes.max()) if opt.candidates <= 0 else opt.candidates
        keys = rng.random(len(pool)) + st.degenerate_of(pool) * 2.0
        order = np.lexsort((keys, pool_owner))
        rank = np.arange(len(pool)) - pool_starts[pool_owner[order]]
        take = order[(rank < C) & (keys[order] < 2.0)]
        add(pool_owner[take], st.planes_of(pool[take])[:, :3], st.src_center[st.src[pool[take]]], KIND_FACE)
        # edge planes: an edge of a random fragment and a corner of another (a node of m
        # fragments gets at most 2m): planes along existing edges that pass between faces
        if opt.edge_planes > 0:
            ne = np.where(sizes >= 2, np.minimum(opt.edge_planes, 2 * sizes), 0)
            nd = np.repeat(np.arange(A), ne)
            j = starts[nd] + np.minimum((rng.random(len(nd)) * sizes[nd]).astype(np.int64), sizes[nd] - 1)
            k = np.minimum((rng.random(len(nd)) * cnt[j]).astype(np.int64), cnt[j] - 1)
            j2 = starts[nd] + np.minimum((rng.random(len(nd)) * sizes[nd]).astype(np.int64), sizes[nd] - 1)
            k2 = np.minimum((rng.random(len(nd)) * cnt[j2]).astype(np.int64), cnt[j2] - 1)
            a, b, c = P[j, k], P[j, (k + 1) % cnt[j]], P[j2, k2]
            n = np.cross(b - a, c - a)
            ln = np.linalg.norm(n, axis=1)
            ok = ln > 1e-9 * np.linalg.norm(b - a, axis=1) * np.linalg.norm(c - a, axis=1)
            add(nd, n / np.maximum(ln, 1e-300)[:, None], a, KIND_EDGE, ok)
        if opt.gap_planes or opt.axis_planes:
            lo, hi = P.min(1), P.max(1)
            cen = (P * (np.arange(P.shape[1])[None, :] < cnt[:, None])[..., None]).sum(1) / cnt[:, None]
            for ax in range(3):
                n = np.zeros((A, 3))
                n[:, ax] = 1.0
                if opt.gap_planes:
                    pt, valid = self.gap(lo[:, ax], hi[:, ax], owner, starts)
                    p3 = np.zeros((A, 3))
                    p3[:, ax] = pt
                    add(np.arange(A), n, p3, KIND_GAP, valid)
                if opt.axis_planes:
                    c = cen[:, ax]
                    o2 = np.lexsort((c, owner))
                    p3 = np.zeros((A, 3))
                    p3[:, ax] = c[o2[starts[:-1] + sizes // 2]]
                    add(np.arange(A), n, p3, KIND_AXIS, sizes > 1)
        if not out:
            z = np.zeros(0, np.int64)
            return z, np.zeros((0, 4)), np.zeros((0, 4)), z.astype(np.int8)
        nd, pl, wo, kd = (np.concatenate(x) for x in zip(*out))
        o = np.argsort(nd, kind="stable")
        return nd[o], pl[o], wo[o], kd[o]

    def score(self, Pc, deg, cnt, c_node, c_plane, c_kind, fpos, foff, fcount, sizes):
        """Scores of candidate planes: candidate i against the fragments ``fpos[foff[a] :
        foff[a] + fcount[a]]`` of its node ``a`` (all of them, or a sample whose counts are
        scaled up to the node's size). ``Pc`` (3, K, L) float32 corners of the level's
        fragments. ``c_node`` is sorted. Returns (score, cost); inf where the plane makes no
        progress.

        Nodes with at least ``_BLOCK_PAIRS`` (fragment, candidate) pairs are counted as a
        fragments x candidates block (``_count_block``: the corners gathered once, the
        planes broadcast); the rest as one flat list of pairs (``_count_flat``). Both do the
        same float32 operations in the same order, so the counts do not depend on the path."""
        opt = self.opt
        n_c = len(c_node)
        sc = np.full(n_c, np.inf)
        cost_out = np.zeros(n_c)
        if n_c == 0:
            return sc, cost_out
        comp = np.ascontiguousarray(c_plane.T, dtype=np.float32)  # (4, n_c)
        lc = fcount[c_node].astype(np.int64)
        counts = np.zeros((4, n_c))  # n_b, n_f, n_sp, cost (sampled)
        bounds = np.flatnonzero(np.diff(c_node)) + 1
        first = np.concatenate([[0], bounds])
        last = np.concatenate([bounds, [n_c]])
        block = (last - first) * lc[first] >= _BLOCK_PAIRS
        for j0, j1 in zip(first[block], last[block]):
            a = int(c_node[j0])
            f = fpos[foff[a]:foff[a] + fcount[a]]
            counts[:, j0:j1] = self._count_block(Pc, deg, cnt, f, comp[:, j0:j1])
        flat = np.flatnonzero(np.repeat(~block, last - first))
        if len(flat):
            counts[:, flat] = self._count_flat(Pc, deg, cnt, c_node[flat], comp[:, flat], fpos, foff, lc[flat])
        n_b, n_f, n_sp, cost = counts
        m = sizes[c_node].astype(np.float64)
        f_ = m / lc  # sampled counts stand for the whole node
        fr, bk = (n_f - n_sp) * f_, (n_b - n_sp) * f_
        on_n = (lc - n_b - n_f + n_sp) * f_
        cost = cost * f_
        s_ = opt.split_weight * cost + opt.balance_weight * np.abs(fr - bk) - opt.coplanar_weight * on_n
        progress = (on_n > 0) | ((fr > 0) & (bk > 0))
        progress &= (c_kind != KIND_EDGE) | (cost <= opt.edge_plane_cost * m)
        sc[:] = np.where(progress, s_, np.inf)
        cost_out[:] = cost
        return sc, cost_out

    def _classify(self, mn, mx, on_c, dg, axis=None):
        """(behind, in front, straddling, added triangles) counts from the per-pair extremes of
        the corners' signed distances; reduced over ``axis`` (block) or returned per pair."""
        eps = np.float32(self.opt.epsilon)
        has_b, has_f = mn < -eps, mx > eps
        if dg.any():  # degenerate fragments are never cut: they go with their middle
            fix = has_b & has_f & dg
            ahead = (mn + mx) >= 0
            has_b &= ~(fix & ahead)
            has_f &= ~(fix & ~ahead)
        span = has_b & has_f
        if self.opt.split_cost == "triangles":
            cost = np.where(span, np.maximum(0, 2 - on_c), 0)
        else:
            cost = span
        if axis is None:
            return has_b, has_f, span, cost
        return [x.sum(axis=axis, dtype=np.int64) for x in (has_b, has_f, span, cost)]

    def _extremes(self, Pc, f, fc, planes, shape, per_pair):
        """Per (fragment, candidate) pair of ``shape``: the least and largest signed distance of
        the fragment's corners to the plane, and how many corners lie on it (within epsilon).
        ``planes`` (a, b, c, w): one per pair (``per_pair``, flat lists: ``shape`` (n,)) or one
        per column (a block of fragments ``f`` x candidates). Corners 0-2 of every fragment,
        further corners only where a fragment has them (the padding repeats corner 0 and would
        change nothing). Both layouts do the same float32 operations in the same order."""
        eps = np.float32(self.opt.epsilon)
        a, b, c, w = planes
        col = (lambda q: q) if per_pair else (lambda q: q[..., None])  # corners down the rows
        d, tmp = np.empty(shape, np.float32), np.empty(shape, np.float32)
        mn, mx = np.empty(shape, np.float32), np.empty(shape, np.float32)
        on_c = np.zeros(shape, np.int8)
        onb = np.empty(shape, bool)
        for k in range(Pc.shape[1]):
            if k < 3:  # in place: d = a*x + b*y + c*z - w
                q = col(Pc[:, k, f])  # one gather of the corner's coordinates
                np.multiply(a, q[0], out=d)
                np.multiply(b, q[1], out=tmp)
                d += tmp
                np.multiply(c, q[2], out=tmp)
                d += tmp
                d -= w
                np.abs(d, out=tmp)
                np.less_equal(tmp, eps, out=onb)
                if k == 0:
                    mn[:] = d
                    mx[:] = d
                else:
                    np.minimum(mn, d, out=mn)
                    np.maximum(mx, d, out=mx)
                on_c += onb
            else:
                sel = np.flatnonzero(fc > k)
                if len(sel) == 0:
                    break
                q = col(Pc[:, k, f[sel]])
                sa, sb, sc, sw = (x[sel] for x in planes) if per_pair else planes
                ds = sa * q[0] + sb * q[1] + sc * q[2] - sw
                mn[sel] = np.minimum(mn[sel], ds)
                mx[sel] = np.maximum(mx[sel], ds)
                on_c[sel] += np.abs(ds) <= eps
        return mn, mx, on_c

    def _count_block(self, Pc, deg, cnt, f, pl):
        """Counts of the candidates ``pl`` (4, C) of one node against its fragments ``f``."""
        a, b, c, w = (pl[i][None, :] for i in range(4))
        mn, mx, on_c = self._extremes(Pc, f, cnt[f], (a, b, c, w), (len(f), pl.shape[1]), per_pair=False)
        return np.array(self._classify(mn, mx, on_c, deg[f][:, None], axis=0), np.float64)

    def _count_flat(self, Pc, deg, cnt, c_node, comp, fpos, foff, ln):
        """Counts of candidates (planes ``comp`` (4, n), nodes ``c_node``) against their nodes'
        fragments, as flat lists of (fragment, candidate) pairs in chunks of about 1.5M pairs."""
        n_c = len(c_node)
        out = np.zeros((4, n_c))
        cum = np.cumsum(ln)
        budget = 1_500_000
        i0 = 0
        while i0 < n_c:
            i1 = max(i0 + 1, int(np.searchsorted(cum, cum[i0] - ln[i0] + budget, "right")))
            cn, lc = c_node[i0:i1], ln[i0:i1]
            seg = np.cumsum(lc) - lc
            rep = np.repeat(np.arange(i1 - i0), lc)
            within = np.arange(int(lc.sum())) - seg[rep]
            f = fpos[foff[cn][rep] + within]
            a, b, c, w = (comp[i, i0:i1][rep] for i in range(4))
            mn, mx, on_c = self._extremes(Pc, f, cnt[f], (a, b, c, w), (len(f),), per_pair=True)
            for r, x in enumerate(self._classify(mn, mx, on_c, deg[f])):
                out[r, i0:i1] = np.add.reduceat(x, seg, dtype=np.int64)
            i0 = i1
        return out

    def choose(self, fids, owner, starts, rng, extra=None, extra_owner=None):
        """One plane per open node: the best-scored of its candidates. Nodes larger than
        ``score_sample`` score every candidate on a sample of their fragments first and rescore
        the ``score_refine`` best on all of them."""
        st, opt = self.store, self.opt
        A = len(starts) - 1
        L = len(fids)
        cnt = st.count[fids]
        Kl = int(cnt.max())
        P = st.pos[fids, :Kl]
        Pc = np.ascontiguousarray(P.transpose(2, 1, 0), dtype=np.float32)  # (3, K, L)
        deg = st.degenerate_of(fids)
        sizes = starts[1:] - starts[:-1]
        pool, pool_owner = fids, owner
        if extra is not None and len(extra):
            pool = np.concatenate([fids, extra])
            pool_owner = np.concatenate([owner, extra_owner])
        c_node, c_plane, c_world, c_kind = self.candidates(fids, owner, starts, rng, P, cnt, pool, pool_owner)
        S = opt.score_sample
        big = (sizes > S) if S > 0 else np.zeros(A, bool)
        if big.any():
            keys = rng.random(L)
            o = np.lexsort((keys, owner))
            rank = np.arange(L) - starts[owner[o]]
            samp = o[rank < np.where(big, S, sizes)[owner[o]]]
            fcount = np.minimum(sizes, np.where(big, S, sizes))
            foff = np.concatenate([[0], np.cumsum(fcount)[:-1]])
            sc, _ = self.score(Pc, deg, cnt, c_node, c_plane, c_kind, samp, foff, fcount, sizes)
            # rescore the best few of each sampled node exactly
            o = np.lexsort((sc, c_node))
            first = np.concatenate([[0], np.cumsum(np.bincount(c_node, minlength=A))[:-1]])
            rank = np.arange(len(o)) - first[c_node[o]]
            again = o[(rank < opt.score_refine) & big[c_node[o]] & np.isfinite(sc[o])]
            again.sort()
            sc[big[c_node]] = np.inf
            if len(again):
                sc[again], _ = self.score(Pc, deg, cnt, c_node[again], c_plane[again], c_kind[again],
                                          np.arange(L), starts[:-1], sizes, sizes)
        else:
            sc, _ = self.score(Pc, deg, cnt, c_node, c_plane, c_kind, np.arange(L), starts[:-1], sizes, sizes)
        o = np.lexsort((sc, c_node))
        first = np.concatenate([[0], np.cumsum(np.bincount(c_node, minlength=A))[:-1]])
        has = np.bincount(c_node, minlength=A) > 0
        pick = o[first[has]]
        self.last_cands = (c_node, c_plane, c_world, sc)
        best_plane = np.zeros((A, 4))
        best_world = np.zeros((A, 4))
        found = np.zeros(A, bool)
        nodes = c_node[pick]
        best_plane[nodes] = c_plane[pick]
        best_world[nodes] = c_world[pick]
        found[nodes] = np.isfinite(sc[pick])
        for kind, name in KIND_NAMES.items():
            self.stats[name] += int(((c_kind[pick] == kind) & found[nodes]).sum())
        return best_plane, best_world, found

    def gap(self, lo, hi, owner, starts):
        """Per node, the most balanced position along an axis that no fragment straddles."""
        eps = self.opt.epsilon
        A = len(starts) - 1
        o = np.lexsort((lo, owner))
        lo_s, hi_s, own = lo[o], hi[o], owner[o]
        run = np.maximum.accumulate(hi_s + 8.0 * own) - 8.0 * own  # segmented running max
        rank = np.arange(len(o)) - starts[own]
        size = (starts[1:] - starts[:-1])[own]
        nxt_lo = np.concatenate([lo_s[1:], [np.inf]])
        same = np.concatenate([own[1:] == own[:-1], [False]])
        ok = same & (run < nxt_lo - 2 * eps)
        bal = np.where(ok, np.abs(2 * (rank + 1) - size), np.iinfo(np.int64).max)
        # best per node: lexsort by (bal, node)
        o2 = np.lexsort((bal, own))
        first = o2[starts[:-1][starts[1:] > starts[:-1]]]
        pos = np.zeros(A)
        valid = np.zeros(A, bool)
        nodes = own[first]
        good = ok[first]
        pos[nodes[good]] = 0.5 * (run[first[good]] + nxt_lo[first[good]])
        valid[nodes[good]] = True
        return pos, valid

    # ------------------------------------------------------------------ main loop
    def run(self, owner0: np.ndarray | None = None, first: tuple | None = None) -> None:
        """Build level by level. ``owner0``: start from several roots (root of each fragment);
        ``first``: (planes, world) forced on the roots at the first level (no peeling there)."""
        st, opt = self.store, self.opt
        eps = opt.epsilon
        fids = np.arange(st.n)
        if owner0 is None:
            owner = np.zeros(st.n, np.int64)
            node_of = self.new_nodes(1, 0, np.array([st.n]))
        else:
            owner = np.asarray(owner0, np.int64)
            node_of = self.new_nodes(int(owner.max()) + 1, 0, np.bincount(owner))
        level = 0
        while len(fids) and level < opt.max_levels:
            A = len(node_of)
            self.stats["levels"] = level + 1
            rng = np.random.default_rng([opt.seed, level])
            o = np.argsort(owner, kind="stable")
            fids, owner = fids[o], owner[o]
            sizes, starts = _segments(owner, A)
            # ---- priority peeling / leaves
            status = np.zeros(len(fids), np.int8)
            key = np.zeros(len(fids), np.int64)
            if opt.leaves != "none" and not (level == 0 and first is not None):
                t = time.perf_counter()
                small = np.flatnonzero(sizes <= opt.leaf_max)
                status, key = priority_peel(st, fids, starts, small, eps, opt.leaves)
                big = (sizes > opt.leaf_max) & opt.hull_peel
                for a in np.flatnonzero(big):
                    sl = slice(starts[a], starts[a + 1])
                    status[sl] = hull_peel(st, fids[sl], eps)
                    if (status[sl] != 0).all():
                        self.stats["convex_leaves"] += 1
                self.stats["leaf_seconds"] += time.perf_counter() - t
            for code, store_to, desc in ((1, self.pre, False), (2, self.suf, True)):
                m = status == code
                if m.any():
                    ids, own, k = fids[m], owner[m], key[m]
                    oo = np.lexsort((-k if desc else k, own))
                    store_to[0].append(ids[oo])
                    store_to[1].append(node_of[own[oo]])
                    self.stats["peeled"] += int(m.sum())
            core = status == 0
            peeled_ids, peeled_owner = fids[~core], owner[~core]
            fids, owner = fids[core], owner[core]
            if len(fids) == 0:
                break
            active = np.bincount(owner, minlength=A) > 0
            remap = np.cumsum(active) - 1
            owner = remap[owner]
            keep = active[peeled_owner]
            peeled = (peeled_ids[keep], remap[peeled_owner[keep]]) if opt.peeled_candidates else (None, None)
            node_of = node_of[active]
            A = len(node_of)
            sizes, starts = _segments(owner, A)
            # ---- plane choice
            t = time.perf_counter()
            if level == 0 and first is not None:
                planes, world = first[0][node_of].copy(), first[1][node_of].copy()
                found = np.ones(A, bool)
            else:
                planes, world, found = self.choose(fids, owner, starts, rng, *peeled)
            self.stats["choose_seconds"] += time.perf_counter() - t
            if opt.ensemble > 1 and opt.ensemble_max > 0 and not (level == 0 and first is not None):
                t = time.perf_counter()
                done = self.ensemble(fids, owner, starts, node_of, sizes, level)
                self.stats["ensemble_seconds"] += time.perf_counter() - t
                if done.any():
                    keepf = ~done[owner]
                    fids = fids[keepf]
                    remap = np.cumsum(~done) - 1
                    owner = remap[owner[keepf]]
                    node_of, planes, world, found = node_of[~done], planes[~done], world[~done], found[~done]
                    A = len(node_of)
                    if len(fids) == 0:
                        break
            if not found.all():
                # no candidate made progress (rounded normals can miss a huge face by more than
                # epsilon): use the exact plane of the node's first non-degenerate fragment,
                # which always holds that fragment
                deg = st.degenerate_of(fids)
                for a in np.flatnonzero(~found):
                    live = np.flatnonzero((owner == a) & ~deg)
                    if len(live):
                        pl = st.planes_of(fids[live[:1]])[0]
                        planes[a] = pl
                        world[a] = np.concatenate([pl[:3], [pl[3] * self.scale + pl[:3] @ self.center]])
                        found[a] = True
                        self.stats["exact_planes"] += 1
            if not found.all():
                # only degenerate fragments left (no plane at all): they hide nothing, draw them first
                lf = ~found[owner]
                self.pre[0].append(fids[lf])
                self.pre[1].append(node_of[owner[lf]])
                fids, owner = fids[~lf], owner[~lf]
                remap = np.cumsum(found) - 1
                owner = remap[owner]
                node_of, planes, world = node_of[found], planes[found], world[found]
                if len(fids) == 0:
                    break
            planes, world = self.share(planes, world, np.ones(len(planes), bool))
            # ---- split
            t = time.perf_counter()
            n_before = st.n
            res = split_faces(st, fids, planes, owner, eps, opt.min_area)
            if opt.fragments == "fans":
                res = _fan_new_pieces(st, res, n_before)
            self.stats["splits"] += res.splits
            self.stats["kept_whole"] += res.kept_whole
            self.stats["grid_kept"] = self.stats.get("grid_kept", 0) + res.grid_kept
            gl = node_of
            self.planes[gl] = planes
            self.world[gl] = world
            self.on[0].append(res.on)
            self.on[1].append(gl[res.on_owner])
            self.on[2].append(res.on_side)
            # ---- children
            nS = len(gl)
            fc = np.bincount(res.front_owner, minlength=nS)
            bc = np.bincount(res.back_owner, minlength=nS)
            hasf, hasb = fc > 0, bc > 0
            nf = int(hasf.sum())
            fnodes = self.new_nodes(nf, level + 1, fc[hasf])
            bnodes = self.new_nodes(int(hasb.sum()), level + 1, bc[hasb])
            floc = np.full(nS, -1, np.int64)
            bloc = np.full(nS, -1, np.int64)
            floc[hasf] = np.arange(nf)
            bloc[hasb] = np.arange(int(hasb.sum())) + nf
            self.front[gl[hasf]] = fnodes
            self.back[gl[hasb]] = bnodes
            fids = np.concatenate([res.front, res.back])
            owner = np.concatenate([floc[res.front_owner], bloc[res.back_owner]])
            node_of = np.concatenate([fnodes, bnodes])
            self.stats["split_seconds"] += time.perf_counter() - t
            level += 1

    def ensemble(self, fids, owner, starts, node_of, sizes, level) -> np.ndarray:
        """Nodes small enough (at most ``ensemble_max`` fragments) are finished here: each is
        built ``ensemble`` times to the end, starting from its best-scored candidate planes,
        and the subtree that adds the fewest triangles is kept. Returns which nodes were done."""
        st, opt = self.store, self.opt
        A = len(node_of)
        c_node, c_plane, c_world, sc = self.last_cands
        sel = (sizes <= opt.ensemble_max) & (sizes >= 2)
        done = np.zeros(A, bool)
        if not sel.any():
            return done
        o = np.lexsort((sc, c_node))
        first = np.concatenate([[0], np.cumsum(np.bincount(c_node, minlength=A))[:-1]])
        rank = np.arange(len(o)) - first[c_node[o]]
        take = o[(rank < opt.ensemble) & sel[c_node[o]] & np.isfinite(sc[o])]
        take = take[np.lexsort((sc[take], c_node[take]))]
        if len(take) == 0:
            return done
        nodes = c_node[take]  # one copy per (node, candidate)
        m = sizes[nodes]
        copy = np.repeat(np.arange(len(take)), m)
        within = np.arange(int(m.sum())) - np.repeat(np.cumsum(m) - m, m)
        dup = fids[starts[nodes][copy] + within]
        sub = st.child(dup)
        so = dataclasses.replace(opt, ensemble=1)
        b = _Builder(sub, so, self.center, self.scale)
        b.registry = {k: list(v) for k, v in self.registry.items()}
        b.run(copy, (c_plane[take], c_world[take]))
        tr = b.tree()
        fr = tr.fragments()
        root = b.root_of()
        tri = np.bincount(root[np.concatenate([tr.on_node, tr.pre_node, tr.suf_node])],
                          weights=sub.count[fr] - 2, minlength=len(take))
        tri -= np.bincount(copy, weights=sub.count[:len(dup)] - 2, minlength=len(take))
        # the cheapest copy of each node (ties: the better-scored first plane)
        oo = np.lexsort((np.arange(len(take)), tri, nodes))
        firsts = np.ones(len(oo), bool)
        firsts[1:] = nodes[oo][1:] != nodes[oo][:-1]
        best = oo[firsts]
        self.graft(b, tr, root, best, node_of[nodes[best]], dup)
        done[nodes[best]] = True
        self.stats["ensembles"] += len(best)
        return done

    def root_of(self) -> np.ndarray:
        """The root (first-level node) each node descends from."""
        n = self.n_nodes
        root = np.arange(n)
        parent = np.full(n, -1, np.int64)
        for ch in (self.front[:n], self.back[:n]):
            has = ch >= 0
            parent[ch[has]] = np.flatnonzero(has)
        depth = self.depth[:n]
        for dd in range(1, int(depth.max()) + 1 if n else 1):
            at = np.flatnonzero(depth == dd)
            root[at] = root[parent[at]]
        return root

    def graft(self, b: "_Builder", tr: Tree, root: np.ndarray, roots: np.ndarray, targets: np.ndarray,
              dup: np.ndarray) -> None:
        """Copy the subtrees of ``b`` under ``roots`` into this tree, root ``roots[i]`` becoming
        node ``targets[i]``; fragments the sub-build made are appended to this store."""
        st = self.store
        n = b.n_nodes
        keep = np.zeros(n, bool)
        keep[np.isin(root, roots)] = True
        nmap = np.full(n, -1, np.int64)
        nmap[roots] = targets
        inner = np.flatnonzero(keep & (nmap < 0))
        base_depth = np.zeros(n, np.int64)
        base_depth[roots] = self.depth[targets]
        if len(inner):
            nmap[inner] = self.new_nodes(len(inner), 0, b.sizes[inner])
            self.depth[nmap[inner]] = base_depth[root[inner]] + b.depth[inner]
        kn = np.flatnonzero(keep)
        tgt = nmap[kn]
        self.planes[tgt] = b.planes[kn]
        self.world[tgt] = b.world[kn]
        for w in b.world[kn][~np.isnan(b.world[kn, 0])]:  # their planes are used now
            nz = np.flatnonzero(w[:3])
            if len(nz):
                sg = 1.0 if w[nz[0]] > 0 else -1.0
                offs = self.registry.setdefault(tuple((w[:3] * sg + 0.0).tolist()), [])
                i = bisect.bisect_left(offs, w[3] * sg)
                if i >= len(offs) or offs[i] != w[3] * sg:
                    offs.insert(i, w[3] * sg)
        for mine, theirs in ((self.front, b.front), (self.back, b.back)):
            ch = theirs[kn]
            mine[tgt] = np.where(ch >= 0, nmap[np.maximum(ch, 0)], -1)
        # fragments: copies map back to the originals, new pieces are appended
        sub = b.store
        n0 = len(dup)
        used = []
        for ids, nodes in ((tr.on_ids, tr.on_node), (tr.pre_ids, tr.pre_node), (tr.suf_ids, tr.suf_node)):
            used.append(ids[keep[nodes]])
        used = np.concatenate(used)
        new = np.unique(used[used >= n0])
        fmap = np.full(sub.n, -1, np.int64)
        fmap[:n0] = dup
        if len(new):
            fmap[new] = st.append(sub.pos[new], sub.attr[new], sub.vid[new], sub.count[new], sub.src[new])
            st.whole[fmap[new]] = sub.whole[new]
        k = keep[tr.on_node]
        self.on[0].append(fmap[tr.on_ids[k]])
        self.on[1].append(nmap[tr.on_node[k]])
        self.on[2].append(tr.on_side[k])
        for lists, ids, nodes in ((self.pre, tr.pre_ids, tr.pre_node), (self.suf, tr.suf_ids, tr.suf_node)):
            k = keep[nodes]
            lists[0].append(fmap[ids[k]])
            lists[1].append(nmap[nodes[k]])
        self.stats["splits"] += len(new)

    def tree(self) -> Tree:
        def cat(xs, dt):
            return np.concatenate(xs).astype(dt) if xs else np.zeros(0, dt)

        n = self.n_nodes
        return Tree(store=self.store, plane=self.planes[:n].copy(), world_plane=self.world[:n].copy(),
                    front=self.front[:n].copy(), back=self.back[:n].copy(), depth=self.depth[:n].copy(),
                    sizes=self.sizes[:n].copy(), on_ids=cat(self.on[0], np.int64),
                    on_node=cat(self.on[1], np.int64), on_side=cat(self.on[2], np.int8),
                    pre_ids=cat(self.pre[0], np.int64), pre_node=cat(self.pre[1], np.int64),
                    suf_ids=cat(self.suf[0], np.int64), suf_node=cat(self.suf[1], np.int64),
                    stats=dict(self.stats))


def _fan_new_pieces(st: FaceStore, res, n_before: int):
    """Replace every piece a cut made by the triangles of its fan (the classic way)."""
    out = []
    for ids, own in ((res.front, res.front_owner), (res.back, res.back_owner)):
        new = (ids >= n_before) & (st.count[ids] > 3)
        keep_ids, keep_own = [ids[~new]], [own[~new]]
        f, o = ids[new], own[new]
        if len(f):
            k = st.count[f] - 2
            rep = np.repeat(np.arange(len(f)), k)
            i = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k) + 1
            fr = f[rep]
            corners = np.stack([np.zeros_like(i), i, i + 1], 1)
            nid = st.append(st.pos[fr[:, None], corners], st.attr[fr[:, None], corners],
                            st.vid[fr[:, None], corners], np.full(len(fr), 3), st.src[fr])
            keep_ids.append(nid)
            keep_own.append(o[rep])
        out.append((np.concatenate(keep_ids), np.concatenate(keep_own)))
    res.front, res.front_owner = out[0]
    res.back, res.back_owner = out[1]
    return res


def build_tree(store: FaceStore, opt: BuildOptions, center: np.ndarray | None = None,
               scale: float = 1.0) -> Tree:
    """Build a tree over every fragment of ``store`` (normalised coordinates). ``center`` and
    ``scale`` map normalised to world coordinates (used to quantise plane offsets)."""
    t0 = time.perf_counter()
    if store.n <= opt.thorough_faces:  # small: search harder
        opt = dataclasses.replace(opt, edge_planes=opt.edge_planes * opt.thorough_edge_factor)
    else:  # big: greedy everywhere
        opt = dataclasses.replace(opt, ensemble=1)
    b = _Builder(store, opt, np.zeros(3) if center is None else np.asarray(center, np.float64), float(scale))
    b.run()
    tree = b.tree()
    tree.stats["seconds"] = time.perf_counter() - t0
    tree.stats["thorough"] = bool(store.n <= opt.thorough_faces)
    return tree
