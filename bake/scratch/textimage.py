"""TextImage format v0 (awesome-llama/TextImage): encoder and decoder.

The format, as a Scratch author reads it, is described in ``docs/formats-textures.md``; the facts
come from ``shared/docs/scratch.md`` section 4a and the reference Python implementation
(``image_io.py``, ``layer_RGB8.py``, ``layer_A8.py``, ``layer_utils.py``, ``cskv_utils.py``).

The encoder reproduces the reference encoder's output byte for byte:

* header ``txtimg,v:0,x:<W>,y:<H>,p:<4L>,<purpose>,<type>,0,<len>,...`` then optional custom
  ``key:value`` attributes, then ``|`` and the data streams concatenated in ``p`` order;
* pixels in stream order: the **bottom row first**, each row left to right;
* per pixel, the first operation that reproduces the colour exactly, tried in the reference order
  (RGB8: copy previous, copy vertical-forward, copy vertical, copy vertical-back, hash table,
  first difference volume in table order, raw; A8: the four copies, increment, decrement, raw);
* a second pass replacing every group of 4..93 consecutive equal opcodes by
  ``[RLE, op, n, data...]`` (runs are cut into groups of 93 first).

One reference quirk is kept on purpose: the reference keeps the last ``W + 2`` pixels in a list and
reads "vertical-forward" as ``list[W - 2]``. For ``W = 1`` that is Python's ``list[-1]``, i.e. the
pixel **3** back, not ``W - 1 = 0`` back. Both the encoder and the decoder use that offset so that
text for 1-pixel-wide images matches the reference and decodes like it.

The encoder is vectorised: since the codec is lossless, "the k-th previously emitted pixel" is just
the input pixel ``k`` positions earlier in stream order, and the hash table's state before pixel
``i`` is "for each slot, the last earlier pixel that hashed there (black if none)", so every
operation can be decided for all pixels at once; the RLE pass uses run-length arithmetic on the
opcode array. The decoder is inherently sequential (a hash-table or difference operation needs the
previous pixels' values) and runs one tight loop over the operations.
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from typing import Literal, Mapping

import numpy as np

from ..errors import InputError

ALPHABET = "".join(chr(c) for c in range(33, 127))  # '!' .. '~', value = ord(c) - 33
BASE = 94
MAGIC = "txtimg"
VERSION = "0"
STREAM_VERSION = "0"
RLE_MAX = 93  # the longest group one RLE operation encodes
MAX_PIXELS = 1 << 26  # the decoder refuses headers asking for more (67M pixels, ~200 MB RGB)

# RGB8 opcodes
RGB8_RAW_LAST = 20  # 0..20: raw, 3 data chars
RGB8_COPY = (22, 23, 24, 25)  # copy previous / vertical-forward / vertical / vertical-back
RGB8_HASH = 26
RGB8_RLE = 27
RGB8_VOLUME_FIRST = 28  # 28..72: volumes 0..44 (1 data char); 73..90: volumes 45..62 (2 chars)
RGB8_UNASSIGNED = frozenset({21, 91, 92, 93})

# A8 opcodes
A8_RAW_LAST = 2  # 0..2: raw, 1 data char
A8_COPY = (3, 4, 5, 6)
A8_RLE = 7
A8_INC_FIRST = 8  # 8..50: previous + (k + 1), k = code - 8
A8_DEC_FIRST = 51  # 51..93: previous - (k + 1), k = code - 51
A8_STEP_MAX = 41  # the encoder uses inc/dec for differences 1..41 only

# The 63 difference volumes: origin (oY, oU, oV), dims (d0, d1, d2); opcode = 28 + volume index.
# A colour difference (dR, dG, dB) is written as (dY, dU, dV) = (dG, dB - dG, dR - dG).
VOLUMES: tuple[tuple[tuple[int, int, int], tuple[int, int, int]], ...] = tuple(
    [((oy, ou, ov), (5, 4, 4)) for oy, ou, ov in (
        (-2, -1, -1), (-2, 3, -1), (-2, -5, -1), (-2, -5, 2), (-2, 3, 2), (-2, -1, 2),
        (-2, -5, -5), (-2, 3, -5), (-2, -1, -5),
        (3, -1, -5), (3, 3, -5), (3, -5, -5), (3, -1, 2), (3, 3, 2), (3, -5, 2),
        (3, -5, -1), (3, 3, -1), (3, -1, -1),
        (8, -1, -1), (8, 3, -1), (8, -5, -1), (8, -5, 2), (8, 3, 2), (8, -1, 2),
        (8, -5, -5), (8, 3, -5), (8, -1, -5),
        (-7, -1, -5), (-7, 3, -5), (-7, -5, -5), (-7, -1, 2), (-7, 3, 2), (-7, -5, 2),
        (-7, -5, -1), (-7, 3, -1), (-7, -1, -1),
        (-12, -1, -1), (-12, 3, -1), (-12, -5, -1), (-12, -5, 2), (-12, 3, 2), (-12, -1, 2),
        (-12, -5, -5), (-12, 3, -5), (-12, -1, -5),
    )]
    + [((oy, ou, ov), (21, 20, 20)) for oy, ou, ov in (
        (-10, 7, -9), (-10, -25, -9), (-10, -9, 7), (-10, -9, -24),
        (11, -9, -8), (-31, -9, -8), (32, -9, -8), (-52, -9, -8), (53, -9, -8), (-73, -9, -8),
        (11, -9, -24), (11, -9, 7), (11, -25, -9), (11, 7, -9),
        (-31, 7, -9), (-31, -25, -9), (-31, -9, 7), (-10, 11, -29),
    )]
)
N_VOLUMES_SIZE1 = 45  # volumes 0..44 use 1 data char (80 cells), 45..62 use 2 (8400 cells)


class TextImageError(InputError, ValueError):
    """Malformed TextImage text, or an image the encoder cannot write. Also a ``ValueError``."""


@dataclass(frozen=True)
class Layer:
    """One entry of the header's ``p`` list."""

    purpose: str  # "main" (colour) or "alpha"; other purposes are carried but not decoded
    type: str  # "RGB8" or "A8"
    version: str  # "0"
    length: int  # data stream length in characters


