"""After the pipeline: put the outputs, the report and the depfile on disk."""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any

from ..pipeline import BakeResult
from . import report as report_mod
from .write import depfile_text, write_atomic, write_outputs

REPORT_FILES = ("report.json", "report.md", "report.html")


def finish(result: BakeResult, out_dir: Path, *, depfile: Path | None = None,
           live_report: bool = False) -> dict[str, Any]:
    """Write every output under ``out_dir`` and return the report.

    Lists (and other data outputs) are written first, then the report, so a report on disk
    always describes complete outputs. Limits are checked by the caller (``--strict``).
    ``live_report``: report.html reloads itself in a browser when rewritten (``bake watch``).
    """
    out_dir = Path(out_dir)
    files: dict[str, bytes] = dict(result.scene.artefacts.get("outputs", {}))
    src = result.scene.source
    protect = set(src.files_read) | ({result.config.source} if result.config.source else set())
    assets = {k: len(v) for k, v in files.items() if k.startswith("assets/")}
    status = write_outputs(out_dir, files, protect=protect, also_ours=REPORT_FILES)
    rep = report_mod.build(result, outputs=status, assets=assets)
    # report.json is rewritten by every bake (Make uses it as the "baked" target)
    if not write_atomic(out_dir / "report.json", report_mod.to_json(rep)):
        os.utime(out_dir / "report.json")
    write_atomic(out_dir / "report.md", report_mod.to_markdown(rep).encode("utf-8"))
    if result.config.report.html:
        from . import html

        w = result.config.report.preview_width
        html.write(out_dir, width=w, height=max(1, w * 3 // 4), live=live_report)
    if depfile is not None:
        deps = [p.resolve() for p in src.files_read]
        if result.config.source:
            deps.append(result.config.source)
        targets = [(out_dir / f).resolve() for f in sorted(files)] + [(out_dir / "report.json").resolve()]
        write_atomic(Path(depfile), depfile_text(targets, sorted(set(deps))).encode("utf-8"))
    return rep
