"""Rendering a loaded scene into a linear RGB image, with per-stage timings.

Methods register here by name; `dpm-render --method NAME` and the benchmarks call `render`.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from dpm.errors import InputError
from dpm.scene import Scene
from dpm.tracer import build_bvh
from dpm.tracer.direct import render_direct_rows

IMPLEMENTED = ("direct",)
PLANNED = ("hybrid", "pt", "pt-nocaustic", "pm", "ppm", "sppm", "appm", "dpm")
COMPONENTS = ("full", "caustic")
MAX_SPECULAR_DEPTH = 16
ROWS_PER_STEP = 8  # rows rendered between progress-bar updates


@dataclass
class RenderOptions:
    """What to render; width/height None keep the camera's resolution."""

    method: str = "direct"
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
            raise InputError(f"method '{options.method}' is not implemented yet; use 'direct'")
        raise InputError(f"unknown method '{options.method}'")
    if options.component not in COMPONENTS:
        raise InputError(f"unknown component '{options.component}'; use full or caustic")
    if options.method == "direct" and options.component != "full":
        raise InputError("method 'direct' renders no separate caustic component")
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


def render(scene: Scene, options: RenderOptions | None = None) -> RenderResult:
    """Render `scene` with `options`; returns the linear RGB image and per-stage statistics."""
    options = options or RenderOptions()
    validate(options)
    camera = scene.camera.with_resolution(options.width, options.height)
    stats: dict = {"method": options.method, "seconds": {}}

    start = time.perf_counter()
    bvh = build_bvh(scene)
    stats["seconds"]["bvh"] = time.perf_counter() - start

    start = time.perf_counter()
    w, h = camera.width, camera.height
    image = np.zeros((h, w, 3), np.float32)
    sc, cam = scene.kernel_arrays(), camera.basis()
    eps = 1e-6 * max(scene.extent, 1e-30)  # spawn offset; geometry is float32, rays float64
    with tqdm(total=h, unit="row", disable=not options.progress, desc="direct") as bar:
        for row0 in range(0, h, ROWS_PER_STEP):
            row1 = min(h, row0 + ROWS_PER_STEP)
            render_direct_rows(
                bvh.arrays, bvh.depth, sc, cam, w, h, row0, row1, options.spp,
                options.seed, eps, MAX_SPECULAR_DEPTH, image[row0:row1],
            )  # fmt: skip
            bar.update(row1 - row0)
    stats["seconds"]["render"] = time.perf_counter() - start
    stats.update(
        width=w,
        height=h,
        spp=options.spp,
        seed=options.seed,
        triangles=int(len(scene.triangles)),
        emitter_triangles=int(len(scene.emitters.triangles)),
        bvh_nodes=bvh.n_nodes,
    )
    return RenderResult(image=image, stats=stats)
