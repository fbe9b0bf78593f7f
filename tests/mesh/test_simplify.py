"""Simplify stage: budgets, measured error, flips, material edges, attributes, hard cases.

References are independent of the code under test: pymeshlab's Hausdorff filter for the error
metric (tests/mesh/simplify_reference.py refines it around the worst samples), brute-force
sampling for point-triangle distances, analytic UVs/colours of generated meshes, and geometric
facts of the corpus files (flat boxes stay flat and closed). The shuffled-order targets are in
test_simplify_targets.py, the measure against the reference in test_simplify_measure.py.
"""

from __future__ import annotations

import numpy as np
import pytest
import trimesh

from bake.config import SimplifyConfig
from bake.errors import ConfigError
from bake.mesh.simplify import attempt, defects, meshopt, rounds
from bake.mesh.simplify import stage as S
from bake.mesh.simplify.error import SurfaceIndex, point_triangle_distance, topology, triangle_normals
from bake.mesh.simplify.measure import hausdorff
from bake.scene import Material, Scene, make_scene

from conftest import corpus_path

FAST_CFG = dict(enabled=True, error_samples=4000, refine_rounds=0, fit_iterations=2)


def cfg(**kw) -> SimplifyConfig:
    d = dict(FAST_CFG)
    d.update(kw)
    return SimplifyConfig(**d)


def bumpy_sphere(sub: int = 4, seed: int = 1) -> tuple[np.ndarray, np.ndarray]:
    m = trimesh.creation.icosphere(subdivisions=sub)
    V = np.asarray(m.vertices, np.float64)
    r = 1.0 + 0.08 * np.sin(3 * V[:, 0]) * np.cos(4 * V[:, 1]) + 0.05 * np.sin(5 * V[:, 2])
    return V * r[:, None], np.asarray(m.faces, np.int64)


def spherical_uv(P: np.ndarray) -> np.ndarray:
    u = (np.arctan2(P[:, 1], P[:, 0]) / (2 * np.pi)) % 1.0
    v = np.arccos(np.clip(P[:, 2] / np.linalg.norm(P, axis=1), -1, 1)) / np.pi
    return np.stack([u, v], axis=1)


def uv_sphere_scene(two_materials: bool = False, sub: int = 4) -> Scene:
    """Bumpy sphere with per-corner spherical UVs (a real seam where u wraps), vertex colours
    that are a function of position, and optionally two materials split at z = 0.25."""
    V, F = bumpy_sphere(sub)
    uv = spherical_uv(V)[F]  # (T, 3, 2)
    # unwrap triangles that straddle the seam so each triangle's UVs are continuous
    span = uv[:, :, 0].max(axis=1) - uv[:, :, 0].min(axis=1)
    wrap = span > 0.5
    uv[wrap, :, 0] = np.where(uv[wrap, :, 0] < 0.5, uv[wrap, :, 0] + 1.0, uv[wrap, :, 0])
    col = np.concatenate([(V - V.min(0)) / np.ptp(V, axis=0), np.ones((len(V), 1))], axis=1)
    mats = None
    tm = None
    if two_materials:
        mats = (Material("bottom", (0.2, 0.2, 0.8, 1.0)), Material("top", (0.9, 0.1, 0.1, 1.0)))
        tm = (V[F].mean(axis=1)[:, 2] > 0.25).astype(np.int64)
    return make_scene(V, F, materials=mats, tri_material=tm, vertex_colors=col, tri_uvs=uv)


def load_corpus(*parts: str) -> Scene:
    """A corpus file through the project's own import, triangulate and clean stages."""
    path = corpus_path(*parts)
    from bake import pipeline
    return pipeline.run(pipeline.load_config_for(path), until="clean").scene


def pymeshlab_hausdorff(Va, Fa, Vb, Fb) -> tuple[float, float]:
    pymeshlab = pytest.importorskip("pymeshlab")
    ms = pymeshlab.MeshSet()
    ms.add_mesh(pymeshlab.Mesh(np.asarray(Va, np.float64), np.asarray(Fa, np.int32)))
    ms.add_mesh(pymeshlab.Mesh(np.asarray(Vb, np.float64), np.asarray(Fb, np.int32)))
    a = ms.get_hausdorff_distance(sampledmesh=0, targetmesh=1, sampleface=True, samplevert=True, samplenum=60000)
    b = ms.get_hausdorff_distance(sampledmesh=1, targetmesh=0, sampleface=True, samplevert=True, samplenum=60000)
    return max(a["max"], b["max"]), 0.5 * (a["mean"] + b["mean"])


