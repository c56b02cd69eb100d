"""Ray queries: the watertight ray–triangle test and closest-hit / any-hit BVH traversal.

The single-ray functions (`closest_hit`, `any_hit`) are what other Numba kernels call inside
their own `prange` loops; the `*_batch` kernels run them over arrays of rays. They are small
inlined wrappers; the traversal itself (`_closest_hit`, `_any_hit`) is compiled once, not
inlined into each caller: inlined, the traversal loop was copied into
every call site (camera chains call it five times), and the first render compiled for three
minutes instead of about one and a half, for no measurable speed. What they pass is kept
small: the BVH's arrays and the stack go as addresses and sizes (`_bvh_address`), not as
Numba's array structs, whose 52 words were pushed on the stack at every call (closest hits
+9-26 % a thread on Zen 3).

Triangle tests are float64 on float32 geometry, with no fastmath: watertightness needs exact
IEEE. Box tests are float32 and conservative (`box_constants`): a box the ray enters is never
missed, and its entry distance is never overestimated, so the closest hit is the brute-force
one. Traversal tests a node's WIDTH child boxes (`_box_test`) and a leaf's up to LEAF_LANES
triangles (`_leaf_test`) in SIMD lanes through LLVM intrinsics; each lane does exactly the
operations of the scalar `hit_box` / `hit_triangle`, in the same order.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from dpm.scene import Scene
from dpm.tracer.addresses import address, array_at, keep_alive, stack_at, stack_words
from dpm.tracer.bvh import LEAF_BITS, MAX_LEAF, RECORD, REFS, WIDTH, BVHArrays

# A leaf's triangles take one float64 lane each: 4 lanes fill one 256-bit register, which
# Zen 4 runs at full rate, where 8 lanes (512 bits) take two passes; leaves hold 2-3 triangles
# on average, so most of a 512-bit register's lanes were idle (rays/s +3-12 % with 4).
LEAF_LANES = MAX_LEAF

# Box tests run in float32 (8 lanes: half the work of float64 and no conversions of the
# float32 boxes) and are made conservative instead of exact: the near planes use the ray's
# inverse direction shrunk by 1 - _SHRINK, the far ones grown by 1 + _SHRINK (which swamps
# every float32 rounding, 2^-24 relative), and the origin's term o·inv is rounded outwards.
_SHRINK = 2.0**-18
# An axis is left out of the box tests where float32 cannot hold its constants to 2^-18:
# 1/d (or o/d) beyond 2^126 (float32's range, with room for the shrink and rounding), or 1/d
# below 2^-108, where float32 is subnormal (directions above about 1e32 in one component).
_MAX_SCALE = 2.0**126
_MIN_SCALE = 2.0**-108
_ROUND_SLACK = 2.0**-23  # float64 → float32 roundings that must go one way: twice their error
# Boxes are entered up to this factor beyond the nearest hit so far: two triangles sharing an
# edge can give distances a few ulps apart for the same point, and the nearer one must still be
# found however the boxes split them, so the BVH returns the brute-force minimum.
_CULL_SCALE = 1.0 + 2.0**-32
# A closest-hit leaf test admits hits up to this factor beyond the nearest so far: the
# watertight test's t·det against tmax·det can reject a hit at exactly t = tmax (about one
# time in twenty), and equal hits must reach the tie rule (the lower triangle wins) for the
# result not to depend on the order leaves are visited in; t < tmax decides after it.
_TIE_SCALE = 1.0 + 2.0**-40
_COUNT = (1 << LEAF_BITS) - 1  # mask of a leaf reference's triangle count
SPAWN_OFFSET = 1e-6  # new rays start this fraction of the scene diagonal off their surface
RAYS_PER_TASK = 256  # rays each parallel task traces with one traversal stack


@nb.njit(cache=True, inline="always", error_model="numpy")
def ray_setup(dx, dy, dz):
    """Per-ray constants of the watertight test: permuted axes and shear (Woop et al. 2013)."""
    kz = _dominant_axis(dx, dy, dz)
    return ray_setup_inverse(dx, dy, dz, kz, 1.0 / pick(kz, dx, dy, dz))


@nb.njit(cache=True, inline="always", error_model="numpy")
def ray_setup_inverse(dx, dy, dz, kz, inv):
    """`ray_setup` given the dominant axis kz (`_dominant_axis`) and inv = 1 / d[kz]: a
    packet has all three inverses already (the single-ray traversals use `_one_ray`)."""
    kx, ky = _other_axes(kz, pick(kz, dx, dy, dz) < 0)
    return kx, ky, kz, -pick(kx, dx, dy, dz) * inv, -pick(ky, dx, dy, dz) * inv, inv


@nb.njit(cache=True, inline="always")
def _other_axes(kz, negative):
    """The watertight test's kx, ky after axis kz, swapped where d[kz] is negative (keeps the
    winding, so front faces stay front faces)."""
    flip = np.int64(negative)
    a = kz + 1 - 3 * np.int64(kz == 2)
    b = a + 1 - 3 * np.int64(a == 2)
    return a + flip * (b - a), b + flip * (a - b)


@nb.njit(cache=True, inline="always", error_model="numpy")
def _dominant_axis(dx, dy, dz):
    """0, 1 or 2: the axis of the direction's largest component (the watertight test's z)."""
    ax, ay, az = abs(dx), abs(dy), abs(dz)
    # Selects, not branches: for incoherent rays the axes are random, and branches mispredict.
    x_max = (ax > ay) & (ax > az)
    y_max = (ay > az) & ~x_max
    return np.int64(2) - 2 * np.int64(x_max) - np.int64(y_max)


@nb.njit(cache=True, inline="always")
def pick(k, x, y, z):
    """x, y or z for k = 0, 1 or 2. Written as selects: indexing a tuple at a run-time index
    compiles to a jump table, whose mispredictions cost incoherent rays about 10 ns each."""
    return x if k == 0 else (y if k == 1 else z)


@intrinsic
def _permuted(typingctx, kx, ky, kz, x, y, z):
    """(v[kx], v[ky], v[kz]) of the float64s v = (x, y, z), through memory: stored, then
    loaded at the indices. For one ray at a time, where LLVM turns `pick`'s selects into
    branches on the ray's random axes (one thread: incoherent closest hits 1.03-1.22×,
    camera rays, whose branches predict, 0.94-1.05×); `pick` stays elsewhere (the packets'
    loops over lanes, which vectorize its selects; `hit_triangle`, the reference). Values
    are promoted to float64, as the leaf test (`_leaf_test`) promotes its origin anyway."""

    def codegen(context, builder, sig, args):
        f64, i64 = ir.DoubleType(), ir.IntType(64)
        slots = cgutils.alloca_once(builder, ir.ArrayType(f64, 3))
        for i, (a, t) in enumerate(zip(args[3:], sig.args[3:], strict=True)):
            value = context.cast(builder, a, t, types.float64)
            builder.store(value, builder.gep(slots, [ir.Constant(i64, 0), ir.Constant(i64, i)]))
        out = []
        for a, t in zip(args[:3], sig.args[:3], strict=True):
            index = context.cast(builder, a, t, types.int64)
            out.append(builder.load(builder.gep(slots, [ir.Constant(i64, 0), index])))
        return context.make_tuple(builder, sig.return_type, out)

    return types.UniTuple(types.float64, 3)(kx, ky, kz, x, y, z), codegen


@nb.njit(cache=True, inline="always", error_model="numpy")
def hit_triangle(v, i, ox, oy, oz, kx, ky, kz, sx, sy, sz, tmax):
    """Distance t in (0, tmax) to triangle row i of v (T, 9), or inf on a miss."""
    ax, ay, az = v[i, 0] - ox, v[i, 1] - oy, v[i, 2] - oz
    bx, by, bz = v[i, 3] - ox, v[i, 4] - oy, v[i, 5] - oz
    cx, cy, cz = v[i, 6] - ox, v[i, 7] - oy, v[i, 8] - oz
    a_z, b_z, c_z = pick(kz, ax, ay, az), pick(kz, bx, by, bz), pick(kz, cx, cy, cz)
    a_x = pick(kx, ax, ay, az) + sx * a_z
    a_y = pick(ky, ax, ay, az) + sy * a_z
    b_x = pick(kx, bx, by, bz) + sx * b_z
    b_y = pick(ky, bx, by, bz) + sy * b_z
    c_x = pick(kx, cx, cy, cz) + sx * c_z
    c_y = pick(ky, cx, cy, cz) + sy * c_z
    e0 = b_x * c_y - b_y * c_x
    e1 = c_x * a_y - c_y * a_x
    e2 = a_x * b_y - a_y * b_x
    if (e0 < 0 or e1 < 0 or e2 < 0) and (e0 > 0 or e1 > 0 or e2 > 0):
        return np.inf
    det = e0 + e1 + e2
    if det == 0:
        return np.inf
    tscaled = sz * (e0 * a_z + e1 * b_z + e2 * c_z)
    if det < 0 and (tscaled >= 0 or tscaled < tmax * det):
        return np.inf
    if det > 0 and (tscaled <= 0 or tscaled > tmax * det):
        return np.inf
    return tscaled / det


def _cast(context, builder, sig, args, which, to):
    """Arguments number `which` of an intrinsic, converted to Numba type `to`."""
    return [context.cast(builder, args[i], sig.args[i], to) for i in which]


def _box_test_codegen(context, builder, sig, args):
    """LLVM IR of `_box_test`: `hit_box` on WIDTH float32 lanes at once."""
    offsets = _cast(context, builder, sig, args, range(2, 8), types.int64)
    f32, i8, i32, i64 = ir.FloatType(), *map(ir.IntType, (8, 32, 64))
    vf32 = ir.VectorType(f32, WIDTH)
    array = context.make_array(sig.args[0])(context, builder, args[0])
    row_bytes = builder.extract_value(array.strides, 0)
    node = context.cast(builder, args[1], sig.args[1], types.int64)
    row = builder.gep(builder.bitcast(array.data, i8.as_pointer()), [builder.mul(node, row_bytes)])
    row = builder.bitcast(row, f32.as_pointer())
    ray, tmax = args[8], args[9]
    # llvmlite's fma helpers take scalars only: declare the vector intrinsic by its name
    fma = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(vf32, [vf32] * 3), f"llvm.fma.v{WIDTH}f32"
    )

    def splat(x):
        v = builder.insert_element(ir.Constant(vf32, ir.Undefined), x, ir.Constant(i32, 0))
        return builder.shuffle_vector(v, v, ir.Constant(ir.VectorType(i32, WIDTH), [0] * WIDTH))

    def plane(column, scale, term):
        ptr = builder.bitcast(builder.gep(row, [column]), vf32.as_pointer())
        scale, term = builder.extract_value(ray, scale), builder.extract_value(ray, term)
        x = builder.load(ptr, align=4)
        return builder.call(fma, [x, splat(scale), builder.fneg(splat(term))])

    t0 = ir.Constant(vf32, [0.0] * WIDTH)
    t1 = splat(tmax)
    for axis in range(3):
        near = plane(offsets[axis], 4 * axis, 4 * axis + 1)
        far = plane(offsets[3 + axis], 4 * axis + 2, 4 * axis + 3)
        # Compare-and-select like `hit_box`: a NaN bound leaves the interval alone.
        t0 = builder.select(builder.fcmp_ordered(">", near, t0), near, t0)
        t1 = builder.select(builder.fcmp_ordered("<", far, t1), far, t1)
    hit = builder.fcmp_ordered("<=", t0, t1)
    # The entry distances go to memory, not into a tuple: reading a tuple at a lane index
    # known only at run time compiles to jump tables, whose mispredictions cost more.
    vi32, vi64 = ir.VectorType(i32, WIDTH), ir.VectorType(i64, WIDTH)
    scratch = context.make_array(sig.args[10])(context, builder, args[10])
    rows = builder.extract_value(scratch.shape, 0)
    first = builder.mul(builder.sub(rows, ir.Constant(i64, WIDTH // 2)), ir.Constant(i64, 2))
    out = builder.bitcast(builder.gep(scratch.data, [first]), vi64.as_pointer())
    builder.store(builder.zext(builder.bitcast(t0, vi32), vi64), out, align=8)
    return builder.zext(builder.bitcast(hit, ir.IntType(WIDTH)), i64)


@intrinsic
def _box_test(typingctx, bounds, node, nx, ny, nz, fx, fy, fz, ray, tmax, stack):
    """Which child boxes of a node record the ray enters before float32 tmax (bit c for
    child c); the bits of each entry distance (`_bits32`; valid if entered) go to
    `_entry(stack, c)`.

    Columns nx, ny, nz of the node record hold the WIDTH near planes of each axis for the ray
    (the min planes where the direction is positive, the max planes where negative) and
    fx, fy, fz the far ones; `ray` is its `box_constants`. Per lane this is exactly
    `hit_box`, with the same float32 operations in the same order.
    """
    sig = types.int64(bounds, node, nx, ny, nz, fx, fy, fz, ray, tmax, stack)
    return sig, _box_test_codegen


def _leaf_test_codegen(context, builder, sig, args):
    """LLVM IR of `_leaf_test`: `hit_triangle` on LEAF_LANES float64 lanes at once."""
    planes = args[0]
    first, count, kx, ky, kz = _cast(context, builder, sig, args, range(1, 6), types.int64)
    okx, oky, okz, sx, sy, sz, tmax = _cast(
        context, builder, sig, args, range(6, 13), types.float64
    )
    f32, f64, i8, i32, i64 = (ir.FloatType(), ir.DoubleType()) + tuple(map(ir.IntType, (8, 32, 64)))
    vf32, vf64 = ir.VectorType(f32, LEAF_LANES), ir.VectorType(f64, LEAF_LANES)
    array = context.make_array(sig.args[0])(context, builder, planes)
    row_bytes = builder.extract_value(array.strides, 0)
    base = builder.gep(
        builder.bitcast(array.data, i8.as_pointer()), [builder.mul(first, ir.Constant(i64, 4))]
    )

    def splat(x):
        v = builder.insert_element(ir.Constant(vf64, ir.Undefined), x, ir.Constant(i32, 0))
        return builder.shuffle_vector(
            v, v, ir.Constant(ir.VectorType(i32, LEAF_LANES), [0] * LEAF_LANES)
        )

    def coord(vertex, k, o):
        """Lanes of (vertex coordinate k) - o, as `hit_triangle` forms a[k] = v[i, k] - o[k]."""
        row = builder.add(ir.Constant(i64, 3 * vertex), k)
        ptr = builder.gep(base, [builder.mul(row, row_bytes)])
        x = builder.load(builder.bitcast(ptr, vf32.as_pointer()), align=4)
        return builder.fsub(builder.fpext(x, vf64), splat(o))

    fsx, fsy, fsz, ftmax = splat(sx), splat(sy), splat(sz), splat(tmax)
    zero = ir.Constant(vf64, [0.0] * LEAF_LANES)
    sheared = []
    for vertex in range(3):
        ex, ey, ez = coord(vertex, kx, okx), coord(vertex, ky, oky), coord(vertex, kz, okz)
        sheared.append(
            (builder.fadd(ex, builder.fmul(fsx, ez)), builder.fadd(ey, builder.fmul(fsy, ez)), ez)
        )
    miss, tscaled, det = watertight_ir(builder, sheared, fsz, ftmax, zero)
    lane = ir.Constant(ir.VectorType(i64, LEAF_LANES), list(range(LEAF_LANES)))
    counts = builder.insert_element(
        ir.Constant(ir.VectorType(i64, LEAF_LANES), ir.Undefined), count, ir.Constant(i32, 0)
    )
    counts = builder.shuffle_vector(
        counts, counts, ir.Constant(ir.VectorType(i32, LEAF_LANES), [0] * LEAF_LANES)
    )
    live = builder.icmp_signed("<", lane, counts)
    hit = builder.and_(live, builder.not_(miss))
    mask = builder.uitofp(builder.zext(builder.bitcast(hit, ir.IntType(LEAF_LANES)), i64), f64)
    lanes = [builder.extract_element(v, ir.Constant(i32, c)) for v in (tscaled, det)
             for c in range(LEAF_LANES)]  # fmt: skip
    return context.make_tuple(builder, sig.return_type, [mask, *lanes])


def watertight_ir(builder, sheared, sz, tmax, zero):
    """LLVM IR of `hit_triangle` after the shear, on vectors of lanes: (miss mask, t·det,
    det). sheared holds the three vertices' (x, y, z) relative to the origin, sheared;
    sz, tmax and zero are vectors; the operations are `hit_triangle`'s, in its order."""
    (a_x, a_y, a_z), (b_x, b_y, b_z), (c_x, c_y, c_z) = sheared
    e0 = builder.fsub(builder.fmul(b_x, c_y), builder.fmul(b_y, c_x))
    e1 = builder.fsub(builder.fmul(c_x, a_y), builder.fmul(c_y, a_x))
    e2 = builder.fsub(builder.fmul(a_x, b_y), builder.fmul(a_y, b_x))

    def cmp(op, x, y):
        return builder.fcmp_ordered(op, x, y)

    def any3(op):
        return builder.or_(builder.or_(cmp(op, e0, zero), cmp(op, e1, zero)), cmp(op, e2, zero))

    miss = builder.and_(any3("<"), any3(">"))
    det = builder.fadd(builder.fadd(e0, e1), e2)
    miss = builder.or_(miss, cmp("==", det, zero))
    tsum = builder.fadd(
        builder.fadd(builder.fmul(e0, a_z), builder.fmul(e1, b_z)), builder.fmul(e2, c_z)
    )
    tscaled = builder.fmul(sz, tsum)
    tdet = builder.fmul(tmax, det)
    neg = builder.or_(cmp(">=", tscaled, zero), cmp("<", tscaled, tdet))
    pos = builder.or_(cmp("<=", tscaled, zero), cmp(">", tscaled, tdet))
    miss = builder.or_(miss, builder.and_(cmp("<", det, zero), neg))
    miss = builder.or_(miss, builder.and_(cmp(">", det, zero), pos))
    return miss, tscaled, det


