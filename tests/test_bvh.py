"""The BVH against brute force, the triangle test against an independent one, watertightness."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import trimesh
from hypothesis import given, settings
from hypothesis import strategies as st

from dpm.tracer import build_bvh, intersect, intersect_brute_force, occluded


def random_soup(rng: np.random.Generator, n: int) -> np.ndarray:
    """n random triangles (n, 3, 3) float32 of varied size in the cube [-1, 1]^3."""
    centres = rng.uniform(-1, 1, (n, 1, 3))
    sizes = 10 ** rng.uniform(-2.5, -0.3, (n, 1, 1))
    return (centres + sizes * rng.normal(size=(n, 3, 3))).astype(np.float32)


def sphere_mesh(subdivisions: int = 3) -> np.ndarray:
    """Closed icosphere triangles (T, 3, 3) float32, radius 0.7."""
    return (0.7 * trimesh.creation.icosphere(subdivisions=subdivisions).triangles).astype(
        np.float32
    )


def unit(v: np.ndarray) -> np.ndarray:
    """Rows of v scaled to unit length."""
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def tricky_rays(rng: np.random.Generator, tri: np.ndarray, n: int):
    """n rays (origins, directions) mixing the hard cases: through vertices and edges,
    starting on surfaces, axis-parallel, and plain random ones."""
    kinds = rng.integers(0, 5, n)
    o = rng.uniform(-1.5, 1.5, (n, 3))
    d = unit(rng.normal(size=(n, 3)))
    pick = tri[rng.integers(0, len(tri), n)].astype(np.float64)
    # 0: aimed exactly at a vertex
    m = kinds == 0
    target = pick[m, rng.integers(0, 3, m.sum())]
    d[m] = target - o[m]
    # 1: aimed at a point on an edge
    m = kinds == 1
    s = rng.uniform(0, 1, (m.sum(), 1))
    target = s * pick[m, 0] + (1 - s) * pick[m, 1]
    d[m] = target - o[m]
    # 2: starting on a surface
    m = kinds == 2
    b = rng.dirichlet([1, 1, 1], m.sum())
    o[m] = np.einsum("ni,nij->nj", b, pick[m])
    # 3: axis-parallel, sometimes lying exactly in a vertex's coordinate plane
    m = kinds == 3
    axis = rng.integers(0, 3, m.sum())
    d[m] = 0.0
    d[m, axis] = rng.choice([-1.0, 1.0], m.sum())
    on_plane = rng.uniform(size=m.sum()) < 0.5
    idx = np.flatnonzero(m)[on_plane]
    o[idx, (axis[on_plane] + 1) % 3] = pick[idx, 0, (axis[on_plane] + 1) % 3]
    return o, d


def assert_agree(tri: np.ndarray, o: np.ndarray, d: np.ndarray, tmax=None) -> None:
    """BVH and brute force give the same hit/miss, and t within 1e-5 relative."""
    bvh = build_bvh(tri)
    t, idx = intersect(bvh, o, d, tmax)
    tb, ib = intersect_brute_force(tri, o, d, tmax)
    np.testing.assert_array_equal(idx >= 0, ib >= 0)
    hit = ib >= 0
    np.testing.assert_allclose(t[hit], tb[hit], rtol=1e-5, atol=0)
    assert np.all(np.isinf(t[~hit])) and np.all(idx[~hit] == -1)
    np.testing.assert_array_equal(occluded(bvh, o, d, tmax), hit)


@settings(max_examples=60, deadline=None)
@given(
    seed=st.integers(0, 2**32 - 1),
    n_tri=st.integers(1, 400),
    tmax=st.one_of(st.none(), st.floats(0.05, 4.0)),
)
def test_bvh_matches_brute_force_on_random_scenes(seed: int, n_tri: int, tmax) -> None:
    rng = np.random.default_rng(seed)
    tri = random_soup(rng, n_tri)
    o, d = tricky_rays(rng, tri, 3000)
    assert_agree(tri, o, d, tmax)


def test_bvh_matches_brute_force_on_a_million_rays() -> None:
    rng = np.random.default_rng(7)
    tri = np.concatenate([sphere_mesh(3), random_soup(rng, 300)])
    o, d = tricky_rays(rng, tri, 1_000_000)
    assert_agree(tri, o, d)


def test_degenerate_input_builds() -> None:
    """Many triangles with the same centroid (no SAH split possible) still trace correctly."""
    rng = np.random.default_rng(1)
    base = rng.normal(size=(1, 3, 3)).astype(np.float32)
    tri = np.repeat(base, 50, axis=0)
    tri[:, 0] += rng.normal(scale=1e-3, size=(50, 3)).astype(np.float32)
    tri[:, 1] -= tri[:, 0] - base[:, 0]  # centroid unchanged
    o, d = tricky_rays(rng, tri, 2000)
    assert_agree(tri, o, d)


def moller_trumbore(tri: np.ndarray, o: np.ndarray, d: np.ndarray) -> np.ndarray:
    """Independent float64 ray–triangle distances (R,) for rays against one triangle each."""
    v0, v1, v2 = (tri[:, i].astype(np.float64) for i in range(3))
    e1, e2 = v1 - v0, v2 - v0
    p = np.cross(d, e2)
    det = np.einsum("ij,ij->i", e1, p)
    s = o - v0
    u = np.einsum("ij,ij->i", s, p) / det
    q = np.cross(s, e1)
    v = np.einsum("ij,ij->i", d, q) / det
    t = np.einsum("ij,ij->i", e2, q) / det
    hit = (u >= 0) & (v >= 0) & (u + v <= 1) & (t > 0)
    return np.where(hit, t, np.inf)


def test_triangle_test_matches_independent_implementation() -> None:
    rng = np.random.default_rng(3)
    tri = random_soup(rng, 4000)
    b = rng.dirichlet([1, 1, 1], len(tri))
    b[::2] += rng.uniform(-0.5, 0.5, (len(tri[::2]), 3))  # half the rays aim outside
    target = np.einsum("ni,nij->nj", b, tri.astype(np.float64))
    o = rng.uniform(-2, 2, (len(tri), 3))
    d = target - o
    expected = moller_trumbore(tri, o, d)
    # Keep away from edges, where two correct tests may round differently.
    clear = np.min(np.abs(b), axis=1) > 1e-3
    assert 1000 < np.count_nonzero(np.isfinite(expected) & clear) < 3000
    for i in np.flatnonzero(clear):
        t, idx = intersect_brute_force(tri[i : i + 1], o[i], d[i])
        assert np.isfinite(t[0]) == np.isfinite(expected[i])
        if np.isfinite(expected[i]):
            assert abs(t[0] - expected[i]) <= 1e-9 * expected[i]


def test_closed_mesh_is_watertight() -> None:
    """Rays from inside a closed mesh always hit it; rays at vertices and edges never leak."""
    rng = np.random.default_rng(5)
    tri = sphere_mesh(4)
    bvh = build_bvh(tri)
    n = 200_000
    o = rng.uniform(-0.3, 0.3, (n, 3))
    d = unit(rng.normal(size=(n, 3)))
    t, idx = intersect(bvh, o, d)
    assert np.all(idx >= 0)
    # From outside, aimed exactly at vertices and at edge points: every ray hits.
    pick = tri[rng.integers(0, len(tri), n)].astype(np.float64)
    s = rng.uniform(0, 1, (n, 1))
    targets = np.where(
        rng.uniform(size=(n, 1)) < 0.5, pick[:, 0], s * pick[:, 0] + (1 - s) * pick[:, 1]
    )
    o = targets * 3.0
    t, idx = intersect(bvh, o, targets - o)
    assert np.all(idx >= 0)


def test_tmax_and_occlusion() -> None:
    tri = np.array([[[-1, -1, 2], [1, -1, 2], [0, 1, 2]]], np.float32)
    bvh = build_bvh(tri)
    o = np.zeros((3, 3))
    d = np.tile([0.0, 0.0, 1.0], (3, 1))
    t, idx = intersect(bvh, o, d, np.array([np.inf, 2.5, 1.5]))
    np.testing.assert_array_equal(idx, [0, 0, -1])
    assert t[0] == pytest.approx(2.0, rel=1e-12)
    np.testing.assert_array_equal(occluded(bvh, o, d, np.array([np.inf, 2.5, 1.5])), [1, 1, 0])
    # A hit exactly at tmax does not count, in either query.
    t, idx = intersect(bvh, o[:1], d[:1], 2.0)
    assert idx[0] == -1 and not occluded(bvh, o[:1], d[:1], 2.0)[0]
    # Ray length is in units of |direction|.
    t, _ = intersect(bvh, o[:1], 2 * d[:1])
    assert t[0] == pytest.approx(1.0, rel=1e-12)


def test_bad_rays_are_rejected() -> None:
    bvh = build_bvh(sphere_mesh(1))
    with pytest.raises(ValueError, match="non-zero"):
        intersect(bvh, np.zeros((1, 3)), np.zeros((1, 3)))
    with pytest.raises(ValueError, match="finite"):
        intersect(bvh, np.full((1, 3), np.nan), np.ones((1, 3)))


def test_same_result_for_any_thread_count() -> None:
    rng = np.random.default_rng(11)
    tri = random_soup(rng, 2000)
    o, d = tricky_rays(rng, tri, 50_000)
    bvh = build_bvh(tri)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        t1, i1 = intersect(bvh, o, d)
        numba.set_num_threads(before)
        t2, i2 = intersect(bvh, o, d)
    finally:
        numba.set_num_threads(before)
    np.testing.assert_array_equal(i1, i2)
    np.testing.assert_array_equal(t1, t2)
