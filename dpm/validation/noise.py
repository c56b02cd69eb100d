"""Comparing two renderers' images within their noise, each measured from two renders."""

from __future__ import annotations

import numpy as np


def block_z(a: list[np.ndarray], b: list[np.ndarray], block: int = 8) -> np.ndarray:
    """z-scores (H/block, W/block, 3) of block-mean differences between the mean images of two
    renderers, each given as two independent renders (H, W, 3).

    A renderer's per-pixel variance is (x₀ − x₁)²/2; pixels are independent, so a block mean's
    variance is the sum over its pixels divided by the squared pixel count.
    """

    def mean_and_var(pair: list[np.ndarray]) -> tuple[np.ndarray, np.ndarray]:
        x = np.stack(pair).astype(np.float64)
        h, w = x.shape[1:3]
        var = (x[0] - x[1]) ** 2 / 2 / 2  # per pixel, of the mean of the two renders
        shape = (h // block, block, w // block, block, 3)
        mean = x.mean(axis=0).reshape(shape).mean(axis=(1, 3))
        return mean, var.reshape(shape).sum(axis=(1, 3)) / block**4

    (ma, va), (mb, vb) = mean_and_var(a), mean_and_var(b)
    floor = 1e-6 * max(ma.mean(), mb.mean()) ** 2  # blocks both see as constant (black, lights)
    return (ma - mb) / np.sqrt(va + vb + floor)


def relative_sigma_of_mean_difference(a: list[np.ndarray], b: list[np.ndarray]) -> float:
    """Standard deviation of mean(a) − mean(b) relative to mean(b), for two renders of each."""
    var = 0.0
    for pair in (a, b):
        grey = np.stack(pair).astype(np.float64).mean(axis=3)  # (2, H, W)
        var += float(np.sum((grey[0] - grey[1]) ** 2 / 4)) / grey[0].size ** 2
    return var**0.5 / float(np.mean(b))
