"""Visible points: camera rays followed through specular chains to the first diffuse surface.

Sample s of pixel (x, y) is random stream (y·W + x)·spp + s: dimensions 0–1 jitter it inside
the pixel, dimension 2 + 2i decides the Fresnel event at specular vertex i and 3 + 2i Russian
roulette there (from vertex RR_SPECULAR on, only where absorption has lowered the weight:
see `specular_survival`; a path trapped in clear glass ends at MAX_SPECULAR_DEPTH). Every method
starts from these same points, so the same seed gives the same visible points whatever the
method; path tracing from them uses dimensions from SHADE_DIM0 on.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numba as nb
import numpy as np

from dpm.camera import Camera
from dpm.scene import DIFFUSE, Scene
from dpm.tracer.bsdf import scatter_specular, specular_survival
from dpm.tracer.bvh import BVH
from dpm.tracer.sampling import uniform
from dpm.tracer.surface import next_surface
from dpm.tracer.traverse import new_stack, spawn_offset

MAX_SPECULAR_DEPTH = 256  # specular vertices a camera path may pass before it is dropped
RR_SPECULAR = 16  # specular vertices before Russian roulette may end a path (also for photons)
SHADE_DIM0 = 2 + 2 * MAX_SPECULAR_DEPTH


@dataclass(frozen=True)
class VisiblePoints:
    """First diffuse hits of camera samples (struct of arrays, one row per pixel sample).

    Rows with hit False escaped, were absorbed or exceeded the specular depth; their other
    fields are zero except `emitted`.
    """

    position: np.ndarray  # (N, 3) float32 world position
    normal: np.ndarray  # (N, 3) float32 unit geometric normal on the side the camera sees
    albedo: np.ndarray  # (N, 3) float32 Lambertian reflectance Kd
    throughput: np.ndarray  # (N, 3) float32 camera-path weight (Ks, Tf, (η₁/η₂)² products)
    emitted: np.ndarray  # (N, 3) float32 radiance of lights seen along the specular chain
    hit: np.ndarray  # (N,) bool: found a diffuse surface
    pixel: np.ndarray  # (N,) int32 row-major pixel index y·W + x
    sample: np.ndarray  # (N,) int64 random stream of the sample, (y·W + x)·spp + s

    def __len__(self) -> int:
        return len(self.hit)

    def select(self, mask: np.ndarray) -> VisiblePoints:
        """The rows where mask (N,) bool is set."""
        return VisiblePoints(*(getattr(self, f.name)[mask] for f in fields(self)))


@nb.njit(cache=True, inline="always", error_model="numpy")
def camera_sample(bvh, sc, cam, width, height, x, y, stream, seed, eps, stack):
    """(hit, point x, y, z, normal x, y, z, albedo r, g, b, throughput r, g, b, emitted r, g,
    b) of sample `stream` of pixel (x, y): its camera ray followed through specular vertices
    to the first diffuse surface. A miss has zero point, normal, albedo and throughput."""
    fx = 2.0 * (x + uniform(seed, stream, 0)) / width - 1.0
    fy = 1.0 - 2.0 * (y + uniform(seed, stream, 1)) / height
    dx = cam[1, 0] + fx * cam[2, 0] + fy * cam[3, 0]
    dy = cam[1, 1] + fx * cam[2, 1] + fy * cam[3, 1]
    dz = cam[1, 2] + fx * cam[2, 2] + fy * cam[3, 2]
    inv_len = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    dx, dy, dz = dx * inv_len, dy * inv_len, dz * inv_len
    ox, oy, oz = cam[0, 0], cam[0, 1], cam[0, 2]
    tr = tg = tb = 1.0
    er = eg = eb = 0.0
    for vertex in range(MAX_SPECULAR_DEPTH + 1):
        tri, _, px, py, pz, nx, ny, nz, m, cos_i, front = next_surface(
            bvh, sc, ox, oy, oz, dx, dy, dz, stack
        )
        if tri < 0:
            break
        if front:  # emitters radiate from the front face only
            er += tr * sc.emission[m, 0]
            eg += tg * sc.emission[m, 1]
            eb += tb * sc.emission[m, 2]
        if sc.kind[m] == DIFFUSE:
            a = sc.albedo[m]
            return (
                True, px, py, pz, nx, ny, nz, np.float64(a[0]), np.float64(a[1]),
                np.float64(a[2]), tr, tg, tb, er, eg, eb,
            )  # fmt: skip
        if vertex == MAX_SPECULAR_DEPTH:
            break
        if vertex >= RR_SPECULAR:
            q = specular_survival(sc, m, front, max(tr, tg, tb), 1.0, True)
            if uniform(seed, stream, 3 + 2 * vertex) >= q:
                break
            tr, tg, tb = tr / q, tg / q, tb / q
        u = uniform(seed, stream, 2 + 2 * vertex)
        dx, dy, dz, wr, wg, wb, side = scatter_specular(
            sc, m, dx, dy, dz, nx, ny, nz, cos_i, front, u, True
        )
        tr, tg, tb = tr * wr, tg * wg, tb * wb
        ox, oy, oz = px + side * eps * nx, py + side * eps * ny, pz + side * eps * nz
    z = 0.0
    return False, z, z, z, z, z, z, z, z, z, z, z, z, er, eg, eb


# Compiled without Numba's reference counting, as `dpm.tracer.path.shade_one` (see there).
@nb.njit(cache=True, _nrt=False, error_model="numpy")
def visible_pixel(
    bvh, sc, cam, width, height, pix, row, spp, seed, eps, stack,
    position, normal, albedo, throughput, emitted, hit, pixel, sample,
):  # fmt: skip
    """Fill output rows row..row+spp-1 with the samples of pixel pix (row-major index)."""
    y, x = pix // width, pix % width
    for s in range(spp):
        i = row + s
        stream = pix * spp + s
        pixel[i], sample[i] = pix, stream
        v = camera_sample(bvh, sc, cam, width, height, x, y, stream, seed, eps, stack)
        hit[i] = v[0]
        position[i, 0], position[i, 1], position[i, 2] = v[1], v[2], v[3]
        normal[i, 0], normal[i, 1], normal[i, 2] = v[4], v[5], v[6]
        albedo[i, 0], albedo[i, 1], albedo[i, 2] = v[7], v[8], v[9]
        throughput[i, 0], throughput[i, 1], throughput[i, 2] = v[10], v[11], v[12]
        emitted[i, 0], emitted[i, 1], emitted[i, 2] = v[13], v[14], v[15]


@nb.njit(cache=True, parallel=True, error_model="numpy")
def visible_points_kernel(
    bvh, depth, sc, cam, width, height, row0, row1, spp, seed, eps,
    position, normal, albedo, throughput, emitted, hit, pixel, sample,
):  # fmt: skip
    """Fill the output arrays (one row per sample of image rows row0..row1-1)."""
    for p in nb.prange((row1 - row0) * width):
        visible_pixel(
            bvh, sc, cam, width, height, row0 * width + p, p * spp, spp, seed, eps,
            new_stack(depth), position, normal, albedo, throughput, emitted, hit, pixel, sample,
        )  # fmt: skip


def trace_visible_points(
    scene: Scene, bvh: BVH, camera: Camera, spp: int, seed: int, rows: tuple[int, int]
) -> VisiblePoints:
    """Visible points of spp samples per pixel for image rows rows[0]..rows[1]-1."""
    row0, row1 = rows
    n = (row1 - row0) * camera.width * spp
    vec = [np.zeros((n, 3), np.float32) for _ in range(5)]
    hit, pixel, sample = np.zeros(n, np.bool_), np.zeros(n, np.int32), np.zeros(n, np.int64)
    visible_points_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
        camera.height, row0, row1, spp, seed, spawn_offset(scene), *vec, hit, pixel, sample,
    )  # fmt: skip
    return VisiblePoints(*vec, hit, pixel, sample)
