"""The nppm network: per visible point, the two precisions of its shaped kernel
(dpm.density.shaped) from the FEATURES of its photon statistics, once per point per pass.

A small MLP (two hidden layers of `width`, ReLU) whose last layer starts at zero, so a fresh
network gives p = 0: the uniform kernel, and nppm is PPM exactly. Inference is one pure
function, `jax.jit(jax.vmap(...))` over points, run on buckets of power-of-two sizes so that a
render compiles it a few times, not once per pass.
"""

from __future__ import annotations

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from dpm.density.shaped import FEATURES, precision

MIN_BUCKET = 1024  # the smallest padded batch of points


class ShapeNet(nn.Module):
    """(2,) raw outputs (before `precision`) of one point from its (FEATURES,) input."""

    width: int = 32

    @nn.compact
    def __call__(self, x: jnp.ndarray) -> jnp.ndarray:
        h = x
        for _ in range(2):
            h = nn.relu(nn.Dense(self.width)(h))
        return nn.Dense(2, kernel_init=nn.initializers.zeros)(h)


def point_precisions(model: nn.Module, params: dict, x: jnp.ndarray) -> jnp.ndarray:
    """(2,) precisions p₁, p₂ (units of 1/R²) of one point from its (FEATURES,) input."""
    return precision(model.apply(params, x), jnp)


def init_shape_params(model: nn.Module, seed: int) -> dict:
    """Fresh parameters of `model` (the uniform kernel)."""
    return model.init(jax.random.key(seed), jnp.zeros(FEATURES, jnp.float32))


class ShapePredictor:
    """A network's jitted, vmapped inference over points, with its parameters."""

    def __init__(self, model: nn.Module, params: dict) -> None:
        self.params = jax.tree.map(jnp.asarray, params)
        self._predict = jax.jit(jax.vmap(lambda p, x: point_precisions(model, p, x), (None, 0)))

    def __call__(self, x: np.ndarray) -> np.ndarray:
        """(n, 2) float64 precisions from features (n, FEATURES) float32."""
        n = len(x)
        if n == 0:
            return np.zeros((0, 2))
        size = max(MIN_BUCKET, 1 << (n - 1).bit_length())
        padded = np.zeros((size, FEATURES), np.float32)
        padded[:n] = x
        return np.asarray(self._predict(self.params, padded))[:n].astype(np.float64)
