"""The unseen-scene set: scenes that no constant of dpm is ever tuned on.

Every constant of the project was tuned on the seven example scenes (`examples/make_scenes.py`:
about 2 units across, 256 px square or 320x240, lights 0.08-0.22 units wide, cameras 2-3
units away). This set varies what they do not: the scale of the whole scene (0.01, 1 and 100
units: the same scene with every length multiplied and the lights' radiance kept, so the
images match), resolution and aspect (64x64 to 512x512, portrait and landscape), light size
(side 0.01 to 1.0 scene units, x10^4 in area), a light seen only through glass, mirrors (a
cup whose cardioid a light on its rim makes, a parabolic dish, chrome balls), clear, tinted,
water and displaced glass, geometry far out of view (a floor 1000 units wide, a wall 500 units
behind the camera) and the camera near (a close-up of a caustic) or far (80 units off, 1.6
degree field of view). Two controls have no mirror or glass at all.

Deterministic: the few random things (waves, bumps) draw from `numpy.random.default_rng` with
seeds >= 100000, disjoint from the training scenes of `dpm.data.procedural` (seeds 0, 1, ...)
so no training scene can repeat one. y is up and the floor is y = 0 (before scaling); specular
objects float LIFT above it; closed dielectrics are watertight with outward winding; one
square area light per scene. Each scene is read back after writing and checked.

Usage: python benchmarks/scenes/make_unseen.py [--out benchmarks/scenes/unseen]
From code: `unseen_scenes()` writes whatever is missing or stale and returns the OBJ paths.
"""

from __future__ import annotations

import argparse
import math
import sys
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

from dpm.data.builder import (
    LIFT,
    UP,
    Mesh,
    Scene,
    Vec,
    add_light,
    box,
    camera,
    dielectric,
    diffuse,
    floor_rect,
    heightfield,
    lathe,
    light_ke,
    merge,
    mirror,
    orient_outward,
    quad,
    render,
    rest_on_floor,
    spherical,
    transform,
    translate,
    write_scene,
)  # fmt: skip

SCENES_DIR = Path(__file__).parent / "unseen"
VERSION = 1  # bump when a scene changes: files written by another version are rewritten
SEED = 100_000  # first seed of this set; the training scenes (dpm.data.procedural) use 0, 1, ...
FLOOR_KD = (0.7, 0.7, 0.7)


# ---------------------------------------------------------------------------------------------
# Helpers


def add_room(
    scene: Scene, half: float = 3.0, wall_z: float | None = -1.5, height: float = 2.0
) -> None:
    """Diffuse floor square of half-size `half` and a back wall at z = wall_z (None: none)."""
    scene.materials.setdefault("floor", diffuse(FLOOR_KD))
    back = -half if wall_z is None else wall_z
    scene.add("floor", "floor", floor_rect(-half, half, back, half))
    if wall_z is not None:
        h = half
        scene.add("back_wall", "floor", quad((-h, 0, wall_z), (h, 0, wall_z), (h, height, wall_z),
                                             (-h, height, wall_z)))  # fmt: skip


def sphere(radius: float, center: Vec, subdivisions: int = 4) -> Mesh:
    """Closed icosphere with outward winding."""
    mesh = trimesh.creation.icosphere(subdivisions=subdivisions, radius=radius)
    return orient_outward((np.asarray(mesh.vertices) + center, np.asarray(mesh.faces)))


def cylinder(radius: float, height: float, center: Vec, sections: int = 64) -> Mesh:
    """Closed vertical cylinder with outward winding."""
    mesh = trimesh.creation.cylinder(radius=radius, height=height, sections=sections)
    return orient_outward((np.asarray(mesh.vertices) + center, np.asarray(mesh.faces)))


def on_floor(mesh: Mesh, x: float, z: float) -> Mesh:
    """Move a mesh to stand LIFT above the floor, centred on (x, z)."""
    v = mesh[0]
    centre = 0.5 * (v.min(axis=0) + v.max(axis=0))
    return rest_on_floor(translate(mesh, (x - centre[0], 0.0, z - centre[2])))


