"""BVH build time and closest-hit rays/s on the example scenes and an 82k-triangle sphere,
side by side with Embree (embreex) on the same rays; the ratio is printed at the end."""

from __future__ import annotations

import time

import numba
import numpy as np
import pytest
import trimesh

from common import SCENES
from conftest import BVH_ROWS, median_seconds
from dpm import load_scene
from dpm.tracer import build_bvh, intersect

EXAMPLES = sorted(SCENES.glob("*.obj"))
N_RAYS = {"sphere82k": 1_000_000}
DEFAULT_RAYS = 500_000


def load_triangles(name: str) -> np.ndarray:
    """(T, 3, 3) float32 triangles of an example scene, or the 81,920-triangle icosphere."""
    if name == "sphere82k":
        return trimesh.creation.icosphere(subdivisions=6).triangles.astype(np.float32)
    return load_scene(next(p for p in EXAMPLES if p.stem == name)).triangles


def incoherent_rays(tri: np.ndarray, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n float32 rays: origins uniform in the bounding box, directions uniform on the sphere."""
    rng = np.random.default_rng(seed)
    flat = tri.reshape(-1, 3)
    o = rng.uniform(flat.min(0), flat.max(0), (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    return o, d


NAMES = [p.stem for p in EXAMPLES] + ["sphere82k"]


@pytest.mark.parametrize("name", NAMES)
def test_dpm_bvh(benchmark, name: str) -> None:
    tri = load_triangles(name)
    build_bvh(tri)  # compile once
    start = time.perf_counter()
    bvh = build_bvh(tri)
    build_s = time.perf_counter() - start
    o, d = incoherent_rays(tri, N_RAYS.get(name, DEFAULT_RAYS))
    trace_s = median_seconds(benchmark, lambda: intersect(bvh, o, d), rounds=5)
    before = numba.get_num_threads()
    numba.set_num_threads(1)
    try:
        start = time.perf_counter()
        intersect(bvh, o, d)
        one_s = time.perf_counter() - start
    finally:
        numba.set_num_threads(before)
    common = {"scene": name, "triangles": len(tri), "rays": len(o), "build_s": build_s}
    BVH_ROWS.append({**common, "engine": "dpm", "trace_s": trace_s})
    BVH_ROWS.append({**common, "engine": "dpm-1thread", "trace_s": one_s})


@pytest.mark.parametrize("name", NAMES)
def test_embree_bvh(benchmark, name: str) -> None:
    rtcore_scene = pytest.importorskip("embreex.rtcore_scene")
    from embreex.mesh_construction import TriangleMesh

    tri = load_triangles(name)
    o, d = incoherent_rays(tri, N_RAYS.get(name, DEFAULT_RAYS))
    start = time.perf_counter()
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, tri)
    scene.run(o[:1], d[:1])  # Embree commits (builds) lazily on the first query
    build_s = time.perf_counter() - start
    trace_s = median_seconds(benchmark, lambda: scene.run(o, d, output=1), rounds=5)
    hits = scene.run(o, d, output=1)
    # Same rays, independent tracer: hit/miss and distances must agree.
    t, idx = intersect(build_bvh(tri), o, d)
    agree = np.mean((hits["primID"] >= 0) == (idx >= 0))
    assert agree > 0.9999, f"hit/miss agreement with Embree only {agree:.6f}"
    both = (hits["primID"] >= 0) & (idx >= 0)
    np.testing.assert_allclose(hits["tfar"][both], t[both], rtol=1e-4, atol=1e-6)
    BVH_ROWS.append(
        {"scene": name, "triangles": len(tri), "rays": len(o), "build_s": build_s,
         "engine": "embree", "trace_s": trace_s}
    )  # fmt: skip
