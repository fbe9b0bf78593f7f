"""The "may hide" relation behind priority leaves, checked by ray casting; peeling; leaves."""

from __future__ import annotations

import numpy as np

from bake.bsp.build import BuildOptions, build_tree, hide_graph, peel, priority_peel
from bake.bsp.split import triangle_store

from .meshes import box, merge

EPS = 1e-9


def _ray_hit(o, d, tri):
    """Möller–Trumbore: distance along d to the triangle, or inf."""
    e1, e2 = tri[1] - tri[0], tri[2] - tri[0]
    p = np.cross(d, e2)
    det = e1 @ p
    if abs(det) < 1e-14:
        return np.inf
    s = o - tri[0]
    u = (s @ p) / det
    q = np.cross(s, e1)
    v = (d @ q) / det
    t = (e2 @ q) / det
    if u < 1e-9 or v < 1e-9 or u + v > 1 - 1e-9 or t <= 1e-9:
        return np.inf
    return t


def _faces(tri, eye):
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    return n @ (eye - tri[0]) > 0


def _clip(poly, n, d, keep_front):
    """Part of a convex polygon strictly on one side of plane (n, d) (Sutherland-Hodgman)."""
    s = poly @ n - d
    if not keep_front:
        s = -s
    out = []
    for k in range(len(poly)):
        a, b, sa, sb = poly[k], poly[(k + 1) % len(poly)], s[k], s[(k + 1) % len(poly)]
        if sa > 0:
            out.append(a)
        if (sa > 0) != (sb > 0) and sa != sb:
            out.append(a + sa / (sa - sb) * (b - a))
    return np.array(out)


def _plane(tri):
    n = np.cross(tri[1] - tri[0], tri[2] - tri[0])
    n /= np.linalg.norm(n)
    return n, n @ tri[0]


def test_may_hide_is_exact_against_ray_casting():
    rng = np.random.default_rng(11)
    positives = negatives = 0
    for _ in range(150):
        pair = rng.uniform(-1, 1, size=(2, 3, 3))
        st = triangle_store(pair, 1e-12)
        M = hide_graph(st, np.array([[0, 1]]), EPS)[0]
        i, j = pair
        (ni, di), (nj, dj) = _plane(i), _plane(j)
        if M[0, 1]:
            positives += 1
            # witness: p on i in front of plane j, q on j behind plane i, eye beyond p on q -> p
            pi = _clip(i, nj, dj, True)
            qj = _clip(j, ni, di, False)
            assert len(pi) >= 3 and len(qj) >= 3
            p, q = pi.mean(0), qj.mean(0)
            eye = p + 0.05 * (p - q)
            d = q - eye
            ti, tj = _ray_hit(eye, d, i), _ray_hit(eye, d, j)
            assert np.isfinite(ti) and np.isfinite(tj) and ti < tj
            assert _faces(i, eye) and _faces(j, eye)
        else:
            negatives += 1
            # no eye anywhere sees i in front of j (both facing it): random eyes and rays
            for _ in range(300):
                eye = rng.uniform(-3, 3, size=3)
                if not (_faces(i, eye) and _faces(j, eye)):
                    continue
                w = rng.dirichlet([1, 1, 1])
                q = w @ j
                d = q - eye
                ti, tj = _ray_hit(eye, d, i), _ray_hit(eye, d, j)
                assert not (np.isfinite(tj) and ti < tj - 1e-9), "missed a hiding pair"
    assert positives > 20 and negatives > 20


