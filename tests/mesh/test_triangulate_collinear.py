"""Collinear corners under random rotations (issue #10, docs/reliability.md item 5).

Once a polygon is rotated, corners on a straight line are collinear only up to rounding in the
plane projection earcut sees, and earcut used to cut zero-area ears there (the clean stage then
dropped them). Triangulate must give ``n - 2`` proper triangles for every such polygon: none with
area <= 1e-12 * size^2, none facing against the polygon, and their areas add up to the polygon's.
"""

from __future__ import annotations

import numpy as np
import pytest

from bake.config import TriangulateConfig
from bake.mesh.triangulate import earcut_polygon, stage, triangulate
from bake.scene import make_scene


def _rotation(rng: np.random.Generator) -> np.ndarray:
    q, r = np.linalg.qr(rng.normal(size=(3, 3)))
    q = q * np.sign(np.diag(r))
    if np.linalg.det(q) < 0:
        q[:, 0] = -q[:, 0]
    return q


def _with_midpoints(xy, k: int = 1) -> np.ndarray:
    """``k`` evenly spaced corners inserted on every edge."""
    xy = np.asarray(xy, float)
    out = []
    for a, b in zip(xy, np.roll(xy, -1, axis=0)):
        out += [a + (b - a) * i / (k + 1) for i in range(k + 1)]
    return np.array(out)


def _star(n: int, r_in: float) -> np.ndarray:
    ang = np.arange(2 * n) * np.pi / n
    r = np.where(np.arange(2 * n) % 2 == 0, 1.0, r_in)
    return np.stack([r * np.cos(ang), r * np.sin(ang)], 1)


COMB = np.array([(0, 0), (5, 0), (5, 3), (4, 3), (4, 1), (3, 1), (3, 3), (2, 3), (2, 1), (1, 1), (1, 3), (0, 3)],
                float) * 0.5
POLYGONS = {
    "comb": COMB,
    "comb_midpoints": _with_midpoints(COMB),
    # a long comb: its inner baseline is 8 collinear corners, 2 per edge of the bottom
    "comb8": np.array([(0, 0), (9, 0)] + [p for i in range(4) for p in ((9 - 2 * i, 3), (8 - 2 * i, 3),
                                                                        (8 - 2 * i, 1), (7 - 2 * i, 1))]
                      + [(1, 3), (0, 3)], float),
    "L_midpoints": _with_midpoints([(0, 0), (4, 0), (4, 1), (1, 1), (1, 3), (0, 3)]),
    "L_thirds": _with_midpoints([(0, 0), (4, 0), (4, 1), (1, 1), (1, 3), (0, 3)], k=2),
    "star_midpoints": _with_midpoints(_star(5, 0.4)),
    "star7_midpoints": _with_midpoints(_star(7, 0.3)),
    "rectangle_midpoints": _with_midpoints([(0, 0), (2, 0), (2, 1), (0, 1)], k=3),
    # a U whose bottom edge is cut in 6 by corners, the inner bottom collinear with two of them
    "U": np.array([(0, 0), (1, 0), (2, 0), (3, 0), (4, 0), (5, 0), (6, 0), (6, 3), (5, 3), (5, 1), (4, 1),
                   (2, 1), (1, 1), (1, 3), (0, 3)], float),
}


def _shoelace(xy: np.ndarray) -> float:
    x, y = xy[:, 0], xy[:, 1]
    return 0.5 * float(np.sum(x * np.roll(y, -1) - np.roll(x, -1) * y))


def _vec_areas(tri: np.ndarray) -> np.ndarray:
    return 0.5 * np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])


@pytest.mark.parametrize("name", sorted(POLYGONS))
def test_collinear_corners_under_200_rotations(name):
    xy = POLYGONS[name]
    n = len(xy)
    area = _shoelace(xy)
    assert area > 0  # counter-clockwise: the rotated z axis is the polygon's normal
    size = float(np.ptp(xy, axis=0).max())
    rng = np.random.default_rng(sum(map(ord, name)))
    rots = [_rotation(rng) for _ in range(200)]
    # all 200 rotated copies in one scene (the vectorised path), then checked one by one
    pos = np.concatenate([np.c_[xy, np.zeros(n)] @ R.T for R in rots])
    polys = [list(range(k * n, (k + 1) * n)) for k in range(len(rots))]
    out, rec = stage(make_scene(pos, polygons=polys), TriangulateConfig())
    assert out.n_triangles == len(rots) * (n - 2)
    assert rec.details["earcut_short_used_fan"] == 0
    tri = out.triangle_vertices()
    va = _vec_areas(tri)
    for k, R in enumerate(rots):
        sel = out.tri_polygon == k
        assert sel.sum() == n - 2
        assert set(np.unique(out.triangles[sel])) == set(range(k * n, (k + 1) * n))  # no corner lost
        along = va[sel] @ R[:, 2]
        assert along.min() > 1e-12 * size * size, f"rotation {k}: a zero-area or flipped triangle"
        assert abs(along.sum() - area) <= 1e-12 * area
        assert abs(np.linalg.norm(va[sel], axis=1).sum() - area) <= 1e-12 * area  # covered once


@pytest.mark.parametrize("name", ["comb", "L_midpoints", "star_midpoints"])
def test_earcut_polygon_has_no_zero_area_ears_after_rotation(name):
    xy = POLYGONS[name]
    n = len(xy)
    size = float(np.ptp(xy, axis=0).max())
    rng = np.random.default_rng(3)
    for _ in range(50):
        R = _rotation(rng)
        p = np.c_[xy, np.zeros(n)] @ R.T
        t = earcut_polygon(p)
        assert t.shape == (n - 2, 3)
        assert (_vec_areas(p[t]) @ R[:, 2]).min() > 1e-12 * size * size


def test_flips_are_counted_and_translation_keeps_the_triangles():
    # the comb at rotations where earcut cuts a zero-area ear: the repair is counted, and moving
    # the polygon by an exact offset gives the same triangles (the repair works in the local frame)
    rng = np.random.default_rng(0)
    flipped = 0
    for _ in range(40):
        R = _rotation(rng)
        p = np.round(np.c_[COMB, np.zeros(len(COMB))] @ R.T * 2.0 ** 30) / 2.0 ** 30  # dyadic: exact moves
        sizes, idx = np.array([len(p)]), np.arange(len(p))
        a = triangulate(p, sizes, idx)
        b = triangulate(p + np.array([1024.0, -2048.0, 512.0]), sizes, idx)
        np.testing.assert_array_equal(a.corners, b.corners)
        flipped += a.stats["earcut_flips"]
    assert flipped > 0
