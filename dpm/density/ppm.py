"""Progressive photon mapping (Hachisuka, Ogaki & Jensen 2008).

Each visible point keeps a radius R, a photon count N and the flux τ gathered so far. A pass
finding M new photons with flux Φ within R sets N' = N + αM, R'² = R² N'/(N + M) and
τ' = (τ + Φ) R'²/R²; the irradiance is τ / (π R² · emitted paths). Passes are consecutive
slices of one photon stream, so a run can stop after any pass and resume bit-identically.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dpm.density.gather import Photons, PointIndex, Watch
from dpm.density.progressive import ALPHA, Statistics, estimate_in_passes
from dpm.errors import InputError
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap, VisiblePoints


def check_progressive(radius: float, photons_per_pass: int, alpha: float) -> None:
    """Raise InputError for a radius ≤ 0, fewer than 1 photon path per pass or α ∉ (0, 1)."""
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"--radius must be a positive length in scene units (got {radius})")
    if photons_per_pass < 1:
        raise InputError(f"--photons-per-pass must be at least 1 (got {photons_per_pass})")
    if not 0 < alpha < 1:
        raise InputError(f"alpha must lie in (0, 1) (got {alpha})")


@dataclass
class PPMState(Statistics):
    """Per-point statistics of a PPM run over n points after `passes` passes."""

    radius: np.ndarray  # (n,) float64 current radius R (scene units)
    count: np.ndarray  # (n,) float64 accumulated photon count N
    tau: np.ndarray  # (n, 3) float64 accumulated flux τ, per emitted path (W)

    @classmethod
    def start(cls, n: int, radius: float, alpha: float = ALPHA) -> PPMState:
        """A state of n points with initial radius `radius` and nothing gathered."""
        return cls(np.full(n, float(radius)), np.zeros(n), np.zeros((n, 3)), alpha=alpha)

    def add(self, index: PointIndex, photons: PhotonMap, watch: Stopwatch | None = None) -> None:
        """Gather one pass of photons (flux divided by its own n_paths) and shrink the radii."""
        pairs = index.within(photons, self.radius, watch)
        flux = photons.flux[pairs.photon].astype(np.float64) * photons.n_paths
        self.update(pairs.point, flux)
        self.paths += photons.n_paths
        self.passes += 1
        self.photons += len(photons)

    def update(self, point: np.ndarray, flux: np.ndarray) -> None:
        """Count photons (Q,) found at points `point` with per-path flux (Q, 3); shrink radii."""
        n = len(self.radius)
        found = np.bincount(point, minlength=n).astype(np.float64)
        phi = np.stack([np.bincount(point, flux[:, c], minlength=n) for c in range(3)], 1)
        grown = self.count + self.alpha * found
        ratio = np.divide(grown, self.count + found, out=np.ones(n), where=found > 0)
        self.radius = self.radius * np.sqrt(ratio)
        self.tau = (self.tau + phi) * ratio[:, None]
        self.count = grown

    def irradiance(self) -> np.ndarray:
        """(n, 3) float64 caustic irradiance E = τ / (π R² paths) (W m⁻²)."""
        return self.tau / (np.pi * self.radius[:, None] ** 2 * max(self.paths, 1))


@dataclass(frozen=True)
class Progressive:
    """Parameters of a progressive estimator at fixed visible points: initial radius (scene
    units), emitted photon paths per pass, α; subclasses say which statistics they keep."""

    radius: float = 0.01
    photons_per_pass: int = 10_000
    alpha: float = ALPHA

    def check(self) -> None:
        """Raise InputError for unusable parameters."""
        check_progressive(self.radius, self.photons_per_pass, self.alpha)

    def estimate(self, points: VisiblePoints, photons: Photons, watch: Watch = None) -> np.ndarray:
        """(N, 3) float32 caustic radiance leaving each visible point, passes of the map;
        stages "gather" and "estimate" count on `watch`."""
        return estimate_in_passes(self, points, photons, watch)


@dataclass(frozen=True)
class PPM(Progressive):
    """PPM at fixed visible points: initial radius (scene units), emitted paths per pass."""

    def start(self, n: int) -> PPMState:
        """The state before the first pass, for n points."""
        return PPMState.start(n, self.radius, self.alpha)
