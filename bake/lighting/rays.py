"""Embree (embreex) ray casting with robust origins and Python threads.

* **Precision.** Embree works in float32. The scene is moved so that its bounding-box centre is
  the origin *in float64* before the cast to float32, so float32 resolution follows the size of
  the scene, not its distance from the world origin (a model at 1e5 is as exact as one at 0).
* **Size.** Embree itself misses hits when coordinates are very large or very small (a triangle
  1e14 away is not hit; nor one 1e-20 away; measured with embreex 4.4). So Embree sees the centred
  scene multiplied by ``k``, the power of two nearest ``1 / scale`` (about unit size), and every ray
  origin and length by the same ``k``; hit distances are divided by it. Multiplying by a power of
  two is exact in float32 and float64, so a scene of ordinary size gets bit-identical hits, and a
  scene scaled by any power of two gets exactly the same answers. Callers keep working in the
  centred frame of world-sized units (``origins``, ``to_local``, distances, ``t``); only ``Ng``
  comes back in Embree's frame (its direction is what callers use).
* **Robust origins.** embreex fixes ``tnear = 0``, so a ray started on a surface may hit that
  surface. Origins are pushed along the geometric normal by
  ``eps = EPS_SCALE * scale + EPS_POS * |p_local|`` (scene-relative, growing with the magnitude
  of the local float32 coordinate, which is what float32 rounding grows with).
* **Threads.** ``run`` is single-threaded and releases the GIL, so work is split into chunks of a
  fixed number of sample points and Python threads take chunks from a shared counter. Chunk
  boundaries do not depend on the thread count, and each point's result only on its own rays,
  so results are bit-identical for any number of threads.
"""

from __future__ import annotations

import math
import os
import threading
import time
from collections import defaultdict
from typing import Callable

import numpy as np

EPS_SCALE = 2e-6  # times the scene scale (bbox diagonal)
EPS_POS = 8e-6  # times the largest |coordinate| of the point in the centred float32 frame
CHUNK_RAYS = 1 << 17  # rays generated and traced per work item


def default_threads(requested: int = 0) -> int:
    if requested and requested > 0:
        return int(requested)
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover
        return max(1, os.cpu_count() or 1)


class Timers:
    """Thread-safe accumulation of seconds per phase (thread-seconds, summed over workers)."""

    def __init__(self) -> None:
        self._lock = threading.Lock()
        self.seconds: dict[str, float] = defaultdict(float)

    def add(self, name: str, seconds: float) -> None:
        with self._lock:
            self.seconds[name] += seconds

    def merge(self, other: "Timers") -> None:
        for k, v in other.seconds.items():
            self.add(k, v)

    def as_dict(self) -> dict[str, float]:
        return {k: round(v, 6) for k, v in sorted(self.seconds.items())}


