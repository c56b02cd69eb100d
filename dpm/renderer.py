"""Rendering a loaded scene into a linear RGB image, with per-stage timings.

One path for every method (`dpm.methods.METHODS`): trace the camera's visible points (first
diffuse hits of the pixel samples) block by block, shade them with the path tracer (without
caustics unless the method is `pt`), and add the method's caustic radiance at the points (or
its per-pixel caustic image); `--component caustic` keeps only the caustics as the camera sees
them. A method that needs no visible points (pt, pt-nocaustic, sppm's per-pixel caustics)
traces and shades whole pixels in one kernel (`trace_pixels`, the same samples). Any method
can be denoised (the hybrid is by default).
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numpy as np
from tqdm import tqdm

from dpm import collector
from dpm.camera import Camera
from dpm.compiling import CompileWatch
from dpm.denoise import denoise, guides
from dpm.errors import InputError
from dpm.methods import method_class, validate
from dpm.options import RenderOptions
from dpm.scene import Scene
from dpm.stopwatch import Stopwatch
from dpm.tracer import (
    BVH,
    build_bvh,
    intersect,
    shade,
    trace_pixels,
    trace_visible_points,
)
from dpm.tracer.sampling import sequence_seed

__all__ = ["RenderOptions", "RenderResult", "render"]

SAMPLES_PER_STEP = 1 << 16  # pixel samples traced between progress-bar updates


@dataclass
class RenderResult:
    """A rendered image (H, W, 3) float32 linear RGB and statistics (seconds per stage, counts)."""

    image: np.ndarray
    stats: dict = field(default_factory=dict)


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
    docs/design.md); a camera inside a room whose walls face inwards is fine.
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


def render(
    scene: Scene, options: RenderOptions | None = None, started: float | None = None
) -> RenderResult:
    """Render `scene` with `options`; returns the linear RGB image and per-stage statistics.

    `started` is the `time.monotonic()` from which a `--time` budget counts (default: now;
    dpm-render passes its process start).
    """
    started = time.monotonic() if started is None else started
    options = options or RenderOptions()
    with CompileWatch(options.progress) as compiling:
        result = _render(scene, options, started)
    collector.resume()  # (where auto's first pass did not already)
    # Seconds Numba spent compiling kernels inside this render: 0 once the renderer is warm.
    result.stats["compile_seconds"] = compiling.seconds
    result.stats["compiled_kernels"] = compiling.kernels
    return result


def _render(scene: Scene, options: RenderOptions, started: float) -> RenderResult:
    """`render`, given its options and start."""
    validate(options)
    cls = method_class(options.method)
    method = cls(scene, options)
    camera = scene.camera.with_resolution(options.width, options.height)
    watch = Stopwatch()
    stats: dict = {"method": options.method, "component": options.component}
    stats["seconds"] = watch.seconds

    with watch("bvh"):
        bvh = build_bvh(scene)
    check_camera_outside(scene, bvh, camera)
    method.prepare(bvh, camera, watch)
    if cls.renders_image:  # passes of its own (auto): it denoises what it should
        image, extra = method.render_image(bvh, camera, watch, started)
        stats.update({
            "denoised": cls.denoises(options), "width": camera.width, "height": camera.height,
            "seed": options.seed, "samples": camera.width * camera.height * extra["spp"],
            "triangles": int(len(scene.triangles)), "bvh_nodes": bvh.n_nodes,
            **extra,  # its own "denoised": whether the image is the denoised one
        })  # fmt: skip
        return RenderResult(image=image, stats=stats)

    w, h, spp = camera.width, camera.height, options.spp
    image = np.zeros((h, w, 3), np.float32)
    denoised = cls.denoises(options)
    if denoised:  # the denoiser's guides: first diffuse surface's albedo and normal per pixel
        albedo, normal = np.zeros_like(image), np.zeros_like(image)
    pixels = method.caustic_pixels()
    if pixels is not None:
        image += pixels
    full = options.component == "full"
    # The progressive methods keep statistics for every visible point at once.
    rows_per_step = h if cls.all_points else max(1, SAMPLES_PER_STEP // (w * spp))
    if cls.at_points:
        watch.add("visible_points", 0.0)
        if full:
            watch.add("shade", 0.0)
    elif full:
        watch.add("path", 0.0)
    hits = dropped = 0
    sequence = (sequence_seed(options.seed), 0)  # each pixel's spp samples stratified
    cs = cls.caustic_samples(options)
    blocks = full or cls.at_points
    show = options.progress and rows_per_step < h
    with tqdm(total=h, unit="row", disable=not show, desc=options.method) as bar:
        for row0 in range(0, h if blocks else 0, rows_per_step):
            row1 = min(h, row0 + rows_per_step)
            if not cls.at_points:  # path tracing alone: whole pixels in one pass, no arrays
                with watch("path"):
                    part, a, n, found, bad = trace_pixels(
                        scene, bvh, camera, spp, options.seed, (row0, row1), cls.path_caustics,
                        sequence,
                    )  # fmt: skip
                image[row0:row1] += part
                if denoised:
                    albedo[row0:row1], normal[row0:row1] = a, n
                hits, dropped = hits + found, dropped + bad
                bar.update(row1 - row0)
                continue
            with watch("visible_points"):
                points = trace_visible_points(
                    scene, bvh, camera, spp, options.seed, (row0, row1), sequence
                )
            radiance = np.zeros((len(points), 3), np.float32)
            if full:
                with watch("shade"):
                    reflected, bad = shade(
                        scene, bvh, points, options.seed, cls.path_caustics, None, sequence, spp
                    )
                    radiance += points.emitted + points.throughput * reflected
                dropped += bad
            if cls.at_points:
                some = points.select(points.sample % spp < cs) if cs < spp else points
                with watch(cls.stage):
                    caustic = method.radiance(some, watch)
                seen = some.throughput * caustic
                image[row0:row1] += seen.reshape(row1 - row0, w, cs, 3).mean(axis=2)
            image[row0:row1] += radiance.reshape(row1 - row0, w, spp, 3).mean(axis=2)
            if denoised:
                a, n = guides(points)
                albedo[row0:row1] = a.reshape(row1 - row0, w, spp, 3).mean(axis=2)
                normal[row0:row1] = n.reshape(row1 - row0, w, spp, 3).mean(axis=2)
            hits += int(points.hit.sum())
            bar.update(row1 - row0)
    if denoised:
        with watch("denoise"):
            image = denoise(image, albedo, normal)
    stats.update(
        denoised=denoised,
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
        **method.stats(),
    )
    return RenderResult(image=image, stats=stats)
