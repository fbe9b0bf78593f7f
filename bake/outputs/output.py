"""After the pipeline: put the outputs, the report and the depfile on disk, as one commit.

:func:`check_paths` runs before the bake (``bake run`` calls it first): the output folder can
be created and written, the depfile is not a folder, and no file the bake is known to read is
where an output will go. :func:`finish` then stages everything -- lists, projects, textures,
``report.json``, ``report.md``, ``report.html`` (rendered from the staged bytes, not from the
folder) and the depfile -- and commits it in one go (:class:`~bake.outputs.write.Outputs`), so
an interrupted bake leaves every file old or the whole folder new.
"""

from __future__ import annotations

import os
import re
import sys
from pathlib import Path
from typing import Any, Iterable

from ..config import RESERVED_OUTPUT_NAMES
from ..errors import ConfigError
from ..pipeline import BakeResult
from . import report as report_mod
from .write import Outputs, check_writable_folder, depfile_text

REPORT_FILES = ("report.json", "report.md", "report.html")


def _inside(path: Path, folder: Path) -> bool:
    try:
        p, f = path.resolve(), folder.resolve()
    except OSError:
        return False
    return f == p or f in p.parents


def check_paths(out_dir: Path, *, depfile: Path | None = None, inputs: Iterable[Path] = (),
                names: Iterable[str] = (), label: str = "--out") -> None:
    """Before baking: every output path given on the command line can be written, exit 2 naming
    the path otherwise. ``inputs``: files the bake will read (model, config, ``export.into``);
    ``names``: output names known before the bake (reports, lists.json, the .sb3/.sprite3)."""
    out_dir = Path(out_dir)
    check_writable_folder(out_dir, label)
    for sub in ("lists", "assets"):  # folders of ours that already exist must take new files too
        if (out_dir / sub).is_dir():
            check_writable_folder(out_dir / sub, f"--out ({sub}/)")
        elif (out_dir / sub).exists():
            raise ConfigError(f"{sub} in the output folder is a file, not a folder; remove it or choose "
                              "another --out", path=out_dir / sub)
    inputs = [Path(p) for p in inputs if p]
    for name in list(REPORT_FILES) + list(names):
        target = out_dir / name
        for p in inputs:
            if p.exists() and target.exists() and os.path.samefile(p, target):
                raise ConfigError(f"refusing to overwrite the input file {p} with the output {name} "
                                  "(choose another --out)", path=out_dir)
    if depfile is not None:
        depfile = Path(depfile)
        if depfile.is_dir():
            raise ConfigError("--depfile names a folder, not a file", path=depfile)
        check_writable_folder(depfile.parent if str(depfile.parent) else Path("."), "--depfile's folder")
        for p in inputs:
            if p.exists() and depfile.exists() and os.path.samefile(p, depfile):
                raise ConfigError("refusing to overwrite an input file with the depfile", path=depfile)
        if _inside(depfile, out_dir):
            # an output named up front, a reserved name (the reports, the manifest) or anything in a
            # folder the bake fills (lists/, assets/, sweeps/, the cache): not all known before the bake
            rel = depfile.resolve().relative_to(out_dir.resolve())
            if not rel.parts or rel.as_posix() in set(names) or rel.parts[0].lower() in RESERVED_OUTPUT_NAMES:
                raise ConfigError("--depfile would overwrite an output of the bake (choose a path outside the "
                                  "output folder, or a name the bake does not write)", path=depfile)


def finish(result: BakeResult, out_dir: Path, *, depfile: Path | None = None,
           live_report: bool = False) -> dict[str, Any]:
    """Write every output under ``out_dir`` (and the depfile) and return the report.

    Nothing is renamed until everything is staged: the lists and projects, then the report built
    from what is staged (its ``outputs`` say what the commit will do), report.html rendered from
    the staged bytes, the depfile. Limits are checked by the caller (``--strict``).
    ``live_report``: report.html reloads itself in a browser when rewritten (``bake watch``:
    ``html.live_script``; report-live.js is written after the commit)."""
    out_dir = Path(out_dir)
    cfg = result.config
    files: dict[str, bytes] = dict(result.scene.artefacts.outputs or {})
    src = result.scene.source
    protect = set(src.files_read) | ({cfg.source} if cfg.source else set())
    assets = {k: len(v) for k, v in files.items() if k.startswith("assets/")}
    reports = ["report.json", "report.md"] + (["report.html"] if cfg.report.html else [])
    with Outputs(out_dir, protect=protect) as outs:
        outs.start(files, also=reports)
        status = dict(outs.status)
        ours = set(files) | set(reports)
        for rel in outs.removals():
            if rel not in ours and (out_dir / rel).is_file():
                status[rel] = "removed"
        rep = report_mod.build(result, outputs=status, assets=assets)
        rep_json = report_mod.to_json(rep)
        outs.add("report.json", rep_json, always=True)  # Make uses it as the "baked" target
        outs.add("report.md", report_mod.to_markdown(rep).encode("utf-8"))
        if cfg.report.html:
            from . import html

            w = cfg.report.preview_width
            page, _ = html.build(out_dir, width=w, height=max(1, w * 3 // 4),
                                 files={**files, "report.json": rep_json}, memo=result.memo)
            if result.memo is not None:  # (report.json is written: a damaged preview memo is said here)
                for w_ in result.memo.take_warnings():
                    print(f"warning: {w_}", file=sys.stderr)
            stamp = None
            if live_report:
                page, stamp = html.make_live(page)
            outs.add("report.html", page.encode("utf-8"))
        if depfile is not None:
            outs.add_file(Path(depfile), depfile_for(result, out_dir).encode("utf-8"))
        outs.commit()
    if live_report and cfg.report.html:
        html.write_live_stamp(out_dir, stamp)
    from ..pipeline import finish_cache

    finish_cache(result)  # a new folder's stage cache: only now that the outputs are written
    return rep


def depfile_for(result: BakeResult, out_dir: Path) -> str:
    """Make rules: ``OUT/report.json`` (named as ``--out`` was given, so it matches the Makefile's
    own target name) depends on every file the bake read, and on every file the model names that
    was not found, once it is there (``$(wildcard ...)``: while it is missing nothing rebakes;
    adding it does). A missing path whose name make cannot quote inside a function (white space,
    parentheses, commas) is watched through the nearest folder on its way instead, whose time
    changes when the file is added."""
    src = result.scene.source
    deps = [p.resolve() for p in src.files_read]
    if result.config.source:
        deps.append(Path(result.config.source).resolve())
    missing = []
    for p in getattr(src, "files_missing", ()):
        p = Path(os.path.abspath(p))
        if re.search(r"[\s(),:%*?\[\]]", str(p)):
            deps.extend(_watch_folders(p))
        else:
            missing.append(p)
    # report.json alone: every bake rewrites it. Naming the list files too would make them targets
    # with no recipe that look out of date after every input edit (they are rewritten only when
    # their bytes change), so every rule consuming them would rerun.
    return depfile_text([out_dir / "report.json"], sorted(set(deps)), sorted(set(missing)))


def _watch_folders(missing: Path) -> list[Path]:
    """The nearest existing folder on the way to a missing file: creating the file (or a folder
    on its way) there changes that folder's modification time."""
    p = Path(os.path.abspath(missing)).parent
    while not p.is_dir():
        if p.parent == p:
            return []
        p = p.parent
    return [p.resolve()]
