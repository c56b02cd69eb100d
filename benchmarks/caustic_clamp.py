"""Choosing the caustic filter's clamp (`dpm.caustic.stats.CLAMP_Z`) on the example scenes.

    python benchmarks/caustic_clamp.py [--passes 1 4 16 64] [--seeds 1 2] [--z 0.5 1 1.5 2 3]

The filter's output is held within Z standard errors of each pixel's own SPPM estimate: a
larger Z lets it denoise more and blur a sharp caustic more. On each example scene (the set
constants are chosen on; never the unseen one), `auto --component caustic` is run to each pass
count without the network, and the shipped filter is applied to the same statistics at each Z.
RMSE against the examples' SPPM caustic references (`caustic_references.py --set examples`),
the mean over the seeds, over the render without the network. Beside each Z, the reference
itself held within Z standard errors: what a filter that predicted the reference exactly
would score through the clamp. Writes results/caustic_clamp.md.
"""

from __future__ import annotations

import argparse
import datetime
import time
from dataclasses import replace

import numpy as np
from caustic_references import EXAMPLES, load_reference, size

from common import RESULTS, cpu, markdown_table
from dpm import load_scene
from dpm.caustic import forward, stats
from dpm.data.caustic_set import caustic_ladder
from dpm.metrics import rmse
from dpm.tracer import build_bvh

TABLE = RESULTS / "caustic_clamp.md"


def run(passes: list[int], seeds: list[int], zs: list[float]) -> list[dict]:
    """Per scene and pass count: RMSE without the network and with it at each Z."""
    weights = forward.load_filter()
    rows = []
    saved = stats.CLAMP_Z
    try:
        for name in EXAMPLES:
            obj, w, h = size(name, "examples")
            ref, _, _ = load_reference(name, w, h, "examples")
            scene = load_scene(obj)
            scene = replace(scene, camera=scene.camera.with_resolution(w, h))
            bvh = build_bvh(scene)
            errors = {p: {"plain": [], **{k: [] for z in zs for k in (z, -z)}} for p in passes}
            for seed in seeds:
                for p, s in zip(
                    passes, caustic_ladder(scene, bvh, seed, tuple(passes)), strict=True
                ):
                    errors[p]["plain"].append(rmse(s.spread.reshape(h, w, 3), ref))
                    for z in zs:
                        # (the clamp alone: the render also holds sparse pixels to the spread
                        # estimate, `auto.held_move`, at auto's own CLAMP_Z, not patched here)
                        stats.CLAMP_Z = z
                        out = forward.filter_caustics(weights, s).reshape(h, w, 3)
                        errors[p][z].append(rmse(out, ref))
                        held = stats.clamp_to_centre(s, ref.reshape(-1, 3).astype(np.float64))
                        errors[p][-z].append(rmse(held.reshape(h, w, 3), ref))  # the oracle
            for p in passes:
                plain = float(np.mean(errors[p]["plain"]))
                row = {"scene": name, "passes": p, "plain": plain,
                       **{k: float(np.mean(errors[p][k])) / plain for k in errors[p]
                          if k != "plain"}}  # fmt: skip
                rows.append(row)
                print(name, p, {k: round(v, 3) for k, v in row.items() if k != "scene"}, flush=True)
    finally:
        stats.CLAMP_Z = saved
    return rows


def main() -> None:
    """Run and write the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--passes", type=int, nargs="+", default=[1, 4, 16, 64])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    p.add_argument("--z", type=float, nargs="+", default=[0.5, 1.0, 1.5, 2.0, 3.0])
    a = p.parse_args()
    if min(a.z) <= 0:  # -z keys the reference held at z
        p.error("--z values must be positive")
    start = time.monotonic()
    rows = run(a.passes, a.seeds, a.z)
    keys = [*a.z, *[-z for z in a.z]]  # the filter at each Z, then the reference held at each
    head = ["scene", "passes", "no network RMSE", *[f"Z = {z:g}" for z in a.z],
            *[f"reference held, Z = {z:g}" for z in a.z]]  # fmt: skip
    body = [[r["scene"], str(r["passes"]), f"{r['plain']:.5f}", *[f"{r[k]:.3f}" for k in keys]]
            for r in rows]  # fmt: skip
    means = ["geometric mean", "", "", *[
        f"{float(np.exp(np.mean(np.log([r[k] for r in rows])))):.3f}" for k in keys]]  # fmt: skip
    worst = ["worst", "", "", *[f"{max(r[k] for r in rows):.3f}" for k in keys]]
    lines = [
        "# The caustic filter's clamp, chosen on the example scenes",
        "",
        f"`python benchmarks/caustic_clamp.py` on {cpu()}, {datetime.date.today()}, seeds "
        f"{a.seeds}, {time.monotonic() - start:.0f} s: the shipped filter's RMSE at each Z over "
        "the render without the network (same statistics), against the examples' SPPM caustic "
        "references; then the reference itself held within Z standard errors of the pixel's "
        "own estimate, as the filter's output is (what a filter that predicted the reference "
        "exactly would score).",
        "",
        *markdown_table(head, [*body, means, worst]),
        "",
    ]
    TABLE.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
