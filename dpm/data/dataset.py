"""The training set (paper §4.3): procedural scenes, visible points, PPM ground truth and
photon sets at several budgets, one compressed shard per scene plus a manifest.

Layout of `DataConfig.out`:
- `scenes/sceneNNNNN.{obj,mtl,toml}`: the generated scenes (inspectable with dpm-render);
- `shards/sceneNNNNN.npz`: the hit visible points of a width × width camera grid (position,
  normal, albedo), their ground-truth caustic radiance, and for each budget B the caustic
  photons of B emitted paths (`B/position`, `B/direction`, `B/flux`, `B/normal`);
- `manifest.json`: the config and one entry per finished shard.
Only this module knows a shard's array names: `load_shard` reads one back as a `Shard`, and
`shard_sizes` reads its counts from its manifest entry.

Each scene depends only on (seed, index), and a shard's bytes only on its arrays (fixed zip
timestamps), so a set is the same file for file however it was made. `make_shard` writes
nothing: it returns the scene's files, and `build` writes them atomically and then the
manifest entry, so a killed build resumes with the scenes it has. Scenes are made as Ray
tasks (`dpm.parallel`): by default on a local runtime of one worker per core, `workers` of
them if set, or on the cluster at `ray_address` (which then needs no shared file system); a
task whose worker dies is run again. `workers = 1` makes them one after the other in this
process (small sets, where Ray's few seconds of start cost more than they save).
"""

from __future__ import annotations

import io
import json
import os
import tempfile
import threading
import time
import zipfile
from collections.abc import Callable
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np
from tqdm import tqdm

from dpm.data.builder import write_scene
from dpm.data.procedural import random_scene
from dpm.errors import InputError
from dpm.io import atomic
from dpm.parallel import fan_out

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
    workers: int = 0  # scenes at once on a local Ray runtime; 0: one per core; 1: no Ray
    ray_address: str = ""  # a Ray cluster to make the scenes on instead (workers is ignored)
    # "points" (DPM's and nppm's: points, photons, PPM truth) or "caustic" (auto's caustic
    # filter: its statistics after each of `passes` passes, and a `target_passes` render;
    # dpm.data.caustic_set)
    kind: str = "points"
    passes: tuple[int, ...] = (1, 2, 4, 8, 16, 32)
    target_passes: int = 256

    def identity(self) -> dict:
        """What a set's content depends on (not where it lives or what makes it)."""
        d = asdict(self)
        for key in ("out", "scenes", "workers", "ray_address"):
            d.pop(key)
        if self.kind == "points":  # what a points set never read (sets made before them)
            for key in ("kind", "passes", "target_passes"):
                d.pop(key)
            d["budgets"] = list(self.budgets)
        else:  # what the shards hold depends on the filter's inputs too
            from dpm.caustic.stats import CHANNELS, EXTRAPOLATED_CENTRE, HULL_CLAMP, TAPS

            d["passes"] = list(self.passes)
            d["format"] = [CHANNELS, TAPS, "extrapolated target", "pixel blur ratio"]
            if EXTRAPOLATED_CENTRE:
                d["format"].append("extrapolated centre")
            if HULL_CLAMP:  # (the set stores the hull's second interval)
                d["format"].append("hull clamp")
            for key in ("budgets", "reference_paths", "reference_radius",
                        "reference_paths_per_pass"):  # fmt: skip
                d.pop(key)
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


