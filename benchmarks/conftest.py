"""Shared benchmark plumbing: the --quick option and the BVH summary table."""

from __future__ import annotations

import datetime
import os

import numba

from common import RESULTS, cpu

BVH_ROWS: list[dict] = []  # one row per (scene, rays, engine), filled by test_bvh.py
BVH_TABLE = RESULTS / "bvh.md"


def pytest_addoption(parser) -> None:
    """--quick: the suite's minutes-long mode (CI) instead of the hours-long full run."""
    parser.addoption("--quick", action="store_true", help="run the benchmark suite's quick mode")


def pytest_terminal_summary(terminalreporter) -> None:
    """Print and save the BVH table: build time and rays/s per engine, with the ratios."""
    if not BVH_ROWS:
        return
    keys = list(dict.fromkeys((r["scene"], r["kind"]) for r in BVH_ROWS))
    by = {(r["scene"], r["kind"], r["engine"]): r for r in BVH_ROWS}
    lines = [
        f"Machine: {cpu()}, "
        f"numba threads {numba.get_num_threads()}; {datetime.date.today().isoformat()}",
        "",
        "| scene | set | rays | triangles | rays traced | dpm build s | embree build s "
        "| dpm Mrays/s | dpm 1-thread Mrays/s | embree 1-thread Mrays/s | dpm / embree | "
        "1 thread: dpm / embree |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for scene, kind in keys:
        d, d1, e = (by.get((scene, kind, engine)) for engine in ("dpm", "dpm-1thread", "embree"))

        def rate(row):
            return row["rays"] / row["trace_s"] / 1e6 if row else float("nan")

        lines.append(
            f"| {scene} | {d['set']} | {kind} | {d['triangles']} | {d['rays']} | "
            f"{d['build_s']:.4f} | "
            f"{e['build_s'] if e else float('nan'):.4f} | {rate(d):.2f} | {rate(d1):.2f} | "
            f"{rate(e):.2f} | {rate(d) / rate(e):.2f}x | {rate(d1) / rate(e):.2f}x |"
        )
    terminalreporter.write_line("")
    for line in lines:
        terminalreporter.write_line(line)
    if os.environ.get("DPM_BENCH_SAVE") == "1":
        BVH_TABLE.write_text(
            "# BVH: build time and closest-hit throughput, dpm (Numba) vs Embree (embreex)\n\n"
            "Made by `DPM_BENCH_SAVE=1 pytest benchmarks/test_bvh.py`. Incoherent rays: origins "
            "uniform in the scene's bounding box, directions uniform on the sphere. Camera rays: "
            "one per pixel of the scene's camera at 512 × 512, row after row. Both engines trace "
            "the same float32 rays through their Python calls (`dpm.tracer.intersect`, "
            "embreex's `run`), in turn, 5 rounds; medians. embreex traces one ray at a time on "
            "one thread; dpm uses all Numba threads, and one in the 1-thread column. Set: the "
            "example scenes, or the unseen-scene set (`benchmarks/scenes/make_unseen.py`).\n\n"
            + "\n".join(lines)
            + "\n"
        )