def plane_waves(
    points: np.ndarray, seed: int, waves: int, wavelength: tuple[float, float]
) -> np.ndarray:
    """(N,) sum of `waves` random plane waves at points (N, 3), scaled to [-1, 1]."""
    rng = np.random.default_rng(seed)
    height = np.zeros(len(points))
    for i in range(waves):
        k = rng.normal(size=3)
        k *= 2.0 * math.pi / (rng.uniform(*wavelength) * np.linalg.norm(k))
        height += 0.6**i * np.sin(points @ k + rng.uniform(0.0, 2.0 * math.pi))
    return height / np.abs(height).max()


def scaled(scene: Scene, factor: float) -> Scene:
    """The same scene with every length (geometry and camera position) times `factor`."""
    for part in scene.parts:
        part.vertices = part.vertices * factor
    for key in ("origin", "target"):
        scene.camera[key] = [float(f"{x * factor:.4g}") for x in scene.camera[key]]
    return scene


# ---------------------------------------------------------------------------------------------
# Scenes (built at unit scale: about 2 units across)


def spheres() -> Scene:
    """Three clear glass spheres (IOR 1.33, 1.5, 1.9) on a floor before a wall."""
    scene = Scene("spheres", camera((0.35, 1.2, 2.3), (0.0, 0.2, 0.0), 40, 128, 128), render())
    for i, (ior, radius, x, z) in enumerate(
        [(1.33, 0.18, -0.5, 0.15), (1.5, 0.25, 0.0, -0.2), (1.9, 0.15, 0.45, 0.2)]
    ):
        scene.materials[f"glass{i}"] = dielectric(ior)
        scene.add(f"sphere{i}", f"glass{i}", on_floor(sphere(radius, (0, 0, 0)), x, z), True)
    add_room(scene)
    light = spherical(215, 55, 2.2, (0.0, 0.2, 0.0))
    add_light(scene, light, (0, 0, 0), 0.12, light_ke(light, 0.12, (0, 0, 0)))
    return scene


def lens_wall() -> Scene:
    """Biconvex glass lens standing between a light and a wall, focusing it onto the wall."""
    scene = Scene("lens_wall", camera((-0.4, 1.0, 2.1), (0.35, 0.45, 0.0), 50, 256, 128), render())
    scene.materials["glass"] = dielectric(1.5)
    aperture, curvature, rim = 0.3, 0.6, 0.01  # radius, surface radius, half rim thickness
    r = np.linspace(0.0, aperture, 25)
    sag = curvature - np.sqrt(curvature**2 - r**2)
    depth = sag[-1] + rim
    bottom = np.stack([r, sag - depth], 1)
    top = np.stack([r, depth - sag], 1)[::-1]
    lens = lathe(np.vstack([bottom, top]), 96)
    turn = trimesh.transformations.rotation_matrix(-math.pi / 2, [0, 0, 1])  # axis along +x
    centre = (0.0, 0.5, 0.0)
    scene.add("lens", "glass", orient_outward(translate(transform(lens, turn), centre)), True)
    # Thin-lens focal length R / (2 (n - 1)) = 0.6; the light 2.0 before it images 0.86 after.
    wall_x = 0.86
    scene.materials["floor"] = diffuse(FLOOR_KD)
    scene.add("floor", "floor", floor_rect(-3.0, wall_x, -1.5, 1.5))
    scene.add("back_wall", "floor", quad((wall_x, 0, 1.5), (wall_x, 0, -1.5), (wall_x, 2, -1.5),
                                         (wall_x, 2, 1.5)))  # fmt: skip
    light = (-2.0, 0.5, 0.0)
    spot = (wall_x, 0.5, 0.3)  # beside the focus: the wall's directly lit level
    ke = light_ke(light, 0.15, spot, 0.35, normal=(-1.0, 0.0, 0.0))
    add_light(scene, light, centre, 0.15, ke)
    return scene


