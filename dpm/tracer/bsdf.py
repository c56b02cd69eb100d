"""Specular scattering: mirror reflection and the smooth dielectric (exact Fresnel)."""

from __future__ import annotations

import math

import numba as nb


@nb.njit(cache=True, inline="always")
def reflect(dx, dy, dz, nx, ny, nz):
    """Mirror direction of incoming direction d about normal n (either orientation)."""
    c = 2.0 * (dx * nx + dy * ny + dz * nz)
    return dx - c * nx, dy - c * ny, dz - c * nz


@nb.njit(cache=True, inline="always", error_model="numpy")
def fresnel_dielectric(cos_i, eta):
    """(reflectance, cos of the transmitted angle) for unpolarised light; eta = n_t / n_i.

    cos_i is the cosine of the incident angle (≥ 0); total internal reflection gives (1, 0).
    """
    sin2_t = (1.0 - cos_i * cos_i) / (eta * eta)
    if sin2_t >= 1.0:
        return 1.0, 0.0
    cos_t = math.sqrt(1.0 - sin2_t)
    rs = (cos_i - eta * cos_t) / (cos_i + eta * cos_t)
    rp = (eta * cos_i - cos_t) / (eta * cos_i + cos_t)
    return 0.5 * (rs * rs + rp * rp), cos_t


@nb.njit(cache=True, inline="always")
def refract(dx, dy, dz, nx, ny, nz, cos_i, cos_t, eta):
    """Transmitted direction of incoming d through normal n facing the incoming side."""
    k = cos_i / eta - cos_t
    return dx / eta + k * nx, dy / eta + k * ny, dz / eta + k * nz
