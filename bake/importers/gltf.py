"""glTF 2.0 / GLB importer: one scene's node hierarchy flattened to world-space polygons.

``load(job) -> (Scene, StageRecord)``. What it does, in order:

1. :mod:`bake.importers.gltf_data` parses the file and checks every reference and byte range.
2. ``extensionsRequired`` is checked against what this importer understands (Draco via DracoPy,
   lights, texture transforms, mesh quantization, unlit); anything else is a clear error.
3. The scene: ``job.scene`` when >= 0, else the file's ``scene``, else ``scenes[0]``, else every
   parentless node. Nodes with two parents or in a cycle are errors (checked for all nodes).
4. Each node instance of a mesh contributes its primitives again (instancing is duplicated),
   positions transformed to world space in float64. A negative-determinant world matrix
   reverses the corner order so front faces stay front.
5. TRIANGLES / TRIANGLE_STRIP / TRIANGLE_FAN become triangles (strip winding alternates per
   the glTF spec); points and lines are skipped with a warning. Every triangle is a polygon of
   size 3; only the vertices a primitive's triangles use are kept.
6. Materials: exact ``baseColorFactor`` floats (alpha forced to 1 for ``OPAQUE``, to 0/1 by
   ``alphaCutoff`` for an untextured ``MASK``), ``baseColorTexture`` as an absolute path
   (external image) or embedded bytes, ``doubleSided``. Only materials the scene uses are kept,
   in file order, then the default material if a primitive has none.
7. ``COLOR_0`` -> ``vertex_colors`` (white where a primitive has none); the UV set the base
   colour texture uses (``TEXCOORD_0`` by default, ``KHR_texture_transform`` applied) ->
   ``poly_uvs`` per corner with v flipped to the bottom-left origin.
8. ``KHR_lights_punctual`` lights on the scene's nodes -> ``scene.lights`` in world space.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

import numpy as np

from ..config import ImportJob
from ..record import StageRecord
from ..scene import DEFAULT_MATERIAL, MAX_COORDINATE, Light, Material, Scene, SourceInfo
from ..colorspace import linear_to_srgb
from .gltf_data import MESHOPT_EXTENSIONS, GltfDocument, decode_draco, open_document

MODE_NAMES = {0: "points", 1: "lines", 2: "line_loop", 3: "line_strip", 4: "triangles",
              5: "triangle_strip", 6: "triangle_fan"}

# Extensions whose absence of support would change what we import; required ones we can't
# handle are an error. KHR_materials_unlit / emissive_strength don't affect base colour.
SUPPORTED_EXTENSIONS = {
    "KHR_draco_mesh_compression", "KHR_lights_punctual", "KHR_texture_transform",
    "KHR_mesh_quantization", "KHR_materials_unlit", "KHR_materials_emissive_strength",
}

# glTF 2.0's default material (a primitive without "material"): baseColorFactor [1, 1, 1, 1],
# single-sided; an OBJ without a material gets bake's grey (DEFAULT_MATERIAL) instead
GLTF_DEFAULT_MATERIAL = DEFAULT_MATERIAL.with_(color=(1.0, 1.0, 1.0, 1.0))


def _draco_available() -> bool:
    try:
        import DracoPy  # noqa: F401
    except ImportError:
        return False
    return True


# --------------------------------------------------------------------------- transforms
def _quat_matrix(q: tuple[float, ...], where: str, doc: GltfDocument) -> np.ndarray:
    x, y, z, w = q
    n = math.sqrt(x * x + y * y + z * z + w * w)
    if n < 1e-12:
        raise doc.error("rotation is a zero quaternion", where)
    x, y, z, w = x / n, y / n, z / n, w / n
    return np.array([
        [1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
        [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
        [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)],
    ])


def node_matrix(doc: GltfDocument, node: dict, where: str, rec: StageRecord) -> np.ndarray:
    """The node's local 4x4 transform (float64)."""
    if "matrix" in node:
        m = np.array(doc.numbers(node, "matrix", where, 16, ()), dtype=np.float64).reshape(4, 4).T
        if any(k in node for k in ("translation", "rotation", "scale")):
            rec.warn(f"{where}: has both matrix and translation/rotation/scale; using matrix")
        if not np.allclose(m[3], [0, 0, 0, 1], atol=1e-6):
            rec.warn(f"{where}: matrix is not affine (last row {m[3].tolist()}); ignoring the "
                     f"last row")
            m[3] = [0, 0, 0, 1]
        return m
    t = doc.numbers(node, "translation", where, 3, (0, 0, 0))
    r = doc.numbers(node, "rotation", where, 4, (0, 0, 0, 1))
    s = doc.numbers(node, "scale", where, 3, (1, 1, 1))
    m = np.eye(4)
    m[:3, :3] = _quat_matrix(r, where, doc) * np.array(s)[None, :]
    m[:3, 3] = t
    return m


