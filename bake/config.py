"""TOML -> typed config.

Every section is a dataclass; the loader checks every key against it. An unknown key is an
error that names the file, the line and the nearest known key. Types are checked (an ``int`` is
accepted where a ``float`` is expected), ``Literal`` choices are enforced, and nested sections
and arrays of tables (``[[lighting.lights]]``) are typed too.

``--set section.key=value`` overrides go through the same checks (the value is parsed as a TOML
value, falling back to a bare string).

Stage owners add their keys to their own section class below; nothing else needs to change.
"""

from __future__ import annotations

import dataclasses
import difflib
import re
import sys
import types
import typing
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Literal, Optional, Union, get_args, get_origin, get_type_hints

if sys.version_info >= (3, 11):
    import tomllib
else:  # pragma: no cover
    import tomli as tomllib

from .errors import ConfigError


# --------------------------------------------------------------------------- sections
@dataclass
class InputConfig:
    path: str = ""  # model file, relative to the config file
    format: Literal["auto", "obj", "gltf", "glb"] = "auto"


@dataclass
class ImportConfig:
    # strict = true: a bad face (index 0, out of range, < 3 vertices) is an error naming file
    # and line. false: a warning and the face is dropped.
    strict: bool = True
    # glTF: which scene (-1 = the file's default scene, else scenes[0]).
    scene: int = -1


@dataclass
class TransformConfig:
    up: Literal["y", "z", "-y", "-z", "x", "-x"] = "y"  # the source file's up axis
    # Target frame. "left": x right, y up, z into the screen (most Scratch engines).
    # "right": x right, y up, z towards the viewer (OBJ / glTF convention).
    frame: Literal["left", "right"] = "left"
    scale: float = 1.0
    # Fit the model so its largest bbox side is this long (0 = keep size; applied after scale).
    fit: float = 0.0
    center: Literal["none", "bounds", "base"] = "none"  # base: centred on x/z, resting on y=0


@dataclass
class TriangulateConfig:
    # fan: the book's fan from the first vertex (right for convex planar polygons).
    # auto: fan where it is valid, ear clipping on the best-fit plane where it is not.
    method: Literal["auto", "fan"] = "auto"


@dataclass
class CleanConfig:
    enabled: bool = True
    weld: bool = True
    # Weld tolerance as a fraction of the bbox diagonal (0 = exact duplicates only).
    weld_tolerance: float = 1e-7
    drop_degenerate: bool = True
    # A triangle whose area is below this fraction of diagonal^2 is dropped.
    area_tolerance: float = 1e-14
    drop_unused_vertices: bool = True


@dataclass
class SimplifyConfig:
    enabled: bool = False
    target_triangles: int = 0  # 0 = not set
    target_ratio: float = 0.0  # 0 = not set
    max_error: float = 0.0  # fraction of the bbox diagonal; 0 = not set
    # meshopt: meshoptimizer (keeps input vertices; UV seams and material edges are seams).
    # fast: fast-simplification. quality: MeshLab quadric edge collapse (slow).
    method: Literal["meshopt", "fast", "quality"] = "meshopt"
    # After simplifying, least-squares refit of vertex positions to the original surface
    # (rounds; 0 = off). Vertices on open borders (with preserve_border) and on material edges
    # are never moved: they stay input vertices on the input's borders and edges.
    fit_iterations: int = 3
    # Needs measure_error: rounds of local repair where the measured error peaks (edges turned,
    # free corners moved to lower the local maximum); kept only if the measured max drops (0 = off).
    # Neither these nor the peak rounds run on a result within 0.01% of the diagonal already.
    refine_rounds: int = 2
    # With a triangle target and refine_rounds > 0: rounds of locking the input vertices where
    # the result cut the most off (a spout tip) and running the stage again; each is kept only if
    # the measured max drops. Each costs about one more stage run (0 = off).
    peak_rounds: int = 1
    # With a triangle target: never accept a result whose measured error (fraction of the
    # diagonal) exceeds this; stop at more triangles instead and say so (0 = no ceiling: the
    # budget is met, and a result more than 5% of the diagonal off is warned about).
    error_ceiling: float = 0.0
    # With a triangle target, what a result with defects (triangles turned against the surface they
    # stand for, triangles on new non-manifold edges) does: "allow" delivers the budget with the
    # fewest defects the repairs leave and reports them (warnings, details.defects); "refuse"
    # backs off to the smallest larger count without any (docs/simplify.md, "Defects").
    defects: Literal["allow", "refuse"] = "allow"
    preserve_border: bool = True
    preserve_materials: bool = True
    # The symmetric Hausdorff error in the record: a grid of about error_samples points on each
    # surface (every vertex, points along every edge and inside every triangle; on the simplified
    # one 12 per triangle where that is more, at most 4 x error_samples), refined around the
    # largest distances; a sampled maximum (the record gives the sample), never called exact
    # (error_bound below proves an upper bound of the true one).
    measure_error: bool = True
    error_samples: int = 20000
    # Then prove an upper bound of the true maximum (over the whole surfaces, not a sample): grid
    # cells are cut until none can hold more than 2% above the largest distance found (or 0.01%
    # of the diagonal), at most 16 x error_samples more points per direction (the record says
    # whether it got there).
    # "original": the original -> simplified direction (cut-off features); "both": the
    # simplified -> original one too (slower: the original is the big mesh); "none". What each
    # costs and finds: docs/simplify.md, "A proven bound".
    error_bound: Literal["none", "original", "both"] = "original"
    seed: int = 0


@dataclass
class MeshConfig:
    triangulate: TriangulateConfig = field(default_factory=TriangulateConfig)
    clean: CleanConfig = field(default_factory=CleanConfig)
    simplify: SimplifyConfig = field(default_factory=SimplifyConfig)


