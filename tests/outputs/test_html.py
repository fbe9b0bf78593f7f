"""report.html: previews from the written lists against an independent depth-buffer render,
every image decodes, limits as bars, textures decoded back, `bake report` re-renders without
baking, and the page opens in headless Chromium (installed by this module when it can be)."""

from __future__ import annotations

import base64
import io
import json
import shutil
import subprocess
import sys
from html.parser import HTMLParser
from pathlib import Path

import numpy as np
import pytest
from PIL import Image

from bake import cli
from bake import config as config_mod
from bake.outputs import html as html_mod
from bake.outputs import preview

COLORS = {"floor": (0.8, 0.8, 0.75), "red": (0.9, 0.1, 0.1), "blue": (0.1, 0.2, 0.9), "magenta": (1.0, 0.0, 1.0)}


def _box(lo, hi):
    import trimesh

    m = trimesh.creation.box(bounds=[lo, hi])
    return np.asarray(m.vertices, float), np.asarray(m.faces)


def write_scene(folder: Path, name: str = "boxes") -> Path:
    """A floor of two big triangles and three boxes, two of them interpenetrating: the case
    where sorting by centroid draws the wrong face on top and a BSP tree has to split."""
    parts = [("floor", np.array([[-3, 0, -3], [3, 0, -3], [3, 0, 3], [-3, 0, 3]], float),
              np.array([[0, 2, 1], [0, 3, 2]]))]
    for mat, lo, hi in (("red", (-1.5, 0, -1.0), (-0.3, 1.2, 0.2)), ("blue", (-0.8, 0, -0.6), (0.6, 0.7, 1.4)),
                        ("magenta", (1.0, 0, -2.5), (2.2, 2.0, -1.3))):
        v, f = _box(lo, hi)
        parts.append((mat, v, f))
    lines, mtl, base = [f"mtllib {name}.mtl"], [], 1
    for mat, v, f in parts:
        lines += [f"v {x:.6f} {y:.6f} {z:.6f}" for x, y, z in v]
        lines.append(f"usemtl {mat}")
        lines += ["f " + " ".join(str(base + int(i)) for i in tri) for tri in f]
        base += len(v)
    for mat, c in COLORS.items():
        mtl += [f"newmtl {mat}", "Kd " + " ".join(f"{x:.4f}" for x in c)]
    folder.mkdir(parents=True, exist_ok=True)
    (folder / f"{name}.mtl").write_text("\n".join(mtl) + "\n")
    path = folder / f"{name}.obj"
    path.write_text("\n".join(lines) + "\n")
    return path


def bake(model: Path, out: Path, *sets: str) -> int:
    args = ["run", str(model), "--out", str(out), "--quiet"]
    for s in sets:
        args += ["--set", s]
    return cli.main(args)


class _Imgs(HTMLParser):
    def __init__(self):
        super().__init__()
        self.imgs: list[dict] = []
        self.links: list[str] = []

    def handle_starttag(self, tag, attrs):
        a = dict(attrs)
        if tag == "img":
            self.imgs.append(a)
        for k in ("href", "src"):
            if k in a and not str(a[k]).startswith("data:"):
                self.links.append(a[k])


def images_of(page: str) -> list[tuple[str, np.ndarray]]:
    """(alt, RGB array) of every <img>: each must be an embedded PNG that decodes."""
    p = _Imgs()
    p.feed(page)
    assert not p.links, f"the page refers to files or the network: {p.links[:3]}"
    out = []
    for a in p.imgs:
        src = a["src"]
        assert src.startswith("data:image/png;base64,"), src[:40]
        im = Image.open(io.BytesIO(base64.b64decode(src.split(",", 1)[1])))
        im.load()
        out.append((a.get("alt", ""), np.asarray(im.convert("RGB"))))
    return out


@pytest.fixture(scope="module")
def baked(tmp_path_factory):
    root = tmp_path_factory.mktemp("html")
    model = write_scene(root / "model")
    out = root / "out"
    assert bake(model, out, "bsp.enabled=true") == 0
    return model, out


def reference_render(model: Path, sets: list[str], cam, light: bool = True):
    """The independent reference: the in-memory scene (unrounded float64 positions, colours
    before encoding) through the z-buffer, no lists and no BSP involved. ``light=False``: flat
    material colours, as the reader sprite draws them (the "green flag" view)."""
    from bake import pipeline
    from bake.render import render_scene

    cfg = config_mod.load(None, [f"input.path={model}", *sets])
    sc = pipeline.run(cfg).scene
    tri = sc.triangle_vertices()
    # no baked light: the preview's headlight, 0.35 + 0.65 |cos(normal, view direction)|
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    d = np.subtract(cam.position, cam.look_at)
    shade = 0.35 + 0.65 * np.abs(n @ d) / (np.linalg.norm(n, axis=1) * np.linalg.norm(d))
    if not light:
        shade = np.ones(len(tri))
    return render_scene(sc, cam, mode="zbuffer", colors=sc.triangle_albedo()[:, :3] * shade[:, None])


