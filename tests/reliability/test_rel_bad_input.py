"""Bad input gets a clear answer: through the real CLI (``bake.cli.main``, and a real subprocess
for the traceback / ``--debug`` contract), every generated bad file gives one line on stderr that
names the file and the place (line, key or glTF object), the documented exit status (2 config,
3 input), no traceback, and no output folder. Inputs that are merely odd (an unknown directive, a
missing or empty .mtl) bake, and the report's warning names the file and line.

The shared corpus is covered by tests/test_corpus.py; everything here is generated."""

from __future__ import annotations

import json
import re
import os
import struct
import zipfile
from pathlib import Path

import numpy as np
import pytest

from bake import pipeline, stages
from rel_util import (TRACEBACK, assert_clean_error, gltf_triangles, glb_bytes, run_cli, run_subprocess,
                      write_gltf)

TRI = "v 0 0 0\nv 1 0 0\nv 0 1 0\n"  # lines 1-3


def bake(capsys, target: Path, out: Path, *extra: str) -> tuple[int, str, str]:
    return run_cli(["run", target, "--out", out, "--quiet", *extra], capsys)


def report(out: Path) -> dict:
    return json.loads((out / "report.json").read_text())


def warnings_of(out: Path) -> list[str]:
    return [w for s in report(out)["stages"] for w in s["warnings"]]


