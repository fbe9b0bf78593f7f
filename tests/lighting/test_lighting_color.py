"""The colour pipeline: decode, light, exposure, tone map, encode; pluggable albedo."""

from __future__ import annotations

import numpy as np
import pytest

from bake.lighting import color as colmod
from bake.lighting.stage import stage
from lighting_geom import cfg, grid, scene, sun


def test_srgb_round_trip_and_known_values():
    x = np.linspace(0, 1, 1001)
    np.testing.assert_allclose(colmod.linear_to_srgb(colmod.srgb_to_linear(x)), x, atol=1e-12)
    assert colmod.srgb_to_linear(np.array([0.5]))[0] == pytest.approx(0.21404114, abs=1e-8)
    assert colmod.linear_to_srgb(np.array([0.0031308]))[0] == pytest.approx(0.04044994, abs=1e-7)


def _plane(color=(0.5, 0.25, 1.0, 0.5)):
    pos, tris = grid(2)
    return scene(pos, tris, color=color)


@pytest.mark.parametrize("space", ["srgb", "linear"])
@pytest.mark.parametrize("tone", ["clamp", "reinhard"])
def test_pipeline_exposure_tonemap_encode(space, tone):
    alb = np.array([0.5, 0.25, 1.0])
    d = np.array([0.0, -1.0, 1.0]) / np.sqrt(2)
    out, _ = stage(_plane(), cfg(lights=[sun(list(d), intensity=3.0)], exposure=0.8, tonemap=tone,
                                 color_space=space))
    cos = np.sqrt(0.5)
    lin = (colmod.srgb_to_linear(alb) if space == "srgb" else alb) * 3.0 * cos * 0.8
    mapped = np.minimum(lin, 1.0) if tone == "clamp" else lin / (1 + lin)
    want = colmod.linear_to_srgb(mapped) if space == "srgb" else mapped
    np.testing.assert_allclose(out.face_colors[:, :3], np.broadcast_to(want, (out.n_triangles, 3)), atol=1e-12)
    np.testing.assert_allclose(out.vertex_colors[:, :3], np.broadcast_to(want, (out.n_vertices, 3)), atol=1e-12)
    assert np.all(out.face_colors[:, 3] == 0.5) and np.all(out.vertex_colors[:, 3] == 0.5)


def test_vertex_output_light_and_extremes_stay_finite():
    out, _ = stage(_plane(), cfg(lights=[sun((0, -1, 0), intensity=1e30)], vertex_output="light"))
    assert np.all(out.vertex_colors[:, :3] == 1.0) and np.isfinite(out.face_colors).all()
    out, _ = stage(_plane(), cfg(lights=[sun((0, -1, 0), intensity=0.25)], vertex_output="light",
                                 color_space="linear"))
    np.testing.assert_allclose(out.vertex_colors[:, :3], 0.25)  # the light alone, no albedo


def test_albedo_is_pluggable():
    sc = _plane()
    red = lambda s: np.tile([1.0, 0.0, 0.0, 1.0], (s.n_triangles, 1))  # noqa: E731
    out, _ = stage(sc, cfg(lights=[sun((0, -1, 0))]), albedo=red)
    np.testing.assert_allclose(out.face_colors, np.tile([1.0, 0.0, 0.0, 1.0], (sc.n_triangles, 1)))
    green = sc.with_artefacts(albedo=lambda s: np.tile([0.0, 1.0, 0.0, 1.0], (s.n_triangles, 1)))
    out, _ = stage(green, cfg(lights=[sun((0, -1, 0))]))
    np.testing.assert_allclose(out.face_colors[:, 1], 1.0)
    out, _ = stage(sc, cfg(lights=[sun((0, -1, 0))]))  # the provider travels with its scene only
    np.testing.assert_allclose(out.face_colors, np.tile(sc.materials[0].color, (sc.n_triangles, 1)))
    bad = sc.with_artefacts(albedo=lambda s: np.zeros((1, 4)))
    with pytest.raises(ValueError):
        stage(bad, cfg(lights=[sun((0, -1, 0))]))
