"""Deep photon mapping (the paper): `DPM(k=50).estimate(points, photons)`.

The network (`dpm.nn`) imports JAX, which costs about a second: it is imported when a model is
first loaded, so a render that does not use DPM never pays for it.
"""

from __future__ import annotations

from dataclasses import dataclass
from functools import cache
from pathlib import Path
from typing import TYPE_CHECKING, ClassVar

import numpy as np

from dpm.density.gather import Photons, Watch
from dpm.errors import InputError
from dpm.estimators.pm import k_nearest_start
from dpm.tracer import VisiblePoints

if TYPE_CHECKING:
    from dpm.nn.weights import Weights

DEFAULT_K = 50  # the shipped model used when neither k nor a weight file is given


@cache
def _load(path: Path, stamp: tuple[int, int]) -> tuple[Weights, object]:
    """Weights and their jitted predictor, once per file version (stamp: mtime, size)."""
    from dpm.nn.infer import make_query_predict
    from dpm.nn.weights import load_weights

    weights = load_weights(path)
    return weights, make_query_predict(weights.model())


def _load_file(path: Path) -> tuple[Weights, object]:
    """`_load` for the file's current version; InputError when it does not exist."""
    try:
        info = path.stat()
    except OSError:
        raise InputError(f"{path}: weight file not found") from None
    return _load(path.resolve(), (info.st_mtime_ns, info.st_size))


@dataclass(frozen=True)
class DPM:
    """Deep photon mapping: learned kernel weights over the k nearest photons (paper Eq. 2).

    weights: a weight file from dpm-train; default the shipped model for this k.
    k: None takes the weight file's K (DEFAULT_K for the shipped models).
    """

    name: ClassVar[str] = "dpm"
    summary: ClassVar[str] = (
        "deep photon mapping: a network weighs each of the --k nearest photons (Eq. 2)"
    )
    options: ClassVar[frozenset[str]] = frozenset({"weights"})  # render options it reads
    stage: ClassVar[str] = "network"

    k: int | None = None
    weights: str | Path | None = None

    def __post_init__(self) -> None:
        if self.k is None:
            k = DEFAULT_K if self.weights is None else self._file_k()
            object.__setattr__(self, "k", k)

    def _file_k(self) -> int:
        """The K the weight file was trained with."""
        return _load_file(Path(self.weights))[0].k

    def estimate(self, points: VisiblePoints, photons: Photons, watch: Watch = None) -> np.ndarray:
        """(N, 3) float32 caustic radiance leaving each visible point (0 where not hit);
        stages "gather" and "network" (features, inference, Eq. 2) count on `watch`."""
        import jax

        from dpm.nn.infer import predict_points

        weights, predict = self.model()
        watch, index, out = k_nearest_start(points, photons, self.k, watch)
        if len(index) == 0:
            return out
        hit = np.flatnonzero(points.hit)
        with watch("network"):
            params = jax.tree.map(jax.numpy.asarray, weights.params)
            out[hit] = predict_points(
                predict, params, index, points.position[hit], points.normal[hit],
                points.albedo[hit], self.k, watch,
            )  # fmt: skip
        return out

    def model(self) -> tuple[Weights, object]:
        """The weights (InputError when missing, corrupt or for another K) and their predictor."""
        path = self.path()
        weights, predict = _load_file(path)
        if weights.k != self.k:
            raise InputError(f"{path}: the model was trained with K = {weights.k}, not {self.k}")
        return weights, predict

    def path(self) -> Path:
        """The weight file: `weights`, or the shipped model for k."""
        from dpm.nn.weights import shipped_weights

        return Path(self.weights) if self.weights is not None else shipped_weights(self.k)
