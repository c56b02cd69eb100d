"""The wide BVH's fast paths: exact agreement with brute force, the SIMD box test against the
scalar one, adversarial rays (zero and negative-zero direction components, origins in box
faces, rays starting on triangles), and the node layout's invariants."""

from __future__ import annotations

from fractions import Fraction

import numba as nb
import numpy as np
import pytest
import trimesh

from dpm.tracer import build_bvh, intersect, intersect_brute_force, occluded
from dpm.tracer.bvh import EMPTY, LEAF_BITS, MAX_LEAF, REFS, WIDTH
from dpm.tracer.traverse import (
    LEAF_LANES,
    _box_test,
    _entry,
    _lane_distance,
    _leaf_test,
    _planes,
    box_constants,
    box_constants_simd,
    hit_box,
    hit_triangle,
    new_stack,
    ray_setup,
)


def random_soup(rng: np.random.Generator, n: int) -> np.ndarray:
    """n random triangles (n, 3, 3) float32 of varied size in the cube [-1, 1]^3."""
    centres = rng.uniform(-1, 1, (n, 1, 3))
    sizes = 10 ** rng.uniform(-2.5, -0.3, (n, 1, 1))
    return (centres + sizes * rng.normal(size=(n, 3, 3))).astype(np.float32)


def grid_mesh(n: int) -> np.ndarray:
    """An axis-aligned n×n grid of unit squares in the plane z = 0, two triangles each:
    float32 coordinates that are small integers, so rays meet edges and vertices exactly."""
    tri = []
    for i in range(n):
        for j in range(n):
            a, b, c, d = (i, j, 0), (i + 1, j, 0), (i + 1, j + 1, 0), (i, j + 1, 0)
            tri += [(a, b, c), (a, c, d)]
    return np.array(tri, np.float32)


def adversarial_rays(rng: np.random.Generator, tri: np.ndarray, n: int):
    """Rays whose origins lie in the planes of triangle vertices (so in box faces), with
    axis-aligned directions of signed zeros, aimed at vertices and edges, or starting on a
    triangle; float64 (n, 3) origins and directions."""
    pick = tri[rng.integers(0, len(tri), n)].astype(np.float64)
    lo, hi = tri.reshape(-1, 3).min(0), tri.reshape(-1, 3).max(0)
    o = rng.uniform(lo - 0.5, hi + 0.5, (n, 3))
    kind = rng.integers(0, 5, n)
    # 0: origin coordinates copied from vertices (box planes), direction along an axis.
    m = kind == 0
    axis = rng.integers(0, 3, m.sum())
    for a in range(3):
        take = rng.uniform(size=m.sum()) < 0.7
        o[np.flatnonzero(m)[take], a] = pick[m][take, rng.integers(0, 3), a]
    d = rng.normal(size=(n, 3))
    d[m] = 0.0
    d[m, axis] = rng.choice([-1.0, 1.0], m.sum())
    # 1: aimed at a vertex from a point in one of its coordinate planes (zero component).
    m = kind == 1
    v = pick[m, rng.integers(0, 3)]
    a = rng.integers(0, 3, m.sum())
    o[m, a] = v[np.arange(m.sum()), a]
    d[m] = v - o[m]
    # 2: aimed at an edge point.
    m = kind == 2
    s = rng.uniform(0, 1, (m.sum(), 1))
    d[m] = s * pick[m, 0] + (1 - s) * pick[m, 1] - o[m]
    # 3: starting on a triangle.
    m = kind == 3
    b = rng.dirichlet([1, 1, 1], m.sum())
    o[m] = np.einsum("ni,nij->nj", b, pick[m])
    # Zero components come with both signs: -0.0 flips 1/d to -inf.
    zero = d == 0
    d[zero] = np.where(rng.uniform(size=zero.sum()) < 0.5, 0.0, -0.0)
    d[np.all(d == 0, axis=1)] = (0.0, 0.0, 1.0)
    return o, d


