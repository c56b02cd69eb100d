"""Caustic filter weights compared on the example scenes, inside `auto` (the set to choose on).

    python benchmarks/caustic_weights.py WEIGHTS [WEIGHTS ...] [--passes 1 4 16 64]
                                         [--seeds 1 2] [--out NAME]

Each example scene's caustic component (`auto --component caustic`) is rendered in this
process at each pass count and seed without the network and with each weight file
(`--weights`: the whole render's filter, its hold at sparse pixels and the passes' halves
blend, as a user gets it), the same seed throughout (the same samples: a ratio is the
filter's effect alone). RMSE against the examples' SPPM caustic references
(`caustic_references.py --set examples`), the mean over the seeds, over the render without
the network; and the filter's seconds per pixel (`seconds.network` of the stats, which
includes loading and the halves' second run). Weights are chosen here and reported on the
unseen set (`caustic_network.py`). Writes results/caustic_weights.md (or `--out`).
"""

from __future__ import annotations

import argparse
import datetime
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from caustic_references import EXAMPLES, load_reference, size

from common import RESULTS, cpu, geomean, markdown_table
from dpm import load_scene
from dpm.methods.auto import paths_per_pixel
from dpm.metrics import rmse
from dpm.options import RenderOptions
from dpm.renderer import render

TABLE = RESULTS / "caustic_weights.md"


def run(weights: list[Path], passes: list[int], seeds: list[int]) -> list[dict]:
    """Per scene and pass count: RMSE without the network, each file's ratio to it, and each
    file's network seconds per pixel (the mean over the seeds)."""
    rows = []
    for name in EXAMPLES:
        obj, w, h = size(name, "examples")
        ref, _, _ = load_reference(name, w, h, "examples")
        scene = load_scene(obj)
        scene = replace(scene, camera=scene.camera.with_resolution(w, h))
        for p in passes:
            errors: dict[str, list[float]] = {"plain": []}
            cost: dict[str, list[float]] = {}
            for seed in seeds:
                paths = round(p * paths_per_pixel(scene) * w * h)  # auto's own paths per pass
                base = RenderOptions(component="caustic", spp=p, photons=paths, width=w,
                                     height=h, seed=seed, progress=False)  # fmt: skip
                errors["plain"].append(rmse(render(scene, replace(base, network=False)).image, ref))
                for f in weights:
                    out = render(scene, replace(base, network=True, weights=f))
                    errors.setdefault(str(f), []).append(rmse(out.image, ref))
                    seconds = out.stats["seconds"].get("network", 0.0)
                    cost.setdefault(str(f), []).append(seconds / (w * h))
            plain = float(np.mean(errors["plain"]))
            row = {"scene": name, "passes": p, "plain": plain}
            for f in weights:
                row[str(f)] = float(np.mean(errors[str(f)])) / plain
                row[f"{f} s/px"] = float(np.mean(cost[str(f)]))
            rows.append(row)
            print(name, p, {k: round(v, 4) if isinstance(v, float) else v
                            for k, v in row.items() if k != "scene"}, flush=True)  # fmt: skip
    return rows


def main() -> None:
    """Run and write the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("weights", nargs="+", type=Path)
    p.add_argument("--passes", type=int, nargs="+", default=[1, 4, 16, 64])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    p.add_argument("--out", default=TABLE.name, help="the table's name in results/")
    a = p.parse_args()
    start = time.monotonic()
    rows = run(a.weights, a.passes, a.seeds)
    names = [str(f) for f in a.weights]
    head = ["scene", "passes", "no network RMSE", *names, *[f"{n}: µs/px" for n in names]]
    body = [[r["scene"], str(r["passes"]), f"{r['plain']:.5f}",
             *[f"{r[n]:.3f}" for n in names], *[f"{r[f'{n} s/px'] * 1e6:.2f}" for n in names]]
            for r in rows]  # fmt: skip
    summary = []
    for q in [*a.passes, None]:
        mine = [r for r in rows if q is None or r["passes"] == q]
        label = "geometric mean" + ("" if q is None else f", {q} passes")
        summary.append([label, "", "", *[f"{geomean([r[n] for r in mine]):.3f}" for n in names],
                        *["" for _ in names]])  # fmt: skip
    summary.append(["worst", "", "", *[f"{max(r[n] for r in rows):.3f}" for n in names],
                    *["" for _ in names]])  # fmt: skip
    lines = [
        "# Caustic filter weights on the example scenes, inside `auto`",
        "",
        f"`python benchmarks/caustic_weights.py {' '.join(names)} --passes "
        f"{' '.join(map(str, a.passes))} --seeds {' '.join(map(str, a.seeds))}"
        f"{'' if a.out == TABLE.name else f' --out {a.out}'}` on {cpu()}, "
        f"{datetime.date.today()}, {time.monotonic() - start:.0f} s: caustic RMSE with each "
        "weight file over `--no-network` (same seeds, same samples), against the examples' SPPM "
        "caustic references; the filter's seconds per pixel from the stats (the renders ran "
        "in one process, so the first render's includes compiling).",
        "",
        *markdown_table(head, [*body, *summary]),
        "",
    ]
    (RESULTS / a.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
