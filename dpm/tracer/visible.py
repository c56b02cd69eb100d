"""Visible points: camera rays followed through specular chains to the first diffuse surface.

Sample s of pixel (x, y) is random stream (y·W + x)·spp + s: dimensions 0–1 jitter it inside
the pixel, dimension 2 + 2i decides the Fresnel event at specular vertex i and 3 + 2i Russian
roulette there (from vertex RR_SPECULAR on, only where absorption has lowered the weight:
see `specular_survival`; a path trapped in clear glass ends at MAX_SPECULAR_DEPTH). Every method
starts from these same points, so the same seed gives the same visible points whatever the
method; path tracing from them uses dimensions from SHADE_DIM0 on. At a dielectric the light
both Fresnel branches see next counts, weighted, on every path (emission splitting, in
`camera_sample`), so the emitted radiance is not the chosen branch's alone; the points are.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

import numba as nb
import numpy as np

from dpm.camera import Camera
from dpm.filters import dilate3
from dpm.scene import DIELECTRIC, DIFFUSE, Scene
from dpm.tracer.addresses import (
    bvh_at,
    bvh_words,
    keep_alive,
    scene_at,
    scene_words,
    stack_at,
    stack_words,
)
from dpm.tracer.bsdf import (
    fresnel_dielectric,
    reflect,
    refract,
    scatter_specular,
    specular_survival,
)
from dpm.tracer.bvh import BVH
from dpm.tracer.sampling import pixel_sequence, sobol2, stratified2, uniform
from dpm.tracer.surface import albedo_at, next_surface
from dpm.tracer.traverse import hit_triangle, new_stack, ray_setup, spawn_offset

# Specular vertices a camera path may pass before it is dropped. Clear glass traps some
# chains by total internal reflection (weight 1, so roulette spares them) and some escape
# late: in the glass egg at 256 the chains left out held 2.2 % of the pt image's mean (the
# light seen through the egg); 1024 loses nothing more than 4096 does, at about 2 % more time.
MAX_SPECULAR_DEPTH = 1024
RR_SPECULAR = 16  # specular vertices before Russian roulette may end a path (also for photons)
# Path tracing from the visible point (`dpm.tracer.path`, `dpm.tracer.wavefront`):
MAX_VERTICES = 256  # path vertices after the visible point; Russian roulette ends most sooner
RR_START = 3  # vertices before Russian roulette may end a path
RR_SURVIVAL = 0.95  # the most likely survival of Russian roulette at a diffuse vertex
SHADE_DIM0 = 2 + 2 * MAX_SPECULAR_DEPTH
LUMINANCE = (0.2126, 0.7152, 0.0722)  # Rec. 709 weights (dpm.density.base.luminance too)


_NO_HIT = (-1, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0.0, 0, 0.0, False)  # `next_surface`'s miss
SCATTER = 2**31 - 1  # a prime above any task count: i -> i·SCATTER mod n is a permutation
# Pixels of one parallel task, which allocates one traversal stack for them (a stack a
# pixel was a malloc and a free for each pixel of every pass)
PIXELS_PER_TASK = 16
LIGHT_TEST_TRIANGLES = 16  # lights with more triangles are found by tracing, not one by one


@nb.njit(cache=True, inline="always", error_model="numpy")
def _may_meet_light(sc, ox, oy, oz, dx, dy, dz):
    """Whether the ray o + t·d (t > 0) meets the front face of an emitter triangle, tested
    against each one (the watertight test the BVH's leaves use, so a light the traced ray
    would hit is never missed); True without testing when the lights have many triangles."""
    if len(sc.emitter_triangles) > LIGHT_TEST_TRIANGLES:
        return True
    kx, ky, kz, sx, sy, sz = ray_setup(dx, dy, dz)
    rows = sc.triangles.reshape((sc.triangles.shape[0], 9))  # hit_triangle's (T, 9) rows
    for e in sc.emitter_triangles:
        n = sc.normals[e]
        if dx * n[0] + dy * n[1] + dz * n[2] < 0:
            if hit_triangle(rows, e, ox, oy, oz, kx, ky, kz, sx, sy, sz, np.inf) < np.inf:
                return True
    return False


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
    # (N,) float32 pixel width at the point (scene units, `Camera.footprint`; 0 on a miss);
    # None for points not seen through a camera
    footprint: np.ndarray | None = None

    def __len__(self) -> int:
        return len(self.hit)

    def select(self, mask: np.ndarray) -> VisiblePoints:
        """The rows where mask (N,) bool is set."""
        return VisiblePoints(
            *(None if (a := getattr(self, f.name)) is None else a[mask] for f in fields(self))
        )


@nb.njit(cache=True, inline="always", error_model="numpy")
def camera_ray(cam, width, height, px, py):
    """Unit direction (x, y, z) of the camera ray through image point (px, py) (pixels from
    the top left corner; cam: origin, forward, right and up rows)."""
    fx = 2.0 * px / width - 1.0
    fy = 1.0 - 2.0 * py / height
    dx = cam[1, 0] + fx * cam[2, 0] + fy * cam[3, 0]
    dy = cam[1, 1] + fx * cam[2, 1] + fy * cam[3, 1]
    dz = cam[1, 2] + fx * cam[2, 2] + fy * cam[3, 2]
    inv_len = 1.0 / math.sqrt(dx * dx + dy * dy + dz * dz)
    return dx * inv_len, dy * inv_len, dz * inv_len


@nb.njit(cache=True, inline="always", error_model="numpy")
def camera_sample(bvh, sc, cam, width, height, x, y, sx, sy, stream, seed, eps, stack):
    """(hit, point x, y, z, normal x, y, z, albedo r, g, b, throughput r, g, b, emitted r, g,
    b) of sample `stream` of pixel (x, y) through its point (x + sx, y + sy): its camera ray
    followed through specular vertices to the first diffuse surface (decisions from
    dimensions 2 on). A miss has zero point, normal, albedo and throughput."""
    dx, dy, dz = camera_ray(cam, width, height, x + sx, y + sy)
    hit = next_surface(bvh, sc, cam[0, 0], cam[0, 1], cam[0, 2], dx, dy, dz, stack)
    return chain_from(bvh, sc, dx, dy, dz, hit, stream, seed, eps, stack)


@nb.njit(cache=True, inline="always", error_model="numpy")
def lean_from(bvh, sc, dx, dy, dz, hit, stream, seed, eps, stack):
    """`chain_from`, the same values, with the chain through mirrors and glass called
    (`_camera_chain`, through `camera_chain`) rather than inlined: a miss or a diffuse first
    hit returns at once. In `path_pixel`, which inlines the path's shading too, the inlined
    chain made the kernel larger and slower (`pt` on the ring 4.9-6.1 M samples/s, varying
    from process to process, against 6.3-6.4); where the camera sample is all a kernel does
    (`visible_pixel`), the call made it slower (16.8 against 9.0)."""
    tri, _, px, py, pz, nx, ny, nz, m, cos_i, front = hit
    z = 0.0
    if tri < 0:
        return False, z, z, z, z, z, z, z, z, z, z, z, z, z, z, z
    if sc.kind[m] != DIFFUSE:
        return camera_chain(bvh, sc, dx, dy, dz, hit, stream, seed, eps, stack)
    er = eg = eb = 0.0  # a diffuse surface seen straight: what `chain_from` would return
    if front:  # emitters radiate from the front face only
        er, eg, eb = sc.emission[m, 0] * 1.0, sc.emission[m, 1] * 1.0, sc.emission[m, 2] * 1.0
    ar, ag, ab = albedo_at(sc, m, tri, px, py, pz)
    return True, px, py, pz, nx, ny, nz, ar, ag, ab, 1.0, 1.0, 1.0, er, eg, eb


@nb.njit(cache=True, inline="always", error_model="numpy")
def chain_from(bvh, sc, dx, dy, dz, hit, stream, seed, eps, stack):
    """`camera_sample` from its camera ray's direction d and first hit (`next_surface`'s
    tuple) on, through the mirrors and glass on its way."""
    tri, _, px, py, pz, nx, ny, nz, m, cos_i, front = hit
    tr = tg = tb = 1.0
    er = eg = eb = 0.0
    counted = False  # whether this hit's emission is already in e (a dielectric's split)
    for vertex in range(MAX_SPECULAR_DEPTH + 1):
        if tri < 0:
            break
        if front and not counted:  # emitters radiate from the front face only
            er += tr * sc.emission[m, 0]
            eg += tg * sc.emission[m, 1]
            eb += tb * sc.emission[m, 2]
        if sc.kind[m] == DIFFUSE:
            ar, ag, ab = albedo_at(sc, m, tri, px, py, pz)
            return True, px, py, pz, nx, ny, nz, ar, ag, ab, tr, tg, tb, er, eg, eb
        if vertex == MAX_SPECULAR_DEPTH:
            break
        if vertex >= RR_SPECULAR:
            q = specular_survival(sc, m, front, max(tr, tg, tb), 1.0, True)
            if uniform(seed, stream, 3 + 2 * vertex) >= q:
                break
            tr, tg, tb = tr / q, tg / q, tb / q
        u = uniform(seed, stream, 2 + 2 * vertex)
        if sc.kind[m] != DIELECTRIC:
            dx, dy, dz, wr, wg, wb, side = scatter_specular(
                sc, m, dx, dy, dz, nx, ny, nz, cos_i, front, u, True
            )
            tr, tg, tb = tr * wr, tg * wg, tb * wb
            ox, oy, oz = px + side * eps * nx, py + side * eps * ny, pz + side * eps * nz
            tri, _, px, py, pz, nx, ny, nz, m, cos_i, front = next_surface(
                bvh, sc, ox, oy, oz, dx, dy, dz, stack
            )
            counted = False
            continue
        # Emission splitting: the light each Fresnel branch sees at its next surface counts
        # with the branch's weight (F, or (1 - F)·Tf/η²) on every path, and the path goes on
        # along one branch, chosen as before. A small light seen in water or glass is
        # otherwise found by a few paths in a hundred: the fireflies that dominate those
        # scenes' error. The branch not taken is traced only if it can meet a light.
        eta = sc.ior[m] if front else 1.0 / sc.ior[m]
        f, cos_t = fresnel_dielectric(cos_i, eta)
        tf = sc.transmittance[m]
        scale = 1.0 / (eta * eta)  # radiance / η² is conserved
        wr, wg, wb = tf[0] * scale, tf[1] * scale, tf[2] * scale
        reflected = u < f
        rx, ry, rz = reflect(dx, dy, dz, nx, ny, nz)
        ox, oy, oz = px + eps * nx, py + eps * ny, pz + eps * nz
        hit_r = _NO_HIT
        if reflected or _may_meet_light(sc, ox, oy, oz, rx, ry, rz):
            hit_r = next_surface(bvh, sc, ox, oy, oz, rx, ry, rz, stack)
            if hit_r[0] >= 0 and hit_r[10]:
                er += tr * f * sc.emission[hit_r[8], 0]
                eg += tg * f * sc.emission[hit_r[8], 1]
                eb += tb * f * sc.emission[hit_r[8], 2]
        tx, ty, tz = refract(dx, dy, dz, nx, ny, nz, cos_i, cos_t, eta)
        ox, oy, oz = px - eps * nx, py - eps * ny, pz - eps * nz
        hit_t = _NO_HIT
        if not reflected or (f < 1 and _may_meet_light(sc, ox, oy, oz, tx, ty, tz)):
            hit_t = next_surface(bvh, sc, ox, oy, oz, tx, ty, tz, stack)
            if hit_t[0] >= 0 and hit_t[10]:
                er += tr * wr * (1.0 - f) * sc.emission[hit_t[8], 0]
                eg += tg * wg * (1.0 - f) * sc.emission[hit_t[8], 1]
                eb += tb * wb * (1.0 - f) * sc.emission[hit_t[8], 2]
        if reflected:
            dx, dy, dz = rx, ry, rz
            tri, _, px, py, pz, nx, ny, nz, m, cos_i, front = hit_r
        else:
            dx, dy, dz = tx, ty, tz
            tr, tg, tb = tr * wr, tg * wg, tb * wb
            tri, _, px, py, pz, nx, ny, nz, m, cos_i, front = hit_t
        counted = True
    z = 0.0
    return False, z, z, z, z, z, z, z, z, z, z, z, z, er, eg, eb


@nb.njit(cache=True, inline="always")
def camera_chain(bvh, sc, dx, dy, dz, hit, stream, seed, eps, stack):
    """`chain_from`, called (`_camera_chain`) with its arrays passed by address."""
    out = _camera_chain(
        bvh_words(bvh), scene_words(sc), dx, dy, dz, hit, stream, seed, eps, *stack_words(stack)
    )
    keep_alive(bvh, sc, stack)
    return out


@nb.njit(cache=True, _nrt=False, error_model="numpy")
def _camera_chain(bvh, sc, dx, dy, dz, hit, stream, seed, eps, stack, rows):
    """`camera_chain` on the `dpm.tracer.addresses` words of its arrays."""
    return chain_from(
        bvh_at(bvh), scene_at(sc), dx, dy, dz, hit, stream, seed, eps, stack_at(stack, (rows, 2))
    )


@nb.njit(cache=True, inline="always")
def visible_pixel(
    bvh, sc, cam, width, height, pix, row, spp, seed, sequence, first, eps, stack,
    position, normal, albedo, throughput, emitted, hit, pixel, sample,
):  # fmt: skip
    """Fill output rows row..row+spp-1 with the samples of pixel pix (row-major index); with
    sequence ≥ 0, sample s lies at point first + s of the pixel's stratified sequence.
    Called (`_visible_pixel`) with the BVH, the scene and the stack passed by address."""
    _visible_pixel(
        bvh_words(bvh), scene_words(sc), cam, width, height, pix, row, spp, seed, sequence,
        first, eps, *stack_words(stack), position, normal, albedo, throughput, emitted, hit,
        pixel, sample,
    )  # fmt: skip
    keep_alive(bvh, sc, stack)


# Compiled without Numba's reference counting, as `dpm.tracer.path._shade_one` (see there).
@nb.njit(cache=True, _nrt=False, error_model="numpy")
def _visible_pixel(
    bvh, sc, cam, width, height, pix, row, spp, seed, sequence, first, eps, stack, rows,
    position, normal, albedo, throughput, emitted, hit, pixel, sample,
):  # fmt: skip
    """`visible_pixel` on the `dpm.tracer.addresses` words of its BVH, scene and stack."""
    bvh, sc, stack = bvh_at(bvh), scene_at(sc), stack_at(stack, (rows, 2))
    y, x = pix // width, pix % width
    pseq = pixel_sequence(max(sequence, 0), pix)
    for s in range(spp):
        i = row + s
        stream = pix * spp + s
        pixel[i], sample[i] = pix, stream
        if sequence >= 0:
            sx, sy = stratified2(first + s, pseq, 0)
        else:
            sx, sy = uniform(seed, stream, 0), uniform(seed, stream, 1)
        v = camera_sample(bvh, sc, cam, width, height, x, y, sx, sy, stream, seed, eps, stack)
        hit[i] = v[0]
        position[i, 0], position[i, 1], position[i, 2] = v[1], v[2], v[3]
        normal[i, 0], normal[i, 1], normal[i, 2] = v[4], v[5], v[6]
        albedo[i, 0], albedo[i, 1], albedo[i, 2] = v[7], v[8], v[9]
        throughput[i, 0], throughput[i, 1], throughput[i, 2] = v[10], v[11], v[12]
        emitted[i, 0], emitted[i, 1], emitted[i, 2] = v[13], v[14], v[15]


@nb.njit(cache=True, parallel=True, error_model="numpy")
def visible_points_kernel(
    bvh, depth, sc, cam, width, height, row0, row1, spp, seed, sequence, first, eps,
    position, normal, albedo, throughput, emitted, hit, pixel, sample,
):  # fmt: skip
    """Fill the output arrays (one row per sample of image rows row0..row1-1)."""
    n = (row1 - row0) * width
    for task in nb.prange((n + PIXELS_PER_TASK - 1) // PIXELS_PER_TASK):
        stack = new_stack(depth)
        for p in range(task * PIXELS_PER_TASK, min(n, (task + 1) * PIXELS_PER_TASK)):
            visible_pixel(
                bvh, sc, cam, width, height, row0 * width + p, p * spp, spp, seed, sequence,
                first, eps, stack, position, normal, albedo, throughput, emitted, hit, pixel,
                sample,
            )  # fmt: skip


def trace_visible_points(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    spp: int,
    seed: int,
    rows: tuple[int, int],
    sequence: tuple[int, int] | None = None,
) -> VisiblePoints:
    """Visible points of spp samples per pixel for image rows rows[0]..rows[1]-1. With
    `sequence` (seed, first), sample s of a pixel lies at point first + s of the pixel's
    stratified sequence (`stratified2`; pass the same to `shade`), else at random."""
    row0, row1 = rows
    qseed, first = (-1, 0) if sequence is None else sequence
    n = (row1 - row0) * camera.width * spp
    vec = [np.zeros((n, 3), np.float32) for _ in range(5)]
    hit, pixel, sample = np.zeros(n, np.bool_), np.zeros(n, np.int32), np.zeros(n, np.int64)
    visible_points_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
        camera.height, row0, row1, spp, seed, qseed, first, spawn_offset(scene), *vec, hit,
        pixel, sample,
    )  # fmt: skip
    footprint = np.where(hit, camera.footprint(vec[0]), 0.0).astype(np.float32)
    return VisiblePoints(*vec, hit, pixel, sample, footprint)


@nb.njit(cache=True, inline="always")
def emitted_pixel(bvh, sc, cam, width, height, pix, count, first, seed, eps, stack):
    """(r, g, b, squared luminance) sums over samples first … first + count - 1 of pixel pix's
    scrambled Sobol sequence: the radiance of lights seen along their specular chains.
    Called (`_emitted_pixel`) with the BVH, the scene and the stack passed by address."""
    out = _emitted_pixel(
        bvh_words(bvh), scene_words(sc), cam, width, height, pix, count, first, seed, eps,
        *stack_words(stack),
    )  # fmt: skip
    keep_alive(bvh, sc, stack)
    return out


# A function of its own, called once per pixel, so the `prange` kernel below stays small:
# Numba's parallel passes over a kernel with the camera chain inlined took 20 s to compile.
@nb.njit(cache=True, _nrt=False, error_model="numpy")
def _emitted_pixel(bvh, sc, cam, width, height, pix, count, first, seed, eps, stack, rows):
    """`emitted_pixel` on the `dpm.tracer.addresses` words of its BVH, scene and stack."""
    bvh, sc, stack = bvh_at(bvh), scene_at(sc), stack_at(stack, (rows, 2))
    y, x = pix // width, pix % width
    # the pixel's scramble (stream pix, dimensions its samples' streams never use)
    shift_x = np.int64(uniform(seed, pix, 0) * 4294967296.0)
    shift_y = np.int64(uniform(seed, pix, 1) * 4294967296.0)
    er = eg = eb = 0.0
    q = 0.0
    for s in range(count):
        k = first + s
        sx, sy = sobol2(k, shift_x, shift_y)
        stream = (np.int64(pix) << np.int64(32)) | k
        v = camera_sample(bvh, sc, cam, width, height, x, y, sx, sy, stream, seed, eps, stack)
        er, eg, eb = er + v[13], eg + v[14], eb + v[15]
        lum = LUMINANCE[0] * v[13] + LUMINANCE[1] * v[14] + LUMINANCE[2] * v[15]
        q += lum * lum
    return er, eg, eb, q


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _emitted_kernel(bvh, depth, sc, cam, width, height, pixels, counts, first, seed, eps, out, sq):
    """out[i], sq[i] = the sums of the emitted radiance and of its squared luminance over
    samples first[i] … first[i] + counts[i] - 1 of pixel pixels[i]'s sequence."""
    n = len(pixels)
    for task in nb.prange((n + PIXELS_PER_TASK - 1) // PIXELS_PER_TASK):
        stack = new_stack(depth)
        for t in range(task * PIXELS_PER_TASK, min(n, (task + 1) * PIXELS_PER_TASK)):
            # Threads take contiguous ranges of t: scattered over the list, each gets a share
            # of the pixels whose chains run long (in glass) and of those that end at once.
            i = (t * SCATTER) % n
            out[i, 0], out[i, 1], out[i, 2], sq[i] = emitted_pixel(
                bvh, sc, cam, width, height, pixels[i], counts[i], first[i], seed, eps, stack
            )


def trace_emitted(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    pixels: np.ndarray,
    counts: np.ndarray | int,
    seed: int,
    first: np.ndarray | int = 0,
) -> tuple[np.ndarray, np.ndarray]:
    """Over counts (L,) camera samples of each listed pixel (L,) (row-major indices), its
    samples first (L,) onward: the sum of the radiance of lights seen along their specular
    chains (L, 3) float64 (W m⁻² sr⁻¹) and of its squared luminance (L,) float64. A pixel's
    samples go through the points of its own scrambled Sobol sequence for `seed` (each
    uniform, together stratified), so calls with one seed and consecutive `first` extend one
    sequence: a light's speck covering a hundredth of a pixel is found in close to its share
    of the samples, not by luck."""
    out, sq = np.zeros((len(pixels), 3)), np.zeros(len(pixels))
    counts = np.broadcast_to(np.asarray(counts, np.int64), (len(pixels),)).copy()
    first = np.broadcast_to(np.asarray(first, np.int64), (len(pixels),)).copy()
    if len(pixels) and counts.max() > 0:
        _emitted_kernel(
            bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
            camera.height, np.asarray(pixels, np.int64), counts, first, seed,
            spawn_offset(scene), out, sq,
        )  # fmt: skip
    return out, sq


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _specular_kernel(bvh, depth, sc, cam, width, height, out):
    """out[p] = whether pixel p's centre sees a mirror or glass first."""
    n = width * height
    for task in nb.prange((n + PIXELS_PER_TASK - 1) // PIXELS_PER_TASK):
        stack = new_stack(depth)
        for p in range(task * PIXELS_PER_TASK, min(n, (task + 1) * PIXELS_PER_TASK)):
            dx, dy, dz = camera_ray(cam, width, height, p % width + 0.5, p // width + 0.5)
            hit = next_surface(bvh, sc, cam[0, 0], cam[0, 1], cam[0, 2], dx, dy, dz, stack)
            out[p] = hit[0] >= 0 and sc.kind[hit[8]] != DIFFUSE


def specular_pixels(scene: Scene, bvh: BVH, camera: Camera) -> np.ndarray:
    """(H·W,) bool: pixels whose centre, or a neighbour's, sees a mirror or glass first."""
    out = np.zeros(camera.width * camera.height, np.bool_)
    _specular_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
        camera.height, out,
    )  # fmt: skip
    grown = dilate3(out.reshape(camera.height, camera.width))
    return grown.ravel()
