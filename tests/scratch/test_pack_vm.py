"""Packed lists in the real Scratch VM: the loader blocks rebuild every packed list kind exactly.

Each bake below runs the real pipeline with ``export.pack = true``; its .sb3 is loaded in
scratch-vm 5.0.300, ``unpack lists`` runs, and every list must equal the plain list the same bake
wrote to lists.json, item for item (the same doubles). Together the bakes pack every list kind the
bake writes: vertices (delta), triangles (index + const), quads (index), per-triangle and
per-vertex colours and texture colour lists (palette), UVs and lightmap UVs, BSP nodes and planes,
and the three BVH lists. The blocks the VM counts must equal the cost model
(``bake.scratch.loader.decode_cost``) that ``bake check`` and report.json show. Bad texts make
``unpack error`` name the list and leave it empty: never a hang, never a wrong mesh."""

from __future__ import annotations

import json

import pytest

from bake.errors import InputError
from bake.scratch import pack as P
from bake.scratch import readers, sb3
from bake.scratch.loader import LoaderPart, LoaderSpec, total_cost
from bake.scratch.project import check_packed_lists
from conftest import corpus_path
from scratch_models import bake, project_lists
from vm_harness import vm  # noqa: F401

LIGHT = {"enabled": True, "target": "triangle", "ambient": [0.2, 0.2, 0.2],
         "lights": [{"kind": "sun", "direction": [0.3, -1, 0.5]}]}
BAKES = {
    # verts, tris, tri colors, BSP nodes and planes, BVH (quantised)
    "suzanne": (("suzanne_obj", "suzanne.obj"),
                {"lighting": LIGHT, "bsp": {"enabled": True}, "bvh": {"enabled": True}}),
    # quads, vertex colours: a generated grid of quads with a colour per vertex (no BVH: its
    # triangle numbers would send every face to the triangle list)
    "grid": (None, {"export": {"faces": "quads"}}),
    # texture colour list, tri uvs, BVH (wide4)
    "duck": (("duck_glb", "Duck.glb"),
             {"textures": {"enabled": True, "max_size": 16, "encodings": ["list"]},
              "bvh": {"enabled": True, "layout": "wide4"}}),
    # lightmap uvs and the lightmap's colour list, BVH (binary)
    "cornell": (("cornell_box_tinyobj", "cornell_box.obj"),
                {"lighting": {**LIGHT, "target": "lightmap"},
                 "textures": {"enabled": True, "lightmap": {"enabled": True, "resolution": 32}},
                 "bvh": {"enabled": True, "layout": "binary"}}),
}


def same_item(a, b) -> bool:
    """The same Scratch item: equal text, or the same double bit for bit."""
    if isinstance(b, str):
        return a == b
    return not isinstance(a, bool) and repr(float(a)) == repr(float(b))


