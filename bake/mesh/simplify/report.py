"""The simplify stage's section of report.html: what the budget cost (the count against the
target, the error, each kind of defect with the share of the surface it covers, what was let go
to reach the target, and the parts with the largest error)."""

from __future__ import annotations

from typing import Any

from ...record import ReportSection


def section(st: dict[str, Any]) -> ReportSection | None:
    """From the stage's entry in report.json; None when the stage kept the mesh as it was."""
    d = st.get("details") or {}
    if "defects" not in d:
        return None
    acc = st.get("accuracy", {})
    t_in = (st.get("counts_in") or {}).get("triangles", 0)
    t_out = (st.get("counts_out") or {}).get("triangles", 0)
    df = d["defects"]
    rows = [("triangles", f"{t_in:,} → {t_out:,} (target {d.get('target_triangles', 0):,}; "
                          f"defects = \"{df.get('policy', '')}\")")]
    if "hausdorff_max" in acc:
        rows.append(("error", f"max {acc['hausdorff_max']:.3%} of the diagonal, mean {acc['hausdorff_mean']:.3%}"
                              + (f"; proven bound {acc['hausdorff_bound_original_to_simplified']:.3%} (original → "
                                 "simplified)" if "hausdorff_bound_original_to_simplified" in acc else "")))
    rows.append(("defects", f"{df['flipped_triangles']:,} flipped ({df['flipped_area']:.2%} of the area), "
                            f"{df['new_nonmanifold_edges']:,} new non-manifold edges "
                            f"({df['new_nonmanifold_area']:.2%}), {df['new_folds']:,} new folds "
                            f"({df['folded_area']:.2%})"))
    lay = d.get("layer")
    if lay:
        rows.append(("two-sided and repeated", f"{lay['with_back']:,} triangles had a back (simplified once, "
                                               f"written twice); {lay['repeated_dropped']:,} repeats dropped"))
    if d.get("relaxed"):
        rows.append(("let go to reach the target", ", ".join(d["relaxed"])))
    out = ReportSection("Simplify: what the budget cost", rows)
    parts = d.get("parts") or {}
    if parts.get("count", 0) > 1:
        out.note = (f"{parts['count']:,} parts (pieces joined by edges of two triangles); {parts['dropped']:,} "
                    f"dropped, {parts['collapsed']:,} collapsed. The parts with the largest error (size and "
                    "error in fractions of the model's diagonal):")
        out.head = ("part", "triangles in", "out", "size", "error", "")
        out.numeric = (True, True, True, True, True, False)
        out.table = [(str(p["part"]), f"{p['triangles_in']:,}", f"{p['triangles_out']:,}", f"{p['size']:.3f}",
                      f"{p['error']:.3%}", str(p["state"])) for p in parts.get("worst", [])[:10]]
    return out
