"""Corpus meshes and generated scenes for the BSP tests and benchmark.

The importers are written in parallel, so this reads the few corpus models the BSP work needs on
its own: OBJ by a minimal reader (``v``/``f``/``usemtl``, negative indices, n-gons fanned; text
decoded as Latin-1 so regr01.obj loads), glTF/GLB through trimesh.
"""

from __future__ import annotations

import os
from pathlib import Path

import numpy as np

from bake.scene import Material, Scene, make_scene
from meshgen import merge

REPO = Path(__file__).resolve().parents[2]
CORPUS = Path(os.environ.get("BAKE_CORPUS", REPO.parent / "shared" / "corpus"))

SUITE = {
    "suzanne": "suzanne_obj/suzanne.obj",
    "teapot": "teapot_obj/teapot.obj",
    "spot": "spot_triangulated/spot/spot_triangulated.obj",
    "duck": "duck_glb/Duck.glb",
    "house": "house_max2obj_walls/regr01.obj",
    "capsule": "capsule_textured/capsule.obj",
    "cornell": "cornell_box_tinyobj/cornell_box.obj",
    "bunny": "stanford_bunny_res1_obj/stanford-bunny.obj",
}
EXTRA = {
    "csg": "boolean_csg_slivers/boolean.glb",
    "tetra": "joined_tetrahedra/joined_tetrahedra.obj",
}


def corpus_file(name: str) -> Path:
    rel = SUITE.get(name) or EXTRA[name]
    return CORPUS / rel


def _mtl_colors(path: Path) -> dict[str, tuple]:
    out: dict[str, tuple] = {}
    if not path.is_file():
        return out
    cur = None
    for raw in path.read_bytes().decode("latin-1").splitlines():
        t = raw.split()
        if not t:
            continue
        if t[0] == "newmtl" and len(t) > 1:
            cur = " ".join(t[1:])
            out[cur] = (0.8, 0.8, 0.8, 1.0)
        elif t[0] == "Kd" and cur is not None and len(t) >= 4:
            out[cur] = tuple(min(1.0, max(0.0, float(x))) for x in t[1:4]) + (1.0,)
    return out


def read_obj(path: Path) -> Scene:
    """Positions, fanned faces and per-face material of an OBJ file."""
    text = path.read_bytes().decode("latin-1")
    verts: list[list[float]] = []
    tris: list[tuple[int, int, int]] = []
    tmat: list[int] = []
    mat_names: list[str] = []
    cur = 0
    colors: dict[str, tuple] = {}
    for raw in text.splitlines():
        t = raw.split()
        if not t:
            continue
        if t[0] == "v":
            verts.append([float(x) for x in t[1:4]])
        elif t[0] == "mtllib" and len(t) > 1:
            colors.update(_mtl_colors(path.parent / " ".join(t[1:])))
        elif t[0] == "usemtl":
            name = " ".join(t[1:])
            if name not in mat_names:
                mat_names.append(name)
            cur = mat_names.index(name)
        elif t[0] == "f":
            idx = []
            for c in t[1:]:
                i = int(c.split("/")[0])
                idx.append(i - 1 if i > 0 else len(verts) + i)
            for k in range(1, len(idx) - 1):
                tris.append((idx[0], idx[k], idx[k + 1]))
                tmat.append(cur)
    mats = tuple(Material(name=n, color=colors.get(n, (0.8, 0.8, 0.8, 1.0))) for n in mat_names) or None
    return make_scene(np.array(verts, np.float64), np.array(tris, np.int64), materials=mats,
                      tri_material=np.array(tmat, np.int64) if mat_names else None)


def load_scene(name: str) -> Scene:
    path = corpus_file(name)
    if path.suffix.lower() == ".obj":
        return read_obj(path)
    import trimesh

    m = trimesh.load(str(path), process=False, force="mesh")
    return make_scene(np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64))


# ---------------------------------------------------------------------------- generated scenes
def box(lo, hi, inward: bool = False) -> tuple[np.ndarray, np.ndarray]:
    """12 triangles of an axis-aligned box, outward normals (inward: a room seen from inside)."""
    lo = np.asarray(lo, float)
    hi = np.asarray(hi, float)
    c = np.array([[x, y, z] for x in (0, 1) for y in (0, 1) for z in (0, 1)], float)
    v = lo + c * (hi - lo)
    quads = [(0, 1, 3, 2), (4, 6, 7, 5), (0, 4, 5, 1), (2, 3, 7, 6), (0, 2, 6, 4), (1, 5, 7, 3)]
    f = []
    for a, b, cc, d in quads:
        f += [(a, b, cc), (a, cc, d)]
    f = np.array(f)
    # make every normal point away from the box centre
    p = v[f]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    out = np.einsum("ij,ij->i", n, p.mean(1) - (lo + hi) / 2) > 0
    f[~out] = f[~out][:, ::-1]
    if inward:
        f = f[:, ::-1]
    return v, f


def interlocked_scene(seed: int = 0) -> Scene:
    """Intersecting boxes, a cyclic 'pinwheel' of three sticks, and coplanar overlapping quads."""
    rng = np.random.default_rng(seed)
    parts = []
    for _ in range(6):  # boxes that pass through each other
        lo = rng.uniform(-1, 0.5, 3)
        parts.append(box(lo, lo + rng.uniform(0.3, 1.0, 3)))
    # three mutually overlapping sticks (the classic case no order can draw)
    parts.append(box([-1.2, -0.1, 0.0], [1.2, 0.1, 0.1]))
    parts.append(box([-0.1, -1.2, 0.05], [0.1, 1.2, 0.15]))
    parts.append(box([-0.9, -0.9, -0.05], [0.9, 0.9, 0.02]))
    # coplanar overlapping quads facing the same way (z-fighting pairs) and back to back
    for k in range(3):
        z = 1.5 + 0.1 * k
        v = np.array([[-0.5 + 0.3 * k, -0.5, z], [0.5 + 0.3 * k, -0.5, z], [0.5 + 0.3 * k, 0.5, z],
                      [-0.5 + 0.3 * k, 0.5, z]])
        parts.append((v, np.array([[0, 1, 2], [0, 2, 3]])))
        parts.append((v + [0.25, 0.25, 0], np.array([[0, 1, 2], [0, 2, 3]])))
        parts.append((v + [0.1, -0.2, 0], np.array([[0, 2, 1], [0, 3, 2]])))
    v, f = merge(*parts)
    return make_scene(v, f)


def rooms_scene() -> Scene:
    """A small 'house': rooms seen from inside (inward boxes) with wall slabs and a pillar."""
    parts = [box([0, 0, 0], [10, 3, 8], inward=True)]
    parts.append(box([4.9, 0, 0], [5.1, 3, 3]))  # partition walls (closed slabs)
    parts.append(box([4.9, 0, 5], [5.1, 3, 8]))
    parts.append(box([0, 0, 3.9], [3, 3, 4.1]))
    parts.append(box([7, 0, 3.9], [10, 3, 4.1]))
    parts.append(box([2, 0, 6], [2.5, 3, 6.5]))  # pillar
    parts.append(box([7.5, 0, 1.5], [8.5, 1.0, 2.5]))  # table
    v, f = merge(*parts)
    return make_scene(v, f)
