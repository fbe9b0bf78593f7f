"""What a new user hit, round two (issue 37): settings that change nothing said so, advice checked
against the settings it is about, config messages in the words a config is written in, and the
list left from earlier stops. Each test fails on the code before the issue."""

from __future__ import annotations

import numpy as np
import pytest

from bake import advice, cli, config
from bake.errors import ConfigError
from bake.record import StageRecord
from bake.scene import make_scene

from test_cli import grid_obj, run


# --------------------------------------------------------------------------- 1. settings of a stage that is off
def test_a_key_of_a_stage_that_does_not_run_is_said_and_fails_strict(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 3)
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o"),
                          "--set", "mesh.simplify.target_triangles=5"], capsys)
    assert code == 0, err
    line = next(ln for ln in out.splitlines() if "mesh.simplify.target_triangles" in ln)
    assert "simplify stage does not run" in line and "mesh.simplify.enabled = true" in line
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--strict",
                          "--set", "mesh.simplify.target_triangles=5"], capsys)
    assert code == 4 and "mesh.simplify.target_triangles" in err


def test_lights_without_the_lighting_switch_are_said(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 3)
    cfg = tmp_path / "lit.toml"
    cfg.write_text(f'[input]\npath = "{model.name}"\n\n[[lighting.lights]]\nkind = "sun"\nangle = 2.0\n')
    code, out, err = run(["run", str(cfg), "--out", str(tmp_path / "o")], capsys)
    assert code == 0, err
    said = [ln for ln in out.splitlines() if "lighting stage does not run" in ln and "PROBLEM:" in ln]
    assert len(said) == 1 and "lighting.lights" in said[0] and "lighting.enabled = true" in said[0]
    assert "lights[0]" not in said[0]  # the list is named once, not each field of each light


def test_keys_of_stages_that_run_are_not_said(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 3)
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--set", "mesh.simplify.enabled=true",
                          "--set", "mesh.simplify.target_triangles=8", "--set", "export.precision=4"], capsys)
    assert code == 0, err
    assert "does not run" not in out


# --------------------------------------------------------------------------- 2. advice
def _records(simplify_out: int, bsp_out: int) -> tuple[list[StageRecord], StageRecord]:
    simp = StageRecord(name="simplify", counts_in={"triangles": 10_000}, counts_out={"triangles": simplify_out})
    bsp = StageRecord(name="bsp", counts_in={"triangles": simplify_out}, counts_out={"triangles": bsp_out})
    return [simp], bsp


def test_bsp_advice_aims_simplify_lower_only_where_simplify_reached_its_target():
    cfg = config.Config()
    cfg.mesh.simplify.enabled = True
    cfg.mesh.simplify.target_triangles = 3000
    records, bsp = _records(3000, 6000)
    advice.bsp_size(cfg, make_scene(np.zeros((3, 3)), [[0, 1, 2]]), bsp, records)
    assert any("aim simplify lower" in w and "target_triangles = 1500" in w for w in bsp.warnings)
    # simplify stopped at the whole input (defects refused): a lower target would change nothing
    records, bsp = _records(10_000, 19_000)
    advice.bsp_size(cfg, make_scene(np.zeros((3, 3)), [[0, 1, 2]]), bsp, records)
    (w,) = bsp.warnings
    assert "aim simplify lower" not in w and "stopped at 10,000" in w and "bsp.split_weight" in w


@pytest.mark.parametrize("layout,precision,quantised,lower", [("quantised", 5, False, True),
                                                               ("binary", 5, True, True),
                                                               ("quantised", 3, False, False)])
