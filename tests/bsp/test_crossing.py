"""Parts that pass through each other (bake/bsp/crossing.py): the pairs it finds against a brute
force over every pair of triangles, and what the BSP stage says about them."""

from __future__ import annotations

import itertools

import numpy as np
import pytest

from bake import config
from bake.bsp import crossing
from bake.bsp.stage import stage
from bake.scene import make_scene

from .meshes import box, corpus_file, load_scene


def _rotation(seed: int) -> np.ndarray:
    q, _ = np.linalg.qr(np.random.default_rng(seed).normal(size=(3, 3)))
    return q * np.sign(np.linalg.det(q))


def _boxes(*specs, seed: int = 0):
    """Boxes (lo, hi) in one mesh, each with its own corners (not welded), turned together."""
    V, F = [], []
    for lo, hi in specs:
        v, f = box(lo, hi)
        F.append(f + sum(len(x) for x in V))
        V.append(v)
    return np.concatenate(V) @ _rotation(seed).T, np.concatenate(F)


def _segment_through(p, q, a, b, c) -> bool:
    """Reference: does the open segment pq pass through the open triangle abc? Solved for the
    segment's and the triangle's parameters (p + s (q - p) = a + u (b - a) + v (c - a))."""
    M = np.column_stack([q - p, a - b, a - c])
    if abs(np.linalg.det(M)) < 1e-12 * np.linalg.norm(q - p) * np.linalg.norm(b - a) * np.linalg.norm(c - a):
        return False  # parallel to the plane: touching at most
    s, u, v = np.linalg.solve(M, a - p)
    m = 1e-9
    return m < s < 1 - m and u > m and v > m and u + v < 1 - m


def brute_pairs(V, F) -> set[tuple[int, int]]:
    """Every pair of triangles sharing at most one corner position (an edge's neighbours cannot
    cross), one edge of either through the other."""
    key = [tuple(map(tuple, V[f])) for f in F]
    out = set()
    for i, j in itertools.combinations(range(len(F)), 2):
        if len(set(key[i]) & set(key[j])) >= 2:
            continue
        A, B = V[F[i]], V[F[j]]
        if any(_segment_through(E[k], E[(k + 1) % 3], *T) for E, T in ((A, B), (B, A)) for k in range(3)):
            out.add((i, j))
    return out


CASES = {
    # each box's faces run through the other's
    "through": [((0, 0, 0), (1, 1, 1)), ((0.5, 0.3, 0.2), (1.5, 1.3, 1.2))],
    # a thin slab through a box: its long faces cross the box's side faces
    "slab": [((0, 0, 0), (1, 1, 1)), ((-0.5, 0.4, 0.2), (1.5, 0.6, 0.8))],
    # one box on another (faces touching in a plane), one apart, one inside another
    "touching": [((0, 0, 0), (1, 1, 1)), ((0.2, 0.2, 1), (0.8, 0.8, 1.5))],
    "apart": [((0, 0, 0), (1, 1, 1)), ((2, 0, 0), (3, 1, 1))],
    "nested": [((0, 0, 0), (1, 1, 1)), ((0.25, 0.25, 0.25), (0.75, 0.75, 0.75))],
}


@pytest.mark.parametrize("case", sorted(CASES))
@pytest.mark.parametrize("seed", [0, 1])
def test_pairs_are_those_a_brute_force_finds(case, seed):
    V, F = _boxes(*CASES[case], seed=seed)
    got = crossing.crossing_pairs(V, F, 1e-9)
    ref = brute_pairs(V, F)
    assert set(map(tuple, got.tolist())) == ref
    if case in ("through", "slab"):
        assert len(ref) > 0
    else:
        assert len(ref) == 0
    assert (got[:, 0] < got[:, 1]).all()


@pytest.mark.parametrize("scale", [1e-3, 1.0, 1e4])
def test_random_soups_against_the_brute_force(scale):
    """Triangles thrown into a cube (many cross), some of them long, one far away: the grid's
    pairs and checks against every pair solved one by one."""
    rng = np.random.default_rng(int(scale * 7) % 1000)
    c = rng.random((150, 1, 3))
    size = np.where(rng.random((150, 1, 1)) < 0.1, 0.8, 0.3)
    T = c + size * (rng.random((150, 3, 3)) - 0.5)
    T = np.concatenate([T, [[[40, 40, 40], [41, 40, 40], [40, 41, 40]]]])  # far away
    V = T.reshape(-1, 3) * scale
    F = np.arange(len(V)).reshape(-1, 3)
    got = crossing.crossing_pairs(V, F, 1e-9 * scale)
    ref = brute_pairs(V, F)
    assert len(ref) > 20
    assert set(map(tuple, got.tolist())) == ref


