"""Flat Scratch lists for a BVH: three layouts, all 1-based, all read by ``traverse.py``.

Every layout writes three lists (names are ``<prefix> nodes`` etc.):

* ``nodes`` -- the tree (layout below);
* ``tris``  -- 9 numbers per leaf slot: the corners v0, v1, v2 (x, y, z each) of the triangle,
  rounded to the decimal grid the stage chose, so the lists are watertight where the mesh is;
* ``tri ids`` -- per leaf slot, the scene triangle number (1-based) for colour look-ups.

``binary``: one 7-item record per node in depth-first order (the root at item 1)::

    lox loy loz hix hiy hiz link
    link < 0 : interior node; its first child is the next record; -link is the item where the
               walk goes when this box is missed (the record after the subtree)
    link > 0 : leaf; first slot = floor(link / 16), triangle count = link mod 16

``wide4`` and ``quantised``: a 6-item header (the root box, lo xyz then hi xyz) and then one
fixed-size record per 4-wide node (the root record starts at item 7)::

    meta child_base tri_base box1 box2 box3 box4
    meta       = sum over children j (0-based) of code_j * 16^j; code 15 = interior child,
                 1..14 = leaf child with that many triangles (0 = no more children)
    child_base = item of the first interior child's record; the others follow every stride items
    tri_base   = first slot of the first leaf child; the leaf children's slots follow in order
    box j      = wide4: 6 floats (lo xyz, hi xyz); quantised: ONE integer packing 6 values
                 q0..q5 (lo xyz, hi xyz) of ``bits`` bits each, q0 in the lowest bits.

Quantised boxes are relative to the box of the node that holds them (its *frame*): with
``Q = 2^bits - 2`` and ``c = (frame_hi - frame_lo) / Q`` per axis, a child's box is
``frame_lo + q * c`` (computed exactly like that, in float64). The root's frame is the header
box; every other node's frame is its own decoded box, which the traversal carries on its stack.
Codes are chosen against exactly that arithmetic and rounded outward, so a decoded box always
contains the float box, which contains the triangles: the quantised walk never loses a hit.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from .build import BVH, half_area

LAYOUTS = ("binary", "wide4", "quantised")
LEAF_BASE = 16  # link / meta code base: at most 14 triangles per leaf
MAX_LEAF = 14
BIN_STRIDE = 7
WIDE_HEADER = 6


@dataclass
class Encoded:
    layout: str
    nodes: np.ndarray  # float64 item values of the node list
    tris: np.ndarray  # float64, 9 per slot
    ids: np.ndarray  # int64, 1 per slot: scene triangle number (1-based)
    n_nodes: int  # records in ``nodes`` (binary nodes or 4-wide nodes)
    stride: int
    header: int = 0
    bits: int = 0
    decimals: int | None = None
    info: dict = field(default_factory=dict)

    @property
    def items(self) -> int:
        return int(len(self.nodes) + len(self.tris) + len(self.ids))


# --------------------------------------------------------------------------- rounding
def decimals_for(scale: float, precision: int) -> int | None:
    """Decimals of the grid used for list coordinates: the power of ten at most
    ``scale * 10^-precision``; ``None`` when ``precision`` is 0 (keep float64 as is)."""
    if precision <= 0:
        return None
    scale = float(scale) if scale > 0 and np.isfinite(scale) else 1.0
    return int(precision - np.floor(np.log10(scale)))


def _grid(d: int) -> tuple[float, bool]:
    return (10.0 ** abs(d), d >= 0)


def round_nearest(x: np.ndarray, d: int | None) -> np.ndarray:
    """The float64 a Scratch project reads back for ``x`` written with ``d`` decimals."""
    x = np.asarray(x, np.float64)
    if d is None:
        return x.copy()
    s, pos = _grid(d)
    if pos:
        return np.rint(x * s) / s
    return np.rint(x / s) * s


def round_down(x: np.ndarray, d: int | None) -> np.ndarray:
    """Largest grid value <= x (exactly, after the decode a reader does)."""
    x = np.asarray(x, np.float64)
    if d is None:
        return x.copy()
    s, pos = _grid(d)
    dec = (lambda k: k / s) if pos else (lambda k: k * s)
    k = np.floor(x * s) if pos else np.floor(x / s)
    v = dec(k)
    for _ in range(3):
        bad = v > x
        if not bad.any():
            break
        k = np.where(bad, k - 1, k)
        v = dec(k)
    return v


def round_up(x: np.ndarray, d: int | None) -> np.ndarray:
    return -round_down(-np.asarray(x, np.float64), d)


def outward(lo: np.ndarray, hi: np.ndarray, d: int | None, pad: float) -> tuple[np.ndarray, np.ndarray]:
    """Boxes grown by ``pad`` and rounded outward onto the grid."""
    return round_down(lo - pad, d), round_up(hi + pad, d)


# --------------------------------------------------------------------------- bytes
def json_lengths(values: np.ndarray) -> int:
    """Bytes of the items as JSON numbers (integers without a point, floats as the shortest
    repr that reads back exactly), plus one comma between items."""
    v = np.asarray(values, np.float64)
    if len(v) == 0:
        return 0
    integral = (v == np.round(v)) & (np.abs(v) < 2.0 ** 53)
    iv = np.abs(v[integral])
    digits = np.floor(np.log10(np.maximum(iv, 1))).astype(np.int64) + 1
    # log10 can be off by one right at powers of ten
    digits = digits + (iv >= 10.0 ** digits) - ((iv < 10.0 ** (digits - 1)) & (iv >= 1))
    total = int(digits.sum()) + int((v[integral] < 0).sum())
    total += sum(len(repr(f)) for f in v[~integral].tolist())
    return total + len(v) - 1


def list_bytes(values: np.ndarray) -> int:
    """project.json bytes of ``[...]`` holding the items."""
    return json_lengths(values) + 2


# --------------------------------------------------------------------------- helpers
def _tri_block(tri: np.ndarray, slots_tri: np.ndarray) -> np.ndarray:
    return tri[slots_tri].reshape(-1)


# --------------------------------------------------------------------------- binary
def encode_binary(bvh: BVH, tri: np.ndarray, tri_ids: np.ndarray, *, d: int | None,
                  pad: float) -> Encoded:
    """``bvh`` must be in preorder (``build.preorder``); ``tri`` (T,3,3) the list triangles."""
    N = bvh.n_nodes
    if N == 0:
        return Encoded("binary", np.zeros(0), np.zeros(0), np.zeros(0, np.int64), 0, BIN_STRIDE,
                       decimals=d)
    lo, hi = outward(bvh.lo, bvh.hi, d, pad)
    # in preorder the record after a subtree is node + subtree size
    size = _subtree_sizes_fast(bvh)
    leaf = bvh.left < 0
    if leaf.any() and bvh.count[leaf].max() > MAX_LEAF:
        raise ValueError(f"a leaf holds more than {MAX_LEAF} triangles")
    skip_item = (np.arange(N) + size) * BIN_STRIDE + 1
    link = np.where(leaf, (bvh.first + 1) * LEAF_BASE + bvh.count, -skip_item).astype(np.float64)
    rec = np.concatenate([lo, hi, link[:, None]], axis=1)
    enc = Encoded("binary", rec.reshape(-1), _tri_block(tri, bvh.order),
                  np.asarray(tri_ids, np.int64)[bvh.order], N, BIN_STRIDE, decimals=d)
    return enc


def _subtree_sizes_fast(bvh: BVH) -> np.ndarray:
    """Subtree node counts, vectorised level by level (bottom-up)."""
    from .build import _level_list

    size = np.ones(bvh.n_nodes, np.int64)
    for lv in reversed(_level_list(bvh)):
        inner = lv[bvh.left[lv] >= 0]
        size[inner] = 1 + size[bvh.left[inner]] + size[bvh.right[inner]]
    return size


# --------------------------------------------------------------------------- 4-wide
@dataclass
class Wide:
    """A 4-wide tree made from a binary one: every wide node is a binary node whose children
    are the binary descendants chosen by opening the largest interior child first."""

    node: list[int]  # binary node of each wide node, record order (root first)
    children: list[list[int]]  # binary nodes of its children, in order
    child_base: list[int]  # record number of the first interior child (-1 if none)
    tri_base: list[int]  # slot (0-based) of the first leaf child's triangles (-1 if none)
    slots: np.ndarray  # triangle number of each slot


def widen(bvh: BVH, width: int = 4) -> Wide:
    if bvh.n_nodes == 0:
        return Wide([], [], [], [], np.zeros(0, np.int64))
    area = half_area(bvh.lo, bvh.hi)
    left, right = bvh.left.tolist(), bvh.right.tolist()
    ar = area.tolist()

    def kids_of(b: int) -> list[int]:
        if left[b] < 0:
            return [b]  # a leaf root: one leaf child with the root box
        kids = [left[b], right[b]]
        while len(kids) < width:
            best, best_a = -1, -1.0
            for j, k in enumerate(kids):
                if left[k] >= 0 and ar[k] > best_a:
                    best, best_a = j, ar[k]
            if best < 0:
                break
            k = kids[best]
            kids[best:best + 1] = [left[k], right[k]]
        return kids

    node = [0]
    children: list[list[int]] = []
    child_base: list[int] = []
    tri_base: list[int] = []
    slots: list[np.ndarray] = []
    n_slots = 0
    kids_cache: dict[int, list[int]] = {}
    stack = [0]
    base_of: dict[int, int] = {}
    while stack:
        b = stack.pop()
        kids = kids_of(b)
        kids_cache[b] = kids
        inner = [k for k in kids if left[k] >= 0 and k != b]
        if inner:
            base_of[b] = len(node)
            node.extend(inner)
        else:
            base_of[b] = -1
        stack.extend(reversed(inner))
    for b in node:
        kids = kids_cache[b]
        children.append(kids)
        child_base.append(base_of[b])
        leaves = [k for k in kids if left[k] < 0 or k == b]
        if leaves:
            tri_base.append(n_slots)
            for k in leaves:
                f, c = int(bvh.first[k]), int(bvh.count[k])
                slots.append(bvh.order[f:f + c])
                n_slots += c
        else:
            tri_base.append(-1)
    return Wide(node, children, child_base, tri_base,
                np.concatenate(slots) if slots else np.zeros(0, np.int64))


def record_depth(bvh: BVH, w: Wide) -> int:
    """Depth of the 4-wide tree in records (the root record 0): what bounds the walk's stack
    (at most 3 x depth + 1 entries), not the binary tree's depth."""
    depth = np.zeros(len(w.node), np.int64)
    left = bvh.left
    for r, (b, kids) in enumerate(zip(w.node, w.children)):  # parents come before children
        n_inner = sum(1 for k in kids if left[k] >= 0 and k != b)
        if n_inner:
            base = w.child_base[r]
            depth[base:base + n_inner] = depth[r] + 1
    return int(depth.max()) if len(depth) else 0


