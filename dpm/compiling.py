"""Numba compiling kernels during a render: how long it took, and a bar that moves meanwhile.

A method's first render compiles its kernels (a minute or more on two cores, once; later runs
load them from Numba's cache). The render's own bar stands still while that happens, so
`CompileWatch` listens to Numba's compile events and, with `show`, keeps a second bar moving
with the seconds spent compiling and the kernels done.
"""

from __future__ import annotations

import threading
import time
from types import TracebackType

from numba.core import event
from tqdm import tqdm

TICK = 0.5  # seconds between the bar's updates


class _Listener(event.Listener):
    """Counts the compiles in progress (nested: a kernel compiles the functions it calls)."""

    def __init__(self, watch: CompileWatch) -> None:
        self.watch = watch

    def on_start(self, ev: event.Event) -> None:
        """A compile began."""
        self.watch._begin()

    def on_end(self, ev: event.Event) -> None:
        """A compile ended."""
        self.watch._end()


class CompileWatch:
    """Context manager: `seconds` spent compiling Numba kernels and `kernels` compiled (the
    outermost ones) while it is open; with `show`, a bar on stderr while any compile runs."""

    def __init__(self, show: bool) -> None:
        self.show = show
        self.seconds = 0.0
        self.kernels = 0
        self._depth = 0
        self._since = 0.0
        self._lock = threading.Lock()
        self._stop = threading.Event()
        self._thread: threading.Thread | None = None
        self._listener = _Listener(self)

    def _begin(self) -> None:
        with self._lock:
            if self._depth == 0:
                self._since = time.monotonic()
            self._depth += 1

    def _end(self) -> None:
        with self._lock:
            self._depth -= 1
            if self._depth == 0:
                self.seconds += time.monotonic() - self._since
                self.kernels += 1

    def elapsed(self) -> float:
        """Seconds spent compiling so far, the compile in progress included."""
        with self._lock:
            running = time.monotonic() - self._since if self._depth else 0.0
            return self.seconds + running

    def _tick(self) -> None:
        bar = None
        while not self._stop.wait(TICK):
            with self._lock:
                busy = self._depth > 0
            if bar is None and not busy:
                continue
            if bar is None:
                bar = tqdm(
                    desc="compiling kernels (first run only)", unit="s", leave=False,
                    bar_format="{desc}: {n:.0f} s{postfix}",
                )  # fmt: skip
            bar.n = self.elapsed()
            bar.set_postfix_str(f"{self.kernels} kernels done", refresh=True)
        if bar is not None:
            bar.close()

    def __enter__(self) -> CompileWatch:
        event.register("numba:compile", self._listener)
        if self.show:
            self._thread = threading.Thread(target=self._tick, daemon=True)
            self._thread.start()
        return self

    def __exit__(
        self,
        kind: type[BaseException] | None,
        value: BaseException | None,
        trace: TracebackType | None,
    ) -> None:
        self._stop.set()
        if self._thread is not None:
            self._thread.join()
        event.unregister("numba:compile", self._listener)
