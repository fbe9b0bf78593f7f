"""Analytic properties of the light baker, each in the unit frame and again with the scene
translated by 1e5 and scaled by 1e-3 (robust origins: no acne, no leaks)."""

from __future__ import annotations

import numpy as np
import pytest

from bake.lighting.color import linear_to_srgb, srgb_to_linear
from bake.lighting.stage import stage
from lighting_geom import (FRAME_IDS, FRAMES, at, box, cfg, convex_view_factor, grid, merge, point, scene,
                           sphere, sun)


@pytest.mark.parametrize("frame", FRAMES, ids=FRAME_IDS)
@pytest.mark.parametrize("target", ["vertex", "triangle"])
def test_sun_on_open_plane_is_exactly_cos_theta(frame, target):
    pos, tris = grid(6)
    sc = scene(pos, tris, frame, color=(0.5, 0.6, 0.7, 1.0))
    for d, angle in (((0, -1, 0), 0.0), ((0.3, -1, 0.2), 0.53), ((-1, -0.4, 0.5), 5.0), ((1, -0.05, 0), 2.0)):
        c = cfg(target=target, lights=[sun(d, angle=angle)], face_cell=0.2)
        out, rec = stage(sc, c)
        res = out.artefacts.lighting
        dd = np.asarray(d, float) / np.linalg.norm(d)
        cos = -dd[1]
        if target == "vertex":
            np.testing.assert_allclose(res.vertex["direct"][res.vertex_evaluated], cos, rtol=1e-12, atol=0)
        np.testing.assert_allclose(res.face["direct"], cos, rtol=1e-12, atol=0)
        # shown colour: sRGB(albedo_lin x cos), alpha kept
        want = linear_to_srgb(srgb_to_linear(np.array([0.5, 0.6, 0.7])) * cos)
        np.testing.assert_allclose(out.face_colors[:, :3], np.broadcast_to(want, (out.n_triangles, 3)), atol=1e-12)
        assert np.all(out.face_colors[:, 3] == 1.0)
        eff = {e["name"]: e for e in rec.effects}
        assert eff["light[0] sun"]["ran"] and eff["light[0] sun"]["rays"] > 0
        # nothing shadows the plane: only the 1/N resolution floor remains in the estimate
        assert eff["light[0] sun"]["error"] <= 1.0 / eff["light[0] sun"]["samples"] + 1e-12


@pytest.mark.parametrize("frame", FRAMES, ids=FRAME_IDS)
def test_ao_of_isolated_plane_and_convex_bodies_is_exactly_one(frame):
    for (pos, tris), target in ((grid(8), "vertex"), (sphere(2), "vertex"), (sphere(2), "triangle"),
                                (box(4), "vertex"), (box(4), "triangle")):
        sc = scene(pos, tris, frame)
        out, rec = stage(sc, cfg(target=target, ao__enabled=True, ao__samples=256, ao__distance=2.0,
                                 face_cell=0.15))
        res = out.artefacts.lighting
        assert np.all(res.vertex["ao"][res.vertex_evaluated] == 1.0), "self-intersection (acne)"
        assert np.all(res.face["ao"] == 1.0)
        assert res.vertex_evaluated.any() if target == "vertex" else res.face_sampled.all()
        assert rec.effects[[e["name"] for e in rec.effects].index("ao")]["rays"] > 0


@pytest.mark.parametrize("frame", FRAMES, ids=FRAME_IDS)
def test_closed_box_lit_from_outside_is_exactly_zero_inside(frame):
    # a room (normals inward) with a cube inside it, and an outward cube with a sphere inside
    room = box(4, half=1.0, inward=True)
    inner = box(2, half=0.3)
    shell = box(4, half=1.0)
    ball = sphere(2, radius=0.5)
    for (pos, tris), n_inside in ((merge(room, inner), len(room[1]) + len(inner[1])),
                                  (merge(ball, shell), len(ball[1]))):
        sc = scene(pos, tris, frame)
        c = cfg(lights=[sun((0.4, -1, 0.3), angle=3.0), point(at((2.5, 2.0, 1.5), frame), radius=0.3 * frame[1],
                                                                 intensity=5.0 * frame[1] ** 2)],
                sky__enabled=True, sky__samples=64, bounces__count=2, bounces__samples=32,
                shadows__samples=16, face_cell=0.2)
        out, rec = stage(sc, c)
        res = out.artefacts.lighting
        inside_t = np.arange(n_inside)
        inside_v = np.unique(tris[inside_t])
        assert np.all(res.face_irradiance[inside_t] == 0.0), "light leaked into the closed box"
        assert np.all(res.vertex_irradiance[inside_v] == 0.0), "light leaked into the closed box"
        assert np.all(out.face_colors[inside_t, :3] == 0.0)
        if len(tris) == len(ball[1]) + len(shell[1]):  # the outside of the shell is lit: not vacuous
            assert res.face_irradiance[len(ball[1]):].max() > 0.5


