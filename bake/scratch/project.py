"""Scratch project outputs of a bake: the fresh .sb3, the .sprite3 and the bake into an author's .sb3.

Called by the export stage (``bake/export/lists.py``) with the lists as they are written
(name -> JSON items). With the reader on (``export.reader``), the fresh ``<model>.sb3`` holds the
lists on the stage plus the reader sprite (its green flag draws the model), and the
``<model>.sprite3`` is the reader sprite with the lists local to it and no green-flag script, so it
can be dropped into any project with "Upload Sprite".
"""

from __future__ import annotations

import dataclasses
import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, InputError
from . import backdrop, engine, sb3
from . import readers
from . import textimage
from .check import check_packed_lists
from .layout import join
from .reader_texture import TextureSource, TextureSpec
from .loader import LoaderPart, LoaderSpec


def _cfg(cfg: Any, key: str, default: Any) -> Any:
    return getattr(cfg, key, default)


def look_at(pos, target, *, focal: float = 300.0, near: float = 0.01) -> readers.Camera:
    """A reader camera at ``pos`` looking at ``target`` (yaw/pitch in degrees, rounded to 0.01)."""
    f = np.asarray(target, np.float64) - np.asarray(pos, np.float64)
    yaw = math.degrees(math.atan2(f[0], f[2]))
    pitch = math.degrees(math.atan2(f[1], math.hypot(f[0], f[2])))
    return readers.Camera(x=float(pos[0]), y=float(pos[1]), z=float(pos[2]), yaw=round(yaw, 2),
                          pitch=round(pitch, 2), focal=focal, near=near)


# auto_camera: the share of the stage's half-width and half-height the model may take
FRAME_FILL = 0.9


def auto_camera(verts: list[float] | np.ndarray) -> readers.Camera:
    """A camera in front of, above and left of the model, looking at its centre, as close as lets
    every vertex fall inside FRAME_FILL of the 480x360 stage with the default focal length (the
    reader's projection ``focal * x / z``): the model fills the green flag's view as it fills the
    report's other previews (at a fixed 0.95 diagonals away a long model sat small in the middle)."""
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    if len(v) == 0:
        return readers.Camera()
    lo, hi = v.min(axis=0), v.max(axis=0)
    c = (lo + hi) / 2
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    f = np.array([0.45, -0.4, 1.0])
    f /= np.linalg.norm(f)
    probe = look_at(c - f * diag, c)
    # the reader's frame for that yaw and pitch (x right, y up, z into the screen)
    yaw, pitch = math.radians(probe.yaw), math.radians(probe.pitch)
    fwd = np.array([math.sin(yaw) * math.cos(pitch), math.sin(pitch), math.cos(yaw) * math.cos(pitch)])
    right = np.cross([0.0, 1.0, 0.0], fwd)
    right /= np.linalg.norm(right)
    up = np.cross(fwd, right)
    rel = v - c
    x, y, z = rel @ right, rel @ up, rel @ fwd
    half_w, half_h = FRAME_FILL * 240.0, FRAME_FILL * 180.0
    # each vertex is inside when the camera stands at least this far back from the centre
    dist = float(np.max(np.maximum(probe.focal * np.abs(x) / half_w, probe.focal * np.abs(y) / half_h) - z))
    dist = max(dist, float(np.max(-z)) + 0.05 * diag, 0.05 * diag)  # (and in front of every vertex)
    pos = [float(f"{x:.4g}") for x in c - fwd * dist]
    return look_at(pos, c, near=float(f"{diag * 1e-3:.4g}"))


def _bvh_spec(scene: Any, values: dict[str, list]) -> readers.BVHSpec | None:
    art = scene.artefacts.bvh if scene is not None else None
    if art is None:
        return None
    names = art.lists
    if not all(n in values for n in names.values()):
        return None
    return readers.BVHSpec(bary=tuple(art.bary), layout=art.encoded.layout, bits=int(art.encoded.bits or 0),
                           nodes=names["nodes"], tris=names["tris"], ids=names["ids"])


