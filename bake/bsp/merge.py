"""Source faces: coplanar neighbouring triangles merged into convex polygons before the build.

A plane that crosses a quad made of two triangles cuts one polygon (+2 triangles) instead of up
to two triangles (+4). Two faces are merged when they share an edge (same positions, opposite
directions), have the same material, face colour and sidedness, lie in the same plane, their
union is strictly convex, and every per-corner attribute (UV, vertex colour) of one is what the
other's affine interpolation predicts — so interpolating along a cut edge of the merged polygon
gives exactly what the original triangles showed. Merging runs in rounds; in each round every
face proposes to its best partner and mutual proposals merge (array operations per round, never
a loop per face). A merged face that the tree never cuts is written back as its own original
triangles, so nothing changes for it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .split import face_planes


@dataclass
class SourceFaces:
    pos: np.ndarray  # (S, K, 3) padded corners (normalised coordinates)
    count: np.ndarray  # (S,)
    attr: np.ndarray  # (S, K, A)
    vid: np.ndarray  # (S, K) scene vertex of each corner
    tri_start: np.ndarray  # (S + 1,) CSR into tri_list
    tri_list: np.ndarray  # the scene triangles each source face stands for
    merged: int  # triangles absorbed into another face
    dropped: int = 0  # input triangles left out (collapsed to a line or point by rounding)
    kept_triangles: np.ndarray | None = None  # the scene triangles merged (not left out), in order
    n_input_corners: int = 0  # 3 x the triangles merged (the tape's first corner ids)


def merge_coplanar(pos_n: np.ndarray, tris: np.ndarray, attr: np.ndarray, group: np.ndarray,
                   eps: float, min_area: float, attr_tol: float = 1e-6, rounds: int = 24,
                   enabled: bool = True, seen: np.ndarray | None = None) -> SourceFaces:
    """Merge triangles ``tris`` (T, 3) over vertices ``pos_n`` (normalised) into convex polygons.

    ``attr`` (T, 3, A): per-corner attributes. ``group`` (T,): only faces with equal group ids
    merge (material, face colour and sidedness folded into one id). ``seen`` (T, A) bool: which
    attributes show on each triangle (UVs of an untextured material do not); only those must be
    affine over a merged polygon. Every attribute is still carried and interpolated."""
    T = len(tris)
    A = attr.shape[2]
    P = pos_n[tris]
    if T == 0 or not enabled:
        return _as_sources(P, np.full(T, 3), attr, tris.copy(), np.arange(T), 0)
    # exact-position ids for adjacency
    _, wid = np.unique(pos_n, axis=0, return_inverse=True)
    wid = wid.ravel()
    loops = wid[tris]  # (F, K) position ids, padded by repeating corner 0
    cnt = np.full(T, 3, np.int64)
    vid = tris.copy()
    cur_attr = attr.copy()
    # the copy the affinity test looks at: attributes that do not show are zeroed
    cur_chk = attr * (np.ones(attr.shape[::2], bool) if seen is None else seen)[:, None, :]
    cur_pos = P.copy()
    owner = np.arange(T)  # polygon each triangle belongs to (ids shrink as polygons merge)
    grp = np.asarray(group, np.int64).copy()
    plane, degen = face_planes(cur_pos, cnt, min_area)
    merged_total = 0
    for _ in range(rounds):
        F, K = loops.shape
        k = np.arange(K)[None, :]
        valid = k < cnt[:, None]
        nxt = (k + 1) % cnt[:, None]
        a = loops
        b = np.take_along_axis(loops, nxt, 1)
        f_idx = np.broadcast_to(np.arange(F)[:, None], (F, K))
        e_f, e_k, e_a, e_b = f_idx[valid], np.broadcast_to(k, (F, K))[valid], a[valid], b[valid]
        lo, hi = np.minimum(e_a, e_b), np.maximum(e_a, e_b)
        o = np.lexsort((hi, lo))
        lo, hi, e_f, e_k, e_a = lo[o], hi[o], e_f[o], e_k[o], e_a[o]
        same = (lo[1:] == lo[:-1]) & (hi[1:] == hi[:-1])
        # exactly two uses of the edge, opposite directions, two different faces
        first = np.flatnonzero(same)
        if len(first) == 0:
            break
        triple = np.zeros(len(lo) + 1, bool)
        triple[first[1:][first[1:] - 1 == first[:-1]]] = True  # edge used 3+ times
        pair_ok = ~triple[first] & ~np.isin(first + 1, first)
        i, j = first[pair_ok], first[pair_ok] + 1
        fp, fq = e_f[i], e_f[j]
        ok = (fp != fq) & (e_a[i] != e_a[j]) & (grp[fp] == grp[fq]) & ~degen[fp] & ~degen[fq]
        ok &= np.einsum("ij,ij->i", plane[fp, :3], plane[fq, :3]) >= 1.0 - 1e-6  # the corner test below decides
        i, j, fp, fq = i[ok], j[ok], fp[ok], fq[ok]
        if len(i) == 0:
            break
        kp, kq = e_k[i], e_k[j]
        # coplanar: every corner of q on p's plane and vice versa
        dq = np.abs(np.einsum("fkc,fc->fk", cur_pos[fq], plane[fp, :3]) - plane[fp, 3:4]).max(1)
        dp = np.abs(np.einsum("fkc,fc->fk", cur_pos[fp], plane[fq, :3]) - plane[fq, 3:4]).max(1)
        ok = (dq <= eps) & (dp <= eps)
        # strictly convex union: corners a and b of the shared edge stay convex
        ok &= _convex_join(cur_pos, cnt, plane, fp, kp, fq, kq)
        if A:
            ok &= _affine_ok(cur_pos, cur_chk, cnt, plane, fp, fq, attr_tol)
        i, j, fp, fq, kp, kq = i[ok], j[ok], fp[ok], fq[ok], kp[ok], kq[ok]
        if len(fp) == 0:
            break
        # mutual best proposals: each face proposes its longest mergeable edge
        mutual = mutual_proposals(cur_pos, cnt, fp, kp, fq, F)
        fp, fq, kp, kq = fp[mutual], fq[mutual], kp[mutual], kq[mutual]
        if len(fp) == 0:
            break
        both = np.concatenate([cur_attr, cur_chk], axis=2)
        loops, cnt, vid, both, cur_pos, owner, grp, plane, degen = _join(
            loops, cnt, vid, both, cur_pos, owner, grp, plane, degen, fp, kp, fq, kq)
        cur_attr, cur_chk = both[..., :A], both[..., A:]
        merged_total += len(fp)
    return _as_sources(cur_pos, cnt, cur_attr, vid, owner, merged_total)


def union_slots(fp, kp, fq, kq, cp, cq, K: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The corners of the unions of faces p and q joined along p's edge kp (a -> b), which is q's
    edge kq (b -> a): p's from b (kp + 1) round to a (cp of them), then q's after a (kq + 2) up to
    before b (cq - 2). Returns the slot numbers (1, K) and, per union and slot, the face and the
    corner it comes from (slots past cp + cq - 2 hold leftovers for the caller to mask)."""
    t = np.arange(K)[None, :]
    from_p = t < cp[:, None]
    ip = (kp[:, None] + 1 + t) % cp[:, None]
    iq = (kq[:, None] + 2 + (t - cp[:, None])) % cq[:, None]
    return t, np.where(from_p, fp[:, None], fq[:, None]), np.where(from_p, ip, iq)