def test_report_html_written_self_contained_and_every_image_decodes(baked):
    _, out = baked
    page = (out / "report.html").read_text(encoding="utf-8")
    imgs = images_of(page)
    previews = [a for a, _ in imgs if a.startswith(("painter", "z-buffer", "difference"))]
    assert len(previews) == 12  # four views (the green flag's first) x (painter, depth buffer, difference)
    assert all(im.shape == (240, 320, 3) for a, im in imgs if a in previews)
    rep = json.loads((out / "report.json").read_text())
    for lim in rep["limits"]:  # a bar per limit, its width the fraction used
        frac = lim["value"] / lim["limit"]
        assert f"title='{frac:.1%}'" in page
        assert f"bar {html_mod.bar_class(frac)}" in page
    for st in rep["stages"]:
        assert f"<td>{st['name']}</td>" in page
    for e in rep["effects"]:
        if not e["ran"]:
            assert html_mod._esc(e["reason"]) in page  # skipped stages say why
    assert "http://" not in page and "https://" not in page and "<script" not in page


def test_the_bsp_table_says_which_triangles_pass_through_each_other(baked):
    """The red and blue boxes interpenetrate: the BSP's record counts the crossing pairs, and
    report.html's BSP table says so; the floor and the magenta box cross nothing."""
    _, out = baked
    rep = json.loads((out / "report.json").read_text())
    cr = next(st for st in rep["stages"] if st["name"] == "bsp")["details"]["crossing"]
    assert cr["pairs"] > 0 and cr["parts"] == 2 and cr["pairs_within_one_part"] == 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert f"{cr['pairs']:,} pairs of triangles cross ({cr['triangles']:,} triangles in 2 part(s))" in page


def test_stage_table_counts_faces_and_reads_distances_as_percent(baked):
    """Import and transform see polygons (no triangles yet): the table says so instead of 0;
    Hausdorff distances (fractions of the diagonal in report.json) read as a percentage."""
    _, out = baked
    rep = json.loads((out / "report.json").read_text())
    imp = next(st for st in rep["stages"] if st["name"] == "import")
    assert imp["counts_out"].get("triangles", 0) == 0 and imp["counts_out"]["polygons"] > 0
    page = (out / "report.html").read_text(encoding="utf-8")
    assert f"<td class=n>{imp['counts_out']['polygons']:,} polygons</td>" in page
    assert html_mod._fmt_accuracy("hausdorff_max", 0.003525) == "0.352% of the diagonal"
    # the BSP's inflation (out / in - 1) as a signed percentage everywhere (a user's review: the
    # terminal's "inflation=1.07" read like 7% for +107%)
    assert html_mod._fmt_accuracy("inflation", 0.5) == "+50.0% triangles"
    assert html_mod._fmt_accuracy("splits", 0.5) == "0.5"
    from bake.outputs import report as report_mod

    rep = {"scene": {"triangles": 5602, "vertices": 10, "materials": 1}, "input": {"path": "house.obj"},
           "seconds": 1.0, "lists": {}, "limits": [], "stages": [{"name": "bsp", "seconds": 0.5, "warnings": [],
                                                                 "accuracy": {"inflation": 1.0702}}]}
    assert "inflation=+107.0%" in report_mod.summary_lines(rep)[1]
    assert report_mod.fmt_accuracy("inflation", 1.0702) == "+107.0% triangles"  # report.md's stage table


def test_bar_colours_follow_how_close_a_limit_is():
    assert [html_mod.bar_class(f) for f in (0.0, 0.49, 0.5, 0.79, 0.8, 1.0, 1.01)] == \
        ["ok", "ok", "watch", "watch", "near", "near", "over"]


def test_previews_match_an_independent_depth_buffer_render(baked):
    """The painter's preview (lists read back, BSP walk) against the scene's own z-buffer render."""
    model, out = baked
    page = (out / "report.html").read_text(encoding="utf-8")
    imgs = dict(images_of(page))
    lists = json.loads((out / "lists.json").read_text())["lists"]
    rep = json.loads((out / "report.json").read_text())
    mesh = preview.mesh_from_lists(lists, rep)
    for name, cam in preview.cameras(mesh.verts, 320, 240):
        ref = reference_render(model, ["bsp.enabled=true"], cam, light=name != "green flag")
        ref8 = ref.to_uint8()
        for kind in ("painter", "z-buffer"):
            got = imgs[f"{kind} {name}"]
            diff = np.abs(got.astype(int) - ref8.astype(int)).max(2) > 2
            # only within a pixel of an edge may rounding of the written positions change a pixel
            inner = ref.edge > 1.5
            assert ref.covered.sum() > 3000
            assert not (diff & inner).any(), f"{kind} {name}: {(diff & inner).sum()} interior pixels differ"
            assert diff.mean() < 0.01
        d = imgs[f"difference {name}"]
        assert not (np.all(d == (220, 0, 0), axis=2)).any()  # no wrong-order pixel with a BSP tree


