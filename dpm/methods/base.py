"""The interface every rendering method answers, and the two shapes most photon methods share.

`render()` drives a method through four hooks: `prepare` (trace a photon map, build its
index, or render a per-pixel caustic image), `radiance` (caustic radiance at a block of
visible points), `caustic_pixels` (a per-pixel caustic image, for methods that trace their
own camera samples) and `stats`. Class attributes say what a method reads and needs, so the
render loop, option checking and `--help` ask the method instead of keeping lists of names.
"""

from __future__ import annotations

from dataclasses import fields
from pathlib import Path
from typing import Any, ClassVar

import numpy as np

from dpm.camera import Camera
from dpm.density.gather import PhotonIndex
from dpm.density.held_out import HeldOutState
from dpm.density.progressive import run_passes
from dpm.errors import InputError
from dpm.estimators.pm import check_k
from dpm.estimators.ppm import ALPHA, check_progressive
from dpm.estimators.ppm import Progressive as ProgressiveEstimator
from dpm.options import RenderOptions
from dpm.scene import Scene
from dpm.stopwatch import Stopwatch
from dpm.tracer import BVH, VisiblePoints, trace_photons

PASSES = 10  # default passes of the progressive methods (sppm's come from its pixel count)


class Method:
    """A way of rendering, registered by name in `dpm.methods.METHODS`."""

    name: ClassVar[str]
    summary: ClassVar[str]  # one line for the README and --help
    options: ClassVar[frozenset[str]] = frozenset()  # scoped RenderOptions fields it reads
    path_caustics: ClassVar[bool] = False  # the path tracer counts caustic paths itself (pt)
    caustic_component: ClassVar[bool] = True  # has a separate caustic image
    at_points: ClassVar[bool] = False  # estimates caustics at the render's visible points
    all_points: ClassVar[bool] = False  # needs every visible point of the image at once
    denoise: ClassVar[bool] = False  # --denoise's default
    caustic_spp: ClassVar[int | None] = None  # --caustic-spp's default (None: every sample)
    renders_image: ClassVar[bool] = False  # renders in passes of its own (`render_image`)
    stage: ClassVar[str] = "estimate"  # the stopwatch stage of its caustic estimate
    estimator_class: ClassVar[type | None] = None  # its density estimator, if it has one

    def __init__(self, scene: Scene, options: RenderOptions) -> None:
        self.scene = scene
        self.options = options

    @classmethod
    def check(cls, options: RenderOptions) -> None:
        """Raise InputError for options this method cannot use (beyond the generic checks)."""

    @classmethod
    def denoises(cls, options: RenderOptions) -> bool:
        """Whether the image goes through the denoiser: --denoise, else the method's default."""
        return cls.denoise if options.denoise is None else options.denoise

    @classmethod
    def caustic_samples(cls, options: RenderOptions) -> int:
        """Samples per pixel (the first ones) whose visible points get a caustic estimate."""
        return min(options.spp, options.caustic_spp or cls.caustic_spp or options.spp)

    @classmethod
    def make_estimator(cls, **params: Any) -> Any:
        """The density estimator behind the method, with these parameters, answering
        `estimate(points, photons, watch) -> (N, 3)` (tuning and the benchmarks use it)."""
        if cls.estimator_class is None:
            raise InputError(f"method '{cls.name}' has no density estimator of its own")
        return cls.estimator_class(**params)

    def prepare(self, bvh: BVH, camera: Camera, watch: Stopwatch) -> None:
        """Work done once before the visible points are traced (photon maps, indices)."""

    def radiance(self, points: VisiblePoints, watch: Stopwatch) -> np.ndarray:
        """(N, 3) float32 caustic radiance leaving each visible point (before the camera
        throughput), for methods with `at_points`."""
        raise NotImplementedError(f"{self.name} estimates no caustics at visible points")

    def render_image(
        self, bvh: BVH, camera: Camera, watch: Stopwatch, started: float
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """((H, W, 3) float32 linear RGB, stats incl. "spp") for methods with `renders_image`:
        the whole image, its budget counted from `started` (time.monotonic())."""
        raise NotImplementedError(f"{self.name} renders through the render loop")

    def caustic_pixels(self) -> np.ndarray | None:
        """(H, W, 3) float32 caustic radiance per pixel as the camera sees it, or None."""
        return None

    def stats(self) -> dict[str, Any]:
        """Counts and settings for the stats JSON."""
        return {}


class PhotonMethod(Method):
    """A method that estimates caustics at visible points from emitted photon paths."""

    at_points = True

    @classmethod
    def check(cls, options: RenderOptions) -> None:
        """Raise InputError when no photons would be traced."""
        check_photons(options)

    def stats(self) -> dict[str, Any]:
        """Emitted paths, the caustic photons they gave and the caustic samples per pixel."""
        return {
            "photon_paths": self.options.photons,
            "caustic_photons": self.caustic_photons,
            "caustic_spp": self.caustic_samples(self.options),
        }


class NearestPhotons(PhotonMethod):
    """One caustic photon map, indexed once, and an estimator over each point's K nearest."""

    options = frozenset({"k", "caustic_spp"})

    @classmethod
    def check(cls, options: RenderOptions) -> None:
        """PhotonMethod's checks, and --k no more than the emitted paths (each deposits at
        most one caustic photon), whatever the scene (also one without caustics)."""
        super().check(options)
        if options.k is not None and options.k > options.photons:
            raise InputError(
                f"--k {options.k} is more than the {options.photons} photon paths emitted (each "
                "gives at most one caustic photon); raise --photons or lower --k"
            )

    def estimator(self) -> Any:
        """The estimator with this render's --k and the options it reads (the estimator's
        own defaults for those not given)."""
        return self.make_estimator(**estimator_options(self.estimator_class, self.options))

    def prepare(self, bvh: BVH, camera: Camera, watch: Stopwatch) -> None:
        """Build the estimator, trace the caustic photon map and index it."""
        self.est = self.estimator()
        with watch("photons"):
            photons = trace_photons(
                self.scene, bvh, self.options.photons, self.options.seed, caustic_only=True
            )
        check_k(self.est.k, photons)
        self.caustic_photons = len(photons)
        self.index = PhotonIndex(photons, watch)

    def radiance(self, points: VisiblePoints, watch: Stopwatch) -> np.ndarray:
        """(N, 3) float32 caustic radiance at the points from their K nearest photons."""
        return self.est.estimate(points, self.index, watch)

    def stats(self) -> dict[str, Any]:
        """PhotonMethod's stats and K."""
        return {**super().stats(), "k": self.est.k}


class Progressive(PhotonMethod):
    """A progressive estimator run pass by pass over every visible point of the image, the
    photon passes streamed from the tracer (with checkpoints)."""

    options = frozenset({"radius", "photons_per_pass", "checkpoint", "caustic_spp"})
    all_points = True

    @classmethod
    def check(cls, options: RenderOptions) -> None:
        """PhotonMethod's checks, and a positive --radius and --photons-per-pass."""
        super().check(options)
        radius, per_pass = options.radius, options.photons_per_pass
        check_progressive(
            1.0 if radius is None else radius, 1 if per_pass is None else per_pass, ALPHA
        )

    def estimator(self) -> Any:
        """The estimator with this render's initial radius, paths per pass and the options it
        reads."""
        given = estimator_options(self.estimator_class, self.options)
        given |= {"radius": self.radius(), "photons_per_pass": self.photons_per_pass()}
        return self.make_estimator(**given)

    def radius(self) -> float | None:
        """Initial radius: --radius, or None: each point's own, from what the camera sees
        (`dpm.density.radius`)."""
        return self.options.radius

    def photons_per_pass(self) -> int:
        """Emitted paths per pass: --photons-per-pass, or photons / PASSES."""
        return self.options.photons_per_pass or max(1, self.options.photons // PASSES)

    def prepare(self, bvh: BVH, camera: Camera, watch: Stopwatch) -> None:
        """Keep the BVH: the passes are traced as the points are known."""
        self.bvh = bvh
        self.est = self.estimator()

    def radiance(self, points: VisiblePoints, watch: Stopwatch) -> np.ndarray:
        """(N, 3) float32 caustic radiance at the points after every pass."""
        o = self.options
        caustic, state = run_passes(
            self.est, self.scene, self.bvh, points, o.photons, o.seed,
            checkpoint=o.checkpoint, progress=o.progress, watch=watch,
        )  # fmt: skip
        self.caustic_photons = state.photons
        # without --radius: the multiple of the view-relative radius the held-out test chose
        held_out = isinstance(state, HeldOutState) and state.passes > 0
        self.radius_scale = state.scale() if held_out else None
        return caustic

    def stats(self) -> dict[str, Any]:
        """PhotonMethod's stats, the initial radius (or the scale chosen without one) and the
        paths per pass."""
        extra = {"radius": self.est.radius, "photons_per_pass": self.est.photons_per_pass}
        if getattr(self, "radius_scale", None) is not None:
            extra["radius_scale"] = self.radius_scale
        return {**super().stats(), **extra}


def check_photons(options: RenderOptions) -> None:
    """Raise InputError when a photon method is given fewer than one photon path."""
    if options.photons < 1:
        raise InputError(
            f"--photons must be at least 1 for method {options.method} (for an image "
            "without caustics use --method pt-nocaustic)"
        )


def estimator_options(estimator: type, options: RenderOptions) -> dict[str, Any]:
    """The render options given (not None) that are parameters of the estimator dataclass,
    paths as strings."""
    given = {}
    for f in fields(estimator):
        value = getattr(options, f.name, None)
        if value is not None:
            given[f.name] = str(value) if isinstance(value, Path) else value
    return given


def estimator_method(estimator: type) -> type[Method]:
    """The render method of a density estimator (a class of `dpm.estimators`): estimates at
    the render's visible points, over the K nearest photons or in progressive passes, under
    the estimator's name, summary, options and stopwatch stage."""
    shape = Progressive if issubclass(estimator, ProgressiveEstimator) else NearestPhotons
    attributes = {
        "__doc__": f"The render method of {estimator.__name__}: {estimator.summary}.",
        "name": estimator.name,
        "summary": estimator.summary,
        "estimator_class": estimator,
        "options": shape.options | getattr(estimator, "options", frozenset()),
        "stage": getattr(estimator, "stage", Method.stage),
        "__module__": estimator.__module__,
    }
    return type(f"{estimator.__name__}Method", (shape,), attributes)
