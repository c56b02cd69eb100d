"""Box means (their running sums in Numba) and a 3 x 3 dilation in NumPy, equal bit for bit to
scipy.ndimage's `uniform_filter` (modes "constant" and "nearest") and `binary_dilation`.

Importing scipy.ndimage costs about 0.2 s of every run (its array-API wrappers), a fifth of a
short render's fixed cost; these are the only parts of it a render calls.
"""

from __future__ import annotations

import numba as nb
import numpy as np


@nb.njit(cache=True)
def _running_mean(line: np.ndarray, size: int) -> np.ndarray:
    """(pre, n − size + 1, post) float64 running means of `size` samples along the middle axis
    of line (pre, n, post) float64, in scipy's order of operations: the first window summed in
    order, then each step adds (entering − leaving), and each sum ÷ size."""
    pre, length, post = line.shape
    n = length - size + 1
    out = np.empty((pre, n, post))
    s = np.empty(post)
    for p in range(pre):
        s[:] = line[p, 0]
        for k in range(1, size):
            for j in range(post):
                s[j] = s[j] + line[p, k, j]
        for j in range(post):
            out[p, 0, j] = s[j] / size
        for i in range(1, n):
            for j in range(post):
                s[j] = s[j] + (line[p, i + size - 1, j] - line[p, i - 1, j])
                out[p, i, j] = s[j] / size
    return out


def _mean_along(a: np.ndarray, size: int, axis: int, mode: str) -> np.ndarray:
    """scipy's running mean of `size` samples along one axis of a, in float64 (Numba: the
    NumPy form of the same sums took 3 ms a call at 256², 14 calls a caustic estimate)."""
    lo = size // 2
    pad = [(0, 0)] * a.ndim
    pad[axis] = (lo, size - lo - 1)
    line = np.pad(a.astype(np.float64), pad, mode="edge" if mode == "nearest" else "constant")
    pre, post = int(np.prod(line.shape[:axis])), int(np.prod(line.shape[axis + 1 :]))
    out = _running_mean(line.reshape(pre, line.shape[axis], post), size)
    return out.reshape(a.shape)


def box_mean(a: np.ndarray, size: int | tuple[int, ...], mode: str = "constant") -> np.ndarray:
    """Mean of each element's window of `size` (an int for every axis, or one per axis)
    centred on it, outside the array 0 ("constant") or the nearest edge value ("nearest");
    in a's (numeric, not bool) dtype, axis after axis, as `scipy.ndimage.uniform_filter`."""
    if a.dtype == bool:
        raise TypeError("box_mean takes numbers, not bool (scipy rounds those differently)")
    if mode not in ("constant", "nearest"):
        raise ValueError(f"mode must be 'constant' or 'nearest' (got {mode!r})")
    sizes = (size,) * a.ndim if isinstance(size, int) else tuple(size)
    out = np.asarray(a)
    for axis, s in enumerate(sizes):
        if s > 1:
            out = _mean_along(out, s, axis, mode).astype(a.dtype)
    return out.copy() if out is a else out


def dilate3(mask: np.ndarray) -> np.ndarray:
    """(H, W) bool: where mask or any of its 8 neighbours is set (outside the image: unset),
    as `scipy.ndimage.binary_dilation` with a 3 x 3 square."""
    padded = np.pad(mask.astype(bool), 1)
    h, w = mask.shape
    out = np.zeros((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            out |= padded[dy : dy + h, dx : dx + w]
    return out
