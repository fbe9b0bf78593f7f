"""Sky light: a dome whose radiance goes from ``horizon`` (at the horizon) to ``color`` (straight
up, +y), and is ``ground`` below the horizon (a stand-in for the ground the model stands on),
all times ``intensity``. Cosine-weighted unbounded rays; a uniform white sky of intensity 1 over
an open upward plane gives E = 1."""

from __future__ import annotations

import numpy as np

from .color import luminance
from .kernel import SALT_SKY, Context, EffectStats, drive, hemisphere
from .sampling import mean_and_se
from .targets import Points


def sky_light(ctx: Context, pts: Points, samples: int, zenith: np.ndarray, horizon: np.ndarray,
              ground: np.ndarray, stats: EffectStats) -> tuple[np.ndarray, np.ndarray]:
    """Irradiance (P, 3) from the sky and the standard error of its luminance (P,)."""
    P = len(pts)
    out = np.zeros((P, 3))
    se = np.zeros(P)
    if P == 0:
        return out, se
    zenith, horizon, ground = (np.asarray(c, np.float64) for c in (zenith, horizon, ground))
    hemi = hemisphere(ctx, pts, samples, SALT_SKY)
    N = hemi.N
    lz, lh, lg = (float(luminance(c)) for c in (zenith, horizon, ground))
    span = max(lz, lh, lg)
    far = ctx.far

    def work(i0: int, i1: int, clock) -> None:
        n = i1 - i0
        with clock("generate"):
            o, d = hemi.embree_rays(i0, i1)
        with clock("trace"):
            occ = ctx.tracer.occluded(o, d, far, embree_frame=True)
        with clock("shade"):
            vis = (~occ).reshape(n, N).astype(np.float32)
            dy = d[:, 1].reshape(n, N)
            up = dy >= 0
            v_up = vis * up
            v_dn = vis - v_up
            w_up = v_up * np.minimum(dy, np.float32(1.0))  # fraction of the way horizon -> zenith
            m_up = v_up.mean(axis=1, dtype=np.float64)
            m_dn = v_dn.mean(axis=1, dtype=np.float64)
            m_w = w_up.mean(axis=1, dtype=np.float64)
            out[i0:i1] = (m_up[:, None] * horizon + m_w[:, None] * (zenith - horizon) + m_dn[:, None] * ground)
            lum = v_up * np.float32(lh) + w_up * np.float32(lz - lh) + v_dn * np.float32(lg)
            _, s = mean_and_se(lum, span)
            se[i0:i1] = s

    drive(ctx, stats, P, N, work)
    stats.samples = N
    stats.rays += P * N
    stats.add_error(se, span / N)
    return out, se
