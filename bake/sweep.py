"""Accuracy against time: bake at several values of one numeric config key and compare.

``bake sweep MODEL --vary KEY=V1,V2,...`` runs the whole pipeline once per value of any numeric
key of any stage (simplify targets, BSP candidates, BVH bins, AO and shadow samples, lightmap
resolution, ...) and writes a table, as JSON and as an SVG plot of error and bytes against
seconds, into ``OUT/sweeps/<key>.json|svg`` where ``bake report OUT`` shows it. One untimed
warm-up bake of the first value runs before the timed ones, so loading libraries is not charged
to the first row.

Every row has: the seconds of the stage(s) the key belongs to and of the whole bake, the bytes
the lists add to project.json, the triangles written, the stage's own accuracy figures, and the
*image error*: RMSE (0..1) of depth-buffer previews rendered from the written lists (what Scratch
will show) against the reference run's, from the same cameras. The plotted ``error`` is the
figure that measures the key's trade-off: Hausdorff distance for simplify, shown-colour RMSE
against the reference for lighting (as before, with each effect's actual error next to the
stage's own estimate), the split inflation for BSP, the SAH cost for BVH, the image error
otherwise (lightmap resolution, textures).

API::

    table = sweep("bake.toml", "lighting.ao.samples", [16, 64, 256], reference=4096,
                  out="bake-out/model/sweeps/lighting.ao.samples")   # writes .json and .svg
    key, values = parse_vary("mesh.simplify.target_ratio=0.02,0.1,0.5")

``scene=`` bakes a given :class:`~bake.scene.Scene` with the lighting stage alone (no import,
no export: lighting keys only), for tests and for sweeping before a model is on disk.

Stage reuse: the stages before the key's stage do not change from row to row, so every bake after
the first loads them from the stage cache (bake/cache/): the bake's folder cache when it has one
(``bake sweep`` uses ``OUT/.bake-cache/stages``, so a sweep after ``bake run`` does not even
compute them once), else one in memory for the sweep. The key's stage and every stage after it
always run (their seconds are the point of the sweep) and are not stored; the key's stages reuse
nothing, the stages after them may reuse work inside the stage (a BSP tree whose merges the new
colours do not change: a row's ``reused_in_stages``). ``cache=None`` bakes every row from
scratch.
"""

from __future__ import annotations

import copy
import io
import json
import math
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Sequence

import numpy as np

from . import config as config_mod
from .files import write_atomic
from .config import Config
from .errors import ConfigError
from .stages import spec, stages_for
from .scene import Scene

# the figure plotted as "error" for a key whose first stage names none (StageSpec.error)
IMAGE_ERROR = ("image_rmse", "RMSE of preview images against the reference (0..1)")
PREVIEW_SIZE = (160, 120)


def error_of(key: str) -> tuple[str, str]:
    st = stages_for(key)
    return (spec(st[0]).error or IMAGE_ERROR) if st else IMAGE_ERROR


def parse_vary(text: str, option: str = "--vary") -> tuple[str, list[float]]:
    """``"section.key=1,2,4"`` -> ``("section.key", [1, 2, 4])`` (numbers as ints when whole);
    errors name ``option``, the command-line option the values came from."""
    if "=" not in text:
        raise ConfigError(f"--vary expects section.key=v1,v2,..., got {text!r}")
    key, vals = text.split("=", 1)
    key = key.strip()
    config_mod.get_key(Config(), key)  # an unknown key is named as such, with a suggestion
    if key not in config_mod.numeric_keys():
        raise ConfigError("is not a numeric key (sweep varies ints and floats)", key=key)
    out: list[float] = []
    for v in vals.split(","):
        v = v.strip()
        if not v:
            continue
        try:
            f = float(v)
        except ValueError:
            raise ConfigError(f"{option} value {v!r} is not a number", key=key) from None
        if not math.isfinite(f):
            raise ConfigError(f"{option} value {v!r} is not finite", key=key)
        out.append(int(f) if f.is_integer() and "." not in v and "e" not in v.lower() else f)
    if not out:
        raise ConfigError(f"{option} needs at least one value", key=key)
    return key, out


def _load(cfg: str | Path | Config) -> Config:
    if isinstance(cfg, Config):
        return copy.deepcopy(cfg)
    return config_mod.load(Path(cfg))


