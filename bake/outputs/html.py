"""``report.html``: the bake as an author would rather look at it than read it.

Built from the output folder alone (``report.json``, ``lists.json``, the written .sb3 and any
``sweeps/*.json``), so ``bake report OUT_DIR`` re-renders it without baking and every picture
shows what Scratch will load: previews rendered from the rounded lists in the painter's order
of the BSP walk next to a z-buffer render and their difference, textures and the lightmap
decoded back from each encoding, a bar per Scratch limit, the stage table with effects run and
skipped, and the sweep tables and plots. One self-contained file: images are embedded as PNG (the sweep plots as SVG)
data URIs, no script, no network -- except under ``bake watch`` (``write(..., live=True)``), which
adds a few lines of script that reload the page when the watch writes a new one (see
:func:`live_script`).

    html_text, info = build(out_dir)       # info: what each image is, for tests and the CLI
    write(out_dir)                         # out_dir/report.html (atomic)
"""

from __future__ import annotations

import base64
import inspect
import html
import io
import json
import re
from pathlib import Path
from typing import Any

import numpy as np

from ..errors import InputError
from ..scratch.limits import fmt_bytes
from .report import cache_note, fmt_unit
from ..files import write_atomic
from .. import stages as registry

HTML_NAME = "report.html"
SWEEP_DIR = "sweeps"


def _esc(x: Any) -> str:
    return html.escape(str(x), quote=True)


def png_data_uri(img: np.ndarray, scale: int = 1) -> str:
    from PIL import Image

    a = np.asarray(img, np.uint8)
    if scale > 1:
        a = a.repeat(scale, 0).repeat(scale, 1)
    buf = io.BytesIO()
    Image.fromarray(a).save(buf, format="PNG", optimize=False)
    return "data:image/png;base64," + base64.b64encode(buf.getvalue()).decode("ascii")


def _bytes_uri(data: bytes, mime: str = "image/png") -> str:
    return f"data:{mime};base64," + base64.b64encode(data).decode("ascii")


def _fmt(v: Any) -> str:
    if isinstance(v, bool):
        return "yes" if v else "no"
    if isinstance(v, int):
        return f"{v:,}"
    if isinstance(v, float):
        return f"{v:.4g}"
    if isinstance(v, dict):
        return ", ".join(f"{k} {_fmt(x)}" for k, x in v.items())
    return str(v)


def bar_class(fraction: float) -> str:
    """Colour of a limit bar: ok below 50 %, watch to 80 %, near to 100 %, over above."""
    return "ok" if fraction < 0.5 else "watch" if fraction < 0.8 else "near" if fraction <= 1.0 else "over"


# --------------------------------------------------------------------------- reading the output folder
def _read(out_dir: Path, rel: str, files: dict[str, bytes] | None) -> bytes | None:
    """``out_dir/rel`` as the bake being written will leave it: from ``files`` (what is about to be
    committed) when it is there, else from disk; None if neither has it."""
    if files is not None and rel in files:
        return files[rel]
    try:
        return (out_dir / rel).read_bytes()
    except (FileNotFoundError, IsADirectoryError, NotADirectoryError):
        return None


def _load_json(out_dir: Path, rel: str, files: dict[str, bytes] | None = None) -> Any:
    path = out_dir / rel
    data = _read(out_dir, rel, files)
    if data is None:
        raise InputError("not found: is this a bake output folder? (bake run writes report.json and lists.json)",
                         path=path)
    try:
        return json.loads(data.decode("utf-8"))
    except (UnicodeDecodeError, json.JSONDecodeError) as e:
        raise InputError(f"cannot be read as JSON: {e}", path=path) from None


def _sb3_costumes(out_dir: Path, report: dict, files: dict[str, bytes] | None = None) -> dict[str, bytes]:
    """Costume name -> image bytes from the .sb3 this bake wrote (if any)."""
    from ..scratch.sb3 import read_archive

    sb3s = sorted(k for k, v in report.get("outputs", {}).items() if k.endswith(".sb3") and v != "removed")
    out: dict[str, bytes] = {}
    for name in sb3s:
        data = _read(out_dir, name, files)
        if data is None:
            continue
        entries = read_archive(data)
        try:
            project = json.loads(entries.get("project.json", b"{}"))
        except json.JSONDecodeError:
            continue
        for target in project.get("targets", []):
            for c in target.get("costumes", []):
                data = entries.get(c.get("md5ext") or f"{c.get('assetId')}.{c.get('dataFormat')}")
                if data is not None and c.get("name") not in out:
                    out[c["name"]] = data
        break
    return out


