"""Scratch colour numbers (shared/docs/scratch.md section 4c) and image <-> colour lists.

``set pen color to (n)`` reads n as ARGB: ``A*2^24 + R*65536 + G*256 + B``, where an alpha byte
of 0 means *opaque*. So plain RGB numbers (alpha byte 0) are opaque colours, and a colour with
alpha must use A in 1..255 (fully transparent cannot be expressed; it is written as A = 1).

Modes used everywhere in this module:

* ``"rgb"``: ``R*65536 + G*256 + B`` (opaque; alpha is dropped). Img2list mode ``dc1``.
* ``"argb"``: ``A*2^24 + R*65536 + G*256 + B`` with A clamped to 1..255, so a fully transparent
  pixel becomes A = 1 (99.6 % pen transparency) instead of A = 0 (which Scratch draws opaque).
  Img2list's ``dc3`` differs only there: it writes A = 0 for transparent pixels.
* ``"hex"``: ``"#rrggbb"`` strings (opaque). Img2list mode ``ic1``.

Image lists are written one item per pixel, each row left to right; ``first_row`` says which row
comes first: ``"top"`` (Img2list, canvas ``getImageData`` order) or ``"bottom"`` (TextImage,
Scratch's y-up order).
"""

from __future__ import annotations

import math
import re
from typing import Iterable, Literal

import numpy as np

from ..colorspace import to_bytes

ColorMode = Literal["rgb", "argb", "hex"]
FirstRow = Literal["top", "bottom"]
MODES = ("rgb", "argb", "hex")
FIRST_ROWS = ("top", "bottom")


def numbers_from_bytes(rgba: np.ndarray, mode: ColorMode = "rgb") -> np.ndarray | list[str]:
    """Colour numbers for ``(N, 3|4)`` uint8 colours (see the module docstring for ``mode``).

    ``rgb`` / ``argb`` give an int64 array; ``hex`` a list of ``#rrggbb`` strings.
    """
    b = np.asarray(rgba)
    if b.ndim != 2 or b.shape[1] not in (3, 4):
        raise ValueError(f"expected (N, 3) or (N, 4) colours, got {b.shape}")
    if not np.issubdtype(b.dtype, np.integer):
        raise ValueError(f"expected 0..255 integer colours, got {b.dtype} "
                         "(floats in [0, 1]: use scratch_numbers)")
    b = b.astype(np.int64)
    rgb = (b[:, 0] << 16) | (b[:, 1] << 8) | b[:, 2]
    if mode == "rgb":
        return rgb
    if mode == "argb":
        alpha = b[:, 3] if b.shape[1] == 4 else np.full(len(b), 255, np.int64)
        alpha = np.maximum(alpha, 1)
        return (alpha << 24) | rgb
    if mode == "hex":
        return [f"#{v:06x}" for v in rgb.tolist()]
    raise ValueError(f"unknown colour mode {mode!r}")


def scratch_numbers(rgba: np.ndarray, mode: ColorMode = "rgb") -> np.ndarray | list[str]:
    """Colour numbers for ``(N, 3|4)`` float colours.

    ``rgb``: ``R*65536 + G*256 + B`` (opaque). ``argb``: ``A*2^24 + RGB`` with A = 0 (opaque)
    written as 255 and A clamped to >= 1 so transparency survives. ``hex``: ``#rrggbb`` strings.
    """
    return numbers_from_bytes(to_bytes(rgba), mode)


# --------------------------------------------------------------------------------------------
# images <-> lists


def _check_first_row(first_row: str) -> None:
    if first_row not in FIRST_ROWS:
        raise ValueError(f"first_row must be 'top' or 'bottom', got {first_row!r}")


def image_to_list(image: np.ndarray, mode: ColorMode = "rgb",
                  first_row: FirstRow = "top") -> np.ndarray | list[str]:
    """``(H, W, 3|4)`` uint8 image (row 0 at the top) -> ``H*W`` colour list items.

    One item per pixel, each row left to right, starting with the top row (``first_row="top"``,
    Img2list order) or the bottom row (``"bottom"``, TextImage / Scratch y-up order). Item ``i``
    is pixel ``(x, y) = (i % W, i // W)`` counted from that first row.
    """
    _check_first_row(first_row)
    a = np.asarray(image)
    if a.dtype != np.uint8:
        raise ValueError(f"expected a uint8 image, got {a.dtype} (floats: use bake.colorspace.to_bytes)")
    if a.ndim != 3 or a.shape[2] not in (3, 4):
        raise ValueError(f"expected an (H, W, 3) or (H, W, 4) image, got shape {a.shape}")
    if first_row == "bottom":
        a = a[::-1]
    return numbers_from_bytes(a.reshape(-1, a.shape[2]), mode)


