"""LuxCoreRender, the second peer renderer, against Mitsuba 3's `path` on example scenes.

Each renderer renders a scene twice with independent seeds; the two renders estimate its
per-pixel noise. Every 8×8 block mean must agree within 4σ and the image mean of each channel
within TOLERANCE, with enough samples that TOLERANCE is at least three standard deviations.
Plain PATHCPU (unbiased) checks the conversion: camera, units and lights on the diffuse Cornell
box (a wide image), glass with a coloured Tf and a coloured mirror (lit from its back) on a
scene with a large light. The PhotonGI caustic cache (consistent: its lookup radius shrinks as
it renders) is checked on that scene and on the example ring as the benchmarks run it, by
time. The example ring and glass egg have small lights, whose caustics and images through
glass come from rare, very bright paths: a short LuxCore render, and Mitsuba at 16384 spp,
sample these too seldom for a per-block test (a far-floor block of the ring's Mitsuba image
was 4 % under one with 4x the samples), so on the ring only the image means are compared.

pyluxcore loads TBB's malloc into its process, after which importing SciPy, Numba, Dr.Jit and
others aborts ("free(): invalid pointer"). So LuxCore renders in child processes
(`render_luxcore`), and this module never imports pyluxcore: it skips on `find_spec` rather
than `pytest.importorskip`, which would import it into the test process.
"""

from __future__ import annotations

import math
from importlib.util import find_spec
from pathlib import Path

import numpy as np
import pytest

from conftest import write_scene
from dpm import load_scene
from dpm.validation.luxcore import (
    RADIUS_FOOTPRINTS,
    caustic_radii,
    config_properties,
    has_specular,
    render_luxcore,
    scene_properties,
)
from dpm.validation.mitsuba import render_mitsuba
from dpm.validation.noise import block_z

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
SEEDS = (3, 4)  # Mitsuba keeps only a seed's low bits: small ones, as tests/test_mitsuba.py
TOLERANCE = 0.02  # relative, per channel, on the image mean
NEEDS_LUXCORE = pytest.mark.skipif(
    find_spec("pyluxcore") is None, reason="pyluxcore is not installed (the bench extra)"
)


def channel_sigma(a: list[np.ndarray], b: list[np.ndarray]) -> np.ndarray:
    """(3,) standard deviation of mean(a) − mean(b) per channel, relative to mean(b)."""
    var = np.zeros(3)
    for pair in (a, b):
        x = np.stack(pair).astype(np.float64)
        var += ((x[0] - x[1]) ** 2 / 4).sum(axis=(0, 1)) / (x[0].shape[0] * x[0].shape[1]) ** 2
    return np.sqrt(var) / np.mean(b, axis=(0, 1, 2))


def agree(name: str, lux: list[np.ndarray], mitsuba: list[np.ndarray]) -> None:
    """Assert LuxCore and Mitsuba agree: blocks within 4σ, channel means within TOLERANCE."""
    z = block_z(lux, mitsuba)
    sigma = channel_sigma(lux, mitsuba)
    ratio = np.mean(lux, axis=(0, 1, 2)) / np.mean(mitsuba, axis=(0, 1, 2))
    print(f"{name}: LuxCore / Mitsuba mean per channel {np.round(ratio, 4)},"
          f" σ {np.round(sigma, 4)}, max |z| {np.abs(z).max():.2f}")  # fmt: skip
    assert np.abs(z).max() < 4, np.round(z.max(axis=2), 1)
    assert np.all(sigma < TOLERANCE / 3), f"too few samples for the test: σ = {sigma}"
    assert np.all(np.abs(ratio - 1) < TOLERANCE), ratio


def glass_and_mirror(folder: Path) -> Path:
    """A glass cube (Ni 1.5, Tf 0.9 0.7 0.5, turned 30°) and a gold mirror (Ks 0.9 0.8 0.5,
    lit from its back: mirrors are two-sided) on a floor under a large light."""
    c, s = math.cos(math.radians(30)), math.sin(math.radians(30))
    corners = [
        (c * x + s * z - 0.1, y + 0.4, c * z - s * x)
        for x in (-0.35, 0.35) for y in (-0.35, 0.35) for z in (-0.35, 0.35)
    ]  # fmt: skip
    floor = [(-3, 0, -3), (3, 0, -3), (3, 0, 3), (-3, 0, 3)]
    light = [(0.3, 2, -0.9), (1.5, 2, -0.9), (1.5, 2, 0.3), (0.3, 2, 0.3)]
    mirror = [(0.5, 0.02, -1.3), (0.5, 0.9, -1.3), (1.5, 0.9, -1.3), (1.5, 0.02, -1.3)]
    faces = ["1 2 4 3", "5 7 8 6", "1 5 6 2", "3 4 8 7", "1 3 7 5", "2 6 8 4"]  # outward
    obj = ["mtllib scene.mtl", *(f"v {x} {y} {z}" for x, y, z in corners + floor + light + mirror)]
    obj += ["usemtl glass", *(f"f {f}" for f in faces), "usemtl floor", "f 9 12 11 10"]
    obj += [
        "usemtl light",
        "f 13 14 15 16",
        "usemtl gold",
        "f 17 18 19 20",
    ]  # light: down, mirror: -z
    mtl = "newmtl glass\nillum 7\nNi 1.5\nTf 0.9 0.7 0.5\nnewmtl floor\nKd 0.7 0.7 0.7\n"
    mtl += "newmtl light\nKe 6 6 6\nnewmtl gold\nillum 3\nKs 0.9 0.8 0.5\n"
    toml = "[camera]\norigin = [0.0, 1.6, 2.4]\ntarget = [0.2, 0.3, -0.3]\nfov = 50\n"
    return write_scene(folder, "\n".join(obj) + "\n", mtl, toml)