def _pattern(template: str) -> re.Pattern:
    return re.compile("^" + re.escape(template).replace(re.escape("{material}"), "(.+)") + "$")


def decoded_textures(lists: dict[str, list], report: dict, costumes: dict[str, bytes]) -> list[dict]:
    """Every texture the bake wrote, decoded back from each encoding: [{name, width, height,
    images: {encoding: (H, W, 4) uint8}, agree: bool}]."""
    from PIL import Image

    from ..scratch import colors, textimage

    tc = report.get("config", {}).get("textures", {})
    size_re = _pattern(tc.get("size_list_name", "tex {material} size"))
    out = []
    for size_name in sorted(lists):
        m = size_re.match(size_name)
        if not m or len(lists[size_name]) != 2:
            continue
        key = m.group(1)
        fmt = {"material": key}
        w, h = (int(float(v)) for v in lists[size_name])
        images: dict[str, np.ndarray] = {}
        name = tc.get("list_name", "tex {material}").format(**fmt)
        if name in lists and len(lists[name]) == w * h:
            images["colour list"] = colors.list_to_image(lists[name], w, h, tc.get("first_row", "bottom"))
        tname = tc.get("textimage_list_name", "tex {material} textimage").format(**fmt)
        if tname in lists and lists[tname]:
            images["TextImage"] = textimage.decode(str(lists[tname][0]), channels=4)
        cname = tc.get("costume_name", "tex {material}").format(**fmt)
        if cname in costumes:
            im = Image.open(io.BytesIO(costumes[cname])).convert("RGBA")
            images["costume"] = np.asarray(im)
        if not images:
            continue
        ref = next(iter(images.values()))
        agree = all(v.shape == ref.shape and np.array_equal(v[..., :3], ref[..., :3]) for v in images.values())
        out.append({"name": key, "width": w, "height": h, "images": images, "agree": agree})
    return out


# --------------------------------------------------------------------------- sections
CSS = """
body{font:14px/1.45 system-ui,-apple-system,Segoe UI,Roboto,sans-serif;margin:24px auto;max-width:1120px;
color:#1d2330;padding:0 16px}
h1{font-size:22px;margin:0 0 4px}h2{font-size:17px;margin:28px 0 8px;border-bottom:1px solid #dde;padding-bottom:4px}
.sub{color:#5a6475}table{border-collapse:collapse;width:100%;margin:6px 0}
td,th{border-bottom:1px solid #e8eaf0;padding:4px 6px;text-align:left;vertical-align:top;font-size:13px}
th{background:#f5f6fa}td.n{text-align:right;font-variant-numeric:tabular-nums;white-space:nowrap}
.bar{position:relative;background:#eef0f5;height:14px;border-radius:3px;min-width:160px;overflow:hidden}
.bar span{position:absolute;left:0;top:0;bottom:0;border-radius:3px}
.ok span{background:#3aa55d}.watch span{background:#d9b100}.near span{background:#e67e22}.over span{background:#d62d20}
.views{display:grid;grid-template-columns:repeat(3,1fr);gap:8px}figure{margin:0}
figure img{width:100%;border:1px solid #dde;image-rendering:auto}figcaption{font-size:12px;color:#5a6475}
.tex img{image-rendering:pixelated;border:1px solid #dde;max-width:256px;min-width:96px}
.tex{display:flex;gap:12px;flex-wrap:wrap;align-items:flex-end}.bad{color:#d62d20;font-weight:600}
.good{color:#2b7d45;font-weight:600}.skip{color:#8a93a3}code{background:#f2f3f7;padding:0 3px;border-radius:3px}
"""


