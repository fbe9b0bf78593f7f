"""The xatlas unwrap (bake/textures/unwrap.py, its cache unwrap_cache.py) against independent references.

* xatlas in a subprocess: results are cached by mesh hash and identical when recomputed; a real
  xatlas segfault, a hang and a too-large mesh are reported as StageError, never a crash; a
  worker that crashes once is started again;
* xatlas works in absolute units: a model 1e-3 or 2^-30 the usual size gets the atlas of an
  ordinary-sized one (xatlas sees it multiplied by a power of two), ordinary models reach xatlas
  exactly as before.
"""

from __future__ import annotations

import sys
import time

import numpy as np
import pytest
import trimesh

from bake.config import LightmapConfig
from bake.errors import StageError
from bake.scene import make_scene
from bake.textures import unwrap as uw
from bake.textures.texels import texel_world_size


# --------------------------------------------------------------------------------------------
# xatlas in a subprocess


def _cfg(tmp_path, **kw):
    return LightmapConfig(enabled=True, cache_dir=str(tmp_path / "cache"), **kw)


def test_unwrap_cache_and_determinism(tmp_path):
    m = trimesh.creation.torus(1.0, 0.4, major_sections=24, minor_sections=12)
    scene = make_scene(np.asarray(m.vertices, float) + 1e4, m.faces)  # far from the origin
    cfg = _cfg(tmp_path, resolution=128)
    a = uw.unwrap(scene, cfg)
    assert not a.cached and a.n_triangles == scene.n_triangles and a.mapped.all()
    assert np.isfinite(a.tri_uvs).all() and a.tri_uvs.min() >= 0 and a.tri_uvs.max() <= 1
    b = uw.unwrap(scene, cfg)
    assert b.cached and b.key == a.key
    c = uw.unwrap(scene, cfg, cache_dir=None)  # a fresh xatlas run
    for other in (b, c):
        assert np.array_equal(other.tri_uvs, a.tri_uvs) and np.array_equal(other.chart, a.chart)
        assert (other.width, other.height) == (a.width, a.height)
    # charts are what they say: triangles of one chart share UVs along shared edges
    assert a.chart.max() + 1 == a.chart_count
    # the key follows the mesh's shape (not its place: xatlas sees it centred)
    assert uw.unwrap(scene.replace(positions=scene.positions + 1.0), cfg).key == a.key
    bent = scene.positions.copy()
    bent[0] += 0.01
    assert uw.unwrap(scene.replace(positions=bent), cfg).key != a.key


def test_unwrap_refuses_too_many_triangles(tmp_path, monkeypatch):
    monkeypatch.setattr(uw, "WORKER_COMMAND", [sys.executable, "-c", "raise SystemExit(9)"])
    m = trimesh.creation.icosphere(3)
    with pytest.raises(StageError, match="max_triangles = 100"):
        uw.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path, max_triangles=100))


def test_real_xatlas_segfault_is_reported(tmp_path):
    # xatlas 0.0.9-0.0.11 crash in PackCharts on a perfectly smooth subdivided icosphere
    m = trimesh.creation.icosphere(6)
    t = time.perf_counter()
    try:
        uw.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path, timeout=60))
    except StageError as e:
        assert "crashed (SIG" in str(e) and "81920 triangles" in str(e)
    else:
        pytest.skip(f"xatlas {uw.xatlas_version()} does not crash on this mesh")
    assert time.perf_counter() - t < 60


def test_a_crash_once_is_run_again_and_a_crash_twice_is_reported(tmp_path, monkeypatch):
    """A worker killed by a signal on its first run is started once more; the second run's atlas
    is the one a clean run gives (the same UVs), and the retry is named. Two crashes: an error."""
    m = trimesh.creation.box(extents=(2, 1, 1))
    scene = make_scene(m.vertices, m.faces)
    clean = uw.unwrap(scene, _cfg(tmp_path), cache_dir=None)
    assert clean.retried_after == ""
    marker = tmp_path / "crashed-once"
    script = ("import os, runpy, signal, sys\n"
              f"m = {str(marker)!r}\n"
              "if not os.path.exists(m):\n"
              "    open(m, 'w').close(); os.kill(os.getpid(), signal.SIGSEGV)\n"
              f"sys.argv = [{str(uw.WORKER)!r}] + sys.argv[1:]\n"
              f"runpy.run_path({str(uw.WORKER)!r}, run_name='__main__')\n")
    monkeypatch.setattr(uw, "WORKER_COMMAND", [sys.executable, "-c", script])
    again = uw.unwrap(scene, _cfg(tmp_path), cache_dir=None)
    assert marker.exists() and again.retried_after == "SIGSEGV"
    assert np.array_equal(again.tri_uvs, clean.tri_uvs)
    monkeypatch.setattr(uw, "WORKER_COMMAND", [sys.executable, "-c",
                                               "import os, signal; os.kill(os.getpid(), signal.SIGABRT)"])
    with pytest.raises(StageError, match=r"crashed \(SIGABRT\) on this mesh \(12 triangles\), twice"):
        uw.unwrap(scene, _cfg(tmp_path), cache_dir=None)


def test_hanging_worker_is_stopped(tmp_path, monkeypatch):
    monkeypatch.setattr(uw, "WORKER_COMMAND", [sys.executable, "-c", "import time; time.sleep(60)"])
    m = trimesh.creation.box()
    t = time.perf_counter()
    with pytest.raises(StageError, match="did not finish within textures.lightmap.timeout = 1"):
        uw.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path, timeout=1.0))
    assert time.perf_counter() - t < 10


