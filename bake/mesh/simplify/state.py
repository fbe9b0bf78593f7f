"""What the phases of the simplify stage hand each other: :class:`Ctx`, what every attempt
shares (the input, its index and grid, the vertices nothing moves, the border chains, the
caches and the seconds per phase), built once by :func:`context`; and :class:`Out`, a result
after the library and the repairs (a library's own result is library.Raw)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from ...config import SimplifyConfig
from . import repair
from .error import FlipResult, SurfaceIndex, edge_counts
from .inputs import Prepared, nonmanifold_vertices, region_edge_vertices, wedges
from .measure import SEEDS, HausdorffResult, surface_grid

PHASES = ("library", "repair", "check", "fit", "measure")  # the record's *_seconds
# The least-squares fit pairs at most this many of the input's points with the result (and a
# third as many random points of the result with the input).
_FIT_POINTS = 60000
# The measure's grid on the input (and what scales with it: the simplified side's grid, the flip
# check's points, the proven bound's budget) has at most this many points per input triangle
# (and at least _MIN_SAMPLES): a mesh of a few hundred triangles is covered many times over by
# error_samples = 20,000 points (Suzanne, 968 triangles: 21 per triangle); the refinement around
# the peaks, not the grid, finds the maximum there (issue 41). Meshes of at least
# error_samples / _SAMPLES_PER_TRIANGLE triangles (5,000 with the default) are measured as before.
_SAMPLES_PER_TRIANGLE = 4
_MIN_SAMPLES = 2000
# ... and the refinement's seeds per round in proportion (measure.SEEDS at 20,000 points)
_MIN_SEEDS = 32


def seeds_for(samples: int) -> int:
    """The measure's seeds per refinement round for a grid of ``samples`` points: measure.SEEDS
    for the default 20,000 and more, in proportion below (at least _MIN_SEEDS)."""
    return int(min(SEEDS, max(_MIN_SEEDS, round(SEEDS * samples / 20000))))


def samples_for(n_triangles: int, error_samples: int) -> int:
    """The grid points per side the stage measures with: ``error_samples``, or fewer on a small
    input (_SAMPLES_PER_TRIANGLE per input triangle, at least _MIN_SAMPLES)."""
    return int(min(error_samples, max(_MIN_SAMPLES, _SAMPLES_PER_TRIANGLE * n_triangles)))


@dataclass
class Out:
    V: np.ndarray
    F: np.ndarray
    src_vertex: np.ndarray
    region: np.ndarray
    src_tri: np.ndarray | None
    tri_uvs: np.ndarray | None
    fixed: np.ndarray
    fit_info: dict
    notes: list[str]
    flipped: np.ndarray  # (t,) bool
    new_nonmanifold: np.ndarray  # (t,) bool: uses an edge with > 2 triangles the input did not have
    h: HausdorffResult | None = None  # the stage's error measure of this result, once taken
    flip: FlipResult | None = None
    lib_error: float = 0.0
    edge_turns: int = 0  # edges turned at sharp dihedrals right after the library
    folded: np.ndarray | None = None  # (t,) bool: in a fold the input does not have there


@dataclass
class Ctx:
    """What every attempt shares: the input, its index and grid, the config, and caches."""
    prep: Prepared
    cfg: SimplifyConfig
    method: str
    index_a: SurfaceIndex
    grid_a: object  # measure.SurfaceGrid over the input
    scale: float
    protect: np.ndarray  # input vertices the fit and repairs never move (when unmoved)
    # the input's own edges, for the record's checks: vertices on material/colour edges and those
    # edges, vertices on open borders, folds
    edge_mask: np.ndarray
    region_edges: np.ndarray
    border_mask: np.ndarray
    folds_in: np.ndarray
    chains: list = field(default_factory=list)  # border / seam chains of the input (meshopt locks)
    chain_ends: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    flip_cache: dict = field(default_factory=dict)
    repair_log: list = field(default_factory=list)
    measures: int = 0
    # seconds per phase, summed over every attempt (back-off probes, peak rounds), not only the
    # result kept: library, repair, check, fit, measure
    seconds: dict = field(default_factory=lambda: dict.fromkeys(PHASES, 0.0))
    fold_zones: np.ndarray | None = None  # centroids of the input's own folded triangles
    fit_points: np.ndarray | None = None  # the input's points the fit pairs with the result
    cap: float = 0.0  # the error ceiling (model units; triangle targets only, 0: none)
    measuring: bool = False  # results are measured (measure_error, or a max_error target)
    border_log: dict = field(default_factory=dict)  # the border locks (details.border_locks)
    relax_log: list[dict] = field(default_factory=list)  # what was let go, when (details.relaxations)
    seeds: int = SEEDS  # the measure's seeds per refinement round (seeds_for)
    samples: int = 20000  # grid points per side of the measure (samples_for: error_samples, fewer on small inputs)


def context(prep: Prepared, cfg: SimplifyConfig, method: str, scale: float, cap: float, measuring: bool) -> Ctx:
    """The shared part of a run: the input's distance index and grid, the vertices the fit and
    the repairs leave alone, the border and seam chains (meshopt), the input's folds and the
    points the fit pairs."""
    index_a = SurfaceIndex(prep.V, prep.F, seed=cfg.seed, scale=scale, corners=False, k=8)
    samples = samples_for(len(prep.F), cfg.error_samples)
    grid_a = surface_grid(prep.V, prep.F, samples)
    # vertices the fit and the repairs leave alone: material edges, non-manifold edges and (with
    # preserve_border) open borders
    edge_mask, region_edges = region_edge_vertices(prep.F, prep.region, len(prep.V))
    e_in, c_in, _ = edge_counts(prep.F)
    border_mask = np.zeros(len(prep.V), bool)
    border_mask[e_in[c_in == 1].ravel()] = True
    protect = edge_mask | nonmanifold_vertices(prep.F, len(prep.V))
    if cfg.preserve_border:
        protect |= border_mask
    chains, chain_ends = [], np.zeros(0, np.int64)
    if method == "meshopt":
        # the input's border and seam chains (open borders, material edges, UV seams): the
        # library's wedge borders, in input vertex numbers
        Fw, w_vertex, _, _ = wedges(prep)
        we, wc, _ = edge_counts(Fw)
        seams = w_vertex[we[wc == 1]]
        chains, chain_ends = repair.border_chains(prep.F, seams)
    folds_in = repair.folds(prep.V, prep.F)
    ctx = Ctx(prep=prep, cfg=cfg, method=method, index_a=index_a, grid_a=grid_a, scale=scale, protect=protect,
              edge_mask=edge_mask, region_edges=region_edges, border_mask=border_mask, folds_in=folds_in,
              chains=chains, chain_ends=chain_ends,
              fold_zones=prep.V[prep.F[np.unique(folds_in.ravel())]].mean(axis=1) if len(folds_in) else None,
              cap=cap, measuring=measuring, samples=samples,
              seeds=seeds_for(samples))
    # the fit pairs at most _FIT_POINTS of the input's grid points (a fixed, even subset)
    ctx.fit_points = grid_a.P if len(grid_a.P) <= _FIT_POINTS else \
        grid_a.P[np.sort(np.random.default_rng(cfg.seed + 3).choice(len(grid_a.P), _FIT_POINTS, replace=False))]
    return ctx
