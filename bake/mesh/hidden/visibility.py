"""Which triangles an eye sees: Embree rays, batched over every eye (docs/hidden.md).

A ray *draws* the triangle it hits when the triangle's front faces the ray's origin, or the
triangle is two-sided (``back_faces = "drawn"`` makes every triangle two-sided): the rule of the
reader sprite and ``bake.render``, whose culling is ``dot(cross(b - a, c - a), eye - a) > 0``. A
ray stops at the first triangle it draws that is opaque; it goes on through a triangle it does
not draw (the back of a single-sided one: culled, so it hides nothing) and through a see-through
one (drawn, and what is behind it shows). Every triangle a ray draws before it stops is *seen*.
Each such continuation is one more vectorised Embree call over all the rays still going, from
just past the hit (``Tracer.epsilon``), at most ``MAX_CHAIN`` times.

Three uses, each a batch of rays cut into fixed chunks (deterministic for any thread count; every
chunk's random numbers come from its own ``(seed, stream, chunk)`` generator):

* :meth:`Visibility.targeted`: from every eye, ``samples`` rays at stratified points of each
  candidate triangle that could face it (:meth:`Visibility.directed`: the same for explicit
  (eye, triangle) pairs); each records, per triangle it sees first, its *witness*: the eye of
  the lowest-numbered ray that drew it and where that ray was aimed;
* :meth:`Visibility.pixels`: a pixel grid from each held-out eye (a view holding the model from an
  outside eye, a cube map around an eye in a box or at a point), and the pixels whose ray draws a
  dropped triangle (the proof);
* :meth:`Visibility.casters`: from points of the kept triangles towards the lights and over the
  hemisphere, the first triangle hit (what shadows or bounces light onto them: lighting's rays see
  every triangle from both sides).
"""

from __future__ import annotations

import threading

import numpy as np

from ...geometry import tangent_frames
from ...lighting.rays import CHUNK_RAYS, Tracer, parallel

MAX_CHAIN = 64  # continuations through see-through and culled triangles, per ray
GOLDEN = (np.sqrt(5.0) - 1.0) / 2.0
CORNER_INSET = 1e-3
MIN_BATCH_RAYS = 1 << 15  # a batch of eyes aims at least this many rays (the calls' overhead)
DECIDE_CHUNK_RAYS = 1 << 14  # rays per work item while deciding: a batch of MIN_BATCH_RAYS is 2 items (2 threads)
INSET = (1.0 - 1.5 * CORNER_INSET) * np.eye(3) + 0.5 * CORNER_INSET  # barycentrics just inside the corners


