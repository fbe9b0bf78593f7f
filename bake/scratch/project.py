"""Scratch project outputs of a bake: the fresh .sb3, the .sprite3 and the bake into an author's .sb3.

Called by the export stage (``bake/export/lists.py``) with the lists as they are written
(name -> JSON items). With the reader on (``export.reader``), the fresh ``<model>.sb3`` holds the
lists on the stage plus the reader sprite (its green flag draws the model), and the
``<model>.sprite3`` is the reader sprite with the lists local to it and no green-flag script, so it
can be dropped into any project with "Upload Sprite".
"""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import ConfigError, InputError
from . import sb3
from . import readers


def _cfg(cfg: Any, key: str, default: Any) -> Any:
    return getattr(cfg, key, default)


def look_at(pos, target, *, focal: float = 300.0, near: float = 0.01) -> readers.Camera:
    """A reader camera at ``pos`` looking at ``target`` (yaw/pitch in degrees, rounded to 0.01)."""
    f = np.asarray(target, np.float64) - np.asarray(pos, np.float64)
    yaw = math.degrees(math.atan2(f[0], f[2]))
    pitch = math.degrees(math.atan2(f[1], math.hypot(f[0], f[2])))
    return readers.Camera(x=float(pos[0]), y=float(pos[1]), z=float(pos[2]), yaw=round(yaw, 2),
                          pitch=round(pitch, 2), focal=focal, near=near)


def auto_camera(verts: list[float] | np.ndarray) -> readers.Camera:
    """A camera in front of, above and left of the model, looking at its centre, far enough for
    the whole model to fit the 480x360 stage with the default focal length."""
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    if len(v) == 0:
        return readers.Camera()
    lo, hi = v.min(axis=0), v.max(axis=0)
    c = (lo + hi) / 2
    diag = float(np.linalg.norm(hi - lo)) or 1.0
    f = np.array([0.45, -0.4, 1.0])
    f /= np.linalg.norm(f)
    pos = [float(f"{x:.4g}") for x in c - f * 0.95 * diag]
    return look_at(pos, c, near=float(f"{diag * 1e-3:.4g}"))


def _bvh_spec(scene: Any, values: dict[str, list]) -> readers.BVHSpec | None:
    art = scene.artefacts.get("bvh") if scene is not None else None
    if not art or "encoded" not in art:
        return None
    enc = art["encoded"]
    names = art.get("lists")
    if not names:
        # the BVH stage names its lists "<prefix> nodes/tris/tri ids" and documents the layout
        nodes = next((n for n, lst in scene.lists.items() if n.endswith(" nodes")
                      and str(getattr(lst, "doc", "")).startswith("BVH (")), None)
        if nodes is None:
            return None
        prefix = nodes[: -len(" nodes")]
        names = {"nodes": nodes, "tris": f"{prefix} tris", "ids": f"{prefix} tri ids"}
    if not all(n in values for n in names.values()):
        return None
    return readers.BVHSpec(bary=tuple(art["bary"]), layout=enc.layout, bits=int(enc.bits or 0), nodes=names["nodes"],
                           tris=names["tris"], ids=names["ids"])


def reader_spec(scene: Any, cfg: Any, values: dict[str, list]) -> readers.ReaderSpec:
    """What the reader can read in these lists."""
    n = cfg.names
    mesh = None
    if n.vertices in values and n.triangles in values:
        mesh = readers.MeshNames(verts=n.vertices, tris=n.triangles,
                                 mat_colors=n.materials if n.materials in values else None,
                                 tri_colors=n.triangle_colors if n.triangle_colors in values else None)
    cam = auto_camera(values[n.vertices]) if mesh else readers.Camera()
    return readers.ReaderSpec(mesh=mesh, bvh=_bvh_spec(scene, values), bsp=_bsp_spec(scene, values),
                              textimage=True, renderer=True, camera=cam)


def _bsp_spec(scene: Any, values: dict[str, list]) -> readers.BSPSpec | None:
    art = scene.artefacts.get("bsp") if scene is not None else None
    if not art:
        return None
    nodes, planes = art.get("nodes", "bsp nodes"), art.get("planes", "bsp planes")
    if nodes not in values or planes not in values:
        return None
    return readers.BSPSpec(nodes=nodes, planes=planes,
                           two_sided=[1 if getattr(m, "double_sided", False) else 0 for m in scene.materials])


def texture_costumes(scene: Any) -> list[sb3.Costume]:
    """The textures stage's PNG costumes (``artefacts["costumes"]``: (name, png bytes)) as
    bitmapResolution-2 costumes centred on the image (sizes read from the PNG header)."""
    out = []
    for cname, png in scene.artefacts.get("costumes", []) or []:
        w = int.from_bytes(png[16:20], "big") if png[:8] == b"\x89PNG\r\n\x1a\n" else 2
        h = int.from_bytes(png[20:24], "big") if png[:8] == b"\x89PNG\r\n\x1a\n" else 2
        out.append(sb3.Costume(cname, sb3.Asset(png, "png"), 2, (w / 2.0, h / 2.0)))
    return out


def project_outputs(scene: Any, cfg: Any, values: dict[str, list], name: str,
                    record: Any = None) -> tuple[dict[str, bytes], list[Path]]:
    """The .sb3 / .sprite3 files of a bake (relative name -> bytes) and the extra input files
    read (the project baked into)."""
    files: dict[str, bytes] = {}
    read: list[Path] = []
    want_reader = bool(_cfg(cfg, "reader", True))
    spec = reader_spec(scene, cfg, values) if want_reader else None
    details = record.details if record is not None else {}
    costumes = texture_costumes(scene)
    if cfg.sb3:
        sb3_name = _cfg(cfg, "sb3_name", "") or f"{name}.sb3"
        if spec is not None:
            sprite = readers.reader_target(spec, cfg.sprite_name, stage_lists=list(values), demo=True)
        else:
            sprite = sb3.Target(cfg.sprite_name, layer_order=1)
        targets = [sb3.Target("Stage", is_stage=True, lists=values), sprite]
        if costumes:  # the texture costumes, in a hidden sprite of their own for stamping engines
            targets.append(sb3.Target("Textures", costumes=list(costumes), layer_order=2, visible=False))
        data, pj_bytes = sb3.write_sb3(targets)
        files[sb3_name] = data
        details["project_json_bytes"] = pj_bytes
        details["sb3_assets"] = sb3.archive_sizes(data)["assets"]
    if cfg.sprite3:
        if spec is not None:
            # no green-flag script: a sprite dropped into an engine must not start drawing on its own
            sprite = readers.reader_target(spec, cfg.sprite_name, local_lists=values)
        else:
            sprite = sb3.Target(cfg.sprite_name, lists=values)
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
        if _cfg(cfg, "into_reader", False) and spec is not None:
            if target != "Stage":
                if record is not None:
                    record.warn("export.into_reader needs export.into_target = \"Stage\" "
                                "(a sprite cannot read another sprite's lists): reader not added")
            else:
                sprites.append(readers.reader_target(spec, cfg.sprite_name, stage_lists=list(values)))
        data = sb3.merge_into(src, target, values, costumes, sprites=sprites)
        files[out_name] = data
        sizes = sb3.archive_sizes(data)
        details["into"] = {"project": str(src), "target": target, "file": out_name,
                           "project_json_bytes": sizes["project_json_bytes"], "assets": sizes["assets"]}
        # the report measures the project the author will upload
        details["project_json_bytes"] = sizes["project_json_bytes"]
        read.append(src)
    return files, read