def _with_value(cfg: Config, key: str, value: Any) -> Config:
    c = copy.deepcopy(cfg)
    current = config_mod.get_key(c, key)
    if isinstance(current, bool) or not isinstance(current, (int, float)):
        raise ConfigError("is not a numeric key (sweep varies ints and floats)", key=key)
    if isinstance(current, int) and not float(value).is_integer():
        raise ConfigError(f"expects an integer, got {value!r}", key=key)
    text = repr(int(value)) if isinstance(current, int) else repr(float(value))
    config_mod.apply_override(c, f"{key}={text}")
    config_mod.validate(c)
    return c


def _value_config(cfg: Config, key: str, value: Any, flag: str) -> Config:
    """:func:`_with_value`, with an error naming the sweep's option (``--vary``, ``--reference``)
    that gave the value instead of the ``--set`` it is applied as (``ConfigError.message`` is the
    bare message; the origin is kept apart)."""
    try:
        return _with_value(cfg, key, value)
    except ConfigError as e:
        raise ConfigError(f"{flag} value {value!r}: {e.message}", key=e.key or key) from None


@dataclass
class _Run:
    scene: Scene
    records: dict[str, dict]  # stage name -> record JSON
    seconds: float  # the key's stage(s)
    total: float
    lists: dict | None = None  # what the export wrote (lists.json), None without export
    report: dict | None = None  # report.json's shape (config, materials) for the previews
    final: Scene | None = None  # the scene after the last stage (else ``scene``)
    cached: list[str] | None = None  # stages loaded from the stage cache
    reused: list[str] | None = None  # stages after the key's that reused work (bake.cache.Memo kinds)


def _bake(cfg: Config, scene: Scene | None, key: str, stage_cache: Any = None) -> _Run:
    """One bake: the lighting stage alone on ``scene``, or the whole pipeline (the stages before
    the key's from ``stage_cache`` when it has them)."""
    t0 = time.perf_counter()
    if scene is not None:
        from .pipeline import run_stage

        if not key.startswith("lighting."):
            raise ConfigError("sweeping a given scene supports lighting keys only", key=key)
        out, rec = run_stage("lighting", scene, cfg)
        r = rec.to_json()
        return _Run(out, {"lighting": r}, r["seconds"], time.perf_counter() - t0)
    from .outputs import report as report_mod
    from .pipeline import run

    seen: dict[str, Scene] = {}
    res = run(cfg, observe=lambda name, sc: seen.__setitem__(name, sc) if name == "lighting" else None,
              cache=stage_cache, recompute=stages_for(key))
    total = time.perf_counter() - t0
    recs = {r.name: r.to_json() for r in res.records}
    stages = stages_for(key)
    ran = [n for n in stages if n in recs]
    if stages and not ran:
        section = key.rsplit(".", 1)[0]
        raise ConfigError(f"the {stages[0]} stage did not run, so this key changes nothing "
                          f"(set {section.split('.')[0] if stages[0] == 'lighting' else section}.enabled = true)",
                          key=key)
    lists = None
    outputs = res.scene.artefacts.outputs or {}
    if cfg.export.json_name in outputs:
        lists = json.loads(outputs[cfg.export.json_name]).get("lists", {})
    # the lighting stage's scene: its colours line up with the lighting artefact (a BSP splits later)
    return _Run(seen.get("lighting", res.scene), recs, sum(recs[n]["seconds"] for n in ran) if ran else total,
                total, lists, report_mod.build(res), final=res.scene,
                cached=list((res.cache or {}).get("from_cache", [])),
                reused=list((res.cache or {}).get("memos_reused", [])))


def _mesh(run: _Run):
    """The mesh as the export wrote it (lists.json), for previews; None without export."""
    if run.lists is None or run.report is None:
        return None
    from .outputs import html, preview

    textures = html.decoded_textures(run.lists, run.report, {})
    lm = next((t for t in textures if t["name"] == "lightmap"), None)
    lm_img = None if lm is None else next(iter(lm["images"].values()))[..., :3].astype(np.float64) / 255.0
    mesh = preview.mesh_from_lists(run.lists, run.report, lightmap=lm_img)
    return mesh if mesh is not None and len(mesh.tris) else None


def _previews(mesh, cams) -> list[np.ndarray] | None:
    """Depth-buffer previews of a written mesh from the given cameras (uint8 RGB)."""
    if mesh is None or cams is None:
        return None
    from .outputs import preview
    from .render import render

    two = mesh.two_sided[mesh.material] if len(mesh.two_sided) else None
    return [preview.shade(mesh, cam, render(cam, mesh.corners, mode="zbuffer", two_sided=two))
            for _, cam in cams]


