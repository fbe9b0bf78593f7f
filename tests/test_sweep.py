"""bake.sweep: one bake per value, errors against the highest value or a reference, JSON + PNG."""

from __future__ import annotations

import json

import numpy as np
import pytest

from bake import config as config_mod
from bake.errors import ConfigError
from bake.scene import make_scene
from bake.sweep import parse_vary, sweep


def _scene(n=9):
    import trimesh

    s = trimesh.creation.icosphere(subdivisions=2, radius=0.4)
    sv = np.asarray(s.vertices) + [0, 0.41, 0]
    g = np.linspace(-1.5, 1.5, n)
    xx, zz = np.meshgrid(g, g, indexing="ij")
    fp = np.stack([xx.ravel(), np.zeros(xx.size), zz.ravel()], 1)
    idx = np.arange(n * n).reshape(n, n)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    ft = np.concatenate([np.stack([a, d, c], 1), np.stack([a, c, b], 1)])
    if np.cross(fp[ft[0, 1]] - fp[ft[0, 0]], fp[ft[0, 2]] - fp[ft[0, 0]])[1] < 0:
        ft = ft[:, ::-1]
    return make_scene(np.concatenate([fp, sv]), np.concatenate([ft, np.asarray(s.faces) + n * n]))


def _cfg():
    cfg = config_mod.load(None)
    cfg.lighting.enabled = True
    cfg.lighting.ao.enabled = True
    return cfg


def test_parse_vary():
    assert parse_vary("lighting.ao.samples=16,64, 256") == ("lighting.ao.samples", [16, 64, 256])
    assert parse_vary("lighting.exposure=0.5,1") == ("lighting.exposure", [0.5, 1])
    with pytest.raises(ConfigError):
        parse_vary("lighting.ao.enabled=1,2")  # not numeric
    with pytest.raises(ConfigError):
        parse_vary("lighting.ao.samples=a,b")
    with pytest.raises(ConfigError):
        parse_vary("lighting.ao.sample=1")


def test_sweep_ao_samples_against_reference_writes_json_and_png(tmp_path):
    sc = _scene()
    out = tmp_path / "sweep_ao"
    table = sweep(_cfg(), "lighting.ao.samples", [4, 16, 64, 256], reference=4096, scene=sc, out=out)
    rows = table["rows"]
    assert [r["value"] for r in rows] == [4, 16, 64, 256]
    rmse = [r["rmse"] for r in rows]
    assert all(x > 0 for x in rmse) and all(a > b for a, b in zip(rmse, rmse[1:]))
    assert table["slope"] <= -0.5
    for r in rows:
        assert r["max_error"] >= r["rmse"] and r["seconds"] > 0 and r["rays"] > 0
        assert "ao" in r["reported_error"] and r["components"]["ao"]["rmse"] > 0
        assert not r["reference"]
    assert rows[1]["rays"] == 4 * rows[0]["rays"]
    j = json.loads((tmp_path / "sweep_ao.json").read_text())
    assert j["key"] == "lighting.ao.samples" and j["reference"]["kind"] == "reference run"
    png = (tmp_path / "sweep_ao.png").read_bytes()
    assert png[:8] == b"\x89PNG\r\n\x1a\n" and len(png) > 5000


def test_sweep_against_highest_value_and_errors():
    sc = _scene()
    table = sweep(_cfg(), "lighting.ao.samples", [64, 8, 1024], scene=sc)
    rows = table["rows"]
    assert [r["value"] for r in rows] == [8, 64, 1024]
    assert rows[-1]["reference"] and rows[-1]["rmse"] == 0.0
    assert rows[0]["rmse"] > rows[1]["rmse"] > 0
    with pytest.raises(ConfigError):
        sweep(_cfg(), "lighting.ao.samples", [1.5], scene=sc)  # int key
    with pytest.raises(ConfigError):
        sweep(_cfg(), "lighting.ao.nope", [1], scene=sc)


def test_sweep_soft_shadow_samples():
    sc = _scene(41)
    cfg = _cfg()
    cfg.lighting.ao.enabled = False
    cfg.lighting.lights = [config_mod.LightConfig(kind="sun", direction=[0.3, -1.0, 0.2], angle=15.0)]
    table = sweep(cfg, "lighting.shadows.samples", [4, 16, 64, 256], reference=4096, scene=sc)
    rmse = [r["rmse"] for r in table["rows"]]
    assert all(a > b for a, b in zip(rmse, rmse[1:])) and rmse[-1] > 0
    assert table["slope"] <= -0.5
