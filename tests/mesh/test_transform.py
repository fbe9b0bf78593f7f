"""Transform: front faces stay front faces under a camera projection, up axes, scale/fit/centre,
lights, and per-corner data following the reversed winding."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import ConvexHull

from bake.config import TransformConfig, TriangulateConfig
from bake.errors import ConfigError
from bake.mesh import transform as T
from bake.mesh.triangulate import stage as triangulate
from bake.scene import Light, make_scene


def convex_solid(seed=0, n=60):
    """A random convex polytope: triangles wound counter-clockwise seen from outside (right-handed),
    plus the outward normal of every face computed from the solid's centre, not from the winding."""
    rng = np.random.default_rng(seed)
    pts = rng.normal(size=(n, 3))
    pts /= np.linalg.norm(pts, axis=1, keepdims=True)
    pts *= rng.uniform(0.8, 1.2, size=(n, 1))
    hull = ConvexHull(pts)
    tris = hull.simplices.copy()
    centre = pts.mean(axis=0)
    p = pts[tris]
    n_ = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    out = np.einsum("ij,ij->i", n_, p.mean(axis=1) - centre) > 0
    tris[~out] = tris[~out][:, [0, 2, 1]]
    return pts, tris


def outward_visible(pts, tris, centre, camera):
    """Faces whose plane has the camera on its outer side (geometry only: the outward direction
    is the one pointing away from the solid's centre)."""
    p = pts[tris]
    fc = p.mean(axis=1)
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    n *= np.sign(np.einsum("ij,ij->i", n, fc - centre))[:, None]
    return np.einsum("ij,ij->i", n, camera - fc) > 0


def screen_winding(pts, tris, camera, forward_sign):
    """Perspective projection for a camera at ``camera`` looking along ``forward_sign * z``:
    screen x right, y up. Returns twice the signed screen area (> 0 counter-clockwise)."""
    rel = pts - camera
    depth = forward_sign * rel[:, 2]
    assert (depth > 0).all(), "everything must be in front of the camera"
    sx, sy = rel[:, 0] / depth, rel[:, 1] / depth
    a, b, c = tris[:, 0], tris[:, 1], tris[:, 2]
    return (sx[b] - sx[a]) * (sy[c] - sy[a]) - (sy[b] - sy[a]) * (sx[c] - sx[a])


@pytest.mark.parametrize("seed", [0, 1, 2])
def test_left_frame_keeps_front_faces_front_facing_under_projection(seed):
    pts, tris = convex_solid(seed)
    centre = pts.mean(axis=0)
    # right-handed (OpenGL) camera on the +z side looking along -z
    cam_rh = np.array([0.3, -0.2, 6.0])
    vis = outward_visible(pts, tris, centre, cam_rh)
    w_rh = screen_winding(pts, tris, cam_rh, forward_sign=-1)
    assert 0 < vis.sum() < len(tris)
    # the fixture is right: in the right-handed frame front faces are counter-clockwise on screen
    assert (w_rh[vis] > 0).all() and (w_rh[~vis] < 0).all()

    scene = make_scene(pts, tris)
    out, rec = T.stage(scene, TransformConfig(frame="left"))
    assert rec.details["winding_reversed"] is True
    np.testing.assert_array_equal(out.positions, pts * [1, 1, -1])
    # the same camera in the left-handed frame: mirrored position, looking along +z
    cam_lh = cam_rh * [1, 1, -1]
    vis_lh = outward_visible(out.positions, out.triangles, out.positions.mean(axis=0), cam_lh)
    np.testing.assert_array_equal(vis_lh, vis)  # the same faces face the camera
    w_lh = screen_winding(out.positions, out.triangles, cam_lh, forward_sign=+1)
    # documented convention: front faces are clockwise on screen for a camera looking along +z ...
    assert (w_lh[vis] < 0).all() and (w_lh[~vis] > 0).all()
    # ... and (v1 - v0) x (v2 - v0) still points out of the solid, towards the camera
    p = out.positions[out.triangles]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    outward = p.mean(axis=1) - out.positions.mean(axis=0)
    assert (np.einsum("ij,ij->i", n, outward) > 0).all()
    # polygons were reversed the same way (they are the triangles here)
    np.testing.assert_array_equal(out.poly_indices.reshape(-1, 3), out.triangles)


def test_without_reversal_the_mirror_would_turn_faces_inside_out():
    # the reason for the reversal: mirroring alone makes the cross-product normals point inwards
    pts, tris = convex_solid(5)
    mirrored = pts * [1, 1, -1]
    p = mirrored[tris]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (np.einsum("ij,ij->i", n, p.mean(axis=1) - mirrored.mean(axis=0)) < 0).all()


def test_right_frame_y_up_is_identity():
    pts, tris = convex_solid(3)
    scene = make_scene(pts, tris)
    out, rec = T.stage(scene, TransformConfig(frame="right"))
    np.testing.assert_array_equal(out.positions, pts)
    np.testing.assert_array_equal(out.triangles, tris)
    assert rec.details["winding_reversed"] is False
    np.testing.assert_array_equal(np.array(rec.details["matrix"]), np.eye(4))


