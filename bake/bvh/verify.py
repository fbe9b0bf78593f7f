"""Proof helpers: test rays, Embree (embreex) as an independent reference, and the comparison
used by the tests and the benchmark.

* The reference traversal must equal brute force over the same list triangles *exactly*
  (same ``t`` bit for bit; the same triangle unless two triangles tie at that ``t``).
* Against Embree (float32, a different intersection algorithm) a ray agrees when both miss or
  both hit within ``tol`` of each other. A ray that does not agree must be explained: Embree's
  answer lies between brute force over triangles shrunk and grown by ``eps`` (a distance, so a
  ray through an edge or a vertex may go either way), or the ray runs (nearly) in the plane of
  the triangle one of them hit. Unexplained rays are reported; the tests require none.
"""

from __future__ import annotations

import numpy as np

from .traverse import brute_force


def make_rays(tri: np.ndarray, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray, dict]:
    """``n`` rays (unit directions) for triangles ``(T,3,3)``: origins outside and inside the
    bounds, aimed at triangle interiors, exactly at edges and vertices, in-plane grazing rays,
    axis-aligned rays and random ones. Deterministic for a seed."""
    rng = np.random.default_rng(seed)
    P = tri.reshape(-1, 3)
    lo, hi = P.min(0), P.max(0)
    c = (lo + hi) / 2
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    T = len(tri)
    kinds = {"outside": 0.35, "inside": 0.2, "edge": 0.15, "vertex": 0.1, "in_plane": 0.1,
             "axis": 0.1}
    counts = {k: int(n * f) for k, f in kinds.items()}
    counts["outside"] += n - sum(counts.values())
    O, D = [], []

    def unit(v):
        return v / np.linalg.norm(v, axis=1, keepdims=True)

    def sphere(m):
        return unit(rng.normal(size=(m, 3)))

    def tri_points(m, mode):
        t = rng.integers(0, T, m)
        if mode == "interior":
            b = rng.dirichlet([1, 1, 1], m)
        elif mode == "edge":
            e = rng.random(m)
            b = np.zeros((m, 3))
            k = rng.integers(0, 3, m)
            b[np.arange(m), k] = e
            b[np.arange(m), (k + 1) % 3] = 1 - e
        else:
            b = np.zeros((m, 3))
            b[np.arange(m), rng.integers(0, 3, m)] = 1
        return np.einsum("mk,mkj->mj", b, tri[t]), t

    m = counts["outside"]
    o = c + sphere(m) * diag * rng.uniform(0.6, 2.0, (m, 1))
    tgt, _ = tri_points(m, "interior")
    O.append(o), D.append(unit(tgt - o))
    m = counts["inside"]
    O.append(lo + rng.random((m, 3)) * (hi - lo)), D.append(sphere(m))
    for kind in ("edge", "vertex"):
        m = counts[kind]
        tgt, _ = tri_points(m, kind)
        o = c + sphere(m) * diag * rng.uniform(0.6, 2.0, (m, 1))
        O.append(o), D.append(unit(tgt - o))
    m = counts["in_plane"]
    tgt, t = tri_points(m, "edge")
    nrm = np.cross(tri[t, 1] - tri[t, 0], tri[t, 2] - tri[t, 0])
    ok = np.linalg.norm(nrm, axis=1) > 0
    nrm[~ok] = [0, 0, 1]
    w = np.cross(nrm, sphere(m))  # a direction in the triangle's plane
    w[np.linalg.norm(w, axis=1) == 0] = [1, 0, 0]
    w = unit(w)
    O.append(tgt - w * diag * rng.uniform(0.1, 1.0, (m, 1))), D.append(w)
    m = counts["axis"]
    ax = rng.integers(0, 3, m)
    d = np.zeros((m, 3))
    d[np.arange(m), ax] = rng.choice([-1.0, 1.0], m)
    tgt, _ = tri_points(m, "interior")
    O.append(tgt - d * diag * rng.uniform(0.2, 1.5, (m, 1))), D.append(d)
    return np.concatenate(O), np.concatenate(D), counts


def embree(tri: np.ndarray, o: np.ndarray, d: np.ndarray, center: np.ndarray | None = None):
    """Closest hits from Embree (float32, coordinates relative to ``center``). Returns
    ``(t, index, u, v)`` with inf / -1 on a miss."""
    from embreex import mesh_construction, rtcore_scene

    center = tri.reshape(-1, 3).mean(0) if center is None else center
    sc = rtcore_scene.EmbreeScene()
    verts = np.ascontiguousarray((tri - center).astype(np.float32))
    mesh_construction.TriangleMesh(sc, verts)
    res = sc.run(np.ascontiguousarray((o - center).astype(np.float32)),
                 np.ascontiguousarray(d.astype(np.float32)), output=1)
    idx = res["primID"].astype(np.int64)
    t = np.where(idx >= 0, res["tfar"].astype(np.float64), np.inf)
    return t, idx, res["u"].astype(np.float64), res["v"].astype(np.float64)


