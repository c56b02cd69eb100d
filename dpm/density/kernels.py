"""Radial density kernels on the unit disc: K(u) for u = distance / bandwidth in [0, 1];
zero outside.

Each integrates to 1 over the unit disc, so a density estimate is Σ wᵢ K(dᵢ / r) / r².
"""

from __future__ import annotations

import numpy as np


def uniform(u: np.ndarray) -> np.ndarray:
    """(…) float64 uniform kernel 1/π inside the unit disc (paper Eq. 1)."""
    return np.where(u <= 1, 1 / np.pi, 0.0)


def cone(u: np.ndarray) -> np.ndarray:
    """(…) float64 cone kernel 3/π · (1 − u) (Jensen 1996 with k = 1)."""
    return np.where(u <= 1, 3 / np.pi * (1 - u), 0.0)


def biweight(u: np.ndarray) -> np.ndarray:
    """(…) float64 biweight kernel 3/π · (1 − u²)², smooth at the rim (APPM)."""
    return np.where(u <= 1, 3 / np.pi * (1 - u * u) ** 2, 0.0)


def biweight_laplacian(u: np.ndarray) -> np.ndarray:
    """(…) float64 Laplacian of the biweight kernel in 2D, −24/π · (1 − 2u²)."""
    return np.where(u <= 1, -24 / np.pi * (1 - 2 * u * u), 0.0)


# ∫K² and the second moment ∫x²K of the biweight kernel: they set APPM's optimal bandwidth.
BIWEIGHT_ROUGHNESS = 9 / (5 * np.pi)
BIWEIGHT_MOMENT = 1 / 8

KERNELS = {"uniform": uniform, "cone": cone, "biweight": biweight}
