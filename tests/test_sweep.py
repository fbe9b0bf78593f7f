"""bake.sweep: one bake per value, errors against the highest value or a reference, JSON + PNG."""

from __future__ import annotations

import json
import math
import re

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


def test_sweep_ao_samples_against_reference_writes_json_and_svg(tmp_path):
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
    panels = _drawn((tmp_path / "sweep_ao.svg").read_text())
    assert len(panels) == 3
    rmse_line = panels[2]["RMSE vertex colour"]
    assert len(rmse_line["points"]) == 4 and len(rmse_line["line"]) == 4
    # the third panel is log-log and the RMSE falls with the samples: the line goes right and down
    # (SVG y grows downwards)
    xs, ys = zip(*rmse_line["line"])
    assert all(b > a for a, b in zip(xs, xs[1:])) and all(b > a for a, b in zip(ys, ys[1:]))


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


def test_sweep_checks_every_value_before_baking_and_names_its_option(monkeypatch):
    """A user's review: a bad --vary or --reference value failed after the warm-up and the
    first bakes, blamed on "--set". Every value is checked first, and the message names the
    sweep's option."""
    import bake.sweep as sweep_mod

    baked = []
    monkeypatch.setattr(sweep_mod, "_bake", lambda *a, **k: baked.append(a) or (_ for _ in ()).throw(AssertionError))
    with pytest.raises(ConfigError, match=r"--vary value 0: must be >= 1") as e:
        sweep(_cfg(), "lighting.ao.samples", [16, 0], scene=_scene())
    assert e.value.key == "lighting.ao.samples" and "--set" not in str(e.value)
    with pytest.raises(ConfigError, match=r"--reference value 2.5: expects an integer"):
        sweep(_cfg(), "lighting.ao.samples", [16, 64], reference=2.5, scene=_scene())
    assert baked == []


def test_sweep_names_its_option_when_the_key_came_from_set(monkeypatch):
    """The sweep's message keeps the check's own words and names --vary, not the --set that
    set the key before nor the --set the value is applied as. The origin is kept apart from
    the message (the sweep once cut it off the text with a pattern), so an origin whose own text
    holds the phrase stays whole."""
    import bake.sweep as sweep_mod
    from bake import config as config_mod

    monkeypatch.setattr(sweep_mod, "_bake", lambda *a, **k: (_ for _ in ()).throw(AssertionError))
    cfg = _cfg()
    config_mod.apply_override(cfg, "lighting.ao.samples=8")
    with pytest.raises(ConfigError) as e:
        sweep(cfg, "lighting.ao.samples", [16, 0], scene=_scene())
    assert str(e.value) == "key 'lighting.ao.samples': --vary value 0: must be >= 1"
    err = ConfigError("must be >= 1", key="k", origin="--set k=0 (on the command line)")
    assert err.message == "must be >= 1"
    assert str(err) == "key 'k': must be >= 1 (from --set k=0 (on the command line) on the command line)"


def test_sweep_soft_shadow_samples():
    sc = _scene(41)
    cfg = _cfg()
    cfg.lighting.ao.enabled = False
    cfg.lighting.lights = [config_mod.LightConfig(kind="sun", direction=[0.3, -1.0, 0.2], angle=15.0)]
    table = sweep(cfg, "lighting.shadows.samples", [4, 16, 64, 256], reference=4096, scene=sc)
    rmse = [r["rmse"] for r in table["rows"]]
    assert all(a > b for a, b in zip(rmse, rmse[1:])) and rmse[-1] > 0
    assert table["slope"] <= -0.5


# --------------------------------------------------------------------------- any numeric key of any stage
def _sphere_obj(tmp_path, subdivisions=3):
    import trimesh

    m = trimesh.creation.icosphere(subdivisions=subdivisions)
    p = tmp_path / "sphere.obj"
    p.write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in m.vertices)
                 + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in m.faces))
    return p


def _model_cfg(path, *sets):
    return config_mod.load(None, [f"input.path={path}", *sets])


