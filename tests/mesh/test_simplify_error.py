"""The simplify stage's measuring tools against independent references.

* distances: trimesh's own point-triangle closest point (``trimesh.triangles.closest_point``),
  evaluated brute force over every (point, triangle) pair of small meshes;
* flips: meshes whose orientation is known by construction (flat CAD-like panels
  retriangulated, a triangle folded over on purpose, coincident double-sided faces).
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from bake.mesh.simplify.error import (SurfaceIndex, flip_check, point_triangle_distance, reliable_normals,
                                      triangle_normals)
from bake.mesh.simplify.measure import hausdorff, surface_grid


def brute_distance(P: np.ndarray, V: np.ndarray, F: np.ndarray, chunk: int = 256) -> np.ndarray:
    """Exact distance from each point to the mesh: trimesh's closest point on every triangle."""
    tris = V[F]
    out = np.empty(len(P))
    for s in range(0, len(P), chunk):
        p = P[s:s + chunk]
        pp = np.repeat(p, len(F), axis=0)
        tt = np.tile(tris, (len(p), 1, 1))
        q = trimesh.triangles.closest_point(tt, pp)
        out[s:s + chunk] = np.linalg.norm(q - pp, axis=1).reshape(len(p), len(F)).min(axis=1)
    return out


def bumpy(sub: int, amp: float = 0.08) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=sub)
    V = np.asarray(m.vertices, np.float64)
    r = 1.0 + amp * np.sin(3 * V[:, 0]) * np.cos(4 * V[:, 1]) + 0.05 * np.sin(5 * V[:, 2])
    return V * r[:, None], np.asarray(m.faces, np.int64)


def grid(n: int, z: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A flat n x n quad grid in the plane z, normals +z."""
    x, y = np.meshgrid(np.linspace(0, 1, n + 1), np.linspace(0, 1, n + 1))
    V = np.stack([x.ravel(), y.ravel(), np.full(x.size, z)], axis=1)
    i = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = i[:-1, :-1].ravel(), i[:-1, 1:].ravel(), i[1:, 1:].ravel(), i[1:, :-1].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F


# --------------------------------------------------------------------------- distances
def test_index_distances_and_exact_are_exact():
    Va, Fa = bumpy(2)  # 320 triangles
    rng = np.random.default_rng(3)
    P = rng.normal(size=(600, 3)) * 0.7
    P = np.concatenate([P, Va[Fa].mean(axis=1)[:100] * 1.01])
    ref = brute_distance(P, Va, Fa)
    idx = SurfaceIndex(Va, Fa, seed=1)
    d, tri = idx.distance(P)
    np.testing.assert_allclose(d, ref, rtol=1e-10, atol=1e-12)  # every one (libigl's AABB tree)
    pt = Va[Fa[tri]]  # the triangle named is one at that distance
    np.testing.assert_allclose(point_triangle_distance(P, pt[:, 0], pt[:, 1], pt[:, 2])[0], ref,
                               rtol=1e-10, atol=1e-12)
    dq, tq, cp = idx.query(P)
    assert np.array_equal(dq, d) and np.array_equal(tq, tri)
    assert np.allclose(np.linalg.norm(cp - P, axis=1), d, rtol=1e-9, atol=1e-12)
    de, te = idx.exact(P, d)
    np.testing.assert_allclose(de, ref, rtol=1e-10, atol=1e-12)


def test_measured_max_is_exact_at_its_point_and_finds_the_peak():
    """The reported maxima are exact distances at points of the surfaces (brute force), at least
    the brute-force maximum over the grid's own points, and within 2% of a brute-force maximum over
    a much denser pattern (the refinement finds the peaks the grid straddles); the means are
    area-weighted means of the grid's cells (within 10% of a dense brute-force area-weighted mean,
    and not below it: a cell's corners average a distance that bends over the cell)."""
    Va, Fa = bumpy(3)  # 1280 triangles
    Vb, Fb = bumpy(1)  # 80 triangles, same shape, coarse
    h = hausdorff(Va, Fa, Vb, Fb, points=3000)
    assert h.max == pytest.approx(max(h.max_a_to_b, h.max_b_to_a), rel=1e-15)
    for d, (X, Y) in ((h.a_to_b, ((Va, Fa), (Vb, Fb))), (h.b_to_a, ((Vb, Fb), (Va, Fa)))):
        # the peaks are exact distances to the other surface, largest first
        np.testing.assert_allclose(d.top_dists, brute_distance(d.top_points, *Y), rtol=1e-9, atol=1e-12)
        assert d.top_dists[0] == pytest.approx(d.max, rel=1e-12) and np.all(np.diff(d.top_dists) <= 0)
        # the worst point lies on X
        assert brute_distance(d.worst[None], *X)[0] < 1e-12
        # every vertex is a grid point
        g = surface_grid(X[0], X[1], 3000)
        assert len(g.P) == d.grid_points
        assert np.linalg.norm(g.P[:, None] - X[0][None], axis=2).min(axis=0).max() == 0.0
        assert d.max >= brute_distance(g.P, *Y).max() * (1 - 1e-12)
        # a dense barycentric pattern on every triangle of X, brute force
        n = 24
        i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
        keep = i + j <= n
        bary = np.stack([1 - (i[keep] + j[keep]) / n, i[keep] / n, j[keep] / n], 1)
        dense = brute_distance(np.einsum("gk,tkd->tgd", bary, X[0][X[1]]).reshape(-1, 3), *Y)
        assert d.max >= 0.98 * dense.max()
        C = X[0][X[1]]
        area = 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1)
        dense_mean = float((dense.reshape(len(C), -1).mean(axis=1) * area).sum() / area.sum())
        assert 0.99 * dense_mean <= d.mean <= 1.1 * dense_mean


