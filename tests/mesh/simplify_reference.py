"""An independent Hausdorff reference for the simplify tests and benchmark.

Nothing here uses bake's own measuring code (bake/mesh/simplify/error.py and measure.py): the
distances come from MeshLab's Hausdorff filter (pymeshlab; exact point-triangle distances over
its own uniform grid) and, for finding which triangle a sample lies on, from a plain
point-triangle distance written here (projection onto the plane, else the closest of the three
edges; trimesh 5.2's ``closest_point`` was seen to return a point 2% of an edge off for a point
inside a small triangle, so it is not used). For each direction X -> Y:

1. MeshLab measures ``samples`` points on X: every vertex, points along every edge and
   area-weighted points inside the triangles (``samplevert``, ``sampleedge``, ``sampleface``).
2. Around the worst of them (``seeds`` places at least a little apart), the triangles of X that
   hold them and every triangle sharing a corner with those are cut into ``4**levels`` pieces
   (midpoint subdivision, trimesh), and MeshLab measures every corner of the pieces.

The directed maximum is the largest distance seen; it is a lower bound of the true maximum
(sampled), like any sampled figure, but a dense one that looks hardest where the peak is.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass
class Directed:
    max: float
    mean: float
    worst: np.ndarray  # where on X the max was found
    points: int  # points measured (MeshLab's samples + refinement corners)


@dataclass
class Reference:
    a_to_b: Directed  # original -> simplified
    b_to_a: Directed  # simplified -> original

    @property
    def max(self) -> float:
        return max(self.a_to_b.max, self.b_to_a.max)


def shuffled_obj(src, dst, seed: int):
    """The OBJ with its face lines in a seeded random order (everything else as it was)."""
    lines = src.read_text().splitlines()
    faces = [i for i, line in enumerate(lines) if line.startswith("f ")]
    order = np.random.default_rng(seed).permutation(len(faces))
    out = list(lines)
    for slot, k in zip(faces, order):
        out[slot] = lines[faces[k]]
    dst.write_text("\n".join(out) + "\n")
    return dst


def _meshlab_distances(Vx, Fx, Vy, Fy, samples: int, vert_only: bool = False):
    """MeshLab's sampled distances from X to Y: (sample positions, distances, mean)."""
    import pymeshlab

    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(Vx, np.float64), np.asarray(Fx, np.int32)))
    ms.add_mesh(pymeshlab.Mesh(np.asarray(Vy, np.float64), np.asarray(Fy, np.int32)))
    diag = float(np.linalg.norm(np.ptp(np.concatenate([Vx, Vy]), axis=0)))
    if vert_only:
        n = len(Vx)
        r = ms.get_hausdorff_distance(sampledmesh=0, targetmesh=1, savesample=True, samplevert=True,
                                      sampleedge=False, sampleface=False, samplenum=n,
                                      maxdist=pymeshlab.PureValue(diag))
    else:
        r = ms.get_hausdorff_distance(sampledmesh=0, targetmesh=1, savesample=True, samplevert=True,
                                      sampleedge=True, sampleface=True, samplenum=int(samples),
                                      maxdist=pymeshlab.PureValue(diag))
    # savesample adds two point meshes: the closest points ("Hausdorff Closest Points") and the
    # samples ("Hausdorff Sample Point"), each with the distance as vertex quality
    pts = None
    for i in range(ms.mesh_number()):
        m = ms.mesh(i)
        if "sample" in m.label().lower():
            pts = m
    assert pts is not None, "MeshLab did not save its samples"
    P = np.asarray(pts.vertex_matrix(), np.float64)
    d = np.asarray(pts.vertex_scalar_array(), np.float64)
    return P, d, float(r["mean"])


def _segment_distance(p, a, b):
    ab = b - a
    L = np.einsum("ij,ij->i", ab, ab)
    t = np.clip(np.einsum("ij,ij->i", p - a, ab) / np.where(L > 0, L, 1.0), 0.0, 1.0)
    return np.linalg.norm(p - (a + t[:, None] * ab), axis=1)


