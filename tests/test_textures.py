"""Diffuse colour textures from MTL `map_Kd` with OBJ `vt`: parsing, decoding and rendering."""

from __future__ import annotations

import imageio.v3 as iio
import numpy as np
import pytest

from conftest import FLOOR_AND_LIGHT_OBJ, write_scene
from dpm import load_file
from dpm.cli import render_main
from dpm.errors import InputError
from dpm.obj import read_mtl, read_obj
from dpm.renderer import RenderOptions, render
from dpm.textures import srgb_to_linear

# The floor of conftest's scene with texture coordinates: u along x, v along z.
TEXTURED_OBJ = FLOOR_AND_LIGHT_OBJ.replace(
    "usemtl floor\nf 1 4 3 2",
    "vt 0 1\nvt 1 1\nvt 1 0\nvt 0 0\nusemtl floor\nf 1/1 4/4 3/3 2/2",
)
CAMERA = """\
[camera]
origin = [0, 3, 0]
up = [0, 0, 1]
target = [0, 0, 0]
fov = 60
"""


def textured_scene(folder, texture: np.ndarray, kd: str = "1 1 1"):
    """conftest's floor and light, the floor's colour Kd times the texture (H, W, 3) uint8."""
    iio.imwrite(folder / "floor.png", texture)
    mtl = f"newmtl floor\nKd {kd}\nmap_Kd floor.png\nnewmtl light\nKe 10 10 10\n"
    return write_scene(folder, TEXTURED_OBJ, mtl, CAMERA)


def test_obj_texture_coordinates_and_map_kd_are_read(tmp_path) -> None:
    mesh = read_obj(write_scene(tmp_path, TEXTURED_OBJ, None))
    assert mesh.texcoords.shape == (4, 2) and mesh.texcoords[2].tolist() == [1.0, 0.0]
    assert mesh.face_texcoords.tolist()[:2] == [[0, 3, 2], [0, 2, 1]]  # the fan of the quad
    assert (mesh.face_texcoords[2:] == -1).all()  # the light has none
    (tmp_path / "a.mtl").write_text("newmtl a\nKd 1 1 1\nmap_Kd -s 2 2 1 wood.png\n")
    with pytest.warns(UserWarning, match="map_Kd -s 2 2 1' ignored"):
        entry = read_mtl(tmp_path / "a.mtl")["a"]
    assert entry.map_kd == tmp_path / "wood.png"


def test_srgb_decoding() -> None:
    assert srgb_to_linear(np.array([0.0, 1.0]))[1] == 1.0
    assert np.isclose(srgb_to_linear(np.array(0.5)), 0.21404, atol=1e-5)
    assert np.isclose(srgb_to_linear(np.array(0.04045)), 0.04045 / 12.92)


def test_a_uniform_texture_renders_as_its_colour(tmp_path) -> None:
    """Kd 1 times a texture of one sRGB value equals Kd = that value decoded: the same image,
    bit for bit, with every method's paths (camera, shading vertices and photons)."""
    value = np.array([200, 120, 40], np.uint8)
    textured = load_file(textured_scene(tmp_path, np.broadcast_to(value, (4, 8, 3)).copy()))
    plain_dir = tmp_path / "plain"
    plain_dir.mkdir()
    kd = " ".join(f"{x:.9g}" for x in srgb_to_linear(value / 255.0).astype(np.float32))
    mtl = f"newmtl floor\nKd {kd}\nnewmtl light\nKe 10 10 10\n"
    plain = load_file(write_scene(plain_dir, TEXTURED_OBJ, mtl, CAMERA))
    assert np.array_equal(plain.materials.albedo[0], textured.materials.textures.texels[0])
    for method in ("pt", "sppm"):
        kw = dict(method=method, width=16, height=16, spp=2, photons=4000, progress=False)
        a = render(textured, RenderOptions(**kw)).image
        b = render(plain, RenderOptions(**kw)).image
        assert np.array_equal(a, b), method


def test_a_half_black_texture_darkens_half_the_floor(tmp_path) -> None:
    texture = np.full((16, 16, 3), 255, np.uint8)
    texture[:, :8] = 0  # u < 1/2 (x < 0) black
    scene = load_file(textured_scene(tmp_path, texture))
    image = render(scene, RenderOptions(method="pt", width=32, height=32, spp=8, progress=False))
    lum = image.image.mean(axis=2)
    # the camera looks down with +z towards the image's top: +x (u > 1/2) is on the right or
    # the left, whichever; the dark side holds only the bilinear seam and the lamp's back
    left, right = lum[8:24, 2:12].mean(), lum[8:24, 20:30].mean()
    assert max(left, right) > 20 * min(left, right)


def test_textured_faces_without_coordinates_and_missing_files_exit_2(tmp_path, capsys) -> None:
    iio.imwrite(tmp_path / "floor.png", np.zeros((2, 2, 3), np.uint8))
    mtl = "newmtl floor\nKd 1 1 1\nmap_Kd floor.png\nnewmtl light\nKe 10 10 10\n"
    no_vt = TEXTURED_OBJ.replace("f 1/1 4/4 3/3 2/2", "f 1 4 3 2")
    path = write_scene(tmp_path, no_vt, mtl)
    with pytest.raises(InputError, match="no texture coordinates"):
        load_file(path)
    missing = tmp_path / "missing"
    missing.mkdir()
    path = write_scene(missing, TEXTURED_OBJ, mtl)
    assert render_main([str(path), "-o", str(missing / "out.png")]) == 2
    err = capsys.readouterr().err
    assert "texture file not found" in err and len(err.strip().splitlines()) == 1
    assert not (missing / "out.png").exists()