def _meta(bvh: BVH, kids: list[int], self_node: int) -> int:
    m = 0
    for j, k in enumerate(kids):
        if bvh.left[k] >= 0 and k != self_node:
            code = LEAF_BASE - 1
        else:
            code = int(bvh.count[k])
            if not 1 <= code <= MAX_LEAF:
                raise ValueError(f"a leaf holds {code} triangles (1..{MAX_LEAF} allowed)")
        m += code * LEAF_BASE ** j
    return m


def encode_wide(bvh: BVH, tri: np.ndarray, tri_ids: np.ndarray, *, d: int | None, pad: float,
                quantised: bool = False, bits: int = 6) -> Encoded:
    layout = "quantised" if quantised else "wide4"
    stride = 3 + (4 if quantised else 24)
    if bvh.n_nodes == 0:
        return Encoded(layout, np.zeros(0), np.zeros(0), np.zeros(0, np.int64), 0, stride,
                       header=WIDE_HEADER, bits=bits if quantised else 0, decimals=d)
    w = widen(bvh)
    lo, hi = outward(bvh.lo, bvh.hi, d, pad)  # float boxes of every binary node
    R = len(w.node)
    rec = np.zeros((R, stride))
    for r, (b, kids) in enumerate(zip(w.node, w.children)):
        rec[r, 0] = _meta(bvh, kids, b)
        rec[r, 1] = WIDE_HEADER + w.child_base[r] * stride + 1 if w.child_base[r] >= 0 else 0
        rec[r, 2] = w.tri_base[r] + 1 if w.tri_base[r] >= 0 else 0
    header = np.concatenate([lo[0], hi[0]])
    info: dict = {}
    if not quantised:
        for r, kids in enumerate(w.children):
            kb = np.concatenate([lo[kids], hi[kids]], axis=1)  # (k, 6)
            rec[r, 3:3 + 6 * len(kids)] = kb.reshape(-1)
    else:
        info = _quantise_boxes(w, lo, hi, rec, bits)
    info["record_depth"] = record_depth(bvh, w)
    nodes = np.concatenate([header, rec.reshape(-1)])
    enc = Encoded(layout, nodes, _tri_block(tri, w.slots), np.asarray(tri_ids, np.int64)[w.slots],
                  R, stride, header=WIDE_HEADER, bits=bits if quantised else 0, decimals=d,
                  info=info)
    return enc


