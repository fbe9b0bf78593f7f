"""Small line and scatter plots as SVG text, for ``bake sweep``'s plot.

Why not matplotlib: a sweep draws one figure of three panels, and matplotlib took 0.84-1.0 s
for it (its import included; 0.6 s without), against 0.03 s for this SVG, measured side by side
on the table of a four-row AO sweep of the 2k bunny, whose rows with reuse take about 0.15 s
each. SVG is text: the same bytes for the same table, sharp at any zoom in report.html, about a
tenth of the PNG's size (12 KB against 123 KB), and no dependency.

API::

    fig = Figure(3, title="bake sweep lighting.ao.samples")
    ax = fig.panels[0]
    ax.points(xs, ys, marker="o", label="error", notes=["16", "32"])  # labelled points
    ax.line(xs, ys, style="-", label="fastest for its error")
    ax.xlog = True; ax.xlabel = "seconds"; ax.title = "..."
    svg_text = fig.svg()

Every series is a ``<g class="series" data-label="...">`` holding its ``<polyline>`` (lines)
and one shape per point (``class="point"``), so tests can read what was drawn.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence
from xml.sax.saxutils import escape

# matplotlib's default colour cycle ("tab10"), so the plot reads as it did
COLORS = ("#1f77b4", "#ff7f0e", "#2ca02c", "#d62728", "#9467bd", "#8c564b", "#e377c2", "#7f7f7f",
          "#bcbd22", "#17becf")
DASH = {"-": None, "--": "6,4", ":": "1.5,3", "-.": "6,3,1.5,3"}
PANEL_W, PANEL_H = 380, 290  # one panel, in SVG user units (pixels)
MARGIN = (62, 18, 46, 30)  # left, right, bottom, top around the plotting area
LEGEND_ROW = 13  # the legends go under the panels, two entries a row


@dataclass
class _Series:
    xs: list[float]
    ys: list[float]
    color: str
    label: str | None
    marker: str | None  # "o", "s", "^", "x" or None
    style: str | None  # "-", "--", ":", "-." or None (no line)
    notes: list[str] | None = None  # a text next to each point


@dataclass
class Axes:
    title: str = ""
    xlabel: str = ""
    ylabel: str = ""
    xlog: bool = False
    ylog: bool = False
    series: list[_Series] = field(default_factory=list)

    def _add(self, xs, ys, marker, style, label, color, notes) -> _Series:
        pts = [(float(x), float(y), None if notes is None else str(notes[i]))
               for i, (x, y) in enumerate(zip(xs, ys)) if _finite(x) and _finite(y)]
        color = color or COLORS[len(self.series) % len(COLORS)]
        s = _Series([p[0] for p in pts], [p[1] for p in pts], color, label, marker, style,
                    None if notes is None else [p[2] for p in pts])
        self.series.append(s)
        return s

    def points(self, xs: Sequence[float], ys: Sequence[float], *, marker: str = "o", label: str | None = None,
               color: str | None = None, notes: Sequence[str] | None = None) -> str:
        """Points without a line; returns the colour used."""
        return self._add(xs, ys, marker, None, label, color, notes).color

    def line(self, xs: Sequence[float], ys: Sequence[float], *, style: str = "-", marker: str | None = None,
             label: str | None = None, color: str | None = None) -> str:
        """A line through the points in the order given (and markers, if ``marker``)."""
        return self._add(xs, ys, marker, style, label, color, None).color

    # ---------------------------------------------------------------- drawing
    def _range(self, log: bool, axis: int) -> tuple[float, float]:
        vals = [v for s in self.series for v in (s.xs if axis == 0 else s.ys) if not log or v > 0]
        if not vals:
            return (1.0, 10.0) if log else (0.0, 1.0)
        lo, hi = min(vals), max(vals)
        if log:
            lo, hi = math.log10(lo), math.log10(hi)
        if hi - lo < 1e-12 * max(1.0, abs(hi)):
            pad = 0.5 if log else max(abs(lo) * 0.1, 1e-12)
            lo, hi = lo - pad, hi + pad
        pad = 0.06 * (hi - lo)
        return lo - pad, hi + pad

    def svg(self, x0: float, y0: float) -> str:
        left, right, bottom, top = MARGIN
        w, h = PANEL_W - left - right, PANEL_H - top - bottom
        ox, oy = x0 + left, y0 + top
        xr, yr = self._range(self.xlog, 0), self._range(self.ylog, 1)

        def tx(v: float) -> float:  # x in the axis's own units (log10 on a log axis) -> pixels
            return ox + (v - xr[0]) / (xr[1] - xr[0]) * w

        def ty(v: float) -> float:
            return oy + h - (v - yr[0]) / (yr[1] - yr[0]) * h

        def px(x: float) -> float:  # a data value -> pixels
            return tx(math.log10(x) if self.xlog else x)

        def py(y: float) -> float:
            return ty(math.log10(y) if self.ylog else y)

        out = [f"<g class='panel'><rect x='{ox:.1f}' y='{oy:.1f}' width='{w:.1f}' height='{h:.1f}' "
               "fill='white' stroke='#444' stroke-width='0.8'/>"]
        for v, text in _ticks(xr, self.xlog):
            x = tx(v)
            out.append(f"<line x1='{x:.1f}' y1='{oy:.1f}' x2='{x:.1f}' y2='{oy + h:.1f}' stroke='#ddd' "
                       "stroke-width='0.6'/>")
            out.append(_text(x, oy + h + 13, text, anchor="middle", size=9))
        for v, text in _ticks(yr, self.ylog):
            y = ty(v)
            out.append(f"<line x1='{ox:.1f}' y1='{y:.1f}' x2='{ox + w:.1f}' y2='{y:.1f}' stroke='#ddd' "
                       "stroke-width='0.6'/>")
            out.append(_text(ox - 4, y + 3, text, anchor="end", size=9))
        out.append(_text(ox + w / 2, oy + h + 30, self.xlabel, anchor="middle", size=10))
        out.append(f"<text x='{x0 + 12:.1f}' y='{oy + h / 2:.1f}' font-size='10' text-anchor='middle' "
                   f"transform='rotate(-90 {x0 + 12:.1f} {oy + h / 2:.1f})'>{escape(self.ylabel)}</text>")
        out.append(_text(ox + w / 2, y0 + 18, self.title, anchor="middle", size=10))
        for s in self.series:
            keep = [(x, y, i) for i, (x, y) in enumerate(zip(s.xs, s.ys))
                    if (not self.xlog or x > 0) and (not self.ylog or y > 0)]
            lab = escape(s.label or "", {"'": "&apos;"})
            out.append(f"<g class='series' data-label='{lab}'>")
            if s.style and len(keep) > 1:
                dash = DASH.get(s.style)
                pts = " ".join(f"{px(x):.2f},{py(y):.2f}" for x, y, _ in keep)
                out.append(f"<polyline points='{pts}' fill='none' stroke='{s.color}' stroke-width='1.5'"
                           + (f" stroke-dasharray='{dash}'" if dash else "") + "/>")
            if s.marker:
                for x, y, i in keep:
                    out.append(_marker(s.marker, px(x), py(y), s.color))
                    if s.notes is not None and s.notes[i]:
                        out.append(_text(px(x) + 5, py(y) - 5, s.notes[i], size=8))
            out.append("</g>")
        labelled = [s for s in self.series if s.label]
        for k, s in enumerate(labelled):  # the legend, under the panel in two columns
            y = y0 + PANEL_H + 6 + LEGEND_ROW * (k // 2)
            x = x0 + 10 + (PANEL_W - 20) / 2 * (k % 2)
            if s.style:
                dash = DASH.get(s.style)
                out.append(f"<line x1='{x:.1f}' y1='{y - 3:.1f}' x2='{x + 18:.1f}' y2='{y - 3:.1f}' "
                           f"stroke='{s.color}' stroke-width='1.5'" + (f" stroke-dasharray='{dash}'" if dash else "")
                           + "/>")
            if s.marker:
                out.append(_marker(s.marker, x + 9, y - 3, s.color, cls="legend"))
            out.append(_text(x + 22, y, s.label, size=8))
        out.append("</g>")
        return "".join(out)


class Figure:
    def __init__(self, n: int, title: str = ""):
        self.panels = [Axes() for _ in range(n)]
        self.title = title

    def svg(self) -> str:
        rows = max((sum(1 for s in ax.series if s.label) + 1) // 2 for ax in self.panels) if self.panels else 0
        W, H = PANEL_W * len(self.panels), PANEL_H + 30 + LEGEND_ROW * rows
        head = (f"<svg xmlns='http://www.w3.org/2000/svg' width='{W}' height='{H}' viewBox='0 0 {W} {H}' "
                "font-family='DejaVu Sans, Arial, sans-serif'>"
                f"<rect width='{W}' height='{H}' fill='white'/>" + _text(W / 2, 16, self.title, anchor="middle", size=12))
        body = "".join(ax.svg(i * PANEL_W, 22) for i, ax in enumerate(self.panels))
        return head + body + "</svg>\n"


def _finite(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(float(v))


def _text(x: float, y: float, text: str, *, anchor: str = "start", size: int = 9) -> str:
    return f"<text x='{x:.1f}' y='{y:.1f}' font-size='{size}' text-anchor='{anchor}'>{escape(str(text))}</text>"


def _marker(kind: str, x: float, y: float, color: str, cls: str = "point") -> str:
    r = 3.2
    if kind == "s":
        return f"<rect class='{cls}' x='{x - r:.2f}' y='{y - r:.2f}' width='{2 * r:.2f}' height='{2 * r:.2f}' fill='{color}'/>"
    if kind == "^":
        return (f"<polygon class='{cls}' points='{x:.2f},{y - r - 0.6:.2f} {x - r:.2f},{y + r - 0.6:.2f} "
                f"{x + r:.2f},{y + r - 0.6:.2f}' fill='{color}'/>")
    if kind == "x":
        return (f"<path class='{cls}' d='M{x - r:.2f},{y - r:.2f}L{x + r:.2f},{y + r:.2f}M{x - r:.2f},{y + r:.2f}"
                f"L{x + r:.2f},{y - r:.2f}' stroke='{color}' stroke-width='1.4'/>")
    return f"<circle class='{cls}' cx='{x:.2f}' cy='{y:.2f}' r='{r:.2f}' fill='{color}'/>"


def _ticks(rng: tuple[float, float], log: bool) -> list[tuple[float, str]]:
    """Tick positions (in the axis's own units: log10 of the value on a log axis) and labels."""
    lo, hi = rng
    if log:
        if hi - lo >= 3.0:  # decades
            step = max(1, math.ceil((hi - lo) / 6))
            ks = range(math.ceil(lo), math.floor(hi) + 1)
            return [(float(k), f"{10.0 ** k:g}") for k in ks if k % step == 0]
        if hi - lo >= 0.7:  # 1, 2 and 5 times a power of ten
            out = []
            for k in range(math.floor(lo), math.ceil(hi) + 1):
                for m in ((1, 2, 5) if hi - lo < 2.0 else (1, 3)):
                    v = math.log10(m) + k
                    if lo <= v <= hi:
                        out.append((v, f"{m * 10.0 ** k:g}"))
            return out
        # less than a decade: ticks at round values, placed on the log scale
        vals = _nice(10 ** lo, 10 ** hi)
        return [(math.log10(v), f"{v:g}") for v in vals if v > 0]
    return [(v, f"{v:g}") for v in _nice(lo, hi)]


def _nice(lo: float, hi: float, n: int = 5) -> list[float]:
    span = hi - lo
    if not span > 0:
        return [lo]
    raw = span / n
    mag = 10 ** math.floor(math.log10(raw))
    step = next(m * mag for m in (1, 2, 2.5, 5, 10) if m * mag >= raw)
    first = math.ceil(lo / step)
    out = []
    k = first
    while k * step <= hi + 1e-12 * abs(step):
        out.append(float(f"{k * step:.12g}"))
        k += 1
    return out
