"""The Python API: dpm.load_file, dpm.render and dpm.write, in the manner of Mitsuba 3's."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

import dpm
from conftest import write_scene
from dpm.io import read_exr
from dpm.options import RenderOptions
from dpm.renderer import render as render_scene

SIDECAR = "[camera]\norigin = [0, 0.5, 2]\ntarget = [0, 0, 0]\nup = [0, 1, 0]\nfov = 50\n" \
    "width = 12\nheight = 10\n[render]\nmethod = \"pt\"\nspp = 2\n"  # fmt: skip


@pytest.fixture
def scene_file(tmp_path: Path) -> Path:
    """A floor and a light, with a sidecar that picks pt at 2 spp on a 12 x 10 image."""
    return write_scene(tmp_path, toml=SIDECAR)


def test_render_is_the_renderer_with_the_sidecar_under_the_arguments(scene_file: Path) -> None:
    scene = dpm.load_file(scene_file)
    image = dpm.render(scene, seed=3, progress=False)
    assert image.shape == (10, 12, 3) and image.dtype == np.float32
    options = RenderOptions(method="pt", spp=2, seed=3)
    options.progress = False
    np.testing.assert_array_equal(image, render_scene(scene, options).image)
    assert image.mean() > 0  # the floor is lit


def test_load_file_overrides_replace_the_sidecar_and_arguments_replace_both(
    scene_file: Path,
) -> None:
    scene = dpm.load_file(scene_file, width=6, height=4, spp=1)
    assert dpm.render(scene, progress=False).shape == (4, 6, 3)
    assert dpm.render(scene, width=8, height=8, progress=False).shape == (8, 8, 3)
    assert dpm.load_file(scene_file).render_defaults["spp"] == 2  # the file is unchanged


def test_bad_arguments_are_one_line_input_errors(scene_file: Path, tmp_path: Path) -> None:
    with pytest.raises(dpm.InputError, match="unknown scene override 'colour'"):
        dpm.load_file(scene_file, colour=1)
    with pytest.raises(dpm.InputError, match="spp must be of type int"):
        dpm.load_file(scene_file, spp="many")
    scene = dpm.load_file(scene_file)
    with pytest.raises(dpm.InputError, match="unknown render option"):
        dpm.render(scene, colour=1)
    with pytest.raises(dpm.InputError, match="--k applies to"):
        dpm.render(scene, k=5)  # pt reads no K
    with pytest.raises(dpm.InputError, match="must end in .png or .exr"):
        dpm.write(tmp_path / "x.jpg", np.zeros((2, 2, 3)))
    with pytest.raises(dpm.InputError, match="not found|No such|does not exist"):
        dpm.load_file(tmp_path / "missing.obj")


def test_write_round_trips_exr_and_writes_png(tmp_path: Path) -> None:
    image = np.random.default_rng(0).random((5, 7, 3)).astype(np.float32)
    dpm.write(tmp_path / "a.exr", image)
    np.testing.assert_array_equal(read_exr(tmp_path / "a.exr"), image)
    dpm.write(tmp_path / "a.png", image)
    assert (tmp_path / "a.png").stat().st_size > 0
    assert sorted(p.name for p in tmp_path.iterdir()) == ["a.exr", "a.png"]  # no leftovers
