"""Path tracing of scenes without mirrors or glass in stages over batches of paths.

`path_pixel` follows one path at a time from the camera to its end: each vertex's shading is
a chain of dependent square roots, divisions and branches that one path leaves exposed, and
LLVM cannot vectorize it across paths. Here a batch of paths (the samples of several pixels)
moves one vertex at a time: each stage is a loop over the batch's live paths (light samples,
their shares, Russian roulette, the next direction, the next hit's light and weight) that
LLVM turns into SIMD code, and the traversals run between them. Every path makes the same
decisions from the same random numbers, in the same arithmetic, as in `path_pixel`: the
sums are equal to the bit (tests/test_wavefront.py).

Two rules of Numba 0.68's LLVM shape the stages (measured on Zen 5, docs/benchmarks.md): a
loop is left scalar if it loads from an array at an index read from another array (a hit's
triangle, a light's), and if it touches more than about a dozen arrays. So the loads by
index have scalar loops of their own (`_light_pick`, `_hit_gather`), and the arithmetic is
split into loops of few arrays each, with scratch arrays between them.

Only for scenes whose materials are all diffuse (no specular chains, no caustics to leave
out, no photon grid); `dpm.tracer.path` sends other scenes to `path_pixel`.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dpm.tracer.packet import LANES, any_packet, closest_packet, new_packet, put_ray
from dpm.tracer.sampling import (
    pixel_sequence,
    sample_cdf,
    sample_cosine,
    stratified2,
    uniform,
)
from dpm.tracer.surface import albedo_at
from dpm.tracer.traverse import new_stack
from dpm.tracer.visible import (
    LUMINANCE,
    MAX_VERTICES,
    RR_START,
    RR_SURVIVAL,
    SHADE_DIM0,
    camera_ray,
)

# The most paths of one batch: some 70 float64 each, 0.6 MB, which stays in a Zen 5 core's
# 1 MB L2 (the diffuse room, 128², 64 spp: 4.1-4.3 M samples/s at 1024-2048 paths, 3.0 at
# 4096, 4.0-4.1 at 512).
BATCH = 1024
MIN_BATCHES = 8  # per thread at least, where the paths allow it (the threads' last batches)

_STAGE = {"cache": True, "_nrt": False, "error_model": "numpy"}


def batch_starts(counts: np.ndarray, threads: int) -> np.ndarray:
    """(B + 1,) int64: the task where each batch starts. Consecutive tasks (counts (T,)
    paths each) go together up to a batch's size: BATCH paths, or fewer where that leaves
    each of `threads` threads fewer than MIN_BATCHES; a task of more paths goes alone."""
    size = min(BATCH, max(1, -(-int(counts.sum()) // (MIN_BATCHES * max(threads, 1)))))
    return _greedy_starts(np.ascontiguousarray(counts, np.int64), size)


@nb.njit(cache=True)
def _greedy_starts(counts, size):
    """`batch_starts` for a batch size: compiled, as a pass calls it on every pixel (a
    Python loop took 2.8 ms a pass at 256²)."""
    starts = np.empty(len(counts) + 1, np.int64)
    starts[0], b, total = 0, 1, 0
    for i in range(len(counts)):
        if total and total + counts[i] > size:
            starts[b] = i
            b += 1
            total = 0
        total += counts[i]
    starts[b] = len(counts)
    return starts[: b + 1].copy()


@nb.njit(cache=True, parallel=True, error_model="numpy")
def wavefront_kernel(
    bvh, depth, sc, cam, width, height, pixels, firsts, counts, qfirsts, stride, seed,
    sequence, eps, emission, starts, out,
):  # fmt: skip
    """`batch_paths` of the batches of tasks starts[b] … starts[b+1]-1, in parallel: for
    each task i, the 12 sums of `path_pixel` (pixel pixels[i], streams pixels[i]·stride +
    firsts[i] + 0 … counts[i]-1, sequence points qfirsts[i] + 0 …) into out (tasks, 12)."""
    for b in nb.prange(len(starts) - 1):
        lo, hi = starts[b], starts[b + 1]
        batch_paths(
            bvh, new_stack(depth), new_packet(depth), sc, cam, width, height, pixels[lo:hi],
            firsts[lo:hi],
            counts[lo:hi], qfirsts[lo:hi], stride, seed, sequence, eps, emission, out[lo:hi],
        )  # fmt: skip


@nb.njit(cache=True, error_model="numpy")
def batch_paths(
    bvh, stack, packet, sc, cam, width, height, pixels, firsts, counts, qfirsts, stride, seed,
    sequence, eps, emission, out,
):  # fmt: skip
    """One batch of `wavefront_kernel`: allocates its state, runs it (`_run`)."""
    n = 0
    for c in counts:
        n += c
    ids = (np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64),
           np.zeros(n, np.int64))  # fmt: skip
    pseq = np.empty(n, np.uint64)
    go, test = np.empty(n, np.bool_), np.empty(n, np.bool_)
    hit_t, hit_tri = np.empty(n), np.empty(n, np.int64)
    # the float64 state and scratch (`_run`), each its own allocation: LLVM vectorizes no
    # loop over rows of one 2-D array
    rows = (  # 56: see `_run`
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
    )  # fmt: skip
    per_path = np.zeros((n, 13))  # each path's terms (`_path_terms`)
    _run(
        bvh, stack, packet, sc, cam, width, height, pixels, firsts, counts, qfirsts, stride,
        seed, sequence, eps, emission, ids, pseq, go, test, hit_t, hit_tri, rows, per_path,
    )  # fmt: skip
    _sums(counts, per_path, out)


@nb.njit(**_STAGE)
def _sums(counts, per_path, out):
    """Each task's sums of its paths' rows of per_path, in `path_pixel`'s order."""
    j = 0
    for i in range(len(counts)):
        for c in range(12):
            out[i, c] = 0.0
        for _ in range(counts[i]):
            for c in range(12):
                out[i, c] += per_path[j, c]
            j += 1


