"""Wavefront OBJ and MTL text parsing into plain arrays and dictionaries.

We parse by hand instead of through trimesh because trimesh drops the MTL fields the scene
format needs (Ke, Ni, Tf, illum), merges vertices and reorders faces, and cannot point at the
offending line of a malformed file.
"""

from __future__ import annotations

import math
import re
import warnings
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from dpm.errors import InputError

# Statements that carry nothing dpm renders (normals, grouping, smoothing, lines, points).
_OBJ_IGNORED = {"vn", "vp", "o", "g", "s", "l", "p", "mg"}
_MTL_IGNORED = {
    "Ns",
    "Ka",
    "d",
    "Tr",
    "Pr",
    "Pm",
    "Ps",
    "Pc",
    "Pcr",
    "aniso",
    "anisor",
    "sharpness",
}


@dataclass
class ObjMesh:
    """Triangles of one OBJ file: vertex positions, fan-triangulated faces and material names."""

    vertices: np.ndarray  # (V, 3) float64 positions as written
    faces: np.ndarray  # (T, 3) int64 zero-based vertex indices
    face_material: np.ndarray  # (T,) int32 index into material_names, -1 = no usemtl
    material_names: list[str] = field(default_factory=list)
    mtllibs: list[Path] = field(default_factory=list)
    texcoords: np.ndarray = field(default_factory=lambda: np.zeros((0, 2)))  # (N, 2) vt u, v
    face_texcoords: np.ndarray | None = None  # (T, 3) int64 indices into texcoords, -1: none


@dataclass
class MtlEntry:
    """The fields of one `newmtl` block that dpm reads; None where the file does not set them."""

    name: str
    kd: tuple[float, float, float] | None = None
    ks: tuple[float, float, float] | None = None
    ke: tuple[float, float, float] | None = None
    tf: tuple[float, float, float] | None = None
    ni: float | None = None
    illum: int | None = None
    map_kd: Path | None = None  # diffuse colour texture, multiplies Kd (the MTL convention)
    thin: bool = False  # a thin dielectric sheet (Ni, Tf): Mitsuba XML's thindielectric only


def _read_lines(path: Path) -> list[str]:
    if not path.is_file():
        raise InputError(f"{path}: file not found")
    try:
        return path.read_text(encoding="utf-8", errors="replace").splitlines()
    except OSError as exc:
        raise InputError(f"{path}: cannot read: {exc.strerror}") from None


def _statements(lines: list[str]) -> Iterator[tuple[int, list[str]]]:
    """(line number, words) of each non-empty line, comments removed."""
    for lineno, raw in enumerate(lines, start=1):
        words = raw.split("#", 1)[0].split()
        if words:
            yield lineno, words


def _floats(path: Path, lineno: int, words: list[str], counts: tuple[int, ...]) -> list[float]:
    if len(words) - 1 not in counts:
        want = " or ".join(str(c) for c in counts)
        raise InputError(f"{path}:{lineno}: '{words[0]}' needs {want} numbers, got {words[1:]}")
    try:
        return [float(w) for w in words[1:]]
    except ValueError:
        raise InputError(
            f"{path}:{lineno}: '{words[0]}' has a value that is not a number"
        ) from None


def _rgb(path: Path, lineno: int, words: list[str]) -> tuple[float, float, float]:
    values = _floats(path, lineno, words, (1, 3))
    rgb = (values[0],) * 3 if len(values) == 1 else tuple(values)
    if not all(math.isfinite(v) and v >= 0 for v in rgb):
        raise InputError(f"{path}:{lineno}: '{words[0]}' must be finite and non-negative")
    return rgb  # type: ignore[return-value]


def read_obj(path: Path) -> ObjMesh:
    """Parse an OBJ file into vertices (V,3), triangles (T,3) and per-triangle material names."""
    lines = _read_lines(path)
    plain = _read_plain(path, lines)
    return plain if plain is not None else _read_any(path, lines)


