"""Models and helpers for the Scratch VM tests: bake through the real pipeline, open the result."""

from __future__ import annotations

import dataclasses
import io
import json
import zipfile
from pathlib import Path

import numpy as np

from bake import config, pipeline


def soup_obj(path: Path, n: int = 60, seed: int = 3) -> Path:
    """Random overlapping triangles of mixed sizes (plus two slivers), as an OBJ file."""
    rng = np.random.default_rng(seed)
    c = rng.random((n, 1, 3)) * 4
    tri = c + rng.normal(size=(n, 3, 3)) * rng.uniform(0.1, 1.2, (n, 1, 1))
    tri[0] = [[0, 0, 0], [4, 0.001, 0], [0, 0.002, 4]]  # slivers
    tri[1] = [[0, 0, 0], [4, 4, 4], [0.001, 0, 0.001]]
    lines = [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in tri.reshape(-1, 3)]
    lines += [f"f {3 * i + 1} {3 * i + 2} {3 * i + 3}" for i in range(n)]
    path.write_text("\n".join(lines) + "\n")
    return path


def bake(model: Path, **sections) -> "pipeline.BakeResult":
    data = {"input": {"path": str(model)}}
    data.update(sections)
    return pipeline.run(config.load(data=data))


def project_lists(sb3_bytes: bytes) -> dict[str, list]:
    """Every list of every target in an .sb3, by name."""
    with zipfile.ZipFile(io.BytesIO(sb3_bytes)) as z:
        project = json.loads(z.read("project.json"))
    out: dict[str, list] = {}
    for t in project["targets"]:
        for name, items in (t.get("lists") or {}).values():
            out[name] = items
    return out


def encoded_from_lists(enc, lists: dict[str, list], names) -> object:
    """The BVH as a Scratch script sees it: the encoder's metadata with the lists as written."""
    return dataclasses.replace(enc, nodes=np.asarray(lists[names.nodes], np.float64),
                               tris=np.asarray(lists[names.tris], np.float64),
                               ids=np.asarray(lists[names.ids], np.int64))


def cameras(verts):
    """Two views of a model: from the front-left above, and from behind-right below, closer (so
    some triangles leave the stage and get clipped)."""
    from bake.scratch.project import look_at

    v = np.asarray(verts, np.float64).reshape(-1, 3)
    c, diag = (v.min(0) + v.max(0)) / 2, float(np.linalg.norm(v.max(0) - v.min(0)))
    return [look_at(c + np.array([-0.4, 0.45, -0.9]) * diag, c + [0.05 * diag, 0, 0]),
            look_at(c + np.array([0.55, -0.2, 0.45]) * diag, c)]


def rays(verts: np.ndarray, tris: np.ndarray, n: int, seed: int) -> list[tuple[list[float], list[float]]]:
    """Rays at a model: from outside its box towards points on random triangles (hits, some
    grazing), random directions (many misses), axis-aligned ones (zero direction components),
    and from inside the box."""
    rng = np.random.default_rng(seed)
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    t = np.asarray(tris, np.int64).reshape(-1, 4)[:, :3] - 1
    lo, hi = v.min(0), v.max(0)
    c, r = (lo + hi) / 2, float(np.linalg.norm(hi - lo)) / 2 or 1.0
    out = []
    for k in range(n):
        kind = k % 4
        if kind == 0:  # towards a point on a random triangle
            tri = v[t[rng.integers(len(t))]]
            w = rng.dirichlet([1, 1, 1])
            target = w @ tri
            o = c + rng.normal(size=3) / np.linalg.norm(rng.normal(size=3) + 1e-9) * 2 * r
            d = target - o
        elif kind == 1:  # random
            o = c + rng.uniform(-2, 2, 3) * r
            d = rng.normal(size=3)
        elif kind == 2:  # axis-aligned through the box
            axis = rng.integers(3)
            o = c + rng.uniform(-0.8, 0.8, 3) * (hi - lo) / 2
            o[axis] = lo[axis] - r
            d = np.zeros(3)
            d[axis] = 1.0
        else:  # from inside
            o = c + rng.uniform(-0.3, 0.3, 3) * (hi - lo) / 2
            d = rng.normal(size=3)
        out.append(([float(x) for x in o], [float(x) for x in d]))
    return out


# --------------------------------------------------------------------------- pen pictures
XS = np.arange(-236, 236) + 0.5  # sample points: pixel centres, away from the stage edge
YS = np.arange(-176, 176) + 0.5


