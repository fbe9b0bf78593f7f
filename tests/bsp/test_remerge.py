"""Fragments joined again after the build (bake/bsp/remerge.py): fewer triangles, the same surface,
the order still right. The house (regr01) has long coplanar walls cut by many planes."""

from __future__ import annotations

import numpy as np
import pytest

from bake import config
from bake.bsp import stage as bsp_stage
from bake.bsp.build import hide_graph
from bake.bsp.verify import check_order, random_cameras
from bake.scratch.numbers import position_decimals

from .meshes import corpus_file, load_scene


def _house():
    if not corpus_file("house").exists():
        pytest.skip(f"corpus missing: {corpus_file('house')}")
    s = load_scene("house")
    return s.replace(position_decimals=position_decimals(s.scale(), 5))


def _cfg(remerge: bool):
    c = config.load(None, ["bsp.enabled=true", f"bsp.remerge={'true' if remerge else 'false'}"]).bsp
    return c


@pytest.fixture(scope="module")
def house_both():
    s = _house()
    return s, bsp_stage.stage(s, _cfg(False)), bsp_stage.stage(s, _cfg(True))


def _area_by_source(scene, new):
    """Written area per input triangle's source (the stage's artefact), from positions alone."""
    tv = new.positions[new.triangles]
    area = 0.5 * np.linalg.norm(np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]), axis=1)
    src = new.artefacts.bsp.source_triangle
    return np.bincount(scene.tri_material[src], weights=area, minlength=len(scene.materials))


def test_fewer_triangles_same_surface_per_material(house_both):
    s, (off, rec_off), (on, rec_on) = house_both
    assert rec_on.details["remerge_saved_triangles"] > 0
    assert on.n_triangles == off.n_triangles - rec_on.details["remerge_saved_triangles"]
    assert on.n_triangles < 0.95 * off.n_triangles
    a_off, a_on = _area_by_source(s, off), _area_by_source(s, on)
    # a dropped corner lies within the tolerance (a fraction of the diagonal D) of the chord
    # between its neighbours (shorter than D): each drop changes the area by at most tol * D^2 / 2
    D = s.scale()
    bound = rec_on.details["remerge_saved_triangles"] * 0.5 * rec_on.details["tolerance"] * D * D
    assert np.abs(a_on - a_off).sum() <= bound
    assert np.abs(a_on - a_off).sum() <= 1e-4 * a_off.sum()


def test_written_triangles_are_not_flipped_or_collapsed(house_both):
    s, _, (on, _) = house_both
    tv = on.positions[on.triangles]
    cr = np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0])
    assert (np.linalg.norm(cr, axis=1) > 0).all()
    src = on.artefacts.bsp.source_triangle
    sv = s.positions[s.triangles[src]]
    n0 = np.cross(sv[:, 1] - sv[:, 0], sv[:, 2] - sv[:, 0])
    cos = np.einsum("ij,ij->i", cr, n0) / (np.linalg.norm(cr, axis=1) * np.linalg.norm(n0, axis=1))
    assert (cos > np.cos(np.radians(30))).all()


def test_order_still_right_inside_and_outside(house_both):
    _, _, (on, _) = house_both
    cams = random_cameras(on, 8, seed=3) + random_cameras(on, 4, seed=4, inside=1.0)
    res = check_order(on, cams)
    assert res["interior"] == 0 and res["non_tie_fraction"] < 1e-3, res


def test_prefix_and_suffix_lists_pass_the_may_hide_check():
    """Independent of the remerge's own check: every peel list of the built tree, in draw order,
    has no fragment that may hide one drawn after it."""
    s = _house()
    opt = bsp_stage.options(_cfg(True))
    store, src, tree, enc, _ = bsp_stage.build(s, opt)
    eps = bsp_stage.tolerance(s, opt)
    checked = 0
    for ids, nodes in ((tree.pre_ids, tree.pre_node), (tree.suf_ids, tree.suf_node)):
        o = np.argsort(nodes, kind="stable")
        ids, nodes = ids[o], nodes[o]
        for n in np.unique(nodes):
            seq = ids[nodes == n]
            if 2 <= len(seq) <= 512:
                M = hide_graph(store, seq[None], eps)[0]
                assert not np.triu(M, 1).any()
                checked += 1
    assert checked > 50
