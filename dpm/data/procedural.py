"""Procedural training scenes (paper §4.3): bumpy primitives in a box under area lights.

1–16 primitives (sphere, box, cylinder, capsule, torus) with random size, rotation and a
random bump displacement stand (or float) roughly on a grid in an open-fronted diffuse box,
below TOP; 2–4 square area lights at random positions above them look at random points of
the floor; each
object is diffuse, mirror or dielectric at random (at least one specular). Everything is
drawn from `numpy.random.default_rng((seed, index))`, so scene `index` is the same whoever
makes it.
"""

from __future__ import annotations

import math

import numpy as np
import trimesh

from dpm.data.builder import (
    LIFT,
    Mesh,
    Scene,
    camera,
    dielectric,
    diffuse,
    emitter,
    floor_rect,
    light_quad,
    orient_outward,
    quad,
)  # fmt: skip

HALF = 2.0  # the box spans [-HALF, HALF] in x and z
HEIGHT = 3.0
TOP = 1.5  # objects stay below this height, lights above LIGHTS[0]
LIGHTS = (1.75, 2.8)  # height range of the lights' centres
SHAPES = ("sphere", "box", "cylinder", "capsule", "torus")


def primitive(shape: str, rng: np.random.Generator) -> trimesh.Trimesh:
    """A closed unit-sized mesh of `shape`, finely enough tessellated to carry bumps."""
    if shape == "sphere":
        return trimesh.creation.icosphere(subdivisions=3, radius=0.5)
    if shape == "box":
        mesh = trimesh.creation.box(extents=rng.uniform(0.5, 1.0, 3))
        return mesh.subdivide().subdivide().subdivide()
    if shape == "cylinder":
        return trimesh.creation.cylinder(radius=0.4, height=rng.uniform(0.4, 1.0), sections=48)
    if shape == "capsule":
        return trimesh.creation.capsule(height=rng.uniform(0.2, 0.6), radius=0.3, count=[24, 24])
    return trimesh.creation.torus(0.35, rng.uniform(0.08, 0.15), 48, 24)


def bump(mesh: trimesh.Trimesh, rng: np.random.Generator, amplitude: float) -> Mesh:
    """Vertices moved along their normals by a sum of three random plane waves."""
    v = np.asarray(mesh.vertices, float)
    height = np.zeros(len(v))
    for _ in range(3):
        direction = rng.normal(size=3)
        direction /= np.linalg.norm(direction)
        height += np.sin(rng.uniform(4.0, 16.0) * v @ direction + rng.uniform(0, 2 * math.pi))
    v = v + (amplitude / 3.0) * height[:, None] * np.asarray(mesh.vertex_normals)
    return orient_outward((v, np.asarray(mesh.faces)))


def random_scene(index: int, seed: int = 0, width: int = 128) -> Scene:
    """Training scene `index` of the set drawn with `seed`, seen by a width × width camera."""
    rng = np.random.default_rng((seed, index))
    scene = Scene(f"scene{index:05d}", camera((0.0, 2.2, 4.6), (0.0, 0.3, -0.4), 45, width, width),
                  render={})  # fmt: skip
    h = HALF
    scene.materials["walls"] = diffuse(tuple(rng.uniform(0.3, 0.9, 3)))
    scene.materials["floor"] = diffuse(tuple(rng.uniform(0.4, 0.9, 3)))
    scene.add("floor", "floor", floor_rect(-h, h, -h, h + 3.0))  # on under the camera
    scene.add("back", "walls", quad((-h, 0, -h), (h, 0, -h), (h, HEIGHT, -h), (-h, HEIGHT, -h)))
    scene.add("left", "walls", quad((-h, 0, h), (-h, 0, -h), (-h, HEIGHT, -h), (-h, HEIGHT, h)))
    scene.add("right", "walls", quad((h, 0, -h), (h, 0, h), (h, HEIGHT, h), (h, HEIGHT, -h)))
    scene.add("ceiling", "walls", quad((-h, HEIGHT, -h), (h, HEIGHT, -h), (h, HEIGHT, h),
                                       (-h, HEIGHT, h)))  # fmt: skip

    count = int(rng.integers(1, 17))
    grid = math.ceil(math.sqrt(count))
    cell = 2 * 0.8 * h / grid
    kinds = rng.choice(3, size=count, p=[0.3, 0.25, 0.45])
    if not (kinds > 0).any():
        kinds[rng.integers(count)] = rng.integers(1, 3)  # caustics need a specular object
    for i, slot in enumerate(rng.permutation(grid * grid)[:count]):
        mesh = primitive(SHAPES[rng.integers(len(SHAPES))], rng)
        mesh.apply_transform(trimesh.transformations.random_rotation_matrix(rng.random(3)))
        size = min(cell * rng.uniform(0.45, 0.8), 0.8 * TOP)
        mesh.apply_scale(size / max(mesh.extents))
        vertices, faces = bump(mesh, rng, rng.uniform(0.0, 0.04) * size)
        centre = (np.array([slot % grid, slot // grid]) + 0.5) * cell - 0.8 * h
        centre += rng.uniform(-0.15, 0.15, 2) * cell
        room = TOP - LIFT - np.ptp(vertices[:, 1])  # how far it may float and stay below TOP
        lift = LIFT + (min(rng.uniform(0.0, 0.5) * cell, room) if rng.random() < 0.3 else 0.0)
        vertices = vertices + [centre[0], lift - vertices[:, 1].min(), centre[1]]
        name = f"object{i}"
        if kinds[i] == 0:
            scene.materials[name] = diffuse(tuple(rng.uniform(0.2, 0.9, 3)))
        elif kinds[i] == 1:
            scene.materials[name] = {"illum": 3, "Ks": tuple(rng.uniform(0.6, 1.0, 3))}
        else:
            tint = rng.uniform(0.6, 1.0, 3) if rng.random() < 0.4 else np.ones(3)
            scene.materials[name] = dielectric(float(rng.uniform(1.3, 1.8)), tuple(tint))
        scene.add(name, name, (vertices, faces), closed=kinds[i] == 2)

    for j in range(int(rng.integers(2, 5))):
        centre = (rng.uniform(-0.8, 0.8) * h, rng.uniform(*LIGHTS), rng.uniform(-0.8, 0.8) * h)
        target = (rng.uniform(-h, h), 0.0, rng.uniform(-h, h))
        size = float(rng.uniform(0.1, 0.4))
        colour = rng.uniform(0.5, 1.0, 3)
        ke = float(np.exp(rng.uniform(np.log(5.0), np.log(60.0)))) / size**2 * colour
        scene.materials[f"light{j}"] = emitter(tuple(ke * 0.3))
        scene.add(f"light{j}", f"light{j}", light_quad(centre, target, size))
    return scene
