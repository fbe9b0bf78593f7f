"""Ambient occlusion through ``lighting.target = "lightmap"`` against a brute-force reference.

The reference: a floor point (y = 0, normal +y) next to one axis-aligned box; AO is the
cosine-weighted fraction of the hemisphere with no box face within ``lighting.ao.distance`` x
the scene's diagonal, counted with 100,000 random rays and an exact ray/box slab test (no
Embree, no baker code). The floor cannot occlude its own upward rays, so the box is the only
occluder.

Both targets must match it: the per-triangle bake (triangle colours) and the lightmap (texel
colours read back with bilinear lookups), with AO recovered from a shown colour as
``decode(colour) / decode(albedo)`` (AO only scales a white ambient here). Far from the box
(no face within the AO distance) every ray escapes and the colour is exactly the material
colour, at any sample count.

Regression: the lightmap target shaded its texels with the albedo of the *lit* scene, whose
vertex colours are the per-triangle bake's lit colours, so ``Scene.triangle_albedo`` multiplied
albedo and light in a second time: an open floor with material colour (204, 204, 191) came out
(163, 163, 143) alone and (137, 137, 120) in the report's scene (AO read back as 0.54 where it
is 1).
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import trimesh

from bake.config import LightingConfig, TexturesConfig
from bake.lighting import stage as lighting_stage
from bake.lighting.lightmap import bake_lightmap
from bake.scene import Material, make_scene
from bake.textures import stage as tstage
from bake.colorspace import srgb_to_linear
from bake.textures.texels import bilinear
from lighting_geom import grid

FLOOR = (0.8, 0.8, 0.75)
BOX = ((-0.6, 0.0, -0.6), (0.6, 1.2, 0.6))
AO_SAMPLES = 256
REF_RAYS = 100_000
Z = 4.0  # standard errors a point may be off


def floor_and_box(box=True, vertex_colors=None):
    """A 6 x 6 floor of 12 x 12 quads (so each small triangle's colour is its own point value)
    and, optionally, a closed box standing on it."""
    pos, tris = grid(12, size=6.0)
    mat = np.zeros(len(tris), np.int64)
    if box:
        m = trimesh.creation.box(bounds=BOX)
        tris = np.concatenate([tris, np.asarray(m.faces) + len(pos)])
        pos = np.concatenate([pos, np.asarray(m.vertices, float)])
        mat = np.concatenate([mat, np.ones(len(m.faces), np.int64)])
    vc = None
    if vertex_colors is not None:
        vc = np.tile(np.append(vertex_colors, 1.0), (len(pos), 1))
    return make_scene(pos, tris, materials=(Material("floor", color=(*FLOOR, 1.0)),
                                            Material("box", color=(0.9, 0.1, 0.1, 1.0))),
                      tri_material=mat, vertex_colors=vc)


def with_atlas(scene, tmp_path):
    cfg = TexturesConfig(enabled=True)
    cfg.lightmap = dataclasses.replace(cfg.lightmap, enabled=True, resolution=128, cache_dir=str(tmp_path))
    out, _ = tstage.stage(scene, cfg)
    return out


def ao_config(target: str, samples: int = AO_SAMPLES) -> LightingConfig:
    c = LightingConfig(enabled=True, target=target)  # ambient black: AO-only, white ambient
    c.ao = dataclasses.replace(c.ao, enabled=True, samples=samples)
    return c


def brute_ao(xz: np.ndarray, lo, hi, dist: float, n: int = REF_RAYS, seed: int = 0) -> tuple[float, float]:
    """AO at floor point (x, z) with the box [lo, hi] as the only occluder: (mean, standard error)."""
    rng = np.random.default_rng(seed)
    u, v = rng.random(n), rng.random(n)
    r, phi = np.sqrt(u), 2.0 * np.pi * v
    d = np.stack([r * np.cos(phi), np.sqrt(1.0 - u), r * np.sin(phi)], axis=1)  # cosine about +y
    o = np.array([xz[0], 0.0, xz[1]])
    with np.errstate(divide="ignore", invalid="ignore"):
        t1 = (np.asarray(lo) - o) / d
        t2 = (np.asarray(hi) - o) / d
        tmin = np.nanmax(np.minimum(t1, t2), axis=1)
        tmax = np.nanmin(np.maximum(t1, t2), axis=1)
    hit = (tmax >= tmin) & (tmin > 0) & (tmin <= dist)
    a = 1.0 - hit.mean()
    return a, float(np.sqrt(max(a * (1.0 - a), 1.0 / n) / n))


def box_gap(xz: np.ndarray) -> np.ndarray:
    """Distance in the floor plane from points (n, 2) to the box's footprint."""
    lo, hi = np.array(BOX[0])[[0, 2]], np.array(BOX[1])[[0, 2]]
    return np.linalg.norm(np.maximum(np.maximum(lo - xz, xz - hi), 0.0), axis=1)


def ao_from_colour(rgb: np.ndarray, albedo=FLOOR) -> np.ndarray:
    """AO read back from shown colours (N, 3) in [0, 1]: linear colour / linear albedo (green)."""
    return srgb_to_linear(np.asarray(rgb, float))[:, 1] / srgb_to_linear(np.array(albedo, float))[1]


def lightmap_at(scene, tri: np.ndarray, xyz: np.ndarray) -> np.ndarray:
    """Bilinear lookups of the baked lightmap (RGB in [0, 1]) at points of the given triangles."""
    img = scene.artefacts.lightmap_image[..., :3] / 255.0
    uvs = scene.artefacts.lightmap.atlas.tri_uvs[tri]  # (n, 3, 2)
    p = scene.positions[scene.triangles[tri]]  # (n, 3, 3)
    e1, e2, w = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0], xyz - p[:, 0]
    # barycentrics in the floor plane (x, z)
    det = e1[:, 0] * e2[:, 2] - e1[:, 2] * e2[:, 0]
    s = (w[:, 0] * e2[:, 2] - w[:, 2] * e2[:, 0]) / det
    t = (e1[:, 0] * w[:, 2] - e1[:, 2] * w[:, 0]) / det
    uv = uvs[:, 0] + s[:, None] * (uvs[:, 1] - uvs[:, 0]) + t[:, None] * (uvs[:, 2] - uvs[:, 0])
    return bilinear(img, uv)


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    """The floor-and-box scene baked both ways, and the reference AO at floor triangle centroids
    clear of the box (>= 0.3 from it: a bilinear lookup then reads no texel under the box)."""
    scene = with_atlas(floor_and_box(), tmp_path_factory.mktemp("atlas"))
    lm, _ = lighting_stage.stage(scene, ao_config("lightmap"))
    tri, _ = lighting_stage.stage(scene, ao_config("triangle"))
    dist = LightingConfig().ao.distance * scene.scale()
    floor = np.flatnonzero(scene.tri_material == 0)
    cen = scene.positions[scene.triangles[floor]].mean(axis=1)
    keep = box_gap(cen[:, [0, 2]]) >= 0.3
    floor, cen = floor[keep], cen[keep]
    ref = np.array([brute_ao(c[[0, 2]], BOX[0], BOX[1], dist, seed=i) for i, c in enumerate(cen)])
    return {"scene": scene, "lm": lm, "tri": tri, "floor": floor, "cen": cen, "ref": ref[:, 0],
            "ref_se": ref[:, 1], "dist": dist}