def check_hierarchy(doc: GltfDocument) -> np.ndarray:
    """Parent of every node (-1 for roots). Two parents or a cycle -> InputError."""
    nodes = doc.array("nodes")
    parent = np.full(len(nodes), -1, dtype=np.int64)
    for i, n in enumerate(nodes):
        for c in n.get("children", []):
            if c == i:
                raise doc.error("is its own child (a cycle)", f"nodes[{i}]")
            if parent[c] >= 0:
                other = int(parent[c])
                if other == i:
                    raise doc.error(f"lists nodes[{c}] twice as a child", f"nodes[{i}]")
                raise doc.error(f"has two parents (nodes[{other}] and nodes[{i}])", f"nodes[{c}]")
            parent[c] = i
    # with at most one parent each, a node is reachable from a root unless it sits in a cycle
    reached = np.zeros(len(nodes), dtype=bool)
    stack = [i for i in range(len(nodes)) if parent[i] < 0]
    while stack:
        i = stack.pop()
        reached[i] = True
        stack.extend(nodes[i].get("children", []))
    if not reached.all():
        start = int(np.flatnonzero(~reached)[0])
        seen, i = [], start
        while i not in seen:
            seen.append(i)
            i = int(parent[i])
        cyc = seen[seen.index(i):][::-1]
        chain = " -> ".join(f"nodes[{k}]" for k in cyc + [cyc[0]])
        raise doc.error(f"the node hierarchy has a cycle: {chain}")
    return parent


def pick_roots(doc: GltfDocument, job_scene: int, parent: np.ndarray,
               rec: StageRecord) -> tuple[int | None, list[int]]:
    scenes = doc.array("scenes")
    if job_scene >= 0:
        if job_scene >= len(scenes):
            raise doc.error(f"import.scene = {job_scene} but the file has {len(scenes)} "
                            f"scene{'s' if len(scenes) != 1 else ''}")
        idx: int | None = job_scene
    elif "scene" in doc.json:
        idx = int(doc.json["scene"])
    elif scenes:
        idx = 0
    else:
        idx = None
    if idx is None:
        roots = [int(i) for i in np.flatnonzero(parent < 0)]
        if roots:
            rec.warn("the file has no scenes; importing every root node")
        return None, roots
    roots = list(scenes[idx].get("nodes", []))
    w = f"scenes[{idx}]"
    if len(set(roots)) != len(roots):
        dup = next(r for r in roots if roots.count(r) > 1)
        raise doc.error(f"lists nodes[{dup}] twice", w)
    for r in roots:
        if parent[r] >= 0:
            raise doc.error(f"nodes[{r}] is listed as a root but is a child of "
                            f"nodes[{int(parent[r])}]", w)
    return idx, roots


# --------------------------------------------------------------------------- primitives
@dataclass
class _Prim:
    positions: np.ndarray  # (n, 3) local
    tris: np.ndarray  # (t, 3) into positions
    colors: np.ndarray | None  # (n, 4)
    uvs: np.ndarray | None  # (n, 2) bottom-left origin
    material: int  # glTF material index or -1


def faces_from_mode(idx: np.ndarray, mode: int) -> np.ndarray:
    """(t, 3) triangles from a TRIANGLES / TRIANGLE_STRIP / TRIANGLE_FAN index list (glTF 3.7.2.1)."""
    n = len(idx)
    if mode == 4:
        return idx[: n - n % 3].reshape(-1, 3)
    if n < 3:
        return np.zeros((0, 3), dtype=np.int64)
    i = np.arange(n - 2)
    if mode == 5:
        odd = i % 2
        return np.stack([idx[i], idx[i + 1 + odd], idx[i + 2 - odd]], axis=1)
    return np.stack([idx[i + 1], idx[i + 2], np.full(n - 2, idx[0])], axis=1)


