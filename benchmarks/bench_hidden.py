"""The hidden-geometry stage (``[mesh.hidden]``, docs/hidden.md) on corpus models.

    PYTHONPATH=. .venv/bin/python benchmarks/bench_hidden.py [--models suzanne,teapot] [--holdout 200]
        [--out benchmarks/results/hidden.json]

Per model, on the scene as cleaned (the stage's input in a bake): triangles before and after,
the bytes the lists add to project.json with the stage off and on (the export stage's own figure,
``project_json_bytes``), the held-out proof (``--holdout`` eyes not used to decide, a pixel grid
each: wrong pixels, pixels showing the model), the stage's seconds (deciding, and the proof), and
against them the seconds of a 64-sample AO bake of the same scene (the lighting stage with AO
alone, ``target = "vertex"``; the issue's cost bound), and the same decided without the witness eyes
(``without_witness``: the refinement rounds' random eyes alone, the method before the messy models).
Suzanne is also built into a BSP tree with the stage off, on, and on with ``trim = true`` (split
inflation, triangles written; the same trees with tree seeds 0 to 7, ``bsp_seeds``), and decided
again with seeds 0 to 7 (each with its own held-out eyes: the wrong pixels per seed). The CAD-style
models (the subpass scene, the KUKA arm segment of benchmarks/messy_models.json when present) are
built into BSP trees the same three ways (``cad_bsp``). The subpass scene is decided again with ``refine`` 0, 2, 4
and 8 (the cost's floor: what fewer refinement eyes cost and what they miss). The Cornell box is seen from an inside box region (the
middle 60% of the room), the rest from outside. Single runs on a shared 2-core machine: the CPU
seconds are given beside the wall seconds.

Also, from outside, the public models found for the simplify issue (a CAD assembly, furniture, CAD
parts, game assets, a vehicle: benchmarks/messy_models.json, with source, licence and sha256). They
are not committed: they are read from ``--models-dir`` (default benchmarks/models/, or
BAKE_MESSY_MODELS), and one that is missing or whose bytes differ is skipped, saying so (stdout
and ``skipped`` in the JSON), as bench_simplify_messy.py does.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import platform
import time
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
MANIFEST = REPO / "benchmarks" / "messy_models.json"

MODELS = {
    "suzanne": ("suzanne_obj/suzanne.obj", "outside"),
    "teapot": ("teapot_obj/teapot.obj", "outside"),
    "spot": ("spot_triangulated/spot/spot_triangulated.obj", "outside"),
    "bunny": ("stanford_bunny_res1_obj/stanford-bunny.obj", "outside"),
    "duck": ("duck_glb/Duck.glb", "outside"),
    "subpass_scene": ("subpass_scene/subpass_scene_opaque.gltf", "outside"),
    "three_story_building": ("three_story_building_noindices/no_indices_3storybuilding.glb", "outside"),
    "cornell_box": ("cornell_box_tinyobj/cornell_box.obj", "inside"),
}


# the public models of the simplify issue (messy_models.json), all seen from outside
MESSY = {m["name"]: (m["file"], "outside") for m in json.loads(MANIFEST.read_text())["models"]}


def messy_check(name: str, folder: Path) -> str | None:
    """Why the messy model ``name`` cannot be run from ``folder`` (None: its files are there, with
    the recorded sha256)."""
    m = next(x for x in json.loads(MANIFEST.read_text())["models"] if x["name"] == name)
    bad = [f for f, h in m["files"].items()
           if not (folder / f).is_file() or hashlib.sha256((folder / f).read_bytes()).hexdigest() != h]
    if bad:
        return (f"{name}: {', '.join(bad)} missing or not the recorded bytes (get it from "
                f"{m['repo']}@{m['commit'][:10]}: {m['path']})")
    return None


def timed(fn):
    t, c = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - t, time.process_time() - c


def list_bytes(res) -> int:
    ex = next(r for r in res.records if r.name == "export")
    return int(sum(v["project_json_bytes"] for v in ex.details["lists"].values()))


def run_model(key: str, holdout: int, folder: Path | None = None) -> dict:
    from bake import pipeline
    from bake.config import AOConfig, LightingConfig
    from bake.lighting.stage import stage as lighting_stage
    from bake.mesh.hidden.stage import job, stage as hidden_stage

    rel, region = MODELS[key] if key in MODELS else MESSY[key]
    path = CORPUS / rel if key in MODELS else folder / rel
    base = ["export.sb3=false", "export.sprite3=false", "export.reader=false"]
    cfg = pipeline.load_config_for(path, base)
    cleaned = pipeline.run(cfg, until="clean", cache=None).scene
    sets = ["mesh.hidden.enabled=true", f"mesh.hidden.holdout_eyes={holdout}"]
    if region == "inside":
        lo, hi = cleaned.bounds()
        a, b = lo + 0.2 * (hi - lo), hi - 0.2 * (hi - lo)
        sets += ["mesh.hidden.outside=false",
                 f"mesh.hidden.boxes=[{{min = {[float(x) for x in a]}, max = {[float(x) for x in b]}}}]"]
    on = pipeline.load_config_for(path, base + sets)
    (out, rec), wall, cpu = timed(lambda: hidden_stage(cleaned, job(on)))
    d = rec.details
    ao_cfg = LightingConfig(enabled=True, ambient=[1.0, 1.0, 1.0], ao=AOConfig(enabled=True, samples=64))
    _, ao_wall, ao_cpu = timed(lambda: lighting_stage(cleaned, ao_cfg))
    bytes_off = list_bytes(pipeline.run(cfg, cache=None))
    bytes_on = list_bytes(pipeline.run(on, cache=None))
    h = d["holdout"]
    row = {
        "model": key, "file": rel, "region": region, "set": "corpus" if key in MODELS else "messy",
        "triangles_in": rec.counts_in["triangles"], "triangles_out": rec.counts_out["triangles"],
        "dropped": d["dropped"], "dropped_share": d["dropped"] / max(rec.counts_in["triangles"], 1),
        "bytes_off": bytes_off, "bytes_on": bytes_on, "bytes_saved": bytes_off - bytes_on,
        "holdout_eyes": h["eyes"], "holdout_pixels": h["pixels"], "pixels_showing": h["pixels_showing_the_model"],
        "wrong_pixels": h["wrong_pixels"], "dropped_seen_by_holdout": h["dropped_triangles_seen"],
        "decide_rays": d["rays"], "decide_seconds": d["decide_seconds"], "proof_seconds": h["seconds"],
        "stage_seconds": round(wall, 4), "stage_cpu_seconds": round(cpu, 4),
        "ao64_seconds": round(ao_wall, 4), "ao64_cpu_seconds": round(ao_cpu, 4),
        "decide_over_ao64": round(d["decide_seconds"] / max(ao_wall, 1e-9), 3),
        "rounds": d["rounds"],
    }
    # the same decided without the witness eyes (the refinement rounds' random eyes alone: the method
    # before issue 42's messy models, byte-identical to it): what the witness rounds keep and cost
    from bake.mesh.hidden import stage as stage_mod

    saved = stage_mod.DIRECTED_EYES, stage_mod.DIRECTED_ROUNDS
    stage_mod.DIRECTED_EYES, stage_mod.DIRECTED_ROUNDS = 0, 0
    try:
        _, r0 = hidden_stage(cleaned, job(on))
    finally:
        stage_mod.DIRECTED_EYES, stage_mod.DIRECTED_ROUNDS = saved
    h0 = r0.details["holdout"]
    row["without_witness"] = {
        "triangles_out": r0.counts_out["triangles"], "wrong_pixels": h0["wrong_pixels"],
        "pixels_showing": h0["pixels_showing_the_model"], "dropped_seen_by_holdout": h0["dropped_triangles_seen"],
        "decide_rays": r0.details["rays"], "decide_seconds": r0.details["decide_seconds"]}
    row["witness_rounds"] = len(d["rounds"]) - 1
    row["witness_seen"] = int(sum(x.get("directed_seen", 0) for x in d["rounds"][1:]))
    row["kept_over_without_witness"] = rec.counts_out["triangles"] - r0.counts_out["triangles"]
    if key == "subpass_scene":
        # the floor of the cost (issue 42): fewer refinement eyes, what they cost and what they miss
        row["refine_sweep"] = []
        # (and fewer first-pass eyes with no refinement: the stage near the AO-64's own cost)
        for eyes, refine in ((64, 0), (64, 2), (64, 4), (64, 8), (8, 0), (16, 0)):
            c2 = pipeline.load_config_for(path, base + sets + [f"mesh.hidden.refine={refine}",
                                                               f"mesh.hidden.eyes={eyes}"])
            _, r2 = hidden_stage(cleaned, job(c2))
            row["refine_sweep"].append({
                "eyes": eyes, "refine": refine, "eyes_a_round": r2.details["rounds"][1]["eyes"] if refine else 0,
                "decide_rays": r2.details["rays"], "decide_seconds": r2.details["decide_seconds"],
                "decide_over_ao64": round(r2.details["decide_seconds"] / max(ao_wall, 1e-9), 3),
                "dropped": r2.details["dropped"], "wrong_pixels": r2.details["holdout"]["wrong_pixels"],
                "dropped_seen_by_holdout": r2.details["holdout"]["dropped_triangles_seen"]})
    if key == "suzanne":
        row["bsp"] = bsp_compare(path, base, sets, rec.counts_in["triangles"])
        # the tree's own seed moves its count by tens of triangles: the same trees with seeds 0-7
        row["bsp_seeds"] = bsp_seed_sweep(path, base, sets)
        # the same with other seeds: how often the held-out eyes find a dropped triangle
        row["seeds"] = []
        for seed in range(8):
            c2 = pipeline.load_config_for(path, base + sets + [f"mesh.hidden.seed={seed}"])
            _, r2 = hidden_stage(cleaned, job(c2))
            row["seeds"].append({"seed": seed, "dropped": r2.details["dropped"],
                                 "wrong_pixels": r2.details["holdout"]["wrong_pixels"],
                                 "pixels_showing": r2.details["holdout"]["pixels_showing_the_model"],
                                 "dropped_seen_by_holdout": r2.details["holdout"]["dropped_triangles_seen"]})
    return row


BSP_STAGES = (("off", None), ("on", []), ("on, trim = true", ["mesh.hidden.trim=true"]))


def bsp_compare(path: Path, base: list[str], sets: list[str], n_model: int) -> dict:
    """The model into a BSP tree (``bsp.enabled``, its defaults) with the hidden stage off, on, and
    on with trimming: triangles in and after the splits, inflation, written against the model, and
    the hidden stage's held-out proof and trimming figures."""
    from bake import pipeline

    bsp = {}
    for name, more in BSP_STAGES:
        # (the stage's own BSP proof off: these runs build the trees it would build)
        c2 = pipeline.load_config_for(path, base + ([] if more is None else sets + more + ["mesh.hidden.bsp_proof=false"])
                                      + ["bsp.enabled=true"])
        t = time.perf_counter()
        res = pipeline.run(c2, cache=None)
        wall = time.perf_counter() - t
        b = next(r for r in res.records if r.name == "bsp")
        bsp[name] = {"triangles_in": b.counts_in["triangles"], "triangles_out": b.counts_out["triangles"],
                     "inflation": round(b.accuracy["inflation"], 4),
                     "out_vs_model": round(b.counts_out["triangles"] / n_model - 1.0, 4),
                     "splits": b.details["splits"], "crossing_pairs_in": b.details["crossing"].get("pairs"),
                     "bsp_seconds": round(b.seconds, 4), "bake_seconds": round(wall, 4)}
        h = next((r for r in res.records if r.name == "hidden"), None)
        if h is not None:
            hh = h.details["holdout"]
            bsp[name].update({"hidden_seconds": round(h.seconds, 4), "wrong_pixels": hh["wrong_pixels"],
                              "pixels_showing": hh["pixels_showing_the_model"], "holdout_eyes": hh["eyes"],
                              "trim": h.details.get("trim")})
    return bsp


