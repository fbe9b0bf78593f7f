"""The report's pictures of the hidden stage's proof: what a held-out eye sees with and without
the removal (docs/hidden.md, "The proof").

For a few held-out eyes (the ones with the most wrong pixels first, then eyes spread over the
rest), the
same pixel rays as the wrong-pixel count go once through the full mesh and once through the kept
triangles alone, with the stage's drawing rules (:meth:`Visibility.chain`). Each pixel takes the
colour of the nearest triangle its ray draws (the material's or the face's colour, shaded by the
angle to the ray, so the shapes read). The difference picture marks in red the wrong pixels as the
proof counts them (the ray draws a dropped triangle before it stops: the nearest, or one behind
glass), over the full picture faded. An eye outside the model looks at its bounding sphere (one square view); an
eye in a box, at a point or at the camera shows its cube map, the six faces side by side.

The pictures are PNGs, kept in the stage's record (base64), small: one pixel per held-out pixel.
"""

from __future__ import annotations

import base64
import io

import numpy as np

from ...scene import Scene
from .visibility import Visibility

BACKGROUND = np.array([186, 198, 214], np.uint8)  # a pale blue: white and grey models stand out
WRONG = np.array([230, 20, 20], np.uint8)


def base_colours(scene: Scene) -> np.ndarray:
    """(T, 3) float colours 0..1 of each triangle: its face colour, else its material's."""
    if scene.face_colors is not None and len(scene.face_colors) == scene.n_triangles:
        return np.clip(np.asarray(scene.face_colors, np.float64)[:, :3], 0.0, 1.0)
    mats = np.array([m.color[:3] for m in scene.materials] or [[0.8, 0.8, 0.8]], np.float64)
    return np.clip(mats[np.clip(scene.tri_material, 0, len(mats) - 1)], 0.0, 1.0)


def nearest(vis: Visibility, eye: np.ndarray, dirs: np.ndarray, dropped: np.ndarray | None = None
            ) -> tuple[np.ndarray, np.ndarray]:
    """(N,) the nearest triangle each pixel ray from ``eye`` draws (``-1``: none), and (N,) bool:
    the ray draws a triangle of ``dropped`` before it stops (a wrong pixel, as counted)."""
    o = np.ascontiguousarray(np.broadcast_to(eye, dirs.shape))
    rays, prims, _ = vis.chain(o, dirs)
    out = np.full(len(dirs), -1, np.int64)
    # chain lists a ray's drawn triangles nearest first: keep each ray's first
    first = np.unique(rays, return_index=True)[1]
    out[rays[first]] = prims[first]
    wrong = np.zeros(len(dirs), bool)
    if dropped is not None:
        wrong[rays[dropped[prims]]] = True
    return out, wrong


