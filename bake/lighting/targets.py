"""Where light is evaluated and how it becomes per-vertex and per-triangle values.

**Sample points.**

* *Vertex points*: every vertex a triangle uses, with the area-weighted mean of its faces'
  geometric normals (a vertex whose normals cancel takes the normal of its largest face).
* *Interior points*: a triangle is cut into ``m x m`` equal sub-triangles (its edges into ``m``
  parts) and one point sits at the centroid of each, with the face normal. The mean over them is
  the midpoint rule for the *area* average of the light over the triangle, so a shadow across a
  big face shows in its colour. ``m = ceil(longest edge / (face_cell * scale))`` capped so that
  ``m * m <= face_points_max``.

With ``target = "vertex"``, triangles with ``m = 1`` (smaller than a cell) take the mean of their
three vertices and bigger ones their interior points; with ``target = "triangle"`` every triangle
has at least its centroid and vertex values are not traced.

**Subdivision** (``lighting.subdivide``) splits triangles whose colour varies by more than a
threshold across them (vertices and interior points), largest variation x area first, in rounds:
a split triangle becomes 4 (edge midpoints); a neighbour sharing one split edge becomes 2, one with
two split edges is split fully (so repeated rounds do not make slivers). Every triangle on a split
edge is split, so no T-junction appears. The triangle count never exceeds ``max_triangles``.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .sampling import hash_combine

INTERIOR_BIT = np.uint64(1 << 63)


# --------------------------------------------------------------------------- geometry
def face_geometry(pos: np.ndarray, tris: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(unit normals (T,3), areas (T,), longest edge (T,)). Degenerate faces get normal 0.

    Component by component (gathers of one coordinate, no (T, 3, 3) block), with the operations
    of ``np.cross`` and ``np.linalg.norm`` in their order, so the values are theirs to the bit
    (``tests/lighting/test_lighting_rays_fast.py`` compares) at a fifth of the time."""
    pos = np.asarray(pos, dtype=np.float64)
    tris = np.asarray(tris)
    T = len(tris)
    col = [np.ascontiguousarray(pos[:, k]) for k in range(3)]
    corner = [np.ascontiguousarray(tris[:, j]) for j in range(3)]
    p0, p1, p2 = ([c[i] for c in col] for i in corner)
    e1 = [p1[k] - p0[k] for k in range(3)]
    e2 = [p2[k] - p0[k] for k in range(3)]
    cr = []
    for i, j in ((1, 2), (2, 0), (0, 1)):  # np.cross: a_i b_j - a_j b_i
        c = e1[i] * e2[j]
        c -= e1[j] * e2[i]
        cr.append(c)
    ln = _norm3(cr)
    n = np.zeros((T, 3))
    ok = ln > 0
    for k in range(3):
        np.divide(cr[k], ln, out=n[:, k], where=ok)
    longest = np.maximum(np.maximum(_norm3(e1), _norm3([p2[k] - p1[k] for k in range(3)])), _norm3(e2))
    return n, 0.5 * ln, longest


def _norm3(v: list[np.ndarray]) -> np.ndarray:
    """``np.linalg.norm`` of vectors given as three component arrays: ``sqrt((x*x + y*y) + z*z)``."""
    s = v[0] * v[0]
    s += v[1] * v[1]
    s += v[2] * v[2]
    return np.sqrt(s, out=s)


def vertex_normals(pos: np.ndarray, tris: np.ndarray, fn: np.ndarray, area: np.ndarray) -> np.ndarray:
    """Area-weighted vertex normals (unit); unused vertices get (0, 1, 0)."""
    V = len(pos)
    w = fn * area[:, None]
    acc = np.zeros((V, 3))
    flat = tris.ravel()
    for k in range(3):  # components
        acc[:, k] = np.bincount(flat, weights=np.repeat(w[:, k], 3), minlength=V)
    ln = np.linalg.norm(acc, axis=1)
    tot = np.bincount(flat, weights=np.repeat(area, 3), minlength=V)
    bad = ln <= 1e-9 * np.maximum(tot, 1e-300)
    out = np.divide(acc, ln[:, None], out=np.zeros_like(acc), where=~bad[:, None])
    if bad.any():
        # the normal of the largest incident face
        order = np.lexsort((np.repeat(area, 3), flat))  # by vertex, then area ascending
        last = np.ones(len(order), dtype=bool)
        last[:-1] = flat[order][1:] != flat[order][:-1]
        verts = flat[order][last]
        faces = order[last] // 3
        fallback = np.zeros((V, 3))
        fallback[verts] = fn[faces]
        out[bad] = fallback[bad]
    none = np.linalg.norm(out, axis=1) == 0
    out[none] = (0.0, 1.0, 0.0)
    return out