def assert_same_as_brute_force(tri: np.ndarray, o: np.ndarray, d: np.ndarray, tmax=None):
    """The BVH's t equals brute force's exactly; its triangle is brute force's or, at an exact
    tie, another triangle that the ray meets at that same t. Occlusion agrees too."""
    bvh = build_bvh(tri)
    t, idx = intersect(bvh, o, d, tmax)
    tb, ib = intersect_brute_force(tri, o, d, tmax)
    np.testing.assert_array_equal(idx >= 0, ib >= 0)
    np.testing.assert_array_equal(t, tb)
    for r in np.flatnonzero(idx != ib):
        t_own, _ = intersect_brute_force(tri[idx[r] : idx[r] + 1], o[r], d[r])
        assert t_own[0] == t[r], f"ray {r}: triangle {idx[r]} is not hit at t = {t[r]}"
    np.testing.assert_array_equal(occluded(bvh, o, d, tmax), ib >= 0)


@pytest.mark.parametrize("n_tri", [1, 2, MAX_LEAF, MAX_LEAF + 1, 37, 700, 5000])
def test_random_soups_match_brute_force_exactly(n_tri: int) -> None:
    rng = np.random.default_rng(n_tri)
    tri = random_soup(rng, n_tri)
    o, d = adversarial_rays(rng, tri, 20_000)
    assert_same_as_brute_force(tri, o, d)
    tmax = rng.uniform(0.0, 3.0, len(o))
    assert_same_as_brute_force(tri, o, d, tmax)


def test_grid_edges_and_vertices_match_brute_force_exactly() -> None:
    """Rays along grid lines and through shared vertices: ties between neighbours everywhere."""
    rng = np.random.default_rng(2)
    tri = grid_mesh(12)
    o, d = adversarial_rays(rng, tri, 30_000)
    assert_same_as_brute_force(tri, o, d)
    # Straight down through every vertex and every edge midpoint, with ±0.0 in x and y.
    g = np.arange(0, 12.5, 0.5)
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    o = np.column_stack([xy, np.ones(len(xy))])
    for sx in (0.0, -0.0):
        for sy in (0.0, -0.0):
            d = np.tile([sx, sy, -1.0], (len(o), 1))
            t, idx = intersect(build_bvh(tri), o, d)
            assert np.all(idx >= 0) and np.all(t == 1.0)
            assert_same_as_brute_force(tri, o, d)


def test_ray_in_a_box_face_with_negative_zero_direction() -> None:
    """A ray lying in a box's min-x face, direction x = -0.0 (1/d = -inf), meets an edge in
    that face: the slab test must not turn the 0·inf NaN into a miss."""
    tri = np.array([[[0, -1, 1], [0, 1, 1], [1, 0, 1]]], np.float32)
    o = np.zeros((4, 3))
    d = np.array([[-0.0, 0.0, 1.0], [0.0, 0.0, 1.0], [-0.0, -0.0, 1.0], [0.0, -0.0, 1.0]])
    t, idx = intersect(build_bvh(tri), o, d)
    np.testing.assert_array_equal(idx, [0, 0, 0, 0])
    np.testing.assert_array_equal(t, [1.0, 1.0, 1.0, 1.0])
    assert np.all(occluded(build_bvh(tri), o, d))


def test_closed_mesh_from_inside_matches_brute_force_exactly() -> None:
    tri = (0.7 * trimesh.creation.icosphere(subdivisions=3).triangles).astype(np.float32)
    rng = np.random.default_rng(4)
    o = rng.uniform(-0.6, 0.6, (40_000, 3))
    d = rng.normal(size=(40_000, 3))
    assert_same_as_brute_force(tri, o, d)


@nb.njit(error_model="numpy")
def _both_constants(o, d):
    """Bits of `box_constants` and `box_constants_simd` for each ray (R, 3): (R, 12) twice."""
    scalar = np.empty((len(o), 12), np.float32)
    simd = np.empty((len(o), 12), np.float32)
    for r in range(len(o)):
        ix, iy, iz = 1.0 / d[r, 0], 1.0 / d[r, 1], 1.0 / d[r, 2]
        a = box_constants(o[r, 0], o[r, 1], o[r, 2], ix, iy, iz)
        b = box_constants_simd(o[r, 0], o[r, 1], o[r, 2], ix, iy, iz)
        for k in range(12):
            scalar[r, k], simd[r, k] = a[k], b[k]
    return scalar.view(np.int32), simd.view(np.int32)


