"""Meshes for the BVH tests (read with trimesh, as the importers are not ours)."""

from __future__ import annotations

import io

import numpy as np

from bake.scene import make_scene


def load_corpus(path) -> tuple[np.ndarray, np.ndarray]:
    import trimesh

    p = str(path)
    if p.endswith("regr01.obj"):
        text = open(p, encoding="latin-1").read()
        m = trimesh.load(io.BytesIO(text.encode()), file_type="obj", process=False, force="mesh")
    else:
        m = trimesh.load(p, process=False, force="mesh")
    return np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)


def soup(n: int = 300, seed: int = 0, degenerate: int = 20):
    """Random triangles of mixed sizes, some of them degenerate (repeated or collinear corners)."""
    rng = np.random.default_rng(seed)
    c = rng.random((n, 1, 3)) * 10
    tri = c + rng.normal(size=(n, 3, 3)) * rng.uniform(0.05, 1.5, (n, 1, 1))
    k = min(degenerate, n)
    tri[:k // 2, 2] = tri[:k // 2, 1]  # repeated corner
    j = np.arange(k // 2, k)
    tri[j, 2] = tri[j, 0] + 2.0 * (tri[j, 1] - tri[j, 0])  # collinear (zero area up to rounding)
    V = tri.reshape(-1, 3)
    return make_scene(V, np.arange(len(V)).reshape(-1, 3))


def flat(n: int = 200, seed: int = 1):
    """Every triangle in the plane z = 0."""
    rng = np.random.default_rng(seed)
    c = rng.random((n, 1, 3)) * 10
    tri = c + rng.normal(size=(n, 3, 3)) * 0.6
    tri[..., 2] = 0.0
    V = tri.reshape(-1, 3)
    return make_scene(V, np.arange(len(V)).reshape(-1, 3))