@intrinsic
def _leaf_test(typingctx, planes, first, count, kx, ky, kz, okx, oky, okz, sx, sy, sz, tmax):
    """(mask, n_0, ..., n_LEAF_LANES-1, d_0, ..., d_LEAF_LANES-1): `hit_triangle` for
    triangles first ... first + count - 1 (count ≤ LEAF_LANES) at once, from the plane-major
    copy `tri_planes` of their vertices, all but its last step: bit j of mask (a float64
    holding a small integer) is set where triangle first + j may be hit at distance
    t_j = n_j / d_j (`_lane_distance`), which the caller still compares with tmax: rounding
    and non-finite inputs can set a bit whose t_j is not below it. The division is left to
    the few lanes the caller needs: most leaf tests hit nothing, and a 4-lane division is the
    test's slowest operation. okx, oky, okz are the ray origin's coordinates kx, ky, kz; per
    lane the float64 operations are those of `hit_triangle`, in its order.
    """
    sig = types.UniTuple(types.float64, 2 * LEAF_LANES + 1)(
        planes, first, count, kx, ky, kz, okx, oky, okz, sx, sy, sz, tmax
    )
    return sig, _leaf_test_codegen


@nb.njit(cache=True, inline="always")
def _lane_distance(hits, c):
    """Lane c's distance t_c of a `_leaf_test` result (its last step, the division; IEEE
    division rounds the same in a scalar as in a vector lane)."""
    return hits[1 + c] / hits[1 + LEAF_LANES + c]


