"""What every benchmark shares: where things are, the estimator table's constants and points,
its committed references, the methods the benchmarks compare, and the one way to time them.

- `SCENES`, `RESULTS`, `M` (emitted paths of Table 1's first column), `WIDTH` (visible points:
  one per pixel of a WIDTH-wide image);
- `table_points`, `save_reference`, `load_reference`: the estimator table's visible points
  and its committed reference at them;
- `photon_methods`: the registry's methods that estimate caustics at visible points with an
  estimator of their own (pm, ppm, appm, dpm, ... and any method registered later);
- `timed_estimate`: an estimate and its seconds per stage, each timed call building its own
  photon index (so it pays for its tree, as a render does); `timed`: wall seconds of any call;
- `markdown_table`: a Markdown table; `save_records`: per-scene JSON records and the Markdown
  table rebuilt from all of them; `cpu`: the machine's CPU model and cores, for the results
  (the same benchmark gives different ratios on different CPUs).
"""

from __future__ import annotations

import json
import os
import platform
import time
from collections.abc import Callable
from pathlib import Path
from statistics import median
from typing import Any

import numpy as np

from dpm.estimators.reference import Reference
from dpm.io import atomic
from dpm.methods import METHODS
from dpm.methods.base import Method, NearestPhotons, Progressive
from dpm.scene import Scene
from dpm.stopwatch import Stopwatch
from dpm.tracer import BVH, PhotonMap, VisiblePoints, trace_visible_points

HERE = Path(__file__).parent
SCENES = HERE.parent / "examples" / "scenes"
RESULTS = HERE / "results"
M = 700_000  # emitted photon paths: the glass egg's ~15k caustic photons, as in the paper
WIDTH = 128  # visible points: one per pixel of a WIDTH-wide image, seed 0
PM_KS = (50, 500)  # the K of the paper's PM baselines
TOTAL = "total"  # timed_estimate's key for the wall seconds of the whole call


def cpu_info() -> dict[str, str]:
    """/proc/cpuinfo's fields of the first CPU (empty where there is none)."""
    info: dict[str, str] = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                key, _, value = line.partition(":")
                info.setdefault(key.strip(), value.strip())
    except OSError:
        pass
    return info


def cpu() -> str:
    """This machine's CPU (/proc/cpuinfo's model name, family and model where there is one:
    a virtual machine may hide the rest of the name), cores and widest vector extension."""
    info = cpu_info()
    name = info.get("model name") or platform.processor() or platform.machine()
    model = [f"{k} {info[k]}" for k in ("cpu family", "model") if k in info]
    flags = set(info.get("flags", "").split())
    vectors = next((n for n, f in VECTORS if f in flags), "vector width unknown")
    return f"{name} ({'; '.join([*model, platform.machine()])}), {os.cpu_count()} cores, {vectors}"


VECTORS = (("AVX-512", "avx512f"), ("AVX2", "avx2"), ("AVX", "avx"), ("SSE2", "sse2"))


def geomean(values) -> float:
    """Geometric mean of positive values (NaN for none)."""
    return float(np.exp(np.mean(np.log(values)))) if len(values) else float("nan")


