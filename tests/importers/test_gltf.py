"""glTF / GLB importer: corpus files against independent counts and trimesh's scene graph,
plus files generated here for modes, transforms, materials, lights and every error path."""

from __future__ import annotations

import base64
import json
import math
import struct
from pathlib import Path

import numpy as np
import pytest

from bake.config import ImportJob
from bake.colorspace import linear_to_srgb
from bake.errors import InputError
from bake.importers.gltf import load

# --------------------------------------------------------------------------- helpers
CT = {5120: np.int8, 5121: np.uint8, 5122: np.int16, 5123: np.uint16, 5125: np.uint32,
      5126: np.float32}


class G:
    """A tiny glTF writer for tests: one buffer, accessors appended from numpy arrays."""

    def __init__(self) -> None:
        self.blob = bytearray()
        self.j: dict = {"asset": {"version": "2.0"}, "buffers": [], "bufferViews": [],
                        "accessors": [], "meshes": [], "nodes": [],
                        "scenes": [{"nodes": []}], "scene": 0}

    def view(self, data: bytes, stride: int | None = None) -> int:
        self.blob += b"\0" * (-len(self.blob) % 4)
        bv = {"buffer": 0, "byteOffset": len(self.blob), "byteLength": len(data)}
        if stride:
            bv["byteStride"] = stride
        self.blob += data
        self.j["bufferViews"].append(bv)
        return len(self.j["bufferViews"]) - 1

    def acc(self, arr, ct: int = 5126, normalized: bool = False, **extra) -> int:
        a = np.ascontiguousarray(arr, dtype=CT[ct])
        typ = "SCALAR" if a.ndim == 1 else f"VEC{a.shape[1]}"
        acc = {"bufferView": self.view(a.tobytes()), "componentType": ct, "count": len(a),
               "type": typ, **extra}
        if normalized:
            acc["normalized"] = True
        self.j["accessors"].append(acc)
        return len(self.j["accessors"]) - 1

    def mesh(self, *prims: dict) -> int:
        self.j["meshes"].append({"primitives": list(prims)})
        return len(self.j["meshes"]) - 1

    def node(self, root: bool = True, **kw) -> int:
        self.j["nodes"].append(kw)
        i = len(self.j["nodes"]) - 1
        if root:
            self.j["scenes"][0]["nodes"].append(i)
        return i

    def doc(self) -> dict:
        d = json.loads(json.dumps(self.j))
        if self.blob:
            d["buffers"] = [{"byteLength": len(self.blob), "uri": "data:application/octet-stream;"
                             "base64," + base64.b64encode(bytes(self.blob)).decode()}]
        return d

    def write(self, path: Path, doc: dict | None = None) -> Path:
        path.write_text(json.dumps(self.doc() if doc is None else doc))
        return path

    def write_glb(self, path: Path) -> Path:
        d = self.doc()
        blob = bytes(self.blob) + b"\0" * (-len(self.blob) % 4)
        d["buffers"] = [{"byteLength": len(self.blob)}]
        js = json.dumps(d).encode()
        js += b" " * (-len(js) % 4)
        body = struct.pack("<II", len(js), 0x4E4F534A) + js + struct.pack("<II", len(blob), 0x004E4942) + blob
        path.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
        return path


def run(path: Path, **kw):
    scene, rec = load(ImportJob(path=Path(path), **kw))
    scene.validate()
    return scene, rec


def tri_positions(scene) -> np.ndarray:
    assert (scene.poly_sizes == 3).all()
    return scene.positions[scene.poly_indices.reshape(-1, 3)]


def canonical(tris: np.ndarray, decimals: int = 6) -> list:
    """Triangles (T, 3, 3) as a sorted list, each rotated so its smallest corner is first
    (rotation keeps the winding, so two lists are equal only if windings agree)."""
    out = []
    for t in np.round(np.asarray(tris, dtype=np.float64), decimals) + 0.0:
        k = min(range(3), key=lambda i: tuple(t[i]))
        out.append(tuple(np.roll(t, -k, axis=0).ravel()))
    return sorted(out)


def normals(tris: np.ndarray) -> np.ndarray:
    return np.cross(tris[:, 1] - tris[:, 0], tris[:, 2] - tris[:, 0])


def signed_volume(tris: np.ndarray) -> float:
    return float(np.einsum("ij,ij->i", tris[:, 0], np.cross(tris[:, 1], tris[:, 2])).sum() / 6)


def _err(path: Path, **kw) -> str:
    with pytest.raises(InputError) as e:
        load(ImportJob(path=Path(path), **kw))
    msg = str(e.value)
    assert "\n" not in msg
    assert Path(path).name in msg
    return msg


# --------------------------------------------------------------------------- corpus
GOOD = [
    ("gltf_primitive_modes", f"Mesh_PrimitiveMode_{i:02d}.gltf") for i in range(16)
] + [
    ("triangle_strips_scene", "mode5.gltf"), ("box_draco_glb", "Box.glb"),
    ("khr_multiple_scenes", "MultipleScenes.gltf"), ("nested_transforms", "nested.glb"),
    ("khr_simple_meshes", "SimpleMeshes.gltf"), ("gltf_empty_nodes", "empty_nodes.glb"),
    ("box_interleaved_glb", "BoxInterleaved.glb"), ("alpha_blend_mode_test", "AlphaBlendModeTest.glb"),
    ("duck_glb", "Duck.glb"), ("box_textured_glb", "BoxTextured.glb"),
    ("box_textured_gltf_separate", "BoxTextured.gltf"), ("cube_vertex_colors_glb", "cubevc.glb"),
    ("khr_box_vertex_colors", "BoxVertexColors.gltf"), ("subpass_scene", "subpass_scene_opaque.gltf"),
    ("test_scene_hierarchy", "TestScene.gltf"), ("boolean_csg_slivers", "boolean.glb"),
    ("three_story_building_noindices", "no_indices_3storybuilding.glb"),
    ("primitives_gltf", "primitives.gltf"), ("teapot_gltf", "teapot.gltf"),
    ("gltf_bad_normals", "BoxBadNormals.glb"),
]

