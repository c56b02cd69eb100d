"""Packets of up to LANES rays traced together through the BVH (closest hit, any hit).

Rays that start near each other and point alike (a pixel's camera samples, their shadow rays
to a light, the bounces of a pixel's paths) enter mostly the same nodes. A packet tests each
node's WIDTH child boxes against all its rays at once, one child per LANES-wide SIMD
comparison (`_packet_node`), and each leaf triangle against all of them at once
(`_leaf_lanes`); a subtree that only a few rays enter (SWITCH or fewer) is left to each of
them alone (`closest_below`, `any_below`), as Embree's hybrid traversal does. Per lane the
box and triangle tests are the single-ray ones, operation for operation, and equal hits go
to the lower triangle in both, so a packet returns exactly what `closest_hit` returns for
each of its rays (tested).

A packet's state lives in `new_packet`'s arrays: per lane the ray (origin, direction), its
watertight constants, box constants (`box_constants`, lane-major rows) and nearest hit so
far. The traversal functions are inlined into their callers' loops: called, they passed
some thirty arrays by value per packet, a fifth of a coherent packet's time.
"""

from __future__ import annotations

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

from dpm.tracer.addresses import by_address
from dpm.tracer.bvh import LEAF_BITS, REFS, WIDTH
from dpm.tracer.traverse import (
    _COUNT,
    _CULL_SCALE,
    _ROUND_SLACK,
    _TIE_SCALE,
    _axis_constants,
    _bits32,
    _dominant_axis,
    _float32_up,
    _lowest_bit,
    _or_all,
    _ray,
    _ray_flags,
    any_below,
    closest_below,
    new_stack,
    pick,
    ray_setup_inverse,
    watertight_ir,
)

LANES = 16  # rays per packet: one AVX-512 register of float32 box distances
# A subtree entered by this many of the packet's rays or fewer is traced by each alone (the
# glass egg's and the dragon's camera and bounce rays: 1, 3 and 5 within noise, 8 slower).
SWITCH = 3
TASK_RAYS = 64 * LANES  # rays of a task of the batch kernels (allocation amortised)


def _vector_helpers(builder, element, lanes=LANES):
    """(vector type, splat(x)) for `lanes` lanes of LLVM type element."""
    vt = ir.VectorType(element, lanes)
    i32 = ir.IntType(32)

    def splat(x):
        v = builder.insert_element(ir.Constant(vt, ir.Undefined), x, ir.Constant(i32, 0))
        return builder.shuffle_vector(v, v, ir.Constant(ir.VectorType(i32, lanes), [0] * lanes))

    return vt, splat


