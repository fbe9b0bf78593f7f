"""The lighting stage: ``stage(scene, LightingConfig) -> (Scene, StageRecord)``.

Flow (each step in its own module):

1. ``plan``: which effects the config and scene call for (lights from ``lighting.lights`` plus the
   model's KHR_lights_punctual lights, AO, sky, bounces); skipped ones get a reason.
2. ``targets``: the sample points: vertices (``target = "vertex"``, or when subdividing) and
   interior points of triangles bigger than ``face_cell`` (all triangles for ``"triangle"``).
3. Local effects at those points: ``direct`` (each light, soft shadows), ``sky``, ``ao``
   (which scales ``ambient``). With ``subdivide``, triangles whose colour varies are split
   (budgeted) and the new points evaluated, for ``subdivide_levels`` rounds.
4. ``bounce``: indirect light gathered ``bounces.count`` times on the final mesh.
5. ``color``: albedo x irradiance x exposure, tone map, encode -> ``vertex_colors`` and
   ``face_colors``. The linear irradiance and every component with its standard error stay in
   ``scene.artefacts.lighting`` (a :class:`LightingResult`).

The record lists every effect that ran (rays, seconds, error = an estimate of the RMSE of its
values over the sample points: the RMS of the points' standard errors, in irradiance units; AO in
AO units and calibrated against a high-sample reference, see ``ao.py``) and every one that was
skipped, with the reason, and splits the time into ray generation, Embree and shading
(thread-seconds). A bake whose every colour is black, or that has no light source, gets a
warning, the effects ``light sources`` / ``all black`` and a record problem (``--strict`` fails).
"""

from __future__ import annotations

import copy
import time

import numpy as np

from ..cache import Unsupported, active_memo
from ..colorspace import to_bytes
from ..config import LightingConfig
from ..record import StageRecord
from ..scene import Scene
from .baker import Baker, coloured
from .kernel import EffectStats
from .lightmap import bake_lightmap
from .plan import Plan, check_config, make_plan
from .rays import default_threads
from .sampling import effective_samples


def _effect_order(plan: Plan, baker: Baker | None) -> list[dict]:
    out: list[dict] = []
    cfg_effects = dict(plan.effects)
    for name, e in cfg_effects.items():
        if name.startswith("light[") or name in ("direct", "imported lights"):
            out.append({"name": name, "ran": False, "reason": e["reason"], "rays": 0, "seconds": 0.0})
    if baker is not None:
        for lt in plan.lights:
            reach = baker.reach[lt.index]
            st = baker.stats.get(lt.label)
            if reach["facing"] == 0:
                out.append({"name": lt.label, "ran": False, "rays": 0, "seconds": 0.0,
                            "reason": "reaches no surface: every sample point faces away from it, is out of "
                                      "its range or outside its cone"})
                continue
            st = st or EffectStats(name=lt.label, ran=True)
            st.ran = True
            soft = (lt.half_angle > 0) if lt.kind == "sun" else (lt.radius > 0)
            if not baker.cfg.shadows.enabled:
                st.reason = "light with no shadows (lighting.shadows.enabled = false)"
            else:
                st.reason = (f"{lt.kind} light, soft shadows ({st.samples} rays per point)" if soft and st.samples > 1
                             else f"{lt.kind} light, hard shadows (1 ray per point)")
            st.extra["source"] = lt.source
            st.extra["points_facing"] = reach["facing"]
            st.extra["points_lit"] = reach["lit"]
            if reach["lit"] == 0:
                st.warnings.append(f"{lt.label} is fully shadowed: it reaches no surface")
            out.append(st.to_effect())
    for name in ("sky", "ao", "bounces"):
        if name in cfg_effects:
            out.append({"name": name, "ran": False, "reason": cfg_effects[name]["reason"], "rays": 0,
                        "seconds": 0.0})
        elif baker is not None and name in baker.stats:
            st = baker.stats[name]
            if st.ran and not st.reason:
                st.reason = {"sky": "lighting.sky.enabled = true",
                             "ao": "lighting.ao.enabled = true (scales the ambient light)",
                             "bounces": f"lighting.bounces.count = {plan.bounces}"}[name]
            out.append(st.to_effect())
    return out


