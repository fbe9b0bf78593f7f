"""The textures stage: ``stage(scene, TexturesConfig) -> (Scene, StageRecord)``.

It runs after the mesh is final (triangulate, clean, simplify) and **before lighting**:

1. **Load** every material texture (OBJ ``map_Kd`` path or glTF ``baseColorTexture`` bytes).
   Materials whose images are identical share one texture (named after the first of them). An
   unreadable image is a warning; that material keeps its plain colour.
2. **Per-triangle base colour** (``bake_colors``): the exact mean of the texture over the
   triangle's UV area (``images.average_over_triangles``, in linear light or stored values) x
   material colour x mean vertex colour, alpha likewise. Written to ``Scene.face_albedo`` (what
   ``Scene.triangle_albedo()`` and so the lighting stage use) and to ``face_colors`` (what export
   writes as the "tri colors" list; lighting replaces it with lit colours).
   :func:`albedo_provider` recomputes it for a changed triangle set (lighting's subdivision); the
   stage puts it in ``scene.artefacts.albedo``, where the lighting stage looks for one.
3. **Resample** each texture (``width``/``height``/``max_size``/``power_of_two``/``filter``/
   ``wrap``) and **encode** it (``bake/textures/encode.py``): colour list + size list, TextImage
   string list, PNG costume (``scene.artefacts.costumes``: ``[(name, png_bytes)]`` for
   bitmapResolution 2). The record compares all three encodings for every texture.
4. **Lightmap atlas** (``lightmap.enabled``): xatlas unwrap (subprocess, cached in the output
   folder's ``.bake-cache/xatlas`` unless ``lightmap.cache_dir`` says otherwise) ->
   ``Scene.tri_lightmap_uvs`` (exported as the ``lightmap uvs`` list) and
   ``scene.artefacts.lightmap`` (a ``lightmap.LightmapJob``: atlas + settings) for the lighting
   stage's ``target = "lightmap"`` (``bake.lighting.lightmap.bake_lightmap``); coverage figures in the record.
   A crash, a timeout or a too-large mesh is a failure: the bake goes on without a lightmap and
   warns, and ``--strict`` exits 5 (a stage failed).
"""

from __future__ import annotations

import dataclasses
import hashlib
import math
import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..config import TexturesConfig
from ..errors import ConfigError, InputError, StageError
from ..record import StageRecord
from ..scene import Scene
from . import images
from .encode import ENCODINGS, EncodedTexture, encode_texture, size_table


@dataclass
class Texture:
    name: str
    materials: list[int]
    source: str  # file path or "embedded"
    original: np.ndarray  # (H, W, 4) uint8 as loaded
    image: np.ndarray | None = None  # resampled
    encoded: EncodedTexture | None = None


@dataclass
class TextureSet:
    """``scene.artefacts.textures``: what :func:`albedo_provider` needs, and the textures."""

    textures: list[Texture] = field(default_factory=list)
    albedo_images: dict[int, np.ndarray] = field(default_factory=dict)  # material -> averaged image
    average: str = "linear"