def qdecode(frame_lo: np.ndarray, frame_hi: np.ndarray, q: np.ndarray, bits: int) -> np.ndarray:
    """The float64 plane values a traversal computes from codes ``q`` in a frame (the exact
    operation order of the Scratch script: ``lo + q * ((hi - lo) / Q)``)."""
    Q = float(2 ** bits - 2)
    c = (frame_hi - frame_lo) / Q
    return frame_lo + q * c


def _quantise_boxes(w: Wide, lo: np.ndarray, hi: np.ndarray, rec: np.ndarray, bits: int) -> dict:
    """Fill the packed child boxes of every record, frames top-down. Returns statistics."""
    if not 2 <= bits <= 8:
        raise ValueError("quantisation bits must be 2..8")
    M = 2 ** bits
    top = M - 1
    Q = float(M - 2)
    rec_of = {b: r for r, b in enumerate(w.node)}
    R = len(w.node)
    f_lo = np.zeros((R, 3))
    f_hi = np.zeros((R, 3))
    f_lo[0], f_hi[0] = lo[0], hi[0]
    grow = []
    for r in range(R):  # parents come before their children in record order
        kids = w.children[r]
        flo, fhi = f_lo[r], f_hi[r]
        c = (fhi - flo) / Q
        klo, khi = lo[kids], hi[kids]
        with np.errstate(divide="ignore", invalid="ignore"):
            qlo = np.where(c > 0, np.floor((klo - flo) / np.where(c > 0, c, 1.0)), 0.0)
            qhi = np.where(c > 0, np.ceil((khi - flo) / np.where(c > 0, c, 1.0)), 0.0)
        qlo = np.clip(qlo, 0, top)
        qhi = np.clip(qhi, 0, top)
        for _ in range(4):  # make the decode (exactly as the reader computes it) contain the box
            dlo = flo + qlo * c
            dhi = flo + qhi * c
            bad_lo = (dlo > klo) & (qlo > 0)
            bad_hi = (dhi < khi) & (qhi < top)
            if not (bad_lo.any() or bad_hi.any()):
                break
            qlo = np.where(bad_lo, qlo - 1, qlo)
            qhi = np.where(bad_hi, qhi + 1, qhi)
        dlo = flo + qlo * c
        dhi = flo + qhi * c
        if (dlo > klo).any() or (dhi < khi).any():
            raise AssertionError("quantised box does not contain its child")  # cannot happen
        packed = (qlo[:, 0] + M * (qlo[:, 1] + M * (qlo[:, 2] + M * (qhi[:, 0] + M * (
            qhi[:, 1] + M * qhi[:, 2])))))
        rec[r, 3:3 + len(kids)] = packed
        for j, k in enumerate(kids):
            rk = rec_of.get(k)
            if rk is not None and rk != r:
                f_lo[rk], f_hi[rk] = dlo[j], dhi[j]
        grow.append(half_area(dlo, dhi) / np.maximum(half_area(klo, khi), 1e-300))
    g = np.concatenate(grow) if grow else np.zeros(0)
    return {"area_growth_mean": float(g.mean()) if len(g) else 1.0}


