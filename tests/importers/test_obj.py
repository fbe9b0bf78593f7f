"""OBJ + MTL importer: every corpus OBJ against a plain-Python reading written here and against
trimesh, plus generated files for every face form, relative indices, vertex colours, MTL
statements, line endings and each error path."""

from __future__ import annotations

import collections
import os
from pathlib import Path

import numpy as np
import pytest

from bake.config import ImportJob
from bake.errors import InputError
from bake.importers.obj import load


# --------------------------------------------------------------------------- helpers
def write(tmp_path: Path, name: str, content: str | bytes) -> Path:
    p = tmp_path / name
    p.parent.mkdir(parents=True, exist_ok=True)
    p.write_bytes(content.encode() if isinstance(content, str) else content)
    return p


def absp(p: Path) -> Path:
    return Path(os.path.abspath(p))


def imp(path: Path, strict: bool = True):
    scene, rec = load(ImportJob(path=path, strict=strict))
    scene.validate()
    if scene.n_polygons:
        assert scene.poly_material.min() >= 0 and scene.poly_material.max() < len(scene.materials)
    return scene, rec


def polys(scene) -> list[list[int]]:
    off = scene.poly_offsets
    return [scene.poly_indices[off[i]:off[i + 1]].tolist() for i in range(scene.n_polygons)]


def warned(rec, *fragments: str) -> bool:
    return any(all(f in w for f in fragments) for w in rec.warnings)


def reference(path: Path) -> dict:
    """A deliberately simple line-by-line reading of an OBJ (independent of the importer):
    physical line numbers, joined continuation lines, per face its 0-based vertex indices
    (None for index 0 / out of range), whether it is valid, and its usemtl name."""
    text = path.read_bytes().decode("latin-1").replace("\r\n", "\n").replace("\r", "\n")
    logical: list[tuple[int, str]] = []
    pending, start = "", None
    for no, line in enumerate(text.split("\n"), 1):
        if start is None:
            start = no
        if line.rstrip(" \t").endswith("\\"):
            pending += line.rstrip(" \t")[:-1] + " "
            continue
        logical.append((start, pending + line))
        pending, start = "", None
    nv = nvt = 0
    raw_faces = []
    mat = "default"
    for no, line in logical:
        toks = line.split("#")[0].split()
        if not toks:
            continue
        if toks[0] == "v":
            nv += 1
        elif toks[0] == "vt":
            nvt += 1
        elif toks[0] == "usemtl":
            mat = " ".join(toks[1:]) or "default"
        elif toks[0] == "f":
            corners = []
            for c in toks[1:]:
                parts = c.split("/")
                corners.append((int(parts[0]), int(parts[1]) if len(parts) > 1 and parts[1] else None,
                                nv, nvt))
            raw_faces.append((no, corners, mat))
    faces = []
    for no, corners, m in raw_faces:
        idx, ok = [], len(corners) >= 3
        for v, t, v_before, t_before in corners:
            i = v - 1 if v > 0 else v_before + v if v < 0 else None
            if i is None or not 0 <= i < nv:
                ok, i = False, None
            if t is not None:
                j = t - 1 if t > 0 else t_before + t if t < 0 else None
                if j is None or not 0 <= j < nvt:
                    ok = False
            idx.append(i)
        faces.append({"line": no, "idx": idx, "ok": ok, "mat": m})
    return {"nv": nv, "nvt": nvt, "faces": faces}


