"""The reader's ``decode textimage`` in the real Scratch VM gives exactly the pixels of our Python
decoder (``bake.scratch.textimage.decode``), as colour numbers bottom row first, for images that
exercise every operation: raw, the four copies, the hash table, small and large difference
volumes, RLE, A8 alpha (raw, increments, decrements), an A8 grey main layer, layers in an unusual
order, custom header attributes, 1-pixel-wide images (the reference's vertical-forward quirk) and a
corpus texture. The data characters include upper and lower case letters, which the decoder must
tell apart (it maps characters through costume names, not ``item # of``)."""

from __future__ import annotations

import numpy as np
import pytest

from bake.scratch import sb3
from bake.scratch import readers
from bake.scratch import colors, textimage
from bake.textures import images
from conftest import corpus_path
from vm_harness import call, vm  # noqa: F401


def _images():
    rng = np.random.default_rng(11)
    out = {}
    noise = rng.integers(0, 256, (7, 9, 4), dtype=np.uint8)
    noise[..., 3] = rng.choice([0, 1, 128, 254, 255], (7, 9))
    out["noise-rgba"] = textimage.encode(noise)
    y, x = np.mgrid[0:16, 0:24]
    grad = np.stack([x * 10, y * 15, (x + y) * 5 + rng.integers(0, 3, x.shape)], -1).clip(0, 255).astype(np.uint8)
    alpha = (255 - (x * 3 + y)).clip(0, 255).astype(np.uint8)
    out["gradient+alpha-ramp"] = textimage.encode(np.dstack([grad, alpha]))
    jumpy = grad.astype(np.int64).copy()
    jumpy[:, ::3] += rng.integers(-40, 40, (16, 8, 3))  # medium jumps: the large volumes
    out["gradient-jumps"] = textimage.encode(jumpy.clip(0, 255).astype(np.uint8))
    flat = np.zeros((10, 20, 3), np.uint8)
    palette = rng.integers(0, 256, (5, 3), dtype=np.uint8)
    flat[:] = palette[(np.arange(20)[None, :] // 4 + np.arange(10)[:, None] // 3) % 5]
    flat[4, 7] = palette[0]  # a colour seen long ago: the hash table
    out["flat-palette"] = textimage.encode(flat, attributes={"note": "hi", "Name": "x"})
    tall = rng.integers(0, 256, (12, 1, 3), dtype=np.uint8)
    tall[5:9] = tall[4]
    out["1-wide"] = textimage.encode(tall)
    out["1-high"] = textimage.encode(rng.integers(0, 256, (1, 12, 3), dtype=np.uint8))
    grey = (np.add.outer(np.arange(6) * 20, np.arange(8) * 3) % 256).astype(np.uint8)
    out["grey-A8-main"] = textimage.encode(grey)
    rgb = rng.integers(0, 256, (4, 5, 3), dtype=np.uint8)
    a = rng.integers(0, 256, (4, 5), dtype=np.uint8)
    out["alpha-layer-first"] = textimage.write_text(5, 4, [
        ("alpha", "A8", textimage.encode_a8(textimage.to_stream_order(a), 5)),
        ("main", "RGB8", textimage.encode_rgb8(textimage.to_stream_order(rgb), 5))])
    tex = images.prepare_texture(corpus_path("capsule_textured", "capsule0.jpg"), size=(20, 14))
    out["capsule-texture"] = textimage.encode(tex[:, :, :3])
    return out


def _reference(text: str) -> list[int]:
    img = textimage.decode(text)
    mode = "argb" if img.ndim == 3 and img.shape[2] == 4 else "rgb"
    return [int(v) for v in colors.image_to_list(img, mode, first_row="bottom")]


# A reader with the decoder alone, and the full reader of a textured bake: with a mesh the pen's
# fence costume sits beside the 94 character costumes, which must not shift their numbers.
MESH = {"verts": [0, 0, 0, 1, 0, 0, 0, 1, 0], "tris": [1, 2, 3, 1], "mat colors": [16711680]}
READERS = {
    "decoder": readers.ReaderSpec(mesh=None, bvh=None, textimage=True),
    "full": readers.ReaderSpec(mesh=readers.MeshNames(tri_colors=None), textimage=True,
                               bounds=readers.bounding_sphere(MESH["verts"])),
}


@pytest.fixture(scope="module")
def decoded(tmp_path_factory, vm):
    texts = _images()
    out = {}
    for kind, spec in READERS.items():
        stage = sb3.Target("Stage", is_stage=True, lists=MESH if spec.mesh else {})
        data, _ = sb3.write_sb3([stage, readers.reader_target(spec, "Reader", stage_lists=list(stage.lists))])
        p = tmp_path_factory.mktemp("ti") / f"ti-{kind}.sb3"
        p.write_bytes(data)
        runs = [call("Reader", "decode textimage %s", t, lists=["ti colors"], variables=["ti width", "ti height"])
                for t in texts.values()]
        res = vm({"load": str(p), "runs": runs})
        assert res["validation"][0]["ok"], res["validation"]
        out.update({(kind, n): v for n, v in zip(texts, zip(texts.values(), res["runs"]))})
    return out


def _rgb8_ops(stream: str) -> set[str]:
    """The kinds of operation in an RGB8 stream (walked with the data sizes of the format)."""
    v = [ord(c) - 33 for c in stream]
    size = lambda op: 3 if op <= 20 else 1 if op == 26 or 28 <= op <= 72 else 2 if op >= 73 else 0  # noqa: E731
    kind = lambda op: ("raw" if op <= 20 else "copy" if op <= 25 else "hash" if op == 26  # noqa: E731
                       else "small" if op <= 72 else "large")
    found, i = set(), 0
    while i < len(v):
        op = v[i]
        if op == 27:
            found.add("rle")
            inner, n = v[i + 1], v[i + 2]
            found.add(kind(inner))
            i += 3 + n * size(inner)
        else:
            found.add(kind(op))
            i += 1 + size(op)
    return found


def _a8_ops(stream: str) -> set[str]:
    v = [ord(c) - 33 for c in stream]
    kind = lambda op: "raw" if op <= 2 else "copy" if op <= 6 else "inc" if op <= 50 else "dec"  # noqa: E731
    found, i = set(), 0
    while i < len(v):
        op = v[i]
        if op == 7:
            found |= {"rle", kind(v[i + 1])}
            i += 3 + v[i + 2] * (1 if v[i + 1] <= 2 else 0)
        else:
            found.add(kind(op))
            i += 2 if op <= 2 else 1
    return found


def test_images_cover_every_operation():
    rgb, a8, cased = set(), set(), False
    for text in _images().values():
        h = textimage.read_header(text)
        pos = h.data_start
        for layer in h.layers:
            stream = text[pos:pos + layer.length]
            pos += layer.length
            cased |= any(c.isupper() for c in stream) and any(c.islower() for c in stream)
            (rgb.update if layer.type == "RGB8" else a8.update)(
                _rgb8_ops(stream) if layer.type == "RGB8" else _a8_ops(stream))
    assert rgb == {"raw", "copy", "hash", "small", "large", "rle"}
    assert a8 == {"raw", "copy", "inc", "dec", "rle"}
    assert cased


@pytest.mark.parametrize("kind", list(READERS))
@pytest.mark.parametrize("name", list(_images()))
def test_vm_decodes_like_python(decoded, name, kind):
    text, run = decoded[(kind, name)]
    img = textimage.decode(text)
    assert run["done"]
    assert float(run["variables"]["ti width"]) == img.shape[1]
    assert float(run["variables"]["ti height"]) == img.shape[0]
    assert run["lists"]["ti colors"] == _reference(text)