def test_sweep_simplify_target_reports_hausdorff_bytes_and_image_error(tmp_path):
    model = _sphere_obj(tmp_path)  # 1,280 triangles
    cfg = _model_cfg(model, "mesh.simplify.enabled=true")
    table = sweep(cfg, "mesh.simplify.target_ratio", [0.5, 0.05, 0.2], out=tmp_path / "sw")
    rows = table["rows"]
    assert [r["value"] for r in rows] == [0.05, 0.2, 0.5]
    assert table["stages"] == ["simplify"] and table["error_key"] == "hausdorff_max"
    tris = [r["triangles"] for r in rows]
    assert tris == sorted(tris) and abs(tris[-1] - 640) <= 7  # within 1% of the target
    assert [r["bytes"] for r in rows] == sorted(r["bytes"] for r in rows)  # bytes grow with triangles
    # the error is the simplify stage's own Hausdorff figure, and it shrinks with the budget
    for r in rows:
        assert r["error"] == r["accuracy"]["hausdorff_max"] and r["seconds"] > 0
    assert rows[0]["error"] > rows[-1]["error"] > 0
    # image error against the reference (the highest value) is 0 there and grows as it coarsens
    assert rows[-1]["reference"] and rows[-1]["image_rmse"] == 0.0
    assert rows[0]["image_rmse"] > rows[1]["image_rmse"] > 0
    assert _drawn((tmp_path / "sw.svg").read_text())[1]["list bytes in project.json"]["points"]
    assert json.loads((tmp_path / "sw.json").read_text())["error_metric"].startswith("Hausdorff")


def test_sweep_bvh_key_reports_sah_cost_and_identical_images(tmp_path):
    model = _sphere_obj(tmp_path, 2)
    cfg = _model_cfg(model, "bvh.enabled=true")
    table = sweep(cfg, "bvh.leaf_size", [1, 4, 8])
    rows = table["rows"]
    assert table["error_key"] == "sah_cost" and all(r["error"] > 0 for r in rows)
    assert all(r["image_rmse"] == 0.0 for r in rows)  # the BVH does not change what is drawn
    assert all(r["bytes"] > 0 and r["stage_seconds"]["bvh"] == r["seconds"] for r in rows)


def test_sweep_key_of_a_stage_that_does_not_run_is_an_error(tmp_path):
    model = _sphere_obj(tmp_path, 1)
    with pytest.raises(ConfigError, match="bsp.enabled = true"):
        sweep(_model_cfg(model), "bsp.candidates", [4, 8])
    with pytest.raises(ConfigError, match="lighting keys only"):
        sweep(_cfg(), "mesh.simplify.target_ratio", [0.5], scene=_scene())


def test_sweep_error_of_keys():
    from bake.sweep import error_of, stages_for

    assert stages_for("textures.lightmap.resolution") == ("textures", "lighting")
    assert error_of("textures.lightmap.resolution")[0] == "image_rmse"
    assert error_of("lighting.ao.samples")[0] == "rmse"
    assert error_of("bsp.candidates")[0] == "inflation"
    for key in config_mod.numeric_keys():  # every numeric key of the bake belongs to a stage
        assert stages_for(key) or key.startswith(("report.", "cache.")), key
    with pytest.raises(ConfigError, match="does not change what is baked"):
        sweep(_cfg(), "report.preview_width", [100, 200])


def test_sweep_lighting_key_compares_colours_before_the_bsp_splits(tmp_path):
    """Later stages (BSP) change the triangles and vertices; the colour errors are taken from the
    lighting stage's own output, so each row compares like with like."""
    sc = _scene()  # a sphere resting on a floor: the floor is occluded
    model = tmp_path / "floor.obj"
    model.write_text("".join(f"v {x:.6f} {y:.6f} {z:.6f}\n" for x, y, z in sc.positions)
                     + "".join(f"f {a + 1} {b + 1} {c + 1}\n" for a, b, c in sc.triangles))
    cfg = _model_cfg(model, "lighting.enabled=true", "lighting.ao.enabled=true", "bsp.enabled=true")
    table = sweep(cfg, "lighting.ao.samples", [4, 16, 256])
    rows = table["rows"]
    assert rows[0]["rmse"] > rows[1]["rmse"] > rows[2]["rmse"] == 0.0
    assert all(r["bytes"] > 0 and "bsp" in r["stage_seconds"] for r in rows)