BAD = [
    ("gltf_index_out_of_range", "IndexOutOfRange.gltf",
     ["meshes[0].primitives[0]", "index 255 out of range (24 vertices)"]),
    ("gltf_index_out_of_range", "AllIndicesOutOfRange.gltf",
     ["meshes[0].primitives[0]", "out of range (24 vertices)"]),
    ("tinygltf_bounds_checking", "integer-out-of-bounds.gltf",
     ["bufferViews[0]", "byteLength = 1e+300 is out of range"]),
    ("tinygltf_bounds_checking", "invalid-buffer-index.gltf",
     ["bufferViews[1]", "out of range: no buffers[1]"]),
    ("tinygltf_bounds_checking", "invalid-buffer-view-index.gltf",
     ["bufferViews[0]", "out of range: no buffers[0]"]),
    ("tinygltf_bounds_checking", "invalid-primitive-indices.gltf",
     ["bufferViews[0]", "out of range: no buffers[0]"]),
]


def independent_count(path: Path) -> int:
    """Triangles the default scene should hold, counted with pygltflib's object model:
    accessor counts per mode, per node instance, walking the default scene."""
    import pygltflib

    g = pygltflib.GLTF2().load(str(path))
    scene = g.scenes[g.scene if g.scene is not None else 0] if g.scenes else None
    roots = scene.nodes if scene else []
    total, stack = 0, list(roots)
    while stack:
        n = g.nodes[stack.pop()]
        stack.extend(n.children or [])
        if n.mesh is None:
            continue
        for p in g.meshes[n.mesh].primitives:
            k = g.accessors[p.indices].count if p.indices is not None else \
                g.accessors[p.attributes.POSITION].count
            mode = 4 if p.mode is None else p.mode
            total += k // 3 if mode == 4 else max(k - 2, 0) if mode in (5, 6) else 0
    return total


@pytest.mark.corpus
@pytest.mark.parametrize("entry,name", GOOD, ids=[f"{e}/{n}" for e, n in GOOD])
def test_corpus_triangle_count_matches_json(corpus, entry, name):
    path = corpus(entry, name)
    scene, rec = run(path)
    expected = independent_count(path)
    assert scene.n_polygons == expected == rec.counts_out["triangles"]
    assert np.isfinite(scene.positions).all()
    if expected:
        # faces only use real vertices, and no face collapsed to a point (Draco zero-fill)
        assert np.ptp(scene.positions, axis=0).max() > 0
    else:
        assert any("no triangles" in w for w in rec.warnings)


@pytest.mark.corpus
@pytest.mark.parametrize("entry,name,parts", BAD, ids=[f"{e}/{n}" for e, n, _ in BAD])
def test_corpus_bad_files_fail_clearly(corpus, entry, name, parts):
    msg = _err(corpus(entry, name))
    for p in parts:
        assert p in msg


@pytest.mark.corpus
def test_corpus_out_of_range_indices_dropped_when_not_strict(corpus):
    scene, rec = run(corpus("gltf_index_out_of_range", "IndexOutOfRange.gltf"), strict=False)
    assert 0 < scene.n_polygons < 12
    assert any("out of range" in w for w in rec.warnings)
    scene, rec = run(corpus("gltf_index_out_of_range", "AllIndicesOutOfRange.gltf"), strict=False)
    assert scene.n_polygons == 0


def _trimesh_world_triangles(path: Path) -> np.ndarray:
    import trimesh

    sc = trimesh.load(str(path), force="scene", process=False)
    parts = []
    for node in sc.graph.nodes_geometry:
        T, geom = sc.graph[node]
        m = sc.geometry[geom]
        parts.append(trimesh.transform_points(m.vertices, T)[m.faces])
    return np.concatenate(parts)


@pytest.mark.corpus
@pytest.mark.parametrize("entry,name", [("nested_transforms", "nested.glb"),
                                        ("test_scene_hierarchy", "TestScene.gltf"),
                                        ("duck_glb", "Duck.glb"),
                                        ("box_textured_glb", "BoxTextured.glb")])
def test_world_transforms_match_trimesh(corpus, entry, name):
    path = corpus(entry, name)
    scene, _ = run(path)
    ours = tri_positions(scene)
    ref = _trimesh_world_triangles(path)
    assert len(ours) == len(ref)
    # same triangles in world space, same winding (decimals relative to the model size)
    d = int(6 - math.ceil(math.log10(max(np.abs(ref).max(), 1e-9))))
    assert canonical(ours, d) == canonical(ref, d)


@pytest.mark.corpus
def test_instancing_duplicates_mesh(corpus):
    scene, rec = run(corpus("khr_simple_meshes", "SimpleMeshes.gltf"))
    t = tri_positions(scene)
    assert len(t) == 2 and rec.counts_out["mesh_instances"] == 2 and rec.counts_out["meshes"] == 1
    # node 1 is node 0 translated by (1, 0, 0)
    np.testing.assert_allclose(t[1], t[0] + [1, 0, 0])


@pytest.mark.corpus
def test_default_scene_is_honoured(corpus):
    path = corpus("khr_multiple_scenes", "MultipleScenes.gltf")
    scene, rec = run(path)  # "scene": 1 -> the square
    assert scene.n_polygons == 2 and rec.details["scene"] == 1
    scene0, rec0 = run(path, scene=0)  # override -> the triangle
    assert scene0.n_polygons == 1 and rec0.details["scene"] == 0
    assert "import.scene = 2" in _err(path, scene=2)


@pytest.mark.corpus
def test_draco_box_decodes_to_the_plain_box(corpus):
    draco, rec = run(corpus("box_draco_glb", "Box.glb"))
    plain, _ = run(corpus("box_interleaved_glb", "BoxInterleaved.glb"))
    assert rec.details["draco_primitives"] == 1
    assert canonical(tri_positions(draco)) == canonical(tri_positions(plain))
    # glTF factors are linear; the scene holds sRGB-encoded display values
    assert draco.materials[0].color == (float(linear_to_srgb(0.800000011920929)), 0.0, 0.0, 1.0)


