"""Bounced light: the furnace test (exact geometric series) and plausibility."""

from __future__ import annotations

import numpy as np
import pytest

from bake.lighting.stage import stage
from lighting_geom import FRAME_IDS, FRAMES, box, cfg, grid, merge, scene, sphere, sun


@pytest.mark.parametrize("frame", FRAMES, ids=FRAME_IDS)
@pytest.mark.parametrize("target", ["vertex", "triangle"])
def test_furnace_closed_room_gives_geometric_series(frame, target):
    # inside a closed room every bounce ray hits a front face lit by the same ambient a, so
    # after n bounces E = a (1 + rho + ... + rho^n) exactly, whatever the sampling
    rho, a = 0.6, 0.5
    pos, tris = box(4, half=1.0, inward=True)
    sc = scene(pos, tris, frame, color=(rho, rho, rho, 1.0))
    for n in (1, 2, 3):
        out, rec = stage(sc, cfg(target=target, color_space="linear", ambient=[a, a, a], bounces__count=n,
                                 bounces__samples=16, face_cell=0.2))
        res = out.artefacts.lighting
        want = a * sum(rho ** k for k in range(n + 1))
        np.testing.assert_allclose(res.face_irradiance, want, rtol=1e-9)
        if target == "vertex":
            np.testing.assert_allclose(res.vertex_irradiance, want, rtol=1e-9)
        e = {x["name"]: x for x in rec.effects}["bounces"]
        assert e["ran"] and e["count"] == n and e["rays"] > 0
        # rays are cast once whatever the number of bounces
        if n == 1:
            rays1 = e["rays"]
        assert e["rays"] == rays1


def test_open_plane_gets_no_bounce_and_sphere_gets_floor_light():
    pos, tris = grid(6, size=2.0)
    # nothing to bounce off: every ray misses
    out, _ = stage(scene(pos, tris), cfg(lights=[sun((0, -1, 0))], bounces__count=1, bounces__samples=16))
    assert np.all(out.artefacts.lighting.vertex["indirect"] == 0)
    R = 0.3
    ball = sphere(2, radius=R, center=(0, R + 0.05, 0))
    floor = grid(8, size=4.0)
    p2, t2 = merge(floor, ball)
    out, rec = stage(scene(p2, t2, color=(0.7, 0.7, 0.7, 1)),
                     cfg(lights=[sun((0, -1, 0))], bounces__count=1, bounces__samples=64))
    res = out.artefacts.lighting
    nf = len(floor[0])
    bottom = np.flatnonzero(ball[0][:, 1] < R * 0.5) + nf  # lower part of the sphere: in the sun's shadow
    assert np.all(res.vertex["direct"][bottom] == 0)
    assert res.vertex["indirect"][bottom].min() > 0.05  # lit by the floor
    # energy: bounced light is at most albedo x the brightest direct light
    assert res.vertex["indirect"].max() <= 0.7 ** 2.2 * 1.0 + 1e-9


def test_back_face_hits_bring_no_light():
    # a floor piece inside a closed cube whose normals point out: every bounce ray meets the back
    # of a wall. The walls are lit (ambient) on their outside only, so nothing may come back.
    inner = grid(2, size=0.5, y=-0.2)
    shell = box(2, half=1.0)
    pos, tris = merge(inner, shell)
    out, rec = stage(scene(pos, tris), cfg(ambient=[1.0, 1.0, 1.0], bounces__count=2, bounces__samples=16,
                                          color_space="linear"))
    res = out.artefacts.lighting
    ni = len(inner[0])
    assert np.all(res.vertex["indirect"][:ni] == 0)
    assert {e["name"]: e for e in rec.effects}["bounces"]["rays"] > 0