def _image_rmse(a: list[np.ndarray] | None, b: list[np.ndarray] | None) -> float | None:
    if a is None or b is None:
        return None
    d = np.concatenate([(x.astype(np.float64) - y.astype(np.float64)).ravel() / 255.0 for x, y in zip(a, b)])
    return float(np.sqrt(np.mean(d * d))) if len(d) else None


def _colors(s: Scene) -> dict[str, np.ndarray | None]:
    res = s.artefacts.lighting
    return {
        "vertex": None if s.vertex_colors is None else np.asarray(s.vertex_colors)[:, :3],
        "face": None if s.face_colors is None else np.asarray(s.face_colors)[:, :3],
        "vertex_irradiance": None if res is None else np.asarray(res.vertex_irradiance),
        "face_irradiance": None if res is None else np.asarray(res.face_irradiance),
        "components": {} if res is None else {k: np.asarray(v) for k, v in res.vertex.items()},
        "evaluated": None if res is None else np.asarray(res.vertex_evaluated),
    }


def _err(a: np.ndarray | None, b: np.ndarray | None, mask: np.ndarray | None = None
         ) -> tuple[float | None, float | None]:
    if a is None or b is None:
        return None, None
    n = min(len(a), len(b))
    if n == 0:
        return None, None
    d = np.asarray(a[:n], np.float64) - np.asarray(b[:n], np.float64)
    if mask is not None:
        d = d[mask[:n]]
        if len(d) == 0:
            return None, None
    return float(np.sqrt(np.mean(d * d))), float(np.abs(d).max())


def compare(run: dict, ref: dict) -> dict[str, Any]:
    """Errors of one bake's outputs against the reference's (shown colours 0..1, irradiance)."""
    mask = run["evaluated"] if run["evaluated"] is not None and run["evaluated"].any() else None
    out: dict[str, Any] = {}
    out["rmse"], out["max_error"] = _err(run["vertex"], ref["vertex"], mask)
    same_faces = (run["face"] is not None and ref["face"] is not None and len(run["face"]) == len(ref["face"]))
    if same_faces:
        out["face_rmse"], out["face_max_error"] = _err(run["face"], ref["face"])
    else:
        out["face_rmse"] = out["face_max_error"] = None
    out["irradiance_rmse"], out["irradiance_max_error"] = _err(run["vertex_irradiance"],
                                                               ref["vertex_irradiance"], mask)
    comp = {}
    for k, v in run["components"].items():
        r = ref["components"].get(k)
        if r is None:
            continue
        default = 1.0 if k == "ao" else 0.0  # the value of a component that did not run
        if np.all(v == default) and np.all(r == default):
            continue
        e = _err(v, r, mask)
        if e[0] is not None:
            comp[k] = {"rmse": e[0], "max_error": e[1]}
    out["components"] = comp
    if mask is None and out["rmse"] is None and same_faces:
        out["rmse"], out["max_error"] = out["face_rmse"], out["face_max_error"]
    if not same_faces and run["face"] is not None:
        out["note"] = "triangle counts differ from the reference (subdivision): faces not compared"
    return out


