"""The BVH view in Python: the picture the reader sprite's ``bvh view`` paints at the green flag
(``export.green_flag = "bvh"``), computed from the lists as written::

    view = bvh_view(lists, cam, cell=8, layout="quantised", bits=6)   # or view_from_report(lists, report)
    view.tri, view.rgb            # (rows, cols): the triangle each cell's ray hits (1-based, 0 = miss), its colour
    view.stage(background)        # (360, 480, 3) uint8: the stage as the pen paints it

Every step is the blocks' own (bake/scratch/reader_bvh.py, ``bvh_view_part``): the cell centres
``sx = (cell / 2) - 240`` then ``+ cell`` per column, ``sy = 180 - (cell / 2)`` then ``+ (0 - cell)``
per row; the camera ray through them (:func:`view_rays`, the same float operations in the same
order, with Scratch's 10-decimal sine and cosine); the closest hit through the BVH lists
(``bake.bvh.traverse.trace``, bit for bit the ``bvh ray`` block); the hit's colour from ``tri
colors`` at the scene triangle number ``bvh tri ids`` gives (the written triangle order: the BVH
is built after the BSP stage reorders triangles, and the export writes them in that order), else
from ``mat colors`` at that triangle's material. :meth:`BVHView.stage` composites the pen's dots in
the order the blocks paint them, each a disc of ``view_pen_size(cell)`` with the pen shader's
one-pixel antialiased edge.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Mapping

import numpy as np

from ..bvh.encode import BIN_STRIDE, WIDE_HEADER, Encoded
from ..bvh.traverse import trace
from ..scratch.colors import decode_numbers
from ..scratch.layout import join, names_of
from ..scratch.reader_bvh import view_grid, view_pen_size
from ..scratch.readers import Camera, scratch_cos, scratch_sin

STAGE_W, STAGE_H = 480, 360
#: the blocks' colour when the bake wrote neither ``tri colors`` nor ``mat colors``
GREY = (128, 128, 128)


def cell_centres(cell: float) -> tuple[np.ndarray, np.ndarray]:
    """(sx per column, sy per row) of the cells' centres, accumulated as the blocks change
    ``_gx`` and ``_gy``."""
    rows, cols = view_grid(cell)
    sx = np.empty(cols)
    x = cell / 2 - 240
    for j in range(cols):
        sx[j] = x
        x = x + cell
    sy = np.empty(rows)
    y = 180 - cell / 2
    for i in range(rows):
        sy[i] = y
        y = y + (0 - cell)
    return sx, sy


def view_rays(cam: Camera, sx: np.ndarray, sy: np.ndarray) -> np.ndarray:
    """(N, 3) directions of the camera's rays through the stage points ``(sx, sy)`` (arrays of
    one shape, flattened), exactly as ``camera ray (sx) (sy)`` computes them (the origin is the
    camera's position)."""
    s, c = scratch_sin(cam.yaw), scratch_cos(cam.yaw)
    sp, cp = scratch_sin(cam.pitch), scratch_cos(cam.pitch)
    f = float(cam.focal)
    x = np.asarray(sx, np.float64).ravel()
    y = np.asarray(sy, np.float64).ravel()
    dx = ((c * x) - ((s * sp) * y)) + ((s * cp) * f)
    dy = (cp * y) + (sp * f)
    dz = ((0.0 - (s * x)) - ((c * sp) * y)) + ((c * cp) * f)
    return np.stack([dx, dy, dz], axis=1)


def encoded_from_lists(lists: Mapping[str, list], layout: str, bits: int = 0,
                       names: Mapping[str, str] | None = None) -> Encoded:
    """The BVH as its walk reads it, from the lists as written (``names``: role ``nodes``,
    ``tris``, ``ids`` -> list name; the defaults' ``bvh nodes`` ...)."""
    n = {"nodes": "bvh nodes", "tris": "bvh tris", "ids": "bvh tri ids", **dict(names or {})}
    stride = {"binary": BIN_STRIDE, "wide4": 27, "quantised": 7}[layout]
    return Encoded(layout, np.asarray(lists[n["nodes"]], np.float64), np.asarray(lists[n["tris"]], np.float64),
                   np.asarray(lists[n["ids"]], np.int64), 0, stride, header=0 if layout == "binary" else WIDE_HEADER,
                   bits=int(bits) if layout == "quantised" else 0)


def _rgb(items: list) -> np.ndarray:
    a = np.asarray(items)
    return decode_numbers(a if np.issubdtype(a.dtype, np.integer) else list(items))[:, :3]


def triangle_colours(lists: Mapping[str, list], export: Mapping[str, Any] | None = None) -> tuple[np.ndarray, str]:
    """(T, 3) uint8: the colour the blocks give each written triangle (``tri colors``, else its
    material's ``mat colors``, else grey), and which list it came from. ``export``: report.json's
    export section (list names, faces, index base) for the layouts of docs/engines.md."""
    export = dict(export or {})
    names = names_of(export.get("names") or {})
    book = join(lists, names, export.get("faces", "triangles"), export.get("index_base", 1))
    n_tris = len(book.get("triangles", [])) // 4
    tc, mc = names.get("triangle_colors"), names.get("materials")
    if isinstance(tc, str) and tc in lists:
        return _rgb(lists[tc]), tc
    if isinstance(mc, str) and mc in lists and n_tris:
        mats = np.asarray(book["triangles"], np.int64).reshape(-1, 4)[:, 3] - 1
        return _rgb(lists[mc])[mats], mc
    return np.tile(np.asarray(GREY, np.uint8), (n_tris, 1)), "grey"


@dataclass
class BVHView:
    """The BVH view's cells (``rows x cols``, row 0 at the top) for one camera."""

    cell: int
    cam: Camera
    sx: np.ndarray  # (cols,) stage x of each column's centres
    sy: np.ndarray  # (rows,) stage y of each row's centres
    tri: np.ndarray  # (rows, cols) scene triangle number hit (1-based; 0: the ray missed)
    t: np.ndarray  # (rows, cols) the hit's distance along the ray (inf on a miss)
    rgb: np.ndarray  # (rows, cols, 3) uint8 the colour painted (0 where nothing is)
    colours: str = ""  # the list the colours came from
    reads: int = 0  # BVH list items read by all the rays

    @property
    def hit(self) -> np.ndarray:
        return self.tri > 0

    @property
    def pen_size(self) -> float:
        return view_pen_size(self.cell)

    def samples(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(row, column, on stage) per cell: the stage pixel a cell is read at, the one whose
        centre is the cell's centre, or for an even cell the one up and left of it (away from the
        cells painted after it, whose dots reach into this cell from the right and below)."""
        rows, cols = self.tri.shape
        k = (self.cell - 1) // 2
        r = (np.arange(rows) * self.cell + k)[:, None].repeat(cols, 1)
        c = (np.arange(cols) * self.cell + k)[None, :].repeat(rows, 0)
        return r, c, (r < STAGE_H) & (c < STAGE_W)

    def stage(self, background=(255, 255, 255)) -> np.ndarray:
        """(360, 480, 3) uint8: the stage after ``bvh view``, the dots composited in the order
        the blocks paint them, each covering ``clamp((size + 1) / 2 - distance, 0, 1)`` of a pixel
        (the pen shader's round line of no length), on ``background``."""
        return np.clip(np.rint(self._composite(background)), 0, 255).astype(np.uint8)

    def _composite(self, background) -> np.ndarray:
        rows, cols = self.tri.shape
        w = self.pen_size
        px = -240 + np.arange(STAGE_W) + 0.5
        py = 180 - np.arange(STAGE_H) - 0.5
        img = np.empty((STAGE_H, STAGE_W, 3))
        img[:] = np.asarray(background, np.float64)[:3]
        # the cell holding each pixel centre, and its neighbours: no dot reaches farther
        ci = np.minimum(np.arange(STAGE_H) // self.cell, rows - 1)
        cj = np.minimum(np.arange(STAGE_W) // self.cell, cols - 1)
        for di in (-1, 0, 1):  # in the order the blocks paint: rows from the top, then columns
            for dj in (-1, 0, 1):
                i, j = ci + di, cj + dj
                ok = ((i >= 0) & (i < rows))[:, None] & ((j >= 0) & (j < cols))[None, :]
                ii, jj = np.clip(i, 0, rows - 1), np.clip(j, 0, cols - 1)
                hit = self.hit[ii[:, None], jj[None, :]] & ok
                d = np.hypot(px[None, :] - self.sx[jj][None, :], py[:, None] - self.sy[ii][:, None])
                a = np.where(hit, np.clip((w + 1) / 2 - d, 0.0, 1.0), 0.0)[..., None]
                col = self.rgb[ii[:, None], jj[None, :]].astype(np.float64)
                img = a * col + (1 - a) * img
        return img

    def to_json(self) -> dict[str, Any]:
        rows, cols = self.tri.shape
        return {"cell": self.cell, "rows": rows, "columns": cols, "rays": rows * cols,
                "hit_cells": int(self.hit.sum()), "pen_size": self.pen_size, "colours": self.colours,
                "bvh_items_read": self.reads}


def bvh_view(lists: Mapping[str, list], cam: Camera, cell: int, layout: str, bits: int = 0, *,
             names: Mapping[str, str] | None = None, export: Mapping[str, Any] | None = None) -> BVHView:
    """The cells of the BVH view for camera ``cam`` (the reader's: position, yaw, pitch, focal)
    from the lists as written (``names``: the BVH lists', see :func:`encoded_from_lists`;
    ``export``: report.json's export section, for the mesh lists' names and layout)."""
    sx, sy = cell_centres(cell)
    gx, gy = np.meshgrid(sx, sy)
    d = view_rays(cam, gx, gy)
    o = np.tile(np.array([cam.x, cam.y, cam.z], np.float64), (len(d), 1))
    hits = trace(encoded_from_lists(lists, layout, bits, names), o, d)
    shape = gy.shape
    tri = hits.tri.reshape(shape)
    colours, source = triangle_colours(lists, export)
    rgb = np.zeros((*shape, 3), np.uint8)
    h = tri > 0
    rgb[h] = colours[tri[h] - 1]
    return BVHView(cell, cam, sx, sy, tri, hits.t.reshape(shape), rgb, source, int(hits.reads.sum()))


def view_from_report(lists: Mapping[str, list], report: Mapping[str, Any]) -> BVHView | None:
    """The green flag's BVH view of a bake (report.json and its lists), or None when the bake
    does not draw one (``export.green_flag`` is not ``"bvh"``, no .sb3 or reader sprite was
    written, or it wrote no BVH or mesh)."""
    from ..scratch.project import auto_camera

    export = (report.get("config") or {}).get("export") or {}
    if export.get("green_flag", "raster") != "bvh" or export.get("reader", True) is False \
            or export.get("sb3", True) is False:
        return None
    bvh = next((s.get("details") or {} for s in report.get("stages", []) if s.get("name") == "bvh"), None)
    if not bvh or not bvh.get("layout"):
        return None
    names = bvh.get("lists") or {}
    book = join(lists, names_of(export.get("names") or {}), export.get("faces", "triangles"),
                export.get("index_base", 1))
    if "vertices" not in book or "triangles" not in book or not all(n in lists for n in names.values()):
        return None
    return bvh_view(lists, auto_camera(book["vertices"]), int(export.get("bvh_cell", 8)), bvh["layout"],
                    int(bvh.get("quant_bits") or 0), names=names, export=export)


def view_agreement(stage: np.ndarray, view: BVHView, background=(255, 255, 255)) -> dict[str, Any]:
    """A player's stage image (360, 480, 3 uint8) against the view: at each cell's sample pixel
    (:meth:`BVHView.samples`, on the stage), the largest channel difference from the cell's
    colour for the cells that hit (``within_0``, ``within_1``, ``within_2``: fractions of them;
    ``hit_left_blank``: how many show the background though their colour is more than a level
    from it), and for the cells that missed, how many the player painted (``empty_painted``: not
    exactly ``background``); over the whole stage, the fraction of pixels within 1 and 2 levels
    of :meth:`BVHView.stage` and the largest difference (the model composites the dots'
    antialiased edges in floating point where the pen layer rounds each dot to 8 bits, so they
    may be a few levels apart there)."""
    r, c, on = view.samples()
    got = stage[r[on], c[on]].astype(np.int16)
    want = view.rgb[on].astype(np.int16)
    hit = view.hit[on]
    d = np.abs(got - want).max(1)[hit]
    bg = np.all(got == np.asarray(background, np.int16)[:3], axis=1)
    # a hit cell shows the background when its sample is the background though its colour is not
    far = np.abs(want - np.asarray(background, np.int16)[:3]).max(1) > 1
    n = int(hit.sum())

    def frac(x):
        return float(x.sum() / n) if n else 0.0

    model = view.stage(background).astype(np.int16)
    full = np.abs(stage.astype(np.int16) - model).max(2)
    return {"cells": int(on.sum()), "hit_cells": n, "empty_cells": int((~hit).sum()),
            "within_0": frac(d <= 0), "within_1": frac(d <= 1), "within_2": frac(d <= 2),
            "max_difference": int(d.max()) if n else 0, "hit_left_blank": int((bg & far)[hit].sum()),
            "empty_painted": int((~bg[~hit]).sum()),
            "pixels_within_1": float((full <= 1).mean()), "pixels_within_2": float((full <= 2).mean()),
            "pixels_max_difference": int(full.max())}
