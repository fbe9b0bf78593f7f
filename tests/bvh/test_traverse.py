"""The reference traversals against brute force (exact) and Embree (independent), per layout.

Ray counts here are small (the suite stays fast); benchmarks/bench_bvh.py runs 100k rays per
corpus model through the same checks.
"""

from __future__ import annotations

import numpy as np
import pytest

from bake.bvh.traverse import brute_force, trace, trace_one
from bake.bvh.verify import compare_brute, compare_embree, make_rays
from bake.bvh.stage import stage
from bake.config import BVHConfig
from bake.scene import make_scene
from bvh_meshes import flat, load_corpus, soup

LAYOUTS = ["binary", "wide4", "quantised"]


def baked(scene, layout, **kw):
    s, rec = stage(scene, BVHConfig(enabled=True, layout=layout, **kw))
    return s.artefacts.bvh.encoded, rec


def exact_against_brute(enc, o, d):
    tl = enc.tris.reshape(-1, 3, 3)
    h = trace(enc, o, d)
    c = compare_brute(h, tl, o, d)
    assert c["t_equal"], c
    assert c["slot_differs_not_tie"] == 0, c
    assert c["u_v_equal_where_same_slot"], c
    return h


@pytest.mark.parametrize("layout", LAYOUTS)
def test_one_ray_loop_equals_batch(layout):
    """trace_one (the Scratch script, item by item) and trace (masks over a batch) agree in
    every output, including the number of items read."""
    enc, _ = baked(soup(250, seed=5), layout, leaf_size=3)
    tl = enc.tris.reshape(-1, 3, 3)
    o, d, _ = make_rays(tl, 300, seed=2)
    h = trace(enc, o, d)
    assert h.hit.sum() > 100
    for i in range(len(o)):
        t, slot, tri, u, v, reads = trace_one(enc, o[i], d[i])
        assert (t, slot, tri, u, v, reads) == (h.t[i], h.slot[i], h.tri[i], h.u[i], h.v[i], h.reads[i])


@pytest.mark.parametrize("layout", LAYOUTS)
@pytest.mark.parametrize("case", ["soup", "translated", "flat"])
def test_closest_hits_equal_brute_force(layout, case):
    """Random soups with degenerate triangles, the same soup moved by 1e5, and a flat scene:
    the BVH walk returns exactly brute force's closest hit over the same triangles."""
    sc = soup(500, seed=7) if case != "flat" else flat(300)
    if case == "translated":
        sc = sc.replace(positions=sc.positions + 1e5)
    enc, rec = baked(sc, layout, leaf_size=4, quant_bits=4)
    tl = enc.tris.reshape(-1, 3, 3)
    o, d, _ = make_rays(tl, 4000, seed=11)
    if case == "flat":
        # plus rays lying exactly in the plane and rays from far above
        rng = np.random.default_rng(3)
        o2 = np.c_[rng.random((500, 2)) * 10, np.zeros(500)]
        d2 = np.c_[rng.normal(size=(500, 2)), np.zeros(500)]
        o = np.r_[o, o2, o2 + [0, 0, 50]]
        d = np.r_[d, d2, np.c_[rng.normal(size=(500, 2)) * 0.1, -np.ones(500)]]
    h = exact_against_brute(enc, o, d)
    assert h.hit.mean() > 0.3
    if case == "flat":
        assert not h.hit[4000:4500].any()  # in-plane rays never hit


@pytest.mark.parametrize("bits", [2, 3, 5, 8])
def test_quantised_never_loses_a_hit(bits):
    """Whatever the code width, quantised boxes only ever add box hits: the closest hit of every
    ray is exactly the float layout's."""
    sc = soup(400, seed=9)
    ef, _ = baked(sc, "wide4")
    eq, _ = baked(sc, "quantised", quant_bits=bits)
    o, d, _ = make_rays(sc.triangle_vertices(), 3000, seed=4)
    hf, hq = trace(ef, o, d), trace(eq, o, d)
    assert np.array_equal(hf.t, hq.t)
    assert np.array_equal(hf.tri > 0, hq.tri > 0)
    assert hq.boxes.sum() >= hf.boxes.sum()


@pytest.mark.corpus
@pytest.mark.parametrize("layout", LAYOUTS)
def test_teapot_against_brute_force_and_embree(corpus, layout):
    V, F = load_corpus(corpus("teapot_obj", "teapot.obj"))
    sc = make_scene(V, F)
    enc, _ = baked(sc, layout)
    tl = enc.tris.reshape(-1, 3, 3)
    o, d, _ = make_rays(tl, 20000, seed=1)
    h = trace(enc, o, d)
    sub = np.arange(0, len(o), 8)  # brute force on every 8th ray (2,500)
    bt, bi, _, _ = brute_force(tl, o[sub], d[sub])
    assert np.array_equal(h.t[sub], bt)
    c = compare_embree(tl, o, d, h.t, h.slot, scale=sc.scale())
    assert c["unexplained"] == 0, c
    assert c["agree"] >= 0.9 * c["rays"], c
    # scene triangle numbers: the hit triangle's list corners are the scene's, rounded
    hit = np.nonzero(h.hit)[0][:500]
    assert np.allclose(tl[h.slot[hit]], sc.triangle_vertices()[h.tri[hit] - 1], atol=1e-5 * sc.scale())


# a ray (x, y, -1) + t (0, 0, 1) at the triangle (0,0,0) (1,0,0) (0,1,0) has u = x, v = y: rays
# 5e-10 outside an edge (in barycentric units) hit, rays 2e-9 outside miss (docs/formats-bvh.md)
TOLERANCE_RAYS = {(0.25, 0.25): True, (0.0, 0.0): True, (-5e-10, 0.5): True, (0.5, -5e-10): True,
                  (0.5, 0.5 + 5e-10): True, (-5e-10, -5e-10): True, (-2e-9, 0.5): False, (0.5, -2e-9): False,
                  (0.5, 0.5 + 2e-9): False, (-2e-9, -2e-9): False}


@pytest.mark.parametrize("layout", LAYOUTS)
def test_inside_test_has_a_1e_9_tolerance(layout):
    """The barycentric tolerance that keeps rays from slipping through shared edges: the same in
    trace_one, trace and brute force (the Scratch reader: tests/scratch/test_scratch_readers.py)."""
    sc = make_scene(np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float), np.array([[0, 1, 2]]))
    enc, _ = baked(sc, layout)
    o = np.array([[x, y, -1.0] for x, y in TOLERANCE_RAYS])
    d = np.tile([0.0, 0.0, 1.0], (len(o), 1))
    h = trace(enc, o, d)
    assert h.hit.tolist() == list(TOLERANCE_RAYS.values())
    assert np.all(h.t[h.hit] == 1.0)
    bt, _, _, _ = brute_force(enc.tris.reshape(-1, 3, 3), o, d)
    assert np.array_equal(h.t, bt)
    for i in range(len(o)):
        assert trace_one(enc, o[i], d[i])[:5] == (h.t[i], h.slot[i], h.tri[i], h.u[i], h.v[i])


def test_tmax_and_tmin_limit_hits():
    enc, _ = baked(soup(200, seed=2), "quantised")
    tl = enc.tris.reshape(-1, 3, 3)
    o, d, _ = make_rays(tl, 2000, seed=8)
    full = trace(enc, o, d)
    lim = trace(enc, o, d, tmax=2.0)
    assert np.all(lim.t[lim.hit] < 2.0)
    keep = full.t < 2.0
    assert np.array_equal(lim.t[keep], full.t[keep])
    assert lim.reads.sum() <= full.reads.sum()
