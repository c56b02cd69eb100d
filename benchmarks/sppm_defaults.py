"""SPPM at its view-relative defaults against its own best of 30 settings, per pixel.

    python benchmarks/sppm_defaults.py --set unseen|examples [SCENE ...] [--budgets N ...]
    python benchmarks/sppm_defaults.py --markdown

`radius_defaults.py` scores the methods at fixed visible points; SPPM traces new ones every
pass, so it is scored per pixel, against the caustic references of `caustic_references.py`
(two independent halves, so their noise is known; a uniformly scaled copy against its
scale-1 twin's). Per scene, at M and 10·M emitted photon paths (the examples' rows M
only; seed 0; one caustic photon stream traced once, its consecutive slices the passes,
and one run per pass count for all radii, `sppm_caustics_at_radii`),
`sppm` at its defaults (no radius,
`default_paths_per_pass`: what `dpm-render --method sppm` does) against its own best of 30
settings: 10 initial radii log-spaced from 0.15 to 6 median pixel widths × 10, 100 and 1000
passes, the radii extended by three more past an edge the best lands on (six more at
most). The pass axis is not extended: at M almost every best ran 1000 passes, the most tried,
so the own best is capped there and default / best flatters the default. The defaults were
chosen on the example scenes, never on the unseen ones.

Each scene writes results/sppm_defaults/SET/NAME.json after every budget (a rerun skips
the budgets it holds; `--defaults-only` reruns their defaults and keeps the 30 settings);
results/sppm_defaults.md is rebuilt from all of them.
"""

from __future__ import annotations

import argparse
import datetime
import json
import sys
from collections.abc import Callable
from functools import partial
from pathlib import Path

import numpy as np
from caustic_references import EXAMPLES, load_reference, size

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import CONTROLS, UNSEEN, unit_scale  # noqa: E402

from common import RESULTS, M, cpu, geomean, markdown_table  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.camera import Camera  # noqa: E402
from dpm.estimators.sppm import default_paths_per_pass, sppm_caustics_at_radii  # noqa: E402
from dpm.io import atomic  # noqa: E402
from dpm.metrics import rmse  # noqa: E402
from dpm.scene import Scene  # noqa: E402
from dpm.tracer import (  # noqa: E402
    BVH,
    PhotonMap,
    build_bvh,
    trace_photons,
    trace_visible_points,
)

OUT = RESULTS / "sppm_defaults"
TABLE = RESULTS / "sppm_defaults.md"
PASSES = (10, 100, 1000)
RADII = np.geomspace(0.15, 6.0, 10)  # tuned initial radii, in median pixel widths
EXTEND = 3  # radii added past an edge the best lands on (twice at most)


def scene_names(set_: str) -> list[str]:
    """The scenes of a set that have caustics to score."""
    return list(EXAMPLES) if set_ == "examples" else [n for n in UNSEEN if n not in CONTROLS]


