"""Path tracing from visible points: next-event estimation with MIS, Russian roulette.

`shade_kernel` estimates the radiance each visible point reflects towards the camera. With
`caustics` False it leaves out, at the visible point only, light that a BSDF-sampled ray
reaches through one or more specular surfaces (the S+ L ends that caustic photons carry), so
that pt-nocaustic plus a caustic density estimate converges to pt (docs/design.md,
light-path split).
Given a `PhotonGrid` of caustic photons, it also leaves them out at the later diffuse vertices
and adds the grid's density estimate there instead (`auto`).
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dpm.camera import Camera
from dpm.scene import DIFFUSE, Scene
from dpm.tracer.addresses import (
    bvh_at,
    bvh_words,
    keep_alive,
    scene_at,
    scene_words,
    stack_at,
    stack_words,
)
from dpm.tracer.bsdf import scatter_specular, specular_survival
from dpm.tracer.bvh import BVH
from dpm.tracer.lights import (
    light_pdf_solid_angle,
    sample_light_point,
    sample_light_stratified,
)
from dpm.tracer.packet import LANES, closest_packet, new_packet, packet_at, packet_words, put_ray
from dpm.tracer.photon_grid import PhotonGrid, grid_irradiance
from dpm.tracer.sampling import pixel_sequence, sample_cosine, stratified2, uniform
from dpm.tracer.surface import albedo_at, next_surface, surface_at
from dpm.tracer.traverse import any_hit, new_stack, spawn_offset
from dpm.tracer.visible import (
    LUMINANCE,
    MAX_VERTICES,
    RR_SPECULAR,
    RR_START,
    RR_SURVIVAL,
    SCATTER,
    SHADE_DIM0,
    VisiblePoints,
    camera_ray,
    lean_from,
)
from dpm.tracer.wavefront import batch_starts, wavefront_kernel

DIMS_PER_VERTEX = 8  # Fresnel, light pick, light point (2), direction (2), roulette, spare
SAMPLES_PER_TASK = 64
# Whole-pixel tasks (`pixels_kernel`) take at least this many pixels: each task allocates its
# traversal stack and packet (24 arrays), which at one pixel a task (64 spp) cost `pt` 2-4 %.
MIN_PIXELS_PER_TASK = 8
# Vertices after the visible point whose light sample and direction come from the pixel's
# stratified sequence (`stratified2`) when one is given; later ones from `uniform`.
STRATIFIED_VERTICES = 1
PATHS_PER_TASK = 1024  # the most camera paths of one pixel in one task of `trace_listed`
LISTED_PER_TASK = 8  # listed tasks that share one packet's arrays (allocated once for them)


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


@nb.njit(cache=True, inline="always")
def shade_one(
    bvh, sc, seed, stream, pseq, index, eps, caustics, grid, stack, px, py, pz, nx, ny, nz,
    ar, ag, ab,
):  # fmt: skip
    """RGB radiance reflected by the diffuse point p (normal n towards the viewer, albedo a).
    Called (`_shade_one`) with the BVH, the scene and the stack passed by address."""
    out = _shade_one(
        bvh_words(bvh), scene_words(sc), seed, stream, pseq, index, eps, caustics, grid,
        *stack_words(stack), px, py, pz, nx, ny, nz, ar, ag, ab,
    )  # fmt: skip
    keep_alive(bvh, sc, stack)
    return out


# Compiled without Numba's reference counting (`_nrt=False`; it allocates nothing). With it,
# every inlined call that takes the scene's or the BVH's tuple of arrays (next_surface, any_hit,
# scatter_specular, ...) increments and decrements each array's reference count: some forty
# atomic updates per ray on counters that both threads share, which cost a third of the
# shading time on two cores. Functions inlined into it inherit the setting; the traversal
# functions it calls (`_closest_hit`, `_any_hit`) are compiled with it as well.
@nb.njit(cache=True, _nrt=False, error_model="numpy")
def _shade_one(
    bvh, sc, seed, stream, pseq, index, eps, caustics, grid, stack, rows, px, py, pz, nx, ny,
    nz, ar, ag, ab,
):  # fmt: skip
    """`shade_one` on the `dpm.tracer.addresses` words of its BVH, scene and stack."""
    return shade_path(
        bvh_at(bvh), scene_at(sc), seed, stream, pseq, index, eps, caustics, grid,
        stack_at(stack, (rows, 2)), px, py, pz, nx, ny, nz, ar, ag, ab,
    )  # fmt: skip


@nb.njit(cache=True, inline="always", error_model="numpy")
def shade_path(
    bvh, sc, seed, stream, pseq, index, eps, caustics, grid, stack, px, py, pz, nx, ny, nz,
    ar, ag, ab,
):  # fmt: skip
    """`shade_one`, inlined where its callers are compiled. With a PhotonGrid `grid` (None:
    none), the light that reaches the diffuse vertices after p through specular chains is
    its density estimate there instead of BSDF-sampled S+ L ends. With index ≥ 0, the first
    STRATIFIED_VERTICES vertices' light points and directions are point `index` of the
    pixel's stratified sequence `pseq` (`pixel_sequence`); other decisions come from stream."""
    inv_pi = 1.0 / math.pi
    lr = lg = lb = 0.0
    br, bg, bb = ar, ag, ab  # path weight including the BSDF·cos/pdf of the current vertex
    vertex = 0
    while vertex < MAX_VERTICES:
        dim = SHADE_DIM0 + DIMS_PER_VERTEX * vertex
        if br <= 0 and bg <= 0 and bb <= 0:
            break
        if grid is not None and vertex > 0:  # a diffuse vertex after p: its caustic light
            er, eg, eb = grid_irradiance(grid, px, py, pz, nx, ny, nz)
            lr += br * er * inv_pi
            lg += bg * eg * inv_pi
            lb += bb * eb * inv_pi
        # Next-event estimation: one point on the lights, weighted against BSDF sampling.
        if index >= 0 and vertex < STRATIFIED_VERTICES:
            u2, u3 = stratified2(index, pseq, 1 + 2 * vertex)
            u4, u5 = stratified2(index, pseq, 2 + 2 * vertex)
            lt, qx, qy, qz, area_pdf = sample_light_stratified(sc, u2, u3)
        else:
            u4, u5 = uniform(seed, stream, dim + 4), uniform(seed, stream, dim + 5)
            lt, qx, qy, qz, area_pdf = sample_light_point(
                sc, uniform(seed, stream, dim + 1), uniform(seed, stream, dim + 2),
                uniform(seed, stream, dim + 3),
            )  # fmt: skip
        wx, wy, wz = qx - px, qy - py, qz - pz
        dist = math.sqrt(wx * wx + wy * wy + wz * wz)
        if dist > 0 and area_pdf > 0:
            inv = 1.0 / dist  # (one division: each sits in the path's chain of latencies)
            wx, wy, wz = wx * inv, wy * inv, wz * inv
            cos_x = wx * nx + wy * ny + wz * nz
            lx, ly, lz = sc.normals[lt, 0], sc.normals[lt, 1], sc.normals[lt, 2]
            cos_l = -(wx * lx + wy * ly + wz * lz)
            if cos_x > 0 and cos_l > 0 and _unoccluded(
                bvh, px + eps * nx, py + eps * ny, pz + eps * nz,
                qx + eps * lx, qy + eps * ly, qz + eps * lz, stack,
            ):  # fmt: skip
                pdf_l = light_pdf_solid_angle(sc, lt, dist, cos_l)
                # BSDF·cos / pdf_l times the power heuristic's weight, in one division:
                # (cos/π) / p · p² / (p² + b²) with b = cos/π, the BSDF sampling's density
                b = cos_x * inv_pi
                g = b * pdf_l / (pdf_l * pdf_l + b * b)
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
        dx, dy, dz = sample_cosine(nx, ny, nz, u4, u5)
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
                elif caustics or (grid is None and vertex > specular + 1):
                    w = 1.0  # only BSDF sampling reaches lights through specular chains
                else:
                    w = 0.0  # an S+ L end: the caustic estimate's share (at p, or the grid's)
                e = sc.emission[m]
                lr += br * e[0] * w
                lg += bg * e[1] * w
                lb += bb * e[2] * w
            if sc.kind[m] == DIFFUSE:
                ar, ag, ab = albedo_at(sc, m, tri, px, py, pz)
                br, bg, bb = br * ar, bg * ag, bb * ab
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
def shade_kernel(
    bvh, depth, sc, position, normal, albedo, hit, pixel, sample, seed, sequence, first, spp,
    eps, caustics, grid, out,
):  # fmt: skip
    """Reflected radiance (N, 3) of visible points into out; returns the non-finite count.
    With sequence ≥ 0, sample pixel·spp + s of a pixel takes point first + s of its
    stratified sequence (`shade_path`)."""
    n = len(hit)
    n_tasks = (n + SAMPLES_PER_TASK - 1) // SAMPLES_PER_TASK
    bad = np.zeros(n_tasks, np.int64)
    for task in nb.prange(n_tasks):
        stack = new_stack(depth)
        for i in range(task * SAMPLES_PER_TASK, min(n, (task + 1) * SAMPLES_PER_TASK)):
            out[i] = 0.0
            if not hit[i]:
                continue
            pseq, index = np.uint64(0), np.int64(-1)
            if sequence >= 0:
                pseq = pixel_sequence(sequence, pixel[i])
                index = first + sample[i] - np.int64(pixel[i]) * spp
            r, g, b = shade_one(
                bvh, sc, seed, sample[i], pseq, index, eps, caustics, grid, stack,
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
    scene: Scene,
    bvh: BVH,
    points: VisiblePoints,
    seed: int,
    caustics: bool = True,
    grid: PhotonGrid | None = None,
    sequence: tuple[int, int] | None = None,
    spp: int = 1,
) -> tuple[np.ndarray, int]:
    """Radiance (N, 3) float32 each visible point reflects towards the camera (before the
    camera-path throughput), and how many non-finite samples were dropped (set to zero).

    caustics=False leaves out the S+ L ends at the visible point (pt-nocaustic); with it, a
    grid of the pass's caustic photons (L S+ D) also takes the place of the S+ L ends at the
    later diffuse vertices, by its density estimate there. With `sequence` (seed, first), the
    points of `trace_visible_points(..., spp, ..., sequence)` take their first vertices' light
    samples and directions from their pixels' stratified sequences (`stratified2`).
    """
    if grid is not None and caustics:
        raise ValueError("a photon grid replaces caustic paths: it needs caustics=False")
    out = np.zeros((len(points), 3), np.float32)
    qseed, first = (-1, 0) if sequence is None else sequence
    bad = shade_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), points.position, points.normal,
        points.albedo, points.hit, points.pixel, points.sample, seed, qseed, first, spp,
        spawn_offset(scene), caustics, grid, out,
    )  # fmt: skip
    return out, int(bad)


