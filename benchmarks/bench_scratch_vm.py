"""What the reader blocks cost in the real Scratch VM: blocks executed per frame and per ray.

    .venv/bin/python benchmarks/bench_scratch_vm.py [--grid 16x12] [--quick]

For teapot, spot and duck (baked by the real pipeline, BSP and BVH on), the reader sprite the bake writes
is run headless in scratch-vm 5.0.300 (vm/run.js, Node), which counts every block it executes
(each call of a block's function: a loop block once per iteration, a reporter once per
evaluation, variable reporters included; typed-in literals are not blocks):

* BVH query (``bvh ray``) for each layout (binary, wide4, quantised 6 bits) over the primary rays
  of a ``--grid`` pinhole camera over the model's box on the stage (what a ray tracer casts per
  pixel): blocks
  per ray (mean / median / p95 / max), hit rate, VM milliseconds per ray, and the list items the
  Python reference reads per ray; every ray's hit is also checked against the reference;
* a frame of the pen renderer (``render``: project every vertex, fill every triangle with
  scanlines) from the bake's camera, and ``project vertices`` alone;
* the BSP walk (``bsp walk``) per frame, from the bake's camera and five other eyes (one inside
  the model's box), each order checked against ``bake.bsp.traverse.draw_order``;
* ``decode textimage`` of a photo texture (capsule0.jpg) at 64x64: blocks per pixel.

Vanilla Scratch runs a few million blocks per second (shared/docs/scratch.md section 5), so
blocks / 2-4 M is roughly the seconds a frame or ray costs there; TurboWarp's compiler is
30-50x faster. Writes ``benchmarks/results/scratch_vm.json`` and prints markdown tables.
"""

from __future__ import annotations

import argparse
import dataclasses
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

from bake import config, pipeline  # noqa: E402
from bake.bsp.traverse import draw_ranges  # noqa: E402
from bake.bvh.traverse import trace_one  # noqa: E402
from bake.scratch import sb3  # noqa: E402
from bake.scratch import readers  # noqa: E402
from bake.scratch.project import reader_spec  # noqa: E402
from bake.scratch import textimage  # noqa: E402
from bake.textures import images  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "scratch_vm.json"
MODELS = [
    ("teapot", "teapot_obj/teapot.obj"),
    ("spot", "spot_triangulated/spot/spot_triangulated.obj"),
    ("duck", "duck_glb/Duck.glb"),
]
LAYOUTS = (("binary", 6), ("wide4", 6), ("quantised", 6))


def bake(path: Path, layout: str, bits: int):
    cfg = config.load(data={"input": {"path": str(path)}, "bsp": {"enabled": True},
                            "bvh": {"enabled": True, "layout": layout, "quant_bits": bits}})
    return pipeline.run(cfg)


def lists_of(data: bytes) -> dict[str, list]:
    project, _ = sb3.load_project(data)
    return {n: items for t in project["targets"] for n, items in (t.get("lists") or {}).values()}


def camera_rays(cam: readers.Camera, w: int, h: int, verts) -> list[tuple[list[float], list[float]]]:
    """Primary rays of the reader camera through a w x h grid over the model's box on the stage
    (a ray tracer frames its model; rays that cannot hit anything cost the same ~180 blocks)."""
    px, py, _ = readers.project(np.asarray(verts, np.float64), cam)
    left, right = max(float(px.min()), -240.0), min(float(px.max()), 240.0)
    bottom, top = max(float(py.min()), -180.0), min(float(py.max()), 180.0)
    sy, cy = readers.scratch_sin(cam.yaw), readers.scratch_cos(cam.yaw)
    sp, cp = readers.scratch_sin(cam.pitch), readers.scratch_cos(cam.pitch)
    out = []
    for j in range(h):
        for i in range(w):
            x = left + (i + 0.5) / w * (right - left)
            y = top - (j + 0.5) / h * (top - bottom)
            # camera space (x, y, focal) -> world: undo pitch, then yaw (inverse of readers.project)
            cx, cyy, cz = x, y, cam.focal
            y1 = cyy * cp + cz * sp
            z1 = -cyy * sp + cz * cp
            dx = cx * cy + z1 * sy
            dz = -cx * sy + z1 * cy
            out.append(([cam.x, cam.y, cam.z], [dx, y1, dz]))
    return out


