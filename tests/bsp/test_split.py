"""Robust splitting: snapping, no slivers, exact areas, interpolated attributes, bit-exact welds."""

from __future__ import annotations

import numpy as np
import pytest

from bake.bsp.split import FaceStore, face_planes, polygon_area, split_faces, triangle_store

EPS = 1e-6
MIN_AREA = 1e-12


def _store(tris, attr=None):
    tris = np.asarray(tris, np.float64).reshape(-1, 3, 3)
    vid = np.arange(3 * len(tris)).reshape(-1, 3)  # every corner its own scene vertex
    return triangle_store(tris, MIN_AREA, attr=attr, vid=vid)


def _split(st, plane, ids=None):
    ids = np.arange(st.n) if ids is None else ids
    return split_faces(st, ids, np.asarray([plane], np.float64), np.zeros(len(ids), np.int64), EPS, MIN_AREA)


def _corners(st, f):
    return st.pos[f, :st.count[f]]


def test_cut_through_two_edges_gives_triangle_and_quad_with_exact_area():
    tri = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    st = _store([tri])
    res = _split(st, [1, 0, 0, 0.25])  # x = 0.25
    assert res.splits == 1 and len(res.front) == 1 and len(res.back) == 1
    f, b = res.front[0], res.back[0]
    assert {st.count[f], st.count[b]} == {3, 4}  # front (x > .25) is a triangle, back a quad
    total = polygon_area(st.pos[[f]])[0] + polygon_area(st.pos[[b]])[0]
    assert total == pytest.approx(0.5, rel=1e-14)
    assert (_corners(st, f)[:, 0] >= 0.25 - 1e-15).all() and (_corners(st, b)[:, 0] <= 0.25 + 1e-15).all()


def test_cut_through_a_vertex_gives_two_triangles_not_a_sliver():
    tri = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    st = _store([tri])
    # the plane x = y passes exactly through corner (0, 0, 0)
    n = np.array([1.0, -1.0, 0.0]) / np.sqrt(2)
    res = _split(st, [*n, 0.0])
    assert res.splits == 1
    assert st.count[res.front[0]] == 3 and st.count[res.back[0]] == 3


def test_vertex_within_tolerance_is_snapped_onto_the_plane():
    tri = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    st = _store([tri])
    # misses corner (0, 0, 0) by 1e-9 (well inside EPS): still two triangles, no sliver piece
    n = np.array([1.0, -1.0, 0.0]) / np.sqrt(2)
    res = _split(st, [*n, 1e-9])
    assert res.splits == 1
    counts = sorted(int(st.count[i]) for i in np.concatenate([res.front, res.back]))
    assert counts == [3, 3]
    areas = polygon_area(st.pos[np.concatenate([res.front, res.back])])
    assert areas.min() > 0.2  # both halves are real pieces
    # but a plane missing the corner by more than EPS really cuts the corner off
    st2 = _store([tri])
    res2 = _split(st2, [*n, 1e-3])
    assert sorted(int(st2.count[i]) for i in np.concatenate([res2.front, res2.back])) == [3, 4]


def test_piece_below_min_area_keeps_the_fragment_whole():
    tri = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]
    st = _store([tri])
    # cuts a corner piece off 1.5e-6 from corner (1, 0, 0): beyond EPS, so not snapped, but its
    # area (~1.1e-12) is below the 1e-11 minimum
    res = split_faces(st, np.array([0]), np.array([[1.0, 0, 0, 1 - 1e-6 * 1.5]]), np.zeros(1, np.int64),
                      EPS, 1e-11)
    assert res.splits == 0 and res.kept_whole == 1
    assert list(res.back) == [0] and len(res.front) == 0  # kept on the side with the area