@pytest.mark.corpus
def test_box_textured_uvs_match_trimesh(corpus):
    """Per-corner UVs with v flipped: trimesh also flips v, so its uv[faces] is the reference."""
    import trimesh

    for name, entry in (("BoxTextured.glb", "box_textured_glb"),
                        ("BoxTextured.gltf", "box_textured_gltf_separate")):
        path = corpus(entry, name)
        scene, _ = run(path)
        sc = trimesh.load(str(path), force="scene", process=False)
        (node,) = sc.graph.nodes_geometry
        T, geom = sc.graph[node]
        m = sc.geometry[geom]
        ref = np.concatenate([trimesh.transform_points(m.vertices, T)[m.faces],
                              np.pad(m.visual.uv[m.faces], ((0, 0), (0, 0), (0, 1)))], axis=2)
        ours = np.concatenate([tri_positions(scene),
                               np.pad(scene.poly_uvs.reshape(-1, 3, 2), ((0, 0), (0, 0), (0, 1)))],
                              axis=2)
        key = lambda a: sorted(tuple(np.round(r, 6).ravel()) for r in a)  # noqa: E731
        assert key(ours) == key(ref)
    # and against the raw TEXCOORD_0 floats of the separate file's .bin: v -> 1 - v
    j = json.loads(path.read_text())
    a = j["accessors"][j["meshes"][0]["primitives"][0]["attributes"]["TEXCOORD_0"]]
    bv = j["bufferViews"][a["bufferView"]]
    assert "byteStride" not in bv or bv["byteStride"] == 8
    raw = np.frombuffer((path.parent / j["buffers"][bv["buffer"]]["uri"]).read_bytes(), "<f4",
                        2 * a["count"], bv.get("byteOffset", 0) + a.get("byteOffset", 0))
    raw = raw.reshape(-1, 2).astype(np.float64)
    assert {tuple(x) for x in np.round(scene.poly_uvs, 6)} == \
        {tuple(x) for x in np.round(np.c_[raw[:, 0], 1 - raw[:, 1]], 6)}


@pytest.mark.corpus
def test_box_textured_texture_sources(corpus):
    glb, rec = run(corpus("box_textured_glb", "BoxTextured.glb"))
    (mat,) = glb.materials
    assert mat.texture is None and mat.texture_data[:8] == b"\x89PNG\r\n\x1a\n"
    assert rec.counts_out["textures"] == 1 and glb.source.format == "glb"
    path = corpus("box_textured_gltf_separate", "BoxTextured.gltf")
    sep, _ = run(path)
    (mat,) = sep.materials
    png = path.parent / "CesiumLogoFlat.png"
    assert mat.texture == png.absolute() and mat.texture.is_absolute() and mat.texture_data is None
    assert sep.source.format == "gltf"
    assert set(sep.source.files_read) == {path, path.parent / "BoxTextured0.bin", png}
    # the embedded bytes are exactly the image's bufferView in the GLB binary chunk
    import pygltflib

    gl = pygltflib.GLTF2().load(str(corpus("box_textured_glb", "BoxTextured.glb")))
    bv = gl.bufferViews[gl.images[0].bufferView]
    blob = gl.binary_blob()
    assert glb.materials[0].texture_data == blob[bv.byteOffset:bv.byteOffset + bv.byteLength]


@pytest.mark.corpus
def test_box_vertex_colors_match_raw_accessor(corpus):
    path = corpus("khr_box_vertex_colors", "BoxVertexColors.gltf")
    scene, _ = run(path)
    j = json.loads(path.read_text())
    (prim,) = j["meshes"][0]["primitives"]

    def raw(ai):  # an independent decoder good enough for this tightly packed float file
        a = j["accessors"][ai]
        bv = j["bufferViews"][a["bufferView"]]
        blob = base64.b64decode(j["buffers"][bv["buffer"]]["uri"].split(",", 1)[1])
        n = {"VEC3": 3, "VEC4": 4}[a["type"]]
        start = bv.get("byteOffset", 0) + a.get("byteOffset", 0)
        return np.frombuffer(blob, "<f4", a["count"] * n, start).reshape(-1, n).astype(np.float64)

    col = raw(prim["attributes"]["COLOR_0"])
    pos = raw(prim["attributes"]["POSITION"])
    assert scene.vertex_colors.shape == (len(pos), 4)
    # match every imported vertex to its source vertex by position (the node is identity)
    ours = {tuple(np.round(p, 6)) + tuple(np.round(c, 6)) for p, c in
            zip(scene.positions, scene.vertex_colors)}
    col = np.c_[linear_to_srgb(col[:, :3]), col[:, 3:]]  # linear in the file, sRGB in the scene
    ref = {tuple(np.round(p, 6)) + tuple(np.round(c, 6)) + ((1.0,) if len(c) == 3 else ())
           for p, c in zip(pos, col)}
    assert ours == ref


@pytest.mark.corpus
def test_cube_vertex_colors_glb(corpus):
    import trimesh

    path = corpus("cube_vertex_colors_glb", "cubevc.glb")
    scene, _ = run(path)
    m = next(iter(trimesh.load(str(path), force="scene", process=False).geometry.values()))
    ref = np.asarray(m.visual.vertex_colors, dtype=np.float64) / 255.0  # uint8 in trimesh, linear
    ref[:, :3] = linear_to_srgb(ref[:, :3])
    assert scene.vertex_colors.shape == (len(m.vertices), 4)
    order_ours = np.lexsort(np.round(scene.positions, 6).T[::-1])
    order_ref = np.lexsort(np.round(m.vertices, 6).T[::-1])
    np.testing.assert_allclose(scene.positions[order_ours], m.vertices[order_ref], atol=1e-6)
    # compare colours of coincident vertices as sets (duplicated positions may reorder)
    a = sorted(map(tuple, np.round(np.c_[scene.positions, scene.vertex_colors], 2)))
    b = sorted(map(tuple, np.round(np.c_[m.vertices, ref], 2)))
    np.testing.assert_allclose(np.array(a), np.array(b), atol=1 / 255 + 1e-9)


@pytest.mark.corpus
def test_exact_factor_and_alpha_modes(corpus):
    scene, _ = run(corpus("nested_transforms", "nested.glb"))
    (mat,) = scene.materials
    g = float(linear_to_srgb(0.800000011920929))
    assert mat.color == (g, g, g, 1.0)
    assert mat.double_sided is True
    scene, rec = run(corpus("alpha_blend_mode_test", "AlphaBlendModeTest.glb"))
    j_names = {m.name for m in scene.materials}
    assert {"MatCutoff25", "MatBlend", "MatBed"} <= j_names
    assert all(m.texture_data is not None for m in scene.materials)
    assert rec.counts_out["textures"] == len(scene.materials)


# --------------------------------------------------------------------------- generated: modes
def _polygon(n: int) -> np.ndarray:
    a = np.linspace(0, 2 * np.pi, n, endpoint=False)
    # float32-exact, so float64 expectations equal what the file stores
    return np.c_[np.cos(a), np.sin(a), np.zeros(n)].astype(np.float32).astype(np.float64)


def _strip_reference(seq: list[int]) -> list[tuple[int, int, int]]:
    # the classic GL rule: even triangles (i, i+1, i+2), odd ones (i+1, i, i+2)
    return [(seq[i], seq[i + 1], seq[i + 2]) if i % 2 == 0 else (seq[i + 1], seq[i], seq[i + 2])
            for i in range(len(seq) - 2)]


def _fan_reference(seq: list[int]) -> list[tuple[int, int, int]]:
    return [(seq[0], seq[i], seq[i + 1]) for i in range(1, len(seq) - 1)]


