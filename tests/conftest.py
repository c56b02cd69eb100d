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
