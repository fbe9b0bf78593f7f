"""The textures stage (bake/textures/stage.py, encode.py) against independent references.

* per-triangle base colour = a brute-force midpoint-rule mean of the texture over the triangle
  (nearest texel, repeat addressing, linear light, alpha-weighted) x material x mean vertex
  colour, and visibly not the centre sample;
* the three encodings decode back to the resampled texture (colour list read the way Scratch's
  pen reads it, TextImage decoder, PNG decoder), and the sizes the record claims equal what the
  export stage and a written .sb3 actually contain;
* the lighting stage picks the textured albedo up, also after it subdivides triangles;
* the textured corpus models bake to every encoding (and a valid .sb3);
* a crashing xatlas costs the lightmap, not the bake; reruns give identical bytes;
* ``bake run`` keeps the xatlas cache in the output folder (not ~/.cache), out of the manifest.
"""

from __future__ import annotations

import dataclasses
import io
import sys

import numpy as np
import pytest
from PIL import Image

from bake import config as config_mod
from bake import pipeline
from bake.config import ExportConfig, LightConfig, LightingConfig, TexturesConfig
from bake.errors import StageError
from bake.scratch import sb3
from bake.scratch.limits import ASSET_LIMIT
from bake.lighting import color as lighting_color
from bake.lighting import stage as lighting_stage
from bake.scene import Material, make_scene
from bake.scratch import colors, textimage
from bake.textures import lightmap, unwrap, unwrap_cache
from bake.export.stage import stage as export_stage
from bake.textures import stage as tstage
from bake.textures.texels import cover, texel_mask
from bake.colorspace import linear_to_srgb, srgb_to_linear
from conftest import corpus_path


def png(img: np.ndarray) -> bytes:
    buf = io.BytesIO()
    Image.fromarray(img).save(buf, format="PNG")
    return buf.getvalue()


def checker(n=8, seed=0, alpha=False):
    rng = np.random.default_rng(seed)
    img = rng.integers(0, 256, size=(n, n, 4), dtype=np.uint8)
    img[:, :, 3] = rng.integers(40, 256, size=(n, n)) if alpha else 255
    return img


def textured_scene(img, n_tri=24, seed=1, color=(0.9, 0.6, 0.8, 1.0), with_vc=True):
    """Random triangles with random UVs (some beyond [0, 1]: repeat) on one textured material,
    plus an untextured one."""
    rng = np.random.default_rng(seed)
    pos = rng.normal(size=(3 * n_tri, 3))
    tris = np.arange(3 * n_tri).reshape(n_tri, 3)
    c = rng.uniform(-0.5, 1.5, size=(n_tri, 1, 2))
    uv = c + rng.normal(scale=0.25, size=(n_tri, 3, 2))
    mats = (Material("wood", color=color, texture_data=png(img)), Material("plain", color=(0.2, 0.4, 0.6, 1.0)))
    tm = (np.arange(n_tri) % 4 == 3).astype(np.int64)  # every 4th triangle untextured
    vc = rng.uniform(0.3, 1.0, size=(3 * n_tri, 4)) if with_vc else None
    return make_scene(pos, tris, materials=mats, tri_material=tm, vertex_colors=vc, tri_uvs=uv)


def brute_mean(img, uv, N=160, space="linear"):
    """Midpoint rule over N^2 sub-triangles, nearest texel with repeat; alpha-weighted RGB."""
    H, W = img.shape[:2]
    ii, jj = np.meshgrid(np.arange(N), np.arange(N), indexing="ij")
    up = (ii + jj <= N - 1)
    dn = (ii + jj <= N - 2)
    st = np.concatenate([np.stack([ii[up] + 1 / 3, jj[up] + 1 / 3], 1),
                         np.stack([ii[dn] + 2 / 3, jj[dn] + 2 / 3], 1)]) / N
    p = uv[0] + st[:, :1] * (uv[1] - uv[0]) + st[:, 1:] * (uv[2] - uv[0])
    x = np.floor(p[:, 0] * W).astype(int) % W
    y = np.floor((1 - p[:, 1]) * H).astype(int) % H
    f = img[y, x].astype(float) / 255
    rgb = srgb_to_linear(f[:, :3]) if space == "linear" else f[:, :3]
    a = f[:, 3]
    m = (rgb * a[:, None]).sum(0) / a.sum()
    out = linear_to_srgb(m) if space == "linear" else m
    return np.append(out, a.mean())


