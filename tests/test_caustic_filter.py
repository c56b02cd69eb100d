"""`auto`'s learned caustic filter: the render's Numba copy equals the JAX network, the clamp
holds whatever the network says, a fresh network leaves SPPM's estimate within its noise, the
error falls pass after pass, the output does not depend on threads, and bad weights are
refused in one line."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path

import jax
import jax.numpy as jnp
import numba
import numpy as np
import pytest
from test_auto import CAMERA, GLASS_MTL, GLASS_OBJ
from test_truths import mirror_scene

from conftest import write_scene
from dpm import load_scene
from dpm.caustic import forward as caustic_forward
from dpm.caustic.halves import PassHalves
from dpm.caustic.stats import (
    CLAMP_Z,
    DILATIONS,
    EXTRAPOLATED_CENTRE,
    HULL_CLAMP,
    CausticStats,
    candidates,
    clamp_centre,
    extrapolated,
    features,
)  # fmt: skip
from dpm.data.caustic_set import pass_arrays
from dpm.density.base import luminance
from dpm.errors import InputError
from dpm.estimators.ppm import PPMState
from dpm.methods.auto import NARROW, Auto, Passes, half_state
from dpm.metrics import rmse
from dpm.nn.caustic_net import CausticNet, example_features, filter_caustics
from dpm.nn.caustic_training import CausticBatch, caustic_estimates
from dpm.nn.weights import Weights, save_weights
from dpm.renderer import RenderOptions, render
from dpm.stopwatch import Stopwatch
from dpm.tracer import build_bvh


def stats_after(scene, passes: int, seed: int = 1) -> CausticStats:
    """auto's caustic statistics after `passes` passes (component caustic)."""
    c = scene.camera
    per_pass = 4 * c.width * c.height
    o = RenderOptions(component="caustic", spp=passes, photons=passes * per_pass, seed=seed,
                      network=False, progress=False)  # fmt: skip
    run = Passes(Auto(scene, o), build_bvh(scene), c, Stopwatch(), 0.0)
    for _ in range(passes):
        run.run_pass()
    return run.caustic_stats()


def random_network(tmp_path: Path, scale: float, seed: int = 1) -> tuple[CausticNet, dict, Path]:
    """A caustic network with random parameters (scale: their spread), saved as a weight file."""
    model = CausticNet(24)
    params = model.init(jax.random.key(0), example_features())
    leaves, tree = jax.tree.flatten(params)
    keys = jax.random.split(jax.random.key(seed), len(leaves))
    noisy = [a + scale * jax.random.normal(k, a.shape) for a, k in zip(leaves, keys, strict=True)]
    params = jax.tree.unflatten(tree, noisy)
    path = tmp_path / "caustic.msgpack"
    save_weights(path, Weights("caustic", 24, 1, jax.tree.map(np.asarray, params)))
    return model, params, path


def moves(weights, s: CausticStats) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(P, 3) the filter's output, how far it moved each channel from the estimate it is held
    around (`clamp_centre`), and CLAMP_Z standard errors there: 1/√photons of the larger of
    that estimate and the network's (unclamped) value, or the smaller of that value and one
    photon's."""
    raw = caustic_forward.kernel_output(weights, features(s), candidates(s)).reshape(-1, 3)
    out = caustic_forward.filter_caustics(weights, s)
    centre, count = clamp_centre(s)

    def reach(m, n):
        n = n[:, None]
        return CLAMP_Z * np.where(n > 0, np.maximum(m, raw) / np.sqrt(np.maximum(n, 1)),
                                  np.minimum(raw, s.photon_value()))  # fmt: skip

    lo, hi = centre - reach(centre, count), centre + reach(centre, count)
    if HULL_CLAMP:  # or of the pixel's own estimate
        lo = np.minimum(lo, s.own - reach(s.own, s.own_count))
        hi = np.maximum(hi, s.own + reach(s.own, s.own_count))
    allowed = np.where(raw > centre, hi - centre, centre - lo)
    return out, np.abs(out - centre), allowed


