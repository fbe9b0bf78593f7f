"""The ``bsp`` stage: build the tree, replace the scene's triangles by the split, reordered set,
and add the ``bsp nodes`` / ``bsp planes`` lists (docs/formats-bsp.md).

The stage works in normalised coordinates (bbox centre at the origin, bbox diagonal 1), so the
tree — split counts, plane choices, draw order — does not depend on where the scene sits or how
big it is; only the written planes are in world units.
"""

from __future__ import annotations

import copy
import dataclasses
import time
from typing import Any

import numpy as np

from ..cache import active_memo
from ..record import StageRecord
from ..scene import BSPArtefact, Scene, ScratchList
from . import crossing
from .build import BuildOptions, Tree, build_tree
from ..scratch.numbers import format_numbers, json_array, project_json_bytes, round_positions
from .cost import blocks_estimate, walk_counts
from .encode import NODES_DOC, Encoded, encode
from .merge import SourceFaces, merge_coplanar
from .remerge import remerge
from .split import FaceStore, Tape, face_planes

NODES_LIST = "bsp nodes"
PLANES_LIST = "bsp planes"


def options(cfg: Any) -> BuildOptions:
    """Build options from the ``[bsp]`` config section (fields it lacks keep their defaults)."""
    opt = BuildOptions()
    for name in BuildOptions.__dataclass_fields__:
        if hasattr(cfg, name):
            setattr(opt, name, getattr(cfg, name))
    return opt


def frame(scene: Scene) -> tuple[np.ndarray, float]:
    """Centre and size that map the scene to normalised coordinates."""
    b = scene.bounds()
    return 0.5 * (b[0] + b[1]), scene.scale()


def _attributes(scene: Scene) -> tuple[np.ndarray, dict[str, slice]]:
    """Per-corner attributes (T, 3, A) interpolated along cuts: UVs, lightmap UVs and vertex
    colours, whichever the scene has; and where each sits in the last axis."""
    T = scene.n_triangles
    parts, layout, at = [], {}, 0
    for name, arr in (("uv", scene.tri_uvs), ("lightmap_uv", scene.tri_lightmap_uvs),
                      ("vertex_color", None if scene.vertex_colors is None else scene.vertex_colors[scene.triangles])):
        if arr is not None:
            parts.append(arr)
            layout[name] = slice(at, at + arr.shape[2])
            at += arr.shape[2]
    attr = np.concatenate(parts, axis=2) if parts else np.zeros((T, 3, 0))
    return attr, layout


def _groups(scene: Scene, two_sided: np.ndarray) -> np.ndarray:
    """Faces may merge only within a group: same material, sidedness, face colour and albedo."""
    cols = [scene.tri_material.astype(np.float64)[:, None], two_sided.astype(np.float64)[:, None]]
    for per_face in (scene.face_colors, scene.face_albedo):
        if per_face is not None:
            cols.append(per_face)
    _, g = np.unique(np.concatenate(cols, axis=1), axis=0, return_inverse=True)
    return g.ravel()


def written_positions(scene: Scene) -> np.ndarray:
    """The scene's positions as the export will write them: on the grid the pipeline fixed
    (``scene.position_decimals``), or exact when there is none."""
    if scene.position_decimals is None:
        return scene.positions
    return round_positions(scene.positions, scene.position_decimals)


# Rounding to the grid moves a point by up to 0.87 step, so two faces closer than about two steps
# can change sides when written: the tree treats them as coplanar (a tie) from the start.
GRID_TIE = 2.0


def tie_tolerance(epsilon: float, decimals: int | None, size: float) -> float:
    """The on-plane tolerance (fraction of ``size``, the model's diagonal): ``epsilon``, or two
    steps of the grid of ``decimals`` when that is coarser (faces that close can swap sides when
    their corners are rounded). The one definition: the tree's, and the previews' ties."""
    if decimals is None:
        return epsilon
    return max(epsilon, GRID_TIE * 10.0 ** -decimals / size)


def tolerance(scene: Scene, opt: BuildOptions) -> float:
    """The tree's on-plane tolerance: :func:`tie_tolerance` of the scene's grid."""
    return tie_tolerance(opt.epsilon, scene.position_decimals, frame(scene)[1])


def tri_two_sided(scene: Scene) -> np.ndarray:
    """Per triangle: is its material drawn from both sides?"""
    two_mat = np.array([m.double_sided for m in scene.materials], bool)
    return two_mat[np.clip(scene.tri_material, 0, len(two_mat) - 1)]


