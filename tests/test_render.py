"""Direct lighting against analytic irradiance; determinism; the written files."""

from __future__ import annotations

import json
import math
import os
from pathlib import Path

import imageio.v3 as iio
import numba
import numpy as np
import pytest

from conftest import write_scene
from dpm import load_scene
from dpm.cli import render_main
from dpm.io import read_exr
from dpm.render import RenderOptions, render

RHO, LE, SIDE, HEIGHT = 0.5, 10.0, 0.2, 1.0


def corner_form_factor(a: float, b: float, h: float) -> float:
    """Form factor from a point to the rectangle [0,a]×[0,b] on a parallel plane at height h."""
    x, y = a / h, b / h
    sx, sy = math.sqrt(1 + x * x), math.sqrt(1 + y * y)
    return (x / sx * math.atan(y / sx) + y / sy * math.atan(x / sy)) / (2 * math.pi)


def rectangle_form_factor(px: float, pz: float) -> float:
    """Form factor from floor point (px, 0, pz) to the centred square light at HEIGHT."""
    total = 0.0
    for x, sign_x in ((SIDE / 2 - px, 1), (-SIDE / 2 - px, -1)):
        for z, sign_z in ((SIDE / 2 - pz, 1), (-SIDE / 2 - pz, -1)):
            # Signed corner rectangles add up to the offset rectangle (superposition).
            f = corner_form_factor(abs(x), abs(z), HEIGHT)
            total += sign_x * sign_z * math.copysign(1, x) * math.copysign(1, z) * f
    return total


def light_over_floor(folder: Path, target: tuple[float, float, float]) -> Path:
    """A 20×20 floor of albedo RHO under a SIDE² light of radiance LE; a 0.5° camera at target."""
    s, h, f = SIDE / 2, HEIGHT, 10
    obj = f"""mtllib scene.mtl
v {-f} 0 {-f}
v {f} 0 {-f}
v {f} 0 {f}
v {-f} 0 {f}
v {-s} {h} {-s}
v {s} {h} {-s}
v {s} {h} {s}
v {-s} {h} {s}
usemtl floor
f 1 4 3 2
usemtl light
f 5 6 7 8
"""
    mtl = f"newmtl floor\nKd {RHO} {RHO} {RHO}\nnewmtl light\nKe {LE} {LE} {LE}\n"
    tx, ty, tz = target
    toml = f"""[camera]
origin = [{tx + 0.3}, 0.6, {tz + 1.5}]
target = [{tx}, {ty}, {tz}]
fov = 0.5
width = 16
height = 16
"""
    return write_scene(folder, obj, mtl, toml)


@pytest.mark.parametrize("target", [(0.0, 0.0, 0.0), (0.3, 0.0, -0.15), (-0.8, 0.0, 0.5)])
def test_square_light_over_plane_matches_analytic_radiance(tmp_path: Path, target) -> None:
    scene = load_scene(light_over_floor(tmp_path, target))
    image = render(scene, RenderOptions(spp=256, progress=False)).image
    # Lambertian: L = ρ/π · E and E = π · LE · F, so L = ρ · LE · F.
    expected = RHO * LE * rectangle_form_factor(target[0], target[2])
    assert image.mean() == pytest.approx(expected, rel=0.01)
    assert np.allclose(image[..., 0], image[..., 1]) and np.allclose(image[..., 0], image[..., 2])


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
    assert set(stats["seconds"]) >= {"load", "bvh", "render", "write"}
    umask = os.umask(0)
    os.umask(umask)
    assert (folder / "a.png").stat().st_mode & 0o777 == 0o666 & ~umask
    # No temporary files are left next to the outputs.
    assert sorted(p.name for p in folder.iterdir()) == [
        "a.exr", "a.png", "s.json", "scene.mtl", "scene.obj",
    ]  # fmt: skip