@pytest.mark.parametrize("ict", [None, 5121, 5123, 5125])
def test_strip_and_fan_match_reference_and_triangles_winding(tmp_path, ict):
    # a zig-zag strip of quads in the z=0 plane, and a convex polygon as a fan
    strip_pts = np.array([[x // 2, 1 - x % 2, 0] for x in range(8)], dtype=float)  # CCW
    strip_seq = list(range(8))
    fan_pts = _polygon(7)
    fan_seq = list(range(7))
    # shuffle the vertex order in the buffer so indexed reads are exercised
    perm = np.array([3, 0, 6, 1, 5, 2, 4, 7]) if ict else np.arange(8)
    g = G()
    prims = []
    for pts, seq, mode, ref in ((strip_pts, strip_seq, 5, _strip_reference),
                                (fan_pts, fan_seq, 6, _fan_reference)):
        n = len(pts)
        p = perm[perm < n] if ict else np.arange(n)
        stored = pts[p]  # stored[k] = pts[p[k]]
        inv = np.argsort(p)  # original vertex v lives at stored[inv[v]]
        prim = {"attributes": {"POSITION": g.acc(stored)}, "mode": mode}
        if ict:
            prim["indices"] = g.acc(inv[seq], ict)
        prims.append((prim, pts, ref(seq)))
        # the same triangles written as a TRIANGLES primitive
        tri_prim = {"attributes": {"POSITION": g.acc(pts)},
                    "indices": g.acc(np.array(ref(seq)).ravel(), 5125)}
        prims.append((tri_prim, pts, ref(seq)))
    g.node(mesh=g.mesh(*[p for p, _, _ in prims]))
    scene, rec = run(g.write(tmp_path / "modes.gltf"))
    got = tri_positions(scene)
    expected = np.concatenate([pts[np.array(r)] for _, pts, r in prims])
    assert canonical(got) == canonical(expected)
    # all faces of these planar, consistently wound shapes point the same way (+z)
    assert (normals(got)[:, 2] > 0).all()
    assert rec.counts_out["primitives_triangle_strip"] == 1
    assert rec.counts_out["primitives_triangle_fan"] == 1
    assert rec.counts_out["primitives_triangles"] == 2
    assert scene.n_polygons == 2 * (6 + 5)


def test_points_and_lines_are_skipped_with_warning(tmp_path):
    g = G()
    pos = g.acc(_polygon(6))
    prims = [{"attributes": {"POSITION": pos}, "mode": m} for m in range(7)]
    g.node(mesh=g.mesh(*prims))
    scene, rec = run(g.write(tmp_path / "all.gltf"))
    assert scene.n_polygons == 2 + 4 + 4  # triangles 6 // 3, strip 6 - 2, fan 6 - 2
    assert rec.counts_out["primitives"] == 7
    (w,) = [w for w in rec.warnings if "skipped" in w]
    for name in ("points", "lines", "line_loop", "line_strip"):
        assert name in w


def test_triangles_not_multiple_of_three(tmp_path):
    g = G()
    g.node(mesh=g.mesh({"attributes": {"POSITION": g.acc(_polygon(4))},
                        "indices": g.acc([0, 1, 2, 0, 2], 5123)}))
    p = g.write(tmp_path / "short.gltf")
    assert "not a multiple of 3" in _err(p)
    scene, rec = run(p, strict=False)
    assert scene.n_polygons == 1 and any("multiple of 3" in w for w in rec.warnings)


# --------------------------------------------------------------------------- generated: transforms
def _tetra(g: G) -> int:
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])  # outward
    return g.mesh({"attributes": {"POSITION": g.acc(pts)}, "indices": g.acc(faces.ravel(), 5123)})


def _trs(t=(0, 0, 0), r=(0, 0, 0, 1), s=(1, 1, 1)) -> np.ndarray:
    x, y, z, w = r
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    M = np.eye(4)
    M[:3, :3] = R @ np.diag(s)
    M[:3, 3] = t
    return M


def test_nested_trs_and_matrix_and_mirroring(tmp_path):
    g = G()
    mesh = _tetra(g)
    h = math.sqrt(0.5)
    # parent: TRS; child: matrix (column-major) with a mirror; grandchild: plain instance
    child_m = _trs(t=(0, 2, 0), s=(-1, 1, 1))
    grand = g.node(root=False, mesh=mesh, translation=[0, 0, 5])
    child = g.node(root=False, mesh=mesh, matrix=child_m.T.ravel().tolist(), children=[grand])
    g.node(mesh=mesh, translation=[1, 2, 3], rotation=[0, 0, h, h], scale=[2, 2, 2],
           children=[child])
    scene, rec = run(g.write(tmp_path / "nest.gltf"))
    t = tri_positions(scene).reshape(3, 4, 3, 3)
    parent = _trs((1, 2, 3), (0, 0, h, h), (2, 2, 2))
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]], dtype=float)
    faces = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    for k, M in enumerate([parent, parent @ child_m, parent @ child_m @ _trs(t=(0, 0, 5))]):
        world = pts @ M[:3, :3].T + M[:3, 3]
        expected = world[faces]
        if np.linalg.det(M[:3, :3]) < 0:
            expected = expected[:, [0, 2, 1]]
        assert canonical(t[k]) == canonical(expected)
        # the mirrored instances stay outward-facing: positive signed volume
        assert signed_volume(t[k]) > 0
    assert rec.counts_out["nodes"] == 3 and rec.counts_out["mesh_instances"] == 3


@pytest.mark.parametrize("children,roots,needle", [
    ({0: [1], 1: [0]}, [], "cycle"),
    ({0: [1], 1: [2], 2: [1]}, [0], "two parents"),
    ({0: [0]}, [], "own child"),
    ({0: [2], 1: [2]}, [0, 1], "two parents"),
    ({0: [1, 1]}, [0], "twice"),
    ({0: [1]}, [0, 1], "listed as a root but is a child"),
])
def test_bad_hierarchies_fail(tmp_path, children, roots, needle):
    g = G()
    mesh = _tetra(g)
    for i in range(3):
        g.node(root=False, mesh=mesh, **({"children": children[i]} if i in children else {}))
    g.j["scenes"][0]["nodes"] = roots
    assert needle in _err(g.write(tmp_path / "h.gltf"))


