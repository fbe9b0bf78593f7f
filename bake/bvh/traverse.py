"""Reference traversals that read the exported lists exactly as the Scratch scripts in
``docs/formats-bvh.md`` do, and brute force over the same triangles.

Two implementations per layout, with identical arithmetic (IEEE float64, the same operation
order, like Scratch's JavaScript numbers):

* :func:`trace_one` -- one ray, a plain loop that mirrors the Scratch blocks item for item;
* :func:`trace` -- a batch of rays walking the flat lists together with masks (the same reads,
  the same results; this is what tests and benchmarks use for 100k rays).

Both return the closest hit ``t`` (inf on a miss), the leaf *slot* (0-based; -1 on a miss),
the scene triangle number from the ids list (1-based, 0 on a miss), barycentrics ``u, v``
(hit = (1-u-v) v0 + u v1 + v v2) and the number of list items read (node list, triangle list,
id list and stack reads; writes and local variables are free).

Ray set-up (no list reads): ``inv = 1 / d`` per axis, or ``1e30`` when ``|d| < 1e-30``; the near
plane of a box on an axis is its lo plane when ``inv >= 0``, else its hi plane.

The triangle test (Möller-Trumbore, double-sided) accepts barycentrics within ``BARY_EPS`` = 1e-9
of the triangle (``u >= -1e-9``, ``v >= -1e-9``, ``u + v <= 1.000000001``), so rays through shared
edges and vertices of a closed mesh cannot slip between its triangles.
"""

from __future__ import annotations

from dataclasses import dataclass
import math

import numpy as np

from .encode import BIN_STRIDE, LEAF_BASE, WIDE_HEADER, Encoded

TINY_DIR = 1e-30
BIG_INV = 1e30
# a hit counts only if det^2 > PARALLEL * |e1|^2 |d x e2|^2, i.e. the ray is not within about
# 1e-6 radians of the triangle's plane (where float rounding can put the hit anywhere)
PARALLEL = 1e-12
# the inside test accepts barycentrics down to -BARY_EPS (u >= -eps, v >= -eps, u + v <= 1 + eps):
# a ray through an edge or vertex shared by two triangles computes u = -1e-17 or so on *both*
# sides and a plain test lets it through (docs/reliability.md item 4). 1e-13 already closed every
# leak measured (icospheres up to 1e6 from the origin), so 1e-9 has a wide margin; it grows a
# triangle by 1e-9 of its heights (far below the list grid), and a duplicate hit on the neighbour
# is harmless to a closest-hit search. In Scratch it changes only typed-in numbers (no blocks).
BARY_EPS = 1e-9
BARY_LO = -BARY_EPS  # -1e-09
BARY_HI = 1 + BARY_EPS  # 1.000000001 (exactly the double a typed-in 1.000000001 gives)


@dataclass
class Hits:
    t: np.ndarray  # (R,) float64, inf = miss
    slot: np.ndarray  # (R,) int64, -1 = miss
    tri: np.ndarray  # (R,) int64 scene triangle number, 1-based; 0 = miss
    u: np.ndarray
    v: np.ndarray
    reads: np.ndarray  # (R,) int64 list items read
    boxes: np.ndarray | None = None  # (R,) box tests
    tests: np.ndarray | None = None  # (R,) triangle tests
    stack: np.ndarray | None = None  # (R,) most stack entries held at once (4-wide layouts)

    @property
    def hit(self) -> np.ndarray:
        return self.slot >= 0


# =========================================================================== one ray
class _Reader:
    def __init__(self) -> None:
        self.reads = 0

    def item(self, lst, i: int) -> float:  # 1-based, like Scratch
        self.reads += 1
        return float(lst[int(i) - 1])


def _setup(d):
    inv = []
    near = []
    for k in range(3):
        x = float(d[k])
        iv = BIG_INV if abs(x) < TINY_DIR else 1.0 / x
        inv.append(iv)
        near.append(0 if iv >= 0 else 3)
    return inv, near


