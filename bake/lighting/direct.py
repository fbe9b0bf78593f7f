"""Direct light from suns, point lights and spot lights, with soft shadows.

``E = colour x intensity x max(0, n . l) x attenuation x V`` where ``l`` is the direction to the
light's centre and ``V`` the fraction of shadow rays that reach the light:

* **sun**: ``l = -direction``; no attenuation. Shadow rays are uniform in solid angle over the sun's
  disc (angular diameter ``angle``), unbounded. With ``angle = 0`` one ray.
* **point**: inverse square ``1 / d^2`` (scene units; ``d`` clamped to the light's radius), and
  with a ``range`` the glTF window ``clamp(1 - (d / range)^4, 0, 1)^2``. Shadow rays go to points
  uniform on the disc of ``radius`` facing the sample point, and stop just short of it.
* **spot**: a point light times the glTF cone falloff
  ``clamp((cos a - cos outer) / (cos inner - cos outer), 0, 1)^2``.

The shading term uses the centre direction, so an unshadowed sun on an open plane gives exactly
``cos(theta)`` whatever its angular size. Points the light cannot reach (facing away, out of range,
outside the cone) cast no rays.
"""

from __future__ import annotations

import numpy as np

from .color import luminance
from .kernel import SALT_LIGHT, Context, EffectStats, as32, drive
from .plan import LightSpec
from .rays import EPS_POS, EPS_SCALE
from .sampling import cone_directions, disk_offsets, frames, mean_and_se, multi_jittered, point_shifts
from .targets import Points


def geometry_term(light: LightSpec, pts: Points, scale: float) -> tuple[np.ndarray, np.ndarray | None,
                                                                       np.ndarray | None]:
    """Unshadowed ``cos x attenuation`` per point, plus (for point/spot) unit direction and
    distance to the light centre."""
    if light.kind == "sun":
        L = -light.direction
        return np.maximum(pts.nrm @ L, 0.0), None, None
    w = light.position[None, :] - pts.pos
    dist = np.linalg.norm(w, axis=1)
    safe = np.maximum(dist, 1e-300)
    l = w / safe[:, None]
    g = np.maximum(np.einsum("ij,ij->i", pts.nrm, l), 0.0)
    rmin = max(light.radius, 1e-6 * scale)
    g = g / np.maximum(dist, rmin) ** 2
    if light.range > 0:
        g = g * np.clip(1.0 - (dist / light.range) ** 4, 0.0, 1.0) ** 2
    if light.kind == "spot":
        cd = -(l @ light.direction)
        span = max(1e-3, light.cos_inner - light.cos_outer)
        g = g * np.clip((cd - light.cos_outer) / span, 0.0, 1.0) ** 2
    g[dist <= 0] = 0.0
    return g, l, dist


def direct_light(ctx: Context, light: LightSpec, pts: Points, samples: int, shadows: bool,
                 stats: EffectStats) -> tuple[np.ndarray, np.ndarray, dict]:
    """Irradiance (P, 3), standard error of its luminance (P,), and reach figures."""
    P = len(pts)
    out = np.zeros((P, 3))
    se = np.zeros(P)
    g, l, dist = geometry_term(light, pts, ctx.scale)
    idx = np.flatnonzero(g > 0)
    info = {"facing": int(len(idx)), "lit": 0}
    if len(idx) == 0:
        return out, se, info
    if not shadows:
        out[idx] = g[idx, None] * light.color[None, :]
        info["lit"] = int(len(idx))
        return out, se, info

    tr = ctx.tracer
    salt = SALT_LIGHT + light.index
    soft = (light.half_angle > 0 if light.kind == "sun" else light.radius > 0) and samples > 1
    pattern = multi_jittered(samples if soft else 1, ctx.seed, salt)
    N = pattern.n if soft else 1
    sub = Points(pts.pos[idx], pts.nrm[idx], pts.key[idx], pts.owner[idx])
    org = tr.origins(sub.pos, sub.nrm)
    vis = np.zeros(len(idx))
    vse = np.zeros(len(idx))
    if soft:
        su, sv = point_shifts(sub.key, ctx.seed, salt)
        su32 = su.astype(np.float32)
        axis = np.broadcast_to(-light.direction, (len(idx), 3)) if light.kind == "sun" else l[idx]
        t, b = frames(np.ascontiguousarray(axis), sv)
        a32, t32, b32 = as32(axis), as32(t), as32(b)
    if light.kind != "sun":
        c_loc = tr.to_local(light.position[None, :])[0]
        c32 = c_loc.astype(np.float32)
        # stop short of the light by a few float32 steps of its position
        short = 4.0 * (EPS_SCALE * tr.scale + EPS_POS * float(np.abs(c_loc).max()))
    cos_max = float(np.cos(light.half_angle))
    far = ctx.far

    def work(i0: int, i1: int, clock) -> None:
        n = i1 - i0
        with clock("generate"):
            o = np.repeat(org[i0:i1], N, axis=0)
            if light.kind == "sun":
                if soft:
                    d = cone_directions(pattern, a32[i0:i1], t32[i0:i1], b32[i0:i1], su32[i0:i1], cos_max)
                else:
                    d = np.broadcast_to((-light.direction).astype(np.float32), (n, 3)).copy()
                length = far
            else:
                target = np.broadcast_to(c32, (n * N, 3))
                if soft:
                    target = target + disk_offsets(pattern, t32[i0:i1], b32[i0:i1], su32[i0:i1], light.radius)
                d = target - o
                ln = np.sqrt(np.einsum("ij,ij->i", d, d))
                d /= np.maximum(ln, np.float32(1e-30))[:, None]
                length = np.maximum(ln - np.float32(short), np.float32(0.0))
        with clock("trace"):
            occ = tr.occluded(o, d, length)
        with clock("shade"):
            f = (~occ).reshape(n, N).astype(np.float32)
            m, s = mean_and_se(f, 1.0)
            vis[i0:i1] = m
            vse[i0:i1] = s

    drive(ctx, stats, len(idx), N, work)
    stats.samples = N
    stats.rays += len(idx) * N
    out[idx] = (g[idx] * vis)[:, None] * light.color[None, :]
    se[idx] = g[idx] * vse * abs(float(luminance(light.color)))
    info["lit"] = int((vis > 0).sum())
    stats.add_error(se[idx], g[idx] * abs(float(luminance(light.color))) / N)
    return out, se, info
