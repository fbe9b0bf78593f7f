"""Reuse inside a stage that must run again (bake.cache.Memo): the BSP tree when only colours
changed (bake/bsp/stage.py: tree_key_parts, grow, complete) and the previews' geometry
(bake/outputs/preview.py: render_view). Every reuse must give the bytes a cold computation gives;
with lit colours (vertex colours) no colour change builds the tree again (nothing merges before
the build; the re-merge after it runs with the new colours in every bake); a damaged memo is
ignored with a warning."""

from __future__ import annotations

import json
import re
from pathlib import Path

import numpy as np
import pytest

from bake import cache as cache_mod
from bake import cli, pipeline
from bake.bsp.stage import stage as bsp_stage
from bake.outputs import html

from test_cache import _entry_of, _flip, bake, outputs, write_model

# per-vertex lighting (vertex and face colours, the default target), a BSP with cuts (the box
# stands in the bumpy ground), previews in report.html
CONFIG = """
[input]
path = "scene.obj"
[transform]
fit = 10
[lighting]
enabled = true
exposure = 0.5  # (no colour reaches 1: a change of exposure clips none, so the merge groups stay)
ambient = [0.2, 0.2, 0.2]
[[lighting.lights]]
kind = "sun"
direction = [0.4, -1.0, 0.3]
[lighting.ao]
enabled = true
samples = 8
[bsp]
enabled = true
[report]
html = true
preview_width = 96
"""


def add_plate(obj: Path, n: int = 4) -> None:
    """A flat plate of n x n quads high above the rest, facing the sun: its coplanar triangles get
    equal colours, so they merge (the merges' colour test has something to decide)."""
    text = obj.read_text()
    base = sum(1 for ln in text.splitlines() if ln.startswith("v "))
    lines = [f"v {x:.3f} 2.0 {z:.3f}" for z in np.linspace(-0.5, 0.5, n + 1) for x in np.linspace(-0.5, 0.5, n + 1)]
    lines.append("usemtl box")
    for j in range(n):
        for i in range(n):
            a = base + j * (n + 1) + i + 1
            lines.append(f"f {a} {a + n + 1} {a + n + 2} {a + 1}")
    obj.write_text(text + "\n".join(lines) + "\n")


@pytest.fixture(scope="module")
def lit(tmp_path_factory):
    """The scene as the BSP stage gets it (lit per vertex, on the export's grid) and the config."""
    root = tmp_path_factory.mktemp("reuse")
    add_plate(write_model(root / "m"))
    cfg_path = root / "m" / "r.toml"
    cfg_path.write_text(CONFIG)
    cfg = pipeline.load_config_for(cfg_path)
    res = pipeline.run(cfg, until="lighting", cache=None)
    scene = pipeline.with_grid(res.scene, cfg)
    assert scene.vertex_colors is not None and scene.face_colors is not None
    return root, cfg_path, cfg, scene


FIELDS = ("positions", "triangles", "tri_material", "tri_uvs", "tri_polygon", "vertex_colors", "face_colors",
          "face_albedo", "tri_lightmap_uvs")


def same_scene(a, b) -> None:
    """Every array the BSP stage writes, bit for bit, with its type; the lists; the artefact."""
    for f in FIELDS:
        x, y = getattr(a, f), getattr(b, f)
        assert (x is None) == (y is None), f
        if x is not None:
            assert x.dtype == y.dtype and x.shape == y.shape, f
            assert x.tobytes() == y.tobytes(), f
    assert sorted(a.lists) == sorted(b.lists)
    for name in a.lists:
        va, vb = a.lists[name].values, b.lists[name].values  # (a TextImage list holds strings)
        assert type(va) is type(vb), name
        assert (va.tobytes() == vb.tobytes()) if hasattr(va, "tobytes") else va == vb, name
    for k, v in vars(a.artefacts.bsp).items():
        w = getattr(b.artefacts.bsp, k)
        assert (v.tobytes() == w.tobytes()) if isinstance(v, np.ndarray) else v == w, k


