"""Texture benchmarks: TextImage encode/decode speed and size, resampling, triangle averages.

    .venv/bin/python benchmarks/bench_textures.py [--repeat 5]
        [--out benchmarks/results/textures.json]

Images: the shared corpus photos (``capsule_textured/capsule0.jpg``, the Duck's embedded PNG)
box-resampled to 480x360 and 128x128, uniform noise, and a smooth synthetic "photo" (used
instead of the corpus when it is absent). Times are the best of ``--repeat`` runs (wall clock,
one thread); every encode is checked to decode back to the same pixels. The sizes quoted in
shared/docs/scratch.md section 4a are written next to ours for comparison.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import struct
import sys
import time
from pathlib import Path

import numpy as np
from PIL import Image

REPO = Path(__file__).resolve().parent.parent
sys.path.insert(0, str(REPO))

from bake.scratch import textimage  # noqa: E402
from bake.textures import images  # noqa: E402

CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))

# shared/docs/scratch.md section 4a, "Sizes seen" (reference encoder, including the header)
QUOTED = {
    "photo_480x360_stream_chars": 278_522,
    "photo_480x360_chars_per_px": 1.6,
    "noise_chars_per_px": 4.04,
    "testcard_128x128_chars": 37_930,
}


def best(f, repeat):
    times = []
    for _ in range(repeat):
        t = time.perf_counter()
        out = f()
        times.append(time.perf_counter() - t)
    return min(times), out


def glb_image(path: Path) -> bytes:
    data = path.read_bytes()
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + jlen])
    view = doc["bufferViews"][doc["images"][0]["bufferView"]]
    off = 20 + jlen + 8 + view.get("byteOffset", 0)
    return data[off:off + view["byteLength"]]


def synthetic_photo(h: int, w: int, seed: int = 0) -> np.ndarray:
    r = np.random.default_rng(seed)
    small = r.integers(0, 256, (6, 8, 3), dtype=np.uint8)
    smooth = np.asarray(Image.fromarray(small).resize((w, h), Image.Resampling.BICUBIC), int)
    return np.clip(smooth + r.normal(0, 4, smooth.shape), 0, 255).astype(np.uint8)


def inputs() -> dict[str, np.ndarray]:
    out: dict[str, np.ndarray] = {}
    sources = {}
    if (CORPUS / "capsule_textured" / "capsule0.jpg").exists():
        sources["capsule_photo"] = images.load_rgba(CORPUS / "capsule_textured" / "capsule0.jpg")
    if (CORPUS / "duck_glb" / "Duck.glb").exists():
        sources["duck_texture"] = images.load_rgba(glb_image(CORPUS / "duck_glb" / "Duck.glb"))
    sources["synthetic_photo"] = images.load_rgba(synthetic_photo(720, 960))
    for name, src in sources.items():
        for w, h in ((480, 360), (128, 128)):
            out[f"{name}_{w}x{h}"] = images.resample(src, (w, h), "box")[:, :, :3]
    r = np.random.default_rng(1)
    out["noise_480x360"] = r.integers(0, 256, (360, 480, 3), dtype=np.uint8)
    out["noise_128x128"] = r.integers(0, 256, (128, 128, 3), dtype=np.uint8)
    alpha = synthetic_photo(360, 480, 2)
    yy, xx = np.mgrid[0:360, 0:480]
    disc = ((xx - 240) ** 2 + (yy - 180) ** 2 < 150 ** 2).astype(np.uint8) * 255
    out["synthetic_cutout_rgba_480x360"] = np.dstack([alpha, disc])
    return out


def bench_textimage(repeat: int) -> list[dict]:
    rows = []
    for name, img in inputs().items():
        h, w = img.shape[:2]
        t_enc, text = best(lambda: textimage.encode(img), repeat)
        t_dec, back = best(lambda: textimage.decode(text), max(1, repeat // 2))
        expect = img if img.shape[2] == 4 and (img[:, :, 3] != 255).any() else img[:, :, :3]
        assert np.array_equal(back, expect), name
        header = text.split("|", 1)[0]
        stream = len(text) - len(header) - 1
        rows.append({
            "image": name, "width": w, "height": h, "alpha_layer": "alpha" in header,
            "chars": len(text), "stream_chars": stream,
            "chars_per_px": round(len(text) / (w * h), 4),
            "encode_s": round(t_enc, 4), "decode_s": round(t_dec, 4),
            "encode_mpx_per_s": round(w * h / t_enc / 1e6, 2),
            "decode_mpx_per_s": round(w * h / t_dec / 1e6, 2),
        })
        print(f"{name:34s} {w}x{h}  {len(text):8d} chars  {len(text) / (w * h):5.2f} ch/px  "
              f"enc {t_enc * 1000:7.1f} ms  dec {t_dec * 1000:7.1f} ms")
    return rows


def bench_images(repeat: int) -> dict:
    r = np.random.default_rng(3)
    tex = r.integers(0, 256, (1024, 1024, 4), dtype=np.uint8)
    out = {}
    for filt in ("box", "lanczos"):
        for wrap in (False, True):
            t, _ = best(lambda: images.resample(tex, (256, 256), filt, wrap=wrap), repeat)
            out[f"resample_1024_to_256_{filt}{'_wrap' if wrap else ''}_s"] = round(t, 4)
    for n_tris, size, label in ((10_000, 0.01, "10k_tris_edges_~10_texels"),
                                (1_000, 0.2, "1k_tris_edges_~200_texels")):
        uv = r.uniform(0, 1, (n_tris, 1, 2)) + size * r.normal(size=(n_tris, 3, 2))
        t, _ = best(lambda: images.average_over_triangles(tex, uv), max(1, repeat // 2))
        out[f"average_over_triangles_1024tex_{label}_s"] = round(t, 4)
    for k, v in out.items():
        print(f"{k:60s} {v * 1000:8.1f} ms")
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--out", type=Path, default=REPO / "benchmarks" / "results" / "textures.json")
    args = ap.parse_args(argv)
    rows = bench_textimage(args.repeat)
    other = bench_images(args.repeat)
    photo = next((r for r in rows if r["image"] == "capsule_photo_480x360"),
                 next(r for r in rows if r["image"] == "synthetic_photo_480x360"))
    noise = next(r for r in rows if r["image"] == "noise_480x360")
    result = {
        "command": "python benchmarks/bench_textures.py" + (
            f" --repeat {args.repeat}" if args.repeat != 5 else ""),
        "machine": {"python": platform.python_version(), "numpy": np.__version__,
                    "pillow": Image.__version__, "platform": platform.platform(),
                    "cpus": os.cpu_count(),
                    "load_average": list(os.getloadavg()) if hasattr(os, "getloadavg") else None},
        "corpus": str(CORPUS) if CORPUS.is_dir() else None,
        "textimage": rows,
        "vs_scratch_md": {
            "quoted": QUOTED,
            "photo_480x360": {"image": photo["image"], "stream_chars": photo["stream_chars"],
                              "chars_per_px": photo["chars_per_px"]},
            "noise_480x360_chars_per_px": noise["chars_per_px"],
            "note": "the quoted photo is a different image; chars/px depends on content",
        },
        "images": other,
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(result, indent=2) + "\n")
    print(f"wrote {args.out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