def glass_lantern() -> Scene:
    """Light inside a closed hollow glass box: everything it lights is caustic, and the camera
    sees it only through glass."""
    scene = Scene("glass_lantern", camera((0.9, 0.75, 2.6), (0.0, 0.55, 0.0), 45, 128, 128),
                  render())  # fmt: skip
    scene.materials["glass"] = dielectric(1.5)
    centre, outer, wall = (0.0, 1.1, 0.0), (0.5, 0.36, 0.5), 0.03
    inner = tuple(e - 2 * wall for e in outer)
    cavity = box(inner, centre)
    shell = merge(box(outer, centre), (cavity[0], cavity[1][:, ::-1]))  # the cavity faces in
    scene.add("lantern", "glass", orient_outward(shell), True)
    scene.materials["red"] = diffuse((0.7, 0.2, 0.15))
    scene.materials["blue"] = diffuse((0.2, 0.3, 0.7))
    scene.add("block", "red", box((0.3, 0.3, 0.3), (0.45, 0.15, 0.25), 30))
    scene.add("post", "blue", cylinder(0.1, 0.5, (-0.5, 0.25, -0.2)))
    add_room(scene, wall_z=-1.5, height=2.5)
    light = (0.0, centre[1] + inner[1] / 2 - 0.01, 0.0)
    add_light(scene, light, (0, 0, 0), 0.3, light_ke(light, 0.3, (0, 0, 0), radiance=0.8))
    return scene


def cardioid_cup() -> Scene:
    """Mirror cup (a ring) with a tiny light just inside its wall: the cardioid on the floor."""
    scene = Scene("cardioid_cup", camera((0.0, 1.9, 0.5), (0.0, 0.0, 0.0), 40, 128, 128),
                  render())  # fmt: skip
    scene.materials["silver"] = mirror((0.95, 0.95, 0.95))
    r_in, r_out, height = 0.5, 0.52, 0.22
    profile = [(r_in, 0.0), (r_out, 0.0), (r_out, height), (r_in, height)]
    scene.add("cup", "silver", translate(lathe(profile, 720, loop=True), (0, LIFT, 0)), True)
    add_room(scene, wall_z=None)
    light, size = (-0.47, 0.08, 0.0), 0.01
    add_light(scene, light, (0.3, 0.0, 0.0), size, light_ke(light, size, (0, 0, 0), radiance=0.4))
    return scene


def tinted_glass() -> Scene:
    """Amber glass cube, blue glass sphere and green glass cylinder: coloured caustics."""
    scene = Scene("tinted_glass", camera((0.5, 1.1, 2.0), (0.0, 0.15, 0.0), 42, 96, 96), render())
    scene.materials["amber"] = dielectric(1.5, (1.0, 0.55, 0.15))
    scene.materials["blue"] = dielectric(1.5, (0.25, 0.5, 1.0))
    scene.materials["green"] = dielectric(1.45, (0.35, 0.9, 0.4))
    scene.add("cube", "amber", on_floor(box((0.3, 0.3, 0.3), (0, 0, 0), 25), -0.35, 0.0), True)
    scene.add("ball", "blue", on_floor(sphere(0.2, (0, 0, 0)), 0.3, -0.15), True)
    scene.add("can", "green", on_floor(cylinder(0.12, 0.45, (0, 0, 0)), 0.05, 0.4), True)
    add_room(scene)
    light = spherical(250, 55, 2.2, (0.0, 0.2, 0.0))
    add_light(scene, light, (0, 0, 0), 0.12, light_ke(light, 0.12, (0, 0, 0)))
    return scene


def water_tiles() -> Scene:
    """Water sheet over a tiled floor under a big light (1 x 1): soft water caustics."""
    scene = Scene("water_tiles", camera((0.0, 1.8, 1.9), (0.0, 0.0, -0.25), 50, 384, 256),
                  render())  # fmt: skip
    scene.materials["tile_light"] = diffuse((0.75, 0.78, 0.8))
    scene.materials["tile_dark"] = diffuse((0.2, 0.42, 0.6))
    scene.materials["water"] = dielectric(1.33)
    half, tile = 2.5, 0.25
    n = round(2 * half / tile)
    tiles: dict[str, list[Mesh]] = {"tile_light": [], "tile_dark": []}
    for i in range(n):
        for j in range(n):
            x0, z0 = -half + i * tile, -half + j * tile
            tiles["tile_light" if (i + j) % 2 == 0 else "tile_dark"].append(
                floor_rect(x0, x0 + tile, z0, z0 + tile)
            )
    for key, meshes in tiles.items():
        scene.add(key, key, merge(*meshes))
    rng = np.random.default_rng(SEED + 8)
    waves = [(float(rng.uniform(0.006, 0.012)), float(rng.uniform(0.25, 0.6)),
              float(rng.uniform(0, math.pi)), float(rng.uniform(0, 2 * math.pi)))
             for _ in range(5)]  # fmt: skip

    def water(x: np.ndarray, z: np.ndarray) -> np.ndarray:
        y = np.full_like(x, 0.2)
        for amplitude, wavelength, angle, phase in waves:
            k = 2.0 * math.pi / wavelength
            y += amplitude * np.sin(k * (x * math.cos(angle) + z * math.sin(angle)) + phase)
        return y

    scene.add("water", "water", heightfield(water, (-half, half), (-half, half), (110, 110)))
    light, size = (0.4, 3.0, -0.6), 1.0
    add_light(scene, light, (0, 0, 0), size, light_ke(light, size, (0, 0, 0), radiance=0.6))
    return scene


