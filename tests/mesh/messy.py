"""Messy models written in code, as OBJ files, for the simplify stage's tests and benchmark.

Each case is what real CAD, furniture and game assets bring (docs/simplify.md, "Messy models"):

* ``touching``: boxes stacked face to face and cylinders standing on them (after the clean
  stage's weld the parts share the vertices where they touch, and the faces where two boxes
  meet are two-sided twins of each other's);
* ``crossing``: cylinders and boxes passing through each other;
* ``tubes``: a chair-like frame of thin open tubes (no caps) bent through corners;
* ``fins``: three or four panels meeting on one edge (non-manifold edges on input);
* ``broken_uvs``: a textured part where some corners have UVs and their neighbours have none
  (``f v`` beside ``f v/vt``: the importer gives them (0, 0));
* ``two_sided``: a curved sheet written twice, front and back with their own materials, and a
  box whose every triangle is repeated with the same winding.

:func:`write` writes one case (OBJ, MTL and, for ``broken_uvs``, a PNG) into a folder and
returns the OBJ's path. Sizes scale with ``detail`` (1: a few thousand triangles per case).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

CASES = ("touching", "crossing", "tubes", "fins", "broken_uvs", "two_sided")
WHAT = {  # one line each, for the benchmark's table
    "touching": "boxes face to face and cylinders standing on them (shared vertices after the weld)",
    "crossing": "cylinders and boxes passing through each other",
    "tubes": "a frame of thin open tubes bent through corners",
    "fins": "panels meeting on one edge (non-manifold on input)",
    "broken_uvs": "textured, patches of corners without UVs",
    "two_sided": "a sheet written front and back, a box with every triangle repeated",
}


class _Obj:
    """Faces collected per material, written as OBJ text."""

    def __init__(self):
        self.v: list[np.ndarray] = []
        self.vt: list[np.ndarray] = []
        self.n = 0
        self.nt = 0
        self.faces: list[tuple[str, np.ndarray, np.ndarray | None]] = []

    def add(self, V: np.ndarray, F: np.ndarray, material: str, uv: np.ndarray | None = None,
            uv_mask: np.ndarray | None = None) -> None:
        """Vertices and triangles (and per-vertex UVs; ``uv_mask``: which triangles get them)."""
        self.v.append(np.asarray(V, np.float64))
        ft = None
        if uv is not None:
            self.vt.append(np.asarray(uv, np.float64))
            ft = np.asarray(F) + self.nt
            if uv_mask is not None:
                ft = np.where(np.asarray(uv_mask)[:, None], ft, -1)
            self.nt += len(uv)
        self.faces.append((material, np.asarray(F) + self.n, ft))
        self.n += len(V)

    def text(self, mtllib: str) -> str:
        out = [f"mtllib {mtllib}"]
        out += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in np.concatenate(self.v)]
        if self.vt:
            out += [f"vt {u:.6g} {v:.6g}" for u, v in np.concatenate(self.vt)]
        for mat, F, FT in self.faces:
            out.append(f"usemtl {mat}")
            for k, f in enumerate(F + 1):
                if FT is not None and FT[k, 0] >= 0:
                    t = FT[k] + 1
                    out.append(f"f {f[0]}/{t[0]} {f[1]}/{t[1]} {f[2]}/{t[2]}")
                else:
                    out.append(f"f {f[0]} {f[1]} {f[2]}")
        return "\n".join(out) + "\n"


def grid_surface(nu: int, nv: int, fn, closed_u: bool = False) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A (nu x nv)-cell parametric surface ``fn(u, v) -> (n, 3)`` over [0, 1]^2: vertices,
    triangles (two per cell, facing along d/du x d/dv) and per-vertex UVs; ``closed_u`` joins
    u = 1 to u = 0 (a tube)."""
    cu = nu if closed_u else nu + 1
    u, v = np.meshgrid(np.arange(cu) / nu, np.arange(nv + 1) / nv, indexing="ij")
    V = fn(u.ravel(), v.ravel())
    k = np.arange(cu * (nv + 1)).reshape(cu, nv + 1)
    k1 = np.roll(k, -1, axis=0) if closed_u else k[1:]
    k0 = k if closed_u else k[:-1]
    a, b, c, d = k0[:, :-1].ravel(), k1[:, :-1].ravel(), k1[:, 1:].ravel(), k0[:, 1:].ravel()
    F = np.concatenate([np.stack([a, b, c], 1), np.stack([a, c, d], 1)])
    return V, F, np.stack([u.ravel(), v.ravel()], 1)


