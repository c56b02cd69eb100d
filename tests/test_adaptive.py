"""Adaptive sampling (dpm.methods.adaptive): Neyman allocation, and an unbiased image where
a pixel's rare bright paths decide where extra paths go."""

from __future__ import annotations

import numpy as np

from dpm.methods.adaptive import Halves, neyman

# Pixels whose path finds a bright light once in RARE tries (value BRIGHT, else 0): the
# mean is BRIGHT/RARE = 1, and a pixel's paths vary wildly, like a light seen through water.
RARE, BRIGHT = 25, 25.0
HEIGHT, WIDTH = 100, 100
PASSES, BUDGET, CAP = 40, 5000, 64


def paths(rng: np.random.Generator, n: int) -> np.ndarray:
    """(n, 3) radiance of n paths."""
    return np.repeat(np.where(rng.random(n) < 1 / RARE, BRIGHT, 0.0)[:, None], 3, axis=1)


def sums(rng: np.random.Generator, counts: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Radiance sums (L, 3) and squared-luminance sums (L,) of counts (L,) paths each."""
    hits = rng.binomial(counts, 1 / RARE).astype(np.float64)
    return np.repeat(hits[:, None] * BRIGHT, 3, axis=1), hits * BRIGHT**2


def test_neyman_gives_paths_where_they_vary_within_budget_and_cap() -> None:
    deviation = np.array([0.0, 1.0, 1.0, 10.0])
    pixels, counts = neyman(deviation, np.full(4, 4.0), budget=30, cap=20)
    got = dict(zip(pixels.tolist(), counts.tolist(), strict=True))
    assert 0 not in got and got[3] == 20 and counts.sum() <= 30
    assert neyman(np.zeros(4), np.ones(4), 30, 20)[0].size == 0


def test_cross_fitted_halves_keep_the_image_unbiased() -> None:
    # The same heavy-tailed pixels, extra paths placed (a) by the other half's paths, as
    # the renderer does, and (b) by each pixel's own paths. (b) is measurably biased low;
    # (a) agrees with the true mean within its standard error.
    rng = np.random.default_rng(1)
    pixels = HEIGHT * WIDTH
    halves = Halves(HEIGHT, WIDTH)
    own = Halves(HEIGHT, WIDTH)  # both halves are one: every choice sees its own paths
    for j in range(PASSES):
        for h, target in ((j % 2, halves), (0, own)):
            target.add_pass(h, paths(rng, pixels))
        if j >= 8:
            extra, counts = halves.plan_extra(j % 2, BUDGET, CAP)
            halves.extra[j % 2].add(extra, counts, *sums(rng, counts))
            # (b): own's half 0 holds everything; plan from "the other half" = its own paths
            own.base[1] = own.base[0]
            extra, counts = own.plan_extra(0, BUDGET, CAP)
            own.extra[0].add(extra, counts, *sums(rng, counts))
    n = halves.half(0).count + halves.half(1).count
    assert n.sum() > PASSES * pixels * 1.15  # extra paths were spent
    stderr = np.sqrt((BRIGHT - 1) / np.mean(n) / pixels) * 1.5  # halves weigh evenly: a bit more
    unbiased = halves.mean()[:, 0].mean()
    assert abs(unbiased - 1.0) < 3 * stderr
    counts0 = own.half(0).count
    biased = (own.base[0].radiance[:, 0] + own.extra[0].radiance[:, 0]) / counts0
    assert biased.mean() < 1.0 - 5 * stderr


def test_standard_error_matches_the_spread_of_pixel_means() -> None:
    # Pixels of PASSES rare-light paths each: the predicted error of a pixel's mean agrees
    # with the spread of the means across pixels (all have the same distribution).
    rng = np.random.default_rng(2)
    halves = Halves(HEIGHT, WIDTH)
    for j in range(PASSES):
        halves.add_pass(j % 2, paths(rng, HEIGHT * WIDTH))
    spread = halves.mean()[:, 0].std()
    error = halves.standard_error()
    # Pixels whose rare paths have not shown up borrow their neighbours' error: a little high.
    assert 0.95 < np.mean(error) / spread < 1.25
    assert error.min() > 0.5 * spread