def _limits_section(report: dict) -> str:
    rows = []
    for lim in report.get("limits", []):
        frac = lim["value"] / lim["limit"] if lim["limit"] else 0.0
        cls = bar_class(frac)
        width = min(frac, 1.0) * 100
        shown = fmt_bytes(lim["value"]) if "bytes" in lim["name"] else f"{lim['value']:,}"
        limit = fmt_bytes(lim["limit"]) if "bytes" in lim["name"] else f"{lim['limit']:,}"
        rows.append(f"<tr><td>{_esc(lim['name'])}</td><td class=n>{shown}</td><td class=n>{limit}</td>"
                    f"<td><div class='bar {cls}' title='{frac:.1%}'><span style='width:{width:.1f}%'></span></div>"
                    f"</td><td class=n>{frac:.1%}</td><td>{'ok' if lim['ok'] else '<b class=bad>EXCEEDED</b>'}"
                    f"</td></tr>")
    return ("<h2>Scratch limits</h2><p class=sub>Green below 50 %, yellow to 80 %, orange to 100 %, red over. "
            "Lists: vanilla <code>add to list</code> stops at 200,000 items (loading is not limited); "
            "project.json: 5 MiB upload limit; each asset under 10 MB.</p>"
            "<table><tr><th>check</th><th>value</th><th>limit</th><th style='width:30%'>used</th><th></th>"
            f"<th></th></tr>{''.join(rows)}</table>")


def _backdrop_words(rgb) -> str:
    h = "#{:02x}{:02x}{:02x}".format(*rgb)
    return "white" if h == "#ffffff" else f"{h}: the model's colours are too light to show on white"


def _views_section(views: list, mesh, bview=None) -> str:
    parts = [f"<h2>Previews</h2><p class=sub>Rendered from the written lists (rounded positions, encoded "
             f"colours: {_esc(mesh.colour_source)}) by scratch-bake's numpy rasterizer. Left: the painter's "
             f"order a Scratch engine would draw ({_esc(views[-1].stats['order']) if views else ''}); middle: "
             f"a depth-buffer render (the exact answer); right: where the painter shows another triangle in "
             f"a visibly different colour — <b class=bad>red</b>: wrong order; <b style='color:#e67e22'>"
             f"orange</b>: within a pixel of a triangle's edge; <b style='color:#b89600'>yellow</b>: the two "
             f"faces are coplanar to the bake (either order is right). The green flag's view is the "
             f"project's stage, in the reader sprite's order "
             f"({_esc(views[0].stats['order']) if views else ''}): colours flat, as the reader sprite fills them, "
             f"on its backdrop "
             f"({_backdrop_words(mesh.backdrop)}).</p>"]
    if bview is not None:
        j = bview.to_json()
        parts.append(f"<p class=sub>The green flag draws the <b>BVH view</b> "
                     f"(<code>export.green_flag = \"bvh\"</code>): "
                     f"one ray per cell of {j['cell']} × {j['cell']} stage pixels ({j['rays']:,} rays, "
                     f"{j['hit_cells']:,} hit), traced here in Python through the BVH lists as written, as the "
                     f"reader's <code>bvh view</code> traces them, each hit cell a pen dot of size "
                     f"{j['pen_size']:.2f} in the colour of the triangle hit ({_esc(j['colours'])}); the rays "
                     f"see either side of a triangle, so a closed model seen from outside shows its outside. "
                     f"Beside the green flag's raster below.</p>")
    for v in views:
        s = v.stats
        cls = "good" if s["wrong_pixels"] == 0 else "bad"
        extra = ""
        if bview is not None and v.name == "green flag":
            extra = (f"<figure><img alt='BVH view' src='{png_data_uri(bview.stage(mesh.backdrop))}'>"
                     f"<figcaption>BVH view (the green flag's)</figcaption></figure>")
        parts.append(
            f"<h3 style='font-size:14px;margin:14px 0 4px'>{_esc(v.name)}: <span class={cls}>"
            f"{s['wrong_pixels']:,} wrong pixels ({s['wrong_fraction']:.3%} of {s['covered_pixels']:,})"
            f"</span>, {s['edge_pixels']:,} on edges, {s['tie_pixels']:,} coplanar ties, {s['drawn']:,} triangles "
            f"drawn</h3><div class=views{' style=grid-template-columns:repeat(4,1fr)' if extra else ''}>"
            f"<figure><img alt='painter {_esc(v.name)}' src='{png_data_uri(v.painter)}'>"
            f"<figcaption>painter's order</figcaption></figure>"
            f"<figure><img alt='z-buffer {_esc(v.name)}' src='{png_data_uri(v.zbuffer)}'>"
            f"<figcaption>depth buffer</figcaption></figure>"
            f"<figure><img alt='difference {_esc(v.name)}' src='{png_data_uri(v.diff)}'>"
            f"<figcaption>difference</figcaption></figure>{extra}</div>")
    return "".join(parts)


