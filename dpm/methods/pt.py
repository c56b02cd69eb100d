"""Path tracing: next-event estimation, MIS and Russian roulette (`dpm.tracer.path`).

`pt` counts every path; `pt-nocaustic` leaves out, at the first diffuse vertex the camera
sees, light that arrives through mirrors or glass straight from a light (the caustics), which
the photon methods add (docs/design.md, "Light-path split").
"""

from __future__ import annotations

from dpm.methods.base import Method


class PathTracing(Method):
    """Plain path tracing: caustics found only by chance."""

    name = "pt"
    summary = "path tracing with next-event estimation and MIS"
    path_caustics = True
    caustic_component = False


class PathTracingNoCaustics(Method):
    """Path tracing without caustic paths at the first diffuse vertex."""

    name = "pt-nocaustic"
    summary = "path tracing without the caustics (what the photon methods add to)"
    caustic_component = False
