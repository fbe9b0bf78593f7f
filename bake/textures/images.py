"""Texture images: load into RGBA uint8, resample, and average over triangles' UV areas.

Conventions:

* images are ``(H, W, 4)`` uint8 arrays, row 0 at the **top** (as stored in the file);
* UVs use the OBJ convention (``bake/scene.py``): ``(0, 0)`` is the bottom-left corner of the
  image, ``v`` grows upward, and addressing wraps (repeat), so ``u = 1.25`` reads like ``0.25``;
* in texel space a UV maps to ``x = u * W`` (columns from the left) and ``y = (1 - v) * H`` (rows
  from the top); texel ``(row i, column j)`` covers ``[j, j+1) x [i, i+1)``.

The texture is treated as piecewise constant (each texel a flat square), and the average over a
triangle is the integral of that function over the triangle's UV area divided by the area. With
alpha, colours are averaged premultiplied (weighted by alpha) and alpha is averaged plainly, so a
half-transparent cut-out texture gives the colour of its opaque part at half alpha.
"""

from __future__ import annotations

import io
import re
import math
import warnings
from pathlib import Path
from typing import Literal, Union

import numpy as np
from PIL import Image

from ..errors import InputError
from ..colorspace import linear_to_srgb, srgb_to_linear, to_bytes

Source = Union[str, Path, bytes, bytearray, memoryview, Image.Image, np.ndarray]
Filter = Literal["nearest", "box", "bilinear", "hamming", "bicubic", "lanczos"]
PowerOfTwo = Literal["floor", "ceil", "nearest"]

FILTERS: dict[str, Image.Resampling] = {
    "nearest": Image.Resampling.NEAREST,
    "box": Image.Resampling.BOX,
    "bilinear": Image.Resampling.BILINEAR,
    "hamming": Image.Resampling.HAMMING,
    "bicubic": Image.Resampling.BICUBIC,
    "lanczos": Image.Resampling.LANCZOS,
}
# Filter radius in source texels at scale 1 (Pillow's filter supports).
_SUPPORT = {"nearest": 0.5, "box": 0.5, "bilinear": 1.0, "hamming": 1.0, "bicubic": 2.0,
            "lanczos": 3.0}


# --------------------------------------------------------------------------------------------
# loading


def _pil_to_rgba(img: Image.Image) -> np.ndarray:
    mode = img.mode
    if mode.startswith("I;16") or mode == "I":
        a = np.asarray(img.convert("I"), dtype=np.float64)
        grey = np.clip(np.rint(a / 257.0), 0, 255).astype(np.uint8)  # 16-bit -> 8-bit
        return np.dstack([grey, grey, grey, np.full_like(grey, 255)])
    if mode == "F":
        grey = to_bytes(np.asarray(img, dtype=np.float64))
        return np.dstack([grey, grey, grey, np.full_like(grey, 255)])
    if mode != "RGBA":
        img = img.convert("RGBA")  # P (+transparency), L, LA, RGB, CMYK, YCbCr, 1, ...
    return np.array(img, dtype=np.uint8)


def _array_to_rgba(a: np.ndarray) -> np.ndarray:
    if a.dtype != np.uint8:
        if np.issubdtype(a.dtype, np.floating):
            a = to_bytes(a)
        elif np.issubdtype(a.dtype, np.integer) and a.size and (a.min() < 0 or a.max() > 255):
            raise ValueError("integer image values must be in 0..255")
        else:
            a = a.astype(np.uint8)
    if a.ndim == 2:
        a = a[:, :, None]
    if a.ndim != 3 or a.shape[2] not in (1, 2, 3, 4):
        raise ValueError(f"expected an (H, W) or (H, W, 1..4) image, got shape {a.shape}")
    c = a.shape[2]
    if c == 4:
        return np.ascontiguousarray(a)
    opaque = np.full(a.shape[:2] + (1,), 255, np.uint8)
    if c == 1:
        return np.concatenate([a, a, a, opaque], axis=2)
    if c == 2:
        return np.concatenate([a[:, :, :1]] * 3 + [a[:, :, 1:]], axis=2)
    return np.concatenate([a, opaque], axis=2)


