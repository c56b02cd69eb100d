"""Running a progressive estimator (PPM, APPM) pass by pass, with checkpoints.

A progressive estimator has `state(n, radius) -> state` (its own `start(n, radius)`, or the
held-out choice of scale without a radius: `dpm.density.held_out`), `check()` and
`photons_per_pass`; its state has `add(index, pass_photons, watch)`, `irradiance()`, `reach`
(the radii the next pass is searched within) and, from `Statistics`, `arrays()` and
`from_arrays()`. Passes are consecutive slices of one photon stream
(`trace_photons(first_path=…)`), so the statistics after pass j depend only on the seed, and a
run resumed from a checkpoint ends bit-identical to one that never stopped.
"""

from __future__ import annotations

import hashlib
import time
import zipfile
from dataclasses import dataclass, fields
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from dpm.density.base import reflected
from dpm.density.gather import PhotonIndex, PointIndex
from dpm.errors import InputError
from dpm.io import atomic
from dpm.scene import Scene
from dpm.stopwatch import Stopwatch
from dpm.tracer import BVH, PhotonMap, VisiblePoints, trace_photons

ALPHA = 0.7  # fraction of new photons kept each pass (the paper's and Hachisuka's choice)
CHECKPOINT_SECONDS = 30.0  # a run writes its statistics at most this often (and at the end)


def pass_seed(seed: int, j: int, part: int = 0) -> int:
    """The seed of pass j (camera samples, a reference's half), or of another `part` of it
    (e.g. its extra paths): independent of every other's."""
    return int(np.random.SeedSequence([seed, j, *([part] if part else [])]).generate_state(1)[0])


def estimate_in_passes(
    estimator: Any,
    points: VisiblePoints,
    photons: PhotonMap | PhotonIndex,
    watch: Stopwatch | None = None,
) -> np.ndarray:
    """(N, 3) float32 radiance at visible points from a photon map split into passes; stages
    "gather" and "estimate" count on `watch`."""
    estimator.check()
    watch = watch or Stopwatch()
    if isinstance(photons, PhotonIndex):  # the progressive methods search from the points
        photons = photons.photons
    out = np.zeros((len(points), 3), np.float32)
    hit = np.flatnonzero(points.hit)
    with watch("estimate"):
        index = PointIndex(points.position[hit], points.normal[hit])
        passes = photons.split(estimator.photons_per_pass)
        radius = estimator.initial_radius(index, footprint(points, hit), passes[0])
        state = estimator.state(len(hit), radius)
        for part in passes:
            state.add(index, part, watch)
        out[hit] = reflected(points.albedo[hit], state.irradiance())
    return out


def footprint(points: VisiblePoints, rows: np.ndarray) -> np.ndarray | None:
    """(len(rows),) pixel width at those points (scene units), or None when not known."""
    return None if points.footprint is None else points.footprint[rows]


def fingerprint(
    estimator: Any, scene: Scene, points: VisiblePoints, seed: int, guided: bool
) -> str:
    """A hash of everything a checkpoint's statistics depend on except the pass count."""
    h = hashlib.sha256(repr((estimator, seed, guided)).encode())
    if getattr(estimator, "radius", 0.0) is None:  # a held-out run's statistics differ
        h.update(b"held-out")
    for a in (scene.triangles, scene.material, points.position, points.normal, points.hit):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


@dataclass(kw_only=True)
class Statistics:
    """Base of a dataclass of per-point statistics: its fields are the checkpoint's arrays;
    these counters are every progressive run's."""

    paths: int = 0  # emitted photon paths so far
    passes: int = 0
    alpha: float = ALPHA  # fraction of new photons kept each pass
    photons: int = 0  # caustic photons those paths stored

    def arrays(self) -> dict[str, np.ndarray]:
        """Everything needed to resume: every field as a named array."""
        return {f.name: np.asarray(getattr(self, f.name)) for f in fields(self)}

    @classmethod
    def from_arrays(cls, a: dict[str, np.ndarray]) -> Any:
        """The state `arrays` saved (0-d arrays back to Python numbers)."""
        return cls(
            **{f.name: a[f.name] if a[f.name].ndim else a[f.name].item() for f in fields(cls)}
        )


