"""The ``bvh`` stage: a BVH over the scene's triangles, written as Scratch lists.

The scene's triangle order is left alone (the BSP stage owns it). The lists carry their own
triangle corners plus a list of scene triangle numbers (1-based) per leaf slot, so a ray
tracer can look the hit triangle's colour up in the exported per-triangle lists.
See ``docs/formats-bvh.md`` for the lists and the Scratch traversal.
"""

from __future__ import annotations

import time

import numpy as np

from ..config import BVHConfig
from ..errors import ConfigError
from ..record import StageRecord
from ..scene import BVHArtefact, Scene, ScratchList
from ..scratch.limits import LIST_ITEM_LIMIT, PROJECT_JSON_LIMIT
from . import build as build_mod
from .encode import MAX_LEAF, decimals_for, encode, outward, round_nearest, sizes
from .traverse import BARY_HI, BARY_LO



def check_config(cfg: BVHConfig) -> None:
    def need(ok: bool, key: str, msg: str) -> None:
        if not ok:
            raise ConfigError(msg, key=f"bvh.{key}")

    need(1 <= cfg.leaf_size <= MAX_LEAF, "leaf_size", f"must be between 1 and {MAX_LEAF}")
    need(2 <= cfg.bins <= 256, "bins", "must be between 2 and 256")
    need(2 <= cfg.quant_bits <= 8, "quant_bits", "must be between 2 and 8")
    need(0 <= cfg.precision <= 15, "precision", "must be between 0 (exact) and 15")
    need(cfg.high_effort >= 0, "high_effort", "must be >= 0")
    need(bool(cfg.list_prefix.strip()), "list_prefix", "must not be empty")


def list_names(prefix: str) -> dict[str, str]:
    return {"nodes": f"{prefix} nodes", "tris": f"{prefix} tris", "ids": f"{prefix} tri ids"}


def _smaller(cfg: BVHConfig) -> str:
    """What would make the BVH lists smaller, from the settings this bake used (advice that is
    already taken is not given: the layout that is already quantised, a precision that is low)."""
    ways = []
    if cfg.layout != "quantised":
        ways.append("bvh.layout = \"quantised\" (its child boxes are small integers)")
    if cfg.precision == 0 or cfg.precision > 3:
        ways.append(f"a lower bvh.precision (now {cfg.precision}{', exact' if cfg.precision == 0 else ''}; 3 rounds "
                    "the coordinates to a thousandth of the diagonal)")
    ways.append("fewer triangles (mesh.simplify)")
    return "try " + ", or ".join(ways)


def prepare(scene: Scene, precision: int) -> tuple[np.ndarray, np.ndarray, int | None, float]:
    """List triangles (T,3,3) rounded as the lists store them, the scene triangle numbers kept
    (0-based; exactly degenerate triangles, which no ray can hit, are left out), the decimals
    and the box padding."""
    tri = scene.triangle_vertices()
    scale = scene.scale()
    d = decimals_for(scale, precision)
    tq = round_nearest(tri, d)
    if len(tq):
        n = np.cross(tq[:, 1] - tq[:, 0], tq[:, 2] - tq[:, 0])
        keep = np.nonzero(np.any(n != 0, axis=1))[0]
        mag = float(np.abs(tq).max())
    else:
        keep = np.zeros(0, np.int64)
        mag = 0.0
    # boxes grow by this before rounding outward: far above float64 rounding of the slab test
    # for origins within ~1e6 scene sizes, and above the 2e-9 x triangle size by which the inside
    # test's tolerance (traverse.BARY_EPS) widens a triangle; far below any size that matters
    pad = 4e-9 * (scale + mag)
    return tq, keep, d, pad


