"""Scale: a generated 1M-triangle, 100-material model through every stage, and a 10M-line OBJ.

    .venv/bin/python benchmarks/bench_scale.py [--triangles 1000000] [--materials 100]
        [--simplify-to 5000] [--obj-lines 10000000] [--skip-full] [--workdir DIR] [--quick]
        [--parse-only] [--out FILE] [--derive]

Part 1, the pipeline. A bumpy height field of quads (``--triangles`` triangles after
triangulation) in ``--materials`` tiles, one ``usemtl`` each, is written as OBJ + MTL. Then one
fresh subprocess per stage runs the real pipeline *up to and including* that stage (import,
transform, triangulate, clean, simplify to ``--simplify-to`` triangles, lighting = AO at 64 samples,
BSP, BVH, export), so ``ru_maxrss`` of the child is the peak of everything up to that stage; inside
the child, tracemalloc measures the peak of Python/numpy allocations *during* that stage alone.
Progress is printed as each stage finishes. Part 2 (unless ``--skip-full``) runs BVH and AO
on the full-size mesh (no simplification), the stages whose cost grows with it.

Part 3, the parser. An OBJ of ``--obj-lines`` lines (1/3 ``v``, 2/3 ``f``) is imported in a
subprocess; peak RSS is reported against the file size (and against a 1/10 file, to show how it
grows). ``--parse-only`` runs this part alone and replaces only ``obj_parse`` in the results file.

Writes ``benchmarks/results/scale.json`` (or ``--out``). Figures depend on the machine and its
load (recorded).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import resource
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "benchmarks" / "results" / "scale.json"
AO_SAMPLES = 64  # the lighting stage's rays per vertex
GB = 1024 ** 3


# --------------------------------------------------------------------------- the model
def write_model(folder: Path, triangles: int, materials: int) -> Path:
    """A height field of quads, ``materials`` rectangular tiles; returns the OBJ path."""
    n = int(np.ceil(np.sqrt(triangles / 2))) + 1  # vertices per side
    x, z = np.meshgrid(np.linspace(-1, 1, n), np.linspace(-1, 1, n))
    y = 0.08 * np.sin(9 * x) * np.cos(7 * z) + 0.03 * np.sin(40 * x + 3 * z)
    v = np.stack([x.ravel(), y.ravel(), z.ravel()], 1)
    i = np.arange(n * n).reshape(n, n)
    quads = np.stack([i[:-1, :-1], i[1:, :-1], i[1:, 1:], i[:-1, 1:]], -1).reshape(-1, 4) + 1
    q = n - 1
    k = int(np.ceil(np.sqrt(materials)))
    tile = (np.arange(q)[:, None] * k // q) * k + (np.arange(q)[None, :] * k // q)
    tile = np.minimum(tile.ravel(), materials - 1)
    order = np.argsort(tile, kind="stable")
    obj = folder / "scale.obj"
    with open(obj, "w") as f:
        f.write("mtllib scale.mtl\n")
        np.savetxt(f, v, fmt="v %.6f %.6f %.6f")
        starts = np.searchsorted(tile[order], np.arange(materials))
        for m in range(materials):
            sel = order[starts[m]:(starts[m + 1] if m + 1 < materials else len(order))]
            f.write(f"usemtl m{m}\n")
            np.savetxt(f, quads[sel], fmt="f %d %d %d %d")
    rng = np.random.default_rng(0)
    (folder / "scale.mtl").write_text("".join(
        f"newmtl m{m}\nKd {c[0]:.3f} {c[1]:.3f} {c[2]:.3f}\n" for m, c in enumerate(rng.random((materials, 3)))))
    return obj


def write_obj_lines(path: Path, lines: int) -> None:
    """An OBJ of ``lines`` lines: a third ``v`` (random numbers), two thirds ``f`` triangles."""
    nv = lines // 3
    nf = lines - nv
    rng = np.random.default_rng(1)
    with open(path, "w") as f:
        for s in range(0, nv, 1_000_000):
            np.savetxt(f, rng.random((min(1_000_000, nv - s), 3)), fmt="v %.6f %.6f %.6f")
        for s in range(0, nf, 1_000_000):
            m = min(1_000_000, nf - s)
            np.savetxt(f, rng.integers(1, nv + 1, (m, 3)), fmt="f %d %d %d")


# --------------------------------------------------------------------------- children
CHILD = r'''
import json, pickle, resource, sys, time, tracemalloc
from bake import config as config_mod, pipeline, stages
from bake.scene import Artefacts
args = json.loads(sys.argv[1])
cfg = config_mod.load(None, data=args["config"])
cfg.input.path = args["model"]
spec = next(s for s in stages.STAGES if s.name == args["stage"])
if args["input"]:
    with open(args["input"], "rb") as f:
        scene = pickle.load(f)
else:
    from bake.scene import Scene
    scene = Scene()
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
print(f"    {spec.name:<12} running on {scene.n_triangles or scene.n_polygons} faces ...", file=sys.stderr, flush=True)
tracemalloc.start()
t = time.perf_counter()
scene, rec = spec.load()(scene, spec.section_of(cfg))
seconds = time.perf_counter() - t
traced = tracemalloc.get_traced_memory()[1]
tracemalloc.stop()
if args["output"]:
    with open(args["output"], "wb") as f:  # the next stage's input (artefacts hold callables)
        pickle.dump(scene.replace(artefacts=Artefacts()), f, protocol=5)
print(json.dumps({"stage": rec.name, "seconds": seconds, "counts_in": rec.counts_in,
                  "counts_out": rec.counts_out or pipeline.counts(scene),
                  "maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, "input_loaded_kb": base,
                  "traced_peak_bytes": traced, "warnings": rec.warnings[:3], "accuracy": rec.accuracy}))
'''

PARSE_CHILD = r'''
import json, resource, sys, time
from pathlib import Path
from bake.config import ImportJob
from bake.importers.obj import load
base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
t = time.perf_counter()
scene, rec = load(ImportJob(path=Path(sys.argv[1])))
print(json.dumps({"seconds": time.perf_counter() - t, "vertices": scene.n_vertices, "polygons": scene.n_polygons,
                  "maxrss_kb": resource.getrusage(resource.RUSAGE_SELF).ru_maxrss, "baseline_kb": base}))
'''


def run_child(code: str, arg: str, timeout: float) -> dict:
    t = time.perf_counter()
    p = subprocess.run([sys.executable, "-c", code, arg], capture_output=False, stdout=subprocess.PIPE,
                       text=True, timeout=timeout)
    wall = time.perf_counter() - t
    if p.returncode != 0:
        return {"error": f"exit {p.returncode}", "wall_seconds": wall}
    out = json.loads(p.stdout.strip().splitlines()[-1])
    out["wall_seconds"] = wall
    return out


def stage_config(simplify_to: int | None, ao: bool = True, bsp: bool = True, bvh: bool = True) -> dict:
    cfg: dict = {"export": {"enabled": False}, "bvh": {"enabled": bvh}, "bsp": {"enabled": bsp}}
    if simplify_to:
        cfg["mesh"] = {"simplify": {"enabled": True, "target_triangles": simplify_to}}
    if ao:
        cfg["lighting"] = {"enabled": True, "ao": {"enabled": True, "samples": AO_SAMPLES}, "ambient": [1.0, 1.0, 1.0]}
    return cfg


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--triangles", type=int, default=1_000_000)
    ap.add_argument("--materials", type=int, default=100)
    ap.add_argument("--simplify-to", type=int, default=5000)
    ap.add_argument("--obj-lines", type=int, default=10_000_000)
    ap.add_argument("--skip-full", action="store_true", help="no BVH/AO on the unsimplified mesh")
    ap.add_argument("--timeout", type=float, default=3600)
    ap.add_argument("--workdir", type=Path, default=None)
    ap.add_argument("--quick", action="store_true", help="100k triangles, 1M lines (a smoke run)")
    ap.add_argument("--parse-only", action="store_true",
                    help="only part 3 (the OBJ parser); keeps the other results in the output file")
    ap.add_argument("--out", type=Path, default=OUT)
    ap.add_argument("--derive", action="store_true", help="only recompute the derived figures of --out")
    a = ap.parse_args()
    if a.derive:
        a.out.write_text(json.dumps(derive(json.loads(a.out.read_text())), indent=2) + "\n")
        print(f"derived figures written to {a.out}")
        return
    if a.quick:
        a.triangles, a.obj_lines = 100_000, 1_000_000
    work = a.workdir or Path(tempfile.mkdtemp(prefix="bake-scale-"))
    work.mkdir(parents=True, exist_ok=True)
    doc: dict = {"benchmark": "scale", "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                                                   "loadavg_1min_before": os.getloadavg()[0]},
                 "target_peak_gb": 4.0}

    if a.parse_only:
        doc = json.loads(a.out.read_text()) if a.out.is_file() else doc
        doc["obj_parse_machine"] = {"python": platform.python_version(), "cpus": os.cpu_count(),
                                    "loadavg_1min_before": os.getloadavg()[0]}
        parse_part(a, work, doc)
        doc["obj_parse_machine"]["loadavg_1min_after"] = os.getloadavg()[0]
        a.out.parent.mkdir(parents=True, exist_ok=True)
        a.out.write_text(json.dumps(derive(doc), indent=2) + "\n")
        print(f"wrote {a.out} (obj_parse only)")
        return

    # ---- part 1: the pipeline, one child per stage
    t = time.perf_counter()
    model = write_model(work, a.triangles, a.materials)
    doc["model"] = {"triangles_requested": a.triangles, "materials": a.materials, "file_bytes": model.stat().st_size,
                    "write_seconds": round(time.perf_counter() - t, 2)}
    print(f"model: {model} ({model.stat().st_size / 1e6:.0f} MB), {a.materials} materials", flush=True)
    stages = ["import", "transform", "triangulate", "clean", "simplify", "lighting", "bsp", "bvh"]

    def chain(names, cfg, tag):
        rows, prev = [], ""
        for st in names:
            nxt = str(work / f"{tag}-{st}.pkl")
            r = run_child(CHILD, json.dumps({"config": cfg, "model": str(model), "stage": st, "input": prev,
                                             "output": nxt}), a.timeout)
            rows.append(r)
            if "error" in r:
                print(f"   {st}: FAILED ({r['error']})", flush=True)
                break
            print(f"   {st:<12} {r['seconds']:8.2f} s  peak RSS {r['maxrss_kb'] / 1024 ** 2:5.2f} GB "
                  f"(input loaded: {r['input_loaded_kb'] / 1024 ** 2:.2f} GB; numpy/Python peak in the stage "
                  f"{r['traced_peak_bytes'] / GB:.2f} GB)  out {r['counts_out']}", flush=True)
            if prev:
                Path(prev).unlink()
            prev = nxt
        if prev and Path(prev).exists():
            Path(prev).unlink()
        return rows

    # the stage's config: export off (the lists of a 1M-triangle model are not the subject)
    print("== pipeline (each stage in its own process, fed the previous stage's scene)", flush=True)
    doc["pipeline"] = chain(stages, stage_config(a.simplify_to), "p")

    # ---- part 2: the size-dependent stages on the full mesh
    if not a.skip_full:
        print("== full size: BVH and AO without simplification", flush=True)
        doc["full_size"] = chain(["import", "transform", "triangulate", "clean", "lighting", "bvh"],
                                 stage_config(None, ao=True, bsp=False, bvh=True), "f")

    parse_part(a, work, doc)
    doc["machine"]["loadavg_1min_after"] = os.getloadavg()[0]
    doc["self_maxrss_kb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(derive(doc), indent=2) + "\n")
    print(f"wrote {a.out}")


def _note(r: dict) -> str:
    """What a stage row's table says besides seconds and memory: what came out."""
    c, acc = r.get("counts_out") or {}, r.get("accuracy") or {}
    st = r.get("stage", "")
    if "error" in r:
        return f"failed: {r['error']}"
    if st in ("import", "transform") and c.get("polygons") and not c.get("triangles"):
        return f"{c['polygons']:,} polygons"
    parts = [f"{c.get('triangles', 0):,} triangles"]
    if st == "simplify" and "hausdorff_max" in acc:
        parts.append(f"Hausdorff max {100 * acc['hausdorff_max']:.3g}% of the diagonal (sampled)")
    if st == "bsp" and "bsp_records" in c:
        parts.append(f"{c['bsp_records']:,} records")
    if st == "bvh" and "bvh_nodes" in c:
        parts.append(f"{c['bvh_nodes']:,} nodes, {c.get('bvh_list_items', 0):,} list items")
    if st == "lighting":
        parts.append(f"{c.get('vertices', 0):,} vertices x {AO_SAMPLES} rays")
    return ", ".join(parts)


