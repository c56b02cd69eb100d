"""The estimator table: caustic RMSE of PM-50, PM-500, PPM-best and APPM-best at M, 10·M and
100·M emitted photon paths on the example scenes, against a PPM reference, with seconds per
stage. M = 700,000 gives the glass egg about 15k caustic photons, as in the paper.

    python benchmarks/estimator_table.py [SCENE ...] [--reference-paths N]
        [--max-reference-paths N] [--reference-radius F]
    python benchmarks/estimator_table.py [SCENE ...] --add METHOD [--budgets N ...]

Each scene writes benchmarks/results/estimators/SCENE.json and its reference radiance
benchmarks/results/references_radiance/SCENE.npz (read by dpm_table.py); the Markdown table
benchmarks/results/estimators.md is rebuilt from every JSON there. References checkpoint to
benchmarks/results/references/ (not committed): an interrupted run resumes, and a larger
budget continues the same reference. A reference starts at --reference-paths and grows
(up to --max-reference-paths) until its noise is at most a fifth of the scene's least error;
the estimators' outputs are kept and rescored, not rerun, and saved beside the reference
checkpoint, so a rerun (say with a longer reference) skips them; delete that folder after
changing an estimator.

--add tunes one more registered progressive method (say cppm) as PPM/APPM are tuned (30
settings, widened at an edge) on the same photon maps, against each scene's saved reference
(references_radiance/SCENE.npz), at the budgets asked for (default M and 10·M), and adds
its METHOD_best and trials to the scene's JSON; the references are not rerun.

--reference-radius sets the reference's initial PPM radius (× scene diagonal). PPM's radius
stays proportional to it, so the noise falls as 1/radius, but the bias grows quickly: at
4 × the default, red_wine's reference moved by RMSE 0.022 (ten times its noise), so the
default stays unless the bias has been measured. The table lists each scene's radius.
"""

from __future__ import annotations

import argparse
import datetime
import json
from dataclasses import asdict
from functools import partial
from pathlib import Path

import numpy as np
from tables import least_error, table1, tabled

from common import (
    PM_KS,
    RESULTS,
    SCENES,
    TOTAL,
    WIDTH,
    M,
    cpu,
    load_reference,
    markdown_table,
    save_reference,
    table_points,
    timed,
    timed_estimate,
)
from dpm import load_scene
from dpm.estimators import PM
from dpm.estimators.reference import Reference, caustic_rmse, ppm_reference
from dpm.estimators.tuning import Trial, best, radii, rescore, tune_widening
from dpm.io import atomic
from dpm.scene import Scene
from dpm.tracer import BVH, VisiblePoints, build_bvh, trace_photons

REFERENCE_RADIUS = 5e-4  # × scene diagonal, default
REFERENCE_PATHS_PER_PASS = 1_000_000  # guided paths
NOISE_EXPONENT = 0.32  # reference noise ∝ paths^-0.32 (glass egg, 20M to 600M paths)


def run_budget(
    name: str,
    n: int,
    scene: Scene,
    bvh: BVH,
    points: VisiblePoints,
    reference: np.ndarray,
    diagonal: float,
) -> tuple[dict, dict, list, list]:
    """One budget's PM estimates and tuning trials, or their saved copy: (row, pm, trials,
    estimates); the RMSEs in them are against `reference` and are rescored later."""
    saved = RESULTS / "references" / name / f"estimates-{n}.npz"
    if saved.exists():
        with np.load(saved) as f:
            row = json.loads(str(f["row"]))
            trials = [Trial(**t) for t in json.loads(str(f["trials"]))]
            pm = {k: (f[f"pm{k}"] if f"pm{k}" in f else None) for k in PM_KS}
            return row, pm, trials, list(f["estimates"])
    photons, (trace_s,) = timed(partial(trace_photons, scene, bvh, n, seed=0, caustic_only=True))
    row = {"paths": n, "caustic_photons": len(photons), "trace_seconds": trace_s}
    pm = {}
    for k in PM_KS:  # each builds its own tree, as a render would
        pm[k], seconds = None, {}
        if len(photons) >= k:
            pm[k], seconds = timed_estimate(PM(k=k), points, photons)
        gather = seconds.get("gather", 0.0)
        row[f"pm{k}"] = {"gather_seconds": gather,
                         "estimate_seconds": seconds.get(TOTAL, 0.0) - gather}  # fmt: skip
    estimates: list[np.ndarray] = []
    trials = tune_widening(points, photons, reference, radii(diagonal), estimates)
    arrays = {f"pm{k}": e for k, e in pm.items() if e is not None}
    with atomic(saved) as tmp, open(tmp, "wb") as f:
        np.savez(f, row=json.dumps(row), trials=json.dumps([asdict(t) for t in trials]),
                 estimates=np.stack(estimates), **arrays)  # fmt: skip
    return row, pm, trials, estimates


