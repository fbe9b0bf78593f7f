"""The config's schema: every section as a dataclass, with its defaults and the range check of
its own keys (``check``). The loader (``bake.config.loader``) reads TOML and ``--set`` into it.

Stage owners add their keys to their own section class here, with a line of ``check`` for a
range; a stage that brings a section of its own hands it in through the registry
(``StageSpec.config``, see :func:`use_stage_sections`). The range checks that need a stage's own
constants live with the stage (``StageSpec.check``).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, Callable, Literal

# how a section's check reports a key out of range: need(ok, key relative to the section, message)
Need = Callable[[bool, str, str], None]


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

    def check(self, need: Need) -> None:
        need(self.scene >= -1, "scene", "must be a scene number >= 0, or -1 for the file's default scene")


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

    def check(self, need: Need) -> None:
        need(self.scale > 0, "scale", "must be > 0")
        need(self.fit >= 0, "fit", "must be >= 0")


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

    def check(self, need: Need) -> None:
        need(self.weld_tolerance >= 0, "weld_tolerance", "must be >= 0")


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
    # (error_bound below proves an upper bound of the true one). A small input is measured with
    # fewer: 4 points per input triangle, at least 2,000 (details.error_samples says how many).
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

    def check(self, need: Need) -> None:
        need(self.target_triangles >= 0, "target_triangles", "must be >= 0")
        need(0 <= self.target_ratio <= 1, "target_ratio", "must be between 0 and 1")
        need(self.max_error >= 0, "max_error", "must be >= 0")
        need(self.fit_iterations >= 0, "fit_iterations", "must be >= 0")
        need(self.refine_rounds >= 0, "refine_rounds", "must be >= 0")
        need(self.peak_rounds >= 0, "peak_rounds", "must be >= 0")
        need(self.error_ceiling >= 0, "error_ceiling", "must be >= 0 (0 = none)")
        need(self.error_samples >= 100, "error_samples", "must be >= 100")


@dataclass
class HiddenBox:
    """A box of eyes for the hidden-geometry stage (scene coordinates, as transformed)."""

    min: list[float] = field(default_factory=list)  # both must be given: [x, y, z]
    max: list[float] = field(default_factory=list)

    def check(self, need: Need) -> None:
        for key, v in (("min", self.min), ("max", self.max)):
            need(len(v) == 3, key, f"must be [x, y, z] (got {v!r})" if v else "is missing: give it as [x, y, z]")
            need(all(math.isfinite(x) and abs(x) <= 1e15 for x in v), key,
                 f"must be finite coordinates of at most 1e15 (got {v!r})")
        need(all(a <= b for a, b in zip(self.min, self.max)), "max",
             f"must be >= min in every coordinate (min = {self.min!r}, max = {self.max!r})")


@dataclass
class HiddenConfig:
    """Hidden-geometry removal (bake/mesh/hidden/, docs/hidden.md): keep the triangles an eye in the
    view region can see, drop the rest. Off by default."""

    enabled: bool = False
    # The view region, a union: eyes anywhere outside the model (on a sphere around it: every
    # direction), the reader's green-flag camera, the given points and the given boxes.
    outside: bool = True
    camera: bool = False
    points: list[list[float]] = field(default_factory=list)  # [[x, y, z], ...]
    boxes: list[HiddenBox] = field(default_factory=list)  # [[mesh.hidden.boxes]] min = [...], max = [...]
    eyes: int = 64  # eyes sampled on the outside sphere and in each box
    samples: int = 2  # rays per eye and triangle, aimed at stratified points of the triangle
    # rounds of more eyes (refine x eyes, and eyes around the witnesses of the seen neighbours) aimed
    # at the unseen triangles that touch a seen one; then witness rounds alone while they find any
    refine: int = 8
    refine_rounds: int = 3
    # cut triangles that pass through each other along each other's planes first, so that the
    # pieces inside are dropped and those that show kept (a source that loses no piece stays whole)
    trim: bool = False
    # a partly kept source whose kept part takes more triangles than this (its pieces or its
    # redrawn outline) is written whole instead, as without trimming (0 = no limit): the tree cuts
    # a whole triangle by one plane into at most 3
    trim_most: int = 3
    # "culled": a single-sided triangle is drawn (and hides what is behind it) only from its front,
    # as the reader sprite and bake.render draw it; "drawn": every triangle from both sides
    back_faces: Literal["culled", "drawn"] = "culled"
    # in a lit bake, also keep the hidden triangles that shadow or bounce light onto kept ones
    keep_casters: bool = True
    caster_samples: int = 16  # hemisphere rays per sample point of a kept triangle (AO, sky, bounces)
    # the proof: held-out eyes (not those that decided), each with a grid of pixels: a square view
    # just holding the model's bounding sphere from an outside eye, a cube map (6 faces) around an
    # eye in a box, at a point or at the camera
    holdout_eyes: int = 64
    holdout_pixels: int = 64  # pixels along the side of a view or of a cube-map face
    pictures: int = 3  # held-out eyes whose pictures (with and without the removal) go into the report
    # with bsp.enabled: build the bake's BSP tree on the stage's input and on its output too, so the
    # report gives the splits' inflation with and without the removal (costs two tree builds)
    bsp_proof: bool = True
    threads: int = 0  # 0 = all cores
    seed: int = 0

    def check(self, need: Need) -> None:
        need(self.outside or self.camera or bool(self.points) or bool(self.boxes), "outside",
             "the view region is empty: set outside = true or camera = true, or give points or "
             "[[mesh.hidden.boxes]]")
        for i, p in enumerate(self.points):
            need(len(p) == 3, f"points[{i}]", f"must be [x, y, z] (got {p!r})")
            need(all(math.isfinite(x) and abs(x) <= 1e15 for x in p), f"points[{i}]",
                 f"must be finite coordinates of at most 1e15 (got {p!r})")
        need(1 <= self.eyes <= 100_000, "eyes", f"must be between 1 and 100000 (got {self.eyes})")
        need(1 <= self.samples <= 64, "samples", f"must be between 1 and 64 (got {self.samples})")
        need(self.trim_most >= 0, "trim_most", f"must be 0 (no limit) or more (got {self.trim_most})")
        need(self.refine >= 0, "refine", f"must be >= 0 (0 = no refinement; got {self.refine})")
        need(self.refine_rounds >= 0, "refine_rounds", f"must be >= 0 (got {self.refine_rounds})")
        need(0 <= self.caster_samples <= 1024, "caster_samples",
             f"must be between 0 and 1024 (got {self.caster_samples})")
        need(self.holdout_eyes >= 0, "holdout_eyes", f"must be >= 0 (0 = no proof; got {self.holdout_eyes})")
        need(2 <= self.holdout_pixels <= 512, "holdout_pixels",
             f"must be between 2 and 512 (got {self.holdout_pixels})")
        need(0 <= self.pictures <= 16, "pictures", f"must be between 0 and 16 (got {self.pictures})")
        need(self.seed >= 0, "seed", f"must be >= 0 (got {self.seed})")
        need(self.threads >= 0, "threads", f"must be >= 0 (0 = all cores; got {self.threads})")


@dataclass
class MeshConfig:
    triangulate: TriangulateConfig = field(default_factory=TriangulateConfig)
    clean: CleanConfig = field(default_factory=CleanConfig)
    hidden: HiddenConfig = field(default_factory=HiddenConfig)
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

    def check(self, need: Need) -> None:
        need(self.candidates >= 0, "candidates", "must be >= 0 (0 = all)")
        need(self.seed >= 0, "seed", f"must be >= 0 (got {self.seed})")
        need(self.leaf_max >= 1, "leaf_max", "must be >= 1")
        need(0 < self.epsilon < 1e-2, "epsilon", "must be > 0 and < 0.01")
        need(0 <= self.min_area < 1e-4, "min_area", "must be >= 0 and < 1e-4")
        need(2 <= self.plane_decimals <= 12, "plane_decimals", "must be between 2 and 12")
        need(0.87 * 10.0 ** -self.plane_decimals < self.epsilon, "plane_decimals",
             f"rounding normals to {self.plane_decimals} decimals tilts planes by up to "
             f"{0.87 * 10.0 ** -self.plane_decimals:.2g}, more than bsp.epsilon = {self.epsilon:g}; "
             "raise one of them")
        need(self.split_weight >= 0 and self.balance_weight >= 0, "split_weight", "weights must be >= 0")
        need(self.edge_planes >= 0, "edge_planes", "must be >= 0 (0 = face planes only)")
        need(self.edge_plane_cost >= 0, "edge_plane_cost", "must be >= 0")
        need(self.score_sample >= 0, "score_sample", "must be >= 0 (0 = score on every face)")
        need(self.score_refine >= 1, "score_refine", "must be >= 1")
        need(self.ensemble >= 1, "ensemble", "must be >= 1 (1 = off)")
        need(self.ensemble_max >= 0, "ensemble_max", "must be >= 0")
        need(self.thorough_faces >= 0, "thorough_faces", "must be >= 0 (0 = never)")
        need(self.thorough_edge_factor >= 1, "thorough_edge_factor", "must be >= 1")


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

    def check(self, need: Need) -> None:
        need(len(self.color) == 3, "color", "must be [r, g, b]")
        need(len(self.direction) == 3, "direction", "must be [x, y, z]")
        need(len(self.position) == 3, "position", "must be [x, y, z]")


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
    # The bake's output folder and whether the lighting stage will fill the atlas: not TOML keys,
    # the registry's section of the textures stage fills them in from the config (``Config.out_dir``,
    # lighting.target) -- nothing else writes them.
    # The output folder: where the default cache lives.
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


def split_problems(names: Any, faces: str) -> list[tuple[str, str]]:
    """(key, why) for each array of names the layout cannot take."""
    from ..scratch.layout import SOUP_SPLITS, SPLITS  # (the layouts' table lives with the layouts)

    table = SOUP_SPLITS if faces == "soup" else SPLITS
    out = []
    for f in dataclasses.fields(names):
        value = getattr(names, f.name)
        if isinstance(value, str):
            continue
        counts = table.get(f.name, {})
        if len(value) not in counts:
            if not counts:
                why = ("holds one item per record, so it cannot be split; give one name"
                       if f.name == "triangles" else "cannot be split; give one name")
            else:
                ways = "; ".join(f"{k} names ({comp} per {rec})" for k, (comp, rec) in sorted(counts.items(),
                                                                                            reverse=True))
                why = f"an array of names splits the list by component: {ways}; got {len(value)}"
            out.append((f.name, why))
    return out


@dataclass
class ListNames:
    # A list with a stride may be given an array of names, one list per component
    # (bake/scratch/layout.py, docs/engines.md): vertices = ["X", "Y", "Z"].
    vertices: str | list[str] = "verts"
    triangles: str | list[str] = "tris"
    materials: str = "mat colors"
    triangle_colors: str = "tri colors"
    vertex_colors: str = "vert colors"
    uvs: str | list[str] = "tri uvs"
    lightmap_uvs: str | list[str] = "lightmap uvs"
    two_sided: str = "mat two-sided"
    quads: str | list[str] = "quads"
    ngons: str = "ngons"
    packed: str = "packed lists"  # with export.pack: the packed texts the loader decodes

    def check(self, need: Need) -> None:
        seen: dict[str, tuple[str, str]] = {}
        for f in dataclasses.fields(self):
            value = getattr(self, f.name)
            for i, name in enumerate([value] if isinstance(value, str) else value):
                key = f.name if isinstance(value, str) else f"{f.name}[{i}]"
                need(name.strip().strip(".") != "", key, f"must be a list name (got {name!r})")
                # lists/<name>.txt: names that differ only in case are one file on Windows and macOS
                other_key, other = seen.setdefault(name.casefold(), (f"export.names.{key}", name))
                need(other_key == f"export.names.{key}", key,
                     f"'{name}' differs from {other_key} = '{other}' only in case (one list "
                     "file on Windows and macOS); choose another" if other != name else
                     f"'{name}' is also {other_key}: two lists cannot share a name")


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
    # "soup": unindexed, for engines without an index list: names.vertices holds each written
    # triangle's corner positions (x1, y1, z1, x2, y2, z2, x3, y3, z3) and names.triangles its
    # material number (docs/engines.md).
    faces: Literal["triangles", "quads", "ngons", "soup"] = "triangles"
    # The first vertex and material number in the triangle, quad and n-gon lists (and the soup's
    # material list): 1 (Scratch's items) or 0 (engines that add 1 when they read). The BSP and BVH
    # lists keep Scratch's 1-based item and triangle numbers (their walk blocks address items).
    index_base: int = 1
    # The reader sprite's textured filler (docs/formats-textures.md, "Drawing a textured triangle"):
    # with a texture or a lightmap in the project, the green flag draws every triangle by square
    # cells of this many stage pixels, each the nearest texel at its centre; 0 = flat colours only.
    texel_size: int = 2
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
    # What the .sb3's green flag draws: "raster" = the pen renderer (`render`: every triangle
    # filled, in BSP order); "bvh" = the reader's BVH ray-traced view (`bvh view`: one ray per
    # cell of `bvh_cell` x `bvh_cell` stage pixels through `bvh ray`, each cell stamped with the
    # colour of the triangle it hits; needs bvh.enabled, else the bake warns and draws the raster).
    # report.html shows the same picture computed in Python (bake/outputs/bvh_view.py).
    green_flag: Literal["raster", "bvh"] = "raster"
    # The BVH view's cell size in stage pixels (3..60; the sprite's variable `bvh cell`): 8 casts
    # 60 x 45 rays. Below 3 the pen's round dots cannot cover a cell without reaching the centre
    # of the next one (docs/formats-bvh.md, "The BVH view").
    bvh_cell: int = 8
    # Bake into an existing project: a new .sb3 with our lists put into `into_target` (replacing
    # same-named lists, monitors hidden), everything else untouched. The input is never written.
    into: str = ""  # path of the .sb3 (relative to the config file)
    into_target: str = "Stage"  # "Stage" or a sprite name
    into_name: str = ""  # the new file's name ("" = <into stem>-<model>.sb3)
    into_reader: bool = False  # also add the reader sprite (needs into_target = "Stage")

    def check(self, need: Need) -> None:
        need(1 <= self.precision <= 15, "precision", "must be between 1 and 15")
        need(self.texel_size in (0, 1, 2, 3, 4, 5, 6, 8, 10, 12), "texel_size",
             f"must divide the stage's 480 x 360 pixels: 1, 2, 3, 4, 5, 6, 8, 10 or 12 (0 = flat colours only; "
             f"got {self.texel_size!r})")
        need(self.index_base in (0, 1) and not isinstance(self.index_base, bool), "index_base",
             f"must be 1 (Scratch's first item) or 0 (got {self.index_base!r})")
        for key, why in split_problems(self.names, self.faces):
            need(False, f"names.{key}", why)
        need(self.pack_max_items >= 0, "pack_max_items", "must be >= 0 (0 = no limit)")
        need(3 <= self.bvh_cell <= 60, "bvh_cell", f"must be between 3 and 60 stage pixels (got {self.bvh_cell})")
        for key, name, blank in (("json_name", self.json_name, False), ("sb3_name", self.sb3_name, True),
                                 ("into_name", self.into_name, True)):
            need(bool(name) or blank, key, "must be a file name (it is empty)")
            need(not name or (Path(name).name == name and "\\" not in name and name not in (".", "..")), key,
                 "must be a file name, not a path")
            need(name.lower() not in RESERVED_OUTPUT_NAMES, key,
                 f"'{name}' is a name the bake writes itself ({', '.join(RESERVED_OUTPUT_NAMES)}); choose another")
            suffix = ".json" if key == "json_name" else ".sb3"
            need(not name or (name.lower().endswith(suffix) and not name.startswith(".")), key,
                 f"must be a visible file name ending in {suffix} (got '{name}': Scratch and the summary look for "
                 f"{suffix} files)")


@dataclass
class ReportConfig:
    strict: bool = False  # like --strict: an exceeded limit or a problem (all-black lighting) exits 4
    html: bool = True  # write report.html (previews, limit bars, stage table, sweeps)
    preview_width: int = 320  # pixels per preview image (height is 3/4 of it)

    def check(self, need: Need) -> None:
        need(16 <= self.preview_width <= 2048, "preview_width", "must be between 16 and 2048")


@dataclass
class CacheConfig:
    """The stage cache (bake/cache/): each stage's output, keyed by everything it depends on."""

    # "" = <output folder>/.bake-cache/stages; a path (relative to this config file) = one cache
    # shared between bakes; "none" = no cache.
    dir: str = ""
    max_mb: float = 1024.0  # size cap in MiB: past it the least recently used entries are deleted

    def check(self, need: Need) -> None:
        need(self.max_mb > 0, "max_mb", "must be > 0 (cache.dir = \"none\" turns the cache off)")


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
    # The folder the command writes the bake to (not a TOML key: ``bake run --out``, ``bake watch``,
    # ``bake sweep``): the default stage cache and xatlas cache live in it. None: no folder.
    out_dir: Path | None = field(default=None, metadata={"internal": True})

    def __getattr__(self, name: str) -> Any:
        """A section a stage brings (:func:`stage_sections`), with its defaults until set."""
        if not name.startswith("__"):
            cls = stage_sections().get(name)
            if cls is not None:
                section = cls()
                object.__setattr__(self, name, section)
                return section
        raise AttributeError(name)


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