def test_painter_sort_without_bsp_shows_its_errors(tmp_path, baked):
    """Without a BSP tree the preview draws in centroid order, and the difference image marks
    the faces it gets wrong: the check can fail."""
    model, _ = baked
    out = tmp_path / "nobsp"
    assert bake(model, out) == 0
    lists = json.loads((out / "lists.json").read_text())["lists"]
    rep = json.loads((out / "report.json").read_text())
    views = preview.render_views(preview.mesh_from_lists(lists, rep))
    # the green flag draws as the reader sprite does (no BSP tree: the list's order); the
    # other views as a sorting engine would
    assert "list's order" in views[0].stats["order"] and views[0].name == "green flag"
    assert all("centroid" in v.stats["order"] for v in views[1:])
    wrong = sum(v.stats["wrong_pixels"] for v in views)
    assert wrong > 100
    for v in views:  # the red pixels are exactly where the painter and the depth buffer differ
        red = np.all(v.diff == (220, 0, 0), axis=2)
        assert red.sum() == v.stats["wrong_pixels"]
        assert (np.abs(v.painter.astype(int) - v.zbuffer.astype(int)).max(2)[red] > 2).all()
    page = (out / "report.html").read_text()
    assert "painter&#x27;s sort by centroid" in page or "painter's sort by centroid" in page


def test_bake_report_rerenders_without_baking(baked, tmp_path, capsys):
    _, out = baked
    copy = tmp_path / "copy"
    shutil.copytree(out, copy)
    before = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in copy.rglob("*") if p.is_file()
              and p.name != "report.html"}
    (copy / "report.html").unlink()
    assert cli.main(["report", str(copy)]) == 0
    text = capsys.readouterr().out
    assert "wrong pixels" in text and "report.html" in text
    page = (copy / "report.html").read_text()
    # the same page as the bake wrote: report.html depends only on the folder's files
    assert page == (out / "report.html").read_text()
    after = {p: (p.stat().st_mtime_ns, p.read_bytes()) for p in copy.rglob("*") if p.is_file()
             and p.name != "report.html"}
    assert after == before  # nothing else touched


def test_bake_report_bad_folder_is_a_one_line_error(tmp_path, capsys):
    assert cli.main(["report", str(tmp_path / "missing")]) == 3
    assert "not a folder" in capsys.readouterr().err
    assert cli.main(["report", str(tmp_path)]) == 3
    err = capsys.readouterr().err
    assert "report.json" in err and len(err.strip().splitlines()) == 1
    (tmp_path / "report.json").write_text("{not json")
    assert cli.main(["report", str(tmp_path)]) == 3
    assert "JSON" in capsys.readouterr().err


def test_report_html_can_be_switched_off(tmp_path, baked):
    model, _ = baked
    out = tmp_path / "o"
    assert bake(model, out, "report.html=false") == 0
    assert not (out / "report.html").exists() and (out / "report.json").exists()


def test_textures_are_decoded_back_from_every_encoding(tmp_path):
    """A textured quad: the colour list, the TextImage and the costume decode to the same pixels,
    and those are the source image (an 8x8 pattern needs no resampling)."""
    rng = np.random.default_rng(3)
    tex = rng.integers(0, 256, (8, 8, 3), dtype=np.uint8)
    folder = tmp_path / "m"
    folder.mkdir()
    Image.fromarray(tex).save(folder / "pattern.png")
    (folder / "q.mtl").write_text("newmtl pat\nKd 1 1 1\nmap_Kd pattern.png\n")
    (folder / "q.obj").write_text("mtllib q.mtl\nv 0 0 0\nv 1 0 0\nv 1 1 0\nv 0 1 0\n"
                                  "vt 0 0\nvt 1 0\nvt 1 1\nvt 0 1\nusemtl pat\nf 1/1 2/2 3/3 4/4\n")
    out = tmp_path / "o"
    assert bake(folder / "q.obj", out, "textures.enabled=true") == 0
    rep = json.loads((out / "report.json").read_text())
    lists = json.loads((out / "lists.json").read_text())["lists"]
    costumes = html_mod._sb3_costumes(out, rep)
    textures = html_mod.decoded_textures(lists, rep, costumes)
    assert len(textures) == 1
    t = textures[0]
    assert set(t["images"]) == {"colour list", "TextImage", "costume"} and t["agree"]
    for img in t["images"].values():
        np.testing.assert_array_equal(img[..., :3], tex)
    page = (out / "report.html").read_text()
    alts = [a for a, _ in images_of(page)]
    assert {"pat colour list", "pat TextImage", "pat costume"} <= set(alts)
    assert "all encodings decode to the same pixels" in page