@pytest.fixture(scope="module")
def glass_stats(tmp_path_factory) -> CausticStats:
    folder = tmp_path_factory.mktemp("glass")
    return stats_after(load_scene(write_scene(folder, GLASS_OBJ, GLASS_MTL, CAMERA)), 6)


def test_the_renders_numba_filter_equals_the_jax_network(glass_stats, tmp_path) -> None:
    s = glass_stats
    model, params, path = random_network(tmp_path, 0.3)
    ours = caustic_forward.filter_caustics(caustic_forward.load_filter(path), s)
    centre, n = clamp_centre(s)  # as the training set stores them

    def image(a: np.ndarray) -> jnp.ndarray:
        return jnp.asarray(a.reshape(s.h, s.w, *a.shape[1:]), jnp.float32)

    hull = (image(s.own), image(s.own_count)) if HULL_CLAMP else (None, None)
    theirs = filter_caustics(model, params, jnp.asarray(features(s)), jnp.asarray(candidates(s)),
                             image(centre), image(n), jnp.float32(s.photon_value()), CLAMP_Z,
                             *hull)  # fmt: skip
    theirs = np.asarray(theirs).reshape(-1, 3)
    assert np.abs(ours - centre).max() > 1e-3 * np.abs(centre).max()  # the network did move it
    np.testing.assert_allclose(ours, theirs, rtol=1e-4, atol=1e-5 * np.abs(theirs).max())


def test_training_holds_the_filter_within_the_renders_intervals(glass_stats, tmp_path) -> None:
    """The training set's arrays, through the training's estimate with `[train] hull`, give
    the render's filter: the same clamp, HULL_CLAMP's second interval included (without it,
    the one interval about the centre the shipped weights were trained through)."""
    s = glass_stats
    model, params, path = random_network(tmp_path, 3.0)  # wild weights: the clamp binds
    arrays = pass_arrays(s)
    batch = CausticBatch(*(jnp.asarray(arrays[n])[None] for n in CausticBatch._fields))
    estimates = caustic_estimates(model, CLAMP_Z, hull=True)  # ([train] hull = true)
    trained = np.asarray(estimates(params, batch)[0])
    rendered = caustic_forward.filter_caustics(caustic_forward.load_filter(path), s)
    np.testing.assert_allclose(trained, rendered, rtol=1e-4, atol=1e-5 * np.abs(rendered).max())
    one = batch._replace(other=batch.own, other_count=batch.count)  # one interval only
    alone = np.asarray(estimates(params, one)[0])
    assert (np.abs(alone - rendered).max() > 1e-3 * np.abs(rendered).max()) == HULL_CLAMP
    unhulled = np.asarray(caustic_estimates(model, CLAMP_Z)(params, batch)[0])  # the default
    np.testing.assert_allclose(unhulled, alone, rtol=1e-6, atol=1e-7 * np.abs(alone).max())


def test_whatever_the_network_says_no_pixel_moves_past_its_error(glass_stats, tmp_path) -> None:
    s = glass_stats
    clamped = 0
    for seed in (1, 2, 3):
        _, _, path = random_network(tmp_path, 3.0, seed)  # wild weights
        out, move, allowed = moves(caustic_forward.load_filter(path), s)
        assert (move <= allowed * (1 + 1e-6) + 1e-11).all()
        assert np.isfinite(out).all() and (out >= 0).all(), out.min()
        clamped += int(np.isclose(move, allowed, rtol=1e-6).any(axis=1).sum())
    assert clamped > 0  # the clamp did bind somewhere


def test_a_fresh_network_leaves_sppm_unchanged_within_noise(glass_stats, tmp_path) -> None:
    s = glass_stats
    _, _, path = random_network(tmp_path, 0.0)  # as `init` makes it
    out, move, allowed = moves(caustic_forward.load_filter(path), s)
    lit = luminance(s.own) > 0
    # from the render's estimate without the network: within one of its standard errors on
    # average (the clamp's centre, the extrapolated estimate, is itself further from it)
    n = s.own_count[:, None]
    se = np.where(n > 0, np.maximum(s.own, out) / np.sqrt(np.maximum(n, 1)),
                  np.minimum(out, s.photon_value()))  # fmt: skip
    assert np.abs(out - s.own)[lit].mean() < se[lit].mean()
    assert (move <= allowed * (1 + 1e-6) + 1e-11).all()  # and nowhere past the clamp