def test_facing_and_two_sided_faces():
    a = np.array([[0, 0, 0], [1, 0, 0], [0, 1, 0]], float)  # normal +z at z=0
    b = (a + [0, 0, 1])[[0, 2, 1]]  # normal -z at z=1: the two face each other
    st = triangle_store(np.stack([a, b]), 1e-12)
    # both are seen only from between them, where neither is behind the other
    assert hide_graph(st, np.array([[0, 1]]), EPS)[0].sum() == 0
    st = triangle_store(np.stack([a, b]), 1e-12, two_sided=np.array([True, True]))
    assert hide_graph(st, np.array([[0, 1]]), EPS)[0].sum() == 2  # from above or below: both ways
    c = a + [0, 0, 1]  # normal +z at z=1, above a
    st = triangle_store(np.stack([a, c]), 1e-12)
    M = hide_graph(st, np.array([[0, 1]]), EPS)[0]
    assert M[1, 0] and not M[0, 1]  # c can hide a from above; a never hides c
    st = triangle_store(np.stack([a, c]), 1e-12, two_sided=np.array([True, True]))
    M = hide_graph(st, np.array([[0, 1]]), EPS)[0]
    assert M[1, 0] and M[0, 1]  # seen from below, a hides c


def test_peel_orders_an_acyclic_graph_and_leaves_a_cycle_as_core():
    # 0 may hide 1, 1 may hide 2: draw 2, 1, 0; plus a 2-cycle 3 <-> 4
    M = np.zeros((1, 5, 5), bool)
    M[0, 0, 1] = M[0, 1, 2] = True
    M[0, 3, 4] = M[0, 4, 3] = True
    status, key = peel(M, np.ones((1, 5), bool))
    assert list(status[0, 3:]) == [0, 0]  # the cycle stays
    pre = [i for i in range(3) if status[0, i] == 1]
    suf = [i for i in range(3) if status[0, i] == 2]
    # prefix drawn by increasing key, suffix by decreasing key: 2 before 1 before 0
    draw = sorted(pre, key=lambda i: key[0, i]) + sorted(suf, key=lambda i: -key[0, i])
    assert draw == [2, 1, 0] and suf == []


def _tris(v, f):
    return np.asarray(v, float)[np.asarray(f)]


def test_convex_and_concave_sets_are_single_leaves_with_no_split():
    v, f = box([0, 0, 0], [1, 2, 3])
    for inward in (False, True):
        vv, ff = box([0, 0, 0], [1, 2, 3], inward=inward)
        st = triangle_store(_tris(vv, ff), 1e-12)
        tree = build_tree(st, BuildOptions())
        assert tree.n_nodes == 1 and not tree.has_plane[0] and tree.stats["splits"] == 0
        assert len(tree.pre_ids) == 12


def test_separate_objects_need_no_split():
    v, f = merge(box([0, 0, 0], [1, 1, 1]), box([3, 0, 0], [4, 1, 1]), box([0, 3, 0], [1, 4, 1]))
    st = triangle_store(_tris(v, f) / 10.0, 1e-12)
    tree = build_tree(st, BuildOptions())
    assert tree.stats["splits"] == 0


def test_priority_peel_agrees_with_the_dense_peel():
    rng = np.random.default_rng(5)
    tris = rng.uniform(-1, 1, size=(40, 3, 3)) * [1, 1, 0.2] + rng.uniform(-1, 1, size=(40, 1, 3))
    st = triangle_store(tris, 1e-12)
    fids = np.arange(40)
    status, key = priority_peel(st, fids, np.array([0, 40]), np.array([0]), EPS, "priority")
    M = hide_graph(st, fids[None, :], EPS)
    s2, k2 = peel(M, np.ones((1, 40), bool))
    assert (status == s2[0]).all() and (key == k2[0]).all()
    # every edge between drawn-first and drawn-later fragments respects the order
    order = np.concatenate([fids[status == 1][np.argsort(key[status == 1], kind="stable")],
                            fids[status == 0],
                            fids[status == 2][np.argsort(-key[status == 2], kind="stable")]])
    pos = np.empty(40, int)
    pos[order] = np.arange(40)
    core = status == 0
    for i, j in zip(*np.nonzero(M[0])):
        if core[i] and core[j]:
            continue  # the core is ordered by the subtree, not by this list
        assert pos[j] < pos[i], f"{i} may hide {j} but is drawn first"
