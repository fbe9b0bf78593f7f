"""What the green flag's BVH view costs (``export.green_flag = "bvh"``): blocks per frame in
scratch-vm and seconds in TurboWarp, per model and cell size, beside the raster green flag of the
same bake.

    .venv/bin/python benchmarks/bench_bvh_view.py [--cells 8,4] [--repeat 5]

Models: the corpus bunny simplified to 2,000 triangles (meshopt alone), lit by a sun, BSP-sorted
(3,000-odd triangles after the splits), quantised BVH; the Cornell box lit by a point light inside,
wide4 BVH (both as tests/player/test_turbowarp_bvh_view.py bakes them). For each:

* ``blocks_per_frame``: blocks scratch-vm 5.0.300 executes from the green flag until every script
  stopped (vm/run.js: every block run, reporters and variable reads included, a custom block call
  as two), and per cell (``blocks_per_cell``: the frame over the cells; nearly all of it is ``bvh
  ray``); the same bake with the raster green flag (``render``) beside it; ``bvh ray`` run alone
  for 300 of the view's cells (seeded), its blocks on the rays that hit and on those that miss
  (``bvh_ray_blocks``), and ``camera ray``'s (``blocks_camera_ray``);
* TurboWarp seconds (vm/player.js, headless Chromium, compiled and interpreted): ``first``, green
  flag to every script stopped on a freshly loaded page (compiling the scripts and a cold JIT
  included), and ``steady``, the minimum over the later green flags of the time inside the VM's
  steps (``--repeat`` runs, all pages open at once and run in rounds);
* the agreement of TurboWarp's stage with the Python view (``bake.outputs.bvh_view.view_agreement``).

Writes ``benchmarks/results/bvh_view.json`` and prints a markdown table. Times depend on the load
of the machine (recorded): quote them as rough figures.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "vm"))

from bake import config, pipeline  # noqa: E402
from bake.outputs import bvh_view as BV  # noqa: E402
from bake.scratch import backdrop, sb3  # noqa: E402
from bake.scratch.project import auto_camera  # noqa: E402

import turbowarp  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "bvh_view.json"

BUNNY = {"transform": {"center": "base", "fit": 100},
         "mesh": {"simplify": {"enabled": True, "target_triangles": 2000, "method": "meshopt", "fit_iterations": 0,
                               "refine_rounds": 0, "peak_rounds": 0}},
         "lighting": {"enabled": True, "target": "triangle", "ambient": [0.2, 0.2, 0.25],
                      "lights": [{"kind": "sun", "direction": [0.5, -1, -0.4]}]},
         "bsp": {"enabled": True}, "bvh": {"enabled": True}}
CORNELL = {"lighting": {"enabled": True, "target": "triangle", "ambient": [0.1, 0.1, 0.1],
                        "lights": [{"kind": "point", "position": [278.0, 450.0, -280.0], "radius": 30.0,
                                    "intensity": 2.0e5}]},
           "bvh": {"enabled": True, "layout": "wide4"}}
MODELS = {"bunny": (("stanford_bunny_res1_obj", "stanford-bunny.obj"), BUNNY),
          "cornell": (("cornell_box_tinyobj", "cornell_box.obj"), CORNELL)}


def bake(model: str, green_flag: str, cell: int, out: Path) -> dict:
    path, sections = MODELS[model]
    data = {"input": {"path": str(CORPUS.joinpath(*path))}, **sections,
            "export": {"green_flag": green_flag, "bvh_cell": cell}}
    res = pipeline.run(config.load(data=data))
    files = res.scene.artefacts.outputs
    name = next(n for n in files if n.endswith(".sb3"))
    out.write_bytes(files[name])
    lists = json.loads(files["lists.json"])["lists"]
    row = {"model": model, "green_flag": green_flag, "what": f"bvh, cell {cell}" if green_flag == "bvh" else
           "raster (render)", "cell": cell if green_flag == "bvh" else None, "triangles": res.scene.n_triangles,
           "file": str(out), "rays": None, "blocks_per_cell": None, "cells_within_1": None,
           "blocks_camera_ray": None,
           "bvh_ray_blocks": {"sampled": 0, "hit_mean": None, "miss_mean": None, "mean": None}}
    if green_flag == "bvh":
        art = res.scene.artefacts.bvh
        view = BV.bvh_view(lists, auto_camera(lists["verts"]), cell, art.encoded.layout, art.encoded.bits,
                           names=art.lists)
        project, assets = sb3.load_project(out)
        row.update(view.to_json())
        row["layout"] = art.encoded.layout
        row["_view"], row["_bg"] = view, backdrop.from_project(project, assets)
    return row


SAMPLE_RAYS = 300  # cells whose ray is run alone through `bvh ray`: its blocks on hits and misses


def _ray_runs(r: dict) -> list[dict]:
    """``camera ray`` once, then ``bvh ray`` alone for a seeded sample of the view's cells."""
    view = r["_view"]
    cam = view.cam
    gx, gy = np.meshgrid(view.sx, view.sy)
    pick = np.random.default_rng(5).choice(gx.size, min(SAMPLE_RAYS, gx.size), replace=False)
    r["_pick"] = pick
    d = BV.view_rays(cam, gx.ravel()[pick], gy.ravel()[pick])
    runs = [{"call": {"target": "Mesh", "proccode": "camera ray %s %s", "args": ["0", "0"]},
             "read": {"lists": [], "variables": []}}]
    for dx, dy, dz in d:
        args = [repr(float(x)) for x in (cam.x, cam.y, cam.z, dx, dy, dz)]
        runs.append({"call": {"target": "Mesh", "proccode": "bvh ray %s %s %s %s %s %s", "args": args},
                     "read": {"lists": [], "variables": ["hit tri"]}})
    return runs


