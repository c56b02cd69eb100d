"""Numba ray tracing: BVH build, closest-hit and occlusion queries over arrays of rays."""

from __future__ import annotations

import numpy as np

from dpm.scene import Scene
from dpm.tracer import _cache  # noqa: F401  (first: drops stale compiled kernels)
from dpm.tracer.bvh import BVH, BVHArrays, build_bvh_from_triangles
from dpm.tracer.path import shade, trace_listed, trace_pixel_sums, trace_pixels
from dpm.tracer.photons import PhotonMap, trace_photons
from dpm.tracer.traverse import any_hit_batch, brute_force_batch, closest_hit_batch
from dpm.tracer.visible import (
    VisiblePoints,
    specular_pixels,
    trace_emitted,
    trace_visible_points,
)

__all__ = [
    "BVH",
    "BVHArrays",
    "PhotonMap",
    "VisiblePoints",
    "build_bvh",
    "intersect",
    "intersect_brute_force",
    "occluded",
    "shade",
    "trace_photons",
    "trace_listed",
    "trace_pixel_sums",
    "trace_pixels",
    "specular_pixels",
    "trace_emitted",
    "trace_visible_points",
]


def build_bvh(scene: Scene | np.ndarray) -> BVH:
    """Build a BVH over a Scene's triangles, or over a (T, 3, 3) array of vertex positions."""
    triangles = scene.triangles if isinstance(scene, Scene) else scene
    return build_bvh_from_triangles(triangles)


def _rays(
    origins: np.ndarray, directions: np.ndarray, tmax: float | np.ndarray | None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rays as the batch kernels take them: (R, 3) C-contiguous, both float32 (kept as given,
    not copied) or both float64, and tmax (R,) or (1,) float64."""
    o, d = np.asarray(origins), np.asarray(directions)
    dtype = np.float32 if o.dtype == d.dtype == np.float32 else np.float64
    o = np.ascontiguousarray(o, dtype=dtype).reshape(-1, 3)
    d = np.ascontiguousarray(d, dtype=dtype).reshape(-1, 3)
    if o.shape != d.shape:
        raise ValueError(f"origins {o.shape} and directions {d.shape} differ in shape")
    if tmax is None or np.ndim(tmax) == 0:
        t = np.full(1, np.inf if tmax is None else tmax, np.float64)
    else:
        t = np.ascontiguousarray(np.broadcast_to(tmax, (len(o),)), dtype=np.float64)
    if np.isnan(t).any():
        raise ValueError("tmax must not be NaN")
    return o, d, t


def _check(flags: int) -> None:
    """Raise for the `traverse._ray_flags` a batch kernel returned (its results are void)."""
    if flags & 1:
        raise ValueError("ray origins and directions must be finite")
    if flags & 2:
        raise ValueError("ray directions must be non-zero")


def intersect(
    bvh: BVH,
    origins: np.ndarray,
    directions: np.ndarray,
    tmax: float | np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """Closest hits of rays (R, 3): t (R,) float64 in units of |direction| and triangle (R,) int32.

    Hits count for 0 < t < tmax; a miss has t = inf and triangle index -1.
    """
    o, d, tm = _rays(origins, directions, tmax)
    t = np.empty(len(o))
    tri = np.empty(len(o), np.int32)
    _check(closest_hit_batch(bvh.arrays, bvh.depth, o, d, tm, t, tri))
    return t, tri


def occluded(
    bvh: BVH,
    origins: np.ndarray,
    directions: np.ndarray,
    tmax: float | np.ndarray | None = None,
) -> np.ndarray:
    """(R,) bool: whether each ray hits any triangle with 0 < t < tmax."""
    o, d, tm = _rays(origins, directions, tmax)
    out = np.empty(len(o), np.bool_)
    _check(any_hit_batch(bvh.arrays, bvh.depth, o, d, tm, out))
    return out


def intersect_brute_force(
    triangles: np.ndarray,
    origins: np.ndarray,
    directions: np.ndarray,
    tmax: float | np.ndarray | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """`intersect` without a BVH, testing every triangle (T, 3, 3): the reference for tests."""
    o, d, tm = _rays(origins, directions, tmax)
    verts = np.ascontiguousarray(triangles, dtype=np.float32).reshape(-1, 9)
    t = np.empty(len(o))
    tri = np.empty(len(o), np.int32)
    _check(brute_force_batch(verts, o, d, tm, t, tri))
    return t, tri
