"""Issue 39, item 4: a model baked into authors' own engines, in their own list layouts, and
played in TurboWarp.

Three engines (tests/player/engines.py), each a sprite whose green flag draws the model with the
pen from its own stage lists: per-coordinate lists with 0-based corners, an unindexed triangle
soup, and the book's interleaved ``verts``/``tris``. For each, the engine's .sb3 is written, the
model is baked into it (``export.into``, ``into_target = "Stage"``, the layout's ``export``
settings), the bake's engine check must find nothing to say, and the merged project runs in
TurboWarp (compiled and interpreted, one run for all). Its stage must agree with the green-flag
preview of a default-layout bake of the same model (``bake.outputs.preview.stage_agreement``) at
the thresholds of test_turbowarp.py. The engines draw in list order with back-face culling, which
is a correct picture for the unlit corpus Suzanne (one colour) and for a convex model: a lit
icosphere, a colour per triangle, baked into the two engines that read a colour per triangle
(the book's layout colours by material; the bake would add an unread ``tri colors`` beside it).

Controls: a mirrored stage and the per-coordinate engine baked with 1-based corners fail the
agreement; a default-layout bake into the per-coordinate engine makes the engine check speak.
The engines that need the export layouts (``export.names`` lists, ``index_base``, ``faces =
"soup"``) are skipped where ``bake.config.ExportConfig`` has no ``index_base``.
"""

from __future__ import annotations

import dataclasses
import sys
import time
from pathlib import Path

import numpy as np
import pytest

from bake import config, pipeline
from bake.outputs import preview
from bake.scratch import sb3
from bake.scratch.project import auto_camera
from conftest import CORPUS

sys.path.insert(0, str(Path(__file__).resolve().parent))
sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "vm"))
import engines  # noqa: E402
import turbowarp  # noqa: E402

COVERED_WITHIN_1 = 0.85  # as test_turbowarp.py
WHITE = (255, 255, 255)
LIT = {"enabled": True, "target": "triangle", "ambient": [0.2, 0.2, 0.25],
       "lights": [{"kind": "sun", "direction": [0.5, -1, -0.4]}]}

#: the models (corpus path, config sections besides export) and the engines each is baked into:
#: Suzanne unlit (one colour), and a lit icosphere (198 colours, one per triangle: convex, so list
#: order with back-face culling is right) for the engines that read a colour per triangle
MODELS = {
    "suzanne": ("suzanne_obj/suzanne.obj", {}, ("per-coordinate", "soup", "interleaved")),
    "lit ico": ("ico4_mtl/ico4.obj", {"lighting": LIT}, ("per-coordinate", "soup")),
}
CASES = [(e, m) for m, (_, _, es) in MODELS.items() for e in es]
IDS = [f"{e}-{m.replace(' ', '-')}" for e, m in CASES]

#: each engine's export settings (besides export.into and export.into_target)
LAYOUTS = {
    "per-coordinate": {"names": {"vertices": ["X", "Y", "Z"], "triangles": ["tri a", "tri b", "tri c", "tri mat"],
                                 "triangle_colors": "tri col"},
                       "index_base": 0, "triangle_colors": "yes"},
    "soup": {"faces": "soup", "names": {"vertices": "tri xyz", "triangles": "tri mat", "triangle_colors": "tri col"},
             "triangle_colors": "yes"},
    "interleaved": {},
}
NEEDS_LAYOUTS = {"per-coordinate", "soup"}  # export.names lists, index_base, faces = "soup"


def layouts_available() -> bool:
    return any(f.name == "index_base" for f in dataclasses.fields(config.ExportConfig))


def _skip_without_layouts(engine: str) -> None:
    if engine in NEEDS_LAYOUTS and not layouts_available():
        pytest.skip("export layouts not on this branch")


def _bake(model: Path, sections: dict, export: dict):
    res = pipeline.run(config.load(data={"input": {"path": str(model)}, **sections, "export": export}))
    return res, res.scene.artefacts.outputs


def _stage_lists(data: bytes) -> dict[str, list]:
    project, _ = sb3.load_project(data)
    stage = next(t for t in project["targets"] if t["isStage"])
    return {n: items for n, items in stage["lists"].values()}