CORPUS_OBJ = [
    ("box_blender_quads_2mtl", "box.obj"), ("capsule_textured", "capsule.obj"),
    ("concave_66gon", "concave_polygon.obj"),
    ("cornell_box_multimaterial", "cornell_box_multimaterial.obj"),
    ("cornell_box_tinyobj", "cornell_box.obj"), ("cube_quads_mtl", "cube.obj"),
    ("empty_obj", "empty.obj"), ("fuze_textured", "fuze.obj"),
    ("house_max2obj_walls", "regr01.obj"), ("ico4_mtl", "ico4.obj"),
    ("inconsistent_face_format", "issue-161-inconsistent-f.obj"),
    ("invalid_face_definition", "invalid-face-definition.obj"), ("jacked_missing_mtl", "jacked.obj"),
    ("joined_tetrahedra", "joined_tetrahedra.obj"), ("negative_indices", "negative_indices.obj"),
    ("ngon_concave_hugecoords", "issue-319-002.obj"),
    ("no_face_in_chunk", "obj_with_no_face_in_chunk.obj"), ("notenough_indices", "notenoughindices.obj"),
    ("obj_vertex_colors", "cube-vertexcol.obj"), ("polygonfaces_pentagon", "polygonfaces.obj"),
    ("quad_torus_creases", "catmark_torus_creases0.obj"),
    ("quads_large_coords", "issue-295-trianguation-failure.obj"),
    ("spot_quadrangulated", "spot/spot_control_mesh.obj"),
    ("spot_quadrangulated", "spot/spot_quadrangulated.obj"),
    ("spot_triangulated", "spot/spot_triangulated.obj"),
    ("stanford_bunny_res1_obj", "stanford-bunny.obj"), ("suzanne_obj", "suzanne.obj"),
    ("teapot_obj", "teapot.obj"), ("texture_filename_whitespace", "texture-filename-with-whitespace.obj"),
    ("vertex_w_component", "cube-vertex-w-component.obj"), ("wallhole_ngons", "wallhole.obj"),
    ("xatlas_degenerate_edge", "degenerate_edge.obj"), ("xatlas_double_sided", "double_sided.obj"),
    ("xatlas_duplicate_edge", "duplicate_edge.obj"), ("xatlas_zero_length_edge", "zero_length_edge.obj"),
    ("zero_face_index", "issue-140-zero-face-idx.obj"),
]
# broken on purpose: the strict import must fail with this message at this line
KNOWN_BAD = {
    "invalid-face-definition.obj": (15, "face has fewer than 3 vertices (1 given)"),
    "notenoughindices.obj": (9, "face has fewer than 3 vertices (2 given)"),
    "issue-140-zero-face-idx.obj": (16, "face index 0 is invalid"),
}


# --------------------------------------------------------------------------- corpus
@pytest.mark.corpus
@pytest.mark.parametrize("entry,name", CORPUS_OBJ, ids=[n for _, n in CORPUS_OBJ])
def test_corpus_faces_match_plain_reading(corpus, entry, name):
    """Polygon sizes, vertex indices and material names per face equal the plain reading;
    the known-bad files fail strict with file:line and drop exactly the bad faces otherwise."""
    path = corpus(entry, *name.split("/"))
    ref = reference(path)
    good = [f for f in ref["faces"] if f["ok"]]
    if name in KNOWN_BAD:
        line, msg = KNOWN_BAD[name]
        with pytest.raises(InputError) as e:
            load(ImportJob(path=path))
        assert str(e.value).startswith(f"{path}:{line}: {msg}")
        scene, rec = imp(path, strict=False)
        bad_lines = [f["line"] for f in ref["faces"] if not f["ok"]]
        assert warned(rec, f"dropped {len(bad_lines)} bad face", ", ".join(map(str, bad_lines[:3])))
    else:
        assert all(f["ok"] for f in ref["faces"])
        scene, rec = imp(path)
    assert scene.n_vertices == ref["nv"]
    assert polys(scene) == [f["idx"] for f in good]
    assert [scene.materials[m].name for m in scene.poly_material] == [f["mat"] for f in good]
    expect = collections.Counter(str(len(f["idx"])) for f in good)
    assert rec.details["polygon_sizes"] == dict(expect)
    assert scene.source.format == "obj" and scene.source.files_read[0] == absp(path)
    if not good:
        assert warned(rec, "no faces")


@pytest.mark.corpus
def test_corpus_polygon_sizes_by_counting_tokens(corpus):
    """The simplest independent count (tokens per `f` line) for files without continuations."""
    for entry, name, expect in [("suzanne_obj", "suzanne.obj", {"3": 32, "4": 468}),
                                ("wallhole_ngons", "wallhole.obj", {"6": 9, "8": 2, "11": 2}),
                                ("concave_66gon", "concave_polygon.obj", {"66": 1}),
                                ("ngon_concave_hugecoords", "issue-319-002.obj",
                                 {"5": 1, "7": 1, "8": 1})]:
        path = corpus(entry, name)
        text = path.read_bytes().decode("latin-1").replace("\\\r\n", " ").replace("\\\n", " ")
        counted = collections.Counter(str(len(ln.split()) - 1) for ln in text.splitlines()
                                      if ln.split()[:1] == ["f"])
        assert dict(counted) == expect
        assert imp(path)[1].details["polygon_sizes"] == expect


@pytest.mark.corpus
def test_corpus_nan_inf_is_an_error_naming_the_lines(corpus):
    path = corpus("test_nan_inf", "test-nan.obj")
    for strict in (True, False):
        with pytest.raises(InputError) as e:
            load(ImportJob(path=path, strict=strict))
        assert str(e.value) == (f"{path}:12: vertex values are NaN or infinite on 4 line(s): "
                                f"12, 13, 14, 15")


