"""Merging coplanar neighbours into convex source polygons."""

from __future__ import annotations

import numpy as np

from bake.bsp.merge import merge_coplanar
from bake.bsp.split import polygon_area

EPS = 1e-6


def _merge(pos, tris, attr=None, group=None):
    pos = np.asarray(pos, float)
    tris = np.asarray(tris)
    T = len(tris)
    attr = np.zeros((T, 3, 0)) if attr is None else np.asarray(attr, float)
    group = np.zeros(T, np.int64) if group is None else np.asarray(group)
    return merge_coplanar(pos, tris, attr, group, EPS, 1e-12)


SQUARE = [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]]


def test_two_triangles_of_a_square_become_one_quad():
    src = _merge(SQUARE, [[0, 1, 2], [0, 2, 3]])
    assert len(src.count) == 1 and src.count[0] == 4 and src.merged == 1
    assert polygon_area(src.pos)[0] == 1.0
    assert sorted(src.tri_list[src.tri_start[0]:src.tri_start[1]].tolist()) == [0, 1]
    # corners are the square's vertices, in the triangles' winding
    assert sorted(src.vid[0, :4].tolist()) == [0, 1, 2, 3]


def test_a_fan_of_coplanar_triangles_becomes_one_convex_polygon():
    ang = np.linspace(0, 2 * np.pi, 9)[:-1]
    pos = np.concatenate([[[0, 0, 0]], np.stack([np.cos(ang), np.sin(ang), 0 * ang], 1)])
    tris = [[0, 1 + k, 1 + (k + 1) % 8] for k in range(8)]
    src = _merge(pos, tris)
    # the centre vertex is straight in the merged octagon, so merging stops before dropping it:
    # every polygon stays strictly convex and together they cover the octagon exactly
    area = polygon_area(src.pos).sum()  # padding repeats corner 0: adds no area
    assert np.isclose(area, 8 * 0.5 * np.sin(2 * np.pi / 8))
    assert len(src.count) < 8
    assert sorted(src.tri_list.tolist()) == list(range(8))


def test_no_merge_across_a_fold_a_material_change_or_a_concave_union():
    folded = [[0, 0, 0], [1, 0, 0], [1, 1, 0.2], [0, 1, 0]]
    assert len(_merge(folded, [[0, 1, 2], [0, 2, 3]]).count) == 2
    assert len(_merge(SQUARE, [[0, 1, 2], [0, 2, 3]], group=[0, 1]).count) == 2
    # an L made of two triangles sharing an edge: union not convex
    L = [[0, 0, 0], [2, 0, 0], [0, 1, 0], [-1, 2, 0]]
    src = _merge(L, [[0, 1, 2], [0, 2, 3]])
    assert len(src.count) == 2


def test_uv_seam_blocks_merging_but_continuous_uvs_merge():
    uv_cont = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float)
    assert len(_merge(SQUARE, [[0, 1, 2], [0, 2, 3]], attr=uv_cont).count) == 1
    uv_seam = uv_cont.copy()
    uv_seam[1, 2] = [0.5, 1.0]  # second triangle maps its far corner elsewhere
    assert len(_merge(SQUARE, [[0, 1, 2], [0, 2, 3]], attr=uv_seam).count) == 2


def test_disabled_merge_keeps_every_triangle():
    pos = np.asarray(SQUARE, float)
    src = merge_coplanar(pos, np.array([[0, 1, 2], [0, 2, 3]]), np.zeros((2, 3, 0)), np.zeros(2, np.int64),
                         EPS, 1e-12, enabled=False)
    assert len(src.count) == 2 and src.merged == 0


def test_attributes_that_do_not_show_do_not_block_merging():
    uv_seam = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0.5, 1]]], float)
    pos = np.asarray(SQUARE, float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    seen = np.zeros((2, 2), bool)  # an untextured material: its UVs are invisible
    src = merge_coplanar(pos, tris, uv_seam, np.zeros(2, np.int64), EPS, 1e-12, seen=seen)
    assert len(src.count) == 1
    # the values are still carried: each corner keeps the UV one of its triangles gave it
    corner_uv = {tuple(p): tuple(a) for p, a in zip(src.pos[0, :4], src.attr[0, :4])}
    assert corner_uv[(0.0, 1.0, 0.0)] == (0.5, 1.0) and corner_uv[(1.0, 0.0, 0.0)] == (1.0, 0.0)
