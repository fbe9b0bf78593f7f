"""Finding the count: a triangle target met by one attempt, or, where its result is refused
(defects with ``defects = "refuse"``, an error above ``error_ceiling``), the smallest larger
count whose result is not (:func:`for_triangles`); for a ``max_error`` target, the smallest
count whose measured error stays within it (:func:`for_error`)."""

from __future__ import annotations

import time

import numpy as np

from ...progress import step as report_step
from ...record import StageRecord
from . import attempt, defects, ladder, meshopt
from .inputs import wedges
from .measure import HausdorffResult
from .state import Ctx, Out


def for_triangles(ctx: Ctx, value: float, details: dict, rec: StageRecord
                  ) -> tuple[int, Out, HausdorffResult | None]:
    """(layer target, result, its measure) for a target of ``value`` triangles written. A
    refused result backs off (details.backed_off_from, details.probes; the record says why)."""
    prep, cfg, scale, cap = ctx.prep, ctx.cfg, ctx.scale, ctx.cap
    T0 = len(prep.F)
    # the layer's count whose triangles, with the backs put back, are the target
    target = max(1, int(round(int(value) * T0 / (T0 + prep.layer.twins))))
    refuse = cfg.defects == "refuse"
    out, h = attempt.whole(ctx, target, refuse_defects=refuse)

    def acceptable(o: Out, hh) -> bool:
        return (not refuse or defects.count(o) == 0) and (hh is None or cap <= 0 or hh.max <= cap)

    if not acceptable(out, h):
        # fewer triangles cost flips, non-manifold edges or more than the ceiling: find the
        # smallest count above the target that does not
        why = (f"{int(out.flipped.sum())} flipped triangle(s), {int(out.new_nonmanifold.sum())} on new "
               f"non-manifold edges (defects = \"refuse\")" if refuse and defects.count(out) else
               f"an error of {h.max / scale:.3%} of the diagonal (error_ceiling = {cfg.error_ceiling})")
        probes: list[dict] = []
        # (never None: the probes go up to the input itself, which is always acceptable)
        n, o2, h2 = _back_off(ctx, target, acceptable, probes)
        if o2 is not None:
            o2, h2 = attempt.fitted(ctx, o2)  # kept only if not worse than the probe's measured result
            n_out, n_got = ladder.total(prep, out), ladder.total(prep, o2)
            got = "" if n_out == int(value) else f" (what a target of {int(value)} gave)"
            rec.warn(f"{n_out} triangles{got} would cost {why}; stopped at {n_got} triangles instead")
            out, h = o2, h2
            details["backed_off_from"] = target
        details["probes"] = probes
    return target, out, h


def _back_off(ctx: Ctx, target: int, acceptable, probes: list):
    """Smallest count in (target, T0] whose result is acceptable (grow by 30% until one is,
    then bisect a few times). Returns (count, out, hausdorff) or (target, None, None)."""
    T0, scale = len(ctx.prep.F), ctx.scale
    tried: dict[int, tuple] = {}

    def probe(n: int) -> bool:
        report_step(f"back-off probe {len(tried) + 1}: {n:,} triangles")
        out, h = attempt.whole(ctx, n, None, 0, False)  # no lock-and-retry rounds here: backing off is the repair
        ok = acceptable(out, h)
        tried[n] = (out, h, ok)
        probes.append({"target": n, "triangles": int(len(out.F)), "defects": defects.count(out),
                       "hausdorff_max": None if h is None else float(h.max) / scale, "ok": ok})
        return ok

    bad, good, n = target, None, target
    while good is None and n < T0:
        # grow faster once small steps keep failing (at most ~8 probes to reach the input)
        step = 1.3 if len(tried) < 3 else 1.8
        n = min(T0, max(n + 1, int(np.ceil(n * step))))
        if probe(n):
            good = n
        else:
            bad = n
    if good is None:
        return target, None, None
    for _ in range(3):
        if good - bad <= max(1, int(0.02 * good)):
            break
        mid = (good + bad) // 2
        if probe(mid):
            good = mid
        else:
            bad = mid
    out, h, _ = tried[good]
    return good, out, h


def for_error(ctx: Ctx, e_abs: float, probes: list) -> tuple[int, Out, HausdorffResult]:
    """Smallest triangle count (within ~5%) whose measured Hausdorff max is <= e_abs."""
    prep, T0, scale = ctx.prep, len(ctx.prep.F), ctx.scale
    tried: dict[int, tuple] = {}

    def probe(n: int):
        n = int(min(max(n, 4), T0))
        if n in tried:
            return tried[n]
        out, h = attempt.whole(ctx, n)
        tried[n] = (out, h)
        probes.append({"target": n, "triangles": int(len(out.F)), "hausdorff_max": float(h.max) / scale,
                       "defects": defects.count(out), "ok": bool(h.max <= e_abs and defects.count(out) == 0)})
        return tried[n]

    # first guess: meshoptimizer's own error bound, else 10% of the input
    if ctx.method == "meshopt":
        Fw, w_vertex, _, _ = wedges(prep)
        t = time.perf_counter()
        raw_n = len(meshopt.simplify(prep.V[w_vertex], Fw, 0, target_error=e_abs, absolute_error=True)[0])
        ctx.seconds["library"] += time.perf_counter() - t
        n = max(raw_n, 4)
    else:
        n = max(T0 // 10, 4)
    lo, hi = 0, None  # lo: largest count known to fail; hi: smallest known to pass
    for _ in range(9):
        out, h = probe(n)
        if h.max <= e_abs and defects.count(out) == 0:
            hi = n if hi is None else min(hi, n)
        else:
            lo = max(lo, n)
        if hi is not None and hi <= lo * 1.05 + 1:
            break
        if hi is None:
            if n >= T0:
                break
            # error falls roughly like 1 / count on smooth surfaces
            n = int(min(T0, max(n * 1.25, n * (h.max / e_abs) * 1.1)))
        elif lo == 0:
            n = int(max(4, n * max(0.25, min(0.8, (h.max / e_abs) * 0.9))))
        else:
            n = int(np.sqrt(lo * hi))
        if n in tried:
            break
    if hi is None:
        best_n = max(tried, key=lambda k: (tried[k][1].max <= e_abs and defects.count(tried[k][0]) == 0, k))
    else:
        best_n = hi
    out, h = tried[best_n]
    return best_n, out, h
