"""What photon density estimators are built from: gathering (cKDTree), kernels, the
per-point statistics of a progressive run, view-relative radii and the estimator interface.

The estimators themselves are in `dpm.estimators`.
"""

from __future__ import annotations

from dpm.density.base import Estimator
from dpm.density.gather import PhotonIndex, PointIndex

__all__ = ["Estimator", "PhotonIndex", "PointIndex"]