def test_no_scenes_imports_all_roots(tmp_path):
    g = G()
    mesh = _tetra(g)
    g.node(root=False, mesh=mesh, children=[1])
    g.node(root=False, mesh=mesh)
    g.node(root=False, mesh=mesh)
    d = g.doc()
    del d["scenes"], d["scene"]
    scene, rec = run(g.write(tmp_path / "noscene.gltf", d))
    assert scene.n_polygons == 12 and rec.details["scene"] is None
    assert any("no scenes" in w for w in rec.warnings)


def test_deep_hierarchy_is_iterative(tmp_path):
    g = G()
    mesh = _tetra(g)
    n = 3000
    for i in range(n):
        g.node(root=i == 0, translation=[1, 0, 0], **({"children": [i + 1]} if i < n - 1 else
                                                      {"mesh": mesh}))
    scene, _ = run(g.write(tmp_path / "deep.gltf"))
    assert scene.positions[:, 0].min() == pytest.approx(n)


# --------------------------------------------------------------------------- generated: data
def test_interleaved_sparse_and_normalized(tmp_path):
    g = G()
    pos = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0]], dtype=np.float32)
    uv = np.array([[0, 0], [1, 0], [0, 1], [1, 1]], dtype=np.float32)
    inter = np.zeros(4, dtype=[("p", "<f4", 3), ("u", "<f4", 2), ("pad", "<f4", 1)])
    inter["p"], inter["u"] = pos, uv
    bv = g.view(inter.tobytes(), stride=24)
    g.j["accessors"] += [
        {"bufferView": bv, "componentType": 5126, "count": 4, "type": "VEC3"},
        {"bufferView": bv, "byteOffset": 12, "componentType": 5126, "count": 4, "type": "VEC2"},
    ]
    # sparse: vertex 3 of the interleaved positions moved to z = 7
    si = g.view(np.array([3], np.uint16).tobytes())
    sv = g.view(np.array([[1, 1, 7]], np.float32).tobytes())
    g.j["accessors"].append({"bufferView": bv, "componentType": 5126, "count": 4, "type": "VEC3",
                             "sparse": {"count": 1, "indices": {"bufferView": si, "componentType": 5123},
                                        "values": {"bufferView": sv}}})
    # normalised ubyte colours (VEC3) and normalised short positions (quantization)
    col = g.acc(np.array([[255, 0, 51], [0, 255, 0], [0, 0, 255], [255, 255, 255]]), 5121, True)
    qpos = g.acc(np.array([[0, 0, 0], [32767, 0, 0], [0, -32767, 0], [-32768, 0, 0]]), 5122, True)
    idx = g.acc([0, 1, 2, 2, 1, 3], 5123)
    g.node(mesh=g.mesh({"attributes": {"POSITION": 2, "TEXCOORD_0": 1, "COLOR_0": col}, "indices": idx},
                       {"attributes": {"POSITION": qpos}, "indices": g.acc([0, 1, 2, 0, 2, 3], 5121)}))
    scene, _ = run(g.write(tmp_path / "data.gltf"))
    t = tri_positions(scene)
    np.testing.assert_allclose(t[0], pos[[0, 1, 2]])
    np.testing.assert_allclose(t[1], [[0, 1, 0], [1, 0, 0], [1, 1, 7]])
    uvs = scene.poly_uvs.reshape(-1, 3, 2)
    np.testing.assert_allclose(uvs[0], [[0, 1], [1, 1], [0, 0]])  # v flipped
    np.testing.assert_allclose(uvs[2:], 0)  # the second primitive has no UVs
    vc = scene.vertex_colors[scene.poly_indices.reshape(-1, 3)]
    np.testing.assert_allclose(vc[0, 0], [1, 0, linear_to_srgb(0.2), 1])
    np.testing.assert_allclose(vc[2:], 1)  # no COLOR_0 -> white
    np.testing.assert_allclose(t[2:].reshape(-1, 3)[[0, 1, 2, 5]],
                               [[0, 0, 0], [1, 0, 0], [0, -1, 0], [-1, 0, 0]])


