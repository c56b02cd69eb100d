"""The caustic filter's forward pass in Numba, for the render: `dpm.nn.caustic_net` without JAX.

Importing JAX and Flax costs about 1.4 s on the 2-core machine, most of a 2-second `auto`
render's budget; the filter's network is four small convolutions, which Numba runs in a few
milliseconds at 128². This module reads a `dpm-train` weight file of the `caustic`
architecture with msgpack alone (Flax's format: arrays as (shape, dtype, bytes) extension
records) and runs the same layers, softmax and weighted sum as `caustic_net.filter_caustics`
(its sums in another order: equal within float rounding, tested). Each image row is one
thread's work in a fixed order, so the output does not depend on the thread count.
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
    clamp_to_centre,
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


# The layers work channel-major, (C, H + 2 PAD, W + 2 PAD) with a zero border PAD wide: each
# thread takes image rows, and its inner loops run along a row over contiguous floats with no
# border tests (the zeros are Flax's SAME padding), which LLVM turns into 16-wide FMAs.
PAD = max(DILATIONS)
BLOCK = 4  # output channels (or taps) summed per pass over an input row: each load serves 4
TAP_OFFSETS = tap_offsets().astype(np.int64)
F32 = np.float32
# e^x in float32 (`_exp`): x = n ln 2 + r, |r| ≤ ln 2 / 2, ln 2 in two parts (Cody and Waite)
# and Cephes' expf polynomial for e^r
LOG2E, LN2_HI, LN2_LO = F32(1.44269504), F32(0.693359375), F32(-2.12194440e-4)
E0, E1, E2, E3, E4, E5 = map(F32, (1.9875691500e-4, 1.3981999507e-3, 8.3334519073e-3,
                                   4.1665795894e-2, 1.6666665459e-1, 5.0000001201e-1))  # fmt: skip
# `contract` lets LLVM fuse a * b + c into one FMA (one rounding fewer), nothing else: the sums
# keep their order, the same in every thread
FAST = {"contract"}


def _blocks(a: np.ndarray) -> np.ndarray:
    """a (..., n) with its last axis (output channels or taps) cut into blocks of BLOCK, as a
    new first axis: (ceil(n / BLOCK), ..., BLOCK), the last block filled up with copies of the
    last channel (computed twice, written once)."""
    n = a.shape[-1]
    pick = np.minimum(np.arange(-(-n // BLOCK) * BLOCK), n - 1)
    return np.ascontiguousarray(np.moveaxis(a[..., pick].reshape(*a.shape[:-1], -1, BLOCK), -2, 0))


@nb.njit(cache=True, parallel=True)
def _channel_major(a: np.ndarray, out: np.ndarray) -> None:
    """out (C, H + 2p, W + 2p): a (H, W, C) inside out's border p (left as it is)."""
    h, w, c = a.shape
    p = (out.shape[1] - h) // 2
    for y in nb.prange(h):
        for ci in range(c):
            for x in range(w):
                out[ci, p + y, p + x] = a[y, x, ci]


@nb.njit(cache=True, error_model="numpy", fastmath=FAST, inline="always")
def _add3(acc: np.ndarray, k: np.ndarray, s0: np.ndarray, s1: np.ndarray, s2: np.ndarray) -> None:
    """acc (BLOCK, n) float32 += kᵀ (s0, s1, s2): BLOCK output rows from three input rows of n
    floats, k (3, BLOCK) each input row's weight in each output row (three products a store)."""
    k00, k01, k02, k03 = k[0, 0], k[0, 1], k[0, 2], k[0, 3]
    k10, k11, k12, k13 = k[1, 0], k[1, 1], k[1, 2], k[1, 3]
    k20, k21, k22, k23 = k[2, 0], k[2, 1], k[2, 2], k[2, 3]
    for i in range(acc.shape[1]):
        u, v, z = s0[i], s1[i], s2[i]
        acc[0, i] = acc[0, i] + k00 * u + k10 * v + k20 * z
        acc[1, i] = acc[1, i] + k01 * u + k11 * v + k21 * z
        acc[2, i] = acc[2, i] + k02 * u + k12 * v + k22 * z
        acc[3, i] = acc[3, i] + k03 * u + k13 * v + k23 * z


@nb.njit(cache=True, error_model="numpy", fastmath=FAST, inline="always")
def _add1(acc: np.ndarray, k: np.ndarray, s: np.ndarray) -> None:
    """acc (BLOCK, n) float32 += k s: BLOCK output rows from one input row s of n floats, k
    (BLOCK,) its weight in each output row."""
    k0, k1, k2, k3 = k[0], k[1], k[2], k[3]
    for i in range(acc.shape[1]):
        v = s[i]
        acc[0, i] += k0 * v
        acc[1, i] += k1 * v
        acc[2, i] += k2 * v
        acc[3, i] += k3 * v


