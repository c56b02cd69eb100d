"""Shared benchmark plumbing: median timings through pytest-benchmark, and a summary table."""

from __future__ import annotations

import datetime
import os
import time
from collections.abc import Callable

import numba

from common import RESULTS, cpu

BVH_ROWS: list[dict] = []  # one row per (scene, engine), filled by test_bvh.py
BVH_TABLE = RESULTS / "bvh.md"


def pytest_addoption(parser) -> None:
    """--quick: the suite's minutes-long mode (CI) instead of the hours-long full run."""
    parser.addoption("--quick", action="store_true", help="run the benchmark suite's quick mode")


def median_seconds(benchmark, fn: Callable[[], object], rounds: int) -> float:
    """Median wall seconds of fn over `rounds` runs after one warm-up (compilation excluded)."""
    if not benchmark.enabled:  # --benchmark-disable: one run, timed by hand
        fn()
        start = time.perf_counter()
        benchmark(fn)
        return time.perf_counter() - start
    benchmark.pedantic(fn, rounds=rounds, warmup_rounds=1, iterations=1)
    return benchmark.stats.stats.median


def pytest_terminal_summary(terminalreporter) -> None:
    """Print and save the BVH table: build time and rays/s per engine, with the ratio."""
    if not BVH_ROWS:
        return
    scenes = list(dict.fromkeys(r["scene"] for r in BVH_ROWS))
    by = {(r["scene"], r["engine"]): r for r in BVH_ROWS}
    lines = [
        f"Machine: {cpu()}, "
        f"numba threads {numba.get_num_threads()}; {datetime.date.today().isoformat()}",
        "",
        "| scene | triangles | rays | dpm build s | embree build s | dpm Mrays/s "
        "| dpm 1-thread Mrays/s | embree Mrays/s | dpm / embree |",
        "|---|---|---|---|---|---|---|---|---|",
    ]
    for s in scenes:
        d, d1, e = by.get((s, "dpm")), by.get((s, "dpm-1thread")), by.get((s, "embree"))
        if d is None:
            continue

        def rate(row):
            return row["rays"] / row["trace_s"] / 1e6 if row else float("nan")

        ratio = rate(d) / rate(e) if e else float("nan")
        lines.append(
            f"| {s} | {d['triangles']} | {d['rays']} | {d['build_s']:.4f} | "
            f"{e['build_s'] if e else float('nan'):.4f} | {rate(d):.2f} | {rate(d1):.2f} | "
            f"{rate(e):.2f} | {ratio:.2f}x |"
        )
    terminalreporter.write_line("")
    for line in lines:
        terminalreporter.write_line(line)
    if os.environ.get("DPM_BENCH_SAVE") == "1":
        BVH_TABLE.write_text(
            "# BVH: build time and closest-hit throughput, dpm (Numba) vs Embree (embreex)\n\n"
            "Made by `DPM_BENCH_SAVE=1 pytest benchmarks/test_bvh.py`. Rays are incoherent: "
            "origins uniform in the scene's bounding box, directions uniform on the sphere; "
            "both engines trace the same float32 rays. embreex traces one ray at a time on one "
            "thread; dpm uses all Numba threads (and one thread in the 1-thread column).\n\n"
            + "\n".join(lines)
            + "\n"
        )