def test_bvh_size_advice_names_only_what_is_not_already_set(monkeypatch, layout, precision, quantised, lower):
    import numpy as np

    from bake.bvh import stage as bvh_stage
    from bake.config import BVHConfig
    from bake.scene import make_scene

    monkeypatch.setattr(bvh_stage, "PROJECT_JSON_LIMIT", 10)  # any BVH is "too big"
    V = np.random.default_rng(0).random((30, 3))
    F = np.arange(30).reshape(-1, 3)
    _, rec = bvh_stage.stage(make_scene(V, F), BVHConfig(enabled=True, layout=layout, precision=precision))
    (w,) = [w for w in rec.warnings if "5 MiB" in w]
    assert ("layout = \"quantised\"" in w) == quantised
    assert ("lower bvh.precision" in w) == lower


def test_uv_advice_does_not_ask_for_textures_that_are_on(tmp_path):
    import numpy as np

    from bake.config import ExportConfig
    from bake.export.lists import choose_lists
    from bake.scene import Material, make_scene
    from pathlib import Path

    V = np.random.default_rng(0).random((3, 3))
    sc = make_scene(V, [[0, 1, 2]], materials=(Material("m", texture=Path("t.png")),),
                    tri_uvs=np.zeros((1, 3, 2)))
    off = choose_lists(sc, ExportConfig())["tri uvs"]
    on = choose_lists(sc.with_artefacts(textures=object()), ExportConfig())["tri uvs"]
    assert "textures.enabled = true" in off.reason
    assert "textures.enabled" not in on.reason and "textures.encodings" in on.reason


# --------------------------------------------------------------------------- 3. config messages
def _load(tmp_path, text: str) -> str:
    p = tmp_path / "c.toml"
    p.write_text(text)
    with pytest.raises(ConfigError) as e:
        config.load(p)
    return str(e.value)


def test_a_light_in_single_brackets_is_told_how_lights_are_written(tmp_path):
    msg = _load(tmp_path, '[lighting]\nenabled = true\n[lighting.lights]\nkind = "sun"\n')
    assert "[[lighting.lights]]" in msg and "double brackets" in msg and "LightConfig" not in msg
    assert "c.toml:3" in msg


def test_a_number_where_a_list_of_numbers_goes_shows_the_list(tmp_path):
    msg = _load(tmp_path, "[lighting]\nambient = 0.3\n")
    assert "expected a list of numbers such as [0.3, 0.3, 0.3], got 0.3" in msg
    with pytest.raises(ConfigError) as e:
        config.load(None, ["textures.encodings=list"])
    assert "a list of values from 'list', 'textimage', 'costume' such as ['list']" in str(e.value)


# --------------------------------------------------------------------------- the list left from earlier stops
@pytest.mark.parametrize("setting, said", [("lighting.ao.samples=0", "must be >= 1"),
                                           ("textures.lightmap.resolution=3", "must be between 16 and 8192"),
                                           ("bvh.leaf_size=0", "must be between 1 and")])
def test_a_bad_value_of_a_stage_that_is_off_is_refused_before_the_bake(tmp_path, capsys, setting, said):
    """The stages' range checks ran only when the stage ran: a bad value waited, unsaid, for the
    day its switch was turned on. Now every section is checked before the bake (exit 2)."""
    model = grid_obj(tmp_path / "grid.obj", 3)
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--set", setting], capsys)
    key = setting.split("=")[0]
    assert code == 2 and f"key '{key}'" in err and said in err, err
    assert not (tmp_path / "o").exists()


def test_a_lightmap_that_times_out_fails_strict_with_status_5(tmp_path, capsys, monkeypatch):
    import sys

    from bake.textures import unwrap

    monkeypatch.setattr(unwrap, "WORKER_COMMAND", [sys.executable, "-c", "import time; time.sleep(30)"])
    model = grid_obj(tmp_path / "grid.obj", 3)
    args = ["run", str(model), "--out", str(tmp_path / "o"), "--set", "textures.enabled=true",
            "--set", "textures.lightmap.enabled=true", "--set", "textures.lightmap.timeout=1",
            "--set", "textures.lightmap.cache_dir=none"]
    code, out, err = run(args, capsys)
    assert code == 0, err
    assert "no lightmap" in out and "did not finish within textures.lightmap.timeout" in out
    code, out, err = run(args + ["--strict"], capsys)
    assert code == 5 and "failed under --strict" in err and "did not finish" in err