@nb.njit(cache=True, parallel=True, error_model="numpy", fastmath=FAST)
def _conv_relu(
    x: np.ndarray, kernel: np.ndarray, bias: np.ndarray, d: int, out: np.ndarray
) -> None:  # fmt: skip
    """out (cout, H + 2 PAD, W + 2 PAD) float32 inside its zero border: the ReLU of a 3 × 3
    convolution at dilation d of x (cin, H + 2 PAD, W + 2 PAD); kernel (blocks, 3 rows, cin,
    3 columns, BLOCK) and bias (blocks, BLOCK) cut by `_blocks`."""
    cin = x.shape[0]
    cout, h, w = out.shape[0], out.shape[1] - 2 * PAD, out.shape[2] - 2 * PAD
    for y in nb.prange(h):
        acc = np.empty((BLOCK, w), np.float32)
        for b in range(kernel.shape[0]):
            for j in range(BLOCK):
                acc[j] = bias[b, j]
            for ky in range(3):
                row = PAD + y + (ky - 1) * d
                for ci in range(cin):
                    s = x[ci, row]  # the three columns' inputs: the row shifted by -d, 0, d
                    left, mid, right = s[PAD - d : w + PAD - d], s[PAD : w + PAD], s[PAD + d :]
                    _add3(acc, kernel[b, ky, ci], left, mid, right)
            for j in range(min(BLOCK, cout - b * BLOCK)):
                o = out[b * BLOCK + j, PAD + y, PAD : PAD + w]
                for i in range(w):
                    o[i] = max(acc[j, i], F32(0.0))


@nb.njit(cache=True, error_model="numpy", fastmath=FAST)
def _exp(x: np.float32) -> np.float32:
    """e^x in float32 for x ≤ 0 within 1 ulp (2e-7 relative down to -88), in vector registers
    where libm's would be one call per value; NaN for NaN, e^-88 below -88 (a weight of 6e-39
    where the largest is 1)."""
    c = x if x > -88 else F32(-88.0)  # also keeps NaN out of the integer n
    n = np.floor(c * LOG2E + F32(0.5))
    r = c - n * LN2_HI - n * LN2_LO
    p = ((((E0 * r + E1) * r + E2) * r + E3) * r + E4) * r + E5
    e = p * r * r + r + F32(1.0)
    # times 2^(n + 1) set in the exponent bits, then halved: normal down to n = -127
    e = e * np.int32((np.int64(n) + 128) << 23).view(np.float32) * F32(0.5)
    return e if x == x else x


@nb.njit(cache=True)
def _columns(yy: int, dx: int, h: int, w: int) -> tuple[int, int]:
    """The columns [x0, x1) of an image row where its tap at column offset dx, in row yy, lies
    inside the h × w image (none where row yy is outside)."""
    if yy < 0 or yy >= h:
        return 0, 0
    return max(0, -dx), min(w, w - dx)


@nb.njit(cache=True, parallel=True, error_model="numpy", fastmath=FAST)
def _weigh(
    hidden: np.ndarray, kernel: np.ndarray, bias: np.ndarray, cand: np.ndarray,
    offsets: np.ndarray, out: np.ndarray,
) -> None:  # fmt: skip
    """out (H, W, 3) float64: the candidates cand (C, 3, H, W) weighed by the softmax, over the
    taps inside the image, of each pixel's logits: the 1 × 1 layer of hidden (width, H + 2 PAD,
    W + 2 PAD), kernel (blocks, width, BLOCK) and bias (blocks, BLOCK) cut by `_blocks`;
    offsets (TAPS, 3): candidate, row and column offset of each tap."""
    width, taps = hidden.shape[0], offsets.shape[0]
    h, w = out.shape[0], out.shape[1]
    three = width - width % 3  # hidden channels taken three at a time, the rest one by one
    for y in nb.prange(h):
        # BLOCK rows at a time (the last block's extra rows, copies of the last tap, unread)
        logit = np.empty((kernel.shape[0] * BLOCK, w), np.float32)
        for b in range(kernel.shape[0]):
            acc = logit[b * BLOCK : (b + 1) * BLOCK]
            for j in range(BLOCK):
                acc[j] = bias[b, j]
            for ci in range(0, three, 3):
                _add3(acc, kernel[b, ci : ci + 3], hidden[ci, PAD + y, PAD : PAD + w],
                      hidden[ci + 1, PAD + y, PAD : PAD + w],
                      hidden[ci + 2, PAD + y, PAD : PAD + w])  # fmt: skip
            for ci in range(three, width):
                _add1(acc, kernel[b, ci], hidden[ci, PAD + y, PAD : PAD + w])
        # each pixel's largest logit inside the image, then the sums of e^(logit - largest)
        # and of the candidates so weighted, tap by tap along the row (float32: 16 a vector)
        top = np.full(w, -np.inf, np.float32)
        for t in range(taps):
            x0, x1 = _columns(y + offsets[t, 1], offsets[t, 2], h, w)
            lt, tp = logit[t, x0:x1], top[x0:x1]
            for i in range(x1 - x0):
                if lt[i] > tp[i]:
                    tp[i] = lt[i]
        sums = np.zeros((4, w), np.float32)  # total weight, weighted red, green, blue
        for t in range(taps):
            c, yy, dx = offsets[t, 0], y + offsets[t, 1], offsets[t, 2]
            x0, x1 = _columns(yy, dx, h, w)
            if x0 == x1:
                continue
            lt, tp = logit[t, x0:x1], top[x0:x1]
            red, green, blue = (cand[c, 0, yy, x0 + dx : x1 + dx],
                                cand[c, 1, yy, x0 + dx : x1 + dx],
                                cand[c, 2, yy, x0 + dx : x1 + dx])  # fmt: skip
            st, sr, sg, sb = sums[0, x0:x1], sums[1, x0:x1], sums[2, x0:x1], sums[3, x0:x1]
            for i in range(x1 - x0):
                e = _exp(lt[i] - tp[i])
                st[i] += e
                sr[i] += e * red[i]
                sg[i] += e * green[i]
                sb[i] += e * blue[i]
        for x in range(w):
            for ch in range(3):
                out[y, x, ch] = np.float64(sums[1 + ch, x]) / sums[0, x]