def test_candidate_pairs_are_every_overlapping_box_pair_once():
    """The grid's box pairs against all pairs of boxes: across grid cells and chunks, with equal
    lower corners, boxes much bigger than the median, and one far off."""
    rng = np.random.default_rng(5)
    n = 1100
    lo = np.round(rng.random((n, 3)) * 4, 1)  # many equal lower corners
    ext = rng.random((n, 3)) * 0.2
    ext[rng.random(n) < 0.03] *= 30  # boxes over many cells
    lo[0] = 500.0  # far off
    hi = lo + ext
    for tol in (0.0, 0.05):
        got = crossing._candidate_pairs(lo, hi, tol)
        i, j = np.triu_indices(n, 1)
        ov = ((lo[i] <= hi[j] + 2 * tol) & (lo[j] <= hi[i] + 2 * tol)).all(axis=1)
        assert got.tolist() == np.stack([i[ov], j[ov]], 1).tolist()
    # small chunks: the same pairs
    import bake.bsp.crossing as mod

    keep = mod._CHUNK
    try:
        mod._CHUNK = 1000
        assert crossing._candidate_pairs(lo, hi, 0.05).tolist() == got.tolist()
    finally:
        mod._CHUNK = keep


def test_a_pierced_face_within_the_tolerance_of_the_other_plane_is_no_pair():
    """A big triangle tilted 1e-4 through a small flat one: an edge of the big one passes
    through the small one, but the small one lies within the tolerance of the big one's plane,
    so neither hides the other at that tolerance and the tree needs no cut (a reviewer's case)."""
    V = np.array([[-1, 0, -1e-4], [1, 0, 1e-4], [0, 1, 0], [-0.01, -0.01, 0], [0.01, -0.01, 0], [0, 0.01, 0]])
    F = np.array([[0, 1, 2], [3, 4, 5]])
    assert len(crossing.crossing_pairs(V, F, 1e-9)) == 1  # it does cross
    tol = 1e-6 * np.linalg.norm(V.max(0) - V.min(0))
    assert len(crossing.crossing_pairs(V, F, tol)) == 0
    new, rec = _stage(V, F)
    assert rec.details["splits"] == 0 and rec.details["crossing"]["pairs"] == 0


def test_random_soups_with_shared_corners_against_the_brute_force():
    """Triangles whose corners come from a small pool of points, so that many pairs share one
    corner or an edge: a pair sharing one corner crosses when the edge opposite it passes
    through the other; a pair sharing an edge never does."""
    rng = np.random.default_rng(3)
    V = rng.random((40, 3))
    F = np.array([rng.choice(40, 3, replace=False) for _ in range(300)])
    got = set(map(tuple, crossing.crossing_pairs(V, F, 1e-9).tolist()))
    ref = brute_pairs(V, F)
    K = [set(f.tolist()) for f in F]
    one = {p for p in ref if len(K[p[0]] & K[p[1]]) == 1}
    assert len(one) > 20 and len(ref) > len(one)  # both kinds are there
    assert got == ref


def test_a_fold_through_itself_crosses_and_a_fan_does_not():
    """Two triangles sharing one corner: the second's far edge passes through the first (a fold
    through itself: a pair, also at a tolerance of 1% of its size), or stays above it (a fan:
    none); and two sharing an edge, folded flat onto each other, are never a pair."""
    V = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0.3, 0.3, -0.5], [0.3, 0.3, 0.5], [0.3, 0.3, 0.2],
                  [0.6, 0.1, 0.5], [0.5, 0.5, 0.0]], float)
    fold, fan, flat = np.array([[0, 1, 2], [0, 3, 4]]), np.array([[0, 1, 2], [0, 5, 6]]), np.array([[0, 1, 2], [1, 2, 7]])
    assert crossing.crossing_pairs(V, fold, 1e-9).tolist() == [[0, 1]]
    assert crossing.crossing_pairs(V, fold, 1e-2).tolist() == [[0, 1]]
    assert len(crossing.crossing_pairs(V, fan, 1e-9)) == 0
    assert len(crossing.crossing_pairs(V, flat, 1e-9)) == 0
    for F in (fold, fan, flat):
        assert set(map(tuple, crossing.crossing_pairs(V, F, 1e-9).tolist())) == brute_pairs(V, F)
    # the fold's pair, through the stage: one of the two is cut (4 triangles or more out)
    out, rec = _stage(V, fold)
    assert rec.details["crossing"]["pairs"] == 1 and rec.details["crossing"]["pairs_within_one_part"] == 0
    assert out.n_triangles > 2


