"""Peak memory and time of gathering: 10M photons × 262,144 visible points (512²).

    python benchmarks/gather_memory.py

Photons lie uniformly on a unit square; each stage runs in a fresh process so that its peak
resident memory (ru_maxrss) is its own. Writes benchmarks/results/gather_memory.md.
"""

from __future__ import annotations

import json
import resource
import subprocess
import sys
import time

import numpy as np

from common import RESULTS, cpu
from dpm.density import gather

OUTPUT = RESULTS / "gather_memory.md"
N_PHOTONS, N_POINTS = 10_000_000, 512 * 512


def data():
    from dpm.tracer import PhotonMap, VisiblePoints

    rng = np.random.default_rng(0)
    pos = np.zeros((N_PHOTONS, 3), np.float32)
    pos[:, :2] = rng.random((N_PHOTONS, 2), dtype=np.float32)
    up = np.zeros((N_PHOTONS, 3), np.float32)
    up[:, 2] = 1
    flux = np.full((N_PHOTONS, 3), 1 / N_PHOTONS, np.float32)
    photons = PhotonMap(pos, up, flux, up, np.ones(N_PHOTONS, bool),
                        np.ones(N_PHOTONS, np.uint16), np.arange(N_PHOTONS), N_PHOTONS)  # fmt: skip
    p = np.zeros((N_POINTS, 3), np.float32)
    p[:, :2] = rng.random((N_POINTS, 2), dtype=np.float32)
    n = np.zeros((N_POINTS, 3), np.float32)
    n[:, 2] = 1
    ones = np.ones((N_POINTS, 3), np.float32)
    points = VisiblePoints(p, n, ones, ones, 0 * ones, np.ones(N_POINTS, bool),
                           np.arange(N_POINTS, dtype=np.int32), np.arange(N_POINTS))  # fmt: skip
    return photons, points


def stage(name: str) -> dict:
    from dpm.estimators import PM, PPM

    photons, points = data()
    base = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    start = time.perf_counter()
    if name.startswith("pm"):
        PM(k=int(name[2:])).estimate(points, photons)
    else:  # 10 passes of 1M paths, radius ≈ 2.5 photon spacings at the start
        PPM(radius=0.0008, photons_per_pass=1_000_000).estimate(points, photons)
    peak = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024
    return {"stage": name, "seconds": time.perf_counter() - start, "data_mib": base,
            "peak_mib": peak}  # fmt: skip


def main() -> None:
    if len(sys.argv) == 3 and sys.argv[1] == "--stage":
        print(json.dumps(stage(sys.argv[2])))
        return
    rows = []
    for name in ("pm50", "pm500", "ppm"):
        out = subprocess.run([sys.executable, __file__, "--stage", name], check=True,
                             capture_output=True, text=True).stdout  # fmt: skip
        rows.append(json.loads(out.splitlines()[-1]))
        print(rows[-1], flush=True)
    lines = [
        "# Gathering: 10M photons × 262,144 visible points",
        "",
        "Made by `python benchmarks/gather_memory.py`. *data*: peak resident memory after",
        "building the inputs (photon map ≈ 0.5 GB); *peak*: after the estimate. Points are",
        f"answered {gather.POINTS_PER_CHUNK:,} at a time (K nearest); PPM's pairs come from",
        "hashed grids over the points, every photon at once (`dpm.tracer.point_grid`).",
        "",
        "| estimator | seconds | data MiB | peak MiB | added by gathering MiB |",
        "|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(f"| {r['stage']} | {r['seconds']:.1f} | {r['data_mib']:.0f} "
                     f"| {r['peak_mib']:.0f} | {r['peak_mib'] - r['data_mib']:.0f} |")  # fmt: skip
    lines += ["", f"Machine: {cpu()}."]
    OUTPUT.write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
