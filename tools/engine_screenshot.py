"""The screenshot of docs/engines.md's worked example: the lit icosphere of the corpus baked into
the small per-coordinate engine of the tests (tests/player/engines.py) with ``export.into``, the
merged project played in TurboWarp (vm/turbowarp.py), the stage saved as a PNG.

    .venv/bin/python tools/engine_screenshot.py [docs/images/turbowarp-own-engine.png]
"""

from __future__ import annotations

import sys
import tempfile
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]
sys.path[:0] = [str(REPO), str(REPO / "tests" / "player"), str(REPO / "vm")]

from PIL import Image  # noqa: E402

import engines  # noqa: E402
import turbowarp  # noqa: E402
from bake import config, pipeline  # noqa: E402
from bake.scratch import sb3  # noqa: E402
from bake.scratch.layout import join  # noqa: E402
from bake.scratch.project import auto_camera  # noqa: E402

MODEL = REPO.parent / "shared" / "corpus" / "ico4_mtl" / "ico4.obj"
LIGHTING = {"enabled": True, "target": "triangle", "ambient": [0.2, 0.2, 0.25],
            "lights": [{"kind": "sun", "direction": [0.5, -1, -0.4]}]}
EXPORT = {"names": {"vertices": ["X", "Y", "Z"], "triangles": ["tri a", "tri b", "tri c", "tri mat"],
                    "triangle_colors": "tri col"}, "index_base": 0, "triangle_colors": "yes"}


def main() -> int:
    out = Path(sys.argv[1]) if len(sys.argv) > 1 else REPO / "docs" / "images" / "turbowarp-own-engine.png"
    why = turbowarp.unavailable()
    if why:
        print(f"engine_screenshot: {why}")
        return 1
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        first = pipeline.run(config.load(data={"input": {"path": str(MODEL)}, "lighting": LIGHTING}))
        lists = {n: v for t in sb3.load_project(first.scene.artefacts.outputs["ico4.sb3"])[0]["targets"]
                 for n, v in (t.get("lists") or {}).values()}
        cam = auto_camera(join(lists)["vertices"])  # the author sets the engine's camera for the model
        engine = tmp / "engine.sb3"
        engine.write_bytes(engines.per_coordinate_engine(cam))
        res = pipeline.run(config.load(data={"input": {"path": str(MODEL)}, "lighting": LIGHTING,
                                             "export": {**EXPORT, "into": str(engine), "into_target": "Stage"}}))
        merged = tmp / "engine-ico4.sb3"
        merged.write_bytes(res.scene.artefacts.outputs[merged.name])
        run = turbowarp.run([("engine", merged)], modes=("compiled",))
        r = run.results[0]
        if r.problems():
            print(f"engine_screenshot: {r.problems()}")
            return 1
        Image.fromarray(r.image).save(out, optimize=True)
    print(f"wrote {out}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
