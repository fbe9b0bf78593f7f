"""Lightmap machinery and texture encodings: figures for docs/formats-textures.md.

    .venv/bin/python benchmarks/bench_lightmap.py [--out benchmarks/results/lightmap.json]
        [--quick] [--no-crash]

1. **Lightmap machinery** on the Cornell box (cornell_box_tinyobj) and the house
   (house_max2obj_walls) at several atlas resolutions: xatlas time (a fresh run, cache off) and
   cached time, atlas size, charts, utilisation, coverage, samples and samples pushed, texels
   shared by two charts, and with a closed-form smooth "lighting" f(position): the seam error
   before/after stitching (smooth seams, and over all UV seams), and the interpolation error of
   bilinear lookups at 20,000 random surface points (RMS and 99th percentile, as a fraction of
   f's range). Times: samples (incl. push-out), splat + dilate + stitch.
2. **Real lighting** of the Cornell box's lightmap through the lighting stage's kernels (point
   light with soft shadows, one bounce as a final gather): time, rays, seam error in 8 bits.
3. **The xatlas crash**: a perfectly smooth 6-times subdivided icosphere (81,920 triangles)
   crashes xatlas 0.0.11; the time until the bake reports it.
4. **Texture encodings** of every textured corpus model at max_size 64, 128 and 256: items,
   project.json bytes, asset bytes and deflated bytes of the colour list, the TextImage string
   and the PNG costume.
"""

from __future__ import annotations

import argparse
import dataclasses
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

from bake import pipeline  # noqa: E402
from bake.config import LightConfig, LightingConfig, LightmapConfig, TexturesConfig  # noqa: E402
from bake.errors import StageError  # noqa: E402
from bake.scene import make_scene  # noqa: E402
from bake.lighting import lightmap as lighting_lightmap  # noqa: E402
from bake.lighting.rays import Tracer  # noqa: E402
from bake.textures import lightmap as lm  # noqa: E402
from bake.textures.seams import SEAM_MAX_ANGLE, seam_error  # noqa: E402
from bake.textures.texels import bilinear, face_normals  # noqa: E402
from bake.textures.unwrap import unwrap  # noqa: E402
from bake.textures import stage as tstage  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))
MODELS = {"cornell_box": ("cornell_box_tinyobj", "cornell_box.obj", "y"),
          "house": ("house_max2obj_walls", "regr01.obj", "z")}
TEXTURED = [("spot_triangulated", "spot/spot_triangulated.obj", "spot_texture.png"),
            ("capsule_textured", "capsule.obj", ""), ("fuze_textured", "fuze.obj", ""),
            ("duck_glb", "Duck.glb", ""), ("box_textured_glb", "BoxTextured.glb", ""),
            ("box_textured_gltf_separate", "BoxTextured.gltf", ""),
            ("alpha_blend_mode_test", "AlphaBlendModeTest.glb", "")]


def load(folder: str, file: str, up: str = "y"):
    cfg = pipeline.load_config_for(CORPUS / folder / file)
    cfg.transform.up = up
    return pipeline.run(cfg, until="clean").scene


def smooth_function(scene):
    lo, hi = scene.bounds()
    size = float((hi - lo).max())
    k = np.array([2.0, 1.5, 1.0]) / size

    def f(p, n, t):
        q = p - lo
        return np.stack([0.5 + 0.4 * np.sin(k[0] * q[:, 0] + 1.0),
                         0.5 + 0.4 * np.cos(k[1] * q[:, 1] + k[2] * q[:, 2]),
                         (q @ np.ones(3)) / (3 * size)], axis=1)

    return f


def surface_points(scene, atlas, n, seed=0):
    rng = np.random.default_rng(seed)
    _, area = face_normals(scene.positions, scene.triangles)
    w = area * atlas.mapped
    t = rng.choice(len(w), size=n, p=w / w.sum())
    r = rng.uniform(size=(n, 2))
    flip = r.sum(axis=1) > 1
    r[flip] = 1 - r[flip]
    bary = np.stack([1 - r.sum(axis=1), r[:, 0], r[:, 1]], axis=1)
    pts = np.einsum("nk,nkd->nd", bary, scene.positions[scene.triangles[t]])
    uv = np.einsum("nk,nkd->nd", bary, atlas.tri_uvs[t])
    return t, pts, uv