def bumpy_blob() -> Scene:
    """Displaced glass blob: an icosphere with multi-octave bumps (20k triangles), 512x512."""
    scene = Scene("bumpy_blob", camera((0.9, 1.3, 2.1), (0.1, 0.25, 0.0), 40, 512, 512), render())
    scene.materials["glass"] = dielectric(1.5)
    mesh = trimesh.creation.icosphere(subdivisions=5, radius=0.35)
    v = np.asarray(mesh.vertices)
    bumps = plane_waves(v, SEED + 9, 8, (0.25, 0.9))
    blob = orient_outward((v * (1.0 + 0.12 * bumps)[:, None], np.asarray(mesh.faces)))
    scene.add("blob", "glass", on_floor(blob, 0.0, 0.0), True)
    add_room(scene, wall_z=-2.0)
    light = spherical(215, 50, 2.3, (0.0, 0.35, 0.0))
    add_light(scene, light, (0, 0, 0), 0.1, light_ke(light, 0.1, (0, 0, 0)))
    return scene


def huge_floor() -> Scene:
    """Glass sphere and cylinder on a floor 1000 units wide reaching the horizon."""
    scene = Scene("huge_floor", camera((0.3, 0.6, 2.4), (0.0, 0.2, 0.0), 50, 128, 96), render())
    scene.materials["glass"] = dielectric(1.5)
    scene.add("ball", "glass", on_floor(sphere(0.2, (0, 0, 0)), -0.3, 0.0), True)
    scene.add("can", "glass", on_floor(cylinder(0.15, 0.5, (0, 0, 0)), 0.3, -0.2), True)
    add_room(scene, half=500.0, wall_z=None)
    light = spherical(190, 45, 2.5, (0.0, 0.2, 0.0))
    add_light(scene, light, (0, 0, 0), 0.12, light_ke(light, 0.12, (0, 0, 0)))
    return scene


def far_wall() -> Scene:
    """Glass torus and mirror box; a wall 1000 wide stands 500 units behind the camera."""
    scene = Scene("far_wall", camera((0.0, 1.2, 2.8), (0.0, 0.2, 0.0), 40, 128, 128), render())
    scene.materials["glass"] = dielectric(1.5)
    scene.materials["chrome"] = mirror((0.9, 0.9, 0.9))
    t = np.linspace(0.0, 2.0 * math.pi, 40, endpoint=False)
    torus = lathe(np.stack([0.35 + 0.12 * np.cos(t), 0.12 * np.sin(t)], 1), 128, loop=True)
    scene.add("torus", "glass", on_floor(torus, -0.2, 0.1), True)
    scene.add("box", "chrome", on_floor(box((0.25, 0.4, 0.25), (0, 0, 0), 35), 0.55, -0.3), True)
    add_room(scene, wall_z=-2.0)
    z, w = 2.8 + 500.0, 500.0
    scene.add("far_wall", "floor", quad((w, 0, z), (-w, 0, z), (-w, w, z), (w, w, z)))
    light = spherical(200, 55, 2.2, (0.0, 0.2, 0.0))
    add_light(scene, light, (0, 0, 0), 0.12, light_ke(light, 0.12, (0, 0, 0)))
    return scene