def load_rgba(source: Source, *, name: str | Path | None = None) -> np.ndarray:
    """Load an image into an ``(H, W, 4)`` uint8 RGBA array (row 0 at the top).

    ``source``: a path, the encoded bytes of an image file (PNG, JPEG, ... e.g. a texture
    embedded in a GLB), a Pillow image, or an array (``(H, W)``, ``(H, W, 1..4)``; uint8, or
    floats in [0, 1]). Multi-frame images give their first frame; 16-bit greyscale is scaled to
    8 bits. ``name`` is used in error messages for byte sources.

    An unreadable or undecodable image raises :class:`bake.errors.InputError` with the path.
    """
    if isinstance(source, np.ndarray):
        return _array_to_rgba(source)
    if isinstance(source, Image.Image):
        return _pil_to_rgba(source)
    where = name
    try:
        if isinstance(source, (bytes, bytearray, memoryview)):
            fp = io.BytesIO(bytes(source))
            where = name or "<embedded image>"
        else:
            fp = Path(source)
            where = fp
        with warnings.catch_warnings():
            warnings.simplefilter("error", Image.DecompressionBombWarning)
            with Image.open(fp) as img:
                img.load()
                return _pil_to_rgba(img)
    except FileNotFoundError:
        raise InputError("image file not found", path=where) from None
    except (OSError, SyntaxError, ValueError, Image.DecompressionBombError,
            Image.DecompressionBombWarning) as e:
        # (Pillow names a byte source by its in-memory object: "<_io.BytesIO object at 0x...>")
        why = re.sub(r"<_io\.BytesIO object at 0x[0-9a-fA-F]+>", "the embedded bytes", str(e))
        raise InputError(f"cannot read image: {why}", path=where) from None


# --------------------------------------------------------------------------------------------
# sizes and resampling


def _pow2(n: int, how: PowerOfTwo) -> int:
    if n <= 1:
        return 1
    lg = math.log2(n)
    if how == "floor":
        e = math.floor(lg)
    elif how == "ceil":
        e = math.ceil(lg)
    elif how == "nearest":
        e = math.floor(lg + 0.5)  # nearest in log scale: 96 -> 128, 90 -> 64
    else:
        raise ValueError(f"power_of_two must be 'floor', 'ceil' or 'nearest', got {how!r}")
    return 1 << e


def fit_size(width: int, height: int, *, size: int | tuple[int, int] | None = None,
             max_size: int | None = None,
             power_of_two: PowerOfTwo | None = None) -> tuple[int, int]:
    """The ``(width, height)`` a texture should be resampled to.

    ``size``: an exact size (``n`` means ``n x n``); otherwise the image's own size, shrunk
    (aspect kept, each side at least 1) so neither side exceeds ``max_size``. Then each side is
    rounded to a power of two if ``power_of_two`` is given (``"floor"``, ``"ceil"`` or
    ``"nearest"`` in log scale); ``"floor"`` / ``"nearest"`` never exceed ``max_size`` when it
    is a power of two itself.
    """
    if size is not None:
        w, h = (size, size) if isinstance(size, int) else (int(size[0]), int(size[1]))
    else:
        w, h = int(width), int(height)
        if max_size is not None and max(w, h) > max_size:
            s = max_size / max(w, h)
            w, h = max(1, round(w * s)), max(1, round(h * s))
    if w < 1 or h < 1:
        raise ValueError(f"texture size must be at least 1x1, got {w}x{h}")
    if power_of_two is not None:
        w, h = _pow2(w, power_of_two), _pow2(h, power_of_two)
        if max_size is not None and size is None:
            cap = 1 << int(math.floor(math.log2(max(1, max_size))))
            w, h = min(w, cap), min(h, cap)
    return w, h