def _sources(plan: Plan, cfg: LightingConfig) -> tuple[bool, str]:
    """Whether anything can light the scene, and what (for the ``light sources`` effect)."""
    parts = [lt.label for lt in plan.lights]
    if plan.sky:
        parts.append("sky")
    if np.any(plan.ambient > 0):
        ao_only = not any(x > 0 for x in cfg.ambient)  # the plan took the ambient as white
        parts.append("ambient " + ("white (AO-only bake)" if ao_only
                                   else "[" + ", ".join(f"{x:g}" for x in plan.ambient) + "]"))
    if parts:
        return True, ", ".join(parts)
    return False, ("no light source: no usable light (lighting.lights and the model's), lighting.sky off or "
                   "black, lighting.ambient black and no AO-only bake")


def _black(out: Scene, albedo: np.ndarray, cfg: LightingConfig, has_source: bool, what: str) -> str | None:
    """A message when every colour the bake writes is black in 8 bits (``None`` otherwise)."""
    used = np.zeros(out.n_vertices, bool)
    used[np.asarray(out.triangles, np.int64).ravel()] = True
    shown = [to_bytes(out.face_colors[:, :3])]
    if out.vertex_colors is not None:
        shown.append(to_bytes(out.vertex_colors[used, :3]))
    if any(np.any(b > 0) for b in shown):
        return None
    res = out.artefacts.lighting
    if not has_source:
        why = what
    elif cfg.exposure == 0:
        why = "lighting.exposure = 0"
    elif not (np.any(res.face_irradiance > 0) or np.any(res.vertex_irradiance > 0)):
        why = "no light reaches a surface (every light faces away, is out of range or is shadowed)"
    elif not np.any(albedo[:, :3] > 0) and cfg.vertex_output == "color":
        why = "every surface colour (albedo) is black"
    else:
        why = (f"the light is too dim to show in 8 bits (largest irradiance "
               f"{float(max(res.face_irradiance.max(), res.vertex_irradiance.max())):.3g})")
    return f"every lit colour is black: {why}"


#: the keys that only the colour step reads (bake.lighting.baker.coloured), unless subdivision ran
COLOUR_KEYS = ("exposure", "tonemap")


def trace_key_parts(scene: Scene, cfg: LightingConfig) -> list | None:
    """The key of a reusable trace: the input scene and every lighting key but the colour step's
    (:data:`COLOUR_KEYS`). None when the trace depends on those too (``subdivide`` compares shown
    colours) or the stage bakes a lightmap (its texels are coloured inside the trace)."""
    if cfg.subdivide or cfg.target == "lightmap":
        return None
    from ..config import to_dict

    section = to_dict(cfg)
    for k in COLOUR_KEYS:
        section.pop(k, None)
    return ["lighting trace 1", section, scene]


