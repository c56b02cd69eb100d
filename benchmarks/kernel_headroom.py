"""How much any per-point choice of kernel could gain over the tuned global radius: an oracle.

    python benchmarks/kernel_headroom.py [SCENE ...] [--budgets 700000 7000000] [--maps 10 6]

nppm (and DPM) choose a kernel per visible point from its photons. Before asking a network
for a gain, this measures the most such a choice can give on the estimator table's scenes.
Per scene and budget, at PPM-best's setting (initial radius R₀, paths per pass) and on
several independent photon maps (seed 0 is the table's map):

- one gather at the widest disc gives, per visible point, PPM estimates over nested discs of
  radius s·R (s = 0.5 … 2.83; one PPM radius schedule, driven by the s = 1 disc, so s = 1 is
  PPM-best itself) and, in the discs s ≥ 1.41, kernels narrowed across one of four tangent
  directions (nppm's Gaussian with precision 12 across, uniform along; `dpm.density.shaped`);
- *per-point oracle*: each point takes the candidate whose squared error against the
  reference, averaged over maps 1 … K, is least, and is scored on map 0. It knows each
  candidate's expected error at each point from K maps and the reference, far more than a
  network that sees map 0's photons, so it bounds what a per-point choice from this family
  can gain (short of knowing map 0's own noise);
- *global affine*: the best single affine pair w·L(sᵢ) + (1 − w)·L(sⱼ) over the scene
  (Richardson-style bias cancellation), chosen on map 0 itself (so it flatters).

Ratios are over the best tuned classic of the estimator table (PM-50, PM-500, PPM-, APPM- and
CPPM-best where tabled; below 1 wins; issue 19 asks a learned method for ≤ 0.8). Needs
results/estimators/SCENE.json and references_radiance/SCENE.npz; writes
results/kernel_headroom/SCENE.json and results/kernel_headroom.md.
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
from functools import partial

import numpy as np
from tables import least_error

from common import RESULTS, SCENES, M, cpu, load_reference, save_records, table_points
from dpm import load_scene
from dpm.density.base import in_plane, reflected, tangent_frame
from dpm.density.gather import PointIndex
from dpm.density.progressive import ALPHA
from dpm.density.shaped import normaliser
from dpm.metrics import rmse
from dpm.tracer import PhotonMap, VisiblePoints, build_bvh, trace_photons

OUT = RESULTS / "kernel_headroom"
SCALES = (0.5, 0.71, 1.0, 1.41, 2.0, 2.83)  # disc radius × PPM's R
NARROWED = (1.41, 2.0, 2.83)  # discs that also get the anisotropic kernels
ANGLES = (0.0, np.pi / 4, np.pi / 2, 3 * np.pi / 4)  # directions the kernel narrows across
PRECISION = 12.0  # across the direction (σ ≈ 0.29 of the disc's radius), 0 along it
WEIGHTS = np.linspace(-2.0, 3.0, 26)  # affine weights tried for the global pairs


def candidates() -> list[tuple[float, float | None]]:
    """(scale, angle or None for the uniform disc) of every kernel the oracle may pick."""
    return [(s, None) for s in SCALES] + [(s, a) for s in NARROWED for a in ANGLES]


def kernel_estimates(
    points: VisiblePoints, photons: PhotonMap, radius: float, per_pass: int
) -> np.ndarray:
    """(C, N, 3) float32 camera-weighted caustic radiance of each candidate kernel at the
    visible points (0 where a point missed), PPM's schedule from initial radius `radius`."""
    hit = np.flatnonzero(points.hit)
    index = PointIndex(points.position[hit], points.normal[hit])
    t, b = tangent_frame(index.normal)
    n, kernels = len(hit), candidates()
    z = float(normaliser(np.array([PRECISION]), np.array([0.0]))[0])
    r = np.full(n, radius)
    count = np.zeros(n)
    tau = np.zeros((len(kernels), n, 3))
    paths = 0
    for part in photons.split(per_pass):
        pairs = index.within(part, r * max(SCALES))
        p = pairs.point
        rel = pairs.distance / r[p]
        offset = part.position[pairs.photon].astype(np.float64) - index.position[p]
        ab = in_plane(offset, t[p], b[p]) / r[p, None]
        flux = part.flux[pairs.photon].astype(np.float64) * part.n_paths
        found = np.bincount(p[rel < 1], minlength=n).astype(np.float64)
        grown = count + ALPHA * found
        ratio = np.divide(grown, count + found, out=np.ones(n), where=found > 0)
        for i, (s, angle) in enumerate(kernels):
            weight = (rel < s).astype(np.float64)
            if angle is not None:  # nppm's kernel, precision across `angle`, 0 along it
                across = (ab[:, 0] * np.cos(angle) + ab[:, 1] * np.sin(angle)) / s
                weight *= np.pi * np.exp(-0.5 * PRECISION * across**2) / z
            phi = np.stack([np.bincount(p, flux[:, c] * weight, minlength=n) for c in range(3)])
            tau[i] = (tau[i] + phi.T) * ratio[:, None]
        r = r * np.sqrt(ratio)
        count = grown
        paths += part.n_paths
    out = np.zeros((len(kernels), len(points), 3), np.float32)
    w = points.throughput[hit]
    for i, (s, _) in enumerate(kernels):
        e = tau[i] / (np.pi * (s * r[:, None]) ** 2 * paths)
        out[i, hit] = w * reflected(points.albedo[hit], e)
    return out