@pytest.mark.parametrize("frame", FRAMES, ids=FRAME_IDS)
def test_sphere_on_plane_ao_matches_exact_view_factor_and_reference(frame):
    R, gap = 0.5, 1e-3
    ball = sphere(3, radius=R, center=(0.0, R + gap, 0.0))
    floor = grid(10, size=4.0)
    pos, tris = merge(floor, ball)
    sc = scene(pos, tris, frame)
    c = cfg(ao__enabled=True, ao__samples=256, ao__distance=1.0, face_cell=0.0 + 1.0)
    out, _ = stage(sc, c)
    res = out.artefacts.lighting
    nf = len(floor[0])
    # exact: 1 - form factor of the (tessellated, convex) sphere from each floor vertex
    p = floor[0]
    exact = 1.0 - convex_view_factor(p, np.tile([0.0, 1.0, 0.0], (nf, 1)), ball[0], ball[1])
    ao, se = res.vertex["ao"][:nf], res.vertex_se["ao"][:nf]
    assert se.max() > 0  # some points see the sphere
    z = (ao - exact) / np.maximum(se, 1e-12)
    assert np.all(np.abs(ao - exact) <= 4 * se + 1e-9), f"max |z| = {np.abs(z).max():.2f}"
    assert abs(float(np.mean(ao - exact))) < 3 * np.sqrt(np.mean(se ** 2) / nf) + 1e-9  # no bias
    # all points (sphere too) against an independent 8x-sample reference, within the error estimate
    ref, _ = stage(sc, cfg(ao__enabled=True, ao__samples=2048, ao__distance=1.0, seed=7))
    rr = ref.artefacts.lighting
    ev = res.vertex_evaluated
    tot = np.sqrt(res.vertex_se["ao"][ev] ** 2 + rr.vertex_se["ao"][ev] ** 2)
    zz = (res.vertex["ao"][ev] - rr.vertex["ao"][ev]) / np.maximum(tot, 1e-12)
    assert np.mean(np.abs(zz) > 3) < 0.01
    assert np.sqrt(np.mean(zz[tot > 0] ** 2)) < 1.2


def test_sky_on_open_plane_and_wall():
    # upward plane, nothing around: E = horizon + (zenith - horizon) * E[cos] with E[cos] = 2/3 for
    # cosine-weighted directions; with a uniform sky exactly the sky colour
    pos, tris = grid(4)
    sc = scene(pos, tris)
    out, _ = stage(sc, cfg(sky__enabled=True, sky__color=[0.9, 0.9, 0.9], sky__horizon=[0.9, 0.9, 0.9],
                           sky__intensity=1.0))
    np.testing.assert_allclose(out.artefacts.lighting.vertex["sky"], 0.9, rtol=1e-12)
    z, h = np.array([0.2, 0.4, 1.0]), np.array([0.8, 0.6, 0.4])
    out, _ = stage(sc, cfg(sky__enabled=True, sky__color=list(z), sky__horizon=list(h), sky__samples=1024))
    r = out.artefacts.lighting
    want = h + (z - h) * 2 / 3
    lum = r.vertex["sky"] @ [0.2126, 0.7152, 0.0722]
    assert np.all(np.abs(lum - want @ [0.2126, 0.7152, 0.0722]) <= 4 * r.vertex_se["sky"] + 1e-9)
    # a vertical wall sees half sky, half ground (by symmetry of the cosine lobe)
    wall = scene(pos[:, [1, 0, 2]], tris[:, ::-1])
    out, _ = stage(wall, cfg(sky__enabled=True, sky__color=[1, 1, 1], sky__horizon=[1, 1, 1],
                             sky__ground=[0, 0, 0], sky__samples=1024))
    r = out.artefacts.lighting
    assert np.all(np.abs(r.vertex["sky"][:, 0] - 0.5) <= 4 * r.vertex_se["sky"])


def test_far_apart_objects_have_no_acne():
    # two small objects 1e4 apart: float32 resolution at the far one is ~1e-3 of its size, so the
    # offset must grow with the distance from the scene centre, not only with the scene size
    a = grid(4, size=1.0)
    b_pos, b_tris = sphere(2, radius=0.5)
    pos, tris = merge(a, (b_pos + [1e4, 3e3, -2e3], b_tris))
    out, _ = stage(scene(pos, tris, (1e5, 1.0)), cfg(target="triangle", ao__enabled=True, ao__samples=64,
                                                     ao__distance=1e-4))
    res = out.artefacts.lighting
    assert np.all(res.face["ao"] == 1.0)