def bsp_seed_sweep(path: Path, base: list[str], sets: list[str], seeds: range = range(8)) -> list[dict]:
    """Triangles the tree writes with the stage on and on with trimming, for tree seeds
    (``bsp.seed``) 0-7: how much of a difference between the two is the tree's own scatter."""
    from bake import pipeline

    out = []
    for seed in seeds:
        row: dict = {"seed": seed}
        for name, more in BSP_STAGES[1:]:
            c2 = pipeline.load_config_for(path, base + sets + more + ["bsp.enabled=true", f"bsp.seed={seed}",
                                                                      "mesh.hidden.holdout_eyes=0", "mesh.hidden.bsp_proof=false"])
            b = next(r for r in pipeline.run(c2, cache=None).records if r.name == "bsp")
            row["trim" if more else "on"] = b.counts_out["triangles"]
            row[("trim" if more else "on") + "_in"] = b.counts_in["triangles"]
        row["trim_minus_on"] = row["trim"] - row["on"]
        out.append(row)
    on = [r["on"] for r in out]
    tr = [r["trim"] for r in out]
    out.append({"seed": "mean", "on": round(sum(on) / len(on), 1), "trim": round(sum(tr) / len(tr), 1),
                "on_in": out[0]["on_in"], "trim_in": out[0]["trim_in"],
                "trim_minus_on": round((sum(tr) - sum(on)) / len(on), 1)})
    return out


