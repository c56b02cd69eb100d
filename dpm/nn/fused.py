"""DPM's whole estimate as one fused CPU kernel that `jax.jit` calls (an XLA FFI custom call).

XLA runs each 32×32 layer of KernelNet as its own dot over an L2-sized step of photon rows
(about 0.45 of the machine's matmul peak on these shapes) and fuses the gather of the photons'
rows into each of its consumers. This kernel (Numba) does what `infer.query_radiance` does for
a step of points in one call: it reads each photon's row once, checks its normal, forms the
features in the point's canonical frame, runs the network and forms Eq. 2. The network carries a
tile of TILE photons' activations (photon-major rows of WIDTH floats) through the layers in L1,
each layer a register-blocked micro-kernel (`_block_codegen`: PHOTONS photons × WIDTH outputs
held in vector accumulators, unrolled over the inputs; the last hidden layer ends in the output
dot), pools each point's photons in one pass (`_pool`) and forms the points' context
(Dense_0's pooled half) in the same blocks; the features' frame (`_frame`) and Eq. 2's
softplus (`softplus`, no libm calls) run in vectors too. It serves the shipped architecture
(9 input channels, width 32; `supports`). One call is single-threaded and a point's result
depends on its own photons alone, so the output does not depend on how calls are spread over
threads. Its sums run in another order than XLA's: equal within float rounding (tested).

The handler speaks the typed XLA FFI C API (`xla/ffi/api/c_api.h`, which XLA keeps binary
stable) directly: it answers XLA's metadata query with the API version and, when executed,
reads the buffers from the call frame.
"""

from __future__ import annotations

import ctypes
import threading

import jax
import jax.numpy as jnp
import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.core.registry import cpu_target
from numba.extending import intrinsic

from dpm.nn.features import MIN_RADIUS
from dpm.nn.model import SHIFT
from dpm.tracer.photon_grid import NORMAL_COS
from dpm.tracer.sampling import orthonormal_basis

CHANNELS = 9  # input features per photon
WIDTH = 32  # channels of every hidden layer


def target_vector_floats() -> int:
    """float32 lanes of the widest vector register Numba compiles for here: 16 with AVX-512F,
    else 8 (AVX2). It follows `NUMBA_CPU_FEATURES` where set, else the host's features."""
    features = cpu_target.target_context.codegen()._get_host_cpu_features()
    return 16 if "+avx512f" in features.split(",") else 8


# The micro-kernel's accumulators must fit the register file with room for the weights and
# the broadcast input: 4 photons × 2 zmm of AVX-512's 32 registers, 2 photons × 4 ymm of
# AVX2's 16 (16-float vectors there split in two and spilled: 0.37-0.47 of peak on Zen 3).
LANES = target_vector_floats()  # floats per vector register
VECTORS = WIDTH // LANES  # vectors per activation row
PHOTONS = 4 if LANES == 16 else 2  # photons a micro-kernel block carries: PHOTONS × VECTORS
TILE = 128  # photons carried through the layers together (activations 16 KiB, in L1)
TARGET = "dpm_kernelnet_radiance"
ROW = 16  # floats of a photon row (`infer.PhotonTable`)

# Packed parameters: (name in the Flax tree, shape) in order; see `pack_params`.
LAYOUT = (
    (("Extractor_0", "Dense_0", "kernel"), (CHANNELS, WIDTH)),
    (("Extractor_0", "Dense_0", "bias"), (WIDTH,)),
    (("Extractor_0", "Dense_1", "kernel"), (WIDTH, WIDTH)),
    (("Extractor_0", "Dense_1", "bias"), (WIDTH,)),
    (("Extractor_0", "Dense_2", "kernel"), (WIDTH, WIDTH)),
    (("Extractor_0", "Dense_2", "bias"), (WIDTH,)),
    (("Dense_0", "kernel"), (3 * WIDTH, WIDTH)),  # [photon feature, max, mean] inputs
    (("Dense_0", "bias"), (WIDTH,)),
    (("Dense_1", "kernel"), (WIDTH, WIDTH)),
    (("Dense_1", "bias"), (WIDTH,)),
    (("Dense_2", "kernel"), (WIDTH, 1)),
    (("Dense_2", "bias"), (1,)),
)
_STARTS = tuple(int(s) for s in np.cumsum([0] + [np.prod(shape) for _, shape in LAYOUT]))
# The constants the estimate shares with the XLA path ride at the end of the packed params, so
# the kernel reads their current values (Numba's cache would keep the values it compiled).
_SHIFT, _NORMAL_COS, _MIN_RADIUS = range(_STARTS[-1], _STARTS[-1] + 3)
PACKED = _STARTS[-1] + 3  # floats of the packed parameters and constants


