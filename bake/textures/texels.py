"""Texels of a lightmap atlas: which texels each triangle covers, their sample points, and the
images made from the values at those points (texel space as in ``atlas.py``).

* :func:`cover`: every (triangle, texel) pair whose areas overlap (conservative rasterisation,
  vectorised: the texels of each triangle's bounding box, kept by the separating-axis test).
* :func:`texel_samples`: ``supersample^2`` sub-texel points per pair that fall inside the
  triangle (weight ``1 / s^2`` each), and for a pair with none of them inside (the triangle only
  grazes the texel) one point at the texel centre clamped onto the triangle (weight
  ``EDGE_WEIGHT``, so it only counts where nothing better covers the texel). Each sample has a
  world position (float64), the geometric normal and the triangle id. :func:`push_out` then moves
  samples that start inside or behind geometry (a tangent ray hits a back face within one texel)
  to just in front of the face they hit.
* :func:`splat`: the weighted mean of the sample values per texel; :func:`dilate` fills ``px``
  rings of padding around the covered texels (mean of covered neighbours), so bilinear lookups
  near chart borders read sensible values; :func:`bilinear` reads an image at lightmap UVs.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterator

import numpy as np

from ..geometry import tangent_frames
from ..scene import Scene
from .atlas import Atlas, cross2

EDGE_WEIGHT = 1e-3  # weight of a clamped sample (a triangle that only grazes the texel)
PAIRS_PER_CHUNK = 1 << 19  # bounds the temporary arrays of the rasteriser
PUSH_DIRECTIONS = 8  # tangent rays per sample for push_out
PUSH_RADIUS = 1.0  # push_out ray length, in texels (world size of one texel of the triangle)


# --------------------------------------------------------------------------------------------
# conservative rasterisation


def _box_texels(lo: np.ndarray, hi: np.ndarray, W: int) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Every texel of each box ``lo..hi`` (inclusive, (n, 2) ints): yields (owner, tx, ty) in
    chunks of about PAIRS_PER_CHUNK."""
    nx = hi[:, 0] - lo[:, 0] + 1
    ny = hi[:, 1] - lo[:, 1] + 1
    count = nx * ny
    ends = np.cumsum(count)
    chunk = (ends - count) // PAIRS_PER_CHUNK
    bounds = [0, *(np.flatnonzero(np.diff(chunk)) + 1).tolist(), len(count)]
    for b0, b1 in zip(bounds[:-1], bounds[1:]):
        if b1 <= b0:
            continue
        c = count[b0:b1]
        owner = np.repeat(np.arange(b0, b1), c)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(c) - c, c)
        yield owner, lo[owner, 0] + k % nx[owner], lo[owner, 1] + k // nx[owner]


def cover(atlas: Atlas) -> tuple[np.ndarray, np.ndarray]:
    """(triangle ids, texel ids) of every pair whose triangle and texel square overlap with
    positive area (texel id = row * W + column). Sorted by triangle, then texel."""
    W, H = atlas.width, atlas.height
    xy = atlas.texel_xy()
    tids = np.flatnonzero(atlas.mapped)
    pts = xy[tids]
    lo = np.floor(pts.min(axis=1)).astype(np.int64)
    hi = np.ceil(pts.max(axis=1)).astype(np.int64) - 1
    hi = np.maximum(hi, lo)
    lo = np.clip(lo, 0, [W - 1, H - 1])
    hi = np.clip(hi, 0, [W - 1, H - 1])
    sgn = np.sign(cross2(pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0]))
    out_t, out_x = [], []
    for owner, tx, ty in _box_texels(lo, hi, W):
        keep = np.ones(len(owner), dtype=bool)
        cx, cy = tx + 0.5, ty + 0.5
        p = pts[owner]
        s = sgn[owner]
        for k in range(3):  # the triangle's three edges
            a, b = p[:, k], p[:, (k + 1) % 3]
            dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
            f = dx * (cy - a[:, 1]) - dy * (cx - a[:, 0])
            reach = 0.5 * (np.abs(dx) + np.abs(dy))
            keep &= s * f + reach > 1e-9 * (np.abs(dx) + np.abs(dy))
        out_t.append(tids[owner[keep]])
        out_x.append(ty[keep] * W + tx[keep])
    if not out_t:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(out_t), np.concatenate(out_x)


# --------------------------------------------------------------------------------------------
# texel samples


