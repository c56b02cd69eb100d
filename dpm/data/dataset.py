"""The training set (paper §4.3): procedural scenes, visible points, PPM ground truth and
photon sets at several budgets, one compressed shard per scene plus a manifest.

Layout of `DataConfig.out`:
- `scenes/sceneNNNNN.{obj,mtl,toml}`: the generated scenes (inspectable with dpm-render);
- `shards/sceneNNNNN.npz`: the hit visible points of a width × width camera grid (position,
  normal, albedo), their ground-truth caustic radiance, and for each budget B the caustic
  photons of B emitted paths (`B/position`, `B/direction`, `B/flux`, `B/normal`);
- `manifest.json`: the config and one entry per finished shard.
Only this module knows a shard's array names: `load_shard` reads one back as a `Shard`, and
`shard_sizes` reads its counts from its manifest entry. A shard is written atomically, so a
killed build resumes with the scenes it has; scenes are made in parallel worker processes,
and each depends only on (seed, index).
"""

from __future__ import annotations

import json
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass
from multiprocessing import get_context
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from dpm.data.builder import write_scene
from dpm.data.procedural import random_scene
from dpm.errors import InputError
from dpm.io import atomic

if TYPE_CHECKING:
    from dpm.tracer import PhotonMap

MANIFEST = "manifest.json"
GENERATOR = 2  # bump when dpm.data.procedural or the shard content changes: old sets are refused
POINT_ARRAYS = ("position", "normal", "albedo", "radiance")  # a shard's per-point arrays
PHOTON_ARRAYS = ("position", "direction", "flux", "normal")  # `B/name` for each budget B


@dataclass(frozen=True)
class DataConfig:
    """How a training set is made (the `[data]` table of a dpm-train config)."""

    out: str  # folder of the set
    scenes: int = 8  # procedural scenes 0 … scenes-1
    width: int = 64  # visible points: first diffuse hits of a width × width camera grid
    budgets: tuple[int, ...] = (100_000, 300_000, 1_000_000)  # emitted paths per photon set
    reference_paths: int = 20_000_000  # guided photon paths of the PPM ground truth
    reference_radius: float = 5e-4  # PPM initial radius × the scene's bounding diagonal
    reference_paths_per_pass: int = 1_000_000
    seed: int = 0
    workers: int = 1  # scenes made at once (processes)

    def identity(self) -> dict:
        """What a set's content depends on (not where it lives or how many workers)."""
        d = asdict(self)
        for key in ("out", "scenes", "workers"):
            d.pop(key)
        d["budgets"] = list(self.budgets)
        d["generator"] = GENERATOR
        return d


@dataclass(frozen=True)
class Shard:
    """One scene's shard, read into memory: its P visible points and caustic photon sets."""

    position: np.ndarray  # (P, 3) float32 world position of each visible point
    normal: np.ndarray  # (P, 3) float32 unit surface normal
    albedo: np.ndarray  # (P, 3) float32 diffuse albedo
    radiance: np.ndarray  # (P, 3) float32 ground-truth caustic radiance, W/(m² sr)
    photons: dict[int, PhotonMap]  # budget B → the caustic photons of B emitted paths


def shard_sizes(entry: dict, budget: int) -> tuple[int, int]:
    """(visible points, caustic photons at `budget`) of the shard of a manifest entry."""
    return entry["points"], entry["caustic_photons"][str(budget)]


def shard_name(index: int) -> str:
    """File stem of scene `index`."""
    return f"scene{index:05d}"


