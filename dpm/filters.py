"""Box means and a 3 x 3 dilation in NumPy, equal bit for bit to scipy.ndimage's
`uniform_filter` (modes "constant" and "nearest") and `binary_dilation`.

Importing scipy.ndimage costs about 0.2 s of every run (its array-API wrappers), a fifth of a
short render's fixed cost; these are the only parts of it a render calls.
"""

from __future__ import annotations

import numpy as np


def _mean_along(a: np.ndarray, size: int, axis: int, mode: str) -> np.ndarray:
    """scipy's running mean of `size` samples along one axis, in float64, in its order of
    operations: the first window summed in order, then each step adds (entering − leaving),
    and each sum ÷ size."""
    lo = size // 2
    pad = [(0, 0)] * a.ndim
    pad[axis] = (lo, size - lo - 1)
    line = np.pad(a.astype(np.float64), pad, mode="edge" if mode == "nearest" else "constant")
    line = np.moveaxis(line, axis, 0)
    n = line.shape[0] - size + 1
    steps = np.empty((n, *line.shape[1:]))
    steps[0] = np.add.accumulate(line[:size], axis=0)[-1]
    steps[1:] = line[size:] - line[: n - 1]
    return np.moveaxis(np.add.accumulate(steps, axis=0) / size, 0, axis)


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
