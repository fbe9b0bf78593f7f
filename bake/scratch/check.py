"""``bake check PROJECT.sb3``: where a project's bytes go, against Scratch's limits.

For authors who hit the 5 MiB project.json wall: every list and variable (items and the bytes it
takes in project.json, including a visible monitor's second copy), each target's blocks, and every
asset (costumes, sounds) against 10 MB. The project is read as untrusted input
(:func:`bake.scratch.sb3.load_project`); nothing is written.
"""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

from ..errors import InputError
from . import sb3
from .limits import ASSET_LIMIT, LIST_ITEM_LIMIT, PROJECT_JSON_LIMIT
from .loader import UNPACK_LISTS_FIXED


def _size(obj: Any) -> int:
    return len(json.dumps(obj, ensure_ascii=False, separators=(",", ":")).encode("utf-8"))


def check(path: Path) -> dict[str, Any]:
    project, assets = sb3.load_project(path)
    raw = Path(path).read_bytes()
    # the real size of the project.json entry (a bare project.json: the file itself)
    pj_bytes = (sb3.archive_sizes(raw)["project_json_bytes"] if raw[:2] == b"PK" else len(raw)) or _size(project)
    items: list[dict[str, Any]] = []
    limits: list[dict[str, Any]] = [{"name": "project.json bytes", "value": pj_bytes, "limit": PROJECT_JSON_LIMIT,
                                     "ok": pj_bytes <= PROJECT_JSON_LIMIT}]
    for t in project.get("targets", []):
        if not isinstance(t, dict):
            continue
        owner = "Stage" if t.get("isStage") else str(t.get("name"))
        for lid, entry in (t.get("lists") or {}).items():
            if isinstance(entry, list) and len(entry) >= 2 and isinstance(entry[1], list):
                n = len(entry[1])
                items.append({"kind": "list", "owner": owner, "name": str(entry[0]), "items": n,
                              "bytes": _size({lid: entry}) - 2})
                limits.append({"name": f"list '{entry[0]}' ({owner}) items", "value": n,
                               "limit": LIST_ITEM_LIMIT, "ok": n <= LIST_ITEM_LIMIT})
        for vid, entry in (t.get("variables") or {}).items():
            items.append({"kind": "variable", "owner": owner, "name": str(entry[0]) if entry else "?",
                          "items": 1, "bytes": _size({vid: entry}) - 2})
        items.append({"kind": "blocks", "owner": owner, "name": f"{len(t.get('blocks') or {})} blocks",
                      "items": len(t.get("blocks") or {}), "bytes": _size(t.get("blocks") or {})})
    for m in project.get("monitors", []) or []:
        if isinstance(m, dict) and m.get("mode") == "list" and m.get("value"):
            items.append({"kind": "monitor copy", "owner": str(m.get("spriteName") or "Stage"),
                          "name": str((m.get("params") or {}).get("LIST", "?")),
                          "items": len(m["value"]), "bytes": _size(m)})
    asset_rows = []
    for name, data in sorted(assets.items()):
        asset_rows.append({"file": name, "bytes": len(data)})
        limits.append({"name": f"asset {name} bytes", "value": len(data), "limit": ASSET_LIMIT,
                       "ok": len(data) < ASSET_LIMIT})
    items.sort(key=lambda r: (-r["bytes"], r["kind"], r["owner"], r["name"]))
    packed = packed_rows(project, path)
    for row in packed:
        limits.append({"name": f"packed list '{row['list']}' items rebuilt by `add to list`", "value": row["items"],
                       "limit": LIST_ITEM_LIMIT, "ok": row["items"] <= LIST_ITEM_LIMIT,
                       "note": "vanilla Scratch's `add to list` stops at 200,000; TurboWarp has no limit"})
    return {"project": str(path), "project_json_bytes": pj_bytes, "items": items, "assets": asset_rows,
            "limits": limits, "problems": sb3.validate_project(project, assets), "packed": packed,
            "decode_blocks": (UNPACK_LISTS_FIXED + sum(r["decode_blocks"] for r in packed)) if packed else 0}


