"""The halves' blend with and without the extrapolated estimate, on the example scenes (the
set to choose on), inside `auto --component caustic`.

    python benchmarks/blend_target.py [--switch target|move|ratio|centre|hull] [--passes 4 16 64]
                                      [--seeds 1 2] [--network]

`Passes.blend` fits the weights of its moves (towards the narrow kernel's estimate and, with
the network, the filter's) to one half of the passes' estimate, computed from the other half.
The narrow estimate has about a quarter of the wide one's blur (a ratio per pixel,
`Passes.blur_ratio`: 1/4 at the first pass, up to about 2/5 later); the extrapolated one
(`dpm.caustic.stats.extrapolated`) cancels it to second order at more noise, which the fit
averages over the pixels. `--switch target`: the blend fitted to the narrow or the
extrapolated estimate (`auto.EXTRAPOLATED_TARGET`), without the move towards the latter;
`--switch move`: that move (`auto.EXTRAPOLATED_MOVE`) off and on, fitted to the extrapolated
estimate; `--switch ratio`: the extrapolation's blur ratio the first pass's 1/4 everywhere
or each pixel's own (`auto.PIXEL_BLUR_RATIO`), with the move, fitted to the extrapolated
estimate. Each example's caustic is rendered in this process both ways, the same seeds (the
same samples), RMSE against the examples' SPPM caustic references (`caustic_references.py
--set examples`), mean over the seeds. Writes results/blend_{switch}[_network].md.
"""

from __future__ import annotations

import argparse
import datetime
import time
from dataclasses import replace

import numpy as np
from caustic_references import EXAMPLES, load_reference, size

import dpm.caustic.stats as stats
import dpm.methods.auto as auto
from common import RESULTS, cpu, geomean, markdown_table
from dpm import load_scene
from dpm.methods.auto import paths_per_pixel
from dpm.metrics import rmse
from dpm.options import RenderOptions
from dpm.renderer import render

# the module flag of `dpm.methods.auto` each switch turns off and on
SWITCHES = {"target": (auto, "EXTRAPOLATED_TARGET"), "move": (auto, "EXTRAPOLATED_MOVE"),
            "ratio": (auto, "PIXEL_BLUR_RATIO"),
            "centre": (stats, "EXTRAPOLATED_CENTRE"), "hull": (stats, "HULL_CLAMP")}  # fmt: skip


def run(switch: str, passes: list[int], seeds: list[int], network: bool) -> list[dict]:
    """Per scene and pass count: RMSE with the switch off and the ratio with it on."""
    auto.EXTRAPOLATED_TARGET = True
    auto.EXTRAPOLATED_MOVE = switch in ("ratio", "centre", "hull")
    auto.PIXEL_BLUR_RATIO = switch != "ratio"
    rows = []
    for name in EXAMPLES:
        obj, w, h = size(name, "examples")
        ref, _, _ = load_reference(name, w, h, "examples")
        scene = load_scene(obj)
        scene = replace(scene, camera=scene.camera.with_resolution(w, h))
        for p in passes:
            errors: dict[bool, list[float]] = {False: [], True: []}
            for seed in seeds:
                paths = round(p * paths_per_pixel(scene) * w * h)
                options = RenderOptions(component="caustic", spp=p, photons=paths, width=w,
                                        height=h, seed=seed, progress=False,
                                        network=network)  # fmt: skip
                for on in (False, True):
                    setattr(*SWITCHES[switch], on)
                    errors[on].append(rmse(render(scene, options).image, ref))
            off = float(np.mean(errors[False]))
            row = {"scene": name, "passes": p, "off": off,
                   "ratio": float(np.mean(errors[True])) / off}  # fmt: skip
            rows.append(row)
            print(name, p, f"{off:.5f}", f"{row['ratio']:.4f}", flush=True)
    return rows


def main() -> None:
    """Run and write the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--switch", choices=tuple(SWITCHES), default="target")
    p.add_argument("--passes", type=int, nargs="+", default=[4, 16, 64])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    p.add_argument("--network", action="store_true", help="with the learned filter")
    a = p.parse_args()
    start = time.monotonic()
    rows = run(a.switch, a.passes, a.seeds, a.network)
    body = [[r["scene"], str(r["passes"]), f"{r['off']:.5f}", f"{r['ratio']:.3f}"]
            for r in rows]  # fmt: skip
    for q in [*a.passes, None]:
        mine = [r["ratio"] for r in rows if q is None or r["passes"] == q]
        body.append(["geometric mean" + ("" if q is None else f", {q} passes"), "", "",
                     f"{geomean(mine):.3f}"])  # fmt: skip
    body.append(["worst", "", "", f"{max(r['ratio'] for r in rows):.3f}"])
    flag = " --network" if a.network else ""
    what = {
        "target": ("fitted to the other half's narrow estimate", "fitted to its extrapolated one"),
        "move": ("without the move towards the extrapolated estimate", "with it"),
        "ratio": ("extrapolated at the first pass's blur ratio 1/4", "at each pixel's own"),
        "centre": ("the filter held around the pixel's own estimate", "around the extrapolated"),
        "hull": ("the filter held near the extrapolated estimate", "near it or the own one"),
    }[a.switch]
    lines = [
        f"# The halves' blend, `--switch {a.switch}`: example scenes",
        "",
        f"`python benchmarks/blend_target.py --switch {a.switch} --passes "
        f"{' '.join(map(str, a.passes))} --seeds {' '.join(map(str, a.seeds))}{flag}` on "
        f"{cpu()}, {datetime.date.today()}, {time.monotonic() - start:.0f} s: caustic RMSE of "
        f"`auto --component caustic{'' if a.network else ' --no-network'}` with the blend "
        f"{what[0]}, and the ratio {what[1]} (same samples).",
        "",
        *markdown_table(["scene", "passes", "off: RMSE", "on / off"], body),
        "",
    ]
    out = RESULTS / f"blend_{a.switch}{'_network' if a.network else ''}.md"
    out.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
