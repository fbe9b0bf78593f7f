"""The stage: lists, names, records, config checks; the scene's triangles stay as they are."""

from __future__ import annotations

import numpy as np
import pytest

from bake import config as config_mod
from bake.bvh.encode import json_lengths, qdecode, widen
from bake.bvh.stage import stage
from bake.config import BVHConfig
from bake.errors import ConfigError
from bake.scratch.numbers import format_numbers
from bake.scene import Scene, make_scene
from bvh_meshes import load_corpus, soup


@pytest.mark.parametrize("layout", ["binary", "wide4", "quantised"])
def test_stage_writes_three_lists_and_leaves_scene_alone(layout):
    sc = soup(300)
    out, rec = stage(sc, BVHConfig(enabled=True, layout=layout, list_prefix="accel"))
    assert np.array_equal(out.triangles, sc.triangles) and out.positions is sc.positions
    names = {"accel nodes", "accel tris", "accel tri ids"}
    assert names <= set(out.lists)
    ids = out.lists["accel tri ids"].values
    tris = out.lists["accel tris"].values
    assert len(tris) == 9 * len(ids) and ids.min() >= 1 and ids.max() <= sc.n_triangles
    # every non-degenerate triangle is in exactly one slot; degenerate ones were left out
    assert len(np.unique(ids)) == len(ids) == sc.n_triangles - rec.details["degenerate_dropped"]
    assert rec.details["degenerate_dropped"] >= 10
    assert rec.accuracy["sah_cost"] > 1
    for lst in out.lists.values():
        assert np.isfinite(np.asarray(lst.values, float)).all()


def test_json_byte_count_matches_the_exporter():
    sc = soup(200)
    for layout in ("binary", "quantised"):
        out, rec = stage(sc, BVHConfig(enabled=True, layout=layout))
        for lst in out.lists.values():
            items = format_numbers(np.asarray(lst.values), lst.decimals, name=lst.name)
            assert json_lengths(np.asarray(lst.values, float)) == len(",".join(items))


def test_quantised_codes_contain_their_boxes():
    """Decode every packed child box with the traversal's arithmetic, frames top-down, and check
    it contains the float box (which contains the triangles)."""
    sc = soup(500, seed=4)
    out, _ = stage(sc, BVHConfig(enabled=True, layout="quantised", quant_bits=3))
    enc = out.artefacts.bvh.encoded
    tree = out.artefacts.bvh.tree
    w = widen(tree)
    M = 2 ** enc.bits
    frames = {0: (enc.nodes[:3], enc.nodes[3:6])}
    tri = enc.tris.reshape(-1, 3, 3)
    rec_of = {b: r for r, b in enumerate(w.node)}
    for r in range(enc.n_nodes):
        base = 6 + r * enc.stride
        flo, fhi = frames[r]
        for j, k in enumerate(w.children[r]):
            v = int(enc.nodes[base + 3 + j])
            q = [(v // M ** i) % M for i in range(6)]
            dlo = qdecode(flo, fhi, np.array(q[:3], float), enc.bits)
            dhi = qdecode(flo, fhi, np.array(q[3:], float), enc.bits)
            assert np.all(dlo <= tree.lo[k]) and np.all(dhi >= tree.hi[k])
            if k in rec_of and rec_of[k] != r:
                frames[rec_of[k]] = (dlo, dhi)
    assert np.all(tri.min(1) >= enc.nodes[:3]) and np.all(tri.max(1) <= enc.nodes[3:6])


@pytest.mark.corpus
def test_quantised_wide_node_fits_64_bytes(corpus):
    V, F = load_corpus(corpus("teapot_obj", "teapot.obj"))
    out, rec = stage(make_scene(V, F), BVHConfig(enabled=True, layout="quantised", quant_bits=6))
    assert rec.details["sizes"]["bytes_per_node"] <= 64


def test_empty_scene_and_config_errors():
    out, rec = stage(Scene(), BVHConfig(enabled=True))
    assert rec.warnings and len(out.lists["bvh nodes"].values) == 0
    for bad in ({"leaf_size": 15}, {"leaf_size": 0}, {"quant_bits": 9}, {"bins": 1}, {"precision": -1}):
        with pytest.raises(ConfigError):
            stage(soup(10), BVHConfig(enabled=True, **bad))
    cfg = config_mod.load(None, ["bvh.enabled=true", "bvh.layout=\"wide4\"", "bvh.quant_bits=5"])
    assert cfg.bvh.layout == "wide4" and cfg.bvh.quant_bits == 5
    with pytest.raises(ConfigError):
        config_mod.load(None, ["bvh.layout=\"octree\""])


def _sah_of_binary_list(nodes: np.ndarray) -> float:
    """The SAH (C_trav = C_int = 1) read back from a written ``binary`` node list alone, as
    docs/formats-bvh.md describes it: 7 items per record, link < 0 interior, link > 0 leaf with
    ``link mod 16`` triangles."""
    rec = np.asarray(nodes, float).reshape(-1, 7)
    e = np.maximum(rec[:, 3:6] - rec[:, 0:3], 0.0)
    a = e[:, 0] * e[:, 1] + e[:, 1] * e[:, 2] + e[:, 2] * e[:, 0]
    link = rec[:, 6]
    leaf = link > 0
    return float((a[~leaf].sum() + (a[leaf] * np.mod(link[leaf], 16)).sum()) / a[0])


@pytest.mark.parametrize("precision", [2, 5])
def test_sah_cost_is_the_written_trees(precision):
    """report.json's sah_cost is the SAH of the boxes as the lists hold them (rounded outward
    onto the list grid), not of the tight float64 boxes (issue 17, item 5)."""
    sc = soup(400, seed=3, degenerate=0)
    out, rec = stage(sc, BVHConfig(enabled=True, layout="binary", precision=precision))
    written = _sah_of_binary_list(out.lists["bvh nodes"].values)
    assert rec.accuracy["sah_cost"] == pytest.approx(written, rel=1e-12)
    # rounding outward only grows boxes: the figure differs from the tight one at a coarse grid
    assert rec.details["sah_cost_unrounded"] <= written
    if precision == 2:
        assert written > rec.details["sah_cost_unrounded"] * (1 + 1e-4)
    # the 4-wide layouts are made from the same tree and float boxes: the same figure
    for layout in ("wide4", "quantised"):
        _, r2 = stage(sc, BVHConfig(enabled=True, layout=layout, precision=precision))
        assert r2.accuracy["sah_cost"] == rec.accuracy["sah_cost"]


@pytest.mark.parametrize("layout", ["wide4", "quantised"])
def test_stack_bound_uses_the_record_depth(layout):
    """docs/formats-bvh.md: the 4-wide walk's stack holds at most 3 x record_depth + 1 entries
    (record_depth: the 4-wide tree's depth in records, reported next to the binary depth)."""
    from bake.bvh.traverse import trace
    from bake.bvh.verify import make_rays

    sc = soup(3000, seed=5, degenerate=0)
    out, rec = stage(sc, BVHConfig(enabled=True, layout=layout, leaf_size=1))
    enc = out.artefacts.bvh.encoded
    D = rec.details["record_depth"]
    assert 0 < D < rec.details["depth"]  # a record spans about two binary levels
    o, d, _ = make_rays(enc.tris.reshape(-1, 3, 3), 4000, seed=2)
    h = trace(enc, o, d)
    assert h.stack.max() <= 3 * D + 1
    assert h.stack.max() > D  # the walk does go deep: the bound is not vacuous
