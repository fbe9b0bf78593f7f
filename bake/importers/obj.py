"""Wavefront OBJ (+ MTL) importer: our own vectorised parser; n-gons are kept as polygons.

The file is read in blocks of whole lines (:data:`BLOCK_SIZE`, 4 MB; a line continued with a
backslash stays in one block) and each block is tokenised with numpy (no Python loop per vertex
or face line; :mod:`bake.importers.obj_lines`), then parsed into compact arrays (positions, UVs,
resolved indices, materials; :mod:`bake.importers.obj_parse`). This module holds :func:`load`
and builds the scene from the blocks' arrays, concatenated at the end, so memory stays near the
size of the result; line numbers, relative indices, ``usemtl``, errors and warnings are carried
across blocks and come out exactly as for one block. MTL files (small) are read line by line
(:mod:`bake.importers.mtl`).

Rules (what this importer decides, so the report and tests can rely on it):

* Lines: ``\\n``, ``\\r\\n`` or bare ``\\r`` endings; bytes up to 0x20 (space, tab, CR, ...)
  separate tokens; a backslash at the end of a line continues it on the next (``wallhole.obj``
  does this); ``#`` starts a comment (also after data on a line;
  a ``#`` inside a token such as ``1.#IND`` is not a comment). A UTF-8 BOM is skipped. A file
  with NUL bytes or many control bytes is not text: :class:`InputError`.
* ``v x y z`` -- 3 values: a position. 4 values: ``x y z w``; ``w`` (a rational weight, only
  meaningful for free-form curves) is ignored, as in corpus ``vertex_w_component``.
  6 values: ``x y z r g b`` (MeshLab and trimesh's exporter write this, as does the corpus
  ``obj_vertex_colors``; trimesh's loader reads columns 4-6 the same way); 7 values: ``x y z r g b a``. Colours in [0, 1] are taken as they are; if any
  colour value is above 1 and all are whole numbers they are read as 0-255 and divided by 255;
  anything else outside [0, 1] is clipped (warning). Vertices without colour in a file where
  others have one get white (warning). 5 or more than 7 values: position only (warning).
  Fewer than 3: :class:`InputError`.
* ``vt u [v [w]]``: ``v`` defaults to 0, ``w`` is ignored; OBJ convention kept (v up).
  ``vn x y z`` lines are checked as strictly (numbers, three of them, finite) and then dropped:
  normals are recomputed downstream.
* Positions, colours, texture coordinates and normals must be finite: NaN/Inf (including MSVC's
  ``1.#IND``/``1.#INF``) is an :class:`InputError` naming the first few lines, as is a position
  beyond ``scene.MAX_COORDINATE`` (1e30). A malformed
  number on a ``v``/``vt``/``vn``/``f`` line is an :class:`InputError` naming file and line.
* Faces: index 0, an index out of range (positive indices may refer to vertices defined later
  in the file; negative ones count back from the line) or fewer than 3 corners make a bad face:
  :class:`InputError` when ``job.strict``, else the face is dropped with one warning giving the
  count and the first lines. Normal indices (``v//vn``, ``v/vt/vn``) are checked the same way
  against the ``vn`` lines, though the normals themselves are unused.
* ``poly_uvs`` is per corner when any kept corner has a ``vt``; corners without one get (0, 0)
  and a warning. No ``vt`` on any kept corner: ``None``.
* ``usemtl``: faces use the last ``usemtl`` above them; faces before any ``usemtl`` (or after an
  empty ``usemtl``) use a material named ``default``. ``scene.materials`` holds exactly the
  materials that kept faces use, in order of first use; MTL materials never used are dropped
  (their names are listed in ``details["materials_unused"]``). A ``usemtl`` name no MTL defines
  gets a default-coloured material of that name (one warning). With no faces at all the scene
  keeps the one default material.
* ``mtllib``: one or more files relative to the OBJ (a name with spaces is tried whole first);
  backslashes are accepted; a missing file falls back to the same base name next to the OBJ,
  then to a case-insensitive match; still missing: a warning and default colours. Like glTF
  URIs, MTL and texture files must lie in the OBJ's folder (or below it): a path that leaves it
  (``..``, absolute, a symbolic link pointing out) is not read (a warning; the same base name next
  to the OBJ is still tried).
* MTL: ``newmtl`` (rest of the line, trimmed), ``Kd`` (rgb; one value = grey; ``spectral``/``xyz``
  forms are ignored with a warning; clipped to [0, 1]), ``d`` (alpha, ``-halo`` skipped) and
  ``Tr`` (alpha = 1 - Tr, used only when the material has no ``d``). ``Tr 1`` would make the
  material invisible, yet MeshLab and other exporters write ``Tr 1.000000`` for opaque textured
  materials (corpus ``fuze_textured``, ``capsule_textured``), so ``Tr 1`` alone is read as
  opaque, with a warning.
  ``map_Kd``: options (``-s 1 1 1``, ``-bm 2`` ...) are skipped, the rest of the line is the file
  name (spaces kept, backslashes accepted, surrounding quotes removed), resolved relative to the
  .mtl like ``mtllib``; :attr:`Material.texture` is the absolute path when the file exists,
  else a warning. A malformed MTL number is a warning naming the MTL line. The first
  definition of a material name wins. Other MTL statements are ignored.
* Names (materials, ``mtllib``/``map_Kd`` files) are decoded as UTF-8, falling back to Latin-1
  per line (corpus ``house_max2obj_walls``), with a warning. (A Latin-1 *file name* is then
  looked up as the UTF-8 encoding of that text, so such a texture may be reported missing.)
* ``o``/``g``/``s``/``mg`` are accepted and ignored (counted in details); ``l``/``p`` are skipped
  and counted in a warning; free-form and unknown directives are counted in one warning.
* An empty file or one without faces gives a scene with 0 polygons and a warning.
"""

