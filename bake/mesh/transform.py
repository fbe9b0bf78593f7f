"""Transform stage: source up axis -> y up, target handedness, scale, fit and centre.

Frames
------
The source model is read in its own frame, right-handed (OBJ and glTF are; a "z up" file is
right-handed with z up, like Blender). The stage first rotates the source up axis onto +y with
a proper rotation (determinant +1, nothing mirrored):

=======  ==========================  ==========================================
``up``   rotation                    ``(x, y, z) ->``
=======  ==========================  ==========================================
``y``    none                        ``(x, y, z)``
``z``    -90 deg about x             ``(x, z, -y)``   (Blender / glTF exporter)
``-z``   +90 deg about x             ``(x, -z, y)``
``x``    +90 deg about z             ``(-y, x, z)``
``-x``   -90 deg about z             ``(y, -x, z)``
``-y``   180 deg about x             ``(x, -y, -z)``
=======  ==========================  ==========================================

The result is the right-handed y-up frame of OBJ / glTF: x right, y up, z towards the viewer.
``frame = "right"`` stops there. ``frame = "left"`` (the default) then mirrors z, giving x right,
y up, z *into* the screen, the frame most Scratch engines use (camera looks along +z, screen
x = f*x/z, screen y = f*y/z).

Front faces and winding
-----------------------
In the right-handed frame a face is front-facing when its corners run counter-clockwise as seen
from outside (from the side its normal points to), i.e. the normal
``n = (v1 - v0) x (v2 - v0)`` (the usual right-hand-rule formula, used by every later stage)
points out of the surface. Mirroring z keeps the picture a camera sees (a right-handed camera
looking along -z and its mirror image looking along +z see the same image) but negates what the
cross-product formula gives for the mirrored corners. So, to keep ``n`` pointing outwards, the
stage reverses every polygon's corner order (corner 0 stays first: ``v0, v[n-1], ..., v1``, so a
fan from corner 0 stays a fan from corner 0) together with its per-corner UVs, and swaps corners
1 and 2 of every triangle (and their UVs).

**Front-facing in the left-handed frame** therefore means: ``(v1 - v0) x (v2 - v0)`` points out of
the surface, towards a camera that sees the front; equivalently the corners appear *clockwise*
on screen (x right, y up) to a camera looking along +z. A Scratch engine culls a projected
triangle ``(x0, y0), (x1, y1), (x2, y2)`` as a back face when
``(x1 - x0) * (y2 - y0) - (y1 - y0) * (x2 - x0) > 0`` (counter-clockwise). This is the convention of
Direct3D's default and of Unity. The test ``tests/mesh/test_transform.py`` checks it with a
perspective projection against normals computed from the solid's centre (not from the winding).

Order of operations: up-axis rotation, handedness, ``scale``, ``fit`` (largest side of the
bounding box of the used vertices becomes ``fit``), ``center`` (``bounds``: box centre at the
origin; ``base``: centred in x and z, lowest y = 0). Everything is composed into one affine map
``p' = A p + t`` applied once, recorded in ``details["matrix"]`` (4x4, row-major, column
vectors). Lights in ``scene.lights`` get the same map: positions by ``A p + t``, directions by the
rotation/mirror part (unit length kept), and ``radius`` / ``range`` by the uniform scale factor.
"""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from ..config import TransformConfig
from ..errors import ConfigError
from ..record import StageRecord
from ..scene import Light, Scene, coordinate_problem

# Rotation taking the source up axis to +y (rows: output axes).
UP_ROTATIONS: dict[str, np.ndarray] = {
    "y": np.eye(3),
    "z": np.array([[1.0, 0, 0], [0, 0, 1], [0, -1, 0]]),
    "-z": np.array([[1.0, 0, 0], [0, 0, -1], [0, 1, 0]]),
    "x": np.array([[0.0, -1, 0], [1, 0, 0], [0, 0, 1]]),
    "-x": np.array([[0.0, 1, 0], [-1, 0, 0], [0, 0, 1]]),
    "-y": np.array([[1.0, 0, 0], [0, -1, 0], [0, 0, -1]]),
}

MIRROR_Z = np.diag([1.0, 1.0, -1.0])


def frame_matrix(up: str = "y", frame: str = "left") -> np.ndarray:
    """The 3x3 orthogonal matrix for the up-axis rotation followed by the handedness change."""
    if up not in UP_ROTATIONS:
        raise ConfigError(f"unknown up axis {up!r} (expected one of {', '.join(UP_ROTATIONS)})",
                          key="transform.up")
    if frame not in ("left", "right"):
        raise ConfigError(f"unknown frame {frame!r} (expected 'left' or 'right')", key="transform.frame")
    r = UP_ROTATIONS[up]
    return MIRROR_Z @ r if frame == "left" else r.copy()


def reverse_polygon_corners(sizes: np.ndarray) -> np.ndarray:
    """Permutation of the flat corner array that reverses every polygon, keeping corner 0 first.

    ``new[k] = old[perm[k]]``; a polygon ``v0 v1 ... v(n-1)`` becomes ``v0 v(n-1) ... v1``.
    """
    sizes = np.asarray(sizes, dtype=np.int64)
    total = int(sizes.sum())
    if total == 0:
        return np.zeros(0, np.int64)
    off = np.zeros(len(sizes), np.int64)
    np.cumsum(sizes[:-1], out=off[1:])
    start = np.repeat(off, sizes)
    n = np.repeat(sizes, sizes)
    k = np.arange(total, dtype=np.int64) - start  # local corner number
    return np.where(k == 0, start, start + n - k)