def sweep(config: str | Path | Config, key: str, values: Sequence[float], reference: Any = None, *,
          scene: Scene | None = None, out: str | Path | None = None,
          progress: Callable[[str], None] | None = None, cache: Any = "auto") -> dict[str, Any]:
    """Bake once per value of ``key`` and compare each bake with a reference.

    ``reference``: ``None`` = the highest value in ``values``; a number = an extra bake at that
    value (not a row); a :class:`Scene` = a lighting bake made elsewhere. ``out`` (a path without
    suffix) writes ``out.json`` and ``out.svg``. ``cache``: ``"auto"`` = the config's stage cache
    (``StageCache.for_config``) or one in memory, a ``StageCache``, or None (no reuse). Returns the
    table (JSON-serialisable)."""
    base = _load(config)
    config_mod.get_key(base, key)  # unknown key -> ConfigError
    if not stages_for(key):
        raise ConfigError("does not change what is baked (sweep varies keys of the pipeline's stages)", key=key)
    vals = sorted(dict.fromkeys(values), key=float)
    if not vals:
        raise ConfigError("sweep needs at least one value", key=key)
    stage_cache = None
    if scene is None and cache is not None:
        from . import cache as cache_mod

        stage_cache = cache_mod.StageCache.for_config(base) if cache == "auto" else cache
        stage_cache = stage_cache or cache_mod.StageCache.in_memory()
    say = progress or (lambda _msg: None)
    # every value is checked before the first bake, and a bad one is named as the sweep's own
    cfgs = {v: _value_config(base, key, v, "--vary") for v in vals}
    ref_cfg = None
    if reference is not None and not isinstance(reference, Scene):
        ref_cfg = _value_config(base, key, reference, "--reference")
    if len(vals) > 1:  # a warm-up bake, not timed: the first bake also pays for loading libraries
        say(f"warm-up bake at {key} = {vals[0]} (not timed: it loads the libraries"
            + (" and stores the stages before the key's)" if stage_cache is not None else ")"))
        _bake(cfgs[vals[0]], scene, key, stage_cache)
    runs = {}
    for i, v in enumerate(vals, 1):  # one bake per value
        say(f"bake {i}/{len(vals)}: {key} = {v}")
        runs[v] = _bake(cfgs[v], scene, key, stage_cache)
    if stage_cache is not None:  # what a new folder's cache kept back: the sweep's bakes succeeded
        stage_cache.store.flush()
    ref_desc: dict[str, Any]
    ref_run: _Run | None = None
    if reference is None:
        ref_run = runs[vals[-1]]
        ref_desc = {"kind": "highest value", "value": vals[-1]}
    elif isinstance(reference, Scene):
        ref_desc = {"kind": "scene"}
    else:
        say(f"reference bake at {key} = {reference}")
        ref_run = _bake(ref_cfg, scene, key, stage_cache)
        ref_desc = {"kind": "reference run", "value": reference, "seconds": round(ref_run.seconds, 6),
                    "total_seconds": round(ref_run.total, 6)}
    ref_colors = _colors(reference if isinstance(reference, Scene) else ref_run.scene)
    ref_mesh = _mesh(ref_run) if ref_run is not None else None
    cams = None
    if ref_mesh is not None:
        from .outputs.preview import cameras

        cams = cameras(ref_mesh.verts, *PREVIEW_SIZE)
    say("rendering previews and comparing with the reference")
    ref_images = _previews(ref_mesh, cams)
    rows = []
    for v in vals:
        run = runs[v]
        row = _row(v, run, key)
        if key.startswith("lighting."):  # the same vertices in every run: compare them
            row.update(compare(_colors(run.scene), ref_colors))
        row["image_rmse"] = _image_rmse(_previews(_mesh(run), cams), ref_images)
        row["reference"] = reference is None and v == vals[-1]
        err_key = error_of(key)[0]
        row["error"] = row.get(err_key, row["accuracy"].get(err_key))
        rows.append(row)
    err_key, err_label = error_of(key)
    table = {"key": key, "values": list(vals), "stages": list(stages_for(key)), "reference": ref_desc,
             "rows": rows, "error_metric": err_label, "error_key": err_key, "slope": _slope(rows),
             "cache": None if stage_cache is None else {
                 "where": stage_cache.store.describe(),
                 "note": "the stages before the key's are baked once and loaded from the stage cache after that "
                         "(cached_stages per row); total_seconds counts loading them, not computing them. The "
                         "key's own stages reuse nothing (seconds is their full cost); a stage after them may "
                         "reuse work its inputs did not change (reused_in_stages per row: a BSP tree when the "
                         "new colours change no merge), and total_seconds is then that cheaper bake"},
             "metric": "error: " + err_label + "; image_rmse: depth-buffer previews of the written lists "
                       f"({PREVIEW_SIZE[0]}x{PREVIEW_SIZE[1]}, 3 views) against the reference's; rmse / max "
                       "error of shown colours (0..1, RGB) over traced vertices (or triangles); irradiance is linear"}
    if out is not None:
        write(table, out)
    return table


