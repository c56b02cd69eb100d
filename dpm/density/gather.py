"""Gathering photons around visible points: scipy's cKDTree for the K nearest, hashed grids
for the photons within a radius.

Two directions:
- `PhotonIndex.nearest`: a tree over the photons, built once per photon map, answers the K
  nearest photons of each point (PM, DPM), in chunks of points so that memory stays bounded;
- `PointIndex.within`: hashed grids over the points answer, for each photon of a pass, the
  points whose radius reaches it (the progressive methods, whose points stay put while passes
  stream by).
A photon counts only where its surface normal agrees with the point's (within 60°): photons on
the far side of a thin wall or on a perpendicular wall belong to another surface. Building
and querying count as the "gather" stage of the `Stopwatch` passed in.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass
from typing import TYPE_CHECKING

import numpy as np

from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap
from dpm.tracer.photon_grid import NORMAL_COS
from dpm.tracer.point_grid import PointGrid, grid_pairs, point_grid

if TYPE_CHECKING:
    from scipy.spatial import cKDTree

POINTS_PER_CHUNK = 1 << 14  # K-nearest queries answered at once
SPREAD = 4.0  # points wider than this times the 90th percentile radius are searched apart
REBUILD = 0.5  # point grids are rebuilt when the 90th percentile radius falls below this × theirs
GATHER = "gather"  # the stopwatch stage of tree building and queries


def kd_tree(points: np.ndarray) -> cKDTree:
    """A cKDTree over points (N, 3) float64. scipy is imported here, on the first tree: at
    start it cost every render about 70 ms, and a scene without caustics none."""
    from scipy.spatial import cKDTree

    return cKDTree(points)


@dataclass(frozen=True)
class Neighbourhoods:
    """The K nearest photons of a chunk of points (rows), nearest first."""

    index: np.ndarray  # (n, K) int64 photon index (len(photons) pads when there are fewer)
    distance: np.ndarray  # (n, K) float64 distance in scene units (inf pads)
    valid: np.ndarray | None  # (n, K) bool: a photon whose normal agrees with the point's


@dataclass(frozen=True)
class Pairs:
    """(point, photon) pairs closer than the point's radius, normals agreeing."""

    point: np.ndarray  # (Q,) int64 index into the points
    photon: np.ndarray  # (Q,) int64 index into the photons
    distance: np.ndarray  # (Q,) float64 distance in scene units


def _agree(normal_a: np.ndarray, normal_b: np.ndarray) -> np.ndarray:
    """(…) bool: unit normals (…, 3) within 60° of each other."""
    return np.einsum("...i,...i->...", normal_a, normal_b) >= NORMAL_COS


def take(values: np.ndarray, index: np.ndarray) -> np.ndarray:
    """values (P, C) of neighbours index (n, K) -> (n, K, C), zero rows for missing ones
    (index P: fewer photons than K), without copying values to add a padding row."""
    if len(values) == 0:
        return np.zeros((*index.shape, values.shape[1]), values.dtype)
    out = values[np.minimum(index, len(values) - 1)]
    out[index >= len(values)] = 0
    return out


class PhotonIndex:
    """A photon map and a cKDTree over its positions, built once per map and passed to every
    query (a render's row blocks, a benchmark's repeated estimates)."""

    def __init__(self, photons: PhotonMap, watch: Stopwatch | None = None) -> None:
        self.photons = photons
        with (watch or Stopwatch())(GATHER):
            self.tree = kd_tree(photons.position.astype(np.float64)) if len(photons) else None

    def __len__(self) -> int:
        return len(self.photons)

    def nearest(
        self,
        position: np.ndarray,
        normal: np.ndarray,
        k: int,
        watch: Stopwatch | None = None,
        agree: bool = True,
    ) -> Iterator[tuple[slice, Neighbourhoods]]:
        """The k nearest photons of points (N, 3) with unit normals (N, 3), a chunk of points
        at a time (the map must hold photons); query time counts as the watch's "gather".
        agree False leaves `valid` None, for callers that check the normals themselves."""
        watch = watch or Stopwatch()
        for first in range(0, len(position), POINTS_PER_CHUNK):
            with watch(GATHER):
                rows = slice(first, min(first + POINTS_PER_CHUNK, len(position)))
                dist, index = self.tree.query(position[rows].astype(np.float64), k=k, workers=-1)
                dist, index = dist.reshape(-1, k), index.reshape(-1, k)  # k = 1 drops the axis
                # a missing neighbour's zero normal never agrees
                valid = (
                    _agree(take(self.photons.normal, index), normal[rows, None, :])
                    if agree
                    else None
                )
            yield rows, Neighbourhoods(index, dist, valid)


