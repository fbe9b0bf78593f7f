"""The lightmap unwrap: xatlas charts and packs the mesh into an :class:`~bake.textures.atlas.Atlas`.

xatlas runs in a subprocess (``xatlas_worker.py``, started by ``WORKER_COMMAND``) with
``textures.lightmap.timeout``: a crash or a hang costs the subprocess, never the bake. A crash is
tried once more (:func:`_run_worker`); a timeout, a second crash or an xatlas error is a
:class:`StageError` saying which. The result is cached (``unwrap_cache.py``) by a hash of the
exact input and options, so a rerun is fast and gives identical UVs.

xatlas's tolerances are absolute, so it sees the mesh centred and, when it is not of a size xatlas
handles well, multiplied by a power of two (:func:`xatlas_scale`); the options in model units are
converted to match (:func:`xatlas_options`), so a model in millimetres or kilometres gets about
the atlas it gets in metres. xatlas grows the atlas past the resolution asked (the charts'
padding), so without ``texels_per_unit`` the unwrap asks again for less until the atlas fits
(:func:`_next_resolution`).
"""

from __future__ import annotations

import json
import math
import signal
import subprocess
import sys
import tempfile
from pathlib import Path

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph

from ..config import LightmapConfig
from ..errors import StageError
from ..scene import Scene
from . import unwrap_cache
from .atlas import Atlas, cross2

WORKER = Path(__file__).with_name("xatlas_worker.py")
# How the worker is started (tests replace it to check crash and timeout handling).
WORKER_COMMAND: list[str] = [sys.executable, str(WORKER)]

# xatlas's tolerances are absolute (XA_EPSILON = 1e-4 on lengths, FLT_EPSILON on areas, a
# colocal distance of 1.2e-7), so its atlas depends on the model's units: a model 0.0074 across
# lost 576 of 590 triangles (14x14 atlas), one 0.3 across got a 48x45 atlas where the same mesh
# 5 across got 81x84. Measured with xatlas 0.0.11 on five meshes, the atlas is bit-identical
# under power-of-two scaling while the model is roughly 10 to 2,500 across. Models whose extent
# (largest bounding-box side) lies in XATLAS_PLAIN_EXTENTS reach xatlas as before (centred
# only); others are multiplied by the power of two that puts their extent in
# [2^XATLAS_TARGET_EXPONENT, 2^(XATLAS_TARGET_EXPONENT + 1)), the middle of that range.
XATLAS_PLAIN_EXTENTS = (1.0, 4096.0)
XATLAS_TARGET_EXPONENT = 7


def xatlas_version() -> str:
    try:
        from importlib.metadata import version

        return version("xatlas")
    except Exception:  # pragma: no cover - not installed as a distribution
        return "unknown"


def xatlas_scale(extent: float) -> float:
    """The power of two xatlas sees a centred model of this extent (largest bounding-box side)
    multiplied by: 1 inside ``XATLAS_PLAIN_EXTENTS``, else the one that puts the extent in
    ``[2^XATLAS_TARGET_EXPONENT, 2^(XATLAS_TARGET_EXPONENT + 1))``. A power of two is exact in
    float32 and float64, so models that differ by one get exactly the same xatlas input."""
    lo, hi = XATLAS_PLAIN_EXTENTS
    if not (0.0 < extent < math.inf) or lo <= extent <= hi:
        return 1.0
    _, e = math.frexp(extent)  # extent = m 2^e, 0.5 <= m < 1
    return math.ldexp(1.0, XATLAS_TARGET_EXPONENT + 1 - e)


def xatlas_options(cfg: LightmapConfig, scale: float = 1.0) -> dict:
    """xatlas's chart and pack options for a model multiplied by ``scale`` (:func:`xatlas_scale`):
    the options in model units (``texels_per_unit``, ``max_chart_area``) are converted; the rest
    are in texels or have no unit. ``scale = 1`` gives the options unchanged."""
    chart = {"max_cost": float(cfg.max_cost), "normal_deviation_weight": float(cfg.normal_deviation_weight)}
    if cfg.max_chart_area > 0:
        chart["max_chart_area"] = float(cfg.max_chart_area) * scale * scale
    pack = {"resolution": int(cfg.resolution), "padding": int(cfg.padding), "bilinear": True,
            "rotate_charts": bool(cfg.rotate_charts)}
    if cfg.texels_per_unit > 0:
        pack["texels_per_unit"] = float(cfg.texels_per_unit) / scale
    return {"chart": chart, "pack": pack}


