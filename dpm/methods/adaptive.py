"""Adaptive sampling: where a pass's extra camera paths go, without biasing the image.

After ADAPT_AFTER paths per pixel, every pass adds up to EXTRA_PER_PIXEL × pixels camera
paths for each path per pixel it takes, shared in proportion to how far each pixel falls
short of Neyman's allocation (paths in proportion to the pixel's standard deviation, which
minimises the summed variance of the pixel means for a given number of paths). The pixels
that gain are the few whose paths vary wildly, such as a small light seen through glass or
water: there one path in a hundred
finds the light, and a handful of such pixels can hold nearly all of an image's squared error.

Choosing pixels by their own paths biases their mean low: a pixel whose rare bright paths
happen to show up early gets more paths that dilute them, one whose rare paths have not
shown up yet keeps its low mean (measured: a pool image's mean 9 % low). So the paths are
kept in two halves (passes alternate between them), each half's extra paths are placed by
the deviations of the *other* half's one-per-pass paths, and a pixel's value is the average
of its two halves' means: each half's mean is over paths whose number did not depend on
their values, so the image is unbiased (cross-fitting).
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numba as nb
import numpy as np

from dpm.density.base import luminance

ADAPT_AFTER = 8  # paths per pixel (half in each half) before the first extra paths
EXTRA_PER_PIXEL = 0.25  # extra paths per pass, at most, per pixel and path per pixel
EXTRA_CAP = 64  # extra paths one pixel gets in one pass, at most
SMOOTH = 5  # pixels across the neighbourhood whose variance a pixel's may take


@dataclass
class PixelPaths:
    """Running sums of some camera paths of P pixels."""

    count: np.ndarray  # (P,) float64 paths
    radiance: np.ndarray  # (P, 3) float64 sum of their radiance (W m⁻² sr⁻¹)
    square: np.ndarray  # (P,) float64 sum of their squared luminance

    @classmethod
    def start(cls, pixels: int) -> PixelPaths:
        """No paths yet at `pixels` pixels."""
        return cls(np.zeros(pixels), np.zeros((pixels, 3)), np.zeros(pixels))

    def add(self, pixels: np.ndarray | slice, counts, sums: np.ndarray, squares) -> None:
        """counts (L,) more paths at pixels (L,), their radiance sums (L, 3) and squares (L,)."""
        self.count[pixels] += counts
        self.radiance[pixels] += sums
        self.square[pixels] += squares

    def mean(self) -> np.ndarray:
        """(P, 3) float64 mean radiance of each pixel's paths (zero where it has none)."""
        return self.radiance / np.maximum(self.count, 1)[:, None]

    def deviation(self) -> np.ndarray:
        """(P,) float64 standard deviation of a path's luminance per pixel."""
        n = np.maximum(self.count, 1)
        mean = luminance(self.radiance) / n
        return np.sqrt(np.maximum(self.square / n - mean * mean, 0.0))