@dataclass
class TexelSamples:
    """Sample points of the lightmap's texels. Unpacks as
    ``points, normals, tri_ids, texel_index, weights = texel_samples(...)``."""

    points: np.ndarray  # (N, 3) float64 world positions
    normals: np.ndarray  # (N, 3) unit geometric normals of the triangles
    tri_ids: np.ndarray  # (N,) int64
    texel_index: np.ndarray  # (N,) int64, row * W + column
    weights: np.ndarray  # (N,) float64: 1/s^2 inside the triangle, EDGE_WEIGHT for a clamped point
    inside: np.ndarray = field(default=None)  # (N,) bool: a sub-texel point inside the triangle
    pushed: np.ndarray = field(default=None)  # (N,) bool: moved by push_out
    texel_size: np.ndarray = field(default=None)  # (T,) world length of one texel per triangle

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.points, self.normals, self.tri_ids, self.texel_index, self.weights))

    def __len__(self) -> int:
        return int(len(self.points))


def face_normals(positions: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit normals (T, 3), areas (T,)); a degenerate triangle gets normal 0."""
    p = positions[triangles]
    cr = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    ln = np.linalg.norm(cr, axis=1)
    n = np.divide(cr, ln[:, None], out=np.zeros_like(cr), where=ln[:, None] > 0)
    return n, 0.5 * ln


def texel_world_size(scene: Scene, atlas: Atlas) -> np.ndarray:
    """(T,) world length of one texel on each triangle: sqrt(world area / texel area)."""
    _, area = face_normals(scene.positions, scene.triangles)
    xy = atlas.texel_xy()
    ta = 0.5 * np.abs(cross2(xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]))
    return np.sqrt(np.divide(area, ta, out=np.zeros_like(area), where=ta > 0))


def _closest_on_triangle(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentrics (n, 3) of the point of each 2-D triangle (n, 3, 2) closest to p (n, 2), for
    points outside the triangle (the closest point is then on an edge)."""
    best_d = np.full(len(p), np.inf)
    bary = np.zeros((len(p), 3))
    for k in range(3):  # edges
        a, b = tri[:, k], tri[:, (k + 1) % 3]
        e = b - a
        ee = np.einsum("ij,ij->i", e, e)
        t = np.clip(np.einsum("ij,ij->i", p - a, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
        q = a + t[:, None] * e
        d = np.einsum("ij,ij->i", p - q, p - q)
        better = d < best_d
        best_d = np.where(better, d, best_d)
        nb = np.zeros((len(p), 3))
        nb[np.arange(len(p)), k] = 1.0 - t
        nb[np.arange(len(p)), (k + 1) % 3] += t
        bary = np.where(better[:, None], nb, bary)
    return bary


def texel_samples(scene: Scene, atlas: Atlas, *, supersample: int = 2, push: bool = False,
                  tracer=None) -> TexelSamples:
    """The sample points of every covered texel (see the module docstring).

    ``push=True`` runs :func:`push_out` with ``tracer`` (the lighting stage's Embree
    :class:`bake.lighting.rays.Tracer`, which the caller builds: this module does not trace rays).
    """
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    if atlas.n_triangles != scene.n_triangles:
        raise ValueError(f"atlas has {atlas.n_triangles} triangles, the scene {scene.n_triangles}")
    W = atlas.width
    xy = atlas.texel_xy()
    tri_pos = scene.positions[scene.triangles]
    fn, _ = face_normals(scene.positions, scene.triangles)
    pair_t, pair_x = cover(atlas)
    off = (np.arange(s) + 0.5) / s
    sub = np.stack(np.meshgrid(off, off, indexing="xy"), axis=-1).reshape(-1, 2)  # (s*s, 2) x, y
    parts = []
    step = max(1, PAIRS_PER_CHUNK // (s * s))
    for c0 in range(0, len(pair_t), step):  # chunks bound the (pairs x s^2) temporaries
        t = pair_t[c0:c0 + step]
        x = pair_x[c0:c0 + step]
        tri = xy[t]  # (n, 3, 2)
        corner = np.stack([x % W, x // W], axis=1).astype(np.float64)
        p = corner[:, None, :] + sub[None, :, :]  # (n, s*s, 2)
        a, b, c = tri[:, 0, None], tri[:, 1, None], tri[:, 2, None]
        area2 = cross2(b - a, c - a)  # (n, 1)
        wa = cross2(c - b, p - b) / area2
        wb = cross2(a - c, p - c) / area2
        wc = 1.0 - wa - wb
        bary = np.stack([wa, wb, wc], axis=-1)  # (n, s*s, 3)
        ins = (bary >= -1e-9).all(axis=-1)
        pi, si = np.nonzero(ins)
        bi = np.clip(bary[pi, si], 0.0, 1.0)
        bi /= bi.sum(axis=1, keepdims=True)
        none = ~ins.any(axis=1)
        ei = np.flatnonzero(none)
        be = _closest_on_triangle(corner[ei] + 0.5, tri[ei])
        idx = np.concatenate([pi, ei])
        bar = np.concatenate([bi, be])
        order = np.argsort(idx, kind="stable")  # keep pair order: deterministic, texel-local
        idx, bar = idx[order], bar[order]
        inside = np.concatenate([np.ones(len(pi), bool), np.zeros(len(ei), bool)])[order]
        tt = t[idx]
        pts = np.einsum("nk,nkd->nd", bar, tri_pos[tt])
        parts.append((pts, tt, x[idx], inside))
    if parts:
        points = np.concatenate([q[0] for q in parts])
        tri_ids = np.concatenate([q[1] for q in parts])
        texel = np.concatenate([q[2] for q in parts])
        inside = np.concatenate([q[3] for q in parts])
    else:
        points, tri_ids, texel, inside = np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64), \
            np.zeros(0, bool)
    weights = np.where(inside, 1.0 / (s * s), EDGE_WEIGHT)
    out = TexelSamples(points=points, normals=fn[tri_ids], tri_ids=tri_ids.astype(np.int64),
                       texel_index=texel.astype(np.int64), weights=weights, inside=inside,
                       pushed=np.zeros(len(points), bool), texel_size=texel_world_size(scene, atlas))
    if push and len(out):
        if tracer is None:
            raise ValueError("push=True needs a ray tracer (bake.lighting.rays.Tracer)")
        out.points, out.pushed = push_out(out.points, out.normals, out.texel_size[out.tri_ids], tracer)
    return out


def push_out(points: np.ndarray, normals: np.ndarray, radius: np.ndarray, tracer, *,
             passes: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Move samples that start inside or behind geometry to the free side.

    From each point (lifted off its surface by the tracer's epsilon) ``PUSH_DIRECTIONS`` rays go
    out in the tangent plane, ``PUSH_RADIUS x radius`` long (``radius``: the world size of the
    sample's texel). If the closest hit of any of them is a **back** face, the point is inside a
    closed object or behind a one-sided wall: it moves to the nearest such hit, then out along the
    hit face's normal by ``max(1e-3 x radius, 4 x epsilon)``. ``passes`` repeats the test on moved
    points (a corner can need two moves). Returns (new points, moved mask).
    """
    pts = np.array(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    rad = np.asarray(radius, dtype=np.float64) * PUSH_RADIUS
    moved = np.zeros(len(pts), dtype=bool)
    todo = np.flatnonzero(rad > 0)
    angles = 2.0 * np.pi * (np.arange(PUSH_DIRECTIONS) + 0.5) / PUSH_DIRECTIONS
    cs, sn = np.cos(angles), np.sin(angles)
    K = PUSH_DIRECTIONS
    for _ in range(max(1, passes)):
        if len(todo) == 0:
            break
        t1, t2 = tangent_frames(nrm[todo])
        o = tracer.origins(pts[todo], nrm[todo]).astype(np.float64)  # local frame
        d = cs[None, :, None] * t1[:, None, :] + sn[None, :, None] * t2[:, None, :]  # (n, K, 3)
        n = len(todo)
        best_t = np.full(n, np.inf)
        best_k = np.zeros(n, np.int64)
        best_ng = np.zeros((n, 3))

        def work(i0: int, i1: int) -> None:  # fixed chunks: results do not depend on threads
            hit = tracer.intersect(np.repeat(o[i0:i1], K, axis=0).astype(np.float32),
                                   d[i0:i1].reshape(-1, 3).astype(np.float32),
                                   np.repeat(rad[todo[i0:i1]], K).astype(np.float32))
            prim = np.asarray(hit["prim"]).reshape(-1, K)
            ng = np.asarray(hit["Ng"], dtype=np.float64).reshape(-1, K, 3)
            tt = np.asarray(hit["t"], dtype=np.float64).reshape(-1, K)
            back = (prim >= 0) & (np.einsum("nkd,nkd->nk", ng, d[i0:i1]) > 0) & np.isfinite(tt)
            tt = np.where(back, tt, np.inf)
            k = np.argmin(tt, axis=1)
            r = np.arange(i1 - i0)
            best_t[i0:i1] = tt[r, k]
            best_k[i0:i1] = k
            best_ng[i0:i1] = ng[r, k]

        tracer.parallel(n, 1 << 14, work)
        rows = np.flatnonzero(np.isfinite(best_t))
        if len(rows) == 0:
            break
        ng_hit = best_ng[rows]
        ng_hit /= np.maximum(np.linalg.norm(ng_hit, axis=1), 1e-300)[:, None]
        local = o[rows] + d[rows, best_k[rows]] * best_t[rows][:, None]
        eps = tracer.epsilon(local)
        lift = np.maximum(1e-3 * rad[todo[rows]], 4.0 * eps)
        ids = todo[rows]
        pts[ids] = local + ng_hit * lift[:, None] + tracer.center
        moved[ids] = True
        todo = ids
    return pts, moved


# --------------------------------------------------------------------------------------------
# splat, dilate, lookups


def splat(values: np.ndarray, texel_index: np.ndarray, weights: np.ndarray, atlas: Atlas) -> np.ndarray:
    """(H, W, C) weighted mean of ``values`` ((N,) or (N, C)) per texel; 0 where no sample."""
    v = np.asarray(values, dtype=np.float64)
    one = v.ndim == 1
    v = v.reshape(len(v), -1)
    n = atlas.width * atlas.height
    w = np.asarray(weights, dtype=np.float64)
    tot = np.bincount(texel_index, weights=w, minlength=n)
    out = np.zeros((n, v.shape[1]))
    for c in range(v.shape[1]):  # channels
        out[:, c] = np.bincount(texel_index, weights=w * v[:, c], minlength=n)
    out = np.divide(out, tot[:, None], out=np.zeros_like(out), where=tot[:, None] > 0)
    out = out.reshape(atlas.height, atlas.width, -1)
    return out[:, :, 0] if one else out


def texel_mask(texel_index: np.ndarray, weights: np.ndarray, atlas: Atlas) -> np.ndarray:
    """(H, W) bool: texels with at least one sample of positive weight."""
    n = atlas.width * atlas.height
    tot = np.bincount(texel_index, weights=np.asarray(weights, np.float64), minlength=n)
    return (tot > 0).reshape(atlas.height, atlas.width)


def dilate(image: np.ndarray, mask: np.ndarray, px: int) -> tuple[np.ndarray, np.ndarray]:
    """Fill ``px`` rings of texels around ``mask``: each ring takes the mean of its filled
    8-neighbours. Returns (image, new mask); filled texels keep their values."""
    img = np.array(image, dtype=np.float64)
    one = img.ndim == 2
    if one:
        img = img[:, :, None]
    m = np.asarray(mask, dtype=bool).copy()
    H, W = m.shape
    for _ in range(max(0, int(px))):
        if m.all() or not m.any():
            break
        vp = np.pad(img * m[:, :, None], ((1, 1), (1, 1), (0, 0)))
        mp = np.pad(m, 1).astype(np.float64)
        acc = np.zeros_like(img)
        cnt = np.zeros((H, W))
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy == 0 and dx == 0:
                    continue
                acc += vp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
                cnt += mp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
        grow = ~m & (cnt > 0)
        img[grow] = acc[grow] / cnt[grow][:, None]
        m = m | grow
    return (img[:, :, 0] if one else img), m


def bilinear_stencil(xy: np.ndarray, W: int, H: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel ids (n, 4) and weights (n, 4) of a bilinear lookup at texel-space points (n, 2)
    (texel centres at half-integers, clamped at the image border)."""
    x = xy[:, 0] - 0.5
    y = xy[:, 1] - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx, fy = x - x0, y - y0
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xs = np.stack([x0, x0 + 1, x0, x0 + 1], axis=1).clip(0, W - 1)
    ys = np.stack([y0, y0, y0 + 1, y0 + 1], axis=1).clip(0, H - 1)
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
    return ys * W + xs, w


def bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookups of an (H, W[, C]) image at lightmap UVs (n, 2) (v up)."""
    img = np.asarray(image, dtype=np.float64)
    H, W = img.shape[:2]
    xy = np.stack([uv[:, 0] * W, (1.0 - uv[:, 1]) * H], axis=1)
    ids, w = bilinear_stencil(xy, W, H)
    flat = img.reshape(H * W, -1)
    out = np.einsum("nk,nkc->nc", w, flat[ids])
    return out[:, 0] if img.ndim == 2 else out
