"""Meeting a triangle count with the library (docs/simplify.md, "Meeting the budget on messy
models"): the count asked of the library is corrected until the triangles written, with the
layer's backs put back, are within _SHORT of what the target stands for; where the library
stops short of it, the stage lets go of, in order, RELAXATIONS (its locks, UV seams, the parts'
copies, material edges, and last edge collapse itself: vertex clustering) and runs again."""

from __future__ import annotations

import time

import numpy as np

from . import library, meshopt
from .inputs import Prepared
from .library import Raw
from .state import Ctx, Out

# What the stage lets go, in this order, when the library stops more than _SHORT above a triangle
# target (with defects = "allow"): the vertices it locked (border chains, the lock-and-retry
# rounds), UV seams of textured triangles, the parts' own copies of the vertices they share,
# material and colour edges, and last the edge collapse itself (meshoptimizer's vertex clustering,
# which reaches any count). Each is kept for the rest of the stage and named in the record.
RELAXATIONS = ("locks", "uv_seams", "parts", "materials", "clustering")
_SHORT = 0.02
RELAXED_TEXT = {
    "locks": "the border and seam vertices it had locked (borders follow the input's less closely)",
    "uv_seams": "the UV seams of textured triangles (textures may shift along them)",
    "parts": "the parts' own copies of the vertices they share (touching parts may be welded)",
    "materials": "the material and colour edges (colours may bleed across them)",
    "clustering": "edge collapse: vertices near each other were clustered (meshoptimizer's sloppy "
                  "simplifier; thin parts may merge)"}


def _applies(prep: Prepared, what: str, lock: np.ndarray) -> bool:
    """Whether letting ``what`` go can change the library's result."""
    if what == "locks":
        return bool(lock.any())
    if what == "uv_seams":
        return prep.tri_uvs is not None and bool(prep.textured.any())
    if what == "parts":
        return prep.parts_shared
    if what == "materials":
        return len(prep.region_material) > 1
    return True


def run_to(ctx: Ctx, target: int, lock: np.ndarray, cap: float, log: list) -> Raw:
    """The library's result for ``target``; where it stops short (not at the error ceiling) and
    defects are allowed, the next of RELAXATIONS that applies is let go and it runs again."""
    prep, cfg = ctx.prep, ctx.cfg
    while True:
        use = lock if "locks" not in prep.relaxed else np.zeros_like(lock)
        raw = _run_layer(ctx, target, use, cap)
        got, goal = _written(prep, raw), _goal(prep, target)
        if got <= goal * (1 + _SHORT) or cfg.defects == "refuse" or "clustering" in prep.relaxed:
            return raw
        if cap > 0 and _written(prep, _run_layer(ctx, target, use, 0.0)) <= goal * (1 + _SHORT):
            return raw  # the error ceiling is what stops it (the stage says so), not a seam
        what = next(r for r in RELAXATIONS if r not in prep.relaxed and _applies(prep, r, use))
        prep.relaxed.append(what)
        prep.wedges = None
        log.append({"relaxed": what, "target": int(target), "triangles_before": int(got)})


def _run_layer(ctx: Ctx, target: int, lock: np.ndarray, cap: float) -> Raw:
    """The library's result for a layer target (parts.py). The count asked is corrected (a
    few runs) until the triangles written, with the layer's backs put back, are within _SHORT of
    what the target stands for: the backs' share of the result is not the input's (two boxes'
    shared flat face keeps 2 triangles where their curved sides keep many), and meshoptimizer
    collapses in batches, so a small target can come back short (188 for 200)."""
    prep = ctx.prep
    T0 = len(prep.F)

    def run(t: int) -> Raw:
        if "clustering" in prep.relaxed:
            return _run_sloppy(ctx, t)
        return library.run(prep, ctx.method, t, ctx.cfg, lock, cap)
    raw = run(target)
    if target >= T0:
        return raw
    goal = _goal(prep, target)
    t, lib = target, raw.lib_seconds
    for _ in range(4):
        total = _written(prep, raw)
        if abs(total - goal) <= _SHORT * goal or (total > goal and len(raw.F) > t * (1 + _SHORT)):
            break  # (over the goal with the library stopping short of ``t``: run_to lets go)
        t_new = int(np.clip(round(t * goal / max(total, 1)), 1, T0 - 1))
        if t_new == t:
            break
        t = t_new
        raw = run(t)
        lib += raw.lib_seconds
    raw.lib_seconds = lib
    return raw


def _goal(prep: Prepared, target: int) -> float:
    """The triangles a layer target stands for, with the backs put back (at the input's share)."""
    T0 = len(prep.F)
    return target * (T0 + prep.layer.twins) / T0


def _written(prep: Prepared, raw: Raw) -> int:
    """Triangles a library result writes: those with three distinct corners (two wedges of one
    vertex, across a UV seam, make a triangle that is dropped) and the backs put back."""
    F = raw.F
    alive = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    return int(alive.sum()) + int(prep.region_back[raw.region[alive]].sum())


def total(prep: Prepared, out: Out) -> int:
    """Triangles a result writes: its layer's and the backs put back (parts.py)."""
    return int(len(out.F) + prep.region_back[out.region].sum())


def _run_sloppy(ctx: Ctx, target: int) -> Raw:
    """meshoptimizer's vertex clustering (meshopt.simplify_sloppy): the smallest of a
    few clusterings at or above the target (its counts come in steps: 48, 96, 144 on a small
    sphere), then edge collapse on that, free of every seam, down to the target. Each triangle
    takes the region of the input triangle closest to its centre."""
    prep = ctx.prep
    t = time.perf_counter()

    def cluster(want: int) -> tuple[np.ndarray, float]:
        Fo, err = meshopt.simplify_sloppy(prep.V, prep.F, want)
        return Fo[(Fo[:, 0] != Fo[:, 1]) & (Fo[:, 1] != Fo[:, 2]) & (Fo[:, 0] != Fo[:, 2])], err
    want, best = target, None
    for _ in range(6):
        Fo, err = cluster(want)
        if len(Fo) >= target and (best is None or len(Fo) < len(best[0])):
            best = (Fo, err)
        if abs(len(Fo) - target) <= _SHORT * target or want >= len(prep.F):
            break
        want = int(min(len(prep.F), max(want + 1, round(want * 1.25 * target / max(len(Fo), 1)))))
    Fo, err = best if best is not None else cluster(len(prep.F))
    if len(Fo) > target * (1 + _SHORT):
        Fo = meshopt.simplify(prep.V, Fo, target)[0]
    lib = time.perf_counter() - t
    _, near, _ = ctx.index_a.query(prep.V[Fo].mean(axis=1)) if len(Fo) else (None, np.zeros(0, np.int64), None)
    return Raw(V=prep.V, F=Fo, src_vertex=np.arange(len(prep.V)), region=prep.region[near], src_tri=None,
               tri_uvs=None if prep.tri_uvs is None else prep.tri_uvs[near],
               fixed=np.zeros(len(prep.V), bool), lib_seconds=lib,
               notes=["vertex clustering: each triangle took the material and UVs of the input triangle closest "
                      "to its centre"], lib_error=float(err) * ctx.scale)
