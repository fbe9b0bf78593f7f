"""Triangulate stage: polygons -> triangles, with a vectorised check of where a fan is wrong.

``method = "fan"``: every polygon ``v0 v1 ... v(n-1)`` becomes the fan ``(v0, vi, vi+1)``,
``i = 1 .. n-2``, all polygons at once (no Python loop).

``method = "auto"`` (default): the fan is kept wherever it is a valid triangulation. A polygon
goes to ear clipping (``mapbox_earcut`` on its best-fit plane) when, and only when, one of these
holds. The checks are numpy over dense ``(m, n, 3)`` blocks of all polygons with ``n`` corners
(the only loop is over the distinct sizes); triangles skip them (a triangle is its own fan).

* **concave**: a fan triangle's vector area points against the polygon's Newell normal
  (beyond a rounding tolerance). For a simple planar polygon this is exactly the case where the
  fan is wrong: the signed fan areas always add up to the polygon's area, so with no negative
  triangle they cover the polygon exactly once (and the unsigned fan area equals the polygon
  area); with one, fan triangles overlap and the unsigned area is too large.
* **self-intersecting**: the boundary's turning number about the Newell normal is not 1 (a
  simple polygon turns exactly once), or the Newell area is ~0 while the fan area is not
  (figure-eight). Here fan triangles can overlap with none flipped (a pentagram winds twice).
  Checked from 5 corners on: a quad with no flipped fan triangle is always simple.
* **non-planar**: a corner is further than ``NONPLANAR_TOLERANCE * scene.scale()`` from the
  polygon's best-fit plane (the plane through the corner centroid with the Newell normal).
* **sliver**: the fan is valid but one of its triangles has ~zero area (corner 0 collinear with
  two consecutive corners, e.g. a rectangle with edge midpoints, or a repeated corner) while the
  polygon itself has area. The clean stage would drop that triangle and the polygon would stop
  being whole (``tri_polygon = -1``); earcut's triangles are made proper (see below), so all
  ``n - 2`` triangles are kept (a repeated corner is dropped instead, see below).

Degenerate polygons (all fan triangles of ~zero area: repeated or collinear corners) are
fanned and left for the clean stage to drop.

Ear clipping works in a local frame: corner 0 is subtracted from every corner (exact, so large
coordinates lose nothing and a model translated by an exactly representable offset gets
bit-identical triangles), then the corner centroid of those differences, then the corners are
projected on an orthonormal basis ``(u, v)`` with ``u x v = n`` (Newell normal; for a zero-area
self-intersecting polygon the normal of the least-squares plane). Earcut's triangles are oriented
so each one's normal agrees with ``n``. The only Python loop is over the polygons that need the
fallback.

Collinear corners after a rotation (docs/reliability.md item 5): corners on a straight edge are
collinear in the projection only up to rounding, and earcut then cuts ears of ~zero area there
(a rotated comb: 20 of 40 rotations), which clean would drop. Every earcut triangle with area at
most ``EAR_TOLERANCE * L^2`` is repaired by flipping its long edge with the triangle across it,
when both new triangles are proper (``_flip_degenerate``: numpy over all such triangles at once,
a few rounds). Rarely a corner rounds to *exactly* collinear and earcut drops it, returning fewer
than ``n - 2`` triangles; that polygon is earcut again in a few turned in-plane frames and the
first whole, proper result is kept (``earcut_turned``).

Guarantees (tested): every triangle uses corners of its own polygon; for every planar polygon
the triangles' areas add up to the polygon's area and no triangle's normal points against the
polygon's normal (and they cover it exactly once); for a non-planar one the same holds for the
projection on its Newell plane. The fan (so ``method="fan"`` and every polygon that is not a
fallback) gives ``n - 2`` triangles, and so does every polygon: where earcut would drop a
corner (one that repeats its neighbour's position, or whose projection is a zero-width spike of
a non-planar polygon), the polygon keeps a fan instead — from the corner whose fan has the
largest smallest triangle along the Newell normal — and the record counts it in
``earcut_short_used_fan`` (``earcut_dropped_corners`` says how many corners earcut would have
dropped); degenerate fan triangles are then dropped and counted by the clean stage. So
triangles = sum(n - 2) over polygons with 3 or more corners. Polygons with fewer than 3 corners
give no triangle (counted and warned). A simple polygon whose corners are collinear only up to
rounding (any rotation of one with corners on its edges) gets no triangle of area at most
``EAR_TOLERANCE * L^2`` (tests/mesh/test_triangulate_collinear.py: 200 rotations each of combs,
Ls and stars with corners on their edges).
"""

from __future__ import annotations

