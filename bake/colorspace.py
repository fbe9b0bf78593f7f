"""Colour spaces: sRGB-encoded values (what Scratch shows, OBJ Kd, image texels) and linear light.

Shared by the importers (glTF factors are linear), the textures stage and the lighting stage; the
Scratch colour numbers built from these values live in :mod:`bake.scratch.colors`.
"""

from __future__ import annotations

import numpy as np


def srgb_to_linear(c: np.ndarray) -> np.ndarray:
    """sRGB-encoded values in [0, 1] (what Scratch shows, OBJ Kd, image texels) to linear light."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    return np.where(c <= 0.04045, c / 12.92, ((c + 0.055) / 1.055) ** 2.4)


def linear_to_srgb(c: np.ndarray) -> np.ndarray:
    """Linear light in [0, 1] (glTF factors and COLOR_0, lighting sums) to sRGB-encoded values."""
    c = np.clip(np.asarray(c, dtype=np.float64), 0.0, 1.0)
    out = np.where(c <= 0.0031308, c * 12.92, 1.055 * np.power(c, 1 / 2.4) - 0.055)
    return np.where(c >= 1.0, 1.0, out)  # exact white (1.055 - 0.055 rounds below 1)


def to_bytes(rgba: np.ndarray) -> np.ndarray:
    """Float colours in [0, 1] -> uint8, rounded to nearest, NaN treated as 0."""
    a = np.nan_to_num(np.asarray(rgba, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    return np.clip(np.rint(a * 255.0), 0, 255).astype(np.uint8)
