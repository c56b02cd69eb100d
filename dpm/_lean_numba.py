"""Numba's start in `dpm-render` without what a warm render's kernels never use.

Numba fills its typing and lowering registries (some 250 modules' worth of declarations and
implementations) the first time a context is refreshed, and its cache refreshes the target
context before it loads each cached kernel. Only compiling reads the registries: a kernel
loaded from the cache is machine code plus its environment, and what it calls at run time is
Numba's runtime (NRT), initialised apart. `start_lean` changes two things, for the rest of
the process:

- **the cache's load initialises NRT only** and leaves the registries alone. A kernel that
  must compile still gets them: Numba's compiler refreshes both contexts itself before it
  starts. On the 2-core host (AMD EPYC, Zen 5) the refresh took 0.065 s of a 2-s render's
  start, and a warm render never compiles.
- **a refresh, or a cache load, runs with two optional imports made to fail** (a kernel's
  environment imports the Numba modules it took code from): `numba.np.arraymath` imports
  `scipy.linalg` to see whether BLAS is there (for `np.dot` and `np.linalg` in kernels, which
  dpm's do not use), and `numba.core.typing.cffi_utils` builds a `cffi.FFI()` (cffi is
  installed for pyoidn), which parses C with pycparser: together 0.17 s of a cold start, and
  scipy.linalg alone 0.07 s of a warm one. The imports themselves are restored at once, so
  scipy.linalg and cffi import as usual afterwards (pyoidn, scipy.spatial). What stays:
  Numba's `_HAVE_BLAS` flag reads False (`np.convolve` and `np.correlate` in kernels take a
  plain loop; `np.dot` and `np.linalg` still find BLAS when first compiled) and kernels cannot
  call cffi functions. Where the two were imported already, nothing is blocked.

Only the `dpm-render` console script calls it, first thing: its process runs no other code.
"""

from __future__ import annotations

import contextlib
import sys
from collections.abc import Iterator

from numba.core import base, caching
from numba.core.runtime.nrt import rtsys
from numba.core.typing import context

OPTIONAL = ("scipy.linalg.cython_blas", "cffi")  # what the registries try to import


@contextlib.contextmanager
def _optional_imports_failing() -> Iterator[None]:
    """Within: importing OPTIONAL (where not imported yet) raises ImportError."""
    blocked = [name for name in OPTIONAL if name not in sys.modules]
    for name in blocked:
        sys.modules[name] = None  # `import name` raises ImportError without importing parents
    try:
        yield
    finally:
        for name in blocked:
            if sys.modules.get(name, 0) is None:
                del sys.modules[name]


def _load_cached(self: caching.Cache, sig, target_context):
    """`Cache.load_overload` less its refresh of the registries (NRT initialised only)."""
    rtsys.initialize(target_context)
    # (a kernel's environment imports the modules it took code from: numba.np.arraymath too)
    with self._guard_against_spurious_io_errors(), _optional_imports_failing():
        return self._load_overload(sig, target_context)


def _refresh_lean(refresh):
    """`refresh` with the OPTIONAL imports failing."""

    def lean(self) -> None:
        with _optional_imports_failing():
            refresh(self)

    lean.lean = True
    return lean


def start_lean() -> None:
    """Load cached kernels without Numba's registries, and refresh them (where a kernel must
    compile) without scipy.linalg and cffi. Calling it again changes nothing."""
    caching.Cache.load_overload = _load_cached
    for cls in (base.BaseContext, context.BaseContext):  # lowering, typing
        if not getattr(cls.refresh, "lean", False):
            cls.refresh = _refresh_lean(cls.refresh)