@pytest.mark.parametrize("text,line", [("vn 0 0 x\n", 4), ("vn 0 1\n", 4), ("vn nan 0 1\n", 4)])
def test_a_malformed_vn_line_is_an_input_error_naming_its_line(tmp_path, capsys, text, line):
    p = tmp_path / "m.obj"
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\n" + text + "f 1 2 3\n")
    code, out, err = run(["run", str(p), "--out", str(tmp_path / "o")], capsys)
    assert code == 3 and f"m.obj:{line}:" in err


def test_bake_watch_stops_at_once_on_a_model_it_can_never_bake(tmp_path):
    import subprocess
    import sys

    mtl = tmp_path / "model.mtl"
    mtl.write_text("newmtl a\nKd 1 0 0\n")
    r = subprocess.run([sys.executable, "-m", "bake.cli", "watch", str(mtl), "--out", str(tmp_path / "o")],
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 3 and "unknown model format '.mtl'" in r.stderr and "watching" not in r.stderr


@pytest.mark.parametrize("value", ["-1", "nan", "inf"])
def test_watch_debounce_must_be_seconds(tmp_path, capsys, value):
    model = grid_obj(tmp_path / "grid.obj", 2)
    code, out, err = run(["watch", str(model), "--debounce", value], capsys)
    assert code == 2 and "--debounce expects seconds >= 0" in err


def test_error_paths_are_absolute_whichever_way_they_were_given(tmp_path, capsys, monkeypatch):
    monkeypatch.chdir(tmp_path)
    code, out, err = run(["run", "missing.obj"], capsys)
    assert code == 3 and f"{tmp_path / 'missing.obj'}: file not found" in err
    cfg = tmp_path / "c.toml"
    cfg.write_text('[input]\npath = "missing.obj"\n')
    code, out, err = run(["run", "c.toml"], capsys)
    assert code == 3 and f"{tmp_path / 'missing.obj'}: file not found" in err


def test_clean_says_why_it_dropped_triangles_and_the_summary_says_what_counts_mean(tmp_path, capsys):
    p = tmp_path / "m.obj"
    # two good triangles, one with a repeated corner, one with no area (collinear)
    p.write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 1 1 0\nv 2 2 0\nf 1 2 3\nf 2 4 3\nf 1 1 2\nf 1 4 5\n")
    code, out, err = run(["run", str(p), "--out", str(tmp_path / "o"), "--set", "import.strict=false"], capsys)
    assert code == 0, err
    said = next(ln for ln in out.splitlines() if "dropped 2 of" in ln)
    assert "1 with a repeated corner" in said and "1 with no area" in said
    md = (tmp_path / "o" / "report.md").read_text()
    assert "1 with a repeated corner" in md


def test_summary_counts_are_whole_numbers_with_their_meaning():
    from bake.outputs.report import _summary_figure

    assert _summary_figure("folds", 13000) == "13,000 (pairs of neighbouring triangles facing each other)"
    assert _summary_figure("hausdorff_max", 0.0123) == "1.23%"
    assert _summary_figure("position_error", 5e-7) == "5e-07"


def test_the_command_prints_its_own_wall_time_beside_the_pipelines(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 2)
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o")], capsys)
    assert code == 0
    first = out.splitlines()[0]
    import re

    m = re.search(r"in ([\d.]+) s \(([\d.]+) s for the whole command", first)
    assert m and float(m.group(2)) >= float(m.group(1)), first


def _textured_gltf(path, image_bytes: bytes, mime: str = "image/png"):
    """A one-triangle glTF whose texture is embedded as a data URI (written here, no sample file)."""
    import base64
    import json
    import struct

    pos = struct.pack("<9f", 0, 0, 0, 1, 0, 0, 0, 1, 0)
    uv = struct.pack("<6f", 0, 0, 1, 0, 0, 1)
    blob = pos + uv
    doc = {"asset": {"version": "2.0"}, "scene": 0, "scenes": [{"nodes": [0]}],
           "nodes": [{"mesh": 0}],
           "meshes": [{"primitives": [{"attributes": {"POSITION": 0, "TEXCOORD_0": 1}, "material": 0}]}],
           "materials": [{"name": "painted", "pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}],
           "textures": [{"source": 0}],
           "images": [{"uri": f"data:{mime};base64," + base64.b64encode(image_bytes).decode(), "mimeType": mime}],
           "buffers": [{"byteLength": len(blob), "uri": "data:application/octet-stream;base64,"
                        + base64.b64encode(blob).decode()}],
           "bufferViews": [{"buffer": 0, "byteOffset": 0, "byteLength": 36},
                           {"buffer": 0, "byteOffset": 36, "byteLength": 24}],
           "accessors": [{"bufferView": 0, "componentType": 5126, "count": 3, "type": "VEC3",
                          "min": [0, 0, 0], "max": [1, 1, 0]},
                         {"bufferView": 1, "componentType": 5126, "count": 3, "type": "VEC2"}]}
    path.write_text(json.dumps(doc))
    return path


def test_a_corrupt_embedded_image_is_named_by_its_index_and_type(tmp_path, capsys):
    import json

    model = _textured_gltf(tmp_path / "t.gltf", b"\x89PNG\r\n\x1a\nnot really a png")
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--set", "textures.enabled=true"], capsys)
    assert code == 0, err
    said = next(ln for ln in out.splitlines() if "texture not used" in ln)
    assert "t.gltf images[0], image/png" in said and "BytesIO" not in said
    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert rep["materials"][0]["texture"] == "t.gltf images[0], image/png"  # was null for embedded ones


@pytest.mark.corpus
@pytest.mark.parametrize("model", [("cornell_box_tinyobj", "cornell_box.obj"), ("teapot_obj", "teapot.obj")])
@pytest.mark.parametrize("res", [64, 256, 1024])
def test_the_lightmap_resolution_asked_is_the_one_written(model, res):
    """xatlas grew every atlas about 25% past textures.lightmap.resolution (its padding was not
    budgeted), so every lightmap bake warned; the unwrap now asks xatlas for less until it fits."""
    from bake import pipeline
    from bake.config import LightmapConfig
    from bake.textures.unwrap import unwrap
    from conftest import corpus_path

    sc = pipeline.run(pipeline.load_config_for(corpus_path(*model)), until="clean", cache=None).scene
    atlas = unwrap(sc, LightmapConfig(enabled=True, resolution=res), cache_dir=None)
    assert max(atlas.width, atlas.height) <= res
    assert max(atlas.width, atlas.height) > 0.5 * res  # (not by shrinking it to nothing)


def test_a_bake_started_with_sigint_ignored_keeps_running(tmp_path):
    """A background job (``make test &``, nohup) starts its children with SIGINT ignored: the bake
    keeps it ignored, so a SIGINT to it changes nothing and it finishes as if none came."""
    import signal
    import subprocess
    import sys
    import time

    model = grid_obj(tmp_path / "grid.obj", 40)
    out = tmp_path / "o"

    def ignore() -> None:
        signal.signal(signal.SIGINT, signal.SIG_IGN)
    p = subprocess.Popen([sys.executable, "-m", "bake.cli", "run", str(model), "--out", str(out),
                          "--set", "bsp.enabled=true"], stdout=subprocess.PIPE, stderr=subprocess.PIPE,
                         text=True, preexec_fn=ignore)
    time.sleep(1.0)  # (inside the bake: imports, the stages)
    p.send_signal(signal.SIGINT)
    stdout, stderr = p.communicate(timeout=300)
    assert p.returncode == 0, stderr
    assert "interrupted" not in stderr and (out / "report.json").is_file()


def test_export_into_prints_the_merged_projects_size_and_the_bakes_own(tmp_path, capsys):
    import zipfile

    from bake.scratch import sb3

    engine = tmp_path / "engine.sb3"
    engine.write_bytes(sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists={"verts": [1, 2, 3]}),
                                      sb3.Target("Engine", layer_order=1)])[0])
    model = grid_obj(tmp_path / "grid.obj", 2)
    out = tmp_path / "o"
    code, text, err = run(["run", str(model), "--out", str(out), "--set", f"export.into={engine}"], capsys)
    assert code == 0, err
    line = next(ln for ln in text.splitlines() if ln.strip().startswith("project.json:"))
    merged = next(p for p in out.glob("engine-*.sb3"))
    own = out / "grid.sb3"
    size = {p: zipfile.ZipFile(p).getinfo("project.json").file_size for p in (merged, own)}
    from bake.scratch.limits import fmt_bytes

    assert f"{fmt_bytes(size[merged])} of 5 MiB" in line and f"in {merged.name} (the bake merged into engine.sb3)" in line
    assert f"the bake's own .sb3: {fmt_bytes(size[own])}" in line