def _packet_node_codegen(context, builder, sig, args):
    """LLVM IR of `_packet_node`: per child, `hit_box` on LANES float32 lanes at once."""
    f32, i8, i32, i64 = ir.FloatType(), *map(ir.IntType, (8, 32, 64))
    vf, splat = _vector_helpers(builder, f32)
    vi, splat_i = _vector_helpers(builder, i32)
    bounds = context.make_array(sig.args[0])(context, builder, args[0])
    node = context.cast(builder, args[1], sig.args[1], types.int64)
    rc = context.make_array(sig.args[2])(context, builder, args[2])
    far = context.make_array(sig.args[3])(context, builder, args[3])
    mask = context.cast(builder, args[4], sig.args[4], types.int64)
    out = builder.bitcast(context.make_array(sig.args[5])(context, builder, args[5]).data,
                          i64.as_pointer())  # fmt: skip
    row_bytes = builder.extract_value(bounds.strides, 0)
    row = builder.gep(builder.bitcast(bounds.data, i8.as_pointer()), [builder.mul(node, row_bytes)])
    row = builder.bitcast(row, f32.as_pointer())
    rc_ptr = builder.bitcast(rc.data, f32.as_pointer())
    fma = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(vf, [vf] * 3), f"llvm.fma.v{LANES}f32"
    )
    # the least entry distance by an integer reduction of the bits (distances are ≥ 0, so
    # their bits order as they do): a float reduction handles NaN and cost 4x the box test
    umin = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(i32, [vi]), f"llvm.vector.reduce.umin.v{LANES}i32"
    )

    def lanes(r):
        p = builder.gep(rc_ptr, [ir.Constant(i64, r * LANES)])
        return builder.load(builder.bitcast(p, vf.as_pointer()), align=4)

    zero = ir.Constant(vf, [0.0] * LANES)
    axes = []
    for axis in range(3):
        ns, nt, fs, ft = (lanes(4 * axis + k) for k in range(4))
        # `hit_box` swaps the planes where the near scale is negative (not where it is NaN)
        axes.append((builder.fcmp_ordered("<", ns, zero), ns, builder.fneg(nt), fs,
                     builder.fneg(ft)))  # fmt: skip
    tmax = builder.load(builder.bitcast(far.data, vf.as_pointer()), align=4)
    inf = ir.Constant(vf, [float("inf")] * LANES)
    # the lanes of mask, as a vector of booleans: only they count (bits and least distances)
    bit = ir.Constant(vi, [1 << lane for lane in range(LANES)])
    lanes_on = builder.and_(splat_i(builder.trunc(mask, i32)), bit)
    on = builder.icmp_unsigned("!=", lanes_on, ir.Constant(vi, [0] * LANES))
    entered = ir.Constant(i64, 0)
    for c in range(WIDTH):
        t0, t1 = zero, tmax
        for axis, (neg, ns, nt, fs, ft) in enumerate(axes):
            lo = splat(builder.load(builder.gep(row, [ir.Constant(i64, axis * WIDTH + c)])))
            hi = splat(builder.load(builder.gep(row, [ir.Constant(i64, (3 + axis) * WIDTH + c)])))
            near = builder.call(fma, [builder.select(neg, hi, lo), ns, nt])
            farther = builder.call(fma, [builder.select(neg, lo, hi), fs, ft])
            t0 = builder.select(builder.fcmp_ordered(">", near, t0), near, t0)
            t1 = builder.select(builder.fcmp_ordered("<", farther, t1), farther, t1)
        hit = builder.and_(builder.fcmp_ordered("<=", t0, t1), on)
        m = builder.zext(builder.bitcast(hit, ir.IntType(LANES)), i64)
        least = builder.call(umin, [builder.bitcast(builder.select(hit, t0, inf), vi)])
        builder.store(m, builder.gep(out, [ir.Constant(i64, c)]))
        builder.store(builder.zext(least, i64), builder.gep(out, [ir.Constant(i64, WIDTH + c)]))
        some = builder.zext(builder.icmp_unsigned("!=", m, ir.Constant(i64, 0)), i64)
        entered = builder.or_(entered, builder.shl(some, ir.Constant(i64, c)))
    return entered


@intrinsic
def _packet_node(typingctx, bounds, node, rc, far, mask, out):
    """Bit c set where a lane of mask enters child c of node record `node` before its far
    (LANES float32); out[c] (int64) gets those lanes, out[WIDTH + c] the `_bits32` of their
    (those lanes') least entry distance. rc holds the lanes' `box_constants`, row r at
    r·LANES."""
    sig = types.int64(bounds, node, rc, far, mask, out)
    return sig, _packet_node_codegen


