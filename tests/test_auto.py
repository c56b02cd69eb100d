"""`auto`, the default render: time budget, plan, reproducibility, denoising split, tone map."""

from __future__ import annotations

import json
import math
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace

import numpy as np
import pytest
from analytic import fresnel

from conftest import (
    FLOOR_AND_LIGHT_MTL,
    FLOOR_AND_LIGHT_OBJ,
    WATER,
    WATER_LE,
    water_between_lights,
    write_scene,
)
from dpm import load_scene
from dpm.denoise import RESTORE_Z, restore_certain
from dpm.density.base import luminance
from dpm.estimators.ppm import PPMState
from dpm.io import KNEE, linear_to_srgb8, tone_map
from dpm.methods import auto
from dpm.metrics import rmse
from dpm.renderer import RenderOptions, render
from dpm.tracer import (
    build_bvh,
    specular_pixels,
    trace_emitted,
    trace_listed,
    trace_pixel_sums,
)
from dpm.tracer.sampling import sobol2
from dpm.tracer.visible import camera_ray

# The floor and light of conftest, and a glass slab between them: caustics.
GLASS_OBJ = (
    FLOOR_AND_LIGHT_OBJ
    + """\
v -0.3 0.5 -0.3
v 0.3 0.5 -0.3
v 0.3 0.5 0.3
v -0.3 0.5 0.3
v -0.3 0.4 -0.3
v 0.3 0.4 -0.3
v 0.3 0.4 0.3
v -0.3 0.4 0.3
usemtl glass
f 9 12 11 10
f 13 14 15 16
"""
)
GLASS_MTL = (
    FLOOR_AND_LIGHT_MTL
    + """\
newmtl glass
illum 7
Ni 1.5
"""
)
CAMERA = """\
[camera]
origin = [0, 2.5, 2.5]
target = [0, 0, 0]
up = [0, 1, 0]
fov = 50
width = 24
height = 16
"""


class FakeClock:
    """time.monotonic stand-in: each call advances `step` seconds."""

    def __init__(self, step: float) -> None:
        self.now, self.step = 0.0, step

    def monotonic(self) -> float:
        self.now += self.step
        return self.now


@pytest.fixture
def glass(tmp_path: Path):
    return load_scene(write_scene(tmp_path, GLASS_OBJ, GLASS_MTL, CAMERA))


@pytest.fixture
def diffuse(tmp_path: Path):
    return load_scene(write_scene(tmp_path, toml=CAMERA))


def options(**kw) -> RenderOptions:
    return RenderOptions(method="auto", progress=False, **kw)


def test_a_tiny_budget_renders_one_pass(glass) -> None:
    result = render(glass, options(time=1e-6))
    assert result.stats["passes"] == 1 and result.stats["spp"] == 1
    assert np.isfinite(result.image).all() and result.image.mean() > 0


def test_the_budget_stops_before_the_pass_that_would_overrun_it(glass, monkeypatch) -> None:
    # The clock is read before the first pass and after each, and in the first pass also
    # after loading its kernels and around what runs once (the plan), whose time is left
    # out of the pass's: with a 0.1 s tick the first pass counts 0.2 s, each later one 0.1,
    # and pass j ends at 0.4 + 0.1 j. The render must stop after the first pass whose
    # successor would end past the budget less the finishing reserve.
    # (the denoiser's call is timed after the first pass: here 0.05 s, with no clock read)
    monkeypatch.setattr(auto, "time", FakeClock(0.1))
    monkeypatch.setattr(auto.Passes, "time_denoiser", lambda self: (0.05, 0.05))
    budget = 2.0
    calls = 1  # a scene with glass: no `denoiser_share`, one denoiser call to come
    finish = auto.FINISH_SECONDS + auto.WRITE_SECONDS_PER_PIXEL * 24 * 16
    finish += auto.FINISH_MARGIN * (calls + auto.REST_CALLS) * 0.05
    finish += auto.network_seconds(24 * 16)  # the learned caustic filter's, planned here
    result = render(glass, options(time=budget), started=0.0)
    assert result.stats["plan"]["network"]
    expected = next(j for j in range(2, 100) if 0.4 + 0.1 * j + 0.1 + finish > budget)
    assert result.stats["passes"] == expected
    assert result.stats["pass_seconds"] == pytest.approx(0.2)
    assert 0.4 + 0.1 * expected + finish <= budget  # the last pass ended inside the budget


