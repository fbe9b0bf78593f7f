"""The export stage's lists: the scene as Scratch lists.

Mesh lists follow the book's "Mesh data in Scratch" tables (see docs/formats.md):

=============  ======  ===============================================================
list           stride  items
=============  ======  ===============================================================
verts          3       x, y, z of each vertex
tris           4       v1, v2, v3 (1-based into verts), material (1-based into mat colors)
mat colors     1       Scratch colour number of each material
mat two-sided  1       1 if material m is two-sided, else 0 (when one is, or with a BSP tree)
tri colors     1       colour number of each triangle (baked light, or material colour)
vert colors    1       colour number of each vertex
tri uvs        6       u1, v1, u2, v2, u3, v3 of each triangle (v up, 0..1 over the image)
quads          5       v1..v4, material (with ``export.faces = "quads"``)
ngons          n + 2   n, material, v1..vn, repeated (with ``export.faces = "ngons"``)
=============  ======  ===============================================================

Lists that other stages added to ``scene.lists`` (BSP, BVH, ...) follow the mesh lists.
The lists as Scratch holds them; the stage (``bake.export.stage``) turns them into files.
"""

from __future__ import annotations

from dataclasses import dataclass
import re

import numpy as np

from ..config import ExportConfig
from ..record import StageRecord
from ..scene import ScratchList, Scene
from ..scratch.colors import scratch_numbers
from ..scratch.numbers import decimals_for, position_decimals, round_positions
from ..scratch.layout import placeholder, split

# An item with one of these is split by Scratch's import of a .txt file (scratch-gui
# src/lib/import-csv.js: a .txt whose first, middle and last lines split into the same number of
# fields at a comma or tab asks for a column and keeps only it). A .csv goes through a CSV parser
# (papaparse) instead, which keeps a quoted field whole.
_SPLIT_BY_IMPORT = re.compile(r'[,\t"\r\n]')