@dataclass(frozen=True)
class Header:
    width: int
    height: int
    layers: tuple[Layer, ...]
    attributes: Mapping[str, str | tuple[str, ...]] = field(default_factory=dict)
    data_start: int = 0  # index in the text of the first data character (just after the '|')


# --------------------------------------------------------------------------------------------
# shared helpers


def copy_offsets(width: int) -> tuple[int, int, int, int]:
    """How many pixels back the four copy operations look: previous, vertical-forward (row below,
    x + 1), vertical (row below), vertical-back (row below, x - 1). ``width == 1`` reproduces the
    reference's ``list[-1]`` quirk (vertical-forward = 3 back)."""
    return (1, width - 1 if width >= 2 else width + 2, width, width + 1)


def to_stream_order(image: np.ndarray) -> np.ndarray:
    """``(H, W, C)`` image -> ``(H*W, C)`` pixels, bottom row first, each row left to right."""
    h, w = image.shape[:2]
    return np.ascontiguousarray(image[::-1]).reshape(h * w, *image.shape[2:])


def from_stream_order(pixels: np.ndarray, width: int, height: int) -> np.ndarray:
    """Inverse of :func:`to_stream_order`."""
    return np.ascontiguousarray(pixels.reshape(height, width, *pixels.shape[1:])[::-1])


def _shifted(a: np.ndarray, k: int) -> np.ndarray:
    """``out[i] = a[i - k]``, 0 before the start (the codec's initial black / 0)."""
    out = np.zeros_like(a)
    if k < len(a):
        out[k:] = a[: len(a) - k]
    return out


