"""Lightmaps: the xatlas unwrap and the texel machinery a light baker fills.

Pieces, in the order a bake uses them:

* :func:`unwrap` -> :class:`Atlas`: xatlas charts and packs the mesh (in a subprocess with a
  timeout, ``xatlas_worker.py``; the result is cached by a hash of the exact input and options,
  so a rerun is fast and gives identical UVs; the default cache is ``.bake-cache/xatlas`` in the
  output folder). xatlas's tolerances are absolute, so it sees the mesh centred and, when it is
  not of a size xatlas handles well, multiplied by a power of two (:func:`xatlas_scale`); the
  options in model units are converted to match, so a model in millimetres or kilometres gets
  about the atlas it gets in metres. Per-corner lightmap UVs use the same convention
  as ``tri_uvs``: ``(0, 0)`` is the bottom-left of the image, ``v`` grows upward; the image is
  ``(H, W, C)`` with row 0 at the top, so texel ``(row i, column j)`` covers
  ``x = u * W`` in ``[j, j + 1)`` and ``y = (1 - v) * H`` in ``[i, i + 1)``.
* :func:`cover`: every (triangle, texel) pair whose areas overlap (conservative rasterisation,
  vectorised: the texels of each triangle's bounding box, kept by the separating-axis test).
* :func:`texel_samples`: ``supersample^2`` sub-texel points per pair that fall inside the
  triangle (weight ``1 / s^2`` each), and for a pair with none of them inside (the triangle only
  grazes the texel) one point at the texel centre clamped onto the triangle (weight
  ``EDGE_WEIGHT``, so it only counts where nothing better covers the texel). Each sample has a
  world position (float64), the geometric normal and the triangle id. :func:`push_out` then moves
  samples that start inside or behind geometry (a tangent ray hits a back face within one texel)
  to just in front of the face they hit.
* :func:`splat`: the weighted mean of the sample values per texel; :func:`dilate` fills ``px``
  rings of padding around the covered texels (mean of covered neighbours), so bilinear lookups
  near chart borders read sensible values.
* :func:`seam_edges` / :func:`stitch_seams`: UV seams (an edge shared by two triangles whose
  lightmap UVs differ) on smooth geometry (dihedral angle <= ``SEAM_MAX_ANGLE``) are sampled on
  both sides, and a sparse least-squares solve moves the texels under those samples so that
  bilinear lookups agree across the seam while staying close to their values.
  :func:`seam_error` measures what is left.
* :func:`bake`: all of the above for a shading function ``f(points, normals, tri_ids) -> (N, C)``.

The light baker supplies the shading function: ``bake.lighting.lightmap.light_function`` builds
one from the lighting stage's own kernels (lights, sky, AO, a final gather of bounced light), and
``lighting.target = "lightmap"`` runs it over the atlas this module unwraps.
"""

from __future__ import annotations

import hashlib
import io
import json
import math
import signal
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable, Iterator

import numpy as np
from scipy import sparse
from scipy.sparse import csgraph
from scipy.sparse import linalg as sparse_linalg

from ..config import LightmapConfig
from ..errors import ConfigError, StageError
from ..files import write_atomic
from ..scene import Scene

WORKER = Path(__file__).with_name("xatlas_worker.py")
# How the worker is started (tests replace it to check crash and timeout handling).
WORKER_COMMAND: list[str] = [sys.executable, str(WORKER)]
CACHE_FORMAT = "scratch-bake xatlas cache 2"  # 2: the atlas after the runs that fit the resolution
CACHE_SUBDIR = Path(".bake-cache") / "xatlas"  # the default cache, inside the output folder

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

EDGE_WEIGHT = 1e-3  # weight of a clamped sample (a triangle that only grazes the texel)
PAIRS_PER_CHUNK = 1 << 19  # bounds the temporary arrays of the rasteriser
PUSH_DIRECTIONS = 8  # tangent rays per sample for push_out
PUSH_RADIUS = 1.0  # push_out ray length, in texels (world size of one texel of the triangle)
SEAM_MAX_ANGLE = 30.0  # degrees: UV seams across sharper creases are left alone
SEAM_WEIGHT = 8.0  # least-squares weight of a seam sample against a texel's own value
PAD_WEIGHT = 0.05  # ... and of a padding texel (its value only matters for filtering)


# --------------------------------------------------------------------------------------------
# the atlas


@dataclass(frozen=True)
class Atlas:
    """An xatlas unwrap of a scene's triangles (in the scene's triangle order)."""

    width: int
    height: int
    tri_uvs: np.ndarray  # (T, 3, 2) float64 lightmap UVs per corner (v up, in [0, 1])
    chart: np.ndarray  # (T,) int64 chart id (triangles joined in the UV layout), -1 = not mapped
    key: str  # hash of xatlas's exact input and options (the cache key)
    chart_count: int = 0
    utilization: float = 0.0  # xatlas: fraction of the atlas covered by charts
    texels_per_unit: float = 0.0  # texels per model unit
    seconds: float = 0.0  # xatlas time when it ran (also kept for a cache hit)
    cached: bool = False
    xatlas_version: str = ""
    xatlas_scale: float = 1.0  # the power of two xatlas saw the (centred) model multiplied by
    retried_after: str = ""  # the signal of a first crashed xatlas run that a second run replaced

    @property
    def n_triangles(self) -> int:
        return int(len(self.tri_uvs))

    @property
    def mapped(self) -> np.ndarray:
        return self.chart >= 0

    def texel_xy(self) -> np.ndarray:
        """(T, 3, 2) corners in texel space: x = u W (right), y = (1 - v) H (down)."""
        xy = np.empty_like(self.tri_uvs)
        xy[..., 0] = self.tri_uvs[..., 0] * self.width
        xy[..., 1] = (1.0 - self.tri_uvs[..., 1]) * self.height
        return xy


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