class Tracer:
    """An Embree scene over ``(positions, triangles)`` with a float64 <-> local float32 frame."""

    def __init__(self, positions: np.ndarray, triangles: np.ndarray, *, threads: int = 0,
                 scale: float | None = None):
        from embreex import mesh_construction, rtcore_scene

        pos = np.asarray(positions, dtype=np.float64)
        tris = np.asarray(triangles, dtype=np.int64)
        if len(tris):  # the vertices the triangles use (a mask: np.unique would sort or hash)
            used = np.zeros(len(pos), bool)
            used[tris.ravel()] = True
            p = pos[used]
        else:
            p = pos if len(pos) else np.zeros((1, 3))
        lo, hi = p.min(axis=0), p.max(axis=0)
        self.center = 0.5 * (lo + hi)
        d = float(np.linalg.norm(hi - lo))
        self.scale = float(scale) if scale else (d if d > 0 else max(float(np.abs(p).max()), 1.0))
        self.threads = default_threads(threads)
        self.n_triangles = len(tris)
        self._scene = rtcore_scene.EmbreeScene()
        # Embree's frame: the centred scene times k, a power of two, so that it is about unit size
        k = 2.0 ** -round(math.log2(self.scale)) if 0 < self.scale < math.inf else 1.0
        self.k, self._k32 = k, np.float32(k)
        local = ((pos - self.center) * k).astype(np.float32)
        if len(tris):
            mesh_construction.TriangleMesh(self._scene, np.ascontiguousarray(local),
                                           np.ascontiguousarray(tris.astype(np.int32)))
            # commit the BVH now, in this thread (a lazy commit from two threads would race)
            self._scene.run(np.zeros((1, 3), np.float32), np.array([[0, 0, 1]], np.float32),
                            query="OCCLUDED")
        self._lock = threading.Lock()
        self.rays = 0

    # ---------------------------------------------------------------- frames and origins
    def to_local(self, p: np.ndarray) -> np.ndarray:
        return np.asarray(p, dtype=np.float64) - self.center

    def epsilon(self, p_local: np.ndarray) -> np.ndarray:
        mag = np.abs(p_local).max(axis=1) if len(p_local) else np.zeros(0)
        return EPS_SCALE * self.scale + EPS_POS * mag

    def origins(self, p_world: np.ndarray, normals: np.ndarray, side: float = 1.0) -> np.ndarray:
        """Offset ray origins (local float32) for surface points and unit geometric normals."""
        loc = self.to_local(p_world)
        eps = self.epsilon(loc)
        return (loc + (side * eps)[:, None] * normals).astype(np.float32)

    def _count(self, n: int) -> None:
        with self._lock:
            self.rays += n

    # ---------------------------------------------------------------- queries
    def embree_origins(self, o_local: np.ndarray) -> np.ndarray:
        """Local float32 origins in Embree's frame (times ``k``: exact), for ``occluded(...,
        embree_frame=True)``: scaling once per sample point instead of once per ray."""
        return np.asarray(o_local, np.float32) * self._k32

    def occluded(self, o: np.ndarray, d: np.ndarray, dist: float | np.ndarray | None = None, *,
                 embree_frame: bool = False) -> np.ndarray:
        """True where the segment ``o + t d``, ``0 <= t <= dist``, hits a triangle. With
        ``embree_frame``, ``o`` is already in Embree's frame (:meth:`embree_origins`) and both
        arrays are float32 ``(n, 3)`` of any strides (embreex reads them in place: no copy)."""
        n = len(o)
        if n == 0 or self.n_triangles == 0:
            return np.zeros(n, dtype=bool)
        self._count(n)
        if isinstance(dist, np.ndarray):  # a copy: embreex writes into it
            dist = np.ascontiguousarray(dist, dtype=np.float32) * self._k32
        elif dist is not None:
            dist = float(dist) * self.k
        if embree_frame:
            if o.dtype != np.float32 or d.dtype != np.float32:
                raise TypeError("occluded(embree_frame=True) takes float32 origins and directions")
            r = self._scene.run(o, d, dists=dist, query="OCCLUDED")
        else:
            r = self._scene.run(np.ascontiguousarray(o, np.float32) * self._k32,
                                np.ascontiguousarray(d, np.float32), dists=dist, query="OCCLUDED")
        return np.asarray(r) == 0

    def intersect(self, o: np.ndarray, d: np.ndarray, dist: float | np.ndarray | None = None) -> dict:
        """Closest hit: ``prim`` (-1 = miss), barycentrics ``u``, ``v``, ``t``, unnormalised ``Ng`` (in
        Embree's frame: use its direction)."""
        n = len(o)
        if n == 0 or self.n_triangles == 0:
            return {"prim": np.full(n, -1, np.int32), "u": np.zeros(n, np.float32),
                    "v": np.zeros(n, np.float32), "t": np.full(n, np.inf, np.float32),
                    "Ng": np.zeros((n, 3), np.float32)}
        self._count(n)
        if isinstance(dist, np.ndarray):
            dist = np.ascontiguousarray(dist, dtype=np.float32) * self._k32
        elif dist is not None:
            dist = float(dist) * self.k
        r = self._scene.run(np.ascontiguousarray(o, np.float32) * self._k32, np.ascontiguousarray(d, np.float32),
                            dists=dist, query="INTERSECT", output=1)
        with np.errstate(over="ignore"):  # a miss's default far limit may become inf: still a miss
            t = np.asarray(r["tfar"], np.float32) / self._k32  # back to world-sized units
        return {"prim": r["primID"], "u": r["u"], "v": r["v"], "t": t, "Ng": r["Ng"]}

    # ---------------------------------------------------------------- work distribution
    def parallel(self, n_items: int, chunk: int, work: Callable[[int, int], None]) -> None:
        """Call ``work(start, stop)`` over fixed chunks of ``range(n_items)`` on the threads."""
        parallel(n_items, chunk, work, self.threads)


def parallel(n_items: int, chunk: int, work: Callable[[int, int], None], threads: int) -> None:
    chunk = max(1, int(chunk))
    starts = list(range(0, n_items, chunk))
    if not starts:
        return
    if threads <= 1 or len(starts) == 1:
        for s in starts:
            work(s, min(n_items, s + chunk))
        return
    lock = threading.Lock()
    pos = [0]
    errors: list[BaseException] = []

    def worker() -> None:
        while True:
            with lock:
                if errors or pos[0] >= len(starts):
                    return
                s = starts[pos[0]]
                pos[0] += 1
            try:
                work(s, min(n_items, s + chunk))
            except BaseException as e:  # re-raised in the caller
                with lock:
                    errors.append(e)
                return

    ts = [threading.Thread(target=worker, daemon=True) for _ in range(min(threads, len(starts)))]
    for t in ts:
        t.start()
    for t in ts:
        t.join()
    if errors:
        raise errors[0]


def points_per_chunk(samples: int) -> int:
    return max(1, CHUNK_RAYS // max(1, samples))


class Clock:
    """``with clock("trace"): ...`` adds the elapsed time to a Timers object."""

    def __init__(self, timers: Timers):
        self.timers = timers

    def __call__(self, name: str) -> "_Section":
        return _Section(self.timers, name)


class _Section:
    """Adds wall time under ``name`` and this thread's CPU time under ``name + "_cpu"``."""

    __slots__ = ("timers", "name", "t", "c")

    def __init__(self, timers: Timers, name: str):
        self.timers, self.name = timers, name

    def __enter__(self) -> None:
        self.t = time.perf_counter()
        self.c = time.thread_time()

    def __exit__(self, *exc) -> None:
        self.timers.add(self.name, time.perf_counter() - self.t)
        self.timers.add(self.name + "_cpu", time.thread_time() - self.c)
