"""Where the error of the result found peaks (stage.py's docstring, steps 3 and 4): the refine
rounds (local repairs of the triangles holding the largest distances), the peak rounds (the
input vertices nearest the largest places the library cut off are locked and the whole attempt
runs again), both only above ROUNDS_FLOOR, and the proven upper bound of the result's maximum
(measure.certify, down to BOUND_SHARE of the largest distance found or BOUND_FLOOR)."""

from __future__ import annotations

import time
from dataclasses import replace

import numpy as np
from scipy.spatial import cKDTree

from ...progress import step as report_step
from . import attempt, defects, repair
from .error import SurfaceIndex
from .measure import HausdorffResult, bound_hausdorff, directed, surface_grid
from .state import Ctx, Out

# A refine round works on the triangles whose error is within this fraction of the maximum ...
_PEAK_SHARE = 0.8
# ... at most this many separate places
_PEAKS = 24
# The peak round locks the input vertices at most this many of the largest cut-off places.
_PEAK_LOCKS = 8
# the proven bound (error_bound): cells are cut until none can hold more than this many times the
# largest distance found, nor more than BOUND_FLOOR of the diagonal (a twentieth of a pixel on a
# model 400 pixels across: where the error is about zero, e.g. flat results on their input), with
# at most _BOUND_POINTS x error_samples new points per direction
BOUND_SHARE = 1.02
BOUND_FLOOR = 1e-4
_BOUND_POINTS = 16
# The refine and peak rounds run only on a result whose measured max is above this fraction of
# the diagonal (the bound's floor: below it nothing a player shows can change; a flat cube cut
# into 48 triangles simplified to 24 spent 1.2 s of 1.8 s lowering an error of 1.3e-8)
ROUNDS_FLOOR = BOUND_FLOOR


class _Tracker:
    """The error around each triangle of a result as the measure ``h`` saw it, kept up to date
    while the refine rounds change a few triangles: per triangle, the largest distance from its
    grid (and the refinement) to the input, and the largest distance of the input's measured
    points whose closest triangle it is. A changed triangle is measured again (its grid at the
    measure's spacing, refined); an input point whose closest triangle changed is measured
    again against the whole result; the other values stay valid (upper bounds)."""

    def __init__(self, ctx: Ctx, F: np.ndarray, h: HausdorffResult):
        ab, ba = h.a_to_b, h.b_to_a
        self.ctx = ctx
        self.PA = ab.all_points
        self.dA = ab.all_dists.copy()
        self.nA = ab.all_nearest.copy()
        self.ba = np.zeros(len(F))
        if ba.tri_max is not None:
            self.ba[:len(ba.tri_max)] = ba.tri_max
        self.spacing = ba.spacing

    def values(self) -> np.ndarray:
        val = self.ba.copy()
        ok = self.nA >= 0
        np.maximum.at(val, self.nA[ok], self.dA[ok])
        return val

    def update(self, V: np.ndarray, F: np.ndarray, changed: np.ndarray) -> None:
        if len(changed) == 0:
            return
        g = surface_grid(V, F[changed], 0, spacing=self.spacing)
        d = directed(self.ctx.index_a, g, seeds=max(8, min(64, 2 * len(changed))), rounds=8, verify=False,
                     prune=False)
        tm = np.zeros(len(changed))
        if d.tri_max is not None:
            tm[:len(d.tri_max)] = d.tri_max
        self.ba[changed] = tm
        hit = np.zeros(len(F), bool)
        hit[changed] = True
        sel = np.flatnonzero(hit[np.maximum(self.nA, 0)] & (self.nA >= 0))
        if len(sel):
            self.dA[sel], self.nA[sel] = SurfaceIndex(V, F).distance(self.PA[sel])