def test_the_denoisers_call_is_timed_on_a_quarter_and_scaled_to_the_image(monkeypatch) -> None:
    # A stand-in denoiser that takes 1 ms per pixel of the fake clock without clean guides
    # and 2 ms with, and nothing else moves it: each filter's first call (OIDN's loading, the
    # filter's set-up) is not counted, the second, on a quarter of the 24 x 16 image, is
    # scaled by four.
    clock = FakeClock(0.0)
    calls = []

    def slow(color, albedo, normal, clean_aux=False):
        calls.append((color.shape, clean_aux))
        clock.now += (1 + clean_aux) * 1e-3 * color.shape[0] * color.shape[1]
        return color

    monkeypatch.setattr(auto, "time", clock)
    monkeypatch.setattr(auto, "denoise", slow)
    passes = SimpleNamespace(
        h=16, w=24, pixels=384, k=1, paths=auto.Halves(16, 24), guide_sums=np.ones((2, 2, 384, 3)),
        clean_guides=lambda paths: paths >= auto.CLEAN_GUIDE_PATHS,  # (no mirror or glass)
    )  # fmt: skip
    assert auto.Passes.time_denoiser(passes) == pytest.approx((0.384, 0.768))
    # both filters the finish may call: without clean guides (few paths) and with
    assert calls == [((8, 12, 3), False)] * 2 + [((8, 12, 3), True)] * 2
    # where the guides never count as clean (mirrors or glass) only the first
    calls.clear()
    passes.clean_guides = lambda paths: False
    assert auto.Passes.time_denoiser(passes) == pytest.approx((0.384, 0.384))
    assert calls == [((8, 12, 3), False)] * 2


def test_the_finish_reserve_counts_the_calls_the_finish_will_make() -> None:
    # Without mirrors or glass the finish denoises once, with clean guides from
    # CLEAN_GUIDE_PATHS paths, and judges the denoiser's share (two calls more, each half
    # with its own guides) once each half has ADAPT_AFTER / 2 paths: a render that stops
    # sooner must not keep time for calls it will not make.
    from dpm.methods.adaptive import ADAPT_AFTER

    passes = SimpleNamespace(
        denoising=True, separate=False, call=(0.1, 0.3), finish_seconds=0.5, spp=0,
        half_spp=[0, 0], j=0, clean_guides=lambda paths: paths >= auto.CLEAN_GUIDE_PATHS,
    )  # fmt: skip

    def reserve(spp, half, j, k=0):
        passes.spp, passes.half_spp, passes.j = spp, list(half), j
        return (auto.Passes.finish_reserve(passes, k) - 0.5) / auto.FINISH_MARGIN

    rest = auto.REST_CALLS * 0.1
    assert reserve(1, (1, 0), 1) == pytest.approx(0.1 + rest)  # one pass: one plain call
    half = ADAPT_AFTER // 2
    assert reserve(2 * half - 1, (half, half - 1), 1) == pytest.approx(0.1 + rest)
    # the coming pass (pass 1, of half 1) would complete the second half: three calls
    three = reserve(2 * half - 1, (half, half - 1), 1, k=1)
    clean = (
        2 * half >= auto.CLEAN_GUIDE_PATHS,
        half >= auto.CLEAN_GUIDE_PATHS,
        half >= auto.CLEAN_GUIDE_PATHS,
    )
    assert three == pytest.approx(sum(0.3 if c else 0.1 for c in clean) + rest)
    many = auto.CLEAN_GUIDE_PATHS
    assert reserve(2 * many, (many, many), 0) == pytest.approx(3 * 0.3 + rest)
    passes.separate = True  # mirrors or glass: one call, never with clean guides
    passes.clean_guides = lambda paths: False
    assert reserve(2 * many, (many, many), 0) == pytest.approx(0.1 + rest)
    passes.denoising = False
    assert auto.Passes.finish_reserve(passes) == 0.5


def test_a_budgeted_render_is_reproduced_by_its_pass_count(glass, monkeypatch) -> None:
    monkeypatch.setattr(auto, "time", FakeClock(0.1))
    monkeypatch.setattr(auto.Passes, "time_denoiser", lambda self: (0.01, 0.01))  # (no clock)
    timed = render(glass, options(time=1.0, seed=4), started=0.0)
    plan = timed.stats["plan"]
    assert plan["caustics"] == "sppm" and timed.stats["caustic_photons"] > 0
    n = timed.stats["passes"]
    again = render(glass, options(spp=n, photons=n * plan["photons_per_pass"], seed=4))
    np.testing.assert_array_equal(timed.image, again.image)
    other = render(glass, options(spp=timed.stats["passes"], seed=5))
    assert not np.array_equal(timed.image, other.image)


