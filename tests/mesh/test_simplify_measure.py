"""The simplify stage's error figure against an independent measurement (issue 19).

The reference (tests/mesh/simplify_reference.py) shares no code with bake's measure: MeshLab's
Hausdorff filter on every vertex, points along every edge and 150,000+ area-weighted points,
refined around its worst samples by cutting the triangles there finer and measuring every
corner again (MeshLab), six times. Each direction's maximum reported by bake must be within
2% of the reference's, both ways: not an under-estimate (as the stage's 0.159% against a true
0.199% was), and not an over-estimate unless it is a real distance the reference missed (its
point lies on the surface and is that far from the other one, brute force, checked here).
"""

from __future__ import annotations

import numpy as np
import pytest

from bake.config import SimplifyConfig
from bake.mesh.simplify import meshopt
from bake.mesh.simplify import stage as S
from bake.mesh.simplify.error import SurfaceIndex
from bake.mesh.simplify.measure import hausdorff, surface_grid

from conftest import corpus_path
from meshgen import heightfield
from simplify_reference import hausdorff_reference, point_triangle_distance

MODELS = {
    "bunny": ("stanford_bunny_res1_obj", "stanford-bunny.obj"),
    "spot": ("spot_triangulated", "spot", "spot_triangulated.obj"),
    "teapot": ("teapot_obj", "teapot.obj"),
    "boolean": ("boolean_csg_slivers", "boolean.glb"),  # CSG parts: sharp edges, slivers
    "strips": ("triangle_strips_scene", "mode5.gltf"),  # a third of its triangles are needles
}


def within(ours: float, ref: float, worst: np.ndarray, X, Y) -> None:
    """``ours`` is within 2% of ``ref``; or above it and a real distance: ``worst`` lies on X
    and is ``ours`` away from Y (brute force over every triangle)."""
    assert ours >= 0.98 * ref, (ours, ref)
    if ours > 1.02 * ref:
        assert point_triangle_distance(worst, X[0][X[1]]).min() <= 1e-9 * ours
        assert point_triangle_distance(worst, Y[0][Y[1]]).min() == pytest.approx(ours, rel=1e-9), (ours, ref)


def load(name: str):
    from bake import pipeline
    path = corpus_path(*MODELS[name])
    return pipeline.run(pipeline.load_config_for(path), until="clean").scene


def stage_against_reference(name: str, ratio: float):
    """The default stage on a corpus model at ``ratio``, and the independent measurement of its
    result: each direction's reported max must be within 2% of it (:func:`within`). Returns
    (scene, output, record, reference)."""
    sc = load(name)
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=ratio))
    diag = sc.scale()
    ref = hausdorff_reference(sc.positions, sc.triangles, out.positions, out.triangles, samples=150_000)
    acc = rec.accuracy
    A, B = (sc.positions, sc.triangles), (out.positions, out.triangles)
    within(acc["hausdorff_max_original_to_simplified"] * diag, ref.a_to_b.max,
           np.asarray(rec.details["worst_point_original_to_simplified"]), A, B)
    within(acc["hausdorff_max_simplified_to_original"] * diag, ref.b_to_a.max,
           np.asarray(rec.details["worst_point_simplified_to_original"]), B, A)
    return sc, out, rec, ref


def test_grid_holds_every_vertex_and_shares_edge_points():
    """Every vertex is a grid point; points along an edge shared by two triangles with different
    grid levels coincide exactly (one point, not two); cells cover the surface (their areas add
    up to the mesh's)."""
    import trimesh
    m = trimesh.creation.icosphere(subdivisions=2)
    V = np.asarray(m.vertices, np.float64)
    F = np.asarray(m.faces, np.int64)
    V[0] *= 3.0  # a few long triangles around one vertex: finer grids there than elsewhere
    g = surface_grid(V, F, 4000)
    assert len(np.unique(g.levels)) > 1
    assert np.linalg.norm(g.P[:, None] - V[None], axis=2).min(axis=0).max() == 0.0
    _, counts = np.unique(g.P, axis=0, return_counts=True)
    assert counts.max() == 1  # no point twice
    C = V[F]
    area = 0.5 * np.linalg.norm(np.cross(C[:, 1] - C[:, 0], C[:, 2] - C[:, 0]), axis=1).sum()
    assert g.cell_area.sum() == pytest.approx(area, rel=1e-9)
    assert abs(len(g.P) - 4000) < 0.6 * 4000