def vm_blocks(rows: list[dict]) -> None:
    jobs = [{"load": r["file"], "runs": [{"greenFlag": True, "read": {"lists": [], "variables": []}}]
             + (_ray_runs(r) if "_view" in r else [])} for r in rows]
    p = subprocess.run(["node", str(REPO / "vm" / "run.js"), "--plan", "-"], input=json.dumps({"jobs": jobs}),
                       capture_output=True, text=True, timeout=7200)
    out = json.loads(p.stdout)
    for r, job in zip(rows, out["jobs"]):
        if job.get("error"):
            raise SystemExit(f"vm/run.js failed: {job['error']}")
        run = job["runs"][0]
        r["blocks_per_frame"], r["vm_ms"], r["vm_done"] = run["blocks"], run["ms"], run["done"]
        if r["green_flag"] == "bvh":
            r["blocks_per_cell"] = run["blocks"] / r["rays"]
            r["blocks_camera_ray"] = job["runs"][1]["blocks"]
            rays = job["runs"][2:]
            blocks = np.array([x["blocks"] for x in rays], np.float64)
            hit = np.array([float(x["variables"]["hit tri"]) > 0 for x in rays])
            assert np.array_equal(hit, r["_view"].tri.ravel()[r["_pick"]] > 0)  # the same hits as the view
            r["bvh_ray_blocks"] = {"sampled": len(rays), "hit_mean": float(blocks[hit].mean()) if hit.any() else None,
                                   "miss_mean": float(blocks[~hit].mean()) if (~hit).any() else None,
                                   "mean": float(blocks.mean())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cells", default="8,4")
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--models", default="bunny,cornell")
    args = ap.parse_args()
    why = turbowarp.unavailable()
    if why:
        raise SystemExit(why)
    cells = [int(c) for c in args.cells.split(",")]
    load_before = os.getloadavg()
    rows: list[dict] = []
    with tempfile.TemporaryDirectory(prefix="bench-bvh-view-") as tmp:
        for model in args.models.split(","):
            rows.append(bake(model, "raster", cells[0], Path(tmp) / f"{model}-raster.sb3"))
            for cell in cells:
                rows.append(bake(model, "bvh", cell, Path(tmp) / f"{model}-bvh-{cell}.sb3"))
        t = time.time()
        vm_blocks(rows)
        vm_seconds = time.time() - t
        ids = [(f"{r['model']}-{r['green_flag']}-{r['cell']}", r["file"]) for r in rows]
        steady = turbowarp.run(ids, modes=("compiled", "interpreted"), repeat=args.repeat, interleave=True,
                               timeout_ms=600_000, timeout=7200)
        for (pid, _), r in zip(ids, rows):
            for mode in ("compiled", "interpreted"):
                res = steady.get(pid, mode)
                later = res.step_seconds[1:] or res.step_seconds
                r[mode] = {"first": res.seconds[0], "seconds": res.seconds, "step_seconds": res.step_seconds,
                           "steady": float(min(later)), "problems": res.problems()}
                if "_view" in r:
                    a = BV.view_agreement(res.image, r["_view"], r["_bg"])
                    r[mode]["agreement"] = a
                    r["cells_within_1"] = min(r["cells_within_1"] if r["cells_within_1"] is not None else 1.0,
                                              a["within_1"])
    for r in rows:
        for k in ("_view", "_bg", "_pick", "file"):
            r.pop(k, None)
    out = {"rows": rows, "repeat": args.repeat, "load_before": load_before, "load_after": os.getloadavg(),
           "vm_seconds": vm_seconds, "versions": steady.versions}
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(out, indent=1) + "\n")
    print("| model (triangles) | green flag | rays | blocks per frame (scratch-vm) | per cell | TurboWarp compiled: "
          "first / steady s | interpreted: first / steady s | hit cells within 1 level |")
    print("|:---|:---|---:|---:|---:|---:|---:|---:|")
    for r in rows:
        per = f"{r['blocks_per_cell']:,.0f}" if r["blocks_per_cell"] is not None else ""
        agree = f"{r['cells_within_1']:.2%}" if r["cells_within_1"] is not None else ""
        print(f"| {r['model']} ({r['triangles']:,}) | {r['what']} | {r['rays'] or ''} | {r['blocks_per_frame']:,} "
              f"| {per} | "
              f"{r['compiled']['first']:.3f} / {r['compiled']['steady']:.3f} | "
              f"{r['interpreted']['first']:.3f} / {r['interpreted']['steady']:.3f} | {agree} |")
    print(f"(load {load_before[0]:.2f} before, {out['load_after'][0]:.2f} after; scratch-vm {vm_seconds:.0f} s)")


if __name__ == "__main__":
    main()