@pytest.mark.parametrize("up,vec", [("y", [0, 1, 0]), ("z", [0, 0, 1]), ("-z", [0, 0, -1]),
                                    ("x", [1, 0, 0]), ("-x", [-1, 0, 0]), ("-y", [0, -1, 0])])
def test_up_axis_goes_to_plus_y_with_a_rotation(up, vec):
    R = T.frame_matrix(up, "right")
    np.testing.assert_allclose(R @ np.array(vec, float), [0, 1, 0])
    assert np.linalg.det(R) == pytest.approx(1.0)
    np.testing.assert_allclose(R @ R.T, np.eye(3))
    L = T.frame_matrix(up, "left")
    assert np.linalg.det(L) == pytest.approx(-1.0)
    np.testing.assert_allclose(L @ np.array(vec, float), [0, 1, 0])


def test_blender_z_up_model_lands_upright_and_facing_the_viewer():
    # Blender: z up, front view looks along +y, so the front of a model is its -y side.
    # A column: top at z = 2, a nose at y = -1 (its front).
    pts = np.array([[0, 0, 0], [0, 0, 2], [0, -1, 1], [1, 0, 1.0]])
    scene = make_scene(pts, [[0, 1, 2], [0, 1, 3]])
    out, _ = T.stage(scene, TransformConfig(up="z", frame="left"))
    np.testing.assert_allclose(out.positions[1], [0, 2, 0])  # top is up
    # left-handed: the viewer is at -z looking along +z, so the front is on the -z side
    assert out.positions[2][2] == pytest.approx(-1.0)
    np.testing.assert_allclose(out.positions[3], [1, 1, 0])  # x (right) unchanged
    out_r, _ = T.stage(scene, TransformConfig(up="z", frame="right"))
    assert out_r.positions[2][2] == pytest.approx(1.0)  # right-handed: towards the viewer is +z


def test_z_up_rotation_then_triangulation_keeps_outward_normals():
    # a closed quad box with z up, outward counter-clockwise: after up=z and the left frame the
    # quads are reversed, and the fan of the reversed quad still points outwards
    v = np.array([[x, y, z] for x in (0, 1) for y in (0, 2) for z in (0, 3)], float)
    quads = [[0, 1, 3, 2], [4, 6, 7, 5], [0, 4, 5, 1], [2, 3, 7, 6], [0, 2, 6, 4], [1, 5, 7, 3]]
    scene = make_scene(v, polygons=quads)
    c = v.mean(axis=0)
    for q in quads:  # fixture: outward counter-clockwise in the source frame
        p = v[q]
        assert np.dot(np.cross(p[1] - p[0], p[2] - p[0]), p.mean(axis=0) - c) > 0
    out, _ = T.stage(scene, TransformConfig(up="z", frame="left"))
    tri, _ = triangulate(out, TriangulateConfig())
    p = tri.triangle_vertices()
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    assert (np.einsum("ij,ij->i", n, p.mean(axis=1) - tri.positions.mean(axis=0)) > 0).all()
    # the box is 3 tall in z: now 3 tall in y
    ext = np.ptp(tri.positions, axis=0)
    np.testing.assert_allclose(ext, [1, 3, 2])


def test_transform_commutes_with_fan_triangulation():
    # reversing with corner 0 kept first means: fan(reversed polygon) == the fan's triangles,
    # each reversed (same oriented triangles, listed in the opposite order within the polygon)
    ang = np.linspace(0, 2 * np.pi, 8)[:-1]
    pts = np.c_[np.cos(ang), np.sin(ang), np.zeros(7)]
    scene = make_scene(np.r_[pts, pts[:4] + [0, 0, 1]], polygons=[list(range(7)), [7, 8, 9, 10]])
    a, _ = triangulate(T.stage(scene, TransformConfig())[0], TriangulateConfig())
    b, _ = T.stage(triangulate(scene, TriangulateConfig())[0], TransformConfig())

    def canonical(t):  # rotate each triangle so its smallest index is first (keeps orientation)
        r = np.argmin(t, axis=1)
        rolled = np.stack([t[np.arange(len(t)), (r + k) % 3] for k in range(3)], axis=1)
        return rolled[np.lexsort(rolled.T[::-1])]

    np.testing.assert_array_equal(canonical(a.triangles), canonical(b.triangles))
    assert a.triangles[:, 0].tolist() == b.triangles[:, 0].tolist()  # fans from the same corner
    np.testing.assert_array_equal(a.positions, b.positions)


