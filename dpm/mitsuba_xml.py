"""Reading the subset of Mitsuba 3's XML scene format that dpm can render.

What is read (anything else is a one-line InputError naming the element, except the few
settings dpm chooses itself, which get one warning line each):
- `<default name value>` and `$name` in attribute values;
- shapes `obj`, `ply` (meshes; an OBJ's own materials are ignored, as in Mitsuba),
  `rectangle` ([-1, 1]² at z = 0, normal +z), `cube` ([-1, 1]³), `sphere` (`center`,
  `radius`; tessellated into SPHERE_SEGMENTS × SPHERE_RINGS quads, flat-shaded: Mitsuba's
  sphere is exact), each with `to_world` (`matrix`, `translate`, `scale`, `rotate`, `lookat`)
  and `flip_normals`;
- bsdfs `diffuse` (`reflectance`), `conductor` and `roughconductor`-free `conductor` as a
  perfect mirror (`specular_reflectance`), `dielectric` and `thindielectric` (`int_ior`,
  `ext_ior` = 1, `specular_transmittance`), `twosided` around one of those, by `id` and `<ref>`;
- `area` emitters (`radiance`) on shapes: one-sided, from the side the normal points to;
- the `perspective` sensor (`fov`, `fov_axis` x or y, `to_world`) and its `hdrfilm`'s width
  and height; its sampler, reconstruction filter and the integrator are dpm's own choice.
Values: `float`, `integer`, `boolean`, `string`, `rgb`, `point`, `vector` (no spectra, no
textures). A shape without a bsdf is diffuse with reflectance 0.5, as in Mitsuba.
"""

from __future__ import annotations

import math
import re
import warnings
import xml.etree.ElementTree as ET
from dataclasses import replace
from pathlib import Path

import numpy as np

from dpm.camera import make_camera
from dpm.errors import InputError
from dpm.obj import MtlEntry, read_obj
from dpm.scene import Scene, build_scene, material_table

SPHERE_SEGMENTS, SPHERE_RINGS = 128, 64  # a sphere's tessellation (longitude, latitude)
DEFAULT_REFLECTANCE = 0.5  # Mitsuba's diffuse default
DEFAULT_IOR = 1.5046  # Mitsuba's dielectric int_ior default (BK7)
FILM_SIZE = (768, 576)  # Mitsuba's hdrfilm default width and height
IGNORED = {"sampler", "rfilter", "integrator"}  # dpm's own choices: one warning line each
IORS = {
    "vacuum": 1.0,
    "air": 1.000277,
    "water": 1.3330,
    "ethanol": 1.361,
    "fused quartz": 1.458,
    "acrylic glass": 1.49,
    "polypropylene": 1.49,
    "bk7": 1.5046,
    "sodium chloride": 1.544,
    "diamond": 2.419,
}  # fmt: skip  (Mitsuba's named indices of refraction)


