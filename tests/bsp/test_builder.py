"""The builder's search (issue 20): edge planes, candidates scored on a sample, best-of-k subtrees;
each keeps the proof of order, and the walk cost the bake reports is what the reference walk does.
(Plane sharing is checked on the house in test_grid.py.)"""

from __future__ import annotations

import numpy as np
import pytest

from bake import config
from bake.bsp.cost import BLOCKS, blocks_estimate, parse, walk_counts
from bake.bsp.build import BuildOptions, build_tree
from bake.bsp.split import triangle_store
from bake.bsp.stage import NODES_LIST, PLANES_LIST, stage
from bake.bsp.traverse import draw_order, draw_ranges
from bake.bsp.verify import check_order, random_cameras
from bake.scratch.numbers import position_decimals
from bake.scene import Material

from .meshes import corpus_file, interlocked_scene, load_scene


def _cfg(**kw):
    c = config.load(None, ["bsp.enabled=true"]).bsp
    for k, v in kw.items():
        setattr(c, k, v)
    return c


def _proof(scene, n_cams=8, seed=3, **kw):
    new, rec = stage(scene, _cfg(**kw))
    res = check_order(new, random_cameras(new, n_cams, seed))
    assert res["covered"] > 1000
    assert res["interior"] == 0 and res["non_tie_fraction"] < 1e-3, res
    return new, rec


@pytest.mark.parametrize("kw", [dict(edge_planes=256, edge_plane_cost=1e9), dict(ensemble=4, ensemble_max=64),
                                dict(score_sample=8, score_refine=2), dict(edge_planes=0)])
def test_every_search_option_keeps_the_order(kw):
    _proof(interlocked_scene(seed=2), **kw)


def test_edge_planes_are_chosen_and_pass_through_their_edge():
    sc = load_scene("suzanne") if corpus_file("suzanne").exists() else interlocked_scene()
    new, rec = stage(sc, _cfg())
    assert rec.details["options"]["edge_planes"] == _cfg().edge_planes
    # the builder's statistics count the planes of each kind it chose
    from bake.bsp.stage import build, options

    store, src, tree, enc, _ = build(sc, options(_cfg()))
    assert tree.stats["edge_planes"] > 0 and tree.stats["face_planes"] > 0


@pytest.mark.parametrize("seed", [1, 4])
def test_block_and_flat_scoring_give_the_same_tree(monkeypatch, seed):
    """Big nodes are scored as fragments x candidates blocks, small ones as flat pair lists
    (bake.bsp.build._BLOCK_PAIRS); both paths must give the same counts, so forcing either one
    everywhere builds the same tree, fragment for fragment."""
    import bake.bsp.build as bb

    sc = interlocked_scene(seed=seed)
    outs = []
    for pairs in (0, 1 << 62):
        monkeypatch.setattr(bb, "_BLOCK_PAIRS", pairs)
        new, rec = stage(sc, _cfg(thorough_faces=0))
        outs.append((new.positions.tobytes(), new.triangles.tobytes(), rec.details["tree_depth"]))
    assert outs[0] == outs[1]


def test_ensemble_grafts_complete_subtrees_deterministically():
    sc = interlocked_scene(seed=5)
    a, ra = _proof(sc, ensemble=3, ensemble_max=256)
    b, rb = stage(sc, _cfg(ensemble=3, ensemble_max=256))
    np.testing.assert_array_equal(a.lists[NODES_LIST].values, b.lists[NODES_LIST].values)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    assert ra.details["inflation"] == rb.details["inflation"]


@pytest.mark.parametrize("two", [False, True])
def test_walk_counts_match_the_reference_walk(two):
    sc = interlocked_scene(seed=4)
    if two:
        sc = sc.replace(materials=(Material("paper", double_sided=True),))
    sc = sc.replace(position_decimals=position_decimals(sc.scale(), 5))
    new, rec = stage(sc, _cfg())
    nodes = np.asarray(new.lists[NODES_LIST].values, np.int64)
    planes = np.asarray(new.lists[PLANES_LIST].values, np.float64)
    tris = np.concatenate([new.triangles + 1, new.tri_material[:, None] + 1], 1).ravel()
    ds = [m.double_sided for m in new.materials]
    starts, kinds = parse(nodes)
    assert starts[0] == 1 and len(starts) == sum(rec.details["records"].values())
    two_t = np.asarray(ds, bool)[new.tri_material]
    for eye in random_cameras(new, 6, seed=1):
        e = eye.position
        c = walk_counts(nodes, planes, new.triangles, new.positions, two_t, e)
        ranges = draw_ranges(nodes.tolist(), planes.tolist(), e)
        assert c["ranges"] == len(ranges)
        assert c["triangles"] == sum(n for _, n in ranges)
        # what a culling renderer fills is the reference's culled draw order
        order = draw_order(nodes.tolist(), planes.tolist(), e, tris.tolist(), new.positions.ravel().tolist(), ds)
        assert c["facing"] == len(order)
        assert c["split"] == int((kinds >= 4).sum())
        assert blocks_estimate(c) > BLOCKS["base"]
    w = rec.details["walk"]
    assert w["blocks_estimate"] == blocks_estimate(w) and w["plane_tests"] == w["split"]


def test_sampled_scoring_is_exact_for_small_nodes():
    # nodes at or below score_sample are scored on every face: the same tree either way
    tri = np.random.default_rng(0).random((60, 3, 3)) - 0.5
    st1 = triangle_store(tri, 1e-12)
    st2 = triangle_store(tri, 1e-12)
    t1 = build_tree(st1, BuildOptions(score_sample=0))
    t2 = build_tree(st2, BuildOptions(score_sample=64))
    np.testing.assert_array_equal(t1.plane, t2.plane)
    np.testing.assert_array_equal(np.sort(t1.fragments()), np.sort(t2.fragments()))


def test_the_thorough_search_only_in_scenes_up_to_thorough_faces():
    from bake.bsp.stage import build, options

    sc = interlocked_scene(seed=5)
    small = options(_cfg(ensemble=3, ensemble_max=256, thorough_faces=100000))
    big = options(_cfg(ensemble=3, ensemble_max=256, thorough_faces=10, thorough_edge_factor=3))
    off = options(_cfg(ensemble=1, thorough_faces=0))
    t_small = build(sc, small)[2]
    t_big = build(sc, big)[2]
    t_off = build(sc, off)[2]
    assert t_small.stats["ensembles"] > 0
    assert t_big.stats["ensembles"] == 0
    # over the limit the tree is the greedy one, record for record
    np.testing.assert_array_equal(t_big.plane, t_off.plane)
    np.testing.assert_array_equal(t_big.pre_ids, t_off.pre_ids)
