"""The reader's textured filler against its flat filler, side by side in one run: blocks per
frame, TurboWarp frame seconds, blocks per cell, and the texture's bytes by encoding.

    .venv/bin/python benchmarks/bench_textured.py [--repeat 20] [--models duck,box,room] [--sizes 1,2,4]

Each model is baked once per setting, everything else the same: ``export.texel_size = 0`` (the
flat fan filler: triangle colours) and each texel size. For each .sb3:

* blocks per frame: blocks scratch-vm 5.0.300 executes from the green flag until every script
  stopped (vm/run.js), the textures' one-time load into ``_tex`` counted apart (the green flag
  of a second frame does not load them again);
* cells: the cells the frame paints (``bake.outputs.cells``), and the frame's blocks per cell;
* TurboWarp seconds, compiled and interpreted (TurboWarp's player in headless Chromium,
  vm/player.js): the steady frame, the minimum over ``--repeat`` green flags after the first;
  all projects in one page set, interleaved rounds;
* the texture data's project.json bytes by encoding (the textures stage's figures).

Writes ``benchmarks/results/textured.json`` (ratios to the flat frame computed here) and prints
a markdown table; README's "In Scratch" table is generated from it.
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


REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))
sys.path.insert(0, str(REPO / "vm"))

from bake import config, pipeline  # noqa: E402
from bake.outputs import cells  # noqa: E402
from bake.scratch.project import reader_spec  # noqa: E402
from bench_player import frame_seconds  # noqa: E402

import turbowarp  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "textured.json"

ROOM = {"lighting": {"enabled": True, "target": "lightmap", "ambient": [0.2, 0.2, 0.25],
                     "lights": [{"kind": "sun", "direction": [0.5, -1, -0.4]}], "ao": {"enabled": True, "samples": 8}},
        "textures": {"enabled": True, "lightmap": {"enabled": True, "resolution": 64}}}
MODELS = {  # name -> (corpus path, sections)
    "duck": ("duck_glb/Duck.glb", {}),
    "box": ("box_textured_glb/BoxTextured.glb", {}),
    "room": ("cornell_box_multimaterial/cornell_box_multimaterial.obj", ROOM),
}


def _bake(model: Path, sections: dict, texel: int, out: Path):
    data = {**sections, "input": {"path": str(model)}, "export": {"texel_size": texel, "sprite3": False}}
    res = pipeline.run(config.load(data=data))
    files = res.scene.artefacts.outputs
    name = next(n for n in files if n.endswith(".sb3"))
    out.parent.mkdir(parents=True, exist_ok=True)
    out.write_bytes(files[name])
    return res, json.loads(files["lists.json"])["lists"]


def _cells(res, lists) -> int:
    """The cells the frame paints (the textured filler's frame in Python)."""
    spec = reader_spec(res.scene, res.config.export, lists)
    found = cells.frame(lists, spec.texture, res.config.export.names, res.config.export.faces,
                        res.config.export.index_base, spec.two_sided) if spec.texture is not None else None
    return int((found[0].colour >= 0).sum()) if found is not None else 0


def vm_frames(paths: list[Path]) -> list[tuple[int, int]]:
    """Blocks scratch-vm runs for the first green flag and for a second one, per project."""
    import subprocess

    jobs = [{"load": str(p), "runs": [{"greenFlag": True, "read": {"lists": [], "variables": []}}] * 2}
            for p in paths]
    r = subprocess.run(["node", str(REPO / "vm" / "run.js"), "--plan", "-"], input=json.dumps({"jobs": jobs}),
                       capture_output=True, text=True, timeout=3600)
    out = []
    for job in json.loads(r.stdout)["jobs"]:
        if job.get("error"):
            raise SystemExit(f"vm/run.js failed: {job['error']}")
        out.append((job["runs"][0]["blocks"], job["runs"][1]["blocks"]))
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--repeat", type=int, default=20, help="green flags per project and mode (steady frame)")
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--sizes", default="1,2,4")
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args()
    sizes = [int(x) for x in args.sizes.split(",")]
    t0 = time.perf_counter()
    results: dict = {"command": "benchmarks/bench_textured.py " + " ".join(sys.argv[1:]), "repeat": args.repeat,
                     "machine": {"platform": platform.platform(), "cpus": os.cpu_count(),
                                 "loadavg_before": os.getloadavg()}, "models": {}}
    with tempfile.TemporaryDirectory() as tmp:
        baked = []  # (model, texel, path)
        for name in args.models.split(","):
            rel, sections = MODELS[name]
            model = CORPUS / rel
            if not model.exists():
                print(f"bench_textured: {model} missing, {name} skipped")
                continue
            row = {"model": rel, "settings": {}}
            for texel in [0] + sizes:
                p = Path(tmp) / name / f"t{texel}.sb3"
                res, lists = _bake(model, sections, texel, p)
                spec = reader_spec(res.scene, res.config.export, lists)
                tex_rec = next((r for r in res.records if r.name == "textures"), None)
                enc = {}
                for t in (tex_rec.details.get("textures", []) if tex_rec else []):
                    for e, fig in t["encodings"].items():
                        enc[e] = enc.get(e, 0) + int(fig.get("project_json_bytes", 0))
                lm = res.scene.artefacts.lightmap_encoded  # the lightmap's encodings, as a texture's
                for e, fig in (lm.sizes if lm is not None else {}).items():
                    enc[e] = enc.get(e, 0) + int(fig.get("project_json_bytes", 0))
                texels = sum(s.width * s.height for s in spec.texture.sources) if spec.texture else 0
                row["triangles"] = res.scene.n_triangles
                row["texture_bytes"] = enc
                row["settings"][str(texel)] = {"texel_size": texel, "textured": spec.texture is not None,
                                               "cells": _cells(res, lists) if texel else 0, "texels": texels}
                baked.append((name, texel, p))
            results["models"][name] = row
        for (name, texel, _), v in zip(baked, vm_frames([b[2] for b in baked])):
            st = results["models"][name]["settings"][str(texel)]
            # the first green flag loads the textures into _tex; the second draws the frame alone
            st["blocks_green_flag"], st["blocks_per_frame"] = v
            st["blocks_load"] = v[0] - v[1]
        why = turbowarp.unavailable()
        if why:
            print(f"bench_textured: TurboWarp cannot run here ({why}): no seconds", file=sys.stderr)
        else:
            run = turbowarp.run([(f"{n}-{t}", p) for n, t, p in baked], modes=("compiled", "interpreted"),
                                repeat=args.repeat, interleave=True)
            results["versions"] = run.versions
            for name, texel, _ in baked:
                st = results["models"][name]["settings"][str(texel)]
                for mode in ("compiled", "interpreted"):
                    r = run.get(f"{name}-{texel}", mode)
                    st[mode] = {"frame_seconds": frame_seconds(r.step_seconds), "problems": r.problems(),
                                "step_seconds": r.step_seconds}
    for name, row in results["models"].items():
        flat = row["settings"]["0"]
        for key, st in row["settings"].items():
            st["blocks_vs_flat"] = st["blocks_per_frame"] / flat["blocks_per_frame"]
            st["blocks_per_cell"] = st["blocks_per_frame"] / st["cells"] if st["cells"] else None
            for mode in ("compiled", "interpreted"):
                if mode in st and mode in flat and flat[mode]["frame_seconds"] > 0:
                    st[mode]["vs_flat"] = st[mode]["frame_seconds"] / flat[mode]["frame_seconds"]
    # one row per model and setting, for README's table
    results["rows"] = [{"model": name, "setting": "flat" if key == "0" else f"texel size {key}",
                        "triangles": row["triangles"], "compiled_ms": 1000 * st["compiled"]["frame_seconds"]
                        if "compiled" in st else None,
                        "interpreted_ms": 1000 * st["interpreted"]["frame_seconds"] if "interpreted" in st else None,
                        "compiled_vs_flat": st.get("compiled", {}).get("vs_flat"),
                        "interpreted_vs_flat": st.get("interpreted", {}).get("vs_flat"),
                        **{k: st[k] for k in ("cells", "blocks_per_frame", "blocks_vs_flat", "blocks_per_cell",
                                              "blocks_load")}}
                       for name, row in results["models"].items() for key, st in row["settings"].items()]
    results["seconds"] = time.perf_counter() - t0
    results["machine"]["loadavg_after"] = os.getloadavg()
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    print("| model | texel size | cells | blocks per frame | vs flat | blocks per cell | TurboWarp compiled ms | "
          "interpreted ms |")
    print("|---|---:|---:|---:|---:|---:|---:|---:|")
    for name, row in results["models"].items():
        for key, st in row["settings"].items():
            c = st.get("compiled", {}).get("frame_seconds")
            i = st.get("interpreted", {}).get("frame_seconds")
            print(f"| {name} | {key if key != '0' else 'flat'} | {st['cells']:,} | {st['blocks_per_frame']:,} | "
                  f"{st['blocks_vs_flat']:.2f} | {st['blocks_per_cell'] or 0:.1f} | "
                  f"{(c or 0) * 1000:.1f} | {(i or 0) * 1000:.1f} |")
    print(f"wrote {args.out} in {results['seconds']:.0f} s")


if __name__ == "__main__":
    main()