@pytest.mark.corpus
@pytest.mark.parametrize("entry,name", [("teapot_obj", "teapot.obj"), ("suzanne_obj", "suzanne.obj"),
                                        ("capsule_textured", "capsule.obj"),
                                        ("concave_66gon", "concave_polygon.obj"),
                                        ("wallhole_ngons", "wallhole.obj")])
def test_corpus_positions_equal_trimesh(corpus, entry, name):
    trimesh = pytest.importorskip("trimesh")
    path = corpus(entry, name)
    m = trimesh.load(path, process=False, force="mesh")
    scene, _ = imp(path)
    assert np.array_equal(scene.positions, np.asarray(m.vertices, dtype=np.float64))


@pytest.mark.corpus
@pytest.mark.parametrize("entry,name,uv", [
    ("stanford_bunny_res1_obj", "stanford-bunny.obj", False), ("teapot_obj", "teapot.obj", False),
    ("capsule_textured", "capsule.obj", True), ("fuze_textured", "fuze.obj", True),
    ("spot_triangulated", "spot/spot_triangulated.obj", True)])
def test_corpus_triangle_corners_equal_trimesh(corpus, entry, name, uv):
    """trimesh splits/drops vertices, but each triangle's corner positions (and UVs) must agree."""
    trimesh = pytest.importorskip("trimesh")
    path = corpus(entry, *name.split("/"))
    m = trimesh.load(path, process=False, force="mesh")
    scene, _ = imp(path)
    assert (scene.poly_sizes == 3).all()
    ours = scene.positions[scene.poly_indices.reshape(-1, 3)]
    assert np.array_equal(ours, np.asarray(m.vertices)[np.asarray(m.faces)])
    if uv:
        theirs = np.asarray(m.visual.uv)[np.asarray(m.faces)].reshape(-1, 2)
        assert np.array_equal(scene.poly_uvs, theirs)
    else:
        assert scene.poly_uvs is None


@pytest.mark.corpus
def test_corpus_w_component_and_vertex_colours(corpus):
    w = corpus("vertex_w_component", "cube-vertex-w-component.obj")
    c = corpus("obj_vertex_colors", "cube-vertexcol.obj")
    rows_w = [ln.split()[1:] for ln in w.read_text().splitlines() if ln.startswith("v ")]
    rows_c = [ln.split()[1:] for ln in c.read_text().splitlines() if ln.startswith("v ")]
    sw, _ = imp(w)
    sc, _ = imp(c)
    assert np.array_equal(sw.positions, np.array([r[:3] for r in rows_w], float))
    assert sw.vertex_colors is None
    assert np.array_equal(sc.positions, np.array([r[:3] for r in rows_c], float))
    assert np.array_equal(sc.vertex_colors[:, :3], np.array([r[3:6] for r in rows_c], float))
    assert (sc.vertex_colors[:, 3] == 1).all()
    assert np.array_equal(sw.positions, sc.positions)


@pytest.mark.corpus
def test_corpus_mixed_face_formats(corpus):
    path = corpus("inconsistent_face_format", "issue-161-inconsistent-f.obj")
    scene, rec = imp(path)
    assert polys(scene)[-1] == [4, 0, 2]  # "f 5 1 3" after eleven v/vt faces
    assert np.array_equal(scene.poly_uvs[-3:], np.zeros((3, 2)))
    assert np.array_equal(scene.poly_uvs[:3], [[0, 0], [1, 0], [0, 1]])
    assert warned(rec, "3 of 36 face corners have no texture coordinate")


@pytest.mark.corpus
def test_corpus_textures_with_spaces_and_missing(corpus):
    fuze = corpus("fuze_textured", "fuze.obj")
    scene, rec = imp(fuze)
    (mat,) = scene.materials
    assert mat.name == "a-super-duper-material"
    assert mat.texture == absp(fuze.parent / "fuze uv.jpg") and mat.texture.is_file()
    assert mat.color == (1.0, 1.0, 1.0, 1.0)  # "Tr 1.000000" from MeshLab is read as opaque
    assert warned(rec, "'Tr 1'", "opaque")
    assert scene.source.files_read == (absp(fuze), absp(fuze.parent / "fuze.obj.mtl"), mat.texture)
    ws = corpus("texture_filename_whitespace", "texture-filename-with-whitespace.obj")
    scene, rec = imp(ws)
    assert [m.name for m in scene.materials] == ["white", "red", "green"]
    assert all(m.texture is None for m in scene.materials)
    assert warned(rec, "texture not found: 'texture 01.png'", "material 'white'")
    assert scene.materials[1].color == (1.0, 0.0, 0.0, 1.0)