def _reference(model: Path, sections: dict) -> dict:
    """A default-layout bake with a colour per triangle: its lists, its green-flag camera, the
    preview of that camera on the engines' white stage."""
    _, files = _bake(model, sections, {"triangle_colors": "yes"})
    ref = _stage_lists(files[f"{model.stem}.sb3"])
    cam = auto_camera(ref["verts"])
    report = {"config": {"export": {"names": {}}}, "materials": [{"double_sided": False} for _ in ref["mat colors"]]}
    mesh = preview.mesh_from_lists(ref, report)
    mesh.backdrop = WHITE
    view, painter = preview.stage_view(mesh, cam)
    return {"lists": ref, "cam": cam, "view": view, "painter": painter}


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    why = turbowarp.unavailable()
    if why:
        pytest.skip(why)
    tmp = tmp_path_factory.mktemp("engines")
    refs, built, projects = {}, {}, []
    for (engine, model), pid in zip(CASES, IDS):
        path, sections, _ = MODELS[model]
        if engine in NEEDS_LAYOUTS and not layouts_available() or not (CORPUS / path).exists():
            continue
        if model not in refs:
            refs[model] = _reference(CORPUS / path, sections)
        folder = tmp / pid
        folder.mkdir()
        src = folder / f"{engine}.sb3"  # the author's engine, its camera set for this model
        src.write_bytes(engines.ENGINES[engine](refs[model]["cam"]))
        res, files = _bake(CORPUS / path, sections, {**LAYOUTS[engine], "into": str(src), "into_target": "Stage"})
        out = f"{engine}-{Path(path).stem}.sb3"
        (folder / out).write_bytes(files[out])
        export = next(r for r in res.records if r.name == "export")
        built[pid] = {"engine": engine, "model": model, "source": src, "merged": folder / out, "record": export,
                      "lists": _stage_lists(files[out])}
        projects.append((pid, folder / out))
    if not projects:
        pytest.skip("no model of the corpus")
    wrong = None
    if "per-coordinate-suzanne" in built:  # a control: the 0-based engine given 1-based corners
        b = built["per-coordinate-suzanne"]
        export = {**LAYOUTS["per-coordinate"], "index_base": 1, "into": str(b["source"]), "into_target": "Stage",
                  "into_name": "one-based.sb3"}
        _, files = _bake(CORPUS / MODELS["suzanne"][0], MODELS["suzanne"][1], export)
        wrong = tmp / "one-based.sb3"
        wrong.write_bytes(files["one-based.sb3"])
        projects.append(("one-based", wrong))
    t0 = time.monotonic()
    run = turbowarp.run(projects, modes=("compiled", "interpreted"))
    seconds = time.monotonic() - t0
    print(f"\nTurboWarp: {len(projects)} projects x 2 modes in {seconds:.1f} s; green flag to done: "
          + ", ".join(f"{r.id} {r.mode} {r.seconds[0]:.2f} s" for r in run.results if r.seconds))
    return {"refs": refs, "built": built, "run": run, "seconds": seconds, "one-based": wrong}


def _built(played, engine: str, model: str) -> dict:
    _skip_without_layouts(engine)
    pid = IDS[CASES.index((engine, model))]
    if pid not in played["built"]:
        pytest.skip(f"corpus file missing: {MODELS[model][0]}")
    return played["built"][pid]


@pytest.mark.parametrize("engine, model", CASES, ids=IDS)
def test_the_bake_fills_the_engines_lists_and_the_engine_check_is_silent(played, engine, model):
    """Every list the bake writes is one the engine reads (no list added beside them), the engine
    check says nothing, and the engine's scripts are the author's, untouched."""
    b = _built(played, engine, model)
    rec = b["record"]
    found = rec.details["into"]["engine"]
    assert found["warnings"] == [], found["warnings"]
    assert rec.warnings == [] and rec.problems == [], (rec.warnings, rec.problems)
    before = _stage_lists(b["source"].read_bytes())
    assert set(b["lists"]) == set(before), sorted(set(b["lists"]) ^ set(before))
    for n, entry in found["lists"].items():
        assert entry["replaced"] and [r["sprite"] for r in entry["read_by"]] == [engines.SPRITE], (n, entry)
        assert entry["emptied_by"] == [] and entry["written_by"] == []
    src, _ = sb3.load_project(b["source"])
    merged, _ = sb3.load_project(b["merged"])
    sprite = {t["name"]: t for t in merged["targets"]}[engines.SPRITE]
    assert sprite == {t["name"]: t for t in src["targets"]}[engines.SPRITE]