@nb.njit(**_STAGE)
def _run(
    bvh, stack, packet, sc, cam, width, height, pixels, firsts, counts, qfirsts, stride, seed,
    sequence, eps, emission, ids, pseq, go, test, hit_t, hit_tri, rows, per_path,
):  # fmt: skip
    """The batch's paths from the camera to their ends; per_path (N, 13) gets each path's
    radiance, guides, hit, non-finite flag and squared luminance (`path_pixel`'s terms)."""
    pid, stream, index, vertex = ids
    ox, oy, oz, dx, dy, dz = rows[0:6]  # the ray
    px, py, pz, nx, ny, nz = rows[6:12]  # the vertex
    br, bg, bb, sr, sg, sb = rows[12:18]  # the path's weight, its light so far
    pdf_b, length, gr, gg, gb = rows[18:23]  # BSDF sample density, shadow ray, light share
    u0, la, lb, u4, u5 = rows[23:28]  # a vertex's numbers
    # rows 28-36: a light's corners; then its (or a hit's) normal, density, emission
    lnx, lny, lnz, lpdf, ler, leg, leb = rows[37:44]
    t0, t1, t2 = rows[44:47]  # scratch: a light share's barycentrics, a hit's albedo
    share = rows[44:56]  # `_light_share`'s scratch
    n = 0
    for i in range(len(pixels)):
        q = pixel_sequence(max(sequence, 0), pixels[i])
        for s in range(counts[i]):
            pid[n], stream[n], pseq[n] = n, pixels[i] * stride + firsts[i] + s, q
            index[n] = qfirsts[i] + s if sequence >= 0 else -1
            pix = pixels[i]
            y, x = pix // width, pix % width
            if sequence >= 0:
                sx, sy = stratified2(index[n], q, 0)
            else:
                sx, sy = uniform(seed, stream[n], 0), uniform(seed, stream[n], 1)
            dx[n], dy[n], dz[n] = camera_ray(cam, width, height, x + sx, y + sy)
            ox[n], oy[n], oz[n] = cam[0, 0], cam[0, 1], cam[0, 2]
            go[n] = True
            n += 1
    _trace_closest(bvh, stack, packet, n, go, ox, oy, oz, dx, dy, dz, hit_t, hit_tri)
    alive = 0
    for j in range(n):  # the visible points (`camera_sample`); the paths that go on
        tri = hit_tri[j]
        if tri < 0:
            continue
        t = hit_t[j]
        ux, uy, uz = sc.normals[tri, 0], sc.normals[tri, 1], sc.normals[tri, 2]
        cos_d = dx[j] * ux + dy[j] * uy + dz[j] * uz
        front = cos_d < 0
        if not front:
            ux, uy, uz = -ux, -uy, -uz
        x, y, z = ox[j] + t * dx[j], oy[j] + t * dy[j], oz[j] + t * dz[j]
        m = sc.material[tri]
        row = per_path[j]
        if front and emission:
            row[0], row[1], row[2] = sc.emission[m, 0], sc.emission[m, 1], sc.emission[m, 2]
        ar, ag, ab = albedo_at(sc, m, tri, x, y, z)
        row[3] = min(max(ar * 1.0, 0.0), 1.0)
        row[4] = min(max(ag * 1.0, 0.0), 1.0)
        row[5] = min(max(ab * 1.0, 0.0), 1.0)
        row[6], row[7], row[8], row[9] = ux, uy, uz, 1.0
        if ar <= 0 and ag <= 0 and ab <= 0:
            continue
        k = alive  # (k ≤ j: moving down never overwrites a path not yet read)
        pid[k], stream[k], index[k], pseq[k], vertex[k] = j, stream[j], index[j], pseq[j], 0
        px[k], py[k], pz[k], nx[k], ny[k], nz[k] = x, y, z, ux, uy, uz
        br[k], bg[k], bb[k], sr[k], sg[k], sb[k] = ar, ag, ab, 0.0, 0.0, 0.0
        alive += 1
    while alive > 0:
        live = alive
        _light_numbers(live, seed, stream, vertex, u0, la, lb, u4, u5)
        _light_pick(sc, live, index, pseq, vertex, u0, la, lb, u4, u5, rows[28:44])
        _light_share(
            live, eps, la, lb, rows[28:37], lpdf, lnx, lny, lnz, ler, leg, leb, px, py, pz, nx,
            ny, nz, br, bg, bb, test, ox, oy, oz, dx, dy, dz, length, gr, gg, gb, share,
        )  # fmt: skip
        _trace_shadow(bvh, stack, packet, live, test, ox, oy, oz, dx, dy, dz, length)
        _bounce(
            live, seed, eps, test, gr, gg, gb, sr, sg, sb, vertex, stream, br, bg, bb, nx, ny,
            nz, px, py, pz, u4, u5, go, pdf_b, ox, oy, oz, dx, dy, dz,
        )  # fmt: skip
        _trace_closest(bvh, stack, packet, live, go, ox, oy, oz, dx, dy, dz, hit_t, hit_tri)
        _hit_gather(sc, live, hit_t, hit_tri, ox, oy, oz, dx, dy, dz, rows[37:44], t0, t1, t2)
        _hit_shade(
            live, hit_t, hit_tri, ox, oy, oz, dx, dy, dz, lnx, lny, lnz, lpdf, ler, leg, leb,
            t0, t1, t2, pdf_b, sr, sg, sb, br, bg, bb, px, py, pz, nx, ny, nz, u4, u5, go,
        )  # fmt: skip
        alive = 0
        for k in range(live):  # paths that ended hand their light over; the rest move down
            on = hit_tri[k] >= 0 and vertex[k] < MAX_VERTICES
            if not (on and (br[k] > 0 or bg[k] > 0 or bb[k] > 0)):
                row = per_path[pid[k]]
                row[10], row[11], row[12] = sr[k], sg[k], sb[k]
                continue
            c = alive
            alive += 1
            if c < k:
                pid[c], stream[c], index[c], pseq[c], vertex[c] = (
                    pid[k], stream[k], index[k], pseq[k], vertex[k]
                )  # fmt: skip
                px[c], py[c], pz[c], nx[c], ny[c], nz[c] = px[k], py[k], pz[k], nx[k], ny[k], nz[k]
                br[c], bg[c], bb[c], sr[c], sg[c], sb[c] = br[k], bg[k], bb[k], sr[k], sg[k], sb[k]
    _path_terms(n, per_path)


