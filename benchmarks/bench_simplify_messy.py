"""The simplify stage on messy models: does it meet the budget, in what time, at what cost in
error, defects and picture; side by side with the stage of another commit.

    .venv/bin/python benchmarks/bench_simplify_messy.py [--before GIT_REF (default 84d81c5)]
        [--models-dir DIR] [--only NAME,NAME] [--no-before] [--out benchmarks/results/simplify_messy.json]

Models (each with the default stage, ``target_triangles`` as listed):

* public models nobody here made, listed with their source, commit, path, sha256 and licence in
  benchmarks/messy_models.json (a CAD assembly, furniture, a vehicle, game assets, CAD parts).
  They are not committed: the benchmark reads them from ``--models-dir`` (default
  benchmarks/models/, or BAKE_MESSY_MODELS) and skips, saying so, one that is missing or whose
  bytes differ;
* messy corpus models (../shared/corpus): the CSG model, the house, the teapot (parts through
  each other), the subpass soup, the triangle strips;
* the generated cases of tests/mesh/messy.py (touching boxes and cylinders, parts through each
  other, open thin tubes, non-manifold fins, broken UVs, two-sided and repeated faces), at
  detail 4, and the touching assembly at detail 6 (112,000 triangles).

Per model, written to ``rows``: triangles in and out against the target (``target_met``: within
2%), the stage's seconds, the reported max against an independent measurement of the same two
meshes (tests/mesh/simplify_reference.py, MeshLab), the defects the record counts (flipped
triangles, new non-manifold edges, new folds, parts dropped and collapsed, and the share of the
area each covers) and what the stage let go of to reach the target; the picture: the RMSE
(0..1) of depth-buffer previews of the output against the input from the four report cameras
(the sweep's image error), and per kind of defect the share of the previews' pixels its
triangles cover, the RMSE over those pixels and the largest distance from its triangles to the
input (independent: libigl's point-mesh distance on 16 points per triangle and its corners).
``before``: the stage of GIT_REF on the same model (``git archive`` in a subprocess, as
bench_simplify.py does): its seconds, triangles and what its record counted.

Timings on a shared machine are noisy: compare within one run (the load average is recorded).
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "tests" / "mesh"))

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
MANIFEST = REPO / "benchmarks" / "messy_models.json"
CORPUS_MODELS = [  # (name, file, target, what)
    ("CSG model", "boolean_csg_slivers/boolean.glb", 400, "CSG parts: slivers, sharp edges, 28 primitives"),
    ("house", "house_max2obj_walls/regr01.obj", 800, "walls meeting on non-manifold edges, 12 materials, unwelded"),
    ("teapot", "teapot_obj/teapot.obj", 630, "19 bodies, spout and handle through the body, open"),
    ("subpass soup", "subpass_scene/subpass_scene_opaque.gltf", 3000, "a soup of big overlapping triangles"),
    ("triangle strips", "triangle_strips_scene/mode5.gltf", 500, "glTF strips: coincident sheets, needles"),
]
GENERATED = [  # (case, detail, share of the input to keep)
    ("touching", 4, 0.1), ("crossing", 4, 0.1), ("tubes", 4, 0.15), ("fins", 4, 0.1), ("broken_uvs", 4, 0.1),
    ("two_sided", 4, 0.1), ("touching", 6, 0.1)]
VIEW = (320, 240)


# --------------------------------------------------------------------------- models
def _sha256(p: Path) -> str:
    return hashlib.sha256(p.read_bytes()).hexdigest()


def public_models(folder: Path) -> tuple[list[dict], list[str]]:
    """The manifest's models that are in ``folder`` with the recorded bytes; and what was skipped."""
    out, skipped = [], []
    for m in json.loads(MANIFEST.read_text())["models"]:
        bad = [f for f, h in m["files"].items() if not (folder / f).is_file() or _sha256(folder / f) != h]
        if bad:
            skipped.append(f"{m['name']}: {', '.join(bad)} missing or not the recorded bytes (get it from "
                           f"{m['repo']}@{m['commit'][:10]}: {m['path']})")
            continue
        out.append({"name": m["name"], "path": folder / m["file"], "target": m["target"], "what": m["what"],
                    "source": f"{m['repo']}@{m['commit'][:10]}: {m['path']}", "licence": m["licence"]})
    return out, skipped