from __future__ import annotations

import time
from pathlib import Path

import numpy as np

from ..config import ImportJob
from ..errors import InputError
from ..record import StageRecord
from ..scene import DEFAULT_MATERIAL, Material, Scene, SourceInfo
from .mtl import materials_from
from .obj_lines import _FIRST_LINES, _Reader, _lines_list
from .obj_parse import _Parser

__all__ = ["load"]

# bytes per parse block (whole lines). Memory is the output arrays plus about 25 times this
# (4 MB: a 263 MB OBJ peaks at 0.63 GB; 4-16 MB parse at the same speed); tests set it tiny to
# show the block boundaries change nothing
BLOCK_SIZE = 4 * 1024 * 1024


# --------------------------------------------------------------------------- entry point
def load(job: ImportJob, *, block_size: int | None = None) -> tuple[Scene, StageRecord]:
    """Read ``job.path`` (OBJ + its MTL files) into a scene with polygons (n-gons kept).

    The file is parsed in blocks of whole lines of about ``block_size`` bytes (default
    :data:`BLOCK_SIZE`); the result, warnings and errors do not depend on the block size."""
    t0 = time.perf_counter()
    path = Path(job.path)
    rec = StageRecord(name="import")
    p = _Parser(path, bool(job.strict), rec)
    try:
        f = open(path, "rb")
    except OSError as e:
        raise InputError(f"cannot read file: {e.strerror or e}", path=path) from None
    with f:
        reader = _Reader(f, path, BLOCK_SIZE if block_size is None else block_size)
        for block, final in reader.blocks():
            p.feed(block, reader.nlb, final)
    scene = _scene(p)
    sizes = scene.poly_sizes
    cnt = np.bincount(sizes) if len(sizes) else np.zeros(0, np.int64)
    rec.details.update({
        "format": "obj",
        "polygon_sizes": {str(int(s)): int(cnt[s]) for s in np.flatnonzero(cnt)},
        "vertices": scene.n_vertices,
        "polygons": scene.n_polygons,
        "materials": [m.name for m in scene.materials],
        "files_read": [str(f) for f in scene.source.files_read],
    })
    rec.details.update(p.details)
    rec.counts_out = {"polygons": scene.n_polygons, "triangles": 0, "vertices": scene.n_vertices,
                      "materials": len(scene.materials), "uv_corners": int(p.details["uv_corners"])}
    rec.seconds = time.perf_counter() - t0
    return scene, rec


