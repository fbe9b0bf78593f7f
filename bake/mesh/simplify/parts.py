"""Messy input for the simplify stage: repeated and two-sided triangles, and parts.

Real models are rarely one clean shell. Two kinds of input the libraries cannot simplify as
they come, and what the stage does with them:

* **Repeated and two-sided triangles.** Exporters write a two-sided surface (a chair's tubes,
  leaves, cloth, a thin wall) as each triangle twice, once per side: the same three vertices,
  the second in the opposite order, often with another material or UVs on the back. Every edge
  of such a sheet is then used by four triangles, so meshoptimizer finds no collapse that keeps
  it valid (a chair of 12,756 such triangles stopped at 9,220 for a target of 3,000) and every
  triangle pair counts as a fold. :func:`fold_layer` keeps one *layer*: the first triangle of
  each set of corners is the front, the first one after it in the opposite order is its back,
  and any further copy (the same corners in the same order as a kept one: drawn twice, seen
  once) is dropped. The stage simplifies and measures the layer, then writes every layer
  triangle that had a back twice, the second copy reversed with the back's material, UVs and
  face colour (materials and UVs stay apart per side because the back's are part of the region
  and wedge keys).
* **Parts.** A CAD assembly or a piece of furniture is many parts, and parts that touch share
  vertices once ``mesh.clean`` welds them. :func:`parts` splits the mesh into the pieces that
  hang together through edges used by exactly two triangles: an edge of three or more
  triangles (parts meeting along a seam, or a T-junction of walls) and a vertex two parts only
  touch at do not join them. Where parts share vertices, each part gets its own copies in the
  library's buffer, so the library sees the shared places as seams it may not weld across
  (meshoptimizer keeps a vertex whose copies do not pair up as a seam where it is), and no
  collapse in one part can pull another part's triangles onto a new non-manifold edge. The
  budget is split between the parts by the library itself: it collapses the cheapest edge of
  the whole mesh first, so every part is reduced until its next collapse would cost more than
  the next part's (balanced error; a small bolt keeps its few triangles where a big housing
  gives up thousands). :func:`part_report` gives each part's count before and after and its
  measured error for the record.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import scipy.sparse as sp
from scipy.sparse.csgraph import connected_components

from .repair import edge_pairs

__all__ = ["Layer", "fold_layer", "parts", "part_report"]


@dataclass
class Layer:
    """One side of the input (:func:`fold_layer`)."""
    front: np.ndarray  # (L,) the input triangle each layer triangle is
    back: np.ndarray  # (L,) its twin in the input, the same corners in the opposite order (-1: none)
    back_corner: np.ndarray  # (L, 3) the twin's corner (0..2) at each of the front's corners (0 where none)
    repeated: int  # input triangles dropped: the same corners in the same order as a kept one

    @property
    def folded(self) -> bool:
        """Whether the layer differs from the input (a twin or a repeated triangle)."""
        return self.repeated > 0 or bool((self.back >= 0).any())

    @property
    def twins(self) -> int:
        return int((self.back >= 0).sum())


def _even(F: np.ndarray, s: np.ndarray) -> np.ndarray:
    """Whether each triangle's corner order is a rotation of its sorted corners."""
    return (F == s).all(axis=1) | (F == s[:, [1, 2, 0]]).all(axis=1) | (F == s[:, [2, 0, 1]]).all(axis=1)


