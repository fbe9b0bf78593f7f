"""The unwrap's cache: xatlas's output stored by a hash of exactly what xatlas was handed.

An entry is an ``.npz`` at ``<cache>/<key[:2]>/<key>.npz`` holding the arrays of the atlas the
unwrap kept (after every run it took to fit the resolution) and :data:`CACHE_FORMAT`; a rerun
with the same mesh and options loads it and gives identical UVs without starting xatlas. The
cache folder is :func:`cache_directory`: ``.bake-cache/xatlas`` in the output folder unless
``textures.lightmap.cache_dir`` names one (or ``"none"``). A damaged or foreign entry is
recomputed; a cache that cannot be written only costs speed.
"""

from __future__ import annotations

import hashlib
import io
import json
from pathlib import Path

import numpy as np

from ..config import LightmapConfig
from ..files import write_atomic

CACHE_FORMAT = "scratch-bake xatlas cache 2"  # 2: the atlas after the runs that fit the resolution
CACHE_SUBDIR = Path(".bake-cache") / "xatlas"  # the default cache, inside the output folder


def cache_directory(cfg: LightmapConfig) -> Path | None:
    """Where atlases are cached: ``cache_dir`` when it is a path (a cache shared between bakes,
    the user's choice), else ``.bake-cache/xatlas`` in the output folder (``cfg.out_dir``, set
    from ``Config.out_dir`` by the textures section; without an output folder there is no cache);
    ``"none"`` turns it off."""
    if cfg.cache_dir.strip().lower() == "none":
        return None
    if cfg.cache_dir:
        return Path(cfg.cache_dir).expanduser()
    return None if cfg.out_dir is None else Path(cfg.out_dir) / CACHE_SUBDIR


def cache_key(p32: np.ndarray, idx: np.ndarray, options: dict, version: str) -> str:
    """The cache key of an unwrap: exactly what xatlas is first handed (the format, its version,
    the options, the positions and indices)."""
    h = hashlib.sha256()
    for part in (CACHE_FORMAT, version, json.dumps(options, sort_keys=True)):
        h.update(part.encode() + b"\0")
    h.update(np.ascontiguousarray(p32).tobytes())
    h.update(np.ascontiguousarray(idx).tobytes())
    return h.hexdigest()


def entry_path(directory: Path | None, key: str) -> Path | None:
    """Where the entry of ``key`` lives in ``directory`` (None: no cache)."""
    return None if directory is None else directory / key[:2] / f"{key}.npz"


_CACHE_KEYS = ("vmapping", "indices", "uvs", "width", "height", "atlas_count", "chart_count",
               "utilization", "texels_per_unit", "seconds")


def load(path: Path | None) -> dict | None:
    """The arrays of the entry at ``path``; None without a cache, an entry or one of this format."""
    if path is None or not path.is_file():
        return None
    try:
        with np.load(path, allow_pickle=False) as f:
            if str(f["format"]) != CACHE_FORMAT:
                return None
            return {k: f[k] for k in _CACHE_KEYS}
    except Exception:  # a damaged cache entry is recomputed
        return None


def store(path: Path | None, data: dict) -> None:
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
