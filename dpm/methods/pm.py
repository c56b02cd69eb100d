"""`pm`: photon mapping (Jensen 1996), the K nearest photons under a uniform kernel (Eq. 1)."""

from __future__ import annotations

from dpm.density.pm import PM
from dpm.methods.base import NearestPhotons


class PhotonMapping(NearestPhotons):
    """PM-K at the visible points."""

    name = "pm"
    summary = "photon mapping, uniform kernel over the --k nearest photons (paper Eq. 1)"
    estimator_class = PM