@pytest.mark.parametrize("engine, model", CASES, ids=IDS)
def test_the_engines_lists_hold_the_default_bakes_model(played, engine, model):
    """The layout is the default bake's model rearranged: the same vertices, triangles (in the
    same order) and colours."""
    b = _built(played, engine, model)
    lists, ref = b["lists"], played["refs"][model]["lists"]
    verts = np.asarray(ref["verts"], np.float64).reshape(-1, 3)
    tris = np.asarray(ref["tris"], np.int64).reshape(-1, 4)
    if engine == "interleaved":
        assert lists["verts"] == ref["verts"] and lists["tris"] == ref["tris"]
        assert lists["mat colors"] == ref["mat colors"]
        return
    if engine == "per-coordinate":
        got = np.column_stack([np.asarray(lists[k], np.float64) for k in ("X", "Y", "Z")])
        assert np.array_equal(got, verts)
        for k, col in (("tri a", 0), ("tri b", 1), ("tri c", 2), ("tri mat", 3)):
            assert [int(x) for x in lists[k]] == (tris[:, col] - 1).tolist(), k
    else:  # soup: the corners' coordinates, triangle by triangle; 1-based materials
        got = np.asarray(lists["tri xyz"], np.float64).reshape(-1, 9)
        assert np.array_equal(got, verts[tris[:, :3] - 1].reshape(-1, 9))
        assert [int(x) for x in lists["tri mat"]] == tris[:, 3].tolist()
    assert [int(c) for c in lists["tri col"]] == [int(c) for c in ref["tri colors"]]
    assert lists["mat colors"] == ref["mat colors"]


@pytest.mark.parametrize("engine, model", CASES, ids=IDS)
def test_the_engine_runs_and_its_stage_agrees_with_the_green_flag_preview(played, engine, model):
    _built(played, engine, model)
    ref = played["refs"][model]
    pid = IDS[CASES.index((engine, model))]
    images = []
    for mode in ("compiled", "interpreted"):
        r = played["run"].get(pid, mode)
        assert r.problems() == [], f"{pid} {mode}: {r.problems()}"
        a = preview.stage_agreement(r.image, ref["view"], ref["painter"], background=WHITE)
        assert a["interior_pixels"] > 100 and a["covered_inner_pixels"] > 5000, a
        assert a["within_1"] == 1.0, f"{pid} {mode}: {a}"
        assert a["covered_within_1"] >= COVERED_WITHIN_1, f"{pid} {mode}: {a}"
        assert a["interior_left_blank"] == 0 and a["empty_painted"] == 0, f"{pid} {mode}: {a}"
        images.append(r.image)
    differ = int((images[0] != images[1]).any(2).sum())
    assert differ == 0, f"{pid}: compiled and interpreted differ at {differ} pixels"


def test_a_mirrored_stage_fails_the_agreement(played):
    """The check can fail: each model's stage mirrored left to right disagrees with its preview."""
    seen = set()
    for pid, b in played["built"].items():
        if b["model"] in seen:
            continue
        seen.add(b["model"])
        ref = played["refs"][b["model"]]
        bad = np.ascontiguousarray(played["run"].get(pid, "compiled").image[:, ::-1])
        a = preview.stage_agreement(bad, ref["view"], ref["painter"], background=WHITE)
        assert a["covered_within_1"] < COVERED_WITHIN_1 or a["within_1"] < 1.0 or a["empty_painted"] > 0, (pid, a)


def test_the_wrong_index_base_fails_the_agreement(played):
    """The stage tells the layouts apart: the per-coordinate engine (0-based corners) baked with
    export.index_base = 1 runs without an error but draws another picture."""
    if played["one-based"] is None:
        pytest.skip("the per-coordinate engine was not baked")
    ref = played["refs"]["suzanne"]
    for mode in ("compiled", "interpreted"):
        r = played["run"].get("one-based", mode)
        assert r.errors == [] and r.done, (mode, r.errors)
        a = preview.stage_agreement(r.image, ref["view"], ref["painter"], background=WHITE)
        assert a["covered_within_1"] < COVERED_WITHIN_1 or a["within_1"] < 1.0 or a["empty_painted"] > 0, (mode, a)


def test_the_engine_check_speaks_when_the_layout_is_not_the_engines(played):
    """A default-layout bake into the per-coordinate engine: the check names the lists no block
    reads (the silence above means something)."""
    _skip_without_layouts("per-coordinate")
    b = played["built"].get("per-coordinate-suzanne")
    if b is None:
        pytest.skip("the per-coordinate engine was not baked")
    res, _ = _bake(CORPUS / MODELS["suzanne"][0], {}, {"into": str(b["source"]), "into_target": "Stage"})
    found = next(r for r in res.records if r.name == "export").details["into"]["engine"]
    assert found["unread"] == ["tris", "verts"], found
    assert len(found["warnings"]) == 1 and "'tris', 'verts'" in found["warnings"][0], found["warnings"]
