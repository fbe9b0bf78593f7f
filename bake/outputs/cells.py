"""The textured filler's picture in Python: what the reader sprite's ``render`` draws cell by cell
(``bake.scratch.reader_texture``) when the bake wrote a texture or a lightmap, with the blocks'
arithmetic in the blocks' order (doubles, as JavaScript computes them), so report.html's
green-flag preview of a textured bake and the player suite's comparison show what the stage will
show.

Vectorised over (triangle, cell row) pairs and their cells; the per-cell steps of ``q``, ``U`` and
``V`` are summed left to right (``np.add.accumulate``), as the blocks add them, and the painter's
order decides each cell (the last triangle drawn there).
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from ..scratch import readers
from ..scratch.colors import decode_numbers
from ..scratch.reader_texture import STAGE_H, STAGE_W, TextureSpec, grid


@dataclass
class CellPicture:
    """The frame: ``colour`` (rows, cols) colour numbers of the cells (-1: nothing drawn),
    ``tri`` the 0-based triangle that drew each cell (-1), ``cell`` the cell size."""

    colour: np.ndarray
    tri: np.ndarray
    cell: int

    def image(self, background=(255, 255, 255)) -> np.ndarray:
        """(360, 480, 3) uint8: each drawn cell's pixels in its colour."""
        s = self.cell
        rgb = np.empty(self.colour.shape + (3,), np.uint8)
        rgb[:] = np.asarray(background, np.uint8)[:3]
        drawn = self.colour >= 0
        if drawn.any():
            rgb[drawn] = decode_numbers(self.colour[drawn])[:, :3].astype(np.uint8)
        return np.repeat(np.repeat(rgb, s, axis=0), s, axis=1)

    def painted(self) -> np.ndarray:
        """(360, 480) bool: the pixels the filler paints."""
        s = self.cell
        return np.repeat(np.repeat(self.colour >= 0, s, axis=0), s, axis=1)


def texture_colours(spec: TextureSpec, lists: dict[str, list]) -> np.ndarray:
    """``_tex`` as the sprite loads it: every source's colour numbers, one after another."""
    from ..scratch import colors, textimage

    parts = []
    for s in spec.sources:
        if s.kind == "textimage":  # ``ti colors``: bottom row first, argb with an alpha layer
            img = textimage.decode(lists[s.list][0])
            mode = "argb" if img.ndim == 3 and img.shape[2] == 4 else "rgb"
            parts.append(np.asarray(colors.image_to_list(img, mode, first_row="bottom"), np.int64))
        else:
            parts.append(colour_numbers(lists[s.list]))
    return np.concatenate(parts) if parts else np.zeros(0, np.int64)


def colour_numbers(items: Sequence[Any]) -> np.ndarray:
    """Colour list items (numbers, or "#rrggbb" strings) as RGB colour numbers, as the pen reads
    them (``bake.scratch.colors.decode_numbers``; an alpha byte is dropped)."""
    arr = np.asarray(items)
    rgba = decode_numbers(arr.astype(np.int64) if arr.dtype.kind in "iuf" else list(items)).astype(np.int64)
    return (rgba[:, 0] << 16) | (rgba[:, 1] << 8) | rgba[:, 2]


def _scratch_mod(a: np.ndarray, m: np.ndarray) -> np.ndarray:
    r = np.fmod(a, m)
    return np.where((r != 0) & ((r < 0) != (m < 0)), r + m, r)


