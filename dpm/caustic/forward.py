"""The caustic filter's forward pass in Numba, for the render: `dpm.nn.caustic_net` without JAX.

Importing JAX and Flax costs about 1.4 s on the 2-core machine, most of a 2-second `auto`
render's budget; the filter's network is four small convolutions, which Numba runs in tens of
milliseconds at 128². This module reads a `dpm-train` weight file of the `caustic`
architecture with msgpack alone (Flax's format: arrays as (shape, dtype, bytes) extension
records) and runs the same layers, softmax and weighted sum as `caustic_net.filter_caustics`
(its sums in another order: equal within float rounding, tested). Each pixel is one thread's
work in a fixed order, so the output does not depend on the thread count.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import msgpack
import numba as nb
import numpy as np

from dpm.caustic.stats import (
    CANDIDATES,
    CHANNELS,
    DILATIONS,
    TAPS,
    CausticStats,
    candidates,
    clamp_to_own,
    features,
    tap_offsets,
)  # fmt: skip
from dpm.errors import InputError

# made by `dpm-train --config configs/caustic.toml` (docs/training.md)
SHIPPED = Path(__file__).parent.parent / "nn" / "weights" / "caustic.msgpack"
ARCHITECTURE = "caustic"
LAYERS = len(DILATIONS)  # 3 × 3 layers before the 1 × 1 output layer


@dataclass(frozen=True)
class FilterWeights:
    """The caustic filter's parameters as float32 arrays, layer by layer."""

    kernels: tuple[np.ndarray, ...]  # (3, 3, in, out) per 3 × 3 layer
    biases: tuple[np.ndarray, ...]  # (out,) per 3 × 3 layer
    out_kernel: np.ndarray  # (width, TAPS)
    out_bias: np.ndarray  # (TAPS,)


def _ext(code: int, data: bytes) -> object:
    """Flax's msgpack extension records: 1 an ndarray, 3 a NumPy scalar."""
    if code in (1, 3):
        shape, dtype, buffer = msgpack.unpackb(data, raw=True)
        array = np.frombuffer(buffer, dtype=np.dtype(dtype.decode())).reshape(shape)
        return array if code == 1 else array[()]
    return msgpack.ExtType(code, data)


