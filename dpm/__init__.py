"""dpm: deep photon mapping — caustics from few photons with a learned density kernel.

The Python API, in the manner of Mitsuba 3's:

>>> import dpm
>>> scene = dpm.load_file("examples/scenes/glass_egg.obj", width=64, height=64)
>>> image = dpm.render(scene, time=4)  # (H, W, 3) float32 linear RGB radiance
>>> dpm.write("egg.png", image)  # .png (sRGB, tone mapped) or .exr (linear)

The renderer (Numba kernels) is imported by the first `render`, so `import dpm` is quick.
"""

from __future__ import annotations

import sys
import time as _time
from dataclasses import replace
from pathlib import Path
from typing import Any

import numpy as np

from dpm import clock  # noqa: F401  (first of dpm: it notes when dpm was imported)
from dpm.camera import Camera
from dpm.errors import InputError
from dpm.options import sidecar_types
from dpm.scene import Scene, load_scene

__all__ = ["Camera", "InputError", "Scene", "load_file", "load_scene", "render", "write"]
__version__ = "0.1.0"


def load_file(path: str | Path, **overrides: Any) -> Scene:
    """The scene of an OBJ file (with its MTL and optional TOML sidecar) or of a Mitsuba 3 XML
    file (`dpm.mitsuba_xml`: the subset it reads); `overrides` replace the sidecar's
    `[render]` values (method, spp, width, height, photons, ...), which are the defaults of
    `render` for this scene. InputError for a bad file or an unknown key."""
    path = Path(path)
    if path.suffix.lower() == ".xml":
        from dpm.mitsuba_xml import read_xml

        scene = read_xml(path)
    else:
        scene = load_scene(path)
    kinds = sidecar_types()
    for key, value in overrides.items():
        if key not in kinds:
            raise InputError(f"unknown scene override '{key}' (one of {', '.join(kinds)})")
        kind = (int, float) if kinds[key] is float else kinds[key]
        if value is not None and not isinstance(value, kind):
            raise InputError(f"scene override {key} must be of type {kinds[key].__name__}")
    return replace(scene, render_defaults={**scene.render_defaults, **overrides})


def render(
    scene: Scene,
    method: str | None = None,
    *,
    time: float | None = None,
    spp: int | None = None,
    seed: int | None = None,
    progress: bool | None = None,
    **options: Any,
) -> np.ndarray:
    """(H, W, 3) float32 linear RGB radiance of `scene` (W m⁻² sr⁻¹ per pixel).

    The arguments are dpm-render's flags (`method`, `time`, `spp`, `seed`, and in `options`
    `photons`, `width`, `height`, `k`, `radius`, `component`, `denoise`, ...) over the
    scene's `[render]` defaults; `time` counts from this call. A progress bar shows when
    `progress` is True (default: when stderr is a terminal).
    """
    from dpm.methods import options_from  # the renderer: Numba kernels, imported when used
    from dpm.renderer import render as render_scene

    started = _time.monotonic()
    given = {"method": method, "time": time, "spp": spp, "seed": seed, **options}
    chosen = options_from(scene.render_defaults, {k: v for k, v in given.items() if v is not None})
    chosen.progress = sys.stderr.isatty() if progress is None else progress
    return render_scene(scene, chosen, started).image


def write(path: str | Path, image: np.ndarray) -> None:
    """Write an (H, W, 3) linear RGB image: .exr as linear float32, .png as tone-mapped sRGB
    (written to a temporary file, then renamed into place)."""
    from dpm.io import write_image

    path = Path(path)
    if path.suffix.lower() not in (".png", ".exr"):
        raise InputError(f"{path}: output must end in .png or .exr")
    write_image(path, np.asarray(image, np.float32))
