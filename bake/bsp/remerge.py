"""Fragments merged back after the build: coplanar neighbours drawn together become one polygon.

A cut leaves a new corner on each edge it crosses. Two neighbouring coplanar fragments of the
same group (material, colour, sidedness) that end up drawn as one unit — the coplanar group of a
split node on one side, or the prefix or suffix of one node — can often be joined again, and the
joint drops the corners that the cut left on a straight line: ``k1 + k2 - 2 - r`` corners instead
of ``k1`` and ``k2``, so ``r`` (1 or 2) triangles fewer. Only joints that remove a corner are made,
and only where the union is convex and every shown attribute is affine over it (as in
``merge.py``).

Why the order stays right. "Fragment U may hide X" holds for a union exactly when it holds for
one of its parts (``build.py``: part of X behind U's plane and part of U in front of X's plane), so
every relation with fragments outside the unit is the one the parts had. Coplanar fragments facing
the same way hide nothing of each other, so a coplanar group needs no check. In a prefix or suffix
the union is drawn at the later part's place, and the new sequence is checked against the "may
hide" graph (no fragment drawn before another may hide it); a node whose sequence fails, or whose
list is too long to check, keeps its fragments as they were.

A removed corner is a point within the tree's tolerance of the straight line through its
neighbours, so the neighbour across that edge (which keeps the corner) meets the union's edge
within that tolerance (a T-junction, at most two grid steps off).
"""

from __future__ import annotations

import numpy as np

from .build import Tree, hide_graph
from .merge import _affine_ok, mutual_proposals, union_slots
from .split import MIN_COS_TILT, FaceStore

CHECK_MAX = 512  # longest prefix/suffix list whose new order is checked (the check is O(m^2))


def _turn_ok(n, prev, mid, nxt, eps):
    """At corner ``mid``: 1 strictly convex, 2 straight (within ``eps`` of the line prev-next, and
    between them), 0 reflex."""
    e1, e2 = mid - prev, nxt - mid
    t = np.einsum("ij,ij->i", np.cross(e1, e2), n)
    chord = nxt - prev
    lc = np.linalg.norm(chord, axis=1)
    dist = np.abs(np.linalg.norm(np.cross(chord, mid - prev), axis=1)) / np.maximum(lc, 1e-300)
    s = np.einsum("ij,ij->i", mid - prev, chord) / np.maximum(lc * lc, 1e-300)
    straight = (dist <= eps) & (s > 0) & (s < 1)
    convex = t > 1e-9 * np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    return np.where(straight, 2, np.where(convex, 1, 0))


def remerge(store: FaceStore, tree: Tree, src_group: np.ndarray, eps: float, min_area: float = 1e-12,
            rounds: int = 8, shown: np.ndarray | None = None) -> dict:
    """Merge fragments of ``tree`` in place (new fragments appended to ``store``; the tree's
    lists rewritten). ``src_group[s]``: merge group of source face s. ``shown``: the attribute
    channels that must be affine over a union (default all; bake.bsp.stage leaves out the corner
    ids of its tape, which are not attributes). Returns counts."""
    lists = [(tree.on_ids, tree.on_node, tree.on_side.astype(np.int64), 0),
             (tree.pre_ids, tree.pre_node, np.zeros(len(tree.pre_ids), np.int64), 1),
             (tree.suf_ids, tree.suf_node, np.zeros(len(tree.suf_ids), np.int64), 2)]
    ids = np.concatenate([x[0] for x in lists])
    if len(ids) < 2:
        return {"remerged": 0, "remerge_saved": 0, "remerge_reverted": 0}
    node = np.concatenate([x[1] for x in lists])
    side = np.concatenate([x[2] for x in lists])
    kind = np.concatenate([np.full(len(x[0]), x[3], np.int64) for x in lists])
    seq = np.concatenate([np.arange(len(x[0])) for x in lists])  # place in its list (draw order)
    unit = np.unique(np.stack([kind, node, side], 1), axis=0, return_inverse=True)[1].ravel()
    # only fragments with a partner of nearly the same normal in their unit and group can join:
    # a cheap key (normal rounded to 0.02) finds them, the exact tests below decide
    # (a coplanar group lies in its node's plane already)
    nk = np.round(store.planes_of(ids)[:, :3] / 0.02).astype(np.int64) * (kind != 0)[:, None]
    key = np.concatenate([unit[:, None], src_group[store.src[ids]][:, None], nk], 1)
    bucket = np.unique(key, axis=0, return_inverse=True)[1].ravel()
    deg = store.degenerate_of(ids)
    lonely = np.bincount(bucket)[bucket] < 2
    w = _Working(store, ids, seq, alive=~deg & ~lonely)
    for _ in range(rounds):
        if not _join_round(w, bucket, eps, min_area, shown):
            break
    bad_units = _failed_units(store, w, unit, kind, eps)
    reverted = np.flatnonzero(np.isin(unit, bad_units)) if bad_units else np.zeros(0, np.int64)
    n_new, saved = _write_back(store, tree, w, ids, node, side, kind, seq, reverted)
    return {"remerged": n_new, "remerge_saved": saved, "remerge_reverted": int(len(bad_units))}


