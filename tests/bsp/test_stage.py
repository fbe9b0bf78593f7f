"""The bsp stage: scene bookkeeping, the lists' structure, invariance, determinism, config."""

from __future__ import annotations

import numpy as np
import pytest

from bake import config
from bake.bsp.stage import NODES_LIST, PLANES_LIST, stage
from bake.bsp.verify import bsp_order
from bake.scene import Material, make_scene

from .meshes import corpus_file, interlocked_scene, load_scene


def parse_records(nodes: np.ndarray):
    """Walk the flat record list item by item (the layout in docs/formats-bsp.md).
    Returns {start item: (kind, fields)}."""
    out = {}
    r = 1
    n = len(nodes)
    while r <= n:
        T = int(nodes[r - 1])
        size = 3 if T == 0 else 5 if T == 1 else 6
        assert r + size - 1 <= n, "record runs past the end of the list"
        out[r] = (T, [int(x) for x in nodes[r:r + size - 1]])
        r += size
    return out


def ranges(recs) -> list[tuple[int, int]]:
    out = []
    for T, f in recs.values():
        if T == 0:
            out.append((f[0], f[1]))
        elif T == 1:
            assert f[2] == f[0] + f[1]  # the suffix follows the prefix
            out.append((f[0], f[1] + f[3]))
        else:  # fF, nF (nA + nD), fB (first + nA), nB (nD + nBack): the group is fF .. fB + nB - 1
            assert f[3] >= f[1] and f[3] + f[4] >= f[1] + f[2]
            out.append((f[1], f[3] + f[4] - f[1]))
    return out


def _cfg(**kw):
    c = config.load(None, ["bsp.enabled=true"]).bsp
    for k, v in kw.items():
        setattr(c, k, v)
    return c


def _decorated(scene):
    """Add affine UVs and vertex colours and per-triangle colours/materials to a scene."""
    rng = np.random.default_rng(2)
    G = rng.normal(size=(2, 3)) * 0.3
    C = rng.normal(size=(4, 3)) * 0.1
    tv = scene.triangle_vertices()
    uv = np.einsum("tkc,ac->tka", tv, G) + 0.5
    vc = np.clip(scene.positions @ C.T + 0.5, 0, 1)
    T = scene.n_triangles
    mats = (Material("a", (1, 0, 0, 1)), Material("b", (0, 0, 1, 1)))
    tm = (np.arange(T) // 7) % 2
    s = make_scene(scene.positions, scene.triangles, materials=mats, tri_material=tm, vertex_colors=vc,
                   tri_uvs=uv)
    lm = np.einsum("tkc,ac->tka", tv, -G) + 0.5  # lightmap UVs: another affine map
    per_mat = rng.random((2, 4))  # constant per material, so coplanar neighbours can still merge
    return s.replace(face_colors=per_mat[tm], face_albedo=per_mat[1 - tm], tri_lightmap_uvs=lm), (G, C)


@pytest.mark.parametrize("vertex_colours", [True, False], ids=["vertex-colours", "face-colours-only"])
def test_stage_keeps_every_triangle_area_plane_and_attribute(vertex_colours):
    scene, (G, C) = _decorated(interlocked_scene())
    if not vertex_colours:
        scene = scene.replace(vertex_colors=None)
    # the pieces of each source face (an input triangle, or coplanar ones merged) add up to it
    # (without the re-merge, which may join fragments of two source faces of one group)
    kept, _ = stage(scene, _cfg(remerge=False))
    tv = kept.triangle_vertices()
    area_in = 0.5 * np.linalg.norm(np.cross(*(scene.triangle_vertices()[:, 1:] - scene.triangle_vertices()[:, :1]
                                             ).transpose(1, 0, 2)), axis=1)
    area_out = 0.5 * np.linalg.norm(np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]), axis=1)
    face_out, face_in = kept.artefacts.bsp.source_face, kept.artefacts.bsp.input_source_face
    nf = int(face_in.max()) + 1
    np.testing.assert_allclose(np.bincount(face_out, weights=area_out, minlength=nf),
                               np.bincount(face_in, weights=area_in, minlength=nf), rtol=1e-9, atol=1e-12)
    assert (face_in[kept.artefacts.bsp.source_triangle] == face_out).all()
    new, rec = stage(scene, _cfg())
    new.validate()
    src = new.artefacts.bsp.source_triangle
    assert len(src) == new.n_triangles
    tv = new.triangle_vertices()
    area_out = 0.5 * np.linalg.norm(np.cross(tv[:, 1] - tv[:, 0], tv[:, 2] - tv[:, 0]), axis=1)
    np.testing.assert_allclose(area_out.sum(), area_in.sum(), rtol=1e-9)
    # every piece lies in its source triangle's plane
    s_tv = scene.triangle_vertices()[src]
    n = np.cross(s_tv[:, 1] - s_tv[:, 0], s_tv[:, 2] - s_tv[:, 0])
    n /= np.linalg.norm(n, axis=1)[:, None]
    dist = np.abs(np.einsum("tc,tkc->tk", n, tv - s_tv[:, :1]))
    assert dist.max() < 1e-9 * scene.scale()
    # material, face colour kept; pieces of a cut triangle marked; UVs / colours interpolated
    assert (new.tri_material == scene.tri_material[src]).all()
    np.testing.assert_array_equal(new.face_colors, scene.face_colors[src])
    np.testing.assert_array_equal(new.face_albedo, scene.face_albedo[src])
    cut = new.tri_polygon < 0
    assert cut.any() and (~cut).any()
    np.testing.assert_allclose(new.tri_uvs, np.einsum("tkc,ac->tka", tv, G) + 0.5, atol=1e-9)
    np.testing.assert_allclose(new.tri_lightmap_uvs, np.einsum("tkc,ac->tka", tv, -G) + 0.5, atol=1e-9)
    if vertex_colours:
        np.testing.assert_allclose(new.vertex_colors, np.clip(new.positions @ C.T + 0.5, 0, 1), atol=1e-9)
    assert rec.details["splits"] > 0 and rec.counts_out["triangles"] == new.n_triangles
    if vertex_colours:  # (lit colours: nothing merges before the build, so no colour decides the tree)
        assert rec.details["merged_triangles"] == 0
    else:
        assert rec.details["merged_triangles"] > 0  # merged polygons were cut and interpolated too