def picture(verts: np.ndarray, tris: np.ndarray, order: np.ndarray, cam: readers.Camera, spec: TextureSpec,
            uvs: Sequence[float], tex: np.ndarray, flat: np.ndarray, material: np.ndarray,
            two_sided: Sequence[int] = ()) -> CellPicture:
    """The cells ``render`` paints. ``verts`` (V, 3) and ``tris`` (T, 4, 1-based) the book's lists;
    ``order``: 0-based triangles in the order the frame visits them (the BSP walk's ranges, or
    the list); ``uvs``: the UV list the filler reads (6 a triangle); ``tex``: ``_tex``
    (:func:`texture_colours`); ``flat``: each triangle's flat colour number; ``material``: each
    triangle's 0-based material."""
    s = spec.cell
    rows_n, cols_n = STAGE_H // s, STAGE_W // s
    colour = np.full((rows_n, cols_n), -1, np.int64)
    owner = np.full((rows_n, cols_n), -1, np.int64)
    t = np.asarray(tris, np.int64).reshape(-1, 4)
    px, py, pz = readers.project(np.asarray(verts, np.float64).reshape(-1, 3), cam)
    ok = readers.drawn(np.asarray(verts, np.float64).reshape(-1, 3), t, cam, two_sided)
    order = np.asarray(order, np.int64)
    order = order[ok[order]] if len(order) else order
    if not len(order):
        return CellPicture(colour, owner, s)
    i = t[order, :3] - 1
    ax, ay, bx, by, cx, cy = px[i[:, 0]], py[i[:, 0]], px[i[:, 1]], py[i[:, 1]], px[i[:, 2]], py[i[:, 2]]
    off_l, tw_l, th_l, top_l = (np.asarray(x) for x in spec.tables())
    m = material[order]
    toff = off_l[m].astype(np.float64)
    tw, th, top = tw_l[m].astype(np.float64), th_l[m].astype(np.float64), top_l[m] == 1
    textured = toff >= 0
    den = ((bx - ax) * (cy - ay)) - ((by - ay) * (cx - ax))
    uv = np.asarray(uvs, np.float64).reshape(-1, 6)[order] if len(uvs) else np.zeros((len(order), 6))
    grads = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        q = [1.0 / pz[i[:, k]] for k in range(3)]
        U = [(uv[:, 2 * k] * tw) * q[k] for k in range(3)]
        V = [np.where(top, ((1.0 - uv[:, 2 * k + 1]) * th) * q[k], (uv[:, 2 * k + 1] * th) * q[k]) for k in range(3)]
        for name, (fa, fb, fc) in (("q", q), ("U", U), ("V", V)):
            fx = (((fb - fa) * (cy - ay)) - ((fc - fa) * (by - ay))) / den
            fy = (((fc - fa) * (bx - ax)) - ((fb - fa) * (cx - ax))) / den
            grads[name] = (fa, fx, fy)
    D, C = grid(s)
    # the corners sorted top, middle, bottom by stage y, as the blocks bubble them (ties keep order)
    Tx, Ty, Mx, My, Bx, By = ax.copy(), ay.copy(), bx.copy(), by.copy(), cx.copy(), cy.copy()
    for hi, lo in (("T", "M"), ("M", "B"), ("T", "M")):
        H_ = {"T": (Tx, Ty), "M": (Mx, My), "B": (Bx, By)}
        (hx, hy), (lx, ly) = H_[hi], H_[lo]
        sw = ly > hy
        hx[sw], lx[sw] = lx[sw].copy(), hx[sw].copy()
        hy[sw], ly[sw] = ly[sw].copy(), hy[sw].copy()
    with np.errstate(divide="ignore", invalid="ignore"):
        sL = (Bx - Tx) / (By - Ty)
        dL = sL * (-s)
        ll = (Tx + ((My - Ty) * sL)) < Mx  # the long edge on the left of both halves
        je = np.where(Ty > My, np.floor((C - My) / s), np.ceil((C - My) / s) - 1)
        halves = [(np.ceil((C - Ty) / s), je, Tx, Ty, Mx, My), (je + 1, np.floor((C - By) / s), Mx, My, Bx, By)]
    # (triangle, row) pairs of both halves: their triangle, row, Y and the edges' x at the row
    parts = []
    for first, end, px_, py_, qx_, qy_ in halves:
        j0 = np.maximum(first, 0).astype(np.int64)
        j1 = np.minimum(end, rows_n - 1).astype(np.int64)
        nrows = np.maximum(j1 - j0 + 1, 0)
        has = np.flatnonzero(nrows > 0)
        if not len(has):
            continue
        with np.errstate(divide="ignore", invalid="ignore"):
            Y0 = C - (s * j0[has].astype(np.float64))
            xL0 = Tx[has] + ((Y0 - Ty[has]) * sL[has])
            sS = (qx_[has] - px_[has]) / (qy_[has] - py_[has])
            dS = sS * (-s)
            xS0 = px_[has] + ((Y0 - py_[has]) * sS)
            h_ll = ll[has]
        width = int(nrows[has].max())
        within_h = np.arange(width)[None, :] < nrows[has][:, None]

        def walk(x0, d):  # the value at each row: the first row's, then + d per row, left to right
            m = np.empty((len(has), width))
            m[:, 0] = x0
            m[:, 1:] = d[:, None]
            return np.add.accumulate(m, axis=1)[within_h]

        parts.append({"k": np.repeat(has, nrows[has]),
                      "row": (j0[has][:, None] + np.arange(width)[None, :])[within_h],
                      "xl": walk(np.where(h_ll, xL0, xS0), np.where(h_ll, dL[has], dS)),
                      "xr": walk(np.where(h_ll, xS0, xL0), np.where(h_ll, dS, dL[has]))})
    if not parts:
        return CellPicture(colour, owner, s)
    cat = {key: np.concatenate([p[key] for p in parts]) for key in parts[0]}
    # back in draw order (a triangle's rows top to bottom), as the blocks visit them
    srt = np.lexsort((cat["row"], cat["k"]))
    cat = {key: v[srt] for key, v in cat.items()}
    k, pair_row, xl, xr = cat["k"], cat["row"], cat["xl"], cat["xr"]
    Y = C - (s * pair_row.astype(np.float64))
    i0 = np.maximum(np.ceil((xl - D) / s), 0).astype(np.int64)
    i1 = np.minimum(np.floor((xr - D) / s), cols_n - 1).astype(np.int64)
    n = np.maximum(i1 - i0 + 1, 0)
    keep = n > 0
    k, Y, i0, n, pair_row = k[keep], Y[keep], i0[keep], n[keep], pair_row[keep]
    if not len(k):
        return CellPicture(colour, owner, s)
    X0 = (s * i0.astype(np.float64)) + D
    # every cell of every pair: its colour
    cell_pair = np.repeat(np.arange(len(k)), n)
    within = np.arange(int(n.sum())) - np.repeat(np.cumsum(n) - n, n)
    cc = np.empty(len(cell_pair), np.int64)
    tk = k[cell_pair]
    flat_cells = ~textured[tk]
    cc[flat_cells] = flat[order][tk[flat_cells]]
    tex_pairs = np.flatnonzero(textured[k])
    if len(tex_pairs):
        width = int(n[tex_pairs].max())
        acc = {}
        for name in ("q", "U", "V"):
            fa, fx, fy = grads[name]
            kk = k[tex_pairs]
            f0 = (fa[kk] + (fx[kk] * (X0[tex_pairs] - ax[kk]))) + (fy[kk] * (Y[tex_pairs] - ay[kk]))
            steps = np.empty((len(tex_pairs), width))
            steps[:, 0] = f0
            steps[:, 1:] = (fx[kk] * s)[:, None]
            acc[name] = np.add.accumulate(steps, axis=1)  # left to right, as `change by` adds them
        sel = textured[tk]
        rowpos = np.searchsorted(tex_pairs, cell_pair[sel])
        col = within[sel]
        qv, Uv, Vv = acc["q"][rowpos, col], acc["U"][rowpos, col], acc["V"][rowpos, col]
        kt = tk[sel]
        with np.errstate(divide="ignore", invalid="ignore"):
            idx = ((_scratch_mod(np.floor(Vv / qv), th[kt]) * tw[kt]) + _scratch_mod(np.floor(Uv / qv), tw[kt])) + \
                (toff[kt] + 1.0)
        idx_i = idx.astype(np.int64) - 1
        good = (idx_i >= 0) & (idx_i < len(tex))
        vals = np.zeros(len(idx_i), np.int64)  # (an item past the list is "": colour 0)
        vals[good] = tex[idx_i[good]]
        cc[sel] = vals
    rows = pair_row[cell_pair]
    cols = i0[cell_pair] + within
    # painter's order: the last triangle to draw a cell decides it (cells are listed in draw order)
    flat_idx = rows * cols_n + cols
    last = np.unique(flat_idx[::-1], return_index=True)[1]
    pick = len(flat_idx) - 1 - last
    colour.ravel()[flat_idx[pick]] = cc[pick]
    owner.ravel()[flat_idx[pick]] = order[tk[pick]]
    return CellPicture(colour, owner, s)