def assert_regions_kept(sc: Scene, out: Scene, region_in: np.ndarray, region_out: np.ndarray) -> None:
    """Each output corner either sits on an input region edge or over input surface of the
    output triangle's region (so no triangle reaches across an edge into the other region)."""
    e = np.sort(np.concatenate([sc.triangles[:, [0, 1]], sc.triangles[:, [1, 2]], sc.triangles[:, [2, 0]]]), axis=1)
    r = np.tile(region_in, 3)
    key = e[:, 0] * sc.n_vertices + e[:, 1]
    order = np.lexsort((r, key))
    k, rr = key[order], r[order]
    diff = (k[1:] == k[:-1]) & (rr[1:] != rr[:-1])
    on_edge = np.zeros(sc.n_vertices, bool)
    on_edge[np.concatenate([k[1:][diff] // sc.n_vertices, k[1:][diff] % sc.n_vertices])] = True
    edge_pos = sc.positions[on_edge]
    idx = SurfaceIndex(sc.positions, sc.triangles)
    corners = out.positions[out.triangles].reshape(-1, 3)
    # a corner's own region: pull it slightly into its triangle so it is not exactly on the edge
    cen = np.repeat(out.positions[out.triangles].mean(axis=1), 3, axis=0)
    _, under, _ = idx.query(0.98 * corners + 0.02 * cen)
    ok_region = region_in[under] == np.repeat(region_out, 3)
    d_edge = np.linalg.norm(corners[:, None, :] - edge_pos[None, :, :], axis=2).min(axis=1)
    assert np.all(ok_region | (d_edge == 0.0))


# --------------------------------------------------------------------------- the metric
def test_point_triangle_distance_matches_brute_force():
    rng = np.random.default_rng(0)
    A, B, C = (rng.normal(size=(200, 3)) for _ in range(3))
    C[:20] = A[:20] + 0.5 * (B[:20] - A[:20])  # degenerate (collinear) triangles too
    P = rng.normal(size=(200, 3)) * 2
    d, q = point_triangle_distance(P, A, B, C)
    # brute force: dense barycentric grid on each triangle
    n = 120
    i, j = np.meshgrid(np.arange(n + 1), np.arange(n + 1), indexing="ij")
    keep = i + j <= n
    bu, bv = (i[keep] / n), (j[keep] / n)
    grid = (A[:, None] + bu[None, :, None] * (B - A)[:, None] + bv[None, :, None] * (C - A)[:, None])
    brute = np.linalg.norm(grid - P[:, None], axis=2).min(axis=1)
    edge = np.max(np.linalg.norm(np.stack([B - A, C - A, C - B]), axis=2), axis=0) / n
    assert np.all(d <= brute + 1e-12)
    assert np.all(brute - d <= edge + 1e-12)
    assert np.allclose(np.linalg.norm(q - P, axis=1), d)


def test_hausdorff_agrees_with_pymeshlab_and_is_exact_on_planes():
    # two parallel unit squares 0.01 apart: every distance is exactly 0.01
    V = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], float)
    F = np.array([[0, 1, 2], [0, 2, 3]])
    h = hausdorff(V, F, V + [0, 0, 0.01], F, points=2000)
    assert h.max == pytest.approx(0.01, rel=1e-9) and h.mean == pytest.approx(0.01, rel=1e-9)
    # a simplified bumpy sphere against MeshLab's sampled Hausdorff filter
    Va, Fa = bumpy_sphere(4)
    sc = make_scene(Va, Fa)
    out, rec = S.stage(sc, cfg(target_ratio=0.05, fit_iterations=0, error_samples=20000))
    hm, mean_ml = pymeshlab_hausdorff(Va, Fa, out.positions, out.triangles)
    diag = sc.scale()
    assert rec.accuracy["hausdorff_max"] * diag == pytest.approx(hm, rel=0.05)
    assert rec.accuracy["hausdorff_mean"] * diag == pytest.approx(mean_ml, rel=0.25)


# --------------------------------------------------------------------------- budgets
@pytest.mark.parametrize("method", ["meshopt", "fast", "quality"])
def test_reaches_target_within_one_percent_without_flips(method):
    sc = uv_sphere_scene()
    out, rec = S.stage(sc, cfg(method=method, target_triangles=500))
    out.validate()
    T = out.n_triangles
    assert abs(T - 500) <= 5 or any("target" in w for w in rec.warnings), (T, rec.warnings)
    assert rec.accuracy["flipped_triangles"] == 0
    assert rec.accuracy["new_nonmanifold_edges"] == 0
    assert (out.tri_polygon == -1).all() and out.poly_sizes is None
    # the sphere is closed: the result is closed, consistently oriented and manifold too
    topo = topology(out.triangles)
    assert topo["open_edges"] == 0 and topo["nonmanifold_edges"] == 0 and topo["misoriented_edges"] == 0
    # independent flip check: outward normals on this star-shaped surface
    n = triangle_normals(out.positions, out.triangles)
    c = out.positions[out.triangles].mean(axis=1)
    assert (np.einsum("ij,ij->i", n, c) > 0).all()
    # the reported error is what it claims, and small for 500 triangles of a smooth blob
    assert 0 < rec.accuracy["hausdorff_max"] < 0.05
    assert rec.counts_in["triangles"] == sc.n_triangles and rec.counts_out["triangles"] == T


def test_ratio_and_config_errors():
    sc = make_scene(*bumpy_sphere(2))
    with pytest.raises(ConfigError):
        S.stage(sc, SimplifyConfig(enabled=True))
    with pytest.raises(ConfigError):
        S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.5, target_triangles=10))
    same, rec = S.stage(sc, cfg(target_triangles=10 ** 6))
    assert same is sc and rec.warnings
    empty, rec = S.stage(Scene(), cfg(target_ratio=0.5))
    assert empty.n_triangles == 0 and rec.warnings
    out, rec = S.stage(sc, cfg(target_ratio=0.25))
    assert abs(out.n_triangles - round(0.25 * sc.n_triangles)) <= 0.01 * sc.n_triangles + 1


