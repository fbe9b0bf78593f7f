"""The AO hot path's fast pieces give the bits of the plain ones (issue 41): the blocked,
component-major ray generator against ``cosine_directions`` + ``np.repeat``; the boolean pair
reduction against the float one; Embree's frame origins read through strided views against the
default contiguous call."""

from __future__ import annotations

import numpy as np
import pytest

from bake.lighting.rays import Tracer
from bake.lighting.sampling import (RayBuffers, cosine_directions, cosine_rays_into, frames, mean_and_se,
                                    multi_jittered, point_shifts)
from lighting_geom import box


def _points(P: int, seed: int):
    rng = np.random.default_rng(seed)
    n = rng.normal(size=(P, 3))
    n /= np.linalg.norm(n, axis=1, keepdims=True)
    n[: min(P, 3)] = [[0, 0, 1], [0, 0, -1], [1, 0, 0]][: min(P, 3)]  # the frames' branch points
    return n, rng.normal(size=(P, 3)) * 1e3


@pytest.mark.parametrize("samples,P,block", [(256, 200, 64), (50, 37, 16), (16, 1, 64), (9, 130, 1), (1, 5, 3)])
def test_blocked_generator_gives_the_plain_generators_bits(samples, P, block):
    nrm, org = _points(P, samples)
    pat = multi_jittered(samples, 7, 1)
    su, sv = point_shifts(np.arange(P, dtype=np.uint64) * 977, 7, 1)
    t, b = frames(nrm, sv)
    n32, t32, b32 = (np.ascontiguousarray(a, np.float32) for a in (nrm, t, b))
    su32, org32 = su.astype(np.float32), org.astype(np.float32)
    # a shift that rounds to 1.0 in float32 and a pattern value at the top of the interval
    su32[0] = np.float32(1.0)
    d_ref, _ = cosine_directions(pat, n32, t32, b32, su32)
    o_ref = np.repeat(org32, pat.n, axis=0)
    buf = RayBuffers(P * pat.n + 11, pat.n, block)  # bigger than needed: views must be trimmed
    buf.dir.fill(np.nan)
    o, d = cosine_rays_into(pat, n32, t32, b32, su32, org32, buf)
    assert o.shape == d.shape == (P * pat.n, 3) and o.dtype == d.dtype == np.float32
    assert d.tobytes() == np.ascontiguousarray(d).tobytes()  # (a view reads like an array)
    assert np.ascontiguousarray(d).tobytes() == d_ref.tobytes()
    assert np.ascontiguousarray(o).tobytes() == o_ref.tobytes()
    # reuse: a smaller second batch in the same buffers
    o2, d2 = cosine_rays_into(pat, n32[1:3], t32[1:3], b32[1:3], su32[1:3], org32[1:3], buf)
    assert np.array_equal(d2, d_ref[pat.n:3 * pat.n]) and np.array_equal(o2, o_ref[pat.n:3 * pat.n])


@pytest.mark.parametrize("N", [1, 2, 7, 56, 256])
def test_boolean_reduction_gives_the_float_reductions_bits(N):
    rng = np.random.default_rng(N)
    occ = rng.random((300, N)) < rng.random((300, 1))  # rows from all-open to all-hit
    for span in (0.0, 1.0):
        m_ref, s_ref = mean_and_se(occ.astype(np.float32), span)
        m, s = mean_and_se(occ, span)
        assert m.dtype == s.dtype == np.float64
        assert m.tobytes() == m_ref.tobytes() and s.tobytes() == s_ref.tobytes()


def test_embree_frame_origins_through_strided_views_match_the_default_call():
    V, F = box(4, 1.0)
    tr = Tracer(V * [3.0, 1.0, 2.0] + 1e4, F, threads=1)  # off the world origin: a real shift and scale
    rng = np.random.default_rng(5)
    n = 5000
    o = (rng.normal(size=(n, 3)) * 2.0).astype(np.float32)  # in the centred frame, inside and out
    d = rng.normal(size=(n, 3)).astype(np.float32)
    ref = tr.occluded(o, d, 1.5)
    o_soa = np.ascontiguousarray(tr.embree_origins(o).T)  # component-major, read as (n, 3) views
    d_soa = np.ascontiguousarray(d.T)
    got = tr.occluded(o_soa.T, d_soa.T, 1.5, embree_frame=True)
    assert 0 < ref.sum() < n  # both answers occur
    assert np.array_equal(got, ref)
    with pytest.raises(TypeError):
        tr.occluded(o_soa.T.astype(np.float64), d_soa.T, 1.5, embree_frame=True)


def test_face_geometry_gives_np_cross_and_norm_bits():
    from bake.lighting.targets import face_geometry

    rng = np.random.default_rng(11)
    V = rng.normal(size=(3000, 3)) * 10.0 ** rng.integers(-8, 8, size=(3000, 1))
    F = rng.integers(0, 3000, size=(9000, 3))
    F[:40, 1] = F[:40, 0]  # degenerate: two corners the same
    F[40:50] = F[40:50, :1]  # a point
    p = V[F]
    e1, e2 = p[:, 1] - p[:, 0], p[:, 2] - p[:, 0]
    cr = np.cross(e1, e2)
    ln = np.linalg.norm(cr, axis=1)
    n_ref = np.divide(cr, ln[:, None], out=np.zeros_like(cr), where=ln[:, None] > 0)
    longest_ref = np.stack([np.linalg.norm(e1, axis=1), np.linalg.norm(p[:, 2] - p[:, 1], axis=1),
                            np.linalg.norm(e2, axis=1)], axis=1).max(axis=1)
    n, area, longest = face_geometry(V, F)
    assert n.tobytes() == n_ref.tobytes()
    assert area.tobytes() == (0.5 * ln).tobytes()
    assert longest.tobytes() == longest_ref.tobytes()
    assert not n[:50].any() and not area[:50].any()
