"""The reference traversal on hand-written lists (independent of the encoder)."""

from __future__ import annotations

import numpy as np
import pytest

from bake.bsp.traverse import draw_order, facing_flags

# triangles (1-based, as exported): 1 at z=1 facing +z, 2 at z=1 facing -z, 3 at z=2, 4 at z=0
VERTS = [0, 0, 1, 1, 0, 1, 0, 1, 1,
         0, 0, 2, 1, 0, 2, 0, 1, 2,
         0, 0, 0, 1, 0, 0, 0, 1, 0]
TRIS = [1, 2, 3, 1,  # z = 1, normal +z
        1, 3, 2, 1,  # z = 1, normal -z
        4, 5, 6, 1,  # z = 2, normal +z
        7, 8, 9, 1]  # z = 0, normal +z
PLANES = [0, 0, 1, 1]  # z - 1
# split on plane 1 (T = 2), back child at item 9, coplanar from triangle 1: 1 seen from the
# front, 1 from the back; front child (next record, item 6): leaf of triangle 3; back: leaf of 4
NODES = [2, 9, 1, 1, 1, 0, 3, 1, 0, 4, 1]


def test_split_record_from_both_sides():
    assert draw_order(NODES, PLANES, (0.2, 0.2, 5), TRIS, VERTS) == [4, 1, 3]
    assert draw_order(NODES, PLANES, (0.2, 0.2, -5), TRIS, VERTS) == [2]  # 3 and 4 face away
    assert draw_order(NODES, PLANES, (0.2, 0.2, -5), cull=False) == [3, 2, 4]
    # double-sided material: leaves draw everything facing either way
    assert draw_order(NODES, PLANES, (0.2, 0.2, -5), TRIS, VERTS, [True]) == [3, 2, 4]


def test_back_only_child_and_peel_record():
    # B < 0: no front child, back child at item -B
    nodes = [2, -6, 1, 1, 1, 0, 4, 1]
    assert draw_order(nodes, PLANES, (0, 0, 5), cull=False) == [4, 1]
    assert draw_order(nodes, PLANES, (0, 0, -5), cull=False) == [2, 4]
    # peel: triangle 4 first, then the child (a leaf of 1, 2), then triangle 3
    nodes = [1, 3, 1, 1, 0, 1, 2]
    assert draw_order(nodes, [], (0, 0, 5), cull=False) == [3, 1, 2, 4]


def test_two_sided_coplanar_group():
    # T <= -2: nA, nD, nB; eye in front draws nA + nD from first, behind draws nD + nB from first + nA
    nodes = [-2, 0, 1, 1, 1, 1, 0, 4, 1]  # front child: leaf of triangle 4
    assert draw_order(nodes, PLANES, (0, 0, 5), cull=False) == [1, 2, 4]
    assert draw_order(nodes, PLANES, (0, 0, -5), cull=False) == [4, 2, 3]


def test_facing_flags_match_the_per_triangle_test():
    for eye in [(0.2, 0.2, 5), (0.2, 0.2, -5), (3, -2, 1.5)]:
        f = facing_flags(TRIS, VERTS, eye)
        for t in range(1, 5):
            one = draw_order([0, t, 1], [], eye, TRIS, VERTS)
            assert bool(one) == bool(f[t - 1])


def test_stack_limit_is_enforced():
    with pytest.raises(RuntimeError):
        draw_order(NODES, PLANES, (0, 0, 5), cull=False, max_stack=1)
    assert np.array_equal(draw_order([], [], (0, 0, 0)), [])