def test_simd_box_constants_equal_the_scalar_ones_bit_for_bit() -> None:
    """The traversals' per-ray constants, three axes in SIMD lanes, are `box_constants`'s
    exactly, NaNs included, over ordinary rays and the cases that leave an axis out: zero
    and signed-zero direction components, tiny and huge ones, origins 1e30 away."""
    rng = np.random.default_rng(5)
    o = rng.normal(size=(20_000, 3)) * 10.0 ** rng.integers(-3, 6, (20_000, 1))
    d = rng.normal(size=(20_000, 3))
    special = np.array([0.0, -0.0, 1e-35, -1e-35, 1e-300, 1e35, 3e38, np.inf, 1.0])
    mask = rng.uniform(size=d.shape) < 0.3
    d[mask] = rng.choice(special, mask.sum())
    o[rng.uniform(size=o.shape) < 0.05] = 1e30
    d[np.all(d == 0, axis=1), 2] = 1.0
    scalar, simd = _both_constants(o, d)
    np.testing.assert_array_equal(simd, scalar)
    # the left-out axes were exercised: NaN beyond what inf - inf gives a zero component
    nan_axes = np.isnan(scalar.view(np.float32)).reshape(-1, 3, 4).all(axis=2).sum()
    assert nan_axes > np.count_nonzero(d == 0)


@nb.njit(error_model="numpy")
def _lanes(bounds, node, ox, oy, oz, dx, dy, dz, tmax):
    """The SIMD box test's entry distances (inf where not entered) and the scalar ones."""
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    nx, ny, nz, fx, fy, fz = _planes(ix, iy, iz)
    ray = box_constants(ox, oy, oz, ix, iy, iz)
    far = np.float32(tmax)
    stack = new_stack(1)
    mask = _box_test(bounds, node, nx, ny, nz, fx, fy, fz, ray, far, stack)
    simd = np.full(WIDTH, np.inf, np.float32)
    scalar = np.empty(WIDTH, np.float32)
    bits = np.empty(1, np.int32)
    for c in range(WIDTH):
        if mask >> c & 1:
            bits[0] = _entry(stack, c)
            simd[c] = bits.view(np.float32)[0]
        lo = (bounds[node, c], bounds[node, WIDTH + c], bounds[node, 2 * WIDTH + c])
        hi = (bounds[node, 3 * WIDTH + c], bounds[node, 4 * WIDTH + c], bounds[node, 5 * WIDTH + c])
        scalar[c] = hit_box(lo, hi, ray, far)
    return simd, scalar


def test_simd_box_test_equals_scalar_slab_test() -> None:
    """Lane by lane the vectorised test gives the scalar `hit_box` result bit for bit,
    including rays in box faces with ±0.0 components, and empty slots are never entered."""
    rng = np.random.default_rng(9)
    tri = random_soup(rng, 300)
    bvh = build_bvh(tri)
    bounds, kids = bvh.arrays.bounds, bvh.arrays.kids
    o, d = adversarial_rays(rng, tri, 4000)
    # Some origins exactly on a child box's planes.
    nodes = rng.integers(0, len(bounds), len(o))
    for r in range(0, len(o), 3):
        c = rng.integers(0, WIDTH)
        for a in range(3):
            if kids[nodes[r], REFS + c] != EMPTY and rng.uniform() < 0.5:
                o[r, a] = bounds[nodes[r], WIDTH * (a + 3 * rng.integers(0, 2)) + c]
    tmax = np.where(rng.uniform(size=len(o)) < 0.5, np.inf, rng.uniform(0, 2, len(o)))
    for r in range(len(o)):
        simd, scalar = _lanes(bounds, nodes[r], *o[r], *d[r], tmax[r])
        np.testing.assert_array_equal(simd, scalar)
        empty = kids[nodes[r], REFS : REFS + WIDTH] == EMPTY
        assert np.all(np.isinf(simd[empty]))


@nb.njit(error_model="numpy")
def _entry_distance(lo, hi, ox, oy, oz, dx, dy, dz, tmax):
    """`hit_box`'s float32 entry distance (inf: not entered) of one box and one ray."""
    ray = box_constants(ox, oy, oz, 1.0 / dx, 1.0 / dy, 1.0 / dz)
    return hit_box(lo, hi, ray, np.float32(tmax))