@nb.njit(cache=True, inline="always")
def path_pixel(
    bvh, sc, cam, width, height, pix, first, spp, stride, seed, sequence, qfirst, eps,
    caustics, emission, grid, stack, packet,
):  # fmt: skip
    """`_path_pixel`, called with the BVH, the scene, the stack and the packet passed by
    address (`dpm.tracer.addresses`: as Numba structs they were some 360 words a call)."""
    out = _path_pixel(
        bvh_words(bvh), scene_words(sc), cam, width, height, pix, first, spp, stride, seed,
        sequence, qfirst, eps, caustics, emission, grid, *stack_words(stack),
        packet_words(packet),
    )  # fmt: skip
    keep_alive(bvh, sc, stack, packet)
    return out


@nb.njit(cache=True, _nrt=False, error_model="numpy")
def _path_pixel(
    bvh, sc, cam, width, height, pix, first, spp, stride, seed, sequence, qfirst, eps,
    caustics, emission, grid, stack, rows, packet,
):  # fmt: skip
    """Sums over spp camera paths of pixel pix (row-major index), random streams pix·stride
    + first … first+spp-1: (radiance r, g, b, denoiser albedo r, g, b and normal x, y, z,
    visible points found, non-finite samples, sum of each path's squared luminance); with
    emission False, the light seen along the camera's specular chain is left out. With
    sequence ≥ 0, path s's position in the pixel and its first vertices' light samples and
    directions are point qfirst + s of the pixel's stratified sequence (`stratified2`).

    The camera rays of up to LANES paths at a time are traced as one packet (`packet`, from
    `new_packet`): a pixel's rays enter the same nodes. The paths then go on one by one."""
    bvh, sc, packet = bvh_at(bvh), scene_at(sc), packet_at(packet)
    stack = stack_at(stack, (rows, 2))
    y, x = pix // width, pix % width
    pseq = pixel_sequence(max(sequence, 0), pix)
    sr = sg = sb = gr = gg = gb = hx = hy = hz = sq = 0.0
    hits = bad = 0
    ox, oy, oz = cam[0, 0], cam[0, 1], cam[0, 2]
    pd = packet[0][3:6]  # the camera rays' directions, read back after the packet
    limit, hit_t, hit_tri, _ = packet[5]
    for s0 in range(0, spp, LANES):
        lanes = min(LANES, spp - s0)
        for j in range(lanes):
            s = s0 + j
            stream = pix * stride + first + s
            index = qfirst + s if sequence >= 0 else np.int64(-1)
            if index >= 0:
                sx, sy = stratified2(index, pseq, 0)
            else:
                sx, sy = uniform(seed, stream, 0), uniform(seed, stream, 1)
            dx, dy, dz = camera_ray(cam, width, height, x + sx, y + sy)
            put_ray(packet[0], limit, j, ox, oy, oz, dx, dy, dz, np.inf)
        closest_packet(bvh, packet, (1 << lanes) - 1, limit, stack, hit_t, hit_tri)
        for j in range(lanes):
            s = s0 + j
            stream = pix * stride + first + s
            index = qfirst + s if sequence >= 0 else np.int64(-1)
            dx, dy, dz = pd[0][j], pd[1][j], pd[2][j]
            hit = surface_at(sc, ox, oy, oz, dx, dy, dz, hit_t[j], hit_tri[j])
            v = lean_from(bvh, sc, dx, dy, dz, hit, stream, seed, eps, stack)
            er, eg, eb = v[13], v[14], v[15]
            if not emission:
                er = eg = eb = 0.0
            if v[0]:
                hits += 1
                r, g, b = shade_path(
                    bvh, sc, seed, stream, pseq, index, eps, caustics, grid, stack,
                    v[1], v[2], v[3], v[4], v[5], v[6], v[7], v[8], v[9],
                )  # fmt: skip
                if math.isfinite(r) and math.isfinite(g) and math.isfinite(b):
                    er, eg, eb = er + v[10] * r, eg + v[11] * g, eb + v[12] * b
                else:  # as `shade`: the sample's reflected light counts as zero
                    bad += 1
                gr += min(max(v[7] * v[10], 0.0), 1.0)
                gg += min(max(v[8] * v[11], 0.0), 1.0)
                gb += min(max(v[9] * v[12], 0.0), 1.0)
                hx, hy, hz = hx + v[4], hy + v[5], hz + v[6]
            else:
                peak = max(v[13], v[14], v[15])
                if peak > 0:  # a light seen directly: its normalised colour
                    gr, gg, gb = gr + v[13] / peak, gg + v[14] / peak, gb + v[15] / peak
            sr, sg, sb = sr + er, sg + eg, sb + eb
            lum = LUMINANCE[0] * er + LUMINANCE[1] * eg + LUMINANCE[2] * eb
            sq += lum * lum
    return sr, sg, sb, gr, gg, gb, hx, hy, hz, hits, bad, sq