def list_file_name(name: str, items: list[str] | None = None) -> str:
    """A safe file name for a list (Scratch ignores the file name on import): ``lists/<name>.txt``,
    or ``.csv`` when an item would be split by the .txt import (TextImage strings)."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "list"
    # (one search over the items joined by a character the pattern does not match: one item has such a
    # character exactly when the joined text has one)
    csv = items is not None and _SPLIT_BY_IMPORT.search("\x00".join(items)) is not None
    return f"lists/{safe}{'.csv' if csv else '.txt'}"


def list_file_bytes(fname: str, items: list[str]) -> bytes:
    """One item per line, no trailing newline (scratch.md 3); in a .csv every item is one quoted
    field (RFC 4180: quotes doubled), so the import reads one column and unquotes it."""
    if fname.endswith(".csv"):
        return "\n".join('"' + it.replace('"', '""') + '"' for it in items).encode("utf-8")
    return "\n".join(items).encode("utf-8")


def _colour_list(rgba: np.ndarray, mode: str):
    vals = scratch_numbers(rgba, mode)
    if mode == "hex":
        return vals, "string"
    return np.asarray(vals, dtype=np.int64), "int"


def _whole_polygons(scene: Scene, size: int) -> tuple[np.ndarray, np.ndarray]:
    """Polygons of ``size`` vertices all of whose triangles survive, and a triangle mask of
    the triangles they cover."""
    T = scene.n_triangles
    if scene.tri_polygon is None or scene.poly_sizes is None or T == 0:
        return np.zeros(0, np.int64), np.zeros(T, bool)
    tp = scene.tri_polygon
    valid = tp >= 0
    per_poly = np.bincount(tp[valid], minlength=scene.n_polygons)
    sizes = scene.poly_sizes
    whole = (per_poly == sizes - 2) & (sizes >= 3)
    sel = whole & (sizes == size) if size > 0 else whole & (sizes > 4)
    polys = np.flatnonzero(sel)
    covered = np.zeros(T, bool)
    covered[valid] = sel[tp[valid]]
    return polys, covered


@dataclass
class ListChoice:
    """Whether an optional list is written, and why (``report.md`` shows the lists left out)."""

    name: str  # the list's name
    key: str  # the config key that decides it
    write: bool
    available: bool  # the scene has the data (a list left out of nothing is not reported)
    reason: str


def textures_in_project(scene: Scene) -> bool:
    """Whether the bake puts a texture into the project (a costume or a texture list) that an
    engine can sample with ``tri uvs``."""
    out = scene.artefacts.texture_outputs or {}
    return bool(scene.artefacts.costumes) or bool(out.get("lists"))


def choose_lists(scene: Scene, cfg: ExportConfig) -> dict[str, ListChoice]:
    """The optional per-triangle and per-vertex lists: ``"yes"`` writes one (zeros or white
    where the scene has no data), ``"no"`` leaves it out, ``"auto"`` writes what the reader sprite
    or an engine built on the documented lists reads and leaves out what nothing would read:

    * ``tri colors``: when the scene has per-triangle colours (baked light, texture means);
    * ``vert colors``: when the scene has per-vertex colours and no per-triangle colours (a lit
      bake has both: the reader draws ``tri colors``, so the per-vertex copy of the same light
      is left out unless asked for);
    * ``tri uvs``: when a texture goes into the project (textures stage: a costume or a texture
      list) for an engine to sample;
    * ``lightmap uvs``: when the scene has a lightmap atlas.

    * ``mat two-sided``: when a material is two-sided, or with a BSP tree (its walk culls the
      single-sided triangles that face away, so an engine needs to know which are which).

    Other stages' documented lists (BSP, BVH, texture lists, ...) are chosen by their stages.
    (A list given an array of names is keyed by its placeholder name: :func:`placeholder`.)"""
    n = _Names(cfg.names)
    has_fc = scene.face_colors is not None
    has_vc = scene.vertex_colors is not None
    textured = any(m.texture is not None or m.texture_data is not None for m in scene.materials)
    has_uv = textured and scene.tri_uvs is not None
    has_lm = scene.tri_lightmap_uvs is not None
    tex = textures_in_project(scene)
    two = any(bool(m.double_sided) for m in scene.materials)

    def pick(name: str, key: str, setting: str, available: bool, auto: bool, why_not: str) -> ListChoice:
        if setting == "yes":
            return ListChoice(name, key, True, available, f"{key} = \"yes\"")
        if setting == "no":
            return ListChoice(name, key, False, available, f"{key} = \"no\"")
        return ListChoice(name, key, auto, available, "written: read by the reader or an engine" if auto else why_not)

    return {c.name: c for c in (
        pick(n.triangle_colors, "export.triangle_colors", cfg.triangle_colors, has_fc, has_fc,
             "the scene has no per-triangle colours"),
        pick(n.vertex_colors, "export.vertex_colors", cfg.vertex_colors, has_vc, has_vc and not has_fc,
             f"'{n.triangle_colors}' carries the same colours per triangle, which the reader draws; "
             "set export.vertex_colors = \"yes\" for an engine that shades per vertex"
             if has_vc else "the scene has no per-vertex colours"),
        pick(n.uvs, "export.uvs", cfg.uvs, has_uv, has_uv and tex,
             ("no texture goes into the project (textures.encodings writes none), so nothing would sample the "
              "UVs; add \"list\", \"textimage\" or \"costume\" to textures.encodings, or set export.uvs = \"yes\""
              if scene.artefacts.textures is not None else
              "no texture goes into the project (textures.enabled = false), so nothing would sample the UVs; set "
              "textures.enabled = true to bake the texture, or export.uvs = \"yes\"")
             if has_uv else "the scene has no textured triangles with UVs"),
        pick(n.lightmap_uvs, "export.lightmap_uvs", cfg.lightmap_uvs, has_lm, has_lm, "the scene has no lightmap"),
        pick(n.two_sided, "export.two_sided", cfg.two_sided, two, two or scene.artefacts.bsp is not None,
             "every material is single-sided and there is no BSP tree"),
    )}


class _Names:
    """``export.names`` with each array of names as one placeholder name (``layout.split`` gives
    the parts their names)."""

    def __init__(self, names) -> None:
        self._names = names

    def __getattr__(self, key: str) -> str:
        return placeholder(getattr(self._names, key))


def _based(ib: int) -> str:
    return "" if ib == 1 else f" ({ib}-based)"


def first_use_order(seq: np.ndarray, n: int) -> np.ndarray:
    """Vertex numbers ``0..n-1`` in the order ``seq`` first uses them, unused ones after in their
    own order: ``order[new] = old``."""
    seq = np.asarray(seq, np.int64)
    first = np.full(n, len(seq), np.int64)
    if len(seq):
        np.minimum.at(first, seq, np.arange(len(seq)))
    return np.lexsort((np.arange(n), first))


def mesh_lists(scene: Scene, cfg: ExportConfig, record: StageRecord) -> list[ScratchList]:
    """The mesh lists in the layout the config asks for (``bake.scratch.layout``)."""
    out = _book_lists(scene, cfg, record)
    if any(not isinstance(v, str) for v in vars(cfg.names).values()):
        out = split(out, cfg.names, cfg.faces, cfg.index_base)
    return out


def _book_lists(scene: Scene, cfg: ExportConfig, record: StageRecord) -> list[ScratchList]:
    """The mesh lists, each as one list (an array of names is joined to a placeholder name until
    ``split`` takes it apart), numbered from ``export.index_base``."""
    n = _Names(cfg.names)
    ib = cfg.index_base
    soup = cfg.faces == "soup"
    out: list[ScratchList] = []
    # the grid the pipeline fixed on the scene (the BSP built on it); a scene run through this
    # stage alone gets it from export.precision
    diag = scene.scale()
    dec = scene.position_decimals
    if dec is None:
        dec = position_decimals(diag, cfg.precision)
    T = scene.n_triangles
    tris = scene.triangles if scene.triangles is not None else np.zeros((0, 3), np.int64)
    mats = scene.tri_material if scene.tri_material is not None else np.zeros(0, np.int64)
    _warn_collapsed(scene, tris, dec, record)

    keep_mask = np.ones(T, bool)
    quad_idx = np.zeros((0, 4), np.int64)  # 0-based corners of whole quads
    quad_mat = np.zeros(0, np.int64)
    ngon_sizes = np.zeros(0, np.int64)
    ngon_corners = np.zeros(0, np.int64)  # 0-based corners of whole n-gons, one after another
    ngon_mat = np.zeros(0, np.int64)
    choice = choose_lists(scene, cfg)
    # lists that hold one entry per written triangle (or number the scene's triangles): a quad or
    # n-gon written whole would leave its triangles without them
    per_tri = [f"'{c.name}'" for c in (choice[n.triangle_colors], choice[n.uvs], choice[n.lightmap_uvs]) if c.write]
    if scene.artefacts.bvh is not None:
        per_tri.append("the BVH's triangle numbers")
    whole_faces = cfg.faces in ("quads", "ngons") and scene.artefacts.bsp is None and not per_tri
    if cfg.faces in ("quads", "ngons"):
        if scene.artefacts.bsp is not None:
            record.warn(f"export.faces = '{cfg.faces}' ignored: the BSP stage orders triangles, "
                        "so every face is written to the triangle list")
        elif per_tri:
            record.warn(f"export.faces = '{cfg.faces}' ignored: {', '.join(per_tri)} "
                        f"{'go' if len(per_tri) > 1 else 'goes'} per triangle, so every face is written to the "
                        "triangle list")
        else:
            off = scene.poly_offsets
            quads, covered4 = _whole_polygons(scene, 4)
            keep_mask &= ~covered4
            if len(quads):
                quad_idx = scene.poly_indices[off[quads][:, None] + np.arange(4)]
                quad_mat = scene.poly_material[quads]
            if cfg.faces == "ngons":
                ngons, coveredn = _whole_polygons(scene, 0)
                keep_mask &= ~coveredn
                ngon_sizes = scene.poly_sizes[ngons]
                ngon_mat = scene.poly_material[ngons]
                if len(ngons):
                    rep = np.repeat(np.arange(len(ngons)), ngon_sizes)
                    within = np.arange(int(ngon_sizes.sum())) - np.repeat(np.cumsum(ngon_sizes) - ngon_sizes,
                                                                          ngon_sizes)
                    ngon_corners = scene.poly_indices[off[ngons][rep] + within]
            record.details["faces"] = {"quads": int(len(quad_idx)), "ngons": int(len(ngon_sizes)),
                                       "triangles": int(keep_mask.sum())}

    # vertex numbers: in the order the written faces first use them (a list order engines do not
    # care about, which makes the index lists pack to a symbol or two per corner), or the scene's
    V = scene.n_vertices
    new_of = np.arange(V)
    if cfg.vertex_order == "first-use" and V:
        seq = np.concatenate([tris[keep_mask].ravel(), quad_idx.ravel(), ngon_corners]).astype(np.int64)
        order = first_use_order(seq, V)
        new_of = np.empty(V, np.int64)
        new_of[order] = np.arange(V)
    else:
        order = np.arange(V)
    record.details["vertex_order"] = cfg.vertex_order

    if cfg.vertices and soup:  # each triangle's corners, in the written triangles' order
        out.append(ScratchList(n.vertices, scene.positions[tris[keep_mask]].ravel(), 9,
                               "x1, y1, z1, x2, y2, z2, x3, y3, z3 per triangle", "number", dec, role="vertices"))
    elif cfg.vertices:
        out.append(ScratchList(n.vertices, scene.positions[order].ravel(), 3, "x, y, z per vertex", "number", dec,
                               role="vertices"))
    if cfg.vertices:
        if V:  # rounding to `dec` decimals moves a coordinate by at most half a step
            record.accuracy["position_error"] = 0.5 * 10.0 ** -dec / diag if diag > 0 else 0.0
            record.details["positions"] = {"decimals": dec, "step": 10.0 ** -dec, "max_error": 0.5 * 10.0 ** -dec,
                                           "max_error_of_diagonal": record.accuracy["position_error"]}

    poly_lists: list[ScratchList] = []
    if whole_faces:
        q = np.concatenate([new_of[quad_idx] + ib, quad_mat[:, None] + ib], axis=1) if len(quad_idx) else \
            np.zeros((0, 5), np.int64)
        poly_lists.append(ScratchList(n.quads, q.ravel(), 5, "v1, v2, v3, v4, material per quad" + _based(ib), "int",
                                      role="quads"))
        if cfg.faces == "ngons":
            # record layout: n, material, v1..vn
            starts = np.zeros(len(ngon_sizes) + 1, np.int64)
            np.cumsum(ngon_sizes + 2, out=starts[1:])
            flat = np.zeros(int(starts[-1]), np.int64)
            flat[starts[:-1]] = ngon_sizes
            flat[starts[:-1] + 1] = ngon_mat + ib
            if len(ngon_sizes):
                rep = np.repeat(np.arange(len(ngon_sizes)), ngon_sizes)
                within = np.arange(int(ngon_sizes.sum())) - np.repeat(np.cumsum(ngon_sizes) - ngon_sizes, ngon_sizes)
                flat[starts[:-1][rep] + 2 + within] = new_of[ngon_corners] + ib
            poly_lists.append(ScratchList(n.ngons, flat, 0, "n, material, v1..vn per polygon" + _based(ib), "int",
                                          role="ngons"))

    if cfg.triangles and soup:
        out.append(ScratchList(n.triangles, mats[keep_mask] + ib, 1, f"material ({ib}-based) per triangle", "int",
                               role="triangles"))
    elif cfg.triangles:
        t = np.concatenate([new_of[tris[keep_mask]].reshape(-1, 3) + ib, mats[keep_mask][:, None] + ib], axis=1)
        out.append(ScratchList(n.triangles, t.ravel(), 4, f"v1, v2, v3 ({ib}-based), material ({ib}-based)", "int",
                               role="triangles"))
    out.extend(poly_lists)

    if cfg.materials:
        mc = np.array([m.color for m in scene.materials], dtype=np.float64).reshape(-1, 4)
        vals, kind = _colour_list(mc, cfg.color_format)
        out.append(ScratchList(n.materials, vals, 1, "colour number per material", kind))

    if choice[n.two_sided].write:
        two = np.array([bool(m.double_sided) for m in scene.materials], dtype=bool)
        out.append(ScratchList(n.two_sided, two.astype(np.int64), 1,
                               "1 if the material is two-sided (drawn from both sides), 0 if single-sided", "int"))

    if choice[n.triangle_colors].write:
        fc = scene.face_colors if scene.face_colors is not None else scene.triangle_albedo()
        vals, kind = _colour_list(fc[keep_mask], cfg.color_format)
        out.append(ScratchList(n.triangle_colors, vals, 1, "colour number per triangle", kind))

    if choice[n.vertex_colors].write:
        vc = scene.vertex_colors if scene.vertex_colors is not None else np.ones((scene.n_vertices, 4))
        if soup:  # per corner, as the positions are
            vals, kind = _colour_list(vc[tris[keep_mask]].reshape(-1, 4), cfg.color_format)
            out.append(ScratchList(n.vertex_colors, vals, 1, "colour number per corner", kind, role="vertex_colors"))
        else:
            vals, kind = _colour_list(vc[order], cfg.color_format)
            out.append(ScratchList(n.vertex_colors, vals, 1, "colour number per vertex", kind, role="vertex_colors"))

    if choice[n.uvs].write:
        uv = scene.tri_uvs if scene.tri_uvs is not None else np.zeros((T, 3, 2))
        out.append(ScratchList(n.uvs, uv[keep_mask].ravel(), 6, "u1, v1, u2, v2, u3, v3 per triangle", "number", 4,
                               role="uvs"))

    if choice[n.lightmap_uvs].write:
        lm = scene.tri_lightmap_uvs if scene.tri_lightmap_uvs is not None else np.zeros((T, 3, 2))
        img = scene.artefacts.lightmap_image
        side = max(img.shape[:2]) if img is not None else 4096
        out.append(ScratchList(n.lightmap_uvs, lm[keep_mask].ravel(), 6,
                               "lightmap u1, v1, u2, v2, u3, v3 per triangle (v up)", "number",
                               decimals_for(0.1 / side), role="lightmap_uvs"))  # a tenth of a texel
    for c in choice.values():
        if not c.write and c.available:  # data the scene has that the bake leaves out: say why
            record.effects.append({"name": f"list '{c.name}'", "ran": False, "reason": c.reason, "key": c.key})
    record.details["lists_left_out"] = [{"list": c.name, "key": c.key, "reason": c.reason}
                                        for c in choice.values() if not c.write and c.available]
    return out


def index_columns(lst: ScratchList, cfg: ExportConfig) -> tuple[int, ...]:
    """Columns of a list holding 1-based vertex numbers in first-use order (packed as index
    codes): the book's triangle and quad records."""
    if cfg.vertex_order != "first-use" or cfg.index_base != 1:
        return ()
    return {("triangles", 4): (0, 1, 2), ("quads", 5): (0, 1, 2, 3)}.get((lst.role, lst.stride), ())