def refine(ctx: Ctx, out: Out, h: HausdorffResult) -> tuple[Out, HausdorffResult, list[dict]]:
    """``refine_rounds`` rounds of local repair where the error peaks (stage.py's docstring, step 3).
    Each round takes the triangles whose error is within _PEAK_SHARE of the largest (as the
    measure saw it, kept up to date by a _Tracker), turns their edges where that lowers the
    local error, moves their free corners to lower the local maximum and puts back any corner
    that turned a triangle against the input. What a round changed is measured again; corners
    around a triangle whose error rose above the round's starting maximum are put back (and the
    round's edge turns undone). The result is measured once at the end and kept only if its
    maximum is lower."""
    log: list[dict] = []
    cfg = ctx.cfg
    if cfg.refine_rounds <= 0 or len(out.F) == 0 or h.a_to_b is None or h.a_to_b.all_points is None \
            or out.flip is None:  # (the input itself, backed off to: left as it is)
        return out, h, log
    t = time.perf_counter()
    V, F = out.V.copy(), out.F.copy()
    tri_uvs = None if out.tri_uvs is None else out.tri_uvs.copy()
    # h measured this mesh: its grid's closest triangles are the assignment
    le = attempt.local_error(ctx, V, F, spacing=h.b_to_a.spacing, near=h.a_to_b.nearest)
    tracker = _Tracker(ctx, F, h)
    fr = out.flip
    stuck = False
    for k in range(cfg.refine_rounds):
        report_step(f"refine round {k + 1} of {cfg.refine_rounds}")
        val = tracker.values()
        mx = float(val.max())
        if mx <= 0:
            break
        hot = np.flatnonzero(val >= _PEAK_SHARE * mx)
        hot = hot[np.argsort(-val[hot], kind="stable")[:_PEAKS]]
        F0, V0, uv0, fr0, a0 = F.copy(), V.copy(), None if tri_uvs is None else tri_uvs.copy(), fr, le.a_tri.copy()
        turned = 0
        if out.src_tri is None:
            turned = repair.flip_edges(V, F, out.region, tri_uvs, None, le, candidates=hot)
            if turned:
                fr = defects.check_flips(ctx, V, F, fr)
                tracker.update(V, F, np.flatnonzero((F != F0).any(axis=1)))
        info: dict = {}
        V_mid = V.copy()
        verts = np.unique(F[hot].ravel())
        if stuck:
            # the last round could not lower these peaks: let the ring around them move too
            ring = np.zeros(len(V), bool)
            ring[verts] = True
            verts = np.unique(F[ring[F].any(axis=1)].ravel())
        moved, _ = repair.polish(V, F, out.fixed, le, verts, ref=fr.ref,
                                 tri_error=tracker.values())
        if moved:
            V, fr, _ = attempt.no_new_flips(ctx, V_mid, V, F, fr, info)
        entry = {"peak_triangles": int(len(hot)), "edges_turned": int(turned), "vertices_moved": int(moved),
                 "reverted_vertices": int(info.get("reverted_vertices", 0)), "largest_error_before": mx / ctx.scale}
        log.append(entry)
        changed = np.flatnonzero((F != F0).any(axis=1) | (V[F] != V0[F]).any(axis=(1, 2)))
        if len(changed) == 0:
            break
        tracker.update(V, F, changed)
        _reassign(le, V, F, changed)
        val = tracker.values()
        worse = changed[val[changed] > mx]
        put_back = 0
        for _ in range(4):
            worse = changed[val[changed] > mx]
            if len(worse) == 0:
                break
            # corners around a triangle that got worse than the round's starting maximum go back
            # (and if it was turned, every turn of the round is undone)
            back = np.unique(F[worse].ravel())
            redo = np.zeros(0, np.int64)
            if (F[worse] != F0[worse]).any():
                redo = np.flatnonzero((F != F0).any(axis=1))
                F[redo] = F0[redo]
                if tri_uvs is not None:
                    tri_uvs[redo] = uv0[redo]
                back = np.unique(np.concatenate([back, F[redo].ravel()]))
            back = back[(V[back] != V0[back]).any(axis=1)]
            V[back] = V0[back]
            put_back += len(back)
            hit = np.zeros(len(V), bool)
            hit[back] = True
            again = np.union1d(np.flatnonzero(hit[F].any(axis=1)), redo)
            fr = defects.check_flips(ctx, V, F, fr)
            tracker.update(V, F, again)
            _reassign(le, V, F, again)
            val = tracker.values()
        if put_back:
            entry["put_back_vertices"] = int(put_back)
        if (val[changed] > mx).any():
            F[:], V[:] = F0, V0
            if tri_uvs is not None:
                tri_uvs[:] = uv0
            le.set_assignment(a0, len(F))
            fr = fr0
            tracker.update(V, F, changed)
            entry["undone"] = True
            entry["largest_error_after"] = float(val.max()) / ctx.scale
            break
        entry["largest_error_after"] = float(val.max()) / ctx.scale
        if val.max() >= mx:
            if stuck:
                break
            stuck = True
        else:
            stuck = False
    repair_s = time.perf_counter() - t
    ctx.seconds["repair"] += repair_s
    if np.array_equal(V, out.V) and np.array_equal(F, out.F):
        return out, h, log
    o2 = replace(out, V=V, F=F, tri_uvs=tri_uvs, flipped=fr.flipped, flip=fr, h=None,
                 folded=defects.new_folds(ctx, V, F),
                 new_nonmanifold=defects.new_nonmanifold_triangles(ctx.prep, F, out.src_vertex))
    h2 = attempt.measure(ctx, o2)
    keep = bool(h2.max < h.max and defects.flaws(o2) <= defects.flaws(out))
    log.append({"hausdorff_max": float(h2.max / ctx.scale), "kept": keep})
    if keep:
        return o2, h2, log
    return out, h, log


