"""BSP benchmark: today's builder against the base commit's, side by side in one run.

    .venv/bin/python benchmarks/bench_bsp.py            # everything (about half an hour on 2 busy cores)
    .venv/bin/python benchmarks/bench_bsp.py --quick    # the suite table only

The docs tables (docs/formats-bsp.md) are rendered from the JSON by tools/doc_tables.py.

Writes benchmarks/results/bsp.json. "Before" is the builder of BASE_COMMIT (the commit this work
started from), extracted with ``git archive`` into a temporary folder and run in its own process;
"after" is this checkout's, run the same way, one model after the other, so both see the same
machine load. Every timed build is preceded by a fixed calibration workload (numpy sort +
matmul) timed the same way, so times can also be compared as ratios. The new builder builds on
the grid a real bake writes (``export.precision = 5``); the old one had no grid.

Also: what each idea of the new builder is worth on its own (each switched off or changed alone,
three seeds), inflation and time against the number of candidates, the proof of order on every
model (painter's order in BSP order against a z-buffer, inside and outside), and the BSP walk's
blocks per frame in the real Scratch VM (vm/run.js) for both builders, from the reader sprite's
starting eye, next to the estimate the bake reports (bake/bsp/cost.py).
"""

from __future__ import annotations

import argparse
import io
import json
import math
import os
import platform
import shutil
import subprocess
import sys
import tarfile
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests"))
sys.path.insert(0, str(REPO / "tests" / "bsp"))

OUT = REPO / "benchmarks" / "results" / "bsp.json"
BASE_COMMIT = "6f0151f"  # the builder before issue 20
GOAL_SET = ("suzanne", "teapot", "spot", "duck", "house", "bunny")
SUITE_ORDER = ("suzanne", "teapot", "spot", "duck", "house", "capsule", "cornell", "bunny", "bunny_20k")
GOALS = {"suzanne": 0.70, "house": 0.60, "bunny": 0.60}

# One build in a fresh process: load the model (tests/bsp/meshes.py of this checkout), build with
# the bake package on PYTHONPATH, print a JSON line.
WORKER = r'''
import json, sys, time
sys.path[:0] = [sys.argv[1] + "/tests", sys.argv[1] + "/tests/bsp", sys.argv[1] + "/benchmarks"]
import numpy as np
from bake import config
from bake.bsp.stage import stage
from meshes import load_scene
name, grid, opts = sys.argv[2], int(sys.argv[3]), json.loads(sys.argv[4])
if name == "bunny_20k":
    from bench_bsp import simplified_bunny
    scene = simplified_bunny()
else:
    scene = load_scene(name)
if grid:
    from bake.scratch.numbers import position_decimals
    scene = scene.replace(position_decimals=position_decimals(scene.scale(), grid))
cfg = config.load(None, ["bsp.enabled=true"]).bsp
for k, v in opts.items():
    object.__setattr__(cfg, k, v)
rng = np.random.default_rng(0)
a, m = rng.random(2_000_000), rng.random((300, 300))
t = time.perf_counter()
for _ in range(3):
    np.sort(a); m @ m @ m
cal = time.perf_counter() - t
t, c0 = time.perf_counter(), time.process_time()
new, rec = stage(scene, cfg)
sec, cpu = time.perf_counter() - t, time.process_time() - c0
d = rec.details
keep = ("splits", "kept_whole", "merged_triangles", "tree_depth", "record_depth", "records", "planes",
        "lists", "bytes_per_triangle", "walk", "collapsed_input_triangles", "tolerance", "crossing")
print(json.dumps({"triangles_in": scene.n_triangles, "triangles_out": new.n_triangles, "seconds": sec,
                  "cpu_seconds": cpu,
                  "calibration_seconds": cal, "details": {k: d[k] for k in keep if k in d}}))
'''


def simplified_bunny(target: int = 20000):
    """A 20k-triangle organic model: the bunny decimated with fast-simplification (deterministic)."""
    import fast_simplification

    from bake.scene import make_scene
    from meshes import load_scene

    b = load_scene("bunny")
    used = np.unique(b.triangles)
    remap = np.full(b.n_vertices, -1)
    remap[used] = np.arange(len(used))
    v, f = fast_simplification.simplify(b.positions[used].astype(np.float32), remap[b.triangles].astype(np.int32),
                                        target_reduction=1 - target / b.n_triangles)
    return make_scene(np.asarray(v, np.float64), np.asarray(f, np.int64))


