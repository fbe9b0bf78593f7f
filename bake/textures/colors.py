"""Scratch colour numbers (shared/docs/scratch.md section 4c).

``set pen color to (n)`` reads n as ARGB: ``A*2^24 + R*65536 + G*256 + B``, where an alpha byte
of 0 means *opaque*. So plain RGB numbers (alpha byte 0) are opaque colours, and a colour with
alpha must use A in 1..255 (fully transparent cannot be expressed; it is written as A = 1).
"""

from __future__ import annotations

import numpy as np


def to_bytes(rgba: np.ndarray) -> np.ndarray:
    """Float colours in [0, 1] -> uint8, rounded to nearest, NaN treated as 0."""
    a = np.nan_to_num(np.asarray(rgba, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)


def scratch_numbers(rgba: np.ndarray, mode: str = "rgb") -> np.ndarray | list[str]:
    """Colour numbers for ``(N, 3|4)`` float colours.

    ``rgb``: ``R*65536 + G*256 + B`` (opaque). ``argb``: ``A*2^24 + RGB`` with A = 0 (opaque)
    written as 255 and A clamped to >= 1 so transparency survives. ``hex``: ``#rrggbb`` strings.
    """
    b = to_bytes(rgba).astype(np.int64)
    if b.ndim != 2 or b.shape[1] not in (3, 4):
        raise ValueError(f"expected (N, 3) or (N, 4) colours, got {b.shape}")
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