class _Reader:
    """One XML file's elements turned into triangles, materials and a camera."""

    def __init__(self, path: Path) -> None:
        self.path = path
        self.defaults: dict[str, str] = {}
        self.bsdfs: dict[str, MtlEntry] = {}
        self.triangles: list[np.ndarray] = []  # per shape (T, 3, 3) float64
        self.materials: list[MtlEntry] = []  # per shape
        self.camera = None
        self.unnamed = 0  # bsdfs without an id so far

    def fail(self, element: ET.Element, message: str) -> InputError:
        """An InputError naming the file and the element."""
        what = element.tag + (f' type="{element.get("type")}"' if element.get("type") else "")
        return InputError(f"{self.path}: <{what}>: {message}")

    def attr(self, element: ET.Element, name: str, default: str | None = None) -> str | None:
        """An attribute with `$name` replaced by the <default> values."""
        value = element.get(name, default)
        if value is None:
            return None

        def substitute(match: re.Match) -> str:
            if match.group(1) not in self.defaults:
                raise self.fail(element, f"${match.group(1)} has no <default>")
            return self.defaults[match.group(1)]

        return re.sub(r"\$(\w+)", substitute, value)

    def properties(self, element: ET.Element) -> dict[str, object]:
        """name -> value of the element's value children (float, rgb, ...)."""
        out: dict[str, object] = {}
        for child in element:
            if child.tag not in ("float", "integer", "boolean", "string", "rgb", "point",
                                 "vector"):  # fmt: skip
                continue
            name, value = self.attr(child, "name"), self.attr(child, "value")
            if name is None:
                raise self.fail(child, "needs a name")
            try:
                if child.tag == "float":
                    out[name] = float(value)
                elif child.tag == "integer":
                    out[name] = int(value)
                elif child.tag == "boolean":
                    out[name] = value.strip().lower() == "true"
                elif child.tag == "string":
                    out[name] = value
                elif value is not None:  # rgb, point, vector: "x y z" or "x, y, z"
                    numbers = [float(v) for v in re.split(r"[,\s]+", value.strip())]
                    out[name] = tuple(numbers * 3 if len(numbers) == 1 else numbers)
                else:
                    out[name] = tuple(float(self.attr(child, k, "0")) for k in "xyz")
            except (TypeError, ValueError):
                raise self.fail(child, f"'{name}' has a bad value {value!r}") from None
            if child.tag in ("rgb", "point", "vector") and len(out[name]) != 3:
                raise self.fail(child, f"'{name}' needs 3 numbers")
        return out

    def transform(self, element: ET.Element | None) -> np.ndarray:
        """(4, 4) float64 matrix of a <transform>'s operations, applied in order."""
        m = np.eye(4)
        for op in [] if element is None else list(element):
            t = np.eye(4)
            xyz = [float(self.attr(op, k, d)) for k, d in (("x", "0"), ("y", "0"), ("z", "0"))]
            value = self.attr(op, "value")
            numbers = [float(v) for v in re.split(r"[,\s]+", value.strip())] if value else None
            if op.tag == "matrix":
                if not numbers or len(numbers) != 16:
                    raise self.fail(op, "needs 16 numbers")
                t = np.array(numbers).reshape(4, 4)
            elif op.tag == "translate":
                t[:3, 3] = numbers if numbers else xyz
            elif op.tag == "scale":
                if numbers:
                    xyz = numbers * 3 if len(numbers) == 1 else numbers
                else:
                    xyz = [float(self.attr(op, k, "1")) for k in "xyz"]
                t[:3, :3] = np.diag(xyz)
            elif op.tag == "rotate":
                axis = np.array(numbers if numbers else xyz, float)
                angle = math.radians(float(self.attr(op, "angle", "0")))
                if not np.linalg.norm(axis) > 0:
                    raise self.fail(op, "needs a non-zero axis")
                x, y, z = axis / np.linalg.norm(axis)
                c, s = math.cos(angle), math.sin(angle)
                t[:3, :3] = [
                    [c + x * x * (1 - c), x * y * (1 - c) - z * s, x * z * (1 - c) + y * s],
                    [y * x * (1 - c) + z * s, c + y * y * (1 - c), y * z * (1 - c) - x * s],
                    [z * x * (1 - c) - y * s, z * y * (1 - c) + x * s, c + z * z * (1 - c)],
                ]
            elif op.tag == "lookat":
                origin, target, up = (self.vector(op, k) for k in ("origin", "target", "up"))
                forward = target - origin
                left = np.cross(up, forward)
                if not (np.linalg.norm(forward) > 0 and np.linalg.norm(left) > 0):
                    raise self.fail(op, "origin, target and up must span a frame")
                forward /= np.linalg.norm(forward)
                left /= np.linalg.norm(left)
                t[:3, 0], t[:3, 1], t[:3, 2] = left, np.cross(forward, left), forward
                t[:3, 3] = origin
            else:
                raise self.fail(op, "unsupported transform operation")
            m = t @ m
        return m

    def vector(self, element: ET.Element, name: str) -> np.ndarray:
        """(3,) float64 of an attribute "x, y, z"."""
        value = self.attr(element, name, "0, 1, 0" if name == "up" else None)
        try:
            numbers = [float(v) for v in re.split(r"[,\s]+", value.strip())]
        except (AttributeError, ValueError):
            raise self.fail(element, f'needs {name}="x, y, z"') from None
        if len(numbers) != 3:
            raise self.fail(element, f"{name} needs 3 numbers")
        return np.array(numbers, float)

    def bsdf(self, element: ET.Element) -> MtlEntry:
        """The MTL entry (dpm's material fields) of a <bsdf> (or a <ref> to one)."""
        if element.tag == "ref":
            ref = self.attr(element, "id")
            if ref not in self.bsdfs:
                raise self.fail(element, f"no bsdf with id '{ref}' before it")
            return self.bsdfs[ref]
        kind, p = self.attr(element, "type"), self.properties(element)
        name = self.attr(element, "id")
        if name is None:
            self.unnamed += 1
            name = f"bsdf-{self.unnamed}"
        for child in element:
            if child.tag in ("texture", "spectrum"):
                raise self.fail(child, "textures and spectra are not supported (use rgb)")
        if kind == "twosided":
            inner = [c for c in element if c.tag in ("bsdf", "ref")]
            if len(inner) != 1:
                raise self.fail(element, "needs one nested bsdf")
            # dpm's diffuse and mirror are two-sided already; the outer id names the material
            return replace(self.bsdf(inner[0]), name=name)
        if kind == "diffuse":
            return MtlEntry(name, kd=p.get("reflectance", (DEFAULT_REFLECTANCE,) * 3))
        if kind == "conductor":
            return MtlEntry(name, ks=p.get("specular_reflectance", (1.0,) * 3), illum=3)
        if kind in ("dielectric", "thindielectric"):
            ext = self.ior(element, p.get("ext_ior", 1.0))
            ior = self.ior(element, p.get("int_ior", DEFAULT_IOR))
            if abs(ext - 1.0) > 1e-3:
                raise self.fail(element, "only ext_ior = 1 (air outside) is supported")
            tf = p.get("specular_transmittance", (1.0,) * 3)
            return MtlEntry(name, ni=float(ior), tf=tf, illum=7, thin=kind == "thindielectric")
        raise self.fail(
            element, "unsupported bsdf (diffuse, conductor, dielectric, thindielectric, twosided)"
        )

    def ior(self, element: ET.Element, value: object) -> float:
        """An index of refraction: a number or one of Mitsuba's names (IORS)."""
        if isinstance(value, str):
            if value.lower() not in IORS:
                raise self.fail(element, f"unknown index of refraction '{value}'")
            return IORS[value.lower()]
        return float(value)

    def mesh(self, element: ET.Element, kind: str, p: dict) -> tuple[np.ndarray, np.ndarray]:
        """(vertices (V, 3) float64, faces (F, 3)) of a shape in its own space."""
        if kind in ("obj", "ply"):
            filename = p.get("filename")
            if not isinstance(filename, str):
                raise self.fail(element, "needs a filename")
            file = self.path.parent / filename
            if kind == "obj":
                mesh = read_obj(file)  # its usemtl and mtllib are passed over
                return mesh.vertices, mesh.faces
            return read_ply(file)
        if kind == "rectangle":
            v = [(-1, -1, 0), (1, -1, 0), (1, 1, 0), (-1, 1, 0)]
            return np.array(v, float), np.array([(0, 1, 2), (0, 2, 3)])
        if kind == "cube":
            v = np.array([(x, y, z) for x in (-1, 1) for y in (-1, 1) for z in (-1, 1)], float)
            quads = [
                (0, 1, 3, 2),
                (4, 6, 7, 5),
                (0, 4, 5, 1),
                (2, 3, 7, 6),
                (0, 2, 6, 4),
                (1, 5, 7, 3),
            ]  # fmt: skip  (-x, +x, -y, +y, -z, +z faces, outwards)
            return v, np.array([f for a, b, c, d in quads for f in ((a, b, c), (a, c, d))])
        if kind == "sphere":
            return sphere(np.array(p.get("center", (0.0, 0.0, 0.0))), float(p.get("radius", 1.0)))
        raise self.fail(element, "unsupported shape (obj, ply, rectangle, cube, sphere)")

    def shape(self, element: ET.Element) -> None:
        """Add a <shape>'s triangles (world space, front = the normal's side) and material."""
        kind, p = self.attr(element, "type"), self.properties(element)
        vertices, faces = self.mesh(element, kind, p)
        transforms = [c for c in element if c.tag == "transform"]
        m = self.transform(transforms[0] if transforms else None)
        world = vertices @ m[:3, :3].T + m[:3, 3]
        if (np.linalg.det(m[:3, :3]) < 0) != bool(p.get("flip_normals", False)):
            faces = faces[:, ::-1]  # a mirroring transform or flip_normals turns the front
        material = MtlEntry(f"shape{len(self.materials)}", kd=(DEFAULT_REFLECTANCE,) * 3)
        for child in element:
            if child.tag in ("bsdf", "ref"):
                material = self.bsdf(child)
            elif child.tag == "emitter":
                if self.attr(child, "type") != "area":
                    raise self.fail(child, "only area emitters on shapes are supported")
                radiance = self.properties(child).get("radiance")
                if not isinstance(radiance, tuple):
                    raise self.fail(child, "needs an rgb (or float) radiance")
                material = MtlEntry(
                    f"{material.name}-emitter{len(self.materials)}", kd=material.kd or (0.0,) * 3,
                    ks=material.ks, ke=radiance, tf=material.tf, ni=material.ni,
                    illum=material.illum,
                )  # fmt: skip
            elif child.tag not in ("transform", "float", "integer", "boolean", "string", "rgb",
                                   "point", "vector"):  # fmt: skip
                raise self.fail(child, "not supported inside a shape")
        self.triangles.append(world[faces])
        self.materials.append(material)

    def sensor(self, element: ET.Element) -> None:
        """The camera of a perspective <sensor> and its film size."""
        if self.attr(element, "type") != "perspective":
            raise self.fail(element, "only the perspective sensor is supported")
        p = self.properties(element)
        width, height = FILM_SIZE
        for child in element:
            if child.tag == "film":
                film = self.properties(child)
                width, height = int(film.get("width", width)), int(film.get("height", height))
                for inner in child:
                    if inner.tag in IGNORED:
                        warnings.warn(f"{self.path}: <{inner.tag}> ignored", stacklevel=4)
            elif child.tag in IGNORED:
                warnings.warn(f"{self.path}: <{child.tag}> ignored (dpm chooses its own)",
                              stacklevel=4)  # fmt: skip
        transforms = [c for c in element if c.tag == "transform"]
        m = self.transform(transforms[0] if transforms else None)
        fov = float(p.get("fov", 45.0))
        axis = p.get("fov_axis", "x")
        if axis == "y":  # dpm's field of view is horizontal
            fov = math.degrees(2 * math.atan(math.tan(math.radians(fov) / 2) * width / height))
        elif axis != "x":
            raise self.fail(element, "fov_axis must be x or y")
        origin, forward, up = m[:3, 3], m[:3, 2], m[:3, 1]
        self.camera = make_camera(
            origin=list(origin), target=list(origin + forward), up=list(up), fov=fov,
            width=width, height=height, where=f"{self.path}: <sensor>",
        )  # fmt: skip

    def read(self) -> None:
        """Walk the <scene> element."""
        try:
            root = ET.parse(self.path).getroot()
        except FileNotFoundError:
            raise InputError(f"{self.path}: file not found") from None
        except ET.ParseError as exc:
            raise InputError(f"{self.path}: invalid XML: {exc}") from None
        if root.tag != "scene":
            raise InputError(f"{self.path}: the root element must be <scene>, not <{root.tag}>")
        for element in root:
            if element.tag == "default":
                name = element.get("name")
                if name is None or element.get("value") is None:
                    raise self.fail(element, "needs a name and a value")
                self.defaults.setdefault(name, element.get("value"))
            elif element.tag == "bsdf":
                entry = self.bsdf(element)
                self.bsdfs[self.attr(element, "id") or entry.name] = entry
            elif element.tag == "shape":
                self.shape(element)
            elif element.tag == "sensor":
                self.sensor(element)
            elif element.tag in IGNORED:
                warnings.warn(f"{self.path}: <{element.tag}> ignored (dpm chooses its own)",
                              stacklevel=3)  # fmt: skip
            else:
                raise self.fail(element, "not supported")


