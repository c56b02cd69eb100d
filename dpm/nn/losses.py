"""The training losses (`[train] loss` and `balance`), on radiance in W/(m² sr).

`LOSSES` names them: 'mu-law' is the paper's L2 after the μ-law tone mapping of Eq. 4. Its
minimiser is the mean of μ(target), below μ(mean target) when targets are noisy, so with our
PPM targets it learns to darken (measured: a 2.6× too dark mean on held-out scenes).
'relmse' (Noise2Noise's relative L2, the denominator from the prediction, not the target)
has the target's mean as its minimiser, so noisy references teach no bias; so has 'mse'.
relmse weighs a dim point as much as a bright one and taught kernels that sharpen
everywhere, which wins with few photons and loses where a caustic is bright and dense
(measured: held-out RMSE 1.25× PM-50's at 10⁶ paths); mse, the metric the benchmarks
report, taught kernels that barely leave the uniform one. 'mse+relmse' (the mean of both,
balanced) keeps most of each.

Balanced (`balanced_loss`), each (scene, budget) part's loss is divided by the uniform
kernel's (PM-K's) on the same points. Unbalanced, the sparse budgets' large errors dominate
the gradient, and the network learned corrections that help there but lose to PM-K at dense
budgets (measured on held-out scenes: 1.45× PM-50's RMSE at 10⁶ paths); balanced, every
budget counts for how much it beats PM-K.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

MU = 5000.0  # μ of the loss's tone mapping (Eq. 4)
LOSSES = ("mu-law", "relmse", "mse", "mse+relmse")
RELMSE_EPSILON = 0.01  # radiance added to the prediction in relmse's denominator


def mu_law(v: jnp.ndarray) -> jnp.ndarray:
    """(…) μ-law tone mapping of Eq. 4 of radiance v (negative values count as 0)."""
    return jnp.log1p(MU * jnp.maximum(v, 0.0)) / jnp.log1p(MU)


def point_loss(estimate: jnp.ndarray, target: jnp.ndarray, name: str) -> jnp.ndarray:
    """(N,) loss `name` of each point's estimated against target radiance (N, 3), W/(m² sr)."""
    if name == "relmse":
        scale = jax.lax.stop_gradient(estimate) + RELMSE_EPSILON
        return jnp.mean(((estimate - target) / scale) ** 2, axis=-1)
    if name == "mse":
        return jnp.mean((estimate - target) ** 2, axis=-1)
    return jnp.mean((mu_law(estimate) - mu_law(target)) ** 2, axis=-1)


def loss_value(estimate: jnp.ndarray, target: jnp.ndarray, name: str) -> jnp.ndarray:
    """The mean loss `name` between estimated and target radiance, both (N, 3) W/(m² sr)."""
    return jnp.mean(point_loss(estimate, target, name))


def balanced_loss(
    estimate: jnp.ndarray, uniform: jnp.ndarray, target: jnp.ndarray, part: jnp.ndarray, name: str
) -> jnp.ndarray:
    """Mean over the batch's parts (part (N,) int) of the loss of estimate (N, 3) divided by
    that of the uniform kernel's estimate (N, 3) on the same points: 1 is PM-K, below beats it."""
    n = part.shape[0]
    num = jax.ops.segment_sum(point_loss(estimate, target, name), part, n)
    den = jax.ops.segment_sum(point_loss(uniform, target, name), part, n)
    used = den > 0
    ratio = jnp.where(used, num / jnp.where(used, den, 1.0), 0.0)
    return jnp.sum(ratio) / jnp.maximum(jnp.sum(used), 1)


def training_loss(
    estimate: jnp.ndarray,
    target: jnp.ndarray,
    name: str,
    uniform: jnp.ndarray | None = None,
    part: jnp.ndarray | None = None,
) -> jnp.ndarray:
    """The loss `name` of one of LOSSES ('a+b': the mean of both) of estimated against target
    radiance, both (N, 3) W/(m² sr); balanced when given the uniform kernel's estimate (N, 3)
    and each point's (scene, budget) part (N,) int32."""
    names = name.split("+")
    if uniform is not None:
        values = [balanced_loss(estimate, uniform, target, part, n) for n in names]
    else:
        values = [loss_value(estimate, target, n) for n in names]
    return sum(values) / len(values)