def run_scene(
    name: str,
    reference_paths: int,
    max_reference_paths: int,
    reference_radius: float,
    ray_address: str | None = None,
) -> dict:
    """Measure one scene, growing its reference until the ⅕ rule holds; returns the JSON record."""
    scene = load_scene(SCENES / f"{name}.obj")
    bvh = build_bvh(scene)
    points = table_points(scene, bvh)
    camera = scene.camera.with_resolution(WIDTH, WIDTH * scene.camera.height // scene.camera.width)
    diagonal = float(np.linalg.norm(np.subtract(*scene.bounds[::-1], dtype=np.float64)))
    reference_seconds = 0.0

    def reference(paths: int) -> Reference:
        nonlocal reference_seconds
        ref, (seconds,) = timed(partial(
            ppm_reference, scene, bvh, points, paths, reference_radius * diagonal,
            REFERENCE_PATHS_PER_PASS, seed=1, checkpoint_dir=RESULTS / "references" / name,
            progress=True, workers=2, ray_address=ray_address,
        ))  # fmt: skip
        reference_seconds += seconds
        print(name, f"reference {ref.n_paths:,} paths: noise {ref.noise:.5f}", flush=True)
        return ref

    ref = reference(reference_paths)
    rows, kept = [], []  # kept: per budget, the PM estimates and every trial's estimate
    for n in (M, 10 * M, 100 * M):
        row, pm, trials, estimates = run_budget(name, n, scene, bvh, points, ref.radiance, diagonal)
        rows.append(row)
        kept.append((pm, trials, estimates))
        print(name, n, f"{row['caustic_photons']:,} caustic photons", flush=True)

    while True:  # score against the reference; lengthen it while its noise is above ⅕ of the least
        for row, (pm, trials, estimates) in zip(rows, kept, strict=True):
            for k, estimate in pm.items():
                rmse = None if estimate is None else caustic_rmse(points, estimate, ref.radiance)
                row[f"pm{k}"]["rmse"] = rmse
            trials = rescore(trials, estimates, points, ref.radiance)
            row["trials"] = [asdict(t) for t in trials]
            for method in dict.fromkeys(t.method for t in trials):
                row[f"{method}_best"] = asdict(best(trials, method))
        least = min(least_error(row) for row in rows)
        if ref.noise <= least / 5 or ref.n_paths >= max_reference_paths:
            break
        # noise falls about as paths^-NOISE_EXPONENT (measured on the glass egg)
        grow = 1.15 * (5 * ref.noise / least) ** (1 / NOISE_EXPONENT)
        step = 2 * REFERENCE_PATHS_PER_PASS
        paths = min(max_reference_paths, int(np.ceil(ref.n_paths * grow / step)) * step)
        ref = reference(paths)
    for row in rows:
        print(name, row["paths"], {k: v for k, v in row.items() if k != "trials"}, flush=True)
    save_reference(name, ref)
    return {
        "scene": name, "points": int(points.hit.sum()), "width": camera.width,
        "height": camera.height, "diagonal": diagonal,
        "reference": {
            "paths": ref.n_paths, "caustic_photons": ref.caustic_photons, "noise": ref.noise,
            "radius": reference_radius * diagonal, "paths_per_pass": REFERENCE_PATHS_PER_PASS,
            "seconds_this_run": reference_seconds,
        },
        "budgets": rows,
        "machine": cpu(),
        "date": datetime.date.today().isoformat(),
    }  # fmt: skip


def add_method(name: str, method: str, budgets: list[int]) -> dict:
    """The scene's JSON record with `method` tuned at `budgets` on the table's photon maps
    (seed 0) against its saved reference: METHOD_best and its trials in each budget's row."""
    path = RESULTS / "estimators" / f"{name}.json"
    record = json.loads(path.read_text())
    scene = load_scene(SCENES / f"{name}.obj")
    bvh = build_bvh(scene)
    points = table_points(scene, bvh)
    reference, _ = load_reference(name)
    grid = radii(record["diagonal"])
    for row in record["budgets"]:
        if row["paths"] not in budgets:
            continue
        photons = trace_photons(scene, bvh, row["paths"], seed=0, caustic_only=True)
        assert len(photons) == row["caustic_photons"], "not the table's photon map"
        trials = tune_widening(points, photons, reference, grid, methods=(method,))
        row["trials"] = [t for t in row["trials"] if t["method"] != method]
        row["trials"] += [asdict(t) for t in trials]
        row[f"{method}_best"] = asdict(best(trials, method))
        print(name, row["paths"], method, row[f"{method}_best"], flush=True)
    return record


def write_markdown(path: Path = RESULTS / "estimators.md") -> None:
    """Rebuild estimators.md from every scene's JSON: Table 1 (`tables.table1`), the seconds
    per stage and the best settings."""
    records = [json.loads(p.read_text()) for p in sorted((RESULTS / "estimators").glob("*.json"))]
    lines = [
        "# Caustic RMSE of the classic estimators",
        "",
        "Made by `python benchmarks/estimator_table.py` (see its docstring). RMSE of the caustic",
        "radiance the camera sees, over one visible point per pixel, against a PPM reference of",
        "two independent half-budget runs with guided emission. *ref noise* is the RMSE between",
        "the halves; the protocol asks it to be at most a fifth of the smallest error of the",
        "scene's rows. PPM/APPM/CPPM-best: the least RMSE of 30 settings (10 initial radii × 3",
        "photons per pass, more radii where the best was at an edge), chosen per scene and",
        "budget; † marks a best that is still at an edge of the radii tried. CPPM was tuned",
        "later on the same maps against the final reference (`--add cppm`), at M and 10·M only.",
        "",
        *table1(records),
        "",
        "## Seconds per stage",
        "",
        "Trace: caustic photon paths. Gather: the photon search (PM: cKDTree build and",
        "K-nearest queries; PPM/APPM/CPPM: the hashed point grid, `dpm.tracer.point_grid`).",
        "Estimate: the rest of the estimator (kernel sums, PPM/APPM statistics). For",
        "PPM/APPM-best, gather + estimate.",
        "",
    ]
    columns = {k: v for r in records for b in r["budgets"] for k, v in tabled(b).items()}
    head = ["scene", "paths", "trace"]
    for label, key in columns.items():
        head += [label] if key.endswith("_best") else [f"{label} gather", f"{label} estimate"]
    body = []
    for r in records:
        for b in r["budgets"]:
            cells = [r["scene"], f"{b['paths']:,}", f"{b['trace_seconds']:.2f}"]
            for key in columns.values():
                stage = b.get(key)
                if stage is None:  # a method added later (--add) at fewer budgets
                    cells += ["–"] if key.endswith("_best") else ["–", "–"]
                    continue
                cells += (
                    [f"{stage['seconds']:.2f}"]
                    if key.endswith("_best")
                    else [f"{stage['gather_seconds']:.2f}", f"{stage['estimate_seconds']:.2f}"]
                )
            body.append([*cells, f"{r['reference']['paths']:,} paths"])
    lines += markdown_table([*head, "reference"], body)
    lines += ["", "Best settings (initial radius in scene units / emitted paths per pass):", ""]
    for r in records:
        for b in r["budgets"]:
            settings = [
                f"{key.removesuffix('_best').upper()} r={b[key]['radius']:.4g}, "
                f"P={b[key]['photons_per_pass']:,}"
                for key in tabled(b).values()
                if key.endswith("_best")
            ]
            lines.append(f"- {r['scene']} {b['paths']:,}: " + "; ".join(settings))
    lines += [f"- {r['scene']}: {r['note']}" for r in records if "note" in r]
    machines = sorted({f"{r['machine']} ({r['date']})" for r in records})
    lines += ["", f"Machine: {'; '.join(machines)}."]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    """Run the scenes named (default: every example with caustics) and rebuild the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=[
        "glass_egg", "ring", "red_wine", "pool1", "pool2", "torus", "dragon"])  # fmt: skip
    p.add_argument("--reference-paths", type=float, default=100e6, help="to start with")
    p.add_argument("--max-reference-paths", type=float, default=3e9)
    p.add_argument("--reference-radius", type=float, default=REFERENCE_RADIUS,
                   help="initial PPM radius of the reference, × scene diagonal")  # fmt: skip
    p.add_argument(
        "--ray-address", metavar="ADDR",
        help="run the reference's two halves on this Ray cluster (default: as two tasks of a "
        "local Ray runtime; the checkpoint folder must be shared)",
    )  # fmt: skip
    p.add_argument("--add", metavar="METHOD", help="tune this method into the existing records")
    p.add_argument("--budgets", type=int, nargs="+", default=[M, 10 * M], help="with --add")
    args = p.parse_args()
    (RESULTS / "estimators").mkdir(parents=True, exist_ok=True)
    for name in args.scenes:
        if args.add:
            record = add_method(name, args.add, args.budgets)
            with atomic(RESULTS / "estimators" / f"{name}.json") as tmp:
                tmp.write_text(json.dumps(record, indent=1))
            write_markdown()
            continue
        record = run_scene(name, int(args.reference_paths), int(args.max_reference_paths),
                           args.reference_radius, args.ray_address)  # fmt: skip
        (RESULTS / "estimators" / f"{name}.json").write_text(json.dumps(record, indent=1))
        write_markdown()


if __name__ == "__main__":
    main()
