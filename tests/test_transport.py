"""Light transport against physics: analytic radiance, the furnace, photon energy, the split.

Every check here has an answer known without our renderer: a form factor, Le/(1−ρ), the power
of the lights, or our own path tracer through a different light-path split.
"""

from __future__ import annotations

import math
from dataclasses import replace
from pathlib import Path

import numba
import numpy as np
import pytest
import trimesh
from analytic import fresnel
from scipy.spatial import cKDTree

from conftest import FLOOR_AND_LIGHT_MTL, WATER, WATER_LE, water_between_lights, write_scene
from dpm import load_scene
from dpm.renderer import RenderOptions, render
from dpm.tracer import build_bvh, shade, trace_photons, trace_visible_points
from dpm.tracer.photon_grid import photon_grid
from dpm.validation.noise import block_z

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
RHO, LE, SIDE, HEIGHT = 0.5, 10.0, 0.2, 1.0


def corner_form_factor(a: float, b: float, h: float) -> float:
    """Form factor from a point to the rectangle [0,a]×[0,b] on a parallel plane at height h."""
    x, y = a / h, b / h
    sx, sy = math.sqrt(1 + x * x), math.sqrt(1 + y * y)
    return (x / sx * math.atan(y / sx) + y / sy * math.atan(x / sy)) / (2 * math.pi)


def rectangle_form_factor(px: float, pz: float, half: float, h: float) -> float:
    """Form factor from point (px, pz) to the square [-half, half]² on a parallel plane at h."""
    total = 0.0
    for x in (half - px, -half - px):
        for z in (half - pz, -half - pz):
            # Signed corner rectangles add up to the offset rectangle (superposition).
            sign = (1 if x == half - px else -1) * (1 if z == half - pz else -1)
            total += (
                sign
                * math.copysign(1, x)
                * math.copysign(1, z)
                * corner_form_factor(abs(x), abs(z), h)
            )
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
    image = render(scene, RenderOptions(method="pt", spp=256, progress=False)).image
    # Lambertian: L = ρ/π · E and E = π · LE · F, so L = ρ · LE · F. Light the floor reflects
    # reaches only the black back of the light, so there is no indirect term.
    expected = RHO * LE * rectangle_form_factor(target[0], target[2], SIDE / 2, HEIGHT)
    assert image.mean() == pytest.approx(expected, rel=0.01)
    assert np.allclose(image[..., 0], image[..., 1]) and np.allclose(image[..., 0], image[..., 2])


def furnace(folder: Path, albedo: float, radiance: float) -> Path:
    """A closed sphere (faces towards the centre) that emits `radiance` and reflects `albedo`."""
    sphere = trimesh.creation.icosphere(subdivisions=2, radius=1.0)
    lines = ["mtllib scene.mtl", "usemtl wall"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in sphere.vertices]
    lines += [f"f {a + 1} {c + 1} {b + 1}" for a, b, c in sphere.faces]  # reversed: inwards
    mtl = f"newmtl wall\nKd {albedo} {albedo} {albedo}\nKe {radiance} {radiance} {radiance}\n"
    toml = "[camera]\norigin = [0, 0.1, 0]\ntarget = [0.3, 0, 1]\nfov = 90\nwidth = 16\nheight = 12"
    return write_scene(folder, "\n".join(lines) + "\n", mtl, toml)


@pytest.mark.parametrize("albedo", [0.0, 0.5, 0.9])
def test_furnace_radiance_is_le_over_one_minus_albedo(tmp_path: Path, albedo: float) -> None:
    scene = load_scene(furnace(tmp_path, albedo, radiance=0.75))
    result = render(scene, RenderOptions(method="pt", spp=256, progress=False))
    expected = 0.75 / (1 - albedo)
    assert result.image.mean() == pytest.approx(expected, rel=0.01)
    # Every pixel, not only the mean; longer paths (higher albedo) are noisier.
    assert np.all(np.abs(result.image / expected - 1) < 0.1 / math.sqrt(1 - albedo))
    assert result.stats["nonfinite_samples"] == 0


def test_first_hit_photons_carry_the_power_that_reaches_the_floor(scene_path: Path) -> None:
    # conftest's scene: a 0.2² light (Ke 10) facing down at height 1 over the floor [-1, 1]².
    scene = load_scene(scene_path)
    n = 200_000
    photons = trace_photons(scene, build_bvh(scene), n, seed=5)
    power = scene.emitters.total_power[0]
    assert power == pytest.approx(math.pi * 0.04 * 10.0)
    # Fraction of the light's power that reaches the floor: the light→floor form factor, the
    # point→floor form factor averaged over the light (Gauss–Legendre, 16² points).
    nodes, weights = np.polynomial.legendre.leggauss(16)
    xs, ws = 0.1 * nodes, 0.5 * weights
    fraction = sum(
        wx * wz * rectangle_form_factor(x, z, 1.0, 1.0)
        for x, wx in zip(xs, ws, strict=True)
        for z, wz in zip(xs, ws, strict=True)
    )
    direct = photons.flux[photons.bounces == 0].sum(axis=0, dtype=np.float64)
    sigma = power * math.sqrt(fraction * (1 - fraction) / n)  # binomial: hit or escape
    assert abs(direct[0] - power * fraction) < 4 * sigma
    assert np.allclose(direct, direct[0])
    assert photons.n_paths == n and not photons.caustic.any()  # nothing specular here
    np.testing.assert_allclose(np.linalg.norm(photons.direction, axis=1), 1, atol=1e-5)


