"""The lighting bake itself: :class:`Baker` evaluates the planned effects at the target points,
subdivides where the light varies, gathers bounces and shades (steps 2-5 of
:mod:`bake.lighting.stage`); :class:`LightingResult` keeps the linear results. Used by the stage
and by the lightmap target (:mod:`bake.lighting.lightmap`), which re-runs it per texel.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np

from ..config import LightingConfig
from ..scene import Scene
from . import color as colmod
from .ao import ambient_occlusion
from .bounce import BounceRays, field_radiance
from .direct import direct_light
from .kernel import Context, EffectStats
from .plan import Plan
from .rays import Tracer
from .sky import sky_light
from .targets import (Points, choose_splits, face_geometry, face_levels, interior_points, reduce_groups,
                      reduce_groups_rms, split, unique_edges, vertex_normals, vertex_points)


@dataclass
class LightingResult:
    """Linear results kept for tests, sweeps and later stages (not exported)."""

    vertex_irradiance: np.ndarray  # (V, 3) linear
    face_irradiance: np.ndarray  # (T, 3) linear
    vertex_evaluated: np.ndarray  # (V,) bool: traced at the vertex (else derived)
    face_sampled: np.ndarray  # (T,) bool: the triangle has interior points (else vertex mean)
    vertex: dict[str, np.ndarray] = field(default_factory=dict)  # component -> (V,) or (V, 3)
    face: dict[str, np.ndarray] = field(default_factory=dict)  # component -> (T,) or (T, 3)
    vertex_se: dict[str, np.ndarray] = field(default_factory=dict)  # component -> (V,)
    face_se: dict[str, np.ndarray] = field(default_factory=dict)  # component -> (T,)
    # (T, 4) the unlit base colour the bake multiplied (shown values, as colmod.triangle_albedo):
    # the lit scene's vertex colours are albedo x light, so a later shading of the same
    # triangles (the lightmap target) must take its albedo from here, not from the lit scene
    albedo: np.ndarray | None = None


COMPONENTS = {"direct": 3, "sky": 3, "ao": 1, "indirect": 3}


class _Store:
    """Per-vertex or per-triangle component values and standard errors."""

    def __init__(self, n: int):
        self.n = n
        self.val = {k: np.zeros((n, c)) for k, c in COMPONENTS.items()}
        self.val["ao"][:] = 1.0
        self.se = {k: np.zeros(n) for k in COMPONENTS}
        self.lo = np.zeros((n, 3))  # min / max of local irradiance over interior points
        self.hi = np.zeros((n, 3))

    def take(self, idx: np.ndarray) -> "_Store":
        s = _Store.__new__(_Store)
        s.n = len(idx)
        s.val = {k: v[idx] for k, v in self.val.items()}
        s.se = {k: v[idx] for k, v in self.se.items()}
        s.lo, s.hi = self.lo[idx], self.hi[idx]
        return s

    def extend(self, n_new: int) -> None:
        for k, c in COMPONENTS.items():
            add = np.ones((n_new, c)) if k == "ao" else np.zeros((n_new, c))
            self.val[k] = np.concatenate([self.val[k], add])
            self.se[k] = np.concatenate([self.se[k], np.zeros(n_new)])
        self.lo = np.concatenate([self.lo, np.zeros((n_new, 3))])
        self.hi = np.concatenate([self.hi, np.zeros((n_new, 3))])
        self.n += n_new


class Baker:
    def __init__(self, scene: Scene, cfg: LightingConfig, plan: Plan, albedo=None):
        self.t_start = time.perf_counter()
        self.cfg = cfg
        self.plan = plan
        self.albedo_fn = albedo
        self.scene = scene
        self.pos = scene.positions
        self.tris = np.asarray(scene.triangles, dtype=np.int64)
        self.tri_material = np.asarray(scene.tri_material, dtype=np.int64)
        self.tri_uvs = scene.tri_uvs
        self.tri_polygon = (np.asarray(scene.tri_polygon, np.int64) if scene.tri_polygon is not None
                            else np.arange(len(self.tris), dtype=np.int64))
        self.vcol = scene.vertex_colors
        self.fn, self.area, self.longest = face_geometry(self.pos, self.tris)
        self.vn = vertex_normals(self.pos, self.tris, self.fn, self.area)
        self.scale = scene.scale()
        self.vertex_mode = cfg.target == "vertex" or cfg.subdivide
        self.V = _Store(len(self.pos))
        self.v_done = np.zeros(len(self.pos), dtype=bool)
        self.F = _Store(len(self.tris))
        self.f_done = np.zeros(len(self.tris), dtype=bool)
        self.f_level = np.zeros(len(self.tris), dtype=np.int64)
        self.stats: dict[str, EffectStats] = {}
        self.reach: dict[int, dict] = {lt.index: {"facing": 0, "lit": 0} for lt in plan.lights}
        self.subdiv = {"rounds": 0, "added": 0, "stopped": ""}
        pos0, tris0 = self.pos, self.tris
        self.ctx = Context(lambda: Tracer(pos0, tris0, threads=cfg.threads, scale=self.scale), cfg.seed,
                           scale=self.scale)

    # ------------------------------------------------------------------ helpers
    def stat(self, name: str) -> EffectStats:
        if name not in self.stats:
            self.stats[name] = EffectStats(name=name, ran=True)
        return self.stats[name]

    def used(self) -> np.ndarray:
        u = np.zeros(len(self.pos), dtype=bool)
        u[self.tris.ravel()] = True
        return u

    def levels(self) -> np.ndarray:
        cell = self.cfg.face_cell * self.scale
        minimum = 1 if self.cfg.target in ("triangle", "lightmap") else 0
        lev = face_levels(self.longest, cell, self.cfg.face_points_max, minimum)
        lev[~(self.area > 0)] = 0  # a degenerate triangle has no inside (and no normal)
        return lev

    def current_scene(self) -> Scene:
        """The scene with the triangles as they are now (split by subdivision). The textures
        stage's per-triangle ``face_albedo`` belongs to the triangles before any split: dropped
        here when they were split (the albedo artefact computes it for the new ones) and put back
        for the new triangles by :meth:`traced`."""
        fa = self.scene.face_albedo
        if fa is not None and len(fa) != len(self.tris):
            fa = None
        return self.scene.replace(positions=self.pos, triangles=self.tris, tri_material=self.tri_material,
                                  tri_uvs=self.tri_uvs, tri_polygon=self.tri_polygon,
                                  vertex_colors=self.vcol, face_colors=None, face_albedo=fa)

    def albedo(self) -> np.ndarray:
        return colmod.triangle_albedo(self.current_scene(), self.albedo_fn)

    # ------------------------------------------------------------------ local effects
    def evaluate(self, pts: Points) -> tuple[dict[str, np.ndarray], dict[str, np.ndarray]]:
        cfg, plan, ctx = self.cfg, self.plan, self.ctx
        P = len(pts)
        val = {k: (np.ones((P, 1)) if k == "ao" else np.zeros((P, c))) for k, c in COMPONENTS.items()}
        se = {k: np.zeros(P) for k in COMPONENTS}
        if P == 0:
            return val, se
        se2 = np.zeros(P)
        for lt in plan.lights:
            st = self.stat(lt.label)
            e, s, info = direct_light(ctx, lt, pts, cfg.shadows.samples, cfg.shadows.enabled, st)
            val["direct"] += e
            se2 += s * s
            self.reach[lt.index]["facing"] += info["facing"]
            self.reach[lt.index]["lit"] += info["lit"]
        se["direct"] = np.sqrt(se2)
        if plan.sky:
            k = cfg.sky.intensity
            e, s = sky_light(ctx, pts, cfg.sky.samples, np.asarray(cfg.sky.color) * k,
                             np.asarray(cfg.sky.horizon) * k, np.asarray(cfg.sky.ground) * k, self.stat("sky"))
            val["sky"], se["sky"] = e, s
        if plan.ao:
            a, s = ambient_occlusion(ctx, pts, cfg.ao.samples, cfg.ao.distance * self.scale,
                                     cfg.ao.strength, self.stat("ao"))
            val["ao"], se["ao"] = a[:, None], s
        return val, se

    def local_irradiance(self, val: dict[str, np.ndarray]) -> np.ndarray:
        return val["direct"] + val["sky"] + val["ao"] * self.plan.ambient[None, :]

    def evaluate_round(self) -> None:
        vidx = np.flatnonzero(self.used() & ~self.v_done) if self.vertex_mode else np.zeros(0, np.int64)
        lev = self.levels()
        self.f_level = lev
        tidx = np.flatnonzero((lev > 0) & ~self.f_done)
        pv = vertex_points(self.pos, self.vn, vidx)
        pi, groups = interior_points(self.pos, self.tris, self.fn, tidx, lev[tidx])
        val, se = self.evaluate(Points.concat([pv, pi]))
        nv = len(vidx)
        for k in COMPONENTS:
            self.V.val[k][vidx] = val[k][:nv]
            self.V.se[k][vidx] = se[k][:nv]
            if len(pi):
                m, _ = reduce_groups(val[k][nv:], groups, len(self.tris))
                self.F.val[k][tidx] = m[tidx]
                self.F.se[k][tidx] = reduce_groups_rms(se[k][nv:], groups, len(self.tris))[tidx]
        if len(pi):
            e = self.local_irradiance({k: v[nv:] for k, v in val.items()})
            o = 0
            for t, m in groups:  # per distinct level
                n = len(t) * m * m
                blk = e[o:o + n].reshape(len(t), m * m, 3)
                self.F.lo[t] = blk.min(axis=1)
                self.F.hi[t] = blk.max(axis=1)
                o += n
        self.v_done[vidx] = True
        self.f_done[tidx] = True

    # ------------------------------------------------------------------ subdivision
    def variation(self, albedo_lin: np.ndarray) -> np.ndarray:
        """Largest shown-colour difference across each triangle (vertices and interior points)."""
        cfg = self.cfg
        ev = self.local_irradiance(self.V.val)
        samples = [ev[self.tris[:, k]] for k in range(3)]
        samples += [np.where(self.f_done[:, None], self.F.lo, samples[0]),
                    np.where(self.f_done[:, None], self.F.hi, samples[0])]
        cols = [colmod.shade(albedo_lin, e, cfg.exposure, cfg.tonemap, cfg.color_space) for e in samples]
        stack = np.stack(cols)  # (5, T, 3)
        return (stack.max(axis=0) - stack.min(axis=0)).max(axis=1)

    def subdivide_round(self) -> bool:
        cfg = self.cfg
        T = len(self.tris)
        budget = cfg.max_triangles - T
        if budget <= 0:
            self.subdiv["stopped"] = f"triangle budget reached ({T} >= lighting.max_triangles = {cfg.max_triangles})"
            return False
        alb_lin = colmod.decode(self.albedo()[:, :3], cfg.color_space)
        var = self.variation(alb_lin)
        cand = np.flatnonzero((var > cfg.subdivide_threshold) &
                              (self.longest > cfg.subdivide_min_edge * self.scale))
        if len(cand) == 0:
            self.subdiv["stopped"] = "no triangle varies more than lighting.subdivide_threshold"
            return False
        pri = var[cand] * self.area[cand]
        cand = cand[np.lexsort((cand, -pri))]
        edges, edge_id = unique_edges(self.tris)
        marked = choose_splits(edge_id, len(edges), cand, budget)
        if not marked.any():
            self.subdiv["stopped"] = "the next split would exceed lighting.max_triangles"
            return False
        sp = split(self.pos, self.tris, marked, edges, edge_id, self.tri_uvs, self.vcol)
        n_new = len(sp.new_vertices)
        # vertex state: new midpoints, normals interpolated from the edge ends
        nv = self.vn[sp.edge_ends[:, 0]] + self.vn[sp.edge_ends[:, 1]]
        ln = np.linalg.norm(nv, axis=1)
        fallback = self.vn[sp.edge_ends[:, 0]]
        nv = np.where(ln[:, None] > 1e-12, nv / np.maximum(ln, 1e-300)[:, None], fallback)
        self.vn = np.concatenate([self.vn, nv])
        self.v_done = np.concatenate([self.v_done, np.zeros(n_new, dtype=bool)])
        self.V.extend(n_new)
        # triangle state
        par = sp.parent
        self.F = self.F.take(par)
        self.f_done = self.f_done[par] & ~sp.split
        self.tri_material = self.tri_material[par]
        self.tri_polygon = np.where(sp.split, -1, self.tri_polygon[par])
        self.pos, self.tris, self.tri_uvs, self.vcol = sp.positions, sp.triangles, sp.tri_uvs, sp.vertex_colors
        self.fn, self.area, self.longest = face_geometry(self.pos, self.tris)
        self.subdiv["rounds"] += 1
        self.subdiv["added"] += len(self.tris) - T
        return True

    # ------------------------------------------------------------------ bounces
    def bounce(self) -> None:
        cfg = self.cfg
        st = self.stat("bounces")
        if self.subdiv["added"]:  # hits must name the triangles of the subdivided mesh
            t = time.perf_counter()
            self.ctx.tracer = Tracer(self.pos, self.tris, threads=cfg.threads, scale=self.scale)
            self.ctx.build_seconds += time.perf_counter() - t
        alb_lin = colmod.decode(self.albedo()[:, :3], cfg.color_space)
        if not np.any(alb_lin > 0):
            st.ran = False
            st.reason = "every albedo is black: nothing bounces"
            return
        vidx = np.flatnonzero(self.v_done) if self.vertex_mode else np.zeros(0, np.int64)
        tidx = np.flatnonzero(self.f_done)
        pv = vertex_points(self.pos, self.vn, vidx)
        pi, groups = interior_points(self.pos, self.tris, self.fn, tidx, self.f_level[tidx])
        pts = Points.concat([pv, pi])
        rays = BounceRays(self.ctx, pts, cfg.bounces.samples, st)
        st.samples = rays.N
        ev_loc = self.local_irradiance(self.V.val)
        ef_loc = self.face_local()
        nv = len(vidx)
        ind_v = np.zeros_like(ev_loc)
        ind_f = np.zeros_like(ef_loc)
        se_v = np.zeros(len(ev_loc))
        se_f = np.zeros(len(ef_loc))
        for _ in range(self.plan.bounces):  # iterations of the gather, not rays
            vfield = (ev_loc + ind_v) if self.vertex_mode else None
            rad = field_radiance(self.tris, alb_lin, vfield, ef_loc + ind_f)
            g, s = rays.gather(rad)
            ind_v = np.zeros_like(ev_loc)
            ind_v[vidx] = g[:nv]
            se_v = np.zeros(len(ev_loc))
            se_v[vidx] = s[:nv]
            ind_f, se_f = self.faces_from(ind_v, se_v)
            if len(pi):
                m, _ = reduce_groups(g[nv:], groups, len(self.tris))
                ind_f[tidx] = m[tidx]
                se_f[tidx] = reduce_groups_rms(s[nv:], groups, len(self.tris))[tidx]
        self.V.val["indirect"], self.V.se["indirect"] = ind_v, se_v
        self.F.val["indirect"], self.F.se["indirect"] = ind_f, se_f
        st.add_error(se_v[vidx])
        st.add_error(se_f[tidx])
        st.extra["count"] = int(self.plan.bounces)
        st.extra["cached_hits"] = bool(rays.cached)

    # ------------------------------------------------------------------ outputs
    def faces_from(self, vals: np.ndarray, se: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Per-triangle mean of vertex values (for triangles without interior points)."""
        t = self.tris
        v = (vals[t[:, 0]] + vals[t[:, 1]] + vals[t[:, 2]]) / 3.0
        s = np.sqrt(se[t[:, 0]] ** 2 + se[t[:, 1]] ** 2 + se[t[:, 2]] ** 2) / 3.0
        return v, s

    def face_local(self) -> np.ndarray:
        ef = self.local_irradiance(self.F.val)
        if self.vertex_mode:
            ev = self.local_irradiance(self.V.val)
            fv, _ = self.faces_from(ev, np.zeros(len(ev)))
            ef = np.where(self.f_done[:, None], ef, fv)
        return ef

    def finish_components(self) -> None:
        """Fill face components of triangles without interior points from their vertices."""
        if not self.vertex_mode:
            return
        ran = {"direct": bool(self.plan.lights), "sky": self.plan.sky, "ao": self.plan.ao}
        for k in COMPONENTS:
            if not ran.get(k, False):
                continue
            v = self.V.val[k]
            fv, fs = self.faces_from(v, self.V.se[k])
            self.F.val[k] = np.where(self.f_done[:, None], self.F.val[k], fv)
            self.F.se[k] = np.where(self.f_done, self.F.se[k], fs)

    def vertex_from_faces(self, face_vals: np.ndarray) -> np.ndarray:
        return _vertex_from_faces(self.tris, self.area, len(self.pos), face_vals)

    def run(self) -> Scene:
        self.trace()
        return coloured(self.traced(), self.cfg)

    def trace(self) -> None:
        """Everything that traces rays: the rounds (and subdivision), the components, the bounces,
        and the irradiance per triangle (``self.ef``) and per vertex (``self.ev``)."""
        cfg = self.cfg
        levels = cfg.subdivide_levels if cfg.subdivide else 0
        rnd = 0
        while True:
            self.evaluate_round()
            if rnd >= levels or not self.subdivide_round():
                break
            rnd += 1
        if cfg.subdivide and not self.subdiv["stopped"]:
            self.subdiv["stopped"] = f"lighting.subdivide_levels = {cfg.subdivide_levels} rounds done"
        self.finish_components()
        if self.plan.bounces:
            self.bounce()
        self.ef = self.local_irradiance(self.F.val) + self.F.val["indirect"]
        if self.vertex_mode:
            self.ev = self.local_irradiance(self.V.val) + self.V.val["indirect"]
        else:
            self.ev = self.vertex_from_faces(self.ef)

    def traced(self) -> dict:
        """What :func:`coloured` turns into colours (after :meth:`trace`): none of it depends on
        ``lighting.exposure`` or ``lighting.tonemap`` unless subdivision (which compares shown
        colours) ran."""
        alb = self.albedo()
        res = LightingResult(
            vertex_irradiance=self.ev, face_irradiance=self.ef, vertex_evaluated=self.v_done.copy(),
            face_sampled=self.f_done.copy(),
            vertex={k: (v[:, 0] if v.shape[1] == 1 else v) for k, v in self.V.val.items()},
            face={k: (v[:, 0] if v.shape[1] == 1 else v) for k, v in self.F.val.items()},
            vertex_se=dict(self.V.se), face_se=dict(self.F.se), albedo=alb.copy())
        scene = self.current_scene()
        if self.scene.face_albedo is not None and scene.face_albedo is None:  # (split triangles: theirs)
            scene = scene.replace(face_albedo=alb.copy())
        return {"scene": scene, "ef": self.ef, "ev": self.ev, "albedo": alb, "used": self.used(),
                "area": self.area, "tris": self.tris, "n_vertices": len(self.pos), "result": res}