def _run(scene, cfg, memo):
    with cache_mod.using_memo(memo):
        return bsp_stage(scene, cfg.bsp)


def _recoloured(scene, vc, fc=None):
    return scene.replace(vertex_colors=vc, face_colors=scene.face_colors if fc is None else fc)


def test_a_reused_tree_gives_the_bytes_of_a_cold_build(lit):
    _, _, cfg, scene = lit
    memo = cache_mod.Memo(cache_mod.MemoryStore())
    first, rec1 = _run(scene, cfg, memo)
    assert rec1.details["tree_reused"]["reused"] is False
    # the case worth testing: cuts made new vertices (their colours come from the tape); with lit
    # colours nothing merges before the build
    assert rec1.details["new_vertices"] > 0 and rec1.details["splits"] > 0 and rec1.details["merged_triangles"] == 0
    # every colour darker by the same factor (an exposure change): the same merges and vertices
    vc = scene.vertex_colors.copy()
    vc[:, :3] *= 0.8
    fc = scene.face_colors.copy()
    fc[:, :3] *= 0.8
    darker = _recoloured(scene, vc, fc)
    warm, rec2 = _run(darker, cfg, memo)
    assert rec2.details["tree_reused"]["reused"] is True
    assert memo.reused == ["bsp"]  # (report.json's cache.memos_reused)
    cold, rec3 = bsp_stage(darker, cfg.bsp)  # no memo: built
    same_scene(warm, cold)
    assert rec2.counts_out == rec3.counts_out and rec2.warnings == rec3.warnings
    # the colours really changed, and the cut vertices' colours are not the old ones
    n = scene.n_vertices
    assert not np.array_equal(warm.vertex_colors[n:], first.vertex_colors[n:])
    assert not np.array_equal(warm.face_colors, first.face_colors)


def test_colours_that_change_the_joins_reuse_the_tree_and_give_the_cold_bytes(lit):
    """Colours no longer affine over any merge or join: the tree is reused (the re-merge runs with
    the new colours), the bytes are a cold build's. (Before issue 41 such colours built the tree
    again; tests/bsp/test_tree_reuse.py has a scene whose joins they change.)"""
    _, _, cfg, scene = lit
    memo = cache_mod.Memo(cache_mod.MemoryStore())
    _run(scene, cfg, memo)
    rng = np.random.default_rng(5)
    vc = scene.vertex_colors.copy()
    vc[:, :3] = rng.random((len(vc), 3))
    other = _recoloured(scene, vc)
    warm, rec = _run(other, cfg, memo)
    assert rec.details["tree_reused"]["reused"] is True
    assert memo.reused == ["bsp"]
    cold, rec_cold = bsp_stage(other, cfg.bsp)
    same_scene(warm, cold)
    assert rec.counts_out == rec_cold.counts_out and rec.warnings == rec_cold.warnings
    assert rec.details["remerged_fragments"] == rec_cold.details["remerged_fragments"]


def test_face_colours_that_change_the_groups_reuse_the_tree_and_give_the_cold_bytes(lit):
    """New face colours regroup the faces (the re-merge joins only within a group): the tree is
    reused, the re-merge runs with the new groups, the bytes are a cold build's."""
    _, _, cfg, scene = lit
    memo = cache_mod.Memo(cache_mod.MemoryStore())
    _run(scene, cfg, memo)
    fc = scene.face_colors.copy()
    fc[::2, :3] = 0.5  # every other triangle one colour: other groups
    other = _recoloured(scene, scene.vertex_colors, fc)
    warm, rec = _run(other, cfg, memo)
    assert rec.details["tree_reused"]["reused"] is True
    assert memo.reused == ["bsp"]
    cold, _ = bsp_stage(other, cfg.bsp)
    same_scene(warm, cold)


def _normals(scene):
    p = scene.positions[scene.triangles]
    n = np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0])
    return n / np.linalg.norm(n, axis=1, keepdims=True)


