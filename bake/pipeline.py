"""Plans which stages a config and scene call for, runs them, and records time and accuracy.

A stage is a function ``(scene, section) -> (new scene, StageRecord)``. Stages do not import
each other; the registry (``bake.stages``) lists them in order with their wiring, and this
runner knows none of them by name. Optional stages are switched by ``<section>.enabled``; the
report says for every stage whether it ran and, if not, why.
"""

from __future__ import annotations

import copy
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Collection


from . import stages as registry
from . import progress as progress_mod
from . import config as config_mod
from .config import Config
from .errors import BakeError, ConfigError, InputError, StageError
from .record import StageRecord
from .stages import StageSpec, stages_for
from .scene import Scene
from .scratch.numbers import position_decimals


def unused_settings(cfg: Config, ran: Collection[str], idle: dict[str, str] | None = None) -> list[str]:
    """One line per key the author set (in the config or with --set) in a section whose stage
    does not run: it changes nothing, and the line names the switch that would run it, or, for a
    stage that found nothing to do (``idle``: stage name -> why), why."""
    switch = {spec.name: spec.switch for spec in registry.STAGES}
    unused: dict[str, list[str]] = {}
    for key, where in cfg.given.items():
        stages = stages_for(key)
        if not stages or any(s in ran for s in stages) or switch.get(stages[0]) in (None, key) or "[" in key:
            continue  # (a field of one [[lights]] entry: the list itself is named)
        unused.setdefault(stages[0], []).append(key if where == "file" else f"{key} ({where})")
    idle = idle or {}
    return [f"{', '.join(keys)} {'is' if len(keys) == 1 else 'are'} set, but the {stage} stage "
            + (f"has nothing to do ({idle[stage]})" if stage in idle else "does not run")
            + f", so {'it changes' if len(keys) == 1 else 'they change'} nothing"
            + ("" if stage in idle else f" (set {switch[stage]} = true)")
            for stage, keys in unused.items()]


def with_grid(scene: Scene, cfg: Config) -> Scene:
    """The scene with the grid its positions will be written on (the registry's
    :func:`~bake.stages.written_precision` of the scene's size), fixed once, before the first
    stage that is ``on_grid`` runs. Stages read it from the scene, never from another's section."""
    precision = registry.written_precision(cfg)
    if scene.position_decimals is not None or precision is None:
        return scene
    return scene.replace(position_decimals=position_decimals(scene.scale(), precision))


def stage_count(cfg: Config) -> int:
    """How many stages a config runs (the progress bar's length)."""
    return sum(1 for _, on, _ in plan(cfg) if on)


def plan(cfg: Config) -> list[tuple[StageSpec, bool, str]]:
    """Each stage with whether it runs and why (or why not)."""
    out = []
    for spec in registry.STAGES:
        value = spec.enabled(cfg)
        on = bool(value)
        if spec.switch is None:
            reason = "always runs"
        else:  # ("auto": the stage runs, and says it was skipped when the scene gives it nothing to do)
            reason = f"{spec.switch} = {value if isinstance(value, str) else 'true' if on else 'false'}"
        out.append((spec, on, reason))
    return out


@dataclass
class BakeResult:
    scene: Scene
    records: list[StageRecord]
    skipped: list[dict[str, Any]]
    seconds: float
    config: Config
    # the stage cache's part in this bake (None without a cache): where it is, which stages came
    # from it, which were stored, its warnings
    cache: dict[str, Any] | None = None
    # entries waiting for the outputs to be written (a first bake into a new folder): finish_cache
    cache_session: Any = None
    # the stage cache's memos (bake.cache.Memo: the BSP tree, the previews' renders), None without a cache
    memo: Any = None


def finish_cache(result: BakeResult) -> None:
    """Write the stage cache entries a bake kept back until its outputs were written."""
    if result.cache_session is not None:
        result.cache_session.finish()
        result.cache_session = None


# (stage name, event: "start" | "done" | "cached" | "skipped" (an idle stage) | "step", and for
# "step" what the stage does now)
Progress = Callable[..., None]