def _leaf_lanes_codegen(context, builder, sig, args):
    """LLVM IR of `_leaf_lanes`: `hit_triangle` on LANES float64 lanes at once."""
    f32, f64, i8, i64 = ir.FloatType(), ir.DoubleType(), ir.IntType(8), ir.IntType(64)
    vd, splat_d = _vector_helpers(builder, f64)
    vf, _ = _vector_helpers(builder, f32)
    vl, splat_l = _vector_helpers(builder, i64)
    verts = context.make_array(sig.args[0])(context, builder, args[0])
    i = context.cast(builder, args[1], sig.args[1], types.int64)
    mask = context.cast(builder, args[2], sig.args[2], types.int64)
    arrays = [context.make_array(sig.args[k])(context, builder, args[k]) for k in range(3, 15)]

    def ptr(k, vt):
        return builder.bitcast(arrays[k].data, vt.as_pointer())

    ox, oy, oz = (builder.load(ptr(k, vd), align=8) for k in range(3))
    kx, ky, kz = (builder.load(ptr(k, vl), align=8) for k in range(3, 6))
    sx, sy, sz = (builder.load(ptr(k, vd), align=8) for k in range(6, 9))
    best_t = builder.load(ptr(9, vd), align=8)
    best = builder.load(ptr(10, vl), align=8)
    far = builder.load(ptr(11, vf), align=4)
    row_bytes = builder.extract_value(verts.strides, 0)
    row = builder.gep(builder.bitcast(verts.data, i8.as_pointer()), [builder.mul(i, row_bytes)])
    row = builder.bitcast(row, f32.as_pointer())

    def coord(k):
        return splat_d(builder.fpext(builder.load(builder.gep(row, [ir.Constant(i64, k)])), f64))

    zero_l, one_l = ir.Constant(vl, [0] * LANES), ir.Constant(vl, [1] * LANES)

    def picker(k):
        """`pick` per lane, as selects."""
        is0, is1 = builder.icmp_signed("==", k, zero_l), builder.icmp_signed("==", k, one_l)
        return lambda x, y, z: builder.select(is0, x, builder.select(is1, y, z))

    px, py, pz = picker(kx), picker(ky), picker(kz)
    sheared = []
    for v in range(3):
        ax, ay, az = (builder.fsub(coord(3 * v + a), o) for a, o in enumerate((ox, oy, oz)))
        z = pz(ax, ay, az)
        sheared.append((builder.fadd(px(ax, ay, az), builder.fmul(sx, z)),
                        builder.fadd(py(ax, ay, az), builder.fmul(sy, z)), z))  # fmt: skip
    zero = ir.Constant(vd, [0.0] * LANES)
    # the limit loosened by _TIE_SCALE, as `closest_below`'s, so equal hits reach the tie rule
    loose = builder.fmul(best_t, ir.Constant(vd, [_TIE_SCALE] * LANES))
    miss, ts, det = watertight_ir(builder, sheared, sz, loose, zero)
    t = builder.fdiv(ts, det)
    lane = ir.Constant(vl, list(range(LANES)))
    on = builder.icmp_signed("!=", builder.and_(builder.lshr(splat_l(mask), lane), one_l), zero_l)
    index = splat_l(i)
    nearer = builder.or_(
        builder.fcmp_ordered("<", t, best_t),
        builder.and_(builder.fcmp_ordered("==", t, best_t), builder.icmp_signed("<", index, best)),
    )
    better = builder.and_(builder.and_(on, builder.not_(miss)), nearer)
    builder.store(builder.select(better, t, best_t), ptr(9, vd), align=8)
    builder.store(builder.select(better, index, best), ptr(10, vl), align=8)
    # far = `_float32_up`(t · _CULL_SCALE) where the lane took the hit
    fabs = cgutils.get_or_insert_function(
        builder.module, ir.FunctionType(vd, [vd]), f"llvm.fabs.v{LANES}f64"
    )
    x = builder.fmul(t, ir.Constant(vd, [_CULL_SCALE] * LANES))
    slack = builder.fmul(ir.Constant(vd, [_ROUND_SLACK] * LANES), builder.call(fabs, [x]))
    up = builder.fadd(builder.fadd(x, slack), ir.Constant(vd, [1e-37] * LANES))
    builder.store(builder.select(better, builder.fptrunc(up, vf), far), ptr(11, vf), align=4)
    return context.get_dummy_value()


@intrinsic
def _leaf_lanes(typingctx, verts, i, mask, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t, best, far):
    """Triangle row i (BVH order) of verts against the lanes of mask: where a lane hits it
    nearer than (best_t, best) (equal t: the lower triangle), best_t, best and far (the
    lane's box-test limit) take the hit. Per lane exactly `hit_triangle`'s float64 steps."""
    sig = types.void(verts, i, mask, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t, best, far)
    return sig, _leaf_lanes_codegen


@nb.njit(cache=True)
def new_packet(depth):
    """A thread's packet: (ox, oy, oz, dx, dy, dz) LANES float64 each, filled by the caller,
    then the traversal's own arrays, a stack for `depth` levels, and for the caller's use
    (limits, hit distances, hit triangles, indices) LANES each."""
    f64 = (
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
        np.empty(LANES),
    )
    i64 = (np.empty(LANES, np.int64), np.empty(LANES, np.int64), np.empty(LANES, np.int64),
           np.empty(LANES, np.int64), np.empty(2 * WIDTH, np.int64))  # fmt: skip
    # rows of (node reference, lanes, least entry bits): a node pushes at most WIDTH
    stack = np.empty(((WIDTH - 1) * depth + 2, 3), np.int64)
    rc, far = np.empty(12 * LANES, np.float32), np.empty(LANES, np.float32)
    io = (np.full(LANES, np.inf), np.empty(LANES), np.empty(LANES, np.int64),
          np.empty(LANES, np.int64))  # fmt: skip
    return f64, i64, rc, far, stack, io


