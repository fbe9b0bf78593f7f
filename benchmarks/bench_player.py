"""The reader sprite in the players, side by side with the previous reader: bytes, blocks, seconds.

    .venv/bin/python benchmarks/bench_player.py [--repeat 100] [--base 6f0151f] [--models demo,teapot]

For each model (the bundled demo, and the Utah teapot lit by a sun and BSP-sorted), the same
input and config are baked twice in this run: by this checkout, and by the previous reader's code
(``--base``, default 6f0151f: the commit before issue 15; its ``bake/`` is exported with ``git
archive`` into a temporary folder and run from there, nothing of it is kept). For both .sb3:

* reader bytes: the reader sprite's blocks, variables and own lists in project.json (``bake
  check``: every item owned by the sprite);
* blocks per frame: blocks scratch-vm 5.0.300 executes from the green flag until every script
  stopped (vm/run.js), i.e. one frame of the demo's ``render``;
* TurboWarp seconds, compiled and interpreted, in TurboWarp's player in headless Chromium
  (vm/player.js): the *first frame* (what an author sees after pressing the green flag: a freshly
  loaded page, green flag to every script stopped, compiling the scripts and a cold JIT included;
  median of ``--fresh`` loads, the old and new reader alternating) and the *steady frame* (one page,
  ``--repeat`` green flags; the time inside the VM steps, without waiting for the next 30 fps
  tick; the minimum over the rounds after the first, since other processes only add time; all
  pages open at once and run in rounds, so both readers see the same load). Every run is in the
  JSON, with the median of per-round ratios;
* the new project again with TurboWarp's fencing left on (the stage's settings comment that
  ``export.turbowarp_fencing = false`` writes removed), in the same interleaved rounds: what
  turning fencing off buys (``new_fencing_on`` in the JSON);
* the image agreement of the new reader's stage with the green flag preview
  (``bake.outputs.preview.stage_agreement``).

Writes ``benchmarks/results/player.json`` and prints a markdown table. Times depend on the load
of the machine (the JSON records ``os.getloadavg()`` before and after): quote the ratios.
"""

from __future__ import annotations

import argparse
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
sys.path.insert(0, str(REPO / "vm"))

from bake.scratch import check as check_mod  # noqa: E402
from bake.scratch import sb3  # noqa: E402

import turbowarp  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "player.json"

TEAPOT = {"lighting": {"enabled": True, "target": "triangle", "ambient": [0.2, 0.2, 0.25],
                       "lights": [{"kind": "sun", "direction": [0.5, -1, -0.4]}]},
          "bsp": {"enabled": True}}

# run by `python -c` with the code to bake on sys.path first: bakes one model, writes the .sb3
BAKE_SNIPPET = r"""
import json, sys
sys.path.insert(0, sys.argv[1])
from bake import config, pipeline
job = json.loads(sys.argv[2])
if job.get("demo"):
    from importlib import resources
    toml = resources.files("bake") / "samples" / "demo.toml"
    cfg = config.load(str(toml))
else:
    cfg = config.load(data=job["data"])
res = pipeline.run(cfg)
art = res.scene.artefacts  # typed since issue 38; a dict in the previous reader's commit
files = art["outputs"] if isinstance(art, dict) else art.outputs
name = next(n for n in files if n.endswith(".sb3"))
open(job["out"], "wb").write(files[name])
print(json.dumps({"triangles": res.scene.n_triangles, "vertices": res.scene.n_vertices, "file": name}))
"""


def bake_with(code_root: Path, job: dict) -> dict:
    r = subprocess.run([sys.executable, "-c", BAKE_SNIPPET, str(code_root), json.dumps(job)], capture_output=True,
                       text=True, cwd=str(REPO), timeout=1800)
    if r.returncode != 0:
        raise SystemExit(f"bake with {code_root} failed: {r.stderr[-3000:]}")
    return json.loads(r.stdout.strip().splitlines()[-1])


def reader_bytes(path: Path, sprite: str = "Mesh") -> dict:
    rep = check_mod.check(path)
    own = [x for x in rep["items"] if x["owner"] == sprite]
    return {"reader_bytes": sum(x["bytes"] for x in own),
            "blocks_bytes": sum(x["bytes"] for x in own if x["kind"] == "blocks"),
            "json_blocks": sum(x["items"] for x in own if x["kind"] == "blocks"),
            "project_json_bytes": rep["project_json_bytes"]}


