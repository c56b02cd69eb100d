"""Photon mapping (Jensen 1996): the K nearest photons, radius = distance to the K-th (Eq. 1)."""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from dpm.density.base import reflected
from dpm.density.gather import PhotonIndex, Photons, Watch, photon_index, take
from dpm.density.kernels import KERNELS
from dpm.errors import InputError
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap, VisiblePoints


def check_k(k: int, photons: PhotonMap) -> None:
    """Raise InputError when k < 1 or k exceeds the photons there are (none is fine: black)."""
    if k < 1:
        raise InputError(f"--k must be at least 1 (got {k})")
    if 0 < len(photons) < k:
        raise InputError(
            f"--k {k} is more than the {len(photons)} caustic photons that {photons.n_paths} "
            "emitted paths gave; raise --photons or lower --k"
        )


def k_nearest_start(
    points: VisiblePoints, photons: Photons, k: int, watch: Watch
) -> tuple[Stopwatch, PhotonIndex, np.ndarray]:
    """What a K-nearest estimate starts from: its stopwatch, the map's index (k checked
    against its photon count) and the (N, 3) float32 zero radiance of the N points."""
    watch = watch or Stopwatch()
    index = photon_index(photons, watch)
    check_k(k, index.photons)
    return watch, index, np.zeros((len(points), 3), np.float32)


@dataclass(frozen=True)
class PM:
    """Kernel density estimate over the k nearest photons; kernel 'uniform' or 'cone'."""

    name: ClassVar[str] = "pm"
    summary: ClassVar[str] = (
        "photon mapping, uniform kernel over the --k nearest photons (paper Eq. 1)"
    )

    k: int = 50
    kernel: str = "uniform"

    def estimate(self, points: VisiblePoints, photons: Photons, watch: Watch = None) -> np.ndarray:
        """(N, 3) float32 caustic radiance leaving each visible point (0 where not hit);
        stages "gather" and "estimate" (the kernel sums) count on `watch`."""
        if self.kernel not in ("uniform", "cone"):
            raise InputError(f"unknown PM kernel '{self.kernel}'; use uniform or cone")
        watch, index, out = k_nearest_start(points, photons, self.k, watch)
        if len(index) == 0:
            return out
        kernel = KERNELS[self.kernel]
        hit = np.flatnonzero(points.hit)
        with watch("estimate"):
            for rows, nb in index.nearest(points.position[hit], points.normal[hit], self.k, watch):
                r = np.maximum(nb.distance[:, -1:], 1e-30)  # bandwidth: the K-th nearest photon
                weight = np.where(nb.valid, kernel(nb.distance / r) / r**2, 0.0)
                flux = take(index.photons.flux, nb.index).astype(np.float64)
                irradiance = np.einsum("nk,nkc->nc", weight, flux)
                out[hit[rows]] = reflected(points.albedo[hit[rows]], irradiance)
        return out