def _texture_uv_info(doc: GltfDocument, mat_index: int) -> tuple[int, np.ndarray | None]:
    """(texCoord set, 2x3 affine KHR_texture_transform in glTF UV space or None)."""
    if mat_index < 0:
        return 0, None
    m = doc.array("materials")[mat_index]
    w = f"materials[{mat_index}].pbrMetallicRoughness.baseColorTexture"
    tex = m.get("pbrMetallicRoughness", {}).get("baseColorTexture")
    if not tex:
        return 0, None
    tc = doc.integer(tex, "texCoord", w, 0)
    tt = doc.extension(tex, "KHR_texture_transform", w)
    if tt is None:
        return tc, None
    wt = w + ".extensions.KHR_texture_transform"
    off = doc.numbers(tt, "offset", wt, 2, (0, 0))
    rot = doc.number(tt, "rotation", wt, 0.0)
    sc = doc.numbers(tt, "scale", wt, 2, (1, 1))
    tc = doc.integer(tt, "texCoord", wt, tc)
    c, s = math.cos(rot), math.sin(rot)
    # translation * rotation * scale; the rotation turns the UVs counter-clockwise as seen with
    # v pointing down (the extension's worked example maps [0,1]^2 to the lower-left quadrant)
    affine = np.array([[c * sc[0], s * sc[1], off[0]],
                       [-s * sc[0], c * sc[1], off[1]]])
    return tc, affine


def _has_texture(doc: GltfDocument, mat_index: int) -> bool:
    if mat_index < 0:
        return False
    return bool(doc.array("materials")[mat_index].get("pbrMetallicRoughness", {})
                .get("baseColorTexture"))


def read_primitive(doc: GltfDocument, mi: int, pi: int, prim: dict, strict: bool,
                   rec: StageRecord) -> _Prim | None:
    where = f"meshes[{mi}].primitives[{pi}]"
    mode = prim.get("mode", 4)
    attrs = prim.get("attributes", {})
    draco = doc.extension(prim, "KHR_draco_mesh_compression", where)
    decoded: dict[str, np.ndarray] = {}
    if draco is not None:
        decoded, idx = decode_draco(doc, prim, where)
        rec.details["draco_primitives"] = rec.details.get("draco_primitives", 0) + 1

    def attribute(sem: str, comps: tuple[int, ...], *, color: bool = False) -> np.ndarray | None:
        if sem in decoded:
            a = decoded[sem]
            if a.shape[1] not in comps:
                raise doc.error(f"decoded {sem} has {a.shape[1]} components", where)
            return a
        if sem not in attrs:
            return None
        ai = attrs[sem]
        if draco is not None and "bufferView" not in doc.array("accessors")[ai]:
            # the accessor only describes Draco output; reading it would give zeros
            raise doc.error(f"{sem} is not in the Draco data and accessors[{ai}] has no "
                            f"bufferView", where)
        ct = doc.accessor_info(ai)[0]
        return doc.floats(ai, f"{where}.attributes.{sem}", components=comps,
                          force_normalized=color and ct != 5126)

    pos = attribute("POSITION", (3,))
    if pos is None:
        rec.warn(f"{where}: no POSITION attribute; skipped")
        return None
    nv = len(pos)
    idx_acc = prim.get("indices")
    if draco is None:
        idx = (doc.indices(idx_acc, where) if idx_acc is not None
               else np.arange(nv, dtype=np.int64))
    else:
        mode = 4  # the Draco decoder always returns a triangle list
    if mode == 4 and len(idx) % 3:
        msg = f"{where}: {len(idx)} indices is not a multiple of 3 (TRIANGLES)"
        if strict:
            raise doc.error(msg.split(": ", 1)[1], where)
        rec.warn(msg + f"; dropped the last {len(idx) % 3}")
    tris = faces_from_mode(idx, mode)
    if mode in (5, 6) and len(idx) < 3:
        rec.warn(f"{where}: {MODE_NAMES[mode]} with {len(idx)} indices has no triangles")
    if len(tris):
        bad = tris.max(axis=1) >= nv
        if bad.any():
            v = int(tris[bad].max())
            acc = f"accessors[{idx_acc}]: " if idx_acc is not None and draco is None else ""
            msg = f"{acc}index {v} out of range ({nv} vertices)"
            if strict:
                raise doc.error(msg, where)
            rec.warn(f"{where}: {msg}; dropped {int(bad.sum())} of {len(tris)} triangles")
            tris = tris[~bad]
    colors = attribute("COLOR_0", (3, 4), color=True)
    if colors is not None:
        if len(colors) != nv:
            raise doc.error(f"COLOR_0 has {len(colors)} elements but POSITION has {nv}", where)
        if colors.shape[1] == 3:
            colors = np.concatenate([colors, np.ones((nv, 1))], axis=1)
        if (colors < 0).any() or (colors > 1).any():
            rec.warn(f"{where}: COLOR_0 values outside [0, 1] clamped")
            colors = np.clip(colors, 0.0, 1.0)
        # glTF vertex colours are linear; the scene holds display (sRGB-encoded) values
        colors = np.concatenate([linear_to_srgb(colors[:, :3]), colors[:, 3:]], axis=1)
    mat = prim.get("material", -1)
    tc, affine = _texture_uv_info(doc, mat)
    uvs = attribute(f"TEXCOORD_{tc}", (2,))
    if uvs is None and (tc != 0 or affine is not None or _has_texture(doc, mat)):
        rec.warn(f"{where}: its material's texture uses TEXCOORD_{tc}, which the primitive "
                 f"lacks")
    if uvs is not None:
        if len(uvs) != nv:
            raise doc.error(f"TEXCOORD_{tc} has {len(uvs)} elements but POSITION has {nv}", where)
        if affine is not None:
            uvs = uvs @ affine[:, :2].T + affine[:, 2]
        uvs = np.stack([uvs[:, 0], 1.0 - uvs[:, 1]], axis=1)
    if prim.get("targets"):
        rec.details.setdefault("ignored", []).append(f"{where}: morph targets")
    # keep only the vertices the triangles use (several primitives may share one big accessor)
    if len(tris):
        used, inv = np.unique(tris, return_inverse=True)
        tris = inv.reshape(-1, 3).astype(np.int64)
    else:
        used = np.zeros(0, dtype=np.int64)
    return _Prim(positions=pos[used], tris=tris,
                 colors=None if colors is None else colors[used],
                 uvs=None if uvs is None else uvs[used], material=int(mat))


