"""Texture colours: Scratch colour numbers and image <-> colour lists (bake.scratch.colors), and
texture loading, resampling and per-triangle averages (bake.textures.images).

The triangle average is checked against an exact brute force written here: every texel the
triangle's bounding box touches is clipped against the triangle (Sutherland-Hodgman, one Python
loop per texel) and weighted by the clipped area.
"""

from __future__ import annotations

import io
import json
import math
import struct

import numpy as np
import pytest
from hypothesis import given, settings, strategies as st
from PIL import Image

from bake.errors import InputError
from bake.scratch import colors
from bake.textures import images
from bake.scratch.colors import (decode_numbers, image_to_list, js_to_number, list_to_image,
                                  numbers_from_bytes, scratch_color, scratch_numbers)

# ---------------------------------------------------------------------------------------------
# colour numbers


def test_scratch_numbers_unchanged():
    cols = np.array([[1, 0, 0, 1], [0, 1, 0, 0], [0, 0, 1, 0.5], [1, 1, 1, 1]], float)
    assert scratch_numbers(cols, "rgb").tolist() == [16711680, 65280, 255, 16777215]
    assert scratch_numbers(cols, "argb").tolist() == [
        255 * 2**24 + 16711680, 1 * 2**24 + 65280, 128 * 2**24 + 255, 255 * 2**24 + 16777215]
    assert scratch_numbers(cols[:, :3], "argb").tolist()[0] == 255 * 2**24 + 16711680
    assert scratch_numbers(cols, "hex") == ["#ff0000", "#00ff00", "#0000ff", "#ffffff"]
    assert scratch_numbers(np.array([[np.nan, 2.0, -1.0]]), "rgb").tolist() == [0x00ff00]
    with pytest.raises(ValueError):
        scratch_numbers(cols, "rgba")
    with pytest.raises(ValueError):
        scratch_numbers(np.zeros((3, 2)))


def test_numbers_from_bytes_matches_float_path():
    b = np.random.default_rng(0).integers(0, 256, (500, 4), dtype=np.uint8)
    for mode in colors.MODES:
        fast = numbers_from_bytes(b, mode)
        slow = scratch_numbers(b / 255.0, mode)
        assert (fast == slow) if mode == "hex" else np.array_equal(fast, slow)
    with pytest.raises(ValueError):
        numbers_from_bytes(b / 255.0)


@pytest.mark.parametrize("value, rgba", [
    (16711680, (255, 0, 0, 255)),
    ("16711680", (255, 0, 0, 255)),
    ("0x80ff0000", (255, 0, 0, 128)),  # 49.8 % pen transparency
    (2164195328, (255, 0, 0, 128)),
    (4278190335, (0, 0, 255, 255)),  # >= 2^31: still opaque blue through ToInt32
    (-1, (255, 255, 255, 255)),
    (16777215.9, (255, 255, 255, 255)),
    (1 * 2**24 + 65280, (0, 255, 0, 1)),  # A = 1: 99.6 % transparency
    (65280, (0, 255, 0, 255)),  # A = 0 is opaque
    ("#f00", (255, 0, 0, 255)),
    ("#00FF7f", (0, 255, 127, 255)),
    ("#ff00", (0, 0, 0, 255)),  # invalid hex -> black
    ("##fff", (0, 0, 0, 255)),
    ("#fff\n", (0, 0, 0, 255)),
    ("banana", (0, 0, 0, 255)),  # junk -> 0
    ("", (0, 0, 0, 255)),
    (" 255 ", (0, 0, 255, 255)),
    ("1e3", (0, 3, 232, 255)),
    ("Infinity", (0, 0, 0, 255)),
    (float("nan"), (0, 0, 0, 255)),
    (True, (0, 0, 1, 255)),
    (2**32 + 5, (0, 0, 5, 255)),
])
def test_scratch_color(value, rgba):
    assert scratch_color(value) == rgba


def test_js_to_number():
    assert js_to_number("0b101") == 5 and js_to_number("0o17") == 15
    assert js_to_number("-0x10") == 0  # Number("-0x10") is NaN
    assert js_to_number(".5") == 0.5 and js_to_number("5.") == 5 and js_to_number(".") == 0
    assert js_to_number("1_000") == 0 and js_to_number("\t-2.5e1\n") == -25
    assert js_to_number("-Infinity") == -math.inf


