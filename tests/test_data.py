"""The training set: procedural scenes, shards, resuming and parallel builds."""

from __future__ import annotations

from dataclasses import fields, replace
from pathlib import Path

import numpy as np
import pytest
import trimesh

from dpm import load_scene
from dpm.data.builder import write_scene
from dpm.data.dataset import DataConfig, build, load_shard, read_manifest, shard_sizes
from dpm.data.procedural import random_scene
from dpm.errors import InputError
from dpm.scene import DIELECTRIC, DIFFUSE


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


def test_parallel_build_equals_serial(tmp_path: Path) -> None:
    serial = build(tiny(tmp_path / "one", 2), progress=False)
    parallel = build(tiny(tmp_path / "two", 2, workers=2), progress=False)
    for a, b in zip(serial["shards"], parallel["shards"], strict=True):
        x = load_shard(tmp_path / "one", a, (20_000, 40_000))
        y = load_shard(tmp_path / "two", b, (20_000, 40_000))
        assert x.photons.keys() == y.photons.keys() == {20_000, 40_000}
        pairs = [(x, y)] + [(x.photons[budget], y.photons[budget]) for budget in x.photons]
        for u, v in pairs:
            for f in fields(u):
                if f.name != "photons":  # the photon sets: compared as pairs of their own
                    np.testing.assert_array_equal(getattr(u, f.name), getattr(v, f.name), f.name)