# --------------------------------------------------------------------------- headless Chromium
def _chromium() -> str | None:
    """The chromium the player tests use (vm/turbowarp.py: on PATH or $CHROMIUM, else Debian's,
    installed as `make test` does)."""
    sys.path.insert(0, str(Path(__file__).resolve().parents[2] / "vm"))
    import turbowarp

    return turbowarp.chromium()


def screenshot(page: Path, png: Path, width: int = 1200, height: int = 2000) -> bool:
    exe = _chromium()
    if exe is None:
        return False
    flags = ["--headless", "--no-sandbox", "--disable-gpu", "--disable-quic", "--no-first-run",
             "--disable-background-networking", "--disable-component-update", "--disable-sync",
             "--hide-scrollbars", f"--user-data-dir={png.parent / 'chromium-profile'}",
             f"--window-size={width},{height}", f"--screenshot={png}", page.resolve().as_uri()]
    subprocess.run([exe, *flags], capture_output=True, timeout=120)
    return png.is_file()


def test_report_opens_in_headless_chromium_and_shows_the_previews(baked, tmp_path):
    _, out = baked
    png = tmp_path / "shot.png"
    if not screenshot(out / "report.html", png):
        pytest.skip("Chromium is not installed and could not be installed (apt-get as root); "
                    "the parse checks above cover the page")
    shot = np.asarray(Image.open(png).convert("RGB")).astype(int)
    # the magenta box appears in the previews as rendered by the browser: pure magenta lit by
    # the headlight, i.e. red == blue, green ~0, bright
    magenta = (np.abs(shot[..., 0] - shot[..., 2]) < 12) & (shot[..., 1] < 40) & (shot[..., 0] > 90)
    assert magenta.sum() > 2000, f"only {magenta.sum()} magenta pixels in the screenshot"
    assert (np.all(shot == (58, 165, 93), axis=2)).sum() > 20  # the green limit bars (as wide as the share used)


def test_lightmap_is_shown_decoded_and_lights_the_previews(baked, tmp_path):
    """With lighting.target = "lightmap" the page shows the atlas decoded from each encoding and
    the previews sample it; they agree with a per-triangle bake of the same light (a different
    estimator of the same irradiance) on average."""
    model, _ = baked
    light = ["lighting.enabled=true", "lighting.ao.enabled=true", "lighting.ao.samples=32", "bsp.enabled=false"]
    a, b = tmp_path / "lm", tmp_path / "tri"
    assert bake(model, a, *light, "textures.enabled=true", "textures.lightmap.enabled=true",
                "textures.lightmap.resolution=128", 'lighting.target="lightmap"') == 0
    assert bake(model, b, *light, "lighting.subdivide=true", "lighting.max_triangles=4000") == 0
    got = {}
    for out in (a, b):
        rep = json.loads((out / "report.json").read_text())
        lists = json.loads((out / "lists.json").read_text())["lists"]
        textures = html_mod.decoded_textures(lists, rep, html_mod._sb3_costumes(out, rep))
        lm = next((t for t in textures if t["name"] == "lightmap"), None)
        mesh = preview.mesh_from_lists(lists, rep, lightmap=None if lm is None else
                                       next(iter(lm["images"].values()))[..., :3] / 255.0)
        got[out.name] = (lm, mesh, [v.zbuffer for v in preview.render_views(mesh)])
    lm, mesh, imgs_lm = got["lm"]
    assert lm is not None and lm["agree"] and len(lm["images"]) == 3
    assert mesh.colour_source == "lightmap (bilinear)"
    page = (a / "report.html").read_text()
    assert {"lightmap colour list", "lightmap TextImage", "lightmap costume"} <= {x for x, _ in images_of(page)}
    _, mesh_b, imgs_tri = got["tri"]
    assert mesh_b.colour_source.startswith("'tri colors'")
    for x, y in zip(imgs_lm, imgs_tri):
        cov = (x != 255).any(2) & (y != 255).any(2)
        assert cov.mean() > 0.05
        diff = np.abs(x[cov].astype(float) - y[cov].astype(float)).mean() / 255
        assert diff < 0.06, diff
        assert np.abs(x[cov].astype(float)).std() > 5  # not a flat image: light varies


def test_without_lists_json_the_page_says_why_there_are_no_previews(baked, tmp_path):
    model, _ = baked
    out = tmp_path / "o"
    assert bake(model, out, "export.json=false") == 0
    page = (out / "report.html").read_text()
    assert "No previews: lists.json was not written" in page and not images_of(page)
