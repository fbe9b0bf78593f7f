"""The lightmap's memory guard: before any texel work, the memory a lightmap of an atlas will take
(:func:`estimate_memory`) against what this process may still use (:func:`available_memory`: the
address-space limit, the cgroup's ``memory.max`` and the machine's ``MemAvailable``, read from
/proc and /sys/fs/cgroup). :func:`check_memory` refuses one that does not fit, naming the
resolution that would.
"""

from __future__ import annotations

import math
from pathlib import Path

from ..config import LightmapConfig
from ..errors import ConfigError
from .atlas import Atlas

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


def check_memory(atlas: Atlas, cfg: LightmapConfig, *, lit: bool = True,
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
