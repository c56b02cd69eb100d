"""Rendering: determinism over thread counts and the files the CLI writes."""

from __future__ import annotations

import json
import os
from pathlib import Path

import imageio.v3 as iio
import numba
import numpy as np

from dpm import load_scene
from dpm.cli import render_main
from dpm.denoise import guides
from dpm.density.base import luminance
from dpm.estimators import PM
from dpm.estimators.sppm import default_paths_per_pass
from dpm.io import read_exr
from dpm.renderer import RenderOptions, render
from dpm.tracer import (
    build_bvh,
    shade,
    trace_listed,
    trace_photons,
    trace_pixels,
    trace_visible_points,
)
from dpm.tracer import path as path_module
from dpm.tracer.sampling import sequence_seed

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"


def test_same_seed_same_image_for_any_thread_count(scene_path: Path) -> None:
    scene = load_scene(scene_path)
    opts = RenderOptions(method="pt", spp=2, width=24, height=16, seed=3, progress=False)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = render(scene, opts).image
    finally:
        numba.set_num_threads(before)
    two = render(scene, opts).image
    np.testing.assert_array_equal(one, two)
    opts.seed = 4
    assert not np.array_equal(one, render(scene, opts).image)


def test_cli_writes_exr_png_and_stats(scene_path: Path, capsys) -> None:
    folder = scene_path.parent
    argv = [str(scene_path), "--width", "20", "--height", "10", "--spp", "2", "--seed", "1"]
    assert render_main([*argv, "-o", str(folder / "a.exr"), "--stats", str(folder / "s.json")]) == 0
    assert "wrote" in capsys.readouterr().out
    assert render_main([*argv, "-o", str(folder / "a.png"), "--quiet"]) == 0
    assert capsys.readouterr().out == ""
    linear = read_exr(folder / "a.exr")
    png = iio.imread(folder / "a.png")
    assert linear.shape == (10, 20, 3) and png.shape == (10, 20, 3) and png.dtype == np.uint8
    assert np.all(np.isfinite(linear)) and linear.max() > 0
    stats = json.loads((folder / "s.json").read_text())
    assert stats["width"] == 20 and stats["spp"] == 2 and stats["triangles"] == 4
    assert set(stats["seconds"]) >= {"load", "bvh", "path", "write"}
    assert stats["samples"] == 400 and stats["nonfinite_samples"] == 0
    umask = os.umask(0)
    os.umask(umask)
    assert (folder / "a.png").stat().st_mode & 0o777 == 0o666 & ~umask
    # No temporary files are left next to the outputs.
    assert sorted(p.name for p in folder.iterdir()) == [
        "a.exr", "a.png", "s.json", "scene.mtl", "scene.obj",
    ]  # fmt: skip


def test_pt_and_pt_nocaustic_share_visible_points_and_random_numbers(scene_path: Path) -> None:
    # Without mirrors or glass there are no caustics, so the two methods must agree exactly.
    scene = load_scene(scene_path)
    opts = RenderOptions(method="pt", spp=3, width=16, height=12, seed=7, progress=False)
    full = render(scene, opts).image
    opts.method = "pt-nocaustic"
    np.testing.assert_array_equal(full, render(scene, opts).image)


def test_whole_pixel_tracing_equals_visible_points_then_shading() -> None:
    # pt renders whole pixels in one kernel; it must be the two-stage path's samples exactly
    # (glass, a light seen directly and through glass, misses), up to float rounding.
    # Also with the pixels' stratified sequences (from sample 6 on, as a later pass's).
    scene = load_scene(EXAMPLES / "glass_egg.obj")
    bvh, camera, spp = build_bvh(scene), scene.camera.with_resolution(24, 20), 4
    for caustics, sequence in ((True, None), (False, None), (True, (9, 6)), (False, (9, 6))):
        image, albedo, normal, hits, bad = trace_pixels(
            scene, bvh, camera, spp, 5, (3, 17), caustics, sequence
        )
        points = trace_visible_points(scene, bvh, camera, spp, 5, (3, 17), sequence)
        reflected, dropped = shade(scene, bvh, points, 5, caustics, None, sequence, spp)
        per_sample = [points.emitted + points.throughput * reflected, *guides(points)]
        for got, want in zip((image, albedo, normal), per_sample, strict=True):
            want = want.astype(np.float64).reshape(14, 24, spp, 3).mean(axis=2)
            np.testing.assert_allclose(got, want, rtol=1e-5, atol=1e-6)
        assert (hits, bad) == (int(points.hit.sum()), dropped) and 0 < hits < len(points)
        assert image.max() > 0 and (albedo > 0).any()


