"""Ambient occlusion: the cosine-weighted fraction of the hemisphere that is open within
``distance`` (a fraction of the bbox diagonal). Shadow-ray (any-hit) queries, bounded in length.

**The error figure.** Each point's standard error comes from pairs of neighbouring strata
(``sampling.mean_and_se``). For AO that estimate is about 1.4-1.6 times the real error: a pair
straddling an occluder's edge counts the difference of its two strata (mostly signal) as noise,
and an occluder's edge is what AO is made of. Measured against a reference of 2 x 4096 rays per
point (its own noise subtracted; ``benchmarks/bench_ao_error.py``), the RMS pair estimate over the
points was 1.34-1.57 times the actual RMSE on the corpus bunny, house and duck at 16-1024 samples
(bunny 256: 0.00962 against 0.00620). The stage's ``error`` for AO is therefore the pair estimate
times ``AO_ERROR_CALIBRATION`` = 1 / 1.3, which put it at 1.03-1.21 times the actual RMSE there;
``tests/lighting/test_lighting_convergence.py`` checks it stays between 1.0 and 1.3 times the error
measured against a high-sample reference. The per-point standard errors and ``error_bound``
(which adds the ``1/N`` resolution floor) stay conservative, for bounds such as ``|ao - exact| <=
4 se``."""

from __future__ import annotations

import numpy as np

from .kernel import SALT_AO, Context, EffectStats, drive, hemisphere
from .sampling import mean_and_se
from .targets import Points

AO_ERROR_CALIBRATION = 1.0 / 1.3


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
            o, d = hemi.embree_rays(i0, i1)
        with clock("trace"):
            occ = ctx.tracer.occluded(o, d, distance, embree_frame=True)
        with clock("shade"):
            m, s = mean_and_se(occ.reshape(i1 - i0, N), 1.0)  # (booleans: counted)
            np.subtract(1.0, m, out=out[i0:i1])
            se[i0:i1] = s

    drive(ctx, stats, P, N, work)
    stats.samples = N
    stats.rays += P * N
    if strength != 1.0:
        out = 1.0 - strength * (1.0 - out)
        se = se * strength
    stats.add_error(se, strength / N)
    stats.error_scale = AO_ERROR_CALIBRATION
    return out, se