# --------------------------------------------------------------------------- 10. a textured model, by default
def _box(*sets: str, tmp_path, capsys, name="o"):
    import json

    from conftest import CORPUS

    model = CORPUS / "box_textured_gltf_separate" / "BoxTextured.gltf"
    out = tmp_path / name
    args = ["run", str(model), "--out", str(out)]
    for s in sets:
        args += ["--set", s]
    code, stdout, err = run(args, capsys)
    assert code == 0, err
    return out, json.loads((out / "report.json").read_text()), stdout


def _green_flag(out):
    """The green flag's stage as report.html previews it (from the written lists and report)."""
    import json

    from bake.outputs import preview
    from bake.scratch.project import auto_camera

    rep = json.loads((out / "report.json").read_text())
    lists = json.loads((out / "lists.json").read_text())["lists"]
    mesh = preview.mesh_from_lists(lists, rep)
    view, painter = preview.stage_view(mesh, auto_camera(lists["verts"]))
    return view.painter, painter.tri_id >= 0, mesh


def test_a_textured_model_bakes_its_texture_by_default(tmp_path, capsys):
    out, rep, _ = _box(tmp_path=tmp_path, capsys=capsys)
    ran = [s["name"] for s in rep["stages"]]
    assert "textures" in ran
    assert rep["config"]["textures"]["enabled"] == "auto"
    assert any(n.startswith("tex") or "texture" in n for n in rep["lists"]), list(rep["lists"])
    img, covered, _ = _green_flag(out)
    # the triangles carry the texture's mean colours: not the white of an untextured material
    assert covered.mean() > 0.2 and (img[covered] < 250).any(axis=1).mean() > 0.9