def stage(scene: Scene, cfg: LightingConfig, *, albedo=None) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord(name="lighting")
    check_config(cfg)
    if scene.triangles is None or scene.n_triangles == 0:
        rec.effects.append({"name": "lighting", "ran": False, "reason": "the scene has no triangles",
                            "rays": 0, "seconds": 0.0})
        rec.seconds = time.perf_counter() - t0
        return scene, rec
    # A trace made for the same scene and keys but another exposure or tone map is reused (bake.cache.Memo)
    memo = active_memo() if albedo is None else None
    parts = trace_key_parts(scene, cfg) if memo is not None else None
    key = part = None
    if parts is not None:
        try:
            key = memo.key("lighting", *parts)
        except Unsupported:  # (a scene the entry format does not store: no reuse)
            key = None
        if key is not None:
            part = memo.get("lighting", key, lambda p: p if _is_trace(p) else None, "a lighting trace")
    reused = part is not None
    if reused:
        memo.used("lighting")
    baker = None
    if part is None:
        plan = make_plan(scene, cfg)
        baker = Baker(scene, cfg, plan, albedo)
        baker.trace()
        part = _trace_part(plan, baker, cfg)
        if key is not None:
            memo.put("lighting", key, part)
    out = coloured(part["traced"], cfg)
    rec.effects = copy.deepcopy(part["effects"])
    has_source, what = part["sources"]
    rec.effects.insert(0, {"name": "light sources", "ran": has_source, "reason": what, "rays": 0,
                           "seconds": 0.0})
    black = _black(out, part["traced"]["albedo"], cfg, has_source, what)
    if black is not None:  # loudly: a warning, an effect, and --strict fails the bake
        rec.effects.insert(1, {"name": "all black", "ran": True, "reason": black, "rays": 0, "seconds": 0.0})
        rec.warn(black)
        rec.problems.append(black)
    rec.effects.append(copy.deepcopy(part["subdivide"]))
    lightmap_figs = None
    if cfg.target == "lightmap":
        # per-triangle colours above (a fallback for flat fillers), then every texel of the atlas
        # the albedo of the unlit input: ``out`` carries lit vertex colours, which
        # Scene.triangle_albedo would multiply into the texels a second time
        out, lightmap_figs = bake_lightmap(out, cfg, albedo=baker.albedo(),
                                           texel_base=scene.replace(face_albedo=None).triangle_albedo())
        rec.effects.append({"name": "lightmap", "ran": True, "reason": "lighting.target = 'lightmap'",
                            "rays": int(sum(v["rays"] for v in lightmap_figs["rays"].values())),
                            "seconds": lightmap_figs["seconds"]})
        rec.accuracy["lightmap seam error (8-bit)"] = lightmap_figs["seam_error_8bit"]
    for w in part["warnings"]:
        rec.warn(w)
    rec.accuracy.update(part["accuracy"])
    if memo is not None:
        for w in memo.take_warnings():
            rec.warn(w)
    rec.seconds = time.perf_counter() - t0
    d = copy.deepcopy(part["details"])
    if not reused:
        d["timing"]["wall_seconds"] = round(rec.seconds, 6)
    rec.details = {
        "target": cfg.target,
        "lightmap": lightmap_figs,
        **d,
        "color_pipeline": f"albedo ({cfg.color_space}) x irradiance x exposure {cfg.exposure:g}, "
                          f"tonemap {cfg.tonemap}, encode {cfg.color_space}",
        "samples": {"ao": effective_samples(cfg.ao.samples), "sky": effective_samples(cfg.sky.samples),
                    "shadows": effective_samples(cfg.shadows.samples),
                    "bounces": effective_samples(cfg.bounces.samples)},
        "trace_reused": {"reused": reused, "traced_seconds": round(float(part["seconds"]), 6)},
    }
    return out, rec


def _trace_part(plan: Plan, baker: Baker, cfg: LightingConfig) -> dict:
    """What the stage needs of a trace besides the colours: :meth:`Baker.traced`, the effects,
    warnings, error figures and details (none of which depends on :data:`COLOUR_KEYS` when the
    trace is reusable)."""
    t_start = baker.t_start
    if cfg.subdivide:
        sub = {"name": "subdivide", "ran": baker.subdiv["added"] > 0, "rays": 0, "seconds": 0.0,
               "reason": baker.subdiv["stopped"], "rounds": baker.subdiv["rounds"],
               "triangles_added": baker.subdiv["added"]}
    else:
        sub = {"name": "subdivide", "ran": False, "rays": 0, "seconds": 0.0, "reason": "lighting.subdivide = false"}
    effects = _effect_order(plan, baker)  # (first: it marks the lights that ran and adds their warnings)
    warnings, accuracy = [], {}
    for st in baker.stats.values():
        warnings.extend(st.warnings)
        if st.ran and st.rays:
            accuracy[f"{st.name} error"] = st.error
    timers = baker.ctx.timers.as_dict()
    seconds = time.perf_counter() - t_start
    details = {
        "threads": default_threads(cfg.threads),
        "points": {"vertices": int(baker.v_done.sum()), "triangles_with_interior_points": int(baker.f_done.sum())},
        "rays": int(sum(st.rays for st in baker.stats.values())),
        "timing": {"build_seconds": round(baker.ctx.build_seconds, 6), "thread_seconds": timers,
                   "wall_seconds": round(seconds, 6)},
        "notes": list(plan.notes),
        "ambient": [float(x) for x in plan.ambient],
    }
    return {"traced": baker.traced(), "effects": effects, "sources": _sources(plan, cfg),
            "subdivide": sub, "warnings": warnings, "accuracy": accuracy, "details": details, "seconds": seconds}


def _is_trace(part) -> bool:
    keys = {"traced", "effects", "sources", "subdivide", "warnings", "accuracy", "details", "seconds"}
    return isinstance(part, dict) and keys <= set(part) and isinstance(part["traced"], dict) and \
        isinstance(part["traced"].get("scene"), Scene) and isinstance(part["effects"], list)
