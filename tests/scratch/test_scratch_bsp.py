"""The reader's ``bsp walk`` in the real Scratch VM gives exactly the draw order of the Python
reference traversal (``bake.bsp.traverse.draw_order``, which reads the exported lists as the
Scratch script does), for several eyes: outside the model, inside it, far away. Models: a Cornell
box, a glTF with two-sided materials (so culling must spare them), Suzanne, and a generated soup
of intersecting triangles (the tree must split them). The pen renderer, drawing in the walk's
order from two cameras, shows the painter's picture of that order."""

from __future__ import annotations

import numpy as np
import pytest

from bake.bsp.traverse import draw_order
from bake.scratch import sb3
from bake.scratch import readers
from bake.scratch.project import reader_spec
from bake.scratch.colors import decode_numbers
from conftest import corpus_path
from scratch_models import bake, cameras, check_render, project_lists, soup_obj
from vm_harness import call, vm  # noqa: F401

MODELS = ["cornell", "alphablend", "suzanne", "soup"]
EYES = ([0, 0, -1.5], [1.1, 0.6, 0.3], [0.05, 0.02, 0.01], [-0.7, -1.2, 0.9], [0.3, 2.5, -0.2], [0, 0, 40])


def _path(name, tmp):
    if name == "cornell":
        return corpus_path("cornell_box_tinyobj", "cornell_box.obj")
    if name == "alphablend":
        return corpus_path("alpha_blend_mode_test", "AlphaBlendModeTest.glb")
    if name == "suzanne":
        return corpus_path("suzanne_obj", "suzanne.obj")
    return soup_obj(tmp / "soup.obj", n=40, seed=5)


def _eyes(verts):
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    c, diag = (v.min(0) + v.max(0)) / 2, float(np.linalg.norm(v.max(0) - v.min(0)))
    return [[float(x) for x in c + np.array(e) * diag] for e in EYES]


@pytest.fixture(scope="module")
def walks(tmp_path_factory, vm):
    tmp = tmp_path_factory.mktemp("bsp")
    cases, jobs = [], []
    for name in MODELS:
        res = bake(_path(name, tmp), bsp={"enabled": True})
        files = res.scene.artefacts["outputs"]
        stem = next(n for n in files if n.endswith(".sb3"))
        p = tmp / f"{name}.sb3"
        p.write_bytes(files[stem])
        lists = project_lists(files[stem])
        spec = reader_spec(res.scene, res.config.export, lists)
        assert spec.bsp is not None
        eyes = _eyes(lists["verts"])
        jobs.append({"load": str(p), "runs": [call("Mesh", "bsp walk %s %s %s", *e, lists=["draw order"])
                                              for e in eyes]})
        cases.append({"name": name, "lists": lists, "spec": spec, "eyes": eyes, "result": res})
    # the renderer in BSP order: Suzanne, a random colour per triangle
    suz = cases[MODELS.index("suzanne")]
    lists = dict(suz["lists"])
    n = len(lists["tris"]) // 4
    lists["tri colors"] = [int(c) for c in np.random.default_rng(3).choice(np.arange(1 << 24), n, replace=False)]
    spec = readers.ReaderSpec(mesh=readers.MeshNames(tri_colors="tri colors"), bsp=suz["spec"].bsp, textimage=False)
    data, _ = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists),
                             readers.reader_target(spec, "Mesh", stage_lists=list(lists))])
    p = tmp / "render.sb3"
    p.write_bytes(data)
    cams = cameras(lists["verts"])
    for cam in cams:
        jobs.append({"load": str(p), "runs": [
            call("Mesh", "set camera %s %s %s %s %s", cam.x, cam.y, cam.z, cam.yaw, cam.pitch),
            call("Mesh", "render", lists=["draw order"], pen=True)]})
    out = vm({"jobs": jobs}, timeout=600)["jobs"]
    for case, res in zip(cases, out):
        case["vm"] = res
    return cases, {"lists": lists, "cams": cams, "vm": out[len(cases):]}


@pytest.mark.parametrize("name", MODELS)
def test_bsp_walk_matches_the_python_traversal(walks, name):
    case = next(c for c in walks[0] if c["name"] == name)
    L = case["lists"]
    assert case["vm"]["validation"][0]["ok"]
    two = [bool(x) for x in case["spec"].bsp.two_sided]
    n_tris = len(L["tris"]) // 4
    lengths = set()
    for eye, run in zip(case["eyes"], case["vm"]["runs"]):
        want = draw_order(L["bsp nodes"], L["bsp planes"], eye, L["tris"], L["verts"], two)
        got = [int(x) for x in run["lists"]["draw order"]]
        assert got == want, f"eye {eye}"
        assert len(set(got)) == len(got) and all(1 <= t <= n_tris for t in got)
        lengths.add(len(got))
    assert len(lengths) > 1 or name == "alphablend"  # culling depends on the eye
    if name == "alphablend":
        assert any(two) and not all(two)  # both kinds of material are exercised


def test_renderer_in_bsp_order_draws_the_painters_picture(walks):
    _cases, render = walks
    lists = render["lists"]
    verts = np.asarray(lists["verts"], np.float64)
    tris = np.asarray(lists["tris"], np.int64).reshape(-1, 4)
    colours = decode_numbers(lists["tri colors"])[:, :3].astype(int)
    for cam, res in zip(render["cams"], render["vm"]):
        run = res["runs"][1]
        order = [int(x) for x in run["lists"]["draw order"]]
        assert order == draw_order(lists["bsp nodes"], lists["bsp planes"], [cam.x, cam.y, cam.z],
                                   lists["tris"], lists["verts"], [False])
        px, py, pz = readers.project(verts, cam)
        # (a few thousand samples at least: split triangles are small, and samples near a later
        # triangle's edge are left out as ambiguous)
        check_render(run["pen"], px, py, pz, tris, order, colours, cam.near, False, min_sure=1500)