@nb.njit(cache=True, parallel=True, error_model="numpy")
def pixels_kernel(
    bvh, depth, sc, cam, width, height, row0, row1, spp, seed, sequence, first, eps, caustics,
    image, albedo, normal, square,
):  # fmt: skip
    """Per pixel of image rows row0..row1-1 (row-major, (P, 3) outputs): the mean radiance of
    spp camera paths, the mean denoiser guides (`dpm.denoise.guides`) and (P,) the sum of the
    paths' squared luminances; returns (visible points found, non-finite samples dropped)."""
    n = (row1 - row0) * width
    per_task = max(MIN_PIXELS_PER_TASK, SAMPLES_PER_TASK // spp)
    n_tasks = (n + per_task - 1) // per_task
    hits = np.zeros(n_tasks, np.int64)
    bad = np.zeros(n_tasks, np.int64)
    for i in nb.prange(n_tasks):
        # Threads take contiguous ranges of i; scattering the tasks they map to over the rows
        # evens out their work where one part of the image costs more than another.
        task = (i * SCATTER) % n_tasks
        stack, packet = new_stack(depth), new_packet(depth)
        for p in range(task * per_task, min(n, (task + 1) * per_task)):
            v = path_pixel(
                bvh, sc, cam, width, height, row0 * width + p, 0, spp, spp, seed, sequence,
                first, eps, caustics, True, None, stack, packet,
            )  # fmt: skip
            image[p, 0], image[p, 1], image[p, 2] = v[0] / spp, v[1] / spp, v[2] / spp
            albedo[p, 0], albedo[p, 1], albedo[p, 2] = v[3] / spp, v[4] / spp, v[5] / spp
            normal[p, 0], normal[p, 1], normal[p, 2] = v[6] / spp, v[7] / spp, v[8] / spp
            square[p] = v[11]
            hits[task] += v[9]
            bad[task] += v[10]
    return hits.sum(), bad.sum()


def trace_pixels(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    spp: int,
    seed: int,
    rows: tuple[int, int],
    caustics: bool = True,
    sequence: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, int, int]:
    """Path tracing of whole pixels, image rows rows[0]..rows[1]-1: (rows, W, 3) float32 mean
    radiance, mean denoiser albedo and normal, visible points found and non-finite samples
    dropped. The same samples (random streams, and `sequence`) as `trace_visible_points` then
    `shade`, in one pass that keeps no per-sample arrays; it equals them within float
    rounding. With `sequence` (seed, first), sample s of a pixel is point first + s of the
    pixel's stratified sequence in its position and first vertices (`stratified2`)."""
    image, albedo, normal, _, hits, bad = _pixels(
        scene, bvh, camera, spp, seed, rows, caustics, sequence
    )
    shape = (rows[1] - rows[0], camera.width, 3)
    out = tuple(a.astype(np.float32).reshape(shape) for a in (image, albedo, normal))
    return (*out, hits, bad)


def trace_pixel_sums(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    spp: int,
    seed: int,
    sequence: tuple[int, int] | None = None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int]:
    """`trace_pixels` of the whole image without the caustics at the visible point, as
    `auto`'s passes take it: (P, 3) float64 radiance summed over each pixel's spp paths, (P,)
    float64 sum of their squared luminances, (P, 3) mean denoiser albedo and normal, and the
    non-finite samples dropped."""
    image, albedo, normal, square, _, bad = _pixels(
        scene, bvh, camera, spp, seed, (0, camera.height), False, sequence
    )
    return image * spp, square, albedo, normal, bad


def _pixels(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    spp: int,
    seed: int,
    rows: tuple[int, int],
    caustics: bool,
    sequence: tuple[int, int] | None,
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, int, int]:
    """`pixels_kernel` on rows[0]..rows[1]-1: (P, 3) float64 mean radiance, albedo, normal,
    (P,) sum of squared luminances, visible points found, non-finite samples dropped."""
    row0, row1 = rows
    pixels = (row1 - row0) * camera.width
    qseed, first = (-1, 0) if sequence is None else sequence
    if scene.all_diffuse:  # the same sums, traced in stages (`dpm.tracer.wavefront`)
        tasks = np.arange(row0 * camera.width, row1 * camera.width, dtype=np.int64)
        sums = _wavefront(
            scene, bvh, camera, tasks, np.zeros(pixels, np.int64), np.full(pixels, spp),
            np.full(pixels, first, np.int64), spp, seed, qseed, True,
        )  # fmt: skip
        image, albedo, normal = (sums[:, c : c + 3] / spp for c in (0, 3, 6))
        return image, albedo, normal, sums[:, 11], int(sums[:, 9].sum()), int(sums[:, 10].sum())
    image, albedo, normal = (np.empty((pixels, 3)) for _ in range(3))
    square = np.empty(pixels)
    hits, bad = pixels_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
        camera.height, row0, row1, spp, seed, qseed, first, spawn_offset(scene), caustics,
        image, albedo, normal, square,
    )  # fmt: skip
    return image, albedo, normal, square, int(hits), int(bad)