class _Working:
    """Working copies of every fragment of the tree's lists (``member``: the working fragment each
    original entry now stands for; ``place``: where a fragment is drawn in its list)."""

    def __init__(self, store: FaceStore, ids: np.ndarray, seq: np.ndarray, alive: np.ndarray):
        self.F = len(ids)
        self.K = store.K
        self.pos = store.pos[ids].copy()
        self.attr = store.attr[ids].copy()
        self.vid = store.vid[ids].copy()
        self.cnt = store.count[ids].copy()
        self.src = store.src[ids].copy()
        self.plane = store.planes_of(ids)
        self.place = seq.copy()
        self.member = np.arange(self.F)  # entry -> working fragment
        self.alive = alive
        self.merged_any = np.zeros(self.F, bool)

    def widen(self, K2: int) -> None:
        """Room for ``K2`` corners per fragment (padded with each fragment's first corner)."""
        if K2 > self.K:
            pad = K2 - self.K
            self.pos = np.concatenate([self.pos, np.repeat(self.pos[:, :1], pad, 1)], 1)
            self.attr = np.concatenate([self.attr, np.repeat(self.attr[:, :1], pad, 1)], 1)
            self.vid = np.concatenate([self.vid, np.repeat(self.vid[:, :1], pad, 1)], 1)
            self.K = K2


def _join_round(w: _Working, bucket: np.ndarray, eps: float, min_area: float,
                shown: np.ndarray | None) -> bool:
    """One round of joints: pairs of live fragments sharing an edge in one bucket, kept where
    the union is coplanar, convex, drops a corner and keeps every shown attribute affine; one
    joint per fragment (mutual proposals); the union's fan must be sound. False when nothing
    joined (no further round can)."""
    live = np.flatnonzero(w.alive)
    if len(live) < 2:
        return False
    pairs = _shared_edges(w, live, bucket)
    if pairs is None:
        return False
    fp, fq, kp, kq = pairs
    pos, cnt, plane = w.pos, w.cnt, w.plane
    n = plane[fp, :3]
    # coplanar within the tolerance, both ways
    dq = np.abs(np.einsum("fkc,fc->fk", pos[fq], plane[fp, :3]) - plane[fp, 3:4]).max(1)
    dp = np.abs(np.einsum("fkc,fc->fk", pos[fp], plane[fq, :3]) - plane[fq, 3:4]).max(1)
    ok = (dq <= eps) & (dp <= eps) & (np.einsum("ij,ij->i", plane[fp, :3], plane[fq, :3]) > 0.999)
    # joint corners: p's edge kp is A->B, q's edge kq is B->A
    cp, cq = cnt[fp], cnt[fq]
    A_ = pos[fp, kp]
    B_ = pos[fp, (kp + 1) % cp]
    ta = _turn_ok(n, pos[fp, (kp - 1) % cp], A_, pos[fq, (kq + 2) % cq], eps)
    tb = _turn_ok(n, pos[fq, (kq - 1) % cq], B_, pos[fp, (kp + 2) % cp], eps)
    ok &= (ta > 0) & (tb > 0) & ((ta == 2) | (tb == 2))  # convex, and at least one corner goes
    seen = w.attr if shown is None else w.attr[..., shown]
    if seen.shape[2]:
        ok &= _affine_ok(pos, seen, cnt, plane, fp, fq, 1e-6)
    fp, fq, kp, kq, ta, tb = fp[ok], fq[ok], kp[ok], kq[ok], ta[ok], tb[ok]
    if len(fp) == 0:
        return False
    # one joint per fragment per round: each proposes its longest joinable edge; mutual ones join
    mutual = mutual_proposals(pos, cnt, fp, kp, fq, w.F)
    fp, fq, kp, kq, ta, tb = fp[mutual], fq[mutual], kp[mutual], kq[mutual], ta[mutual], tb[mutual]
    if len(fp) == 0:
        return False
    fp, fq, sf, sk, newc = _unions(w, fp, fq, kp, kq, ta, tb, min_area)
    if len(fp) == 0:
        return False
    w.pos[fp], w.attr[fp], w.vid[fp] = w.pos[sf, sk], w.attr[sf, sk], w.vid[sf, sk]
    w.cnt[fp] = newc
    w.place[fp] = np.maximum(w.place[fp], w.place[fq])
    w.alive[fq] = False
    tgt = np.arange(w.F)
    tgt[fq] = fp
    w.member = tgt[w.member]
    w.merged_any[fp] = True
    return True


