"""The proven upper bound of the simplify stage's error (``error_bound``, issue 19).

The bound of a grid cell is the largest value over the cell of the lower envelope of three
affine functions (the distances to the triangles closest to its corners, interpolated): a small
linear programme that bake solves in closed form (``envelope_bound``). Here it is compared with
scipy's LP solver; the bound a certification proves is compared with a brute-force dense
measurement that shares no code with bake's (every distance from simplify_reference's own
point-triangle distance over every triangle); and on the CSG model at 2%, where the sampled
measure was 7.6% low in the original -> simplified direction, the stage's figure is compared
with the independent reference.
"""

from __future__ import annotations

import numpy as np
import pytest

from bake.config import SimplifyConfig
from bake.mesh.simplify import inputs
from bake.mesh.simplify import stage as S
from bake.mesh.simplify.error import SurfaceIndex
from bake.mesh.simplify.measure import _cell_bounds, certify, directed, envelope_bound, surface_grid

from conftest import corpus_path
from meshgen import heightfield
from simplify_reference import hausdorff_reference, point_triangle_distance


def _lp_optimum(D: np.ndarray) -> float:
    """max z subject to z <= sum_i lam_i D[i, j] for every j, lam >= 0, sum lam = 1 (scipy)."""
    from scipy.optimize import linprog

    A = np.hstack([-D.T, np.ones((3, 1))])
    r = linprog([0, 0, 0, -1], A_ub=A, b_ub=np.zeros(3), A_eq=[[1, 1, 1, 0]], b_eq=[1],
                bounds=[(0, None)] * 3 + [(None, None)], method="highs")
    assert r.status == 0
    return -r.fun


def test_envelope_bound_is_the_linear_programme_optimum():
    rng = np.random.default_rng(7)
    D = rng.random((400, 3, 3))
    D[::4, :, 2] = D[::4, :, 1]  # two functions the same (two corners share a closest triangle)
    D[1::4] = D[1::4, :, :1]  # one function three times
    D[2::4, 1] = D[2::4, 0]  # two corners with equal values
    got = envelope_bound(D)
    want = np.array([_lp_optimum(d) for d in D])
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-12)
    # it is the largest value of the envelope: dense barycentric samples stay below and reach it
    u = rng.random((50_000, 3))
    u /= u.sum(axis=1, keepdims=True)
    for d, b in zip(D[:40], got[:40]):
        vals = (u @ d).min(axis=1)
        assert vals.max() <= b + 1e-12
        assert vals.max() >= b - 0.02


def _dense_max(X, Y, n: int, seed: int) -> float:
    """Brute force: every vertex of X and ``n`` area-weighted random points on X, each against
    every triangle of Y with the reference's own point-triangle distance."""
    V, F = X
    C = V[F]
    area = 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1)
    rng = np.random.default_rng(seed)
    t = rng.choice(len(F), n, p=area / area.sum())
    r1, r2 = rng.random(n), rng.random(n)
    s = np.sqrt(r1)
    P = (1 - s)[:, None] * C[t, 0] + (s * (1 - r2))[:, None] * C[t, 1] + (s * r2)[:, None] * C[t, 2]
    P = np.concatenate([V[np.unique(F)], P])
    T = Y[0][Y[1]]
    return max(float(point_triangle_distance(p, T).min()) for p in P)


def _bumpy_sphere(sub: int = 3):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=sub)
    V = np.asarray(m.vertices, np.float64)
    rng = np.random.default_rng(3)
    V *= (1 + 0.04 * rng.standard_normal(len(V)))[:, None]
    return V, np.asarray(m.faces, np.int64)