def test_auto_skips_the_textures_stage_on_a_model_without_textures_and_says_why(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 3)
    code, out, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--set", "textures.max_size=64"], capsys)
    assert code == 0, err
    import json

    rep = json.loads((tmp_path / "o" / "report.json").read_text())
    assert "textures" not in [s["name"] for s in rep["stages"]]
    why = next(e["reason"] for e in rep["effects"] if e["name"] == "textures")
    assert "auto" in why and "no material" in why
    line = next(ln for ln in out.splitlines() if "textures.max_size" in ln)
    assert "nothing to do" in line and "set textures.enabled = true" not in line


@pytest.mark.parametrize("value, ok", [("true", True), ("false", True), ('"auto"', True), ("auto", True),
                                       ('"maybe"', False), ("3", False)])
def test_textures_enabled_takes_true_false_or_auto(tmp_path, value, ok):
    (tmp_path / "c.toml").write_text(f'[input]\npath = "m.obj"\n[textures]\nenabled = {value}\n')
    if ok and value != "auto":
        cfg = config.load(tmp_path / "c.toml")
        assert cfg.textures.enabled in (True, False, "auto")
        return
    if value == "auto":  # bare word: not TOML; on the command line it is a string
        assert config.load(None, ["textures.enabled=auto"]).textures.enabled == "auto"
        return
    with pytest.raises(ConfigError) as e:
        config.load(tmp_path / "c.toml")
    assert "expected true, false or 'auto'" in str(e.value) and "textures.enabled" in str(e.value)