def test_lone_floor_is_its_material_colour_in_both_targets(tmp_path):
    """No occluder: AO = 1 at every point, so every texel and every triangle shows the material
    colour (up to 8-bit rounding), whatever the sample count."""
    scene = with_atlas(floor_and_box(box=False), tmp_path)
    want = np.rint(np.array(FLOOR) * 255)  # decode then encode: the colour itself
    lm, rec = lighting_stage.stage(scene, ao_config("lightmap", samples=16))
    assert "AO is the only effect: ambient taken as white [1, 1, 1]" in rec.details["notes"]
    img = lm.artefacts.lightmap_image[..., :3].astype(float)
    covered = img.sum(axis=2) > 0  # covered and padding texels (the rest stay black)
    assert covered.mean() > 0.3
    assert np.abs(img[covered] - want).max() <= 1, np.unique(img[covered].reshape(-1, 3), axis=0)[:4]
    tri, _ = lighting_stage.stage(scene, ao_config("triangle", samples=16))
    assert np.abs(tri.face_colors[:, :3] * 255 - np.array(FLOOR) * 255).max() < 0.5


def test_far_from_the_box_the_floor_is_its_material_colour(baked):
    """Points with no box face within the AO distance: the reference is exactly 1 and so must be
    both bakes (the report's open corners)."""
    far = box_gap(baked["cen"][:, [0, 2]]) > baked["dist"] + 0.3
    assert far.sum() >= 8 and np.all(baked["ref"][far] == 1.0)
    want = np.array(FLOOR) * 255
    got_lm = lightmap_at(baked["lm"], baked["floor"][far], baked["cen"][far]) * 255
    assert np.abs(got_lm - want).max() <= 1.0, got_lm[:3]
    got_tri = baked["tri"].face_colors[baked["floor"][far], :3] * 255
    assert np.abs(got_tri - want).max() < 0.5, got_tri[:3]


