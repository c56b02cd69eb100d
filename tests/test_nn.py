"""The learned estimator: pre-processing invariances, jit/vmap inference against a plain
implementation, training steps, kill-and-resume, weight files and the CLI."""

from __future__ import annotations

import os
import subprocess
import sys
import tomllib
from dataclasses import replace
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from dpm.cli import render_main, train_main
from dpm.data.dataset import DataConfig
from dpm.errors import InputError
from dpm.estimators import PM
from dpm.nn.config import Config, ModelConfig, TrainConfig, load_config
from dpm.nn.features import flux_map, flux_unmap
from dpm.nn.fused import available
from dpm.nn.infer import (
    Batch,
    make_predict,
    make_query_predict,
    neighbourhoods,
    point_radiance,
    predict_points,
    use_fused,
)
from dpm.nn.losses import loss_value, mu_law
from dpm.nn.model import make_model
from dpm.nn.sampler import Sampler
from dpm.nn.sharding import DataParallel
from dpm.nn.train import init_params, make_steps, train
from dpm.nn.weights import Weights, load_weights, save_weights
from dpm.tracer import PhotonMap, VisiblePoints

ROOT = Path(__file__).parent.parent
K = 16


def plane_photons(n: int, seed: int) -> PhotonMap:
    """n photons on the plane y = 0 with a lumpy density, random flux and directions."""
    rng = np.random.default_rng(seed)
    xz = rng.random((n, 2)) ** 1.5
    d = rng.normal(size=(n, 3))
    d[:, 1] = np.abs(d[:, 1]) + 0.1
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    up = np.tile(np.float32([0, 1, 0]), (n, 1))
    return PhotonMap(
        np.c_[xz[:, 0], np.zeros(n), xz[:, 1]].astype(np.float32), d.astype(np.float32),
        (rng.random((n, 3)) * 3 / n).astype(np.float32), up, np.ones(n, bool),
        np.ones(n, np.uint16), np.arange(n), n,
    )  # fmt: skip


def random_params(model, seed: int) -> dict:
    """Parameters with every layer random (the last layer too, unlike a fresh init)."""
    params = init_params(model, K, seed)
    leaves, tree = jax.tree.flatten(params)
    keys = jax.random.split(jax.random.key(seed + 1), len(leaves))
    leaves = [0.5 * jax.random.normal(key, x.shape) for key, x in zip(keys, leaves, strict=True)]
    return jax.tree.unflatten(tree, leaves)


@pytest.fixture(scope="module")
def one_point() -> Batch:
    """The K nearest photons of one visible point, as a Batch of one (canonical frame)."""
    photons = plane_photons(3000, 0)
    p = np.float32([[0.4, 0.0, 0.5]])
    n = np.float32([[0, 1, 0]])
    return next(neighbourhoods(photons, p, n, np.float32([[0.5, 0.6, 0.7]]), K))[1]


def estimate(model, params, b: Batch) -> np.ndarray:
    return np.asarray(make_predict(model)(params, b))[0]


def rotation(axis: np.ndarray, angle: float) -> np.ndarray:
    """3×3 rotation by angle about the unit axis (Rodrigues)."""
    k = np.array([[0, -axis[2], axis[1]], [axis[2], 0, -axis[0]], [-axis[1], axis[0], 0]])
    return np.eye(3) + np.sin(angle) * k + (1 - np.cos(angle)) * k @ k


@pytest.mark.parametrize("architecture", ["dpm", "direct"])
def test_preprocessing_invariances(one_point: Batch, architecture: str) -> None:
    """Translation and rotation about the normal leave the estimate unchanged; scaling the
    positions by s scales it by 1/s² (same kernel, s² the area); N × c with each photon's
    flux ÷ c and the positions ÷ √c (the same irradiance sampled c times more densely)
    leaves it unchanged."""
    model = make_model(architecture, 8)
    params = random_params(model, 3)
    if architecture == "direct":  # lift its output off the clamp at zero power
        params["params"]["Dense_2"]["bias"] = params["params"]["Dense_2"]["bias"] + 1.0
    b = one_point
    base = estimate(model, params, b)
    assert np.all(np.isfinite(base)) and base.max() > 0
    # translation: offsets are relative to the point already; move the whole scene
    photons = plane_photons(3000, 0)
    shift = np.float32([3.0, -2.0, 7.5])
    moved = replace(photons, position=photons.position + shift)
    p = np.float32([[0.4, 0.0, 0.5]]) + shift
    b2 = next(neighbourhoods(moved, p, b.normal, b.albedo, K))[1]
    np.testing.assert_allclose(estimate(model, params, b2), base, rtol=1e-4)
    # rotation about the normal (any angle), and a tilted plane (rotating the normal too)
    for axis, angle in ((b.normal[0], 0.7), (b.normal[0], 2.9), (np.float32([1, 0, 0]), 0.4)):
        r = rotation(np.asarray(axis, np.float64), angle).astype(np.float32)
        turned = b._replace(offset=b.offset @ r.T, direction=b.direction @ r.T,
                            normal=b.normal @ r.T)  # fmt: skip
        np.testing.assert_allclose(estimate(model, params, turned), base, rtol=1e-4)
    s = 3.7
    scaled = b._replace(offset=b.offset * s, radius=b.radius * s)
    np.testing.assert_allclose(estimate(model, params, scaled), base / s**2, rtol=1e-4)
    c = 8.0
    denser = b._replace(offset=b.offset / np.sqrt(c), radius=b.radius / np.sqrt(c),
                        flux=b.flux / c, n_paths=b.n_paths * c)  # fmt: skip
    np.testing.assert_allclose(estimate(model, params, denser), base, rtol=1e-4)