# the CAD-style models of issue 42's "measure what it buys": the BSP with the stage off, on, on + trim
CAD_BSP = {
    "subpass_scene": ("corpus", "subpass_scene/subpass_scene_opaque.gltf"),
    "segment": ("models", "segment/segment.obj"),  # KUKA arm segment (benchmarks/messy_models.json)
}
MODELS_DIR = Path(os.environ.get("BAKE_MESSY_MODELS", REPO / "benchmarks" / "models"))


def run_cad_bsp(holdout: int) -> dict:
    from bake import pipeline

    out = {}
    for key, (where, rel) in CAD_BSP.items():
        path = (CORPUS if where == "corpus" else MODELS_DIR) / rel
        if not path.exists():
            print(f"cad_bsp {key}: {path} missing, skipped")
            continue
        base = ["export.sb3=false", "export.sprite3=false", "export.reader=false"]
        cleaned = pipeline.run(pipeline.load_config_for(path, base), until="clean", cache=None).scene
        sets = ["mesh.hidden.enabled=true", f"mesh.hidden.holdout_eyes={holdout}"]
        out[key] = {"file": rel, "triangles": cleaned.n_triangles,
                    "bsp": bsp_compare(path, base, sets, cleaned.n_triangles)}
        for name, r in out[key]["bsp"].items():
            print(f"cad_bsp {key} ({name}): {r['triangles_in']:,} -> {r['triangles_out']:,} ({r['inflation']:+.1%}), "
                  f"wrong pixels {r.get('wrong_pixels')}, {r['bake_seconds']:.1f} s", flush=True)
    return out


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--models", default=",".join(list(MODELS) + list(MESSY)),
                    help="comma-separated: corpus keys and messy model names")
    ap.add_argument("--models-dir", default=os.environ.get("BAKE_MESSY_MODELS", str(REPO / "benchmarks" / "models")))
    ap.add_argument("--holdout", type=int, default=200)
    ap.add_argument("--out", default=str(REPO / "benchmarks" / "results" / "hidden.json"))
    ap.add_argument("--no-cad-bsp", action="store_true", help="leave out the CAD models' BSP comparison")
    a = ap.parse_args()
    load_before = os.getloadavg()[0]  # the 1-minute load when the run starts
    rows, skipped = [], []
    folder = Path(a.models_dir)
    for key in [m for m in a.models.split(",") if m]:
        if key in MODELS:
            where = CORPUS / MODELS[key][0]
            why = None if where.exists() else f"{key}: not in the corpus ({where})"
        elif key in MESSY:
            why = messy_check(key, folder)
        else:
            why = f"{key}: not a model of this benchmark"
        if why:
            skipped.append(why)
            print("skip", why, flush=True)
            continue
        row = run_model(key, a.holdout, folder)
        rows.append(row)
        print(f"{key}: {row['triangles_in']:,} -> {row['triangles_out']:,} triangles, {row['bytes_saved']:,} bytes "
              f"saved, {row['wrong_pixels']} wrong of {row['pixels_showing']:,} pixels from {row['holdout_eyes']} "
              f"held-out eyes; decide {row['decide_rays']:,} rays in {row['decide_seconds']:.2f} s, AO-64 "
              f"{row['ao64_seconds']:.2f} s", flush=True)
    doc = {"command": "benchmarks/bench_hidden.py " + f"--holdout {a.holdout}",
           "machine": {"python": platform.python_version(), "cpus": os.cpu_count(),
                       "load_before": load_before, "load_after": os.getloadavg()[0]},
           "defaults": {"eyes": 64, "samples": 2, "refine": 8, "refine_rounds": 3, "holdout_pixels": 64},
           "skipped": skipped, "models": {r["model"]: r for r in rows}, "rows": rows}
    if not a.no_cad_bsp:
        doc["cad_bsp"] = run_cad_bsp(a.holdout)
    Path(a.out).write_text(json.dumps(doc, indent=1) + "\n")
    print(f"wrote {a.out}")


if __name__ == "__main__":
    main()
