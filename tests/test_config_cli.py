"""Paths and errors on the command line (issue 18, items 7 and 9): paths typed with --set resolve
against the current folder, errors in --set values say they came from the command line, range
errors in a config carry the line, a model target refuses --set input.path, export.into is
checked before the bake, typo suggestions, and the non-UTF-8 warning names its file."""

import json
import subprocess
import sys
import time
from pathlib import Path

import pytest

from bake import config
from bake.errors import ConfigError
from bake.scratch import sb3 as sb3_mod

TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 3 4\nf 1 4 2\nf 2 4 3\n"


def bake(args, cwd, timeout=300):
    return subprocess.run([sys.executable, "-m", "bake.cli", *map(str, args)], capture_output=True, text=True,
                          cwd=cwd, timeout=timeout)


def error_line(r, status):
    assert r.returncode == status, (r.returncode, r.stderr)
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    return r.stderr.strip()


def engine(path: Path, sprite: str = "Engine") -> Path:
    data, _ = sb3_mod.write_sb3([sb3_mod.Target("Stage", is_stage=True), sb3_mod.Target(sprite, layer_order=1)])
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_bytes(data)
    return path


@pytest.fixture
def layout(tmp_path):
    """tmp/cfg/bake.toml naming cfg/m.obj; tmp/models/other.obj; tmp/engine/x.sb3 (and a decoy
    cfg/engine/x.sb3 with another sprite, where the config's folder would resolve it)."""
    (tmp_path / "cfg").mkdir()
    (tmp_path / "cfg" / "m.obj").write_text(TRI)
    (tmp_path / "cfg" / "bake.toml").write_text('[input]\npath = "m.obj"\n[export]\nprecision = 4\n')
    (tmp_path / "models").mkdir()
    (tmp_path / "models" / "other.obj").write_text(TRI.replace("v 0 0 1", "v 0 0 2"))
    engine(tmp_path / "engine" / "x.sb3", "Engine")
    engine(tmp_path / "cfg" / "engine" / "x.sb3", "Decoy")
    return tmp_path


def test_paths_typed_with_set_resolve_against_the_current_folder(layout):
    r = bake(["run", "cfg/bake.toml", "--out", "o", "--quiet", "--set", "export.into=engine/x.sb3",
              "--set", 'export.into_target="Engine"', "--set", "input.path=models/other.obj"], cwd=layout)
    assert r.returncode == 0, r.stderr
    rep = json.loads((layout / "o" / "report.json").read_text())
    assert Path(rep["input"]["path"]) == (layout / "models" / "other.obj").resolve()
    export = next(s for s in rep["stages"] if s["name"] == "export")
    assert Path(export["details"]["into"]["project"]) == (layout / "engine" / "x.sb3").resolve()
    assert (layout / "o" / "x-other.sb3").is_file()
    # in the config file the same keys stay relative to the config's folder
    (layout / "cfg" / "bake.toml").write_text('[input]\npath = "m.obj"\n[export]\ninto = "engine/x.sb3"\n'
                                              'into_target = "Decoy"\n')
    r = bake(["run", "cfg/bake.toml", "--out", "o2", "--quiet"], cwd=layout)
    assert r.returncode == 0, r.stderr
    assert (layout / "o2" / "x-m.sb3").is_file()


def test_lightmap_cache_dir_in_a_config_is_relative_to_the_config(tmp_path, monkeypatch):
    (tmp_path / "c").mkdir()
    p = tmp_path / "c" / "bake.toml"
    p.write_text('[textures.lightmap]\ncache_dir = "cache"\n')
    monkeypatch.chdir(tmp_path)
    assert config.load(p).textures.lightmap.cache_dir == str(tmp_path.resolve() / "c" / "cache")
    assert config.load(p, ["textures.lightmap.cache_dir=mine"]).textures.lightmap.cache_dir == \
        str(tmp_path / "mine")
    assert config.load(p, ["textures.lightmap.cache_dir=none"]).textures.lightmap.cache_dir == "none"


def test_errors_in_set_values_say_they_came_from_the_command_line(layout):
    for setting, what in (("transform.scale=-1", "must be > 0"), ("bvh.leaf_size=abc", "expected an integer"),
                          ("textures.lightmap.resolution=5", "between 16 and 8192"),
                          ("export.precision=99", "between 1 and 15")):
        extra = ["--set", "textures.enabled=true"] if "lightmap" in setting else []
        line = error_line(bake(["run", "cfg/bake.toml", "--out", "o", "--set", setting, *extra], cwd=layout), 2)
        key = setting.split("=")[0]
        assert f"key '{key}'" in line and what in line, line
        assert f"--set {setting}" in line and "command line" in line, line
        assert "bake.toml" not in line, f"blamed on the config file, which has no such key: {line}"
    # the file's own value, overridden on the command line: still the command line's
    line = error_line(bake(["run", "cfg/bake.toml", "--out", "o", "--set", "export.precision=0"], cwd=layout), 2)
    assert "--set export.precision=0" in line and "bake.toml" not in line


