"""Every way of rendering, registered by name (as Mitsuba registers plugins).

`render()`, option checking, `--help`, tuning, the benchmarks and the tests iterate over
`METHODS`. Every estimator of `dpm.estimators.ESTIMATORS` is a method under its own name (its
render adapter is made by `estimator_method`); beside them are the path tracers, SPPM's
per-pixel render, the paper's hybrid and the default `auto`. A new estimator is one file in
`dpm/estimators/` and one registration:

>>> from dpm.methods import METHODS, register, make_estimator
>>> register(MyEstimator)            # a dataclass with name, summary and estimate()
>>> sorted(METHODS)[:3]
['appm', 'auto', 'cppm']
>>> radiance = make_estimator("ppm", radius=0.02, photons_per_pass=50_000).estimate(pts, pm)
"""

from __future__ import annotations

from typing import Any

from dpm.errors import InputError
from dpm.estimators import ESTIMATORS
from dpm.methods.auto import Auto
from dpm.methods.base import Method, estimator_method
from dpm.methods.hybrid import Hybrid
from dpm.methods.pt import PathTracing, PathTracingNoCaustics
from dpm.methods.sppm import StochasticPPM
from dpm.options import COMPONENTS, RenderOptions, cli_fields, flag

METHODS: dict[str, type[Method]] = {}

__all__ = [
    "METHODS", "Method", "caustic_methods", "make_estimator", "method_class", "register",
    "options_from", "scoped_users", "validate",
]  # fmt: skip


def register(method: type) -> type[Method]:
    """Register a Method subclass, or a density estimator (made a method by
    `estimator_method`), under its `name`; returns the method."""
    if not (isinstance(method, type) and issubclass(method, Method)):
        method = estimator_method(method)
    METHODS[method.name] = method
    return method


for _method in (PathTracing, PathTracingNoCaustics, *ESTIMATORS, Hybrid, Auto):
    register(_method)
register(StochasticPPM)  # SPPM's own render (camera samples per pass), not one at points


def method_class(name: str) -> type[Method]:
    """The method registered as `name`; InputError naming the registered ones otherwise."""
    if name not in METHODS:
        raise InputError(f"unknown method '{name}' (one of {', '.join(METHODS)})")
    return METHODS[name]


def caustic_methods() -> tuple[str, ...]:
    """Names of the methods that render a separate caustic component."""
    return tuple(name for name, cls in METHODS.items() if cls.caustic_component)


def make_estimator(name: str, **params: Any) -> Any:
    """The density estimator behind method `name` (pm, ppm, appm, cppm, dpm, nppm, ...) with
    its parameters."""
    return method_class(name).make_estimator(**params)


def scoped_users(name: str) -> list[str]:
    """Names of the methods that read the scoped option `name`."""
    return [m for m, cls in METHODS.items() if name in cls.options]


def validate(options: RenderOptions) -> None:
    """Raise InputError (naming the flag) for options the chosen method cannot use."""
    cls = method_class(options.method)
    if options.component not in COMPONENTS:
        raise InputError(f"unknown component '{options.component}'; use full or caustic")
    if options.component == "caustic" and not cls.caustic_component:
        raise InputError(f"method '{options.method}' renders no separate caustic component")
    for f in cli_fields():
        if f.metadata["scoped"] and getattr(options, f.name) is not None:
            if f.name not in cls.options:
                users = ", ".join(scoped_users(f.name))
                raise InputError(f"{flag(f.name)} applies to {users} only, not {options.method}")
    for name in ("spp", "k", "caustic_spp"):
        if getattr(options, name) is not None and getattr(options, name) < 1:
            raise InputError(f"{flag(name)} must be at least 1")
    if options.photons < 0:
        raise InputError("--photons must not be negative")
    if options.seed < 0:
        raise InputError("--seed must not be negative")
    for name in ("width", "height"):
        value = getattr(options, name)
        if value is not None and not 1 <= value <= 16384:
            raise InputError(f"{flag(name)} must be from 1 to 16384")
    cls.check(options)


def options_from(defaults: dict[str, Any], given: dict[str, Any]) -> RenderOptions:
    """RenderOptions from `given` values (flags, keyword arguments) over a scene's `[render]`
    `defaults`. A default of a scoped option that the chosen method does not read is passed
    over (it is a default for the methods that read it), while such a given value is an
    error (`validate`); a given option that supersedes others (--weights: the file knows its
    K) sets their defaults aside."""
    fields = {f.name: f for f in cli_fields()}
    unknown = sorted(set(given) - set(fields))
    if unknown:
        raise InputError(f"unknown render option(s) {', '.join(unknown)}")
    options = RenderOptions()
    options.method = given.get("method") or defaults.get("method", options.method)
    users = method_class(options.method).options
    aside = {n for name in given for n in fields[name].metadata["supersedes"]}
    for name, f in fields.items():
        if name in defaults and name not in aside and (not f.metadata["scoped"] or name in users):
            setattr(options, name, defaults[name])
        if given.get(name) is not None:
            setattr(options, name, given[name])
    return options
