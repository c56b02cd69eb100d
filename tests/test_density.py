"""Gathering and the classic density estimators: known densities, convergence, resuming."""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest

from conftest import water_between_lights
from dpm import load_scene, stopwatch
from dpm.density import gather
from dpm.density.progressive import run_passes
from dpm.errors import InputError
from dpm.estimators import APPM, PM, PPM
from dpm.estimators.cppm import CPPM
from dpm.estimators.reference import ppm_reference
from dpm.estimators.sppm import sppm_caustics
from dpm.estimators.tuning import best, rescore, tune, tune_descending, tune_widening
from dpm.methods.auto import AIMED_PHOTONS_PER_PIXEL, PHOTONS_PER_PIXEL, paths_per_pixel
from dpm.metrics import rmse
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap, VisiblePoints, build_bvh, trace_photons, trace_visible_points
from dpm.tracer.photon_grid import disc_sums, grid_irradiance, photon_grid
from dpm.tracer.photons import aimed_share

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"


def plane_density(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A smooth density on the unit square (integrates to 1)."""
    return 1 + 0.5 * np.cos(2 * np.pi * x) * np.cos(2 * np.pi * y)


def plane_photons(n: int, seed: int, normal_z: float = 1.0) -> PhotonMap:
    """n photons of total flux 1 W on z = 0, distributed by plane_density (rejection)."""
    rng = np.random.default_rng(seed)
    xy = np.zeros((0, 2))
    while len(xy) < n:
        c = rng.random((2 * n, 2))
        keep = rng.random(2 * n) * 1.5 < plane_density(c[:, 0], c[:, 1])
        xy = np.vstack([xy, c[keep]])
    position = np.zeros((n, 3), np.float32)
    position[:, :2] = xy[:n]
    normal = np.zeros((n, 3), np.float32)
    normal[:, 2] = normal_z
    flux = np.full((n, 3), 1 / n, np.float32)
    return PhotonMap(
        position, normal.copy(), flux, normal, np.ones(n, bool), np.ones(n, np.uint16),
        np.arange(n), n,
    )  # fmt: skip


def plane_points(side: int = 16) -> VisiblePoints:
    """Visible points on a grid inside [0.25, 0.75]² of z = 0, normal +z, albedo 1."""
    g = np.linspace(0.25, 0.75, side)
    n = side * side
    position = np.zeros((n, 3), np.float32)
    position[:, 0], position[:, 1] = (a.ravel() for a in np.meshgrid(g, g))
    normal = np.zeros((n, 3), np.float32)
    normal[:, 2] = 1
    ones, zeros = np.ones((n, 3), np.float32), np.zeros((n, 3), np.float32)
    return VisiblePoints(
        position, normal, ones, ones, zeros, np.ones(n, bool), np.arange(n, dtype=np.int32),
        np.arange(n),
    )  # fmt: skip


def relative_error(points: VisiblePoints, radiance: np.ndarray) -> float:
    """RMSE of radiance (N, 3) against the exact ρ/π · E, relative to its mean."""
    exact = plane_density(points.position[:, 0], points.position[:, 1]) / np.pi
    return rmse(radiance, exact[:, None].repeat(3, 1)) / float(exact.mean())


@pytest.mark.parametrize(
    "make",
    [
        lambda n: PM(k=int(2 * n**0.5)),  # consistent: K grows, K/n shrinks
        lambda n: PM(k=int(2 * n**0.5), kernel="cone"),
        lambda n: PPM(radius=0.08, photons_per_pass=n // 20),
        lambda n: APPM(radius=0.15, photons_per_pass=n // 20),
        lambda n: CPPM(radius=0.08, photons_per_pass=n // 20),
    ],
    ids=["pm", "pm-cone", "ppm", "appm", "cppm"],
)
def test_estimators_recover_a_known_density(make) -> None:
    points = plane_points()
    errors = [relative_error(points, make(n).estimate(points, plane_photons(n, 1))) for n in
              (10_000, 100_000, 1_000_000)]  # fmt: skip
    assert errors[0] > errors[1] > errors[2], errors
    assert errors[2] < 0.05, errors


def uniform_photons(n: int, seed: int) -> PhotonMap:
    """n photons of total flux 1 W spread uniformly over the unit square of z = 0."""
    photons = plane_photons(n, seed)
    xy = np.random.default_rng(seed).random((n, 2)).astype(np.float32)
    photons.position[:, :2] = xy
    return photons


def striped_photons(n: int, seed: int) -> PhotonMap:
    """n photons of total flux 1 W on the unit square of z = 0, 9× denser on stripes 0.1 wide
    (every other): a disc of radius 0.05 almost always holds an edge."""
    photons = plane_photons(n, seed)
    rng = np.random.default_rng(seed)
    bright = rng.random(n) < 0.9
    x = (rng.integers(0, 5, n) * 2 + ~bright + rng.random(n)) / 10
    photons.position[:, 0], photons.position[:, 1] = x, rng.random(n)
    return photons


def test_cppm_critical_value_is_the_chi_square_quantile() -> None:
    """CPPM's written-out critical value is χ²'s upper quantile at its cells and significance
    (kept out of scipy at import: `dpm.estimators.cppm`)."""
    from scipy.special import chdtri

    from dpm.estimators import cppm

    assert cppm.CRITICAL == pytest.approx(
        float(chdtri(cppm.CELLS - 1, cppm.SIGNIFICANCE)), rel=1e-12
    )


@pytest.mark.parametrize("per_pass", [10_000, 500])  # discs get ~80 or ~4 photons a pass
def test_cppm_keeps_its_radius_where_the_density_is_flat(per_pass: int) -> None:
    """On a uniform density a disc's average is exact, so CPPM should keep (most of) its
    radius and beat PPM, which shrinks anyway; where an edge crosses the disc it must shrink.
    Also when a pass brings too few photons to test (they are counted until it can)."""
    points = plane_points()
    exact = np.full((len(points), 3), 1 / np.pi)
    index = gather.PointIndex(points.position, points.normal)
    for seed in (1, 2):
        photons = uniform_photons(200_000, seed)
        cppm = CPPM(radius=0.05, photons_per_pass=per_pass)
        ppm = PPM(radius=0.05, photons_per_pass=per_pass)
        assert rmse(cppm.estimate(points, photons), exact) < 0.8 * rmse(
            ppm.estimate(points, photons), exact
        )
        flat, varying = cppm.start(len(points), cppm.radius), cppm.start(len(points), cppm.radius)
        for part in photons.split(per_pass):
            flat.add(index, part)
        for part in striped_photons(200_000, seed).split(per_pass):
            varying.add(index, part)
        assert np.median(flat.radius) > 0.9 * 0.05  # most discs kept their radius
        assert np.median(varying.radius) < 0.8 * np.median(flat.radius)


def test_photons_from_the_other_side_are_not_counted() -> None:
    points = plane_points(8)
    below = plane_photons(20_000, 2, normal_z=-1.0)  # arrived on the far side of the plane
    assert not PM(k=50).estimate(points, below).any()
    assert not PPM(radius=0.1, photons_per_pass=1000).estimate(points, below).any()
    # Mixed in with photons from the seen side, they change nothing in a range query.
    above = plane_photons(20_000, 3)
    both = PhotonMap(
        *(np.concatenate([getattr(above, f), getattr(below, f)]) for f in
          ("position", "direction", "flux", "normal", "caustic", "bounces")),
        np.concatenate([above.path, below.path]), 20_000,
    )  # fmt: skip
    order = np.argsort(both.path, kind="stable")
    both = both.select(order)
    one_pass = PPM(radius=0.1, photons_per_pass=20_000)
    np.testing.assert_allclose(
        one_pass.estimate(points, both), one_pass.estimate(points, above), rtol=1e-6
    )


def test_gathering_matches_brute_force_and_chunking(monkeypatch) -> None:
    """K nearest in chunks of points, and pairs within radii from fresh and kept point grids
    (radii shrinking, growing, some zero), all as brute force finds them."""
    rng = np.random.default_rng(4)
    photons = plane_photons(3000, 5)
    photons = PhotonMap(
        rng.random((3000, 3), dtype=np.float32), photons.direction, photons.flux,
        rng.choice([-1.0, 1.0], (3000, 1)).astype(np.float32) * [0, 0, 1], photons.caustic,
        photons.bounces, photons.path, 3000,
    )  # fmt: skip
    points = rng.random((200, 3)).astype(np.float32)
    normal = np.tile(np.float32([0, 0, 1]), (200, 1))
    d = np.linalg.norm(points[:, None].astype(np.float64) - photons.position[None], axis=2)
    agree = photons.normal[:, 2] > 0
    monkeypatch.setattr(gather, "POINTS_PER_CHUNK", 37)
    chunks = [nb for _, nb in gather.PhotonIndex(photons).nearest(points, normal, 10)]
    rows, valid = np.vstack([nb.index for nb in chunks]), np.vstack([nb.valid for nb in chunks])
    np.testing.assert_array_equal(rows, np.argsort(d, axis=1, kind="stable")[:, :10])
    np.testing.assert_array_equal(valid, agree[rows])
    radius = rng.uniform(0.02, 0.2, 200)
    # a few points far wider than the rest (searched apart), one of those wider still
    spread = radius.copy()
    spread[[3, 50, 120]] = (0.9, 2.0, 40.0)
    kept = gather.PointIndex(points, normal)  # one index, radii shrinking then growing
    for r in (
        radius,
        spread,
        spread * 0.9,
        spread * 0.3,
        spread * 2.0,
        np.where(d[:, 0] < 0.5, spread, 0),
        np.where(d[:, 0] >= 0.5, spread, 0),  # other points live
    ):
        for index in (gather.PointIndex(points, normal), kept):
            pairs = index.within(photons, r)
            found = set(zip(pairs.point.tolist(), pairs.photon.tolist(), strict=True))
            expected = set(zip(*np.nonzero((d < r[:, None]) & agree[None]), strict=True))
            assert found == expected and len(pairs.point) == len(found)
            np.testing.assert_allclose(pairs.distance, d[pairs.point, pairs.photon], rtol=1e-12)


def test_photon_index_answers_from_its_own_map_and_times_gathering() -> None:
    a, b = plane_photons(500, 1), plane_photons(500, 2)
    point, normal = np.float32([[0.5, 0.5, 0.0]]), np.float32([[0, 0, 1]])
    watch = Stopwatch()
    index = {id(m): gather.PhotonIndex(m, watch) for m in (a, b)}
    for photons in (a, b, a):  # each index answers from its own map's tree
        d = np.linalg.norm(photons.position - point, axis=1)
        nb = next(index[id(photons)].nearest(point, normal, 5, watch))[1]
        np.testing.assert_array_equal(nb.index[0], np.argsort(d, kind="stable")[:5])
    assert set(watch.seconds) == {"gather"} and watch.seconds["gather"] > 0
    # an estimator given the index uses it, and gives what it gives from the bare map
    np.testing.assert_array_equal(
        PM(k=5).estimate(plane_points(4), index[id(a)]), PM(k=5).estimate(plane_points(4), a)
    )


def test_stopwatch_counts_nested_stages_once(monkeypatch) -> None:
    clock = iter([0.0, 2.0, 5.0, 6.0, 10.0, 11.0])  # a fake perf_counter: no wall clock
    monkeypatch.setattr(stopwatch.time, "perf_counter", lambda: next(clock))
    watch = Stopwatch()
    with watch("outer"):  # 0 .. 6, of which 2 .. 5 inside "inner"
        with watch("inner"):
            pass
    with watch("inner"):  # 10 .. 11
        pass
    assert watch.seconds == {"inner": 4.0, "outer": 3.0} and watch.total() == 7.0


@pytest.fixture(scope="module")
def egg():
    """The glass egg, its BVH and 32×32 visible points (one sample per pixel)."""
    scene = load_scene(EXAMPLES / "glass_egg.obj")
    bvh = build_bvh(scene)
    points = trace_visible_points(scene, bvh, scene.camera.with_resolution(32, 32), 1, 0, (0, 32))
    return scene, bvh, points


def test_ppm_error_against_a_ten_times_longer_run_falls_with_the_budget(egg) -> None:
    scene, bvh, points = egg
    ppm = PPM(radius=0.05, photons_per_pass=20_000)
    photons = trace_photons(scene, bvh, 20_000_000, seed=1, caustic_only=True)
    longest = ppm.estimate(points, photons)
    errors = [rmse(ppm.estimate(points, photons.first(n)), longest) for n in
              (20_000, 200_000, 2_000_000)]  # fmt: skip
    assert errors[0] > errors[1] > errors[2] > 0, errors


@pytest.mark.parametrize(
    "cls,radius",
    [(PPM, 0.05), (APPM, 0.05), (CPPM, 0.05), (PPM, None), (APPM, None), (CPPM, None)],
)
def test_a_resumed_run_ends_bit_identical(cls, radius, egg, tmp_path: Path) -> None:
    scene, bvh, points = egg
    estimator = cls(radius=radius, photons_per_pass=50_000)  # None: the held-out choice
    whole, _ = run_passes(estimator, scene, bvh, points, 400_000, seed=3)
    checkpoint = tmp_path / "run.npz"
    part, state = run_passes(
        estimator, scene, bvh, points, 400_000, seed=3, checkpoint=checkpoint, stop_after=3
    )
    assert state.passes == 3 and checkpoint.exists() and not np.array_equal(part, whole)
    resumed, state = run_passes(estimator, scene, bvh, points, 400_000, 3, checkpoint=checkpoint)
    assert state.passes == 8
    np.testing.assert_array_equal(resumed, whole)
    # In memory, passes of one traced map give the same answer (up to float32 flux rounding).
    photons = trace_photons(scene, bvh, 400_000, seed=3, caustic_only=True)
    np.testing.assert_allclose(estimator.estimate(points, photons), whole, rtol=1e-5, atol=1e-7)
    with pytest.raises(InputError, match="another run"):
        run_passes(estimator, scene, bvh, points, 400_000, seed=4, checkpoint=checkpoint)
    checkpoint.write_bytes(b"not a checkpoint")
    with pytest.raises(InputError, match="not a readable checkpoint"):
        run_passes(estimator, scene, bvh, points, 400_000, seed=3, checkpoint=checkpoint)
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.npz"]  # no temporary left


def test_guided_emission_changes_no_expectation(egg) -> None:
    scene, bvh, points = egg
    plain = trace_photons(scene, bvh, 4_000_000, seed=5, caustic_only=True)
    guided = trace_photons(scene, bvh, 200_000, seed=6, caustic_only=True, guided=True)
    assert len(guided) > 4 * len(plain) * 200_000 / 4_000_000  # it finds caustics faster
    for m in (plain, guided):
        assert np.all(np.isfinite(m.flux)) and m.caustic.all()
    total = [m.flux.astype(np.float64).sum(axis=0) for m in (plain, guided)]
    np.testing.assert_allclose(total[0], total[1], rtol=0.02)
    # And per visible point, one pass of PPM (a fixed radius) sees the same caustics.
    a = PPM(radius=0.1, photons_per_pass=4_000_000).estimate(points, plain)
    b = PPM(radius=0.1, photons_per_pass=200_000).estimate(points, guided)
    assert float(a.mean()) == pytest.approx(float(b.mean()), rel=0.05)


def test_auto_aims_its_photons_where_the_light_is_outside_the_glass(egg, tmp_path) -> None:
    # The egg's light lies outside the sphere around its glass: every path is aimed, and auto
    # takes the aimed paths per pixel. Lights inside the sphere (a water sheet between two
    # lights larger than it) aim nothing, and keep the unaimed paths per pixel.
    scene, bvh, _ = egg
    assert aimed_share(scene) == 1.0
    assert paths_per_pixel(scene) == AIMED_PHOTONS_PER_PIXEL
    water = load_scene(water_between_lights(tmp_path))
    assert aimed_share(water) == 0.0 and paths_per_pixel(water) == PHOTONS_PER_PIXEL
    plain = trace_photons(water, build_bvh(water), 20_000, seed=1, caustic_only=True)
    same = trace_photons(water, build_bvh(water), 20_000, seed=1, caustic_only=True, guided=True)
    np.testing.assert_array_equal(plain.flux, same.flux)  # from inside, emission is unchanged


def test_a_reference_from_two_ray_tasks_is_the_serial_one(egg, tmp_path: Path) -> None:
    scene, bvh, points = egg
    args = (scene, bvh, points, 400_000, 0.02, 100_000)
    serial = ppm_reference(*args, seed=4)
    fanned = ppm_reference(*args, seed=4, workers=2, checkpoint_dir=tmp_path)  # local Ray
    np.testing.assert_array_equal(serial.radiance, fanned.radiance)
    assert (serial.noise, serial.n_paths, serial.caustic_photons) == (
        fanned.noise, fanned.n_paths, fanned.caustic_photons)  # fmt: skip
    assert serial.noise > 0 and sorted(p.name for p in tmp_path.iterdir()) == [
        "half1.npz", "half2.npz"]  # fmt: skip


def test_sppm_and_ppm_see_the_same_caustics(egg) -> None:
    scene, bvh, _ = egg
    camera = scene.camera.with_resolution(32, 32)
    sppm, found = sppm_caustics(scene, bvh, camera, 1_000_000, 7, 0.05, 50_000)
    assert found > 0 and sppm.shape == (32, 32, 3)
    points = trace_visible_points(scene, bvh, camera, 20, 8, (0, 32))
    photons = trace_photons(scene, bvh, 1_000_000, seed=9, caustic_only=True)
    ppm = PPM(radius=0.05, photons_per_pass=50_000).estimate(points, photons)
    image = (points.throughput * ppm).reshape(32, 32, 20, 3).mean(axis=2)
    assert float(sppm.mean()) == pytest.approx(float(image.mean()), rel=0.1)


def test_k_larger_than_the_caustic_photons_is_refused(egg) -> None:
    scene, bvh, points = egg
    photons = trace_photons(scene, bvh, 1000, seed=1, caustic_only=True)
    assert 0 < len(photons) < 500
    with pytest.raises(InputError, match="more than the"):
        PM(k=500).estimate(points, photons)
    none = photons.select(np.zeros(len(photons), bool))  # no caustic photons: black, no error
    assert not PM(k=500).estimate(points, none).any()


def test_tuning_widens_the_radius_grid_until_the_best_is_inside() -> None:
    points, photons = plane_points(8), plane_photons(20_000, 3)
    exact = plane_density(points.position[:, 0], points.position[:, 1]) / np.pi
    reference = exact[:, None].repeat(3, 1).astype(np.float32)
    too_small = np.array([0.0025, 0.005, 0.01])  # far below the best radius for 20k photons
    estimates: list[np.ndarray] = []
    trials = tune_widening(points, photons, reference, too_small, estimates, max_steps=10)
    for method in ("ppm", "appm"):
        tried = sorted({t.radius for t in trials if t.method == method})
        assert len(tried) > len(too_small)
        assert tried[0] < best(trials, method).radius < tried[-1]
    # the kept estimates line up with the trials: rescoring against the same reference is exact
    assert rescore(trials, estimates, points, reference) == trials


def test_descending_tuning_finds_the_grids_best_from_either_side() -> None:
    points, photons = plane_points(8), plane_photons(20_000, 3)
    exact = plane_density(points.position[:, 0], points.position[:, 1]) / np.pi
    reference = exact[:, None].repeat(3, 1).astype(np.float32)
    grid = np.geomspace(0.005, 0.32, 7)
    full = tune(points, photons, reference, grid, passes=(10,), methods=("ppm",))
    target = best(full, "ppm").radius
    assert grid[0] < target < grid[-1]  # inside: the walk needs no step past an edge
    lengths = []
    for start in (grid[0], grid[-1]):  # the walk turns towards lower error from either end
        trials = tune_descending(points, photons, reference, grid, {("ppm", 10): start})
        found, whole = best(trials, "ppm"), best(full, "ppm")
        assert (found.radius, found.rmse) == (whole.radius, whole.rmse)  # the grid's own radius
        lengths.append(len(trials))
        # with no steps allowed past the edges, the walk stays on the grid from either end
        edge = tune_descending(points, photons, reference, grid, {("ppm", 10): start}, 0)
        assert {t.radius for t in edge} <= set(grid.tolist())
    assert min(lengths) < len(grid)  # from near the best it runs fewer settings than the grid


@numba.njit
def _grid_sums(grid, position, normal, out):
    for i in range(len(position)):
        p, n = position[i], normal[i]
        out[i] = grid_irradiance(grid, p[0], p[1], p[2], n[0], n[1], n[2])


@pytest.mark.parametrize("radius", [1e-3, 0.03, 0.2, 5.0])
def test_photon_grid_sums_the_photons_within_the_radius(radius: float) -> None:
    photons = plane_photons(4000, 3)
    tilted = np.arange(4000) % 3 == 0  # a third face away: the normal test drops them
    photons.normal[tilted] = [0.0, 0.8, -0.6]
    rng = np.random.default_rng(4)
    position = rng.uniform(-0.2, 1.2, (300, 3))
    position[:150, 2] = 0.0  # on the plane, and some off it
    position[:20, :2] = photons.position[:20, :2]  # right on photons
    normal = np.tile([0.0, 0.0, 1.0], (300, 1))
    out = np.zeros((300, 3))
    _grid_sums(photon_grid(photons, radius), position, normal, out)
    near = np.linalg.norm(photons.position[None].astype(np.float64) - position[:, None], axis=2)
    counts = (near < radius) & ~tilted
    expected = counts @ photons.flux.astype(np.float64) / (np.pi * radius**2)
    np.testing.assert_allclose(out, expected, rtol=1e-12, atol=0)
    assert counts.sum() > 0 or radius < 0.01


@pytest.mark.parametrize("n_photons", [5000, 40])
def test_disc_sums_are_the_point_grids_pairs_summed(n_photons: int) -> None:
    """Each point's photons and flux within each of several radii, summed without storing a
    pair, are those of the point grid's pairs (the same pairs, by the same arithmetic):
    radii of one scale up to the grid's widest (balls over 5 cells a side), a few far wider
    (summed apart, in grids of their own), some zero in one state or both, the widest in
    either state; the same at one thread and at two. With 40 photons (128 buckets) a ball's
    cells share buckets, each of which must be read once."""
    rng = np.random.default_rng(7)
    photons = plane_photons(n_photons, 8)
    photons.normal[::4] = [0.0, 0.8, -0.6]  # a quarter face away
    position = rng.uniform(-0.1, 1.1, (400, 3))
    position[:300, 2] = rng.normal(0, 0.01, 300)  # near the plane, and some off it
    normal = np.tile(np.float32([0, 0, 1]), (400, 1))
    wide = rng.uniform(0.01, 0.08, 400)
    wide[:20] = 3.9 * np.median(wide)  # within the first grid (SPREAD × the median)
    wide[[25, 60, 200]] = (0.5, 2.0, 1e6)
    wide[rng.random(400) < 0.1] = 0.0
    other = wide * rng.uniform(0.3, 1.5, 400)  # wider than `wide` at some points
    other[rng.random(400) < 0.1] = 0.0
    radii = np.stack([wide, other])
    pairs = gather.PointIndex(position, normal).within(photons, radii.max(axis=0))
    flux = photons.flux[pairs.photon].astype(np.float64)
    expected = []
    for r in radii:
        inside = pairs.distance < r[pairs.point]
        count = np.bincount(pairs.point[inside], minlength=400)
        sums = [np.bincount(pairs.point[inside], flux[inside, c], 400) for c in range(3)]
        expected.append((count, np.stack(sums, 1)))
    assert expected[0][0][200] > 0.5 * len(photons) and expected[1][0][:20].sum() > 0
    assert (other > wide).any() and ((wide > 0) & (other == 0)).any()
    if n_photons > 1000:
        assert expected[1][0].sum() > 1000
    numba.set_num_threads(1)
    try:
        one = disc_sums(photons, position, normal, radii)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    two = disc_sums(photons, position, normal, radii)
    # into arrays kept from an earlier call (NaN here): every entry is written, those of a
    # point of NaN radii too (as none); with no photons, all zero
    kept = (np.full(radii.shape, np.nan), np.full((*radii.shape, 3), np.nan))
    three = disc_sums(photons, position, normal, np.where(np.arange(400) == 7, np.nan, radii), kept)
    assert three[0] is kept[0] and three[1] is kept[1]
    assert not three[0][:, 7].any() and not three[1][:, 7].any()
    for found, summed in (one, two, three):
        for k, (count, sums) in enumerate(expected):
            rows = np.arange(400) != 7 if found is three[0] else np.arange(400) >= 0
            np.testing.assert_array_equal(found[k][rows], count[rows])
            np.testing.assert_allclose(summed[k][rows], sums[rows], rtol=1e-12, atol=1e-300)
    np.testing.assert_array_equal(one[1], two[1])
    none = disc_sums(photons.select(np.zeros(len(photons), bool)), position, normal, radii, kept)
    assert not none[0].any() and not none[1].any()
    with pytest.raises(ValueError, match="out needs"):
        disc_sums(photons, position, normal, radii, out=(kept[0][:1], kept[1]))