def _drawn(svg: str) -> list[dict]:
    """What each panel of a sweep's SVG plot draws: per series (by its label) the polyline's
    points and the point markers' centres, in SVG pixels (x grows with the value on linear and
    log axes alike)."""
    import xml.etree.ElementTree as ET

    ns = "{http://www.w3.org/2000/svg}"
    root = ET.fromstring(svg)
    out = []
    for panel in root.iter(ns + "g"):
        if panel.get("class") != "panel":
            continue
        series = {}
        for g in panel.iter(ns + "g"):
            if g.get("class") != "series":
                continue
            line = [tuple(map(float, p.split(","))) for pl in g.iter(ns + "polyline")
                    for p in pl.get("points").split()]
            pts = []
            for el in g:
                if el.get("class") != "point":
                    continue
                if el.tag == ns + "circle":
                    pts.append((float(el.get("cx")), float(el.get("cy"))))
                elif el.tag == ns + "rect":
                    pts.append((float(el.get("x")) + float(el.get("width")) / 2,
                                float(el.get("y")) + float(el.get("height")) / 2))
                else:
                    pts.append(None)
            series[g.get("data-label")] = {"line": line, "points": pts}
        out.append(series)
    return out


def test_sweep_plot_does_not_join_points_in_value_order_against_seconds():
    """Noisy stage times must not zig-zag the error-against-seconds line (issue 17, item 9):
    every line drawn against seconds runs left to right, and joins only bakes no other bake
    beats on both time and error; every bake is still a point."""
    secs = [0.50, 0.31, 0.90, 0.62, 2.10]  # value order: 16 is slower than 32, 128 than 256
    err = [0.080, 0.052, 0.030, 0.021, 0.010]
    rows = [{"value": v, "seconds": s, "total_seconds": s + 1, "error": e, "image_rmse": e / 2,
             "bytes": 1000 + i, "reported_error": {}, "reference": False}
            for i, (v, s, e) in enumerate(zip([16, 32, 64, 128, 256], secs, err))]
    table = {"key": "bsp.candidates", "rows": rows, "stages": ["bsp"], "error_key": "inflation",
             "error_metric": "split inflation", "reference": {"kind": "highest value"}}
    from bake.sweep import plot

    panels = _drawn(plot(table))
    for series in panels[:2]:  # the panels against seconds
        points = 0
        for name, drawn in series.items():
            xs = [p[0] for p in drawn["line"]]
            assert all(b >= a for a, b in zip(xs, xs[1:])), f"a line against seconds goes back: {name} {xs}"
            points = max(points, len(drawn["points"]))
        assert points == len(rows)
    from bake.sweep import pareto_front

    # the front: 32 (0.31 s) dominates 16 (0.50 s, worse error); 128 (0.62 s) dominates 64
    assert pareto_front(np.array(secs), np.array(err)).tolist() == [1, 3, 4]
    # the line joins the points of 32, 128 and 256 (0.31, 0.62 and 2.10 s), in that order
    err = panels[0]["inflation"]["points"]
    assert panels[0]["inflation: fastest for its error"]["line"] == [err[1], err[3], err[4]]
    assert not panels[0]["inflation"]["line"]  # the points themselves are not joined


def test_sweep_plot_of_degenerate_tables_is_valid_svg_without_nan():
    """One row, missing figures, zero and infinite errors, zero seconds, a NaN estimate and markup
    in the labels: still one well-formed SVG, with no NaN or infinity in its coordinates."""
    import xml.etree.ElementTree as ET

    from bake.sweep import plot

    one = [{"value": 4, "seconds": 0.1, "total_seconds": 1, "error": None, "image_rmse": None, "bytes": None,
            "reported_error": {}, "reference": True}]
    odd = [{"value": v, "seconds": 0.0, "total_seconds": 0.0, "error": e, "rmse": e, "image_rmse": 0.0,
            "bytes": 100, "reported_error": {"ao": float("nan")}, "components": {}, "reference": False}
           for v, e in [(1, 0.0), (2, float("inf")), (1000, 1e-30)]]
    for rows in (one, odd):
        for key in ("lighting.ao.samples", "bsp.candidates"):
            svg = plot({"key": key, "rows": rows, "stages": ["x"], "error_key": "rmse",
                        "error_metric": "a < b & 'c'", "reference": {"kind": "highest value"}})
            root = ET.fromstring(svg)
            assert root.tag.endswith("svg")
            for el in root.iter():  # every coordinate is a finite number
                for name, val in el.attrib.items():
                    if name in ("x", "y", "x1", "x2", "y1", "y2", "cx", "cy", "width", "height", "points", "d"):
                        nums = [float(t) for t in re.findall(r"-?[0-9.]+(?:e-?[0-9]+)?|nan|inf", val, re.I)]
                        assert nums and all(math.isfinite(v) for v in nums), (name, val)