def test_flux_map_is_eq3_and_inverts() -> None:
    u = jnp.array([0.0, 1e-3, 0.5, 10.0, 1e4])
    t = (jnp.log(u + 0.01) - jnp.log(0.01)) / (jnp.log(u + 0.01) - jnp.log(0.01) + 1)
    np.testing.assert_allclose(flux_map(u), 2 * t - 1, atol=1e-6)
    np.testing.assert_allclose(flux_unmap(flux_map(u)), u, rtol=1e-4, atol=1e-9)


def plain_radiance(params: dict, b: Batch, i: int) -> np.ndarray:
    """A per-point numpy forward pass of KernelNet, written out from the paper."""
    p = jax.tree.map(np.asarray, params)["params"]
    n = b.normal[i].astype(np.float64)
    sign = 1.0 if n[2] >= 0 else -1.0
    a = -1.0 / (sign + n[2])
    bb = n[0] * n[1] * a
    t = np.array([1 + sign * n[0] ** 2 * a, sign * bb, -sign * n[0]])
    s = np.array([bb, sign + n[1] ** 2 * a, -n[1]])
    valid = b.valid[i]
    centre = b.offset[i][valid].sum(axis=0)
    ang = np.arctan2(centre @ s, centre @ t)
    t1, t2 = np.cos(ang) * t + np.sin(ang) * s, -np.sin(ang) * t + np.cos(ang) * s
    frame = np.stack([t1, t2, n])
    u = np.log1p(b.flux[i] * b.n_paths[i] / 0.01)
    x = np.concatenate([b.offset[i] @ frame.T / b.radius[i], b.direction[i] @ frame.T,
                        2 * u / (u + 1) - 1], axis=1)  # fmt: skip

    def dense(layer, h):
        return h @ layer["kernel"] + layer["bias"]

    h = x
    for j in range(3):
        h = np.maximum(dense(p["Extractor_0"][f"Dense_{j}"], h), 0)
    context = np.concatenate([h[valid].max(axis=0), h[valid].mean(axis=0)])
    z = np.concatenate([h, np.tile(context, (len(h), 1))], axis=1)
    for j in range(2):
        z = np.maximum(dense(p[f"Dense_{j}"], z), 0)
    z = dense(p["Dense_2"], z)[:, 0] + np.log(np.expm1(1.0))
    w = np.where(valid, np.log1p(np.exp(z)), 0.0)
    total = (w[:, None] * b.flux[i]).sum(axis=0)
    return b.albedo[i] / np.pi * total / (np.pi * b.radius[i] ** 2)


def test_jit_vmap_inference_equals_a_plain_per_point_implementation(monkeypatch) -> None:
    photons = plane_photons(5000, 1)
    rng = np.random.default_rng(2)
    n = 200
    position = np.c_[rng.random(n), np.zeros(n), rng.random(n)].astype(np.float32)
    normal = np.tile(np.float32([0, 1, 0]), (n, 1))
    normal[::7] = np.float32([0, -1, 0])  # disagreeing normals: no valid photon, black
    albedo = rng.uniform(0.2, 0.9, (n, 3)).astype(np.float32)
    model = make_model("dpm", 8)
    params = random_params(model, 5)
    monkeypatch.setattr("dpm.nn.infer.ACTIVATIONS_PER_CHUNK", 64 * K)  # several chunks
    out = predict_points(make_query_predict(model), params, photons, position, normal, albedo, K)
    b = next(neighbourhoods(photons, position, normal, albedo, K))[1]
    plain = np.array([plain_radiance(params, b, i) if b.valid[i].any() else np.zeros(3)
                      for i in range(n)])  # fmt: skip
    assert np.all(out[::7] == 0)
    np.testing.assert_allclose(out, plain, rtol=2e-4, atol=1e-7)


