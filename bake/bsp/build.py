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

The builder works one *level* at a time: every open node of a depth is tested, scored and split
together with array operations (a Python loop per level and per candidate slot, never per face).
Everything is in normalised coordinates (see ``split.py``).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from scipy.spatial import ConvexHull

from .split import FaceStore, classify, distances, split_faces


@dataclass
class BuildOptions:
    candidates: int = 64  # candidate planes per node (0 = every face of the node)
    split_weight: float = 4.0  # per triangle a cut adds (qbsp-style 8 per cut fragment)
    balance_weight: float = 1.0
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
    lookahead: int = 0
    root_plane: object = None
    capture: object = None
    sweep: bool = False
    sweep_dirs: int = 0
    free_planes: int = 0
    free_min: int = 0
    core_weight: float = 1.0
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
    P = store.pos[ids, :K]  # (B, m, K, 3)
    pl = store.planes_of(ids)  # (B, m, 4)
    live = valid & ~store.degenerate_of(ids)
    return hide_raw(P, pl, store.two_sided_of(ids) & valid, live, eps)


def hide_raw(P, pl, ts, live, eps):
    """:func:`hide_graph` on raw padded polygons ``P (B, m, K, 3)`` with planes ``pl (B, m, 4)``,
    two-sided flags and which slots are live (valid and not degenerate)."""
    B, m, K = P.shape[:3]
    P = P.astype(np.float32)
    pl = pl.astype(np.float32)
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
    if ts.any():
        M |= ts[:, :, None] & inf & inf.transpose(0, 2, 1)
        M |= ts[:, None, :] & beh & beh.transpose(0, 2, 1)
        M |= (ts[:, :, None] & ts[:, None, :]) & inf & beh.transpose(0, 2, 1)
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