def _tree(scene: Scene, opt: BuildOptions, merge: bool, tape: bool, remerge_fragments: bool):
    """The source faces, the tree built on them and re-merged: (store, src, tree, (center,
    scale), options with the tree's tolerance), what :func:`build` and :func:`grow` share."""
    center, scale = frame(scene)
    opt = dataclasses.replace(opt, epsilon=tolerance(scene, opt))
    src, two, ch = merged(scene, opt, merge, tape)
    plane, degen = face_planes(src.pos, src.count, opt.min_area)
    first_tri = src.tri_list[src.tri_start[:-1]]
    store = FaceStore(src.pos, src.count, src.attr, src.vid, plane, degen, two[first_tri])
    if ch is not None:
        store.tape = Tape(ch, src.n_input_corners)
    if scene.position_decimals is not None:
        store.grid = (center, scale, scene.position_decimals)
    tree = build_tree(store, opt, center, scale)
    if remerge_fragments:
        t = time.perf_counter()
        groups, shown = remerge_groups(scene, src, two, store.A, ch)
        tree.stats.update(remerge(store, tree, groups, opt.epsilon, opt.min_area, shown=shown))
        tree.stats["remerge_seconds"] = time.perf_counter() - t
    return store, src, tree, (center, scale), opt


def build(scene: Scene, opt: BuildOptions, merge: bool = True, tape: bool = False, remerge_fragments: bool = True):
    """Everything but writing the scene: (store, sources, tree, encoded, frame), in one go (the
    stage itself goes through :func:`grow` and :func:`complete`, which give the same result).

    With a grid on the scene (``scene.position_decimals``) the tree is built on the positions as
    they will be written: input positions rounded, every vertex a cut makes snapped to the grid,
    a cut whose snapped pieces would be collapsed, flipped or tilted not made, triangles that
    rounding collapses left out, and the on-plane tolerance at least a grid step.

    ``tape``: with vertex colours, ``store.tape`` records where every cut corner's attributes came
    from (:class:`bake.bsp.split.Tape`; the result is the same either way: the corner ids it adds
    decide neither a merge nor a re-merge). ``remerge_fragments``: join coplanar fragments drawn
    together again (:func:`bake.bsp.remerge.remerge`)."""
    store, src, tree, (center, scale), _ = _tree(scene, opt, merge, tape, remerge_fragments)
    frag_tris = fragment_triangles(store, src)
    enc = encode(tree, frag_tris)
    return store, src, tree, enc, (center, scale)


def merges_before_build(scene: Scene, merge: bool) -> bool:
    """Does the coplanar merge run before the build? Not with vertex colours (a lit bake): which
    faces may merge would depend on the lit colours (equal face colours, vertex colours affine
    over the union), so a new light, AO sample count or exposure would give other source faces and
    another tree. Without it the tree depends on the geometry, materials and sidedness only (the
    re-merge after the build looks at no colour either: :func:`remerge_groups`); the colours
    follow the triangles and the cut pieces they belong to (:func:`complete`). Without vertex
    colours the face colours are the model's, not the lighting's."""
    return bool(merge) and scene.vertex_colors is None


def merged(scene: Scene, opt: BuildOptions, merge: bool, tape: bool = False) -> tuple[SourceFaces, np.ndarray, int | None]:
    """The source faces (coplanar triangles merged; ``opt.epsilon`` already the tree's tolerance),
    each triangle's sidedness, and the attribute channel that holds corner ids for the tape (None:
    no tape; only with ``tape`` and vertex colours)."""
    center, scale = frame(scene)
    pos_w = written_positions(scene)
    pos_n = (pos_w - center) / scale
    keep = np.arange(scene.n_triangles)
    if scene.position_decimals is not None:  # triangles rounding collapsed to a line or point
        p = pos_w[scene.triangles]
        keep = np.flatnonzero(np.any(np.cross(p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]) != 0, axis=1))
    tris = scene.triangles[keep]
    two = tri_two_sided(scene)
    attr, layout = _attributes(scene)
    attr = attr[keep]
    ch = None
    if tape and "vertex_color" in layout:  # corner ids ride along as one more attribute
        ch = attr.shape[2]
        attr = np.concatenate([attr, np.arange(3 * len(keep), dtype=np.float64).reshape(-1, 3, 1)], axis=2)
    seen = np.ones((len(tris), attr.shape[2]), bool)
    if "uv" in layout:  # an untextured material shows no UVs: they need not agree to merge
        textured = np.array([m.texture is not None or m.texture_data is not None for m in scene.materials], bool)
        seen[:, layout["uv"]] = textured[np.clip(scene.tri_material[keep], 0, len(textured) - 1)][:, None]
    if ch is not None:
        seen[:, ch] = False  # (an id is not an attribute: it never decides a merge)
    src = merge_coplanar(pos_n, tris, attr, _groups(scene, two)[keep], opt.epsilon, opt.min_area,
                         enabled=merges_before_build(scene, merge), seen=seen)
    src.tri_list = keep[src.tri_list]  # scene triangle numbers
    src.dropped = int(scene.n_triangles - len(keep))
    src.kept_triangles = keep
    src.n_input_corners = 3 * len(keep)
    return src, two, ch


