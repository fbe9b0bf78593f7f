"""Config loading: types, unknown keys with suggestions and line numbers, overrides."""

import pytest

from bake import config
from bake.errors import ConfigError


def write(tmp_path, text):
    p = tmp_path / "bake.toml"
    p.write_text(text)
    return p


def test_defaults_run_only_the_always_on_stages():
    from bake.pipeline import plan
    cfg = config.load()
    ran = [spec.name for spec, on, _ in plan(cfg) if on]
    # textures: "auto", planned, and skipped when the model names no texture (tests/test_new_user_round2.py)
    assert ran == ["import", "transform", "triangulate", "clean", "textures", "export"]
    assert [why for spec, on, why in plan(cfg) if spec.name == "textures"] == ["textures.enabled = auto"]


def test_unknown_key_names_file_line_and_suggestion(tmp_path):
    p = write(tmp_path, '[input]\npath = "m.obj"\n\n[bsp]\nenabled = true\ncandidtes = 32\n')
    with pytest.raises(ConfigError) as e:
        config.load(p)
    msg = str(e.value)
    assert f"{p}:6" in msg and "bsp.candidtes" in msg and "did you mean 'bsp.candidates'" in msg
    assert e.value.exit_code == 2


def test_unknown_section_suggests(tmp_path):
    p = write(tmp_path, "[lightning]\nenabled = true\n")
    with pytest.raises(ConfigError, match=r"unknown table \[lightning\]; did you mean \[lighting\]\?"):
        config.load(p)


@pytest.mark.parametrize("text,key", [
    ('[bsp]\ncandidates = "many"\n', "bsp.candidates"),
    ('[bvh]\nleaf_size = 2.5\n', "bvh.leaf_size"),
    ('[mesh.clean]\nweld = 1\n', "mesh.clean.weld"),
    ('[transform]\nframe = "lefty"\n', "transform.frame"),
    ('[transform]\nscale = -1\n', "transform.scale"),
])
def test_wrong_types_and_values_are_errors_naming_the_key(tmp_path, text, key):
    with pytest.raises(ConfigError) as e:
        config.load(write(tmp_path, text))
    assert key in str(e.value)


def test_int_is_accepted_for_float_and_nested_tables(tmp_path):
    p = write(tmp_path, "[transform]\nscale = 2\n[mesh.simplify]\nenabled = true\ntarget_ratio = 0.5\n"
                        "[[lighting.lights]]\nkind = \"point\"\nposition = [1, 2, 3]\n")
    cfg = config.load(p)
    assert cfg.transform.scale == 2.0 and isinstance(cfg.transform.scale, float)
    assert cfg.mesh.simplify.enabled and cfg.mesh.simplify.target_ratio == 0.5
    assert cfg.lighting.lights[0].kind == "point" and cfg.lighting.lights[0].position == [1.0, 2.0, 3.0]
    assert cfg.base_dir == tmp_path.resolve()


def test_overrides_go_through_the_same_checks():
    cfg = config.load(None, ["bsp.enabled=true", "export.names.vertices=V", "lighting.ao.samples=16"])
    assert cfg.bsp.enabled is True and cfg.export.names.vertices == "V" and cfg.lighting.ao.samples == 16
    with pytest.raises(ConfigError, match="did you mean 'lighting.ao.samples'"):
        config.load(None, ["lighting.ao.sampels=3"])
    with pytest.raises(ConfigError, match="expected true or false"):
        config.load(None, ["bsp.enabled=maybe"])
    with pytest.raises(ConfigError, match="key=value"):
        config.load(None, ["bsp.enabled"])


def test_import_section_uses_toml_name(tmp_path):
    cfg = config.load(write(tmp_path, "[import]\nstrict = false\n"))
    assert cfg.import_.strict is False
    assert "import.strict" in config.all_keys()


def test_invalid_toml_names_line(tmp_path):
    with pytest.raises(ConfigError) as e:
        config.load(write(tmp_path, "[input]\npath = \n"))
    assert e.value.line == 2


