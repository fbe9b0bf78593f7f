"""Simplify's worst case: soups of disjoint triangles, where its checks cost the most.

    .venv/bin/python benchmarks/bench_simplify_soup.py [--sizes 3000,10000] [--ratio 0.5]

Two kinds of soup, each simplified by the stage with its defaults, in a subprocess of its own
(so peak RSS is the stage's):

* ``soup``: random triangles with corners anywhere in the unit cube. Every triangle is large and
  passes near every other, so the closest-triangle queries behind the Hausdorff error and the
  flip checks are quadratic in the count; the stage bounds their memory (ball queries in
  chunks) and their work (the max is verified within a pair budget, else reported as an upper
  bound). No real model looks like this; it is the upper end of what the stage costs.
* ``cards``: foliage-like cards (two-triangle quads 2% of the cube across, at random places
  and angles): disjoint like a soup, but small, as real unwelded content is.

Writes ``benchmarks/results/simplify_soup.json``: seconds, peak RSS, triangles out, whether
the max error is exact, the record's first warning.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parent.parent
OUT = REPO / "benchmarks" / "results" / "simplify_soup.json"

CHILD = r'''
import json, resource, sys, time
import numpy as np
from bake.config import SimplifyConfig
from bake.mesh.simplify import stage as S
from bake.scene import make_scene
kind, n, ratio = sys.argv[1], int(sys.argv[2]), float(sys.argv[3])
rng = np.random.default_rng(0)
if kind == "soup":
    V = rng.random((3 * n, 3))
    F = np.arange(3 * n).reshape(-1, 3)
else:
    q = n // 2
    c, u, w = rng.random((q, 1, 3)), rng.normal(size=(q, 1, 3)), rng.normal(size=(q, 1, 3))
    s = 0.02
    V = np.concatenate([c, c + s * u, c + s * (u + w), c + s * w], axis=1).reshape(-1, 3)
    b = 4 * np.arange(q)[:, None]
    F = np.concatenate([b + [0, 1, 2], b + [0, 2, 3]], axis=1).reshape(-1, 3)
scene = make_scene(V, F)
t = time.perf_counter()
out, rec = S.stage(scene, SimplifyConfig(enabled=True, target_ratio=ratio))
print(json.dumps({"kind": kind, "triangles_in": int(len(F)), "triangles_out": out.n_triangles,
                  "seconds": round(time.perf_counter() - t, 3),
                  "peak_rss_gb": round(resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 2**20, 3),
                  "hausdorff_max": rec.accuracy.get("hausdorff_max"),
                  "hausdorff_max_exact": rec.details.get("hausdorff_max_exact"),
                  "flipped_triangles": rec.accuracy.get("flipped_triangles"),
                  "warning": rec.warnings[0] if rec.warnings else None}))
'''


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--sizes", default="3000,10000", help="triangle counts (30000 takes ~5 min for the soup)")
    ap.add_argument("--kinds", default="soup,cards")
    ap.add_argument("--ratio", type=float, default=0.5)
    ap.add_argument("--out", type=Path, default=OUT)
    a = ap.parse_args(argv)
    rows = []
    for kind in a.kinds.split(","):
        for n in (int(x) for x in a.sizes.split(",")):
            p = subprocess.run([sys.executable, "-c", CHILD, kind, str(n), str(a.ratio)], capture_output=True,
                               text=True, cwd=REPO)
            if p.returncode != 0:
                rows.append({"kind": kind, "triangles_in": n, "error": p.stderr.strip().splitlines()[-1:]})
            else:
                rows.append(json.loads(p.stdout.strip().splitlines()[-1]))
            r = rows[-1]
            print(f"{kind:6s} {n:7d} -> {r.get('triangles_out', '-')!s:>7}  {r.get('seconds', '-')!s:>8} s  "
                  f"{r.get('peak_rss_gb', '-')!s:>6} GB  exact max {r.get('hausdorff_max_exact')}  "
                  f"{r.get('warning') or r.get('error') or ''}", flush=True)
    doc = {"benchmark": "simplify_soup", "command": "benchmarks/bench_simplify_soup.py " + " ".join(
        argv if argv is not None else sys.argv[1:]), "machine": {
        "platform": platform.platform(), "cpus": os.cpu_count(), "load_average": os.getloadavg()}, "rows": rows}
    a.out.parent.mkdir(parents=True, exist_ok=True)
    a.out.write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {a.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