def neyman(
    deviation: np.ndarray, count: np.ndarray, budget: int, cap: int
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels (L,) int64 and their extra paths (L,) int64 (`budget` in all, `cap` each at
    most) that bring paths per pixel count (P,) nearest to proportional to deviation (P,)."""
    total = deviation.sum()
    if total <= 0 or budget <= 0:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    short = np.maximum((count.sum() + budget) * deviation / total - count, 0.0)
    counts = np.minimum(np.floor(budget * short / max(short.sum(), 1e-300)), cap)
    pixels = np.flatnonzero(counts > 0)
    return pixels, counts[pixels].astype(np.int64)


@dataclass
class Halves:
    """The camera paths of P pixels in two halves: per half its one-per-pass paths (which
    place the other half's extra paths) and its extra paths."""

    height: int
    width: int
    base: list[PixelPaths] = field(init=False)
    extra: list[PixelPaths] = field(init=False)

    def __post_init__(self) -> None:
        pixels = self.height * self.width
        self.base = [PixelPaths.start(pixels) for _ in range(2)]
        self.extra = [PixelPaths.start(pixels) for _ in range(2)]

    def add_pass(self, half: int, radiance: np.ndarray) -> None:
        """One path per pixel, radiance (P, 3), into half 0 or 1."""
        radiance = radiance.astype(np.float64)
        self.base[half].add(slice(None), 1, radiance, luminance(radiance) ** 2)

    def add_paths(self, half: int, count: int, sums: np.ndarray, squares: np.ndarray) -> None:
        """count paths per pixel into half 0 or 1: their radiance sums (P, 3) and the sums of
        their squared luminances (P,)."""
        self.base[half].add(slice(None), count, sums, squares)

    def half(self, h: int) -> PixelPaths:
        """All paths of half h (its one-per-pass and its extra ones)."""
        base, extra = self.base[h], self.extra[h]
        return PixelPaths(
            base.count + extra.count, base.radiance + extra.radiance, base.square + extra.square
        )

    def plan_extra(self, half: int, budget: int, cap: int) -> tuple[np.ndarray, np.ndarray]:
        """Pixels (L,) and extra paths (L,) for `half`, placed by the other half's deviations
        (each pixel's, or its SMOOTH × SMOOTH neighbourhood's where that is larger: a rare
        path's neighbours see it as rarely, and together they tell its variance sooner)."""
        sigma = np.sqrt(self._or_neighbourhood(self.base[1 - half].deviation() ** 2))
        return neyman(sigma, self.half(half).count, budget, cap)

    def mean(self) -> np.ndarray:
        """(P, 3) float64 radiance per pixel: the mean of its halves' means (a half without
        paths: the other's)."""
        a, b = self.half(0), self.half(1)
        mean_a, mean_b = a.mean(), b.mean()
        one = np.where((b.count > 0)[:, None], mean_b, mean_a)
        return np.where(((a.count > 0) & (b.count > 0))[:, None], (mean_a + mean_b) / 2, one)

    def standard_error(self) -> np.ndarray:
        """(P,) float64 standard error of each pixel's luminance, from its halves' paths, or
        its SMOOTH × SMOOTH neighbourhood's mean squared error where that is larger (a pixel
        whose rare paths have not shown up yet knows no variance of its own); inf where it
        cannot be told (`_variance`): such a pixel is not known exactly, its error is unknown."""
        return np.sqrt(self._or_neighbourhood(self._variance()))

    def noise(self) -> float:
        """Expected RMSE of the pixels' luminance, from each half's deviations and paths (inf
        while some pixel's error cannot be told)."""
        return float(np.sqrt(np.mean(self._variance())))

    def _variance(self) -> np.ndarray:
        """(P,) float64 variance of each pixel's luminance as `mean` takes it (the mean of its
        halves' means, or the one half's mean where the other has no paths); inf where a half
        it takes has fewer than 2 paths, or neither has any: one path's spread reads 0, which
        would pass a first pass's noise for exact."""
        a, b = self.half(0), self.half(1)
        var_a, var_b = (p.deviation() ** 2 / np.maximum(p.count, 1) for p in (a, b))
        both = (a.count > 0) & (b.count > 0)
        var = np.where(both, (var_a + var_b) / 4, var_a + var_b)  # an empty half's var is 0
        unknown = (a.count == 1) | (b.count == 1) | ((a.count == 0) & (b.count == 0))
        return np.where(unknown, np.inf, var)

    def _or_neighbourhood(self, var: np.ndarray) -> np.ndarray:
        """(P,) per-pixel values var (P,), or the SMOOTH × SMOOTH mean of the finite ones where
        that is larger (an infinite value, unknown, stays so and is left out of its
        neighbours' means)."""
        near = _known_mean(var.reshape(self.height, self.width), SMOOTH)
        return np.maximum(var, near.ravel())


@nb.njit(cache=True)
def _known_mean(values, size):
    """(H, W) float64 mean of the finite values (H, W) in each pixel's size × size window
    (beyond the image: the nearest edge pixel's, as `box_mean`'s "nearest"), 0 where the
    window holds none: sums and counts along rows, then along columns. (In NumPy, two box
    means took 1.5 ms of every 128² pass.)"""
    h, w = values.shape
    lo = size // 2
    total, known = np.zeros((h, w)), np.zeros((h, w))
    for y in range(h):
        for x in range(w):
            for dx in range(-lo, size - lo):
                v = values[y, min(max(x + dx, 0), w - 1)]
                if np.isfinite(v):
                    total[y, x] += v
                    known[y, x] += 1.0
    out = np.zeros((h, w))
    for y in range(h):
        for x in range(w):
            t = n = 0.0
            for dy in range(-lo, size - lo):
                row = min(max(y + dy, 0), h - 1)
                t += total[row, x]
                n += known[row, x]
            if n > 0:
                out[y, x] = t / n
    return out