def _slab(planes, o, inv, near, tbest):
    """planes = (lox, loy, loz, hix, hiy, hiz). Returns (hit, tnear)."""
    nx = (planes[near[0]] - o[0]) * inv[0]
    fx = (planes[3 - near[0]] - o[0]) * inv[0]
    ny = (planes[1 + near[1]] - o[1]) * inv[1]
    fy = (planes[4 - near[1]] - o[1]) * inv[1]
    nz = (planes[2 + near[2]] - o[2]) * inv[2]
    fz = (planes[5 - near[2]] - o[2]) * inv[2]
    tn = nx
    if ny > tn:
        tn = ny
    if nz > tn:
        tn = nz
    tf = fx
    if fy < tf:
        tf = fy
    if fz < tf:
        tf = fz
    return (tn <= tf and tf >= 0 and tn <= tbest), tn


def _tri_one(rd, tris, slot1, o, best, tmin):
    # o = (ox, oy, oz, dx, dy, dz)
    """Möller-Trumbore on slot ``slot1`` (1-based). ``best`` = [t, slot0, u, v]."""
    b = (slot1 - 1) * 9
    v0x, v0y, v0z = rd.item(tris, b + 1), rd.item(tris, b + 2), rd.item(tris, b + 3)
    v1x, v1y, v1z = rd.item(tris, b + 4), rd.item(tris, b + 5), rd.item(tris, b + 6)
    v2x, v2y, v2z = rd.item(tris, b + 7), rd.item(tris, b + 8), rd.item(tris, b + 9)
    e1x, e1y, e1z = v1x - v0x, v1y - v0y, v1z - v0z
    e2x, e2y, e2z = v2x - v0x, v2y - v0y, v2z - v0z
    dx, dy, dz = o[3], o[4], o[5]
    px = dy * e2z - dz * e2y
    py = dz * e2x - dx * e2z
    pz = dx * e2y - dy * e2x
    det = e1x * px + e1y * py + e1z * pz
    # reject rays (nearly) in the triangle's plane: there the hit point is ill-conditioned
    if det * det <= PARALLEL * ((e1x * e1x + e1y * e1y + e1z * e1z) * (px * px + py * py + pz * pz)):
        return
    inv = 1 / det
    sx, sy, sz = o[0] - v0x, o[1] - v0y, o[2] - v0z
    u = (sx * px + sy * py + sz * pz) * inv
    if u < BARY_LO or u > BARY_HI:
        return
    qx = sy * e1z - sz * e1y
    qy = sz * e1x - sx * e1z
    qz = sx * e1y - sy * e1x
    v = (dx * qx + dy * qy + dz * qz) * inv
    if v < BARY_LO or u + v > BARY_HI:
        return
    t = (e2x * qx + e2y * qy + e2z * qz) * inv
    if t > tmin and t < best[0]:
        best[0], best[1], best[2], best[3] = t, slot1 - 1, u, v


