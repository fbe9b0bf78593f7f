"""The stage backdrop of a baked .sb3: white, unless the model would vanish on white.

The reader sprite draws every triangle in one flat colour (its ``tri colors`` item, else its
material's ``mat colors`` item, else grey), with no shading of its own. A white or near-white model
baked without lighting (a textured model with its texture off, a white material) is then white on
Scratch's white stage: a blank picture. Baking a headlight into the colours would be wrong for an
author's engine (it shades with its own light, or the model turns), and shading in the reader costs
blocks every frame, so the project's *backdrop* changes instead: it costs nothing per frame and
leaves the lists as the author's engine expects them.

:func:`choose` weighs each triangle by its area and counts the share that stands out against a
backdrop: a channel at least :data:`VISIBLE_LEVELS` levels away from the backdrop's (the default
light grey material, 204, stands out on white; a white or pale pink model does not; a pure green one
does, which a luminance contrast alone would miss). White is kept unless under half of the model's
area stands out on it and more stands out on :data:`DARK`. The choice is in the export record
(``details.backdrop``), and report.html's green flag preview draws on the same colour. A project
baked into (``export.into``) keeps its own stage, and a .sprite3 has none.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from .colors import decode_numbers

WHITE = (255, 255, 255)
#: a dark slate: white and pale colours stand far from it
DARK = (38, 43, 53)
#: a triangle stands out when one channel differs from the backdrop's by this many levels (of 255)
VISIBLE_LEVELS = 48
#: the reader's colour for a triangle without a colour list
READER_GREY = (128, 128, 128)


@dataclass(frozen=True)
class Backdrop:
    rgb: tuple[int, int, int]
    reason: str
    visible_on_white: float  # share of the drawn area VISIBLE_LEVELS or more from white
    visible_on_dark: float

    @property
    def hex(self) -> str:
        return "#{:02x}{:02x}{:02x}".format(*self.rgb)

    def to_json(self) -> dict:
        return {"colour": self.hex, "reason": self.reason,
                "visible_on_white": round(self.visible_on_white, 4), "visible_on_dark": round(self.visible_on_dark, 4)}

    def svg(self) -> bytes:
        return (b'<svg xmlns="http://www.w3.org/2000/svg" width="480" height="360" viewBox="0 0 480 360">'
                + f'<rect width="480" height="360" fill="{self.hex}"/></svg>'.encode("ascii"))


def difference(colours: np.ndarray, backdrop: tuple[int, int, int]) -> np.ndarray:
    """The largest channel difference (0..255) of sRGB byte colours (..., 3) from a backdrop."""
    return np.abs(np.asarray(colours, np.int64) - np.asarray(backdrop, np.int64)).max(axis=-1)


def drawn_colours(tris: list, tri_colors: list | None, mat_colors: list | None) -> np.ndarray:
    """(T, 3) uint8: the colour the reader fills each triangle with (``tris``: the flat list of
    four items per triangle, 1-based corners and material)."""
    t = np.asarray(tris, np.float64).reshape(-1, 4)
    if tri_colors is not None and len(tri_colors) == len(t):
        return decode_numbers(tri_colors)[:, :3]
    if mat_colors:
        mats = decode_numbers(mat_colors)[:, :3]
        idx = np.clip(t[:, 3].astype(np.int64) - 1, 0, len(mats) - 1)
        return mats[idx]
    return np.tile(np.asarray(READER_GREY, np.uint8), (len(t), 1))


def choose(verts: list, tris: list, tri_colors: list | None = None, mat_colors: list | None = None) -> Backdrop:
    """The backdrop for a mesh as the reader draws it (the written lists)."""
    v = np.asarray(verts, np.float64).reshape(-1, 3)
    t = np.asarray(tris, np.float64).reshape(-1, 4)
    if len(t) == 0 or len(v) == 0:
        return Backdrop(WHITE, "no triangles", 1.0, 1.0)
    idx = np.clip(t[:, :3].astype(np.int64) - 1, 0, len(v) - 1)
    p = v[idx]
    area = 0.5 * np.linalg.norm(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]), axis=1)
    if not np.isfinite(area).all() or area.sum() <= 0:
        area = np.ones(len(t))
    w = area / area.sum()
    col = drawn_colours(tris, tri_colors, mat_colors)
    on_white = float(w[difference(col, WHITE) >= VISIBLE_LEVELS].sum())
    on_dark = float(w[difference(col, DARK) >= VISIBLE_LEVELS].sum())
    if on_white >= 0.5 or on_dark <= on_white:
        return Backdrop(WHITE, f"{on_white:.0%} of the model's area stands out on white", on_white, on_dark)
    return Backdrop(DARK, f"only {on_white:.0%} of the model's area would stand out on white (its colours are "
                          f"light), {on_dark:.0%} does on this dark backdrop", on_white, on_dark)


def from_report(report: dict) -> tuple[int, int, int]:
    """The backdrop a bake's .sb3 has, from report.json (white for older reports)."""
    for st in report.get("stages", []):
        b = (st.get("details") or {}).get("backdrop") if st.get("name") == "export" else None
        if isinstance(b, dict) and isinstance(b.get("colour"), str) and len(b["colour"]) == 7:
            h = b["colour"]
            return int(h[1:3], 16), int(h[3:5], 16), int(h[5:7], 16)
    return WHITE


def from_project(project: dict, assets: dict[str, bytes]) -> tuple[int, int, int]:
    """The colour of a project's stage backdrop as this module writes it (one filled rectangle of
    SVG); white for any other backdrop."""
    import re

    stage = next((t for t in project.get("targets", []) if t.get("isStage")), None)
    costumes = (stage or {}).get("costumes") or []
    if not costumes:
        return WHITE
    c = costumes[min(int(stage.get("currentCostume", 0) or 0), len(costumes) - 1)]
    data = assets.get(c.get("md5ext") or f"{c.get('assetId')}.{c.get('dataFormat')}", b"")
    m = re.fullmatch(rb'<svg [^>]*><rect width="480" height="360" fill="#([0-9a-f]{6})"/></svg>', data)
    if not m:
        return WHITE
    h = m.group(1).decode()
    return int(h[0:2], 16), int(h[2:4], 16), int(h[4:6], 16)
