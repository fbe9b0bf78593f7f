"""BVH figures: SAH, nodes, build time, list sizes, items read per ray, and the 100k-ray proof.

    .venv/bin/python benchmarks/bench_bvh.py [--rays 100000] [--brute-pairs 6e8] [--quick]

For teapot, spot, duck, the house (regr01.obj), the multi-object subpass scene, the 69k bunny
and the teapot moved by 1e5:

* build: binned (leaf 4, 8 bins) and quality = "high", run alternately, best of ``--repeat``
  (wall and CPU seconds; the machine is shared, so compare the ratio, not the absolute time);
* lists per layout (binary, wide4, quantised 6 bits): items, project.json bytes, per node;
* rays (``--rays`` per model, from ``bake.bvh.verify.make_rays``: outside, inside, exactly at
  edges and vertices, in-plane grazing, axis-aligned): mean list items read per ray by the
  reference traversal of each layout; every layout's closest t must be identical (so the
  quantised layout never misses a hit of the float ones); Embree agreement on all rays; exact
  equality with brute force on as many rays as ``--brute-pairs`` ray-triangle pairs allow;
* sweeps: bins 4/8/16/32 x leaf sizes 1/2/4/8 (SAH, build time, items read per ray with the
  quantised layout on 20k rays) and quantisation bits 3..8 (bytes per node, items read).

Writes ``benchmarks/results/bvh.json`` and prints markdown tables.
"""

from __future__ import annotations

import argparse
import io
import json
import os
import platform
import sys
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bake.bvh import build as B  # noqa: E402
from bake.bvh.encode import encode, outward, sizes  # noqa: E402
from bake.bvh.stage import prepare  # noqa: E402
from bake.bvh.traverse import brute_force, trace  # noqa: E402
from bake.bvh.verify import compare_embree, make_rays  # noqa: E402
from bake.scene import make_scene  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "bvh.json"
MODELS = [
    ("teapot", "teapot_obj/teapot.obj"),
    ("spot", "spot_triangulated/spot/spot_triangulated.obj"),
    ("duck", "duck_glb/Duck.glb"),
    ("house", "house_max2obj_walls/regr01.obj"),
    ("subpass", "subpass_scene/subpass_scene_opaque.gltf"),
    ("bunny", "stanford_bunny_res1_obj/stanford-bunny.obj"),
]
LAYOUTS = ("binary", "wide4", "quantised")


def load(rel: str):
    import trimesh

    p = CORPUS / rel
    if rel.endswith("regr01.obj"):
        text = p.read_text(encoding="latin-1")
        m = trimesh.load(io.BytesIO(text.encode()), file_type="obj", process=False, force="mesh")
    else:
        m = trimesh.load(str(p), process=False, force="mesh")
    return make_scene(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))


def timed(fn):
    w, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - w, time.process_time() - c


