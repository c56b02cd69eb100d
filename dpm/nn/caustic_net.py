"""`auto`'s learned caustic filter: a small screen-space network that predicts, per pixel, a
kernel over its neighbours' SPPM estimates (kernel prediction, as in learned denoisers), and
the pure function that applies it.

The network reads `dpm.caustic.stats.features` (scale-free per-pixel statistics and
guides) and gives TAPS logits per pixel: one per (candidate estimate, neighbour) of
`stats.CANDIDATES`; their softmax weighs those estimates. The result is then held
within a few standard errors of the pixel's extrapolated SPPM estimate (`clamp`, around
`stats.clamp_centre`), or of the hull of that interval and the one about the pixel's own
estimate (`stats.HULL_CLAMP`, training and render alike), so whatever the network says,
as passes add photons the filter's reach shrinks to nothing and the render converges to
SPPM's. A fresh network's last layer is zero with the pixel's own wide estimate favoured, so
it starts close to the identity.

Training runs this module under `jax.jit`; a render runs `dpm.caustic.forward`, a Numba
copy of the same forward pass (tested equal), because importing JAX costs a 2-second render
most of its budget.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from dpm.caustic.stats import (
    CHANNELS,
    DILATIONS,
    TAPS,
    TINY,
    TRAIN_CLAMP_Z,
    centre_tap,
    tap_offsets,
)  # fmt: skip

# A fresh network's logit for the pixel's own wide estimate: weight 0.96 against the other
# TAPS - 1 taps' 0.04 (0.97 and 0.03 with 101 taps; at 6, 0.8: with aimed photons, whose
# noise is lower at the same pass count, a fresh filter's 20 % blur of the neighbours went
# past one standard error)
CENTRE_LOGIT = 8.0


def _centre_bias(key: jax.Array, shape: tuple[int, ...], dtype: jnp.dtype = jnp.float32):
    """The output layer's initial bias: zero but for the pixel's own wide estimate."""
    return jnp.zeros(shape, dtype).at[centre_tap()].set(CENTRE_LOGIT)


class CausticNet(nn.Module):
    """(..., H, W, TAPS) kernel logits from (..., H, W, CHANNELS) features."""

    width: int = 24

    @nn.compact
    def __call__(self, x: jnp.ndarray) -> jnp.ndarray:
        for d in DILATIONS:
            x = nn.relu(nn.Conv(self.width, (3, 3), kernel_dilation=d, padding="SAME")(x))
        return nn.Conv(TAPS, (1, 1), kernel_init=nn.initializers.zeros, bias_init=_centre_bias)(x)


def example_features() -> jnp.ndarray:
    """Zero features of a small image, for `init`."""
    return jnp.zeros((8, 8, CHANNELS), jnp.float32)


def gather_taps(candidates: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
    """(H, W, TAPS, 3) each tap's estimate at each pixel and (H, W, TAPS) bool whether the tap
    lies inside the image, from (C, H, W, 3) candidates."""
    _, h, w, _ = candidates.shape
    offsets = tap_offsets()
    reach = int(abs(offsets[:, 1:]).max())
    padded = jnp.pad(candidates, ((0, 0), (reach, reach), (reach, reach), (0, 0)))
    inside = jnp.pad(jnp.ones((h, w), bool), reach)
    taps, masks = [], []
    for c, dy, dx in offsets:
        y, x = reach + int(dy), reach + int(dx)
        taps.append(padded[c, y : y + h, x : x + w])
        masks.append(inside[y : y + h, x : x + w])
    return jnp.stack(taps, axis=2), jnp.stack(masks, axis=2)


def apply_kernel(logits: jnp.ndarray, candidates: jnp.ndarray) -> jnp.ndarray:
    """(H, W, 3) the candidates (C, H, W, 3) weighed by the softmax of the (H, W, TAPS) logits
    over the taps inside the image."""
    taps, inside = gather_taps(candidates)
    weights = jax.nn.softmax(jnp.where(inside, logits, -1e30), axis=-1)
    return jnp.einsum("hwt,hwtc->hwc", weights, taps)


def clamp(
    filtered: jnp.ndarray, own: jnp.ndarray, count: jnp.ndarray, photon: jnp.ndarray,
    z: float = TRAIN_CLAMP_Z, other: jnp.ndarray | None = None,
    other_count: jnp.ndarray | None = None,
) -> jnp.ndarray:  # fmt: skip
    """(..., 3) `filtered` moved back toward `own` (..., 3), the estimate it is held around
    (`dpm.caustic.stats.clamp_centre`), until every channel is within z standard errors of it,
    or with `other` (..., 3) and `other_count` (...) within the hull of that interval and the
    one z standard errors about other (as `dpm.caustic.stats.clamp_to_centre`; count (...):
    photons behind own, photon: one photon's luminance)."""

    def error(m, n):
        return jnp.where(n[..., None] > 0,
                         jnp.maximum(m, filtered) / jnp.sqrt(jnp.maximum(n, 1.0))[..., None],
                         jnp.minimum(filtered, photon))  # fmt: skip

    if (other is None) != (other_count is None):
        raise ValueError("clamp: pass other and other_count together, or neither")
    reach = z * error(own, count)
    # (starting from own, as `dpm.caustic.stats._clamp` does: a negative reach allows no move)
    lo, hi = jnp.minimum(own, own - reach), jnp.maximum(own, own + reach)
    if other is not None:
        reach = z * error(other, other_count)
        lo, hi = jnp.minimum(lo, other - reach), jnp.maximum(hi, other + reach)
    allowed = jnp.where(filtered > own, hi - own, own - lo) + TINY  # the share below is 1
    keep = (allowed / jnp.maximum(jnp.abs(filtered - own) + TINY, allowed)).min(axis=-1)
    return (1 - keep[..., None]) * own + keep[..., None] * filtered  # within reach (no
    # `where` on the move: its gradient is NaN)


def filter_caustics(
    model: nn.Module, params: dict, features: jnp.ndarray, candidates: jnp.ndarray,
    own: jnp.ndarray, count: jnp.ndarray, photon: jnp.ndarray, z: float = TRAIN_CLAMP_Z,
    other: jnp.ndarray | None = None, other_count: jnp.ndarray | None = None,
) -> jnp.ndarray:  # fmt: skip
    """(H, W, 3) filtered caustic radiance of one image: features (H, W, CHANNELS), candidates
    (C, H, W, 3), own (H, W, 3) and count (H, W) the estimate it is held around and its photons,
    photon () one photon's luminance; other, other_count: the hull's second interval
    (`clamp`; the render's HULL_CLAMP, which training stores as the shard's `P/other`).
    Pure: jit and vmap it."""
    logits = model.apply(params, features)
    return clamp(apply_kernel(logits, candidates), own, count, photon, z, other, other_count)