# `new_packet`'s types, for passing packets by address (`dpm.tracer.addresses`)
packet_words, packet_at = by_address(
    (
        tuple(np.zeros(0) for _ in range(10)),
        tuple(np.zeros(0, np.int64) for _ in range(5)),
        np.zeros(0, np.float32),
        np.zeros(0, np.float32),
        np.zeros((0, 0), np.int64),
        (np.zeros(0), np.zeros(0), np.zeros(0, np.int64), np.zeros(0, np.int64)),
    )
)


@nb.njit(cache=True, inline="always")
def put_ray(rays, limits, j, ox, oy, oz, dx, dy, dz, tmax):
    """Lane j of a packet's rays (`new_packet`'s first tuple, rays[0:6]) and of limits."""
    rays[0][j], rays[1][j], rays[2][j] = ox, oy, oz
    rays[3][j], rays[4][j], rays[5][j] = dx, dy, dz
    limits[j] = tmax


@nb.njit(cache=True, inline="always", error_model="numpy")
def _axis_rows(rc, r, o, d):
    """Rows r … r + 3·LANES of rc: one axis's `box_constants` for each lane."""
    for j in range(LANES):
        a, b, c, e = _axis_constants(o[j], 1.0 / d[j])
        rc[r + j], rc[r + LANES + j], rc[r + 2 * LANES + j], rc[r + 3 * LANES + j] = a, b, c, e


@nb.njit(cache=True, inline="always", error_model="numpy")
def _setup(packet, active, tmax):
    """Each lane's constants and its limit (tmax (LANES,) float64); lanes not in active
    enter no box. Loops of few arrays each: LLVM vectorizes those, not one loop of all."""
    (ox, oy, oz, dx, dy, dz, sx, sy, sz, best_t), (kx, ky, kz, best, _), rc, far, _, _ = packet
    for j in range(LANES):
        x, y, z = dx[j], dy[j], dz[j]
        k = _dominant_axis(x, y, z)
        kx[j], ky[j], kz[j], sx[j], sy[j], sz[j] = ray_setup_inverse(
            x, y, z, k, 1.0 / pick(k, x, y, z)
        )
    _axis_rows(rc, 0, ox, dx)
    _axis_rows(rc, 4 * LANES, oy, dy)
    _axis_rows(rc, 8 * LANES, oz, dz)
    for j in range(LANES):
        on = ((active >> j) & 1) == 1
        best_t[j] = tmax[j]
        best[j] = -1
        far[j] = _float32_up(tmax[j] * _CULL_SCALE) if on else np.float32(-1.0)


@nb.njit(cache=True, inline="always", error_model="numpy")
def _lane_ray(ox, oy, oz, kx, ky, kz, sx, sy, sz, rc, j):
    """Lane j's ray as `closest_below` takes it (box constants, planes, k, o, s). Given the
    packet's arrays, not the packet: inlined with the packet's tuple, the single-ray
    traversal that follows ran 30 % slower."""
    ray = (rc[j], rc[LANES + j], rc[2 * LANES + j], rc[3 * LANES + j], rc[4 * LANES + j],
           rc[5 * LANES + j], rc[6 * LANES + j], rc[7 * LANES + j], rc[8 * LANES + j],
           rc[9 * LANES + j], rc[10 * LANES + j], rc[11 * LANES + j])  # fmt: skip
    # the near planes as `hit_box` takes them: max where the near scale is negative
    nx = 3 * WIDTH if ray[0] < 0 else 0
    ny = 4 * WIDTH if ray[4] < 0 else WIDTH
    nz = 5 * WIDTH if ray[8] < 0 else 2 * WIDTH
    planes_at = (nx, ny, nz, 3 * WIDTH - nx, 5 * WIDTH - ny, 7 * WIDTH - nz)
    x, y, z = kx[j], ky[j], kz[j]
    o = (pick(x, ox[j], oy[j], oz[j]), pick(y, ox[j], oy[j], oz[j]), pick(z, ox[j], oy[j], oz[j]))
    return ray, planes_at, (x, y, z), o, (sx[j], sy[j], sz[j])


@nb.njit(cache=True, inline="always")
def _count(mask):
    """Number of set bits of a LANES-bit mask."""
    n = 0
    while mask != 0:
        mask &= mask - 1
        n += 1
    return n


