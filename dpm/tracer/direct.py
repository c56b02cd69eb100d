"""Direct lighting through specular chains: the simplest correct image, until full transport.

Camera rays follow mirrors and dielectrics (Fresnel-sampled, with the (η₁/η₂)² radiance
factor) to the first diffuse surface, which is lit by one next-event sample of the emitters.
Light reaching that point through glass (caustics) or other diffuse surfaces is not counted.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dpm.scene import DIELECTRIC, DIFFUSE, MIRROR
from dpm.tracer.bsdf import fresnel_dielectric, reflect, refract
from dpm.tracer.sampling import sample_cdf, sample_triangle, uniform
from dpm.tracer.traverse import any_hit, closest_hit, new_stack

DIMS_PER_BOUNCE = 4  # random numbers one vertex may use: emitter, two for its point, Fresnel


@nb.njit(cache=True, parallel=True, error_model="numpy")
def render_direct_rows(
    bvh, depth, sc, cam, width, height, row0, row1, spp, seed, eps, max_depth, out
):
    """Mean radiance of spp samples for image rows row0..row1-1 into out (rows, width, 3)."""
    inv_pi = 1.0 / math.pi
    for p in nb.prange((row1 - row0) * width):
        stack = new_stack(depth)
        y, x = row0 + p // width, p % width
        acc_r = acc_g = acc_b = 0.0
        for s in range(spp):
            stream = (y * width + x) * spp + s
            fx = 2.0 * (x + uniform(seed, stream, 0)) / width - 1.0
            fy = 1.0 - 2.0 * (y + uniform(seed, stream, 1)) / height
            dx = cam[1, 0] + fx * cam[2, 0] + fy * cam[3, 0]
            dy = cam[1, 1] + fx * cam[2, 1] + fy * cam[3, 1]
            dz = cam[1, 2] + fx * cam[2, 2] + fy * cam[3, 2]
            inv_len = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
            dx, dy, dz = dx * inv_len, dy * inv_len, dz * inv_len
            ox, oy, oz = cam[0, 0], cam[0, 1], cam[0, 2]
            tr = tg = tb = 1.0
            for bounce in range(max_depth):
                t, tri = closest_hit(bvh, ox, oy, oz, dx, dy, dz, np.inf, stack)
                if tri < 0:
                    break
                px, py, pz = ox + t * dx, oy + t * dy, oz + t * dz
                nx, ny, nz = sc.normals[tri, 0], sc.normals[tri, 1], sc.normals[tri, 2]
                m = sc.material[tri]
                cos_d = dx * nx + dy * ny + dz * nz
                front = cos_d < 0  # the front side of a dielectric is outside (air)
                if front:  # emitters radiate from the front face only
                    acc_r += tr * sc.emission[m, 0]
                    acc_g += tg * sc.emission[m, 1]
                    acc_b += tb * sc.emission[m, 2]
                else:  # face the normal towards the incoming ray
                    nx, ny, nz, cos_d = -nx, -ny, -nz, -cos_d
                kind = sc.kind[m]
                dim = 2 + DIMS_PER_BOUNCE * bounce
                if kind == DIFFUSE:
                    e = sample_cdf(sc.emitter_cdf, uniform(seed, stream, dim))
                    lt = sc.emitter_triangles[e]
                    pick = sc.emitter_cdf[e] - (sc.emitter_cdf[e - 1] if e > 0 else 0.0)
                    qx, qy, qz = sample_triangle(
                        sc.triangles[lt],
                        uniform(seed, stream, dim + 1),
                        uniform(seed, stream, dim + 2),
                    )
                    wx, wy, wz = qx - px, qy - py, qz - pz
                    dist2 = wx * wx + wy * wy + wz * wz
                    dist = math.sqrt(dist2)
                    wx, wy, wz = wx / dist, wy / dist, wz / dist
                    cos_x = wx * nx + wy * ny + wz * nz
                    ln = sc.normals[lt]
                    cos_l = -(wx * ln[0] + wy * ln[1] + wz * ln[2])
                    if cos_x > 0 and cos_l > 0 and pick > 0:
                        sx, sy, sz = px + eps * nx, py + eps * ny, pz + eps * nz
                        if not any_hit(bvh, sx, sy, sz, wx, wy, wz, dist - 2 * eps, stack):
                            # Kd/π · Le · cosθx cosθl / d² / pdf_area, pdf_area = pick / area
                            g = inv_pi * cos_x * cos_l / dist2 * sc.areas[lt] / pick
                            lm = sc.material[lt]
                            acc_r += tr * sc.albedo[m, 0] * sc.emission[lm, 0] * g
                            acc_g += tg * sc.albedo[m, 1] * sc.emission[lm, 1] * g
                            acc_b += tb * sc.albedo[m, 2] * sc.emission[lm, 2] * g
                    break
                if kind == MIRROR:
                    dx, dy, dz = reflect(dx, dy, dz, nx, ny, nz)
                    tr, tg, tb = (
                        tr * sc.specular[m, 0],
                        tg * sc.specular[m, 1],
                        tb * sc.specular[m, 2],
                    )
                    ox, oy, oz = px + eps * nx, py + eps * ny, pz + eps * nz
                elif kind == DIELECTRIC:
                    eta = sc.ior[m] if front else 1.0 / sc.ior[m]
                    f, cos_t = fresnel_dielectric(-cos_d, eta)
                    if uniform(seed, stream, dim + 3) < f:
                        dx, dy, dz = reflect(dx, dy, dz, nx, ny, nz)
                        ox, oy, oz = px + eps * nx, py + eps * ny, pz + eps * nz
                    else:
                        dx, dy, dz = refract(dx, dy, dz, nx, ny, nz, -cos_d, cos_t, eta)
                        scale = 1.0 / (eta * eta)  # radiance / η² is conserved
                        tr *= sc.transmittance[m, 0] * scale
                        tg *= sc.transmittance[m, 1] * scale
                        tb *= sc.transmittance[m, 2] * scale
                        ox, oy, oz = px - eps * nx, py - eps * ny, pz - eps * nz
                else:
                    break
        out[p // width, x, 0] = acc_r / spp
        out[p // width, x, 1] = acc_g / spp
        out[p // width, x, 2] = acc_b / spp