def base_checkout(tmp: Path) -> Path | None:
    """The base commit's ``bake`` package in ``tmp`` (git archive), or None without git/commit."""
    try:
        data = subprocess.run(["git", "-C", str(REPO), "archive", BASE_COMMIT, "bake"], capture_output=True,
                              check=True, timeout=120).stdout
    except (OSError, subprocess.SubprocessError):
        return None
    with tarfile.open(fileobj=io.BytesIO(data)) as tf:
        tf.extractall(tmp, filter="data")
    return tmp


def build(code: Path, name: str, grid: int, single_thread: bool = False, **opts) -> dict:
    env = dict(os.environ, PYTHONPATH=str(code))
    if single_thread:  # CPU seconds comparable between runs: no BLAS threads
        env.update(OMP_NUM_THREADS="1", OPENBLAS_NUM_THREADS="1", MKL_NUM_THREADS="1")
    r = subprocess.run([sys.executable, "-c", WORKER, str(REPO), name, str(grid), json.dumps(opts)], env=env,
                       capture_output=True, text=True, cwd=tempfile.gettempdir(), timeout=3600)
    if r.returncode:
        raise SystemExit(f"build of {name} failed:\n{r.stderr[-3000:]}")
    row = json.loads(r.stdout.strip().splitlines()[-1])
    row["inflation"] = round(row["triangles_out"] / max(1, row["triangles_in"]) - 1, 4)
    row["seconds"] = round(row["seconds"], 3)
    row["cpu_seconds"] = round(row["cpu_seconds"], 3)
    row["seconds_per_calibration"] = round(row["seconds"] / row["calibration_seconds"], 2)
    d = row.pop("details")
    lists = d.pop("lists", {})
    row["project_json_bytes"] = sum(v["project_json_bytes"] for v in lists.values())
    row["list_items"] = sum(v["items"] for v in lists.values())
    row["records_total"] = sum(d.get("records", {}).values())
    row.update(d)
    return row


def geomean(rows: dict, names) -> float:
    return math.exp(np.mean([math.log(rows[k]["triangles_out"] / rows[k]["triangles_in"]) for k in names])) - 1


# ---------------------------------------------------------------------------- in-process parts
def ablations(names, seeds=(0, 1, 2)) -> dict:
    """Each idea of the new builder changed alone (geometric mean over models and seeds)."""
    from meshes import load_scene

    from bake import config
    from bake.bsp.stage import stage
    from bake.scratch.numbers import position_decimals

    scenes = {k: load_scene(k) for k in names}
    grids = {k: s.replace(position_decimals=position_decimals(s.scale(), 5)) for k, s in scenes.items()}
    variants = {
        "default (edge planes, sampled scoring, balance 0.5, grid, thorough search, re-merge)": {},
        "without edge planes (edge_planes = 0)": dict(edge_planes=0),
        "edge planes at any cost (edge_plane_cost = 1e9)": dict(edge_plane_cost=1e9),
        "balance_weight 1.0 (the old default)": dict(balance_weight=1.0),
        "without the grid (tolerance epsilon = 1e-6 only)": {"_grid": False},
        "every candidate scored on every face (score_sample = 0)": dict(score_sample=0),
        "edge_planes = 64 (the default before this run's change)": dict(edge_planes=64),
        "without best-of-8 subtrees (ensemble = 1)": dict(ensemble=1),
        "doubled edge planes in the thorough search (thorough_edge_factor = 2)": dict(thorough_edge_factor=2),
        "greedy, as for big scenes (thorough_faces = 0)": dict(thorough_faces=0),
        "candidates = 16": dict(candidates=16),
        "without re-merging fragments (remerge = false)": dict(remerge=False),
    }
    out = {}
    for label, kw in variants.items():
        kw = dict(kw)
        use_grid = kw.pop("_grid", True)
        logs = {k: [] for k in names}
        secs = 0.0
        for k in names:
            for s in seeds:
                cfg = config.load(None, ["bsp.enabled=true"]).bsp
                for key, v in {**kw, "seed": s}.items():
                    object.__setattr__(cfg, key, v)
                t = time.perf_counter()
                new, _ = stage(grids[k] if use_grid else scenes[k], cfg)
                secs += time.perf_counter() - t
                logs[k].append(math.log(new.n_triangles / scenes[k].n_triangles))
        out[label] = {"geomean_inflation": round(math.exp(np.mean([v for k in names for v in logs[k]])) - 1, 4),
                      "seconds": round(secs, 2),
                      "models": {k: round(math.exp(np.mean(logs[k])) - 1, 4) for k in names}}
        print(f"{label:60s} {out[label]['geomean_inflation']:+.1%} {secs:6.1f}s  " +
              "  ".join(f"{k} {v:+.0%}" for k, v in out[label]["models"].items()), flush=True)
    return {"models": list(names), "seeds": list(seeds), "variants": out}


