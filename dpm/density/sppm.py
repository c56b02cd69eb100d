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
from dpm.density.ppm import ALPHA, PPMState, check_progressive
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
        state = PPMState.start(camera.width * camera.height, self.radius, self.alpha)
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
                photons, state.radius[hit]
            )
            pixel = hit[pairs.point]
            weight = points.throughput[pixel].astype(np.float64) * points.albedo[pixel] / np.pi
            flux = photons.flux[pairs.photon].astype(np.float64) * photons.n_paths * weight
            state.update(pixel, flux)  # PPM's statistics, per pixel
            state.paths += photons.n_paths
        image = state.irradiance()  # already weighted by throughput · ρ/π: radiance
        return image.reshape(camera.height, camera.width, 3).astype(np.float32), n_photons