# --------------------------------------------------------------------------------------------
# base colour


@pytest.mark.parametrize("space", ["linear", "srgb"])
def test_albedo_is_texture_mean_times_material_and_vertex_colour(space):
    img = checker(8, alpha=True)
    scene = textured_scene(img)
    out, rec = tstage.stage(scene, TexturesConfig(enabled=True, average=space, encodings=[]))
    alb = out.face_albedo
    assert alb.shape == (scene.n_triangles, 4) and np.isfinite(alb).all()
    assert np.array_equal(out.face_colors, alb) and np.array_equal(out.triangle_albedo(), alb)
    vmean = scene.vertex_colors[scene.triangles].mean(axis=1)
    for t in range(scene.n_triangles):
        mat = np.array(scene.materials[scene.tri_material[t]].color)
        tex = brute_mean(img, scene.tri_uvs[t], space=space) if scene.tri_material[t] == 0 else np.ones(4)
        assert np.allclose(alb[t], tex * mat * vmean[t], atol=4e-3), t
    assert rec.counts_out["textured_triangles"] == int((scene.tri_material == 0).sum())


def test_albedo_is_not_the_centre_sample():
    # one triangle covering a black/white checker: the mean is grey, the centre is black or white
    img = np.zeros((8, 8, 4), np.uint8)
    img[:, :, 3] = 255
    img[(np.add.outer(np.arange(8), np.arange(8)) % 2) == 0, :3] = 255
    uv = np.array([[[0.02, 0.03], [0.97, 0.05], [0.4, 0.95]]])
    scene = make_scene(np.eye(3), [[0, 1, 2]], materials=(Material("c", color=(1, 1, 1, 1), texture_data=png(img)),),
                       tri_uvs=uv)
    out, _ = tstage.stage(scene, TexturesConfig(enabled=True, average="srgb", encodings=[]))
    c = uv[0].mean(axis=0)
    centre = img[int((1 - c[1]) * 8), int(c[0] * 8), 0] / 255
    assert abs(out.face_albedo[0, 0] - 0.5) < 0.03 and abs(out.face_albedo[0, 0] - centre) > 0.4


# --------------------------------------------------------------------------------------------
# encodings


@pytest.mark.parametrize("fmt,first_row,alpha", [("rgb", "bottom", False), ("argb", "top", True),
                                                ("hex", "bottom", False)])
