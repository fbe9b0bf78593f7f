"""The stage registry: every stage of a bake, in the order it runs, with all of its wiring.

A stage is a function ``(scene, section) -> (new scene, StageRecord)`` in its package. Its entry
here says everything the rest of bake needs to know about it, so the runner
(``bake.pipeline``), ``bake sweep``, the advice, ``bake keys`` and report.html read this table and
know no stage by name:

- ``entry``: the function, ``"module:function"`` (loaded when the stage runs, so a command that
  runs no stage imports none of their libraries; the layout test reads these as imports);
- ``section`` and ``enabled``: its part of the config and whether it runs (``switch`` names the
  key, for the report); ``keys``: the config key prefixes it reads (a sweep of such a key reruns
  it and reports its seconds; a key set while it does not run is said to change nothing);
- ``error``: the figure of its record a sweep plots as the error (others use the image error);
- ``check``: the range check of its section, run before every bake whether the stage runs or not;
- ``advice``: what to tell the author after it ran (it may read the records before it);
- ``report``: its own section of report.html (``section(stage entry of report.json) ->
  ReportSection``);
- ``on_grid``: it builds on the positions as the export will write them (the grid is fixed once,
  before the first such stage); ``checks_coordinates``: the model's range is checked after it;
  ``leaves``: what it must leave for the bake to go on ("faces": an import without any is an
  input error; "triangles": likewise after triangulation and cleaning).

Adding a stage is its package and one entry below.
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable

from .config import Config, ImportJob
from .record import StageRecord
from .scene import Scene


def _load(target: str) -> Any:
    mod_name, fn = target.split(":")
    return getattr(importlib.import_module(mod_name), fn)


def _always(_: Config) -> bool:
    return True


@dataclass(frozen=True)
class StageSpec:
    name: str
    entry: str  # "module:function"
    section: Callable[[Config], Any]
    enabled: Callable[[Config], Any] = _always
    switch: str | None = None  # the key that turns it on/off, for the report
    keys: tuple[str, ...] = ()
    error: tuple[str, str] | None = None  # (record key, label)
    check: str | None = None  # "module:function"(section)
    advice: str | None = None  # "module:function"(cfg, scene, record, records before)
    report: str | None = None  # "module:function"(stage entry of report.json) -> ReportSection | None
    on_grid: bool = False
    checks_coordinates: bool = False
    leaves: str | None = None  # "faces" | "triangles"

    def load(self) -> Callable[[Scene, Any], tuple[Scene, StageRecord]]:
        return _load(self.entry)

    def load_check(self) -> Callable[[Any], None] | None:
        return _load(self.check) if self.check else None

    def load_advice(self) -> Callable[..., None] | None:
        return _load(self.advice) if self.advice else None

    def load_report(self) -> Callable[[dict], Any]:
        return _load(self.report)

    def reads(self, key: str) -> bool:
        """Whether the stage reads the config key ``key``."""
        return any(key.startswith(prefix) for prefix in self.keys)


def _import_job(cfg: Config) -> ImportJob:
    p = Path(cfg.input.path)
    if not p.is_absolute():
        p = cfg.base_dir / p
    return ImportJob(path=p, format=cfg.input.format, strict=cfg.import_.strict, scene=cfg.import_.scene)


def _textures_section(cfg: Config):
    """The textures section, told whether the lighting stage will bake into its lightmap atlas."""
    lit = cfg.lighting.enabled and cfg.lighting.target == "lightmap"
    return dataclasses.replace(cfg.textures, lightmap=dataclasses.replace(cfg.textures.lightmap, lit=lit))


STAGES: tuple[StageSpec, ...] = (
    StageSpec("import", "bake.importers.stage:stage", _import_job, keys=("import.",),
              advice="bake.advice:unused_textures", checks_coordinates=True, leaves="faces"),
    StageSpec("transform", "bake.mesh.transform:stage", lambda c: c.transform, keys=("transform.",),
              checks_coordinates=True),
    StageSpec("triangulate", "bake.mesh.triangulate:stage", lambda c: c.mesh.triangulate,
              keys=("mesh.triangulate.",), leaves="triangles"),
    StageSpec("clean", "bake.mesh.clean:stage", lambda c: c.mesh.clean, lambda c: c.mesh.clean.enabled,
              "mesh.clean.enabled", keys=("mesh.clean.",), leaves="triangles"),
    StageSpec("simplify", "bake.mesh.simplify.stage:stage", lambda c: c.mesh.simplify, lambda c: c.mesh.simplify.enabled,
              "mesh.simplify.enabled", keys=("mesh.simplify.",),
              error=("hausdorff_max", "Hausdorff max, fraction of the diagonal"),
              report="bake.mesh.simplify.report:section"),
    StageSpec("textures", "bake.textures.stage:stage", _textures_section, lambda c: c.textures.enabled,
              "textures.enabled", keys=("textures.",), check="bake.textures.stage:check_config"),
    StageSpec("lighting", "bake.lighting.stage:stage", lambda c: c.lighting, lambda c: c.lighting.enabled,
              "lighting.enabled", keys=("lighting.", "textures.lightmap."),
              error=("rmse", "RMSE of shown colours against the reference (0..1)"),
              check="bake.lighting.plan:check_config", advice="bake.advice:unplaced_or_dark_lights"),
    StageSpec("bsp", "bake.bsp.stage:stage", lambda c: c.bsp, lambda c: c.bsp.enabled, "bsp.enabled",
              keys=("bsp.",), error=("inflation", "triangles added by splits (fraction of the input)"),
              advice="bake.advice:bsp_size", report="bake.bsp.report:section", on_grid=True),
    StageSpec("bvh", "bake.bvh.stage:stage", lambda c: c.bvh, lambda c: c.bvh.enabled, "bvh.enabled",
              keys=("bvh.",), error=("sah_cost", "SAH cost (expected node + triangle tests per ray)"),
              check="bake.bvh.stage:check_config"),
    StageSpec("export", "bake.export.stage:stage", lambda c: c.export, lambda c: c.export.enabled,
              "export.enabled", keys=("export.",),
              error=("position_error", "largest position rounding error, fraction of the diagonal "
                                       "(a bound: half the rounding step)"), on_grid=True),
)


def names() -> list[str]:
    return [s.name for s in STAGES]


def spec(name: str) -> StageSpec:
    for s in STAGES:
        if s.name == name:
            return s
    raise KeyError(name)


def stages_for(key: str) -> tuple[str, ...]:
    """The stages that read a config key, in the order they run."""
    return tuple(s.name for s in STAGES if s.reads(key))
