"""Layouts for authors' engines (bake/scratch/layout.py, docs/engines.md): every layout
rebuilds the book's lists item for item, a config the layout cannot take is refused with the key,
and the reader's ``load triangle`` reads every layout in the real Scratch VM exactly as the book's
lists say. (Drawing from split and soup lists in TurboWarp: tests/player/test_turbowarp.py.)"""

from __future__ import annotations

import json

import numpy as np
import pytest

from bake import config, pipeline
from bake.errors import ConfigError
from bake.scratch import sb3
from bake.scratch.layout import join
from conftest import CORPUS
from vm_harness import call, vm  # noqa: F401

XYZ = ["X", "Y", "Z"]
CORNERS = ["tri a", "tri b", "tri c", "tri mat"]
NINE = [f"{a}{k}" for k in "123" for a in "xyz"]
LAYOUTS = {
    "per-coordinate, 0-based": {"names": {"vertices": XYZ, "triangles": CORNERS}, "index_base": 0},
    "corner lists, interleaved verts": {"names": {"triangles": CORNERS}},
    "x y z lists, book tris, 0-based": {"names": {"vertices": XYZ}, "index_base": 0},
    "soup": {"faces": "soup"},
    "soup x y z, 0-based": {"faces": "soup", "names": {"vertices": XYZ}, "index_base": 0},
    "soup 9 lists": {"faces": "soup", "names": {"vertices": NINE}},
}
MODELS = {  # model -> extra sections (each has something the layouts rearrange)
    "suzanne_obj/suzanne.obj": {"lighting": {"enabled": True}, "export": {"vertex_colors": "yes"}},
    "box_textured_glb/BoxTextured.glb": {"textures": {"enabled": True}},
    "cube_quads_mtl/cube.obj": {"export": {"faces": "quads"}},
}


def _model(rel: str):
    p = CORPUS / rel
    if not p.exists():
        pytest.skip(f"corpus model {rel} missing")
    return p


def _bake(model, sections: dict, export: dict):
    data = {**sections, "input": {"path": str(model)},
            "export": {**sections.get("export", {}), **export, "sb3": False}}
    res = pipeline.run(config.load(data=data))
    return res, json.loads(res.scene.artefacts.outputs["lists.json"])


@pytest.fixture(scope="module")
def bakes():
    out = {}
    for rel, sections in MODELS.items():
        if not (CORPUS / rel).exists():
            continue
        model = CORPUS / rel
        out[rel] = {"book": _bake(model, sections, {})}
        for key, export in LAYOUTS.items():
            if sections.get("export", {}).get("faces") == "quads" and export.get("faces") == "soup":
                continue
            out[rel][key] = _bake(model, sections, export)
        if "textures" in sections:  # the UVs by corner (u, v) and by triangle (6 lists)
            out[rel]["uv corners"] = _bake(model, sections, {"names": {"uvs": ["U", "V"]}})
            out[rel]["uv six"] = _bake(model, sections, {"names": {"uvs": [f"{a}{k}" for k in "123" for a in "uv"]}})
        if sections.get("export", {}).get("faces") == "quads":
            out[rel]["quad lists 0-based"] = _bake(model, sections, {"names": {"quads": ["qa", "qb", "qc", "qd", "qm"]},
                                                                     "index_base": 0})
    if not out:
        pytest.skip("no corpus models")
    return out


def _export(res) -> dict:
    e = res.config.export
    return {"names": e.names, "faces": e.faces, "index_base": e.index_base}


def test_every_layout_rebuilds_the_books_lists_item_for_item(bakes):
    checked = 0
    for rel, by in bakes.items():
        _, book_json = by["book"]
        book = join(book_json["lists"])
        assert {"vertices", "triangles"} <= set(book)
        for key, (res, lj) in by.items():
            if key == "book" or res.config.export.faces == "soup":
                continue
            back = join(lj["lists"], **_export(res))
            for role, items in book.items():
                assert back[role] == items, f"{rel} {key}: {role}"
                checked += 1
            # the lists the layout does not touch are the same lists
            numbered = {"tris", "quads"} if res.config.export.index_base != 1 else set()
            same = (set(lj["lists"]) & set(book_json["lists"])) - numbered
            for name in same:
                assert lj["lists"][name] == book_json["lists"][name], f"{rel} {key}: {name}"
    assert checked >= 20