def check_config(cfg: TexturesConfig) -> None:
    def need(cond: bool, key: str, msg: str) -> None:
        if not cond:
            raise ConfigError(msg, key=f"textures.{key}")

    need(cfg.width >= 0 and cfg.height >= 0, "width", "width and height must be >= 0 (0 = from the image)")
    need(cfg.max_size >= 0, "max_size", "must be >= 0 (0 = no cap)")
    need(len(set(cfg.encodings)) == len(cfg.encodings), "encodings", "lists an encoding twice")
    for key in ("list_name", "size_list_name", "textimage_list_name", "costume_name"):
        v = getattr(cfg, key)
        need(bool(v.strip()), key, "must not be empty")
        try:
            v.format(material="m")
        except (KeyError, IndexError, ValueError):
            need(False, key, "may only use the placeholder {material}")
    names = {cfg.list_name, cfg.size_list_name, cfg.textimage_list_name}
    need(len(names) == 3, "list_name", "list_name, size_list_name and textimage_list_name must differ")
    lm = cfg.lightmap
    need(16 <= lm.resolution <= 8192, "lightmap.resolution", "must be between 16 and 8192")
    need(lm.texels_per_unit >= 0, "lightmap.texels_per_unit", "must be >= 0 (0 = xatlas chooses)")
    need(0 <= lm.padding <= 64, "lightmap.padding", "must be between 0 and 64")
    need(lm.max_chart_area >= 0, "lightmap.max_chart_area", "must be >= 0")
    need(lm.max_cost > 0, "lightmap.max_cost", "must be > 0")
    need(lm.normal_deviation_weight >= 0, "lightmap.normal_deviation_weight", "must be >= 0")
    need(1 <= lm.supersample <= 8, "lightmap.supersample", "must be between 1 and 8")
    need(0 <= lm.dilate <= 64, "lightmap.dilate", "must be between 0 and 64")
    need(lm.max_triangles >= 1, "lightmap.max_triangles", "must be >= 1")
    need(lm.timeout > 0, "lightmap.timeout", "must be > 0 seconds")


# --------------------------------------------------------------------------------------------
# albedo


def textured_albedo(scene: Scene, albedo_images: dict[int, np.ndarray], average: str) -> np.ndarray:
    """(T, 4): texture mean over each triangle's UV area x material colour x mean vertex colour.
    Triangles of untextured materials (or a scene without UVs) get material x vertex colour."""
    base = scene.replace(face_albedo=None).triangle_albedo()
    if scene.tri_uvs is None or not albedo_images or scene.n_triangles == 0:
        return base
    tex = np.ones_like(base)
    mats = np.asarray(scene.tri_material, dtype=np.int64)
    groups: dict[int, tuple[np.ndarray, list[int]]] = {}
    for mi, img in albedo_images.items():  # materials sharing an image: one call for all
        groups.setdefault(id(img), (img, []))[1].append(mi)
    for img, mis in groups.values():  # one exact average per texture
        sel = np.flatnonzero(np.isin(mats, mis))
        if len(sel):
            tex[sel] = images.average_over_triangles(img, scene.tri_uvs[sel], space=average)
    return np.clip(base * tex, 0.0, 1.0)


def albedo_provider(scene: Scene) -> np.ndarray:
    """The ``albedo`` artefact: the textured base colour of the scene's
    *current* triangles (exact after the lighting stage splits triangles), else
    ``scene.triangle_albedo()``; a ``face_albedo`` left over from a different triangle set is
    ignored."""
    ts = scene.artefacts.textures
    if isinstance(ts, TextureSet) and ts.albedo_images:
        return textured_albedo(scene, ts.albedo_images, ts.average)
    if scene.face_albedo is not None and len(scene.face_albedo) != scene.n_triangles:
        scene = scene.replace(face_albedo=None)
    return scene.triangle_albedo()


# --------------------------------------------------------------------------------------------
# loading


def _default_texture(scene: Scene, cfg: TexturesConfig) -> Path | None:
    if not cfg.texture:
        return None
    p = Path(cfg.texture).expanduser()
    if not p.is_absolute():
        base = scene.source.path.parent if scene.source.path is not None else Path.cwd()
        p = base / p
    if not p.is_file():
        raise InputError("textures.texture: image file not found", path=p)
    return p.resolve()


