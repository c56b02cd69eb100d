"""Neural progressive photon mapping: PPM whose kernel in each pass is shaped per point by a
small network (after the idea of Benoist, Litalien & Gruson, Eurographics 2026; our design).

Each visible point keeps PPM's radius R, count N and flux τ, updated exactly as PPM's, except
that a pass's photons enter τ weighted by the point's shaped kernel relative to the uniform
disc (dpm.density.shaped): an anisotropic Gaussian truncated at R and normalised exactly. Its
two precisions come from the network, once per point per pass, from the statistics of the
photons the point gathered in *earlier* passes (their spread's principal axes, eigenvalues,
mean offset, incident directions, counts); the kernel of a pass never depends on that pass's
photons, so each pass's weighted flux is an unbiased estimate of the kernel-smoothed density.

Consistent whatever the network says: the radius follows PPM's schedule (R → 0, N → ∞), the
kernel is even and integrates to 1 over the disc, and its weight is bounded (≤ 13), so the
bias is O(R²) and the variance a bounded multiple of PPM's. Points with no earlier photons
(every point in the first pass) use the uniform kernel; a fresh network (zero last layer)
gives p = 0 everywhere, and then nppm is PPM, bit for bit.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import ClassVar

import numpy as np

from dpm.density.base import in_plane, tangent_frame
from dpm.density.gather import PointIndex
from dpm.density.progressive import ALPHA
from dpm.density.shaped import (
    MOMENTS,
    features,
    normaliser,
    pair_moments,
    principal_axes,
    relative_weight,
    to_axes,
)
from dpm.errors import InputError
from dpm.estimators.ppm import PPMState, Progressive, Radius, start_radius
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap

SHIPPED = Path(__file__).parents[1] / "nn" / "weights" / "nppm.msgpack"
NETWORK = "network"  # the stopwatch stage of features and inference


@cache
def _predictor(path: str, stamp: tuple[int, int]) -> object:
    """The jitted network of a weight file, once per file version (imports JAX)."""
    from dpm.nn.shape_net import ShapePredictor
    from dpm.nn.weights import load_weights

    weights = load_weights(path)
    if weights.architecture != "nppm":
        raise InputError(f"{path}: a {weights.architecture} model, not an nppm one")
    return ShapePredictor(weights.model(), weights.params)


def predictor(path: str) -> object:
    """The network of weight file `path` ('' : the shipped one); InputError when missing."""
    p = Path(path) if path else SHIPPED
    try:
        info = p.stat()
    except OSError:
        raise InputError(f"{p}: weight file not found") from None
    return _predictor(str(p.resolve()), (info.st_mtime_ns, info.st_size))


@dataclass
class NPPMState(PPMState):
    """PPM's per-point statistics, the photon moments of earlier passes and the network's file."""

    SUMS: ClassVar[bool] = False  # reads the pairs (`add`)

    moments: np.ndarray  # (n, MOMENTS) float64, decayed as τ (dpm.density.shaped)
    weights: str = ""  # weight file of the network ('': the shipped one)

    @classmethod
    def start(
        cls, n: int, radius: float | np.ndarray, alpha: float = ALPHA, weights: str = ""
    ) -> NPPMState:
        """A state of n points with initial radius `radius` (one, or (n,) per point) and
        nothing gathered."""
        return cls(
            start_radius(n, radius), np.zeros(n), np.zeros((n, 3)), np.zeros((n, MOMENTS)),
            weights, alpha=alpha,
        )  # fmt: skip

    def add(self, index: PointIndex, photons: PhotonMap, watch: Stopwatch | None = None) -> None:
        """Gather one pass, weigh each photon by its point's shaped kernel, shrink as PPM."""
        watch = watch or Stopwatch()
        pairs = index.within(photons, self.radius, watch)
        point, n = pairs.point, len(self.radius)
        offset = photons.position[pairs.photon].astype(np.float64) - index.position[point]
        t, b = tangent_frame(index.normal[point])
        ab = in_plane(offset, t, b) / self.radius[point, None]
        dab = in_plane(photons.direction[pairs.photon], t, b)
        weight = self.kernel(point, ab, watch)
        flux = photons.flux[pairs.photon].astype(np.float64) * photons.n_paths
        before = self.radius
        self.update(point, flux * weight[:, None])
        ratio = (self.radius / before) ** 2
        self.moments = (self.moments + pair_moments(point, n, ab, dab)) * ratio[:, None]
        self.paths += photons.n_paths
        self.passes += 1
        self.photons += len(photons)

    def kernel(self, point: np.ndarray, ab: np.ndarray, watch: Stopwatch) -> np.ndarray:
        """(Q,) kernel weights relative to the uniform disc of photons at points `point` (Q,)
        with offsets ab (Q, 2, units of R): 1 at points with no earlier photons."""
        weight = np.ones(len(point))
        found = np.bincount(point, minlength=len(self.radius)) > 0
        shaped = np.flatnonzero(found & (self.moments[:, 0] > 0))
        if len(shaped) == 0:
            return weight
        with watch(NETWORK):  # per shaped point (few in a small pass), not per photon
            n = len(self.radius)
            p, z, cos, sin = np.zeros((n, 2)), np.full(n, np.pi), np.ones(n), np.zeros(n)
            p[shaped] = predictor(self.weights)(features(self.moments[shaped]))
            z[shaped] = normaliser(p[shaped, 0], p[shaped, 1])
            cos[shaped], sin[shaped] = principal_axes(self.moments[shaped])
            sel = np.flatnonzero(self.moments[point, 0] > 0)
            q = point[sel]
            uv = to_axes(ab[sel], cos[q], sin[q])
            weight[sel] = relative_weight(uv[:, 0], uv[:, 1], p[q, 0], p[q, 1], z=z[q])
        return weight


@dataclass(frozen=True)
class NPPM(Progressive):
    """nppm at fixed visible points: initial radius (scene units), emitted paths per pass and
    the network's weight file ('': the shipped one)."""

    name: ClassVar[str] = "nppm"
    summary: ClassVar[str] = (
        "neural PPM: PPM whose kernel a network shapes per point and pass (consistent)"
    )
    options: ClassVar[frozenset[str]] = frozenset({"weights"})  # render options it reads
    stage: ClassVar[str] = NETWORK
    # The shaped kernel is narrower than the disc it lives in, so the disc starts wider than
    # PPM's (×1, ×1.4, ×2 on the examples at M and 10·M: default / best tuned classic 1.26,
    # 1.14, 1.17 geometric mean; worst 1.75, 1.56, 2.10).
    scale: ClassVar[float] = 1.4

    weights: str = ""

    def check(self) -> None:
        """Progressive's checks, and that the weight file loads."""
        super().check()
        predictor(self.weights)

    def start(self, n: int, radius: Radius) -> NPPMState:
        """The state before the first pass, for n points with initial radius `radius`."""
        return NPPMState.start(n, radius, self.alpha, self.weights)
