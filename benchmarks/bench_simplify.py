"""Simplification: accuracy against time, every method side by side on the same machine.

    .venv/bin/python benchmarks/bench_simplify.py [--models bunny,spot,teapot]
                                                  [--ratios 0.5,0.1,0.02,0.01] [--quick]

For every model, ratio and method it runs the simplify stage and records triangles out, the
stage's seconds, the measured symmetric Hausdorff max/mean (fractions of the bbox diagonal;
bake/mesh/simplify_error.py, the same metric for every method), flipped triangles and new
non-manifold edges. Separately it times the bare library call (best of 3, no checks, no
measuring) so the libraries' own speed can be compared. Timings on a shared machine are noisy:
compare the ratios within one run, not the absolute numbers across runs.

Methods:
  meshopt        meshoptimizer alone (fit_iterations = 0, refine_rounds = 0)
  fast           fast-simplification alone (preserve_border)
  quality        MeshLab quadric edge collapse alone
  meshopt+fit    meshoptimizer + least-squares refit + 2 refine rounds (the stage default)

The error ceiling is switched off (error_ceiling = 0) so every method is held to the same
triangle count. Results go to benchmarks/results/simplify.json and a table is printed.
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

from bake.config import SimplifyConfig  # noqa: E402
from bake.mesh import simplify as S  # noqa: E402
from bake.mesh import simplify_meshopt  # noqa: E402
from bake.scene import Scene, make_scene  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
MODELS = {
    "bunny": "stanford_bunny_res1_obj/stanford-bunny.obj",
    "spot": "spot_triangulated/spot/spot_triangulated.obj",
    "teapot": "teapot_obj/teapot.obj",
}
METHODS = {
    "meshopt": dict(method="meshopt", fit_iterations=0, refine_rounds=0),
    "fast": dict(method="fast", fit_iterations=0, refine_rounds=0),
    "quality": dict(method="quality", fit_iterations=0, refine_rounds=0),
    "meshopt+fit": dict(method="meshopt", fit_iterations=3, refine_rounds=2),
}


def load(path: Path) -> Scene:
    """Through the project's import/triangulate/clean stages; trimesh if they are missing."""
    try:
        from bake import pipeline
        return pipeline.run(pipeline.load_config_for(path), until="clean").scene
    except ImportError:
        import trimesh
        m = trimesh.load(path, process=False, force="mesh")
        V, inv = np.unique(np.asarray(m.vertices, np.float64), axis=0, return_inverse=True)
        F = inv.reshape(-1)[np.asarray(m.faces)]
        uv = getattr(m.visual, "uv", None)
        return make_scene(V, F, tri_uvs=None if uv is None else np.asarray(uv, np.float64)[np.asarray(m.faces)])


