"""Simplify stage: reduce the triangles to a budget and measure what it cost in shape.

Targets (exactly one): ``target_triangles = N``, ``target_ratio = r`` (of the input count) or
``max_error = e`` (symmetric Hausdorff distance as a fraction of the bounding-box diagonal; the
stage searches the smallest triangle count whose measured error stays within ``e``).

Methods (quadric edge collapse, all through compiled libraries; library.py runs them):

* ``meshopt`` (default): meshoptimizer (meshopt.py). It keeps a subset of the input's
  vertices, so colours and UVs are the input's exact values. The mesh is handed
  over as *wedges* (one vertex per position + region + UV): meshoptimizer treats vertices that
  share a position as a seam, so a material edge or a UV seam collapses only along itself,
  never across, and every output corner keeps its wedge's UV and region. Open borders also
  collapse only along themselves. Every border and seam chain of the input is first simplified
  on its own (Douglas-Peucker, at half the library's own error estimate for the target) and
  the vertices that keeps are locked, so no border chord strays far from the input's border.
* ``fast``: fast-simplification. It knows only points and triangles; the mesh is split along
  material edges so those become open borders, which ``preserve_border`` keeps vertex for
  vertex. The collapse list is replayed to get the vertex map; each output triangle is one
  input triangle with corners replaced, so material, UVs and face colour come from that
  triangle, and each output vertex takes the colour of the closest input vertex merged into it.
* ``quality``: MeshLab's quadric edge collapse (pymeshlab) with optimal placement and normal
  checks. Input vertex and triangle numbers ride along as MeshLab's per-vertex and per-face
  quality, giving the same correspondence as for ``fast``. Material edges are held by leaving
  the triangles that touch them out of the selection MeshLab may simplify.

After the library (attempt.py; repair.py for the local repairs):

1. edges whose two triangles meet at a sharp angle (fins, folds) are turned where that lowers
   the error around them; flipped triangles (normal turned by more than 90 degrees from the
   input surface they stand for; ``error.flip_check``) are repaired where possible
   (turning an edge, moving a free corner back onto the input surface; undone if it costs more
   than 10% of the local error), and triangles still flipped get the input vertices under them
   locked and the library runs again (three rounds).
2. ``fit_iterations`` rounds of least-squares refit of the free vertex positions to the input
   surface (fit.py); not kept if it raises the measured max by more than a quarter (a fit
   rounds off the sharp corners of CAD parts; the record's ``fit.kept`` says which).
3. ``refine_rounds`` rounds of repair where the error peaks (rounds.py): the triangles holding
   the largest distances (within 80% of the maximum, both directions) get their edges turned
   where that lowers the local error, and their free corners moved to lower the local *maximum*
   (a Chebyshev fit; ``repair.polish``); every move is kept only if the local maximum
   drops and no triangle turns against the input.
   Then ``peak_rounds`` rounds (with a triangle target and ``refine_rounds`` > 0): the input
   vertices nearest the largest places the library cut off are locked and the whole stage runs
   again; a round is kept if its measured max is lower (``details.peak_rounds``).
4. the error is measured (measure.py): a dense deterministic grid on both surfaces (every
   vertex, points along every edge, points inside every triangle), refined
   around the largest distances, the largest made exact at their points. The record gives the
   sample size; the maximum is a sampled one (the true maximum can only be larger, by at most
   how much the distance grows between samples) and is never called exact. Then, on the result
   kept (``error_bound``), an upper bound of the true maximum is *proven*: the grid's cells are
   cut, largest bound first, until no cell can hold a distance more than 2% above the largest
   found or BOUND_FLOOR of the diagonal, or a budget of points is spent
   (``measure.certify``, rounds.prove_bound); the record gives the bound, whether it got
   there, and what it cost. Cutting finds peaks the sample missed (the CSG model at 2%: 7.6%
   higher).
5. with a triangle target, the budget is met (``defects = "allow"``): flipped triangles, new
   non-manifold edges and folds the repairs leave are counted in the record (defects.py;
   ``details.defects``, ``details.defect_triangles``) and warned about. With ``defects =
   "refuse"``, a result that has any is not accepted and the stage backs off to the smallest
   larger count without (search.py); with an ``error_ceiling`` (default 0: none), neither is a
   result whose error is above it.

Messy input (parts.py, inputs.py): a two-sided surface written twice is simplified as one layer
and written with its backs; repeated triangles are dropped; parts that share vertices keep their
own copies in the library's buffer. Where the library stops short of a triangle target, the
stage lets go of, in order, its locks, UV seams, the parts' copies, material edges and last edge
collapse itself (ladder.py, RELAXATIONS; ``details.relaxed``), and says so. docs/simplify.md,
"Meeting the budget on messy models", has what each costs.

What stays where it was: vertices on the input's open borders (``preserve_border``) and on
material or face-colour edges (``preserve_materials``) are never moved by the refit or the
repairs; with ``meshopt`` they are input border/edge vertices, so every border and material edge
of the output runs through input border/edge vertices, along chords of the input's border. The
record reports how far those chords stray from the input's borders
(``border_chord_max``, fraction of the diagonal) and how many border/edge vertices moved (0).
Vertices on UV seams may move (both sides of the seam together, so no crack opens).

Whatever the method, material edges (and face-colour edges) are kept when
``preserve_materials``; every output triangle has a valid material, UVs and face colour; vertex
colours are input values; ``tri_polygon`` is -1 everywhere and the polygon arrays are dropped
(they describe the input vertex numbering, which simplification replaces).

The record (outcome.py): triangles in/out and the target, seconds per phase (library, fit,
repairs, checks, measure), the symmetric Hausdorff max/mean as fractions of the diagonal
(``accuracy``) with the sample it was measured on, flipped triangles, folds (neighbouring
triangles whose normals have a dot product below -0.9) in the input and the output, new
non-manifold and mis-oriented edges, material-edge and border checks, how each attribute was
carried, and a warning for anything that kept the target from being reached.
"""
from __future__ import annotations

