"""Previews of a finished bake, rendered from what Scratch will get: the written lists.

Everything here reads the output folder's ``lists.json`` (and the .sb3's costumes), never the
in-memory scene, so a preview shows the rounded positions, the encoded colour numbers and the
decoded lightmap exactly as a Scratch project loads them::

    mesh = mesh_from_lists(lists, report)            # lists: name -> items, report: report.json
    views = render_views(mesh, width=320, height=240)
    for v in views:
        v.painter, v.zbuffer, v.diff                  # (H, W, 3) uint8 images
        v.stats                                       # wrong pixels, ties, order used

The painter's image draws the triangles in the order a Scratch painter engine would: the BSP walk
of ``bsp nodes`` / ``bsp planes`` for the camera (bake/bsp/traverse.py, the reference model of
the reader sprite's ``bsp walk`` block), or, without a BSP tree, the book's painter's sort by
centroid depth, except the green flag's view, which draws as the reader sprite does: without a
tree, in the list's order. The z-buffer image is the exact reference; the difference image marks pixels
where the painter shows another triangle in a visibly different colour: red where the order is
wrong, orange on a triangle's edge (rasterization of slivers), yellow where the two faces are
coplanar to the bake (either order is right; see bake/bsp/verify.py).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from ..scratch.layout import join
from ..render import Camera, Image, headlight, render
from ..scratch import backdrop
from ..scratch.colors import decode_numbers

#: two pixels differ visibly when a channel differs by more than this (0..255)
VISIBLE = 2


@dataclass
class Mesh:
    """The mesh as a Scratch project reads it back from the lists (0-based arrays)."""
    verts: np.ndarray  # (V, 3) float64
    tris: np.ndarray  # (T, 3) int64, 0-based
    material: np.ndarray  # (T,) int64, 0-based
    mat_rgb: np.ndarray  # (M, 3) float 0..1
    two_sided: np.ndarray  # (M,) bool
    tri_rgb: np.ndarray | None = None  # (T, 3) baked triangle colours
    vert_rgb: np.ndarray | None = None  # (V, 3) baked vertex colours
    vertex_output: str = "color"  # "light": the engine multiplies the material colour
    lightmap: np.ndarray | None = None  # (H, W, 3) float, row 0 at the top
    lightmap_uvs: np.ndarray | None = None  # (T, 3, 2), v up
    bsp_nodes: list | None = None
    bsp_planes: list | None = None
    colour_source: str = "material colours"
    notes: list[str] = field(default_factory=list)
    # the .sb3's stage backdrop (bake.scratch.backdrop): what the green flag's view is drawn on
    backdrop: tuple[int, int, int] = (255, 255, 255)

    @property
    def flat_tris(self) -> list:
        """The ``tris`` list as Scratch holds it (1-based, stride 4)."""
        return np.c_[self.tris + 1, self.material + 1].ravel().tolist()

    @property
    def corners(self) -> np.ndarray:
        return self.verts[self.tris]


def _rgb(items) -> np.ndarray:
    return decode_numbers(items)[:, :3].astype(np.float64) / 255.0


def mesh_from_lists(lists: dict[str, list], report: dict[str, Any],
                    lightmap: np.ndarray | None = None) -> Mesh | None:
    """Read the mesh lists back. ``report`` is report.json (for list names, the colour settings
    and which materials are two-sided). ``lightmap``: the decoded lightmap image if one was
    written. Returns None when the bake wrote no vertex or triangle list."""
    cfg = report.get("config", {})
    export = cfg.get("export", {})
    names = export.get("names", {})
    # any layout (split, 0-based, soup) read back in the book's (bake/scratch/layout.py)
    book = join(lists, names, export.get("faces", "triangles"), export.get("index_base", 1))
    if "vertices" not in book or "triangles" not in book:
        return None
    verts = np.asarray(book["vertices"], np.float64).reshape(-1, 3)
    t = np.asarray(book["triangles"], np.int64).reshape(-1, 4)
    mats = report.get("materials") or []
    mname = names.get("materials", "mat colors")
    if mname in lists:
        mat_rgb = _rgb(lists[mname])
    elif mats:
        mat_rgb = np.array([m["color"][:3] for m in mats], np.float64)
    else:
        mat_rgb = np.ones((max(int(t[:, 3].max(initial=1)), 1), 3))
    two = np.zeros(len(mat_rgb), bool)
    for i, m in enumerate(mats[:len(two)]):
        two[i] = bool(m.get("double_sided"))
    mesh = Mesh(verts=verts, tris=t[:, :3] - 1, material=np.clip(t[:, 3] - 1, 0, len(mat_rgb) - 1),
                mat_rgb=mat_rgb, two_sided=two,
                vertex_output=cfg.get("lighting", {}).get("vertex_output", "color"),
                backdrop=backdrop.from_report(report))
    cname, vcname = names.get("triangle_colors", "tri colors"), names.get("vertex_colors", "vert colors")
    if cname in lists and len(lists[cname]) == len(t):
        mesh.tri_rgb = _rgb(lists[cname])
    if vcname in lists and len(lists[vcname]) == len(verts):
        mesh.vert_rgb = _rgb(lists[vcname])
    lm = book.get("lightmap_uvs")
    if lightmap is not None and lm is not None and len(lm) == 6 * len(t):
        mesh.lightmap = lightmap
        mesh.lightmap_uvs = np.asarray(lm, np.float64).reshape(-1, 3, 2)
    if "bsp nodes" in lists and "bsp planes" in lists:
        mesh.bsp_nodes, mesh.bsp_planes = lists["bsp nodes"], lists["bsp planes"]
    mesh.colour_source = ("lightmap (bilinear)" if mesh.lightmap is not None else
                          f"'{cname}' (flat per triangle)" if mesh.tri_rgb is not None else
                          f"'{vcname}' (interpolated)" if mesh.vert_rgb is not None else
                          f"'{mname}' with a headlight")
    return mesh


# --------------------------------------------------------------------------- cameras
def stage_camera(cam, width: int = 480) -> Camera:
    """The reader sprite's camera (``bake.scratch.readers.Camera``: position, yaw, pitch, focal on
    the 480 x 360 stage) as a render camera ``width`` pixels wide, so a preview shows exactly the
    stage the green flag draws (scaled): the same projection, the same mirror sense."""
    scale = width / 480.0
    return Camera.yaw_pitch((cam.x, cam.y, cam.z), cam.yaw, cam.pitch, cam.focal * scale, width=width,
                            height=int(round(360 * scale)), near=cam.near)


def cameras(verts: np.ndarray, width: int = 320, height: int = 240, fov: float = 45.0
            ) -> list[tuple[str, Camera]]:
    """Four views: the green flag's (the reader sprite's camera, :func:`bake.scratch.project.auto_camera`,
    on a stage-shaped image ``width`` wide; plain material colours flat, as the reader draws
    them), then three that frame the model's bounding sphere:
    front right above, back left, top. The frame is the export's (x right, y up, z into the
    screen): "front" looks along +z, "right" is +x."""
    from ..scratch.project import auto_camera

    out = [("green flag", stage_camera(auto_camera(verts), width))] if len(verts) else []
    lo, hi = verts.min(0), verts.max(0)
    c = (lo + hi) / 2.0
    r = max(float(np.linalg.norm(hi - lo)) / 2.0, 1e-12)
    tan_v = math.tan(math.radians(fov) / 2.0)
    tan_h = tan_v * width / height
    for name, az, el in (("front right", 35.0, 25.0), ("back left", -145.0, 20.0), ("top", 10.0, 80.0)):
        a, e = math.radians(az), math.radians(el)
        d = np.array([math.sin(a) * math.cos(e), math.sin(e), -math.cos(a) * math.cos(e)])
        probe = Camera(position=tuple(c + d), look_at=tuple(c), fov=fov, width=width, height=height)
        _, right, up, fwd = probe.basis()
        rel = verts - c  # the distance at which every vertex is inside the frame, plus 6 %
        x, y, z = rel @ right, rel @ up, rel @ fwd
        dist = float(np.max(np.maximum(np.abs(x) / tan_h, np.abs(y) / tan_v) - z)) * 1.06
        dist = max(dist, 1e-9 * r)
        out.append((name, Camera(position=tuple(c + dist * d), look_at=tuple(c), fov=fov, width=width,
                                 height=height, near=max(dist - 1.5 * r, dist * 1e-4))))
    return out


# --------------------------------------------------------------------------- shading
def pixel_barycentrics(camera: Camera, corners: np.ndarray, tri_id: np.ndarray) -> np.ndarray:
    """(H, W, 3) barycentric weights of each covered pixel centre's ray on the triangle seen there
    (perspective-correct: the ray meets the triangle's plane). Background pixels get 0."""
    H, W = tri_id.shape
    out = np.zeros((H, W, 3))
    ys, xs = np.nonzero(tri_id >= 0)
    if len(ys) == 0:
        return out
    eye, r, u, f = camera.basis()
    fl = camera.focal
    d = f + ((xs + 0.5 - W / 2.0) / fl)[:, None] * r - ((ys + 0.5 - H / 2.0) / fl)[:, None] * u
    p = corners[tri_id[ys, xs]]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    h = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, h)
    det = np.where(np.abs(det) > 0, det, 1e-300)
    s = eye - p[:, 0]
    b1 = np.einsum("ij,ij->i", s, h) / det
    b2 = np.einsum("ij,ij->i", d, np.cross(s, e1)) / det
    w = np.clip(np.stack([1.0 - b1 - b2, b1, b2], 1), 0.0, 1.0)
    w /= np.maximum(w.sum(1, keepdims=True), 1e-300)
    out[ys, xs] = w
    return out


