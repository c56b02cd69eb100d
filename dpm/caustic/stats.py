"""What `auto`'s learned caustic filter sees of a render in passes: per-pixel SPPM statistics,
the view-relative features made from them, and the candidate estimates its kernel weighs.

NumPy only (no JAX), so a render can form them without importing JAX; the network that reads
them is `dpm.nn.caustic_net` (training, pure JAX) and `dpm.caustic.forward` (the render's
Numba copy of its forward pass). Every feature is scale-free: radiance over the image's mean
caustic, radii in pixel footprints, depth relative to the median pixel's, so a scene's size
and brightness do not matter.
"""

from __future__ import annotations

from dataclasses import dataclass

import numba as nb
import numpy as np

from dpm.density.base import LUMINANCE, luminance
from dpm.filters import box_mean

CHANNELS = 15  # features per pixel (`features`)
# (candidate, dilation, taps per side) of `candidates`: the wide and the narrow estimates at
# the 5 × 5 neighbouring pixels; the wide one's 3 × 3 and 9 × 9 means at every third and
# ninth pixel (reaching ±6 and ±18 pixels: sparse photons at few passes); the pixel's own
# estimate with sparse pixels spread (`auto.spread_sparse`); the extrapolated estimate
# (`extrapolated`) at the 5 × 5 neighbours, the one candidate with less blur than the narrow
CANDIDATES = ((0, 1, 5), (1, 1, 5), (2, 3, 5), (3, 9, 5), (4, 1, 1), (5, 1, 5))
TAPS = sum(size * size for *_, size in CANDIDATES)  # kernel weights per pixel
SPREAD = 4  # the candidate that is the render's caustic without the network
DILATIONS = (1, 2, 4, 8)  # of the network's four 3 × 3 layers: it sees 31 × 31 pixels
# Standard errors of the clamp's centre (`clamp_centre`) the filter may move it from (with
# HULL_CLAMP, or of the pixel's own estimate, and anywhere between the two intervals): 2 at
# render (chosen, when the centre was the pixel's own estimate, on
# the examples with the shipped weights, benchmarks/results/caustic_clamp.md: geometric mean
# 0.851 of the render without the network over 1-64 passes, worst 0.972, against 0.869 and
# 0.971 at 1, 0.847 and 1.003 at 3), and 2 in training (the shipped weights were trained
# through it; the weights before them, trained without augmentation, did best at 1)
CLAMP_Z, TRAIN_CLAMP_Z = 2.0, 2.0
TINY = 1e-12  # radiance far below any caustic's, keeping the clamp's ratio finite
# SPPM's blur grows as the radius squared where a caustic is smooth, so of two estimates whose
# blurs are in the ratio q (narrow over wide), wide + (narrow − wide)/(1 − q) cancels it to
# second order (Richardson extrapolation): less bias than either, more noise. SPPM's estimate
# is the mean of its passes' own estimates, each at that pass's radius (the radius shrinks
# and the flux is rescaled with it: the rescalings telescope), so q is Σ r_narrow² / Σ r_wide²
# over the passes (`CausticStats.blur_ratio`): NARROW² = 1/4 at the first pass, then each
# radius shrinks with its own photons, and by 64 passes q is 0.25-0.40 (the glass egg's
# median 0.33, its factor 1.48 where 1/4 gives 4/3). Capped where the radii would be too
# close for the difference to say anything (a factor of at most 2).
FIRST_BLUR_RATIO = 0.25
MAX_BLUR_RATIO = 0.5
# What the filter's result is held around (`clamp_centre`): the pixel's own estimate, or the
# extrapolated one (less blur, more noise, so a wider reach; both converge as passes grow).
# Chosen on the examples (benchmarks/blend_target.py --switch centre --network, the weights
# then trained around the own one): 0.979 / 0.982 / 0.988 of the own centre at 4 / 16 / 64
# passes; the network is trained through the same centre (the set stores it)
EXTRAPOLATED_CENTRE = True
# With an extrapolated centre, the filter may also reach anywhere within CLAMP_Z standard
# errors of the pixel's own estimate (the hull of the two intervals): both converge, and at
# few passes the own one's reach is the wider where the narrow disc is nearly empty
HULL_CLAMP = True