@nb.njit(cache=True, parallel=True, error_model="numpy")
def listed_kernel(
    bvh, depth, sc, cam, width, height, pixels, first, counts, stride, seed, sequence, qfirst,
    eps, emission, grid, out, sq,
):  # fmt: skip
    """Per listed task: the radiance sums (L, 3) of counts[i] camera paths of pixels[i]
    (streams pixel·stride + first[i] + 0 … counts[i]-1; with sequence ≥ 0, points qfirst[i]
    + 0 … of the pixel's stratified sequence) into out, their squared luminances' sum into
    sq; returns the non-finite samples dropped."""
    bad = np.zeros(len(pixels), np.int64)
    chunks = (len(pixels) + LISTED_PER_TASK - 1) // LISTED_PER_TASK
    for c in nb.prange(chunks):
        stack, packet = new_stack(depth), new_packet(depth)
        for i in range(c * LISTED_PER_TASK, min(len(pixels), (c + 1) * LISTED_PER_TASK)):
            v = path_pixel(
                bvh, sc, cam, width, height, pixels[i], first[i], counts[i], stride, seed,
                sequence, qfirst[i], eps, False, emission, grid, stack, packet,
            )  # fmt: skip
            out[i, 0], out[i, 1], out[i, 2], sq[i], bad[i] = v[0], v[1], v[2], v[11], v[10]
    return bad.sum()