# A face line's vertices, each `v`, `v/t`, `v/t/n` or `v//n` (one form per file), one space
# apart: the forms `_read_plain` parses; negative (relative) indices go to `_read_any`.
_FACE_FORMS = {
    (1, False): re.compile(r"[0-9]+(?: [0-9]+)*"),
    (2, False): re.compile(r"[0-9]+/[0-9]+(?: [0-9]+/[0-9]+)*"),
    (3, False): re.compile(r"[0-9]+/[0-9]+/[0-9]+(?: [0-9]+/[0-9]+/[0-9]+)*"),
    (3, True): re.compile(r"[0-9]+//[0-9]+(?: [0-9]+//[0-9]+)*"),
}


def _read_plain(path: Path, lines: list[str]) -> ObjMesh | None:
    """The OBJ files exporters write (single spaces, `v x y z`, one face form), parsed with
    numpy's string functions in about a third of `_read_any`'s time (0.05 against 0.15 s for
    40k lines); None where any line is other, for `_read_any` to parse or name the line."""
    text = np.array(lines, dtype=np.dtypes.StringDType())
    key, _, rest = np.strings.partition(text, np.array(" ", dtype=text.dtype))
    known = np.isin(key, ["v", "vt", "f", "usemtl", "mtllib", *_OBJ_IGNORED])
    known |= np.strings.startswith(key, "#")
    empty = np.flatnonzero(key == "")
    known[empty] = np.strings.strip(rest[empty]) == ""  # " v 1 2 3" is not a blank line
    if not known.all():
        return None
    line_v, line_vt, line_f = (np.flatnonzero(key == k) for k in ("v", "vt", "f"))
    vertices = _plain_numbers(rest[line_v], (3,))
    texcoords = _plain_numbers(rest[line_vt], (2, 3))
    if vertices is None or texcoords is None or len(line_f) == 0:
        return None
    face = rest[line_f]
    corners = np.strings.count(face, " ") + 1  # (F,) vertices per face line
    joined = " ".join(face.tolist())
    fields = joined.count("/") // int(corners.sum()) + 1
    form = _FACE_FORMS.get((fields, "//" in joined))
    if form is None or corners.min() < 3 or form.fullmatch(joined) is None:
        return None
    numbers = np.fromstring(joined.replace("/", " "), dtype=np.int64, sep=" ")
    numbers = numbers.reshape(-1, fields - ("//" in joined))
    # Indices count from 1 among the statements before the face (a later vertex is an error).
    index = numbers[:, 0] - 1
    if index.min() < 0 or (index >= np.repeat(np.searchsorted(line_v, line_f), corners)).any():
        return None
    first = np.cumsum(corners) - corners  # (F,) each face line's first corner
    uv = np.full(len(index), -1, np.int64)
    if fields > 1 and "//" not in joined:  # no such vt: that face is untextured, as in _read_any
        uv = numbers[:, 1] - 1
        defined = np.repeat(np.searchsorted(line_vt, line_f), corners)
        whole = np.logical_and.reduceat((uv >= 0) & (uv < defined), first)
        uv = np.where(np.repeat(whole, corners), uv, -1)
    materials = _plain_materials(path, lines, key)
    if materials is None:
        return None
    names, current, mtllibs = materials
    # Fan triangulation (0, j, j + 1) of each face line, keeping the winding.
    triangles = corners - 2
    line = np.repeat(np.arange(len(line_f)), triangles)
    j = np.arange(len(line)) - np.repeat(np.cumsum(triangles) - triangles, triangles) + 1
    base = first[line]
    corner = np.stack([base, base + j, base + j + 1], axis=1)
    return ObjMesh(
        vertices=vertices,
        faces=index[corner],
        face_material=current[np.searchsorted(np.flatnonzero(key == "usemtl"), line_f)][line],
        material_names=names,
        mtllibs=mtllibs,
        texcoords=texcoords,
        face_texcoords=uv[corner],
    )


