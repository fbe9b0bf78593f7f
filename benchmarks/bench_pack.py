"""Packed lists (export.pack) against the plain export, side by side in one run.

    .venv/bin/python benchmarks/bench_pack.py [--quick] [--no-turbowarp] [--no-vm]

For each model (the 2,000-triangle lit BSP bunny, the teapot and the house lit with BSP, the
bundled demo, the 69,451-triangle bunny lit with its mesh and colour lists, and the same with BSP)
the real pipeline bakes it three ways: plain with the old defaults (every colour list the scene
has: the figure the issue started from), plain with the new defaults (lists nothing reads left
out), and packed. Per list: project.json bytes plain and packed and bytes per written triangle;
per model: project.json bytes, what the loader blocks add, the blocks the loader runs
(the cost model, and the count scratch-vm reports), and seconds in TurboWarp (compiled and
interpreted: ``vm/turbowarp.py``, ``unpack lists`` called three times, the seconds inside VM
steps). Every packed list is decoded by the Python mirror and compared with the plain list item
for item; in scratch-vm every rebuilt list is compared too (lossless: the same doubles).

Ideas, measured one at a time on the lists of the 2k and 69k bunnies (Python only: bytes):
cumulative (each row adds one idea) and leave-one-out (the full packing without one idea).
Format changes that cost accuracy: ``export.precision`` (positions; the rounding bound) and
``bsp.plane_decimals`` (planes; the split inflation), packed bytes for each value.

The whole project.json, split (issue 41): the lists (the stage's, packed texts included), the
loader's blocks, the reader's blocks, the costumes, the sprite's variables and own lists, and the
rest, per written triangle; ``--baseline TREE`` also bakes the 2k and 69k bunnies packed with
another checkout (e.g. main) for the same split and times its 69k decode in the same TurboWarp
run, so before and after come from one run.

Writes ``benchmarks/results/pack.json``; docs/formats.md's tables are rendered from it.
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

from bake import config, pipeline  # noqa: E402
from bake.scratch import pack as P  # noqa: E402
from bake.scratch import sb3  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
OUT = REPO / "benchmarks" / "results" / "pack.json"
BUNNY = CORPUS / "stanford_bunny_res1_obj" / "stanford-bunny.obj"
LIT = {"enabled": True, "ambient": [0.3, 0.3, 0.33],
       "lights": [{"kind": "sun", "direction": [0.5, -1.0, 0.6], "angle": 2.0}], "ao": {"enabled": True, "samples": 64}}


def models(quick: bool) -> dict[str, dict]:
    bunny2k_sets = ["mesh.simplify.target_triangles=2000"]
    bunny2k = config.load(REPO / "configs" / "bunny.toml", bunny2k_sets)
    out = {
        "bunny2k": {"label": "bunny 2k, lit, BSP", "config": bunny2k,
                    "recipe": {"path": str(REPO / "configs" / "bunny.toml"), "sets": bunny2k_sets}},
        "teapot": {"label": "teapot, lit, BSP", "config": config.load(data={
            "input": {"path": str(CORPUS / "teapot_obj" / "teapot.obj")}, "transform": {"fit": 100},
            "lighting": LIT, "bsp": {"enabled": True}})},
        "house": {"label": "house, lit, BSP", "config": config.load(REPO / "configs" / "house.toml")},
        "demo": {"label": "demo (lit, BSP, BVH)", "config": config.load(REPO / "bake" / "samples" / "demo.toml")},
    }
    if not quick:
        b69 = {"input": {"path": str(BUNNY)}, "transform": {"center": "base", "fit": 100}, "lighting": LIT}
        out["bunny69k"] = {"label": "bunny 69k, lit", "config": config.load(data=b69), "recipe": {"data": b69}}
        out["bunny69k_bsp"] = {"label": "bunny 69k, lit, BSP", "config": config.load(data={**b69, "bsp": {"enabled": True}})}
    return out


def with_export(cfg, **kw):
    import copy
    import dataclasses

    c = copy.deepcopy(cfg)
    c.export = dataclasses.replace(c.export, **kw)
    return c


def bake(cfg, out_dir: Path):
    t0 = time.perf_counter()
    res = pipeline.run(cfg)
    files = res.scene.artefacts.outputs
    sb3_name = next(n for n in files if n.endswith(".sb3"))
    path = out_dir / sb3_name
    path.write_bytes(files[sb3_name])
    export = next(r for r in res.records if r.name == "export")
    lists = json.loads(files["lists.json"])["lists"]
    info = res.scene.artefacts.list_info
    return {"res": res, "path": path, "lists": lists, "info": info, "export": export,
            "seconds": time.perf_counter() - t0, "pj": export.details["project_json_bytes"]}


def per_tri(n_bytes: int, tris: int) -> float:
    return round(n_bytes / max(1, tris), 3)


def _json_len(x) -> int:
    return len(json.dumps(x, ensure_ascii=False, separators=(",", ":"), allow_nan=False).encode("utf-8"))


def _is_loader(proccode: str) -> bool:
    return proccode.startswith("_pk ") or proccode in ("unpack lists", "clear unpacked lists")


def project_split(sb3_path: Path, tris: int) -> dict:
    """Bytes of project.json by what they hold, and per written triangle: ``lists`` (the stage's
    lists: the data, packed texts included), ``loader_blocks`` (the scripts of the loader's custom
    blocks), ``reader_blocks`` (every other block), ``costumes`` (every target's), ``variables`` (the
    targets' variables and the sprites' own lists: the loader's and the reader's working lists) and
    ``other`` (the rest: the JSON around them, comments, meta)."""
    project = sb3.load_project(sb3_path)[0]
    total = _json_len(project)
    out = {"lists": 0, "loader_blocks": 0, "reader_blocks": 0, "costumes": 0, "variables": 0}
    for t in project["targets"]:
        out["costumes"] += _json_len(t.get("costumes", []))
        out["variables"] += _json_len(t.get("variables", {}))
        out["lists" if t.get("isStage") else "variables"] += _json_len(t.get("lists", {}))
        blocks = t.get("blocks", {})
        owner: dict[str, str] = {}

        def walk(bid, top):
            stack = [bid]
            while stack:
                b = stack.pop()
                if not isinstance(b, str) or b not in blocks or b in owner:
                    continue
                owner[b] = top
                blk = blocks[b]
                if not isinstance(blk, dict):
                    continue
                stack.append(blk.get("next"))
                for v in (blk.get("inputs") or {}).values():
                    stack.extend(x for x in v[1:] if isinstance(x, str))
        for bid, blk in blocks.items():
            if isinstance(blk, dict) and blk.get("topLevel"):
                name = ""
                if blk.get("opcode") == "procedures_definition":
                    proto = blocks.get(blk["inputs"]["custom_block"][1], {})
                    name = proto.get("mutation", {}).get("proccode", "")
                walk(bid, "loader" if _is_loader(name) else "reader")
        for bid, blk in blocks.items():
            n = _json_len({bid: blk}) - 2 + 1  # the member and its comma
            out["loader_blocks" if owner.get(bid) == "loader" else "reader_blocks"] += n
    out["other"] = total - sum(out.values())
    out["total"] = total
    return {"bytes": out, "per_tri": {k: per_tri(v, tris) for k, v in out.items()}, "written_triangles": tris}


BASELINE_SCRIPT = """
import dataclasses, json, sys
from pathlib import Path
from bake import config, pipeline
recipe = json.loads(Path(sys.argv[1]).read_text())
if "path" in recipe:
    cfg = config.load(Path(recipe["path"]), recipe["sets"])