def test_face_colours_that_regroup_without_changing_a_merge_reuse_the_tree(lit):
    """A lit bake's face colours are nearly all different; a new light or AO sample count makes a
    few of them equal or unequal. Triangles that face different ways can never merge, so giving
    two of them one colour regroups the faces without changing a merge: the tree is reused, and
    the bytes are a cold build's."""
    _, _, cfg, scene = lit
    memo = cache_mod.Memo(cache_mod.MemoryStore())
    _run(scene, cfg, memo)
    from bake.bsp.stage import _canonical, _groups, tri_two_sided

    two = tri_two_sided(scene)
    g = _groups(scene, two)
    alone = np.flatnonzero(np.bincount(g)[g] == 1)  # triangles alone in their group
    nrm = _normals(scene)
    # two of them of one material, facing different ways
    pairs = [(int(a), int(b)) for a in alone for b in alone
             if scene.tri_material[a] == scene.tri_material[b] and nrm[a] @ nrm[b] < 0.5]
    a, b = pairs[0]
    fc = scene.face_colors.copy() * 0.9
    fc[b] = fc[a]  # one group of two where there were two (colour and albedo alike)
    other = _recoloured(scene, scene.vertex_colors * 0.9, fc)
    if scene.face_albedo is not None:
        alb = scene.face_albedo.copy()
        alb[b] = alb[a]
        other = other.replace(face_albedo=alb)
    assert not np.array_equal(_canonical(_groups(other, two)), _canonical(_groups(scene, two)))
    warm, rec = _run(other, cfg, memo)
    assert rec.details["tree_reused"]["reused"] is True and memo.reused == ["bsp"]
    cold, _ = bsp_stage(other, cfg.bsp)
    same_scene(warm, cold)


def test_the_tape_changes_nothing_the_build_makes(lit):
    """The corner ids that ride along as one more attribute decide nothing: a build with the
    tape and one without give the same store and encoding."""
    from bake.bsp.stage import build, options

    _, _, cfg, scene = lit
    a = build(scene, options(cfg.bsp), True, tape=False)
    b = build(scene, options(cfg.bsp), True, tape=True)
    assert a[0].tape is None and b[0].tape is not None and len(b[0].tape.batches) > 0
    n = a[0].n
    assert n == b[0].n
    assert np.array_equal(a[0].pos[:n], b[0].pos[:n]) and np.array_equal(a[0].vid[:n], b[0].vid[:n])
    assert np.array_equal(a[0].attr[:n], b[0].attr[:n, :, :a[0].A])
    assert np.array_equal(a[3].nodes, b[3].nodes) and np.array_equal(a[3].planes, b[3].planes)


def _memo_kinds(rep: dict) -> list[str]:
    return rep["cache"]["memos_reused"]