def test_lists_cover_every_triangle_exactly_once():
    new, rec = stage(interlocked_scene(), _cfg())
    nodes = new.lists[NODES_LIST].values
    planes = np.asarray(new.lists[PLANES_LIST].values).reshape(-1, 4)
    recs = parse_records(nodes)
    seen = np.zeros(new.n_triangles + 1, int)
    for first, n in ranges(recs):
        if n:
            seen[first:first + n] += 1
    assert (seen[1:] == 1).all()
    starts = set(recs)
    for r, (T, f) in recs.items():
        if T >= 2:
            assert T % 4 == 0 and 1 <= T // 4 <= len(planes)  # the item of the plane's d
            size = 6
            B = f[0]
            if B != 0:
                assert abs(B) in starts and abs(B) > r
            if B >= 0:
                assert r + size in starts  # the front child follows
        elif T == 1:
            assert r + 5 in starts  # the peeled core follows
    # planes are unit normals (to the kept decimals) in canonical orientation, all distinct
    assert np.allclose(np.linalg.norm(planes[:, :3], axis=1), 1, atol=1e-5)
    first_nz = planes[np.arange(len(planes)), np.argmax(planes[:, :3] != 0, axis=1)]
    assert (first_nz > 0).all()
    assert len(np.unique(planes, axis=0)) == len(planes)
    assert rec.details["lists"][NODES_LIST]["items"] == len(nodes)


