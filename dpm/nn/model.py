"""The DPM networks (paper §4.2): PointNet-style over the K photons of one visible point.

- `KernelNet` (DPM, and DPM-L with 4× channels): a feature extractor (three dense layers with
  ReLU, to `width` channels) per photon; max- and average-pooling over the valid photons give
  the context; a kernel predictor (three dense layers) on [photon feature, context] gives one
  kernel weight per photon.
- `DirectNet`: the paper's ablation baseline; the same extractor and pooling, then three dense
  layers from the context straight to the radiance.

Both map one point's (K, 9) features and (K,) validity to an output; the estimate (Eq. 2)
and batching live in `dpm.nn.infer`.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp

from dpm.density.shaped import FEATURES
from dpm.nn.caustic_net import CausticNet, example_features
from dpm.nn.features import CHANNELS, flux_unmap
from dpm.nn.shape_net import ShapeNet

# softplus(x + SHIFT) = 1 at x = 0: a zero last layer starts as the uniform kernel (PM), and
# weights stay positive, so the estimate is never negative.
SHIFT = float(jnp.log(jnp.expm1(1.0)))


class Extractor(nn.Module):
    """Per-photon features (K, width) and the pooled context (2·width,)."""

    width: int

    @nn.compact
    def __call__(self, x: jnp.ndarray, valid: jnp.ndarray) -> tuple[jnp.ndarray, jnp.ndarray]:
        h = x
        for _ in range(3):
            h = nn.relu(nn.Dense(self.width)(h))
        count = jnp.maximum(valid.sum(), 1)
        biggest = jnp.max(jnp.where(valid[:, None], h, -jnp.inf), axis=0)
        biggest = jnp.where(valid.any(), biggest, 0.0)  # no valid photon: an empty context
        mean = jnp.sum(jnp.where(valid[:, None], h, 0.0), axis=0) / count
        return h, jnp.concatenate([biggest, mean])


class KernelNet(nn.Module):
    """(K,) positive kernel weights of one point from its (K, 9) features and (K,) validity."""

    width: int = 32

    @nn.compact
    def __call__(self, x: jnp.ndarray, valid: jnp.ndarray) -> jnp.ndarray:
        h, context = Extractor(self.width)(x, valid)
        z = jnp.concatenate([h, jnp.broadcast_to(context, (h.shape[0], context.shape[0]))], -1)
        for _ in range(2):
            z = nn.relu(nn.Dense(self.width)(z))
        z = nn.Dense(1, kernel_init=nn.initializers.zeros)(z)[:, 0]
        return jnp.where(valid, jax.nn.softplus(z + SHIFT), 0.0)


class DirectNet(nn.Module):
    """(3,) mean photon power in the disc (the flux input's units) regressed from the context."""

    width: int = 32

    @nn.compact
    def __call__(self, x: jnp.ndarray, valid: jnp.ndarray) -> jnp.ndarray:
        _, z = Extractor(self.width)(x, valid)
        for _ in range(2):
            z = nn.relu(nn.Dense(self.width)(z))
        # through the inverse of the input's flux map; the sigmoid keeps gradients alive
        return flux_unmap(2.0 * jax.nn.sigmoid(nn.Dense(3)(z)) - 1.0)


ARCHITECTURES = {
    "dpm": (KernelNet, 1), "dpm-l": (KernelNet, 4), "direct": (DirectNet, 1),
    "nppm": (ShapeNet, 1), "caustic": (CausticNet, 1),
}  # fmt: skip


def make_model(architecture: str, width: int = 32) -> nn.Module:
    """The network called 'dpm', 'dpm-l' (4× channels), 'direct', 'nppm' (the shape network
    of dpm.nn.shape_net) or 'caustic' (auto's caustic filter, dpm.nn.caustic_net), base
    width `width`."""
    cls, factor = ARCHITECTURES[architecture]
    return cls(width=width * factor)


def example_input(architecture: str, k: int) -> tuple[jnp.ndarray, ...]:
    """Zero arguments of the right shapes for `init` of network `architecture` on K photons."""
    if architecture == "nppm":
        return (jnp.zeros(FEATURES, jnp.float32),)
    if architecture == "caustic":
        return (example_features(),)
    return jnp.zeros((k, CHANNELS), jnp.float32), jnp.ones(k, bool)