def test_decode_numbers_vectorised_equals_scalar():
    r = np.random.default_rng(1)
    ints = np.concatenate([r.integers(-2**40, 2**40, 2000), r.integers(0, 2**32, 2000)])
    fast = decode_numbers(ints)
    slow = np.array([scratch_color(int(v)) for v in ints], np.uint8)
    assert np.array_equal(fast, slow)
    assert np.array_equal(decode_numbers([str(int(v)) for v in ints[:300]]), slow[:300])


# ---------------------------------------------------------------------------------------------
# image <-> list


def test_image_to_list_pixel_order():
    img = np.zeros((2, 3, 3), np.uint8)
    img[..., 0] = np.arange(6).reshape(2, 3)  # R = 3*row + column, row 0 at the top
    top = image_to_list(img, "rgb", "top")
    bottom = image_to_list(img, "rgb", "bottom")
    assert (top >> 16).tolist() == [0, 1, 2, 3, 4, 5]  # Img2list: top row first
    assert (bottom >> 16).tolist() == [3, 4, 5, 0, 1, 2]  # TextImage / Scratch y-up
    with pytest.raises(ValueError):
        image_to_list(img, "rgb", "left")
    with pytest.raises(ValueError):
        image_to_list(img.astype(float), "rgb")


@settings(max_examples=60, deadline=None)
@given(st.integers(1, 9), st.integers(1, 9), st.sampled_from(colors.MODES),
       st.sampled_from(colors.FIRST_ROWS), st.integers(0, 2**31))
def test_list_round_trip(h, w, mode, first_row, seed):
    img = np.random.default_rng(seed).integers(0, 256, (h, w, 4), dtype=np.uint8)
    img[0, 0, 3] = 0
    items = image_to_list(img, mode, first_row)
    back = list_to_image(items, w, h, first_row)
    assert back.shape == (h, w, 4)
    assert np.array_equal(back[:, :, :3], img[:, :, :3])
    if mode == "argb":  # alpha survives, except fully transparent which becomes A = 1
        assert np.array_equal(back[:, :, 3], np.maximum(img[:, :, 3], 1))
    else:
        assert (back[:, :, 3] == 255).all()
    as_text = [str(v) for v in items] if mode != "hex" else items  # list items are strings
    assert np.array_equal(list_to_image(as_text, w, h, first_row), back)


def test_list_to_image_size_check():
    with pytest.raises(ValueError):
        list_to_image([1, 2, 3], 2, 2)


# ---------------------------------------------------------------------------------------------
# loading


def glb_image_bytes(path):
    data = path.read_bytes()
    jlen = struct.unpack_from("<I", data, 12)[0]
    doc = json.loads(data[20:20 + jlen])
    view = doc["bufferViews"][doc["images"][0]["bufferView"]]
    off = 20 + jlen + 8 + view.get("byteOffset", 0)
    return data[off:off + view["byteLength"]]


def test_load_corpus_textures(corpus):
    duck = glb_image_bytes(corpus("duck_glb", "Duck.glb"))
    a = images.load_rgba(duck)
    ref = np.asarray(Image.open(io.BytesIO(duck)).convert("RGBA"))
    assert a.dtype == np.uint8 and a.shape == ref.shape and np.array_equal(a, ref)
    logo = images.load_rgba(corpus("box_textured_gltf_separate", "CesiumLogoFlat.png"))
    assert logo.ndim == 3 and logo.shape[2] == 4
    jpg = images.load_rgba(str(corpus("capsule_textured", "capsule0.jpg")))
    assert jpg.shape[2] == 4 and (jpg[:, :, 3] == 255).all()


