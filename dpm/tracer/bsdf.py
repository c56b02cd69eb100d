"""Specular scattering: mirror reflection, the smooth dielectric (exact Fresnel) and the thin
dielectric sheet."""

from __future__ import annotations

import math

import numba as nb

from dpm.scene import DIELECTRIC, MIRROR, THIN


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


@nb.njit(cache=True, inline="always", error_model="numpy")
def scatter_specular(sc, m, dx, dy, dz, nx, ny, nz, cos_i, front, u, radiance):
    """Scatter direction d off specular material m: (new d, RGB weight, side).

    n faces the incoming side and cos_i = -d·n > 0; `front` says the ray arrived from the
    outside of a dielectric. A dielectric reflects with probability F (Fresnel), so the weight
    is Tf for refraction and 1 for reflection, times (η₁/η₂)² on radiance paths only. side is
    +1 when the new ray leaves on the incoming side (offset along n), -1 when it crosses.
    A thin sheet reflects with probability R' = 2F/(1+F), F's reflection plus every path that
    bounces inside and leaves on the incoming side (as Mitsuba's `thindielectric`), and
    otherwise passes straight through with weight Tf (air on both sides: no η² scale).
    """
    if sc.kind[m] == MIRROR:
        rx, ry, rz = reflect(dx, dy, dz, nx, ny, nz)
        return rx, ry, rz, sc.specular[m, 0], sc.specular[m, 1], sc.specular[m, 2], 1.0
    if sc.kind[m] == THIN:
        f, _ = fresnel_dielectric(cos_i, sc.ior[m])
        if u < 2.0 * f / (1.0 + f):
            rx, ry, rz = reflect(dx, dy, dz, nx, ny, nz)
            return rx, ry, rz, 1.0, 1.0, 1.0, 1.0
        tf = sc.transmittance[m]
        return dx, dy, dz, tf[0], tf[1], tf[2], -1.0
    eta = sc.ior[m] if front else 1.0 / sc.ior[m]
    f, cos_t = fresnel_dielectric(cos_i, eta)
    if u < f:
        rx, ry, rz = reflect(dx, dy, dz, nx, ny, nz)
        return rx, ry, rz, 1.0, 1.0, 1.0, 1.0
    tx, ty, tz = refract(dx, dy, dz, nx, ny, nz, cos_i, cos_t, eta)
    scale = 1.0 / (eta * eta) if radiance else 1.0  # radiance / η² is conserved
    tf = sc.transmittance[m]
    return tx, ty, tz, tf[0] * scale, tf[1] * scale, tf[2] * scale, -1.0


@nb.njit(cache=True, inline="always")
def specular_survival(sc, m, front, weight, start, radiance):
    """Russian-roulette survival probability at a specular vertex of material m.

    weight is the path's largest RGB weight and start its value where the chain began. Inside
    a dielectric the radiance weight's (η₁/η₂)² is undone, as it comes back on the way out.
    Never above 1, so surviving weights never grow: a path trapped in clear glass by total
    internal reflection is not rouletted (growing weights would make rare, huge fireflies) but
    runs to the depth cap: photons at 256 bounces lose 6e-4 of the glass egg's caustic flux;
    camera chains run to 1024 vertices (`dpm.tracer.visible.MAX_SPECULAR_DEPTH`).
    """
    scale = 1.0
    if radiance and not front and sc.kind[m] == DIELECTRIC:
        scale = sc.ior[m] * sc.ior[m]
    return min(weight * scale / start, 1.0)
