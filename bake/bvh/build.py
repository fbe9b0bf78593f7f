"""Top-down binned-SAH BVH builder (vectorised, level by level) and the SAH cost.

The builder works breadth first: every node of one level is binned, evaluated and partitioned
with the same handful of numpy calls, so the Python overhead is per *level* (a few dozen for
any mesh), not per node, and never per triangle.

Conventions
-----------
* A :class:`BVH` is a binary tree over *references*: ``order[first:first+count]`` of a leaf
  are the triangle numbers (0-based, scene order) it holds.
* Boxes are exact float64 boxes of the triangles below a node (no padding; the encoder pads).
* The SAH cost is the one tinybvh's ``SAHCost`` reports::

      (sum over interior nodes C_trav * A  +  sum over leaves C_int * A * n) / A_root

  with ``A`` the surface area of a node box. ``C_trav = C_int = 1`` unless told otherwise.
"""

from __future__ import annotations

import heapq
import math
from dataclasses import dataclass, field

import numpy as np


@dataclass
class BVH:
    """A binary BVH. Node 0 is the root; children always have larger numbers than parents."""

    lo: np.ndarray  # (N, 3) float64 node box minimum
    hi: np.ndarray  # (N, 3) float64 node box maximum
    left: np.ndarray  # (N,) int64 child, -1 for a leaf
    right: np.ndarray  # (N,) int64 child, -1 for a leaf
    first: np.ndarray  # (N,) int64 start of the node's references in ``order``
    count: np.ndarray  # (N,) int64 number of references below the node
    order: np.ndarray  # (M,) int64 triangle number of each reference
    info: dict = field(default_factory=dict)

    @property
    def n_nodes(self) -> int:
        return int(len(self.left))

    @property
    def is_leaf(self) -> np.ndarray:
        return self.left < 0

    @property
    def n_leaves(self) -> int:
        return int(self.is_leaf.sum())

    def parents(self) -> np.ndarray:
        par = np.full(self.n_nodes, -1, np.int64)
        inner = np.nonzero(~self.is_leaf)[0]
        par[self.left[inner]] = inner
        par[self.right[inner]] = inner
        return par

    def depths(self) -> np.ndarray:
        """Depth of every node (root 0). Children are numbered after parents, so one pass."""
        d = np.zeros(self.n_nodes, np.int64)
        for lvl_nodes in _levels(self):
            ch = lvl_nodes[~self.is_leaf[lvl_nodes]]
            d[self.left[ch]] = d[ch] + 1
            d[self.right[ch]] = d[ch] + 1
        return d

    def depth(self) -> int:
        return int(self.depths().max()) if self.n_nodes else 0


def _levels(bvh: BVH):
    """Yield arrays of node numbers, level by level from the root."""
    if bvh.n_nodes == 0:
        return
    cur = np.array([0], np.int64)
    while len(cur):
        yield cur
        inner = cur[bvh.left[cur] >= 0]
        cur = np.concatenate([bvh.left[inner], bvh.right[inner]])


def half_area(lo: np.ndarray, hi: np.ndarray) -> np.ndarray:
    """Half the surface area of boxes (..., 3); 0 for empty/inverted boxes."""
    e = np.maximum(hi - lo, 0.0)
    return e[..., 0] * e[..., 1] + e[..., 1] * e[..., 2] + e[..., 2] * e[..., 0]


def sah_cost(bvh: BVH, c_trav: float = 1.0, c_int: float = 1.0, *, lo: np.ndarray | None = None,
             hi: np.ndarray | None = None) -> float:
    """The tinybvh SAH cost of the tree (see module doc). 0 for an empty tree. ``lo``/``hi``
    (N, 3) replace the node boxes (e.g. the boxes as the lists write them, rounded outward)."""
    if bvh.n_nodes == 0:
        return 0.0
    a = half_area(bvh.lo if lo is None else lo, bvh.hi if hi is None else hi)
    leaf = bvh.is_leaf
    root = a[0]
    total = c_trav * a[~leaf].sum() + c_int * (a[leaf] * bvh.count[leaf]).sum()
    if root <= 0:
        # a flat scene has no area; fall back to the box perimeter-free measure: leaf refs
        return float(bvh.count[leaf].max()) if leaf.any() else 0.0
    return float(total / root)