def sphere(center: np.ndarray, radius: float) -> tuple[np.ndarray, np.ndarray]:
    """(vertices, faces) of a UV sphere, counter-clockwise seen from outside."""
    theta = np.linspace(0.0, math.pi, SPHERE_RINGS + 1)[1:-1]
    phi = np.linspace(0.0, 2 * math.pi, SPHERE_SEGMENTS, endpoint=False)
    t, f = np.meshgrid(theta, phi, indexing="ij")
    ring = np.stack([np.sin(t) * np.cos(f), np.cos(t), np.sin(t) * np.sin(f)], -1).reshape(-1, 3)
    vertices = np.concatenate([[(0, 1, 0)], ring, [(0, -1, 0)]]) * radius + center
    faces = []
    n, last = SPHERE_SEGMENTS, len(vertices) - 1
    for j in range(n):
        k = (j + 1) % n
        faces.append((0, 1 + k, 1 + j))  # the cap at +y
        for r in range(SPHERE_RINGS - 2):
            a, b = 1 + r * n + j, 1 + r * n + k
            faces += [(a, b, b + n), (a, b + n, a + n)]
        base = 1 + (SPHERE_RINGS - 2) * n
        faces.append((last, base + j, base + k))  # the cap at -y
    return vertices, np.array(faces)