def coloured(traced: dict, cfg: LightingConfig) -> Scene:
    """The lit scene from :meth:`Baker.traced`: albedo x irradiance x exposure, tone map, encode,
    per triangle and per vertex (area-weighted albedo of the triangles around it)."""
    ef, ev, alb, used = traced["ef"], traced["ev"], traced["albedo"], traced["used"]
    alb_lin = colmod.decode(alb[:, :3], cfg.color_space)
    face_rgb = colmod.shade(alb_lin, ef, cfg.exposure, cfg.tonemap, cfg.color_space)
    face_colors = np.concatenate([face_rgb, alb[:, 3:4]], axis=1)
    v_alb = _vertex_from_faces(traced["tris"], traced["area"], traced["n_vertices"],
                               np.concatenate([alb_lin, alb[:, 3:4]], axis=1))
    if cfg.vertex_output == "light":
        v_alb[:, :3] = 1.0
    vert_rgb = colmod.shade(v_alb[:, :3], ev, cfg.exposure, cfg.tonemap, cfg.color_space)
    v_alpha = np.where(used, v_alb[:, 3], 1.0)
    vertex_colors = np.concatenate([vert_rgb, v_alpha[:, None]], axis=1)
    vertex_colors = np.clip(np.nan_to_num(vertex_colors, nan=0.0), 0.0, 1.0)
    face_colors = np.clip(np.nan_to_num(face_colors, nan=0.0), 0.0, 1.0)
    out = traced["scene"].replace(vertex_colors=vertex_colors, face_colors=face_colors)
    return out.with_artefacts(lighting=traced["result"])


def _vertex_from_faces(tris: np.ndarray, area: np.ndarray, V: int, face_vals: np.ndarray) -> np.ndarray:
    """Per-vertex area-weighted mean of per-triangle values."""
    w = np.repeat(area, 3)
    flat = tris.ravel()
    tot = np.bincount(flat, weights=w, minlength=V)
    out = np.zeros((V, face_vals.shape[1]))
    for c in range(face_vals.shape[1]):  # channels
        out[:, c] = np.bincount(flat, weights=w * np.repeat(face_vals[:, c], 3), minlength=V)
    return np.divide(out, tot[:, None], out=np.zeros_like(out), where=tot[:, None] > 0)
