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
from dpm.io import read_exr
from dpm.render import RenderOptions, render


def test_same_seed_same_image_for_any_thread_count(scene_path: Path) -> None:
    scene = load_scene(scene_path)
    opts = RenderOptions(spp=2, width=24, height=16, seed=3, progress=False)
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
    assert set(stats["seconds"]) >= {"load", "bvh", "visible_points", "shade", "write"}
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
    opts = RenderOptions(spp=3, width=16, height=12, seed=7, progress=False)
    full = render(scene, opts).image
    opts.method = "pt-nocaustic"
    np.testing.assert_array_equal(full, render(scene, opts).image)
