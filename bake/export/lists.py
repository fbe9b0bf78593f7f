"""The export stage: the scene as Scratch lists (list files and one JSON file).

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
The stage writes nothing to disk: it returns the file contents in the artefact ``outputs``
(relative path -> bytes), which the writer puts in place atomically.
"""

from __future__ import annotations

import dataclasses
import json
import re
import time

import numpy as np

from ..config import ExportConfig
from ..errors import ConfigError
from ..record import StageRecord
from ..scene import ScratchList, Scene
from ..scratch.colors import scratch_numbers
from ..scratch.numbers import (decimals_for, format_numbers, json_array, position_decimals, project_json_bytes,
                               render_items, round_positions)

# An item with one of these is split by Scratch's import of a .txt file (scratch-gui
# src/lib/import-csv.js: a .txt whose first, middle and last lines split into the same number of
# fields at a comma or tab asks for a column and keeps only it). A .csv goes through a CSV parser
# (papaparse) instead, which keeps a quoted field whole.
_SPLIT_BY_IMPORT = re.compile(r'[,\t"\r\n]')


def list_file_name(name: str, items: list[str] | None = None) -> str:
    """A safe file name for a list (Scratch ignores the file name on import): ``lists/<name>.txt``,
    or ``.csv`` when an item would be split by the .txt import (TextImage strings)."""
    safe = re.sub(r"[^A-Za-z0-9._-]+", "_", name).strip("._") or "list"
    csv = items is not None and any(_SPLIT_BY_IMPORT.search(it) for it in items)
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


def mesh_lists(scene: Scene, cfg: ExportConfig, record: StageRecord) -> list[ScratchList]:
    n = cfg.names
    out: list[ScratchList] = []
    # the grid the pipeline fixed on the scene (the BSP built on it); a scene run through this
    # stage alone gets it from export.precision
    dec = scene.position_decimals
    if dec is None:
        dec = position_decimals(scene.scale(), cfg.precision)
    T = scene.n_triangles
    tris = scene.triangles if scene.triangles is not None else np.zeros((0, 3), np.int64)
    mats = scene.tri_material if scene.tri_material is not None else np.zeros(0, np.int64)
    _warn_collapsed(scene, tris, dec, record)

    if cfg.vertices:
        out.append(ScratchList(n.vertices, scene.positions.ravel(), 3, "x, y, z per vertex", "number", dec))

    keep_mask = np.ones(T, bool)
    poly_lists: list[ScratchList] = []
    if cfg.faces != "triangles":
        if "bsp" in scene.artefacts:
            record.warn(f"export.faces = '{cfg.faces}' ignored: the BSP stage orders triangles, "
                        "so every face is written to the triangle list")
        else:
            off = scene.poly_offsets
            quads, covered4 = _whole_polygons(scene, 4)
            keep_mask &= ~covered4
            if len(quads):
                idx = scene.poly_indices[off[quads][:, None] + np.arange(4)] + 1
                q = np.concatenate([idx, scene.poly_material[quads][:, None] + 1], axis=1)
                poly_lists.append(ScratchList(n.quads, q.ravel(), 5, "v1, v2, v3, v4, material per quad", "int"))
            else:
                poly_lists.append(ScratchList(n.quads, np.zeros(0, np.int64), 5, "v1..v4, material per quad", "int"))
            if cfg.faces == "ngons":
                ngons, coveredn = _whole_polygons(scene, 0)
                keep_mask &= ~coveredn
                sizes = scene.poly_sizes[ngons]
                # record layout: n, material, v1..vn
                rec_len = sizes + 2
                starts = np.zeros(len(ngons) + 1, np.int64)
                np.cumsum(rec_len, out=starts[1:])
                flat = np.zeros(int(starts[-1]), np.int64)
                flat[starts[:-1]] = sizes
                flat[starts[:-1] + 1] = scene.poly_material[ngons] + 1
                if len(ngons):
                    rep = np.repeat(np.arange(len(ngons)), sizes)
                    within = np.arange(int(sizes.sum())) - np.repeat(np.cumsum(sizes) - sizes, sizes)
                    flat[starts[:-1][rep] + 2 + within] = scene.poly_indices[off[ngons][rep] + within] + 1
                poly_lists.append(ScratchList(n.ngons, flat, 0, "n, material, v1..vn per polygon", "int"))
            record.details["faces"] = {"quads": int(len(quads)),
                                       "ngons": int(len(_whole_polygons(scene, 0)[0])) if cfg.faces == "ngons" else 0,
                                       "triangles": int(keep_mask.sum())}

    if cfg.triangles:
        t = np.concatenate([tris[keep_mask] + 1, mats[keep_mask][:, None] + 1], axis=1)
        out.append(ScratchList(n.triangles, t.ravel(), 4, "v1, v2, v3 (1-based), material (1-based)", "int"))
    out.extend(poly_lists)

    if cfg.materials:
        mc = np.array([m.color for m in scene.materials], dtype=np.float64).reshape(-1, 4)
        vals, kind = _colour_list(mc, cfg.color_format)
        out.append(ScratchList(n.materials, vals, 1, "colour number per material", kind))

    two = np.array([bool(m.double_sided) for m in scene.materials], dtype=bool)
    if cfg.two_sided == "yes" or (cfg.two_sided == "auto" and (two.any() or "bsp" in scene.artefacts)):
        out.append(ScratchList(n.two_sided, two.astype(np.int64), 1,
                               "1 if the material is two-sided (drawn from both sides), 0 if single-sided", "int"))

    want_tri = cfg.triangle_colors == "yes" or (cfg.triangle_colors == "auto" and scene.face_colors is not None)
    if want_tri:
        fc = scene.face_colors if scene.face_colors is not None else scene.triangle_albedo()
        vals, kind = _colour_list(fc[keep_mask], cfg.color_format)
        out.append(ScratchList(n.triangle_colors, vals, 1, "colour number per triangle", kind))

    want_vc = cfg.vertex_colors == "yes" or (cfg.vertex_colors == "auto" and scene.vertex_colors is not None)
    if want_vc:
        vc = scene.vertex_colors if scene.vertex_colors is not None else np.ones((scene.n_vertices, 4))
        vals, kind = _colour_list(vc, cfg.color_format)
        out.append(ScratchList(n.vertex_colors, vals, 1, "colour number per vertex", kind))

    textured = any(m.texture is not None or m.texture_data is not None for m in scene.materials)
    want_uv = cfg.uvs == "yes" or (cfg.uvs == "auto" and textured and scene.tri_uvs is not None)
    if want_uv:
        uv = scene.tri_uvs if scene.tri_uvs is not None else np.zeros((T, 3, 2))
        out.append(ScratchList(n.uvs, uv[keep_mask].ravel(), 6, "u1, v1, u2, v2, u3, v3 per triangle", "number", 4))

    want_lm = cfg.lightmap_uvs == "yes" or (cfg.lightmap_uvs == "auto" and scene.tri_lightmap_uvs is not None)
    if want_lm:
        lm = scene.tri_lightmap_uvs if scene.tri_lightmap_uvs is not None else np.zeros((T, 3, 2))
        img = scene.artefacts.get("lightmap_image")
        side = max(img.shape[:2]) if img is not None else 4096
        out.append(ScratchList(n.lightmap_uvs, lm[keep_mask].ravel(), 6,
                               "lightmap u1, v1, u2, v2, u3, v3 per triangle (v up)", "number",
                               decimals_for(0.1 / side)))  # a tenth of a texel
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