# --------------------------------------------------------------------------- sample points
@dataclass
class Points:
    """A batch of sample points (world float64)."""

    pos: np.ndarray  # (P, 3)
    nrm: np.ndarray  # (P, 3) unit geometric normals
    key: np.ndarray  # (P,) uint64, the point's random stream
    owner: np.ndarray  # (P,) vertex index (vertex points) or triangle index (interior points)

    def __len__(self) -> int:
        return len(self.pos)

    @staticmethod
    def concat(parts: list["Points"]) -> "Points":
        parts = [p for p in parts if len(p)]
        if not parts:
            return Points(np.zeros((0, 3)), np.zeros((0, 3)), np.zeros(0, np.uint64), np.zeros(0, np.int64))
        return Points(*(np.concatenate([getattr(p, f) for p in parts])
                        for f in ("pos", "nrm", "key", "owner")))


def vertex_points(pos: np.ndarray, vn: np.ndarray, idx: np.ndarray) -> Points:
    idx = np.asarray(idx, dtype=np.int64)
    return Points(pos[idx], vn[idx], idx.astype(np.uint64), idx)


_BARY: dict[int, np.ndarray] = {}


def sub_centroids(m: int) -> np.ndarray:
    """(m*m, 2) barycentric (s, t) of the centroids of the m*m sub-triangles (p = v0 + s e1 + t e2)."""
    if m not in _BARY:
        ii, jj = np.meshgrid(np.arange(m), np.arange(m), indexing="ij")
        ii, jj = ii.ravel(), jj.ravel()
        up = ii + jj <= m - 1
        dn = ii + jj <= m - 2
        a = np.stack([ii[up] + 1 / 3, jj[up] + 1 / 3], axis=1)
        b = np.stack([ii[dn] + 2 / 3, jj[dn] + 2 / 3], axis=1)
        _BARY[m] = np.concatenate([a, b]) / m
    return _BARY[m]


def face_levels(longest: np.ndarray, cell: float, max_points: int, minimum: int) -> np.ndarray:
    """Sub-division level m per triangle for interior points (0 = none)."""
    mmax = max(1, int(np.floor(np.sqrt(max(1, max_points)))))
    with np.errstate(divide="ignore", invalid="ignore"):
        m = np.ceil(longest / cell) if cell > 0 else np.full(len(longest), mmax)
    m = np.clip(np.nan_to_num(m, nan=1.0, posinf=mmax), 1, mmax).astype(np.int64)
    if minimum <= 0:
        m[m == 1] = 0
    return m


def interior_points(pos: np.ndarray, tris: np.ndarray, fn: np.ndarray, tri_idx: np.ndarray,
                    levels: np.ndarray) -> tuple[Points, list[tuple[np.ndarray, int]]]:
    """Interior points for triangles ``tri_idx`` with levels ``levels`` (> 0).

    Returns the points and the groups ``(triangle indices, m)`` in the order the points are laid
    out (each group: ``len(tris) * m * m`` points, triangle-major)."""
    parts = []
    groups = []
    for m in np.unique(levels):  # a loop over the few distinct levels
        if m <= 0:
            continue
        t = tri_idx[levels == m]
        st = sub_centroids(int(m))
        v = pos[tris[t]]  # (Tm, 3, 3)
        e1 = v[:, 1] - v[:, 0]
        e2 = v[:, 2] - v[:, 0]
        p = v[:, None, 0] + st[None, :, 0, None] * e1[:, None] + st[None, :, 1, None] * e2[:, None]
        k = int(m) * int(m)
        tv = tris[t]
        key = hash_combine(tv[:, 0, None], tv[:, 1, None], tv[:, 2, None], np.arange(k)[None, :]) | INTERIOR_BIT
        parts.append(Points(p.reshape(-1, 3), np.repeat(fn[t], k, axis=0), key.ravel(),
                            np.repeat(t, k)))
        groups.append((t, int(m)))
    return Points.concat(parts), groups