def test_with_the_network_the_error_falls_pass_after_pass(tmp_path) -> None:
    # the mirror scene of the table of truths: a caustic whose truth is known; the reference
    # here is a long render without the network (what the filter must converge to)
    scene = load_scene(mirror_scene(tmp_path))
    c = scene.camera
    per_pass = 4 * c.width * c.height
    base = dict(component="caustic", progress=False)

    def image(passes: int, network: bool, seed: int) -> np.ndarray:
        o = RenderOptions(spp=passes, photons=passes * per_pass, seed=seed, network=network,
                          **base)  # fmt: skip
        return render(scene, o).image

    reference = image(512, False, 99)
    errors = [np.mean([rmse(image(p, True, s), reference) for s in (1, 2)]) for p in (2, 8, 32)]
    assert errors[0] > errors[1] > errors[2], errors


def test_the_filter_does_not_depend_on_the_thread_count(glass_stats) -> None:
    weights = caustic_forward.load_filter()
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = caustic_forward.filter_caustics(weights, glass_stats)
        numba.set_num_threads(threads)
        many = caustic_forward.filter_caustics(weights, glass_stats)
    finally:
        numba.set_num_threads(threads)
    assert np.array_equal(one, many)


def test_the_shipped_filter_is_used_by_default_and_no_network_turns_it_off(glass) -> None:
    on = render(glass, RenderOptions(spp=4, photons=8000, progress=False))
    off = render(glass, RenderOptions(spp=4, photons=8000, network=False, progress=False))
    assert on.stats["plan"]["network"] and not off.stats["plan"]["network"]
    assert "learned caustic filter" in on.stats["plan"]["reason"]
    assert not np.array_equal(on.image, off.image)


def test_the_plan_leaves_the_filter_out_where_its_time_is_over_its_share() -> None:
    """`plan_network`: the filter's predicted seconds (a fixed part and per pixel) against
    NETWORK_SHARE of the budget; --network keeps it, --no-network and a render without
    caustics leave it out, and a render without a budget always has it."""
    from dpm.methods import auto

    plan = auto.Plan("sppm", 1000, "caustics")
    pixels = 256 * 256
    fits = auto.network_seconds(pixels) / auto.NETWORK_SHARE  # the least budget that holds it
    assert auto.plan_network(plan, None, pixels, fits * 1.01).network
    assert auto.plan_network(plan, None, pixels, None).network
    tight = auto.plan_network(plan, None, pixels, fits * 0.99)
    assert not tight.network and "over 15% of the budget" in tight.reason
    assert auto.plan_network(plan, True, pixels, fits * 0.99).network
    assert not auto.plan_network(plan, False, pixels, None).network
    assert not auto.plan_network(auto.Plan("off", 0, "none"), True, pixels, None).network
    assert auto.network_seconds(4 * pixels) > 3 * auto.network_seconds(pixels)


@pytest.fixture
def glass(tmp_path: Path):
    return load_scene(write_scene(tmp_path, GLASS_OBJ, GLASS_MTL, CAMERA))


def test_a_bad_weight_file_is_one_line_and_exit_status_2(tmp_path: Path) -> None:
    path = write_scene(tmp_path, GLASS_OBJ, GLASS_MTL, CAMERA)
    corrupt = tmp_path / "corrupt.msgpack"
    corrupt.write_bytes(b"\x93not a weight file")
    other = caustic_forward.SHIPPED.with_name("dpm-50.msgpack")
    for weights, words in ((corrupt, "not a dpm weight file"), (other, "not the caustic filter"),
                           (tmp_path / "missing.msgpack", "not found")):  # fmt: skip
        out = tmp_path / "o.exr"
        run = subprocess.run(
            [sys.executable, "-m", "dpm.cli", str(path), "--spp", "2", "--weights", str(weights),
             "-o", str(out), "--quiet"],
            capture_output=True, text=True,
        )  # fmt: skip
        assert run.returncode == 2, run.stderr
        assert words in run.stderr and len(run.stderr.strip().splitlines()) == 1, run.stderr
        assert not out.exists()