def oracle(estimates: np.ndarray, others: list[np.ndarray], reference: np.ndarray) -> np.ndarray:
    """(N, 3) map 0's estimates (C, N, 3) taking per point the candidate of least mean squared
    error over the other maps' estimates (each (C, N, 3)) against reference (N, 3)."""
    mse = np.mean([((o - reference[None]) ** 2).sum(-1) for o in others], axis=0)
    return np.take_along_axis(estimates, mse.argmin(0)[None, :, None], 0)[0]


def run_scene(name: str, budgets: list[int], maps: list[int]) -> dict:
    """The scene's record: per budget the ratios of each oracle to the best tuned classic."""
    table = json.loads((RESULTS / "estimators" / f"{name}.json").read_text())
    reference, noise = load_reference(name)
    scene = load_scene(SCENES / f"{name}.obj")
    bvh = build_bvh(scene)
    points = table_points(scene, bvh)
    hit = points.hit
    ref = reference * points.throughput

    def score(estimate: np.ndarray) -> float:  # as caustic_rmse: camera-weighted, hit points
        return rmse(estimate[hit], ref[hit])

    kernels = candidates()
    uniform = [i for i, (_, a) in enumerate(kernels) if a is None]
    rows = []
    for n, k in zip(budgets, maps, strict=True):
        row = next(b for b in table["budgets"] if b["paths"] == n)
        best = row["ppm_best"]
        est = [
            kernel_estimates(
                points, trace_photons(scene, bvh, n, seed=seed, caustic_only=True),
                best["radius"], best["photons_per_pass"],
            )
            for seed in range(k)
        ]  # fmt: skip
        classic = least_error(row)
        few = est[1 : 1 + min(4, k - 1)]
        pairs = itertools.combinations(uniform, 2)
        affine = min(score(w * est[0][i] + (1 - w) * est[0][j]) for i, j in pairs for w in WEIGHTS)
        out = {
            "paths": n, "maps": k, "best_classic": classic, "ppm_best": row["ppm_best"]["rmse"],
            "scales": {str(SCALES[i]): score(est[0][i]) for i in uniform},
            "oracle_scale_few": score(oracle(est[0][uniform], [e[uniform] for e in few], ref)),
            "oracle_scale": score(oracle(est[0][uniform], [e[uniform] for e in est[1:]], ref)),
            "oracle_all": score(oracle(est[0], est[1:], ref)),
            "global_affine": affine,
        }  # fmt: skip
        print(name, n, {k: v for k, v in out.items() if k != "scales"}, flush=True)
        rows.append(out)
    return {
        "scene": name, "reference_noise": noise, "budgets": rows,
        "machine": cpu(),
        "date": datetime.date.today().isoformat(),
    }  # fmt: skip


def markdown(records: list[dict]) -> str:
    """results/kernel_headroom.md from the scene records."""
    lines = [
        "# Headroom of per-point kernel choice (an oracle)",
        "",
        "Made by `python benchmarks/kernel_headroom.py` (see its docstring). Caustic RMSE at",
        "the estimator table's points against its reference, each divided by the best tuned",
        "classic (*best classic*, absolute). PPM-best: the table's. *Scales*: one disc scale",
        "s × PPM-best's radius everywhere. *Oracle*: per point, the kernel of least squared",
        "error over K other photon maps (scored on map 0): disc scales only, with the first 4",
        "maps or all K, and with the anisotropic kernels too. *Affine*: the best global pair",
        "of scales w·L(sᵢ) + (1 − w)·L(sⱼ), chosen on map 0 itself.",
        "",
        "| scene | paths | best classic | PPM-best | s=0.71 | s=1.41 | oracle scale (4 maps) | "
        "oracle scale (K) | oracle + anisotropic (K) | K | affine | ref noise |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for rec in records:
        for row in rec["budgets"]:
            c = row["best_classic"]
            lines.append(
                f"| {rec['scene']} | {row['paths']:,} | {c:.4f} | {row['ppm_best'] / c:.2f} | "
                f"{row['scales']['0.71'] / c:.2f} | {row['scales']['1.41'] / c:.2f} | "
                f"{row['oracle_scale_few'] / c:.2f} | {row['oracle_scale'] / c:.2f} | "
                f"{row['oracle_all'] / c:.2f} | {row['maps'] - 1} | "
                f"{row['global_affine'] / c:.2f} | {rec['reference_noise']:.4f} |"
            )
    machines = sorted({f"{r['machine']} ({r['date']})" for r in records})
    return "\n".join([*lines, "", f"Machine: {'; '.join(machines)}.", ""])


def main() -> None:
    """Run the scenes asked for, then rebuild the Markdown table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", help="example scene names (default: every tabled one)")
    p.add_argument("--budgets", type=int, nargs="+", default=[M, 10 * M])
    p.add_argument("--maps", type=int, nargs="+", default=[10, 6], help="per budget (≥ 2)")
    args = p.parse_args()
    if len(args.maps) != len(args.budgets) or min(args.maps) < 2:
        p.error("--maps: one count of at least 2 per budget")
    names = args.scenes or sorted(f.stem for f in (RESULTS / "estimators").glob("*.json"))
    run = partial(run_scene, budgets=args.budgets, maps=args.maps)
    save_records(OUT, names, run, markdown, RESULTS / "kernel_headroom.md")


if __name__ == "__main__":
    main()