def run(cfg: Config, *, progress: Progress | None = None, until: str | None = None,
        scene: Scene | None = None, observe: Callable[[str, Scene], None] | None = None,
        cache: Any = "auto", recompute: Collection[str] = ()) -> BakeResult:
    """Run every stage the config calls for. ``until`` stops after the named stage; ``observe``
    is called with each stage's name and output scene (``bake sweep`` compares the lighting
    stage's colours before later stages split triangles).

    ``cache``: ``"auto"`` = the stage cache the config names (``cache.dir``, or the output folder's
    when ``Config.out_dir`` is set; ``bake.cache.StageCache.for_config``), a ``StageCache``, or None.
    The bake loads the entry of the deepest stage whose key is unchanged and runs the stages after
    it; ``observe`` then sees the loaded stage's scene, not those of the stages before it. Stages
    named in ``recompute`` and every stage after the first of them always run and are not stored
    (``bake sweep`` times them); the stages after them may reuse work inside the stage (the
    cache's memos: a BSP tree the new colours do not change), the ``recompute`` stages reuse
    none. A bake from a given ``scene`` uses no cache."""
    from . import cache as cache_mod

    t0 = time.perf_counter()
    records: list[StageRecord] = []
    cold: list[StageRecord] = []  # the records as computed (what entries store)
    skipped: list[dict[str, Any]] = []
    active: list[StageSpec] = []
    check_sections(cfg)
    for spec, on, reason in plan(cfg):
        if not on:
            skipped.append({"name": spec.name, "ran": False, "reason": reason})
            continue
        active.append(spec)
        if until == spec.name:
            break
    if scene is not None:
        cache = None
    elif cache == "auto":
        cache = cache_mod.StageCache.for_config(cfg)
    scene = scene if scene is not None else Scene()
    limit = next((i for i, spec in enumerate(active) if spec.name in recompute), len(active))
    session = cache.session() if cache is not None else None
    memo = cache_mod.Memo(cache.store) if cache is not None else None
    sections = [spec.section_of(cfg) for spec in active]
    info: dict[str, Any] | None = None
    start, prev_key, covered = 0, None, frozenset()
    pending: list[str] = []  # cache warnings for the next record
    if session is not None:
        info = {"where": cache.store.describe(), "from_cache": [], "stored": [], "warnings": session.warnings}
        steps = session.plan([(spec.name, sec) for spec, sec in zip(active, sections)])
        hit = session.load_deepest(steps, limit)
        pending = list(session.warnings)
        if hit is not None:
            start = hit.index + 1
            prev_key, covered = steps[hit.index].key, steps[hit.index].covered
            scene = hit.scene
            cold = list(hit.records)
            for k, rec in enumerate(hit.records):
                shown = _from_cache(rec, hit.seconds if k == hit.index else 0.0)
                # advice reads the config beyond the stage's section (the import's warning about
                # textures.enabled): given again for this bake's config
                _advise(registry.spec(rec.name), cfg, scene, shown, records)
                records.append(shown)
                if progress:
                    progress(rec.name, "skipped" if rec.idle else "cached")
            info["from_cache"] = [r.name for r in hit.records]
            info["load_seconds"] = hit.seconds
            if observe is not None:
                observe(active[hit.index].name, scene)
    for i in range(start, len(active)):
        spec = active[i]
        fn = spec.load()
        if spec.on_grid:
            scene = with_grid(scene, cfg)
        if progress:
            progress(spec.name, "start")
        counts_in = counts(scene)
        t = time.perf_counter()
        try:
            # (the stages a sweep varies reuse nothing: their seconds are what it measures)
            steps = None if progress is None else (lambda text, _n=spec.name: progress(_n, "step", text))
            with cache_mod.using_memo(memo if spec.name not in recompute else None), progress_mod.reporting(steps):
                scene, rec = fn(scene, sections[i])
        except ConfigError as e:
            raise _in_config_file(e, cfg) from None
        except BakeError:
            raise
        except MemoryError:
            raise StageError(f"stage '{spec.name}' ran out of memory") from None
        rec.seconds = rec.seconds or (time.perf_counter() - t)
        if spec.leaves == "faces" and scene.n_polygons == 0:
            why = "; ".join(rec.warnings[:3])
            raise InputError("has no faces to bake" + (f" ({why})" if why else ""), path=scene.source.path)
        if until is None and spec.leaves == "triangles" and scene.triangles is not None \
                and scene.n_triangles == 0:
            # every face had repeated corners or no area: an empty bake is not what was asked for
            # (`bake inspect`, which stops at clean, shows such a model instead)
            why = "; ".join(rec.warnings[:3])
            raise InputError(f"has no triangles left to bake after {spec.name}: every face is degenerate "
                             "(repeated corners, or an area under mesh.clean.area_tolerance)"
                             + (f" ({why})" if why else ""), path=scene.source.path)
        if not rec.counts_in:
            rec.counts_in = counts_in
        if not rec.counts_out:
            rec.counts_out = counts(scene)
        cold.append(copy.deepcopy(rec))  # as computed: what the cache stores (advice is added per bake)
        _advise(spec, cfg, scene, rec, records)
        for w in pending:
            rec.warn(w)
        pending = []
        records.append(rec)
        if session is not None and i < limit:
            base = session.base(prev_key, spec.name, sections[i])
            prev_key, covered, warning = session.store_stage(spec.name, base, covered, scene, cold)
            if warning:
                rec.warn(warning)
                session.warnings.append(warning)
        if observe is not None:
            observe(spec.name, scene)
        if progress:
            progress(spec.name, "skipped" if rec.idle else "done")
    records, idle = _idle_to_skipped(records, skipped)
    if until is None and records:
        # settings of a stage that did not run: said with the first stage, a problem under --strict
        for line in unused_settings(cfg, {r.name for r in records}, idle):
            records[0].warn(line)
            records[0].problems.append(line)
    later = None
    if session is not None:
        if session.deferred():  # a new output folder: written once the outputs are (output.finish)
            later = session
        else:
            info["dropped"] = len(session.finish())
        info["stored"] = list(session.stored)
        info["memos_reused"] = list(memo.reused)
    return BakeResult(scene=scene, records=records, skipped=skipped,
                      seconds=time.perf_counter() - t0, config=cfg, cache=info, cache_session=later,
                      memo=memo)