def closeup_caustic() -> Scene:
    """Camera 0.4 units from the focused caustic of a glass sphere, 64x64."""
    scene = Scene("closeup_caustic", camera((0.3, 0.28, 0.25), (0.08, 0.0, 0.0), 60, 64, 64),
                  render())  # fmt: skip
    scene.materials["glass"] = dielectric(1.5)
    scene.add("ball", "glass", on_floor(sphere(0.2, (0, 0, 0)), 0.0, 0.0), True)
    add_room(scene, wall_z=None)
    light = spherical(180, 62, 2.0, (0.0, 0.2, 0.0))
    add_light(scene, light, (0, 0, 0), 0.08, light_ke(light, 0.08, (0, 0, 0)))
    return scene


def far_camera() -> Scene:
    """Glass torus and mirror ball seen from 80 units away through a 1.6 degree lens, 64x64."""
    target = (0.0, 0.12, 0.0)
    origin = spherical(70, 30, 80.0, target)
    scene = Scene("far_camera", camera(origin, target, 1.6, 64, 64), render())
    scene.materials["glass"] = dielectric(1.5)
    scene.materials["chrome"] = mirror((0.9, 0.9, 0.9))
    t = np.linspace(0.0, 2.0 * math.pi, 40, endpoint=False)
    torus = lathe(np.stack([0.35 + 0.12 * np.cos(t), 0.12 * np.sin(t)], 1), 128, loop=True)
    scene.add("torus", "glass", on_floor(torus, 0.0, -0.1), True)
    scene.add("ball", "chrome", on_floor(sphere(0.15, (0, 0, 0)), 0.45, 0.45), True)
    add_room(scene, wall_z=-1.5)
    light = spherical(210, 50, 2.2, (0.0, 0.1, 0.0))
    add_light(scene, light, (0, 0, 0), 0.1, light_ke(light, 0.1, (0, 0, 0)))
    return scene


def concave_mirror() -> Scene:
    """Parabolic mirror dish focusing an off-axis light onto the floor, and two chrome balls."""
    scene = Scene("concave_mirror", camera((1.4, 1.2, 1.8), (-0.1, 0.3, -0.4), 45, 128, 128),
                  render())  # fmt: skip
    scene.materials["silver"] = mirror((0.95, 0.95, 0.95))
    focal, aperture = 0.6, 0.35
    r = np.linspace(0.0, aperture, 30)
    dish = lathe(np.stack([r, r * r / (4.0 * focal)], 1), 96)  # open, opening towards +y
    axis_deg, off_deg, distance = -10.0, 25.0, 2.5  # axis elevation, light's angle off it
    a = math.radians(axis_deg)
    matrix = trimesh.geometry.align_vectors(UP, [0.0, math.sin(a), math.cos(a)])
    vertex = (0.0, 0.45, -0.8)
    scene.add("dish", "silver", translate(transform(dish, matrix), vertex))
    for i, (x, z) in enumerate([(0.55, 0.25), (-0.5, 0.1)]):
        scene.add(f"ball{i}", "silver", on_floor(sphere(0.12, (0, 0, 0)), x, z), True)
    add_room(scene, wall_z=-1.5)
    b = math.radians(axis_deg + off_deg)
    light = tuple(np.add(vertex, distance * np.array([0.0, math.sin(b), math.cos(b)])))
    add_light(scene, light, vertex, 0.06, light_ke(light, 0.06, (0, 0, 0.5), radiance=0.5))
    return scene


def vase_profile() -> np.ndarray:
    """(r, y) profile of a thick-walled vase: outside up, over a round lip, inside down."""
    y = np.linspace(0.0, 0.7, 40)
    outer = 0.07 + 0.08 * np.exp(-(((y - 0.2) / 0.15) ** 2)) + 0.03 * y
    wall, floor = 0.012, 0.03
    inner_y = y[y > floor + 0.01]
    inner = 0.07 + 0.08 * np.exp(-(((inner_y - 0.2) / 0.15) ** 2)) + 0.03 * inner_y - wall
    t = np.linspace(0.0, math.pi, 9)[1:-1]
    lip_mid = outer[-1] - wall / 2
    lip = np.stack([lip_mid + wall / 2 * np.cos(t), 0.7 + wall / 2 * np.sin(t)], 1)
    return np.vstack([
        [(0.0, 0.0)], np.stack([outer, y], 1), lip, np.stack([inner, inner_y], 1)[::-1],
        [(inner[0], floor), (0.0, floor)],
    ])  # fmt: skip


