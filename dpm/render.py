"""Rendering a loaded scene into a linear RGB image, with per-stage timings.

Every method starts from the same visible points (first diffuse hits of the camera samples);
`dpm-render --method NAME` and the benchmarks call `render`. The photon methods estimate the
caustic radiance at the visible points (`--component caustic` writes it as the camera sees
it) and, for the full image, add the path tracer without caustics (`pt-nocaustic`). The
hybrid (paper §5) is `dpm` followed by Open Image Denoise; any method can be denoised.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from tqdm import tqdm

from dpm.camera import Camera
from dpm.density import APPM, PM, PPM, SPPM, Estimator, gather
from dpm.density.pm import check_k
from dpm.density.progressive import run_passes
from dpm.errors import InputError
from dpm.scene import Scene
from dpm.tracer import (
    BVH,
    VisiblePoints,
    build_bvh,
    intersect,
    shade,
    trace_photons,
    trace_visible_points,
)

PATH_TRACERS = ("pt", "pt-nocaustic")
PHOTON_METHODS = ("pm", "ppm", "sppm", "appm", "dpm", "hybrid")
NEAREST_METHODS = ("pm", "dpm", "hybrid")  # one photon map, K nearest photons per visible point
LEARNED_METHODS = ("dpm", "hybrid")
AT_POINTS = ("pm", "ppm", "appm", "dpm", "hybrid")  # estimate at this render's visible points
METHODS = PATH_TRACERS + PHOTON_METHODS
COMPONENTS = ("full", "caustic")
SAMPLES_PER_STEP = 1 << 16  # pixel samples traced between progress-bar updates
RADIUS_FRACTION = 1e-3  # default initial radius, as a fraction of the scene's bounding diagonal
PASSES = 10  # default passes of the progressive methods: photons_per_pass = photons / PASSES
HYBRID_CAUSTIC_SPP = 1  # the hybrid estimates caustics at this many samples per pixel


@dataclass
class RenderOptions:
    """What to render; width/height None keep the camera's resolution."""

    method: str = "hybrid"
    spp: int = 16
    photons: int = 200_000
    k: int = 50
    seed: int = 0
    width: int | None = None
    height: int | None = None
    component: str = "full"
    radius: float | None = None  # initial radius (scene units); None: RADIUS_FRACTION × diagonal
    photons_per_pass: int | None = None  # None: photons / PASSES
    checkpoint: Path | None = None  # ppm/appm: statistics file to resume from and save to
    weights: Path | None = None  # dpm: weight file from dpm-train; None: the shipped model for k
    denoise: bool | None = None  # OIDN with albedo and normal images; None: for hybrid only
    caustic_spp: int | None = None  # samples per pixel given a caustic estimate; None: all
    # (hybrid: HYBRID_CAUSTIC_SPP, as the network costs more than a path)
    progress: bool = True

    @property
    def caustic_samples(self) -> int:
        """Samples per pixel (the first ones) whose visible points get a caustic estimate."""
        default = HYBRID_CAUSTIC_SPP if self.method == "hybrid" else self.spp
        return min(self.spp, self.caustic_spp or default)

    @property
    def denoised(self) -> bool:
        """Whether the image goes through the denoiser."""
        return self.method == "hybrid" if self.denoise is None else self.denoise


@dataclass
class RenderResult:
    """A rendered image (H, W, 3) float32 linear RGB and statistics (seconds per stage, counts)."""

    image: np.ndarray
    stats: dict = field(default_factory=dict)


def validate(options: RenderOptions) -> None:
    """Raise InputError for options no method can use."""
    if options.method not in METHODS:
        raise InputError(f"unknown method '{options.method}'")
    if options.component not in COMPONENTS:
        raise InputError(f"unknown component '{options.component}'; use full or caustic")
    if options.method in PATH_TRACERS and options.component != "full":
        raise InputError(f"method '{options.method}' renders no separate caustic component")
    if options.radius is not None and not (np.isfinite(options.radius) and options.radius > 0):
        raise InputError(
            f"--radius must be a positive length in scene units (got {options.radius})"
        )
    if options.photons_per_pass is not None and options.photons_per_pass < 1:
        raise InputError("--photons-per-pass must be at least 1")
    if options.checkpoint is not None and options.method not in ("ppm", "appm"):
        raise InputError("--checkpoint applies to the progressive methods ppm and appm only")
    if options.weights is not None and options.method not in LEARNED_METHODS:
        raise InputError("--weights applies to --method dpm and hybrid only")
    if options.method == "sppm" and options.component == "caustic" and options.denoised:
        raise InputError("sppm's caustic component has no albedo and normal images to denoise with")
    if options.caustic_spp is not None and options.method not in AT_POINTS:
        raise InputError("--caustic-spp applies to pm, ppm, appm, dpm and hybrid")
    for name in ("spp", "k", "caustic_spp"):
        if getattr(options, name) is not None and getattr(options, name) < 1:
            raise InputError(f"--{name.replace('_', '-')} must be at least 1")
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


def default_radius(scene: Scene) -> float:
    """Initial radius of the progressive methods: RADIUS_FRACTION of the bounding diagonal."""
    lo, hi = scene.bounds
    return float(RADIUS_FRACTION * np.linalg.norm(np.asarray(hi, np.float64) - lo))