def _row(v: Any, run: _Run, key: str) -> dict[str, Any]:
    effects = [e for r in run.records.values() for e in r.get("effects", []) if e.get("ran")]
    accuracy: dict[str, Any] = {}
    for name in stages_for(key) or tuple(run.records):
        for k, x in run.records.get(name, {}).get("accuracy", {}).items():
            if isinstance(x, (int, float)) and not isinstance(x, bool):
                accuracy[k] = x
    last = run.final if run.final is not None else run.scene
    info = last.artefacts.list_info or {}
    costumes = last.artefacts.costumes or []
    return {
        "value": v,
        "seconds": round(run.seconds, 6),
        "total_seconds": round(run.total, 6),
        "stage_seconds": {n: r["seconds"] for n, r in run.records.items()},
        "triangles": int(last.n_triangles),
        "bytes": int(sum(i["project_json_bytes"] for i in info.values())) if info else None,
        "asset_bytes": int(sum(len(c[1]) for c in costumes)) if costumes else 0,
        "accuracy": accuracy,
        "rays": int(sum(e.get("rays", 0) or 0 for e in effects)),
        "reported_error": {e["name"]: e["error"] for e in effects if "error" in e},
        "effect_seconds": {e["name"]: e.get("seconds") for e in effects},
        "cached_stages": list(run.cached or []),
        "reused_in_stages": list(run.reused or []),
    }


def summary_lines(table: dict) -> list[str]:
    """The sweep as a terminal table."""
    lines = [f"sweep {table['key']}: reference = {reference_text(table['reference'])}",
             f"  error = {table['error_metric']}",
             f"  {'value':>10} {'stage s':>9} {'total s':>9} {'error':>11} {'image err':>10} {'bytes':>10} "
             f"{'triangles':>10}"]

    def num(v, fmt):
        return format(v, fmt) if isinstance(v, (int, float)) else "-"
    for r in table["rows"]:
        lines.append(f"  {r['value']:>10} {num(r['seconds'], '9.3f')} {num(r['total_seconds'], '9.3f')} "
                     f"{num(r.get('error'), '11.5g')} {num(r.get('image_rmse'), '10.5f')} "
                     f"{num(r.get('bytes'), '10d')} {num(r.get('triangles'), '10d')}")
    if table.get("slope") is not None:
        lines.append(f"  log-log slope of the colour error against the value: {table['slope']:.2f}")
    return lines


def reference_text(ref: dict) -> str:
    """The reference of a sweep in words."""
    kind = ref.get("kind")
    if kind == "highest value":
        return f"the bake at the highest value ({ref.get('value')})"
    if kind == "reference run":
        return f"an extra bake at {ref.get('value')} (not a row)"
    if kind == "scene":
        return "a lighting bake given by the caller"
    return str(kind)


def _slope(rows: list[dict]) -> float | None:
    """Least-squares slope of log(rmse) against log(value), reference row excluded."""
    pts = [(float(r["value"]), r["rmse"]) for r in rows
           if not r.get("reference") and r.get("rmse") and float(r["value"]) > 0]
    if len(pts) < 2:
        return None
    x = np.log([p[0] for p in pts])
    y = np.log([p[1] for p in pts])
    return float(np.polyfit(x, y, 1)[0])