# The sections stages bring themselves (``StageSpec.config``), table name -> dataclass: set by the
# registry (``bake.stages``) whenever its table changes. They are read, checked, listed (``bake
# keys``) and reported like the built-in ones. (The registry tells the loader, not the other way
# round: the registry leads to every stage, and every stage reads its section from here.)
_STAGE_SECTIONS: dict[str, type] = {}
# and the range checks the stages hold for their sections (``StageSpec.check``), run by
# :func:`validate` after its own, whether the stage will run or not
_STAGE_CHECKS: list[Any] = []


def use_stage_sections(sections: dict[str, type], checks: Any = None) -> None:
    """Called by the registry with the sections of its stages and a function that runs their
    range checks on a config."""
    clash = set(sections) & {f.name for f in dataclasses.fields(Config)}
    if clash:
        raise ValueError(f"a stage's section takes the name of a built-in one: {sorted(clash)}")
    _STAGE_SECTIONS.clear()
    _STAGE_SECTIONS.update(sections)
    _STAGE_CHECKS[:] = [checks] if checks is not None else []


def stage_sections() -> dict[str, type]:
    return dict(_STAGE_SECTIONS)


# Names in the output folder that every bake writes (the reports, the list and asset folders,
# bake watch's script, the sweeps, the xatlas cache and the manifest of what the bake wrote,
# bake/outputs/write.py's MANIFEST): no configured output name may take one.
RESERVED_OUTPUT_NAMES = ("report.json", "report.md", "report.html", "report-live.js", "lists", "assets", "sweeps",
                         ".bake-cache", ".bake-manifest.json")