def all_numbers(items: list) -> bool:
    """Whether a list's items are all numbers (as the lists' JSON holds them)."""
    return np.asarray(items).dtype.kind in "iuf"


def has_textimage(values: dict[str, list]) -> bool:
    """Did the bake write a TextImage string (a list item starting with the TextImage magic)?"""
    return any(len(items) and isinstance(items[0], str) and items[0].startswith(textimage.MAGIC + ",")
               for items in values.values())


def book_lists(cfg: Any, values: dict[str, list]) -> dict[str, list]:
    """The mesh lists in the book's layout (role -> items), whatever layout the bake wrote them in
    (``bake.scratch.layout.join``)."""
    return join(values, cfg.names, _cfg(cfg, "faces", "triangles"), _cfg(cfg, "index_base", 1))


def reader_spec(scene: Any, cfg: Any, values: dict[str, list]) -> readers.ReaderSpec:
    """The reader for these lists: only the blocks whose lists the bake wrote (a renderer for a
    mesh, the BSP walk for a BSP tree, the ray query for the BVH layout written, the TextImage
    decoder for TextImage strings)."""
    n = cfg.names
    mesh = None
    book = book_lists(cfg, values)
    if "vertices" in book and "triangles" in book:
        mesh = readers.MeshNames(verts=_one_or_tuple(n.vertices), tris=_one_or_tuple(n.triangles),
                                 mat_colors=n.materials if n.materials in values else None,
                                 tri_colors=n.triangle_colors if n.triangle_colors in values else None,
                                 two_sided=getattr(n, "two_sided", "mat two-sided"),
                                 index_base=_cfg(cfg, "index_base", 1), soup=_cfg(cfg, "faces", "") == "soup")
    cam = auto_camera(book["vertices"]) if mesh else readers.Camera()
    two = [1 if getattr(m, "double_sided", False) else 0 for m in getattr(scene, "materials", ())]
    bvh = _bvh_spec(scene, values)
    # the green flag's BVH view (export.green_flag = "bvh"): only with a BVH and a mesh to colour it
    view = int(_cfg(cfg, "bvh_cell", 8)) if _cfg(cfg, "green_flag", "raster") == "bvh" and bvh and mesh else None
    return readers.ReaderSpec(mesh=mesh, bvh=bvh, bsp=_bsp_spec(scene, values),
                              textimage=has_textimage(values), renderer=True, camera=cam, two_sided=two,
                              bounds=readers.bounding_sphere(book["vertices"]) if mesh else None,
                              texture=texture_spec(scene, cfg, values) if mesh else None, bvh_view=view)


def texture_spec(scene: Any, cfg: Any, values: dict[str, list]) -> TextureSpec | None:
    """The textured filler's sources (``reader_texture.py``), or None: the lightmap for every
    triangle when the bake wrote it and its UVs; else each material's texture (its colour list, or
    its TextImage string) through ``tri uvs``; None when no drawn triangle has a texture in the
    project, or ``export.texel_size = 0``."""
    cell = int(_cfg(cfg, "texel_size", 0) or 0)
    if not cell or scene is None:
        return None
    n = cfg.names
    n_mat = max(len(getattr(scene, "materials", ())), 1)
    arts = scene.artefacts

    def source(enc, image) -> TextureSource | None:
        H, W = image.shape[:2]
        lists = {e: [lst.name for lst in enc.lists.get(e, [])] for e in ("list", "textimage")}
        if lists["list"] and lists["list"][0] in values:
            return TextureSource("list", lists["list"][0], W, H, enc.first_row)
        if lists["textimage"] and lists["textimage"][0] in values:
            return TextureSource("textimage", lists["textimage"][0], W, H, "bottom")
        return None

    lm_enc = getattr(arts, "lightmap_encoded", None)
    if isinstance(n.lightmap_uvs, str) and n.lightmap_uvs in values and lm_enc is not None:
        src = source(lm_enc, lm_enc.image)
        if src is not None:
            return TextureSpec([src], [0] * n_mat, n.lightmap_uvs, cell)
    tex = arts.textures
    if tex is None or not isinstance(n.uvs, str) or n.uvs not in values:
        return None
    sources: list[TextureSource] = []
    per_mat = [-1] * n_mat
    for t in tex.textures:
        if t.encoded is None or t.image is None:
            continue
        src = source(t.encoded, t.image)
        if src is None:
            continue
        for m in t.materials:
            if 0 <= m < n_mat:
                per_mat[m] = len(sources)
        sources.append(src)
    if not sources:
        return None
    return TextureSpec(sources, per_mat, n.uvs, cell)


