"""Issue 41: the BSP tree does not depend on lit colours. With vertex colours (a lit bake) nothing
merges before the build and the re-merge joins only pieces of one input triangle without looking
at colours, so the tree (bake.bsp.stage.grow, the memo) is built on geometry, materials and
sidedness; the colours follow the triangles and pieces (bake.bsp.stage.complete). Any colour
change reuses the tree and gives the bytes of a cold build."""

from __future__ import annotations

import numpy as np

from bake import cache as cache_mod
from bake.bsp.stage import stage, tree_key_parts, options
from bake.cache import content_digest

from .meshes import interlocked_scene
from .test_stage import _cfg, _decorated


def _run(scene, memo):
    with cache_mod.using_memo(memo):
        return stage(scene, _cfg())


def _same(a, b):
    for f in ("positions", "triangles", "tri_material", "tri_uvs", "tri_polygon", "vertex_colors", "face_colors",
              "face_albedo", "tri_lightmap_uvs"):
        x, y = getattr(a, f), getattr(b, f)
        assert (x is None) == (y is None), f
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape and x.tobytes() == y.tobytes(), f
    assert sorted(a.lists) == sorted(b.lists)
    for name in a.lists:
        assert a.lists[name].values.tobytes() == b.lists[name].values.tobytes(), name


def test_the_tree_key_leaves_every_colour_out():
    scene, _ = _decorated(interlocked_scene())
    rng = np.random.default_rng(1)
    other = scene.replace(vertex_colors=rng.random(scene.vertex_colors.shape),
                          face_colors=rng.random(scene.face_colors.shape))
    opt = options(_cfg())
    assert content_digest(*tree_key_parts(scene, opt, True)) == content_digest(*tree_key_parts(other, opt, True))


def test_any_colours_reuse_the_tree_and_give_the_cold_bytes():
    scene, _ = _decorated(interlocked_scene())
    memo = cache_mod.Memo(cache_mod.MemoryStore())
    first, rec0 = _run(scene, memo)
    assert rec0.details["tree_reused"]["reused"] is False
    assert rec0.details["splits"] > 0 and rec0.details["new_vertices"] > 0
    # noisy vertex colours (no longer affine over two input triangles) and face colours all different
    rng = np.random.default_rng(7)
    vc = scene.vertex_colors.copy()
    vc[:, :3] = np.clip(vc[:, :3] + rng.random((len(vc), 3)) * 0.3, 0, 1)
    fc = scene.face_colors.copy()
    fc[:, :3] = rng.random((len(fc), 3))
    other = scene.replace(vertex_colors=vc, face_colors=fc)
    warm, rec = _run(other, memo)
    assert rec.details["tree_reused"]["reused"] is True and memo.reused == ["bsp"]
    assert rec.details["remerged_fragments"] == rec0.details["remerged_fragments"]  # no colour decides a join
    cold, rec_cold = stage(other, _cfg())
    _same(warm, cold)
    assert rec.counts_out == rec_cold.counts_out and rec.warnings == rec_cold.warnings
    # and back to the first colours: the first bytes again, from the same tree
    again, rec2 = _run(scene, memo)
    assert rec2.details["tree_reused"]["reused"] is True
    _same(again, first)


def test_joined_pieces_show_their_triangles_colours():
    """The re-merge joins pieces of one input triangle only: with face colours made different per
    input triangle, every output triangle's face colour is its source triangle's, and every output
    triangle lies inside its source triangle. (The cut corners' vertex colours against a build
    with the colours from the start: test_any_colours_reuse_the_tree_and_give_the_cold_bytes.)"""
    scene, _ = _decorated(interlocked_scene())
    rng = np.random.default_rng(3)
    # per-corner colours cannot be noisy per triangle with shared vertices: noisy face colours
    fc = scene.face_colors.copy()
    fc[:, :3] = rng.random((len(fc), 3))
    other = scene.replace(face_colors=fc)
    new, rec = stage(other, _cfg())
    assert rec.details["splits"] > 0
    src = new.artefacts.bsp.source_triangle
    np.testing.assert_array_equal(new.face_colors, fc[src])
    # every output triangle lies inside its source triangle (barycentrics >= 0 within rounding)
    tv = scene.triangle_vertices()[src]
    out = new.triangle_vertices()
    e1, e2 = tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]
    n = np.cross(e1, e2)
    nn = (n * n).sum(1)
    for k in range(3):
        d = out[:, k] - tv[:, 0]
        b1 = (np.cross(d, e2) * n).sum(1) / nn
        b2 = (np.cross(e1, d) * n).sum(1) / nn
        assert (b1 > -1e-6).all() and (b2 > -1e-6).all() and (b1 + b2 < 1 + 1e-6).all()