@intrinsic
def _bits32(typingctx, x):
    """The IEEE bits of float32 x as an int64: for x ≥ 0 (and +inf) they order as x does."""

    def codegen(context, builder, sig, args):
        return builder.zext(builder.bitcast(args[0], ir.IntType(32)), ir.IntType(64))

    return types.int64(types.float32), codegen


@intrinsic
def _fma32(typingctx, a, b, c):
    """a·b + c of float32s with one rounding (the lanes of `_box_test` do the same)."""

    def codegen(context, builder, sig, args):
        return builder.fma(*args)

    return types.float32(types.float32, types.float32, types.float32), codegen


@intrinsic
def _lowest_bit(typingctx, mask):
    """Index of the lowest set bit of a non-zero int64."""

    def codegen(context, builder, sig, args):
        return builder.cttz(args[0], ir.Constant(ir.IntType(1), 1))

    return types.int64(types.int64), codegen


@nb.njit(cache=True, inline="always", error_model="numpy")
def _float32_up(x):
    """A float32 ≥ float64 x, within 2^-22 of it (+ 1e-37); NaN stays NaN. (Rounding to
    nearest moves x by at most 2^-24 of itself; np.nextafter would be exact but is a libm
    call, and this runs several times a ray.)"""
    return np.float32(x + _ROUND_SLACK * abs(x) + 1e-37)