def trace_one(enc: Encoded, origin, direction, tmin: float = 0.0, tmax: float = math.inf):
    """One ray through the lists, as the Scratch script does it.
    Returns ``(t, slot0, tri_id, u, v, reads)``."""
    o = [float(origin[0]), float(origin[1]), float(origin[2]),
         float(direction[0]), float(direction[1]), float(direction[2])]
    inv, near = _setup(direction)
    rd = _Reader()
    best = [float(tmax), -1, 0.0, 0.0]
    nodes, tris = enc.nodes, enc.tris
    L = len(nodes)
    if enc.layout == "binary":
        p = 1
        while p <= L:
            planes = [0.0] * 6
            for k in range(6):
                planes[k] = rd.item(nodes, p + k)
            hit, _ = _slab(planes, o, inv, near, best[0])
            link = rd.item(nodes, p + 6)
            if hit:
                if link > 0:
                    first = math.floor(link / LEAF_BASE)
                    cnt = link - first * LEAF_BASE
                    for s in range(first, first + int(cnt)):
                        _tri_one(rd, tris, s, o, best, tmin)
                p = p + BIN_STRIDE
            else:
                p = -link if link < 0 else p + BIN_STRIDE
    elif L > 0:
        quant = enc.layout == "quantised"
        stride = enc.stride
        M = 2 ** enc.bits
        Q = float(M - 2) if M > 2 else 1.0
        frame = [rd.item(nodes, k) for k in range(1, 7)]
        hit, _ = _slab(frame, o, inv, near, best[0])
        stack: list[float] = []
        p = WIDE_HEADER + 1 if hit else 0
        while p > 0:
            m = rd.item(nodes, p)
            if quant:
                c = [(frame[3 + k] - frame[k]) / Q for k in range(3)]
            j = 0
            ni = 0
            nl = 0
            found = []
            while m > 0:
                code = m % LEAF_BASE
                m = math.floor(m / LEAF_BASE)
                if quant:
                    w = rd.item(nodes, p + 3 + j)
                    qs = []
                    for _k in range(6):
                        qs.append(w % M)
                        w = math.floor(w / M)
                    planes = [frame[0] + qs[0] * c[0], frame[1] + qs[1] * c[1], frame[2] + qs[2] * c[2],
                              frame[0] + qs[3] * c[0], frame[1] + qs[4] * c[1], frame[2] + qs[5] * c[2]]
                    # only the near and far plane of each axis is needed; 6 decodes either way
                else:
                    base = p + 3 + 6 * j
                    planes = [0.0] * 6
                    for k in range(6):
                        planes[k] = rd.item(nodes, base + k)
                hit, tn = _slab(planes, o, inv, near, best[0])
                if code == LEAF_BASE - 1:
                    if hit:
                        ptr = rd.item(nodes, p + 1) + ni * stride
                        found.append((tn, j, ptr, planes))
                    ni += 1
                else:
                    if hit:
                        first = rd.item(nodes, p + 2) + nl
                        for s in range(int(first), int(first + code)):
                            _tri_one(rd, tris, s, o, best, tmin)
                    nl += int(code)
                j += 1
            # push far to near, so the nearest child is on top
            found.sort(key=lambda e: (e[0], e[1]))
            for tn, _j, ptr, planes in reversed(found):
                if tn <= best[0]:
                    if quant:
                        stack.extend(planes)
                    stack.append(ptr)
                    stack.append(tn)
            p = 0
            while stack:
                tn = rd.item(stack, len(stack))
                stack.pop()
                if tn <= best[0]:
                    p = int(rd.item(stack, len(stack)))
                    stack.pop()
                    if quant:
                        fr = [0.0] * 6
                        for k in range(5, -1, -1):
                            fr[k] = rd.item(stack, len(stack))
                            stack.pop()
                        frame = fr
                    break
                del stack[len(stack) - (7 if quant else 1):]
    if best[1] < 0:
        return math.inf, -1, 0, 0.0, 0.0, rd.reads
    tri_id = int(rd.item(enc.ids, best[1] + 1))
    return best[0], best[1], tri_id, best[2], best[3], rd.reads


