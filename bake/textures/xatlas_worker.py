"""Runs xatlas in its own process: ``python xatlas_worker.py IN.npz OUT.npz``.

xatlas 0.0.9-0.0.11 can segfault (a perfectly smooth 6-times subdivided icosphere crashes in
``PackCharts``; shared/docs/dependencies.md section 4) and large meshes take tens of seconds, so
``bake/textures/unwrap.py`` starts this script as a subprocess with a timeout: a crash or a hang
costs the subprocess, never the bake.

This file imports only numpy and xatlas (not the ``bake`` package), so it starts fast and works
whatever the working directory.

Input (``IN.npz``): ``positions`` float32 (V, 3), ``indices`` uint32 (T, 3), ``options`` a JSON
string with ``chart`` and ``pack`` option dicts (xatlas attribute names). The positions are the
model centred and multiplied by a power of two (``unwrap.xatlas_scale``), and the options in
model units converted to match; this script hands both to xatlas as they are. Output (``OUT.npz``,
written to a temporary name and renamed, so a partial file is never read): ``vmapping`` (V',),
``indices`` (T, 3), ``uvs`` (V', 2) normalised to [0, 1], ``width``, ``height``, ``atlas_count``,
``chart_count``, ``utilization`` (one per atlas), ``texels_per_unit``, ``seconds``, ``version``.
Exit status 0 on success, 2 on bad input, 3 when xatlas raised; a signal (e.g. -11) is a crash.
"""

from __future__ import annotations

import json
import os
import sys
import time


def main(argv: list[str]) -> int:
    if len(argv) != 3:
        print("usage: xatlas_worker.py IN.npz OUT.npz", file=sys.stderr)
        return 2
    import numpy as np

    try:
        with np.load(argv[1], allow_pickle=False) as f:
            pos = np.ascontiguousarray(f["positions"], dtype=np.float32)
            idx = np.ascontiguousarray(f["indices"], dtype=np.uint32)
            options = json.loads(str(f["options"]))
    except (OSError, KeyError, ValueError) as e:
        print(f"cannot read input: {e}", file=sys.stderr)
        return 2
    import xatlas

    t0 = time.perf_counter()
    try:
        chart = xatlas.ChartOptions()
        for k, v in options.get("chart", {}).items():
            setattr(chart, k, v)
        pack = xatlas.PackOptions()
        for k, v in options.get("pack", {}).items():
            setattr(pack, k, v)
        atlas = xatlas.Atlas()
        atlas.add_mesh(pos, idx)
        atlas.generate(chart_options=chart, pack_options=pack)
        vmapping, indices, uvs = atlas[0]
        util = np.atleast_1d(np.asarray(atlas.utilization, dtype=np.float64))
        out = {
            "vmapping": np.asarray(vmapping, dtype=np.int64),
            "indices": np.asarray(indices, dtype=np.int64),
            "uvs": np.asarray(uvs, dtype=np.float32),
            "width": np.int64(atlas.width),
            "height": np.int64(atlas.height),
            "atlas_count": np.int64(atlas.atlas_count),
            "chart_count": np.int64(atlas.chart_count),
            "utilization": util,
            "texels_per_unit": np.float64(atlas.texels_per_unit),
            "seconds": np.float64(time.perf_counter() - t0),
            "version": np.str_(getattr(xatlas, "__version__", "")),
        }
    except Exception as e:  # xatlas raised (bad mesh): report, do not crash
        print(f"xatlas failed: {type(e).__name__}: {e}", file=sys.stderr)
        return 3
    tmp = argv[2] + ".part"
    with open(tmp, "wb") as fh:
        np.savez(fh, **out)
    os.replace(tmp, argv[2])
    return 0


if __name__ == "__main__":
    sys.exit(main(sys.argv))
