"""What every effect shares: the context (tracer, seed), per-effect statistics and the chunked,
threaded driver over sample points."""

from __future__ import annotations

import threading
import time
from dataclasses import dataclass, field
from typing import Callable

import numpy as np

from .rays import Clock, Timers, Tracer, points_per_chunk
from .sampling import RayBuffers, cosine_directions, cosine_rays_into, frames, multi_jittered, point_shifts

# stream salts: each effect draws from its own random stream
SALT_AO = 1
SALT_SKY = 2
SALT_BOUNCE = 3
SALT_LIGHT = 100  # + light index


class Context:
    """The tracer (built on first use, in the calling thread), the seed and the timers."""

    def __init__(self, tracer: Tracer | Callable[[], Tracer], seed: int, scale: float | None = None):
        self._tracer = tracer if isinstance(tracer, Tracer) else None
        self._factory = None if isinstance(tracer, Tracer) else tracer
        self.seed = int(seed)
        self.timers = Timers()
        self._scale = scale if scale is not None else (self._tracer.scale if self._tracer else None)
        self.build_seconds = 0.0

    @property
    def tracer(self) -> Tracer:
        if self._tracer is None:
            t = time.perf_counter()
            self._tracer = self._factory()
            self.build_seconds += time.perf_counter() - t
        return self._tracer

    @tracer.setter
    def tracer(self, value: Tracer) -> None:
        self._tracer = value

    @property
    def built(self) -> bool:
        return self._tracer is not None

    @property
    def scale(self) -> float:
        return float(self._scale) if self._scale is not None else self.tracer.scale

    @property
    def far(self) -> float:
        """A ray length that reaches every triangle from any point of the scene's box."""
        return 1.5 * self.scale


@dataclass
class EffectStats:
    """Rays, time and error of one effect, summed over the batches of points it ran on."""

    name: str
    samples: int = 0  # rays per point (effective)
    rays: int = 0
    points: int = 0
    seconds: float = 0.0
    se_sq_sum: float = 0.0
    bound_sq_sum: float = 0.0
    se_max: float = 0.0
    se_n: int = 0
    ran: bool = False
    reason: str = ""
    # ``error`` = this x the pair estimate (1 = uncalibrated; AO sets its measured calibration)
    error_scale: float = 1.0
    warnings: list[str] = field(default_factory=list)
    timers: Timers = field(default_factory=Timers)
    extra: dict = field(default_factory=dict)

    def add_error(self, se: np.ndarray, floor: np.ndarray | float = 0.0) -> None:
        """Record per-point standard errors ``se`` that include a resolution ``floor`` (added in
        quadrature, see ``sampling.mean_and_se``). ``error`` aggregates them without the floor,
        ``error_bound`` with it."""
        se = np.asarray(se, dtype=np.float64)
        if len(se):
            fl = np.broadcast_to(np.asarray(floor, dtype=np.float64), se.shape)
            self.se_sq_sum += float(np.maximum(se * se - fl * fl, 0.0).sum())
            self.bound_sq_sum += float(np.dot(se, se))
            self.se_max = max(self.se_max, float(se.max()))
            self.se_n += len(se)

    @property
    def error(self) -> float:
        """RMS over the sample points of each point's standard error (sample pairs only), times
        ``error_scale``: an estimate of the RMSE of this effect's values against the exact ones."""
        return float(self.error_scale * np.sqrt(self.se_sq_sum / self.se_n)) if self.se_n else 0.0

    @property
    def error_bound(self) -> float:
        """The same with the per-point resolution floor: conservative."""
        return float(np.sqrt(self.bound_sq_sum / self.se_n)) if self.se_n else 0.0

    def to_effect(self) -> dict:
        d = {"name": self.name, "ran": self.ran, "reason": self.reason, "rays": int(self.rays),
             "seconds": round(self.seconds, 6)}
        if self.ran:
            d["error"] = round(self.error, 8)
            d["error_bound"] = round(self.error_bound, 8)
            d["error_max"] = round(self.se_max, 8)
            if self.error_scale != 1.0:
                d["error_calibration"] = round(self.error_scale, 6)
            d["samples"] = int(self.samples)
            d["points"] = int(self.points)
            d["timing"] = self.timers.as_dict()
        d.update(self.extra)
        return d


def drive(ctx: Context, stats: EffectStats, n_points: int, samples: int,
          work: Callable[[int, int, Clock], None]) -> None:
    """Run ``work(i0, i1, clock)`` over fixed chunks of the points on the tracer's threads."""
    t0 = time.perf_counter()
    timers = Timers()
    clock = Clock(timers)
    ctx.tracer.parallel(n_points, points_per_chunk(samples), lambda a, b: work(a, b, clock))
    stats.seconds += time.perf_counter() - t0
    stats.timers.merge(timers)
    ctx.timers.merge(timers)
    stats.points += n_points


def as32(a: np.ndarray) -> np.ndarray:
    return np.ascontiguousarray(a, dtype=np.float32)


@dataclass
class Hemisphere:
    """Cosine-weighted hemisphere rays for a set of points: one multi-jittered pattern shifted
    per point (seeded by the effect's salt), tangent frames, and origins pushed off the surface.
    Shared by AO, sky and bounces; ``rays(i0, i1)`` makes the rays of points ``i0 .. i1 - 1``."""

    pattern: object
    n32: np.ndarray
    t32: np.ndarray
    b32: np.ndarray
    su32: np.ndarray
    org: np.ndarray
    org_embree: np.ndarray  # ``org`` in Embree's frame (Tracer.embree_origins)
    _local: threading.local = field(default_factory=threading.local, repr=False)

    @property
    def N(self) -> int:
        return self.pattern.n

    def rays(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray]:
        """(origins, directions) float32, ``N`` rays per point, point-major, contiguous."""
        d, _ = cosine_directions(self.pattern, self.n32[i0:i1], self.t32[i0:i1], self.b32[i0:i1],
                                 self.su32[i0:i1])
        return np.repeat(self.org[i0:i1], self.N, axis=0), d

    def embree_rays(self, i0: int, i1: int) -> tuple[np.ndarray, np.ndarray]:
        """The same rays as :meth:`rays` (bit for bit), origins in Embree's frame, for
        ``Tracer.occluded(..., embree_frame=True)``: ``(n, 3)`` float32 views of this thread's
        reused buffers, valid until this thread's next call (so the caller traces and reduces
        them before asking for the next chunk)."""
        n_rays = (i1 - i0) * self.N
        buf = getattr(self._local, "buf", None)
        if buf is None or not buf.fits(n_rays, self.N):
            buf = self._local.buf = RayBuffers(max(n_rays, points_per_chunk(self.N) * self.N), self.N)
        return cosine_rays_into(self.pattern, self.n32[i0:i1], self.t32[i0:i1], self.b32[i0:i1],
                                self.su32[i0:i1], self.org_embree[i0:i1], buf)


def hemisphere(ctx: "Context", pts, samples: int, salt: int) -> Hemisphere:
    pattern = multi_jittered(samples, ctx.seed, salt)
    su, sv = point_shifts(pts.key, ctx.seed, salt)
    t, b = frames(pts.nrm, sv)
    org = ctx.tracer.origins(pts.pos, pts.nrm)
    return Hemisphere(pattern, as32(pts.nrm), as32(t), as32(b), su.astype(np.float32), org,
                      ctx.tracer.embree_origins(org))