import time
from dataclasses import dataclass
from typing import NamedTuple

import numpy as np

from ..config import TriangulateConfig
from ..errors import ConfigError
from ..record import StageRecord
from ..scene import Scene

try:  # pragma: no cover - import guard
    import mapbox_earcut as _earcut
except ImportError:  # pragma: no cover
    _earcut = None

# A corner further than this fraction of the scene scale from the polygon's best-fit plane makes
# the polygon non-planar (1e-3: a fold you could see at ~1 pixel on a 1000 px view of the model).
NONPLANAR_TOLERANCE = 1e-3
# A fan triangle is flipped when its area along the normal is below -FLIP_TOLERANCE * L^2, with L
# the polygon's largest distance from corner 0 (far above float64 rounding of L^2).
FLIP_TOLERANCE = 1e-10
# A polygon whose fan triangles add up to less than DEGENERATE_TOLERANCE * L^2 is degenerate
# (repeated / collinear corners) ...
DEGENERATE_TOLERANCE = 1e-12
# ... as is one below this fraction of scale^2 (clean's default area tolerance drops it anyway).
SCENE_AREA_TOLERANCE = 1e-14
# An earcut triangle whose area is at most EAR_TOLERANCE * L^2 (L as above, measured in the plane
# projection) is an ear cut at corners that are collinear up to rounding; it is repaired by an
# edge flip (see _flip_degenerate). 1e-10: a hundred times the sliver tolerance of the fan check,
# so no repaired triangle comes near it, and still far below any triangle a model means to have.
EAR_TOLERANCE = 1e-10
# Polygons are analysed in dense blocks of at most this many corners (memory ~100 bytes a corner).
_BLOCK_CORNERS = 1 << 21


@dataclass(frozen=True)
class PolygonAnalysis:
    """Per-polygon figures for the fan check (arrays of length P)."""

    normal: np.ndarray  # (P, 3) Newell vector area (|normal| = area for planar polygons)
    area: np.ndarray  # (P,) |normal|
    fan_area: np.ndarray  # (P,) sum of |fan triangle areas| (3-D)
    reach: np.ndarray  # (P,) largest distance of a corner from corner 0
    deviation: np.ndarray  # (P,) largest distance of a corner from the best-fit plane
    turning: np.ndarray  # (P,) turning number of the boundary about the normal
    small: np.ndarray  # (P,) bool, fewer than 3 corners
    degenerate: np.ndarray  # (P,) bool
    concave: np.ndarray  # (P,) bool, a fan triangle is flipped
    self_intersecting: np.ndarray  # (P,) bool
    nonplanar: np.ndarray  # (P,) bool
    sliver: np.ndarray  # (P,) bool, a fan triangle has ~zero area in a polygon that has area

    @property
    def fan_wrong(self) -> np.ndarray:
        return ~self.small & ~self.degenerate & (self.concave | self.self_intersecting)

    @property
    def fallback(self) -> np.ndarray:
        return ~self.small & ~self.degenerate & (self.concave | self.self_intersecting | self.nonplanar
                                                 | self.sliver)


class Triangulation(NamedTuple):
    corners: np.ndarray  # (T, 3) int64 indices into the flat corner array (poly_indices / poly_uvs)
    polygon: np.ndarray  # (T,) int64 source polygon
    analysis: PolygonAnalysis
    stats: dict


# --------------------------------------------------------------------------- helpers
def _offsets(sizes: np.ndarray) -> np.ndarray:
    off = np.zeros(len(sizes) + 1, np.int64)
    np.cumsum(sizes, out=off[1:])
    return off


def fan_corners(sizes: np.ndarray, offsets: np.ndarray | None = None,
                select: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray]:
    """Fan triangles ``(c0, ci, ci+1)`` of every polygon (or the ``select`` mask), as corner
    indices into the flat corner array, plus the polygon of each triangle. Polygons with fewer
    than 3 corners give none."""
    sizes = np.asarray(sizes, np.int64)
    off = _offsets(sizes) if offsets is None else offsets
    counts = np.maximum(sizes - 2, 0)
    if select is not None:
        counts = np.where(select, counts, 0)
    T = int(counts.sum())
    poly = np.repeat(np.arange(len(sizes), dtype=np.int64), counts)
    tstart = np.zeros(len(sizes), np.int64)
    np.cumsum(counts[:-1], out=tstart[1:])
    i = np.arange(T, dtype=np.int64) - tstart[poly] + 1  # 1 .. n-2
    base = off[:-1][poly]
    return np.stack([base, base + i, base + i + 1], axis=1), poly