@nb.njit(**_STAGE)
def _path_terms(n, per_path):
    """Each path's row of per_path as `path_pixel` adds it up: columns 0-2 radiance (the
    light seen plus, if finite, the reflected light that columns 10-12 hold: see `_run`),
    3-5 albedo, 6-8 normal, 9 whether it saw a surface, 10 whether its light was not finite,
    11 its luminance squared (12: scratch)."""
    for j in range(n):
        row = per_path[j]
        r, g, b = row[0], row[1], row[2]
        if row[9] > 0:
            lr, lg, lb = row[10], row[11], row[12]
            if math.isfinite(lr) and math.isfinite(lg) and math.isfinite(lb):
                r, g, b = r + 1.0 * lr, g + 1.0 * lg, b + 1.0 * lb
                row[10] = 0.0
            else:
                row[10] = 1.0
        else:
            row[10] = 0.0
        row[0], row[1], row[2] = r, g, b
        lum = LUMINANCE[0] * r + LUMINANCE[1] * g + LUMINANCE[2] * b
        row[11] = lum * lum


@nb.njit(**_STAGE)
def _trace_closest(bvh, stack, packet, n, go, ox, oy, oz, dx, dy, dz, hit_t, hit_tri):
    """Closest hits of the rays whose `go` is set (hit_tri -1 for the others), in packets of
    LANES consecutive such rays: a pixel's paths lie together, and their rays enter the same
    nodes (`dpm.tracer.packet`; the same hits as one ray at a time)."""
    limit, t, tri, at = packet[5]
    j = 0
    for k in range(n):
        hit_tri[k] = -1
        if go[k]:
            put_ray(packet[0], limit, j, ox[k], oy[k], oz[k], dx[k], dy[k], dz[k], np.inf)
            at[j] = k
            j += 1
        if j == LANES or (k == n - 1 and j > 0):
            closest_packet(bvh, packet, (1 << j) - 1, limit, stack, t, tri)
            for i in range(j):
                hit_t[at[i]], hit_tri[at[i]] = t[i], tri[i]
            j = 0


