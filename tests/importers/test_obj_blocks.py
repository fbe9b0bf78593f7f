"""The OBJ importer reads in blocks of whole lines (``load(job, block_size=...)``): the block
boundaries must be invisible. Each file here is generated in code, read with tiny blocks (down to
one byte, so nearly every line is a block of its own) and with one block for the whole file, and
the scenes (every array, dtype included), warnings, details and errors must be identical --
besides being right: line numbers count from the start of the file, relative indices count the
vertices above the line in the whole file, ``usemtl`` carries over, and an error found in a later
block still wins when the whole-file reading would have reported it first."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from bake.config import ImportJob
from bake.errors import InputError
from bake.importers import obj, obj_lines, obj_parse
from bake.importers.obj import load

ONE_BLOCK = 1 << 30
TINY = (1, 7, 64, 1000)


# --------------------------------------------------------------------------- helpers
def write(tmp_path: Path, content: bytes | str, name: str = "model.obj") -> Path:
    p = tmp_path / name
    p.write_bytes(content.encode("latin-1") if isinstance(content, str) else content)
    return p


def outcome(path: Path, block_size: int | None, strict: bool = True):
    try:
        scene, rec = load(ImportJob(path=path, strict=strict), block_size=block_size)
    except InputError as e:
        return ("error", str(e), e.line)
    scene.validate()
    return ("ok", scene, list(rec.warnings), list(rec.details.items()), dict(rec.counts_out))


def assert_same(a, b) -> None:
    assert a[0] == b[0], (a[:3], b[:3])
    if a[0] == "error":
        assert a == b
        return
    sa, sb = a[1], b[1]
    for f in ("positions", "poly_sizes", "poly_indices", "poly_material", "poly_uvs",
              "vertex_colors"):
        x, y = getattr(sa, f), getattr(sb, f)
        assert (x is None) == (y is None), f
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape, f
            np.testing.assert_array_equal(x, y, err_msg=f)
    assert sa.materials == sb.materials
    assert sa.source == sb.source
    assert a[2:] == b[2:]


def same_for_all_blocks(path: Path, strict: bool = True, sizes=TINY):
    """The outcome with one block, after checking every tiny block size gives the same."""
    ref = outcome(path, ONE_BLOCK, strict)
    assert_same(ref, outcome(path, None, strict))  # the default block size
    for bs in sizes:
        assert_same(ref, outcome(path, bs, strict))
    return ref


def grid(n: int, z: float = 0.0) -> list[str]:
    return [f"v {i % 10}.{i % 7} {i // 10}.5 {z + i * 0.001:.4f}" for i in range(n)]


# --------------------------------------------------------------------------- tests
def test_block_size_is_a_module_constant_and_a_keyword(tmp_path, monkeypatch):
    p = write(tmp_path, "\n".join(grid(40) + [f"f {i} {i + 1} {i + 2}" for i in range(1, 38)]) + "\n")
    fed = []
    orig = obj_parse._Parser.feed

    def feed(self, block, nlb, final):
        fed.append(len(block))
        return orig(self, block, nlb, final)

    monkeypatch.setattr(obj_parse._Parser, "feed", feed)
    load(ImportJob(path=p), block_size=64)
    assert len(fed) > 20 and max(fed[:-1]) <= 64 + 40  # cut at a line end near 64 bytes
    fed.clear()
    monkeypatch.setattr(obj, "BLOCK_SIZE", 100)
    load(ImportJob(path=p))
    assert len(fed) > 10
    fed.clear()
    monkeypatch.setattr(obj, "BLOCK_SIZE", ONE_BLOCK)
    load(ImportJob(path=p))
    assert len(fed) == 1


def test_mixed_file_is_the_same_with_tiny_blocks(tmp_path):
    """Every directive, every corner form, comments, CRLF, blank lines, groups, vertex colours,
    relative and forward indices, many blocks."""
    mtl = write(tmp_path, "newmtl red\nKd 1 0 0\nnewmtl blue\nKd 0 0 1\nnewmtl unused\n", "m.mtl")
    assert mtl.is_file()
    lines = ["# generated", "mtllib m.mtl", "o thing", "f 1 2 3  # forward references"]
    for k in range(60):
        lines += [f"v {k}.0 {k % 3}.5 -{k}.25 0.{k % 10} 0.5 0.25", f"vt 0.{k % 10} 0.{(k * 7) % 10}",
                  "vn 0 1 0"]
        if k >= 3:
            lines.append(["usemtl red", "usemtl blue", "usemtl", "g part", "s 1", ""][k % 6])
            lines.append([f"f -1 -2 -3", f"f {k}/{k} {k - 1}/{k - 1} {k - 2}/{k - 2}",
                          f"f -1//1 -2//1 -3//1 -4//1", f"f {k}/-1/1 {k - 1}/-2/1 {k - 2}/-3/1",
                          "l 1 2", f"f {k - 2} {k - 1} {k}\t# tab and comment"][k % 6])
    p = write(tmp_path, "\r\n".join(lines) + "\r\n")
    ref = same_for_all_blocks(p)
    scene = ref[1]
    assert scene.n_vertices == 60 and scene.vertex_colors is not None
    assert [m.name for m in scene.materials][:2] == ["default", "red"]
    assert any("line element" in w for w in ref[2])


def test_bad_line_after_many_blocks_names_its_line(tmp_path):
    head = grid(300) + [f"f {i} {i + 1} {i + 2}" for i in range(1, 290)]
    cases = {
        "v 1 2 x3": "malformed number 'x3' in a 'v' line",
        "v 1 2": "vertex needs x y z, got 2 value(s)",
        "v 1 nan 2": "vertex values are NaN or infinite on 1 line(s): ",
        "v 1 2 1e31": "vertex coordinates beyond",
        "vt": "texture coordinate needs u [v [w]], got no values",
        "vt 0.5 inf": "texture coordinates are NaN or infinite on 1 line(s): ",
        "f 1 2 3x": "malformed face corner '3x'",
        "f 1 2 -400": "face index -400 is out of range (300 vertices defined before this line)",
        "f 1 2 301": "face index 301 is out of range (file has 300 vertices)",
        "f 1 0 2": "face index 0 is invalid",
        "f 1 2": "face has fewer than 3 vertices (2 given)",
    }
    for bad, msg in cases.items():
        p = write(tmp_path, "\n".join(head + [bad] + head[-5:]) + "\n")
        line = len(head) + 1
        ref = same_for_all_blocks(p, sizes=(1, 64, 999))
        assert ref[0] == "error" and ref[2] == line, (bad, ref)
        assert ref[1].startswith(f"{p}:{line}: ") and msg in ref[1], (bad, ref[1])


def test_bad_faces_dropped_across_blocks_warn_the_same(tmp_path):
    """Not strict: bad faces in many blocks, some bad only because an index lies past the last
    vertex of the file (known at the end), some relative before the file, some index 0."""
    lines = []
    for k in range(120):
        lines.append(f"v {k} 0 {k % 5}")
        if k % 17 == 5:
            lines.append("f 1 2 999")
        elif k % 23 == 7:
            lines.append("f -1 -2 -300")
        elif k % 29 == 3:
            lines.append("f 0 1 2")
        elif k >= 3:
            lines.append(f"f -1 -2 -3 {k + 2}")  # a forward reference: fine once it exists
    p = write(tmp_path, "\n".join(lines) + "\n")
    ref = same_for_all_blocks(p, strict=False)
    drop = [w for w in ref[2] if w.startswith("dropped")]
    assert len(drop) == 1 and drop[0].startswith("dropped 16 bad face(s)"), drop
    assert "at lines 5, 9, 13, 43, 59, ...; first, line 5: face index 0 is invalid" in drop[0]
    strict = same_for_all_blocks(p, strict=True, sizes=(1, 64))
    assert strict[0] == "error" and strict[2] == 5
    # the first bad face: an index past the end of the file (known only at the end) comes
    # before an index 0 on the same line
    p = write(tmp_path, "\n".join(lines[:3] + ["f 500 0 1"] + lines[3:]) + "\n")
    strict = same_for_all_blocks(p, strict=True, sizes=(1, 64))
    assert strict[1].endswith(":4: face index 500 is out of range (file has 120 vertices)")
    p = write(tmp_path, "\n".join(lines[:3] + ["f 1 2 500"] + lines[3:]) + "\n")
    strict = same_for_all_blocks(p, strict=True, sizes=(1, 64))
    assert strict[1].endswith(":4: face index 500 is out of range (file has 120 vertices)")


def test_continuation_line_across_every_boundary(tmp_path):
    """A face continued over three physical lines (LF, CRLF), placed at every offset against a
    64-byte block; a bad line after it still gets its physical line number."""
    for pad in range(0, 70, 3):
        body = ["# " + "x" * pad] + grid(6) + ["f 1 2 \\", "3 \\\r", "4"] + grid(3) + ["v 1 2 oops"]
        p = write(tmp_path, "\n".join(body) + "\n")
        ref = same_for_all_blocks(p, sizes=(1, 5, 16, 64, 65, 66))
        assert ref[0] == "error" and ref[2] == len(body), (pad, ref)
        p = write(tmp_path, "\n".join(body[:-1]) + "\n")
        ref = same_for_all_blocks(p, sizes=(1, 16, 64, 66))
        assert ref[1].poly_sizes.tolist() == [4]
        assert ref[1].poly_indices.tolist() == [0, 1, 2, 3]


def test_continuation_at_end_of_file_and_bare_cr(tmp_path):
    p = write(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3 \\")  # continues nothing
    ref = same_for_all_blocks(p, sizes=(1, 2, 3, 9, 17))
    assert ref[1].endswith(":4: malformed face corner '\\' (expected v, v/vt, v//vn or v/vt/vn "
                           "with integer indices)")
    for tail in (b"f 1 2 \\\n3\\\n", b"f 1 2 \\\r\n3 \\\r\n"):
        p = write(tmp_path, b"v 0 0 0\nv 1 0 0\nv 0 1 0\n" + tail)
        ref = same_for_all_blocks(p, sizes=(1, 2, 3, 9, 17))
        assert ref[1].n_polygons == 1
    p = write(tmp_path, "\r".join(grid(50) + ["f 1 2 \\", "3", "f -1 -2 -3", "v 1 2 y"]) + "\r")
    ref = same_for_all_blocks(p)
    assert ref[0] == "error" and ref[2] == 54


def test_newline_kind_is_decided_for_the_whole_file(tmp_path):
    """No LF in the first 64 KiB but one later: the whole file uses LF (its CRs are spaces), as
    when it was read at once; without any LF, CR ends lines."""
    cr_lines = "\r".join(["s 1 2 3 4"] * 8000)
    assert len(cr_lines) > obj_lines._HEAD_BYTES
    p = write(tmp_path, cr_lines + "\rv 1 2 3\n")
    ref = same_for_all_blocks(p, sizes=(64, 4096))
    assert ref[1].n_vertices == 0 and dict(ref[3])["groups_objects_smoothing_lines"] == 1  # one long 's' line
    p = write(tmp_path, cr_lines + "\rv 1 2 3\r")
    ref = same_for_all_blocks(p, sizes=(64, 4096))
    assert ref[1].n_vertices == 1 and dict(ref[3])["groups_objects_smoothing_lines"] == 8000


def test_relative_indices_count_vertices_in_earlier_blocks(tmp_path):
    n = 400
    lines = grid(n) + [f"vt 0.{i % 10} 0.5" for i in range(n)]
    lines += [f"f -{n - i}/-{n - i} -{n - i - 1}/-{n - i - 1} -{n - i - 2}/-{n - i - 2}"
              for i in range(0, n - 2, 7)]
    lines += grid(5, z=9.0) + ["f -1 -2 -3 -405"]
    p = write(tmp_path, "\n".join(lines) + "\n")
    ref = same_for_all_blocks(p)
    scene = ref[1]
    expect = [[i, i + 1, i + 2] for i in range(0, n - 2, 7)] + [[n + 4, n + 3, n + 2, 0]]
    got = np.split(scene.poly_indices, np.cumsum(scene.poly_sizes)[:-1])
    assert [g.tolist() for g in got] == expect
    assert scene.poly_uvs is not None and scene.poly_uvs.shape == (len(scene.poly_indices), 2)


def test_usemtl_carries_over_blocks(tmp_path):
    write(tmp_path, "newmtl a\nKd 1 0 0\nnewmtl b\nKd 0 1 0\n", "m.mtl")
    lines = ["mtllib m.mtl"] + grid(30) + ["usemtl b"] + ["f 1 2 3"] * 50 + ["usemtl a"]
    lines += ["# " + "filler " * 20] * 20 + ["f 2 3 4"] * 40 + ["usemtl", "f 3 4 5", "usemtl b"]
    lines += ["f 4 5 6"] * 3
    p = write(tmp_path, "\n".join(lines) + "\n")
    ref = same_for_all_blocks(p)
    scene = ref[1]
    assert [m.name for m in scene.materials] == ["b", "a", "default"]
    assert scene.poly_material.tolist() == [0] * 50 + [1] * 40 + [2] + [0] * 3


def test_first_error_in_file_order_wins_across_blocks(tmp_path):
    """The whole-file reader checked all 'v' lines, then all 'vt', then faces: an error in a later
    block can come first; a NUL byte anywhere comes before all of them."""
    body = ["f 1 2 x"] + grid(200) + ["vt 1 nan"] + grid(200) + ["v 1 2 bad"] + grid(100)
    p = write(tmp_path, "\n".join(body) + "\n")
    ref = same_for_all_blocks(p)
    assert "malformed number 'bad' in a 'v' line" in ref[1] and ref[2] == 403
    body = ["v 1 2 nan"] + grid(300) + ["v inf 2 3", "v 1 2 1e40"] + grid(10)
    p = write(tmp_path, "\n".join(body) + "\n")
    ref = same_for_all_blocks(p)
    assert ref[1].endswith("vertex values are NaN or infinite on 2 line(s): 1, 302")
    body = ["f 1 2 3"] * 3 + grid(300) + ["v 1 2 q"] + grid(10)
    p = write(tmp_path, ("\n".join(body) + "\n").encode() + b"v 1 2 3\x00\n")
    ref = same_for_all_blocks(p)
    assert "NUL byte at offset" in ref[1]
    p = write(tmp_path, b"\x01\x02\x03\x04\x05\x06\x07\x08v 1 2 3\n" + b"v 1 1 1\n" * 20000
              + b"\x00")
    ref = same_for_all_blocks(p, sizes=(64, 4096))
    assert "NUL byte at offset" in ref[1]


def test_counts_and_first_lines_in_warnings_span_blocks(tmp_path):
    """Warnings that count lines and list the first few: the same over blocks (Latin-1 names,
    odd 'v' lines, unknown directives, vertex colours 0-255 in one block only)."""
    lines = []
    for k in range(80):
        lines.append(f"v {k} 1 2" + (" 7 8" if k % 9 == 4 else ""))
        if k % 11 == 2:
            lines.append("usemtl caf\xe9")
        if k % 13 == 1:
            lines.append("bogus 1 2")
        if k == 70:
            lines.append("v 1 2 3 255 128 0")
        if k >= 2:
            lines.append("f -1 -2 -3")
    p = write(tmp_path, "\n".join(lines) + "\n")
    ref = same_for_all_blocks(p, strict=False)
    warns = "\n".join(ref[2])
    assert "Latin-1" in warns and "'bogus' x7 (first at line" in warns
    assert "'v' line(s) have 5 values" in warns
    assert dict(ref[3])["vertex_color_scale"] == "0-255"


def test_empty_and_tiny_files(tmp_path):
    for content in (b"", b"\n", b"\xef\xbb\xbf", b"\xef\xbb\xbfv 1 2 3\nv 1 1 1\nv 0 0 1\nf 1 2 3",
                    b"#", b"\\", b"\r\n\r\n", b"\r"):
        p = write(tmp_path, content)
        same_for_all_blocks(p, sizes=(1, 2, 3, 4))
