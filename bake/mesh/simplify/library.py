"""Running the libraries (stage.py's docstring, "Methods"): one run of meshoptimizer, fast-simplification
or MeshLab on the prepared input for a layer target, handed back as a :class:`Raw` (per output
triangle and vertex, which input vertex and triangle it comes from). Meeting the count, with what
is let go when a library stops short, is ladder.py."""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np

from ...config import SimplifyConfig
from ...errors import ConfigError, StageError
from . import meshopt
from .inputs import Prepared, wedges

METHODS = ("meshopt", "fast", "quality")


@dataclass
class Raw:
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


def run(prep: Prepared, method: str, target: int, cfg: SimplifyConfig, lock: np.ndarray, cap: float) -> Raw:
    if method == "meshopt":
        return _run_meshopt(prep, target, cfg, lock, cap)
    if method == "fast":
        return _run_fast(prep, target, cfg, lock)
    if method == "quality":
        return _run_quality(prep, target, cfg, lock)
    raise ConfigError(f"unknown method {method!r}; expected one of {', '.join(METHODS)}", key="mesh.simplify.method")


def _run_meshopt(prep: Prepared, target: int, cfg: SimplifyConfig, lock: np.ndarray, cap: float) -> Raw:
    Fw, w_vertex, w_region, w_uv = wedges(prep)
    Vw = prep.V[w_vertex]
    t = time.perf_counter()
    # with an error ceiling, meshoptimizer stops before its own error estimate passes it
    Fo, err = meshopt.simplify(Vw, Fw, target, lock=lock[w_vertex] if lock.any() else None,
                               target_error=cap if cap > 0 else 1e30, absolute_error=True)
    lib = time.perf_counter() - t
    notes = []
    reg = w_region[Fo]
    mixed = int((reg != reg[:, :1]).any(axis=1).sum())
    if mixed:
        notes.append(f"{mixed} triangle(s) had corners from different regions; the first corner's region was used")
    return Raw(V=prep.V, F=w_vertex[Fo], src_vertex=np.arange(len(prep.V)), region=reg[:, 0], src_tri=None,
               tri_uvs=None if w_uv is None else w_uv[Fo], fixed=np.zeros(len(prep.V), bool), lib_seconds=lib,
               notes=notes, lib_error=float(err))


def _split_regions(prep: Prepared, lock: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
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


def _run_fast(prep: Prepared, target: int, cfg: SimplifyConfig, lock: np.ndarray) -> Raw:
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
    return Raw(V=V2, F=F2, src_vertex=src2, region=region, src_tri=src_tri, tri_uvs=None, fixed=fixed2,
               lib_seconds=t_lib, notes=notes)


def _run_quality(prep: Prepared, target: int, cfg: SimplifyConfig, lock: np.ndarray) -> Raw:
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
    return Raw(V=V2, F=F2, src_vertex=src2, region=prep.region[fq], src_tri=fq, tri_uvs=None, fixed=fixed2,
               lib_seconds=lib, notes=notes)
