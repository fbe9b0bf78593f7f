"""Eyes in a view region: seeded, stratified samples (docs/hidden.md, "What is sampled").

* ``outside``: the sphere around the bounding box (centre the box's centre, radius
  ``SPHERE_MARGIN`` x half its diagonal). Every point a model shows to an eye anywhere outside its
  convex hull it also shows to an eye on that sphere (the ray from the point through the eye leaves
  the hull for good once out, so going on backwards along it to the sphere stays clear), so eyes on
  the sphere stand for every outside eye. The eyes form a spherical Fibonacci lattice with a
  seeded shift: eye ``i`` lies in the ``i``-th of ``n`` bands of equal area (stratified in
  height) at a golden-angle longitude plus a seeded turn.
* boxes: a Latin hypercube in each box (each axis cut into ``n`` equal strata, one eye per stratum,
  the strata paired by seeded permutations), jittered inside its cell.
* points and the reader's camera: the point itself (a point region has one eye).

Held-out eyes (the proof) come from the same regions with another seed stream; outside ones lie
between the sphere and ``HOLDOUT_FAR`` times its radius (still outside the hull).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

SPHERE_MARGIN = 1.01
HOLDOUT_FAR = 3.0
GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0


@dataclass(frozen=True)
class Region:
    kind: str  # outside | box | point | camera
    label: str
    lo: np.ndarray | None = None  # box corners, or the point (lo)
    hi: np.ndarray | None = None


def bounding_sphere(positions: np.ndarray) -> tuple[np.ndarray, float]:
    lo, hi = positions.min(axis=0), positions.max(axis=0)
    c = 0.5 * (lo + hi)
    r = 0.5 * float(np.linalg.norm(hi - lo))
    return c, (r if r > 0 else 1.0)


def sphere_eyes(n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) unit vectors: a Fibonacci lattice, one per equal-area band, with seeded shifts."""
    u, turn = rng.random(), rng.random()
    i = np.arange(n, dtype=np.float64)
    z = 1.0 - 2.0 * (i + u) / n
    phi = 2.0 * np.pi * (i * GOLDEN + turn)
    s = np.sqrt(np.clip(1.0 - z * z, 0.0, 1.0))
    return np.stack([s * np.cos(phi), z, s * np.sin(phi)], axis=1)


def box_eyes(lo: np.ndarray, hi: np.ndarray, n: int, rng: np.random.Generator) -> np.ndarray:
    """(n, 3) points in the box: a jittered Latin hypercube."""
    cells = np.stack([rng.permutation(n) for _ in range(3)], axis=1).astype(np.float64)
    t = (cells + rng.random((n, 3))) / n
    return lo + t * (hi - lo)


def regions_of(cfg, positions: np.ndarray, camera: np.ndarray | None) -> list[Region]:
    out: list[Region] = []
    if cfg.outside:
        out.append(Region("outside", "outside"))
    if cfg.camera and camera is not None:
        out.append(Region("camera", "the reader's camera", lo=np.asarray(camera, np.float64)))
    for i, p in enumerate(cfg.points):
        out.append(Region("point", f"points[{i}]", lo=np.asarray(p, np.float64)))
    for i, b in enumerate(cfg.boxes):
        out.append(Region("box", f"boxes[{i}]", lo=np.asarray(b.min, np.float64), hi=np.asarray(b.max, np.float64)))
    return out


def eyes(regions: list[Region], positions: np.ndarray, n: int, rng: np.random.Generator, *,
         holdout: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """``(eyes (E, 3), region index per eye)``: ``n`` eyes on the outside sphere and in each box,
    the point itself for a point region (held out: ``n`` in all, shared by the regions in turn)."""
    c, r = bounding_sphere(positions)
    pts, owner = [], []
    k = len(regions)
    for j, reg in enumerate(regions):
        m = n if not holdout else n // k + (1 if j < n % k else 0)
        if m == 0:
            continue
        if reg.kind == "outside":
            d = sphere_eyes(m, rng)
            rad = SPHERE_MARGIN * r
            if holdout:  # anywhere between the sphere and HOLDOUT_FAR x its radius
                rad = rad * (1.0 + (HOLDOUT_FAR - 1.0) * rng.random(m))[:, None]
            p = c + rad * d
        elif reg.kind == "box":
            p = box_eyes(reg.lo, reg.hi, m, rng)
        else:  # a point, the camera: one place, however many eyes are asked for
            p = reg.lo[None, :]
        pts.append(p)
        owner.append(np.full(len(p), j, np.int64))
    if not pts:
        return np.zeros((0, 3)), np.zeros(0, np.int64)
    return np.concatenate(pts), np.concatenate(owner)


__all__ = ["Region", "bounding_sphere", "sphere_eyes", "box_eyes", "regions_of", "eyes", "SPHERE_MARGIN"]
