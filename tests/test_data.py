"""The training set: procedural scenes, shards, resuming and parallel builds."""

from __future__ import annotations

import os
import sys
import tomllib
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from dpm import load_scene
from dpm.data.builder import write_scene
from dpm.data.dataset import (
    MANIFEST,
    DataConfig,
    build,
    load_shard,
    make_shard,
    read_manifest,
    shard_sizes,
)
from dpm.data.procedural import random_scene
from dpm.errors import InputError
from dpm.parallel import fan_out
from dpm.scene import DIELECTRIC, DIFFUSE

ROOT = Path(__file__).parent.parent


def tiny(out: Path, scenes: int, workers: int = 1) -> DataConfig:
    return DataConfig(str(out), scenes=scenes, width=24, budgets=(20_000, 40_000),
                      reference_paths=500_000, reference_paths_per_pass=250_000,
                      workers=workers)  # fmt: skip


@pytest.mark.parametrize("index", [0, 1, 2, 3, 4, 5])
def test_procedural_scenes_are_valid_and_deterministic(tmp_path: Path, index: int) -> None:
    a = random_scene(index, seed=0, width=16)
    b = random_scene(index, seed=0, width=16)
    assert [p.name for p in a.parts] == [p.name for p in b.parts]
    for p, q in zip(a.parts, b.parts, strict=True):
        np.testing.assert_array_equal(p.vertices, q.vertices)
    objects = [p for p in a.parts if p.name.startswith("object")]
    assert 1 <= len(objects) <= 16
    lights = [p for p in a.parts if p.name.startswith("light")]
    assert 2 <= len(lights) <= 4
    for part in objects:
        assert part.vertices[:, 1].min() > 0  # above the floor, not touching it
        if part.closed:
            mesh = trimesh.Trimesh(part.vertices, part.faces, process=False)
            assert mesh.is_watertight and mesh.volume > 0
    scene = load_scene(write_scene(a, tmp_path))
    kinds = scene.materials.kind
    assert (kinds != DIFFUSE).any()  # at least one mirror or glass object: caustics
    glass = [p for p in a.parts if a.materials[p.material].get("illum") == 7]
    assert all(p.closed for p in glass) and (len(glass) > 0) == (kinds == DIELECTRIC).any()
    assert len(scene.emitters.triangles) == 2 * len(lights)
    assert random_scene(index, seed=1, width=16).parts[-1].vertices.tolist() != (
        a.parts[-1].vertices.tolist()
    )


def test_a_build_resumes_and_refuses_other_settings(tmp_path: Path) -> None:
    out = tmp_path / "set"
    first = build(tiny(out, 2), progress=False)
    assert [e["index"] for e in first["shards"]] == [0, 1]
    shard0 = (out / "shards" / "scene00000.npz").read_bytes()
    more = build(tiny(out, 3), progress=False)
    assert [e["index"] for e in more["shards"]] == [0, 1, 2]
    assert (out / "shards" / "scene00000.npz").read_bytes() == shard0  # not remade
    assert read_manifest(out) == more
    shard = load_shard(out, more["shards"][2], (20_000, 40_000))
    n, photons = shard_sizes(more["shards"][2], 40_000)
    assert shard.position.shape == shard.radiance.shape == (n, 3)
    assert len(shard.photons[40_000]) == len(shard.photons[40_000].flux) == photons
    assert shard.photons[40_000].n_paths == 40_000 and shard.photons[40_000].caustic.all()
    assert np.all(shard.radiance >= 0) and shard.radiance.max() > 0
    with pytest.raises(InputError, match="other \\[data\\] settings"):
        build(replace(tiny(out, 3), reference_paths=1_000_000), progress=False)
    assert sorted(p.name for p in (out / "shards").iterdir()) == [
        "scene00000.npz", "scene00001.npz", "scene00002.npz"]  # fmt: skip


def set_files(root: Path) -> dict[str, bytes]:
    """Every file of a training set but its manifest, by path relative to `root`."""
    files = (p for p in root.rglob("*") if p.is_file() and p.name != MANIFEST)
    return {str(p.relative_to(root)): p.read_bytes() for p in sorted(files)}


def assert_same_set(a: Path, b: Path) -> None:
    """Two training sets hold the same files byte for byte and the same manifest, but for the
    seconds each scene took."""
    files_a, files_b = set_files(a), set_files(b)
    assert files_a.keys() == files_b.keys()
    for name in files_a:
        assert files_a[name] == files_b[name], name
    manifests = [read_manifest(root) for root in (a, b)]
    assert manifests[0]["config"] == manifests[1]["config"]
    entries = [[{k: v for k, v in e.items() if k != "seconds"} for e in m["shards"]]
               for m in manifests]  # fmt: skip
    assert entries[0] == entries[1]


@pytest.fixture(scope="module")
def tiny_set(tmp_path_factory) -> tuple[DataConfig, Path]:
    """configs/tiny.toml's [data] table and its set, built serially in a temporary folder."""
    raw = tomllib.loads((ROOT / "configs" / "tiny.toml").read_text())["data"]
    out = tmp_path_factory.mktemp("tiny-serial")
    config = DataConfig(**{**raw, "out": str(out), "budgets": tuple(raw["budgets"])})
    build(config, progress=False)
    return config, out


def test_a_ray_build_equals_the_serial_build(tiny_set, tmp_path: Path) -> None:
    config, serial = tiny_set
    build(replace(config, out=str(tmp_path), workers=2), progress=False)  # local Ray, 2 workers
    assert_same_set(serial, tmp_path)


def make_and_die_once(config: DataConfig, index: int, threads: int | None) -> tuple[dict, dict]:
    """make_shard, but the first worker to finish scene 1 dies before it can hand it back."""
    made = make_shard(config, index, threads)
    marker = Path(config.out).parent / "killed"
    if index == 1 and not marker.exists():
        marker.touch()
        os._exit(1)  # the worker process is gone mid-build: Ray runs the task again
    return made


def test_a_killed_worker_is_redone_and_the_set_is_the_same(tiny_set, tmp_path: Path) -> None:
    import ray

    config, serial = tiny_set
    out = tmp_path / "set"
    module = sys.modules[__name__]
    ray.cloudpickle.register_pickle_by_value(module)  # the workers cannot import tests/
    try:
        build(replace(config, out=str(out), workers=2), progress=False, make=make_and_die_once)
    finally:
        ray.cloudpickle.unregister_pickle_by_value(module)
    assert (tmp_path / "killed").exists()  # a worker did die
    assert_same_set(serial, out)


def test_a_tasks_own_error_comes_back_as_itself(tmp_path: Path) -> None:
    missing = tmp_path / "missing.obj"
    with pytest.raises(InputError, match="missing.obj") as raised:
        list(fan_out(load_scene, [(missing,)], cpus=1))  # not retried: it would fail again
    assert "\n" not in str(raised.value)  # one line, as the CLI prints it
