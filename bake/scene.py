"""The one data model every stage reads and writes.

A :class:`Scene` is immutable by convention: a stage builds a new one with
:meth:`Scene.replace` (or :func:`dataclasses.replace`) and never edits arrays in place.

Geometry is world space, float64. Faces exist in two forms:

* ``polygons``: what the importer read (n-gons kept), as vertex counts plus a flat index
  array, with per-corner UVs aligned to the flat index array;
* ``triangles``: what triangulation produced, ``(T, 3)`` vertex indices with per-triangle
  material, per-corner UVs ``(T, 3, 2)`` and the polygon each triangle came from.

Stages after triangulation work on ``triangles``. A stage that rebuilds triangles (simplify,
BSP splitting) sets ``tri_polygon`` to ``-1`` for triangles that no longer correspond to a
whole source polygon; export uses that to decide which quads / n-gons it can still write.

Colours are floats in [0, 1], RGBA, sRGB-encoded (the values Scratch shows), never NaN.
UVs use the OBJ/OpenGL convention: (0, 0) is the bottom-left of the image, v grows upward
(the glTF importer converts from glTF's top-left origin).
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Mapping

import numpy as np


@dataclass(frozen=True)
class Material:
    name: str
    color: tuple[float, float, float, float] = (0.8, 0.8, 0.8, 1.0)
    texture: Path | None = None  # base colour image (absolute path), if any
    # Encoded image bytes (PNG/JPEG) for textures embedded in the model (GLB, data: URIs).
    texture_data: bytes | None = field(default=None, repr=False)
    double_sided: bool = False
    # where ``texture_data`` came from, for messages and the report ("Box.glb images[0], image/png")
    texture_source: str | None = None

    def with_(self, **kw: Any) -> "Material":
        return dataclasses.replace(self, **kw)


DEFAULT_MATERIAL = Material(name="default")

# The coordinates bake works with (docs/reliability.md): every position within +-MAX_COORDINATE and
# a model at least MIN_EXTENT across (or a single point). Beyond them, squared lengths and areas
# overflow or underflow float64 (clean would drop every triangle of a 1e-80 model and weld all its
# vertices), and the float32 work (ray tracing, simplification) has nothing left to resolve.
MAX_COORDINATE = 1e30
MIN_EXTENT = 1e-30


@dataclass(frozen=True)
class Light:
    """A light source. ``kind`` is one of ``sun``, ``point``, ``spot``.

    ``direction`` points *from* the light *towards* the scene (sun, spot).
    ``angle`` is the sun's angular diameter in degrees (soft shadows); ``radius`` the size of a
    point or spot light. ``intensity`` scales ``color`` (linear).
    """

    kind: str
    color: tuple[float, float, float] = (1.0, 1.0, 1.0)
    intensity: float = 1.0
    position: tuple[float, float, float] | None = None
    direction: tuple[float, float, float] | None = None
    angle: float = 0.0
    radius: float = 0.0
    range: float | None = None
    inner_cone: float = 0.0  # radians (glTF convention)
    outer_cone: float = 0.7853981633974483
    name: str = ""
    source: str = "config"  # "config" or the file it was imported from


@dataclass(frozen=True)
class ScratchList:
    """A list destined for Scratch: numbers (or strings) plus how to read them.

    ``values`` is a 1-D numpy array of numbers or a tuple of strings. ``stride`` is the number of
    items per record; ``precision`` the number of significant decimals to write for floats
    (``None`` = integers or exact). ``doc`` is one line for the report and docs.
    """

    name: str
    values: Any
    stride: int = 1
    doc: str = ""
    kind: str = "number"  # "number" | "int" | "string"
    decimals: int | None = None  # decimals after the point for floats (None: shortest repr)
    # The list's shape for packing (export.pack): ``pack_prefix`` items (e.g. a header) and then
    # records of ``pack_stride`` items (0 = ``stride``); a list of variable-length records leaves both 0.
    pack_prefix: int = 0
    pack_stride: int = 0
    # The export key the list is written under (``export.names.<role>``: "vertices", "triangles",
    # ...), which an array of names splits by component (bake/scratch/layout.py); "" for others.
    role: str = ""


@dataclass(frozen=True)
class SourceInfo:
    path: Path | None = None
    files_read: tuple[Path, ...] = ()  # every file an importer opened (for --depfile)
    # files a model names that were not there (a texture, an .mtl): --depfile watches their folders
    files_missing: tuple[Path, ...] = ()
    format: str = ""


@dataclass(frozen=True)
class BSPArtefact:
    """The BSP stage's tree as later stages and the reader see it: its lists' names, the stack
    the walk needs, the on-plane tolerance it was built with (``bsp.stage.tie_tolerance``), and per
    output triangle its source triangle and face (and per input triangle its face)."""

    nodes: str
    planes: str
    stack: int
    epsilon: float
    source_triangle: np.ndarray | None = None
    source_face: np.ndarray | None = None
    input_source_face: np.ndarray | None = None


@dataclass(frozen=True)
class BVHArtefact:
    """The BVH stage's tree, its encoding, the barycentric bounds of the reader's inside test, and
    the names of its lists ("nodes", "tris", "ids")."""

    tree: Any
    encoded: Any
    bary: tuple[float, float]
    lists: Mapping[str, str]


@dataclass(frozen=True)
class Artefacts:
    """What a stage hands to later stages and to what runs after the bake, one field each (None
    until the stage that makes it ran). A stage reads the fields of the stages before it, never
    their sections."""

    # textures: the model's textures (a ``bake.textures.stage.TextureSet``), the albedo lighting
    # samples (a function of the scene: per-triangle RGBA), what the encodings wrote (lists,
    # images), the costumes for the project ((name, PNG bytes), also written to assets/), and
    # the lightmap atlas to bake into (``bake.textures.lightmap.LightmapJob``)
    textures: Any = None
    albedo: Any = None
    texture_outputs: dict[str, Any] | None = None
    costumes: list[tuple[str, bytes]] | None = None
    lightmap: Any = None
    # lighting: its result (``bake.lighting`` colours and effects) and the baked lightmap (uint8 RGBA)
    lighting: Any = None
    lightmap_image: Any = None
    lightmap_encoded: Any = None  # its lists and costume (bake.textures.encode.EncodedTexture)
    # bsp / bvh: the tree, its list names and encoding (read by the reader sprite and the previews)
    bsp: BSPArtefact | None = None
    bvh: BVHArtefact | None = None
    # export: per list its items, bytes and file; the files to write (relative path -> bytes)
    list_info: dict[str, dict] | None = None
    outputs: dict[str, bytes] | None = None


@dataclass(frozen=True)
class Scene:
    positions: np.ndarray = field(default_factory=lambda: np.zeros((0, 3)))
    # polygons as read
    poly_sizes: np.ndarray | None = None  # (P,) int64
    poly_indices: np.ndarray | None = None  # (sum sizes,) int64
    poly_material: np.ndarray | None = None  # (P,) int64
    poly_uvs: np.ndarray | None = None  # (sum sizes, 2) float64, per corner
    # triangles
    triangles: np.ndarray | None = None  # (T, 3) int64
    tri_material: np.ndarray | None = None  # (T,) int64
    tri_uvs: np.ndarray | None = None  # (T, 3, 2) float64, per corner
    tri_polygon: np.ndarray | None = None  # (T,) int64 source polygon or -1
    # colours
    vertex_colors: np.ndarray | None = None  # (V, 4) float64 in [0, 1]
    face_colors: np.ndarray | None = None  # (T, 4) float64 in [0, 1], per triangle
    # (T, 4) base colour per triangle from the textures stage (texture mean over the UV area x
    # material colour x mean vertex colour); None = material x vertex colour. Stages that split or
    # reorder triangles after it must carry it (and tri_lightmap_uvs) along.
    face_albedo: np.ndarray | None = None
    tri_lightmap_uvs: np.ndarray | None = None  # (T, 3, 2) lightmap UVs per corner (v up, in [0, 1])
    # Positions are written rounded to this many decimals (the grid of
    # bake.scratch.numbers.position_decimals); set by the pipeline before the first stage that
    # builds on the written positions (bsp, export). None: not known (exact positions).
    position_decimals: int | None = None
    # the rest
    materials: tuple[Material, ...] = (DEFAULT_MATERIAL,)
    lights: tuple[Light, ...] = ()
    lists: Mapping[str, ScratchList] = field(default_factory=dict)
    artefacts: Artefacts = field(default_factory=lambda: Artefacts())
    source: SourceInfo = field(default_factory=SourceInfo)

    # ------------------------------------------------------------------ helpers
    def replace(self, **changes: Any) -> "Scene":
        return dataclasses.replace(self, **changes)

    def with_list(self, lst: ScratchList) -> "Scene":
        lists = dict(self.lists)
        lists[lst.name] = lst
        return self.replace(lists=lists)

    def with_artefacts(self, **made: Any) -> "Scene":
        """The scene with the given :class:`Artefacts` fields set (``with_artefacts(bvh=...)``)."""
        return self.replace(artefacts=dataclasses.replace(self.artefacts, **made))

    @property
    def n_vertices(self) -> int:
        return int(len(self.positions))

    @property
    def n_polygons(self) -> int:
        return 0 if self.poly_sizes is None else int(len(self.poly_sizes))

    @property
    def n_triangles(self) -> int:
        return 0 if self.triangles is None else int(len(self.triangles))

    @property
    def poly_offsets(self) -> np.ndarray:
        """Start of each polygon in ``poly_indices`` (length P + 1)."""
        sizes = self.poly_sizes if self.poly_sizes is not None else np.zeros(0, np.int64)
        off = np.zeros(len(sizes) + 1, dtype=np.int64)
        np.cumsum(sizes, out=off[1:])
        return off

    def bounds(self) -> np.ndarray:
        """(2, 3) min/max of the vertices that faces use (all vertices if no faces)."""
        if self.n_vertices == 0:
            return np.zeros((2, 3))
        used = self.used_vertex_mask()
        p = self.positions[used] if used.any() else self.positions
        return np.stack([p.min(axis=0), p.max(axis=0)])

    def diagonal(self) -> float:
        b = self.bounds()
        return float(np.linalg.norm(b[1] - b[0]))

    def scale(self) -> float:
        """A length for scene-relative tolerances: the bbox diagonal, or the largest
        coordinate magnitude for a flat/degenerate scene, never 0."""
        d = self.diagonal()
        if d > 0 and np.isfinite(d):
            return d
        m = float(np.abs(self.positions).max()) if self.n_vertices else 0.0
        return m if m > 0 else 1.0

    def used_vertex_mask(self) -> np.ndarray:
        used = np.zeros(self.n_vertices, dtype=bool)
        if self.triangles is not None and len(self.triangles):
            used[self.triangles.ravel()] = True
        elif self.poly_indices is not None and len(self.poly_indices):
            used[self.poly_indices] = True
        return used

    def triangle_vertices(self) -> np.ndarray:
        """(T, 3, 3) float64 corner positions."""
        if self.triangles is None:
            return np.zeros((0, 3, 3))
        return self.positions[self.triangles]

    def triangle_albedo(self) -> np.ndarray:
        """(T, 4) base colour per triangle: ``face_albedo`` when set, else the material colour
        times the mean vertex colour."""
        T = self.n_triangles
        if T == 0:
            return np.zeros((0, 4))
        if self.face_albedo is not None:
            return np.array(self.face_albedo, dtype=np.float64)
        mat = np.array([m.color for m in self.materials], dtype=np.float64)
        col = mat[np.clip(self.tri_material, 0, len(mat) - 1)]
        if self.vertex_colors is not None:
            col = col * self.vertex_colors[self.triangles].mean(axis=1)
        return col

    def validate(self) -> None:
        """Internal consistency check used by tests and the pipeline (raises AssertionError)."""
        V = self.n_vertices
        assert self.positions.dtype == np.float64 and self.positions.shape == (V, 3)
        if self.poly_sizes is not None:
            assert self.poly_indices is not None and self.poly_material is not None
            assert int(self.poly_sizes.sum()) == len(self.poly_indices)
            assert len(self.poly_material) == len(self.poly_sizes)
            if len(self.poly_indices):
                assert self.poly_indices.min() >= 0 and self.poly_indices.max() < V
            if self.poly_uvs is not None:
                assert self.poly_uvs.shape == (len(self.poly_indices), 2)
        if self.triangles is not None:
            T = len(self.triangles)
            assert self.triangles.shape == (T, 3)
            assert self.tri_material is not None and len(self.tri_material) == T
            if T:
                assert self.triangles.min() >= 0 and self.triangles.max() < V
                assert self.tri_material.min() >= 0 and self.tri_material.max() < len(self.materials)
            if self.tri_uvs is not None:
                assert self.tri_uvs.shape == (T, 3, 2)
            if self.tri_polygon is not None:
                assert len(self.tri_polygon) == T
            if self.face_colors is not None:
                assert self.face_colors.shape == (T, 4)
            if self.face_albedo is not None:
                assert self.face_albedo.shape == (T, 4)
            if self.tri_lightmap_uvs is not None:
                assert self.tri_lightmap_uvs.shape == (T, 3, 2)
        if self.vertex_colors is not None:
            assert self.vertex_colors.shape == (V, 4)
        for name in ("positions", "vertex_colors", "face_colors", "poly_uvs", "tri_uvs", "face_albedo",
                     "tri_lightmap_uvs"):
            a = getattr(self, name)
            if a is not None:
                assert np.isfinite(a).all(), f"{name} has NaN/Inf"


def make_scene(positions: Any, triangles: Any = None, *, polygons: list[list[int]] | None = None,
               materials: tuple[Material, ...] | None = None, tri_material: Any = None,
               vertex_colors: Any = None, tri_uvs: Any = None) -> Scene:
    """Build a scene from plain arrays (tests, generated meshes). Either ``triangles`` (T, 3)
    or ``polygons`` (a list of index lists) is given; triangles also fill the polygon arrays."""
    pos = np.asarray(positions, dtype=np.float64).reshape(-1, 3)
    mats = tuple(materials) if materials else (DEFAULT_MATERIAL,)
    if polygons is not None:
        sizes = np.array([len(p) for p in polygons], dtype=np.int64)
        idx = np.array([i for p in polygons for i in p], dtype=np.int64)
        pm = np.zeros(len(sizes), np.int64) if tri_material is None else np.asarray(tri_material, np.int64)
        return Scene(positions=pos, poly_sizes=sizes, poly_indices=idx, poly_material=pm, materials=mats,
                     vertex_colors=None if vertex_colors is None else np.asarray(vertex_colors, np.float64))
    tris = np.asarray(triangles, dtype=np.int64).reshape(-1, 3)
    T = len(tris)
    tm = np.zeros(T, np.int64) if tri_material is None else np.asarray(tri_material, np.int64)
    vc = None if vertex_colors is None else np.asarray(vertex_colors, np.float64)
    uv = None if tri_uvs is None else np.asarray(tri_uvs, np.float64).reshape(T, 3, 2)
    return Scene(positions=pos, poly_sizes=np.full(T, 3, np.int64), poly_indices=tris.ravel().copy(),
                 poly_material=tm.copy(), poly_uvs=None if uv is None else uv.reshape(-1, 2).copy(),
                 triangles=tris, tri_material=tm, tri_uvs=uv, tri_polygon=np.arange(T, dtype=np.int64),
                 vertex_colors=vc, materials=mats)


def coordinate_problem(scene: Scene) -> str | None:
    """What is wrong with the used vertices' coordinates, or None: they must lie within
    +-MAX_COORDINATE and span at least MIN_EXTENT (or be one point). The import and transform
    stages check their results (the importers name the lines of coordinates that are too large
    themselves; what is left is a model too small to bake, or a transform that scales it out of
    range)."""
    used = scene.used_vertex_mask()
    if not used.any():
        return None
    p = scene.positions[used]
    with np.errstate(over="ignore"):
        big = float(np.abs(p).max())
        extent = float(np.abs(p.max(axis=0) - p.min(axis=0)).max())
    small = 0.0 < extent < MIN_EXTENT
    if big <= MAX_COORDINATE and np.isfinite(big) and not small:
        return None
    return (f"the model is only {extent:.3g} across (bake needs at least {MIN_EXTENT:g})" if small else
            f"coordinates reach {big:.3g}, beyond +-{MAX_COORDINATE:g} (the range bake supports)")