def test_verification_out_of_budget_reports_an_upper_bound():
    """Verification takes any upper bounds: given loose ones (the exact distances inflated by up
    to 2x, as candidate bounds are on soups of big overlapping triangles) it makes the max exact
    (brute force) with the default budget, and with a tiny budget stops early, says so, and
    reports a value that is still never below the true max."""
    from bake.mesh.simplify import error as E

    Va, Fa = bumpy(2)
    rng = np.random.default_rng(5)
    Q = rng.normal(size=(3000, 3)) * 0.8
    truth = brute_distance(Q, Va, Fa)
    idx = SurfaceIndex(Va, Fa, seed=3)
    loose = truth * (1.0 + rng.random(len(Q))) + 1e-9
    d = loose.copy()
    tops, exact = E._verify(Q, d, idx)
    assert exact
    assert d[tops[0]] == pytest.approx(truth.max(), rel=1e-12)
    assert (loose > truth.max()).sum() > 64  # more than one block was needed
    d = loose.copy()
    tops, exact = E._verify(Q, d, idx, budget=10)
    assert not exact
    assert d[tops[0]] >= truth.max() * (1 - 1e-12)  # an upper bound of the true max
    assert d[tops[0]] < loose.max()  # but the bounds did tighten: the loosest ones were verified


def test_near_chunks_equal_one_query():
    """Chunked ball queries give the same pairs as one query (balls of every size)."""
    Va, Fa = bumpy(2)
    idx = SurfaceIndex(Va, Fa, seed=1)
    rng = np.random.default_rng(8)
    P = rng.normal(size=(500, 3))
    r = rng.random(500) ** 3 * 3.0
    rows, tris = idx.near(P, r)
    got = [(i0 + rr, tt) for i0, rr, tt in idx.near_chunks(P, r, max_pairs=2000)]
    rows2 = np.concatenate([g[0] for g in got])
    tris2 = np.concatenate([g[1] for g in got])
    assert len(got) > 3
    a = np.unique(np.stack([rows, tris], 1), axis=0)
    b = np.unique(np.stack([rows2, tris2], 1), axis=0)
    assert np.array_equal(a, b) and len(a) == len(rows)
    # every pair is a triangle whose bounding sphere is within reach; none missing (brute force)
    lb = np.linalg.norm(P[:, None, :] - idx.centers[None], axis=2) - idx.radii[None]
    ref = np.argwhere(lb <= r[:, None] * (1 + 1e-12))
    assert np.array_equal(np.unique(ref, axis=0), a)



