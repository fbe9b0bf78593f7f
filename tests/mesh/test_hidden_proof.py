"""The hidden stage's proof in the report (issue 42, "Proof in the report"): the pictures from
held-out eyes with and without the removal, and the BSP splits with and without it, each against
an independent reference (a numpy z-buffer; the BSP stage's own record in a bake)."""

from __future__ import annotations

import json

import numpy as np

from bake import cli
from bake.mesh.hidden import proof, regions
from bake.mesh.hidden.visibility import Visibility
from bake.render import Camera, render

from conftest import corpus_path
from mesh.test_hidden import box, run, scene_of


def _view(s, P):
    c, r = regions.bounding_sphere(s.positions)
    eye = c + np.array([0.3, 0.4, -2.5]) * r
    s_ = r / np.linalg.norm(c - eye)
    half = s_ / np.sqrt(1 - s_ * s_)
    cam = Camera(tuple(eye), tuple(c), width=P, height=P, focal_px=P / 2 / half, near=1e-6)
    return eye, c, r, cam


def test_pictures_show_what_a_zbuffer_shows_with_and_without_the_dropped_triangles():
    """A box beside a bigger one, three of its faces' triangles dropped: the full picture covers
    what a z-buffer of every triangle covers, the kept picture what a z-buffer of the kept ones
    covers, and the red pixels of the difference are the wrong pixels the proof counts (the
    z-buffer's pixels of dropped triangles)."""
    s = scene_of(box([-1, -1, -1], [1, 1, 1]), box([1.5, -0.5, -0.5], [2.5, 0.5, 0.5]))
    T, P = s.n_triangles, 160
    no = np.zeros(T, bool)
    vis = Visibility(s.positions, s.triangles, two_sided=no, see_through=no)
    eye, c, r, cam = _view(s, P)
    d = vis.view_directions(eye, c, r, P)
    kept = np.ones(T, bool)
    kept[[0, 1, 2, 3, 12, 13]] = False
    counted = vis.pixels(eye[None, :], [d], ~kept)
    pics = proof.pictures(s, vis, kept, eye[None, :], [d], counted["wrong_per_eye"], P, 1,
                          two_sided=no, see_through=no)
    assert len(pics) == 1 and pics[0]["wrong_pixels"] == counted["wrong"] > 200
    before, after, diff = (proof.decode(pics[0][k]) for k in ("before", "after", "difference"))
    assert before.shape == after.shape == diff.shape == (P, P, 3)

    tri = s.triangle_vertices()
    full_z, kept_z = render(cam, tri), render(cam, tri[kept])
    red = np.all(diff == proof.WRONG, axis=2)
    assert red.sum() == counted["wrong"]
    ref_wrong = np.isin(full_z.tri_id, np.flatnonzero(~kept))
    assert (red != ref_wrong).sum() <= 0.03 * ref_wrong.sum()  # the same pixels, bar the edges
    bg = lambda img: np.all(img == proof.BACKGROUND, axis=2)
    for img, z in ((before, full_z), (after, kept_z)):
        shows = z.tri_id >= 0
        assert (~bg(img) != shows).sum() <= 0.03 * shows.sum()
    assert (~bg(after)).sum() < (~bg(before)).sum()  # the kept mesh shows less: the removal is seen


def test_pictures_put_the_worst_eyes_first():
    """One eye with one ray per triangle drops faces the held-out eyes see: the first picture is
    of an eye with wrong pixels, the most of those pictured; the eyes to picture are those with
    wrong pixels (most first), then eyes spread over the rest (not the first few, all near one
    pole); ``pictures = 0`` pictures none."""
    s = scene_of(box([-1, -1, -1], [1, 1, 1]), box([1.5, -0.5, -0.5], [2.5, 0.5, 0.5]))
    out, rec = run(s, eyes=1, samples=1, refine=0, seed=3, holdout_eyes=24, holdout_pixels=24, pictures=2)
    h = rec.details["holdout"]
    assert len(h["pictures"]) == 2 and h["wrong_pixels"] > 0
    assert h["pictures"][0]["wrong_pixels"] == max(p["wrong_pixels"] for p in h["pictures"]) > 0
    wrong = np.zeros(12, np.int64)
    wrong[[7, 2]] = [3, 9]
    assert proof._choose(wrong, 4).tolist() == [2, 7, 1, 4]  # the two with wrong pixels, then spread
    assert proof._choose(np.zeros(12, np.int64), 3).tolist() == [2, 6, 10]
    _, rec = run(s, holdout_eyes=8, pictures=0)
    assert rec.details["holdout"]["pictures"] == []