def _concat(parts: list[np.ndarray], empty_shape: tuple, dtype) -> np.ndarray:
    """The blocks' arrays as one (the list is emptied, so each part can be freed)."""
    if not parts:
        return np.zeros(empty_shape, dtype)
    out = parts[0] if len(parts) == 1 else np.concatenate(parts)
    parts.clear()
    return out


# --------------------------------------------------------------------------- the scene
def _scene(p: _Parser) -> Scene:
    """The scene from what the parser collected, in phases: the first error (raised), the vertex
    data, the lines not imported, the faces kept, their materials. The warnings come out in this
    order, and so do the keys of ``p.details``."""
    p.raise_first_error()
    positions, colors, uvs = _vertex_data(p)
    _skipped_lines(p)
    sizes, poly_indices, poly_uvs, fmat = _kept_faces(p, uvs)
    del uvs
    poly_material, materials = _materials(p, fmat)
    del fmat
    if len(sizes) == 0:
        p.rec.warn("no faces in file" if p.nf == 0 else "no faces left after dropping bad faces")
    if p.latin1.n:
        p.rec.warn(f"names on {p.latin1.n} line(s) of {p.path} are not UTF-8 and were decoded as "
                   f"Latin-1 (lines {p.latin1.text()})")
    return Scene(
        positions=positions,
        poly_sizes=sizes.astype(np.int64, copy=False),
        poly_indices=poly_indices.astype(np.int64, copy=False),
        poly_material=poly_material.astype(np.int64, copy=False),
        poly_uvs=poly_uvs,
        vertex_colors=colors,
        materials=tuple(materials),
        source=SourceInfo(path=p.files[0], files_read=tuple(p.files), format="obj",
                          files_missing=tuple(dict.fromkeys(p.missing))),
    )


def _vertex_data(p: _Parser) -> tuple[np.ndarray, np.ndarray | None, np.ndarray]:
    """Positions, vertex colours (None without any) and texture coordinates, with the warnings
    about ``v`` and ``vt`` lines that had values left over."""
    rec = p.rec
    if p.odd_v.n:
        rec.warn(f"{p.odd_v.n} 'v' line(s) have {p.odd_v_values} values (expected "
                 f"3, 4, 6 or 7); extra values ignored (lines {p.odd_v.text()})")
    positions = _concat(p.pos, (0, 3), np.float64)
    colors = _vertex_colors(p, p.nv)
    if p.many_vt.n:
        rec.warn(f"{p.many_vt.n} 'vt' line(s) have more than 3 values; extra "
                 f"values ignored (lines {p.many_vt.text()})")
    uvs = _concat(p.uv, (0, 2), np.float64)
    p.details.update({"texcoords": p.nt, "normals": p.nvn})
    return positions, colors, uvs


def _vertex_colors(p: _Parser, NV: int) -> np.ndarray | None:
    """The colours of the ``v`` lines that had some (0-255 scaled down, the rest clipped to
    [0, 1]), white for the vertices without; None when no line had a colour."""
    colors = None
    if p.col_blocks:
        p.details["vertex_color_scale"] = "0-1"
        scale = p.col_max > 1.0 and p.col_whole and p.col_min >= 0
        if scale:
            p.details["vertex_color_scale"] = "0-255"
        elif p.col_max > 1.0 or p.col_min < 0.0:
            p.rec.warn(f"vertex colours outside [0, 1] (from {p.col_min:g} to "
                       f"{p.col_max:g}) were clipped")
        colors = np.ones((NV, 4))
        for first, col, has_col, has_a in p.col_blocks:
            if scale:
                col[has_col, :3] /= 255.0
                col[has_a, 3] /= 255.0
            colors[first:first + len(col)] = col
        p.col_blocks.clear()
        np.clip(colors, 0.0, 1.0, out=colors)
        if p.col_vertices < NV:
            p.rec.warn(f"{NV - p.col_vertices} of {NV} vertices have no colour; "
                       f"they get white")
    p.details["vertex_colors"] = colors is not None
    return colors