@pytest.mark.corpus
@pytest.mark.slow
@pytest.mark.parametrize("name,ratio", [("bunny", 0.1), ("bunny", 0.01), ("spot", 0.1), ("teapot", 0.02),
                                        ("boolean", 0.1)])
def test_measure_matches_the_independent_reference(name, ratio):
    sc = load(name)
    target = max(4, int(round(sc.n_triangles * ratio)))
    Fo, _ = meshopt.simplify(sc.positions, sc.triangles, target)
    h = hausdorff(sc.positions, sc.triangles, sc.positions, Fo,
                  index_a=SurfaceIndex(sc.positions, sc.triangles, corners=False, k=8))
    ref = hausdorff_reference(sc.positions, sc.triangles, sc.positions, Fo, samples=150_000)
    A, B = (sc.positions, sc.triangles), (sc.positions, Fo)
    within(h.max_a_to_b, ref.a_to_b.max, h.a_to_b.worst, A, B)
    within(h.max_b_to_a, ref.b_to_a.max, h.b_to_a.worst, B, A)


@pytest.mark.corpus
@pytest.mark.slow
@pytest.mark.parametrize("name,ratio", [("bunny", 0.1), ("bunny", 0.03), ("spot", 0.1), ("boolean", 0.1)])
def test_cells_left_uncut_hide_no_peak(name, ratio):
    """The measure cuts only the cells that may hold more than 80% of the largest exact distance
    so far (a convexity bound). The cells left uncut must not lower either direction's maximum
    by more than 0.5% against cutting every cell (a first version took the share of the largest
    *upper bound*, which hid the bunny's peak at 10%: 0.149% against 0.164%), and fewer points
    must be measured."""
    from bake.mesh.simplify.measure import directed
    sc = load(name)
    target = max(4, int(round(sc.n_triangles * ratio)))
    Fo, _ = meshopt.simplify(sc.positions, sc.triangles, target)
    ia = SurfaceIndex(sc.positions, sc.triangles, corners=False, k=8)
    ib = SurfaceIndex(sc.positions, Fo)
    ga = surface_grid(sc.positions, sc.triangles, 20000)
    gb = surface_grid(sc.positions, Fo, 20000, min_level=1)
    for idx, g, kw in ((ib, ga, dict(seeds=1024, straddling=True)), (ia, gb, dict(seeds=256))):
        cut = directed(idx, g, prune=True, **kw)
        full = directed(idx, g, prune=False, **kw)
        assert cut.max >= 0.995 * full.max, (cut.max, full.max)
        assert cut.refine_points < full.refine_points


@pytest.mark.corpus
@pytest.mark.slow
def test_needles_are_measured_and_bounded_within_two_percent():
    """The triangle-strip scene (2,786 triangles, a third of them needles: shortest edge under a
    tenth of the longest) at 50% with the default stage. When every cut made four children, the
    proven bound ran out of points (320,000) on the needles' cells without finishing, and the
    original -> simplified max it reported was 5.5% below the independent measurement. Cut
    along their long edges only, the bound finishes, holds the independent max, and the reported
    max is within 2% of it (both directions)."""
    sc, _, rec, ref = stage_against_reference("strips", 0.5)
    assert rec.accuracy["hausdorff_bound_original_to_simplified"] * sc.scale() >= ref.a_to_b.max * (1 - 1e-9)
    bound = rec.details["error_bound"]["original_to_simplified"]
    assert bound["finished"] and bound["within_share"], bound


@pytest.mark.corpus
@pytest.mark.slow
def test_stage_reports_what_the_reference_measures_and_says_it_is_sampled():
    """The bunny to 10% with the default stage: the figure in the record is within 2% of the
    independent measurement (was 0.159% reported as exact, 0.199% measured), and the record says
    what was sampled."""
    sc, out, rec, _ = stage_against_reference("bunny", 0.1)
    assert rec.details["hausdorff_max_exact"] is False
    sample = rec.details["error_sample"]
    assert sample["original_grid_points"] >= sc.n_vertices  # every vertex at least
    assert sample["simplified_grid_points"] > 4 * out.n_vertices  # vertices, edge midpoints and more
    assert sample["refinement_points"] > 0
    assert "sampled" in sample["max_is"]