def test_max_error_mode_meets_the_bound():
    Va, Fa = bumpy_sphere(4)
    sc = make_scene(Va, Fa)
    out, rec = S.stage(sc, cfg(max_error=0.01))
    assert out.n_triangles < sc.n_triangles / 4
    assert rec.accuracy["hausdorff_max"] <= 0.01
    hm, _ = pymeshlab_hausdorff(Va, Fa, out.positions, out.triangles)
    assert hm / sc.scale() <= 0.0105  # independent check (sampled differently)
    assert rec.details["probes"]


# --------------------------------------------------------------------------- what authors see
@pytest.mark.parametrize("method", ["meshopt", "fast", "quality"])
def test_material_edges_kept_and_attributes_carried(method):
    sc = uv_sphere_scene(two_materials=True)
    # (defects = "refuse": what each method keeps when nothing is let go; MeshLab leaves the
    # triangles along the edge out of its selection and stops at 902 for 512, where the default
    # lets the material edge go to meet the budget: test_budget_met_by_letting_edges_go)
    out, rec = S.stage(sc, cfg(method=method, target_ratio=0.1, defects="refuse"))
    out.validate()
    assert rec.accuracy["flipped_triangles"] == 0
    # 1. no triangle crosses the material edge: every corner of a triangle is either on the
    #    input's material edge or lies on input surface of the triangle's own material
    assert_regions_kept(sc, out, sc.tri_material, out.tri_material)
    # 2. the material edge: its output vertices are input edge vertices, unmoved
    def edge_vertices(s: Scene) -> np.ndarray:
        e = np.sort(np.concatenate([s.triangles[:, [0, 1]], s.triangles[:, [1, 2]], s.triangles[:, [2, 0]]]), axis=1)
        m = np.tile(s.tri_material, 3)
        key = e[:, 0] * s.n_vertices + e[:, 1]
        mats = {}
        for k, mm in zip(key.tolist(), m.tolist()):
            mats.setdefault(k, set()).add(mm)
        both = np.array([k for k, v in mats.items() if len(v) > 1], np.int64)
        return np.unique(np.concatenate([both // s.n_vertices, both % s.n_vertices]))
    ein = sc.positions[edge_vertices(sc)]
    eout = out.positions[edge_vertices(out)]
    assert len(eout) >= 8
    d = np.linalg.norm(eout[:, None] - ein[None], axis=2).min(axis=1)
    assert d.max() == 0.0
    if method in ("fast", "quality"):
        assert len(eout) == len(ein)  # these keep every vertex of the edge
    # 3. UVs: every output corner carries an input corner's UV; UVs stay in range and, away
    #    from the seam, match the analytic parameterisation at the corner
    in_uv = {tuple(x) for x in sc.tri_uvs.reshape(-1, 2).tolist()}
    assert all(tuple(x) in in_uv for x in out.tri_uvs.reshape(-1, 2).tolist())
    lo, hi = sc.tri_uvs.reshape(-1, 2).min(0), sc.tri_uvs.reshape(-1, 2).max(0)
    assert (out.tri_uvs >= lo - 1e-12).all() and (out.tri_uvs <= hi + 1e-12).all()
    if method == "meshopt":
        ref = spherical_uv(out.positions)[out.triangles]
        du = np.abs(out.tri_uvs[..., 0] - ref[..., 0])
        du = np.minimum(du, np.abs(du - 1.0))
        dv = np.abs(out.tri_uvs[..., 1] - ref[..., 1])
        assert np.median(du) < 0.01 and np.median(dv) < 0.01
    # 4. vertex colours are input colours (no invented colours)
    in_col = {tuple(x) for x in sc.vertex_colors.tolist()}
    assert all(tuple(x) in in_col for x in out.vertex_colors.tolist())


def test_face_colours_follow_their_regions():
    V, F = bumpy_sphere(3)
    sc = make_scene(V, F)
    fc = np.where((V[F].mean(axis=1)[:, 0] > 0)[:, None], [1.0, 0.0, 0.0, 1.0], [0.0, 0.5, 1.0, 1.0])
    sc = sc.replace(face_colors=fc)
    out, rec = S.stage(sc, cfg(target_ratio=0.15))
    key_in = (fc[:, 0] > 0.5).astype(np.int64)
    key_out = (out.face_colors[:, 0] > 0.5).astype(np.int64)
    assert set(map(tuple, out.face_colors.tolist())) <= set(map(tuple, fc.tolist()))
    assert_regions_kept(sc, out, key_in, key_out)


def test_deterministic():
    sc = uv_sphere_scene(two_materials=True, sub=3)
    c = cfg(target_ratio=0.08, refine_rounds=1)
    a, ra = S.stage(sc, c)
    b, rb = S.stage(sc, c)
    for name in ("positions", "triangles", "tri_material", "tri_uvs", "vertex_colors"):
        assert np.array_equal(getattr(a, name), getattr(b, name)), name
    assert ra.accuracy == rb.accuracy


def test_pipeline_runs_it_only_when_enabled():
    from bake import pipeline, stages
    from bake.config import Config
    c = Config()
    assert [on for spec, on, _ in pipeline.plan(c) if spec.name == "simplify"] == [False]
    c.mesh.simplify.enabled = True
    spec = next(s for s in stages.STAGES if s.name == "simplify")
    assert spec.enabled(c) and spec.load() is S.stage


# --------------------------------------------------------------------------- hard cases
@pytest.mark.corpus
@pytest.mark.parametrize("parts,ratio", [
    (("house_max2obj_walls", "regr01.obj"), 0.3),  # unwelded walls, slivers, 12 materials
    (("joined_tetrahedra", "joined_tetrahedra.obj"), 0.5),  # non-manifold
    (("xatlas_double_sided", "double_sided.obj"), 0.5),  # coincident opposite faces
    (("boolean_csg_slivers", "boolean.glb"), 0.5),
    (("cornell_box_multimaterial", "cornell_box_multimaterial.obj"), 0.5),  # flat, CAD-like
])
def test_hard_cases(parts, ratio):
    sc = load_corpus(*parts)
    # (error_ceiling 5%: what keeps the flat walls below, where the default meets the budget)
    out, rec = S.stage(sc, cfg(target_ratio=ratio, fit_iterations=0, error_samples=2000, error_ceiling=0.05))
    out.validate()
    assert np.isfinite(out.positions).all()
    # flips and new non-manifold edges: none, or the record says how many (CSG slivers and
    # overlapping internal walls can defeat the flip check; see the report)
    for key, word in (("flipped_triangles", "face against"), ("new_nonmanifold_edges", "non-manifold")):
        assert rec.accuracy[key] == 0 or any(word in w for w in rec.warnings), (key, rec.warnings)
    assert rec.counts_out["triangles"] == out.n_triangles <= sc.n_triangles
    missed = abs(out.n_triangles - rec.details.get("target_triangles", out.n_triangles)) > \
        0.01 * rec.details.get("target_triangles", 1)
    if missed:
        assert any("target" in w or "stopped at" in w for w in rec.warnings)  # the record says why
    if parts[0] in ("cornell_box_multimaterial", "xatlas_double_sided"):
        # flat CAD-like walls that cannot lose a triangle without changing shape: the error
        # ceiling keeps every wall (no hole) and the record says the target was not reached
        assert rec.accuracy["hausdorff_max_original_to_simplified"] < 1e-6
        assert rec.warnings


@pytest.mark.corpus
def test_spot_keeps_uv_seams_and_is_clean(corpus):
    m = trimesh.load(corpus("spot_triangulated", "spot", "spot_triangulated.obj"), process=False, force="mesh")
    V, inv = np.unique(np.asarray(m.vertices, np.float64), axis=0, return_inverse=True)
    F = inv.reshape(-1)[np.asarray(m.faces)]
    uv = np.asarray(m.visual.uv, np.float64)[np.asarray(m.faces)]
    sc = make_scene(V, F, tri_uvs=uv)
    out, rec = S.stage(sc, cfg(target_ratio=0.1))
    assert rec.accuracy["flipped_triangles"] == 0 and rec.accuracy["new_nonmanifold_edges"] == 0
    assert abs(out.n_triangles - round(0.1 * sc.n_triangles)) <= 0.01 * round(0.1 * sc.n_triangles) + 1
    # each output triangle's UV triangle keeps its orientation (no chart folded over)
    def uv_sign(s):
        u = s.tri_uvs
        return np.sign((u[:, 1, 0] - u[:, 0, 0]) * (u[:, 2, 1] - u[:, 0, 1]) -
                       (u[:, 1, 1] - u[:, 0, 1]) * (u[:, 2, 0] - u[:, 0, 0]))
    # (spot has a few mirrored charts: compare with the input triangle under each output one)
    idx = SurfaceIndex(sc.positions, sc.triangles)
    _, under, _ = idx.query(out.positions[out.triangles].mean(axis=1))
    assert (uv_sign(out) == uv_sign(sc)[under]).mean() > 0.97
    assert rec.accuracy["hausdorff_max"] < 0.02


# --------------------------------------------------------------------------- borders and folds
def _independent_folds(V: np.ndarray, F: np.ndarray) -> int:
    """Pairs of triangles sharing an edge whose unit normals have a dot product below -0.9,
    counted with a plain dictionary of edges (independent of bake.mesh.simplify.repair.folds)."""
    by_edge: dict = {}
    for t, (a, b, c) in enumerate(F.tolist()):
        for u, v in ((a, b), (b, c), (c, a)):
            by_edge.setdefault((min(u, v), max(u, v)), []).append(t)
    n = np.cross(V[F[:, 1]] - V[F[:, 0]], V[F[:, 2]] - V[F[:, 0]])
    ln = np.linalg.norm(n, axis=1)
    pairs = set()
    for ts in by_edge.values():
        for i in range(len(ts)):
            for j in range(i + 1, len(ts)):
                t, u = ts[i], ts[j]
                if t != u and ln[t] > 0 and ln[u] > 0 and n[t] @ n[u] / (ln[t] * ln[u]) < -0.9:
                    pairs.add((min(t, u), max(t, u)))
    return len(pairs)


@pytest.mark.corpus
@pytest.mark.parametrize("method", ["meshopt", "fast"])
def test_borders_stay_on_the_input_border_and_folds_are_counted(method):
    """The bunny's open borders (the holes in its base) at 1%: every output border vertex is an
    input border vertex, unmoved (before: the refit moved all 37 of them, by up to 0.56% of the
    diagonal; with fast-simplification 220 of 223, though the library kept them), and the record
    says how far the border chords stray; the fold count in the record is the independent one
    (before: no fold check, and 4 folds with fast-simplification reported as 0 flips)."""
    sc = load_corpus("stanford_bunny_res1_obj", "stanford-bunny.obj")
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.01, method=method))
    def border(F):
        e = np.sort(np.concatenate([F[:, [0, 1]], F[:, [1, 2]], F[:, [2, 0]]]), axis=1)
        u, c = np.unique(e, axis=0, return_counts=True)
        return np.unique(u[c == 1])
    b_in = sc.positions[border(sc.triangles)]
    b_out = out.positions[border(out.triangles)]
    assert len(b_out) >= 8
    d = np.linalg.norm(b_out[:, None] - b_in[None], axis=2).min(axis=1)
    assert d.max() == 0.0, f"{(d > 0).sum()} of {len(d)} border vertices left the input border"
    assert rec.details["border_vertices_moved"] == 0 and rec.details["border_vertices_off_input_border"] == 0
    assert 0 <= rec.details["border_chord_max"] <= rec.accuracy["hausdorff_max"] * 1.5
    folds = _independent_folds(out.positions, out.triangles)
    assert rec.accuracy["folds"] == folds
    assert folds == 0 or any("fold" in w for w in rec.warnings)


@pytest.mark.parametrize("stuck", [False, True])
def test_backing_off_to_the_input_returns_the_input(monkeypatch, stuck):
    """When no count below the input is acceptable, the stage backs off to the input itself and
    returns it unchanged, with the default fit and refine rounds on (the corpus house at 30% and
    50% crashed here: the fit and the refine rounds ran on the input, which has no flip check).
    Its error is exactly 0, not a measure of the input against itself, also when a probe below
    the input's count gets every triangle back (``stuck``: a library that collapses nothing
    above 95% of the input)."""
    V, F = bumpy_sphere(2)
    sc = make_scene(V, F)
    T0 = len(F)
    real = defects.count
    monkeypatch.setattr(defects, "count", lambda o: 1 if len(o.F) < T0 else real(o))
    if stuck:
        lib = meshopt.simplify
        monkeypatch.setattr(meshopt, "simplify",
                            lambda V, F, target, **k: (F.copy(), 0.0) if target > 0.95 * len(F) else lib(V, F, target, **k))
    # the defaults, with today's back-off (defects = "allow" delivers the budget instead)
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.5, defects="refuse"))
    assert out.n_triangles == T0
    got = np.sort(np.sort(out.positions[out.triangles], axis=1).reshape(T0, -1), axis=0)
    want = np.sort(np.sort(sc.positions[sc.triangles], axis=1).reshape(T0, -1), axis=0)
    np.testing.assert_array_equal(got, want)
    assert any("stopped at" in w and "flipped" in w and "error_ceiling" not in w for w in rec.warnings)
    assert rec.accuracy["hausdorff_max"] == 0.0 and rec.details["error_bound"] is None
    if stuck:
        assert any(p["target"] < T0 and p["triangles"] == T0 and p["ok"] for p in rec.details["probes"])