@pytest.mark.corpus
def test_corpus_missing_mtl_and_latin1_names(corpus):
    jacked = corpus("jacked_missing_mtl", "jacked.obj")
    scene, rec = imp(jacked)
    assert warned(rec, "material library not found: 'nonexistent.mtl'", "jacked.obj:2")
    assert [m.name for m in scene.materials] == ["material0"]
    assert scene.materials[0].color == (0.8, 0.8, 0.8, 1.0)
    house = corpus("house_max2obj_walls", "regr01.obj")
    scene, rec = imp(house)
    names = [m.name for m in scene.materials]
    terrain = scene.materials[names.index("Terraind\xe6k")]
    assert terrain.color == (0.4, 0.3, 0.3, 1.0)  # matched its Latin-1 newmtl in regr01.mtl
    assert warned(rec, "Latin-1", "4841")


# --------------------------------------------------------------------------- generated files
SQUARE = "v 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\nvt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nvn 0 0 1\n"


def test_all_four_face_forms_and_mixtures(tmp_path):
    p = write(tmp_path, "forms.obj", SQUARE + (
        "f 1 2 3\n"
        "f 1/1 2/2 3/3\n"
        "f 1//1 2//1 3//1\n"
        "f 1/1/1 2/2/1 3/3/1 4/4/1\n"
        "f 4/4 3//1 2/2/1 1\n"
        "f 1/ 2/3/ 3//\n"))
    scene, rec = imp(p)
    assert polys(scene) == [[0, 1, 2]] * 3 + [[0, 1, 2, 3], [3, 2, 1, 0], [0, 1, 2]]
    uv = scene.poly_uvs
    vt = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], float)
    no = [0, 0]
    expect = [no, no, no, *vt[:3], no, no, no, *vt, vt[3], no, vt[1], no, no, vt[2], no]
    assert np.array_equal(uv, np.array(expect, float))
    assert uv.dtype == np.float64
    assert warned(rec, "face corners have no texture coordinate")


def _random_obj(rng, negative: np.ndarray | None, crlf=False, chunks=6):
    """OBJ text with interleaved chunks of v/vt and faces; `negative` says per corner field
    whether to write it relative (the same mesh either way)."""
    out, nv, nvt, k = [], 0, 0, 0
    for c in range(chunks):
        n = int(rng.integers(5, 12))
        for _ in range(n):
            out.append("v " + " ".join(repr(float(x)) for x in rng.normal(size=3)))
            out.append("vt " + " ".join(repr(float(x)) for x in rng.random(2)))
        nv += n
        nvt += n
        out.append(f"usemtl m{c % 3}")
        for _ in range(int(rng.integers(2, 6))):
            size = int(rng.integers(3, 8))
            vs = rng.integers(0, nv, size)
            ts = rng.integers(0, nvt, size)
            parts = []
            for a, b in zip(vs, ts):
                neg_v = negative is not None and negative[k % len(negative), 0]
                neg_t = negative is not None and negative[k % len(negative), 1]
                k += 1
                parts.append(f"{a - nv if neg_v else a + 1}/{b - nvt if neg_t else b + 1}")
            out.append("f " + " ".join(parts))
    return ("\r\n" if crlf else "\n").join(out) + "\n"


def test_negative_indices_equal_positive(tmp_path):
    for seed in range(3):
        pos = write(tmp_path, f"pos{seed}.obj", _random_obj(np.random.default_rng(seed), None))
        flags = np.random.default_rng(100 + seed).random((97, 2)) < 0.5
        neg = write(tmp_path, f"neg{seed}.obj", _random_obj(np.random.default_rng(seed), flags))
        assert "/-" in neg.read_text() and " -" in neg.read_text()
        a, _ = imp(pos)
        b, _ = imp(neg)
        for name in ("positions", "poly_sizes", "poly_indices", "poly_material", "poly_uvs"):
            assert np.array_equal(getattr(a, name), getattr(b, name)), name
        assert [m.name for m in a.materials] == [m.name for m in b.materials]
        assert polys(a) == [f["idx"] for f in reference(pos)["faces"]]