@nb.njit(cache=True, inline="always", error_model="numpy")
def _float32_down(x):
    """A float32 ≤ float64 x, within 2^-22 of it (- 1e-37); NaN stays NaN."""
    return np.float32(x - _ROUND_SLACK * abs(x) - 1e-37)


@nb.njit(cache=True, inline="always", error_model="numpy")
def box_constants(ox, oy, oz, ix, iy, iz):
    """12 float32 constants of the box test of the ray from o with inverse direction i: per
    axis (near scale, near term, far scale, far term). A plane at coordinate x is crossed at
    fma(x, scale, -term); near planes use (i·(1 - _SHRINK), o·scale rounded up), far planes
    (i·(1 + _SHRINK), o·scale rounded down).

    With these, a box the ray enters at a (real) distance in [0, tmax] is always entered, at
    a distance no greater: the scales move the true distance (x - o)·i inwards by 2^-18 of
    itself, more than the fma's rounding moves it out, and the terms' rounding only moves
    near planes nearer and far planes farther. A zero direction component gives inf scales;
    the NaNs of inf - inf then leave that axis out, which only enters more boxes. An axis
    whose constants float32 cannot hold to that precision (|1/d| or |o/d| above _MAX_SCALE,
    |1/d| below _MIN_SCALE) is left out the same way, with NaN constants.
    """
    nx, cnx, fx, cfx = _axis_constants(ox, ix)
    ny, cny, fy, cfy = _axis_constants(oy, iy)
    nz, cnz, fz, cfz = _axis_constants(oz, iz)
    return nx, cnx, fx, cfx, ny, cny, fy, cfy, nz, cnz, fz, cfz