def _plain_numbers(rest: np.ndarray, counts: tuple[int, ...]) -> np.ndarray | None:
    """(N, counts[0]) float64 of N statements' numbers, each statement `counts` numbers one
    space apart (one count for all; beyond the first counts[0], dropped); None otherwise."""
    if len(rest) == 0:
        return np.zeros((0, counts[0]))
    spaces = np.strings.count(rest, " ")
    joined = " ".join(rest.tolist())
    if spaces.min() != spaces.max() or spaces[0] + 1 not in counts or "  " in joined:
        return None
    # Words one space apart exactly: a tab (not printable) or a space at either end of a line
    # would shift numbers across lines and still add up to the right count.
    ends = np.strings.startswith(rest, " ") | np.strings.endswith(rest, " ")
    if not joined.isprintable() or ends.any():
        return None
    try:  # a word that is not a number raises
        values = np.fromstring(joined, sep=" ")
    except ValueError:
        return None
    if len(values) != len(rest) * (spaces[0] + 1) or not np.isfinite(values).all():
        return None
    return values.reshape(len(rest), -1)[:, : counts[0]].copy()


def _plain_materials(
    path: Path, lines: list[str], key: np.ndarray
) -> tuple[list[str], np.ndarray, list[Path]] | None:
    """The material names in order of first use; (U + 1,) int32 the material from each usemtl
    on (-1 before the first); the mtllib paths. None where a usemtl or mtllib names nothing."""
    used, libraries = (
        [" ".join(lines[i].split("#", 1)[0].split()[1:]) for i in np.flatnonzero(key == k)]
        for k in ("usemtl", "mtllib")
    )
    if "" in used or "" in libraries:
        return None
    index = {name: i for i, name in enumerate(dict.fromkeys(used))}  # in order of first use
    current = [-1] + [index[name] for name in used]
    return list(index), np.asarray(current, np.int32), [path.parent / lib for lib in libraries]


def _read_any(path: Path, lines: list[str]) -> ObjMesh:
    """Any OBJ file dpm reads, statement by statement: the reference for `_read_plain`, and
    the one that names the line of an error."""
    vertices: list[list[float]] = []
    texcoords: list[list[float]] = []
    faces: list[tuple[int, int, int]] = []
    face_uv: list[tuple[int, int, int]] = []
    face_material: list[int] = []
    names: list[str] = []
    name_index: dict[str, int] = {}
    mtllibs: list[Path] = []
    current = -1
    for lineno, words in _statements(lines):
        key = words[0]
        if key == "v":
            # A fourth (w) or extra colour values are allowed by common exporters; keep x, y, z.
            if len(words) < 4:
                raise InputError(f"{path}:{lineno}: vertex needs 3 coordinates")
            try:
                vertex = [float(w) for w in words[1:4]]
            except ValueError:
                raise InputError(f"{path}:{lineno}: vertex coordinate is not a number") from None
            if not all(math.isfinite(x) for x in vertex):
                raise InputError(f"{path}:{lineno}: vertex coordinate is NaN or infinite")
            vertices.append(vertex)
        elif key == "vt":
            if len(words) < 2:
                raise InputError(f"{path}:{lineno}: 'vt' needs a texture coordinate")
            try:
                uv = [float(w) for w in words[1:3]] + [0.0] * (3 - len(words[:3]))
            except ValueError:
                raise InputError(f"{path}:{lineno}: texture coordinate is not a number") from None
            if not all(math.isfinite(x) for x in uv):
                raise InputError(f"{path}:{lineno}: texture coordinate is NaN or infinite")
            texcoords.append(uv)
        elif key == "f":
            if len(words) < 4:
                raise InputError(f"{path}:{lineno}: face needs at least 3 vertices")
            idx, uvs = [], []
            for w in words[1:]:
                parts = w.split("/")
                try:
                    i = int(parts[0])
                    t = int(parts[1]) if len(parts) > 1 and parts[1] else None
                except ValueError:
                    raise InputError(f"{path}:{lineno}: bad face vertex '{w}'") from None
                i = i - 1 if i > 0 else len(vertices) + i
                if i < 0 or i >= len(vertices):
                    raise InputError(f"{path}:{lineno}: face vertex '{w}' out of range")
                if t is not None:
                    t = t - 1 if t > 0 else len(texcoords) + t
                    if t < 0 or t >= len(texcoords):  # no such vt: an error only if textured
                        t = None
                idx.append(i)
                uvs.append(-1 if t is None else t)
            if -1 in uvs:
                uvs = [-1] * len(uvs)  # all or none: a face's texture needs its three corners
            for j in range(1, len(idx) - 1):  # fan triangulation, keeps the winding
                faces.append((idx[0], idx[j], idx[j + 1]))
                face_uv.append((uvs[0], uvs[j], uvs[j + 1]))
                face_material.append(current)
        elif key == "usemtl":
            if len(words) < 2:
                raise InputError(f"{path}:{lineno}: usemtl needs a material name")
            name = " ".join(words[1:])
            current = name_index.setdefault(name, len(names))
            if current == len(names):
                names.append(name)
        elif key == "mtllib":
            if len(words) < 2:
                raise InputError(f"{path}:{lineno}: mtllib needs a file name")
            mtllibs.append(path.parent / " ".join(words[1:]))
        elif key not in _OBJ_IGNORED:
            raise InputError(f"{path}:{lineno}: unsupported OBJ statement '{key}'")
    return ObjMesh(
        vertices=np.asarray(vertices, dtype=np.float64).reshape(-1, 3),
        faces=np.asarray(faces, dtype=np.int64).reshape(-1, 3),
        face_material=np.asarray(face_material, dtype=np.int32),
        material_names=names,
        mtllibs=mtllibs,
        texcoords=np.asarray(texcoords, dtype=np.float64).reshape(-1, 2),
        face_texcoords=np.asarray(face_uv, dtype=np.int64).reshape(-1, 3),
    )