def cache_directory(cfg: LightmapConfig) -> Path | None:
    """Where atlases are cached: ``cache_dir`` when it is a path (a cache shared between bakes,
    the user's choice), else ``.bake-cache/xatlas`` in the output folder (``cfg.out_dir``, set
    by ``bake run``; without an output folder there is no cache); ``"none"`` turns it off."""
    if cfg.cache_dir.strip().lower() == "none":
        return None
    if cfg.cache_dir:
        return Path(cfg.cache_dir).expanduser()
    return None if cfg.out_dir is None else Path(cfg.out_dir) / CACHE_SUBDIR


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


_CACHE_KEYS = ("vmapping", "indices", "uvs", "width", "height", "atlas_count", "chart_count",
               "utilization", "texels_per_unit", "seconds")


def _cache_load(path: Path | None) -> dict | None:
    if path is None or not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as f:
            if str(f["format"]) != CACHE_FORMAT:
                return None
            return {k: f[k] for k in _CACHE_KEYS}
    except Exception:  # a damaged cache entry is recomputed
        return None


def _cache_store(path: Path | None, data: dict) -> None:
    """Written like every output (``bake.files.write_atomic``: a flushed temporary beside
    the entry, then a rename; the usual file mode; a temporary left by a killed bake is removed
    by the next bake into that folder), so a reader never sees half an entry."""
    if path is None:
        return
    buf = io.BytesIO()
    np.savez(buf, format=np.str_(CACHE_FORMAT), **{k: data[k] for k in _CACHE_KEYS})
    try:
        write_atomic(path, buf.getvalue())
    except OSError:
        pass  # a read-only cache directory only costs speed


def unwrap(scene: Scene, cfg: LightmapConfig, *, cache_dir: Path | None | str = "config") -> Atlas:
    """Lightmap UVs for every triangle of ``scene`` (see :class:`Atlas`).

    xatlas runs in a subprocess (``WORKER_COMMAND``) with ``cfg.timeout``; a crash, a timeout or
    an xatlas error raises :class:`StageError` saying which. Meshes with more than
    ``cfg.max_triangles`` triangles are refused before xatlas starts. ``cache_dir`` overrides
    :func:`cache_directory` (``None`` = no cache). The cache key is a hash of exactly what xatlas
    receives (the centred, scaled positions, the indices, the converted options, its version).
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
    cdir = cache_directory(cfg) if cache_dir == "config" else (Path(cache_dir) if cache_dir else None)
    key = _cache_key(p32, idx, options, version)
    cpath = None if cdir is None else cdir / key[:2] / f"{key}.npz"
    data = _cache_load(cpath)  # the atlas these options came to, after every run it took
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
    _cache_store(cpath, data)
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


def _cache_key(p32: np.ndarray, idx: np.ndarray, options: dict, version: str) -> str:
    """The cache key of an unwrap: exactly what xatlas is first handed (the format, its version,
    the options, the positions and indices)."""
    h = hashlib.sha256()
    for part in (CACHE_FORMAT, version, json.dumps(options, sort_keys=True)):
        h.update(part.encode() + b"\0")
    h.update(np.ascontiguousarray(p32).tobytes())
    h.update(np.ascontiguousarray(idx).tobytes())
    return h.hexdigest()


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
    area2 = _cross2(xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0])
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


# --------------------------------------------------------------------------------------------
# memory: estimated from the atlas before any texel work, against what this process may still use

# Peak memory growth of a lightmap bake, measured with /usr/bin/time and /proc/self/status on the
# corpus Suzanne (968 triangles, sun + AO 32..1024 samples, 0.2 to 3.2 million texel samples,
# supersample 1, 2 and 4): 615-775 bytes per texel sample (ray batches are chunked, so the ray
# counts do not matter), plus per-texel images (splat, mask, dilation, seams) and the texel
# covering of the textures stage.
BYTES_PER_SAMPLE = 720
BYTES_PER_TEXEL = 128
BYTES_FIXED = 64 << 20
# Address space (ulimit -v) the lighting stage takes beyond the memory it touches: thread stacks,
# malloc arenas, Embree's reservations (measured 250-400 MiB on 2 cores: VmPeak against VmHWM).
ADDRESS_SPACE_EXTRA = 400 << 20
# Texels covered by triangles per texel of xatlas's utilisation: 0.50-0.89 on six corpus models.
COVERED_PER_UTILISED = 0.9


def estimate_samples(width: int, height: int, utilization: float, supersample: int) -> int:
    """Texel samples of a lightmap bake: the texels covered (xatlas's utilisation, the charts'
    share of the atlas, x COVERED_PER_UTILISED) x supersample^2, plus clamped samples where a
    triangle only grazes a texel (measured: 1.15, 3.9 and 15.4 samples per covered texel at
    supersample 1, 2 and 4)."""
    covered = COVERED_PER_UTILISED * max(0.0, min(1.0, float(utilization) or 1.0)) * width * height
    return int(math.ceil(covered * (supersample * supersample + 0.2)))


def estimate_memory(width: int, height: int, utilization: float, supersample: int, *, lit: bool = True) -> int:
    """Bytes a lightmap of this atlas needs beyond what the process already uses: the texel
    covering alone, or (``lit``: ``lighting.target = "lightmap"``) the whole texel bake."""
    texels = width * height
    if not lit:
        return BYTES_FIXED + 48 * int(max(0.0, min(1.0, utilization or 1.0)) * texels)
    return BYTES_FIXED + BYTES_PER_TEXEL * texels + BYTES_PER_SAMPLE * estimate_samples(
        width, height, utilization, supersample)


def _proc_kib(field: str, path: str = "/proc/self/status") -> int | None:
    try:
        with open(path, encoding="ascii") as f:
            for line in f:
                if line.startswith(field + ":"):
                    return int(line.split()[1]) * 1024
    except (OSError, ValueError, IndexError):
        return None
    return None


def _cgroup_room() -> int | None:
    """Bytes left under this process's cgroup v2 memory.max (None: no limit or not readable)."""
    try:
        with open("/proc/self/cgroup", encoding="utf-8") as f:
            rel = next((ln.split("::", 1)[1].strip() for ln in f if ln.startswith("0::")), None)
        if rel is None:
            return None
        base = Path("/sys/fs/cgroup") / rel.lstrip("/")
        limit = (base / "memory.max").read_text().strip()
        if limit == "max":
            return None
        return int(limit) - int((base / "memory.current").read_text().strip())
    except (OSError, ValueError, StopIteration):
        return None