def stratified_barycentric(k: int, r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
    """(n, k, 3) barycentric weights: point ``j`` of ``k`` in the ``j``-th of ``k`` equal-area
    strata of the triangle (square-root warp of a shifted rank-1 lattice; ``r1``, ``r2`` (n,)
    are the shifts)."""
    j = np.arange(k, dtype=np.float64)
    u = (j[None, :] + r1[:, None]) / k
    v = np.mod(r2[:, None] + j[None, :] * GOLDEN, 1.0)
    s = np.sqrt(u)
    return np.stack([1.0 - s, s * (1.0 - v), s * v], axis=-1)


def _lowest(prims: np.ndarray, key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The distinct triangles of ``prims`` and, for each, the index of its lowest ``key`` (keys
    distinct and >= 0): one sort of ``prims x (max key + 1) + key``."""
    if len(prims) == 0:
        return prims, np.zeros(0, np.int64)
    order = np.argsort(prims * (int(key.max()) + 1) + key)
    p = prims[order]
    first = np.ones(len(order), bool)
    first[1:] = p[1:] != p[:-1]
    return p[first], order[first]


class Visibility:
    def __init__(self, positions: np.ndarray, triangles: np.ndarray, *, two_sided: np.ndarray,
                 see_through: np.ndarray, threads: int = 0):
        self.pos = np.asarray(positions, np.float64)
        self.tris = np.asarray(triangles, np.int64)
        self.corners = self.pos[self.tris]
        c = self.corners
        self.normal = np.cross(c[:, 1] - c[:, 0], c[:, 2] - c[:, 0])
        self.two_sided = np.asarray(two_sided, bool)
        self.see_through = np.asarray(see_through, bool)
        self.tracer = Tracer(self.pos, self.tris, threads=threads)
        self.T = len(self.tris)
        self.rays = 0
        self._lock = threading.Lock()

    # ------------------------------------------------------------------ the chain of one batch
    def chain(self, o: np.ndarray, d: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
        """Rays from world points ``o`` along unit ``d`` (float64): ``(ray, triangle)`` of every
        triangle drawn before each ray stops, and the rays cut short after MAX_CHAIN steps."""
        n = len(o)
        idx = np.arange(n)
        start = self.tracer.to_local(o)
        d = np.asarray(d, np.float64)
        rays_out, prims_out = [], []
        casts = 0
        for _ in range(MAX_CHAIN):
            if len(idx) == 0:
                break
            h = self.tracer.intersect(start.astype(np.float32), d.astype(np.float32))
            casts += len(idx)
            prim = np.asarray(h["prim"], np.int64)
            hit = np.flatnonzero((prim >= 0) & (prim < self.T))
            prim, dh = prim[hit], d[hit]
            drawn = (np.einsum("ij,ij->i", self.normal[prim], dh) < 0) | self.two_sided[prim]
            rays_out.append(idx[hit[drawn]])
            prims_out.append(prim[drawn])
            go = hit[~drawn | self.see_through[prim]]  # the rays that go on (few: culled, see-through)
            idx, start, d = idx[go], start[go], d[go]
            t = np.asarray(h["t"], np.float64)[go]
            at = start + t[:, None] * d
            start = at + self.tracer.epsilon(at)[:, None] * d
        with self._lock:
            self.rays += casts
        cat = (lambda a: np.concatenate(a) if a else np.zeros(0, np.int64))
        return cat(rays_out), cat(prims_out), int(len(idx))

    # ------------------------------------------------------------------ deciding
    def targeted(self, eyes: np.ndarray, candidates: np.ndarray, samples: int, seed: int, stream: int,
                 batch: int = 8, corners: bool = False, witness: np.ndarray | None = None,
                 owner: np.ndarray | None = None) -> tuple[np.ndarray, int]:
        """``(seen (T,) bool, rays cut short)``: from every eye, ``samples`` rays at stratified
        points of each candidate triangle whose front faces the eye (or that is two-sided). The
        eyes go in batches of ``batch``; a batch aims only at the candidates no batch before it saw
        (a triangle seen once is decided), so a dropped triangle was aimed at from every eye.
        ``corners``: also aim just inside each corner (``CORNER_INSET`` of the way to the others):
        the piece of a triangle that pokes out through another surface holds a corner unless
        the surface bulges through the triangle's middle. ``witness``: see :meth:`_witness`
        (``owner``: the region of each eye)."""
        seen = np.zeros(self.T, bool)
        short = 0
        cand = np.asarray(candidates, np.int64)
        first, b = 0, 0
        while first < len(eyes) and len(cand):
            # at least `batch` eyes, and enough for a batch of MIN_BATCH_RAYS rays (few candidates)
            n = max(batch, -(-MIN_BATCH_RAYS // (len(cand) * (samples + 3 * corners))))
            ee = eyes[first:first + n]
            C = len(cand)
            has = None if witness is None else ~np.isnan(witness[:, 0])
            got, hit, cut = self._aim(ee, cand, len(ee) * C, lambda q, C=C: (q // C, q % C), samples, seed,
                                      stream * 4099 + b, corners, has)
            if witness is not None:
                self._witness(witness, hit, ee, None if owner is None else owner[first:first + n],
                              lambda q, C=C: q // C)
            seen |= got
            short += cut
            cand = cand[~seen[cand]]
            first, b = first + n, b + 1
        return seen, short

    def directed(self, eyes: np.ndarray, aim: np.ndarray, samples: int, seed: int, stream: int,
                 witness: np.ndarray | None = None, owner: np.ndarray | None = None) -> tuple[np.ndarray, int]:
        """``(seen (T,) bool, rays cut short)``: from each eye ``eyes[i]``, ``samples`` rays at
        stratified points of triangle ``aim[i]`` and one just inside each of its corners (if it
        could face the eye): explicit (eye, triangle) pairs, in one batch."""
        aim = np.asarray(aim, np.int64)
        if len(aim) == 0:
            return np.zeros(self.T, bool), 0
        has = None if witness is None else ~np.isnan(witness[:, 0])
        seen, hit, cut = self._aim(eyes, aim, len(aim), lambda q: (q, q), samples, seed, stream, True, has)
        if witness is not None:
            self._witness(witness, hit, eyes, owner, lambda q: q)
        return seen, cut

    @staticmethod
    def _witness(witness: np.ndarray, hit, eyes: np.ndarray, owner: np.ndarray | None, eye_of) -> None:
        """``witness`` (T, 7), NaN where none yet: for each triangle a batch saw that has none, the
        eye of the batch's lowest-numbered ray that drew it, that eye's region (``owner``) and the
        point the ray was aimed at (the rays of every work item: the answer is the same for any
        thread count)."""
        prims, key, target, k = hit
        q = eye_of(key // k)
        witness[prims, :3] = eyes[q]
        witness[prims, 3] = -1.0 if owner is None else owner[q]
        witness[prims, 4:7] = target

    def _aim(self, eyes: np.ndarray, cand: np.ndarray, P: int, pair, samples: int, seed: int, stream: int,
             corners: bool, has: np.ndarray | None = None
             ) -> tuple[np.ndarray, tuple[np.ndarray, np.ndarray, np.ndarray, int], int]:
        """The rays of ``P`` (eye, candidate) pairs, ``pair(q) -> (eye numbers, candidate numbers)``:
        ``(seen (T,), (triangles drawn that ``has`` (a witness already) is not true of, the lowest
        ray number that drew each, where that ray was aimed, rays per pair), rays cut short)``."""
        cand = np.asarray(cand, np.int64)
        kk = samples + 3 * corners
        seen = np.zeros(self.T, bool)
        parts: list[tuple[np.ndarray, np.ndarray, np.ndarray]] = []
        short = [0]
        none = (np.zeros(0, np.int64), np.zeros(0, np.int64), np.zeros((0, 3)), kk)
        if P == 0:
            return seen, none, 0
        # the random numbers: one generator per CHUNK_RAYS rays of pairs, as drawn up front; the
        # work goes in smaller items (DECIDE_CHUNK_RAYS: both threads busy on a small batch)
        rng_per = max(1, CHUNK_RAYS // kk)
        R1, R2 = np.empty(P), np.empty(P)
        for s0 in range(0, P, rng_per):
            rng = np.random.default_rng([seed, stream, s0 // rng_per])
            n = min(P, s0 + rng_per) - s0
            R1[s0:s0 + n], R2[s0:s0 + n] = rng.random(n), rng.random(n)
        per = max(1, DECIDE_CHUNK_RAYS // kk)
        lock = threading.Lock()
        # the candidates' corners, normals and sidedness gathered once per batch, not once per ray
        cc = self.corners[cand]
        c0, cn, c2 = np.ascontiguousarray(cc[:, 0]), self.normal[cand], self.two_sided[cand]
        cin = np.einsum("kc,ncx->nkx", INSET, cc) if corners else None

        def work(a: int, b: int) -> None:
            q = np.arange(a, b)
            e, j = pair(q)
            r1, r2 = R1[a:b], R2[a:b]
            rel = eyes[e] - c0[j]
            ok = np.flatnonzero((np.einsum("ij,ij->i", cn[j], rel) > 0) | c2[j])
            e, j, r1, r2 = e[ok], j[ok], r1[ok], r2[ok]
            w = stratified_barycentric(samples, r1, r2)  # (n, k, 3)
            target = np.einsum("nkc,ncx->nkx", w, cc[j])
            if corners:
                target = np.concatenate([target, cin[j]], axis=1)
            k = target.shape[1]
            target = target.reshape(-1, 3)
            o = np.repeat(eyes[e], k, axis=0)
            d = target - o
            ln = np.linalg.norm(d, axis=1)
            good = np.flatnonzero(ln > 0)
            d = d[good] / ln[good, None]
            rays, prims, cut = self.chain(o[good], d)
            mine = np.zeros(self.T, bool)
            mine[prims] = True
            if has is not None:  # the witnesses of the triangles that have none yet
                new = np.flatnonzero(~has[prims])
                row = good[rays[new]]
                key = (a + ok[row // k]) * k + row % k  # the ray's number in the batch
                up, first = _lowest(prims[new], key)
            with lock:
                np.logical_or(seen, mine, out=seen)
                if has is not None:
                    parts.append((up, key[first], target[row[first]]))
                short[0] += cut

        parallel(P, per, work, self.tracer.threads)
        if not parts:
            return seen, none, short[0]
        prims = np.concatenate([x[0] for x in parts])
        key = np.concatenate([x[1] for x in parts])
        target = np.concatenate([x[2] for x in parts])
        up, first = _lowest(prims, key)
        return seen, (up, key[first], target[first], kk), short[0]

    # ------------------------------------------------------------------ the proof
    @staticmethod
    def cube_directions(pixels: int) -> np.ndarray:
        """(6 P^2, 3) unit directions through the pixel centres of a cube map of side ``P``."""
        P = int(pixels)
        g = (np.arange(P) + 0.5) / P * 2.0 - 1.0
        u, v = np.meshgrid(g, g, indexing="xy")
        u, v = u.ravel(), v.ravel()
        faces = []
        for axis in range(3):
            for sign in (1.0, -1.0):
                f = np.zeros((P * P, 3))
                f[:, axis] = sign
                f[:, (axis + 1) % 3] = u
                f[:, (axis + 2) % 3] = v
                faces.append(f)
        d = np.concatenate(faces)
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    @staticmethod
    def view_directions(eye: np.ndarray, center: np.ndarray, radius: float, pixels: int) -> np.ndarray:
        """(P^2, 3) unit directions through the pixel centres of a square pinhole view from ``eye``
        at ``center`` whose field of view just holds the sphere (``center``, ``radius``)."""
        P = int(pixels)
        f = center - eye
        dist = float(np.linalg.norm(f))
        f = f / dist
        a = np.array([0.0, 1.0, 0.0]) if abs(f[1]) < 0.9 else np.array([1.0, 0.0, 0.0])
        r = np.cross(a, f)
        r /= np.linalg.norm(r)
        u = np.cross(f, r)
        s = radius / dist
        half = s / np.sqrt(max(1.0 - s * s, 1e-12))  # tan of the sphere's angular radius
        g = ((np.arange(P) + 0.5) / P * 2.0 - 1.0) * half
        x, y = np.meshgrid(g, g, indexing="xy")
        d = f[None, :] + x.ravel()[:, None] * r[None, :] + y.ravel()[:, None] * u[None, :]
        return d / np.linalg.norm(d, axis=1, keepdims=True)

    def pixels(self, eyes: np.ndarray, views: list[np.ndarray], dropped: np.ndarray) -> dict:
        """Pixel-centre rays ``views[i]`` (unit directions) from each eye ``eyes[i]``, through the
        full mesh; a pixel is wrong when its ray draws a dropped triangle. Counts (also per eye), and
        the dropped triangles the held-out eyes saw."""
        dropped = np.asarray(dropped, bool)
        totals = {"wrong": 0, "covered": 0, "short": 0, "pixels": 0}
        per_eye = np.zeros(len(eyes), np.int64)
        seen_dropped = np.zeros(self.T, bool)
        lock = threading.Lock()

        def work(a: int, b: int) -> None:
            for i in range(a, b):  # one eye's view at a time: tens of thousands of rays each
                d = views[i]
                o = np.broadcast_to(eyes[i], d.shape)
                rays, prims, cut = self.chain(np.ascontiguousarray(o), d)
                bad = dropped[prims]
                mine = np.zeros(self.T, bool)
                mine[prims[bad]] = True
                wrong = int(len(np.unique(rays[bad])))
                per_eye[i] = wrong
                with lock:
                    totals["wrong"] += wrong
                    totals["covered"] += int(len(np.unique(rays)))
                    totals["short"] += cut
                    totals["pixels"] += len(d)
                    np.logical_or(seen_dropped, mine, out=seen_dropped)

        parallel(len(eyes), 1, work, self.tracer.threads)
        return {"pixels": totals["pixels"], "covered": totals["covered"], "wrong": totals["wrong"],
                "cut_short": totals["short"], "dropped_seen": seen_dropped, "wrong_per_eye": per_eye}

    # ------------------------------------------------------------------ lighting
    def surface_points(self, ids: np.ndarray, cell: float, max_level: int, samples: int, seed: int
                       ) -> tuple[np.ndarray, np.ndarray]:
        """Points on the triangles ``ids``: their corners, the centroids of an ``m x m`` cut of each
        (``m = ceil(longest edge / cell)``, at most ``max_level``: the lighting stage's interior
        points) and ``samples`` stratified random points; ``(points, triangle of each)``."""
        c = self.corners[ids]
        longest = np.max(np.linalg.norm(c - np.roll(c, 1, axis=1), axis=2), axis=1)
        m = np.clip(np.ceil(longest / max(cell, 1e-300)), 1, max_level).astype(np.int64)
        pts, owner = [c.reshape(-1, 3)], [np.repeat(ids, 3)]
        for level in np.unique(m):
            sel = m == level
            i, j = np.meshgrid(np.arange(level), np.arange(level), indexing="ij")
            ok = (i + j) < level
            up = np.stack([(i[ok] + 1 / 3), (j[ok] + 1 / 3)], 1) / level  # upright sub-triangles
            ok2 = (i + j) < level - 1
            down = np.stack([(i[ok2] + 2 / 3), (j[ok2] + 2 / 3)], 1) / level  # the inverted ones
            uv = np.concatenate([up, down])
            w = np.stack([1 - uv.sum(1), uv[:, 0], uv[:, 1]], 1)
            cs = c[sel]
            pts.append(np.einsum("kc,ncx->nkx", w, cs).reshape(-1, 3))
            owner.append(np.repeat(ids[sel], len(w)))
        rng = np.random.default_rng([seed, 7])
        w = stratified_barycentric(samples, rng.random(len(ids)), rng.random(len(ids)))
        pts.append(np.einsum("nkc,ncx->nkx", w, c).reshape(-1, 3))
        owner.append(np.repeat(ids, samples))
        return np.concatenate(pts), np.concatenate(owner)

    def casters(self, points: np.ndarray, owner: np.ndarray, directions: list[np.ndarray],
                lights: list[np.ndarray], hemisphere: int, seed: int) -> np.ndarray:
        """(T,) bool: the triangles first hit by rays from ``points`` (on the triangles ``owner``,
        from each side a triangle is drawn from) towards every direction (unit, towards a light),
        every light position (up to it) and over ``hemisphere`` cosine-weighted directions."""
        out = np.zeros(self.T, bool)
        if len(points) == 0:
            return out
        rng = np.random.default_rng([seed, 8])
        nrm = self.normal[owner]
        nrm = nrm / np.maximum(np.linalg.norm(nrm, axis=1, keepdims=True), 1e-300)
        sides = [(points, nrm)]
        back = self.two_sided[owner]
        if back.any():
            sides.append((points[back], -nrm[back]))
        for q, n in sides:
            loc = self.tracer.to_local(q)
            lo = loc + self.tracer.epsilon(loc)[:, None] * n
            jobs: list[tuple[np.ndarray, np.ndarray | None]] = []
            for d in directions:
                jobs.append((np.ascontiguousarray(np.broadcast_to(np.asarray(d, np.float64), n.shape)), None))
            for lp in lights:
                dd = self.tracer.to_local(np.asarray(lp, np.float64)[None, :]) - lo
                ln = np.linalg.norm(dd, axis=1)
                jobs.append((dd / np.maximum(ln, 1e-300)[:, None], ln))
            for _ in range(hemisphere):
                jobs.append((self._cosine(n, rng.random(len(q)), rng.random(len(q))), None))
            for d, ln in jobs:
                facing = np.einsum("ij,ij->i", d, n) > 0
                h = self.tracer.intersect(lo[facing].astype(np.float32), d[facing].astype(np.float32),
                                          dist=None if ln is None else ln[facing])
                self.rays += int(facing.sum())
                prim = np.asarray(h["prim"], np.int64)
                out[prim[(prim >= 0) & (prim < self.T)]] = True
        return out

    @staticmethod
    def _cosine(n: np.ndarray, r1: np.ndarray, r2: np.ndarray) -> np.ndarray:
        t, b = tangent_frames(n)
        s, phi = np.sqrt(r1), 2 * np.pi * r2
        z = np.sqrt(np.clip(1 - r1, 0, 1))
        return (s * np.cos(phi))[:, None] * t + (s * np.sin(phi))[:, None] * b + z[:, None] * n


__all__ = ["Visibility", "stratified_barycentric", "MAX_CHAIN"]
