"""Convergence (log error vs log samples), soft-shadow penumbra against an exact integral, and
determinism across reruns, thread counts and chunk sizes."""

from __future__ import annotations

import numpy as np
import pytest

from bake.lighting import rays as rays_mod
from bake.lighting.stage import stage
from lighting_geom import FRAME_IDS, FRAMES, box, cfg, convex_view_factor, grid, merge, scene, sphere, sun


def _slope(ns, errs):
    return float(np.polyfit(np.log(ns), np.log(errs), 1)[0])


def test_ao_error_falls_at_least_as_one_over_sqrt_samples():
    R = 0.5
    ball = sphere(3, radius=R, center=(0.0, R + 1e-3, 0.0))
    floor = grid(10, size=4.0)
    pos, tris = merge(floor, ball)
    sc = scene(pos, tris)
    nf = len(floor[0])
    exact = 1.0 - convex_view_factor(floor[0], np.tile([0.0, 1.0, 0.0], (nf, 1)), ball[0], ball[1])
    ns, errs, ses = [16, 64, 256, 1024], [], []
    for n in ns:
        out, _ = stage(sc, cfg(ao__enabled=True, ao__samples=n, ao__distance=1.0))
        r = out.artefacts.lighting
        errs.append(np.sqrt(np.mean((r.vertex["ao"][:nf] - exact) ** 2)))
        ses.append(np.sqrt(np.mean(r.vertex_se["ao"][:nf] ** 2)))
    assert _slope(ns, errs) <= -0.5, (errs, _slope(ns, errs))
    # the reported error tracks the real one (conservative, within a factor of 3)
    for e, s in zip(errs, ses):
        assert e <= s <= 3 * e


def _penumbra_scene(frame):
    # floor y = 0 and an occluding half-plane x < 0 at height H; sun straight down
    floor = grid(16, size=2.0)
    H = 1.0
    occ = (np.array([[-50.0, H, -50.0], [0.0, H, -50.0], [0.0, H, 50.0], [-50.0, H, 50.0]]),
           np.array([[0, 2, 1], [0, 3, 2]]))
    pos, tris = merge(floor, occ)
    return scene(pos, tris, frame), floor, H


def _exact_visible(x, H, half_angle, n=800):
    """Fraction of a sun disc (uniform in solid angle, radius half_angle about -y) whose
    directions pass x > 0 at height H, from floor points at x: exact 2-D quadrature."""
    c = 1 - (np.arange(n) + 0.5) / n * (1 - np.cos(half_angle))  # cos(theta) uniform in solid angle
    s = np.sqrt(1 - c * c)
    phi = (np.arange(n) + 0.5) / n * 2 * np.pi
    dx = s[:, None] * np.cos(phi)[None, :]
    out = []
    for xi in x:
        xh = xi + H * dx / c[:, None]  # where the ray crosses y = H
        out.append(np.mean(xh > 0))
    return np.array(out)


@pytest.mark.parametrize("frame", FRAMES, ids=FRAME_IDS)
def test_soft_shadow_penumbra_matches_exact_integral_and_converges(frame):
    sc, floor, H = _penumbra_scene(frame)
    angle = 20.0  # degrees, a wide sun so the penumbra spans several vertices
    nf = len(floor[0])
    x = floor[0][:, 0]
    exact = _exact_visible(x, H, np.radians(angle) / 2)
    band = (exact > 0) & (exact < 1)
    assert band.sum() > 20
    ns, errs = [4, 16, 64, 256], []
    for n in ns:
        out, rec = stage(sc, cfg(lights=[sun((0, -1, 0), angle=angle)], shadows__samples=n))
        r = out.artefacts.lighting
        vis = r.vertex["direct"][:nf, 0]  # cos = 1 on the floor
        se = r.vertex_se["direct"][:nf]
        assert np.all(np.abs(vis - exact) <= 4 * se + 1e-9)
        errs.append(np.sqrt(np.mean((vis - exact)[band] ** 2)))
    assert np.all(vis[exact == 1] == 1) and np.all(vis[exact == 0] == 0)
    assert _slope(ns, errs) <= -0.5, errs


