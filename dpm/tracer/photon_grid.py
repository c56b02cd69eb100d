"""A pass's caustic photons in a hashed uniform grid, for fixed-radius density estimates
inside Numba kernels: the path tracer's diffuse vertices after the visible point
(`grid_irradiance`), and SPPM's sums within each pixel's radii (`disc_sums`).

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
    return PhotonGrid(
        *_by_bucket(photons.position, photons.normal, photons.flux, 2.0 * radius,
                    bucket_count(len(photons)) - 1),
        float(radius),
    )  # fmt: skip


@nb.njit(cache=True)
def _by_bucket(position, normal, flux, cell, mask):
    """(start, position, normal, flux): the photons (P, 3) float32 arrays as float64, sorted
    by the bucket of their cell (cubes of side `cell`), in photon order within a bucket (a
    counting sort: NumPy's argsort and gathers took 20 ms a pass at 128²)."""
    n = position.shape[0]
    key = np.empty(n, np.int64)
    start = np.zeros(mask + 2, np.int64)
    for i in range(n):
        h = bucket(
            math.floor(np.float64(position[i, 0]) / cell),
            math.floor(np.float64(position[i, 1]) / cell),
            math.floor(np.float64(position[i, 2]) / cell),
            mask,
        )
        key[i] = h
        start[h + 1] += 1
    for h in range(mask + 1):
        start[h + 1] += start[h]
    fill = start[:-1].copy()
    p, m, f = np.empty((n, 3)), np.empty((n, 3)), np.empty((n, 3))
    for i in range(n):
        row = fill[key[i]]
        fill[key[i]] += 1
        for c in range(3):
            p[row, c], m[row, c], f[row, c] = position[i, c], normal[i, c], flux[i, c]
    return start, p, m, f


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


# `disc_sums`' cells are cubes of side twice the median radius (a typical ball meets 2 × 2 × 2
# of them), and points whose radius is over SPREAD times the median of those left are summed
# apart, in a grid of cells sized for them (and so on): a ball, at most 2 cells in radius,
# then meets at most 5 cells a side (6 where rounding moves an edge). A block of more cells
# than MAX_BALL_CELLS (rounding far from the origin) reads every bucket once instead.
# (Cells of 1.5 or 1 median radius read fewer photons and more buckets: no faster.)
SPREAD = 4.0
MAX_BALL_CELLS = 216
POINTS_PER_TASK = 64  # points of one parallel task (each task keeps its ball's buckets)


def disc_sums(
    photons: PhotonMap,
    position: np.ndarray,
    normal: np.ndarray,
    radii: np.ndarray,
    out: tuple[np.ndarray, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """(found, flux): (S, N) float64 photons and (S, N, 3) float64 their summed flux (W)
    within each of S radii (S, N) float64 (scene units; ≤ 0: none) of points (N, 3) with
    unit normals (N, 3) float32, normals agreeing. The pairs are those of
    `dpm.tracer.point_grid.grid_pairs` (the same arithmetic), none of them stored: each
    point sums its photons in the grid's order, the same at any thread count. `out`: arrays
    of those shapes to write into (a caller gathering pass after pass keeps them: fresh
    arrays of a million points' sums are hundreds of MB of new pages each pass)."""
    radii = np.ascontiguousarray(np.atleast_2d(radii), np.float64)
    position = np.ascontiguousarray(position, np.float64)
    normal = np.ascontiguousarray(normal, np.float32)
    shapes = (radii.shape, (*radii.shape, 3))
    found, flux = out if out is not None else (np.empty(shapes[0]), np.empty(shapes[1]))
    for a, shape in zip((found, flux), shapes, strict=True):
        if a.shape != shape or a.dtype != np.float64 or not a.flags.c_contiguous:
            raise ValueError(f"disc_sums: out needs C-contiguous float64 arrays {shapes}")
    reach = radii.max(axis=0)
    ids = np.flatnonzero(reach > 0)
    dead = np.flatnonzero(~(reach > 0)) if len(photons) else slice(None)  # the kernel's skip
    found[:, dead], flux[:, dead] = 0.0, 0.0
    while len(ids) and len(photons):
        typical = float(np.median(reach[ids]))
        part = ids[reach[ids] <= SPREAD * typical]
        _disc_sums(photon_grid(photons, typical), position, normal, radii, part, found, flux)
        ids = ids[reach[ids] > SPREAD * typical]
    return found, flux


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _disc_sums(grid, position, normal, radii, rows, found, flux):
    """`disc_sums` of the points rows (R,) of position (N, 3) at radii (S, N) into found
    (S, N) and flux (S, N, 3), from one grid whose cells are at least half the widest radius
    of those points (their entries are zeroed first; others are left alone)."""
    mask = len(grid.start) - 2
    cell = 2.0 * grid.radius
    n, states = len(rows), radii.shape[0]
    for task in nb.prange((n + POINTS_PER_TASK - 1) // POINTS_PER_TASK):
        buckets = np.empty(MAX_BALL_CELLS, np.int64)
        for j in range(task * POINTS_PER_TASK, min(n, (task + 1) * POINTS_PER_TASK)):
            i = rows[j]
            for k in range(states):
                found[k, i] = 0.0
                flux[k, i, 0] = flux[k, i, 1] = flux[k, i, 2] = 0.0
            reach = 0.0
            for k in range(states):
                reach = max(reach, radii[k, i])
            if not reach > 0:
                continue
            px, py, pz = position[i, 0], position[i, 1], position[i, 2]
            far = reach * reach * (1.0 + 1e-9)
            m = 0  # the ball's distinct buckets
            x0, y0, z0, cx, cy, cz = ball_cells(px, py, pz, reach, cell)
            every = cx * cy * cz > MAX_BALL_CELLS
            for a in range(0 if every else cx):
                for b in range(cy):
                    for c in range(cz):
                        h = bucket(x0 + a, y0 + b, z0 + c, mask)
                        seen = False
                        for e in range(m):
                            if buckets[e] == h:
                                seen = True
                                break
                        if not seen:
                            buckets[m] = h
                            m += 1
            for e in range(mask + 1 if every else m):
                h = e if every else buckets[e]
                for row in range(grid.start[h], grid.start[h + 1]):
                    # as `point_grid._pairs`: float64 distance, float32 normals
                    dx = px - grid.position[row, 0]
                    dy = py - grid.position[row, 1]
                    dz = pz - grid.position[row, 2]
                    q = dx * dx + dy * dy + dz * dz
                    if q > far:  # (surely out: the exact test below takes a square root)
                        continue
                    d = math.sqrt(q)
                    if not d < reach:
                        continue
                    cos = (
                        normal[i, 0] * np.float32(grid.normal[row, 0])
                        + normal[i, 1] * np.float32(grid.normal[row, 1])
                        + normal[i, 2] * np.float32(grid.normal[row, 2])
                    )
                    if cos < NORMAL_COS:
                        continue
                    for k in range(states):
                        if d < radii[k, i]:
                            found[k, i] += 1.0
                            for ch in range(3):
                                flux[k, i, ch] += grid.flux[row, ch]