def test_encodings_decode_back_and_sizes_are_real(fmt, first_row, alpha, tmp_path):
    img = checker(32, seed=4, alpha=alpha)
    scene = textured_scene(img, with_vc=False)
    cfg = TexturesConfig(enabled=True, max_size=16, filter="box", color_format=fmt, first_row=first_row)
    out, rec = tstage.stage(scene, cfg)
    ts = out.artefacts.textures
    res = ts.textures[0].image
    assert res.shape == (16, 16, 4)
    # colour list, read like Scratch's pen reads it
    pix = out.lists["tex wood"]
    assert out.lists["tex wood size"].values.tolist() == [16, 16]
    back = colors.list_to_image(list(pix.values), 16, 16, first_row=first_row)
    assert np.array_equal(back[:, :, :3], res[:, :, :3])
    if fmt == "argb":
        assert np.array_equal(back[:, :, 3], np.maximum(res[:, :, 3], 1))
    # TextImage, one string item
    txt = out.lists["tex wood textimage"]
    assert txt.kind == "string" and len(txt.values) == 1
    dec = textimage.decode(txt.values[0], channels=4)
    assert np.array_equal(dec if alpha else dec[:, :, :3], res if alpha else res[:, :, :3])
    # PNG costume
    (name, data), = out.artefacts.costumes
    assert name == "tex wood"
    pimg = np.asarray(Image.open(io.BytesIO(data)).convert("RGBA"))
    assert np.array_equal(pimg, res)
    # the record's sizes = what export writes
    enc = rec.details["textures"][0]["encodings"]
    ex, _ = export_stage(out, config_mod.ExportConfig(sb3=False, sprite3=False))
    info = ex.artefacts.list_info
    assert enc["list"]["project_json_bytes"] == info["tex wood"]["project_json_bytes"] + \
        info["tex wood size"]["project_json_bytes"]
    assert enc["list"]["items"] == 16 * 16 + 2
    assert enc["textimage"]["project_json_bytes"] == info["tex wood textimage"]["project_json_bytes"]
    # ... and what a costume adds to a written project.json; the project validates
    base = sb3.Costume("costume1", sb3.Asset(sb3.SPRITE_SVG, "svg"), 1, (1.0, 1.0))
    mine = sb3.Costume(name, sb3.Asset(data, "png"), 2, (8.0, 8.0))
    lists = {k: (list(lst.values) if lst.kind == "string" else lst.values.tolist()) for k, lst in out.lists.items()}
    _, pj0 = sb3.write_sb3([sb3.Target("Stage", is_stage=True), sb3.Target("S", costumes=[base])])
    blob, pj1 = sb3.write_sb3([sb3.Target("Stage", is_stage=True, lists=lists),
                               sb3.Target("S", costumes=[base, mine])])
    claimed = enc["costume"]["project_json_bytes"] + sum(v["project_json_bytes"] for v in info.values() if _is_tex(v))
    # export's per-list estimate (which the record repeats) is one byte high per list (+ the last comma)
    assert 0 <= claimed - (pj1 - pj0) <= len(lists) + 1
    path = tmp_path / "t.sb3"
    path.write_bytes(blob)
    project, assets = sb3.load_project(path)
    assert sb3.validate_project(project, assets) == []
    costume = project["targets"][1]["costumes"][1]
    assert costume["bitmapResolution"] == 2 and costume["dataFormat"] == "png"
    assert enc["costume"]["asset_bytes"] == len(data) < ASSET_LIMIT


def _is_tex(v):
    return v["doc"].startswith("texture ")


def test_resampling_options():
    img = checker(20, seed=2)
    scene = textured_scene(img)
    for kw, size in (({"width": 12, "height": 6}, (6, 12)), ({"max_size": 10}, (10, 10)),
                     ({"max_size": 20, "power_of_two": "floor"}, (16, 16)),
                     ({"width": 12, "power_of_two": "ceil"}, (16, 16))):
        out, _ = tstage.stage(scene, TexturesConfig(enabled=True, encodings=["list"], **kw))
        assert out.artefacts.textures.textures[0].image.shape[:2] == size, kw
    out, _ = tstage.stage(scene, TexturesConfig(enabled=True, max_size=7, filter="nearest"))
    res = out.artefacts.textures.textures[0].image
    src = {tuple(c) for c in img.reshape(-1, 4).tolist()}
    assert all(tuple(c) in src for c in res.reshape(-1, 4).tolist())  # nearest: exact source colours


def test_only_requested_encodings_are_written_but_all_are_compared():
    scene = textured_scene(checker(8))
    out, rec = tstage.stage(scene, TexturesConfig(enabled=True, encodings=["textimage"]))
    assert set(out.lists) == {"tex wood textimage"} and out.artefacts.costumes is None
    enc = rec.details["textures"][0]["encodings"]
    assert set(enc) == {"list", "textimage", "costume"}
    assert enc["list"]["written"].startswith("not requested") and enc["textimage"]["written"] == "written"
    assert all(enc[e]["project_json_bytes"] > 0 for e in enc)


