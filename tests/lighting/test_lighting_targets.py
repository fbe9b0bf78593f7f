"""Per-triangle colours are area averages; subdivision is budgeted, crack-free and goes where
the light varies."""

from __future__ import annotations

import numpy as np
import pytest

from bake.lighting.stage import stage
from bake.lighting.targets import unique_edges
from bake.scene import make_scene
from lighting_geom import box, cfg, grid, merge, scene, sun


def _occluder(x0: float, H: float = 1.0):
    """A big horizontal plate over x < x0 at height H."""
    return (np.array([[-50.0, H, -50.0], [x0, H, -50.0], [x0, H, 50.0], [-50.0, H, 50.0]]),
            np.array([[0, 2, 1], [0, 3, 2]]))


@pytest.mark.parametrize("target", ["vertex", "triangle"])
def test_face_colour_is_area_average_not_vertex_mean(target):
    quad = (np.array([[-1.0, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]]), np.array([[0, 2, 1], [0, 3, 2]]))
    pos, tris = merge(quad, _occluder(0.0))
    sc = scene(pos, tris)
    out, _ = stage(sc, cfg(target=target, lights=[sun((0, -1, 0))], face_cell=0.01, face_points_max=64))
    res = out.artefacts.lighting
    # exact lit fractions (x > 0) of the two floor triangles
    p = pos[tris[:2]]
    lit = []
    for t in p:  # integrate x > 0 over each triangle with a fine barycentric grid
        s = (np.arange(400) + 0.5) / 400
        u, v = np.meshgrid(s, s)
        keep = u + v < 1
        q = t[0] + u[keep, None] * (t[1] - t[0]) + v[keep, None] * (t[2] - t[0])
        lit.append(np.mean(q[:, 0] > 0))
    lit = np.array(lit)
    got = res.face["direct"][:2, 0]
    assert np.all(np.abs(got - lit) < 0.03), (got, lit)
    if target == "vertex":
        vmean = res.vertex["direct"][tris[:2], 0].mean(axis=1)
        assert np.all(np.abs(vmean - lit) > 0.06)  # what a vertex-only average would say


def _floor_scene(n=4, x0=0.1):
    floor = grid(n, size=2.0)
    pos, tris = merge(floor, _occluder(x0))
    uv = pos[tris][:, :, [0, 2]]  # uv = (x, z)
    sc = make_scene(pos, tris, tri_uvs=uv)
    return sc, len(floor[1])


def test_subdivision_goes_where_light_varies_within_budget():
    sc, nfloor = _floor_scene()
    T0 = sc.n_triangles
    c = cfg(lights=[sun((0, -1, 0))], subdivide=True, subdivide_levels=3, max_triangles=400,
            subdivide_min_edge=0.0)
    out, rec = stage(sc, c)
    out.validate()
    sub = {e["name"]: e for e in rec.effects}["subdivide"]
    assert sub["ran"] and out.n_triangles == T0 + sub["triangles_added"] <= 400
    split = out.tri_polygon == -1
    tp = out.positions[out.triangles]
    near = np.abs(tp[:, :, 0] - 0.1).min(axis=1) < 0.6
    assert split.any() and not (split & ~near & (tp[:, :, 1].max(axis=1) < 0.5)).any()
    # UVs are carried exactly (uv = (x, z) stays true on every new corner)
    np.testing.assert_allclose(out.tri_uvs, tp[:, :, [0, 2]], atol=1e-12)
    # better area average of the light over the floor than without subdivision
    res = out.artefacts.lighting
    area = 0.5 * np.linalg.norm(np.cross(tp[:, 1] - tp[:, 0], tp[:, 2] - tp[:, 0]), axis=1)
    on_floor = tp[:, :, 1].max(axis=1) < 0.5
    exact = 0.9 * 2.0  # lit area of the floor: x in [0.1, 1], z in [-1, 1]
    got = float((area * res.face["direct"][:, 0])[on_floor].sum())
    out0, _ = stage(sc, cfg(lights=[sun((0, -1, 0))], face_cell=10.0))
    r0 = out0.artefacts.lighting
    tp0 = sc.positions[sc.triangles]
    a0 = 0.5 * np.linalg.norm(np.cross(tp0[:, 1] - tp0[:, 0], tp0[:, 2] - tp0[:, 0]), axis=1)
    got0 = float((a0 * r0.face["direct"][:, 0])[:nfloor].sum())
    assert abs(got - exact) < abs(got0 - exact) / 2


def test_subdivision_budget_is_a_hard_limit():
    sc, _ = _floor_scene()
    T0 = sc.n_triangles
    for budget in (T0, T0 + 1, T0 + 7, T0 + 30):
        out, rec = stage(sc, cfg(lights=[sun((0, -1, 0))], subdivide=True, max_triangles=budget,
                                 subdivide_min_edge=0.0))
        if budget > T0 + 3:
            assert out.n_triangles > T0
        assert out.n_triangles <= max(budget, T0)
        out.validate()


def test_subdivision_keeps_closed_mesh_closed():
    # a closed cube, half in the shadow of a plate: every edge must keep exactly two triangles
    cube = box(2, half=0.5)
    pos, tris = merge(cube, _occluder(0.05, H=2.0))
    sc = scene(pos, tris)
    out, rec = stage(sc, cfg(lights=[sun((0.2, -1, 0.1))], subdivide=True, subdivide_levels=3,
                             subdivide_min_edge=0.0, max_triangles=2000))
    assert out.n_triangles > sc.n_triangles
    keep = np.flatnonzero(out.positions[out.triangles][:, :, 1].max(axis=1) < 1.0)  # the cube's pieces
    edges, eid = unique_edges(out.triangles[keep])
    counts = np.bincount(eid.ravel(), minlength=len(edges))
    assert np.all(counts == 2), "a T-junction / crack appeared"
