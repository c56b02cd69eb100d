"""Shared helpers: writing small scenes to a temporary folder."""

from __future__ import annotations

import os
from pathlib import Path

import pytest
from hypothesis import settings

# CI runs the same examples every time (a red CI must be reproducible); locally they vary.
settings.register_profile("ci", derandomize=True)
if os.environ.get("CI"):
    settings.load_profile("ci")

# A unit floor with a small downward-facing light above it.
FLOOR_AND_LIGHT_OBJ = """\
mtllib scene.mtl
v -1 0 -1
v 1 0 -1
v 1 0 1
v -1 0 1
v -0.1 1 -0.1
v 0.1 1 -0.1
v 0.1 1 0.1
v -0.1 1 0.1
usemtl floor
f 1 4 3 2
usemtl light
f 5 6 7 8
"""
FLOOR_AND_LIGHT_MTL = """\
newmtl floor
Kd 0.5 0.5 0.5
newmtl light
Ke 10 10 10
"""


def write_scene(
    folder: Path,
    obj: str = FLOOR_AND_LIGHT_OBJ,
    mtl: str | None = FLOOR_AND_LIGHT_MTL,
    toml: str | None = None,
    stem: str = "scene",
) -> Path:
    """Write stem.obj (+ scene.mtl, + stem.toml) into folder and return the .obj path."""
    (folder / f"{stem}.obj").write_text(obj)
    if mtl is not None:
        (folder / "scene.mtl").write_text(mtl)
    if toml is not None:
        (folder / f"{stem}.toml").write_text(toml)
    return folder / f"{stem}.obj"


@pytest.fixture
def scene_path(tmp_path: Path) -> Path:
    """A valid floor-and-light scene on disk."""
    return write_scene(tmp_path)


WATER, WATER_LE = 1.33, 10.0  # the water's ior, the lights' radiance


def water_between_lights(folder: Path) -> Path:
    """A water surface (one sheet, ior 1.33) between a red light above and a green one below,
    both larger than anything the camera's reflected or refracted rays can miss."""
    f, h = 50, 3
    obj = f"""mtllib scene.mtl
v {-f} 0 {-f}
v {f} 0 {-f}
v {f} 0 {f}
v {-f} 0 {f}
v {-f} {h} {-f}
v {f} {h} {-f}
v {f} {h} {f}
v {-f} {h} {f}
v {-f} {-h} {-f}
v {f} {-h} {-f}
v {f} {-h} {f}
v {-f} {-h} {f}
usemtl water
f 1 4 3 2
usemtl above
f 5 6 7 8
usemtl below
f 9 12 11 10
"""
    le = WATER_LE
    mtl = (
        f"newmtl water\nillum 7\nNi {WATER}\nnewmtl above\nKe {le} 0 0\nnewmtl below\nKe 0 {le} 0\n"
    )
    toml = "[camera]\norigin = [0, 1, 2]\ntarget = [0, 0, 0]\nfov = 1\nwidth = 16\nheight = 16\n"
    return write_scene(folder, obj, mtl, toml)
