"""A pass's caustic photons in a hashed uniform grid, for fixed-radius density estimates
inside Numba kernels (the path tracer's diffuse vertices after the visible point).

Cells are cubes of side 2r, so the ball of radius r around a point meets at most 2×2×2 of
them; cells hash into 2^k buckets (k: the least with 2^k ≥ 2·photons), a bucket's photons
being consecutive rows. Photons of other cells that share a bucket are rejected by the
distance test, and a bucket two of the cells share is read once.
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from dpm.tracer.photons import PhotonMap

NORMAL_COS = 0.5  # a photon counts when dot(photon normal, point normal) ≥ this (within 60°)
_PRIMES = (73856093, 19349663, 83492791)  # Teschner et al. 2003's spatial hash


class PhotonGrid(NamedTuple):
    """Photons sorted by hash bucket, and the query radius (pass it into Numba kernels)."""

    start: np.ndarray  # (buckets + 1,) int64: bucket h holds rows start[h] … start[h+1] − 1
    position: np.ndarray  # (P, 3) float64 world position
    normal: np.ndarray  # (P, 3) float64 unit normal on the side the photon arrived
    flux: np.ndarray  # (P, 3) float64 stored flux (W, already ÷ N)
    radius: float  # query radius r (scene units)


@nb.njit(cache=True, inline="always")
def bucket(ix, iy, iz, mask):
    """Hash bucket of integer cell (ix, iy, iz)."""
    return ((ix * _PRIMES[0]) ^ (iy * _PRIMES[1]) ^ (iz * _PRIMES[2])) & mask


@nb.njit(cache=True, inline="always")
def ball_cells(px, py, pz, r, cell):
    """The block of cells (cubes of side `cell`) that the ball of radius r about p meets: its
    first integer cell (x0, y0, z0) and its cells along x, y and z."""
    x0, y0, z0 = (
        math.floor((px - r) / cell),
        math.floor((py - r) / cell),
        math.floor((pz - r) / cell),
    )
    cx = math.floor((px + r) / cell) - x0 + 1
    cy = math.floor((py + r) / cell) - y0 + 1
    cz = math.floor((pz + r) / cell) - z0 + 1
    return x0, y0, z0, cx, cy, cz


@nb.njit(cache=True, inline="always")
def ball_bucket(c, x0, y0, z0, cy, cz, mask):
    """The bucket of the block's c-th cell (z fastest), or −1 where an earlier cell of the
    block hashed to the same bucket (each bucket is read once)."""
    h = bucket(x0 + c // (cy * cz), y0 + c // cz % cy, z0 + c % cz, mask)
    for e in range(c):
        if bucket(x0 + e // (cy * cz), y0 + e // cz % cy, z0 + e % cz, mask) == h:
            return -1
    return h


def bucket_count(n: int) -> int:
    """Buckets for n entries: the least power of two ≥ 2n (at least 2)."""
    return 1 << max(1, (2 * n - 1).bit_length())


def photon_grid(photons: PhotonMap, radius: float) -> PhotonGrid:
    """The grid of a photon map for queries of radius r > 0 (scene units)."""
    if not (math.isfinite(radius) and radius > 0):
        raise ValueError(f"the grid's radius must be positive and finite (got {radius})")
    buckets = bucket_count(len(photons))
    cells = np.floor(photons.position.astype(np.float64) / (2.0 * radius)).astype(np.int64)
    key = bucket(cells[:, 0], cells[:, 1], cells[:, 2], buckets - 1)
    order = np.argsort(key, kind="stable")
    start = np.searchsorted(key[order], np.arange(buckets + 1)).astype(np.int64)
    return PhotonGrid(
        start,
        photons.position[order].astype(np.float64),
        photons.normal[order].astype(np.float64),
        photons.flux[order].astype(np.float64),
        float(radius),
    )


@nb.njit(cache=True, inline="always", error_model="numpy")
def grid_irradiance(grid, px, py, pz, nx, ny, nz):
    """(r, g, b) Σ Φᵢ / (π r²) over the photons within r of point p whose normals agree with
    the unit normal n: the caustic irradiance (W/m²) of a density estimate with a disc of
    radius r."""
    r = grid.radius
    mask = len(grid.start) - 2
    x0, y0, z0, cx, cy, cz = ball_cells(px, py, pz, r, 2.0 * r)  # 1 or 2 cells each way
    er = eg = eb = 0.0
    for c in range(cx * cy * cz):
        h = ball_bucket(c, x0, y0, z0, cy, cz, mask)
        if h < 0:
            continue
        for k in range(grid.start[h], grid.start[h + 1]):
            dx = grid.position[k, 0] - px
            dy = grid.position[k, 1] - py
            dz = grid.position[k, 2] - pz
            if dx * dx + dy * dy + dz * dz >= r * r:
                continue
            cos = grid.normal[k, 0] * nx + grid.normal[k, 1] * ny + grid.normal[k, 2] * nz
            if cos >= NORMAL_COS:
                er += grid.flux[k, 0]
                eg += grid.flux[k, 1]
                eb += grid.flux[k, 2]
    area = math.pi * r * r
    return er / area, eg / area, eb / area