@pytest.mark.parametrize("soup", [False, True])
def test_near_pairs_and_near_set_against_every_pair(soup):
    """near()'s pairs and near_set()'s triangles equal a test of every (point, triangle) pair, on a
    fine mesh and on a soup of big overlapping triangles (where most balls hold more than the
    K-nearest queries' 32 and 1,024 triangles and the dense paths take over)."""
    rng = np.random.default_rng(5)
    if soup:
        V = rng.normal(size=(6000, 3))
        F = rng.integers(0, len(V), size=(2000, 3))
    else:
        V, F = bumpy(3)
    idx = SurfaceIndex(V, F, seed=1)
    P = rng.normal(size=(300, 3)) * 1.5
    r = rng.random(300) ** 4 * 2.0
    lb = np.linalg.norm(P[:, None, :] - idx.centers[None], axis=2) - idx.radii[None]
    ref = np.argwhere(lb <= r[:, None] * (1 + 1e-12))
    rows, tris = idx.near(P, r)
    got = np.stack([rows, tris], 1)
    assert len(np.unique(got, axis=0)) == len(got)  # no pair twice
    assert np.array_equal(np.unique(got, axis=0), ref)
    assert np.array_equal(idx.near_set(P, r), np.unique(ref[:, 1]))
    # a point alone, and radii that reach nothing
    assert np.array_equal(idx.near_set(P[:1], r[:1]), np.unique(ref[ref[:, 0] == 0, 1]))
    assert len(idx.near_set(P + 100.0, np.zeros(len(P)))) == 0


@pytest.mark.parametrize("how", ["reversed", "shuffled"])
def test_callers_of_near_do_not_depend_on_its_pair_order(monkeypatch, how):
    """near() lists its pairs in no promised order (the K-nearest queries', then the dense
    blocks'); its callers sort them. With the pairs handed back reversed or shuffled,
    ``exact`` (its fallback for points with no close candidate) and the stage's locks under
    flipped triangles (``_lock_under``) give the same arrays bit for bit."""
    from types import SimpleNamespace

    from scipy.spatial import cKDTree

    from bake.mesh.simplify import defects
    from bake.mesh.simplify import error as E

    Va, Fa = bumpy(5)  # more triangles than exact()'s brute-force path takes
    assert len(Fa) > E._EXACT_BRUTE
    rng = np.random.default_rng(21)
    Q = Va[rng.integers(0, len(Va), 400)] + rng.normal(scale=0.05, size=(400, 3))
    # a simplified mesh on a subset of the input's vertices (the library's kind of result)
    keep = np.flatnonzero(rng.random(len(Va)) < 0.25)
    hull = trimesh.convex.convex_hull(Va[keep])
    Vo = np.asarray(hull.vertices, np.float64)
    src = keep[cKDTree(Va[keep]).query(Vo)[1]]  # (the hull's corners are input vertices)
    assert np.array_equal(Va[src], Vo)
    Fo = np.asarray(hull.faces, np.int64)
    bad = np.zeros(len(Fo), bool)
    bad[::3] = True
    prep = SimpleNamespace(V=Va, F=Fa)
    out = SimpleNamespace(V=Vo, F=Fo, src_vertex=src, flipped=bad, new_nonmanifold=np.zeros(len(Fo), bool),
                          folded=None)

    def results():
        idx = SurfaceIndex(Va, Fa, seed=1)
        d, t = idx.exact(Q, 1.5 * idx.distance(Q)[0] + 0.01)
        return d, t, defects.lock_under(prep, out, SurfaceIndex(Va, Fa, seed=1), np.zeros(len(Va), bool))

    d0, t0, lock0 = results()
    near = SurfaceIndex.near
    calls = []

    def permuted(self, P, radius):
        rows, tris = near(self, P, radius)
        calls.append(len(rows))
        p = np.arange(len(rows))[::-1] if how == "reversed" else np.random.default_rng(len(calls)).permutation(len(rows))
        return rows[p], tris[p]
    monkeypatch.setattr(SurfaceIndex, "near", permuted)
    d1, t1, lock1 = results()
    assert len(calls) >= 2 and max(calls) > 100  # both callers went through near
    assert np.array_equal(d0, d1) and np.array_equal(t0, t1)
    assert lock0.any() and np.array_equal(lock0, lock1)