def bench_machinery(resolutions, tmp: Path) -> list[dict]:
    rows = []
    for label, (folder, file, up) in MODELS.items():
        scene = load(folder, file, up)
        f = smooth_function(scene)
        for res in resolutions:
            cfg = LightmapConfig(enabled=True, resolution=res, cache_dir=str(tmp / "cache"))
            t = time.perf_counter()
            atlas = unwrap(scene, cfg, cache_dir=None)
            t_fresh = time.perf_counter() - t
            unwrap(scene, cfg)  # fill the cache
            t = time.perf_counter()
            cached = unwrap(scene, cfg)
            t_cached = time.perf_counter() - t
            assert cached.cached and np.array_equal(cached.tri_uvs, atlas.tri_uvs)
            tracer = Tracer(scene.positions, scene.triangles, threads=0, scale=scene.scale())
            out = lm.bake(scene, atlas, f, cfg, tracer=tracer)
            all_seams = seam_error(out.image, atlas, out.seams, smooth_only=False)
            raw = lm.bake(scene, atlas, f, dataclasses.replace(cfg, stitch_seams=False), tracer=tracer)
            all_raw = seam_error(raw.image, atlas, raw.seams, smooth_only=False)
            t_, pts, uv = surface_points(scene, atlas, 20000)
            err = np.abs(bilinear(out.image, uv) - f(pts, None, t_)).max(axis=1)
            fig = out.figures
            row = {
                "model": label, "triangles": scene.n_triangles, "resolution": res,
                "atlas": f"{atlas.width}x{atlas.height}", "charts": atlas.chart_count,
                "utilization_xatlas": round(atlas.utilization, 4), "coverage": fig["coverage"],
                "texels_covered": fig["texels_covered"], "triangles_unmapped": fig["triangles_unmapped"],
                "triangles_without_samples": fig["triangles_without_samples"],
                "texels_two_charts": fig["texels_two_charts"],
                "samples": fig["samples"], "samples_pushed": fig["samples_pushed"],
                "seam_edges": fig["seam_edges"], "seam_edges_smooth": fig["seam_edges_smooth"],
                "seam_error_smooth_before_x255": round(fig["seam_error_before"] * 255, 3),
                "seam_error_smooth_after_x255": round(fig["seam_error"] * 255, 3),
                "seam_error_all_before_x255": round(all_raw["max"] * 255, 3),
                "seam_error_all_after_x255": round(all_seams["max"] * 255, 3),
                "seam_error_all_mean_after_x255": round(all_seams["mean"] * 255, 3),
                "interp_error_rms_x255": round(float(np.sqrt(np.mean(err ** 2))) * 255, 3),
                "interp_error_p99_x255": round(float(np.quantile(err, 0.99)) * 255, 3),
                "xatlas_fresh_s": round(t_fresh, 3), "xatlas_cached_s": round(t_cached, 4),
                "xatlas_inside_s": round(atlas.seconds, 3),
                "samples_s": fig["seconds_samples"], "splat_dilate_stitch_s": fig["seconds_splat_dilate_stitch"],
            }
            rows.append(row)
            print(f"{label:12s} res {res:4d} atlas {row['atlas']:>9s} charts {row['charts']:4d} "
                  f"cov {row['coverage']:.3f} util {row['utilization_xatlas']:.3f} "
                  f"seam smooth {row['seam_error_smooth_before_x255']:.2f}->"
                  f"{row['seam_error_smooth_after_x255']:.2f} "
                  f"all {row['seam_error_all_before_x255']:.2f}->{row['seam_error_all_after_x255']:.2f} /255  "
                  f"interp rms {row['interp_error_rms_x255']:.2f}/255  xatlas {t_fresh:.2f}s "
                  f"samples {row['samples_s']:.2f}s")
    return rows


def bench_real_lighting(tmp: Path) -> dict:
    scene = load(*MODELS["cornell_box"])
    cfg = TexturesConfig(enabled=True, encodings=["list", "textimage", "costume"])
    cfg.lightmap = dataclasses.replace(cfg.lightmap, enabled=True, resolution=256, cache_dir=str(tmp / "cache"))
    scene, _ = tstage.stage(scene, cfg)
    light = LightingConfig(enabled=True, target="triangle", ambient=[0.02] * 3, bounces=dataclasses.replace(
        LightingConfig().bounces, count=1, samples=64),
        lights=[LightConfig(kind="point", position=[278.0, 540.0, -280.0], intensity=2.0e5, radius=40.0)])
    t = time.perf_counter()
    from bake.lighting import stage as lighting_stage

    lit, _ = lighting_stage.stage(scene, light)
    t_light = time.perf_counter() - t
    t = time.perf_counter()
    out, figs = lighting_lightmap.bake_lightmap(lit, light)
    t_map = time.perf_counter() - t
    img = out.artefacts.lightmap_image
    try:
        from PIL import Image

        Image.fromarray(img).save(REPO / "benchmarks" / "results" / "lightmap_cornell.png")
    except OSError:
        pass
    res = {"model": "cornell_box", "atlas": f"{img.shape[1]}x{img.shape[0]}",
           "lighting_stage_s": round(t_light, 3), "lightmap_s": round(t_map, 3),
           "samples": figs["samples"], "samples_pushed": figs["samples_pushed"],
           "seam_error_8bit_x255": round(figs["seam_error_8bit"] * 255, 3), "rays": figs["rays"],
           "seconds_samples": figs["seconds_samples"], "seconds_shade": figs["seconds_shade"],
           "encodings": {k: {kk: v[kk] for kk in ("items", "project_json_bytes", "asset_bytes", "deflated_bytes")}
                         for k, v in figs["encodings"].items()}}
    print(f"cornell lightmap (point light + 1 bounce): lighting {t_light:.2f}s, lightmap {t_map:.2f}s, "
          f"{figs['samples']} samples, seam {res['seam_error_8bit_x255']}/255")
    return res