def test_listed_pixels_trace_the_same_paths_as_whole_pixels(monkeypatch) -> None:
    # Adaptive sampling's extra paths (trace_listed) at every pixel of some rows, spp each,
    # are pt-nocaustic's paths of those pixels: the same sums, and the squared luminances of
    # the very samples that visible points then shading give; also when a pixel's paths are
    # split over several tasks (here 3 + 1).
    monkeypatch.setattr(path_module, "PATHS_PER_TASK", 3)
    scene = load_scene(EXAMPLES / "glass_egg.obj")
    bvh, camera, spp = build_bvh(scene), scene.camera.with_resolution(24, 20), 4
    image = trace_pixels(scene, bvh, camera, spp, 5, (3, 17), False)[0]
    pixels = np.arange(3 * 24, 17 * 24)
    sums, squares, bad = trace_listed(scene, bvh, camera, pixels, np.full(len(pixels), spp), 5)
    np.testing.assert_allclose(sums / spp, image.reshape(-1, 3), rtol=1e-5, atol=1e-6)
    points = trace_visible_points(scene, bvh, camera, spp, 5, (3, 17))
    reflected, dropped = shade(scene, bvh, points, 5, False)
    lum = luminance((points.emitted + points.throughput * reflected).astype(np.float64))
    np.testing.assert_allclose(squares, (lum**2).reshape(-1, spp).sum(axis=1), rtol=1e-4)
    assert bad == dropped and squares.max() > 0


def test_caustic_component_is_the_estimate_times_the_camera_throughput() -> None:
    scene = load_scene(EXAMPLES / "glass_egg.obj")
    opts = RenderOptions(method="pm", spp=2, width=16, height=16, photons=50_000, k=20,
                         seed=2, component="caustic", progress=False)  # fmt: skip
    caustic = render(scene, opts)
    assert caustic.stats["caustic_photons"] > 20 and caustic.image.max() > 0
    bvh = build_bvh(scene)
    camera, sequence = scene.camera.with_resolution(16, 16), (sequence_seed(2), 0)
    points = trace_visible_points(scene, bvh, camera, 2, 2, (0, 16), sequence)  # the render's
    photons = trace_photons(scene, bvh, 50_000, seed=2, caustic_only=True)
    expected = points.throughput * PM(k=20).estimate(points, photons)
    np.testing.assert_allclose(caustic.image, expected.reshape(16, 16, 2, 3).mean(axis=2))
    # full = pt-nocaustic + caustic, from the same visible points.
    opts.component = "full"
    full = render(scene, opts).image
    rest = render(scene, RenderOptions(method="pt-nocaustic", spp=2, width=16, height=16,
                                       seed=2, progress=False)).image  # fmt: skip
    np.testing.assert_allclose(full, rest + caustic.image, rtol=1e-5, atol=1e-6)


def test_a_scene_without_specular_surfaces_has_a_black_caustic_image(scene_path: Path) -> None:
    scene = load_scene(scene_path)
    for method in ("pm", "ppm", "appm", "sppm"):
        opts = RenderOptions(method=method, spp=1, width=8, height=8, photons=5000,
                             component="caustic", progress=False)  # fmt: skip
        result = render(scene, opts)
        assert result.stats["caustic_photons"] == 0 and not result.image.any(), method


def test_cli_writes_exr_and_png_by_default(scene_path: Path, monkeypatch, capsys) -> None:
    monkeypatch.chdir(scene_path.parent)
    argv = [str(scene_path), "--width", "12", "--height", "8", "--spp", "1"]
    assert render_main(argv) == 0
    assert "scene.exr, scene.png" in capsys.readouterr().out
    linear, png = read_exr("scene.exr"), iio.imread("scene.png")
    assert linear.shape == png.shape == (8, 12, 3)
    assert render_main([*argv, "-o", "b.png", "-o", "b.exr", "--quiet"]) == 0
    np.testing.assert_array_equal(read_exr("b.exr"), linear)  # same seed, same image


def test_sppm_passes_follow_the_pixel_count(scene_path: Path) -> None:
    # Each sppm pass is also one camera sample per pixel, so its default paths per pass come
    # from the pixel count, not from the photon budget; --photons-per-pass still rules.
    scene = load_scene(scene_path)
    for width, height in ((8, 8), (16, 8)):
        opts = RenderOptions(method="sppm", spp=1, width=width, height=height, photons=1000,
                             component="caustic", progress=False, denoise=False)  # fmt: skip
        stats = render(scene, opts).stats
        assert stats["photons_per_pass"] == default_paths_per_pass(1000, width * height)
    assert default_paths_per_pass(1000, 64) == 16  # 0.25 per pixel
    assert default_paths_per_pass(5000, 10**6) == 5000  # never more than the run
    assert default_paths_per_pass(10**7, 64) == 10**4  # at most MAX_PASSES passes
    assert default_paths_per_pass(5000, 0) == 5
    opts.photons_per_pass = 700
    assert render(scene, opts).stats["photons_per_pass"] == 700
