"""Fixed points (the progressive methods' visible points) in a hashed uniform grid, and the
(point, photon) pairs a pass of photons makes with them: each pair closer than the point's
own radius, normals agreeing.

Each point is entered in every cell (cubes of side `side`) that its ball meets, as in pbrt's
SPPM, so a photon reads the one bucket its own cell hashes to; a point is entered once per
bucket, and the distance test drops the points of other cells that share it. The grid holds
for any radii within those it was built with (the progressive methods' radii only shrink):
the search takes the current radii. A first parallel sweep counts each photon's pairs and a
second writes them where the counts' running sum puts them: pairs come photon by photon, each
photon's in bucket order, the same at any thread count. (This replaced a scipy cKDTree, whose
import alone cost a render 0.13 s.)
"""

from __future__ import annotations

import math
from typing import NamedTuple

import numba as nb
import numpy as np

from dpm.tracer.photon_grid import NORMAL_COS, ball_cells, bucket, bucket_count


class PointGrid(NamedTuple):
    """Points and their entries (a point in a bucket) sorted by bucket (pass it into Numba
    kernels)."""

    start: np.ndarray  # (buckets + 1,) int64: bucket h holds rows start[h] … start[h+1] − 1
    point: np.ndarray  # (E,) int64 the point of each row
    position: np.ndarray  # (N, 3) float64 world position of each point
    normal: np.ndarray  # (N, 3) float32 unit normal of each point
    radius: np.ndarray  # (N,) float64 the radius each point was entered with (scene units)
    side: float  # side of a cell (scene units)


def point_grid(
    position: np.ndarray, normal: np.ndarray, radius: np.ndarray, side: float
) -> PointGrid:
    """The grid of points (N, 3) float64 with unit normals (N, 3) for radii up to radius
    (N,) float64 > 0, in cells of side > 0 (a point meets about (1 + 2·radius / side)³)."""
    if not (math.isfinite(side) and side > 0):
        raise ValueError(f"the grid's cell side must be positive and finite (got {side})")
    position = np.ascontiguousarray(position, np.float64)
    radius = np.ascontiguousarray(radius, np.float64)
    start, point = _entries(position, radius, float(side), bucket_count(len(position)) - 1)
    return PointGrid(
        start, point, position, np.ascontiguousarray(normal, np.float32), radius, float(side)
    )


@nb.njit(cache=True)
def _entries(position, radius, side, mask):
    """(start, point): (buckets + 1,) int64 first row of each bucket and (E,) int64 the point
    of each row, each point in the buckets of the cells its ball meets, once per bucket, in
    point order within a bucket (a counting sort: one sweep hashes each point's cells and
    counts, a second places). A cell whose bucket an earlier cell of the same ball has is
    left out (`ball_bucket`'s rule, by comparing stored buckets: recomputing them, with the
    integer divisions of the cell's index, took most of a 128² pass's 4.6 ms here)."""
    n = len(position)
    first = np.zeros(n + 1, np.int64)  # point i's cells are rows first[i] … first[i+1] − 1
    for i in range(n):
        _, _, _, cx, cy, cz = ball_cells(
            position[i, 0], position[i, 1], position[i, 2], radius[i], side
        )
        first[i + 1] = first[i] + max(cx, 0) * max(cy, 0) * max(cz, 0)
    cells = np.empty(first[n], np.int32)  # each cell's bucket, −1 where the ball has it already
    start = np.zeros(mask + 2, np.int64)
    for i in range(n):
        x0, y0, z0, cx, cy, cz = ball_cells(
            position[i, 0], position[i, 1], position[i, 2], radius[i], side
        )
        k = first[i]
        for a in range(cx):
            for b in range(cy):
                for c in range(cz):  # z fastest, as `ball_bucket` numbers them
                    h = bucket(x0 + a, y0 + b, z0 + c, mask)
                    for e in range(first[i], k):
                        if cells[e] == h:
                            h = -1
                            break
                    cells[k] = h
                    k += 1
                    if h >= 0:
                        start[h + 1] += 1
    start = np.cumsum(start)
    fill = start[:-1].copy()
    point = np.empty(start[-1], np.int64)
    for i in range(n):
        for e in range(first[i], first[i + 1]):
            h = cells[e]
            if h >= 0:
                point[fill[h]] = i
                fill[h] += 1
    return start, point


def grid_pairs(
    grid: PointGrid, radius: np.ndarray, position: np.ndarray, normal: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(point, photon, distance): (Q,) int64 point, (Q,) int64 photon row, (Q,) float64
    distance, of each pair closer than the point's radius (N,) float64 (each at most the
    grid's; photons: (P, 3) float32 positions and unit normals)."""
    radius = np.ascontiguousarray(radius, np.float64)
    if (radius > grid.radius).any():
        raise ValueError("a radius is beyond the one its point was entered with")
    position = np.ascontiguousarray(position, np.float32)
    normal = np.ascontiguousarray(normal, np.float32)
    counts = np.zeros(len(position), np.int64)
    none = np.zeros(0, np.int64)
    _pairs(grid, radius, position, normal, counts, False, none, none, np.zeros(0))
    offset = np.cumsum(counts) - counts
    total = int(counts.sum())
    point, photon, distance = np.empty(total, np.int64), np.empty(total, np.int64), np.empty(total)
    _pairs(grid, radius, position, normal, offset, True, point, photon, distance)
    return point, photon, distance


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _pairs(grid, radius, position, normal, slot, write, point, photon, distance):
    """Per photon: count its pairs into slot (write False), or write them from slot[j] on
    (write True) as points, photon rows and distances."""
    mask = len(grid.start) - 2
    side = grid.side
    for j in nb.prange(len(position)):
        px, py, pz = (
            np.float64(position[j, 0]),
            np.float64(position[j, 1]),
            np.float64(position[j, 2]),
        )
        h = bucket(math.floor(px / side), math.floor(py / side), math.floor(pz / side), mask)
        k = slot[j] if write else 0
        for e in range(grid.start[h], grid.start[h + 1]):
            i = grid.point[e]
            dx = grid.position[i, 0] - px
            dy = grid.position[i, 1] - py
            dz = grid.position[i, 2] - pz
            d = math.sqrt(dx * dx + dy * dy + dz * dz)
            if not d < radius[i]:  # a NaN photon pairs with nothing
                continue
            cos = (
                grid.normal[i, 0] * normal[j, 0]
                + grid.normal[i, 1] * normal[j, 1]
                + grid.normal[i, 2] * normal[j, 2]
            )
            if cos < NORMAL_COS:
                continue
            if write:
                point[k], photon[k], distance[k] = i, j, d
            k += 1
        if not write:
            slot[j] = k
