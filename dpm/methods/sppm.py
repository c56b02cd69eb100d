"""`sppm`: stochastic progressive photon mapping as a render method, a caustic image per pixel.

Unlike the methods at fixed visible points, SPPM traces new visible points every pass, so it
renders its own caustic image (`dpm.estimators.sppm`), which the render adds to the path-traced
rest.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from dpm.camera import Camera
from dpm.errors import InputError
from dpm.estimators.sppm import SPPM, default_paths_per_pass
from dpm.methods.base import Progressive
from dpm.options import RenderOptions
from dpm.stopwatch import Stopwatch
from dpm.tracer import BVH


class StochasticPPM(Progressive):
    """SPPM: the caustic image per pixel, from its own camera samples every pass."""

    name = SPPM.name
    summary = SPPM.summary
    estimator_class = SPPM
    options = frozenset({"radius", "photons_per_pass"})
    at_points = False
    all_points = False
    pixels: int | None = None  # the image's, once `prepare` knows the camera

    @classmethod
    def check(cls, options: RenderOptions) -> None:
        """Progressive's checks; a caustic-only image has no guides to denoise with."""
        super().check(options)
        if options.component == "caustic" and cls.denoises(options):
            raise InputError(
                "sppm's caustic component has no albedo and normal images to denoise with"
            )

    def photons_per_pass(self) -> int:
        """Emitted paths per pass: --photons-per-pass, or from the pixel count
        (`default_paths_per_pass`), known once `prepare` has the camera."""
        if self.options.photons_per_pass:
            return self.options.photons_per_pass
        if self.pixels is None:
            raise RuntimeError("sppm's paths per pass depend on the camera: call prepare first")
        return default_paths_per_pass(self.options.photons, self.pixels)

    def prepare(self, bvh: BVH, camera: Camera, watch: Stopwatch) -> None:
        """Render the caustic image, pass by pass."""
        o = self.options
        self.pixels = camera.width * camera.height
        self.est = self.estimator()
        self.image, self.caustic_photons = self.est.estimate_pixels(
            self.scene, bvh, camera, o.photons, o.seed, progress=o.progress, watch=watch
        )

    def caustic_pixels(self) -> np.ndarray:
        """(H, W, 3) float32 caustic radiance per pixel as the camera sees it."""
        return self.image

    def stats(self) -> dict[str, Any]:
        """Emitted paths, caustic photons, initial radius and paths per pass."""
        return {
            "photon_paths": self.options.photons, "caustic_photons": self.caustic_photons,
            "caustic_spp": self.caustic_samples(self.options), "radius": self.est.radius,
            "photons_per_pass": self.est.photons_per_pass,
        }  # fmt: skip