def _reassign(le: repair.LocalError, V: np.ndarray, F: np.ndarray, changed: np.ndarray) -> None:
    """The input points that stood for a changed triangle: their closest triangle again."""
    pts, _ = le.points_of(changed)
    if len(pts):
        _, near = SurfaceIndex(V, F).distance(le.P[pts])
        le.a_tri[pts] = near
        le.set_assignment(le.a_tri, len(F))


def peak_rounds(ctx: Ctx, out: Out, h: HausdorffResult, target: int, details: dict
                ) -> tuple[Out, HausdorffResult]:
    """``peak_rounds`` rounds for features the library cut off (the input's points farthest
    from the result, within _PEAK_SHARE of the maximum, up to _PEAK_LOCKS separate places),
    which moving corners cannot put back: the input vertex closest to each is locked (with
    those of the rounds before) and the whole stage runs again (library, repairs, fit, refine
    rounds). A round's result is kept if its measured max is lower, with no more defects and
    folds (teapot at 10%: 0.988% -> 0.531% of the diagonal); a round whose result has flipped
    triangles or new non-manifold edges after the fit is neither measured nor refined."""
    log: list[dict] = []
    lock = np.zeros(len(ctx.prep.V), bool)
    tree = cKDTree(ctx.prep.V)
    for k in range(ctx.cfg.peak_rounds):
        report_step(f"peak round {k + 1} of {ctx.cfg.peak_rounds}")
        ab = h.a_to_b
        if ab is None or len(ab.peak_points) == 0:
            break
        pts = ab.peak_points[ab.peak_dists >= _PEAK_SHARE * h.max][:_PEAK_LOCKS]
        if len(pts) == 0:
            break
        _, nv = tree.query(pts)
        if lock[nv].all():
            break
        lock[nv] = True
        o3, h3 = attempt.whole(ctx, target, lock, refuse_defects=True)
        if h3 is not None and ctx.cfg.refine_rounds:
            o3, h3, _ = refine(ctx, o3, h3)
        keep = bool(h3 is not None and h3.max < h.max and defects.count(o3) == 0
                    and defects.flaws(o3) <= defects.flaws(out))
        log.append({"locked_vertices": int(lock.sum()), "defects": defects.count(o3),
                    "hausdorff_max_before": float(h.max / ctx.scale),
                    "hausdorff_max_after": None if h3 is None else float(h3.max / ctx.scale), "kept": keep})
        if not keep:
            break
        out, h = o3, h3
    details["peak_rounds"] = log
    return out, h


def prove_bound(ctx: Ctx, h: HausdorffResult) -> tuple[HausdorffResult, dict | None]:
    """The result's measure with a proven upper bound of its maximum, per direction that
    ``error_bound`` asks for (measure.certify: cells cut, largest bound first, until none
    can hold more than BOUND_SHARE times the largest distance found or BOUND_FLOOR of the
    diagonal, or the points run out)."""
    if h.a_to_b is None or h.b_to_a is None:  # (backed off all the way: the input, not measured)
        return h, None
    report_step("proving the error bound")
    t = time.perf_counter()
    floor = BOUND_FLOOR * ctx.scale
    # a result whose measured max is under the floor (flat faces simplified flat) gets a small
    # budget: its only open cells straddle the result's edges, where the bound is the cell's size
    # and halves per cut (a CSG-like assembly at 26% spent 320,000 points, 2.4 s, to prove 2e-4)
    points = (_BOUND_POINTS if h.max > floor else 1) * ctx.samples
    h2 = bound_hausdorff(h, BOUND_SHARE, points, floor, both=ctx.cfg.error_bound == "both")
    log: dict = {"share": BOUND_SHARE, "floor": BOUND_FLOOR, "points_per_direction": points}
    for name, d, before in (("original_to_simplified", h2.a_to_b, h.a_to_b),
                            ("simplified_to_original", h2.b_to_a, h.b_to_a)):
        if d.certification is None:
            continue
        log[name] = {"bound": float(d.bound / ctx.scale), "finished": d.certification["open_cells"] == 0,
                     "within_share": bool(d.bound <= BOUND_SHARE * d.max),
                     "max_before": float(before.max / ctx.scale), "max_after": float(d.max / ctx.scale),
                     **d.certification}
    ctx.seconds["measure"] += time.perf_counter() - t
    log["seconds"] = round(time.perf_counter() - t, 6)
    return h2, log
