"""BSP benchmark: triangle inflation, tree and list sizes, build time, order proof, ablations.

    .venv/bin/python benchmarks/bench_bsp.py            # everything (several minutes)
    .venv/bin/python benchmarks/bench_bsp.py --quick    # suite table only, no bunny proofs

Writes benchmarks/results/bsp.json. The machine may be shared: every timed build is preceded by
a fixed calibration workload (numpy sort + matmul) timed the same way, and the JSON keeps both,
so times can be compared as ratios measured side by side.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "tests" / "bsp"))

from meshes import SUITE, corpus_file, interlocked_scene, load_scene, rooms_scene  # noqa: E402

from bake import config  # noqa: E402
from bake.bsp.stage import stage  # noqa: E402
from bake.bsp.verify import check_order, random_cameras  # noqa: E402
from bake.scene import make_scene  # noqa: E402

OUT = REPO / "benchmarks" / "results" / "bsp.json"


def calibration() -> float:
    """Seconds for a fixed numpy workload (about 0.15 s on an idle core of this machine)."""
    rng = np.random.default_rng(0)
    a = rng.random(2_000_000)
    m = rng.random((300, 300))
    t = time.perf_counter()
    for _ in range(3):
        np.sort(a)
        m @ m @ m
    return time.perf_counter() - t


def cfg(**kw):
    c = config.load(None, ["bsp.enabled=true"]).bsp
    for k, v in kw.items():
        object.__setattr__(c, k, v)
    return c


def run(scene, **kw):
    cal = calibration()
    t = time.perf_counter()
    new, rec = stage(scene, cfg(**kw))
    sec = time.perf_counter() - t
    d = rec.details
    nb = d["lists"]["bsp nodes"]
    pb = d["lists"]["bsp planes"]
    records = sum(d["records"].values())
    return new, {
        "triangles_in": scene.n_triangles, "triangles_out": new.n_triangles,
        "inflation": round(new.n_triangles / max(1, scene.n_triangles) - 1, 4),
        "splits": d["splits"], "kept_whole": d["kept_whole"], "merged_triangles": d["merged_triangles"],
        "tree_nodes": d["tree_nodes"], "tree_depth": d["tree_depth"], "record_depth": d["record_depth"],
        "records": d["records"], "records_total": records, "planes": d["planes"],
        "list_items": nb["items"] + pb["items"], "nodes_items": nb["items"], "planes_items": pb["items"],
        "project_json_bytes": nb["project_json_bytes"] + pb["project_json_bytes"],
        "bytes_per_record": round((nb["project_json_bytes"] + pb["project_json_bytes"]) / max(1, records), 2),
        "items_per_record": round((nb["items"] + pb["items"]) / max(1, records), 2),
        "nodes_bytes": nb["project_json_bytes"], "planes_bytes": pb["project_json_bytes"],
        "bytes_per_triangle": d["bytes_per_triangle"], "items_per_triangle": d["items_per_triangle"],
        "seconds": round(sec, 3), "calibration_seconds": round(cal, 3),
        "seconds_per_calibration": round(sec / cal, 2), "phases": d["seconds"],
    }


def geomean_inflation(rows) -> float:
    return math.exp(np.mean([math.log(r["triangles_out"] / r["triangles_in"]) for r in rows])) - 1


def simplified_bunny(target: int = 20000):
    """A 20k-triangle organic model: the bunny decimated with fast-simplification (deterministic)."""
    import fast_simplification

    b = load_scene("bunny")
    used = np.unique(b.triangles)
    remap = np.full(b.n_vertices, -1)
    remap[used] = np.arange(len(used))
    v, f = fast_simplification.simplify(b.positions[used].astype(np.float32), remap[b.triangles].astype(np.int32),
                                        target_reduction=1 - target / b.n_triangles)
    return make_scene(np.asarray(v, np.float64), np.asarray(f, np.int64))


def table(rows: dict) -> str:
    head = f"{'model':10s} {'in':>6s} {'out':>7s} {'infl':>7s} {'depth':>5s} {'recs':>6s} {'planes':>6s} " \
           f"{'items':>7s} {'bytes':>8s} {'B/rec':>6s} {'B/tri':>6s} {'sec':>6s} {'sec/cal':>7s}"
    lines = [head]
    for k, r in rows.items():
        lines.append(f"{k:10s} {r['triangles_in']:6d} {r['triangles_out']:7d} {r['inflation']:+7.1%} "
                     f"{r['tree_depth']:5d} {r['records_total']:6d} {r['planes']:6d} {r['list_items']:7d} "
                     f"{r['project_json_bytes']:8d} {r['bytes_per_record']:6.2f} {r['bytes_per_triangle']:6.2f} "
                     f"{r['seconds']:6.2f} {r['seconds_per_calibration']:7.1f}")
    return "\n".join(lines)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quick", action="store_true", help="suite table only")
    args = ap.parse_args()
    out: dict = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                             "loadavg_start": os.getloadavg()}, "command": " ".join(sys.argv)}
    missing = [k for k in SUITE if not corpus_file(k).exists()]
    if missing:
        print(f"corpus models missing: {missing} (set BAKE_CORPUS)")
    names = [k for k in SUITE if k not in missing]
    scenes = {k: load_scene(k) for k in names}

    # ---- the suite with the default configuration
    suite = {}
    built = {}
    for k in names:
        built[k], suite[k] = run(scenes[k])
        print(f"{k}: {suite[k]['inflation']:+.1%} in {suite[k]['seconds']:.2f}s", flush=True)
    out["suite"] = suite
    out["suite_geomean_inflation"] = round(geomean_inflation(list(suite.values())), 4)
    print(table(suite))
    print(f"geometric mean inflation {out['suite_geomean_inflation']:+.1%}")

    # ---- a 20k-triangle organic model for the build-time target
    try:
        b20 = simplified_bunny()
        _, out["bunny_20k"] = run(b20)
        print(f"bunny 20k: {out['bunny_20k']['triangles_in']} tris, {out['bunny_20k']['seconds']:.2f}s, "
              f"{out['bunny_20k']['inflation']:+.1%}")
    except Exception as e:  # noqa: BLE001
        out["bunny_20k"] = {"error": repr(e)}

    if args.quick:
        _write(out)
        return

    # ---- ablations: each idea on / off, side by side
    small = [k for k in ("suzanne", "teapot", "spot", "duck", "house", "cornell", "capsule") if k in scenes]
    variants = {
        "naive_one_random_pivot": dict(candidates=1, leaves="none", merge_coplanar=False, gap_planes=False,
                                       split_cost="pieces", split_weight=8.0, fragments="fans"),
        "classic_fans(8*splits+|F-B|)": dict(leaves="none", merge_coplanar=False, gap_planes=False,
                                             split_cost="pieces", split_weight=8.0, fragments="fans"),
        "classic_polygons": dict(leaves="none", merge_coplanar=False, gap_planes=False, split_cost="pieces",
                                 split_weight=8.0),
        "+triangle_cost": dict(leaves="none", merge_coplanar=False, gap_planes=False),
        "+convex_leaves": dict(leaves="convex", merge_coplanar=False, gap_planes=False),
        "+acyclic_leaves(no_peel)": dict(leaves="acyclic", merge_coplanar=False, gap_planes=False),
        "+priority_peel(no_peeled_candidates)": dict(merge_coplanar=False, gap_planes=False,
                                                     peeled_candidates=False),
        "+priority_peel": dict(merge_coplanar=False, gap_planes=False),
        "+merge_coplanar": dict(gap_planes=False),
        "+gap_planes(=default)": {},
        "default+axis_planes": dict(axis_planes=True),
        "default+coplanar_weight4": dict(coplanar_weight=4.0),
        "default+split_weight8": dict(split_weight=8.0),
        "default+split_weight2": dict(split_weight=2.0),
        "default+no_hull_peel": dict(hull_peel=False),
        "default+epsilon1e-5": dict(epsilon=1e-5),
    }
    abl = {}
    for name, kw in variants.items():
        rows = {}
        for k in small:
            # "fragments" is a build option, not a config key: set on the section object, the
            # stage copies every BuildOptions field the section has
            _, rows[k] = run(scenes[k], **kw)
        abl[name] = {"geomean_inflation": round(geomean_inflation(list(rows.values())), 4),
                     "models": {k: {"inflation": r["inflation"], "seconds": r["seconds"],
                                    "seconds_per_calibration": r["seconds_per_calibration"],
                                    "records": r["records_total"]} for k, r in rows.items()}}
        print(f"{name:30s} geomean {abl[name]['geomean_inflation']:+.1%}  " +
              "  ".join(f"{k} {r['inflation']:+.0%}" for k, r in rows.items()), flush=True)
    out["ablations"] = {"models": small, "variants": abl}

    # ---- accuracy against time: number of candidate planes
    cand = {}
    for k in [m for m in ("suzanne", "house", "duck", "teapot") if m in scenes]:
        cand[k] = {}
        for c in (8, 32, 64, 256, 0):
            _, r = run(scenes[k], candidates=c)
            cand[k]["all" if c == 0 else str(c)] = {"inflation": r["inflation"], "seconds": r["seconds"],
                                                     "seconds_per_calibration": r["seconds_per_calibration"]}
            print(f"candidates {k} {c}: {r['inflation']:+.1%} {r['seconds']:.2f}s", flush=True)
    out["candidates"] = cand

    # ---- proof of order on every model and the generated scenes
    proofs = {}
    gen = {"interlocked": interlocked_scene(), "rooms": rooms_scene()}
    for extra in ("csg", "tetra"):
        if corpus_file(extra).exists():
            gen[extra] = load_scene(extra)
    for k, sc in list(built.items()) + [(g, run(s)[0]) for g, s in gen.items()]:
        n = 4 if sc.n_triangles > 50000 else 10
        t = time.perf_counter()
        res = check_order(sc, random_cameras(sc, n, seed=7))
        res.pop("per_camera")
        res["seconds"] = round(time.perf_counter() - t, 2)
        proofs[k] = res
        print(f"proof {k}: covered {res['covered']} mismatched {res['mismatched']} (ties {res['ties']}, "
              f"edge {res['edge']}, interior {res['interior']}) = {res['mismatch_fraction']:.4%}, "
              f"not ties {res['non_tie_fraction']:.4%}", flush=True)
    out["proof"] = proofs
    _write(out)


def _write(out: dict) -> None:
    out["machine"]["loadavg_end"] = os.getloadavg()
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(out, indent=1))
    print(f"wrote {OUT}")


if __name__ == "__main__":
    main()