# =========================================================================== OBJ lines
# (name, text, line the message must name, what it must say)
OBJ_ERRORS = [
    ("v_too_few", TRI + "v 1 2\nf 1 2 3\n", 4, "vertex needs x y z"),
    ("v_malformed", TRI + "v 1 x 2\nf 1 2 3\n", 4, "malformed number 'x'"),
    ("v_nan", TRI + "v nan 0 0\nf 1 2 4\n", 4, "NaN or infinite"),
    ("v_inf", TRI + "v 0 -inf 0\nf 1 2 4\n", 4, "NaN or infinite"),
    ("v_overflows_to_inf", TRI + "v 1e999 0 0\nf 1 2 4\n", 4, "NaN or infinite"),
    ("v_msvc_nan", TRI + "v 1.#IND 0 0\nf 1 2 4\n", 4, "NaN or infinite"),
    ("v_beyond_range", TRI + "v 1e300 0 0\nf 1 2 4\n", 4, r"beyond \+-1e\+30"),
    ("v_colour_nan", "v 0 0 0 nan 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 1, "NaN or infinite"),
    ("v_colour_inf", "v 0 0 0 1 0 inf 1\nv 1 0 0\nv 0 1 0\nf 1 2 3\n", 1, "NaN or infinite"),
    ("vt_empty", TRI + "vt\nf 1 2 3\n", 4, "texture coordinate needs u"),
    ("vt_malformed", TRI + "vt 0 y\nf 1 2 3\n", 4, "malformed number 'y'"),
    ("vt_nan", TRI + "vt nan 0\nf 1/1 2/1 3/1\n", 4, "texture coordinates are NaN"),
    # normals are checked as vt lines are (issue 37), though bake computes its own
    ("vn_malformed", TRI + "vn a b c\nf 1 2 3\n", 4, "malformed number 'a' in a 'vn' line"),
    ("vn_too_few", TRI + "vn 0 1\nf 1//1 2//1 3//1\n", 4, "vertex normal needs x y z, got 2"),
    ("vn_nan", TRI + "vn 0 nan 1\nf 1//1 2//1 3//1\n", 4, "vertex normals are NaN"),
    ("f_empty", TRI + "f\n", 4, "fewer than 3"),
    ("f_two_corners", TRI + "f 1 2\n", 4, "fewer than 3"),
    ("f_malformed", TRI + "f 1 2 x\n", 4, "malformed face corner 'x'"),
    ("f_four_fields", TRI + "f 1/1/1/1 2 3\n", 4, "malformed face corner"),
    ("f_bad_normal_field", TRI + "f 1//a 2//1 3//1\n", 4, "malformed face corner"),
    ("f_empty_vertex_field", TRI + "f /1 2 3\n", 4, "malformed face corner"),
    ("f_index_zero", TRI + "f 0 1 2\n", 4, "index 0"),
    ("f_index_past_end", TRI + "f 1 2 99\n", 4, "99 is out of range"),
    ("f_negative_past_start", TRI + "f -9 1 2\n", 4, "-9 is out of range"),
    ("f_texture_index", TRI + "vt 0 0\nf 1/9 2/1 3/1\n", 5, "texture index 9 is out of range"),
    ("f_huge_index", TRI + "f 1 2 99999999999999999999\n", 4, "malformed face corner"),
    ("continued_last_line", TRI + "f 1 2 3\\", 4, "malformed face corner"),  # fuzz find (obj_lines.py fix)
]


@pytest.mark.parametrize("name,text,line,what", OBJ_ERRORS, ids=[c[0] for c in OBJ_ERRORS])
def test_malformed_obj_line_names_file_and_line(tmp_path, capsys, name, text, line, what):
    p = tmp_path / "model" / f"{name}.obj"
    p.parent.mkdir()
    p.write_text(text)
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert_clean_error(code, err, status=3, file=f"{name}.obj", place=rf"{name}\.obj:{line}: .*{what}")
    assert not out.exists(), "a failed bake wrote outputs"


# directives that are legal or ignorable: they bake, and a warning names what was skipped
OBJ_ODD = [
    # a face naming a normal that is not there (real files do: OpenSubdiv's catmark torus has no vn)
    ("vn_index_missing", TRI + "vn 0 0 1\nf 1//1 2//1 3//2\n", r"1 face\(s\) name a normal .*\(lines 5\)"),
    ("usemtl_without_name", TRI + "usemtl\nf 1 2 3\n", None),
    ("mtllib_without_name", TRI + "mtllib\nf 1 2 3\n", r"\.obj:4: 'mtllib' without a file name"),
    ("mtllib_missing", "mtllib gone.mtl\n" + TRI + "f 1 2 3\n", r"not found: 'gone\.mtl' \(.*\.obj:1\)"),
    ("groups_with_junk", TRI + "o \x01\x02\ng\ns 999 x\nf 1 2 3\n", None),
    ("lines_and_points", TRI + "l 1 x\np\nf 1 2 3\n", "skipped 1 line element"),
    ("unknown_directive", TRI + "frob 1 2\nf 1 2 3\n", r"'frob' x1 \(first at line 4\)"),
]


@pytest.mark.parametrize("name,text,warning", OBJ_ODD, ids=[c[0] for c in OBJ_ODD])
def test_odd_obj_directives_bake_with_a_named_warning(tmp_path, capsys, name, text, warning):
    p = tmp_path / f"{name}.obj"
    p.write_text(text)
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert code == 0 and err == "", err
    if warning:
        assert any(re.search(warning, w) for w in warnings_of(out)), warnings_of(out)
    # the one good face is baked whatever the odd line was, its corners reversed (left frame):
    # (0,0,0), (0,1,0), (1,0,0); vertices are numbered in first-use order, so they are 1, 2, 3
    tris = [int(x) for x in (out / "lists" / "tris.txt").read_text().split("\n")]
    verts = [float(x) for x in (out / "lists" / "verts.txt").read_text().split("\n")]
    assert tris == [1, 2, 3, 1]
    assert [tuple(verts[3 * (t - 1): 3 * t]) for t in tris[:3]] == [(0, 0, 0), (0, 1, 0), (1, 0, 0)]


def test_lenient_import_drops_bad_faces_and_names_their_lines(tmp_path, capsys):
    p = tmp_path / "m.obj"
    p.write_text(TRI + "f 1 2 3\nf 1 2 9\nf 0 1 2\nf 3 2 1\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out, "--set", "import.strict=false")
    assert code == 0, err
    w = [w for w in warnings_of(out) if "dropped 2 bad face" in w]
    assert w and "lines 5, 6" in w[0] and "line 5" in w[0], warnings_of(out)
    assert report(out)["scene"]["triangles"] == 2


# =========================================================================== MTL
MTL_WARNINGS = [
    ("kd_malformed", "newmtl a\nKd 1 x 0\n", 2, "malformed number in 'Kd'"),
    ("kd_nan", "newmtl a\nKd nan 0 0\n", 2, "non-finite value in 'Kd'"),
    ("kd_count", "newmtl a\nKd 1 0\n", 2, "'Kd' needs 1 or 3 numbers"),
    ("d_malformed", "newmtl a\nd half\n", 2, "malformed number in 'd'"),
    ("tr_inf", "newmtl a\nTr inf\n", 2, "non-finite value in 'Tr'"),
    ("newmtl_without_name", "newmtl\nKd 1 0 0\n", 1, "'newmtl' without a name"),
    ("kd_before_newmtl", "Kd 1 0 0\nnewmtl a\n", 1, "'Kd' before any 'newmtl'"),
    ("map_kd_without_file", "newmtl a\nmap_Kd\n", 2, "'map_Kd' without a file name"),
    ("map_kd_missing", "newmtl a\nmap_Kd gone.png\n", 2, "texture not found: 'gone.png'"),
]


@pytest.mark.parametrize("name,mtl,line,what", MTL_WARNINGS, ids=[c[0] for c in MTL_WARNINGS])
def test_malformed_mtl_statement_is_a_warning_naming_mtl_line(tmp_path, capsys, name, mtl, line, what):
    (tmp_path / "m.mtl").write_text(mtl)
    p = tmp_path / "m.obj"
    p.write_text("mtllib m.mtl\n" + TRI + "usemtl a\nf 1 2 3\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert code == 0 and err == "", err
    assert any(f"m.mtl:{line}" in w and what in w for w in warnings_of(out)), warnings_of(out)


def test_zero_byte_mtl_bakes_with_default_colour_and_says_so(tmp_path, capsys):
    (tmp_path / "m.mtl").write_bytes(b"")
    p = tmp_path / "m.obj"
    p.write_text("mtllib m.mtl\n" + TRI + "usemtl red\nf 1 2 3\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert code == 0 and err == "", err
    assert any("not defined in any loaded .mtl" in w and "'red'" in w for w in warnings_of(out))
    # 0.8 grey, the documented default: 204 * 65536 + 204 * 256 + 204
    assert (out / "lists" / "mat_colors.txt").read_text() == str(204 * 65536 + 204 * 256 + 204)


# =========================================================================== empty files
@pytest.mark.parametrize("name,status,place", [
    ("empty.obj", 3, "has no faces"),
    ("empty.gltf", 3, "not valid JSON"),
    ("empty.glb", 3, "not a GLB file"),
    ("empty.toml", 2, "key 'input.path'"),
])
def test_empty_file(tmp_path, capsys, name, status, place):
    p = tmp_path / name
    p.write_bytes(b"")
    code, _, err = bake(capsys, p, tmp_path / "out")
    assert_clean_error(code, err, status=status, file=name, place=place)


# =========================================================================== glTF
def good_doc(**kw):
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], np.float64)
    return gltf_triangles(pos, [[0, 1, 2], [1, 3, 2]], **kw)


def _nan_bytes(buf: bytes, offset: int, value: float) -> bytes:
    b = bytearray(buf)
    b[offset:offset + 4] = struct.pack("<f", value)
    return bytes(b)


def test_generated_gltf_bakes(tmp_path, capsys):
    """The base document the bad variants below start from is good."""
    doc, buf = good_doc(colors=np.ones((4, 4)), uvs=np.zeros((4, 2)))
    code, _, err = bake(capsys, write_gltf(tmp_path / "ok.gltf", doc, buf), tmp_path / "out")
    assert code == 0, err
    assert report(tmp_path / "out")["scene"]["triangles"] == 2


def _gltf_case(name):
    """(doc, buffer) of a bad variant, and the place its message must name."""
    doc, buf = good_doc(colors=np.ones((4, 4)), uvs=np.zeros((4, 2)))
    nodes = doc["nodes"]
    if name == "position_nan":
        return doc, _nan_bytes(buf, 4, float("nan")), r"attributes\.POSITION: accessors\[0\] has NaN/Inf"
    if name == "position_inf":
        return doc, _nan_bytes(buf, 8, float("inf")), r"accessors\[0\] has NaN/Inf"
    if name == "color_nan":
        off = doc["bufferViews"][2]["byteOffset"]
        return doc, _nan_bytes(buf, off + 20, float("nan")), r"attributes\.COLOR_0: accessors\[2\] has NaN/Inf"
    if name == "uv_inf":
        off = doc["bufferViews"][3]["byteOffset"]
        return doc, _nan_bytes(buf, off, float("-inf")), r"attributes\.TEXCOORD_0: accessors\[3\] has NaN/Inf"
    if name == "translation_nan":
        nodes[0]["translation"] = [float("nan"), 0, 0]
        return doc, buf, r"nodes\[0\]: translation has NaN/Inf"
    if name == "scale_inf":
        nodes[0]["scale"] = [float("inf"), 1, 1]
        return doc, buf, r"nodes\[0\]: scale has NaN/Inf"
    if name == "matrix_nan":
        nodes[0]["matrix"] = [1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, float("nan"), 0, 0, 1]
        return doc, buf, r"nodes\[0\]: matrix has NaN/Inf"
    if name == "scale_beyond_range":
        nodes[0]["scale"] = [1e300, 1e300, 1e300]
        return doc, buf, r"placed by nodes\[0\].*beyond"
    if name == "base_color_nan":
        doc["materials"] = [{"pbrMetallicRoughness": {"baseColorFactor": [float("nan"), 0, 0, 1]}}]
        doc["meshes"][0]["primitives"][0]["material"] = 0
        return doc, buf, r"materials\[0\]\.pbrMetallicRoughness: baseColorFactor has NaN/Inf"
    if name == "alpha_cutoff_inf":
        doc["materials"] = [{"alphaMode": "MASK", "alphaCutoff": float("inf")}]
        doc["meshes"][0]["primitives"][0]["material"] = 0
        return doc, buf, r"materials\[0\]: alphaCutoff must be a finite number"
    if name == "light_intensity_nan":
        doc["extensions"] = {"KHR_lights_punctual": {"lights": [{"type": "point", "intensity": float("nan")}]}}
        nodes[0]["extensions"] = {"KHR_lights_punctual": {"light": 0}}
        return doc, buf, r"lights\[0\]: intensity must be a finite number"
    if name == "index_out_of_range":
        off = doc["bufferViews"][1]["byteOffset"]
        b = bytearray(buf)
        b[off + 4:off + 8] = struct.pack("<I", 77)
        return doc, bytes(b), r"primitives\[0\]: accessors\[1\]: index 77 out of range"
    if name == "view_past_buffer":
        doc["bufferViews"][0]["byteLength"] = 10_000
        return doc, buf, r"bufferViews\[0\]: bytes .* run past the end of buffers\[0\]"
    if name == "cycle":
        doc["nodes"] = [{"mesh": 0, "children": [1]}, {"children": [0]}]
        return doc, buf, r"cycle"
    if name == "self_child":
        doc["nodes"] = [{"mesh": 0, "children": [0]}]
        return doc, buf, r"nodes\[0\]: is its own child"
    if name == "two_parents":
        doc["nodes"] = [{"children": [2]}, {"children": [2]}, {"mesh": 0}]
        doc["scenes"][0]["nodes"] = [0, 1]
        return doc, buf, r"nodes\[2\]: has two parents"
    raise KeyError(name)


GLTF_ERRORS = ["position_nan", "position_inf", "color_nan", "uv_inf", "translation_nan", "scale_inf",
               "matrix_nan", "scale_beyond_range", "base_color_nan", "alpha_cutoff_inf",
               "light_intensity_nan", "index_out_of_range", "view_past_buffer", "cycle", "self_child",
               "two_parents"]


@pytest.mark.parametrize("name", GLTF_ERRORS)
@pytest.mark.parametrize("container", ["gltf", "glb"])
def test_bad_gltf_names_file_and_object(tmp_path, capsys, name, container):
    doc, buf, place = _gltf_case(name)
    if container == "gltf":
        p = write_gltf(tmp_path / f"{name}.gltf", doc, buf)
    else:
        doc = json.loads(json.dumps(doc))
        p = tmp_path / f"{name}.glb"
        p.write_bytes(glb_bytes(doc, buf))
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert_clean_error(code, err, status=3, file=p.name, place=place)
    assert not out.exists()


@pytest.mark.parametrize("cut", ["0", "5", "12", "19", "header+json/2", "half", "all-1"])
def test_truncated_glb(tmp_path, capsys, cut):
    doc, buf = good_doc()
    data = glb_bytes(doc, buf)
    n = {"0": 0, "5": 5, "12": 12, "19": 19, "header+json/2": 20 + struct.unpack_from("<I", data, 12)[0] // 2,
         "half": len(data) // 2, "all-1": len(data) - 1}[cut]
    p = tmp_path / "cut.glb"
    p.write_bytes(data[:n])
    code, _, err = bake(capsys, p, tmp_path / "out")
    assert_clean_error(code, err, status=3, file="cut.glb", place="truncated GLB|not a GLB file")


@pytest.mark.parametrize("uri,place", [
    ("../secret.bin", "points outside the model's folder"),
    ("%2e%2e/secret.bin", "points outside the model's folder"),
    ("..%2Fsecret.bin", "points outside the model's folder"),
    ("..\\secret.bin", "points outside the model's folder"),
    ("sub/../../secret.bin", "points outside the model's folder"),
    ("{abs}", "is an absolute path"),
    ("file://{abs}", "is a URL"),
    ("https://example.com/secret.bin", "is a URL"),
    ("link.bin", "points outside the model's folder"),  # a symbolic link inside, pointing out
])
def test_gltf_uri_leaving_the_model_folder_is_refused_unread(tmp_path, capsys, monkeypatch, uri, place):
    doc, buf = good_doc()
    secret = tmp_path / "secret.bin"
    secret.write_bytes(buf)
    model = tmp_path / "model"
    model.mkdir()
    (model / "sub").mkdir()
    if uri == "link.bin":
        os.symlink(secret, model / "link.bin")
    uri = uri.replace("{abs}", str(secret))
    doc["buffers"][0]["uri"] = uri
    p = model / "m.gltf"
    p.write_text(json.dumps(doc))
    opened = _record_opens(monkeypatch)
    code, _, err = bake(capsys, p, tmp_path / "out")
    assert_clean_error(code, err, status=3, file="m.gltf", place=rf"buffers\[0\]: uri .*{place}")
    assert not any(Path(o).resolve() == secret.resolve() for o in opened), "the file outside was opened"


def test_gltf_image_uri_leaving_the_folder_is_refused(tmp_path, capsys):
    doc, buf = good_doc(uvs=np.zeros((4, 2)))
    doc["images"] = [{"uri": "../tex.png"}]
    doc["textures"] = [{"source": 0}]
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    p = write_gltf(tmp_path / "model" / "m.gltf", doc, buf)
    code, _, err = bake(capsys, p, tmp_path / "out")
    assert_clean_error(code, err, status=3, file="m.gltf", place=r"images\[0\]: uri '\.\./tex\.png' points outside")


def _record_opens(monkeypatch) -> list[str]:
    """Every path opened through builtins.open / io.open / os.open from here on."""
    import builtins
    import io

    opened: list[str] = []
    real_open, real_os_open = builtins.open, os.open

    def rec_open(file, *a, **k):
        if isinstance(file, (str, bytes, os.PathLike)):
            opened.append(os.fsdecode(file))
        return real_open(file, *a, **k)

    def rec_os_open(path, *a, **k):
        opened.append(os.fsdecode(path))
        return real_os_open(path, *a, **k)

    monkeypatch.setattr(builtins, "open", rec_open)
    monkeypatch.setattr(io, "open", rec_open)
    monkeypatch.setattr(os, "open", rec_os_open)
    return opened


# =========================================================================== OBJ files outside the folder
@pytest.mark.parametrize("ref", ["../outside.mtl", "{abs}", "link.mtl"])
def test_obj_mtllib_outside_the_model_folder_is_not_read(tmp_path, capsys, monkeypatch, ref):
    outside = tmp_path / "outside.mtl"
    outside.write_text("newmtl red\nKd 1 0 0\n")
    model = tmp_path / "model"
    model.mkdir()
    if ref == "link.mtl":
        os.symlink(outside, model / "link.mtl")
    ref = ref.replace("{abs}", str(outside))
    p = model / "m.obj"
    p.write_text(f"mtllib {ref}\n" + TRI + "usemtl red\nf 1 2 3\n")
    opened = _record_opens(monkeypatch)
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert code == 0, err
    assert not any(Path(o).resolve() == outside.resolve() for o in opened), "the .mtl outside was read"
    assert any("outside the model's folder" in w and "m.obj:1" in w for w in warnings_of(out)), warnings_of(out)
    assert report(out)["input"]["files_read"] == [str(p)]


def test_obj_texture_outside_the_model_folder_is_not_used(tmp_path, capsys):
    (tmp_path / "private.png").write_bytes(b"\x89PNG\r\n\x1a\n not really")
    model = tmp_path / "model"
    model.mkdir()
    (model / "m.mtl").write_text(f"newmtl a\nmap_Kd {tmp_path / 'private.png'}\nnewmtl b\nmap_Kd ../private.png\n")
    p = model / "m.obj"
    p.write_text("mtllib m.mtl\n" + TRI + "vt 0 0\nusemtl a\nf 1/1 2/1 3/1\nusemtl b\nf 3/1 2/1 1/1\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert code == 0, err
    w = [w for w in warnings_of(out) if "outside the model's folder" in w]
    assert len(w) == 2 and "m.mtl:2" in w[0] and "m.mtl:4" in w[1], warnings_of(out)
    assert str(tmp_path / "private.png") not in report(out)["input"]["files_read"]


def test_names_longer_than_the_file_system_allows(tmp_path, capsys):
    """Fuzz find: a 300-byte mtllib / map_Kd / image name made ``Path.is_file`` raise (ENAMETOOLONG)
    and the bake end in an internal error. Now: the OBJ bakes with a warning naming the line, the
    glTF fails naming the image."""
    long = "x" * 300
    (tmp_path / "m.mtl").write_text(f"newmtl a\nmap_Kd {long}.png\n")
    p = tmp_path / "m.obj"
    p.write_text(f"mtllib {long}.mtl\nmtllib m.mtl\n" + TRI + "usemtl a\nf 1 2 3\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert code == 0, err
    w = warnings_of(out)
    assert any("not found" in x and "m.obj:1" in x for x in w) and any("m.mtl:2" in x for x in w), w
    doc, buf = good_doc(uvs=np.zeros((4, 2)))
    doc["images"] = [{"uri": long + ".png"}]
    doc["textures"] = [{"source": 0}]
    doc["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    doc["meshes"][0]["primitives"][0]["material"] = 0
    g = write_gltf(tmp_path / "m.gltf", doc, buf)
    code, _, err = bake(capsys, g, tmp_path / "out2")
    assert_clean_error(code, err, status=3, file="m.gltf", place=r"images\[0\]: uri 'x+\.\.\.' cannot be used")


def test_obj_subfolder_files_are_still_read(tmp_path, capsys):
    """The folder rule does not lose what is legitimately beside the model."""
    model = tmp_path / "model"
    (model / "mat").mkdir(parents=True)
    (model / "mat" / "m.mtl").write_text("newmtl red\nKd 1 0 0\n")
    p = model / "m.obj"
    p.write_text("mtllib mat/m.mtl\n" + TRI + "usemtl red\nf 1 2 3\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out)
    assert code == 0, err
    assert (out / "lists" / "mat_colors.txt").read_text() == str(255 * 65536)


# =========================================================================== coordinate range
@pytest.mark.parametrize("s", [1e-35, 1e-100, 1e-300])
def test_model_too_small_to_bake_is_an_input_error(tmp_path, capsys, s):
    p = tmp_path / "tiny.obj"
    p.write_text(f"v 0 0 0\nv {s!r} 0 0\nv 0 {s!r} 0\nf 1 2 3\n")
    code, _, err = bake(capsys, p, tmp_path / "out")
    assert_clean_error(code, err, status=3, file="tiny.obj", place="across")


@pytest.mark.parametrize("key,value", [("transform.scale", "1e300"), ("transform.fit", "1e300"),
                                       ("transform.scale", "1e-300"), ("transform.fit", "1e-40")])
def test_transform_out_of_range_names_the_key(tmp_path, capsys, key, value):
    p = tmp_path / "m.obj"
    p.write_text("v 0 0 0\nv 1e10 0 0\nv 0 1e10 0\nf 1 2 3\n")
    cfg = tmp_path / "c.toml"
    cfg.write_text(f'[input]\npath = "m.obj"\n[transform]\n{key.split(".")[1]} = {value}\n')
    code, _, err = bake(capsys, cfg, tmp_path / "out")
    # the line of the key in the config too (line 4: the key under [transform])
    assert_clean_error(code, err, status=2, file="c.toml", place=rf"c\.toml:4: key '{key}'")


# =========================================================================== config
CONFIG_ERRORS = [  # (name, body after [input], line, key)
    ("string_for_int", '[export]\nprecision = "five"\n', 4, "export.precision"),
    ("int_for_bool", "[bvh]\nenabled = 1\n", 4, "bvh.enabled"),
    ("string_for_list", '[lighting]\nambient = "dark"\n', 4, "lighting.ambient"),
    ("table_for_value", "[export.precision]\nx = 1\n", 3, "export.precision"),
    ("unknown_key", "[export]\nprecison = 4\n", 4, "export.precison"),
    ("unknown_section", "[exprot]\nprecision = 4\n", 3, "exprot"),
    ("unknown_in_array_table", '[[lighting.lights]]\nkind = "sun"\ncolour = [1, 1, 1]\n', 5,
     r"lighting.lights\[0\].colour"),
    ("nan", "[transform]\nscale = nan\n", 4, "transform.scale"),
    ("inf", "[transform]\nscale = -inf\n", 4, "transform.scale"),
    ("bad_choice", '[transform]\nup = "w"\n', 4, "transform.up"),
    ("negative_scale", "[transform]\nscale = -1.0\n", 4, "transform.scale"),
    ("precision_out_of_range", "[export]\nprecision = 99\n", 4, "export.precision"),
    ("stage_range_check", "[bvh]\nenabled = true\nleaf_size = 99\n", 5, "bvh.leaf_size"),
    ("light_direction_length", '[[lighting.lights]]\nkind = "sun"\ndirection = [0, 1]\n', 5,
     r"lighting.lights\[0\].direction"),
]


@pytest.mark.parametrize("name,body,line,key", CONFIG_ERRORS, ids=[c[0] for c in CONFIG_ERRORS])
def test_bad_config_names_file_line_and_key(tmp_path, capsys, name, body, line, key):
    (tmp_path / "m.obj").write_text(TRI + "f 1 2 3\n")
    cfg = tmp_path / f"{name}.toml"
    cfg.write_text('[input]\npath = "m.obj"\n' + body)
    code, _, err = bake(capsys, cfg, tmp_path / "out")
    where = rf"{name}\.toml:{line}: " if line else rf"{name}\.toml: "
    msg = assert_clean_error(code, err, status=2, file=cfg.name, place=rf"{where}key '{key}'")
    if name.startswith("unknown_key"):
        assert "did you mean 'export.precision'" in msg


@pytest.mark.parametrize("raw,place", [
    (b'[input\npath = "m.obj"\n', r"c\.toml:1: not valid TOML"),
    (b'[input]\npath = "m\xe9.obj"\n', r"c\.toml: config is not UTF-8"),
])
def test_unreadable_config(tmp_path, capsys, raw, place):
    cfg = tmp_path / "c.toml"
    cfg.write_bytes(raw)
    code, _, err = bake(capsys, cfg, tmp_path / "out")
    assert_clean_error(code, err, status=2, file="c.toml", place=place)


@pytest.mark.parametrize("assignment,key", [
    ("export.precision=abc", "export.precision"), ("export.precison=3", "export.precison"),
    ("input.format=fbx", "input.format"), ("lighting.lights=3", "lighting.lights"),
    ("transform.scale=0", "transform.scale"), ("nodot", None), ("bvh.enabled", None),
])
def test_bad_set_override_names_the_key(tmp_path, capsys, assignment, key):
    p = tmp_path / "m.obj"
    p.write_text(TRI + "f 1 2 3\n")
    code, _, err = bake(capsys, p, tmp_path / "out", "--set", assignment)
    assert_clean_error(code, err, status=2, file=None, place=rf"key '{key}'" if key else "--set expects")


# =========================================================================== .sb3 (export.into)
def _zip(entries: dict[str, bytes], method=zipfile.ZIP_DEFLATED) -> bytes:
    import io

    b = io.BytesIO()
    with zipfile.ZipFile(b, "w", method) as z:
        for k, v in entries.items():
            z.writestr(k, v)
    return b.getvalue()


def _project() -> bytes:
    return json.dumps({"targets": [{"isStage": True, "name": "Stage", "variables": {}, "lists": {},
                                    "broadcasts": {}, "blocks": {}, "comments": {}, "currentCostume": 0,
                                    "costumes": [], "sounds": [], "volume": 100, "layerOrder": 0}],
                       "monitors": [], "extensions": [], "meta": {"semver": "3.0.0"}}).encode()


def _sb3_case(name: str) -> tuple[bytes, str]:
    if name == "not_a_zip":
        return b"hello, not a zip", "not a Scratch project archive"
    if name == "empty":
        return b"", "not a Scratch project archive"
    if name == "truncated":
        return _zip({"project.json": _project()})[:-30], "not a Scratch project archive"
    if name == "ratio_bomb":  # 4 MiB of zeros: about 4 KiB compressed
        return _zip({"project.json": _project(), "a.bin": b"\0" * (4 << 20)}), "compression ratio"
    if name == "many_entries":
        return _zip({f"{i}.txt": b"" for i in range(10_001)}, zipfile.ZIP_STORED), "10001 entries"
    if name == "path_traversal":
        return _zip({"project.json": _project(), "../evil.txt": b"x"}), "outside the archive root"
    if name == "no_project_json":
        return _zip({"a.txt": b"x"}), "no project.json"
    if name == "project_not_json":
        return _zip({"project.json": b"{not json"}), "not valid JSON"
    if name == "project_without_targets":
        return _zip({"project.json": b'{"meta": {}}'}), "not a Scratch 3 project"
    if name == "lying_size":  # the header says 10 bytes, the data inflates to 1 MiB
        data = bytearray(_zip({"project.json": _project(), "a.bin": b"\0" * (1 << 20)}))
        for sig, off in ((b"PK\x03\x04", 22), (b"PK\x01\x02", 24)):
            i = data.rfind(sig)
            struct.pack_into("<I", data, i + off, 10)
        return bytes(data), "archive entry 'a.bin'"
    raise KeyError(name)


SB3_CASES = ["not_a_zip", "empty", "truncated", "ratio_bomb", "many_entries", "path_traversal", "lying_size",
             "no_project_json", "project_not_json", "project_without_targets"]


@pytest.mark.parametrize("name", SB3_CASES)
def test_bad_sb3_to_bake_into_is_an_input_error(tmp_path, capsys, name):
    data, what = _sb3_case(name)
    sb3 = tmp_path / "author" / "project.sb3"
    sb3.parent.mkdir()
    sb3.write_bytes(data)
    p = tmp_path / "m.obj"
    p.write_text(TRI + "f 1 2 3\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out, "--set", f'export.into="{sb3}"')
    assert sb3.read_bytes() == data, "the author's project was written"
    assert not out.exists()
    assert_clean_error(code, err, status=3, file="project.sb3", place=what)


def test_corrupt_deflate_data_in_sb3_is_an_input_error(tmp_path, capsys):
    data = (Path(__file__).resolve().parents[2] / "fuzz" / "corpus" / "sb3" / "crash-zlib-error.sb3").read_bytes()
    sb3 = tmp_path / "project.sb3"
    sb3.write_bytes(data)
    p = tmp_path / "m.obj"
    p.write_text(TRI + "f 1 2 3\n")
    code, _, err = bake(capsys, p, tmp_path / "out", "--set", f'export.into="{sb3}"')
    assert_clean_error(code, err, status=3, file=None, place="archive")


# =========================================================================== textures
def test_texture_that_is_not_an_image(tmp_path, capsys):
    """The bake never fails on it; where a stage reads textures, it warns naming the file."""
    (tmp_path / "t.png").write_text("this is not an image")
    (tmp_path / "m.mtl").write_text("newmtl a\nmap_Kd t.png\n")
    p = tmp_path / "m.obj"
    p.write_text("mtllib m.mtl\n" + TRI + "vt 0 0\nvt 1 0\nvt 0 1\nusemtl a\nf 1/1 2/2 3/3\n")
    out = tmp_path / "out"
    code, _, err = bake(capsys, p, out, "--set", "textures.enabled=true")
    assert code == 0 and err == "", err
    if "textures" in stages.names():
        assert any("t.png" in w for w in warnings_of(out)), warnings_of(out)
    else:  # not wired into the pipeline yet: the stage itself must say so when it runs
        from bake.config import TexturesConfig
        from bake.textures import stage as tex_stage

        cfg = pipeline.load_config_for(p)
        scene = pipeline.run(cfg, until="clean").scene
        _, rec = tex_stage.stage(scene, TexturesConfig(enabled=True))
        assert any("t.png" in w and "texture not used" in w for w in rec.warnings), rec.warnings


# =========================================================================== traceback and --debug
@pytest.mark.slow
def test_subprocess_error_is_one_line_and_debug_shows_the_traceback(tmp_path):
    p = tmp_path / "bad.obj"
    p.write_text(TRI + "f 1 2 9\n")
    plain = run_subprocess(["run", p, "--out", tmp_path / "out"])
    assert_clean_error(plain.returncode, plain.stderr, status=3, file="bad.obj", place=r"bad\.obj:4: ")
    for argv in (["--debug", "run", p, "--out", tmp_path / "out"], ["run", p, "--out", tmp_path / "out", "--debug"]):
        dbg = run_subprocess(argv)
        assert dbg.returncode == 3
        assert TRACEBACK in dbg.stderr and "InputError" in dbg.stderr, (argv, dbg.stderr)
        assert dbg.stderr.strip().splitlines()[-1] == plain.stderr.strip()


def test_debug_flag_before_the_command_shows_the_traceback(tmp_path, capsys):
    """``bake --debug run`` used to print no traceback: the subcommand's --debug default (False)
    overwrote the top-level flag. Fixed in bake/cli.py."""
    p = tmp_path / "bad.obj"
    p.write_text(TRI + "f 0 1 2\n")
    code, _, err = run_cli(["--debug", "run", p, "--out", tmp_path / "out"], capsys)
    assert code == 3 and TRACEBACK in err