def search_sweep(names) -> dict:
    """Inflation and build seconds against the number of face candidates and of edge planes."""
    from meshes import load_scene

    from bake import config
    from bake.bsp.stage import stage
    from bake.scratch.numbers import position_decimals

    out = {"candidates": {}, "edge_planes": {}}
    for k in names:
        s = load_scene(k)
        s = s.replace(position_decimals=position_decimals(s.scale(), 5))
        for key, values in (("candidates", (8, 32, 64, 256, 0)), ("edge_planes", (0, 32, 64, 128, 256))):
            out[key][k] = {}
            for v in values:
                cfg = config.load(None, ["bsp.enabled=true"]).bsp
                object.__setattr__(cfg, key, v)
                t = time.perf_counter()
                new, _ = stage(s, cfg)
                sec = time.perf_counter() - t
                out[key][k]["all" if (key == "candidates" and v == 0) else f"v{v}"] = {
                    "inflation": round(new.n_triangles / s.n_triangles - 1, 4), "seconds": round(sec, 2)}
                print(f"{key} {k} {v}: {new.n_triangles / s.n_triangles - 1:+.1%} {sec:.2f}s", flush=True)
    return out


def proofs(names) -> dict:
    """The order proof (bake/bsp/verify.py) for the new builder on every model, written positions."""
    from meshes import corpus_file, interlocked_scene, load_scene, rooms_scene

    from bake import config
    from bake.bsp.stage import stage
    from bake.bsp.verify import check_order, random_cameras
    from bake.scratch.numbers import position_decimals

    scenes = {k: (simplified_bunny() if k == "bunny_20k" else load_scene(k)) for k in names}
    scenes["interlocked"] = interlocked_scene()
    scenes["rooms"] = rooms_scene()
    for extra in ("csg", "tetra"):
        if corpus_file(extra).exists():
            scenes[extra] = load_scene(extra)
    out = {}
    for k, s in scenes.items():
        s = s.replace(position_decimals=position_decimals(s.scale(), 5))
        new, _ = stage(s, config.load(None, ["bsp.enabled=true"]).bsp)
        n = 4 if new.n_triangles > 50000 else 10
        t = time.perf_counter()
        res = check_order(new, random_cameras(new, n, seed=7))
        res.pop("per_camera")
        res["seconds"] = round(time.perf_counter() - t, 2)
        out[k] = res
        print(f"proof {k}: covered {res['covered']} mismatched {res['mismatched']} (ties {res['ties']}, "
              f"edge {res['edge']}, interior {res['interior']})", flush=True)
    return out


WALK_WORKER = r'''
import json, sys
sys.path[:0] = [sys.argv[1] + "/tests", sys.argv[1] + "/tests/scratch"]
from bake import config, pipeline
from bake.scratch.project import reader_spec
from scratch_models import project_lists
res = pipeline.run(config.load(data={"input": {"path": sys.argv[2]}, "bsp": {"enabled": True}}))
art = res.scene.artefacts  # typed since issue 38; a dict in the base commit
files = art["outputs"] if isinstance(art, dict) else art.outputs
stem = next(n for n in files if n.endswith(".sb3"))
open(sys.argv[3], "wb").write(files[stem])
lists = project_lists(files[stem])
cam = reader_spec(res.scene, res.config.export, lists).camera
bsp = next(r for r in res.records if r.name == "bsp")
print(json.dumps({"eye": [cam.x, cam.y, cam.z], "triangles": res.scene.n_triangles,
                  "estimate": bsp.details.get("walk", {}).get("blocks_estimate")}))
'''