def _load_textures(scene: Scene, cfg: TexturesConfig, rec: StageRecord) -> tuple[Scene, list[Texture]]:
    by_digest: dict[str, Texture] = {}
    out: list[Texture] = []
    default = _default_texture(scene, cfg)
    if default is not None:
        mats = tuple(m if (m.texture is not None or m.texture_data is not None) else m.with_(texture=default)
                     for m in scene.materials)
        n = sum(1 for a, b in zip(mats, scene.materials) if a is not b)
        if n:
            rec.effects.append({"name": "default texture", "ran": True,
                                "reason": f"textures.texture = {cfg.texture!r} given to {n} material(s) "
                                          "without a texture"})
            files = scene.source.files_read + ((default,) if default not in scene.source.files_read else ())
            scene = scene.replace(materials=mats, source=dataclasses.replace(scene.source, files_read=files))
    for mi, m in enumerate(scene.materials):
        if m.texture is None and m.texture_data is None:
            continue
        src = m.texture_data if m.texture_data is not None else m.texture
        where = str(m.texture) if m.texture is not None else "embedded"
        try:
            img = images.load_rgba(src, name=m.texture if m.texture is not None else
                                   m.texture_source or f"material '{m.name}' image")
        except InputError as e:
            rec.warn(f"material '{m.name}': texture not used ({e}); the material keeps its colour")
            continue
        h = hashlib.sha256(np.asarray(img.shape, np.int64).tobytes() + img.tobytes()).hexdigest()
        if h in by_digest:
            by_digest[h].materials.append(mi)
            continue
        t = Texture(name=m.name, materials=[mi], source=where, original=img)
        by_digest[h] = t
        out.append(t)
    return scene, out


def _target_size(img: np.ndarray, cfg: TexturesConfig) -> tuple[int, int]:
    h, w = img.shape[:2]
    pot = None if cfg.power_of_two == "none" else cfg.power_of_two
    if cfg.width or cfg.height:
        tw = cfg.width or max(1, round(w * cfg.height / h))
        th = cfg.height or max(1, round(h * cfg.width / w))
        return images.fit_size(w, h, size=(tw, th), power_of_two=pot)
    return images.fit_size(w, h, max_size=cfg.max_size or None, power_of_two=pot)


# --------------------------------------------------------------------------------------------
# the stage


def idle_reason(scene: Scene, cfg: TexturesConfig) -> str:
    """Why the stage has nothing to do under ``enabled = "auto"`` ("" when it has): no material
    names a texture, no ``textures.texture`` is given and no lightmap atlas is asked for."""
    if cfg.enabled != "auto" or cfg.texture or cfg.lightmap.enabled:
        return ""
    if any(m.texture is not None or m.texture_data is not None for m in scene.materials):
        return ""
    return "textures.enabled = auto: no material of the model names a texture"


