"""Ambient occlusion: the cosine-weighted fraction of the hemisphere that is open within
``distance`` (a fraction of the bbox diagonal). Shadow-ray (any-hit) queries, bounded in length."""

from __future__ import annotations

import numpy as np

from .kernel import SALT_AO, Context, EffectStats, as32, drive
from .sampling import cosine_directions, frames, mean_and_se, multi_jittered, point_shifts
from .targets import Points


def ambient_occlusion(ctx: Context, pts: Points, samples: int, distance: float, strength: float,
                      stats: EffectStats) -> tuple[np.ndarray, np.ndarray]:
    """AO in [0, 1] per point (1 = open) and its standard error. ``distance`` is absolute."""
    P = len(pts)
    out = np.ones(P)
    se = np.zeros(P)
    if P == 0:
        return out, se
    pattern = multi_jittered(samples, ctx.seed, SALT_AO)
    N = pattern.n
    su, sv = point_shifts(pts.key, ctx.seed, SALT_AO)
    t, b = frames(pts.nrm, sv)
    n32, t32, b32 = as32(pts.nrm), as32(t), as32(b)
    org = ctx.tracer.origins(pts.pos, pts.nrm)
    su32 = su.astype(np.float32)

    def work(i0: int, i1: int, clock) -> None:
        with clock("generate"):
            d, _ = cosine_directions(pattern, n32[i0:i1], t32[i0:i1], b32[i0:i1], su32[i0:i1])
            o = np.repeat(org[i0:i1], N, axis=0)
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
