"""The caustic estimate in two independent halves, for judging its moves at render time.

Each pass of `auto` gathers its own photons at its own visible points into SPPM's per-pixel
statistics (one state at the wide radius, one at the narrow). What a pass added alone, φ_j
photons' flux within radius R_j, is an estimate of its own: φ_j / (π R_j² paths_j). The
passes are independent, so the sums of those estimates over the even passes and over the
odd ones are two independent estimates of the same caustic (at about the same radii), as the
paths' halves are for the denoiser (`Passes.denoiser_share`). A move of one half (towards
its narrow kernel's estimate, its extrapolated one, or the learned filter's) scored against
the other tells, without any reference, whether it brings that half closer to the truth:
the other half's noise is independent, so it adds the same to either side of the
comparison (`dpm.caustic.blend`).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _add_pass(
    flux: np.ndarray, found: np.ndarray, r0: np.ndarray, tau0: np.ndarray, n0: np.ndarray,
    radius: np.ndarray, tau: np.ndarray, count: np.ndarray, alpha: float,
) -> None:  # fmt: skip
    """flux (P, 3) += φ / (π r0²) and found (P,) += new photons, from a state's radius (P,),
    τ (P, 3) and count (P,) before (r0, tau0, n0) and after a pass (one loop: 0.1 ms a pass
    at 128², where the NumPy form with fresh copies took 1 ms, 2-4 % of a short render's)."""
    keep = 1.0 / alpha
    for i in range(r0.shape[0]):
        unshrink = (r0[i] / radius[i]) ** 2  # 1 / ratio (divisions are what this loop waits on)
        per_area = 1.0 / (np.pi * r0[i] ** 2)
        for c in range(3):
            flux[i, c] += max(tau[i, c] * unshrink - tau0[i, c], 0.0) * per_area  # (rounding)
        found[i] += (count[i] - n0[i]) * keep


@dataclass
class PassHalves:
    """Per-pixel sums of each pass's own estimate, apart for even (half 0) and odd (1) passes,
    for each of several SPPM states (kernels: `auto`'s wide and narrow)."""

    flux: np.ndarray  # (2, K, P, 3) float64 Σ φ_j / (π R_j²) over the half's passes (W m⁻²·paths)
    found: np.ndarray  # (2, K, P) float64 photons the half's passes found in the discs
    paths: np.ndarray  # (2,) int64 emitted photon paths of the half's passes
    passes: np.ndarray  # (2,) int64 passes in the half
    # (2, K, P) float64 Σ R_j² over the half's passes: SPPM's estimate is the mean of its
    # passes' estimates at their radii, so this tells each kernel's blur (`Passes.blur_ratio`)
    radius2: np.ndarray
    # the states' radius R (K, P), τ (K, P, 3) and count (K, P) before the coming gather
    # (`mark`; kept in place: fresh copies each pass cost more than the sums)
    radius: np.ndarray
    tau: np.ndarray
    count: np.ndarray

    @classmethod
    def start(cls, kernels: int, pixels: int) -> PassHalves:
        """Empty sums for `kernels` states of `pixels` pixels."""
        k, p = kernels, pixels
        return cls(np.zeros((2, k, p, 3)), np.zeros((2, k, p)), np.zeros(2, np.int64),
                   np.zeros(2, np.int64), np.zeros((2, k, p)), np.zeros((k, p)),
                   np.zeros((k, p, 3)), np.zeros((k, p)))  # fmt: skip

    def mark(self, states: Sequence[Any]) -> None:
        """Keep the statistics of PPM states (`dpm.estimators.ppm.PPMState`: radius, τ,
        count) before a gather (`add` takes them back)."""
        for k, s in enumerate(states):
            self.radius[k], self.tau[k], self.count[k] = s.radius, s.tau, s.count

    def add(self, half: int, states: Sequence[Any], paths: int) -> None:
        """Add to `half` what one pass of `paths` emitted paths gathered into `states` since
        `mark`. PPM's update scales τ by ratio = (R_after / R_before)² after adding the
        pass's flux φ, and grows the count by α·found: both are undone here."""
        for k, s in enumerate(states):
            _add_pass(self.flux[half, k], self.found[half, k], self.radius[k], self.tau[k],
                      self.count[k], s.radius, s.tau, s.count, s.alpha)  # fmt: skip
            self.radius2[half, k] += self.radius[k] ** 2  # (the radii the pass gathered with)
        self.paths[half] += paths
        self.passes[half] += 1
