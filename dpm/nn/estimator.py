"""The learned estimator behind the common interface: `DPM(k=50).estimate(points, photons)`."""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path

import jax
import numpy as np

from dpm.density.pm import check_k
from dpm.errors import InputError
from dpm.nn.infer import make_predict, predict_points
from dpm.nn.weights import Weights, load_weights, shipped_weights
from dpm.tracer import PhotonMap, VisiblePoints


@cache
def _load(path: Path, stamp: tuple[int, int]) -> tuple[Weights, object]:
    """Weights and their jitted predictor, once per file version (stamp: mtime, size)."""
    weights = load_weights(path)
    return weights, make_predict(weights.model())


@dataclass(frozen=True)
class DPM:
    """Deep photon mapping: learned kernel weights over the k nearest photons (paper Eq. 2).

    weights: a weight file from dpm-train; default the shipped model for this k.
    """

    k: int = 50
    weights: str | Path | None = None

    def estimate(self, points: VisiblePoints, photons: PhotonMap) -> np.ndarray:
        """(N, 3) float32 caustic radiance leaving each visible point (0 where not hit)."""
        path = Path(self.weights) if self.weights is not None else shipped_weights(self.k)
        try:
            info = path.stat()
        except OSError:
            raise InputError(f"{path}: weight file not found") from None
        weights, predict = _load(path.resolve(), (info.st_mtime_ns, info.st_size))
        if weights.k != self.k:
            raise InputError(f"{path}: the model was trained with K = {weights.k}, not {self.k}")
        check_k(self.k, photons)
        out = np.zeros((len(points), 3), np.float32)
        if len(photons) == 0:
            return out
        hit = np.flatnonzero(points.hit)
        params = jax.tree.map(jax.numpy.asarray, weights.params)
        out[hit] = predict_points(
            predict, params, photons, points.position[hit], points.normal[hit],
            points.albedo[hit], self.k,
        )  # fmt: skip
        return out
