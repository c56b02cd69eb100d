"""Counter-based random numbers and the sampling routines built on them.

A random number is a hash of (seed, stream, dimension): a stream is e.g. a pixel sample or a
photon path, a dimension one decision along it. No generator state is shared between threads,
so results do not depend on the thread count or on the order of work. A camera path's first
decisions can instead be points of its pixel's stratified sequence (`stratified2`, indexed by
the path's number within the pixel): as uniform, but spread evenly over the pixel's paths.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np
from llvmlite import ir
from numba.core import cgutils, types
from numba.extending import intrinsic

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30, _S27, _S31, _S11 = np.uint64(30), np.uint64(27), np.uint64(31), np.uint64(11)


@nb.njit(cache=True, inline="always")
def mix64(x):
    """SplitMix64 finaliser: a bijective avalanche of a uint64."""
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@nb.njit(cache=True, inline="always")
def uniform(seed, stream, dim):
    """A uniform float64 in [0, 1) determined by (seed, stream, dim), all non-negative ints."""
    h = mix64(np.uint64(seed) * _GOLDEN + np.uint64(stream))
    h = mix64(h + np.uint64(dim) * _GOLDEN)
    return np.float64(h >> _S11) * (1.0 / 9007199254740992.0)


@nb.njit(cache=True, inline="always")
def sample_cdf(cdf, u):
    """Index i with probability cdf[i] - cdf[i-1], for u in [0, 1)."""
    i = np.searchsorted(cdf, u, side="right")
    return min(i, cdf.shape[0] - 1)


@nb.njit(cache=True, inline="always")
def sample_triangle(tri, u1, u2):
    """A point (x, y, z) uniform by area on triangle tri (3, 3)."""
    s = math.sqrt(u1)
    b0, b1 = 1.0 - s, u2 * s
    b2 = 1.0 - b0 - b1
    x = b0 * tri[0, 0] + b1 * tri[1, 0] + b2 * tri[2, 0]
    y = b0 * tri[0, 1] + b1 * tri[1, 1] + b2 * tri[2, 1]
    z = b0 * tri[0, 2] + b1 * tri[1, 2] + b2 * tri[2, 2]
    return x, y, z


@nb.njit(cache=True, inline="always", error_model="numpy")
def orthonormal_basis(nx, ny, nz):
    """Two unit tangents (tx, ty, tz, bx, by, bz) completing unit n to a right-handed frame."""
    # Without branches on the normal's sign (Duff et al. 2017).
    sign = 1.0 if nz >= 0 else -1.0
    a = -1.0 / (sign + nz)
    b = nx * ny * a
    return 1.0 + sign * nx * nx * a, sign * b, -sign * nx, b, sign + ny * ny * a, -ny


@nb.njit(cache=True, inline="always", error_model="numpy")
def turn(u):
    """(cos 2πu, sin 2πu) for u in [0, 1), within 1e-11 of libm's, without its call (libm's
    sincos was 4-8 % of a path tracer's time: one per bounce). u is reduced to the nearest
    quarter turn k/4 and a remainder of at most an eighth of a turn, whose angle a (|a| ≤ π/4)
    takes the Taylor series to a^11 (sin) and a^12 (cos); then k quarter turns rotate it."""
    k = math.floor(4.0 * u + 0.5)
    a = (2.0 * math.pi) * (u - 0.25 * k)
    a2 = a * a
    s = a * (1.0 + a2 * (-1 / 6 + a2 * (1 / 120 + a2 * (-1 / 5040 + a2 * (
        1 / 362880 + a2 * (-1 / 39916800))))))  # fmt: skip
    c = 1.0 + a2 * (-0.5 + a2 * (1 / 24 + a2 * (-1 / 720 + a2 * (1 / 40320 + a2 * (
        -1 / 3628800 + a2 * (1 / 479001600))))))  # fmt: skip
    # k quarter turns (k = 4 is none) as selects on the float k: an integer chain of
    # `q == 1 else ...` compiled to branches on a random quadrant, mispredicted half the time
    # (10 ns a call, against 0.7 in a loop LLVM vectorizes; the values are the same)
    odd = (k == 1.0) | (k == 3.0)
    x = s if odd else c
    y = c if odd else s
    cos = -x if (k == 1.0) | (k == 2.0) else x
    sin = -y if (k == 2.0) | (k == 3.0) else y
    return cos, sin


@nb.njit(cache=True, inline="always", error_model="numpy")
def sample_cosine(nx, ny, nz, u1, u2):
    """A unit direction about unit normal n with density cosθ/π (solid angle)."""
    tx, ty, tz, bx, by, bz = orthonormal_basis(nx, ny, nz)
    r = math.sqrt(u1)
    c, s = turn(u2)
    x, y = r * c, r * s
    z = math.sqrt(max(0.0, 1.0 - u1))
    return (
        x * tx + y * bx + z * nx,
        x * ty + y * by + z * ny,
        x * tz + y * bz + z * nz,
    )


_TOP = np.int64(1) << np.int64(31)
_MASK32 = (np.int64(1) << np.int64(32)) - np.int64(1)


@nb.njit(cache=True, inline="always")
def sobol2(index, scramble_x, scramble_y):
    """Point `index` (≥ 0) of the first two Sobol dimensions, each digitally shifted by a
    32-bit scramble: (x, y) in [0, 1)². Every point is uniform; every run of 2^m points from
    a multiple of 2^m puts one in each of 2^m equal boxes of any shape 2^-a × 2^-(m-a)
    (a (0, 2)-sequence), so a region's share of the samples is off by far less than at random."""
    x, y = np.int64(scramble_x) & _MASK32, np.int64(scramble_y) & _MASK32
    i, vx, vy = np.int64(index), _TOP, _TOP
    while i > 0:  # dimension 1 is van der Corput's; dimension 2's matrix is Pascal's mod 2
        if i & 1:
            x ^= vx
            y ^= vy
        i >>= 1
        vx >>= 1
        vy ^= vy >> 1
    return np.float64(x) * (1.0 / 4294967296.0), np.float64(y) * (1.0 / 4294967296.0)