@pytest.mark.parametrize("where", ["first", "peak"])
def test_refused_results_are_not_measured(monkeypatch, where):
    """A result that is refused for its defects whatever its error is not measured: the first
    result of a triangle target whose flips survive the fit (the stage backs off from it) and a
    peak round's result with flips (that round is not kept). Here every result below the input's
    count has a flip (``first``), or only those of the peak round (``peak``); the Hausdorff
    measure and the fit check's original-side measure count what they are given."""
    V, F = bumpy_sphere(3)
    T0 = len(F)
    real = defects.count
    state = {"peak": False, "measured": []}
    if where == "first":
        monkeypatch.setattr(defects, "count", lambda o: 1 if len(o.F) < T0 else real(o))
    else:
        monkeypatch.setattr(defects, "count", lambda o: 1 if state["peak"] else real(o))
        peak_rounds = rounds.peak_rounds

        def peak(*a, **k):
            state["peak"] = True
            try:
                return peak_rounds(*a, **k)
            finally:
                state["peak"] = False
        monkeypatch.setattr(rounds, "peak_rounds", peak)
    for name in ("hausdorff", "original_side"):  # (the measures of attempt.measure and attempt.fitted)
        fn = getattr(attempt, name)

        def counted(*a, _fn=fn, _name=name, **k):
            state["measured"].append((_name, state["peak"]))
            return _fn(*a, **k)
        monkeypatch.setattr(attempt, name, counted)
    out, rec = S.stage(make_scene(V, F), SimplifyConfig(enabled=True, target_ratio=0.1, error_samples=4000,
                                                        defects="refuse"))
    if where == "first":
        # backed off all the way to the input, which needs no measure (its error is 0)
        assert out.n_triangles == T0 and rec.details["backed_off_from"] == int(round(0.1 * T0))
        assert state["measured"] == [] and rec.details["measures"] == 0
        assert rec.accuracy["hausdorff_max"] == 0.0
    else:
        log = rec.details["peak_rounds"]
        assert log, "the test needs a peak round"
        assert log[0]["defects"] > 0 and log[0]["hausdorff_max_after"] is None and log[0]["kept"] is False
        assert state["measured"] and not any(in_peak for _, in_peak in state["measured"])
        assert rec.accuracy["flipped_triangles"] == 0 and 0 < rec.accuracy["hausdorff_max"]


