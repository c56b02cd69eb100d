"""Python's garbage collector, paused while `dpm-render` starts.

Starting creates some hundred thousand objects that live as long as the process (the modules
of NumPy, Numba, llvmlite and cffi; Numba's typing and lowering registries, loaded at the first
kernel call) and next to no garbage. The collector, triggered by allocation counts, walks all
of them again and again meanwhile: on the 2-core host (AMD EPYC, Zen 5) pyoidn's import took
50-70 ms inside a render against 17 ms with the collector paused, and a 2-s render of the
diffuse control room started its passes 0.04 s later. `pause` (the console script, first
thing) turns the collector off; `resume` (once the renderer's kernels and the denoiser are
loaded) moves every object alive into the permanent generation (`gc.freeze`: never walked
again) and turns it back on, so what the passes leave behind is collected as usual, at the
cost of the new objects only. A caller that never paused it (a library user's process) is
left as it was: `resume` does nothing there.
"""

from __future__ import annotations

import gc

_paused = False  # whether `pause` turned the collector off and `resume` has not yet


def pause() -> None:
    """Turn the collector off until `resume` (where it is on)."""
    global _paused
    if gc.isenabled():
        gc.disable()
        _paused = True


def resume() -> None:
    """Freeze what is alive and turn the collector back on, where `pause` turned it off."""
    global _paused
    if _paused:
        gc.freeze()
        gc.enable()
        _paused = False