@nb.njit(cache=True, inline="always", error_model="numpy")
def _leaf(verts, ref, mask, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t, best, far):
    """Every triangle of leaf reference ref against the lanes of mask (`_leaf_lanes`)."""
    code = ~ref
    first = code >> LEAF_BITS
    for c in range(code & _COUNT):
        _leaf_lanes(verts, first + c, mask, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t, best, far)


@nb.njit(cache=True, inline="always", _nrt=False, error_model="numpy")
def closest_packet(bvh, packet, active, tmax, single, out_t, out_tri):
    """Closest hits in (0, tmax[j]) of the rays in `packet`'s lanes j of bitmask active:
    out_t[j] (float64, inf on a miss) and out_tri[j] (scene triangle, -1), as `closest_hit`
    gives them. `single` is a `new_stack` for the lanes that go on alone."""
    bounds, kids, verts = bvh.bounds, bvh.kids, bvh.tri_verts
    (ox, oy, oz, _, _, _, sx, sy, sz, best_t), (kx, ky, kz, best, out), rc, far, stack, _ = packet
    _setup(packet, active, tmax)
    stack[0, 0], stack[0, 1], stack[0, 2] = 0, active, 0
    sp = 1
    while sp > 0:
        sp -= 1
        ref, mask, least = stack[sp, 0], stack[sp, 1], stack[sp, 2]
        m = mask  # lanes whose nearest hit so far lies before the subtree's least entry
        while m != 0:
            j = _lowest_bit(m)
            m &= m - 1
            if _bits32(far[j]) < least:
                mask &= ~(1 << j)
        if mask == 0:
            continue
        if _count(mask) <= SWITCH:
            while mask != 0:
                j = _lowest_bit(mask)
                mask &= mask - 1
                ray, planes_at, k, o, s = _lane_ray(ox, oy, oz, kx, ky, kz, sx, sy, sz, rc, j)
                t, b = closest_below(bvh, ref, ray, planes_at, k, o, s, best_t[j], best[j], single)
                if b != best[j]:
                    best_t[j], best[j] = t, b
                    far[j] = _float32_up(t * _CULL_SCALE)
            continue
        if ref >= 0:
            base = sp
            entered = _packet_node(bounds, ref, rc, far, mask, out)
            while entered != 0:
                c = _lowest_bit(entered)
                entered &= entered - 1
                lanes, d = out[c], out[WIDTH + c]
                j = sp  # sorted so that the nearest is on top
                while j > base and stack[j - 1, 2] < d:
                    stack[j, 0], stack[j, 1], stack[j, 2] = (
                        stack[j - 1, 0], stack[j - 1, 1], stack[j - 1, 2]
                    )  # fmt: skip
                    j -= 1
                stack[j, 0], stack[j, 1], stack[j, 2] = kids[ref, REFS + c], lanes, d
                sp += 1
        else:
            _leaf(verts, ref, mask, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t, best, far)
    for j in range(LANES):
        hit = best[j] >= 0
        out_t[j] = best_t[j] if hit else np.inf
        out_tri[j] = bvh.tri_index[best[j]] if hit else -1


@nb.njit(cache=True, inline="always", _nrt=False, error_model="numpy")
def any_packet(bvh, packet, active, tmax, single):
    """Bitmask of the lanes of active whose ray hits a triangle in (0, tmax[j]), as
    `any_hit` finds them. `single` is a `new_stack` for the lanes that go on alone."""
    bounds, kids, verts = bvh.bounds, bvh.kids, bvh.tri_verts
    (ox, oy, oz, _, _, _, sx, sy, sz, best_t), (kx, ky, kz, best, out), rc, far, stack, _ = packet
    _setup(packet, active, tmax)
    blocked = 0
    stack[0, 0], stack[0, 1] = 0, active
    sp = 1
    while sp > 0:
        sp -= 1
        ref, mask = stack[sp, 0], stack[sp, 1] & ~blocked
        if mask == 0:
            continue
        if _count(mask) <= SWITCH:
            while mask != 0:
                j = _lowest_bit(mask)
                mask &= mask - 1
                ray, planes_at, k, o, s = _lane_ray(ox, oy, oz, kx, ky, kz, sx, sy, sz, rc, j)
                if any_below(bvh, ref, ray, planes_at, k, o, s, tmax[j], single):
                    blocked |= 1 << j
                    far[j] = np.float32(-1.0)
            continue
        if ref >= 0:
            entered = _packet_node(bounds, ref, rc, far, mask, out)
            while entered != 0:
                c = _lowest_bit(entered)
                entered &= entered - 1
                stack[sp, 0], stack[sp, 1] = kids[ref, REFS + c], out[c]
                sp += 1
        else:
            # a hit strictly before tmax sets best (the tie rule's best is -1: t < tmax)
            _leaf(verts, ref, mask, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t, best, far)
            for j in range(LANES):
                if best[j] >= 0 and (mask >> j) & 1:
                    blocked |= 1 << j
                    far[j] = np.float32(-1.0)
            if blocked & active == active:
                break
    return blocked & active


