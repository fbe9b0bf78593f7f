"""The result handed on (stage.py's docstring, "What stays where it was" and "The record"): the
output's attributes (materials, UVs, face and vertex colours, the layer's backs put back), the
checks of the result against the input, the warnings, the new scene, and the record's accuracy
and details."""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ...record import StageRecord
from ...scene import Scene
from . import defects, measure, repair
from .error import SurfaceIndex, edge_counts, topology, triangle_areas
from .inputs import Prepared, region_edge_vertices
from .ladder import RELAXED_TEXT
from .measure import HausdorffResult
from .parts import part_report
from .state import Ctx, Out

_DEFECT_IDS = 10000
# Without an error_ceiling, a result more than this far off the input (fraction of the diagonal)
# is warned about
_LARGE_ERROR = 0.05


@dataclass
class _Checks:
    """The result against the input: topology, folds, material edges and open borders."""
    topo_in: dict
    topo_out: dict
    folds_out: np.ndarray  # (k, 2) fold pairs of the result
    out_region_edges: np.ndarray  # the result's material/colour edges
    off_boundary: int  # material-edge vertices that are not input material-edge vertices
    moved_boundary: int  # material-edge vertices that moved
    border_off: int  # border vertices that are not input border vertices
    border_moved: int  # border vertices that moved
    new_nm: int  # new non-manifold edges
    new_mis: int  # new mis-oriented edges


def write(scene: Scene, ctx: Ctx, rec: StageRecord, details: dict, *, kind: str, value: float, out: Out,
          h: HausdorffResult | None, refine_log: list[dict], bound_log: dict | None, prep_s: float) -> Scene:
    """The new scene from the result kept; the record's warnings, counts, accuracy and details
    (all but the stage's own seconds) are filled in."""
    notes = list(out.notes)
    parts_rec = _parts_record(ctx, out, h)
    for kind_, what in (("dropped", "no triangle left"), ("collapsed", "error above half the part's own size")):
        if parts_rec[kind_]:
            rec.warn(f"{parts_rec[kind_]} of {ctx.prep.n_parts} part(s) {kind_} ({what}; "
                     f"{parts_rec[kind_ + '_area'] / max(float(ctx.index_a.total_area) / ctx.scale ** 2, 1e-300):.2%} "
                     "of the input's surface); details.parts lists the worst")
    attrs = _attributes(ctx.prep, out, ctx.index_a, notes)
    if ctx.prep.layer.twins:  # the layer's triangles that had a back get it again, reversed
        attrs = _with_backs(ctx.prep, out, attrs, _attributes(ctx.prep.back(), out, ctx.index_a, [], side=1))
    checks = _check(ctx, out)
    T1 = len(attrs["triangles"])
    _warn(rec, ctx, details, checks, notes, kind=kind, value=value, out=out, h=h, T1=T1)
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
    _accuracy(rec, ctx.scale, out, h, checks)
    details.update(_details(ctx, out, h, checks, parts_rec, target_triangles=int(value) if kind == "triangles" else T1,
                            refine_log=refine_log, bound_log=bound_log, prep_s=prep_s))
    return new


def _check(ctx: Ctx, out: Out) -> _Checks:
    prep = ctx.prep
    topo_in = topology(prep.F)
    topo_out = topology(out.F)
    out_edge_mask, out_region_edges = region_edge_vertices(out.F, out.region, len(out.V))
    moved = np.linalg.norm(out.V - prep.V[out.src_vertex], axis=1) > 0
    e_out, c_out, _ = edge_counts(out.F)
    out_border = np.zeros(len(out.V), bool)
    out_border[e_out[c_out == 1].ravel()] = True
    return _Checks(topo_in=topo_in, topo_out=topo_out, folds_out=repair.folds(out.V, out.F),
                   out_region_edges=out_region_edges,
                   off_boundary=int((out_edge_mask & ~ctx.edge_mask[out.src_vertex]).sum()),
                   moved_boundary=int((out_edge_mask & moved).sum()),
                   border_off=int((out_border & ~ctx.border_mask[out.src_vertex]).sum()),
                   border_moved=int((out_border & moved).sum()),
                   new_nm=max(0, topo_out["nonmanifold_edges"] - topo_in["nonmanifold_edges"]),
                   new_mis=max(0, topo_out["misoriented_edges"] - topo_in["misoriented_edges"]))