import time
from dataclasses import dataclass

from ...config import SimplifyConfig
from ...errors import ConfigError, StageError
from ...record import StageRecord
from ...scene import Scene
from . import defects, inputs, meshopt, outcome, rounds, search, state
from .library import METHODS
from .measure import HausdorffResult
from .state import Ctx, Out

__all__ = ["stage", "simplify_mesh", "resolve_target", "METHODS"]


def stage(scene: Scene, cfg: SimplifyConfig) -> tuple[Scene, StageRecord]:
    """Pipeline entry point: ``(scene, SimplifyConfig) -> (scene, record)``."""
    try:
        return simplify_mesh(scene, cfg)
    except MemoryError:
        raise StageError("simplify ran out of memory") from None


def resolve_target(n_triangles: int, cfg: SimplifyConfig) -> tuple[str, float]:
    """("triangles", N) or ("error", e) from the config; exactly one target must be set."""
    set_ = [k for k, v in (("target_triangles", cfg.target_triangles), ("target_ratio", cfg.target_ratio),
                           ("max_error", cfg.max_error)) if v]
    if len(set_) != 1:
        what = "none is set" if not set_ else "got " + ", ".join(set_)
        raise ConfigError(f"set exactly one of target_triangles, target_ratio, max_error ({what})",
                          key="mesh.simplify")
    if cfg.target_triangles:
        return "triangles", float(cfg.target_triangles)
    if cfg.target_ratio:
        return "triangles", float(max(1, int(round(n_triangles * cfg.target_ratio))))
    return "error", float(cfg.max_error)


@dataclass
class _Job:
    """What the stage was asked, resolved against its input."""
    kind: str  # "triangles" or "error" (resolve_target)
    value: float  # triangles written, or the largest error as a fraction of the diagonal
    method: str  # the library that runs (meshopt falls back to fast when it is not installed)
    scale: float  # the input's bounding-box diagonal
    prep: inputs.Prepared
    details: dict  # the record's details, filled in as the phases go


def simplify_mesh(scene: Scene, cfg: SimplifyConfig) -> tuple[Scene, StageRecord]:
    """The stage body (see the module docstring): the job, the context every attempt shares,
    the count found (a triangle target, or the smallest count within ``max_error``), the rounds
    where its error peaks, the proven bound, and the new scene with its record."""
    t0 = time.perf_counter()
    rec = StageRecord(name="simplify")
    job = _job(scene, cfg, rec)
    if job is None:  # nothing to simplify: the record says why
        rec.seconds = time.perf_counter() - t0
        return scene, rec
    t_prep = time.perf_counter()
    ctx = state.context(job.prep, cfg, job.method, job.scale,
                        cap=float(cfg.error_ceiling) * job.scale if job.kind == "triangles" else 0.0,
                        measuring=cfg.measure_error or job.kind == "error")
    prep_s = time.perf_counter() - t_prep
    if job.kind == "triangles":
        out, h, refine_log = _meet_triangles(ctx, job, rec)
    else:
        out, h, refine_log = _meet_error(ctx, job)
    h, bound_log = _bound(ctx, job, h, rec)
    new = outcome.write(scene, ctx, rec, job.details, kind=job.kind, value=job.value, out=out, h=h,
                        refine_log=refine_log, bound_log=bound_log, prep_s=prep_s)
    rec.details = job.details
    rec.seconds = time.perf_counter() - t0
    # the rest: the stage's own bookkeeping, attribute transfer, the final checks
    job.details["other_seconds"] = round(max(0.0, rec.seconds - prep_s - sum(ctx.seconds.values())), 6)
    return new, rec


