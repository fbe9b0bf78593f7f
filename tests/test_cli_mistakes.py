"""Mistakes a bug hunt found the command line letting through with exit 0: a depfile over one of
the bake's own files, the manifest's name taken by a project, a BVH list prefix that replaces
the BSP lists, a model whose every face is degenerate, quads written whole beside lists that go
per triangle, and ``bake report`` on a folder whose lists.json is gone or damaged."""

import hashlib
import json

import pytest

from test_cli import bake_subprocess, grid_obj, one_error_line


def _digests(folder):
    return {p.relative_to(folder).as_posix(): hashlib.sha256(p.read_bytes()).hexdigest()
            for p in sorted(folder.rglob("*")) if p.is_file()}


@pytest.fixture
def baked(tmp_path):
    model = grid_obj(tmp_path / "grid.obj", 2)
    out = tmp_path / "o"
    r = bake_subprocess(["run", model, "--out", out, "--quiet"])
    assert r.returncode == 0, r.stderr
    return model, out


@pytest.mark.parametrize("rel", ["lists/tris.txt", "lists/new.d", ".bake-manifest.json", "assets/x.d", "sweeps/x.d",
                                 ".bake-cache/x.d"])
def test_a_depfile_over_a_file_the_bake_writes_is_refused(baked, rel):
    model, out = baked
    before = _digests(out)
    r = bake_subprocess(["run", model, "--out", out, "--depfile", out / rel])
    assert "--depfile would overwrite an output of the bake" in one_error_line(r, 2, out / rel)
    assert _digests(out) == before


def test_a_depfile_beside_the_outputs_is_still_written(baked):
    model, out = baked
    r = bake_subprocess(["run", model, "--out", out, "--quiet", "--depfile", out / "grid.d"])
    assert r.returncode == 0, r.stderr
    assert (out / "grid.d").read_text().startswith(str(out))


@pytest.mark.parametrize("key", ["export.sb3_name", "export.into_name"])
def test_the_manifest_name_is_reserved(baked, key):
    model, out = baked
    before = _digests(out)
    r = bake_subprocess(["run", model, "--out", out, "--set", f"{key}=.bake-manifest.json"])
    assert "is a name the bake writes itself" in one_error_line(r, 2, key)
    assert _digests(out) == before


def test_a_bvh_prefix_that_takes_the_bsp_lists_names_is_refused(tmp_path):
    model = grid_obj(tmp_path / "grid.obj", 2)
    out = tmp_path / "o"
    r = bake_subprocess(["run", model, "--out", out, "--set", "bsp.enabled=true", "--set", "bvh.enabled=true",
                         "--set", "bvh.list_prefix=bsp"])
    err = one_error_line(r, 2, "bvh.list_prefix", "bsp nodes")
    assert "already written by an earlier stage (BSP records)" in err
    assert not out.exists()
    # another prefix: both trees' lists are written
    r = bake_subprocess(["run", model, "--out", out, "--quiet", "--set", "bsp.enabled=true", "--set",
                         "bvh.enabled=true", "--set", "bvh.list_prefix=ray"])
    assert r.returncode == 0, r.stderr
    lists = json.loads((out / "lists.json").read_text())["lists"]
    assert {"bsp nodes", "ray nodes", "ray tris", "ray tri ids"} <= set(lists)
    assert lists["bsp nodes"] != lists["ray nodes"]


@pytest.mark.parametrize("faces", ["f 1 1 2", "f 1 2 3"], ids=["repeated corner", "collinear"])
def test_a_model_whose_every_face_is_degenerate_exits_3(tmp_path, faces):
    obj = tmp_path / "flat.obj"
    obj.write_text(f"v 0 0 0\nv 1 0 0\nv 2 0 0\n{faces}\n")
    out = tmp_path / "o"
    r = bake_subprocess(["run", obj, "--out", out])
    assert "has no triangles left to bake" in one_error_line(r, 3, obj)
    assert not out.exists()
    # one good face beside it: baked, the degenerate one dropped
    obj.write_text(f"v 0 0 0\nv 1 0 0\nv 2 0 0\nv 0 1 0\n{faces}\nf 1 2 4\n")
    r = bake_subprocess(["run", obj, "--out", out, "--quiet"])
    assert r.returncode == 0, r.stderr
    assert len(json.loads((out / "lists.json").read_text())["lists"]["tris"]) == 4


def test_inspect_still_shows_a_model_whose_every_face_is_degenerate(tmp_path):
    obj = tmp_path / "flat.obj"
    obj.write_text("v 0 0 0\nv 1 0 0\nv 2 0 0\nf 1 2 3\n")
    r = bake_subprocess(["inspect", obj])
    assert r.returncode == 0, r.stderr
    assert "triangles 0, vertices 3" in r.stdout