# --------------------------------------------------------------------------- materials
def build_material(doc: GltfDocument, i: int, rec: StageRecord, names: set[str]) -> Material:
    m = doc.array("materials")[i]
    w = f"materials[{i}]"
    pbr = doc.dict_(m, "pbrMetallicRoughness", w)
    wp = w + ".pbrMetallicRoughness"
    color = list(doc.numbers(pbr, "baseColorFactor", wp, 4, (1, 1, 1, 1)))
    if any(c < 0 or c > 1 for c in color):
        rec.warn(f"{wp}.baseColorFactor {color} outside [0, 1]; clamped")
        color = [min(max(c, 0.0), 1.0) for c in color]
    # baseColorFactor is linear; the scene holds display (sRGB-encoded) values
    color = [float(c) for c in linear_to_srgb(np.array(color[:3]))] + [float(color[3])]
    mode = m.get("alphaMode", "OPAQUE")
    if mode not in ("OPAQUE", "MASK", "BLEND"):
        raise doc.error(f"alphaMode {mode!r} is not OPAQUE, MASK or BLEND", w)
    texture = data = source = None
    tex = pbr.get("baseColorTexture")
    if tex:
        t = doc.array("textures")[tex["index"]]
        src = t.get("source")
        if src is None:
            rec.warn(f"{w}: base colour texture textures[{tex['index']}] has no source image "
                     f"bake can read (extension-only images are not supported); ignored")
        else:
            ref = doc.image(src)
            if ref.missing:
                rec.warn(f"{w}: image file {ref.path} not found; texture ignored")
            else:
                texture, data = ref.path, ref.data
                if data is not None:  # embedded (a GLB buffer view or a data: URI)
                    source = f"{doc.path.name} images[{src}]" + (f", {ref.mime}" if ref.mime else "")
        wrap = _wrap_modes(doc, t)
        if wrap:  # said by load() if this material's UVs leave [0, 1]
            rec.details.setdefault("texture_wrap", {})[i] = f"{w}: textures[{tex['index']}] samples with {wrap}"
    if mode == "OPAQUE":
        color[3] = 1.0
    elif mode == "MASK" and texture is None and data is None:
        cutoff = doc.number(m, "alphaCutoff", w, 0.5)
        color[3] = 1.0 if color[3] >= cutoff else 0.0
    name = m.get("name") if isinstance(m.get("name"), str) and m.get("name") else f"material{i}"
    if name in names:
        name = f"{name}.{i}"
    names.add(name)
    ds = m.get("doubleSided", False)
    if not isinstance(ds, bool):
        raise doc.error("doubleSided must be true or false", w)
    return Material(name=name, color=(color[0], color[1], color[2], color[3]), texture=texture,
                    texture_data=data, double_sided=ds, texture_source=source)