@nb.njit(**_STAGE)
def _trace_shadow(bvh, stack, packet, n, test, ox, oy, oz, dx, dy, dz, length):
    """`test` cleared where the segment of the ray up to `length` is occluded (in packets,
    as `_trace_closest`)."""
    limit, _, _, at = packet[5]
    j = 0
    for k in range(n):
        if test[k] and length[k] > 0:
            put_ray(packet[0], limit, j, ox[k], oy[k], oz[k], dx[k], dy[k], dz[k], length[k])
            at[j] = k
            j += 1
        if j == LANES or (k == n - 1 and j > 0):
            blocked = any_packet(bvh, packet, (1 << j) - 1, limit, stack)
            for i in range(j):
                if (blocked >> i) & 1:
                    test[at[i]] = False
            j = 0


@nb.njit(**_STAGE)
def _light_numbers(n, seed, stream, vertex, u0, la, lb, u4, u5):
    """The uniform numbers of a vertex's light sample and direction (`shade_path`)."""
    for k in range(n):
        dim = SHADE_DIM0 + 8 * vertex[k]
        u0[k] = uniform(seed, stream[k], dim + 1)
        la[k] = uniform(seed, stream[k], dim + 2)
        lb[k] = uniform(seed, stream[k], dim + 3)
        u4[k] = uniform(seed, stream[k], dim + 4)
        u5[k] = uniform(seed, stream[k], dim + 5)


