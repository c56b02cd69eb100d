"""Image metrics against scikit-image and their definitions."""

from __future__ import annotations

import numpy as np
import pytest
from skimage.metrics import mean_squared_error, peak_signal_noise_ratio, structural_similarity

from dpm.metrics import dssim, psnr, relmse, rmse, ssim


@pytest.fixture
def images() -> tuple[np.ndarray, np.ndarray]:
    rng = np.random.default_rng(0)
    reference = rng.random((40, 48, 3))
    return reference + 0.1 * rng.standard_normal(reference.shape), reference


def test_rmse_and_psnr_match_scikit_image(images) -> None:
    x, y = images
    assert rmse(x, y) == pytest.approx(mean_squared_error(y, x) ** 0.5, rel=1e-12)
    assert psnr(x, y, peak=1.0) == pytest.approx(peak_signal_noise_ratio(y, x, data_range=1.0))
    assert psnr(y, y) == float("inf")


@pytest.mark.parametrize("data_range", [1.0, None])
def test_ssim_matches_scikit_image(images, data_range) -> None:
    x, y = images
    theirs = structural_similarity(
        x, y, data_range=data_range or float(y.max() - y.min()), channel_axis=2
    )
    assert ssim(x, y, data_range) == pytest.approx(theirs, rel=1e-9)
    assert ssim(y, y) == pytest.approx(1.0)
    assert dssim(x, y, data_range) == pytest.approx((1 - theirs) / 2, rel=1e-9)


def test_relmse_is_relative() -> None:
    y = np.array([1.0, 10.0])
    assert relmse(y * 1.1, y, eps=0.0) == pytest.approx(0.01)
    assert relmse(y, y) == 0.0