def test_flips_the_fit_turns_back_are_measured_and_kept(monkeypatch):
    """The other side of the test above: a first result whose flips the fit turns back is
    measured and kept as before. Every result the library hands back (``_finish``) counts as
    flipped here, every fitted one as it is; the stage must give the same mesh and accuracy as
    without that (the fit is kept on this model, so nothing else changes)."""
    V, F = bumpy_sphere(3)
    T0 = len(F)
    config = SimplifyConfig(enabled=True, target_ratio=0.1, error_samples=4000)
    want, want_rec = S.stage(make_scene(V, F), config)
    assert want_rec.details["fit"]["kept"] is True and "backed_off_from" not in want_rec.details
    raw = []
    finish, real = attempt._finish, defects.count

    def marked(*a, **k):
        o = finish(*a, **k)
        raw.append(o)
        return o
    monkeypatch.setattr(attempt, "_finish", marked)
    monkeypatch.setattr(defects, "count", lambda o: 1 if len(o.F) < T0 and any(o is r for r in raw) else real(o))
    got, rec = S.stage(make_scene(V, F), config)
    assert raw and "backed_off_from" not in rec.details and rec.details["measures"] > 0
    np.testing.assert_array_equal(got.positions, want.positions)
    np.testing.assert_array_equal(got.triangles, want.triangles)
    assert rec.accuracy == want_rec.accuracy


