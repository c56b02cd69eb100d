"""The caustic estimate in two independent halves, for judging the learned filter at render time.

Each pass of `auto` gathers its own photons at its own visible points into SPPM's per-pixel
statistics (one state at the wide radius, one at the narrow). What a pass added alone, φ_j
photons' flux within radius R_j, is an estimate of its own: φ_j / (π R_j² paths_j). The
passes are independent, so the sums of those estimates over the even passes and over the
odd ones are two independent estimates of the same caustic (at about the same radii), as the
paths' halves are for the denoiser (`Passes.denoiser_share`). The filter applied to one half
and scored against the other tells, without any reference, whether the filter brings that
half closer to the truth: the other half's noise is independent, so it adds the same to
either side of the comparison.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from dpm.estimators.ppm import PPMState


@dataclass
class Snapshot:
    """The per-pixel statistics of SPPM states before a pass's gather (copies)."""

    radius: tuple[np.ndarray, ...]  # (P,) float64 per state
    tau: tuple[np.ndarray, ...]  # (P, 3) float64 per state
    count: tuple[np.ndarray, ...]  # (P,) float64 per state


@dataclass
class PassHalves:
    """Per-pixel sums of each pass's own estimate, apart for even (half 0) and odd (1) passes,
    for each of several SPPM states (kernels: `auto`'s wide and narrow)."""

    flux: np.ndarray  # (2, K, P, 3) float64 Σ φ_j / (π R_j²) over the half's passes (W m⁻²·paths)
    found: np.ndarray  # (2, K, P) float64 photons the half's passes found in the discs
    paths: np.ndarray  # (2,) int64 emitted photon paths of the half's passes
    passes: np.ndarray  # (2,) int64 passes in the half

    @classmethod
    def start(cls, kernels: int, pixels: int) -> PassHalves:
        """Empty sums for `kernels` states of `pixels` pixels."""
        return cls(np.zeros((2, kernels, pixels, 3)), np.zeros((2, kernels, pixels)),
                   np.zeros(2, np.int64), np.zeros(2, np.int64))  # fmt: skip

    @staticmethod
    def snapshot(states: tuple[PPMState, ...]) -> Snapshot:
        """The states' statistics before a gather (`add` takes them back)."""
        return Snapshot(tuple(s.radius.copy() for s in states), tuple(s.tau.copy() for s in states),
                        tuple(s.count.copy() for s in states))  # fmt: skip

    def add(self, half: int, before: Snapshot, states: tuple[PPMState, ...], paths: int) -> None:
        """Add to `half` what one pass of `paths` emitted paths gathered into `states` since
        `before`. PPM's update scales τ by ratio = (R_after / R_before)² after adding the
        pass's flux φ, and grows the count by α·found: both are undone here."""
        for k, s in enumerate(states):
            r0, tau0, n0 = before.radius[k], before.tau[k], before.count[k]
            ratio = (s.radius / r0) ** 2
            phi = np.maximum(s.tau / ratio[:, None] - tau0, 0.0)  # (rounding: never below 0)
            self.flux[half, k] += phi / (np.pi * r0**2)[:, None]
            self.found[half, k] += (s.count - n0) / s.alpha
        self.paths[half] += paths
        self.passes[half] += 1

    def state(self, half: int, k: int, like: PPMState) -> PPMState:
        """A PPM state whose estimate is half `half`'s of kernel `k`, at the radii of `like`
        (the full run's state of that kernel) and its count (α·found, as PPM counts)."""
        paths = max(int(self.paths[half]), 1)
        tau = self.flux[half, k] * (np.pi * like.radius**2)[:, None]
        return PPMState(like.radius, like.alpha * self.found[half, k], tau, paths=paths,
                        passes=int(self.passes[half]), alpha=like.alpha)  # fmt: skip