def library_ms(scene: Scene, method: str, target: int, repeat: int = 3) -> float:
    """Best-of-``repeat`` milliseconds of the bare library call on the stage's own input."""
    prep = S._prepare(scene, SimplifyConfig(target_triangles=target))
    best = float("inf")
    for _ in range(repeat):
        if method == "meshopt":
            t = time.perf_counter()
            Fw, wv, _, _ = S._wedges(prep)
            simplify_meshopt.simplify(prep.V[wv], Fw, target)
        elif method == "fast":
            import fast_simplification
            t = time.perf_counter()
            fast_simplification.simplify(prep.V, prep.F.astype(np.int32), target_count=target, preserve_border=True)
        else:
            import pymeshlab
            ms = pymeshlab.MeshSet()
            ms.add_mesh(pymeshlab.Mesh(prep.V, prep.F.astype(np.int32)))
            t = time.perf_counter()
            ms.meshing_decimation_quadric_edge_collapse(targetfacenum=target, qualitythr=0.3, preserveboundary=True,
                                                        preservenormal=True, optimalplacement=True)
        best = min(best, time.perf_counter() - t)
    return best * 1000.0


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--models", default="bunny,spot,teapot")
    ap.add_argument("--ratios", default="0.5,0.1,0.02,0.01")
    ap.add_argument("--methods", default=",".join(METHODS))
    ap.add_argument("--quick", action="store_true", help="skip the bare library timings")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "simplify.json"))
    args = ap.parse_args(argv)
    ratios = [float(r) for r in args.ratios.split(",")]
    rows = []
    for model in args.models.split(","):
        path = CORPUS / MODELS[model]
        if not path.exists():
            print(f"skip {model}: {path} missing", file=sys.stderr)
            continue
        scene = load(path)
        T0 = scene.n_triangles
        for ratio in ratios:
            target = max(1, int(round(T0 * ratio)))
            for name in args.methods.split(","):
                cfg = SimplifyConfig(enabled=True, target_ratio=ratio, error_ceiling=0.0, **METHODS[name])
                t = time.perf_counter()
                out, rec = S.stage(scene, cfg)
                stage_s = time.perf_counter() - t
                base = name.split("+")[0]
                lib_ms = None if args.quick or name != base else library_ms(scene, base, target)
                row = {
                    "model": model, "ratio": ratio, "method": name, "triangles_in": T0, "target": target,
                    "triangles_out": out.n_triangles, "stage_seconds": round(stage_s, 4),
                    "library_ms_best_of_3": None if lib_ms is None else round(lib_ms, 2),
                    "library_ms_per_100k_input": None if lib_ms is None else round(lib_ms * 1e5 / T0, 2),
                    "hausdorff_max": rec.accuracy.get("hausdorff_max"),
                    "hausdorff_mean": rec.accuracy.get("hausdorff_mean"),
                    "flipped_triangles": rec.accuracy.get("flipped_triangles"),
                    "new_nonmanifold_edges": rec.accuracy.get("new_nonmanifold_edges"),
                    "fit_seconds": rec.details.get("fit_seconds"), "warnings": rec.warnings,
                }
                rows.append(row)
                print(f"{model:7s} {ratio:5.2f} {name:12s} {out.n_triangles:6d}/{target:<6d} "
                      f"stage {stage_s:7.2f}s lib {'-' if lib_ms is None else f'{lib_ms:8.1f}ms'} "
                      f"max {100 * row['hausdorff_max']:.3f}% mean {100 * row['hausdorff_mean']:.4f}% "
                      f"flips {row['flipped_triangles']} nm {row['new_nonmanifold_edges']}", flush=True)
    result = {
        "command": "benchmarks/bench_simplify.py " + " ".join(argv if argv is not None else sys.argv[1:]),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                    "load_average": os.getloadavg() if hasattr(os, "getloadavg") else None},
        "libraries": {"meshoptimizer": simplify_meshopt.version(), "fast_simplification": _v("fast-simplification"),
                      "pymeshlab": _v("pymeshlab")},
        "metric": "symmetric Hausdorff (all vertices + 20000 area-weighted samples per direction; KD-tree "
                  "candidate point-triangle distances, the max verified exact), fractions of the bbox diagonal",
        "rows": rows,
    }
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(result, indent=1))
    print_table(rows)
    return 0


def _v(name: str) -> str | None:
    try:
        from importlib.metadata import version
        return version(name)
    except Exception:
        return None


def print_table(rows: list[dict]) -> None:
    print()
    print("| model | ratio | method | tris out | stage s | library ms (best of 3) | ms / 100k in | Hmax % diag | Hmean % diag | flips | new NM |")
    print("|---|---|---|---|---|---|---|---|---|---|---|")
    for r in rows:
        lib = "-" if r["library_ms_best_of_3"] is None else f"{r['library_ms_best_of_3']:.1f}"
        per = "-" if r["library_ms_per_100k_input"] is None else f"{r['library_ms_per_100k_input']:.1f}"
        print(f"| {r['model']} | {r['ratio']:.0%} | {r['method']} | {r['triangles_out']} | {r['stage_seconds']:.2f} | "
              f"{lib} | {per} | {100 * r['hausdorff_max']:.3f} | {100 * r['hausdorff_mean']:.4f} | "
              f"{r['flipped_triangles']} | {r['new_nonmanifold_edges']} |")


if __name__ == "__main__":
    raise SystemExit(main())