def model_figures(name, scene, a) -> dict:
    tq, keep, d, pad = prepare(scene, 5)
    lo, hi = tq[keep].min(1), tq[keep].max(1)
    res: dict = {"triangles": scene.n_triangles, "kept": int(len(keep)), "decimals": d}
    best = {}
    for _ in range(a.repeat):  # alternate the builders, keep the best of each
        for q in ("binned", "high"):
            if q == "high" and a.quick:
                continue
            bvh, w, c = timed(lambda: B.build(lo, hi, leaf_size=4, bins=8, quality=q,
                                              high_effort=a.high_effort, ids=keep))
            if q not in best or w < best[q][1]:
                best[q] = (bvh, w, c)
    for q, (bvh, w, c) in best.items():
        wlo, whi = outward(bvh.lo, bvh.hi, d, pad)
        res[q] = {"sah": B.sah_cost(bvh), "sah_written": B.sah_cost(bvh, lo=wlo, hi=whi),
                  "nodes": bvh.n_nodes, "leaves": bvh.n_leaves,
                  "depth": bvh.depth(), "build_wall_s": w, "build_cpu_s": c,
                  "info": {k: v for k, v in bvh.info.items() if isinstance(v, (int, float, str))}}
    if "high" in res:
        res["high"]["sah_vs_binned"] = res["high"]["sah"] / res["binned"]["sah"] - 1
    bvh = best["binned"][0]
    ids = np.arange(1, scene.n_triangles + 1)
    o, dd, kinds = make_rays(tq[keep], a.rays, seed=1)
    res["rays"] = {"count": int(len(o)), "kinds": kinds}
    ts = {}
    for lay in LAYOUTS:
        enc, w, _ = timed(lambda: encode(bvh, tq, ids, lay, d=d, pad=pad, bits=6))
        h, tw, _ = timed(lambda: trace(enc, o, dd))
        ts[lay] = h
        res[lay] = {**sizes(enc), "encode_s": w, "trace_s": tw,
                    "reads_per_ray": float(h.reads.mean()), "reads_p99": float(np.percentile(h.reads, 99)),
                    "boxes_per_ray": float(h.boxes.mean()), "tri_tests_per_ray": float(h.tests.mean()),
                    "hit_rate": float(h.hit.mean()), "record_depth": enc.info.get("record_depth"),
                    "stack_max": int(h.stack.max()) if lay != "binary" and len(h.stack) else 0}
    t0 = ts["binary"].t
    res["layouts_identical_t"] = all(np.array_equal(t0, ts[k].t) for k in LAYOUTS)
    res["quantised_misses_float_hit"] = int((np.isfinite(ts["wide4"].t) & ~np.isfinite(ts["quantised"].t)).sum())
    # Embree on every ray (scene triangle numbers index tq)
    tri_of = np.where(ts["binary"].tri > 0, ts["binary"].tri - 1, -1)
    res["embree"] = compare_embree(tq, o, dd, t0, tri_of, scale=scene.scale())
    # brute force (same arithmetic) on as many rays as the pair budget allows
    nb = int(min(len(o), max(1000, a.brute_pairs // max(len(keep), 1))))
    sub = np.linspace(0, len(o) - 1, nb).astype(np.int64)
    (bt, bi, _, _), w, _ = timed(lambda: brute_force(tq[keep], o[sub], dd[sub]))
    res["brute"] = {"rays": nb, "seconds": w, "t_equal": bool(np.array_equal(bt, t0[sub])),
                    "hits": int(np.isfinite(bt).sum())}
    return res


def sweep(scene, a) -> list:
    tq, keep, d, pad = prepare(scene, 5)
    lo, hi = tq[keep].min(1), tq[keep].max(1)
    o, dd, _ = make_rays(tq[keep], a.sweep_rays, seed=2)
    ids = np.arange(1, scene.n_triangles + 1)
    rows = []
    for bins in (4, 8, 16, 32):
        for leaf in (1, 2, 4, 8):
            bvh, w, c = timed(lambda: B.build(lo, hi, leaf_size=leaf, bins=bins, ids=keep))
            enc = encode(bvh, tq, ids, "quantised", d=d, pad=pad, bits=6)
            h = trace(enc, o, dd)
            rows.append({"bins": bins, "leaf_size": leaf, "sah": B.sah_cost(bvh), "nodes": bvh.n_nodes,
                         "build_wall_s": w, "build_cpu_s": c, "quantised_reads_per_ray": float(h.reads.mean()),
                         "bytes": sizes(enc)["bytes"]})
    return rows


def bits_sweep(scene, a) -> list:
    tq, keep, d, pad = prepare(scene, 5)
    lo, hi = tq[keep].min(1), tq[keep].max(1)
    bvh = B.build(lo, hi, ids=keep)
    o, dd, _ = make_rays(tq[keep], a.sweep_rays, seed=3)
    ids = np.arange(1, scene.n_triangles + 1)
    rows = []
    for bits in (3, 4, 5, 6, 7, 8):
        enc = encode(bvh, tq, ids, "quantised", d=d, pad=pad, bits=bits)
        h = trace(enc, o, dd)
        s = sizes(enc)
        rows.append({"bits": bits, "bytes_per_node": s["bytes_per_node"], "node_bytes": s["node_bytes"],
                     "reads_per_ray": float(h.reads.mean()), "boxes_per_ray": float(h.boxes.mean()),
                     "tri_tests_per_ray": float(h.tests.mean()),
                     "area_growth": enc.info.get("area_growth_mean")})
    return rows


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--rays", type=int, default=100_000)
    ap.add_argument("--sweep-rays", type=int, default=20_000)
    ap.add_argument("--brute-pairs", type=float, default=6e8)
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--high-effort", type=float, default=10.0)
    ap.add_argument("--quick", action="store_true", help="no high-quality builds, no sweeps")
    ap.add_argument("--only", nargs="*", help="model names")
    a = ap.parse_args()
    out = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                       "loadavg_start": os.getloadavg()},
           "args": vars(a), "models": {}, "sweeps": {}, "bits": {}}
    t_all = time.perf_counter()
    scenes = {}
    for name, rel in MODELS:
        if a.only and name not in a.only:
            continue
        scenes[name] = load(rel)
    if "teapot" in scenes and (not a.only or "teapot+1e5" in a.only or "teapot" in a.only):
        t = scenes["teapot"]
        scenes["teapot+1e5"] = t.replace(positions=t.positions + 1e5)
    for name, sc in scenes.items():
        print(f"[{name}] {sc.n_triangles} triangles", flush=True)
        out["models"][name] = model_figures(name, sc, a)
        OUT.parent.mkdir(parents=True, exist_ok=True)
        OUT.write_text(json.dumps(out, indent=1, default=float))
    if not a.quick:
        for name in ("teapot", "bunny"):
            if name in scenes:
                print(f"[sweep {name}]", flush=True)
                out["sweeps"][name] = sweep(scenes[name], a)
                out["bits"][name] = bits_sweep(scenes[name], a)
                OUT.write_text(json.dumps(out, indent=1, default=float))
    out["machine"]["loadavg_end"] = os.getloadavg()
    out["seconds"] = time.perf_counter() - t_all
    OUT.write_text(json.dumps(out, indent=1, default=float))
    report(out)


def report(out) -> None:
    print("\n| model | tris | SAH binned | SAH high (vs binned) | nodes | build s wall/cpu (high) |"
          " bytes/node bin / w4 / q | items read/ray bin / w4 / q | Embree agree (unexplained) | brute rays, t equal |")
    print("|---|---|---|---|---|---|---|---|---|---|")
    for n, r in out["models"].items():
        hb = r.get("high")
        high = f"{hb['sah']:.2f} ({100 * hb['sah_vs_binned']:+.1f}%)" if hb else "-"
        ht = f" ({hb['build_wall_s']:.1f})" if hb else ""
        print(f"| {n} | {r['triangles']} | {r['binned']['sah']:.2f} | {high} | {r['binned']['nodes']} | "
              f"{r['binned']['build_wall_s']:.2f}/{r['binned']['build_cpu_s']:.2f}{ht} | "
              f"{r['binary']['bytes_per_node']:.1f} / {r['wide4']['bytes_per_node']:.1f} / {r['quantised']['bytes_per_node']:.1f} | "
              f"{r['binary']['reads_per_ray']:.0f} / {r['wide4']['reads_per_ray']:.0f} / {r['quantised']['reads_per_ray']:.0f} | "
              f"{r['embree']['agree']}/{r['embree']['rays']} ({r['embree']['unexplained']}) | "
              f"{r['brute']['rays']}, {r['brute']['t_equal']} |")
    for n, rows in out["sweeps"].items():
        print(f"\n{n}: bins x leaf size -> SAH / build s / quantised items read per ray")
        for row in rows:
            print(f"  bins {row['bins']:2d} leaf {row['leaf_size']}: SAH {row['sah']:.2f}  "
                  f"{row['build_wall_s']:.2f}s  reads {row['quantised_reads_per_ray']:.0f}")
    for n, rows in out["bits"].items():
        print(f"\n{n}: quantisation bits -> bytes/node, items read per ray")
        for row in rows:
            print(f"  {row['bits']} bits: {row['bytes_per_node']:.1f} B/node  reads {row['reads_per_ray']:.0f}")


if __name__ == "__main__":
    main()
