"""The progressive methods at their view-relative defaults against their own best of 30 settings.

    python benchmarks/radius_defaults.py --set examples [SCENE ...]
    python benchmarks/radius_defaults.py --set unseen [SCENE ...] [--reference-paths N]
    python benchmarks/radius_defaults.py --markdown

A user has no reference to tune a radius against, so a default must come close to the best
radius without one. Per scene, caustic component, at M and 10·M emitted photon paths (seed 0,
the estimator table's maps), each of ppm, appm and cppm at its defaults (no --radius: each
point's radius from its photons and pixel footprint, `dpm.density.radius`; photons / 10 per
pass) against its own best of 30 settings (10 initial radii × 10, 100 and 1000 passes, the
grid extended at an edge as `dpm.estimators.tuning.tune_widening` does), and nppm at its
defaults against the best tuned classic.

- examples (the scenes the defaults were chosen on): the estimator table's visible points,
  committed references and tuned settings (results/estimators/SCENE.json); only the defaults
  run here.
- unseen (`benchmarks/scenes/make_unseen.py`, never tuned on): visible points one per pixel
  of the scene's own camera (at most MAX_WIDTH wide), a PPM reference at them (two halves of
  --reference-paths guided paths, initial radius REFERENCE_FOOTPRINTS median pixel widths,
  checkpointed under results/references/unseen/), and the 30 settings over radii log-spaced
  from 0.15 to 6 median pixel widths (the bounding box means nothing where a floor is 1000
  units wide). A record tuned against another reference (an earlier one, blurrier or with
  fewer paths) is retuned by walking each (method, passes) column's radii from its earlier
  best towards lower error (`tune_descending`: the grid's best where the error is unimodal
  in the radius, as 274 of the 279 columns tuned in full against the 40M-path references
  were, the other five with a second minimum four or more steps narrower than the best); a
  budget never tuned walks from its neighbouring budget's bests.

Each scene writes results/radius_defaults/SET/SCENE.json (the unseen references' radiance
beside it, SCENE.npz, reused by later runs); results/radius_defaults.md is rebuilt from all of them.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import sys
from dataclasses import asdict
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import unseen_scenes  # noqa: E402

from common import (  # noqa: E402
    RESULTS,
    SCENES,
    M,
    cpu,
    geomean,
    load_reference,
    markdown_table,
    table_points,
)
from dpm import load_scene  # noqa: E402
from dpm.estimators.reference import caustic_rmse, ppm_reference  # noqa: E402
from dpm.estimators.tuning import best, tune_descending, tune_widening  # noqa: E402
from dpm.io import atomic  # noqa: E402
from dpm.methods import make_estimator  # noqa: E402
from dpm.scene import Scene  # noqa: E402
from dpm.tracer import BVH, VisiblePoints, build_bvh, trace_photons, trace_visible_points  # noqa: E402

OUT = RESULTS / "radius_defaults"
TUNED = ("ppm", "appm", "cppm")
DEFAULTS = (*TUNED, "nppm")
MAX_WIDTH = 256
# The reference's initial radius, in median pixel widths, and its paths. 0.5 widths (40M
# paths) blurred the spheres' foci and the far camera's caustic enough to move the best
# radius at 10·M; 0.2 needs (0.5 / 0.2)² more paths for the same noise.
REFERENCE_FOOTPRINTS = 0.2
REFERENCE_PATHS = 250_000_000
REFERENCE_PATHS_PER_PASS = 1_000_000
DEFAULT_PASSES = 10


def unseen_points(scene: Scene, bvh: BVH) -> VisiblePoints:
    """One visible point per pixel (seed 0) of the scene's camera, at most MAX_WIDTH wide."""
    c = scene.camera
    width = min(c.width, MAX_WIDTH)
    camera = c.with_resolution(width, max(1, round(c.height * width / c.width)))
    return trace_visible_points(scene, bvh, camera, 1, 0, (0, camera.height))