@dataclass
class BSPConfig:
    enabled: bool = False
    candidates: int = 64  # candidate planes sampled per node (0 = all)
    # score = split_weight * cost + balance_weight * |front - back| - coplanar_weight * coplanar;
    # cost "triangles": what the cuts add (2 per cut, 1 through a corner, 0 along a diagonal),
    # "pieces": 1 per fragment cut (qbsp/ZDBSP count; use split_weight 8 for their balance)
    split_cost: Literal["triangles", "pieces"] = "triangles"
    split_weight: float = 4.0
    balance_weight: float = 0.5
    coplanar_weight: float = 0.0
    # planes through an edge of one face and a corner of another, per node (0 = face planes only);
    # used only where their cuts add at most edge_plane_cost triangles per face of the node
    edge_planes: int = 256
    edge_plane_cost: float = 0.3
    # nodes of more faces score every candidate on a sample of this many (0 = all of them) and
    # rescore the best score_refine on all
    score_sample: int = 512
    score_refine: int = 4
    # nodes of at most ensemble_max faces are built `ensemble` times from their best planes and the
    # subtree adding the fewest triangles is kept (1 = off)
    ensemble: int = 8
    ensemble_max: int = 64
    # Scenes of at most thorough_faces faces (after coplanar merging) get the thorough search:
    # the ensembles above and thorough_edge_factor times edge_planes per node; bigger scenes are
    # built greedily (no ensembles, edge_planes) (0 = never thorough)
    thorough_faces: int = 8000
    thorough_edge_factor: int = 1
    seed: int = 0
    # Leaves: "priority" (sets drawn in a fixed order valid from every viewpoint, plus peeling),
    # "convex" (only sets in which no face can hide another), "none" (classic BSP).
    leaves: Literal["priority", "convex", "none"] = "priority"
    leaf_max: int = 128  # largest set given the O(n^2) priority test
    gap_planes: bool = True  # also try the most balanced axis-aligned plane that cuts nothing
    axis_planes: bool = False  # also try axis planes through the median
    merge_coplanar: bool = True  # merge coplanar neighbours into convex polygons first
    # after the build, join coplanar neighbouring fragments drawn as one unit where the joint
    # drops a corner a cut left on a straight line (bake/bsp/remerge.py)
    remerge: bool = True
    epsilon: float = 1e-6  # on-plane tolerance, fraction of the bbox diagonal
    min_area: float = 1e-12  # smallest fragment, fraction of the diagonal squared
    plane_decimals: int = 6  # decimals kept in plane normals (offsets: 2 more digits)


@dataclass
class BVHConfig:
    enabled: bool = False
    leaf_size: int = 4  # most triangles in a leaf (1..14)
    bins: int = 8  # SAH bins per axis
    # high: more bins, single-triangle leaves, reinsertion optimiser, then optimal collapse
    quality: Literal["binned", "high"] = "binned"
    # binary: stackless 7-item nodes; wide4: 4-wide float nodes; quantised: 4-wide nodes whose
    # child boxes are packed small integers (docs/formats-bvh.md)
    layout: Literal["binary", "wide4", "quantised"] = "quantised"
    quant_bits: int = 6  # bits per quantised box plane (2..8)
    # list coordinates are rounded to a power of ten <= diagonal * 10^-precision (0 = exact)
    precision: int = 5
    high_effort: float = 10.0  # work budget of the reinsertion optimiser (quality = "high"), millions of node visits
    list_prefix: str = "bvh"  # lists are "<prefix> nodes", "<prefix> tris", "<prefix> tri ids"


@dataclass
class LightConfig:
    kind: Literal["sun", "point", "spot"] = "sun"
    color: list[float] = field(default_factory=lambda: [1.0, 1.0, 1.0])
    intensity: float = 1.0
    direction: list[float] = field(default_factory=lambda: [-0.3, -1.0, 0.4])  # light -> scene
    position: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    angle: float = 0.53  # sun angular diameter, degrees
    radius: float = 0.0  # point / spot size
    inner_cone: float = 0.0  # degrees
    outer_cone: float = 45.0  # degrees
    range: float = 0.0  # 0 = unbounded
    name: str = ""


@dataclass
class AOConfig:
    enabled: bool = False
    samples: int = 64
    distance: float = 0.25  # fraction of the bbox diagonal
    strength: float = 1.0


@dataclass
class SkyConfig:
    enabled: bool = False
    color: list[float] = field(default_factory=lambda: [0.6, 0.7, 0.9])
    horizon: list[float] = field(default_factory=lambda: [0.6, 0.7, 0.9])  # gradient bottom
    ground: list[float] = field(default_factory=lambda: [0.3, 0.3, 0.3])  # below the horizon
    intensity: float = 1.0
    samples: int = 64


@dataclass
class BouncesConfig:
    count: int = 0
    samples: int = 64


@dataclass
class ShadowsConfig:
    enabled: bool = True
    samples: int = 16  # rays per light per point for soft shadows


@dataclass
class LightingConfig:
    enabled: bool = False
    target: Literal["vertex", "triangle", "lightmap"] = "vertex"
    ambient: list[float] = field(default_factory=lambda: [0.0, 0.0, 0.0])
    exposure: float = 1.0
    import_lights: bool = True  # KHR_lights_punctual from glTF
    threads: int = 0  # 0 = all cores
    seed: int = 0
    lights: list[LightConfig] = field(default_factory=list)
    ao: AOConfig = field(default_factory=AOConfig)
    sky: SkyConfig = field(default_factory=SkyConfig)
    shadows: ShadowsConfig = field(default_factory=ShadowsConfig)
    bounces: BouncesConfig = field(default_factory=BouncesConfig)
    # Colour pipeline (bake/lighting/color.py): "srgb" decodes albedo to linear light and
    # encodes the result; "linear" multiplies the shown values as they are.
    color_space: Literal["srgb", "linear"] = "srgb"
    tonemap: Literal["clamp", "reinhard"] = "clamp"
    # vertex colours: "color" = lit albedo, "light" = the light alone (engine multiplies).
    vertex_output: Literal["color", "light"] = "color"
    # Triangle colour = area average: triangles longer than face_cell x diagonal get interior
    # sample points (at most face_points_max per triangle).
    face_cell: float = 0.1
    face_points_max: int = 16
    # Split triangles whose colour varies across them (budgeted by max_triangles).
    subdivide: bool = False
    max_triangles: int = 20000
    subdivide_threshold: float = 0.05  # colour difference (0..1, shown values) that splits
    subdivide_levels: int = 3  # rounds
    subdivide_min_edge: float = 0.01  # fraction of the diagonal: shorter edges are not split


@dataclass
class LightmapConfig:
    """Lightmap atlas and texel machinery (bake/textures/: unwrap.py, texels.py, seams.py,
    lightmap.py); lighting.target = "lightmap" is what fills it with light."""

    enabled: bool = False
    # xatlas packing: the atlas's longer side in texels, at most this (xatlas grows the atlas by
    # the padding, so it is asked again for less until it fits); texels per model unit (0 = xatlas
    # chooses so the charts fit the resolution; > 0: one run, the atlas may be larger); texels
    # between charts.
    resolution: int = 256
    texels_per_unit: float = 0.0
    padding: int = 2
    # xatlas chart options (0 = xatlas default / unlimited)
    max_chart_area: float = 0.0
    max_cost: float = 2.0
    normal_deviation_weight: float = 2.0
    rotate_charts: bool = True
    # Texel sampling: supersample x supersample points per texel; push samples that start inside
    # or behind geometry out to the free side; texels of padding to fill; least-squares seams.
    supersample: int = 2
    push_out: bool = True
    dilate: int = 2
    stitch_seams: bool = True
    max_triangles: int = 100000  # larger meshes are refused (xatlas takes 17-26 s at 100k)
    timeout: float = 120.0  # seconds the xatlas subprocess may run
    # xatlas atlas cache: "" = <output folder>/.bake-cache/xatlas (nothing outside the output
    # folder; no cache without one); a path = a cache shared between bakes; "none" = no cache.
    cache_dir: str = ""
    # The bake's output folder (not a TOML key; `bake run` sets it): where the default cache lives.
    out_dir: Path | None = field(default=None, metadata={"internal": True})
    # Whether the lighting stage will fill the atlas (lighting.target = "lightmap"; not a TOML key:
    # the pipeline sets it): the memory estimate then counts the texel bake too.
    lit: bool = field(default=True, metadata={"internal": True})