def resample(image: np.ndarray, size: tuple[int, int], filter: Filter = "box", *,
             wrap: bool = False) -> np.ndarray:
    """Resample an ``(H, W, 4)`` uint8 image to ``size = (width, height)``.

    ``filter``: ``"nearest"`` (pixel art, exact colours) or a Pillow filter (``"box"`` = area
    average, good for shrinking; ``"bilinear"``, ``"hamming"``, ``"bicubic"``, ``"lanczos"``).
    Filtering uses premultiplied alpha (Pillow does this for RGBA), so transparent texels do not
    bleed their colour. ``wrap=True`` treats the image as tiling (UV repeat): the filter reads
    across the opposite edge instead of clamping, so the result still tiles seamlessly.
    """
    img = _array_to_rgba(np.asarray(image))
    h0, w0 = img.shape[:2]
    w, h = int(size[0]), int(size[1])
    if w < 1 or h < 1:
        raise ValueError(f"target size must be at least 1x1, got {w}x{h}")
    if filter not in FILTERS:
        raise ValueError(f"unknown filter {filter!r}; use one of {', '.join(FILTERS)}")
    if (w, h) == (w0, h0):
        return img.copy()
    if not wrap or filter == "nearest":
        out = Image.fromarray(img).resize((w, h), FILTERS[filter])
        return np.asarray(out, dtype=np.uint8).copy()
    # Pad by wrapping, then resize the original region (box) so edge texels see their neighbours
    # across the seam.
    sup = _SUPPORT[filter]
    mx = int(math.ceil(sup * max(w0 / w, 1.0))) + 2
    my = int(math.ceil(sup * max(h0 / h, 1.0))) + 2
    padded = np.pad(img, ((my, my), (mx, mx), (0, 0)), mode="wrap")
    out = Image.fromarray(padded).resize(
        (w, h), FILTERS[filter], box=(mx, my, mx + w0, my + h0))
    return np.asarray(out, dtype=np.uint8).copy()


def prepare_texture(source: Source, *, size: int | tuple[int, int] | None = None,
                    max_size: int | None = None, power_of_two: PowerOfTwo | None = None,
                    filter: Filter = "box", wrap: bool = False,
                    name: str | Path | None = None) -> np.ndarray:
    """:func:`load_rgba`, then :func:`resample` to :func:`fit_size`'s size (if it differs)."""
    img = load_rgba(source, name=name)
    target = fit_size(img.shape[1], img.shape[0], size=size, max_size=max_size,
                      power_of_two=power_of_two)
    return resample(img, target, filter, wrap=wrap)


# --------------------------------------------------------------------------------------------
# averages over triangles


def _edge_pieces(a: np.ndarray, b: np.ndarray):
    """Split segments a -> b (texel space, (E, 2)) where they cross the texel grid lines.

    Returns ``(edge, t0, t1)`` for every piece, sorted by edge then t; each piece lies inside one
    texel (up to rounding). Crossings are generated ragged-vectorised: the integers strictly
    between the ends' coordinates, for x and for y.
    """
    e_count = len(a)
    ts, owners = [np.zeros(e_count), np.ones(e_count)], [np.arange(e_count)] * 2
    for axis in (0, 1):
        lo = np.minimum(a[:, axis], b[:, axis])
        hi = np.maximum(a[:, axis], b[:, axis])
        first = np.floor(lo) + 1.0
        count = np.maximum(np.ceil(hi) - first, 0).astype(np.int64)
        owner = np.repeat(np.arange(e_count), count)
        if owner.size:
            starts = np.cumsum(count) - count
            k = first[owner] + (np.arange(owner.size) - starts[owner])
            span = b[owner, axis] - a[owner, axis]
            ts.append(np.clip((k - a[owner, axis]) / span, 0.0, 1.0))
            owners.append(owner)
    t = np.concatenate(ts)
    edge = np.concatenate(owners)
    # sort by (edge, t) with one float key: edge + t/2 (much faster than a two-key lexsort; two
    # crossings closer than ~1e-9 of an edge may swap, which changes nothing measurable)
    order = np.argsort(edge + 0.5 * t)
    t, edge = t[order], edge[order]
    same = edge[1:] == edge[:-1]
    return edge[:-1][same], t[:-1][same], t[1:][same]