def _raster_strokes(strokes, xs, ys):
    """Index of the last pen stroke covering each sample point (-1: none)."""
    owner = np.full((len(ys), len(xs)), -1, np.int64)
    for k, (x0, y0, x1, y1, diam, *_rgba) in enumerate(strokes):
        rad = diam / 2
        yi = np.flatnonzero((ys >= min(y0, y1) - rad) & (ys <= max(y0, y1) + rad))
        xi = np.flatnonzero((xs >= min(x0, x1) - rad) & (xs <= max(x0, x1) + rad))
        if not len(yi) or not len(xi):
            continue
        X, Y = np.meshgrid(xs[xi], ys[yi])
        dx, dy = x1 - x0, y1 - y0
        L = dx * dx + dy * dy
        s = np.clip(((X - x0) * dx + (Y - y0) * dy) / L, 0, 1) if L > 0 else 0.0
        dist2 = (X - (x0 + s * dx)) ** 2 + (Y - (y0 + s * dy)) ** 2
        sub = owner[np.ix_(yi, xi)]
        sub[dist2 <= rad * rad] = k
        owner[np.ix_(yi, xi)] = sub
    return owner


def _painter(px, py, pz, tris, order, near, cull, xs, ys, margin=1.5):
    """Python reference: the triangle seen at each sample (-1 none), and where that is ambiguous
    (a sample within ``margin`` of an edge of a triangle drawn later; the whole neighbourhood of
    a degenerate one)."""
    seen = np.full((len(ys), len(xs)), -1, np.int64)
    amb = np.zeros(seen.shape, bool)
    for t in order:
        i = tris[t - 1, :3] - 1
        if not np.all(pz[i] > near):
            continue
        a, b, c = np.stack([px[i], py[i]], 1)
        area = (b[0] - a[0]) * (c[1] - a[1]) - (b[1] - a[1]) * (c[0] - a[0])
        if cull and not area < 0:
            continue
        lo, hi = np.minimum(np.minimum(a, b), c) - margin, np.maximum(np.maximum(a, b), c) + margin
        xi = slice(np.searchsorted(xs, lo[0]), np.searchsorted(xs, hi[0], side="right"))
        yi = slice(np.searchsorted(ys, lo[1]), np.searchsorted(ys, hi[1], side="right"))
        if xi.start >= xi.stop or yi.start >= yi.stop:
            continue
        if abs(area) < 1e-9:
            amb[yi, xi] = True  # a line or a point: the pen may draw a thin stroke anywhere near it
            continue
        X, Y = np.meshgrid(xs[xi], ys[yi])
        sign = 1.0 if area > 0 else -1.0
        dmin = np.full(X.shape, np.inf)
        for p, q in ((a, b), (b, c), (c, a)):
            e = q - p
            ln = float(np.hypot(*e))
            dmin = np.minimum(dmin, sign * ((X - p[0]) * -e[1] + (Y - p[1]) * e[0]) / ln)
        inside = dmin > margin
        near_ = dmin > -margin
        s_seen, s_amb = seen[yi, xi], amb[yi, xi]
        s_seen[inside] = t
        s_amb[inside] = False
        s_amb[near_ & ~inside] = True
    return seen, amb


def check_render(strokes, px, py, pz, tris, order, colours, near, cull, min_sure=2000):
    """The pen strokes, rasterised, show at every unambiguous sample the colour of the triangle
    the Python painter's rasterisation shows there, and nothing where no triangle is. ``pz`` and
    ``near`` in the same unit (``readers.project`` gives depth / focal: pass near / focal)."""
    assert strokes, "nothing drawn"
    owner = _raster_strokes(strokes, XS, YS)
    seen, amb = _painter(px, py, pz, tris, order, near, cull, XS, YS)
    stroke_rgb = np.array([s[5:8] for s in strokes])
    sure = (seen >= 0) & ~amb
    assert sure.sum() > min_sure, "the camera sees too little of the model for a meaningful test"
    assert np.all(owner[sure] >= 0), "holes where a triangle is drawn"
    got = stroke_rgb[owner[sure]]
    want = colours[seen[sure] - 1]
    wrong = np.any(np.abs(got - want) > 2, axis=1)  # the pen's HSV round trip moves a channel by <= 1
    assert wrong.mean() == 0, f"{wrong.sum()} of {sure.sum()} pixels show the wrong triangle"
    empty = (seen < 0) & ~amb
    assert np.all(owner[empty] < 0), "strokes outside every triangle"
    return int(sure.sum())
