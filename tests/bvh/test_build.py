"""The builder: a valid tree, the SAH it reports, and what quality = "high" buys."""

from __future__ import annotations

import numpy as np
import pytest

from bake.bvh.build import BVH, build, build_binned, collapse, preorder, reinsertion, sah_cost, triangle_bounds
from bvh_meshes import flat, load_corpus, soup


def check_tree(b: BVH, lo: np.ndarray, hi: np.ndarray, leaf_size: int) -> None:
    """Every primitive once, boxes nest and contain their primitives, leaves are small."""
    assert sorted(b.order.tolist()) == list(range(len(lo)))
    inner = np.nonzero(b.left >= 0)[0]
    for ch in (b.left[inner], b.right[inner]):
        assert np.all(b.lo[ch] >= b.lo[inner]) and np.all(b.hi[ch] <= b.hi[inner])
        assert np.all(ch > inner)
    leaves = np.nonzero(b.left < 0)[0]
    assert b.count[leaves].max() <= leaf_size and b.count[leaves].min() >= 1
    assert b.count[leaves].sum() == len(lo)
    rep = np.repeat(leaves, b.count[leaves])
    refs = np.concatenate([b.order[b.first[i]:b.first[i] + b.count[i]] for i in leaves])
    assert np.all(lo[refs] >= b.lo[rep]) and np.all(hi[refs] <= b.hi[rep])


def sah_recursive(b: BVH, i: int = 0) -> float:
    """SAH from its definition, node by node (independent of ``sah_cost``)."""
    e = b.hi[i] - b.lo[i]
    a = 2 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0])
    if b.left[i] < 0:
        return a * b.count[i]
    return a + sah_recursive(b, b.left[i]) + sah_recursive(b, b.right[i])


@pytest.mark.parametrize("leaf_size,bins", [(1, 2), (4, 8), (8, 16), (14, 32)])
def test_binned_tree_is_valid_and_sah_matches_definition(leaf_size, bins):
    sc = soup(400)
    lo, hi = triangle_bounds(sc.triangle_vertices())
    b = preorder(build_binned(lo, hi, leaf_size=leaf_size, bins=bins))
    check_tree(b, lo, hi, leaf_size)
    e = b.hi[0] - b.lo[0]
    ref = sah_recursive(b) / (2 * (e[0] * e[1] + e[1] * e[2] + e[2] * e[0]))
    assert sah_cost(b) == pytest.approx(ref, rel=1e-12)


def test_coincident_and_flat_primitives():
    # 50 identical triangles: no split plane exists, the object-median fallback must still
    # produce leaves of at most leaf_size
    tri = np.tile(np.array([[[0, 0, 0], [1, 0, 0], [0, 1, 0]]], float), (50, 1, 1))
    lo, hi = triangle_bounds(tri)
    b = preorder(build_binned(lo, hi, leaf_size=3))
    check_tree(b, lo, hi, 3)
    assert b.info["median_splits"] > 0
    sc = flat()
    lo, hi = triangle_bounds(sc.triangle_vertices())
    b = preorder(build_binned(lo, hi, leaf_size=4))
    check_tree(b, lo, hi, 4)
    assert np.isfinite(sah_cost(b))


def test_collapse_and_reinsertion_never_raise_sah():
    sc = soup(600, seed=3)
    lo, hi = triangle_bounds(sc.triangle_vertices())
    b = build_binned(lo, hi, leaf_size=1)
    c = collapse(b, 4)
    check_tree(c, lo, hi, 4)
    assert sah_cost(c) <= sah_cost(b) + 1e-12
    r = reinsertion(b, passes=2, fraction=0.2)
    check_tree(r, lo, hi, 1)
    assert sah_cost(r) <= sah_cost(b) * (1 + 1e-12)


def test_reinsertion_budget_is_work_not_time(monkeypatch):
    """Same input, same tree however busy the machine is: the optimiser's budget counts node
    visits. With a clock that jumps 100 s at every reading (a loaded machine, or a time budget's
    view of one) the result must equal the unhurried one, and a small budget stops early the same
    way every time."""
    import time as time_mod

    sc = soup(600, seed=5)
    lo, hi = triangle_bounds(sc.triangle_vertices())
    b = build_binned(lo, hi, leaf_size=1)
    calm = reinsertion(b, passes=2, fraction=0.2)
    small = reinsertion(b, passes=2, fraction=0.2, budget=2000)
    assert small.info["reinsertion_budget_reached"] and not calm.info["reinsertion_budget_reached"]
    clock = iter(range(0, 10**9, 100))
    monkeypatch.setattr(time_mod, "perf_counter", lambda: float(next(clock)))
    busy = reinsertion(b, passes=2, fraction=0.2)
    busy_small = reinsertion(b, passes=2, fraction=0.2, budget=2000)
    for x, y in ((calm, busy), (small, busy_small)):
        for f in ("lo", "hi", "left", "right", "first", "count"):
            assert np.array_equal(getattr(x, f), getattr(y, f))
    assert sah_cost(calm) < sah_cost(small) <= sah_cost(b) * (1 + 1e-12)


@pytest.mark.corpus
def test_teapot_sah_at_or_below_reference_and_high_quality_lower(corpus):
    V, F = load_corpus(corpus("teapot_obj", "teapot.obj"))
    lo, hi = triangle_bounds(V[F])
    b = build(lo, hi, leaf_size=4, bins=8)
    check_tree(b, lo, hi, 4)
    # the plain binned-SAH reference measured here: 24.1 (8 bins)
    assert round(sah_cost(b), 1) <= 24.1
    h = build(lo, hi, leaf_size=4, bins=8, quality="high")
    check_tree(h, lo, hi, 4)
    assert sah_cost(h) < 0.97 * sah_cost(b)


@pytest.mark.corpus
@pytest.mark.slow
def test_bunny_sah_matches_reference(corpus):
    V, F = load_corpus(corpus("stanford_bunny_res1_obj", "stanford-bunny.obj"))
    lo, hi = triangle_bounds(V[F])
    b = build(lo, hi, leaf_size=4, bins=8)
    assert b.n_leaves * 4 >= len(F)
    # reference 31.8 (8 bins) at the precision it was quoted
    assert round(sah_cost(b), 1) <= 31.8
