"""Speed of the OBJ importer against trimesh on corpus files, measured side by side.

    .venv/bin/python benchmarks/bench_import.py [--repeat 5] [extra.obj ...]

For each file (the Stanford bunny, the Utah teapot, the textured capsule, plus any given on
the command line) the runs alternate: our ``bake.importers.obj.load``, then
``trimesh.load(path, process=False)``, then the same with ``skip_materials=True`` (trimesh
otherwise decodes texture images, which our importer only checks for existence). The table
shows the best of ``--repeat`` runs of each and the ratio ours / trimesh (below 1 = faster).
The machine's load average is recorded because other jobs may share it.
Writes ``benchmarks/results/import.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from pathlib import Path

import numpy as np

from bake.config import ImportJob
from bake.importers.obj import load

REPO = Path(__file__).resolve().parent.parent
CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
FILES = [
    ("bunny", "stanford_bunny_res1_obj/stanford-bunny.obj"),
    ("teapot", "teapot_obj/teapot.obj"),
    ("capsule", "capsule_textured/capsule.obj"),
]
OUT = REPO / "benchmarks" / "results" / "import.json"


def timed(fn) -> float:
    t0 = time.perf_counter()
    fn()
    return time.perf_counter() - t0


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("extra", nargs="*", type=Path, help="more OBJ files to time")
    a = ap.parse_args()
    import trimesh

    files = [(n, CORPUS / f) for n, f in FILES] + [(p.stem, p) for p in a.extra]
    missing = [str(p) for _, p in files if not p.is_file()]
    if missing:
        raise SystemExit(f"missing files (set BAKE_CORPUS?): {', '.join(missing)}")

    results = []
    load_before = os.getloadavg()[0]
    for name, path in files:
        scene, rec = load(ImportJob(path=path))  # warm up (imports, page cache)
        trimesh.load(path, process=False)
        ours, tm, tm_skip = [], [], []
        for _ in range(a.repeat):
            ours.append(timed(lambda: load(ImportJob(path=path))))
            tm.append(timed(lambda: trimesh.load(path, process=False)))
            tm_skip.append(timed(lambda: trimesh.load(path, process=False, skip_materials=True)))
        size = path.stat().st_size
        results.append({
            "name": name, "file": str(path), "bytes": size,
            "vertices": scene.n_vertices, "polygons": scene.n_polygons,
            "polygon_sizes": rec.details["polygon_sizes"],
            "ours_best_s": min(ours), "ours_median_s": statistics.median(ours),
            "trimesh_best_s": min(tm), "trimesh_median_s": statistics.median(tm),
            "trimesh_skip_materials_best_s": min(tm_skip),
            "ratio_best": min(ours) / min(tm),
            "ratio_best_skip_materials": min(ours) / min(tm_skip),
            "ours_mb_per_s": size / 1e6 / min(ours),
        })
    doc = {
        "benchmark": "import (OBJ)",
        "command": "python benchmarks/bench_import.py --repeat %d" % a.repeat,
        "repeat": a.repeat,
        "python": platform.python_version(), "numpy": np.__version__, "trimesh": trimesh.__version__,
        "cpus": os.cpu_count(),
        "loadavg_1min_before": load_before, "loadavg_1min_after": os.getloadavg()[0],
        "results": results,
    }
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(doc, indent=2) + "\n")

    print(f"best of {a.repeat}, side by side (load average {load_before:.2f} -> "
          f"{doc['loadavg_1min_after']:.2f} on {os.cpu_count()} cpus)")
    print(f"{'file':10s} {'MB':>6s} {'polygons':>9s} {'ours s':>8s} {'trimesh s':>10s} {'ratio':>6s} "
          f"{'tm skip-mtl s':>14s} {'ratio':>6s} {'ours MB/s':>10s}")
    for r in results:
        print(f"{r['name']:10s} {r['bytes'] / 1e6:6.2f} {r['polygons']:9,d} {r['ours_best_s']:8.4f} "
              f"{r['trimesh_best_s']:10.4f} {r['ratio_best']:6.2f} "
              f"{r['trimesh_skip_materials_best_s']:14.4f} {r['ratio_best_skip_materials']:6.2f} "
              f"{r['ours_mb_per_s']:10.1f}")
    print(f"wrote {OUT.relative_to(REPO)}")


if __name__ == "__main__":
    main()