def _warn(rec: StageRecord, ctx: Ctx, details: dict, checks: _Checks, notes: list[str], *, kind: str, value: float,
          out: Out, h: HausdorffResult | None, T1: int) -> None:
    """What the record warns about the result: a count off the target and why, a large error,
    flipped triangles, folds, new non-manifold or mis-oriented edges, material-edge and border
    vertices off the input's, what was let go, and the notes of the library and the attributes."""
    prep, cfg, cap, scale = ctx.prep, ctx.cfg, ctx.cap, ctx.scale
    topo_in = checks.topo_in
    if kind == "triangles":
        miss = abs(T1 - int(value)) / max(int(value), 1)
        if miss > 0.01 and "backed_off_from" not in details:
            why = []
            if cap > 0:
                why.append(f"error_ceiling = {cfg.error_ceiling} (the library stops before its own error estimate "
                           "passes it)")
            if len(prep.region_material) > 1:
                why.append(f"{len(ctx.region_edges)} material/colour edges are kept")
            if cfg.preserve_border and topo_in["open_edges"]:
                why.append(f"{topo_in['open_edges']} open border edges are kept")
            if prep.tri_uvs is not None and ctx.method == "meshopt":
                why.append("UV seams collapse only along themselves")
            if topo_in["nonmanifold_edges"]:
                why.append(f"{topo_in['nonmanifold_edges']} non-manifold edges")
            rec.warn(f"got {T1} triangles for a target of {int(value)} ({miss:.1%} off): "
                     + ("; ".join(why) if why else "the library stopped (no collapse left that keeps the mesh valid)"))
    if h is not None and cap <= 0 and kind == "triangles" and h.max > _LARGE_ERROR * scale:
        rec.warn(f"the result is {h.max / scale:.2%} of the diagonal off the input (the largest distance between "
                 "them): set mesh.simplify.error_ceiling to stop at more triangles instead")
    if int(out.flipped.sum()):
        rec.warn(f"{int(out.flipped.sum())} triangle(s) face against the original surface")
    if len(checks.folds_out) > len(ctx.folds_in):
        rec.warn(f"{len(checks.folds_out)} fold(s): neighbouring triangles whose normals point against each other "
                 f"(the input has {len(ctx.folds_in)})")
    if checks.new_nm or checks.new_mis:
        rec.warn(f"{checks.new_nm} new non-manifold edge(s), {checks.new_mis} new mis-oriented edge(s)")
    if checks.off_boundary or checks.moved_boundary:
        rec.warn(f"{checks.off_boundary} material-edge vertices are not input material-edge vertices; "
                 f"{checks.moved_boundary} moved")
    if cfg.preserve_border and (checks.border_off or checks.border_moved):
        rec.warn(f"{checks.border_off} border vertices are not input border vertices; {checks.border_moved} moved")
    if prep.relaxed:
        rec.warn(f"to reach {int(value) if kind == 'triangles' else T1} triangles the library was let go of: "
                 + "; ".join(RELAXED_TEXT[r] for r in prep.relaxed))
    for n in notes:
        rec.warn(n)


def _accuracy(rec: StageRecord, scale: float, out: Out, h: HausdorffResult | None, checks: _Checks) -> None:
    """The record's accuracy: the measured error (and its proven bounds), flips, folds and new edges."""
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
    rec.accuracy.update({"flipped_triangles": int(out.flipped.sum()), "folds": int(len(checks.folds_out)),
                         "new_nonmanifold_edges": checks.new_nm, "new_misoriented_edges": checks.new_mis})


def _sample(h: HausdorffResult | None, scale: float) -> dict | None:
    """What the measure's maximum was taken over (details.error_sample)."""
    if h is None or h.a_to_b is None:
        return None
    return {"original_grid_points": int(h.a_to_b.grid_points), "simplified_grid_points": int(h.b_to_a.grid_points),
            "refinement_points": int(h.refine_points),
            "original_spacing": float(h.a_to_b.spacing / scale), "simplified_spacing": float(h.b_to_a.spacing / scale),
            "max_is": ("sampled: the largest exact distance at a point of the sample (the true maximum "
                       "over the surfaces can only be larger)" if h.exact else
                       "an upper bound of the largest distance at a point of the sample") +
            ("; accuracy.hausdorff_bound_* are proven upper bounds of the true maximum (details."
             "error_bound says how they were made)" if np.isfinite(h.a_to_b.bound) else "")}


