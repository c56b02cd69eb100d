"""`nppm`: neural progressive photon mapping, PPM with a per-point kernel shape from a network.

Consistent whatever the network says (dpm.density.nppm); JAX is imported only when the
estimate starts.
"""

from __future__ import annotations

from typing import Any

from dpm.density.nppm import NPPM
from dpm.methods.base import Progressive


class NeuralPPM(Progressive):
    """nppm with the shipped or trained (`--weights`) shape network."""

    name = "nppm"
    summary = "neural PPM: PPM whose kernel a network shapes per point and pass (consistent)"
    options = Progressive.options | {"weights"}
    stage = "network"
    estimator_class = NPPM

    def estimator(self) -> Any:
        """NPPM with this render's initial radius, paths per pass and --weights."""
        weights = "" if self.options.weights is None else str(self.options.weights)
        return self.make_estimator(
            radius=self.radius(), photons_per_pass=self.photons_per_pass(), weights=weights
        )