def clip_pieces(P, cnt, d):
    """Front and back pieces of padded convex polygons cut by their snapped distances ``d``
    (no store, no attributes): ((front P, count), (back P, count))."""
    m, K = P.shape[:2]
    k = np.arange(K)[None, :]
    valid = k < cnt[:, None]
    nxt = (k + 1) % cnt[:, None]
    d1 = np.take_along_axis(d, nxt, axis=1)
    cross = valid & (d * d1 < 0)
    pos_first = d > 0
    ia = np.where(pos_first, k, nxt)
    ib = np.where(pos_first, nxt, k)
    da = np.take_along_axis(d, ia, axis=1)
    db = np.take_along_axis(d, ib, axis=1)
    with np.errstate(invalid="ignore", divide="ignore"):
        t = np.where(cross, da / (da - db), 0.0)[..., None]
    Pa, Pb = np.take_along_axis(P, ia[..., None], 1), np.take_along_axis(P, ib[..., None], 1)
    cand = np.stack([P, Pa + t * (Pb - Pa)], axis=2).reshape(m, 2 * K, 3)
    out = []
    for keep in (np.stack([valid & (d >= 0), cross], 2).reshape(m, 2 * K),
                 np.stack([valid & (d <= 0), cross], 2).reshape(m, 2 * K)):
        c = keep.sum(1)
        kmax = max(3, int(c.max())) if m else 3
        order = np.argsort(~keep, axis=1, kind="stable")[:, :kmax]
        order = np.where(np.arange(kmax)[None] < c[:, None], order, order[:, :1])
        out.append((np.take_along_axis(cand, order[..., None], 1), c))
    return out


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
                      "gap_planes": 0, "axis_planes": 0, "face_planes": 0, "exact_planes": 0}

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
    def score_planes(self, Pc, deg, cnt, owner, starts, planes, valid, A):
        """Scores ``(R, A)`` of R planes per node (``planes (R, A, 4)``), each against every
        fragment of its node. ``Pc`` (3, K, L) float32 corner coordinates."""
        opt = self.opt
        eps = np.float32(opt.epsilon)
        R = planes.shape[0]
        comp = [np.ascontiguousarray(planes[:, :, i], dtype=np.float32)[:, owner] for i in range(4)]
        exact = opt.split_cost == "triangles"
        K = Pc.shape[1]
        d = np.empty_like(comp[0])
        tmp = np.empty_like(comp[0])
        mn = mx = on_corners = None
        for k in range(K):
            np.multiply(comp[0], Pc[0, k], out=d)
            np.multiply(comp[1], Pc[1, k], out=tmp)
            d += tmp
            np.multiply(comp[2], Pc[2, k], out=tmp)
            d += tmp
            d -= comp[3]
            if exact:
                on = (d <= eps) & (d >= -eps)
                if on_corners is None:
                    on_corners = on.astype(np.int8)
                    on0 = on
                else:
                    on_corners += on
            if mn is None:
                mn, mx = d.copy(), d.copy()
            else:
                np.minimum(mn, d, out=mn)
                np.maximum(mx, d, out=mx)
        if exact and K > 3:
            # padding repeats corner 0: take its extra counts back
            on_corners -= (K - cnt).astype(np.int8)[None, :] * on0
        # straddling = has a part behind and a part in front; degenerate ones are never cut
        has_b = mn < -eps
        has_f = mx > eps
        if deg.any():
            fix = has_b & has_f & deg[None, :]
            ahead = (mn + mx) >= 0
            has_b &= ~(fix & ahead)
            has_f &= ~(fix & ~ahead)
        seg = starts[:-1]
        n_b = np.add.reduceat(has_b, seg, axis=1, dtype=np.int32)
        n_f = np.add.reduceat(has_f, seg, axis=1, dtype=np.int32)
        span = has_b & has_f
        n_sp = np.add.reduceat(span, seg, axis=1, dtype=np.int32)
        # a cut adds 2 triangles, 1 through a corner, none along a diagonal
        cost = n_sp if not exact else np.add.reduceat(
            np.where(span, np.maximum(0, 2 - on_corners), 0), seg, axis=1, dtype=np.int32)
        n = (starts[1:] - starts[:-1])[None, :]
        fr, bk = n_f - n_sp, n_b - n_sp
        on = n - n_b - n_f + n_sp
        sc = opt.split_weight * cost + opt.balance_weight * np.abs(fr - bk) - opt.coplanar_weight * on
        progress = (on > 0) | ((fr > 0) & (bk > 0))
        return np.where(valid & progress, sc, np.inf)

    def choose(self, fids, owner, starts, rng, extra=None, extra_owner=None):
        """One plane per open node: the best of its candidates. Candidates are planes of the
        node's fragments and of ``extra`` (fragments peeled off the node: their planes often
        separate what is left); only ``fids`` are scored."""
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
        pool_sizes = np.bincount(pool_owner, minlength=A)
        pool_starts = np.concatenate([[0], np.cumsum(pool_sizes)])
        C = int(pool_sizes.max()) if opt.candidates <= 0 else opt.candidates
        # sample C candidate fragments per node without replacement (seeded, stable)
        keys = rng.random(len(pool)) + st.degenerate_of(pool) * 2.0
        order = np.lexsort((keys, pool_owner))
        rank = np.arange(len(pool)) - pool_starts[pool_owner[order]]
        take = (rank < C) & (keys[order] < 2.0)
        cand = np.full((A, C), -1, np.int64)
        cand[pool_owner[order[take]], rank[take]] = pool[order[take]]  # fragment ids
        best = np.full(A, np.inf)
        best_plane = np.zeros((A, 4))
        best_world = np.zeros((A, 4))
        best_kind = np.zeros(A, np.int8)
        cen_all = (P * (np.arange(Kl)[None, :] < cnt[:, None])[..., None]).sum(1) / cnt[:, None]

        allsc, allpl, allw, allk = [], [], [], []

        def consider(planes, world, valid, kind):
            """planes/world (R, A, 4), valid (R, A)"""
            sc = self.score_planes(Pc, deg, cnt, owner, starts, planes, valid, A)
            if opt.lookahead:
                allsc.append(sc)
                allpl.append(planes)
                allw.append(world)
                allk.append(np.full(sc.shape, kind, np.int8))
            for r in range(len(sc)):
                better = sc[r] < best
                best[better] = sc[r][better]
                best_plane[better] = planes[r][better]
                best_world[better] = world[r][better]
                best_kind[better] = kind

        used = int((cand >= 0).any(0).sum())
        R = max(1, min(used, 2_000_000 // max(1, L)))
        for r0 in range(0, used, R):
            c = cand[:, r0:r0 + R].T  # (R, A)
            valid = c >= 0
            cc = np.where(valid, c, 0)
            fr = cc.ravel()
            nrm = st.planes_of(fr)[:, :3]
            planes, world = self.quantise(nrm, st.src_center[st.src[fr]])
            consider(planes.reshape(*cc.shape, 4), world.reshape(*cc.shape, 4), valid, 0)
            if opt.sweep:
                nr = nrm.reshape(*cc.shape, 3)
                for r in range(len(nr)):
                    t, ok = self.sweep(P, owner, starts, nr[r])
                    planes, world = self.quantise(nr[r], t[:, None] * nr[r])
                    consider(planes[None], world[None], (ok & valid[r])[None], 4)
        for r in range(opt.sweep_dirs):
            n = rng.normal(size=(A, 3))
            n /= np.linalg.norm(n, axis=1)[:, None]
            t, ok = self.sweep(P, owner, starts, n)
            planes, world = self.quantise(n, t[:, None] * n)
            consider(planes[None], world[None], ok[None], 5)
        if opt.free_planes:
            # planes through three random corners of the node's fragments
            F = opt.free_planes
            for r0 in range(F):
                pick = []
                for t in range(3):
                    u = rng.random(A)
                    j = starts[:-1] + np.minimum((u * sizes).astype(np.int64), sizes - 1)
                    kk = (rng.random(A) * cnt[j]).astype(np.int64)
                    pick.append(P[j, kk])
                n = np.cross(pick[1] - pick[0], pick[2] - pick[0])
                ln = np.linalg.norm(n, axis=1)
                ok = ln > 1e-9
                n = n / np.maximum(ln, 1e-300)[:, None]
                ok &= sizes >= opt.free_min
                planes, world = self.quantise(n, pick[0])
                consider(planes[None], world[None], ok[None], 3)
        if opt.gap_planes or opt.axis_planes:
            lo = P.min(1)
            hi = P.max(1)
            for ax in range(3):
                if opt.gap_planes:
                    pt, valid = self.gap(lo[:, ax], hi[:, ax], owner, starts)
                    n = np.zeros((A, 3))
                    n[:, ax] = 1.0
                    p3 = np.zeros((A, 3))
                    p3[:, ax] = pt
                    planes, world = self.quantise(n, p3)
                    consider(planes[None], world[None], valid[None], 1)
                if opt.axis_planes:
                    c = cen_all[:, ax]
                    o2 = np.lexsort((c, owner))
                    med = c[o2[starts[:-1] + sizes // 2]]
                    n = np.zeros((A, 3))
                    n[:, ax] = 1.0
                    p3 = np.zeros((A, 3))
                    p3[:, ax] = med
                    planes, world = self.quantise(n, p3)
                    consider(planes[None], world[None], (sizes > 1)[None], 2)
        if opt.lookahead and allsc:
            self.look(fids, starts, np.concatenate(allsc), np.concatenate(allpl), np.concatenate(allw),
                      np.concatenate(allk), best, best_plane, best_world, best_kind)
        # a node whose every candidate failed (all fragments degenerate): no plane
        for k, name in ((0, "face_planes"), (1, "gap_planes"), (2, "axis_planes")):
            self.stats[name] += int(((best_kind == k) & np.isfinite(best)).sum())
        return best_plane, best_world, np.isfinite(best)

    def look(self, fids, starts, sc, pl, wo, kind, best, best_plane, best_world, best_kind):
        """One step of lookahead on small nodes: re-score the ``lookahead`` best candidates by
        what the children leave unpeeled (their cyclic cores must be split again)."""
        st, opt = self.store, self.opt
        eps = opt.epsilon
        k = opt.lookahead
        sizes = starts[1:] - starts[:-1]
        for a in np.flatnonzero((sizes <= opt.leaf_max) & np.isfinite(best)):
            ids = fids[starts[a]:starts[a + 1]]
            M = hide_graph(st, ids[None], eps)
            top = np.argsort(sc[:, a], kind="stable")[:k]
            top = top[np.isfinite(sc[top, a])]
            bsc = np.inf
            for r in top:
                plane = pl[r, a]
                d = distances(st.pos[ids], np.repeat(plane[None], len(ids), 0), eps)
                lab = classify(d, st.degenerate_of(ids), st.count[ids])
                core = 0
                X = lab == 3
                (fP, fc), (bP, bc) = clip_pieces(st.pos[ids[X]], st.count[ids[X]], d[X])
                for side, pP in ((0, fP), (1, bP)):
                    keep = lab == side
                    K2 = max(st.K, pP.shape[1])
                    Pw = st.pos[ids[keep]]
                    if K2 > Pw.shape[1]:
                        Pw = np.concatenate([Pw, np.repeat(Pw[:, :1], K2 - Pw.shape[1], 1)], 1)
                    if K2 > pP.shape[1]:
                        pP = np.concatenate([pP, np.repeat(pP[:, :1], K2 - pP.shape[1], 1)], 1)
                    Pc = np.concatenate([Pw, pP])
                    ii = np.concatenate([ids[keep], ids[X]])
                    if len(ii) == 0:
                        continue
                    live = ~st.degenerate_of(ii)
                    Mc = hide_raw(Pc[None], st.planes_of(ii)[None], st.two_sided_of(ii)[None], live[None], eps)
                    stt, _ = peel(Mc, np.ones((1, len(ii)), bool))
                    core += int((stt == 0).sum())
                total = sc[r, a] + opt.core_weight * core
                if total < bsc:
                    bsc = total
                    best_plane[a] = plane
                    best_world[a] = wo[r, a]
                    best_kind[a] = kind[r, a]

    def sweep(self, P, owner, starts, n):
        """Per node, the offset along direction ``n[a]`` with the best estimated score
        (cuts counted as 2 triangles, balance of the rest), among the fragments' extreme
        positions. Returns (offset, valid) per node."""
        opt = self.opt
        eps = opt.epsilon
        A = len(starts) - 1
        proj = np.einsum("lkc,lc->lk", P, n[owner])
        lo, hi = proj.min(1), proj.max(1)
        base = owner * 8.0
        klo = np.sort(base + lo)
        khi = np.sort(base + hi)
        m = (starts[1:] - starts[:-1])[owner]
        res = []
        for t in (hi, lo):
            a_ = np.searchsorted(klo, base + t - eps, "left") - starts[owner]
            bn = starts[owner + 1] - np.searchsorted(khi, base + t + eps, "right")
            sc = opt.split_weight * 2.0 * np.maximum(0, a_ + bn - m) + opt.balance_weight * np.abs(bn - a_)
            ok = (m - a_ > 0) & (m - bn > 0)
            res.append((t, np.where(ok, sc, np.inf)))
        t = np.concatenate([res[0][0], res[1][0]])
        sc = np.concatenate([res[0][1], res[1][1]])
        own = np.concatenate([owner, owner])
        o = np.lexsort((sc, own))
        firsts = np.ones(len(o), bool)
        firsts[1:] = own[o][1:] != own[o][:-1]
        pick = o[firsts]
        out_t = np.zeros(A)
        out_ok = np.zeros(A, bool)
        out_t[own[pick]] = t[pick]
        out_ok[own[pick]] = np.isfinite(sc[pick])
        return out_t, out_ok

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
    def run(self) -> None:
        st, opt = self.store, self.opt
        eps = opt.epsilon
        fids = np.arange(st.n)
        owner = np.zeros(st.n, np.int64)
        node_of = self.new_nodes(1, 0, np.array([st.n]))
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
            if opt.leaves != "none":
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
            planes, world, found = self.choose(fids, owner, starts, rng, *peeled)
            if level == 0 and opt.root_plane is not None and len(node_of) == 1:
                planes[0] = opt.root_plane
                world[0] = opt.root_plane
                found[0] = True
            if opt.capture is not None:
                opt.capture.append((fids.copy(), starts.copy(), planes.copy()))
            self.stats["choose_seconds"] += time.perf_counter() - t
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
            # ---- split
            t = time.perf_counter()
            n_before = st.n
            res = split_faces(st, fids, planes, owner, eps, opt.min_area)
            if opt.fragments == "fans":
                res = _fan_new_pieces(st, res, n_before)
            self.stats["splits"] += res.splits
            self.stats["kept_whole"] += res.kept_whole
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
    b = _Builder(store, opt, np.zeros(3) if center is None else np.asarray(center, np.float64), float(scale))
    b.run()
    tree = b.tree()
    tree.stats["seconds"] = time.perf_counter() - t0
    return tree