@pytest.mark.parametrize(
    ("scene", "spp"),
    [("glass", 3), ("diffuse", 24)],  # diffuse: passes of whole pixels, several paths each
)
def test_same_seed_same_image_whatever_the_thread_count(scene, spp, request) -> None:
    import numba

    scene = request.getfixturevalue(scene)
    images = []
    for threads in (1, numba.config.NUMBA_NUM_THREADS):
        numba.set_num_threads(threads)
        images.append(render(scene, options(spp=spp, seed=2)).image)
    numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)
    np.testing.assert_array_equal(*images)


def test_adaptive_extra_paths_are_spent_and_reproducible(glass) -> None:
    passes = auto.ADAPT_AFTER + 4
    first, again = (render(glass, options(spp=passes, seed=6)) for _ in range(2))
    assert first.stats["extra_paths"] > 0
    np.testing.assert_array_equal(first.image, again.image)


def test_passes_of_whole_pixels_double_up_to_the_paths_asked_for(diffuse) -> None:
    # Without mirrors or glass a pass takes whole pixels: 1, 1, 2, 2, 4, 4 paths per pixel,
    # then what is left of --spp (6): seven passes, 20 paths per pixel.
    result = render(diffuse, options(spp=20, seed=3))
    assert result.stats["passes"] == 7 and result.stats["spp"] == 20
    assert result.stats["samples"] == 20 * 24 * 16
    with_glass = render(diffuse, options(spp=20, seed=3, component="caustic"))
    assert with_glass.stats["passes"] == 20  # no paths: one sample per pass


def test_a_budgeted_render_of_whole_pixels_is_reproduced_by_its_paths(diffuse, monkeypatch) -> None:
    # Every pass takes 0.1 s on this clock whatever its paths, so the budget's last pass is
    # cut to what the time left holds; --spp of the render's paths makes the same passes.
    monkeypatch.setattr(auto, "time", FakeClock(0.1))
    monkeypatch.setattr(auto.Passes, "time_denoiser", lambda self: (0.01, 0.01))  # (no clock)
    timed = render(diffuse, options(time=1.7, seed=4), started=0.0)
    assert timed.stats["spp"] > timed.stats["passes"] > 1
    again = render(diffuse, options(spp=timed.stats["spp"], seed=4))
    assert again.stats["passes"] == timed.stats["passes"]
    np.testing.assert_array_equal(timed.image, again.image)


def test_each_half_of_whole_pixel_passes_runs_on_through_its_own_sequence(
    diffuse, monkeypatch
) -> None:
    # A half's passes take consecutive points of its pixels' stratified sequences: pass j
    # starts where the half's earlier passes ended (no point used twice), under the half's
    # own sequence seed.
    calls = []

    def spy(scene, bvh, camera, spp, seed, sequence=None):
        calls.append((spp, sequence))
        return trace_pixel_sums(scene, bvh, camera, spp, seed, sequence)

    monkeypatch.setattr(auto, "trace_pixel_sums", spy)
    render(diffuse, options(spp=20, seed=3))
    passes = calls[-7:]  # (the first call loads the kernels on a 2 × 2 image)
    assert [k for k, _ in passes] == [1, 1, 2, 2, 4, 4, 6]
    for half in (0, 1):
        mine = passes[half::2]
        starts = [first for _, (_, first) in mine]
        assert starts == list(np.cumsum([0] + [k for k, _ in mine[:-1]]))
        assert len({qseed for _, (qseed, _) in mine}) == 1
    assert passes[0][1][0] != passes[1][1][0]