def test_an_unlit_white_model_is_drawn_on_a_backdrop_it_shows_on(tmp_path, capsys):
    """The textured box with its texture off bakes white (its base colour) and unlit: on the white
    stage it was invisible. The .sb3's backdrop is dark then, and the green flag's preview draws on
    it; a model of ordinary colours keeps the white stage."""
    from bake.scratch import backdrop, sb3

    out, rep, _ = _box("textures.enabled=false", tmp_path=tmp_path, capsys=capsys)
    img, covered, mesh = _green_flag(out)
    assert mesh.backdrop == backdrop.DARK
    bg = np.asarray(mesh.backdrop)
    assert (img[~covered] == bg).all()
    # every drawn pixel stands far from the backdrop (white on white was 0 levels apart)
    assert covered.mean() > 0.2 and (np.abs(img[covered].astype(int) - bg).max(axis=1) > 100).all()
    project, assets = sb3.load_project(out / "BoxTextured.sb3")
    assert backdrop.from_project(project, assets) == backdrop.DARK
    plain = grid_obj(tmp_path / "grid.obj", 3, mtl=False)  # the default light grey material: white stays
    code, _, err = run(["run", str(plain), "--out", str(tmp_path / "p")], capsys)
    assert code == 0, err
    project, assets = sb3.load_project(tmp_path / "p" / "grid.sb3")
    assert backdrop.from_project(project, assets) == backdrop.WHITE


def test_the_backdrop_choice_weighs_the_drawn_area():
    from bake.scratch import backdrop

    assert backdrop.difference(np.array([[255, 250, 255], [0, 255, 0]]), backdrop.WHITE).tolist() == [5, 255]
    # two triangles: a big white one and a small black one (area 4:1), then the other way round
    verts = [0, 0, 0, 2, 0, 0, 0, 2, 0, 10, 0, 0, 11, 0, 0, 10, 1, 0]
    tris = [1, 2, 3, 1, 4, 5, 6, 2]
    white, black = 0xFFFFFF, 0x000000
    assert backdrop.choose(verts, tris, mat_colors=[white, black]).rgb == backdrop.DARK
    assert backdrop.choose(verts, tris, mat_colors=[black, white]).rgb == backdrop.WHITE
    assert backdrop.choose(verts, tris, tri_colors=[0xCCCCCC, 0xCCCCCC]).rgb == backdrop.WHITE  # light grey
    assert backdrop.choose(verts, tris, tri_colors=[0x00FF00, 0x00FF00]).rgb == backdrop.WHITE  # pure green
    assert backdrop.choose(verts, tris, tri_colors=[0xFFDCDC, 0xFFDCDC]).rgb == backdrop.DARK  # pale pink
    assert backdrop.choose(verts, tris).rgb == backdrop.WHITE  # the reader's grey


def test_the_readme_says_how_wide_the_bunny_config_comes_out(tmp_path, capsys):
    """fit and center apply before simplify (the stages' order); README says so with the figure a
    bake of configs/bunny.toml gives (lighting and the BSP tree do not move a vertex: left off)."""
    import json
    import re

    from conftest import REPO, corpus_path

    corpus_path("stanford_bunny_res1_obj", "stanford-bunny.obj")
    text = (REPO / "README.md").read_text()
    m = re.search(r"configs/bunny\.toml \(fit = 100, center = \"base\", 3,000 triangles\) comes out ([\d.]+) wide, "
                  r"([\d.]+) off centre", text)
    assert m, "README's transform comment"
    code, _, err = run(["run", str(REPO / "configs" / "bunny.toml"), "--out", str(tmp_path / "o"), "--quiet",
                        "--set", "lighting.enabled=false", "--set", "bsp.enabled=false"], capsys)
    assert code == 0, err
    v = np.asarray(json.loads((tmp_path / "o" / "lists.json").read_text())["lists"]["verts"], float).reshape(-1, 3)
    lo, hi = v.min(0), v.max(0)
    assert f"{(hi - lo).max():.3f}" == m.group(1)
    assert f"{abs((hi[0] + lo[0]) / 2):.2f}" == m.group(2)


