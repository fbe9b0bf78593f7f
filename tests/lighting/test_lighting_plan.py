"""Effect planning: nothing runs without a reason, every skip says why, rays are counted."""

from __future__ import annotations

import numpy as np
import pytest

from bake.config import LightConfig
from bake.errors import ConfigError
from bake.lighting.sampling import effective_samples
from bake.lighting.stage import stage
from bake.scene import Light
from lighting_geom import box, cfg, grid, merge, point, scene, sun


def _eff(rec):
    return {e["name"]: e for e in rec.effects}


def _plane():
    pos, tris = grid(4)
    return scene(pos, tris)


def test_no_lights_no_direct_pass_and_default_effects_skipped():
    out, rec = stage(_plane(), cfg(ambient=[0.5, 0.5, 0.5]))
    e = _eff(rec)
    assert not e["direct"]["ran"] and "no lights" in e["direct"]["reason"]
    assert not e["ao"]["ran"] and e["ao"]["reason"] == "lighting.ao.enabled = false" and e["ao"]["rays"] == 0
    assert not e["sky"]["ran"] and not e["bounces"]["ran"] and "count = 0" in e["bounces"]["reason"]
    assert not e["subdivide"]["ran"]
    assert rec.details["rays"] == 0 and rec.details["timing"]["build_seconds"] == 0  # no Embree scene
    np.testing.assert_allclose(out.artefacts.lighting.face_irradiance, 0.5)


def test_rays_counted_per_effect():
    sc = _plane()
    out, rec = stage(sc, cfg(ao__enabled=True, ao__samples=50, ambient=[0.2] * 3, lights=[sun((0, -1, 0), angle=1.0)],
                             shadows__samples=10, face_cell=1.0))
    e = _eff(rec)
    V = sc.n_vertices
    assert e["ao"]["rays"] == V * effective_samples(50) == V * 56
    assert e["light[0] sun"]["rays"] == V * effective_samples(10)
    assert rec.details["rays"] == e["ao"]["rays"] + e["light[0] sun"]["rays"]
    assert e["ao"]["seconds"] > 0 and "error" in e["ao"]


def test_light_that_reaches_no_surface_is_reported_and_casts_no_rays():
    sc = _plane()  # normal +y
    lights = [sun((0, 1, 0)),  # shines from below
              LightConfig(kind="spot", position=[0, 1, 0], direction=[0, 1, 0], outer_cone=30.0),  # points up
              point([0, 5, 0], range_=2.0),  # out of range
              point([0, 1, 0], intensity=0.0)]  # black
    out, rec = stage(sc, cfg(lights=lights, ambient=[0.1, 0.1, 0.1]))
    e = _eff(rec)
    for name in ("light[0] sun", "light[1] spot", "light[2] point"):
        assert not e[name]["ran"] and "reaches no surface" in e[name]["reason"] and e[name]["rays"] == 0
    assert not e["light[3] point"]["ran"] and "black" in e["light[3] point"]["reason"]
    assert rec.details["rays"] == 0


def test_fully_shadowed_light_is_reported():
    # a point light inside a closed outward box: it faces the plane below but every ray is blocked
    pos, tris = merge(grid(4, y=-2.0), box(2, half=0.5))
    sc = scene(pos, tris)
    out, rec = stage(sc, cfg(lights=[point([0, 0, 0], intensity=1.0)]))
    e = _eff(rec)["light[0] point"]
    assert e["ran"] and e["points_lit"] == 0 and e["rays"] > 0
    assert any("fully shadowed" in w for w in rec.warnings)


def test_imported_lights_used_unless_disabled():
    sc = _plane().replace(lights=(Light(kind="point", position=(0.0, 1.0, 0.0), intensity=2.0, name="lamp",
                                        source="model.gltf"),))
    out, rec = stage(sc, cfg())
    e = _eff(rec)
    assert e["light[0] point 'lamp'"]["ran"] and e["light[0] point 'lamp'"]["source"] == "model.gltf"
    res = out.artefacts.lighting
    i = np.argmin(np.linalg.norm(sc.positions - [0, 0, 0], axis=1))  # vertex under the lamp
    assert res.vertex["direct"][i, 0] == pytest.approx(2.0)  # intensity / d^2, cos = 1
    out2, rec2 = stage(sc, cfg(import_lights=False))
    e2 = _eff(rec2)
    assert not e2["imported lights"]["ran"] and "import_lights = false" in e2["imported lights"]["reason"]
    assert not e2["direct"]["ran"]


