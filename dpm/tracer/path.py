"""Path tracing from visible points: next-event estimation with MIS, Russian roulette.

`shade_kernel` estimates the radiance each visible point reflects towards the camera. With
`caustics` False it leaves out, at the visible point only, light that a BSDF-sampled ray
reaches through one or more specular surfaces (the S+ L ends that caustic photons carry), so
that pt-nocaustic plus a caustic density estimate converges to pt (DESIGN.md, light-path split).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dpm.scene import DIFFUSE, Scene
from dpm.tracer.bsdf import scatter_specular, specular_survival
from dpm.tracer.bvh import BVH
from dpm.tracer.lights import light_pdf_solid_angle, sample_light_point
from dpm.tracer.sampling import sample_cosine, uniform
from dpm.tracer.surface import next_surface
from dpm.tracer.traverse import any_hit, new_stack, spawn_offset
from dpm.tracer.visible import RR_SPECULAR, SHADE_DIM0, VisiblePoints

MAX_VERTICES = 256  # path vertices after the visible point; Russian roulette ends most sooner
RR_START = 3  # vertices before Russian roulette may end a path
RR_SURVIVAL = 0.95  # the most likely survival of Russian roulette at a diffuse vertex
DIMS_PER_VERTEX = 8  # Fresnel, light pick, light point (2), direction (2), roulette, spare
SAMPLES_PER_TASK = 64


@nb.njit(cache=True, inline="always", error_model="numpy")
def _power2(a, b):
    """Power-heuristic weight of a strategy with density a against one with density b."""
    return a * a / (a * a + b * b)


@nb.njit(cache=True, inline="always", error_model="numpy")
def _unoccluded(bvh, ax, ay, az, bx, by, bz, stack):
    """Whether the open segment between points a and b is free of geometry.

    Callers lift both ends off their surfaces along the normals facing each other, so the
    segment lies in front of both planes and cannot hit either surface, even at grazing angles.
    """
    dx, dy, dz = bx - ax, by - ay, bz - az
    length = math.sqrt(dx * dx + dy * dy + dz * dz)
    if length == 0:
        return True
    inv = 1.0 / length
    return not any_hit(bvh, ax, ay, az, dx * inv, dy * inv, dz * inv, length, stack)


# Compiled without Numba's reference counting (`_nrt=False`; it allocates nothing). With it,
# every inlined call that takes the scene's or the BVH's tuple of arrays (next_surface, any_hit,
# scatter_specular, ...) increments and decrements each array's reference count: some forty
# atomic updates per ray on counters that both threads share, which cost a third of the
# shading time on two cores. Functions it calls inherit the setting.
@nb.njit(cache=True, _nrt=False, error_model="numpy")
def shade_one(bvh, sc, seed, stream, eps, caustics, stack, px, py, pz, nx, ny, nz, ar, ag, ab):
    """RGB radiance reflected by the diffuse point p (normal n towards the viewer, albedo a)."""
    inv_pi = 1.0 / math.pi
    lr = lg = lb = 0.0
    br, bg, bb = ar, ag, ab  # path weight including the BSDF·cos/pdf of the current vertex
    vertex = 0
    while vertex < MAX_VERTICES:
        dim = SHADE_DIM0 + DIMS_PER_VERTEX * vertex
        if br <= 0 and bg <= 0 and bb <= 0:
            break
        # Next-event estimation: one point on the lights, weighted against BSDF sampling.
        lt, qx, qy, qz, area_pdf = sample_light_point(
            sc, uniform(seed, stream, dim + 1), uniform(seed, stream, dim + 2),
            uniform(seed, stream, dim + 3),
        )  # fmt: skip
        wx, wy, wz = qx - px, qy - py, qz - pz
        dist = math.sqrt(wx * wx + wy * wy + wz * wz)
        if dist > 0 and area_pdf > 0:
            wx, wy, wz = wx / dist, wy / dist, wz / dist
            cos_x = wx * nx + wy * ny + wz * nz
            lx, ly, lz = sc.normals[lt, 0], sc.normals[lt, 1], sc.normals[lt, 2]
            cos_l = -(wx * lx + wy * ly + wz * lz)
            if cos_x > 0 and cos_l > 0 and _unoccluded(
                bvh, px + eps * nx, py + eps * ny, pz + eps * nz,
                qx + eps * lx, qy + eps * ly, qz + eps * lz, stack,
            ):  # fmt: skip
                pdf_l = light_pdf_solid_angle(sc, lt, dist, cos_l)
                g = inv_pi * cos_x / pdf_l * _power2(pdf_l, cos_x * inv_pi)
                e = sc.emission[sc.material[lt]]
                lr += br * e[0] * g
                lg += bg * e[1] * g
                lb += bb * e[2] * g
        # Continue by cosine sampling: BSDF·cos/pdf is the albedo, already in b.
        if vertex >= RR_START:
            q = min(max(br, bg, bb), RR_SURVIVAL)
            if uniform(seed, stream, dim + 6) >= q:
                break
            br, bg, bb = br / q, bg / q, bb / q
        dx, dy, dz = sample_cosine(
            nx, ny, nz, uniform(seed, stream, dim + 4), uniform(seed, stream, dim + 5)
        )
        pdf_b = max(dx * nx + dy * ny + dz * nz, 0.0) * inv_pi
        ox, oy, oz = px + eps * nx, py + eps * ny, pz + eps * nz
        specular = 0  # specular vertices since the last diffuse one
        start = max(br, bg, bb)  # the chain's weight before its first specular vertex
        found = False
        while vertex < MAX_VERTICES:
            vertex += 1
            tri, t, px, py, pz, nx, ny, nz, m, cos_i, front = next_surface(
                bvh, sc, ox, oy, oz, dx, dy, dz, stack
            )
            if tri < 0:
                break
            if front and sc.emitter_pdf[tri] > 0:
                if specular == 0:  # light sampling could have found it: MIS
                    w = _power2(pdf_b, light_pdf_solid_angle(sc, tri, t, cos_i))
                elif caustics or vertex > specular + 1:
                    w = 1.0  # only BSDF sampling reaches lights through specular chains
                else:
                    w = 0.0  # an S+ L end at the visible point: the caustic estimate's share
                e = sc.emission[m]
                lr += br * e[0] * w
                lg += bg * e[1] * w
                lb += bb * e[2] * w
            if sc.kind[m] == DIFFUSE:
                br, bg, bb = br * sc.albedo[m, 0], bg * sc.albedo[m, 1], bb * sc.albedo[m, 2]
                found = True
                break
            dim = SHADE_DIM0 + DIMS_PER_VERTEX * vertex
            if vertex >= RR_SPECULAR:  # long specular chains too: TIR can trap a path in glass
                q = specular_survival(sc, m, front, max(br, bg, bb), start, True)
                if uniform(seed, stream, dim + 6) >= q:
                    break
                br, bg, bb = br / q, bg / q, bb / q
            u = uniform(seed, stream, dim)
            dx, dy, dz, wr, wg, wb, side = scatter_specular(
                sc, m, dx, dy, dz, nx, ny, nz, cos_i, front, u, True
            )
            br, bg, bb = br * wr, bg * wg, bb * wb
            ox, oy, oz = px + side * eps * nx, py + side * eps * ny, pz + side * eps * nz
            specular += 1
        if not found:
            break
    return lr, lg, lb


@nb.njit(cache=True, parallel=True, error_model="numpy")
def shade_kernel(bvh, depth, sc, position, normal, albedo, hit, sample, seed, eps, caustics, out):
    """Reflected radiance (N, 3) of visible points into out; returns the non-finite count."""
    n = len(hit)
    n_tasks = (n + SAMPLES_PER_TASK - 1) // SAMPLES_PER_TASK
    bad = np.zeros(n_tasks, np.int64)
    for task in nb.prange(n_tasks):
        stack = new_stack(depth)
        for i in range(task * SAMPLES_PER_TASK, min(n, (task + 1) * SAMPLES_PER_TASK)):
            out[i] = 0.0
            if not hit[i]:
                continue
            r, g, b = shade_one(
                bvh, sc, seed, sample[i], eps, caustics, stack,
                position[i, 0], position[i, 1], position[i, 2],
                normal[i, 0], normal[i, 1], normal[i, 2],
                albedo[i, 0], albedo[i, 1], albedo[i, 2],
            )  # fmt: skip
            if math.isfinite(r) and math.isfinite(g) and math.isfinite(b):
                out[i, 0], out[i, 1], out[i, 2] = r, g, b
            else:  # never let one bad sample poison a pixel; report the count instead
                bad[task] += 1
    return bad.sum()


def shade(
    scene: Scene, bvh: BVH, points: VisiblePoints, seed: int, caustics: bool = True
) -> tuple[np.ndarray, int]:
    """Radiance (N, 3) float32 each visible point reflects towards the camera (before the
    camera-path throughput), and how many non-finite samples were dropped (set to zero).

    caustics=False leaves out the S+ L ends at the visible point (pt-nocaustic).
    """
    out = np.zeros((len(points), 3), np.float32)
    bad = shade_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), points.position, points.normal,
        points.albedo, points.hit, points.sample, seed, spawn_offset(scene), caustics, out,
    )  # fmt: skip
    return out, int(bad)
