"""The lightmap atlas: what the unwrap (``unwrap.py``) gives and every texel step reads.

Per-corner lightmap UVs use the same convention as ``tri_uvs``: ``(0, 0)`` is the bottom-left of
the image, ``v`` grows upward; the image is ``(H, W, C)`` with row 0 at the top, so texel
``(row i, column j)`` covers ``x = u * W`` in ``[j, j + 1)`` and ``y = (1 - v) * H`` in
``[i, i + 1)`` (:meth:`Atlas.texel_xy` gives the corners in that texel space).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Atlas:
    """An xatlas unwrap of a scene's triangles (in the scene's triangle order)."""

    width: int
    height: int
    tri_uvs: np.ndarray  # (T, 3, 2) float64 lightmap UVs per corner (v up, in [0, 1])
    chart: np.ndarray  # (T,) int64 chart id (triangles joined in the UV layout), -1 = not mapped
    key: str  # hash of xatlas's exact input and options (the cache key)
    chart_count: int = 0
    utilization: float = 0.0  # xatlas: fraction of the atlas covered by charts
    texels_per_unit: float = 0.0  # texels per model unit
    seconds: float = 0.0  # xatlas time when it ran (also kept for a cache hit)
    cached: bool = False
    xatlas_version: str = ""
    xatlas_scale: float = 1.0  # the power of two xatlas saw the (centred) model multiplied by
    retried_after: str = ""  # the signal of a first crashed xatlas run that a second run replaced

    @property
    def n_triangles(self) -> int:
        return int(len(self.tri_uvs))

    @property
    def mapped(self) -> np.ndarray:
        return self.chart >= 0

    def texel_xy(self) -> np.ndarray:
        """(T, 3, 2) corners in texel space: x = u W (right), y = (1 - v) H (down)."""
        xy = np.empty_like(self.tri_uvs)
        xy[..., 0] = self.tri_uvs[..., 0] * self.width
        xy[..., 1] = (1.0 - self.tri_uvs[..., 1]) * self.height
        return xy


def cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """The 2-D cross product of texel-space vectors (twice the signed area they span)."""
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
