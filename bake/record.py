"""The record a stage returns next to its new scene; the report is built from these."""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any


@dataclass
class StageRecord:
    """What one stage did: time, counts in and out, accuracy figures, warnings.

    ``counts_in`` / ``counts_out`` map names (``triangles``, ``vertices``, ...) to ints.
    ``accuracy`` maps figure names to numbers (e.g. ``hausdorff_max``: fraction of the diagonal).
    ``effects`` lists effects this stage ran or skipped: dicts with ``name``, ``ran`` (bool),
    ``reason`` and optional ``rays``/``seconds``/``error``.
    ``details`` holds anything else worth keeping in report.json (JSON-serialisable).
    ``problems`` are warnings (also in ``warnings``) that make the bake a failure under
    ``--strict`` / ``report.strict`` (exit status 4), e.g. a lit bake whose colours are all black.
    ``failures`` are the problems where a part of the stage failed on valid input (an external
    tool crashed or timed out) and the bake went on without it: under ``--strict`` they make the
    exit status 5 (a stage failed) instead of 4. :meth:`fail` records one.
    ``idle`` is set by a stage that found nothing to do in this scene (``textures.enabled = "auto"``
    on a model without textures): why; the pipeline reports the stage as skipped with that reason.
    """

    name: str
    seconds: float = 0.0
    counts_in: dict[str, int] = field(default_factory=dict)
    counts_out: dict[str, int] = field(default_factory=dict)
    accuracy: dict[str, float] = field(default_factory=dict)
    warnings: list[str] = field(default_factory=list)
    effects: list[dict[str, Any]] = field(default_factory=list)
    details: dict[str, Any] = field(default_factory=dict)
    problems: list[str] = field(default_factory=list)
    failures: list[str] = field(default_factory=list)
    idle: str = ""

    def warn(self, message: str) -> None:
        self.warnings.append(message)

    def fail(self, message: str) -> None:
        """A part of the stage failed on valid input and the bake goes on without it: a warning,
        a problem, and under --strict exit status 5."""
        self.warnings.append(message)
        self.problems.append(message)
        self.failures.append(message)

    def to_json(self) -> dict[str, Any]:
        return {
            "name": self.name,
            "seconds": round(float(self.seconds), 6),
            "counts_in": dict(self.counts_in),
            "counts_out": dict(self.counts_out),
            "accuracy": {k: _num(v) for k, v in self.accuracy.items()},
            "warnings": list(self.warnings),
            "effects": list(self.effects),
            "details": self.details,
            "problems": list(self.problems),
            "failures": list(self.failures),
        }


def _num(v: Any) -> Any:
    try:
        f = float(v)
    except (TypeError, ValueError):
        return v
    if f != f or f in (float("inf"), float("-inf")):
        return None
    return f


@dataclass
class ReportSection:
    """A stage's own section of report.html, as plain text (the outputs render it): a title, rows
    of (label, text), and optionally a note and a table under them (``head``: column titles;
    ``numeric``: which columns hold numbers; ``table``: rows of cell texts; ``images``: pictures,
    each a caption and a base64 PNG, drawn at 3 screen pixels per pixel)."""

    title: str
    rows: list[tuple[str, str]]
    note: str = ""
    head: tuple[str, ...] = ()
    numeric: tuple[bool, ...] = ()
    table: list[tuple[str, ...]] = field(default_factory=list)
    images: list[tuple[str, str]] = field(default_factory=list)  # (caption, base64 PNG), shown after the rows