def read_ply(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """(vertices (V, 3) float64, faces (F, 3)) of a PLY mesh (ASCII or binary; trimesh)."""
    import trimesh

    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        mesh = trimesh.load(path, file_type="ply", force="mesh", process=False)
    except Exception as exc:  # trimesh raises many kinds on a malformed file
        raise InputError(f"{path}: not a readable PLY mesh ({exc})") from None
    vertices = np.asarray(mesh.vertices, float)
    if not np.isfinite(vertices).all():
        raise InputError(f"{path}: a vertex coordinate is NaN or infinite")
    if len(mesh.faces) == 0:
        raise InputError(f"{path}: the mesh has no faces")
    return vertices, np.asarray(mesh.faces, np.int64)


def read_xml(path: str | Path) -> Scene:
    """The Scene of a Mitsuba 3 XML file (the subset in this module's docstring)."""
    reader = _Reader(Path(path))
    reader.read()
    if not reader.triangles:
        raise InputError(f"{path}: the scene has no shapes")
    names = [m.name for m in reader.materials]
    unique = list(dict.fromkeys(names))
    library = {m.name: m for m in reader.materials}
    index = {name: i for i, name in enumerate(unique)}
    pairs = zip(reader.triangles, reader.materials, strict=True)
    face_material = np.concatenate([np.full(len(t), index[m.name]) for t, m in pairs])
    materials = material_table(unique, library, Path(path))
    camera = reader.camera
    return build_scene(Path(path), np.concatenate(reader.triangles), face_material, materials,
                       camera, {} if camera is not None else None)  # fmt: skip
