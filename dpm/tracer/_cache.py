"""Numba's on-disk kernel cache: invalidated when a kernel source changed (once, when
`dpm.tracer` is imported), and whether it holds compiled kernels."""

from __future__ import annotations

import hashlib
import os
from pathlib import Path


def drop_stale_kernel_cache() -> None:
    """Delete Numba's cached kernels when any kernel source changed.

    Numba re-validates a cached function against its own file only, but our kernels inline
    functions from other files (traversal into direct lighting, say): after an edit or upgrade
    a stale kernel with the same signature would run old code. One stamp covers them all.
    """
    here = Path(__file__).parent
    sources = sorted(here.glob("*.py")) + [here.parent / "scene.py"]
    digest = hashlib.sha256(b"".join(p.read_bytes() for p in sources)).hexdigest()
    cache = here / "__pycache__"
    stamp = cache / "kernels.sha256"
    try:
        if stamp.is_file() and stamp.read_text() == digest:
            return
        for f in [*cache.glob("*.nbi"), *cache.glob("*.nbc")]:
            f.unlink()
        cache.mkdir(exist_ok=True)
        stamp.write_text(digest)
    except OSError:
        pass  # a read-only install: Numba then caches elsewhere or compiles each run


def kernels_cached() -> bool:
    """Whether Numba's cache holds compiled tracer kernels (beside the sources, or under
    NUMBA_CACHE_DIR, which mirrors the source folders)."""
    place = Path(os.environ.get("NUMBA_CACHE_DIR") or Path(__file__).parent / "__pycache__")
    return place.is_dir() and next(place.rglob("traverse.*.nbi"), None) is not None


drop_stale_kernel_cache()