def fragment_triangles(store: FaceStore, src: SourceFaces) -> np.ndarray:
    """Triangles each fragment is written as: its source's own triangles if it was never cut,
    else a fan of its corners."""
    n = store.n
    per_src = np.diff(src.tri_start)
    out = store.count[:n] - 2
    w = store.whole[:n]
    out[w] = per_src[store.src[:n][w]]
    return out


def write_scene(scene: Scene, store: FaceStore, src: SourceFaces, enc: Encoded, center: np.ndarray,
                scale: float) -> tuple[Scene, dict]:
    """The scene with its triangles replaced by the fragments, in the encoded order."""
    layout = split_layout(scene, store, src, enc, center, scale)
    return apply_layout(scene, layout), layout


def apply_layout(scene: Scene, layout: dict) -> Scene:
    """The scene with its triangles replaced by a :func:`split_layout`'s: positions, corners, UVs
    and polygons from the layout, materials and colours (``face_colors``, ``face_albedo``) taken
    from ``scene`` through each output triangle's source triangle. Only this step reads the
    scene's per-triangle colours, so a layout made for one set of colours applies to another
    (:func:`stage` reuses it when nothing the layout depends on changed)."""
    src_tri = layout["source_triangle"]
    return scene.replace(
        positions=layout["positions"],
        triangles=layout["triangles"],
        tri_material=scene.tri_material[src_tri].copy(),
        tri_uvs=layout["tri_uvs"],
        tri_polygon=layout["tri_polygon"],
        vertex_colors=layout["vertex_colors"],
        face_colors=None if scene.face_colors is None else scene.face_colors[src_tri].copy(),
        face_albedo=None if scene.face_albedo is None else scene.face_albedo[src_tri].copy(),
        tri_lightmap_uvs=layout["tri_lightmap_uvs"],
    )