@pytest.mark.corpus
def test_corpus_negative_indices_equal_positive_rewrite(corpus, tmp_path):
    path = corpus("negative_indices", "negative_indices.obj")
    lines, nv, nvt, nvn = [], 0, 0, 0
    for ln in path.read_text().splitlines():
        t = ln.split()
        nv += t[:1] == ["v"]
        nvt += t[:1] == ["vt"]
        nvn += t[:1] == ["vn"]
        if t[:1] == ["f"]:
            ln = "f " + " ".join("/".join(str(int(x) + 1 + n) if x else "" for x, n in
                                          zip(c.split("/"), (nv, nvt, nvn))) for c in t[1:])
        lines.append(ln)
    pos = write(tmp_path, "positive.obj", "\n".join(lines) + "\n")
    assert "-" not in "".join(ln for ln in lines if ln.startswith("f"))
    a, _ = imp(path)
    b, _ = imp(pos)
    assert np.array_equal(a.poly_indices, b.poly_indices)
    assert np.array_equal(a.poly_uvs, b.poly_uvs)
    assert polys(a)[0] == [0, 4, 6, 2]


def test_line_endings_tabs_comments_and_continuations_do_not_change_the_result(tmp_path):
    rng = np.random.default_rng(7)
    text = _random_obj(rng, None)
    base, base_rec = imp(write(tmp_path, "lf.obj", text))
    lines = text.splitlines()
    variants = {
        "crlf": "\r\n".join(lines) + "\r\n",
        "cr": "\r".join(lines),  # old Mac, no final newline
        "tabs_comments": "# header\n\n" + "\n".join(
            "\t " + ln.replace(" ", " \t ") + "   # trailing comment" for ln in lines) + "\n# end",
        "continued": "\n".join(ln.replace(" ", " \\\n", 1) if ln.startswith("f") else ln
                               for ln in lines) + "\n",
        "continued_crlf": "\r\n".join(ln.replace(" ", " \\\r\n", 1) if ln.startswith("f") else ln
                                      for ln in lines),
        "bom": "\ufeff" + text,
    }
    for name, v in variants.items():
        s, rec = imp(write(tmp_path, f"{name}.obj", v))
        for field in ("positions", "poly_sizes", "poly_indices", "poly_material", "poly_uvs"):
            assert np.array_equal(getattr(s, field), getattr(base, field)), (name, field)
        assert rec.warnings == base_rec.warnings, name


def test_error_after_continuation_names_the_physical_line(tmp_path):
    p = write(tmp_path, "cont.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 \\\n2 \\\n3\n\nf 1 2 9\n")
    with pytest.raises(InputError) as e:
        load(ImportJob(path=p))
    assert str(e.value) == f"{p}:8: face index 9 is out of range (file has 3 vertices)"


CUBE8 = "".join(f"v {x} {y} {z}\n" for x in (0, 1) for y in (0, 1) for z in (0, 1))


@pytest.mark.parametrize("face,line_msg", [
    ("f 1 2 9", "12: face index 9 is out of range (file has 8 vertices)"),
    ("f 1 2 -9", "12: face index -9 is out of range (8 vertices defined before this line)"),
    ("f 1 0 2", "12: face index 0 is invalid (OBJ indices start at 1)"),
    ("f 1 2", "12: face has fewer than 3 vertices (2 given)"),
    ("f", "12: face has fewer than 3 vertices (0 given)"),
    ("f 1/1 2/2 3/7", "12: face texture index 7 is out of range (file has 2 texture coordinates)"),
    ("f 1/0 2/1 3/2", "12: face texture index 0 is invalid (OBJ indices start at 1)"),
])
def test_bad_faces_strict_error_and_lenient_drop(tmp_path, face, line_msg):
    text = CUBE8 + "vt 0 0\nvt 1 1\nf 1 2 3\n" + face + "\nf 5 6 7 8\n"
    p = write(tmp_path, "model.obj", text)
    with pytest.raises(InputError) as e:
        load(ImportJob(path=p))
    assert str(e.value) == f"{p}:{line_msg}"
    assert e.value.exit_code == 3
    scene, rec = imp(p, strict=False)
    assert polys(scene) == [[0, 1, 2], [4, 5, 6, 7]]
    assert warned(rec, "dropped 1 bad face(s)", "at lines 12;", line_msg.split(": ", 1)[1])


def test_lenient_warning_counts_and_lists_first_lines(tmp_path):
    faces = "".join("f 1 2 99\n" if i % 3 == 0 else "f 1 2 3\n" for i in range(30))
    p = write(tmp_path, "m.obj", CUBE8 + faces)
    scene, rec = imp(p, strict=False)
    assert scene.n_polygons == 20
    assert warned(rec, "dropped 10 bad face(s)", "at lines 9, 12, 15, 18, 21, ...")