def test_reversal_keeps_uvs_with_their_corners():
    pts = np.array([[0, 0, 0], [2, 0, 0], [2, 1, 0], [1, 2, 0], [0, 1, 0], [5, 5, 5], [6, 5, 5], [5, 6, 5]], float)
    scene = make_scene(pts, polygons=[[0, 1, 2, 3, 4], [5, 6, 7]])
    uv = pts[[0, 1, 2, 3, 4, 5, 6, 7], :2] * 0.1 + 0.05
    scene = scene.replace(poly_uvs=uv)
    tri, _ = triangulate(scene, TriangulateConfig())
    out, _ = T.stage(tri, TransformConfig(frame="left"))
    assert out.poly_indices.tolist() == [0, 4, 3, 2, 1, 5, 7, 6]
    # UV of every corner still belongs to its vertex: uv = source xy * 0.1 + 0.05
    np.testing.assert_allclose(out.poly_uvs, pts[out.poly_indices, :2] * 0.1 + 0.05)
    np.testing.assert_allclose(out.tri_uvs, pts[out.triangles][..., :2] * 0.1 + 0.05)
    np.testing.assert_array_equal(out.tri_polygon, tri.tri_polygon)
    # input not mutated
    assert scene.poly_indices.tolist() == [0, 1, 2, 3, 4, 5, 6, 7]
    np.testing.assert_array_equal(scene.poly_uvs, uv)


def test_scale_fit_and_center():
    rng = np.random.default_rng(0)
    pts = rng.uniform([-3, 10, 5], [7, 12, 6], size=(50, 3))
    pts = np.r_[pts, [[1e9, 1e9, 1e9]]]  # an unused vertex must not affect fit/centre
    scene = make_scene(pts, rng.integers(0, 50, size=(40, 3)))
    used = np.unique(scene.triangles)
    ext = np.ptp(pts[used], axis=0)

    out, _ = T.stage(scene, TransformConfig(frame="right", scale=2.0))
    np.testing.assert_allclose(out.positions, pts * 2.0)

    out, rec = T.stage(scene, TransformConfig(frame="right", scale=5.0, fit=4.0, center="bounds"))
    b = out.bounds()
    assert np.ptp(b, axis=0).max() == pytest.approx(4.0)
    np.testing.assert_allclose(np.ptp(b, axis=0), ext * 4.0 / ext.max())
    np.testing.assert_allclose(b.mean(axis=0), 0, atol=1e-12)
    np.testing.assert_allclose(rec.details["bounds_after"], b)
    np.testing.assert_allclose(rec.details["bounds_before"], scene.bounds())
    # the recorded matrix is what was applied
    M = np.array(rec.details["matrix"])
    np.testing.assert_allclose(out.positions, pts @ M[:3, :3].T + M[:3, 3])

    out, _ = T.stage(scene, TransformConfig(frame="left", up="z", center="base"))
    b = out.bounds()
    assert b[0, 1] == pytest.approx(0.0, abs=1e-12)
    assert b[0, 0] + b[1, 0] == pytest.approx(0.0, abs=1e-12)
    assert b[0, 2] + b[1, 2] == pytest.approx(0.0, abs=1e-12)
    np.testing.assert_allclose(np.ptp(b, axis=0), ext[[0, 2, 1]])


def test_lights_follow_the_model():
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 4.0]])
    sun = Light(kind="sun", direction=(0.0, 0.0, -1.0), source="model.gltf")
    point = Light(kind="point", position=(1.0, 2.0, 3.0), radius=0.5, range=10.0, source="model.gltf")
    scene = make_scene(pts, [[0, 1, 2], [0, 1, 3]]).replace(lights=(sun, point))
    out, rec = T.stage(scene, TransformConfig(up="z", frame="left", scale=3.0, center="bounds"))
    M = np.array(rec.details["matrix"])
    # a point light moves exactly like a vertex at its position
    probe = make_scene(np.r_[pts, [[1.0, 2.0, 3.0]]], [[0, 1, 2], [0, 1, 3]])
    moved = probe.positions @ M[:3, :3].T + M[:3, 3]
    np.testing.assert_allclose(out.lights[1].position, moved[4])
    assert out.lights[1].radius == pytest.approx(1.5) and out.lights[1].range == pytest.approx(30.0)
    # a sun pointing down (-z, source up = z) points down (-y) afterwards, still unit length
    np.testing.assert_allclose(out.lights[0].direction, [0, -1, 0], atol=1e-15)
    assert rec.details["lights_transformed"] == 2


def test_bad_values_are_config_errors():
    scene = make_scene(np.eye(3), [[0, 1, 2]])
    with pytest.raises(ConfigError):
        T.stage(scene, TransformConfig(up="w"))
    with pytest.raises(ConfigError):
        T.stage(scene, TransformConfig(scale=0.0))


def test_fit_on_a_point_warns_and_stays_finite():
    scene = make_scene(np.zeros((3, 3)), [[0, 1, 2]])
    out, rec = T.stage(scene, TransformConfig(fit=2.0, center="bounds"))
    assert np.isfinite(out.positions).all() and rec.warnings


def test_reverse_polygon_corners():
    perm = T.reverse_polygon_corners(np.array([3, 4, 5]))
    assert perm.tolist() == [0, 2, 1, 3, 6, 5, 4, 7, 11, 10, 9, 8]