def test_glb_round_trip_and_truncation(tmp_path):
    g = G()
    g.node(mesh=_tetra(g))
    p = g.write_glb(tmp_path / "t.glb")
    scene, rec = run(p)
    assert scene.n_polygons == 4 and scene.source.format == "glb"
    data = p.read_bytes()
    for cut in (0, 3, 11, 12, 19, 30, len(data) // 2, len(data) - 4):
        q = tmp_path / f"cut{cut}.glb"
        q.write_bytes(data[:cut])
        msg = _err(q)
        assert "GLB" in msg or "JSON" in msg or "byteLength" in msg
    bad = tmp_path / "magic.glb"
    bad.write_bytes(b"gLTF" + data[4:])
    assert "magic" in _err(bad)
    v1 = tmp_path / "v1.glb"
    v1.write_bytes(data[:4] + struct.pack("<I", 1) + data[8:])
    assert "version 1" in _err(v1)
    # a BIN chunk shorter than the buffer's byteLength
    short = bytearray(data)
    short[8:12] = struct.pack("<I", len(data) - 4)
    blen_pos = len(data) - (len(g.blob) + (-len(g.blob) % 4)) - 8
    short[blen_pos:blen_pos + 4] = struct.pack("<I", len(g.blob) + (-len(g.blob) % 4) - 4)
    q = tmp_path / "shortbin.glb"
    q.write_bytes(bytes(short[:-4]))
    assert "buffers[0]" in _err(q)


def test_bad_json(tmp_path):
    p = tmp_path / "bad.gltf"
    p.write_text('{"asset": {"version": "2.0"},\n "nodes": [}')
    assert "line 2" in _err(p)
    p.write_text("[1, 2]")
    assert "JSON object" in _err(p)
    p.write_text('{"asset": {"version": "1.0"}}')
    assert "version" in _err(p)


def test_nan_inf_fail_naming_the_accessor(tmp_path):
    g = G()
    pts = np.array([[0, 0, 0], [1, 0, 0], [0, np.nan, 0]])
    g.node(mesh=g.mesh({"attributes": {"POSITION": g.acc(pts)}}))
    msg = _err(g.write(tmp_path / "nan.gltf"))
    assert "accessors[0]" in msg and "NaN/Inf" in msg and "POSITION" in msg
    g = G()
    uv = np.array([[0, 0], [np.inf, 0], [0, 1]])
    g.node(mesh=g.mesh({"attributes": {"POSITION": g.acc(_polygon(3)), "TEXCOORD_0": g.acc(uv)}}))
    assert "accessors[1]" in _err(g.write(tmp_path / "inf.gltf"))
    g = G()
    g.node(mesh=_tetra(g), matrix=[1, 0, 0, 0, 0, 1, 0, 0, 0, 0, 1, 0, 0, float("nan"), 0, 1])
    assert "nodes[0]" in _err(g.write(tmp_path / "nanm.gltf"))
    # overflow: a huge scale on float32-max positions
    g = G()
    big = np.array([[3e38, 0, 0], [0, 3e38, 0], [0, 0, 3e38]])
    g.node(mesh=g.mesh({"attributes": {"POSITION": g.acc(big)}}), scale=[1e300, 1, 1])
    assert "Inf" in _err(g.write(tmp_path / "ovf.gltf"))


def test_out_of_range_references(tmp_path):
    def make(mutate):
        g = G()
        g.node(mesh=g.mesh({"attributes": {"POSITION": g.acc(_polygon(24))},
                            "indices": g.acc([0, 1, 40], 5123)}))
        d = g.doc()
        mutate(d)
        return g.write(tmp_path / "r.gltf", d)

    msg = _err(make(lambda d: None))
    assert "meshes[0].primitives[0]: accessors[1]: index 40 out of range (24 vertices)" in msg
    scene, rec = run(make(lambda d: None), strict=False)
    assert scene.n_polygons == 0 and any("index 40" in w for w in rec.warnings)

    def set_(path, value):
        def f(d):
            obj = d
            for k in path[:-1]:
                obj = obj[k]
            obj[path[-1]] = value
        return f

    cases = [
        (("meshes", 0, "primitives", 0, "indices"), 9, "meshes[0].primitives[0]"),
        (("meshes", 0, "primitives", 0, "attributes", "POSITION"), -1, "meshes[0].primitives[0].attributes"),
        (("meshes", 0, "primitives", 0, "material"), 0, "no materials[0]"),
        (("accessors", 0, "bufferView"), 7, "accessors[0]"),
        (("accessors", 0, "count"), 25, "accessors[0]: 25 elements need"),
        (("accessors", 0, "byteOffset"), 8, "accessors[0]"),
        (("accessors", 0, "componentType"), 5124, "componentType"),
        (("accessors", 1, "count"), 0, "accessors[1]: count = 0 is out of range"),
        (("bufferViews", 0, "buffer"), 3, "bufferViews[0]"),
        (("bufferViews", 1, "byteOffset"), 10 ** 6, "bufferViews[1]"),
        (("buffers", 0, "byteLength"), 10 ** 6, "buffers[0]"),
        (("nodes", 0, "mesh"), 4, "nodes[0]"),
        (("nodes", 0, "children"), [5], "nodes[0]"),
        (("scenes", 0, "nodes"), [2], "scenes[0]"),
        (("scene",), 1, "no scenes[1]"),
        (("meshes", 0, "primitives", 0, "mode"), 9, "mode 9"),
    ]
    for path, value, needle in cases:
        assert needle in _err(make(set_(path, value))), (path, value)
    # integral JSON floats are integers (JSON Schema), fractional ones are not
    d_ok = set_(("meshes", 0, "primitives", 0, "indices"), 1.0)
    with pytest.raises(InputError, match="index 40 out of range"):
        load(ImportJob(path=make(d_ok)))
    assert "must be an index" in _err(make(set_(("meshes", 0, "primitives", 0, "indices"), 1.5)))


def test_uris_must_stay_in_the_model_folder(tmp_path):
    model_dir = tmp_path / "model"
    (model_dir / "sub").mkdir(parents=True)
    g = G()
    g.node(mesh=_tetra(g))
    blob = bytes(g.blob)
    (tmp_path / "x.bin").write_bytes(blob)  # outside: must never be read
    (model_dir / "sub" / "in side.bin").write_bytes(blob)
    ok = g.doc()
    ok["buffers"] = [{"byteLength": len(blob), "uri": "sub/in%20side.bin"}]
    scene, _ = run(g.write(model_dir / "ok.gltf", ok))
    assert scene.n_polygons == 4
    assert model_dir / "sub" / "in side.bin" in scene.source.files_read
    for uri, needle in [("../x.bin", "outside"), ("sub/../../x.bin", "outside"),
                        ("%2E%2E/x.bin", "outside"), (str(tmp_path / "x.bin"), "absolute"),
                        ("file:///etc/passwd", "URL"), ("http://example.com/x.bin", "URL"),
                        ("missing.bin", "not found")]:
        d = g.doc()
        d["buffers"] = [{"byteLength": len(blob), "uri": uri}]
        msg = _err(g.write(model_dir / "esc.gltf", d))
        assert "buffers[0]" in msg and needle in msg, uri
    # images are checked too, even when no material uses them
    d = g.doc()
    d["images"] = [{"uri": "../x.png"}]
    assert "images[0]" in _err(g.write(model_dir / "img.gltf", d))
    # a symlink inside the folder that points outside is refused
    (model_dir / "link.bin").symlink_to(tmp_path / "x.bin")
    d = g.doc()
    d["buffers"] = [{"byteLength": len(blob), "uri": "link.bin"}]
    assert "outside" in _err(g.write(model_dir / "link.gltf", d))


# --------------------------------------------------------------------------- generated: materials
PNG = b"\x89PNG\r\n\x1a\n" + b"\0" * 16  # bytes are passed through, not decoded here


def test_materials_textures_and_defaults(tmp_path):
    g = G()
    pos = g.acc(_polygon(3))
    uv = g.acc(np.array([[0, 0], [1, 0], [0, 1]]))
    img_view = g.view(PNG)
    (tmp_path / "tex.png").write_bytes(PNG)
    g.j["images"] = [{"uri": "tex.png"}, {"bufferView": img_view, "mimeType": "image/png"},
                     {"uri": "data:image/png;base64," + base64.b64encode(PNG).decode()},
                     {"uri": "gone.png"}]
    g.j["textures"] = [{"source": i} for i in range(4)]
    f = [0.1, 0.2, 0.30000000000000004, 0.4]
    g.j["materials"] = [
        {"name": "ext", "pbrMetallicRoughness": {"baseColorFactor": f, "baseColorTexture": {"index": 0}},
         "alphaMode": "BLEND", "doubleSided": True},
        {"name": "glb", "pbrMetallicRoughness": {"baseColorTexture": {"index": 1}}},
        {"name": "data", "pbrMetallicRoughness": {"baseColorFactor": f, "baseColorTexture": {"index": 2}}},
        {"name": "unused"},
        {"name": "mask", "pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 0.3]},
         "alphaMode": "MASK", "alphaCutoff": 0.25},
        {"name": "mask", "pbrMetallicRoughness": {"baseColorFactor": [1, 0, 0, 0.2]}, "alphaMode": "MASK"},
        {"pbrMetallicRoughness": {"baseColorTexture": {"index": 3}}},
    ]
    prims = [{"attributes": {"POSITION": pos, "TEXCOORD_0": uv}, "material": m} for m in (0, 1, 2, 4, 5, 6)]
    prims.append({"attributes": {"POSITION": pos}})
    g.node(mesh=g.mesh(*prims))
    scene, rec = run(g.write(tmp_path / "m.gltf"))
    names = [m.name for m in scene.materials]
    assert names == ["ext", "glb", "data", "mask", "mask.5", "material6", "default"]
    ext, glb, data, m1, m2, gone, default = scene.materials
    # BLEND keeps alpha exactly; rgb converted from linear to sRGB
    np.testing.assert_array_equal(ext.color, [*linear_to_srgb(np.array([0.1, 0.2, 0.30000000000000004])), 0.4])
    assert ext.texture == (tmp_path / "tex.png").absolute() and ext.double_sided
    assert glb.texture_data == PNG and glb.texture is None and not glb.double_sided
    np.testing.assert_array_equal(data.color, [*linear_to_srgb(np.array([0.1, 0.2, 0.30000000000000004])), 1.0])  # OPAQUE -> alpha 1
    assert data.texture_data == PNG
    assert m1.color == (1, 0, 0, 1.0) and m2.color == (1, 0, 0, 0.0)  # MASK by cutoff
    assert gone.texture is None and any("gone.png" in w for w in rec.warnings)
    # glTF's default material: white (baseColorFactor [1, 1, 1, 1]), single-sided, not the OBJ grey
    assert default.name == "default" and default.color == (1.0, 1.0, 1.0, 1.0) and not default.double_sided
    np.testing.assert_array_equal(scene.poly_material, np.arange(7))
    assert rec.counts_out["materials"] == 7 and rec.counts_out["textures"] == 3
    assert (tmp_path / "tex.png") in scene.source.files_read


def test_texture_transform_and_texcoord_set(tmp_path):
    g = G()
    pos = g.acc(_polygon(4))
    corners = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float)
    uv0 = g.acc(np.full((4, 2), 0.5))
    uv1 = g.acc(corners)
    g.j["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(PNG).decode()}]
    g.j["textures"] = [{"source": 0}]
    # the extension's own example: "only the lower left quadrant ... rotated clockwise 90 deg"
    tt = {"offset": [0, 1], "rotation": math.pi / 2, "scale": [0.5, 0.5], "texCoord": 1}
    g.j["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {
        "index": 0, "texCoord": 0, "extensions": {"KHR_texture_transform": tt}}}}]
    g.j["extensionsUsed"] = ["KHR_texture_transform"]
    g.node(mesh=g.mesh({"attributes": {"POSITION": pos, "TEXCOORD_0": uv0, "TEXCOORD_1": uv1},
                        "indices": g.acc([0, 1, 2, 0, 2, 3], 5123), "material": 0}))
    scene, rec = run(g.write(tmp_path / "tt.gltf"))
    uv = scene.poly_uvs
    # lower-left quadrant of the image in the bottom-left-origin convention: u, v in [0, 0.5]
    assert uv.min() > -1e-12 and uv.max() < 0.5 + 1e-12
    # the quadrant is covered (all four of its corners are reached), not a sliver
    got = {tuple(np.round(x, 9) + 0.0) for x in uv}
    assert got == {(0.0, 0.0), (0.5, 0.0), (0.5, 0.5), (0.0, 0.5)}
    # rotated clockwise: glTF uv (1, 0) (top-right of the image) lands on the top-left of the
    # quadrant, i.e. (0, 0.5) bottom-left-origin
    idx = scene.poly_indices
    v_of_corner1 = np.flatnonzero(np.isclose(scene.positions[idx], _polygon(4)[1]).all(axis=1))
    np.testing.assert_allclose(uv[v_of_corner1[0]], [0.0, 0.5], atol=1e-12)
    assert not rec.warnings


