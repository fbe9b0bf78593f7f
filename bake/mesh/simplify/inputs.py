"""The stage's input as the libraries take it: one layer of the scene's triangles (a two-sided
surface written twice is simplified once; parts.fold_layer), its regions (triangles that share
material, face colour and back), its parts, and the wedges meshoptimizer is handed (one vertex
per position + region + UV)."""

from __future__ import annotations

from dataclasses import dataclass, field, replace

import numpy as np

from ...config import SimplifyConfig
from ...scene import Scene
from .error import edge_counts
from .parts import Layer, fold_layer, parts

# Face colours with more distinct values than this are a colour signal, not flat regions.
MAX_COLOR_REGIONS = 1024


@dataclass
class Prepared:
    """The stage's input: one layer of the scene's triangles (parts.fold_layer: a two-sided
    surface written twice is simplified once), with its regions and parts."""
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
    part: np.ndarray  # (T,) parts.parts
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
    # what the stage let go to reach a triangle target the library stopped short of (ladder.run_to)
    relaxed: list = field(default_factory=list)
    wedges: tuple | None = None  # wedges(), once (again after a relaxation)

    def back(self) -> "Prepared":
        """The same layer with the backs' materials and face colours as its own (for
        outcome's attributes, whose ``side = 1`` takes the back UVs: the last two of tri_uvs' four)."""
        return replace(self, tri_material=self.back_material, region_material=self.region_back_material,
                       face_colors=self.back_colors, region_color=self.region_back_color)


def prepare(scene: Scene, cfg: SimplifyConfig) -> Prepared:
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
    return Prepared(V=np.asarray(scene.positions, np.float64), F=F, region=region,
                    region_material=mat[first] if T else np.zeros(1, np.int64),
                    region_color=fc[first] if colors_as_regions else None,
                    colors_as_regions=colors_as_regions, tri_material=mat, tri_uvs=uvs, face_colors=fc,
                    vertex_colors=None if scene.vertex_colors is None else np.asarray(scene.vertex_colors),
                    layer=layer, part=part, n_parts=n_parts, parts_shared=shared, textured=textured,
                    materials_as_regions=bool(cfg.preserve_materials), back_material=bmat, back_colors=bfc,
                    region_back=has_back[first] if T else np.zeros(1, bool),
                    region_back_material=bmat[first] if T else np.zeros(1, np.int64),
                    region_back_color=bfc[first] if colors_as_regions else None)


def region_edge_vertices(F: np.ndarray, region: np.ndarray, n_vertices: int) -> tuple[np.ndarray, np.ndarray]:
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


def nonmanifold_vertices(F: np.ndarray, n_vertices: int) -> np.ndarray:
    edges, cnt, _ = edge_counts(F)
    mask = np.zeros(n_vertices, bool)
    mask[edges[cnt > 2].ravel()] = True
    return mask


def wedges(prep: Prepared) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
    """Wedge ids per corner (T, 3), wedge -> vertex, wedge -> region, wedge -> UV (computed
    once per input)."""
    if prep.wedges is None:
        prep.wedges = _make_wedges(prep)
    return prep.wedges


def _make_wedges(prep: Prepared) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray | None]:
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