def test_the_bar_counts_a_stage_that_found_nothing_to_do_as_one_fewer():
    import io

    from rich.console import Console

    from bake.progress import StageProgress

    buf = io.StringIO()
    prog = StageProgress(total=3, after=0.0, console=Console(file=buf, force_terminal=True, width=100))
    for stage, event in (("import", "start"), ("import", "done"), ("textures", "start"), ("textures", "skipped"),
                         ("export", "start"), ("export", "done")):
        prog(stage, event)
    assert prog.total == 2 and prog._done == 2
    prog.stop()


@pytest.mark.parametrize("args, said", [
    (["--set", "import.scene=-2"], "key 'import.scene': must be a scene number >= 0, or -1"),
    (["--set", "import.scene=-1"], None),
])
def test_import_scene_takes_minus_one_and_no_other_negative(tmp_path, capsys, args, said):
    model = grid_obj(tmp_path / "grid.obj", 2)
    code, _, err = run(["run", str(model), "--out", str(tmp_path / "o"), "--quiet", *args], capsys)
    assert (code, said is None or said in err) == ((0, True) if said is None else (2, True)), err


def test_a_sweep_reference_that_is_not_a_number_names_reference(tmp_path, capsys):
    model = grid_obj(tmp_path / "grid.obj", 2)
    code, _, err = run(["sweep", str(model), "--out", str(tmp_path / "o"), "--vary", "export.precision=3,4",
                        "--reference", "abc"], capsys)
    assert code == 2 and "--reference value 'abc' is not a number" in err and "--vary" not in err, err


def test_a_textured_model_lit_with_subdivision_keeps_the_albedo_of_its_split_triangles(tmp_path):
    """Found with textures on by default: lighting.subdivide split the triangles but kept the
    textures stage's per-triangle albedo of the triangles before, and the BSP stage's merge groups
    then failed on the mismatch (an internal error). The split triangles carry their own albedo:
    the texture's mean over each new triangle (the albedo artefact), and the bake finishes."""
    from bake import pipeline

    from test_cache import write_model

    model = write_model(tmp_path / "m", n=8)
    data = {"input": {"path": str(model)},
            "lighting": {"enabled": True, "subdivide": True, "lights": [{"kind": "sun", "direction": [0.4, -1, 0.3]}]},
            "bsp": {"enabled": True}, "export": {"enabled": False}}
    lit = pipeline.run(config.load(data=data), until="lighting", cache=None).scene
    before = pipeline.run(config.load(data=data), until="textures", cache=None).scene
    assert lit.n_triangles > before.n_triangles  # subdivision split some
    assert lit.face_albedo is not None and len(lit.face_albedo) == lit.n_triangles
    # a triangle the split left whole has the albedo the textures stage gave it
    key = lambda sc: {tuple(np.round(sc.positions[t], 9).ravel()): i for i, t in enumerate(sc.triangles)}
    old, new = key(before), key(lit)
    whole = [(old[k], i) for k, i in new.items() if k in old]
    assert 0 < len(whole) < lit.n_triangles
    a, b = np.array(whole).T
    assert np.allclose(lit.face_albedo[b], before.face_albedo[a], atol=1e-12)
    res = pipeline.run(config.load(data=data), cache=None)
    assert [r.name for r in res.records][-1] == "bsp"