def npz_bytes(arrays: dict[str, np.ndarray]) -> bytes:
    """A compressed .npz of `arrays` (what np.savez_compressed writes) whose bytes depend on
    the arrays alone: every member has the same fixed timestamp."""
    buf = io.BytesIO()
    with zipfile.ZipFile(buf, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, array in arrays.items():
            info = zipfile.ZipInfo(f"{name}.npy", date_time=(1980, 1, 1, 0, 0, 0))
            info.compress_type = zipfile.ZIP_DEFLATED
            with zf.open(info, "w", force_zip64=True) as f:
                np.lib.format.write_array(f, np.asanyarray(array), allow_pickle=False)
    return buf.getvalue()


def scene_files(config: DataConfig, index: int, what: str) -> tuple:
    """Procedural scene `index` of the set, loaded, and its OBJ, MTL and TOML files
    ({'scenes/NAME': bytes}), headed by a comment naming `what` it is."""
    from dpm.scene import load_scene

    files = {}
    with tempfile.TemporaryDirectory() as tmp:
        comment = f"{what} {index} (seed {config.seed}), by dpm.data"
        obj = write_scene(random_scene(index, config.seed, config.width), Path(tmp), comment)
        for path in sorted(Path(tmp).iterdir()):
            files[f"scenes/{path.name}"] = path.read_bytes()
        return load_scene(obj), files


def make_shard(config: DataConfig, index: int, threads: int | None = None) -> tuple[dict, dict]:
    """Make scene `index` and its shard on `threads` Numba threads (default: all); returns its
    manifest entry and its files, {path relative to `out`: bytes}, written by the caller."""
    import numba

    from dpm.estimators.reference import ppm_reference
    from dpm.tracer import build_bvh, trace_photons, trace_visible_points

    numba.set_num_threads(threads or numba.config.NUMBA_NUM_THREADS)
    start = time.perf_counter()
    scene, files = scene_files(config, index, "dpm training scene")
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
    shard = f"shards/{shard_name(index)}.npz"
    files[shard] = npz_bytes(arrays)
    entry = {
        "index": index, "file": shard, "points": len(keep),
        "caustic_photons": photons, "reference_noise": ref.noise,
        "reference_caustic_photons": ref.caustic_photons,
        "seconds": time.perf_counter() - start,
    }  # fmt: skip
    return entry, files


def write_files(out: Path, files: dict[str, bytes]) -> None:
    """Write a shard's files under `out`, each atomically, the shard (.npz) last."""
    for name in sorted(files, key=lambda n: n.endswith(".npz")):
        path = out / name
        path.parent.mkdir(parents=True, exist_ok=True)
        with atomic(path) as tmp:
            tmp.write_bytes(files[name])


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


def build(
    config: DataConfig,
    progress: bool = True,
    make: Callable[[DataConfig, int, int | None], tuple[dict, dict]] | None = None,
) -> dict:
    """Make every missing shard of the set (resuming a killed build), as Ray tasks or, with
    `workers` = 1 and no `ray_address`, in this process; returns the manifest. `make` makes
    one scene (default: `make_shard`; `caustic_set.make_caustic_shard` for a caustic set;
    tests put faults in it)."""
    make = make or make_shard
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
    if config.workers == 1 and not config.ray_address:
        results = ((i, make(config, i, None)) for i in todo)
    else:  # a task has one CPU, so one Numba thread
        jobs = [(config, i, 1) for i in todo]
        results = fan_out(make, jobs, config.ray_address, config.workers or os.cpu_count() or 1)
    try:
        for _, (entry, files) in results:
            write_files(out, files)
            manifest["shards"].append(entry)
            manifest["shards"].sort(key=lambda e: e["index"])
            write_manifest(out, manifest)
            bar.update()
    finally:
        bar.close()
        results.close()  # stops a Ray runtime this build started
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


# Shards a sampler keeps in memory (beyond them, the oldest read is forgotten with its trees).
# The committed configs' 72 training shards hold 0.85 GB with their trees; at 64, fewer than
# those, a random batch missed one shard in nine and rebuilt its trees (a DPM-500 batch took
# 94 ms to draw instead of 53 on the 2-core machine).
MAX_CACHED_SHARDS = 256


class ShardCache:
    """Shards of a training set read on demand, and one object per (shard, budget) built from
    them (a photon tree), kept with the shard; bounded memory: beyond `size` shards the oldest
    read is forgotten with its objects. Safe to share between the threads that draw batches
    ahead (a miss is read and built under a lock)."""

    def __init__(self, out: Path, entries: list[dict], budgets: tuple[int, ...], size: int) -> None:
        self.out, self.entries, self.budgets, self.size = out, entries, budgets, size
        self.shards: dict[int, Shard] = {}
        self.built: dict[tuple[int, int], object] = {}
        self.lock = threading.RLock()

    def shard(self, i: int) -> Shard:
        """Shard number i of `entries`."""
        with self.lock:
            if i not in self.shards:
                if len(self.shards) >= self.size:
                    oldest = next(iter(self.shards))
                    del self.shards[oldest]
                    self.built = {k: v for k, v in self.built.items() if k[0] != oldest}
                self.shards[i] = load_shard(self.out, self.entries[i], self.budgets)
            return self.shards[i]

    def per_map(self, i: int, budget: int, build: Callable) -> object:
        """build(photon map) of shard i's map of `budget` paths, built once while it is kept."""
        with self.lock:
            if (i, budget) not in self.built:
                self.built[i, budget] = build(self.shard(i).photons[budget])
            return self.built[i, budget]