# =========================================================================== ray batches
class _Batch:
    """State of a batch of rays (all arrays (R,))."""

    def __init__(self, o, d, tmin, tmax):
        o = np.asarray(o, np.float64).reshape(-1, 3)
        d = np.asarray(d, np.float64).reshape(-1, 3)
        self.o, self.d = o, d
        R = len(o)
        with np.errstate(divide="ignore"):
            self.inv = np.where(np.abs(d) < TINY_DIR, BIG_INV, 1.0 / np.where(d == 0, 1.0, d))
        self.near = np.where(self.inv >= 0, 0, 3).astype(np.int64)
        self.tmin = float(tmin)
        self.t = np.full(R, float(tmax))
        self.slot = np.full(R, -1, np.int64)
        self.u = np.zeros(R)
        self.v = np.zeros(R)
        self.reads = np.zeros(R, np.int64)
        self.boxes = np.zeros(R, np.int64)
        self.tests = np.zeros(R, np.int64)
        self.stack = np.zeros(R, np.int64)

    def slab(self, idx, planes):
        """planes (n, 6) for rays idx -> (hit, tnear); identical arithmetic to ``_slab``."""
        o, inv, nr = self.o[idx], self.inv[idx], self.near[idx]
        r = np.arange(len(idx))
        n = [None] * 3
        f = [None] * 3
        for k in range(3):
            n[k] = (planes[r, k + nr[:, k]] - o[:, k]) * inv[:, k]
            f[k] = (planes[r, k + 3 - nr[:, k]] - o[:, k]) * inv[:, k]
        tn = n[0].copy()
        np.copyto(tn, n[1], where=n[1] > tn)
        np.copyto(tn, n[2], where=n[2] > tn)
        tf = f[0].copy()
        np.copyto(tf, f[1], where=f[1] < tf)
        np.copyto(tf, f[2], where=f[2] < tf)
        self.boxes[idx] += 1
        return (tn <= tf) & (tf >= 0) & (tn <= self.t[idx]), tn

    def tri(self, idx, slot1, tris):
        """Möller-Trumbore for rays ``idx`` against slots ``slot1`` (1-based), in place."""
        if len(idx) == 0:
            return
        b = (slot1 - 1) * 9
        V = tris[b[:, None] + np.arange(9)]
        self.reads[idx] += 9
        self.tests[idx] += 1
        o, d = self.o[idx], self.d[idx]
        v0x, v0y, v0z = V[:, 0], V[:, 1], V[:, 2]
        e1x, e1y, e1z = V[:, 3] - v0x, V[:, 4] - v0y, V[:, 5] - v0z
        e2x, e2y, e2z = V[:, 6] - v0x, V[:, 7] - v0y, V[:, 8] - v0z
        dx, dy, dz = d[:, 0], d[:, 1], d[:, 2]
        with np.errstate(all="ignore"):
            px = dy * e2z - dz * e2y
            py = dz * e2x - dx * e2z
            pz = dx * e2y - dy * e2x
            det = e1x * px + e1y * py + e1z * pz
            ok = det * det > PARALLEL * ((e1x * e1x + e1y * e1y + e1z * e1z) * (px * px + py * py + pz * pz))
            inv = 1 / np.where(ok, det, 1.0)
            sx, sy, sz = o[:, 0] - v0x, o[:, 1] - v0y, o[:, 2] - v0z
            u = (sx * px + sy * py + sz * pz) * inv
            ok &= (u >= BARY_LO) & (u <= BARY_HI)
            qx = sy * e1z - sz * e1y
            qy = sz * e1x - sx * e1z
            qz = sx * e1y - sy * e1x
            v = (dx * qx + dy * qy + dz * qz) * inv
            ok &= (v >= BARY_LO) & (u + v <= BARY_HI)
            t = (e2x * qx + e2y * qy + e2z * qz) * inv
        ok &= (t > self.tmin) & (t < self.t[idx])
        w = idx[ok]
        self.t[w] = t[ok]
        self.slot[w] = slot1[ok] - 1
        self.u[w] = u[ok]
        self.v[w] = v[ok]

    def leaf(self, idx, first1, cnt, tris):
        """Test ``cnt`` slots from ``first1`` (1-based) for rays idx, in slot order."""
        for k in range(int(cnt.max()) if len(cnt) else 0):
            m = cnt > k
            self.tri(idx[m], first1[m] + k, tris)

    def result(self, enc: Encoded) -> Hits:
        hit = self.slot >= 0
        tri = np.zeros(len(self.t), np.int64)
        tri[hit] = enc.ids[self.slot[hit]]
        self.reads += hit
        t = np.where(hit, self.t, np.inf)
        return Hits(t, self.slot, tri, np.where(hit, self.u, 0.0), np.where(hit, self.v, 0.0),
                    self.reads, self.boxes, self.tests, self.stack)


def trace(enc: Encoded, origins, directions, tmin: float = 0.0, tmax: float = math.inf) -> Hits:
    """Closest hits for a batch of rays; same results and read counts as :func:`trace_one`."""
    B = _Batch(origins, directions, tmin, tmax)
    if enc.layout == "binary":
        _trace_binary(enc, B)
    elif len(enc.nodes):
        _trace_wide(enc, B)
    return B.result(enc)


def _trace_binary(enc: Encoded, B: _Batch) -> None:
    nodes, tris = enc.nodes, enc.tris
    L = len(nodes)
    R = len(B.t)
    p = np.ones(R, np.int64)
    act = np.nonzero(p <= L)[0]
    while len(act):
        pp = p[act] - 1
        planes = nodes[pp[:, None] + np.arange(6)]
        hit, _ = B.slab(act, planes)
        link = nodes[pp + 6]
        B.reads[act] += 7
        lh = hit & (link > 0)
        if lh.any():
            first = np.floor(link[lh] / LEAF_BASE)
            cnt = (link[lh] - first * LEAF_BASE).astype(np.int64)
            B.leaf(act[lh], first.astype(np.int64), cnt, tris)
        nxt = np.where(hit | (link > 0), pp + 1 + BIN_STRIDE, (-link).astype(np.int64))
        p[act] = nxt
        act = act[nxt <= L]


