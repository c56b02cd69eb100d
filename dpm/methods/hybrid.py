"""`hybrid` (paper §5): path tracing without caustics, DPM caustics at one sample per pixel
(the network costs far more than a path sample), then Open Image Denoise."""

from __future__ import annotations

from dpm.estimators.dpm import DPM
from dpm.methods.base import estimator_method


class Hybrid(estimator_method(DPM)):
    """pt-nocaustic + DPM caustics at 1 spp + OIDN."""

    name = "hybrid"
    summary = "pt-nocaustic + dpm caustics at one sample per pixel + Open Image Denoise"
    denoise = True
    caustic_spp = 1