def _emit(op: np.ndarray, data: np.ndarray, size: np.ndarray, rle_code: int) -> str:
    """Per-pixel opcodes and data chars -> stream text, with the reference RLE pass.

    Consecutive equal opcodes form runs; a run is cut into groups of 93 (the last group takes the
    remainder) and a group of n >= 4 becomes ``[rle_code, op, n, data of each pixel]`` (that is
    when ``3 + n*size < n*(1 + size)``); shorter groups are written as they are.
    """
    n = len(op)
    if n == 0:
        return ""
    start = np.empty(n, dtype=bool)
    start[0] = True
    np.not_equal(op[1:], op[:-1], out=start[1:])
    run_first = np.flatnonzero(start)
    run_len = np.diff(np.append(run_first, n))
    run_id = np.cumsum(start) - 1
    pos = np.arange(n) - run_first[run_id]
    group = pos // RLE_MAX
    group_len = np.minimum(RLE_MAX, run_len[run_id] - group * RLE_MAX)
    rle = group_len >= 4
    header = rle & (pos % RLE_MAX == 0)
    op_char = ~rle
    count = header * 3 + op_char + size.astype(np.int64)
    ends = np.cumsum(count)
    offs = ends - count
    buf = np.empty(int(ends[-1]), dtype=np.uint8)
    h = np.flatnonzero(header)
    buf[offs[h]] = rle_code
    buf[offs[h] + 1] = op[h]
    buf[offs[h] + 2] = group_len[h]
    o = np.flatnonzero(op_char)
    buf[offs[o]] = op[o]
    first_data = offs + header * 3 + op_char
    for j in range(3):
        m = np.flatnonzero(size > j)
        buf[first_data[m] + j] = data[m, j]
    buf += 33
    return buf.tobytes().decode("ascii")


def _hash(rgb: np.ndarray) -> np.ndarray:
    return (3 * rgb[:, 0] + 5 * rgb[:, 1] + 7 * rgb[:, 2]) % BASE


def _previous_same(keys: np.ndarray) -> np.ndarray:
    """For each i, the largest j < i with keys[j] == keys[i], or -1."""
    order = np.argsort(keys, kind="stable")
    sk = keys[order]
    same = sk[1:] == sk[:-1]
    prev = np.full(len(keys), -1, dtype=np.int64)
    prev[order[1:][same]] = order[:-1][same]
    return prev


# --------------------------------------------------------------------------------------------
# stream encoders