@pytest.mark.parametrize("wrap,scale,said", [(None, 1.0, False), (33071, 1.0, False), (33071, 2.0, True),
                                              (33648, 3.0, True), (10497, 3.0, False)])
def test_a_clamping_sampler_is_said_where_the_uvs_leave_the_image(tmp_path, wrap, scale, said):
    """bake samples every texture as repeating; a sampler that clamps or mirrors is said only
    where the material's UVs leave [0, 1] (a transform's scale here), where it makes a difference."""
    g = G()
    pos = g.acc(_polygon(4))
    uv = g.acc(np.array([[0, 0], [1, 0], [1, 1], [0, 1]], dtype=float))
    g.j["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(PNG).decode()}]
    g.j["textures"] = [{"source": 0} if wrap is None else {"source": 0, "sampler": 0}]
    if wrap is not None:
        g.j["samplers"] = [{"wrapS": wrap}]
    tex = {"index": 0}
    if scale != 1.0:
        tex["extensions"] = {"KHR_texture_transform": {"scale": [scale, scale]}}
        g.j["extensionsUsed"] = ["KHR_texture_transform"]
    g.j["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": tex}}]
    g.node(mesh=g.mesh({"attributes": {"POSITION": pos, "TEXCOORD_0": uv},
                        "indices": g.acc([0, 1, 2, 0, 2, 3], 5123), "material": 0}))
    _, rec = run(g.write(tmp_path / "w.gltf"))
    warned = [w for w in rec.warnings if "samples with" in w]
    assert bool(warned) == said, rec.warnings
    if said:
        assert "samplers[0]" in warned[0] and ("CLAMP_TO_EDGE" in warned[0] or "MIRRORED_REPEAT" in warned[0])


