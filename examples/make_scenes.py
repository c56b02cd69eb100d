"""Generate the dpm example scenes: `<name>.obj` + `<name>.mtl` + `<name>.toml` per scene.

Analogues of the test scenes of "Deep Photon Mapping" (EGSR 2020) -- glass egg, red wine, ring,
two water pools, torus, "dragon" -- plus a diffuse Cornell box. Everything is deterministic
(fixed seeds). y is up, the floor is y = 0 and scenes are about 1-3 units across. Each scene is
read back after writing and checked: materials, indices, degenerate triangles, watertight closed
dielectrics with outward (counter-clockwise) winding, and lights facing the scene.

Usage: python examples/make_scenes.py [--out examples/scenes]
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path

import numpy as np
import trimesh

from dpm.data.builder import (
    LIFT,
    UP,
    Mesh,
    Scene,
    add_light,
    back_wall,
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

FLOOR_KD = (0.7, 0.7, 0.7)


# ---------------------------------------------------------------------------------------------
# Materials


# ---------------------------------------------------------------------------------------------
# Geometry helpers


def add_floor(scene: Scene, half: float = 8.0, wall_z: float | None = None) -> None:
    """Add a diffuse floor square of half-size `half` and optionally a back wall at z = wall_z."""
    scene.materials["floor"] = diffuse(FLOOR_KD)
    back = -half if wall_z is None else wall_z  # the floor ends at the wall
    scene.add("floor", "floor", floor_rect(-half, half, back, half))
    if wall_z is not None:
        scene.add("back_wall", "floor", back_wall(wall_z, half, 3.0))


# ---------------------------------------------------------------------------------------------
# Scenes


def glass_egg() -> Scene:
    """Asymmetric glass egg lying on a floor, lit from above-left; caustic to its right."""
    scene = Scene("glass_egg", camera((1.1, 1.25, 1.9), (0.3, 0.15, 0.0), 40), render())
    scene.materials["glass"] = dielectric(1.5)
    s = np.linspace(0.0, math.pi, 36)
    radius, half_length, skew = 0.3, 0.42, 0.12
    profile = np.stack([radius * np.sin(s) * (1 + skew * np.cos(s)), -half_length * np.cos(s)], 1)
    profile[[0, -1], 0] = 0.0
    egg = lathe(profile, 64)
    tilt = trimesh.transformations.rotation_matrix(math.pi / 2, [1, 0, 0])  # long axis along z
    yaw = trimesh.transformations.rotation_matrix(math.radians(-25), UP)
    egg = rest_on_floor(transform(egg, yaw @ tilt))
    scene.add("egg", "glass", egg, closed=True)
    add_floor(scene, wall_z=-2.0)
    center = egg[0].mean(axis=0)
    light = spherical(190, 40, 2.2, center)
    spot = (center[0], 0.0, center[2])
    add_light(scene, light, spot, 0.1, light_ke(light, 0.1, spot))
    return scene


def wine_glass_profiles() -> tuple[np.ndarray, np.ndarray]:
    """(r, y) profiles of a wine glass (foot, stem, bowl as a thick shell) and its wine."""
    bowl_r, bowl_b, bowl_yc = 0.2, 0.32, 0.72  # outer bowl: half-ellipse-like tulip
    wall, bottom, gap, level = 0.006, 0.03, 0.0015, 0.66
    phi = np.linspace(0.0, 2.0, 49)
    outer = np.stack([bowl_r * np.sin(phi), bowl_yc - bowl_b * np.cos(phi)], 1)
    normal = np.stack([bowl_b * np.sin(phi), -bowl_r * np.cos(phi)], 1)
    normal /= np.linalg.norm(normal, axis=1, keepdims=True)
    thickness = wall + (bottom - wall) * np.exp(-((phi / 0.45) ** 2))  # thick bowl bottom
    inner = outer - thickness[:, None] * normal
    wine = outer - (thickness + gap)[:, None] * normal
    foot_and_stem = [
        (0.0, 0.0),
        (0.16, 0.0),
        (0.165, 0.004),
        (0.163, 0.009),
        (0.14, 0.014),
        (0.08, 0.022),
        (0.04, 0.032),
        (0.026, 0.05),
        (0.02, 0.08),
        (0.017, 0.16),
        (0.016, 0.25),
        (0.018, 0.33),
        (0.024, 0.375),
    ]
    start = np.searchsorted(outer[:, 0], 0.03)  # where the stem flares into the bowl
    t = np.linspace(0.0, math.pi, 9)[1:-1]  # rounded rim between outer and inner lip
    lip_mid, lip_dir = 0.5 * (outer[-1] + inner[-1]), 0.5 * (outer[-1] - inner[-1])
    lip_up = np.array([-lip_dir[1], lip_dir[0]])  # lip_dir turned counter-clockwise: upwards
    lip = lip_mid + np.outer(np.cos(t), lip_dir) + np.outer(np.sin(t), lip_up)
    inner[0, 0] = 0.0
    glass = np.vstack([foot_and_stem, outer[start:], lip, inner[::-1]])
    below = wine[wine[:, 1] < level]
    k = len(below)
    f = (level - wine[k - 1, 1]) / (wine[k, 1] - wine[k - 1, 1])
    surface = wine[k - 1] + f * (wine[k] - wine[k - 1])
    top = np.outer(np.linspace(1.0, 0.0, 5)[1:], [surface[0], 0.0]) + [0.0, level]
    below = below.copy()
    below[0, 0] = 0.0
    return glass, np.vstack([below, surface, top])


def red_wine() -> Scene:
    """Wine glass (thick glass shell) holding red wine, lit from the side; red caustic."""
    scene = Scene("red_wine", camera((0.65, 0.85, 1.9), (0.25, 0.38, 0.0), 38), render())
    scene.materials["glass"] = dielectric(1.5)
    scene.materials["wine"] = dielectric(1.33, (0.9, 0.15, 0.1))
    glass_profile, wine_profile = wine_glass_profiles()
    scene.add("glass", "glass", translate(lathe(glass_profile, 96), (0, LIFT, 0)), closed=True)
    scene.add("wine", "wine", translate(lathe(wine_profile, 96), (0, LIFT, 0)), closed=True)
    add_floor(scene, wall_z=-2.0)
    light = spherical(185, 42, 2.2, (0.0, 0.6, 0.0))
    spot = (0.0, 0.0, 0.0)
    add_light(scene, light, spot, 0.1, light_ke(light, 0.1, spot))
    return scene


def ring() -> Scene:
    """Gold ring band standing on the floor; a low light makes the nephroid caustic inside."""
    scene = Scene("ring", camera((0.05, 2.2, 0.95), (0.05, 0.0, 0.0), 40), render())
    scene.materials["gold"] = mirror((0.9, 0.8, 0.5))
    r_in, r_out, height = 0.45, 0.5, 0.4
    profile = [(r_in, 0.0), (r_out, 0.0), (r_out, height), (r_in, height)]
    scene.add("ring", "gold", translate(lathe(profile, 720, loop=True), (0, LIFT, 0)), closed=True)
    add_floor(scene)
    # Low enough that the near wall shadows the inside floor, high enough to light the whole
    # far wall: tan(elevation) ~ height / (2 r_in). The nephroid is then the only light inside.
    light = spherical(180, 25, 3.0, (0.0, 0.0, 0.0))
    add_light(scene, light, (0.0, 0.0, 0.0), 0.15, light_ke(light, 0.15, (0, 0, 0), 0.5))
    return scene


def pool(name: str, waves: list[tuple[float, float, float, float]]) -> Scene:
    """Tiled pool with low walls under a water sheet; waves: (amplitude, wavelength, deg, phase)."""
    scene = Scene(name, camera((0.0, 2.7, 1.6), (0.0, 0.0, -0.05), 50, 320, 240), render())
    half, tile, depth, wall_h, thick = 0.8, 0.2, 0.3, 0.38, 0.08
    scene.materials["tile_light"] = diffuse((0.75, 0.78, 0.8))
    scene.materials["tile_dark"] = diffuse((0.2, 0.42, 0.6))
    scene.materials["wall"] = diffuse((0.7, 0.7, 0.7))
    scene.materials["floor"] = diffuse(FLOOR_KD)
    scene.materials["water"] = dielectric(1.33)
    n = round(2 * half / tile)
    tiles: dict[str, list[Mesh]] = {"tile_light": [], "tile_dark": []}
    for i in range(n):
        for j in range(n):
            x0, z0 = -half + i * tile, -half + j * tile
            key = "tile_light" if (i + j) % 2 == 0 else "tile_dark"
            tiles[key].append(floor_rect(x0, x0 + tile, z0, z0 + tile))
    for key, meshes in tiles.items():
        scene.add(key, key, merge(*meshes))
    outer = half + thick
    walls = [
        box((2 * outer, wall_h, thick), (0.0, wall_h / 2, sign * (half + thick / 2)))
        for sign in (-1, 1)
    ] + [
        box((thick, wall_h, 2 * half), (sign * (half + thick / 2), wall_h / 2, 0.0))
        for sign in (-1, 1)
    ]
    scene.add("walls", "wall", merge(*walls))
    deck = 3.0
    scene.add(
        "floor",
        "floor",
        merge(
            floor_rect(-deck, deck, -deck, -outer),
            floor_rect(-deck, deck, outer, deck),
            floor_rect(-deck, -outer, -outer, outer),
            floor_rect(outer, deck, -outer, outer),
        ),
    )

    def water(x: np.ndarray, z: np.ndarray) -> np.ndarray:
        y = np.full_like(x, depth)
        for amplitude, wavelength, angle, phase in waves:
            a = math.radians(angle)
            k = 2.0 * math.pi / wavelength
            y += amplitude * np.sin(k * (x * math.cos(a) + z * math.sin(a)) + phase)
        return y

    edge = half + 0.02  # the open sheet reaches into the walls: no gap at the border
    scene.add("water", "water", heightfield(water, (-edge, edge), (-edge, edge), (120, 120)))
    light = (0.35, 2.4, -0.45)
    spot = (0.0, 0.0, 0.0)
    add_light(scene, light, spot, 0.08, light_ke(light, 0.08, spot))
    return scene


def pool1() -> Scene:
    """Pool with long, gentle waves."""
    waves = [(0.019, 0.5, 20, 0.0), (0.016, 0.38, 75, 1.3), (0.013, 0.3, 140, 2.1)]
    return pool("pool1", waves)


def pool2() -> Scene:
    """Pool with many short crossing waves (random directions, fixed seed)."""
    rng = np.random.default_rng(2)
    waves = [
        (float(rng.uniform(0.0035, 0.006)), float(rng.uniform(0.12, 0.22)), float(angle), phase)
        for angle, phase in zip(
            np.linspace(0, 180, 7, endpoint=False) + rng.uniform(-10, 10, 7),
            rng.uniform(0, 2 * math.pi, 7),
            strict=True,
        )
    ]
    return pool("pool2", waves)


def torus() -> Scene:
    """Glass torus lying on the floor, light above at an angle."""
    scene = Scene("torus", camera((1.2, 1.5, 1.9), (0.2, 0.1, 0.0), 40), render())
    scene.materials["glass"] = dielectric(1.5)
    major, minor = 0.45, 0.16
    t = np.linspace(0.0, 2.0 * math.pi, 48, endpoint=False)
    profile = np.stack([major + minor * np.cos(t), minor * np.sin(t)], 1)
    scene.add("torus", "glass", rest_on_floor(lathe(profile, 160, loop=True)), closed=True)
    add_floor(scene, wall_z=-2.0)
    light = spherical(200, 60, 2.2, (0.0, 0.16, 0.0))
    spot = (0.0, 0.0, 0.0)
    add_light(scene, light, spot, 0.1, light_ke(light, 0.1, spot))
    return scene


def knot_tube(samples: int, sides: int, tube: float, seed: int) -> Mesh:
    """Watertight (2, 3) torus-knot tube whose radius carries multi-octave bumps."""
    p, q, major, minor = 2, 3, 0.6, 0.26
    t = np.linspace(0.0, 2.0 * math.pi, samples, endpoint=False)
    ring_r = major + minor * np.cos(q * t)
    center = np.stack([ring_r * np.cos(p * t), minor * np.sin(q * t), ring_r * np.sin(p * t)], 1)
    tangent = np.roll(center, -1, axis=0) - np.roll(center, 1, axis=0)
    tangent /= np.linalg.norm(tangent, axis=1, keepdims=True)
    core = np.stack([major * np.cos(p * t), np.zeros_like(t), major * np.sin(p * t)], 1)
    n1 = center - core  # points away from the torus core circle: a smooth, periodic frame
    n1 -= np.sum(n1 * tangent, axis=1, keepdims=True) * tangent
    n1 /= np.linalg.norm(n1, axis=1, keepdims=True)
    n2 = np.cross(tangent, n1)
    phi = np.linspace(0.0, 2.0 * math.pi, sides, endpoint=False)
    radial = np.cos(phi)[None, :, None] * n1[:, None] + np.sin(phi)[None, :, None] * n2[:, None]
    base = center[:, None] + tube * radial
    rng = np.random.default_rng(seed)
    bumps = np.zeros(base.shape[:2])
    for octave in range(4):  # sum of random plane waves, wavelength halving per octave
        for _ in range(6):
            k = rng.normal(size=3)
            k *= 2.0 * math.pi * 2**octave / (0.5 * np.linalg.norm(k))
            bumps += 0.5**octave * np.sin(base @ k + rng.uniform(0, 2 * math.pi))
    bumps *= 0.13 / np.abs(bumps).max()  # at most +-13 % of the tube radius
    vertices = (center[:, None] + tube * (1.0 + bumps)[..., None] * radial).reshape(-1, 3)
    index = np.arange(samples * sides).reshape(samples, sides)
    a, b = index, np.roll(index, -1, axis=0)
    c, d = np.roll(a, -1, axis=1), np.roll(b, -1, axis=1)
    faces = np.concatenate([np.stack([a, b, c], -1), np.stack([b, d, c], -1)]).reshape(-1, 3)
    # Self-intersection guard: distant parts of the centreline stay apart, bends stay gentle.
    gaps = np.linalg.norm(center[:, None] - center[None], axis=-1)
    lag = np.abs(np.arange(samples)[:, None] - np.arange(samples)[None])
    far = np.minimum(lag, samples - lag) > samples // 8
    assert gaps[far].min() > 2.4 * tube, "knot strands too close for the tube radius"
    step = np.linalg.norm(np.roll(center, -1, axis=0) - center, axis=1)
    bend = np.linalg.norm(np.roll(tangent, -1, axis=0) - tangent, axis=1) / step
    assert 1.0 / bend.max() > 2.0 * tube, "knot bends too sharply for the tube radius"
    return orient_outward((vertices, faces))


def dragon() -> Scene:
    """Complex glass object: bumpy trefoil-knot tube (>= 50k triangles) on a floor."""
    scene = Scene("dragon", camera((0.0, 2.3, 2.6), (0.0, 0.1, 0.15), 45), render())
    scene.materials["glass"] = dielectric(1.5)
    scene.add("dragon", "glass", rest_on_floor(knot_tube(720, 40, 0.13, seed=7)), closed=True)
    add_floor(scene, wall_z=-2.5)
    light = spherical(235, 58, 2.4, (0.0, 0.3, 0.0))
    spot = (0.0, 0.0, 0.0)
    add_light(scene, light, spot, 0.12, light_ke(light, 0.12, spot))
    return scene


def cornell_box() -> Scene:
    """Classic diffuse Cornell box, 1 unit wide, open towards the camera (+z)."""
    scene = Scene(
        "cornell_box", camera((0.0, 0.5, 1.95), (0.0, 0.5, 0.0), 38), render(photons=100_000)
    )
    scene.materials["white"] = diffuse((0.73, 0.73, 0.73))
    scene.materials["red"] = diffuse((0.63, 0.065, 0.05))
    scene.materials["green"] = diffuse((0.14, 0.45, 0.091))
    h = 0.5  # half width; the box spans x, z in [-h, h] and y in [0, 1]
    scene.add("floor", "white", floor_rect(-h, h, -h, h))
    scene.add("ceiling", "white", quad((-h, 1, -h), (h, 1, -h), (h, 1, h), (-h, 1, h)))
    scene.add("back", "white", quad((-h, 0, -h), (h, 0, -h), (h, 1, -h), (-h, 1, -h)))
    scene.add("left", "red", quad((-h, 0, -h), (-h, 1, -h), (-h, 1, h), (-h, 0, h)))
    scene.add("right", "green", quad((h, 0, -h), (h, 0, h), (h, 1, h), (h, 1, -h)))
    scene.add("tall_box", "white", box((0.3, 0.6, 0.3), (-0.17, 0.3, -0.15), 17))
    scene.add("short_box", "white", box((0.3, 0.3, 0.3), (0.18, 0.15, 0.15), -18))
    light = (0.0, 0.995, 0.0)
    ke = light_ke(light, 0.22, (0.0, 0.0, 0.0), 0.7, (1.0, 0.72, 0.3))
    add_light(scene, light, (0.0, 0.0, 0.0), 0.22, ke)
    return scene


SCENES: list[Callable[[], Scene]] = [
    glass_egg,
    red_wine,
    ring,
    pool1,
    pool2,
    torus,
    dragon,
    cornell_box,
]


# ---------------------------------------------------------------------------------------------
# Writing and checking


def read_parts(obj: Path) -> tuple[np.ndarray, dict[str, tuple[str, np.ndarray]], list[str]]:
    """Read back an OBJ written by `write_scene`: vertices, {object: (material, faces)}, mtllibs."""
    vertices: list[list[float]] = []
    parts: dict[str, tuple[str, list[list[int]]]] = {}
    mtllibs, current = [], ""
    for line in obj.read_text().splitlines():
        words = line.split()
        if not words or words[0] == "#":
            continue
        if words[0] == "v":
            vertices.append([float(w) for w in words[1:]])
        elif words[0] == "f":
            parts[current][1].append([int(w) - 1 for w in words[1:]])
        elif words[0] == "o":
            current = words[1]
        elif words[0] == "usemtl":
            parts[current] = (words[1], [])
        elif words[0] == "mtllib":
            mtllibs.append(words[1])
        else:
            raise ValueError(f"{obj}: unexpected statement {words[0]}")
    v = np.array(vertices)
    return v, {k: (m, np.array(f)) for k, (m, f) in parts.items()}, mtllibs


def check_scene(scene: Scene, obj: Path) -> None:
    """Read the written scene back and assert it follows the dpm scene format."""
    vertices, parts, mtllibs = read_parts(obj)
    assert mtllibs == [f"{scene.name}.mtl"] and (obj.parent / mtllibs[0]).is_file()
    mtl = (obj.parent / mtllibs[0]).read_text().splitlines()
    names = {line.split()[1] for line in mtl if line.startswith("newmtl ")}
    assert np.isfinite(vertices).all()
    for name, (material, faces) in parts.items():
        assert material in names, f"{obj}: {name} uses undefined material {material}"
        assert faces.min() >= 0 and faces.max() < len(vertices), f"{obj}: {name}: bad index"
        tri = vertices[faces]
        cross = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
        longest2 = np.max(np.sum((tri - np.roll(tri, 1, axis=1)) ** 2, axis=2), axis=1)
        assert (np.linalg.norm(cross, axis=1) > 1e-6 * longest2).all(), f"{obj}: {name}: sliver"
    closed = {p.name for p in scene.parts if p.closed}
    for name in closed:
        mesh = trimesh.Trimesh(vertices, parts[name][1], process=False)
        mesh.remove_unreferenced_vertices()
        assert mesh.is_watertight and mesh.is_winding_consistent, f"{obj}: {name} not closed"
        assert mesh.volume > 0, f"{obj}: {name} is inside out"
    background = {"light", "floor", "back_wall"}
    lit = np.vstack([vertices[np.unique(f)] for n, (_, f) in parts.items() if n not in background])
    middle = 0.5 * (lit.min(axis=0) + lit.max(axis=0))
    tri = vertices[parts["light"][1]]
    normal = np.cross(tri[:, 1] - tri[:, 0], tri[:, 2] - tri[:, 0])
    assert (np.einsum("ij,ij->i", normal, middle - tri.mean(axis=1)) > 0).all(), "light faces away"


def main() -> None:
    """Build, write and check every example scene."""
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "scenes")
    args = parser.parse_args()
    for make in SCENES:
        scene = make()
        obj = write_scene(
            scene, args.out, f"dpm example scene '{scene.name}', written by examples/make_scenes.py"
        )
        check_scene(scene, obj)
        triangles = sum(len(p.faces) for p in scene.parts)
        print(f"{obj}: {triangles} triangles, {obj.stat().st_size / 1e6:.2f} MB")


if __name__ == "__main__":
    main()
