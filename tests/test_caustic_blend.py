"""The caustic's moves towards other estimates, weighted by least squares on the simplex."""

from __future__ import annotations

import itertools

import numpy as np

from dpm.caustic.blend import blend_weights


def cost(w: np.ndarray, moves: list[np.ndarray], residual: np.ndarray) -> float:
    """|Σ w_i·moves_i − residual|²."""
    return float(np.sum((sum(wi * m for wi, m in zip(w, moves, strict=True)) - residual) ** 2))


def test_one_move_takes_the_share_that_fits() -> None:
    rng = np.random.default_rng(0)
    x = rng.normal(size=(100, 3))
    assert np.allclose(blend_weights([x], 0.4 * x), [0.4])
    assert np.allclose(blend_weights([x], 2.0 * x), [1.0])  # at most the whole move
    assert np.allclose(blend_weights([x], -x), [0.0])  # a move away from the target: none
    assert np.allclose(blend_weights([np.zeros((100, 3))], x), [0.0])  # no move, no evidence


def test_two_moves_stay_on_the_simplex_and_beat_every_point_of_it() -> None:
    rng = np.random.default_rng(1)
    grid = [np.array(w) for w in itertools.product(np.linspace(0, 1, 41), repeat=2)]
    grid = [w for w in grid if w.sum() <= 1 + 1e-12]
    for trial in range(30):
        moves = [rng.normal(size=(50, 3)) for _ in range(2)]
        if trial % 3 == 0:  # nearly parallel moves
            moves[1] = moves[0] + 0.1 * rng.normal(size=(50, 3))
        residual = rng.uniform(-1, 2) * moves[0] + rng.uniform(-1, 2) * moves[1]
        residual += 0.5 * rng.normal(size=(50, 3))
        w = blend_weights(moves, residual)
        assert (w >= 0).all() and w.sum() <= 1 + 1e-9
        assert cost(w, moves, residual) <= min(cost(g, moves, residual) for g in grid) + 1e-9


def test_the_blend_of_non_negative_images_stays_non_negative() -> None:
    # a + Σ w_i (b_i - a) is a convex blend of a and the b_i: never below zero where all are
    rng = np.random.default_rng(2)
    a = rng.uniform(0, 1, (200, 3))
    b = [rng.uniform(0, 1, (200, 3)) for _ in range(2)]
    target = 3 * b[0] + 3 * b[1] - 5 * a  # asks for weights past the simplex
    w = blend_weights([bi - a for bi in b], target - a)
    assert (a + sum(wi * (bi - a) for wi, bi in zip(w, b, strict=True)) >= 0).all()
    assert np.isclose(w.sum(), 1.0)


def test_degenerate_and_non_finite_moves_give_feasible_weights() -> None:
    rng = np.random.default_rng(3)
    x = rng.normal(size=(60, 3))
    # identical moves: any split of the best total share is a minimum; the total is 0.5
    w = blend_weights([x, x], 0.5 * x)
    assert (w >= 0).all() and np.isclose(w.sum(), 0.5)
    # a zero move beside a useful one: weight 0, the other fitted alone
    assert np.allclose(blend_weights([np.zeros_like(x), x], 0.3 * x), [0.0, 0.3])
    # NaN and inf entries are left out of the fit instead of switching it off
    bad = 0.7 * x
    bad[0, 0], bad[5, 1] = np.nan, np.inf
    y = x.copy()
    y[9, 2] = np.nan
    assert np.allclose(blend_weights([y], bad), [0.7])


def test_moves_leave_sparse_pixels_spread_or_within_its_error() -> None:
    # a pixel whose disc holds too few photons keeps spread_sparse's window mean (z = 0: the
    # narrow kernel would paint a lone photon's speck back, four times brighter), or moves
    # at most z standard errors of it, from its window's photons (the learned filter)
    from dpm.caustic.stats import CausticStats
    from dpm.methods.auto import SPARSE_PHOTONS, held_move

    p = 4
    counts = np.array([0.0, SPARSE_PHOTONS / 2, SPARSE_PHOTONS, 10 * SPARSE_PHOTONS])
    window = np.array([0.0, 16.0, SPARSE_PHOTONS, 10 * SPARSE_PHOTONS])  # photons behind spread
    narrow, spread = np.full((p, 3), 4.0), np.full((p, 3), 1.0)
    ones = np.ones(p)
    stats = CausticStats(1, p, 4, spread, narrow, counts, counts / 4, spread, counts, spread,
                         window, ones, ones / 4, 0 * ones, np.ones((p, 3)),
                         np.ones((p, 3)))  # fmt: skip
    move = held_move(stats, narrow, 0.0)
    assert np.array_equal(move[:2], np.zeros((2, 3)))
    assert np.array_equal(move[2:], np.full((2, 3), 3.0))
    far = narrow.copy()
    far[1, 0] = 1.0
    move = held_move(stats, far, 2.0)
    # no photon in the window: the error is the spread value itself (1), so 2 at most
    assert np.allclose(move[0], [2.0, 2.0, 2.0])
    assert np.allclose(move[1], [0.0, 0.5, 0.5])  # 16 photons: 2 / √16 = 0.5 allowed
    far[1] = [4.0, 1.5, 1.25]  # one share for all three channels: the colour is kept
    assert np.allclose(held_move(stats, far, 2.0)[1], [0.5, 0.5 / 6, 0.25 / 6])
    assert np.array_equal(held_move(stats, far, 2.0)[2:], far[2:] - 1.0)  # dense: as it is
    # a channel the light lacks (spread 0, or -1e-17 from the box sums) does not hold the
    # others still, and the move never turns round
    stats.spread[1] = [1.0, -1e-17, 0.0]
    before = stats.spread.copy()
    move = held_move(stats, stats.spread + [[0.0, 1e-6, 0.0]], 2.0)
    assert np.allclose(move[1], [0.0, 1e-6, 0.0])
    move = held_move(stats, np.zeros((p, 3)), 2.0)
    assert move[1, 0] == -0.5 and (move[1] <= 1e-17).all()  # towards 0, never past it
    np.testing.assert_array_equal(stats.spread, before)  # its input is left as it was
    # an estimate that is not finite moves no sparse pixel (z = 0 included)
    wild = np.full((p, 3), np.inf)
    wild[0, 0] = np.nan
    for z in (0.0, 2.0):
        assert np.array_equal(held_move(stats, wild, z)[:2], np.zeros((2, 3)))