def available_memory() -> tuple[int, str, bool] | None:
    """(bytes this process may still allocate, what limits it, whether it is address space), the
    tightest of: the address-space limit (``ulimit -v``, ``prlimit --as``) less the address space
    in use, the cgroup's memory.max less its usage, and the system's MemAvailable. None if
    nothing can be read (not Linux)."""
    out: list[tuple[int, str, bool]] = []
    try:
        import resource

        soft, _ = resource.getrlimit(resource.RLIMIT_AS)
        if soft != resource.RLIM_INFINITY:
            used = _proc_kib("VmSize") or 0
            out.append((soft - used, "the address-space limit (ulimit -v)", True))
    except (ImportError, OSError, ValueError):
        pass
    room = _cgroup_room()
    if room is not None:
        out.append((room, "the memory limit of this process's cgroup", False))
    avail = _proc_kib("MemAvailable", "/proc/meminfo")
    if avail is not None:
        out.append((avail, "the memory the system has available", False))
    if not out:
        return None
    return min(out, key=lambda c: c[0] - (ADDRESS_SPACE_EXTRA if c[2] else 0))


def _gib(n: float) -> str:
    return f"{n / (1 << 30):.2f} GiB" if n >= (1 << 30) else f"{n / (1 << 20):.0f} MiB"


def check_memory(atlas: "Atlas", cfg: LightmapConfig, *, lit: bool = True,
                 available: tuple[int, str, bool] | None | str = "measure") -> dict:
    """Refuse, before any texel work, an atlas whose bake would not fit in memory: a
    :class:`ConfigError` naming ``textures.lightmap.resolution`` (or ``texels_per_unit`` when that
    sets the size) with the largest resolution that fits. Returns the figures (estimate, room) for
    the record; ``warn`` in them when the estimate passes half the room."""
    need = estimate_memory(atlas.width, atlas.height, atlas.utilization, cfg.supersample, lit=lit)
    room = available_memory() if available == "measure" else available
    figs: dict = {"memory_estimate_bytes": int(need)}
    if room is None:
        return figs
    free, what, address_space = room
    usable = free - (ADDRESS_SPACE_EXTRA if address_space and lit else 0)
    figs.update({"memory_available_bytes": int(free), "memory_limited_by": what})
    key = "textures.lightmap.texels_per_unit" if cfg.texels_per_unit > 0 else "textures.lightmap.resolution"
    if need > usable:
        # the largest resolution (a multiple of 16) that fits: the atlas's texels grow as the
        # resolution squared, times xatlas's growth past the request (up to 1.14 measured, more
        # at small sizes: assume at least 1.2 so the advice passes this check when followed)
        growth = max(max(atlas.width, atlas.height) / max(cfg.resolution, 1), 1.2)
        per_texel = (need - BYTES_FIXED) / max(atlas.width * atlas.height, 1)
        fit = int(math.sqrt(max(usable - BYTES_FIXED, 0) / per_texel) / growth) // 16 * 16
        advice = (f"use {key.rsplit('.', 1)[1]} <= {fit}" if fit >= 16 and key.endswith("resolution") else
                  "lower textures.lightmap.texels_per_unit" if key.endswith("texels_per_unit") else
                  "bake without a lightmap (lighting.target = \"triangle\")")
        sup = f", supersample {cfg.supersample}" if lit else ""
        raise ConfigError(f"a {atlas.width}x{atlas.height} lightmap{sup} needs about {_gib(need)} "
                          f"{'to bake' if lit else 'to lay out'}, more than the {_gib(max(usable, 0))} left "
                          f"under {what}; {advice}"
                          + (" or lower textures.lightmap.supersample" if lit and cfg.supersample > 1 else ""),
                          key=key)
    if need > usable / 2:
        figs["warn"] = (f"the {atlas.width}x{atlas.height} lightmap needs about {_gib(need)} of the "
                        f"{_gib(usable)} left under {what} ({key} = "
                        f"{cfg.texels_per_unit if key.endswith('unit') else cfg.resolution})")
    return figs


# --------------------------------------------------------------------------------------------
# conservative rasterisation


def _cross2(a: np.ndarray, b: np.ndarray) -> np.ndarray:
    return a[..., 0] * b[..., 1] - a[..., 1] * b[..., 0]


