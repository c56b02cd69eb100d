"""The estimator table: caustic RMSE of PM-50, PM-500, PPM-best and APPM-best at M, 10·M and
100·M emitted photon paths on the example scenes, against a PPM reference, with seconds per
stage. M = 700,000 gives the glass egg about 15k caustic photons, as in the paper.

    python benchmarks/estimator_table.py [SCENE ...] [--reference-paths N]
        [--max-reference-paths N] [--reference-radius F]

Each scene writes benchmarks/results/estimators/SCENE.json and its reference radiance
benchmarks/results/references_radiance/SCENE.npz (read by dpm_table.py); the Markdown table
benchmarks/results/estimators.md is rebuilt from every JSON there. References checkpoint to
benchmarks/results/references/ (not committed): an interrupted run resumes, and a larger
budget continues the same reference. A reference starts at --reference-paths and grows
(up to --max-reference-paths) until its noise is at most a fifth of the scene's least error;
the estimators' outputs are kept and rescored, not rerun, and saved beside the reference
checkpoint, so a rerun (say with a longer reference) skips them; delete that folder after
changing an estimator.

--reference-radius sets the reference's initial PPM radius (× scene diagonal). PPM's radius
stays proportional to it, so the noise falls as 1/radius, but the bias grows quickly: at
4 × the default, red_wine's reference moved by RMSE 0.022 (ten times its noise), so the
default stays unless the bias has been measured. The table lists each scene's radius.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from dpm import load_scene
from dpm.density import PM, gather
from dpm.density.reference import Reference, caustic_rmse, ppm_reference
from dpm.density.tuning import Trial, best, radii, rescore, tune_widening
from dpm.io import atomic
from dpm.scene import Scene
from dpm.tracer import BVH, VisiblePoints, build_bvh, trace_photons, trace_visible_points

HERE = Path(__file__).parent
SCENES = HERE.parent / "examples" / "scenes"
RESULTS = HERE / "results"
M = 700_000
WIDTH = 128  # visible points: one per pixel of a WIDTH-wide image, seed 0
REFERENCE_RADIUS = 5e-4  # × scene diagonal, default
REFERENCE_PATHS_PER_PASS = 1_000_000  # guided paths
NOISE_EXPONENT = 0.32  # reference noise ∝ paths^-0.32 (glass egg, 20M to 600M paths)


def table_points(scene: Scene, bvh: BVH) -> VisiblePoints:
    """The table's visible points: one per pixel of a WIDTH-wide image, seed 0."""
    camera = scene.camera.with_resolution(WIDTH, WIDTH * scene.camera.height // scene.camera.width)
    return trace_visible_points(scene, bvh, camera, 1, 0, (0, camera.height))


def save_reference(name: str, ref: Reference) -> None:
    """Keep a scene's reference radiance (committed, so later tables need no rerun)."""
    path = RESULTS / "references_radiance" / f"{name}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, radiance=ref.radiance, noise=ref.noise, paths=ref.n_paths)


def load_reference(name: str) -> tuple[np.ndarray, float]:
    """(N, 3) reference caustic radiance at `table_points` and its noise, as saved."""
    with np.load(RESULTS / "references_radiance" / f"{name}.npz") as f:
        return f["radiance"], float(f["noise"])


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
            pm = {k: (f[f"pm{k}"] if f"pm{k}" in f else None) for k in (50, 500)}
            return row, pm, trials, list(f["estimates"])
    start = time.perf_counter()
    photons = trace_photons(scene, bvh, n, seed=0, caustic_only=True)
    row = {"paths": n, "caustic_photons": len(photons), "trace_seconds": 0.0}
    row["trace_seconds"] = time.perf_counter() - start
    pm = {}
    for k in (50, 500):
        gather.seconds = 0.0
        gather.forget_tree()  # PM-500 builds its own tree, as a render would
        start = time.perf_counter()
        pm[k] = PM(k=k).estimate(points, photons) if len(photons) >= k else None
        total = time.perf_counter() - start
        row[f"pm{k}"] = {"gather_seconds": gather.seconds,
                         "estimate_seconds": total - gather.seconds}  # fmt: skip
    estimates: list[np.ndarray] = []
    trials = tune_widening(points, photons, reference, radii(diagonal), estimates)
    arrays = {f"pm{k}": e for k, e in pm.items() if e is not None}
    with atomic(saved) as tmp, open(tmp, "wb") as f:
        np.savez(f, row=json.dumps(row), trials=json.dumps([asdict(t) for t in trials]),
                 estimates=np.stack(estimates), **arrays)  # fmt: skip
    return row, pm, trials, estimates


def run_scene(
    name: str, reference_paths: int, max_reference_paths: int, reference_radius: float
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
        start = time.perf_counter()
        ref = ppm_reference(
            scene, bvh, points, paths, reference_radius * diagonal, REFERENCE_PATHS_PER_PASS,
            seed=1, checkpoint_dir=RESULTS / "references" / name, progress=True,
        )  # fmt: skip
        reference_seconds += time.perf_counter() - start
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
            for method in ("ppm", "appm"):
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
        "machine": f"{platform.machine()}, {os.cpu_count()} cores",
        "date": datetime.date.today().isoformat(),
    }  # fmt: skip


def least_error(row: dict) -> float:
    """The least RMSE of one budget's PM-50, PM-500, PPM-best and APPM-best."""
    values = (row["pm50"]["rmse"], row["pm500"]["rmse"], row["ppm_best"]["rmse"],
              row["appm_best"]["rmse"])  # fmt: skip
    return min(v for v in values if v is not None)


def edge(row: dict, method: str) -> str:
    """'†' when the method's best radius is the smallest or largest it tried, else ''."""
    tried = [t["radius"] for t in row["trials"] if t["method"] == method]
    return "†" if row[f"{method}_best"]["radius"] in (min(tried), max(tried)) else ""


def fmt(x: float | None) -> str:
    return "–" if x is None else f"{x:.4f}"


def write_markdown() -> None:
    """Rebuild estimators.md from every scene's JSON."""
    records = [json.loads(p.read_text()) for p in sorted((RESULTS / "estimators").glob("*.json"))]
    lines = [
        "# Caustic RMSE of the classic estimators",
        "",
        "Made by `python benchmarks/estimator_table.py` (see its docstring). RMSE of the caustic",
        "radiance the camera sees, over one visible point per pixel, against a PPM reference of",
        "two independent half-budget runs with guided emission. *ref noise* is the RMSE between",
        "the halves; the protocol asks it to be at most a fifth of the smallest error of the",
        "scene's rows. PPM/APPM-best: the least RMSE of 30 settings (10 initial radii × 3",
        "photons per pass, more radii where the best was at an edge), chosen per scene and",
        "budget; † marks a best that is still at an edge of the radii tried.",
        "",
        "| scene | paths | caustic photons | PM-50 | PM-500 | PPM-best | APPM-best "
        "| ref noise | noise ≤ ⅕ min | ref r₀ (× diagonal) |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        smallest = min(least_error(b) for b in r["budgets"])
        noise = r["reference"]["noise"]
        for b in r["budgets"]:
            lines.append(
                f"| {r['scene']} | {b['paths']:,} | {b['caustic_photons']:,} "
                f"| {fmt(b['pm50']['rmse'])} | {fmt(b['pm500']['rmse'])} "
                f"| {fmt(b['ppm_best']['rmse'])}{edge(b, 'ppm')} "
                f"| {fmt(b['appm_best']['rmse'])}{edge(b, 'appm')} "
                f"| {noise:.4f} | {'yes' if noise <= smallest / 5 else 'no'} "
                f"| {r['reference']['radius'] / r['diagonal']:.1e} |"
            )
    lines += [
        "",
        "## Seconds per stage",
        "",
        "Trace: caustic photon paths. Gather: cKDTree build and queries. Estimate: the rest of",
        "the estimator (kernel sums, PPM/APPM statistics). For PPM/APPM-best, gather + estimate.",
        "",
        "| scene | paths | trace | PM-50 gather | PM-50 estimate | PM-500 gather "
        "| PM-500 estimate | PPM-best | APPM-best | reference |",
        "|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in records:
        for b in r["budgets"]:
            lines.append(
                f"| {r['scene']} | {b['paths']:,} | {b['trace_seconds']:.2f} "
                f"| {b['pm50']['gather_seconds']:.2f} | {b['pm50']['estimate_seconds']:.2f} "
                f"| {b['pm500']['gather_seconds']:.2f} | {b['pm500']['estimate_seconds']:.2f} "
                f"| {b['ppm_best']['seconds']:.2f} | {b['appm_best']['seconds']:.2f} "
                f"| {r['reference']['paths']:,} paths |"
            )
    lines += ["", "Best settings (initial radius in scene units / emitted paths per pass):", ""]
    for r in records:
        for b in r["budgets"]:
            p, a = b["ppm_best"], b["appm_best"]
            lines.append(
                f"- {r['scene']} {b['paths']:,}: PPM r={p['radius']:.4g}, "
                f"P={p['photons_per_pass']:,}; APPM r={a['radius']:.4g}, "
                f"P={a['photons_per_pass']:,}"
            )
    lines += [f"- {r['scene']}: {r['note']}" for r in records if "note" in r]
    machines = sorted({f"{r['machine']} ({r['date']})" for r in records})
    lines += ["", f"Machine: {'; '.join(machines)}."]
    (RESULTS / "estimators.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    """Run the scenes named (default: every example with caustics) and rebuild the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=[
        "glass_egg", "ring", "red_wine", "pool1", "pool2", "torus", "dragon"])  # fmt: skip
    p.add_argument("--reference-paths", type=float, default=100e6, help="to start with")
    p.add_argument("--max-reference-paths", type=float, default=3e9)
    p.add_argument("--reference-radius", type=float, default=REFERENCE_RADIUS,
                   help="initial PPM radius of the reference, × scene diagonal")  # fmt: skip
    args = p.parse_args()
    (RESULTS / "estimators").mkdir(parents=True, exist_ok=True)
    for name in args.scenes:
        record = run_scene(name, int(args.reference_paths), int(args.max_reference_paths),
                           args.reference_radius)  # fmt: skip
        (RESULTS / "estimators" / f"{name}.json").write_text(json.dumps(record, indent=1))
        write_markdown()


if __name__ == "__main__":
    main()
