"""Accuracy against time: bake at several values of one numeric config key and compare.

``bake sweep CONFIG --vary lighting.ao.samples=16,64,256,1024`` runs the pipeline (up to and
including the lighting stage) once per value and writes a table, as JSON and as a PNG plot:
seconds, rays, RMSE and max error of the colours Scratch will show (vertex and triangle colours,
0..1) and of the linear irradiance, each against the highest value (or an explicit reference
run), next to the error the stage itself estimated from its samples.

API::

    table = sweep("bake.toml", "lighting.ao.samples", [16, 64, 256], reference=4096,
                  out="sweep_ao")           # writes sweep_ao.json and sweep_ao.png
    key, values = parse_vary("lighting.ao.samples=16,64,256")

``scene=`` bakes a given :class:`~bake.scene.Scene` with the lighting stage alone (no import),
for tests and for sweeping before a model is on disk.
"""

from __future__ import annotations

import copy
import io
import json
import math
import time
from pathlib import Path
from typing import Any, Sequence

import numpy as np

from . import config as config_mod
from .export.write import write_atomic
from .config import Config
from .errors import ConfigError
from .scene import Scene


def parse_vary(text: str) -> tuple[str, list[float]]:
    """``"section.key=1,2,4"`` -> ``("section.key", [1, 2, 4])`` (numbers as ints when whole)."""
    if "=" not in text:
        raise ConfigError(f"--vary expects section.key=v1,v2,..., got {text!r}")
    key, vals = text.split("=", 1)
    key = key.strip()
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
            raise ConfigError(f"--vary value {v!r} is not a number", key=key) from None
        if not math.isfinite(f):
            raise ConfigError(f"--vary value {v!r} is not finite", key=key)
        out.append(int(f) if f.is_integer() and "." not in v and "e" not in v.lower() else f)
    if not out:
        raise ConfigError("--vary needs at least one value", key=key)
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


def _bake(cfg: Config, scene: Scene | None) -> tuple[Scene, dict, float]:
    """Run up to the lighting stage. Returns (scene, lighting record as JSON, total seconds)."""
    t0 = time.perf_counter()
    if scene is not None:
        from .lighting.stage import stage

        out, rec = stage(scene, cfg.lighting)
        return out, rec.to_json(), time.perf_counter() - t0
    from .pipeline import run

    res = run(cfg, until="lighting")
    recs = [r for r in res.records if r.name == "lighting"]
    if not recs:
        raise ConfigError("the lighting stage did not run (set lighting.enabled = true)",
                          key="lighting.enabled")
    return res.scene, recs[0].to_json(), time.perf_counter() - t0


def _colors(s: Scene) -> dict[str, np.ndarray | None]:
    res = s.artefacts.get("lighting")
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
          scene: Scene | None = None, out: str | Path | None = None) -> dict[str, Any]:
    """Bake once per value of ``key`` and compare each bake with a reference.

    ``reference``: ``None`` = the highest value in ``values``; a number = an extra bake at that
    value (not a row); a :class:`Scene` = a bake made elsewhere. ``out`` (a path without suffix)
    writes ``out.json`` and ``out.png``. Returns the table (JSON-serialisable)."""
    base = _load(config)
    config_mod.get_key(base, key)  # unknown key -> ConfigError
    vals = sorted(dict.fromkeys(values), key=float)
    if not vals:
        raise ConfigError("sweep needs at least one value", key=key)
    rows = []
    runs = {}
    for v in vals:  # one bake per value
        c = _with_value(base, key, v)
        s, rec, total = _bake(c, scene)
        runs[v] = _colors(s)
        rows.append(_row(v, rec, total))
    ref_desc: dict[str, Any]
    if reference is None:
        ref_v = vals[-1]
        ref = runs[ref_v]
        ref_desc = {"kind": "highest value", "value": ref_v}
    elif isinstance(reference, Scene):
        ref = _colors(reference)
        ref_desc = {"kind": "scene"}
    else:
        c = _with_value(base, key, reference)
        s, rec, total = _bake(c, scene)
        ref = _colors(s)
        ref_desc = {"kind": "reference run", "value": reference, "seconds": rec["seconds"],
                    "total_seconds": round(total, 6)}
    for row, v in zip(rows, vals):
        row.update(compare(runs[v], ref))
        row["reference"] = reference is None and v == vals[-1]
    table = {"key": key, "values": list(vals), "reference": ref_desc, "rows": rows,
             "slope": _slope(rows), "metric": "RMSE / max error of shown colours (0..1, RGB) over "
                                               "traced vertices (or triangles); irradiance is linear"}
    if out is not None:
        write(table, out)
    return table


