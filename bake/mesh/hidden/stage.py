"""The hidden-geometry stage (``[mesh.hidden]``, off by default): keep the triangles an eye in the
view region can see, drop the rest (docs/hidden.md).

0. With ``trim`` (``trim.py``): triangles that pass through each other are cut along each other's
   planes where they cross first, and the steps below decide piece by piece; a source that loses
   no piece is written whole, one that does keeps its pieces or the outline of them, or is written
   whole when those take more than ``trim_most`` triangles.
1. Eyes (``regions.py``): ``eyes`` seeded, stratified eyes on the outside sphere and in each box;
   the given points and the reader's camera as they are.
2. Decide (``visibility.py``): from every eye, ``samples`` rays at stratified points of every
   triangle that could face it, all eyes in one batch through Embree; a triangle a ray draws
   before it stops is seen (an eye at a point or the camera: ``eyes`` x ``samples`` rays per
   triangle, the same budget). Then ``refine_rounds`` rounds aim ``refine`` x ``eyes`` new eyes (on
   the sphere, in the boxes; ``refine`` x more rays from a point or the camera) at the
   unseen triangles that share a corner with one seen so far (the edges of what shows, where a
   triangle partly seen, such as one crossing another surface, sits). Each round first aims eyes
   near the *witnesses* of those seen neighbours (the eye of the first ray that drew each): what
   shows through a gap between parts shows only to a narrow cone of eyes, and a neighbour seen
   through the gap names one. After the ``refine_rounds``, rounds of witness eyes alone go on
   (at most ``DIRECTED_ROUNDS``) while they find new triangles, following a surface down a gap.
3. Lit bakes (``keep_casters``): the hidden triangles that a kept triangle's light rays (towards
   each light, and over the hemisphere with AO, sky or bounces) hit first are kept too: they cast
   the shadows and bounce the light the kept ones show.
4. Drop the rest (their polygons and the vertices nothing uses any more).
5. The proof: ``holdout_eyes`` eyes from another seed stream, a cube map of pixels around each,
   traced through the full mesh: the pixels showing a dropped triangle are wrong pixels.

Decisions (each tested in tests/mesh/test_hidden.py): a single-sided triangle is drawn and hides
what is behind it only from its front (``back_faces = "culled"``, as the reader draws it), a
two-sided one from both sides; a see-through triangle (material, face or vertex alpha below 1, or
a texture with transparent texels) is kept when seen but hides nothing.
"""

from __future__ import annotations

import io
import time
from dataclasses import dataclass
from typing import Any

import numpy as np

from ...config import HiddenConfig, LightingConfig
from ...errors import ConfigError
from ...geometry import tangent_frames
from ...record import ReportSection, StageRecord
from ...scene import Material, Scene
from ...scratch.numbers import position_decimals
from ..clean import unique_rows
from . import proof as proof_mod
from . import regions as regions_mod
from . import trim as trim_mod
from .visibility import Visibility


@dataclass(frozen=True)
class TreeProof:
    """The BSP tree the bake builds, for the proof's splits with and without the removal: the BSP
    stage's entry ("module:function"), its section and the written grid's digits."""

    entry: str
    bsp: Any
    decimals: int | None


@dataclass(frozen=True)
class HiddenJob:
    """The stage's section: ``[mesh.hidden]`` and, for a lit bake whose casters are kept, ``[lighting]``."""

    hidden: HiddenConfig
    lighting: LightingConfig | None = None
    tree: TreeProof | None = None  # the registry wires it in when bsp.enabled and bsp_proof


def job(cfg, tree: TreeProof | None = None) -> HiddenJob:
    h = cfg.mesh.hidden
    return HiddenJob(hidden=h, lighting=cfg.lighting if (cfg.lighting.enabled and h.keep_casters) else None,
                     tree=tree)


# ---------------------------------------------------------------------------- materials
def _texture_has_alpha(m: Material) -> bool:
    if m.texture is None and m.texture_data is None:
        return False
    try:
        from PIL import Image

        with Image.open(io.BytesIO(m.texture_data) if m.texture_data is not None else m.texture) as im:
            if "transparency" in im.info:
                return True
            if im.mode not in ("RGBA", "LA", "PA", "RGBa", "La"):
                return False
            return bool(np.asarray(im.getchannel("A")).min() < 255)
    except Exception:  # an unreadable texture: the textures stage says so; here it hides nothing
        return True


