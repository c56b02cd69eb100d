"""Seconds per named stage of a render or a benchmark, passed explicitly (no module globals).

Stages nest: time spent in a stage opened inside another counts for the inner stage only, so
`with watch("network"):` around an estimate that gathers inside `with watch("gather"):` splits
the two without subtracting by hand.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from contextlib import contextmanager


class Stopwatch:
    """Exclusive seconds per stage name: `with watch("gather"): ...`, then `watch.seconds`."""

    def __init__(self) -> None:
        self.seconds: dict[str, float] = {}
        self._inner: list[float] = []  # per open stage: seconds spent in stages inside it

    @contextmanager
    def __call__(self, stage: str) -> Iterator[None]:
        """Time the body as `stage`, less the stages timed inside it."""
        start = time.perf_counter()
        self._inner.append(0.0)
        try:
            yield
        finally:
            span = time.perf_counter() - start
            self.add(stage, span - self._inner.pop())
            if self._inner:
                self._inner[-1] += span

    def add(self, stage: str, seconds: float) -> None:
        """Count `seconds` towards `stage` (0 makes the stage appear in `seconds`)."""
        self.seconds[stage] = self.seconds.get(stage, 0.0) + seconds

    def get(self, stage: str) -> float:
        """Seconds counted for `stage` so far (0 if never timed)."""
        return self.seconds.get(stage, 0.0)

    def total(self) -> float:
        """Seconds over every stage."""
        return sum(self.seconds.values())