def test_identical_textures_are_shared_and_names_must_differ():
    img = checker(8)
    s = textured_scene(img)
    mats = s.materials + (Material("wood2", texture_data=png(img)),)
    tm = s.tri_material.copy()
    tm[0] = 2
    s = s.replace(materials=mats, tri_material=tm)
    out, rec = tstage.stage(s, TexturesConfig(enabled=True))
    assert len(rec.details["textures"]) == 1 and rec.details["textures"][0]["materials"] == ["wood", "wood2"]
    with pytest.raises(config_mod.ConfigError):
        tstage.stage(s, TexturesConfig(enabled=True, list_name="tex", size_list_name="tex"))


def test_unreadable_texture_is_a_warning():
    s = textured_scene(checker(8))
    bad = s.replace(materials=(Material("wood", texture_data=b"not an image"),) + s.materials[1:])
    out, rec = tstage.stage(bad, TexturesConfig(enabled=True))
    assert any("texture not used" in w for w in rec.warnings)
    assert out.face_albedo is None and not out.lists


def test_deterministic_bytes():
    s = textured_scene(checker(16, alpha=True))
    cfg = TexturesConfig(enabled=True, color_format="argb")
    a, ra = tstage.stage(s, cfg)
    b, rb = tstage.stage(s, cfg)
    assert a.artefacts.costumes == b.artefacts.costumes
    for k in a.lists:
        va, vb = a.lists[k].values, b.lists[k].values
        assert (va == vb) if isinstance(va, tuple) else np.array_equal(va, vb)
    assert np.array_equal(a.face_albedo, b.face_albedo)
    assert ra.details["size_table"] == rb.details["size_table"]


# --------------------------------------------------------------------------------------------
# lighting picks the albedo up


def test_lighting_uses_textured_albedo_also_after_subdividing():
    img = checker(8, seed=3)
    # a textured floor under a point light: the light varies, so the lighting stage splits it
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    tris = np.array([[0, 2, 1], [0, 3, 2]])
    uv = np.array([[[0, 0], [1, 1], [1, 0]], [[0, 0], [0, 1], [1, 1]]], float) * 2  # repeats twice
    scene = make_scene(pos, tris, materials=(Material("floor", color=(1, 1, 1, 1), texture_data=png(img)),),
                       tri_uvs=uv)
    out, _ = tstage.stage(scene, TexturesConfig(enabled=True, encodings=[]))
    light = LightingConfig(enabled=True, lights=[LightConfig(kind="point", position=[0.3, 0.6, 0.2], intensity=1.0)],
                           color_space="srgb", subdivide=True, max_triangles=200, subdivide_levels=2,
                           subdivide_threshold=0.02, face_cell=0.05)
    lit, _ = lighting_stage.stage(out, light)
    assert lit.n_triangles > scene.n_triangles  # it did split
    res = lit.artefacts.lighting
    exact = np.array([brute_mean(img, lit.tri_uvs[t], N=96) for t in range(lit.n_triangles)])
    expect = lighting_color.shade(srgb_to_linear(exact[:, :3]), res.face_irradiance, 1.0, "clamp", "srgb")
    assert np.abs(lit.face_colors[:, :3] - expect).max() < 8e-3
    # with the default (material x vertex colour) albedo the colours would be white x light
    plain = lighting_color.shade(np.ones_like(expect), res.face_irradiance, 1.0, "clamp", "srgb")
    assert np.abs(lit.face_colors[:, :3] - plain).max() > 0.1


# --------------------------------------------------------------------------------------------
# lightmap outputs of the stage