def _skipped_lines(p: _Parser) -> None:
    """The details and warnings of the lines that import nothing: groups, ``l``/``p`` elements,
    unknown directives."""
    rec = p.rec
    p.details["groups_objects_smoothing_lines"] = p.groups
    if p.n_l or p.n_p:
        rec.warn(f"skipped {p.n_l} line element(s) ('l') and {p.n_p} point element(s) "
                 f"('p'); only faces are imported")
    p.details["skipped_elements"] = {"l": p.n_l, "p": p.n_p}
    unknown = p.unknown
    if unknown:
        parts = [f"'{k}' x{v[0]} (first at line {v[1]})" for k, v in sorted(unknown.items())]
        rec.warn(f"ignored {sum(v[0] for v in unknown.values())} line(s) with unsupported "
                 f"or unknown directives: {', '.join(parts)}")
    p.details["unknown_directives"] = {k: v[0] for k, v in sorted(unknown.items())}


# --------------------------------------------------------------------------- faces
def _kept_faces(p: _Parser, uvs: np.ndarray
                ) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray]:
    """The faces kept: (corners per face, vertex index per corner, UV per corner or None,
    material id per face). Indices beyond the end of the file are known only now; a bad face is
    dropped with a warning, or raised when ``strict``."""
    sizes, vres, tres, nres = _corner_arrays(p)
    _warn_bad_normals(p, sizes, nres)
    del nres
    badf = _bad_faces(p, sizes, vres, tres)
    dropped = int(np.count_nonzero(badf))
    keepf = ~badf if dropped else slice(None)
    keepc = np.repeat(~badf, sizes) if dropped else slice(None)
    del badf
    sizes_k = sizes[keepf] if dropped else sizes
    poly_indices = vres[keepc] if dropped else vres
    del vres
    tk = None if tres is None else tres[keepc] if dropped else tres
    del tres
    poly_uvs = _corner_uvs(p, tk, uvs)
    del tk
    p.details["dropped_faces"] = dropped
    fmat = _concat(p.fmat, (0,), np.int32)
    if dropped:
        fmat = fmat[keepf]
    return sizes_k, poly_indices, poly_uvs, fmat


def _corner_arrays(p: _Parser) -> tuple[np.ndarray, np.ndarray, np.ndarray | None, np.ndarray | None]:
    """The blocks' faces as one: corners per face and, per corner, the 0-based vertex, texture
    coordinate and normal index (-1 bad, -2 none; the last two None when no block had any)."""
    sizes = _concat(p.sizes, (0,), np.int64)
    tres = None
    if any(x is not None for x in p.tres):
        tres = np.concatenate([np.full(len(v), -2, np.int64) if x is None else x
                               for v, x in zip(p.vres, p.tres)])
    p.tres.clear()
    nres = None
    if any(x is not None for x in p.nres):
        nres = np.concatenate([np.full(len(v), -2, np.int64) if x is None else x
                               for v, x in zip(p.vres, p.nres)])
    p.nres.clear()
    vres = _concat(p.vres, (0,), np.int64)
    return sizes, vres, tres, nres


def _warn_bad_normals(p: _Parser, sizes: np.ndarray, nres: np.ndarray | None) -> None:
    """One warning for the faces that name a normal that is 0 or not in the file (kept: bake
    computes its own normals)."""
    if nres is not None and (nres >= p.nvn).any():  # normals named past the file's last vn
        faces_of = np.searchsorted(np.cumsum(sizes), np.flatnonzero(nres >= p.nvn), side="right")
        p.bad_normals.add(np.array([p.face_line(int(f)) for f in np.unique(faces_of)[:_FIRST_LINES + 1]]),
                          n=len(np.unique(faces_of)))
    if p.bad_normals.n:
        p.rec.warn(f"{p.bad_normals.n} face(s) name a normal (v//vn, v/vt/vn) that is 0 or beyond the file's "
                   f"{p.nvn} 'vn' line(s) (lines {p.bad_normals.text()}); normals are not used (bake "
                   "computes its own), so the faces are kept")