def derive(doc: dict) -> dict:
    """The figures the docs' tables show, from the measured ones (tools/doc_tables.py formats,
    it does not compute): peak RSS in GB, a note per stage, the parser's file size in MB."""
    for part in ("pipeline", "full_size"):
        for r in doc.get(part) or []:
            if "maxrss_kb" in r:
                r["peak_rss_gb"] = round(r["maxrss_kb"] / 1024 ** 2, 2)
            r["note"] = _note(r)
    for r in doc.get("obj_parse") or []:
        if "maxrss_kb" in r:
            r["peak_rss_gb"] = round(r["maxrss_kb"] / 1024 ** 2, 2)
        r["file_mb"] = round(r.get("file_bytes", 0) / 1e6)
    return doc


def parse_part(a: argparse.Namespace, work: Path, doc: dict) -> None:
    """Part 3: the OBJ parser on a 1/10 file and the full ``--obj-lines`` file."""
    parse = []
    for lines in (a.obj_lines // 10, a.obj_lines):
        path = work / f"lines{lines}.obj"
        t = time.perf_counter()
        write_obj_lines(path, lines)
        size = path.stat().st_size
        print(f"== parse {lines:,} lines ({size / 1e6:.0f} MB, written in {time.perf_counter() - t:.0f} s)", flush=True)
        r = run_child(PARSE_CHILD, str(path), a.timeout)
        r.update({"lines": lines, "file_bytes": size})
        if "error" not in r:
            r["peak_over_file"] = round(r["maxrss_kb"] * 1024 / size, 2)
            r["growth_over_file"] = round((r["maxrss_kb"] - r["baseline_kb"]) * 1024 / size, 2)
            print(f"   {r['seconds']:.1f} s, peak RSS {r['maxrss_kb'] / 1024 ** 2:.2f} GB = "
                  f"{r['peak_over_file']}x the file ({r['growth_over_file']}x above the interpreter's "
                  f"{r['baseline_kb'] / 1024:.0f} MB)", flush=True)
        parse.append(r)
        path.unlink()
    doc["obj_parse"] = parse


if __name__ == "__main__":
    main()