def _box_texels(lo: np.ndarray, hi: np.ndarray, W: int) -> Iterator[tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Every texel of each box ``lo..hi`` (inclusive, (n, 2) ints): yields (owner, tx, ty) in
    chunks of about PAIRS_PER_CHUNK."""
    nx = hi[:, 0] - lo[:, 0] + 1
    ny = hi[:, 1] - lo[:, 1] + 1
    count = nx * ny
    ends = np.cumsum(count)
    chunk = (ends - count) // PAIRS_PER_CHUNK
    bounds = [0, *(np.flatnonzero(np.diff(chunk)) + 1).tolist(), len(count)]
    for b0, b1 in zip(bounds[:-1], bounds[1:]):
        if b1 <= b0:
            continue
        c = count[b0:b1]
        owner = np.repeat(np.arange(b0, b1), c)
        k = np.arange(len(owner)) - np.repeat(np.cumsum(c) - c, c)
        yield owner, lo[owner, 0] + k % nx[owner], lo[owner, 1] + k // nx[owner]


def cover(atlas: Atlas) -> tuple[np.ndarray, np.ndarray]:
    """(triangle ids, texel ids) of every pair whose triangle and texel square overlap with
    positive area (texel id = row * W + column). Sorted by triangle, then texel."""
    W, H = atlas.width, atlas.height
    xy = atlas.texel_xy()
    tids = np.flatnonzero(atlas.mapped)
    pts = xy[tids]
    lo = np.floor(pts.min(axis=1)).astype(np.int64)
    hi = np.ceil(pts.max(axis=1)).astype(np.int64) - 1
    hi = np.maximum(hi, lo)
    lo = np.clip(lo, 0, [W - 1, H - 1])
    hi = np.clip(hi, 0, [W - 1, H - 1])
    sgn = np.sign(_cross2(pts[:, 1] - pts[:, 0], pts[:, 2] - pts[:, 0]))
    out_t, out_x = [], []
    for owner, tx, ty in _box_texels(lo, hi, W):
        keep = np.ones(len(owner), dtype=bool)
        cx, cy = tx + 0.5, ty + 0.5
        p = pts[owner]
        s = sgn[owner]
        for k in range(3):  # the triangle's three edges
            a, b = p[:, k], p[:, (k + 1) % 3]
            dx, dy = b[:, 0] - a[:, 0], b[:, 1] - a[:, 1]
            f = dx * (cy - a[:, 1]) - dy * (cx - a[:, 0])
            reach = 0.5 * (np.abs(dx) + np.abs(dy))
            keep &= s * f + reach > 1e-9 * (np.abs(dx) + np.abs(dy))
        out_t.append(tids[owner[keep]])
        out_x.append(ty[keep] * W + tx[keep])
    if not out_t:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    return np.concatenate(out_t), np.concatenate(out_x)


# --------------------------------------------------------------------------------------------
# texel samples


@dataclass
class TexelSamples:
    """Sample points of the lightmap's texels. Unpacks as
    ``points, normals, tri_ids, texel_index, weights = texel_samples(...)``."""

    points: np.ndarray  # (N, 3) float64 world positions
    normals: np.ndarray  # (N, 3) unit geometric normals of the triangles
    tri_ids: np.ndarray  # (N,) int64
    texel_index: np.ndarray  # (N,) int64, row * W + column
    weights: np.ndarray  # (N,) float64: 1/s^2 inside the triangle, EDGE_WEIGHT for a clamped point
    inside: np.ndarray = field(default=None)  # (N,) bool: a sub-texel point inside the triangle
    pushed: np.ndarray = field(default=None)  # (N,) bool: moved by push_out
    texel_size: np.ndarray = field(default=None)  # (T,) world length of one texel per triangle

    def __iter__(self) -> Iterator[np.ndarray]:
        return iter((self.points, self.normals, self.tri_ids, self.texel_index, self.weights))

    def __len__(self) -> int:
        return int(len(self.points))


def face_normals(positions: np.ndarray, triangles: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(unit normals (T, 3), areas (T,)); a degenerate triangle gets normal 0."""
    p = positions[triangles]
    cr = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    ln = np.linalg.norm(cr, axis=1)
    n = np.divide(cr, ln[:, None], out=np.zeros_like(cr), where=ln[:, None] > 0)
    return n, 0.5 * ln


def texel_world_size(scene: Scene, atlas: Atlas) -> np.ndarray:
    """(T,) world length of one texel on each triangle: sqrt(world area / texel area)."""
    _, area = face_normals(scene.positions, scene.triangles)
    xy = atlas.texel_xy()
    ta = 0.5 * np.abs(_cross2(xy[:, 1] - xy[:, 0], xy[:, 2] - xy[:, 0]))
    return np.sqrt(np.divide(area, ta, out=np.zeros_like(area), where=ta > 0))


def _closest_on_triangle(p: np.ndarray, tri: np.ndarray) -> np.ndarray:
    """Barycentrics (n, 3) of the point of each 2-D triangle (n, 3, 2) closest to p (n, 2), for
    points outside the triangle (the closest point is then on an edge)."""
    best_d = np.full(len(p), np.inf)
    bary = np.zeros((len(p), 3))
    for k in range(3):  # edges
        a, b = tri[:, k], tri[:, (k + 1) % 3]
        e = b - a
        ee = np.einsum("ij,ij->i", e, e)
        t = np.clip(np.einsum("ij,ij->i", p - a, e) / np.where(ee > 0, ee, 1.0), 0.0, 1.0)
        q = a + t[:, None] * e
        d = np.einsum("ij,ij->i", p - q, p - q)
        better = d < best_d
        best_d = np.where(better, d, best_d)
        nb = np.zeros((len(p), 3))
        nb[np.arange(len(p)), k] = 1.0 - t
        nb[np.arange(len(p)), (k + 1) % 3] += t
        bary = np.where(better[:, None], nb, bary)
    return bary


def texel_samples(scene: Scene, atlas: Atlas, *, supersample: int = 2, push: bool = False,
                  tracer=None) -> TexelSamples:
    """The sample points of every covered texel (see the module docstring).

    ``push=True`` runs :func:`push_out` with ``tracer`` (the lighting stage's Embree
    :class:`bake.lighting.rays.Tracer`, which the caller builds: this module does not trace rays).
    """
    s = int(supersample)
    if s < 1:
        raise ValueError(f"supersample must be >= 1, got {supersample}")
    if atlas.n_triangles != scene.n_triangles:
        raise ValueError(f"atlas has {atlas.n_triangles} triangles, the scene {scene.n_triangles}")
    W = atlas.width
    xy = atlas.texel_xy()
    tri_pos = scene.positions[scene.triangles]
    fn, _ = face_normals(scene.positions, scene.triangles)
    pair_t, pair_x = cover(atlas)
    off = (np.arange(s) + 0.5) / s
    sub = np.stack(np.meshgrid(off, off, indexing="xy"), axis=-1).reshape(-1, 2)  # (s*s, 2) x, y
    parts = []
    step = max(1, PAIRS_PER_CHUNK // (s * s))
    for c0 in range(0, len(pair_t), step):  # chunks bound the (pairs x s^2) temporaries
        t = pair_t[c0:c0 + step]
        x = pair_x[c0:c0 + step]
        tri = xy[t]  # (n, 3, 2)
        corner = np.stack([x % W, x // W], axis=1).astype(np.float64)
        p = corner[:, None, :] + sub[None, :, :]  # (n, s*s, 2)
        a, b, c = tri[:, 0, None], tri[:, 1, None], tri[:, 2, None]
        area2 = _cross2(b - a, c - a)  # (n, 1)
        wa = _cross2(c - b, p - b) / area2
        wb = _cross2(a - c, p - c) / area2
        wc = 1.0 - wa - wb
        bary = np.stack([wa, wb, wc], axis=-1)  # (n, s*s, 3)
        ins = (bary >= -1e-9).all(axis=-1)
        pi, si = np.nonzero(ins)
        bi = np.clip(bary[pi, si], 0.0, 1.0)
        bi /= bi.sum(axis=1, keepdims=True)
        none = ~ins.any(axis=1)
        ei = np.flatnonzero(none)
        be = _closest_on_triangle(corner[ei] + 0.5, tri[ei])
        idx = np.concatenate([pi, ei])
        bar = np.concatenate([bi, be])
        order = np.argsort(idx, kind="stable")  # keep pair order: deterministic, texel-local
        idx, bar = idx[order], bar[order]
        inside = np.concatenate([np.ones(len(pi), bool), np.zeros(len(ei), bool)])[order]
        tt = t[idx]
        pts = np.einsum("nk,nkd->nd", bar, tri_pos[tt])
        parts.append((pts, tt, x[idx], inside))
    if parts:
        points = np.concatenate([q[0] for q in parts])
        tri_ids = np.concatenate([q[1] for q in parts])
        texel = np.concatenate([q[2] for q in parts])
        inside = np.concatenate([q[3] for q in parts])
    else:
        points, tri_ids, texel, inside = np.zeros((0, 3)), np.zeros(0, np.int64), np.zeros(0, np.int64), \
            np.zeros(0, bool)
    weights = np.where(inside, 1.0 / (s * s), EDGE_WEIGHT)
    out = TexelSamples(points=points, normals=fn[tri_ids], tri_ids=tri_ids.astype(np.int64),
                       texel_index=texel.astype(np.int64), weights=weights, inside=inside,
                       pushed=np.zeros(len(points), bool), texel_size=texel_world_size(scene, atlas))
    if push and len(out):
        if tracer is None:
            raise ValueError("push=True needs a ray tracer (bake.lighting.rays.Tracer)")
        out.points, out.pushed = push_out(out.points, out.normals, out.texel_size[out.tri_ids], tracer)
    return out


def tangent_frames(normals: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two unit tangents per unit normal (deterministic)."""
    n = np.asarray(normals, dtype=np.float64)
    helper = np.where((np.abs(n[:, 0]) < 0.9)[:, None], [[1.0, 0.0, 0.0]], [[0.0, 1.0, 0.0]])
    t = np.cross(n, helper)
    ln = np.linalg.norm(t, axis=1)
    t = np.divide(t, ln[:, None], out=np.tile([[1.0, 0.0, 0.0]], (len(n), 1)), where=ln[:, None] > 0)
    return t, np.cross(n, t)


def push_out(points: np.ndarray, normals: np.ndarray, radius: np.ndarray, tracer, *,
             passes: int = 2) -> tuple[np.ndarray, np.ndarray]:
    """Move samples that start inside or behind geometry to the free side.

    From each point (lifted off its surface by the tracer's epsilon) ``PUSH_DIRECTIONS`` rays go
    out in the tangent plane, ``PUSH_RADIUS x radius`` long (``radius``: the world size of the
    sample's texel). If the closest hit of any of them is a **back** face, the point is inside a
    closed object or behind a one-sided wall: it moves to the nearest such hit, then out along the
    hit face's normal by ``max(1e-3 x radius, 4 x epsilon)``. ``passes`` repeats the test on moved
    points (a corner can need two moves). Returns (new points, moved mask).
    """
    pts = np.array(points, dtype=np.float64)
    nrm = np.asarray(normals, dtype=np.float64)
    rad = np.asarray(radius, dtype=np.float64) * PUSH_RADIUS
    moved = np.zeros(len(pts), dtype=bool)
    todo = np.flatnonzero(rad > 0)
    angles = 2.0 * np.pi * (np.arange(PUSH_DIRECTIONS) + 0.5) / PUSH_DIRECTIONS
    cs, sn = np.cos(angles), np.sin(angles)
    K = PUSH_DIRECTIONS
    for _ in range(max(1, passes)):
        if len(todo) == 0:
            break
        t1, t2 = tangent_frames(nrm[todo])
        o = tracer.origins(pts[todo], nrm[todo]).astype(np.float64)  # local frame
        d = cs[None, :, None] * t1[:, None, :] + sn[None, :, None] * t2[:, None, :]  # (n, K, 3)
        n = len(todo)
        best_t = np.full(n, np.inf)
        best_k = np.zeros(n, np.int64)
        best_ng = np.zeros((n, 3))

        def work(i0: int, i1: int) -> None:  # fixed chunks: results do not depend on threads
            hit = tracer.intersect(np.repeat(o[i0:i1], K, axis=0).astype(np.float32),
                                   d[i0:i1].reshape(-1, 3).astype(np.float32),
                                   np.repeat(rad[todo[i0:i1]], K).astype(np.float32))
            prim = np.asarray(hit["prim"]).reshape(-1, K)
            ng = np.asarray(hit["Ng"], dtype=np.float64).reshape(-1, K, 3)
            tt = np.asarray(hit["t"], dtype=np.float64).reshape(-1, K)
            back = (prim >= 0) & (np.einsum("nkd,nkd->nk", ng, d[i0:i1]) > 0) & np.isfinite(tt)
            tt = np.where(back, tt, np.inf)
            k = np.argmin(tt, axis=1)
            r = np.arange(i1 - i0)
            best_t[i0:i1] = tt[r, k]
            best_k[i0:i1] = k
            best_ng[i0:i1] = ng[r, k]

        tracer.parallel(n, 1 << 14, work)
        rows = np.flatnonzero(np.isfinite(best_t))
        if len(rows) == 0:
            break
        ng_hit = best_ng[rows]
        ng_hit /= np.maximum(np.linalg.norm(ng_hit, axis=1), 1e-300)[:, None]
        local = o[rows] + d[rows, best_k[rows]] * best_t[rows][:, None]
        eps = tracer.epsilon(local)
        lift = np.maximum(1e-3 * rad[todo[rows]], 4.0 * eps)
        ids = todo[rows]
        pts[ids] = local + ng_hit * lift[:, None] + tracer.center
        moved[ids] = True
        todo = ids
    return pts, moved


# --------------------------------------------------------------------------------------------
# splat, dilate, lookups


def splat(values: np.ndarray, texel_index: np.ndarray, weights: np.ndarray, atlas: Atlas) -> np.ndarray:
    """(H, W, C) weighted mean of ``values`` ((N,) or (N, C)) per texel; 0 where no sample."""
    v = np.asarray(values, dtype=np.float64)
    one = v.ndim == 1
    v = v.reshape(len(v), -1)
    n = atlas.width * atlas.height
    w = np.asarray(weights, dtype=np.float64)
    tot = np.bincount(texel_index, weights=w, minlength=n)
    out = np.zeros((n, v.shape[1]))
    for c in range(v.shape[1]):  # channels
        out[:, c] = np.bincount(texel_index, weights=w * v[:, c], minlength=n)
    out = np.divide(out, tot[:, None], out=np.zeros_like(out), where=tot[:, None] > 0)
    out = out.reshape(atlas.height, atlas.width, -1)
    return out[:, :, 0] if one else out


def texel_mask(texel_index: np.ndarray, weights: np.ndarray, atlas: Atlas) -> np.ndarray:
    """(H, W) bool: texels with at least one sample of positive weight."""
    n = atlas.width * atlas.height
    tot = np.bincount(texel_index, weights=np.asarray(weights, np.float64), minlength=n)
    return (tot > 0).reshape(atlas.height, atlas.width)


def dilate(image: np.ndarray, mask: np.ndarray, px: int) -> tuple[np.ndarray, np.ndarray]:
    """Fill ``px`` rings of texels around ``mask``: each ring takes the mean of its filled
    8-neighbours. Returns (image, new mask); filled texels keep their values."""
    img = np.array(image, dtype=np.float64)
    one = img.ndim == 2
    if one:
        img = img[:, :, None]
    m = np.asarray(mask, dtype=bool).copy()
    H, W = m.shape
    for _ in range(max(0, int(px))):
        if m.all() or not m.any():
            break
        vp = np.pad(img * m[:, :, None], ((1, 1), (1, 1), (0, 0)))
        mp = np.pad(m, 1).astype(np.float64)
        acc = np.zeros_like(img)
        cnt = np.zeros((H, W))
        for dy in (-1, 0, 1):
            for dx in (-1, 0, 1):
                if dy == 0 and dx == 0:
                    continue
                acc += vp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
                cnt += mp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]
        grow = ~m & (cnt > 0)
        img[grow] = acc[grow] / cnt[grow][:, None]
        m = m | grow
    return (img[:, :, 0] if one else img), m


def bilinear_stencil(xy: np.ndarray, W: int, H: int) -> tuple[np.ndarray, np.ndarray]:
    """Texel ids (n, 4) and weights (n, 4) of a bilinear lookup at texel-space points (n, 2)
    (texel centres at half-integers, clamped at the image border)."""
    x = xy[:, 0] - 0.5
    y = xy[:, 1] - 0.5
    x0 = np.floor(x)
    y0 = np.floor(y)
    fx, fy = x - x0, y - y0
    x0 = x0.astype(np.int64)
    y0 = y0.astype(np.int64)
    xs = np.stack([x0, x0 + 1, x0, x0 + 1], axis=1).clip(0, W - 1)
    ys = np.stack([y0, y0, y0 + 1, y0 + 1], axis=1).clip(0, H - 1)
    w = np.stack([(1 - fx) * (1 - fy), fx * (1 - fy), (1 - fx) * fy, fx * fy], axis=1)
    return ys * W + xs, w


def bilinear(image: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Bilinear lookups of an (H, W[, C]) image at lightmap UVs (n, 2) (v up)."""
    img = np.asarray(image, dtype=np.float64)
    H, W = img.shape[:2]
    xy = np.stack([uv[:, 0] * W, (1.0 - uv[:, 1]) * H], axis=1)
    ids, w = bilinear_stencil(xy, W, H)
    flat = img.reshape(H * W, -1)
    out = np.einsum("nk,nkc->nc", w, flat[ids])
    return out[:, 0] if img.ndim == 2 else out


# --------------------------------------------------------------------------------------------
# seams


@dataclass
class Seams:
    """Points sampled along UV seams: the same surface point seen from both sides."""

    xy_a: np.ndarray  # (n, 2) texel-space position on side A
    xy_b: np.ndarray  # (n, 2) ... on side B
    edge: np.ndarray  # (n,) seam edge id of each point
    tri_a: np.ndarray  # (E,) triangle of side A of each seam edge
    tri_b: np.ndarray  # (E,)
    smooth: np.ndarray  # (E,) dihedral angle <= SEAM_MAX_ANGLE
    count_all: int = 0  # UV seam edges (any angle)


def seam_edges(scene: Scene, atlas: Atlas, *, max_angle: float = SEAM_MAX_ANGLE,
               per_texel: float = 2.0) -> Seams:
    """Mesh edges shared by two mapped triangles (matched by vertex *position*, so split vertices
    still match) whose lightmap UVs differ at either end, sampled ``per_texel`` times per texel of
    the longer side (at least 2 points, at most 256)."""
    tris = scene.triangles
    T = len(tris)
    _, gid = np.unique(scene.positions, axis=0, return_inverse=True)
    g = gid.reshape(-1)[tris]  # (T, 3) geometric vertex ids
    xy = atlas.texel_xy()
    k0 = np.tile(np.arange(3), T)
    t = np.repeat(np.arange(T), 3)
    k1 = (k0 + 1) % 3
    va, vb = g[t, k0], g[t, k1]
    lo, hi = np.minimum(va, vb), np.maximum(va, vb)
    ok = atlas.mapped[t] & (va != vb)
    order = np.lexsort((t, hi, lo))
    order = order[ok[order]]
    L, Hh = lo[order], hi[order]
    same_next = (L[1:] == L[:-1]) & (Hh[1:] == Hh[:-1])
    # exactly two half-edges per edge: i, i+1 equal, and not part of a longer run
    run_start = np.ones(len(order), bool)
    run_start[1:] = ~same_next
    run_id = np.cumsum(run_start) - 1
    run_len = np.bincount(run_id)
    first = np.flatnonzero(run_start & (run_len[run_id] == 2))
    ea, eb = order[first], order[first + 1]
    ta, tb = t[ea], t[eb]
    # side A corners in its own order; side B's UV at the same geometric vertices
    a0, a1 = xy[ta, k0[ea]], xy[ta, k1[ea]]
    b_at = {0: xy[tb, k0[eb]], 1: xy[tb, k1[eb]]}
    flip = va[ea] != va[eb]  # B runs the other way
    b0 = np.where(flip[:, None], b_at[1], b_at[0])
    b1 = np.where(flip[:, None], b_at[0], b_at[1])
    differ = (np.abs(a0 - b0).max(axis=1) > 1e-6) | (np.abs(a1 - b1).max(axis=1) > 1e-6)
    fn, _ = face_normals(scene.positions, tris)
    cosang = np.einsum("ij,ij->i", fn[ta], fn[tb])
    sel = np.flatnonzero(differ)
    smooth = cosang[sel] >= math.cos(math.radians(max_angle))
    a0, a1, b0, b1 = a0[sel], a1[sel], b0[sel], b1[sel]
    la = np.linalg.norm(a1 - a0, axis=1)
    lb = np.linalg.norm(b1 - b0, axis=1)
    n = np.clip(np.ceil(per_texel * np.maximum(la, lb)), 2, 256).astype(np.int64)
    e = np.repeat(np.arange(len(sel)), n)
    k = np.arange(len(e)) - np.repeat(np.cumsum(n) - n, n)
    s = ((k + 0.5) / n[e])[:, None]
    return Seams(xy_a=a0[e] + s * (a1 - a0)[e], xy_b=b0[e] + s * (b1 - b0)[e], edge=e,
                 tri_a=ta[sel], tri_b=tb[sel], smooth=smooth, count_all=int(len(sel)))


def seam_error(image: np.ndarray, atlas: Atlas, seams: Seams, *, smooth_only: bool = True) -> dict:
    """Bilinear lookups on both sides of each seam point: max and mean of the largest channel
    difference (the image's units), over smooth seams (or all)."""
    img = np.asarray(image, dtype=np.float64)
    H, W = img.shape[:2]
    flat = img.reshape(H * W, -1)
    keep = seams.smooth[seams.edge] if smooth_only else np.ones(len(seams.edge), bool)
    if not keep.any():
        return {"points": 0, "max": 0.0, "mean": 0.0}
    ia, wa = bilinear_stencil(seams.xy_a[keep], W, H)
    ib, wb = bilinear_stencil(seams.xy_b[keep], W, H)
    d = np.abs(np.einsum("nk,nkc->nc", wa, flat[ia]) - np.einsum("nk,nkc->nc", wb, flat[ib])).max(axis=1)
    return {"points": int(keep.sum()), "max": float(d.max()), "mean": float(d.mean())}


def stitch_seams(image: np.ndarray, mask: np.ndarray, atlas: Atlas, seams: Seams, *,
                 seam_weight: float = SEAM_WEIGHT, pad_weight: float = PAD_WEIGHT) -> np.ndarray:
    """Least squares over the texels under smooth seams' bilinear stencils:

        minimise  sum_texels  w_i^2 (x_i - x0_i)^2  +  seam_weight^2 sum_points (B_a x - B_b x)^2

    with ``w_i = 1`` for covered texels and ``pad_weight`` for padding texels (``mask`` False).
    One sparse Cholesky-like solve (SuperLU) for all channels. Other texels are unchanged.
    """
    img = np.array(image, dtype=np.float64)
    one = img.ndim == 2
    if one:
        img = img[:, :, None]
    H, W, C = img.shape
    keep = seams.smooth[seams.edge]
    if not keep.any():
        return img[:, :, 0] if one else img
    ia, wa = bilinear_stencil(seams.xy_a[keep], W, H)
    ib, wb = bilinear_stencil(seams.xy_b[keep], W, H)
    cols = np.concatenate([ia, ib], axis=1)  # (n, 8) texel ids
    vals = np.concatenate([wa, -wb], axis=1)
    var, inv = np.unique(cols.ravel(), return_inverse=True)
    n = len(cols)
    S = sparse.csr_matrix((vals.ravel() * seam_weight, (np.repeat(np.arange(n), 8), inv)),
                          shape=(n, len(var)))
    flat = img.reshape(H * W, C)
    wdat = np.where(np.asarray(mask).reshape(-1)[var], 1.0, pad_weight) ** 2
    A = (S.T @ S + sparse.diags(wdat)).tocsc()
    rhs = wdat[:, None] * flat[var]
    x = sparse_linalg.splu(A).solve(rhs)
    flat = flat.copy()
    flat[var] = x
    out = flat.reshape(H, W, C)
    return out[:, :, 0] if one else out


# --------------------------------------------------------------------------------------------
# one bake


@dataclass
class LightmapBake:
    image: np.ndarray  # (H, W, C) float64
    mask: np.ndarray  # (H, W) covered texels (before dilation)
    samples: TexelSamples
    seams: Seams
    figures: dict


Shader = Callable[[np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def bake(scene: Scene, atlas: Atlas, shade: Shader, cfg: LightmapConfig, *, tracer=None) -> LightmapBake:
    """Samples -> ``shade(points, normals, tri_ids)`` -> splat -> dilate -> stitch seams.

    ``figures``: texel counts, coverage, samples pushed, seam error before and after stitching
    (in the shader's units), seconds per step.
    """
    t0 = time.perf_counter()
    smp = texel_samples(scene, atlas, supersample=cfg.supersample, push=cfg.push_out, tracer=tracer)
    t1 = time.perf_counter()
    vals = np.asarray(shade(smp.points, smp.normals, smp.tri_ids), dtype=np.float64)
    vals = np.nan_to_num(vals.reshape(len(smp), -1), nan=0.0, posinf=0.0, neginf=0.0)
    t2 = time.perf_counter()
    img = splat(vals, smp.texel_index, smp.weights, atlas)
    if img.ndim == 2:
        img = img[:, :, None]
    mask = texel_mask(smp.texel_index, smp.weights, atlas)
    img, filled = dilate(img, mask, cfg.dilate)
    seams = seam_edges(scene, atlas)
    before = seam_error(img, atlas, seams)
    if cfg.stitch_seams:
        img = stitch_seams(img, mask, atlas, seams)  # covered texels weigh more than padding
    after = seam_error(img, atlas, seams)
    t3 = time.perf_counter()
    figs = coverage_figures(scene, atlas, smp)
    figs.update({
        "samples": int(len(smp)), "samples_pushed": int(smp.pushed.sum()),
        "seam_edges": int(seams.count_all), "seam_edges_smooth": int(seams.smooth.sum()),
        "seam_error_before": before["max"], "seam_error": after["max"], "seam_error_mean": after["mean"],
        "seconds_samples": round(t1 - t0, 6), "seconds_shade": round(t2 - t1, 6),
        "seconds_splat_dilate_stitch": round(t3 - t2, 6),
    })
    return LightmapBake(image=img, mask=mask, samples=smp, seams=seams, figures=figs)


def coverage_figures(scene: Scene, atlas: Atlas, smp: TexelSamples | None = None) -> dict:
    """Texels covered, triangles with samples, texels claimed by two charts, utilisation."""
    if smp is None:
        t, x = cover(atlas)
        w = np.ones(len(t))
    else:
        t, x, w = smp.tri_ids, smp.texel_index, smp.weights
    n = atlas.width * atlas.height
    covered = np.bincount(x, weights=w, minlength=n) > 0
    mapped = atlas.mapped
    _, area = face_normals(scene.positions, scene.triangles)
    real = mapped & (area > 0)
    has = np.zeros(scene.n_triangles, bool)
    has[t] = True
    # texels reached by triangles of two different charts (bleeding between charts)
    ch = atlas.chart[t]
    lo = np.full(n, np.iinfo(np.int64).max)
    hi = np.full(n, -1)
    np.minimum.at(lo, x, ch)
    np.maximum.at(hi, x, ch)
    conflicts = int(((hi >= 0) & (lo != hi)).sum())
    return {"atlas_width": atlas.width, "atlas_height": atlas.height, "charts": atlas.chart_count,
            "utilization_xatlas": round(atlas.utilization, 6),
            "texels_covered": int(covered.sum()), "coverage": round(float(covered.sum()) / n, 6),
            "triangles_unmapped": int((~mapped).sum()),
            "triangles_without_samples": int((real & ~has).sum()),
            "texels_two_charts": conflicts}


# --------------------------------------------------------------------------------------------
# the job the textures stage leaves for the lighting stage's lightmap target


@dataclass
class LightmapJob:
    """``scene.artefacts.lightmap``, left by the textures stage for the lighting stage."""

    atlas: Atlas
    config: LightmapConfig
    textures: object  # the TexturesConfig: encodings and list names for the lightmap image