@nb.njit(**_STAGE)
def _light_pick(sc, n, index, pseq, vertex, u0, la, lb, u4, u5, light):
    """Each light sample's triangle (by power) and what it holds into light: corners (9),
    normal (3), density per area, emission (3); the first vertex's numbers come from the
    pixel's stratified sequence where it has one (`sample_light_stratified`)."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8, lnx, lny, lnz, lpdf, ler, leg, leb = light
    for k in range(n):
        if index[k] >= 0 and vertex[k] < 1:
            v = vertex[k]
            u, w_ = stratified2(index[k], pseq[k], 1 + 2 * v)
            u4[k], u5[k] = stratified2(index[k], pseq[k], 2 + 2 * v)
            i = sample_cdf(sc.emitter_cdf, u)
            low = sc.emitter_cdf[i - 1] if i > 0 else 0.0
            share = sc.emitter_cdf[i] - low
            w = min(max((u - low) / share, 0.0), 1.0 - 2.0**-53) if share > 0 else 0.5
            la[k], lb[k] = w, w_
        else:  # `sample_light_point`
            i = sample_cdf(sc.emitter_cdf, u0[k])
        lt = sc.emitter_triangles[i]
        t = sc.triangles[lt]
        c0[k], c1[k], c2[k] = t[0, 0], t[0, 1], t[0, 2]
        c3[k], c4[k], c5[k] = t[1, 0], t[1, 1], t[1, 2]
        c6[k], c7[k], c8[k] = t[2, 0], t[2, 1], t[2, 2]
        lnx[k], lny[k], lnz[k] = sc.normals[lt, 0], sc.normals[lt, 1], sc.normals[lt, 2]
        lpdf[k] = sc.emitter_pdf[lt]
        e = sc.material[lt]
        ler[k], leg[k], leb[k] = sc.emission[e, 0], sc.emission[e, 1], sc.emission[e, 2]


@nb.njit(**_STAGE)
def _light_share(
    n, eps, la, lb, corners, lpdf, lnx, lny, lnz, ler, leg, leb, px, py, pz, nx, ny, nz, br,
    bg, bb, test, ox, oy, oz, dx, dy, dz, length, gr, gg, gb, scratch,
):  # fmt: skip
    """The light sample's point on its triangle (corners), its MIS-weighted share (gr, gg,
    gb), whether it counts (test) and the shadow ray to it: `shade_path`'s and
    `_unoccluded`'s arithmetic, in loops of few arrays each."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8 = corners
    t0, t1, t2, qx, qy, qz, wx, wy, wz, dist, cos_x, cos_l = scratch
    for k in range(n):  # `sample_triangle`'s barycentric weights
        s = math.sqrt(la[k])
        t0[k], t1[k] = 1.0 - s, lb[k] * s
        t2[k] = 1.0 - t0[k] - t1[k]
    for k in range(n):
        qx[k] = t0[k] * c0[k] + t1[k] * c3[k] + t2[k] * c6[k]
    for k in range(n):
        qy[k] = t0[k] * c1[k] + t1[k] * c4[k] + t2[k] * c7[k]
    for k in range(n):
        qz[k] = t0[k] * c2[k] + t1[k] * c5[k] + t2[k] * c8[k]
    for k in range(n):
        x, y, z = qx[k] - px[k], qy[k] - py[k], qz[k] - pz[k]
        d = math.sqrt(x * x + y * y + z * z)
        inv = 1.0 / d
        wx[k], wy[k], wz[k], dist[k] = x * inv, y * inv, z * inv, d
    for k in range(n):
        cos_x[k] = wx[k] * nx[k] + wy[k] * ny[k] + wz[k] * nz[k]
    for k in range(n):
        cos_l[k] = -(wx[k] * lnx[k] + wy[k] * lny[k] + wz[k] * lnz[k])
    for k in range(n):
        test[k] = (dist[k] > 0) & (lpdf[k] > 0) & (cos_x[k] > 0) & (cos_l[k] > 0)
    for k in range(n):  # the segment's ends lifted off their surfaces
        ox[k], oy[k], oz[k] = px[k] + eps * nx[k], py[k] + eps * ny[k], pz[k] + eps * nz[k]
    for k in range(n):
        dx[k] = (qx[k] + eps * lnx[k]) - ox[k]
    for k in range(n):
        dy[k] = (qy[k] + eps * lny[k]) - oy[k]
    for k in range(n):
        dz[k] = (qz[k] + eps * lnz[k]) - oz[k]
    for k in range(n):
        x, y, z = dx[k], dy[k], dz[k]
        d = math.sqrt(x * x + y * y + z * z)
        inv = 1.0 / d
        dx[k], dy[k], dz[k], length[k] = x * inv, y * inv, z * inv, d
    inv_pi = 1.0 / math.pi
    for k in range(n):  # `light_pdf_solid_angle` (cos_l > 0 where it counts), MIS weight
        pdf_l = lpdf[k] * dist[k] * dist[k] / cos_l[k]
        b = cos_x[k] * inv_pi
        t0[k] = b * pdf_l / (pdf_l * pdf_l + b * b)
    for k in range(n):
        gr[k] = br[k] * ler[k] * t0[k]
    for k in range(n):
        gg[k] = bg[k] * leg[k] * t0[k]
    for k in range(n):
        gb[k] = bb[k] * leb[k] * t0[k]