def load_filter(path: str | Path = SHIPPED) -> FilterWeights:
    """The caustic filter's weights from a weight file; InputError (one line) when it is
    missing, not a weight file, or not of the `caustic` architecture."""
    path = Path(path)
    try:
        data = msgpack.unpackb(path.read_bytes(), ext_hook=_ext, raw=False, strict_map_key=False)
        if data["architecture"] != ARCHITECTURE:
            raise InputError(f"{path}: a {data['architecture']} network, not the caustic filter")
        p = data["params"]["params"]
        # copies: the buffers msgpack gives are read-only, which Numba types apart from the
        # writable arrays `warm` compiles for (a second compile at the first real call)
        layers = [
            (np.array(p[f"Conv_{i}"]["kernel"], np.float32),
             np.array(p[f"Conv_{i}"]["bias"], np.float32))
            for i in range(LAYERS + 1)
        ]  # fmt: skip
        names = set(p)
    except FileNotFoundError:
        raise InputError(f"{path}: weight file not found") from None
    except InputError:
        raise
    except Exception as e:  # msgpack, key and shape errors alike: not a weight file
        raise InputError(f"{path}: not a dpm weight file ({type(e).__name__})") from None
    width = layers[0][0].shape[-1] if layers[0][0].ndim == 4 else -1
    shapes = [((3, 3, n, width), (width,)) for n in (CHANNELS,) + (width,) * (LAYERS - 1)]
    shapes.append(((1, 1, width, TAPS), (TAPS,)))
    fits = names == {f"Conv_{i}" for i in range(LAYERS + 1)} and all(
        (k.shape, b.shape) == shape for (k, b), shape in zip(layers, shapes, strict=True)
    )
    if not fits:
        raise InputError(f"{path}: parameters do not fit the caustic filter")
    if not all(np.isfinite(a).all() for layer in layers for a in layer):
        raise InputError(f"{path}: the caustic filter's parameters are not finite")
    (*hidden, (out_kernel, out_bias)) = layers
    return FilterWeights(tuple(k for k, _ in hidden), tuple(b for _, b in hidden),
                         np.ascontiguousarray(out_kernel[0, 0]), out_bias)  # fmt: skip


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _conv_relu(x: np.ndarray, kernel: np.ndarray, bias: np.ndarray, d: int) -> np.ndarray:
    """(H, W, out) float32 ReLU of a 3 × 3 convolution of x (H, W, in) at dilation d, zero
    outside the image (Flax's SAME padding)."""
    h, w, cin = x.shape
    cout = kernel.shape[3]
    out = np.empty((h, w, cout), np.float32)
    for y in nb.prange(h):
        acc = np.empty(cout, np.float32)
        for xx in range(w):
            acc[:] = bias
            for ky in range(3):
                yy = y + (ky - 1) * d
                if yy < 0 or yy >= h:
                    continue
                for kx in range(3):
                    xs = xx + (kx - 1) * d
                    if xs < 0 or xs >= w:
                        continue
                    for ci in range(cin):
                        v = x[yy, xs, ci]
                        for co in range(cout):
                            acc[co] += v * kernel[ky, kx, ci, co]
            for co in range(cout):
                out[y, xx, co] = max(acc[co], np.float32(0.0))
    return out


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _weigh(
    hidden: np.ndarray, kernel: np.ndarray, bias: np.ndarray, cand: np.ndarray,
    offsets: np.ndarray,
) -> np.ndarray:  # fmt: skip
    """(H, W, 3) float64 candidates (C, H, W, 3) weighed by the softmax, over the taps inside
    the image, of each pixel's logits (hidden (H, W, width) @ kernel + bias)."""
    h, w, width = hidden.shape
    taps = kernel.shape[1]
    out = np.zeros((h, w, 3))
    for y in nb.prange(h):
        logit = np.empty(taps, np.float32)
        for x in range(w):
            logit[:] = bias
            for ci in range(width):
                v = hidden[y, x, ci]
                for t in range(taps):
                    logit[t] += v * kernel[ci, t]
            top = -np.inf
            for t in range(taps):
                yy, xx = y + offsets[t, 1], x + offsets[t, 2]
                if 0 <= yy < h and 0 <= xx < w and logit[t] > top:
                    top = logit[t]
            total, r, g, b = 0.0, 0.0, 0.0, 0.0
            for t in range(taps):
                yy, xx = y + offsets[t, 1], x + offsets[t, 2]
                if 0 <= yy < h and 0 <= xx < w:
                    e = np.exp(np.float64(logit[t] - top))
                    c = offsets[t, 0]
                    total += e
                    r += e * cand[c, yy, xx, 0]
                    g += e * cand[c, yy, xx, 1]
                    b += e * cand[c, yy, xx, 2]
            out[y, x, 0], out[y, x, 1], out[y, x, 2] = r / total, g / total, b / total
    return out


def kernel_output(weights: FilterWeights, feats: np.ndarray, cands: np.ndarray) -> np.ndarray:
    """(H, W, 3) float64 the candidates (C, H, W, 3) weighed by the network's kernels for
    features (H, W, CHANNELS) (`caustic_net.apply_kernel` of its logits)."""
    x = np.ascontiguousarray(feats, np.float32)
    for kernel, bias, d in zip(weights.kernels, weights.biases, DILATIONS, strict=True):
        x = _conv_relu(x, kernel, bias, d)
    offsets = tap_offsets().astype(np.int64)
    cands = np.ascontiguousarray(cands, np.float32)
    assert cands.shape[0] == len(CANDIDATES), cands.shape
    return _weigh(x, weights.out_kernel, weights.out_bias, cands, offsets)


def warm() -> None:
    """Compile (or load from Numba's cache) the kernels, on a one-pixel image and weights of
    the right types (no file read)."""
    w = 1
    kernels = tuple(np.zeros((3, 3, n, w), np.float32) for n in (CHANNELS,) + (w,) * (LAYERS - 1))
    biases = tuple(np.zeros(w, np.float32) for _ in range(LAYERS))
    weights = FilterWeights(kernels, biases, np.zeros((w, TAPS), np.float32),
                            np.zeros(TAPS, np.float32))  # fmt: skip
    cands = np.zeros((len(CANDIDATES), 1, 1, 3), np.float32)
    kernel_output(weights, np.zeros((1, 1, CHANNELS), np.float32), cands)


def filter_caustics(weights: FilterWeights, stats: CausticStats) -> np.ndarray:
    """(P, 3) float64 caustic radiance per pixel: the network's kernel over the candidate
    estimates, held within CLAMP_Z standard errors of the pixel's own (`clamp_to_own`); the
    pixel's own where the network's output is not finite (weights that overflow)."""
    filtered = kernel_output(weights, features(stats), candidates(stats)).reshape(-1, 3)
    filtered = np.where(np.isfinite(filtered).all(axis=1, keepdims=True), filtered, stats.own)
    return clamp_to_own(stats, filtered)
