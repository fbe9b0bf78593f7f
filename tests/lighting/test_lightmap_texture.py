"""A "color" lightmap of a textured model carries the texture (``bake.lighting.lightmap.texel_albedo``):
the reader's textured filler draws texture and light from the lightmap alone. Under a uniform
white ambient light, no lights and no AO, a texel's lit colour is its albedo, so the lightmap's
texels must be the texture's own colours (each within 2 levels of a texel of the texture), where
the triangle-mean albedo of the flat bake would give blends no texel has."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bake import config, pipeline
from bake.scratch.colors import decode_numbers
from conftest import CORPUS

BOX = CORPUS / "box_textured_glb" / "BoxTextured.glb"  # a logo: sharp colours, far from their mean


def _bake(**lighting):
    data = {"input": {"path": str(BOX)}, "export": {"sb3": False, "sprite3": False},
            "lighting": {"enabled": True, "target": "lightmap", "ambient": [1.0, 1.0, 1.0], "lights": [],
                         "ao": {"enabled": False}, **lighting},
            "textures": {"lightmap": {"enabled": True, "resolution": 64}}}
    return pipeline.run(config.load(data=data))


def _off_palette(res) -> np.ndarray:
    """Per lightmap texel: levels to the nearest colour of the material's texture."""
    lists = json.loads(res.scene.artefacts.outputs["lists.json"])["lists"]
    lm = decode_numbers(np.asarray(lists["tex lightmap"], np.int64))[:, :3].astype(np.int64)
    tex = next(t for t in res.scene.artefacts.textures.textures if t.image is not None)
    palette = np.unique(tex.image[:, :, :3].reshape(-1, 3).astype(np.int64), axis=0)
    return np.abs(lm[:, None, :] - palette[None, :, :]).max(axis=2).min(axis=1)


@pytest.mark.skipif(not BOX.exists(), reason="corpus textured box missing")
def test_a_lit_textured_lightmap_holds_the_textures_colours():
    res = _bake()
    d = _off_palette(res)
    # (the atlas's background, texels no chart covers, is dilated chart colour: every texel counts)
    assert (d <= 2).mean() >= 0.95, np.percentile(d, [50, 90, 99])


@pytest.mark.skipif(not BOX.exists(), reason="corpus textured box missing")
def test_without_the_texture_at_each_texel_the_lightmap_would_not_hold_its_colours(monkeypatch):
    """The control: each texel lit with its triangle's mean albedo (the lightmap before the texture
    went into it) fails the same measure."""
    from bake.lighting import lightmap

    monkeypatch.setattr(lightmap, "texel_albedo", lambda scene, base=None: None)
    res = _bake()
    d = _off_palette(res)
    assert (d <= 2).mean() < 0.95