def split_layout(scene: Scene, store: FaceStore, src: SourceFaces, enc: Encoded, center: np.ndarray,
                 scale: float) -> dict:
    """The split, reordered triangles as arrays (:func:`apply_layout` makes the scene of them):
    positions (with the vertices cuts made), corners, UVs, lightmap UVs, vertex colours,
    polygons, and for each output triangle the scene triangle whose material and colour it keeps
    (``source_triangle``) and its source face; for each input triangle its source face."""
    order = enc.frag_order
    ntri = enc.frag_tris
    T_out = int(ntri.sum())
    slot = np.zeros(len(order) + 1, np.int64)
    np.cumsum(ntri, out=slot[1:])
    _, layout = _attributes(scene)
    A = store.A
    V = scene.n_vertices
    uv_s, lm_s, vc_s = layout.get("uv"), layout.get("lightmap_uv"), layout.get("vertex_color")

    out_tris = np.zeros((T_out, 3), np.int64)
    out_uv = np.zeros((T_out, 3, 2)) if uv_s else None
    out_lm = np.zeros((T_out, 3, 2)) if lm_s else None
    out_src_tri = np.zeros(T_out, np.int64)  # the scene triangle whose material/colour it keeps
    out_face = np.repeat(store.src[order], ntri)  # the source face (merged polygon) it comes from
    out_poly = np.full(T_out, -1, np.int64)
    tri_polygon = scene.tri_polygon if scene.tri_polygon is not None else np.arange(scene.n_triangles)

    whole = store.whole[order]
    # ---- fragments never cut: their source's own triangles, untouched
    wf = np.flatnonzero(whole)
    if len(wf):
        s = store.src[order[wf]]
        cnt = np.diff(src.tri_start)[s]
        rep = np.repeat(np.arange(len(wf)), cnt)
        within = np.arange(int(cnt.sum())) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        t_src = src.tri_list[src.tri_start[s][rep] + within]
        dst = slot[wf][rep] + within
        out_tris[dst] = scene.triangles[t_src]
        if uv_s:
            out_uv[dst] = scene.tri_uvs[t_src]
        if lm_s:
            out_lm[dst] = scene.tri_lightmap_uvs[t_src]
        out_src_tri[dst] = t_src
        out_poly[dst] = tri_polygon[t_src]
    # ---- cut fragments: fans over their corners
    cf = np.flatnonzero(~whole)
    new_pos = np.zeros((0, 3))
    new_vc = np.zeros((0, 4))
    n_new = 0
    # with a tape: the cut corners that became new vertices (their corner ids and positions) and
    # the vertex each became
    replay = None if store.tape is None else {"ids": np.zeros(0, np.int64), "pos": np.zeros((0, 3)),
                                              "inv": np.zeros(0, np.int64)}
    if len(cf):
        f = order[cf]
        c = store.count[f]
        k = c - 2
        rep = np.repeat(np.arange(len(cf)), k)
        i = np.arange(int(k.sum())) - np.repeat(np.cumsum(k) - k, k) + 1  # fan: (0, i, i + 1)
        fr = f[rep]
        corners = np.stack([np.zeros_like(i), i, i + 1], 1)
        vid = store.vid[fr[:, None], corners]
        cpos = store.pos[fr[:, None], corners]
        cattr = store.attr[fr[:, None], corners] if A else np.zeros(corners.shape + (0,))
        need = vid < 0
        if need.any():
            vcols = cattr[need][:, vc_s] if vc_s else np.zeros((int(need.sum()), 0))
            # one vertex per position and colour -- decided without the colours, so that the
            # vertices, hence the triangles written, do not change with the lighting (the
            # previews' geometry is reused after a lighting change): two cut corners at one place
            # have one colour for every lighting when their colours are made of the same input
            # vertices' (one edge's two ends, or one triangle's three corners) with the same
            # weights; the tape replayed on fixed random values per scene vertex tells them
            # apart (equal values: the same vertices and weights), and the corner first used
            # gives the vertex its colour. Numbered in the order the output first uses them.
            if vc_s and store.tape is None:  # (bake.bsp.stage.build without a tape: by colour)
                ident = vcols
            else:
                ident = _identities(scene, src, store, cattr[need]) if vc_s else np.zeros((int(need.sum()), 0))
            key = np.concatenate([cpos[need], ident], 1)
            uniq, first, inv = np.unique(key, axis=0, return_index=True, return_inverse=True)
            by_use = np.argsort(first, kind="stable")
            rank = np.empty(len(first), np.int64)
            rank[by_use] = np.arange(len(first))
            uniq, first, inv = uniq[by_use], first[by_use], rank[inv.ravel()]
            vid = vid.copy()
            vid[need] = V + inv.ravel()
            new_pos = uniq[:, :3] * scale + center
            if scene.position_decimals is not None:  # made on the grid: keep them exactly there
                new_pos = round_positions(new_pos, scene.position_decimals)
            new_vc = vcols[first]
            n_new = len(uniq)
            if replay is not None:
                replay = {"ids": cattr[need][:, store.tape.ch].astype(np.int64), "pos": cpos[need],
                          "inv": inv.ravel().astype(np.int64)}
        dst = slot[cf][rep] + (i - 1)
        out_tris[dst] = vid
        if uv_s:
            out_uv[dst] = cattr[..., uv_s]
        if lm_s:
            out_lm[dst] = cattr[..., lm_s]
        t_src = src.tri_list[src.tri_start[store.src[fr]]]
        out_src_tri[dst] = t_src
    base = written_positions(scene)
    positions = np.concatenate([base, new_pos]) if n_new else base
    vcol = scene.vertex_colors
    if vcol is not None and n_new:
        vcol = np.concatenate([vcol, np.clip(new_vc, 0.0, 1.0)])
    in_face = np.full(scene.n_triangles, -1, np.int64)
    in_face[src.tri_list] = np.repeat(np.arange(len(src.count)), np.diff(src.tri_start))
    out_tris, out_uv, out_lm = apex_first(positions, out_tris, out_uv, out_lm)
    return {"positions": positions, "triangles": out_tris, "tri_uvs": out_uv, "tri_polygon": out_poly,
            "vertex_colors": vcol, "tri_lightmap_uvs": out_lm, "new_vertices": n_new,
            "source_triangle": out_src_tri, "source_face": out_face, "input_source_face": in_face,
            "replay": replay}


