"""The size/limit report: ``report.json`` for scripts, ``report.md`` and a terminal summary for people.

``report.json`` shape (stable; documented in docs/formats.md; ``report_version`` bumps on breaking changes):

* ``report_version``, ``tool`` {name, version}
* ``input`` {path, format, files_read}
* ``scene`` {polygons, triangles, vertices, materials} after the last stage
* ``materials``: list of {name, color (sRGB RGBA 0..1), double_sided, texture} in list order
* ``stages``: list in run order of {name, seconds, counts_in, counts_out, accuracy, warnings, effects, details}
* ``lists``: name -> {items, stride, bytes, file, doc}; ``bytes`` is what the list adds to project.json
* ``limits``: list of {name, value, limit, ok, note}
* ``effects``: list of {name, ran, reason, ...}: every stage and effect that ran or was skipped, and why
* ``problems``: list of {stage, message}: what makes ``--strict`` fail besides a limit (e.g. a lit
  bake whose colours are all black); each is also among its stage's warnings
* ``outputs``: relative path -> "written" | "unchanged" | "removed"
* ``seconds``: wall time of the whole bake
* ``cache``: the stage cache's part (``where``, ``from_cache``: the stages loaded rather than run,
  ``stored``, ``warnings``), null without a cache; a stage from the cache has
  ``details.cache = {from_cache: true, computed_seconds}`` and ``seconds`` this bake spent on it
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from .. import __version__
from ..config import to_dict
from ..pipeline import BakeResult, counts
from ..scratch.limits import ASSET_LIMIT, LIST_ITEM_LIMIT, PROJECT_BASE_BYTES, PROJECT_JSON_LIMIT, fmt_bytes

REPORT_VERSION = 1


def build(result: BakeResult, outputs: dict[str, str] | None = None,
          assets: dict[str, int] | None = None) -> dict[str, Any]:
    scene = result.scene
    assets = dict(assets or {})
    info = scene.artefacts.list_info or {}
    lists = {name: {"items": v["items"], "stride": v["stride"], "bytes": v["project_json_bytes"],
                    "file": v.get("file"), "doc": v.get("doc", ""),
                    **({"plain_bytes": v["plain_bytes"], "packed": v["packed"]} if "packed" in v else {})}
             for name, v in info.items()}
    limits = []
    for name, v in lists.items():
        limits.append({"name": f"list '{name}' items", "value": v["items"], "limit": LIST_ITEM_LIMIT,
                       "ok": v["items"] <= LIST_ITEM_LIMIT,
                       "note": "packed: vanilla Scratch cannot rebuild more than 200,000 items at the green flag "
                               "(`add to list` stops there); TurboWarp can" if "packed" in v else
                               "vanilla `add to list` stops at 200,000 items; loading a longer list works"})
    export = next((r for r in result.records if r.name == "export"), None)
    real = export.details.get("project_json_bytes") if export else None
    if real is not None:
        pj, what = int(real), "project.json bytes (the written .sb3)"
    else:
        pj, what = PROJECT_BASE_BYTES + sum(v["bytes"] for v in lists.values()), "project.json bytes (estimated)"
    limits.append({"name": what, "value": pj, "limit": PROJECT_JSON_LIMIT,
                   "ok": pj <= PROJECT_JSON_LIMIT, "note": "upload limit on scratch.mit.edu"})
    if export is not None:  # the largest asset inside each written project
        into = export.details.get("into") or {}
        for where, sizes in (("the .sb3", export.details.get("sb3_assets", {})),
                             (into.get("file", ""), into.get("assets", {}))):
            if sizes:
                big = max(sizes, key=lambda k: (sizes[k], k))
                assets.setdefault(f"largest in {where} ({big}, of {len(sizes)})", sizes[big])
    for name, size in (assets or {}).items():
        limits.append({"name": f"asset {name} bytes", "value": size, "limit": ASSET_LIMIT,
                       "ok": size < ASSET_LIMIT, "note": "each asset must be under 10 MB"})
    effects: list[dict[str, Any]] = []
    for rec in result.records:
        cached = (rec.details.get("cache") or {}).get("from_cache")
        effects.append({"name": rec.name, "ran": True, "seconds": round(rec.seconds, 6),
                        "reason": f"from the stage cache (computed in {rec.details['cache']['computed_seconds']:.3f} s)"
                        if cached else "stage ran"})
        for e in rec.effects:
            effects.append({**e, "name": f"{rec.name}.{e.get('name', '?')}"})
    effects.extend(result.skipped)
    src = scene.source
    return {
        "report_version": REPORT_VERSION,
        "tool": {"name": "scratch-bake", "version": __version__},
        "input": {"path": str(src.path) if src.path else None, "format": src.format,
                  "files_read": [str(p) for p in src.files_read],
                  "config": str(result.config.source) if result.config.source else None},
        "scene": counts(scene),
        "materials": [{"name": m.name, "color": [round(float(c), 6) for c in m.color],
                       "double_sided": bool(m.double_sided),
                       "texture": str(m.texture) if m.texture is not None else m.texture_source}
                      for m in scene.materials],
        "stages": [r.to_json() for r in result.records],
        "lists": lists,
        "limits": limits,
        "effects": effects,
        "problems": [{"stage": r.name, "message": m, **({"failed": True} if m in r.failures else {})}
                     for r in result.records for m in r.problems],
        "outputs": dict(sorted((outputs or {}).items())),
        "seconds": round(result.seconds, 6),
        "config": to_dict(result.config),
        "cache": _cache_json(getattr(result, "cache", None)),
        # export.into: which blocks of the author's engine read each list (bake/scratch/engine.py)
        "engine": next((r.details.get("into", {}).get("engine") for r in result.records
                        if r.name == "export" and "engine" in r.details.get("into", {})), None),
    }


def _cache_json(info: dict[str, Any] | None) -> dict[str, Any] | None:
    if info is None:
        return None
    return {"where": info.get("where"), "from_cache": list(info.get("from_cache", [])),
            "stored": list(info.get("stored", [])), "warnings": list(info.get("warnings", [])),
            "load_seconds": round(float(info.get("load_seconds", 0.0)), 6),
            # results reused inside stages that ran (bake.cache.Memo: "bsp" = the tree)
            "memos_reused": list(info.get("memos_reused", []))}


def cache_note(stage: dict[str, Any]) -> str:
    """"from the cache (computed in 6.41 s)" for a stage the bake loaded, else ""."""
    c = (stage.get("details") or {}).get("cache") or {}
    return f"from the cache (computed in {c.get('computed_seconds', 0):.2f} s)" if c.get("from_cache") else ""


def to_json(report: dict[str, Any]) -> bytes:
    return (json.dumps(report, indent=2, ensure_ascii=False, allow_nan=False) + "\n").encode("utf-8")


def _limit_pct(lim: dict) -> str:
    return f"{100.0 * lim['value'] / lim['limit']:.1f}%"


def _counts(c: dict) -> str:
    """Triangles and vertices; before triangulation (import, transform) the polygons instead of
    "triangles 0"; nothing before the first stage."""
    if not any(c.get(k) for k in ("polygons", "triangles", "vertices")):
        return "–"  # the import stage starts from nothing
    t, p = c.get("triangles", 0), c.get("polygons", 0)
    parts = [f"polygons {p}" if not t and p else f"triangles {t}"]
    parts += [f"{k} {c[k]}" for k in ("vertices", "corners") if k in c]
    return ", ".join(parts)


def fmt_unit(key: str, v: Any, short: bool = False) -> str | None:
    """An accuracy figure that has a unit, with it (None for the rest): Hausdorff distances are
    fractions of the bounding-box diagonal, shown as a percentage of it; the BSP's
    ``inflation`` (triangles out / in - 1) as a signed percentage (1.07 reads +107%)."""
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return None
    if key.startswith("hausdorff"):
        return f"{100 * v:.3g}%" + ("" if short else " of the diagonal")
    if key == "inflation":
        return f"{100 * v:+.1f}%" + ("" if short else " triangles")
    return None


def fmt_accuracy(key: str, v: Any) -> str:
    """An accuracy figure with its unit (:func:`fmt_unit`), else as it is."""
    unit = fmt_unit(key, v)
    if unit is not None:
        return unit
    if isinstance(v, bool) or not isinstance(v, (int, float)):
        return str(v)
    return f"{v:.4g}"


def to_markdown(report: dict[str, Any]) -> str:
    s = report["scene"]
    out = [f"# Bake report: {Path(report['input']['path'] or '').name}", "",
           f"scratch-bake {report['tool']['version']} · {report['seconds']:.2f} s · "
           f"{s['triangles']} triangles, {s['vertices']} vertices, {s['materials']} materials", "",
           "## Stages", "", "| stage | seconds | in | out | accuracy | warnings |", "|---|---:|---|---|---|---|"]
    for st in report["stages"]:
        cin, cout = _counts(st["counts_in"]), _counts(st["counts_out"])
        acc = ", ".join(f"{k} {fmt_accuracy(k, v)}" for k, v in st["accuracy"].items())
        warn = "<br>".join(w.replace("|", "\\|") for w in st["warnings"])
        note = cache_note(st)
        out.append(f"| {st['name']}{' (' + note + ')' if note else ''} | {st['seconds']:.3f} | {cin} | {cout} | "
                   f"{acc} | {warn} |")
    out += ["", "## Effects", "", "| effect | ran | reason |", "|---|---|---|"]
    for e in report["effects"]:
        extra = f" ({e['rays']} rays)" if e.get("rays") else ""
        out.append(f"| {e['name']} | {'yes' if e['ran'] else 'no'} | {e.get('reason', '')}{extra} |")
    out += ["", "## Lists", "", "| list | items | stride | project.json bytes | file |", "|---|---:|---:|---:|---|"]
    for name, v in report["lists"].items():
        packed = f" (packed; plain {v['plain_bytes']})" if "packed" in v else ""
        out.append(f"| {name} | {v['items']} | {v['stride'] or 'var'} | {v['bytes']}{packed} | {v['file'] or ''} |")
    out += _left_out_markdown(report) + _packed_markdown(report)
    out += ["", "## Limits", "", "| check | value | limit | used | ok |", "|---|---:|---:|---:|---|"]
    for lim in report["limits"]:
        out.append(f"| {lim['name']} | {lim['value']} | {lim['limit']} | {_limit_pct(lim)} | "
                   f"{'ok' if lim['ok'] else '**EXCEEDED**'} |")
    return "\n".join(out) + "\n"


def _export_details(report: dict[str, Any]) -> dict[str, Any]:
    st = next((st for st in report["stages"] if st["name"] == "export"), None)
    return st["details"] if st else {}


def _left_out_markdown(report: dict[str, Any]) -> list[str]:
    left = _export_details(report).get("lists_left_out") or []
    if not left:
        return []
    out = ["", "## Lists left out", "", "The scene has this data, but nothing the bake writes would read it:", "",
           "| list | why | key |", "|---|---|---|"]
    for e in left:
        out.append(f"| {e['list']} | {e['reason'].replace('|', '/')} | `{e['key']}` |")
    return out


def _packed_markdown(report: dict[str, Any]) -> list[str]:
    pk = _export_details(report).get("pack")
    if not pk:
        return []
    out = ["", "## Packed lists", "",
           f"In the project these lists are stored packed in the list `{pk['list']}` and rebuilt, item for "
           "item, by the reader sprite's `unpack lists` at the green flag (docs/formats.md, \"Packed lists\"); "
           "the list files and lists.json hold them plain. Decode cost: blocks scratch-vm executes.", "",
           "| list | items | plain bytes | packed bytes | ratio | decode blocks | coding |",
           "|---|---:|---:|---:|---:|---:|---|"]
    for r in pk["lists"]:
        coding = ", ".join(f"{c['mode']}" + (f"×{c['columns']}" if c["columns"] > 1 else "") +
                           (f" ({c['palette']} colours)" if "palette" in c else "") for c in r["columns"])
        out.append(f"| {r['list']} | {r['items']} | {r['plain_bytes']} | {r['packed_bytes']} | {r['ratio']:.3f} | "
                   f"{r['decode_blocks']} | {coding} |")
    out.append(f"| **all** | | {pk['plain_bytes']} | {pk['packed_bytes']} | "
               f"{pk['packed_bytes'] / max(1, pk['plain_bytes']):.3f} | {pk['decode_blocks']} | |")
    return out


# counts in the one-line summary whose name alone does not say what they count (left out there when 0)
SUMMARY_MEANING = {
    "folds": "pairs of neighbouring triangles facing each other",
    "flipped_triangles": "triangles facing against the surface they stand for",
    "new_nonmanifold_edges": "edges of three or more triangles the input did not have",
    "new_misoriented_edges": "edges whose two triangles wind the same way",
}


def _summary_figure(key: str, v: Any) -> str:
    """A figure for the one-line summary: with its unit, a count as a whole number, what a count
    means where its name does not say."""
    unit = fmt_unit(key, v, short=True)
    if unit is not None:
        return unit
    text = f"{v:,}" if isinstance(v, int) or float(v).is_integer() and abs(v) >= 1 else f"{v:.3g}"
    return f"{text} ({SUMMARY_MEANING[key]})" if key in SUMMARY_MEANING else text


def summary_lines(report: dict[str, Any], command_seconds: float | None = None) -> list[str]:
    """A short human summary (gltfpack-style) for the terminal; ``command_seconds``: the whole
    command's wall time so far (start-up, imports, writing the outputs and reports), shown beside
    the pipeline's."""
    s = report["scene"]
    took = f"{report['seconds']:.2f} s"
    if command_seconds is not None:
        took += f" ({command_seconds:.2f} s for the whole command: start-up, stages, writing the outputs and reports)"
    lines = [f"{Path(report['input']['path'] or '').name}: {s['triangles']} triangles, {s['vertices']} vertices, "
             f"{s['materials']} materials in {took}"]
    for st in report["stages"]:
        nums = {k: v for k, v in st["accuracy"].items() if isinstance(v, (int, float)) and not isinstance(v, bool)
                and not (k in SUMMARY_MEANING and v == 0)}  # (a count of defects that is 0 says nothing)
        acc = " ".join(f"{k}={_summary_figure(k, v)}" for k, v in nums.items())
        if any(k.startswith("hausdorff") for k in nums):
            acc += " (Hausdorff distances in % of the bounding-box diagonal)"
        note = cache_note(st)
        lines.append((f"  {st['name']:<12} {st['seconds']:8.3f} s  {acc}".rstrip() + (f"  [{note}]" if note else "")))
        problems = set(st.get("problems", []))
        for w in st["warnings"]:
            lines.append(f"    {'PROBLEM' if w in problems else 'warning'}: {w}")
    total = sum(v["bytes"] for v in report["lists"].values())
    pk = _export_details(report).get("pack")
    packed = f" (packed from {fmt_bytes(total - pk['packed_bytes'] + pk['plain_bytes'])})" if pk else ""
    lines.append(f"  lists: {len(report['lists'])}, {sum(v['items'] for v in report['lists'].values())} items, "
                 f"{fmt_bytes(total)} in project.json{packed}")
    for lim in report["limits"]:
        if not lim["ok"]:
            lines.append(f"  LIMIT EXCEEDED: {lim['name']} = {lim['value']} > {lim['limit']}")
    if report.get("problems"):
        lines.append(f"  {len(report['problems'])} PROBLEM(S) (--strict fails the bake): "
                     + "; ".join(f"{p['stage']}: {p['message']}" for p in report["problems"]))
    pj = [lim for lim in report["limits"] if lim["name"].startswith("project.json")]
    if pj:
        ex = _export_details(report)
        into, own = ex.get("into") or {}, ex.get("sb3_project_json_bytes")
        merged = f" in {into['file']} (the bake merged into {Path(into['project']).name})" if into.get("file") else ""
        lines.append(f"  project.json: {fmt_bytes(pj[0]['value'])} of 5 MiB ({_limit_pct(pj[0])}){merged}"
                     + (f"; the bake's own .sb3: {fmt_bytes(own)}" if merged and own is not None else ""))
    return lines