# --------------------------------------------------------------------------- generated: lights
def test_lights_punctual_world_space(tmp_path):
    g = G()
    h = math.sqrt(0.5)
    g.j["extensionsUsed"] = ["KHR_lights_punctual"]
    g.j["extensions"] = {"KHR_lights_punctual": {"lights": [
        {"type": "spot", "color": [1, 0.5, 0.25], "intensity": 30, "range": 12,
         "spot": {"innerConeAngle": 0.2, "outerConeAngle": 0.6}, "name": "lamp"},
        {"type": "directional", "intensity": 3},
        {"type": "point", "range": 4},
    ]}}
    ext = lambda i: {"KHR_lights_punctual": {"light": i}}  # noqa: E731
    # spot: child rotated +90 deg about X (local -Z -> world +Y) under a translated parent
    spot = g.node(root=False, rotation=[h, 0, 0, h], translation=[0, 0, 1], extensions=ext(0))
    g.node(translation=[5, 0, 0], children=[spot])
    sun = g.node(rotation=[0, h, 0, h], extensions=ext(1))  # -Z -> -X
    g.node(translation=[1, 2, 3], scale=[2, 2, 2], extensions=ext(2), name="bulb")
    g.node(mesh=_tetra(g))
    scene, rec = run(g.write(tmp_path / "lights.gltf"))
    spot_l, sun_l, point_l = scene.lights
    assert spot_l.kind == "spot" and spot_l.name == "lamp" and spot_l.source == "lights.gltf"
    np.testing.assert_allclose(spot_l.position, [5, 0, 1], atol=1e-12)
    np.testing.assert_allclose(spot_l.direction, [0, 1, 0], atol=1e-12)
    assert spot_l.color == (1, 0.5, 0.25) and spot_l.intensity == 30 and spot_l.range == 12
    assert (spot_l.inner_cone, spot_l.outer_cone) == (0.2, 0.6)
    assert sun_l.kind == "sun" and sun_l.position is None
    np.testing.assert_allclose(sun_l.direction, [-1, 0, 0], atol=1e-12)
    assert sun_l.intensity == 3 and sun_l.range is None
    assert point_l.kind == "point" and point_l.name == "bulb" and point_l.direction is None
    np.testing.assert_allclose(point_l.position, [1, 2, 3])
    assert rec.counts_out["lights"] == 3
    d = g.doc()
    d["nodes"][0]["extensions"] = ext(7)
    assert "no KHR_lights_punctual.lights[7]" in _err(g.write(tmp_path / "badlight.gltf", d))


# --------------------------------------------------------------------------- generated: extensions
def test_required_extensions(tmp_path):
    g = G()
    g.node(mesh=_tetra(g))
    for ext, needle in [("EXT_meshopt_compression", "meshopt"), ("KHR_meshopt_compression", "meshopt"),
                        ("KHR_texture_basisu", "requires extension KHR_texture_basisu"),
                        ("EXT_mesh_gpu_instancing", "requires extension EXT_mesh_gpu_instancing")]:
        d = g.doc()
        d["extensionsUsed"] = d["extensionsRequired"] = [ext]
        assert needle in _err(g.write(tmp_path / "req.gltf", d))
    d = g.doc()
    d["extensionsUsed"] = ["KHR_materials_variants", "KHR_lights_punctual"]
    scene, rec = run(g.write(tmp_path / "used.gltf", d))
    assert scene.n_polygons == 4
    assert rec.warnings == ["ignored extensions: KHR_materials_variants"]


def test_meshopt_buffer_view_without_fallback_data(tmp_path):
    g = G()
    g.node(mesh=_tetra(g))
    d = g.doc()
    # the extension used but not required, and the view's buffer is a fallback with no data
    d["extensionsUsed"] = ["EXT_meshopt_compression"]
    d["buffers"].append({"byteLength": d["buffers"][0]["byteLength"],
                         "extensions": {"EXT_meshopt_compression": {"fallback": True}}})
    d["bufferViews"][0]["buffer"] = 1
    d["bufferViews"][0]["extensions"] = {"EXT_meshopt_compression": {
        "buffer": 0, "byteLength": 4, "byteStride": 12, "count": 4, "mode": "ATTRIBUTES"}}
    msg = _err(g.write(tmp_path / "mo.gltf", d))
    assert "EXT_meshopt_compression" in msg and "bufferViews[0]" in msg


# --------------------------------------------------------------------------- Draco failures
def _draco_glb_bytes(corpus) -> tuple[bytearray, int, int]:
    data = bytearray(corpus("box_draco_glb", "Box.glb").read_bytes())
    jlen = struct.unpack_from("<I", data, 12)[0]
    j = json.loads(bytes(data[20:20 + jlen]))
    bv = j["bufferViews"][j["meshes"][0]["primitives"][0]["extensions"]
                          ["KHR_draco_mesh_compression"]["bufferView"]]
    return data, 20 + jlen + 8 + bv.get("byteOffset", 0), bv["byteLength"]


@pytest.mark.corpus
def test_draco_without_decoder_is_refused_not_zero_filled(corpus, monkeypatch):
    import sys

    monkeypatch.setitem(sys.modules, "DracoPy", None)  # import DracoPy -> ImportError
    msg = _err(corpus("box_draco_glb", "Box.glb"))
    assert "KHR_draco_mesh_compression" in msg and "DracoPy" in msg


@pytest.mark.corpus
def test_corrupt_draco_data_fails(corpus, tmp_path):
    data, start, n = _draco_glb_bytes(corpus)
    data[start:start + n] = bytes(range(n))
    p = tmp_path / "corrupt.glb"
    p.write_bytes(bytes(data))
    msg = _err(p)
    assert "meshes[0].primitives[0]" in msg and "Draco" in msg


@pytest.mark.corpus
def test_draco_attribute_missing_from_compressed_data(corpus, tmp_path):
    data, _, _ = _draco_glb_bytes(corpus)
    jlen = struct.unpack_from("<I", data, 12)[0]
    j = json.loads(bytes(data[20:20 + jlen]))
    del j["meshes"][0]["primitives"][0]["extensions"]["KHR_draco_mesh_compression"]["attributes"]["POSITION"]
    js = json.dumps(j).encode()
    js += b" " * (-len(js) % 4)
    rest = bytes(data[20 + jlen:])
    body = struct.pack("<II", len(js), 0x4E4F534A) + js + rest
    p = tmp_path / "nopos.glb"
    p.write_bytes(struct.pack("<4sII", b"glTF", 2, 12 + len(body)) + body)
    assert "POSITION is not in the Draco data" in _err(p)


def test_textured_material_without_uvs_warns_and_dispatch_reads_glb(tmp_path):
    from bake.importers.stage import stage
    from bake.scene import Scene

    g = G()
    g.j["images"] = [{"uri": "data:image/png;base64," + base64.b64encode(PNG).decode()}]
    g.j["textures"] = [{"source": 0}]
    g.j["materials"] = [{"pbrMetallicRoughness": {"baseColorTexture": {"index": 0}}}]
    g.node(mesh=g.mesh({"attributes": {"POSITION": g.acc(_polygon(3))}, "material": 0}))
    p = g.write_glb(tmp_path / "nouv.glb")
    scene, rec = stage(Scene(), ImportJob(path=p))
    assert scene.n_polygons == 1 and scene.poly_uvs is None and scene.source.format == "glb"
    assert scene.materials[0].texture_data == PNG
    assert any("TEXCOORD_0" in w for w in rec.warnings)