def _leaf(p: dict, path: tuple[str, ...]):
    """The array at `path` of a params tree."""
    for name in path:
        p = p[name]
    return p


def supports(p: dict) -> bool:
    """Whether KernelNet params p (the "params" tree) have the shapes this kernel runs."""
    try:
        return all(tuple(_leaf(p, path).shape) == shape for path, shape in LAYOUT)
    except (KeyError, TypeError):
        return False


def pack_params(p: dict) -> jnp.ndarray:
    """(PACKED,) float32: KernelNet params p (the "params" tree) flattened in LAYOUT's order,
    then SHIFT, NORMAL_COS and MIN_RADIUS."""
    parts = [jnp.ravel(jnp.asarray(_leaf(p, path), jnp.float32)) for path, _ in LAYOUT]
    parts.append(jnp.array([SHIFT, NORMAL_COS, MIN_RADIUS], jnp.float32))
    return jnp.concatenate(parts)


def _splat(builder, value):
    """IR: a LANES-float vector with every lane `value`."""
    i32 = ir.IntType(32)
    v = builder.insert_element(
        ir.Constant(ir.VectorType(value.type, LANES), ir.Undefined), value, ir.Constant(i32, 0)
    )
    return builder.shuffle_vector(v, v, ir.Constant(ir.VectorType(i32, LANES), [0] * LANES))


def _vector_at(builder, data, at):
    """IR: a pointer to the LANES floats at element `at` of float pointer `data`."""
    vf = ir.VectorType(ir.FloatType(), LANES)
    return builder.bitcast(builder.gep(data, [at]), vf.as_pointer())


def _block_codegen(n_in: int, head: bool, relu: bool = True):
    """LLVM IR of one micro-kernel block: for photons p < PHOTONS, output row
    y[y0 + p, :] = ReLU(init[owner[o0 + p], :] + Σ_i x[x0 + p·xp + i·xi] · w[i, :]), float32,
    with fused multiply-adds (without `relu`, no ReLU). Photon-major rows of WIDTH floats; x
    has any strides. With `head`, y is 1-D and gets y[y0 + p] = row · head (the last
    argument, WIDTH floats) instead, summed as a fixed pairwise tree."""

    def codegen(context, builder, sig, args):
        f32, i32, i64 = ir.FloatType(), ir.IntType(32), ir.IntType(64)
        vf = ir.VectorType(f32, LANES)
        w, init, owner, x, y = (
            context.make_array(sig.args[i])(context, builder, args[i]) for i in range(5)
        )
        o0, x0, xp, xi, y0 = (
            context.cast(builder, args[i], sig.args[i], types.int64) for i in range(5, 10)
        )

        def const(v):
            return ir.Constant(i64, v)

        def vector(data, at):
            return _vector_at(builder, data, at)

        acc = []
        for p in range(PHOTONS):
            row = builder.load(builder.gep(owner.data, [builder.add(o0, const(p))]))
            at = builder.mul(row, const(WIDTH))
            acc.append(
                [
                    builder.load(vector(init.data, builder.add(at, const(v * LANES))), align=4)
                    for v in range(VECTORS)
                ]
            )
        photon = [builder.add(x0, builder.mul(xp, const(p))) for p in range(PHOTONS)]
        for i in range(n_in):
            ws = [
                builder.load(vector(w.data, const(i * WIDTH + v * LANES)), align=4)
                for v in range(VECTORS)
            ]
            feature = builder.mul(xi, const(i))
            for p in range(PHOTONS):
                xs = _splat(
                    builder, builder.load(builder.gep(x.data, [builder.add(photon[p], feature)]))
                )
                for v in range(VECTORS):
                    product = builder.fmul(xs, ws[v], flags=["contract"])
                    acc[p][v] = builder.fadd(product, acc[p][v], flags=["contract"])
        zero = ir.Constant(vf, [0.0] * LANES)
        if relu:
            acc = [[builder.select(builder.fcmp_ordered(">", a, zero), a, zero) for a in row]
                   for row in acc]  # fmt: skip
        if head:
            last = context.make_array(sig.args[10])(context, builder, args[10])
            hs = [
                builder.load(vector(last.data, const(v * LANES)), align=4) for v in range(VECTORS)
            ]
            for p in range(PHOTONS):
                t = builder.fmul(acc[p][0], hs[0])
                for v in range(1, VECTORS):
                    t = builder.fadd(t, builder.fmul(acc[p][v], hs[v]))
                n = LANES
                while n > 1:  # pairwise: lanes [0, n/2) plus [n/2, n)
                    n //= 2
                    lo = builder.shuffle_vector(
                        t, t, ir.Constant(ir.VectorType(i32, n), list(range(n)))
                    )
                    hi = builder.shuffle_vector(
                        t, t, ir.Constant(ir.VectorType(i32, n), list(range(n, 2 * n)))
                    )
                    t = builder.fadd(lo, hi)
                total = builder.extract_element(t, ir.Constant(i32, 0))
                builder.store(total, builder.gep(y.data, [builder.add(y0, const(p))]))
            return context.get_dummy_value()
        for p in range(PHOTONS):
            at = builder.mul(builder.add(y0, const(p)), const(WIDTH))
            for v in range(VECTORS):
                builder.store(acc[p][v], vector(y.data, builder.add(at, const(v * LANES))), align=4)
        return context.get_dummy_value()

    return codegen


