"""The colour pipeline of the light baker, and the pluggable albedo.

1. **Albedo** per triangle, RGBA in [0, 1] as Scratch shows colours (sRGB-encoded): by default
   the material colour times the triangle's mean vertex colour (``Scene.triangle_albedo``). A
   stage that knows better puts a provider in ``scene.artefacts.albedo`` (a function
   Scene -> (T, 4), re-evaluated for the current triangles, e.g. after subdivision): the
   textures stage's mean of the texture over each triangle's UV area. ``albedo=`` passed to the
   stage overrides both.
2. **Decode** to linear light (sRGB EOTF) when ``lighting.color_space = "srgb"`` (default);
   ``"linear"`` multiplies the shown values as they are (what many Scratch engines do at run
   time).
3. **Irradiance** ``E`` (linear RGB) = sum of lights + sky + ambient x AO + bounced light, in
   units where a white sun of intensity 1 at normal incidence gives ``E = 1`` (there is no 1/pi:
   ``E`` is the fraction of full light a white surface sends back).
4. ``linear colour = albedo_lin x E x exposure``.
5. **Tone map**: ``clamp`` (min(x, 1)) or ``reinhard`` (x / (1 + x)).
6. **Encode** (sRGB OETF) back to the shown values; alpha is the albedo's alpha. Never NaN.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..colorspace import linear_to_srgb, srgb_to_linear

AlbedoProvider = Callable[["object"], np.ndarray]  # Scene -> (T, 4) RGBA in [0, 1]


def triangle_albedo(scene, override: AlbedoProvider | None = None) -> np.ndarray:
    fn = override or scene.artefacts.albedo
    a = fn(scene) if fn is not None else scene.triangle_albedo()
    a = np.nan_to_num(np.asarray(a, dtype=np.float64), nan=0.0, posinf=1.0, neginf=0.0)
    if a.shape != (scene.n_triangles, 4):
        raise ValueError(f"albedo provider returned shape {a.shape}, expected ({scene.n_triangles}, 4)")
    return np.clip(a, 0.0, 1.0)


def decode(c: np.ndarray, space: str) -> np.ndarray:
    return srgb_to_linear(c) if space == "srgb" else np.clip(np.asarray(c, np.float64), 0.0, 1.0)


def encode(c: np.ndarray, space: str) -> np.ndarray:
    return linear_to_srgb(c) if space == "srgb" else np.clip(np.asarray(c, np.float64), 0.0, 1.0)


def tonemap(x: np.ndarray, mode: str) -> np.ndarray:
    x = np.nan_to_num(np.maximum(np.asarray(x, dtype=np.float64), 0.0), nan=0.0, posinf=1e30)
    if mode == "reinhard":
        return x / (1.0 + x)
    return np.minimum(x, 1.0)


def shade(albedo_lin_rgb: np.ndarray, irradiance: np.ndarray, exposure: float, tone: str,
          space: str) -> np.ndarray:
    """Shown RGB in [0, 1] for linear albedo and irradiance (both (N, 3))."""
    return encode(tonemap(albedo_lin_rgb * irradiance * exposure, tone), space)


def luminance(rgb: np.ndarray) -> np.ndarray:
    return np.asarray(rgb, dtype=np.float64) @ np.array([0.2126, 0.7152, 0.0722])
