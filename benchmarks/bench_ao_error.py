"""How honest the AO error figure is: the stage's ``error`` against the actual RMSE.

    .venv/bin/python benchmarks/bench_ao_error.py [--reference 4096] [--samples 16 64 256 1024] [--only bunny]

For the corpus bunny, house and duck (imported and cleaned by the pipeline, ``target = "vertex"``,
``ao.distance = 0.25``), AO is baked twice at ``--reference`` rays per point with seeds 101 and
202; their mean is the reference, and a quarter of their mean squared difference is its own
variance, subtracted from the measured MSE. Then at each ``--samples`` (seed 0) the stage's AO
effect reports ``error`` (calibrated, ``bake/lighting/ao.py``) and ``error_bound``; the actual
RMSE is over the same vertices. Ratios above 1 are conservative, below 1 optimistic.

Writes ``benchmarks/results/ao_error.json`` (docs/lighting.md's table is generated from it).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bake import config as config_mod  # noqa: E402
from bake.config import LightingConfig  # noqa: E402
from bake.lighting.ao import AO_ERROR_CALIBRATION  # noqa: E402
from bake.lighting.stage import stage  # noqa: E402
from bake.pipeline import run  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "ao_error.json"
MODELS = [("bunny", "stanford_bunny_res1_obj/stanford-bunny.obj", "y"),
          ("house", "house_max2obj_walls/regr01.obj", "z"),
          ("duck", "duck_glb/Duck.glb", "y")]


def load(rel: str, up: str):
    cfg = config_mod.load(None, [f'transform.up="{up}"'])
    cfg.input.path = str(CORPUS / rel)
    return run(cfg, until="clean").scene


def bake_ao(scene, samples: int, seed: int):
    c = LightingConfig(enabled=True, target="vertex", seed=seed)
    c.ao.enabled = True
    c.ao.samples = samples
    c.ao.distance = 0.25
    out, rec = stage(scene, c)
    effect = next(e for e in rec.effects if e["name"] == "ao")
    return out.artefacts.lighting, effect


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--reference", type=int, default=4096)
    ap.add_argument("--samples", type=int, nargs="*", default=[16, 64, 256, 1024])
    ap.add_argument("--only", nargs="*")
    a = ap.parse_args()
    out = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                       "loadavg_start": os.getloadavg()},
           "args": vars(a), "calibration": AO_ERROR_CALIBRATION, "models": {}, "table": []}
    t_all = time.perf_counter()
    for name, rel, up in MODELS:
        if a.only and name not in a.only:
            continue
        sc = load(rel, up)
        t = time.perf_counter()
        r1, _ = bake_ao(sc, a.reference, 101)
        r2, _ = bake_ao(sc, a.reference, 202)
        ev = r1.vertex_evaluated
        ref = (r1.vertex["ao"][ev] + r2.vertex["ao"][ev]) / 2
        ref_var = float(np.mean((r1.vertex["ao"][ev] - r2.vertex["ao"][ev]) ** 2) / 4)
        rows = []
        for n in a.samples:
            res, eff = bake_ao(sc, n, 0)
            actual = float(np.sqrt(max(np.mean((res.vertex["ao"][ev] - ref) ** 2) - ref_var, 0.0)))
            rows.append({"samples": eff["samples"], "actual_rmse": actual, "error": eff["error"],
                         "error_bound": eff["error_bound"], "uncalibrated": eff["error"] / AO_ERROR_CALIBRATION,
                         "error_ratio": eff["error"] / actual, "bound_ratio": eff["error_bound"] / actual,
                         "uncalibrated_ratio": eff["error"] / AO_ERROR_CALIBRATION / actual})
            print(f"[{name}] {n:5d} rays: actual {actual:.5f}  error {eff['error']:.5f} "
                  f"({rows[-1]['error_ratio']:.2f}x, uncalibrated {rows[-1]['uncalibrated_ratio']:.2f}x)  "
                  f"bound {eff['error_bound']:.5f} ({rows[-1]['bound_ratio']:.2f}x)", flush=True)
        out["models"][name] = {"vertices": int(ev.sum()), "reference_rays": a.reference,
                               "reference_rmse": float(np.sqrt(ref_var)), "seconds": time.perf_counter() - t,
                               "rows": rows}
        out["table"].extend({"model": name, **r} for r in rows)
        OUT.parent.mkdir(parents=True, exist_ok=True)
        OUT.write_text(json.dumps(out, indent=1))
    out["machine"]["loadavg_end"] = os.getloadavg()
    out["seconds"] = time.perf_counter() - t_all
    OUT.write_text(json.dumps(out, indent=1))


if __name__ == "__main__":
    main()