def test_error_ceiling_backs_off_to_more_triangles():
    """A target whose error would pass error_ceiling stops at more triangles, says why, and
    the result's measured error is within the ceiling."""
    V, F = bumpy_sphere(3)
    ceiling = 0.001
    out, rec = S.stage(make_scene(V, F), cfg(target_ratio=0.02, error_ceiling=ceiling))
    assert out.n_triangles > rec.details["backed_off_from"] == int(round(0.02 * len(F)))
    assert rec.accuracy["hausdorff_max"] <= ceiling
    # the warning names the count the library gave (meshoptimizer stops at its own error estimate
    # under the ceiling, far above the target) and the reason
    import re
    said = [re.match(r"(\d+) triangles \(what a target of (\d+) gave\) would cost an error of .*"
                     rf"\(error_ceiling = {ceiling}\); stopped at (\d+) triangles", w) for w in rec.warnings]
    said = [m for m in said if m]
    assert len(said) == 1
    first, target, stop = (int(x) for x in said[0].groups())
    assert target < first < stop == out.n_triangles
    assert all(p["ok"] == (p["hausdorff_max"] is not None and p["hausdorff_max"] <= ceiling and p["defects"] == 0)
               for p in rec.details["probes"])


@pytest.mark.corpus
@pytest.mark.slow
def test_house_backs_off_when_defects_are_refused():
    sc = load_corpus("house_max2obj_walls", "regr01.obj")
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.3, defects="refuse"))
    out.validate()
    assert out.n_triangles <= sc.n_triangles
    assert rec.accuracy["flipped_triangles"] == 0 and rec.accuracy["new_nonmanifold_edges"] == 0
    if out.n_triangles > 1.01 * rec.details["target_triangles"]:
        assert any("stopped at" in w for w in rec.warnings)