def tall_vase() -> Scene:
    """Thick green glass vase and a clear marble, portrait 96x160."""
    scene = Scene("tall_vase", camera((0.55, 0.6, 1.7), (0.08, 0.33, 0.0), 30, 96, 160), render())
    scene.materials["green"] = dielectric(1.5, (0.55, 0.9, 0.6))
    scene.materials["glass"] = dielectric(1.5)
    scene.add("vase", "green", translate(lathe(vase_profile(), 128), (0, LIFT, 0)), True)
    scene.add("marble", "glass", on_floor(sphere(0.07, (0, 0, 0)), 0.3, 0.15), True)
    add_room(scene, wall_z=-1.2)
    light = spherical(200, 40, 2.2, (0.0, 0.3, 0.0))
    add_light(scene, light, (0, 0, 0), 0.1, light_ke(light, 0.1, (0, 0, 0), radiance=0.5))
    return scene


def prism() -> Mesh:
    """Closed triangular glass prism (side 0.35, length 0.6 along z) with outward winding."""
    s = 0.35
    tri = np.array([[-s / 2, 0.0], [s / 2, 0.0], [0.0, s * math.sqrt(3) / 2]])
    v = np.array([[x, y, z] for z in (-0.3, 0.3) for x, y in tri])
    caps = [[0, 2, 1], [3, 4, 5]]
    sides = [[0, 1, 4], [0, 4, 3], [1, 2, 5], [1, 5, 4], [2, 0, 3], [2, 3, 5]]
    faces = np.array(caps + sides)
    return orient_outward((v, faces))


def prism_slab() -> Scene:
    """Glass prism lying on the floor and a glass pane standing behind it, portrait 96x128."""
    scene = Scene("prism_slab", camera((0.4, 1.3, 1.9), (0.0, 0.15, -0.1), 40, 96, 128), render())
    scene.materials["glass"] = dielectric(1.5)
    yaw = trimesh.transformations.rotation_matrix(math.radians(20), UP)
    scene.add("prism", "glass", on_floor(transform(prism(), yaw), 0.1, 0.2), True)
    pane = box((0.5, 0.4, 0.04), (0, 0, 0), -15)
    scene.add("pane", "glass", on_floor(pane, -0.25, -0.45), True)
    add_room(scene, wall_z=-1.5)
    light = spherical(200, 35, 2.3, (0.0, 0.15, 0.0))
    add_light(scene, light, (0, 0, 0), 0.12, light_ke(light, 0.12, (0, 0, 0), radiance=0.45))
    return scene


def control_room() -> Scene:
    """Diffuse only: coloured boxes, a ball and a post in a room under a ceiling light."""
    scene = Scene("control_room", camera((0.0, 0.9, 2.6), (0.0, 0.45, 0.0), 45, 128, 128),
                  render())  # fmt: skip
    scene.materials["white"] = diffuse((0.75, 0.75, 0.75))
    scene.materials["ochre"] = diffuse((0.75, 0.55, 0.2))
    scene.materials["teal"] = diffuse((0.15, 0.5, 0.5))
    scene.materials["rose"] = diffuse((0.7, 0.3, 0.35))
    w, h = 1.0, 1.6
    scene.add("floor", "white", floor_rect(-w, w, -w, w + 0.5))
    scene.add("ceiling", "white", quad((-w, h, -w), (w, h, -w), (w, h, w + 0.5), (-w, h, w + 0.5)))
    scene.add("back_wall", "white", quad((-w, 0, -w), (w, 0, -w), (w, h, -w), (-w, h, -w)))
    scene.add("left", "rose", quad((-w, 0, -w), (-w, h, -w), (-w, h, w + 0.5), (-w, 0, w + 0.5)))
    scene.add("right", "teal", quad((w, 0, -w), (w, 0, w + 0.5), (w, h, w + 0.5), (w, h, -w)))
    scene.add("crate", "ochre", box((0.4, 0.4, 0.4), (-0.4, 0.2, -0.3), 20))
    scene.add("ball", "white", on_floor(sphere(0.2, (0, 0, 0), 3), 0.35, 0.2))
    scene.add("post", "teal", cylinder(0.1, 0.8, (0.5, 0.4, -0.5)))
    light = (0.0, h - 0.005, 0.0)
    ke = light_ke(light, 0.25, (0, 0, 0), radiance=0.6, color=(1.0, 0.85, 0.7))
    add_light(scene, light, (0, 0, 0), 0.25, ke)
    return scene


