"""The fused CPU kernel of KernelNet (`dpm.nn.fused`) against XLA's flat matmuls."""

from __future__ import annotations

import os
import platform
import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dpm.nn.fused import PACKED, available, logits_kernel, pack_params, softplus, supports
from dpm.nn.infer import PhotonTable, Query, kernel_logits, query_radiance, use_fused
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


def test_fused_radiance_equals_the_xla_path(monkeypatch) -> None:
    """The whole fused estimate (reading the photon rows, normal check, canonical frame,
    features, network, Eq. 2) equals XLA's `query_radiance` within float rounding, with
    missing neighbours, disagreeing normals, a given frame angle, and under `vmap`."""
    rng = np.random.default_rng(3)
    n_photons, n, k = 400, 6, 37
    rows = np.zeros((n_photons + 1, 16), np.float32)
    rows[:-1, 0:3] = rng.normal(0, 0.05, (n_photons, 3)) + [10.0, 2.0, -5.0]
    rows[:-1, 3:6] = unit(rng.normal(size=(n_photons, 3)))
    rows[:-1, 6:9] = rng.uniform(0, 1e-4, (n_photons, 3))
    rows[:-1, 9:12] = unit(rng.normal(size=(n_photons, 3)) * 0.4 + [0, 0, 1])
    rows[:-1, 12:15] = rng.uniform(-1, 1, (n_photons, 3))
    index = rng.integers(0, n_photons, (n, k)).astype(np.int32)
    index[1, -5:] = n_photons  # missing neighbours
    position = np.float64([10.0, 2.0, -5.0]) + rng.normal(0, 0.01, (n, 3))
    hi = position.astype(np.float32)
    normal = unit(rng.normal(size=(n, 3)) * 0.2 + [0, 0, 1]).astype(np.float32)
    normal[2] = -normal[2]  # no photon agrees
    angle = np.full(n, np.nan, np.float32)
    angle[3] = 0.7
    q = Query(index, hi, (position - hi).astype(np.float32), normal,
              rng.uniform(0.2, 0.9, (n, 3)).astype(np.float32),
              rng.uniform(0.02, 0.1, n).astype(np.float32), angle,
              np.full(n, 1e5, np.float32))  # fmt: skip
    params = {"params": random_params(32, 4)}
    table = PhotonTable(jnp.asarray(rows))
    fused = np.asarray(jax.jit(lambda *a: query_radiance(*a))(params, table, q))
    monkeypatch.setattr("dpm.nn.infer.FUSED", False)  # a new function: traced afresh
    xla = np.asarray(jax.jit(lambda *a: query_radiance(*a))(params, table, q))
    assert np.all(fused[2] == 0) and np.abs(xla).max() > 0
    np.testing.assert_allclose(fused, xla, rtol=1e-4, atol=1e-5 * np.abs(xla).max())
    monkeypatch.setattr("dpm.nn.infer.FUSED", True)
    stacked = Query(*(np.stack([a, a]) for a in q))
    batched = jax.jit(jax.vmap(lambda *a: query_radiance(*a), (None, None, 0)))(
        params, table, stacked
    )
    np.testing.assert_array_equal(np.asarray(batched), np.stack([fused, fused]))


def test_softplus_without_libm_is_within_an_ulp() -> None:
    """Eq. 2's weight log(1 + e^u), computed without libm calls so that its loop vectorizes,
    is within an ulp of float32 over the range of logits (and keeps inf and NaN)."""
    import numba as nb

    @nb.njit
    def each(u):
        out = np.empty_like(u)
        for i in range(len(u)):
            out[i] = softplus(u[i])
        return out

    u = np.concatenate([np.linspace(-80, 90, 200_001), [0.0, -0.0, 1e-30, -1e-30]])
    u = u.astype(np.float32)
    got = each(u).astype(np.float64)
    exact = np.logaddexp(0.0, u.astype(np.float64))
    normal = exact > np.finfo(np.float32).tiny
    assert np.all(np.abs(got - exact)[normal] <= 2.0**-23 * exact[normal])
    assert np.all(got[~normal] <= np.finfo(np.float32).tiny)
    special = each(np.float32([np.inf, -np.inf, np.nan]))
    assert special[0] == np.inf and special[1] == 0.0 and np.isnan(special[2])


def unit(v: np.ndarray) -> np.ndarray:
    """Rows of v (n, 3) scaled to unit length."""
    return v / np.linalg.norm(v, axis=1, keepdims=True)


def test_the_kernel_serves_the_shipped_weights_only_where_it_applies() -> None:
    """The shipped DPM weights render with the fused kernel on the CPU; other widths
    (DPM-L) keep XLA's matmuls."""
    for k in (50, 500):
        assert use_fused(load_weights(shipped_weights(k)).params["params"]) == available()
    wide = random_params(128, 0)
    assert not supports(wide) and not use_fused(wide)
    assert pack_params(random_params(32, 1)).shape == (PACKED,)


# Haswell's features without AVX-512: what an AVX2-only host compiles for
AVX2 = ",".join(
    ["+64bit", "+avx", "+avx2", "+fma", "+sse", "+sse2", "+sse3", "+ssse3", "+sse4.1", "+sse4.2",
     "+popcnt", "+bmi", "+bmi2", "+f16c", "+lzcnt", "+movbe", "+cx16", "+xsave", "-avx512f",
     "-avx512bw", "-avx512dq", "-avx512vl", "-avx512cd"]
)  # fmt: skip


@pytest.mark.skipif(platform.machine() not in ("x86_64", "AMD64"), reason="x86 vector widths")
def test_fused_kernel_on_avx2_code(tmp_path) -> None:
    """Compiled for an AVX2-only CPU (8-float vectors, 2-photon blocks), the kernel still
    equals the flat matmuls: the variant AVX2 hosts run, which this host would not test."""
    if "avx2" not in open("/proc/cpuinfo").read():
        pytest.skip("this CPU cannot run AVX2 code")
    script = (
        "from dpm.nn import fused\n"
        "assert (fused.LANES, fused.PHOTONS) == (8, 2), (fused.LANES, fused.PHOTONS)\n"
        "import test_fused\n"
        "for n, k in [(5, 50), (3, 7), (1, 500), (2, 1)]:\n"
        "    test_fused.test_fused_kernel_equals_the_flat_matmuls(n, k)\n"
    )
    env = {**os.environ, "NUMBA_CPU_NAME": "haswell", "NUMBA_CPU_FEATURES": AVX2,
           "NUMBA_CACHE_DIR": str(tmp_path)}  # fmt: skip
    done = subprocess.run(
        [sys.executable, "-c", script], cwd=Path(__file__).parent, env=env,
        capture_output=True, text=True, timeout=600,
    )  # fmt: skip
    assert done.returncode == 0, done.stderr[-2000:]