def _trace_wide(enc: Encoded, B: _Batch) -> None:
    nodes, tris = enc.nodes, enc.tris
    quant = enc.layout == "quantised"
    stride = enc.stride
    M = 2 ** enc.bits
    Q = float(M - 2) if M > 2 else 1.0
    R = len(B.t)
    allr = np.arange(R)
    B.reads += 6
    frame = np.repeat(nodes[:6][None, :], R, axis=0)  # (R, 6) current frame
    hit, _ = B.slab(allr, frame)
    # stacks: entries of E numbers: [frame(6)], ptr, tnear
    E = 8 if quant else 2
    cap = 16
    stack = np.zeros((R, cap, E))
    sp = np.zeros(R, np.int64)
    p = np.where(hit, WIDE_HEADER + 1, 0).astype(np.int64)
    cur = np.nonzero(p > 0)[0]
    while len(cur):
        n = len(cur)
        pp = p[cur]
        m = nodes[pp - 1].copy()
        B.reads[cur] += 1
        fr = frame[cur]
        if quant:
            c = (fr[:, 3:] - fr[:, :3]) / Q
        ni = np.zeros(n, np.int64)
        nl = np.zeros(n, np.int64)
        f_t = np.full((n, 4), np.inf)
        f_ok = np.zeros((n, 4), bool)
        f_ptr = np.zeros((n, 4), np.int64)
        f_box = np.zeros((n, 4, 6)) if quant else None
        for j in range(4):
            alive = m > 0
            if not alive.any():
                break
            a = np.nonzero(alive)[0]
            code = m[a] % LEAF_BASE
            m[a] = np.floor(m[a] / LEAF_BASE)
            ra = cur[a]
            if quant:
                w = nodes[pp[a] - 1 + 3 + j].copy()
                B.reads[ra] += 1
                qs = np.empty((len(a), 6))
                for k in range(6):
                    qs[:, k] = w % M
                    w = np.floor(w / M)
                ca = c[a]
                fa = fr[a]
                planes = np.empty((len(a), 6))
                for k in range(3):
                    planes[:, k] = fa[:, k] + qs[:, k] * ca[:, k]
                    planes[:, 3 + k] = fa[:, k] + qs[:, 3 + k] * ca[:, k]
            else:
                base = pp[a] - 1 + 3 + 6 * j
                planes = nodes[base[:, None] + np.arange(6)]
                B.reads[ra] += 6
            hit, tn = B.slab(ra, planes)
            inner = code == LEAF_BASE - 1
            ih = inner & hit
            if ih.any():
                ai = a[ih]
                ptr = nodes[pp[ai] - 1 + 1].astype(np.int64) + ni[ai] * stride
                B.reads[cur[ai]] += 1
                f_t[ai, j] = tn[ih]
                f_ok[ai, j] = True
                f_ptr[ai, j] = ptr
                if quant:
                    f_box[ai, j] = planes[ih]
            ni[a[inner]] += 1
            lh = ~inner & hit
            if lh.any():
                al = a[lh]
                first = nodes[pp[al] - 1 + 2].astype(np.int64) + nl[al]
                B.reads[cur[al]] += 1
                B.leaf(cur[al], first, code[lh].astype(np.int64), tris)
            nl[a[~inner]] += code[~inner].astype(np.int64)
        # push found children far to near (ties: later child deeper), skipping culled ones
        key = np.where(f_ok, f_t, np.inf)
        order = np.argsort(key, axis=1, kind="stable")  # near first
        for jj in range(3, -1, -1):
            col = order[:, jj]
            rr = np.arange(n)
            ok = f_ok[rr, col] & (f_t[rr, col] <= B.t[cur])
            if not ok.any():
                continue
            w = cur[ok]
            if (sp[w] >= cap).any():
                grow = np.zeros((R, cap, E))
                stack = np.concatenate([stack, grow], axis=1)
                cap *= 2
            ent = np.empty((int(ok.sum()), E))
            if quant:
                ent[:, :6] = f_box[rr[ok], col[ok]]
            ent[:, E - 2] = f_ptr[rr[ok], col[ok]]
            ent[:, E - 1] = f_t[rr[ok], col[ok]]
            stack[w, sp[w]] = ent
            sp[w] += 1
            B.stack[w] = np.maximum(B.stack[w], sp[w])
        # pop until an entry survives the tnear cull or the stack is empty
        p[cur] = 0
        pend = cur[sp[cur] > 0]
        while len(pend):
            top = stack[pend, sp[pend] - 1]
            sp[pend] -= 1
            B.reads[pend] += 1
            keep = top[:, E - 1] <= B.t[pend]
            kk = pend[keep]
            if len(kk):
                p[kk] = top[keep, E - 2].astype(np.int64)
                B.reads[kk] += 1
                if quant:
                    frame[kk] = top[keep, :6]
                    B.reads[kk] += 6
            rest = pend[~keep]
            pend = rest[sp[rest] > 0]
        cur = np.nonzero(p > 0)[0]


