"""Speed of the mesh stages (transform, triangulate, clean) on generated meshes.

    .venv/bin/python benchmarks/bench_mesh.py [--quads 1000000] [--concave 0.01] [--repeat 3]

A grid of ``--quads`` quads (each vertex duplicated per quad, as importers of unindexed data
produce), mixed with hexagons, with ``--concave`` of the polygons replaced by concave L-shaped
hexagons (they go through the ear-clipping loop). Prints the best of ``--repeat`` runs.
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from bake.config import CleanConfig, TransformConfig, TriangulateConfig
from bake.mesh import clean, transform, triangulate
from bake.scene import Scene


def grid_scene(n_quads: int, concave_fraction: float, seed: int = 0) -> Scene:
    side = max(1, int(np.sqrt(n_quads)))
    i, j = np.meshgrid(np.arange(side), np.arange(side), indexing="ij")
    i, j = i.ravel().astype(float), j.ravel().astype(float)
    P = len(i)
    rng = np.random.default_rng(seed)
    concave = rng.random(P) < concave_fraction
    # every polygon has its own corners (6 for L-shapes, 4 for quads)
    quad = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    ell = np.array([[1, 0.5], [1, 1], [0, 1], [0, 0], [0.5, 0], [0.5, 0.5]], float)  # fan is wrong
    sizes = np.where(concave, 6, 4).astype(np.int64)
    corners = []
    for shape, sel in ((quad, ~concave), (ell, concave)):
        k = len(shape)
        c = np.empty((int(sel.sum()), k, 3))
        c[..., 0] = i[sel, None] + shape[None, :, 0]
        c[..., 2] = j[sel, None] + shape[None, :, 1]
        c[..., 1] = 0.0
        corners.append((sel, c.reshape(-1, 3)))
    off = np.zeros(P + 1, np.int64)
    np.cumsum(sizes, out=off[1:])
    pos = np.empty((int(off[-1]), 3))
    for sel, c in corners:
        if not sel.any():
            continue
        k = int(sizes[sel][0])
        pos[(off[:-1][sel][:, None] + np.arange(k)).ravel()] = c
    return Scene(positions=pos, poly_sizes=sizes, poly_indices=np.arange(len(pos), dtype=np.int64),
                 poly_material=np.zeros(P, np.int64))


def best(fn, repeat):
    """Best wall time of ``repeat`` runs (CPU time of that run in brackets: on a busy machine the
    CPU time is the steadier figure)."""
    t = []
    out = None
    for _ in range(repeat):
        t0, c0 = time.perf_counter(), time.process_time()
        out = fn()
        t.append((time.perf_counter() - t0, time.process_time() - c0))
    return min(t), out


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--quads", type=int, default=1_000_000)
    ap.add_argument("--concave", type=float, default=0.01)
    ap.add_argument("--repeat", type=int, default=3)
    a = ap.parse_args()
    scene = grid_scene(a.quads, a.concave)
    print(f"polygons {scene.n_polygons:,}  corners {len(scene.poly_indices):,}  "
          f"concave {int((scene.poly_sizes == 6).sum()):,}")
    t, (s1, r) = best(lambda: transform.stage(scene, TransformConfig(up="z", fit=10, center="base")), a.repeat)
    print(f"transform    {t[0]:7.3f} s ({t[1]:.3f} cpu)")
    t, (s2, r) = best(lambda: triangulate.stage(s1, TriangulateConfig(method="fan")), a.repeat)
    print(f"tri fan      {t[0]:7.3f} s ({t[1]:.3f} cpu)  triangles {s2.n_triangles:,}")
    t, (s2, r) = best(lambda: triangulate.stage(s1, TriangulateConfig()), a.repeat)
    print(f"tri auto     {t[0]:7.3f} s ({t[1]:.3f} cpu)  triangles {s2.n_triangles:,}  "
          f"fallback {r.details['fallback']}")
    t, (s3, r) = best(lambda: clean.stage(s2, CleanConfig()), a.repeat)
    print(f"clean        {t[0]:7.3f} s ({t[1]:.3f} cpu)  vertices {s2.n_vertices:,} -> {s3.n_vertices:,}  "
          f"welded {r.details['welded_vertices']:,}")


if __name__ == "__main__":
    main()