def bench_crash(tmp: Path) -> dict:
    import trimesh

    m = trimesh.creation.icosphere(6)
    scene = make_scene(m.vertices, m.faces)
    cfg = LightmapConfig(enabled=True, cache_dir="none", timeout=120)
    t = time.perf_counter()
    try:
        unwrap(scene, cfg)
        msg = "no crash (xatlas handled it)"
    except StageError as e:
        msg = str(e)
    dt = time.perf_counter() - t
    print(f"icosphere(6) smooth, {scene.n_triangles} triangles: {dt:.2f}s -> {msg[:90]}")
    return {"mesh": "icosphere(6), perfectly smooth", "triangles": scene.n_triangles, "seconds": round(dt, 3),
            "message": msg}


def bench_encodings(sizes) -> list[dict]:
    rows = []
    for folder, file, texture in TEXTURED:
        path = CORPUS / folder / file
        if not path.exists():
            continue
        scene = pipeline.run(pipeline.load_config_for(path), until="clean").scene
        for size in sizes:
            cfg = TexturesConfig(enabled=True, texture=texture, max_size=size)
            t = time.perf_counter()
            _, rec = tstage.stage(scene, cfg)
            dt = time.perf_counter() - t
            for d in rec.details["textures"]:
                for enc in ("list", "textimage", "costume"):
                    e = d["encodings"][enc]
                    rows.append({"model": folder, "texture": d["name"],
                                 "original": "x".join(map(str, d["original_size"])),
                                 "size": "x".join(map(str, d["size"])), "opaque": d["opaque"], "encoding": enc,
                                 "items": e["items"], "project_json_bytes": e["project_json_bytes"],
                                 "asset_bytes": e["asset_bytes"], "deflated_bytes": e["deflated_bytes"],
                                 "stage_s": round(dt, 3)})
                lst, txt, cos = (d["encodings"][k] for k in ("list", "textimage", "costume"))
                size_txt = "x".join(map(str, d["size"]))
                print(f"{folder:28s} {d['name'][:18]:18s} {size_txt:>8s}  list {lst['project_json_bytes']:8d} B  "
                      f"textimage {txt['project_json_bytes']:7d} B  png {cos['asset_bytes']:7d} B "
                      f"(+{cos['project_json_bytes']} B json)")
    return rows


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "lightmap.json")
    ap.add_argument("--quick", action="store_true", help="one resolution, one texture size")
    ap.add_argument("--no-crash", action="store_true", help="skip the xatlas crash case")
    args = ap.parse_args(argv)
    if not CORPUS.is_dir():
        print(f"corpus not found at {CORPUS} (set BAKE_CORPUS)")
        return 2
    with tempfile.TemporaryDirectory(prefix="bench-lightmap-") as tmp:
        tmp = Path(tmp)
        machinery = bench_machinery([256] if args.quick else [128, 256, 512], tmp)
        real = bench_real_lighting(tmp)
        crash = None if args.no_crash else bench_crash(tmp)
    encodings = bench_encodings([128] if args.quick else [64, 128, 256])
    result = {
        "machine": {"python": platform.python_version(), "platform": platform.platform(),
                    "cpus": os.cpu_count()},
        "command": "benchmarks/bench_lightmap.py" + (" --quick" if args.quick else ""),
        "notes": ["seam errors and interpolation errors are in 1/255 units of a closed-form smooth "
                  "function of position (three waves across the model); 'smooth' seams are those across "
                  f"dihedral angles <= {SEAM_MAX_ANGLE} deg, the ones stitch_seams works on",
                  "xatlas_fresh_s includes starting the subprocess; xatlas_inside_s is xatlas alone"],
        "lightmap_machinery": machinery,
        "lightmap_real_lighting": real,
        "xatlas_crash": crash,
        "texture_encodings": encodings,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=1) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