def _other_surface(V: np.ndarray, F: np.ndarray, seed: int = 11):
    """Another bumpy surface over the same sphere, with holes (a third of its triangles): cells
    whose corners are closest to different triangles, far from some of them."""
    rng = np.random.default_rng(seed)
    Vo = V * (1 + 0.05 * rng.standard_normal(len(V)))[:, None]
    return Vo, F[np.sort(rng.permutation(len(F))[: len(F) // 3])]


def _near_surface(V: np.ndarray, F: np.ndarray, seed: int = 11):
    """The same sphere with its vertices moved by about 0.3%: distances small against the grid's
    cells, so their bounds need cuts to come within 2%."""
    rng = np.random.default_rng(seed)
    return V * (1 + 0.003 * rng.standard_normal(len(V)))[:, None], F


def _cell_samples(C: np.ndarray, k: int = 8) -> np.ndarray:
    """Points of a barycentric grid (k parts per side) on each cell ``C`` (s, 3, 3): (s, m, 3)."""
    i, j = np.meshgrid(np.arange(k + 1), np.arange(k + 1), indexing="ij")
    ok = i + j <= k
    w = np.stack([i[ok], j[ok], k - i[ok] - j[ok]], axis=1) / k
    return np.einsum("mc,scd->smd", w, C)


def test_each_cell_bound_holds_over_its_cell():
    """Every cell's bound (the three-triangle envelope) against the distance at 45 points of the
    cell, brute force over every triangle of the other mesh (the reference's own distance); and
    no looser than the plain Lipschitz bound (largest corner distance plus the cell's size)."""
    V, F = _bumpy_sphere()
    rng = np.random.default_rng(11)
    Vo, Fo = _other_surface(V, F)
    ib = SurfaceIndex(Vo, Fo)
    d = directed(ib, surface_grid(V, F, 2000), rounds=3)
    st = d.state
    cells = np.arange(len(st["cells"]))
    b = _cell_bounds(st, ib, cells)
    pick = rng.choice(len(cells), 300, replace=False)
    C = st["P"][st["cells"][pick]]
    T = Vo[Fo]
    for c, bound, pts in zip(C, b[pick], _cell_samples(C)):
        got = max(float(point_triangle_distance(p, T).min()) for p in pts)
        assert got <= bound * (1 + 1e-9) + 1e-12, (got, bound)
        corner = max(float(point_triangle_distance(p, T).min()) for p in c)
        size = max(np.linalg.norm(c[0] - c[1]), np.linalg.norm(c[1] - c[2]), np.linalg.norm(c[2] - c[0]))
        assert bound <= corner + size + 1e-12


def test_cut_cells_still_cover_the_surface():
    """After the certification's cuts, the cells on each triangle of X add up to its area (no
    child dropped, none twice)."""
    V, F = _bumpy_sphere()
    Vo, Fo = _near_surface(V, F)
    d = directed(SurfaceIndex(Vo, Fo), surface_grid(V, F, 3000))
    c = certify(d, 1.02, 50_000)
    assert c.certification["cells_cut"] > 1000
    st = c.state
    P, cells = st["P"], st["cells"]
    a = 0.5 * np.linalg.norm(np.cross(P[cells[:, 1]] - P[cells[:, 0]], P[cells[:, 2]] - P[cells[:, 0]]), axis=1)
    per = np.bincount(st["ctri"], weights=a, minlength=len(F))
    C = V[F]
    want = 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1)
    np.testing.assert_allclose(per, want, rtol=1e-9)


def test_the_proven_bound_holds_against_brute_force():
    """A bumpy sphere (320 triangles) simplified to 10% by the stage with ``error_bound =
    "both"``: in each direction the record's bound is at least the brute-force maximum over a
    dense sample, the sampled max is within 2% of that, and where the record says the bound is
    within 2% it is."""
    from bake.scene import make_scene

    V, F = _bumpy_sphere(2)
    sc = make_scene(V, F)
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.1, error_bound="both"))
    diag = sc.scale()
    A, B = (V, F), (out.positions, out.triangles)
    acc = rec.accuracy
    for direction, X, Y in (("original_to_simplified", A, B), ("simplified_to_original", B, A)):
        dense = _dense_max(X, Y, 6_000, seed=1) / diag
        bound, mx = acc[f"hausdorff_bound_{direction}"], acc[f"hausdorff_max_{direction}"]
        assert dense <= bound * (1 + 1e-9), (direction, dense, bound)
        assert mx >= 0.98 * dense, (direction, mx, dense)
        # the sampled max is a real distance (its point lies on X, that far from Y): so where the
        # record says the bound is within 2% of it, it is within 2% of the true maximum
        worst = np.asarray(rec.details[f"worst_point_{direction}"])
        assert point_triangle_distance(worst, X[0][X[1]]).min() <= 1e-9 * diag
        assert point_triangle_distance(worst, Y[0][Y[1]]).min() / diag == pytest.approx(mx, rel=1e-9)
        if rec.details["error_bound"][direction]["within_share"]:
            assert bound <= 1.02 * mx * (1 + 1e-12)
    assert acc["hausdorff_bound"] == max(acc["hausdorff_bound_original_to_simplified"],
                                         acc["hausdorff_bound_simplified_to_original"])


