"""Test geometry for the light baker: grids, boxes, spheres, frames, and exact references."""

from __future__ import annotations

import numpy as np
import trimesh

from bake.config import LightConfig, LightingConfig
from bake.scene import Material, make_scene
from meshgen import merge  # noqa: F401  (re-exported for the lighting tests)

# (translation, scale) frames every analytic test runs in
FRAMES = [(0.0, 1.0), (1e5, 1e-3)]
FRAME_IDS = ["unit", "at1e5_scale1e-3"]


def grid(n: int, size: float = 2.0, y: float = 0.0, up: bool = True):
    """An n x n quad grid on y = const, centred at the origin, normal +y (or -y)."""
    s = np.linspace(-size / 2, size / 2, n + 1)
    xx, zz = np.meshgrid(s, s, indexing="ij")
    pos = np.stack([xx.ravel(), np.full(xx.size, y), zz.ravel()], axis=1)
    idx = np.arange((n + 1) ** 2).reshape(n + 1, n + 1)
    a, b, c, d = idx[:-1, :-1].ravel(), idx[1:, :-1].ravel(), idx[1:, 1:].ravel(), idx[:-1, 1:].ravel()
    # (a, d, c) winding gives +y: x-step then z-step cross = -y, so use (a, c, b) / (a, d, c)?
    tris = np.concatenate([np.stack([a, c, b], 1), np.stack([a, d, c], 1)])
    n_ = np.cross(pos[tris[:, 1]] - pos[tris[:, 0]], pos[tris[:, 2]] - pos[tris[:, 0]])
    if (n_[:, 1].mean() > 0) != up:
        tris = tris[:, ::-1]
    return pos, tris


def box(n: int = 2, half: float = 1.0, inward: bool = False):
    """A closed cube [-half, half]^3 made of n x n grids per side, welded (shared vertices)."""
    m = trimesh.creation.box(extents=(2 * half,) * 3)
    for _ in range(max(0, int(np.log2(n)))):
        m = m.subdivide()
    v, f = np.asarray(m.vertices, float), np.asarray(m.faces)
    v, inv = np.unique(np.round(v, 12), axis=0, return_inverse=True)
    f = inv.reshape(-1)[f]
    if inward:
        f = f[:, ::-1]
    return v, f


def sphere(sub: int = 3, radius: float = 1.0, center=(0.0, 0.0, 0.0)):
    m = trimesh.creation.icosphere(subdivisions=sub, radius=radius)
    return np.asarray(m.vertices, float) + np.asarray(center, float), np.asarray(m.faces)


def scene(pos, tris, frame=(0.0, 1.0), color=(0.8, 0.8, 0.8, 1.0), tri_material=None, materials=None):
    t, s = frame
    mats = materials or (Material("m", color=tuple(color)),)
    return make_scene(np.asarray(pos) * s + t, tris, materials=mats, tri_material=tri_material)


def at(p, frame):
    t, s = frame
    return [float(x) * s + t for x in p]


def cfg(**kw) -> LightingConfig:
    c = LightingConfig(enabled=True)
    for k, v in kw.items():
        obj = c
        parts = k.split("__")
        for p in parts[:-1]:
            obj = getattr(obj, p)
        setattr(obj, parts[-1], v)
    return c


def sun(direction, angle=0.0, intensity=1.0, color=(1.0, 1.0, 1.0)) -> LightConfig:
    return LightConfig(kind="sun", direction=list(direction), angle=angle, intensity=intensity, color=list(color))


def point(position, radius=0.0, intensity=1.0, range_=0.0) -> LightConfig:
    return LightConfig(kind="point", position=list(position), radius=radius, intensity=intensity, range=range_)


def polygon_form_factor(p: np.ndarray, n: np.ndarray, tri_pos: np.ndarray) -> np.ndarray:
    """Exact cosine-weighted solid angle / pi (Lambert's contour formula) of each triangle seen
    from points ``p`` (P, 3) with normals ``n`` (P, 3): (P, T). Triangles wholly above each
    point's horizon; orientation-independent (absolute value)."""
    r = tri_pos[None, :, :, :] - p[:, None, None, :]  # (P, T, 3, 3)
    r /= np.linalg.norm(r, axis=3, keepdims=True)
    tot = np.zeros(r.shape[:2])
    for i in range(3):
        a, b = r[:, :, i], r[:, :, (i + 1) % 3]
        c = np.cross(a, b)
        cn = np.linalg.norm(c, axis=2)
        theta = np.arctan2(cn, np.einsum("ptk,ptk->pt", a, b))
        g = np.divide(c, cn[..., None], out=np.zeros_like(c), where=cn[..., None] > 0)
        tot += theta * np.einsum("ptk,pk->pt", g, n)
    return np.abs(tot) / (2 * np.pi)


def convex_view_factor(p: np.ndarray, n: np.ndarray, pos: np.ndarray, tris: np.ndarray) -> np.ndarray:
    """Exact form factor from points to a convex closed mesh wholly above their horizon: the sum
    over the faces turned towards each point (they tile the silhouette without overlap)."""
    tp = pos[tris]
    fn = np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0])
    ff = polygon_form_factor(p, n, tp)
    facing = np.einsum("tk,ptk->pt", fn, p[:, None, :] - tp[None, :, 0, :]) > 0
    return (ff * facing).sum(axis=1)