def _shade(tri: np.ndarray, colour: np.ndarray, normal: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    img = np.broadcast_to(BACKGROUND, (len(tri), 3)).astype(np.float64) / 255.0
    hit = tri >= 0
    t = tri[hit]
    n = normal[t]
    with np.errstate(invalid="ignore", divide="ignore"):
        lam = np.abs(np.einsum("ij,ij->i", n, dirs[hit])) / np.linalg.norm(n, axis=1)
    img[hit] = colour[t] * (0.35 + 0.65 * np.nan_to_num(lam, nan=0.0))[:, None]
    return np.round(np.clip(img, 0.0, 1.0) * 255.0).astype(np.uint8)


def _layout(px: np.ndarray, P: int) -> np.ndarray:
    """(N, 3) pixels of one square view (N = P^2, bottom row first) or of a cube map (6 faces) as
    an image (rows top first), the faces side by side."""
    faces = px.reshape(-1, P, P, 3)[:, ::-1]  # each face: top row first
    return np.concatenate(list(faces), axis=1)


def nearest_depth(vis: Visibility, eye: np.ndarray, dirs: np.ndarray) -> np.ndarray:
    """(N,) the distance along each pixel ray from ``eye`` to the nearest triangle it draws (inf:
    none), float64 from that triangle's plane."""
    tri = nearest(vis, eye, dirs)[0]
    out = np.full(len(dirs), np.inf)
    hit = tri >= 0
    t = tri[hit]
    n, v0 = vis.normal[t], vis.corners[t, 0]
    with np.errstate(invalid="ignore", divide="ignore"):
        out[hit] = np.einsum("ij,ij->i", n, v0 - eye) / np.einsum("ij,ij->i", n, dirs[hit])
    return out


def depths_differ(model: Visibility, written: Visibility, eyes: np.ndarray, views: list[np.ndarray],
                  tol: float) -> tuple[int, int]:
    """Trimmed output against the model: ``(pixels whose nearest drawn surface is not at the same
    depth, by more than ``tol``, pixels showing the model)`` over the held-out views. Trimming
    writes other triangles than it decided on (sources whole again, outlines redrawn), so this
    checks what is written, not the pieces."""
    bad = shown = 0
    for e, d in zip(eyes, views):
        a, b = nearest_depth(model, e, d), nearest_depth(written, e, d)
        both = np.isfinite(a) & np.isfinite(b)
        differ = np.isfinite(a) != np.isfinite(b)
        differ[both] |= np.abs(a[both] - b[both]) > tol
        bad += int(differ.sum())
        shown += int(np.isfinite(a).sum())
    return bad, shown


def png_base64(img: np.ndarray) -> str:
    from PIL import Image

    buf = io.BytesIO()
    Image.fromarray(np.ascontiguousarray(img, np.uint8)).save(buf, format="PNG", optimize=False)
    return base64.b64encode(buf.getvalue()).decode("ascii")


def _choose(wrong: np.ndarray, count: int) -> np.ndarray:
    """The eyes to picture: those with wrong pixels, most first, then eyes spread evenly over the
    held-out ones (the outside eyes run from one pole of the sphere to the other, so the first few
    would all look from above)."""
    n = len(wrong)
    bad = np.flatnonzero(wrong > 0)
    bad = bad[np.lexsort((bad, -wrong[bad]))]
    spread = (np.arange(count) * n) // max(count, 1) + n // (2 * max(count, 1))
    taken = set(bad.tolist())
    rest = [int(i) for i in spread if int(i) not in taken]
    rest += [i for i in range(n) if i not in taken and i not in rest]
    return np.array((bad.tolist() + rest)[:count], np.int64)


def pictures(scene: Scene, vis: Visibility, kept: np.ndarray, eyes: np.ndarray, views: list[np.ndarray],
             wrong_per_eye: np.ndarray, pixels: int, count: int, *, two_sided: np.ndarray,
             see_through: np.ndarray) -> list[dict]:
    """Pictures from ``count`` held-out eyes (most wrong pixels first, then in order): the full
    mesh (``vis``, every triangle of ``scene``), the kept triangles (``kept``), and the difference."""
    if count <= 0 or len(eyes) == 0:
        return []
    order = _choose(np.asarray(wrong_per_eye), count)
    keep_ids = np.flatnonzero(kept)
    colour = base_colours(scene)
    normal = vis.normal
    only = Visibility(scene.positions, scene.triangles[keep_ids], two_sided=two_sided[keep_ids],
                      see_through=see_through[keep_ids], threads=vis.tracer.threads)
    out = []
    for i in order:
        d = views[i]
        full, wrong = nearest(vis, eyes[i], d, ~kept)
        mine = nearest(only, eyes[i], d)[0]
        mine = np.where(mine >= 0, keep_ids[np.maximum(mine, 0)], -1)
        before = _shade(full, colour, normal, d)
        after = _shade(mine, colour, normal, d)
        diff = (0.3 * before + 0.7 * 255).astype(np.uint8)  # the full picture, faded
        diff[wrong] = WRONG
        out.append({"eye": int(i), "position": [float(x) for x in eyes[i]], "wrong_pixels": int(wrong.sum()),
                    "differ": int((full != mine).sum()),
                    "before": png_base64(_layout(before, pixels)), "after": png_base64(_layout(after, pixels)),
                    "difference": png_base64(_layout(diff, pixels))})
    return out


def decode(b64: str) -> np.ndarray:
    """A picture of :func:`pictures` back as an (H, W, 3) uint8 array."""
    from PIL import Image

    with Image.open(io.BytesIO(base64.b64decode(b64))) as im:
        return np.asarray(im.convert("RGB"))
