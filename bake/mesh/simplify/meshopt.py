"""meshoptimizer's edge-collapse simplifier, called through its C API.

The PyPI package ``meshoptimizer`` (0.2.30a0, a pre-release) builds the C++ library and loads
it with ctypes. Its Python wrapper declares argument types for ``meshopt_simplify`` but not for
``meshopt_simplifyWithAttributes`` (ctypes would then pass the ``size_t`` counts as C ints), so
this module opens the same shared library with its own ``ctypes.CDLL`` handle and declares the
signature from meshoptimizer.h itself. Nothing here is copied from the package.

meshoptimizer never moves vertices: the result indexes the input vertex buffer. Vertices that
share a position but have different indices are "seams": they collapse only along the seam, so
a wedge buffer (one vertex per position + material + UV) keeps UV seams and material edges.
"""

from __future__ import annotations

import ctypes
import glob
import os
from functools import lru_cache

import numpy as np

SIMPLIFY_LOCK_BORDER = 1
SIMPLIFY_ERROR_ABSOLUTE = 4

__all__ = ["available", "version", "simplify", "simplify_sloppy", "SIMPLIFY_LOCK_BORDER", "SIMPLIFY_ERROR_ABSOLUTE"]


@lru_cache(maxsize=1)
def _lib() -> ctypes.CDLL | None:
    try:
        import meshoptimizer  # noqa: F401  (only to find its shared library)
    except Exception:  # not installed, or its loader failed
        return None
    here = os.path.dirname(meshoptimizer.__file__)
    found = sorted(glob.glob(os.path.join(here, "_meshoptimizer*.so")) +
                   glob.glob(os.path.join(here, "_meshoptimizer*.pyd")))
    if not found:
        return None
    lib = ctypes.CDLL(found[0])
    P = ctypes.POINTER
    f = lib.meshopt_simplifyWithAttributes
    f.argtypes = [
        P(ctypes.c_uint),   # destination
        P(ctypes.c_uint),   # indices
        ctypes.c_size_t,    # index_count
        P(ctypes.c_float),  # vertex_positions
        ctypes.c_size_t,    # vertex_count
        ctypes.c_size_t,    # vertex_positions_stride (bytes)
        P(ctypes.c_float),  # vertex_attributes
        ctypes.c_size_t,    # vertex_attributes_stride (bytes)
        P(ctypes.c_float),  # attribute_weights
        ctypes.c_size_t,    # attribute_count
        P(ctypes.c_ubyte),  # vertex_lock (may be NULL)
        ctypes.c_size_t,    # target_index_count
        ctypes.c_float,     # target_error
        ctypes.c_uint,      # options
        P(ctypes.c_float),  # result_error (may be NULL)
    ]
    f.restype = ctypes.c_size_t
    g = lib.meshopt_simplifySloppy
    g.argtypes = [P(ctypes.c_uint), P(ctypes.c_uint), ctypes.c_size_t, P(ctypes.c_float), ctypes.c_size_t,
                  ctypes.c_size_t, ctypes.c_size_t, ctypes.c_float, P(ctypes.c_float)]
    g.restype = ctypes.c_size_t
    return lib


def available() -> bool:
    return _lib() is not None


def version() -> str | None:
    try:
        from importlib.metadata import version as v
        return v("meshoptimizer")
    except Exception:
        return None


def _float32(positions: np.ndarray) -> np.ndarray:
    """Positions centred on their box (a small model far from the origin keeps its digits) as
    contiguous float32, which the library reads."""
    p64 = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    if len(p64):
        p64 = p64 - 0.5 * (p64.min(axis=0) + p64.max(axis=0))
    pos = np.ascontiguousarray(p64, dtype=np.float32)
    if len(pos) and not np.isfinite(pos).all():
        raise ValueError("positions do not fit in float32")
    return pos