# --------------------------------------------------------------------------- binned build
def triangle_bounds(tri: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(T,3,3) corners -> per-triangle (lo, hi)."""
    return tri.min(axis=1), tri.max(axis=1)


def build_binned(lo: np.ndarray, hi: np.ndarray, *, leaf_size: int = 4, bins: int = 8,
                 c_trav: float = 1.0, c_int: float = 1.0, centroids: np.ndarray | None = None,
                 ids: np.ndarray | None = None, sweep_max: int | None = None) -> BVH:
    """Top-down binned SAH over primitive boxes ``lo``/``hi`` (P, 3).

    Bins are laid over the centroid bounds of every node on all three axes. A node becomes a
    leaf when it holds at most ``leaf_size`` primitives and no split is cheaper than the leaf
    (``C_trav + (A_L N_L + A_R N_R)/A >= C_int N``); a larger node is always split (an object
    median when every centroid coincides). ``ids`` (default ``arange(P)``) is what ``order``
    stores for each primitive. Nodes with at most ``sweep_max`` primitives (default
    ``bins``) are split with an exact sweep over their sorted centroids instead of bins: that
    is cheaper than binning a tiny node and never worse.
    """
    lo = np.ascontiguousarray(lo, np.float64)
    hi = np.ascontiguousarray(hi, np.float64)
    P = len(lo)
    cen = (lo + hi) * 0.5 if centroids is None else np.ascontiguousarray(centroids, np.float64)
    ids = np.arange(P, dtype=np.int64) if ids is None else np.asarray(ids, np.int64)
    leaf_size = max(1, int(leaf_size))
    bins = max(2, int(bins))
    sweep_max = bins if sweep_max is None else int(sweep_max)
    if P == 0:
        z = np.zeros((0, 3))
        e = np.zeros(0, np.int64)
        return BVH(z, z.copy(), e, e.copy(), e.copy(), e.copy(), e.copy())

    cap = 2 * P  # a binary tree over P leaves has < 2P nodes
    n_lo = np.empty((cap, 3))
    n_hi = np.empty((cap, 3))
    n_left = np.full(cap, -1, np.int64)
    n_right = np.full(cap, -1, np.int64)
    n_first = np.zeros(cap, np.int64)
    n_count = np.zeros(cap, np.int64)
    order = np.arange(P, dtype=np.int64)  # permutation of primitive numbers

    # the current level: node ids and their [start, end) ranges in ``order``
    lvl_id = np.array([0], np.int64)
    lvl_start = np.array([0], np.int64)
    lvl_n = np.array([P], np.int64)
    n_used = 1
    levels = 0
    n_fallback = 0
    while len(lvl_id):
        levels += 1
        K = len(lvl_id)
        offs = np.zeros(K, np.int64)
        np.cumsum(lvl_n[:-1], out=offs[1:])
        total = int(lvl_n.sum())
        local = np.repeat(np.arange(K), lvl_n)  # node (local number) of every slot
        pos = np.arange(total, dtype=np.int64) - offs[local] + lvl_start[local]  # slot in order
        prim = order[pos]
        plo, phi, pc = lo[prim], hi[prim], cen[prim]
        blo = np.minimum.reduceat(plo, offs, axis=0)
        bhi = np.maximum.reduceat(phi, offs, axis=0)
        clo = np.minimum.reduceat(pc, offs, axis=0)
        chi = np.maximum.reduceat(pc, offs, axis=0)
        n_lo[lvl_id] = blo
        n_hi[lvl_id] = bhi
        n_first[lvl_id] = lvl_start
        n_count[lvl_id] = lvl_n
        area = half_area(blo, bhi)

        # ---- best split of every node: exact sweep for small nodes, bins for the rest
        best_cost = np.full(K, np.inf)
        go_left = np.zeros(total, bool)
        multi = lvl_n >= 2
        swept = multi & (lvl_n <= sweep_max)
        binned = multi & ~swept
        if binned.any():
            _binned_split(binned, local, offs, lvl_n, pc, plo, phi, clo, chi, bins, best_cost,
                          go_left)
        if swept.any():
            _sweep_split(swept, local, offs, lvl_n, pc, plo, phi, best_cost, go_left)
        has_split = np.isfinite(best_cost)
        split_sah = c_trav * area + c_int * best_cost
        leaf_sah = c_int * lvl_n * area
        small = lvl_n <= leaf_size
        make_leaf = (lvl_n <= 1) | (small & ((split_sah >= leaf_sah) | ~has_split))
        split = ~make_leaf
        median = split & ~has_split  # all centroids equal: split the range in half
        n_fallback += int(median.sum())
        if not split.any():
            break

        # ---- partition every split node's range: left references first, order kept
        rank_in_node = np.arange(total, dtype=np.int64) - offs[local]
        med_slot = median[local]
        go_left[med_slot] = rank_in_node[med_slot] < (lvl_n[local][med_slot] // 2)
        keep = split[local]
        gl = go_left & keep
        cnt_left = np.bincount(local, weights=gl, minlength=K).astype(np.int64)
        cl = np.cumsum(gl) - gl  # lefts before this slot (global)
        cl_node = cl - cl[offs][local]
        gr = (~go_left) & keep
        cr = np.cumsum(gr) - gr
        cr_node = cr - cr[offs][local]
        new_rank = np.where(go_left, cl_node, cnt_left[local] + cr_node)
        sel = keep
        order[lvl_start[local[sel]] + new_rank[sel]] = prim[sel]

        sid = np.nonzero(split)[0]
        S = len(sid)
        left_id = n_used + 2 * np.arange(S)
        right_id = left_id + 1
        n_used += 2 * S
        n_left[lvl_id[sid]] = left_id
        n_right[lvl_id[sid]] = right_id
        nl = cnt_left[sid]
        ch_id = np.empty(2 * S, np.int64)
        ch_start = np.empty(2 * S, np.int64)
        ch_n = np.empty(2 * S, np.int64)
        ch_id[0::2], ch_id[1::2] = left_id, right_id
        ch_start[0::2], ch_start[1::2] = lvl_start[sid], lvl_start[sid] + nl
        ch_n[0::2], ch_n[1::2] = nl, lvl_n[sid] - nl
        lvl_id, lvl_start, lvl_n = ch_id, ch_start, ch_n

    N = n_used
    bvh = BVH(lo=n_lo[:N].copy(), hi=n_hi[:N].copy(), left=n_left[:N].copy(),
              right=n_right[:N].copy(), first=n_first[:N].copy(), count=n_count[:N].copy(),
              order=ids[order])
    bvh.info.update(levels=levels, median_splits=n_fallback, bins=bins, leaf_size=leaf_size)
    return bvh


def _binned_split(sel_nodes, local, offs, lvl_n, pc, plo, phi, clo, chi, bins, best_cost, go_left):
    """Binned SAH for the nodes in ``sel_nodes`` (bool over the level's nodes)."""
    slots = np.nonzero(sel_nodes[local])[0]
    nodes = np.nonzero(sel_nodes)[0]
    K = len(nodes)
    remap = np.full(len(sel_nodes), -1, np.int64)
    remap[nodes] = np.arange(K)
    loc = remap[local[slots]]
    c, lo_, hi_ = pc[slots], plo[slots], phi[slots]
    ext = chi[nodes] - clo[nodes]
    with np.errstate(divide="ignore", invalid="ignore"):
        scale = np.where(ext > 0, bins / np.where(ext > 0, ext, 1.0), 0.0)
    b = ((c - clo[nodes][loc]) * scale[loc]).astype(np.int64)
    np.clip(b, 0, bins - 1, out=b)
    key = (loc[:, None] * 3 + np.arange(3)) * bins + b  # (n, 3)
    nb = K * 3 * bins
    cnt = np.bincount(key.ravel(), minlength=nb)
    bin_lo = np.full((3, nb), np.inf)
    bin_hi = np.full((3, nb), -np.inf)
    for ax in range(3):
        k = key[:, ax]
        for j in range(3):
            np.minimum.at(bin_lo[j], k, lo_[:, j])
            np.maximum.at(bin_hi[j], k, hi_[:, j])
    # bins first, so the prefix/suffix sweeps run over contiguous rows: (bins, 3, K*3)
    K3 = K * 3
    bin_lo = np.ascontiguousarray(bin_lo.reshape(3, K3, bins).transpose(2, 0, 1))
    bin_hi = np.ascontiguousarray(bin_hi.reshape(3, K3, bins).transpose(2, 0, 1))
    cnt_b = np.ascontiguousarray(cnt.reshape(K3, bins).T)
    l_lo = np.minimum.accumulate(bin_lo, axis=0)[:-1]
    l_hi = np.maximum.accumulate(bin_hi, axis=0)[:-1]
    l_n = np.cumsum(cnt_b, axis=0)[:-1]
    r_lo = np.minimum.accumulate(bin_lo[::-1], axis=0)[::-1][1:]
    r_hi = np.maximum.accumulate(bin_hi[::-1], axis=0)[::-1][1:]
    r_n = np.repeat(lvl_n[nodes], 3)[None, :] - l_n
    valid = (l_n > 0) & (r_n > 0)
    with np.errstate(invalid="ignore"):
        cost = np.where(valid, _harea(l_lo, l_hi, 1) * l_n + _harea(r_lo, r_hi, 1) * r_n, np.inf)
    # (bins-1, K*3) -> (K, 3*(bins-1)) with index axis*(bins-1) + split
    flat = cost.reshape(bins - 1, K, 3).transpose(1, 2, 0).reshape(K, -1)
    best = np.argmin(flat, axis=1)
    best_cost[nodes] = flat[np.arange(K), best]
    axis, split_bin = best // (bins - 1), best % (bins - 1)
    go_left[slots] = b[np.arange(len(slots)), axis[loc]] <= split_bin[loc]


def _sweep_split(sel_nodes, local, offs, lvl_n, pc, plo, phi, best_cost, go_left):
    """Exact SAH sweep (every split between sorted centroids) for small nodes."""
    slots = np.nonzero(sel_nodes[local])[0]
    nodes = np.nonzero(sel_nodes)[0]
    K = len(nodes)
    m = int(lvl_n[nodes].max())
    remap = np.full(len(sel_nodes), -1, np.int64)
    remap[nodes] = np.arange(K)
    loc = remap[local[slots]]
    rank = slots - offs[local[slots]]
    C = np.full((K, m, 3), np.inf)
    L = np.full((K, m, 3), np.inf)
    H = np.full((K, m, 3), -np.inf)
    C[loc, rank] = pc[slots]
    L[loc, rank] = plo[slots]
    H[loc, rank] = phi[slots]
    n = lvl_n[nodes]
    ks = np.arange(1, m)  # left gets the first k of the sorted order
    costs = np.empty((K, 3, m - 1))
    orders = np.empty((K, 3, m), np.int64)
    for ax in range(3):
        o = np.argsort(C[:, :, ax], axis=1, kind="stable")
        orders[:, ax] = o
        sl = np.take_along_axis(L, o[:, :, None], axis=1)
        sh = np.take_along_axis(H, o[:, :, None], axis=1)
        pl = np.minimum.accumulate(sl, axis=1)[:, :-1]
        ph = np.maximum.accumulate(sh, axis=1)[:, :-1]
        # suffix over the real entries only: padding sorts last and is +inf/-inf (neutral)
        ql = np.minimum.accumulate(sl[:, ::-1], axis=1)[:, ::-1][:, 1:]
        qh = np.maximum.accumulate(sh[:, ::-1], axis=1)[:, ::-1][:, 1:]
        nr = n[:, None] - ks[None, :]
        with np.errstate(invalid="ignore"):
            c = _harea(pl, ph, 2) * ks[None, :] + _harea(ql, qh, 2) * nr
        costs[:, ax] = np.where(nr > 0, c, np.inf)
    flat = costs.reshape(K, -1)
    best = np.argmin(flat, axis=1)
    best_cost[nodes] = flat[np.arange(K), best]
    axis, k = best // (m - 1), best % (m - 1) + 1
    o = orders[np.arange(K), axis]  # (K, m) sorted -> rank
    pos = np.empty_like(o)
    np.put_along_axis(pos, o, np.arange(m)[None, :].repeat(K, 0), axis=1)
    go_left[slots] = pos[loc, rank] < k[loc]


def _harea(lo, hi, axis):
    """Half surface area with the xyz components on ``axis``."""
    e = hi - lo
    x, y, z = (np.take(e, i, axis=axis) for i in range(3))
    return x * y + y * z + z * x


# --------------------------------------------------------------------------- tree tools
def _level_list(bvh: BVH) -> list[np.ndarray]:
    return list(_levels(bvh))


def refit_counts(bvh: BVH, levels: list[np.ndarray] | None = None) -> None:
    """Recompute interior ``count``/``lo``/``hi`` bottom-up from the leaves (in place)."""
    levels = levels if levels is not None else _level_list(bvh)
    for lv in reversed(levels):
        inner = lv[bvh.left[lv] >= 0]
        if len(inner) == 0:
            continue
        l, r = bvh.left[inner], bvh.right[inner]
        bvh.count[inner] = bvh.count[l] + bvh.count[r]
        bvh.lo[inner] = np.minimum(bvh.lo[l], bvh.lo[r])
        bvh.hi[inner] = np.maximum(bvh.hi[l], bvh.hi[r])


def preorder(bvh: BVH) -> BVH:
    """The same tree renumbered depth-first (node, left subtree, right subtree), unreachable
    nodes dropped, and ``order`` rewritten so every subtree's references are contiguous in
    depth-first leaf order (``first``/``count`` updated)."""
    if bvh.n_nodes == 0:
        return bvh
    levels = _level_list(bvh)
    N = bvh.n_nodes
    size = np.ones(N, np.int64)  # nodes in the subtree
    refs = np.where(bvh.left < 0, bvh.count, 0).astype(np.int64)
    for lv in reversed(levels):
        inner = lv[bvh.left[lv] >= 0]
        size[inner] = 1 + size[bvh.left[inner]] + size[bvh.right[inner]]
        refs[inner] = refs[bvh.left[inner]] + refs[bvh.right[inner]]
    new = np.full(N, -1, np.int64)
    nfirst = np.zeros(N, np.int64)
    new[0] = 0
    for lv in levels:
        inner = lv[bvh.left[lv] >= 0]
        l, r = bvh.left[inner], bvh.right[inner]
        new[l] = new[inner] + 1
        new[r] = new[inner] + 1 + size[l]
        nfirst[l] = nfirst[inner]
        nfirst[r] = nfirst[inner] + refs[l]
    keep = np.nonzero(new >= 0)[0]
    M = len(keep)
    inv = np.empty(M, np.int64)
    inv[new[keep]] = keep  # old id of each new id
    leaf_old = inv[bvh.left[inv] < 0]
    order = np.empty(int(refs[0]), np.int64)
    # scatter every leaf's references to its new place
    starts_old = bvh.first[leaf_old]
    cnt = bvh.count[leaf_old]
    rep = np.repeat(np.arange(len(leaf_old)), cnt)
    off = np.zeros(len(leaf_old), np.int64)
    np.cumsum(cnt[:-1], out=off[1:])
    within = np.arange(int(cnt.sum())) - off[rep]
    order[nfirst[leaf_old][rep] + within] = bvh.order[starts_old[rep] + within]
    left = np.where(bvh.left[inv] >= 0, new[np.maximum(bvh.left[inv], 0)], -1)
    right = np.where(bvh.right[inv] >= 0, new[np.maximum(bvh.right[inv], 0)], -1)
    out = BVH(lo=bvh.lo[inv].copy(), hi=bvh.hi[inv].copy(), left=left, right=right,
              first=nfirst[inv].copy(), count=refs[inv].copy(), order=order, info=dict(bvh.info))
    return out


def collapse(bvh: BVH, leaf_size: int, c_trav: float = 1.0, c_int: float = 1.0) -> BVH:
    """Bottom-up optimal leaf collapse: a subtree with at most ``leaf_size`` references becomes
    one leaf when that is cheaper under the SAH than the subtree. Never raises the SAH cost."""
    if bvh.n_nodes == 0:
        return bvh
    levels = _level_list(bvh)
    a = half_area(bvh.lo, bvh.hi)
    cost = c_int * a * bvh.count
    left = bvh.left.copy()
    right = bvh.right.copy()
    changed = 0
    for lv in reversed(levels):
        inner = lv[left[lv] >= 0]
        if len(inner) == 0:
            continue
        sub = c_trav * a[inner] + cost[left[inner]] + cost[right[inner]]
        as_leaf = c_int * a[inner] * bvh.count[inner]
        mk = (bvh.count[inner] <= leaf_size) & (as_leaf <= sub)
        cost[inner] = np.where(mk, as_leaf, sub)
        left[inner[mk]] = -1
        right[inner[mk]] = -1
        changed += int(mk.sum())
    if not changed:
        return bvh
    out = BVH(lo=bvh.lo, hi=bvh.hi, left=left, right=right, first=bvh.first, count=bvh.count,
              order=bvh.order, info=dict(bvh.info))
    out = preorder(out)
    out.info["collapsed"] = changed
    return out


# --------------------------------------------------------------------------- reinsertion
def reinsertion(bvh: BVH, *, passes: int = 4, fraction: float = 0.1, budget: float = 10e6,
                c_trav: float = 1.0, mode: str = "children") -> BVH:
    """Insertion-based optimisation (after Bittner, Hapala & Havran 2013).

    Each pass ranks the interior nodes by how much larger their box is than their children's
    (Bittner's M_sum * M_min * M_area) and, for the top ``fraction``, pulls the node out of the
    tree (it and its parent become free) and puts its two children back one by one where they
    raise the interior surface area least (an exact branch-and-bound search over the whole
    tree). A move that does not lower the SAH cost is undone, so the cost never rises. Leaves are
    kept as they are. ``mode="subtree"`` instead moves whole subtrees (leaves too), largest
    first; on the teapot it bought ~0.5% more for 10x the time, so ``build`` does not use it. A Python loop per move (nodes, never triangles).

    ``budget`` bounds the work: the number of nodes the placement searches and refits may visit in all. It is
    a count, not a time, so the same tree comes out on a busy machine and a quiet one (a time limit
    made bakes differ under load); ``info["reinsertion_visits"]`` says how many were used.
    """
    if bvh.n_nodes < 5:
        return bvh
    t = _Tree(bvh)
    moves = undone = 0
    inner = [i for i in range(len(t.L)) if t.L[i] >= 0]
    for _pass in range(passes):
        if t.visits > budget:
            break
        cand = t.ranked(inner, mode)
        k = max(1, int(len(cand) * fraction))
        for _, i in cand[:k]:
            if t.visits > budget:
                break
            kept = t.move_subtree(i) if mode == "subtree" else t.move_children(i)
            if kept is None:  # the root or (moving children) a child of it: nothing to move
                continue
            if kept:
                moves += 1
            else:
                undone += 1
    out = BVH(lo=np.array(t.lo), hi=np.array(t.hi), left=np.array(t.L, np.int64),
              right=np.array(t.Rg, np.int64), first=bvh.first.copy(), count=bvh.count.copy(),
              order=bvh.order, info=dict(bvh.info))
    if t.root != 0:
        out = _reroot(out, t.root)
    refit_counts(out)
    out = preorder(out)
    out.info["reinsertions"] = moves
    out.info["reinsertions_undone"] = undone
    out.info["reinsertion_visits"] = t.visits
    out.info["reinsertion_budget_reached"] = t.visits > budget
    return out


def _area_box(a, b):
    """Half the surface area of the box from ``a`` to ``b`` (3 floats each)."""
    ex, ey, ez = b[0] - a[0], b[1] - a[1], b[2] - a[2]
    return ex * ey + ey * ez + ez * ex


def _union_area(a, b, blo, bhi):
    """:func:`_area_box` of the box ``a``..``b`` grown to hold ``blo``..``bhi``."""
    x0 = a[0] if a[0] < blo[0] else blo[0]
    y0 = a[1] if a[1] < blo[1] else blo[1]
    z0 = a[2] if a[2] < blo[2] else blo[2]
    x1 = b[0] if b[0] > bhi[0] else bhi[0]
    y1 = b[1] if b[1] > bhi[1] else bhi[1]
    z1 = b[2] if b[2] > bhi[2] else bhi[2]
    ex, ey, ez = x1 - x0, y1 - y0, z1 - z0
    return ex * ey + ey * ez + ez * ex


class _Tree:
    """The tree :func:`reinsertion` edits, as Python lists (a move touches a handful of nodes, where
    numpy calls per node would cost more): children ``L``/``Rg``, parents ``P``, boxes ``lo``/``hi``,
    the ``root``, the interior surface area ``total`` (the SAH cost the moves lower), and the
    ``visits`` the budget counts. During a move, ``journal`` holds every touched node's state before
    it, so the move can be undone."""

    def __init__(self, bvh: BVH):
        self.L = bvh.left.tolist()
        self.Rg = bvh.right.tolist()
        self.P = bvh.parents().tolist()
        self.lo = bvh.lo.tolist()
        self.hi = bvh.hi.tolist()
        self.root = 0
        self.total = 0.0
        self.visits = 0
        self.journal: dict[int, tuple] | None = None

    def ranked(self, inner: list[int], mode: str) -> list[tuple[float, int]]:
        """This pass's candidates, best first: (minus the score, node). ``children``: the interior
        nodes below the root's children by Bittner's M_sum * M_min * M_area; ``subtree``: every node
        but the root by its area."""
        L, Rg, P, lo, hi = self.L, self.Rg, self.P, self.lo, self.hi
        root = self.root
        cand = []
        if mode == "subtree":
            for i in range(len(L)):
                if i != root and P[i] >= 0:
                    cand.append((-_area_box(lo[i], hi[i]), i))
        for i in (inner if mode == "children" else ()):
            if i == root or P[i] == root:
                continue
            a = _area_box(lo[i], hi[i])
            al = _area_box(lo[L[i]], hi[L[i]])
            ar = _area_box(lo[Rg[i]], hi[Rg[i]])
            m_sum = a / max(0.5 * (al + ar), 1e-300)
            m_min = a / max(min(al, ar), 1e-300)
            cand.append((-(m_sum * m_min * a), i))
        cand.sort()
        return cand

    # ------------------------------------------------------------------ moves
    def move_subtree(self, i: int) -> bool | None:
        """Move the subtree of ``i`` to its best place; None if ``i`` is the root (no move), else
        whether the move was kept."""
        if i == self.root or self.P[i] < 0:
            return None
        self.journal = {}
        saved = (self.root, self.total)
        p_free = self.detach(i)
        self.attach(i, self.best_place(i), p_free)
        kept = self.settle(saved)
        self.journal = None
        return kept

    def move_children(self, i: int) -> bool | None:
        """Pull ``i`` out (it and its parent become free) and put its children back one by one,
        the larger first; None if ``i`` is the root or one of its children, else whether the move
        was kept."""
        L, Rg, P, lo, hi = self.L, self.Rg, self.P, self.lo, self.hi
        if i == self.root or P[i] < 0 or P[i] == self.root:
            return None
        self.journal = {}
        saved = (self.root, self.total)
        a, b = L[i], Rg[i]
        p_free = self.detach(i)
        self.touch(a), self.touch(b)
        self.total -= _area_box(lo[i], hi[i])
        P[a] = P[b] = -1
        L[i] = Rg[i] = -1
        if _area_box(lo[a], hi[a]) < _area_box(lo[b], hi[b]):
            a, b = b, a
        for orphan, free in ((a, p_free), (b, i)):
            self.attach(orphan, self.best_place(orphan), free)
        kept = self.settle(saved)
        self.journal = None
        return kept

    def settle(self, saved) -> bool:
        """Keep a move that lowered the SAH; otherwise roll every touched node back from the
        journal. True if the move was kept."""
        if self.total >= saved[1] - 1e-12 * abs(saved[1]):
            L, Rg, P, lo, hi = self.L, self.Rg, self.P, self.lo, self.hi
            for j, (lj, rj, pj, loj, hij) in self.journal.items():
                L[j], Rg[j], P[j], lo[j], hi[j] = lj, rj, pj, loj, hij
            self.root, self.total = saved
            return False
        return True

    # ------------------------------------------------------------------ edits
    def touch(self, i):
        """Note node i's state in the journal (the first time in a move)."""
        journal = self.journal
        if journal is not None and i >= 0 and i not in journal:
            journal[i] = (self.L[i], self.Rg[i], self.P[i], self.lo[i], self.hi[i])

    def refit(self, i):
        """The boxes of i and every node above it made to hold their children again."""
        L, Rg, P, lo, hi, touch = self.L, self.Rg, self.P, self.lo, self.hi, self.touch
        while i >= 0:
            self.visits += 1
            touch(i)
            a, b = L[i], Rg[i]
            la, lb, ha, hb = lo[a], lo[b], hi[a], hi[b]
            old = _area_box(lo[i], hi[i])
            lo[i] = [min(la[0], lb[0]), min(la[1], lb[1]), min(la[2], lb[2])]
            hi[i] = [max(ha[0], hb[0]), max(ha[1], hb[1]), max(ha[2], hb[2])]
            self.total += _area_box(lo[i], hi[i]) - old
            i = P[i]

    def detach(self, n):
        """Take n out: its parent is freed and n's sibling takes the parent's place."""
        L, Rg, P, lo, hi, touch = self.L, self.Rg, self.P, self.lo, self.hi, self.touch
        p = P[n]
        s = Rg[p] if L[p] == n else L[p]
        g = P[p]
        touch(p), touch(s), touch(g), touch(n)
        self.total -= _area_box(lo[p], hi[p])
        if g < 0:
            self.root = s
            P[s] = -1
        else:
            if L[g] == p:
                L[g] = s
            else:
                Rg[g] = s
            P[s] = g
            self.refit(g)
        P[n] = -1
        return p

    def best_place(self, n):
        """The node whose place n should share (a new parent over both) for the least added
        interior area: a branch-and-bound search from the root."""
        L, Rg, lo, hi = self.L, self.Rg, self.lo, self.hi
        blo, bhi = lo[n], hi[n]
        an = _area_box(blo, bhi)
        root = self.root
        best_c, best_x = math.inf, root
        heap = [(0.0, root)]
        visits = 0
        while heap:
            ci, x = heapq.heappop(heap)
            visits += 1
            if ci + an >= best_c:
                break
            ux = _union_area(lo[x], hi[x], blo, bhi)
            cd = ci + ux
            if cd < best_c:
                best_c, best_x = cd, x
            if L[x] >= 0:
                cc = ci + ux - _area_box(lo[x], hi[x])
                if cc + an < best_c:
                    heapq.heappush(heap, (cc, L[x]))
                    heapq.heappush(heap, (cc, Rg[x]))
        self.visits += visits
        return best_x

    def attach(self, n, x, p):
        """Make the free node p the parent of x and n, in x's place."""
        L, Rg, P, lo, hi, touch = self.L, self.Rg, self.P, self.lo, self.hi, self.touch
        g = P[x]
        touch(p), touch(x), touch(n), touch(g)
        L[p], Rg[p] = x, n
        P[p] = g
        P[x] = p
        P[n] = p
        if g < 0:
            self.root = p
        elif L[g] == x:
            L[g] = p
        else:
            Rg[g] = p
        lo[p], hi[p] = [0.0] * 3, [0.0] * 3  # refit sets it; area 0 -> adds the new area
        self.refit(p)


def _reroot(bvh: BVH, r: int) -> BVH:
    """Swap node numbers 0 and r (r becomes the root)."""
    perm = np.arange(bvh.n_nodes)
    perm[0], perm[r] = r, 0  # new id -> old id
    newid = np.empty_like(perm)
    newid[perm] = np.arange(bvh.n_nodes)

    def m(a):
        return np.where(a >= 0, newid[np.maximum(a, 0)], -1)

    return BVH(lo=bvh.lo[perm], hi=bvh.hi[perm], left=m(bvh.left[perm]), right=m(bvh.right[perm]),
               first=bvh.first[perm], count=bvh.count[perm], order=bvh.order, info=bvh.info)


# --------------------------------------------------------------------------- entry point
def build(lo: np.ndarray, hi: np.ndarray, *, leaf_size: int = 4, bins: int = 8,
          quality: str = "binned", high_effort: float = 10.0, ids: np.ndarray | None = None,
          c_trav: float = 1.0, c_int: float = 1.0) -> BVH:
    """A depth-first (preorder) BVH over primitive boxes.

    ``binned``: :func:`build_binned` with ``bins`` bins (exact sweep for nodes of at most
    ``bins`` primitives). ``high``: at least 32 bins and an exact sweep up to 64 primitives,
    built down to single-triangle leaves, improved by :func:`reinsertion` with a budget of
    ``high_effort`` million node visits (a count, so the tree does not depend on the machine's
    load), then :func:`collapse` to leaves of at most ``leaf_size``.
    """
    import time

    t0 = time.perf_counter()
    if quality == "high":
        b = build_binned(lo, hi, leaf_size=1, bins=max(bins, 32), sweep_max=64, ids=ids,
                         c_trav=c_trav, c_int=c_int)
        stages = {"start_sah": sah_cost(b, c_trav, c_int)}
        t1 = time.perf_counter()
        b = reinsertion(b, passes=4, fraction=0.05, budget=max(0.0, high_effort) * 1e6, c_trav=c_trav)
        stages["reinsertion_sah"] = sah_cost(b, c_trav, c_int)
        stages["reinsertion_seconds"] = time.perf_counter() - t1
        b = collapse(b, leaf_size, c_trav, c_int)
        b.info.update(stages)
    elif quality == "binned":
        b = preorder(build_binned(lo, hi, leaf_size=leaf_size, bins=bins, ids=ids, c_trav=c_trav,
                                  c_int=c_int))
    else:
        raise ValueError(f"unknown quality {quality!r}")
    b.info["quality"] = quality
    b.info["seconds"] = time.perf_counter() - t0
    return b
