"""When this process started: a `--time` budget counts from there (interpreter start and
imports included), for dpm-render and for the peers the benchmarks time-box. Imports nothing
heavy, so a process that must not load SciPy or Numba (the LuxCore child) can use it."""

from __future__ import annotations

import os
import time

IMPORTED = time.monotonic()  # when dpm was imported (`dpm/__init__` imports this first)
# The most seconds from a process's start to dpm's import (the interpreter, site packages,
# NumPy) that are believed: /proc's start time is the fork's, so a process a shell exec'd
# after other work (the last command of `(make_scene; dpm-render --time 4)`) would count
# the shell's earlier work against its budget.
BEFORE_IMPORT = 2.0


def process_started() -> float:
    """`time.monotonic()` when this process started (Linux: from /proc, so interpreter start
    and imports count against a --time budget, but at most BEFORE_IMPORT seconds before dpm
    was imported; elsewhere: dpm's import)."""
    try:
        with open("/proc/self/stat") as f:
            ticks = int(f.read().rsplit(")", 1)[1].split()[19])  # field 22: starttime
        age = time.clock_gettime(time.CLOCK_BOOTTIME) - ticks / os.sysconf("SC_CLK_TCK")
        return max(time.monotonic() - max(0.0, age), IMPORTED - BEFORE_IMPORT)
    except (OSError, ValueError, IndexError, AttributeError):
        return IMPORTED