def vm_blocks(paths: list[Path], phases: list[bool]) -> list[dict]:
    """Blocks of one green-flag frame; with ``phases``, also of ``project vertices`` and ``bsp walk``
    alone (the new reader's blocks, from the green flag's camera)."""
    jobs = []
    for p, ph in zip(paths, phases):
        runs = [{"greenFlag": True, "read": {"lists": [], "variables": []}}]
        if ph:
            runs += [{"call": {"target": "Mesh", "proccode": c, "args": []}, "read": {"lists": [], "variables": []}}
                     for c in ("project vertices", "bsp walk")]
        jobs.append({"load": str(p), "runs": runs})
    r = subprocess.run(["node", str(REPO / "vm" / "run.js"), "--plan", "-"], input=json.dumps({"jobs": jobs}),
                       capture_output=True, text=True, timeout=3600)
    out = json.loads(r.stdout)
    res = []
    for job in out["jobs"]:
        if job.get("error"):
            raise SystemExit(f"vm/run.js failed: {job['error']}")
        run = job["runs"][0]
        row = {"blocks_per_frame": run["blocks"], "vm_ms": run["ms"], "done": run["done"]}
        if len(job["runs"]) == 3:
            row["blocks_project_vertices"] = job["runs"][1]["blocks"]
            row["blocks_bsp_walk"] = job["runs"][2]["blocks"]
            row["blocks_fill"] = run["blocks"] - row["blocks_project_vertices"] - row["blocks_bsp_walk"]
        res.append(row)
    return res


def without_settings_comment(src: Path, dst: Path) -> Path:
    """A copy of the .sb3 ``src`` whose stage has no TurboWarp settings comment (fencing on)."""
    import zipfile

    with zipfile.ZipFile(src) as z:
        files = {n: z.read(n) for n in z.namelist()}
    project = json.loads(files["project.json"])
    stage = next(t for t in project["targets"] if t.get("isStage"))
    if sb3.turbowarp_settings(stage.get("comments") or {}) is None:
        raise SystemExit(f"{src}: no TurboWarp settings comment to remove")
    stage["comments"] = {}
    files["project.json"] = sb3.dumps(project).encode("utf-8")
    with zipfile.ZipFile(dst, "w") as z:
        for n in sorted(files):
            z.writestr(n, files[n])
    return dst


def frame_seconds(xs: list[float]) -> float:
    """The least disturbed frame: the minimum over the runs after the first (the first compiles).
    On a shared machine other processes only ever add time, so the minimum is the estimate of a
    frame's own cost; the medians are in the JSON too."""
    later = xs[1:] if len(xs) > 1 else xs
    return float(np.min(later))


