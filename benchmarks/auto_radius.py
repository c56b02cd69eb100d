"""`auto`'s caustic radius at its default against its own best initial radius, per pixel.

    python benchmarks/auto_radius.py --set unseen|examples [SCENE ...] [--budgets N ...]
    python benchmarks/auto_radius.py --markdown

`auto` estimates caustics by SPPM at an initial radius of RADIUS_FOOTPRINTS pixel widths at
each pixel's first visible point (`dpm.methods.auto`; a second estimate at half of it where
the two differ clearly, and the learned caustic filter where the plan uses it). Per scene,
caustic component (`--component caustic`, seed 0), at M and 10·M emitted photon paths in
auto's own passes of `paths_per_pixel` paths per pixel (what a `--time` render plans:
`--spp` passes sharing `--photons`), the default (no `--radius`) is scored against `--radius`
at 10 initial radii log-spaced from 0.15 to 6 median pixel widths, extended by three more past
an edge the best lands on (six more at most), as `sppm_defaults.py` tunes SPPM. Only the
radius is tuned: the passes are auto's plan (its photons per pass were chosen for time, not
for a fixed photon count; `sppm_defaults.py` shows what more passes would give SPPM). RMSE
per pixel against the caustic references of `caustic_references.py` (a uniformly scaled copy
against its scale-1 twin's). The default was chosen on the example scenes, never on the
unseen ones.

Each scene writes results/auto_radius/SET/NAME.json after every budget (a rerun skips the
budgets it holds); results/auto_radius.md is rebuilt from all of them.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from pathlib import Path

import numpy as np
from caustic_references import load_reference, size
from sppm_defaults import RADII, past_edge, save, scene_names, set_report

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import unit_scale  # noqa: E402

from common import RESULTS, M, cpu  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.io import atomic  # noqa: E402
from dpm.methods.auto import RADIUS_FOOTPRINTS, paths_per_pixel  # noqa: E402
from dpm.metrics import rmse  # noqa: E402
from dpm.options import RenderOptions  # noqa: E402
from dpm.renderer import render  # noqa: E402
from dpm.tracer import build_bvh, trace_visible_points  # noqa: E402

OUT = RESULTS / "auto_radius"
TABLE = RESULTS / "auto_radius.md"


def auto_passes(scene, paths: int, pixels: int) -> int:
    """The passes auto's plan splits `paths` photon paths into at `pixels` pixels."""
    return max(1, round(paths / (paths_per_pixel(scene) * pixels)))


def run_scene(name: str, set_: str, budgets: tuple[int, ...]) -> dict:
    """auto's default radius and its tuned radii at each budget on one scene."""
    twin = unit_scale(name) if set_ == "unseen" else name
    obj, width, height = size(name, set_)
    scene = load_scene(obj)
    camera = scene.camera.with_resolution(width, height)
    reference, noise, reference_passes = load_reference(twin, width, height, set_)
    points = trace_visible_points(scene, build_bvh(scene), camera, 1, 0, (0, height))
    pixel = float(np.median(points.footprint[points.hit]))
    path = OUT / set_ / f"{name}.json"
    rows = json.loads(path.read_text())["budgets"] if path.exists() else []
    done = {row["paths"] for row in rows}
    for n in budgets:
        if n in done:
            continue
        passes = auto_passes(scene, n, width * height)

        def score(radius: float | None, n=n, passes=passes) -> tuple[float, bool]:
            """RMSE of auto's caustics at initial radius `radius` (None: its default) and
            whether the plan used the network."""
            options = RenderOptions(
                component="caustic", spp=passes, photons=n, width=width, height=height,
                seed=0, radius=radius, progress=False,
            )  # fmt: skip
            result = render(scene, options)
            return rmse(result.image, reference), bool(result.stats["plan"]["network"])

        default, network = score(None)
        row = {
            "paths": n, "passes": passes, "default": default, "network": network,
            "reference_passes": reference_passes, "trials": [],
        }  # fmt: skip
        radii, tried = list(pixel * RADII), []
        while radii:  # the grid, then past an edge the best lands on (`past_edge`)
            tried += radii
            row["trials"] += [{"radius": r, "rmse": score(r)[0]} for r in radii]
            best = min(row["trials"], key=lambda t: t["rmse"])
            radii = past_edge(tried, best["radius"])
        row["best"] = best
        rows.append(row)
        print(name, n, f"default {default:.5f} best {best}", flush=True)
        save(path, {
            "scene": name, "set": set_, "size": [width, height], "noise": noise,
            "pixel_width": pixel, "budgets": sorted(rows, key=lambda r: r["paths"]),
            "machine": cpu(), "date": datetime.date.today().isoformat(),
        })  # fmt: skip
    return json.loads(path.read_text())


def markdown() -> str:
    """The report: per set, a row per scene and budget, then the geometric mean and worst
    per budget."""
    lines = [
        "# auto's caustic radius at its default against its own best initial radius",
        "",
        "Made by `python benchmarks/auto_radius.py` (see its docstring). Caustic RMSE per",
        f"pixel of `auto --component caustic` at its default initial radius ({RADIUS_FOOTPRINTS:g}",
        "pixel widths at each pixel's first visible point) divided by its own best of 10+",
        "initial radii (0.15 to 6 median pixel widths, extended past an edge), tuned against",
        "the reference, in auto's own passes. The default was chosen on the examples; the",
        "unseen scenes were never tuned on.",
    ]
    head = ["scene", "paths", "passes", "network", "ref. noise", "default", "best",
            "best radius", "default / best"]  # fmt: skip

    def cells(r: dict, row: dict, ratio: float) -> list[str]:
        return [
            r["scene"], f"{row['paths']:,}", f"{row['passes']}",
            "yes" if row["network"] else "no", f"{r['noise']:.4f}",
            f"{row['default']:.4f}", f"{row['best']['rmse']:.4f}",
            f"{row['best']['radius'] / r['pixel_width']:.2f} px", f"{ratio:.2f}",
        ]  # fmt: skip

    for set_ in ("examples", "unseen"):
        lines += set_report(OUT, set_, head, cells)
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the scenes named (default: the whole set), then rebuild the Markdown."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--set", choices=("examples", "unseen"), default="unseen")
    p.add_argument("--budgets", type=int, nargs="+", default=[M, 10 * M])
    p.add_argument("--markdown", action="store_true", help="only rebuild the Markdown")
    args = p.parse_args()
    if not args.markdown:
        for name in args.scenes or scene_names(args.set):
            run_scene(name, args.set, tuple(args.budgets))
    text = markdown()
    with atomic(TABLE) as tmp:
        tmp.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
