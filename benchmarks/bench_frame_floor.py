"""The floor of the reader's frame: what a frame costs before it draws a single line.

    .venv/bin/python benchmarks/bench_frame_floor.py [--models demo,teapot]

The frame (``render``) projects every vertex, walks the BSP tree, and then visits every triangle
of the ranges the walk gave: it reads the projected corners and tests which way the triangle
faces on the stage; only then does it draw the triangles that face the camera. This benchmark
bakes each model (the bundled demo, and the lit BSP-sorted Utah teapot of bench_player.py) twice
with this checkout: as it is, and with the filler's drawing taken out (the blocks that run for a
triangle that faces the camera: colour, fan, pen), everything else the same. In scratch-vm
(vm/run.js) it counts the blocks of one green-flag frame of each, and of ``project vertices`` and
``bsp walk`` alone; in Python (the reader's own arithmetic, ``bake.scratch.readers``) the
vertices, the triangles the frame visits, those it draws, and the vertices those use.

So ``undrawn`` is the least any frame of this design costs for the model and camera (projecting,
walking, visiting: the same whatever the filler draws), and ``per_vertex`` / ``per_visit`` its
costs per unit. Writes ``benchmarks/results/frame_floor.json``; README's table is rendered from it.
"""

from __future__ import annotations

import argparse
import json
import platform
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))
sys.path.insert(0, str(REPO / "benchmarks"))

from bake import config, pipeline  # noqa: E402
from bake.bsp.traverse import draw_ranges  # noqa: E402
from bake.scratch import readers, sb3  # noqa: E402
from bench_player import CORPUS, TEAPOT, vm_blocks  # noqa: E402

OUT = REPO / "benchmarks" / "results" / "frame_floor.json"


def bake(name: str, out: Path, undrawn: bool) -> Path:
    """The model's .sb3; ``undrawn``: the filler's drawing left out (its facing test kept, its
    body empty)."""
    if name == "demo":
        from importlib import resources

        cfg = config.load(str(resources.files("bake") / "samples" / "demo.toml"))
    else:
        cfg = config.load(data={"input": {"path": str(CORPUS / "teapot_obj" / "teapot.obj")}, **TEAPOT})
    original = readers._fill_blocks

    def without_drawing(r, *a, **k):
        blocks = original(r, *a, **k)
        last = blocks[-1]  # if <faces the camera> then <draw>
        assert last.opcode == "control_if", last
        return blocks[:-1] + [readers.B.if_(last.inputs["CONDITION"][0], [])]

    if undrawn:
        readers._fill_blocks = without_drawing
    try:
        res = pipeline.run(cfg)
    finally:
        readers._fill_blocks = original
    files = res.scene.artefacts.outputs
    path = out / f"{name}{'-undrawn' if undrawn else ''}.sb3"
    path.write_bytes(files[next(n for n in files if n.endswith(".sb3"))])
    return path


def counts(path: Path) -> dict:
    """Vertices, triangles visited (in the walk's ranges) and drawn, vertices of drawn triangles,
    from the lists and the green flag's camera, with the reader's arithmetic."""
    project, _ = sb3.load_project(path)
    lists = {n: items for t in project["targets"] for n, items in (t.get("lists") or {}).values()}
    sprite = next(t for t in project["targets"] if t["name"] == "Mesh")
    v = {n: val for n, val in sprite["variables"].values()}
    cam = readers.Camera(*(float(v[k]) for k in ("cam x", "cam y", "cam z", "cam yaw", "cam pitch", "focal", "near")))
    verts = np.asarray(lists["verts"], np.float64).reshape(-1, 3)
    tris = np.asarray(lists["tris"], np.int64).reshape(-1, 4)
    shown = readers.drawn(verts, tris, cam, lists.get("mat two-sided") or [])
    ranges = draw_ranges(lists["bsp nodes"], lists["bsp planes"], (cam.x, cam.y, cam.z))
    visited = int(sum(n for _, n in ranges))
    return {"vertices": len(verts), "triangles": len(tris), "ranges": len(ranges), "visited": visited,
            "drawn": int(shown.sum()), "vertices_of_drawn": int(len(np.unique(tris[shown, :3])))}


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--models", default="demo,teapot")
    args = ap.parse_args()
    t0 = time.perf_counter()
    rows = []
    with tempfile.TemporaryDirectory(prefix="bench-floor-") as tmp:
        tmp = Path(tmp)
        names = [n for n in args.models.split(",") if n == "demo" or (CORPUS / "teapot_obj" / "teapot.obj").exists()]
        paths = [(n, bake(n, tmp, False), bake(n, tmp, True)) for n in names]
        vm = vm_blocks([p for _, a, b in paths for p in (a, b)], [True] * (2 * len(paths)))
        for k, (name, full, bare) in enumerate(paths):
            f, u = vm[2 * k], vm[2 * k + 1]
            if not (f["done"] and u["done"]):
                raise SystemExit(f"{name}: a frame did not finish")
            c = counts(full)
            assert (f["blocks_project_vertices"], f["blocks_bsp_walk"]) == \
                (u["blocks_project_vertices"], u["blocks_bsp_walk"])  # the same projection and walk
            visit = u["blocks_fill"]
            rows.append({"model": name, **c, "frame": f["blocks_per_frame"], "undrawn": u["blocks_per_frame"],
                         "project": f["blocks_project_vertices"], "walk": f["blocks_bsp_walk"], "visit": visit,
                         "draw": f["blocks_per_frame"] - u["blocks_per_frame"],
                         "per_vertex": f["blocks_project_vertices"] / c["vertices"],
                         "per_visit": visit / c["visited"],
                         "per_drawn": (f["blocks_per_frame"] - u["blocks_per_frame"]) / c["drawn"]})
            r = rows[-1]
            print(f"{name}: frame {r['frame']:,} = project {r['project']:,} ({r['per_vertex']:.1f} a vertex of "
                  f"{r['vertices']:,}) + walk {r['walk']:,} + visit {visit:,} ({r['per_visit']:.1f} a triangle of "
                  f"{r['visited']:,} in {r['ranges']:,} ranges) + draw {r['draw']:,} ({r['per_drawn']:.1f} a "
                  f"triangle of {r['drawn']:,}); undrawn {r['undrawn']:,}; vertices of drawn triangles "
                  f"{r['vertices_of_drawn']:,}")
    out = {"machine": {"platform": platform.platform()}, "command": " ".join(["benchmarks/bench_frame_floor.py",
                                                                               *sys.argv[1:]]),
           "models": rows, "seconds": time.perf_counter() - t0}
    OUT.write_text(json.dumps(out, indent=1) + "\n")
    print(f"wrote {OUT.relative_to(REPO)}")


if __name__ == "__main__":
    main()