def stage(scene: Scene, cfg: TexturesConfig) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord(name="textures")
    check_config(cfg)
    rec.idle = idle_reason(scene, cfg)
    if rec.idle:
        rec.seconds = time.perf_counter() - t0
        return scene, rec
    T = scene.n_triangles
    scene, textures = _load_textures(scene, cfg, rec)
    used = set(np.unique(scene.tri_material).tolist()) if T else set()
    for t in textures:
        t.image = images.resample(t.original, _target_size(t.original, cfg), cfg.filter, wrap=cfg.wrap)

    # 1. per-triangle base colour
    albedo_images = {}
    for t in textures:
        for mi in t.materials:
            albedo_images[mi] = t.original if cfg.average_source == "original" else t.image
    tex_set = TextureSet(textures=textures, albedo_images=albedo_images, average=cfg.average)
    textured_tris = int(np.isin(scene.tri_material, list(albedo_images)).sum()) if T and albedo_images else 0
    if not cfg.bake_colors:
        rec.effects.append({"name": "colors", "ran": False, "reason": "textures.bake_colors = false"})
    elif not textures:
        rec.effects.append({"name": "colors", "ran": False, "reason": "no material has a usable texture"})
    elif scene.tri_uvs is None:
        rec.effects.append({"name": "colors", "ran": False, "reason": "the model has no UVs"})
        rec.warn("textured materials but no UVs: triangles keep their material colour")
    elif textured_tris == 0:
        rec.effects.append({"name": "colors", "ran": False, "reason": "no triangle uses a textured material"})
    else:
        ta = time.perf_counter()
        alb = textured_albedo(scene, albedo_images, cfg.average)
        scene = scene.replace(face_albedo=alb, face_colors=alb.copy())
        scene = scene.with_artefacts(textures=tex_set).with_artefacts(albedo=albedo_provider)
        rec.effects.append({"name": "colors", "ran": True, "seconds": round(time.perf_counter() - ta, 6),
                            "reason": f"texture mean over each triangle's UV area ({cfg.average}) x material "
                                      f"x vertex colour -> face_albedo, face_colors ({textured_tris} textured "
                                      "triangles)"})
    if scene.artefacts.textures is None:
        scene = scene.with_artefacts(textures=TextureSet(textures=textures, albedo_images={},
                                                           average=cfg.average))

    # 2. encodings
    costumes: list[tuple[str, bytes]] = list(scene.artefacts.costumes or [])
    written_lists: list[str] = []  # for the export's list choice: a texture in the project needs UVs
    details = []
    seen_names: set[str] = set(scene.lists)
    for t in textures:
        fmt = {"material": t.name}
        enc = encode_texture(t.name, t.image, list_name=cfg.list_name.format(**fmt),
                             size_list_name=cfg.size_list_name.format(**fmt),
                             textimage_list_name=cfg.textimage_list_name.format(**fmt),
                             costume_name=cfg.costume_name.format(**fmt), color_format=cfg.color_format,
                             first_row=cfg.first_row, textimage_alpha=cfg.textimage_alpha)
        t.encoded = enc
        written = {}
        for e in ENCODINGS:
            if e not in cfg.encodings:
                written[e] = "not requested (textures.encodings)"
                continue
            if e == "costume":
                if not enc.sizes["costume"]["under_asset_limit"]:
                    written[e] = "not written: the PNG is not under the 10 MB asset limit"
                    rec.warn(f"texture '{t.name}': PNG costume of {enc.sizes['costume']['asset_bytes']} bytes "
                             "is over the 10 MB asset limit; lower textures.max_size")
                    continue
                costumes.append(enc.costume)
                written[e] = "written"
                continue
            for lst in enc.lists[e]:
                if lst.name in seen_names:
                    raise ConfigError(f"texture list name '{lst.name}' is used twice; put {{material}} in "
                                      "the textures.*_name keys or rename the materials", key="textures.list_name")
                seen_names.add(lst.name)
                scene = scene.with_list(lst)
                written_lists.append(lst.name)
            written[e] = "written"
        H, W = t.image.shape[:2]
        details.append({
            "name": t.name, "materials": [scene.materials[i].name for i in t.materials],
            "used_by_triangles": any(i in used for i in t.materials), "source": t.source,
            "original_size": [int(t.original.shape[1]), int(t.original.shape[0])], "size": [W, H],
            "filter": cfg.filter, "opaque": bool((t.image[:, :, 3] == 255).all()),
            "encodings": {e: {**enc.sizes[e], "written": written[e]} for e in ENCODINGS},
        })
    if costumes:
        scene = scene.with_artefacts(costumes=costumes)
    scene = scene.with_artefacts(texture_outputs={"lists": written_lists,
                                                    "costumes": [c[0] for c in costumes]})
    rec.details["textures"] = details
    rec.details["size_table"] = size_table([t.encoded for t in textures])
    rec.counts_out = {"polygons": scene.n_polygons, "triangles": scene.n_triangles, "vertices": scene.n_vertices,
                      "materials": len(scene.materials), "textures": len(textures),
                      "textured_triangles": textured_tris if scene.face_albedo is not None else 0}

    # 3. lightmap atlas
    lm = cfg.lightmap
    if not lm.enabled:
        rec.effects.append({"name": "lightmap", "ran": False, "reason": "textures.lightmap.enabled = false"})
    elif T == 0:
        rec.effects.append({"name": "lightmap", "ran": False, "reason": "the scene has no triangles"})
    else:
        scene = _lightmap(scene, cfg, rec)
    rec.seconds = time.perf_counter() - t0
    return scene, rec