def _one_or_tuple(value: str | list[str]) -> str | tuple[str, ...]:
    return value if isinstance(value, str) else tuple(value)


def _bsp_spec(scene: Any, values: dict[str, list]) -> readers.BSPSpec | None:
    art = scene.artefacts.bsp if scene is not None else None
    if art is None:
        return None
    nodes, planes = art.nodes, art.planes
    if nodes not in values or planes not in values:
        return None
    return readers.BSPSpec(nodes=nodes, planes=planes)


def _read_project(project: Path) -> dict | None:
    """The project.json of a project baked into (None if it cannot be read: merge_into reports it)."""
    try:
        return sb3.load_project(project)[0]
    except InputError:
        return None


def _list_names(proj: dict | None, targets: Any = None, non_empty: bool = False) -> set[str]:
    """Names of the lists of ``proj``'s targets (those ``targets(t)`` accepts, or all; with
    ``non_empty`` only lists holding items)."""
    return {e[0] for t in (proj or {}).get("targets", []) or []
            if isinstance(t, dict) and (targets is None or targets(t))
            for e in (t.get("lists") or {}).values() if isinstance(e, list) and e and isinstance(e[0], str)
            and (not non_empty or (len(e) > 1 and isinstance(e[1], list) and len(e[1]) > 0))}


def _bake_list_names(cfg: Any) -> set[str]:
    """Lists a bake writes, whichever stages run: the mesh lists (``export.names``), the packed
    texts, and the BSP and BVH lists (their readers' default names)."""
    names = {n for v in vars(cfg.names).values() for n in ([v] if isinstance(v, str) else v)}
    for spec in (readers.BSPSpec, readers.BVHSpec):  # their list-name fields
        names |= {f.default for f in dataclasses.fields(spec) if f.name in ("nodes", "planes", "tris", "ids")}
    return names


def _stale_lists(proj: dict | None, target: str, written: dict[str, list], cfg: Any) -> list[str]:
    """Lists of an earlier bake that a project baked into keeps because this bake does not write
    them (a BSP tree of another model, colours the new model does not have): the stage's and the
    target sprite's non-empty lists with a bake's list name that is not among ``written`` (an
    empty one holds no earlier model)."""
    seen = _list_names(proj, lambda t: t.get("isStage") or t.get("name") == target, non_empty=True)
    return sorted(seen & (_bake_list_names(cfg) - set(written)))


def texture_costumes(scene: Any) -> list[sb3.Costume]:
    """The textures stage's PNG costumes (``artefacts.costumes``: (name, png bytes)) as
    bitmapResolution-2 costumes centred on the image (sizes read from the PNG header)."""
    out = []
    for cname, png in scene.artefacts.costumes or []:
        w = int.from_bytes(png[16:20], "big") if png[:8] == b"\x89PNG\r\n\x1a\n" else 2
        h = int.from_bytes(png[20:24], "big") if png[:8] == b"\x89PNG\r\n\x1a\n" else 2
        out.append(sb3.Costume(cname, sb3.Asset(png, "png"), 2, (w / 2.0, h / 2.0)))
    return out


def packed_values(values: dict[str, list], packed: dict[str, Any], packed_name: str) -> dict[str, list]:
    """The lists as the project stores them: each packed list empty, its text an item of
    ``packed_name`` (in ``packed``'s order, which the loader follows)."""
    out = {k: ([] if k in packed else v) for k, v in values.items()}
    if packed:
        out[packed_name] = [p.text for p in packed.values()]
    return out