def _exact_entry(lo, hi, o, d, tmax) -> Fraction | None:
    """Exact entry distance of the ray into the box within [0, tmax], or None if it misses."""
    t0, t1 = Fraction(0), Fraction(tmax) if np.isfinite(tmax) else None
    for a in range(3):
        if d[a] == 0:
            if not lo[a] <= o[a] <= hi[a]:
                return None
            continue
        near = (Fraction(float(lo[a])) - Fraction(o[a])) / Fraction(d[a])
        far = (Fraction(float(hi[a])) - Fraction(o[a])) / Fraction(d[a])
        near, far = min(near, far), max(near, far)
        t0 = max(t0, near)
        t1 = far if t1 is None else min(t1, far)
    return t0 if t1 is None or t0 <= t1 else None


def test_float32_box_test_never_misses_a_box_the_ray_enters() -> None:
    """Against exact rational arithmetic, the float32 box test enters every box a ray enters
    (origins in box faces, boxes of zero width, far-off scenes, tiny direction components),
    at an entry distance no greater than the true one and close to it."""
    # 1/d subnormal in float32 (found by a review): its rounding exceeds the shrink
    lo = np.array([42352208, -65036408, -11619525], np.float32)
    hi = np.array([106240040, -19914762, 31264918], np.float32)
    o, d = (-104675963.8, -50151187.0, 20110983.4), (1.39e45, -9.80e43, 7.35e43)
    exact = _exact_entry(lo, hi, o, d, np.inf)
    assert exact is not None and _entry_distance(lo, hi, *o, *d, np.inf) <= exact
    rng = np.random.default_rng(12)
    checked = entered = irregular = 0
    for case in range(5000):
        offset = rng.choice([0.0, 1e3, -1e5])
        lo = (offset + rng.uniform(-1, 1, 3)).astype(np.float32)
        hi = (lo + rng.choice([0.0, 1e-6, 1.0], 3) * rng.uniform(0, 1, 3)).astype(np.float32)
        o = offset + rng.uniform(-2, 2, 3)
        faces = rng.uniform(size=3) < 0.3
        o[faces] = np.where(rng.uniform(size=3) < 0.5, lo, hi)[faces]
        aim = lo + rng.uniform(0, 1, 3) * (hi.astype(np.float64) - lo)  # a point of the box
        d = aim - o if rng.uniform() < 0.7 else rng.normal(size=3)
        d *= rng.choice([1.0, 1e-7, 1e40])  # long distances; huge directions (tiny 1/d)
        d[rng.uniform(size=3) < 0.1] *= rng.choice([1e-7, 1e-40])  # nearly axis-parallel
        d[rng.uniform(size=3) < 0.1] = 0.0
        if not d.any():
            continue
        tmax = rng.choice([np.inf, 3.0])
        exact = _exact_entry(lo, hi, o, d, tmax)
        got = _entry_distance(lo, hi, *o, *d, tmax)
        checked += 1
        if exact is None:
            continue
        entered += 1
        assert got <= exact, (case, float(exact), got)
        regular = float(exact) > 1e-30 and all(
            d[a] == 0 or (1e-30 < abs(d[a]) < 1e30 and abs(o[a] / d[a]) < 1e30) for a in range(3)
        )
        if not regular:  # float32 left an axis out (or the distance is subnormal): only ≤
            irregular += 1
            continue
        # looser by the float32 rounding of the origin's terms o·i
        slack = 2.0**-17 * float(exact) + 2.0**-21 * max(abs(o[a] / d[a]) for a in range(3) if d[a])
        assert float(exact) - got <= slack, case
    assert entered > 1200 and checked > 4500 and irregular > 100