@pytest.mark.parametrize("bad_line,msg", [
    ("v 1 2 x", "malformed number 'x' in a 'v' line"),
    ("v 1 2 3,5", "malformed number '3,5' in a 'v' line"),
    ("v 1 2 1_0", "malformed number '1_0' in a 'v' line"),
    ("v 1 2", "vertex needs x y z, got 2 value(s)"),
    ("vt 0.5 zz", "malformed number 'zz' in a 'vt' line"),
    ("vt", "texture coordinate needs u [v [w]], got no values"),
    ("f 1 2 3.5", "malformed face corner '3.5'"),
    ("f 1/1/1/1 2 3", "malformed face corner '1/1/1/1'"),
    ("f a b c", "malformed face corner 'a'"),
    ("f /1 2 3", "malformed face corner '/1'"),
    ("f 1 2- 3", "malformed face corner '2-'"),
    ("f 1 --2 3", "malformed face corner '--2'"),
    ("f 1 2 3/-", "malformed face corner '3/-'"),
    ("f 1 2 12345678901234567890", "malformed face corner '12345678901234567890'"),
])
def test_malformed_numbers_name_file_and_line(tmp_path, bad_line, msg):
    p = write(tmp_path, "bad.obj", CUBE8 + "vt 0 0\n# note\n" + bad_line + "\nf 1 2 3\n")
    for strict in (True, False):
        with pytest.raises(InputError) as e:
            load(ImportJob(path=p, strict=strict))
        assert str(e.value).startswith(f"{p}:11: {msg}")