def _box_constants_codegen(context, builder, sig, args):
    """LLVM IR of `box_constants_simd`: `box_constants` with the three axes in the lanes of
    one 4 × float64 vector (the fourth idle), the same operations per lane in the same order
    (no fused multiply-adds: LLVM contracts nothing without fast-math flags)."""
    f32, f64, i32 = ir.FloatType(), ir.DoubleType(), ir.IntType(32)
    v64, v32 = ir.VectorType(f64, 4), ir.VectorType(f32, 4)
    ox, oy, oz, ix, iy, iz = args

    def vector(values):
        v = ir.Constant(v64, [0.0] * 4)
        for lane, x in enumerate(values):
            v = builder.insert_element(v, x, ir.Constant(i32, lane))
        return v

    def const(x):
        return ir.Constant(v64, [x] * 4)

    fabs = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(v64, [v64]), "llvm.fabs.v4f64"
    )
    o, inv = vector([ox, oy, oz]), vector([ix, iy, iz, ir.Constant(f64, 1.0)])
    near = builder.fptrunc(builder.fmul(inv, const(1.0 - _SHRINK)), v32)
    far = builder.fptrunc(builder.fmul(inv, const(1.0 + _SHRINK)), v32)
    x = builder.fmul(o, builder.fpext(near, v64))
    near_term = builder.fadd(
        builder.fadd(x, builder.fmul(const(_ROUND_SLACK), builder.call(fabs, [x]))), const(1e-37)
    )
    y = builder.fmul(o, builder.fpext(far, v64))
    far_term = builder.fsub(
        builder.fsub(y, builder.fmul(const(_ROUND_SLACK), builder.call(fabs, [y]))), const(1e-37)
    )
    size = builder.call(fabs, [inv])
    keep = builder.and_(
        builder.fcmp_ordered(">=", size, const(_MIN_SCALE)),
        builder.fcmp_ordered("<=", size, const(_MAX_SCALE)),
    )
    reach = builder.fmul(builder.call(fabs, [o]), size)
    keep = builder.and_(keep, builder.fcmp_ordered("<=", reach, const(_MAX_SCALE)))
    keep = builder.or_(keep, builder.fcmp_ordered("==", size, const(np.inf)))
    nan = ir.Constant(v32, [float("nan")] * 4)
    columns = [
        builder.select(keep, v, nan)
        for v in (near, builder.fptrunc(near_term, v32), far, builder.fptrunc(far_term, v32))
    ]
    out = [builder.extract_element(c, ir.Constant(i32, axis)) for axis in range(3) for c in columns]
    return context.make_tuple(builder, sig.return_type, out)


@intrinsic
def box_constants_simd(typingctx, ox, oy, oz, ix, iy, iz):
    """`box_constants`, the three axes computed at once in SIMD lanes (float32 arguments are
    promoted): equal to it bit for bit (tested)."""
    sig = types.UniTuple(types.float32, 12)(*[types.float64] * 6)
    return sig, _box_constants_codegen


@nb.njit(cache=True, inline="always", error_model="numpy")
def _axis_constants(o, inv):
    """(near scale, near term, far scale, far term) of one axis for `box_constants`, all NaN
    where float32 would lose the bound. Selects, not branches (this runs for every ray)."""
    near = np.float32(inv * (1.0 - _SHRINK))
    far = np.float32(inv * (1.0 + _SHRINK))
    near_term = _float32_up(o * np.float64(near))
    far_term = _float32_down(o * np.float64(far))
    size = abs(inv)
    keep = ((size >= _MIN_SCALE) & (size <= _MAX_SCALE) & (abs(o) * size <= _MAX_SCALE)) | (
        size == np.inf  # a zero direction component: see above
    )
    nan = np.float32(np.nan)
    # selects, not a branch: a loop over a packet's lanes vectorizes (`dpm.tracer.packet`)
    return (near if keep else nan, near_term if keep else nan, far if keep else nan,
            far_term if keep else nan)  # fmt: skip


@nb.njit(cache=True, inline="always", error_model="numpy")
def hit_box(lo, hi, ray, tmax):
    """Entry distance (float32) into the box [lo, hi] (two 3-sequences of float32) of the ray
    with `box_constants` ray, if entered before float32 tmax, else inf.

    Compare-and-select, not min/max, so a NaN bound (a ray lying in a box face, or a zero
    direction component) leaves the interval alone rather than turning into a miss. The near
    and far planes are chosen by the sign of the scales, never by comparing the distances.
    """
    t0, t1 = np.float32(0.0), tmax
    for axis in range(3):
        a, b = np.float32(lo[axis]), np.float32(hi[axis])
        if ray[4 * axis] < 0:
            a, b = b, a
        near = _fma32(a, ray[4 * axis], -ray[4 * axis + 1])
        far = _fma32(b, ray[4 * axis + 2], -ray[4 * axis + 3])
        if near > t0:
            t0 = near
        if far < t1:
            t1 = far
    return t0 if t0 <= t1 else np.float32(np.inf)