def all_models(folder: Path, tmp: Path, only: set[str] | None) -> tuple[list[dict], list[str]]:
    import messy

    models, skipped = public_models(folder)
    for name, rel, target, what in CORPUS_MODELS:
        p = CORPUS / rel
        if p.is_file():
            models.append({"name": name, "path": p, "target": target, "what": what,
                           "source": f"../shared/corpus/{rel}", "licence": "see ../shared/corpus/MANIFEST.md"})
        else:
            skipped.append(f"{name}: {p} is not there")
    for case, detail, share in GENERATED:
        p = messy.write(case, tmp / f"messy{detail}", detail)
        models.append({"name": f"{case} ({detail})", "path": p, "target": None, "share": share,
                       "what": messy.WHAT[case], "source": "generated: tests/mesh/messy.py", "licence": "ours"})
    if only:
        models = [m for m in models if m["name"] in only]
    return models, skipped


def load(path: Path):
    from bake import pipeline
    return pipeline.run(pipeline.load_config_for(path), until="clean", cache=None).scene


# --------------------------------------------------------------------------- the picture
def picture(a, b, defects: dict) -> dict:
    """Previews of ``b`` against ``a`` from the report's four cameras (culled by material
    sidedness, as the reader draws): the RMSE over every pixel, and per kind of defect (its
    triangles' ids in ``b``) the share of the pixels they cover and the RMSE over those."""
    from bake.outputs.preview import cameras
    from bake.render import render_scene

    cams = cameras(np.asarray(a.positions), *VIEW)
    diff, kinds = [], {k: [] for k in defects}
    for _, cam in cams:
        ia, ib = render_scene(a, cam, shade=True), render_scene(b, cam, shade=True)
        d2 = ((ia.image - ib.image) ** 2).mean(axis=2)
        diff.append(d2.ravel())
        for k, ids in defects.items():
            mask = np.isin(ib.tri_id, np.asarray(ids, np.int64)) if len(ids) else np.zeros(ib.tri_id.shape, bool)
            kinds[k].append(d2[mask])
    n = sum(len(x) for x in diff)
    out = {"rmse": float(np.sqrt(np.concatenate(diff).mean())), "pixels": int(n)}
    for k, parts in kinds.items():
        px = np.concatenate(parts)
        out[k] = {"pixel_share": len(px) / n, "rmse": float(np.sqrt(px.mean())) if len(px) else None}
    return out


def defect_error(a, b, ids: list[int]) -> float | None:
    """The largest distance (fraction of the diagonal) from points on triangles ``ids`` of ``b``
    (their corners and 16 points inside each) to ``a``: libigl's exact point-mesh distance."""
    import igl

    if not ids:
        return None
    C = np.asarray(b.positions)[np.asarray(b.triangles)[np.asarray(ids)]]
    g = np.linspace(0, 1, 6)
    u, v = np.meshgrid(g, g, indexing="ij")
    ok = u + v <= 1
    w = np.stack([1 - u[ok] - v[ok], u[ok], v[ok]], 1)
    P = np.einsum("pk,tkd->tpd", w, C).reshape(-1, 3)
    d2, _, _ = igl.point_mesh_squared_distance(P, np.asarray(a.positions, np.float64),
                                                np.asarray(a.triangles, np.int64))
    return float(np.sqrt(d2.max()) / a.scale())


