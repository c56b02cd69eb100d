"""Photon density estimation: gathering and the classic estimators behind one interface.

Every estimator is built from its parameters and answers
`estimate(points, photons) -> (N, 3) caustic radiance at the visible points`:

>>> from dpm.density import make_estimator
>>> radiance = make_estimator("ppm", radius=0.02, photons_per_pass=50_000).estimate(pts, pm)

SPPM, which traces new visible points every pass, renders per pixel instead (`SPPM.render`).
"""

from __future__ import annotations

from typing import Any

from dpm.density.appm import APPM
from dpm.density.base import Estimator
from dpm.density.pm import PM
from dpm.density.ppm import PPM
from dpm.density.sppm import SPPM

ESTIMATORS: dict[str, type] = {"pm": PM, "ppm": PPM, "appm": APPM}

__all__ = ["APPM", "ESTIMATORS", "PM", "PPM", "SPPM", "Estimator", "make_estimator"]


def make_estimator(method: str, **params: Any) -> Estimator:
    """The estimator called `method` ('pm', 'ppm', 'appm' or 'dpm') with its parameters."""
    if method == "dpm":
        from dpm.nn.estimator import DPM  # imports JAX: only when asked for

        return DPM(**params)
    if method not in ESTIMATORS:
        raise ValueError(f"unknown estimator '{method}'; one of {sorted(ESTIMATORS)} or 'dpm'")
    return ESTIMATORS[method](**params)