def walk(bvh) -> tuple[list[tuple[int, int]], int]:
    """Every leaf (first, count) of the BVH, checking that each child box holds its subtree's
    triangles; and the number of node levels."""
    bounds, kids, verts = bvh.arrays.bounds, bvh.arrays.kids, bvh.arrays.tri_verts
    leaves, levels = [], 0
    todo = [(0, 1)]
    while todo:
        node, level = todo.pop()
        levels = max(levels, level)
        for c in range(WIDTH):
            ref = int(kids[node, REFS + c])
            lo = bounds[node, [c, WIDTH + c, 2 * WIDTH + c]]
            hi = bounds[node, [3 * WIDTH + c, 4 * WIDTH + c, 5 * WIDTH + c]]
            if ref == EMPTY:
                assert np.all(lo == np.inf) and np.all(hi == -np.inf)
                continue
            if ref >= 0:
                todo.append((ref, level + 1))
                sub = [ref]
                while sub:  # all triangles below this child lie in its box
                    n = sub.pop()
                    for k in range(WIDTH):
                        r = int(kids[n, REFS + k])
                        if r >= 0:
                            sub.append(r)
                        elif r != EMPTY:
                            f, m = ~r >> LEAF_BITS, ~r & ((1 << LEAF_BITS) - 1)
                            p = verts[f : f + m].reshape(-1, 3)
                            assert np.all(p >= lo) and np.all(p <= hi)
                continue
            first, count = ~ref >> LEAF_BITS, ~ref & ((1 << LEAF_BITS) - 1)
            assert 1 <= count <= MAX_LEAF
            p = verts[first : first + count].reshape(-1, 3)
            assert np.all(p >= lo) and np.all(p <= hi)
            leaves.append((first, count))
    return leaves, levels


@pytest.mark.parametrize("n_tri", [1, 3, MAX_LEAF + 1, 1000])
def test_layout_invariants(n_tri: int) -> None:
    """Each triangle is in exactly one leaf, boxes contain their triangles, records are
    aligned, tri_index is a permutation, and `depth` counts the node levels."""
    rng = np.random.default_rng(n_tri)
    tri = random_soup(rng, n_tri)
    bvh = build_bvh(tri)
    leaves, levels = walk(bvh)
    covered = np.zeros(n_tri, np.int64)
    for first, count in leaves:
        covered[first : first + count] += 1
    np.testing.assert_array_equal(covered, 1)
    np.testing.assert_array_equal(np.sort(bvh.arrays.tri_index), np.arange(n_tri))
    np.testing.assert_array_equal(bvh.arrays.tri_verts, tri[bvh.arrays.tri_index].reshape(-1, 9))
    assert bvh.depth == levels
    assert bvh.arrays.kids.ctypes.data % 64 == 0
    assert bvh.arrays.bounds.ctypes.data == bvh.arrays.kids.ctypes.data


def test_same_result_for_any_thread_count_on_adversarial_rays() -> None:
    rng = np.random.default_rng(13)
    tri = np.concatenate([grid_mesh(6), random_soup(rng, 500)])
    o, d = adversarial_rays(rng, tri, 60_000)
    bvh = build_bvh(tri)
    before = nb.get_num_threads()
    try:
        nb.set_num_threads(1)
        t1, i1 = intersect(bvh, o, d)
        h1 = occluded(bvh, o, d)
        nb.set_num_threads(before)
        t2, i2 = intersect(bvh, o, d)
        h2 = occluded(bvh, o, d)
    finally:
        nb.set_num_threads(before)
    np.testing.assert_array_equal(i1, i2)
    np.testing.assert_array_equal(t1, t2)
    np.testing.assert_array_equal(h1, h2)


@nb.njit(error_model="numpy")
def _leaf_lanes(planes, verts, first, count, ox, oy, oz, dx, dy, dz, tmax):
    """The SIMD leaf test's distances (inf where no hit before tmax) and the scalar ones."""
    kx, ky, kz, sx, sy, sz = ray_setup(dx, dy, dz)
    origin = (ox, oy, oz)
    hits = _leaf_test(
        planes, first, count, kx, ky, kz, origin[kx], origin[ky], origin[kz], sx, sy, sz, tmax
    )
    m = int(hits[0])
    simd = np.full(count, np.inf)
    scalar = np.full(count, np.inf)
    for j in range(count):
        if m >> j & 1 and _lane_distance(hits, j) < tmax:
            simd[j] = _lane_distance(hits, j)
        t = hit_triangle(verts, first + j, ox, oy, oz, kx, ky, kz, sx, sy, sz, tmax)
        if t < tmax:
            scalar[j] = t
    return simd, scalar