def run_scene(name: str, set_: str, budgets: tuple[int, ...], defaults_only: bool = False) -> dict:
    """sppm's defaults and its 30 (or more) settings at each budget on one scene (with
    `defaults_only`, only the defaults of the budgets already held)."""
    twin = unit_scale(name) if set_ == "unseen" else name
    obj, width, height = size(name, set_)
    scene = load_scene(obj)
    bvh = build_bvh(scene)
    camera = scene.camera.with_resolution(width, height)
    reference, noise, reference_passes = load_reference(twin, width, height, set_)
    points = trace_visible_points(scene, bvh, camera, 1, 0, (0, height))
    pixel = float(np.median(points.footprint[points.hit]))
    path = OUT / set_ / f"{name}.json"
    rows = json.loads(path.read_text())["budgets"] if path.exists() else []
    done = {row["paths"]: row for row in rows}
    for n in budgets:
        if (n in done) != defaults_only:
            continue
        stream = trace_photons(scene, bvh, n, seed=0, caustic_only=True)
        scores = partial(sppm_rmses, scene, bvh, camera, stream, reference)
        per_pass = default_paths_per_pass(n, width * height)
        default = {
            "default": scores([None], per_pass)[0],
            "default_per_pass": per_pass,
            "default_machine": cpu(),
            "default_date": datetime.date.today().isoformat(),
            "reference_passes": reference_passes,  # per half; a row is scored against these
        }
        if defaults_only:
            if done[n].get("reference_passes") != reference_passes:
                sys.exit(
                    f"{name}: its settings were tuned against another reference than the "
                    f"{reference_passes}-pass one now: delete {path} to rerun it in full"
                )
            done[n].update(default)
            print(name, n, f"default {default['default']:.5f}", flush=True)
            save_record(path, name, set_, (width, height), noise, pixel, rows)
            continue
        row = {"paths": n, "caustic_photons": len(stream), **default, "trials": []}
        radii, tried = list(pixel * RADII), []
        while True:  # one run per pass count tries a round's radii at once
            tried += radii
            for p in PASSES:
                row["trials"] += [
                    {"radius": r, "passes": p, "rmse": e}
                    for r, e in zip(radii, scores(radii, -(-n // p)), strict=True)
                ]  # fmt: skip
            best = min(row["trials"], key=lambda t: t["rmse"])
            radii = past_edge(tried, best["radius"])
            if not radii:
                break
        row["best"] = best
        rows.append(row)
        print(name, n, f"default {row['default']:.5f} best {best}", flush=True)
        save_record(path, name, set_, (width, height), noise, pixel, rows)
    return json.loads(path.read_text())


def past_edge(tried: list[float], best: float) -> list[float]:
    """EXTEND more radii of the grid's step past the edge of the radii tried that the best
    radius lies on; none where it lies inside, or the grid has grown twice already."""
    step, low, high = RADII[1] / RADII[0], min(tried), max(tried)
    if len(tried) >= len(RADII) + 2 * EXTEND or low < best < high:
        return []
    return [low / step**k if best == low else high * step**k for k in range(1, EXTEND + 1)]


def records(out: Path, set_: str) -> list[dict]:
    """The scene records of a set under a benchmark's results folder, by scene name."""
    return [json.loads(f.read_text()) for f in sorted((out / set_).glob("*.json"))]


def set_report(
    out: Path, set_: str, head: list[str], cells: Callable[[dict, dict, float], list[str]],
    label: str = "",
) -> list[str]:  # fmt: skip
    """A set's Markdown section (none without records): a table row per scene and budget,
    `cells(record, row, default / best)`, then the geometric mean and worst per budget."""
    records_ = records(out, set_)
    if not records_:
        return []
    rows, ratios = [], {}
    for r in records_:
        for row in r["budgets"]:
            ratio = row["default"] / row["best"]["rmse"]
            ratios.setdefault(row["paths"], []).append(ratio)
            rows.append(cells(r, row, ratio))
    machines = "; ".join(sorted({r["machine"] for r in records_}))  # RMSE: any will do
    lines = ["", f"## {set_} ({machines})", "", *markdown_table(head, rows), ""]
    return lines + [
        f"- {label}{n:,} paths: geometric mean {geomean(v):.2f}, worst {max(v):.2f} "
        f"({len(v)} rows, {sum(x > 2 for x in v)} above 2)"
        for n, v in sorted(ratios.items())
    ]


def save_record(
    path: Path, name: str, set_: str, size_: tuple[int, int], noise: float, pixel: float,
    rows: list[dict],
) -> None:  # fmt: skip
    """Write a scene's record: its rows in budget order, and where and when its settings were
    first tuned (the machine and date a record already holds are kept)."""
    old = json.loads(path.read_text()) if path.exists() else {}
    save(path, {
        "scene": name, "set": set_, "size": list(size_), "noise": noise, "pixel_width": pixel,
        "budgets": sorted(rows, key=lambda r: r["paths"]),
        "machine": old.get("machine", cpu()),
        "date": old.get("date", datetime.date.today().isoformat()),
    })  # fmt: skip


def sppm_rmses(
    scene: Scene, bvh: BVH, camera: Camera, stream: PhotonMap, reference: np.ndarray,
    radii: list[float | None], per_pass: int,
) -> list[float]:  # fmt: skip
    """Per-pixel RMSE against the reference (H, W, 3) of sppm over one photon stream in
    passes of `per_pass` paths from each initial radius of `radii` (scene units; None: its
    default), the runs sharing their camera samples (`sppm_caustics_at_radii`)."""
    images, _ = sppm_caustics_at_radii(
        scene, bvh, camera, stream.n_paths, 0, radii, per_pass, stream=stream
    )  # fmt: skip
    return [rmse(image, reference) for image in images]


def save(path: Path, record: dict) -> None:
    """Write a JSON record atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic(path) as tmp:
        tmp.write_text(json.dumps(record, indent=1))


def markdown() -> str:
    """The report: per set, a row per scene and budget, then the geometric mean and worst."""
    lines = [
        "# SPPM at its defaults against its own best of 30 settings, per pixel",
        "",
        "Made by `python benchmarks/sppm_defaults.py` (see its docstring). Caustic RMSE per",
        "pixel at sppm's defaults divided by its own best of 30 settings (10 initial radii ×",
        "10/100/1000 passes, tuned against the reference). The defaults were chosen on the",
        "examples; the unseen scenes were never tuned on.",
    ]
    head = ["scene", "paths", "caustic photons", "ref. noise", "ref. passes",
            "default passes", "default", "best", "best setting", "default / best"]  # fmt: skip

    def cells(r: dict, row: dict, ratio: float) -> list[str]:
        best = row["best"]
        return [
            r["scene"], f"{row['paths']:,}", f"{row['caustic_photons']:,}",
            f"{r['noise']:.4f}", f"{row.get('reference_passes', '–')}",
            f"{-(-row['paths'] // row['default_per_pass'])}",
            f"{row['default']:.4f}", f"{best['rmse']:.4f}",
            f"{best['radius'] / r['pixel_width']:.2f} px, {best['passes']} passes",
            f"{ratio:.2f}",
        ]  # fmt: skip

    for set_ in ("examples", "unseen"):
        lines += set_report(OUT, set_, head, cells, "sppm, ")
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the scenes named (default: the whole set), then rebuild the Markdown."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--set", choices=("examples", "unseen"), default="unseen")
    p.add_argument("--budgets", type=int, nargs="+", default=[M, 10 * M])
    p.add_argument(
        "--defaults-only", action="store_true", help="rerun the defaults, keep the settings"
    )
    p.add_argument("--markdown", action="store_true", help="only rebuild the Markdown")
    args = p.parse_args()
    if not args.markdown:
        for name in args.scenes or scene_names(args.set):
            run_scene(name, args.set, tuple(args.budgets), args.defaults_only)
    text = markdown()
    with atomic(TABLE) as tmp:
        tmp.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