# --------------------------------------------------------------------------- the old stage
_WORKER = r"""
import json, sys, time
import numpy as np
sys.path.insert(0, sys.argv[1])
from bake import pipeline
from bake.config import SimplifyConfig
try:  # the stage's package (issue 38)
    from bake.mesh.simplify.stage import stage
except ModuleNotFoundError:  # a commit before it: the one module bake/mesh/simplify.py
    from bake.mesh.simplify import stage
args = json.loads(sys.argv[2])
sc = pipeline.run(pipeline.load_config_for(args["path"]), until="clean").scene
t = time.perf_counter()
out, rec = stage(sc, SimplifyConfig(enabled=True, target_triangles=args["target"]))
dt = time.perf_counter() - t
a = rec.accuracy
print(json.dumps({"stage_seconds": dt, "triangles_out": int(out.n_triangles),
                  "reported_max": a.get("hausdorff_max"), "flipped_triangles": a.get("flipped_triangles"),
                  "new_nonmanifold_edges": a.get("new_nonmanifold_edges"),
                  "backed_off": "backed_off_from" in rec.details, "warnings": list(rec.warnings)}))
"""


def before_run(src: Path, path: Path, target: int) -> dict:
    env = dict(os.environ, PYTHONPATH=str(src))
    done = subprocess.run([sys.executable, "-c", _WORKER, str(src), json.dumps({"path": str(path), "target": target})],
                          capture_output=True, text=True, env=env, timeout=3600)
    if done.returncode != 0:
        return {"failed": done.stderr.strip().splitlines()[-1][:300] if done.stderr.strip() else "exit "
                f"{done.returncode}"}
    return json.loads(done.stdout.strip().splitlines()[-1])


# --------------------------------------------------------------------------- main
def row_for(m: dict, sc, out, rec, seconds: float) -> dict:
    from simplify_reference import hausdorff_reference

    diag = sc.scale()
    ref = hausdorff_reference(sc.positions, sc.triangles, out.positions, out.triangles, samples=100_000, rounds=5)
    acc, det = rec.accuracy, rec.details
    d = det.get("defects", {})
    ids = det.get("defect_triangles", {})
    target = int(det.get("target_triangles", 0))
    pic = picture(sc, out, ids)
    return {
        "model": m["name"], "what": m["what"], "source": m["source"], "licence": m["licence"],
        "triangles_in": int(sc.n_triangles), "target": target, "triangles_out": int(out.n_triangles),
        "target_off": (out.n_triangles - target) / target, "target_met": abs(out.n_triangles - target) <= 0.02 * target,
        "stage_seconds": round(seconds, 3),
        "phase_seconds": {k[:-8]: det.get(k) for k in ("prepare_seconds", "library_seconds", "repair_seconds",
                                                         "check_seconds", "fit_seconds", "measure_seconds",
                                                         "other_seconds")},
        "reported_max": acc.get("hausdorff_max"), "reference_max": ref.max / diag,
        "reported_over_reference": acc["hausdorff_max"] / (ref.max / diag) if ref.max > 0 else None,
        "flipped_triangles": d.get("flipped_triangles"), "flipped_area": d.get("flipped_area"),
        "new_nonmanifold_edges": d.get("new_nonmanifold_edges"), "new_nonmanifold_area": d.get("new_nonmanifold_area"),
        "new_folds": d.get("new_folds"), "folded_area": d.get("folded_area"),
        "parts": (det.get("parts") or {}).get("count"), "parts_dropped": d.get("parts_dropped"),
        "parts_collapsed": d.get("parts_collapsed"), "relaxed": ", ".join(det.get("relaxed") or []) or "-",
        "two_sided": (det.get("layer") or {}).get("with_back", 0), "repeats_dropped": (det.get("layer") or {}).get(
            "repeated_dropped", 0),
        "picture": pic,
        "defect_error": {k: defect_error(sc, out, v) for k, v in ids.items()},
        "warnings": list(rec.warnings),
    }