def write(table: dict, out: str | Path) -> tuple[Path, Path]:
    """Write ``out.json`` and ``out.svg`` (the plot); returns both paths."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    jp = out.with_name(out.name + ".json")
    pp = out.with_name(out.name + ".svg")
    write_atomic(jp, (json.dumps(table, indent=2, default=_jsonable) + "\n").encode("utf-8"))
    write_atomic(pp, plot(table).encode("utf-8"))
    return jp, pp


def _jsonable(o: Any) -> Any:
    if isinstance(o, (np.integer,)):
        return int(o)
    if isinstance(o, (np.floating,)):
        return float(o)
    if isinstance(o, np.ndarray):
        return o.tolist()
    return str(o)


_COMPONENT_OF = {"ao": "ao", "sky": "sky", "bounces": "indirect"}


def _component(effect: str) -> str:
    return "direct" if effect.startswith("light[") else _COMPONENT_OF.get(effect, effect)


def pareto_front(seconds: np.ndarray, error: np.ndarray) -> np.ndarray:
    """Indices of the bakes no other bake beats on both time and error (the fastest bake for
    each error reached), in order of seconds. Stage times are noisy, so joining the points in
    the order of the swept value zig-zags back and forth along the seconds axis; the front is
    the trade-off a reader looks for, and it runs left to right."""
    seconds = np.asarray(seconds, float)
    error = np.asarray(error, float)
    order = np.lexsort((error, seconds))  # by seconds, then error
    e = error[order]
    best_before = np.minimum.accumulate(np.concatenate([[np.inf], e[:-1]]))
    return order[e < best_before].astype(np.int64)


def plot(table: dict, path: str | Path | io.BytesIO | None = None) -> str:
    """Three panels, as SVG (bake/svgplot.py): the key's error against seconds, list bytes
    against seconds (each point labelled with its value; against seconds only the Pareto front of
    error and seconds is joined, in order of seconds), and the errors against the value (for
    lighting keys each effect's actual error next to the stage's own estimate, in the same
    units). Returns the SVG text, and writes it to ``path`` when given."""
    from .svgplot import COLORS, Figure

    rows = table["rows"]
    key = table["key"]
    secs = np.array([float(r["seconds"]) for r in rows])
    x = np.array([float(r["value"]) for r in rows])
    fig = Figure(3, title=f"bake sweep {key}")
    ax1, ax2, ax3 = fig.panels

    def series(values, xs=x):
        y = np.array([v if isinstance(v, (int, float)) and v is not None else np.nan for v in values], float)
        return np.isfinite(y) & (y > 0) & np.isfinite(xs), y

    def labelled(ax, xs, ys, ok, marker, label):
        """Points labelled with their values; no line (against seconds the value order is not
        the order along the axis). Returns the colour."""
        notes = [f"{r['value']:g}" if isinstance(r["value"], (int, float)) else str(r["value"])
                 for r, k in zip(rows, ok) if k]
        return ax.points(xs[ok], ys[ok], marker=marker, label=label, notes=notes)

    def front(ax, xs, ys, ok, color, label):
        f = pareto_front(xs[ok], ys[ok])
        if len(f) > 1:
            ax.line(xs[ok][f], ys[ok][f], style="-", color=color, label=f"{label}: fastest for its error")

    err_label = table.get("error_key", "error")
    ok, y = series([r.get("error") for r in rows], secs)
    if ok.any():
        front(ax1, secs, y, ok, labelled(ax1, secs, y, ok, "o", err_label), err_label)
        if (y[ok] > 0).all() and y[ok].max() > 20 * y[ok].min():
            ax1.ylog = True
    ok2, y2 = series([r.get("image_rmse") for r in rows], secs)
    if ok2.any() and table.get("error_key") != "image_rmse":
        front(ax1, secs, y2, ok2, labelled(ax1, secs, y2, ok2, "s", "image_rmse"), "image_rmse")
    ax1.xlabel = f"seconds ({'+'.join(table.get('stages') or ['stage'])})"
    ax1.ylabel = "error"
    ax1.title = str(table.get("error_metric", "error"))[:60]
    ok, y = series([r.get("bytes") for r in rows], secs)
    if ok.any():
        labelled(ax2, secs, y, ok, "o", "list bytes in project.json")
    ax2.xlabel = "seconds"
    ax2.ylabel = "bytes"
    ax2.title = "what it costs in project.json"
    if key.startswith("lighting."):
        ax3.xlog = ax3.ylog = True
        for name, label, marker, style in (("rmse", "RMSE vertex colour", "o", "-"),
                                           ("max_error", "max error", "s", "--"),
                                           ("face_rmse", "RMSE triangle colour", "^", "-")):
            ok, y = series([r.get(name) for r in rows])
            if ok.any():
                ax3.line(x[ok], y[ok], style=style, marker=marker, label=label)
        effects = sorted({e for r in rows for e in r["reported_error"]})
        for k, eff in enumerate(effects):
            comp = _component(eff)
            color = COLORS[(k + 3) % len(COLORS)]
            ok, y = series([r.get("components", {}).get(comp, {}).get("rmse") for r in rows])
            if ok.any():
                ax3.line(x[ok], y[ok], style="-", marker="o", color=color, label=f"{comp}: actual RMSE")
            ok, y = series([r["reported_error"].get(eff) for r in rows])
            if ok.any():
                ax3.line(x[ok], y[ok], style=":", marker="x", color=color, label=f"{eff}: stage's estimate")
        ax3.title = "per effect, against " + str(table["reference"].get("kind"))
    else:
        for name, marker, style in (("error", "o", "-"), ("image_rmse", "s", "--")):
            ok, y = series([r.get(name) for r in rows])
            if ok.any():
                ax3.line(x[ok], y[ok], style=style, marker=marker, label=name)
        if (x > 0).all() and x.max() > 20 * x.min():
            ax3.xlog = True
        ax3.title = "errors against the value"
    ax3.xlabel = key
    text = fig.svg()
    if isinstance(path, io.BytesIO):
        path.write(text.encode("utf-8"))
    elif path is not None:
        write_atomic(Path(path), text.encode("utf-8"))
    return text
