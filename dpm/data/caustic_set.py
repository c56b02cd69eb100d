"""The caustic filter's training set (`[data] kind = "caustic"`): per procedural scene, `auto`'s
caustic statistics at a ladder of pass counts and an independent long render as the target.

A shard holds, for each pass count P of `passes`, what `dpm.caustic.stats` makes of the
render after P passes (`P/features`, `P/candidates`, `P/own` and `P/count`: the estimate the
filter is held around and its photons, `clamp_centre`; `P/other` and `P/other_count`: the
pixel's own estimate and its photons, the hull's second interval, `clamp_to_centre`;
`P/photon`), and
`target`: the extrapolated estimate (`dpm.caustic.stats.extrapolated`, SPPM's blur cancelled
to second order) of a render of `target_passes` passes with another seed. The target is
noisy, but its noise is independent of the inputs', so an L2 loss against it has the same
minimiser as against the truth (Noise2Noise); the render's own estimate after that many
passes, the target before, kept its blur, so a filter trained on it learned to keep blur.
Scenes are `dpm.data.procedural`'s (disjoint from the unseen-scene set, which has a generator
of its own), at `width`² pixels.
"""

from __future__ import annotations

import time
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    from dpm.caustic.stats import CausticStats
    from dpm.data.dataset import DataConfig
    from dpm.scene import Scene
    from dpm.tracer import BVH

# `P/name` per pass count; `other`, `other_count`: the hull's second interval (stats.HULL_CLAMP)
PASS_ARRAYS = ("features", "candidates", "own", "count", "other", "other_count", "photon")


def caustic_ladder(
    scene: Scene, bvh: BVH, seed: int, ladder: tuple[int, ...]
) -> list[CausticStats]:
    """`auto`'s caustic statistics (component caustic, two aimed photon paths per pixel per
    pass) after each pass count of `ladder` (ascending), from one render with `seed`."""
    from dpm.methods.auto import AIMED_PHOTONS_PER_PIXEL, Auto, Passes
    from dpm.options import RenderOptions
    from dpm.stopwatch import Stopwatch

    camera = scene.camera
    n = max(ladder)
    # aimed paths' count for every scene (`auto.paths_per_pixel` gives 4 where nothing is
    # aimed): the shipped weights were trained so; 49 of the set's 160 scenes have lights
    # partly inside the glass's sphere, where auto takes between 2 and 4
    per_pass = round(AIMED_PHOTONS_PER_PIXEL * camera.width * camera.height)
    options = RenderOptions(method="auto", component="caustic", spp=n, photons=n * per_pass,
                            seed=seed, network=False, progress=False)  # fmt: skip
    passes = Passes(Auto(scene, options), bvh, camera, Stopwatch(), time.monotonic())
    out = []
    while passes.j < n:
        passes.run_pass()
        if passes.j in ladder:
            out.append(passes.caustic_stats())
    return out


def pass_arrays(s: CausticStats) -> dict[str, np.ndarray]:
    """A shard's arrays for one pass count ({name: array} for PASS_ARRAYS, float32, images
    h × w × ...): the filter's inputs and the two intervals the render holds it within."""
    from dpm.caustic.stats import candidates, clamp_centre, clamp_other, features

    centre, count = clamp_centre(s)  # what the render holds the filter around
    other, other_count = clamp_other(s)
    image, plane = (s.h, s.w, 3), (s.h, s.w)
    return {"features": features(s), "candidates": candidates(s),
            "own": centre.reshape(image).astype(np.float32),
            "count": count.reshape(plane).astype(np.float32),
            "other": other.reshape(image).astype(np.float32),
            "other_count": other_count.reshape(plane).astype(np.float32),
            "photon": np.float32(s.photon_value())}  # fmt: skip


def make_caustic_shard(config: DataConfig, index: int, threads: int | None = None) -> tuple:
    """Make scene `index` and its caustic-filter shard on `threads` Numba threads (default:
    all); returns its manifest entry and its files, {path relative to `out`: bytes}."""
    import numba

    from dpm.caustic.stats import extrapolated
    from dpm.data.dataset import npz_bytes, scene_files, shard_name
    from dpm.tracer import build_bvh

    numba.set_num_threads(threads or numba.config.NUMBA_NUM_THREADS)
    start = time.perf_counter()
    scene, files = scene_files(config, index, "dpm caustic-filter training scene")
    bvh = build_bvh(scene)
    base = (config.seed * 7919 + index) * 4
    ladder = tuple(sorted(config.passes))
    arrays = {}
    for p, s in zip(ladder, caustic_ladder(scene, bvh, base + 1, ladder), strict=True):
        arrays.update({f"{p}/{name}": a for name, a in pass_arrays(s).items()})
    (target,) = caustic_ladder(scene, bvh, base + 2, (config.target_passes,))
    sharp = extrapolated(target.wide, target.narrow, target.blur_ratio)
    arrays["target"] = sharp.reshape(target.h, target.w, 3).astype(np.float32)
    shard = f"shards/{shard_name(index)}.npz"
    files[shard] = npz_bytes(arrays)
    lit = float(np.mean(arrays["target"]))
    entry = {"index": index, "file": shard, "points": target.h * target.w,
             "passes": list(ladder), "target_mean": lit,
             "seconds": time.perf_counter() - start}  # fmt: skip
    return entry, files


def load_caustic_shard(out: Path, entry: dict, ladder: tuple[int, ...]) -> dict[str, np.ndarray]:
    """A caustic-filter shard's arrays ({'P/name': array} for P in ladder, and 'target')."""
    from dpm.errors import InputError

    path = Path(out) / entry["file"]
    try:
        with np.load(path) as f:
            arrays = {f"{p}/{n}": f[f"{p}/{n}"] for p in ladder for n in PASS_ARRAYS}
            arrays["target"] = f["target"]
    except Exception as e:  # OSError, KeyError, BadZipFile, zlib.error, ValueError alike
        raise InputError(f"{path}: unreadable training shard ({type(e).__name__})") from None
    return arrays
