"""Defaults come from what the camera sees: geometry out of view changes no render.

A progressive method's initial radius once was a fraction of the scene's bounding box, so a
tiny triangle far behind the camera (the box's diagonal grows a thousandfold) changed every
radius-based render. Now each method at its defaults must keep its error within 10 %.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest
from test_truths import glass_radiance, glass_scene, pixel_truth

from dpm import load_scene
from dpm.density.radius import FOOTPRINTS, NEAREST, SHAPE, initial_radii
from dpm.methods import METHODS, method_class
from dpm.renderer import RenderOptions, render
from dpm.tracer import PhotonMap

FAR = 1000.0  # the triangle's distance behind the camera (scene units; the scene is ~4 wide)
PHOTONS = 100_000  # emitted paths: a small render, the rest of each method's settings default


def with_far_triangle(obj: Path) -> Path:
    """A copy of the scene `obj` (same folder, material and sidecar) with a triangle of side
    0.01 FAR units behind its camera, facing away from the scene."""
    scene = load_scene(obj)
    c = scene.camera
    forward = (c.target - c.origin) / np.linalg.norm(c.target - c.origin)
    centre = c.origin - FAR * forward
    side = np.cross(forward, [1.0, 0.0, 0.0] if abs(forward[0]) < 0.9 else [0.0, 0.0, 1.0])
    side *= 0.01 / np.linalg.norm(side)
    up = np.cross(forward, side)
    corners = [centre, centre + side, centre + up]
    text = obj.read_text()
    n = sum(line.startswith("v ") for line in text.splitlines())
    far = obj.with_name("far.obj")
    lines = ["o far", "usemtl floor", *(f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in corners)]
    far.write_text(text + "\n".join([*lines, f"f {n + 1} {n + 3} {n + 2}"]) + "\n")
    far.with_suffix(".toml").write_text(obj.with_suffix(".toml").read_text())
    return far


@pytest.fixture(scope="module")
def scenes(tmp_path_factory: pytest.TempPathFactory) -> tuple:
    """The glass-slab truth scene, the same with a far triangle, and the caustic truth."""
    plain = glass_scene(tmp_path_factory.mktemp("view") / "glass")
    far = with_far_triangle(plain)
    a, b = load_scene(plain), load_scene(far)
    assert np.linalg.norm(np.subtract(*b.bounds)) > 100 * np.linalg.norm(np.subtract(*a.bounds))
    return a, b, pixel_truth(a.camera, glass_radiance)


def error(image: np.ndarray, truth: np.ndarray) -> float:
    """RMSE of a grey image's channel mean (H, W, 3) against the truth (H, W)."""
    return float(np.sqrt(np.mean((image.mean(axis=2) - truth) ** 2)))


@pytest.mark.slow
@pytest.mark.parametrize("method", list(METHODS))
def test_far_geometry_changes_no_error(scenes: tuple, method: str) -> None:
    plain, far, truth = scenes
    cls = method_class(method)
    component = "caustic" if cls.caustic_component else "full"
    options = RenderOptions(
        method=method, photons=PHOTONS, spp=4, component=component, progress=False,
        denoise=False,
    )  # fmt: skip
    errors = [error(render(s, options).image, truth) for s in (plain, far)]
    assert errors[1] == pytest.approx(errors[0], rel=0.1), (method, errors)


def test_initial_radii_follow_density_and_footprint() -> None:
    # Photons on a plane, uniform at density n per unit area: the radius of the disc that
    # holds the NEAREST-th is about √(k / (π n)); a point far from all photons gets the
    # footprint's cap; no bounding box anywhere.
    rng = np.random.default_rng(3)
    n = 40_000
    xy = rng.uniform(-1, 1, (n, 2))
    position = np.c_[xy, np.zeros(n)].astype(np.float32)
    normal = np.tile(np.float32([0, 0, 1]), (n, 1))
    flux = np.full((n, 3), 1 / n, np.float32)
    photons = PhotonMap(
        position, normal, flux, normal.copy(), np.ones(n, bool), np.ones(n, np.uint16),
        np.arange(n), n,
    )  # fmt: skip
    points = np.array([[0.0, 0.0, 0.0], [0.3, -0.2, 0.0], [50.0, 0.0, 0.0]])
    up = np.tile([0.0, 0.0, 1.0], (3, 1))
    footprint = np.full(3, 0.01)
    r = initial_radii(points, up, footprint, photons)
    density = n / 4
    knn = math.sqrt(NEAREST / (math.pi * density))
    expected = SHAPE * knn ** (1 / 3) * 0.01 ** (2 / 3)
    np.testing.assert_allclose(r[:2], min(expected, FOOTPRINTS * 0.01), rtol=0.35)
    assert r[2] == pytest.approx(FOOTPRINTS * 0.01)
