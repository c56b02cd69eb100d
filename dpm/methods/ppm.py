"""`ppm`: progressive photon mapping (Hachisuka et al. 2008) at the render's visible points."""

from __future__ import annotations

from dpm.density.ppm import PPM
from dpm.methods.base import Progressive


class ProgressivePhotonMapping(Progressive):
    """PPM: per-point radius, count and flux, α = 0.7, passes of --photons-per-pass paths."""

    name = "ppm"
    summary = "progressive photon mapping (per-point radius, count and flux; α = 0.7)"
    estimator_class = PPM