def list_to_image(items: Iterable[object] | np.ndarray, width: int, height: int,
                  first_row: FirstRow = "top") -> np.ndarray:
    """Inverse of :func:`image_to_list`: list items -> ``(H, W, 4)`` uint8 image, row 0 at top.

    Each item is read the way Scratch's ``set pen color to`` reads it (:func:`scratch_color`),
    so the mode does not need to be given; ``rgb`` and ``hex`` items come back opaque and an
    ``argb`` item written for a fully transparent pixel comes back with alpha 1.
    """
    _check_first_row(first_row)
    rgba = decode_numbers(items)
    if len(rgba) != width * height:
        raise ValueError(f"{len(rgba)} list items for a {width}x{height} image "
                         f"({width * height} pixels)")
    img = rgba.reshape(height, width, 4)
    return np.ascontiguousarray(img[::-1]) if first_row == "bottom" else img


# --------------------------------------------------------------------------------------------
# how Scratch reads a colour (scratch-vm Cast.toRgbColorObject, Color.decimalToRgb/hexToRgb)

_HEX6 = re.compile(r"#?([0-9a-fA-F]{2})([0-9a-fA-F]{2})([0-9a-fA-F]{2})")
_HEX3 = re.compile(r"#?([0-9a-fA-F])([0-9a-fA-F])([0-9a-fA-F])")
_JS_DECIMAL = re.compile(r"[+-]?(?:[0-9]+\.?[0-9]*|\.[0-9]+)(?:[eE][+-]?[0-9]+)?")
_JS_RADIX = re.compile(r"0([xXoObB])([0-9a-zA-Z]+)")
_JS_SPACE = " \t\n\r\x0b\x0c\xa0\ufeff\u1680\u2000\u2001\u2002\u2003\u2004\u2005\u2006\u2007" \
            "\u2008\u2009\u200a\u2028\u2029\u202f\u205f\u3000"


def js_to_number(value: object) -> float:
    """Scratch's ``Cast.toNumber``: JavaScript ``Number(value)``, with NaN read as 0."""
    if isinstance(value, bool):
        return float(value)
    if isinstance(value, (int, float, np.integer, np.floating)):
        v = float(value)
        return 0.0 if math.isnan(v) else v
    s = str(value).strip(_JS_SPACE)
    if s == "":
        return 0.0
    if s in ("Infinity", "+Infinity"):
        return math.inf
    if s == "-Infinity":
        return -math.inf
    if _JS_DECIMAL.fullmatch(s):
        return float(s)
    m = _JS_RADIX.fullmatch(s)
    if m:
        base = {"x": 16, "o": 8, "b": 2}[m.group(1).lower()]
        try:
            return float(int(m.group(2), base))
        except ValueError:
            return 0.0
    return 0.0


def _to_uint32(v: float) -> int:
    """JavaScript ToInt32 (as used by ``>>``), returned as its unsigned 32-bit pattern."""
    if not math.isfinite(v):
        return 0
    return int(math.trunc(v)) % (1 << 32)


def scratch_color(value: object) -> tuple[int, int, int, int]:
    """``(r, g, b, a)`` bytes that ``set pen color to (value)`` uses (a = 255 means opaque).

    A string starting with ``#`` must be ``#rgb`` or ``#rrggbb`` (else black, opaque); anything
    else is a number ``A*2^24 + R*65536 + G*256 + B`` (via ToInt32, so ``-1`` is white and
    ``4278190335`` is opaque blue) where alpha byte 0 means opaque.
    """
    if isinstance(value, str) and value[:1] == "#":
        s = value
        m = _HEX3.fullmatch(s)
        if m:
            s = "".join(c + c for c in m.groups())
        m = _HEX6.fullmatch(s)
        if not m:
            return (0, 0, 0, 255)
        return (int(m.group(1), 16), int(m.group(2), 16), int(m.group(3), 16), 255)
    u = _to_uint32(js_to_number(value))
    a = (u >> 24) & 255
    return ((u >> 16) & 255, (u >> 8) & 255, u & 255, a if a > 0 else 255)


def decode_numbers(items: Iterable[object] | np.ndarray) -> np.ndarray:
    """Colour list items -> ``(N, 4)`` uint8 RGBA, each read like :func:`scratch_color`.

    Integer arrays take a vectorised path; other items (strings, mixed lists) are read one by one.
    """
    if isinstance(items, np.ndarray) and np.issubdtype(items.dtype, np.integer):
        u = items.reshape(-1).astype(np.int64) % (1 << 32)
        a = (u >> 24) & 255
        out = np.stack([(u >> 16) & 255, (u >> 8) & 255, u & 255, np.where(a > 0, a, 255)], axis=1)
        return out.astype(np.uint8)
    values = items.reshape(-1).tolist() if isinstance(items, np.ndarray) else list(items)
    return np.array([scratch_color(v) for v in values], dtype=np.uint8).reshape(-1, 4)