@pytest.mark.parametrize("fused", [True, False])
@pytest.mark.parametrize("n_photons", [3000, K])
def test_fast_inference_equals_the_flax_module_point_by_point(
    n_photons: int, fused: bool, monkeypatch
) -> None:
    """`make_query_predict` (photons gathered inside the jit; the fused CPU kernel, or
    feature-major flat matmuls) equals the Flax module applied point by point to
    numpy-gathered Batches, far from the origin (the offsets keep their float64 accuracy), and
    with exactly K photons."""
    monkeypatch.setattr("dpm.nn.infer.FUSED", fused)
    shift = np.float32([1000.0, 0.0, -2000.0])
    photons = plane_photons(n_photons, 7)
    photons = replace(photons, position=photons.position + shift)
    rng = np.random.default_rng(8)
    n = 150
    position = (np.c_[rng.random(n), np.zeros(n), rng.random(n)] + shift).astype(np.float64)
    normal = np.tile(np.float32([0, 1, 0]), (n, 1))
    normal[::9] = np.float32([0, -1, 0])  # no valid photon
    albedo = rng.uniform(0.2, 0.9, (n, 3)).astype(np.float32)
    model = make_model("dpm", 32)  # the fused kernel's width
    params = random_params(model, 9)
    assert use_fused(params["params"]) == (fused and available())
    fast = predict_points(make_query_predict(model), params, photons, position, normal, albedo, K)
    b = next(neighbourhoods(photons, position, normal, albedo, K))[1]
    slow = jax.jit(jax.vmap(lambda p, one: point_radiance(model, p, one), (None, 0)))
    plain = np.asarray(slow(params, b))
    assert np.all(fast[::9] == 0) and np.all(plain[::9] == 0)
    assert np.abs(plain).max() > 0
    np.testing.assert_allclose(fast, plain, rtol=1e-4, atol=1e-6 * np.abs(plain).max())


@pytest.mark.parametrize("fused", [True, False])
def test_the_estimate_is_linear_in_the_lights_power(fused: bool, monkeypatch) -> None:
    """Every photon c times brighter (every light c times brighter, or a scene scaled by
    √c with its radiance kept) gives c times the estimate, at 10⁻⁴ and 10⁴ as at 1: the
    features see each photon's power relative to its map's (`feature_paths`), and Eq. 2 is
    linear in the stored flux. With the paper's absolute power the kernels changed."""
    monkeypatch.setattr("dpm.nn.infer.FUSED", fused)
    photons = plane_photons(3000, 12)
    rng = np.random.default_rng(13)
    n = 120
    position = np.c_[rng.random(n), np.zeros(n), rng.random(n)].astype(np.float32)
    normal = np.tile(np.float32([0, 1, 0]), (n, 1))
    albedo = rng.uniform(0.2, 0.9, (n, 3)).astype(np.float32)
    model = make_model("dpm", 32)
    params = random_params(model, 14)
    predict = make_query_predict(model)
    base = predict_points(predict, params, photons, position, normal, albedo, K)
    assert np.abs(base).max() > 0
    for c in (1e-4, 1e4):
        bright = replace(photons, flux=photons.flux * np.float32(c))
        out = predict_points(predict, params, bright, position, normal, albedo, K)
        np.testing.assert_allclose(out / c, base, rtol=2e-4, atol=1e-6 * np.abs(base).max())
    # the Batch path (training's) sees the same inputs too
    b1 = next(neighbourhoods(photons, position, normal, albedo, K))[1]
    b2 = next(neighbourhoods(replace(photons, flux=photons.flux * np.float32(1e4)), position,
                             normal, albedo, K))[1]  # fmt: skip
    np.testing.assert_allclose(
        b2.flux * b2.n_paths[:, None, None], b1.flux * b1.n_paths[:, None, None], rtol=1e-5
    )


