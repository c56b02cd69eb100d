"""What any caustic filter could gain over `auto --no-network`: the error's bias and variance.

    python benchmarks/caustic_bounds.py [--set examples unseen] [SCENE ...] [--passes 8 32 128]
                                        [--seeds 1 2 3 4 5 6]

Issue 43 asks the learned filter for 0.75 of the render's caustic RMSE without it. A filter
works on one render's photons: it can trade variance for bias, and no more. Per scene and pass
count, `auto --component caustic --no-network` is run with each seed (`caustic_ladder`, the
statistics the filter reads), and against the scene's SPPM caustic reference
(`caustic_references.py`) this reports, as ratios to the render's own RMSE (mean over seeds):

- `filter`: the shipped filter on the same statistics (`forward.filter_caustics`: its
  network and clamp; the render's blend with the halves is not applied);
- `variance share`: the share of the render's mean squared error that is variance across the
  seeds (the rest: bias and the reference's own noise);
- `bias floor`: what a filter that removed all variance and added no bias would score,
  √(1 − variance share);
- `narrow floor`, `extrapolated floor`: the same for the narrow kernel's estimate and for the
  extrapolated one (`stats.extrapolated`, the two kernels' blur cancelled to second order),
  √((their mean squared error − their variance across seeds) / the render's mean squared
  error): what a filter of those estimates could reach at best (0 where the seeds' mean
  matches the reference within noise, or where few seeds underestimate the variance);
- `others' mean`: the mean of the other seeds' renders (the same bias, a fifth of the
  variance with six seeds), and that mean held within the clamp of each render
  (`stats.clamp_to_centre`): whether the clamp lets a low-variance estimate through;
- `reference held`: the reference itself held within the clamp (what a filter that
  predicted the reference would score);
- `3 x 3 box`: the render's image averaged over 3 x 3 pixels, and the share of its noise
  variance (render minus the seeds' mean) that average leaves (1/9 for noise independent from
  pixel to pixel): how far averaging neighbours removes noise, and what it costs in blur.

Examples: the scenes the constants were chosen on; unseen: the report set. Writes
results/caustic_bounds.md.
"""

from __future__ import annotations

import argparse
import datetime
import sys
import time
from dataclasses import replace
from pathlib import Path

import numpy as np
from caustic_references import EXAMPLES, load_reference, size
from scipy.ndimage import uniform_filter

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import CONTROLS, UNSEEN, unit_scale  # noqa: E402

from common import RESULTS, cpu, geomean, markdown_table  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.caustic import forward, stats  # noqa: E402
from dpm.data.caustic_set import caustic_ladder  # noqa: E402
from dpm.metrics import rmse  # noqa: E402
from dpm.tracer import build_bvh  # noqa: E402

TABLE = RESULTS / "caustic_bounds.md"
COLUMNS = ("filter", "variance share", "bias floor", "narrow floor", "extrapolated floor",
           "others' mean", "others' mean held", "reference held", "3 x 3 box",
           "noise left by 3 x 3")  # fmt: skip
OTHERS = "others' mean"


def _sharp(s: stats.CausticStats) -> np.ndarray:
    """(P, 3) the extrapolated estimate of a run's statistics (blur cancelled to second order)."""
    return stats.extrapolated(s.wide, s.narrow, s.blur_ratio)