@nb.njit(**_STAGE)
def _bounce(
    n, seed, eps, test, gr, gg, gb, sr, sg, sb, vertex, stream, br, bg, bb, nx, ny, nz, px,
    py, pz, u4, u5, go, pdf_b, ox, oy, oz, dx, dy, dz,
):  # fmt: skip
    """The light sample's share where unoccluded; Russian roulette (go); the next ray."""
    for k in range(n):
        if test[k]:
            sr[k] += gr[k]
            sg[k] += gg[k]
            sb[k] += gb[k]
    for k in range(n):
        v = vertex[k]
        q = min(max(br[k], bg[k], bb[k]), RR_SURVIVAL)
        roll = v >= RR_START
        go[k] = not roll or uniform(seed, stream[k], SHADE_DIM0 + 8 * v + 6) < q
        if roll:
            br[k], bg[k], bb[k] = br[k] / q, bg[k] / q, bb[k] / q
        vertex[k] = v + 1
    inv_pi = 1.0 / math.pi
    for k in range(n):
        mx, my, mz = nx[k], ny[k], nz[k]
        ex, ey, ez = sample_cosine(mx, my, mz, u4[k], u5[k])
        pdf_b[k] = max(ex * mx + ey * my + ez * mz, 0.0) * inv_pi
        dx[k], dy[k], dz[k] = ex, ey, ez
    for k in range(n):
        ox[k], oy[k], oz[k] = px[k] + eps * nx[k], py[k] + eps * ny[k], pz[k] + eps * nz[k]


@nb.njit(**_STAGE)
def _hit_gather(sc, n, hit_t, hit_tri, ox, oy, oz, dx, dy, dz, surface, ar, ag, ab):
    """What each hit triangle holds into surface (normal (3), emitter density, emission
    (3)) and its albedo at the hit point into ar, ag, ab."""
    lnx, lny, lnz, lpdf, ler, leg, leb = surface
    for k in range(n):
        tri = hit_tri[k]
        if tri < 0:
            continue
        t = hit_t[k]
        m = sc.material[tri]
        lnx[k], lny[k], lnz[k] = sc.normals[tri, 0], sc.normals[tri, 1], sc.normals[tri, 2]
        lpdf[k] = sc.emitter_pdf[tri]
        ler[k], leg[k], leb[k] = sc.emission[m, 0], sc.emission[m, 1], sc.emission[m, 2]
        x, y, z = ox[k] + t * dx[k], oy[k] + t * dy[k], oz[k] + t * dz[k]
        ar[k], ag[k], ab[k] = albedo_at(sc, m, tri, x, y, z)


@nb.njit(**_STAGE)
def _hit_shade(
    n, hit_t, hit_tri, ox, oy, oz, dx, dy, dz, lnx, lny, lnz, lpdf, ler, leg, leb, ar, ag, ab,
    pdf_b, sr, sg, sb, br, bg, bb, px, py, pz, nx, ny, nz, cos_d, w, emit,
):  # fmt: skip
    """Light found by BSDF sampling (MIS-weighted); the path's weight times the albedo; the
    hit as the next vertex (`next_surface`'s point and normal facing the ray). cos_d, w and
    emit are scratch."""
    for k in range(n):
        cos_d[k] = dx[k] * lnx[k] + dy[k] * lny[k] + dz[k] * lnz[k]  # < 0: the front face
    for k in range(n):  # `light_pdf_solid_angle` at cos_i = |cos_d|, and `_power2`
        c = cos_d[k]
        emit[k] = (hit_tri[k] >= 0) & (c < 0) & (lpdf[k] > 0)
        t = hit_t[k]
        light_pdf = lpdf[k] * t * t / -c if -c > 0 else 0.0
        p = pdf_b[k]
        w[k] = p * p / (p * p + light_pdf * light_pdf)
    for k in range(n):
        if emit[k]:
            sr[k] += br[k] * ler[k] * w[k]
    for k in range(n):
        if emit[k]:
            sg[k] += bg[k] * leg[k] * w[k]
    for k in range(n):
        if emit[k]:
            sb[k] += bb[k] * leb[k] * w[k]
    for k in range(n):
        if hit_tri[k] >= 0:
            br[k], bg[k], bb[k] = br[k] * ar[k], bg[k] * ag[k], bb[k] * ab[k]
    for k in range(n):
        if hit_tri[k] >= 0:
            t = hit_t[k]
            px[k], py[k], pz[k] = ox[k] + t * dx[k], oy[k] + t * dy[k], oz[k] + t * dz[k]
    for k in range(n):
        if hit_tri[k] >= 0:
            f = cos_d[k] < 0
            nx[k] = lnx[k] if f else -lnx[k]
            ny[k] = lny[k] if f else -lny[k]
            nz[k] = lnz[k] if f else -lnz[k]