_LOW32 = np.uint64(0xFFFFFFFF)
# Laine & Karras's hash (as Burley 2020 gives it): applied to a bit-reversed fraction, each
# bit flips by a hash of the bits above it in the fraction.
_LK = (np.uint64(0x6C50B47C), np.uint64(0xB82F1E52), np.uint64(0xC7AFE638), np.uint64(0x8D22F6E6))


@intrinsic
def _reverse32(typingctx, x):
    """The 32 low bits of uint64 x in reverse order (LLVM's bitreverse, a few instructions)."""

    def codegen(context, builder, sig, args):
        i32 = ir.IntType(32)
        fn = cgutils.get_or_insert_function(
            builder.module, ir.FunctionType(i32, [i32]), "llvm.bitreverse.i32"
        )
        low = builder.trunc(args[0], i32)
        return builder.zext(builder.call(fn, [low]), ir.IntType(64))

    return types.uint64(types.uint64), codegen


@nb.njit(cache=True, inline="always")
def _hash_reversed(x, seed):
    """Laine & Karras's permutation of uint64 x (< 2^32) for uint64 seed, mod 2^32."""
    x = (x + (seed & _LOW32)) & _LOW32
    for c in _LK:
        x ^= (x * c) & _LOW32
    return x


@nb.njit(cache=True, inline="always")
def owen32(x, seed):
    """A hash-based Owen scramble of the 32-bit fraction x (uint64) for uint64 seed (Burley
    2020): bit b flips by a hash of the bits above it, so any aligned run of 2^m fractions
    maps to another aligned run (a random nested permutation)."""
    return _reverse32(_hash_reversed(_reverse32(x), seed))


def _sobol_tables() -> np.ndarray:
    """(4, 256) uint64: Sobol dimension 2's 32-bit fraction for each byte of an index, per
    byte position (the fraction of an index is the XOR of its bytes' entries)."""
    columns, v = [], 1 << 31
    for _ in range(32):  # the generator matrix's columns: Pascal's triangle mod 2
        columns.append(v)
        v ^= v >> 1
    tables = np.zeros((4, 256), np.uint64)
    for k in range(4):
        for b in range(256):
            for bit in range(8):
                if b >> bit & 1:
                    tables[k, b] ^= columns[8 * k + bit]
    return tables


_SOBOL2 = _sobol_tables()
_BYTE = np.uint64(0xFF)


@nb.njit(cache=True, inline="always")
def stratified2(index, seed, pair):
    """Point `index` (0 ≤ index < 2^32) of the pixel sequence `seed` (uint64) in dimension
    pair `pair`: (u, v) in [0, 1)². The first two Sobol dimensions, index shuffled and both
    coordinates Owen-scrambled by hashes of (seed, pair) (Burley 2020), so each point is
    uniform, pairs are independent of each other, and any 2^m consecutive points from a
    multiple of 2^m stratify the square as a (0, m, 2)-net does: progressive stratification."""
    h = mix64(seed + np.uint64(pair + 1) * _GOLDEN)
    # the shuffle is an Owen scramble of the index's reversed bits; Sobol's first dimension
    # is the index reversed, so its scramble needs no reversal of its own
    r = _hash_reversed(_reverse32(np.uint64(index) & _LOW32), h)
    i = _reverse32(r)
    x = _reverse32(_hash_reversed(i, mix64(h)))
    t = _SOBOL2
    y = t[0, i & _BYTE] ^ t[1, (i >> np.uint64(8)) & _BYTE]
    y ^= t[2, (i >> np.uint64(16)) & _BYTE] ^ t[3, i >> np.uint64(24)]
    y = owen32(y, mix64(h ^ _M1))
    return np.float64(x) * (1.0 / 4294967296.0), np.float64(y) * (1.0 / 4294967296.0)


@nb.njit(cache=True, inline="always")
def pixel_sequence(seed, pix):
    """uint64 seed of pixel pix's stratified sequence (`stratified2`) for a sequence seed."""
    return mix64(mix64(np.uint64(seed) * _GOLDEN + np.uint64(pix)) ^ _M2)


def sequence_seed(seed: int, half: int = 0, extra: bool = False) -> int:
    """The seed (≥ 0) of the pixels' stratified sequences of a render's seed, or of one of its
    halves (`auto`: each half's passes extend one sequence, and with `extra` its adaptive
    paths another): independent of the random streams' seeds and of each other."""
    entropy = [seed, half, 0x5EC] + ([1] if extra else [])
    return int(np.random.SeedSequence(entropy).generate_state(1)[0])
