"""Ambient occlusion: the cosine-weighted fraction of the hemisphere that is open within
``distance`` (a fraction of the bbox diagonal). Shadow-ray (any-hit) queries, bounded in length."""

from __future__ import annotations

import numpy as np

from .kernel import SALT_AO, Context, EffectStats, drive, hemisphere
from .sampling import mean_and_se
from .targets import Points


def ambient_occlusion(ctx: Context, pts: Points, samples: int, distance: float, strength: float,
                      stats: EffectStats) -> tuple[np.ndarray, np.ndarray]:
    """AO in [0, 1] per point (1 = open) and its standard error. ``distance`` is absolute."""
    P = len(pts)
    out = np.ones(P)
    se = np.zeros(P)
    if P == 0:
        return out, se
    hemi = hemisphere(ctx, pts, samples, SALT_AO)
    N = hemi.N

    def work(i0: int, i1: int, clock) -> None:
        with clock("generate"):
            o, d = hemi.rays(i0, i1)
        with clock("trace"):
            occ = ctx.tracer.occluded(o, d, distance)
        with clock("shade"):
            f = occ.reshape(i1 - i0, N).astype(np.float32)
            m, s = mean_and_se(f, 1.0)
            out[i0:i1] = 1.0 - m
            se[i0:i1] = s

    drive(ctx, stats, P, N, work)
    stats.samples = N
    stats.rays += P * N
    if strength != 1.0:
        out = 1.0 - strength * (1.0 - out)
        se = se * strength
    stats.add_error(se, strength / N)
    return out, se