def _mesh_for_xatlas(scene: Scene) -> tuple[np.ndarray, np.ndarray, np.ndarray, float]:
    """Used vertices centred on their bounding box (float32 keeps its precision far from the
    origin) and multiplied by :func:`xatlas_scale`, triangle indices into them, the used vertex
    ids and the scale."""
    tris = np.asarray(scene.triangles, dtype=np.int64)
    used = np.unique(tris.ravel())
    remap = np.full(scene.n_vertices, -1, dtype=np.int64)
    remap[used] = np.arange(len(used))
    p = scene.positions[used]
    lo, hi = p.min(axis=0), p.max(axis=0)
    centre = 0.5 * (lo + hi)
    with np.errstate(over="ignore"):
        scale = xatlas_scale(float((hi - lo).max()))
    local = p - centre
    if scale != 1.0:
        local = local * scale  # exact: a power of two
    return local.astype(np.float32), remap[tris].astype(np.uint32), used, scale


def _run_worker(p32: np.ndarray, idx: np.ndarray, options: dict, timeout: float) -> dict:
    """xatlas's output for this input. A crash (the worker killed by a signal) is tried once more:
    xatlas runs its chart work on a thread pool, and one CI run lost a small mesh's lightmap once
    (its cause not recorded; 3,300 runs of that mesh here were clean); a mesh that crashes
    xatlas every time (the icosphere in shared/docs/dependencies.md section 4) crashes in well
    under a second, so the second try costs little. ``retried_after`` in the result names the
    first crash's signal (empty when the first run succeeded)."""
    first = ""
    for attempt in (1, 2):
        proc, data = _run_worker_once(p32, idx, options, timeout)
        if proc.returncode >= 0:
            break
        try:
            sig = signal.Signals(-proc.returncode).name
        except ValueError:
            sig = f"signal {-proc.returncode}"
        if attempt == 1:
            first = sig
            continue
        T = len(idx)
        raise StageError(
            f"lightmap: xatlas crashed ({sig}) on this mesh ({T} triangles), twice; the bake itself "
            "is unharmed. xatlas 0.0.9-0.0.11 crash on some meshes, e.g. a perfectly smooth, "
            "finely subdivided sphere: try mesh.simplify, or change textures.lightmap.resolution, "
            "max_chart_area or max_cost")
    if data is None:
        why = (proc.stderr or "").strip().splitlines()
        raise StageError(f"lightmap: xatlas failed on this mesh ({len(idx)} triangles): "
                         f"{why[-1] if why else f'exit status {proc.returncode}'}")
    data["retried_after"] = np.str_(first)
    return data


def _run_worker_once(p32: np.ndarray, idx: np.ndarray, options: dict, timeout: float):
    """(the finished process, its output arrays or None)."""
    T = len(idx)
    with tempfile.TemporaryDirectory(prefix="bake-xatlas-") as tmp:
        inp, out = Path(tmp) / "in.npz", Path(tmp) / "out.npz"
        np.savez(inp, positions=p32, indices=idx, options=np.str_(json.dumps(options, sort_keys=True)))
        try:
            proc = subprocess.run([*WORKER_COMMAND, str(inp), str(out)], capture_output=True, text=True,
                                  timeout=timeout)
        except subprocess.TimeoutExpired:
            raise StageError(
                f"lightmap: xatlas did not finish within textures.lightmap.timeout = {timeout:g} s on "
                f"{T} triangles and was stopped (xatlas takes 17-26 s per 100k triangles, minutes on "
                "noisy multi-part meshes); simplify the mesh (mesh.simplify) or raise the timeout",
                key="textures.lightmap.timeout") from None
        except OSError as e:
            raise StageError(f"lightmap: cannot start the xatlas worker: {e}") from None
        if proc.returncode != 0 or not out.exists():
            return proc, None
        with np.load(out, allow_pickle=False) as f:
            return proc, {k: f[k] for k in f.files}