def _shared_edges(w: _Working, live: np.ndarray, bucket: np.ndarray):
    """Pairs of live fragments of one bucket that share an edge (its corners the same to 1e-9),
    run in opposite directions by exactly these two: (fragment p, fragment q, p's edge, q's
    edge), or None."""
    K, q = w.K, 1e9
    k = np.arange(K)[None, :]
    valid = k < w.cnt[live][:, None]
    nxt = (k + 1) % w.cnt[live][:, None]
    pid = np.round(w.pos[live] * q).astype(np.int64)
    _, pid = np.unique(pid.reshape(-1, 3), axis=0, return_inverse=True)
    pid = pid.reshape(len(live), K)
    a, b = pid, np.take_along_axis(pid, nxt, 1)
    fw = np.broadcast_to(np.arange(len(live))[:, None], a.shape)
    kk = np.broadcast_to(k, a.shape)
    e_f, e_k, e_a, e_b = fw[valid], kk[valid], a[valid], b[valid]
    e_u = bucket[live][e_f]
    lo, hi = np.minimum(e_a, e_b), np.maximum(e_a, e_b)
    o = np.lexsort((hi, lo, e_u))
    lo, hi, e_u, e_f, e_k, e_a = lo[o], hi[o], e_u[o], e_f[o], e_k[o], e_a[o]
    same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1]) & (e_u[1:] == e_u[:-1])
    first = np.flatnonzero(same)
    if len(first) == 0:
        return None
    pair_ok = ~np.isin(first + 1, first) & ~np.isin(first - 1, first)
    i, j = first[pair_ok], first[pair_ok] + 1
    ok = (e_f[i] != e_f[j]) & (e_a[i] != e_a[j])
    i, j = i[ok], j[ok]
    if len(i) == 0:
        return None
    return live[e_f[i]], live[e_f[j]], e_k[i], e_k[j]


def _unions(w: _Working, fp, fq, kp, kq, ta, tb, min_area: float):
    """The union loops of the joints (straight joint corners dropped) whose fan triangles all face
    the plane's way, untilted and not collapsed: (p, q, slot fragment, slot corner, corners)."""
    # the union loop: p from B round to A (cp corners), then q after A up to before B
    cp, cq = w.cnt[fp], w.cnt[fq]
    newc = cp + cq - 2
    w.widen(max(w.K, int(newc.max())))
    K = w.K
    t, sf, sk = union_slots(fp, kp, fq, kq, cp, cq, K)
    # drop the straight joint corners: B is slot 0, A is slot cp - 1
    drop = ((t == 0) & (tb == 2)[:, None]) | ((t == cp[:, None] - 1) & (ta == 2)[:, None])
    keep = (t < newc[:, None]) & ~drop
    newc = keep.sum(1)
    order = np.argsort(~keep, axis=1, kind="stable")
    sf = np.take_along_axis(sf, order, 1)
    sk = np.take_along_axis(sk, order, 1)
    padm = t >= newc[:, None]
    sf = np.where(padm, sf[:, :1], sf)
    sk = np.where(padm, sk[:, :1], sk)
    P2 = w.pos[sf, sk]
    # every fan triangle of the union must face the plane's way, untilted and not collapsed
    # (a corner just inside the tolerance could make a sliver flip)
    e1 = P2[:, 1:-1] - P2[:, :1]
    e2 = P2[:, 2:] - P2[:, :1]
    tn = np.cross(e1, e2)
    ln = np.linalg.norm(tn, axis=2)
    cos = np.einsum("fkc,fc->fk", tn, w.plane[fp, :3]) / np.maximum(ln, 1e-300)
    real = np.arange(K - 2)[None, :] < (newc - 2)[:, None]
    good = ~(real & ((cos < MIN_COS_TILT) | (0.5 * ln <= min_area))).any(1)
    return fp[good], fq[good], sf[good], sk[good], newc[good]