def _with_loader(spec: readers.ReaderSpec | None, packed: dict[str, Any], packed_name: str
                 ) -> readers.ReaderSpec | None:
    if not packed:
        return spec
    if spec is None:  # no reader asked for: a sprite with the loader alone
        spec = readers.ReaderSpec(mesh=None, textimage=False, renderer=False)
    loader = LoaderPart(LoaderSpec(list(packed), packed_name))
    return dataclasses.replace(spec, parts=list(spec.parts) + [loader])


def _has_loader(spec: readers.ReaderSpec | None) -> bool:
    return spec is not None and any(isinstance(p, LoaderPart) for p in spec.parts)


def project_outputs(scene: Any, cfg: Any, values: dict[str, list], name: str,
                    record: Any = None, packed: dict[str, Any] | None = None) -> tuple[dict[str, bytes], list[Path]]:
    """The .sb3 / .sprite3 files of a bake (relative name -> bytes) and the extra input files
    read (the project baked into). ``packed``: list name -> :class:`bake.scratch.pack.Packed` for
    the lists stored packed (with the loader blocks in the reader sprite)."""
    files: dict[str, bytes] = {}
    read: list[Path] = []
    packed = dict(packed or {})
    packed_name = cfg.names.packed
    want_reader = bool(_cfg(cfg, "reader", True))
    plain_spec = reader_spec(scene, cfg, values) if want_reader else None
    if plain_spec is not None and _cfg(cfg, "green_flag", "raster") == "bvh" and plain_spec.bvh_view is None \
            and record is not None:
        record.warn("export.green_flag = \"bvh\" needs a BVH (bvh.enabled = true) and the mesh lists: "
                    + ("the bake wrote no BVH" if plain_spec.bvh is None else "the bake wrote no mesh lists")
                    + ", so the green flag draws " + ("the raster (render)" if plain_spec.mesh else "nothing"))
    spec = _with_loader(plain_spec, packed, packed_name)
    stored = packed_values(values, packed, packed_name)
    details = record.details if record is not None else {}
    if plain_spec is not None and plain_spec.texture is not None:  # what the textured filler reads
        details["reader_texture"] = plain_spec.texture.to_json()
    costumes = texture_costumes(scene)
    if cfg.sb3:
        sb3_name = _cfg(cfg, "sb3_name", "") or f"{name}.sb3"
        # a packed project is the lighter one (issue 41): the stage's list ids as short as the sprite's
        id_length = readers.VAR_ID_LENGTH if packed else 20
        stage_ids = sb3.data_ids("Stage", [], list(stored), length=id_length)[1]
        if spec is not None:
            sprite = readers.reader_target(spec, cfg.sprite_name, stage_lists=stage_ids, demo=True)
        else:
            sprite = sb3.Target(cfg.sprite_name, layer_order=1)
        stage = sb3.Target("Stage", is_stage=True, lists=stored, id_length=id_length)
        if spec is not None and spec.mesh is not None:  # the reader draws the mesh: a backdrop it shows on
            m, book = spec.mesh, book_lists(cfg, values)
            bd = backdrop.choose(book["vertices"], book["triangles"],
                                 values.get(m.tri_colors) if m.tri_colors else None,
                                 values.get(m.mat_colors) if m.mat_colors else None)
            stage.costumes = [sb3.Costume("backdrop1", sb3.Asset(bd.svg(), "svg"), 1, (240.0, 180.0))]
            details["backdrop"] = bd.to_json()
            if bd.rgb != backdrop.WHITE and record is not None:
                record.effects.append({"name": "dark backdrop", "ran": True, "reason": bd.reason})
        if not bool(_cfg(cfg, "turbowarp_fencing", True)):
            stage.comments[sb3.TW_CONFIG_COMMENT_ID] = sb3.turbowarp_settings_comment(
                {"runtimeOptions": {"fencing": False}})
        targets = [stage, sprite]
        if costumes:  # the texture costumes, in a hidden sprite of their own for stamping engines
            targets.append(sb3.Target("Textures", costumes=list(costumes), layer_order=2, visible=False))
        data, pj_bytes = sb3.write_sb3(targets)
        files[sb3_name] = data
        details["project_json_bytes"] = pj_bytes
        details["sb3_project_json_bytes"] = pj_bytes  # (project_json_bytes is the merged one with export.into)
        details["sb3_assets"] = sb3.archive_sizes(data)["assets"]
    if cfg.sprite3:
        if spec is not None:
            # no green-flag script: a sprite dropped into an engine must not start drawing on its own;
            # with `load triangle` for authors who copy blocks into their engines
            sprite = readers.reader_target(dataclasses.replace(spec, helpers=True), cfg.sprite_name,
                                           local_lists=stored)
        else:
            sprite = sb3.Target(cfg.sprite_name, lists=stored)
        if costumes:
            sprite.costumes = list(sprite.costumes) + list(costumes)
        # named like the .sb3 (export.sb3_name), so the two sit side by side
        stem = Path(_cfg(cfg, "sb3_name", "") or f"{name}.sb3").stem
        files[f"{stem}.sprite3"] = sb3.write_sprite3(sprite)
    into = _cfg(cfg, "into", "")
    if into:
        src = Path(into)
        if not src.is_file():
            raise InputError("export.into: project not found", path=src)
        target = _cfg(cfg, "into_target", "Stage") or "Stage"
        out_name = _cfg(cfg, "into_name", "") or f"{src.stem}-{name}.sb3"
        if Path(out_name).name != out_name:
            raise ConfigError("must be a file name, not a path", key="export.into_name")
        sprites = []
        src_project = _read_project(src)
        into_spec, into_lists = spec, stored
        if packed and target != "Stage":
            # the loader would have to be in the author's sprite that owns the lists
            if record is not None:
                record.warn("export.pack needs export.into_target = \"Stage\" (the loader sprite must see the "
                            f"lists): the lists baked into {src.name} are plain")
            into_spec, into_lists = plain_spec, dict(values)
        elif not packed and packed_name not in into_lists and packed_name in _list_names(src_project):
            # an earlier packed bake's texts would overwrite these lists at the green flag: empty them
            into_lists = {**into_lists, packed_name: []}
        if not _cfg(cfg, "into_reader", False) and _has_loader(into_spec):
            into_spec = _with_loader(None, packed, packed_name)  # the loader alone
        elif not _cfg(cfg, "into_reader", False):
            into_spec = None
        if into_spec is not None:
            if target != "Stage":
                if record is not None:
                    record.warn("export.into_reader needs export.into_target = \"Stage\" "
                                "(a sprite cannot read another sprite's lists): reader not added")
            else:
                sprites.append(readers.reader_target(dataclasses.replace(into_spec, helpers=True),
                                                     cfg.sprite_name, stage_lists=list(into_lists)))
        data = sb3.merge_into(src, target, into_lists, costumes, sprites=sprites)
        check_packed_lists(sb3.load_project(data)[0], src)
        files[out_name] = data
        sizes = sb3.archive_sizes(data)
        stale = _stale_lists(src_project, target, into_lists, cfg)
        if stale and record is not None:
            record.warn(f"export.into: {src.name} keeps list(s) an earlier bake wrote and this one does not: "
                        f"{', '.join(repr(n) for n in stale)}; they are left as they were, so blocks that read them "
                        "get the earlier model's data (delete them in the editor, or bake the stage that "
                        "writes them)")
        details["into"] = {"project": str(src), "target": target, "file": out_name,
                           "project_json_bytes": sizes["project_json_bytes"], "assets": sizes["assets"],
                           "stale_lists": stale}
        if src_project is not None:  # what the author's engine does with the lists (scratch/engine.py)
            lengths = {n: len(values[n]) if n in values else len(v) for n, v in into_lists.items()}
            found = engine.check(src_project, target, lengths, reader_added=bool(sprites),
                                 numbers={n for n, v in values.items() if all_numbers(v)})
            details["into"]["engine"] = found
            for line in found["warnings"]:
                if record is not None:
                    record.warn(line)
                    record.problems.append(line)
        # the report measures the project the author will upload
        details["project_json_bytes"] = sizes["project_json_bytes"]
        read.append(src)
    return files, read