def test_triangle_target_matches_brute_force_ao(baked):
    """Each small floor triangle's colour is AO at its centroid (one interior point): within Z
    standard errors (the bake's own, conservative, plus the reference's) of the reference, and
    unbiased over all of them."""
    res = baked["tri"].artefacts.lighting
    f = baked["floor"]
    assert np.all(res.face_sampled[f])
    got = ao_from_colour(baked["tri"].face_colors[f, :3])
    np.testing.assert_allclose(got, res.face["ao"][f], atol=1e-9)  # colour = albedo x AO exactly
    se = np.sqrt(res.face_se["ao"][f] ** 2 + baked["ref_se"] ** 2)
    d = got - baked["ref"]
    near = baked["ref"] < 0.99
    assert near.sum() >= 20  # points the box actually darkens
    assert np.all(np.abs(d) <= Z * se), (np.abs(d) / se).max()
    assert abs(d.mean()) <= Z * np.sqrt((se ** 2).mean() / len(d)), d.mean()


def test_lightmap_target_matches_brute_force_ao(baked):
    """Lightmap lookups at the same points: a texel averages about ``lighting.ao.samples`` rays
    (``supersample^2`` points x samples / supersample^2), so its binomial standard error
    sqrt(a (1 - a) / samples) is conservative (the rays are stratified); add 8-bit rounding
    and the texel's area (a bilinear lookup averages the light over about a texel) as 0.01."""
    got = ao_from_colour(lightmap_at(baked["lm"], baked["floor"], baked["cen"]))
    ref = baked["ref"]
    a = np.clip(ref, 0.0, 1.0)
    se = np.sqrt(np.maximum(a * (1.0 - a), 1.0 / AO_SAMPLES) / AO_SAMPLES + baked["ref_se"] ** 2)
    d = got - ref
    assert np.all(np.abs(d) <= Z * se + 0.01), (d[np.argmax(np.abs(d) - Z * se)], got[:4], ref[:4])
    assert abs(d.mean()) <= Z * np.sqrt((se ** 2).mean() / len(d)) + 0.005, d.mean()
    # and the two targets agree with each other on average (the report's comparison)
    tri = ao_from_colour(baked["tri"].face_colors[baked["floor"], :3])
    assert abs((got - tri).mean()) < 0.01


def test_lightmap_keeps_vertex_colours_and_a_lit_scene_rebakes_the_same(tmp_path):
    """The albedo of a lightmap texel is the *unlit* base colour (material x the model's own
    vertex colours), never the lit colours the lighting stage writes into the vertex colours: a
    lone vertex-coloured floor shows exactly that albedo, and baking the lightmap again from the
    lighting stage's output (``bake_lightmap(lit scene)``, as the benchmark does) gives the
    same image."""
    vc = (1.0, 0.6, 0.4)
    scene = with_atlas(floor_and_box(box=False, vertex_colors=vc), tmp_path)
    cfg = ao_config("lightmap", samples=4)
    lm, _ = lighting_stage.stage(scene, cfg)
    img = lm.artefacts.lightmap_image[..., :3].astype(float)
    covered = img.sum(axis=2) > 0
    want = np.rint(np.array(FLOOR) * np.array(vc) * 255)
    assert np.abs(img[covered] - want).max() <= 1
    again, _ = bake_lightmap(lm.replace(lists={}), cfg)
    np.testing.assert_array_equal(again.artefacts.lightmap_image, lm.artefacts.lightmap_image)
    # linear in, linear out: the same light with colour_space = "linear"
    lin = dataclasses.replace(cfg, color_space="linear")
    out, _ = lighting_stage.stage(scene, lin)
    img = out.artefacts.lightmap_image[..., :3].astype(float)
    assert np.abs(img[covered] - want).max() <= 1
