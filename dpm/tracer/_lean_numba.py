"""Numba's first use without the optional imports that no dpm kernel needs.

The first kernel a process calls makes Numba load its implementation registries, and two of
them import optional libraries at import time: `numba.np.arraymath` imports `scipy.linalg`
to see whether BLAS is there (for `np.dot` and `np.linalg` in kernels, which dpm's do not
use), and `numba.core.typing.cffi_utils` builds a `cffi.FFI()` (cffi is installed for
pyoidn), which parses C with pycparser. Together they were about 0.17 s of a 2-s render's
start on the 2-core host (0.83 → 0.66 s to a first BVH, mean of eight processes each).
`load_registries_lean` imports those two Numba modules with the two optional imports made to
fail; the imports themselves are restored at once, so scipy.linalg and cffi import as usual
afterwards (pyoidn, scipy.spatial). What stays for the rest of the process: Numba's
`_HAVE_BLAS` flag reads False (`np.convolve` and `np.correlate` in kernels take a plain loop;
`np.dot` and `np.linalg` still find BLAS when first compiled) and kernels cannot call cffi
functions. Where the two were imported already, nothing is blocked. Only the `dpm-render`
console script calls it, first thing: its process runs no other code.
"""

from __future__ import annotations

import sys

OPTIONAL = ("scipy.linalg.cython_blas", "cffi")  # what the two registries try to import


def load_registries_lean() -> None:
    """Import Numba's array-math and cffi registries with OPTIONAL imports made to fail."""
    blocked = [name for name in OPTIONAL if name not in sys.modules]
    for name in blocked:
        sys.modules[name] = None  # `import name` raises ImportError without importing parents
    try:
        from numba.core.typing import cffi_utils  # noqa: F401
        from numba.np import arraymath  # noqa: F401
    finally:
        for name in blocked:
            if sys.modules.get(name, 0) is None:
                del sys.modules[name]
