"""The defects of a result and what the stage does with them (docs/simplify.md, "Defects"):
finding them (flipped triangles through the stage's cached flip check, folds the input does not
have, triangles on new non-manifold edges), counting them (a result with :func:`count` > 0 is
refused by ``defects = "refuse"``; :func:`flaws` adds the folds, which the lock-and-retry
rounds try to remove), the input vertices to lock under them for the next round, and the
record's account of them.

The stage's phases call these through the module (``defects.count(out)``), so a test can
change one for the whole stage."""

from __future__ import annotations

import numpy as np
from scipy.spatial import cKDTree

from ...config import SimplifyConfig
from . import repair
from .error import FlipResult, SurfaceIndex, bounding_spheres, edge_counts, flip_check, triangle_areas
from .inputs import Prepared
from .state import Ctx, Out

# Points of the flip check over the input's area (at least 3 per output triangle).
_FLIP_SAMPLES = 8000


def check_flips(ctx: Ctx, V: np.ndarray, F: np.ndarray, prev: FlipResult | None = None) -> FlipResult:
    """The stage's flip check: only triangles not judged before (in ``prev``, else in the stage's
    last check) are measured; the result becomes the stage's last check."""
    cache = ctx.flip_cache
    fr = flip_check(ctx.index_a, V, F, samples=min(ctx.samples, _FLIP_SAMPLES), scale=ctx.scale,
                    prev=prev if prev is not None else cache.get("last"))
    cache["last"] = fr
    cache["checked"] = cache.get("checked", 0) + fr.checked
    return fr


def new_folds(ctx: Ctx, V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(t,) triangles in a fold (repair.folds) that is not where the input has one of
    its own (within 1% of the diagonal of an input fold)."""
    mask = np.zeros(len(F), bool)
    pairs = repair.folds(V, F)
    if len(pairs) == 0:
        return mask
    tris = np.unique(pairs.ravel())
    if ctx.fold_zones is not None and len(ctx.fold_zones):
        d, _ = cKDTree(ctx.fold_zones).query(V[F[tris]].mean(axis=1))
        tris = tris[d > 0.01 * ctx.scale]
    mask[tris] = True
    return mask


def new_nonmanifold_triangles(prep: Prepared, F: np.ndarray, src_vertex: np.ndarray) -> np.ndarray:
    """Output triangles on an edge used by more than two triangles, where the input vertices
    the edge's ends come from were not such an edge in the input."""
    bad = np.zeros(len(F), bool)
    edges, cnt, _ = edge_counts(F)
    nm = edges[cnt > 2]
    if len(nm) == 0:
        return bad
    e_in, c_in, _ = edge_counts(prep.F)
    n = len(prep.V)
    old = set((e_in[c_in > 2, 0] * n + e_in[c_in > 2, 1]).tolist())
    a, b = src_vertex[nm[:, 0]], src_vertex[nm[:, 1]]
    key = np.minimum(a, b) * n + np.maximum(a, b)
    new = nm[~np.isin(key, np.fromiter(old, np.int64, len(old)))]
    if len(new) == 0:
        return bad
    m = max(int(F.max()) + 1, 1)
    new_key = new[:, 0] * m + new[:, 1]
    for i, j in ((0, 1), (1, 2), (2, 0)):
        lo, hi = np.minimum(F[:, i], F[:, j]), np.maximum(F[:, i], F[:, j])
        bad |= np.isin(lo * m + hi, new_key)
    return bad


def count(out: Out) -> int:
    """Flipped triangles and triangles on new non-manifold edges: a result with any is not
    accepted (the stage backs off to more triangles)."""
    return int(out.flipped.sum()) + int(out.new_nonmanifold.sum())


def flaws(out: Out) -> int:
    """Defects and triangles in new folds: what the lock-and-retry rounds try to remove (a fold
    left over is reported, not a reason to back off: at strong reductions of thin parts a few
    are the price of the budget)."""
    return count(out) + (int(out.folded.sum()) if out.folded is not None else 0)


def lock_under(prep: Prepared, out: Out, index_a: SurfaceIndex, lock: np.ndarray) -> np.ndarray:
    """For each flipped output triangle (or one on a new non-manifold edge), the input vertex
    under it closest to its centre that is neither kept already (an output vertex's source)
    nor locked: a corner of the input triangles within its bounding sphere whose centroid is
    closest to it (or of any within the sphere, if none is)."""
    add = np.zeros(len(prep.V), bool)
    bad = out.flipped | out.new_nonmanifold
    if out.folded is not None:
        bad = bad | out.folded
    bad = np.flatnonzero(bad)
    if len(bad) == 0:
        return add
    cen, rad = bounding_spheres(out.V[out.F[bad]])
    rows, tris = index_a.near(cen, rad)
    if len(rows):
        # prefer the input triangles that stand under it (whose centroid is closest to it)
        # (each input triangle once: in soups of big triangles every one is near every bad one)
        ut, inv = np.unique(tris, return_inverse=True)
        _, closest = SurfaceIndex(out.V, out.F, seed=13, density=0).distance(index_a.centers[ut])
        own = closest[inv.reshape(-1)] == bad[rows]
        has_own = np.zeros(len(bad), bool)
        has_own[rows[own]] = True
        keep = own | ~has_own[rows]
        rows, tris = rows[keep], tris[keep]
    rows = np.repeat(rows, 3)
    cand = prep.F[tris].ravel()
    taken = lock.copy()
    taken[out.src_vertex] = True
    ok = ~taken[cand]
    rows, cand = rows[ok], cand[ok]
    done = np.zeros(len(bad), bool)
    if len(cand):
        d = np.linalg.norm(prep.V[cand] - cen[rows], axis=1)
        order = np.lexsort((cand, d, rows))
        rows, cand = rows[order], cand[order]
        # one vertex per bad triangle, distinct where possible: a vertex two triangles want
        # goes to the lower-numbered one, the other takes its next closest (a few passes)
        for _ in range(4):
            live = ~done[rows] & ~add[cand]
            r, c = rows[live], cand[live]
            if len(r) == 0:
                break
            first = np.r_[True, r[1:] != r[:-1]]
            r, c = r[first], c[first]
            _, win = np.unique(c, return_index=True)
            add[c[win]] = True
            done[r[win]] = True
    missing = np.flatnonzero(~done)
    add[out.src_vertex[out.F[bad[missing]].ravel()]] = True
    return add


def record(cfg: SimplifyConfig, out: Out, parts_rec: dict, new_nm: int, folds_added: int) -> dict:
    """What the result's defects are (docs/simplify.md, "Defects"): how many of each kind and the
    share of the result's area they cover (the parts': of the input's)."""
    area = triangle_areas(out.V, out.F)
    total = max(float(area.sum()), 1e-300)
    folded = out.folded if out.folded is not None else np.zeros(len(out.F), bool)
    return {"policy": cfg.defects,
            "flipped_triangles": int(out.flipped.sum()), "flipped_area": float(area[out.flipped].sum() / total),
            "new_nonmanifold_edges": int(new_nm),
            "triangles_on_new_nonmanifold_edges": int(out.new_nonmanifold.sum()),
            "new_nonmanifold_area": float(area[out.new_nonmanifold].sum() / total),
            "new_folds": int(max(0, folds_added)), "folded_area": float(area[folded].sum() / total),
            "parts_dropped": parts_rec["dropped"], "parts_collapsed": parts_rec["collapsed"],
            "areas_are": "shares of the result's area (the parts': their share of the input's, details.parts)"}