def kernel_output(weights: FilterWeights, feats: np.ndarray, cands: np.ndarray) -> np.ndarray:
    """(H, W, 3) float64 the candidates (C, H, W, 3) weighed by the network's kernels for
    features (H, W, CHANNELS) (`caustic_net.apply_kernel` of its logits)."""
    h, w, _ = feats.shape
    assert cands.shape[0] == len(CANDIDATES), cands.shape
    # the kernels are compiled (`warm`) for aligned, writable, C-contiguous arrays: a
    # read-only input would compile them again
    feats, cands = (np.require(a, np.float32, "ACW") for a in (feats, cands))
    size = (h + 2 * PAD, w + 2 * PAD)
    x = np.zeros((CHANNELS, *size), np.float32)
    _channel_major(feats, x)
    # two hidden images in turn, each layer reading one and writing the other's inside: their
    # borders stay zero
    hidden = [np.zeros((weights.out_kernel.shape[0], *size), np.float32) for _ in range(2)]
    layers = zip(weights.kernels, weights.biases, DILATIONS, strict=True)
    for i, (kernel, bias, d) in enumerate(layers):
        _conv_relu(x, _blocks(kernel.transpose(0, 2, 1, 3)), _blocks(bias), d, hidden[i % 2])
        x = hidden[i % 2]
    cand = np.empty((len(CANDIDATES), 3, h, w), np.float32)
    for c in range(len(CANDIDATES)):
        _channel_major(cands[c], cand[c])
    out = np.empty((h, w, 3))
    _weigh(x, _blocks(weights.out_kernel), _blocks(weights.out_bias), cand, TAP_OFFSETS, out)
    return out


def warm() -> None:
    """Compile (or load from Numba's cache) the kernels, on a one-pixel image and weights of
    the right types (no file read): the network's and its statistics' (`filter_caustics`)."""
    w = 1
    kernels = tuple(np.zeros((3, 3, n, w), np.float32) for n in (CHANNELS,) + (w,) * (LAYERS - 1))
    biases = tuple(np.zeros(w, np.float32) for _ in range(LAYERS))
    weights = FilterWeights(kernels, biases, np.zeros((w, TAPS), np.float32),
                            np.zeros(TAPS, np.float32))  # fmt: skip
    one, rgb = np.ones(1), np.ones((1, 3))
    filter_caustics(weights, CausticStats(1, 1, 1, rgb, rgb, one, one, rgb, one, rgb, one, one,
                                          one, one, rgb, rgb))  # fmt: skip


def filter_caustics(weights: FilterWeights, stats: CausticStats) -> np.ndarray:
    """(P, 3) float64 caustic radiance per pixel: the network's kernel over the candidate
    estimates, held within CLAMP_Z standard errors of the pixel's extrapolated estimate, or
    with HULL_CLAMP within the hull of that interval and the one about the pixel's own
    estimate (`clamp_to_centre`); the pixel's own where the network's output is not finite (weights
    that overflow)."""
    filtered = kernel_output(weights, features(stats), candidates(stats)).reshape(-1, 3)
    filtered = np.where(np.isfinite(filtered).all(axis=1, keepdims=True), filtered, stats.own)
    return clamp_to_centre(stats, filtered)
