"""Where a ray meets the scene: the hit point, its material, and the normal facing the ray."""

from __future__ import annotations

import math

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
    return surface_at(sc, ox, oy, oz, dx, dy, dz, t, tri)


@nb.njit(cache=True, inline="always", error_model="numpy")
def surface_at(sc, ox, oy, oz, dx, dy, dz, t, tri):
    """`next_surface`'s tuple for the ray's closest hit (t, triangle or -1), traced already."""
    if tri < 0:
        return tri, t, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0.0, False
    nx, ny, nz = sc.normals[tri, 0], sc.normals[tri, 1], sc.normals[tri, 2]
    cos_d = dx * nx + dy * ny + dz * nz
    front = cos_d < 0
    if not front:
        nx, ny, nz, cos_d = -nx, -ny, -nz, -cos_d
    px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
    return tri, t, px, py, pz, nx, ny, nz, sc.material[tri], -cos_d, front


@nb.njit(cache=True, inline="always", error_model="numpy")
def albedo_at(sc, m, tri, px, py, pz):
    """(r, g, b) diffuse reflectance of material m at point p on triangle tri: Kd, times its
    texture (bilinear, repeating; v up, the image's first row at v = 1) where it has one."""
    a = sc.albedo[m]
    k = sc.texture[m]
    if k < 0:
        return np.float64(a[0]), np.float64(a[1]), np.float64(a[2])
    # barycentric coordinates of p, by the normal equations of p - v0 = b1·e1 + b2·e2
    v = sc.triangles[tri]
    e1x, e1y, e1z = v[1, 0] - v[0, 0], v[1, 1] - v[0, 1], v[1, 2] - v[0, 2]
    e2x, e2y, e2z = v[2, 0] - v[0, 0], v[2, 1] - v[0, 1], v[2, 2] - v[0, 2]
    qx, qy, qz = px - v[0, 0], py - v[0, 1], pz - v[0, 2]
    d11 = e1x * e1x + e1y * e1y + e1z * e1z
    d12 = e1x * e2x + e1y * e2y + e1z * e2z
    d22 = e2x * e2x + e2y * e2y + e2z * e2z
    q1 = qx * e1x + qy * e1y + qz * e1z
    q2 = qx * e2x + qy * e2y + qz * e2z
    det = d11 * d22 - d12 * d12
    b1 = (d22 * q1 - d12 * q2) / det
    b2 = (d11 * q2 - d12 * q1) / det
    b0 = 1.0 - b1 - b2
    uv = sc.uvs[tri]
    u = b0 * uv[0, 0] + b1 * uv[1, 0] + b2 * uv[2, 0]
    w = b0 * uv[0, 1] + b1 * uv[1, 1] + b2 * uv[2, 1]
    first, width, height = sc.texture_dims[k, 0], sc.texture_dims[k, 1], sc.texture_dims[k, 2]
    x = u * width - 0.5  # texel centres at half-integers
    y = (1.0 - w) * height - 0.5
    fx, fy = math.floor(x), math.floor(y)
    tx, ty = x - fx, y - fy
    x0, y0 = np.int64(fx) % width, np.int64(fy) % height
    x1, y1 = (x0 + 1) % width, (y0 + 1) % height
    i00, i10 = first + y0 * width + x0, first + y0 * width + x1
    i01, i11 = first + y1 * width + x0, first + y1 * width + x1
    t = sc.texels
    out_r = _bilinear(t[i00, 0], t[i10, 0], t[i01, 0], t[i11, 0], tx, ty)
    out_g = _bilinear(t[i00, 1], t[i10, 1], t[i01, 1], t[i11, 1], tx, ty)
    out_b = _bilinear(t[i00, 2], t[i10, 2], t[i01, 2], t[i11, 2], tx, ty)
    return a[0] * out_r, a[1] * out_g, a[2] * out_b


@nb.njit(cache=True, inline="always", error_model="numpy")
def _bilinear(t00, t10, t01, t11, tx, ty):
    """Bilinear blend of four corner values at fractions (tx, ty) from the first."""
    top = t00 + (t10 - t00) * tx
    bottom = t01 + (t11 - t01) * tx
    return top + (bottom - top) * ty
