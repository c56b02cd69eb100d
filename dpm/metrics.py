"""Image and per-point error metrics against a reference (linear RGB unless noted).

RMSE and relMSE take any matching arrays (images (H, W, 3) or visible points (N, 3)); PSNR,
SSIM and DSSIM take images. SSIM follows Wang et al. 2004 with a 7×7 uniform window,
K₁ = 0.01, K₂ = 0.03, the sample covariance, and the mean over the valid interior of every
channel (scikit-image's defaults, which the tests check against).
"""

from __future__ import annotations

import numpy as np


def rmse(estimate: np.ndarray, reference: np.ndarray) -> float:
    """Root mean squared error over all elements."""
    d = np.asarray(estimate, np.float64) - np.asarray(reference, np.float64)
    return float(np.sqrt(np.mean(d * d)))


def relmse(estimate: np.ndarray, reference: np.ndarray, eps: float = 1e-2) -> float:
    """Relative MSE, mean of (x − y)² / (y² + eps) (Rousselle et al. 2011)."""
    x, y = np.asarray(estimate, np.float64), np.asarray(reference, np.float64)
    return float(np.mean((x - y) ** 2 / (y * y + eps)))


def psnr(estimate: np.ndarray, reference: np.ndarray, peak: float | None = None) -> float:
    """Peak signal-to-noise ratio in dB; peak defaults to the reference's maximum."""
    peak = float(np.max(reference)) if peak is None else peak
    mse = rmse(estimate, reference) ** 2
    return float("inf") if mse == 0 else float(10 * np.log10(peak * peak / mse))


def ssim(
    estimate: np.ndarray,
    reference: np.ndarray,
    data_range: float | None = None,
    window: int = 7,
) -> float:
    """Structural similarity of images (H, W) or (H, W, C), mean over pixels and channels.

    data_range defaults to the reference's max − min (clip tone-mapped images to [0, 1] and
    pass 1 to compare what a viewer sees).
    """
    x, y = np.asarray(estimate, np.float64), np.asarray(reference, np.float64)
    if x.shape != y.shape:
        raise ValueError(f"shapes differ: {x.shape} vs {y.shape}")
    if x.ndim == 2:
        x, y = x[..., None], y[..., None]
    if min(x.shape[:2]) < window:
        raise ValueError(f"images must be at least {window}×{window} pixels")
    if data_range is None:
        data_range = float(y.max() - y.min()) or 1.0
    c1, c2 = (0.01 * data_range) ** 2, (0.03 * data_range) ** 2
    cov = window * window / (window * window - 1)  # sample, not population, covariance
    from scipy.ndimage import uniform_filter  # here, not at the top: its import costs 0.2 s

    scores = []
    for c in range(x.shape[2]):
        a, b = x[..., c], y[..., c]
        mean = [uniform_filter(v, window) for v in (a, b, a * a, b * b, a * b)]
        ma, mb, maa, mbb, mab = mean
        va, vb, vab = cov * (maa - ma * ma), cov * (mbb - mb * mb), cov * (mab - ma * mb)
        s = ((2 * ma * mb + c1) * (2 * vab + c2)) / ((ma * ma + mb * mb + c1) * (va + vb + c2))
        pad = (window - 1) // 2
        scores.append(s[pad:-pad, pad:-pad].mean())
    return float(np.mean(scores))


def dssim(estimate: np.ndarray, reference: np.ndarray, data_range: float | None = None) -> float:
    """Structural dissimilarity (1 − SSIM) / 2."""
    return (1 - ssim(estimate, reference, data_range)) / 2
