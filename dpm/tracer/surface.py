"""Where a ray meets the scene: the hit point, its material, and the normal facing the ray."""

from __future__ import annotations

import numba as nb
import numpy as np

from dpm.tracer.traverse import closest_hit


@nb.njit(cache=True, inline="always", error_model="numpy")
def next_surface(bvh, sc, ox, oy, oz, dx, dy, dz, stack):
    """(triangle or -1, t, point x, y, z, normal x, y, z, material, cos_i, front) of a ray.

    The normal is flipped to face the incoming ray, so cos_i = -d·n > 0; `front` says the ray
    arrived on the triangle's front side (outside a dielectric; the side an emitter lights).
    """
    t, tri = closest_hit(bvh, ox, oy, oz, dx, dy, dz, np.inf, stack)
    if tri < 0:
        return tri, t, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0.0, False
    nx, ny, nz = sc.normals[tri, 0], sc.normals[tri, 1], sc.normals[tri, 2]
    cos_d = dx * nx + dy * ny + dz * nz
    front = cos_d < 0
    if not front:
        nx, ny, nz, cos_d = -nx, -ny, -nz, -cos_d
    px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
    return tri, t, px, py, pz, nx, ny, nz, sc.material[tri], -cos_d, front
