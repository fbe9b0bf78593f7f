"""The hidden stage's camera region against the project it writes (issue 42): the green-flag
camera the .sb3's reader uses (``reader_spec`` of the lists read back from the archive) is the
one the stage decided for, and every triangle a z-buffer shows from there was kept."""

from __future__ import annotations

import numpy as np

from bake.render import Camera, render
from bake.scratch.project import reader_spec
from conftest import corpus_path
from scratch_models import bake, project_lists


def test_the_written_projects_camera_is_the_one_the_hidden_stage_decided_for():
    model = corpus_path("suzanne_obj", "suzanne.obj")
    res = bake(model, mesh={"hidden": {"enabled": True, "outside": False, "camera": True, "holdout_eyes": 8}})
    rec = next(r for r in res.records if r.name == "hidden")
    files = res.scene.artefacts.outputs
    stem = next(n for n in files if n.endswith(".sb3"))[:-4]
    cam = reader_spec(res.scene, res.config.export, project_lists(files[f"{stem}.sb3"])).camera
    eye = np.array([cam.x, cam.y, cam.z])
    # the lists hold rounded positions: the camera they frame moves by about the rounding step
    assert np.allclose(eye, rec.details["camera_eye"], rtol=0, atol=1e-4 * res.scene.scale())
    full = bake(model, mesh={"hidden": {"enabled": False}}).scene
    kept = {tuple(np.round(t, 4).ravel()) for t in res.scene.triangle_vertices()}
    tri = full.triangle_vertices()
    shown: set[int] = set()
    for f in np.vstack([np.eye(3), -np.eye(3)]):  # the cube around the eye
        up = (0, 0, 1) if abs(f[1]) > 0.5 else (0, 1, 0)
        img = render(Camera(tuple(eye), tuple(eye + f), fov=90.0, width=256, height=256, up=up, near=1e-6), tri)
        shown |= set(np.unique(img.tri_id[img.tri_id >= 0]).tolist())
    missing = [t for t in shown if tuple(np.round(tri[t], 4).ravel()) not in kept]
    assert len(shown) > 100 and missing == []