def run_walks(old: Path | None, models: dict, tmp: Path) -> dict:
    if shutil.which("node") is None or not (REPO / "vm" / "node_modules" / "scratch-vm").is_dir():
        return {"skipped": "node or vm/node_modules missing (make vm/node_modules)"}
    from conftest import corpus_path

    jobs, meta = [], []
    for name, rel in models.items():
        for who, code in (("before", old), ("after", REPO)):
            if code is None:
                continue
            p = tmp / f"{name}-{who}.sb3"
            r = subprocess.run([sys.executable, "-c", WALK_WORKER, str(REPO), str(corpus_path(*rel)), str(p)],
                               env=dict(os.environ, PYTHONPATH=str(code)), capture_output=True, text=True,
                               cwd=tempfile.gettempdir(), timeout=3600)
            if r.returncode:
                raise SystemExit(f"bake of {name} ({who}) failed:\n{r.stderr[-3000:]}")
            info = json.loads(r.stdout.strip().splitlines()[-1])
            if who == "before":  # the base commit's reader: record format 1, the eye as arguments
                run = {"call": {"target": "Mesh", "proccode": "bsp walk %s %s %s",
                                "args": [repr(float(x)) for x in info["eye"]]}, "read": {"lists": ["draw order"]}}
            else:  # format 2: the eye in the camera variables, ranges out
                run = {"call": {"target": "Mesh", "proccode": "bsp walk", "args": []},
                       "read": {"lists": ["draw ranges"]},
                       "set": {"target": "Mesh", "variables": {"cam x": repr(float(info["eye"][0])),
                                                               "cam y": repr(float(info["eye"][1])),
                                                               "cam z": repr(float(info["eye"][2]))}}}
            jobs.append({"load": str(p), "runs": [run]})
            meta.append((name, who, info))
    r = subprocess.run(["node", str(REPO / "vm" / "run.js"), "--plan", "-"], input=json.dumps({"jobs": jobs}),
                       capture_output=True, text=True, timeout=7200, cwd=str(REPO))
    res = json.loads(r.stdout)["jobs"]
    out: dict = {}
    for (name, who, info), job in zip(meta, res):
        run = job["runs"][0]
        row = {"triangles": info["triangles"], "blocks": run["blocks"], "ms": round(run["ms"], 1)}
        if who == "before":
            row["drawn"] = len(run["lists"]["draw order"])  # triangles, culled by the walk
        else:
            row["ranges"] = len(run["lists"]["draw ranges"]) // 2  # (first, n) pairs; the filler culls
        if who == "after":
            row["estimate"] = info["estimate"]
        out.setdefault(name, {})[who] = row
        print(f"walk {name} {who}: {run['blocks']:,} blocks", flush=True)
    return out


# ---------------------------------------------------------------------------- the JSON
LABELS = {"house": "house (regr01)", "cornell": "cornell box", "bunny_20k": "bunny at 20k"}


def finish(out: dict) -> dict:
    """Derived figures the docs tables show (tools/doc_tables.py renders them, never typed):
    per model before/after side by side with the time ratio, the goals, the walk ratios."""
    before, after = out.pop("before", {}), out.pop("after", {})
    models = {}
    for k in SUITE_ORDER:
        if k not in after:
            continue
        b = before.get(k)
        models[k] = {"label": LABELS.get(k, k), "before": b, "after": after[k],
                     "time_ratio": round(after[k]["seconds"] / b["seconds"], 2) if b and b["seconds"] else None,
                     "cpu_ratio": round(after[k]["seconds_per_calibration"] / b["seconds_per_calibration"], 2)
                     if b else None}
    out["models"] = models
    goal = [k for k in GOAL_SET if k in after]
    g = {}
    if all(k in before for k in goal):
        gb = round(geomean(before, goal), 4)
        ga = round(geomean(after, goal), 4)
        g["geomean"] = {"label": "geometric mean over " + ", ".join(goal), "before": gb, "goal": round(gb / 2, 4),
                        "goal_text": "at most half of before", "after": ga, "met": "yes" if ga <= gb / 2 else "no"}
    for k, v in GOALS.items():
        if k in after:
            g[k] = {"label": LABELS.get(k, k), "before": before[k]["inflation"] if k in before else None,
                    "goal": v, "goal_text": f"at most {v:+.0%}", "after": after[k]["inflation"],
                    "met": "yes" if after[k]["inflation"] <= v else "no"}
    out["goals"] = g
    walk_ratios(out)
    return out


def walk_ratios(out: dict) -> None:
    for v in (out.get("walks") or {}).values():
        if isinstance(v, dict) and v.get("before"):
            v["ratio"] = round(v["after"]["blocks"] / v["before"]["blocks"], 3)
            v["estimate_error"] = round(v["after"]["estimate"] / v["after"]["blocks"] - 1, 4)