def defaults(points: VisiblePoints, photons, reference: np.ndarray, n: int) -> dict[str, float]:
    """Each method's caustic RMSE at its defaults (no radius; n / DEFAULT_PASSES per pass)."""
    per_pass = max(1, n // DEFAULT_PASSES)
    return {
        m: caustic_rmse(
            points, make_estimator(m, photons_per_pass=per_pass).estimate(points, photons),
            reference,
        )
        for m in DEFAULTS
    }  # fmt: skip


def run_examples(name: str) -> dict:
    """The defaults on one example scene, against the estimator table's tuned settings."""
    table = json.loads((RESULTS / "estimators" / f"{name}.json").read_text())
    scene = load_scene(SCENES / f"{name}.obj")
    bvh = build_bvh(scene)
    points = table_points(scene, bvh)
    reference, noise = load_reference(name)
    rows = []
    for row in table["budgets"][:2]:
        n = row["paths"]
        photons = trace_photons(scene, bvh, n, seed=0, caustic_only=True)
        rows.append({
            "paths": n, "caustic_photons": len(photons),
            "default": defaults(points, photons, reference, n),
            "best": {m: row[f"{m}_best"] for m in TUNED},
        })  # fmt: skip
        print(name, n, rows[-1]["default"], flush=True)
    return record(name, "examples", points, noise, rows)


def unseen_reference(
    name: str, scene: Scene, bvh: BVH, points: VisiblePoints, paths: int
) -> tuple[np.ndarray, float, int]:
    """(N, 3) reference radiance at the points, its noise and paths: the saved one
    (OUT/unseen/NAME.npz) when it has at least `paths` from REFERENCE_FOOTPRINTS, else a new
    run (resumed from its checkpoints)."""
    saved = OUT / "unseen" / f"{name}.npz"
    if saved.exists():
        with np.load(saved) as f:
            footprints = float(f["footprints"]) if "footprints" in f else 0.5
            if int(f["paths"]) >= paths and footprints == REFERENCE_FOOTPRINTS:
                return f["radiance"], float(f["noise"]), int(f["paths"])
    width = float(np.median(points.footprint[points.hit]))
    ref = ppm_reference(
        scene, bvh, points, paths, REFERENCE_FOOTPRINTS * width, REFERENCE_PATHS_PER_PASS,
        seed=1, progress=True,
        checkpoint_dir=RESULTS / "references" / "unseen" / f"{name}-w{REFERENCE_FOOTPRINTS}",
    )  # fmt: skip
    saved.parent.mkdir(parents=True, exist_ok=True)
    with atomic(saved) as tmp, open(tmp, "wb") as f:
        np.savez_compressed(
            f, radiance=ref.radiance, noise=ref.noise, paths=ref.n_paths,
            footprints=REFERENCE_FOOTPRINTS,
        )  # fmt: skip
    return ref.radiance, ref.noise, ref.n_paths


def run_unseen(
    name: str, reference_paths: int, budgets: tuple[int, ...], tune: bool = True
) -> dict:
    """References, defaults and (with `tune`) the 30 settings on one unseen scene, merged
    into its saved record (rows of other budgets, and without `tune` the tuned settings,
    kept)."""
    path = next(p for p in unseen_scenes() if p.stem == name)
    scene = load_scene(path)
    bvh = build_bvh(scene)
    points = unseen_points(scene, bvh)
    reference, noise, paths = unseen_reference(name, scene, bvh, points, reference_paths)
    print(name, f"reference {paths:,} paths, noise {noise:.5f}", flush=True)
    width = float(np.median(points.footprint[points.hit]))
    saved = OUT / "unseen" / f"{name}.json"
    rows = {}
    if saved.exists():
        earlier = json.loads(saved.read_text())
        rows = {row["paths"]: row for row in earlier["budgets"]}
        if not same_reference(earlier["reference"], reference_record(width, paths)):
            for row in rows.values():  # tuned against another reference: retune from its bests
                row["start"] = column_bests(row.pop("trials", []), row["paths"])
                row["best"] = {}
    grid = width * np.geomspace(0.15, 6.0, 10)
    for n in budgets:
        photons = trace_photons(scene, bvh, n, seed=0, caustic_only=True)
        row = {**rows.get(n, {}), "paths": n, "caustic_photons": len(photons)}
        if len(photons) == 0:  # a diffuse control: nothing to estimate
            rows[n] = {**row, "default": {}, "best": {}}
            continue
        row["default"] = defaults(points, photons, reference, n)
        rows[n] = row
        print(name, n, row["default"], flush=True)
        if not tune:  # a row never tuned stays so (the table shows it as missing)
            continue
        row.setdefault("best", {})
        row.setdefault("trials", [])
        others = [r for r in rows.values() if r is not row and r.get("trials")]
        if not row.get("start") and not row["trials"] and others:
            # never tuned, a neighbouring budget was: walk from that budget's bests
            other = min(others, key=lambda r: abs(np.log(r["paths"] / n)))
            row["start"] = column_bests(other["trials"], other["paths"])
        for m in TUNED:  # saved after each method: a long run keeps its part, a rerun resumes
            if m in row["best"]:
                continue
            start = {(mm, k): r for mm, k, r in row.get("start", []) if mm == m}
            trials = (
                tune_descending(points, photons, reference, grid, start) if start
                else tune_widening(points, photons, reference, grid, methods=(m,))
            )  # fmt: skip
            row["best"][m] = asdict(best(trials, m))
            row["trials"] += [asdict(t) for t in trials]
            save(OUT / "unseen" / f"{name}.json", unseen_record(name, points, noise, paths, rows))
            print(name, n, m, row["best"][m]["rmse"], f"{len(trials)} trials", flush=True)
    return unseen_record(name, points, noise, paths, rows)


def column_bests(trials: list[dict], paths: int) -> list[list]:
    """[method, passes, radius] of the least-error trial in each (method, passes) column."""
    out: dict[tuple[str, int], dict] = {}
    for t in trials:
        key = (t["method"], round(paths / t["photons_per_pass"]))
        if key not in out or t["rmse"] < out[key]["rmse"]:
            out[key] = t
    return [[m, n, t["radius"]] for (m, n), t in sorted(out.items())]


def reference_record(width: float, paths: int) -> dict:
    """What a record says of the reference it was scored against."""
    return {"paths": paths, "radius": REFERENCE_FOOTPRINTS * width}


def same_reference(a: dict, b: dict) -> bool:
    """Whether two `reference_record`s name the same reference (radii to rounding)."""
    return a["paths"] == b["paths"] and math.isclose(a["radius"], b["radius"], rel_tol=1e-9)


def unseen_record(
    name: str, points: VisiblePoints, noise: float, paths: int, rows: dict[int, dict]
) -> dict:
    """The JSON record of an unseen scene, its rows in budget order."""
    width = float(np.median(points.footprint[points.hit]))
    out = record(name, "unseen", points, noise, [rows[n] for n in sorted(rows)])
    out["reference"] = reference_record(width, paths)
    return out


def save(path: Path, rec: dict) -> None:
    """Write a JSON record atomically."""
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic(path) as tmp:
        tmp.write_text(json.dumps(rec, indent=1))


def record(name: str, set_: str, points: VisiblePoints, noise: float, rows: list) -> dict:
    """The JSON record of one scene."""
    return {
        "scene": name, "set": set_, "points": int(points.hit.sum()), "noise": noise,
        "budgets": rows, "machine": cpu(), "date": datetime.date.today().isoformat(),
    }  # fmt: skip


def ratios(records: list[dict]) -> dict[str, list[float]]:
    """Per method, default / its own best (nppm: / the best tuned classic), every row."""
    out: dict[str, list[float]] = {m: [] for m in DEFAULTS}
    for r in records:
        for row in r["budgets"]:
            if not row["default"]:
                continue
            if any(m not in row.get("best", {}) for m in TUNED):
                continue  # tuning unfinished
            classic = min(row["best"][m]["rmse"] for m in TUNED)
            for m in DEFAULTS:
                own = row["best"][m]["rmse"] if m in TUNED else classic
                out[m].append(row["default"][m] / own)
    return out


def markdown() -> str:
    """The report: per set, a row per scene and budget, then the geometric means and worst."""
    lines = [
        "# Progressive methods at their defaults against their own best of 30 settings",
        "",
        "Made by `python benchmarks/radius_defaults.py` (see its docstring). Caustic RMSE at a",
        "method's defaults divided by its own best of 30 settings (10 radii × 10/100/1000",
        "passes, tuned against the reference); nppm's by the best tuned classic. The defaults",
        "were chosen on the examples; the unseen scenes were never tuned on. Unseen",
        f"references: PPM from {REFERENCE_FOOTPRINTS} median pixel widths (the record's",
        "`reference`); rows tuned against an earlier reference were retuned by walking each",
        "column of the grid from its earlier best (`tune_descending`).",
    ]
    for set_ in ("examples", "unseen"):
        files = sorted((OUT / set_).glob("*.json"))
        if not files:
            continue
        records = [json.loads(f.read_text()) for f in files]
        head = ["scene", "paths", "caustic photons", "ref. noise", *DEFAULTS]
        rows = []
        for r in records:
            for row in r["budgets"]:
                if not row["default"] or any(m not in row.get("best", {}) for m in TUNED):
                    rows.append([r["scene"], f"{row['paths']:,}", f"{row['caustic_photons']:,}",
                                 "–", *["–"] * 4])  # fmt: skip
                    continue
                classic = min(row["best"][m]["rmse"] for m in TUNED)
                cells = [
                    f"{row['default'][m] / (row['best'][m]['rmse'] if m in TUNED else classic):.2f}"
                    for m in DEFAULTS
                ]
                rows.append([r["scene"], f"{row['paths']:,}", f"{row['caustic_photons']:,}",
                             f"{r['noise']:.4f}", *cells])  # fmt: skip
        summary = ratios(records)
        machines = "; ".join(sorted({r["machine"] for r in records}))  # RMSE: any machine will do
        lines += ["", f"## {set_} ({machines})", "", *markdown_table(head, rows), ""]
        for m, values in summary.items():
            worst = max(values, default=float("nan"))
            lines.append(f"- {m}: geometric mean {geomean(values):.2f}, worst {worst:.2f}"
                         f" ({len(values)} rows)")  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the scenes named (default: the whole set), then rebuild the Markdown."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--set", choices=("examples", "unseen"), default="unseen")
    p.add_argument("--reference-paths", type=int, default=REFERENCE_PATHS)
    p.add_argument("--budgets", type=int, nargs="+", default=[M, 10 * M], help="unseen only")
    p.add_argument(
        "--defaults-only",
        action="store_true",
        help="unseen: rerun the defaults, keep the saved tuned settings",
    )
    p.add_argument("--markdown", action="store_true", help="only rebuild the Markdown")
    args = p.parse_args()
    if not args.markdown:
        if args.set == "examples":
            names = args.scenes or sorted(f.stem for f in (RESULTS / "estimators").glob("*.json"))
        else:
            names = args.scenes or [p.stem for p in unseen_scenes()]
        for name in names:
            rec = (
                run_examples(name) if args.set == "examples"
                else run_unseen(
                    name, args.reference_paths, tuple(args.budgets), not args.defaults_only
                )
            )  # fmt: skip
            save(OUT / args.set / f"{name}.json", rec)
    text = markdown()
    with atomic(RESULTS / "radius_defaults.md") as tmp:
        tmp.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