@pytest.mark.parametrize("name", ["suzanne", "house"])
def test_same_result_after_translation_and_scaling(name):
    path = corpus_file(name)
    if not path.exists():
        pytest.skip(f"corpus missing: {path}")
    base = load_scene(name)
    # face planes only: an edge plane takes its normal from corner coordinates the move has
    # rounded (1e-16 of 1e5), and through a short edge that can reach the 6th decimal
    out0, rec0 = stage(base, _cfg(edge_planes=0))
    rng = np.random.default_rng(9)
    eyes = base.bounds()[0] + rng.random((6, 3)) * 3 * (base.bounds()[1] - base.bounds()[0]) - \
        (base.bounds()[1] - base.bounds()[0])
    orders0 = [bsp_order(out0, e) for e in eyes]
    for shift, scale in ((1e5, 1.0), (0.0, 1e-3), (-3e4, 250.0)):
        moved = base.replace(positions=base.positions * scale + shift)
        out, rec = stage(moved, _cfg(edge_planes=0))
        assert rec.details["splits"] == rec0.details["splits"]
        assert out.n_triangles == out0.n_triangles
        # the same records; each split record's plane is the same plane moved with the scene
        # (plane *numbering* may differ: two planes equal after rounding may share one entry
        # in one frame and not in the other)
        r0 = parse_records(out0.lists[NODES_LIST].values)
        r1 = parse_records(out.lists[NODES_LIST].values)
        assert list(r0) == list(r1)
        p0 = np.asarray(out0.lists[PLANES_LIST].values).reshape(-1, 4)
        p1 = np.asarray(out.lists[PLANES_LIST].values).reshape(-1, 4)
        for r in r0:
            (T0, f0), (T1, f1) = r0[r], r1[r]
            assert f0 == f1 and (T0 > 1) == (T1 > 1) and (T0 < -1) == (T1 < -1) and (T0 in (0, 1)) == (T1 in (0, 1))
            if T0 >= 2:
                a, b = p0[T0 // 4 - 1], p1[T1 // 4 - 1]
                np.testing.assert_array_equal(a[:3], b[:3])  # same rounded normal
                # offset moved with the scene: d' = scale * d + n . shift
                assert abs(b[3] - (scale * a[3] + a[:3].sum() * shift)) <= 1e-7 * base.scale() * scale + 1e-10 * abs(shift)
        for e, o0 in zip(eyes, orders0):
            np.testing.assert_array_equal(bsp_order(out, e * scale + shift), o0)


def test_deterministic_and_seeded():
    scene = interlocked_scene(seed=4)
    a, _ = stage(scene, _cfg())
    b, _ = stage(scene, _cfg())
    np.testing.assert_array_equal(a.lists[NODES_LIST].values, b.lists[NODES_LIST].values)
    np.testing.assert_array_equal(a.triangles, b.triangles)
    c, _ = stage(scene, _cfg(seed=5, candidates=4))
    d, _ = stage(scene, _cfg(seed=6, candidates=4))
    # a different seed samples different candidates (with few candidates the trees differ)
    assert not np.array_equal(c.lists[NODES_LIST].values, d.lists[NODES_LIST].values)


def test_empty_and_single_triangle_scenes():
    empty = make_scene(np.zeros((0, 3)), np.zeros((0, 3), np.int64))
    new, rec = stage(empty, _cfg())
    assert len(new.lists[NODES_LIST].values) == 0 and rec.warnings
    one = make_scene([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    new, rec = stage(one, _cfg())
    assert list(new.lists[NODES_LIST].values) == [0, 1, 1]  # one leaf holding triangle 1
    # the same triangle, the same winding, turned so that corner 0 faces the shortest edge (1-2)
    assert new.n_triangles == 1 and new.triangles.tolist() == [[1, 2, 0]]


def test_config_keys_reach_the_builder():
    from bake.bsp.stage import options

    cfg = config.load(None, ["bsp.leaves='convex'", "bsp.leaf_max=7", "bsp.epsilon=1e-7", "bsp.candidates=0",
                             "bsp.plane_decimals=8"])
    opt = options(cfg.bsp)
    assert (opt.leaves, opt.leaf_max, opt.epsilon, opt.candidates, opt.plane_decimals) == ("convex", 7, 1e-7, 0, 8)
    with pytest.raises(config.ConfigError):
        config.load(None, ["bsp.epsilon=0.5"])
    with pytest.raises(config.ConfigError, match="plane_decimals"):
        config.load(None, ["bsp.epsilon=1e-7"])  # 6-decimal normals tilt planes by more than that
    with pytest.raises(config.ConfigError):
        config.load(None, ["bsp.leaves='some'"])


@pytest.mark.parametrize("leaves", ["none", "convex", "priority"])
def test_every_leaf_mode_gives_a_valid_cover(leaves):
    new, rec = stage(interlocked_scene(seed=1), _cfg(leaves=leaves))
    recs = parse_records(new.lists[NODES_LIST].values)
    seen = np.zeros(new.n_triangles + 1, int)
    for first, n in ranges(recs):
        seen[first:first + n] += 1
    assert (seen[1:] == 1).all()
    if leaves == "none":
        assert rec.details["peeled_fragments"] == 0


def test_corner_zero_faces_the_shortest_edge_and_corner_data_turns_with_it():
    """The stage turns each output triangle so that corner 0 is opposite its shortest edge (the
    reader's fan starts there); UVs and lightmap UVs must turn with their corners. Here both are
    affine functions of the position, so every corner's UV must still be that function of its
    own vertex, also on cut pieces (their UVs are interpolated along the cut edges)."""
    sc = interlocked_scene(seed=3)
    P = sc.positions[sc.triangles]  # (T, 3, 3)
    uv = np.stack([P[..., 0] + 0.5 * P[..., 2], P[..., 1] - 0.25 * P[..., 0]], -1)
    lm = np.stack([0.3 * P[..., 2] + 0.1, 0.2 * P[..., 0] + P[..., 1]], -1)
    sc = sc.replace(tri_uvs=uv, tri_lightmap_uvs=lm)
    new, rec = stage(sc, _cfg())
    assert rec.details["splits"] > 0  # cut pieces are part of the check
    Q = new.positions[new.triangles]
    np.testing.assert_allclose(new.tri_uvs[..., 0], Q[..., 0] + 0.5 * Q[..., 2], atol=1e-9)
    np.testing.assert_allclose(new.tri_uvs[..., 1], Q[..., 1] - 0.25 * Q[..., 0], atol=1e-9)
    np.testing.assert_allclose(new.tri_lightmap_uvs[..., 0], 0.3 * Q[..., 2] + 0.1, atol=1e-9)
    np.testing.assert_allclose(new.tri_lightmap_uvs[..., 1], 0.2 * Q[..., 0] + Q[..., 1], atol=1e-9)
    e = [((Q[:, (k + 2) % 3] - Q[:, (k + 1) % 3]) ** 2).sum(-1) for k in range(3)]  # opposite corner k
    assert (e[0] <= e[1] * (1 + 1e-6)).all() and (e[0] <= e[2] * (1 + 1e-6)).all()
    # the winding is kept: every triangle faces the way its source triangle faced
    n_new = np.cross(Q[:, 1] - Q[:, 0], Q[:, 2] - Q[:, 0])
    src = new.artefacts.bsp.source_triangle
    n_src = np.cross(P[src, 1] - P[src, 0], P[src, 2] - P[src, 0])
    big = np.linalg.norm(n_new, axis=1) > 1e-9
    assert ((n_new * n_src).sum(1)[big] > 0).all()
