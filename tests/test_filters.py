"""`dpm.filters` equals scipy.ndimage bit for bit where a render uses it."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.ndimage import binary_dilation, uniform_filter

from dpm.filters import box_mean, dilate3


@pytest.mark.parametrize("mode", ["constant", "nearest"])
@pytest.mark.parametrize("dtype", [np.float64, np.float32, np.int64])
def test_box_mean_is_scipys_uniform_filter(mode: str, dtype: type) -> None:
    rng = np.random.default_rng(7)
    for _ in range(40):
        shape = tuple(int(s) for s in rng.integers(1, 30, rng.integers(1, 4)))
        a = (rng.random(shape) * 10).astype(dtype)
        size = int(rng.integers(1, 12))
        sizes = tuple(int(s) for s in rng.integers(1, 12, len(shape)))
        for s in (size, sizes):
            want = uniform_filter(a, s, mode=mode)
            got = box_mean(a, s, mode)
            assert got.dtype == want.dtype and np.array_equal(got, want)


def test_box_mean_refuses_what_it_does_not_copy() -> None:
    with pytest.raises(ValueError, match="mode"):
        box_mean(np.ones(4), 3, "reflect")
    with pytest.raises(TypeError, match="bool"):
        box_mean(np.ones(4, bool), 3)


def test_dilate3_is_scipys_binary_dilation() -> None:
    rng = np.random.default_rng(8)
    for _ in range(40):
        mask = rng.random((int(rng.integers(1, 20)), int(rng.integers(1, 20)))) > 0.85
        assert np.array_equal(dilate3(mask), binary_dilation(mask, np.ones((3, 3), bool)))