def _job(scene: Scene, cfg: SimplifyConfig, rec: StageRecord) -> _Job | None:
    """The target, the method and the prepared input; None (the record filled in) when there
    is nothing to simplify: no triangles, or a target not below the input's count."""
    T0 = scene.n_triangles
    rec.counts_in = {"triangles": T0, "vertices": scene.n_vertices, "polygons": scene.n_polygons,
                     "materials": len(scene.materials)}
    method = cfg.method
    if method not in METHODS:
        raise ConfigError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}",
                          key="mesh.simplify.method")
    if T0 == 0:
        rec.warn("no triangles to simplify")
        rec.counts_out = dict(rec.counts_in)
        return None
    kind, value = resolve_target(T0, cfg)
    if method == "meshopt" and not meshopt.available():
        rec.warn("meshoptimizer is not installed; used method 'fast' instead")
        method = "fast"
    scale = scene.scale()
    prep = inputs.prepare(scene, cfg)
    details: dict = {"method": method, "target_kind": kind, "scale": scale,
                     "regions": int(len(prep.region_material))}
    if method == "meshopt":
        details["library"] = f"meshoptimizer {meshopt.version()}"
    if kind == "triangles" and int(value) >= T0:
        rec.warn(f"target {int(value)} triangles is not below the input's {T0}; nothing to do")
        rec.counts_out = dict(rec.counts_in)
        rec.details = details | {"target_triangles": int(value)}
        return None
    if prep.layer.folded:  # the layer (parts.fold_layer) is what the library simplifies
        details["layer"] = {"triangles": len(prep.F), "with_back": prep.layer.twins,
                            "repeated_dropped": prep.layer.repeated}
    details["parts_in"] = prep.n_parts
    return _Job(kind=kind, value=value, method=method, scale=scale, prep=prep, details=details)


def _meet_triangles(ctx: Ctx, job: _Job, rec: StageRecord) -> tuple[Out, HausdorffResult | None, list[dict]]:
    """A triangle target: the count met (or backed off from), then the refine rounds and, on a
    result not backed off to and without defects, the peak rounds."""
    cfg, scale = ctx.cfg, ctx.scale
    target, out, h = search.for_triangles(ctx, job.value, job.details, rec)
    refine_log: list[dict] = []
    if h is not None and cfg.refine_rounds and h.max > rounds.ROUNDS_FLOOR * scale:
        out, h, refine_log = rounds.refine(ctx, out, h)
        # (the peak rounds refuse a result with defects: a result that has some already is not
        # run again for them)
        if "backed_off_from" not in job.details and cfg.peak_rounds > 0 and h.max > rounds.ROUNDS_FLOOR * scale \
                and defects.count(out) == 0:
            out, h = rounds.peak_rounds(ctx, out, h, target, job.details)
    return out, h, refine_log


def _meet_error(ctx: Ctx, job: _Job) -> tuple[Out, HausdorffResult, list[dict]]:
    """A ``max_error`` target: the smallest count within it, then the refine rounds."""
    probes: list[dict] = []
    _, out, h = search.for_error(ctx, job.value * ctx.scale, probes)
    job.details["max_error_target"] = job.value
    job.details["probes"] = probes
    refine_log: list[dict] = []
    if ctx.cfg.refine_rounds and h.max > rounds.ROUNDS_FLOOR * ctx.scale:
        out, h, refine_log = rounds.refine(ctx, out, h)
    return out, h, refine_log


def _bound(ctx: Ctx, job: _Job, h: HausdorffResult | None, rec: StageRecord
           ) -> tuple[HausdorffResult | None, dict | None]:
    """The proven bound of the result's error (``error_bound``), and a warning where proving it
    found an error above the limit the result was accepted under."""
    bound_log = None
    if h is not None and ctx.cfg.error_bound != "none":
        before = h.max
        h, bound_log = rounds.prove_bound(ctx, h)
        # the bound's cuts can find a larger distance than the measure that accepted the result
        limit = ctx.cap if job.kind == "triangles" else job.value * ctx.scale
        if h.max > before and limit > 0 and h.max > limit:
            what = f"error_ceiling = {ctx.cfg.error_ceiling}" if job.kind == "triangles" else f"max_error = {job.value}"
            rec.warn(f"proving the error bound found a larger error, {h.max / ctx.scale:.4%} of the diagonal, than "
                     f"the measure that accepted this result ({before / ctx.scale:.4%}); it is above {what}")
    return h, bound_log
