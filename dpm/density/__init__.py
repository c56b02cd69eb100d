"""Photon density estimation: gathering and the classic estimators behind one interface.

Every estimator is built from its parameters and answers
`estimate(points, photons, watch=None) -> (N, 3) caustic radiance at the visible points`,
where `photons` is a PhotonMap or, to share one tree among many calls, a `PhotonIndex`:

>>> from dpm.density import PPM, PhotonIndex
>>> radiance = PPM(radius=0.02, photons_per_pass=50_000).estimate(pts, PhotonIndex(pm))

The methods that `dpm-render` runs, and their name -> estimator table, are in `dpm.methods`.
"""

from __future__ import annotations

from dpm.density.appm import APPM
from dpm.density.base import Estimator
from dpm.density.gather import PhotonIndex
from dpm.density.pm import PM
from dpm.density.ppm import PPM

__all__ = ["APPM", "PM", "PPM", "Estimator", "PhotonIndex"]