def mutual_proposals(pos, cnt, fp, kp, fq, n_faces: int) -> np.ndarray:
    """Which candidate joints (p's edge kp shared with face q) to make in one round, at most one
    per face: every face proposes its longest candidate edge (ties: the lower partner), and a
    joint is made when both faces propose it. Returns a mask over the candidates."""
    length = np.linalg.norm(pos[fp, kp] - pos[fp, (kp + 1) % cnt[fp]], axis=1)
    cand_f = np.concatenate([fp, fq])
    cand_g = np.concatenate([fq, fp])
    cand_l = np.concatenate([length, length])
    cand_e = np.concatenate([np.arange(len(fp)), np.arange(len(fp))])
    oo = np.lexsort((cand_g, -cand_l, cand_f))
    firsts = np.ones(len(oo), bool)
    firsts[1:] = cand_f[oo][1:] != cand_f[oo][:-1]
    best_partner = np.full(n_faces, -1, np.int64)
    best_edge = np.full(n_faces, -1, np.int64)
    best_partner[cand_f[oo][firsts]] = cand_g[oo][firsts]
    best_edge[cand_f[oo][firsts]] = cand_e[oo][firsts]
    return (best_partner[fp] == fq) & (best_partner[fq] == fp) & (best_edge[fp] == np.arange(len(fp)))


def _convex_join(pos, cnt, plane, fp, kp, fq, kq, tol: float = 1e-9) -> np.ndarray:
    """p's edge kp is a->b, q's edge kq is b->a. The union is convex iff the turns at a
    (p's predecessor -> a -> q's successor) and at b (q's predecessor -> b -> p's successor)
    are strict left turns about the normal."""
    cp, cq = cnt[fp], cnt[fq]
    r = np.arange(len(fp))
    a = pos[fp, kp]
    b = pos[fp, (kp + 1) % cp]
    p_prev_a = pos[fp, (kp - 1) % cp]
    p_next_b = pos[fp, (kp + 2) % cp]
    q_next_a = pos[fq, (kq + 2) % cq]  # q: ..., b (kq), a (kq+1), next
    q_prev_b = pos[fq, (kq - 1) % cq]
    n = plane[fp, :3]
    e1, e2 = a - p_prev_a, q_next_a - a
    e3, e4 = b - q_prev_b, p_next_b - b
    ta = np.einsum("ij,ij->i", np.cross(e1, e2), n)
    tb = np.einsum("ij,ij->i", np.cross(e3, e4), n)
    la = np.linalg.norm(e1, axis=1) * np.linalg.norm(e2, axis=1)
    lb = np.linalg.norm(e3, axis=1) * np.linalg.norm(e4, axis=1)
    _ = r
    # sine of the turn above tol: no straight (collinear) corner is kept
    return (ta > tol * la) & (tb > tol * lb)