def test_a_soup_holds_each_triangles_corners_in_order(bakes):
    for rel, by in bakes.items():
        _, book_json = by["book"]
        book = join(book_json["lists"])
        v = np.asarray(book["vertices"], dtype=object).reshape(-1, 3)
        t = np.asarray(book["triangles"], np.int64).reshape(-1, 4)
        corners = v[t[:, :3] - 1].ravel().tolist()
        for key, (res, lj) in by.items():
            if res.config.export.faces != "soup":
                continue
            back = join(lj["lists"], **_export(res))
            assert back["vertices"] == corners, f"{rel} {key}"  # the same numbers, as written
            bt = np.asarray(back["triangles"], np.int64).reshape(-1, 4)
            assert bt[:, 3].tolist() == t[:, 3].tolist(), f"{rel} {key}: materials"
            assert bt[:, :3].ravel().tolist() == list(range(1, 3 * len(t) + 1))
            for name in ("tri colors", "mat colors"):
                if name in book_json["lists"]:
                    assert lj["lists"][name] == book_json["lists"][name]
            if "vert colors" in book_json["lists"]:  # per corner in a soup
                vc = np.asarray(book_json["lists"]["vert colors"], dtype=object)
                assert lj["lists"]["vert colors"] == vc[t[:, :3] - 1].ravel().tolist()


def test_split_lists_are_named_and_described_in_lists_json(bakes):
    res, lj = bakes["suzanne_obj/suzanne.obj"]["per-coordinate, 0-based"]
    assert [n for n in lj["lists"] if n in XYZ + CORNERS] == XYZ + CORNERS
    info = lj["info"]
    assert info["X"] == {"stride": 1, "doc": "x per vertex"}
    assert info["tri a"]["doc"] == "v1 (0-based) per triangle" and info["tri mat"]["doc"] == "material (0-based) per triangle"
    assert min(lj["lists"]["tri a"]) == 0 and "verts" not in lj["lists"] and "tris" not in lj["lists"]
    n = len(lj["lists"]["X"])
    assert len(lj["lists"]["Y"]) == len(lj["lists"]["Z"]) == n and max(lj["lists"]["tri b"]) == n - 1


@pytest.mark.parametrize("export, key, words", [
    ({"names": {"vertices": ["X", "Y"]}}, "export.names.vertices", "3 names (x y z per vertex); got 2"),
    ({"faces": "soup", "names": {"triangles": CORNERS}}, "export.names.triangles", "cannot be split"),
    ({"faces": "soup", "names": {"vertices": ["a", "b"]}}, "export.names.vertices", "9 names (x1 y1 z1"),
    ({"names": {"uvs": ["a", "b", "c"]}}, "export.names.uvs", "2 names (u v per corner)"),
    ({"names": {"vertices": ["X", "Y", "X"]}}, "export.names.vertices[2]", "is also export.names.vertices[0]"),
    ({"names": {"vertices": ["X", "Y", "Z"], "materials": "Y"}}, "export.names.materials", "two lists cannot share"),
    ({"names": {"ngons": ["a", "b"]}}, "export.names.ngons", "expected a string"),
    ({"index_base": 2}, "export.index_base", "must be 1"),
    ({"index_base": True}, "export.index_base", "expected an integer"),
])
def test_a_layout_the_lists_cannot_take_is_refused_with_its_key(export, key, words):
    with pytest.raises(ConfigError) as e:
        config.load(data={"export": export})
    assert e.value.key == key and words in str(e.value), str(e.value)


def test_load_triangle_reads_every_layout_in_the_scratch_vm(vm, tmp_path):
    """The .sprite3's ``load triangle (t)`` (the block authors copy) gives each layout's corners and
    colour exactly as the book's lists hold them, in scratch-vm."""
    model = _model("suzanne_obj/suzanne.obj")
    sections = {"lighting": {"enabled": True}}
    book = None
    jobs, expect = [], []
    for key, export in {"book": {}, **LAYOUTS}.items():
        data = {**sections, "input": {"path": str(model)}, "export": {**export, "sb3": False}}
        res = pipeline.run(config.load(data=data))
        files = res.scene.artefacts.outputs
        name = next(n for n in files if n.endswith(".sprite3"))
        path = tmp_path / f"{len(jobs)}.sprite3"
        path.write_bytes(files[name])
        lists = json.loads(files["lists.json"])["lists"]
        if book is None:
            book = join(lists)
            v = np.asarray(book["vertices"], np.float64).reshape(-1, 3)
            t = np.asarray(book["triangles"], np.int64).reshape(-1, 4)
            colours = lists["tri colors"]
            ts = [1, len(t), 1 + 7 * len(t) // 13]
        jobs.append({"load": str(path), "runs": [call("Mesh", "load triangle %s", k, variables=[
            "x1", "y1", "z1", "x2", "y2", "z2", "x3", "y3", "z3", "tri color"]) for k in ts]})
        expect.append(key)
    out = vm({"jobs": jobs}, timeout=600)["jobs"]
    for key, job in zip(expect, out):
        assert all(x["ok"] for x in job["validation"]), key
        for k, run in zip(ts, job["runs"]):
            got = run["variables"]
            want = v[t[k - 1, :3] - 1]
            for c in range(3):
                for a, axis in enumerate("xyz"):
                    assert float(got[f"{axis}{c + 1}"]) == want[c, a], f"{key}: triangle {k} corner {c + 1} {axis}"
            assert int(float(got["tri color"])) == colours[k - 1], key
