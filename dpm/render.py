"""Rendering a loaded scene into a linear RGB image, with per-stage timings.

Every method starts from the same visible points (first diffuse hits of the camera samples);
`dpm-render --method NAME` and the benchmarks call `render`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from dpm.camera import Camera
from dpm.errors import InputError
from dpm.scene import Scene
from dpm.tracer import BVH, build_bvh, intersect, shade, trace_visible_points

IMPLEMENTED = ("pt", "pt-nocaustic")
PLANNED = ("hybrid", "pm", "ppm", "sppm", "appm", "dpm")
COMPONENTS = ("full", "caustic")
SAMPLES_PER_STEP = 1 << 16  # pixel samples traced between progress-bar updates


@dataclass
class RenderOptions:
    """What to render; width/height None keep the camera's resolution."""

    method: str = "pt"
    spp: int = 16
    photons: int = 200_000
    k: int = 50
    seed: int = 0
    width: int | None = None
    height: int | None = None
    component: str = "full"
    progress: bool = True


@dataclass
class RenderResult:
    """A rendered image (H, W, 3) float32 linear RGB and statistics (seconds per stage, counts)."""

    image: np.ndarray
    stats: dict = field(default_factory=dict)


def validate(options: RenderOptions) -> None:
    """Raise InputError for options no method can use."""
    if options.method not in IMPLEMENTED:
        if options.method in PLANNED:
            raise InputError(f"method '{options.method}' is not implemented yet; use 'pt'")
        raise InputError(f"unknown method '{options.method}'")
    if options.component not in COMPONENTS:
        raise InputError(f"unknown component '{options.component}'; use full or caustic")
    if options.method.startswith("pt") and options.component != "full":
        raise InputError(f"method '{options.method}' renders no separate caustic component")
    for name in ("spp", "k"):
        if getattr(options, name) < 1:
            raise InputError(f"--{name} must be at least 1")
    if options.photons < 0:
        raise InputError("--photons must not be negative")
    if options.seed < 0:
        raise InputError("--seed must not be negative")
    for name in ("width", "height"):
        value = getattr(options, name)
        if value is not None and not 1 <= value <= 16384:
            raise InputError(f"--{name} must be from 1 to 16384")


def _fibonacci_sphere(n: int) -> np.ndarray:
    """(n, 3) unit directions spread evenly over the sphere."""
    i = np.arange(n) + 0.5
    z = 1 - 2 * i / n
    phi = np.pi * (1 + 5**0.5) * i
    r = np.sqrt(1 - z * z)
    return np.stack([r * np.cos(phi), r * np.sin(phi), z], axis=1)


def check_camera_outside(scene: Scene, bvh: BVH, camera: Camera) -> None:
    """Raise InputError when the camera sits inside a closed object.

    Inside means rays in every direction hit the back of a surface (normals point outwards,
    DESIGN.md); a camera inside a room whose walls face inwards is fine.
    """
    directions = _fibonacci_sphere(256)
    origins = np.broadcast_to(camera.origin, directions.shape)
    _, tri = intersect(bvh, origins, directions)
    if np.all(tri >= 0):
        facing = np.einsum("ij,ij->i", scene.normals[tri].astype(np.float64), directions)
        if np.all(facing > 0):
            raise InputError(
                f"{scene.path}: the camera at {tuple(np.round(camera.origin, 6).tolist())} is"
                " inside a closed object (every ray from it hits a back face)"
            )


def render(scene: Scene, options: RenderOptions | None = None) -> RenderResult:
    """Render `scene` with `options`; returns the linear RGB image and per-stage statistics."""
    options = options or RenderOptions()
    validate(options)
    camera = scene.camera.with_resolution(options.width, options.height)
    seconds: dict[str, float] = {}
    stats: dict = {"method": options.method, "seconds": seconds}

    start = time.perf_counter()
    bvh = build_bvh(scene)
    seconds["bvh"] = time.perf_counter() - start
    check_camera_outside(scene, bvh, camera)

    w, h, spp = camera.width, camera.height, options.spp
    image = np.zeros((h, w, 3), np.float32)
    rows_per_step = max(1, SAMPLES_PER_STEP // (w * spp))
    seconds["visible_points"] = seconds["shade"] = 0.0
    hits = dropped = 0
    with tqdm(total=h, unit="row", disable=not options.progress, desc=options.method) as bar:
        for row0 in range(0, h, rows_per_step):
            row1 = min(h, row0 + rows_per_step)
            start = time.perf_counter()
            points = trace_visible_points(scene, bvh, camera, spp, options.seed, (row0, row1))
            seconds["visible_points"] += time.perf_counter() - start
            start = time.perf_counter()
            caustics = options.method == "pt"
            reflected, bad = shade(scene, bvh, points, options.seed, caustics=caustics)
            radiance = points.emitted + points.throughput * reflected
            image[row0:row1] = radiance.reshape(row1 - row0, w, spp, 3).mean(axis=2)
            seconds["shade"] += time.perf_counter() - start
            hits += int(points.hit.sum())
            dropped += bad
            bar.update(row1 - row0)
    stats.update(
        width=w,
        height=h,
        spp=spp,
        seed=options.seed,
        samples=w * h * spp,
        visible_points=hits,
        nonfinite_samples=dropped,
        triangles=int(len(scene.triangles)),
        emitter_triangles=int(len(scene.emitters.triangles)),
        bvh_nodes=bvh.n_nodes,
    )
    return RenderResult(image=image, stats=stats)
