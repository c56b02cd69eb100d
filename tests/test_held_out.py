"""The held-out choice of a progressive method's radius scale (`dpm.density.held_out`)."""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import numpy as np
import pytest
from test_density import (
    plane_density,
    plane_photons,
    plane_points,
    relative_error,
    striped_photons,
)

from dpm.density import held_out
from dpm.density.base import luminance
from dpm.density.gather import PointIndex
from dpm.density.held_out import KEEP, LADDER, NARROWER, HeldOutState, block_ids, half
from dpm.estimators import APPM, PPM
from dpm.estimators.cppm import CPPM
from dpm.estimators.ppm import PPMState
from dpm.metrics import rmse
from dpm.tracer import PhotonMap, VisiblePoints


def test_halves_deal_a_pass_by_path_parity_and_keep_each_paths_flux() -> None:
    photons = plane_photons(1001, seed=2)
    a, b = half(photons, 0), half(photons, 1)
    assert a.n_paths + b.n_paths == photons.n_paths and len(a) + len(b) == len(photons)
    assert (a.n_paths, b.n_paths) == (501, 500)
    np.testing.assert_array_equal(np.sort(np.r_[a.path * 2, b.path * 2 + 1]), photons.path)
    # flux is per emitted path of its own map: a photon's path carries the same power
    np.testing.assert_allclose(a.flux * a.n_paths, photons.flux[::2] * photons.n_paths, rtol=1e-6)


