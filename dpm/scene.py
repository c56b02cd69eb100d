"""Scenes: loading OBJ + MTL + TOML sidecar into flat float32 arrays, with validation.

See docs/design.md "Scene format". Material kinds: DIFFUSE (two-sided Lambertian), MIRROR (two-sided
perfect mirror with reflectance Ks), DIELECTRIC (smooth, IOR Ni inside, air on the front side),
THIN (a thin dielectric sheet, air on both sides: Fresnel reflection with the bounces inside
summed, straight transmission; Mitsuba's `thindielectric`, read from XML scenes only).
Any material with non-zero Ke is also a one-sided Lambertian emitter (front face).
"""

from __future__ import annotations

import math
import tomllib
import warnings
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import NamedTuple

import numpy as np

from dpm.camera import Camera, framing_camera, make_camera
from dpm.errors import InputError
from dpm.obj import MtlEntry, read_mtl, read_obj
from dpm.options import sidecar_types
from dpm.textures import Textures, pack_textures

DIFFUSE, MIRROR, DIELECTRIC, THIN = 0, 1, 2, 3
KIND_NAMES = ("diffuse", "mirror", "dielectric", "thin dielectric")


@dataclass(frozen=True)
class Materials:
    """Material table, one row per material (struct of arrays)."""

    names: tuple[str, ...]
    kind: np.ndarray  # (M,) int32: DIFFUSE, MIRROR, DIELECTRIC or THIN
    albedo: np.ndarray  # (M, 3) float32 Lambertian reflectance Kd
    specular: np.ndarray  # (M, 3) float32 mirror reflectance Ks
    emission: np.ndarray  # (M, 3) float32 emitted radiance Ke (W m^-2 sr^-1)
    ior: np.ndarray  # (M,) float32 index of refraction inside a dielectric
    transmittance: np.ndarray  # (M, 3) float32 Tf, applied at every refraction
    textures: Textures | None = None  # diffuse colour textures (map_Kd), multiplying albedo


@dataclass(frozen=True)
class Emitters:
    """Emitting triangles and the distribution that samples them proportionally to power."""

    triangles: np.ndarray  # (E,) int32 scene triangle indices
    radiance: np.ndarray  # (E, 3) float32 emitted radiance Ke
    power: np.ndarray  # (E, 3) float64 emitted flux π·A·Ke (W)
    cdf: np.ndarray  # (E,) float64 cumulative probability by mean RGB power, last = 1

    @property
    def total_power(self) -> np.ndarray:
        """(3,) float64 flux of all emitters (W)."""
        return self.power.sum(axis=0)


class SceneArrays(NamedTuple):
    """The arrays of a Scene that Numba kernels read, per triangle and per material."""

    triangles: np.ndarray  # (T, 3, 3) float32 vertex positions
    normals: np.ndarray  # (T, 3) float32 unit front normals
    areas: np.ndarray  # (T,) float32
    material: np.ndarray  # (T,) int32
    kind: np.ndarray  # (M,) int32
    albedo: np.ndarray  # (M, 3) float32
    specular: np.ndarray  # (M, 3) float32
    emission: np.ndarray  # (M, 3) float32
    ior: np.ndarray  # (M,) float32
    transmittance: np.ndarray  # (M, 3) float32
    emitter_triangles: np.ndarray  # (E,) int32
    emitter_cdf: np.ndarray  # (E,) float64
    emitter_pdf: np.ndarray  # (T,) float64 area density of light sampling (0: not an emitter)
    uvs: np.ndarray  # (T, 3, 2) float32 texture coordinates of the corners ((1, 3, 2): none)
    texture: np.ndarray  # (M,) int32 texture of each material, -1: none
    texels: np.ndarray  # (N, 3) float32 linear RGB of every texture
    texture_dims: np.ndarray  # (K, 3) int64 first texel, width, height