def _bad_faces(p: _Parser, sizes: np.ndarray, vres: np.ndarray, tres: np.ndarray | None) -> np.ndarray:
    """Which faces are bad (an index 0 or out of range, fewer than 3 corners). With
    ``strict`` the first raises; else one warning counts them and says why the first is bad."""
    NV, NT = p.nv, p.nt
    badc = vres < 0
    badc |= vres >= NV
    if tres is not None:
        badc |= tres == -1
        badc |= tres >= NT
    badf = sizes < 3
    cend = None
    if badc.any():
        cend = np.cumsum(sizes)
        badf[np.searchsorted(cend, np.flatnonzero(badc), side="right")] = True
    del badc
    if badf.any():
        order = np.flatnonzero(badf)
        f0 = int(order[0])
        c0 = int(cend[f0] - sizes[f0]) if cend is not None else int(sizes[:f0].sum())
        why = p.why_bad(f0, int(sizes[f0]), c0, vres, tres, NV, NT)
        line = p.face_line(f0)
        if p.strict:
            raise p.err(why, line)
        shown = np.array([p.face_line(int(f)) for f in order[:_FIRST_LINES + 1]])
        p.rec.warn(f"dropped {len(order)} bad face(s) (index 0, index out of range or fewer than 3 "
                   f"vertices) at lines {_lines_list(shown)}; first, line {line}: {why}")
    return badf


def _corner_uvs(p: _Parser, tk: np.ndarray | None, uvs: np.ndarray) -> np.ndarray | None:
    """The UV of every kept corner (``tk``: their texture coordinate indices, -2 for none), or
    None when no corner has one; corners without one get (0, 0) and a warning."""
    poly_uvs = None
    if tk is not None:
        has_t = tk != -2
        n_t = int(np.count_nonzero(has_t))
    else:
        has_t, n_t = None, 0
    p.details["uv_corners"] = n_t
    if n_t:
        all_t = n_t == len(has_t)
        poly_uvs = uvs[tk if all_t else np.where(has_t, tk, 0)]
        if not all_t:
            poly_uvs[~has_t] = 0.0
            p.rec.warn(f"{len(has_t) - n_t} of {len(has_t)} face corners have no texture "
                       f"coordinate (vt); they get UV (0, 0)")
    return poly_uvs


# --------------------------------------------------------------------------- materials
def _materials(p: _Parser, fmat: np.ndarray) -> tuple[np.ndarray, list[Material]]:
    """The material number of every kept face, and the materials the faces use in order of first
    use (read from the ``mtllib`` files; default-coloured when no MTL defines the name)."""
    mtl = materials_from(p.path, p.mtllibs, p.rec, p.files, p.missing)
    names = p.names
    if len(fmat):  # materials in order of first use (faces come in runs of one material)
        heads = fmat[np.concatenate([[0], np.flatnonzero(fmat[1:] != fmat[:-1]) + 1])]
        u, first = np.unique(heads, return_index=True)
        used = u[np.argsort(first, kind="stable")]
        lut = np.zeros(len(names), np.int64)
        lut[used] = np.arange(len(used))
        poly_material = lut[fmat]
        used_names = [names[i] for i in used]
    else:
        poly_material = np.zeros(0, np.int64)
        used_names = []
    materials, unknown_m = [], []
    for nm in used_names:
        if nm in mtl:
            materials.append(mtl[nm])
        elif nm == "default":
            materials.append(DEFAULT_MATERIAL)
        else:
            unknown_m.append(nm)
            materials.append(Material(name=nm))
    if unknown_m:
        shown = ", ".join(repr(n) for n in unknown_m[:_FIRST_LINES])
        more = ", ..." if len(unknown_m) > _FIRST_LINES else ""
        p.rec.warn(f"{len(unknown_m)} material(s) used by faces are not defined in any loaded "
                   f".mtl: {shown}{more}; they get the default colour")
    p.details["materials_unused"] = sorted(n for n in mtl if n not in set(used_names))
    if not materials:
        materials = [DEFAULT_MATERIAL]
    for m in materials:
        if m.texture is not None and m.texture not in p.files:
            p.files.append(m.texture)
    return poly_material, materials