Photons = PhotonMap | PhotonIndex  # what an estimator's `estimate` takes: a map or its index
Watch = Stopwatch | None  # the stopwatch an estimate's stages count on (None: not timed)


def photon_index(photons: Photons, watch: Watch = None) -> PhotonIndex:
    """`photons` itself when it is already indexed, else a new PhotonIndex over it."""
    return photons if isinstance(photons, PhotonIndex) else PhotonIndex(photons, watch)


class PointIndex:
    """Fixed points (N, 3) with their normals, queried by passes of photons through hashed
    grids (`dpm.tracer.point_grid`), kept from pass to pass while the radii shrink."""

    def __init__(self, position: np.ndarray, normal: np.ndarray) -> None:
        self.position = np.asarray(position, np.float64)
        self.normal = np.asarray(normal, np.float32)
        self.levels: list[tuple[np.ndarray, PointGrid]] = []  # (points, their grid)

    def within(
        self, photons: PhotonMap, radius: np.ndarray | float, watch: Stopwatch | None = None
    ) -> Pairs:
        """Pairs with distance < radius of the point: radius is (N,) per point or one value;
        the search counts as the watch's "gather"."""
        with (watch or Stopwatch())(GATHER):
            return self._within(photons, radius)

    def _within(self, photons: PhotonMap, radius: np.ndarray | float) -> Pairs:
        radius = np.broadcast_to(np.asarray(radius, np.float64), (len(self.position),))
        live = np.flatnonzero(radius > 0)
        parts = []
        if len(live) and len(photons):
            if not self._holds(radius, live):
                self.levels = self._grids(live, radius)
            for ids, grid in self.levels:
                point, photon, dist = grid_pairs(
                    grid, radius[ids], photons.position, photons.normal
                )
                parts.append((ids[point], photon, dist))
        if not parts:
            empty = np.zeros(0, np.int64)
            parts.append((empty, empty, np.zeros(0)))
        point, photon, dist = (np.concatenate(c) for c in zip(*parts, strict=True))
        return Pairs(point, photon, dist)

    def _holds(self, radius: np.ndarray, live: np.ndarray) -> bool:
        """Whether the grids serve these radii: each within the one its point was entered
        with, and the typical one not below REBUILD of theirs (cells far wider than the
        balls would make each photon read too many points)."""
        if not self.levels:
            return False
        entered = np.zeros(len(radius), bool)
        for ids, grid in self.levels:
            if (radius[ids] > grid.radius).any():
                return False
            entered[ids] = True
        typical = self.levels[0][1].side / 2  # the first grid's cells: 2 × its 90th percentile
        return bool(entered[live].all()) and np.quantile(radius[live], 0.9) >= REBUILD * typical

    def _grids(self, ids: np.ndarray, radius: np.ndarray) -> list[tuple[np.ndarray, PointGrid]]:
        """Grids over the points `ids`, in cells twice their 90th percentile radius. A point
        is entered in every cell its ball meets, so a few points far wider than the rest
        (seen 500 units away past a mirror) would fill every cell: points wider than SPREAD
        times the 90th percentile are entered apart, in a grid of their own (and so on, if
        they spread too)."""
        own = radius[ids]
        typical = float(np.quantile(own, 0.9))
        wide = own > SPREAD * typical
        narrow = ids[~wide]
        grid = point_grid(self.position[narrow], self.normal[narrow], own[~wide], 2 * typical)
        return [(narrow, grid)] + (self._grids(ids[wide], radius) if wide.any() else [])