@pytest.mark.corpus
@pytest.mark.slow
def test_refit_never_makes_a_cad_model_worse():
    """The CSG model (sharp edges, slivers) at 50%: the least-squares refit rounds its corners
    off, so the default stage must keep the unfitted result when the fit raises the max. Both
    results measured independently: the default's max is not above the fit-free one's (before
    the fix: 0.96% of the diagonal with the fit, 0.09% without), and the record says whether the
    fit was kept."""
    sc = load("boolean")
    diag = sc.scale()
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.5))
    raw, _ = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.5, fit_iterations=0))
    ref = hausdorff_reference(sc.positions, sc.triangles, out.positions, out.triangles, samples=100_000, rounds=4)
    ref_raw = hausdorff_reference(sc.positions, sc.triangles, raw.positions, raw.triangles, samples=100_000, rounds=4)
    assert ref.max <= 1.02 * ref_raw.max, (ref.max / diag, ref_raw.max / diag)
    assert "kept" in rec.details["fit"]
    assert rec.accuracy["hausdorff_max"] == pytest.approx(ref.max / diag, rel=0.02)


@pytest.mark.corpus
@pytest.mark.slow
def test_peak_round_puts_a_cut_off_feature_back():
    """The teapot at 10%: the library cuts the spout's tip off (0.988% of the diagonal, measured
    independently), which moving corners cannot undo; the peak round locks the input vertex there
    and simplifies again. Independent max below 0.7% (the stage before issue 19 reached 0.711%),
    and the record says the round was kept."""
    sc = load("teapot")
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.1))
    ref = hausdorff_reference(sc.positions, sc.triangles, out.positions, out.triangles, samples=100_000, rounds=4)
    assert ref.max / sc.scale() < 0.007, ref.max / sc.scale()
    assert rec.details["peak_rounds"][0]["kept"] is True
    assert rec.accuracy["hausdorff_max"] == pytest.approx(ref.max / sc.scale(), rel=0.02)



