"""The PPM reference: two independent half-budget runs, their mean, and their disagreement.

A reference may need billions of photon paths, so it aims emission at the specular surfaces
(`guided`, which changes no expectation), streams passes, and checkpoints each half to its
own file; the halves can run at once as two Ray tasks (`dpm.parallel`: local worker
processes, or a cluster by address, whose tasks need the checkpoint folder on a shared file
system), with the same result as one after the other. Its noise is reported as the RMSE
between the two halves (a comparison whose
differences are below that says nothing). PPM's bias is shared by both halves and does not
show in that figure; the validation test against the path tracer bounds it.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from dpm.density.progressive import pass_seed, run_passes
from dpm.estimators.ppm import PPM
from dpm.metrics import rmse
from dpm.parallel import fan_out
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


def _half(
    scene: Scene, bvh: BVH, points: VisiblePoints, n_paths: int, radius: float,
    photons_per_pass: int, seed: int, checkpoint: Path | None, progress: bool,
) -> tuple[np.ndarray, int, int]:  # fmt: skip
    """One half's (N, 3) radiance, caustic photons and emitted paths (a whole pass counted
    whole when a longer run's checkpoint is resumed)."""
    estimator = PPM(radius=radius, photons_per_pass=photons_per_pass)
    radiance, state = run_passes(
        estimator, scene, bvh, points, n_paths, seed,
        checkpoint=checkpoint, guided=True, progress=progress,
    )  # fmt: skip
    longer = state.passes > -(-n_paths // photons_per_pass)
    return radiance, state.photons, state.passes * photons_per_pass if longer else n_paths


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
    workers: int = 1,
    ray_address: str | None = None,
) -> Reference:
    """Run the two halves of n_paths guided photon paths (resuming from checkpoint_dir), one
    after the other, or at once as Ray tasks when `workers` > 1 or `ray_address` is given."""
    if checkpoint_dir is not None:
        checkpoint_dir.mkdir(parents=True, exist_ok=True)
    jobs = [
        (scene, bvh, points, n_paths // 2, radius, photons_per_pass, pass_seed(seed, half),
         None if checkpoint_dir is None else checkpoint_dir / f"half{half}.npz", progress)
        for half in (1, 2)
    ]  # fmt: skip
    if workers > 1 or ray_address:
        done = dict(fan_out(_half, jobs, ray_address, min(workers, 2)))
        halves = [done[0], done[1]]
    else:
        halves = [_half(*job) for job in jobs]
    (a, photons_a, paths_a), (b, photons_b, paths_b) = halves
    mean = ((a.astype(np.float64) + b) / 2).astype(np.float32)
    noise = caustic_rmse(points, a, b)
    return Reference(mean, (a, b), noise, paths_a + paths_b, photons_a + photons_b)
