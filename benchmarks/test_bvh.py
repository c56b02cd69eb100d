"""BVH build time and closest-hit rays/s on the example scenes, an 82k-triangle sphere and the
unseen-scene set (`scenes/make_unseen.py`), side by side with Embree (embreex) on the same
rays, incoherent and camera-coherent; the ratios are printed at the end (and saved with
DPM_BENCH_SAVE=1)."""

from __future__ import annotations

import sys
import time
from collections.abc import Callable
from pathlib import Path

import numba
import numpy as np
import pytest
import trimesh

from common import SCENES
from conftest import BVH_ROWS
from dpm import load_scene
from dpm.camera import framing_camera
from dpm.tracer import build_bvh, intersect

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import unseen_scenes  # noqa: E402

EXAMPLES = sorted(SCENES.glob("*.obj"))
UNSEEN = unseen_scenes()  # built on first use (git-ignored)
PATHS = {p.stem: p for p in EXAMPLES + UNSEEN}
SET = {
    **{p.stem: "example" for p in EXAMPLES},
    "sphere82k": "—",
    **{p.stem: "unseen" for p in UNSEEN},
}
N_RAYS = {"sphere82k": 1_000_000}
DEFAULT_RAYS = 500_000
CAMERA_SIZE = 512  # camera rays: one per pixel of a 512 × 512 image
ROUNDS = 5  # timed rounds per engine, alternating


def load_triangles(name: str) -> np.ndarray:
    """(T, 3, 3) float32 triangles of an example or unseen scene, or the 81,920-triangle
    icosphere."""
    if name == "sphere82k":
        return trimesh.creation.icosphere(subdivisions=6).triangles.astype(np.float32)
    return load_scene(PATHS[name]).triangles


def incoherent_rays(tri: np.ndarray, n: int, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """n float32 rays: origins uniform in the bounding box, directions uniform on the sphere."""
    rng = np.random.default_rng(seed)
    flat = tri.reshape(-1, 3)
    o = rng.uniform(flat.min(0), flat.max(0), (n, 3)).astype(np.float32)
    d = rng.normal(size=(n, 3))
    d = (d / np.linalg.norm(d, axis=1, keepdims=True)).astype(np.float32)
    return o, d


def camera_rays(name: str, tri: np.ndarray, size: int = CAMERA_SIZE) -> tuple[np.ndarray, ...]:
    """size² float32 primary rays through the pixel centres of the scene's camera, row after
    row (the sphere: a camera framing it): the coherent rays a render starts with."""
    if name == "sphere82k":
        flat = tri.reshape(-1, 3)
        camera = framing_camera(flat.min(0), flat.max(0), size, size)
    else:
        camera = load_scene(PATHS[name]).camera
        camera = camera.with_resolution(size, size)
    origin, forward, right, up = camera.basis()
    y, x = np.mgrid[0:size, 0:size] + 0.5
    d = forward + (2 * x / size - 1)[..., None] * right + (1 - 2 * y / size)[..., None] * up
    d = (d / np.linalg.norm(d, axis=-1, keepdims=True)).reshape(-1, 3).astype(np.float32)
    return np.broadcast_to(origin.astype(np.float32), d.shape).copy(), d


NAMES = [p.stem for p in EXAMPLES] + ["sphere82k"] + [p.stem for p in UNSEEN]
RAYS = {"incoherent": incoherent_rays, "camera": camera_rays}


def seconds(fn: Callable[[], object]) -> float:
    """Wall seconds of one call of fn."""
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


@pytest.mark.parametrize("kind", list(RAYS))
@pytest.mark.parametrize("name", NAMES)
def test_bvh_against_embree(benchmark, name: str, kind: str) -> None:
    """Build both, check they agree hit for hit, then time them in turn, round after round:
    dpm on all Numba threads, dpm on one, Embree (one thread); medians."""
    rtcore_scene = pytest.importorskip("embreex.rtcore_scene")
    from embreex.mesh_construction import TriangleMesh

    tri = load_triangles(name)
    build_bvh(tri)  # compile once
    dpm_build = seconds(lambda: build_bvh(tri))
    bvh = build_bvh(tri)
    o, d = incoherent_rays(tri, N_RAYS.get(name, DEFAULT_RAYS)) if kind == "incoherent" else (
        camera_rays(name, tri)
    )  # fmt: skip

    def embree_scene():
        scene = rtcore_scene.EmbreeScene()
        TriangleMesh(scene, tri)
        scene.run(o[:1], d[:1])  # Embree commits (builds) lazily on the first query
        return scene

    start = time.perf_counter()
    scene = embree_scene()
    embree_build = time.perf_counter() - start
    hits = scene.run(o, d, output=1)
    t, idx = intersect(bvh, o, d)
    agree = np.mean((hits["primID"] >= 0) == (idx >= 0))
    assert agree > 0.9999, f"hit/miss agreement with Embree only {agree:.6f}"
    both = (hits["primID"] >= 0) & (idx >= 0)
    np.testing.assert_allclose(hits["tfar"][both], t[both], rtol=1e-4, atol=1e-6)
    threads = numba.get_num_threads()
    times: dict[str, list[float]] = {"dpm": [], "dpm-1thread": [], "embree": []}
    for _ in range(ROUNDS if benchmark.enabled else 1):
        times["dpm"].append(seconds(lambda: intersect(bvh, o, d)))
        numba.set_num_threads(1)
        try:
            times["dpm-1thread"].append(seconds(lambda: intersect(bvh, o, d)))
        finally:
            numba.set_num_threads(threads)
        times["embree"].append(seconds(lambda: scene.run(o, d, output=1)))
    common = {"scene": name, "set": SET[name], "kind": kind, "triangles": len(tri), "rays": len(o)}
    for engine, runs in times.items():
        build = embree_build if engine == "embree" else dpm_build
        row = {**common, "engine": engine, "build_s": build, "trace_s": float(np.median(runs))}
        BVH_ROWS.append(row)
