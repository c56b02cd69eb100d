"""The committed example scenes: each loads, has what it is for, and renders finite images."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest

from dpm import load_scene
from dpm.renderer import RenderOptions, render
from dpm.scene import DIELECTRIC, MIRROR

SCENES = Path(__file__).parents[1] / "examples" / "scenes"
EXPECTED = {
    "glass_egg": DIELECTRIC,
    "red_wine": DIELECTRIC,
    "ring": MIRROR,
    "pool1": DIELECTRIC,
    "pool2": DIELECTRIC,
    "torus": DIELECTRIC,
    "dragon": DIELECTRIC,
    "cornell_box": None,
}


def test_every_example_is_present() -> None:
    assert sorted(p.stem for p in SCENES.glob("*.obj")) == sorted(EXPECTED)
    for name in EXPECTED:
        assert (SCENES / f"{name}.toml").is_file(), f"{name} has no camera sidecar"


@pytest.mark.parametrize("name", sorted(EXPECTED))
def test_example_loads_and_renders(name: str) -> None:
    scene = load_scene(SCENES / f"{name}.obj")
    kinds = set(scene.materials.kind[scene.material].tolist())
    if EXPECTED[name] is None:
        assert kinds == {0}, "the Cornell box is all diffuse"
    else:
        assert EXPECTED[name] in kinds
    if name == "dragon":
        assert len(scene.triangles) >= 50_000
    # Every light faces something: its front normal points into the scene's box.
    lo, hi = scene.bounds
    centre = (lo + hi) / 2
    for t in scene.emitters.triangles:
        assert np.dot(scene.normals[t], centre - scene.triangles[t].mean(axis=0)) > 0
    image = render(
        scene, RenderOptions(method="pt", spp=1, width=24, height=24, progress=False)
    ).image
    assert np.all(np.isfinite(image)) and np.all(image >= 0)
    assert image.max() > 0, "the camera sees no light at all"


def test_committed_scenes_match_their_generator(tmp_path: Path) -> None:
    """The committed files are exactly what examples/make_scenes.py writes (it is seeded)."""
    import subprocess
    import sys

    script = SCENES.parent / "make_scenes.py"
    subprocess.run(
        [sys.executable, str(script), "--out", str(tmp_path)], check=True, capture_output=True
    )
    for committed in sorted(SCENES.iterdir()):
        assert (tmp_path / committed.name).read_bytes() == committed.read_bytes(), committed.name
