"""Simplify stage: reduce the triangles to a budget and measure what it cost in shape.

Targets (exactly one): ``target_triangles = N``, ``target_ratio = r`` (of the input count) or
``max_error = e`` (symmetric Hausdorff distance as a fraction of the bounding-box diagonal; the
stage searches the smallest triangle count whose measured error stays within ``e``).

Methods (quadric edge collapse, all through compiled libraries):

* ``meshopt`` (default): meshoptimizer (bake/mesh/simplify_meshopt.py). It keeps a subset of
  the input's vertices, so colours and UVs are the input's exact values. The mesh is handed
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

After the library (bake/mesh/simplify_repair.py for the local repairs):

1. edges whose two triangles meet at a sharp angle (fins, folds) are turned where that lowers
   the error around them; flipped triangles (normal turned by more than 90 degrees from the
   input surface they stand for; ``simplify_error.flip_check``) are repaired where possible
   (turning an edge, moving a free corner back onto the input surface; undone if it costs more
   than 10% of the local error), and triangles still flipped get the input vertices under them
   locked and the library runs again (three rounds).
2. ``fit_iterations`` rounds of least-squares refit of the free vertex positions to the input
   surface (bake/mesh/simplify_fit.py); not kept if it raises the measured max by more than a
   quarter (a fit rounds off the sharp corners of CAD parts; the record's ``fit.kept`` says which).
3. ``refine_rounds`` rounds of repair where the error peaks: the triangles holding the largest
   distances (within 80% of the maximum, both directions) get their edges turned where that
   lowers the local error, and their free corners moved to lower the local *maximum*
   (a Chebyshev fit; ``simplify_repair.polish``); every move is kept only if the local maximum
   drops and no triangle turns against the input.
   Then ``peak_rounds`` rounds (with a triangle target and ``refine_rounds`` > 0): the input
   vertices nearest the largest places the library cut off are locked and the whole stage runs
   again; a round is kept if its measured max is lower (``details.peak_rounds``).
4. the error is measured (bake/mesh/simplify_measure.py): a dense deterministic grid on both
   surfaces (every vertex, points along every edge, points inside every triangle), refined
   around the largest distances, the largest made exact at their points. The record gives the
   sample size; the maximum is a sampled one (the true maximum can only be larger, by at most
   how much the distance grows between samples) and is never called exact. Then, on the result
   kept (``error_bound``), an upper bound of the true maximum is *proven*: the grid's cells are
   cut, largest bound first, until no cell can hold a distance more than 2% above the largest
   found or BOUND_FLOOR of the diagonal, or a budget of points is spent
   (``simplify_measure.certify``); the record gives the bound, whether it got there, and what it
   cost. Cutting finds peaks the sample missed (the CSG model at 2%: 7.6% higher).
5. with a triangle target, the budget is met (``defects = "allow"``): flipped triangles, new
   non-manifold edges and folds the repairs leave are counted in the record (``details.defects``,
   ``details.defect_triangles``) and warned about. With ``defects = "refuse"``, a result that has
   any is not accepted and the stage backs off to the smallest larger count without; with an
   ``error_ceiling`` (default 0: none), neither is a result whose error is above it.

Messy input (bake/mesh/simplify_parts.py): a two-sided surface written twice is simplified as one
layer and written with its backs; repeated triangles are dropped; parts that share vertices keep
their own copies in the library's buffer. Where the library stops short of a triangle target,
the stage lets go of, in order, its locks, UV seams, the parts' copies, material edges and last
edge collapse itself (RELAXATIONS; ``details.relaxed``), and says so. docs/simplify.md, "Meeting
the budget on messy models", has what each costs.

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

The record: triangles in/out and the target, seconds per phase (library, fit, repairs, checks,
measure), the symmetric Hausdorff max/mean as fractions of the diagonal (``accuracy``) with the
sample it was measured on, flipped triangles, folds (neighbouring triangles whose normals have
a dot product below -0.9) in the input and the output, new non-manifold and mis-oriented
edges, material-edge and border checks, how each attribute was carried, and a warning for
anything that kept the target from being reached.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field, replace

import numpy as np

from ..config import SimplifyConfig
from ..progress import step as report_step
from ..errors import ConfigError, StageError
from ..record import StageRecord
from ..scene import Scene
from . import simplify_meshopt
from . import simplify_repair as repair
from scipy.spatial import cKDTree

from .simplify_error import (FlipResult, SurfaceIndex, bounding_spheres, edge_counts, flip_check, topology,
                             triangle_areas, triangle_pattern)
from .simplify_fit import refit
from .simplify_parts import Layer, fold_layer, part_report, parts
from . import simplify_measure as _measure_mod
from .simplify_measure import HausdorffResult, bound_hausdorff, directed, hausdorff, original_side, surface_grid

__all__ = ["stage", "simplify_mesh", "resolve_target", "METHODS"]

METHODS = ("meshopt", "fast", "quality")
# Rounds of "lock the input vertices under flipped triangles and simplify again".
_REPAIR_ROUNDS = 3
_PHASES = ("library", "repair", "check", "fit", "measure")  # the record's *_seconds
# The lock-and-retry rounds stop when a round leaves more than _FLAWS_FEW flaws and more than
# _FLAWS_DROP of the best before it: on a CAD assembly each round moved most of its ~1,500 flaws
# elsewhere (1,509 -> 1,222 -> 1,330) at the cost of a whole library run and repair. A few flaws
# go on to the last round (the teapot's peak round: 2 folds, then 4, then none)
_FLAWS_FEW = 32
_FLAWS_DROP = 0.75
# Points of the flip check over the input's area (at least 3 per output triangle).
_FLIP_SAMPLES = 8000
# Border and seam chains are simplified at this fraction of the library's own error estimate.
_BORDER_TOLERANCE = 0.5
# A refine round works on the triangles whose error is within this fraction of the maximum ...
_PEAK_SHARE = 0.8
# ... at most this many separate places
_PEAKS = 24
# The peak round locks the input vertices at most this many of the largest cut-off places.
_PEAK_LOCKS = 8
# The least-squares fit pairs at most this many of the input's points with the result (and a
# third as many random points of the result with the input).
_FIT_POINTS = 60000
# Refinement rounds of the quick measure that checks whether the fit made the result worse (0:
# the grids alone, a subset of the full measure's points, so a lower bound of its max).
_FIT_CHECK_ROUNDS = 0
# The fit lowers the mean distance and may raise a peak a little, which the refine rounds then
# work on (the bunny's orderings: up to 10% higher before the rounds, lower after them); a fit
# that raises the measured max by more than this factor is not kept (CSG corners: 10x).
_FIT_TOLERANCE = 1.25
# Face colours with more distinct values than this are a colour signal, not flat regions.
MAX_COLOR_REGIONS = 1024
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


# --------------------------------------------------------------------------- input preparation
@dataclass
class _Prepared:
    """The stage's input: one layer of the scene's triangles (simplify_parts.fold_layer: a
    two-sided surface written twice is simplified once), with its regions and parts."""
    V: np.ndarray  # (V, 3) float64 (all scene vertices)
    F: np.ndarray  # (T, 3) int64: the layer
    region: np.ndarray  # (T,) int64: triangles of one region share material, face colour and back
    region_material: np.ndarray  # (R,)
    region_color: np.ndarray | None  # (R, 4) face colour per region, or None
    colors_as_regions: bool
    tri_material: np.ndarray
    tri_uvs: np.ndarray | None  # (T, 3, 2), or (T, 3, 4) with the back's UVs beside the front's
    face_colors: np.ndarray | None
    vertex_colors: np.ndarray | None
    layer: Layer
    part: np.ndarray  # (T,) simplify_parts.parts
    n_parts: int
    parts_shared: bool  # two parts share a vertex: each gets its own copies in the library's buffer
    textured: np.ndarray  # (T,) the triangle's material (or its back's) has a texture: its UV seams stay
    materials_as_regions: bool  # preserve_materials: the region gives the material
    # the back of each layer triangle (its own values where it has none) and of each region
    back_material: np.ndarray | None = None  # (T,)
    back_colors: np.ndarray | None = None  # (T, 4)
    region_back: np.ndarray | None = None  # (R,) bool: the region's triangles have a back
    region_back_material: np.ndarray | None = None  # (R,)
    region_back_color: np.ndarray | None = None  # (R, 4)
    # what the stage let go to reach a triangle target the library stopped short of (_run_to)
    relaxed: list = field(default_factory=list)
    wedges: tuple | None = None  # _wedges(), once (again after a relaxation)

    def back(self) -> "_Prepared":
        """The same layer with the backs' materials and face colours as its own (for
        _attributes, whose ``side = 1`` takes the back UVs: the last two of tri_uvs' four)."""
        return replace(self, tri_material=self.back_material, region_material=self.region_back_material,
                       face_colors=self.back_colors, region_color=self.region_back_color)


def _prepare(scene: Scene, cfg: SimplifyConfig) -> _Prepared:
    F_all = np.asarray(scene.triangles, np.int64).reshape(-1, 3)
    layer = fold_layer(F_all)
    front, back = layer.front, layer.back
    has_back = back >= 0
    bk = np.where(has_back, back, front)  # (the front itself where there is no back)
    F = F_all[front]
    T = len(F)
    mat_all = np.asarray(scene.tri_material, np.int64) if scene.tri_material is not None else \
        np.zeros(len(F_all), np.int64)
    mat, bmat = mat_all[front], mat_all[bk]
    fc_all = None if scene.face_colors is None else np.asarray(scene.face_colors, np.float64)
    fc = None if fc_all is None else fc_all[front]
    bfc = None if fc_all is None else fc_all[bk]
    uvs = None
    if scene.tri_uvs is not None:
        uv_all = np.asarray(scene.tri_uvs, np.float64)
        uvs = uv_all[front]
        if has_back.any():  # the back's UVs at the front's corners, beside the front's
            buv = np.take_along_axis(uv_all[bk], np.where(has_back[:, None], layer.back_corner,
                                                          np.arange(3))[:, :, None], axis=1)
            uvs = np.concatenate([uvs, buv], axis=2)
    colors_as_regions = False
    cols = []
    if cfg.preserve_materials:
        cols.append(mat[:, None])
        if fc is not None:
            q = np.round(np.clip(fc, 0, 1) * 255).astype(np.int64)
            qb = np.round(np.clip(bfc, 0, 1) * 255).astype(np.int64)
            if len(np.unique(np.concatenate([q, qb]), axis=0)) <= MAX_COLOR_REGIONS:
                cols.append(q)
                colors_as_regions = True
    # whether a triangle has a back is a region of its own (with its back's material and colour)
    if has_back.any():
        cols.append(has_back[:, None].astype(np.int64))
        if cfg.preserve_materials:
            cols.append(np.where(has_back, bmat, -1)[:, None])
            if colors_as_regions:
                cols.append(np.where(has_back[:, None], qb, -1))
    if cols:
        key = np.concatenate(cols, axis=1)
        _, first, region = np.unique(key, axis=0, return_index=True, return_inverse=True)
        region = region.reshape(-1).astype(np.int64)
    else:
        first, region = np.zeros(1, np.int64), np.zeros(T, np.int64)
    part, n_parts, shared = parts(F, len(scene.positions))
    has_tex = np.array([m.texture is not None or m.texture_data is not None for m in scene.materials] or [False])
    textured = has_tex[np.clip(mat, 0, len(has_tex) - 1)] | (has_back & has_tex[np.clip(bmat, 0, len(has_tex) - 1)])
    return _Prepared(V=np.asarray(scene.positions, np.float64), F=F, region=region,
                     region_material=mat[first] if T else np.zeros(1, np.int64),
                     region_color=fc[first] if colors_as_regions else None,
                     colors_as_regions=colors_as_regions, tri_material=mat, tri_uvs=uvs, face_colors=fc,
                     vertex_colors=None if scene.vertex_colors is None else np.asarray(scene.vertex_colors),
                     layer=layer, part=part, n_parts=n_parts, parts_shared=shared, textured=textured,
                     materials_as_regions=bool(cfg.preserve_materials), back_material=bmat, back_colors=bfc,
                     region_back=has_back[first] if T else np.zeros(1, bool),
                     region_back_material=bmat[first] if T else np.zeros(1, np.int64),
                     region_back_color=bfc[first] if colors_as_regions else None)


