"""One attempt at a triangle count (stage.py's docstring, steps 1 and 2): the library through the
ladder (ladder.run_to, with the border and seam chains locked first), the repairs right after it
(turning edges at fins and folds, repairing flipped triangles), the lock-and-retry rounds while
defects are left, then the least-squares fit, kept only if the measure says it did not cost
shape. :func:`whole` is an attempt as the searches and the peak rounds call it."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np

from ...progress import step as report_step
from . import defects, ladder, repair
from .error import FlipResult, SurfaceIndex
from .fit import refit
from .library import Raw
from .measure import HausdorffResult, hausdorff, original_side
from .state import Ctx, Out

# Rounds of "lock the input vertices under flipped triangles and simplify again".
_REPAIR_ROUNDS = 3
# The lock-and-retry rounds stop when a round leaves more than _FLAWS_FEW flaws and more than
# _FLAWS_DROP of the best before it: on a CAD assembly each round moved most of its ~1,500 flaws
# elsewhere (1,509 -> 1,222 -> 1,330) at the cost of a whole library run and repair. A few flaws
# go on to the last round (the teapot's peak round: 2 folds, then 4, then none)
_FLAWS_FEW = 32
_FLAWS_DROP = 0.75
# Border and seam chains are simplified at this fraction of the library's own error estimate.
_BORDER_TOLERANCE = 0.5
# Refinement rounds of the quick measure that checks whether the fit made the result worse (0:
# the grids alone, a subset of the full measure's points, so a lower bound of its max).
_FIT_CHECK_ROUNDS = 0
# The fit lowers the mean distance and may raise a peak a little, which the refine rounds then
# work on (the bunny's orderings: up to 10% higher before the rounds, lower after them); a fit
# that raises the measured max by more than this factor is not kept (CSG corners: 10x).
_FIT_TOLERANCE = 1.25


def local_error(ctx: Ctx, V: np.ndarray, F: np.ndarray, spacing: float = 0.0,
                near: np.ndarray | None = None) -> repair.LocalError:
    """The input's grid points, each assigned to its closest triangle of (V, F) (``near``:
    already known, from a measure of this very mesh)."""
    if near is None or len(near) != len(ctx.grid_a.P):
        _, near = SurfaceIndex(V, F).distance(ctx.grid_a.P)
    return repair.LocalError(ctx.index_a, ctx.grid_a.P, near, len(F), spacing=spacing)


def _finish(ctx: Ctx, raw: Raw) -> Out:
    """Drop repeated-corner triangles, compact vertices, turn edges at fins and folds, find and
    repair flips (the fit comes after, in _fit)."""
    prep, scale = ctx.prep, ctx.scale
    F = raw.F
    ok = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    F = F[ok]
    region = raw.region[ok]
    src_tri = None if raw.src_tri is None else raw.src_tri[ok]
    tri_uvs = None if raw.tri_uvs is None else raw.tri_uvs[ok]
    used = np.zeros(len(raw.V), bool)
    used[F.ravel()] = True
    remap = np.cumsum(used) - 1
    V = raw.V[used]
    F = remap[F]
    src_vertex = raw.src_vertex[used]
    fixed = raw.fixed[used] | ctx.protect[src_vertex] & (np.linalg.norm(V - prep.V[src_vertex], axis=1) == 0)
    if tri_uvs is None and prep.tri_uvs is not None and src_tri is not None:
        tri_uvs = prep.tri_uvs[src_tri]  # corner order is kept by the libraries
    t = time.perf_counter()
    turns = 0
    if src_tri is None and len(F) > 1:
        # fins and folds: turn edges at sharp dihedrals where that lowers the local error
        # (methods that carry a source triangle per output triangle keep their triangles)
        F = F.copy()
        tri_uvs = None if tri_uvs is None else tri_uvs.copy()
        le = local_error(ctx, V, F)
        turns = repair.flip_edges(V, F, region, tri_uvs, None, le)
    repair_s = time.perf_counter() - t
    t = time.perf_counter()
    info_repair = None
    fr = defects.check_flips(ctx, V, F)
    before = (V.copy(), F.copy(), None if tri_uvs is None else tri_uvs.copy(), fr) if fr.flipped.any() else None
    edge_flips = 0
    for _ in range(3):
        if not fr.flipped.any():
            break
        n = repair.edge_flip_repair(V, F, region, tri_uvs, fr)
        if n == 0:
            break
        edge_flips += n
        fr = defects.check_flips(ctx, V, F, fr)
    relocated = 0
    if fr.flipped.any():
        V = V.copy()
        relocated = repair.relocate_repair(V, F, fixed, fr, ctx.index_a)
        if relocated:
            fr = defects.check_flips(ctx, V, F, fr)
    if before is not None and (edge_flips or relocated):
        # repairs act on what the flip check flagged; keep them only if they do not cost shape
        # where they act (the error over the repaired triangles and the ring around them)
        e0, e1 = repair.repair_cost(ctx.index_a, before[0], before[1], V, F)
        info_repair = {"local_error_before": e0 / scale, "local_error_after": e1 / scale}
        if e1 > 1.1 * e0 + 1e-12 * scale:
            V, F, tri_uvs, fr = before
            edge_flips = relocated = 0
            info_repair["undone"] = True
    folded = defects.new_folds(ctx, V, F)
    unfolded = 0
    if folded.any():
        # a fold the edge turns could not undo: move a free corner to the middle of its
        # neighbours on the input surface, where every triangle around it then faces the input
        V = V.copy()
        unfolded = repair.relocate_repair(V, F, fixed, replace(fr, flipped=folded), ctx.index_a)
        if unfolded:
            fr = defects.check_flips(ctx, V, F, fr)
            folded = defects.new_folds(ctx, V, F)
    check_s = time.perf_counter() - t
    ctx.seconds["library"] += raw.lib_seconds
    ctx.seconds["repair"] += repair_s
    ctx.seconds["check"] += check_s
    info = {"rounds": 0, "reverted_vertices": 0, "edge_flips": edge_flips, "relocated_vertices": relocated,
            "unfolded_vertices": unfolded}
    if info_repair is not None:
        info["repair_check"] = info_repair
    return Out(V=V, F=F, src_vertex=src_vertex, region=region, src_tri=src_tri, tri_uvs=tri_uvs, fixed=fixed,
               fit_info=info, notes=list(raw.notes), flipped=fr.flipped, flip=fr,
               new_nonmanifold=defects.new_nonmanifold_triangles(prep, F, src_vertex), lib_error=raw.lib_error,
               edge_turns=turns, folded=folded)


def _identity(ctx: Ctx) -> Out:
    """The input itself as a result (what backing off to the input's count gives), with its
    error, exactly 0, as its measure (so nothing measures it against itself)."""
    prep = ctx.prep
    T = len(prep.F)
    z = np.zeros(T, bool)
    return Out(V=prep.V, F=prep.F, src_vertex=np.arange(len(prep.V)), region=prep.region, src_tri=np.arange(T),
               tri_uvs=None if prep.tri_uvs is None else prep.tri_uvs, fixed=np.ones(len(prep.V), bool),
               fit_info={"rounds": 0}, notes=[], flipped=z,
               new_nonmanifold=z.copy(), folded=z.copy(),
               h=HausdorffResult(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, np.zeros(3), 0, 0))


def no_new_flips(ctx: Ctx, V0: np.ndarray, Vn: np.ndarray, F: np.ndarray, fr: FlipResult,
                 info: dict) -> tuple[np.ndarray, FlipResult, bool]:
    """Put back the corners of any triangle a move (V0 -> Vn) turned against the input or into a
    fold (a few rounds, only the triangles that moved are checked). Returns (positions, flip
    result, whether no new flip or fold is left)."""
    Vn = Vn.copy()
    ff = fr
    folded0 = defects.new_folds(ctx, V0, F)
    for _ in range(6):
        ff = defects.check_flips(ctx, Vn, F, ff)
        new = (ff.flipped & ~fr.flipped) | (defects.new_folds(ctx, Vn, F) & ~folded0)
        if not new.any():
            return Vn, ff, True
        back = np.unique(F[new].ravel())
        moved = back[(Vn[back] != V0[back]).any(axis=1)]
        if len(moved) == 0:
            break
        info["reverted_vertices"] = info.get("reverted_vertices", 0) + int(len(moved))
        Vn[moved] = V0[moved]
    ff = defects.check_flips(ctx, Vn, F, ff)
    return Vn, ff, not ((ff.flipped & ~fr.flipped) | (defects.new_folds(ctx, Vn, F) & ~folded0)).any()


def _fit(ctx: Ctx, out: Out) -> Out:
    """Refit the free vertices of a result (fit.py), adding no flipped triangle (corners of any
    it turns are put back). Whether the fit is kept is decided by the caller, on the measured
    error."""
    cfg = ctx.cfg
    if cfg.fit_iterations <= 0 or len(out.F) == 0 or out.fixed.all():  # (the input itself: nothing moves)
        return out
    V, F, fr, fixed = out.V, out.F, out.flip, out.fixed
    info = dict(out.fit_info)
    report_step(f"{len(F):,} triangles: fit")
    t = time.perf_counter()
    Vf, fit_info = refit(V, F, fixed, ctx.index_a, ctx.fit_points, iterations=cfg.fit_iterations,
                         samples_b=min(ctx.samples, 8000), seed=cfg.seed)
    info.update(fit_info)
    fit_s = time.perf_counter() - t
    ctx.seconds["fit"] += fit_s
    t = time.perf_counter()
    Vf, ff, ok = no_new_flips(ctx, V, Vf, F, fr, info)
    folded = defects.new_folds(ctx, Vf, F) if ok else None
    ctx.seconds["check"] += time.perf_counter() - t
    if not ok:
        info["abandoned"] = True
        return replace(out, fit_info=info)
    return replace(out, V=Vf, flipped=ff.flipped, flip=ff, fit_info=info, h=None, folded=folded)


def measure(ctx: Ctx, out: Out) -> HausdorffResult:
    """The stage's error measure of a result (taken once; measure.hausdorff)."""
    if out.h is None:
        report_step(f"{len(out.F):,} triangles: measure")
        t = time.perf_counter()
        out.h = hausdorff(ctx.prep.V, ctx.prep.F, out.V, out.F, points=ctx.samples, index_a=ctx.index_a,
                          grid_a=ctx.grid_a, seeds=ctx.seeds)
        ctx.measures += 1
        ctx.seconds["measure"] += time.perf_counter() - t
    return out.h


def _lock_and_retry(ctx: Ctx, target: int, lock0: np.ndarray | None = None, rounds: int = _REPAIR_ROUNDS) -> Out:
    """Simplify; while triangles come out flipped, keep the input vertices under them
    (locked) and simplify again (a few rounds)."""
    prep, scale = ctx.prep, ctx.scale
    lock = np.zeros(len(prep.V), bool) if lock0 is None else lock0.copy()
    lib_s = 0.0
    if ctx.chains and "locks" not in prep.relaxed:
        # keep each border/seam chain within half the library's error estimate of itself
        raw0 = ladder.run_to(ctx, target, lock, ctx.cap, ctx.relax_log)
        lib_s += raw0.lib_seconds
        tol = _BORDER_TOLERANCE * raw0.lib_error
        # the locks may take at most a quarter of the target's vertices (about target / 2):
        # the chords that stray furthest are kept first
        budget = max(8, target // 8)
        blk = repair.border_locks(prep.V, ctx.chains, ctx.chain_ends, tol, len(prep.V), budget)
        ctx.border_log.update({"tolerance": tol / scale, "budget": budget, "locked_vertices": int(blk.sum()),
                               "chain_vertices": int(sum(len(c) for c in ctx.chains))})
        if int(blk.sum()) > budget:  # the chains' ends alone are too many (soups, CSG slivers)
            blk[:] = False
            ctx.border_log.update({"locked_vertices": 0, "skipped": f"the chains have more than {budget} ends"})
        lock |= blk
    best = None
    for rnd in range(rounds + 1):
        report_step(f"{target:,} triangles: library and repairs" + (f", lock round {rnd}" if rnd else ""))
        raw = ladder.run_to(ctx, target, lock, ctx.cap, ctx.relax_log)
        raw.lib_seconds += lib_s
        lib_s = 0.0
        out = _finish(ctx, raw)
        n_flip = defects.flaws(out)
        before = None if best is None else defects.flaws(best)
        if best is None or n_flip < before:
            best = out
        if n_flip == 0 or rnd == rounds:
            break
        if before is not None and n_flip > _FLAWS_FEW and n_flip > _FLAWS_DROP * before:
            break  # the last round moved the flaws more than it removed them
        if "locks" in prep.relaxed:  # (locking is what the target could not afford)
            break
        t = time.perf_counter()
        add = defects.lock_under(prep, out, ctx.index_a, lock)
        ctx.seconds["repair"] += time.perf_counter() - t
        if not (add & ~lock).any():
            break
        lock |= add
        ctx.repair_log.append({"target": int(target), "round": rnd + 1, "flipped": int(out.flipped.sum()),
                               "on_new_nonmanifold_edges": int(out.new_nonmanifold.sum()),
                               "folded": int(out.folded.sum()) if out.folded is not None else 0,
                               "locked_vertices": int(lock.sum())})
    return best


def fitted(ctx: Ctx, out: Out, o1: Out | None = None) -> tuple[Out, HausdorffResult | None]:
    """The fit (abandoned if it turns triangles against the input or into folds) and the
    measure of the result; the fit is kept only if its measured max is not above
    _FIT_TOLERANCE times the unfitted result's. A least-squares fit pulls sharp CSG/CAD
    corners off their places (boolean.glb at 50%: 0.96% of the diagonal with it, 0.09%
    without), so the unfitted result is measured too: first on the input's grid alone,
    then on both grids (_FIT_CHECK_ROUNDS refinement rounds, no cut cells: a subset of the
    full measure's points, so its max can only be lower than the full one), in full only
    if neither already settles it. ``o1``: the fit of ``out``, made already."""
    prep, cfg, scale = ctx.prep, ctx.cfg, ctx.scale
    o1 = _fit(ctx, out) if o1 is None else o1
    if not ctx.measuring:
        return o1, None
    h1 = measure(ctx, o1)
    if o1 is out:
        return o1, h1
    if out.h is not None:  # measured already (a back-off probe)
        hl = out.h
    else:
        t = time.perf_counter()
        # the input's side first (its grid against the small result: cheap); the other side,
        # against the input, only if that alone does not already keep the fit
        ib = SurfaceIndex(out.V, out.F)
        hl = original_side(ib, ctx.grid_a, seeds=ctx.seeds, rounds=_FIT_CHECK_ROUNDS, straddling=False)
        if h1.max > _FIT_TOLERANCE * hl.max:
            hl = hausdorff(prep.V, prep.F, out.V, out.F, points=ctx.samples, index_a=ctx.index_a,
                           grid_a=ctx.grid_a, index_b=ib, seeds=ctx.seeds, rounds=_FIT_CHECK_ROUNDS, straddling=False,
                           a_to_b=hl)
        ctx.measures += 1
        ctx.seconds["measure"] += time.perf_counter() - t
    check = {"max_with_fit": float(h1.max / scale), "max_without_fit_at_least": float(hl.max / scale)}
    if h1.max <= _FIT_TOLERANCE * hl.max:
        o1.fit_info = {**o1.fit_info, "kept": True, "check": check}
        return o1, h1
    h0 = measure(ctx, out)
    check["max_without_fit"] = float(h0.max / scale)
    if h1.max > _FIT_TOLERANCE * h0.max:
        out.fit_info = {**o1.fit_info, "kept": False, "check": check}
        return out, h0
    o1.fit_info = {**o1.fit_info, "kept": True, "check": check}
    return o1, h1


def whole(ctx: Ctx, target: int, lock0: np.ndarray | None = None, rounds: int = _REPAIR_ROUNDS, fit: bool = True,
          refuse_defects: bool = False) -> tuple[Out, HausdorffResult | None]:
    """One attempt at ``target`` (layer triangles): the library and its repairs with the
    lock-and-retry ``rounds`` (``lock0``: input vertices locked from the start), then the fit and
    the measure. ``fit = False``: a back-off probe, the library's result measured as it is.
    ``refuse_defects``: a result with defects is handed back unmeasured (None)."""
    T0 = len(ctx.prep.F)
    if target >= T0:  # backing off all the way: the input as it is
        o = _identity(ctx)
        return o, o.h
    o = _lock_and_retry(ctx, target, lock0, rounds)
    if len(o.F) >= T0:  # nothing collapsed (a box): the input itself is as many triangles, exact
        return whole(ctx, T0)
    if not fit:  # a back-off probe: the library's result, measured (the fit comes once, after)
        # a result with defects is refused whatever its error: not measured
        return o, (measure(ctx, o) if ctx.measuring and defects.count(o) == 0 else None)
    if refuse_defects and o.new_nonmanifold.any():
        # refused whatever its error (the triangle target backs off from it; the fit moves
        # vertices only, so it cannot mend the topology): neither fitted nor measured
        return o, None
    if refuse_defects and defects.count(o):
        # flipped triangles: refused too, unless the fit turns them back (it turns none
        # against the input, and may turn some back); if it does not, not measured
        o1 = _fit(ctx, o)
        if defects.count(o1):
            return o1, None
        return fitted(ctx, o, o1)
    return fitted(ctx, o)