def _failed_units(store: FaceStore, w: _Working, unit: np.ndarray, kind: np.ndarray, eps: float) -> list:
    """The prefix/suffix lists (units) that changed and whose new order fails the "may hide"
    check, or are too long to check (they are reverted)."""
    changed_units = np.unique(unit[w.merged_any[w.member]])
    bad_units = []
    for u in changed_units:
        e = np.flatnonzero(unit == u)
        if kind[e[0]] == 0:
            continue
        if len(e) > CHECK_MAX:
            bad_units.append(u)
            continue
        frag = np.unique(w.member[e])
        frag = frag[np.argsort(w.place[frag], kind="stable")]
        # the new fragments, temporarily in the store, in draw order
        tmp = store.append(w.pos[frag], w.attr[frag], w.vid[frag], w.cnt[frag], w.src[frag])
        M = hide_graph(store, tmp[None], eps)[0]
        store.n -= len(tmp)
        if np.triu(M, 1).any():
            bad_units.append(u)
    return bad_units


def _write_back(store: FaceStore, tree: Tree, w: _Working, ids, node, side, kind, seq,
                reverted: np.ndarray) -> tuple[int, int]:
    """Every entry's working fragment (merged ones appended to the store; the ``reverted``
    entries their original fragment) into the tree's lists, in draw order. Returns (fragments
    appended, triangles saved)."""
    F, member, place, merged_any = w.F, w.member, w.place, w.merged_any
    final = member.copy()
    final[reverted] = -1 - reverted  # stays the original fragment
    out_ids = np.empty(F, np.int64)
    orig = final < 0
    out_ids[orig] = ids[-1 - final[orig]]
    changed = ~orig & (merged_any[np.maximum(final, 0)])
    single = ~orig & ~changed
    out_ids[single] = ids[final[single]]
    # one output entry per working fragment: the entry at the fragment's place
    wf = np.unique(final[changed])
    new_ids = store.append(w.pos[wf], w.attr[wf], w.vid[wf], w.cnt[wf], w.src[wf])
    lookup = np.full(F, -1, np.int64)
    lookup[wf] = new_ids
    out_ids[changed] = lookup[final[changed]]
    # drop duplicate entries of a merged fragment: keep the entry at its (later) place
    keep_entry = np.ones(F, bool)
    ce = np.flatnonzero(changed)
    keep_entry[ce] = seq[ce] == place[final[ce]]
    out_place = np.where(changed, place[np.maximum(final, 0)], seq)
    saved = int((store.count[ids] - 2).sum() - (store.count[out_ids[keep_entry]] - 2).sum())
    # rebuild the tree's lists in draw order
    res = []
    for lst in (0, 1, 2):
        sel = np.flatnonzero((kind == lst) & keep_entry)
        o = np.lexsort((out_place[sel], node[sel]))
        res.append((out_ids[sel][o], node[sel][o], side[sel][o]))
    tree.on_ids, tree.on_node, tree.on_side = res[0][0], res[0][1], res[0][2].astype(np.int8)
    tree.pre_ids, tree.pre_node = res[1][0], res[1][1]
    tree.suf_ids, tree.suf_node = res[2][0], res[2][1]
    return int(len(wf)), saved