def _identities(scene: Scene, src: SourceFaces, store: FaceStore, cattr: np.ndarray) -> np.ndarray:
    """Per cut corner (its attributes ``cattr``, with the tape's corner ids): what its colour is
    made of, as values that do not depend on the colours (:func:`split_layout`): the tape replayed
    on fixed random values per scene vertex, on a grid of 2^-20 (corners reached along two ways
    differ in the last bits only)."""
    rnd = np.random.default_rng(41).random((scene.n_vertices, 2))
    base = rnd[scene.triangles][src.kept_triangles].reshape(-1, 2)
    vals = Tape.replay(store.tape.state(), base)
    ids = cattr[:, store.tape.ch].astype(np.int64)
    return np.round(vals[ids] * 2.0 ** 20)


def apex_first(positions: np.ndarray, tris: np.ndarray, *corner_arrays: np.ndarray | None) -> tuple:
    """Each triangle's corners turned (cyclically: the winding and the facing stay) so that the
    first corner is the one opposite the triangle's shortest edge, with every per-corner array
    (UVs, lightmap UVs) turned alike. The reader's filler strokes a fan from the first corner to
    the opposite edge, one line per pixel of that edge's length (docs/formats.md, "tris"): from
    the corner opposite the shortest edge it needs the fewest lines (lit BSP teapot: 19,089 ->
    17,247 pen lines per frame, measured with ``bake.scratch.readers`` on the green flag's camera).
    Edges within a millionth of the shortest count as tied and the lowest corner wins, so the
    choice does not depend on rounding (the same model moved or scaled gets the same corners)."""
    if len(tris) == 0:
        return (tris, *corner_arrays)
    P = positions[tris]
    opposite = np.stack([((P[:, 2] - P[:, 1]) ** 2).sum(-1), ((P[:, 0] - P[:, 2]) ** 2).sum(-1),
                         ((P[:, 1] - P[:, 0]) ** 2).sum(-1)], 1)
    tied = opposite <= opposite.min(axis=1, keepdims=True) * (1.0 + 1e-6)
    turn = (tied.argmax(axis=1)[:, None] + np.arange(3)[None, :]) % 3
    out = [np.take_along_axis(tris, turn, axis=1)]
    for arr in corner_arrays:
        out.append(None if arr is None else np.take_along_axis(arr, turn[:, :, None], axis=1))
    return tuple(out)


def typical_walk(scene: Scene, enc: Encoded) -> dict:
    """One frame's walk from the eye the reader sprite starts with (bake.scratch.project.auto_camera:
    in front of, above and left of the model): records, plane tests, ranges and the triangles in
    them (and how many face the eye), and the Scratch blocks the walk costs (bake/bsp/cost.py)."""
    from ..scratch.project import auto_camera

    cam = auto_camera(scene.positions[scene.used_vertex_mask()])
    eye = [cam.x, cam.y, cam.z]
    two = tri_two_sided(scene)
    counts = walk_counts(enc.nodes, enc.planes, scene.triangles, scene.positions, two, eye)
    return {"eye": eye, **counts, "plane_tests": counts["split"], "blocks_estimate": blocks_estimate(counts)}


def list_bytes(name: str, values: np.ndarray, decimals: int | None = None) -> tuple[int, int]:
    """(items, project.json bytes) of a list written as short JSON numbers."""
    items = format_numbers(np.asarray(values), decimals, name=name)
    return len(items), project_json_bytes(name, json_array(items))


def tree_key_parts(scene: Scene, opt: BuildOptions, merge: bool, remerge_fragments: bool = True) -> list:
    """The key of a reusable tree (:func:`grow`): everything of the scene and options the tree
    depends on, never a lit colour. Positions and their grid, corners, materials (sidedness,
    textured or not), polygons, UVs, lightmap UVs, whether there are vertex colours, and, without
    vertex colours, the merge groups (material, sidedness, face colour and albedo, as the group
    numbers :func:`_groups` gives: the coplanar merge before the build reads them). With vertex
    colours (a lit bake) nothing merges before the build (:func:`merges_before_build`) and the
    re-merge joins only pieces of one input triangle without looking at colours
    (:func:`remerge_groups`), so the tree is built on geometry, materials and sidedness alone and
    every lit colour follows the triangle or piece it belongs to (:func:`complete`)."""
    two = tri_two_sided(scene)
    mats = [[bool(m.double_sided), m.texture is not None or m.texture_data is not None] for m in scene.materials]
    return ["bsp tree 3", {k: getattr(opt, k) for k in BuildOptions.__dataclass_fields__},
            merges_before_build(scene, merge), bool(remerge_fragments),
            scene.positions, scene.position_decimals, scene.triangles, scene.tri_material, mats,
            scene.tri_polygon, scene.tri_uvs, scene.tri_lightmap_uvs,
            None if scene.vertex_colors is None else list(scene.vertex_colors.shape),
            _canonical(_groups(scene, two)) if scene.vertex_colors is None else None]