def grid_obj(path, n: int = 30):
    """An n x n grid of quads on a bumpy surface, a colour per vertex (OBJ ``v x y z r g b``),
    eight colours in all."""
    lines = []
    for j in range(n + 1):
        for i in range(n + 1):
            r, g, b = (i // 8) % 2, (j // 8) % 2, ((i + j) // 8) % 2
            lines.append(f"v {i / n:.4f} {0.1 * ((i * 7 + j * 3) % 5) / 5:.4f} {j / n:.4f} {r} {g} {b}")
    for j in range(n):
        for i in range(n):
            a = j * (n + 1) + i + 1
            lines.append(f"f {a} {a + 1} {a + n + 2} {a + n + 1}")
    path.write_text("\n".join(lines) + "\n")
    return path


@pytest.fixture(scope="module")
def baked(tmp_path_factory, vm):
    tmp = tmp_path_factory.mktemp("pack")
    cases, jobs = {}, []
    for name, (path, sections) in BAKES.items():
        model = corpus_path(*path) if path else grid_obj(tmp / "grid.obj")
        sections = json.loads(json.dumps(sections))
        sections.setdefault("export", {}).update({"pack": True})
        sections.setdefault("textures", {}).setdefault("lightmap", {}).setdefault("cache_dir", str(tmp / "xatlas"))
        res = bake(model, **sections)
        files = res.scene.artefacts.outputs
        plain = json.loads(files["lists.json"])["lists"]
        stem = next(n for n in files if n.endswith(".sb3"))
        f = tmp / f"{name}.sb3"
        f.write_bytes(files[stem])
        export = next(r for r in res.records if r.name == "export")
        pk = export.details["pack"]
        stored = project_lists(files[stem])
        cases[name] = {"plain": plain, "pack": pk, "stored": stored, "file": f}
        jobs.append({"load": str(f), "runs": [
            {"call": {"target": "Mesh", "proccode": "unpack lists", "args": []},
             "read": {"target": "Stage", "lists": list(plain)}},
            {"read": {"target": "Mesh", "variables": ["unpack error", "unpacked"]}},
        ]})
    out = vm({"jobs": jobs}, timeout=900)["jobs"]
    for (name, case), res in zip(cases.items(), out):
        case["vm"] = res
    return cases


def test_every_list_kind_is_packed_somewhere(baked):
    kinds = {}
    for case in baked.values():
        for row in case["pack"]["lists"]:
            kinds[row["list"]] = {c["mode"] for c in row["columns"]}
    for name in ("verts", "tris", "quads", "tri colors", "vert colors", "tri uvs", "lightmap uvs", "bsp nodes",
                 "bsp planes", "bvh nodes", "bvh tris", "bvh tri ids"):
        assert name in kinds, f"{name} was not packed by any bake"
    assert any(n.startswith("tex ") for n in kinds)  # a texture colour list
    modes = set().union(*kinds.values())
    assert modes >= {"const", "offset", "delta", "index", "palette"}


@pytest.mark.parametrize("name", list(BAKES))
def test_loader_rebuilds_the_plain_lists_exactly(baked, name):
    case = baked[name]
    res = case["vm"]
    assert all(v["ok"] for v in res["validation"]), res["validation"]
    run, state = res["runs"]
    assert run["done"]
    assert state["variables"] == {"unpack error": "", "unpacked": 1} or \
        state["variables"] == {"unpack error": "", "unpacked": "1"}
    packed = {r["list"] for r in case["pack"]["lists"]}
    assert packed
    for lst, items in case["plain"].items():
        got = run["lists"][lst]
        if lst in packed:
            assert case["stored"][lst] == []  # the project stores it packed ...
        # ... and after the loader every list is the plain list, the same doubles item for item
        assert len(got) == len(items), lst
        assert all(same_item(a, b) for a, b in zip(got, items)), lst


@pytest.mark.parametrize("name", list(BAKES))
def test_decode_cost_model_counts_what_the_vm_runs(baked, name):
    case = baked[name]
    run = case["vm"]["runs"][0]
    assert run["blocks"] == case["pack"]["decode_blocks"]


def _with_texts(path, edit) -> bytes:
    """The .sb3 with each packed text replaced by edit(name, text)."""
    project, assets = sb3.load_project(path)
    for t in project["targets"]:
        for entry in (t.get("lists") or {}).values():
            if entry[0] == "packed lists":
                entry[1] = [edit(P.header_name(x), x) for x in entry[1]]
    entries = {"project.json": sb3.dumps(project).encode()}
    entries.update(assets)
    return sb3._zip(entries)


def test_bad_texts_are_named_errors_in_scratch(baked, vm, tmp_path):
    """Truncated, edited and emptied texts: ``unpack error`` names the list, that list stays
    empty, the others are rebuilt, and the loader finishes (no hang)."""
    case = baked["suzanne"]
    plain = case["plain"]
    edits = {
        "truncated": lambda n, x: x[: len(x) * 2 // 3] if n == "verts" else x,
        "edited": lambda n, x: (x[:-40] + ("#" if x[-40] != "#" else "$") + x[-39:]) if n == "tris" else x,
        "end cut": lambda n, x: x[:-1] if n == "bsp planes" else x,
        "garbage": lambda n, x: "sbpk1" + "~" * 500 if n == "tri colors" else x,
    }
    bad = {"truncated": "verts", "edited": "tris", "end cut": "bsp planes", "garbage": "tri colors"}
    jobs = []
    for key, edit in edits.items():
        f = tmp_path / f"{key.replace(' ', '_')}.sb3"
        f.write_bytes(_with_texts(case["file"], edit))
        jobs.append({"load": str(f), "runs": [
            {"call": {"target": "Mesh", "proccode": "unpack lists", "args": []},
             "read": {"target": "Stage", "lists": list(plain)}},
            {"read": {"target": "Mesh", "variables": ["unpack error"]}}]})
        with pytest.raises(InputError, match=f"packed list '{bad[key]}'"):  # the Python side names it too
            check_packed_lists(sb3.load_project(f)[0], f)
    out = vm({"jobs": jobs}, timeout=600)["jobs"]
    for (key, name), res in zip(bad.items(), out):
        run, state = res["runs"]
        assert run["done"], key
        err = state["variables"]["unpack error"]
        assert err.startswith(f"{name}: "), (key, err)
        assert run["lists"][name] == [], key  # never a half-decoded or wrong list
        others = [n for n in plain if n != name and n in {r["list"] for r in case["pack"]["lists"]}]
        for n in others:
            assert [float(v) for v in run["lists"][n]] == [float(v) for v in plain[n]], (key, n)


def test_more_than_vanilla_can_add_is_an_error_not_a_wrong_list(vm, tmp_path):
    """A packed list of 200,001 items: vanilla's `add to list` stops at 200,000, so the loader
    says so instead of rebuilding a short list."""
    pk = P.pack("big", [3] * 200_001)
    spec = readers.ReaderSpec(mesh=None, textimage=False, renderer=False, parts=[LoaderPart(LoaderSpec(["big"]))])
    lists = {"big": [], "packed lists": [pk.text]}
    data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists),
                             readers.reader_target(spec, "Mesh", stage_lists=list(lists))])
    f = tmp_path / "big.sb3"
    f.write_bytes(data)
    res = vm({"load": str(f), "runs": [
        {"call": {"target": "Mesh", "proccode": "unpack lists", "args": []}, "read": {"target": "Stage",
                                                                                     "lists": ["big"]}},
        {"read": {"target": "Mesh", "variables": ["unpack error"]}}]}, timeout=600)
    run, state = res["runs"]
    assert run["done"] and run["lists"]["big"] == []
    assert "200,000" in state["variables"]["unpack error"] and state["variables"]["unpack error"].startswith("big: ")


