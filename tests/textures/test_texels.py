"""The texels of a lightmap atlas (bake/textures/texels.py) against independent references.

* rasterisation: the conservative (triangle, texel) pairs equal the pairs whose exact clipped
  overlap area (Sutherland-Hodgman, written here) is positive; inside samples equal a brute-force
  lattice count; every sample lies on its triangle and in its texel;
* splat / dilate / bilinear: a per-sample loop, scipy's binary dilation, exactness on linear data.

Push-out is tested with real geometry and lighting in test_lightmap.py.
"""

from __future__ import annotations

import numpy as np
import pytest
from scipy import ndimage

from bake.scene import make_scene
from bake.textures.atlas import Atlas
from bake.textures.texels import EDGE_WEIGHT, bilinear, cover, dilate, splat, texel_mask, texel_samples


def flat_atlas(xy, W, H):
    """An Atlas and matching scene from texel-space triangles (world = (x, y, 0))."""
    xy = np.asarray(xy, float)
    T = len(xy)
    uv = np.stack([xy[..., 0] / W, 1.0 - xy[..., 1] / H], axis=-1)
    atlas = Atlas(width=W, height=H, tri_uvs=uv, chart=np.arange(T), key="test")
    pos = np.concatenate([xy.reshape(-1, 2), np.zeros((3 * T, 1))], axis=1)
    return atlas, make_scene(pos, np.arange(3 * T).reshape(T, 3))


def clip_area(tri, x0, y0):
    """Exact area of a triangle clipped to the unit square at (x0, y0) (Sutherland-Hodgman)."""
    poly = [np.asarray(p, float) for p in tri]
    for axis, bound, low in ((0, x0, True), (0, x0 + 1, False), (1, y0, True), (1, y0 + 1, False)):
        out = []
        for k in range(len(poly)):
            p, q = poly[k], poly[(k + 1) % len(poly)]
            pin = p[axis] >= bound if low else p[axis] <= bound
            qin = q[axis] >= bound if low else q[axis] <= bound
            if pin:
                out.append(p)
            if pin != qin:
                out.append(p + (bound - p[axis]) / (q[axis] - p[axis]) * (q - p))
        poly = out
        if len(poly) < 3:
            return 0.0
    a = np.array(poly)
    return 0.5 * abs(np.dot(a[:, 0], np.roll(a[:, 1], -1)) - np.dot(a[:, 1], np.roll(a[:, 0], -1)))


def random_triangles(rng, n, W, H, snap=False):
    c = rng.uniform([1, 1], [W - 1, H - 1], size=(n, 1, 2))
    size = rng.choice([0.3, 1.5, 4.0], size=(n, 1, 1))
    xy = np.clip(c + rng.normal(size=(n, 3, 2)) * size, 0.0, [W, H])
    if snap:  # vertices on texel lines / centres: the touching cases
        xy = np.round(xy * 2) / 2
    e1, e2 = xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]
    a2 = e1[:, 0] * e2[:, 1] - e1[:, 1] * e2[:, 0]
    return xy[np.abs(a2) > 1e-3]


# --------------------------------------------------------------------------------------------
# rasterisation


@pytest.mark.parametrize("snap", [False, True], ids=["random", "on_texel_lines"])
def test_cover_equals_exact_clipping(snap):
    rng = np.random.default_rng(7 + snap)
    W, H = 14, 11
    xy = random_triangles(rng, 60, W, H, snap)
    atlas, _ = flat_atlas(xy, W, H)
    t, x = cover(atlas)
    got = set(zip(t.tolist(), x.tolist()))
    want, tiny = set(), set()
    for k, tri in enumerate(xy):  # brute force over every texel
        for ty in range(H):
            for tx in range(W):
                a = clip_area(tri, tx, ty)
                if a > 1e-7:
                    want.add((k, ty * W + tx))
                elif a > 0:
                    tiny.add((k, ty * W + tx))
    assert want <= got
    assert got - want <= tiny  # only pairs with a (numerically) zero overlap may differ
    assert len(want) > 200