def _pitted_waves(k: int = 60, depth: float = 0.3, cell: tuple[int, int] = (40, 40)):
    """The square [-1, 1]^2 as a k x k grid of cells (two triangles each), dented by broad waves
    0.012 deep (z = -0.012 sin^2(3 pi x) sin^2(3 pi y): zero along x, y = +-1/3, ...) and one cell,
    beside such a zero line, replaced by a square pyramid pit ``depth`` deep (four triangles from
    the cell's edges down to its tip)."""
    g = np.linspace(-1.0, 1.0, k + 1)
    X, Y = np.meshgrid(g, g, indexing="ij")
    Z = -0.012 * np.sin(3 * np.pi * X) ** 2 * np.sin(3 * np.pi * Y) ** 2
    V = np.stack([X.ravel(), Y.ravel(), Z.ravel()], 1)
    idx = np.arange((k + 1) ** 2).reshape(k + 1, k + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    pit = cell[0] * k + cell[1]
    keep = np.arange(k * k) != pit
    F = np.concatenate([np.stack([a, b, c], 1)[keep], np.stack([a, c, d], 1)[keep]])
    ring = [a[pit], b[pit], c[pit], d[pit]]
    centre = V[ring].mean(axis=0)
    tip = len(V)
    V = np.vstack([V, centre - [0.0, 0.0, depth]])
    F = np.vstack([F, [[ring[i], ring[(i + 1) % 4], tip] for i in range(4)]])
    return V, F, centre


def test_peak_over_a_narrow_pit_between_the_simplified_sides_grid_points_is_found():
    """The original: a square with broad shallow waves and one narrow, deep pit; the simplified
    surface: the flat square as two triangles, its grid far coarser than the pit. Its farthest point
    from the original is above the pit's centre (the distance there computed by the independent
    reference), between grid points whose distances are lower than the waves': refinement that
    follows the largest grid distances (8 places here) goes to the waves and misses it. The measure
    also refines where the original's farthest points (the pit's tip) are closest to the simplified
    surface, and must find it within 2%."""
    Va, Fa, centre = _pitted_waves()
    Vb = np.array([[-1.0, -1.0, 0.0], [1.0, -1.0, 0.0], [1.0, 1.0, 0.0], [-1.0, 1.0, 0.0]])
    Fb = np.array([[0, 1, 2], [0, 2, 3]])
    top = np.array([centre[0], centre[1], 0.0])
    want = float(point_triangle_distance(top, Va[Fa]).min())  # the independent reference's
    assert want > 0.015  # nearly half the pit's width (1/30): its walls are steep; the waves give 0.012
    h = hausdorff(Va, Fa, Vb, Fb, points=2000, seeds=8)
    assert h.b_to_a.spacing > 2 / 30  # the grid is coarser than the pit
    assert 0.98 * want <= h.max_b_to_a <= want * (1 + 1e-9)
    assert h.max_a_to_b == pytest.approx(0.3, abs=1e-3)  # the pit's tip


def _distinct_top_reference(P: np.ndarray, d: np.ndarray, k: int, apart: float) -> list[int]:
    """The seeds computed from all 64 k largest distances at once (what _distinct_top did before
    it tried the largest 4 k first), walked one point at a time: in order of distance (ties in
    the order numpy's partition and the index give), the first point of each box of side
    ``apart``, up to k of them."""
    m = min(len(d), 64 * k)
    cand = np.argpartition(-d, m - 1)[:m] if m < len(d) else np.arange(len(d))
    seen, out = set(), []
    for i in sorted(cand.tolist(), key=lambda i: (-d[i], i)):
        box = tuple(np.floor(P[i] / apart).astype(np.int64).tolist())
        if box not in seen:
            seen.add(box)
            out.append(i)
            if len(out) == k:
                break
    return out


@pytest.mark.parametrize("seed", range(6))
def test_seeds_taken_from_the_largest_distances_first_are_the_defined_ones(seed):
    """_distinct_top tries the largest 4 k distances before the 64 k it is defined on; with
    heavy ties (a few distinct values, so ties straddle the 4 k boundary) and with spread-out
    values it must pick exactly the reference's points."""
    from bake.mesh.simplify.measure import _distinct_top

    rng = np.random.default_rng(seed)
    n = 3000
    P = rng.random((n, 3))
    for d in (rng.integers(0, 3, n).astype(np.float64), rng.random(n)):
        for k, apart in ((1, 0.5), (8, 0.25), (40, 0.1), (200, 0.05)):
            got = _distinct_top(P, d, k, apart).tolist()
            assert got == _distinct_top_reference(P, d, k, apart), (k, apart)


def test_past_its_cap_the_simplified_grid_cuts_every_triangle_twice():
    """The simplified side's grid: 12 points per triangle, capped at 4x error_samples; where the
    cap bites every triangle is cut into at least 16 cells (the bunny at 50%: 2.4 points per
    triangle under the cap left its maximum 6.1% low against the independent measurement).
    Outputs small enough for the cap not to bite keep the grid they had."""
    from bake.mesh.simplify import measure as M

    assert M.simplified_grid(2000, 20000) == (24000, M.MIN_LEVEL_SIMPLIFIED)
    assert M.simplified_grid(6666, 20000) == (79992, M.MIN_LEVEL_SIMPLIFIED)
    assert M.simplified_grid(34725, 20000) == (80000, 2)
    # on a uniform sheet of that size the levels jump (2 nodes per triangle at level 1, about 8
    # at level 2): under the cap alone the grid stays at level 1
    V, F = heightfield(132, lambda x, y: 0.02 * np.sin(9 * x) * np.cos(7 * y))
    n, level = M.simplified_grid(len(F), 20000)
    capped = M.surface_grid(V, F, n, min_level=M.MIN_LEVEL_SIMPLIFIED)
    g = M.surface_grid(V, F, n, min_level=level)
    assert len(capped.P) < 2.1 * len(F)
    assert len(g.P) >= 7 * len(F) and np.bincount(g.cell_tri, minlength=len(F)).min() >= 16