def _bake_bytes(sc, c):
    out, _ = stage(sc, c)
    return out.vertex_colors.tobytes() + out.face_colors.tobytes()


def test_deterministic_across_runs_threads_and_chunks(monkeypatch):
    R = 0.5
    pos, tris = merge(grid(8, size=4.0), sphere(2, radius=R, center=(0, R, 0)))
    sc = scene(pos, tris)
    base = dict(ao__enabled=True, ao__samples=64, ambient=[0.3, 0.3, 0.3], lights=[sun((0.3, -1, 0.2), angle=8.0)],
                sky__enabled=True, sky__samples=16, bounces__count=1, bounces__samples=16, face_cell=0.1)
    a = _bake_bytes(sc, cfg(threads=1, **base))
    b = _bake_bytes(sc, cfg(threads=1, **base))
    c = _bake_bytes(sc, cfg(threads=2, **base))
    d = _bake_bytes(sc, cfg(threads=3, **base))
    monkeypatch.setattr(rays_mod, "CHUNK_RAYS", 1000)  # many more, smaller work items
    e = _bake_bytes(sc, cfg(threads=2, **base))
    assert a == b == c == d == e
    f = _bake_bytes(sc, cfg(threads=2, seed=1, **base))
    assert f != a  # the seed does change the noise


def _cluttered_floor():
    """A floor with spheres and a cube on it: thousands of points, most partly occluded."""
    parts = [grid(30, size=4.0)]
    rng = np.random.default_rng(3)
    for _ in range(8):
        r = rng.uniform(0.15, 0.45)
        c = rng.uniform(-1.6, 1.6, 3)
        c[1] = r * rng.uniform(0.6, 1.5)
        parts.append(sphere(2, radius=r, center=tuple(c)))
    b = box(2, half=0.35)
    parts.append((b[0] + [0.8, 0.35, -0.9], b[1]))
    pos, tris = parts[0]
    for p in parts[1:]:
        pos, tris = merge((pos, tris), p)
    return scene(pos, tris)


def test_ao_error_figure_is_calibrated_against_a_high_sample_reference():
    """Issue 17, item 6: the AO effect's ``error`` estimates the RMSE of the AO values against
    the exact ones honestly: not below it, and not 1.5x above it (the uncalibrated pair estimate
    was 1.4x here, 1.55x on the bunny). Actual = RMSE against the mean of two independent
    2048-ray bakes, minus that reference's own variance; pooled over four seeds."""
    sc = _cluttered_floor()
    kw = dict(ao__enabled=True, ao__distance=0.25, face_cell=10.0)
    r1 = stage(sc, cfg(ao__samples=2048, seed=101, **kw))[0].artefacts.lighting
    r2 = stage(sc, cfg(ao__samples=2048, seed=202, **kw))[0].artefacts.lighting
    ev = r1.vertex_evaluated
    assert ev.sum() > 2000
    ref = (r1.vertex["ao"][ev] + r2.vertex["ao"][ev]) / 2
    ref_var = np.mean((r1.vertex["ao"][ev] - r2.vertex["ao"][ev]) ** 2) / 4
    for n in (16, 64, 256):
        est2, act2 = [], []
        for seed in range(4):
            out, rec = stage(sc, cfg(ao__samples=n, seed=seed, **kw))
            res = out.artefacts.lighting
            assert np.array_equal(res.vertex_evaluated, ev)  # the same points as the figure covers
            act2.append(np.mean((res.vertex["ao"][ev] - ref) ** 2) - ref_var)
            ao = [e for e in rec.effects if e["name"] == "ao"][0]
            est2.append(ao["error"] ** 2)
            assert ao["error_bound"] >= ao["error"]  # the conservative figure stays conservative
        ratio = float(np.sqrt(np.mean(est2) / np.mean(act2)))
        assert ref_var < 0.05 * np.mean(act2)  # the reference is far more accurate than the bake
        assert 1.0 <= ratio <= 1.3, (n, ratio)
