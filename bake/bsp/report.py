"""The BSP stage's section of report.html: what painter's order costs the author (triangles before
and after, its lists' bytes, one frame's walk from the reader sprite's starting eye)."""

from __future__ import annotations

from typing import Any

from ..record import ReportSection
from ..scratch.limits import fmt_bytes


def section(st: dict[str, Any]) -> ReportSection | None:
    """From the stage's entry in report.json; None when the stage built no tree."""
    d = st.get("details") or {}
    if "inflation" not in d:
        return None
    t_in = (st.get("counts_in") or {}).get("triangles", 0)
    t_out = (st.get("counts_out") or {}).get("triangles", 0)
    nbytes = sum(v.get("project_json_bytes", 0) for v in d.get("lists", {}).values())
    rec = d.get("records", {})
    w = d.get("walk") or {}
    rows = [("triangles", f"{t_in:,} → {t_out:,} (+{d['inflation']:.1%})"),
            ("records", f"{sum(rec.values()):,} ({rec.get('split', 0) + rec.get('split_two_sided', 0):,} split, "
                        f"{rec.get('leaf', 0):,} leaf, {rec.get('peel', 0):,} peel); {d.get('planes', 0):,} planes"),
            ("list bytes", f"{fmt_bytes(nbytes)} in project.json ({d.get('bytes_per_triangle', 0):.1f} per triangle)")]
    cr = d.get("crossing") or {}
    if cr.get("pairs"):
        rows.append(("parts through each other", f"{cr['pairs']:,} pairs of triangles cross ({cr['triangles']:,} "
                                                 f"triangles in {cr['parts']} part(s)): one of each pair is cut, "
                                                 "whatever the tree"))
    if w:
        rows.append(("one frame's walk", f"from the reader's starting eye: {w['plane_tests']:,} plane tests, "
                                         f"{w['ranges']:,} ranges of {w['triangles']:,} triangles "
                                         f"({w['facing']:,} face the eye); ≈ {w['blocks_estimate']:,} blocks "
                                         "(estimate fitted to scratch-vm, docs/formats-bsp.md)"))
    return ReportSection("BSP: what painter's order costs", rows)