def unwrap(scene: Scene, cfg: LightmapConfig, *, cache_dir: Path | None | str = "config") -> Atlas:
    """Lightmap UVs for every triangle of ``scene`` (see :class:`Atlas`).

    xatlas runs in a subprocess (``WORKER_COMMAND``) with ``cfg.timeout``; a crash, a timeout or
    an xatlas error raises :class:`StageError` saying which. Meshes with more than
    ``cfg.max_triangles`` triangles are refused before xatlas starts. ``cache_dir`` overrides
    :func:`unwrap_cache.cache_directory` (``None`` = no cache). The cache key is a hash of exactly
    what xatlas receives (the centred, scaled positions, the indices, the converted options, its
    version).
    """
    T = scene.n_triangles
    if T == 0:
        raise StageError("lightmap: the scene has no triangles to unwrap")
    if T > cfg.max_triangles:
        raise StageError(f"lightmap: {T} triangles is more than textures.lightmap.max_triangles = "
                         f"{cfg.max_triangles} (xatlas takes 17-26 s per 100k triangles); simplify the "
                         "mesh (mesh.simplify) or raise the limit", key="textures.lightmap.max_triangles")
    p32, idx, used, scale = _mesh_for_xatlas(scene)
    options = xatlas_options(cfg, scale)
    version = xatlas_version()
    cdir = unwrap_cache.cache_directory(cfg) if cache_dir == "config" else (Path(cache_dir) if cache_dir else None)
    key = unwrap_cache.cache_key(p32, idx, options, version)
    cpath = unwrap_cache.entry_path(cdir, key)
    data = unwrap_cache.load(cpath)  # the atlas these options came to, after every run it took
    if data is not None:
        return _atlas_from(data, scene, used, key, True, version, scale)
    want = int(cfg.resolution)
    best = None
    retried = ""
    tried: list[tuple[int, int]] = []  # (resolution asked, atlas side)
    for _ in range(_FIT_RUNS):
        data = _run_worker(p32, idx, options, cfg.timeout)
        retried = retried or str(data.get("retried_after", ""))
        side = max(int(data["width"]), int(data["height"]))
        asked = int(options["pack"]["resolution"])
        tried.append((asked, side))
        # the largest atlas that fits, else the smallest one
        rank = (side <= want, side if side <= want else -side)
        if best is None or rank > best[1]:
            best = (data, rank)
        # xatlas sizes the charts for the resolution asked, then grows the atlas where they and
        # their padding do not fit (25-60%; padding around many small charts is a floor): ask for
        # less, where a line through the tries says the atlas fits; once one fits, ask between it
        # and the least that did not, until the atlas is within _FIT_CLOSE of the side wanted
        if cfg.texels_per_unit > 0 or (side <= want and side >= _FIT_CLOSE * want) or asked <= _FIT_LEAST:
            break
        nxt = _next_resolution(tried, want)
        if nxt is None:
            break
        options = json.loads(json.dumps(options))
        options["pack"]["resolution"] = nxt
    data = best[0]
    if retried:
        data["retried_after"] = np.str_(retried)  # (a crash in any of the runs is named)
    unwrap_cache.store(cpath, data)
    return _atlas_from(data, scene, used, key, False, version, scale)


# unwrap: runs of xatlas with a smaller resolution asked, until the atlas fits the one wanted; how
# far below the size that should fit the next one asks, and the least resolution asked
_FIT_RUNS = 5
_FIT_MARGIN = 0.97
_FIT_LEAST = 8
_FIT_CLOSE = 0.95