def test_every_key_round_trips_through_set():
    cfg = config.Config()
    for key in config.all_keys():
        val = config.get_key(cfg, key)
        if isinstance(val, list):
            continue
        text = {True: "true", False: "false"}.get(val, None) if isinstance(val, bool) else None
        if text is None:
            text = repr(val) if isinstance(val, (int, float)) else f'"{val}"'
        config.apply_override(cfg, f"{key}={text}")
        assert config.get_key(cfg, key) == val


def test_numeric_keys_cover_sweepable_settings():
    keys = config.numeric_keys()
    assert "lighting.ao.samples" in keys and "bsp.candidates" in keys and "bvh.bins" in keys
    assert "bsp.enabled" not in keys


LIGHTS_TOML = """[lighting]
enabled = true

[[lighting.lights]]
kind = "sun"
angle = 2.0

[[lighting.lights]]
kind = "point"
{field} = {value}
position = [0, 1, 0]
"""


def test_light_fields_are_checked_like_any_key_naming_the_line(tmp_path):
    """Issue 17, item 7: a typo inside the second [[lighting.lights]] names its line and
    suggests the light field, not 'lighting.lights'."""
    with pytest.raises(ConfigError) as e:
        config.load(write(tmp_path, LIGHTS_TOML.format(field="angel", value="3.0")))
    assert e.value.line == 10 and e.value.key == "lighting.lights[1].angel"
    assert "did you mean 'angle'?" in str(e.value) and "\n" not in str(e.value)
    with pytest.raises(ConfigError, match="did you mean 'intensity'") as e:
        config.load(write(tmp_path, LIGHTS_TOML.format(field="angle", value="3").replace("angle = 2.0", "intensty = 2")))
    assert e.value.line == 6 and e.value.key == "lighting.lights[0].intensty"
    # range / shape checks name the field's line in the right block too
    with pytest.raises(ConfigError, match=r"must be \[r, g, b\]") as e:
        config.load(write(tmp_path, LIGHTS_TOML.format(field="color", value="[1, 1]")))
    assert e.value.line == 10 and e.value.key == "lighting.lights[1].color"
    cfg = config.load(write(tmp_path, LIGHTS_TOML.format(field="angle", value="3.0")))
    assert [lt.angle for lt in cfg.lighting.lights] == [2.0, 3.0]


@pytest.mark.parametrize("field,value,key", [("direction", '[0.5, "x", 1]', "direction[1]"),
                                             ("color", '[1, 1, "white"]', "color[2]")])
def test_a_bad_element_of_a_light_field_names_the_field_line(tmp_path, field, value, key):
    """A bad item inside a light's array names the line of that field, not the block's header
    (a user's review: line 7, the [[lighting.lights]] line, for a bad direction on line 10)."""
    with pytest.raises(ConfigError, match="expected a number") as e:
        config.load(write(tmp_path, LIGHTS_TOML.format(field=field, value=value)))
    assert e.value.key == f"lighting.lights[1].{key}" and e.value.line == 10


def test_light_fields_by_set_and_in_bake_keys(capsys):
    cfg = config.load(None, ["lighting.lights[0].intensity=2", "lighting.lights[0].kind=\"point\"",
                             "lighting.lights[1].angle=4"])
    assert [(lt.kind, lt.intensity, lt.angle) for lt in cfg.lighting.lights] == [("point", 2.0, 0.53),
                                                                                ("sun", 1.0, 4.0)]
    assert config.get_key(cfg, "lighting.lights[1].angle") == 4.0
    with pytest.raises(ConfigError, match="did you mean 'angle'"):
        config.load(None, ["lighting.lights[0].anlge=3"])
    with pytest.raises(ConfigError, match=r"\[0\] adds one"):
        config.load(None, ["lighting.lights[3].angle=3"])
    with pytest.raises(ConfigError, match="expected a number"):
        config.load(None, ["lighting.lights[0].angle=\"wide\""])
    from bake import cli

    assert cli.main(["keys"]) == 0
    lines = capsys.readouterr().out.splitlines()
    want = {f"lighting.lights[].{k}" for k in config.all_keys(config.LightConfig)}
    assert len(want) == 11 and want <= {ln.split(" = ")[0] for ln in lines}
    assert 'lighting.lights[].angle = 0.53' in lines and 'lighting.lights[].kind = "sun"' in lines