def closed_box(folder: Path, inner: str, light: float = 0.2, toml: str | None = None) -> Path:
    """A closed box [-1, 1]³ (walls face inwards), a ceiling light of half-width `light` and
    the `inner` OBJ lines (vertex numbers start at 13; materials: wall, light, glass, mirror).
    """
    box = trimesh.creation.box(extents=(2, 2, 2))
    lines = ["mtllib scene.mtl", "usemtl wall"]
    lines += [f"v {x:.9g} {y:.9g} {z:.9g}" for x, y, z in box.vertices]
    lines += [f"f {a + 1} {c + 1} {b + 1}" for a, b, c in box.faces]
    lines += [f"v {x * light} 0.99 {z * light}" for x, z in ((-1, -1), (1, -1), (1, 1), (-1, 1))]
    lines += ["usemtl light", "f 9 10 11 12", inner]
    mtl = FLOOR_AND_LIGHT_MTL.replace("floor", "wall")
    mtl += "newmtl glass\nillum 7\nNi 1.5\nnewmtl mirror\nillum 3\nKs 0.9 0.9 0.9\n"
    return write_scene(folder, "\n".join(lines) + "\n", mtl, toml)


def test_in_a_closed_box_first_hits_carry_all_the_power(tmp_path: Path) -> None:
    scene = load_scene(closed_box(tmp_path, ""))
    photons = trace_photons(scene, build_bvh(scene), 50_000, seed=1)
    direct = photons.flux[photons.bounces == 0].sum(axis=0, dtype=np.float64)
    np.testing.assert_allclose(direct, scene.emitters.total_power, rtol=1e-5)
    # Every path deposits its first photon; later ones fade by albedo 0.5 per bounce.
    assert np.count_nonzero(photons.bounces == 0) == 50_000
    total = photons.flux.sum(axis=0, dtype=np.float64) / scene.emitters.total_power
    assert total[0] == pytest.approx(1 / (1 - 0.5), rel=0.03)  # Σ ρ^k with Russian roulette


GLASS_SLAB = """
v -0.5 -0.3 -0.5
v 0.5 -0.3 -0.5
v 0.5 -0.3 0.5
v -0.5 -0.3 0.5
v -0.5 -0.1 -0.5
v 0.5 -0.1 -0.5
v 0.5 -0.1 0.5
v -0.5 -0.1 0.5
usemtl glass
f 13 14 15 16
f 17 20 19 18
f 13 17 18 14
f 14 18 19 15
f 15 19 20 16
f 16 20 17 13
v 0.95 -1 -0.6
v 0.95 -1 0.6
v 0.95 0.2 0.6
v 0.95 0.2 -0.6
usemtl mirror
f 21 22 23 24"""


def test_photon_map_flags_caustics_and_does_not_depend_on_threads(tmp_path: Path) -> None:
    scene = load_scene(closed_box(tmp_path, GLASS_SLAB))
    bvh = build_bvh(scene)
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        one = trace_photons(scene, bvh, 70_000, seed=3)  # more than one chunk of paths
    finally:
        numba.set_num_threads(before)
    two = trace_photons(scene, bvh, 70_000, seed=3)
    for name in ("position", "direction", "flux", "normal", "caustic", "bounces", "path"):
        np.testing.assert_array_equal(getattr(one, name), getattr(two, name))
    caustic = one.caustic
    assert 0 < caustic.sum() < len(one)
    assert np.all(one.bounces[caustic] >= 1)  # L S+ D: at least one specular bounce
    assert not np.any(caustic[one.bounces == 0])
    # On the floor under the slab, caustic photons came through both of its faces.
    under = (one.position[:, 1] < -0.99) & np.all(np.abs(one.position[:, [0, 2]]) < 0.3, axis=1)
    assert np.count_nonzero(caustic & under & (one.bounces == 2)) > 1000
    only = trace_photons(scene, bvh, 70_000, seed=3, caustic_only=True)
    np.testing.assert_array_equal(only.position, one.position[caustic])
    np.testing.assert_array_equal(only.flux, one.flux[caustic])
    assert not np.array_equal(trace_photons(scene, bvh, 1000, seed=4).position, one.position[:1])