def test_weights_that_do_not_fit_are_refused(tmp_path: Path) -> None:
    model = CausticNet(8)
    params = jax.tree.map(np.asarray, model.init(jax.random.key(0), example_features()))
    path = tmp_path / "narrow.msgpack"
    save_weights(path, Weights("caustic", 8, 1, params))
    assert caustic_forward.load_filter(path).out_kernel.shape[0] == 8  # any width fits
    last = params["params"][f"Conv_{len(DILATIONS)}"]
    last["bias"] = last["bias"][:5]
    save_weights(path, Weights("caustic", 8, 1, params))
    with pytest.raises(InputError, match="do not fit"):
        caustic_forward.load_filter(path)


@pytest.mark.parametrize("k", range(8))
def test_a_turned_image_gives_the_same_taps_turned(k: int) -> None:
    """`[train] augment` turns training images by the square's symmetries: valid because the
    kernel's taps map onto taps, so what the filter may weigh at a pixel of the turned image
    is what it could weigh at the pixel it came from (its candidates turned alike)."""
    from dpm.caustic.stats import tap_offsets
    from dpm.nn.caustic_net import gather_taps
    from dpm.nn.caustic_training import turn

    rng = np.random.default_rng(k)
    cands = jnp.asarray(rng.random((5, 7, 7, 3), dtype=np.float32))
    taps, inside = map(np.asarray, gather_taps(cands))
    turned, turned_inside = map(np.asarray, gather_taps(jnp.asarray(turn(np.asarray(cands), k, 1))))
    offsets = [tuple(o) for o in tap_offsets()]
    for t, (c, dy, dx) in enumerate(offsets):
        dy, dx = (-dy if k & 1 else dy), (-dx if k & 2 else dx)
        if k & 4:
            dy, dx = dx, dy
        u = offsets.index((c, dy, dx))  # the tap it becomes: there is one
        np.testing.assert_array_equal(turned[:, :, u], turn(taps[:, :, t], k, 0))
        np.testing.assert_array_equal(turned_inside[:, :, u], turn(inside[:, :, t], k, 0))
    assert len({turn(np.arange(6).reshape(2, 3), k, 0).tobytes() for k in range(8)}) == 4


def test_keep_best_writes_the_weights_of_the_least_validation_loss(tmp_path: Path) -> None:
    """`[train] keep_best`: the weights saved are those offered with the least loss, also
    after a resume that reads the losses back from the metrics rows."""
    from dpm.nn.config import ModelConfig
    from dpm.nn.train import Best
    from dpm.nn.weights import load_weights

    path = tmp_path / "best.msgpack"
    fresh = CausticNet(24).init(jax.random.key(0), example_features())
    params = {v: jax.tree.map(lambda a, v=v: np.asarray(a) + v, fresh) for v in (3, 1, 2, 0)}

    def saved() -> float:  # which params the file holds: the value added to them
        bias = load_weights(path).params["params"]["Conv_0"]["bias"]
        return float(bias[0] - np.asarray(fresh["params"]["Conv_0"]["bias"])[0])

    best = Best(path, ModelConfig("caustic", 24, 1))
    for v in (3, 1, 2):
        best.offer(float(v), params[v])
    assert saved() == 1
    again = Best(path, ModelConfig("caustic", 24, 1))
    again.resume([{"validation_loss": "3"}, {"validation_loss": ""}, {"validation_loss": "1"}],
                 params[3])  # fmt: skip
    again.offer(2.0, params[2])
    assert saved() == 1
    again.offer(0.0, params[0])
    assert saved() == 0
    # keep_best turned on mid-run (no file): the restored params, at their own step's loss
    # only if that step was validated (an earlier row's loss belongs to other weights)
    path.unlink()
    late = Best(path, ModelConfig("caustic", 24, 1))
    late.resume([{"validation_loss": "0.5"}, {"validation_loss": ""}], params[3])
    assert saved() == 3
    late.offer(2.0, params[2])  # beats the restored params, whose loss is unknown
    assert saved() == 2
    path.unlink()
    late = Best(path, ModelConfig("caustic", 24, 1))
    late.resume([{"validation_loss": ""}, {"validation_loss": "1.5"}], params[3])
    late.offer(2.0, params[2])
    assert saved() == 3


