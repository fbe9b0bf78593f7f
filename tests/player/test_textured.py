"""The reader's textured filler in TurboWarp (issue 40): textured and lightmapped bakes drawn cell
by cell, compiled and interpreted, against report.html's textured green-flag picture
(``bake.outputs.cells``, the filler's arithmetic in Python).

Agreement (``cells.agreement``): of the pixels the filler paints, at least ``WITHIN_8`` within 8
levels and ``WITHIN_1`` within 1 level, and nothing painted beyond a pixel from them. Measured:
within 8 levels 0.9999-1.0 of the painted pixels on every model (the largest difference 11: the
pen tints a pixel drawn earlier by about 1% of its later neighbour's difference), within 1 level
0.95 (the box: its texture's sharp edges) to 1.0 (the lightmapped room). A texture flipped in u
or v, or a lightmap shifted by one texel row, must fail."""

from __future__ import annotations

import json
import sys
import zipfile
from pathlib import Path

import numpy as np
import pytest

from bake import cli
from bake.outputs import cells
from bake.scratch import backdrop, sb3
from conftest import CORPUS

sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "vm"))
import turbowarp  # noqa: E402

WITHIN_8 = 0.999
WITHIN_1 = 0.9

BAKES = {  # name -> (corpus model, --set overrides)
    "box": ("box_textured_glb/BoxTextured.glb", []),
    "duck": ("duck_glb/Duck.glb", []),
    "duck packed": ("duck_glb/Duck.glb", ["export.pack=true"]),  # the loader rebuilds the texture list first
    "box textimage": ("box_textured_glb/BoxTextured.glb", ['textures.encodings=["textimage"]']),
    # texture and light baked together in the lightmap
    "duck lightmap": ("duck_glb/Duck.glb", ["lighting.enabled=true", 'lighting.target="lightmap"',
                                            'lighting.lights=[{kind="sun", direction=[0.5, -1, -0.4]}]',
                                            "textures.lightmap.enabled=true", "textures.lightmap.resolution=128"]),
    # an engine's layout (issue 39): a soup with one list per coordinate, 0-based materials
    "box soup": ("box_textured_glb/BoxTextured.glb", ['export.faces="soup"', 'export.names.vertices=["X", "Y", "Z"]',
                                                      "export.index_base=0"]),
    "room lightmap": ("cornell_box_multimaterial", ["lighting.enabled=true", 'lighting.target="lightmap"',
                                                     "textures.enabled=true", "textures.lightmap.enabled=true",
                                                     "textures.lightmap.resolution=64", "lighting.ao.enabled=true",
                                                     "lighting.ao.samples=8", "lighting.ambient=[0.2, 0.2, 0.25]",
                                                     'lighting.lights=[{kind="sun", direction=[0.5, -1, -0.4]}]']),
}


def _model(rel: str) -> Path | None:
    p = CORPUS / rel
    if p.is_dir():
        found = sorted(p.rglob("*.obj")) + sorted(p.rglob("*.gl*"))
        return found[0] if found else None
    return p if p.exists() else None


def _edited(src: Path, dst: Path, edit) -> Path:
    """A copy of the .sb3 with ``edit(lists)`` applied to the stage's lists."""
    z = zipfile.ZipFile(src)
    project = json.loads(z.read("project.json"))
    stage = next(t for t in project["targets"] if t["isStage"])
    lists = {v[0]: v for v in stage["lists"].values()}
    edit(lists)
    with zipfile.ZipFile(dst, "w") as out:
        for name in z.namelist():
            out.writestr(name, sb3.dumps(project) if name == "project.json" else z.read(name))
    return dst


def _flip(lists, name, W, H, axis):
    grid = np.asarray(lists[name][1], dtype=object).reshape(H, W)
    lists[name][1] = (grid[:, ::-1] if axis == "u" else grid[::-1]).ravel().tolist()


def _shift_row(lists, name, W, H):
    grid = np.asarray(lists[name][1], dtype=object).reshape(H, W)
    lists[name][1] = np.roll(grid, 1, axis=0).ravel().tolist()


@pytest.fixture(scope="module")
def played(tmp_path_factory):
    why = turbowarp.unavailable()
    if why:
        pytest.skip(why)
    tmp = tmp_path_factory.mktemp("textured")
    projects, pictures, controls = [], {}, []
    for name, (rel, sets) in BAKES.items():
        model = _model(rel)
        if model is None:
            continue
        out = tmp / name.replace(" ", "_")
        args = ["run", str(model), "--out", str(out), "--quiet"]
        for s in sets:
            args += ["--set", s]
        assert cli.main(args) == 0
        report = json.loads((out / "report.json").read_text())
        lists = json.loads((out / "lists.json").read_text())["lists"]
        found = cells.green_flag(lists, report)
        assert found is not None, f"{name}: no textured filler"
        sb3_path = next(out.glob("*.sb3"))
        project, assets = sb3.load_project(sb3_path)
        pictures[name] = (found[0], backdrop.from_project(project, assets), report)
        projects.append((name, sb3_path))
        tex = next(st for st in report["stages"] if st["name"] == "export")["details"]["reader_texture"]
        src = tex["sources"][0]
        if src["kind"] == "list" and name in ("duck", "room lightmap"):
            W, H = src["width"], src["height"]
            edits = ([("u", lambda ls: _flip(ls, src["list"], W, H, "u")),
                      ("v", lambda ls: _flip(ls, src["list"], W, H, "v"))] if name == "duck" else
                     [("row", lambda ls: _shift_row(ls, src["list"], W, H))])
            for tag, edit in edits:
                cid = f"{name} {tag}"
                controls.append(cid)
                projects.append((cid, _edited(sb3_path, tmp / f"{cid.replace(' ', '_')}.sb3", edit)))
                pictures[cid] = pictures[name]
    if not projects:
        pytest.skip("no textured model in the corpus")
    run = turbowarp.run(projects, modes=("compiled", "interpreted"), repeat=1)
    return {"run": run, "pictures": pictures, "controls": controls}


def test_every_textured_bake_runs_and_agrees_with_its_textured_green_flag(played):
    run = played["run"]
    seen = set()
    for r in run.results:
        if r.id in played["controls"]:
            continue
        pic, bg, _ = played["pictures"][r.id]
        assert r.problems() == [], f"{r.id} {r.mode}: {r.problems()}"
        a = cells.agreement(r.image, pic, bg)
        assert a["painted_pixels"] > 5000, a
        assert a["within_8"] >= WITHIN_8 and a["within_1"] >= WITHIN_1 and a["empty_painted"] == 0, \
            f"{r.id} {r.mode}: {a}"
        seen.add(r.id)
    # every bake built (each model the corpus has), compiled and interpreted
    built = {pid for pid in played["pictures"] if pid not in played["controls"]}
    assert seen == built and len(seen) >= 2


def test_compiled_and_interpreted_draw_the_same_textured_picture(played):
    run = played["run"]
    for pid in played["pictures"]:
        a, b = run.get(pid, "compiled").image, run.get(pid, "interpreted").image
        assert np.array_equal(a, b), f"{pid}: {(a != b).any(2).sum()} pixels differ"


def test_a_flipped_texture_or_a_shifted_lightmap_fails_the_agreement(played):
    assert played["controls"], "no control was built"
    for cid in played["controls"]:
        pic, bg, _ = played["pictures"][cid]
        r = played["run"].get(cid, "compiled")
        a = cells.agreement(r.image, pic, bg)
        assert a["within_8"] < WITHIN_8, f"{cid}: {a}"
