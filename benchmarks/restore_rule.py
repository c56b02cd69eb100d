"""`auto`'s restore step (`dpm.denoise.restore_certain`) against other ways to blend the raw
and the denoised image, at fixed passes on the example scenes.

    python benchmarks/restore_rule.py [SCENE ...] [--passes 4 16 64 256] [--seeds 1 2]

Each example scene renders `auto --spp P` at 128 px wide (photons 4 per pixel per pass, as a
budgeted render plans them) for each P and seed; the arrays `restore_certain` is given (raw
image, denoised image, each pixel's standard error) are kept, and each rule below is applied
to them, the light seen in mirrors and glass added back after it as the render does. RMSE
(`dpm.metrics.rmse`) against the scene's equal-time reference (results/equal_time/), the mean
over the seeds; each rule's ratio to the current one, as geometric means.

- current: `restore_certain` (undo the denoiser from 2 to 4 standard errors of shift);
- denoised: the denoiser's image alone; plain: no denoising;
- js: James-Stein, keep 1 - σ²/s² of the raw pixel (s the denoiser's luminance shift, σ the
  pixel's standard error; 0 where σ is unknown), the MSE-optimal blend of an unbiased pixel and
  a biased one whose bias² is estimated by s² - σ²; js3: the same with s² averaged over 3 × 3.

Writes results/restore_rule.md.
"""

from __future__ import annotations

import argparse
import datetime

import numpy as np

from common import RESULTS, SCENES, cpu, geomean, markdown_table
from dpm import load_scene
from dpm.denoise import restore_certain
from dpm.density.base import luminance
from dpm.filters import box_mean
from dpm.io import read_exr
from dpm.methods import auto
from dpm.metrics import rmse
from dpm.renderer import RenderOptions, render

EXAMPLES = ("dragon", "glass_egg", "pool1", "pool2", "red_wine", "ring", "torus")
RULES = ("current", "denoised", "plain", "js", "js3")


def blends(color: np.ndarray, denoised: np.ndarray, error: np.ndarray) -> dict[str, np.ndarray]:
    """Each rule's (H, W, 3) image from the raw and denoised images and (H, W) errors."""
    shift2 = (luminance(denoised) - luminance(color)) ** 2
    out = {
        "current": restore_certain(color, denoised, error),
        "denoised": denoised,
        "plain": color,
    }
    for name, s2 in (("js", shift2), ("js3", box_mean(shift2, 3, mode="nearest"))):
        known = np.isfinite(error)
        var = np.where(known, error, 0.0) ** 2
        keep = np.where(known, np.clip(1 - var / np.maximum(s2, 1e-30), 0, 1), 0.0)
        out[name] = denoised + keep[..., None] * (color - denoised)
    return out


def run(name: str, passes: list[int], seeds: list[int]) -> list[dict]:
    """Rows of each rule's mean RMSE per pass count on one scene."""
    scene = load_scene(SCENES / f"{name}.obj")
    w = 128
    h = round(scene.camera.height * w / scene.camera.width)
    ref = read_exr(RESULTS / "equal_time" / f"{name}-{w}x{h}-reference.exr")
    kept = {}

    def spy(color, denoised, error, *args):
        kept["args"] = (color.copy(), denoised.copy(), error.copy())
        return restore_certain(color, denoised, error, *args)

    rows = []
    auto.restore_certain = spy
    try:
        for p in passes:
            errors: dict[str, list[float]] = {r: [] for r in RULES}
            for seed in seeds:
                options = RenderOptions(method="auto", spp=p, seed=seed, width=w, height=h,
                                        photons=p * 4 * w * h, progress=False)  # fmt: skip
                image = render(scene, options).image
                images = blends(*kept["args"])
                after = image - images["current"]  # the light seen, added after the denoiser
                for r in RULES:
                    errors[r].append(rmse(images[r] + after, ref))
            rows.append({"scene": name, "passes": p,
                         **{r: float(np.mean(v)) for r, v in errors.items()}})  # fmt: skip
            print(rows[-1], flush=True)
    finally:
        auto.restore_certain = restore_certain
    return rows


def report(rows: list[dict], seeds: list[int]) -> str:
    """The Markdown table and each rule's geometric mean against the current one."""
    lines = [
        "# The restore step against other blends of the raw and denoised image",
        "",
        f"Made by `python benchmarks/restore_rule.py` (see its docstring) on {cpu()},",
        f"{datetime.date.today()}; seeds {seeds}. RMSE of `auto --spp P` at 128 px against the",
        "equal-time references.",
        "",
    ]
    table = [[x["scene"], str(x["passes"]), *[f"{x[r]:.5f}" for r in RULES]] for x in rows]
    lines += [*markdown_table(["scene", "passes", *RULES], table), ""]
    for r in RULES[1:]:
        q = [x[r] / x["current"] for x in rows]
        by = ", ".join(
            f"{p}: {geomean([x[r] / x['current'] for x in rows if x['passes'] == p]):.3f}"
            for p in sorted({x["passes"] for x in rows})
        )
        lines.append(f"- {r} / current: geometric mean {geomean(q):.3f}, worst {max(q):.3f} "
                     f"({len(q)} rows); by passes {by}")  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the scenes and write the report."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=list(EXAMPLES))
    p.add_argument("--passes", type=int, nargs="+", default=[4, 16, 64, 256])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    a = p.parse_args()
    rows = [row for name in a.scenes for row in run(name, a.passes, a.seeds)]
    text = report(rows, a.seeds)
    (RESULTS / "restore_rule.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
