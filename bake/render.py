"""A small numpy software rasterizer: flat-coloured triangles, z-buffer or painter's order.

Used as the independent reference for the BSP order (a z-buffer render and a painter's render
in the BSP's order must agree) and for previews in the report::

    cam = Camera(position=(3, 2, 5), look_at=(0, 0, 0), fov=60, width=320, height=240)
    img = render(cam, scene_triangles(scene), colors=scene.triangle_albedo()[:, :3])
    img = render_scene(scene, cam, shade=True)         # the same, with a headlight
    img = render_scene(scene, cam, mode="painter", order=draw_order)
    img.image      # (H, W, 3) float RGB in [0, 1]
    img.tri_id     # (H, W) int: triangle seen at each pixel, -1 for background
    img.depth      # (H, W) view-space depth of that triangle at the pixel centre (inf: none)
    img.edge       # (H, W) distance in pixels from the pixel centre to that triangle's nearest edge

The frame is the export's (x right, y up, z into the screen, left-handed): a point at +x of
where the camera looks is drawn right of the centre, as a Scratch engine draws it.
``Camera.yaw_pitch`` is the reader sprite's camera (screen ``focal * x / z``, stage 480 x 360).

Conventions: a pixel is covered when its centre is inside the (near-clipped, projected) triangle,
edges included. ``mode="zbuffer"`` keeps the nearest triangle (perspective-correct depth; exact
ties go to the lower index); ``mode="painter"`` draws ``order`` in sequence, later triangles
covering earlier ones, with no depth test. Single-sided triangles facing away from the camera
(``dot(cross(b - a, c - a), eye - a) <= 0``) are culled in both modes unless ``two_sided``.
Triangles are clipped against the near plane, so cameras inside the model work.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Camera:
    position: tuple[float, float, float]
    look_at: tuple[float, float, float]
    fov: float = 60.0  # vertical field of view, degrees
    width: int = 256
    height: int = 256
    up: tuple[float, float, float] = (0.0, 1.0, 0.0)
    near: float = 1e-3  # near plane distance (world units)
    focal_px: float | None = None  # focal length in pixels; None: from ``fov`` and ``height``

    @classmethod
    def yaw_pitch(cls, position, yaw: float, pitch: float, focal_px: float, *, width: int = 480,
                  height: int = 360, near: float = 1e-3) -> "Camera":
        """The camera of a Scratch engine that turns ``yaw`` degrees about y (positive turns right)
        and then ``pitch`` degrees about its x axis (positive looks up), with the screen
        ``focal_px * x / z`` pixels right of the centre: the reader sprite's camera
        (bake/scratch/readers.py) on a ``width`` x ``height`` stage (|pitch| < 90)."""
        sy, cy = np.sin(np.radians(yaw)), np.cos(np.radians(yaw))
        sp, cp = np.sin(np.radians(pitch)), np.cos(np.radians(pitch))
        e = np.asarray(position, np.float64)
        f = np.array([sy * cp, sp, cy * cp])
        return cls(tuple(float(x) for x in e), tuple(float(x) for x in e + f), width=width, height=height,
                   near=near, focal_px=float(focal_px))

    def basis(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(eye, right, up, forward) orthonormal camera frame in the documented left-handed frame
        (x right, y up, z into the screen): a camera looking along +z with up +y has right = +x.
        So right = up x forward (forward x up would be -x, a mirrored picture)."""
        e = np.asarray(self.position, np.float64)
        f = np.asarray(self.look_at, np.float64) - e
        nf = np.linalg.norm(f)
        if not nf > 0:
            raise ValueError("camera position and look_at coincide")
        f = f / nf
        up = np.asarray(self.up, np.float64)
        r = np.cross(up, f)
        if np.linalg.norm(r) < 1e-9 * max(1.0, np.linalg.norm(up)):  # looking along up
            alt = np.array([0.0, 0.0, 1.0]) if abs(f[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
            r = np.cross(alt, f)
        r = r / np.linalg.norm(r)
        u = np.cross(f, r)
        return e, r, u, f

    @property
    def focal(self) -> float:
        if self.focal_px is not None:
            return float(self.focal_px)
        return 0.5 * self.height / np.tan(np.radians(self.fov) / 2.0)


@dataclass
class Image:
    image: np.ndarray  # (H, W, 3) float
    tri_id: np.ndarray  # (H, W) int64, -1 = background
    depth: np.ndarray  # (H, W) float64, inf = background
    edge: np.ndarray  # (H, W) float64 pixels to the nearest edge of the visible triangle

    @property
    def covered(self) -> np.ndarray:
        return self.tri_id >= 0

    def to_uint8(self) -> np.ndarray:
        return np.clip(np.rint(self.image * 255.0), 0, 255).astype(np.uint8)


def scene_triangles(scene) -> np.ndarray:
    """(T, 3, 3) world corners of a Scene's triangles."""
    return scene.triangle_vertices()


def scene_two_sided(scene) -> np.ndarray:
    """(T,) bool: the triangle's material is double-sided."""
    ds = np.array([m.double_sided for m in scene.materials], bool)
    return ds[np.clip(scene.tri_material, 0, len(ds) - 1)]


def facing(tri: np.ndarray, eye) -> np.ndarray:
    """(T,) bool: the triangle's front side faces the eye (strictly)."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    return np.einsum("ij,ij->i", n, np.asarray(eye, np.float64) - tri[:, 0]) > 0


def render(camera: Camera, tri: np.ndarray, colors: np.ndarray | None = None, *, mode: str = "zbuffer",
           order: np.ndarray | None = None, two_sided: np.ndarray | None = None, cull: bool = True,
           background=(1.0, 1.0, 1.0), budget: int = 4_000_000) -> Image:
    """Render triangles ``tri`` (T, 3, 3) seen by ``camera``. See the module docstring."""
    tri = np.asarray(tri, np.float64).reshape(-1, 3, 3)
    T = len(tri)
    H, W = int(camera.height), int(camera.width)
    if mode not in ("zbuffer", "painter"):
        raise ValueError(f"mode must be 'zbuffer' or 'painter', got {mode!r}")
    if mode == "painter":
        seq = np.arange(T) if order is None else np.asarray(order, np.int64)
        rank = np.full(T, -1, np.int64)
        rank[seq] = np.arange(len(seq))  # a triangle listed twice keeps its last position
    else:
        rank = np.arange(T)
    draw = rank >= 0
    eye, r, u, f = camera.basis()
    if cull:
        vis = facing(tri, eye)
        if two_sided is not None:
            vis |= np.asarray(two_sided, bool)
        draw &= vis
    ids = np.flatnonzero(draw)
    rel = tri[ids] - eye
    cam = np.stack([rel @ r, rel @ u, rel @ f], axis=-1)  # (n, 3, 3): x right, y up, z forward
    pieces, owner = _clip_near(cam, camera.near)
    owner = ids[owner]
    fx = camera.focal
    sx = pieces[..., 0] / pieces[..., 2] * fx + W / 2.0
    sy = H / 2.0 - pieces[..., 1] / pieces[..., 2] * fx
    inv_z = 1.0 / pieces[..., 2]

    best_key = np.full(H * W, np.inf)  # depth (zbuffer) or -rank (painter)
    best_tie = np.full(H * W, np.iinfo(np.int64).max)
    best_id = np.full(H * W, -1, np.int64)
    best_depth = np.full(H * W, np.inf)
    best_edge = np.zeros(H * W)
    x0 = np.clip(np.floor(sx.min(1) - 0.5), 0, W).astype(np.int64)
    x1 = np.clip(np.ceil(sx.max(1) - 0.5) + 1, 0, W).astype(np.int64)
    y0 = np.clip(np.floor(sy.min(1) - 0.5), 0, H).astype(np.int64)
    y1 = np.clip(np.ceil(sy.max(1) - 0.5) + 1, 0, H).astype(np.int64)
    bw, bh = np.maximum(x1 - x0, 0), np.maximum(y1 - y0, 0)
    area = bw * bh
    area2 = (sx[:, 1] - sx[:, 0]) * (sy[:, 2] - sy[:, 0]) - (sx[:, 2] - sx[:, 0]) * (sy[:, 1] - sy[:, 0])
    live = np.flatnonzero((area > 0) & (area2 != 0))
    csum = np.cumsum(area[live])
    start = 0
    while start < len(live):
        base = csum[start - 1] if start else 0
        stop = int(np.searchsorted(csum, base + budget, side="right"))
        stop = max(stop, start + 1)
        chunk = live[start:stop]
        start = stop
        a = area[chunk]
        rep = np.repeat(np.arange(len(chunk)), a)
        local = np.arange(int(a.sum())) - np.repeat(np.cumsum(a) - a, a)
        c = chunk[rep]
        px = x0[c] + local % bw[c]
        py = y0[c] + local // bw[c]
        cx, cy = px + 0.5, py + 0.5
        X, Y = sx[c], sy[c]
        # edge functions, signed so that the inside is positive whatever the winding
        s = np.sign(area2[c])
        e0 = ((X[:, 1] - X[:, 0]) * (cy - Y[:, 0]) - (Y[:, 1] - Y[:, 0]) * (cx - X[:, 0])) * s
        e1 = ((X[:, 2] - X[:, 1]) * (cy - Y[:, 1]) - (Y[:, 2] - Y[:, 1]) * (cx - X[:, 1])) * s
        e2 = ((X[:, 0] - X[:, 2]) * (cy - Y[:, 2]) - (Y[:, 0] - Y[:, 2]) * (cx - X[:, 2])) * s
        inside = (e0 >= 0) & (e1 >= 0) & (e2 >= 0)
        if not inside.any():
            continue
        c, px, py = c[inside], px[inside], py[inside]
        e0, e1, e2 = e0[inside], e1[inside], e2[inside]
        X, Y = X[inside], Y[inside]
        l0 = np.hypot(X[:, 1] - X[:, 0], Y[:, 1] - Y[:, 0])
        l1 = np.hypot(X[:, 2] - X[:, 1], Y[:, 2] - Y[:, 1])
        l2 = np.hypot(X[:, 0] - X[:, 2], Y[:, 0] - Y[:, 2])
        edge = np.minimum(np.minimum(e0 / np.maximum(l0, 1e-300), e1 / np.maximum(l1, 1e-300)),
                          e2 / np.maximum(l2, 1e-300))
        tot = e0 + e1 + e2
        # barycentrics of the pixel centre: weight of corner k is the edge opposite it
        w0, w1, w2 = e1 / tot, e2 / tot, e0 / tot
        iz = w0 * inv_z[c, 0] + w1 * inv_z[c, 1] + w2 * inv_z[c, 2]
        depth = 1.0 / iz
        tid = owner[c]
        pix = py * W + px
        if mode == "zbuffer":
            key, tie = depth, tid
        else:
            key, tie = -rank[tid].astype(np.float64), np.zeros(len(tid), np.int64)
        o = np.lexsort((tie, key, pix))
        first = np.ones(len(o), bool)
        first[1:] = pix[o][1:] != pix[o][:-1]
        w = o[first]
        p = pix[w]
        better = (key[w] < best_key[p]) | ((key[w] == best_key[p]) & (tie[w] < best_tie[p]))
        p, w = p[better], w[better]
        best_key[p], best_tie[p] = key[w], tie[w]
        best_id[p], best_depth[p], best_edge[p] = tid[w], depth[w], edge[w]

    img = np.empty((H * W, 3))
    img[:] = np.asarray(background, np.float64)[:3]
    hit = best_id >= 0
    if colors is not None:
        col = np.asarray(colors, np.float64)[:, :3]
        img[hit] = col[best_id[hit]]
    else:
        img[hit] = _id_colors(best_id[hit])
    return Image(image=img.reshape(H, W, 3), tri_id=best_id.reshape(H, W), depth=best_depth.reshape(H, W),
                 edge=np.where(hit, best_edge, np.inf).reshape(H, W))


def _id_colors(ids: np.ndarray) -> np.ndarray:
    """Distinct-looking colours from triangle ids (for previews without colours)."""
    h = (ids.astype(np.uint64) * np.uint64(2654435761)) & np.uint64(0xFFFFFF)
    return np.stack([(h >> np.uint64(16)) & np.uint64(255), (h >> np.uint64(8)) & np.uint64(255),
                     h & np.uint64(255)], 1).astype(np.float64) / 255.0


def _clip_near(cam: np.ndarray, near: float) -> tuple[np.ndarray, np.ndarray]:
    """Clip camera-space triangles (n, 3, 3) against z >= near. Returns triangles and, for each,
    the index of the input triangle it came from (a triangle with one corner behind becomes two)."""
    z = cam[..., 2]
    inside = z >= near
    k = inside.sum(1)
    out = [cam[k == 3]]
    own = [np.flatnonzero(k == 3)]

    def cut(p, q):
        t = ((near - p[..., 2]) / (q[..., 2] - p[..., 2]))[..., None]
        v = p + t * (q - p)
        v[..., 2] = near
        return v

    # one corner inside: rotate so it is corner 0, keep (0, cut01, cut02)
    one = np.flatnonzero(k == 1)
    if len(one):
        s = np.argmax(inside[one], 1)
        rot = (s[:, None] + np.arange(3)[None, :]) % 3
        t = np.take_along_axis(cam[one], rot[..., None], 1)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        out.append(np.stack([a, cut(a, b), cut(a, c)], 1))
        own.append(one)
    # two corners inside: rotate so the outside one is corner 0; quad (cut01, 1, 2, cut02)
    two = np.flatnonzero(k == 2)
    if len(two):
        s = np.argmin(inside[two], 1)
        rot = (s[:, None] + np.arange(3)[None, :]) % 3
        t = np.take_along_axis(cam[two], rot[..., None], 1)
        a, b, c = t[:, 0], t[:, 1], t[:, 2]
        ab, ac = cut(a, b), cut(a, c)
        out.append(np.stack([ab, b, c], 1))
        out.append(np.stack([ab, c, ac], 1))
        own += [two, two]
    return np.concatenate(out), np.concatenate(own)


def headlight(tri: np.ndarray, camera: Camera) -> np.ndarray:
    """(T,) brightness 0.35 + 0.65 |cos| of the angle between each triangle's normal and the view
    direction: a directional light from the camera, so the pieces of a split face match."""
    n = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    d = np.asarray(camera.position, np.float64) - np.asarray(camera.look_at, np.float64)
    with np.errstate(invalid="ignore", divide="ignore"):
        c = np.abs(n @ d) / (np.linalg.norm(n, axis=1) * np.linalg.norm(d))
    return 0.35 + 0.65 * np.nan_to_num(c)


def render_scene(scene, camera: Camera, *, mode: str = "zbuffer", order: np.ndarray | None = None,
                 colors: np.ndarray | None = None, shade: bool = False, cull: bool = True,
                 background=(1.0, 1.0, 1.0)) -> Image:
    """Render a Scene: its triangles in their base colours (``scene.triangle_albedo()``, or
    ``colors``), back faces culled by material sidedness. ``shade`` darkens faces turned away
    from the camera (:func:`headlight`), which makes flat-coloured previews readable."""
    tri = scene_triangles(scene)
    col = np.asarray(scene.triangle_albedo() if colors is None else colors, np.float64)[:, :3]
    if shade and len(tri):
        col = col * headlight(tri, camera)[:, None]
    return render(camera, tri, col, mode=mode, order=order, two_sided=scene_two_sided(scene), cull=cull,
                  background=background)