def test_samples_on_triangle_in_texel_and_lattice_count():
    rng = np.random.default_rng(3)
    W, H = 16, 12
    xy = random_triangles(rng, 40, W, H)
    atlas, scene = flat_atlas(xy, W, H)
    s = 3
    smp = texel_samples(scene, atlas, supersample=s)
    p = smp.points[:, :2]
    tx, ty = smp.texel_index % W, smp.texel_index // W
    assert np.all(smp.points[:, 2] == 0)
    # on the triangle: barycentrics >= 0 (independent solve)
    tri = xy[smp.tri_ids]
    M = np.stack([tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0]], axis=2)
    w = np.linalg.solve(M, (p - tri[:, 0])[..., None])[..., 0]
    assert (w >= -1e-9).all() and (w.sum(axis=1) <= 1 + 1e-9).all()
    # inside samples lie in their texel; clamped ones within one texel diagonal of its centre
    ins = smp.inside
    assert np.all((p[ins, 0] >= tx[ins]) & (p[ins, 0] <= tx[ins] + 1))
    assert np.all((p[ins, 1] >= ty[ins]) & (p[ins, 1] <= ty[ins] + 1))
    d = np.hypot(p[~ins, 0] - tx[~ins] - 0.5, p[~ins, 1] - ty[~ins] - 0.5)
    assert (d <= np.sqrt(0.5) + 1e-9).all()
    assert np.allclose(smp.weights[ins], 1 / s**2) and np.allclose(smp.weights[~ins], EDGE_WEIGHT)
    # inside samples per triangle = lattice points (j + (a + 0.5)/s) inside it, counted by brute force
    g = (np.arange(W * s) + 0.5) / s
    gy = (np.arange(H * s) + 0.5) / s
    X, Y = np.meshgrid(g, gy)
    q = np.stack([X.ravel(), Y.ravel()], axis=1)
    for k in range(len(xy)):
        a, b, c = xy[k]
        m = np.array([b - a, c - a]).T
        ww = np.linalg.solve(m, (q - a).T).T
        inside = (ww >= 0).all(axis=1) & (ww.sum(axis=1) <= 1)
        assert inside.sum() == np.sum(ins & (smp.tri_ids == k)), k
    # every pair of cover() has samples, nothing else does
    t, x = cover(atlas)
    assert set(zip(t.tolist(), x.tolist())) == set(zip(smp.tri_ids.tolist(), smp.texel_index.tolist()))


def test_splat_dilate_bilinear():
    rng = np.random.default_rng(5)
    W, H = 9, 7
    atlas = Atlas(width=W, height=H, tri_uvs=np.zeros((0, 3, 2)), chart=np.zeros(0, np.int64), key="t")
    n = 300
    texel = rng.integers(0, W * H // 2, n)
    w = rng.uniform(0.01, 1.0, n)
    v = rng.normal(size=(n, 3))
    img = splat(v, texel, w, atlas)
    ref = np.zeros((W * H, 3))
    tot = np.zeros(W * H)
    for i in range(n):  # the obvious loop
        ref[texel[i]] += w[i] * v[i]
        tot[texel[i]] += w[i]
    has = tot > 0
    ref[has] /= tot[has, None]
    assert np.allclose(img.reshape(-1, 3), ref)
    mask = texel_mask(texel, w, atlas)
    assert np.array_equal(mask.ravel(), has)
    # dilation: the 8-connected rings, filled with values between their neighbours'
    for px in (1, 2):
        out, m2 = dilate(img, mask, px)
        assert np.array_equal(m2, ndimage.binary_dilation(mask, np.ones((3, 3), bool), iterations=px))
        assert np.array_equal(out[mask], img[mask])
        assert out[m2].min() >= img[mask].min() - 1e-12 and out[m2].max() <= img[mask].max() + 1e-12
    const, _ = dilate(np.where(mask[..., None], 0.25, 0.0), mask, 3)
    assert np.allclose(const[ndimage.binary_dilation(mask, np.ones((3, 3), bool), iterations=3)], 0.25)
    # bilinear lookups reproduce a linear function of texel centres exactly (inside the image)
    yy, xx = np.mgrid[0:H, 0:W] + 0.5
    lin = 0.3 * xx - 0.7 * yy + 2.0
    pts = rng.uniform([0.5, 0.5], [W - 0.5, H - 0.5], size=(200, 2))
    uv = np.stack([pts[:, 0] / W, 1 - pts[:, 1] / H], axis=1)
    assert np.allclose(bilinear(lin, uv), 0.3 * pts[:, 0] - 0.7 * pts[:, 1] + 2.0)