def read_mtl(path: Path) -> dict[str, MtlEntry]:
    """Parse an MTL file into its materials by name, keeping only the fields dpm uses; one
    warning line per key it passes over (textures, shininess, ...: the first line named), and
    one for specular colours (Ks) on materials that are not mirrors (dpm's diffuse is
    Lambertian)."""
    entries: dict[str, MtlEntry] = {}
    entry: MtlEntry | None = None
    ignored: dict[str, int] = {}  # key -> the first line it is on
    for lineno, words in _statements(_read_lines(path)):
        key = words[0]
        if key == "newmtl":
            if len(words) < 2:
                raise InputError(f"{path}:{lineno}: newmtl needs a name")
            entry = MtlEntry(name=" ".join(words[1:]))
            entries[entry.name] = entry
            continue
        if key == "map_Kd" and entry is not None:
            if len(words) < 2:
                raise InputError(f"{path}:{lineno}: map_Kd needs a file name")
            if len(words) > 2:  # options (-s, -o, -bm, ...) come before the file name
                ignored.setdefault(f"map_Kd {' '.join(words[1:-1])}", lineno)
            entry.map_kd = path.parent / words[-1]
            continue
        if key in _MTL_IGNORED or key.startswith(("map_", "bump", "disp", "decal", "refl", "norm")):
            ignored.setdefault(key, lineno)
            continue
        if entry is None:
            raise InputError(f"{path}:{lineno}: '{key}' before any newmtl")
        if key in ("Kd", "Ks", "Ke", "Tf"):
            setattr(entry, key.lower(), _rgb(path, lineno, words))
        elif key == "Ni":
            (ni,) = _floats(path, lineno, words, (1,))
            if not (math.isfinite(ni) and ni > 0):
                raise InputError(f"{path}:{lineno}: Ni must be a positive number")
            entry.ni = ni
        elif key == "illum":
            (value,) = _floats(path, lineno, words, (1,))
            if value != int(value) or not 0 <= value <= 10:
                raise InputError(f"{path}:{lineno}: illum must be an integer 0..10")
            entry.illum = int(value)
        else:
            raise InputError(f"{path}:{lineno}: unsupported MTL statement '{key}'")
    for key, lineno in ignored.items():
        warnings.warn(f"{path}:{lineno}: MTL key '{key}' ignored", stacklevel=2)
    glossy = [e.name for e in entries.values() if e.ks is not None and e.illum not in (3, 5)]
    if glossy:
        names = ", ".join(glossy[:3]) + (", ..." if len(glossy) > 3 else "")
        warnings.warn(f"{path}: Ks ignored on {len(glossy)} non-mirror material(s) ({names}):"
                      " dpm's diffuse is Lambertian", stacklevel=2)  # fmt: skip
    return entries