def reduce_groups(values: np.ndarray, groups: list[tuple[np.ndarray, int]], n_tris: int
                  ) -> tuple[np.ndarray, np.ndarray]:
    """Per-triangle mean of interior-point values laid out as ``groups``.
    Returns ``(means (n_tris, ...), has (n_tris,) bool)``."""
    shape = values.shape[1:]
    out = np.zeros((n_tris,) + shape)
    has = np.zeros(n_tris, dtype=bool)
    o = 0
    for t, m in groups:
        k = m * m
        n = len(t) * k
        out[t] = values[o:o + n].reshape((len(t), k) + shape).mean(axis=1)
        has[t] = True
        o += n
    return out, has


def reduce_groups_rms(se: np.ndarray, groups: list[tuple[np.ndarray, int]], n_tris: int) -> np.ndarray:
    """Standard error of a per-triangle mean of independent point estimates."""
    out = np.zeros(n_tris)
    o = 0
    for t, m in groups:
        k = m * m
        n = len(t) * k
        out[t] = np.sqrt((se[o:o + n].reshape(len(t), k) ** 2).sum(axis=1)) / k
        o += n
    return out


# --------------------------------------------------------------------------- subdivision
@dataclass
class Split:
    """What one subdivision round did: new arrays plus the maps to carry values over."""

    positions: np.ndarray
    triangles: np.ndarray
    parent: np.ndarray  # (T',) index of the old triangle each new one comes from
    split: np.ndarray  # (T',) bool: the triangle is a piece of a split triangle
    tri_uvs: np.ndarray | None
    vertex_colors: np.ndarray | None
    new_vertices: np.ndarray  # indices of the midpoints added
    edge_ends: np.ndarray  # (n_new, 2) the endpoints of each midpoint
    extra: dict = field(default_factory=dict)