def encode(bvh: BVH, tri: np.ndarray, tri_ids: np.ndarray, layout: str, *, d: int | None,
           pad: float, bits: int = 6) -> Encoded:
    if layout == "binary":
        return encode_binary(bvh, tri, tri_ids, d=d, pad=pad)
    if layout == "wide4":
        return encode_wide(bvh, tri, tri_ids, d=d, pad=pad)
    if layout == "quantised":
        return encode_wide(bvh, tri, tri_ids, d=d, pad=pad, quantised=True, bits=bits)
    raise ValueError(f"unknown layout {layout!r}; expected one of {LAYOUTS}")


def sizes(enc: Encoded) -> dict:
    """List items and project.json bytes, total and per node."""
    nb = list_bytes(enc.nodes)
    tb = list_bytes(enc.tris)
    ib = list_bytes(enc.ids)
    n = max(enc.n_nodes, 1)
    rec_items = len(enc.nodes) - (enc.header if len(enc.nodes) else 0)
    rec_bytes = json_lengths(enc.nodes[enc.header:]) + 1 if len(enc.nodes) else 0
    return {
        "node_records": enc.n_nodes,
        "node_items": int(len(enc.nodes)),
        "tri_items": int(len(enc.tris)),
        "id_items": int(len(enc.ids)),
        "items": enc.items,
        "node_bytes": nb,
        "tri_bytes": tb,
        "id_bytes": ib,
        "bytes": nb + tb + ib,
        "items_per_node": rec_items / n,
        "bytes_per_node": rec_bytes / n,
    }