@dataclass
class CausticStats:
    """One render's caustic statistics after `passes` passes, per pixel of an h × w image
    (flattened, row-major)."""

    h: int
    w: int
    passes: int
    wide: np.ndarray  # (P, 3) float64 caustic radiance at the wide radius (W m⁻² sr⁻¹)
    narrow: np.ndarray  # (P, 3) float64 the same at the narrow radius
    wide_count: np.ndarray  # (P,) float64 photons in the wide disc (PPM's N)
    narrow_count: np.ndarray  # (P,) float64 photons in the narrow disc
    own: np.ndarray  # (P, 3) float64 the estimate without the network (Lepski's choice)
    own_count: np.ndarray  # (P,) float64 photons behind `own`
    spread: np.ndarray  # (P, 3) float64 `own` with its sparse pixels spread (no network)
    spread_count: np.ndarray  # (P,) float64 photons behind `spread` (a sparse pixel's window's)
    radius: np.ndarray  # (P,) float64 wide radius in pixel footprints
    blur_ratio: np.ndarray  # (P,) float64 narrow over wide Σ radius² of the passes (`extrapolated`)
    depth: np.ndarray  # (P,) float64 log(footprint / the median pixel's footprint)
    albedo: np.ndarray  # (P, 3) float64 mean albedo guide in [0, 1]
    normal: np.ndarray  # (P, 3) float64 mean normal guide

    def photon_value(self) -> float:
        """Luminance one photon adds to a pixel, on average over the pixels holding any (the
        error of a pixel whose disc holds none: it shrinks as passes add paths)."""
        held = self.wide_count > 0
        if not held.any():
            return 0.0
        return float(luminance(self.wide[held]).sum() / self.wide_count[held].sum())


def f64(a: np.ndarray) -> np.ndarray:
    """a as a C-contiguous float64 array (a copy only where it is not one): the Numba kernels
    here and in `auto` are compiled for those types alone, and warmed on them in the first
    pass (`dpm.caustic.forward.warm`), so the finish never stops to compile another."""
    return np.ascontiguousarray(a, np.float64)


def features(s: CausticStats) -> np.ndarray:
    """(h, w, CHANNELS) float32 scale-free inputs of the filter network per pixel: log
    radiance (wide, narrow, spread) over the image's mean, log photon counts, relative error, log
    radius in footprints, albedo, normal, relative depth, log passes."""
    hit = s.albedo.max(axis=1) > 0
    scale = max(float(luminance(s.wide[hit]).mean()) if hit.any() else 0.0, 1e-30)
    out = np.empty((s.h * s.w, CHANNELS), np.float32)
    arrays = (s.wide, s.narrow, s.spread, s.wide_count, s.narrow_count, s.radius, s.albedo,
              s.normal, s.depth)  # fmt: skip
    _features(*map(f64, arrays), scale, float(np.log1p(s.passes) / 4), out)
    return out.reshape(s.h, s.w, CHANNELS)


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _features(
    wide: np.ndarray, narrow: np.ndarray, spread: np.ndarray, wide_count: np.ndarray,
    narrow_count: np.ndarray, radius: np.ndarray, albedo: np.ndarray, normal: np.ndarray,
    depth: np.ndarray, scale: float, passes: float, out: np.ndarray,
) -> None:  # fmt: skip
    """out (P, CHANNELS) float32: `features`' columns pixel by pixel (one pass over the
    pixels where the NumPy form made a (P,) temporary per column: 9 ms a call at 256²)."""
    r, g, b = LUMINANCE
    for i in nb.prange(out.shape[0]):
        lw = wide[i, 0] * r + wide[i, 1] * g + wide[i, 2] * b
        ln = narrow[i, 0] * r + narrow[i, 1] * g + narrow[i, 2] * b
        ls = spread[i, 0] * r + spread[i, 1] * g + spread[i, 2] * b
        row = out[i]
        row[0], row[1], row[2] = np.log1p(lw / scale), np.log1p(ln / scale), np.log1p(ls / scale)
        row[3], row[4] = np.log1p(wide_count[i]) / 4, np.log1p(narrow_count[i]) / 4
        row[5] = 1 / np.sqrt(max(wide_count[i], 1.0))
        row[6] = np.log(max(radius[i], 1e-3))
        for c in range(3):
            row[7 + c], row[10 + c] = albedo[i, c], normal[i, c]
        row[13], row[14] = depth[i], passes


def extrapolated(wide: np.ndarray, narrow: np.ndarray, blur_ratio: np.ndarray) -> np.ndarray:
    """(P, 3) the Richardson extrapolation of the wide and narrow estimates (P, 3) to a zero
    radius, their blurs in the ratio blur_ratio (P,) (`extrapolation`), held at zero where
    the narrow one's noise takes it below."""
    factor = extrapolation(blur_ratio)[:, None]
    return np.maximum(wide + factor * (narrow - wide), 0.0)


def extrapolation(blur_ratio: np.ndarray) -> np.ndarray:
    """(P,) float64 the weight 1 / (1 − q) of the narrow estimate's difference from the wide
    one that cancels their blur, q (P,) the ratio of the two (capped at MAX_BLUR_RATIO)."""
    return 1.0 / (1.0 - np.minimum(blur_ratio, MAX_BLUR_RATIO))


def candidates(s: CausticStats) -> np.ndarray:
    """(6, h, w, 3) float32 the estimates the kernel weighs: wide, narrow, the wide one's
    3 × 3 and 9 × 9 means (over the pixels inside the image), the spread one and the
    extrapolated one."""
    wide = s.wide.reshape(s.h, s.w, 3)
    means = []
    for size in (3, 9):
        inside = box_mean(np.ones((s.h, s.w)), size)
        means.append(box_mean(wide, (size, size, 1)) / inside[..., None])
    narrow, spread = (a.reshape(s.h, s.w, 3) for a in (s.narrow, s.spread))
    # running box sums leave -1e-17 where the image is dark: radiance is never negative
    sharp = extrapolated(s.wide, s.narrow, s.blur_ratio).reshape(s.h, s.w, 3)
    out = np.stack([wide, narrow, *means, spread, sharp])
    return np.maximum(out, 0.0).astype(np.float32)