def test_ao_needs_ambient_light_to_darken():
    sc = _plane()
    # lights present and ambient black: AO would change nothing, so it does not run
    _, rec = stage(sc, cfg(ao__enabled=True, lights=[sun((0, -1, 0))]))
    assert not _eff(rec)["ao"]["ran"] and "ambient is black" in _eff(rec)["ao"]["reason"]
    # AO alone: ambient taken as white so the bake shows AO
    out, rec = stage(sc, cfg(ao__enabled=True))
    assert _eff(rec)["ao"]["ran"] and rec.details["ambient"] == [1.0, 1.0, 1.0]
    assert rec.details["notes"]


def test_bounces_need_light():
    _, rec = stage(_plane(), cfg(bounces__count=2))
    assert not _eff(rec)["bounces"]["ran"] and "nothing lights" in _eff(rec)["bounces"]["reason"]


@pytest.mark.parametrize("key,value", [("target", "texels"), ("ao__samples", 0), ("exposure", -1.0),
                                       ("bounces__samples", 0), ("max_triangles", -1)])
def test_bad_config_values_are_config_errors(key, value):
    with pytest.raises(ConfigError) as ei:
        stage(_plane(), cfg(**{key: value}))
    assert "lighting." in str(ei.value)


def test_lightmap_target_refuses_subdivision():
    with pytest.raises(ConfigError, match="lighting.subdivide"):
        stage(_plane(), cfg(target="lightmap", subdivide=True))


def test_empty_scene_is_skipped():
    from bake.scene import Scene
    out, rec = stage(Scene(), cfg(ao__enabled=True))
    assert not rec.effects[0]["ran"] and "no triangles" in rec.effects[0]["reason"]


def test_lit_bake_with_no_light_source_says_so_loudly():
    """Issue 17, item 1: lighting on, AO and sky off, no lights, ambient black: every colour is
    black; the record warns, lists an effect saying why, and marks it a problem (--strict fails)."""
    out, rec = stage(_plane(), cfg())
    assert np.all(out.face_colors[:, :3] == 0) and np.all(out.vertex_colors[:, :3] == 0)
    e = _eff(rec)
    assert not e["light sources"]["ran"] and "no light source" in e["light sources"]["reason"]
    assert e["all black"]["ran"] and "every lit colour is black: no light source" in e["all black"]["reason"]
    assert any("every lit colour is black" in w for w in rec.warnings)
    assert rec.problems and rec.problems[0] in rec.warnings
    assert rec.to_json()["problems"] == rec.problems


@pytest.mark.parametrize("kw,why", [
    (dict(lights=[sun((0, 1, 0))]), "no light reaches a surface"),  # shines from below
    (dict(lights=[sun((0, -1, 0))], exposure=0.0), "lighting.exposure = 0"),
    (dict(ambient=[1e-5] * 3), "too dim to show in 8 bits"),
])
def test_lit_bake_whose_every_colour_is_black_says_why(kw, why):
    out, rec = stage(_plane(), cfg(**kw))
    e = _eff(rec)
    assert e["light sources"]["ran"]  # there is a source, yet nothing shows
    assert why in e["all black"]["reason"] and rec.problems == [e["all black"]["reason"]]


def test_black_albedo_is_named_and_a_lit_bake_has_no_problem():
    pos, tris = grid(4)
    black = scene(pos, tris, color=(0.0, 0.0, 0.0, 1.0))
    _, rec = stage(black, cfg(lights=[sun((0, -1, 0))]))
    assert "albedo" in _eff(rec)["all black"]["reason"]
    for kw in (dict(lights=[sun((0, -1, 0))]), dict(ambient=[0.2] * 3), dict(ao__enabled=True),
               dict(sky__enabled=True, sky__samples=4)):
        out, rec = stage(_plane(), cfg(**kw))
        e = _eff(rec)
        assert e["light sources"]["ran"] and "all black" not in e and not rec.problems, kw
        assert out.face_colors[:, :3].max() > 0
    assert "ambient white (AO-only bake)" in _eff(stage(_plane(), cfg(ao__enabled=True))[1])["light sources"]["reason"]