def test_phase_seconds_count_every_attempt(monkeypatch):
    """The record's library/check/repair seconds are totals over every attempt (the peak
    round's second run, back-off probes), not the kept result's alone: each library call and
    each flip check is made to take at least 20 ms here, and the record must hold them all."""
    import time as _time

    calls = {"library": 0, "flip": 0}
    lib, flip = meshopt.simplify, defects.check_flips

    def slow_lib(*a, **k):
        calls["library"] += 1
        _time.sleep(0.02)
        return lib(*a, **k)

    def slow_flip(*a, **k):
        calls["flip"] += 1
        _time.sleep(0.02)
        return flip(*a, **k)

    monkeypatch.setattr(meshopt, "simplify", slow_lib)
    monkeypatch.setattr(defects, "check_flips", slow_flip)
    V, F = bumpy_sphere(3)
    out, rec = S.stage(make_scene(V, F), SimplifyConfig(enabled=True, target_ratio=0.1, error_samples=4000))
    d = rec.details
    assert d["peak_rounds"], "the test needs a second run of the library"
    assert calls["library"] >= 2 and calls["flip"] >= 3
    assert d["library_seconds"] >= 0.02 * calls["library"]
    # flip checks count as checks (after the library, the fit) or as the refine rounds' repairs
    assert d["check_seconds"] + d["repair_seconds"] >= 0.02 * calls["flip"]
    phases = ("prepare", "library", "repair", "check", "fit", "measure", "other")
    assert sum(d[f"{p}_seconds"] for p in phases) == pytest.approx(rec.seconds, abs=1e-3)
    # an error target: the search's first guess is a library call too
    calls["library"] = 0
    _, rec = S.stage(make_scene(V, F), SimplifyConfig(enabled=True, max_error=0.01, error_samples=4000))
    assert calls["library"] >= 2 and rec.details["library_seconds"] >= 0.02 * calls["library"]


