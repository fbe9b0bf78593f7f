"""What one frame's walk of the BSP lists costs from an eye: records, plane tests, ranges.

The walk (docs/formats-bsp.md, record format 2) visits every record once per frame — one plane
test per split record — and appends ``(first, n)`` ranges to ``draw ranges``: one per leaf, two per
peel record, and a split record's coplanar range on the eye's side when it is not empty. It does no
work per triangle (the renderer culls). :func:`walk_counts` counts this from the lists as written,
and :func:`blocks_estimate` turns the counts into Scratch blocks executed with per-item costs fitted
to the reader sprite's ``bsp walk`` in the real Scratch VM (``benchmarks/bench_bsp.py`` measures
the walk in scratch-vm and reports its blocks next to this estimate, so a stale fit shows).
"""

from __future__ import annotations

import numpy as np

# Blocks per item: a least-squares fit (rounded) of the blocks scratch-vm 5.0.300 counts for the
# reader's `bsp walk` as it emits and pops in its branches (Suzanne, teapot, duck, house, spot,
# fuze, the CSG slivers and the tinyobj Cornell box with the default BSP, 6 eyes each, one of them
# inside the model: largest error 0.2%, except 6 blocks of 166 on the Cornell box's one-split
# tree; refitted for issue 41's walk, which tests the children in each branch). A split record's cost
# includes its share of the leaves (a tree has about one leaf per split); a peel record's its two
# ranges.
BLOCKS = {"base": 33, "split": 81, "peel": 46, "coplanar_ranges": 20}
SIZES = {0: 3, 1: 5}  # leaf, peel; a split record (T >= 4) has 6 items


def parse(nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start item (1-based) and first value ``T`` of every record, in list order."""
    nodes = np.asarray(nodes, np.int64)
    starts, kinds = [], []
    r, n = 0, len(nodes)
    while r < n:  # one step per record (3, 5 or 6 items)
        T = int(nodes[r])
        starts.append(r + 1)
        kinds.append(T)
        r += SIZES.get(T, 6)
    return np.asarray(starts, np.int64), np.asarray(kinds, np.int64)


def walk_counts(nodes: np.ndarray, planes: np.ndarray, triangles: np.ndarray, positions: np.ndarray,
                two_sided: np.ndarray, eye) -> dict:
    """Work of one walk from ``eye``: records of each kind (a plane test per split), ranges
    appended, the triangles in them, and how many of those face the eye (or are two-sided: what
    a culling renderer then fills). ``triangles`` (T, 3) 0-based and ``positions`` as written."""
    nodes = np.asarray(nodes, np.int64)
    out = {"split": 0, "leaf": 0, "peel": 0, "ranges": 0, "coplanar_ranges": 0, "triangles": 0, "facing": 0}
    if len(nodes) == 0:
        return out
    starts, T = parse(nodes)
    i = starts - 1
    eye = np.asarray(eye, np.float64)
    p = positions[triangles]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    faces = (np.einsum("ij,ij->i", nrm, eye - p[:, 0]) > 0) | np.asarray(two_sided, bool)
    cum = np.concatenate([[0], np.cumsum(faces)])

    def facing(first, n):  # facing triangles in ranges first .. first + n - 1 (1-based)
        return cum[first - 1 + n] - cum[first - 1]

    leaf, peel, split = T == 0, T == 1, T >= 4
    out["leaf"], out["peel"], out["split"] = int(leaf.sum()), int(peel.sum()), int(split.sum())
    firsts = [nodes[i[leaf] + 1], nodes[i[peel] + 1], nodes[i[peel] + 3]]
    counts = [nodes[i[leaf] + 2], nodes[i[peel] + 2], nodes[i[peel] + 4]]
    r = i[split]
    if len(r):
        pl = np.asarray(planes, np.float64).ravel()  # flat, as written
        t = T[split]  # item of the plane's d: a, b, c are the three items before it
        a, b, c, d = pl[t - 4], pl[t - 3], pl[t - 2], pl[t - 1]
        front = ((a * eye[0] + b * eye[1]) + c * eye[2]) - d >= 0
        f = np.where(front, nodes[r + 2], nodes[r + 4])
        n = np.where(front, nodes[r + 3], nodes[r + 5])
        out["coplanar_ranges"] = int((n > 0).sum())
        firsts.append(f[n > 0])
        counts.append(n[n > 0])
    f, n = np.concatenate(firsts), np.concatenate(counts)
    out["ranges"] = int(len(f))
    out["triangles"] = int(n.sum())
    out["facing"] = int(facing(f, n).sum())
    return out


def blocks_estimate(counts: dict) -> int:
    """Scratch blocks the reader's ``bsp walk`` executes for these counts (see BLOCKS)."""
    return int(round(BLOCKS["base"] + sum(BLOCKS[k] * counts.get(k, 0) for k in BLOCKS if k != "base")))