def _idle_to_skipped(records: list[StageRecord], skipped: list[dict[str, Any]]
                     ) -> tuple[list[StageRecord], dict[str, str]]:
    """A stage that found nothing to do in this scene (``StageRecord.idle``: the textures stage
    under ``textures.enabled = "auto"`` on a model without textures) is reported as skipped, with
    its reason; a warning it carries (the cache's) moves to the next stage that ran. Returns the
    records of the stages that ran and the idle ones' reasons by name."""
    kept: list[StageRecord] = []
    idle: dict[str, str] = {}
    carried: list[str] = []
    for rec in records:
        if rec.idle:
            skipped.append({"name": rec.name, "ran": False, "reason": rec.idle})
            idle[rec.name] = rec.idle
            carried.extend(rec.warnings)
            continue
        for w in carried:
            rec.warn(w)
        carried = []
        kept.append(rec)
    if carried and kept:
        for w in carried:
            kept[-1].warn(w)
    return kept, idle


def _from_cache(rec: StageRecord, seconds: float) -> StageRecord:
    """A record loaded from the cache, as this bake reports it: the time this bake spent on it
    (loading the entry, or nothing for the stages before the loaded one) and, in
    ``details["cache"]``, that it came from the cache and how long computing it took."""
    out = copy.deepcopy(rec)
    out.details["cache"] = {"from_cache": True, "computed_seconds": round(float(rec.seconds), 6)}
    out.seconds = seconds
    return out


def check_sections(cfg: Config) -> None:
    """The stages' range checks (:func:`bake.stages.check_all`) before the bake, for a config
    made in code as for one loaded (the loader ran them already)."""
    try:
        registry.check_all(cfg)
    except ConfigError as e:
        raise _in_config_file(e, cfg) from None


def _advise(spec: StageSpec, cfg: Config, scene: Scene, rec: StageRecord, records: list[StageRecord]) -> None:
    """The stage's advice (``StageSpec.advice``), added to its record."""
    check = spec.load_advice()
    if check is not None:
        check(cfg, scene, rec, records)


def run_stage(name: str, scene: Scene, cfg: Config) -> tuple[Scene, StageRecord]:
    """One stage on a given scene, with its section of ``cfg`` (``bake inspect`` shows the lists
    the export stage would write of the mesh as cleaned)."""
    spec = registry.spec(name)
    if spec.on_grid:
        scene = with_grid(scene, cfg)
    return spec.load()(scene, spec.section_of(cfg))


def _in_config_file(e: ConfigError, cfg: Config) -> ConfigError:
    """A stage's range check names the key; add where its value came from (the config file and
    the key's line, or the --set on the command line)."""
    if e.path is not None or e.key is None:
        return e
    return config_mod.error_at(cfg, e.key, e.message)


def counts(scene: Scene) -> dict[str, int]:
    return {"polygons": scene.n_polygons, "triangles": scene.n_triangles,
            "vertices": scene.n_vertices, "materials": len(scene.materials)}


def load_config_for(target: str | Path, overrides: list[str] | None = None) -> Config:
    """``bake run MODEL`` or ``bake run CONFIG.toml``: a config either way."""
    p = Path(target)
    if p.suffix.lower() == ".toml":
        cfg = config_mod.load(p, overrides)
        if not cfg.input.path:
            raise ConfigError("no model to bake: set input.path (relative to the config)", path=p,
                              key="input.path")
        return cfg
    cfg = config_mod.load(None, overrides)
    given = config_mod.origin(cfg, "input.path")
    if given is not None:
        raise ConfigError(f"{given} names a model, and so does the command line ({p}); give one model, or "
                          "a config whose input.path names it", key="input.path")
    cfg.input.path = str(p.resolve())
    cfg.base_dir = Path.cwd()
    return cfg