def _canonical(labels: np.ndarray) -> np.ndarray:
    """Group numbers renumbered by first appearance: the same partition gives the same numbers
    (merging compares group numbers for equality only)."""
    _, first, inv = np.unique(labels, return_index=True, return_inverse=True)
    rank = np.empty(len(first), np.int64)
    rank[np.argsort(first, kind="stable")] = np.arange(len(first))
    return rank[inv.ravel()]


def _plain(v: Any) -> Any:
    return v.item() if isinstance(v, np.generic) else v


def remerge_groups(scene: Scene, src: SourceFaces, two: np.ndarray, A: int, ch: int | None
                   ) -> tuple[np.ndarray, np.ndarray | None]:
    """What the re-merge may join, per source face, and the attribute channels that must be affine
    over a join. With vertex colours (a lit bake) only fragments of one source face (one input
    triangle: nothing merged before the build) join, and the colours are not looked at: a source
    triangle's colours are affine over it and its face colour is one, so such a join shows the
    colours it had, whatever they are, and no colour decides a join. Without vertex colours: the
    merge groups (material, sidedness, face colour, albedo; part of the tree's key) and every
    attribute."""
    if scene.vertex_colors is None:
        first_tri = src.tri_list[src.tri_start[:-1]]
        return _groups(scene, two)[first_tri], None
    _, at = _attributes(scene)
    shown = np.ones(A, bool)
    shown[at["vertex_color"]] = False
    if ch is not None:
        shown[ch] = False
    return np.arange(len(src.count)), shown


def grow(scene: Scene, opt: BuildOptions, merge: bool, remerge_fragments: bool = True) -> dict:
    """The tree as the build and the re-merge leave it, as plain arrays (what the memo keeps;
    :func:`complete` makes the stage's result of it for any colours): the store and tree
    (:func:`_freeze`), the build's figures, and with vertex colours the tape of the cuts
    (:class:`bake.bsp.split.Tape`), from which :func:`complete` computes every cut corner's colour
    for the colours of the bake at hand."""
    t0 = time.perf_counter()
    store, src, tree, (center, scale), opt = _tree(scene, opt, merge, True, remerge_fragments)
    t_cross = time.perf_counter()
    # parts that pass through each other: cuts no tree avoids (bake/bsp/crossing.py)
    crossed = crossing.summary(written_positions(scene), scene.triangles, opt.epsilon * scale)
    crossed["seconds"] = round(time.perf_counter() - t_cross, 4)
    return {"frozen": _freeze(store, tree), "tape": None if store.tape is None else store.tape.state(),
            "stats": {k: _plain(v) for k, v in tree.stats.items()}, "crossing": crossed,
            "seconds": time.perf_counter() - t0}


def _tape_of(state: dict) -> Tape:
    tape = Tape(int(state["ch"]), int(state["n0"]))
    tape.next = int(state["next"])
    tape.batches = [tuple(b) for b in state["batches"]]
    return tape