def test_load_modes(tmp_path):
    pal = Image.new("P", (3, 1))
    pal.putpalette([255, 0, 0, 0, 255, 0, 0, 0, 255] + [0] * 759)
    pal.putdata([0, 1, 2])
    pal.info["transparency"] = 1
    pal.save(tmp_path / "p.png")
    got = images.load_rgba(tmp_path / "p.png")
    assert got.tolist() == [[[255, 0, 0, 255], [0, 255, 0, 0], [0, 0, 255, 255]]]

    deep = np.array([[0, 257 * 100, 65535]], np.uint16)
    Image.fromarray(deep).save(tmp_path / "16.png")
    got = images.load_rgba(tmp_path / "16.png")
    assert got[0, :, 0].tolist() == [0, 100, 255] and (got[..., 3] == 255).all()

    la = Image.fromarray(np.array([[[10, 20]]], np.uint8))  # 2 channels: LA
    assert images.load_rgba(la).tolist() == [[[10, 10, 10, 20]]]
    assert images.load_rgba(np.array([[0.5]])).tolist() == [[[128, 128, 128, 255]]]
    assert images.load_rgba(np.array([[[1, 2, 3]]], np.uint8)).tolist() == [[[1, 2, 3, 255]]]


def test_load_errors(tmp_path):
    with pytest.raises(InputError) as e:
        images.load_rgba(tmp_path / "missing.png")
    assert "missing.png" in str(e.value)
    (tmp_path / "bad.png").write_bytes(b"\x89PNG\r\n\x1a\nnot really")
    with pytest.raises(InputError) as e:
        images.load_rgba(tmp_path / "bad.png")
    assert "bad.png" in str(e.value)
    with pytest.raises(InputError) as e:
        images.load_rgba(b"garbage", name="model.glb#image0")
    assert "model.glb#image0" in str(e.value)


# ---------------------------------------------------------------------------------------------
# sizes and resampling


@pytest.mark.parametrize("args, kw, out", [
    ((1000, 500), dict(max_size=256), (256, 128)),
    ((100, 50), dict(max_size=256), (100, 50)),
    ((300, 200), dict(power_of_two="floor"), (256, 128)),
    ((300, 200), dict(power_of_two="ceil"), (512, 256)),
    ((300, 200), dict(power_of_two="nearest"), (256, 256)),
    ((30, 20), dict(size=(30, 20), power_of_two="nearest"), (32, 16)),
    ((7, 9), dict(size=64), (64, 64)),
    ((1000, 1000), dict(max_size=200, power_of_two="ceil"), (128, 128)),
    ((5000, 3), dict(max_size=64), (64, 1)),
    ((1, 1), dict(power_of_two="ceil"), (1, 1)),
])
def test_fit_size(args, kw, out):
    assert images.fit_size(*args, **kw) == out


def test_resample_nearest_and_box():
    r = np.random.default_rng(2)
    img = r.integers(0, 256, (5, 7, 4), dtype=np.uint8)
    img[..., 3] = 255
    up = images.resample(img, (14, 10), "nearest")
    assert np.array_equal(up, np.repeat(np.repeat(img, 2, 0), 2, 1))
    big = r.integers(0, 256, (16, 12, 4), dtype=np.uint8)
    big[..., 3] = 255
    down = images.resample(big, (6, 8), "box").astype(float)
    mean = big.reshape(8, 2, 6, 2, 4).mean(axis=(1, 3))
    assert np.abs(down - mean).max() <= 1.0
    assert np.array_equal(images.resample(img, (7, 5)), img)
    with pytest.raises(ValueError):
        images.resample(img, (4, 4), "sinc")


def test_resample_does_not_bleed_transparent_colour():
    img = np.zeros((8, 8, 4), np.uint8)
    img[:, ::2] = (255, 0, 0, 255)  # opaque red columns
    img[:, 1::2] = (0, 255, 0, 0)  # fully transparent green columns
    for wrap in (False, True):
        out = images.resample(img, (4, 4), "bilinear", wrap=wrap)
        assert (out[..., 1] <= 2).all() and (out[..., 0] >= 250).all()
    # with wrap every output texel sees the same mix: half coverage (clamped edges differ)
    assert (np.abs(out[..., 3].astype(int) - 128) <= 1).all()


@pytest.mark.parametrize("filter", ["box", "bilinear", "bicubic", "lanczos"])
def test_resample_wrap_is_shift_invariant(filter):
    # with wrap, shifting the source by 2 texels shifts a 2x reduction by exactly 1
    img = np.random.default_rng(3).integers(0, 256, (16, 24, 4), dtype=np.uint8)
    img[..., 3] = 255
    a = images.resample(np.roll(img, 2, axis=1), (12, 8), filter, wrap=True)
    b = np.roll(images.resample(img, (12, 8), filter, wrap=True), 1, axis=1)
    assert np.abs(a.astype(int) - b).max() <= 1
    if filter != "box":  # clamped edges break the symmetry
        a = images.resample(np.roll(img, 2, axis=1), (12, 8), filter)
        b = np.roll(images.resample(img, (12, 8), filter), 1, axis=1)
        assert np.abs(a.astype(int) - b).max() > 8