def summarise(rows: list[dict]) -> dict:
    done = [r for r in rows if "triangles_out" in r]
    big = [r for r in done if r["triangles_in"] >= 80_000]
    small = [r for r in done if r["triangles_in"] < 20_000]
    ratios = [r["reported_over_reference"] for r in done if r["reported_over_reference"] is not None]
    return {"models": len(done), "targets_met": sum(r["target_met"] for r in done),
            "slowest_100k_class_seconds": max((r["stage_seconds"] for r in big), default=None),
            "slowest_small_seconds": max((r["stage_seconds"] for r in small), default=None),
            "reported_over_reference_min": min(ratios, default=None),
            "reported_over_reference_max": max(ratios, default=None),
            "before_targets_met": sum(bool(r.get("before", {}).get("target_met")) for r in done),
            "before_slowest_seconds": max((r["before"]["stage_seconds"] for r in done
                                           if "stage_seconds" in r.get("before", {})), default=None)}


def main(argv: list[str] | None = None) -> int:
    from bake.config import SimplifyConfig
    from bake.mesh.simplify import stage as S

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    # (`make bench` runs every benchmark without arguments: the default is the commit before the
    # budget was met by default, the one docs/simplify.md's "Messy models" table compares with)
    ap.add_argument("--before", default="84d81c5")
    ap.add_argument("--no-before", action="store_true")
    ap.add_argument("--models-dir", default=os.environ.get("BAKE_MESSY_MODELS", str(REPO / "benchmarks" / "models")))
    ap.add_argument("--only", default="", help="comma-separated model names")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "simplify_messy.json"))
    args = ap.parse_args(argv)
    load_start = os.getloadavg()
    t_all = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory() as td:
        tmp = Path(td)
        models, skipped = all_models(Path(args.models_dir), tmp, set(filter(None, args.only.split(","))) or None)
        for s in skipped:
            print("skip", s, flush=True)
        src = None
        if not args.no_before:
            ref = subprocess.run(["git", "-C", str(REPO), "rev-parse", args.before], check=True, capture_output=True,
                                 text=True).stdout.strip()
            src = tmp / "before"
            src.mkdir()
            arc = subprocess.run(["git", "-C", str(REPO), "archive", ref, "bake"], check=True, capture_output=True).stdout
            subprocess.run(["tar", "-x", "-C", str(src)], input=arc, check=True)
        for m in models:
            sc = load(m["path"])
            target = m["target"] or int(round(m["share"] * sc.n_triangles))
            t = time.perf_counter()
            out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_triangles=target))
            sec = time.perf_counter() - t
            row = row_for(m, sc, out, rec, sec)
            if src is not None:
                b = before_run(src, m["path"], target)
                if "triangles_out" in b:
                    b["target_met"] = abs(b["triangles_out"] - target) <= 0.02 * target
                row["before"] = b
            rows.append(row)
            b = row.get("before", {})
            print(f"{m['name']:20s} {row['triangles_in']:7,d} -> {row['triangles_out']:6,d} (target {target:,}) "
                  f"{sec:6.2f} s  max {row['reported_max']:.3%} / independent {row['reference_max']:.3%}  "
                  f"flipped {row['flipped_triangles']} nm {row['new_nonmanifold_edges']} folds {row['new_folds']} "
                  f"image {row['picture']['rmse']:.3f} relaxed {row['relaxed']}"
                  + (f" | before {b['triangles_out']:,} in {b['stage_seconds']:.1f} s" if "triangles_out" in b else
                     f" | before: {b.get('failed')}" if b else ""), flush=True)
    res = {"benchmark": "bench_simplify_messy.py",
           "command": " ".join(["benchmarks/bench_simplify_messy.py"] + (argv if argv is not None else sys.argv[1:])),
           "before": None if args.no_before else args.before, "skipped": skipped,
           "machine": {"platform": platform.platform(), "python": platform.python_version(), "cpus": os.cpu_count(),
                       "load_average_start": load_start, "load_average_end": os.getloadavg()},
           "seconds": round(time.perf_counter() - t_all, 1), "rows": rows, "summary": summarise(rows)}
    Path(args.out).write_text(json.dumps(res, indent=1) + "\n")
    print(json.dumps(res["summary"]))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
