"""What one frame's walk of the BSP lists costs from an eye: records, plane tests, triangles.

Every record is visited once per frame (one plane test per split record); every triangle of a
leaf or peel range is tested for facing and drawn if it faces the eye; of a split record's
coplanar triangles only the group facing the eye is drawn, untested. :func:`walk_counts` counts
these from the lists as written (the record layout of docs/formats-bsp.md), and
:func:`blocks_estimate` turns the counts into Scratch blocks executed with per-item costs fitted
to the reader sprite's ``bsp walk`` in the real Scratch VM (``benchmarks/bench_bsp.py`` measures
the walk in scratch-vm and reports its blocks next to this estimate, so a stale fit shows).
"""

from __future__ import annotations

import numpy as np

# Blocks per item: a least-squares fit of the blocks scratch-vm 5.0.300 counts for the reader's
# `bsp walk` (Suzanne, teapot, duck, Cornell box, AlphaBlendModeTest, 6 eyes each; largest error
# 0.5%). A split record's cost includes its share of the leaves (a tree has about one leaf per
# split); a single-sided triangle in a leaf or peel range costs the facing test, a two-sided one
# a material look-up. benchmarks/bench_bsp.py measures the walk again and reports both.
BLOCKS = {"base": 46, "split": 197, "peel": 70, "tested": 162, "tested_two_sided": 23, "drawn": 2,
          "coplanar_drawn": 5}


def parse(nodes: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Start item (1-based) and first value ``T`` of every record, in list order."""
    nodes = np.asarray(nodes, np.int64)
    starts, kinds = [], []
    r, n = 0, len(nodes)
    size = {0: 3, 1: 4}
    while r < n:  # one step per record (records have 3 to 6 items)
        T = int(nodes[r])
        starts.append(r + 1)
        kinds.append(T)
        r += size.get(T, 5 if T > 0 else 6)
    return np.asarray(starts, np.int64), np.asarray(kinds, np.int64)


def walk_counts(nodes: np.ndarray, planes: np.ndarray, triangles: np.ndarray, positions: np.ndarray,
                two_sided: np.ndarray, eye) -> dict:
    """Work of one walk from ``eye``: records of each kind, triangles tested for facing in leaf
    and peel ranges (single-sided ones take the full test, two-sided ones a material look-up) and
    how many of them are drawn, coplanar triangles drawn. ``triangles`` (T,
    3) 0-based and ``positions`` as written; ``two_sided`` per triangle."""
    nodes = np.asarray(nodes, np.int64)
    out = {"split": 0, "split_two_sided": 0, "leaf": 0, "peel": 0, "tested": 0, "tested_two_sided": 0,
           "drawn": 0, "coplanar_drawn": 0}
    if len(nodes) == 0:
        return out
    starts, T = parse(nodes)
    i = starts - 1
    eye = np.asarray(eye, np.float64)
    p = positions[triangles]
    nrm = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    two_sided = np.asarray(two_sided, bool)
    faces = (np.einsum("ij,ij->i", nrm, eye - p[:, 0]) > 0) | two_sided
    cum = np.concatenate([[0], np.cumsum(faces)])
    cum2 = np.concatenate([[0], np.cumsum(two_sided)])

    def count(first, n, c=cum):  # triangles counted by c in ranges first .. first + n - 1 (1-based)
        return c[first - 1 + n] - c[first - 1]

    leaf, peel = T == 0, T == 1
    out["leaf"], out["peel"] = int(leaf.sum()), int(peel.sum())
    lf, ln = nodes[i[leaf] + 1], nodes[i[leaf] + 2]
    pf, pp, ps = nodes[i[peel] + 1], nodes[i[peel] + 2], nodes[i[peel] + 3]
    out["tested_two_sided"] = int(count(lf, ln, cum2).sum() + count(pf, pp + ps, cum2).sum())
    out["tested"] = int(ln.sum() + pp.sum() + ps.sum()) - out["tested_two_sided"]
    out["drawn"] = int(count(lf, ln).sum() + count(pf, pp + ps).sum())
    for two, sel in ((False, T >= 2), (True, T <= -2)):
        r = i[sel]
        out["split_two_sided" if two else "split"] = int(sel.sum())
        if not len(r):
            continue
        pl = np.asarray(planes, np.float64).reshape(-1, 4)[np.abs(T[sel]) - 2]
        front = ((pl[:, 0] * eye[0] + pl[:, 1] * eye[1]) + pl[:, 2] * eye[2]) - pl[:, 3] >= 0
        nA = nodes[r + 3]
        nD = nodes[r + 4] if two else np.zeros(len(r), np.int64)
        nB = nodes[r + 5] if two else nodes[r + 4]
        out["coplanar_drawn"] += int(np.where(front, nA + nD, nD + nB).sum())
    return out


def blocks_estimate(counts: dict) -> int:
    """Scratch blocks the reader's ``bsp walk`` executes for these counts (see BLOCKS)."""
    c = dict(counts)
    c["split"] = c.get("split", 0) + c.pop("split_two_sided", 0)
    c.pop("leaf", None)
    return int(round(BLOCKS["base"] + sum(BLOCKS[k] * v for k, v in c.items() if k in BLOCKS)))