def table_points(scene: Scene, bvh: BVH) -> VisiblePoints:
    """The table's visible points: one per pixel of a WIDTH-wide image, seed 0."""
    camera = scene.camera.with_resolution(WIDTH, WIDTH * scene.camera.height // scene.camera.width)
    return trace_visible_points(scene, bvh, camera, 1, 0, (0, camera.height))


def save_reference(name: str, ref: Reference) -> None:
    """Keep a scene's reference radiance at `table_points` (committed, so later tables need
    no rerun): results/references_radiance/NAME.npz."""
    path = RESULTS / "references_radiance" / f"{name}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    np.savez_compressed(path, radiance=ref.radiance, noise=ref.noise, paths=ref.n_paths)


def load_reference(name: str) -> tuple[np.ndarray, float]:
    """(N, 3) reference caustic radiance at `table_points` and its noise, as saved."""
    with np.load(RESULTS / "references_radiance" / f"{name}.npz") as f:
        return f["radiance"], float(f["noise"])


def photon_methods() -> dict[str, type[Method]]:
    """Registered methods that estimate caustics at visible points with their own estimator,
    in registry order: the K-nearest ones (NearestPhotons) and the progressive ones. A method
    that reuses another's estimator (hybrid is dpm's) or renders per pixel (sppm) is left out."""
    return {
        name: cls
        for name, cls in METHODS.items()
        if cls.at_points
        and ("estimator_class" in vars(cls) or "make_estimator" in vars(cls))
        and issubclass(cls, NearestPhotons | Progressive)
    }


def needed_k(estimator: Any) -> int:
    """Photons an estimator needs at least: its K (K-nearest estimators), else 1."""
    return int(getattr(estimator, "k", None) or 1)


def timed(fn: Callable[[], Any], rounds: int = 1) -> tuple[Any, list[float]]:
    """fn()'s (last) result and the wall seconds of each of `rounds` calls."""
    seconds = []
    for _ in range(rounds):
        start = time.perf_counter()
        result = fn()
        seconds.append(time.perf_counter() - start)
    return result, seconds


def linear_fit(lo: tuple[int, float], hi: tuple[int, float]) -> tuple[float, float]:
    """(fixed seconds, seconds per sample per pixel) of the line through two timed renders
    (spp, seconds)."""
    per_spp = max((hi[1] - lo[1]) / (hi[0] - lo[0]), 1e-6)
    return lo[1] - per_spp * lo[0], per_spp


def secant_spp(spp: int, seconds: float, fixed: float, budget: float) -> int:
    """Samples per pixel that should take `budget` seconds, after spp took `seconds`: the
    line through that render and the fit's fixed seconds, kept within 4× of spp (a noisy
    fixed cost near `seconds` once asked for 79,119 spp)."""
    rate = max(seconds - fixed, 1e-3) / spp
    return min(max(round((budget - fixed) / rate), spp // 4, 1), 4 * spp)


def timed_estimate(
    estimator: Any,
    points: VisiblePoints,
    photons: PhotonMap,
    *,
    repeats: int = 1,
    warmup: bool = False,
) -> tuple[np.ndarray, dict[str, float]]:
    """(N, 3) radiance of estimator at the points, and the median over `repeats` calls of
    each stage's seconds (the estimator's own stages: "gather", "estimate" or "network")
    and of TOTAL, the wall seconds of the whole call.

    Every call gets the bare photon map, so it builds its own index as a render does (the
    K-nearest estimators their photon tree, timed as "gather"; the progressive ones their
    point tree); handing them a prebuilt PhotonIndex would time the K-nearest ones without
    their tree and charge the progressive ones for a tree they never query. `warmup` first
    runs one untimed call (JIT compilation of Numba and XLA).
    """
    if warmup:
        estimator.estimate(points, photons)
    runs = []
    for _ in range(repeats):
        watch = Stopwatch()
        with watch(TOTAL):  # exclusive: what the estimator's own stages leave out
            radiance = estimator.estimate(points, photons, watch)
        runs.append(watch.seconds)
    stages = dict.fromkeys(s for run in runs for s in run if s != TOTAL)
    seconds = {s: median(run.get(s, 0.0) for run in runs) for s in stages}
    seconds[TOTAL] = median(sum(run.values()) for run in runs)
    return radiance, seconds


def median_or_nan(values: list[float]) -> float:
    """Median of values, NaN when empty."""
    return float(median(values)) if values else float("nan")


def markdown_table(head: list[str], rows: list[list[str]]) -> list[str]:
    """The lines of a Markdown table."""
    return ["| " + " | ".join(head) + " |", "|" + "---|" * len(head)] + [
        "| " + " | ".join(r) + " |" for r in rows
    ]


def save_records(
    folder: Path,
    names: list[str],
    run: Callable[[str], dict],
    markdown: Callable[[list[dict]], str],
    table: Path,
) -> None:
    """Run each named scene, keep its record as folder/NAME.json, then rebuild `table` (the
    Markdown of every record in the folder, also scenes run earlier) and print it."""
    folder.mkdir(parents=True, exist_ok=True)
    for name in names:
        record = run(name)
        with atomic(folder / f"{name}.json") as tmp:
            tmp.write_text(json.dumps(record, indent=1))
    text = markdown([json.loads(f.read_text()) for f in sorted(folder.glob("*.json"))])
    with atomic(table) as tmp:
        tmp.write_text(text)
    print(text)


def passes_text(row: dict) -> str:
    """A row's `auto` passes, with its paths per pixel where they differ (passes of whole
    pixels take several; rows recorded before that have no "spp")."""
    spp = row.get("spp", row["passes"])
    return str(row["passes"]) + (f" ({spp} spp)" if spp != row["passes"] else "")
