"""The tree as two flat Scratch lists, and the triangle order the export writes.

``bsp planes`` (stride 4): ``a, b, c, d`` of each distinct plane; the eye at ``(x, y, z)`` is in
front of plane ``p`` when ``a*x + b*y + c*z - d >= 0``. Normals are rounded to a few decimals and
offsets to a scene-relative unit, the tree was built with exactly these planes, and nodes that
lie in the same plane share one entry (orientation is made canonical by flipping the node).

``bsp nodes``: variable-length records, addressed by the (1-based) item index of their first item;
the root is at item 1. The first item ``T`` says what the record is (format 2: every number the
walk needs is stored, nothing is computed from it per frame):

======  ==============================  =======================================================
``T``   items                           meaning
======  ==============================  =======================================================
0       ``0, first, n``                 leaf: triangles first .. first+n-1, in this order
1       ``1, first, np, first2, ns``    peel: ``np`` triangles from ``first``, then the child
                                        (the next record, 5 items on), then ``ns`` from
                                        ``first2`` (= first + np)
>= 4    ``T, B, fF, nF, fB, nB``        split on the plane whose ``d`` is item ``T`` of ``bsp
                                        planes`` (plane ``T / 4``: a, b, c at ``T-3 .. T-1``)
======  ==============================  =======================================================

Split records: the front child is the next record (6 items on) unless ``B < 0``; the back child is
at item ``B`` if ``B > 0``, at item ``-B`` if ``B < 0`` (and then there is no front child), none if
``B = 0``. The coplanar triangles are two ready-made ranges: with the eye in front (or on the
plane) draw the back child, ``nF`` triangles from ``fF``, then the front child; with the eye behind
the front child, ``nB`` from ``fB``, then the back child. (The coplanar triangles are stored
``nA`` seen from the front, ``nD`` two-sided, ``nBack`` seen from the back: ``fF = first, nF = nA
+ nD, fB = first + nA, nB = nD + nBack``.)

Every triangle of the scene appears in exactly one leaf, peel or coplanar group; the BSP stage
reorders the scene's triangles so that each is contiguous (``first`` is 1-based into the exported
triangle list). Back faces are not culled by the walk: a renderer skips the triangles that face
away (on screen, or in 3D), which is why the order inside a leaf is only right for the faces drawn.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .build import Tree

LEAF, PEEL = 0, 1
SPLIT_SIZE, PEEL_SIZE, LEAF_SIZE = 6, 5, 3

NODES_DOC = ("BSP records (0 leaf: first, n; 1 peel: first, np, first2, ns; >=4 split: item of the plane's d, "
             "back, fF, nF, fB, nB) — docs/formats-bsp.md")


@dataclass
class Encoded:
    nodes: np.ndarray  # int64 items of "bsp nodes"
    planes: np.ndarray  # (P, 4) world planes of "bsp planes"
    frag_order: np.ndarray  # fragments in the order their triangles are written
    frag_tris: np.ndarray  # triangles each of those fragments becomes
    records: dict  # count of each record kind
    max_depth: int  # deepest record nesting (the traversal stack needs <= 2 * max_depth + 2)
    plane_uses: int  # split records (planes referenced)


def _group(ids: np.ndarray, node: np.ndarray, n: int, extra: np.ndarray | None = None):
    order = np.argsort(node, kind="stable")
    start = np.zeros(n + 1, np.int64)
    np.cumsum(np.bincount(node, minlength=n), out=start[1:])
    return ids[order], (extra[order] if extra is not None else None), start


def encode(tree: Tree, frag_tris: np.ndarray) -> Encoded:
    """Lay the tree out as records (preorder) and fix the order of every fragment.

    ``frag_tris[f]``: how many triangles fragment f becomes when written."""
    N = tree.n_nodes
    on_ids, on_side, on_start = _group(tree.on_ids, tree.on_node, N, tree.on_side)
    pre_ids, _, pre_start = _group(tree.pre_ids, tree.pre_node, N)
    suf_ids, _, suf_start = _group(tree.suf_ids, tree.suf_node, N)
    has_plane = tree.has_plane

    items: list[int] = []
    frags: list[np.ndarray] = []
    plane_index: dict[tuple, int] = {}
    planes: list[np.ndarray] = []
    kinds = {"leaf": 0, "peel": 0, "split": 0, "split_two_sided": 0}
    tri_counter = 0
    max_depth = 0
    patch: dict[int, int] = {}  # node -> item position of the B field of its parent's record
    patch_sign: dict[int, int] = {}
    stack = [(0, 0)] if N else []  # (node, record depth)
    while stack:
        n, depth = stack.pop()
        offset = len(items) + 1  # 1-based item of this node's first record
        if n in patch:
            items[patch.pop(n)] = patch_sign.pop(n) * offset
        max_depth = max(max_depth, depth)
        pre = pre_ids[pre_start[n]:pre_start[n + 1]]
        suf = suf_ids[suf_start[n]:suf_start[n + 1]]
        on = on_ids[on_start[n]:on_start[n + 1]]
        side = on_side[on_start[n]:on_start[n + 1]]
        f, b = int(tree.front[n]), int(tree.back[n])
        if not has_plane[n] or (f < 0 and b < 0):
            # a leaf: prefix, coplanar faces (no children: they cannot hide each other), suffix
            leaf = np.concatenate([pre, on[side == 0], on[side == 2], on[side == 1], suf])
            nt = int(frag_tris[leaf].sum())
            items += [LEAF, tri_counter + 1, nt]
            frags.append(leaf)
            tri_counter += nt
            kinds["leaf"] += 1
            continue
        if len(pre) or len(suf):
            npre, nsuf = int(frag_tris[pre].sum()), int(frag_tris[suf].sum())
            items += [PEEL, tri_counter + 1, npre, tri_counter + 1 + npre, nsuf]
            frags += [pre, suf]
            tri_counter += npre + nsuf
            kinds["peel"] += 1
            depth += 1
            max_depth = max(max_depth, depth)
        pl = tree.world_plane[n].copy()
        A, D, B = on[side == 0], on[side == 2], on[side == 1]
        nz = np.flatnonzero(pl[:3] != 0)
        if len(nz) and pl[nz[0]] < 0:  # canonical orientation: flip the node
            pl = -pl
            f, b = b, f
            A, B = B, A
        pl = pl + 0.0
        key = tuple(pl.tolist())
        if key not in plane_index:
            plane_index[key] = len(planes) + 1
            planes.append(pl)
        p = plane_index[key]
        nA, nD, nB = (int(frag_tris[x].sum()) for x in (A, D, B))
        first = tri_counter + 1
        b_pos = len(items) + 1
        items += [4 * p, 0, first, nA + nD, first + nA, nD + nB]
        kinds["split_two_sided" if len(D) else "split"] += 1
        frags += [A, D, B]
        tri_counter += nA + nD + nB
        if f >= 0 and b >= 0:
            patch[b], patch_sign[b] = b_pos, 1
            stack.append((b, depth + 1))
            stack.append((f, depth + 1))
        elif f >= 0:
            stack.append((f, depth + 1))
        else:
            patch[b], patch_sign[b] = b_pos, -1
            stack.append((b, depth + 1))
    order = np.concatenate(frags) if frags else np.zeros(0, np.int64)
    return Encoded(nodes=np.array(items, np.int64), planes=np.array(planes, np.float64).reshape(-1, 4),
                   frag_order=order, frag_tris=frag_tris[order], records=kinds, max_depth=max_depth,
                   plane_uses=kinds["split"] + kinds["split_two_sided"])
