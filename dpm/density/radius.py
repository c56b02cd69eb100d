"""View-relative initial radii of the progressive estimators.

A kernel estimate's error balances noise (few photons in a small disc) against blur (a wide
disc smears what varies inside it): its best radius grows with the distance r_k to the k-th
nearest photon, but only as r_k^(1/3) (asymptotically r ∝ N^(-1/6), while r_k ∝ N^(-1/2)),
times a length over which the caustic varies. The length taken here is the pixel's footprint
at the point (what the camera can show): each point starts at
    SHAPE · r_k^(1/3) · footprint^(2/3),   at most FOOTPRINTS footprints,
with r_k its NEAREST-th photon in the first pass (inf where there are fewer: the cap). So a
denser caustic or a finer image gets a smaller disc, and nothing reads the scene's bounding
box: geometry out of view changes no radius. Points not seen through a camera (no
footprint) take r_k itself. Constants chosen on the example scenes
(`benchmarks/radius_defaults.py`), reported on the unseen scenes too. A method given no radius
runs a ladder of scales of this start and keeps one by held-out error
(`dpm.density.held_out`).
"""

from __future__ import annotations

import numpy as np

from dpm.density.gather import PhotonIndex
from dpm.tracer import PhotonMap

NEAREST = 8  # the photon of the first pass whose distance measures the density
SHAPE = 1.0  # the radius in units of r_k^(1/3) · footprint^(2/3)
FOOTPRINTS = 4.0  # the largest initial radius, in pixel widths at the point


def nearest_distance(
    position: np.ndarray, normal: np.ndarray, photons: PhotonMap, k: int
) -> np.ndarray:
    """(N,) float64 distance from each point (N, 3) to its k-th nearest photon whose normal
    agrees with the point's (N, 3); inf where fewer than k are found."""
    out = np.full(len(position), np.inf)
    if len(photons) == 0 or len(position) == 0:
        return out
    ask = min(2 * k, len(photons))  # room for neighbours on surfaces facing elsewhere
    for rows, near in PhotonIndex(photons).nearest(position, normal, ask):
        distance = np.where(near.valid, near.distance, np.inf)
        out[rows] = np.partition(distance, k - 1, axis=1)[:, k - 1] if ask >= k else np.inf
    return out


def initial_radii(
    position: np.ndarray,
    normal: np.ndarray,
    footprint: np.ndarray | None,
    photons: PhotonMap,
    shape: float = SHAPE,
) -> np.ndarray:
    """(N,) float64 initial radius (scene units) of points (N, 3) with normals (N, 3) and
    pixel footprints (N,) (None: not seen through a camera), from a first pass of photons
    (see the module's docstring). Without a footprint, points with too few photons take the
    largest radius found (or 1 if none)."""
    radius = nearest_distance(position, normal, photons, NEAREST)
    if footprint is not None:
        width = np.asarray(footprint, np.float64)
        blend = shape * np.cbrt(radius) * np.cbrt(width) ** 2
        radius = np.where(width > 0, np.minimum(blend, FOOTPRINTS * width), radius)
    finite = np.isfinite(radius) & (radius > 0)
    fill = float(radius[finite].max()) if finite.any() else 1.0
    return np.where(finite, radius, fill)
