"""The learned estimator against the classic ones at the lowest budget M (paper Table 1).

Caustic RMSE of every shipped DPM model (dpm/nn/weights/dpm-K.msgpack) on the example scenes
at M emitted paths, next to PM-50, PM-500, PPM-best and APPM-best from the estimator table,
and the ratio (best classic RMSE) / (DPM-500 RMSE): above 1 means DPM-500 wins.

    python benchmarks/dpm_table.py [SCENE ...] [--weights DIR]

Needs each scene's benchmarks/results/estimators/SCENE.json and references_radiance/SCENE.npz
(made by estimator_table.py); writes benchmarks/results/dpm.md. Same visible points and the
same photon map (seed 0) as the table's M row.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import time
from pathlib import Path

from dpm import load_scene
from dpm.density import gather
from dpm.density.reference import caustic_rmse
from dpm.nn.estimator import DPM
from dpm.nn.weights import SHIPPED, load_weights, weight_ks
from dpm.tracer import build_bvh, trace_photons
from estimator_table import RESULTS, SCENES, M, load_reference, table_points

CLASSIC = ("pm50", "pm500", "ppm_best", "appm_best")


def run_scene(name: str, models: list[Path]) -> dict:
    """RMSE and seconds of each model at M on one scene, with the table's classic row."""
    record = json.loads((RESULTS / "estimators" / f"{name}.json").read_text())
    reference, noise = load_reference(name)
    scene = load_scene(SCENES / f"{name}.obj")
    bvh = build_bvh(scene)
    points = table_points(scene, bvh)
    photons = trace_photons(scene, bvh, M, seed=0, caustic_only=True)
    row = {"scene": name, "caustic_photons": len(photons), "reference_noise": noise}
    classic = record["budgets"][0]
    assert classic["paths"] == M and classic["caustic_photons"] == len(photons), name
    for key in CLASSIC:
        row[key] = classic[key]["rmse"]
    for path in models:
        weights = load_weights(path)
        estimator = DPM(weights.k, path)
        if len(photons) < weights.k:
            row[path.stem] = None
            continue
        estimator.estimate(points, photons)  # compile first: time the second call
        gather.seconds = 0.0
        gather.forget_tree()  # count the tree build, as PM's timing does
        start = time.perf_counter()
        estimate = estimator.estimate(points, photons)
        total = time.perf_counter() - start
        row[path.stem] = caustic_rmse(points, estimate, reference)
        row[f"{path.stem}_seconds"] = {"gather": gather.seconds, "total": total}
    print(row, flush=True)
    return row


def write_markdown(rows: list[dict], models: list[Path]) -> None:
    """benchmarks/results/dpm.md from the rows."""
    names = [p.stem for p in models]
    head = "| scene | caustic photons | PM-50 | PM-500 | PPM-best | APPM-best | "
    head += " | ".join(n.upper() for n in names) + " | best classic / DPM-500 | ref noise |"
    lines = [
        "# DPM against the classic estimators at M emitted paths",
        "",
        "Made by `python benchmarks/dpm_table.py`. Caustic RMSE over one visible point per",
        f"pixel (camera-weighted) at M = {M:,} emitted paths, against the estimator table's PPM",
        "reference (`estimators.md`). The last column is above 1 where DPM-500 beats the best",
        "classic estimator tuned for that scene and budget.",
        "",
        head,
        "|" + "---|" * (8 + len(names)),
    ]
    for r in rows:
        cells = [f"{r[k]:.4f}" if r[k] is not None else "–" for k in (*CLASSIC, *names)]
        best = min(r[k] for k in CLASSIC if r[k] is not None)
        dpm500 = r.get("dpm-500")
        ratio = f"{best / dpm500:.2f}" if dpm500 else "–"
        lines.append(f"| {r['scene']} | {r['caustic_photons']:,} | " + " | ".join(cells)
                     + f" | {ratio} | {r['reference_noise']:.4f} |")  # fmt: skip
    lines += ["", "Seconds (gather / total estimate, after compilation):", ""]
    for r in rows:
        parts = [f"{n} {r[n + '_seconds']['gather']:.2f} / {r[n + '_seconds']['total']:.2f}"
                 for n in names if f"{n}_seconds" in r]  # fmt: skip
        lines.append(f"- {r['scene']}: " + "; ".join(parts))
    lines += ["", f"Machine: {platform.machine()}, {os.cpu_count()} cores."]
    (RESULTS / "dpm.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    """Run the scenes named (default: every scene the estimator table has) and write dpm.md."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--weights", type=Path, default=SHIPPED, help="folder of dpm-K.msgpack files")
    args = p.parse_args()
    names = args.scenes or sorted(f.stem for f in (RESULTS / "estimators").glob("*.json"))
    models = [args.weights / f"dpm-{k}.msgpack" for k in weight_ks(args.weights)]
    if not models:
        raise SystemExit(f"no dpm-K.msgpack in {args.weights}: train one with dpm-train first")
    write_markdown([run_scene(name, models) for name in names], models)


if __name__ == "__main__":
    main()
