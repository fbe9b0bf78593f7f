"""List layouts for authors' engines (docs/engines.md), side by side in one run: what each costs
in project.json bytes and in the reader's blocks per frame.

    .venv/bin/python benchmarks/bench_layouts.py [--models teapot]

The lit, BSP-sorted Utah teapot (the player benchmark's config) is baked by this checkout once
per layout, everything else the same: the book's interleaved lists (the default), per-coordinate
vertex lists with 0-based per-corner index lists, and the unindexed "soup" (one list of 9 numbers
a triangle; x, y, z per corner; 9 lists). For each .sb3:

* project.json bytes, the lists' share (every list item in project.json) and the reader
  sprite's (``bake check``: everything the sprite owns);
* blocks per frame: blocks scratch-vm executes from the green flag until every script stopped
  (vm/run.js; the reader's ``render``: project, walk, fill), with ``project vertices`` and
  ``bsp walk`` alone;
* the same, packed (``export.pack``): project.json bytes, and the green flag's blocks with the
  loader's (the loader runs once, before the first frame).

Writes ``benchmarks/results/layouts.json`` (ratios against the book's layout computed here) and
prints a markdown table; the table in docs/engines.md is generated from it.
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

from bake import config, pipeline  # noqa: E402
from bench_player import reader_bytes, vm_blocks  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "layouts.json"

MODELS = {
    "teapot": (CORPUS / "teapot_obj" / "teapot.obj",
               {"lighting": {"enabled": True, "target": "triangle", "ambient": [0.2, 0.2, 0.25],
                             "lights": [{"kind": "sun", "direction": [0.5, -1, -0.4]}]},
                "bsp": {"enabled": True}}),
}

LAYOUTS = {  # key -> (label, export keys)
    "book": ("interleaved, 1-based (default)", {}),
    "per_coordinate": ("x, y, z lists; 0-based corner lists",
                       {"names": {"vertices": ["X", "Y", "Z"], "triangles": ["tri a", "tri b", "tri c", "tri mat"]},
                        "index_base": 0}),
    "soup": ("soup: 9 numbers a triangle", {"faces": "soup"}),
    "soup_xyz": ("soup: x, y, z lists per corner", {"faces": "soup", "names": {"vertices": ["X", "Y", "Z"]}}),
    "soup_9": ("soup: 9 lists", {"faces": "soup",
                                 "names": {"vertices": [f"{a}{k}" for k in "123" for a in "xyz"]}}),
}


def bake(model: Path, sections: dict, export: dict, out: Path) -> tuple[Path, dict]:
    data = {**sections, "input": {"path": str(model)}, "export": {**export, "sprite3": False, "txt": False}}
    res = pipeline.run(config.load(data=data))
    files = res.scene.artefacts.outputs
    name = next(n for n in files if n.endswith(".sb3"))
    out.mkdir(parents=True, exist_ok=True)
    (out / name).write_bytes(files[name])
    info = res.scene.artefacts.list_info
    mesh = {k: v for k, v in info.items() if not k.startswith(("bsp ", "bvh "))}
    return out / name, {"lists": len(info), "mesh_lists": len(mesh),
                        "list_bytes": sum(v["project_json_bytes"] for v in info.values()),
                        "mesh_list_bytes": sum(v["project_json_bytes"] for v in mesh.values()),
                        "triangles": res.scene.n_triangles}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--models", default=",".join(MODELS))
    ap.add_argument("--out", default=str(OUT))
    args = ap.parse_args()
    t0 = time.perf_counter()
    results: dict = {"command": "benchmarks/bench_layouts.py " + " ".join(sys.argv[1:]),
                     "machine": {"platform": platform.platform(), "cpus": os.cpu_count()}, "models": {}, "rows": []}
    with tempfile.TemporaryDirectory() as tmp:
        for model in args.models.split(","):
            path, sections = MODELS[model]
            if not path.exists():
                print(f"bench_layouts: {path} missing, {model} skipped")
                continue
            rows, paths = [], []
            for key, (label, export) in LAYOUTS.items():
                for packed in (False, True):
                    p, meta = bake(path, sections, {**export, "pack": packed}, Path(tmp) / model / key / str(packed))
                    paths.append(p)
                    rows.append({"model": model, "layout": key, "label": label, "packed": packed, **meta,
                                 **reader_bytes(p)})
            for row, vm in zip(rows, vm_blocks(paths, [not r["packed"] for r in rows])):
                row.update(vm)
            base = {r["packed"]: r for r in rows if r["layout"] == "book"}
            for r in rows:
                b = base[r["packed"]]
                r["bytes_vs_book"] = r["project_json_bytes"] / b["project_json_bytes"]
                r["blocks_vs_book"] = r["blocks_per_frame"] / b["blocks_per_frame"]
            plain = {r["layout"]: r for r in rows if not r["packed"]}
            packed = {r["layout"]: r for r in rows if r["packed"]}
            results["models"][model] = {
                key: {"label": plain[key]["label"], "plain": plain[key], "packed": packed[key]} for key in LAYOUTS}
            results["rows"] += rows
    results["seconds"] = time.perf_counter() - t0
    Path(args.out).parent.mkdir(parents=True, exist_ok=True)
    Path(args.out).write_text(json.dumps(results, indent=1) + "\n")
    print("| model | layout | project.json bytes | vs book | blocks per frame | vs book | packed bytes | "
          "packed: green flag blocks (loader + frame) |")
    print("|---|---|---:|---:|---:|---:|---:|---:|")
    for model, lay in results["models"].items():
        for key, x in lay.items():
            p, q = x["plain"], x["packed"]
            print(f"| {model} | {x['label']} | {p['project_json_bytes']:,} | {p['bytes_vs_book']:.3f} | "
                  f"{p['blocks_per_frame']:,} | {p['blocks_vs_book']:.3f} | {q['project_json_bytes']:,} | "
                  f"{q['blocks_per_frame']:,} |")
    print(f"wrote {args.out} in {results['seconds']:.0f} s")


if __name__ == "__main__":
    main()
