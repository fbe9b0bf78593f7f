"""Clean stage: weld close vertices, drop degenerate triangles and unused vertices.

* **Weld** (``weld``): vertices closer than ``weld_tolerance * scene.scale()`` (the bounding-box
  diagonal) become one. Exact duplicates are merged first (``np.unique`` on rows), then a k-d tree
  finds the pairs within the tolerance and connected components give the groups, so welding is
  transitive (a chain of vertices each within the tolerance of the next welds into one; with the
  default 1e-7 of the diagonal that never matters). When the scene has vertex colours, only
  vertices with equal RGBA colours weld. UVs are per corner, so they never block welding. A group
  keeps the position (and colour) of its lowest-numbered vertex, so no coordinate drifts, and the
  groups are numbered in order of their lowest vertex (deterministic, order-preserving).
* **Degenerate triangles** (``drop_degenerate``): a triangle with a repeated vertex index (after
  welding) or with area below ``area_tolerance * scale^2`` is dropped, with its material, UVs,
  face colour and source polygon entry. A polygon that loses any triangle is no longer whole:
  its remaining triangles get ``tri_polygon = -1`` (counted as ``polygons_split``; polygons
  with no triangle left are ``polygons_dropped``).
* **Unused vertices** (``drop_unused_vertices``): vertices that no triangle and no polygon uses
  are dropped and the rest renumbered in order. Polygons are remapped through the weld and kept
  (the export stage reads them with ``tri_polygon``), so vertices they use are kept.

Every count goes into the record; the result passes ``Scene.validate()``.
"""

from __future__ import annotations

import time

import numpy as np
from scipy.sparse import coo_matrix
from scipy.sparse.csgraph import connected_components
from scipy.spatial import cKDTree

from ..config import CleanConfig
from ..record import StageRecord
from ..scene import Scene


