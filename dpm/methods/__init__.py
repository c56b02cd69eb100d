"""Every way of rendering, registered by name (as Mitsuba registers plugins).

`render()`, option checking, `--help`, tuning, the benchmarks and the tests iterate over
`METHODS`; adding a method is one file in this folder (a `Method` subclass) and one line here:

>>> from dpm.methods import METHODS, make_estimator
>>> sorted(METHODS)[:3]
['appm', 'auto', 'cppm']
>>> radiance = make_estimator("ppm", radius=0.02, photons_per_pass=50_000).estimate(pts, pm)
"""

from __future__ import annotations

from typing import Any

from dpm.errors import InputError
from dpm.methods.appm import AdaptivePPM
from dpm.methods.auto import Auto
from dpm.methods.base import Method
from dpm.methods.cppm import ChiSquaredPPM
from dpm.methods.dpm import DeepPhotonMapping
from dpm.methods.hybrid import Hybrid
from dpm.methods.nppm import NeuralPPM
from dpm.methods.pm import PhotonMapping
from dpm.methods.ppm import ProgressivePhotonMapping
from dpm.methods.pt import PathTracing, PathTracingNoCaustics
from dpm.methods.sppm import StochasticPPM

METHODS: dict[str, type[Method]] = {
    cls.name: cls
    for cls in (
        PathTracing,
        PathTracingNoCaustics,
        PhotonMapping,
        ProgressivePhotonMapping,
        StochasticPPM,
        AdaptivePPM,
        ChiSquaredPPM,
        DeepPhotonMapping,
        NeuralPPM,
        Hybrid,
        Auto,
    )
}

__all__ = ["METHODS", "Method", "caustic_methods", "make_estimator", "method_class"]


def method_class(name: str) -> type[Method]:
    """The method registered as `name`; InputError naming the registered ones otherwise."""
    if name not in METHODS:
        raise InputError(f"unknown method '{name}' (one of {', '.join(METHODS)})")
    return METHODS[name]


def caustic_methods() -> tuple[str, ...]:
    """Names of the methods that render a separate caustic component."""
    return tuple(name for name, cls in METHODS.items() if cls.caustic_component)


def make_estimator(name: str, **params: Any) -> Any:
    """The density estimator behind method `name` (pm, ppm, appm, cppm, dpm, nppm) with its
    parameters."""
    return method_class(name).make_estimator(**params)