def _make_block(n_in: int, head: bool = False, relu: bool = True):
    """The micro-kernel intrinsic for n_in inputs, ReLU (unless not `relu`), and with `head`
    the output dot."""
    if head:

        def block(typingctx, w, init, owner, x, y, o0, x0, xp, xi, y0, last):
            sig = types.void(w, init, owner, x, y, o0, x0, xp, xi, y0, last)
            return sig, _block_codegen(n_in, True)
    else:

        def block(typingctx, w, init, owner, x, y, o0, x0, xp, xi, y0):
            sig = types.void(w, init, owner, x, y, o0, x0, xp, xi, y0)
            return sig, _block_codegen(n_in, False, relu)

    block.__name__ = f"_block_{n_in}{'_head' if head else ''}{'' if relu else '_linear'}"
    return intrinsic(block)


_first_block = _make_block(CHANNELS)
_hidden_block = _make_block(WIDTH)
_head_block = _make_block(WIDTH, head=True)
_context_block = _make_block(2 * WIDTH, relu=False)  # Dense_0's pooled half, once per point


def _pool_codegen(context, builder, sig, args):
    """LLVM IR of `_pool`: one pass over a point's k photon rows, max and sum in registers."""
    f32, i64 = ir.FloatType(), ir.IntType(64)
    vf = ir.VectorType(f32, LANES)
    features, valid, pooled = (context.make_array(sig.args[i])(context, builder, args[i])
                               for i in (0, 1, 3))  # fmt: skip
    point = context.cast(builder, args[2], sig.args[2], types.int64)
    k = builder.extract_value(valid.shape, 1)
    first = builder.mul(point, k)
    zero = ir.Constant(vf, [0.0] * LANES)
    biggest = [cgutils.alloca_once_value(builder, zero) for _ in range(VECTORS)]
    sums = [cgutils.alloca_once_value(builder, zero) for _ in range(VECTORS)]
    count = cgutils.alloca_once_value(builder, ir.Constant(f32, 0.0))

    def vector(data, at):
        return _vector_at(builder, data, at)

    with cgutils.for_range(builder, k, intp=i64) as loop:
        photon = builder.add(first, loop.index)
        m = builder.load(builder.gep(valid.data, [photon]))
        builder.store(builder.fadd(builder.load(count), m), count)
        ms = _splat(builder, m)
        row = builder.mul(photon, ir.Constant(i64, WIDTH))
        for v in range(VECTORS):
            at = builder.add(row, ir.Constant(i64, v * LANES))
            x = builder.fmul(builder.load(vector(features.data, at), align=4), ms)
            big = builder.load(biggest[v])
            builder.store(builder.select(builder.fcmp_ordered(">", x, big), x, big), biggest[v])
            builder.store(builder.fadd(builder.load(sums[v]), x), sums[v])
    n = builder.load(count)
    n = builder.select(
        builder.fcmp_ordered(">", n, ir.Constant(f32, 1.0)), n, ir.Constant(f32, 1.0)
    )
    ns = _splat(builder, n)
    for v in range(VECTORS):
        builder.store(
            builder.load(biggest[v]), vector(pooled.data, ir.Constant(i64, v * LANES)), align=4
        )
        mean = builder.fdiv(builder.load(sums[v]), ns)
        builder.store(mean, vector(pooled.data, ir.Constant(i64, WIDTH + v * LANES)), align=4)
    return context.get_dummy_value()