def bsp_eyes(verts, cam: readers.Camera) -> list[list[float]]:
    """The bake's camera plus five eyes around the model (one inside its box)."""
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    c, diag = (v.min(0) + v.max(0)) / 2, float(np.linalg.norm(v.max(0) - v.min(0)))
    offs = ([0, 0.3, -1.2], [1.1, 0.2, 0.4], [-0.8, 0.9, 0.6], [0.2, -1.0, -0.3], [0.02, 0.01, 0.0])
    return [[cam.x, cam.y, cam.z]] + [[float(x) for x in c + np.array(o) * diag] for o in offs]


def run_vm(plan: dict) -> dict:
    r = subprocess.run(["node", str(REPO / "vm" / "run.js"), "--plan", "-"], input=json.dumps(plan),
                       capture_output=True, text=True, timeout=3600)
    if not r.stdout.strip():
        raise SystemExit(f"vm/run.js failed: {r.stderr[-2000:]}")
    out = json.loads(r.stdout)
    for job in out.get("jobs", [out]):
        if job.get("error"):
            raise SystemExit(f"vm/run.js failed: {job['error']}")
    return out


def stats(values: list[float]) -> dict:
    a = np.asarray(values, np.float64)
    return {"mean": float(a.mean()), "median": float(np.median(a)), "p95": float(np.percentile(a, 95)),
            "max": float(a.max())}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--grid", default="16x12", help="camera rays per model and layout, WxH")
    ap.add_argument("--quick", action="store_true", help="8x6 rays, one model")
    args = ap.parse_args()
    gw, gh = (8, 6) if args.quick else map(int, args.grid.lower().split("x"))
    models = MODELS[:1] if args.quick else MODELS
    tmp = Path(tempfile.mkdtemp(prefix="bench-scratch-"))
    jobs, meta = [], []
    t0 = time.perf_counter()
    for name, rel in models:
        path = CORPUS / rel
        if not path.exists():
            print(f"skip {name}: {path} not found", file=sys.stderr)
            continue
        for layout, bits in LAYOUTS:
            res = bake(path, layout, bits)
            files = res.scene.artefacts.outputs
            sb3_name = next(n for n in files if n.endswith(".sb3"))
            p = tmp / f"{name}-{layout}.sb3"
            p.write_bytes(files[sb3_name])
            lists = lists_of(files[sb3_name])
            spec = reader_spec(res.scene, res.config.export, lists)
            cam = spec.camera
            rays = camera_rays(cam, gw, gh, lists[spec.mesh.verts])
            runs = [{"call": {"target": "Mesh", "proccode": "bvh ray %s %s %s %s %s %s",
                              "args": [repr(float(x)) for x in o + d]},
                     "read": {"variables": ["hit tri", "hit t"]}} for o, d in rays]
            first = layout == LAYOUTS[0][0]
            eyes = []
            if first:
                runs.append({"call": {"target": "Mesh", "proccode": "project vertices", "args": []},
                             "read": {"variables": []}})
                runs.append({"call": {"target": "Mesh", "proccode": "render", "args": []},
                             "read": {"lists": ["draw ranges"]}, "pen": True})
                if spec.bsp is not None:
                    eyes = bsp_eyes(lists[spec.mesh.verts], cam)
                    runs += [{"set": {"target": "Mesh", "variables": {"cam x": e[0], "cam y": e[1], "cam z": e[2]}},
                              "call": {"target": "Mesh", "proccode": "bsp walk", "args": []},
                              "read": {"lists": ["draw ranges"]}} for e in eyes]
            jobs.append({"load": str(p), "runs": runs})
            enc = res.scene.artefacts.bvh.encoded
            enc = dataclasses.replace(enc, nodes=np.asarray(lists[spec.bvh.nodes], np.float64),
                                      tris=np.asarray(lists[spec.bvh.tris], np.float64),
                                      ids=np.asarray(lists[spec.bvh.ids], np.int64))  # as written
            ref = [trace_one(enc, o, d, tmax=readers.BIG) for o, d in rays]
            meta.append({"model": name, "layout": layout, "bits": bits if layout == "quantised" else None,
                         "triangles": res.scene.n_triangles, "vertices": res.scene.n_vertices,
                         "rays": len(rays), "ref": ref, "render": first, "eyes": eyes,
                         "bsp_ref": [[x for r in draw_ranges(lists[spec.bsp.nodes], lists[spec.bsp.planes], e)
                                      for x in r] for e in eyes] if eyes else [],
                         "bsp_items": (len(lists[spec.bsp.nodes]), len(lists[spec.bsp.planes])) if spec.bsp else None,
                         "bsp": res.scene.artefacts.bsp is not None,
                         "project_json_bytes": sb3.archive_sizes(files[sb3_name])["project_json_bytes"]})
    # TextImage: a photo texture at 64x64
    ti_runs = []
    cand = CORPUS / "capsule_textured" / "capsule0.jpg"
    if cand.exists():
        tex = images.prepare_texture(cand, size=(64, 64))
        text = textimage.encode(tex[:, :, :3])
        spec = readers.ReaderSpec(mesh=None, bvh=None, textimage=True)  # the decoder alone
        data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True), readers.reader_target(spec, "Reader")])
        p = tmp / "ti.sb3"
        p.write_bytes(data)
        jobs.append({"load": str(p), "runs": [{"call": {"target": "Reader", "proccode": "decode textimage %s",
                                                        "args": [text]}, "read": {"lists": ["ti colors"]}}]})
        ti_runs = [{"pixels": 64 * 64, "chars": len(text), "image": "capsule0.jpg at 64x64"}]
    prep = time.perf_counter() - t0
    t1 = time.perf_counter()
    out = run_vm({"jobs": jobs})["jobs"]
    vm_s = time.perf_counter() - t1

    results = {"machine": {"platform": platform.platform(), "python": platform.python_version(),
                           "cpus": os.cpu_count()},
               "versions": out[0]["versions"], "grid": [gw, gh], "bvh": [], "render": [], "bsp": [],
               "textimage": [], "seconds": {"prepare": prep, "vm": vm_s}}
    for m, job in zip(meta, out):
        runs = job["runs"]
        ray_runs = runs[:m["rays"]]
        mismatches = 0
        for (t, _slot, tri, _u, _v, _reads), r in zip(m["ref"], ray_runs):
            got = float(r["variables"]["hit tri"])
            if got != tri or (tri and r["variables"]["hit t"] != t):
                mismatches += 1
        results["bvh"].append({
            "model": m["model"], "layout": m["layout"], "bits": m["bits"], "triangles": m["triangles"],
            "rays": m["rays"], "hit_rate": float(np.mean([ref[2] > 0 for ref in m["ref"]])),
            "blocks_per_ray": stats([r["blocks"] for r in ray_runs]),
            "blocks_per_hit_ray": stats([r["blocks"] for r, ref in zip(ray_runs, m["ref"]) if ref[2] > 0] or [0]),
            "blocks_per_miss_ray": stats([r["blocks"] for r, ref in zip(ray_runs, m["ref"]) if ref[2] == 0] or [0]),
            "ms_per_ray": stats([r["ms"] for r in ray_runs]),
            "reference_items_read_per_ray": stats([ref[5] for ref in m["ref"]]),
            "mismatches_vs_reference": mismatches,
            "project_json_bytes": m["project_json_bytes"]})
        if m["eyes"]:
            walks = runs[m["rays"] + 2:]
            results["bsp"].append({
                "model": m["model"], "triangles": m["triangles"], "eyes": len(m["eyes"]),
                "node_items": m["bsp_items"][0], "plane_items": m["bsp_items"][1],
                "blocks_per_walk": stats([w["blocks"] for w in walks]),
                "ms_per_walk": stats([w["ms"] for w in walks]),
                "ranges_per_walk": stats([len(w["lists"]["draw ranges"]) // 2 for w in walks]),
                "mismatches_vs_reference": sum(int([int(x) for x in w["lists"]["draw ranges"]] != ref)
                                               for w, ref in zip(walks, m["bsp_ref"]))})
        if m["render"]:
            proj, frame = runs[m["rays"]], runs[m["rays"] + 1]
            results["render"].append({
                "model": m["model"], "triangles": m["triangles"], "vertices": m["vertices"],
                "project_vertices_blocks": proj["blocks"], "frame_blocks": frame["blocks"],
                "frame_ms": frame["ms"], "pen_strokes": len(frame.get("pen", [])),
                "ranges": len(frame["lists"]["draw ranges"]) // 2,
                "draw_order": "BSP walk" if m["bsp"] else "list order (no BSP in this bake)"})
    if ti_runs:
        r = out[-1]["runs"][0]
        ti_runs[0].update({"blocks": r["blocks"], "blocks_per_pixel": r["blocks"] / ti_runs[0]["pixels"],
                           "ms": r["ms"]})
        results["textimage"] = ti_runs

    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(results, indent=1))

    print(f"scratch-vm {results['versions']['scratch-vm']}, Node {results['versions']['node']}; "
          f"{gw}x{gh} camera rays per model and layout\n")
    print("| model | tris | layout | blocks/ray mean | p95 | max | mean, rays that hit | mean, misses | "
          "items read/ray | hit rate | ms/ray (vanilla VM) | mismatches |")
    print("|---|---|---|---|---|---|---|---|---|---|---|---|")
    for b in results["bvh"]:
        s = b["blocks_per_ray"]
        print(f"| {b['model']} | {b['triangles']} | {b['layout']} | {s['mean']:.0f} | "
              f"{s['p95']:.0f} | {s['max']:.0f} | {b['blocks_per_hit_ray']['mean']:.0f} | "
              f"{b['blocks_per_miss_ray']['mean']:.0f} | {b['reference_items_read_per_ray']['mean']:.0f} | "
              f"{b['hit_rate']:.2f} | {b['ms_per_ray']['mean']:.2f} | {b['mismatches_vs_reference']} |")
    print("\n| model | tris (after BSP splits) | BSP walk blocks/frame mean | max | ms/walk (vanilla VM) | "
          "ranges drawn | node + plane items | mismatches |")
    print("|---|---|---|---|---|---|---|---|")
    for b in results["bsp"]:
        print(f"| {b['model']} | {b['triangles']} | {b['blocks_per_walk']['mean']:.0f} | "
              f"{b['blocks_per_walk']['max']:.0f} | {b['ms_per_walk']['mean']:.0f} | "
              f"{b['ranges_per_walk']['mean']:.0f} | {b['node_items']} + {b['plane_items']} | "
              f"{b['mismatches_vs_reference']} |")
    print("\n| model | tris | verts | project vertices (blocks) | render frame (blocks) | frame ms (vanilla VM) | "
          "pen strokes | ranges | order |")
    print("|---|---|---|---|---|---|---|---|---|")
    for r in results["render"]:
        print(f"| {r['model']} | {r['triangles']} | {r['vertices']} | {r['project_vertices_blocks']} | "
              f"{r['frame_blocks']} | {r['frame_ms']:.0f} | {r['pen_strokes']} | {r['ranges']} | {r['draw_order']} |")
    for t in results["textimage"]:
        print(f"\nTextImage decode, {t['image']}: {t['blocks']} blocks ({t['blocks_per_pixel']:.1f} per pixel), "
              f"{t['ms']:.0f} ms")
    print(f"\nwrote {OUT.relative_to(REPO)} (prepare {prep:.1f} s, VM {vm_s:.1f} s)")


if __name__ == "__main__":
    main()
