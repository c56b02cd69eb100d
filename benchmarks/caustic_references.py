"""Per-pixel caustic references of the unseen scenes and the examples (`auto`'s caustics).

    python benchmarks/caustic_references.py [--passes N] [--scenes NAME ...] [--set examples]

`auto --component caustic` averages, per pixel, SPPM's estimates at one jittered visible
point per pass, so its limit is the caustic radiance the camera sees averaged over the
pixel. The reference is the same estimator run long: `auto --component caustic
--no-network` at `--passes` passes of 4 photon paths per pixel (`auto` takes 2-4: the
reference's passes gather more), twice with independent
seeds (the halves, so its noise is known: the RMSE between them over 2 is the mean's). It is
consistent and shares no sample with any render it scores. Its remaining bias is SPPM's
after that many passes, and both halves share it, so the noise estimate does not show it:
at closeup_caustic's focus the halves of 512 passes agreed on 23.6 where renders of 1024
passes gave 27.5 (the radius shrinks as passes^-1/6, the blur as passes^-1/3), and a render
longer than its reference was scored against the reference's blur (16-s renders there ran
1121 passes). So each unseen scene gets PASSES[name]: at least 4 times the passes of the
longest 16-s render of `caustic_network.py` (its equal-time table of 2026-11-28), 512 where
that is more; `--passes` overrides it. What bias is left favours the estimate whose blur
is nearer the reference's, the render without the network more often than not. The
examples (`--set examples`, to choose constants on) get EXAMPLE_PASSES: 16 times the passes
of a 4-s aimed render. `auto` aims its caustic photons (since 2026-11-29), so references
made since are aimed too: the examples' (made that day on a 16-core Xeon, 7 scenes at once,
6.6 min) have 2.1-6x less noise than the 512 unaimed passes before them; the unseen scenes'
are still unaimed, at passes sized for unaimed renders, which aimed renders do not reach
(they run fewer passes in the same time).

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
SETS = {  # where each set's scenes lie, and their references (the examples: to choose on)
    "unseen": (HERE / "scenes" / "unseen", HERE / "results" / "unseen"),
    "examples": (HERE.parent / "examples" / "scenes", HERE / "results" / "caustic_examples"),
}
EXAMPLES = ("dragon", "glass_egg", "pool1", "pool2", "red_wine", "ring", "torus")
EXAMPLE_WIDTH = 128  # as the equal-time references of the examples
CONTROLS = ("control_room", "control_huge")  # no mirror or glass: no caustics
SCALED = ("spheres_s0p01", "spheres_s100")  # copies of spheres_s1, scored against its reference
MAX_WIDTH = 256
SEEDS = (1001, 1002)
DEFAULT_PASSES = 512
PASSES = {  # 4x the passes of the longest 16-s render (caustic_network.md, 2026-11-28)
    "far_camera": 16700, "closeup_caustic": 14900, "tinted_glass": 8300, "prism_slab": 7300,
    "huge_floor": 6800, "concave_mirror": 5300, "tall_vase": 4600, "spheres_s1": 4500,
    "far_wall": 4000, "cardioid_cup": 3300, "lens_wall": 2700, "glass_lantern": 2000,
    "bumpy_blob": 1100, "water_tiles": 900,
}  # fmt: skip
EXAMPLE_PASSES = {  # 16x the passes of a 4-s aimed render (4x the 16-s one), 2026-11-29
    "dragon": 1100, "glass_egg": 1500, "pool1": 2300, "pool2": 2200, "red_wine": 1500,
    "ring": 2100, "torus": 1500,
}  # fmt: skip


def reference_file(name: str, width: int, height: int, which: str = "unseen") -> Path:
    """Where scene `name`'s caustic reference at width × height lies."""
    return SETS[which][1] / f"{name}-{width}x{height}-caustic.npz"


def load_reference(
    name: str, width: int, height: int, which: str = "unseen"
) -> tuple[np.ndarray, float, int]:
    """(H, W, 3) float32 caustic reference (the halves' mean), its noise (RMSE) and passes."""
    with np.load(reference_file(name, width, height, which)) as f:
        return f["halves"].mean(axis=0), float(f["noise"]), int(f["passes"])


def size(name: str, which: str = "unseen") -> tuple[Path, int, int]:
    """(OBJ path, W, H) of scene `name` of a set at its reference's size."""
    path = SETS[which][0] / f"{name}.obj"
    c = load_scene(path).camera
    width = min(c.width, MAX_WIDTH if which == "unseen" else EXAMPLE_WIDTH)
    return path, width, max(1, width * c.height // c.width)


def make(name: str, passes: int, which: str = "unseen") -> None:
    """Render scene `name`'s two halves at `passes` passes and save them."""
    obj, width, height = size(name, which)
    scene = load_scene(obj)
    path = reference_file(name, width, height, which)
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
    p.add_argument("--passes", type=int, default=None, help="passes per half (default: PASSES)")
    p.add_argument("--scenes", nargs="*")
    p.add_argument("--set", choices=sorted(SETS), default="unseen")
    a = p.parse_args()
    folder = SETS[a.set][0]
    if a.set == "examples":
        names = a.scenes or list(EXAMPLES)
    else:
        names = a.scenes or sorted(
            q.stem for q in folder.glob("*.obj") if q.stem not in CONTROLS + SCALED
        )
    if not names:
        sys.exit(f"no scenes in {folder}: run benchmarks/scenes/make_unseen.py first")
    for name in names:
        table = PASSES if a.set == "unseen" else EXAMPLE_PASSES
        default = table.get(name, DEFAULT_PASSES)
        passes = a.passes or default
        make(name, passes, a.set)


if __name__ == "__main__":
    main()