def complete(scene: Scene, opt: BuildOptions, merge: bool, remerge_fragments: bool, grown: dict) -> dict:
    """The stage's result (what :func:`finish` turns into the scene and record) from a
    :func:`grow` of a scene that differs from this one at most in its colours: the cut corners'
    vertex colours computed again from the tape (exactly as the build computes them), the
    encoding, the split layout and the figures. A cold bake takes the same path, so a reused tree
    gives the cold bytes."""
    t0 = time.perf_counter()
    T_in = scene.n_triangles
    center, scale = frame(scene)
    topt = dataclasses.replace(opt, epsilon=tolerance(scene, opt))
    src, two, _ = merged(scene, topt, merge, tape=grown["tape"] is not None)
    store, tree = _thaw(grown["frozen"])
    tree.stats = dict(grown["stats"])
    if grown["tape"] is not None:
        store.tape = _tape_of(grown["tape"])
        _, at = _attributes(scene)
        C = scene.vertex_colors.shape[1]
        corners = scene.vertex_colors[scene.triangles][src.kept_triangles].reshape(-1, C)
        vals = Tape.replay(grown["tape"], corners)
        ids = store.attr[:, :, store.tape.ch].astype(np.int64)
        store.attr[:, :, at["vertex_color"]] = vals[np.clip(ids, 0, len(vals) - 1)]
    enc = encode(tree, fragment_triangles(store, src))
    layout = split_layout(scene, store, src, enc, center, scale)
    nodes_items, nodes_bytes = list_bytes(NODES_LIST, enc.nodes)
    planes_items, planes_bytes = list_bytes(PLANES_LIST, enc.planes.ravel())
    stack_bound = 2 * enc.max_depth + 2
    tol = tolerance(scene, opt)
    crossed = copy.deepcopy(grown["crossing"])
    T_out = len(layout["triangles"])
    st = tree.stats
    records = sum(enc.records.values())
    counts_out = {"triangles": T_out, "vertices": len(layout["positions"]), "bsp_records": records,
                  "bsp_planes": len(enc.planes), "bsp_items": nodes_items + planes_items}
    details = {
        "inflation": round(T_out / T_in - 1.0, 6),
        "splits": st["splits"], "kept_whole": st["kept_whole"], "merged_triangles": src.merged,
        "thorough_search": st.get("thorough", False),
        "remerged_fragments": st.get("remerged", 0), "remerge_saved_triangles": st.get("remerge_saved", 0),
        "remerge_reverted_lists": st.get("remerge_reverted", 0),
        "source_faces": int(len(src.count)), "tree_nodes": tree.n_nodes, "tree_depth": int(tree.depth.max()),
        "records": enc.records, "record_depth": enc.max_depth, "stack_bound": stack_bound,
        "planes": int(len(enc.planes)), "plane_uses": enc.plane_uses, "peeled_fragments": st["peeled"],
        "new_vertices": layout["new_vertices"],
        "grid": None if scene.position_decimals is None else 10.0 ** -scene.position_decimals,
        "tolerance": tol, "collapsed_input_triangles": src.dropped, "grid_kept_whole": st.get("grid_kept", 0),
        "crossing": crossed,
        "lists": {NODES_LIST: {"items": nodes_items, "project_json_bytes": nodes_bytes},
                  PLANES_LIST: {"items": planes_items, "project_json_bytes": planes_bytes}},
        "bytes_per_record": round((nodes_bytes + planes_bytes) / max(1, records), 3),
        "bytes_per_triangle": round((nodes_bytes + planes_bytes) / max(1, T_out), 3),
        "items_per_triangle": round((nodes_items + planes_items) / max(1, T_out), 4),
        "seconds": {"build": round(st["seconds"], 4), "leaf_tests": round(st["leaf_seconds"], 4),
                    "choose": round(st["choose_seconds"], 4), "split": round(st["split_seconds"], 4),
                    "remerge": round(st.get("remerge_seconds", 0.0), 4)},
        "options": {k: getattr(opt, k) for k in BuildOptions.__dataclass_fields__},
    }
    details["walk"] = typical_walk(apply_layout(scene, layout), enc)
    warnings = []
    if src.dropped:
        warnings.append(f"{src.dropped} triangle(s) have zero area at the written positions (rounded to "
                        f"{10.0 ** -scene.position_decimals:g}) and were left out")
    if crossed["pairs"]:
        warnings.append(f"{crossed['pairs']:,} pair(s) of triangles pass through each other ({crossed['triangles']:,} "
                        f"triangles in {crossed['parts']} connected part(s)): a painter's order must cut one triangle of "
                        "each pair, whatever the tree; parts modelled to touch or sit apart cost fewer splits "
                        "(docs/formats-bsp.md, Known limits)")
    if st["kept_whole"]:
        why = f"below the minimum area ({opt.min_area:g} of diagonal^2)"
        if scene.position_decimals is not None:
            why += " or collapsed, flipped or tilted on the written grid"
        warnings.append(f"{st['kept_whole']} straddling fragment(s) left uncut: a piece would have been {why}")
    return {"layout": layout, "nodes": enc.nodes, "planes": enc.planes, "stack_bound": stack_bound,
            "tolerance": tol, "epsilon": opt.epsilon, "counts_out": counts_out,
            "inflation": T_out / T_in - 1.0, "details": details, "warnings": warnings,
            "seconds": float(grown["seconds"]) + time.perf_counter() - t0}


def make(scene: Scene, opt: BuildOptions, merge: bool, remerge_fragments: bool = True) -> dict:
    """Build the tree and the split layout (:func:`grow`, then :func:`complete`)."""
    return complete(scene, opt, merge, remerge_fragments, grow(scene, opt, merge, remerge_fragments))


def _freeze(store: FaceStore, tree: Tree) -> dict:
    """A store and its tree as plain arrays and numbers (what the stage cache's entries hold)."""
    st = {k: v for k, v in vars(store).items() if k not in ("tape", "grid")}
    st["grid"] = None if store.grid is None else [np.asarray(store.grid[0]), float(store.grid[1]), int(store.grid[2])]
    return {"store": st, "tree": {f.name: getattr(tree, f.name) for f in dataclasses.fields(tree)
                                  if f.name not in ("store", "stats")}}