def _atlas_warnings(atlas, cfg: TexturesConfig, rec: StageRecord) -> None:
    """Say when xatlas grew the atlas past the requested resolution, and what the lightmap's lists
    will cost against Scratch's limits (known from the atlas size, before the lighting work)."""
    from ..scratch.limits import LIST_ITEM_LIMIT, PROJECT_JSON_LIMIT

    lm = cfg.lightmap
    W, H = atlas.width, atlas.height
    key = "textures.lightmap.resolution"
    if lm.texels_per_unit <= 0 and max(W, H) > lm.resolution:
        rec.warn(f"lightmap: xatlas made the atlas {W}x{H}, past {key} = {lm.resolution} even when asked for "
                 "less (the charts' padding does not fit in it); the lightmap lists and costume are that size. "
                 "Fewer, larger charts (a higher textures.lightmap.max_cost) or less textures.lightmap.padding "
                 "make it smaller")
    if not lm.lit or "list" not in cfg.encodings:
        return
    items = W * H
    if items > LIST_ITEM_LIMIT:
        side = int(math.isqrt(LIST_ITEM_LIMIT) / max(W, H) * lm.resolution) // 16 * 16
        rec.warn(f"lightmap: its colour list will have {items:,} items ({W}x{H}), past the {LIST_ITEM_LIMIT:,} "
                 f"of vanilla Scratch's `add to list`; use {key} <= {side} or drop \"list\" from "
                 "textures.encodings (the TextImage and costume encodings carry it too)")
    est = items * 9  # a colour number is up to 8 digits and a comma in project.json
    if est > PROJECT_JSON_LIMIT:
        rec.warn(f"lightmap: its colour list alone adds about {est / 1048576:.1f} MiB to project.json, past "
                 f"the 5 MiB upload limit; lower {key} or drop \"list\" from textures.encodings")


def _lightmap(scene: Scene, cfg: TexturesConfig, rec: StageRecord) -> Scene:
    from .lightmap import LightmapJob, coverage_figures
    from .memory import check_memory
    from .unwrap import unwrap

    lm = cfg.lightmap
    t0 = time.perf_counter()
    try:
        atlas = unwrap(scene, lm)
    except StageError as e:
        rec.fail(f"no lightmap: {e}")
        rec.effects.append({"name": "lightmap", "ran": False, "reason": str(e),
                            "seconds": round(time.perf_counter() - t0, 6)})
        return scene
    if atlas.retried_after:
        rec.warn(f"lightmap: xatlas crashed ({atlas.retried_after}) once on this mesh; a second run "
                 "succeeded and its atlas is used")
    _atlas_warnings(atlas, cfg, rec)
    # before any texel work (the covering below, the lighting stage's bake): will it fit in memory?
    mem = check_memory(atlas, lm, lit=lm.lit)
    if mem.get("warn"):
        rec.warn(f"lightmap: {mem.pop('warn')}")
    figs = coverage_figures(scene, atlas)
    figs.update(mem)
    figs.update({"xatlas_seconds": round(atlas.seconds, 6), "cached": atlas.cached, "key": atlas.key[:16],
                 "xatlas_version": atlas.xatlas_version, "texels_per_unit": atlas.texels_per_unit,
                 "xatlas_scale": atlas.xatlas_scale, "xatlas_retried_after": atlas.retried_after})
    if figs["triangles_unmapped"]:
        rec.warn(f"lightmap: xatlas left {figs['triangles_unmapped']} degenerate triangle(s) without UVs "
                 "(they get the texel at UV 0, 0)")
    if figs["texels_two_charts"]:
        rec.warn(f"lightmap: {figs['texels_two_charts']} texels are touched by two charts; raise "
                 "textures.lightmap.padding")
    # the export stage writes the list from tri_lightmap_uvs (in the final triangle order)
    scene = scene.replace(tri_lightmap_uvs=atlas.tri_uvs.copy())
    scene = scene.with_artefacts(lightmap=LightmapJob(atlas=atlas, config=lm, textures=cfg))
    rec.details["lightmap"] = figs
    rec.accuracy["lightmap coverage"] = figs["coverage"]
    rec.effects.append({"name": "lightmap", "ran": True, "seconds": round(time.perf_counter() - t0, 6),
                        "reason": f"xatlas atlas {atlas.width}x{atlas.height}, {atlas.chart_count} charts"
                                  + (" (cached)" if atlas.cached else "")})
    return scene


__all__ = ["stage", "albedo_provider", "textured_albedo", "TextureSet", "Texture", "check_config"]
