"""Proof of order: a z-buffer render against a painter's render in the BSP's order.

The reference is :mod:`bake.render` in z-buffer mode (nearest triangle wins, per pixel centre).
The painter's render draws the same triangles in the order the reference traversal
(:mod:`bake.bsp.traverse`) reads from the exported lists, with no depth test. Both use the same
coverage, so a pixel can only differ in *which* triangle is seen. A difference is

* a *tie* when both triangles have the same depth there: the point one render sees lies within
  the bake's epsilon of the other triangle's plane (coplanar or coincident overlap: the tree
  treats such faces as coplanar and the z-buffer's own choice is arbitrary);
* an *edge* pixel when its centre is within ``edge_px`` pixels of an edge of either triangle
  (where the tolerance-snapped splitting and rasterization of slivers legitimately differ);
* an *interior* error otherwise — a visible wrong order.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from ..render import Camera, render, scene_two_sided
from .stage import NODES_LIST, PLANES_LIST
from .traverse import draw_order, facing_flags


@dataclass
class CameraCheck:
    eye: tuple
    covered: int
    mismatched: int
    ties: int
    edge: int
    interior: int


def random_cameras(scene, n: int, seed: int = 0, *, inside: float = 0.5, fov: float = 70.0,
                   width: int = 160, height: int = 120) -> list[Camera]:
    """``n`` cameras: a fraction ``inside`` placed uniformly inside the bounding box (in rooms,
    in walls, anywhere), the rest outside around it; each looks at a random point near the
    middle."""
    rng = np.random.default_rng(seed)
    b = scene.bounds()
    c = 0.5 * (b[0] + b[1])
    size = np.maximum(b[1] - b[0], 1e-9 * max(1.0, float(np.abs(b).max())))
    diag = float(np.linalg.norm(size))
    cams = []
    for i in range(n):
        if rng.random() < inside:
            eye = b[0] + rng.random(3) * size
        else:
            d = rng.normal(size=3)
            eye = c + d / np.linalg.norm(d) * diag * rng.uniform(0.7, 1.5)
        look = c + (rng.random(3) - 0.5) * size * 0.8
        if np.linalg.norm(look - eye) < 1e-6 * diag:
            look = eye + np.array([1.0, 0.0, 0.0]) * diag
        cams.append(Camera(tuple(eye), tuple(look), fov=fov, width=width, height=height,
                           near=1e-5 * diag))
    return cams


def exported_lists(scene):
    """Flat lists as the export writes them: tris (v1, v2, v3, material; 1-based) and verts."""
    tris = np.concatenate([scene.triangles + 1, scene.tri_material[:, None] + 1], 1).ravel()
    return tris, scene.positions.ravel()


def bsp_order(scene, eye) -> np.ndarray:
    """0-based triangle indices in the painter's order the exported lists give for ``eye``."""
    tris, verts = exported_lists(scene)
    ds = [m.double_sided for m in scene.materials]
    fac = facing_flags(tris, verts, eye, ds)
    nodes = scene.lists[NODES_LIST].values
    planes = scene.lists[PLANES_LIST].values
    return np.asarray(draw_order(nodes.tolist(), np.asarray(planes).tolist(), eye, facing=fac), np.int64) - 1


def check_camera(scene, cam: Camera, order: np.ndarray | None = None, *, edge_px: float = 1.0,
                 tie: float | None = None) -> CameraCheck:
    """Compare the z-buffer render with the painter's render in ``order`` (default: the BSP's).

    ``tie``: two triangles are at the same depth at a pixel when the point seen on each lies
    within ``tie * diagonal`` of the other's plane — by default the epsilon the tree was built
    with (faces that close are coplanar to the bake, and their order is arbitrary)."""
    tv = scene.triangle_vertices()
    ts = scene_two_sided(scene)
    if order is None:
        order = bsp_order(scene, cam.position)
    if tie is None:
        tie = float(scene.artefacts.bsp.epsilon) if scene.artefacts.bsp is not None else 1e-6
    z = render(cam, tv, mode="zbuffer", two_sided=ts)
    p = render(cam, tv, mode="painter", order=order, two_sided=ts)
    cov = z.covered
    mis = (z.tri_id != p.tri_id) & cov
    ties = mis & near_coplanar(cam, tv, z, p, mis, tie * scene.scale())
    edge = mis & ~ties & ((z.edge <= edge_px) | (p.edge <= edge_px))
    interior = mis & ~ties & ~edge
    return CameraCheck(eye=tuple(float(x) for x in cam.position), covered=int(cov.sum()),
                       mismatched=int(mis.sum()), ties=int(ties.sum()), edge=int(edge.sum()),
                       interior=int(interior.sum()))


def near_coplanar(cam: Camera, tv: np.ndarray, z, p, mis: np.ndarray, tol: float) -> np.ndarray:
    """At the differing pixels: is the point each render sees within ``tol`` of the plane of
    the triangle the other render sees?"""
    out = np.zeros(mis.shape, bool)
    ys, xs = np.nonzero(mis)
    if not len(ys):
        return out
    eye, r, u, f = cam.basis()
    H, W = cam.height, cam.width
    ray = (f[None, :] + ((xs + 0.5 - W / 2.0) / cam.focal)[:, None] * r[None, :]
           + ((H / 2.0 - (ys + 0.5)) / cam.focal)[:, None] * u[None, :])  # unit view-space z

    def dist(point_depth, tri_ids):
        q = eye + point_depth[:, None] * ray
        t = tv[tri_ids]
        n = np.cross(t[:, 1] - t[:, 0], t[:, 2] - t[:, 0])
        n /= np.maximum(np.linalg.norm(n, axis=1), 1e-300)[:, None]
        return np.abs(np.einsum("ij,ij->i", n, q - t[:, 0]))

    a, b = z.tri_id[ys, xs], p.tri_id[ys, xs]
    close = (dist(p.depth[ys, xs], a) <= tol) | (dist(z.depth[ys, xs], b) <= tol)
    out[ys, xs] = close
    return out


def check_order(scene, cameras, **kw) -> dict:
    """Run :func:`check_camera` for every camera; totals and the worst camera."""
    res = [check_camera(scene, c, **kw) for c in cameras]
    covered = sum(r.covered for r in res)
    mism = sum(r.mismatched for r in res)
    return {
        "cameras": len(res),
        "covered": covered,
        "mismatched": mism,
        "ties": sum(r.ties for r in res),
        "edge": sum(r.edge for r in res),
        "interior": sum(r.interior for r in res),
        "mismatch_fraction": mism / covered if covered else 0.0,
        "non_tie_fraction": (mism - sum(r.ties for r in res)) / covered if covered else 0.0,
        "per_camera": [r.__dict__ for r in res],
    }
