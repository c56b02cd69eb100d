"""The one interface every density estimator answers, classic or learned."""

from __future__ import annotations

from typing import Any, Protocol

import numpy as np

from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap, VisiblePoints


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
    return rgb @ np.array([0.2126, 0.7152, 0.0722])
