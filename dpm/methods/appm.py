"""`appm`: adaptive progressive photon mapping (after Kaplanyan & Dachsbacher 2013)."""

from __future__ import annotations

from dpm.density.appm import APPM
from dpm.methods.base import Progressive


class AdaptivePPM(Progressive):
    """APPM: each point picks its next-pass bandwidth from its estimated density Laplacian."""

    name = "appm"
    summary = "adaptive PPM: each point's bandwidth from its estimated density Laplacian"
    estimator_class = APPM
