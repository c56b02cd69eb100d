"""The one interface every density estimator answers, classic or learned."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap, VisiblePoints
from dpm.tracer.visible import LUMINANCE


class Estimator(Protocol):
    """Caustic radiance at visible points from a photon map (scikit-learn style: parameters
    go to the constructor, data to `estimate`)."""

    def estimate(
        self, points: VisiblePoints, photons: PhotonMap | Any, watch: Stopwatch | None = None
    ) -> np.ndarray:
        """(N, 3) float32 caustic radiance leaving each visible point towards the camera
        (W m⁻² sr⁻¹, before the camera-path throughput); 0 where points.hit is False.
        `photons` may be a `PhotonIndex` over the map; stages count on `watch`."""
        ...


def reflected(albedo: np.ndarray, irradiance: np.ndarray) -> np.ndarray:
    """(n, 3) float32 radiance ρ/π · E leaving Lambertian points of albedo (n, 3), irradiance E."""
    return (np.asarray(albedo, np.float64) / np.pi * irradiance).astype(np.float32)


def luminance(rgb: np.ndarray) -> np.ndarray:
    """(…) Rec. 709 luminance of linear RGB (…, 3)."""
    return rgb @ np.array(LUMINANCE)


def tangent_frame(normal: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Two (Q, 3) float64 unit tangents orthogonal to unit normals (Q, 3) and to each other."""
    n = np.asarray(normal, np.float64)
    axis = np.where(np.abs(n[:, :1]) > 0.9, [[0.0, 1.0, 0.0]], [[1.0, 0.0, 0.0]])
    t = np.cross(n, axis)
    t /= np.linalg.norm(t, axis=1, keepdims=True)
    return t, np.cross(n, t)


def in_plane(v: np.ndarray, t: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(Q, 2) float64 components of vectors v (Q, 3) along tangents t and b (Q, 3)."""
    v = np.asarray(v, np.float64)
    return np.stack([np.einsum("ij,ij->i", v, t), np.einsum("ij,ij->i", v, b)], axis=1)