def pack_lists(lists: list[ScratchList], values: dict[str, list], info: dict[str, dict], cfg: ExportConfig,
               rec: StageRecord) -> dict:
    """The lists to store packed (name -> :class:`bake.scratch.pack.Packed`, in list order): each
    numeric list whose packed text is smaller than its plain items, within ``pack_max_items``.
    Every packed text is decoded again here and must give the plain items back exactly."""
    from ..errors import StageError
    from ..scratch.loader import decode_cost, total_cost
    from ..scratch.pack import pack, packed_bytes, unpack

    out: dict = {}
    costs: dict = {}
    rows: list[dict] = []
    for lst in lists:
        name = lst.name
        n_items = info[name]["items"]
        plain = info[name]["project_json_bytes"]
        why = None
        if lst.kind == "string":
            why = "text items (not packed)"
        elif n_items == 0:
            why = "empty"
        elif cfg.pack_max_items and n_items > cfg.pack_max_items:
            why = (f"{n_items:,} items is more than export.pack_max_items = {cfg.pack_max_items:,} (vanilla Scratch's "
                   "`add to list` stops at 200,000; set 0 for TurboWarp)")
        pk = None
        if why is None:
            pk = pack(name, values[name], lst.pack_stride or lst.stride, prefix=lst.pack_prefix,
                      index_columns=index_columns(lst, cfg))
            if pk is None:
                why = "values are not decimals below 2^53 (not packed)"
        if pk is not None:
            size = packed_bytes(name, pk.text)
            if size >= plain:
                why = f"packing would not save bytes ({size} >= {plain})"
            else:
                u = unpack(pk.text, name)
                if u.items != values[name] or len(u.items) != len(values[name]):
                    raise StageError(f"list '{name}': the packed text does not decode to the list (a bug)")
                info[name].update({"plain_bytes": plain, "project_json_bytes": size,
                                   "packed": {"chars": pk.chars, "bytes": size, "columns": pk.describe()}})
                out[name] = pk
                costs[name] = u.cost
                rows.append({"list": name, "items": n_items, "plain_bytes": plain, "packed_bytes": size,
                             "ratio": round(size / plain, 4), "columns": pk.describe()})
                continue
        rec.effects.append({"name": f"pack '{name}'", "ran": False, "reason": why})
    for row in rows:  # blocks the loader runs for each list, as scratch-vm counts them
        row["decode_blocks"] = decode_cost(costs[row["list"]], len(rows))
        info[row["list"]]["packed"]["decode_blocks"] = row["decode_blocks"]
    if out:
        total_plain = sum(r["plain_bytes"] for r in rows)
        total = sum(r["packed_bytes"] for r in rows)
        rec.details["pack"] = {"lists": rows, "plain_bytes": total_plain, "packed_bytes": total,
                               "decode_blocks": total_cost([costs[r["list"]] for r in rows]),
                               "list": cfg.names.packed}
        rec.effects.append({"name": "pack", "ran": True,
                            "reason": f"{len(out)} lists packed: {total_plain:,} -> {total:,} bytes in project.json; "
                                      f"the loader rebuilds them at the green flag "
                                      f"({rec.details['pack']['decode_blocks']:,} blocks in scratch-vm)"})
    return out


def _warn_collapsed(scene: Scene, tris: np.ndarray, dec: int, record: StageRecord) -> None:
    """Triangles whose written (rounded) corners are collinear: a filler that strokes edges
    draws them as lines. Counted in the record and named in a warning."""
    if len(tris) == 0:
        return
    p = round_positions(scene.positions, dec)[tris]
    flat = ~np.any(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) != 0, axis=1)
    n = int(flat.sum())
    record.details["collinear_triangles"] = n
    if n:
        first = ", ".join(str(int(t) + 1) for t in np.flatnonzero(flat)[:6])
        record.warn(f"{n} triangle(s) have zero area at the written positions (rounded to {10.0 ** -dec:g}): "
                    f"tris {first}{', ...' if n > 6 else ''}; a pen filler that strokes edges draws them "
                    "as lines (raise export.precision, or bake with bsp, which drops them)")
