"""Arrays passed by address (`dpm.tracer.addresses`): the callee sees the caller's arrays."""

from __future__ import annotations

from typing import NamedTuple

import numba as nb
import numpy as np
import pytest
from numba.core.errors import TypingError

from dpm.tracer.addresses import by_address, example_of


class Pair(NamedTuple):
    """A bundle of a 2-D float32 and a 1-D int64 array."""

    points: np.ndarray
    index: np.ndarray


to_words, from_words = by_address(
    (example_of(Pair, {"points": (np.float32, 2), "index": (np.int64, 1)}), np.zeros(0))
)


@nb.njit(_nrt=False)
def _callee(words):
    """Writes through the views and returns what it read (the arrays' own shapes)."""
    (pair, extra) = from_words(words)
    pair.points[1, 2] = 7.5
    extra[0] = pair.index[2] + pair.points.shape[1]
    return pair.points.shape[0], pair.points.shape[1], pair.index.shape[0], pair.points.sum()


@nb.njit
def _caller(pair, extra):
    """Passes a (nested) bundle by address."""
    return _callee(to_words((pair, extra)))


def test_views_share_memory_and_shapes() -> None:
    """The callee's arrays are the caller's: same shapes, same values, writes seen."""
    points = np.arange(12, dtype=np.float32).reshape(4, 3)
    index = np.array([5, 6, 40], np.int64)
    extra = np.zeros(2)
    rows, cols, n, total = _caller(Pair(points, index), extra)
    assert (rows, cols, n) == (4, 3, 3)
    assert points[1, 2] == 7.5 and total == pytest.approx(float(points.sum()))
    assert extra[0] == 43.0


def test_rejects_views_that_are_not_contiguous() -> None:
    """A strided view would be read wrongly as contiguous: it does not compile."""
    points = np.zeros((4, 6), np.float32)[:, ::2]
    with pytest.raises(TypingError, match="C-contiguous"):
        _caller(Pair(points, np.zeros(3, np.int64)), np.zeros(2))


def test_rejects_other_dtypes() -> None:
    """A bundle of other dtypes than the example's does not compile."""
    with pytest.raises(TypingError, match="not like"):
        _caller(Pair(np.zeros((4, 3)), np.zeros(3, np.int64)), np.zeros(2))
