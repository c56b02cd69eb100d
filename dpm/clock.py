"""When this process started: a `--time` budget counts from there (interpreter start and
imports included), for dpm-render and for the peers the benchmarks time-box. Imports nothing
heavy, so a process that must not load SciPy or Numba (the LuxCore child) can use it."""

from __future__ import annotations

import os
import time


def process_started() -> float:
    """`time.monotonic()` when this process started (Linux: from /proc, so interpreter start
    and imports count against a --time budget; elsewhere: now)."""
    try:
        with open("/proc/self/stat") as f:
            ticks = int(f.read().rsplit(")", 1)[1].split()[19])  # field 22: starttime
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK")
        return time.monotonic() - max(0.0, age)
    except (OSError, ValueError, IndexError, AttributeError):
        return time.monotonic()
