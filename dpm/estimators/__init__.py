"""Every photon density estimator, classic or learned, behind one interface.

Each is a frozen dataclass built from its parameters (scikit-learn style) that answers
`estimate(points, photons, watch=None) -> (N, 3) caustic radiance at the visible points`,
where `photons` is a PhotonMap or, to share one tree among many calls, a `PhotonIndex`; its
class attributes `name` and `summary` name and describe it, `options` lists the render
options it reads beyond its shape's (K or radius and paths per pass):

>>> from dpm.density import PhotonIndex
>>> from dpm.estimators import PPM
>>> radiance = PPM(radius=0.02, photons_per_pass=50_000).estimate(pts, PhotonIndex(pm))

Estimators over the K nearest photons: PM (Jensen 1996) and DPM (the paper). Progressive ones
(subclasses of `Progressive`, radius shrinking pass by pass): PPM, SPPM (which also renders a
caustic image of its own, `estimate_pixels`), APPM, CPPM and nppm. `dpm.methods` makes each a
render method; adding one is a file here and one line in `ESTIMATORS`.
"""

from __future__ import annotations

from dpm.estimators.appm import APPM
from dpm.estimators.cppm import CPPM
from dpm.estimators.dpm import DPM
from dpm.estimators.nppm import NPPM
from dpm.estimators.pm import PM
from dpm.estimators.ppm import PPM, Progressive
from dpm.estimators.sppm import SPPM

ESTIMATORS: tuple[type, ...] = (PM, PPM, SPPM, APPM, CPPM, DPM, NPPM)

__all__ = ["APPM", "CPPM", "DPM", "ESTIMATORS", "NPPM", "PM", "PPM", "SPPM", "Progressive"]