def best_fan_corners(positions: np.ndarray, indices: np.ndarray, offsets: np.ndarray,
                     polys: np.ndarray, normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """For each polygon in ``polys``, the fan whose smallest triangle area along the polygon's
    Newell normal is largest (ties: the lowest start corner), as corner indices + polygon.

    Used only for the rare polygons earcut cannot split into n - 2 triangles (a folded,
    non-planar polygon: the fan from corner 0 may flip where a fan from another corner does not).
    One small numpy evaluation per such polygon.
    """
    out_c, out_p = [], []
    for p in polys.tolist():
        a, b = int(offsets[p]), int(offsets[p + 1])
        n = b - a
        pts = positions[indices[a:b]]
        pts = pts - pts.mean(axis=0)
        nh = normals[p] / max(float(np.linalg.norm(normals[p])), 1e-300)
        s = np.arange(n)[:, None]
        i = np.arange(1, n - 1)[None, :]
        c0, c1, c2 = s + 0 * i, (s + i) % n, (s + i + 1) % n  # (n, n-2) local corners
        area = _dot(_cross(pts[c1] - pts[c0], pts[c2] - pts[c0]), nh)
        best = int(np.argmax(area.min(axis=1)))
        out_c.append(np.stack([c0[best], c1[best], c2[best]], axis=1) + a)
        out_p.append(np.full(n - 2, p, np.int64))
    if not out_c:
        return np.zeros((0, 3), np.int64), np.zeros(0, np.int64)
    return np.concatenate(out_c), np.concatenate(out_p)


def _cross(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    """Cross product over the last axis (plain arithmetic: faster than np.cross on big arrays)."""
    out = np.empty(np.broadcast_shapes(a.shape, b.shape))
    out[..., 0] = a[..., 1] * b[..., 2] - a[..., 2] * b[..., 1]
    out[..., 1] = a[..., 2] * b[..., 0] - a[..., 0] * b[..., 2]
    out[..., 2] = a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]
    return out


def _dot(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1] + a[..., 2] * b[..., 2]


def analyse_polygons(positions: np.ndarray, sizes: np.ndarray, indices: np.ndarray,
                     scale: float | None = None) -> PolygonAnalysis:
    """Newell normals, fan flips, turning numbers and planarity of every polygon.

    Vectorised per polygon size: all polygons with ``n`` corners are one dense ``(m, n, 3)``
    block, so the loop runs over the distinct sizes only. Corner 0 of each polygon is the local
    origin (exact differences, so large coordinates cost no precision).
    """
    positions = np.asarray(positions, np.float64)
    sizes = np.asarray(sizes, np.int64)
    indices = np.asarray(indices, np.int64)
    P = len(sizes)
    if scale is None:
        scale = _scale_of(positions, indices)
    off = _offsets(sizes)
    small = sizes < 3
    normal = np.zeros((P, 3))
    fan_area = np.zeros(P)
    reach = np.zeros(P)
    deviation = np.zeros(P)
    turning = np.ones(P, np.int64)
    concave = np.zeros(P, bool)
    sliver = np.zeros(P, bool)
    tiny = SCENE_AREA_TOLERANCE * scale * scale
    blocks = []
    for n in np.unique(sizes[~small]).tolist():
        all_rows = np.flatnonzero(sizes == n)
        step = max(1, _BLOCK_CORNERS // n)  # bounded memory: at most ~_BLOCK_CORNERS corners a block
        blocks += [(n, all_rows[i:i + step]) for i in range(0, len(all_rows), step)]
    for n, rows in blocks:
        p = positions[indices[off[rows][:, None] + np.arange(n)]]  # (m, n, 3)
        q = p - p[:, :1]
        r2 = _dot(q, q).max(axis=1)
        terms = 0.5 * _cross(q[:, 1:n - 1], q[:, 2:n])  # fan triangle vector areas (m, n-2, 3)
        N = terms.sum(axis=1)  # == the Newell vector area (the two terms with corner 0 vanish)
        A = np.sqrt(_dot(N, N))
        normal[rows], reach[rows] = N, np.sqrt(r2)
        tri_area = np.sqrt(_dot(terms, terms))
        fan_area[rows] = tri_area.sum(axis=1)
        if n == 3:
            continue  # a triangle is its own fan: never concave, non-planar or self-intersecting
        nhat = np.divide(N, A[:, None], out=np.zeros_like(N), where=A[:, None] > 0)
        along = _dot(terms, nhat[:, None])
        conc = (along < -FLIP_TOLERANCE * r2[:, None]).any(axis=1)
        concave[rows] = conc
        sliver[rows] = ((tri_area <= DEGENERATE_TOLERANCE * r2[:, None]) | (tri_area <= tiny)).any(axis=1)
        cen = q.mean(axis=1)
        deviation[rows] = np.abs(_dot(q - cen[:, None], nhat[:, None])).max(axis=1)
        if n >= 5:
            # a quad with no flipped fan triangle is simple (the diagonal 0-2 separates corners
            # 1 and 3), so quads skip this; from 5 corners on, a boundary can wind twice
            turning[rows] = _turning_numbers(q, nhat, r2)
    area = np.linalg.norm(normal, axis=1)
    ok = ~small
    degenerate = ok & ((reach == 0) | (fan_area <= DEGENERATE_TOLERANCE * reach * reach)
                       | (fan_area <= SCENE_AREA_TOLERANCE * scale * scale))
    live = ok & ~degenerate
    zero_net = area <= DEGENERATE_TOLERANCE * reach * reach
    self_int = live & ((turning != 1) | zero_net)
    concave = live & concave & ~zero_net
    nonplanar = live & ~zero_net & (deviation > NONPLANAR_TOLERANCE * scale)
    sliver = live & sliver
    return PolygonAnalysis(normal=normal, area=area, fan_area=fan_area, reach=reach, deviation=deviation,
                           turning=turning, small=small, degenerate=degenerate, concave=concave,
                           self_intersecting=self_int, nonplanar=nonplanar, sliver=sliver)


def _turning_numbers(q: np.ndarray, nhat: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """Turning number of each polygon ``(m, n, 3)`` projected on the plane of its normal.

    Edge directions are measured in ``(u, v)`` with ``u x v = n``; a zero-length edge (repeated
    corner) takes the direction of the edge before it, so the turn at a repeated corner is not
    lost; the wrapped direction changes add up to ``2 pi * turning number``."""
    m, n, _ = q.shape
    e = np.roll(q, -1, axis=1) - q
    u, v = _plane_bases(nhat)
    ex = _dot(e, u[:, None])
    ey = _dot(e, v[:, None])
    valid = (ex * ex + ey * ey) > 1e-24 * r2[:, None]
    theta = np.arctan2(ey, ex)
    idx = np.where(valid, np.arange(n), -1)
    ff = np.maximum.accumulate(idx, axis=1)
    ff = np.where(ff < 0, ff[:, -1:], ff)  # before the first valid edge: the last one (cyclic)
    th = np.take_along_axis(theta, np.maximum(ff, 0), axis=1)
    d = np.roll(th, -1, axis=1) - th
    d = (d + np.pi) % (2 * np.pi) - np.pi  # wrapped to [-pi, pi)
    return np.rint(d.sum(axis=1) / (2 * np.pi)).astype(np.int64)


def _plane_bases(nhat: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal ``u, v`` with ``u x v = n`` for unit (or zero) normals ``(P, 3)``."""
    nhat = np.atleast_2d(nhat)
    a = np.zeros_like(nhat)
    a[np.arange(len(nhat)), np.argmin(np.abs(nhat), axis=1)] = 1.0
    u = _cross(a, nhat)
    ln = np.sqrt(_dot(u, u))[:, None]
    u = np.divide(u, ln, out=np.zeros_like(u), where=ln > 0)
    return u, _cross(nhat, u)


def _scale_of(positions: np.ndarray, indices: np.ndarray) -> float:
    p = positions[np.unique(indices)] if len(indices) else positions
    if len(p) == 0:
        return 1.0
    d = float(np.linalg.norm(p.max(0) - p.min(0)))
    if d > 0 and np.isfinite(d):
        return d
    m = float(np.abs(p).max())
    return m if m > 0 else 1.0


def plane_basis(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Orthonormal ``u, v`` with ``u x v = normal / |normal|``."""
    n = np.asarray(normal, np.float64)
    u, v = _plane_bases((n / np.linalg.norm(n))[None])
    return u[0], v[0]


def _project(points: np.ndarray, cp: np.ndarray, starts: np.ndarray, counts: np.ndarray,
             normals: np.ndarray) -> np.ndarray:
    """2-D coordinates of flat corner ``points`` of several polygons (``cp``: polygon of each
    corner, ``starts``/``counts``: their runs) on the planes of ``normals``: relative to corner 0,
    then to the corner centroid; a ~zero normal is replaced by the least-squares plane normal."""
    q = points - points[starts][cp]
    q = q - (np.add.reduceat(q, starts, axis=0) / counts[:, None])[cp]
    nrm = np.asarray(normals, np.float64).copy()
    ln = np.sqrt(_dot(nrm, nrm))
    r2 = np.maximum.reduceat(_dot(q, q), starts)
    for k in np.flatnonzero(~(ln > DEGENERATE_TOLERANCE * r2)):  # zero net area (rare)
        s = int(starts[k])
        nrm[k] = np.linalg.svd(q[s:s + int(counts[k])], full_matrices=False)[2][-1]
        ln[k] = 1.0
    nhat = nrm / ln[:, None]
    u, v = _plane_bases(nhat)
    return np.stack([_dot(q, u[cp]), _dot(q, v[cp])], axis=1)


class _Earcut(NamedTuple):
    tris: np.ndarray  # (T, 3) indices into xy, counter-clockwise
    run: np.ndarray  # (T,) run (polygon) of each triangle
    flips: np.ndarray  # (R,) edge flips made in each run (_flip_degenerate)
    turned: np.ndarray  # (R,) bool, earcut was short and was run again in a turned frame


# In-plane turns (radians) tried, in order, when earcut drops corners of a polygon (rare).
_RETRY_TURNS = (0.5, 1.3, 2.2)


def _earcut_runs(xy: np.ndarray, starts: np.ndarray, counts: np.ndarray) -> _Earcut:
    """Earcut each run of ``xy``; triangles as indices into ``xy``, oriented counter-clockwise.

    Two repairs keep earcut's output whole where corners are collinear only up to rounding (a
    rotated straight edge):

    * earcut cuts ears of ~zero area at such corners: they are removed by edge flips
      (``_flip_degenerate``);
    * earcut drops a corner whose projection rounds to *exactly* collinear with its neighbours
      (sometimes after using it in other ears, leaving a zero-area gap) and returns fewer than
      ``n - 2`` triangles: the run is earcut again with its plane coordinates turned by a few
      fixed angles (``_RETRY_TURNS``), which rounds the corners differently; the first complete
      result is kept and its coordinates are the ones ``xy`` holds for that run from then on (a
      turn keeps lengths and areas, so all tolerances stay valid). A repeated corner or a
      zero-width spike of a folded polygon is dropped in every frame: the run stays short and
      the caller keeps a fan for it.
    """
    if _earcut is None:  # pragma: no cover
        raise RuntimeError("mapbox_earcut is not installed")
    R = len(starts)
    flips = np.zeros(R, np.int64)
    turned = np.zeros(R, bool)
    if not R:
        return _Earcut(np.zeros((0, 3), np.int64), np.zeros(0, np.int64), flips, turned)
    d = xy - xy[starts][np.repeat(np.arange(R), counts)]
    r2 = np.maximum.reduceat(_dot2(d, d), starts)  # L^2: largest squared distance from corner 0
    limit = 2.0 * EAR_TOLERANCE * r2  # doubled area at or below which a triangle is degenerate
    tris, which = [], []
    copied = False
    for k in range(R):  # the fallback loop: one earcut call per polygon
        s, n = int(starts[k]), int(counts[k])
        t = _earcut_one(xy[s:s + n])
        if len(t) < n - 2:  # rare: earcut dropped corners
            t, turn, flips[k] = _earcut_turned(xy[s:s + n], t, limit[k:k + 1])
            if turn is not None:
                if not copied:
                    xy, copied = xy.copy(), True
                xy[s:s + n] = turn
                turned[k] = True
        tris.append(t + s)
        which.append(np.full(len(t), k, np.int64))
    t = _orient(xy, np.concatenate(tris))
    w = np.concatenate(which)
    if len(t):
        t, more = _flip_degenerate(xy, t, w, limit)
        flips += more
    return _Earcut(t, w, flips, turned)


def _earcut_turned(xy: np.ndarray, t: np.ndarray, limit: np.ndarray
                   ) -> tuple[np.ndarray, np.ndarray | None, int]:
    """Earcut one polygon again in turned frames; the first that gives ``n - 2`` triangles, all
    proper after ``_flip_degenerate``, wins: (triangles, turned coordinates, flips). Otherwise
    earcut's short result, ``None`` and 0."""
    n = len(xy)
    for a in _RETRY_TURNS:
        turn = xy @ np.array([[np.cos(a), np.sin(a)], [-np.sin(a), np.cos(a)]])
        t2 = _earcut_one(turn)
        if len(t2) != n - 2:
            continue
        t2, f = _flip_degenerate(turn, _orient(turn, t2), np.zeros(n - 2, np.int64), limit)
        if (_cross2(turn, t2) > limit[0]).all():
            return t2, turn, int(f[0])
    return t, None, 0


def _earcut_one(xy: np.ndarray) -> np.ndarray:
    t = _earcut.triangulate_float64(np.ascontiguousarray(xy), np.array([len(xy)], np.uint32))
    return np.asarray(t, np.int64).reshape(-1, 3)


def _orient(xy: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``t`` with every triangle counter-clockwise in ``xy`` (mapbox-earcut 2.x already returns
    counter-clockwise triangles; be sure)."""
    t = t.copy()
    if len(t):
        swap = _cross2(xy, t) < 0
        t[swap] = t[swap][:, [0, 2, 1]]
    return t


def _cross2(xy: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Twice the signed area of the 2-D triangles ``xy[t]`` (counter-clockwise positive)."""
    a, b, c = xy[t[:, 0]], xy[t[:, 1]], xy[t[:, 2]]
    return (b[:, 0] - a[:, 0]) * (c[:, 1] - a[:, 1]) - (b[:, 1] - a[:, 1]) * (c[:, 0] - a[:, 0])


def _dot2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 0] + a[..., 1] * b[..., 1]


def _flip_degenerate(xy: np.ndarray, t: np.ndarray, w: np.ndarray, limit: np.ndarray
                     ) -> tuple[np.ndarray, np.ndarray]:
    """Repair earcut triangles of ~zero area by edge flips; returns the triangles and the number
    of flips in each run.

    ``t``: counter-clockwise triangles (indices into ``xy``), ``w``: run (polygon) of each,
    ``limit``: per run, the doubled area at or below which a triangle is degenerate.

    Earcut accepts an ear whose corners are collinear up to rounding (after a rotation, corners on
    a straight line are no longer exactly collinear in the projection): a triangle ``(x, b, y)``
    with ``b`` on its long edge ``x-y``. The triangle across that edge, ``(x, y, d)``
    counter-clockwise, is proper, so the quad ``x b y d`` is convex at ``b`` and flipping the
    diagonal gives ``(b, y, d)`` and ``(b, d, x)``: the same quad, the same count, the same signed
    area. A flip is made only when both new triangles are proper (doubled area above ``limit``),
    so it never makes a triangle degenerate or turns one against the normal, and every round
    removes at least one degenerate triangle (the loop ends). A degenerate triangle whose
    neighbour across the long edge is degenerate too waits for that one to be repaired first; one
    with no neighbour there (a corner touching another edge) or whose flip would not give two
    proper triangles (a repeated corner) is left as it is.

    Vectorised: each round builds the undirected edge table of the polygons that have a
    degenerate triangle and flips every candidate that shares no triangle with an earlier one.
    """
    t = t.copy()
    flips = np.zeros(len(limit), np.int64)
    n = np.int64(len(xy))
    while True:
        bad = _cross2(xy, t) <= limit[w]
        if not bad.any():
            break
        affected = np.zeros(len(limit), bool)
        affected[w[bad]] = True
        sel = np.flatnonzero(affected[w])  # triangles of polygons with a degenerate triangle
        ts, bs = t[sel], bad[sel]
        lo = np.minimum(ts, np.roll(ts, -1, axis=1))  # edge k: corner k -> corner k + 1
        hi = np.maximum(ts, np.roll(ts, -1, axis=1))
        keys = (lo * n + hi).ravel()
        order = np.argsort(keys, kind="stable")
        skeys = keys[order]
        bi = np.flatnonzero(bs)
        tb = ts[bi]
        e = xy[np.roll(tb, -1, axis=1)] - xy[tb]
        k = np.argmax(_dot2(e, e), axis=1)  # the long edge
        r = np.arange(len(bi))
        x, y, b = tb[r, k], tb[r, (k + 1) % 3], tb[r, (k + 2) % 3]
        key = np.minimum(x, y) * n + np.maximum(x, y)
        left = np.searchsorted(skeys, key, "left")
        ok = np.searchsorted(skeys, key, "right") - left == 2  # an inner edge of a manifold fan
        left = np.minimum(left, len(skeys) - 2)
        t1, t2 = order[left] // 3, order[left + 1] // 3
        nb = np.where(t1 == bi, t2, t1)
        ok &= (nb != bi) & ~bs[nb]
        B = ts[nb]
        other = (B != x[:, None]) & (B != y[:, None])
        ok &= other.sum(axis=1) == 1
        j = np.argmax(other, axis=1)
        d, p, q = B[r, j], B[r, (j + 1) % 3], B[r, (j + 2) % 3]  # B = (p, q, d) counter-clockwise
        new1 = np.stack([b, q, d], axis=1)
        new2 = np.stack([b, d, p], axis=1)
        lim = limit[w[sel[bi]]]
        ok &= (_cross2(xy, new1) > lim) & (_cross2(xy, new2) > lim)
        cand = np.flatnonzero(ok)
        if not len(cand):
            break
        # each triangle in at most one flip a round: the first candidate that uses it wins
        first = np.full(len(ts), len(cand), np.int64)
        rank = np.arange(len(cand))
        np.minimum.at(first, bi[cand], rank)
        np.minimum.at(first, nb[cand], rank)
        go = cand[(first[bi[cand]] == rank) & (first[nb[cand]] == rank)]
        t[sel[bi[go]]] = new1[go]
        t[sel[nb[go]]] = new2[go]
        np.add.at(flips, w[sel[bi[go]]], 1)
    return t, flips


def earcut_polygon(points: np.ndarray, normal: np.ndarray | None = None) -> np.ndarray:
    """Ear-clip one polygon given as ``(n, 3)`` corner positions (in order).

    Returns ``(m, 3)`` local corner indices, each triangle oriented so its normal agrees with
    ``normal`` (default: the Newell normal, or the least-squares plane normal when that is ~0).
    ``m`` is ``n - 2`` unless earcut drops repeated corners; empty if earcut finds nothing.
    """
    pts = np.asarray(points, np.float64)
    n = len(pts)
    if normal is None:
        q = pts - pts[0]
        normal = 0.5 * _cross(q, np.roll(q, -1, axis=0)).sum(axis=0)
    starts = np.zeros(1, np.int64)
    counts = np.array([n], np.int64)
    xy = _project(pts, np.zeros(n, np.int64), starts, counts, np.asarray(normal, np.float64)[None])
    return _earcut_runs(xy, starts, counts).tris


def triangulate(positions: np.ndarray, sizes: np.ndarray, indices: np.ndarray, method: str = "auto",
                scale: float | None = None) -> Triangulation:
    """Triangulate polygons given as flat arrays. Returns corner indices (index ``indices`` or
    per-corner UVs with them), the source polygon of each triangle, the analysis and counts."""
    if method not in ("auto", "fan"):
        raise ConfigError(f"unknown triangulation method {method!r} (expected 'auto' or 'fan')",
                          key="mesh.triangulate.method")
    positions = np.asarray(positions, np.float64)
    sizes = np.asarray(sizes, np.int64)
    indices = np.asarray(indices, np.int64)
    if scale is None:
        scale = _scale_of(positions, indices)
    off = _offsets(sizes)
    an = analyse_polygons(positions, sizes, indices, scale)
    stats: dict = {
        "polygons": int(len(sizes)),
        "skipped_small": int(an.small.sum()),
        "degenerate": int(an.degenerate.sum()),
        "fan_wrong": int(an.fan_wrong.sum()),
        "nonplanar": int(an.nonplanar.sum()),
        "fallback": 0,
        "fallback_concave": 0,
        "fallback_self_intersecting": 0,
        "fallback_nonplanar": 0,
        "fallback_sliver": 0,
        "earcut_dropped_corners": 0,
        "earcut_short_used_fan": 0,
        "earcut_flips": 0,
        "earcut_turned": 0,
    }
    if method == "fan":
        corners, poly = fan_corners(sizes, off)
        return Triangulation(corners, poly, an, stats)

    fb = an.fallback
    stats["fallback"] = int(fb.sum())
    stats["fallback_concave"] = int((fb & an.concave).sum())
    stats["fallback_self_intersecting"] = int((fb & an.self_intersecting).sum())
    stats["fallback_nonplanar"] = int((fb & an.nonplanar).sum())
    stats["fallback_sliver"] = int((fb & an.sliver).sum())
    fan_c, fan_p = fan_corners(sizes, off, select=~fb)
    parts_c, parts_p = [fan_c], [fan_p]
    rows = np.flatnonzero(fb)
    if len(rows):
        # vectorised gather and projection of every fallback polygon, then one earcut call each
        cnt = sizes[rows]
        starts = _offsets(cnt)[:-1]
        cp = np.repeat(np.arange(len(rows)), cnt)
        corner = off[rows][cp] + np.arange(int(cnt.sum())) - starts[cp]  # flat corner index
        xy = _project(positions[indices[corner]], cp, starts, cnt, an.normal[rows])
        ec = _earcut_runs(xy, starts, cnt)
        t, w = ec.tris, ec.run
        got = np.bincount(w, minlength=len(rows))
        # earcut drops corners that repeat a neighbour or project to a zero-width spike (a
        # non-planar polygon seen edge-on) in every frame (exactly collinear corners of a rotated
        # planar polygon are handled by _earcut_runs). Those polygons keep the fan instead, so every
        # polygon gives n - 2 triangles and no real surface is lost; degenerate fan triangles
        # are left for the clean stage to drop and count.
        short = got < cnt - 2
        stats["earcut_dropped_corners"] = int(((cnt - 2) - got)[short].sum())
        keep = ~short[w]
        stats["earcut_flips"] = int(ec.flips[~short].sum())
        stats["earcut_turned"] = int(ec.turned.sum())
        parts_c.append(corner[t[keep]])
        parts_p.append(rows[w[keep]])
        failed = rows[short]
        if len(failed):
            c, pp = best_fan_corners(positions, indices, off, failed, an.normal)
            parts_c.append(c)
            parts_p.append(pp)
            stats["earcut_short_used_fan"] = int(len(failed))
    corners = np.asarray(np.concatenate(parts_c), np.int64)
    poly = np.asarray(np.concatenate(parts_p), np.int64)
    order = np.argsort(poly, kind="stable")
    return Triangulation(corners[order], poly[order], an, stats)


def stage(scene: Scene, cfg: TriangulateConfig) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord(name="triangulate")
    if scene.poly_sizes is None or scene.poly_indices is None:
        rec.details = {"note": "no polygons; triangles kept as they are"}
        rec.seconds = time.perf_counter() - t0
        return scene, rec
    tr = triangulate(scene.positions, scene.poly_sizes, scene.poly_indices, cfg.method, scene.scale())
    corners, poly = tr.corners, tr.polygon
    triangles = scene.poly_indices[corners] if len(corners) else np.zeros((0, 3), np.int64)
    pm = scene.poly_material if scene.poly_material is not None else np.zeros(scene.n_polygons, np.int64)
    changes: dict = {
        "triangles": np.asarray(triangles, np.int64),
        "tri_material": np.asarray(pm[poly], np.int64),
        "tri_uvs": None if scene.poly_uvs is None else scene.poly_uvs[corners],
        "tri_polygon": poly,
        "face_colors": None,
    }
    if scene.face_colors is not None:
        fc = _face_colors_per_polygon(scene)
        if fc is None:
            rec.warn("face colours dropped: they could not be matched to polygons")
        else:
            changes["face_colors"] = fc[poly]
    out = scene.replace(**changes)
    st = tr.stats
    if st["skipped_small"]:
        rec.warn(f"{st['skipped_small']} polygon(s) with fewer than 3 corners gave no triangle")
    if cfg.method == "fan" and st["fan_wrong"]:
        rec.warn(f"method = 'fan': {st['fan_wrong']} concave or self-intersecting polygon(s) are "
                 "triangulated wrongly (use method = 'auto')")
    if st["earcut_short_used_fan"]:
        rec.warn(f"ear clipping would drop corners of {st['earcut_short_used_fan']} polygon(s) "
                 "(repeated or edge-on corners); kept their fan")
    rec.counts_in = {"polygons": scene.n_polygons, "corners": int(len(scene.poly_indices))}
    rec.counts_out = {"triangles": out.n_triangles, "polygons": out.n_polygons,
                      "vertices": out.n_vertices, "materials": len(out.materials)}
    rec.details = {
        "method": cfg.method,
        "expected_triangles": int(np.maximum(scene.poly_sizes - 2, 0).sum()),
        "fallback": {"total": st["fallback"], "concave": st["fallback_concave"],
                     "self_intersecting": st["fallback_self_intersecting"],
                     "nonplanar": st["fallback_nonplanar"], "sliver": st["fallback_sliver"]},
        "degenerate_polygons": st["degenerate"],
        "skipped_small_polygons": st["skipped_small"],
        "fan_wrong_polygons": st["fan_wrong"],
        "nonplanar_polygons": st["nonplanar"],
        "earcut_dropped_corners": st["earcut_dropped_corners"],
        "earcut_short_used_fan": st["earcut_short_used_fan"],
        "earcut_flips": st["earcut_flips"],
        "earcut_turned": st["earcut_turned"],
        "nonplanar_tolerance": NONPLANAR_TOLERANCE,
    }
    rec.seconds = time.perf_counter() - t0
    rec.details["seconds"] = rec.seconds
    return out, rec


def _face_colors_per_polygon(scene: Scene) -> np.ndarray | None:
    """Colour of each polygon from the scene's existing per-triangle colours (first triangle)."""
    if scene.tri_polygon is None or scene.face_colors is None:
        return None
    tp = scene.tri_polygon
    good = (tp >= 0) & (tp < scene.n_polygons)
    uniq, first = np.unique(tp[good], return_index=True)
    if len(uniq) != scene.n_polygons:
        return None
    return scene.face_colors[np.flatnonzero(good)[first]]


__all__ = ["stage", "triangulate", "analyse_polygons", "fan_corners", "earcut_polygon", "plane_basis",
           "PolygonAnalysis", "Triangulation", "NONPLANAR_TOLERANCE"]