def test_whole_pixel_sums_are_those_of_the_same_paths_listed(diffuse) -> None:
    # trace_pixel_sums and trace_listed draw the same random streams for k paths per pixel
    # (without a stratified sequence): the same radiance sums and squared luminances.
    bvh, camera, k = build_bvh(diffuse), diffuse.camera, 5
    sums, squares, *_ = trace_pixel_sums(diffuse, bvh, camera, k, 7)
    pixels = np.arange(camera.width * camera.height)
    listed, listed_squares, _ = trace_listed(
        diffuse, bvh, camera, pixels, np.full(len(pixels), k), 7
    )
    np.testing.assert_allclose(sums, listed, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(squares, listed_squares, rtol=1e-12, atol=1e-12)
    assert (squares >= luminance(sums) ** 2 / k * (1 - 1e-12)).all() and squares.max() > 0


def test_a_scene_without_mirror_or_glass_traces_no_photons(diffuse) -> None:
    result = render(diffuse, options(spp=2))
    plan = result.stats["plan"]
    assert plan["caustics"] == "off" and plan["photons_per_pass"] == 0
    assert "no mirror or glass" in plan["reason"]
    assert result.stats["caustic_photons"] == 0


def test_the_default_render_never_imports_jax(tmp_path: Path) -> None:
    # auto's caustic filter runs in Numba (dpm.caustic.forward): importing JAX would cost a
    # short render most of its budget.
    path = write_scene(tmp_path, GLASS_OBJ, GLASS_MTL, CAMERA)
    stats = tmp_path / "stats.json"
    code = (
        "import sys; from dpm.cli import render_main; "
        f"assert render_main([{str(path)!r}, '--spp', '2', '-o', {str(tmp_path / 'o.exr')!r},"
        f" '--quiet', '--stats', {str(stats)!r}]) == 0; "
        "assert 'jax' not in sys.modules, 'the default render imported JAX'"
    )
    subprocess.run([sys.executable, "-c", code], check=True)
    assert json.loads(stats.read_text())["plan"]["network"]  # and it did run the filter


def three_renders(scene, **kw) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The (H, W, 3) images of one auto render: denoised, not denoised, caustics alone (SPPM's:
    the learned caustic filter, tested in test_caustic_filter.py, left out)."""
    kw.setdefault("network", False)
    full = render(scene, options(**kw)).image
    plain = render(scene, options(**kw, denoise=False)).image
    caustic = render(scene, options(**kw, component="caustic")).image
    return full, plain, caustic


def test_noisy_caustics_go_through_the_denoiser_and_known_ones_keep_their_estimate(
    glass, monkeypatch
) -> None:
    # A denoiser that darkens every pixel by half. After two passes no pixel's error is known
    # (one sample per half), so its output is kept, caustics included; after many passes a
    # caustic pixel known to within a few percent moved by half is given back its own value.
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: color * 0.5)
    for spp, kept in ((2, True), (48, False)):
        full, plain, caustic = three_renders(glass, spp=spp, seed=1)
        light = luminance(caustic)
        bright = (light > 0.5 * luminance(plain)) & (light > 0.2 * light.max())  # the caustic
        assert bright.sum() > 10
        halved = np.isclose(full[bright], 0.5 * plain[bright], rtol=1e-4, atol=0).all(axis=1)
        if kept:
            assert halved.mean() > 0.9
        else:
            restored = np.isclose(full[bright], plain[bright], rtol=1e-4, atol=0).all(axis=1)
            assert restored.mean() > 0.5 and halved.mean() < 0.1


def test_a_caustic_read_low_by_chance_is_not_taken_for_certain(glass, monkeypatch) -> None:
    # A denoiser that quadruples every pixel. A caustic pixel of a few photons has a relative
    # error of about 1/√count, but of which value? Of its own, a pixel read low by chance
    # (2 photons where 10 were due) would look certain and keep its dark reading against
    # the denoiser (the dark specks in a water caustic). Scaled by what the denoiser leaves
    # the caustic, a few photons do not overrule it; with many, the pixel is given back.
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: color * 4.0)
    # (photon paths aimed at the glass: 100 give the caustic a few photons a pixel)
    for spp, photons, most in ((4, 100, False), (48, 200_000, True)):
        full, plain, caustic = three_renders(glass, spp=spp, seed=1, photons=photons)
        light = luminance(caustic)
        bright = (light > 0.5 * luminance(plain)) & (light > 0.2 * light.max())  # the caustic
        assert bright.sum() > 10
        restored = np.isclose(full[bright], plain[bright], rtol=1e-4, atol=0).all(axis=1)
        assert restored.mean() == 1.0 if most else restored.mean() < 0.9, (spp, restored.mean())


def test_a_pixel_with_no_caustic_is_judged_by_its_paths(glass, monkeypatch) -> None:
    # Lit pixels the caustic does not reach: their caustic neither knows nor hides anything,
    # so after many passes the denoiser's quadrupling is undone wherever the paths' own error
    # rules it out (a caustic error scaled by what the denoiser leaves would excuse it).
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: color * 4.0)
    full, plain, caustic = three_renders(glass, spp=48, seed=1)
    light = luminance(plain)
    dark = (luminance(caustic) < 0.01 * light) & (light > 0.05 * light.max())
    assert dark.sum() > 50
    restored = np.isclose(full[dark], plain[dark], rtol=1e-4, atol=0).all(axis=1)
    assert restored.mean() > 0.5, restored.mean()


def test_without_mirror_or_glass_the_denoisers_errors_are_given_back_too(
    diffuse, monkeypatch
) -> None:
    # No light is seen apart from the paths here: its (empty) estimate must not read as
    # "error unknown" everywhere, which kept every denoised pixel, the light's edge blurred
    # into the ceiling included (the Cornell box had 3-7 times the raw image's error). The
    # check that may skip the denoiser is held to "it pays", so that the restore is tested.
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: color * 4.0)
    monkeypatch.setattr(auto.Passes, "denoiser_share", lambda self, error: 1.0)
    full = render(diffuse, options(spp=48, seed=1)).image
    plain = render(diffuse, options(spp=48, seed=1, denoise=False)).image
    light = luminance(plain)
    lit = light > 0.05 * light.max()
    assert lit.sum() > 50
    restored = np.isclose(full[lit], plain[lit], rtol=1e-4, atol=0).all(axis=1)
    assert restored.mean() > 0.5, restored.mean()


def test_the_denoisers_share_is_what_the_halves_show_it_earns(
    diffuse, monkeypatch, tmp_path: Path, capsys
) -> None:
    # Each half, denoised alone, is blended with its plain mean to fit the other half. A
    # "denoiser" that returns the converged image gets (nearly) the whole share; one that
    # flattens the image to its mean little or none of it (the blend no further from the
    # truth than the plain mean); one that adds to the noise none: the plain mean exactly.
    converged = render(diffuse, options(spp=4096, seed=9, denoise=False)).image
    plain = render(diffuse, options(spp=64, seed=2, denoise=False))
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: converged)
    good = render(diffuse, options(spp=64, seed=2))
    assert good.stats["denoised"] and good.stats["denoiser_share"] > 0.9

    def flat(color, albedo, normal, clean=False):
        return np.broadcast_to(color.mean((0, 1)), color.shape)

    monkeypatch.setattr(auto, "denoise", flat)
    blend = render(diffuse, options(spp=64, seed=2))
    assert blend.stats["denoiser_share"] < 0.2
    flattened = flat(plain.image, None, None)
    assert rmse(blend.image, converged) <= 1.001 * rmse(plain.image, converged)
    assert rmse(blend.image, converged) < rmse(flattened, converged)
    # one that returns the converged image 10 % too bright earns part of the share
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: 1.1 * converged)
    biased = render(diffuse, options(spp=64, seed=2))
    assert 0 < biased.stats["denoiser_share"] < 1
    # one that moves nothing (or whose every move the restore undoes) leaves the image alone
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: color)
    idle = render(diffuse, options(spp=64, seed=1))
    assert idle.stats["denoiser_share"] == 1 and idle.stats["denoised"]
    noisier = lambda color, albedo, normal, clean=False: color + 3.0 * (color - converged)  # noqa: E731
    monkeypatch.setattr(auto, "denoise", noisier)
    late = render(diffuse, options(spp=64, seed=2))
    assert not late.stats["denoised"] and late.stats["denoiser_share"] == 0
    np.testing.assert_array_equal(late.image, plain.image)
    # and the command line's summary says so
    from dpm.cli import render_main

    scene = write_scene(tmp_path, toml=CAMERA, stem="cli")
    for flags, said in (([], True), (["--no-denoise"], False)):
        argv = [str(scene), "--spp", "64", "-o", str(tmp_path / "o.exr"), *flags]
        assert render_main(argv) == 0
        assert ("not denoised" in capsys.readouterr().out) == said
    monkeypatch.setattr(auto, "denoise", lambda color, albedo, normal, clean=False: 1.1 * converged)
    assert render_main([str(scene), "--spp", "64", "-o", str(tmp_path / "o.exr")]) == 0
    assert "denoised image weighted 0." in capsys.readouterr().out


def test_light_seen_in_glass_that_every_sample_finds_skips_the_denoiser(
    tmp_path: Path, monkeypatch
) -> None:
    # Every pixel sees the water (its extra light samples are spent there), and every sample
    # of a pixel sees both lights, weighted by Fresnel: that light is known exactly, so it is
    # added after the denoiser. A denoiser that wiped everything leaves it whole.
    scene = load_scene(water_between_lights(tmp_path))
    camera = scene.camera
    assert specular_pixels(scene, build_bvh(scene), camera).all()
    f = fresnel(np.array(1 / math.sqrt(5)), WATER)  # the centre pixel's angle
    centre = np.array([camera.height // 2 * camera.width + camera.width // 2])
    sums, squares = trace_emitted(scene, build_bvh(scene), camera, centre, 64, 3)
    expected = np.array([f * WATER_LE, (1 - f) * WATER_LE / WATER**2, 0])
    np.testing.assert_allclose(sums[0] / 64, expected, rtol=0.005, atol=1e-9)  # F varies a little
    luma = 0.2126 * expected[0] + 0.7152 * expected[1]
    assert squares[0] / 64 == pytest.approx(luma**2, rel=0.005)  # no spread: known exactly
    seen = []

    def wipe(color, albedo, normal, clean=False):
        seen.append(color.copy())
        return np.zeros_like(color)

    monkeypatch.setattr(auto, "denoise", wipe)
    image = render(scene, options(spp=3, seed=1)).image
    assert seen and not seen[0].any()  # the denoiser saw none of the light
    assert image[..., 0].mean() == pytest.approx(expected[0], rel=0.02)
    assert image[..., 1].mean() == pytest.approx(expected[1], rel=0.002)


def test_the_narrow_kernel_is_taken_only_where_the_wide_ones_blur_shows() -> None:
    # Pixels that gathered 400 photons at the wide radius and 100 at half of it. Where the
    # estimates differ by less than their noise the wide one stays (it is the less noisy);
    # where the narrow one sees twice the light (a peak the wide kernel blurs) it is taken;
    # a narrow kernel that found no photon (reading 0) is no evidence of blur.
    def state(values: list[float], counts: list[float], radius: float) -> PPMState:
        s = PPMState.start(len(values), radius)
        s.count[:] = counts
        s.paths = 1000
        s.tau = np.array(values)[:, None] * np.pi * radius**2 * s.paths * np.ones(3)
        return s

    wide = state([1.0, 1.0, 0.0, 1.0], [400, 400, 0, 400], 0.02)
    narrow = state([1.05, 2.0, 0.0, 0.0], [100, 100, 0, 0], 0.01)
    image, sharp = auto.sharper_where_biased(wide, narrow, 2.0)
    assert sharp.tolist() == [False, True, False, False]
    np.testing.assert_allclose(image[:, 0], [1.0, 2.0, 0.0, 1.0])
    _, sharp = auto.sharper_where_biased(wide, narrow, 5.0)  # 1.0 apart: 4.5 errors of 0.22
    assert not sharp.any()


def test_sobol_points_are_uniform_and_stratified_from_any_scramble() -> None:
    rng = np.random.default_rng(0)
    scrambles = rng.integers(0, 2**32, (400, 2))
    for m in (4, 7):  # every aligned run of 2^m points: one in each 2^-a × 2^-(m-a) box
        for start in (0, 2**m, 5 * 2**m):
            for sx, sy in scrambles[:5]:
                pts = np.array([sobol2(start + k, sx, sy) for k in range(2**m)])
                for a in range(m + 1):
                    cells = (pts * [2**a, 2 ** (m - a)]).astype(int)
                    assert len(np.unique(cells, axis=0)) == 2**m
    for k in (0, 1, 6):  # point k over random scrambles: uniform in the unit square
        pts = np.array([sobol2(k, sx, sy) for sx, sy in scrambles])
        assert pts.min() >= 0 and pts.max() < 1
        counts = np.histogram2d(pts[:, 0], pts[:, 1], bins=4, range=[[0, 1], [0, 1]])[0]
        assert counts.min() > 10 and counts.max() < 45  # 25 expected in each of 16 cells


def test_a_light_edge_across_a_pixel_is_found_in_its_share_of_the_samples(tmp_path: Path) -> None:
    # The camera looks straight at a light whose edge cuts one pixel: the light's share of
    # that pixel, over 64 samples of its stratified sequence, is off by at most one sample
    # (at random it would be off by four: sqrt(64 · 0.3 · 0.7)), and calls that continue
    # the sequence add up to one call.
    def scene_with_edge(edge: float):
        obj = (  # the light, and a wall behind the camera for it to light
            f"mtllib scene.mtl\nv {edge} -10 0\nv 10 -10 0\nv 10 10 0\nv {edge} 10 0\n"
            "v -10 -10 6\nv 10 -10 6\nv 10 10 6\nv -10 10 6\n"
            "usemtl light\nf 1 2 3 4\nusemtl wall\nf 5 8 7 6\n"
        )
        toml = (
            "[camera]\norigin = [0, 0, 5]\ntarget = [0, 0, 0]\nfov = 10\nwidth = 16\nheight = 16\n"
        )
        return load_scene(
            write_scene(
                tmp_path, obj, "newmtl light\nKe 2 2 2\nnewmtl wall\nKd 0.5 0.5 0.5\n", toml
            )
        )

    camera = scene_with_edge(0.0).camera
    # where the pixel's left and right edges (image columns 8 and 9) meet the light's plane
    x = [5 * d[0] / -d[2] for d in (camera_ray(camera.basis(), 16, 16, c, 8.5) for c in (8, 9))]
    share = 0.3
    scene = scene_with_edge(max(x) - share * abs(x[1] - x[0]))  # lit: x beyond the edge
    bvh, pixel = build_bvh(scene), np.array([8 * 16 + 8])
    found = []
    for seed in range(20):
        sums, _ = trace_emitted(scene, bvh, camera, pixel, 64, seed)
        found.append(sums[0, 0] / 2)  # samples that saw the light
        half, _ = trace_emitted(scene, bvh, camera, pixel, 32, seed)
        rest, _ = trace_emitted(scene, bvh, camera, pixel, 32, seed, 32)
        np.testing.assert_allclose(half + rest, sums, rtol=1e-12)
    assert np.all(np.abs(np.array(found) - 64 * share) <= 1 + 1e-9)
    assert np.mean(found) == pytest.approx(64 * share, abs=0.25)


def test_the_tone_map_keeps_shadows_and_never_clips_highlights() -> None:
    x = np.linspace(0, 50, 2001, dtype=np.float32)
    grey = tone_map(np.repeat(x[None, :, None], 3, axis=2))[0, :, 0]
    below = x <= KNEE
    np.testing.assert_allclose(grey[below], x[below], rtol=1e-6)
    assert np.all(np.diff(grey) > 0) and grey.max() < 1.0  # strictly increasing: no clip
    colour = tone_map(np.array([[[4.0, 2.0, 1.0]]], np.float32))[0, 0]
    np.testing.assert_allclose(colour / colour[0], [1.0, 0.5, 0.25], rtol=1e-6)  # hue kept
    assert linear_to_srgb8(np.full((1, 1, 3), np.nan, np.float32)).max() == 0


def test_bad_budgets_are_refused(glass) -> None:
    from dpm.errors import InputError

    for bad in (0.0, -1.0, float("nan"), float("inf")):
        with pytest.raises(InputError, match="--time"):
            render(glass, options(time=bad))
    with pytest.raises(InputError, match="--time applies to auto only"):
        render(glass, RenderOptions(method="ppm", time=1.0, progress=False))


def test_pixels_the_denoiser_moves_beyond_their_own_error_are_given_back() -> None:
    # A glint every path of its pixel saw (30 ± 0.5) that the denoiser wiped comes back; a
    # change within the pixel's error stays; halfway between z and 2z errors, half of each.
    color = np.ones((4, 4, 3), np.float32)
    color[0, 0] = 30.0
    denoised = np.ones_like(color)
    error = np.full((4, 4), 0.5)
    denoised[1, 1] = 1.0 + 0.5 * RESTORE_Z * error[1, 1]  # within z errors
    denoised[2, 2] = 1.0 + 1.5 * RESTORE_Z * error[2, 2]  # between z and 2z
    out = restore_certain(color, denoised, error)
    np.testing.assert_allclose(out[0, 0], 30.0)
    np.testing.assert_allclose(out[1, 1], denoised[1, 1])
    np.testing.assert_allclose(out[2, 2], (color[2, 2] + denoised[2, 2]) / 2, rtol=1e-6)
    np.testing.assert_allclose(out[3, 3], 1.0)


def test_a_lone_photon_is_spread_not_a_speck_and_dense_caustics_are_kept() -> None:
    """`spread_sparse`: pixels whose discs hold fewer than SPARSE_PHOTONS photons share the
    mean of a window holding that many (energy kept within a few per cent); a dense caustic
    beside them is left bit for bit, and does not bleed into them."""
    h = w = 40
    caustic, count = np.zeros((h, w, 3)), np.zeros((h, w))
    for dy, dx in ((0, 0), (1, 0), (-1, 0), (0, 1), (0, -1)):  # one photon in 5 pixels' discs
        caustic[10 + dy, 10 + dx] = 2.0
        count[10 + dy, 10 + dx] = 0.7
    caustic[25:35, 25:35], count[25:35, 25:35] = 5.0, 50.0  # a dense caustic
    overlap = np.full(h * w, 5.0)
    out, behind = auto.spread_sparse(caustic.reshape(-1, 3), count.ravel(), overlap, h, w)
    out, behind = out.reshape(h, w, 3), behind.reshape(h, w)
    sparse = np.ones((h, w), bool)
    sparse[25:35, 25:35] = False
    assert out[sparse].max() < 0.05 * caustic[sparse].max()  # no speck left
    assert out[sparse].sum() == pytest.approx(caustic[sparse].sum(), rel=0.1)
    np.testing.assert_array_equal(out[25:35, 25:35], caustic[25:35, 25:35])
    assert out[36:, 25:35].max() == 0  # the dense caustic does not bleed
    # the photons behind each estimate: a dense pixel's own, a spread one's its window's
    np.testing.assert_array_equal(behind[25:35, 25:35], count[25:35, 25:35])
    assert behind[10, 10] == pytest.approx(5 * 0.7 / 5.0)  # the one photon, counted once


def test_stray_caustic_photons_leave_no_specks(tmp_path: Path) -> None:
    """The Quick start's glass egg: light refracted far from its caustic reaches the floor as
    single photons, which at the sidecar's 16 passes painted ~100 isolated specks (islands of
    a few pixels: one photon's discs) over the floor, in light and in shadow."""
    from scipy.ndimage import label

    egg = load_scene(Path(__file__).parents[1] / "examples" / "scenes" / "glass_egg.obj")
    options = RenderOptions(method="auto", component="caustic", width=96, height=96)
    options.spp, options.photons = 16, 200_000  # the sidecar's
    options.progress = False
    image = render(egg, options).image.mean(axis=2)
    islands, n = label(image > 0)
    sizes = np.bincount(islands.ravel())[1:]
    assert n >= 1 and (sizes <= 15).sum() <= 2, sorted(sizes)[:20]


def test_the_learned_filter_paints_no_specks_back() -> None:
    """The glass egg's floor, lit by light reflected off the egg, holds single photons that
    `spread_sparse` spreads; the learned filter, reading each pixel's own photons, painted
    them back (the default render showed ~50 specks on the floor: 47 local peaks at 96², 14
    without the network). Its move at a sparse pixel is held within CLAMP_Z standard errors
    of the spread estimate (`held_move`): no more peaks than without it."""
    from scipy.ndimage import maximum_filter, median_filter

    egg = load_scene(Path(__file__).parents[1] / "examples" / "scenes" / "glass_egg.obj")

    def peaks(network: bool) -> int:
        options = RenderOptions(method="auto", component="caustic", width=96, height=96,
                                network=network, progress=False)  # fmt: skip
        options.spp, options.photons = 16, 200_000  # the sidecar's
        image = render(egg, options).image.mean(axis=2)
        # local maxima three times brighter than their 9 x 9 neighbourhood's median
        return int(
            ((image > 3 * median_filter(image, 9)) & (image == maximum_filter(image, 5))).sum()
        )

    assert peaks(True) <= peaks(False) + 5


@pytest.mark.parametrize(
    ("scene", "spp", "clean"),
    [("diffuse", 24, [True, True, True]), ("diffuse", 12, [True, False, False]),
     ("glass", 16, [False])],
)  # fmt: skip
def test_the_guides_count_as_clean_from_enough_paths_without_glass(
    scene, spp, clean, request, monkeypatch
) -> None:
    """The denoiser is told its guides are noise-free (OIDN's cleanAux) where each call's
    guides average CLEAN_GUIDE_PATHS paths or more and no mirror or glass is in the scene:
    the whole image and each half `denoiser_share` checks (passes of 1, 1, 2, 2, 4, 4, 8 and 2
    paths: halves of 15 and 9; of 12 paths, 7 and 5)."""
    calls = []

    def recording(color, albedo, normal, clean_aux=False):
        calls.append(clean_aux)
        return color

    monkeypatch.setattr(auto, "denoise", recording)
    render(request.getfixturevalue(scene), options(spp=spp, seed=1))
    assert calls == clean