def test_coplanar_faces_are_grouped_by_the_side_they_face():
    up = [[0, 0, 0], [1, 0, 0], [0, 1, 0]]  # normal +z
    down = [[0, 0, 0], [0, 1, 0], [1, 0, 0]]  # normal -z
    st = _store([up, down])
    res = _split(st, [0, 0, 1, 0])
    assert list(res.on) == [0, 1] and list(res.on_side) == [0, 1]
    assert res.splits == 0


def test_attributes_are_interpolated_affinely_onto_new_vertices():
    rng = np.random.default_rng(3)
    tri = rng.normal(size=(1, 3, 3))
    # an affine attribute field (like UVs or colours): a(x) = G x + c
    G = rng.normal(size=(6, 3))
    c = rng.normal(size=6)
    attr = np.einsum("tkc,ac->tka", tri, G) + c
    st = _store(tri, attr=attr)
    cen = tri[0].mean(0)
    n = rng.normal(size=3)
    n /= np.linalg.norm(n)
    res = _split(st, [*n, n @ cen])
    assert res.splits == 1
    for f in np.concatenate([res.front, res.back]):
        k = st.count[f]
        expect = st.pos[f, :k] @ G.T + c
        np.testing.assert_allclose(st.attr[f, :k], expect, rtol=0, atol=1e-12)
        # corners made by the cut are marked as new vertices
        assert ((st.vid[f, :k] == -1) == (np.abs(st.pos[f, :k] @ n - n @ cen) < 1e-12)).all()


def test_edge_shared_by_two_triangles_gives_bit_identical_new_vertices():
    rng = np.random.default_rng(7)
    a, b, c, d = rng.normal(size=(4, 3))
    st = _store([[a, b, c], [b, a, d]])  # share edge a-b, opposite directions
    mid = (a + b) / 2
    n = (b - a) / np.linalg.norm(b - a)  # a plane crossing edge a-b at its middle
    res = _split(st, [*n, n @ mid])
    assert res.splits == 2
    new = []
    for f in np.concatenate([res.front, res.back]):
        k = st.count[f]
        new += [tuple(p) for p, v in zip(st.pos[f, :k], st.vid[f, :k]) if v == -1 and abs(p @ n - n @ mid) < 1e-12]
    # the new vertex on the shared edge is computed identically from both triangles
    on_edge = [p for p in new if np.linalg.norm(np.cross(np.array(p) - a, b - a)) < 1e-9]
    assert len(on_edge) == 4 and len(set(on_edge)) == 1


def test_degenerate_fragments_are_never_cut():
    st = _store([[[0, 0, 0], [1, 0, 0], [2, 0, 0]]])  # zero area
    assert st.src_degenerate[0]
    res = _split(st, [1, 0, 0, 1.5])
    assert res.splits == 0 and res.kept_whole == 0
    assert len(res.front) + len(res.back) == 1


def test_face_planes_match_the_winding_and_flag_degenerate_faces():
    pos = np.array([[[0, 0, 1], [1, 0, 1], [0, 1, 1]], [[0, 0, 0], [1, 1, 1], [2, 2, 2]]], float)
    pl, deg = face_planes(pos, np.array([3, 3]), MIN_AREA)
    np.testing.assert_allclose(pl[0], [0, 0, 1, 1])
    assert list(deg) == [False, True] and (pl[1, :3] == 0).all()


def test_store_pads_with_corner_zero_so_reductions_need_no_mask():
    st = FaceStore(np.zeros((1, 3, 3)) + [[0, 0, 0], [1, 0, 0], [0, 1, 0]], np.array([3]), np.zeros((1, 3, 0)),
                   np.full((1, 3), -1), np.array([[0, 0, 1, 0.0]]), np.array([False]), np.array([False]))
    # growing to 5 corners pads the existing fragment with its corner 0
    st.append(np.zeros((1, 5, 3)), np.zeros((1, 5, 0)), np.full((1, 5), -1), np.array([5]), np.array([0]))
    assert st.K == 5 and (st.pos[0, 3:] == st.pos[0, 0]).all()