def tap_offsets() -> np.ndarray:
    """(TAPS, 3) int: candidate, row offset and column offset of each kernel weight."""
    return np.array([(c, dy * d, dx * d) for c, d, size in CANDIDATES
                     for dy in range(-(size // 2), size // 2 + 1)
                     for dx in range(-(size // 2), size // 2 + 1)])  # fmt: skip


def centre_tap() -> int:
    """Index of the wide estimate's own pixel among the taps (a fresh network favours it)."""
    return CANDIDATES[0][2] ** 2 // 2


def clamp_centre(s: CausticStats) -> tuple[np.ndarray, np.ndarray]:
    """((P, 3) radiance, (P,) photons behind it) the filter's result is held around: the
    pixel's own estimate, or with EXTRAPOLATED_CENTRE the extrapolated one, whose relative
    variance (nested discs, weight f of the narrow one) is (1 − f²)/N_wide + f²/N_narrow, so
    its photons are the inverse (none where the narrow disc holds none)."""
    if not EXTRAPOLATED_CENTRE:
        return s.own, s.own_count
    f = extrapolation(s.blur_ratio)
    held = (s.narrow_count > 0) & (s.wide_count > 0)
    count = np.where(held, nested_photons(s.wide_count, s.narrow_count, f), 0.0)
    return extrapolated(s.wide, s.narrow, s.blur_ratio), count


def nested_photons(wide_count: np.ndarray, narrow_count: np.ndarray, b: np.ndarray) -> np.ndarray:
    """(P,) photons the estimate (1 − b)·wide + b·narrow is worth, wide_count and narrow_count
    (P,) the discs' photons (at least 1): the narrow disc's photons are among the wide one's,
    so their errors correlate and its relative variance is (1 − b²)/N_wide + b²/N_narrow."""
    nw, nn = np.maximum(wide_count, 1.0), np.maximum(narrow_count, 1.0)
    return 1.0 / ((1 - b * b) / nw + b * b / nn)


def clamp_other(s: CausticStats) -> tuple[np.ndarray, np.ndarray]:
    """((P, 3) radiance, (P,) photons) the hull's second interval is about: the pixel's own
    estimate with HULL_CLAMP, else the centre again (one interval)."""
    return (s.own, s.own_count) if HULL_CLAMP else clamp_centre(s)


def clamp_to_centre(s: CausticStats, filtered: np.ndarray) -> np.ndarray:
    """(P, 3) float64: `filtered` (P, 3) moved back toward the estimate it is held around
    (`clamp_centre`) until every channel lies within CLAMP_Z standard errors of it, or with
    HULL_CLAMP within the hull of that interval and the one CLAMP_Z standard errors about the
    pixel's own estimate (`_clamp`: between the two included), so as passes add photons the
    result converges to a consistent estimate whatever the network says, colour included."""
    centre, count = clamp_centre(s)
    other, other_count = clamp_other(s)
    out = np.empty((len(s.own), 3))
    _clamp(*map(f64, (centre, count, other, other_count, filtered)), s.photon_value(), CLAMP_Z,
           out)  # fmt: skip
    return out  # a sum of non-negatives


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _clamp(
    centre: np.ndarray, count: np.ndarray, other: np.ndarray, other_count: np.ndarray,
    filtered: np.ndarray, photon: float, z: float, out: np.ndarray,
) -> None:  # fmt: skip
    """out (P, 3) = centre + keep·(filtered − centre), keep the largest share of the move from
    centre (P, 3) to filtered (P, 3) that keeps each channel inside the hull of the intervals
    z standard errors about centre and about other (P, 3; centre again for one interval): an
    estimate's error is 1/√n of the larger of it and the filtered value where its disc holds
    n photons (count, other_count (P,)), else the smaller of the filtered value and one
    photon's luminance `photon` (all shrink as passes add photons and paths). One pass over
    the pixels (the NumPy form made a dozen (P, 3) temporaries)."""
    for i in nb.prange(centre.shape[0]):
        keep = np.inf
        for c in range(3):
            o, f = centre[i, c], filtered[i, c]
            lo, hi = o, o
            for m, n in ((o, count[i]), (other[i, c], other_count[i])):
                error = max(m, f) / np.sqrt(max(n, 1.0)) if n > 0 else min(f, photon)
                lo, hi = min(lo, m - z * error), max(hi, m + z * error)
            allowed = (hi - o if f > o else o - lo) + TINY
            keep = min(keep, allowed / max(abs(f - o) + TINY, allowed))
        for c in range(3):
            out[i, c] = (1 - keep) * centre[i, c] + keep * filtered[i, c]
