"""One texture, three ways into Scratch, and what each costs.

* **colour list** (``"list"``): one Scratch colour number per pixel (``colors.image_to_list``:
  ``rgb`` / ``argb`` / ``hex``, top or bottom row first) plus a 2-item size list ``[W, H]``.
  Lives in project.json; any pixel can be read at run time (exact projection).
* **TextImage** (``"textimage"``): the image as one TextImage v0 string in a one-item string list
  (``textimage.encode``). Also project.json, usually far smaller than the colour list, but the
  project must decode it (once, at load) and it cannot go through the list-import GUI (commas,
  shared/docs/scratch.md section 3).
* **PNG costume** (``"costume"``): the image as a PNG, meant for ``bitmapResolution: 2``
  (shared/docs/scratch.md section 1). Outside project.json (an asset, each < 10 MB); drawn by
  stamping, so only what the renderer can do with a costume.

:func:`encode_texture` builds all three and :func:`sizes` measures them the same way for each:
``items`` (list items), ``project_json_bytes`` (what the entry adds to project.json, hidden
monitor, as ``bake/export/lists.py`` counts it), ``asset_bytes`` (files beside project.json) and
``deflated_bytes`` (roughly what the entry adds to the zipped .sb3).
"""

from __future__ import annotations

import io
import json
import zlib
from dataclasses import dataclass, field
from typing import Literal

import numpy as np
from PIL import Image

from ..scene import ScratchList
from ..scratch import colors, sb3, textimage
from ..scratch.limits import ASSET_LIMIT
from ..scratch.numbers import json_array, project_json_bytes, render_items

ENCODINGS = ("list", "textimage", "costume")
BITMAP_RESOLUTION = 2


def png_bytes(image: np.ndarray) -> bytes:
    """Deterministic PNG of an (H, W, 4) uint8 image (RGB when every pixel is opaque)."""
    img = np.asarray(image, dtype=np.uint8)
    if img.shape[2] == 4 and bool((img[:, :, 3] == 255).all()):
        img = img[:, :, :3]
    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img)).save(buf, format="PNG", compress_level=9)
    return buf.getvalue()


def costume_entry(name: str, png: bytes, width: int, height: int) -> dict:
    """The project.json costume object for a texture PNG at bitmapResolution 2 (rotation centre
    in the middle, in image pixels as Scratch stores it)."""
    c = sb3.Costume(name, sb3.Asset(png, "png"), BITMAP_RESOLUTION, (width / 2.0, height / 2.0))
    return c.to_json()


@dataclass
class EncodedTexture:
    """A texture's lists and costume, with the size of each encoding."""

    name: str  # the texture's name (its first material)
    image: np.ndarray  # (H, W, 4) uint8, the resampled texture
    lists: dict[str, list[ScratchList]] = field(default_factory=dict)  # encoding -> its lists
    costume: tuple[str, bytes] | None = None
    sizes: dict[str, dict] = field(default_factory=dict)  # encoding -> figures
    first_row: str = "bottom"  # the colour list's first row: the image's "bottom" or "top"


def _list_cost(lst: ScratchList) -> tuple[int, int, int]:
    items = render_items(lst)
    arr = json_array(items, "string" if lst.kind == "string" else "number")
    entry = project_json_bytes(lst.name, arr)
    return len(items), entry, len(zlib.compress(arr.encode("utf-8"), 6))


def encode_texture(name: str, image: np.ndarray, *, list_name: str, size_list_name: str,
                   textimage_list_name: str, costume_name: str,
                   color_format: Literal["rgb", "argb", "hex"] = "rgb",
                   first_row: Literal["top", "bottom"] = "bottom",
                   textimage_alpha: Literal["auto", "always", "never"] = "auto") -> EncodedTexture:
    """All three encodings of ``image`` ((H, W, 4) uint8, row 0 at the top) and their sizes."""
    img = np.ascontiguousarray(np.asarray(image, dtype=np.uint8))
    H, W = img.shape[:2]
    out = EncodedTexture(name=name, image=img, first_row=first_row)

    vals = colors.image_to_list(img, color_format, first_row=first_row)
    if color_format == "hex":
        pix = ScratchList(list_name, tuple(vals), 1, f"texture '{name}': #rrggbb per pixel, {first_row} row "
                          f"first, {W}x{H}", "string")
    else:
        pix = ScratchList(list_name, np.asarray(vals, dtype=np.int64), 1,
                          f"texture '{name}': {color_format} colour number per pixel, {first_row} row first, "
                          f"{W}x{H}", "int")
    size = ScratchList(size_list_name, np.array([W, H], dtype=np.int64), 2,
                       f"texture '{name}': width, height", "int")
    out.lists["list"] = [pix, size]

    alpha = {"auto": "auto", "always": True, "never": False}[textimage_alpha]
    text = textimage.encode(img, alpha=alpha)
    out.lists["textimage"] = [ScratchList(textimage_list_name, (text,), 1,
                                          f"texture '{name}': TextImage v0, {W}x{H}", "string")]

    png = png_bytes(img)
    out.costume = (costume_name, png)

    items = bytes_ = defl = 0
    for lst in out.lists["list"]:
        i, b, d = _list_cost(lst)
        items, bytes_, defl = items + i, bytes_ + b, defl + d
    out.sizes["list"] = {"items": items, "project_json_bytes": bytes_, "asset_bytes": 0,
                         "deflated_bytes": defl}
    i, b, d = _list_cost(out.lists["textimage"][0])
    out.sizes["textimage"] = {"items": i, "project_json_bytes": b, "asset_bytes": 0, "deflated_bytes": d,
                              "chars": len(text), "chars_per_pixel": round(len(text) / (W * H), 4)}
    entry = json.dumps(costume_entry(costume_name, png, W, H), ensure_ascii=False, separators=(",", ":"))
    out.sizes["costume"] = {"items": 0, "project_json_bytes": len(entry.encode("utf-8")) + 1,
                            "asset_bytes": len(png), "deflated_bytes": len(zlib.compress(png, 6)),
                            "under_asset_limit": len(png) < ASSET_LIMIT}
    return out


def size_table(textures: list[EncodedTexture]) -> list[dict]:
    """One row per texture and encoding (for the record and the docs)."""
    rows = []
    for t in textures:
        H, W = t.image.shape[:2]
        for enc in ENCODINGS:
            s = t.sizes[enc]
            rows.append({"texture": t.name, "size": f"{W}x{H}", "encoding": enc, "items": s["items"],
                         "project_json_bytes": s["project_json_bytes"], "asset_bytes": s["asset_bytes"],
                         "deflated_bytes": s["deflated_bytes"]})
    return rows