@nb.njit(cache=True, inline="always")
def _planes(ix, iy, iz):
    """Record columns of the near and far planes of the child boxes, per axis."""
    nx = 3 * WIDTH if ix < 0 else 0
    ny = 4 * WIDTH if iy < 0 else WIDTH
    nz = 5 * WIDTH if iz < 0 else 2 * WIDTH
    return nx, ny, nz, 3 * WIDTH - nx, 5 * WIDTH - ny, 7 * WIDTH - nz


@nb.njit(cache=True)
def new_stack(depth):
    """Traversal scratch for one thread: int64 rows of (node reference, entry distance bits).

    A wide node pushes at most WIDTH - 1 more entries than it pops, per level of `depth`; the
    last WIDTH / 2 rows hold the entry distances of the latest box test (`_entry`).
    """
    rows = (WIDTH - 1) * depth + 1 + WIDTH // 2
    raw = np.empty((rows + 3, 2), np.int64)
    # The scratch (the last WIDTH / 2 rows, 64 bytes) on a cache line of its own: the box test
    # stores it in one 64-byte write that the next loads read back, and a write split over two
    # lines cannot forward to them (at random alignment, rays/s varied 12-19 M from run to run).
    end = raw.ctypes.data + (rows - WIDTH // 2) * 16
    skip = (-end % 64) // 16
    return raw[skip : skip + rows]


@nb.njit(cache=True, inline="always")
def _entry(stack, c):
    """The bits of child c's entry distance from the latest `_box_test` on this stack."""
    return stack[stack.shape[0] - WIDTH // 2 + (c >> 1), c & 1]


_float32_2d, _int32_2d, _int32_1d = (
    array_at(types.float32, 2), array_at(types.int32, 2), array_at(types.int32, 1),
)  # fmt: skip


@nb.njit(cache=True, inline="always")
def _bvh_at(nodes, n_nodes, planes, n_planes, order, n_tri):
    """The BVHArrays at the addresses `_bvh_address` gave (tri_verts left empty: traversal
    does not read it)."""
    return BVHArrays(
        _float32_2d(nodes, (n_nodes, RECORD)),
        _int32_2d(nodes, (n_nodes, RECORD)),
        _float32_2d(planes, (0, 9)),
        _int32_1d(order, (n_tri,)),
        _float32_2d(planes, (9, n_planes)),
    )


@nb.njit(cache=True, inline="always")
def _bvh_address(bvh):
    """A BVHArrays as six integers (addresses and sizes) for `_bvh_at`: fewer than
    `dpm.tracer.addresses`' general form (the boxes and references share their memory, and
    the vertices are not read), as traversal is called most."""
    return (address(bvh.bounds), bvh.bounds.shape[0], address(bvh.tri_planes),
            bvh.tri_planes.shape[1], address(bvh.tri_index), bvh.tri_index.shape[0])  # fmt: skip


@nb.njit(cache=True, inline="always", error_model="numpy")
def _one_ray(ox, oy, oz, dx, dy, dz):
    """The ray from o along d as `closest_below` and `any_below` take it: (`box_constants`,
    `_planes`, axes k, origin along them, shear), all without branches on its direction."""
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    kz = _dominant_axis(dx, dy, dz)
    # as `ray_setup_inverse`, with d[kz] < 0 read off the signs (no pick)
    kx, ky = _other_axes(
        kz, ((kz == 0) & (dx < 0)) | ((kz == 1) & (dy < 0)) | ((kz == 2) & (dz < 0))
    )
    ax, ay, az = _permuted(kx, ky, kz, dx, dy, dz)
    o = _permuted(kx, ky, kz, ox, oy, oz)
    inv = 1.0 / az
    s = (-ax * inv, -ay * inv, inv)
    ray = box_constants_simd(ox, oy, oz, ix, iy, iz)
    return ray, _planes(ix, iy, iz), (kx, ky, kz), o, s


@nb.njit(cache=True, inline="always")
def closest_hit(bvh, ox, oy, oz, dx, dy, dz, tmax, stack):
    """(t, scene triangle index) of the nearest hit in (0, tmax), or (inf, -1).

    `bvh` is a BVHArrays; `stack` is scratch from `new_stack`. Inlined: it passes the arrays
    to `_closest_hit` (not inlined) as addresses.
    """
    out = _closest_hit(*_bvh_address(bvh), ox, oy, oz, dx, dy, dz, tmax, *stack_words(stack))
    keep_alive(bvh, stack)
    return out


@nb.njit(cache=True, _nrt=False, error_model="numpy")
def _closest_hit(nodes, n_nodes, planes, n_planes, order, n_tri, ox, oy, oz, dx, dy, dz, tmax,
                 stack_address, stack_rows):  # fmt: skip
    """`closest_hit` on the words `_bvh_address` and `stack_words` give."""
    bvh = _bvh_at(nodes, n_nodes, planes, n_planes, order, n_tri)
    stack = stack_at(stack_address, (stack_rows, 2))
    ray, planes_at, k, o, s = _one_ray(ox, oy, oz, dx, dy, dz)
    best_t, best = closest_below(bvh, 0, ray, planes_at, k, o, s, tmax, -1, stack)
    if best < 0:
        return np.inf, -1
    return best_t, bvh.tri_index[best]


@nb.njit(cache=True, inline="always", _nrt=False, error_model="numpy")
def closest_below(bvh, start, ray, planes_at, k, o, s, best_t, best, stack):
    """(t, BVH-order triangle) of the nearest hit below node reference `start` nearer than
    (best_t, best), or (best_t, best) itself; of hits at equal t the lower triangle wins
    (each leaf test admitting hits a little beyond best_t, `_TIE_SCALE`, so that equal ones
    reach that rule), so the result does not depend on the order subtrees are visited in.

    The ray is given by its `box_constants` ray, `_planes` planes_at, and its watertight
    constants: axes k = (kx, ky, kz), origin coordinates o along them, shear s (sx, sy, sz).
    """
    bounds, kids, planes = bvh.bounds, bvh.kids, bvh.tri_planes
    nx, ny, nz, fx, fy, fz = planes_at
    kx, ky, kz = k
    sx, sy, sz = s
    far = _float32_up(best_t * _CULL_SCALE)
    cull = _bits32(far)
    ref, sp = start, 0
    while True:
        if ref >= 0:
            m = _box_test(bounds, ref, nx, ny, nz, fx, fy, fz, ray, far, stack)
            if m != 0:
                c = _lowest_bit(m)
                m &= m - 1
                if m == 0:  # one child entered: descend, no stack traffic
                    ref = kids[ref, REFS + c]
                    continue
                c2 = _lowest_bit(m)
                m &= m - 1
                a, da = kids[ref, REFS + c], _entry(stack, c)
                b, db = kids[ref, REFS + c2], _entry(stack, c2)
                if db < da:
                    a, da, b, db = b, db, a, da
                if m == 0:  # two: descend into the nearer, the farther waits
                    stack[sp, 0], stack[sp, 1] = b, db
                    sp += 1
                    ref = a
                    continue
                # Three or more: push them all, sorted so the nearest is on top, and pop it.
                stack[sp, 0], stack[sp, 1] = b, db
                stack[sp + 1, 0], stack[sp + 1, 1] = a, da
                base = sp
                sp += 2
                while m != 0:
                    c = _lowest_bit(m)
                    m &= m - 1
                    dc = _entry(stack, c)
                    j = sp
                    while j > base and stack[j - 1, 1] < dc:
                        stack[j, 0], stack[j, 1] = stack[j - 1, 0], stack[j - 1, 1]
                        j -= 1
                    stack[j, 0], stack[j, 1] = kids[ref, REFS + c], dc
                    sp += 1
                sp -= 1
                ref = stack[sp, 0]
                continue
        else:
            code = ~ref
            first = code >> LEAF_BITS
            loose = best_t * _TIE_SCALE
            hits = _leaf_test(planes, first, code & _COUNT, kx, ky, kz, *o, sx, sy, sz, loose)
            m = int(hits[0])
            if m != 0:
                while m != 0:
                    c = _lowest_bit(m)
                    m &= m - 1
                    t = _lane_distance(hits, c)
                    if t < best_t or (t == best_t and first + c < best):
                        best_t, best = t, first + c
                far = _float32_up(best_t * _CULL_SCALE)
                cull = _bits32(far)
        # Pop the next subtree that may still hold a nearer hit.
        while sp > 0 and stack[sp - 1, 1] > cull:
            sp -= 1
        if sp == 0:
            break
        sp -= 1
        ref = stack[sp, 0]
    return best_t, best


@nb.njit(cache=True, inline="always")
def any_hit(bvh, ox, oy, oz, dx, dy, dz, tmax, stack):
    """True if the ray hits any triangle at a distance in (0, tmax). Inlined, as
    `closest_hit`: the work is in `_any_hit`."""
    out = _any_hit(*_bvh_address(bvh), ox, oy, oz, dx, dy, dz, tmax, *stack_words(stack))
    keep_alive(bvh, stack)
    return out


@nb.njit(cache=True, _nrt=False, error_model="numpy")
def _any_hit(nodes, n_nodes, planes, n_planes, order, n_tri, ox, oy, oz, dx, dy, dz, tmax,
             stack_address, stack_rows):  # fmt: skip
    """`any_hit` on the words `_bvh_address` and `stack_words` give."""
    bvh = _bvh_at(nodes, n_nodes, planes, n_planes, order, n_tri)
    stack = stack_at(stack_address, (stack_rows, 2))
    ray, planes_at, k, o, s = _one_ray(ox, oy, oz, dx, dy, dz)
    return any_below(bvh, 0, ray, planes_at, k, o, s, tmax, stack)


@nb.njit(cache=True, inline="always", _nrt=False, error_model="numpy")
def any_below(bvh, start, ray, planes_at, k, o, s, tmax, stack):
    """True if the ray (given as to `closest_below`) hits a triangle below node reference
    `start` at a distance in (0, tmax)."""
    bounds, kids, planes = bvh.bounds, bvh.kids, bvh.tri_planes
    nx, ny, nz, fx, fy, fz = planes_at
    kx, ky, kz = k
    sx, sy, sz = s
    far = _float32_up(tmax * _CULL_SCALE)
    stack[0, 0] = start
    sp = 1
    while sp > 0:
        sp -= 1
        ref = stack[sp, 0]
        if ref < 0:  # only where `start` is a leaf
            return _leaf_any(planes, ref, k, o, s, tmax)
        m = _box_test(bounds, ref, nx, ny, nz, fx, fy, fz, ray, far, stack)
        while m != 0:
            c = _lowest_bit(m)
            m &= m - 1
            child = kids[ref, REFS + c]
            if child >= 0:
                stack[sp, 0] = child
                sp += 1
            elif _leaf_any(planes, child, k, o, s, tmax):
                return True
    return False


@nb.njit(cache=True, inline="always", _nrt=False, error_model="numpy")
def _leaf_any(planes, ref, k, o, s, tmax):
    """True if the ray hits a triangle of leaf reference ref at a distance in (0, tmax)."""
    code = ~ref
    first = code >> LEAF_BITS
    hits = _leaf_test(planes, first, code & _COUNT, *k, *o, *s, tmax)
    lanes = int(hits[0])
    while lanes != 0:  # hits count only strictly before tmax (hit_triangle admits tmax)
        lane = _lowest_bit(lanes)
        lanes &= lanes - 1
        if _lane_distance(hits, lane) < tmax:
            return True
    return False


@nb.njit(cache=True, inline="always")
def _ray_flags(ox, oy, oz, dx, dy, dz):
    """Bit 0: origin o or direction d not finite; bit 1: d is zero."""
    # x - x is 0 for finite x and NaN for inf or NaN: one comparison for all six numbers
    finite = (ox - ox) + (oy - oy) + (oz - oz) + (dx - dx) + (dy - dy) + (dz - dz) == 0
    still = (dx == 0) & (dy == 0) & (dz == 0)
    return np.int64(not finite) | (np.int64(still) << 1)


@nb.njit(cache=True, inline="always")
def _ray(origins, directions, r):
    """Ray r of (R, 3) arrays as six float64 scalars (no array views: in a parallel loop each
    view would update a shared reference count)."""
    return (
        np.float64(origins[r, 0]), np.float64(origins[r, 1]), np.float64(origins[r, 2]),
        np.float64(directions[r, 0]), np.float64(directions[r, 1]), np.float64(directions[r, 2]),
    )  # fmt: skip


@nb.njit(cache=True, inline="always")
def _or_all(flags):
    """The bitwise or of an int64 array."""
    out = 0
    for f in flags:
        out |= f
    return out


@nb.njit(cache=True, parallel=True, error_model="numpy")
def closest_hit_batch(bvh, depth, origins, directions, tmax, out_t, out_tri):
    """Closest hits of rays (R, 3) into out_t (R,) float64 and out_tri (R,) int32, up to tmax
    (R,) or (1,) for all. Returns `_ray_flags` of all rays or'ed; a flagged ray is not traced."""
    n = origins.shape[0]
    n_tasks = (n + RAYS_PER_TASK - 1) // RAYS_PER_TASK
    flags = np.zeros(n_tasks, np.int64)
    for task in nb.prange(n_tasks):
        stack = new_stack(depth)
        for r in range(task * RAYS_PER_TASK, min(n, (task + 1) * RAYS_PER_TASK)):
            ox, oy, oz, dx, dy, dz = _ray(origins, directions, r)
            bad = _ray_flags(ox, oy, oz, dx, dy, dz)
            if bad:
                flags[task] |= bad
                out_t[r], out_tri[r] = np.inf, -1
                continue
            limit = tmax[r if tmax.shape[0] > 1 else 0]
            out_t[r], out_tri[r] = closest_hit(bvh, ox, oy, oz, dx, dy, dz, limit, stack)
    return _or_all(flags)


@nb.njit(cache=True, parallel=True, error_model="numpy")
def any_hit_batch(bvh, depth, origins, directions, tmax, out):
    """Occlusion of rays (R, 3) within tmax (R,) or (1,) into out (R,) bool. Returns
    `_ray_flags` of all rays or'ed; a flagged ray is not traced."""
    n = origins.shape[0]
    n_tasks = (n + RAYS_PER_TASK - 1) // RAYS_PER_TASK
    flags = np.zeros(n_tasks, np.int64)
    for task in nb.prange(n_tasks):
        stack = new_stack(depth)
        for r in range(task * RAYS_PER_TASK, min(n, (task + 1) * RAYS_PER_TASK)):
            ox, oy, oz, dx, dy, dz = _ray(origins, directions, r)
            bad = _ray_flags(ox, oy, oz, dx, dy, dz)
            if bad:
                flags[task] |= bad
                out[r] = False
                continue
            limit = tmax[r if tmax.shape[0] > 1 else 0]
            out[r] = any_hit(bvh, ox, oy, oz, dx, dy, dz, limit, stack)
    return _or_all(flags)


@nb.njit(cache=True, parallel=True, error_model="numpy")
def brute_force_batch(verts, origins, directions, tmax, out_t, out_tri):
    """Closest hits by testing every triangle of verts (T, 9): the BVH's reference. Rays and
    tmax as `closest_hit_batch`'s, and the same return value."""
    n = origins.shape[0]
    flags = np.zeros(n, np.int64)
    for ray in nb.prange(n):
        r = np.int64(ray)  # the prange index is unsigned: mixed with int64 it turns float
        ox, oy, oz, dx, dy, dz = _ray(origins, directions, r)
        flags[r] = _ray_flags(ox, oy, oz, dx, dy, dz)
        out_t[r], out_tri[r] = np.inf, -1
        if flags[r]:
            continue
        kx, ky, kz, sx, sy, sz = ray_setup(dx, dy, dz)
        best_t, best = tmax[r if tmax.shape[0] > 1 else 0], -1
        for i in range(verts.shape[0]):
            t = hit_triangle(verts, i, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t)
            if t < best_t:
                best_t, best = t, i
        if best >= 0:
            out_t[r], out_tri[r] = best_t, best
    return _or_all(flags)


def spawn_offset(scene: Scene) -> float:
    """Distance (scene units) new rays start off the surface they leave, against self-hits.

    Hit points are float64 on float32 triangles, so their error is far below this offset.
    """
    return SPAWN_OFFSET * max(scene.extent, 1e-30)
