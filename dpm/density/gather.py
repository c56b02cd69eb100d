"""Gathering photons around visible points with scipy's cKDTree.

Two directions, both chunked so that peak memory stays bounded:
- `nearest`: a tree over the photons answers the K nearest photons of each point (PM, DPM);
- `within`: a tree over the points answers, for each photon of a pass, the points whose
  radius reaches it (the progressive methods, whose points stay put while passes stream by).
A photon counts only where its surface normal agrees with the point's (within 60°): photons on
the far side of a thin wall or on a perpendicular wall belong to another surface.
"""

from __future__ import annotations

import time
import weakref
from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np
from scipy.spatial import cKDTree

from dpm.tracer import PhotonMap

NORMAL_COS = 0.5  # a photon counts when dot(photon normal, point normal) ≥ this
POINTS_PER_CHUNK = 1 << 14  # K-nearest queries answered at once
PHOTONS_PER_CHUNK = 1 << 16  # photons of a pass whose points are sought at once

# Seconds spent in tree building and queries since the last reset, so that benchmarks can
# report gathering apart from estimation (reset by assigning 0.0).
seconds = 0.0

# The last photon tree and a weak reference to the positions it was built from: a render asks
# for the same map's neighbours once per block of rows, and rebuilding costs ~0.4 s per 1M.
_last_tree: tuple[weakref.ref, cKDTree] | None = None


@dataclass(frozen=True)
class Neighbourhoods:
    """The K nearest photons of a chunk of points (rows), nearest first."""

    index: np.ndarray  # (n, K) int64 photon index (len(photons) pads when there are fewer)
    distance: np.ndarray  # (n, K) float64 distance in scene units (inf pads)
    valid: np.ndarray  # (n, K) bool: a photon whose normal agrees with the point's


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


def photon_tree(photons: PhotonMap) -> cKDTree:
    """A cKDTree over photons.position (P, 3), reused while the same position array is asked
    for again (the map is frozen; its arrays are never written after tracing)."""
    global _last_tree
    if _last_tree is not None and _last_tree[0]() is photons.position:
        return _last_tree[1]
    tree = cKDTree(photons.position.astype(np.float64))
    _last_tree = (weakref.ref(photons.position), tree)
    return tree


def forget_tree() -> None:
    """Drop the reused photon tree, so that a timed query pays for building its own."""
    global _last_tree
    _last_tree = None


def nearest(
    photons: PhotonMap,
    position: np.ndarray,
    normal: np.ndarray,
    k: int,
    tree: cKDTree | None = None,
) -> Iterator[tuple[slice, Neighbourhoods]]:
    """The k nearest photons of points (N, 3) with normals (N, 3), a chunk of points at a time;
    `tree` (a cKDTree over photons.position) saves rebuilding it for repeated queries."""
    global seconds
    start = time.perf_counter()
    if tree is None:
        tree = photon_tree(photons)
    seconds += time.perf_counter() - start
    for first in range(0, len(position), POINTS_PER_CHUNK):
        start = time.perf_counter()
        rows = slice(first, min(first + POINTS_PER_CHUNK, len(position)))
        dist, index = tree.query(position[rows].astype(np.float64), k=k, workers=-1)
        dist, index = dist.reshape(-1, k), index.reshape(-1, k)  # k = 1 drops the axis
        # a missing neighbour's zero normal never agrees
        valid = _agree(take(photons.normal, index), normal[rows, None, :])
        seconds += time.perf_counter() - start
        yield rows, Neighbourhoods(index, dist, valid)


class PointIndex:
    """A cKDTree over fixed points (N, 3) with their normals, queried by passes of photons."""

    def __init__(self, position: np.ndarray, normal: np.ndarray) -> None:
        self.position = np.asarray(position, np.float64)
        self.normal = np.asarray(normal, np.float32)
        self.tree = cKDTree(self.position)

    def within(self, photons: PhotonMap, radius: np.ndarray | float) -> Pairs:
        """Pairs with distance < radius of the point: radius is (N,) per point or one value."""
        global seconds
        begin = time.perf_counter()
        radius = np.broadcast_to(np.asarray(radius, np.float64), (len(self.position),))
        reach = float(radius.max(initial=0.0))
        parts = []
        for start in range(0, len(photons), PHOTONS_PER_CHUNK):
            position = photons.position[start : start + PHOTONS_PER_CHUNK].astype(np.float64)
            # Most photons land where no point's radius reaches (the discs cover a few per
            # cent of the surfaces): a parallel nearest-point query drops them before the
            # single-threaded pair search.
            near, _ = self.tree.query(position, k=1, distance_upper_bound=reach, workers=-1)
            reached = np.flatnonzero(near <= reach)
            if len(reached) == 0:
                continue
            other = cKDTree(position[reached])
            m = self.tree.sparse_distance_matrix(other, reach, output_type="ndarray")
            point, photon, dist = m["i"], reached[m["j"]] + start, m["v"]
            keep = (dist < radius[point]) & _agree(self.normal[point], photons.normal[photon])
            parts.append((point[keep], photon[keep], dist[keep]))
        if not parts:
            empty = np.zeros(0, np.int64)
            parts.append((empty, empty, np.zeros(0)))
        point, photon, dist = (np.concatenate(c) for c in zip(*parts, strict=True))
        seconds += time.perf_counter() - begin
        return Pairs(point, photon, dist)