def test_the_halves_hold_what_each_pass_gathered_alone() -> None:
    # PPM statistics after random passes: the halves' sums are each pass's own flux over its
    # own disc's area, and α·(photons found), whatever the radii shrank to since
    rng = np.random.default_rng(3)
    n = 50
    states = (PPMState.start(n, rng.uniform(0.5, 1.0, n)), PPMState.start(n, 0.3))
    halves = PassHalves.start(2, n)
    want = np.zeros((2, 2, n, 3))
    found = np.zeros((2, 2, n))
    for j in range(7):
        halves.mark(states)
        for k, s in enumerate(states):
            point = rng.integers(0, n, 40 + 10 * k)
            flux = rng.uniform(0.0, 2.0, (len(point), 3))
            want[j % 2, k] += np.stack(
                [np.bincount(point, flux[:, c], minlength=n) for c in range(3)], 1
            ) / (np.pi * s.radius[:, None] ** 2)  # fmt: skip
            found[j % 2, k] += np.bincount(point, minlength=n)
            s.update(point, flux)
            s.paths += 100
        halves.add(j % 2, states, 100)
    assert np.allclose(halves.flux, want, rtol=1e-9, atol=1e-12)
    assert np.allclose(halves.found, found)
    assert list(halves.paths) == [400, 300] and list(halves.passes) == [4, 3]
    # the half's state reads its flux over its paths, at the full run's radii
    half = half_state(halves, 1, 0, states[0])
    assert np.allclose(half.irradiance(), want[1, 0] / 300)
    assert np.array_equal(half.radius, states[0].radius)
    # and the whole run's estimate is the mean of its passes' own (the rescalings telescope),
    # so its blur is that of the passes' mean radius² (`Passes.blur_ratio`)
    for k, s in enumerate(states):
        assert np.allclose(s.irradiance(), want[:, k].sum(axis=0) / 700, rtol=1e-9)


def test_the_blur_ratio_is_a_quarter_at_the_first_pass_then_each_pixels_own(glass) -> None:
    c = glass.camera
    o = RenderOptions(component="caustic", spp=8, photons=8 * 4 * c.width * c.height, seed=1,
                      network=False, progress=False)  # fmt: skip
    run = Passes(Auto(glass, o), build_bvh(glass), c, Stopwatch(), 0.0)
    run.run_pass()
    assert np.allclose(run.blur_ratio(), NARROW**2)  # the narrow radius is half the wide
    for _ in range(7):
        run.run_pass()
    q, halves = run.blur_ratio(), (run.blur_ratio(0), run.blur_ratio(1))
    # each radius shrinks with its own photons, the narrow one's mostly more slowly
    assert np.median(q) >= NARROW**2 - 1e-12 and q.max() > NARROW**2 + 0.02 and q.min() > 0.2
    r2 = run.halves.radius2  # (halves, kernels, P) Σ radius² of each kernel's passes
    wide, narrow = r2[:, 0], r2[:, 1]
    assert np.allclose(q, narrow.sum(0) / wide.sum(0))
    assert all(np.allclose(h, narrow[i] / wide[i]) for i, h in enumerate(halves))


def weights_of(scene, passes: int, filtered, monkeypatch) -> np.ndarray:
    """auto's weights (narrow, extrapolated, filter) for a filter whose output is
    filtered(stats) (P, 3), after `passes`."""
    c = scene.camera
    o = RenderOptions(component="caustic", spp=passes, photons=passes * 4 * c.width * c.height,
                      seed=1, network=True, progress=False)  # fmt: skip
    run = Passes(Auto(scene, o), build_bvh(scene), c, Stopwatch(), 0.0)
    for _ in range(passes):
        run.run_pass()
    monkeypatch.setattr(caustic_forward, "filter_caustics", lambda _, s: filtered(s))
    weights = run.blend()
    assert (weights >= 0).all() and weights.sum() <= 1 + 1e-9  # a convex blend, always
    return weights