def _buffers(positions: np.ndarray, triangles: np.ndarray):
    """The library and what its simplifiers read and write: (lib, the indices as uint32, the
    positions as :func:`_float32`, room for the result's indices)."""
    lib = _lib()
    if lib is None:
        raise RuntimeError("meshoptimizer is not installed")
    idx = np.ascontiguousarray(np.asarray(triangles).reshape(-1), dtype=np.uint32)
    return lib, idx, _float32(positions), np.empty(max(len(idx), 3), dtype=np.uint32)


def simplify_sloppy(positions: np.ndarray, triangles: np.ndarray, target_triangles: int) -> tuple[np.ndarray, float]:
    """meshoptimizer's vertex-clustering simplifier: reaches about ``target_triangles`` whatever
    the topology (seams, borders, soups of separate triangles), at the cost of merging vertices
    that are near each other without regard to what they belong to. Returns (triangles indexing
    ``positions``, the library's error estimate relative to the mesh extent)."""
    lib, idx, pos, dst = _buffers(positions, triangles)
    P = ctypes.POINTER
    err = ctypes.c_float(0.0)
    n = lib.meshopt_simplifySloppy(dst.ctypes.data_as(P(ctypes.c_uint)), idx.ctypes.data_as(P(ctypes.c_uint)),
                                   len(idx), pos.ctypes.data_as(P(ctypes.c_float)), len(pos), 12,
                                   int(max(0, target_triangles)) * 3, ctypes.c_float(1e30), ctypes.byref(err))
    return dst[:n].reshape(-1, 3).astype(np.int64), float(err.value)


def simplify(positions: np.ndarray, triangles: np.ndarray, target_triangles: int, *,
             target_error: float = 1e30, absolute_error: bool = False, lock: np.ndarray | None = None,
             lock_border: bool = False, attributes: np.ndarray | None = None,
             attribute_weights: np.ndarray | None = None) -> tuple[np.ndarray, float]:
    """Simplify ``triangles`` (T, 3) over ``positions`` (V, 3) to at most ``target_triangles``
    or until the next collapse would cost more than ``target_error`` (relative to the mesh
    extent, or absolute with ``absolute_error``). Returns (triangles (T', 3) int64 indexing
    ``positions``, the error meshoptimizer reports, in the same units as ``target_error``)."""
    lib, idx, pos, dst = _buffers(positions, triangles)
    P = ctypes.POINTER
    if attributes is not None:
        attr = np.ascontiguousarray(np.asarray(attributes, np.float64).reshape(len(pos), -1), dtype=np.float32)
        weights = np.ascontiguousarray(np.asarray(attribute_weights, np.float64).reshape(-1), dtype=np.float32)
        assert len(weights) == attr.shape[1]
        n_attr = attr.shape[1]
    else:
        attr = np.zeros((1, 1), dtype=np.float32)  # no attributes (count 0); a valid pointer all the same
        weights = np.zeros(1, dtype=np.float32)
        n_attr = 0
    if lock is not None:
        lk = np.ascontiguousarray(np.asarray(lock, dtype=bool), dtype=np.uint8)
        assert lk.shape == (len(pos),)
        lock_ptr = lk.ctypes.data_as(P(ctypes.c_ubyte))
    else:
        lk = None
        lock_ptr = P(ctypes.c_ubyte)()
    err = ctypes.c_float(0.0)
    options = (SIMPLIFY_ERROR_ABSOLUTE if absolute_error else 0) | (SIMPLIFY_LOCK_BORDER if lock_border else 0)
    n = lib.meshopt_simplifyWithAttributes(
        dst.ctypes.data_as(P(ctypes.c_uint)), idx.ctypes.data_as(P(ctypes.c_uint)), len(idx),
        pos.ctypes.data_as(P(ctypes.c_float)), len(pos), 12,
        attr.ctypes.data_as(P(ctypes.c_float)), 4 * max(n_attr, 1), weights.ctypes.data_as(P(ctypes.c_float)), n_attr,
        lock_ptr, int(max(0, target_triangles)) * 3, float(target_error), options, ctypes.byref(err))
    del lk
    return dst[:n].reshape(-1, 3).astype(np.int64), float(err.value)