def _affine_ok(pos, attr, cnt, plane, fp, fq, tol) -> np.ndarray:
    """Every corner attribute of q equals p's affine interpolation there (and vice versa by
    symmetry of the test on the shared corners)."""
    p0, p1, p2 = pos[fp, 0], pos[fp, 1], pos[fp, 2]
    a0, a1, a2 = attr[fp, 0], attr[fp, 1], attr[fp, 2]
    n = plane[fp, :3]
    M = np.stack([p1 - p0, p2 - p0, n], 1)  # rows
    try:
        Minv = np.linalg.inv(M)
    except np.linalg.LinAlgError:
        return np.zeros(len(fp), bool)
    # attr(x) = a0 + [(x - p0) @ Minv] @ [a1 - a0, a2 - a0, 0]
    dA = np.stack([a1 - a0, a2 - a0, np.zeros_like(a0)], 1)  # (m, 3, A)
    K = pos.shape[1]
    x = pos[fq] - p0[:, None, :]  # (m, K, 3)
    coef = np.einsum("mkc,mcd->mkd", x, Minv)
    pred = a0[:, None, :] + np.einsum("mkd,mda->mka", coef, dA)
    err = np.abs(pred - attr[fq]).max(2)
    valid = np.arange(K)[None, :] < cnt[fq][:, None]
    return ~(np.where(valid, err, 0.0) > tol).any(1)


def _join(loops, cnt, vid, attr, pos, owner, grp, plane, degen, fp, kp, fq, kq):
    """Merge face q into face p for each pair; faces q disappear (ids are compacted)."""
    F, K = loops.shape
    cp, cq = cnt[fp], cnt[fq]
    newc = cp + cq - 2
    K2 = max(K, int(newc.max()))
    t, src_face, src_k = union_slots(fp, kp, fq, kq, cp, cq, K2)
    valid = t < newc[:, None]
    src_face = np.where(valid, src_face, fp[:, None])
    src_k = np.where(valid, src_k, ((kp + 1) % cp)[:, None])  # pad with corner 0 of the new loop

    def grow(x, fill):
        if K2 == K:
            return x
        pad = np.repeat(x[:, :1], K2 - K, 1) if fill is None else np.full((F, K2 - K) + x.shape[2:], fill, x.dtype)
        return np.concatenate([x, pad], 1)

    loops2, vid2, attr2, pos2 = grow(loops, None), grow(vid, None), grow(attr, None), grow(pos, None)
    new_loops = loops2[src_face, src_k]
    new_vid = vid2[src_face, src_k]
    new_attr = attr2[src_face, src_k]
    new_pos = pos2[src_face, src_k]
    loops2[fp], vid2[fp], attr2[fp], pos2[fp] = new_loops, new_vid, new_attr, new_pos
    cnt = cnt.copy()
    cnt[fp] = newc
    # re-pad every face by its corner 0
    kk = np.arange(K2)[None, :]
    pad = kk >= cnt[:, None]
    for arr in (loops2, vid2):
        arr[pad] = np.broadcast_to(arr[:, :1], arr.shape)[pad]
    attr2[pad] = np.broadcast_to(attr2[:, :1], attr2.shape)[pad]
    pos2[pad] = np.broadcast_to(pos2[:, :1], pos2.shape)[pad]
    # drop the absorbed faces, relabel owners
    target = np.arange(F)
    target[fq] = fp
    keep = np.ones(F, bool)
    keep[fq] = False
    new_id = np.cumsum(keep) - 1
    owner = new_id[target[owner]]
    plane2, degen2 = face_planes(pos2[keep], cnt[keep], 0.0)
    plane2[:, :3] = plane[keep, :3]  # keep the (identical within eps) plane of p
    plane2[:, 3] = np.einsum("ij,ij->i", plane2[:, :3],
                             (pos2[keep] * (kk < cnt[keep][:, None])[..., None]).sum(1) / cnt[keep][:, None])
    return (loops2[keep], cnt[keep], vid2[keep], attr2[keep], pos2[keep], owner, grp[keep], plane2,
            degen[keep])


def _as_sources(pos, cnt, attr, vid, owner, merged) -> SourceFaces:
    S = len(pos)
    order = np.argsort(owner, kind="stable")
    start = np.zeros(S + 1, np.int64)
    np.cumsum(np.bincount(owner, minlength=S), out=start[1:])
    return SourceFaces(pos=pos, count=cnt, attr=attr, vid=vid, tri_start=start, tri_list=order,
                       merged=int(merged))
