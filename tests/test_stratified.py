"""The pixels' stratified sequences: uniform points, stratified runs, unbiased and less noisy
path tracing than independent samples (`dpm.tracer.sampling.stratified2`)."""

from __future__ import annotations

import math
from pathlib import Path

import numba as nb
import numpy as np
from analytic import polygon_form_factor

from dpm import load_scene
from dpm.data import builder
from dpm.tracer import build_bvh, trace_listed, trace_pixels
from dpm.tracer.lights import sample_light_stratified
from dpm.tracer.sampling import pixel_sequence, stratified2, turn

RHO, LE, SIDE, HEIGHT = 0.5, 10.0, 0.4, 0.5  # floor albedo, light radiance, side, height


@nb.njit(cache=False)
def _points(first, n, seed, pix, pair):
    """(n, 2) points first … first + n - 1 of pixel pix's sequence in dimension pair `pair`."""
    out = np.empty((n, 2))
    s = pixel_sequence(seed, pix)
    for k in range(n):
        out[k, 0], out[k, 1] = stratified2(first + k, s, pair)
    return out


def test_aligned_runs_are_stratified_and_each_point_is_uniform() -> None:
    for m in (4, 7):  # every aligned run of 2^m points: one in each 2^-a × 2^-(m-a) box
        for first in (0, 2**m, 5 * 2**m):
            for seed, pix, pair in ((1, 0, 0), (2, 77, 1), (3, 5, 2)):
                pts = _points(first, 2**m, seed, pix, pair)
                for a in range(m + 1):
                    cells = (pts * [2**a, 2 ** (m - a)]).astype(int)
                    assert len(np.unique(cells, axis=0)) == 2**m
    for k in (0, 1, 6):  # point k over 400 pixels: uniform in the unit square
        pts = np.array([_points(k, 1, 9, pix, 0)[0] for pix in range(400)])
        assert pts.min() >= 0 and pts.max() < 1
        counts = np.histogram2d(pts[:, 0], pts[:, 1], bins=4, range=[[0, 1], [0, 1]])[0]
        assert counts.min() > 10 and counts.max() < 45  # 25 expected in each of 16 cells


def test_dimension_pairs_and_pixels_are_independent_and_estimates_unbiased() -> None:
    a, b = _points(0, 1024, 4, 3, 0), _points(0, 1024, 4, 3, 1)
    for i in range(2):
        for j in range(2):  # a shared index would tie the pairs' coordinates together
            assert abs(np.corrcoef(a[:, i], b[:, j])[0, 1]) < 0.1
    # ∫∫ x·y = 1/4: 16 points per pixel, 2000 pixels; unbiased, and the estimates' spread
    # far below independent points' (1/16 · Var(xy) = 0.0030)
    est = np.array([_points(0, 16, 5, pix, 2).prod(axis=1).mean() for pix in range(2000)])
    assert abs(est.mean() - 0.25) < 4 * est.std() / math.sqrt(len(est))
    assert est.var() < 0.0030 / 20


def test_stratified_light_samples_stay_stratified_over_the_light(tmp_path: Path) -> None:
    # A square light of two triangles: u picks the triangle and, rescaled, places the point,
    # so 4096 points of one sequence put 256 in each of 16 cells of the square (at random:
    # 256 ± 16) and half on each triangle.
    scene = load_scene(floor_under_light(tmp_path / "floor"))
    sc = scene.kernel_arrays()
    pts = _points(0, 4096, 1, 0, 1)
    samples = np.array([sample_light_stratified(sc, u, v) for u, v in pts])
    corners = scene.triangles[scene.emitters.triangles].reshape(-1, 3)
    low, high = corners.min(axis=0), corners.max(axis=0)
    xz = (samples[:, [1, 3]] - low[[0, 2]]) / (high - low)[[0, 2]]
    assert xz.min() >= 0 and xz.max() <= 1 and np.allclose(samples[:, 2], low[1])
    counts = np.histogram2d(xz[:, 0], xz[:, 1], bins=4, range=[[0, 1], [0, 1]])[0]
    assert np.abs(counts - 256).max() <= 10
    assert np.isin(samples[:, 0], scene.emitters.triangles).all()
    assert abs(np.mean(samples[:, 0] == scene.emitters.triangles[0]) - 0.5) < 0.01


def test_stratified_path_tracing_is_unbiased_and_less_noisy(tmp_path: Path) -> None:
    # Direct light on a floor from a square light out of view: the closed form (Lambert's
    # form factor) against pt's 16 paths per pixel with and without the pixels' sequences.
    scene = load_scene(floor_under_light(tmp_path / "floor"))
    bvh, camera = build_bvh(scene), scene.camera
    truth = _lit_floor_truth(scene, camera)
    error = {}
    for name, sequence in (("random", None), ("stratified", (11, 0))):
        images = [
            trace_pixels(scene, bvh, camera, 16, seed, (0, camera.height), True, sequence)[0]
            for seed in (1, 2, 3, 4)
        ]
        grey = np.array(images).mean(axis=-1)  # (4, H, W)
        error[name] = float(np.sqrt(np.mean((grey - truth) ** 2)))
        spread = grey.std(axis=0, ddof=1).mean() / math.sqrt(grey.size)
        assert abs(grey.mean() - truth.mean()) < 4 * spread + 1e-3 * truth.mean()
    assert error["stratified"] < 0.6 * error["random"]