def unique_rows(a: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Exactly equal rows of a float array (``-0.0 == 0.0``): ``(first, inverse)`` with ``first``
    the lowest index of each distinct row, in increasing order, and ``inverse`` the row's group.

    Sorts a 64-bit hash of each row (much faster than ``np.unique(axis=0)``), checks that equal
    hashes hold equal rows, and falls back to a lexicographic sort on a hash collision."""
    a = np.ascontiguousarray(a, np.float64) + 0.0  # -0.0 -> 0.0
    n = len(a)
    if n == 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    u = a.view(np.uint64).reshape(n, -1)
    h = np.full(n, 0xCBF29CE484222325, np.uint64)
    for c in range(u.shape[1]):
        h = (h ^ u[:, c]) * np.uint64(0x100000001B3)
        h ^= h >> np.uint64(29)
    order = np.argsort(h, kind="stable")
    rows = a[order]
    eq = (rows[1:] == rows[:-1]).all(axis=1)
    hs = h[order]
    if np.any((hs[1:] == hs[:-1]) & ~eq):  # a collision: equal rows might not be adjacent
        order = np.lexsort(a.T[::-1])
        rows = a[order]
        eq = (rows[1:] == rows[:-1]).all(axis=1)
    start = np.r_[True, ~eq]
    group_sorted = np.cumsum(start) - 1
    first = np.minimum.reduceat(order, np.flatnonzero(start))  # lowest index of each group
    # renumber groups by their lowest index
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    inverse = np.empty(n, np.int64)
    inverse[order] = rank[group_sorted]
    return np.sort(first), inverse


def weld_map(positions: np.ndarray, tolerance: float, colors: np.ndarray | None = None) -> np.ndarray:
    """Group vertices closer than ``tolerance`` (absolute) with equal colours (if given).

    Returns ``group`` (V,) int64: the new index of every vertex, groups numbered by their lowest
    vertex index, so ``group[first vertex of each group]`` is increasing.
    """
    pos = np.asarray(positions, np.float64)
    V = len(pos)
    if V == 0:
        return np.zeros(0, np.int64)
    key = pos if colors is None else np.concatenate([pos, np.asarray(colors, np.float64)], axis=1)
    # 1. exact duplicates (same position and colour)
    first, inv = unique_rows(key)
    label = inv  # label per vertex: one per unique row
    n_lab = len(first)
    if tolerance > 0 and n_lab > 1:
        upos = pos[first]
        pairs = cKDTree(upos).query_pairs(r=float(tolerance), output_type="ndarray")
        if colors is not None and len(pairs):
            cgroup = unique_rows(np.asarray(colors, np.float64)[first])[1]
            pairs = pairs[cgroup[pairs[:, 0]] == cgroup[pairs[:, 1]]]
        if len(pairs):
            g = coo_matrix((np.ones(len(pairs), np.int8), (pairs[:, 0], pairs[:, 1])),
                           shape=(n_lab, n_lab))
            _, comp = connected_components(g, directed=False)
            label = comp[inv]
    # renumber labels by the lowest vertex index in each group
    lowest = np.full(int(label.max()) + 1, V, np.int64)
    np.minimum.at(lowest, label, np.arange(V, dtype=np.int64))
    present = lowest < V
    order = np.argsort(lowest[present], kind="stable")
    rank = np.empty(int(present.sum()), np.int64)
    rank[order] = np.arange(len(order))
    newid = np.full(len(lowest), -1, np.int64)
    newid[np.flatnonzero(present)] = rank
    return newid[label]


def triangle_areas(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Area of each triangle (edge vectors from corner 0, so large coordinates are fine)."""
    if len(triangles) == 0:
        return np.zeros(0)
    pos = np.asarray(positions, np.float64)
    t = np.asarray(triangles, np.int64)
    e1 = pos[t[:, 1]] - pos[t[:, 0]]
    e2 = pos[t[:, 2]] - pos[t[:, 0]]
    cx = e1[:, 1] * e2[:, 2] - e1[:, 2] * e2[:, 1]
    cy = e1[:, 2] * e2[:, 0] - e1[:, 0] * e2[:, 2]
    cz = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    return 0.5 * np.sqrt(cx * cx + cy * cy + cz * cz)


def degenerate_mask(positions: np.ndarray, triangles: np.ndarray, min_area: float
                    ) -> tuple[np.ndarray, np.ndarray]:
    """``(repeated, zero_area)`` masks: a repeated vertex index; else area below ``min_area``."""
    t = np.asarray(triangles, np.int64)
    repeated = (t[:, 0] == t[:, 1]) | (t[:, 1] == t[:, 2]) | (t[:, 0] == t[:, 2])
    small = ~repeated & (triangle_areas(positions, t) < min_area)
    return repeated, small


def stage(scene: Scene, cfg: CleanConfig) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord(name="clean")
    scale = scene.scale()
    V0 = scene.n_vertices
    T0 = scene.n_triangles
    pos = scene.positions
    vcol = scene.vertex_colors
    tris = scene.triangles
    pidx = scene.poly_indices
    counts = {"welded_vertices": 0, "dropped_repeated_index": 0, "dropped_zero_area": 0,
              "dropped_unused_vertices": 0, "polygons_split": 0, "polygons_dropped": 0}

    # ---- weld
    if cfg.weld and V0:
        tol = float(cfg.weld_tolerance) * scale
        group = weld_map(pos, tol, vcol)
        n_new = int(group.max()) + 1
        counts["welded_vertices"] = V0 - n_new
        if n_new < V0:
            keep_first = np.full(n_new, V0, np.int64)
            np.minimum.at(keep_first, group, np.arange(V0, dtype=np.int64))
            pos = pos[keep_first]
            vcol = None if vcol is None else vcol[keep_first]
            tris = None if tris is None else group[tris]
            pidx = None if pidx is None else group[pidx]

    # ---- degenerate triangles
    tri_keep = None
    tri_polygon = scene.tri_polygon
    if cfg.drop_degenerate and tris is not None and len(tris):
        repeated, small = degenerate_mask(pos, tris, float(cfg.area_tolerance) * scale * scale)
        counts["dropped_repeated_index"] = int(repeated.sum())
        counts["dropped_zero_area"] = int(small.sum())
        drop = repeated | small
        if drop.any():
            tri_keep = ~drop
            if tri_polygon is not None:
                hit = np.unique(tri_polygon[drop & (tri_polygon >= 0)])
                marked = np.isin(tri_polygon, hit)
                split = np.unique(tri_polygon[marked & ~drop])
                counts["polygons_split"] = int(len(split))  # some triangles left, now -1
                counts["polygons_dropped"] = int(len(hit) - len(split))  # no triangle left
                tri_polygon = np.where(marked, -1, tri_polygon)

    def tsel(a):
        if a is None or tri_keep is None:
            return a
        return a[tri_keep]

    tris = tsel(tris)
    tri_material = tsel(scene.tri_material)
    tri_uvs = tsel(scene.tri_uvs)
    face_colors = tsel(scene.face_colors)
    tri_polygon = tsel(tri_polygon)

    # ---- unused vertices
    if cfg.drop_unused_vertices and len(pos):
        used = np.zeros(len(pos), bool)
        if tris is not None and len(tris):
            used[tris.ravel()] = True
        if pidx is not None and len(pidx):
            used[pidx] = True
        n_unused = int((~used).sum())
        counts["dropped_unused_vertices"] = n_unused
        if n_unused:
            remap = np.cumsum(used) - 1
            pos = pos[used]
            vcol = None if vcol is None else vcol[used]
            tris = None if tris is None else remap[tris]
            pidx = None if pidx is None else remap[pidx]

    out = scene.replace(
        positions=np.ascontiguousarray(pos, np.float64),
        vertex_colors=vcol,
        triangles=None if tris is None else np.asarray(tris, np.int64),
        tri_material=tri_material,
        tri_uvs=tri_uvs,
        face_colors=face_colors,
        tri_polygon=tri_polygon,
        poly_indices=None if pidx is None else np.asarray(pidx, np.int64),
    )
    out.validate()
    rec.counts_in = {"vertices": V0, "triangles": T0, "polygons": scene.n_polygons,
                     "materials": len(scene.materials)}
    rec.counts_out = {"vertices": out.n_vertices, "triangles": out.n_triangles,
                      "polygons": out.n_polygons, "materials": len(out.materials)}
    rec.details = dict(counts)
    rec.details.update({
        "weld_distance": float(cfg.weld_tolerance) * scale if cfg.weld else None,
        "min_area": float(cfg.area_tolerance) * scale * scale if cfg.drop_degenerate else None,
        "scale": scale,
    })
    dropped = counts["dropped_repeated_index"] + counts["dropped_zero_area"]
    if dropped:
        why = []
        if counts["dropped_repeated_index"]:
            why.append(f"{counts['dropped_repeated_index']:,} with a repeated corner (two of its corners are one "
                       "vertex, as written or after welding)")
        if counts["dropped_zero_area"]:
            why.append(f"{counts['dropped_zero_area']:,} with no area (under mesh.clean.area_tolerance x the "
                       "diagonal squared: collinear or tiny)")
        rec.warn(f"dropped {dropped:,} of {T0:,} triangles: " + "; ".join(why))
    if counts["polygons_split"]:
        rec.warn(f"{counts['polygons_split']} polygon(s) lost a degenerate triangle; their other "
                 "triangles are no longer marked as whole polygons (tri_polygon = -1)")
    rec.seconds = time.perf_counter() - t0
    return out, rec


__all__ = ["stage", "weld_map", "unique_rows", "triangle_areas", "degenerate_mask"]