def unique_edges(tris: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(E, 2) sorted unique edges and (T, 3) edge id of edge k = (v_k, v_k+1)."""
    e = np.stack([tris, np.roll(tris, -1, axis=1)], axis=2).reshape(-1, 2)
    e.sort(axis=1)
    uniq, inv = np.unique(e, axis=0, return_inverse=True)
    return uniq, inv.reshape(-1, 3)


def close_marks(edge_id: np.ndarray, marked: np.ndarray) -> np.ndarray:
    """Mark the third edge of every triangle with two marked edges, until none is left."""
    marked = marked.copy()
    for _ in range(64):
        k = marked[edge_id].sum(axis=1)
        two = k == 2
        if not two.any():
            break
        marked[edge_id[two]] = True
    return marked


def added_triangles(edge_id: np.ndarray, marked: np.ndarray) -> int:
    k = marked[edge_id].sum(axis=1)
    return int(k.sum())  # k=1 -> +1, k=3 -> +3


def choose_splits(edge_id: np.ndarray, n_edges: int, candidates: np.ndarray, budget: int) -> np.ndarray:
    """Edge marks for the longest prefix of ``candidates`` (priority order) whose refinement adds
    at most ``budget`` triangles."""
    def marks(n: int) -> np.ndarray:
        m = np.zeros(n_edges, dtype=bool)
        if n:
            m[edge_id[candidates[:n]].ravel()] = True
        return close_marks(edge_id, m)

    full = marks(len(candidates))
    if added_triangles(edge_id, full) <= budget:
        return full
    lo, hi = 0, len(candidates)  # lo fits, hi does not
    while hi - lo > 1:
        mid = (lo + hi) // 2
        if added_triangles(edge_id, marks(mid)) <= budget:
            lo = mid
        else:
            hi = mid
    return marks(lo)


def split(positions: np.ndarray, tris: np.ndarray, marked: np.ndarray, edges: np.ndarray,
          edge_id: np.ndarray, tri_uvs: np.ndarray | None, vertex_colors: np.ndarray | None) -> Split:
    """Split triangles along ``marked`` edges (closed: each triangle has 0, 1 or 3 marked edges)."""
    V = len(positions)
    me = np.flatnonzero(marked)
    mid_of = np.full(len(edges), -1, dtype=np.int64)
    mid_of[me] = V + np.arange(len(me))
    ends = edges[me]
    new_pos = np.concatenate([positions, 0.5 * (positions[ends[:, 0]] + positions[ends[:, 1]])])
    new_vc = None
    if vertex_colors is not None:
        new_vc = np.concatenate([vertex_colors, 0.5 * (vertex_colors[ends[:, 0]] + vertex_colors[ends[:, 1]])])
    em = mid_of[edge_id]  # (T, 3) midpoint of edge k or -1
    k = (em >= 0).sum(axis=1)
    uv = tri_uvs
    out_t, out_p, out_uv = [], [], []

    # unchanged
    keep = np.flatnonzero(k == 0)
    out_t.append(tris[keep])
    out_p.append(keep)
    if uv is not None:
        out_uv.append(uv[keep])

    # one split edge: rotate so it is edge 0 = (a, b); children (a, m, c), (m, b, c)
    one = np.flatnonzero(k == 1)
    if len(one):
        e = np.argmax(em[one] >= 0, axis=1)
        rot = (np.arange(3)[None, :] + e[:, None]) % 3
        tv = np.take_along_axis(tris[one], rot, axis=1)
        mm = em[one, e]
        a, b, c = tv[:, 0], tv[:, 1], tv[:, 2]
        out_t.append(np.stack([np.stack([a, mm, c], 1), np.stack([mm, b, c], 1)], 1).reshape(-1, 3))
        out_p.append(np.repeat(one, 2))
        if uv is not None:
            tu = np.take_along_axis(uv[one], rot[:, :, None], axis=1)
            mu = 0.5 * (tu[:, 0] + tu[:, 1])
            out_uv.append(np.stack([np.stack([tu[:, 0], mu, tu[:, 2]], 1),
                                    np.stack([mu, tu[:, 1], tu[:, 2]], 1)], 1).reshape(-1, 3, 2))

    # three split edges: four children
    three = np.flatnonzero(k == 3)
    if len(three):
        a, b, c = tris[three, 0], tris[three, 1], tris[three, 2]
        ab, bc, ca = em[three, 0], em[three, 1], em[three, 2]
        out_t.append(np.stack([np.stack([a, ab, ca], 1), np.stack([ab, b, bc], 1),
                               np.stack([ca, bc, c], 1), np.stack([ab, bc, ca], 1)], 1).reshape(-1, 3))
        out_p.append(np.repeat(three, 4))
        if uv is not None:
            u0, u1, u2 = uv[three, 0], uv[three, 1], uv[three, 2]
            m01, m12, m20 = 0.5 * (u0 + u1), 0.5 * (u1 + u2), 0.5 * (u2 + u0)
            out_uv.append(np.stack([np.stack([u0, m01, m20], 1), np.stack([m01, u1, m12], 1),
                                    np.stack([m20, m12, u2], 1), np.stack([m01, m12, m20], 1)],
                                   1).reshape(-1, 3, 2))
    if ((k == 2) | (k > 3)).any():  # pragma: no cover - close_marks prevents it
        raise AssertionError("split: marks were not closed")
    new_t = np.concatenate(out_t)
    parent = np.concatenate(out_p)
    order = np.argsort(parent, kind="stable")  # children in place of their parent
    new_t, parent = new_t[order], parent[order]
    new_uv = np.concatenate(out_uv)[order] if uv is not None else None
    return Split(positions=new_pos, triangles=new_t, parent=parent, split=k[parent] > 0,
                 tri_uvs=new_uv, vertex_colors=new_vc, new_vertices=V + np.arange(len(me)),
                 edge_ends=ends)
