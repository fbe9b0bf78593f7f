"""Trimming crossing geometry (``mesh.hidden.trim``): cut each triangle that passes through
another along the other's plane, so the hidden stage can keep the pieces that show and drop the
ones inside (docs/hidden.md, "Trimming").

The crossing pairs are ``bake.bsp.crossing.crossing_pairs`` (the BSP's own test: two triangles
whose interiors pass through each other, neighbours across an edge excluded). Each triangle of a
pair is cut by the plane of each triangle it crosses, in rounds (round ``j``: every triangle's
``j``-th plane, all triangles at once), but only the pieces where the crossing is: a piece is cut
when its chord along the plane overlaps the stretch of that line inside the other triangle (a
piece the crossing does not enter does not cross it, so cutting it would only add pieces, and the
kept ones would need joining again). Each piece is a convex polygon kept as barycentric
coordinates of its source triangle, so positions, UVs and vertex colours of the new corners are
interpolated from the source's. A corner within ``eps`` of a plane is on it (no sliver); a new
corner is computed from the corner on the plane's positive side towards the negative one, so the
two pieces on either side of a cut get bit-identical corners. Pieces are fanned into triangles.

The hidden stage decides on the cut scene; a source whose pieces are all kept is written whole
again (:func:`merge_back`), so trimming changes only triangles that lost a piece. Those keep their
pieces or the outline of them (:func:`outline`), or are written whole again when that takes more
than ``trim_most`` triangles (:func:`whole_again`).
"""

from __future__ import annotations

import numpy as np

from ...geometry import corners_at, edge_crossings
from ...scene import Scene
from ..clean import unique_rows


def crossing(scene: Scene, tol: float) -> np.ndarray:
    from ...bsp.crossing import crossing_pairs

    return crossing_pairs(scene.positions, scene.triangles, tol)


def _clip(bary: np.ndarray, count: np.ndarray, d: np.ndarray, positive: bool) -> tuple[np.ndarray, np.ndarray]:
    """The part of each convex polygon (``bary`` (n, K, 3), ``count``) where the signed distance
    ``d`` (n, K) is >= 0 (``positive``) or <= 0: Sutherland-Hodgman, all polygons at once."""
    n, K = d.shape
    # the new corner from the positive corner towards the negative one (the same for both sides)
    valid, cross, ia, ib, t = edge_crossings(d, count)
    inside = valid & ((d if positive else -d) >= 0)
    ba, bb = corners_at(bary, ia), corners_at(bary, ib)
    new = ba + t[..., None] * (bb - ba)
    # slots: corner i (if inside), then the crossing on edge i (if any)
    slots = np.stack([bary, new], axis=2).reshape(n, 2 * K, 3)
    keep = np.stack([inside, cross], axis=2).reshape(n, 2 * K)
    order = np.argsort(~keep, axis=1, kind="stable")
    out = np.take_along_axis(slots, order[..., None], axis=1)[:, :K]
    cnt = keep.sum(axis=1)
    return out, np.minimum(cnt, K)