def _region_edge_vertices(F: np.ndarray, region: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
    """(vertex mask, edges (E,2)) of edges shared by triangles of different regions."""
    mask = np.zeros(n_vertices, bool)
    if len(F) == 0:
        return mask, np.zeros((0, 2), np.int64)
    e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
    r = np.concatenate([region, region, region])
    order = np.lexsort((r, e[:, 1], e[:, 0]))
    e, r = e[order], r[order]
    same_edge = (e[1:] == e[:-1]).all(axis=1)
    diff = same_edge & (r[1:] != r[:-1])
    edges = np.unique(e[1:][diff], axis=0) if diff.any() else np.zeros((0, 2), np.int64)
    mask[edges.ravel()] = True
    return mask, edges


def _nonmanifold_vertices(F: np.ndarray, n_vertices: int) -> np.ndarray:
    edges, cnt, _ = edge_counts(F)
    mask = np.zeros(n_vertices, bool)
    mask[edges[cnt > 2].ravel()] = True
    return mask


# --------------------------------------------------------------------------- backends
@dataclass
class _Raw:
    """What a backend hands back, per output triangle and vertex (vertex-level, not compacted)."""
    V: np.ndarray  # (n, 3) positions of output vertices
    F: np.ndarray  # (t, 3) into V
    src_vertex: np.ndarray  # (n,) input vertex whose attributes this vertex takes
    region: np.ndarray  # (t,)
    src_tri: np.ndarray | None  # (t,) input triangle each output triangle is (corner order kept)
    tri_uvs: np.ndarray | None  # (t, 3, 2) if already known
    fixed: np.ndarray  # (n,) vertices the fit must not move
    lib_seconds: float
    notes: list[str]
    lib_error: float = 0.0  # the library's own error estimate (meshoptimizer; absolute units)


def _wedges(prep: _Prepared) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Wedge ids per corner (T, 3), wedge -> vertex, wedge -> region, wedge -> UV (computed
    once per input)."""
    if prep.wedges is None:
        prep.wedges = _make_wedges(prep)
    return prep.wedges


def _make_wedges(prep: _Prepared) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    T = len(prep.F)
    corner_v = prep.F.reshape(-1)
    corner_r = np.repeat(prep.region, 3)
    cols = [corner_v[:, None], corner_r[:, None]]
    if prep.tri_uvs is not None and prep.textured.any() and "uv_seams" not in prep.relaxed:
        # UV seams where a texture shows them (untextured triangles' UVs draw nothing)
        k = prep.tri_uvs.shape[2]
        uv = np.where(np.repeat(prep.textured, 3)[:, None], prep.tri_uvs.reshape(-1, k), 0.0)
        cols.append(np.ascontiguousarray(uv + 0.0).view(np.int64))  # (+ 0.0: -0.0 -> 0.0)
    if prep.parts_shared and "parts" not in prep.relaxed:  # parts keep their own copies of shared vertices
        cols.append(np.repeat(prep.part, 3)[:, None])
    if "materials" in prep.relaxed:  # material and colour edges may collapse across
        cols.pop(1)
    key = np.concatenate(cols, axis=1)
    if key.shape[1] == 1 or (key.shape[1] == 2 and len(prep.region_material) == 1):
        # one region (or regions let go), no UVs: wedges are the vertices themselves
        nv = len(prep.V)
        w_region = np.zeros(nv, np.int64)
        w_region[prep.F.ravel()] = corner_r  # (regions let go: a region of a triangle at the vertex)
        return prep.F.copy(), np.arange(nv), w_region, None
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(T, 3)
    wuv = None if prep.tri_uvs is None else prep.tri_uvs.reshape(-1, prep.tri_uvs.shape[2])[first]
    return inv, corner_v[first], corner_r[first], wuv


def _run_meshopt(prep: _Prepared, target: int, cfg: SimplifyConfig, lock: np.ndarray, cap: float) -> _Raw:
    Fw, w_vertex, w_region, w_uv = _wedges(prep)
    Vw = prep.V[w_vertex]
    t = time.perf_counter()
    # with an error ceiling, meshoptimizer stops before its own error estimate passes it
    Fo, err = simplify_meshopt.simplify(Vw, Fw, target, lock=lock[w_vertex] if lock.any() else None,
                                        target_error=cap if cap > 0 else 1e30, absolute_error=True)
    lib = time.perf_counter() - t
    notes = []
    reg = w_region[Fo]
    mixed = int((reg != reg[:, :1]).any(axis=1).sum())
    if mixed:
        notes.append(f"{mixed} triangle(s) had corners from different regions; the first corner's region was used")
    return _Raw(V=prep.V, F=w_vertex[Fo], src_vertex=np.arange(len(prep.V)), region=reg[:, 0], src_tri=None,
                tri_uvs=None if w_uv is None else w_uv[Fo], fixed=np.zeros(len(prep.V), bool), lib_seconds=lib,
                notes=notes, lib_error=float(err))


def _split_regions(prep: _Prepared, lock: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Split vertices shared by several regions: (split faces (T,3), split -> input vertex,
    split vertex lies on a region edge). Triangles touching a ``lock`` vertex become regions of
    their own, so their corners are border vertices, which the libraries keep."""
    region = prep.region if "materials" not in prep.relaxed else np.zeros(len(prep.F), np.int64)
    R = len(prep.region_material) if "materials" not in prep.relaxed else 1
    if prep.parts_shared and "parts" not in prep.relaxed:  # parts keep their own copies of shared vertices
        _, region = np.unique(np.stack([region, prep.part], axis=1), axis=0, return_inverse=True)
        region = region.reshape(-1)
        R = int(region.max()) + 1
    if lock.any():
        own = lock[prep.F].any(axis=1)
        region = np.where(own, R + np.arange(len(prep.F)), region)
        R = R + len(prep.F)
    if R <= 1:
        nv = len(prep.V)
        return prep.F.copy(), np.arange(nv), np.zeros(nv, bool)
    key = prep.F * R + region[:, None]
    uniq, inv = np.unique(key.reshape(-1), return_inverse=True)
    Fs = inv.reshape(-1, 3)
    split_vertex = uniq // R
    counts = np.bincount(split_vertex, minlength=len(prep.V))
    on_edge = counts[split_vertex] > 1
    return Fs, split_vertex, on_edge


def _closest_member(P_out: np.ndarray, mapping: np.ndarray, P_in: np.ndarray) -> np.ndarray:
    """For each output vertex, the input vertex mapped to it that lies closest (-1 if none)."""
    n = len(P_out)
    src = np.full(n, -1, np.int64)
    ok = (mapping >= 0) & (mapping < n)
    ids = np.flatnonzero(ok)
    if len(ids) == 0:
        return src
    d = np.linalg.norm(P_in[ids] - P_out[mapping[ids]], axis=1)
    order = np.lexsort((ids, d, mapping[ids]))
    m_sorted = mapping[ids][order]
    firsts = np.r_[True, m_sorted[1:] != m_sorted[:-1]]
    src[m_sorted[firsts]] = ids[order][firsts]
    return src


def _weld_copies(V: np.ndarray, F: np.ndarray, src_vertex: np.ndarray, fixed: np.ndarray
                 ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Merge output vertices that come from the same input vertex and sit at the same place
    (the two sides of a material edge that was split for the library)."""
    key = np.concatenate([src_vertex[:, None], np.ascontiguousarray(V).view(np.int64).reshape(len(V), 3)], axis=1)
    _, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inv = inv.reshape(-1)
    fx = np.zeros(len(first), bool)
    fx[inv[fixed]] = True
    return V[first], inv[F], src_vertex[first], fx


def _run_fast(prep: _Prepared, target: int, cfg: SimplifyConfig, lock: np.ndarray) -> _Raw:
    import fast_simplification as fs_lib

    Fs, split_vertex, on_edge = _split_regions(prep, lock)
    Vs = prep.V[split_vertex]
    # fast-simplification overshoots small targets: ask again with a corrected target
    want = target
    best = None
    t_lib = 0.0
    for _ in range(4):
        t = time.perf_counter()
        P, Fo, coll = fs_lib.simplify(Vs, Fs.astype(np.int32), target_count=int(max(want, 1)),
                                      preserve_border=bool(cfg.preserve_border or on_edge.any()),
                                      return_collapses=True)
        t_lib += time.perf_counter() - t
        if best is None or abs(len(Fo) - target) < abs(len(best[1]) - target):
            best = (P, Fo, coll)
        if abs(len(Fo) - target) <= 0.01 * target or len(Fo) <= target or want <= 1:
            break
        want = int(want * target / max(len(Fo), 1))
    P, Fo, coll = best
    t = time.perf_counter()
    _, _, mapping = fs_lib.replay_simplification(Vs, Fs.astype(np.int32), coll)
    t_lib += time.perf_counter() - t
    mapping = np.asarray(mapping, np.int64)
    Fo = np.asarray(Fo, np.int64)
    P = np.asarray(P, np.float64)
    mf = mapping[Fs]
    alive = (mf[:, 0] != mf[:, 1]) & (mf[:, 1] != mf[:, 2]) & (mf[:, 0] != mf[:, 2])
    notes: list[str] = []
    if int(alive.sum()) == len(Fo) and np.array_equal(mf[alive], Fo):
        src_tri = np.flatnonzero(alive)
    else:  # should not happen with fast-simplification 0.2; keep going with nearest-surface
        src_tri = None
        notes.append("fast-simplification's replay did not match its output; attributes were sampled "
                     "from the nearest input triangle")
    member = _closest_member(P, mapping, Vs)
    src_vertex = np.where(member >= 0, split_vertex[np.maximum(member, 0)], 0)
    fixed = np.zeros(len(P), bool)
    fixed[mapping[on_edge]] = True
    V2, F2, src2, fixed2 = _weld_copies(P, Fo, src_vertex, fixed)
    region = prep.region[src_tri] if src_tri is not None else np.zeros(len(F2), np.int64)
    return _Raw(V=V2, F=F2, src_vertex=src2, region=region, src_tri=src_tri, tri_uvs=None, fixed=fixed2,
                lib_seconds=t_lib, notes=notes)


def _run_quality(prep: _Prepared, target: int, cfg: SimplifyConfig, lock: np.ndarray) -> _Raw:
    import pymeshlab

    Fs, split_vertex, on_edge = _split_regions(prep, lock)
    Vs = prep.V[split_vertex]
    # MeshLab may be told to simplify only selected triangles; it then never moves a vertex of
    # an unselected one. Triangles touching a material edge are left out (listed last, so the
    # selection is "face index < n"), which keeps the edge exactly.
    locked = on_edge[Fs].any(axis=1)
    order = np.argsort(locked, kind="stable")
    n_sel = int((~locked).sum())
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(vertex_matrix=Vs, face_matrix=Fs[order].astype(np.int32),
                               v_scalar_array=np.arange(len(Vs), dtype=np.float64),
                               f_scalar_array=order.astype(np.float64)))
    selected = bool(locked.any())
    if selected:
        ms.compute_selection_by_condition_per_face(condselect=f"(fi < {n_sel})")
    t = time.perf_counter()
    ms.meshing_decimation_quadric_edge_collapse(
        targetfacenum=int(max(target, 1)), qualitythr=0.3, preserveboundary=bool(cfg.preserve_border),
        boundaryweight=1.0, preservenormal=True, preservetopology=False, optimalplacement=True,
        planarquadric=False, autoclean=True, selected=selected)
    lib = time.perf_counter() - t
    m = ms.current_mesh()
    P = np.asarray(m.vertex_matrix(), np.float64)
    Fo = np.asarray(m.face_matrix(), np.int64)
    vq = np.rint(np.asarray(m.vertex_scalar_array())).astype(np.int64)
    fq = np.rint(np.asarray(m.face_scalar_array())).astype(np.int64)
    notes = []
    if not ((vq >= 0).all() and (vq < len(Vs)).all() and (fq >= 0).all() and (fq < len(Fs)).all()):
        raise StageError("MeshLab lost the vertex/face numbering it was given")
    src_vertex = split_vertex[vq]
    fixed = on_edge[vq] & (np.linalg.norm(P - Vs[vq], axis=1) == 0)
    V2, F2, src2, fixed2 = _weld_copies(P, Fo, src_vertex, fixed)
    return _Raw(V=V2, F=F2, src_vertex=src2, region=prep.region[fq], src_tri=fq, tri_uvs=None, fixed=fixed2,
                lib_seconds=lib, notes=notes)


# --------------------------------------------------------------------------- main entry
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


# What the stage lets go, in this order, when the library stops more than _SHORT above a triangle
# target (with defects = "allow"): the vertices it locked (border chains, the lock-and-retry
# rounds), UV seams of textured triangles, the parts' own copies of the vertices they share,
# material and colour edges, and last the edge collapse itself (meshoptimizer's vertex clustering,
# which reaches any count). Each is kept for the rest of the stage and named in the record.
RELAXATIONS = ("locks", "uv_seams", "parts", "materials", "clustering")
_SHORT = 0.02
_DEFECT_IDS = 10000
# Without an error_ceiling, a result more than this far off the input (fraction of the diagonal)
# is warned about
_LARGE_ERROR = 0.05
_RELAXED_TEXT = {
    "locks": "the border and seam vertices it had locked (borders follow the input's less closely)",
    "uv_seams": "the UV seams of textured triangles (textures may shift along them)",
    "parts": "the parts' own copies of the vertices they share (touching parts may be welded)",
    "materials": "the material and colour edges (colours may bleed across them)",
    "clustering": "edge collapse: vertices near each other were clustered (meshoptimizer's sloppy "
                  "simplifier; thin parts may merge)"}


def _applies(prep: _Prepared, what: str, lock: np.ndarray) -> bool:
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


def _run_to(ctx: "_Ctx", target: int, lock: np.ndarray, cap: float, log: list) -> _Raw:
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


def _run_layer(ctx: "_Ctx", target: int, lock: np.ndarray, cap: float) -> _Raw:
    """The library's result for a layer target (simplify_parts). The count asked is corrected (a
    few runs) until the triangles written, with the layer's backs put back, are within _SHORT of
    what the target stands for: the backs' share of the result is not the input's (two boxes'
    shared flat face keeps 2 triangles where their curved sides keep many), and meshoptimizer
    collapses in batches, so a small target can come back short (188 for 200)."""
    prep = ctx.prep
    T0, twins = len(prep.F), prep.layer.twins

    def run(t: int) -> _Raw:
        if "clustering" in prep.relaxed:
            return _run_sloppy(ctx, t)
        return _run(prep, ctx.method, t, ctx.cfg, lock, cap)
    raw = run(target)
    if target >= T0:
        return raw
    goal = _goal(prep, target)
    t, lib = target, raw.lib_seconds
    for _ in range(4):
        total = _written(prep, raw)
        if abs(total - goal) <= _SHORT * goal or (total > goal and len(raw.F) > t * (1 + _SHORT)):
            break  # (over the goal with the library stopping short of ``t``: _run_to lets go)
        t_new = int(np.clip(round(t * goal / max(total, 1)), 1, T0 - 1))
        if t_new == t:
            break
        t = t_new
        raw = run(t)
        lib += raw.lib_seconds
    raw.lib_seconds = lib
    return raw


def _goal(prep: _Prepared, target: int) -> float:
    """The triangles a layer target stands for, with the backs put back (at the input's share)."""
    T0 = len(prep.F)
    return target * (T0 + prep.layer.twins) / T0


def _written(prep: _Prepared, raw: _Raw) -> int:
    """Triangles a library result writes: those with three distinct corners (two wedges of one
    vertex, across a UV seam, make a triangle that is dropped) and the backs put back."""
    F = raw.F
    alive = (F[:, 0] != F[:, 1]) & (F[:, 1] != F[:, 2]) & (F[:, 0] != F[:, 2])
    return int(alive.sum()) + int(prep.region_back[raw.region[alive]].sum())


def _run_sloppy(ctx: "_Ctx", target: int) -> _Raw:
    """meshoptimizer's vertex clustering (simplify_meshopt.simplify_sloppy): the smallest of a
    few clusterings at or above the target (its counts come in steps: 48, 96, 144 on a small
    sphere), then edge collapse on that, free of every seam, down to the target. Each triangle
    takes the region of the input triangle closest to its centre."""
    prep = ctx.prep
    t = time.perf_counter()

    def cluster(want: int) -> tuple[np.ndarray, float]:
        Fo, err = simplify_meshopt.simplify_sloppy(prep.V, prep.F, want)
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
        Fo = simplify_meshopt.simplify(prep.V, Fo, target)[0]
    lib = time.perf_counter() - t
    _, near, _ = ctx.index_a.query(prep.V[Fo].mean(axis=1)) if len(Fo) else (None, np.zeros(0, np.int64), None)
    return _Raw(V=prep.V, F=Fo, src_vertex=np.arange(len(prep.V)), region=prep.region[near], src_tri=None,
                tri_uvs=None if prep.tri_uvs is None else prep.tri_uvs[near],
                fixed=np.zeros(len(prep.V), bool), lib_seconds=lib,
                notes=["vertex clustering: each triangle took the material and UVs of the input triangle closest "
                       "to its centre"], lib_error=float(err) * ctx.scale)


def _run(prep: _Prepared, method: str, target: int, cfg: SimplifyConfig, lock: np.ndarray, cap: float) -> _Raw:
    if method == "meshopt":
        return _run_meshopt(prep, target, cfg, lock, cap)
    if method == "fast":
        return _run_fast(prep, target, cfg, lock)
    if method == "quality":
        return _run_quality(prep, target, cfg, lock)
    raise ConfigError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}", key="mesh.simplify.method")




@dataclass
class _Out:
    V: np.ndarray
    F: np.ndarray
    src_vertex: np.ndarray
    region: np.ndarray
    src_tri: np.ndarray | None
    tri_uvs: np.ndarray | None
    fixed: np.ndarray
    fit_info: dict
    notes: list[str]
    flipped: np.ndarray  # (t,) bool
    new_nonmanifold: np.ndarray  # (t,) bool: uses an edge with > 2 triangles the input did not have
    h: HausdorffResult | None = None  # the stage's error measure of this result, once taken
    flip: FlipResult | None = None
    lib_error: float = 0.0
    edge_turns: int = 0  # edges turned at sharp dihedrals right after the library
    folded: np.ndarray | None = None  # (t,) bool: in a fold the input does not have there


@dataclass
class _Ctx:
    """What every attempt shares: the input, its index and grid, the config, and caches."""
    prep: "_Prepared"
    cfg: SimplifyConfig
    method: str
    index_a: SurfaceIndex
    grid_a: object  # simplify_measure.SurfaceGrid over the input
    scale: float
    protect: np.ndarray  # input vertices the fit and repairs never move (when unmoved)
    chains: list = field(default_factory=list)  # border / seam chains of the input (meshopt locks)
    chain_ends: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    flip_cache: dict = field(default_factory=dict)
    repair_log: list = field(default_factory=list)
    measures: int = 0
    # seconds per phase, summed over every attempt (back-off probes, peak rounds), not only the
    # result kept: library, repair, check, fit, measure
    seconds: dict = field(default_factory=lambda: dict.fromkeys(_PHASES, 0.0))
    fold_zones: np.ndarray | None = None  # centroids of the input's own folded triangles
    fit_points: np.ndarray | None = None  # the input's points the fit pairs with the result


def _local_error(ctx: _Ctx, V: np.ndarray, F: np.ndarray, spacing: float = 0.0,
                 near: np.ndarray | None = None) -> repair.LocalError:
    """The input's grid points, each assigned to its closest triangle of (V, F) (``near``:
    already known, from a measure of this very mesh)."""
    if near is None or len(near) != len(ctx.grid_a.P):
        _, near = SurfaceIndex(V, F).distance(ctx.grid_a.P)
    return repair.LocalError(ctx.index_a, ctx.grid_a.P, near, len(F), spacing=spacing)


def _finish(ctx: _Ctx, raw: _Raw) -> _Out:
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
        le = _local_error(ctx, V, F)
        turns = repair.flip_edges(V, F, region, tri_uvs, None, le)
    repair_s = time.perf_counter() - t
    t = time.perf_counter()
    info_repair = None

    def check(Vc: np.ndarray, Fc: np.ndarray, prev: FlipResult | None = None) -> FlipResult:
        return _flip_check(ctx, Vc, Fc, prev)

    fr = check(V, F)
    before = (V.copy(), F.copy(), None if tri_uvs is None else tri_uvs.copy(), fr) if fr.flipped.any() else None
    edge_flips = 0
    for _ in range(3):
        if not fr.flipped.any():
            break
        n = _edge_flip_repair(V, F, region, tri_uvs, fr)
        if n == 0:
            break
        edge_flips += n
        fr = check(V, F, fr)
    relocated = 0
    if fr.flipped.any():
        V = V.copy()
        relocated = _relocate_repair(V, F, fixed, fr, ctx.index_a)
        if relocated:
            fr = check(V, F, fr)
    if before is not None and (edge_flips or relocated):
        # repairs act on what the flip check flagged; keep them only if they do not cost shape
        # where they act (the error over the repaired triangles and the ring around them)
        e0, e1 = _repair_cost(ctx.index_a, before[0], before[1], V, F)
        info_repair = {"local_error_before": e0 / scale, "local_error_after": e1 / scale}
        if e1 > 1.1 * e0 + 1e-12 * scale:
            V, F, tri_uvs, fr = before
            edge_flips = relocated = 0
            info_repair["undone"] = True
    folded = _new_folds(ctx, V, F)
    unfolded = 0
    if folded.any():
        # a fold the edge turns could not undo: move a free corner to the middle of its
        # neighbours on the input surface, where every triangle around it then faces the input
        V = V.copy()
        unfolded = _relocate_repair(V, F, fixed, replace(fr, flipped=folded), ctx.index_a)
        if unfolded:
            fr = check(V, F, fr)
            folded = _new_folds(ctx, V, F)
    check_s = time.perf_counter() - t
    ctx.seconds["library"] += raw.lib_seconds
    ctx.seconds["repair"] += repair_s
    ctx.seconds["check"] += check_s
    info = {"rounds": 0, "reverted_vertices": 0, "edge_flips": edge_flips, "relocated_vertices": relocated,
            "unfolded_vertices": unfolded}
    if info_repair is not None:
        info["repair_check"] = info_repair
    return _Out(V=V, F=F, src_vertex=src_vertex, region=region, src_tri=src_tri, tri_uvs=tri_uvs, fixed=fixed,
                fit_info=info, notes=list(raw.notes), flipped=fr.flipped, flip=fr,
                new_nonmanifold=_new_nonmanifold_triangles(prep, F, src_vertex), lib_error=raw.lib_error,
                edge_turns=turns, folded=folded)


def _identity(ctx: _Ctx) -> _Out:
    """The input itself as a result (what backing off to the input's count gives), with its
    error, exactly 0, as its measure (so nothing measures it against itself)."""
    prep = ctx.prep
    T = len(prep.F)
    z = np.zeros(T, bool)
    return _Out(V=prep.V, F=prep.F, src_vertex=np.arange(len(prep.V)), region=prep.region, src_tri=np.arange(T),
                tri_uvs=None if prep.tri_uvs is None else prep.tri_uvs, fixed=np.ones(len(prep.V), bool),
                fit_info={"rounds": 0}, notes=[], flipped=z,
                new_nonmanifold=z.copy(), folded=z.copy(),
                h=HausdorffResult(0.0, 0.0, 0.0, 0.0, 0.0, 0.0, np.zeros(3), 0, 0))


def _flip_check(ctx: _Ctx, V: np.ndarray, F: np.ndarray, prev: FlipResult | None = None) -> FlipResult:
    """The stage's flip check: only triangles not judged before (in ``prev``, else in the stage's
    last check) are measured; the result becomes the stage's last check."""
    cache = ctx.flip_cache
    fr = flip_check(ctx.index_a, V, F, samples=min(ctx.cfg.error_samples, _FLIP_SAMPLES), scale=ctx.scale,
                    prev=prev if prev is not None else cache.get("last"))
    cache["last"] = fr
    cache["checked"] = cache.get("checked", 0) + fr.checked
    return fr


def _new_folds(ctx: _Ctx, V: np.ndarray, F: np.ndarray) -> np.ndarray:
    """(t,) triangles in a fold (simplify_repair.folds) that is not where the input has one of
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


def _no_new_flips(ctx: _Ctx, V0: np.ndarray, Vn: np.ndarray, F: np.ndarray, fr: FlipResult,
                  info: dict) -> tuple[np.ndarray, FlipResult, bool]:
    """Put back the corners of any triangle a move (V0 -> Vn) turned against the input or into a
    fold (a few rounds, only the triangles that moved are checked). Returns (positions, flip
    result, whether no new flip or fold is left)."""
    Vn = Vn.copy()
    ff = fr
    folded0 = _new_folds(ctx, V0, F)
    for _ in range(6):
        ff = _flip_check(ctx, Vn, F, ff)
        new = (ff.flipped & ~fr.flipped) | (_new_folds(ctx, Vn, F) & ~folded0)
        if not new.any():
            return Vn, ff, True
        back = np.unique(F[new].ravel())
        moved = back[(Vn[back] != V0[back]).any(axis=1)]
        if len(moved) == 0:
            break
        info["reverted_vertices"] = info.get("reverted_vertices", 0) + int(len(moved))
        Vn[moved] = V0[moved]
    ff = _flip_check(ctx, Vn, F, ff)
    return Vn, ff, not ((ff.flipped & ~fr.flipped) | (_new_folds(ctx, Vn, F) & ~folded0)).any()


def _fit(ctx: _Ctx, out: _Out) -> _Out:
    """Refit the free vertices of a result (bake/mesh/simplify_fit.py), adding no flipped
    triangle (corners of any it turns are put back). Whether the fit is kept is decided by the
    caller, on the measured error."""
    cfg = ctx.cfg
    if cfg.fit_iterations <= 0 or len(out.F) == 0 or out.fixed.all():  # (the input itself: nothing moves)
        return out
    V, F, fr, fixed = out.V, out.F, out.flip, out.fixed
    info = dict(out.fit_info)
    report_step(f"{len(F):,} triangles: fit")
    t = time.perf_counter()
    Vf, fit_info = refit(V, F, fixed, ctx.index_a, ctx.fit_points, iterations=cfg.fit_iterations,
                         samples_b=min(cfg.error_samples, 8000), seed=cfg.seed)
    info.update(fit_info)
    fit_s = time.perf_counter() - t
    ctx.seconds["fit"] += fit_s
    t = time.perf_counter()
    Vf, ff, ok = _no_new_flips(ctx, V, Vf, F, fr, info)
    folded = _new_folds(ctx, Vf, F) if ok else None
    ctx.seconds["check"] += time.perf_counter() - t
    if not ok:
        info["abandoned"] = True
        return replace(out, fit_info=info)
    return replace(out, V=Vf, flipped=ff.flipped, flip=ff, fit_info=info, h=None, folded=folded)


def _measure(ctx: _Ctx, out: _Out) -> HausdorffResult:
    if out.h is None:
        report_step(f"{len(out.F):,} triangles: measure")
        t = time.perf_counter()
        out.h = hausdorff(ctx.prep.V, ctx.prep.F, out.V, out.F, points=ctx.cfg.error_samples, index_a=ctx.index_a,
                          grid_a=ctx.grid_a)
        ctx.measures += 1
        ctx.seconds["measure"] += time.perf_counter() - t
    return out.h


class _Tracker:
    """The error around each triangle of a result as the measure ``h`` saw it, kept up to date
    while the refine rounds change a few triangles: per triangle, the largest distance from its
    grid (and the refinement) to the input, and the largest distance of the input's measured
    points whose closest triangle it is. A changed triangle is measured again (its grid at the
    measure's spacing, refined); an input point whose closest triangle changed is measured
    again against the whole result; the other values stay valid (upper bounds)."""

    def __init__(self, ctx: _Ctx, F: np.ndarray, h: HausdorffResult):
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


def _refine(ctx: _Ctx, out: _Out, h: HausdorffResult) -> tuple[_Out, HausdorffResult, list[dict]]:
    """``refine_rounds`` rounds of local repair where the error peaks (module docstring, step 3).
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
    le = _local_error(ctx, V, F, spacing=h.b_to_a.spacing, near=h.a_to_b.nearest)
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
                fr = _flip_check(ctx, V, F, fr)
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
            V, fr, _ = _no_new_flips(ctx, V_mid, V, F, fr, info)
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
            fr = _flip_check(ctx, V, F, fr)
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
    o2 = replace(out, V=V, F=F, tri_uvs=tri_uvs, flipped=fr.flipped, flip=fr, h=None, folded=_new_folds(ctx, V, F),
                 new_nonmanifold=_new_nonmanifold_triangles(ctx.prep, F, out.src_vertex))
    h2 = _measure(ctx, o2)
    keep = bool(h2.max < h.max and _flaws(o2) <= _flaws(out))
    log.append({"hausdorff_max": float(h2.max / ctx.scale), "kept": keep})
    if keep:
        return o2, h2, log
    return out, h, log


def _prove_bound(ctx: _Ctx, h: HausdorffResult) -> tuple[HausdorffResult, dict | None]:
    """The result's measure with a proven upper bound of its maximum, per direction that
    ``error_bound`` asks for (simplify_measure.certify: cells cut, largest bound first, until none
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
    points = (_BOUND_POINTS if h.max > floor else 1) * ctx.cfg.error_samples
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


def _peak_rounds(ctx: _Ctx, out: _Out, h: HausdorffResult, whole, target: int, details: dict
                 ) -> tuple[_Out, HausdorffResult]:
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
        o3, h3 = whole(target, lock, refuse_defects=True)
        if h3 is not None and ctx.cfg.refine_rounds:
            o3, h3, _ = _refine(ctx, o3, h3)
        keep = bool(h3 is not None and h3.max < h.max and _defects(o3) == 0 and _flaws(o3) <= _flaws(out))
        log.append({"locked_vertices": int(lock.sum()), "defects": _defects(o3),
                    "hausdorff_max_before": float(h.max / ctx.scale),
                    "hausdorff_max_after": None if h3 is None else float(h3.max / ctx.scale), "kept": keep})
        if not keep:
            break
        out, h = o3, h3
    details["peak_rounds"] = log
    return out, h


def _reassign(le: repair.LocalError, V: np.ndarray, F: np.ndarray, changed: np.ndarray) -> None:
    """The input points that stood for a changed triangle: their closest triangle again."""
    pts, _ = le.points_of(changed)
    if len(pts):
        _, near = SurfaceIndex(V, F).distance(le.P[pts])
        le.a_tri[pts] = near
        le.set_assignment(le.a_tri, len(F))


def _edge_flip_repair(V: np.ndarray, F: np.ndarray, region: np.ndarray, tri_uvs: np.ndarray | None,
                      fr: FlipResult, limit: int = 256) -> int:
    """Turn the shared edge of a flipped triangle and a neighbour (in place) when both new
    triangles then face the way the input surface under the pair does. Only edges inside one
    region and off UV seams are turned, so materials and UVs stay valid. Works on the few
    flipped triangles only (at most ``limit``). Returns how many edges were turned."""
    flipped, ref = fr.flipped, fr.ref
    # directed edge -> triangle
    n = max(int(F.max()) + 1, 1)
    d_key = np.concatenate([F[:, 0] * n + F[:, 1], F[:, 1] * n + F[:, 2], F[:, 2] * n + F[:, 0]])
    d_tri = np.tile(np.arange(len(F)), 3)
    order = np.argsort(d_key, kind="stable")
    d_key, d_tri = d_key[order], d_tri[order]

    def owner(p: int, q: int) -> int:
        k = p * n + q
        i = np.searchsorted(d_key, k)
        if i < len(d_key) and d_key[i] == k and (i + 1 == len(d_key) or d_key[i + 1] != k):
            return int(d_tri[i])
        return -1

    def nrm(tri: np.ndarray) -> np.ndarray:
        return np.cross(V[tri[1]] - V[tri[0]], V[tri[2]] - V[tri[0]])

    turned = 0
    touched = np.zeros(len(F), bool)
    for t in np.flatnonzero(flipped)[:limit]:
        if touched[t]:
            continue
        best = None
        for k in range(3):
            p, q, r = F[t, k], F[t, (k + 1) % 3], F[t, (k + 2) % 3]
            u = owner(q, p)
            if u < 0 or touched[u] or region[u] != region[t]:
                continue
            ku = int(np.flatnonzero(F[u] == q)[0])  # u = (q, p, d) rotated
            if F[u, (ku + 1) % 3] != p:
                continue
            d = F[u, (ku + 2) % 3]
            if d == r or owner(r, d) >= 0 or owner(d, r) >= 0:
                continue
            if tri_uvs is not None:
                uv_t = {F[t, j]: tri_uvs[t, j] for j in range(3)}
                uv_u = {F[u, j]: tri_uvs[u, j] for j in range(3)}
                if not (np.array_equal(uv_t[p], uv_u[p]) and np.array_equal(uv_t[q], uv_u[q])):
                    continue  # a UV seam runs along this edge
            t1 = np.array([p, d, r])
            t2 = np.array([d, q, r])
            rn = ref[t] + ref[u]
            score = min(float(nrm(t1) @ rn), float(nrm(t2) @ rn))
            if score > 0 and (best is None or score > best[0]):
                best = (score, u, t1, t2, k, ku)
        if best is None:
            continue
        _, u, t1, t2, k, ku = best
        if tri_uvs is not None:
            uv = {F[t, j]: tri_uvs[t, j].copy() for j in range(3)}
            uv.update({F[u, (ku + 2) % 3]: tri_uvs[u, (ku + 2) % 3].copy()})
            tri_uvs[t] = [uv[x] for x in t1]
            tri_uvs[u] = [uv[x] for x in t2]
        F[t], F[u] = t1, t2
        touched[t] = touched[u] = True
        turned += 1
    return turned


def _relocate_repair(V: np.ndarray, F: np.ndarray, fixed: np.ndarray, fr: FlipResult, index_a: SurfaceIndex,
                     limit: int = 256) -> int:
    """Unfold a flipped triangle by moving one of its free corners (in place) to the centre of
    its neighbours, put back onto the input surface (closest point), when every triangle
    around that corner then faces the way the input under it does. Returns vertices moved."""
    flipped = fr.flipped
    ref = fr.ref.copy()
    no_vote = np.linalg.norm(ref, axis=1) == 0
    ref[no_vote] = np.cross(V[F[no_vote, 1]] - V[F[no_vote, 0]], V[F[no_vote, 2]] - V[F[no_vote, 0]])
    ref[flipped & no_vote] *= -1.0
    # vertex -> incident triangles (CSR)
    order = np.argsort(F.ravel(), kind="stable")
    starts = np.searchsorted(F.ravel()[order], np.arange(len(V) + 1))
    moved = 0
    for t in np.flatnonzero(flipped)[:limit]:
        for v in F[t]:
            if fixed[v]:
                continue
            ring_t = order[starts[v]:starts[v + 1]] // 3
            ring_v = np.unique(F[ring_t].ravel())
            ring_v = ring_v[ring_v != v]
            if len(ring_v) == 0:
                continue
            c = V[ring_v].mean(axis=0)
            _, _, cp = index_a.query(c[None])
            done = False
            for cand in (cp[0], c):
                old = V[v].copy()
                V[v] = cand
                tri = F[ring_t]
                n = np.cross(V[tri[:, 1]] - V[tri[:, 0]], V[tri[:, 2]] - V[tri[:, 0]])
                if (np.einsum("ij,ij->i", n, ref[ring_t]) > 0).all():
                    moved += 1
                    done = True
                    break
                V[v] = old
            if done:
                break
    return moved


def _repair_cost(index_a: SurfaceIndex, V0: np.ndarray, F0: np.ndarray, V1: np.ndarray, F1: np.ndarray
                 ) -> tuple[float, float]:
    """Two-sided error of a repaired result (V1, F1) and of what it was before (V0, F0; same
    triangle count), over the triangles the repair changed and the ring around them: points on
    those triangles against the input, and the input vertices under them against those
    triangles (KD-tree bounds, the same for both). Cheap: a repair touches a few triangles."""
    changed = np.flatnonzero((V0[F0] != V1[F1]).any(axis=(1, 2)))
    if len(changed) == 0:
        return 0.0, 0.0
    verts = np.unique(np.concatenate([F0[changed].ravel(), F1[changed].ravel()]))
    ring = np.flatnonzero(np.isin(F0, verts).any(axis=1) | np.isin(F1, verts).any(axis=1))
    tid, bary = triangle_pattern(np.full(len(ring), 7, np.int64))
    pts, under = [], []
    for Vx, Fx in ((V0, F0[ring]), (V1, F1[ring])):
        C = Vx[Fx]
        P = np.concatenate([np.einsum("nk,nkd->nd", bary, C[tid]), C.reshape(-1, 3)])
        d, t = index_a.distance(P)
        pts.append(d)
        under.append(t)
    qa = index_a.V[np.unique(index_a.F[np.concatenate(under)].ravel())]
    out = []
    for (Vx, Fx), d_ba in zip(((V0, F0[ring]), (V1, F1[ring])), pts):
        d_ab, _ = SurfaceIndex(Vx, Fx, density=0).distance(qa)
        out.append(max(float(d_ba.max()), float(d_ab.max())))
    return out[0], out[1]


def _new_nonmanifold_triangles(prep: _Prepared, F: np.ndarray, src_vertex: np.ndarray) -> np.ndarray:
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


def _parts_record(ctx: _Ctx, out: _Out, h: HausdorffResult | None) -> dict:
    """simplify_parts.part_report for a result: each output triangle belongs to the part of its
    corners' input vertices (those of one part only), or where every corner is shared between
    parts, to the part of the input triangle closest to its centre; the errors are the measure's
    largest distances on each input triangle (original -> simplified) and output triangle (the
    other way)."""
    prep = ctx.prep
    n = prep.n_parts
    lo = np.full(len(prep.V), n, np.int64)
    hi = np.full(len(prep.V), -1, np.int64)
    np.minimum.at(lo, prep.F.ravel(), np.repeat(prep.part, 3))
    np.maximum.at(hi, prep.F.ravel(), np.repeat(prep.part, 3))
    vpart = np.where(lo == hi, hi, -1)  # (a vertex of two parts says nothing)
    cp = vpart[out.src_vertex[out.F]] if len(out.F) else np.zeros((0, 3), np.int64)
    part_out = cp.max(axis=1) if len(cp) else np.zeros(0, np.int64)
    loose = np.flatnonzero(part_out < 0)
    if len(loose):
        _, near = ctx.index_a.distance(out.V[out.F[loose]].mean(axis=1))
        part_out[loose] = prep.part[near]
    C = prep.V[prep.F]
    lo = np.full((n, 3), np.inf)
    hi = np.full((n, 3), -np.inf)
    np.minimum.at(lo, np.repeat(prep.part, 3), C.reshape(-1, 3))
    np.maximum.at(hi, np.repeat(prep.part, 3), C.reshape(-1, 3))

    def per_tri(d, count):
        if d is None or d.tri_max is None:
            return None
        v = np.zeros(count)
        v[:min(count, len(d.tri_max))] = d.tri_max[:count]
        return v
    err_in = None if h is None else per_tri(h.a_to_b, len(prep.F))
    err_out = None if h is None else per_tri(h.b_to_a, len(out.F))
    return part_report(prep.part, part_out, n, ctx.index_a.area, triangle_areas(out.V, out.F), err_in, err_out,
                       np.linalg.norm(hi - lo, axis=1), ctx.scale)


def _defects_record(cfg: SimplifyConfig, out: _Out, parts_rec: dict, new_nm: int, new_folds: int) -> dict:
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
            "new_folds": int(max(0, new_folds)), "folded_area": float(area[folded].sum() / total),
            "parts_dropped": parts_rec["dropped"], "parts_collapsed": parts_rec["collapsed"],
            "areas_are": "shares of the result's area (the parts': their share of the input's, details.parts)"}


def _total(prep: _Prepared, out: _Out) -> int:
    """Triangles a result writes: its layer's and the backs put back (simplify_parts)."""
    return int(len(out.F) + prep.region_back[out.region].sum())


def _defects(out: _Out) -> int:
    """Flipped triangles and triangles on new non-manifold edges: a result with any is not
    accepted (the stage backs off to more triangles)."""
    return int(out.flipped.sum()) + int(out.new_nonmanifold.sum())


def _flaws(out: _Out) -> int:
    """Defects and triangles in new folds: what the lock-and-retry rounds try to remove (a fold
    left over is reported, not a reason to back off: at strong reductions of thin parts a few
    are the price of the budget)."""
    return _defects(out) + (int(out.folded.sum()) if out.folded is not None else 0)


def _lock_under(prep: _Prepared, out: _Out, index_a: SurfaceIndex, lock: np.ndarray) -> np.ndarray:
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


def _with_backs(prep: _Prepared, out: _Out, front: dict, back: dict) -> dict:
    """The output's triangles with the backs of the layer put back (simplify_parts): every
    triangle of a region with a back is followed, after all the fronts, by itself reversed with
    the back's material, UVs and face colour."""
    tw = np.flatnonzero(prep.region_back[out.region])
    res = dict(front)
    flip = [0, 2, 1]
    res["triangles"] = np.concatenate([out.F, out.F[tw][:, flip]])
    res["tri_material"] = np.concatenate([front["tri_material"], back["tri_material"][tw]])
    if "tri_uvs" in front:
        res["tri_uvs"] = np.concatenate([front["tri_uvs"], back["tri_uvs"][tw][:, flip]])
    if "face_colors" in front:
        res["face_colors"] = np.concatenate([front["face_colors"], back["face_colors"][tw]])
    return res


def _attributes(prep: _Prepared, out: _Out, index_a: SurfaceIndex | None, notes: list[str], side: int = 0) -> dict:
    """Triangles, material, UVs, face colours and vertex colours for the output (where tri_uvs
    holds the backs' UVs beside the fronts', ``side`` 0 takes the fronts', 1 the backs')."""
    t = len(out.F)
    res: dict = {"triangles": out.F}
    nearest = None

    def nearest_tri() -> np.ndarray:
        nonlocal nearest
        if nearest is None:
            idx = index_a if index_a is not None else SurfaceIndex(prep.V, prep.F)
            _, nearest, _ = idx.query(out.V[out.F].mean(axis=1))
        return nearest

    # material
    if out.src_tri is not None:
        res["tri_material"] = prep.tri_material[out.src_tri]
    elif prep.materials_as_regions or not len(prep.tri_material) or np.all(prep.tri_material == prep.tri_material[0]):
        res["tri_material"] = prep.region_material[out.region] if len(prep.tri_material) else np.zeros(t, np.int64)
    else:  # materials not preserved: the material of the input triangle under each centroid
        res["tri_material"] = prep.tri_material[nearest_tri()]
        notes.append("materials were not kept as regions (preserve_materials = false): each triangle "
                     "takes the material of the input triangle nearest its centre")
    # UVs
    if prep.tri_uvs is not None:
        if out.tri_uvs is not None:
            res["tri_uvs"] = out.tri_uvs
        elif out.src_tri is not None:
            res["tri_uvs"] = prep.tri_uvs[out.src_tri]
        else:
            res["tri_uvs"] = prep.tri_uvs[nearest_tri()]
            notes.append("UVs were taken from the input triangle nearest each triangle's centre")
    # face colours
    if prep.face_colors is not None:
        if out.src_tri is not None:
            res["face_colors"] = prep.face_colors[out.src_tri]
        elif prep.colors_as_regions and prep.region_color is not None:
            res["face_colors"] = prep.region_color[out.region]
        else:
            res["face_colors"] = prep.face_colors[nearest_tri()]
            notes.append("face colours vary too much to be kept as regions: each triangle takes the "
                         "colour of the input triangle nearest its centre")
    if prep.vertex_colors is not None:
        res["vertex_colors"] = prep.vertex_colors[out.src_vertex]
    if "tri_uvs" in res:
        res["tri_uvs"] = res["tri_uvs"][..., 2 * side:2 * side + 2]
    return res




def _border_chord_max(prep: "_Prepared", out: _Out, chains: list, scale: float) -> tuple[float, int]:
    """How far the output's borders and seams stray from the input's: along each input chain
    (open border, material edge, UV seam), the output keeps some of its vertices (unmoved); the
    output edge between two kept vertices that follow each other on the chain is a chord of the
    chain between them, and this is the largest distance of a chain vertex from its chord
    (fraction of the diagonal). Also returns how many input chains kept fewer than two vertices
    (a closed hole or a seam that vanished)."""
    if not chains:
        return 0.0, 0
    kept = np.zeros(len(prep.V), bool)
    unmoved = np.linalg.norm(out.V - prep.V[out.src_vertex], axis=1) == 0
    kept[out.src_vertex[unmoved]] = True
    worst, gone = 0.0, 0
    for c in chains:
        idx = np.flatnonzero(kept[c])
        closed = len(c) > 2 and c[0] != c[-1]
        if len(idx) < 2:
            gone += 1
            continue
        P = prep.V[c]
        starts = idx
        ends = np.r_[idx[1:], idx[0] + len(c)] if closed else idx[1:]
        starts = starts[:len(ends)]
        Q = np.concatenate([P, P]) if closed else P
        for i, j in zip(starts.tolist(), ends.tolist()):
            if j - i < 2:
                continue
            a, ab = Q[i], Q[j] - Q[i]
            L = float(ab @ ab)
            X = Q[i + 1:j] - a
            t = np.clip((X @ ab) / L, 0.0, 1.0) if L > 0 else np.zeros(len(X))
            worst = max(worst, float(np.linalg.norm(X - t[:, None] * ab, axis=1).max()))
    return worst / scale, gone


def simplify_mesh(scene: Scene, cfg: SimplifyConfig) -> tuple[Scene, StageRecord]:
    """The stage body (see the module docstring)."""
    t0 = time.perf_counter()
    rec = StageRecord(name="simplify")
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
        rec.seconds = time.perf_counter() - t0
        return scene, rec
    kind, value = resolve_target(T0, cfg)
    if method == "meshopt" and not simplify_meshopt.available():
        rec.warn("meshoptimizer is not installed; used method 'fast' instead")
        method = "fast"
    scale = scene.scale()
    prep = _prepare(scene, cfg)
    details: dict = {"method": method, "target_kind": kind, "scale": scale,
                     "regions": int(len(prep.region_material))}
    if method == "meshopt":
        details["library"] = f"meshoptimizer {simplify_meshopt.version()}"
    notes: list[str] = []

    if kind == "triangles" and int(value) >= T0:
        rec.warn(f"target {int(value)} triangles is not below the input's {T0}; nothing to do")
        rec.counts_out = dict(rec.counts_in)
        rec.details = details | {"target_triangles": int(value)}
        rec.seconds = time.perf_counter() - t0
        return scene, rec

    T0 = len(prep.F)  # the layer (simplify_parts.fold_layer): what the library simplifies
    if prep.layer.folded:
        details["layer"] = {"triangles": T0, "with_back": prep.layer.twins, "repeated_dropped": prep.layer.repeated}
    details["parts_in"] = prep.n_parts
    t_prep = time.perf_counter()
    index_a = SurfaceIndex(prep.V, prep.F, seed=cfg.seed, scale=scale, corners=False, k=8)
    grid_a = surface_grid(prep.V, prep.F, cfg.error_samples)
    # vertices the fit and the repairs leave alone: material edges, non-manifold edges and (with
    # preserve_border) open borders
    edge_mask, region_edges = _region_edge_vertices(prep.F, prep.region, len(prep.V))
    e_in, c_in, _ = edge_counts(prep.F)
    border_mask = np.zeros(len(prep.V), bool)
    border_mask[e_in[c_in == 1].ravel()] = True
    protect = edge_mask | _nonmanifold_vertices(prep.F, len(prep.V))
    if cfg.preserve_border:
        protect |= border_mask
    chains, chain_ends = [], np.zeros(0, np.int64)
    if method == "meshopt":
        # the input's border and seam chains (open borders, material edges, UV seams): the
        # library's wedge borders, in input vertex numbers
        Fw, w_vertex, _, _ = _wedges(prep)
        we, wc, _ = edge_counts(Fw)
        seams = w_vertex[we[wc == 1]]
        chains, chain_ends = repair.border_chains(prep.F, seams)
    folds_in = repair.folds(prep.V, prep.F)
    ctx = _Ctx(prep=prep, cfg=cfg, method=method, index_a=index_a, grid_a=grid_a, scale=scale, protect=protect,
               chains=chains, chain_ends=chain_ends,
               fold_zones=prep.V[prep.F[np.unique(folds_in.ravel())]].mean(axis=1) if len(folds_in) else None)
    # the fit pairs at most _FIT_POINTS of the input's grid points (a fixed, even subset)
    ctx.fit_points = grid_a.P if len(grid_a.P) <= _FIT_POINTS else \
        grid_a.P[np.sort(np.random.default_rng(cfg.seed + 3).choice(len(grid_a.P), _FIT_POINTS, replace=False))]
    prep_s = time.perf_counter() - t_prep

    cap = float(cfg.error_ceiling) * scale if kind == "triangles" else 0.0
    border_log: dict = {}
    relax_log: list[dict] = []

    def attempt(target: int, lock0: np.ndarray | None = None, rounds: int = _REPAIR_ROUNDS) -> _Out:
        """Simplify; while triangles come out flipped, keep the input vertices under them
        (locked) and simplify again (a few rounds)."""
        lock = np.zeros(len(prep.V), bool) if lock0 is None else lock0.copy()
        lib_s = 0.0
        if ctx.chains and "locks" not in prep.relaxed:
            # keep each border/seam chain within half the library's error estimate of itself
            raw0 = _run_to(ctx, target, lock, cap, relax_log)
            lib_s += raw0.lib_seconds
            tol = _BORDER_TOLERANCE * raw0.lib_error
            # the locks may take at most a quarter of the target's vertices (about target / 2):
            # the chords that stray furthest are kept first
            budget = max(8, target // 8)
            blk = repair.border_locks(prep.V, ctx.chains, ctx.chain_ends, tol, len(prep.V), budget)
            border_log.update({"tolerance": tol / scale, "budget": budget, "locked_vertices": int(blk.sum()),
                               "chain_vertices": int(sum(len(c) for c in ctx.chains))})
            if int(blk.sum()) > budget:  # the chains' ends alone are too many (soups, CSG slivers)
                blk[:] = False
                border_log.update({"locked_vertices": 0, "skipped": f"the chains have more than {budget} ends"})
            lock |= blk
        best = None
        for rnd in range(rounds + 1):
            report_step(f"{target:,} triangles: library and repairs" + (f", lock round {rnd}" if rnd else ""))
            raw = _run_to(ctx, target, lock, cap, relax_log)
            raw.lib_seconds += lib_s
            lib_s = 0.0
            out = _finish(ctx, raw)
            n_flip = _flaws(out)
            before = None if best is None else _flaws(best)
            if best is None or n_flip < before:
                best = out
            if n_flip == 0 or rnd == rounds:
                break
            if before is not None and n_flip > _FLAWS_FEW and n_flip > _FLAWS_DROP * before:
                break  # the last round moved the flaws more than it removed them
            if "locks" in prep.relaxed:  # (locking is what the target could not afford)
                break
            t = time.perf_counter()
            add = _lock_under(prep, out, index_a, lock)
            ctx.seconds["repair"] += time.perf_counter() - t
            if not (add & ~lock).any():
                break
            lock |= add
            ctx.repair_log.append({"target": int(target), "round": rnd + 1, "flipped": int(out.flipped.sum()),
                                   "on_new_nonmanifold_edges": int(out.new_nonmanifold.sum()),
                                   "folded": int(out.folded.sum()) if out.folded is not None else 0,
                                   "locked_vertices": int(lock.sum())})
        return best

    measuring = cfg.measure_error or kind == "error"

    def fitted(out: _Out, o1: _Out | None = None) -> tuple[_Out, HausdorffResult | None]:
        """The fit (abandoned if it turns triangles against the input or into folds) and the
        measure of the result; the fit is kept only if its measured max is not above
        _FIT_TOLERANCE times the unfitted result's. A least-squares fit pulls sharp CSG/CAD
        corners off their places (boolean.glb at 50%: 0.96% of the diagonal with it, 0.09%
        without), so the unfitted result is measured too: first on the input's grid alone,
        then on both grids (_FIT_CHECK_ROUNDS refinement rounds, no cut cells: a subset of the
        full measure's points, so its max can only be lower than the full one), in full only
        if neither already settles it. ``o1``: the fit of ``out``, made already."""
        o1 = _fit(ctx, out) if o1 is None else o1
        if not measuring:
            return o1, None
        h1 = _measure(ctx, o1)
        if o1 is out:
            return o1, h1
        if out.h is not None:  # measured already (a back-off probe)
            hl = out.h
        else:
            t = time.perf_counter()
            # the input's side first (its grid against the small result: cheap); the other side,
            # against the input, only if that alone does not already keep the fit
            ib = SurfaceIndex(out.V, out.F)
            hl = original_side(ib, grid_a, rounds=_FIT_CHECK_ROUNDS, straddling=False)
            if h1.max > _FIT_TOLERANCE * hl.max:
                hl = hausdorff(prep.V, prep.F, out.V, out.F, points=cfg.error_samples, index_a=index_a,
                               grid_a=grid_a, index_b=ib, rounds=_FIT_CHECK_ROUNDS, straddling=False,
                               a_to_b=hl)
            ctx.measures += 1
            ctx.seconds["measure"] += time.perf_counter() - t
        check = {"max_with_fit": float(h1.max / scale), "max_without_fit_at_least": float(hl.max / scale)}
        if h1.max <= _FIT_TOLERANCE * hl.max:
            o1.fit_info = {**o1.fit_info, "kept": True, "check": check}
            return o1, h1
        h0 = _measure(ctx, out)
        check["max_without_fit"] = float(h0.max / scale)
        if h1.max > _FIT_TOLERANCE * h0.max:
            out.fit_info = {**o1.fit_info, "kept": False, "check": check}
            return out, h0
        o1.fit_info = {**o1.fit_info, "kept": True, "check": check}
        return o1, h1

    def whole(target: int, lock0: np.ndarray | None = None, rounds: int = _REPAIR_ROUNDS, fit: bool = True,
              refuse_defects: bool = False):
        if target >= T0:  # backing off all the way: the input as it is
            o = _identity(ctx)
            return o, o.h
        o = attempt(target, lock0, rounds)
        if len(o.F) >= T0:  # nothing collapsed (a box): the input itself is as many triangles, exact
            return whole(T0)
        if not fit:  # a back-off probe: the library's result, measured (the fit comes once, after)
            # a result with defects is refused whatever its error: not measured
            return o, (_measure(ctx, o) if measuring and _defects(o) == 0 else None)
        if refuse_defects and o.new_nonmanifold.any():
            # refused whatever its error (the triangle target backs off from it; the fit moves
            # vertices only, so it cannot mend the topology): neither fitted nor measured
            return o, None
        if refuse_defects and _defects(o):
            # flipped triangles: refused too, unless the fit turns them back (it turns none
            # against the input, and may turn some back); if it does not, not measured
            o1 = _fit(ctx, o)
            if _defects(o1):
                return o1, None
            return fitted(o, o1)
        return fitted(o)

    probes: list[dict] = []
    refine_log: list[dict] = []
    if kind == "triangles":
        # the layer's count whose triangles, with the backs put back, are the target
        target = max(1, int(round(int(value) * T0 / (T0 + prep.layer.twins))))
        refuse = cfg.defects == "refuse"
        out, h = whole(target, refuse_defects=refuse)

        def acceptable(o: _Out, hh) -> bool:
            return (not refuse or _defects(o) == 0) and (hh is None or cap <= 0 or hh.max <= cap)

        if not acceptable(out, h):
            # fewer triangles cost flips, non-manifold edges or more than the ceiling: find the
            # smallest count above the target that does not
            why = (f"{int(out.flipped.sum())} flipped triangle(s), {int(out.new_nonmanifold.sum())} on new "
                   f"non-manifold edges (defects = \"refuse\")" if refuse and _defects(out) else
                   f"an error of {h.max / scale:.3%} of the diagonal (error_ceiling = {cfg.error_ceiling})")
            # (never None: the probes go up to the input itself, which is always acceptable)
            n, o2, h2 = _back_off(target, T0, whole, acceptable, probes, scale)
            if o2 is not None:
                o2, h2 = fitted(o2)  # kept only if not worse than the probe's measured result
                n_out, n_got = _total(prep, out), _total(prep, o2)
                got = "" if n_out == int(value) else f" (what a target of {int(value)} gave)"
                rec.warn(f"{n_out} triangles{got} would cost {why}; stopped at {n_got} triangles instead")
                out, h = o2, h2
                details["backed_off_from"] = target
            details["probes"] = probes
        if h is not None and cfg.refine_rounds and h.max > ROUNDS_FLOOR * scale:
            out, h, refine_log = _refine(ctx, out, h)
            # (the peak rounds refuse a result with defects: a result that has some already is not
            # run again for them)
            if "backed_off_from" not in details and cfg.peak_rounds > 0 and h.max > ROUNDS_FLOOR * scale \
                    and _defects(out) == 0:
                out, h = _peak_rounds(ctx, out, h, whole, target, details)
    else:
        target, out, h = _search_error(prep, method, value * scale, T0, whole, probes, scale, ctx.seconds)
        details["max_error_target"] = value
        details["probes"] = probes
        if cfg.refine_rounds and h.max > ROUNDS_FLOOR * scale:
            out, h, refine_log = _refine(ctx, out, h)
    bound_log = None
    if h is not None and cfg.error_bound != "none":
        before = h.max
        h, bound_log = _prove_bound(ctx, h)
        # the bound's cuts can find a larger distance than the measure that accepted the result
        limit = cap if kind == "triangles" else value * scale
        if h.max > before and limit > 0 and h.max > limit:
            what = f"error_ceiling = {cfg.error_ceiling}" if kind == "triangles" else f"max_error = {value}"
            rec.warn(f"proving the error bound found a larger error, {h.max / scale:.4%} of the diagonal, than "
                     f"the measure that accepted this result ({before / scale:.4%}); it is above {what}")
    notes.extend(out.notes)
    parts_rec = _parts_record(ctx, out, h)
    for kind_, what in (("dropped", "no triangle left"), ("collapsed", "error above half the part's own size")):
        if parts_rec[kind_]:
            rec.warn(f"{parts_rec[kind_]} of {prep.n_parts} part(s) {kind_} ({what}; "
                     f"{parts_rec[kind_ + '_area'] / max(float(ctx.index_a.total_area) / scale ** 2, 1e-300):.2%} "
                     "of the input's surface); details.parts lists the worst")
    attrs = _attributes(prep, out, index_a, notes)
    if prep.layer.twins:  # the layer's triangles that had a back get it again, reversed
        attrs = _with_backs(prep, out, attrs, _attributes(prep.back(), out, index_a, [], side=1))

    # ---- checks
    topo_in = topology(prep.F)
    topo_out = topology(out.F)
    flips = out.flipped
    folds_out = repair.folds(out.V, out.F)
    out_edge_mask, out_region_edges = _region_edge_vertices(out.F, out.region, len(out.V))
    off_boundary = int((out_edge_mask & ~edge_mask[out.src_vertex]).sum())
    moved_boundary = int((out_edge_mask & (np.linalg.norm(out.V - prep.V[out.src_vertex], axis=1) > 0)).sum())
    e_out, c_out, _ = edge_counts(out.F)
    out_border = np.zeros(len(out.V), bool)
    out_border[e_out[c_out == 1].ravel()] = True
    border_off = int((out_border & ~border_mask[out.src_vertex]).sum())
    border_moved = int((out_border & (np.linalg.norm(out.V - prep.V[out.src_vertex], axis=1) > 0)).sum())

    T1 = len(attrs["triangles"])
    if kind == "triangles":
        miss = abs(T1 - int(value)) / max(int(value), 1)
        if miss > 0.01 and "backed_off_from" not in details:
            why = []
            if cap > 0:
                why.append(f"error_ceiling = {cfg.error_ceiling} (the library stops before its own error estimate "
                           "passes it)")
            if len(prep.region_material) > 1:
                why.append(f"{len(region_edges)} material/colour edges are kept")
            if cfg.preserve_border and topo_in["open_edges"]:
                why.append(f"{topo_in['open_edges']} open border edges are kept")
            if prep.tri_uvs is not None and method == "meshopt":
                why.append("UV seams collapse only along themselves")
            if topo_in["nonmanifold_edges"]:
                why.append(f"{topo_in['nonmanifold_edges']} non-manifold edges")
            rec.warn(f"got {T1} triangles for a target of {int(value)} ({miss:.1%} off): "
                     + ("; ".join(why) if why else "the library stopped (no collapse left that keeps the mesh valid)"))
    if h is not None and cap <= 0 and kind == "triangles" and h.max > _LARGE_ERROR * scale:
        rec.warn(f"the result is {h.max / scale:.2%} of the diagonal off the input (the largest distance between "
                 "them): set mesh.simplify.error_ceiling to stop at more triangles instead")
    new_nm = max(0, topo_out["nonmanifold_edges"] - topo_in["nonmanifold_edges"])
    new_mis = max(0, topo_out["misoriented_edges"] - topo_in["misoriented_edges"])
    if int(flips.sum()):
        rec.warn(f"{int(flips.sum())} triangle(s) face against the original surface")
    if len(folds_out) > len(folds_in):
        rec.warn(f"{len(folds_out)} fold(s): neighbouring triangles whose normals point against each other "
                 f"(the input has {len(folds_in)})")
    if new_nm or new_mis:
        rec.warn(f"{new_nm} new non-manifold edge(s), {new_mis} new mis-oriented edge(s)")
    if off_boundary or moved_boundary:
        rec.warn(f"{off_boundary} material-edge vertices are not input material-edge vertices; "
                 f"{moved_boundary} moved")
    if cfg.preserve_border and (border_off or border_moved):
        rec.warn(f"{border_off} border vertices are not input border vertices; {border_moved} moved")
    if prep.relaxed:
        rec.warn(f"to reach {int(value) if kind == 'triangles' else T1} triangles the library was let go of: "
                 + "; ".join(_RELAXED_TEXT[r] for r in prep.relaxed))
    for n in notes:
        rec.warn(n)

    chord_max, chains_gone = _border_chord_max(prep, out, chains, scale)

    # ---- the new scene
    new = scene.replace(
        positions=np.ascontiguousarray(out.V, np.float64),
        triangles=attrs["triangles"].astype(np.int64),
        tri_material=np.asarray(attrs["tri_material"], np.int64),
        tri_uvs=attrs.get("tri_uvs"),
        tri_polygon=np.full(T1, -1, np.int64),
        face_colors=attrs.get("face_colors"),
        vertex_colors=attrs.get("vertex_colors"),
        poly_sizes=None, poly_indices=None, poly_material=None, poly_uvs=None,
    )
    new.validate()

    rec.counts_out = {"triangles": T1, "vertices": new.n_vertices, "polygons": 0, "materials": len(new.materials)}
    if h is not None:
        rec.accuracy = {"hausdorff_max": h.max / scale, "hausdorff_mean": h.mean / scale,
                        "hausdorff_max_original_to_simplified": h.max_a_to_b / scale,
                        "hausdorff_max_simplified_to_original": h.max_b_to_a / scale}
        # proven upper bounds of the true maxima (not samples), where error_bound made them
        if h.a_to_b is not None and np.isfinite(h.a_to_b.bound):
            rec.accuracy["hausdorff_bound_original_to_simplified"] = h.a_to_b.bound / scale
        if h.b_to_a is not None and np.isfinite(h.b_to_a.bound):
            rec.accuracy["hausdorff_bound_simplified_to_original"] = h.b_to_a.bound / scale
        if np.isfinite(h.bound):
            rec.accuracy["hausdorff_bound"] = h.bound / scale
        if not h.exact:
            rec.warnings.append("the Hausdorff max is an upper bound: verifying it exactly would have measured "
                                "millions of point-triangle pairs (loose bounds on large overlapping triangles)")
    rec.accuracy.update({"flipped_triangles": int(flips.sum()), "folds": int(len(folds_out)),
                         "new_nonmanifold_edges": new_nm, "new_misoriented_edges": new_mis})
    sample = None
    if h is not None and h.a_to_b is not None:
        sample = {"original_grid_points": int(h.a_to_b.grid_points), "simplified_grid_points": int(h.b_to_a.grid_points),
                  "refinement_points": int(h.refine_points),
                  "original_spacing": float(h.a_to_b.spacing / scale), "simplified_spacing": float(h.b_to_a.spacing / scale),
                  "max_is": ("sampled: the largest exact distance at a point of the sample (the true maximum "
                             "over the surfaces can only be larger)" if h.exact else
                             "an upper bound of the largest distance at a point of the sample") +
                  ("; accuracy.hausdorff_bound_* are proven upper bounds of the true maximum (details."
                   "error_bound says how they were made)" if np.isfinite(h.a_to_b.bound) else "")}
    details.update({
        "target_triangles": int(value) if kind == "triangles" else T1,
        "prepare_seconds": round(prep_s, 6),
        **{f"{k}_seconds": round(v, 6) for k, v in ctx.seconds.items()},
        "phase_seconds_are": "totals over every attempt (back-off probes, peak rounds), not only the result kept",
        "measures": int(ctx.measures),
        "flip_repairs": ctx.repair_log,
        "flip_checked_triangles": int(ctx.flip_cache.get("checked", 0)),
        "edges_turned_at_sharp_angles": int(out.edge_turns),
        "fit": out.fit_info,
        "refine": refine_log,
        "error_samples": int(cfg.error_samples) if sample is not None else 0,
        "error_sample": sample,
        "error_bound": bound_log,
        "error_metric": "symmetric Hausdorff: a grid on each surface (every vertex, points along every edge and "
                        f"inside every triangle; on the simplified one {_measure_mod.POINTS_PER_SIMPLIFIED} per "
                        "triangle where that is more, at most 4 x error_samples, and then every triangle cut "
                        f"into at least {4 ** _measure_mod.CAPPED_MIN_LEVEL} cells), refined "
                        f"{_measure_mod.ROUNDS} times around up to "
                        f"{_measure_mod.SEEDS} of the largest distances at separate places "
                        f"({4 * _measure_mod.SEEDS} on the original's side), only cells that may hold more than "
                        f"{_measure_mod.KEEP_SHARE:.0%} of the largest exact distance so far (a convexity bound), "
                        "the largest made exact at their points (bake/mesh/simplify_measure.py); a sampled "
                        "maximum; fractions of the bbox diagonal",
        "hausdorff_max_exact": False if h is not None else None,
        "worst_point": None if h is None else [float(x) for x in h.worst_point],
        "worst_point_original_to_simplified": None if h is None or h.a_to_b is None else
        [float(x) for x in h.a_to_b.worst],
        "worst_point_simplified_to_original": None if h is None or h.b_to_a is None else
        [float(x) for x in h.b_to_a.worst],
        "topology_in": topo_in, "topology_out": topo_out,
        "folds_in": int(len(folds_in)), "folds_out": int(len(folds_out)),
        "fold_pairs": [[int(a), int(b)] for a, b in folds_out[:20]],
        # the output triangles (numbers in the stage's output) of each kind of defect, at most
        # _DEFECT_IDS of each: the report's previews and the benchmark's picture cost read them
        "defect_triangles": {k: np.flatnonzero(m)[:_DEFECT_IDS].tolist() for k, m in (
            ("flipped", out.flipped), ("on_new_nonmanifold_edges", out.new_nonmanifold),
            ("folded", out.folded if out.folded is not None else np.zeros(len(out.F), bool)))},
        "material_edges_in": int(len(region_edges)), "material_edges_out": int(len(out_region_edges)),
        "material_edge_vertices_off_input_edges": off_boundary,
        "material_edge_vertices_moved": moved_boundary,
        "border_vertices_off_input_border": border_off,
        "border_vertices_moved": border_moved,
        "parts": parts_rec,
        "defects": _defects_record(cfg, out, parts_rec, new_nm, len(folds_out) - len(folds_in)),
        "border_locks": border_log,
        "relaxed": list(prep.relaxed),
        "relaxations": relax_log,
        "border_chord_max": chord_max,
        "border_chains_closed": chains_gone,
        "attributes": _attribute_notes(prep, out, method),
        "polygons": "dropped: every output triangle has tri_polygon = -1",
    })
    rec.details = details
    rec.seconds = time.perf_counter() - t0
    # the rest: the stage's own bookkeeping, attribute transfer, the final checks
    details["other_seconds"] = round(max(0.0, rec.seconds - prep_s - sum(ctx.seconds.values())), 6)
    return new, rec


def _attribute_notes(prep: _Prepared, out: _Out, method: str) -> dict:
    how = {}
    if method == "meshopt":
        how["uvs"] = "exact input corner values (UV seams kept as meshoptimizer seams)"
        how["material"] = "region of the corners' wedges (material edges kept as seams)"
        how["vertex_colors"] = "exact (vertices are a subset of the input's)"
    else:
        how["uvs"] = "the corners of the input triangle each output triangle descends from"
        how["material"] = "the input triangle each output triangle descends from"
        how["vertex_colors"] = "the closest input vertex merged into each output vertex"
    how["face_colors"] = "region colour" if prep.colors_as_regions else "source or nearest input triangle"
    return how


def _back_off(target: int, T0: int, whole, acceptable, probes: list, scale: float):
    """Smallest count in (target, T0] whose result is acceptable (grow by 30% until one is,
    then bisect a few times). Returns (count, out, hausdorff) or (target, None, None)."""
    tried: dict[int, tuple] = {}

    def probe(n: int) -> bool:
        report_step(f"back-off probe {len(tried) + 1}: {n:,} triangles")
        out, h = whole(n, None, 0, False)  # no lock-and-retry rounds here: backing off is the repair
        ok = acceptable(out, h)
        tried[n] = (out, h, ok)
        probes.append({"target": n, "triangles": int(len(out.F)), "defects": _defects(out),
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


def _search_error(prep: _Prepared, method: str, e_abs: float, T0: int, whole, probes: list, scale: float,
                  seconds: dict):
    """Smallest triangle count (within ~5%) whose measured Hausdorff max is <= e_abs."""
    tried: dict[int, tuple] = {}

    def probe(n: int):
        n = int(min(max(n, 4), T0))
        if n in tried:
            return tried[n]
        out, h = whole(n)
        tried[n] = (out, h)
        probes.append({"target": n, "triangles": int(len(out.F)), "hausdorff_max": float(h.max) / scale,
                       "defects": _defects(out), "ok": bool(h.max <= e_abs and _defects(out) == 0)})
        return tried[n]

    # first guess: meshoptimizer's own error bound, else 10% of the input
    if method == "meshopt":
        Fw, w_vertex, _, _ = _wedges(prep)
        t = time.perf_counter()
        raw_n = len(simplify_meshopt.simplify(prep.V[w_vertex], Fw, 0, target_error=e_abs, absolute_error=True)[0])
        seconds["library"] += time.perf_counter() - t
        n = max(raw_n, 4)
    else:
        n = max(T0 // 10, 4)
    lo, hi = 0, None  # lo: largest count known to fail; hi: smallest known to pass
    for _ in range(9):
        out, h = probe(n)
        if h.max <= e_abs and _defects(out) == 0:
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
        best_n = max(tried, key=lambda k: (tried[k][1].max <= e_abs and _defects(tried[k][0]) == 0, k))
    else:
        best_n = hi
    out, h = tried[best_n]
    return best_n, out, h


def stage(scene: Scene, cfg: SimplifyConfig) -> tuple[Scene, StageRecord]:
    """Pipeline entry point: ``(scene, SimplifyConfig) -> (scene, record)``."""
    try:
        return simplify_mesh(scene, cfg)
    except MemoryError:
        raise StageError("simplify ran out of memory") from None
