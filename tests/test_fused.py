"""The fused CPU kernel of KernelNet (`dpm.nn.fused`) against XLA's flat matmuls."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dpm.nn.fused import PACKED, fused_logits, logits_kernel, pack_params, supports
from dpm.nn.infer import kernel_logits, use_fused
from dpm.nn.model import make_model
from dpm.nn.weights import load_weights, shipped_weights


def random_params(width: int, seed: int) -> dict:
    """KernelNet params (the "params" tree) of `width` channels with every weight random."""
    model = make_model("dpm", width)
    x = jnp.zeros((4, 9), jnp.float32)
    params = model.init(jax.random.key(seed), x, jnp.ones(4, bool))
    rng = np.random.default_rng(seed)
    return jax.tree.map(lambda a: jnp.asarray(rng.normal(0, 0.4, a.shape), jnp.float32), params)[
        "params"
    ]


@pytest.mark.parametrize("n, k", [(5, 50), (3, 7), (1, 500), (9, 16), (2, 1)])
def test_fused_kernel_equals_the_flat_matmuls(n: int, k: int) -> None:
    """Logits agree within float rounding for K not a multiple of the vector width, a last
    partial tile, and a point with no valid photon (its context the empty one)."""
    p = random_params(32, n * 100 + k)
    rng = np.random.default_rng(k)
    x = rng.normal(0, 1, (9, n, k)).astype(np.float32)
    valid = rng.random((n, k)) > 0.3
    valid[0] = False
    expected = np.asarray(kernel_logits(p, jnp.asarray(x), jnp.asarray(valid)))
    out = np.empty(n * k, np.float32)
    logits_kernel(x.reshape(9, -1), valid.astype(np.float32), np.asarray(pack_params(p)), out)
    scale = np.abs(expected).max()
    np.testing.assert_allclose(out.reshape(n, k), expected, rtol=1e-5, atol=1e-5 * scale)
    jitted = jax.jit(jax.vmap(fused_logits, (None, 0, 0)))  # also under vmap
    batched = np.asarray(jitted(pack_params(p), jnp.asarray(x)[None], jnp.asarray(valid)[None]))
    np.testing.assert_array_equal(batched[0], out.reshape(n, k))


def test_the_kernel_serves_the_shipped_weights_only_where_it_applies() -> None:
    """The shipped DPM weights render with the fused kernel on the CPU; other widths
    (DPM-L) keep XLA's matmuls."""
    for k in (50, 500):
        assert use_fused(load_weights(shipped_weights(k)).params["params"])
    wide = random_params(128, 0)
    assert not supports(wide) and not use_fused(wide)
    assert pack_params(random_params(32, 1)).shape == (PACKED,)
