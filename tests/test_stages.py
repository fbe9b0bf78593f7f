"""The stage registry (bake/stages.py): a stage is its package plus one entry. An example stage,
added and removed by the test itself, brings its own config section and shows in `bake keys`,
in the bake's report (report.json, report.md, its own section of report.html) and in `bake sweep`,
with nothing else of bake changed."""

from __future__ import annotations

import json
import time
from dataclasses import dataclass

import numpy as np
import pytest

from bake import cli, pipeline, stages
from bake import config as config_mod
from bake.errors import ConfigError
from bake.record import ReportSection, StageRecord
from bake.scene import Scene
from bake.sweep import sweep

from conftest import CORPUS

MODEL = CORPUS / "cube_quads_mtl"


@dataclass
class ExampleConfig:
    enabled: bool = False
    lift: float = 0.0  # moves the model up by this fraction of its diagonal


def example_stage(scene: Scene, cfg: ExampleConfig) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord("example")
    by = cfg.lift * scene.diagonal()
    positions = scene.positions.copy()
    positions[:, 1] += by
    rec.details["lifted_by"] = by
    rec.accuracy["lift_error"] = abs(by) * 1e-3  # the figure a sweep plots
    rec.seconds = time.perf_counter() - t0
    return scene.replace(positions=positions), rec


def check_example(cfg: ExampleConfig) -> None:
    if not -1.0 <= cfg.lift <= 1.0:
        raise ConfigError("must be between -1 and 1", key="example.lift")


def example_report(st: dict) -> ReportSection:
    return ReportSection("Example: how far the model was lifted", [("lifted by", f"{st['details']['lifted_by']:.4f}")])


EXAMPLE = stages.StageSpec(
    "example", example_stage, lambda c: c.example, lambda c: c.example.enabled, "example.enabled",
    keys=("example.",), error=("lift_error", "a thousandth of the lift"), check=check_example,
    report=example_report, config=("example", ExampleConfig))


@pytest.fixture
def example_added():
    before = stages.names()
    stages.add(EXAMPLE, after="transform")
    try:
        yield
    finally:
        stages.remove("example")
    assert stages.names() == before and "example" not in {k.split(".")[0] for k, _ in config_mod.key_defaults()}


def _model():
    return next(MODEL.glob("*.obj"))


def test_an_example_stage_appears_in_keys_report_and_sweep(example_added, tmp_path, capsys):
    # bake keys lists its section with the defaults
    assert cli.main(["keys"]) == 0
    keys = capsys.readouterr().out.splitlines()
    assert "example.enabled = false" in keys and "example.lift = 0.0" in keys
    assert stages.names().index("example") == stages.names().index("transform") + 1

    # a bake with it: report.json, report.md and its own section of report.html
    out = tmp_path / "out"
    code = cli.main(["run", str(_model()), "--out", str(out), "--quiet", "--set", "example.enabled=true",
                     "--set", "example.lift=0.5", "--set", "cache.dir=\"none\""])
    assert code == 0
    rep = json.loads((out / "report.json").read_text())
    st = next(s for s in rep["stages"] if s["name"] == "example")
    ran = [s["name"] for s in rep["stages"]]
    assert ran.index("example") == ran.index("transform") + 1
    assert rep["config"]["example"] == {"enabled": True, "lift": 0.5}
    verts = np.array(json.loads((out / "lists.json").read_text())["lists"]["verts"], float).reshape(-1, 3)
    assert st["details"]["lifted_by"] > 0
    assert verts[:, 1].min() == pytest.approx(st["details"]["lifted_by"] + _min_y_without(tmp_path), abs=1e-3)
    assert "example" in (out / "report.md").read_text()
    page = (out / "report.html").read_text()
    assert "Example: how far the model was lifted" in page

    # its range check runs before the bake, whether the stage runs or not
    with pytest.raises(ConfigError, match="example.lift"):
        pipeline.run(pipeline.load_config_for(_model(), ["example.lift=3"]), cache=None)

    # bake sweep varies its key, reruns it and plots its own error figure
    cfg = pipeline.load_config_for(_model(), ["example.enabled=true", "cache.dir=\"none\""])
    table = sweep(cfg, "example.lift", [0.0, 0.25], cache=None)
    assert table["stages"] == ["example"] and table["error_key"] == "lift_error"
    assert [r["error"] for r in table["rows"]] == pytest.approx([0.0, 0.25e-3 * _diagonal()])

    # a key set while it does not run is said to change nothing (the switch named)
    res = pipeline.run(pipeline.load_config_for(_model(), ["example.lift=0.2"]), cache=None)
    assert any("example.lift" in w and "example.enabled = true" in w for w in res.records[0].warnings)


def _min_y_without(tmp_path) -> float:
    out = tmp_path / "plain"
    assert cli.main(["run", str(_model()), "--out", str(out), "--quiet", "--set", "cache.dir=\"none\""]) == 0
    verts = np.array(json.loads((out / "lists.json").read_text())["lists"]["verts"], float).reshape(-1, 3)
    return float(verts[:, 1].min())


def _diagonal() -> float:
    res = pipeline.run(pipeline.load_config_for(_model(), ["cache.dir=\"none\""]), until="transform", cache=None)
    return res.scene.diagonal()


def test_the_registry_refuses_a_second_stage_of_a_name_and_a_section_of_a_built_in_name():
    with pytest.raises(ValueError, match="already"):
        stages.add(stages.spec("bsp"), after="bvh")
    clash = stages.StageSpec("clash", example_stage, lambda c: c.bsp, config=("bsp", ExampleConfig))
    with pytest.raises(ValueError, match="built-in"):
        stages.add(clash, after="bvh")
    assert "clash" not in stages.names()


def test_the_runner_names_no_stage():
    """The runner's rules come from the registry's fields, not from stage names."""
    from pathlib import Path

    src = Path(pipeline.__file__).read_text()
    for spec in stages.STAGES:
        assert f'"{spec.name}"' not in src, spec.name