# =========================================================================== brute force
def brute_force(tri: np.ndarray, origins, directions, tmin: float = 0.0, tmax: float = math.inf,
                chunk: int = 4_000_000) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Every ray against every triangle (T,3,3) with the same Möller-Trumbore arithmetic.
    Returns ``(t, index, u, v)``; among equal ``t`` the lowest index wins; inf / -1 on a miss."""
    o = np.asarray(origins, np.float64).reshape(-1, 3)
    d = np.asarray(directions, np.float64).reshape(-1, 3)
    tri = np.asarray(tri, np.float64).reshape(-1, 3, 3)
    R, T = len(o), len(tri)
    bt = np.full(R, float(tmax))
    bi = np.full(R, -1, np.int64)
    bu = np.zeros(R)
    bv = np.zeros(R)
    if T == 0 or R == 0:
        return np.where(bi >= 0, bt, np.inf), bi, bu, bv
    v0 = tri[:, 0]
    e1 = tri[:, 1] - v0
    e2 = tri[:, 2] - v0
    rc = max(1, min(R, chunk // max(T, 1)))
    tc = T if rc > 1 else max(1, chunk)
    for r0 in range(0, R, rc):
        rs = slice(r0, min(R, r0 + rc))
        oo, dd = o[rs][:, None, :], d[rs][:, None, :]
        for t0 in range(0, T, tc):
            ts = slice(t0, min(T, t0 + tc))
            V0, E1, E2 = v0[ts][None], e1[ts][None], e2[ts][None]
            dx, dy, dz = dd[..., 0], dd[..., 1], dd[..., 2]
            with np.errstate(all="ignore"):
                px = dy * E2[..., 2] - dz * E2[..., 1]
                py = dz * E2[..., 0] - dx * E2[..., 2]
                pz = dx * E2[..., 1] - dy * E2[..., 0]
                det = E1[..., 0] * px + E1[..., 1] * py + E1[..., 2] * pz
                e1e1 = E1[..., 0] * E1[..., 0] + E1[..., 1] * E1[..., 1] + E1[..., 2] * E1[..., 2]
                ok = det * det > PARALLEL * (e1e1 * (px * px + py * py + pz * pz))
                inv = 1 / np.where(ok, det, 1.0)
                sx = oo[..., 0] - V0[..., 0]
                sy = oo[..., 1] - V0[..., 1]
                sz = oo[..., 2] - V0[..., 2]
                u = (sx * px + sy * py + sz * pz) * inv
                ok &= (u >= BARY_LO) & (u <= BARY_HI)
                qx = sy * E1[..., 2] - sz * E1[..., 1]
                qy = sz * E1[..., 0] - sx * E1[..., 2]
                qz = sx * E1[..., 1] - sy * E1[..., 0]
                v = (dx * qx + dy * qy + dz * qz) * inv
                ok &= (v >= BARY_LO) & (u + v <= BARY_HI)
                t = (E2[..., 0] * qx + E2[..., 1] * qy + E2[..., 2] * qz) * inv
            ok &= t > tmin
            t = np.where(ok, t, np.inf)
            j = np.argmin(t, axis=1)
            rr = np.arange(t.shape[0])
            tj = t[rr, j]
            better = tj < bt[rs]
            idx = np.arange(rs.start, rs.stop)[better]
            bt[idx] = tj[better]
            bi[idx] = j[better] + t0
            bu[idx] = u[rr, j][better]
            bv[idx] = v[rr, j][better]
    return np.where(bi >= 0, bt, np.inf), bi, bu, bv