def test_the_bound_is_proven_only_where_asked():
    from bake.scene import make_scene

    V, F = _bumpy_sphere(2)
    sc = make_scene(V, F)
    _, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.1))  # default: "original"
    acc = rec.accuracy
    assert "hausdorff_bound_original_to_simplified" in acc
    assert "hausdorff_bound_simplified_to_original" not in acc and "hausdorff_bound" not in acc
    assert "simplified_to_original" not in rec.details["error_bound"]
    _, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.1, error_bound="none"))
    assert not any(k.startswith("hausdorff_bound") for k in rec.accuracy)
    assert rec.details["error_bound"] is None


def test_a_bound_that_runs_out_of_points_is_still_a_bound():
    """With too few points to get within 2%, certify stops at its budget; what it reports still
    bounds the brute-force maximum, and is no tighter than going on. The measure it starts from
    is left as it was, so starting again from it gives the same answer."""
    V, F = _bumpy_sphere()
    Vo, Fo = _near_surface(V, F)
    d = directed(SurfaceIndex(Vo, Fo), surface_grid(V, F, 3000))
    D0, P0 = d.state["D"].copy(), d.state["P"].copy()
    short = certify(d, 1.02, 200)
    full = certify(d, 1.02, 10_000_000)
    assert 0 < short.certification["points"] <= 200 and short.certification["open_cells"] > 0
    assert full.certification["open_cells"] == 0
    dense = _dense_max((V, F), (Vo, Fo), 4000, seed=2)
    for c in (short, full):
        assert dense <= c.bound * (1 + 1e-9)
    assert full.bound <= short.bound
    assert full.bound <= 1.02 * full.max * (1 + 1e-12)
    np.testing.assert_array_equal(d.state["D"], D0)  # d itself is left as it was
    np.testing.assert_array_equal(d.state["P"], P0)
    again = certify(d, 1.02, 200)
    assert again.bound == short.bound and again.certification == short.certification


def test_a_floor_ends_the_cuts_where_the_error_is_zero():
    """A flat result on its flat input (the error is rounding): the cuts stop once no cell can
    hold more than the floor, instead of chasing 1.02 x 1e-16."""
    n = 21
    V, F = heightfield(n)
    # the same square in 2 triangles, cut along the diagonal the grid's cells cross
    Fo = np.array([[0, n * (n - 1), n - 1], [n * (n - 1), n * n - 1, n - 1]])
    d = directed(SurfaceIndex(V, Fo), surface_grid(V, F, 2000))
    c = certify(d, 1.02, 2_000_000, floor=1e-3)
    assert c.max < 1e-12
    assert c.certification["open_cells"] == 0 and c.bound <= 1e-3
    assert certify(d, 1.02, 20_000).certification["open_cells"] > 0  # without the floor it cannot finish