def test_stage_lightmap_outputs_and_crash(tmp_path, monkeypatch):
    import trimesh

    m = trimesh.creation.box(extents=(2, 1, 1))
    scene = make_scene(m.vertices, m.faces)
    cfg = TexturesConfig(enabled=True)
    cfg.lightmap = dataclasses.replace(cfg.lightmap, enabled=True, resolution=64, cache_dir=str(tmp_path))
    out, rec = tstage.stage(scene, cfg)
    assert out.tri_lightmap_uvs is not None, rec.warnings
    assert out.tri_lightmap_uvs.shape == (scene.n_triangles, 3, 2)
    exported, _ = export_stage(out, ExportConfig(sb3=False, sprite3=False))
    uv = exported.lists["lightmap uvs"]
    assert uv.stride == 6 and len(uv.values) == 6 * scene.n_triangles
    assert np.array_equal(np.asarray(uv.values).reshape(-1, 3, 2), out.tri_lightmap_uvs)
    job = out.artefacts.lightmap
    assert isinstance(job, lightmap.LightmapJob) and job.atlas.n_triangles == scene.n_triangles
    assert rec.details["lightmap"]["triangles_without_samples"] == 0
    out.validate()
    # a crashing xatlas: a warning, no lightmap, the rest of the stage done
    monkeypatch.setattr(unwrap, "WORKER_COMMAND", [sys.executable, "-c",
                                                   "import os, signal; os.kill(os.getpid(), signal.SIGSEGV)"])
    cfg.lightmap = dataclasses.replace(cfg.lightmap, cache_dir="none")
    out2, rec2 = tstage.stage(scene, cfg)
    assert any("crashed (SIGSEGV)" in w for w in rec2.warnings)
    assert out2.tri_lightmap_uvs is None
    assert [e for e in rec2.effects if e["name"] == "lightmap"][0]["ran"] is False


def test_xatlas_cache_directory():
    from pathlib import Path

    cfg = config_mod.LightmapConfig()
    assert cfg.cache_dir == "" and unwrap_cache.cache_directory(cfg) is None  # no output folder: no cache
    cfg.out_dir = Path("out")
    assert unwrap_cache.cache_directory(cfg) == Path("out/.bake-cache/xatlas")
    assert unwrap_cache.cache_directory(dataclasses.replace(cfg, cache_dir=" None ")) is None
    assert unwrap_cache.cache_directory(dataclasses.replace(cfg, cache_dir="/shared/x")) == Path("/shared/x")
    assert "out_dir" not in config_mod.to_dict(config_mod.Config())["textures"]["lightmap"]  # not a key


def test_default_xatlas_cache_stays_in_the_output_folder(tmp_path, monkeypatch, capsys):
    """``bake run`` caches the atlas in <out>/.bake-cache/xatlas (nothing under ~/.cache or
    $XDG_CACHE_HOME), written like an output (usual mode, no temporary left), never listed in the
    manifest or the report's outputs, and kept when the outputs it served are removed as stale."""
    import json
    import os

    from bake import cli

    home, xdg = tmp_path / "home", tmp_path / "xdg"
    home.mkdir()
    xdg.mkdir()
    monkeypatch.setenv("HOME", str(home))
    monkeypatch.setenv("XDG_CACHE_HOME", str(xdg))
    model = tmp_path / "model"
    model.mkdir()
    (model / "m.obj").write_text("v 0 0 0\nv 2 0 0\nv 2 0 2\nv 0 0 2\nv 0 1 0\nv 2 1 0\n"
                                 "f 1 3 2\nf 1 4 3\nf 1 2 6\nf 1 6 5\n")
    cfg = model / "bake.toml"
    cfg.write_text('[input]\npath = "m.obj"\n[textures]\nenabled = true\n'
                   '[textures.lightmap]\nenabled = true\nresolution = 32\n'
                   '[cache]\ndir = "none"\n')  # (the stage cache would serve the rerun before xatlas's)
    out = tmp_path / "out"

    def bake(*extra):
        assert cli.main(["run", str(cfg), "--out", str(out), "--quiet", *extra]) == 0, capsys.readouterr().err
        rep = json.loads((out / "report.json").read_text())
        st = next(s for s in rep["stages"] if s["name"] == "textures")
        return rep, st["details"].get("lightmap")

    rep, figs = bake()
    entries = list((out / ".bake-cache" / "xatlas").rglob("*"))
    files = [p for p in entries if p.is_file()]
    assert len(files) == 1 and files[0].name.endswith(".npz") and figs["cached"] is False
    assert files[0].name.startswith(figs["key"])
    mask = os.umask(0o022)
    os.umask(mask)
    assert files[0].stat().st_mode & 0o777 == 0o666 & ~mask
    assert not list(home.rglob("*")) and not list(xdg.rglob("*"))
    listed = json.loads((out / ".bake-manifest.json").read_text())["files"]
    assert "lists/lightmap_uvs.txt" in listed
    assert not [f for f in [*listed, *rep["outputs"]] if ".bake-cache" in f]
    # a rerun is served by the cache; the entry is not rewritten
    stamp = files[0].stat().st_mtime_ns
    _, figs2 = bake()
    assert figs2["cached"] is True and figs2["key"] == figs["key"] and files[0].stat().st_mtime_ns == stamp
    # a temporary left by a killed bake is removed by the next bake into the folder
    orphan = files[0].parent / f".{files[0].name}.x1y2z3.bake-tmp"
    orphan.write_bytes(b"half")
    # without the lightmap its lists are stale and removed; the cache stays
    rep3, figs3 = bake("--set", "textures.lightmap.enabled=false")
    assert figs3 is None and "removed" in rep3["outputs"].values()
    assert files[0].is_file() and not orphan.exists()
    # an explicit cache_dir is used instead (the user's shared cache); "none" writes nothing
    shared = tmp_path / "shared"
    _, figs4 = bake("--set", f'textures.lightmap.cache_dir="{shared}"')
    assert figs4["cached"] is False and len(list(shared.rglob("*.npz"))) == 1
    _, figs5 = bake("--set", 'textures.lightmap.cache_dir="none"')
    assert figs5["cached"] is False and len(list(out.rglob("*.npz"))) == 1 and len(list(shared.rglob("*.npz"))) == 1


