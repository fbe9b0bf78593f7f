"""The export stage: the scene as Scratch lists, their files (one per list and one JSON file)
and the projects (.sb3, .sprite3, ``export.into``). The lists are made in ``lists.py``.

The stage writes nothing to disk: it returns the file contents in the artefact ``outputs``
(relative path -> bytes), which the writer (``bake.outputs.write``) puts in place atomically.
"""

from __future__ import annotations

import dataclasses
import json
import re
import time

from ..config import ExportConfig
from ..errors import ConfigError
from ..record import StageRecord
from ..scene import Scene
from ..scratch.numbers import json_array, project_json_bytes, render_items
from .lists import list_file_bytes, list_file_name, mesh_lists, pack_lists


def stage(scene: Scene, cfg: ExportConfig) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord("export")
    lists = mesh_lists(scene, cfg, rec)
    names = {lst.name for lst in lists}
    for lst in scene.lists.values():
        if lst.name in names:
            raise ConfigError(f"list name '{lst.name}' is used twice (a mesh list and a {lst.doc or 'stage'} list); "
                              "rename one under [export.names]", key="export.names")
        lists.append(lst)
        names.add(lst.name)

    files: dict[str, bytes] = {}
    info: dict[str, dict] = {}
    arrays: dict[str, str] = {}
    used_files: dict[str, str] = {}
    for lst in lists:
        items = render_items(lst)
        arr = json_array(items, "string" if lst.kind == "string" else "number")
        arrays[lst.name] = arr
        fname = list_file_name(lst.name, items)
        stem = fname.rsplit(".", 1)[0]
        if stem in used_files:
            raise ConfigError(f"lists '{used_files[stem]}' and '{lst.name}' map to the same file {stem}.*",
                              key="export.names")
        used_files[stem] = lst.name
        if cfg.txt:
            files[fname] = list_file_bytes(fname, items)
        info[lst.name] = {"items": len(items), "stride": lst.stride, "doc": lst.doc,
                          "project_json_bytes": project_json_bytes(lst.name, arr),
                          "file": fname if cfg.txt else None}
    if cfg.json:
        body = ",".join(f"{json.dumps(k, ensure_ascii=False)}:{v}" for k, v in arrays.items())
        meta = json.dumps({k: {"stride": v["stride"], "doc": v["doc"]} for k, v in info.items()},
                          ensure_ascii=False, separators=(",", ":"))
        files[cfg.json_name] = ('{"format":"scratch-bake lists","version":1,"lists":{' + body +
                                '},"info":' + meta + "}").encode("utf-8")

    name = scene.source.path.stem if scene.source.path else "model"
    extra_read: list = []
    if cfg.sb3 or cfg.sprite3 or cfg.into:
        # .sb3 / .sprite3 (with the reader sprite) and the bake into an author's project
        from ..scratch.project import project_outputs

        values = {k: json.loads(v) for k, v in arrays.items()}
        packed = pack_lists(lists, values, info, cfg, rec) if cfg.pack else {}
        projects, extra_read = project_outputs(scene, cfg, values, name, rec, packed=packed)
        files.update(projects)
    elif cfg.pack:
        rec.warn("export.pack: no project is written (export.sb3, sprite3 and into are off), so nothing is packed")
    for cname, png in scene.artefacts.costumes or []:  # texture costumes as files too
        files[f"assets/{re.sub(r'[^A-Za-z0-9._-]+', '_', cname).strip('._') or 'costume'}.png"] = png

    new = scene.replace(lists={lst.name: lst for lst in lists})
    if extra_read:  # the project baked into: protected from overwriting, and a depfile input
        new = new.replace(source=dataclasses.replace(
            new.source, files_read=tuple(new.source.files_read) + tuple(extra_read)))
    new = new.with_artefacts(outputs=files).with_artefacts(list_info=info)
    rec.details["lists"] = info
    rec.seconds = time.perf_counter() - t0
    return new, rec
