"""Scene loading: every material kind, defaults, emitters, camera sidecar."""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

from conftest import write_scene
from dpm import load_scene
from dpm.scene import DIELECTRIC, DIFFUSE, MIRROR

ALL_KINDS_OBJ = """\
mtllib scene.mtl
v 0 0 0
v 1 0 0
v 1 1 0
v 0 1 0
v 0 0 1
f 1 2 3
usemtl plain
f 1 2 3
usemtl red
f 1 2 3
usemtl mirror3
f 1 2 3
usemtl mirror5
f -5 -4 -3
usemtl glass4
f 1/1 2/2 3/3
usemtl glass6
f 1//1 2//2 3//3
usemtl wine7
f 1/1/1 2/2/2 3/3/3
usemtl lamp
f 1 2 3 4
usemtl lamp
f 1 2 5
"""
ALL_KINDS_MTL = """\
# every material kind the format knows
newmtl plain
newmtl red
Kd 0.7 0.1 0.1
Ns 10
map_Ks ignored.png
newmtl mirror3
illum 3
newmtl mirror5
illum 5
Ks 0.9 0.8 0.5
newmtl glass4
illum 4
newmtl glass6
illum 6
Ni 1.33
newmtl wine7
illum 7
Ni 1.4
Tf 0.9 0.2 0.1
newmtl lamp
Ke 4 2 1
"""


def test_every_material_kind(tmp_path: Path) -> None:
    with pytest.warns(UserWarning) as caught:  # Ns and map_Ks: one line each
        scene = load_scene(write_scene(tmp_path, ALL_KINDS_OBJ, ALL_KINDS_MTL))
    assert sorted(str(w.message).split(": ", 1)[1] for w in caught) == [
        "MTL key 'Ns' ignored",
        "MTL key 'map_Ks' ignored",
    ]
    assert all(str(w.message).startswith(f"{tmp_path / 'scene.mtl'}:") for w in caught)
    m = scene.materials
    by_name = {name: i for i, name in enumerate(m.names)}
    assert len(scene.triangles) == 11  # the quad is split into two triangles
    assert scene.triangles.dtype == np.float32 and scene.triangles.shape == (11, 3, 3)
    # Faces before any usemtl get the default diffuse (Kd 0.8).
    default = scene.material[0]
    assert m.kind[default] == DIFFUSE and np.allclose(m.albedo[default], 0.8)
    assert np.allclose(m.albedo[by_name["plain"]], 0.8)
    assert np.allclose(m.albedo[by_name["red"]], [0.7, 0.1, 0.1])
    assert m.kind[by_name["mirror3"]] == MIRROR and np.allclose(m.specular[by_name["mirror3"]], 1)
    assert m.kind[by_name["mirror5"]] == MIRROR
    assert np.allclose(m.specular[by_name["mirror5"]], [0.9, 0.8, 0.5])
    for name, ior in (("glass4", 1.5), ("glass6", 1.33), ("wine7", 1.4)):
        assert m.kind[by_name[name]] == DIELECTRIC
        assert m.ior[by_name[name]] == pytest.approx(ior)
    assert np.allclose(m.transmittance[by_name["glass4"]], 1)
    assert np.allclose(m.transmittance[by_name["wine7"]], [0.9, 0.2, 0.1])
    lamp = by_name["lamp"]
    assert np.allclose(m.emission[lamp], [4, 2, 1]) and np.allclose(m.albedo[lamp], 0)
    assert m.kind[lamp] == DIFFUSE


def test_geometry_and_emitter_distribution(tmp_path: Path) -> None:
    scene = load_scene(write_scene(tmp_path, ALL_KINDS_OBJ, ALL_KINDS_MTL))
    # Counter-clockwise winding seen from +z gives the +z normal.
    np.testing.assert_allclose(scene.normals[0], [0, 0, 1], atol=1e-7)
    np.testing.assert_allclose(scene.areas[0], 0.5)
    e = scene.emitters
    assert len(e.triangles) == 3
    area = scene.areas[e.triangles].astype(np.float64)
    np.testing.assert_allclose(e.power, math.pi * area[:, None] * [4, 2, 1], rtol=1e-6)
    np.testing.assert_allclose(e.total_power, math.pi * area.sum() * np.array([4, 2, 1]))
    expected = np.cumsum(area) / area.sum()
    np.testing.assert_allclose(e.cdf, expected)


def test_camera_sidecar_and_render_defaults(tmp_path: Path) -> None:
    toml = """
[camera]
origin = [0, 1, 5]
target = [0, 1, 0]
fov = 30
width = 64
height = 32
[render]
spp = 4
photons = 1000
"""
    scene = load_scene(write_scene(tmp_path, toml=toml))
    cam = scene.camera
    assert (cam.width, cam.height, cam.fov) == (64, 32, 30.0)
    basis = cam.basis()
    np.testing.assert_allclose(basis[1], [0, 0, -1])
    np.testing.assert_allclose(basis[2], [math.tan(math.radians(15)), 0, 0])  # right = +x
    np.testing.assert_allclose(basis[3], [0, math.tan(math.radians(15)) / 2, 0])
    assert scene.render_defaults == {"spp": 4, "photons": 1000}


def test_default_camera_sees_the_whole_scene(scene_path: Path) -> None:
    scene = load_scene(scene_path)
    basis = scene.camera.basis()
    corners = np.array(np.meshgrid(*scene.bounds.T)).reshape(3, -1).T
    rel = corners - basis[0]
    depth = rel @ basis[1]
    assert np.all(depth > 0)
    x = rel @ basis[2] / np.sum(basis[2] ** 2) / depth
    y = rel @ basis[3] / np.sum(basis[3] ** 2) / depth
    assert np.all(np.abs(x) <= 1) and np.all(np.abs(y) <= 1)


def test_degenerate_and_out_of_range_triangles_are_dropped_with_a_warning(
    tmp_path: Path,
) -> None:
    obj = """\
mtllib scene.mtl
v -1 0 -1
v 1 0 -1
v 1 0 1
v 0 0 -1
v 1e300 0 0
v 2 0 -1
v -1 1 -1
v 1 1 1
v 1 1 -1
usemtl floor
f 1 3 2
f 1 2 6
f 1 4 2
f 1 5 2
usemtl light
f 7 9 8
"""
    with pytest.warns(UserWarning, match="dropped 3 degenerate or out-of-range"):
        scene = load_scene(write_scene(tmp_path, obj))
    assert len(scene.triangles) == 2
    assert np.all(np.isfinite(scene.triangles))


def test_specular_colour_on_a_diffuse_material_is_one_warning(tmp_path: Path) -> None:
    mtl = "newmtl floor\nKd 0.5 0.5 0.5\nKs 0.5 0.5 0.5\nillum 2\nnewmtl light\nKe 10 10 10\n"
    with pytest.warns(UserWarning, match=r"Ks ignored on 1 non-mirror material\(s\) \(floor\)"):
        load_scene(write_scene(tmp_path, mtl=mtl))