@nb.njit(cache=True, inline="always")
def _load(packet, origins, directions, tmax, first, n, limit):
    """Rays first … first + LANES - 1 of (R, 3) arrays into packet's lanes, tmax (R,) or
    (1,) into limit; returns the bitmask of lanes holding a traceable ray, and the
    `_ray_flags` of those that are not."""
    active, flags = 0, 0
    for j in range(LANES):
        r = first + j
        put_ray(packet[0], limit, j, 0.0, 0.0, 0.0, 1.0, 1.0, 1.0, 0.0)
        if r < n:
            x, y, z, a, b, c = _ray(origins, directions, r)
            bad = _ray_flags(x, y, z, a, b, c)
            flags |= bad
            if not bad:
                put_ray(packet[0], limit, j, x, y, z, a, b, c, tmax[r if tmax.shape[0] > 1 else 0])
                active |= 1 << j
    return active, flags


@nb.njit(cache=True, parallel=True, error_model="numpy")
def closest_hit_packets(bvh, depth, origins, directions, tmax, out_t, out_tri):
    """`closest_hit_batch` with consecutive rays traced in packets of LANES: the same hits."""
    n = origins.shape[0]
    n_tasks = (n + TASK_RAYS - 1) // TASK_RAYS
    flags = np.zeros(n_tasks, np.int64)
    for task in nb.prange(n_tasks):
        flags[task] = _closest_task(bvh, depth, origins, directions, tmax, out_t, out_tri, task)
    return _or_all(flags)


@nb.njit(cache=True, error_model="numpy")
def _closest_task(bvh, depth, origins, directions, tmax, out_t, out_tri, task):
    """One task of `closest_hit_packets` (its own function: Numba's parallel analysis fails
    on the inlined traversal)."""
    n = origins.shape[0]
    packet, single = new_packet(depth), new_stack(depth)
    limit, t, tri, _ = packet[5]
    flags = 0
    for first in range(task * TASK_RAYS, min(n, (task + 1) * TASK_RAYS), LANES):
        active, bad = _load(packet, origins, directions, tmax, first, n, limit)
        flags |= bad
        closest_packet(bvh, packet, active, limit, single, t, tri)
        for j in range(min(LANES, n - first)):
            on = (active >> j) & 1
            out_t[first + j] = t[j] if on else np.inf
            out_tri[first + j] = tri[j] if on else -1
    return flags


@nb.njit(cache=True, parallel=True, error_model="numpy")
def any_hit_packets(bvh, depth, origins, directions, tmax, out):
    """`any_hit_batch` with consecutive rays traced in packets of LANES: the same answers."""
    n = origins.shape[0]
    n_tasks = (n + TASK_RAYS - 1) // TASK_RAYS
    flags = np.zeros(n_tasks, np.int64)
    for task in nb.prange(n_tasks):
        flags[task] = _any_task(bvh, depth, origins, directions, tmax, out, task)
    return _or_all(flags)


@nb.njit(cache=True, error_model="numpy")
def _any_task(bvh, depth, origins, directions, tmax, out, task):
    """One task of `any_hit_packets`."""
    n = origins.shape[0]
    packet, single = new_packet(depth), new_stack(depth)
    limit = packet[5][0]
    flags = 0
    for first in range(task * TASK_RAYS, min(n, (task + 1) * TASK_RAYS), LANES):
        active, bad = _load(packet, origins, directions, tmax, first, n, limit)
        flags |= bad
        blocked = any_packet(bvh, packet, active, limit, single)
        for j in range(min(LANES, n - first)):
            out[first + j] = (blocked >> j) & 1 == 1
    return flags