def fold_layer(F: np.ndarray) -> Layer:
    """The first triangle of each set of three corners is the front; the first in the opposite
    order is its back; the rest are repeats (see the module docstring). Triangles keep their
    input order."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    T = len(F)
    if T == 0:
        z = np.zeros(0, np.int64)
        return Layer(z, z.copy(), np.zeros((0, 3), np.int64), 0)
    s = np.sort(F, axis=1)
    n = int(s[:, 2].max()) + 1
    if n < 2_000_000:  # one integer per set of corners (n**3 < 2**63): a 1-D unique, 5x faster
        key = (s[:, 0] * n + s[:, 1]) * n + s[:, 2]
        _, first, group = np.unique(key, return_index=True, return_inverse=True)
    else:
        _, first, group = np.unique(s, axis=0, return_index=True, return_inverse=True)
    group = group.reshape(-1)
    if len(first) == T:  # every set of corners once: the layer is the input
        ids = np.arange(T)
        return Layer(ids, np.full(T, -1, np.int64), np.zeros((T, 3), np.int64), 0)
    even = _even(F, s)
    front = np.sort(first)
    opposite = even != even[first][group]
    # the first triangle of each group in the opposite order (np.unique keeps first occurrences)
    opp = np.flatnonzero(opposite)
    g_opp, i_opp = np.unique(group[opp], return_index=True)
    back_of_group = np.full(len(first), -1, np.int64)
    back_of_group[g_opp] = opp[i_opp]
    back = back_of_group[group[front]]
    # the twin's corner at each front corner: its corners are the front's in another order
    back_corner = np.zeros((len(front), 3), np.int64)
    has = np.flatnonzero(back >= 0)
    if len(has):
        fb, bb = F[front[has]], F[back[has]]
        back_corner[has] = np.argmax(fb[:, :, None] == bb[:, None, :], axis=2)
    repeated = T - len(front) - len(has)
    return Layer(front, back, back_corner, int(repeated))


def parts(F: np.ndarray, n_vertices: int) -> tuple[np.ndarray, int, bool]:
    """(part of each triangle, how many parts, whether two parts share a vertex): the pieces that
    hang together through edges used by exactly two triangles (see the module docstring), numbered
    by their first triangle."""
    F = np.asarray(F, np.int64).reshape(-1, 3)
    T = len(F)
    if T == 0:
        return np.zeros(0, np.int64), 0, False
    _, _, h1, h2 = edge_pairs(F)
    t1, t2 = h1 // 3, h2 // 3
    g = sp.coo_matrix((np.ones(len(t1), np.int8), (t1, t2)), shape=(T, T))
    n, label = connected_components(g, directed=False)
    # numbered by first triangle, so the numbering does not depend on scipy's traversal
    _, first = np.unique(label, return_index=True)  # (component labels are 0..n-1)
    rank = np.empty(n, np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(n)
    part = rank[label]
    if n <= 1:
        return part, n, False
    # a vertex used by triangles of two parts
    vp = np.unique(np.stack([F.ravel(), np.repeat(part, 3)], axis=1), axis=0)
    shared = bool((np.bincount(vp[:, 0], minlength=n_vertices) > 1).any())
    return part, n, shared


def part_report(part_in: np.ndarray, part_out: np.ndarray, n_parts: int, area_in: np.ndarray,
                area_out: np.ndarray, err_in: np.ndarray | None, err_out: np.ndarray | None, extent: np.ndarray,
                scale: float, top: int = 20) -> dict:
    """Per part: triangles in and out, area in and out, and the largest measured distance on
    its triangles in either direction (fraction of the diagonal), for the ``top`` parts with the
    largest error (all when there are few); with the counts of parts dropped (no triangle left)
    and collapsed (error above half the part's own size: its shape is gone)."""
    n_in = np.bincount(part_in, minlength=n_parts)
    n_out = np.bincount(part_out, minlength=n_parts)
    a_in = np.bincount(part_in, weights=area_in, minlength=n_parts)
    a_out = np.bincount(part_out, weights=area_out, minlength=n_parts)
    err = np.zeros(n_parts)
    if err_in is not None:
        np.maximum.at(err, part_in, err_in)
    if err_out is not None:
        np.maximum.at(err, part_out, err_out)
    dropped = (n_out == 0) & (n_in > 0)
    collapsed = ~dropped & (err > 0.5 * extent)
    order = np.lexsort((np.arange(n_parts), -err))[:top]
    rows = [{"part": int(p), "triangles_in": int(n_in[p]), "triangles_out": int(n_out[p]),
             "area_in": float(a_in[p] / scale ** 2), "area_out": float(a_out[p] / scale ** 2),
             "size": float(extent[p] / scale), "error": float(err[p] / scale),
             "state": "dropped" if dropped[p] else "collapsed" if collapsed[p] else "kept"} for p in order]
    return {"count": int(n_parts), "dropped": int(dropped.sum()), "collapsed": int(collapsed.sum()),
            "dropped_area": float(a_in[dropped].sum() / scale ** 2),
            "collapsed_area": float(a_in[collapsed].sum() / scale ** 2),
            "worst": rows, "units": "areas in diagonal^2, size and error in fractions of the diagonal; "
                                    "error: the largest measured distance on the part's triangles, either way"}