def test_the_halves_keep_a_filter_that_helps_and_turn_down_one_that_hurts(
    tmp_path, monkeypatch
) -> None:
    scene = load_scene(mirror_scene(tmp_path))
    c = scene.camera
    o = RenderOptions(component="caustic", spp=256, photons=256 * 4 * c.width * c.height,
                      seed=99, network=False, progress=False)  # fmt: skip
    truth = render(scene, o).image.reshape(-1, 3).astype(np.float64)  # a long render
    oracle = weights_of(scene, 8, lambda s: truth, monkeypatch)[2]
    assert 0.6 < oracle, oracle  # the reference itself: about all of its move
    assert weights_of(scene, 8, lambda s: 3 * s.spread, monkeypatch)[2] == 0.0  # thrice too bright
    # a filter that moves nothing: as it is, with the rest of the simplex (the kernels' moves)
    narrow, sharp, still = weights_of(scene, 8, lambda s: s.spread, monkeypatch)
    assert still == pytest.approx(1.0 - narrow - sharp, abs=1e-12)


def test_the_extrapolated_estimate_cancels_a_quadratic_blur() -> None:
    # disc means of irradiance a + b·|x|² about the pixel: a + b·R²/2 at the wide radius R,
    # a + b·(NARROW·R)²/2 at the narrow one; their extrapolation is a, the value at the pixel
    a, b, r = np.array([[0.3, 1.0, 2.0]]), np.array([[0.5, -0.2, 4.0]]), 0.7
    wide, narrow = a + b * r**2 / 2, a + b * (NARROW * r) ** 2 / 2
    np.testing.assert_allclose(extrapolated(wide, narrow, np.array([NARROW**2])), a, rtol=1e-12)
    # the narrow radius shrunk more slowly, pass by pass: blur ∝ the passes' mean radius²
    wide_r2, narrow_r2 = np.array([1.0, 0.8, 0.7]) * r**2, np.array([0.25, 0.23, 0.22]) * r**2
    wide, narrow = a + b * wide_r2.mean() / 2, a + b * narrow_r2.mean() / 2
    ratio = np.array([narrow_r2.sum() / wide_r2.sum()])
    np.testing.assert_allclose(extrapolated(wide, narrow, ratio), a, rtol=1e-12)
    # where the narrow disc's noise takes it below zero, it is held at zero
    assert (extrapolated(np.ones((2, 3)), np.zeros((2, 3)), np.full(2, 0.25)) == 0).all()