def test_simd_leaf_test_equals_scalar_triangle_test() -> None:
    """Lane by lane the vectorised watertight test gives `hit_triangle`'s distance bit for bit
    (hits strictly before tmax), and lanes past the leaf's count never hit."""
    rng = np.random.default_rng(21)
    tri = np.concatenate([grid_mesh(3), random_soup(rng, 200)])
    bvh = build_bvh(tri)
    planes, verts = bvh.arrays.tri_planes, bvh.arrays.tri_verts
    o, d = adversarial_rays(rng, tri, 6000)
    tmax = np.where(rng.uniform(size=len(o)) < 0.5, np.inf, rng.uniform(0, 3, len(o)))
    firsts = rng.integers(0, len(tri), len(o))
    counts = rng.integers(1, LEAF_LANES + 1, len(o))
    # Half the rays aim inside (or at the rim of) one of the lanes' triangles.
    aim = np.flatnonzero(rng.uniform(size=len(o)) < 0.5)
    lane = np.minimum(firsts[aim] + rng.integers(0, LEAF_LANES, len(aim)), len(tri) - 1)
    target = np.einsum(
        "ni,nij->nj", rng.dirichlet([1, 1, 1], len(aim)), verts[lane].reshape(-1, 3, 3)
    )
    d[aim] = target - o[aim]
    d[np.all(d == 0, axis=1)] = (0.0, 0.0, 1.0)
    hits = 0
    for r in range(len(o)):
        count = min(int(counts[r]), len(tri) - int(firsts[r]))
        simd, scalar = _leaf_lanes(planes, verts, firsts[r], count, *o[r], *d[r], tmax[r])
        np.testing.assert_array_equal(simd, scalar)
        hits += np.count_nonzero(np.isfinite(scalar))
    assert hits > 500


@pytest.mark.parametrize("side", [1.0, -1.0])
def test_tiny_direction_components_far_from_the_origin(side: float) -> None:
    """A direction component so small that o/d overflows float32 (1e4 / 1e-35) leaves that
    axis out of the box tests instead of missing every box: hits as brute force's."""
    xs = side * (9990.0 + 2.0 * np.arange(8))
    tri = np.array([[[x, -1, 1], [x + 2, -1, 1], [x + 1, 1, 1]] for x in xs], np.float32)
    o = np.array([[side * 9999.5, 0.0, 0.0]])
    d = np.array([[side * 1e-35, 0.0, 1.0]])
    t, idx = intersect(build_bvh(tri), o, d)
    t_ref, idx_ref = intersect_brute_force(tri, o, d)
    assert idx_ref[0] >= 0 and t_ref[0] == 1.0
    np.testing.assert_array_equal(idx, idx_ref)
    np.testing.assert_array_equal(t, t_ref)
    assert occluded(build_bvh(tri), o, d, 10.0)[0]


@pytest.mark.parametrize(
    ("origin", "direction", "message"),
    [
        ([0.0, np.nan, 0.0], [0.0, 0.0, 1.0], "finite"),
        ([0.0, 0.0, 0.0], [np.inf, 0.0, 1.0], "finite"),
        ([0.0, 0.0, 0.0], [0.0, -0.0, 0.0], "non-zero"),
    ],
)
def test_bad_rays_are_refused(origin, direction, message) -> None:
    """The cheap input checks still catch one bad ray among many good ones."""
    bvh = build_bvh(trimesh.creation.icosphere(subdivisions=1).triangles.astype(np.float32))
    o = np.zeros((1000, 3))
    d = np.tile([0.0, 0.0, 1.0], (1000, 1))
    o[517], d[517] = origin, direction
    with pytest.raises(ValueError, match=message):
        intersect(bvh, o, d)


def test_nan_tmax_is_refused() -> None:
    bvh = build_bvh(trimesh.creation.icosphere(subdivisions=1).triangles.astype(np.float32))
    o, d = np.zeros((3, 3)), np.tile([0.0, 0.0, 1.0], (3, 1))
    with pytest.raises(ValueError, match="NaN"):
        intersect(bvh, o, d, np.array([1.0, np.nan, 2.0]))
    with pytest.raises(ValueError, match="NaN"):
        occluded(bvh, o, d, float("nan"))