def test_the_bound_covers_what_a_sparse_sample_misses():
    """A flat square (2 triangles) over a height field with one narrow pit: the distance from the
    square peaks above the pit, inside a big triangle. A sparse grid without refinement misses
    it (its max is below the brute-force one near the pit); the bound over its cells, with no
    cell cut, is still above the brute-force max."""
    Vy, Fy = heightfield(41, lambda x, y: -0.3 * np.exp(-((x - 0.37) ** 2 + (y - 0.61) ** 2) / 0.004))
    Vx = np.array([[0.0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
    Fx = np.array([[0, 1, 2], [0, 2, 3]])
    g = surface_grid(Vx, Fx, 40)
    d = directed(SurfaceIndex(Vy, Fy), g, rounds=0)
    rng = np.random.default_rng(5)
    P = np.concatenate([rng.uniform([0.27, 0.51, 0], [0.47, 0.71, 0], (3000, 3)), Vx])
    T = Vy[Fy]
    dense = max(float(point_triangle_distance(p, T).min()) for p in P)
    assert d.max < 0.9 * dense  # the sample alone is low here ...
    c = certify(d, 1.02, 0)
    assert c.certification["cells_cut"] == 0
    assert c.bound >= dense  # ... and the bound is not
    full = certify(d, 1.02, 1_000_000)  # cutting down to it finds it
    assert full.max >= 0.98 * dense and full.bound <= 1.02 * full.max * (1 + 1e-12)


@pytest.mark.corpus
@pytest.mark.slow
def test_csg_model_at_two_percent_finds_the_peak_the_sample_missed(monkeypatch):
    """boolean.glb at 2%: the sampled measure put the original -> simplified max 7.6% below the
    independent one (a peak near the tip of a 1.0 x 0.022 sliver, between grid points). Proving
    the bound cuts down to it: the stage's figure is within 2% of the reference or above it."""
    from bake import pipeline

    sc = pipeline.run(pipeline.load_config_for(corpus_path("boolean_csg_slivers", "boolean.glb")),
                      until="clean").scene
    # The result this peak was found on (3,542 triangles): defects refused under a 5% ceiling, the
    # parts welded where they touch, as the stage had them then (the default meets the budget, and
    # parts that keep their own vertices back off to 2,020 triangles, whose sample finds its peak)
    real = inputs.parts
    monkeypatch.setattr(inputs, "parts", lambda F, n: real(F, n)[:2] + (False,))
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.02, defects="refuse", error_ceiling=0.05))
    assert out.n_triangles == 3542
    diag = sc.scale()
    ref = hausdorff_reference(sc.positions, sc.triangles, out.positions, out.triangles, samples=100_000, rounds=5)
    ours = rec.accuracy["hausdorff_max_original_to_simplified"] * diag
    assert ours >= 0.98 * ref.a_to_b.max, (ours, ref.a_to_b.max)
    log = rec.details["error_bound"]["original_to_simplified"]
    assert log["max_after"] > 1.05 * log["max_before"]  # the sample alone was low
    assert log["within_share"] and log["finished"]
    assert rec.accuracy["hausdorff_bound_original_to_simplified"] * diag >= ref.a_to_b.max * (1 - 1e-9)


def _slivers():
    """A fan of long thin triangles (needles: one short edge) and flat ones (caps: one long
    edge), wavy so the distances vary along them, with a few well-shaped triangles between."""
    n = 24
    t = np.linspace(0.0, 1.0, n + 1)
    top = np.stack([t, np.full_like(t, 0.04), 0.02 * np.sin(9 * t)], 1)
    bot = np.stack([t + 0.5 / n, np.zeros_like(t), 0.02 * np.cos(7 * t)], 1)
    V = np.concatenate([top, bot, [[0.5, 3.0, 0.1]]])
    F = [[i, n + 1 + i, i + 1] for i in range(n)] + [[i + 1, n + 1 + i, n + 2 + i] for i in range(n - 1)]
    F += [[i, i + 1, 2 * n + 2] for i in range(n)]  # needles up to the far apex
    # flat triangles under the strip: a corner just below each third bottom edge's middle
    caps = [0.5 * (bot[i] + bot[i + 1]) - [0.0, 0.006, 0.0] for i in range(0, n - 1, 3)]
    F += [[n + 2 + i, n + 1 + i, len(V) + k] for k, i in enumerate(range(0, n - 1, 3))]
    return np.concatenate([V, caps]), np.asarray(F, np.int64)


def test_long_edges_are_cut_and_short_ones_kept():
    """_split for the proven bound (``thin``) on cells of every shape: children tile their parent
    (inside it, their areas add up to its area), every child's longest edge is at most 0.8 of its
    parent's (the bound shrinks with the cell), and a cell gets four children only when its three
    edges are long (a needle three, a flat cell two): fewer points on thin triangles for the same
    shrinking. The measure's own cuts (not ``thin``) still cut every cell into four."""
    from bake.mesh.simplify.measure import _split

    V, F = _slivers()
    Vo, Fo = _other_surface(*_bumpy_sphere(2))
    d = directed(SurfaceIndex(Vo * 0.6, Fo), surface_grid(V, F, 0, spacing=1e9), rounds=0)
    st = {k: v for k, v in d.state.items() if not k.startswith("_")}
    P0, cells0 = st["P"].copy(), st["cells"].copy()
    sel = np.arange(len(cells0))
    four = {k: v for k, v in d.state.items() if not k.startswith("_")}
    _split(four, SurfaceIndex(Vo * 0.6, Fo), sel)
    assert len(four["cells"]) == 4 * len(cells0)
    new = _split(st, SurfaceIndex(Vo * 0.6, Fo), sel, thin=True)
    P, kids = st["P"], st["cells"]
    assert len(P) == len(P0) + len(new)
    np.testing.assert_array_equal(P[:len(P0)], P0)

    def longest(C):
        return np.max(np.linalg.norm(C - C[:, [1, 2, 0]], axis=2), axis=1)

    def area(C):
        return 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1)

    C0 = P0[cells0]
    e = np.sort(np.linalg.norm(C0 - C0[:, [1, 2, 0]], axis=2), axis=1)
    long_edges = (e >= 0.6 * e[:, 2:]).sum(axis=1)
    assert {1, 2, 3} <= set(long_edges.tolist())  # caps, needles and well-shaped cells
    # the children are appended in blocks; find each one's parent by containment
    Ck = P[kids]
    n_kids = np.zeros(len(cells0), np.int64)
    got_area = np.zeros(len(cells0))
    for ck, a in zip(Ck, area(Ck)):
        inside = []
        for p, cp in enumerate(C0):
            # barycentric coordinates of the child's centroid and corners in the parent's plane
            M = np.stack([cp[1] - cp[0], cp[2] - cp[0]], 1)
            uv = np.linalg.lstsq(M, (np.vstack([ck, ck.mean(0)]) - cp[0]).T, rcond=None)[0]
            res = np.linalg.norm(M @ uv - (np.vstack([ck, ck.mean(0)]) - cp[0]).T, axis=0)
            if (uv >= -1e-9).all() and (uv.sum(0) <= 1 + 1e-9).all() and (res <= 1e-9).all():
                inside.append(p)
        assert len(inside) == 1, inside
        p = inside[0]
        n_kids[p] += 1
        got_area[p] += a
        assert longest(ck[None])[0] <= 0.8 * longest(C0[p:p + 1])[0] * (1 + 1e-12)
    np.testing.assert_allclose(got_area, area(C0), rtol=1e-9)
    np.testing.assert_array_equal(n_kids, np.array([0, 2, 3, 4])[long_edges])


def test_the_bound_holds_on_slivers():
    """On a mesh of needles and flat triangles the certified bound still holds against brute
    force, and the cut cells still cover every triangle."""
    V, F = _slivers()
    Vo, Fo = V + np.array([0.0, 0.0, 0.001]) * np.sin(40 * V[:, :1]), F
    d = directed(SurfaceIndex(Vo, Fo), surface_grid(V, F, 400), rounds=4)
    c = certify(d, 1.02, 200_000)
    assert c.certification["cells_cut"] > 100 and c.certification["open_cells"] == 0
    dense = _dense_max((V, F), (Vo, Fo), 4000, seed=5)
    assert dense <= c.bound * (1 + 1e-9)
    assert c.max >= 0.98 * dense
    st = c.state
    P, cells = st["P"], st["cells"]
    a = 0.5 * np.linalg.norm(np.cross(P[cells[:, 1]] - P[cells[:, 0]], P[cells[:, 2]] - P[cells[:, 0]]), axis=1)
    C = V[F]
    want = 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1)
    np.testing.assert_allclose(np.bincount(st["ctri"], weights=a, minlength=len(F)), want, rtol=1e-9)