@pytest.mark.parametrize("off", ["export.enabled=false", "export.json=false"])
def test_a_bake_without_lists_json_still_writes_its_report(tmp_path, off):
    model = grid_obj(tmp_path / "grid.obj", 2)
    out = tmp_path / "o"
    r = bake_subprocess(["run", model, "--out", out, "--quiet", "--set", off])
    assert r.returncode == 0, r.stderr
    assert (out / "report.html").is_file() and not (out / "lists.json").exists()
    page = (out / "report.html").read_bytes()
    r = bake_subprocess(["report", out])
    assert r.returncode == 0, r.stderr
    assert (b"export stage was off" if off.startswith("export.enabled") else b"lists.json was not written") in page


@pytest.mark.parametrize("extra, why", [
    (["--set", "lighting.enabled=true", "--set", 'lighting.lights=[{kind="sun"}]'], "'tri colors' goes per triangle"),
    (["--set", "bvh.enabled=true"], "the BVH's triangle numbers"),
    (["--set", "export.uvs=yes"], "'tri uvs' goes per triangle"),
    (["--set", "export.lightmap_uvs=yes"], "'lightmap uvs' goes per triangle"),
])
@pytest.mark.parametrize("faces", ["quads", "ngons"])
def test_whole_faces_fall_back_to_triangles_beside_per_triangle_lists(tmp_path, extra, why, faces):
    model = grid_obj(tmp_path / "grid.obj", 2)
    out = tmp_path / "o"
    r = bake_subprocess(["run", model, "--out", out, "--set", f"export.faces={faces}", *extra])
    assert r.returncode == 0, r.stderr
    assert f"export.faces = '{faces}' ignored: " in r.stdout + r.stderr and why in r.stdout + r.stderr
    lists = json.loads((out / "lists.json").read_text())["lists"]
    assert len(lists["tris"]) == 4 * 8  # every face of the 2 x 2 grid as two triangles
    assert "quads" not in lists and "ngons" not in lists
    if "tri colors" in why:  # one colour per written triangle
        assert len(lists["tri colors"]) == 8
    elif "uvs" in why:  # u1, v1, u2, v2, u3, v3 per written triangle
        assert len(lists[why.split("'")[1]]) == 6 * 8
    else:  # the BVH numbers the triangles of the list
        assert sorted(int(i) for i in lists["bvh tri ids"] if int(i) > 0) == list(range(1, 9))


def test_report_on_a_folder_without_its_lists_exits_3_and_keeps_the_page(baked):
    model, out = baked
    page = (out / "report.html").read_bytes()
    lists = out / "lists.json"
    doc = json.loads(lists.read_text())
    lists.unlink()
    r = bake_subprocess(["report", out])
    assert "lists.json is missing, though report.json says the bake wrote it" in one_error_line(r, 3, lists)
    assert (out / "report.html").read_bytes() == page
    doc["lists"] = {"verts": ["a"]}
    lists.write_text(json.dumps(doc))
    r = bake_subprocess(["report", out])
    assert "missing: 'mat colors', 'tris'" in one_error_line(r, 3, lists)
    assert (out / "report.html").read_bytes() == page
    # a lists.json that holds no "lists" object at all (an edited or foreign file)
    del doc["lists"]
    lists.write_text(json.dumps(doc))
    r = bake_subprocess(["report", out])
    assert "does not hold the lists report.json says the bake wrote" in one_error_line(r, 3, lists)
    assert (out / "report.html").read_bytes() == page


@pytest.mark.parametrize("value", ["", "..", " "])
def test_a_blank_list_name_is_refused(baked, value):
    model, out = baked
    before = _digests(out)
    r = bake_subprocess(["run", model, "--out", out, "--set", f"export.names.vertices={value}"])
    assert "must be a list name" in one_error_line(r, 2, "export.names.vertices")
    assert _digests(out) == before


def test_list_names_that_differ_only_in_case_are_refused(baked):
    model, out = baked
    r = bake_subprocess(["run", model, "--out", out, "--set", "export.names.vertices=Tris"])
    assert "differs from export.names.vertices = 'Tris' only in case" in one_error_line(r, 2, "export.names.triangles")


def test_check_strict_fails_on_a_project_problem(baked, tmp_path):
    import zipfile
    _, out = baked
    good = out / "grid.sb3"
    assert bake_subprocess(["check", good, "--strict"]).returncode == 0
    bad = tmp_path / "bad.sb3"
    with zipfile.ZipFile(good) as zin, zipfile.ZipFile(bad, "w") as zout:
        for info in zin.infolist():
            data = zin.read(info)
            if info.filename == "project.json":
                doc = json.loads(data)
                doc["targets"][0]["costumes"][0]["md5ext"] = "missing.svg"
                data = json.dumps(doc).encode()
            zout.writestr(info, data)
    r = bake_subprocess(["check", bad])
    assert r.returncode == 0 and "problem: " in r.stdout  # listed, not failed, without --strict
    r = bake_subprocess(["check", bad, "--strict"])
    assert "problem(s) under --strict" in one_error_line(r, 4, bad) and "missing.svg" in r.stderr
