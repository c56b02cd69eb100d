"""The learned estimator (paper §4): pre-processing, Flax networks, inference and training.

JAX keeps compiled programs in a persistent cache (`~/.cache/dpm/jax`, or the folder in
JAX_COMPILATION_CACHE_DIR), so a second render or training run starts without recompiling.
"""

from __future__ import annotations

import os
from pathlib import Path

import jax

if not os.environ.get("JAX_COMPILATION_CACHE_DIR"):
    jax.config.update("jax_compilation_cache_dir", str(Path.home() / ".cache" / "dpm" / "jax"))
jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.2)