def test_sprite3_unpacks_its_own_lists(baked, vm, tmp_path):
    """The .sprite3 (lists local to the sprite, for Upload Sprite) carries the loader too."""
    model = corpus_path("cornell_box_tinyobj", "cornell_box.obj")
    res = bake(model, bsp={"enabled": True}, export={"pack": True})
    files = res.scene.artefacts.outputs
    plain = json.loads(files["lists.json"])["lists"]
    sprite = next(n for n in files if n.endswith(".sprite3"))
    f = tmp_path / "c.sprite3"
    f.write_bytes(files[sprite])
    host = tmp_path / "host.sb3"
    host.write_bytes(sb3.write_sb3([sb3.Target("Stage", is_stage=True)])[0])
    out = vm({"load": str(host), "sprites": [str(f)], "runs": [
        {"call": {"target": "Mesh", "proccode": "unpack lists", "args": []},
         "read": {"target": "Mesh", "lists": list(plain), "variables": ["unpack error"]}}]})
    run = out["runs"][0]
    assert run["variables"]["unpack error"] == ""
    for n, items in plain.items():
        assert [float(v) for v in run["lists"][n]] == [float(v) for v in items], n


def test_green_flag_draws_the_same_picture_packed_and_plain(vm, tmp_path):
    """The reader's green flag (unpack, then render) draws exactly the pen strokes of the plain
    project's green flag."""
    model = corpus_path("cornell_box_tinyobj", "cornell_box.obj")
    strokes = []
    for pack in (False, True):
        res = bake(model, bsp={"enabled": True}, export={"pack": pack})
        files = res.scene.artefacts.outputs
        f = tmp_path / f"g{int(pack)}.sb3"
        f.write_bytes(files[next(n for n in files if n.endswith(".sb3"))])
        out = vm({"load": str(f), "runs": [{"greenFlag": True, "pen": True}]})
        strokes.append(out["runs"][0]["pen"])
    assert strokes[0] and strokes[0] == strokes[1]


def test_total_cost_adds_up(baked):
    # the report's total is the sum of the lists plus the fixed part
    for case in baked.values():
        pk = case["pack"]
        assert pk["decode_blocks"] == sum(r["decode_blocks"] for r in pk["lists"]) + 10
    assert total_cost([]) == 10