def renders(
    path: Path, size: int | tuple[int, int], mitsuba_spp: int, **luxcore
) -> tuple[list, list]:
    """Two LuxCore renders (keyword arguments of render_luxcore) and two Mitsuba renders, at
    size × size or (width, height) pixels."""
    scene = load_scene(path)
    width, height = size if isinstance(size, tuple) else (size, size)
    camera = scene.camera.with_resolution(width, height)
    lux = []
    for seed in SEEDS:
        image, stats = render_luxcore(scene, camera, seed=seed, **luxcore)
        print(f"{path.stem}: {stats}")
        lux.append(image)
    return lux, [render_mitsuba(scene, camera, mitsuba_spp, seed=s) for s in SEEDS]


@pytest.mark.validation
@NEEDS_LUXCORE
def test_diffuse_scene_agrees_with_mitsuba() -> None:
    # Wider than high: LuxCore's field of view would span the longer side, here the width.
    lux, mitsuba = renders(EXAMPLES / "cornell_box.obj", (64, 48), 4096, spp=1024)  # ~1 min
    agree("cornell_box", lux, mitsuba)


@pytest.mark.validation
@NEEDS_LUXCORE
def test_glass_and_mirror_agree_with_mitsuba(tmp_path: Path) -> None:
    scene = glass_and_mirror(tmp_path)
    lux, mitsuba = renders(scene, 32, 8192, spp=4096, caustics=False)  # ~40 s
    agree("glass and mirror (plain PATHCPU)", lux, mitsuba)


@pytest.mark.validation
@NEEDS_LUXCORE
def test_caustic_cache_agrees_with_mitsuba(tmp_path: Path) -> None:
    scene = glass_and_mirror(tmp_path)
    lux, mitsuba = renders(scene, 32, 16384, seconds=45)  # ~2 min
    agree("glass and mirror (PhotonGI caustic cache)", lux, mitsuba)


@pytest.mark.validation
@NEEDS_LUXCORE
def test_caustic_cache_on_the_ring_keeps_the_image_mean() -> None:
    # Means only: Mitsuba's caustics from the ring's small light come from rare, very bright
    # paths; at 16384 spp a block of its far floor still misses ~4 % (against 4x the samples).
    lux, mitsuba = renders(EXAMPLES / "ring.obj", 32, 32768, seconds=30)  # ~2 min
    ratio = np.mean(lux, axis=(0, 1, 2)) / np.mean(mitsuba, axis=(0, 1, 2))
    sigma = channel_sigma(lux, mitsuba)
    print(f"ring (PhotonGI caustic cache): LuxCore / Mitsuba mean per channel"
          f" {np.round(ratio, 4)}, σ {np.round(sigma, 4)}")  # fmt: skip
    assert np.all(sigma < TOLERANCE / 3), f"too few samples for the test: σ = {sigma}"
    assert np.all(np.abs(ratio - 1) < TOLERANCE), ratio


# The conversion itself, without pyluxcore (fast, in the default run).


def test_camera_keeps_the_horizontal_field_of_view_on_any_aspect() -> None:
    scene = load_scene(EXAMPLES / "cornell_box.obj")
    camera = scene.camera.with_resolution(64, 32)
    props = scene_properties(scene, camera)
    assert props["scene.camera.fieldofview"] == camera.fov
    # x spans [-1, 1] (the fov); y spans H/W of it, shifted down by LuxCore's one-row offset
    assert props["scene.camera.screenwindow"] == [-1.0, 1.0, -34 / 64, 30 / 64]
    assert props["scene.camera.lookat.orig"] == camera.origin.tolist()


def test_materials_lights_and_cache_follow_the_scene() -> None:
    ring, egg = load_scene(EXAMPLES / "ring.obj"), load_scene(EXAMPLES / "glass_egg.obj")
    mirror, glass = scene_properties(ring, ring.camera), scene_properties(egg, egg.camera)
    gold = f"scene.materials.mat{ring.materials.names.index('gold')}"
    lens = f"scene.materials.mat{egg.materials.names.index('glass')}"
    light = f"scene.materials.mat{egg.materials.names.index('light')}"
    assert mirror[f"{gold}.type"] == "mirror"
    assert mirror[f"{gold}.kr"] == pytest.approx([0.9, 0.8, 0.5])
    assert glass[f"{lens}.type"] == "glass" and glass[f"{lens}.kt"] == pytest.approx([1.0] * 3)
    assert glass[f"{lens}.interiorior"] == pytest.approx(1.5)
    assert glass[f"{light}.emission"] == pytest.approx([2550.0] * 3)
    assert glass[f"{light}.emission.power"] == 0.0  # the value is radiance, as given
    assert has_specular(ring) and not has_specular(load_scene(EXAMPLES / "cornell_box.obj"))
    config = config_properties(ring.camera, seed=5, spp=16)
    radius, minimum = caustic_radii(ring.camera)
    footprint = ring.camera.footprint(ring.camera.target[None])[0]
    assert radius == pytest.approx(RADIUS_FOOTPRINTS * footprint) and minimum < radius
    assert config["path.photongi.caustic.lookup.radius"] == radius
    assert config["path.photongi.indirect.enabled"] is False
    assert config["renderengine.seed"] == 6 and config["batch.haltspp"] == 16


def test_glass_cube_faces_outward(tmp_path: Path) -> None:
    scene = load_scene(glass_and_mirror(tmp_path))
    glass = scene.material == scene.materials.names.index("glass")
    centres = scene.triangles[glass].mean(axis=1)
    outward = np.einsum("ij,ij->i", scene.normals[glass], centres - centres.mean(axis=0))
    assert len(centres) == 12 and np.all(outward > 0)