@pytest.mark.parametrize("text,key,line,what", [
    ('[input]\npath = "m.obj"\n\n[transform]\nup = "y"\nscale = -2\n', "transform.scale", 6, "must be > 0"),
    ('[input]\npath = "m.obj"\n[export]\nprecision = 40\n', "export.precision", 4, "between 1 and 15"),
    ('[input]\npath = "m.obj"\n[textures]\nenabled = true\n[textures.lightmap]\nenabled = true\nresolution = 4\n',
     "textures.lightmap.resolution", 7, "between 16 and 8192"),
])
def test_range_errors_in_a_config_carry_the_line(tmp_path, text, key, line, what):
    (tmp_path / "m.obj").write_text(TRI)
    cfg = tmp_path / "bake.toml"
    cfg.write_text(text)
    msg = error_line(bake(["run", cfg, "--out", tmp_path / "o"], cwd=tmp_path), 2)
    assert f"bake.toml:{line}: key '{key}'" in msg and what in msg, msg


def test_set_input_path_with_a_model_target_is_an_error(layout):
    line = error_line(bake(["run", "models/other.obj", "--out", "o", "--set", "input.path=cfg/m.obj"], cwd=layout), 2)
    assert "input.path" in line and "other.obj" in line, line
    assert not (layout / "o").exists()


def test_a_bad_export_into_is_found_before_the_bake(tmp_path):
    big = tmp_path / "big.obj"
    n = 120  # a model that takes a while to bake, so "before" is measurable
    lines = [f"v {i} {j} {(i * j) % 7}" for i in range(n) for j in range(n)]
    lines += [f"f {i * n + j + 1} {i * n + j + 2} {(i + 1) * n + j + 2}" for i in range(n - 1) for j in range(n - 1)]
    big.write_text("\n".join(lines))
    engine(tmp_path / "engine.sb3", "Engine")
    sets = ["--set", "bvh.enabled=true", "--set", "bsp.enabled=true"]
    t0 = time.perf_counter()
    ok = bake(["run", big, "--out", tmp_path / "ok", "--quiet", *sets], cwd=tmp_path)
    full = time.perf_counter() - t0
    assert ok.returncode == 0, ok.stderr
    for setting, status, what in (("export.into=missing.sb3", 3, "project not found"),
                                  ("export.into=big.obj", 3, "big.obj"),
                                  ('export.into_target="Nope"', 3, "no sprite named 'Nope'")):
        extra = ["--set", "export.into=engine.sb3"] if "target" in setting else []
        t0 = time.perf_counter()
        r = bake(["run", big, "--out", tmp_path / "o", *sets, *extra, "--set", setting], cwd=tmp_path)
        took = time.perf_counter() - t0
        assert what in error_line(r, status)
        assert not (tmp_path / "o").exists(), "the bake ran (its output folder exists)"
        assert took < full, (took, full)


def test_typo_suggestions():
    cases = [(["lightning.enabled=true"], "did you mean 'lighting.enabled'?"),
             (["lighting.occlusion.samples=8"], "did you mean 'lighting.ao.samples'?"),
             (["bsp.candidatez=3"], "did you mean 'bsp.candidates'?"),
             (["mesh.simplfy.target_ratio=0.5"], "did you mean 'mesh.simplify.target_ratio'?")]
    for overrides, hint in cases:
        with pytest.raises(ConfigError) as e:
            config.load(None, overrides)
        assert hint in str(e.value), str(e.value)


def test_typo_suggestions_in_files_name_tables(tmp_path):
    p = tmp_path / "bake.toml"
    p.write_text("[lighting]\nenabled = true\n\n[lighting.occlusion]\nenabled = true\nsamples = 32\n")
    with pytest.raises(ConfigError) as e:
        config.load(p)
    assert e.value.line == 4 and "did you mean [lighting.ao]?" in str(e.value), str(e.value)
    p.write_text("[lightning]\nenabled = true\n")
    with pytest.raises(ConfigError) as e:
        config.load(p)
    assert e.value.line == 1 and "did you mean [lighting]?" in str(e.value), str(e.value)
    p.write_text("lightning.enabled = true\n")  # a dotted key: the whole key is mended
    with pytest.raises(ConfigError) as e:
        config.load(p)
    assert e.value.line == 1 and "did you mean 'lighting.enabled'?" in str(e.value), str(e.value)