@dataclass
class TexturesConfig:
    # "auto": on when the model's materials name a texture (or textures.texture or the lightmap
    # asks for the stage); else the stage is reported as skipped, with why
    enabled: bool | Literal["auto"] = "auto"
    # An image for every material that has no texture (a model shipped without its .mtl, like
    # spot); relative paths are relative to the model's folder. "" = none.
    texture: str = ""
    # Resampling of material textures (map_Kd / baseColorTexture): an exact width x height
    # (0 = from the image), else the image shrunk to max_size (0 = no cap); then each side
    # rounded to a power of two ("none" = keep). filter: nearest or a Pillow filter; wrap: the
    # filter reads across the edges (repeat addressing).
    width: int = 0
    height: int = 0
    max_size: int = 128
    power_of_two: Literal["none", "floor", "ceil", "nearest"] = "none"
    filter: Literal["nearest", "box", "bilinear", "hamming", "bicubic", "lanczos"] = "box"
    wrap: bool = True
    # Per-triangle base colour = mean of the texture over the triangle's UV area x material
    # colour x mean vertex colour -> Scene.face_albedo (and face_colors, the "tri colors" list).
    # average: mean of linear light ("linear") or of the stored values ("srgb"); average_source:
    # the texture as loaded ("original") or as resampled for Scratch ("resampled").
    bake_colors: bool = True
    average: Literal["linear", "srgb"] = "linear"
    average_source: Literal["original", "resampled"] = "original"
    # Which encodings to write for each texture (the record compares all three whatever this says).
    encodings: list[Literal["list", "textimage", "costume"]] = field(
        default_factory=lambda: ["list", "textimage", "costume"])
    color_format: Literal["rgb", "argb", "hex"] = "rgb"  # colour-list items
    first_row: Literal["top", "bottom"] = "bottom"  # colour-list pixel order
    textimage_alpha: Literal["auto", "always", "never"] = "auto"
    # Names; {material} is the (first) material using the texture.
    list_name: str = "tex {material}"
    size_list_name: str = "tex {material} size"
    textimage_list_name: str = "tex {material} textimage"
    costume_name: str = "tex {material}"
    lightmap: LightmapConfig = field(default_factory=LightmapConfig)


@dataclass
class ListNames:
    vertices: str = "verts"
    triangles: str = "tris"
    materials: str = "mat colors"
    triangle_colors: str = "tri colors"
    vertex_colors: str = "vert colors"
    uvs: str = "tri uvs"
    lightmap_uvs: str = "lightmap uvs"
    two_sided: str = "mat two-sided"
    quads: str = "quads"
    ngons: str = "ngons"
    packed: str = "packed lists"  # with export.pack: the packed texts the loader decodes


@dataclass
class ExportConfig:
    enabled: bool = True
    # Which mesh lists to write. "auto" colour lists are written when the scene has colours.
    vertices: bool = True
    triangles: bool = True
    materials: bool = True
    triangle_colors: Literal["auto", "yes", "no"] = "auto"
    vertex_colors: Literal["auto", "yes", "no"] = "auto"
    uvs: Literal["auto", "yes", "no"] = "auto"
    lightmap_uvs: Literal["auto", "yes", "no"] = "auto"  # auto: when the scene has a lightmap atlas
    # Which materials are two-sided (1) or single-sided (0), one item per material in "mat colors"
    # order. auto: when a material is two-sided or a BSP tree is written (its walk skips
    # single-sided triangles that face away); without the list every material is single-sided.
    two_sided: Literal["auto", "yes", "no"] = "auto"
    # Faces: "triangles" only, or keep quads / n-gons in their own lists (the book's Quads and
    # Ngons lists); polygons that cannot be kept whole are written as triangles, and so is every
    # face with a BSP tree, a BVH or a list that goes per triangle (tri colors, tri uvs, lightmap uvs; docs/formats.md).
    faces: Literal["triangles", "quads", "ngons"] = "triangles"
    # Positions are rounded to this many significant digits of the model's size: a step of the
    # largest power of ten <= diagonal * 10^-precision (never coarser than 1; docs/formats.md;
    # bake.scratch.numbers.position_decimals, the grid the BSP builds on too).
    precision: int = 5
    # Vertex numbering: "first-use" = in the order the written triangles first use them (the
    # index lists then pack to a symbol or two per corner); "scene" = the scene's order.
    vertex_order: Literal["first-use", "scene"] = "first-use"
    color_format: Literal["rgb", "argb", "hex"] = "rgb"
    # Packed lists (docs/formats.md "Packed lists"): in the .sb3/.sprite3/export.into project the
    # numeric lists are stored as short strings in the list `names.packed`, and loader blocks in
    # the reader sprite rebuild exactly the plain lists at the green flag (list files and
    # lists.json stay plain). A list is packed only when that is smaller, and when it decodes to
    # at most pack_max_items items (vanilla Scratch's `add to list` stops at 200,000; 0 = no
    # limit, for TurboWarp).
    pack: bool = False
    pack_max_items: int = 200_000
    names: ListNames = field(default_factory=ListNames)
    txt: bool = True
    json: bool = True
    json_name: str = "lists.json"
    # A fresh <model>.sb3 (lists on the stage, monitors hidden) and <model>.sprite3 (lists local
    # to a sprite) beside the list files.
    sb3: bool = True
    sprite3: bool = True
    sprite_name: str = "Mesh"
    # The reference reader sprite (custom blocks reading these lists, a pen renderer; its green
    # flag draws the model) in the .sb3 and as the .sprite3.
    reader: bool = True
    sb3_name: str = ""  # file name of the fresh .sb3 ("" = <model>.sb3)
    # TurboWarp's "fencing" (every move of a sprite is tested against the stage's edges) in the
    # fresh .sb3: false stores TurboWarp's settings comment on the stage turning it off, so the
    # pen renderer's moves skip the test (benchmarks/bench_player.py measures what it buys: the
    # "fencing on" table in README). TurboWarp applies it to the whole project; Scratch ignores it. Never written
    # into export.into projects or the .sprite3.
    turbowarp_fencing: bool = False
    # Bake into an existing project: a new .sb3 with our lists put into `into_target` (replacing
    # same-named lists, monitors hidden), everything else untouched. The input is never written.
    into: str = ""  # path of the .sb3 (relative to the config file)
    into_target: str = "Stage"  # "Stage" or a sprite name
    into_name: str = ""  # the new file's name ("" = <into stem>-<model>.sb3)
    into_reader: bool = False  # also add the reader sprite (needs into_target = "Stage")


