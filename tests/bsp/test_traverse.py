"""The reference traversal on hand-written lists (independent of the encoder)."""

from __future__ import annotations

import numpy as np
import pytest

from bake.bsp.traverse import draw_order, draw_ranges, facing_flags

# triangles (1-based, as exported): 1 at z=1 facing +z, 2 at z=1 facing -z, 3 at z=2, 4 at z=0
VERTS = [0, 0, 1, 1, 0, 1, 0, 1, 1,
         0, 0, 2, 1, 0, 2, 0, 1, 2,
         0, 0, 0, 1, 0, 0, 0, 1, 0]
TRIS = [1, 2, 3, 1,  # z = 1, normal +z
        1, 3, 2, 1,  # z = 1, normal -z
        4, 5, 6, 1,  # z = 2, normal +z
        7, 8, 9, 1]  # z = 0, normal +z
PLANES = [0, 0, 1, 1]  # z - 1
# split on plane 1 (T = 4: its d is item 4), back child at item 10, coplanar: triangle 1 seen
# from the front (fF = 1, nF = 1), triangle 2 from the back (fB = 2, nB = 1); front child (the
# next record, item 7): leaf of triangle 3; back: leaf of 4
NODES = [4, 10, 1, 1, 2, 1, 0, 3, 1, 0, 4, 1]


def test_split_record_from_both_sides():
    assert draw_order(NODES, PLANES, (0.2, 0.2, 5), TRIS, VERTS) == [4, 1, 3]
    assert draw_order(NODES, PLANES, (0.2, 0.2, -5), TRIS, VERTS) == [2]  # 3 and 4 face away
    assert draw_order(NODES, PLANES, (0.2, 0.2, -5), cull=False) == [3, 2, 4]
    # double-sided material: leaves draw everything facing either way
    assert draw_order(NODES, PLANES, (0.2, 0.2, -5), TRIS, VERTS, [True]) == [3, 2, 4]


def test_back_only_child_and_peel_record():
    # B < 0: no front child, back child at item -B
    nodes = [4, -7, 1, 1, 2, 1, 0, 4, 1]
    assert draw_order(nodes, PLANES, (0, 0, 5), cull=False) == [4, 1]
    assert draw_order(nodes, PLANES, (0, 0, -5), cull=False) == [2, 4]
    assert draw_ranges(nodes, PLANES, (0, 0, -5)) == [(2, 1), (4, 1)]
    # peel: triangle 3 first, then the child (a leaf of 1, 2), then triangle 4
    nodes = [1, 3, 1, 4, 1, 0, 1, 2]
    assert draw_order(nodes, [], (0, 0, 5), cull=False) == [3, 1, 2, 4]
    assert draw_ranges(nodes, [], (0, 0, 5)) == [(3, 1), (1, 2), (4, 1)]


def test_two_sided_coplanar_group():
    # triangles 1 (front), 2 (two-sided), 3 (back): the eye in front draws 1, 2 (fF = 1, nF = 2),
    # behind 2, 3 (fB = 2, nB = 2)
    nodes = [4, 0, 1, 2, 2, 2, 0, 4, 1]  # front child: leaf of triangle 4
    assert draw_order(nodes, PLANES, (0, 0, 5), cull=False) == [1, 2, 4]
    assert draw_order(nodes, PLANES, (0, 0, -5), cull=False) == [4, 2, 3]


def test_empty_coplanar_range_is_not_emitted_and_the_eye_on_the_plane_is_in_front():
    nodes = [4, 0, 1, 0, 1, 1, 0, 4, 1]
    assert draw_ranges(nodes, PLANES, (0, 0, 5)) == [(4, 1)]
    assert draw_ranges(nodes, PLANES, (0, 0, 1.0)) == [(4, 1)]
    assert draw_ranges(nodes, PLANES, (0, 0, 0.5)) == [(4, 1), (1, 1)]


def test_facing_flags_match_the_per_triangle_test():
    for eye in [(0.2, 0.2, 5), (0.2, 0.2, -5), (3, -2, 1.5)]:
        f = facing_flags(TRIS, VERTS, eye)
        for t in range(1, 5):
            one = draw_order([0, t, 1], [], eye, TRIS, VERTS)
            assert bool(one) == bool(f[t - 1])
            v = np.asarray(VERTS, float).reshape(-1, 3)[np.asarray(TRIS).reshape(-1, 4)[t - 1, :3] - 1]
            n = np.cross(v[1] - v[0], v[2] - v[0])
            assert bool(f[t - 1]) == bool(n @ (np.asarray(eye) - v[0]) > 0)


def test_stack_limit_is_enforced():
    with pytest.raises(RuntimeError):
        draw_order(NODES, PLANES, (0, 0, 5), cull=False, max_stack=1)
    assert np.array_equal(draw_order([], [], (0, 0, 0)), [])
