"""Counter-based random numbers and the sampling routines built on them.

A random number is a hash of (seed, stream, dimension): a stream is e.g. a pixel sample or a
photon path, a dimension one decision along it. No generator state is shared between threads,
so results do not depend on the thread count or on the order of work.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

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
def sample_cosine(nx, ny, nz, u1, u2):
    """A unit direction about unit normal n with density cosθ/π (solid angle)."""
    tx, ty, tz, bx, by, bz = orthonormal_basis(nx, ny, nz)
    r = math.sqrt(u1)
    phi = 2.0 * math.pi * u2
    x, y = r * math.cos(phi), r * math.sin(phi)
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