def control_huge() -> Scene:
    """Diffuse only, at scale 100: matte balls and blocks on a floor, landscape 128x80."""
    scene = Scene("control_huge", camera((1.2, 1.0, 2.4), (0.0, 0.2, 0.0), 45, 128, 80), render())
    scene.materials["grey"] = diffuse((0.6, 0.6, 0.6))
    scene.materials["red"] = diffuse((0.7, 0.15, 0.1))
    scene.materials["blue"] = diffuse((0.15, 0.25, 0.7))
    scene.add("ball", "red", on_floor(sphere(0.2, (0, 0, 0), 3), -0.3, 0.1))
    scene.add("block", "blue", on_floor(box((0.3, 0.5, 0.3), (0, 0, 0), 30), 0.35, -0.2))
    scene.add("slab", "grey", on_floor(box((0.6, 0.1, 0.4), (0, 0, 0), -10), 0.1, 0.5))
    add_room(scene)
    light = spherical(160, 60, 2.0, (0.0, 0.2, 0.0))
    add_light(scene, light, (0, 0, 0), 0.3, light_ke(light, 0.3, (0, 0, 0)))
    return scene


# name -> (builder, scale, one line on what it varies); the written scene is named `name`
SPECS: dict[str, tuple[Callable[[], Scene], float, str]] = {
    "spheres_s0p01": (spheres, 0.01, "scale 0.01 (whole scene 0.03 units): clear glass spheres"),
    "spheres_s1": (spheres, 1.0, "scale 1: the same clear glass spheres (the scale baseline)"),
    "spheres_s100": (spheres, 100.0, "scale 100 (whole scene 300 units): the same spheres"),
    "lens_wall": (lens_wall, 1.0, "biconvex glass lens focusing the light on a wall, 256x128"),
    "glass_lantern": (glass_lantern, 1.0, "light inside a hollow glass box: all light caustic"),
    "cardioid_cup": (cardioid_cup, 1.0, "curved mirror cup, tiny light (side 0.01): cardioid"),
    "tinted_glass": (tinted_glass, 1.0, "tinted glass (amber, blue, green Tf), 96x96"),
    "water_tiles": (water_tiles, 1.0, "water sheet over tiles, big light (1 x 1), 384x256"),
    "bumpy_blob": (bumpy_blob, 1.0, "displaced (bumpy) glass blob, 20k triangles, 512x512"),
    "huge_floor": (huge_floor, 1.0, "floor 1000 units wide to the horizon, 128x96"),
    "far_wall": (far_wall, 1.0, "wall 500 units behind the camera; glass torus, mirror box"),
    "closeup_caustic": (closeup_caustic, 1.0, "camera 0.4 units from a sphere's caustic, 64x64"),
    "far_camera": (far_camera, 1.0, "camera 80 units away, 1.6 degree field of view, 64x64"),
    "concave_mirror": (concave_mirror, 1.0, "parabolic mirror dish, chrome balls, small light"),
    "tall_vase": (tall_vase, 1.0, "thick green glass vase and marble, portrait 96x160"),
    "prism_slab": (prism_slab, 1.0, "glass prism and standing pane, portrait 96x128"),
    "control_room": (control_room, 1.0, "diffuse-only control: room with matte objects"),
    "control_huge": (control_huge, 100.0, "diffuse-only control at scale 100, 128x80"),
}
UNSEEN: dict[str, str] = {name: spec[2] for name, spec in SPECS.items()}