def test_prepare_texture(corpus):
    tex = images.prepare_texture(corpus("capsule_textured", "capsule0.jpg"), max_size=100,
                                 power_of_two="floor", wrap=True)
    assert tex.shape == (32, 64, 4) and tex.dtype == np.uint8


# ---------------------------------------------------------------------------------------------
# averages over triangles


def _clip(poly, axis, bound, keep_below):
    out = []
    for k in range(len(poly)):
        p, q = poly[k], poly[(k + 1) % len(poly)]
        p_in = p[axis] <= bound if keep_below else p[axis] >= bound
        q_in = q[axis] <= bound if keep_below else q[axis] >= bound
        if p_in:
            out.append(p)
        if p_in != q_in:
            t = (bound - p[axis]) / (q[axis] - p[axis])
            out.append((p[0] + t * (q[0] - p[0]), p[1] + t * (q[1] - p[1])))
    return out


def _area(poly):
    return abs(sum(poly[k][0] * poly[(k + 1) % len(poly)][1]
                   - poly[(k + 1) % len(poly)][0] * poly[k][1] for k in range(len(poly)))) / 2


def brute_average(img, tri_uvs):
    """Exact coverage-weighted average, one texel at a time (wrap addressing, v up)."""
    h, w = img.shape[:2]
    f = img.astype(np.float64) / 255.0
    out = []
    for tri in tri_uvs:
        pts = [(u * w, (1 - v) * h) for u, v in tri]
        xs, ys = [p[0] for p in pts], [p[1] for p in pts]
        total, acc, acc_pre = 0.0, np.zeros(4), np.zeros(3)
        for i in range(math.floor(min(ys)), math.ceil(max(ys))):
            for j in range(math.floor(min(xs)), math.ceil(max(xs))):
                poly = pts
                for axis, bound, below in ((0, j, False), (0, j + 1, True), (1, i, False),
                                           (1, i + 1, True)):
                    poly = _clip(poly, axis, bound, below)
                    if not poly:
                        break
                if len(poly) < 3:
                    continue
                a = _area(poly)
                texel = f[i % h, j % w]
                total += a
                acc += a * texel
                acc_pre += a * texel[:3] * texel[3]
        mean = acc / total
        rgb = acc_pre / total / mean[3] if mean[3] > 1e-12 else mean[:3]
        out.append([*rgb, mean[3]])
    return np.array(out)


def random_triangles(rng, n, scale):
    centres = rng.uniform(-2, 3, (n, 1, 2))  # far outside [0, 1]: wrap addressing
    return centres + scale * rng.normal(size=(n, 3, 2)) * rng.uniform(0.05, 1, (n, 1, 1))


def test_average_equals_exact_coverage():
    rng = np.random.default_rng(4)
    img = rng.integers(0, 256, (12, 10, 4), dtype=np.uint8)
    img[rng.random((12, 10)) < 0.2, 3] = 0  # some fully transparent texels
    tris = np.concatenate([random_triangles(rng, 120, 0.15),  # mostly 0.1 .. 3 texels
                           random_triangles(rng, 20, 0.6),  # large, crossing the seams
                           np.array([[[0.9, 0.1], [1.15, 0.3], [0.95, -0.2]]])])  # on the seam
    fast = images.average_over_triangles(img, tris)
    ref = brute_average(img, tris)
    assert fast.shape == (len(tris), 4)
    assert np.abs(fast - ref).max() < 1e-9
    # and it is not a centre sample
    c = tris.mean(axis=1)
    centre = img[np.floor((1 - c[:, 1]) * 12).astype(int) % 12,
                 np.floor(c[:, 0] * 10).astype(int) % 10] / 255.0
    assert np.abs(centre - ref).max(axis=1).mean() > 0.1


def test_average_photo_texture(corpus):
    tex = images.prepare_texture(corpus("capsule_textured", "capsule0.jpg"), size=(24, 16))
    rng = np.random.default_rng(5)
    tris = random_triangles(rng, 40, 0.2)
    assert np.abs(images.average_over_triangles(tex, tris) - brute_average(tex, tris)).max() < 1e-9