def _row(v: Any, rec: dict, total: float) -> dict[str, Any]:
    effects = [e for e in rec.get("effects", []) if e.get("ran")]
    return {
        "value": v,
        "seconds": rec.get("seconds"),
        "total_seconds": round(total, 6),
        "rays": int(sum(e.get("rays", 0) or 0 for e in effects)),
        "reported_error": {e["name"]: e["error"] for e in effects if "error" in e},
        "effect_seconds": {e["name"]: e.get("seconds") for e in effects},
    }


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
    """Write ``out.json`` and ``out.png``; returns both paths."""
    out = Path(out)
    out.parent.mkdir(parents=True, exist_ok=True)
    jp = out.with_name(out.name + ".json")
    pp = out.with_name(out.name + ".png")
    write_atomic(jp, (json.dumps(table, indent=2, default=_jsonable) + "\n").encode("utf-8"))
    buf = io.BytesIO()
    plot(table, buf)
    write_atomic(pp, buf.getvalue())
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


def plot(table: dict, path: str | Path | io.BytesIO) -> str | Path | io.BytesIO:
    """Three panels: shown-colour error, each component's error next to the stage's own estimate
    (same units), and seconds."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    rows = [r for r in table["rows"] if not r.get("reference")]
    x = np.array([float(r["value"]) for r in rows])
    fig, (ax1, ax2, ax3) = plt.subplots(1, 3, figsize=(14, 4))

    def series(values):
        y = np.array([v if v is not None else np.nan for v in values], dtype=float)
        return np.isfinite(y) & (y > 0) & (x > 0), y

    for name, label, style in (("rmse", "RMSE vertex colour", "o-"), ("max_error", "max error", "s--"),
                               ("face_rmse", "RMSE triangle colour", "^-")):
        ok, y = series([r.get(name) for r in rows])
        if ok.any():
            ax1.loglog(x[ok], y[ok], style, label=label)
    ok, y = series([r.get("rmse") for r in rows])
    if ok.any():
        i = int(np.flatnonzero(ok)[0])
        ax1.loglog(x, y[i] * (x / x[i]) ** -0.5, color="grey", lw=0.8, label="slope -1/2")
    ax1.set_title("shown colours (0..1) vs " + str(table["reference"].get("kind")), fontsize=9)
    effects = sorted({e for r in rows for e in r["reported_error"]})
    for k, eff in enumerate(effects):
        comp = _component(eff)
        col = f"C{k}"
        ok, y = series([r.get("components", {}).get(comp, {}).get("rmse") for r in rows])
        if ok.any():
            ax2.loglog(x[ok], y[ok], "o-", color=col, label=f"{comp}: actual RMSE")
        ok, y = series([r["reported_error"].get(eff) for r in rows])
        if ok.any():
            ax2.loglog(x[ok], y[ok], "x:", color=col, label=f"{eff}: stage's estimate")
    ax2.set_title("per effect (irradiance / AO units)", fontsize=9)
    xs = np.array([float(r["value"]) for r in table["rows"]])
    ax3.plot(xs, [r["seconds"] for r in table["rows"]], "o-", label="lighting stage")
    ax3.plot(xs, [r["total_seconds"] for r in table["rows"]], "s--", label="total")
    if (xs > 0).all():
        ax3.set_xscale("log")
    ax3.set_ylabel("seconds")
    for ax in (ax1, ax2, ax3):
        ax.set_xlabel(table["key"])
        ax.grid(True, which="both", alpha=0.3)
        if ax.get_legend_handles_labels()[0]:
            ax.legend(fontsize=7)
    ax1.set_ylabel("error")
    fig.tight_layout()
    fig.savefig(path, dpi=110, format="png", metadata={"Software": None})
    plt.close(fig)
    return path