def _bake(tmp_path, name, *sets):
    out = tmp_path / name
    argv = ["run", str(corpus_path("suzanne_obj/suzanne.obj")), "--out", str(out), "--quiet"]
    for s in ("bsp.enabled=true", "export.sb3=false", "export.sprite3=false", *sets):
        argv += ["--set", s]
    assert cli.main(argv) == 0
    rep = json.loads((out / "report.json").read_text())
    return {x["name"]: x for x in rep["stages"]}, out


def test_the_report_gives_the_bsp_splits_with_and_without_the_removal(tmp_path):
    """The proof's two trees are the BSP stage's own: "with the removal" is this bake's BSP record
    (nothing runs between the stages here), "without" the BSP record of the bake with the hidden
    stage off. The report shows them, and the held-out pictures."""
    on, out = _bake(tmp_path, "on", "mesh.hidden.enabled=true", "mesh.hidden.trim=true", "mesh.hidden.holdout_eyes=8")
    off, _ = _bake(tmp_path, "off")
    tree = on["hidden"]["details"]["bsp"]
    for got, ref in ((tree["with_removal"], on["bsp"]), (tree["without_removal"], off["bsp"])):
        assert got["triangles_in"] == ref["counts_in"]["triangles"]
        assert got["triangles_out"] == ref["counts_out"]["triangles"]
    assert tree["with_removal"]["inflation"] < tree["without_removal"]["inflation"]  # trimming: fewer splits
    page = (out / "report.html").read_text()
    sec = page[page.index("Hidden geometry: what no eye sees"):]
    assert "BSP splits" in sec and f"{tree['without_removal']['triangles_out']:,}" in sec
    assert sec[:sec.index("<h2>")].count("<img ") == 3 * len(on["hidden"]["details"]["holdout"]["pictures"]) == 9
    # with the proof's tree switched off, no tree is built for it
    on2, _ = _bake(tmp_path, "on2", "mesh.hidden.enabled=true", "mesh.hidden.bsp_proof=false",
                   "mesh.hidden.holdout_eyes=8")
    assert "bsp" not in on2["hidden"]["details"]


def test_the_written_triangles_are_checked_against_the_model_when_trimming():
    """With trimming the stage writes other triangles than it decided on (sources whole again,
    outlines redrawn), so the proof also compares the depth of the nearest drawn surface of what is
    written with the model's, pixel by pixel: none differs on a peg sunk into a box; a written mesh
    missing a face the held-out eyes see differs on about the pixels a z-buffer gives that face."""
    s = scene_of(box([-2, -2, -2], [2, 2, 2]), box([-0.5, 1.0, -0.5], [0.5, 3.0, 0.5]))
    out, rec = run(s, trim=True, holdout_eyes=16, holdout_pixels=48)
    check = rec.details["holdout"]["written_vs_model"]
    assert check["pixels_differ"] == 0 and check["pixels_showing"] > 10_000
    no = np.zeros(s.n_triangles, bool)
    model = Visibility(s.positions, s.triangles, two_sided=no, see_through=no)
    eye, c, r, cam = _view(s, 120)
    d = model.view_directions(eye, c, r, 120)
    z = render(cam, s.triangle_vertices())
    face = int(np.bincount(z.tri_id[z.tri_id >= 0]).argmax())  # the triangle that shows most
    rest = np.delete(np.arange(s.n_triangles), face)
    written = Visibility(s.positions, s.triangles[rest], two_sided=no[rest], see_through=no[rest])
    differ, shown = proof.depths_differ(model, written, eye[None, :], [d], 1e-9)
    ref = int((z.tri_id == face).sum())
    assert abs(shown - int((z.tri_id >= 0).sum())) <= 0.02 * shown
    assert abs(differ - ref) <= 0.03 * ref and ref > 300