def stage(scene: Scene, cfg: BVHConfig) -> tuple[Scene, StageRecord]:
    check_config(cfg)
    taken = sorted(set(list_names(cfg.list_prefix).values()) & set(scene.lists))
    if taken:  # (the BSP stage's lists, say): one would silently replace the other
        raise ConfigError(f"list name '{taken[0]}' is already written by an earlier stage "
                          f"({(scene.lists[taken[0]].doc or 'a stage list').split(' (')[0]}); choose another prefix",
                          key="bvh.list_prefix")
    t0 = time.perf_counter()
    rec = StageRecord(name="bvh")
    tq, keep, d, pad = prepare(scene, cfg.precision)
    T = scene.n_triangles
    if T == 0:
        rec.warn("the scene has no triangles: the BVH lists are empty")
    dropped = T - len(keep)
    if dropped:
        rec.warn(f"{dropped} degenerate triangle(s) (zero area after rounding) left out of the BVH")
    lo = tq[keep].min(axis=1) if len(keep) else np.zeros((0, 3))
    hi = tq[keep].max(axis=1) if len(keep) else np.zeros((0, 3))
    tb = time.perf_counter()
    bvh = build_mod.build(lo, hi, leaf_size=cfg.leaf_size, bins=cfg.bins, quality=cfg.quality,
                          high_effort=cfg.high_effort, ids=keep)
    build_s = time.perf_counter() - tb
    te = time.perf_counter()
    enc = encode(bvh, tq, np.arange(1, T + 1, dtype=np.int64), cfg.layout, d=d, pad=pad,
                 bits=cfg.quant_bits)
    encode_s = time.perf_counter() - te
    sz = sizes(enc)
    names = list_names(cfg.list_prefix)
    what = {"binary": "7 items per node: box lo xyz, hi xyz, link",
            "wide4": "6-item root box, then 27 items per 4-wide node",
            "quantised": "6-item root box, then 7 items per 4-wide node (packed child boxes)"}
    record_items = {"binary": (0, 7), "wide4": (6, 27), "quantised": (6, 7)}[cfg.layout]
    scene = scene.with_list(ScratchList(
        names["nodes"], enc.nodes, stride=1, kind="number", decimals=None,
        doc=f"BVH ({cfg.layout}): {what[cfg.layout]}; see docs/formats-bvh.md",
        pack_prefix=record_items[0], pack_stride=record_items[1]))
    scene = scene.with_list(ScratchList(
        names["tris"], enc.tris, stride=9, kind="number", decimals=None,
        doc="BVH leaf slots: triangle corners v0 v1 v2 (x y z each)"))
    scene = scene.with_list(ScratchList(
        names["ids"], enc.ids, stride=1, kind="int", decimals=None,
        doc="BVH leaf slots: scene triangle number (1-based)"))
    # the reader sprite's inside test uses the reference's bounds (bake.scratch.readers.BVHSpec)
    scene = scene.with_artefacts(bvh=BVHArtefact(bvh, enc, (BARY_LO, BARY_HI), dict(names)))

    # the SAH of the tree as written: every box grown by the pad and rounded outward onto the
    # list grid, exactly the boxes of the binary layout's records (the float boxes the 4-wide
    # layouts are made from); the tight float64 boxes' figure is kept in the details
    sah_tight = build_mod.sah_cost(bvh)
    wlo, whi = outward(bvh.lo, bvh.hi, d, pad) if bvh.n_nodes else (bvh.lo, bvh.hi)
    sah = build_mod.sah_cost(bvh, lo=wlo, hi=whi)
    rec.accuracy["sah_cost"] = sah
    rec.counts_out = {"triangles": T, "bvh_nodes": bvh.n_nodes, "bvh_leaves": bvh.n_leaves,
                      "bvh_records": enc.n_nodes, "bvh_slots": int(len(enc.ids)),
                      "bvh_list_items": enc.items}
    rec.details = {
        "layout": cfg.layout, "quality": cfg.quality, "leaf_size": cfg.leaf_size,
        "bins": cfg.bins, "quant_bits": cfg.quant_bits if cfg.layout == "quantised" else None,
        "decimals": d, "pad": pad, "depth": bvh.depth(), "sah_cost": sah,
        "sah_cost_unrounded": sah_tight,
        "build_seconds": build_s, "encode_seconds": encode_s, "lists": names,
        "degenerate_dropped": dropped, "sizes": sz,
        # 4-wide layouts: depth in records (root record 0), which bounds the walk's stack
        "record_depth": enc.info.get("record_depth"),
        "quantised_area_growth_mean": enc.info.get("area_growth_mean"),
        "build_info": {k: v for k, v in bvh.info.items() if isinstance(v, (int, float, str))},
    }
    for key, n in (("nodes", len(enc.nodes)), ("tris", len(enc.tris)), ("ids", len(enc.ids))):
        if n > LIST_ITEM_LIMIT:
            rec.warn(f"list '{names[key]}' has {n} items: more than vanilla Scratch's 200,000 "
                     "(it loads, but blocks cannot add to it; TurboWarp has no limit)")
    if sz["bytes"] > PROJECT_JSON_LIMIT:
        rec.warn(f"the BVH lists alone take {sz['bytes']:,} bytes of project.json, more than the "
                 f"5 MiB scratch.mit.edu accepts; {_smaller(cfg)}")
    rec.seconds = time.perf_counter() - t0
    return scene, rec