@intrinsic
def _pool(typingctx, features, valid, point, pooled):
    """pooled (2·WIDTH,) = [max, mean] over the valid photons of point (rows point·k ... of
    photon-major features (N, WIDTH); valid (n, k) as 1.0/0.0), the max 0 when none is valid
    (ReLU features are ≥ 0, so masking with 0 keeps the max)."""
    return types.void(features, valid, point, pooled), _pool_codegen


def _frame_codegen(context, builder, sig, args):
    """LLVM IR of `_frame`: LANES columns a step, the rows as vectors."""
    i64 = ir.IntType(64)
    x, coef = (context.make_array(sig.args[i])(context, builder, args[i]) for i in (0, 3))
    first, steps = (context.cast(builder, args[i], sig.args[i], types.int64) for i in (1, 2))
    stride = builder.extract_value(x.shape, 1)  # floats between rows
    c = [_splat(builder, builder.load(builder.gep(coef.data, [ir.Constant(i64, i)])))
         for i in range(10)]  # fmt: skip
    with cgutils.for_range(builder, steps, intp=i64) as loop:
        col = builder.add(first, builder.mul(loop.index, ir.Constant(i64, LANES)))
        at = [builder.add(builder.mul(stride, ir.Constant(i64, r)), col) for r in range(6)]
        v = [builder.load(_vector_at(builder, x.data, a), align=4) for a in at]

        def dot(w, a, b, d):  # w·(a, b, d) in the order of the scalar loop: (w0a + w1b) + w2d
            return builder.fadd(builder.fadd(builder.fmul(c[w], a), builder.fmul(c[w + 1], b)),
                                builder.fmul(c[w + 2], d))  # fmt: skip

        out = [builder.fmul(dot(w, *v[:3]), c[9]) for w in (0, 3, 6)]
        out += [dot(w, *v[3:]) for w in (0, 3, 6)]
        for a, value in zip(at, out, strict=True):
            builder.store(value, _vector_at(builder, x.data, a), align=4)
    return context.get_dummy_value()


@intrinsic
def _frame(typingctx, x, first, steps, coef):
    """Rows 0-5 of x (CHANNELS, N) at columns first ... first + steps·LANES - 1 (offsets o,
    directions d) into a point's frame: rows 0-2 (f0·o, f1·o, n·o)·inv_r, rows 3-5 (f0·d,
    f1·d, n·d), from coef = (f0, f1, n, inv_r) (10 float32): the scalar loop's operations
    on LANES columns at once (LLVM's vectorizer left that loop scalar: six rows of one array
    read and written, more than its alias checks allow)."""
    return types.void(x, first, steps, coef), _frame_codegen


@nb.njit(cache=True, inline="always")
def _layer_first(w, b, x, y, x0, xi, zero_rows):
    """y[:TILE] = relu(w · x + b) on TILE photons of feature-major x (photon x0 + p at
    x0 + p, feature i at i·xi), photon-major out."""
    for p in range(0, TILE, PHOTONS):
        _first_block(w, b, zero_rows, x, y, 0, x0 + p, 1, xi, p)


@nb.njit(cache=True, inline="always")
def _layer(w, init, owner, o0, x, row0, y, y0):
    """y[y0 : y0 + TILE] = relu(x[row0 : row0 + TILE] · w + init[owner[o0 + p]]), photon-major."""
    for p in range(0, TILE, PHOTONS):
        _hidden_block(w, init, owner, x, y, o0 + p, (row0 + p) * WIDTH, WIDTH, 1, y0 + p)


@nb.njit(cache=True, inline="always")
def _part(packed, i):
    """Entry i of LAYOUT in the packed params, flat."""
    return packed[_STARTS[i] : _STARTS[i + 1]]


