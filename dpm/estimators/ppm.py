"""Progressive photon mapping (Hachisuka, Ogaki & Jensen 2008).

Each visible point keeps a radius R, a photon count N and the flux τ gathered so far. A pass
finding M new photons with flux Φ within R sets N' = N + αM, R'² = R² N'/(N + M) and
τ' = (τ + Φ) R'²/R²; the irradiance is τ / (π R² · emitted paths). Passes are consecutive
slices of one photon stream, so a run can stop after any pass and resume bit-identically.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any, ClassVar

import numpy as np

from dpm.density.gather import Photons, PointIndex, Watch
from dpm.density.held_out import HeldOutState
from dpm.density.progressive import ALPHA, Statistics, estimate_in_passes
from dpm.density.radius import initial_radii
from dpm.errors import InputError
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap, VisiblePoints

Radius = float | np.ndarray  # one initial radius (scene units), or (n,) per point
Footprint = np.ndarray | None  # (n,) pixel width at each point (scene units), or unknown


def check_progressive(radius: float, photons_per_pass: int, alpha: float) -> None:
    """Raise InputError for a radius ≤ 0, fewer than 1 photon path per pass or α ∉ (0, 1)."""
    if not (np.isfinite(radius) and radius > 0):
        raise InputError(f"--radius must be a positive length in scene units (got {radius})")
    if photons_per_pass < 1:
        raise InputError(f"--photons-per-pass must be at least 1 (got {photons_per_pass})")
    if not 0 < alpha < 1:
        raise InputError(f"alpha must lie in (0, 1) (got {alpha})")


def start_radius(n: int, radius: float | np.ndarray) -> np.ndarray:
    """(n,) float64 initial radii from one radius or (n,) per point (a fresh copy)."""
    return np.broadcast_to(np.asarray(radius, np.float64), (n,)).copy()


@dataclass
class PPMState(Statistics):
    """Per-point statistics of a PPM run over n points after `passes` passes."""

    radius: np.ndarray  # (n,) float64 current radius R (scene units)
    count: np.ndarray  # (n,) float64 accumulated photon count N
    tau: np.ndarray  # (n, 3) float64 accumulated flux τ, per emitted path (W)

    @classmethod
    def start(cls, n: int, radius: float | np.ndarray, alpha: float = ALPHA) -> PPMState:
        """A state of n points with initial radius `radius` (one, or (n,) per point) and
        nothing gathered."""
        return cls(start_radius(n, radius), np.zeros(n), np.zeros((n, 3)), alpha=alpha)

    # PPM's statistics are counts and summed flux, which `disc_sums` gives point by point
    # without storing pairs (`add_found`); subclasses that read the pairs themselves say False.
    SUMS: ClassVar[bool] = True

    def add(self, index: PointIndex, photons: PhotonMap, watch: Stopwatch | None = None) -> None:
        """Gather one pass of photons (flux divided by its own n_paths) and shrink the radii."""
        pairs = index.within(photons, self.radius, watch)
        flux = photons.flux[pairs.photon].astype(np.float64) * photons.n_paths
        self.update(pairs.point, flux)
        self.count_pass(photons)

    def add_found(self, found: np.ndarray, flux: np.ndarray, photons: PhotonMap) -> None:
        """Take one pass as per-point sums within the radii: photons found (n,) and their
        summed flux (n, 3) (W, as stored: `disc_sums`); shrink the radii."""
        self.add_sums(found, flux * photons.n_paths)
        self.count_pass(photons)

    def count_pass(self, photons: PhotonMap) -> None:
        """Count one pass of photons in the run's counters."""
        self.paths += photons.n_paths
        self.passes += 1
        self.photons += len(photons)

    def update(self, point: np.ndarray, flux: np.ndarray) -> None:
        """Count photons (Q,) found at points `point` with per-path flux (Q, 3); shrink radii."""
        n = len(self.radius)
        found = np.bincount(point, minlength=n).astype(np.float64)
        phi = np.stack([np.bincount(point, flux[:, c], minlength=n) for c in range(3)], 1)
        self.add_sums(found, phi)

    def add_sums(self, found: np.ndarray, phi: np.ndarray) -> None:
        """Count a pass's photons found (n,) at each point, with summed per-path flux (n, 3);
        shrink radii."""
        n = len(self.radius)
        grown = self.count + self.alpha * found
        ratio = np.divide(grown, self.count + found, out=np.ones(n), where=found > 0)
        self.radius = self.radius * np.sqrt(ratio)
        self.tau = (self.tau + phi) * ratio[:, None]
        self.count = grown

    @property
    def reach(self) -> np.ndarray:
        """(n,) float64 radius within which the next pass is gathered (scene units)."""
        return self.radius

    def irradiance(self) -> np.ndarray:
        """(n, 3) float64 caustic irradiance E = τ / (π R² paths) (W m⁻²)."""
        return self.tau / (np.pi * self.radius[:, None] ** 2 * max(self.paths, 1))


@dataclass(frozen=True)
class Progressive:
    """Parameters of a progressive estimator at fixed visible points: initial radius (scene
    units; None: each point's own from the first pass, `dpm.density.radius`), emitted photon
    paths per pass, α; subclasses say which statistics they keep (`start`)."""

    radius: float | None = None
    photons_per_pass: int = 10_000
    alpha: float = ALPHA
    # the default initial radius, in units of `initial_radii`'s (chosen on the examples)
    scale: ClassVar[float] = 1.0

    def check(self) -> None:
        """Raise InputError for unusable parameters."""
        check_progressive(
            1.0 if self.radius is None else self.radius, self.photons_per_pass, self.alpha
        )

    def initial_radius(self, index: PointIndex, footprint: Footprint, first: PhotonMap) -> Radius:
        """The initial radius: the one given, or (n,) float64 per point of `index` from the
        first pass's photons and the points' pixel footprints (n,) (None: unknown)."""
        if self.radius is not None:
            return self.radius
        return initial_radii(index.position, index.normal, footprint, first, self.scale)

    def state(self, n: int, radius: Radius) -> Any:
        """The run's state for n points at initial radius `radius`: the method's own (`start`)
        when a radius was given, else its held-out choice among scales of `radius`
        (`dpm.density.held_out`)."""
        if self.radius is None:
            return HeldOutState(self.start, n, radius)
        return self.start(n, radius)

    def estimate(self, points: VisiblePoints, photons: Photons, watch: Watch = None) -> np.ndarray:
        """(N, 3) float32 caustic radiance leaving each visible point, passes of the map;
        stages "gather" and "estimate" count on `watch`."""
        return estimate_in_passes(self, points, photons, watch)


@dataclass(frozen=True)
class PPM(Progressive):
    """PPM at fixed visible points: initial radius (scene units), emitted paths per pass."""

    name: ClassVar[str] = "ppm"
    summary: ClassVar[str] = (
        "progressive photon mapping (per-point radius, count and flux; α = 0.7)"
    )

    def start(self, n: int, radius: Radius) -> PPMState:
        """The state before the first pass, for n points with initial radius `radius`."""
        return PPMState.start(n, radius, self.alpha)
