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
