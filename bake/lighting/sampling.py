"""Deterministic stratified sampling for the light baker.

Every stochastic estimate in the baker is a mean over ``N`` samples taken at one *sample point*
(a vertex or a point inside a triangle). The samples come from

* a **base pattern** of ``N = m * n`` points in the unit square, multi-jittered: one point in
  every cell of an ``m x n`` grid *and* one point in every one of the ``N`` thin columns and rows
  (Chiu, Shirley and Wang's construction, vectorised). It depends only on the seed, the effect
  and ``N``;
* a **per-point toroidal shift** ``(su, sv)`` (Cranley-Patterson rotation) taken from a 64-bit
  hash of ``(seed, effect, point key)``. A uniformly random shift of any point set gives an
  unbiased estimate, and a shifted multi-jittered pattern is still stratified, so each point
  gets an independent, unbiased, stratified estimate.

Because a point's samples depend only on its key (never on the order points are processed in,
the chunking or the thread count), reruns and different worker counts give bit-identical
results.

The shift in ``v`` is an azimuthal rotation, so it is applied once per point to the tangent
frame; only the shift in ``u`` is applied per ray. Directions then cost a handful of float32
array operations per ray and no trigonometry.

**Error estimate.** Samples ``2k`` and ``2k + 1`` lie in neighbouring cells of the grid. Pairing
them ("collapsed strata") gives ``SE^2 = sum_k (f_2k - f_2k+1)^2 / N^2``, an estimate of the
variance of the stratified mean that is conservative (it counts the difference of the two cell
means as noise), unlike ``s / sqrt(N)``, which ignores the stratification altogether.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_GOLD = np.uint64(0x9E3779B97F4A7C15)
_S30, _S27, _S31 = np.uint64(30), np.uint64(27), np.uint64(31)


def mix64(x: np.ndarray) -> np.ndarray:
    """SplitMix64 finaliser on a uint64 array (wrapping arithmetic)."""
    x = np.asarray(x, dtype=np.uint64)
    with np.errstate(over="ignore"):
        x = (x ^ (x >> _S30)) * _M1
        x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


def hash_combine(*parts) -> np.ndarray:
    """A 64-bit hash of integer arrays / scalars (broadcast together)."""
    h = np.uint64(0x243F6A8885A308D3)
    out = None
    for p in parts:
        a = np.asarray(p)
        if a.dtype.kind == "i":
            a = a.astype(np.int64).view(np.uint64) if a.ndim else np.uint64(int(a) & ((1 << 64) - 1))
        else:
            a = a.astype(np.uint64)
        with np.errstate(over="ignore"):
            out = mix64((h if out is None else out) + _GOLD + np.asarray(a, dtype=np.uint64))
    return np.asarray(out, dtype=np.uint64)


def to_unit(h: np.ndarray) -> np.ndarray:
    """uint64 hash -> float64 in [0, 1) (53 bits)."""
    return (np.asarray(h, dtype=np.uint64) >> np.uint64(11)).astype(np.float64) * (2.0 ** -53)


def grid_shape(n: int) -> tuple[int, int]:
    """The ``m x n`` grid used for ``n`` requested samples (``m * n >= n``, nearly square)."""
    n = max(1, int(n))
    m = int(math.ceil(math.sqrt(n)))
    k = int(math.ceil(n / m))
    return m, k


def effective_samples(n: int) -> int:
    """Samples actually taken for ``n`` requested: rounded up to a full grid (16 -> 16,
    50 -> 56, 100 -> 100). Reported as the rays cast."""
    m, k = grid_shape(n)
    return m * k


@dataclass(frozen=True)
class Pattern:
    """A base pattern of ``n`` points: ``u`` (radial/polar parameter) and the unit vector of
    the azimuth ``2 pi v`` as ``cos``/``sin`` (all float32, shape (n,))."""

    u: np.ndarray
    v: np.ndarray
    cos: np.ndarray
    sin: np.ndarray

    @property
    def n(self) -> int:
        return int(len(self.u))


def multi_jittered(n: int, seed: int, salt: int) -> Pattern:
    """Multi-jittered ``m x k`` pattern (``m * k = effective_samples(n)``), ordered so that
    consecutive indices are neighbouring cells of the same row where possible."""
    m, k = grid_shape(n)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, int(salt) & 0xFFFFFFFF, m, k, 0x6C69])
    # cell (j, i): row j in [0, k), column i in [0, m)
    j = np.arange(k)[:, None]
    i = np.arange(m)[None, :]
    # canonical arrangement: sub-column / sub-row offsets make the 1-D projections stratified
    x = (i + (j + rng.random((k, m))) / k) / m
    y = (j + (i + rng.random((k, m))) / m) / k
    # shuffle the fine x-offsets among the rows of each column, the fine y-offsets among the
    # columns of each row: keeps both the 2-D cells and the 1-D strata
    xo = np.take_along_axis(x - i / m, np.argsort(rng.random((k, m)), axis=0), axis=0)
    yo = np.take_along_axis(y - j / k, np.argsort(rng.random((k, m)), axis=1), axis=1)
    x = (i / m + xo).ravel()
    y = (j / k + yo).ravel()
    # serpentine order: row 0 left->right, row 1 right->left, ... so pairs stay neighbours
    order = np.arange(m * k).reshape(k, m)
    order[1::2] = order[1::2, ::-1]
    order = order.ravel()
    x, y = x[order], y[order]
    x = np.clip(x, 0.0, np.nextafter(1.0, 0.0))
    y = np.clip(y, 0.0, np.nextafter(1.0, 0.0))
    ang = 2.0 * np.pi * y
    return Pattern(u=x.astype(np.float32), v=y.astype(np.float32),
                   cos=np.cos(ang).astype(np.float32), sin=np.sin(ang).astype(np.float32))


def point_shifts(keys: np.ndarray, seed: int, salt: int) -> tuple[np.ndarray, np.ndarray]:
    """Per-point toroidal shift ``(su, sv)`` in [0, 1) from the point keys (uint64)."""
    keys = np.asarray(keys, dtype=np.uint64)
    h = hash_combine(np.int64(seed), np.int64(salt), keys)
    su = to_unit(h)
    sv = to_unit(mix64(h ^ _GOLD))
    return su, sv


def frames(axis: np.ndarray, angle01: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal tangents ``(T, B)`` for unit ``axis`` (P, 3) (Duff et al. 2017, branch-free),
    rotated about the axis by ``2 pi * angle01`` when given. float64 in, float64 out."""
    n = np.asarray(axis, dtype=np.float64)
    s = np.where(n[:, 2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (s + n[:, 2])
    b = n[:, 0] * n[:, 1] * a
    t = np.stack([1.0 + s * n[:, 0] * n[:, 0] * a, s * b, -s * n[:, 0]], axis=1)
    bt = np.stack([b, s + n[:, 1] * n[:, 1] * a, -n[:, 1]], axis=1)
    if angle01 is not None:
        ang = 2.0 * np.pi * np.asarray(angle01, dtype=np.float64)
        c, si = np.cos(ang)[:, None], np.sin(ang)[:, None]
        t, bt = c * t + si * bt, c * bt - si * t
    return t, bt


def shifted_u(pattern: Pattern, su: np.ndarray) -> np.ndarray:
    """(P, N) float32: ``frac(u_j + su_i)``."""
    u = pattern.u[None, :] + su.astype(np.float32)[:, None]
    u -= (u >= 1.0).astype(np.float32)
    np.clip(u, 0.0, np.float32(1.0 - 2 ** -24), out=u)
    return u


def combine(x: np.ndarray, y: np.ndarray, z: np.ndarray, t: np.ndarray, b: np.ndarray,
            n: np.ndarray) -> np.ndarray:
    """``x T + y B + z N`` for (P, N) coefficients and (P, 3) float32 axes -> (P * N, 3)."""
    P, N = x.shape
    d = np.empty((P, N, 3), dtype=np.float32)
    for k in range(3):  # the three components, not a loop over rays
        dk = d[:, :, k]
        np.multiply(x, t[:, k, None], out=dk)
        dk += y * b[:, k, None]
        dk += z * n[:, k, None]
    return d.reshape(P * N, 3)


def cosine_directions(pattern: Pattern, normal32: np.ndarray, t32: np.ndarray, b32: np.ndarray,
                      su: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Cosine-weighted hemisphere directions about ``normal`` (polar map ``r = sqrt(u)``).
    Returns ``(dirs (P*N, 3) float32, cos_theta (P, N) float32)``."""
    u = shifted_u(pattern, su)
    r = np.sqrt(u)
    z = np.sqrt(1.0 - u)
    d = combine(r * pattern.cos, r * pattern.sin, z, t32, b32, normal32)
    return d, z


#: rays per block in :func:`cosine_rays_into`: a block's (points x samples) float32 temporaries
#: stay in the core's cache (16,384 rays: 64 KB each); measured on the 69k bunny at 256 spp
#: (blocks of 16 points = 4,096 rays: 2.05 ms per 512-point chunk; 64 or 128 points: 1.25 ms;
#: one block of 512 points: 1.58 ms)
RAY_BLOCK = 1 << 14
_U_MAX = np.float32(1.0 - 2 ** -24)


class RayBuffers:
    """One thread's buffers for :func:`cosine_rays_into`: rays component-major, ``(3, rays)``
    float32 for origins and directions (Embree reads them through ``(rays, 3)`` views), and the
    per-block temporaries. Reused from chunk to chunk, so no array is allocated per chunk."""

    def __init__(self, n_rays: int, samples: int, block: int | None = None):
        self.org = np.empty((3, n_rays), np.float32)
        self.dir = np.empty((3, n_rays), np.float32)
        self.block = max(1, int(block) if block else RAY_BLOCK // max(1, samples))  # points per block
        shape = (self.block, samples)
        self.scratch = [np.empty(shape, np.float32) for _ in range(5)]
        self.mask = np.empty(shape, bool)

    def fits(self, n_rays: int, samples: int) -> bool:
        return self.org.shape[1] >= n_rays and self.scratch[0].shape[1] == samples


def cosine_rays_into(pattern: Pattern, normal32: np.ndarray, t32: np.ndarray, b32: np.ndarray,
                     su: np.ndarray, org32: np.ndarray, buf: RayBuffers) -> tuple[np.ndarray, np.ndarray]:
    """The rays of :func:`cosine_directions` (bit for bit: the same float32 operations in the same
    order, each on the same operands) with origin ``org32[i]`` for every ray of point ``i``, into
    ``buf``. Returns ``(origins, directions)`` as ``(P * N, 3)`` float32 views of ``buf`` (valid
    until ``buf`` is used again). Works block by block of points so the temporaries stay in cache,
    and writes each component contiguously (no stride-3 stores)."""
    P, N = len(su), pattern.n
    M = P * N
    u_all, r_all, z_all, tmp_all, x_all = buf.scratch
    for a0 in range(0, P, buf.block):
        a1 = min(P, a0 + buf.block)
        p = a1 - a0
        u, r, z, tmp, x = u_all[:p], r_all[:p], z_all[:p], tmp_all[:p], x_all[:p]
        m = buf.mask[:p]
        # shifted_u: frac(u_j + su_i), clipped below 1 (u >= 0 already, so the lower clip is moot)
        np.add(pattern.u[None, :], su[a0:a1, None], out=u)
        np.greater_equal(u, np.float32(1.0), out=m)
        np.subtract(u, np.float32(1.0), out=u, where=m)
        np.minimum(u, _U_MAX, out=u)
        np.sqrt(u, out=r)  # r = sqrt(u)
        np.subtract(np.float32(1.0), u, out=z)
        np.sqrt(z, out=z)  # z = sqrt(1 - u)
        np.multiply(r, pattern.cos, out=x)  # x = r cos
        np.multiply(r, pattern.sin, out=u)  # y = r sin (u is free now)
        s0, s1 = a0 * N, a1 * N
        for k in range(3):  # components: d_k = x T_k + y B_k + z N_k
            dk = buf.dir[k, s0:s1].reshape(p, N)
            np.multiply(x, t32[a0:a1, k, None], out=dk)
            np.multiply(u, b32[a0:a1, k, None], out=tmp)
            dk += tmp
            np.multiply(z, normal32[a0:a1, k, None], out=tmp)
            dk += tmp
            buf.org[k, s0:s1].reshape(p, N)[...] = org32[a0:a1, k, None]
    return buf.org[:, :M].T, buf.dir[:, :M].T


def cone_directions(pattern: Pattern, axis32: np.ndarray, t32: np.ndarray, b32: np.ndarray,
                    su: np.ndarray, cos_max: float) -> np.ndarray:
    """Directions uniform in solid angle inside the cone ``cos(theta) >= cos_max`` about
    ``axis`` (a sun of angular radius ``acos(cos_max)``). (P*N, 3) float32."""
    u = shifted_u(pattern, su)
    ct = 1.0 - u * np.float32(1.0 - cos_max)
    st = np.sqrt(np.maximum(0.0, 1.0 - ct * ct))
    return combine(st * pattern.cos, st * pattern.sin, ct, t32, b32, axis32)


def disk_offsets(pattern: Pattern, t32: np.ndarray, b32: np.ndarray, su: np.ndarray,
                 radius: float) -> np.ndarray:
    """Points uniform on a disk of ``radius`` spanned by ``(T, B)``: (P*N, 3) float32 offsets."""
    u = shifted_u(pattern, su)
    r = np.sqrt(u) * np.float32(radius)
    return combine(r * pattern.cos, r * pattern.sin, np.zeros_like(r), t32, b32, t32)


def mean_and_se(f: np.ndarray, span: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """Row means of ``f`` (P, N) and their collapsed-strata standard error (see module doc).

    ``span`` (the range of values a sample can take, e.g. 1 for visibility) adds a resolution
    floor ``span / N`` in quadrature: a feature thinner than a stratum (say a distant object seen
    at a grazing angle) can go unseen by every sample, and then the pairs alone would report no
    error at all. With the floor the estimate is conservative (measured: 1.3x to 3x the actual
    RMSE), never optimistic in the tests."""
    f = np.asarray(f)
    N = f.shape[1]
    if f.dtype == bool:  # 0/1 samples (visibility): counts, without float temporaries
        return _bool_mean_and_se(f, span)
    mean = f.mean(axis=1, dtype=np.float64)
    if N < 2:
        return mean, np.zeros(len(f))
    h = N // 2
    d = f[:, 0:2 * h:2].astype(np.float64) - f[:, 1:2 * h:2]
    var = np.einsum("ij,ij->i", d, d) / (N * N) * (N / (2 * h))
    if span:
        var += (span / N) ** 2
    return mean, np.sqrt(var)


def _bool_mean_and_se(f: np.ndarray, span: float) -> tuple[np.ndarray, np.ndarray]:
    """:func:`mean_and_se` of 0/1 samples given as booleans, bit for bit: a row's float64 sum of
    0/1 values and its sum of squared pair differences are whole numbers below 2**53, so counting
    gives them exactly, and the divisions that follow are the same operations on the same values."""
    N = f.shape[1]
    mean = np.count_nonzero(f, axis=1).astype(np.float64) / N
    if N < 2:
        return mean, np.zeros(len(f))
    h = N // 2
    differ = np.not_equal(f[:, 0:2 * h:2], f[:, 1:2 * h:2])
    var = np.count_nonzero(differ, axis=1).astype(np.float64) / (N * N) * (N / (2 * h))
    if span:
        var += (span / N) ** 2
    return mean, np.sqrt(var)