def test_visible_points_do_not_depend_on_threads_or_row_blocks() -> None:
    scene = load_scene(EXAMPLES / "glass_egg.obj")
    bvh = build_bvh(scene)
    camera = scene.camera.with_resolution(24, 20)
    whole = trace_visible_points(scene, bvh, camera, 3, seed=2, rows=(0, 20))
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        parts = [trace_visible_points(scene, bvh, camera, 3, 2, rows) for rows in ((0, 7), (7, 20))]
    finally:
        numba.set_num_threads(before)
    for name in ("position", "normal", "albedo", "throughput", "emitted", "hit", "sample"):
        joined = np.concatenate([getattr(p, name) for p in parts])
        np.testing.assert_array_equal(getattr(whole, name), joined)
    np.testing.assert_array_equal(whole.pixel, np.repeat(np.arange(24 * 20), 3))
    assert whole.hit.mean() > 0.9
    # Seen through the glass, (η₁/η₂)² cancels on the way out: throughput stays at most 1.
    assert whole.throughput.max() <= 1.0 + 1e-6


def caustic_radiance(scene, points, photons, radius: float) -> np.ndarray:
    """Uniform-kernel density estimate (N, 3) of caustic radiance at visible points.

    Brute force for the test: L = ρ/π · Σ Φ_p / (π r²) over caustic photons within r whose
    normal agrees with the point's.
    """
    out = np.zeros((len(points), 3))
    caustic = photons.select(photons.caustic)
    tree = cKDTree(caustic.position)
    hits = np.flatnonzero(points.hit)
    for i, near in zip(hits, tree.query_ball_point(points.position[hits], radius), strict=True):
        if near:
            near = np.asarray(near)
            same_side = caustic.normal[near] @ points.normal[i] > 0.9
            out[i] = caustic.flux[near[same_side]].sum(axis=0)
    return out * points.albedo / math.pi / (math.pi * radius**2)


def test_pt_nocaustic_plus_photon_caustics_matches_pt(tmp_path: Path) -> None:
    # Glass and a mirror under a large light, so that pt itself resolves the caustics.
    camera = "[camera]\norigin = [0, 0.9, 0.9]\ntarget = [0.1, -1, -0.1]\nfov = 80\n"
    scene = load_scene(closed_box(tmp_path, GLASS_SLAB, light=0.5, toml=camera))
    bvh = build_bvh(scene)
    camera = scene.camera.with_resolution(32, 32)
    spp = 64
    full, split, gridded = [], [], []
    for seed in (1, 2):
        points = trace_visible_points(scene, bvh, camera, spp, seed, (0, 32))
        photons = trace_photons(scene, bvh, 1_000_000, seed=seed, caustic_only=True)
        rest, _ = shade(scene, bvh, points, seed, caustics=False)
        caustic = caustic_radiance(scene, points, photons, radius=0.01)
        both, _ = shade(scene, bvh, points, seed + 10, caustics=True)
        # the photons also at the later diffuse vertices (auto's passes): the same light
        later, _ = shade(scene, bvh, points, seed, False, photon_grid(photons, 0.02))
        dark = replace(photons, flux=np.zeros_like(photons.flux))
        without, _ = shade(scene, bvh, points, seed, False, photon_grid(dark, 0.02))
        assert np.mean(rest - without) > 0.05 * np.mean(rest)  # those paths matter here
        for out, reflected in ((full, both), (split, rest + caustic), (gridded, later + caustic)):
            radiance = points.emitted + points.throughput * reflected
            out.append(radiance.reshape(32, 32, spp, 3).mean(axis=2))
        assert np.mean(points.throughput * caustic) > 0.1 * np.mean(split[-1])  # caustics matter
    for estimate in (split, gridded):
        z = block_z(full, estimate)
        assert np.abs(z).max() < 4, np.round(z[..., 0], 1)
        assert np.mean(estimate) == pytest.approx(np.mean(full), rel=0.01)


@pytest.mark.parametrize("name", sorted(p.stem for p in EXAMPLES.glob("*.obj")))
@pytest.mark.parametrize("method", ["pt", "pt-nocaustic"])
def test_every_example_renders_finite(name: str, method: str) -> None:
    scene = load_scene(EXAMPLES / f"{name}.obj")
    result = render(scene, RenderOptions(method=method, spp=2, width=24, height=16, progress=False))
    assert np.all(np.isfinite(result.image)) and result.image.min() >= 0
    assert result.stats["nonfinite_samples"] == 0 and result.image.max() > 0


MIRROR_TRAP = """
v -0.3 0.5 -0.3
v 0.3 0.5 -0.3
v 0.3 0.5 0.3
v -0.3 0.5 0.3
v -0.3 -1 -0.3
v 0.3 -1 -0.3
v 0.3 -1 0.3
v -0.3 -1 0.3
usemtl mirror
f 13 14 15 16
f 13 17 18 14
f 14 18 19 15
f 15 19 20 16
f 16 20 17 13
usemtl glass
f 17 20 19 18"""