@dataclass(frozen=True)
class Scene:
    """A loaded scene: flat triangle arrays, materials, emitters and camera."""

    path: Path
    triangles: np.ndarray  # (T, 3, 3) float32 vertex positions, counter-clockwise = front
    normals: np.ndarray  # (T, 3) float32 unit geometric (front) normals
    areas: np.ndarray  # (T,) float32 triangle areas
    material: np.ndarray  # (T,) int32 index into `materials`
    materials: Materials
    emitters: Emitters
    camera: Camera
    render_defaults: dict[str, object] = field(default_factory=dict)
    uvs: np.ndarray | None = None  # (T, 3, 2) float32 texture coordinates (None: no textures)

    @cached_property
    def bounds(self) -> np.ndarray:
        """(2, 3) float64 axis-aligned bounding box: minimum and maximum corner."""
        flat = self.triangles.reshape(-1, 3)
        return np.stack([flat.min(axis=0), flat.max(axis=0)]).astype(np.float64)

    def kernel_arrays(self) -> SceneArrays:
        """The scene as a tuple of plain arrays for Numba kernels."""
        m, e = self.materials, self.emitters
        tex = m.textures or Textures(
            np.full(len(m.kind), -1, np.int32), np.zeros((1, 3), np.float32),
            np.zeros((1, 3), np.int64),
        )  # fmt: skip
        # Without textures the kernels never read uvs: one placeholder row, not (T, 3, 2) zeros
        # allocated for every kernel call.
        uvs = self.uvs if self.uvs is not None else np.zeros((1, 3, 2), np.float32)
        return SceneArrays(
            self.triangles,
            self.normals,
            self.areas,
            self.material,
            m.kind,
            m.albedo,
            m.specular,
            m.emission,
            m.ior,
            m.transmittance,
            e.triangles,
            e.cdf,
            self.emitter_pdf,
            uvs,
            tex.index,
            tex.texels,
            tex.dims,
        )

    @cached_property
    def emitter_pdf(self) -> np.ndarray:
        """(T,) float64 density per unit area (m⁻²) with which light sampling picks each point."""
        e = self.emitters
        pdf = np.zeros(len(self.triangles))
        pick = np.diff(e.cdf, prepend=0.0)
        pdf[e.triangles] = pick / self.areas[e.triangles].astype(np.float64)
        return pdf

    @cached_property
    def all_diffuse(self) -> bool:
        """Whether every triangle is diffuse (no mirror or glass: no light path has a
        caustic, and paths need no specular chains)."""
        return bool(np.all(self.materials.kind[np.unique(self.material)] == DIFFUSE))

    @cached_property
    def specular_sphere(self) -> np.ndarray:
        """(4,) float64 centre and radius of a sphere holding every mirror and glass triangle
        (radius −1: none). Cached: guided photon emission reads it every pass."""
        specular = self.materials.kind[self.material] != DIFFUSE
        if not specular.any():
            return np.array([0.0, 0.0, 0.0, -1.0])
        v = self.triangles[specular].reshape(-1, 3).astype(np.float64)
        centre = (v.min(axis=0) + v.max(axis=0)) / 2
        return np.append(centre, np.sqrt(((v - centre) ** 2).sum(axis=1).max()))

    @property
    def extent(self) -> float:
        """Length of the bounding box diagonal (scene units)."""
        lo, hi = self.bounds
        return float(np.linalg.norm(hi - lo))


def material_table(names: list[str], library: dict[str, MtlEntry], obj_path: Path) -> Materials:
    """The material table of `names` ("": the default diffuse) from MTL entries."""
    kinds, albedo, specular, emission, ior, tf, maps = [], [], [], [], [], [], []
    for name in names:
        if name == "":
            entry = MtlEntry(name="")  # faces before any usemtl: default diffuse
        elif name in library:
            entry = library[name]
        else:
            raise InputError(f"{obj_path}: material '{name}' is not defined in any mtllib")
        ke = entry.ke or (0.0, 0.0, 0.0)
        emissive = any(v > 0 for v in ke)
        if entry.thin:
            kind = THIN
        elif entry.illum in (3, 5):
            kind = MIRROR
        elif entry.illum in (4, 6, 7):
            kind = DIELECTRIC
        else:
            kind = DIFFUSE
        kinds.append(kind)
        albedo.append(entry.kd or ((0.0,) * 3 if emissive else (0.8,) * 3))
        specular.append(entry.ks or (1.0,) * 3)
        emission.append(ke)
        ior.append(entry.ni if entry.ni is not None else 1.5)
        tf.append(entry.tf or (1.0,) * 3)
        maps.append(entry.map_kd if kind == DIFFUSE else None)
    f32 = np.float32
    return Materials(
        names=tuple(names),
        kind=np.asarray(kinds, dtype=np.int32),
        albedo=np.asarray(albedo, dtype=f32).reshape(-1, 3),
        specular=np.asarray(specular, dtype=f32).reshape(-1, 3),
        emission=np.asarray(emission, dtype=f32).reshape(-1, 3),
        ior=np.asarray(ior, dtype=f32),
        transmittance=np.asarray(tf, dtype=f32).reshape(-1, 3),
        textures=pack_textures(maps),
    )