def test_bake_lightmap_target_end_to_end(tmp_path):
    """textures stage (atlas) -> lighting stage with target = "lightmap": the lightmap image and
    its encodings; a lit floor under a sun reads cos(theta) everywhere it is not shadowed."""
    pos = np.array([[-1, 0, -1], [1, 0, -1], [1, 0, 1], [-1, 0, 1]], float)
    scene = make_scene(pos, [[0, 2, 1], [0, 3, 2]])
    cfg = TexturesConfig(enabled=True)
    cfg.lightmap = dataclasses.replace(cfg.lightmap, enabled=True, resolution=32, cache_dir=str(tmp_path))
    out, _ = tstage.stage(scene, cfg)
    light = LightingConfig(enabled=True, target="lightmap", color_space="linear", vertex_output="light",
                           lights=[LightConfig(kind="sun", direction=[0.0, -1.0, -1.0], angle=0.0)])
    final, rec = lighting_stage.stage(out, light)
    figs = rec.details["lightmap"]
    assert [e for e in rec.effects if e["name"] == "lightmap"][0]["rays"] > 0
    img = final.artefacts.lightmap_image
    H, W = img.shape[:2]
    atlas = out.artefacts.lightmap.atlas
    _, texels = cover(atlas)
    covered = texel_mask(texels, np.ones(len(texels)), atlas)
    assert covered.sum() > 0.3 * W * H
    assert np.all(np.abs(img[covered][:, :3].astype(int) - round(255 / np.sqrt(2))) <= 1)
    assert final.lists["tex lightmap size"].values.tolist() == [W, H]
    assert textimage.decode(final.lists["tex lightmap textimage"].values[0]).shape == (H, W, 3)
    assert figs["encodings"]["costume"]["written"] == "written" and figs["samples"] > 0
    with pytest.raises(StageError, match="needs the lightmap atlas"):
        lighting_stage.stage(scene, light)


# --------------------------------------------------------------------------------------------
# the textured corpus


