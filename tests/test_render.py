"""The numpy software rasterizer: coverage, depth, z-buffer vs painter, culling, near clipping."""

from __future__ import annotations

import numpy as np
import pytest

from bake.render import Camera, render, render_scene, scene_triangles, scene_two_sided
from bake.scene import Material, make_scene


def quad(z, half=1.0, cx=0.0, cy=0.0, facing_camera=True):
    """Two triangles of a square at depth z (camera at the origin looking down +z... see cam)."""
    a = [cx - half, cy - half, z]
    b = [cx + half, cy - half, z]
    c = [cx + half, cy + half, z]
    d = [cx - half, cy + half, z]
    t = np.array([[a, b, c], [a, c, d]], float)
    return t if facing_camera else t[:, ::-1]


# camera at the origin looking along -z (so the front side of a face must point to +z)
CAM = Camera(position=(0, 0, 0), look_at=(0, 0, -1), fov=90, width=64, height=64, near=1e-3)


def _front(t):
    """Orient triangles so they face the camera at the origin (normal towards +z)."""
    n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
    flip = n[:, 2] < 0
    t = t.copy()
    t[flip] = t[flip][:, ::-1]
    return t


def test_square_covers_the_expected_pixels_and_depth_is_exact():
    # a square at distance 2 spanning [-1, 1]: with fov 90 it covers half the width
    t = _front(quad(-2.0))
    img = render(CAM, t)
    cols = np.flatnonzero(img.covered.any(0))
    rows = np.flatnonzero(img.covered.any(1))
    assert (cols.min(), cols.max()) == (16, 47) and (rows.min(), rows.max()) == (16, 47)
    assert img.covered.sum() == 32 * 32
    assert np.allclose(img.depth[img.covered], 2.0)


def test_perspective_correct_depth_on_a_tilted_plane():
    # plane z = -2 - 0.5 x seen from the origin: depth at each pixel centre is analytic
    t = np.array([[[-1, -1, -1.5], [1, -1, -2.5], [1, 1, -2.5]], [[-1, -1, -1.5], [1, 1, -2.5], [-1, 1, -1.5]]])
    img = render(CAM, _front(t))
    H = W = 64
    f = CAM.focal
    ys, xs = np.nonzero(img.covered)
    # ray through the pixel centre: direction (x', y', -1) with x' = (px + .5 - W/2) / f
    xr = (xs + 0.5 - W / 2) / f
    # depth z along the view axis solves z = 2 + 0.5 * x, x = xr * z  ->  z = 2 / (1 - 0.5 xr)
    expect = 2.0 / (1.0 - 0.5 * xr)
    np.testing.assert_allclose(img.depth[ys, xs], expect, rtol=1e-9)
    assert H == CAM.height


def test_zbuffer_keeps_the_nearest_painter_keeps_the_last():
    near = _front(quad(-2.0, half=0.5))
    far = _front(quad(-4.0, half=2.0))
    tri = np.concatenate([near, far])
    z = render(CAM, tri)
    c = 32
    assert z.tri_id[c, c] in (0, 1)  # the near square
    p = render(CAM, tri, mode="painter", order=[0, 1, 2, 3])  # far drawn last: covers it
    assert p.tri_id[c, c] in (2, 3)
    p2 = render(CAM, tri, mode="painter", order=[2, 3, 0, 1])
    # same square everywhere (pixels on a square's diagonal are covered by both its halves)
    assert (p2.tri_id // 2 == z.tri_id // 2).all()
    # triangles left out of the order are not drawn
    p3 = render(CAM, tri, mode="painter", order=[2, 3])
    assert p3.tri_id[c, c] in (2, 3) and not np.isin(p3.tri_id, [0, 1]).any()


def test_back_faces_are_culled_unless_two_sided():
    back = _front(quad(-2.0))[:, ::-1]
    assert not render(CAM, back).covered.any()
    assert render(CAM, back, two_sided=np.array([True, True])).covered.sum() == 32 * 32
    assert render(CAM, back, cull=False).covered.sum() == 32 * 32


def test_triangles_crossing_the_near_plane_are_clipped():
    # a floor under the camera running from behind it to far ahead
    floor = np.array([[[-5, -1, 5], [5, -1, 5], [5, -1, -50]], [[-5, -1, 5], [5, -1, -50], [-5, -1, -50]]], float)
    n = np.cross(floor[:, 1] - floor[:, 0], floor[:, 2] - floor[:, 0])
    floor[n[:, 1] < 0] = floor[n[:, 1] < 0][:, ::-1]  # face up, towards the camera
    img = render(CAM, floor)
    assert img.covered[-1].all()  # the row at the bottom of the screen sees the floor
    assert not img.covered[: 32].any()  # nothing above the horizon
    assert np.isfinite(img.depth[img.covered]).all() and (img.depth[img.covered] > 0).all()
    # something entirely behind the camera is invisible
    assert not render(CAM, _front(quad(+2.0))).covered.any()


def test_edge_distance_is_small_on_edges_and_large_inside():
    big = _front(np.array([[[-2, -2, -2], [2, -2, -2], [0, 2, -2]]], float))
    img = render(CAM, big)
    assert img.edge[40, 32] > 10  # well inside the triangle...
    ys, xs = np.nonzero(img.covered)
    bottom = ys.max()
    assert img.edge[bottom, 32] < 1.0  # ...the last covered row is on its bottom edge


def test_scene_helpers_and_colors():
    mats = (Material("a", (1, 0, 0, 1)), Material("b", (0, 1, 0, 1), double_sided=True))
    t = _front(quad(-2.0))
    s = make_scene(t.reshape(-1, 3), np.arange(6).reshape(2, 3), materials=mats, tri_material=[0, 1])
    assert scene_triangles(s).shape == (2, 3, 3) and list(scene_two_sided(s)) == [False, True]
    img = render(CAM, scene_triangles(s), colors=s.triangle_albedo(), background=(0, 0, 1))
    assert img.to_uint8().shape == (64, 64, 3)
    assert (img.image[0, 0] == [0, 0, 1]).all()
    seen = set(map(tuple, img.image[img.covered].tolist()))
    assert seen == {(1.0, 0.0, 0.0), (0.0, 1.0, 0.0)}


def test_bad_arguments():
    with pytest.raises(ValueError):
        render(CAM, quad(-2.0), mode="ray")
    with pytest.raises(ValueError):
        Camera((0, 0, 0), (0, 0, 0)).basis()


def test_render_scene_uses_albedo_sidedness_and_order():
    mats = (Material("a", (1, 0, 0, 1)), Material("b", (0, 1, 0, 1), double_sided=True))
    near = _front(quad(-2.0, half=0.5))
    far = _front(quad(-4.0, half=2.0))[:, ::-1]  # facing away, but double-sided
    t = np.concatenate([near, far])
    s = make_scene(t.reshape(-1, 3), np.arange(12).reshape(4, 3), materials=mats, tri_material=[0, 0, 1, 1])
    z = render_scene(s, CAM)
    assert tuple(z.image[32, 32]) == (1.0, 0.0, 0.0) and tuple(z.image[20, 20]) == (0.0, 1.0, 0.0)
    p = render_scene(s, CAM, mode="painter", order=[0, 1, 2, 3])  # far one drawn last
    assert tuple(p.image[32, 32]) == (0.0, 1.0, 0.0)
    shaded = render_scene(s, CAM, shade=True)
    assert 0.9 < shaded.image[32, 32, 0] <= 1.0  # facing the camera: nearly full colour