def test_a_fresh_network_is_the_uniform_kernel() -> None:
    """The kernel predictor's last layer starts at zero: weights 1, i.e. PM (Eq. 1)."""
    photons = plane_photons(4000, 3)
    rng = np.random.default_rng(4)
    n = 100
    points = VisiblePoints(
        np.c_[rng.random(n), np.zeros(n), rng.random(n)].astype(np.float32),
        np.tile(np.float32([0, 1, 0]), (n, 1)), np.full((n, 3), 0.5, np.float32),
        np.ones((n, 3), np.float32), np.zeros((n, 3), np.float32), np.ones(n, bool),
        np.arange(n, dtype=np.int32), np.arange(n),
    )  # fmt: skip
    model = make_model("dpm", 8)
    out = predict_points(make_query_predict(model), init_params(model, K, 0), photons,
                         points.position, points.normal, points.albedo, K)  # fmt: skip
    np.testing.assert_allclose(out, PM(k=K).estimate(points, photons), rtol=1e-5)


def plane_batch(n: int, seed: int) -> Batch:
    """The K nearest plane photons of n random points on the plane (normal +y, albedo 0.6)."""
    rng = np.random.default_rng(seed)
    position = np.c_[rng.random(n), np.zeros(n), rng.random(n)].astype(np.float32)
    return next(neighbourhoods(plane_photons(3000, 6), position,
                               np.tile(np.float32([0, 1, 0]), (n, 1)),
                               np.full((n, 3), 0.6, np.float32), K))[1]  # fmt: skip


def test_one_training_step_lowers_the_loss_on_a_fixed_batch(one_point: Batch) -> None:
    n = 64
    b = plane_batch(n, 7)
    target = np.full((n, 3), 0.05, np.float32)
    for architecture in ("dpm", "dpm-l", "direct"):
        model = make_model(architecture, 8)
        optimiser, loss, step = make_steps(model, 1e-3, "mu-law", balance=False)
        params = init_params(model, K, 0)
        before = float(loss(params, b, target))
        params, _, value = step(params, optimiser.init(params), b, target)
        assert float(value) == pytest.approx(before)
        assert float(loss(params, b, target)) < before, architecture