CORPUS = [("spot_triangulated", "spot/spot_triangulated.obj", "spot_texture.png"),
          ("capsule_textured", "capsule.obj", ""), ("fuze_textured", "fuze.obj", ""),
          ("duck_glb", "Duck.glb", ""), ("box_textured_glb", "BoxTextured.glb", ""),
          ("box_textured_gltf_separate", "BoxTextured.gltf", ""),
          ("alpha_blend_mode_test", "AlphaBlendModeTest.glb", "")]


@pytest.mark.corpus
@pytest.mark.parametrize("name,file,texture", CORPUS, ids=[c[0] for c in CORPUS])
def test_textured_corpus_bakes_to_every_encoding(name, file, texture, tmp_path):
    cfg = pipeline.load_config_for(corpus_path(name, *file.split("/")))
    scene = pipeline.run(cfg, until="clean").scene
    assert not scene.lists  # (export has not run)
    tcfg = TexturesConfig(enabled=True, texture=texture, color_format="argb")
    out, rec = tstage.stage(scene, tcfg)
    out.validate()
    assert rec.details["textures"], rec.warnings
    assert out.face_albedo is not None and np.isfinite(out.face_albedo).all()
    assert out.face_albedo.min() >= 0 and out.face_albedo.max() <= 1
    for t in rec.details["textures"]:
        for e in ("list", "textimage", "costume"):
            assert t["encodings"][e]["written"] == "written", (t["name"], e)
            assert t["encodings"][e]["project_json_bytes"] > 0
        assert t["encodings"]["costume"]["asset_bytes"] < ASSET_LIMIT
        assert max(t["size"]) <= 128
    assert len(rec.details["size_table"]) == 3 * len(rec.details["textures"])
    # export writes it all into a valid project
    ex, _ = export_stage(out, config_mod.ExportConfig(sprite3=False))
    files = ex.artefacts.outputs
    blob = next(v for k, v in files.items() if k.endswith(".sb3"))
    p = tmp_path / "m.sb3"
    p.write_bytes(blob)
    project, assets = sb3.load_project(p)
    assert sb3.validate_project(project, assets) == []
    names = {v[0] for v in project["targets"][0]["lists"].values()}
    for t in rec.details["textures"]:
        assert {f"tex {t['name']}", f"tex {t['name']} size", f"tex {t['name']} textimage"} <= names
    assert "tri colors" in names
    if name == "alpha_blend_mode_test":  # cut-out / blended textures: alpha survives
        assert (out.face_albedo[:, 3] < 0.99).any()
        assert any((np.asarray(out.lists[f"tex {t['name']}"].values) >> 24 < 255).any()
                   for t in rec.details["textures"])


@pytest.mark.corpus
def test_texture_costumes_reach_the_projects_and_assets(tmp_path):
    """The PNG costume of a texture is a file under assets/, a costume of a hidden "Textures"
    sprite in the .sb3 and of the .sprite3, byte-identical, and counted against the asset limit."""
    from bake import pipeline
    from bake.outputs import output
    from bake.scratch import sb3

    cfg = pipeline.load_config_for(corpus_path("duck_glb", "Duck.glb"), ["textures.enabled=true"])
    rep = output.finish(pipeline.run(cfg), tmp_path)
    pngs = sorted((tmp_path / "assets").glob("*.png"))
    assert len(pngs) == 1
    png = pngs[0].read_bytes()
    project, assets = sb3.load_project(tmp_path / "Duck.sb3")
    assert sb3.validate_project(project, assets) == []
    tex = [t for t in project["targets"] if t["name"] == "Textures"][0]
    assert tex["visible"] is False and tex["costumes"][0]["bitmapResolution"] == 2
    assert assets[tex["costumes"][0]["md5ext"]] == png
    entries = sb3.read_archive(tmp_path / "Duck.sprite3")
    sprite = __import__("json").loads(entries.pop("sprite.json"))
    assert sb3.validate_sprite(sprite, entries) == []
    assert any(entries.get(c["md5ext"]) == png for c in sprite["costumes"])
    names = [lim["name"] for lim in rep["limits"]]
    assert any(n.startswith("asset assets/") for n in names) and any("largest in the .sb3" in n for n in names)