def _textured_section(lists: dict, report: dict, mesh) -> str:
    """The green flag of a textured bake: the reader's textured filler, cell by cell
    (``bake.outputs.cells``), on the stage's backdrop."""
    from . import cells

    found = cells.green_flag(lists, report)
    if found is None:
        return ""
    pic, _ = found
    img = pic.image(background=mesh.backdrop)
    n = int((pic.colour >= 0).sum())
    return (f"<h3 style='font-size:14px;margin:14px 0 4px'>green flag, textured: {n:,} cells of {pic.cell} x "
            f"{pic.cell} pixels</h3><p class=sub>What the reader sprite's textured filler draws on the stage "
            f"(export.texel_size = {pic.cell}): each cell the nearest texel at its centre, perspective-correct, in the "
            f"painter's order (docs/formats-textures.md, \"Drawing a textured triangle\"); the player suite "
            f"compares TurboWarp's stage with this picture.</p><div class=views><figure><img alt='textured green flag' "
            f"src='{png_data_uri(img)}'><figcaption>textured filler, 480 x 360</figcaption></figure></div>")


def _textures_section(textures: list[dict]) -> str:
    if not textures:
        return ""
    parts = ["<h2>Textures and lightmap, as encoded</h2><p class=sub>Each image is decoded back from what "
             "was written (colour list, TextImage string, costume PNG), so this is what Scratch gets.</p>"]
    for t in textures:
        agree = ("<span class=good>all encodings decode to the same pixels</span>" if t["agree"] else
                 "<span class=bad>encodings differ</span>")
        scale = max(1, min(8, 256 // max(t["width"], t["height"], 1)))
        figs = "".join(f"<figure><img alt='{_esc(t['name'])} {_esc(k)}' src='{png_data_uri(img, scale)}'>"
                       f"<figcaption>{_esc(k)}</figcaption></figure>" for k, img in t["images"].items())
        parts.append(f"<h3 style='font-size:14px;margin:14px 0 4px'>{_esc(t['name'])} "
                     f"({t['width']}×{t['height']}): {agree}</h3><div class=tex>{figs}</div>")
    return "".join(parts)


def _faces(counts: dict) -> str:
    """Triangles, or polygons before triangulation (import and transform see polygons)."""
    t, p = counts.get("triangles", 0), counts.get("polygons", 0)
    return f"{p:,} polygons" if not t and p else f"{t:,}"


def _fmt_accuracy(key: str, v: Any) -> str:
    """Figures with a unit as the terminal and report.md show them (``report.fmt_unit``)."""
    unit = fmt_unit(key, v)
    return unit if unit is not None else _fmt(v)


def _stages_section(report: dict) -> str:
    total = max(report.get("seconds") or 0.0, 1e-9)
    rows = []
    for st in report.get("stages", []):
        frac = st["seconds"] / total
        cin, cout = _faces(st["counts_in"]), _faces(st["counts_out"])
        acc = "<br>".join(f"{_esc(k)} {_esc(_fmt_accuracy(k, v))}" for k, v in st.get("accuracy", {}).items())
        warn = "<br>".join(_esc(w) for w in st.get("warnings", []))
        note = cache_note(st)
        note = f"<br><span class=sub>{_esc(note)}</span>" if note else ""
        rows.append(f"<tr><td>{_esc(st['name'])}{note}</td><td class=n>{st['seconds']:.3f}</td>"
                    f"<td><div class='bar ok' style='min-width:80px'><span style='width:{min(frac, 1) * 100:.1f}%'>"
                    f"</span></div></td><td class=n>{cin}</td><td class=n>{cout}</td><td>{acc}</td>"
                    f"<td>{warn}</td></tr>")
    eff = []
    for e in report.get("effects", []):
        if e.get("reason") == "stage ran":
            continue
        extra = f" · {e['rays']:,} rays" if e.get("rays") else ""
        extra += f" · {e['seconds']:.3f} s" if isinstance(e.get("seconds"), (int, float)) else ""
        extra += f" · error {e['error']:.3g}" if isinstance(e.get("error"), (int, float)) else ""
        cls = "" if e.get("ran") else " class=skip"
        eff.append(f"<tr{cls}><td>{_esc(e['name'])}</td><td>{'ran' if e.get('ran') else 'skipped'}</td>"
                   f"<td>{_esc(e.get('reason', ''))}{_esc(extra)}</td></tr>")
    return (f"<h2>Stages</h2><table><tr><th>stage</th><th>seconds</th><th>share</th><th>faces in</th>"
            f"<th>out</th><th>accuracy</th><th>warnings</th></tr>{''.join(rows)}</table>"
            f"<h2>Effects and stages: run and skipped</h2><table><tr><th>effect</th><th></th><th>why / cost</th>"
            f"</tr>{''.join(eff)}</table>")


def _tie(report: dict, mesh) -> float:
    """The previews' on-plane tolerance (fraction of the diagonal): the BSP tree's own when it
    ran (report.json), else the same definition for the grid the export wrote."""
    from ..bsp.stage import tie_tolerance

    by_name = {x.get("name"): x for x in report.get("stages", [])}
    made = (by_name.get("bsp") or {}).get("details") or {}
    if "tolerance" in made:
        return float(made["tolerance"])
    decimals = (((by_name.get("export") or {}).get("details") or {}).get("positions") or {}).get("decimals")
    size = float(np.linalg.norm(mesh.verts.max(0) - mesh.verts.min(0))) if mesh is not None and len(mesh.verts) else 1.0
    epsilon = float(report.get("config", {}).get("bsp", {}).get("epsilon", 1e-6))
    return tie_tolerance(epsilon, None if decimals is None else int(decimals), size or 1.0)


def _shown_width(b64: str) -> int:
    """The width to show a stage's base64 PNG at: 3 screen pixels per pixel for a small one, its
    own size for a wide one (a cube map's six faces side by side), so it fits the page."""
    w = int.from_bytes(base64.b64decode(b64[:32])[16:20], "big")  # the IHDR chunk's width
    return 3 * w if w <= 200 else w


def _stage_sections(report: dict) -> list[str]:
    """The sections the stages contribute (``StageSpec.report``: plain rows, rendered here), in
    the order of the stages."""
    out = []
    by_name = {x.get("name"): x for x in report.get("stages", [])}
    for spec in registry.STAGES:
        if spec.report is None or spec.name not in by_name:
            continue
        fn = spec.load_report()
        # a section function takes its stage's entry, and the whole report if it has a second parameter
        two = len(inspect.signature(fn).parameters) >= 2
        sec = fn(by_name[spec.name], report) if two else fn(by_name[spec.name])
        if sec is None:
            continue
        body = "".join(f"<tr><td>{_esc(k)}</td><td>{_esc(v)}</td></tr>" for k, v in sec.rows)
        html_ = f"<h2>{_esc(sec.title)}</h2>" + (f"<table>{body}</table>" if body else "")
        if sec.table:
            num = sec.numeric + (False,) * (len(sec.head) - len(sec.numeric))
            head = "".join(f"<th>{_esc(c)}</th>" for c in sec.head)
            rows = "".join("<tr>" + "".join(f"<td class=n>{_esc(c)}</td>" if n else f"<td>{_esc(c)}</td>"
                                            for c, n in zip(row, num)) + "</tr>" for row in sec.table)
            html_ += f"<p class=sub>{_esc(sec.note)}</p><table><tr>{head}</tr>{rows}</table>"
        if sec.images:
            figs = "".join(f"<figure><img alt='{_esc(c)}' style='image-rendering:pixelated;width:{_shown_width(b)}px' "
                           f"src='data:image/png;base64,{b}'><figcaption>{_esc(c)}</figcaption></figure>"
                           for c, b in sec.images)
            html_ += f"<div class=views>{figs}</div>"
        out.append(html_)
    return out


def _lists_section(report: dict) -> str:
    lists = report.get("lists", {})
    total = max(sum(v["bytes"] for v in lists.values()), 1)
    rows = []
    for name, v in sorted(lists.items(), key=lambda kv: -kv[1]["bytes"]):
        frac = v["bytes"] / total
        rows.append(f"<tr><td>{_esc(name)}</td><td class=n>{v['items']:,}</td><td class=n>{v['stride'] or 'var'}"
                    f"</td><td class=n>{fmt_bytes(v['bytes'])}</td><td><div class='bar ok'><span style='width:"
                    f"{frac * 100:.1f}%'></span></div></td><td class=sub>{_esc(v.get('doc', ''))}</td></tr>")
    return (f"<h2>Lists: where project.json's bytes go</h2><table><tr><th>list</th><th>items</th><th>stride</th>"
            f"<th>bytes</th><th style='width:20%'>share of list bytes</th><th>what</th></tr>{''.join(rows)}</table>")


def load_sweeps(out_dir: Path) -> list[dict]:
    folder = out_dir / SWEEP_DIR
    out = []
    if folder.is_dir():
        for j in sorted(folder.glob("*.json")):
            try:
                table = json.loads(j.read_text(encoding="utf-8"))
            except (OSError, UnicodeDecodeError, json.JSONDecodeError):
                continue
            if isinstance(table, dict) and "rows" in table and "key" in table:
                # the plot: SVG (a PNG from a sweep written before the plot was SVG)
                svg, png = j.with_suffix(".svg"), j.with_suffix(".png")
                plot = (svg.read_bytes(), "image/svg+xml") if svg.is_file() else \
                    (png.read_bytes(), "image/png") if png.is_file() else None
                out.append({"table": table, "plot": plot, "file": j.name})
    return out


def sweep_hint(report: dict) -> str:
    """A ``bake sweep`` command that works for this bake, run in its output folder: the bake's own
    config or model (absolute paths), a key of a stage that ran (with values around the one used),
    and ``--out .`` (so the page does not depend on where the folder is)."""
    import shlex

    cfg = report.get("config", {})
    ran = {s.get("name") for s in report.get("stages", [])}
    inp = report.get("input", {})
    target = inp.get("config") or inp.get("path") or "MODEL"
    from_config = bool(inp.get("config"))
    sets: list[str] = []

    def around(v: float, whole: bool) -> str:
        vals = [v / 4, v / 2, v] + ([v * 2] if not whole or v * 2 <= 1e9 else [])
        if not whole:
            vals = [x for x in vals if x <= 1.0] if v <= 1.0 else vals
            return ",".join(f"{x:.3g}" for x in vals)
        return ",".join(str(max(1, int(round(x)))) for x in dict.fromkeys(vals))

    simp = cfg.get("mesh", {}).get("simplify", {})
    light = cfg.get("lighting", {})
    if "simplify" in ran and simp.get("target_triangles", 0) > 0:
        vary = f"mesh.simplify.target_triangles={around(simp['target_triangles'], True)}"
    elif "simplify" in ran and simp.get("target_ratio", 0) > 0:
        vary = f"mesh.simplify.target_ratio={around(simp['target_ratio'], False)}"
    elif "simplify" in ran and simp.get("max_error", 0) > 0:
        vary = f"mesh.simplify.max_error={around(simp['max_error'], False)}"
    elif "lighting" in ran and light.get("ao", {}).get("enabled"):
        vary = "lighting.ao.samples=16,64,256"
    elif "lighting" in ran and light.get("lights"):
        vary = "lighting.shadows.samples=1,4,16,64"
    elif "bsp" in ran:
        vary = "bsp.candidates=4,16,64"
    elif "bvh" in ran:
        vary = "bvh.leaf_size=1,2,4,8"
    else:
        vary = "export.precision=2,3,4,5"
    if not from_config:  # a model baked with --set: switch the swept stage on again
        stage_switch = {"mesh.simplify.": ["mesh.simplify.enabled=true"],
                        "lighting.ao.": ["lighting.enabled=true", "lighting.ao.enabled=true"],
                        "lighting.": ["lighting.enabled=true"], "bsp.": ["bsp.enabled=true"],
                        "bvh.": ["bvh.enabled=true"]}
        for prefix, sw in stage_switch.items():
            if vary.startswith(prefix):
                sets = sw
                break
    parts = ["bake", "sweep", str(target)] + [x for s in sets for x in ("--set", s)] + ["--vary", vary,
                                                                                        "--out", "."]
    return " ".join(shlex.quote(p) for p in parts)


def _sweeps_section(sweeps: list[dict], report: dict | None = None) -> str:
    if not sweeps:
        cmd = sweep_hint(report or {})
        return ("<h2>Accuracy against time</h2><p class=sub>No sweep yet. In this folder run for example "
                f"<code>{_esc(cmd)}</code> (any numeric key of a stage that runs: <code>bake keys</code>) "
                "and the table and plot appear here.</p>")
    parts = ["<h2>Accuracy against time</h2>"]
    for sw in sweeps:
        t = sw["table"]
        metric = t.get("error_metric", "rmse")
        head = "<tr><th>value</th><th>stage s</th><th>total s</th><th>error</th><th>image error</th><th>bytes</th>" \
               "<th>triangles</th></tr>"
        rows = []
        for r in t["rows"]:
            err = r.get("error", r.get("rmse"))
            rows.append(f"<tr><td class=n>{_esc(r['value'])}{' (reference)' if r.get('reference') else ''}</td>"
                        f"<td class=n>{_fmt(r.get('seconds'))}</td><td class=n>{_fmt(r.get('total_seconds'))}</td>"
                        f"<td class=n>{_fmt(err)}</td><td class=n>{_fmt(r.get('image_rmse'))}</td>"
                        f"<td class=n>{_fmt(r.get('bytes'))}</td><td class=n>{_fmt(r.get('triangles'))}</td></tr>")
        img = f"<img style='width:100%' alt='sweep {_esc(t['key'])}' src='{_bytes_uri(*sw['plot'])}'>" \
            if sw["plot"] else ""
        parts.append(f"<h3 style='font-size:14px'>{_esc(t['key'])} ({_esc(sw['file'])}; error: {_esc(metric)})"
                     f"</h3>{img}<table>{head}{''.join(rows)}</table>")
    return "".join(parts)


# --------------------------------------------------------------------------- the page
def build(out_dir: Path, *, width: int = 320, height: int = 240,
          files: dict[str, bytes] | None = None, memo: Any = None) -> tuple[str, dict[str, Any]]:
    """The report page for a finished bake in ``out_dir`` and facts about what it shows.
    ``files`` (relative path -> bytes): a bake's outputs not yet on disk, read instead of the
    folder's (``bake run`` renders the page before it commits anything). ``memo``: the stage
    cache's memos, which keep the previews' geometry (``preview.render_view``)."""
    from . import preview

    out_dir = Path(out_dir)
    report = _load_json(out_dir, "report.json", files)
    cfg = report.get("config", {})
    ex = cfg.get("export", {})
    json_name = ex.get("json_name", "lists.json")
    has_json = json_name in files if files is not None else (out_dir / json_name).is_file()
    if not has_json and ex.get("enabled", True) and ex.get("json", True) and report.get("lists"):
        raise InputError(f"{json_name} is missing, though report.json says the bake wrote it (bake the model again)",
                         path=out_dir / json_name)
    lists: dict = {}
    if has_json:
        doc = _load_json(out_dir, json_name, files)
        lists = doc.get("lists") if isinstance(doc, dict) else None
        gone = sorted(set(report.get("lists", {})) - set(lists)) if isinstance(lists, dict) else None
        if gone is None or gone:
            raise InputError("does not hold the lists report.json says the bake wrote"
                             + (f" (missing: {', '.join(repr(g) for g in gone[:5])})" if gone else "")
                             + "; bake the model again", path=out_dir / json_name)
    costumes = _sb3_costumes(out_dir, report, files)
    textures = decoded_textures(lists, report, costumes)
    lightmap = next((t for t in textures if t["name"] == "lightmap"), None)
    lm_img = None
    if lightmap is not None:
        lm_img = next(iter(lightmap["images"].values()))[..., :3].astype(np.float64) / 255.0
    mesh = preview.mesh_from_lists(lists, report, lightmap=lm_img)
    tie = _tie(report, mesh)
    views = preview.render_views(mesh, width, height, tie, memo=memo) if mesh is not None and len(mesh.tris) else []
    bview = None
    if views:  # the green flag's BVH view (export.green_flag = "bvh"), as the reader traces it
        from .bvh_view import view_from_report

        bview = view_from_report(lists, report)
    sweeps = load_sweeps(out_dir)
    s = report.get("scene", {})
    title = Path(report.get("input", {}).get("path") or "bake").name
    pj = next((lim for lim in report.get("limits", []) if lim["name"].startswith("project.json")), None)
    pj_line = (f" · project.json {fmt_bytes(pj['value'])} of 5 MiB ({pj['value'] / pj['limit']:.1%})"
               if pj else "")
    bad = [lim for lim in report.get("limits", []) if not lim["ok"]]
    head = (f"<h1>{_esc(title)}</h1><p class=sub>scratch-bake {_esc(report.get('tool', {}).get('version', ''))} · "
            f"{report.get('seconds', 0):.2f} s · {s.get('triangles', 0):,} triangles, {s.get('vertices', 0):,} "
            f"vertices, {s.get('materials', 0):,} materials{pj_line}"
            + (f" · <b class=bad>{len(bad)} limit(s) exceeded</b>" if bad else " · <b class=good>within every limit"
                                                                               "</b>") + "</p>")
    body = [head, _limits_section(report)]
    if views:
        body.append(_views_section(views, mesh, bview))
        body.append(_textured_section(lists, report, mesh))
    else:
        why = ("the export stage was off (export.enabled = false)" if not ex.get("enabled", True) else
               f"{json_name} was not written (export.json = false)" if not has_json else
               "the bake wrote no vertex and triangle lists")
        body.append(f"<h2>Previews</h2><p class=sub>No previews: {_esc(why)}.</p>")
    body += [_textures_section(textures), _stages_section(report), *_stage_sections(report),
             _lists_section(report),
             _sweeps_section(sweeps, report)]
    page = (f"<!doctype html><html lang=en><head><meta charset=utf-8><title>Bake report: {_esc(title)}</title>"
            f"<meta name=viewport content='width=device-width,initial-scale=1'><style>{CSS}</style></head>"
            f"<body>{''.join(body)}<p class=sub style='margin-top:32px'>report.json has every figure on this page; "
            "re-render with <code>bake report FOLDER</code>.</p></body></html>\n")
    info = {"views": [{"name": v.name, **v.stats} for v in views],
            "bvh_view": bview.to_json() if bview is not None else None,
            "textures": [{"name": t["name"], "encodings": list(t["images"]), "agree": t["agree"]} for t in textures],
            "sweeps": [sw["file"] for sw in sweeps], "images": page.count("<img ")}
    return page, info


LIVE_NAME = "report-live.js"
LIVE_POLL_MS = 300


def live_script(stamp: str) -> str:
    """What ``bake watch`` adds to report.html so that an open page reloads itself after a bake.

    No server: every 0.3 s the page adds a ``<script src="report-live.js?<time>">`` element (a
    browser loads scripts from ``file://`` pages, which it refuses to ``fetch``; the query defeats
    its cache). The watch rewrites report-live.js after each report.html with a call naming the
    new page's stamp (a hash of the page); a page whose own stamp differs reloads itself, so it
    shows the new report (Chromium keeps the scroll position: tests/test_watch.py). Without the file (the watch
    ended) the element fails to load and nothing happens."""
    return ("<script>/* bake watch: reload when a new report is written */(function(){var s='%s';"
            "window.bakeReportStamp=function(t){if(t!==s){location.reload();}};"
            "setInterval(function(){var e=document.createElement('script');e.src='%s?'+Date.now();"
            "e.onload=e.onerror=function(){e.remove();};document.head.appendChild(e);},%d);})();</script>"
            % (stamp, LIVE_NAME, LIVE_POLL_MS))


def make_live(page: str) -> tuple[str, str]:
    """The page with :func:`live_script` in it, and its stamp (a hash of the page without it)."""
    import hashlib

    stamp = hashlib.sha256(page.encode("utf-8")).hexdigest()[:16]
    return page.replace("</body>", live_script(stamp) + "</body>", 1), stamp


def write_live_stamp(out_dir: Path, stamp: str) -> None:
    """``report-live.js`` naming the page of ``stamp``: written after that page is in place, so an
    open browser reloads only to a complete page."""
    write_atomic(Path(out_dir) / LIVE_NAME, f"window.bakeReportStamp&&window.bakeReportStamp('{stamp}');\n"
                 .encode("utf-8"))


def write(out_dir: Path, *, live: bool = False, **kw) -> dict[str, Any]:
    """Write ``out_dir/report.html`` atomically; returns :func:`build`'s info. ``live``: with the
    reload script of :func:`live_script`, then ``report-live.js`` naming this page."""
    page, info = build(out_dir, **kw)
    if live:
        page, info["live_stamp"] = make_live(page)
    write_atomic(Path(out_dir) / HTML_NAME, page.encode("utf-8"))
    if live:
        write_live_stamp(out_dir, info["live_stamp"])
    return info