def test_hard_light_paths_stay_finite(tmp_path: Path) -> None:
    # A mirror column with a glass bottom standing on the floor under a small light: specular
    # chains, total internal reflection and grazing hits along the column's edges.
    camera = "[camera]\norigin = [0.7, 0.9, 0.8]\ntarget = [0, -1, 0]\nfov = 100\nwidth = 24\n"
    scene = load_scene(closed_box(tmp_path, MIRROR_TRAP, light=0.1, toml=camera + "height = 16"))
    photons = trace_photons(scene, build_bvh(scene), 20_000, seed=0)
    assert np.all(np.isfinite(photons.flux)) and np.all(photons.flux >= 0)
    assert photons.caustic.any()
    for method in ("pt", "pt-nocaustic"):
        result = render(scene, RenderOptions(method=method, spp=16, progress=False))
        assert np.all(np.isfinite(result.image)) and result.image.max() > 0
        assert result.stats["nonfinite_samples"] == 0


def test_light_seen_in_water_counts_with_its_fresnel_weight_on_every_path(tmp_path: Path) -> None:
    # Seen at 63.4° from the normal, the water reflects F ≈ 7.6 % of the red light above and
    # passes the rest of the green one below (radiance ÷ η² on the way out). Each camera path
    # chooses one Fresnel branch, but both branches' light counts, weighted, on every path
    # (emission splitting): the image is exact at 4 spp, where choosing alone would put one
    # path in thirteen on the red light and leave the red channel's mean ±6 % off.
    scene = load_scene(water_between_lights(tmp_path))
    images = [
        render(scene, RenderOptions(method="pt", spp=4, seed=s, progress=False)).image
        for s in (1, 2)
    ]
    f = fresnel(np.array(1 / math.sqrt(5)), WATER)  # the centre pixel's angle
    for image in images:
        assert image[..., 0].mean() == pytest.approx(f * WATER_LE, rel=0.02)
        assert image[..., 1].mean() == pytest.approx((1 - f) * WATER_LE / WATER**2, rel=0.002)
        assert not image[..., 2].any()
    # Per pixel, two seeds differ only by where the samples fall inside the pixel.
    assert np.allclose(images[0], images[1], rtol=0.01)


def light_pipe(folder: Path, length: float, thickness: float) -> Path:
    """A clear glass bar (ior 1.5) along x from 0 to `length`, `thickness` tall, with a light
    facing its far end and a camera that looks into its near end at 60° from its axis."""
    bar = trimesh.creation.box(extents=(length, thickness, 4.0))
    bar.apply_translation((length / 2, thickness / 2, 0.0))
    x = length + 0.05
    lines = ["mtllib scene.mtl", *(f"v {a} {b} {c}" for a, b, c in bar.vertices)]
    lines += [f"v {x} -1 -1", f"v {x} -1 1", f"v {x} 1 1", f"v {x} 1 -1"]  # faces -x
    lines += ["usemtl glass", *(f"f {a + 1} {b + 1} {c + 1}" for a, b, c in bar.faces)]
    lines += ["usemtl light", "f 9 10 11 12"]
    mtl = f"newmtl glass\nillum 7\nNi 1.5\nTf 1 1 1\nnewmtl light\nKe {LE} {LE} {LE}\n"
    eye = (-math.cos(math.pi / 3), thickness / 2 + math.sin(math.pi / 3), 0.0)
    camera = (
        f"[camera]\norigin = {list(eye)}\ntarget = [0, {thickness / 2}, 0]\nup = [0, 0, 1]\n"
        "fov = 0.05\nwidth = 8\nheight = 8\n"
    )
    return write_scene(folder, "\n".join(lines) + "\n", mtl, camera)


def test_light_seen_after_hundreds_of_internal_reflections_counts(tmp_path: Path) -> None:
    # Entering at 60° the camera's rays travel 35.3° off the bar's axis and meet its long faces
    # at 54.7°, past the critical 41.8°: total internal reflection every 1.41 thicknesses, so
    # about 495 lossless bounces before they leave through the far end (at 35.3°) and see the
    # light. Each bounce keeps the weight at 1 (roulette spares them), so a chain cap below
    # ~500 vertices would leave the bar black; the light arrives times (1 - F) at both ends.
    scene = load_scene(light_pipe(tmp_path, length=7.0, thickness=0.01))
    image = render(scene, RenderOptions(method="pt", spp=64, seed=1, progress=False)).image
    f = float(fresnel(np.array(math.cos(math.pi / 3)), 1.5))
    assert image.mean() == pytest.approx(LE * (1 - f) ** 2, rel=0.03)