def apply_affine(points: np.ndarray, A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """``A p + t`` for ``(N, 3)`` points (three fused column sums: A is a signed permutation
    times a scale here, so every coordinate is one product plus zeros, computed exactly)."""
    p = np.asarray(points, np.float64)
    shape = p.shape
    p = p.reshape(-1, 3)
    A = np.asarray(A, np.float64)
    t = np.asarray(t, np.float64)
    out = np.empty_like(p)
    # a scale that overflows gives Inf here, quietly: the pipeline then names the key (exit 2)
    with np.errstate(over="ignore", invalid="ignore"):
        for r in range(3):
            col = out[:, r]
            col[...] = t[r]
            for c in range(3):
                if A[r, c] != 0.0:
                    col += A[r, c] * p[:, c]
    return out.reshape(shape)


def map_bounds(bounds: np.ndarray, A: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Bounding box ``(2, 3)`` of the image of a box under ``p -> A p + t`` (from its 8 corners;
    exact for the axis-aligned maps used here, since rounding is monotonic)."""
    b = np.asarray(bounds, np.float64)
    corners = np.array([[b[i, 0], b[j, 1], b[k, 2]] for i in (0, 1) for j in (0, 1) for k in (0, 1)])
    m = apply_affine(corners, A, t)
    return np.stack([m.min(axis=0), m.max(axis=0)])


def compute_transform(bounds: np.ndarray, cfg: TransformConfig, warn=None, empty: bool = False
                      ) -> tuple[np.ndarray, np.ndarray, float, np.ndarray]:
    """The affine map for ``cfg`` given the source bounds ``(2, 3)`` of the used vertices.

    Returns ``(A, t, uniform_scale, R)`` with ``p' = A p + t``, ``A = uniform_scale * R`` and
    ``R`` the orthogonal up/handedness part."""
    R = frame_matrix(cfg.up, cfg.frame)
    s = float(cfg.scale)
    if not (s > 0 and np.isfinite(s)):
        raise ConfigError("must be > 0", key="transform.scale")
    if cfg.fit < 0 or not np.isfinite(cfg.fit):
        raise ConfigError("must be >= 0", key="transform.fit")
    b = map_bounds(bounds, s * R, np.zeros(3))
    if cfg.fit > 0:
        side = float((b[1] - b[0]).max())
        if side > 0 and np.isfinite(side) and not empty:
            f = float(cfg.fit) / side
            s *= f
            b = map_bounds(bounds, s * R, np.zeros(3))
        elif warn is not None:
            warn("transform.fit ignored: the model has no extent")
    t = np.zeros(3)
    if cfg.center == "bounds":
        t = -0.5 * (b[0] + b[1])
    elif cfg.center == "base":
        t = np.array([-0.5 * (b[0, 0] + b[1, 0]), -b[0, 1], -0.5 * (b[0, 2] + b[1, 2])])
    elif cfg.center != "none":
        raise ConfigError(f"unknown center {cfg.center!r}", key="transform.center")
    if empty:
        t = np.zeros(3)
    return s * R, t, s, R


def transform_light(light: Light, A: np.ndarray, t: np.ndarray, R: np.ndarray, s: float) -> Light:
    ch: dict = {}
    if light.position is not None:
        ch["position"] = tuple(float(v) for v in apply_affine(np.array(light.position), A, t))
    if light.direction is not None:
        # R is orthogonal: the direction keeps its length (a unit vector stays a unit vector).
        ch["direction"] = tuple(float(v) for v in R @ np.asarray(light.direction, np.float64))
    if light.radius:
        ch["radius"] = float(light.radius * s)
    if light.range is not None:
        ch["range"] = float(light.range * s)
    return dataclasses.replace(light, **ch)


def stage(scene: Scene, cfg: TransformConfig) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord(name="transform")
    before = scene.bounds()
    A, t, s, R = compute_transform(before, cfg, warn=rec.warn, empty=scene.n_vertices == 0)
    flip = bool(np.linalg.det(R) < 0)

    changes: dict = {"positions": apply_affine(scene.positions, A, t)}
    if flip:
        if scene.poly_sizes is not None and scene.poly_indices is not None:
            perm = reverse_polygon_corners(scene.poly_sizes)
            changes["poly_indices"] = scene.poly_indices[perm]
            if scene.poly_uvs is not None:
                changes["poly_uvs"] = scene.poly_uvs[perm]
        if scene.triangles is not None:
            changes["triangles"] = scene.triangles[:, [0, 2, 1]]
            if scene.tri_uvs is not None:
                changes["tri_uvs"] = scene.tri_uvs[:, [0, 2, 1], :]
    if scene.lights:
        changes["lights"] = tuple(transform_light(lt, A, t, R, s) for lt in scene.lights)
    out = scene.replace(**changes)

    M = np.eye(4)
    M[:3, :3] = A
    M[:3, 3] = t
    rec.details = {
        "matrix": M.tolist(),
        "up": cfg.up,
        "frame": cfg.frame,
        "uniform_scale": s,
        "winding_reversed": flip,
        "bounds_before": before.tolist(),
        "bounds_after": map_bounds(before, A, t).tolist(),
        "lights_transformed": len(scene.lights),
    }
    problem = coordinate_problem(out)
    if problem is not None:
        key = "transform.fit" if cfg.fit > 0 else "transform.scale"
        raise ConfigError(f"{problem} after the transform ({key} = {cfg.fit if cfg.fit > 0 else cfg.scale:g})",
                          key=key)
    rec.seconds = time.perf_counter() - t0
    return out, rec


__all__ = ["stage", "frame_matrix", "compute_transform", "reverse_polygon_corners", "apply_affine",
           "transform_light", "map_bounds", "UP_ROTATIONS"]
