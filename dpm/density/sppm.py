"""Stochastic progressive photon mapping (Hachisuka & Jensen 2009), per pixel.

Unlike the estimators at fixed visible points, SPPM traces new visible points every pass
(one jittered camera sample per pixel, Fresnel-sampled through glass) and keeps PPM's
statistics per pixel, so pixels seen through glass or partly covered average over their
whole footprint. The flux a pixel gathers is weighted by its camera throughput and ρ/π, so
the result is the caustic radiance as the camera sees it.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from tqdm import tqdm

from dpm.camera import Camera
from dpm.density.gather import PointIndex
from dpm.density.ppm import ALPHA, check_progressive
from dpm.scene import Scene
from dpm.tracer import BVH, trace_photons, trace_visible_points


def pass_seed(seed: int, j: int) -> int:
    """The camera-sample seed of pass j: independent of every other pass's."""
    return int(np.random.SeedSequence([seed, j]).generate_state(1)[0])


@dataclass(frozen=True)
class SPPM:
    """SPPM parameters: initial radius (scene units), emitted photon paths per pass."""

    radius: float = 0.01
    photons_per_pass: int = 10_000
    alpha: float = ALPHA

    def render(
        self,
        scene: Scene,
        bvh: BVH,
        camera: Camera,
        n_paths: int,
        seed: int,
        progress: bool = False,
    ) -> tuple[np.ndarray, int]:
        """((H, W, 3) float32 caustic radiance per pixel as the camera sees it, caustic photons)
        from n_paths emitted photon paths."""
        check_progressive(self.radius, self.photons_per_pass, self.alpha)
        n = camera.width * camera.height
        radius, count, tau = np.full(n, float(self.radius)), np.zeros(n), np.zeros((n, 3))
        per_pass = self.photons_per_pass
        n_passes = -(-n_paths // per_pass)
        n_photons = 0
        for j in tqdm(range(n_passes), unit="pass", disable=not progress, desc="sppm"):
            points = trace_visible_points(
                scene, bvh, camera, 1, pass_seed(seed, j), (0, camera.height)
            )
            photons = trace_photons(
                scene, bvh, min(per_pass, n_paths - j * per_pass), seed,
                caustic_only=True, first_path=j * per_pass,
            )  # fmt: skip
            n_photons += len(photons)
            hit = np.flatnonzero(points.hit)  # one sample per pixel: row = pixel
            pairs = PointIndex(points.position[hit], points.normal[hit]).within(
                photons, radius[hit]
            )
            pixel = hit[pairs.point]
            weight = points.throughput[pixel].astype(np.float64) * points.albedo[pixel] / np.pi
            flux = photons.flux[pairs.photon].astype(np.float64) * photons.n_paths * weight
            found = np.bincount(pixel, minlength=n).astype(np.float64)
            phi = np.stack([np.bincount(pixel, flux[:, c], minlength=n) for c in range(3)], 1)
            grown = count + self.alpha * found
            ratio = np.divide(grown, count + found, out=np.ones(n), where=found > 0)
            radius = radius * np.sqrt(ratio)
            tau = (tau + phi) * ratio[:, None]
            count = grown
        image = tau / (np.pi * radius[:, None] ** 2 * max(n_paths, 1))
        return image.reshape(camera.height, camera.width, 3).astype(np.float32), n_photons