def packed_rows(project: dict[str, Any], path: Path | None = None) -> list[dict[str, Any]]:
    """Every packed text of a project: the list it rebuilds, its items, its bytes in project.json
    and the blocks the loader runs for it (scratch-vm's count). A bad text is an InputError."""
    from .loader import decode_cost
    from .pack import packed_bytes

    found = check_packed_lists(project, path)
    per_container: dict[tuple, int] = {}
    for f in found:
        per_container[(f["owner"], f["in"])] = per_container.get((f["owner"], f["in"]), 0) + 1
    rows = []
    for f in found:
        rows.append({"list": f["list"], "in": f["in"], "owner": f["owner"], "item": f["item"], "items": f["items"],
                     "chars": f["chars"], "bytes": packed_bytes(f["list"], f["text"]), "modes": f["modes"],
                     "decode_blocks": decode_cost(f["cost"], per_container[(f["owner"], f["in"])])})
    return rows


def check_packed_lists(project: dict[str, Any], path: Path | None = None) -> list[dict[str, Any]]:
    """Decode every packed text in a project (any list item that starts like one): what each
    rebuilds. A bad one is an :class:`InputError` naming the list (and the project)."""
    from .pack import PackError, is_packed, unpack

    from .pack import header_name

    found = []
    # the loader's own list of names (item k of the packed list rebuilds _pk names[k]): names a
    # text whose header is unreadable
    expected: list = []
    for t in project.get("targets", []) or []:
        for entry in ((t.get("lists") or {}).values() if isinstance(t, dict) else ()):
            if isinstance(entry, list) and len(entry) >= 2 and entry[0] == "_pk names" and isinstance(entry[1], list):
                expected = entry[1]
    for t in project.get("targets", []) or []:
        if not isinstance(t, dict):
            continue
        owner = "Stage" if t.get("isStage") else str(t.get("name"))
        for entry in (t.get("lists") or {}).values():
            if not (isinstance(entry, list) and len(entry) >= 2 and isinstance(entry[1], list)):
                continue
            for k, text in enumerate(entry[1], start=1):
                if not is_packed(text):
                    continue
                try:
                    name = header_name(text)
                    if name is None and k <= len(expected):
                        name = str(expected[k - 1])
                    u = unpack(text, name)
                except PackError as e:
                    raise InputError(f"{e} (item {k} of list '{entry[0]}' in {owner})", path=path) from None
                found.append({"list": u.name, "owner": owner, "in": str(entry[0]), "item": k, "text": text,
                              "items": len(u.items), "chars": u.chars, "modes": u.modes, "cost": u.cost})
    return found


def summary_lines(rep: dict[str, Any], top: int = 15) -> list[str]:
    pj = rep["project_json_bytes"]
    lines = [f"{Path(rep['project']).name}: project.json {pj:,} bytes = {100 * pj / PROJECT_JSON_LIMIT:.1f}% "
             f"of 5 MiB; {len(rep['assets'])} assets, {sum(a['bytes'] for a in rep['assets']):,} bytes"]
    lines.append(f"  {'bytes':>10}  {'share':>6}  what")
    for r in rep["items"][:top]:
        lines.append(f"  {r['bytes']:>10,}  {100 * r['bytes'] / max(pj, 1):5.1f}%  {r['kind']} "
                     f"'{r['name']}' ({r['owner']}, {r['items']:,} items)" if r["kind"] != "blocks" else
                     f"  {r['bytes']:>10,}  {100 * r['bytes'] / max(pj, 1):5.1f}%  blocks of {r['owner']} "
                     f"({r['items']:,})")
    if len(rep["items"]) > top:
        lines.append(f"  ... {len(rep['items']) - top} more (--json for all)")
    if rep.get("packed"):
        lines.append(f"  packed lists (rebuilt at the green flag by the loader; {rep['decode_blocks']:,} blocks "
                     "in scratch-vm):")
        for r in rep["packed"]:
            lines.append(f"  {r['bytes']:>10,}  list '{r['list']}' ({r['owner']}, item {r['item']} of '{r['in']}'): "
                         f"{r['items']:,} items, {r['decode_blocks']:,} blocks, {', '.join(r['modes'])}")
    for lim in rep["limits"]:
        if not lim["ok"]:
            lines.append(f"  LIMIT EXCEEDED: {lim['name']} = {lim['value']:,} > {lim['limit']:,}")
    for p in rep["problems"][:10]:
        lines.append(f"  problem: {p}")
    return lines