def test_listed_paths_extend_their_sequence_call_after_call(tmp_path: Path) -> None:
    # Adaptive sampling's extra paths (`trace_listed`): 16 paths per pixel drawn in two calls
    # of 8, the second going on from point 8 of each pixel's sequence, are unbiased and as
    # much less noisy than independent paths as one call of 16 stratified ones.
    scene = load_scene(floor_under_light(tmp_path / "floor"))
    bvh, camera = build_bvh(scene), scene.camera
    truth = _lit_floor_truth(scene, camera)
    pixels = np.arange(camera.width * camera.height)
    eight = np.full(len(pixels), 8)
    error = {}
    for name in ("random", "one call", "two calls"):
        images = []
        for seed in (1, 2, 3, 4):
            if name == "random":
                sums = trace_listed(scene, bvh, camera, pixels, 2 * eight, seed)[0]
            elif name == "one call":
                sums = trace_listed(scene, bvh, camera, pixels, 2 * eight, seed, None, True,
                                    (seed, 0 * eight))[0]  # fmt: skip
            else:  # the second call's streams and sequence points both go on from the first's
                sums = sum(
                    trace_listed(scene, bvh, camera, pixels, eight, 10 * seed + k, None, True,
                                 (seed, k * eight))[0]
                    for k in (0, 1)
                )  # fmt: skip
            images.append((sums / 16).mean(axis=-1).reshape(camera.height, camera.width))
        grey = np.array(images)
        error[name] = float(np.sqrt(np.mean((grey - truth) ** 2)))
        spread = grey.std(axis=0, ddof=1).mean() / math.sqrt(grey.size)
        assert abs(grey.mean() - truth.mean()) < 4 * spread + 1e-3 * truth.mean()
    assert error["one call"] < 0.4 * error["random"]  # direct light: only stratified dims
    assert error["two calls"] < 1.2 * error["one call"]  # 8 points twice over: 2.5 times


def _lit_floor_truth(scene, camera) -> np.ndarray:
    """(H, W) closed-form pixel means of `floor_under_light` (Lambert's form factor)."""
    corners = np.unique(scene.triangles[scene.emitters.triangles].reshape(-1, 3), axis=0)
    centre = corners.mean(axis=0)
    order = np.argsort(np.arctan2(corners[:, 2] - centre[2], corners[:, 0] - centre[0]))
    square = corners[order]
    return _pixel_truth(camera, lambda p: RHO * LE * polygon_form_factor(p, UP, square))


UP = np.array([0.0, 1.0, 0.0])


def _pixel_truth(camera, radiance, sub: int = 4) -> np.ndarray:
    """(H, W) mean radiance (`radiance` of (P, 3) floor points) over a sub × sub grid of
    camera rays per pixel, for a camera looking straight down at the floor y = 0."""
    origin, forward, right, up = camera.basis()
    s = (np.arange(sub) + 0.5) / sub
    y = (np.arange(camera.height)[:, None] + s).reshape(-1)
    x = (np.arange(camera.width)[:, None] + s).reshape(-1)
    u, v = 2 * x / camera.width - 1, 1 - 2 * y / camera.height
    d = forward + v[:, None, None] * up + u[None, :, None] * right
    hit = origin + (-origin[1] / d[..., 1])[..., None] * d
    values = radiance(hit.reshape(-1, 3)).reshape(len(y), len(x))
    return values.reshape(camera.height, sub, camera.width, sub).mean(axis=(1, 3))


def floor_under_light(out: Path) -> Path:
    """A floor under a square light out of the camera's view; the camera looks straight down."""
    camera = builder.camera((0.0, 1.2, 0.0), (0.0, 0.0, 0.0), 50, 24, 24)
    camera["up"] = [0, 0, -1]
    scene = builder.Scene("lit_floor", camera, builder.render())
    scene.materials = {"floor": builder.diffuse((RHO,) * 3), "light": builder.emitter((LE,) * 3)}
    scene.add("floor", "floor", builder.floor_rect(-2, 2, -2, 2))
    scene.add("light", "light", builder.light_quad((1.0, HEIGHT, 0.0), (1.0, 0.0, 0.0), SIDE))
    return builder.write_scene(scene, out)


@nb.njit(cache=False)
def _turns(u):
    """(N, 2) `turn` of each u."""
    out = np.empty((len(u), 2))
    for i in range(len(u)):
        out[i, 0], out[i, 1] = turn(u[i])
    return out


def test_turn_is_cos_and_sin_of_a_full_turn() -> None:
    edges = np.array([0.0, 0.125, 0.25, 0.375, 0.5, 0.625, 0.75, 0.875, 1.0 - 2.0**-53])
    u = np.concatenate([np.random.default_rng(3).random(100_000), edges, np.nextafter(edges, 0)])
    got = _turns(u)
    want = np.stack([np.cos(2 * np.pi * u), np.sin(2 * np.pi * u)], axis=1)
    np.testing.assert_allclose(got, want, rtol=0, atol=1e-11)