# --------------------------------------------------------------------------- flips
def test_flat_cad_panel_retriangulated_has_no_flips():
    """A flat panel cut into a fine grid, against the same panel triangulated as a fan from one
    corner, with slivers and a zero-area triangle on its border: no flips."""
    Va, Fa = grid(12)
    ia = SurfaceIndex(Va, Fa, scale=np.sqrt(2))
    # output: border vertices of the unit square fanned from corner 0 (collinear corners give
    # slivers and exactly-zero-area triangles)
    t = np.linspace(0, 1, 13)
    ring = np.concatenate([np.stack([t, 0 * t], 1), np.stack([0 * t[1:] + 1, t[1:]], 1),
                           np.stack([t[::-1][1:], 0 * t[1:] + 1], 1), np.stack([0 * t[1:-1], t[::-1][1:-1]], 1)])
    Vo = np.concatenate([ring, np.zeros((len(ring), 1))], axis=1)
    Fo = np.stack([np.zeros(len(ring) - 2, np.int64), np.arange(1, len(ring) - 1), np.arange(2, len(ring))], 1)
    res = flip_check(ia, Vo, Fo)
    assert res.unreliable.any()  # the zero-area triangles along the first edges
    assert not res.flipped.any()
    # the same panel re-cut along the other diagonals
    Fo2 = Fa.copy()
    n = 12 * 12
    quad = np.stack([Fa[:n, 0], Fa[:n, 1], Fa[:n, 2], Fa[n:, 2]], 1)
    Fo2 = np.concatenate([quad[:, [0, 1, 3]], quad[:, [1, 2, 3]]])
    assert not flip_check(ia, Va, Fo2).flipped.any()


def test_cad_box_with_fanned_faces_has_no_flips():
    box = trimesh.creation.box(extents=(2.0, 1.0, 0.5))
    fine = box.subdivide().subdivide()
    ia = SurfaceIndex(np.asarray(fine.vertices), np.asarray(fine.faces))
    V = np.asarray(box.vertices)
    F = np.asarray(box.faces)
    # every face of the box as the other diagonal pair: coplanar, fanned differently
    n = triangle_normals(V, F)
    pairs = {}
    for i, nn in enumerate(np.round(n, 6).tolist()):
        pairs.setdefault(tuple(nn), []).append(i)
    F2 = []
    for (i, j) in pairs.values():
        quad = list(dict.fromkeys(list(F[i]) + list(F[j])))  # 4 corners
        c = V[quad].mean(axis=0)
        nn = n[i]
        # order the corners around the face normal, then split on the other diagonal
        u = V[quad[0]] - c
        w = np.cross(nn, u)
        ang = np.arctan2((V[quad] - c) @ w, (V[quad] - c) @ u)
        q = np.asarray(quad)[np.argsort(ang)]
        F2 += [[q[1], q[2], q[3]], [q[1], q[3], q[0]]]
    F2 = np.asarray(F2)
    assert (np.einsum("ij,ij->i", triangle_normals(V, F2), V[F2].mean(axis=1)) > 0).all()  # outward by construction
    assert not flip_check(ia, V, F2).flipped.any()
    # and one face turned inside out is found, both of its triangles and nothing else
    F3 = F2.copy()
    F3[:2] = F3[:2, ::-1]
    res = flip_check(ia, V, F3)
    assert np.flatnonzero(res.flipped).tolist() == [0, 1]