else:
    cfg = config.load(data=recipe["data"])
cfg.export = dataclasses.replace(cfg.export, **recipe["export"])
res = pipeline.run(cfg)
files = res.scene.artefacts.outputs
name = next(n for n in files if n.endswith(".sb3"))
Path(sys.argv[2]).write_bytes(files[name])
lists = json.loads(files["lists.json"])["lists"]
Path(sys.argv[2] + ".json").write_text(json.dumps({"triangles": len(lists["tris"]) // 4}))
"""


def bake_with_tree(tree: Path, recipe: dict, out: Path) -> tuple[Path, int]:
    """The .sb3 another checkout bakes, at ``out``, from a config it loads itself from ``recipe``
    (a config file and its --set overrides, or the config's data, then ``export`` fields replaced):
    an older checkout may not know this one's config classes, so no config object goes across.
    With the triangles it wrote (its BSP may split others than this checkout's)."""
    cfg_file = out.with_suffix(".recipe.json")
    cfg_file.write_text(json.dumps(recipe))
    r = subprocess.run([sys.executable, "-c", BASELINE_SCRIPT, str(cfg_file), str(out)], cwd=str(tree),
                       env=dict(os.environ, PYTHONPATH=str(tree)), capture_output=True, text=True, timeout=3600)
    if r.returncode != 0:
        raise SystemExit(f"baseline bake with {tree} failed: {r.stderr[-2000:]}")
    return out, int(json.loads(Path(str(out) + ".json").read_text())["triangles"])


# --------------------------------------------------------------------------- ideas
def ideas(first_use: dict, scene_order: dict, old_plain: dict, strides: dict, tris: int) -> dict:
    """Bytes of the lists with each idea on or off (first_use / scene_order: the lists of bakes with
    export.vertex_order = first-use / scene; old_plain: bytes of the old defaults' plain lists)."""
    new_names = list(first_use)
    plain_new = {n: old_plain.get(n, 0) for n in new_names}
    full = frozenset(range(5))
    base_allow = frozenset({P.OFFSET})

    def size(lists, allow, fixed_t=None, index=True):
        tot = 0
        for n in new_names:
            items = lists[n]
            if not items or isinstance(items[0], str):
                tot += plain_new[n]
                continue
            pk = P.pack(n, items, strides.get(n, 1), index_columns=(0, 1, 2) if (n == "tris" and index) else (),
                        allow=allow, fixed_t=fixed_t)
            tot += min(P.packed_bytes(n, pk.text) if pk else plain_new[n], plain_new[n])
        return tot

    rows = []

    def add(label, b, kind):
        rows.append({"idea": label, "kind": kind, "bytes": b, "per_tri": per_tri(b, tris)})

    add("plain lists, old defaults (every colour list the scene has)", sum(old_plain.values()), "cumulative")
    add("+ lists nothing reads left out (vert colors)", sum(plain_new.values()), "cumulative")
    add("+ strings: base-92 symbols, varints (T = 46), offset per column", size(scene_order, base_allow, 46),
        "cumulative")
    add("+ best varint parameter per column", size(scene_order, base_allow), "cumulative")
    add("+ delta columns", size(scene_order, base_allow | {P.DELTA}), "cumulative")
    add("+ palettes", size(scene_order, base_allow | {P.DELTA, P.PALETTE}), "cumulative")
    add("+ constant columns", size(scene_order, base_allow | {P.DELTA, P.PALETTE, P.CONST}), "cumulative")
    add("+ vertices in first-use order, index codes (all ideas)", size(first_use, full), "cumulative")
    full_b = rows[-1]["bytes"]
    for label, b in (("best varint parameter", size(first_use, full, 46)),
                     ("delta columns", size(first_use, full - {P.DELTA})),
                     ("palettes", size(first_use, full - {P.PALETTE})),
                     ("constant columns", size(first_use, full - {P.CONST})),
                     ("index codes", size(first_use, full - {P.INDEX})),
                     ("first-use vertex order (and so index codes)", size(scene_order, full))):
        add(f"all but {label}", b, "leave-one-out")
        rows[-1]["costs"] = b - full_b
        rows[-1]["costs_per_tri"] = per_tri(b - full_b, tris)
    return {"rows": rows}


# --------------------------------------------------------------------------- character lookups
def lookup_costs(n: int = 400_000) -> dict:
    """TurboWarp compiled, ns per character of three ways to read one: `letter of` alone, a costume
    switch by name (case-sensitive, what the loader does) and `item # of` in a 92-item list
    (case-insensitive, so it could not tell A from a; measured for comparison)."""
    import random

    import turbowarp
    from bake.scratch import blocks as B
    from bake.scratch.textimage import ALPHABET

    rnd = random.Random(1)
    text = "".join(rnd.choice(P.ALPHABET[:60]) for _ in range(n))
    i, t = B.var("i"), B.var("t")
    bodies = {
        "letter_of": [B.set_var("s", B.letter_of(i, t)), B.change_var("i", 1)],
        "costume": [B.switch_costume(B.letter_of(i, t)), B.set_var("s", B.item(B.costume_number(), "sym")),
                    B.change_var("i", 1)],
        "item_number_of": [B.set_var("s", B.item_number(B.letter_of(i, t), "alpha")), B.change_var("i", 1)],
    }
    files = []
    tmp = Path(tempfile.mkdtemp(prefix="bench-lookup-"))
    asset = sb3.Asset(sb3.SPRITE_SVG, "svg")
    for name, body in bodies.items():
        b = B.Builder(B.Scope("S", variables=["i", "s", "t"], lists=["sym", "alpha"]))
        b.define("go", [], [B.set_var("i", 1), B.repeat(n, body)])
        target = sb3.Target("S", variables={"i": 0, "s": 0, "t": text}, lists={"sym": list(range(94)),
                                                                                "alpha": list(P.ALPHABET)},
                            costumes=[sb3.Costume(ch, asset, 1, (1.0, 1.0)) for ch in ALPHABET], blocks=b.build(),
                            layer_order=1, visible=False)
        f = tmp / f"{name}.sb3"
        f.write_bytes(sb3.write_sb3([sb3.Target("Stage", is_stage=True), target])[0])
        files.append((name, f))
    run = turbowarp.run(files, modes=("compiled",), repeat=3, action={"call": {"target": "S", "proccode": "go",
                                                                               "args": []}})
    return {r.id: {"ns_per_char": [round(x["stepSeconds"] / n * 1e9, 1) for x in r.runs],
                   "median": round(float(np.median([x["stepSeconds"] / n * 1e9 for x in r.runs])), 1)}
            for r in run.results} | {"characters": n, "load": load()}


# --------------------------------------------------------------------------- runs
def run_vm(jobs: list[dict]) -> list[dict]:
    r = subprocess.run(["node", str(REPO / "vm" / "run.js"), "--plan", "-"], input=json.dumps({"jobs": jobs}),
                       capture_output=True, text=True, timeout=7200)
    if not r.stdout.strip():
        raise SystemExit(f"vm/run.js failed: {r.stderr[-2000:]}")
    return json.loads(r.stdout)["jobs"]


def same_items(a: list, b: list) -> bool:
    return len(a) == len(b) and all((x == y) if isinstance(y, str) else repr(float(x)) == repr(float(y))
                                    for x, y in zip(a, b))


def load() -> str:
    try:
        return " ".join(f"{x:.2f}" for x in os.getloadavg())
    except OSError:
        return "?"


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true", help="the small models only (no 69k bunny)")
    ap.add_argument("--no-turbowarp", action="store_true", help="skip the TurboWarp timings")
    ap.add_argument("--no-vm", action="store_true", help="skip the scratch-vm runs")
    ap.add_argument("--baseline", type=Path, help="another checkout (e.g. ../main): its packed 2k and 69k "
                    "bunnies, split and timed in the same run")
    args = ap.parse_args()
    if not BUNNY.exists():
        raise SystemExit(f"needs the corpus: {BUNNY} not found (set BAKE_CORPUS)")
    tmp = Path(tempfile.mkdtemp(prefix="bench-pack-"))
    result = {"machine": {"python": platform.python_version(), "cpus": os.cpu_count(), "load_start": load()},
              "command": "benchmarks/bench_pack.py" + (" --quick" if args.quick else ""), "models": {}, "ideas": {},
              "lossy": {}}
    t_start = time.perf_counter()
    baked = {}
    for key, m in models(args.quick).items():
        cfg = m["config"]
        d = tmp / key
        d.mkdir()
        (d / "old").mkdir()
        (d / "plain").mkdir()
        (d / "packed").mkdir()
        # the old defaults: every colour list the scene has (a lit scene has both), the scene's vertex order
        old = bake(with_export(cfg, vertex_colors="yes" if cfg.lighting.enabled else "auto", vertex_order="scene"),
                   d / "old")
        plain = bake(cfg, d / "plain")
        packed = bake(with_export(cfg, pack=True, pack_max_items=0), d / "packed")
        baked[key] = (old, plain, packed)
        T = len(plain["lists"]["tris"]) // 4
        pk = packed["export"].details.get("pack", {"lists": [], "decode_blocks": 0, "packed_bytes": 0,
                                                    "plain_bytes": 0})
        rows = {r["list"]: r for r in pk["lists"]}
        lists = {}
        for name, inf in plain["info"].items():
            pinf = packed["info"][name]
            lists[name] = {"items": inf["items"], "plain_bytes": inf["project_json_bytes"],
                           "packed_bytes": pinf["project_json_bytes"], "packed": name in rows,
                           "plain_per_tri": per_tri(inf["project_json_bytes"], T),
                           "packed_per_tri": per_tri(pinf["project_json_bytes"], T),
                           "coding": ", ".join(c["mode"] + (f"×{c['columns']}" if c["columns"] > 1 else "")
                                               for c in rows[name]["columns"]) if name in rows else "plain",
                           "decode_blocks": rows[name]["decode_blocks"] if name in rows else 0}
            # lossless: the Python mirror of the loader gives the plain list back
            if name in rows:
                stored = sb3.load_project(packed["path"])[0]
                texts = [e[1] for t in stored["targets"] for e in (t.get("lists") or {}).values()
                         if e[0] == "packed lists"][0]
                text = next(x for x in texts if P.header_name(x) == name)
                lists[name]["lossless_python"] = P.unpack(text, name).items == plain["lists"][name]
        old_total = sum(v["project_json_bytes"] for v in old["info"].values())
        plain_total = sum(v["project_json_bytes"] for v in plain["info"].values())
        packed_total = sum(v["project_json_bytes"] for v in packed["info"].values())
        loader_bytes = (packed["pj"] - packed_total) - (plain["pj"] - plain_total)
        result["models"][key] = {
            "label": m["label"], "triangles": T, "vertices": len(plain["lists"]["verts"]) // 3,
            "lists": lists,
            "left_out": [e["list"] for e in plain["export"].details.get("lists_left_out", [])],
            "old_lists_bytes": old_total, "plain_lists_bytes": plain_total, "packed_lists_bytes": packed_total,
            "old_per_tri": per_tri(old_total, T), "plain_per_tri": per_tri(plain_total, T),
            "packed_per_tri": per_tri(packed_total, T),
            "packed_ratio": round(packed_total / plain_total, 4), "old_ratio": round(packed_total / old_total, 4),
            "project_json_old": old["pj"], "project_json_plain": plain["pj"], "project_json_packed": packed["pj"],
            "fits_5mib_plain": plain["pj"] <= 5 * 1024 * 1024, "fits_5mib_packed": packed["pj"] <= 5 * 1024 * 1024,
            "project_json_packed_of_5mib": round(packed["pj"] / (5 * 1024 * 1024), 4),
            "loader_bytes": loader_bytes, "loader_per_tri": per_tri(loader_bytes, T),
            "packed_with_loader_per_tri": per_tri(packed_total + loader_bytes, T),
            "decode_blocks": pk["decode_blocks"], "decode_blocks_per_1000_tris": round(pk["decode_blocks"] / T * 1000),
            "max_decoded_items": max((v["items"] for v in lists.values() if v["packed"]), default=0),
            "lossless_python": all(v.get("lossless_python", True) for v in lists.values()),
            "bake_seconds": {"plain": round(plain["seconds"], 3), "packed": round(packed["seconds"], 3)},
            "export_seconds": {"plain": round(plain["export"].seconds, 3), "packed": round(packed["export"].seconds, 3)},
            "split": {"plain": project_split(plain["path"], T), "packed": project_split(packed["path"], T)},
        }
        print(f"{key}: {T} triangles, lists {per_tri(old_total, T)} -> {per_tri(plain_total, T)} -> "
              f"{per_tri(packed_total, T)} B/tri; project.json {packed['pj']:,}", flush=True)

    # the same packed bakes with another checkout: the split, and below its 69k decode time
    baseline = {}
    if args.baseline:
        for key in ("bunny2k", "bunny69k"):
            if key in baked:
                recipe = {**models(args.quick)[key]["recipe"], "export": {"pack": True, "pack_max_items": 0}}
                f, T = bake_with_tree(args.baseline.resolve(), recipe, tmp / key / "baseline.sb3")
                baseline[key] = f
                result.setdefault("baseline", {"tree": str(args.baseline), "models": {}})
                commit = subprocess.run(["git", "-C", str(args.baseline), "rev-parse", "--short", "HEAD"],
                                        capture_output=True, text=True).stdout.strip()
                result["baseline"]["commit"] = commit
                result["baseline"]["models"][key] = {"split": project_split(f, T)}
                print(f"{key} baseline ({commit}): project.json {result['baseline']['models'][key]['split']['bytes']['total']:,}",
                      flush=True)

    # scratch-vm: the loader's blocks and the rebuilt lists (not the 69k BSP bunny: ~2 minutes of VM)
    if not args.no_vm:
        keys = [k for k in baked if k != "bunny69k_bsp"]
        jobs = [{"load": str(baked[k][2]["path"]), "runs": [
            {"call": {"target": "Mesh", "proccode": "unpack lists", "args": []},
             "read": {"target": "Stage", "lists": list(baked[k][1]["lists"])}},
            {"read": {"target": "Mesh", "variables": ["unpack error"]}}]} for k in keys]
        out = run_vm(jobs)
        for k, res in zip(keys, out):
            run, state = res["runs"]
            m = result["models"][k]
            # vanilla rebuilds lists of up to 200,000 items (`add to list`); a longer one is an error, left empty
            small = {n: items for n, items in baked[k][1]["lists"].items() if len(items) <= 200_000}
            m["vm"] = {"blocks": run["blocks"], "ms": round(run["ms"], 1), "done": run["done"],
                       "blocks_equal_model": run["blocks"] == m["decode_blocks"],
                       "unpack_error": state["variables"]["unpack error"],
                       "lists_checked": len(small), "lists_over_200000": len(baked[k][1]["lists"]) - len(small),
                       "lossless": all(same_items(run["lists"][n], items) for n, items in small.items())}
            print(f"{k}: scratch-vm {run['blocks']:,} blocks ({run['ms']:.0f} ms), model "
                  f"{'equal' if m['vm']['blocks_equal_model'] else 'different'}, lossless {m['vm']['lossless']} "
                  f"({len(small)} lists; error {m['vm']['unpack_error']!r})", flush=True)

    # TurboWarp: seconds of `unpack lists`, compiled and interpreted
    if not args.no_turbowarp:
        import turbowarp

        why = turbowarp.unavailable()
        if why:
            result["turbowarp_skipped"] = why
        else:
            keys = list(baked)
            result["lookups"] = lookup_costs()
            print(f"character lookups, ns: {result['lookups']}", flush=True)
            for k in keys:  # one model at a time: every list is read back and compared
                pair = [(k, baked[k][2]["path"])] + ([(f"{k}@baseline", baseline[k])] if k in baseline else [])
                run = turbowarp.run(pair, modes=("compiled", "interpreted"), repeat=3,
                                    action={"call": {"target": "Mesh", "proccode": "unpack lists", "args": []}},
                                    read={"target": "Stage", "lists": list(baked[k][1]["lists"]), "variables": []},
                                    timeout_ms=900_000)
                result["turbowarp_versions"] = run.versions
                for r in run.results:
                    secs = [x["stepSeconds"] for x in r.runs]
                    # (the baseline's own lists are not at hand: another checkout may write others)
                    lossless = None if "@" in r.id else all(same_items(r.lists.get(n, []), items)
                                                            for n, items in baked[k][1]["lists"].items())
                    where = result["models"][r.id] if "@" not in r.id else result["baseline"]["models"][k]
                    where.setdefault("turbowarp", {})[r.mode] = {
                        "seconds": [round(s, 4) for s in secs], "median": round(float(np.median(secs)), 4),
                        "min": round(min(secs), 4), "errors": r.errors[:3], "lossless": lossless, "load": load()}
                    print(f"{r.id} {r.mode}: {', '.join(f'{s:.3f}' for s in secs)} s, lossless {lossless} "
                          f"(load {load()})", flush=True)

    # the split of project.json, one row per bake (docs/formats.md's table): plain, the baseline's
    # packed and this tree's packed for the bunnies, this tree's packed for the others
    rows = {}
    for key, m in result["models"].items():
        for kind, split, tw in (("plain", m["split"]["plain"], None),
                                ("baseline", result.get("baseline", {}).get("models", {}).get(key, {}).get("split"),
                                 result.get("baseline", {}).get("models", {}).get(key, {}).get("turbowarp")),
                                ("packed", m["split"]["packed"], m.get("turbowarp"))):
            if split is None or (kind == "plain" and key not in result.get("baseline", {}).get("models", {})):
                continue
            label = {"plain": f"{m['label']}: plain", "packed": f"{m['label']}: packed",
                     "baseline": f"{m['label']}: packed at {result['baseline']['commit']} (before)"
                     if kind == "baseline" else ""}[kind]
            rows[f"{key} {kind}"] = {"bake": label, "triangles": split["written_triangles"], **split["per_tri"],
                                     "bytes": split["bytes"]["total"],
                                     "blocks_per_tri": round(split["per_tri"]["loader_blocks"]
                                                             + split["per_tri"]["reader_blocks"], 3),
                                     "costumes_variables_other_per_tri": round(
                                         split["per_tri"]["costumes"] + split["per_tri"]["variables"]
                                         + split["per_tri"]["other"], 3),
                                     "compiled_s": (tw or {}).get("compiled", {}).get("median")}
    result["split_rows"] = rows

    # ideas one at a time (bytes), on the 2k and 69k bunnies
    for key in ("bunny2k", "bunny69k_bsp"):
        if key not in baked:
            continue
        old, plain, packed = baked[key]
        cfg = models(args.quick)[key]["config"]
        scene = bake(with_export(cfg, vertex_order="scene"), tmp / key / "old")
        strides = {n: plain["res"].scene.lists[n].stride for n in plain["lists"] if n in plain["res"].scene.lists}
        T = len(plain["lists"]["tris"]) // 4
        old_plain = {n: v["project_json_bytes"] for n, v in old["info"].items()}
        result["ideas"][key] = ideas(plain["lists"], {n: scene["lists"][n] for n in plain["lists"]}, old_plain,
                                     strides, T)
        for row in result["ideas"][key]["rows"]:
            print(f"  {key} {row['idea']}: {row['bytes']:,} ({row['per_tri']} B/tri)", flush=True)

    # format changes that cost accuracy (2k bunny)
    base = models(True)["bunny2k"]["config"]
    lossy = {"precision": [], "plane_decimals": []}
    for prec in (3, 4, 5, 6):
        c = with_export(base, precision=prec, pack=True)
        b = bake(c, tmp / "bunny2k" / "packed")
        T = len(b["lists"]["tris"]) // 4
        tot = sum(v["project_json_bytes"] for v in b["info"].values())
        pos = b["export"].details.get("positions", {})
        lossy["precision"].append({"value": prec, "triangles": T, "packed_bytes": tot,
                                          "per_tri": per_tri(tot, T), "verts_bytes": b["info"]["verts"]["project_json_bytes"],
                                          "error_of_diagonal": pos.get("max_error_of_diagonal"),
                                          "decimals": pos.get("decimals")})
    for dec in (4, 5, 6, 8):
        import copy
        import dataclasses

        c = copy.deepcopy(base)
        c.bsp = dataclasses.replace(c.bsp, plane_decimals=dec, epsilon=max(c.bsp.epsilon, 10.0 ** -dec))
        c = with_export(c, pack=True)
        b = bake(c, tmp / "bunny2k" / "packed")
        T = len(b["lists"]["tris"]) // 4
        tot = sum(v["project_json_bytes"] for v in b["info"].values())
        bsp = next(r for r in b["res"].records if r.name == "bsp")
        lossy["plane_decimals"].append({"value": dec, "triangles": T, "packed_bytes": tot, "per_tri": per_tri(tot, T),
                                            "planes_bytes": b["info"]["bsp planes"]["project_json_bytes"],
                                            "inflation": bsp.accuracy.get("inflation", bsp.details.get("inflation"))})
    result["lossy"] = lossy
    result["machine"]["load_end"] = load()
    result["seconds"] = round(time.perf_counter() - t_start, 1)
    OUT.parent.mkdir(parents=True, exist_ok=True)
    OUT.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {OUT} in {result['seconds']} s (load {result['machine']['load_start']} -> {result['machine']['load_end']})")


if __name__ == "__main__":
    main()