def trace_listed(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    pixels: np.ndarray,
    counts: np.ndarray,
    seed: int,
    grid: PhotonGrid | None = None,
    emission: bool = True,
    sequence: tuple[int, np.ndarray] | None = None,
) -> tuple[np.ndarray, np.ndarray, int]:
    """More camera paths at some pixels, as pt-nocaustic (or `auto`'s paths with a photon
    grid) would trace them: pixels (L,) row-major indices, counts (L,) paths each. Returns the
    radiance sums (L, 3) float64, the sums of each path's squared luminance (L,) float64 and
    the non-finite samples dropped (emission False: without the light seen along the camera's
    specular chains). Streams are pixel·max(counts) + 0 … counts-1, so a seed not used for the
    pixels' other paths gives independent samples. With `sequence` (seed, first (L,)), pixel
    i's paths are points first[i] … of its stratified sequence in their position and first
    vertices (`stratified2`): calls with one seed and first = the paths so far extend it."""
    pixels = np.asarray(pixels, np.int64)
    counts = np.asarray(counts, np.int64)
    out = np.zeros((len(pixels), 3))
    sq = np.zeros(len(pixels))
    if len(pixels) == 0:
        return out, sq, 0
    # Tasks of at most PATHS_PER_TASK paths, so that one pixel given many cannot hold a thread
    # while the others idle.
    pieces = -(-counts // PATHS_PER_TASK)
    owner = np.repeat(np.arange(len(pixels)), pieces)
    first = np.arange(len(owner)) - np.repeat(np.cumsum(pieces) - pieces, pieces)
    first = first * PATHS_PER_TASK
    task_counts = np.minimum(counts[owner] - first, PATHS_PER_TASK)
    task_out, task_sq = np.zeros((len(owner), 3)), np.zeros(len(owner))
    qseed, done = (-1, np.zeros(len(pixels), np.int64)) if sequence is None else sequence
    qfirst = np.asarray(done, np.int64)[owner] + first
    if scene.all_diffuse and grid is None:  # in stages (`dpm.tracer.wavefront`)
        sums = _wavefront(
            scene, bvh, camera, pixels[owner], first, task_counts, qfirst, int(counts.max()),
            seed, qseed, emission,
        )  # fmt: skip
        np.add.at(out, owner, sums[:, :3])
        np.add.at(sq, owner, sums[:, 11])
        return out, sq, int(sums[:, 10].sum())
    bad = listed_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
        camera.height, pixels[owner], first, task_counts, int(counts.max()), seed, qseed,
        qfirst, spawn_offset(scene), emission, grid, task_out, task_sq,
    )  # fmt: skip
    np.add.at(out, owner, task_out)
    np.add.at(sq, owner, task_sq)
    return out, sq, int(bad)


def _wavefront(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    pixels: np.ndarray,
    firsts: np.ndarray,
    counts: np.ndarray,
    qfirsts: np.ndarray,
    stride: int,
    seed: int,
    sequence: int,
    emission: bool,
) -> np.ndarray:
    """(L, 12) float64 `path_pixel`'s sums for each task (pixels (L,), streams pixel·stride
    + firsts + 0 … counts-1, sequence points qfirsts + 0 …) of a scene without mirrors or
    glass, by `dpm.tracer.wavefront`: radiance (3), albedo (3) and normal (3) sums, visible
    points, non-finite samples, sum of squared luminances."""
    pixels, firsts, counts, qfirsts = (
        np.ascontiguousarray(a, np.int64) for a in (pixels, firsts, counts, qfirsts)
    )
    out = np.empty((len(pixels), 12))
    wavefront_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
        camera.height, pixels, firsts, counts, qfirsts, stride, seed, sequence,
        spawn_offset(scene), emission, batch_starts(counts, nb.get_num_threads()), out,
    )  # fmt: skip
    return out