def _photon_estimator(scene: Scene, options: RenderOptions) -> Estimator | SPPM:
    """The density estimator of a photon method, with defaults filled in."""
    if options.method == "pm":
        return PM(options.k)
    if options.method in LEARNED_METHODS:
        from dpm.nn.estimator import DPM  # imports JAX: only when asked for

        return DPM(options.k, options.weights)
    radius = options.radius if options.radius is not None else default_radius(scene)
    per_pass = options.photons_per_pass or max(1, options.photons // PASSES)
    cls = {"ppm": PPM, "appm": APPM, "sppm": SPPM}[options.method]
    return cls(radius=radius, photons_per_pass=per_pass)


def guides(points: VisiblePoints) -> tuple[np.ndarray, np.ndarray]:
    """The denoiser's per-sample guides: (N, 3) albedo in [0, 1] and (N, 3) unit normal.

    Albedo is the first diffuse surface's reflectance tinted by the mirrors and glass on the
    way (OIDN's convention for delta surfaces); a light seen directly gets its normalised
    colour, and a miss zero albedo and normal.
    """
    albedo = np.clip(points.albedo * points.throughput, 0.0, 1.0)
    peak = points.emitted.max(axis=1, keepdims=True)
    light = ~points.hit & (peak[:, 0] > 0)
    albedo[light] = points.emitted[light] / peak[light]
    return albedo, points.normal


def render(scene: Scene, options: RenderOptions | None = None) -> RenderResult:
    """Render `scene` with `options`; returns the linear RGB image and per-stage statistics."""
    options = options or RenderOptions()
    validate(options)
    camera = scene.camera.with_resolution(options.width, options.height)
    seconds: dict[str, float] = {}
    stats: dict = {"method": options.method, "component": options.component, "seconds": seconds}

    start = time.perf_counter()
    bvh = build_bvh(scene)
    seconds["bvh"] = time.perf_counter() - start
    check_camera_outside(scene, bvh, camera)

    method, w, h, spp = options.method, camera.width, camera.height, options.spp
    estimator = _photon_estimator(scene, options) if method in PHOTON_METHODS else None
    photons = None
    if method in NEAREST_METHODS:
        start = time.perf_counter()
        photons = trace_photons(scene, bvh, options.photons, options.seed, caustic_only=True)
        seconds["photons"] = time.perf_counter() - start
        check_k(options.k, photons)
        stats["caustic_photons"] = len(photons)
    image = np.zeros((h, w, 3), np.float32)
    denoised = options.denoised
    if denoised:  # the denoiser's guides: first diffuse surface's albedo and normal per pixel
        albedo, normal = np.zeros_like(image), np.zeros_like(image)
    if isinstance(estimator, SPPM):
        start = time.perf_counter()
        caustic, stats["caustic_photons"] = estimator.render(
            scene, bvh, camera, options.photons, options.seed, options.progress
        )
        image += caustic
        seconds["estimate"] = time.perf_counter() - start
    full = options.component == "full"
    # The progressive methods keep statistics for every visible point at once.
    rows_per_step = h if method in ("ppm", "appm") else max(1, SAMPLES_PER_STEP // (w * spp))
    seconds["visible_points"] = 0.0
    if full:
        seconds["shade"] = 0.0
    hits = dropped = 0
    cs = options.caustic_samples
    blocks = full or method in AT_POINTS
    show = options.progress and rows_per_step < h
    with tqdm(total=h, unit="row", disable=not show, desc=method) as bar:
        for row0 in range(0, h if blocks else 0, rows_per_step):
            row1 = min(h, row0 + rows_per_step)
            start = time.perf_counter()
            points = trace_visible_points(scene, bvh, camera, spp, options.seed, (row0, row1))
            seconds["visible_points"] += time.perf_counter() - start
            radiance = np.zeros((len(points), 3), np.float32)
            if full:
                start = time.perf_counter()
                caustics = method == "pt"
                reflected, bad = shade(scene, bvh, points, options.seed, caustics=caustics)
                radiance += points.emitted + points.throughput * reflected
                seconds["shade"] += time.perf_counter() - start
                dropped += bad
            if method in AT_POINTS:
                start = time.perf_counter()
                some = points.select(points.sample % spp < cs) if cs < spp else points
                if photons is not None:
                    gathered = gather.seconds
                    caustic = estimator.estimate(some, photons)
                    seconds["gather"] = seconds.get("gather", 0.0) + gather.seconds - gathered
                    start += gather.seconds - gathered  # "estimate": the rest, kernel or network
                else:
                    caustic, state = run_passes(
                        estimator, scene, bvh, some, options.photons, options.seed,
                        checkpoint=options.checkpoint, progress=options.progress,
                    )  # fmt: skip
                    stats["caustic_photons"] = state.photons
                stage = "network" if method in LEARNED_METHODS else "estimate"
                seconds[stage] = seconds.get(stage, 0.0) + time.perf_counter() - start
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
        from dpm.denoise import denoise

        start = time.perf_counter()
        image = denoise(image, albedo, normal)
        seconds["denoise"] = time.perf_counter() - start
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
    )
    if estimator is not None:
        stats["photon_paths"] = options.photons
        stats["caustic_spp"] = cs
        if method in NEAREST_METHODS:
            stats["k"] = options.k
        else:
            stats.update(radius=estimator.radius, photons_per_pass=estimator.photons_per_pass)
    return RenderResult(image=image, stats=stats)