def _next_resolution(tried: list[tuple[int, int]], want: int) -> int | None:
    """The resolution to ask xatlas for next so its atlas fits ``want`` as closely as it can
    (``tried``: (asked, atlas side) so far). Before any fits: proportional after one try, then
    along the line through the last two (the atlas grows by a floor of padding plus a share of
    what is asked). Once one fits: along the line between the largest that fit and the least
    asked that did not, strictly between them. None when there is nothing new to ask."""
    fits = [t for t in tried if t[1] <= want]
    over = [t for t in tried if t[1] > want]
    if fits:
        a0, s0 = max(fits)
        above = [t for t in over if t[0] > a0]
        if not above:
            return None  # (nothing above the fit was asked: it was the side wanted, or more)
        a1, s1 = min(above)
        guess = a0 + (want - s0) * (a1 - a0) / max(s1 - s0, 1)
        nxt = min(int(guess), a1 - 1)
        return nxt if nxt > a0 and all(a != nxt for a, _ in tried) else None
    (a1, s1) = tried[-1]
    if len(tried) >= 2 and tried[-2][0] != a1 and tried[-2][1] != s1:
        a0, s0 = tried[-2]
        slope = (s1 - s0) / (a1 - a0)
        guess = a1 + (want - s1) / slope if slope > 0 else a1 * want / s1
    else:
        guess = a1 * want / s1
    nxt = max(_FIT_LEAST, int(guess * _FIT_MARGIN))
    return None if nxt >= a1 or any(a == nxt for a, _ in tried) else nxt


def _atlas_from(data: dict, scene: Scene, used: np.ndarray, key: str, cached: bool, version: str,
                scale: float = 1.0) -> Atlas:
    T = scene.n_triangles
    out_idx = np.asarray(data["indices"], dtype=np.int64).reshape(-1, 3)
    vmap = np.asarray(data["vmapping"], dtype=np.int64)
    if len(out_idx) != T or not np.array_equal(used[vmap[out_idx]], scene.triangles):
        raise StageError("lightmap: xatlas returned triangles that do not match the input "
                         f"({len(out_idx)} for {T}); cannot use this atlas")
    if int(data["atlas_count"]) != 1:
        raise StageError(f"lightmap: xatlas made {int(data['atlas_count'])} atlases; set "
                         "textures.lightmap.texels_per_unit = 0 (or lower) so one atlas holds every chart",
                         key="textures.lightmap.texels_per_unit")
    W, H = int(data["width"]), int(data["height"])
    uv = np.asarray(data["uvs"], dtype=np.float64)[out_idx]  # xatlas: x right, y down, / (W, H)
    tri_uvs = np.stack([uv[..., 0], 1.0 - uv[..., 1]], axis=-1)
    xy = uv * np.array([W, H], dtype=np.float64)
    area2 = cross2(xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0])
    mapped = np.abs(area2) > 1e-9  # xatlas gives ignored (degenerate) faces all-zero UVs
    # charts: triangles connected through xatlas's output vertices (a seam duplicates vertices)
    nv = len(vmap)
    rows = np.repeat(np.arange(T), 3)
    g = sparse.coo_matrix((np.ones(3 * T), (rows, T + out_idx.ravel())), shape=(T + nv, T + nv))
    _, labels = csgraph.connected_components(g, directed=False)
    lab = labels[:T]
    _, first = np.unique(lab, return_index=True)
    order = np.argsort(first)  # chart ids in order of first triangle
    rank = np.empty(len(first), dtype=np.int64)
    rank[order] = np.arange(len(first))
    chart = rank[np.searchsorted(np.unique(lab), lab)]
    chart = np.where(mapped, chart, -1)
    util = np.asarray(data["utilization"], dtype=np.float64).ravel()
    return Atlas(width=W, height=H, tri_uvs=tri_uvs, chart=chart.astype(np.int64), key=key,
                 chart_count=int(data["chart_count"]), utilization=float(util[0]) if len(util) else 0.0,
                 texels_per_unit=float(data["texels_per_unit"]) * scale, seconds=float(data["seconds"]),
                 cached=cached, xatlas_version=version, xatlas_scale=scale,
                 retried_after=str(data.get("retried_after", "")))