def unit_scale(name: str) -> str:
    """The scene at scale 1 of which scene `name` is a uniformly scaled copy (the same
    builder; the lights' radiance kept, so its image is the same), else `name` itself."""
    builder, scale, _ = SPECS[name]
    twins = [n for n, (b, s, _) in SPECS.items() if b is builder and s == 1.0]
    return twins[0] if scale != 1.0 and twins else name


CONTROLS: tuple[str, ...] = ("control_room", "control_huge")
BACKGROUND = {"light", "floor", "back_wall", "far_wall", "ceiling", "left", "right"}


# ---------------------------------------------------------------------------------------------
# Writing and checking


def build(name: str) -> Scene:
    """Build scene `name` of the set, scaled and named."""
    make, factor, _ = SPECS[name]
    scene = make()
    scene.name = name
    return scaled(scene, factor) if factor != 1.0 else scene


def comment(name: str) -> str:
    """The first-line comment of each written file (names the generator and its VERSION)."""
    return f"dpm unseen scene '{name}' v{VERSION}, written by benchmarks/scenes/make_unseen.py"


def check(scene: Scene, obj: Path) -> None:
    """Read the written scene back and assert the dpm scene format (as the examples do)."""
    from dpm.obj import read_obj

    mesh = read_obj(obj)
    v = mesh.vertices
    assert np.isfinite(v).all(), obj
    offset = 0
    for part in scene.parts:
        faces = np.asarray(mesh.faces[offset : offset + len(part.faces)])
        offset += len(part.faces)
        tri = v[faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        longest2 = np.max(np.sum((tri - np.roll(tri, 1, axis=1)) ** 2, axis=2), axis=1)
        assert (np.linalg.norm(cross, axis=1) > 1e-6 * longest2).all(), f"{obj}: {part.name}"
        if part.closed:
            m = trimesh.Trimesh(v, faces, process=False)
            m.remove_unreferenced_vertices()
            assert m.is_watertight and m.is_winding_consistent, f"{obj}: {part.name} not closed"
            assert m.volume > 0, f"{obj}: {part.name} is inside out"
    assert offset == len(mesh.faces), obj
    specular = any("illum" in scene.materials[p.material] for p in scene.parts)
    assert specular == (scene.name not in CONTROLS), f"{obj}: controls only are diffuse-only"
    lit = np.vstack([p.vertices for p in scene.parts if p.name not in BACKGROUND])
    middle = 0.5 * (lit.min(axis=0) + lit.max(axis=0))
    light = next(p for p in scene.parts if p.name == "light")
    tri = light.vertices[light.faces]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.einsum("ij,ij->i", normal, middle - tri.mean(axis=1)) > 0).all(), "light faces away"


def is_current(name: str, out: Path) -> bool:
    """Whether scene `name`'s three files are in `out`, written by this VERSION."""
    files = [out / f"{name}{suffix}" for suffix in (".obj", ".mtl", ".toml")]
    if not all(f.is_file() for f in files):
        return False
    with open(files[2], encoding="utf-8") as f:
        return f.readline().strip() == f"# {comment(name)}"


def unseen_scenes(out: Path = SCENES_DIR) -> list[Path]:
    """Write every scene of the set whose files are missing or stale into `out`; return the
    OBJ paths, in the fixed order of UNSEEN."""
    paths = []
    for name in SPECS:
        if not is_current(name, out):
            scene = build(name)
            write_scene(scene, out, comment(name))
            check(scene, out / f"{name}.obj")
        paths.append(out / f"{name}.obj")
    return paths


def main() -> None:
    """Build, write and check every scene of the set; print a line per scene."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=SCENES_DIR)
    args = parser.parse_args()
    for name in SPECS:
        scene = build(name)
        obj = write_scene(scene, args.out, comment(name))
        check(scene, obj)
        light = next(p for p in scene.parts if p.name == "light")
        side = float(np.linalg.norm(light.vertices[1] - light.vertices[0]))
        triangles = sum(len(p.faces) for p in scene.parts)
        c = scene.camera
        print(f"{name:16s} {c['width']}x{c['height']:<4} {triangles:6d} triangles, light side "
              f"{side:.3g} (area {side * side:.3g}); {UNSEEN[name]}")  # fmt: skip
    return None


if __name__ == "__main__":
    sys.exit(main())