def _emitters(
    triangles: np.ndarray, areas: np.ndarray, material: np.ndarray, materials: Materials
) -> Emitters:
    radiance = materials.emission[material]
    ids = np.flatnonzero(radiance.max(axis=1) > 0).astype(np.int32)
    power = math.pi * areas[ids, None].astype(np.float64) * radiance[ids].astype(np.float64)
    weight = power.mean(axis=1)
    cdf = np.cumsum(weight)
    if len(cdf):
        cdf /= cdf[-1]
        cdf[-1] = 1.0
    return Emitters(triangles=ids, radiance=radiance[ids], power=power, cdf=cdf)


def _read_sidecar(path: Path, lo: np.ndarray, hi: np.ndarray) -> tuple[Camera, dict[str, object]]:
    if not path.exists():
        return framing_camera(lo, hi), {}
    try:
        data = tomllib.loads(path.read_text(encoding="utf-8"))
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as exc:
        raise InputError(f"{path}: invalid TOML: {exc}") from None
    unknown = set(data) - {"camera", "render"}
    if unknown:
        raise InputError(f"{path}: unknown section(s) {sorted(unknown)}")
    camera = framing_camera(lo, hi)
    if "camera" in data:
        cam = data["camera"]
        allowed = {"origin", "target", "up", "fov", "width", "height"}
        if not isinstance(cam, dict) or set(cam) - allowed:
            bad = sorted(set(cam) - allowed) if isinstance(cam, dict) else cam
            raise InputError(f"{path}: [camera] has unknown key(s) {bad}")
        if "origin" not in cam or "target" not in cam:
            raise InputError(f"{path}: [camera] needs 'origin' and 'target'")
        camera = make_camera(**cam, where=f"{path}: [camera]")
    render = data.get("render", {})
    if not isinstance(render, dict):
        raise InputError(f"{path}: [render] must be a table")
    kinds = sidecar_types()  # the keys dpm-render's options allow, with their types
    for key, value in render.items():
        want = kinds.get(key)
        if want is None:
            raise InputError(f"{path}: [render] has unknown key '{key}'")
        ok = isinstance(value, want) and not isinstance(value, bool)
        if want is float:
            ok = isinstance(value, int | float) and not isinstance(value, bool)
        if not ok:
            raise InputError(f"{path}: [render] '{key}' must be of type {want.__name__}")
    return camera, dict(render)