def test_nothing_to_collapse_returns_the_input_without_rounds():
    """A box cannot lose a triangle (every collapse would fold a face): the library hands back
    the 12 triangles, and the stage returns the input itself (error 0) instead of fitting,
    measuring and refining a copy of it (0.5 s on a 12-triangle box before). (With defects =
    "refuse": the default meets the budget by clustering, test_simplify_messy.py.)"""
    m = trimesh.creation.box(extents=(1.0, 2.0, 3.0))
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    out, rec = S.stage(make_scene(V, F), SimplifyConfig(enabled=True, target_ratio=0.5, defects="refuse",
                                                        error_ceiling=0.05))
    assert out.n_triangles == 12
    got = np.sort(np.sort(out.positions[out.triangles], axis=1).reshape(12, -1), axis=0)
    want = np.sort(np.sort(V[F], axis=1).reshape(12, -1), axis=0)
    np.testing.assert_array_equal(got, want)
    assert rec.accuracy["hausdorff_max"] == 0.0
    assert rec.details["measures"] == 0 and rec.details["refine"] == [] and "peak_rounds" not in rec.details
    assert any("target of 6" in w for w in rec.warnings)


def test_no_rounds_below_the_floor():
    """A flat box cut into 48 triangles simplified to 24 has an error of rounding size: the
    refine and peak rounds do not run (below ROUNDS_FLOOR of the diagonal), and the result is
    still within the floor of the input by an independent measure (every output vertex and
    points on every output triangle against the input's faces, trimesh's closest points)."""
    m = trimesh.creation.box(extents=(1.0, 2.0, 3.0)).subdivide()
    V, F = np.asarray(m.vertices, np.float64), np.asarray(m.faces, np.int64)
    sc = make_scene(V, F)
    out, rec = S.stage(sc, SimplifyConfig(enabled=True, target_ratio=0.5))
    assert out.n_triangles < len(F)
    assert rec.details["refine"] == [] and "peak_rounds" not in rec.details
    diag = float(np.linalg.norm(np.ptp(V, axis=0)))
    bary = np.random.default_rng(0).dirichlet(np.ones(3), 50)
    P = np.concatenate([out.positions, np.einsum("pk,tkd->tpd", bary, out.positions[out.triangles]).reshape(-1, 3)])
    # trimesh's closest point on every input face (48 faces: one call per face)
    d = np.min([np.linalg.norm(trimesh.triangles.closest_point(np.repeat(V[f][None], len(P), 0), P) - P, axis=1)
                for f in F], axis=0)
    assert d.max() <= rounds.ROUNDS_FLOOR * diag
    assert rec.accuracy["hausdorff_max"] <= rounds.ROUNDS_FLOOR
    # above the floor the rounds do run (a curved surface)
    Vb, Fb = bumpy_sphere(3)
    _, rec2 = S.stage(make_scene(Vb, Fb), SimplifyConfig(enabled=True, target_ratio=0.1, error_samples=4000))
    assert rec2.accuracy["hausdorff_max"] > rounds.ROUNDS_FLOOR and rec2.details["refine"]
