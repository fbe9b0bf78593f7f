"""The export stage's section of report.html: with ``export.into``, what the author's engine does
with each list the bake wrote into it (the blocks that read, write and empty it) and what the
engine check warns about (``bake/scratch/engine.py``)."""

from __future__ import annotations

from typing import Any

from ..record import ReportSection


def _who(uses: list[dict]) -> str:
    return ", ".join(f"{u['sprite']} ({u['blocks']} block{'s' if u['blocks'] != 1 else ''})" for u in uses)


def section(st: dict[str, Any]) -> ReportSection | None:
    """From the stage's entry in report.json; None without ``export.into``."""
    eng = ((st.get("details") or {}).get("into") or {}).get("engine")
    if not eng:
        return None
    rows = [("warning", w.removeprefix("export.into: ")) for w in eng.get("warnings", [])]
    out = ReportSection(f"Your engine: which blocks read the lists (baked into {eng.get('target', 'Stage')})", rows)
    out.note = ("Per list the bake wrote: the sprites whose blocks read it, write it and empty it "
                "(delete all of), in the project as it was before the merge.")
    out.head = ("list", "read by", "named in text by", "written by", "emptied by", "replaced")
    out.table = [(name, _who(e["read_by"]) or "no block", _who(e.get("named_by", [])), _who(e["written_by"]),
                  _who(e["emptied_by"]), "yes" if e.get("replaced") else "added")
                 for name, e in eng.get("lists", {}).items()]
    return out