@nb.njit(cache=True, error_model="numpy")
def logits_kernel(x, valid, packed, out):
    """KernelNet's logits out (N,) from features x (CHANNELS, N) of n points' k photons each
    (N = n·k, point-major), valid (n, k) as 1.0/0.0 and the packed params (PACKED,)."""
    n, k = valid.shape
    total = n * k
    e0w, e0b = _part(packed, 0).reshape(CHANNELS, WIDTH), _part(packed, 1)
    e1w, e1b = _part(packed, 2).reshape(WIDTH, WIDTH), _part(packed, 3)
    e2w, e2b = _part(packed, 4).reshape(WIDTH, WIDTH), _part(packed, 5)
    d0w, d0b = _part(packed, 6).reshape(3 * WIDTH, WIDTH), _part(packed, 7)
    d1w, d1b = _part(packed, 8).reshape(WIDTH, WIDTH), _part(packed, 9)
    d2w, d2b = _part(packed, 10), _part(packed, 11)[0]
    own = d0w[:WIDTH]
    tiles = -(-total // TILE)
    padded = tiles * TILE
    zero_rows = np.zeros(TILE, np.int64)  # every photon's init row is row 0: the bias
    owner = np.empty(padded, np.int64)  # each photon's point (the last for the padding)
    for point in range(n):  # (no division per photon: 4 % of the kernel at K = 50)
        owner[point * k : (point + 1) * k] = point
    owner[total:] = n - 1
    features = np.empty((padded, WIDTH), np.float32)  # the extractor's output, photon-major
    tile_in = np.zeros((CHANNELS, TILE), np.float32)
    a = np.empty((TILE, WIDTH), np.float32)
    c = np.empty((TILE, WIDTH), np.float32)
    e0b, e1b, e2b = e0b.reshape(1, WIDTH), e1b.reshape(1, WIDTH), e2b.reshape(1, WIDTH)
    d1b = d1b.reshape(1, WIDTH)
    # 1: the extractor, tile by tile (the last, partial tile through a zero-padded copy)
    for t in range(tiles):
        start = t * TILE
        if start + TILE <= total:
            _layer_first(e0w, e0b, x, a, start, total, zero_rows)
        else:
            for ch in range(CHANNELS):
                for j in range(TILE):
                    tile_in[ch, j] = x[ch, start + j] if start + j < total else 0.0
            _layer_first(e0w, e0b, tile_in, a, 0, TILE, zero_rows)
        _layer(e1w, e1b, zero_rows, 0, a, 0, c, 0)
        _layer(e2w, e2b, zero_rows, 0, c, 0, features, start)
    # 2: each point's context, Dense_0's pooled half: max and mean over its valid photons
    # (`_pool`), then its pooled half of Dense_0 (no ReLU), once per point, PHOTONS points a
    # block (a loop per point took a fifth of the kernel's time at K = 50)
    blocks = -(-n // PHOTONS) * PHOTONS
    pooled = np.zeros((blocks, 2 * WIDTH), np.float32)
    context = np.empty((blocks, WIDTH), np.float32)
    for point in range(n):
        _pool(features, valid, point, pooled[point])
    bias = d0b.reshape(1, WIDTH)
    for p in range(0, blocks, PHOTONS):
        _context_block(d0w[WIDTH:], bias, zero_rows, pooled, context, 0, p * 2 * WIDTH,
                       2 * WIDTH, 1, p)  # fmt: skip
    # 3: the predictor, tile by tile: relu(own · feature + context) → ReLU layer → logit
    logit = np.empty(TILE, np.float32)
    for t in range(tiles):
        start = t * TILE
        _layer(own, context, owner, start, features, start, a, 0)
        for p in range(0, TILE, PHOTONS):
            _head_block(d1w, d1b, zero_rows, a, logit, 0, p * WIDTH, WIDTH, 1, p, d2w)
        for j in range(min(TILE, total - start)):
            out[start + j] = logit[j] + d2b


_LN2 = 0.6931471805599453
_EXP_TERMS = (1.0, 1.0, 1 / 2, 1 / 6, 1 / 24, 1 / 120, 1 / 720, 1 / 5040)  # e^x to x^7


@nb.njit(cache=True, inline="always", error_model="numpy")
def softplus(u):
    """log(1 + e^u) (float32) within 1e-7 of itself, relative, from float64 arithmetic
    alone: no libm calls, so a loop of it vectorizes (two scalar calls a photon cost as
    much as a fifth of its network). e^-|u| = 2^m · e^x (m = round(-|u|/ln 2), |x| ≤ ln 2 / 2,
    Taylor to x^7) and log(1 + t) = 2 atanh(t / (2 + t)) (its series to the 13th power:
    t / (2 + t) ≤ 1/3)."""
    a = -min(abs(np.float64(u)), 700.0)
    m = np.floor(a / _LN2 + 0.5)  # -1010 ≤ m ≤ 0
    x = a - m * _LN2
    e = _EXP_TERMS[7]
    for c in _EXP_TERMS[6::-1]:
        e = e * x + c
    b, p = -np.int64(m), 1.0  # 2^m = ∏ over the bits of -m: exact products of powers of 2
    half = 0.5
    for _ in range(10):
        p = p * (half if b & 1 else 1.0)
        b, half = b >> 1, half * half
    t = e * p
    s = t / (2.0 + t)
    s2 = s * s
    series = 1 / 13
    for c in (1 / 11, 1 / 9, 1 / 7, 1 / 5, 1 / 3, 1.0):
        series = series * s2 + c
    return np.float32(max(np.float64(u), 0.0) + 2.0 * s * series)


@nb.njit(cache=True, error_model="numpy")
def radiance_kernel(rows, index, hi, lo, normal, albedo, radius, angle, packed, out):
    """(n, 3) radiance out of n points from their K nearest photons, as `infer.query_radiance`
    computes it: the photons' rows (P + 1, 16) of an `infer.PhotonTable` read by index (n, K)
    (P: missing), the points' float32 position split hi + lo (n, 3), unit normals, albedos
    (n, 3), bandwidths and frame angles (n,; NaN: canonical), and `pack_params`' array."""
    n, k = index.shape
    last = rows.shape[0] - 1  # the zero row of a missing neighbour
    shift, agree_cos = packed[_SHIFT], packed[_NORMAL_COS]
    min_radius = packed[_MIN_RADIUS]
    out[:] = 0.0
    x = np.empty((CHANNELS, n * k), np.float32)
    valid = np.empty((n, k), np.float32)
    coef = np.empty(10, np.float32)  # a point's frame for `_frame`
    for point in range(n):
        first = point * k
        nx, ny, nz = normal[point, 0], normal[point, 1], normal[point, 2]
        cx, cy, cz = np.float32(0.0), np.float32(0.0), np.float32(0.0)
        for j in range(k):
            i = min(index[point, j], last)
            ox = (rows[i, 0] - hi[point, 0]) - lo[point, 0]
            oy = (rows[i, 1] - hi[point, 1]) - lo[point, 1]
            oz = (rows[i, 2] - hi[point, 2]) - lo[point, 2]
            if i >= last:
                ox, oy, oz = np.float32(0.0), np.float32(0.0), np.float32(0.0)
            agree = rows[i, 9] * nx + rows[i, 10] * ny + rows[i, 11] * nz >= agree_cos
            valid[point, j] = 1.0 if agree else 0.0
            if agree:
                cx, cy, cz = cx + ox, cy + oy, cz + oz
            col = first + j  # the row's other inputs too: the frame's pass reads no rows
            x[0, col], x[1, col], x[2, col] = ox, oy, oz
            x[3, col], x[4, col], x[5, col] = rows[i, 3], rows[i, 4], rows[i, 5]
            x[6, col], x[7, col], x[8, col] = rows[i, 12], rows[i, 13], rows[i, 14]
        tx, ty, tz, sx, sy, sz = orthonormal_basis(nx, ny, nz)  # `local_frame` at angle 0
        t, s = (tx, ty, tz), (sx, sy, sz)
        turn = angle[point]
        if np.isnan(turn):  # the canonical angle: the first tangent towards the mean offset,
            # (cos, sin) of atan2(v, u) as (u, v) / |(u, v)| (atan2(±0, ±0) is 0 or ±π, so
            # cos ±1: the points without a valid photon, whose estimate is zero anyway)
            u = cx * t[0] + cy * t[1] + cz * t[2]
            v = cx * s[0] + cy * s[1] + cz * s[2]
            h = np.sqrt(u * u + v * v)
            c, si = (u / h, v / h) if h > 0 else (np.copysign(np.float32(1.0), u), v * 0)
        else:
            c, si = np.cos(turn), np.sin(turn)
        f0 = (c * t[0] + si * s[0], c * t[1] + si * s[1], c * t[2] + si * s[2])
        f1 = (-si * t[0] + c * s[0], -si * t[1] + c * s[1], -si * t[2] + c * s[2])
        inv_r = np.float32(1.0) / max(radius[point], min_radius)
        coef[0], coef[1], coef[2], coef[3], coef[4] = f0[0], f0[1], f0[2], f1[0], f1[1]
        coef[5], coef[6], coef[7], coef[8], coef[9] = f1[2], nx, ny, nz, inv_r
        steps = k // LANES
        _frame(x, first, steps, coef)
        for col in range(first + steps * LANES, first + k):  # the rest, one by one
            ox, oy, oz = x[0, col], x[1, col], x[2, col]
            dx, dy, dz = x[3, col], x[4, col], x[5, col]
            x[0, col] = (f0[0] * ox + f0[1] * oy + f0[2] * oz) * inv_r
            x[1, col] = (f1[0] * ox + f1[1] * oy + f1[2] * oz) * inv_r
            x[2, col] = (nx * ox + ny * oy + nz * oz) * inv_r
            x[3, col] = f0[0] * dx + f0[1] * dy + f0[2] * dz
            x[4, col] = f1[0] * dx + f1[1] * dy + f1[2] * dz
            x[5, col] = nx * dx + ny * dy + nz * dz
    z = np.empty(n * k, np.float32)
    logits_kernel(x, valid, packed, z)
    weight = np.empty(k, np.float32)
    for point in range(n):  # Eq. 2 with weights softplus(z + SHIFT) on the valid photons
        first = point * k
        for j in range(k):  # (no calls: vectorized)
            weight[j] = softplus(z[first + j] + shift) * valid[point, j]
        tr = tg = tb = np.float32(0.0)
        for j in range(k):
            i = min(index[point, j], last)
            tr += weight[j] * rows[i, 6]
            tg += weight[j] * rows[i, 7]
            tb += weight[j] * rows[i, 8]
        r = max(radius[point], min_radius)
        scale = np.float32(1.0 / (np.pi * np.pi)) / (r * r)
        out[point, 0] = albedo[point, 0] * tr * scale
        out[point, 1] = albedo[point, 1] * tg * scale
        out[point, 2] = albedo[point, 2] * tb * scale


# --- the XLA FFI handler: raw call-frame access (offsets of c_api.h's structs on 64-bit) ---
_EXTENSION, _STAGE, _ARGS, _RETS = 8, 32, 72, 112  # call frame: extension_start, stage,
# args.args, rets.rets
_EXT_TYPE, _EXT_METADATA = 8, 24  # extension base: type; metadata extension: metadata pointer
_META_VERSION, _META_TRAITS = 8, 32  # metadata: api_version struct, traits
_BUFFER_DATA, _BUFFER_DIMS = 24, 40  # buffer: data, dims
_API_MAJOR, _API_MINOR = 0, 1  # the FFI version reported: these structs are unchanged since
# 0.1 (offsets checked against jaxlib 0.10's header, API 0.3); XLA accepts older handlers
_METADATA_KIND, _EXECUTE = 1, 3


@intrinsic
def _load(typingctx, address, offset, kind):
    """The value of type `kind` (int32 / int64) at byte address + offset."""
    result = kind.instance_type

    def codegen(context, builder, sig, args):
        ptr = builder.add(args[0], args[1])
        width = context.get_value_type(result)
        return builder.load(builder.inttoptr(ptr, width.as_pointer()))

    return result(address, offset, kind), codegen


@intrinsic
def _store(typingctx, address, offset, value):
    """Store value (int32 / int64) at byte address + offset."""

    def codegen(context, builder, sig, args):
        ptr = builder.add(args[0], args[1])
        width = context.get_value_type(sig.args[2])
        builder.store(args[2], builder.inttoptr(ptr, width.as_pointer()))
        return context.get_dummy_value()

    return types.void(address, offset, value), codegen


@intrinsic
def _pointer(typingctx, address):
    """The int64 address as a void pointer (for `nb.carray`)."""

    def codegen(context, builder, sig, args):
        return builder.inttoptr(args[0], context.get_value_type(types.voidptr))

    return types.voidptr(address), codegen


@nb.njit(inline="always")
def _buffer(list_address, i):
    """(data address, dims address) of buffer i of an args / rets list."""
    buffer = _load(list_address, 8 * i, nb.int64)
    return _load(buffer, _BUFFER_DATA, nb.int64), _load(buffer, _BUFFER_DIMS, nb.int64)


@nb.njit(inline="always")
def _metadata_answered(frame):
    """Whether the call is XLA's metadata query (then answered: the API version, no traits)."""
    extension = _load(frame, _EXTENSION, nb.int64)
    if extension == 0 or _load(extension, _EXT_TYPE, nb.int32) != _METADATA_KIND:
        return False
    metadata = _load(extension, _EXT_METADATA, nb.int64)
    version = metadata + _META_VERSION
    _store(version, 0, nb.int64(24))  # struct_size of XLA_FFI_Api_Version
    _store(version, 8, nb.int64(0))  # extension_start
    _store(version, 16, nb.int32(_API_MAJOR))
    _store(version, 20, nb.int32(_API_MINOR))
    _store(metadata, _META_TRAITS, nb.int32(0))
    return True


@nb.njit(inline="always")
def _array(list_address, i, shape, dtype):
    """Buffer i of an args / rets list as an array of the given shape and dtype."""
    data, _ = _buffer(list_address, i)
    return nb.carray(_pointer(data), shape, dtype)


def _handler(frame):
    """XLA FFI handler of `fused_radiance`: args rows (P + 1, 16), index (n, K), hi, lo,
    normal, albedo (n, 3), radius, angle (n,), packed (PACKED,); ret (n, 3)."""
    if _metadata_answered(frame) or _load(frame, _STAGE, nb.int32) != _EXECUTE:
        return 0
    args, rets = _load(frame, _ARGS, nb.int64), _load(frame, _RETS, nb.int64)
    _, rows_dims = _buffer(args, 0)
    _, index_dims = _buffer(args, 1)
    n_rows = _load(rows_dims, 0, nb.int64)
    n, k = _load(index_dims, 0, nb.int64), _load(index_dims, 8, nb.int64)
    f32 = np.float32
    radiance_kernel(
        _array(args, 0, (n_rows, ROW), f32), _array(args, 1, (n, k), np.int32),
        _array(args, 2, (n, 3), f32), _array(args, 3, (n, 3), f32),
        _array(args, 4, (n, 3), f32), _array(args, 5, (n, 3), f32),
        _array(args, 6, (n,), f32), _array(args, 7, (n,), f32),
        _array(args, 8, (PACKED,), f32), _array(rets, 0, (n, 3), f32),
    )  # fmt: skip
    return 0


_handler_cfunc = None  # the compiled handler, kept alive for XLA once registered
_registering = threading.Lock()  # two threads may trace their first call at once


def _register() -> None:
    """Compile the handler (or load it from Numba's cache) and register it with XLA's CPU
    platform, once per process: on first use, so importing costs no compilation."""
    global _handler_cfunc
    with _registering:
        if _handler_cfunc is None:
            handler = nb.cfunc(types.int64(types.int64), cache=True)(_handler)
            address = ctypes.c_void_p(handler.address)
            jax.ffi.register_ffi_target(TARGET, jax.ffi.pycapsule(address), platform="cpu")
            _handler_cfunc = handler


def available() -> bool:
    """Whether jitted code here runs on the CPU, where the fused kernel is registered."""
    return jax.default_backend() == "cpu"


def fused_radiance(packed: jnp.ndarray, rows: jnp.ndarray, q) -> jnp.ndarray:
    """(B, 3) radiance of a `infer.Query` q of B points from the photons' rows (P + 1, ROW)
    float32 of an `infer.PhotonTable` and `pack_params`' array (PACKED,), by the fused kernel
    (CPU only): what `infer.query_radiance` computes, in one call (arrays cast to float32)."""
    if packed.shape != (PACKED,):
        raise ValueError(f"the fused kernel runs {CHANNELS} channels and width {WIDTH} only")
    if rows.shape[1] != ROW:
        raise ValueError(f"photon rows must hold {ROW} floats, not {rows.shape[1]}")
    _register()
    call = jax.ffi.ffi_call(
        TARGET, jax.ShapeDtypeStruct((len(q.radius), 3), jnp.float32), vmap_method="sequential"
    )
    f32 = jnp.float32
    points = [jnp.asarray(a, f32) for a in (q.position_hi, q.position_lo, q.normal, q.albedo,
              q.radius, q.angle)]  # fmt: skip
    return call(jnp.asarray(rows, f32), jnp.asarray(q.index, jnp.int32), *points, packed)