def test_within_the_tolerance_nothing_crosses():
    """A box sunk 1e-4 into another crosses it; with a tolerance above that, it only touches."""
    V, F = _boxes(((0, 0, 0), (1, 1, 1)), ((0.2, 0.2, 1 - 1e-4), (0.8, 0.8, 1.5)))
    assert len(crossing.crossing_pairs(V, F, 1e-6)) > 0
    assert len(crossing.crossing_pairs(V, F, 1e-3)) == 0


def test_parts_join_by_edges_at_one_position():
    V, F = _boxes(((0, 0, 0), (1, 1, 1)), ((2, 0, 0), (3, 1, 1)))
    # every triangle its own corners: the positions still join each box into one part
    U = V[F].reshape(-1, 3)
    G = np.arange(len(U)).reshape(-1, 3)
    lab = crossing.parts(U, G)
    assert lab.tolist() == [0] * 12 + [1] * 12
    # two triangles that share one corner only are two parts
    V2 = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [-1, 0, 0], [0, -1, 0]], float)
    assert crossing.parts(V2, np.array([[0, 1, 2], [0, 3, 4]])).tolist() == [0, 1]


def _stage(V, F):
    scene = make_scene(V, F)
    return stage(scene, config.load(None, ["bsp.enabled=true"]).bsp)


def test_the_stage_counts_crossing_pairs_and_says_what_they_cost():
    V, F = _boxes(*CASES["through"])
    _, rec = _stage(V, F)
    cr = rec.details["crossing"]
    ref = brute_pairs(V, F)
    assert cr["pairs"] == len(ref) > 0
    assert cr["triangles"] == len({t for p in ref for t in p})
    assert cr["parts"] == 2 and cr["pairs_within_one_part"] == 0
    assert any("pass through each other" in w and f"{len(ref):,} pair" in w for w in rec.warnings)
    V, F = _boxes(*CASES["apart"])
    _, rec = _stage(V, F)
    assert rec.details["crossing"]["pairs"] == 0
    assert not any("pass through each other" in w for w in rec.warnings)


def test_suzannes_eyes_cross_its_head_and_nothing_else_crosses():
    """The corpus Suzanne (docs/formats-bsp.md, Known limits): every pair is an eye's triangle
    against the head's, the grid's pairs the same as all 468,028 pairs checked."""
    path = corpus_file("suzanne")
    if not path.is_file():
        pytest.skip(f"corpus missing: {path}")
    s = load_scene("suzanne")
    V, F = s.positions, s.triangles
    tol = 2e-5 * s.scale()
    got = crossing.crossing_pairs(V, F, tol)
    # every pair of triangles that share at most one corner position, tested with the same check
    i, j = np.triu_indices(len(F), 1)
    _, vid = np.unique(V, axis=0, return_inverse=True)
    K = vid.reshape(-1)[F]
    apart = (K[i][:, :, None] == K[j][:, None, :]).any(axis=2).sum(axis=1) < 2
    i, j = i[apart], j[apart]
    C = V[F]
    hit = crossing._crosses(C[i], C[j], tol)
    assert got.tolist() == np.stack([i[hit], j[hit]], 1).tolist()
    lab = crossing.parts(V, F)
    sizes = np.bincount(lab)
    assert sorted(sizes.tolist())[:2] == [56, 56]  # the eyes
    eyes = np.flatnonzero(sizes == 56)
    pair_parts = lab[got]
    assert len(got) > 50
    assert (np.isin(pair_parts, eyes).sum(axis=1) == 1).all()  # an eye's against the head's
