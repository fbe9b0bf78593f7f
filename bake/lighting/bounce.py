"""Bounced (indirect) light by iterated gathering.

Each sample point casts ``bounces.samples`` cosine-weighted rays once (closest hit, unbounded).
Then, ``count`` times:

    E_ind(p) = mean over rays of  albedo_lin(hit triangle) x E_total(hit)
    E_total  = E_local (lights, sky, ambient x AO) + E_ind

where ``E_total(hit)`` is interpolated from the vertex field with the hit's barycentrics (or
taken from the hit triangle when only triangle values exist). So ``count = 1`` is one bounce,
``count = 2`` light that bounced twice, and so on; the rays are cast once whatever the count.

Back-face hits (the ray entered a closed surface through a crack, or started behind a surface)
and misses bring no bounced light (sky light arriving directly is the sky effect's job), so
bounced light cannot leak into closed volumes.
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from .color import luminance
from .kernel import SALT_BOUNCE, Context, EffectStats, drive, hemisphere
from .sampling import mean_and_se
from .targets import Points

CACHE_RAYS = 1 << 24  # keep hit records for up to this many rays, else re-cast each iteration


class BounceRays:
    """The bounce rays of a set of points: hit triangle, barycentrics, front/back facing."""

    def __init__(self, ctx: Context, pts: Points, samples: int, stats: EffectStats):
        self.ctx = ctx
        self.pts = pts
        self.stats = stats
        self.hemi = hemisphere(ctx, pts, samples, SALT_BOUNCE)
        self.N = self.hemi.N
        P = len(pts)
        self.cached = P * self.N <= CACHE_RAYS
        if self.cached:
            self.prim = np.empty((P, self.N), np.int32)
            self.u = np.empty((P, self.N), np.float32)
            self.v = np.empty((P, self.N), np.float32)
            self.front = np.empty((P, self.N), bool)
            self._cast_all()

    def _cast(self, i0: int, i1: int, clock) -> tuple[np.ndarray, ...]:
        N = self.N
        with clock("generate"):
            o, d = self.hemi.rays(i0, i1)
        with clock("trace"):
            h = self.ctx.tracer.intersect(o, d, self.ctx.far)
        with clock("shade"):
            prim = h["prim"].reshape(i1 - i0, N)
            front = (np.einsum("ij,ij->i", h["Ng"], d) < 0).reshape(i1 - i0, N) & (prim >= 0)
        return prim, h["u"].reshape(i1 - i0, N), h["v"].reshape(i1 - i0, N), front

    def _cast_all(self) -> None:
        def work(i0: int, i1: int, clock) -> None:
            p, u, v, f = self._cast(i0, i1, clock)
            self.prim[i0:i1], self.u[i0:i1], self.v[i0:i1], self.front[i0:i1] = p, u, v, f

        drive(self.ctx, self.stats, len(self.pts), self.N, work)
        self.stats.rays += len(self.pts) * self.N

    def gather(self, radiance: Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]
               ) -> tuple[np.ndarray, np.ndarray]:
        """Mean over each point's rays of ``radiance(prim, u, v)`` ((n, 3), for front-face hits).
        Returns ((P, 3), standard error of the luminance (P,))."""
        P, N = len(self.pts), self.N
        out = np.zeros((P, 3))
        se = np.zeros(P)

        def work(i0: int, i1: int, clock) -> None:
            if self.cached:
                prim, u, v, front = self.prim[i0:i1], self.u[i0:i1], self.v[i0:i1], self.front[i0:i1]
            else:
                prim, u, v, front = self._cast(i0, i1, clock)
            with clock("shade"):
                sel = front.ravel()
                val = np.zeros(((i1 - i0) * N, 3))
                if sel.any():
                    val[sel] = radiance(prim.ravel()[sel], u.ravel()[sel], v.ravel()[sel])
                val = val.reshape(i1 - i0, N, 3)
                out[i0:i1] = val.mean(axis=1)
                _, s = mean_and_se(luminance(val))
                se[i0:i1] = s

        drive(self.ctx, self.stats, P, N, work)
        if not self.cached:
            self.stats.rays += P * N
        self.stats.points -= P  # drive counts points per pass; count them once
        return out, se


def field_radiance(tris: np.ndarray, albedo_lin: np.ndarray, vertex_field: np.ndarray | None,
                   face_field: np.ndarray) -> Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]:
    """Radiance leaving a hit: ``albedo_lin[prim] x E(hit)`` (vertex-interpolated when a vertex
    field is given, else the triangle's value)."""
    def radiance(prim: np.ndarray, u: np.ndarray, v: np.ndarray) -> np.ndarray:
        if vertex_field is not None:
            t = tris[prim]
            u64 = u.astype(np.float64)[:, None]
            v64 = v.astype(np.float64)[:, None]
            e = (1.0 - u64 - v64) * vertex_field[t[:, 0]] + u64 * vertex_field[t[:, 1]] + v64 * vertex_field[t[:, 2]]
            e = np.maximum(e, 0.0)
        else:
            e = face_field[prim]
        return albedo_lin[prim] * e

    return radiance