def test_sweep_of_an_unknown_key_says_unknown_with_a_suggestion(tmp_path):
    (tmp_path / "m.obj").write_text(TRI)
    line = error_line(bake(["sweep", "m.obj", "--vary", "bsp.candidatez=4,16"], cwd=tmp_path), 2)
    assert "unknown key" in line and "did you mean 'bsp.candidates'?" in line, line


def test_non_utf8_warning_names_the_file(tmp_path):
    obj = tmp_path / "m.obj"
    obj.write_bytes(b"mtllib m.mtl\n" + TRI.encode().replace(b"f 1 2 3", b"usemtl caf\xe9\nf 1 2 3"))
    (tmp_path / "m.mtl").write_bytes(b"newmtl caf\xe9\nKd 1 0 0\n")
    r = bake(["run", "m.obj", "--out", "o"], cwd=tmp_path)
    assert r.returncode == 0, r.stderr
    warns = [ln for ln in r.stdout.splitlines() if "not UTF-8" in ln]
    assert warns and all("m.obj" in w or "m.mtl" in w for w in warns), warns
    assert any("m.obj" in w for w in warns), warns


@pytest.mark.parametrize("setting,key,what", [
    ("export.json_name=../escape.json", "export.json_name", "must be a file name, not a path"),
    ("export.json_name=", "export.json_name", "it is empty"),
    ("export.json_name=report.json", "export.json_name", "a name the bake writes itself"),
    ("export.sb3_name=report.html", "export.sb3_name", "a name the bake writes itself"),
    ("export.sb3_name=Report.MD", "export.sb3_name", "a name the bake writes itself"),
    ("export.into_name=lists", "export.into_name", "a name the bake writes itself"),
    # (issue 37: a project under another name was written and left out of the summary; the names
    # that used to collide with the others' now end in their own suffixes)
    ("export.json_name=m.sb3", "export.json_name", "must be a visible file name ending in .json"),
    ("export.json_name=M.sprite3", "export.json_name", "must be a visible file name ending in .json"),
    ("export.sb3_name=lists.json", "export.sb3_name", "must be a visible file name ending in .sb3"),
    ("export.sb3_name=x.txt", "export.sb3_name", "must be a visible file name ending in .sb3"),
    ("export.sb3_name=.hidden.sb3", "export.sb3_name", "must be a visible file name ending in .sb3"),
    ("export.into_name=merged.txt", "export.into_name", "must be a visible file name ending in .sb3"),
])
def test_output_names_are_checked_before_the_bake(layout, setting, key, what):
    """A user's review: export.json_name was never checked (a path failed after the bake with
    exit 1, report.json crashed, the .sb3's name failed as "bad input"), and export.sb3_name =
    report.html silently lost the project. Now each is exit 2 before baking, naming the key the
    user set, and no output folder is made."""
    r = bake(["run", "cfg/bake.toml", "--out", "o", "--quiet", "--set", setting], cwd=layout)
    line = error_line(r, 2)
    assert f"key '{key}'" in line and what in line, line
    assert not (layout / "o").exists()


def test_output_name_clash_in_a_config_names_its_line(layout):
    (layout / "cfg" / "bake.toml").write_text('[input]\npath = "m.obj"\n[export]\njson_name = "m.sb3"\n')
    line = error_line(bake(["run", "cfg/bake.toml", "--out", "o", "--quiet"], cwd=layout), 2)
    assert "bake.toml:4: key 'export.json_name'" in line, line


def test_reserved_output_names_cover_what_the_bake_writes_beside_its_outputs():
    """config.RESERVED_OUTPUT_NAMES repeats names other modules own (the reports, report.html's
    live script and sweep folder, the list and asset folders, the xatlas cache): it must keep
    every one of them, or a configured output name could take one again."""
    from bake.outputs import html, output
    from bake.export.lists import list_file_name
    from bake.textures.unwrap_cache import CACHE_SUBDIR

    owned = set(output.REPORT_FILES) | {html.HTML_NAME, html.LIVE_NAME, html.SWEEP_DIR, CACHE_SUBDIR.parts[0],
                                        list_file_name("verts").split("/")[0], "assets"}
    assert owned <= set(config.RESERVED_OUTPUT_NAMES), owned - set(config.RESERVED_OUTPUT_NAMES)