def test_folded_triangle_is_detected():
    Va, Fa = bumpy(3)
    ia = SurfaceIndex(Va, Fa)
    Vo, Fo = bumpy(2)
    assert not flip_check(ia, Vo, Fo).flipped.any()
    # reverse one triangle's winding
    F1 = Fo.copy()
    F1[17] = F1[17, ::-1]
    assert np.flatnonzero(flip_check(ia, Vo, F1).flipped).tolist() == [17]
    # fold: move a vertex across the far edge of one of its triangles (point reflection
    # through that edge's midpoint), so that triangle lies over its neighbour, turned over
    # (independent check: on this star-shaped surface its normal now points inwards)
    V2 = Vo.copy()
    v = 5
    t = int(np.flatnonzero((Fo == v).any(axis=1))[0])
    a, b = [int(x) for x in Fo[t] if x != v]
    V2[v] = Vo[a] + Vo[b] - Vo[v]
    inward = np.einsum("ij,ij->i", triangle_normals(V2, Fo), V2[Fo].mean(axis=1)) < 0
    assert inward[t]
    res = flip_check(ia, V2, Fo)
    assert np.array_equal(res.flipped, inward)


def test_double_sided_faces_and_degenerate_input_are_not_flips():
    V, F = grid(4)
    # coincident opposite faces: both windings present in the original
    Fa = np.concatenate([F, F[:, ::-1]])
    ia = SurfaceIndex(V, Fa)
    assert not flip_check(ia, V, F).flipped.any()
    assert not flip_check(ia, V, F[:, ::-1]).flipped.any()
    # zero-area input triangles (a collinear triple) have no say
    Vz = np.concatenate([V, [[0.5, 0.5, 0.0], [0.5, 0.5, 0.0]]])
    Fz = np.concatenate([F, [[len(V), len(V) + 1, 0]]])
    rel = reliable_normals(Vz, Fz, np.sqrt(2))
    assert not rel[-1] and rel[:-1].all()


def test_recheck_measures_only_changed_triangles_and_agrees_with_a_full_check():
    Va, Fa = bumpy(3)
    ia = SurfaceIndex(Va, Fa)
    Vo, Fo = bumpy(2)
    first = flip_check(ia, Vo, Fo)
    V2 = Vo.copy()
    V2[[3, 40]] *= -0.2  # two vertices pulled through the centre: their triangles turn over
    again = flip_check(ia, V2, Fo, prev=first)
    full = flip_check(ia, V2, Fo)
    touched = np.isin(Fo, [3, 40]).any(axis=1)
    assert again.checked == int(touched.sum()) < len(Fo)
    assert np.array_equal(again.flipped, full.flipped) and again.flipped.any()
    assert np.array_equal(again.ref, full.ref) and np.array_equal(again.under, full.under)


