"""README's picture of a lightmapped room: the corpus's Cornell box lit by a sun, ambient light
and AO into a lightmap, baked with the default export (the reader's textured filler, texel size 2),
played in TurboWarp (vm/turbowarp.py, compiled), beside report.html's textured green flag
(``bake.outputs.cells``) of the same bake.

    .venv/bin/python tools/room_screenshot.py [docs/images/turbowarp-room-lightmap.png]
"""

from __future__ import annotations

import json
import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "vm")]

import numpy as np  # noqa: E402
from PIL import Image, ImageDraw  # noqa: E402

import turbowarp  # noqa: E402
from bake import cli  # noqa: E402
from bake.outputs import cells  # noqa: E402
from bake.scratch import backdrop, sb3  # noqa: E402

MODEL = REPO.parent / "shared" / "corpus" / "cornell_box_multimaterial" / "cornell_box_multimaterial.obj"
SETS = ["lighting.enabled=true", 'lighting.target="lightmap"', "lighting.ambient=[0.2, 0.2, 0.25]",
        'lighting.lights=[{kind="sun", direction=[0.5, -1, -0.4]}]', "lighting.ao.enabled=true",
        "lighting.ao.samples=64", "textures.enabled=true", "textures.lightmap.enabled=true",
        "textures.lightmap.resolution=128"]


def main() -> int:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs" / "images" / "turbowarp-room-lightmap.png"
    why = turbowarp.unavailable()
    if why:
        print(f"room_screenshot: {why}")
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp) / "room"
        args = ["run", str(MODEL), "--out", str(folder), "--quiet"]
        for s in SETS:
            args += ["--set", s]
        if cli.main(args) != 0:
            return 1
        sb3_path = next(folder.glob("*.sb3"))
        report = json.loads((folder / "report.json").read_text())
        lists = json.loads((folder / "lists.json").read_text())["lists"]
        pic, _ = cells.green_flag(lists, report)
        project, assets = sb3.load_project(sb3_path)
        bg = backdrop.from_project(project, assets)
        r = turbowarp.run([("room", sb3_path)], modes=("compiled",)).results[0]
        if r.problems():
            print(f"room_screenshot: {r.problems()}")
            return 1
        a = cells.agreement(r.image, pic, bg)
        gap = np.full((360, 16, 3), 255, np.uint8)
        im = Image.fromarray(np.concatenate([r.image, gap, pic.image(bg)], 1))
        d = ImageDraw.Draw(im)
        d.text((8, 8), "TurboWarp (compiled): the stage after the green flag", fill=(0, 0, 0))
        d.text((504, 8), "report.html: the textured green flag (Python)", fill=(0, 0, 0))
        im.save(out, optimize=True)
    print(f"wrote {out}: {a['within_8']:.4%} of {a['painted_pixels']:,} painted pixels within 8 levels, "
          f"{a['within_1']:.2%} within 1")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
