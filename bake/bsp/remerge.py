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
    # working copies of every fragment (members: which original entries each stands for)
    F = len(ids)
    K = store.K
    pos = store.pos[ids].copy()
    attr = store.attr[ids].copy()
    vid = store.vid[ids].copy()
    cnt = store.count[ids].copy()
    src = store.src[ids].copy()
    plane = store.planes_of(ids)
    place = seq.copy()
    member = np.arange(F)  # entry -> working fragment
    alive = ~deg & ~lonely
    merged_any = np.zeros(F, bool)
    q = 1e9
    for _ in range(rounds):
        w = np.flatnonzero(alive)
        if len(w) < 2:
            break
        k = np.arange(K)[None, :]
        valid = k < cnt[w][:, None]
        nxt = (k + 1) % cnt[w][:, None]
        pid = np.round(pos[w] * q).astype(np.int64)
        _, pid = np.unique(pid.reshape(-1, 3), axis=0, return_inverse=True)
        pid = pid.reshape(len(w), K)
        a, b = pid, np.take_along_axis(pid, nxt, 1)
        fw = np.broadcast_to(np.arange(len(w))[:, None], a.shape)
        kk = np.broadcast_to(k, a.shape)
        e_f, e_k, e_a, e_b = fw[valid], kk[valid], a[valid], b[valid]
        e_u = bucket[w][e_f]
        lo, hi = np.minimum(e_a, e_b), np.maximum(e_a, e_b)
        o = np.lexsort((hi, lo, e_u))
        lo, hi, e_u, e_f, e_k, e_a = lo[o], hi[o], e_u[o], e_f[o], e_k[o], e_a[o]
        same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1]) & (e_u[1:] == e_u[:-1])
        first = np.flatnonzero(same)
        if len(first) == 0:
            break
        pair_ok = ~np.isin(first + 1, first) & ~np.isin(first - 1, first)
        i, j = first[pair_ok], first[pair_ok] + 1
        ok = (e_f[i] != e_f[j]) & (e_a[i] != e_a[j])
        i, j = i[ok], j[ok]
        if len(i) == 0:
            break
        fp, fq = w[e_f[i]], w[e_f[j]]
        kp, kq = e_k[i], e_k[j]
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
        seen = attr if shown is None else attr[..., shown]
        if seen.shape[2]:
            ok &= _affine_ok(pos, seen, cnt, plane, fp, fq, 1e-6)
        fp, fq, kp, kq, ta, tb = fp[ok], fq[ok], kp[ok], kq[ok], ta[ok], tb[ok]
        if len(fp) == 0:
            break
        # one joint per fragment per round: each proposes its longest joinable edge; mutual ones join
        mutual = mutual_proposals(pos, cnt, fp, kp, fq, F)
        fp, fq, kp, kq, ta, tb = fp[mutual], fq[mutual], kp[mutual], kq[mutual], ta[mutual], tb[mutual]
        if len(fp) == 0:
            break
        # the union loop: p from B round to A (cp corners), then q after A up to before B
        cp, cq = cnt[fp], cnt[fq]
        newc = cp + cq - 2
        K2 = max(K, int(newc.max()))
        if K2 > K:
            pad = K2 - K
            pos = np.concatenate([pos, np.repeat(pos[:, :1], pad, 1)], 1)
            attr = np.concatenate([attr, np.repeat(attr[:, :1], pad, 1)], 1)
            vid = np.concatenate([vid, np.repeat(vid[:, :1], pad, 1)], 1)
            K = K2
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
        P2 = pos[sf, sk]
        # every fan triangle of the union must face the plane's way, untilted and not collapsed
        # (a corner just inside the tolerance could make a sliver flip)
        e1 = P2[:, 1:-1] - P2[:, :1]
        e2 = P2[:, 2:] - P2[:, :1]
        tn = np.cross(e1, e2)
        ln = np.linalg.norm(tn, axis=2)
        cos = np.einsum("fkc,fc->fk", tn, plane[fp, :3]) / np.maximum(ln, 1e-300)
        real = np.arange(K - 2)[None, :] < (newc - 2)[:, None]
        good = ~(real & ((cos < MIN_COS_TILT) | (0.5 * ln <= min_area))).any(1)
        fp, fq, sf, sk, newc = fp[good], fq[good], sf[good], sk[good], newc[good]
        if len(fp) == 0:
            break
        pos[fp], attr[fp], vid[fp] = pos[sf, sk], attr[sf, sk], vid[sf, sk]
        cnt[fp] = newc
        place[fp] = np.maximum(place[fp], place[fq])
        alive[fq] = False
        tgt = np.arange(F)
        tgt[fq] = fp
        member = tgt[member]
        merged_any[fp] = True
    # ---- check the new order of every prefix/suffix list that changed; revert the ones that fail
    changed_units = np.unique(unit[merged_any[member]])
    reverted = np.zeros(0, np.int64)
    bad_units = []
    for u in changed_units:
        e = np.flatnonzero(unit == u)
        if kind[e[0]] == 0:
            continue
        if len(e) > CHECK_MAX:
            bad_units.append(u)
            continue
        frag = np.unique(member[e])
        frag = frag[np.argsort(place[frag], kind="stable")]
        # the new fragments, temporarily in the store, in draw order
        tmp = store.append(pos[frag], attr[frag], vid[frag], cnt[frag], src[frag])
        M = hide_graph(store, tmp[None], eps)[0]
        store.n -= len(tmp)
        if np.triu(M, 1).any():
            bad_units.append(u)
    if bad_units:
        bad = np.isin(unit, bad_units)
        reverted = np.flatnonzero(bad)
    # ---- write back: every entry's working fragment; merged ones appended to the store
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
    new_ids = store.append(pos[wf], attr[wf], vid[wf], cnt[wf], src[wf])
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
    return {"remerged": int(len(wf)), "remerge_saved": saved, "remerge_reverted": int(len(bad_units))}