# ---------------------------------------------------------------------------- main
def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="the suite table only")
    ap.add_argument("--no-before", action="store_true", help="skip the base commit's builder")
    ap.add_argument("--cpu", metavar="MODELS", help="only: CPU seconds of both builders, one BLAS thread, "
                    "alternating 3 times per model (e.g. bunny,bunny_20k); added to the JSON as 'cpu'")
    ap.add_argument("--walks", action="store_true", help="only: the scratch-vm walks of both builders, each "
                    "with its own commit's reader; replaces 'walks' in the JSON")
    args = ap.parse_args()
    if args.walks:
        walks_only()
        return
    if args.cpu:
        cpu_only(args.cpu.split(","))
        return
    from meshes import SUITE, corpus_file

    out: dict = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                             "loadavg_start": os.getloadavg()}, "command": " ".join(sys.argv),
                 "base_commit": BASE_COMMIT}
    names = [k for k in SUITE if corpus_file(k).exists()]
    with tempfile.TemporaryDirectory(prefix="bench-bsp-") as tmp:
        old = None if args.no_before else base_checkout(Path(tmp) / "base")
        if old is None and not args.no_before:
            print(f"base commit {BASE_COMMIT} not available (git archive failed): no 'before' column")
        before, after = {}, {}
        for k in names + ["bunny_20k"]:
            if old is not None:
                before[k] = build(old, k, 0)
            after[k] = build(REPO, k, 5)
            print(f"{k}: before {before[k]['inflation'] if k in before else float('nan'):+.1%} "
                  f"{before.get(k, {}).get('seconds', float('nan')):.2f}s, after {after[k]['inflation']:+.1%} "
                  f"{after[k]['seconds']:.2f}s", flush=True)
        out["before"], out["after"] = before, after
        if args.quick:
            _write(out)
            return
        out["ablations"] = ablations([k for k in ("suzanne", "teapot", "spot", "duck", "house") if k in names])
        out["search"] = search_sweep([k for k in ("suzanne", "house", "duck", "teapot") if k in names])
        out["proof"] = proofs(names)
        out["walks"] = run_walks(old, WALK_MODELS, Path(tmp))
    _write(out)


WALK_MODELS = {"suzanne": ("suzanne_obj", "suzanne.obj"), "teapot": ("teapot_obj", "teapot.obj"),
               "duck": ("duck_glb", "Duck.glb"), "house": ("house_max2obj_walls", "regr01.obj")}


def walks_only() -> None:
    """Re-measure the walks alone (block counts do not depend on the machine's load) and keep the
    rest of the JSON; the models' walk estimates are computed again from their recorded counts
    with this checkout's fit (bake/bsp/cost.py: the counts depend on the tree, the blocks per
    item on the reader's walk)."""
    from bake.bsp.cost import blocks_estimate

    out = json.loads(OUT.read_text()) if OUT.exists() else {"machine": {}}
    with tempfile.TemporaryDirectory(prefix="bench-bsp-") as tmp:
        old = base_checkout(Path(tmp) / "base")
        out["walks"] = run_walks(old, WALK_MODELS, Path(tmp))
    for row in (out.get("models") or {}).values():
        walk = (row.get("after") or {}).get("walk")
        if walk:
            walk["blocks_estimate"] = blocks_estimate(walk)
    out["walks_command"] = " ".join(sys.argv)
    walk_ratios(out)
    OUT.write_text(json.dumps(out, indent=1))
    print(f"wrote {OUT}")


def cpu_only(names) -> None:
    """Build time as CPU seconds (one BLAS thread), before and after alternating, so a shared
    machine's load changes both alike; the minimum of three builds each."""
    out = json.loads(OUT.read_text()) if OUT.exists() else {}
    res = out.setdefault("cpu", {"command": " ".join(sys.argv), "models": {}})
    res["loadavg_start"] = os.getloadavg()
    with tempfile.TemporaryDirectory(prefix="bench-bsp-") as tmp:
        old = base_checkout(Path(tmp) / "base")
        if old is None:
            raise SystemExit(f"base commit {BASE_COMMIT} not available")
        for k in names:
            b, a = [], []
            for _ in range(3):
                b.append(build(old, k, 0, single_thread=True)["cpu_seconds"])
                a.append(build(REPO, k, 5, single_thread=True)["cpu_seconds"])
            res["models"][k] = {"before": min(b), "after": min(a), "ratio": round(min(a) / min(b), 2),
                                "before_all": b, "after_all": a}
            print(f"cpu {k}: before {min(b):.2f}s after {min(a):.2f}s ratio {min(a) / min(b):.2f}", flush=True)
    res["loadavg_end"] = os.getloadavg()
    OUT.write_text(json.dumps(out, indent=1))
    print(f"wrote {OUT}")


def _write(out: dict) -> None:
    out = finish(out)
    out["machine"]["loadavg_end"] = os.getloadavg()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(out, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