def brute_force_margin(tri, o, d, eps: float, grow: bool):
    """Brute force over triangles grown (or shrunk) by the distance ``eps`` in their plane:
    barycentric b_i >= -eps/h_i (>= +eps/h_i), h_i the height over the edge opposite i."""
    o = np.asarray(o, np.float64)
    d = np.asarray(d, np.float64)
    v0 = tri[:, 0]
    e1 = tri[:, 1] - v0
    e2 = tri[:, 2] - v0
    a2 = np.linalg.norm(np.cross(e1, e2), axis=1)  # twice the area
    edge = np.stack([np.linalg.norm(tri[:, 2] - tri[:, 1], axis=1), np.linalg.norm(e2, axis=1),
                     np.linalg.norm(e1, axis=1)], 1)
    with np.errstate(divide="ignore", invalid="ignore"):
        mrg = np.where(a2[:, None] > 0, eps * edge / a2[:, None], 1.0)
    mrg = np.minimum(mrg, 1.0) * (-1 if grow else 1)
    R = len(o)
    best = np.full(R, np.inf)
    for r in range(R):
        dd, oo = d[r], o[r]
        p = np.cross(dd, e2)
        det = np.einsum("ij,ij->i", e1, p)
        with np.errstate(all="ignore"):
            inv = 1 / det
            s = oo - v0
            u = np.einsum("ij,ij->i", s, p) * inv
            q = np.cross(s, e1)
            v = (q @ dd) * inv
            t = np.einsum("ij,ij->i", e2, q) * inv
            ok = (np.abs(det) > 0) & (1 - u - v >= mrg[:, 0]) & (u >= mrg[:, 1]) & (v >= mrg[:, 2]) & (t > 0)
        if ok.any():
            best[r] = t[ok].min()
    return best


def compare_embree(tri, o, d, t_ours, idx_ours, *, scale: float, tol_rel: float = 1e-4,
                   eps_rel: float = 1e-4, parallel_cos: float = 1e-3) -> dict:
    """Agreement of our closest hits (``idx_ours`` indexes ``tri``) with Embree; see the module
    doc. Returns counts; ``unexplained`` must be 0."""
    te, ie, _, _ = embree(tri, o, d)
    with np.errstate(invalid="ignore"):
        return _compare(tri, o, d, t_ours, idx_ours, te, ie, scale, tol_rel, eps_rel, parallel_cos)


def _compare(tri, o, d, t_ours, idx_ours, te, ie, scale, tol_rel, eps_rel, parallel_cos):
    tol = tol_rel * scale
    both_miss = np.isinf(t_ours) & np.isinf(te)
    both_hit = np.isfinite(t_ours) & np.isfinite(te)
    agree = both_miss | (both_hit & (np.abs(t_ours - te) <= tol))
    bad = np.nonzero(~agree)[0]
    explained_edge = explained_plane = 0
    unexplained = []
    if len(bad):
        eps = eps_rel * scale
        tg = brute_force_margin(tri, o[bad], d[bad], eps, True)
        ts = brute_force_margin(tri, o[bad], d[bad], eps, False)
        for k, r in enumerate(bad):
            if tg[k] - tol <= te[r] <= ts[k] + tol or (np.isinf(te[r]) and np.isinf(ts[k])):
                explained_edge += 1
                continue
            cos = []
            for j in (idx_ours[r], ie[r]):
                if j >= 0:
                    n = np.cross(tri[j, 1] - tri[j, 0], tri[j, 2] - tri[j, 0])
                    nn = np.linalg.norm(n)
                    cos.append(abs(n @ d[r]) / (nn * np.linalg.norm(d[r])) if nn > 0 else 0.0)
            if cos and min(cos) < parallel_cos:
                explained_plane += 1
                continue
            unexplained.append(int(r))
    same_tri = both_hit & (idx_ours == ie)
    return {
        "rays": int(len(o)), "ours_hit": int(np.isfinite(t_ours).sum()),
        "embree_hit": int(np.isfinite(te).sum()), "agree": int(agree.sum()),
        "same_triangle": int(same_tri.sum()),
        "max_dt_agreeing": float(np.abs(t_ours - te)[both_hit & agree].max() / scale)
        if (both_hit & agree).any() else 0.0,
        "explained_edge_or_vertex": explained_edge, "explained_in_plane": explained_plane,
        "unexplained": len(unexplained), "unexplained_rays": unexplained[:10],
    }


def compare_brute(hits, tri_list: np.ndarray, o, d) -> dict:
    """The traversal against brute force over the list's own triangles in slot order (exact)."""
    bt, bi, bu, bv = brute_force(tri_list, o, d)
    same_t = np.array_equal(hits.t, bt)
    tie = np.ones(len(o), bool)
    differ = np.nonzero(hits.slot != bi)[0]
    if len(differ):
        # a different slot is fine only when it hits at exactly the same t (shared edges)
        for k, r in enumerate(differ):
            s = hits.slot[r]
            if s < 0 or bi[r] < 0:
                tie[r] = False
                continue
            t1, _, _, _ = brute_force(tri_list[s:s + 1], o[r:r + 1], d[r:r + 1])
            tie[r] = t1[0] == bt[r]
    return {"rays": int(len(o)), "t_equal": bool(same_t), "hits": int(np.isfinite(bt).sum()),
            "slot_differs": int(len(differ)), "slot_differs_not_tie": int((~tie).sum()),
            "u_v_equal_where_same_slot": bool(np.array_equal(
                hits.u[hits.slot == bi], np.where(bi >= 0, bu, 0.0)[hits.slot == bi]))}