def stripes(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """The density of `striped_photons`: 1.8 on the stripes [0.2k, 0.2k + 0.1), else 0.2."""
    return np.where((x * 10).astype(int) % 2 == 0, 1.8, 0.2) + 0 * y


def run(
    state: Any,
    photons: PhotonMap,
    points: VisiblePoints,
    per_pass: int,
    truth: Callable[[np.ndarray, np.ndarray], np.ndarray] = plane_density,
) -> tuple[Any, float]:
    """The state after the passes of `photons`, and its error relative to the truth's mean."""
    index = PointIndex(points.position, points.normal)
    for part in photons.split(per_pass):
        state.add(index, part)
    exact = truth(points.position[:, 0], points.position[:, 1])
    error = rmse(luminance(state.irradiance()), exact) / float(exact.mean())
    return state, error


@pytest.mark.parametrize("cls", [PPM, CPPM])
def test_the_default_comes_close_to_its_best_fixed_scale(cls) -> None:
    # A smooth density wants wide discs, stripes 0.1 wide narrow ones: the held-out choice,
    # made without the truth, is within 40 % of the best ladder scale judged against it (the
    # run keeps a step narrower than the held-out minimum: on the smooth density, whose best
    # is the widest, that costs 1.37×; across the ladder the errors span 10×).
    points = plane_points(24)
    for photons, truth in ((plane_photons(200_000, 1), plane_density),
                           (striped_photons(200_000, 1), stripes)):  # fmt: skip
        per_pass = photons.n_paths // 10
        est = cls(photons_per_pass=per_pass)
        index = PointIndex(points.position, points.normal)
        footprint = np.full(len(points), 0.5 / 24)  # the grid's spacing, as a camera's pixels
        radius = est.initial_radius(index, footprint, photons.split(per_pass)[0])
        errors = [run(est.start(len(points), s * radius), photons, points, per_pass, truth)[1]
                  for s in LADDER]  # fmt: skip
        got = run(est.state(len(points), radius), photons, points, per_pass, truth)[1]
        assert got <= 1.4 * min(errors), (got, errors)


def test_a_flat_density_takes_a_wide_scale_and_stripes_a_narrow_one() -> None:
    points = plane_points(24)
    chosen = []
    for photons in (plane_photons(200_000, 1), striped_photons(200_000, 1)):
        est = PPM(photons_per_pass=20_000)
        index = PointIndex(points.position, points.normal)
        footprint = np.full(len(points), 0.5 / 24)
        radius = est.initial_radius(index, footprint, photons.split(20_000)[0])
        chosen.append(run(est.state(len(points), radius), photons, points, 20_000)[0].scale())
    assert chosen[0] >= 2.0 and chosen[1] <= 1.0, chosen


def test_a_default_run_converges() -> None:
    points = plane_points()
    errors = [
        relative_error(points, PPM(photons_per_pass=n // 10).estimate(points, plane_photons(n, 1)))
        for n in (10_000, 100_000, 1_000_000)
    ]
    assert errors[0] > errors[1] > errors[2], errors
    assert errors[2] < 0.05, errors


@pytest.mark.parametrize("per_pass", [1, 2_000])
def test_ppms_sums_point_by_point_are_its_pairs_summed(monkeypatch, per_pass: int) -> None:
    # PPM's steps gather as per-point sums (`disc_sums`, no pair stored); forced through the
    # pairs (as CPPM's steps are), the run is the same to rounding: radii, counts, flux, the
    # steps dropped and the scale chosen. One-path passes leave a half with no photons.
    points, photons = plane_points(16), striped_photons(20_000, seed=6)
    index = PointIndex(points.position, points.normal)
    radius = PPM().initial_radius(index, None, photons.split(2_000)[0])
    runs, calls, counted = [], [], []
    spy = held_out.disc_sums
    monkeypatch.setattr(held_out, "disc_sums", lambda *a, **k: calls.append(1) or spy(*a, **k))
    for sums in (True, False):
        monkeypatch.setattr(PPMState, "SUMS", sums)
        state = PPM().state(len(points), radius)
        for part in photons.split(per_pass)[:40]:
            state.add(index, part)
        runs.append(state)
        counted.append(len(calls))
    # the sums ran in the first run only, once per half that had paths in a pass
    halves = 1 if per_pass == 1 else 2
    assert counted == [halves * len(photons.split(per_pass)[:40])] * 2, counted
    a, b = runs
    assert (a.live, a.chosen(), a.passes, a.paths) == (b.live, b.chosen(), b.passes, b.paths)
    for run_a, run_b in zip(a.runs, b.runs, strict=True):
        for x, y in zip(run_a, run_b, strict=True):
            assert (x.paths, x.passes, x.photons) == (y.paths, y.passes, y.photons)
            np.testing.assert_array_equal(x.count, y.count)
            np.testing.assert_allclose(x.radius, y.radius, rtol=1e-14)
            np.testing.assert_allclose(x.tau, y.tau, rtol=1e-12, atol=1e-300)
    assert a.irradiance().mean() > 0


@pytest.mark.parametrize("cls", [PPM, APPM])
@pytest.mark.parametrize("per_pass", [1, 399])
def test_one_path_passes_deal_the_halves_evenly_and_stay_finite(cls, per_pass: int) -> None:
    # Paths are dealt by their number in the run: one-path passes (and a last pass of one
    # path) alternate between the halves, and neither half divides by zero paths.
    points, photons = plane_points(8), plane_photons(400, seed=4)
    est = cls(photons_per_pass=per_pass)
    index = PointIndex(points.position, points.normal)
    state = est.state(len(points), est.initial_radius(index, None, photons.split(per_pass)[0]))
    for part in photons.split(per_pass):
        state.add(index, part)
    assert [run[0].paths for run in state.runs] == [200, 200]
    assert state.passes == -(-400 // per_pass)
    irradiance = state.irradiance()
    assert np.isfinite(irradiance).all() and irradiance.mean() > 0


@pytest.mark.parametrize("points", [20, 20_000])
def test_a_wide_step_is_dropped_only_when_clearly_worse(points: int) -> None:
    # Scores least at step 1 and rising with the scale by 10 % a step: over 20 noisy points
    # that rise is within the noise (an early pass's few photons), so every step runs on;
    # over 20,000 the steps past KEEP above the minimum are clearly worse and are dropped.
    rng = np.random.default_rng(3)
    factor = np.array([1.3, 1.0, 1.1, 1.2, 1.3, 1.4, 1.5, 1.6])
    terms = factor[:, None] * rng.exponential(1.0, (len(LADDER), points))
    state = PPM().state(points, 0.05)
    state.terms = lambda: terms  # the per-point score terms a pass would have left
    assert state.still_live() == (len(LADDER) if points == 20 else 1 + 1 + KEEP)


def test_a_wide_step_is_kept_when_its_rise_rests_on_photons_that_points_share() -> None:
    # 20,000 points in 200 tight clusters of 100 whose points have the same score terms
    # (one disc's photons, found by all of them). Step 1 is the minimum; step j > 1 is 2 %
    # a step above it on average, and ±1 cluster by cluster: over 200 independent clusters
    # the rise is 1.7 standard errors at most, and the wide steps stay; counted as 20,000
    # independent points it is 8.5 from step 4 on, and they go. The clusters lie a disc
    # apart, so blocked in space each is one block.
    clusters, size = 200, 100
    rise = np.r_[0.5, 0.0, 0.02 * np.arange(1, len(LADDER) - 1)]
    swing = np.r_[0.0, 0.0, np.ones(len(LADDER) - 2)][:, None] * (-1.0) ** np.arange(clusters)
    terms = np.repeat(1.0 + rise[:, None] + swing, size, axis=1)
    centre = np.c_[np.arange(clusters) % 20, np.arange(clusters) // 20, np.zeros(clusters)]
    rng = np.random.default_rng(5)
    position = np.repeat(centre + 0.1, size, axis=0) + rng.uniform(-0.02, 0.02, (len(terms[0]), 3))
    state = PPM().state(clusters * size, 0.05)  # discs of 0.025 to 0.28: within a cluster
    state.terms = lambda: terms
    assert state.still_live() == 1 + 1 + KEEP  # points unplaced: taken one by one
    state.position = position
    assert state.still_live() == len(LADDER)
    ids = block_ids(position, np.full(len(position), 0.28))
    assert len(np.unique(ids)) == clusters and len(np.unique(ids[::size])) == clusters


def test_blocks_are_numbered_as_numpy_unique_numbers_the_rows() -> None:
    """block_ids ranks the (side, cube) rows as np.unique(axis=0) does (sorted rows; -0.0
    and 0.0 one cube; positions that are not finite each a block past the others), so the
    blocked sums, and with them which steps are dropped, stay as they were."""
    rng = np.random.default_rng(3)
    n = 5000
    position = rng.normal(size=(n, 3))
    position[rng.random(n) < 0.2, 0] = -0.0
    position[rng.random(n) < 0.2, 1] = 0.0
    position[:3] = [[np.nan, 0, 0], [np.inf, 1, 1], [0, 0, 0]]
    reach = 2.0 ** rng.integers(-4, 1, n) * rng.uniform(0.3, 0.5, n)
    side = 2.0 ** np.ceil(np.log2(2 * reach))
    key = np.column_stack([side, np.floor(position / side[:, None])])
    ok = np.isfinite(key).all(axis=1)
    want = n + np.arange(n)
    want[ok] = np.unique(key[ok], axis=0, return_inverse=True)[1].ravel()
    np.testing.assert_array_equal(block_ids(position, reach), want)


def test_a_given_radius_runs_the_method_alone() -> None:
    ppm = PPM(radius=0.05, photons_per_pass=100)
    assert type(ppm.state(4, 0.05)).__name__ == "PPMState"
    assert isinstance(PPM().state(4, 0.05), HeldOutState)
    assert NARROWER >= 0 and LADDER[0] < 1 < LADDER[-1]
