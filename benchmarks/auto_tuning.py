"""The plan constants of `auto`: photon paths per pixel per pass × initial radius in pixel
footprints, each setting rendered for the same time budget and scored against the references
of benchmarks/equal_time.py (run that first, or with --references-only).

    python benchmarks/auto_tuning.py [SCENE ...] [--time T] [--width W]

In-process renders (`started` = the render's start, so the process start is left out),
after one warm-up render per scene; prints a line per setting.
"""

from __future__ import annotations

import argparse
import itertools
import time

from equal_time import OUT

from common import SCENES
from dpm import load_scene
from dpm.io import read_exr
from dpm.methods import auto
from dpm.metrics import rmse
from dpm.renderer import RenderOptions, render

PHOTONS_PER_PIXEL = (0.25, 1.0, 4.0)
RADIUS_FOOTPRINTS = (1.0, 2.0, 4.0)


def main() -> None:
    """Render every setting on the scenes named; print time split and RMSE."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=["glass_egg", "ring", "pool1", "dragon"])
    p.add_argument("--time", type=float, default=2.5)
    p.add_argument("--width", type=int, default=128)
    args = p.parse_args()
    for name in args.scenes:
        scene = load_scene(SCENES / f"{name}.obj")
        h = args.width * scene.camera.height // scene.camera.width
        ref = read_exr(OUT / f"{name}-{args.width}x{h}-reference.exr")
        size = {"width": args.width, "height": h, "progress": False}
        render(scene, RenderOptions(spp=2, **size))  # warm-up
        for ppp, footprints in itertools.product(PHOTONS_PER_PIXEL, RADIUS_FOOTPRINTS):
            # (both paths-per-pixel constants: aimed and not, `auto.paths_per_pixel`)
            auto.PHOTONS_PER_PIXEL = auto.AIMED_PHOTONS_PER_PIXEL = ppp
            auto.RADIUS_FOOTPRINTS = footprints
            options = RenderOptions(time=args.time, **size)
            result = render(scene, options, started=time.monotonic())
            s = result.stats["seconds"]
            caustic = sum(s.get(k, 0.0) for k in ("photons", "gather", "estimate"))
            path = s.get("visible_points", 0.0) + s.get("shade", 0.0) + s.get("path", 0.0)
            print(
                f"{name} photons/pixel {ppp:g} footprints {footprints:g}: "
                f"{result.stats['passes']} passes, RMSE {rmse(result.image, ref):.4f}, "
                f"caustic s {caustic:.2f}, path s {path:.2f}",
                flush=True,
            )


if __name__ == "__main__":
    main()