def test_balanced_loss_is_one_for_the_uniform_kernel_and_trains() -> None:
    """The fresh DPM network is the uniform kernel (PM-K): balanced against PM-K its loss is
    1 on any batch, whatever each part's scale; a μ-law or MSE step lowers it (relmse's
    gradient is the Noise2Noise surrogate's, whose first step need not lower relmse itself)."""
    n = 64
    b = plane_batch(n, 3)
    target = np.repeat(np.float32([[0.05], [5.0]]), n // 2, axis=0) * np.ones(3, np.float32)
    part = np.repeat(np.int32([0, 1]), n // 2)
    model = make_model("dpm", 8)
    for name in ("relmse", "mu-law", "mse", "mse+relmse"):
        optimiser, loss, step = make_steps(model, 1e-3, name, balance=True)
        params = init_params(model, K, 0)
        assert float(loss(params, b, target, part)) == pytest.approx(1.0, rel=1e-5)
        if name in ("mu-law", "mse"):
            params, _, _ = step(params, optimiser.init(params), b, target, part)
            assert float(loss(params, b, target, part)) < 1.0


def test_cosine_schedule_falls_to_no_step_at_the_last() -> None:
    """`[train] schedule = 'cosine'`: the first step moves the weights as the constant rate's
    does, and once `steps` steps are taken a step leaves them where they are."""
    n = 64
    b = plane_batch(n, 7)
    target = np.full((n, 3), 0.05, np.float32)
    model = make_model("dpm", 8)
    params = init_params(model, K, 0)
    moved = {}
    for schedule in ("constant", "cosine"):
        optimiser, _, step = make_steps(model, 1e-3, "mse", False, schedule=schedule, steps=3)
        p, state = params, optimiser.init(params)
        for _ in range(3):
            p, state, _ = step(p, state, b, target)
        first = step(params, optimiser.init(params), b, target)[0]
        moved[schedule] = first
        after = step(p, state, b, target)[0]
        still = all(
            np.array_equal(x, y)
            for x, y in zip(jax.tree.leaves(p), jax.tree.leaves(after), strict=True)
        )
        assert still == (schedule == "cosine")
    for x, y in zip(*(jax.tree.leaves(moved[k]) for k in ("constant", "cosine")), strict=True):
        np.testing.assert_allclose(np.asarray(x), np.asarray(y), rtol=1e-6)


def steps_over(devices: DataParallel | None, steps: int = 3) -> list[np.ndarray]:
    """The parameters' leaves after `steps` balanced mse+relmse steps on fixed batches of 64
    points in 4 parts, each batch split over `devices` (None: not sharded)."""
    model = make_model("dpm", 8)
    optimiser, _, step = make_steps(model, 1e-2, "mse+relmse", balance=True)
    params = init_params(model, K, 0)
    opt_state = optimiser.init(params)
    if devices is not None:
        params, opt_state = devices.replicate(params), devices.replicate(opt_state)
    for s in range(steps):
        batch = plane_batch(64, 10 + s)
        target = np.random.default_rng(s).random((64, 3)).astype(np.float32) * 0.1
        data = (batch, target, np.repeat(np.arange(4, dtype=np.int32), 16))
        params, opt_state, _ = step(params, opt_state, *(devices.split(data) if devices else data))
    return [np.asarray(x) for x in jax.tree.leaves(params)]


def test_the_sharded_step_on_one_device_is_the_plain_step() -> None:
    one = DataParallel(jax.devices()[:1])
    for a, b in zip(steps_over(None), steps_over(one), strict=True):
        np.testing.assert_array_equal(a, b)
    with pytest.raises(InputError, match="multiple of the 3 JAX devices"):
        DataParallel(jax.devices()[:1] * 3).check("[train] batch", 64)


def test_the_sharded_step_over_two_devices_equals_the_plain_step() -> None:
    # two host devices exist only if XLA is told before JAX starts: a fresh interpreter
    code = (
        "import jax, numpy as np, test_nn\n"
        "from dpm.nn.sharding import DataParallel\n"
        "assert len(jax.devices()) == 2\n"
        "a, b = test_nn.steps_over(None), test_nn.steps_over(DataParallel())\n"
        "print(max(float(np.abs(x - y).max() / np.abs(x).max()) for x, y in zip(a, b)))\n"
    )
    env = {**os.environ, "XLA_FLAGS": "--xla_force_host_platform_device_count=2",
           "PYTHONPATH": str(Path(__file__).parent), "JAX_PLATFORMS": "cpu"}  # fmt: skip
    done = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    assert done.returncode == 0, done.stderr[-2000:]
    assert float(done.stdout.split()[-1]) < 1e-5  # the same step, float sums in another order


def test_mu_law_is_eq4() -> None:
    v = jnp.array([0.0, 0.01, 1.0, 50.0])
    np.testing.assert_allclose(mu_law(v), np.log(1 + 5000 * v) / np.log(5001), rtol=1e-6)
    assert float(mu_law(jnp.array(-1.0))) == 0.0


@pytest.fixture(scope="module")
def tiny(tmp_path_factory) -> Config:
    """configs/tiny.toml with its folders moved under a temporary directory."""
    root = tmp_path_factory.mktemp("tiny")
    text = (ROOT / "configs" / "tiny.toml").read_text()
    text = text.replace('"runs/', f'"{root}/')
    path = root / "tiny.toml"
    path.write_text(text)
    return load_config(path)


def test_kill_and_resume_gives_the_same_parameters(tiny: Config, monkeypatch) -> None:
    steps = 12
    whole = replace(tiny, train=replace(tiny.train, steps=steps, out=tiny.train.out + "-whole"))
    cut = replace(whole, train=replace(whole.train, out=tiny.train.out + "-cut"))
    params, rows = train(whole, progress=False)
    # Ctrl-C in the 7th draw (validation, then steps 1 … 6), on the one drawing thread (with
    # more, the 7th call could be another step's): the loop meets it when it needs step 6's
    # batch, so step 5 is the last done and saved
    monkeypatch.setattr("dpm.nn.train.DRAW_THREADS", 1)
    monkeypatch.setattr("dpm.nn.train.DRAW_AHEAD", 2)
    draw, calls = Sampler.draw, []

    def interrupted(self, *args):
        calls.append(1)
        if len(calls) == 7:
            raise KeyboardInterrupt
        return draw(self, *args)

    monkeypatch.setattr(Sampler, "draw", interrupted)
    with pytest.raises(KeyboardInterrupt):
        train(cut, progress=False)
    monkeypatch.setattr(Sampler, "draw", draw)
    assert sorted(p.name for p in (Path(cut.train.out) / "checkpoints").iterdir()) == ["5"]
    assert not (Path(cut.train.out) / "model.msgpack").exists()
    resumed, resumed_rows = train(cut, progress=False)
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(resumed), strict=True):
        np.testing.assert_array_equal(a, b)
    assert [r["loss"] for r in rows] == [r["loss"] for r in resumed_rows]
    assert [int(r["step"]) for r in resumed_rows] == list(range(steps + 1))
    out = Path(cut.train.out)
    assert (out / "loss.png").stat().st_size > 0
    w = load_weights(out / "model.msgpack")
    assert (w.architecture, w.width, w.k) == ("dpm", 8, K)


def test_dpm_train_and_render_from_the_command_line(tiny: Config, tmp_path: Path, capsys):
    config = tmp_path / "cli.toml"
    text = (ROOT / "configs" / "tiny.toml").read_text()
    text = text.replace('"runs/data-tiny"', f'"{tiny.data.out}"')
    text = text.replace('"runs/tiny"', f'"{tmp_path / "run"}"')
    config.write_text(text)
    assert train_main(["--config", str(config), "--quiet"]) == 0
    weights = tmp_path / "run" / "model.msgpack"
    scene = ROOT / "examples" / "scenes" / "glass_egg.obj"
    out = tmp_path / "egg.exr"
    argv = [str(scene), "-o", str(out), "--quiet", "--method", "dpm", "--photons", "20000",
            "--width", "16", "--height", "12", "--spp", "1", "--component", "caustic"]  # fmt: skip
    assert render_main([*argv, "--k", str(K), "--weights", str(weights)]) == 0
    assert out.exists()
    for extra, expected in (
        (["--k", "50", "--weights", str(weights)], f"trained with K = {K}"),
        (["--k", "7"], "no shipped DPM model for --k 7"),
        (["--k", str(K), "--weights", str(tmp_path / "none.msgpack")], "not found"),
        (["--k", str(K), "--weights", str(config)], "not a dpm weight file"),
    ):
        out.unlink(missing_ok=True)
        capsys.readouterr()
        assert render_main([*argv, *extra]) == 2
        err = capsys.readouterr().err
        assert expected in err and len(err.strip().splitlines()) == 1, err
        assert not out.exists()


def test_weight_files_round_trip(tmp_path: Path) -> None:
    model = make_model("dpm-l", 4)
    params = jax.tree.map(np.asarray, random_params(model, 9))
    save_weights(tmp_path / "w.msgpack", Weights("dpm-l", 4, K, params))
    back = load_weights(tmp_path / "w.msgpack")
    assert (back.architecture, back.width, back.k) == ("dpm-l", 4, K)
    for a, b in zip(jax.tree.leaves(params), jax.tree.leaves(back.params), strict=True):
        np.testing.assert_array_equal(a, b)
    (tmp_path / "bad.msgpack").write_bytes(b"\x93garbage")
    with pytest.raises(InputError, match="not a dpm weight file"):
        load_weights(tmp_path / "bad.msgpack")
    save_weights(tmp_path / "other.msgpack", Weights("dpm", 4, K, params))  # dpm-l's params
    with pytest.raises(InputError, match="do not fit a dpm network of width 4"):
        load_weights(tmp_path / "other.msgpack")


@pytest.mark.parametrize(
    ("text", "expected"),
    [
        ("[data\n", "not valid TOML"),
        ("[model]\nk = 5\n", "[data] needs `out`"),
        ('[data]\nout = "d"\n[model]\nk = 0\n', "k must be at least 1"),
        ('[data]\nout = "d"\n[model]\nk = "5"\n', "k must be an integer"),
        ('[data]\nout = "d"\n[model]\narchitecture = "big"\n', "architecture must be one of"),
        ('[data]\nout = "d"\nbudgets = [1.5]\n', "list of integers"),
        ('[data]\nout = "d"\nscenes = 1\n', "validation_scenes"),
        ('[data]\nout = "d"\n[train]\nsteps = 10\nfoo = 1\n', "unknown key 'foo'"),
        ('[data]\nout = "d"\n[extra]\n', "unknown table [extra]"),
        ('[data]\nout = "d"\nreference_radius = 0\n', "reference_radius"),
        ('[data]\nout = "d"\n[train]\nbatch = 2\nscenes_per_batch = 4\n', "batch must"),
        ('[data]\nout = "d"\n[train]\nloss = "l1"\n', "loss must be one of"),
        ('[data]\nout = "d"\n[train]\nbalance = 1\n', "balance must be true or false"),
        ('[data]\nout = "d"\n[train]\nclamp_z = 0\n', "clamp_z must be positive"),
        ('[data]\nout = "d"\n[train]\nschedule = "step"\n', "schedule must be one of"),
        ('[data]\nout = "d"\nworkers = -1\n', "workers must be 0 (one per core)"),
        ('[data]\nout = "d"\nray_address = 6379\n', "ray_address must be a string"),
        ('[data]\nout = "d"\nkind = "images"\n', "kind must be 'points' or 'caustic'"),
        ('[data]\nout = "d"\nkind = "caustic"\n', "the caustic architecture trains on"),
        ('[data]\nout = "d"\n[model]\narchitecture = "caustic"\n', "the caustic architecture"),
        (
            '[data]\nout = "d"\nkind = "caustic"\npasses = [1, 300]\n[model]\n'
            'architecture = "caustic"\n',
            "below target_passes",
        ),
        (
            '[data]\nout = "d"\nkind = "caustic"\npasses = [2, 1]\n[model]\n'
            'architecture = "caustic"\n',
            "increasing",
        ),
    ],
)
def test_bad_configs_are_one_line(
    tmp_path: Path, capsys, monkeypatch, text: str, expected: str
) -> None:
    monkeypatch.chdir(tmp_path)  # the configs' folders are relative: nothing may appear here
    bad = tmp_path / "bad.toml"
    bad.write_text(text)
    assert train_main(["--config", str(bad), "--quiet"]) == 2
    err = capsys.readouterr().err
    assert expected in err and len(err.strip().splitlines()) == 1, err
    assert sorted(p.name for p in tmp_path.iterdir()) == ["bad.toml"]


def test_the_ray_address_comes_from_the_flag_over_the_config(tmp_path: Path, monkeypatch):
    import dpm.nn.train

    seen = []
    monkeypatch.setattr(dpm.nn.train, "train", lambda config, progress: (seen.append(config), []))
    text = (ROOT / "configs" / "tiny.toml").read_text()
    config = tmp_path / "ray.toml"
    config.write_text(text.replace("[data]\n", '[data]\nray_address = "head:6379"\n'))
    assert train_main(["--config", str(config), "--quiet"]) == 0
    assert train_main(["--config", str(config), "--quiet", "--ray-address", "other:6379"]) == 0
    assert [c.data.ray_address for c in seen] == ["head:6379", "other:6379"]
    assert seen[0].data.identity() == load_config(ROOT / "configs" / "tiny.toml").data.identity()


def test_committed_configs_load() -> None:
    for path in sorted((ROOT / "configs").glob("*.toml")):
        config = load_config(path)
        assert isinstance(config.data, DataConfig) and isinstance(config.model, ModelConfig)
        assert isinstance(config.train, TrainConfig)
        raw = tomllib.loads(path.read_text())
        assert raw["data"]["out"].startswith("runs/")
        assert {"loss", "balance"} <= raw["train"].keys(), path  # named, not left to defaults
        assert "relative to the directory you run dpm-train from" in path.read_text(), path


def test_a_config_without_a_loss_gets_the_recommended_one(tmp_path: Path) -> None:
    path = tmp_path / "bare.toml"
    path.write_text('[data]\nout = "d"\n')
    config = load_config(path)
    assert (config.train.loss, config.train.balance) == ("mse+relmse", True)


def test_relative_folders_are_relative_to_the_working_directory(
    tiny: Config, tmp_path: Path, monkeypatch, capsys
) -> None:
    """Not to the config's folder: `out`s are kept as written, and train says where they lie."""
    here = Path(tiny.data.out).parent  # holds the tiny set, built by the other tests
    monkeypatch.chdir(here)
    text = (ROOT / "configs" / "tiny.toml").read_text()
    text = text.replace('"runs/data-tiny"', f'"{Path(tiny.data.out).name}"')
    text = text.replace('"runs/tiny"', '"relative-run"').replace("steps = 40", "steps = 2")
    path = tmp_path / "relative.toml"
    path.write_text(text)
    config = load_config(path)
    assert (config.data.out, config.train.out) == (Path(tiny.data.out).name, "relative-run")
    capsys.readouterr()
    train(config, progress=True)
    err = capsys.readouterr().err
    assert (here / "relative-run" / "model.msgpack").exists()
    assert sorted(p.name for p in tmp_path.iterdir()) == ["relative.toml"]
    first = err.lstrip().splitlines()[0]
    assert str(Path(tiny.data.out).resolve()) in first, err
    assert str((here / "relative-run").resolve()) in first, err
    assert "relative to the directory dpm-train runs from" in first, err


def test_point_radiance_is_pure(one_point: Batch) -> None:
    """The same (params, inputs) under jit, vmap and plain calls give the same radiance."""
    model = make_model("dpm", 8)
    params = random_params(model, 11)
    single = jax.tree.map(lambda a: a[0], one_point)
    plain = point_radiance(model, params, single)
    jitted = jax.jit(lambda p, b: point_radiance(model, p, b))(params, single)
    np.testing.assert_allclose(plain, jitted, rtol=1e-5)
    np.testing.assert_allclose(estimate(model, params, one_point), plain, rtol=1e-5)


def test_relmse_and_mse_teach_the_mean_of_noisy_targets_and_mu_law_does_not() -> None:
    """At the targets' mean the relmse and MSE gradients vanish; the μ-law one pushes the estimate
    down, which is why training on noisy PPM references with it darkens every caustic."""
    target = jnp.asarray(np.random.default_rng(0).exponential(0.05, (20000, 3)), jnp.float32)
    mean = jnp.full_like(target, float(target.mean()))

    def grad(name: str) -> float:
        return float(jax.grad(lambda e: loss_value(e, target, name))(mean).sum())

    assert abs(grad("relmse")) < 1e-3 * abs(grad("mu-law"))
    assert abs(grad("mse")) < 1e-3 * abs(grad("mu-law"))
    assert grad("mu-law") > 0  # descending it lowers the estimate below the mean


def test_a_caustic_filter_trains_and_the_render_reads_its_weights(tmp_path: Path) -> None:
    from dpm.caustic.forward import load_filter
    from dpm.caustic.stats import TAPS

    text = (ROOT / "configs" / "caustic.toml").read_text()
    for old, new in (('"runs/caustic-data"', f'"{tmp_path / "data"}"'),
                     ('"runs/caustic"', f'"{tmp_path / "run"}"'), ("scenes = 160", "scenes = 3"),
                     ("width = 64", "width = 16"),
                     ("passes = [1, 2, 4, 8, 16, 32, 64, 128]", "passes = [1, 3]"),
                     ("target_passes = 512", "target_passes = 8"), ("steps = 3000", "steps = 3"),
                     ("batch = 16 ", "batch = 2 "),
                     ("scenes_per_batch = 16", "scenes_per_batch = 2"),
                     ("validation_scenes = 12", "validation_scenes = 1"),
                     ("validation_points = 96", "validation_points = 2"),
                     ("workers = 0", "workers = 1")):  # fmt: skip
        assert old in text, old
        text = text.replace(old, new)
    config = tmp_path / "caustic.toml"
    config.write_text(text)
    assert train_main(["--config", str(config), "--quiet"]) == 0
    weights = load_filter(tmp_path / "run" / "model.msgpack")
    assert weights.out_kernel.shape == (24, TAPS)
    rows = (tmp_path / "run" / "metrics.csv").read_text().splitlines()
    assert len(rows) == 5 and all("nan" not in r for r in rows)  # header, steps 0-3
    # the shipped config keeps the held-out best step's weights: those are what it wrote
    best = tmp_path / "run" / "best.msgpack"
    assert best.read_bytes() == (tmp_path / "run" / "model.msgpack").read_bytes()


def test_threads_drawing_ahead_change_nothing(tiny: Config, monkeypatch) -> None:
    import dpm.nn.train as training

    runs = []
    for threads in (1, 3):
        monkeypatch.setattr(training, "DRAW_THREADS", threads)
        monkeypatch.setattr(training, "DRAW_AHEAD", 2 * threads)
        config = replace(
            tiny, train=replace(tiny.train, steps=6, out=f"{tiny.train.out}-t{threads}")
        )
        runs.append(train(config, progress=False)[0])
    for a, b in zip(*(jax.tree.leaves(r) for r in runs), strict=True):
        np.testing.assert_array_equal(a, b)


def test_a_run_keeps_its_identity_when_clamp_z_is_left_at_its_default(tiny: Config) -> None:
    """Run folders from before `[train] clamp_z` still resume: the key joins a run's identity
    only where it is set away from its default on the caustic filter, the one it changes."""
    from dpm.nn.run_folder import _identity

    assert "clamp_z" not in _identity(tiny)["train"]
    other = replace(tiny, train=replace(tiny.train, clamp_z=1.0))
    assert "clamp_z" not in _identity(other)["train"]  # not the caustic architecture
    caustic = replace(other, model=replace(other.model, architecture="caustic"))
    assert _identity(caustic)["train"]["clamp_z"] == 1.0


def test_augment_joins_a_runs_identity_only_when_set_and_keep_best_never(tiny: Config) -> None:
    """Runs from before `augment` and `keep_best` still resume; turning the images changes
    the parameters (a resume must not mix the two), keeping the best step does not."""
    from dpm.nn.run_folder import _identity

    assert {"augment", "keep_best"}.isdisjoint(_identity(tiny)["train"])
    both = replace(tiny, train=replace(tiny.train, augment=True, keep_best=True))
    assert _identity(both)["train"]["augment"] is True
    assert "keep_best" not in _identity(both)["train"]
