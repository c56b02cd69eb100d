"""Building scenes in code: meshes, materials, a camera, and writing OBJ + MTL + TOML.

Used by `examples/make_scenes.py` (the example scenes) and `dpm.data.procedural` (training
scenes). Meshes are (vertices (V, 3) float, faces (T, 3) int) pairs, counter-clockwise = front.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
import trimesh

Mesh = tuple[np.ndarray, np.ndarray]  # (V, 3) float vertices, (T, 3) int faces (CCW = front)
Vec = tuple[float, float, float]

LIFT = 1e-3  # gap between specular objects and the floor, so no face touches it
UP = np.array([0.0, 1.0, 0.0])


@dataclass
class Part:
    """One OBJ object: a triangle mesh with a single material."""

    name: str
    material: str
    vertices: np.ndarray
    faces: np.ndarray
    closed: bool = False  # must be watertight with outward winding (positive volume)


@dataclass
class Scene:
    """A scene under construction: materials, parts, camera and render defaults."""

    name: str
    camera: dict[str, object]
    render: dict[str, int]
    materials: dict[str, dict[str, object]] = field(default_factory=dict)
    parts: list[Part] = field(default_factory=list)

    def add(self, name: str, material: str, mesh: Mesh, closed: bool = False) -> None:
        """Append a part; its material must already be defined."""
        assert material in self.materials, material
        vertices, faces = mesh
        self.parts.append(Part(name, material, np.asarray(vertices, float), faces, closed))


def diffuse(kd: Vec) -> dict[str, object]:
    """Lambertian material."""
    return {"Kd": kd}


def emitter(ke: Vec) -> dict[str, object]:
    """Area light: one-sided Lambertian emitter, black otherwise."""
    return {"Kd": (0.0, 0.0, 0.0), "Ke": ke}


def mirror(ks: Vec) -> dict[str, object]:
    """Perfect mirror with reflectance ks."""
    return {"illum": 3, "Ks": ks}


def dielectric(ior: float, tf: Vec = (1.0, 1.0, 1.0)) -> dict[str, object]:
    """Smooth dielectric, IOR `ior` on the back side, air on the front side."""
    return {"illum": 7, "Ni": ior, "Tf": tf}


def merge(*meshes: Mesh) -> Mesh:
    """Concatenate meshes into one vertex and face array."""
    vertices, faces, offset = [], [], 0
    for v, f in meshes:
        vertices.append(np.asarray(v, float))
        faces.append(np.asarray(f) + offset)
        offset += len(v)
    return np.vstack(vertices), np.vstack(faces)


def transform(mesh: Mesh, matrix: np.ndarray) -> Mesh:
    """Apply a 4x4 homogeneous transform to the vertices."""
    vertices, faces = mesh
    return trimesh.transform_points(vertices, matrix), faces


def translate(mesh: Mesh, offset: Vec) -> Mesh:
    """Move a mesh by `offset`."""
    return mesh[0] + np.asarray(offset, float), mesh[1]


def rest_on_floor(mesh: Mesh, lift: float = LIFT) -> Mesh:
    """Translate vertically so that the lowest vertex is `lift` above y = 0."""
    return translate(mesh, (0.0, lift - mesh[0][:, 1].min(), 0.0))


def quad(p0: Vec, p1: Vec, p2: Vec, p3: Vec) -> Mesh:
    """Planar quad p0-p1-p2-p3; counter-clockwise order gives the front normal."""
    return np.array([p0, p1, p2, p3], float), np.array([[0, 1, 2], [0, 2, 3]])


def floor_rect(x0: float, x1: float, z0: float, z1: float, y: float = 0.0) -> Mesh:
    """Horizontal rectangle facing up (+y)."""
    return quad((x0, y, z0), (x0, y, z1), (x1, y, z1), (x1, y, z0))


def back_wall(z: float, half_width: float, height: float) -> Mesh:
    """Vertical wall in the plane z = `z`, facing +z, standing on the floor."""
    w = half_width
    return quad((-w, 0.0, z), (w, 0.0, z), (w, height, z), (-w, height, z))


def box(extents: Vec, center: Vec, yaw_deg: float = 0.0) -> Mesh:
    """Closed box with outward normals, rotated by `yaw_deg` about the vertical axis."""
    matrix = trimesh.transformations.rotation_matrix(math.radians(yaw_deg), UP)
    matrix[:3, 3] = center
    mesh = trimesh.creation.box(extents=extents, transform=matrix)
    return np.asarray(mesh.vertices), np.asarray(mesh.faces)


def lathe(profile: np.ndarray, segments: int, loop: bool = False) -> Mesh:
    """Surface of revolution about the y axis of an (r, y) profile.

    The front normal is the profile tangent turned clockwise in the (r, y) plane: a profile
    running upwards faces away from the axis. Points with r == 0 become single pole vertices;
    `loop` joins the last profile point back to the first (e.g. a torus).
    """
    profile = np.asarray(profile, float)
    theta = np.linspace(0.0, 2.0 * math.pi, segments, endpoint=False)
    ring = np.stack([np.cos(theta), np.zeros_like(theta), np.sin(theta)], axis=1)
    vertices, index = [], np.empty((len(profile), segments), dtype=np.int64)
    count = 0
    for i, (r, y) in enumerate(profile):
        if r == 0.0:
            vertices.append([[0.0, y, 0.0]])
            index[i] = count
            count += 1
        else:
            vertices.append(ring * r + [0.0, y, 0.0])
            index[i] = count + np.arange(segments)
            count += segments
    a = index
    b = np.roll(index, -1, axis=0)  # next profile point
    c = np.roll(index, -1, axis=1)  # next angle
    d = np.roll(b, -1, axis=1)
    rows = len(profile) if loop else len(profile) - 1
    faces = np.concatenate([np.stack([a, b, c], -1)[:rows], np.stack([b, d, c], -1)[:rows]])
    faces = faces.reshape(-1, 3)
    keep = (faces[:, [0, 1, 0]] != faces[:, [1, 2, 2]]).all(axis=1)  # drop collapsed pole faces
    return np.vstack(vertices), faces[keep]


def heightfield(
    height: Callable[[np.ndarray, np.ndarray], np.ndarray],
    x_range: tuple[float, float],
    z_range: tuple[float, float],
    cells: tuple[int, int],
) -> Mesh:
    """Open grid sheet y = height(x, z) with the front side up (+y)."""
    nx, nz = cells
    x, z = np.meshgrid(np.linspace(*x_range, nx + 1), np.linspace(*z_range, nz + 1), indexing="ij")
    vertices = np.stack([x, height(x, z), z], axis=-1).reshape(-1, 3)
    index = np.arange((nx + 1) * (nz + 1)).reshape(nx + 1, nz + 1)
    v00, v10 = index[:-1, :-1], index[1:, :-1]
    v01, v11 = index[:-1, 1:], index[1:, 1:]
    faces = np.concatenate(
        [np.stack([v00, v01, v10], -1).reshape(-1, 3), np.stack([v10, v01, v11], -1).reshape(-1, 3)]
    )
    return vertices, faces


def orient_outward(mesh: Mesh) -> Mesh:
    """Flip the winding of a closed mesh if its signed volume is negative."""
    vertices, faces = mesh
    if trimesh.Trimesh(vertices, faces, process=False).volume < 0:
        faces = faces[:, ::-1]
    return vertices, faces


def light_quad(center: Vec, target: Vec, size: float) -> Mesh:
    """Square area light of side `size` at `center` whose front face looks at `target`."""
    c = np.asarray(center, float)
    n = np.asarray(target, float) - c
    n /= np.linalg.norm(n)
    helper = np.array([1.0, 0.0, 0.0]) if abs(n[0]) < 0.9 else np.array([0.0, 0.0, 1.0])
    u = np.cross(helper, n)
    u *= 0.5 * size / np.linalg.norm(u)
    v = np.cross(n, u)  # u x v is along n: counter-clockwise seen from the front
    return quad(c - u - v, c + u - v, c + u + v, c - u + v)


def light_ke(
    center: Vec, size: float, spot: Vec, radiance: float = 0.7, color: Vec = (1.0, 1.0, 1.0),
    *, normal: Vec = (0.0, 1.0, 0.0), albedo: float = 0.7,
) -> Vec:  # fmt: skip
    """Ke (RGB radiance) of a square light of side `size` at `center` facing `spot` that gives
    a diffuse surface there (unit normal `normal`, albedo `albedo`) the outgoing radiance
    `radiance` (tinted by `color`)."""
    d = np.asarray(spot, float) - np.asarray(center, float)
    dist2 = float(d @ d)
    cos_receiver = abs(float(np.dot(d, normal))) / math.sqrt(dist2)
    ke = math.pi * radiance * dist2 / (albedo * size * size * cos_receiver)
    return tuple(float(f"{ke * c:.3g}") for c in color)  # type: ignore[return-value]


def add_light(scene: Scene, center: Vec, target: Vec, size: float, ke: Vec) -> None:
    """Add the scene's square area light (material "light", emitted radiance `ke`) at
    `center`, looking at `target`."""
    scene.materials["light"] = emitter(ke)
    scene.add("light", "light", light_quad(center, target, size))


def spherical(azimuth_deg: float, elevation_deg: float, distance: float, origin: Vec) -> Vec:
    """Point at `distance` from `origin` towards (azimuth from +x to +z, elevation), degrees."""
    az, el = math.radians(azimuth_deg), math.radians(elevation_deg)
    direction = np.array([math.cos(el) * math.cos(az), math.sin(el), math.cos(el) * math.sin(az)])
    return tuple(np.asarray(origin, float) + distance * direction)  # type: ignore[return-value]


def camera(origin: Vec, target: Vec, fov: float, width: int = 256, height: int = 256) -> dict:
    """[camera] table of the TOML sidecar (y up)."""
    return {
        "origin": [float(f"{x:.4g}") for x in origin],
        "target": [float(f"{x:.4g}") for x in target],
        "up": [0, 1, 0],
        "fov": fov,
        "width": width,
        "height": height,
    }


def render(spp: int = 16, photons: int = 200_000, k: int = 50) -> dict[str, int]:
    """[render] table of the TOML sidecar."""
    return {"spp": spp, "photons": photons, "k": k}


def fmt(value: object) -> str:
    """Format an MTL value: scalars and RGB triples with 5 significant digits."""
    if isinstance(value, tuple | list):
        return " ".join(f"{float(x):.5g}" for x in value)
    return f"{value:.5g}" if isinstance(value, float) else str(value)


def toml_value(value: object) -> str:
    """Format a TOML value (number or list of numbers)."""
    if isinstance(value, list):
        return "[" + ", ".join(toml_value(x) for x in value) + "]"
    return f"{value:.6g}" if isinstance(value, float) else str(value)


def write_scene(scene: Scene, out: Path, comment: str = "") -> Path:
    """Write `<name>.obj`, `<name>.mtl` and `<name>.toml` into `out` (each headed by the
    comment line); return the OBJ path."""
    out.mkdir(parents=True, exist_ok=True)
    comment = comment or f"dpm scene '{scene.name}'"
    mtl = [f"# {comment}"]
    for name, fields in scene.materials.items():
        mtl += ["", f"newmtl {name}"] + [f"{key} {fmt(value)}" for key, value in fields.items()]
    (out / f"{scene.name}.mtl").write_text("\n".join(mtl) + "\n")

    lines = [f"# {comment}"]
    lines.append(f"mtllib {scene.name}.mtl")
    offset = 1
    for part in scene.parts:
        lines += [f"o {part.name}", f"usemtl {part.material}"]
        lines += [f"v {x:.5g} {y:.5g} {z:.5g}" for x, y, z in part.vertices]
        lines += [f"f {a} {b} {c}" for a, b, c in (part.faces + offset).tolist()]
        offset += len(part.vertices)
    obj = out / f"{scene.name}.obj"
    obj.write_text("\n".join(lines) + "\n")

    toml = [f"# {comment}", "[camera]"]
    toml += [f"{key} = {toml_value(value)}" for key, value in scene.camera.items()]
    toml += ["", "[render]"] + [f"{key} = {toml_value(v)}" for key, v in scene.render.items()]
    (out / f"{scene.name}.toml").write_text("\n".join(toml) + "\n")
    return obj