def make_shard(config: DataConfig, index: int) -> dict:
    """Make scene `index` and its shard; returns its manifest entry."""
    import numba

    from dpm import load_scene
    from dpm.density.reference import ppm_reference
    from dpm.tracer import build_bvh, trace_photons, trace_visible_points

    numba.set_num_threads(max(1, numba.config.NUMBA_NUM_THREADS // max(1, config.workers)))
    start = time.perf_counter()
    out = Path(config.out)
    obj = write_scene(random_scene(index, config.seed, config.width), out / "scenes",
                      f"dpm training scene {index} (seed {config.seed}), by dpm.data")  # fmt: skip
    scene = load_scene(obj)
    bvh = build_bvh(scene)
    camera = scene.camera
    points = trace_visible_points(scene, bvh, camera, 1, config.seed, (0, camera.height))
    keep = np.flatnonzero(points.hit)
    diagonal = scene.extent
    ref = ppm_reference(
        scene, bvh, points, config.reference_paths, config.reference_radius * diagonal,
        config.reference_paths_per_pass, seed=config.seed * 7919 + index * 2 + 1,
    )  # fmt: skip
    arrays = {
        "position": points.position[keep], "normal": points.normal[keep],
        "albedo": points.albedo[keep], "radiance": ref.radiance[keep],
    }  # fmt: skip
    photons = {}
    for j, budget in enumerate(config.budgets):
        pm = trace_photons(scene, bvh, budget, seed=(config.seed * 7919 + index) * 16 + j,
                           caustic_only=True)  # fmt: skip
        for name in PHOTON_ARRAYS:
            arrays[f"{budget}/{name}"] = getattr(pm, name)
        photons[str(budget)] = len(pm)
    path = out / "shards" / f"{shard_name(index)}.npz"
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic(path) as tmp, tmp.open("wb") as f:
        np.savez_compressed(f, **arrays)
    return {
        "index": index, "file": f"shards/{path.name}", "points": len(keep),
        "caustic_photons": photons, "reference_noise": ref.noise,
        "reference_caustic_photons": ref.caustic_photons,
        "seconds": time.perf_counter() - start,
    }  # fmt: skip


def read_manifest(out: Path) -> dict | None:
    """The manifest of the set in `out`, or None when there is none yet."""
    path = out / MANIFEST
    if not path.exists():
        return None
    try:
        manifest = json.loads(path.read_text())
        if not isinstance(manifest["config"], dict) or not all(
            isinstance(e["index"], int) and isinstance(e["file"], str) for e in manifest["shards"]
        ):
            raise TypeError
    except (json.JSONDecodeError, UnicodeDecodeError, KeyError, TypeError):
        raise InputError(f"{path}: not a dpm training-set manifest") from None
    return manifest


def write_manifest(out: Path, manifest: dict) -> None:
    """Write the manifest atomically."""
    with atomic(out / MANIFEST) as tmp:
        tmp.write_text(json.dumps(manifest, indent=1))


def build(config: DataConfig, progress: bool = True) -> dict:
    """Make every missing shard of the set (resuming a killed build); returns the manifest."""
    out = Path(config.out)
    out.mkdir(parents=True, exist_ok=True)
    manifest = read_manifest(out) or {"config": config.identity(), "shards": []}
    if manifest["config"] != config.identity():
        raise InputError(f"{out}: holds a training set made with other [data] settings; "
                         "use another `out` or remove it")  # fmt: skip
    done = {entry["index"] for entry in manifest["shards"]}
    todo = [i for i in range(config.scenes) if i not in done]
    bar = tqdm(total=config.scenes, initial=config.scenes - len(todo), unit="scene",
               desc="training scenes", disable=not progress)  # fmt: skip
    if config.workers <= 1:
        results = (make_shard(config, i) for i in todo)
        pool = None
    else:
        pool = ProcessPoolExecutor(config.workers, mp_context=get_context("spawn"))
        results = (f.result() for f in as_completed(pool.submit(make_shard, config, i)
                                                    for i in todo))  # fmt: skip
    try:
        for entry in results:
            manifest["shards"].append(entry)
            manifest["shards"].sort(key=lambda e: e["index"])
            write_manifest(out, manifest)
            bar.update()
    finally:
        bar.close()
        if pool is not None:
            pool.shutdown(cancel_futures=True)
    # a set made for more scenes serves a config asking for fewer: scenes 0 … scenes-1 only
    return {**manifest, "shards": [e for e in manifest["shards"] if e["index"] < config.scenes]}


def load_shard(out: Path, entry: dict, budgets: tuple[int, ...]) -> Shard:
    """The shard of a manifest entry, read into memory with the photon sets of `budgets`."""
    from dpm.tracer import PhotonMap

    path = Path(out) / entry["file"]
    try:
        with np.load(path) as f:
            points = [f[name] for name in POINT_ARRAYS]
            photons = {}
            for b in budgets:
                position, direction, flux, normal = (f[f"{b}/{n}"] for n in PHOTON_ARRAYS)
                photons[b] = PhotonMap(position, direction, flux, normal,
                                       np.ones(len(flux), bool), np.zeros(0, np.uint16),
                                       np.zeros(0, np.int64), b)  # fmt: skip
    except Exception as e:  # OSError, KeyError, BadZipFile, zlib.error, ValueError alike
        raise InputError(f"{path}: unreadable training shard ({type(e).__name__})") from None
    return Shard(*points, photons)
