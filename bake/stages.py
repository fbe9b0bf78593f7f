"""The stage registry: every stage of a bake, in the order it runs, with all of its wiring.

A stage is a function ``(scene, section) -> (new scene, StageRecord)`` in its package. Its entry
here says everything the rest of bake needs to know about it, so the runner
(``bake.pipeline``), ``bake sweep``, the advice, ``bake keys`` and report.html read this table and
know no stage by name:

- ``entry``: the function, ``"module:function"`` (loaded when the stage runs, so a command that
  runs no stage imports none of their libraries; the layout test reads these as imports);
- ``section`` and ``enabled``: its part of the config (a function of the config, or the name of
  one) and whether it runs (``switch`` names the key, for the report); ``keys``: the config key
  prefixes it reads (a sweep of such a key reruns it and reports its seconds; a key set while it
  does not run is said to change nothing); ``config``: a section the stage brings itself, as
  (TOML table name, dataclass): the loader reads and lists it (``bake keys``) like the built-in
  ones (the registry tells the loader, :func:`add` and :func:`remove` too);
- ``error``: the figure of its record a sweep plots as the error (others use the image error);
- ``check``: the range check of its section, run before every bake whether the stage runs or not;
- ``advice``: what to tell the author after it ran (it may read the records before it);
- ``report``: its own section of report.html (``section(stage entry of report.json) ->
  ReportSection``, or ``section(entry, the whole report)`` to read other stages' entries too);
- ``on_grid``: it builds on the positions as the export will write them (the grid is fixed once,
  before the first such stage); ``leaves``: what it must leave for the bake to go on ("faces": an import without any is an
  input error; "triangles": likewise after triangulation and cleaning).

Adding a stage is its package and one entry below (or, at run time, :func:`add`).
"""

from __future__ import annotations

import dataclasses
import importlib
from dataclasses import dataclass
from typing import Any, Callable

from . import config as config_mod
from .config import Config
from .record import StageRecord
from .scene import Scene


def _load(target: str | Callable) -> Any:
    """A function named ``"module:function"`` (imported when first needed), or the function itself
    (a stage added at run time)."""
    if callable(target):
        return target
    mod_name, fn = target.split(":")
    return getattr(importlib.import_module(mod_name), fn)


def _always(_: Config) -> bool:
    return True


@dataclass(frozen=True)
class StageSpec:
    name: str
    entry: str | Callable  # "module:function" (or the function, for a stage added at run time)
    section: Callable[[Config], Any] | str  # or "module:function"
    enabled: Callable[[Config], Any] = _always
    switch: str | None = None  # the key that turns it on/off, for the report
    keys: tuple[str, ...] = ()
    error: tuple[str, str] | None = None  # (record key, label)
    check: str | Callable | None = None  # "module:function"(section)
    advice: str | Callable | None = None  # "module:function"(cfg, scene, record, records before)
    report: str | Callable | None = None  # "module:function"(stage entry[, report]) -> ReportSection | None
    on_grid: bool = False
    leaves: str | None = None  # "faces" | "triangles"
    config: tuple[str, type] | None = None  # (TOML table, dataclass) of a section the stage brings

    def section_of(self, cfg: Config) -> Any:
        """The stage's part of ``cfg`` (what its entry point is called with)."""
        return (_load(self.section) if isinstance(self.section, str) else self.section)(cfg)

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


def _textures_section(cfg: Config):
    """The textures section, told whether the lighting stage will bake into its lightmap atlas and
    where the bake's output folder is (the default xatlas cache)."""
    lit = cfg.lighting.enabled and cfg.lighting.target == "lightmap"
    return dataclasses.replace(cfg.textures, lightmap=dataclasses.replace(cfg.textures.lightmap, lit=lit,
                                                                          out_dir=cfg.out_dir))


def _hidden_section(cfg: Config):
    """The hidden stage's job, told which BSP tree the bake builds (the BSP stage's entry, its
    section and the written grid) when the proof compares the splits with and without the removal."""
    job = _load("bake.mesh.hidden.stage:job")
    if not (cfg.bsp.enabled and cfg.mesh.hidden.bsp_proof):
        return job(cfg)
    bsp = spec("bsp")
    return job(cfg, _load("bake.mesh.hidden.stage:TreeProof")(bsp.entry, bsp.section_of(cfg), written_precision(cfg)))


STAGES: tuple[StageSpec, ...] = (
    StageSpec("import", "bake.importers.stage:stage", "bake.importers.stage:job", keys=("import.",),
              advice="bake.advice:unused_textures", leaves="faces"),
    StageSpec("transform", "bake.mesh.transform:stage", lambda c: c.transform, keys=("transform.",)),
    StageSpec("triangulate", "bake.mesh.triangulate:stage", lambda c: c.mesh.triangulate,
              keys=("mesh.triangulate.",), leaves="triangles"),
    StageSpec("clean", "bake.mesh.clean:stage", lambda c: c.mesh.clean, lambda c: c.mesh.clean.enabled,
              "mesh.clean.enabled", keys=("mesh.clean.",), leaves="triangles"),
    StageSpec("hidden", "bake.mesh.hidden.stage:stage", _hidden_section, lambda c: c.mesh.hidden.enabled,
              "mesh.hidden.enabled", keys=("mesh.hidden.",), error=("wrong_pixel_share", "share of held-out "
                                                                     "pixels showing a dropped triangle"),
              report="bake.mesh.hidden.stage:section"),
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
                                       "(a bound: half the rounding step)"), report="bake.export.report:section",
              on_grid=True),
)


def written_precision(cfg: Config) -> int | None:
    """The significant digits positions are written with (``export.precision``; docs/formats.md
    "Numbers"), or None when nothing is written: the grid the ``on_grid`` stages build on."""
    return cfg.export.precision if cfg.export.enabled else None


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


def check_all(cfg: Config) -> None:
    """Every stage's range check of its section (``StageSpec.check``), whether the stage runs or
    not (a bad value under a switch that is off would otherwise wait, unsaid, for the day the
    switch is turned on). The loader runs it (:func:`bake.config.validate`); so does the runner,
    for a config made in code."""
    for s in STAGES:
        check = s.load_check()
        if check is not None:
            check(s.section_of(cfg))


def _publish(table: tuple[StageSpec, ...]) -> None:
    """Make ``table`` the registry, telling the loader the sections its stages bring and how to
    check them (refused, with the registry unchanged, when one takes a built-in section's name)."""
    global STAGES
    config_mod.use_stage_sections({s.config[0]: s.config[1] for s in table if s.config is not None}, check_all)
    STAGES = table


def add(new: StageSpec, *, after: str) -> None:
    """Put a stage into the table after the stage ``after`` (a plug-in, or a test's example
    stage); its section, if it brings one, becomes part of every config loaded from now on."""
    if new.name in names():
        raise ValueError(f"there is a stage '{new.name}' already")
    i = names().index(after) + 1
    _publish(STAGES[:i] + (new,) + STAGES[i:])


def remove(name: str) -> None:
    """Take a stage added with :func:`add` out of the table again."""
    spec(name)
    _publish(tuple(s for s in STAGES if s.name != name))


_publish(STAGES)