def _interval(pts: np.ndarray, d: np.ndarray, valid: np.ndarray, u: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The extent, along ``u``, of where each convex polygon (corners ``pts`` (n, K, 3), signed
    distances ``d`` (n, K) to a plane, ``valid`` (n, K)) meets the plane: ``(lo, hi)``, lo > hi
    where it does not."""
    valid, cross, ia, ib, t = edge_crossings(d, valid.sum(axis=1))
    pa = corners_at(pts, ia)
    x = np.where(cross[..., None], pa + t[..., None] * (corners_at(pts, ib) - pa), pts)
    on = valid & ((d == 0) | cross)
    tx = np.einsum("nkx,nx->nk", x, u)
    lo = np.where(on, tx, np.inf).min(axis=1)
    hi = np.where(on, tx, -np.inf).max(axis=1)
    return lo, hi


def _chord_meets(pos: np.ndarray, d: np.ndarray, count: np.ndarray, other: np.ndarray, n_src: np.ndarray,
                 off_src: np.ndarray, n_other: np.ndarray, eps: float) -> np.ndarray:
    """(n,) bool: whether the chord of each piece (corners ``pos``, distances ``d`` to the other
    triangle's plane) along the line where the source's plane meets the other's overlaps, by more
    than ``eps``, the stretch of that line inside the other triangle ``other`` (n, 3, 3)."""
    u = np.cross(n_src, n_other)
    un = np.linalg.norm(u, axis=1)
    K = d.shape[1]
    valid = np.arange(K)[None, :] < count[:, None]
    plo, phi = _interval(pos, d, valid, u)
    dq = np.einsum("nkx,nx->nk", other, n_src) - off_src[:, None]
    dq[np.abs(dq) < eps] = 0.0
    qlo, qhi = _interval(other, dq, np.ones(dq.shape, bool), u)
    parallel = un < 1e-9
    return parallel | (np.minimum(phi, qhi) - np.maximum(plo, qlo) > eps * un)


def cut(scene: Scene, pairs: np.ndarray, eps: float) -> dict:
    """The pieces of the crossing triangles: ``src`` (F,) source triangle, ``bary`` (F, 3, 3)
    barycentric corners of each piece's fan triangles (already fanned)."""
    T = scene.n_triangles
    both = np.concatenate([pairs, pairs[:, ::-1]])
    both = both[np.lexsort((both[:, 1], both[:, 0]))]
    tri, plane_of = both[:, 0], both[:, 1]
    start = np.searchsorted(tri, tri, side="left")
    rank = np.arange(len(tri)) - start
    kmax = int(rank.max()) + 1 if len(rank) else 0
    corners = scene.triangle_vertices()
    n = np.cross(corners[:, 1] - corners[:, 0], corners[:, 2] - corners[:, 0])
    n = n / np.maximum(np.linalg.norm(n, axis=1, keepdims=True), 1e-300)
    off = np.einsum("ij,ij->i", n, corners[:, 0])
    cut_tris = np.unique(tri)
    # the pieces' corners, as wide as the piece with the most needs (a triangle crossed by hundreds
    # of others is cut by hundreds of planes, but each piece keeps a few corners)
    K = 4
    bary = np.zeros((len(cut_tris), K, 3))
    bary[:, :3] = np.eye(3)
    count = np.full(len(cut_tris), 3, np.int64)
    src = cut_tris.copy()
    plane_table = np.full((T, max(kmax, 1)), -1, np.int64)
    plane_table[tri, rank] = plane_of
    for j in range(kmax):
        p = plane_table[src, j]
        act = np.flatnonzero(p >= 0)
        if len(act) == 0:
            continue
        if int(count[act].max()) + 1 > K:  # a cut adds at most one corner
            bary = np.concatenate([bary, np.zeros((len(bary), int(count[act].max()) + 1 - K, 3))], axis=1)
            K = bary.shape[1]
        pos = np.einsum("nkc,ncx->nkx", bary[act], corners[src[act]])
        d = np.einsum("nkx,nx->nk", pos, n[p[act]]) - off[p[act]][:, None]
        d[np.abs(d) < eps] = 0.0
        valid = np.arange(K)[None, :] < count[act][:, None]
        dv = np.where(valid, d, 0.0)
        straddle = (dv.max(axis=1) > 0) & (dv.min(axis=1) < 0)
        s = act[straddle]
        if len(s) == 0:
            continue
        # only where the piece's chord on the plane meets the other triangle: a piece the
        # crossing segment does not enter does not cross it (the cut is clipped to the crossing)
        meets = _chord_meets(pos[straddle], d[straddle], count[s], corners[p[s]], n[src[s]], off[src[s]],
                             n[p[s]], eps)
        s = s[meets]
        if len(s) == 0:
            continue
        ds = d[straddle][meets]
        fb, fc = _clip(bary[s], count[s], ds, True)
        bb, bc = _clip(bary[s], count[s], ds, False)
        bary[s], count[s] = fb, fc
        bary = np.concatenate([bary, bb])
        count = np.concatenate([count, bc])
        src = np.concatenate([src, src[s]])
    # fan each piece: (0, i, i + 1)
    i = np.arange(1, K - 1)
    fan = (i[None, :] < (count - 1)[:, None])
    piece, corner = np.nonzero(fan)
    tri_bary = np.stack([bary[piece, 0], bary[piece, corner + 1], bary[piece, corner + 2]], axis=1)
    return {"src": src[piece], "bary": tri_bary, "cut": cut_tris, "pieces": int(len(src))}


def cut_scene(scene: Scene, pieces: dict, min_area: float) -> tuple[Scene, np.ndarray, int]:
    """The scene with every cut triangle replaced by its pieces' triangles (appended after the
    uncut ones, which keep their order), ``src`` (T1,) the source triangle of each, and the
    number of uncut ones."""
    T = scene.n_triangles
    cut_mask = np.zeros(T, bool)
    cut_mask[pieces["cut"]] = True
    keep = np.flatnonzero(~cut_mask)
    src_f, bary = pieces["src"], pieces["bary"]
    corners = scene.triangle_vertices()
    P = np.einsum("fkc,fcx->fkx", bary, corners[src_f])  # (F, 3, 3)
    area = 0.5 * np.linalg.norm(np.cross(P[:, 1] - P[:, 0], P[:, 2] - P[:, 0]), axis=1)
    ok = area > min_area
    src_f, bary, P = src_f[ok], bary[ok], P[ok]
    V = scene.n_vertices
    cols = [scene.positions, P.reshape(-1, 3)]
    if scene.vertex_colors is not None:
        vc = np.einsum("fkc,fcx->fkx", bary, scene.vertex_colors[scene.triangles[src_f]]).reshape(-1, 4)
        key = np.concatenate([np.concatenate(cols), np.concatenate([scene.vertex_colors, vc])], axis=1)
        allc = np.concatenate([scene.vertex_colors, vc])
    else:
        key = np.concatenate(cols)
        allc = None
    first, inv = unique_rows(key)
    allp = np.concatenate(cols)
    new_tris = inv[V:].reshape(-1, 3)
    src = np.concatenate([keep, src_f])

    def tsel(a, interp=False):
        if a is None:
            return None
        if interp:
            return np.concatenate([a[keep], np.einsum("fkc,fcx->fkx", bary, a[src_f])])
        return a[src]

    tp = scene.tri_polygon
    if tp is not None:
        hit = np.unique(tp[cut_mask & (tp >= 0)])
        tp = np.where(np.isin(tp, hit), -1, tp)
        tp = np.concatenate([tp[keep], np.full(len(src_f), -1, np.int64)])
    out = scene.replace(
        positions=np.ascontiguousarray(allp[first]),
        vertex_colors=None if allc is None else allc[first],
        triangles=np.concatenate([inv[scene.triangles[keep]], new_tris]),
        tri_material=scene.tri_material[src], tri_uvs=tsel(scene.tri_uvs, True), tri_polygon=tp,
        face_colors=tsel(scene.face_colors), face_albedo=tsel(scene.face_albedo),
        tri_lightmap_uvs=tsel(scene.tri_lightmap_uvs, True))
    return out, src, int(len(keep))


def merge_back(scene: Scene, cut: Scene, src: np.ndarray, n_uncut: int, keep_cut: np.ndarray
               ) -> tuple[Scene, np.ndarray, np.ndarray, dict]:
    """``(union scene, keep mask over it, source of each union triangle (-1: the scene's own), counts)``: the union of ``scene``'s triangles and the
    cut scene's pieces (its triangles from ``n_uncut`` on); a source whose pieces are all kept is
    kept whole (its pieces not), one that lost a piece keeps its kept pieces."""
    T = scene.n_triangles
    pieces = np.arange(len(src)) >= n_uncut
    cut_src = np.zeros(T, bool)
    cut_src[src[pieces]] = True
    kept_pieces = np.bincount(src[pieces & keep_cut], minlength=T)
    all_pieces = np.bincount(src[pieces], minlength=T)
    whole = cut_src & (kept_pieces == all_pieces)
    keep_orig = np.zeros(T, bool)
    keep_orig[src[~pieces]] = keep_cut[~pieces]
    keep_orig |= whole
    piece_ids = np.flatnonzero(pieces)
    keep_piece = keep_cut[piece_ids] & ~whole[src[piece_ids]]
    # the union: the scene's vertices and triangles, then the cut scene's pieces
    V = scene.n_vertices
    allp = np.concatenate([scene.positions, cut.positions])
    allc = None if scene.vertex_colors is None else np.concatenate([scene.vertex_colors, cut.vertex_colors])
    first, inv = unique_rows(allp if allc is None else np.concatenate([allp, allc], axis=1))

    def cat(a, b):
        return None if a is None or b is None else np.concatenate([a, b[piece_ids]])

    tp = scene.tri_polygon
    union = scene.replace(
        positions=np.ascontiguousarray(allp[first]), vertex_colors=None if allc is None else allc[first],
        triangles=np.concatenate([inv[scene.triangles], inv[V + cut.triangles[piece_ids]]]),
        tri_material=np.concatenate([scene.tri_material, cut.tri_material[piece_ids]]),
        tri_uvs=cat(scene.tri_uvs, cut.tri_uvs),
        tri_polygon=None if tp is None else np.concatenate([tp, np.full(len(piece_ids), -1, np.int64)]),
        face_colors=cat(scene.face_colors, cut.face_colors), face_albedo=cat(scene.face_albedo, cut.face_albedo),
        tri_lightmap_uvs=cat(scene.tri_lightmap_uvs, cut.tri_lightmap_uvs))
    keep = np.concatenate([keep_orig, keep_piece])
    source = np.concatenate([np.full(T, -1, np.int64), src[piece_ids]])
    info = {"triangles_cut": int(cut_src.sum()), "restored_whole": int(whole.sum()),
            "pieces": int(len(piece_ids)), "pieces_kept": int(keep_piece.sum()),
            "pieces_dropped": int((~keep_cut[piece_ids]).sum())}
    return union, keep, source, info


__all__ = ["crossing", "cut", "cut_scene", "merge_back", "outline", "whole_again"]


def outline(union: Scene, keep: np.ndarray, n_orig: int, source: np.ndarray, scale: float
            ) -> tuple[Scene, np.ndarray, int, np.ndarray]:
    """Redraw the kept pieces of each partly kept source as few triangles: the outline of the
    pieces (the edges only one kept piece of the source has), when it is one closed loop, with its
    straight-through corners left out, triangulated again (``bake.mesh.triangulate``: a fan where
    valid, ear clipping where not). ``source`` (T_union,) is each triangle's source (-1: not a
    piece). The pieces' edges are first cut at the corners of other pieces that lie on them (the
    T-junctions a cut clipped to its crossing leaves, :func:`_split_at_corners`), so the inner
    edges match. A redrawn outline may pass through a kept triangle that its pieces met only
    along a cut (both sides of that crossing show): the BSP cuts it there, which costs the tree
    fewer triangles than keeping the pieces does (docs/hidden.md, "Trimming"). Returns the scene
    with the new triangles appended, the keep mask over it (the pieces of a redrawn source
    dropped), how many sources were redrawn, and the source of each of its triangles (``source``
    and the new triangles' sources). All sources at once: the loops are walked by
    pointer jumping (list ranking), not one by one."""
    from ..triangulate import triangulate

    piece = (np.arange(union.n_triangles) >= n_orig) & keep
    ids = np.flatnonzero(piece)
    if len(ids) == 0:
        return union, keep, 0, source
    tri = union.triangles[ids]
    src = source[ids]
    # directed edges of the kept pieces; an edge both ways within one source is inside the region
    a = tri.ravel()
    b = np.roll(tri, -1, axis=1).ravel()
    s = np.repeat(src, 3)
    a, b, s = _split_at_corners(union.positions, a, b, s, tri, src, scale)
    Vn = union.n_vertices + 1
    fwd = (s * Vn + a) * Vn + b
    rev = (s * Vn + b) * Vn + a
    inner = np.isin(fwd, rev)
    a, b, s = a[~inner], b[~inner], s[~inner]
    E = len(a)
    # successor: the edge of the same source starting where this one ends
    start_key = s * Vn + a
    order = np.argsort(start_key, kind="stable")
    sk = start_key[order]
    dup = np.zeros(E, bool)
    dup[order[1:][sk[1:] == sk[:-1]]] = True
    dup[order[:-1][sk[1:] == sk[:-1]]] = True
    pos = np.searchsorted(sk, s * Vn + b)
    found = (pos < E) & (sk[np.minimum(pos, E - 1)] == s * Vn + b)
    succ = np.where(found, order[np.minimum(pos, E - 1)], -1)
    ok_src = np.ones(int(src.max()) + 1, bool)
    ok_src[s[dup | ~found]] = False  # a vertex with two ways on, or a loop that does not close
    # one loop per source: the smallest edge id reached by pointer jumping is the same for all
    succ_safe = np.where(succ >= 0, succ, np.arange(E))
    rep, p = np.arange(E), succ_safe.copy()
    for _ in range(int(np.ceil(np.log2(max(E, 2)))) + 1):
        rep = np.minimum(rep, rep[p])
        p = p[p]
    first_rep = np.full(len(ok_src), E, np.int64)
    np.minimum.at(first_rep, s, rep)
    ok_src[np.unique(s[rep != first_rep[s]])] = False
    # list ranking: steps from the loop's first edge (its successor chain cut before it)
    nxt = np.where(succ_safe == rep, -1, succ_safe)
    dist = np.where(nxt >= 0, 1, 0)
    p = nxt.copy()
    for _ in range(int(np.ceil(np.log2(max(E, 2)))) + 1):
        live = p >= 0
        dist = np.where(live, dist + dist[np.where(live, p, 0)], dist)
        p = np.where(live, p[np.maximum(p, 0)], -1)
    good = ok_src[s]
    if not good.any():  # no source's outline is one loop
        return union, keep, 0, source
    # order each source's loop: by source, then by distance to the loop's end (descending)
    o = np.lexsort((-dist[good], s[good]))
    loop_v, loop_s = a[good][o], s[good][o]
    # leave out corners the outline goes straight through
    P = union.positions
    starts = np.r_[0, np.flatnonzero(np.diff(loop_s)) + 1]
    sizes0 = np.diff(np.r_[starts, len(loop_s)])
    grp = np.repeat(np.arange(len(starts)), sizes0)
    local = np.arange(len(loop_s)) - starts[grp]
    prev = starts[grp] + (local - 1) % sizes0[grp]
    nextv = starts[grp] + (local + 1) % sizes0[grp]
    u = P[loop_v] - P[loop_v[prev]]
    w = P[loop_v[nextv]] - P[loop_v]
    straight = (np.linalg.norm(np.cross(u, w), axis=1) <= 1e-9 * np.linalg.norm(u, axis=1)
                * np.linalg.norm(w, axis=1) + 1e-18 * scale * scale) & (np.einsum("ij,ij->i", u, w) > 0)
    loop_v, grp = loop_v[~straight], grp[~straight]
    sizes = np.bincount(grp, minlength=len(starts))
    redraw_src = loop_s[starts]
    fewer = sizes - 2 < np.bincount(source[ids], minlength=int(source.max()) + 1)[redraw_src]
    fewer &= sizes >= 3
    sel = np.isin(grp, np.flatnonzero(fewer))
    if not fewer.any():
        return union, keep, 0, source
    sizes, loop_v, redraw_src = sizes[fewer], loop_v[sel], redraw_src[fewer]
    tr = triangulate(P, sizes, loop_v)
    new = loop_v[tr.corners]
    owner = redraw_src[tr.polygon]
    # the source's facing: flip any triangle turned against its pieces' normal
    pidx = np.flatnonzero(piece)
    first_piece = pidx[np.argsort(src, kind="stable")][np.searchsorted(np.sort(src), owner)]
    pt = P[union.triangles[first_piece]]
    pn = np.cross(pt[:, 1] - pt[:, 0], pt[:, 2] - pt[:, 0])
    nt = P[new]
    nn = np.cross(nt[:, 1] - nt[:, 0], nt[:, 2] - nt[:, 0])
    flip = np.einsum("ij,ij->i", pn, nn) < 0
    new[flip] = new[flip][:, ::-1]
    # attributes: a piece's per-triangle ones; per-corner UVs are re-interpolated by the caller
    rows = first_piece

    def add(a):
        return None if a is None else np.concatenate([a, a[rows]])

    out = union.replace(
        triangles=np.concatenate([union.triangles, new]), tri_material=add(union.tri_material),
        tri_uvs=None if union.tri_uvs is None else np.concatenate([union.tri_uvs, _corner_uvs(union, rows, new)]),
        tri_polygon=None if union.tri_polygon is None else np.concatenate(
            [union.tri_polygon, np.full(len(new), -1, np.int64)]),
        face_colors=add(union.face_colors), face_albedo=add(union.face_albedo),
        tri_lightmap_uvs=None if union.tri_lightmap_uvs is None else np.concatenate(
            [union.tri_lightmap_uvs, _corner_uvs(union, rows, new, "tri_lightmap_uvs")]))
    drop = np.isin(source, redraw_src) & piece
    keep2 = np.concatenate([keep & ~drop, np.ones(len(new), bool)])
    return out, keep2, int(len(redraw_src)), np.concatenate([source, owner])


def whole_again(keep: np.ndarray, n_orig: int, source: np.ndarray, most: int) -> tuple[np.ndarray, int]:
    """The keep mask with every partly kept source whose kept part takes more than ``most``
    triangles (its pieces or its redrawn outline) written whole again instead, and how many.
    ``source`` (T,) is each triangle's source (-1: not a piece). Whole, the source shows what its
    kept part showed and its hidden part stays hidden (as without trimming); the tree then cuts
    it where it crosses a kept triangle, into at most 3 triangles per plane."""
    mine = (np.arange(len(keep)) >= n_orig) & keep & (source >= 0)
    cost = np.bincount(source[mine], minlength=n_orig)
    back = np.flatnonzero(cost > most)
    keep = keep.copy()
    keep[back] = True
    keep[mine & np.isin(source, back)] = False
    return keep, int(len(back))


def _split_at_corners(P: np.ndarray, a: np.ndarray, b: np.ndarray, s: np.ndarray, tri: np.ndarray,
                      src: np.ndarray, scale: float) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The directed edges ``a -> b`` (of source ``s``) cut at every corner of a kept piece of the
    same source that lies inside them: a cut clipped to its crossing ends on an edge that the
    piece beyond it does not have a corner on (a T-junction), and the two pieces' edges match only
    once that edge is cut there too. All sources at once (edges x corners of the same source)."""
    sv = np.unique(np.stack([np.repeat(src, 3), tri.ravel()], axis=1), axis=0)  # (source, corner), sorted
    E = len(a)
    lo = np.searchsorted(sv[:, 0], s, side="left")
    hi = np.searchsorted(sv[:, 0], s, side="right")
    cnt = hi - lo
    e = np.repeat(np.arange(E), cnt)
    v = sv[np.repeat(lo, cnt) + (np.arange(len(e)) - np.repeat(np.cumsum(cnt) - cnt, cnt)), 1]
    ab = P[b[e]] - P[a[e]]
    av = P[v] - P[a[e]]
    L2 = np.einsum("ij,ij->i", ab, ab)
    t = np.einsum("ij,ij->i", av, ab)
    off = np.linalg.norm(np.cross(ab, av), axis=1)
    on = (v != a[e]) & (v != b[e]) & (t > 0) & (t < L2) & (off <= 1e-9 * L2 + 1e-18 * scale * scale)
    if not on.any():
        return a, b, s
    # each edge's corners in order along it: a, the corners inside, b
    ee = np.concatenate([np.arange(E), e[on], np.arange(E)])
    tt = np.concatenate([np.zeros(E), t[on] / L2[on], np.ones(E)])
    vv = np.concatenate([a, v[on], b])
    o = np.lexsort((tt, ee))
    ee, vv = ee[o], vv[o]
    step = ee[1:] == ee[:-1]
    return vv[:-1][step], vv[1:][step], s[ee[:-1][step]]


def _corner_uvs(union: Scene, rows: np.ndarray, new: np.ndarray, name: str = "tri_uvs") -> np.ndarray:
    """Per-corner UVs of new triangles on the plane of piece ``rows``: the affine map of the
    piece's corners to its UVs, applied to the new corners."""
    uv = getattr(union, name)[rows]  # (n, 3, 2)
    P = union.positions
    c = P[union.triangles[rows]]  # (n, 3, 3)
    e1, e2 = c[:, 1] - c[:, 0], c[:, 2] - c[:, 0]
    q = P[new] - c[:, None, 0]  # (n, 3, 3)
    d00 = np.einsum("ij,ij->i", e1, e1)
    d01 = np.einsum("ij,ij->i", e1, e2)
    d11 = np.einsum("ij,ij->i", e2, e2)
    den = d00 * d11 - d01 * d01
    den = np.where(den == 0, 1.0, den)
    q1 = np.einsum("ikj,ij->ik", q, e1)
    q2 = np.einsum("ikj,ij->ik", q, e2)
    v = (d11[:, None] * q1 - d01[:, None] * q2) / den[:, None]
    w = (d00[:, None] * q2 - d01[:, None] * q1) / den[:, None]
    return uv[:, None, 0] * (1 - v - w)[..., None] + uv[:, None, 1] * v[..., None] + uv[:, None, 2] * w[..., None]