def _save(path: Path, key: str, arrays: dict[str, np.ndarray]) -> None:
    """Write a checkpoint atomically (temporary file, then rename): never half-written."""
    with atomic(path) as tmp, tmp.open("wb") as f:
        np.savez(f, fingerprint=np.str_(key), **arrays)


def _load(path: Path, key: str) -> dict[str, np.ndarray]:
    """The arrays of a checkpoint made for `key`; InputError if corrupt or for another run."""
    try:
        with np.load(path, allow_pickle=False) as f:
            arrays = {name: f[name] for name in f.files}
    except (OSError, ValueError, EOFError, zipfile.BadZipFile) as exc:
        raise InputError(f"{path}: not a readable checkpoint ({exc})") from None
    if str(arrays.pop("fingerprint", "")) != key:
        raise InputError(
            f"{path}: checkpoint of another run (scene, points, seed or settings differ);"
            " delete it or choose another file"
        )
    return arrays


def run_passes(
    estimator: Any,
    scene: Scene,
    bvh: BVH,
    points: VisiblePoints,
    n_paths: int,
    seed: int,
    checkpoint: Path | None = None,
    guided: bool = False,
    progress: bool = False,
    stop_after: int | None = None,
    watch: Stopwatch | None = None,
) -> tuple[np.ndarray, Any]:
    """Trace n_paths photon paths pass by pass into the estimator's statistics.

    Returns ((N, 3) float32 radiance at the visible points, final state). With `checkpoint`
    the statistics are saved every CHECKPOINT_SECONDS and at the end, and an existing file
    from the same run is resumed. `stop_after` ends after that many passes in total (as an
    interruption would); `guided` aims emission at the specular surfaces (references). Stages
    "photons" (tracing), "gather" and "estimate" count on `watch`.
    """
    estimator.check()
    watch = watch or Stopwatch()
    hit = np.flatnonzero(points.hit)
    index = PointIndex(points.position[hit], points.normal[hit])
    state = None  # started at the first pass, whose photons may set the radii
    key = fingerprint(estimator, scene, points, seed, guided)
    if checkpoint is not None and checkpoint.exists():
        empty = estimator.state(0, 1.0)  # only its kind, to read the statistics into
        state = empty.from_arrays(_load(checkpoint, key))
    per_pass = estimator.photons_per_pass
    n_passes = -(-n_paths // per_pass)
    last = n_passes if stop_after is None else min(n_passes, stop_after)
    saved = time.monotonic()
    done = 0 if state is None else state.passes
    with tqdm(total=n_passes, initial=done, unit="pass", disable=not progress) as bar:
        for j in range(done, last):
            first = j * per_pass
            with watch("photons"):
                photons = trace_photons(
                    scene, bvh, min(per_pass, n_paths - first), seed,
                    caustic_only=True, first_path=first, guided=guided,
                )  # fmt: skip
            with watch("estimate"):
                if state is None:
                    radius = estimator.initial_radius(index, footprint(points, hit), photons)
                    state = estimator.state(len(hit), radius)
                state.add(index, photons, watch)
            bar.update(1)
            if checkpoint is not None and time.monotonic() - saved > CHECKPOINT_SECONDS:
                _save(checkpoint, key, state.arrays())
                saved = time.monotonic()
    if state is None:  # no pass run: nothing gathered, at any radius
        state = estimator.state(len(hit), estimator.radius or 1.0)
    if checkpoint is not None:
        _save(checkpoint, key, state.arrays())
    out = np.zeros((len(points), 3), np.float32)
    out[hit] = reflected(points.albedo[hit], state.irradiance())
    return out, state