def test_nan_inf_lines_are_named(tmp_path):
    p = write(tmp_path, "nan.obj", "v 0 0 0\nv 1 0 0\nv nan 1 0\nv 1 -inf 0\nv 1 1 1.#INF\nf 1 2 3\n")
    with pytest.raises(InputError) as e:
        load(ImportJob(path=p, strict=False))
    assert str(e.value) == f"{p}:3: vertex values are NaN or infinite on 3 line(s): 3, 4, 5"
    p = write(tmp_path, "nanuv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0 0\nvt inf 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"nanuv.obj:5: texture coordinates are NaN or infinite"):
        load(ImportJob(path=p))
    p = write(tmp_path, "nancol.obj", "v 0 0 0 1 nan 1\nv 1 0 0\nv 0 1 0\nf 1 2 3\n")
    with pytest.raises(InputError, match=r"nancol.obj:1: vertex values are NaN"):
        load(ImportJob(path=p))


def test_vertex_colour_rules(tmp_path):
    s, rec = imp(write(tmp_path, "rgba.obj",
                       "v 0 0 0 0.1 0.2 0.3 0.4\nv 1 0 0 1 1 1 1\nv 0 1 0 0 0 0 0\nf 1 2 3\n"))
    assert np.array_equal(s.vertex_colors, [[0.1, 0.2, 0.3, 0.4], [1, 1, 1, 1], [0, 0, 0, 0]])
    assert np.array_equal(s.positions, [[0, 0, 0], [1, 0, 0], [0, 1, 0]])
    s, rec = imp(write(tmp_path, "255.obj", "v 0 0 0 255 0 51\nv 1 0 0 0 255 0\nv 0 1 0 0 0 255\nf 1 2 3\n"))
    assert np.allclose(s.vertex_colors[0], [1, 0, 0.2, 1]) and rec.details["vertex_color_scale"] == "0-255"
    s, rec = imp(write(tmp_path, "mixed.obj", "v 0 0 0 1 0 0\nv 1 0 0\nv 0 1 0 0.5 0.5 0.5\nf 1 2 3\n"))
    assert np.array_equal(s.vertex_colors, [[1, 0, 0, 1], [1, 1, 1, 1], [0.5, 0.5, 0.5, 1]])
    assert warned(rec, "1 of 3 vertices have no colour")
    s, rec = imp(write(tmp_path, "hdr.obj", "v 0 0 0 1.5 -0.5 0.5\nv 1 0 0 0 0 0\nv 0 1 0 0 0 0\nf 1 2 3\n"))
    assert np.array_equal(s.vertex_colors[0], [1, 0, 0.5, 1]) and warned(rec, "clipped")
    s, rec = imp(write(tmp_path, "five.obj", "v 0 0 0 7 7\nv 1 0 0\nv 0 1 0 1\nf 1 2 3\n"))
    assert s.vertex_colors is None and np.array_equal(s.positions[0], [0, 0, 0])
    assert warned(rec, "1 'v' line(s) have 5 values", "lines 1")


def test_texcoord_forms(tmp_path):
    s, _ = imp(write(tmp_path, "uv.obj", "v 0 0 0\nv 1 0 0\nv 0 1 0\nvt 0.25\nvt 0.5 0.75 0.9\n"
                                        "vt 1 2\nf 1/1 2/2 3/3\n"))
    assert np.array_equal(s.poly_uvs, [[0.25, 0], [0.5, 0.75], [1, 2]])


MTL = """# test library
newmtl plain
Kd 0.1 0.2 0.3
newmtl glass
Kd 0.5
d 0.25
newmtl tr_only
Tr 0.25
newmtl both
Tr 0.9
d 0.6
newmtl meshlab
Tr 1.000000
newmtl textured
Kd 1 1 1
map_Kd -s 1 1 1 -bm 2 -clamp on tex dir\\my tex.png
newmtl notex
map_Kd missing.png
newmtl scaled
map_Kd -o 0.5 0.5 -bm 1 "tex dir/my tex.png"
newmtl unused
Kd 0 1 0
"""


def test_mtl_statements(tmp_path):
    write(tmp_path, "lib.mtl", MTL)
    write(tmp_path, "tex dir/my tex.png", b"\x89PNG fake")
    obj = CUBE8 + "mtllib lib.mtl\n" + "f 1 2 3\n" + "".join(
        f"usemtl {m}\nf 1 2 3\n" for m in
        ["plain", "glass", "tr_only", "both", "meshlab", "textured", "notex", "ghost", "plain",
         "scaled"])
    p = write(tmp_path, "m.obj", obj)
    s, rec = imp(p)
    by = {m.name: m for m in s.materials}
    assert [m.name for m in s.materials] == ["default", "plain", "glass", "tr_only", "both",
                                             "meshlab", "textured", "notex", "ghost", "scaled"]
    assert s.poly_material.tolist() == [0, 1, 2, 3, 4, 5, 6, 7, 8, 1, 9]
    assert by["plain"].color == (0.1, 0.2, 0.3, 1.0)
    assert by["glass"].color == (0.5, 0.5, 0.5, 0.25)
    assert by["tr_only"].color[3] == 0.75
    assert by["both"].color[3] == 0.6  # d wins over Tr
    assert by["meshlab"].color[3] == 1.0 and warned(rec, "'Tr 1' in 'meshlab'")
    tex = absp(tmp_path / "tex dir" / "my tex.png")
    assert by["textured"].texture == tex and by["textured"].texture.is_absolute()
    assert by["scaled"].texture == tex  # -o takes 1-3 numbers; quotes removed
    assert by["notex"].texture is None and warned(rec, "texture not found: 'missing.png'")
    assert by["ghost"].color == (0.8, 0.8, 0.8, 1.0) and warned(rec, "'ghost'", "default colour")
    assert by["default"].color == (0.8, 0.8, 0.8, 1.0)
    assert rec.details["materials_unused"] == ["unused"]
    assert s.source.files_read == (absp(p), absp(tmp_path / "lib.mtl"), tex)


def test_mtllib_fallbacks_and_malformed_mtl_lines(tmp_path):
    write(tmp_path, "Lib One.MTL", "newmtl a\nKd 1 0 0\nnewmtl b\nKd 1 x 0\nd 2\n")
    write(tmp_path, "second.mtl", "newmtl c\nKd 0 0 1\nmap_Kd C:\\Users\\someone\\tex.png\n")
    write(tmp_path, "tex.png", b"fake")
    p = write(tmp_path, "m.obj", "mtllib lib one.mtl\nmtllib ..\\elsewhere\\second.mtl nothere.mtl\n"
                                 "v 0 0 0\nv 1 0 0\nv 0 1 0\nusemtl a\nf 1 2 3\nusemtl b\nf 1 2 3\n"
                                 "usemtl c\nf 1 2 3\n")
    s, rec = imp(p)
    a, b, c = s.materials
    assert a.color == (1.0, 0.0, 0.0, 1.0)  # "lib one.mtl" found case-insensitively, spaces kept
    assert b.color == (0.8, 0.8, 0.8, 1.0)  # Kd malformed -> ignored; d 2 clipped to 1
    assert warned(rec, "Lib One.MTL:4: malformed number in 'Kd'")
    assert warned(rec, "alpha of 'b' outside [0, 1] was clipped")
    assert c.color == (0.0, 0.0, 1.0, 1.0) and c.texture == absp(tmp_path / "tex.png")
    assert warned(rec, "material library not found: 'nothere.mtl'")


def test_missing_mtl_gives_named_default_materials(tmp_path):
    p = write(tmp_path, "m.obj", "mtllib gone.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\nf 1 2 3\n"
                                 "usemtl red\nf 3 2 1\nusemtl\nf 1 3 2\n")
    s, rec = imp(p)
    assert [m.name for m in s.materials] == ["default", "red"]
    assert s.poly_material.tolist() == [0, 1, 0]
    assert all(m.color == (0.8, 0.8, 0.8, 1.0) for m in s.materials)
    assert warned(rec, "material library not found: 'gone.mtl'", "m.obj:1")
    assert s.source.files_read == (absp(p),)


def test_latin1_names_match_between_obj_and_mtl(tmp_path):
    write(tmp_path, "l.mtl", b"newmtl Terraind\xe6k\nKd 0.4 0.3 0.3\n")
    p = write(tmp_path, "l.obj", b"mtllib l.mtl\nv 0 0 0\nv 1 0 0\nv 0 1 0\no \xff\xfe\n"
                                 b"usemtl Terraind\xe6k\nf 1 2 3\n")
    s, rec = imp(p)
    (m,) = s.materials
    assert m.name == "Terraind\xe6k" and m.color == (0.4, 0.3, 0.3, 1.0)
    assert warned(rec, "Latin-1", "lines 6")


def test_directives_skipped_and_counted(tmp_path):
    p = write(tmp_path, "d.obj", "o thing\ng a b\ns off\nmg 1\nv 0 0 0\nv 1 0 0\nv 0 1 0\n"
                                 "l 1 2\nl 2 3\np 1\nt crease 2/1/0 1 2 4.7\nt crease 2/1/0 2 3 4.7\n"
                                 "curv 0 1 1 2\nfoo\nf 1 2 3\n")
    s, rec = imp(p)
    assert s.n_polygons == 1
    assert warned(rec, "skipped 2 line element(s) ('l') and 1 point element(s) ('p')")
    assert warned(rec, "ignored 4 line(s)", "'t' x2 (first at line 11)", "'curv' x1", "'foo' x1")
    assert rec.details["unknown_directives"] == {"curv": 1, "foo": 1, "t": 2}
    assert len(rec.warnings) == 2


@pytest.mark.parametrize("content", [b"", b"# only a comment\n\n", b"v 0 0 0\nv 1 1 1\n", b"\n\r\n  \t\n"])
def test_empty_or_faceless_file_gives_zero_polygons_and_a_warning(tmp_path, content):
    s, rec = imp(write(tmp_path, "e.obj", content))
    assert s.n_polygons == 0 and s.poly_sizes.dtype == np.int64 and len(s.poly_indices) == 0
    assert s.poly_uvs is None and s.materials[0].name == "default"
    assert warned(rec, "no faces in file")
    assert rec.details["polygon_sizes"] == {}


def test_binary_garbage_is_an_input_error(tmp_path):
    rng = np.random.default_rng(3)
    garbage = rng.integers(0, 256, 4096, dtype=np.uint8).tobytes()
    with pytest.raises(InputError, match="not a text file"):
        load(ImportJob(path=write(tmp_path, "g.obj", garbage)))
    ctrl = bytes(rng.integers(1, 8, 2000, dtype=np.uint8)) + b"v 0 0 0\n"
    with pytest.raises(InputError, match="not a text file"):
        load(ImportJob(path=write(tmp_path, "c.obj", ctrl)))
    with pytest.raises(InputError, match="UTF-16"):
        load(ImportJob(path=write(tmp_path, "u.obj", "v 0 0 0\n".encode("utf-16"))))
    with pytest.raises(InputError, match="cannot read file"):
        load(ImportJob(path=tmp_path / "absent.obj"))


def test_record_counts(tmp_path):
    p = write(tmp_path, "r.obj", SQUARE + "f 1/1 2/2 3/3\nf 1 2 3 4\nf 1 2 3 4\nf 4 3 2 1 1\n")
    s, rec = imp(p)
    assert rec.details["polygon_sizes"] == {"3": 1, "4": 2, "5": 1}
    assert rec.counts_out == {"polygons": 4, "triangles": 0, "vertices": 4, "materials": 1,
                              "uv_corners": 3}
    assert rec.name == "import" and rec.seconds > 0
    assert rec.details["normals"] == 1 and rec.details["texcoords"] == 4


def test_determinism(tmp_path):
    text = _random_obj(np.random.default_rng(11), np.random.default_rng(12).random((50, 2)) < 0.3)
    p = write(tmp_path, "d.obj", text)
    a, ra = load(ImportJob(path=p))
    b, rb = load(ImportJob(path=p))
    for name in ("positions", "poly_sizes", "poly_indices", "poly_material", "poly_uvs"):
        x, y = getattr(a, name), getattr(b, name)
        assert x.dtype == y.dtype and x.tobytes() == y.tobytes()
    assert a.materials == b.materials and ra.warnings == rb.warnings
    assert {k: v for k, v in ra.details.items()} == rb.details
