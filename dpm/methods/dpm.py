"""`dpm`: deep photon mapping (the paper), learned weights over the K nearest photons (Eq. 2).

The network is not consistent: the error stops falling as photons grow (README, benchmarks).
JAX is imported only when the method is prepared.
"""

from __future__ import annotations

from typing import Any

from dpm.methods.base import NearestPhotons


class DeepPhotonMapping(NearestPhotons):
    """DPM-K with shipped or trained weights."""

    name = "dpm"
    summary = "deep photon mapping: a network weighs each of the --k nearest photons (Eq. 2)"
    options = NearestPhotons.options | {"weights"}
    stage = "network"

    @classmethod
    def make_estimator(cls, **params: Any) -> Any:
        """The estimator behind the method: DPM(k, weights)."""
        from dpm.nn.estimator import DPM  # imports JAX: only when asked for

        return DPM(**params)

    def estimator(self) -> Any:
        """DPM with --k and --weights (k defaults to the weight file's K)."""
        return self.make_estimator(k=self.options.k, weights=self.options.weights)