def paired(prev: list[float], new: list[float]) -> float:
    """Median over rounds (after the first) of previous / new seconds of the same round."""
    r = [a / b for a, b in zip(prev[1:], new[1:]) if b > 0] or [prev[0] / new[0]]
    return float(np.median(r))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=100, help="green flags per project and mode (the steady frame: the minimum over rounds 2..; with 40 the teapot's ratio still moved 2.69-3.77x between runs)")
    ap.add_argument("--base", default="6f0151f", help="commit of the previous reader")
    ap.add_argument("--fresh", type=int, default=5, help="fresh page loads per project and mode for the first frame")
    ap.add_argument("--models", default="demo,teapot")
    ap.add_argument("--screenshot", default="", help="also write the new reader's TurboWarp stage next to the "
                    "green flag preview of the last model to this PNG (docs/images/turbowarp-teapot.png)")
    args = ap.parse_args()
    why = turbowarp.unavailable()
    if why:  # `make bench` goes on with the other benchmarks
        print(f"bench_player: skipped, TurboWarp cannot run here: {why}", file=sys.stderr)
        return
    models = []
    for name in args.models.split(","):
        if name == "demo":
            models.append(("demo", {"demo": True}))
        elif name == "teapot":
            path = CORPUS / "teapot_obj" / "teapot.obj"
            if not path.exists():
                print(f"skip teapot: {path} not found", file=sys.stderr)
                continue
            models.append(("teapot", {"data": {"input": {"path": str(path)}, **TEAPOT}}))
        else:
            raise SystemExit(f"unknown model {name!r} (demo, teapot)")
    load0 = os.getloadavg()
    t0 = time.perf_counter()
    results = {"machine": {"platform": platform.platform(), "cpus": os.cpu_count(), "loadavg_before": load0},
               "base": args.base, "repeat": args.repeat, "fresh": args.fresh, "models": []}
    with tempfile.TemporaryDirectory(prefix="bench-player-") as tmp:
        tmp = Path(tmp)
        base = tmp / "base"
        base.mkdir()
        arch = subprocess.run(["git", "-C", str(REPO), "archive", args.base, "bake"], capture_output=True, check=True)
        subprocess.run(["tar", "-x", "-C", str(base)], input=arch.stdout, check=True)
        baked = []
        for name, job in models:
            row = {"model": name}
            for who, root in (("new", REPO), ("previous", base)):
                out = tmp / f"{name}-{who}.sb3"
                info = bake_with(root, {**job, "out": str(out)})
                row[who] = {"triangles": info["triangles"], "vertices": info["vertices"], **reader_bytes(out)}
                baked.append((name, who, out))
            results["models"].append(row)
        for (name, who, out), vmres in zip(baked, vm_blocks([b[2] for b in baked], [b[1] == "new" for b in baked])):
            next(r for r in results["models"] if r["model"] == name)[who].update(vmres)
        # the new project with TurboWarp's fencing left on (its stage's settings comment removed),
        # in the same interleaved rounds: what export.turbowarp_fencing = false buys
        fenced = [(f"{n}-fenced", without_settings_comment(p, tmp / f"{n}-fenced.sb3")) for n, w, p in baked
                  if w == "new"]
        run = turbowarp.run([(f"{n}-{w}", p) for n, w, p in baked] + fenced, modes=("compiled", "interpreted"),
                            repeat=args.repeat, interleave=True)
        results["versions"] = run.versions
        # the first frame: a freshly loaded page, one green flag (compiling the scripts and a cold
        # JIT included), old and new alternating, --fresh times each
        fresh = turbowarp.run([(f"{n}-{w}#{k}", p) for k in range(args.fresh) for n, w, p in baked],
                              modes=("compiled", "interpreted"), repeat=1)
        from bake.outputs import preview
        from bake.scratch.project import auto_camera

        for name, who, out in baked:
            row = next(r for r in results["models"] if r["model"] == name)[who]
            for mode in ("compiled", "interpreted"):
                r = run.get(f"{name}-{who}", mode)
                later = r.seconds[1:] or r.seconds
                first = [fresh.get(f"{name}-{who}#{k}", mode).seconds[0] for k in range(args.fresh)]
                row[mode] = {"seconds": r.seconds, "step_seconds": r.step_seconds, "problems": r.problems(),
                             "first_frame_seconds": first, "first_frame_median": float(np.median(first)),
                             "frame_seconds": frame_seconds(r.step_seconds),
                             "median_seconds": float(np.median(later))}
            if who == "new":
                project, _ = sb3.load_project(out)
                lists = {n: items for t in project["targets"] for n, items in (t.get("lists") or {}).values()}
                two = lists.get("mat two-sided") or [0] * len(lists.get("mat colors", []))
                mesh = preview.mesh_from_lists(lists, {"config": {"export": {"names": {}}},
                                                       "materials": [{"double_sided": bool(x)} for x in two]})
                view, pim = preview.stage_view(mesh, auto_camera(lists["verts"]))
                row["agreement"] = {m: preview.stage_agreement(run.get(f"{name}-{who}", m).image, view, pim)
                                    for m in ("compiled", "interpreted")}
                if args.screenshot:
                    from PIL import Image

                    from PIL import ImageDraw

                    gap = np.full((360, 16, 3), 255, np.uint8)
                    pic = np.concatenate([run.get(f"{name}-{who}", "compiled").image, gap, view.painter], 1)
                    im = Image.fromarray(pic)
                    d = ImageDraw.Draw(im)
                    d.text((8, 8), "TurboWarp player (packager 3.13.0), compiled: the stage after the green flag", fill=(0, 0, 0))
                    d.text((504, 8), "report.html green flag preview (numpy rasterizer)", fill=(0, 0, 0))
                    d.line([(487, 0), (487, 359)], fill=(200, 200, 200))
                    Path(args.screenshot).parent.mkdir(parents=True, exist_ok=True)
                    im.save(args.screenshot, optimize=True)
        for row in results["models"]:
            row["new_fencing_on"] = {}
            for mode in ("compiled", "interpreted"):
                r = run.get(f"{row['model']}-fenced", mode)
                row["new_fencing_on"][mode] = {"seconds": r.seconds, "step_seconds": r.step_seconds,
                                               "frame_seconds": frame_seconds(r.step_seconds),
                                               "runtime_options": r.runtime_options}
                new_r = run.get(f"{row['model']}-new", mode)
                row["new"][mode]["runtime_options"] = new_r.runtime_options
                row["new_fencing_on"][f"{mode}_over_new"] = (frame_seconds(r.step_seconds)
                                                             / row["new"][mode]["frame_seconds"])
                row["new_fencing_on"][f"{mode}_over_new_paired"] = paired(r.step_seconds, new_r.step_seconds)
        for row in results["models"]:
            n, p = row["new"], row["previous"]
            row["ratio_previous_to_new"] = {
                "first_frame_compiled": p["compiled"]["first_frame_median"] / n["compiled"]["first_frame_median"],
                "first_frame_interpreted": (p["interpreted"]["first_frame_median"]
                                            / n["interpreted"]["first_frame_median"]),
                "reader_bytes": p["reader_bytes"] / n["reader_bytes"],
                "blocks_per_frame": p["blocks_per_frame"] / n["blocks_per_frame"],
                "turbowarp_compiled": p["compiled"]["frame_seconds"] / n["compiled"]["frame_seconds"],
                "turbowarp_interpreted": p["interpreted"]["frame_seconds"] / n["interpreted"]["frame_seconds"],
                # the pages run interleaved: round k of the previous reader next to round k of the
                # new one; the median over rounds (the first, which compiles, left out) of the
                # ratio of the times inside the VM steps (what the minimum is taken of)
                "turbowarp_compiled_paired": paired(p["compiled"]["step_seconds"], n["compiled"]["step_seconds"]),
                "turbowarp_interpreted_paired": paired(p["interpreted"]["step_seconds"],
                                                       n["interpreted"]["step_seconds"]),
                # the ratio of the two sides' medians (rounds after the first)
                "turbowarp_compiled_medians": (float(np.median(p["compiled"]["step_seconds"][1:]))
                                               / float(np.median(n["compiled"]["step_seconds"][1:]))),
                "turbowarp_interpreted_medians": (float(np.median(p["interpreted"]["step_seconds"][1:]))
                                                  / float(np.median(n["interpreted"]["step_seconds"][1:])))}
    results["machine"]["loadavg_after"] = os.getloadavg()
    results["seconds"] = time.perf_counter() - t0
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(results, indent=1))

    print(f"TurboWarp (packager {results['versions']['@turbowarp/packager']}, {results['versions']['chromium']}), "
          f"scratch-vm blocks; previous reader = {args.base}; load {load0[0]:.1f} -> "
          f"{results['machine']['loadavg_after'][0]:.1f}\n")
    print("| model | reader | triangles | reader bytes | blocks/frame | TurboWarp first frame, compiled s | "
          "interpreted s | steady frame, compiled s | interpreted s |")
    print("|---|---|---:|---:|---:|---:|---:|---:|---:|")
    for row in results["models"]:
        for who in ("previous", "new"):
            x = row[who]
            print(f"| {row['model']} | {who} | {x['triangles']:,} | {x['reader_bytes']:,} | {x['blocks_per_frame']:,} | "
                  f"{x['compiled']['first_frame_median']:.3f} | {x['interpreted']['first_frame_median']:.3f} | "
                  f"{x['compiled']['frame_seconds']:.4f} | {x['interpreted']['frame_seconds']:.4f} |")
        q = row["ratio_previous_to_new"]
        print(f"| {row['model']} | previous / new | | {q['reader_bytes']:.1f}x | {q['blocks_per_frame']:.2f}x | "
              f"{q['first_frame_compiled']:.2f}x | {q['first_frame_interpreted']:.2f}x | "
              f"{q['turbowarp_compiled']:.2f}x | {q['turbowarp_interpreted']:.2f}x |")
    print(f"\nfirst frame: green flag to every script stopped on a freshly loaded page (compiling and a cold "
          f"JIT included), median of {args.fresh} loads; steady frame: the time inside the VM steps, minimum "
          f"over rounds 2..{args.repeat} of green flags on one page (the JIT warm), the two readers interleaved")
    print("\nimage agreement of the new reader's stage with the green flag preview:")
    for row in results["models"]:
        for mode, a in row["new"]["agreement"].items():
            print(f"  {row['model']} {mode}: interior within 1 level {a['within_1']:.4f} of {a['interior_pixels']:,}, "
                  f"covered within 1 level {a['covered_within_1']:.4f} of {a['covered_inner_pixels']:,}, "
                  f"blank interior {a['interior_left_blank']}, painted empty {a['empty_painted']}")
    for row in results["models"]:
        f = row["new_fencing_on"]
        print(f"{row['model']}: new with TurboWarp's fencing on: compiled {f['compiled']['frame_seconds']:.4f} s "
              f"({f['compiled_over_new']:.2f}x the new frame; paired {f['compiled_over_new_paired']:.2f}x), "
              f"interpreted {f['interpreted']['frame_seconds']:.4f} s ({f['interpreted_over_new']:.2f}x)")
    for row in results["models"]:
        n = row["new"]
        if "blocks_bsp_walk" in n:
            print(f"{row['model']}: new frame = project vertices {n['blocks_project_vertices']:,} + bsp walk "
                  f"{n['blocks_bsp_walk']:,} + fill {n['blocks_fill']:,} blocks")
    print(f"\nwrote {OUT.relative_to(REPO)} ({results['seconds']:.0f} s)")


if __name__ == "__main__":
    main()