def average_over_triangles(image: np.ndarray, tri_uvs: np.ndarray, *,
                           space: Literal["srgb", "linear"] = "srgb") -> np.ndarray:
    """Average colour of the texture over each triangle's UV area -> ``(T, 4)`` floats in [0, 1].

    ``image``: ``(H, W, 3|4)`` uint8, row 0 at the top. ``tri_uvs``: ``(T, 3, 2)`` UVs in the OBJ
    convention with wrap addressing (see the module docstring).

    The result is exact for the piecewise-constant texture (each texel weighted by the area of
    the triangle covering it), computed without rasterising the interior: by Green's theorem
    ``integral over T of f dA`` equals the boundary integral ``of P dy`` where ``P(x, y)`` is the
    integral of row ``y`` from 0 to ``x`` (a prefix sum, linear inside a texel, periodic with the
    row's total). Each edge is cut where it crosses the texel grid, and on each piece the
    midpoint rule is exact, so the cost grows with the triangles' perimeters in texels, not their
    areas. The area comes from the same sum with ``f = 1``.

    A triangle with (numerically) zero area gets the length-weighted average along its edges, and
    a single point its texel. RGB is averaged weighted by alpha (premultiplied); where the average
    alpha is 0 the plain RGB average is used. ``space="linear"`` averages linear light (decoding
    sRGB first, encoding the result), what the eye sees from a distance; ``"srgb"`` averages the
    stored values.
    """
    img = _array_to_rgba(np.asarray(image))
    uv = np.asarray(tri_uvs, dtype=np.float64)
    if uv.ndim != 3 or uv.shape[1:] != (3, 2):
        raise ValueError(f"tri_uvs must be (T, 3, 2), got {uv.shape}")
    if not np.isfinite(uv).all():
        raise ValueError("tri_uvs contain NaN or Inf")
    if space not in ("srgb", "linear"):
        raise ValueError(f"space must be 'srgb' or 'linear', got {space!r}")
    if len(uv) == 0:
        return np.zeros((0, 4), dtype=np.float64)
    h, w = img.shape[:2]

    # texel space (x right, y down), each triangle moved by whole periods next to the origin
    pts = np.empty_like(uv)
    pts[..., 0] = uv[..., 0] * w
    pts[..., 1] = (1.0 - uv[..., 1]) * h
    lo = pts.min(axis=1)
    pts[..., 0] -= (np.floor(lo[:, 0] / w) * w)[:, None]
    pts[..., 1] -= (np.floor(lo[:, 1] / h) * h)[:, None]

    f = img.astype(np.float64) / 255.0
    rgb, alpha = f[:, :, :3], f[:, :, 3:]
    if space == "linear":
        rgb = srgb_to_linear(rgb)
    result = np.empty((len(uv), 4), dtype=np.float64)
    pre = _triangle_means(np.concatenate([rgb * alpha, alpha], axis=2), pts)
    result[:, 3] = pre[:, 3]
    clear = result[:, 3] <= 1e-12
    result[~clear, :3] = pre[~clear, :3] / pre[~clear, 3:4]
    if clear.any():
        result[clear, :3] = _triangle_means(rgb, pts[clear])
    if space == "linear":
        result[:, :3] = linear_to_srgb(result[:, :3])
    return np.clip(result, 0.0, 1.0)


_PIECES_PER_CHUNK = 2_000_000  # bounds the temporary arrays (~100 bytes per piece)
_TABLE_BYTES = 256 << 20  # prefix tables of more channels than fit here are built in turns