_WRAP = {33071: "CLAMP_TO_EDGE", 33648: "MIRRORED_REPEAT", 10497: "REPEAT"}


def _wrap_modes(doc: GltfDocument, t: dict) -> str:
    """The texture's sampler's wrap modes other than REPEAT (glTF's default, and how bake samples
    every texture), as text; empty when it repeats both ways."""
    si = t.get("sampler")
    smps = doc.array("samplers")
    if not isinstance(si, int) or not 0 <= si < len(smps) or not isinstance(smps[si], dict):
        return ""
    other = sorted({_WRAP.get(smps[si].get(k, 10497), str(smps[si].get(k))) for k in ("wrapS", "wrapT")} - {"REPEAT"})
    return f"{' / '.join(other)} (samplers[{si}])" if other else ""


# --------------------------------------------------------------------------- lights
def _light_defs(doc: GltfDocument) -> list[dict]:
    ext = doc.extension(doc.json, "KHR_lights_punctual", "glTF")
    if ext is None:
        return []
    lights = ext.get("lights", [])
    if not isinstance(lights, list) or not all(isinstance(x, dict) for x in lights):
        raise doc.error("must be an array of objects", "extensions.KHR_lights_punctual.lights")
    return lights


def build_light(doc: GltfDocument, li: int, world: np.ndarray, node_name: str) -> Light:
    d = _light_defs(doc)[li]
    w = f"extensions.KHR_lights_punctual.lights[{li}]"
    kind = {"directional": "sun", "point": "point", "spot": "spot"}.get(d.get("type"))
    if kind is None:
        raise doc.error(f"type {d.get('type')!r} is not directional, point or spot", w)
    color = doc.numbers(d, "color", w, 3, (1, 1, 1))
    intensity = doc.number(d, "intensity", w, 1.0)
    if intensity < 0:
        raise doc.error(f"intensity must be >= 0, got {intensity}", w)
    rng = doc.number(d, "range", w, 0.0) if "range" in d else None
    if rng is not None and rng <= 0:
        raise doc.error(f"range must be > 0, got {rng}", w)
    inner, outer = 0.0, math.pi / 4
    if kind == "spot":
        spot = doc.dict_(d, "spot", w)
        inner = doc.number(spot, "innerConeAngle", w + ".spot", 0.0)
        outer = doc.number(spot, "outerConeAngle", w + ".spot", math.pi / 4)
        if not 0 <= inner < outer <= math.pi / 2 + 1e-9:
            raise doc.error(f"need 0 <= innerConeAngle < outerConeAngle <= pi/2, got {inner}, "
                            f"{outer}", w + ".spot")
    direction = position = None
    if kind in ("sun", "spot"):
        dvec = world[:3, :3] @ np.array([0.0, 0.0, -1.0])
        n = float(np.linalg.norm(dvec))
        if not n > 0 or not np.isfinite(n):
            raise doc.error(f"the node transform gives {w} no direction", node_name)
        direction = tuple(float(x) for x in dvec / n)
    if kind in ("point", "spot"):
        position = tuple(float(x) for x in world[:3, 3])
    name = d.get("name") if isinstance(d.get("name"), str) and d.get("name") else node_name
    return Light(kind=kind, color=color, intensity=intensity, position=position,
                 direction=direction, range=rng, inner_cone=inner, outer_cone=outer, name=name,
                 source=doc.path.name)


