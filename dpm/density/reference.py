"""The PPM reference: two independent half-budget runs, their mean, and their disagreement.

A reference may need billions of photon paths, so it aims emission at the specular surfaces
(`guided`, which changes no expectation), streams passes, and checkpoints each half to its
own file. Its noise is reported as the RMSE between the two halves (a comparison whose
differences are below that says nothing). PPM's bias is shared by both halves and does not
show in that figure; the validation test against the path tracer bounds it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpm.density.ppm import PPM
from dpm.density.progressive import pass_seed, run_passes
from dpm.metrics import rmse
from dpm.scene import Scene
from dpm.tracer import BVH, VisiblePoints


@dataclass(frozen=True)
class Reference:
    """Caustic radiance at visible points from two half-budget PPM runs."""

    radiance: np.ndarray  # (N, 3) float32 mean of the halves, leaving each visible point
    halves: tuple[np.ndarray, np.ndarray]  # (N, 3) float32 each half on its own
    noise: float  # RMSE between the halves, camera-weighted like `caustic_rmse`
    n_paths: int  # emitted (guided) photon paths in all
    caustic_photons: int


def caustic_rmse(points: VisiblePoints, estimate: np.ndarray, reference: np.ndarray) -> float:
    """RMSE over the hit visible points of the caustic radiance as the camera sees it."""
    hit = points.hit
    weight = points.throughput[hit]
    return rmse(weight * estimate[hit], weight * reference[hit])


def ppm_reference(
    scene: Scene,
    bvh: BVH,
    points: VisiblePoints,
    n_paths: int,
    radius: float,
    photons_per_pass: int,
    seed: int = 0,
    checkpoint_dir: Path | None = None,
    progress: bool = False,
) -> Reference:
    """Run the two halves of n_paths guided photon paths (resuming from checkpoint_dir)."""
    estimator = PPM(radius=radius, photons_per_pass=photons_per_pass)
    if checkpoint_dir is not None:
        checkpoint_dir.mkdir(parents=True, exist_ok=True)
    halves, photons, paths = [], 0, 0
    for half in (1, 2):
        checkpoint = None if checkpoint_dir is None else checkpoint_dir / f"half{half}.npz"
        radiance, state = run_passes(
            estimator, scene, bvh, points, n_paths // 2, pass_seed(seed, half),
            checkpoint=checkpoint, guided=True, progress=progress,
        )  # fmt: skip
        halves.append(radiance)
        photons += state.photons
        # a checkpoint from a longer run (whole passes) is used whole rather than cut back
        asked = n_paths // 2
        longer = state.passes > -(-asked // photons_per_pass)
        paths += state.passes * photons_per_pass if longer else asked
    a, b = halves
    mean = ((a.astype(np.float64) + b) / 2).astype(np.float32)
    return Reference(mean, (a, b), caustic_rmse(points, a, b), paths, photons)