def _thaw(frozen: dict) -> tuple[FaceStore, Tree]:
    """The store and tree of a :func:`_freeze` (new arrays: the frozen ones stay as they are)."""
    frozen = copy.deepcopy(frozen)
    store = object.__new__(FaceStore)
    for k, v in frozen["store"].items():
        setattr(store, k, v)
    store.grid = None if frozen["store"]["grid"] is None else tuple(frozen["store"]["grid"])
    store.tape = None
    return store, Tree(store=store, stats={}, **frozen["tree"])


def finish(scene: Scene, made: dict, rec: StageRecord) -> Scene:
    """The stage's scene from a :func:`make` (this bake's or a reused one), and its record's
    figures (the same either way)."""
    layout = made["layout"]
    new = apply_layout(scene, layout)
    new = new.with_list(ScratchList(NODES_LIST, made["nodes"].copy(), 0, _NODES_DOC, "int"))
    new = new.with_list(ScratchList(PLANES_LIST, made["planes"].ravel().copy(), 4, _PLANES_DOC, "number"))
    new = new.with_artefacts(bsp=BSPArtefact(NODES_LIST, PLANES_LIST, made["stack_bound"], made["tolerance"],
                                             source_triangle=layout["source_triangle"],
                                             source_face=layout["source_face"],
                                             input_source_face=layout["input_source_face"]))
    rec.counts_in = {"triangles": scene.n_triangles, "vertices": scene.n_vertices}
    rec.counts_out = dict(made["counts_out"])
    rec.accuracy = {"inflation": made["inflation"]}
    rec.details = copy.deepcopy(made["details"])
    for w in made["warnings"]:
        rec.warn(w)
    return new


def stage(scene: Scene, cfg: Any) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord("bsp")
    T_in = scene.n_triangles
    opt = options(cfg)
    merge = bool(getattr(cfg, "merge_coplanar", True))
    remerge_fragments = bool(getattr(cfg, "remerge", True))
    if T_in == 0:
        new = scene.with_list(ScratchList(NODES_LIST, np.zeros(0, np.int64), 0, _NODES_DOC, "int"))
        new = new.with_list(ScratchList(PLANES_LIST, np.zeros(0), 4, _PLANES_DOC, "number"))
        new = new.with_artefacts(bsp=BSPArtefact(NODES_LIST, PLANES_LIST, 2, opt.epsilon))
        rec.warn("no triangles: empty BSP")
        rec.seconds = time.perf_counter() - t0
        return new, rec
    # A tree built for the same geometry, materials and options is reused (a bake whose lighting
    # changed): bake.cache.Memo, the stage cache's store, keyed by tree_key_parts.
    memo = active_memo()
    key = grown = None
    if memo is not None:
        key = memo.key("bsp", *tree_key_parts(scene, opt, merge, remerge_fragments))
        grown = memo.get("bsp", key, lambda m: m if _is_grown(m) else None, "a BSP tree")
    reused = grown is not None
    if reused:
        memo.used("bsp")
    else:
        grown = grow(scene, opt, merge, remerge_fragments)
        if memo is not None:
            memo.put("bsp", key, grown)
    made = complete(scene, opt, merge, remerge_fragments, grown)
    new = finish(scene, made, rec)
    if memo is not None:
        for w in memo.take_warnings():
            rec.warn(w)
    rec.details["tree_reused"] = {"reused": reused, "built_seconds": round(float(grown["seconds"]), 6)}
    rec.seconds = time.perf_counter() - t0
    return new, rec


def _is_grown(grown: Any) -> bool:
    """A loaded memo holds what :func:`grow` returns (the entry format checked the types inside)."""
    return isinstance(grown, dict) and {"frozen", "tape", "stats", "crossing", "seconds"} <= set(grown) and \
        isinstance(grown["frozen"], dict) and {"store", "tree"} <= set(grown["frozen"]) and \
        isinstance(grown["stats"], dict) and (grown["tape"] is None or isinstance(grown["tape"], dict))


_NODES_DOC = NODES_DOC
_PLANES_DOC = "a, b, c, d per BSP plane (eye in front when a*x + b*y + c*z - d >= 0)"

__all__ = ["stage", "build", "write_scene", "split_layout", "apply_layout", "make", "grow", "complete", "finish", "options", "frame", "NODES_LIST", "PLANES_LIST", "Tree"]