@dataclass
class ReportConfig:
    strict: bool = False  # like --strict: an exceeded limit or a problem (all-black lighting) exits 4
    html: bool = True  # write report.html (previews, limit bars, stage table, sweeps)
    preview_width: int = 320  # pixels per preview image (height is 3/4 of it)


@dataclass
class CacheConfig:
    """The stage cache (bake/cache/): each stage's output, keyed by everything it depends on."""

    # "" = <output folder>/.bake-cache/stages; a path (relative to this config file) = one cache
    # shared between bakes; "none" = no cache.
    dir: str = ""
    max_mb: float = 1024.0  # size cap in MiB: past it the least recently used entries are deleted
    # The bake's output folder (not a TOML key; `bake run` sets it): where the default cache lives.
    out_dir: Path | None = field(default=None, metadata={"internal": True})


@dataclass
class Config:
    input: InputConfig = field(default_factory=InputConfig)
    import_: ImportConfig = field(default_factory=ImportConfig)
    transform: TransformConfig = field(default_factory=TransformConfig)
    mesh: MeshConfig = field(default_factory=MeshConfig)
    bsp: BSPConfig = field(default_factory=BSPConfig)
    bvh: BVHConfig = field(default_factory=BVHConfig)
    lighting: LightingConfig = field(default_factory=LightingConfig)
    textures: TexturesConfig = field(default_factory=TexturesConfig)
    export: ExportConfig = field(default_factory=ExportConfig)
    report: ReportConfig = field(default_factory=ReportConfig)
    cache: CacheConfig = field(default_factory=CacheConfig)
    # Where the config came from (not a TOML key): paths in it are relative to this folder.
    base_dir: Path = field(default_factory=Path.cwd, metadata={"internal": True})
    source: Path | None = field(default=None, metadata={"internal": True})
    # Every key set explicitly, and where: "file" (the config) or the --set assignment that set it.
    given: dict[str, str] = field(default_factory=dict, metadata={"internal": True})


@dataclass(frozen=True)
class ImportJob:
    """The import stage's section, derived from ``[input]`` and ``[import]``."""

    path: Path
    format: str = "auto"
    strict: bool = True
    scene: int = -1


# TOML names that are Python keywords.
_ALIASES = {"import": "import_"}
_REVERSE = {v: k for k, v in _ALIASES.items()}


# --------------------------------------------------------------------------- loading
def _toml_name(attr: str) -> str:
    return _REVERSE.get(attr, attr)


def _fields(cls: type) -> dict[str, dataclasses.Field]:
    return {f.name: f for f in dataclasses.fields(cls) if not f.metadata.get("internal")}


def all_keys(cls: type = Config, prefix: str = "") -> list[str]:
    """Every dotted key the config accepts (for suggestions and docs)."""
    hints = get_type_hints(cls)
    out = []
    for name in _fields(cls):
        key = prefix + _toml_name(name)
        t = hints[name]
        if dataclasses.is_dataclass(t):
            out.extend(all_keys(t, key + "."))
        else:
            out.append(key)
    return out


# Words authors reach for, and the key bake calls that thing (matched per dotted component).
_SYNONYMS = {"occlusion": "ao", "ambient_occlusion": "ao", "ambientocclusion": "ao", "ssao": "ao",
             "shadow": "shadows", "bounce": "bounces", "gi": "bounces", "indirect": "bounces",
             "light": "lights", "lamp": "lights", "lamps": "lights", "simplification": "simplify",
             "decimate": "simplify", "decimation": "simplify", "texture": "textures", "uv": "uvs",
             "lightmaps": "lightmap", "colour": "color", "colours": "colors", "centre": "center",
             "triangulation": "triangulate", "cleanup": "clean", "output": "export", "model": "input"}


def _children(cls: Any) -> dict[str, Any]:
    """TOML name -> type of each key of a section (list[Section] as Section)."""
    hints = get_type_hints(cls)
    out = {}
    for name in _fields(cls):
        t = hints[name]
        if get_origin(t) in (list, typing.List) and get_args(t) and dataclasses.is_dataclass(get_args(t)[0]):
            t = get_args(t)[0]
        out[_toml_name(name)] = t
    return out


def _walk_suggestion(parts: list[str], *, table: bool) -> str | None:
    """Mend a dotted key one component at a time, from the top: a known name stays, a synonym
    or the closest name at that level replaces an unknown one (``lightning.enabled`` ->
    ``lighting.enabled``, ``lighting.occlusion`` -> ``lighting.ao``)."""
    cls: Any = Config
    out = []
    for i, raw in enumerate(parts):
        if not dataclasses.is_dataclass(cls):
            return None
        name, _, index = raw.partition("[")
        kids = _children(cls)
        last = i == len(parts) - 1
        # at the last component of a table, or on the way down, only sections fit; else keys
        fits = [k for k, t in kids.items() if dataclasses.is_dataclass(t) == (table or not last)]
        if name not in kids or (last and name not in fits):
            syn = _SYNONYMS.get(name.lower())
            if syn in fits:
                name = syn
            else:
                close = difflib.get_close_matches(name, fits, n=1, cutoff=0.6)
                if not close:
                    return None
                name = close[0]
        out.append(name + (f"[{index}" if index else ""))
        cls = kids[name]
    return ".".join(out)


def _suggest(key: str, candidates: list[str], *, table: bool = False) -> str:
    """``; did you mean 'x'?`` for an unknown ``key`` (a table: ``table=True``), or ""."""
    mended = _walk_suggestion(key.split("."), table=table)
    if mended and mended != key:
        return f"; did you mean [{mended}]?" if table else f"; did you mean '{mended}'?"
    close = difflib.get_close_matches(key, candidates, n=1, cutoff=0.5)
    if not close:
        # try the last component against the last components
        last = key.rsplit(".", 1)[-1]
        by_last = {c.rsplit(".", 1)[-1]: c for c in candidates}
        m = difflib.get_close_matches(last, list(by_last), n=1, cutoff=0.6)
        close = [by_last[m[0]]] if m else []
    return f"; did you mean '{close[0]}'?" if close else ""