def test_the_filters_inputs_and_clamp_equal_their_numpy_formulas() -> None:
    """`features`, `candidates` and `clamp_to_centre` run in Numba, one pass over the pixels: the
    same values as their NumPy formulas (scipy's box means over the pixels inside the image;
    the clamp's share of the move from the pixel's own estimate), on random statistics with
    empty, sparse and dense discs."""
    from scipy.ndimage import uniform_filter

    from dpm.caustic.stats import clamp_to_centre

    rng = np.random.default_rng(3)
    h, w = 13, 17
    p = h * w
    count = rng.choice([0.0, 0.5, 3.0, 40.0], p)
    wide, narrow, own, spread = (rng.gamma(0.5, 2.0, (p, 3)) for _ in range(4))
    albedo, normal = rng.uniform(0, 1, (p, 3)), rng.normal(size=(p, 3))
    albedo[:5] = 0.0  # pixels that see no surface
    s = CausticStats(h, w, 7, wide, narrow, count, count / 3, own, count, spread, count,
                     rng.uniform(0.1, 4.0, p), rng.uniform(0.2, 0.6, p), rng.normal(size=p),
                     albedo, normal)  # fmt: skip
    lw, ln, ls = luminance(wide), luminance(narrow), luminance(spread)
    scale = lw[albedo.max(axis=1) > 0].mean()
    expected = np.stack([
        np.log1p(lw / scale), np.log1p(ln / scale), np.log1p(ls / scale),
        np.log1p(count) / 4, np.log1p(count / 3) / 4, 1 / np.sqrt(np.maximum(count, 1)),
        np.log(np.maximum(s.radius, 1e-3)), *albedo.T, *normal.T, s.depth,
        np.full(p, np.log1p(7) / 4)], axis=1).astype(np.float32)  # fmt: skip
    np.testing.assert_allclose(features(s).reshape(p, -1), expected, rtol=1e-6, atol=1e-7)
    image = wide.reshape(h, w, 3)
    means = []
    for size in (3, 9):
        inside = uniform_filter(np.ones((h, w)), size, mode="constant")
        means.append(uniform_filter(image, (size, size, 1), mode="constant") / inside[..., None])
    # Richardson: blurs in the ratio q (capped at 1/2), blur ∝ R²
    sharp = wide + (narrow - wide) / (1 - np.minimum(s.blur_ratio, 0.5))[:, None]
    want = np.stack([image, narrow.reshape(h, w, 3), *means, spread.reshape(h, w, 3),
                     sharp.reshape(h, w, 3)])  # fmt: skip
    np.testing.assert_allclose(candidates(s), np.maximum(want, 0), rtol=1e-6, atol=1e-12)
    # the clamp's centre: the extrapolated estimate, its photons from the nested discs'
    # relative variance (1 − f²)/N_wide + f²/N_narrow (none where either disc is empty)
    f = 1 / (1 - np.minimum(s.blur_ratio, 0.5))
    n_ext = np.where(count > 0, 1 / ((1 - f**2) / np.maximum(count, 1)
                                     + f**2 / np.maximum(count / 3, 1)), 0.0)  # fmt: skip
    centre, n = (np.maximum(sharp, 0), n_ext) if EXTRAPOLATED_CENTRE else (own, count)
    got_centre, got_n = clamp_centre(s)
    np.testing.assert_allclose(got_centre, centre, rtol=1e-12)
    np.testing.assert_allclose(got_n, n, rtol=1e-12)
    filtered = own * rng.uniform(0.2, 3.0, (p, 3))
    photon = s.photon_value()

    def reach(m: np.ndarray, k: np.ndarray) -> np.ndarray:
        return CLAMP_Z * np.where(k[:, None] > 0,
                                  np.maximum(m, filtered) / np.sqrt(np.maximum(k, 1))[:, None],
                                  np.minimum(filtered, photon))  # fmt: skip

    # within CLAMP_Z standard errors of the centre or (HULL_CLAMP) of the pixel's own estimate
    lo, hi = centre - reach(centre, n), centre + reach(centre, n)
    if HULL_CLAMP:
        lo, hi = np.minimum(lo, own - reach(own, count)), np.maximum(hi, own + reach(own, count))
    allowed = np.where(filtered > centre, hi - centre, centre - lo) + 1e-12
    keep = (allowed / np.maximum(np.abs(filtered - centre) + 1e-12, allowed)).min(axis=1)
    held = (1 - keep[:, None]) * centre + keep[:, None] * filtered
    np.testing.assert_allclose(clamp_to_centre(s, filtered), held, rtol=1e-12)
    assert 0 < keep.min() < 1 and keep.max() == 1  # some moves held, some not
    for h, w in ((6, 1), (6, 2), (6, 3), (2, 9)):  # images narrower than the 9 × 9 window
        p, one = h * w, np.ones(h * w)
        rgb = rng.uniform(0.5, 2.0, (p, 3))
        s = CausticStats(
            h, w, 1, rgb, rgb, one, one, rgb, one, rgb, one, one, one / 4, one, rgb, rgb
        )
        image = rgb.reshape(h, w, 3)
        for c, size in ((2, 3), (3, 9)):
            inside = uniform_filter(np.ones((h, w)), size, mode="constant")
            want = uniform_filter(image, (size, size, 1), mode="constant") / inside[..., None]
            np.testing.assert_allclose(candidates(s)[c], want, rtol=1e-6)
