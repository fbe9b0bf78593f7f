"""Lightmaps: one texel bake over an xatlas atlas, and the job the textures stage leaves for it.

The pieces, each in its module of ``bake/textures/``, in the order a bake uses them:

* ``unwrap.py``: :func:`~bake.textures.unwrap.unwrap` -> :class:`~bake.textures.atlas.Atlas`
  (``atlas.py``: the UVs per corner, the charts, texel space): xatlas charts and packs the mesh
  in a subprocess with a timeout (``xatlas_worker.py``), seen centred and at a size xatlas handles
  well, asked again for less until the atlas fits the resolution; ``unwrap_cache.py`` keeps the
  result by a hash of the exact input and options (default ``.bake-cache/xatlas`` in the output
  folder), so a rerun is fast and gives identical UVs.
* ``memory.py``: :func:`~bake.textures.memory.check_memory`, before any texel work, refuses an
  atlas whose bake would not fit in what this process may still use (/proc, the cgroup).
* ``texels.py``: the (triangle, texel) pairs that overlap (conservative rasterisation), the
  sample points of each texel, :func:`~bake.textures.texels.push_out` of samples inside or behind
  geometry, then the weighted mean per texel (``splat``), rings of padding (``dilate``) and
  bilinear lookups.
* ``seams.py``: UV seams on smooth geometry sampled on both sides and stitched by a sparse
  least-squares solve, so bilinear lookups agree across them.
* here: :func:`bake`, the texel and seam steps over an atlas for a shading function
  ``f(points, normals, tri_ids) -> (N, C)``, its :func:`coverage_figures`, and the
  :class:`LightmapJob` the textures stage leaves in ``scene.artefacts.lightmap``.

The light baker supplies the shading function: ``bake.lighting.lightmap.light_function`` builds
one from the lighting stage's own kernels (lights, sky, AO, a final gather of bounced light), and
``lighting.target = "lightmap"`` runs it over the atlas the textures stage unwraps.
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import Callable

import numpy as np

from ..config import LightmapConfig
from ..scene import Scene
from .atlas import Atlas
from .seams import Seams, seam_edges, seam_error, stitch_seams
from .texels import TexelSamples, cover, dilate, face_normals, splat, texel_mask, texel_samples


@dataclass
class LightmapBake:
    image: np.ndarray  # (H, W, C) float64
    mask: np.ndarray  # (H, W) covered texels (before dilation)
    samples: TexelSamples
    seams: Seams
    figures: dict


Shader = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def bake(scene: Scene, atlas: Atlas, shade: Shader, cfg: LightmapConfig, *, tracer=None) -> LightmapBake:
    """Samples -> ``shade(points, normals, tri_ids)`` -> splat -> dilate -> stitch seams.

    ``figures``: texel counts, coverage, samples pushed, seam error before and after stitching
    (in the shader's units), seconds per step.
    """
    t0 = time.perf_counter()
    smp = texel_samples(scene, atlas, supersample=cfg.supersample, push=cfg.push_out, tracer=tracer)
    t1 = time.perf_counter()
    vals = np.asarray(shade(smp.points, smp.normals, smp.tri_ids), dtype=np.float64)
    vals = np.nan_to_num(vals.reshape(len(smp), -1), nan=0.0, posinf=0.0, neginf=0.0)
    t2 = time.perf_counter()
    img = splat(vals, smp.texel_index, smp.weights, atlas)
    if img.ndim == 2:
        img = img[:, :, None]
    mask = texel_mask(smp.texel_index, smp.weights, atlas)
    img, filled = dilate(img, mask, cfg.dilate)
    seams = seam_edges(scene, atlas)
    before = seam_error(img, atlas, seams)
    if cfg.stitch_seams:
        img = stitch_seams(img, mask, atlas, seams)  # covered texels weigh more than padding
    after = seam_error(img, atlas, seams)
    t3 = time.perf_counter()
    figs = coverage_figures(scene, atlas, smp)
    figs.update({
        "samples": int(len(smp)), "samples_pushed": int(smp.pushed.sum()),
        "seam_edges": int(seams.count_all), "seam_edges_smooth": int(seams.smooth.sum()),
        "seam_error_before": before["max"], "seam_error": after["max"], "seam_error_mean": after["mean"],
        "seconds_samples": round(t1 - t0, 6), "seconds_shade": round(t2 - t1, 6),
        "seconds_splat_dilate_stitch": round(t3 - t2, 6),
    })
    return LightmapBake(image=img, mask=mask, samples=smp, seams=seams, figures=figs)


def coverage_figures(scene: Scene, atlas: Atlas, smp: TexelSamples | None = None) -> dict:
    """Texels covered, triangles with samples, texels claimed by two charts, utilisation."""
    if smp is None:
        t, x = cover(atlas)
        w = np.ones(len(t))
    else:
        t, x, w = smp.tri_ids, smp.texel_index, smp.weights
    n = atlas.width * atlas.height
    covered = np.bincount(x, weights=w, minlength=n) > 0
    mapped = atlas.mapped
    _, area = face_normals(scene.positions, scene.triangles)
    real = mapped & (area > 0)
    has = np.zeros(scene.n_triangles, bool)
    has[t] = True
    # texels reached by triangles of two different charts (bleeding between charts)
    ch = atlas.chart[t]
    lo = np.full(n, np.iinfo(np.int64).max)
    hi = np.full(n, -1)
    np.minimum.at(lo, x, ch)
    np.maximum.at(hi, x, ch)
    conflicts = int(((hi >= 0) & (lo != hi)).sum())
    return {"atlas_width": atlas.width, "atlas_height": atlas.height, "charts": atlas.chart_count,
            "utilization_xatlas": round(atlas.utilization, 6),
            "texels_covered": int(covered.sum()), "coverage": round(float(covered.sum()) / n, 6),
            "triangles_unmapped": int((~mapped).sum()),
            "triangles_without_samples": int((real & ~has).sum()),
            "texels_two_charts": conflicts}


# --------------------------------------------------------------------------------------------
# the job the textures stage leaves for the lighting stage's lightmap target


@dataclass
class LightmapJob:
    """``scene.artefacts.lightmap``, left by the textures stage for the lighting stage."""

    atlas: Atlas
    config: LightmapConfig
    textures: object  # the TexturesConfig: encodings and list names for the lightmap image