def encode_rgb8(pixels: np.ndarray, width: int) -> str:
    """RGB8 data stream for ``(N, 3)`` uint8 pixels already in stream order."""
    px = np.asarray(pixels).astype(np.int64, copy=False).reshape(-1, 3)
    n = len(px)
    if n == 0:
        return ""
    packed = (px[:, 0] << 16) | (px[:, 1] << 8) | px[:, 2]
    op = np.full(n, -1, dtype=np.int64)
    data = np.zeros((n, 3), dtype=np.int64)
    size = np.zeros(n, dtype=np.int64)

    # 1-4: copies
    for code, k in zip(RGB8_COPY, copy_offsets(width)):
        free = op < 0
        op[free & (packed == _shifted(packed, k))] = code

    # 5: hash table. Before pixel i, slot s holds the last earlier pixel whose colour hashes to s,
    # or the initial black. A non-black colour can only sit in its own slot; black sits in slot 0
    # (its hash) and in every slot nothing has been written to yet, and the reference takes the
    # first slot that matches.
    free = np.flatnonzero(op < 0)
    if free.size:
        slot = _hash(px)
        last = _previous_same(slot)
        lf = last[free]
        held = np.where(lf >= 0, packed[np.maximum(lf, 0)], 0)
        colour = packed[free]
        hit_slot = np.where(held == colour, slot[free], -1)
        black_miss = np.flatnonzero((colour == 0) & (hit_slot < 0))
        if black_miss.size:
            first_seen = np.full(BASE, n, dtype=np.int64)
            np.minimum.at(first_seen, slot, np.arange(n))
            at = free[black_miss]
            best = np.full(black_miss.size, -1, dtype=np.int64)
            for s in range(BASE - 1, 0, -1):  # lowest untouched slot s >= 1
                best[first_seen[s] >= at] = s
            hit_slot[black_miss] = best
        hit = hit_slot >= 0
        op[free[hit]] = RGB8_HASH
        data[free[hit], 0] = hit_slot[hit]
        size[free[hit]] = 1

    # 6: the first difference volume containing (dY, dU, dV) of (this - previous pixel)
    rest = np.flatnonzero(op < 0)
    if rest.size:
        d = px[rest] - _shifted(px, 1)[rest]
        dy = d[:, 1]
        du = d[:, 2] - dy
        dv = d[:, 0] - dy
        for vol, ((oy, ou, ov), (d0, d1, d2)) in enumerate(VOLUMES):
            ry, ru, rv = dy - oy, du - ou, dv - ov
            inside = (ry >= 0) & (ry < d0) & (ru >= 0) & (ru < d1) & (rv >= 0) & (rv < d2)
            if inside.any():
                at = rest[inside]
                index = (ry[inside] * d1 + ru[inside]) * d2 + rv[inside]
                op[at] = RGB8_VOLUME_FIRST + vol
                if vol < N_VOLUMES_SIZE1:
                    data[at, 0] = index
                    size[at] = 1
                else:
                    data[at, 0] = index // BASE
                    data[at, 1] = index % BASE
                    size[at] = 2
                keep = ~inside
                rest, dy, du, dv = rest[keep], dy[keep], du[keep], dv[keep]
                if not rest.size:
                    break

    # 7: raw, R*65536 + G*256 + B in the mixed base (21, 94, 94, 94)
    if rest.size:
        dec = packed[rest]
        op[rest] = dec // BASE**3
        rem = dec % BASE**3
        data[rest, 0] = rem // BASE**2
        data[rest, 1] = (rem // BASE) % BASE
        data[rest, 2] = rem % BASE
        size[rest] = 3
    return _emit(op, data, size, RGB8_RLE)


def encode_a8(values: np.ndarray, width: int) -> str:
    """A8 data stream for ``(N,)`` uint8 values already in stream order."""
    v = np.asarray(values).astype(np.int64, copy=False).reshape(-1)
    n = len(v)
    if n == 0:
        return ""
    op = np.full(n, -1, dtype=np.int64)
    data = np.zeros((n, 3), dtype=np.int64)
    size = np.zeros(n, dtype=np.int64)
    for code, k in zip(A8_COPY, copy_offsets(width)):
        free = op < 0
        op[free & (v == _shifted(v, k))] = code
    diff = (v - _shifted(v, 1) + 128) % 256 - 128
    free = op < 0
    inc = free & (diff > 0) & (diff <= A8_STEP_MAX)
    op[inc] = A8_INC_FIRST + diff[inc] - 1
    dec = free & (diff < 0) & (diff >= -A8_STEP_MAX)
    op[dec] = A8_DEC_FIRST - 1 - diff[dec]
    raw = op < 0
    op[raw] = v[raw] // BASE
    data[raw, 0] = v[raw] % BASE
    size[raw] = 1
    return _emit(op, data, size, A8_RLE)


# --------------------------------------------------------------------------------------------
# whole images


_ATTR_OK = re.compile(r"[!-~]+")  # printable ASCII without space


def _check_attribute(text: str, what: str) -> str:
    text = str(text)
    if not _ATTR_OK.fullmatch(text) or any(c in text for c in ",:|"):
        raise TextImageError(f"TextImage attribute {what} {text!r} must be printable ASCII "
                             "without spaces, ',', ':' or '|'")
    return text


def write_text(width: int, height: int, layers: list[tuple[str, str, str]],
               attributes: Mapping[str, object] | None = None) -> str:
    """Assemble a TextImage from ``(purpose, type, stream)`` layers, in the reference's layout."""
    items = [MAGIC, f"v:{VERSION}", f"x:{int(width)}", f"y:{int(height)}"]
    props: list[str] = []
    for purpose, typ, stream in layers:
        props += [purpose, typ, STREAM_VERSION, str(len(stream))]
    items.append(f"p:{len(props)}," + ",".join(props))
    for key, value in (attributes or {}).items():
        key = _check_attribute(key, "key")
        if key in ("v", "x", "y", "p"):
            raise TextImageError(f"TextImage attribute key {key!r} is reserved")
        items.append(f"{key}:{_check_attribute(value, 'value')}")
    return ",".join(items) + "|" + "".join(stream for _, _, stream in layers)


def _as_uint8_image(image: np.ndarray) -> np.ndarray:
    a = np.asarray(image)
    if a.dtype != np.uint8:
        if not np.issubdtype(a.dtype, np.integer):
            raise TextImageError(f"TextImage encoder needs uint8 pixels, got {a.dtype} "
                                 "(convert floats in [0, 1] with bake.colorspace.to_bytes)")
        if a.size and (a.min() < 0 or a.max() > 255):
            raise TextImageError("TextImage encoder needs pixel values in 0..255")
        a = a.astype(np.uint8)
    if a.ndim == 3 and a.shape[2] == 1:
        a = a[:, :, 0]
    if a.ndim not in (2, 3) or (a.ndim == 3 and a.shape[2] not in (3, 4)):
        raise TextImageError("expected an (H, W), (H, W, 3) or (H, W, 4) image, "
                             f"got shape {a.shape}")
    return a


def encode(image: np.ndarray, alpha: bool | Literal["auto"] = "auto", *,
           attributes: Mapping[str, object] | None = None) -> str:
    """Encode a uint8 image as TextImage v0 text (one line, no spaces).

    ``image``: ``(H, W, 3)`` RGB or ``(H, W, 4)`` RGBA, row 0 at the top (the usual image layout;
    the stream itself is written bottom row first). ``(H, W)`` greyscale is written as an ``A8``
    main layer, as the reference does for Pillow mode ``L``.

    ``alpha``: ``"auto"`` writes an ``alpha`` (A8) layer when the image has 4 channels and at least
    one pixel is not fully opaque; ``True`` always writes one (255 for RGB input); ``False`` never
    does. The reference writes the alpha layer whenever the source image is RGBA, even when every
    pixel is opaque: pass ``alpha=True`` to reproduce that for an opaque RGBA image.

    ``attributes``: extra ``key:value`` header items written after ``p`` (ignored by decoders).
    """
    a = _as_uint8_image(image)
    h, w = a.shape[:2]
    layers: list[tuple[str, str, str]] = []
    if a.ndim == 2:
        layers.append(("main", "A8", encode_a8(to_stream_order(a), w)))
        if alpha is True:
            layers.append(("alpha", "A8", encode_a8(np.full(h * w, 255, np.uint8), w)))
        return write_text(w, h, layers, attributes)
    layers.append(("main", "RGB8", encode_rgb8(to_stream_order(a[:, :, :3]), w)))
    if alpha == "auto":
        want = a.shape[2] == 4 and bool((a[:, :, 3] != 255).any())
    elif alpha is True or alpha is False:
        want = alpha
    else:
        raise TextImageError(f"alpha must be 'auto', True or False, got {alpha!r}")
    if want:
        av = a[:, :, 3] if a.shape[2] == 4 else np.full((h, w), 255, np.uint8)
        layers.append(("alpha", "A8", encode_a8(to_stream_order(av), w)))
    return write_text(w, h, layers, attributes)


# --------------------------------------------------------------------------------------------
# decoding


def _err(message: str) -> TextImageError:
    return TextImageError(f"TextImage: {message}")


_UINT = re.compile(r"[0-9]+")


def _uint(value: str, what: str) -> int:
    if not _UINT.fullmatch(value):
        raise _err(f"{what} must be a non-negative integer, got {value[:40]!r}")
    return int(value)


def _strip(text: str) -> str:
    # Editors add a BOM or a final newline; neither is ever part of TextImage data.
    return text.lstrip("\ufeff \t\r\n").rstrip(" \t\r\n")


def read_header(text: str) -> Header:
    """Parse and check the header of TextImage text (not the data)."""
    if not isinstance(text, str):
        raise _err(f"expected text (str), got {type(text).__name__}")
    lead = len(text) - len(text.lstrip("\ufeff \t\r\n"))
    body = _strip(text)
    bar = body.find("|")
    if bar < 0:
        raise _err("no '|' between the header and the data")
    items = body[:bar].split(",")
    if items[0] != MAGIC:
        raise _err(f"header must start with {MAGIC!r}, got {items[0][:40]!r}")
    values: dict[str, list[str]] = {}
    current = None
    for item in items[1:]:
        if ":" in item:
            key, _, value = item.partition(":")
            if ":" in value:
                raise _err(f"header item {item[:40]!r} has more than one ':'")
            if key in values:
                raise _err(f"header key {key!r} appears twice")
            values[key] = [value]
            current = key
        elif current is None:
            raise _err(f"header item {item[:40]!r} is not key:value")
        else:
            values[current].append(item)
    for key in ("v", "x", "y", "p"):
        if key not in values:
            raise _err(f"header has no {key!r}")
    if values["v"] != [VERSION]:
        raise _err(f"unsupported version v:{','.join(values['v'])[:20]} (only v:0 is known)")
    for key in ("x", "y"):
        if len(values[key]) != 1:
            raise _err(f"{key!r} must be one number")
    width = _uint(values["x"][0], "x (width)")
    height = _uint(values["y"][0], "y (height)")
    if width * height > MAX_PIXELS:
        raise _err(f"{width}x{height} is more than {MAX_PIXELS} pixels")
    p = values["p"]
    count = _uint(p[0], "p (layer list length)")
    if count != len(p) - 1:
        raise _err(f"p says {count} items but {len(p) - 1} follow")
    if count % 4:
        raise _err(f"p must hold 4 items per layer, got {count}")
    layers = []
    for i in range(1, len(p), 4):
        purpose, typ, version, length = p[i:i + 4]
        layers.append(Layer(purpose, typ, version, _uint(length, f"length of layer {purpose!r}")))
    attributes = {k: (v[0] if len(v) == 1 else tuple(v))
                  for k, v in values.items() if k not in ("v", "x", "y", "p")}
    return Header(width, height, tuple(layers), attributes, lead + bar + 1)


def _codes(stream: str, what: str) -> list[int]:
    try:
        raw = stream.encode("ascii")
    except UnicodeEncodeError as e:
        raise _err(f"{what} stream has a non-ASCII character at {e.start}") from None
    arr = np.frombuffer(raw, dtype=np.uint8)
    bad = np.flatnonzero((arr < 33) | (arr > 126))
    if bad.size:
        raise _err(f"{what} stream has invalid character {chr(arr[bad[0]])!r} at {bad[0]} "
                   "(only '!' .. '~' are allowed)")
    return (arr.astype(np.int64) - 33).tolist()


def _volume_table(dims: tuple[int, int, int], origin: tuple[int, int, int], cells: int):
    d0, d1, d2 = dims
    oy, ou, ov = origin
    out = []
    for i in range(cells):
        dy = i // (d1 * d2) % d0 + oy
        du = (i // d2) % d1 + ou
        dv = i % d2 + ov
        out.append((dv + dy, dy, du + dy))  # (dR, dG, dB)
    return out


# (dR, dG, dB) for every data value of every volume, decoded with the spec's formula (an index past
# the volume's cells wraps in Y, as the reference decoder does).
_VOLUME_DELTAS = [
    _volume_table(dims, origin, BASE if v < N_VOLUMES_SIZE1 else BASE * BASE)
    for v, (origin, dims) in enumerate(VOLUMES)
]


def _too_long(what: str, count: int) -> TextImageError:
    return _err(f"{what} stream holds more than the {count} pixels of the image")


def decode_rgb8(stream: str, width: int, count: int) -> np.ndarray:
    """Decode an RGB8 data stream of ``count`` pixels -> ``(count, 3)`` uint8 in stream order."""
    codes = _codes(stream, "RGB8")
    n = len(codes)
    if count > 31 * n:  # one RLE op (3 chars) gives at most 93 pixels
        raise _err(f"RGB8 stream of {n} chars cannot hold {count} pixels")
    k1, kf, kv, kb = copy_offsets(width)
    table = [0] * BASE
    out = [0] * count
    vol = _VOLUME_DELTAS
    p = i = 0
    rep_op = rep_left = 0
    try:
        while True:
            if rep_left:
                op = rep_op
                rep_left -= 1
            else:
                if i >= n:
                    break
                op = codes[i]
                i += 1
                if op == RGB8_RLE:
                    rep_op, rep_left = codes[i], codes[i + 1]
                    i += 2
                    if rep_op == RGB8_RLE or rep_op in RGB8_UNASSIGNED:
                        raise _err(f"RGB8 RLE of opcode {rep_op} at char {i - 2}")
                    continue
            if p >= count:
                raise _too_long("RGB8", count)
            if op <= RGB8_RAW_LAST:
                c = (op * 830584 + codes[i] * 8836 + codes[i + 1] * 94 + codes[i + 2]) & 0xFFFFFF
                i += 3
            elif op == 22:
                c = out[p - k1] if p >= k1 else 0
            elif op == 23:
                c = out[p - kf] if p >= kf else 0
            elif op == 24:
                c = out[p - kv] if p >= kv else 0
            elif op == 25:
                c = out[p - kb] if p >= kb else 0
            elif op == RGB8_HASH:
                c = table[codes[i]]
                i += 1
            elif RGB8_VOLUME_FIRST <= op <= 90:
                v = op - RGB8_VOLUME_FIRST
                if v < N_VOLUMES_SIZE1:
                    dr, dg, db = vol[v][codes[i]]
                    i += 1
                else:
                    dr, dg, db = vol[v][codes[i] * 94 + codes[i + 1]]
                    i += 2
                prev = out[p - 1] if p else 0
                r = (prev >> 16) + dr
                g = ((prev >> 8) & 255) + dg
                b = (prev & 255) + db
                if not (0 <= r <= 255 and 0 <= g <= 255 and 0 <= b <= 255):
                    raise _err(f"RGB8 difference op {op} at pixel {p} leaves 0..255")
                c = (r << 16) | (g << 8) | b
            else:
                raise _err(f"unknown RGB8 opcode {op} ({ALPHABET[op]!r}) at char {i - 1}")
            out[p] = c
            p += 1
            table[(3 * (c >> 16) + 5 * ((c >> 8) & 255) + 7 * (c & 255)) % 94] = c
    except IndexError:
        raise _err("RGB8 stream ends in the middle of an operation") from None
    if p != count:
        raise _err(f"RGB8 stream holds {p} pixels, the image has {count}")
    packed = np.array(out, dtype=np.int64)
    return np.stack([packed >> 16, (packed >> 8) & 255, packed & 255], axis=1).astype(np.uint8)


def decode_a8(stream: str, width: int, count: int) -> np.ndarray:
    """Decode an A8 data stream of ``count`` values -> ``(count,)`` uint8 in stream order."""
    codes = _codes(stream, "A8")
    n = len(codes)
    if count > 31 * n:
        raise _err(f"A8 stream of {n} chars cannot hold {count} pixels")
    k1, kf, kv, kb = copy_offsets(width)
    out = [0] * count
    p = i = 0
    rep_op = rep_left = 0
    try:
        while True:
            if rep_left:
                op = rep_op
                rep_left -= 1
            else:
                if i >= n:
                    break
                op = codes[i]
                i += 1
                if op == A8_RLE:
                    rep_op, rep_left = codes[i], codes[i + 1]
                    i += 2
                    if rep_op == A8_RLE:
                        raise _err(f"A8 RLE of the RLE opcode at char {i - 2}")
                    continue
            if p >= count:
                raise _too_long("A8", count)
            if op <= A8_RAW_LAST:
                c = op * 94 + codes[i]
                i += 1
                if c > 255:
                    raise _err(f"A8 raw value {c} at pixel {p} is above 255")
            elif op == 3:
                c = out[p - k1] if p >= k1 else 0
            elif op == 4:
                c = out[p - kf] if p >= kf else 0
            elif op == 5:
                c = out[p - kv] if p >= kv else 0
            elif op == 6:
                c = out[p - kb] if p >= kb else 0
            elif op < A8_DEC_FIRST:
                c = ((out[p - 1] if p else 0) + op - A8_INC_FIRST + 1) & 255
            else:
                c = ((out[p - 1] if p else 0) - (op - A8_DEC_FIRST + 1)) & 255
            out[p] = c
            p += 1
    except IndexError:
        raise _err("A8 stream ends in the middle of an operation") from None
    if p != count:
        raise _err(f"A8 stream holds {p} pixels, the image has {count}")
    return np.array(out, dtype=np.uint8)


def decode_layers(text: str) -> tuple[Header, dict[str, np.ndarray]]:
    """Decode every ``main`` / ``alpha`` layer: ``{"main": (H, W, 3) or (H, W), "alpha": (H, W)}``
    (row 0 at the top). Layers with other purposes are checked for length and skipped."""
    header = read_header(text)
    body = text[header.data_start:].rstrip(" \t\r\n")
    total = sum(layer.length for layer in header.layers)
    if total != len(body):
        raise _err(f"data is {len(body)} chars but the header declares {total}")
    w, h = header.width, header.height
    out: dict[str, np.ndarray] = {}
    pos = 0
    for layer in header.layers:
        stream = body[pos:pos + layer.length]
        pos += layer.length
        if layer.purpose not in ("main", "alpha"):
            continue
        if layer.purpose in out:
            raise _err(f"two {layer.purpose!r} layers")
        if layer.version != STREAM_VERSION:
            raise _err(f"layer {layer.purpose!r} has unsupported version {layer.version!r}")
        if layer.type == "RGB8" and layer.purpose == "main":
            out["main"] = from_stream_order(decode_rgb8(stream, w, w * h), w, h)
        elif layer.type == "A8":
            out[layer.purpose] = from_stream_order(decode_a8(stream, w, w * h), w, h)
        else:
            raise _err(f"layer {layer.purpose!r} has unsupported type {layer.type!r}")
    return header, out


def decode(text: str, channels: Literal[3, 4] | None = None) -> np.ndarray:
    """Decode TextImage text -> uint8 image, row 0 at the top.

    The result is ``(H, W, 4)`` when the text has an ``alpha`` layer and ``(H, W, 3)`` otherwise;
    ``channels`` forces 3 (alpha dropped) or 4 (255 added when there is no alpha layer). A missing
    ``main`` layer decodes as black, an ``A8`` main layer as grey. Malformed text raises
    :class:`TextImageError` (a ``ValueError``) naming the problem.
    """
    if channels not in (None, 3, 4):
        raise ValueError(f"channels must be None, 3 or 4, got {channels!r}")
    header, layers = decode_layers(text)
    h, w = header.height, header.width
    main = layers.get("main")
    if main is None:
        rgb = np.zeros((h, w, 3), dtype=np.uint8)
    elif main.ndim == 2:
        rgb = np.repeat(main[:, :, None], 3, axis=2)
    else:
        rgb = main
    alpha = layers.get("alpha")
    if channels == 3 or (channels is None and alpha is None):
        return rgb
    if alpha is None:
        alpha = np.full((h, w), 255, dtype=np.uint8)
    return np.concatenate([rgb, alpha[:, :, None]], axis=2)