# --------------------------------------------------------------------------- extensions
def check_extensions(doc: GltfDocument, rec: StageRecord) -> None:
    required = list(dict.fromkeys(doc.json.get("extensionsRequired", [])))
    used = list(dict.fromkeys(doc.json.get("extensionsUsed", []) + required))
    for e in required:
        if e in MESHOPT_EXTENSIONS:
            raise doc.error(f"the file requires {e} (meshopt compression), which bake cannot "
                            f"decode; decompress it first (e.g. gltf-transform copy or gltfpack "
                            f"-noq)")
        if e == "KHR_draco_mesh_compression" and not _draco_available():
            raise doc.error("the file requires KHR_draco_mesh_compression; install DracoPy "
                            "(pip install DracoPy) to read Draco-compressed meshes")
        if e not in SUPPORTED_EXTENSIONS:
            raise doc.error(f"the file requires extension {e}, which bake does not support "
                            f"(supported: {', '.join(sorted(SUPPORTED_EXTENSIONS))})")
    ignored = [e for e in used if e not in SUPPORTED_EXTENSIONS]
    if ignored:
        rec.warn(f"ignored extensions: {', '.join(ignored)}")
    rec.details["extensions_used"] = used


# --------------------------------------------------------------------------- load
def load(job: ImportJob) -> tuple[Scene, StageRecord]:
    t0 = time.perf_counter()
    rec = StageRecord(name="import")
    doc = open_document(job.path, job.format)
    for w in doc.warnings:
        rec.warn(w)
    check_extensions(doc, rec)
    parent = check_hierarchy(doc)
    scene_idx, roots = pick_roots(doc, job.scene, parent, rec)
    nodes = doc.array("nodes")
    meshes = doc.array("meshes")
    light_defs = _light_defs(doc)

    # walk the hierarchy depth-first (children in file order): world matrices per node
    instances: list[tuple[int, np.ndarray]] = []
    stack: list[tuple[int, np.ndarray]] = [(r, np.eye(4)) for r in reversed(roots)]
    visited = 0
    lights: list[Light] = []
    skinned = 0
    while stack:
        ni, pm = stack.pop()
        visited += 1
        node = nodes[ni]
        w = f"nodes[{ni}]"
        with np.errstate(over="ignore", invalid="ignore"):
            world = pm @ node_matrix(doc, node, w, rec)
        if not np.isfinite(world).all():
            raise doc.error("world transform overflows to Inf/NaN", w)
        if node.get("mesh") is not None:
            instances.append((ni, world))
            skinned += "skin" in node
        lext = doc.extension(node, "KHR_lights_punctual", w)
        if lext is not None:
            li = doc.ref(lext, "light", w + ".extensions.KHR_lights_punctual",
                         "KHR_lights_punctual.lights", required=True, target=light_defs)
            nm = node.get("name") if isinstance(node.get("name"), str) else f"node{ni}"
            lights.append(build_light(doc, li, world, nm or f"node{ni}"))
        stack.extend((c, world) for c in reversed(node.get("children", [])))
    if skinned:
        rec.warn(f"{skinned} skinned mesh instance(s): skins are ignored, meshes are placed by "
                 f"their node transforms")

    prim_cache: dict[tuple[int, int], _Prim | None] = {}
    mode_counts: dict[str, int] = {}
    skipped_modes: dict[str, int] = {}
    parts_pos, parts_tri, parts_col, parts_uv, parts_mat = [], [], [], [], []
    offset = 0
    any_col = any_uv = False
    for ni, world in instances:
        mi = nodes[ni]["mesh"]
        with np.errstate(all="ignore"):  # only its sign is used; a huge scale may overflow it
            det = float(np.linalg.det(world[:3, :3]))
        for pi, prim in enumerate(meshes[mi]["primitives"]):
            mode = prim.get("mode", 4)
            mode_counts[MODE_NAMES[mode]] = mode_counts.get(MODE_NAMES[mode], 0) + 1
            if mode < 4:
                skipped_modes[MODE_NAMES[mode]] = skipped_modes.get(MODE_NAMES[mode], 0) + 1
                continue
            key = (mi, pi)
            if key not in prim_cache:
                prim_cache[key] = read_primitive(doc, mi, pi, prim, job.strict, rec)
            p = prim_cache[key]
            if p is None or not len(p.tris):
                continue
            with np.errstate(over="ignore", invalid="ignore"):
                pos = p.positions @ world[:3, :3].T + world[:3, 3]
            if not np.isfinite(pos).all():
                raise doc.error(f"nodes[{ni}] transform makes positions of "
                                f"meshes[{mi}].primitives[{pi}] overflow to Inf")
            if len(pos) and float(np.abs(pos).max()) > MAX_COORDINATE:
                raise doc.error(f"positions of meshes[{mi}].primitives[{pi}] placed by nodes[{ni}] reach "
                                f"{float(np.abs(pos).max()):.3g}, beyond +-{MAX_COORDINATE:g} (the range "
                                f"bake supports)")
            tris = p.tris[:, [0, 2, 1]] if det < 0 else p.tris
            parts_pos.append(pos)
            parts_tri.append(tris + offset)
            parts_col.append(p.colors)
            parts_uv.append(p.uvs)
            parts_mat.append(np.full(len(tris), p.material, dtype=np.int64))
            any_col |= p.colors is not None
            any_uv |= p.uvs is not None
            offset += len(pos)
    if skipped_modes:
        rec.warn("skipped primitives without faces: " + ", ".join(
            f"{n} {m}" for m, n in skipped_modes.items()))

    # materials: the ones used, in file order, then the default for primitives without one
    gl_mats = np.concatenate(parts_mat) if parts_mat else np.zeros(0, dtype=np.int64)
    used_mats = sorted(int(m) for m in np.unique(gl_mats) if m >= 0)
    names: set[str] = set()
    materials = [build_material(doc, m, rec, names) for m in used_mats]
    lut = np.zeros(len(doc.array("materials")) + 1, dtype=np.int64)
    for k, m in enumerate(used_mats):
        lut[m] = k
    if (gl_mats < 0).any() or not materials:
        lut[-1] = len(materials)
        materials.append(GLTF_DEFAULT_MATERIAL)
    poly_material = lut[gl_mats]

    V = offset
    positions = np.concatenate(parts_pos) if parts_pos else np.zeros((0, 3))
    tris = np.concatenate(parts_tri) if parts_tri else np.zeros((0, 3), dtype=np.int64)
    vcol = None
    if any_col:
        vcol = np.concatenate([c if c is not None else np.ones((len(p), 4))
                               for c, p in zip(parts_col, parts_pos)])
    poly_uvs = None
    if any_uv:
        uv = np.concatenate([u if u is not None else np.zeros((len(p), 2))
                             for u, p in zip(parts_uv, parts_pos)])
        poly_uvs = uv[tris.reshape(-1)]
    if not len(tris):
        rec.warn("the scene has no triangles" + (" (no scenes or nodes)" if not roots else ""))
    for gi, said in rec.details.pop("texture_wrap", {}).items():
        # a texture that clamps or mirrors: it matters where its UVs leave [0, 1]
        mine = np.repeat(gl_mats == gi, 3)
        if poly_uvs is not None and mine.any() and ((poly_uvs[mine] < 0) | (poly_uvs[mine] > 1)).any():
            rec.warn(f"{said}, but bake repeats every texture; its UVs leave [0, 1], so those triangles read "
                     "other texels than the file shows")

    source = SourceInfo(path=job.path, files_read=tuple(doc.files_read), format=doc.format,
                        files_missing=tuple(doc.files_missing))
    scene = Scene(positions=positions.astype(np.float64), poly_sizes=np.full(len(tris), 3, np.int64),
                  poly_indices=tris.reshape(-1).astype(np.int64), poly_material=poly_material,
                  poly_uvs=poly_uvs, vertex_colors=vcol, materials=tuple(materials),
                  lights=tuple(lights), source=source)

    textures = sum(1 for m in materials if m.texture is not None or m.texture_data is not None)
    rec.counts_out.update({
        "vertices": V, "polygons": len(tris), "triangles": len(tris),
        "nodes": visited, "mesh_instances": len(instances),
        "meshes": len({nodes[ni]["mesh"] for ni, _ in instances}),
        "primitives": sum(mode_counts.values()),
        **{f"primitives_{m}": n for m, n in sorted(mode_counts.items())},
        "materials": len(materials), "textures": textures, "lights": len(lights),
    })
    rec.details.update({
        "format": doc.format, "scene": scene_idx,
        "file": {k: len(doc.array(k)) for k in ("scenes", "nodes", "meshes", "materials",
                                                "textures", "images", "accessors", "buffers")}
        | {"lights": len(light_defs)},
    })
    if rec.details.get("ignored"):
        rec.details["ignored"] = sorted(set(rec.details["ignored"]))
    rec.seconds = time.perf_counter() - t0
    return scene, rec