def _valid_triangles(
    tri: np.ndarray, tri64: np.ndarray
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """(keep (T,) bool, cross (T, 3), twice the area (T,)) for float32 triangles (T, 3, 3)."""
    finite = np.all(np.isfinite(tri), axis=(1, 2)) & np.all(np.abs(tri64) < 1e30, axis=(1, 2))
    t64 = np.where(finite[:, None, None], tri.astype(np.float64), 0.0)
    cross = np.cross(t64[:, 1] - t64[:, 0], t64[:, 2] - t64[:, 0])
    double_area = np.linalg.norm(cross, axis=1)
    edges = t64 - np.roll(t64, 1, axis=1)
    longest2 = np.max(np.sum(edges * edges, axis=2), axis=1)
    # Slivers whose smallest angle is below ~1e-9 rad have no meaningful normal: drop them too.
    return finite & (double_area > 1e-9 * longest2), cross, double_area


def _light_reaches_geometry(tri: np.ndarray, normals: np.ndarray, emitting: np.ndarray) -> bool:
    """Whether some vertex lies in front of some emitter (light can reach nothing otherwise)."""
    verts = tri.reshape(-1, 3).astype(np.float64)  # shared vertices repeat: no matter for any()
    scale = max(float(np.abs(verts).max()), 1e-30)
    for chunk in np.array_split(emitting, max(1, len(emitting) * len(verts) // 2**22)):
        n = normals[chunk].astype(np.float64)  # (C, 3)
        offset = np.einsum("ij,ij->i", n, tri[chunk, 0].astype(np.float64))
        if np.any(verts @ n.T - offset > 1e-6 * scale):
            return True
    return False


def load_scene(path: str | Path) -> Scene:
    """Load `scene.obj`, its MTL libraries and the optional `scene.toml` sidecar beside it
    (`dpm.load_file` also reads Mitsuba 3 XML scenes)."""
    path = Path(path)
    if path.suffix.lower() != ".obj":
        raise InputError(f"{path}: expected a .obj scene file")
    mesh = read_obj(path)
    library: dict[str, MtlEntry] = {}
    for lib in mesh.mtllibs:
        library.update(read_mtl(lib))
    names = list(mesh.material_names)
    face_material = mesh.face_material.copy()
    if np.any(face_material < 0):  # faces before the first usemtl get the default material
        face_material[face_material < 0] = len(names)
        names.append("")
    if len(mesh.faces) == 0:
        raise InputError(f"{path}: the scene has no faces")
    materials = material_table(names, library, path)
    uvs = None
    if materials.textures is not None:
        textured = materials.textures.index[face_material] >= 0
        missing = textured & np.any(mesh.face_texcoords < 0, axis=1)
        if missing.any():
            line = f"{np.count_nonzero(missing)} face(s) of a textured material"
            raise InputError(f"{path}: {line} have no texture coordinates (f v/vt ...)")
        corner = mesh.face_texcoords
        coords = mesh.texcoords if len(mesh.texcoords) else np.zeros((1, 2))
        uvs = np.where(corner[..., None] >= 0, coords[np.maximum(corner, 0)], 0.0)
    return build_scene(path, mesh.vertices[mesh.faces], face_material, materials, None, None, uvs)


def build_scene(
    path: Path,
    tri64: np.ndarray,
    face_material: np.ndarray,
    materials: Materials,
    camera: Camera | None,
    render: dict[str, object] | None,
    uvs: np.ndarray | None = None,
) -> Scene:
    """A validated Scene from float64 triangles (T, 3, 3) (counter-clockwise = front), their
    material indices (T,) into `materials`, and a camera and [render] defaults (None: those of
    the TOML sidecar beside `path`, or a camera framing the scene); with textured materials,
    the texture coordinates of the triangles' corners uvs (T, 3, 2)."""
    with np.errstate(invalid="ignore", over="ignore"):  # beyond float32: dropped below
        tri = tri64.astype(np.float32)
        keep, cross, double_area = _valid_triangles(tri, tri64)
    if not keep.all():
        warnings.warn(
            f"{path}: dropped {np.count_nonzero(~keep)} degenerate or out-of-range triangle(s)",
            stacklevel=3,
        )
    if not keep.any():
        raise InputError(f"{path}: no valid triangles left (all degenerate or out of range)")
    tri, cross, double_area = tri[keep], cross[keep], double_area[keep]
    material = np.asarray(face_material)[keep].astype(np.int32)
    normals = (cross / double_area[:, None]).astype(np.float32)
    areas = (0.5 * double_area).astype(np.float32)

    emitters = _emitters(tri, areas, material, materials)
    if len(emitters.triangles) == 0:
        raise InputError(f"{path}: the scene has no emitter (no material with non-zero Ke)")
    if not _light_reaches_geometry(tri, normals, emitters.triangles):
        raise InputError(
            f"{path}: every light faces away from the geometry (emitters radiate from the"
            " counter-clockwise front face only)"
        )
    flat = tri.reshape(-1, 3).astype(np.float64)
    if camera is None:
        camera, render = _read_sidecar(path.with_suffix(".toml"), flat.min(0), flat.max(0))
    return Scene(
        path=path,
        triangles=np.ascontiguousarray(tri),
        normals=normals,
        areas=areas,
        material=material,
        materials=materials,
        emitters=emitters,
        camera=camera,
        render_defaults=dict(render or {}),
        uvs=None if uvs is None else np.ascontiguousarray(uvs[keep], dtype=np.float32),
    )