def scene_rows(name: str, which: str, passes: tuple[int, ...], seeds: list[int]) -> list[dict]:
    """Rows of the ratios above for one scene at each pass count."""
    obj, w, h = size(name, which)
    ref, noise, _ = load_reference(unit_scale(name) if which == "unseen" else name, w, h, which)
    ref = ref.astype(np.float64)
    scene = load_scene(obj)
    scene = replace(scene, camera=scene.camera.with_resolution(w, h))
    bvh = build_bvh(scene)
    weights = forward.load_filter()
    ladders = [caustic_ladder(scene, bvh, seed, passes) for seed in seeds]
    rows = []
    for i, p in enumerate(passes):
        runs = [ladder[i] for ladder in ladders]
        images = np.stack([s.spread.reshape(h, w, 3) for s in runs])
        n = len(runs)
        plain = float(np.mean([rmse(x, ref) for x in images]))
        mean = images.mean(axis=0)
        variance = float(images.var(axis=0, ddof=1).mean())
        mse = float(((images - ref) ** 2).mean())
        share = variance / mse
        floors = []
        for sharp in (False, True):
            e = np.stack([(_sharp(s) if sharp else s.narrow).reshape(h, w, 3) for s in runs])
            bias2 = float(((e - ref) ** 2).mean()) - float(e.var(axis=0, ddof=1).mean())
            floors.append(np.sqrt(max(bias2, 0.0) / mse))
        filtered, others, held, oracle = [], [], [], []
        for s, x in zip(runs, images, strict=True):
            filtered.append(rmse(forward.filter_caustics(weights, s).reshape(h, w, 3), ref))
            other = (images.sum(axis=0) - x) / (n - 1)
            others.append(rmse(other, ref))
            held.append(rmse(stats.clamp_to_centre(s, other.reshape(-1, 3)).reshape(h, w, 3), ref))
            oracle.append(rmse(stats.clamp_to_centre(s, ref.reshape(-1, 3)).reshape(h, w, 3), ref))
        box = [rmse(uniform_filter(x, (3, 3, 1), mode="nearest"), ref) for x in images]
        left = uniform_filter(images - mean, (1, 3, 3, 1), mode="nearest").var(axis=0, ddof=1)
        values = (np.mean(filtered) / plain, share, np.sqrt(max(1.0 - share, 0.0)), *floors,
                  np.mean(others) / plain, np.mean(held) / plain, np.mean(oracle) / plain,
                  np.mean(box) / plain, float(left.mean()) / variance)  # fmt: skip
        row = {"set": which, "scene": name, "passes": p, "rmse": plain, "reference_noise": noise,
               **{c: float(v) for c, v in zip(COLUMNS, values, strict=True)}}  # fmt: skip
        rows.append(row)
        print(name, p, {k: round(v, 3) for k, v in row.items() if isinstance(v, float)},
              flush=True)  # fmt: skip
    return rows


def _range(rows: list[dict], column: str) -> str:
    """'low-high' of a column over rows."""
    values = [r[column] for r in rows]
    return f"{min(values):.2f}-{max(values):.2f}"


def main() -> None:
    """Run the sets' scenes and write the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", help="scene names (default: every scene of the sets)")
    p.add_argument("--set", nargs="+", choices=("examples", "unseen"),
                   default=["examples", "unseen"])  # fmt: skip
    p.add_argument("--passes", type=int, nargs="+", default=[8, 32, 128])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2, 3, 4, 5, 6])
    a = p.parse_args()
    if len(a.seeds) < 2:
        p.error("--seeds needs two seeds at least (the variance is across them)")
    start = time.monotonic()
    rows = []
    for which in a.set:
        names = EXAMPLES if which == "examples" else [n for n in UNSEEN if n not in CONTROLS]
        for name in names:
            if not a.scenes or name in a.scenes:
                rows += scene_rows(name, which, tuple(sorted(a.passes)), a.seeds)
    head = ["set", "scene", "passes", "no network RMSE", *COLUMNS]
    body = [[r["set"], r["scene"], str(r["passes"]), f"{r['rmse']:.5f}",
             *[f"{r[c]:.3f}" for c in COLUMNS]] for r in rows]  # fmt: skip
    lines = [
        "# What a caustic filter could gain: bias and variance of `auto --no-network`",
        "",
        f"`python benchmarks/caustic_bounds.py` on {cpu()}, {datetime.date.today()}, seeds "
        f"{a.seeds}, {time.monotonic() - start:.0f} s. Ratios to the render's own caustic RMSE "
        "(see the script's docstring for each column).",
        "",
        *markdown_table(head, body),
        "",
    ]
    for which in a.set:
        part = [r for r in rows if r["set"] == which]
        if not part:
            continue
        for p_ in sorted({r["passes"] for r in part}):
            at = [r for r in part if r["passes"] == p_]
            lines.append(
                f"- {which}, {p_} passes: geometric means: filter "
                f"{geomean([r['filter'] for r in at]):.3f}, bias floor "
                f"{geomean([r['bias floor'] for r in at]):.3f} (ranges, as they reach 0: the "
                f"narrow one's {_range(at, 'narrow floor')}, the extrapolated one's "
                f"{_range(at, 'extrapolated floor')}), others' mean "
                f"{geomean([r[OTHERS] for r in at]):.3f}, "
                f"reference held {geomean([r['reference held'] for r in at]):.3f}, 3 x 3 box "
                f"{geomean([r['3 x 3 box'] for r in at]):.3f}; variance share "
                f"{min(r['variance share'] for r in at):.2f}-"
                f"{max(r['variance share'] for r in at):.2f}"
            )
    TABLE.write_text("\n".join(lines) + "\n")
    print(f"wrote {TABLE}")


if __name__ == "__main__":
    main()