def green_flag(lists: dict[str, list], report: dict[str, Any]) -> tuple[CellPicture, Any] | None:
    """The textured filler's green-flag frame of a bake (lists as written, report.json), and its
    camera; None when the bake's reader has no textured filler."""
    export = next((st for st in report.get("stages", []) if st.get("name") == "export"), {})
    spec_json = export.get("details", {}).get("reader_texture")
    if not spec_json:
        return None
    ex = report.get("config", {}).get("export", {})
    two = [1 if m.get("double_sided") else 0 for m in report.get("materials", [])]
    return frame(lists, TextureSpec.from_json(spec_json), ex.get("names", {}), ex.get("faces", "triangles"),
                 ex.get("index_base", 1), two)


def frame(lists: dict[str, list], spec: TextureSpec, names: Any = None, faces: str = "triangles",
          index_base: int = 1, two_sided: Sequence[int] = ()) -> tuple[CellPicture, Any] | None:
    """The filler's frame for the lists as written in any layout (``export.names``, ``faces``,
    ``index_base``) from the reader's green-flag camera, in its painter's order (the BSP walk's
    ranges, or the list's order), and that camera; None without the mesh or UV lists."""
    from ..bsp.traverse import draw_order
    from ..scratch.layout import join, names_of
    from ..scratch.project import auto_camera

    names = names_of(names)
    book = join(lists, names, faces, index_base)
    if "vertices" not in book or "triangles" not in book or spec.uvs not in lists:
        return None
    v = np.asarray(book["vertices"], np.float64).reshape(-1, 3)
    t = np.asarray(book["triangles"], np.int64).reshape(-1, 4)
    cam = auto_camera(v)
    if "bsp nodes" in lists and "bsp planes" in lists:
        order = np.asarray(draw_order(lists["bsp nodes"], lists["bsp planes"], (cam.x, cam.y, cam.z), cull=False),
                           np.int64) - 1
    else:
        order = np.arange(len(t))
    tname, mname = names["triangle_colors"], names["materials"]
    material = t[:, 3] - 1
    if tname in lists and len(lists[tname]) == len(t):
        flat = colour_numbers(lists[tname])
    elif mname in lists:
        flat = colour_numbers(lists[mname])[np.clip(material, 0, None)]
    else:
        flat = np.full(len(t), 0x808080, np.int64)
    pic = picture(v, t, order, cam, spec, lists[spec.uvs], texture_colours(spec, lists), flat, material, two_sided)
    return pic, cam


def agreement(stage: np.ndarray, pic: CellPicture, background=(255, 255, 255)) -> dict[str, Any]:
    """A player's stage (360, 480, 3 uint8) against the filler's picture: of the painted pixels,
    the fractions within 1 and within 8 levels (largest channel difference; the pen's HSV round
    trip moves a channel by 1, and a stroke next to a pixel drawn earlier tints it by about 1% of
    their difference), and the pixels farther than one pixel from every painted one that are
    not the background."""
    want = pic.image(background)
    painted = pic.painted()
    d = np.abs(stage.astype(np.int16) - want.astype(np.int16)).max(axis=2)
    near = painted.copy()
    near[1:] |= painted[:-1]
    near[:-1] |= painted[1:]
    near[:, 1:] |= near[:, :-1].copy()
    near[:, :-1] |= near[:, 1:].copy()
    n = int(painted.sum())
    return {"painted_pixels": n,
            "within_1": float((d[painted] <= 1).mean()) if n else 0.0,
            "within_8": float((d[painted] <= 8).mean()) if n else 0.0,
            "empty_painted": int(((~near) & (d > 8)).sum())}
