"""Sampling the area lights: a triangle by power, a point uniform by area, and its density."""

from __future__ import annotations

import numba as nb

from dpm.tracer.sampling import sample_cdf, sample_triangle


@nb.njit(cache=True, inline="always")
def sample_light_point(sc, u0, u1, u2):
    """(emitter triangle, point x, y, z, density per unit area) of a light sample."""
    tri = sc.emitter_triangles[sample_cdf(sc.emitter_cdf, u0)]
    x, y, z = sample_triangle(sc.triangles[tri], u1, u2)
    return tri, x, y, z, sc.emitter_pdf[tri]


@nb.njit(cache=True, inline="always", error_model="numpy")
def light_pdf_solid_angle(sc, tri, dist, cos_light):
    """Density (sr⁻¹) with which light sampling produces a point on emitter tri seen at dist."""
    if cos_light <= 0:
        return 0.0
    return sc.emitter_pdf[tri] * dist * dist / cos_light


@nb.njit(cache=True, inline="always")
def sample_light_stratified(sc, u, v):
    """`sample_light_point` from two numbers: u picks the triangle and, rescaled to [0, 1)
    within its share, places the point with v, so a stratified (u, v) stays stratified over
    the lights' whole area."""
    i = sample_cdf(sc.emitter_cdf, u)
    low = sc.emitter_cdf[i - 1] if i > 0 else 0.0
    share = sc.emitter_cdf[i] - low
    w = min(max((u - low) / share, 0.0), 1.0 - 2.0**-53) if share > 0 else 0.5
    tri = sc.emitter_triangles[i]
    x, y, z = sample_triangle(sc.triangles[tri], w, v)
    return tri, x, y, z, sc.emitter_pdf[tri]