def test_failing_worker_message(tmp_path, monkeypatch):
    script = "import sys; print('xatlas failed: boom', file=sys.stderr); sys.exit(3)"
    monkeypatch.setattr(uw, "WORKER_COMMAND", [sys.executable, "-c", script])
    m = trimesh.creation.box()
    with pytest.raises(StageError, match="xatlas failed: boom"):
        uw.unwrap(make_scene(m.vertices, m.faces), _cfg(tmp_path))


# --------------------------------------------------------------------------------------------
# xatlas works in absolute units: what it is handed


def _torus(scale=1.0, shift=0.0):
    m = trimesh.creation.torus(1.0, 0.4, major_sections=24, minor_sections=12)  # 2.8 across
    return make_scene(np.asarray(m.vertices, float) * scale + shift, m.faces)


def test_xatlas_scale_is_a_power_of_two_outside_the_ordinary_sizes():
    lo, hi = uw.XATLAS_PLAIN_EXTENTS
    for e in (lo, 1.5, 2.8, 559.2, hi):
        assert uw.xatlas_scale(e) == 1.0
    for e in (0.0, -1.0, float("inf"), float("nan")):
        assert uw.xatlas_scale(e) == 1.0
    t = 2.0 ** uw.XATLAS_TARGET_EXPONENT
    for e in (1e-30, 7.4e-6, 0.0074, 0.5, np.nextafter(lo, 0), np.nextafter(hi, np.inf), 7.4e3, 1e5, 2e30):
        k = uw.xatlas_scale(e)
        assert np.log2(k) == round(np.log2(k)) and t <= e * k < 2 * t, e
    # options in model units are converted; those in texels or without a unit are not
    cfg = LightmapConfig(texels_per_unit=12.0, max_chart_area=3.0, resolution=128, padding=3)
    assert uw.xatlas_options(cfg, 1.0) == {
        "chart": {"max_cost": 2.0, "normal_deviation_weight": 2.0, "max_chart_area": 3.0},
        "pack": {"resolution": 128, "padding": 3, "bilinear": True, "rotate_charts": True, "texels_per_unit": 12.0}}
    big = uw.xatlas_options(cfg, 2.0 ** 15)
    assert big["pack"]["texels_per_unit"] == 12.0 / 2 ** 15 and big["chart"]["max_chart_area"] == 3.0 * 2 ** 30
    assert {k: v for k, v in big["pack"].items() if k != "texels_per_unit"} == \
        {k: v for k, v in uw.xatlas_options(cfg)["pack"].items() if k != "texels_per_unit"}


def test_ordinary_models_reach_xatlas_exactly_as_before():
    """A model of ordinary size is handed to xatlas centred in float64, then cast: the bytes (and
    so the cache key and the atlas) of the unwrap before xatlas_scale existed."""
    scene = _torus(shift=1e4)
    p32, idx, used, scale = uw._mesh_for_xatlas(scene)
    p = scene.positions[used]
    assert scale == 1.0
    assert np.array_equal(p32, (p - 0.5 * (p.min(axis=0) + p.max(axis=0))).astype(np.float32))


def test_atlas_does_not_depend_on_the_model_units(tmp_path):
    cfg = _cfg(tmp_path, resolution=64)
    unit = uw.unwrap(_torus(64.0), cfg)  # 179 across: a size xatlas handles well, given as it is
    assert unit.xatlas_scale == 1.0 and unit.mapped.all()
    # 1e-3: xatlas alone called most triangles degenerate (its epsilons are absolute: 14x14 atlas);
    # now it sees the model at about the size above. Not bit for bit (1e-3 is no power of two, and
    # the last bits decide some of xatlas's chart growing on this symmetric mesh), but alike.
    milli = uw.unwrap(_torus(1e-3, shift=5e-3), cfg)
    assert milli.xatlas_scale == 2.0 ** 16 and milli.mapped.all()
    for got, ref in ((milli.width, unit.width), (milli.height, unit.height), (milli.chart_count, unit.chart_count)):
        assert abs(got - ref) <= 0.15 * ref, (got, ref)
    assert milli.texels_per_unit == pytest.approx(64e3 * unit.texels_per_unit, rel=0.01)  # per model unit
    # models a power of two apart are the same input to xatlas: one cache entry, the same atlas
    a = uw.unwrap(_torus(2.0 ** -20), cfg)
    b = uw.unwrap(_torus(2.0 ** -30), cfg)
    assert b.cached and b.key == a.key and a.mapped.all()
    assert np.array_equal(a.tri_uvs, b.tri_uvs) and (a.width, a.height) == (b.width, b.height)
    assert b.texels_per_unit == a.texels_per_unit * 2 ** 10
    huge = uw.unwrap(_torus(2.0 ** 40), cfg)
    assert huge.key == a.key and huge.texels_per_unit == a.texels_per_unit * 2.0 ** -60
    # texels_per_unit is in model units whatever the size (exact: powers of two)
    fixed = uw.unwrap(_torus(1e-3), _cfg(tmp_path, resolution=128, texels_per_unit=16e3))
    assert fixed.texels_per_unit == 16e3 and fixed.mapped.all()
    h = texel_world_size(_torus(1e-3), fixed)
    assert np.median(h) == pytest.approx(1 / 16e3, rel=0.1)