def _triangle_means(channels: np.ndarray, pts: np.ndarray) -> np.ndarray:
    """(T, C) exact means of periodic piecewise-constant (H, W, C) channels over triangles given
    in texel space ``pts`` (T, 3, 2); see :func:`average_over_triangles`."""
    h, w, n_ch = channels.shape
    t_count = len(pts)
    a_all = pts
    b_all = np.roll(pts, -1, axis=1)
    # pieces per triangle = grid crossings of its edges + 3; chunks of about _PIECES_PER_CHUNK
    cross = np.abs(np.floor(b_all) - np.floor(a_all)).sum(axis=(1, 2)) + 3
    chunk = ((np.cumsum(cross) - cross) // _PIECES_PER_CHUNK).astype(np.int64)
    bounds = [0, *np.flatnonzero(np.diff(chunk)) + 1, t_count]

    means = channels.reshape(-1, n_ch).mean(axis=0)
    per_group = max(1, int(_TABLE_BYTES // (8 * h * (w + 1))))
    out = np.empty((t_count, n_ch), dtype=np.float64)
    for c0 in range(0, n_ch, per_group):
        c = channels[:, :, c0:c0 + per_group] - means[c0:c0 + per_group]  # small prefix sums
        k = c.shape[2]
        prefix = np.zeros((h, w + 1, k), dtype=np.float64)
        np.cumsum(c, axis=1, out=prefix[:, 1:])
        prefix = prefix.reshape(-1, k)
        totals = prefix[w::w + 1]  # P(W) of every row
        for s0, s1 in zip(bounds[:-1], bounds[1:]):
            out[s0:s1, c0:c0 + k] = _chunk_means(prefix, totals, c, pts[s0:s1], h, w)
    return out + means


def _chunk_means(prefix, totals, c, pts, h, w):
    t_count = len(pts)
    a = pts.reshape(-1, 2)
    b = np.roll(pts, -1, axis=1).reshape(-1, 2)
    edge, t0, t1 = _edge_pieces(a, b)
    tri = edge // 3
    dt = t1 - t0
    tm = 0.5 * (t0 + t1)
    d = b - a
    xm = a[edge, 0] + tm * d[edge, 0]
    row = np.floor(a[edge, 1] + tm * d[edge, 1]).astype(np.int64) % h
    dy = dt * d[edge, 1]
    qx = np.floor(xm / w)
    rx = xm - qx * w
    col = np.minimum(rx.astype(np.int64), w - 1)  # rx >= 0
    frac = rx - col
    cell = row * (w + 1) + col  # index into the flattened (H, W + 1) prefix table
    del t0, t1, tm, rx

    area = np.bincount(tri, weights=dy * xm, minlength=t_count)
    piece_len = dt * np.hypot(d[edge, 0], d[edge, 1])
    length = np.bincount(tri, weights=piece_len, minlength=t_count)
    scale = np.maximum(1.0, np.max(np.abs(pts), axis=(1, 2)))
    flat = np.abs(area) <= 1e-9 * scale * scale  # zero area up to rounding
    point = flat & (length <= 1e-12 * scale)
    line = flat & ~point

    # P at the texel's left and right edges (np.take is much faster than fancy indexing here)
    lo = np.take(prefix, cell, axis=0)
    hi = np.take(prefix, cell + 1, axis=0)
    p = qx[:, None] * np.take(totals, row, axis=0) + lo + frac[:, None] * (hi - lo)
    k = prefix.shape[1]
    out = np.empty((t_count, k), dtype=np.float64)
    for j in range(k):
        out[:, j] = np.bincount(tri, weights=dy * p[:, j], minlength=t_count)
    out[~flat] /= area[~flat, None]
    if line.any():  # zero area: length-weighted mean along the edges (texel value = hi - lo)
        on_line = line[tri]
        for j in range(k):
            seg = np.bincount(tri[on_line], minlength=t_count,
                              weights=(piece_len * (hi[:, j] - lo[:, j]))[on_line])
            out[line, j] = seg[line] / length[line]
    if point.any():
        r0 = np.floor(pts[point, 0, 1]).astype(np.int64) % h
        q0 = np.floor(pts[point, 0, 0]).astype(np.int64) % w
        out[point] = c[r0, q0]
    return out