def _bilinear(img: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Sample an (H, W, 3) image (row 0 at the top) at uv in [0, 1] (v up), texel centres at
    (i + 0.5) / W, clamped at the edges."""
    H, W = img.shape[:2]
    x = np.clip(uv[:, 0] * W - 0.5, 0, W - 1)
    y = np.clip((1.0 - uv[:, 1]) * H - 0.5, 0, H - 1)
    x0, y0 = np.floor(x).astype(np.int64), np.floor(y).astype(np.int64)
    x1, y1 = np.minimum(x0 + 1, W - 1), np.minimum(y0 + 1, H - 1)
    fx, fy = (x - x0)[:, None], (y - y0)[:, None]
    top = img[y0, x0] * (1 - fx) + img[y0, x1] * fx
    bot = img[y1, x0] * (1 - fx) + img[y1, x1] * fx
    return top * (1 - fy) + bot * fy


def shade(mesh: Mesh, camera: Camera, im: Image, background=(1.0, 1.0, 1.0), *, light: bool = True) -> np.ndarray:
    """(H, W, 3) uint8: the colour Scratch shows at each pixel of a render (see
    :attr:`Mesh.colour_source`). ``light=False``: plain material colours stay flat, as the
    reader sprite draws them (no headlight)."""
    H, W = im.tri_id.shape
    img = np.empty((H, W, 3))
    img[:] = np.asarray(background, np.float64)[:3]
    cov = im.tri_id >= 0
    tid = im.tri_id[cov]
    if len(tid):
        if mesh.lightmap is not None or (mesh.tri_rgb is None and mesh.vert_rgb is not None):
            w = pixel_barycentrics(camera, mesh.corners, im.tri_id)[cov]
        if mesh.lightmap is not None:
            uv = np.einsum("nk,nkj->nj", w, mesh.lightmap_uvs[tid])
            col = _bilinear(mesh.lightmap, uv)
            if mesh.vertex_output == "light":
                col = col * mesh.mat_rgb[mesh.material[tid]]
        elif mesh.tri_rgb is not None:
            col = mesh.tri_rgb[tid]
        elif mesh.vert_rgb is not None:
            col = np.einsum("nk,nkj->nj", w, mesh.vert_rgb[mesh.tris[tid]])
            if mesh.vertex_output == "light":
                col = col * mesh.mat_rgb[mesh.material[tid]]
        else:  # plain material colours: a headlight so the shape reads
            col = mesh.mat_rgb[mesh.material[tid]]
            if light:
                col = col * headlight(mesh.corners[tid], camera)[:, None]
        img[cov] = col
    return np.clip(np.rint(img * 255.0), 0, 255).astype(np.uint8)


# --------------------------------------------------------------------------- painter's order
def painter_order(mesh: Mesh, eye, reader: bool = False) -> tuple[np.ndarray, str]:
    """0-based draw order for a painter's engine at ``eye`` and how it was made. ``reader``: the
    reader sprite's own order (its green flag), which without a BSP tree is the list's order (it
    does not sort) where an engine would sort by centroid."""
    if mesh.bsp_nodes is not None:
        from ..bsp.traverse import draw_order, facing_flags

        flat = mesh.flat_tris
        verts = mesh.verts.ravel().tolist()
        face = facing_flags(flat, verts, eye, mesh.two_sided)
        order = draw_order(mesh.bsp_nodes, mesh.bsp_planes, eye, flat, verts, mesh.two_sided, facing=face)
        return np.asarray(order, np.int64) - 1, "BSP walk of 'bsp nodes' / 'bsp planes'"
    if reader:
        return np.arange(len(mesh.tris)), "the list's order (no BSP tree: the reader sprite does not sort)"
    depth = np.linalg.norm(mesh.corners.mean(1) - np.asarray(eye, np.float64), axis=1)
    return np.argsort(-depth, kind="stable"), "painter's sort by centroid distance (no BSP tree)"


@dataclass
class View:
    name: str
    camera: Camera
    painter: np.ndarray  # (H, W, 3) uint8
    zbuffer: np.ndarray
    diff: np.ndarray
    stats: dict[str, Any]


def difference(painter: Image, zbuf: Image, pimg: np.ndarray, zimg: np.ndarray, camera: Camera,
               corners: np.ndarray, tie_tol: float, edge_px: float = 1.0) -> tuple[np.ndarray, dict[str, Any]]:
    """The difference image and its pixel counts. Where the painter shows another triangle than
    the depth buffer, the pixel is a *tie* when the two faces are within ``tie_tol`` of each
    other's plane there (coplanar to the bake: either order is right), an *edge* pixel when its
    centre is within ``edge_px`` of either triangle's edge, else *wrong* (a visible order error).
    Drawn on the faded depth-buffer render: wrong red, edge orange, tie yellow; pixels whose
    colour does not change are not marked (the author cannot see them)."""
    tie, edge = mismatch_kinds(painter, zbuf, camera, corners, tie_tol, edge_px)
    return _difference(painter.tri_id, zbuf.tri_id, tie, edge, pimg, zimg)


def mismatch_kinds(painter: Image, zbuf: Image, camera: Camera, corners: np.ndarray, tie_tol: float,
                   edge_px: float = 1.0) -> tuple[np.ndarray, np.ndarray]:
    """(tie, edge) masks of :func:`difference`: what the geometry alone decides (no colour)."""
    from ..bsp.verify import near_coplanar

    mis = (painter.tri_id != zbuf.tri_id) & zbuf.covered
    tie = mis & near_coplanar(camera, corners, zbuf, painter, mis, tie_tol)
    edge = mis & ~tie & ((zbuf.edge <= edge_px) | (painter.edge <= edge_px))
    return tie, edge


def _difference(p_id: np.ndarray, z_id: np.ndarray, tie: np.ndarray, edge: np.ndarray, pimg: np.ndarray,
                zimg: np.ndarray) -> tuple[np.ndarray, dict[str, Any]]:
    covered_mask = z_id >= 0
    mis = (p_id != z_id) & covered_mask
    visible = np.abs(pimg.astype(np.int16) - zimg.astype(np.int16)).max(2) > VISIBLE
    wrong = mis & ~tie & ~edge & visible
    out = np.rint(zimg.astype(np.float64) * 0.25 + 0.75 * 255).astype(np.uint8)
    out[tie & visible] = (240, 200, 0)
    out[edge & visible] = (245, 140, 30)
    out[wrong] = (220, 0, 0)
    covered = int(covered_mask.sum())
    return out, {"covered_pixels": covered, "wrong_pixels": int(wrong.sum()),
                 "edge_pixels": int((edge & visible).sum()), "tie_pixels": int((tie & visible).sum()),
                 "unseen_differences": int((mis & ~visible).sum()),
                 "wrong_fraction": float(wrong.sum() / covered) if covered else 0.0}


def render_view(mesh: Mesh, name: str, cam: Camera, tie: float = 1e-5, *, light: bool = True,
                memo: Any = None, reader: bool = False) -> tuple[View, Image]:
    """One view (see :func:`render_views`) and the painter's :class:`bake.render.Image` behind it
    (which triangle each pixel shows, how far it is from that triangle's edge). ``light``: see
    :func:`shade`; ``reader``: draw in the reader sprite's order (:func:`painter_order`).

    ``memo`` (a :class:`bake.cache.Memo`): the renders' geometry -- which triangle each pixel
    shows in both renders, the tie and edge pixels, the draw order's size and origin -- depends
    on the written positions, triangles, sidedness, the BSP lists and the camera, not on the
    colours, so it is stored under those and reused by a bake that changed only colours; the
    colours, the difference image and its counts are computed again. (The painter's image it
    returns then has ``tri_id`` only.)"""
    corners = mesh.corners
    diag = float(np.linalg.norm(mesh.verts.max(0) - mesh.verts.min(0))) if len(mesh.verts) else 1.0
    two = mesh.two_sided[mesh.material] if len(mesh.two_sided) else None
    key = geo = None
    if memo is not None:
        key = memo.key("preview", "preview geometry 1", cam, mesh.verts, mesh.tris, mesh.material, mesh.two_sided,
                       _numbers(mesh.bsp_nodes), _numbers(mesh.bsp_planes), float(tie), reader)
        geo = memo.get("preview", key, lambda raw: _unpack_geometry(raw, cam),
                       "a preview's geometry for this camera")
        if geo is not None:
            memo.used("preview")
    if geo is None:
        order, how = painter_order(mesh, cam.position, reader)
        pim = render(cam, corners, mode="painter", order=order, two_sided=two)
        zim = render(cam, corners, mode="zbuffer", two_sided=two)
        t_mask, e_mask = mismatch_kinds(pim, zim, cam, corners, tie * diag)
        geo = {"painter": pim.tri_id, "zbuffer": zim.tri_id, "tie": t_mask, "edge": e_mask, "order": how,
               "drawn": int(len(order))}
        if memo is not None:
            memo.put("preview", key, _pack_geometry(geo))
    else:
        pim = Image(image=None, tri_id=geo["painter"], depth=None, edge=None)
        zim = Image(image=None, tri_id=geo["zbuffer"], depth=None, edge=None)
    bg = (1.0, 1.0, 1.0) if light else tuple(c / 255.0 for c in mesh.backdrop)  # the stage's own: its backdrop
    pimg, zimg = shade(mesh, cam, pim, bg, light=light), shade(mesh, cam, zim, bg, light=light)
    diff, stats = _difference(geo["painter"], geo["zbuffer"], geo["tie"], geo["edge"], pimg, zimg)
    stats.update({"order": geo["order"], "drawn": geo["drawn"], "colours": mesh.colour_source})
    return View(name, cam, pimg, zimg, diff, stats), pim


def _numbers(items: list | None) -> np.ndarray | None:
    """A list of numbers as one float64 array (exact for the lists' integers and doubles), for a
    key: hashing it is one blob, not an object per item."""
    if items is None:
        return None
    try:
        return np.asarray(items, np.float64)  # (a numeric string stands for its number, as in the walk)
    except (TypeError, ValueError):
        return items


def _pack_geometry(geo: dict) -> dict:
    """A view's geometry compactly (triangle ids as zlib'd int32, masks as bits)."""
    import zlib

    out = {k: geo[k] for k in ("order", "drawn")}
    out["shape"] = list(geo["painter"].shape)
    for k in ("painter", "zbuffer"):
        out[k] = zlib.compress(np.ascontiguousarray(geo[k], np.int32).tobytes(), 1)
    for k in ("tie", "edge"):
        out[k] = np.packbits(geo[k].ravel()).tobytes()
    return out


def _unpack_geometry(packed: Any, cam: Camera) -> dict | None:
    """:func:`_pack_geometry` back, or None when it is not one of this camera's size."""
    import zlib

    if not isinstance(packed, dict):
        return None
    try:
        H, W = (int(x) for x in packed["shape"])
        if (H, W) != (int(cam.height), int(cam.width)):
            return None
        out = {"order": str(packed["order"]), "drawn": int(packed["drawn"])}
        for k in ("painter", "zbuffer"):
            a = np.frombuffer(zlib.decompress(packed[k]), np.int32)
            if a.size != H * W:
                return None
            out[k] = a.astype(np.int64).reshape(H, W)
        for k in ("tie", "edge"):
            bits = np.frombuffer(packed[k], np.uint8)
            if bits.size != (H * W + 7) // 8:
                return None
            out[k] = np.unpackbits(bits)[:H * W].astype(bool).reshape(H, W)
    except (KeyError, TypeError, ValueError, zlib.error):
        return None
    return out


def render_views(mesh: Mesh, width: int = 320, height: int = 240, tie: float = 1e-5, *,
                 memo: Any = None) -> list[View]:
    """Each camera of :func:`cameras`: painter's render in the engine's order, the z-buffer
    render, and their difference. ``tie``: faces this close (a fraction of the bounding-box
    diagonal) count as coplanar (:func:`difference`). ``memo``: see :func:`render_view`."""
    return [render_view(mesh, name, cam, tie, light=name != "green flag", memo=memo, reader=name == "green flag")[0]
            for name, cam in cameras(mesh.verts, width, height)]


# --------------------------------------------------------------------------- a player's stage
def stage_view(mesh: Mesh, cam, tie: float = 1e-5) -> tuple[View, Image]:
    """The green flag's stage at full size (480 x 360) for the reader camera ``cam``
    (``bake.scratch.readers.Camera``): what a Scratch player should show."""
    return render_view(mesh, "stage", stage_camera(cam, 480), tie, light=False, reader=True)


def stage_agreement(stage: np.ndarray, view: View, painter: Image, *, margin: int = 2,
                    background=(255, 255, 255)) -> dict[str, Any]:
    """Compare a player's stage image (H, W, 3 uint8) with the preview of the same camera.

    A pixel is *interior* when the preview shows the same triangle at every pixel within
    ``margin`` pixels of it (so no triangle edge, and no pen stroke of a neighbour, is near) and
    *empty* when the preview shows no triangle within ``margin`` (pixels nearer the image's border
    than ``margin`` are neither: what lies beyond it is not rendered). Returns: the fraction of interior
    pixels whose colour is within 0, 1, 2 and 8 levels (largest channel difference), the interior
    pixels the player left as background, the empty pixels it painted, and the counts.

    Small triangles leave few interior pixels, so also: of the *covered* pixels (the preview shows
    a triangle at the pixel and at its 8 neighbours: not on the silhouette, where the pen's
    antialiased edge blends with the background), the fraction whose colour is within 1 level
    of the preview's colour at the pixel or at one of its 8 neighbours (``covered_within_1``; the
    pen's stroke is 2 pixels wide, so a triangle's colour may reach one pixel past its edge)."""
    tid = painter.tri_id
    H, W = tid.shape
    if stage.shape[:2] != (H, W):
        raise ValueError(f"stage image is {stage.shape[1]}x{stage.shape[0]}, the preview {W}x{H}")
    # beyond the image nothing is known (-2): a pixel nearer the border than ``margin`` is neither
    # interior nor empty (a stage cut through the model has triangle edges just outside it)
    pad = np.pad(tid, margin, constant_values=-2)
    same = np.ones((H, W), bool)
    none = np.ones((H, W), bool)
    for dy in range(-margin, margin + 1):
        for dx in range(-margin, margin + 1):
            win = pad[margin + dy:margin + dy + H, margin + dx:margin + dx + W]
            same &= win == tid
            none &= win == -1
    interior = same & (tid >= 0)
    empty = none & (tid < 0)
    d = np.abs(stage.astype(np.int16) - view.painter.astype(np.int16)).max(2)
    bg = np.all(stage == np.asarray(background, np.uint8), axis=2)
    n = int(interior.sum())
    di = d[interior]

    def frac(x):
        return float(x.sum() / n) if n else 0.0

    cov = np.ones((H, W), bool)
    best = np.full((H, W), 10**4, np.int32)
    sp = np.pad(stage.astype(np.int16), ((1, 1), (1, 1), (0, 0)), mode="edge")
    vp = np.pad(view.painter.astype(np.int16), ((1, 1), (1, 1), (0, 0)), mode="edge")
    tp = np.pad(tid, 1, mode="edge")
    for dy in (-1, 0, 1):
        for dx in (-1, 0, 1):
            cov &= tp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W] >= 0
            best = np.minimum(best, np.abs(sp[1:1 + H, 1:1 + W] - vp[1 + dy:1 + dy + H, 1 + dx:1 + dx + W]).max(2))
    nc = int(cov.sum())
    return {"interior_pixels": n, "covered_pixels": int((tid >= 0).sum()), "empty_pixels": int(empty.sum()),
            "covered_inner_pixels": nc,
            "covered_within_1": float((best[cov] <= 1).sum() / nc) if nc else 0.0,
            "within_0": frac(di <= 0), "within_1": frac(di <= 1), "within_2": frac(di <= 2),
            "within_8": frac(di <= 8), "max_difference": int(di.max()) if n else 0,
            "interior_left_blank": int((bg & interior).sum()), "empty_painted": int((~bg & empty).sum())}