def test_long_triangles_are_tiled_for_the_tree_and_distances_stay_exact():
    """The distance index cuts triangles far longer than most into pieces for libigl's tree
    (tile_long): the pieces cover each triangle exactly (areas add up, every piece inside its
    triangle), and distances and closest triangles are the brute force's over the whole ones."""
    from bake.mesh.simplify.error import tile_long, triangle_areas

    V, F = bumpy(2)
    # a fan of long slivers beside it, like a CAD cylinder's cap
    n = 40
    ang = np.linspace(0, 2 * np.pi, n, endpoint=False)
    ring = np.stack([3 + 2.5 * np.cos(ang), 2.5 * np.sin(ang), np.full(n, 0.3)], 1)
    Vf = np.concatenate([V, ring, [[3.0, 0.0, 0.3]]])
    c = len(Vf) - 1
    Ff = np.concatenate([F, np.stack([np.full(n, c), len(V) + np.arange(n), len(V) + (np.arange(n) + 1) % n], 1)])
    Vt, Ft, of = tile_long(Vf, Ff)
    assert of is not None and len(Ft) > len(Ff) and set(of[len(F):].tolist()) <= set(range(len(Ff)))
    np.testing.assert_allclose(np.bincount(of, weights=triangle_areas(Vt, Ft), minlength=len(Ff)),
                               triangle_areas(Vf, Ff), rtol=1e-12)
    assert (np.bincount(of, minlength=len(Ff))[:len(F)] == 1).all()  # the bumpy sphere's are whole
    P = np.random.default_rng(2).uniform(-1.5, 5.5, size=(400, 3))
    d, tri = SurfaceIndex(Vf, Ff).distance(P)
    np.testing.assert_allclose(d, brute_distance(P, Vf, Ff), atol=1e-12)
    np.testing.assert_allclose(brute_distance_to(P, Vf, Ff[tri]), d, atol=1e-12)


def brute_distance_to(P: np.ndarray, V: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Distance from each point to its own triangle (``tris[i]`` for ``P[i]``)."""
    q = trimesh.triangles.closest_point(V[tris], P)
    return np.linalg.norm(q - P, axis=1)


def test_recheck_pairs_again_only_what_a_move_can_change():
    """The second opinion's pairing of original triangles with output triangles carries on
    through re-checks: after a few vertices move, the pairings a moved triangle could change are
    made again, and every pairing and verdict is the full check's (many flips, so many pairings)."""
    Va, Fa = bumpy(3)
    ia = SurfaceIndex(Va, Fa)
    Vo, Fo = bumpy(2, amp=0.2)
    rng = np.random.default_rng(4)
    Vo = Vo.copy()
    Vo[rng.choice(len(Vo), 30, replace=False)] *= -0.3  # many triangles turned over
    first = flip_check(ia, Vo, Fo)
    assert first.flipped.sum() > 20
    for k in range(3):
        V2 = Vo.copy()
        V2[rng.choice(len(Vo), 5, replace=False)] *= 0.9
        again = flip_check(ia, V2, Fo, prev=first)
        full = flip_check(ia, V2, Fo)
        assert np.array_equal(again.flipped, full.flipped)
        # the pairings carried over are the full check's, but where its candidate search (the
        # KD-tree's nearest sample points, not every triangle) sees a moved triangle's samples
        # crowd out another: one of 1,280 here
        known = np.flatnonzero((again.voted >= 0) & (full.voted >= 0))
        assert len(known) > 1000
        assert np.mean(again.voted[known] == full.voted[known]) > 0.99
        first, Vo = again, V2


def test_suspect_between_two_sheets_is_judged_by_what_it_stands_for():
    """A triangle inside a thin slab, nearer its bottom sheet but standing for the finely cut
    top (the original triangles it is closest to face up, as it does): the first pass suspects
    it, the second opinion clears it. Turned over it faces the sheet it is nearest to, so the
    first pass clears it: between two opposite sheets either way is defensible, and only a
    triangle both views call flipped is flipped."""
    Vt, Ft = grid(20, z=0.01)  # top, normals +z, 800 triangles
    Vb, Fb = grid(1, z=-0.01)  # bottom, 2 triangles, turned to face -z
    V = np.concatenate([Vt, Vb])
    F = np.concatenate([Ft, Fb[:, ::-1] + len(Vt)])
    ia = SurfaceIndex(V, F)
    Vo, Fo = grid(1, z=-0.004)  # facing +z, 0.006 above the bottom, 0.014 below the top
    res = flip_check(ia, Vo, Fo, samples=8000)
    assert res.suspect.all() and not res.flipped.any()
    res = flip_check(ia, Vo, Fo[:, ::-1], samples=8000)
    assert not res.suspect.any() and not res.flipped.any()