def test_average_analytic_cases():
    bw = np.array([[[0, 0, 0, 255], [255, 255, 255, 255]]], np.uint8)  # u < 0.5 black
    tri = np.array([[[0.0, 0.0], [0.0, 1.0], [1.0, 0.5]]])  # centroid u = 1/3 is black
    assert images.average_over_triangles(bw, tri)[0] == pytest.approx([0.25, 0.25, 0.25, 1])
    # linear light: a half black, half white area is 50 % light, sRGB ~0.7354
    half = np.array([[[0.0, 0.0], [1.0, 0.0], [0.5, 1.0]]])  # symmetric about u = 0.5
    assert images.average_over_triangles(bw, half)[0, 0] == pytest.approx(0.5)
    lin = images.average_over_triangles(bw, half, space="linear")
    assert lin[0] == pytest.approx([1.055 * 0.5 ** (1 / 2.4) - 0.055] * 3 + [1])
    # v is up: (0, 0) is the bottom-left of the image
    tb = np.array([[[255, 0, 0, 255]], [[0, 0, 255, 255]]], np.uint8)  # top red, bottom blue
    low = np.array([[[0.1, 0.05], [0.9, 0.05], [0.5, 0.45]]])
    assert images.average_over_triangles(tb, low)[0] == pytest.approx([0, 0, 1, 1])
    assert images.average_over_triangles(tb, 1 - low)[0] == pytest.approx([1, 0, 0, 1])
    # premultiplied: an opaque red texel next to a transparent green one
    rg = np.array([[[255, 0, 0, 255], [0, 255, 0, 0]]], np.uint8)
    whole = np.array([[[0, 0], [1, 0], [1, 1]], [[0, 0], [1, 1], [0, 1]]], float)
    got = images.average_over_triangles(rg, np.concatenate([half, whole]))
    assert got == pytest.approx(np.array([[1, 0, 0, 0.5], [1, 0, 0, 0.25], [1, 0, 0, 0.75]]))
    # all transparent: the plain colour average
    clear = np.array([[[255, 0, 0, 0], [0, 255, 0, 0]]], np.uint8)
    assert images.average_over_triangles(clear, half)[0] == pytest.approx([0.5, 0.5, 0, 0])


def test_average_wrap_and_degenerate():
    rng = np.random.default_rng(6)
    img = rng.integers(0, 256, (8, 8, 4), dtype=np.uint8)
    tris = random_triangles(rng, 50, 0.3)
    base = images.average_over_triangles(img, tris)
    shifted = images.average_over_triangles(img, tris + np.array([3.0, -2.0]))
    assert np.abs(base - shifted).max() < 1e-9
    # zero area: the length-weighted average along the segment; a point: its texel
    bw = np.array([[[0, 0, 0, 255], [255, 255, 255, 255]]], np.uint8)
    seg = np.array([[[0.25, 0.5], [0.75, 0.5], [0.5, 0.5]]])
    assert images.average_over_triangles(bw, seg)[0] == pytest.approx([0.5, 0.5, 0.5, 1])
    pt = np.array([[[0.7, 0.2]] * 3])
    assert images.average_over_triangles(bw, pt)[0] == pytest.approx([1, 1, 1, 1])
    assert images.average_over_triangles(bw, np.zeros((0, 3, 2))).shape == (0, 4)
    with pytest.raises(ValueError):
        images.average_over_triangles(bw, np.full((1, 3, 2), np.nan))
    with pytest.raises(ValueError):
        images.average_over_triangles(bw, np.zeros((2, 2, 2)))


def test_average_chunked_and_grouped_paths(monkeypatch):
    # many triangles / huge textures are processed in chunks and channel groups: same answer
    rng = np.random.default_rng(7)
    img = rng.integers(0, 256, (9, 11, 4), dtype=np.uint8)
    tris = random_triangles(rng, 60, 0.4)
    monkeypatch.setattr(images, "_PIECES_PER_CHUNK", 50)
    monkeypatch.setattr(images, "_TABLE_BYTES", 8 * 9 * 12)  # one channel per table
    assert np.abs(images.average_over_triangles(img, tris) - brute_average(img, tris)).max() < 1e-9
