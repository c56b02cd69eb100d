"""View-relative initial radii of the progressive estimators.

A kernel estimate's error balances noise (few photons in a small disc) against blur (a wide
disc smears what varies inside it), and the balance depends on a length the renderer cannot
know beforehand: how fast the caustic varies. Points seen through a camera start at a
multiple of their pixel footprint (what the camera can show), and that multiple is measured
on the first pass's photons by a held-out test (`pilot_footprints`):
- the pass's photon paths are split in two halves A and B (even and odd path index);
- each visible point estimates its irradiance from A at each candidate radius c · footprint,
  and from B at a narrow radius (almost unbiased, noisy);
- the mean squared difference between the two is, up to a constant (B's variance), the
  squared error of A's estimate at c: its minimum is the radius a pass of this size wants.
PPM's schedule then shrinks the radius as photons accumulate. The whole run holds more
photons than half a pass, so the measured multiple is scaled by SHRINK. Nothing reads the
scene's bounding box: geometry out of view changes no radius. Points not seen through a
camera (no footprint) take the distance r_k to their NEAREST-th photon. Constants chosen on
the example scenes (`benchmarks/radius_defaults.py`), reported on the unseen scenes too.
"""

from __future__ import annotations

import numpy as np

from dpm.density.base import luminance
from dpm.density.gather import PhotonIndex, PointIndex
from dpm.tracer import PhotonMap

NEAREST = 8  # the photon whose distance measures the density where there is no footprint
# candidate radii of the pilot, in pixel footprints (ratio √2)
CANDIDATES = np.geomspace(0.25 * np.sqrt(2), 4 * np.sqrt(2), 9)
HELD_OUT = 0.35  # the held-out half's radius, in pixel footprints
SHRINK = 0.6  # PPM's multiple of the pilot's (the run holds more photons than half a pass)
FALLBACK = 1.0  # the multiple when the pass holds too few photons to test


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


def _irradiance(index: PointIndex, half: PhotonMap, radius: np.ndarray, scales: np.ndarray):
    """(len(scales), N) luminance irradiance at the points from one half of a pass, each row
    gathered within scale · radius (N,)."""
    pairs = index.within(half, scales.max() * radius)
    flux = luminance(half.flux[pairs.photon].astype(np.float64)) * 2.0  # a half: twice the flux
    out = np.empty((len(scales), len(radius)))
    for i, s in enumerate(scales):
        inside = pairs.distance < s * radius[pairs.point]
        found = np.bincount(pairs.point[inside], flux[inside], minlength=len(radius))
        out[i] = found / (np.pi * (s * radius) ** 2)
    return out


def pilot_footprints(
    position: np.ndarray, normal: np.ndarray, footprint: np.ndarray, photons: PhotonMap
) -> float:
    """The radius, in pixel footprints, a pass of `photons` wants at points (N, 3) with
    normals (N, 3) and footprints (N,) > 0 (see the module's docstring); FALLBACK when
    either half holds fewer than NEAREST photons."""
    even = photons.path % 2 == 0
    halves = photons.select(even), photons.select(~even)
    if min(len(h) for h in halves) < NEAREST or len(position) == 0:
        return FALLBACK
    index = PointIndex(position, normal)
    width = np.asarray(footprint, np.float64)
    score = np.zeros(len(CANDIDATES))
    for a, b in (halves, halves[::-1]):  # each half tested against the other
        wide = _irradiance(index, a, width, CANDIDATES)
        narrow = _irradiance(index, b, width, np.array([HELD_OUT]))
        score += np.mean((wide - narrow) ** 2, axis=1)
    return float(_vertex(CANDIDATES, score))


def _vertex(candidates: np.ndarray, score: np.ndarray) -> float:
    """The minimum of score over candidates, refined by a parabola in log-log through the
    best and its two neighbours (the best itself at an end of the range)."""
    i = int(np.argmin(score))
    if not 0 < i < len(score) - 1 or np.any(score[i - 1 : i + 2] <= 0):
        return float(candidates[i])
    x, y = np.log(candidates), np.log(score[i - 1 : i + 2])
    curvature = y[0] - 2 * y[1] + y[2]
    if curvature <= 0:
        return float(candidates[i])
    step = 0.5 * (x[1] - x[0]) * (y[0] - y[2]) / curvature
    return float(np.exp(x[i] + step))


def initial_radii(
    position: np.ndarray,
    normal: np.ndarray,
    footprint: np.ndarray | None,
    photons: PhotonMap,
    shape: float = 1.0,
) -> np.ndarray:
    """(N,) float64 initial radius (scene units) of points (N, 3) with normals (N, 3) and
    pixel footprints (N,) (None: not seen through a camera), from a first pass of photons:
    shape · SHRINK · the pilot's multiple of the footprint (see the module's docstring).
    Without a footprint, each point takes r_k, and points with too few photons the largest
    r_k found (or 1 if none)."""
    if footprint is not None:
        width = np.asarray(footprint, np.float64)
        seen = width > 0
        if seen.any():
            multiple = pilot_footprints(position[seen], normal[seen], width[seen], photons)
            fill = float(np.median(width[seen]))
            return shape * SHRINK * multiple * np.where(seen, width, fill)
    radius = nearest_distance(position, normal, photons, NEAREST)
    finite = np.isfinite(radius) & (radius > 0)
    fill = float(radius[finite].max()) if finite.any() else 1.0
    return np.where(finite, radius, fill)