def _typos(a: str, b: str) -> int:
    """Edits (insert, delete, substitute, swap two neighbours) from ``a`` to ``b``: ``angel`` is
    one swap from ``angle`` and two edits from ``range`` (difflib rates both alike). Names are a
    few letters long, so the quadratic table is nothing."""
    d = [[i + j if i * j == 0 else 0 for j in range(len(b) + 1)] for i in range(len(a) + 1)]
    for i in range(1, len(a) + 1):
        for j in range(1, len(b) + 1):
            d[i][j] = min(d[i - 1][j] + 1, d[i][j - 1] + 1, d[i - 1][j - 1] + (a[i - 1] != b[j - 1]))
            if i > 1 and j > 1 and a[i - 1] == b[j - 2] and a[i - 2] == b[j - 1]:
                d[i][j] = min(d[i][j], d[i - 2][j - 2] + 1)
    return d[len(a)][len(b)]


def _closest_field(name: str, fields: list[str]) -> list[str]:
    """The field a misspelt ``name`` most likely meant (fewest edits, then difflib's ratio), if
    it is within a third of the name's length; else difflib's closest (``[]`` if none)."""
    if not fields:
        return []
    best = min(fields, key=lambda f: (_typos(name, f), -difflib.SequenceMatcher(None, name, f).ratio()))
    if _typos(name, best) <= max(1, len(name) // 3):
        return [best]
    return difflib.get_close_matches(name, fields, n=1, cutoff=0.5)


class _Where:
    """Finds the line of a dotted key in the TOML text, for messages."""

    def __init__(self, text: str | None, path: Path | None, origin: str = "file"):
        self.lines = text.splitlines() if text else []
        self.path = path
        self.origin = origin  # "file", or the --set assignment being applied
        self.given: dict[str, str] = {}  # keys set, -> origin

    def line_of(self, key: str) -> int | None:
        if not self.lines:
            return None
        m = re.match(r"^(?P<table>[\w.]+)\[(?P<index>\d+)\](?:\.(?P<rest>.+))?$", key)
        if m:  # a field of the n-th [[table]] (e.g. lighting.lights[1].angle)
            return self._element_line(m.group("table"), int(m.group("index")), m.group("rest"))
        parts = key.split(".")
        last = re.escape(parts[-1].split("[")[0])
        section = ".".join(parts[:-1])
        current = ""
        found = None
        for i, raw in enumerate(self.lines, 1):
            s = raw.strip()
            m = re.match(r"^\[\[?\s*([^\]]+?)\s*\]?\]$", s)
            if m:
                current = m.group(1).replace(" ", "")
                if current == key:
                    return i
                continue
            if re.match(rf"^{last}\s*=", s) or re.match(rf"^[\w.]*\.{last}\s*=", s):
                if current == section or section.endswith(current) or not section or \
                        s.startswith(section.split(".", 1)[-1]):
                    return i
                if found is None:
                    found = i
        return found

    def is_header(self, key: str) -> bool:
        """Whether ``key`` is written as a ``[table]`` (or ``[[table]]``) header in the file."""
        line = self.line_of(key)
        return line is not None and self.lines[line - 1].strip().startswith("[")

    def _element_line(self, table: str, index: int, rest: str | None) -> int | None:
        """The line of ``rest`` (a field, or None for the element itself) in the ``index``-th
        ``[[table]]`` block; for an inline array (``lights = [{...}, ...]``) the line naming the
        field after the array starts, else the array's line."""
        seen = -1
        start = None
        field = None if rest is None else re.escape(rest.split(".")[0].split("[")[0])  # direction[1] -> direction
        for i, raw in enumerate(self.lines, 1):
            s = raw.strip()
            h = re.match(r"^\[\[\s*([^\]]+?)\s*\]\]$", s)
            if start is not None and re.match(r"^\[", s):
                break  # the next table header ends the block
            if h and h.group(1).replace(" ", "") == table:
                seen += 1
                if seen == index:
                    start = i
                    if rest is None:
                        return i
            elif start is not None and field is not None and re.match(rf"^{field}\s*=", s):
                return i
        if start is not None:
            return start
        name = table.rsplit(".", 1)[-1]
        for i, raw in enumerate(self.lines, 1):  # inline: lights = [{...}] or lighting.lights = [...]
            if re.match(rf"^\s*(?:[\w.]*\.)?{re.escape(name)}\s*=", raw):
                if field is not None:
                    for j in range(i, len(self.lines) + 1):
                        if re.search(rf"\b{field}\s*=", self.lines[j - 1]):
                            return j
                return i
        return None

    def error(self, key: str, msg: str) -> ConfigError:
        if self.origin != "file":
            return ConfigError(msg, key=key, origin=self.origin)
        return ConfigError(msg, path=self.path, line=self.line_of(key), key=key)


_PLURAL = {"int": "integers", "float": "numbers", "str": "strings", "bool": "true or false values"}


def _type_name(t: Any) -> str:
    if get_origin(t) in (Union, types.UnionType):
        words: list[str] = []
        for a in get_args(t):
            if a is bool:
                words += ["true", "false"]
            elif get_origin(a) is Literal:
                words += [repr(c) for c in get_args(a)]
            elif a is not type(None):
                words.append(_type_name(a))
        return ", ".join(words[:-1]) + " or " + words[-1] if len(words) > 1 else "".join(words)
    if get_origin(t) is Literal:
        return "one of " + ", ".join(repr(a) for a in get_args(t))
    if get_origin(t) in (list, typing.List):
        (inner,) = get_args(t) or (Any,)
        if get_origin(inner) is Literal:
            return "a list of values from " + ", ".join(repr(a) for a in get_args(inner))
        if isinstance(inner, type) and inner.__name__ in _PLURAL:
            return f"a list of {_PLURAL[inner.__name__]}"
        return f"a list of {_type_name(inner)}"
    if isinstance(t, type):
        return {"int": "an integer", "float": "a number", "str": "a string", "bool": "true or false"}.get(
            t.__name__, t.__name__)
    return str(t)


def _list_expected(t: Any, key: str, value: Any, example: Any) -> str:
    """What a list-typed key expects, said so a reader can write it: an array of tables as its
    double-bracket headers, a list of numbers with an example in the shape of its default."""
    (inner,) = get_args(t) or (Any,)
    if dataclasses.is_dataclass(inner):
        one = key.rsplit(".", 1)[-1].rstrip("s") or "entry"
        got = f"a single [{key}] table" if isinstance(value, dict) else f"{value!r}"
        return (f"an array of tables: each {one} is written under its own [[{key}]] header (double brackets); "
                f"got {got}")
    such = ""
    numbers = inner in (int, float)
    if not isinstance(value, (list, dict)):  # one value where a list goes: the list it may have meant
        such = f" such as {[value] * len(example) if numbers and isinstance(example, list) and example else [value]!r}"
    elif isinstance(example, list) and example:
        such = f" such as {example!r}"
    return f"{_type_name(t)}{such}, got {value!r}"


def _convert(value: Any, t: Any, key: str, where: _Where, example: Any = None) -> Any:
    origin = get_origin(t)
    if origin in (Union, types.UnionType):
        args = [a for a in get_args(t) if a is not type(None)]
        if value is None:
            return None
        if len(args) == 1:
            return _convert(value, args[0], key, where)
        for a in args:  # (bool | Literal["auto"]: the first that takes the value)
            try:
                return _convert(value, a, key, where)
            except ConfigError:
                continue
        raise where.error(key, f"expected {_type_name(t)}, got {value!r}")
    if origin is Literal:
        choices = get_args(t)
        if value not in choices:
            sugg = difflib.get_close_matches(str(value), [str(c) for c in choices], n=1)
            hint = f"; did you mean {sugg[0]!r}?" if sugg else ""
            raise where.error(key, f"expected {_type_name(t)}, got {value!r}{hint}")
        return value
    if origin in (list, typing.List):
        (inner,) = get_args(t) or (Any,)
        if not isinstance(value, list):
            raise where.error(key, "expected " + _list_expected(t, key, value, example))
        return [_convert(v, inner, f"{key}[{i}]", where) for i, v in enumerate(value)]
    if dataclasses.is_dataclass(t):
        if not isinstance(value, dict):
            raise where.error(key, f"expected a table [{key}], got {value!r}")
        return _build(t, value, key + ".", where)
    if t is bool:
        if not isinstance(value, bool):
            raise where.error(key, f"expected true or false, got {value!r}")
        return value
    if t is int:
        if isinstance(value, bool) or not isinstance(value, int):
            raise where.error(key, f"expected an integer, got {value!r}")
        return value
    if t is float:
        if isinstance(value, bool) or not isinstance(value, (int, float)):
            raise where.error(key, f"expected a number, got {value!r}")
        f = float(value)
        if f != f or f in (float("inf"), float("-inf")):
            raise where.error(key, f"expected a finite number, got {value!r}")
        return f
    if t is str:
        if not isinstance(value, str):
            raise where.error(key, f"expected a string, got {value!r}")
        return value
    return value


def _leaves(value: dict, prefix: str) -> list[str]:
    out = []
    for k, v in value.items():
        out.extend(_leaves(v, f"{prefix}.{k}") if isinstance(v, dict) and v else [f"{prefix}.{k}"])
    return out


def _build(cls: type, data: dict, prefix: str, where: _Where, base: Any = None) -> Any:
    fields = _fields(cls)
    hints = get_type_hints(cls)
    obj = base if base is not None else cls()
    for raw_key, value in data.items():
        attr = _ALIASES.get(raw_key, raw_key)
        key = prefix + raw_key
        if attr not in fields:
            if re.search(r"\[\d+\]\.$", prefix):  # inside [[...]]: the element's own fields, by name
                close = _closest_field(raw_key, all_keys(cls))
                hint = f"; did you mean '{close[0]}'?" if close else ""
                raise where.error(key, f"unknown key{hint} (an entry of [[{prefix.split('[')[0]}]] has "
                                  + ", ".join(all_keys(cls)) + ")")
            known = all_keys(Config)
            sub = [k for k in known if k.startswith(prefix)] if prefix else known
            leaves = _leaves(value, key) if isinstance(value, dict) else [key]
            # a [table] header in the file, or a table of several keys: mend the table's name;
            # a dotted key (--set lightning.enabled=true): mend the whole key
            if len(leaves) != 1 or (isinstance(value, dict) and where.is_header(key)):
                raise where.error(key, f"unknown table [{key}]" + _suggest(key, sub or known, table=True))
            raise where.error(leaves[0], "unknown key" + _suggest(leaves[0], known))
        t = hints[attr]
        if dataclasses.is_dataclass(t) and isinstance(value, dict):
            setattr(obj, attr, _build(t, value, key + ".", where, base=getattr(obj, attr)))
        else:
            setattr(obj, attr, _convert(value, t, key, where, example=getattr(obj, attr, None)))
            where.given[key] = where.origin
    return obj


def load(path: str | Path | None = None, overrides: list[str] | None = None,
         data: dict | None = None) -> Config:
    """Load a config file (or none: defaults), then apply ``key=value`` overrides."""
    text = None
    src = None
    if path is not None:
        src = Path(path)
        try:
            raw = src.read_bytes()
        except OSError as e:
            raise ConfigError(f"cannot read config: {e.strerror}", path=src) from None
        try:
            text = raw.decode("utf-8")
        except UnicodeDecodeError as e:
            raise ConfigError(f"config is not UTF-8 text (byte {e.start})", path=src) from None
        try:
            data = tomllib.loads(text)
        except tomllib.TOMLDecodeError as e:
            m = re.search(r"line (\d+)", str(e))
            raise ConfigError(f"not valid TOML: {e}", path=src,
                              line=int(m.group(1)) if m else None) from None
    where = _Where(text, src)
    cfg = _build(Config, data or {}, "", where)
    cfg.given.update(where.given)
    if src is not None:
        cfg.base_dir = src.resolve().parent
        cfg.source = src.resolve()
    for key in FILE_RELATIVE_KEYS:  # paths in a config are relative to it (input.path: see pipeline)
        val = get_key(cfg, key)
        if val and val.strip().lower() != "none" and not Path(val).expanduser().is_absolute():
            _set_key(cfg, key, str(cfg.base_dir / Path(val).expanduser()))
    for ov in overrides or []:
        apply_override(cfg, ov)
    validate(cfg)
    return cfg


def parse_value(text: str) -> Any:
    try:
        return tomllib.loads(f"v = {text}")["v"]
    except tomllib.TOMLDecodeError:
        return text


def apply_override(cfg: Config, assignment: str) -> None:
    """Apply ``section.key=value`` (value parsed as TOML, else a string)."""
    if "=" not in assignment:
        raise ConfigError(f"--set expects section.key=value, got {assignment!r}")
    key, text = assignment.split("=", 1)
    key = key.strip()
    m = re.match(r"^(?P<head>[\w.]+)\[(?P<n>\d+)\]\.(?P<rest>[\w.]+)$", key)
    if m:  # a field of one element of an array of tables: lighting.lights[0].angle=2
        where = _Where(None, None, origin=f"--set {key}={text.strip()}")
        _override_element(cfg, m.group("head"), int(m.group("n")), m.group("rest"), parse_value(text.strip()),
                          where)
        cfg.given.update(where.given)
        return
    parts = key.split(".")
    nested: dict = {}
    cur = nested
    for p in parts[:-1]:
        cur = cur.setdefault(p, {})
    value = parse_value(text.strip())
    if key in PATH_KEYS and isinstance(value, str) and value and value.strip().lower() != "none":
        # a path typed on the command line is relative to the current folder
        value = str((Path.cwd() / Path(value).expanduser()).absolute())
    cur[parts[-1]] = value
    where = _Where(None, None, origin=f"--set {key}={text.strip()}")
    _build(Config, nested, "", where, base=cfg)
    cfg.given.update(where.given)


# Keys that hold paths. From --set they resolve against the current folder; in a config file,
# FILE_RELATIVE_KEYS against the config's folder (input.path too, in the pipeline; textures.texture
# is relative to the model's folder, see TexturesConfig).
PATH_KEYS = ("input.path", "export.into", "textures.texture", "textures.lightmap.cache_dir")
FILE_RELATIVE_KEYS = ("export.into", "textures.lightmap.cache_dir")


def _set_key(cfg: Config, key: str, value: Any) -> None:
    obj: Any = cfg
    parts = key.split(".")
    for p in parts[:-1]:
        obj = getattr(obj, _ALIASES.get(p, p))
    setattr(obj, _ALIASES.get(parts[-1], parts[-1]), value)


def origin(cfg: Config, key: str) -> str | None:
    """Where ``key`` was set: "file", "--set KEY=VALUE", or None (its default)."""
    return cfg.given.get(key)


def error_at(cfg: Config, key: str, msg: str) -> ConfigError:
    """A range error on ``key`` placed where the value came from: the config file and the key's
    line in it, or the --set assignment on the command line (or just the key, for a default)."""
    where = cfg.given.get(key)
    if where is None and "[" in key:  # lighting.lights[0].color: the light's table
        where = next((v for k, v in cfg.given.items() if k.startswith(key.split("]")[0] + "]")), None)
    if where is not None and where != "file":
        return ConfigError(msg, key=key, origin=where)
    if cfg.source is None:
        return ConfigError(msg, key=key)
    try:
        text = cfg.source.read_text("utf-8")
    except (OSError, UnicodeDecodeError):
        text = None
    line = _Where(text, cfg.source).line_of(key) if where == "file" or where is None else None
    return ConfigError(msg, path=cfg.source, line=line, key=key)


def _element_class(obj: Any, attr: str, key: str) -> type:
    """The dataclass of the elements of the list field ``attr`` (e.g. LightConfig)."""
    t = get_type_hints(type(obj)).get(attr) if dataclasses.is_dataclass(obj) else None
    args = get_args(t) if t is not None and get_origin(t) in (list, typing.List) else ()
    if not args or not dataclasses.is_dataclass(args[0]):
        raise ConfigError("unknown key" + _suggest(key, all_keys()), key=key)
    return args[0]


def _override_element(cfg: Config, head: str, n: int, rest: str, value: Any, where: "_Where | None" = None) -> None:
    """``--set lighting.lights[n].field=value``: set a field of element ``n``; ``n`` equal to
    the number of elements adds one with the defaults."""
    parts = head.split(".")
    obj: Any = get_key(cfg, ".".join(parts[:-1])) if len(parts) > 1 else cfg
    attr = _ALIASES.get(parts[-1], parts[-1])
    cls = _element_class(obj, attr, f"{head}[{n}].{rest}")
    items = getattr(obj, attr)
    if n > len(items):
        raise ConfigError(f"there are {len(items)} element(s); [{len(items)}] adds one", key=f"{head}[{n}]")
    elem = items[n] if n < len(items) else cls()
    nested: dict = {}
    cur = nested
    rparts = rest.split(".")
    for p in rparts[:-1]:
        cur = cur.setdefault(p, {})
    cur[rparts[-1]] = value
    _build(cls, nested, f"{head}[{n}].", where or _Where(None, None), base=elem)
    if n == len(items):
        items.append(elem)


def key_defaults() -> list[tuple[str, Any]]:
    """Every key with its default, for ``bake keys``: the keys of :func:`all_keys`, and for an
    array of tables (``[[lighting.lights]]``) each field of one element as ``lighting.lights[].kind``."""
    cfg = Config()
    out: list[tuple[str, Any]] = []
    for key in all_keys():
        val = get_key(cfg, key)
        out.append((key, to_dict(val)))
        *path, last = key.split(".")
        owner = get_key(cfg, ".".join(path)) if path else cfg
        t = get_type_hints(type(owner)).get(_ALIASES.get(last, last))
        args = get_args(t) if get_origin(t) in (list, typing.List) else ()
        if args and dataclasses.is_dataclass(args[0]):
            elem = args[0]()
            out.extend((f"{key}[].{k}", to_dict(get_key(elem, k))) for k in all_keys(args[0]))
    return out


def get_key(cfg: Any, key: str) -> Any:
    """The value of a dotted key (``lighting.lights[0].angle`` reads one element)."""
    obj: Any = cfg
    for p in key.split("."):
        m = re.match(r"^(\w+)\[(\d+)\]$", p)
        if m and dataclasses.is_dataclass(obj) and m.group(1) in _fields(type(obj)):
            items = getattr(obj, m.group(1))
            if not isinstance(items, list) or int(m.group(2)) >= len(items):
                raise ConfigError(f"no element {m.group(2)} (there are {len(items)})", key=key)
            obj = items[int(m.group(2))]
            continue
        attr = _ALIASES.get(p, p)
        if not dataclasses.is_dataclass(obj) or attr not in _fields(type(obj)):
            raise ConfigError("unknown key" + _suggest(key, all_keys()), key=key)
        obj = getattr(obj, attr)
    return obj


# Names in the output folder that every bake writes (the reports, the list and asset folders,
# bake watch's script, the sweeps, the xatlas cache and the manifest of what the bake wrote,
# bake/outputs/write.py's MANIFEST): no configured output name may take one.
RESERVED_OUTPUT_NAMES = ("report.json", "report.md", "report.html", "report-live.js", "lists", "assets", "sweeps",
                         ".bake-cache", ".bake-manifest.json")


def validate(cfg: Config) -> None:
    """Range checks that types alone cannot express."""
    def need(cond: bool, key: str, msg: str) -> None:
        if not cond:
            raise error_at(cfg, key, msg)

    need(cfg.import_.scene >= -1, "import.scene", "must be a scene number >= 0, or -1 for the file's default scene")
    need(cfg.transform.scale > 0, "transform.scale", "must be > 0")
    need(cfg.transform.fit >= 0, "transform.fit", "must be >= 0")
    need(cfg.mesh.clean.weld_tolerance >= 0, "mesh.clean.weld_tolerance", "must be >= 0")
    need(1 <= cfg.export.precision <= 15, "export.precision", "must be between 1 and 15")
    need(cfg.export.pack_max_items >= 0, "export.pack_max_items", "must be >= 0 (0 = no limit)")
    need(16 <= cfg.report.preview_width <= 2048, "report.preview_width", "must be between 16 and 2048")
    s = cfg.mesh.simplify
    need(s.target_triangles >= 0, "mesh.simplify.target_triangles", "must be >= 0")
    need(0 <= s.target_ratio <= 1, "mesh.simplify.target_ratio", "must be between 0 and 1")
    need(s.max_error >= 0, "mesh.simplify.max_error", "must be >= 0")
    need(s.fit_iterations >= 0, "mesh.simplify.fit_iterations", "must be >= 0")
    need(s.refine_rounds >= 0, "mesh.simplify.refine_rounds", "must be >= 0")
    need(s.peak_rounds >= 0, "mesh.simplify.peak_rounds", "must be >= 0")
    need(s.error_ceiling >= 0, "mesh.simplify.error_ceiling", "must be >= 0 (0 = none)")
    need(s.error_samples >= 100, "mesh.simplify.error_samples", "must be >= 100")
    need(cfg.bsp.candidates >= 0, "bsp.candidates", "must be >= 0 (0 = all)")
    need(cfg.bsp.leaf_max >= 1, "bsp.leaf_max", "must be >= 1")
    need(0 < cfg.bsp.epsilon < 1e-2, "bsp.epsilon", "must be > 0 and < 0.01")
    need(0 <= cfg.bsp.min_area < 1e-4, "bsp.min_area", "must be >= 0 and < 1e-4")
    need(2 <= cfg.bsp.plane_decimals <= 12, "bsp.plane_decimals", "must be between 2 and 12")
    need(0.87 * 10.0 ** -cfg.bsp.plane_decimals < cfg.bsp.epsilon, "bsp.plane_decimals",
         f"rounding normals to {cfg.bsp.plane_decimals} decimals tilts planes by up to "
         f"{0.87 * 10.0 ** -cfg.bsp.plane_decimals:.2g}, more than bsp.epsilon = {cfg.bsp.epsilon:g}; "
         "raise one of them")
    need(cfg.bsp.split_weight >= 0 and cfg.bsp.balance_weight >= 0, "bsp.split_weight",
         "weights must be >= 0")
    need(cfg.bsp.edge_planes >= 0, "bsp.edge_planes", "must be >= 0 (0 = face planes only)")
    need(cfg.bsp.edge_plane_cost >= 0, "bsp.edge_plane_cost", "must be >= 0")
    need(cfg.bsp.score_sample >= 0, "bsp.score_sample", "must be >= 0 (0 = score on every face)")
    need(cfg.bsp.score_refine >= 1, "bsp.score_refine", "must be >= 1")
    need(cfg.bsp.ensemble >= 1, "bsp.ensemble", "must be >= 1 (1 = off)")
    need(cfg.bsp.ensemble_max >= 0, "bsp.ensemble_max", "must be >= 0")
    need(cfg.bsp.thorough_faces >= 0, "bsp.thorough_faces", "must be >= 0 (0 = never)")
    need(cfg.bsp.thorough_edge_factor >= 1, "bsp.thorough_edge_factor", "must be >= 1")
    need(cfg.cache.max_mb > 0, "cache.max_mb", "must be > 0 (cache.dir = \"none\" turns the cache off)")
    for key, name, blank in (("export.json_name", cfg.export.json_name, False),
                             ("export.sb3_name", cfg.export.sb3_name, True),
                             ("export.into_name", cfg.export.into_name, True)):
        need(bool(name) or blank, key, "must be a file name (it is empty)")
        need(not name or (Path(name).name == name and "\\" not in name and name not in (".", "..")), key,
             "must be a file name, not a path")
        need(name.lower() not in RESERVED_OUTPUT_NAMES, key,
             f"'{name}' is a name the bake writes itself ({', '.join(RESERVED_OUTPUT_NAMES)}); choose another")
        suffix = ".json" if key == "export.json_name" else ".sb3"
        need(not name or (name.lower().endswith(suffix) and not name.startswith(".")), key,
             f"must be a visible file name ending in {suffix} (got '{name}': Scratch and the summary look for "
             f"{suffix} files)")
    seen: dict[str, tuple[str, str]] = {}
    for f in dataclasses.fields(ListNames):
        name = getattr(cfg.export.names, f.name)
        key = f"export.names.{_toml_name(f.name)}"
        need(name.strip().strip(".") != "", key, f"must be a list name (got {name!r})")
        # lists/<name>.txt: names that differ only in case are one file on Windows and macOS
        other_key, other = seen.setdefault(name.casefold(), (key, name))
        need(other == name, key, f"'{name}' differs from {other_key} = '{other}' only in case (one list file on "
                                 "Windows and macOS); choose another")
    for i, lt in enumerate(cfg.lighting.lights):
        need(len(lt.color) == 3, f"lighting.lights[{i}].color", "must be [r, g, b]")
        need(len(lt.direction) == 3, f"lighting.lights[{i}].direction", "must be [x, y, z]")
        need(len(lt.position) == 3, f"lighting.lights[{i}].position", "must be [x, y, z]")


def to_dict(obj: Any) -> Any:
    """The config as plain data (TOML names), for the report."""
    if dataclasses.is_dataclass(obj):
        return {_toml_name(f): to_dict(getattr(obj, f)) for f in _fields(type(obj))}
    if isinstance(obj, list):
        return [to_dict(v) for v in obj]
    if isinstance(obj, Path):
        return str(obj)
    return obj


def numeric_keys() -> list[str]:
    """Keys whose value is an int or float (what ``bake sweep --vary`` accepts)."""
    out = []

    def walk(cls: type, prefix: str) -> None:
        hints = get_type_hints(cls)
        for name in _fields(cls):
            t = hints[name]
            key = prefix + _toml_name(name)
            if dataclasses.is_dataclass(t):
                walk(t, key + ".")
            elif t in (int, float):
                out.append(key)

    walk(Config, "")
    return out


__all__ = ["Config", "load", "apply_override", "get_key", "all_keys", "key_defaults", "to_dict", "numeric_keys",
           "parse_value", "origin", "error_at", "PATH_KEYS", "Optional"]