def point_triangle_distance(p: np.ndarray, T: np.ndarray) -> np.ndarray:
    """Exact distances from the point ``p`` (3,) to triangles ``T`` (n, 3, 3): the distance to
    the plane where the projection falls inside, else the nearest of the three edges."""
    a, b, c = T[:, 0], T[:, 1], T[:, 2]
    n = np.cross(b - a, c - a)
    nn = np.einsum("ij,ij->i", n, n)
    ok = nn > 0
    # barycentric coordinates of the projection (Cramer's rule on the plane's basis)
    w = p - a
    u_ = np.einsum("ij,ij->i", np.cross(w, c - a), n) / np.where(ok, nn, 1.0)
    v_ = np.einsum("ij,ij->i", np.cross(b - a, w), n) / np.where(ok, nn, 1.0)
    inside = ok & (u_ >= 0) & (v_ >= 0) & (u_ + v_ <= 1)
    plane = np.abs(np.einsum("ij,ij->i", w, n)) / np.sqrt(np.where(ok, nn, 1.0))
    P = np.broadcast_to(p, a.shape)
    edge = np.minimum(np.minimum(_segment_distance(P, a, b), _segment_distance(P, b, c)), _segment_distance(P, c, a))
    return np.where(inside, plane, edge)


def _containing_triangles(V, F, P, tol: float) -> list[np.ndarray]:
    """For each point, the triangles of (V, F) within ``tol`` of it."""
    T = V[F]
    lo, hi = T.min(axis=1) - tol, T.max(axis=1) + tol
    out = []
    for p in P:
        cand = np.flatnonzero(((lo <= p) & (p <= hi)).all(axis=1))
        if len(cand) == 0:
            out.append(cand)
            continue
        d = point_triangle_distance(p, T[cand])
        out.append(cand[d <= d.min() + tol])
    return out


def _distinct_top(P: np.ndarray, d: np.ndarray, k: int, apart: float) -> np.ndarray:
    """Indices of the ``k`` largest ``d``, skipping points within ``apart`` of one taken."""
    chosen: list[int] = []
    for i in np.argsort(-d, kind="stable")[:50_000]:
        if len(chosen) >= k:
            break
        if not chosen or np.linalg.norm(P[chosen] - P[i], axis=1).min() > apart:
            chosen.append(int(i))
    return np.asarray(chosen, np.int64)


def directed(Vx, Fx, Vy, Fy, *, samples: int = 300_000, seeds: int = 48, rounds: int = 6,
             levels: int = 2) -> Directed:
    import trimesh

    Vx = np.asarray(Vx, np.float64)
    Fx = np.asarray(Fx, np.int64)
    P, d, mean = _meshlab_distances(Vx, Fx, Vy, Fy, samples)
    n_points = len(P)
    diag = float(np.linalg.norm(np.ptp(Vx, axis=0)))
    top = _distinct_top(P, d, seeds, 0.002 * diag)
    tris = _containing_triangles(Vx, Fx, P[top], 1e-9 * diag)
    seed_tris = np.unique(np.concatenate(tris)) if tris else np.zeros(0, np.int64)
    if len(seed_tris):
        # the triangles holding the worst samples and every triangle sharing a corner with them
        corner = np.zeros(len(Vx), bool)
        corner[Fx[seed_tris].ravel()] = True
        Vw, Fw = Vx, Fx[corner[Fx].any(axis=1)]
        for _ in range(rounds):
            # cut them finer, measure every corner, keep the triangles around the worst corners
            for _ in range(levels):
                Vw, Fw = trimesh.remesh.subdivide(Vw, Fw)
            used = np.unique(Fw.ravel())
            Vw, Fw = Vw[used], np.searchsorted(used, Fw)
            Pr, dr, _ = _meshlab_distances(Vw, np.zeros((0, 3), np.int64), Vy, Fy, 0, vert_only=True)
            n_points += len(Pr)
            P = np.concatenate([P, Pr])
            d = np.concatenate([d, dr])
            edge = float(np.median(np.linalg.norm(Vw[Fw[:, 0]] - Vw[Fw[:, 1]], axis=1)))
            best = _distinct_top(Vw, dr, seeds, 2.0 * edge)
            corner = np.zeros(len(Vw), bool)
            corner[best] = True
            Fw = Fw[corner[Fw].any(axis=1)]
    i = int(np.argmax(d))
    return Directed(max=float(d[i]), mean=mean, worst=P[i], points=n_points)


def hausdorff_reference(Va, Fa, Vb, Fb, **kw) -> Reference:
    """Both directions: original (A) -> simplified (B) and B -> A."""
    return Reference(a_to_b=directed(Va, Fa, Vb, Fb, **kw), b_to_a=directed(Vb, Fb, Va, Fa, **kw))