def _details(ctx: Ctx, out: Out, h: HausdorffResult | None, checks: _Checks, parts_rec: dict, *,
             target_triangles: int, refine_log: list[dict], bound_log: dict | None, prep_s: float) -> dict:
    """The record's details on the result (added to what the phases before wrote there)."""
    prep, cfg, scale = ctx.prep, ctx.cfg, ctx.scale
    sample = _sample(h, scale)
    chord_max, chains_gone = _border_chord_max(prep, out, ctx.chains, scale)
    return {
        "target_triangles": target_triangles,
        "prepare_seconds": round(prep_s, 6),
        **{f"{k}_seconds": round(v, 6) for k, v in ctx.seconds.items()},
        "phase_seconds_are": "totals over every attempt (back-off probes, peak rounds), not only the result kept",
        "measures": int(ctx.measures),
        "flip_repairs": ctx.repair_log,
        "flip_checked_triangles": int(ctx.flip_cache.get("checked", 0)),
        "edges_turned_at_sharp_angles": int(out.edge_turns),
        "fit": out.fit_info,
        "refine": refine_log,
        # the grid points per side measured with: error_samples, fewer on a small input (state.samples_for)
        "error_samples": int(ctx.samples) if sample is not None else 0,
        "error_samples_asked": int(cfg.error_samples),
        "error_sample": sample,
        "error_bound": bound_log,
        "error_metric": "symmetric Hausdorff: a grid on each surface (every vertex, points along every edge and "
                        f"inside every triangle; on the simplified one {measure.POINTS_PER_SIMPLIFIED} per "
                        "triangle where that is more, at most 4 x error_samples; error_samples is what was asked "
                        "or, when fewer, 4 per input triangle and at least 2,000), and then every triangle cut "
                        f"into at least {4 ** measure.CAPPED_MIN_LEVEL} cells), refined "
                        f"{measure.ROUNDS} times around up to "
                        f"{ctx.seeds} of the largest distances at separate places "
                        f"({4 * ctx.seeds} on the original's side), only cells that may hold more than "
                        f"{measure.KEEP_SHARE:.0%} of the largest exact distance so far (a convexity bound), "
                        "the largest made exact at their points (bake/mesh/simplify/measure.py); a sampled "
                        "maximum; fractions of the bbox diagonal",
        "hausdorff_max_exact": False if h is not None else None,
        "worst_point": None if h is None else [float(x) for x in h.worst_point],
        "worst_point_original_to_simplified": None if h is None or h.a_to_b is None else
        [float(x) for x in h.a_to_b.worst],
        "worst_point_simplified_to_original": None if h is None or h.b_to_a is None else
        [float(x) for x in h.b_to_a.worst],
        "topology_in": checks.topo_in, "topology_out": checks.topo_out,
        "folds_in": int(len(ctx.folds_in)), "folds_out": int(len(checks.folds_out)),
        "fold_pairs": [[int(a), int(b)] for a, b in checks.folds_out[:20]],
        # the output triangles (numbers in the stage's output) of each kind of defect, at most
        # _DEFECT_IDS of each: the report's previews and the benchmark's picture cost read them
        "defect_triangles": {k: np.flatnonzero(m)[:_DEFECT_IDS].tolist() for k, m in (
            ("flipped", out.flipped), ("on_new_nonmanifold_edges", out.new_nonmanifold),
            ("folded", out.folded if out.folded is not None else np.zeros(len(out.F), bool)))},
        "material_edges_in": int(len(ctx.region_edges)), "material_edges_out": int(len(checks.out_region_edges)),
        "material_edge_vertices_off_input_edges": checks.off_boundary,
        "material_edge_vertices_moved": checks.moved_boundary,
        "border_vertices_off_input_border": checks.border_off,
        "border_vertices_moved": checks.border_moved,
        "parts": parts_rec,
        "defects": defects.record(cfg, out, parts_rec, checks.new_nm, len(checks.folds_out) - len(ctx.folds_in)),
        "border_locks": ctx.border_log,
        "relaxed": list(prep.relaxed),
        "relaxations": ctx.relax_log,
        "border_chord_max": chord_max,
        "border_chains_closed": chains_gone,
        "attributes": _attribute_notes(prep, ctx.method),
        "polygons": "dropped: every output triangle has tri_polygon = -1",
    }


def _parts_record(ctx: Ctx, out: Out, h: HausdorffResult | None) -> dict:
    """parts.part_report for a result: each output triangle belongs to the part of its
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


def _with_backs(prep: Prepared, out: Out, front: dict, back: dict) -> dict:
    """The output's triangles with the backs of the layer put back (parts.py): every
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


def _attributes(prep: Prepared, out: Out, index_a: SurfaceIndex | None, notes: list[str], side: int = 0) -> dict:
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


def _border_chord_max(prep: Prepared, out: Out, chains: list, scale: float) -> tuple[float, int]:
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


def _attribute_notes(prep: Prepared, method: str) -> dict:
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
