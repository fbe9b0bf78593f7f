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
    # ray through the pixel centre: screen x' = (px + .5 - W/2) / f; looking along -z in the
    # left-handed frame (x right when looking along +z) the screen's right is world -x
    xr = (xs + 0.5 - W / 2) / f
    # depth z along the view axis solves z = 2 + 0.5 * x, x = -xr * z  ->  z = 2 / (1 + 0.5 xr)
    expect = 2.0 / (1.0 + 0.5 * xr)
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


# --------------------------------------------------------------------------- the frame: no mirror
def _arrow():
    """An asymmetric model: a big triangle pointing to +x (its tip at x = 3) and a small one
    above it, at z = 0, both facing a camera in front (at -z, looking along +z)."""
    tip = np.array([[[-1.0, -1.0, 0.0], [-1.0, 1.0, 0.0], [3.0, 0.0, 0.0]],
                    [[-0.5, 1.5, 0.0], [-0.5, 2.5, 0.0], [0.5, 1.5, 0.0]]])
    n = np.cross(tip[:, 1] - tip[:, 0], tip[:, 2] - tip[:, 0])
    assert (n[:, 2] < 0).all()  # fronts face -z: towards the camera
    return tip


def test_plus_x_is_drawn_right_and_plus_y_up_as_in_a_scratch_engine():
    """The documented frame (x right, y up, z into the screen): a camera in front of the model
    looking along +z draws the point (3, 0, 0) right of the centre, (0, 2, 0) above it. A
    mirrored camera (right = forward x up) puts the tip on the left and fails this."""
    cam = Camera(position=(0, 0, -10), look_at=(0, 0, 0), fov=40, width=200, height=150)
    img = render(cam, _arrow())
    f = cam.focal
    # the pixel of a known point: the tip at (3, 0, 0), one pixel inside it; the small triangle
    col = int(np.floor(100 + f * 2.9 / 10))
    row = int(np.floor(75 - f * 0.0 / 10))
    assert img.tri_id[row, col] == 0, "the tip of the arrow (+x) is not right of the centre"
    assert not img.covered[row, 200 - 1 - col]
    row_up = int(np.floor(75 - f * 1.8 / 10))
    assert img.tri_id[row_up, int(np.floor(100 + f * -0.3 / 10))] == 1, "+y is not up"
    cols = np.flatnonzero(img.covered.any(0))
    assert cols.max() - 100 > 100 - cols.min()  # the long side of the arrow is on the right


def test_camera_basis_is_left_handed():
    eye, r, u, f = Camera((0, 0, -5), (0, 0, 0)).basis()
    np.testing.assert_allclose(r, [1, 0, 0], atol=1e-15)
    np.testing.assert_allclose(u, [0, 1, 0], atol=1e-15)
    # (right, up, forward) is oriented as (x, y, z): the view frame is the world's own frame turned
    np.testing.assert_allclose(np.cross(r, u), f, atol=1e-15)
    # from behind (looking along -z) +x is on the left
    _, r2, _, _ = Camera((0, 0, 5), (0, 0, 0)).basis()
    np.testing.assert_allclose(r2, [-1, 0, 0], atol=1e-15)


def test_the_reader_sprites_camera_model_gives_the_same_pixels():
    """``Camera.yaw_pitch`` is the reader sprite's projection (bake/scratch/readers.py
    ``project``, the arithmetic of its blocks): every vertex of a random model lands on the same
    stage pixel in both, and the triangle the render shows at a triangle's centroid pixel is that
    triangle, for cameras turned every way."""
    from bake.scratch import readers

    rng = np.random.default_rng(7)
    pts = rng.normal(size=(40, 3))
    for yaw, pitch in ((0.0, 0.0), (30.0, -20.0), (-125.5, 35.25), (170.0, 10.0)):
        cam = readers.Camera(x=1.0, y=0.5, z=-2.0, yaw=yaw, pitch=pitch, focal=300.0, near=0.01)
        sy, cy = np.sin(np.radians(yaw)), np.cos(np.radians(yaw))
        sp, cp = np.sin(np.radians(pitch)), np.cos(np.radians(pitch))
        fwd = np.array([sy * cp, sp, cy * cp])
        world = np.array([cam.x, cam.y, cam.z]) + 8.0 * fwd + pts  # in front of the camera
        px, py, pz = readers.project(world, cam)
        rc = Camera.yaw_pitch((cam.x, cam.y, cam.z), yaw, pitch, cam.focal, near=cam.near)
        eye, r, u, f = rc.basis()
        rel = world - eye
        sx = rel @ r / (rel @ f) * rc.focal + 240.0  # render.py's screen position
        sy_ = 180.0 - rel @ u / (rel @ f) * rc.focal
        np.testing.assert_allclose(sx - 240.0, px, atol=1e-6)
        np.testing.assert_allclose(180.0 - sy_, py, atol=1e-6)
        np.testing.assert_allclose(rel @ f, pz * cam.focal, rtol=1e-9)  # pz: depth / focal
        # one small triangle around each point: seen at the point's pixel
        tri = world[:, None, :] + np.array([[-0.05, -0.05, 0], [0.0, 0.07, 0], [0.05, -0.05, 0]]) @ \
            np.stack([r, u, f])
        img = render(rc, tri, cull=False)
        col = np.floor(px + 240.0).astype(int)
        row = np.floor(180.0 - py).astype(int)
        ok = (col >= 0) & (col < 480) & (row >= 0) & (row < 360)
        assert ok.sum() > 20
        seen = img.tri_id[row[ok], col[ok]]
        assert (seen >= 0).all()
        # where triangles overlap the nearer one shows: it must be within a few px
        own = seen == np.flatnonzero(ok)
        assert own.mean() > 0.7