def box(lo, hi, n: int, bulge: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A closed box, each face an n x n grid, outward-facing; ``bulge`` > 0 puffs each face out
    (by that fraction of the box's smallest side at its middle), so simplifying it costs shape."""
    lo, hi = np.asarray(lo, float), np.asarray(hi, float)
    Vs, Fs, off = [], [], 0
    for axis in range(3):
        for side in (0, 1):
            a1, a2 = [x for x in range(3) if x != axis]
            if np.cross(np.eye(3)[a1], np.eye(3)[a2])[axis] * (1 if side else -1) < 0:
                a1, a2 = a2, a1  # (the grid faces along d/du x d/dv: outward)

            def fn(u, v, axis=axis, side=side, a1=a1, a2=a2):
                P = np.zeros((len(u), 3))
                P[:, axis] = hi[axis] if side else lo[axis]
                P[:, a1] = lo[a1] + u * (hi[a1] - lo[a1])
                P[:, a2] = lo[a2] + v * (hi[a2] - lo[a2])
                # (a polynomial bump: exactly 0 on the edges, so the faces weld)
                P[:, axis] += (1 if side else -1) * bulge * (hi - lo).min() * 16 * u * (1 - u) * v * (1 - v)
                return P
            V, F, _ = grid_surface(n, n, fn)
            Vs.append(V)
            Fs.append(F + off)
            off += len(V)
    return np.concatenate(Vs), np.concatenate(Fs)


def cylinder(base, axis_len: float, radius: float, seg: int, rings: int, caps: bool = True,
             axis: int = 1, barrel: float = 0.0) -> tuple[np.ndarray, np.ndarray]:
    """A cylinder along ``axis`` from ``base``, ``seg`` sides, ``rings`` bands, its radius
    ``barrel`` wider at the middle; with ``caps`` closed by fans (the long slivers CAD exporters
    write)."""
    base = np.asarray(base, float)
    o1, o2 = [x for x in range(3) if x != axis]

    def fn(u, v):
        P = np.tile(base, (len(u), 1))
        r = radius * (1 + barrel * np.sin(np.pi * v))
        P[:, o1] += r * np.cos(2 * np.pi * u)
        P[:, o2] -= r * np.sin(2 * np.pi * u)
        P[:, axis] += v * axis_len
        return P
    V, F, _ = grid_surface(seg, rings, fn, closed_u=True)
    if not caps:
        return V, F
    ring0 = np.arange(seg) * (rings + 1)
    ring1 = ring0 + rings
    c0, c1 = len(V), len(V) + 1
    top = base.copy()
    top[axis] += axis_len
    V = np.concatenate([V, base[None], top[None]])
    nxt = np.roll(np.arange(seg), -1)
    cap0 = np.stack([np.full(seg, c0), ring0[nxt], ring0], 1)
    cap1 = np.stack([np.full(seg, c1), ring1, ring1[nxt]], 1)
    return V, np.concatenate([F, cap0, cap1])


def _touching(o: _Obj, d: int) -> None:
    n = 4 * d
    for i in range(4):
        for j in range(3):
            V, F = box((i, 0, j), (i + 1, 1, j + 1), n)
            o.add(V, F, f"part{(i + j) % 4}")
    for i in range(4):
        V, F = cylinder((i + 0.5, 1.0, 1.5), 1.5, 0.3, 16 * d, 6 * d, barrel=0.2)
        o.add(V, F, "shaft")
        V, F = cylinder((i + 0.5, 2.5, 1.5), 0.12, 0.05, 8, 1)  # a small bolt on top
        o.add(V, F, "bolt")


def _crossing(o: _Obj, d: int) -> None:
    for k in range(5):
        V, F = box((k * 0.8, 0, 0), (k * 0.8 + 1.2, 1, 1), 4 * d, bulge=0.1)
        o.add(V, F, f"block{k % 3}")
        V, F = cylinder((k * 0.8 + 0.6, -0.5, 0.5), 2.0, 0.25, 16 * d, 8 * d, barrel=0.15)
        o.add(V, F, "pin")
    V, F = cylinder((-0.5, 0.5, 0.5), 5.0, 0.2, 16 * d, 20 * d, axis=0, barrel=0.1)
    o.add(V, F, "axle")


def _tubes(o: _Obj, d: int) -> None:
    r = 0.02
    path = np.array([[0, 0, 0], [0, 1, 0], [0, 1, 1], [0, 2, 1], [1, 2, 1], [1, 1, 1], [1, 1, 0], [1, 0, 0.0]])
    seg, per = 8, 12 * d
    for k in range(len(path) - 1):
        a, b = path[k], path[k + 1]
        axis = int(np.argmax(np.abs(b - a)))
        lo = np.minimum(a, b)
        V, F = cylinder(lo, float(np.abs(b - a).max()), r, seg, per, caps=False, axis=axis, barrel=0.3)
        o.add(V, F, f"frame{k % 2}")
    for x in (0.25, 0.5, 0.75):  # rungs through the frame's sides
        V, F = cylinder((x, 1.0, -0.05), 1.1, r * 0.8, seg, 8 * d, caps=False, axis=2)
        o.add(V, F, "rung")


def _fins(o: _Obj, d: int) -> None:
    n = 6 * d
    for k, ang in enumerate(np.radians([0, 100, 220, 300])):
        def fn(u, v, ang=ang):  # panels with a wave across them
            w = 0.05 * np.sin(np.pi * u) * np.sin(2 * np.pi * v)
            return np.stack([u * np.cos(ang) - w * np.sin(ang), v, u * np.sin(ang) + w * np.cos(ang)], 1)
        V, F, _ = grid_surface(n, n, fn)
        o.add(V, F, f"fin{k}")
    V, F = box((-0.05, 0, -0.05), (0.05, 1.2, 0.05), n)  # a post through the shared edge
    o.add(V, F, "post")


def _broken_uvs(o: _Obj, d: int) -> None:
    def fn(u, v):
        a, b = 2 * np.pi * u, np.pi * v
        r = 1 + 0.1 * np.sin(5 * a) * np.sin(3 * b)
        return np.stack([r * np.sin(b) * np.cos(a), r * np.cos(b), r * np.sin(b) * np.sin(a)], 1)
    V, F, uv = grid_surface(24 * d, 16 * d, fn)
    rng = np.random.default_rng(5)
    # whole patches of the surface lost their UVs (a bad export), not single triangles
    cen = V[F].mean(axis=1)
    holes = rng.normal(size=(6, 3))
    holes /= np.linalg.norm(holes, axis=1, keepdims=True)
    lost = (np.linalg.norm(cen[:, None, :] - holes[None], axis=2) < 0.45).any(axis=1)
    o.add(V, F, "painted", uv=uv, uv_mask=~lost)


def _two_sided(o: _Obj, d: int) -> None:
    def fn(u, v):
        return np.stack([u * 2 - 1, 0.3 * np.sin(np.pi * u) * np.cos(np.pi * v), v * 2 - 1], 1)
    V, F, _ = grid_surface(16 * d, 16 * d, fn)
    o.add(V, F, "front")
    o.add(V, F[:, [0, 2, 1]], "back")
    V, F = box((-0.5, 0.5, -0.5), (0.5, 1.5, 0.5), 4 * d, bulge=0.15)
    o.add(V, np.concatenate([F, F]), "doubled")


_BUILD = {"touching": _touching, "crossing": _crossing, "tubes": _tubes, "fins": _fins,
          "broken_uvs": _broken_uvs, "two_sided": _two_sided}


def write(case: str, folder: str | Path, detail: int = 1) -> Path:
    """Write ``case`` (one of CASES) as ``<case>.obj`` (+ .mtl, + texture) into ``folder``."""
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    o = _Obj()
    _BUILD[case](o, detail)
    mats = sorted({m for m, _, _ in o.faces})
    mtl = []
    for k, m in enumerate(mats):
        rgb = np.array([(37 * k + 80) % 256, (91 * k + 40) % 256, (53 * k + 160) % 256]) / 255.0
        mtl += [f"newmtl {m}", "Kd {:.4f} {:.4f} {:.4f}".format(*rgb)]
        if case == "broken_uvs":
            mtl.append(f"map_Kd {case}.png")
    (folder / f"{case}.mtl").write_text("\n".join(mtl) + "\n")
    if case == "broken_uvs":
        from PIL import Image

        y, x = np.mgrid[0:64, 0:64]
        img = np.stack([(x * 4) % 256, (y * 4) % 256, ((x // 8 + y // 8) % 2) * 255], -1).astype(np.uint8)
        Image.fromarray(img).save(folder / f"{case}.png")
    path = folder / f"{case}.obj"
    path.write_text(o.text(f"{case}.mtl"))
    return path
