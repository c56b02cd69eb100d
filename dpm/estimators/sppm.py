"""Stochastic progressive photon mapping (Hachisuka & Jensen 2009), per pixel: the estimator.

Unlike the estimators at fixed visible points, SPPM traces new visible points every pass
(one jittered camera sample per pixel, Fresnel-sampled through glass) and keeps PPM's
statistics per pixel, so pixels seen through glass or partly covered average over their
whole footprint. The flux a pixel gathers is weighted by its camera throughput and ρ/π, so
the result is the caustic radiance as the camera sees it.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from functools import partial
from typing import ClassVar

import numpy as np
from tqdm import tqdm

from dpm.camera import Camera
from dpm.density.gather import PointIndex
from dpm.density.held_out import HeldOutState
from dpm.density.progressive import pass_seed
from dpm.density.radius import initial_radii
from dpm.estimators.ppm import ALPHA, PPM, PPMState, check_progressive
from dpm.scene import Scene
from dpm.stopwatch import Stopwatch
from dpm.tracer import BVH, PhotonMap, VisiblePoints, trace_photons, trace_visible_points
from dpm.tracer.photon_grid import disc_sums

# Default emitted photon paths per pass per pixel. Each pass also traces one camera sample per
# pixel, and a pixel's estimate averages its footprint only over the passes: ten passes (the
# fixed-point methods' default) left sppm at 1.26-1.92x its own best at M paths on the
# examples, whose best settings almost all ran 1000 passes. Fewer paths per pass is better at
# equal paths and slower (the seven examples at M, default / own best: 0.1 per pixel 1.09,
# 0.25 1.16, 0.5 1.20, 1 1.28, 4 1.47; the egg at 128x128 took 10.9, 5.0 and 2.0 s at 0.1,
# 0.25 and 1): 0.25 spends on camera samples four times what it spends on photon paths.
# `benchmarks/sppm_defaults.py`.
PATHS_PER_PIXEL = 0.25
# A pass with at least this many photons per visible point sums them point by point
# (`disc_sums`: no pair stored); fewer, photon by photon through the stored pairs (`sppm`'s
# held-out halves of 2,000 photons against 16k points: the pairs 1.4x faster in all; `auto`'s
# passes of 2-4 photons per point: the point walk 2-4x faster; glass lantern, 128²).
POINT_SIDE_PHOTONS = 0.25
MAX_PASSES = 1000  # beyond it, passes grow longer instead (a tiny image would want thousands)


def default_paths_per_pass(n_paths: int, pixels: int) -> int:
    """Emitted paths per pass of an sppm run of n_paths over `pixels` pixels by default:
    PATHS_PER_PIXEL per pixel, but at most MAX_PASSES passes, at least 1 path, at most the
    run."""
    per_pass = max(round(PATHS_PER_PIXEL * pixels), -(-n_paths // MAX_PASSES), 1)
    return min(n_paths, per_pass) if n_paths >= 1 else 1


def sppm_caustics(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    n_paths: int,
    seed: int,
    radius: float | None,
    photons_per_pass: int,
    alpha: float = ALPHA,
    progress: bool = False,
    watch: Stopwatch | None = None,
) -> tuple[np.ndarray, int]:
    """((H, W, 3) float32 caustic radiance per pixel as the camera sees it, caustic photons)
    from n_paths emitted photon paths in passes of photons_per_pass from the initial radius
    (scene units; None: each pixel's from its first visible point, `pixel_radii`); stages
    "visible_points", "photons", "gather" and "estimate" count on watch."""
    images, photons = sppm_caustics_at_radii(
        scene, bvh, camera, n_paths, seed, (radius,), photons_per_pass, alpha, progress, watch
    )  # fmt: skip
    return images[0], photons


def sppm_caustics_at_radii(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    n_paths: int,
    seed: int,
    radii: Sequence[float | None],
    photons_per_pass: int,
    alpha: float = ALPHA,
    progress: bool = False,
    watch: Stopwatch | None = None,
    stream: PhotonMap | None = None,
) -> tuple[list[np.ndarray], int]:
    """`sppm_caustics` from each initial radius of `radii` at once ((H, W, 3) float32 images
    in that order, and the caustic photons): the runs share every pass's camera samples,
    photons and one photon search (a default radius, None, runs the held-out choice of
    scale, `dpm.density.held_out`, whose halves search apart). `stream`: the caustic photons
    of those n_paths paths, traced before (a benchmark sweeping settings over one stream),
    whose consecutive slices are the passes a run would trace."""
    for radius in radii:
        check_progressive(radius or 1.0, photons_per_pass, alpha)
    if stream is not None and stream.n_paths != n_paths:
        raise ValueError(f"the stream holds {stream.n_paths} paths, not {n_paths}")
    watch = watch or Stopwatch()
    pixels = camera.width * camera.height
    states = [PPMState.start(pixels, r or 1.0, alpha) for r in radii]
    # a default (None) radius: the held-out choice among scales of each pixel's own
    held_out: HeldOutState | None = None
    n_passes = -(-n_paths // photons_per_pass)
    passes = None if stream is None else stream.split(photons_per_pass)
    for j in tqdm(range(n_passes), unit="pass", disable=not progress, desc="sppm"):
        with watch("visible_points"):
            points = trace_visible_points(
                scene, bvh, camera, 1, pass_seed(seed, j), (0, camera.height)
            )
        with watch("photons"):
            photons = (
                passes[j] if passes is not None
                else trace_photons(
                    scene, bvh, min(photons_per_pass, n_paths - j * photons_per_pass), seed,
                    caustic_only=True, first_path=j * photons_per_pass,
                )
            )  # fmt: skip
        if j == 0 and None in radii:
            with watch("estimate"):
                own = pixel_radii(points, photons)
            held_out = HeldOutState(partial(PPMState.start, alpha=alpha), pixels, own)
            # each pixel's first visible point places it for the pruning's blocks (a pixel
            # that sees no diffuse surface gets no photon, whatever its block)
            held_out.position = np.where(points.hit[:, None], points.position, np.nan)
        plain = [s for s, r in zip(states, radii, strict=True) if r is not None]
        if plain:
            sppm_gather(plain, points, photons, watch)
        if held_out is not None:  # each half gathers with its own paths' photons
            held_out.add_pass(
                lambda h, run, part, p=points: sppm_gather(run, p, part, watch), photons
            )
    # already weighted by throughput · ρ/π: radiance
    final = [
        s if r is not None or held_out is None else held_out
        for s, r in zip(states, radii, strict=True)
    ]
    images = [
        s.irradiance().reshape(camera.height, camera.width, 3).astype(np.float32) for s in final
    ]
    return images, final[0].photons


def pixel_radii(points: VisiblePoints, photons: PhotonMap) -> np.ndarray:
    """(P,) float64 initial radius per pixel from its first pass's visible point (one per
    pixel) and photons (`dpm.density.radius.initial_radii`); pixels that saw no diffuse
    surface take the median."""
    hit = np.flatnonzero(points.hit)
    footprint = None if points.footprint is None else points.footprint[hit]
    found = initial_radii(points.position[hit], points.normal[hit], footprint, photons)
    fill = float(np.median(found)) if len(found) else 1.0
    radius = np.full(len(points), fill)
    radius[hit] = found
    return radius


def sppm_gather(
    states: Sequence[PPMState],
    points: VisiblePoints,
    photons: PhotonMap,
    watch: Stopwatch,
) -> None:
    """Gather one pass of photons into per-pixel PPM statistics at this pass's visible
    points (one sample per pixel, in pixel order), into each of `states` (radii of their
    own; one search at the largest); stages "gather" (the search) and "estimate" (the
    statistics) count on watch."""
    hit = np.flatnonzero(points.hit)  # one sample per pixel: row = pixel
    weight = points.throughput[hit].astype(np.float64) * points.albedo[hit] / np.pi
    weight *= photons.n_paths
    if len(photons) >= POINT_SIDE_PHOTONS * len(hit):
        with watch("gather"):  # point by point, in Numba, no pair stored
            radii = np.stack([s.radius[hit] for s in states])
            found, flux = disc_sums(photons, points.position[hit], points.normal[hit], radii)
        with watch("estimate"):
            per_pixel, phi = np.zeros(len(points)), np.zeros((len(points), 3))
            for k, state in enumerate(states):
                per_pixel[hit], phi[hit] = found[k], flux[k] * weight
                state.add_sums(per_pixel, phi)  # PPM's statistics, per pixel
    else:  # photon by photon, through the pairs within the widest radius
        index = PointIndex(points.position[hit], points.normal[hit])
        pairs = index.within(photons, np.max([s.radius[hit] for s in states], axis=0), watch)
        with watch("estimate"):
            flux = photons.flux[pairs.photon].astype(np.float64) * weight[pairs.point, :]
            for state in states:
                inside = pairs.distance < state.radius[hit[pairs.point]]
                state.update(hit[pairs.point[inside]], flux[inside])
    for state in states:
        state.paths += photons.n_paths
        state.passes += 1
        state.photons += len(photons)


@dataclass(frozen=True)
class SPPM(PPM):
    """SPPM: initial radius (scene units; None: each pixel's own), emitted paths per pass.

    `estimate_pixels` is SPPM proper: new camera samples every pass, statistics per pixel.
    At visible points fixed by the caller there is nothing to resample, and SPPM is PPM
    (Hachisuka & Jensen 2009): `estimate` is PPM's.
    """

    name: ClassVar[str] = "sppm"
    summary: ClassVar[str] = "stochastic PPM: new camera samples every pass, statistics per pixel"

    def estimate_pixels(
        self,
        scene: Scene,
        bvh: BVH,
        camera: Camera,
        n_paths: int,
        seed: int,
        progress: bool = False,
        watch: Stopwatch | None = None,
    ) -> tuple[np.ndarray, int]:
        """((H, W, 3) float32 caustic radiance per pixel as the camera sees it, caustic
        photons) from n_paths emitted photon paths (`sppm_caustics`)."""
        return sppm_caustics(
            scene, bvh, camera, n_paths, seed, self.radius, self.photons_per_pass, self.alpha,
            progress, watch,
        )  # fmt: skip
