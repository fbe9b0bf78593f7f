"""The simplify stage on corpus models where it used to waste its time, side by side with the
stage of another commit.

    .venv/bin/python benchmarks/bench_simplify_cases.py [--before GIT_REF (default b00b62d)] [--out benchmarks/results/simplify_cases.json]

Each case runs the stage of this tree and the stage of ``GIT_REF`` (a ``git archive`` of its
bake/, in a subprocess: bench_simplify.Before) in turn, each run of one between runs of the
other, so both see the same load; best of ``repeat`` runs each. Cases:

* models that cannot lose a triangle (a box) or whose simplified error is rounding-sized (a flat
  cube cut into 48 triangles): nothing for the refine and peak rounds to do;
* models that back off (the house, whose every collapse costs flips or new non-manifold
  edges; glTF triangle strips with coincident sheets);
* a soup of big overlapping triangles (the subpass scene), where the flip check's second opinion
  paired every suspect with every big triangle;
* the bunny to 2,000 and Suzanne to 300 triangles as controls (the speed rows of
  bench_simplify.py).

Writes, per case: seconds now and before, their ratio, the triangles out, the reported max, and
whether both stages gave the same mesh (positions and triangles equal).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

CASES = [  # (label, corpus file, stage options, repeat)
    ("box (12)", "box_draco_glb/Box.glb", {"target_ratio": 0.5}, 3),
    ("cube cut in 48", "cube_vertex_colors_glb/cubevc.glb", {"target_ratio": 0.5}, 3),
    ("alpha-blend cards (61)", "alpha_blend_mode_test/AlphaBlendModeTest.glb", {"target_ratio": 0.5}, 3),
    ("house (2,706)", "house_max2obj_walls/regr01.obj", {"target_ratio": 0.5}, 2),
    ("triangle strips (2,786)", "triangle_strips_scene/mode5.gltf", {"target_ratio": 0.5}, 1),
    ("subpass soup (19,220)", "subpass_scene/subpass_scene_opaque.gltf", {"target_ratio": 0.5}, 1),
    ("suzanne (968)", "suzanne_obj/suzanne.obj", {"target_triangles": 300}, 3),
    ("bunny (69,451)", "stanford_bunny_res1_obj/stanford-bunny.obj", {"target_triangles": 2000}, 3),
]


def main(argv: list[str] | None = None) -> int:
    import bench_simplify as B

    ap = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    # (`make bench` runs every benchmark without arguments: the default is the commit the cases
    # were found on, the one docs/simplify.md's table compares with)
    ap.add_argument("--before", default="b00b62d", help="the git ref whose stage runs beside this tree's")
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "simplify_cases.json"))
    args = ap.parse_args(argv)
    rows = []
    with tempfile.TemporaryDirectory() as td:
        before = B.Before(args.before, Path(td))
        for label, rel, cfg, repeat in CASES:
            path = B.CORPUS / rel
            if not path.exists():
                print(f"skip {label}: {path} is not there")
                continue
            scene = B.load(path, None)
            now, old = [], []
            for _ in range(repeat):  # alternate: the same load for both
                out, rec, sec = B.run_stage(scene, **cfg)
                now.append(sec)
                res, arr = before.run(path, None, cfg, repeat=1)
                old.append(res["stage_seconds"])
            same = bool(np.array_equal(arr["Vb"], out.positions) and np.array_equal(arr["Fb"], out.triangles))
            target = f"{cfg['target_ratio']:.0%}" if "target_ratio" in cfg else f"{cfg['target_triangles']:,}"
            row = {"case": label, "file": rel, "config": cfg, "target": target, "repeat": repeat,
                   "triangles_in": int(scene.n_triangles), "triangles_out": int(out.n_triangles),
                   "triangles_out_before": int(res["triangles_out"]),
                   "seconds": round(min(now), 3), "seconds_before": round(min(old), 3),
                   "speedup": round(min(old) / min(now), 2),
                   "reported_max": rec.accuracy.get("hausdorff_max"), "reported_max_before": res["reported_max"],
                   "same_mesh": same,
                   "phase_seconds": {k[:-8]: rec.details.get(k) for k in rec.details
                                     if k.endswith("_seconds") and isinstance(rec.details.get(k), float)}}
            rows.append(row)
            print(f"{label}: {row['seconds']:.3f}s, before {row['seconds_before']:.3f}s ({row['speedup']}x), "
                  f"{row['triangles_out']} triangles, same mesh: {same}", flush=True)
        ref = before.ref
    default_out = Path(ap.get_default("out")).resolve()
    command = "benchmarks/bench_simplify_cases.py --before " + args.before
    if Path(args.out).resolve() != default_out:
        command += " --out " + os.path.relpath(Path(args.out).resolve(), REPO)
    result = {"command": command, "before": ref,
              "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                          "load_average": list(os.getloadavg())},
              "date": time.strftime("%Y-%m-%d"), "rows": rows}
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    tmp = Path(args.out).with_suffix(".tmp")
    tmp.write_text(json.dumps(result, indent=1) + "\n")
    tmp.replace(args.out)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