def see_through(scene: Scene) -> tuple[np.ndarray, list[str]]:
    """(T,) bool: triangles that may let what is behind them show, and the materials why."""
    T = scene.n_triangles
    mats = scene.materials
    mat_clear = np.array([m.color[3] < 1.0 or _texture_has_alpha(m) for m in mats], bool)
    out = mat_clear[np.clip(scene.tri_material, 0, len(mats) - 1)]
    if scene.face_colors is not None:
        out = out | (scene.face_colors[:, 3] < 1.0)
    if scene.vertex_colors is not None:
        out = out | (scene.vertex_colors[scene.triangles, 3].min(axis=1) < 1.0)
    names = [m.name for m, c in zip(mats, mat_clear) if c]
    return out if len(out) == T else np.zeros(T, bool), names


def two_sided(scene: Scene, mode: str) -> np.ndarray:
    if mode == "drawn":
        return np.ones(scene.n_triangles, bool)
    ds = np.array([m.double_sided for m in scene.materials], bool)
    return ds[np.clip(scene.tri_material, 0, len(ds) - 1)]


# ---------------------------------------------------------------------------- the scene
def corner_ids(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """(T, 3) corners numbered by position (vertices at one place are one corner: faces written
    with vertices of their own still touch)."""
    return unique_rows(positions)[1][triangles]


def neighbours(corners: np.ndarray, of: np.ndarray) -> np.ndarray:
    """(T,) bool: triangles that share a corner (by :func:`corner_ids`) with one of the mask ``of``."""
    V = int(corners.max()) + 1 if len(corners) else 0
    touched = np.zeros(V, bool)
    touched[corners[of].ravel()] = True
    return touched[corners].any(axis=1)


def keep_triangles(scene: Scene, keep: np.ndarray) -> Scene:
    """The scene with only the triangles ``keep``; a polygon that lost some keeps the rest as
    triangles (``tri_polygon = -1``), one that lost all is dropped; unused vertices go."""
    keep = np.asarray(keep, bool)
    tp = scene.tri_polygon
    poly_sizes, poly_indices, poly_material, poly_uvs = (scene.poly_sizes, scene.poly_indices,
                                                         scene.poly_material, scene.poly_uvs)
    if tp is not None and poly_sizes is not None:
        P = len(poly_sizes)
        has = np.zeros(P, np.int64)
        lost = np.zeros(P, np.int64)
        ok = tp >= 0
        np.add.at(has, tp[ok & keep], 1)
        np.add.at(lost, tp[ok & ~keep], 1)
        split = (has > 0) & (lost > 0)
        tp = np.where(ok & split[np.clip(tp, 0, max(P - 1, 0))], -1, tp)
        # polygons with no triangle left go (those whose triangles were never listed stay)
        gone = (has == 0) & (lost > 0)
        if gone.any():
            live = ~gone
            corner_live = np.repeat(live, poly_sizes)
            renum = np.cumsum(live) - 1
            tp = np.where(tp >= 0, renum[np.clip(tp, 0, P - 1)], -1)
            poly_sizes, poly_indices = poly_sizes[live], poly_indices[corner_live]
            poly_material = poly_material[live]
            poly_uvs = None if poly_uvs is None else poly_uvs[corner_live]
    sel = (lambda a: None if a is None else a[keep])
    tris = scene.triangles[keep]
    used = np.zeros(scene.n_vertices, bool)
    used[tris.ravel()] = True
    if poly_indices is not None and len(poly_indices):
        used[poly_indices] = True
    remap = np.cumsum(used) - 1
    return scene.replace(
        positions=np.ascontiguousarray(scene.positions[used]),
        vertex_colors=None if scene.vertex_colors is None else scene.vertex_colors[used],
        triangles=remap[tris], tri_material=sel(scene.tri_material), tri_uvs=sel(scene.tri_uvs),
        tri_polygon=None if tp is None else tp[keep], face_colors=sel(scene.face_colors),
        face_albedo=sel(scene.face_albedo), tri_lightmap_uvs=sel(scene.tri_lightmap_uvs),
        poly_sizes=poly_sizes, poly_indices=None if poly_indices is None else remap[poly_indices],
        poly_material=poly_material, poly_uvs=poly_uvs)


def _camera_eye(positions: np.ndarray, triangles: np.ndarray) -> np.ndarray:
    """Where the reader sprite's green flag puts its camera for these triangles (it frames the
    vertices the lists hold: ``bake.scratch.project.auto_camera``)."""
    from ...scratch.project import auto_camera

    cam = auto_camera(positions[np.unique(triangles)])
    return np.array([cam.x, cam.y, cam.z], np.float64)


def _lights(scene: Scene, lighting: LightingConfig, rng: np.random.Generator
            ) -> tuple[list[np.ndarray], list[np.ndarray], bool]:
    """Directions towards the suns (the centre and CONE_RAYS more across a soft sun's disc),
    light positions (a point's or spot's centre and CONE_RAYS points of its sphere), and whether
    light comes over the whole hemisphere (AO, sky, bounces)."""
    from ...lighting.plan import make_plan

    plan = make_plan(scene, lighting)
    dirs, pts = [], []
    for lt in plan.lights:
        if lt.kind == "sun":
            w = -np.asarray(lt.direction, np.float64)
            dirs.append(w)
            if lt.half_angle > 0:
                for _ in range(CONE_RAYS):
                    j = w + np.tan(lt.half_angle) * np.sqrt(rng.random()) * _unit_perp(w, rng.random())
                    dirs.append(j / np.linalg.norm(j))
        else:
            p = np.asarray(lt.position, np.float64)
            pts.append(p)
            if lt.radius > 0:
                for _ in range(CONE_RAYS):
                    v = rng.normal(size=3)
                    pts.append(p + lt.radius * v / max(np.linalg.norm(v), 1e-300))
    return dirs, pts, bool(plan.ao or plan.sky or plan.bounces)


TRIM_EPS = 1e-6  # trimming: a corner this close to a cutting plane (x the diagonal) is on it
TRIM_MIN_AREA = 1e-12  # pieces smaller than this x the diagonal squared are left out
FIXED = ("point", "camera")  # regions of one eye
CAMERA_ROUNDS = 8  # at most this many moves of the reader's camera as what is kept changes
CONE_RAYS = 8  # more rays across a soft sun's disc or a light's sphere
MAX_LEVEL = 8  # a kept triangle's points for the casters: at most an 8 x 8 cut (64 centroids)


def _unit_perp(w: np.ndarray, turn: float) -> np.ndarray:
    t, b = tangent_frames(w[None, :])
    return np.cos(2 * np.pi * turn) * t[0] + np.sin(2 * np.pi * turn) * b[0]


# rounds at the edges of what shows: eyes near the witnesses of the seen neighbours (docs/hidden.md)
DIRECTED_ROUNDS = 256  # at most this many rounds of witness eyes alone, after the refine_rounds
DIRECTED_EYES = 8  # eyes per witness a candidate gets: the witness itself and 7 around it
DIRECTED_TURN = 0.05  # radians: how far around an outside witness (a box: this x the box's diagonal)
GOLDEN_TURN = (np.sqrt(5.0) - 1.0) / 2.0


def directed_eyes(regs, witness: np.ndarray, corners: np.ndarray, seen: np.ndarray, fresh: np.ndarray,
                  cand: np.ndarray, centre: np.ndarray, rng: np.random.Generator
                  ) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """``(eyes, region of each, the candidate each aims at)``: for every candidate and each of its
    corners, the witnesses of the lowest- and the highest-numbered triangle seen in the last round
    at that corner (of those seen before when none was), each the witness eye itself and
    ``DIRECTED_EYES - 1`` eyes around it in its region (turned on the outside sphere by up to
    ``DIRECTED_TURN``, moved in a box by up to that times its diagonal; a point stays)."""
    V = int(corners.max()) + 1
    big = np.iinfo(np.int64).max
    at_cand = np.zeros(V, bool)
    at_cand[corners[cand].ravel()] = True
    near = np.flatnonzero(seen & ~np.isnan(witness[:, 0]) & at_cand[corners].any(axis=1))
    picks = []
    for ids in (near[fresh[near]], near):
        lo = np.full(V, big, np.int64)
        hi = np.full(V, -1, np.int64)
        np.minimum.at(lo, corners[ids].ravel(), np.repeat(ids, 3))
        np.maximum.at(hi, corners[ids].ravel(), np.repeat(ids, 3))
        picks.append((lo, hi))
    (flo, fhi), (slo, shi) = picks
    lo = np.where(flo < big, flo, slo)
    hi = np.where(fhi >= 0, fhi, shi)
    cc = corners[cand]
    w = np.concatenate([lo[cc], np.where(hi[cc] != lo[cc], hi[cc], big)], axis=1)  # (C, 6)
    ok = (w < big) & (w >= 0)
    ci, _ = np.nonzero(ok)
    wt = w[ok]
    m = len(wt)
    J = DIRECTED_EYES
    aim = np.repeat(cand[ci], J)
    W = np.repeat(witness[wt, :3], J, axis=0)
    own = np.repeat(witness[wt, 3].astype(np.int64), J)
    j = np.tile(np.arange(J), m)
    r1, r2, r3, r4 = (rng.random(m * J) for _ in range(4))
    rad = np.sqrt((np.maximum(j - 1, 0) + r1) / max(J - 1, 1)) * (j > 0)  # stratified over a disc; 0: the witness
    out = W.copy()
    o = np.array([g.kind == "outside" for g in regs] + [False])[own] & (j > 0)
    if o.any():
        u = W[o] - centre
        dist = np.linalg.norm(u, axis=1, keepdims=True)
        u = u / dist
        t, bb = tangent_frames(u)
        phi = 2 * np.pi * (j[o] * GOLDEN_TURN + r2[o])
        v = u + np.tan(DIRECTED_TURN * rad[o])[:, None] * (np.cos(phi)[:, None] * t + np.sin(phi)[:, None] * bb)
        out[o] = centre + dist * v / np.linalg.norm(v, axis=1, keepdims=True)
    for k, g in enumerate(regs):
        bx = (own == k) & (j > 0)
        if g.kind == "box" and bx.any():
            step = DIRECTED_TURN * float(np.linalg.norm(g.hi - g.lo)) * rad[bx]
            phi = 2 * np.pi * r3[bx]
            z = 2 * r4[bx] - 1
            s_ = np.sqrt(1 - z * z)
            dirn = np.stack([s_ * np.cos(phi), s_ * np.sin(phi), z], axis=1)
            out[bx] = np.clip(W[bx] + step[:, None] * dirn, g.lo, g.hi)
    return out, own, aim


# ---------------------------------------------------------------------------- the stage
def _tree_proof(before: Scene, after: Scene, tree: TreeProof) -> dict[str, Any]:
    """The bake's BSP tree built on the stage's input and on its output (the BSP stage itself, on
    the written grid): triangles in, after the splits, and the inflation, with and without the
    removal."""
    import importlib

    mod, fn = tree.entry.split(":")
    build = getattr(importlib.import_module(mod), fn)
    t = time.perf_counter()
    out: dict[str, Any] = {}
    for name, s in (("without_removal", before), ("with_removal", after)):
        if tree.decimals is not None:
            s = s.replace(position_decimals=position_decimals(before.scale(), tree.decimals))
        _, r = build(s, tree.bsp)
        t_in, t_out = r.counts_in["triangles"], r.counts_out["triangles"]
        out[name] = {"triangles_in": t_in, "triangles_out": t_out, "inflation": t_out / max(t_in, 1) - 1.0}
    out["seconds"] = round(time.perf_counter() - t, 6)
    return out


def stage(scene: Scene, section: HiddenJob) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    cfg = section.hidden
    rec = StageRecord(name="hidden")
    T = scene.n_triangles
    if T == 0:
        rec.idle = "no triangles"
        return scene, rec
    original = scene
    camera = _camera_eye(scene.positions, scene.triangles) if cfg.camera else None
    # ---- trimming: crossing triangles cut along each other's planes, decided piece by piece
    trimmed = None
    if cfg.trim:
        tol = TRIM_EPS * scene.scale()
        pairs = trim_mod.crossing(scene, tol)
        if len(pairs):
            pieces = trim_mod.cut(scene, pairs, tol)
            scene, src, n_uncut = trim_mod.cut_scene(scene, pieces, TRIM_MIN_AREA * scene.scale() ** 2)
            trimmed = (src, n_uncut, int(len(pairs)))
        T = scene.n_triangles
    pos = scene.positions
    used = scene.used_vertex_mask()
    regs = regions_mod.regions_of(cfg, pos[used], camera)
    clear, clear_names = see_through(scene)
    sided = two_sided(scene, cfg.back_faces)
    vis = Visibility(pos, scene.triangles, two_sided=sided, see_through=clear, threads=cfg.threads)
    rng = np.random.default_rng([cfg.seed, 1])
    eyes, owner = regions_mod.eyes(regs, pos[used], cfg.eyes, rng)

    # ---- decide: every triangle from every eye, then rounds at the edges of what shows
    # a sampled region (outside, a box) has `eyes` eyes with `samples` rays each per triangle; a
    # fixed eye (a point, the camera) has eyes x samples rays per triangle: the same budget
    fixed = np.array([regs[k].kind in FIXED for k in owner], bool)
    # per seen triangle its witness: the eye of the first ray that drew it, its region, where it aimed
    witness = np.full((T, 7), np.nan)
    seen, short = vis.targeted(eyes[~fixed], np.arange(T), cfg.samples, cfg.seed, 0, witness=witness,
                               owner=owner[~fixed])
    got, cut = vis.targeted(eyes[fixed], np.arange(T), cfg.samples * cfg.eyes, cfg.seed, 1, witness=witness,
                            owner=owner[fixed])
    seen |= got
    short += cut
    rounds = [{"eyes": int(len(eyes)), "candidates": T, "seen": int(seen.sum())}]
    fresh = seen.copy()
    corners = corner_ids(pos, scene.triangles)
    c_sph, _ = regions_mod.bounding_sphere(pos[used])
    n_rounds = cfg.refine_rounds if cfg.refine > 0 else 0
    for r in range(n_rounds + (DIRECTED_ROUNDS if n_rounds else 0)):
        cand = np.flatnonzero(neighbours(corners, fresh) & ~seen)
        if len(cand) == 0:
            break
        # eyes near those that saw a neighbour (witnesses): what shows through a gap shows to a
        # narrow cone of eyes, and a neighbour seen through the same gap names one of them
        w_eyes, w_owner, w_aim = directed_eyes(regs, witness, corners, seen, fresh, cand, c_sph,
                                              np.random.default_rng([cfg.seed, 5, r]))
        got, cut = vis.directed(w_eyes, w_aim, cfg.samples, cfg.seed, 1_000_003 + r, witness=witness,
                                owner=w_owner)
        short += cut
        n_dir = int((got & ~seen).sum())
        seen_before = seen.copy()
        seen |= got
        entry = {"candidates": int(len(cand)), "eyes": 0, "directed_eyes": int(len(w_eyes)), "directed_seen": n_dir}
        left = cand[~seen[cand]]
        if r < n_rounds and len(left):
            # sampled regions (outside, boxes) get refine x more eyes; an eye at a point refine x more rays
            more, more_owner = regions_mod.eyes(regs, pos[used], cfg.eyes * cfg.refine,
                                                np.random.default_rng([cfg.seed, 2, r]))
            fixed = np.array([regs[k].kind in FIXED for k in more_owner], bool)
            got, cut = vis.targeted(more[~fixed], left, cfg.samples, cfg.seed, 2 * r + 2, corners=True,
                                    witness=witness, owner=more_owner[~fixed])
            got2, cut2 = vis.targeted(more[fixed], left, cfg.samples * cfg.eyes * cfg.refine, cfg.seed, 2 * r + 3,
                                      corners=True, witness=witness, owner=more_owner[fixed])
            got |= got2
            short += cut + cut2
            seen |= got
            entry["eyes"] = int(len(more))
        fresh = seen & ~seen_before
        entry["seen"] = int(fresh.sum())
        rounds.append(entry)
        if not fresh.any():
            break
    if not seen.any():
        raise ConfigError("no triangle is seen from the view region (every eye is inside a closed surface, "
                          "or sees only backs of single-sided triangles): move the points or boxes, or set "
                          "back_faces = \"drawn\"", key="mesh.hidden.outside")
    keep = seen.copy()

    # ---- lit bakes: the casters of the shadows and bounces the kept triangles show
    casters = 0
    if section.lighting is not None:
        lit = section.lighting
        dirs, pts, hemi = _lights(scene, lit, np.random.default_rng([cfg.seed, 4]))
        where, owner_tri = vis.surface_points(np.flatnonzero(seen), lit.face_cell * scene.scale(),
                                              MAX_LEVEL, cfg.samples, cfg.seed)
        hit = vis.casters(where, owner_tri, dirs, pts, cfg.caster_samples if hemi else 0, cfg.seed)
        casters = int((hit & ~keep).sum())
        keep |= hit

    # ---- the camera region: the reader frames what is written (auto_camera of the kept vertices),
    # so the camera moves as triangles drop: decide again from where it moves to, until it stays
    camera_moves = 0
    if camera is not None:
        k_cam = next(i for i, g in enumerate(regs) if g.kind == "camera")
        for _ in range(CAMERA_ROUNDS):
            eye = _camera_eye(scene.positions, scene.triangles[keep])
            if np.array_equal(eye, regs[k_cam].lo):
                break
            regs[k_cam] = regions_mod.Region("camera", regs[k_cam].label, lo=eye)
            camera_moves += 1
            got, cut = vis.targeted(eye[None, :], np.flatnonzero(~keep), cfg.samples * cfg.eyes * (1 + cfg.refine),
                                    cfg.seed, 9000 + camera_moves, witness=witness, owner=np.array([k_cam]))
            short += cut
            seen |= got
            keep |= got
        else:
            rec.warn(f"mesh.hidden.camera: the reader's camera still moved after {CAMERA_ROUNDS} rounds of deciding "
                     "from where it moves to: what the last move shows may be dropped (use a box around it)")
        camera = regs[k_cam].lo

    dropped = ~keep
    trim_info: dict[str, Any] | None = None
    if trimmed is not None:
        union, keep_union, source, trim_info = trim_mod.merge_back(original, scene, trimmed[0], trimmed[1], keep)
        trim_info["crossing_pairs"] = trimmed[2]
        source = np.concatenate([source, np.full(union.n_triangles - len(source), -1, np.int64)])
        union, keep_union, trim_info["outlines_redrawn"], source = trim_mod.outline(
            union, keep_union, original.n_triangles, source, original.scale())
        if cfg.trim_most > 0:
            keep_union, trim_info["written_whole"] = trim_mod.whole_again(
                keep_union, original.n_triangles, source, cfg.trim_most)
        out = keep_triangles(union, keep_union)
        # both sides of these show (a redrawn outline or a source kept whole passes through a kept
        # triangle): the BSP cuts them, which costs it fewer triangles than keeping the pieces
        trim_info["crossings_left"] = int(len(trim_mod.crossing(out, TRIM_EPS * original.scale())))
    else:
        out = keep_triangles(scene, keep) if dropped.any() else scene
    out.validate()
    decide_seconds = time.perf_counter() - t0
    decide_rays = vis.rays

    # ---- the proof: held-out eyes, a cube map of pixels each, through the full mesh
    proof: dict[str, Any] = {"eyes": 0}
    if cfg.holdout_eyes > 0:
        t1 = time.perf_counter()
        held, held_owner = regions_mod.eyes(regs, pos[used], cfg.holdout_eyes,
                                            np.random.default_rng([cfg.seed, 3]), holdout=True)
        c, r = regions_mod.bounding_sphere(pos[used])
        cube = vis.cube_directions(cfg.holdout_pixels)
        views = [vis.view_directions(e, c, r, cfg.holdout_pixels) if regs[k].kind == "outside" else cube
                 for e, k in zip(held, held_owner)]
        vis.rays = 0
        px = vis.pixels(held, views, dropped)
        proof = {"eyes": int(len(held)), "pixels": px["pixels"],
                 "pixels_showing_the_model": px["covered"], "wrong_pixels": px["wrong"],
                 "dropped_triangles_seen": int(px["dropped_seen"].sum()), "rays": vis.rays,
                 "cut_short": px["cut_short"]}
        proof["pictures"] = proof_mod.pictures(scene, vis, keep, held, views, px["wrong_per_eye"],
                                               cfg.holdout_pixels, min(cfg.pictures, len(held)),
                                               two_sided=sided, see_through=clear)
        if trim_info is not None:  # what is written (whole sources, redrawn outlines) against the model
            def vis_of(sc: Scene) -> Visibility:
                return Visibility(sc.positions, sc.triangles, two_sided=two_sided(sc, cfg.back_faces),
                                  see_through=see_through(sc)[0], threads=cfg.threads)

            differ, shown = proof_mod.depths_differ(vis_of(original), vis_of(out), held, views,
                                                    TRIM_EPS * original.scale())
            proof["written_vs_model"] = {"pixels_differ": differ, "pixels_showing": shown}
            if differ:
                rec.warn(f"trimming: {differ:,} of {shown:,} held-out pixels show the written triangles at another "
                         "depth than the model's (or one shows nothing there)")
        proof["seconds"] = round(time.perf_counter() - t1, 6)
        if px["covered"] == 0:
            rec.warn("the held-out eyes saw none of the model (no pixel shows it): the proof measured nothing; "
                     "move the points or boxes closer")
        rec.accuracy["wrong_pixels"] = float(px["wrong"])
        rec.accuracy["wrong_pixel_share"] = px["wrong"] / max(px["covered"], 1)
        if px["wrong"]:
            rec.warn(f"{px['wrong']:,} of {px['covered']:,} pixels seen by {len(held)} held-out eyes show one of "
                     f"{int(px['dropped_seen'].sum())} dropped triangle(s): raise mesh.hidden.eyes or "
                     "mesh.hidden.samples")

    tree = _tree_proof(original, out, section.tree) if section.tree is not None else None
    n_per = cfg.eyes * cfg.samples
    rec.counts_in = {"vertices": original.n_vertices, "triangles": original.n_triangles,
                     "polygons": original.n_polygons, "materials": len(original.materials)}
    rec.counts_out = {"vertices": out.n_vertices, "triangles": out.n_triangles, "polygons": out.n_polygons,
                      "materials": len(out.materials)}
    rec.details = {
        "regions": [{"kind": g.kind, "label": g.label, "eyes": int((owner == i).sum())} for i, g in enumerate(regs)],
        "eyes": int(len(eyes)), "eyes_per_region": cfg.eyes, "samples": cfg.samples, "rounds": rounds,
        "seen": int(seen.sum()), "casters_kept": casters, "dropped": int(dropped.sum()),
        "vertices_dropped": original.n_vertices - out.n_vertices,
        "see_through_triangles": int(clear.sum()), "see_through_materials": clear_names,
        "two_sided_triangles": int(sided.sum()), "back_faces": cfg.back_faces,
        "rays": decide_rays, "cut_short": short, "decide_seconds": round(decide_seconds, 6),
        # a triangle seen from a share p of the (eye, point) pairs of the first pass is missed by it
        # with probability at most (1 - p)^n (independent pairs; stratification only lowers it)
        "pairs_per_triangle": n_per,
        "miss_bound": {f"p={p:g}": float((1.0 - p) ** n_per) for p in (0.001, 0.01, 0.05)},
        "holdout": proof,
    }
    if trim_info is not None:
        rec.details["trim"] = trim_info
    if tree is not None:
        rec.details["bsp"] = tree
    if camera is not None:
        rec.details["camera_eye"] = [float(x) for x in camera]
        rec.details["camera_moves"] = camera_moves
    if cfg.camera and camera is None:
        rec.warn("mesh.hidden.camera: no camera eye (the model has no vertices)")
    if short:
        rec.warn(f"{short:,} rays went through {64} see-through or culled triangles and were cut short")
    rec.seconds = time.perf_counter() - t0
    return out, rec


def _bytes_estimate(d: dict[str, Any], st: dict[str, Any], report: dict[str, Any] | None) -> tuple[str, str] | None:
    """The report's row on the bytes the removal saves: an estimate from this bake's lists (each
    list that holds a value per written vertex or per written triangle, scaled by the vertices or
    triangles dropped), or why there is none."""
    stages = {x.get("name"): x for x in (report or {}).get("stages", [])}
    ex = stages.get("export")
    if ex is None:
        return None
    if "bsp" in stages:
        return ("bytes saved", "not estimated: the BSP tree's splits change with what is dropped (the BSP row "
                "below); bake with mesh.hidden.enabled = false and compare project.json for the figure")
    v_w, t_w = (ex.get("counts_in") or {}).get("vertices", 0), (ex.get("counts_in") or {}).get("triangles", 0)
    dv = st["counts_in"]["vertices"] - st["counts_out"]["vertices"]
    dt = st["counts_in"]["triangles"] - st["counts_out"]["triangles"]
    est = 0.0
    for v in ((ex.get("details") or {}).get("lists") or {}).values():
        per = int(v.get("items", 0)) // max(int(v.get("stride", 1)), 1)
        if v_w and per == v_w:
            est += v["project_json_bytes"] * dv / v_w
        elif t_w and per in (t_w, 3 * t_w):
            est += v["project_json_bytes"] * dt / t_w
    how = ("this bake's per-vertex and per-triangle lists scaled by the vertices and triangles dropped (textures "
           "and other lists unchanged); bake with mesh.hidden.enabled = false for the exact figure")
    return ("bytes saved (estimate)", f"about {round(est):,} bytes of project.json: {how}" if est >= 0 else
            f"none: about {round(-est):,} bytes more (trimming's pieces outnumber what it drops): {how}")


def section(st: dict[str, Any], report: dict[str, Any] | None = None) -> ReportSection | None:
    """The stage's section of report.html, from its entry in report.json (and the export's, for
    the bytes)."""
    d = st.get("details") or {}
    if "seen" not in d:
        return None
    ci, co = st.get("counts_in") or {}, st.get("counts_out") or {}
    regs = ", ".join(f"{r['label']} ({r['eyes']} eye{'s' if r['eyes'] != 1 else ''})" for r in d["regions"])
    trim = d.get("trim")
    what = (f"{d['dropped']:,} of the triangles and trimmed pieces dropped (trimming cut {trim['triangles_cut']:,} "
            f"crossing triangles into {trim['pieces']:,} pieces)" if trim else f"{d['dropped']:,} dropped")
    rows = [("triangles", f"{ci.get('triangles', 0):,} → {co.get('triangles', 0):,}; vertices "
                          f"{ci.get('vertices', 0):,} → {co.get('vertices', 0):,}; {what}; "
                          f"{d['casters_kept']:,} hidden kept as shadow or bounce casters"),
            ("view region", regs),
            ("sampling", f"{d['samples']} rays per eye and triangle"
                         + (f" ({d['samples'] * d['eyes_per_region']:,} from an eye at a point or the camera)"
                            if any(r["kind"] in FIXED for r in d["regions"]) and "eyes_per_region" in d else "")
                         + f"; {d['rays']:,} rays in {d['decide_seconds']:.2f} s; {len(d['rounds']) - 1} "
                           "refinement round(s)")]
    saved = _bytes_estimate(d, st, report)
    if saved:
        rows.append(saved)
    h = d.get("holdout") or {}
    if h.get("eyes"):
        rows.append(("held-out proof", f"{h['wrong_pixels']:,} wrong of {h['pixels_showing_the_model']:,} pixels "
                                       f"showing the model, from {h['eyes']} held-out eyes "
                                       f"({h['pixels']:,} pixels)"))
    tree = d.get("bsp")
    if tree:
        a, b = tree["without_removal"], tree["with_removal"]
        rows.append(("BSP splits", f"without the removal {a['triangles_in']:,} → {a['triangles_out']:,} triangles "
                     f"({a['inflation']:+.1%}); with it {b['triangles_in']:,} → {b['triangles_out']:,} "
                     f"({b['inflation']:+.1%}): the [bsp] settings on this stage's input and output, before the "
                     f"textures, simplify and lighting stages (this bake's own tree is in the BSP section; "
                     f"{tree['seconds']:.2f} s)"))
    out = ReportSection("Hidden geometry: what no eye sees", rows)
    for p in h.get("pictures") or []:
        where = f"held-out eye {p['eye']} ({p['wrong_pixels']:,} wrong pixels)"
        out.images += [(f"{where}: the full mesh", p["before"]), (f"{where}: what is kept", p["after"]),
                       (f"{where}: wrong pixels in red", p["difference"])]
    return out


__all__ = ["stage", "job", "section", "HiddenJob", "TreeProof", "keep_triangles", "see_through", "two_sided", "neighbours"]