def stage(scene: Scene, cfg: ExportConfig) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord("export")
    lists = mesh_lists(scene, cfg, rec)
    names = {lst.name for lst in lists}
    for lst in scene.lists.values():
        if lst.name in names:
            raise ConfigError(f"list name '{lst.name}' is used twice (a mesh list and a {lst.doc or 'stage'} list); "
                              "rename one under [export.names]", key="export.names")
        lists.append(lst)
        names.add(lst.name)

    files: dict[str, bytes] = {}
    info: dict[str, dict] = {}
    arrays: dict[str, str] = {}
    used_files: dict[str, str] = {}
    for lst in lists:
        items = render_items(lst)
        arr = json_array(items, "string" if lst.kind == "string" else "number")
        arrays[lst.name] = arr
        fname = list_file_name(lst.name, items)
        stem = fname.rsplit(".", 1)[0]
        if stem in used_files:
            raise ConfigError(f"lists '{used_files[stem]}' and '{lst.name}' map to the same file {stem}.*",
                              key="export.names")
        used_files[stem] = lst.name
        if cfg.txt:
            files[fname] = list_file_bytes(fname, items)
        info[lst.name] = {"items": len(items), "stride": lst.stride, "doc": lst.doc,
                          "project_json_bytes": project_json_bytes(lst.name, arr),
                          "file": fname if cfg.txt else None}
    if cfg.json:
        body = ",".join(f"{json.dumps(k, ensure_ascii=False)}:{v}" for k, v in arrays.items())
        meta = json.dumps({k: {"stride": v["stride"], "doc": v["doc"]} for k, v in info.items()},
                          ensure_ascii=False, separators=(",", ":"))
        files[cfg.json_name] = ('{"format":"scratch-bake lists","version":1,"lists":{' + body +
                                '},"info":' + meta + "}").encode("utf-8")

    name = scene.source.path.stem if scene.source.path else "model"
    extra_read: list = []
    if cfg.sb3 or cfg.sprite3 or cfg.into:
        # .sb3 / .sprite3 (with the reader sprite) and the bake into an author's project
        from ..scratch.project import project_outputs

        values = {k: json.loads(v) for k, v in arrays.items()}
        projects, extra_read = project_outputs(scene, cfg, values, name, rec)
        files.update(projects)
    for cname, png in scene.artefacts.get("costumes", []) or []:  # texture costumes as files too
        files[f"assets/{re.sub(r'[^A-Za-z0-9._-]+', '_', cname).strip('._') or 'costume'}.png"] = png

    new = scene.replace(lists={lst.name: lst for lst in lists})
    if extra_read:  # the project baked into: protected from overwriting, and a depfile input
        new = new.replace(source=dataclasses.replace(
            new.source, files_read=tuple(new.source.files_read) + tuple(extra_read)))
    new = new.with_artefact("outputs", files).with_artefact("list_info", info)
    rec.details["lists"] = info
    rec.seconds = time.perf_counter() - t0
    return new, rec
