"""Per-pixel caustic references of the unseen scenes, for `auto`'s caustic component.

    python benchmarks/caustic_references.py [--passes 512] [--scenes NAME ...]

`auto --component caustic` averages, per pixel, SPPM's estimates at one jittered visible
point per pass, so its limit is the caustic radiance the camera sees averaged over the
pixel. The reference is the same estimator run long: `auto --component caustic
--no-network` at `--passes` passes of 4 photon paths per pixel, twice with independent
seeds (the halves, so its noise is known: the RMSE between them over 2 is the mean's). It is
consistent and shares no sample with any render it scores. Its remaining bias (SPPM's after
that many passes, radii shrunk to about a third of their start) is the renders' own at
long budgets, which favours the estimate without the network, never the network's.

Each scene is rendered at W = min(camera width, MAX_WIDTH), as its Mitsuba reference
(`equal_time_unseen.py`); a uniformly scaled copy gets none (it is scored against its scale-1
twin's). Writes results/unseen/NAME-WxH-caustic.npz (halves (2, H, W, 3) float32, passes,
noise); a scene whose file has at least `--passes` passes is skipped, so a killed run
resumes.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

import numpy as np

from dpm import load_scene
from dpm.io import atomic
from dpm.metrics import rmse
from dpm.options import RenderOptions
from dpm.renderer import render

HERE = Path(__file__).parent
SCENES = HERE / "scenes" / "unseen"
OUT = HERE / "results" / "unseen"
CONTROLS = ("control_room", "control_huge")  # no mirror or glass: no caustics
SCALED = ("spheres_s0p01", "spheres_s100")  # copies of spheres_s1, scored against its reference
MAX_WIDTH = 256
SEEDS = (1001, 1002)


def reference_file(name: str, width: int, height: int) -> Path:
    """Where scene `name`'s caustic reference at width × height lies."""
    return OUT / f"{name}-{width}x{height}-caustic.npz"


def load_reference(name: str, width: int, height: int) -> tuple[np.ndarray, float, int]:
    """(H, W, 3) float32 caustic reference (the halves' mean), its noise (RMSE) and passes."""
    with np.load(reference_file(name, width, height)) as f:
        return f["halves"].mean(axis=0), float(f["noise"]), int(f["passes"])


def make(name: str, passes: int) -> None:
    """Render scene `name`'s two halves at `passes` passes and save them."""
    scene = load_scene(SCENES / f"{name}.obj")
    c = scene.camera
    width = min(c.width, MAX_WIDTH)
    height = max(1, width * c.height // c.width)
    path = reference_file(name, width, height)
    if path.exists():
        with np.load(path) as f:
            if int(f["passes"]) >= passes:
                return
    halves = []
    for seed in SEEDS:
        options = RenderOptions(component="caustic", spp=passes, network=False, seed=seed,
                                width=width, height=height,
                                photons=passes * 4 * width * height, progress=False)  # fmt: skip
        halves.append(render(scene, options).image)
    noise = rmse(halves[0], halves[1]) / 2
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic(path) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(f, halves=np.stack(halves), passes=passes, noise=noise)
    print(f"{name} {width}x{height}: {passes} passes per half, noise {noise:.5f}", flush=True)


def main() -> None:
    """Make the missing references."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--passes", type=int, default=512)
    p.add_argument("--scenes", nargs="*")
    a = p.parse_args()
    names = a.scenes or sorted(
        q.stem for q in SCENES.glob("*.obj") if q.stem not in CONTROLS + SCALED
    )
    if not names:
        sys.exit(f"no scenes in {SCENES}: run benchmarks/scenes/make_unseen.py first")
    for name in names:
        make(name, a.passes)


if __name__ == "__main__":
    main()
