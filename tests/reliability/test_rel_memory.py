"""A lightmap resolution the config accepts must not run the machine out of memory (issue 18, item 4).

Run as a user would, under a real address-space cap (``RLIMIT_AS``, what ``ulimit -v`` and
``prlimit --as`` set) in a subprocess: a resolution whose bake cannot fit is refused before any
texel work -- exit 2, one line naming ``textures.lightmap.resolution`` and the resolution that
fits -- and that advice, followed under the same cap, bakes. Without a cap, 8192 (the top of the
accepted range) is refused against the memory the machine has. The atlas growing past the request
and a colour list past Scratch's 200,000 items are said before the lighting work.
"""

from __future__ import annotations

import json
import re
import resource
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from rel_util import write_obj

pytestmark = pytest.mark.slow

CAP = 1536 << 20  # 1.5 GiB of address space: Python, numpy, Embree and a small lightmap fit


def sphere(levels: int = 3):
    """An icosphere (20 * 4^levels triangles) with a dent, so charts are not all alike."""
    t = (1 + 5 ** 0.5) / 2
    v = [(-1, t, 0), (1, t, 0), (-1, -t, 0), (1, -t, 0), (0, -1, t), (0, 1, t), (0, -1, -t), (0, 1, -t),
         (t, 0, -1), (t, 0, 1), (-t, 0, -1), (-t, 0, 1)]
    f = [(0, 11, 5), (0, 5, 1), (0, 1, 7), (0, 7, 10), (0, 10, 11), (1, 5, 9), (5, 11, 4), (11, 10, 2),
         (10, 7, 6), (7, 1, 8), (3, 9, 4), (3, 4, 2), (3, 2, 6), (3, 6, 8), (3, 8, 9), (4, 9, 5), (2, 4, 11),
         (6, 2, 10), (8, 6, 7), (9, 8, 1)]
    pos = [np.array(p, float) / np.linalg.norm(p) for p in v]
    for _ in range(levels):
        mid: dict = {}
        nf = []

        def m(a, b):
            k = (min(a, b), max(a, b))
            if k not in mid:
                p = pos[a] + pos[b]
                pos.append(p / np.linalg.norm(p))
                mid[k] = len(pos) - 1
            return mid[k]
        for a, b, c in f:
            ab, bc, ca = m(a, b), m(b, c), m(c, a)
            nf += [(a, ab, ca), (b, bc, ab), (c, ca, bc), (ab, bc, ca)]
        f = nf
    p = np.array(pos)
    p[:, 1] *= 1.0 - 0.3 * np.exp(-8 * ((p[:, 0] - 0.5) ** 2 + p[:, 2] ** 2))
    return p, np.array(f)


@pytest.fixture(scope="module")
def scene(tmp_path_factory):
    d = tmp_path_factory.mktemp("memory")
    pos, tris = sphere(3)
    write_obj(d / "ball.obj", pos, tris)
    (d / "bake.toml").write_text(
        '[input]\npath = "ball.obj"\n[textures]\nenabled = true\n[textures.lightmap]\nenabled = true\n'
        'resolution = 128\n[lighting]\nenabled = true\ntarget = "lightmap"\n'
        '[[lighting.lights]]\nkind = "sun"\ndirection = [0.4, -1.0, 0.3]\n[lighting.ao]\nenabled = true\n'
        'samples = 16\n[report]\nhtml = false\n')
    return d


def bake(cfg: Path, out: Path, resolution: int, cap: int | None = None, *extra: str):
    def limit():
        if cap is not None:
            resource.setrlimit(resource.RLIMIT_AS, (cap, cap))
    t0 = time.perf_counter()
    r = subprocess.run([sys.executable, "-m", "bake.cli", "run", str(cfg), "--out", str(out), "--quiet",
                        "--set", f"textures.lightmap.resolution={resolution}", *extra],
                       capture_output=True, text=True, timeout=900, preexec_fn=limit)
    return r, time.perf_counter() - t0


def test_a_resolution_that_cannot_fit_under_a_memory_cap_is_refused_with_one_that_does(scene):
    cfg = scene / "bake.toml"
    r, took = bake(cfg, scene / "o1", 2048, CAP)
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    line = r.stderr.strip()
    assert r.stderr.count("\n") == 1 and "Traceback" not in r.stderr, r.stderr
    assert "key 'textures.lightmap.resolution'" in line and "address-space limit" in line, line
    assert not (scene / "o1" / "report.json").exists()
    fit = int(re.search(r"use resolution <= (\d+)", line).group(1))
    assert 128 <= fit < 2048, line
    # the advice, followed under the same cap, bakes (the estimate is not optimistic)
    r2, took2 = bake(cfg, scene / "o2", fit, CAP)
    assert r2.returncode == 0, (fit, r2.stderr[-2000:])
    rep = json.loads((scene / "o2" / "report.json").read_text())
    lm = next(s for s in rep["stages"] if s["name"] == "lighting")["details"]["lightmap"]
    # a real lightmap of about that size was baked (its longer side: xatlas's atlas need not be square)
    assert fit * 0.9 <= max(lm["atlas_width"], lm["atlas_height"]) <= fit
    tex = next(s for s in rep["stages"] if s["name"] == "textures")["details"]["lightmap"]
    assert tex["memory_estimate_bytes"] <= tex["memory_available_bytes"]
    # the refusal came before the work: far sooner than the bake that fits
    assert took < took2, (took, took2)


def test_the_top_of_the_accepted_range_is_refused_against_the_machines_memory(scene):
    r, _ = bake(scene / "bake.toml", scene / "o3", 8192)
    avail = None
    for line in Path("/proc/meminfo").read_text().splitlines():
        if line.startswith("MemAvailable:"):
            avail = int(line.split()[1]) * 1024
    if avail is not None and avail > 200 << 30:
        pytest.skip("this machine has more than 200 GiB available")
    assert r.returncode == 2, (r.returncode, r.stderr[-2000:])
    assert "textures.lightmap.resolution" in r.stderr and "needs about" in r.stderr, r.stderr


def test_atlas_growth_and_list_size_are_said_naming_the_key(scene):
    r, _ = bake(scene / "bake.toml", scene / "o4", 480, None)
    assert r.returncode == 0, r.stderr[-2000:]
    rep = json.loads((scene / "o4" / "report.json").read_text())
    tex = next(s for s in rep["stages"] if s["name"] == "textures")
    w, h = tex["details"]["lightmap"]["atlas_width"], tex["details"]["lightmap"]["atlas_height"]
    warnings = " | ".join(tex["warnings"])
    if max(w, h) > 480:
        assert f"{w}x{h}, past textures.lightmap.resolution = 480" in warnings, warnings
    assert w * h > 200_000, (w, h)
    assert f"{w * h:,} items" in warnings and "textures.lightmap.resolution <=" in warnings, warnings
    assert rep["lists"]["tex lightmap"]["items"] == w * h  # the figure said before the work was right