def test_a_bake_after_an_exposure_change_reuses_the_tree_and_the_previews(lit, tmp_path):
    root, cfg_path, _, _ = lit
    out = tmp_path / "warm"
    first = bake(cfg_path, out)
    assert _memo_kinds(first) == []
    rep = bake(cfg_path, out, "lighting.exposure=0.4")
    assert rep["cache"]["from_cache"][-1] == "transform" or "lighting" not in rep["cache"]["from_cache"]
    bsp = next(s for s in rep["stages"] if s["name"] == "bsp")
    assert bsp["details"]["tree_reused"]["reused"] is True
    assert _memo_kinds(rep).count("bsp") == 1
    cold = bake(cfg_path, tmp_path / "cold", "lighting.exposure=0.4", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")
    # report.json: the same figures (times and the cache's part aside)
    for a, b in zip(rep["stages"], cold["stages"], strict=True):
        assert a["counts_out"] == b["counts_out"] and a["accuracy"] == b["accuracy"], a["name"]
        assert a["warnings"] == b["warnings"], a["name"]
    # report.html's previews: the page rendered with the reused geometry is the page rendered from scratch
    memo = cache_mod.Memo(cache_mod.DiskStore(out / cache_mod.SUBDIR, 10**9))
    page_memo, info_memo = html.build(out, width=96, height=72, memo=memo)
    assert memo.reused == ["preview"] * 4 and memo.warnings == []
    page_ref, info_ref = html.build(out, width=96, height=72)
    assert page_memo == page_ref and info_memo == info_ref
    # and the bake's own report.html (previews from the reused geometry) shows the images of a cold bake's
    images = [re.findall(r"data:image/png;base64,[A-Za-z0-9+/=]+", (d / "report.html").read_text())
              for d in (out, tmp_path / "cold")]
    assert len(images[0]) >= 12 and images[0] == images[1]
    assert bake(cfg_path, tmp_path / "first")  # the first colours: other images
    assert re.findall(r"data:image/png;base64,[A-Za-z0-9+/=]+", (tmp_path / "first" / "report.html").read_text()) \
        != images[0]


def test_a_preview_memo_of_another_camera_size_is_not_used(lit, tmp_path):
    root, cfg_path, _, _ = lit
    out = tmp_path / "o"
    bake(cfg_path, out)
    store = cache_mod.DiskStore(out / cache_mod.SUBDIR, 10**9)
    memo = cache_mod.Memo(store)
    p1, _ = html.build(out, width=96, height=72, memo=memo)
    assert memo.reused == ["preview"] * 4  # the bake stored them at this size
    memo2 = cache_mod.Memo(store)
    p2, _ = html.build(out, width=64, height=48, memo=memo2)
    assert memo2.reused == [] and p2 == html.build(out, width=64, height=48)[0]


def test_a_damaged_tree_memo_is_ignored_with_a_warning(lit, tmp_path):
    root, cfg_path, _, _ = lit
    out = tmp_path / "o"
    bake(cfg_path, out)
    bad = _entry_of(out / cache_mod.SUBDIR, "memo bsp")
    _flip(bad)
    rep = bake(cfg_path, out, "lighting.exposure=0.45")
    bsp = next(s for s in rep["stages"] if s["name"] == "bsp")
    assert bsp["details"]["tree_reused"]["reused"] is False
    assert any("bsp memo" in w and bad.name in w for w in bsp["warnings"]), bsp["warnings"]
    bake(cfg_path, tmp_path / "cold", "lighting.exposure=0.45", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")
    # built again and stored again: the next colour change reuses it
    rep = bake(cfg_path, out, "lighting.exposure=0.42")
    assert next(s for s in rep["stages"] if s["name"] == "bsp")["details"]["tree_reused"]["reused"] is True


def test_a_sweep_times_its_stage_without_reuse_and_the_stages_after_may_reuse(lit, tmp_path):
    """``bake sweep`` measures the key's stage (``recompute``): it reuses nothing (no lighting
    trace), while a stage after it reuses what the new colours did not change (the BSP tree), as
    a bake of the same config does."""
    root, cfg_path, _, _ = lit
    out = tmp_path / "o"
    bake(cfg_path, out)
    store = cache_mod.DiskStore(out / cache_mod.SUBDIR, 10**9)
    cfg = pipeline.load_config_for(cfg_path, ["lighting.exposure=0.35"])
    res = pipeline.run(cfg, cache=cache_mod.StageCache(store), recompute=("lighting",))
    light = next(r for r in res.records if r.name == "lighting")
    bsp = next(r for r in res.records if r.name == "bsp")
    assert light.details["trace_reused"]["reused"] is False and light.details["rays"] > 0
    assert bsp.details["tree_reused"]["reused"] is True and res.cache["memos_reused"] == ["bsp"]
    res = pipeline.run(cfg, cache=cache_mod.StageCache(store))
    assert next(r for r in res.records if r.name == "lighting").details["trace_reused"]["reused"] is True
    assert next(r for r in res.records if r.name == "bsp").details["tree_reused"]["reused"] is True


# --------------------------------------------------------------------------- the lighting trace
def _stage(rep: dict, name: str) -> dict:
    return next(s for s in rep["stages"] if s["name"] == name)


@pytest.mark.parametrize("change,reused", [
    ("lighting.exposure=0.4", True), ("lighting.tonemap=\"reinhard\"", True),
    ("lighting.lights[0].direction=[0.2, -1.0, 0.5]", False), ("lighting.ao.samples=12", False)],
    ids=["exposure", "tonemap", "sun-direction", "ao-samples"])
def test_a_colour_key_change_reuses_the_trace_and_gives_the_cold_bytes(lit, tmp_path, change, reused):
    root, cfg_path, _, _ = lit
    out = tmp_path / "warm"
    bake(cfg_path, out)
    rep = bake(cfg_path, out, change)
    light = _stage(rep, "lighting")
    assert light["details"]["trace_reused"]["reused"] is reused
    assert ("lighting" in rep["cache"]["memos_reused"]) is reused
    cold = bake(cfg_path, tmp_path / "cold", change, "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")
    c = _stage(cold, "lighting")
    assert light["accuracy"] == c["accuracy"] and light["warnings"] == c["warnings"]
    assert light["details"]["color_pipeline"] == c["details"]["color_pipeline"]
    def figures(effects):  # (times aside)
        return [{k: v for k, v in e.items() if k not in ("seconds", "timing")} for e in effects]

    assert figures(light["effects"]) == figures(c["effects"])
    if not reused:  # the key that needs new rays traced them: the figure is not the cheap one
        assert light["details"]["rays"] > 0 and light["details"]["trace_reused"]["traced_seconds"] > 0


def test_a_trace_with_subdivision_is_not_reused(lit, tmp_path):
    """Subdivision compares shown colours (exposure, tone map), so its trace depends on them."""
    root, cfg_path, _, _ = lit
    out = tmp_path / "o"
    bake(cfg_path, out, "lighting.subdivide=true")
    rep = bake(cfg_path, out, "lighting.subdivide=true", "lighting.exposure=0.4")
    assert _stage(rep, "lighting")["details"]["trace_reused"]["reused"] is False
    bake(cfg_path, tmp_path / "cold", "lighting.subdivide=true", "lighting.exposure=0.4", "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")


@pytest.mark.parametrize("change", ["lighting.ao.samples=9", "lighting.lights[0].direction=[0.2, -1.0, 0.5]",
                                    "lighting.ambient=[0.3, 0.25, 0.2]"], ids=["ao-samples", "sun-direction", "ambient"])
def test_a_lighting_change_reuses_the_tree_and_gives_the_lists_of_a_cold_bake(lit, tmp_path, change):
    """Issue 41: a re-bake after a lighting key that needs new rays (AO samples, the sun's
    direction) or changes every colour reuses the BSP tree (report.json says so), and writes the
    lists a cold bake of the changed config writes, byte for byte."""
    root, cfg_path, _, _ = lit
    out = tmp_path / "warm"
    bake(cfg_path, out)
    geometry = {n: (out / "lists" / n).read_bytes() for n in ("verts.txt", "tris.txt", "bsp_nodes.txt",
                                                              "bsp_planes.txt")}
    rep = bake(cfg_path, out, change)
    assert "bsp" in _memo_kinds(rep)
    # the written geometry is the lighting's no more: the same vertices, triangles and tree
    assert {n: (out / "lists" / n).read_bytes() for n in geometry} == geometry
    bsp = _stage(rep, "bsp")
    assert bsp["details"]["tree_reused"]["reused"] is True
    cold = bake(cfg_path, tmp_path / "cold", change, "cache.dir=\"none\"")
    assert outputs(out) == outputs(tmp_path / "cold")
    lists = sorted(p.name for p in (out / "lists").iterdir())
    assert lists and lists == sorted(p.name for p in (tmp_path / "cold" / "lists").iterdir())
    for name in ["lists.json", *(f"lists/{n}" for n in lists)]:
        assert (out / name).read_bytes() == (tmp_path / "cold" / name).read_bytes(), name
    c = _stage(cold, "bsp")
    assert bsp["counts_out"] == c["counts_out"] and bsp["warnings"] == c["warnings"]
    assert bsp["details"]["remerged_fragments"] == c["details"]["remerged_fragments"]
