"""Path tracing in stages over batches of paths.

`path_pixel` follows one path at a time from the camera to its end: each vertex's shading is
a chain of dependent square roots, divisions and branches that one path leaves exposed, and
LLVM cannot vectorize it across paths. Here a batch of paths (the samples of several pixels)
moves one vertex at a time: each stage is a loop over the batch's live paths (light samples,
their shares, Russian roulette, the next direction, the next hit's light and weight) that
LLVM turns into SIMD code, and the traversals run between them. Every path makes the same
decisions from the same random numbers, in the same arithmetic, as in `path_pixel` (and
`shade_path` from given visible points): the sums are equal to the bit
(tests/test_wavefront.py).

A path is at a diffuse vertex (it samples a light and a cosine direction) or at a specular
one (mirror, glass: it scatters as `scatter_specular` says); both kinds move together, each
stage masked to its kind. Camera rays that meet mirrors or glass first follow their chain to
the visible point one path at a time (`camera_chain`, with its emission splitting), as the
batch is set up.

Two rules of Numba 0.68's LLVM shape the stages (measured on Zen 5, docs/benchmarks.md): a
loop is left scalar if it loads from an array at an index read from another array (a hit's
triangle, a light's), and if it touches more than about a dozen arrays. So the loads by
index have scalar loops of their own (`_light_pick`, `_hit_gather`, `_scatter`), and the
arithmetic is split into loops of few arrays each, with scratch arrays between them.
"""

from __future__ import annotations

import math

import numba as nb
import numpy as np

from dpm.scene import DIFFUSE
from dpm.tracer.bsdf import scatter_specular, specular_survival
from dpm.tracer.photon_grid import grid_irradiance
from dpm.tracer.sampling import (
    pixel_sequence,
    sample_cdf,
    sample_cosine,
    stratified2,
    uniform,
)
from dpm.tracer.surface import albedo_at, surface_at
from dpm.tracer.traverse import any_hit, closest_hit, new_stack
from dpm.tracer.visible import (
    LUMINANCE,
    MAX_VERTICES,
    RR_SPECULAR,
    RR_START,
    RR_SURVIVAL,
    SHADE_DIM0,
    camera_chain,
    camera_ray,
)

# The most paths of one batch: some 75 float64 each, 0.6 MB, which stays in a Zen 5 core's
# 1 MB L2 (the diffuse room, 128², 64 spp: 4.1-4.3 M samples/s at 1024-2048 paths, 3.0 at
# 4096, 4.0-4.1 at 512).
BATCH = 1024
MIN_BATCHES = 8  # per thread at least, where the paths allow it (the threads' last batches)
ROWS = 57  # float64 state and scratch arrays of a batch (`_run`)
TERMS = 16  # columns of per_path (`_path_terms`)

# The traversal, inlined into the stages that trace (compiled without reference counting,
# as `closest_hit` is): a call passes the BVH's arrays by value, some 40 words per ray.
_closest = nb.njit(cache=True, inline="always", _nrt=False, error_model="numpy")(
    closest_hit.py_func
)
_any = nb.njit(cache=True, inline="always", _nrt=False, error_model="numpy")(any_hit.py_func)
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
    sequence, eps, caustics, emission, grid, starts, out,
):  # fmt: skip
    """`batch_paths` of the batches of tasks starts[b] … starts[b+1]-1, in parallel: for
    each task i, the 12 sums of `path_pixel` (pixel pixels[i], streams pixels[i]·stride +
    firsts[i] + 0 … counts[i]-1, sequence points qfirsts[i] + 0 …) into out (tasks, 12)."""
    for b in nb.prange(len(starts) - 1):
        lo, hi = starts[b], starts[b + 1]
        batch_paths(
            bvh, new_stack(depth), sc, cam, width, height, pixels[lo:hi], firsts[lo:hi],
            counts[lo:hi], qfirsts[lo:hi], stride, seed, sequence, eps, caustics, emission,
            grid, out[lo:hi],
        )  # fmt: skip


@nb.njit(cache=True, parallel=True, error_model="numpy")
def points_kernel(
    bvh, depth, sc, position, normal, albedo, hit, pixel, sample, seed, sequence, first, spp,
    eps, caustics, grid, out,
):  # fmt: skip
    """`shade_kernel` in stages: the reflected radiance (N, 3) of visible points into out,
    batches of BATCH points in parallel; returns the non-finite count."""
    n = len(hit)
    n_batches = (n + BATCH - 1) // BATCH
    bad = np.zeros(n_batches, np.int64)
    for b in nb.prange(n_batches):
        lo, hi = b * BATCH, min(n, (b + 1) * BATCH)
        bad[b] = batch_points(
            bvh, new_stack(depth), sc, position[lo:hi], normal[lo:hi], albedo[lo:hi],
            hit[lo:hi], pixel[lo:hi], sample[lo:hi], seed, sequence, first, spp, eps,
            caustics, grid, out[lo:hi],
        )  # fmt: skip
    return bad.sum()


@nb.njit(cache=True, error_model="numpy")
def _state(n):
    """A batch's state for n paths: ids (path, stream, sequence index, vertex, specular
    vertices since the last diffuse one), sequence seeds, flags (go, test, at a diffuse
    vertex), the hits, ROWS float64 arrays (`_run`) and per_path (n, TERMS) zeros."""
    ids = (np.empty(n, np.int64), np.empty(n, np.int64), np.empty(n, np.int64),
           np.zeros(n, np.int64), np.zeros(n, np.int64))  # fmt: skip
    pseq = np.empty(n, np.uint64)
    flags = (np.empty(n, np.bool_), np.empty(n, np.bool_), np.ones(n, np.bool_))
    hit_t, hit_tri = np.empty(n), np.empty(n, np.int64)
    # each its own allocation: LLVM vectorizes no loop over rows of one 2-D array
    rows = (
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n), np.empty(n),
        np.empty(n),
    )  # fmt: skip
    per_path = np.zeros((n, TERMS))
    return ids, pseq, flags, hit_t, hit_tri, rows, per_path


@nb.njit(cache=True, error_model="numpy")
def batch_paths(
    bvh, stack, sc, cam, width, height, pixels, firsts, counts, qfirsts, stride, seed,
    sequence, eps, caustics, emission, grid, out,
):  # fmt: skip
    """One batch of `wavefront_kernel`: allocates its state, runs it (`_run`)."""
    n = 0
    for c in counts:
        n += c
    ids, pseq, flags, hit_t, hit_tri, rows, per_path = _state(n)
    _run(
        bvh, stack, sc, cam, width, height, pixels, firsts, counts, qfirsts, stride, seed,
        sequence, eps, caustics, emission, grid, ids, pseq, flags, hit_t, hit_tri, rows,
        per_path,
    )  # fmt: skip
    _sums(counts, per_path, out)


@nb.njit(cache=True, error_model="numpy")
def batch_points(
    bvh, stack, sc, position, normal, albedo, hit, pixel, sample, seed, sequence, first, spp,
    eps, caustics, grid, out,
):  # fmt: skip
    """One batch of `points_kernel`: each visible point's path (`shade_path`) in stages;
    returns the non-finite count."""
    n = len(hit)
    ids, pseq, flags, hit_t, hit_tri, rows, per_path = _state(n)
    pid, stream, index, vertex, nspec = ids
    px, py, pz, nx, ny, nz = rows[6:12]
    br, bg, bb, sr, sg, sb = rows[12:18]
    alive = 0
    for i in range(n):
        if not hit[i] or (albedo[i, 0] <= 0 and albedo[i, 1] <= 0 and albedo[i, 2] <= 0):
            continue
        k = alive
        pid[k], stream[k], vertex[k] = i, sample[i], 0
        pseq[k], index[k] = np.uint64(0), -1
        if sequence >= 0:
            pseq[k] = pixel_sequence(sequence, pixel[i])
            index[k] = first + sample[i] - np.int64(pixel[i]) * spp
        px[k], py[k], pz[k] = position[i, 0], position[i, 1], position[i, 2]
        nx[k], ny[k], nz[k] = normal[i, 0], normal[i, 1], normal[i, 2]
        br[k], bg[k], bb[k] = albedo[i, 0], albedo[i, 1], albedo[i, 2]
        sr[k], sg[k], sb[k] = 0.0, 0.0, 0.0
        alive += 1
    _shade(
        bvh, stack, sc, seed, eps, caustics, grid, alive, ids, pseq, flags, hit_t, hit_tri,
        rows, per_path,
    )  # fmt: skip
    bad = 0
    for i in range(n):
        row = per_path[i]
        r, g, b = row[10], row[11], row[12]
        out[i, 0] = out[i, 1] = out[i, 2] = 0.0
        if math.isfinite(r) and math.isfinite(g) and math.isfinite(b):
            out[i, 0], out[i, 1], out[i, 2] = r, g, b
        elif hit[i]:  # as `shade_kernel`: one bad sample must not poison a pixel
            bad += 1
    return bad


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
    bvh, stack, sc, cam, width, height, pixels, firsts, counts, qfirsts, stride, seed,
    sequence, eps, caustics, emission, grid, ids, pseq, flags, hit_t, hit_tri, rows, per_path,
):  # fmt: skip
    """The batch's paths from the camera to their ends; per_path (N, TERMS) gets each path's
    radiance, guides, hit, non-finite flag, squared luminance and camera throughput
    (`path_pixel`'s terms). The camera rays' first hits are traced together; the chains of
    those that meet a mirror or glass follow one at a time (`camera_chain`)."""
    pid, stream, index, vertex, nspec = ids
    go = flags[0]
    ox, oy, oz, dx, dy, dz = rows[0:6]
    px, py, pz, nx, ny, nz = rows[6:12]
    br, bg, bb, sr, sg, sb = rows[12:18]
    n = 0
    for i in range(len(pixels)):
        q = pixel_sequence(max(sequence, 0), pixels[i])
        pix = pixels[i]
        y, x = pix // width, pix % width
        for s in range(counts[i]):
            pid[n], stream[n], pseq[n] = n, pixels[i] * stride + firsts[i] + s, q
            index[n] = qfirsts[i] + s if sequence >= 0 else -1
            if sequence >= 0:
                sx, sy = stratified2(index[n], q, 0)
            else:
                sx, sy = uniform(seed, stream[n], 0), uniform(seed, stream[n], 1)
            dx[n], dy[n], dz[n] = camera_ray(cam, width, height, x + sx, y + sy)
            ox[n], oy[n], oz[n] = cam[0, 0], cam[0, 1], cam[0, 2]
            go[n] = True
            n += 1
    _trace_closest(bvh, stack, n, go, ox, oy, oz, dx, dy, dz, hit_t, hit_tri)
    alive = 0
    for j in range(n):  # the visible points, through the camera's specular chains
        first = surface_at(sc, ox[j], oy[j], oz[j], dx[j], dy[j], dz[j], hit_t[j], hit_tri[j])
        v = camera_chain(bvh, sc, dx[j], dy[j], dz[j], first, stream[j], seed, eps, stack)
        row = per_path[j]
        if emission:
            row[0], row[1], row[2] = v[13], v[14], v[15]
        if not v[0]:
            peak = max(v[13], v[14], v[15])
            if peak > 0:  # a light seen directly: its normalised colour
                row[3], row[4], row[5] = v[13] / peak, v[14] / peak, v[15] / peak
            continue
        row[3] = min(max(v[7] * v[10], 0.0), 1.0)
        row[4] = min(max(v[8] * v[11], 0.0), 1.0)
        row[5] = min(max(v[9] * v[12], 0.0), 1.0)
        row[6], row[7], row[8], row[9] = v[4], v[5], v[6], 1.0
        row[13], row[14], row[15] = v[10], v[11], v[12]
        if v[7] <= 0 and v[8] <= 0 and v[9] <= 0:
            continue  # a black point's path adds nothing (`shade_path` returns at once)
        k = alive  # (k ≤ j: moving down never overwrites a path not yet read)
        pid[k], stream[k], index[k], pseq[k], vertex[k] = j, stream[j], index[j], pseq[j], 0
        px[k], py[k], pz[k], nx[k], ny[k], nz[k] = v[1], v[2], v[3], v[4], v[5], v[6]
        br[k], bg[k], bb[k], sr[k], sg[k], sb[k] = v[7], v[8], v[9], 0.0, 0.0, 0.0
        alive += 1
    _shade(
        bvh, stack, sc, seed, eps, caustics, grid, alive, ids, pseq, flags, hit_t, hit_tri,
        rows, per_path,
    )  # fmt: skip
    _path_terms(n, per_path)


@nb.njit(**_STAGE)
def _shade(
    bvh, stack, sc, seed, eps, caustics, grid, alive, ids, pseq, flags, hit_t, hit_tri, rows,
    per_path,
):  # fmt: skip
    """`shade_path` of the first `alive` paths, each at its visible point (ids, pseq, point,
    normal, weight, light so far): their reflected light into per_path[pid, 10:13]."""
    pid, stream, index, vertex, nspec = ids
    go, test, diffuse = flags
    ox, oy, oz, dx, dy, dz = rows[0:6]  # the ray
    px, py, pz, nx, ny, nz = rows[6:12]  # the vertex
    br, bg, bb, sr, sg, sb = rows[12:18]  # the path's weight, its light so far
    pdf_b, length, gr, gg, gb = rows[18:23]  # BSDF sample density, shadow ray, light share
    u0, la, lb, u4, u5 = rows[23:28]  # a vertex's numbers
    # rows 28-36: a light's corners; then its (or a hit's) normal, density, emission
    lnx, lny, lnz, lpdf, ler, leg, leb = rows[37:44]
    t0, t1, t2 = rows[44:47]  # scratch: a hit's albedo
    share = rows[44:56]  # `_light_share`'s scratch; 50-52 the shadow ray's direction
    start = rows[56]  # the path's weight where its specular chain began
    for k in range(alive):
        diffuse[k] = True
    while alive > 0:
        live = alive
        if grid is not None:
            _grid_light(grid, live, diffuse, vertex, px, py, pz, nx, ny, nz, br, bg, bb, sr, sg, sb)
        _light_numbers(live, seed, stream, vertex, u0, la, lb, u4, u5)
        _light_pick(sc, live, diffuse, index, pseq, vertex, u0, la, lb, u4, u5, rows[28:44])
        _light_share(
            live, eps, diffuse, la, lb, rows[28:37], lpdf, lnx, lny, lnz, ler, leg, leb, px,
            py, pz, nx, ny, nz, br, bg, bb, test, length, gr, gg, gb, share,
        )  # fmt: skip
        _trace_shadow(bvh, stack, live, eps, test, px, py, pz, nx, ny, nz, share[6:9], length)
        _bounce(
            live, seed, eps, diffuse, test, gr, gg, gb, sr, sg, sb, vertex, nspec, stream, br,
            bg, bb, start, nx, ny, nz, px, py, pz, u4, u5, go, pdf_b, ox, oy, oz, dx, dy, dz,
        )  # fmt: skip
        _trace_closest(bvh, stack, live, go, ox, oy, oz, dx, dy, dz, hit_t, hit_tri)
        _hit_gather(
            sc, live, hit_t, hit_tri, ox, oy, oz, dx, dy, dz, diffuse, rows[37:44], t0, t1, t2
        )
        _hit_shade(
            live, caustics, grid is None, hit_t, hit_tri, vertex, nspec, diffuse, ox, oy, oz,
            dx, dy, dz, lnx, lny, lnz, lpdf, ler, leg, leb, t0, t1, t2, pdf_b, sr, sg, sb, br,
            bg, bb, px, py, pz, nx, ny, nz, u4, u5, go,
        )  # fmt: skip
        _scatter(
            sc, live, seed, eps, hit_tri, vertex, nspec, stream, diffuse, u4, br, bg, bb,
            start, px, py, pz, nx, ny, nz, ox, oy, oz, dx, dy, dz, go,
        )  # fmt: skip
        alive = 0
        for k in range(live):  # paths that ended hand their light over; the rest move down
            on = hit_tri[k] >= 0 and vertex[k] < MAX_VERTICES and go[k]
            if not (on and (not diffuse[k] or br[k] > 0 or bg[k] > 0 or bb[k] > 0)):
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
                diffuse[c] = diffuse[k]
                if not diffuse[k]:  # its chain and its next ray
                    nspec[c], start[c] = nspec[k], start[k]
                    ox[c], oy[c], oz[c] = ox[k], oy[k], oz[k]
                    dx[c], dy[c], dz[c] = dx[k], dy[k], dz[k]


@nb.njit(**_STAGE)
def _path_terms(n, per_path):
    """Each path's row of per_path as `path_pixel` adds it up: columns 0-2 radiance (the
    light seen plus, if finite, the camera throughput (columns 13-15) times the reflected
    light that columns 10-12 hold: see `_run`), 3-5 albedo, 6-8 normal, 9 whether it saw a
    surface, 10 whether its light was not finite, 11 its luminance squared (12: scratch)."""
    for j in range(n):
        row = per_path[j]
        r, g, b = row[0], row[1], row[2]
        if row[9] > 0:
            lr, lg, lb = row[10], row[11], row[12]
            if math.isfinite(lr) and math.isfinite(lg) and math.isfinite(lb):
                r, g, b = r + row[13] * lr, g + row[14] * lg, b + row[15] * lb
                row[10] = 0.0
            else:
                row[10] = 1.0
        else:
            row[10] = 0.0
        row[0], row[1], row[2] = r, g, b
        lum = LUMINANCE[0] * r + LUMINANCE[1] * g + LUMINANCE[2] * b
        row[11] = lum * lum


@nb.njit(**_STAGE)
def _trace_closest(bvh, stack, n, go, ox, oy, oz, dx, dy, dz, hit_t, hit_tri):
    """Closest hits of the rays whose `go` is set (hit_tri -1 for the others)."""
    for k in range(n):
        hit_tri[k] = -1
        if go[k]:
            hit_t[k], hit_tri[k] = _closest(
                bvh, ox[k], oy[k], oz[k], dx[k], dy[k], dz[k], np.inf, stack
            )


@nb.njit(**_STAGE)
def _trace_shadow(bvh, stack, n, eps, test, px, py, pz, nx, ny, nz, direction, length):
    """`test` cleared where the shadow ray from the vertex (lifted off its surface) along
    `direction` up to `length` is occluded."""
    wx, wy, wz = direction
    for k in range(n):
        if test[k] and length[k] > 0:
            ax, ay, az = px[k] + eps * nx[k], py[k] + eps * ny[k], pz[k] + eps * nz[k]
            test[k] = not _any(bvh, ax, ay, az, wx[k], wy[k], wz[k], length[k], stack)


@nb.njit(**_STAGE)
def _grid_light(grid, n, diffuse, vertex, px, py, pz, nx, ny, nz, br, bg, bb, sr, sg, sb):
    """The photon grid's caustic light at the diffuse vertices after the visible point."""
    inv_pi = 1.0 / math.pi
    for k in range(n):
        if diffuse[k] and vertex[k] > 0:
            er, eg, eb = grid_irradiance(grid, px[k], py[k], pz[k], nx[k], ny[k], nz[k])
            sr[k] += br[k] * er * inv_pi
            sg[k] += bg[k] * eg * inv_pi
            sb[k] += bb[k] * eb * inv_pi


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
def _light_pick(sc, n, diffuse, index, pseq, vertex, u0, la, lb, u4, u5, light):
    """Each diffuse vertex's light sample: its triangle (by power) and what it holds into
    light: corners (9), normal (3), density per area, emission (3); the first vertex's
    numbers come from the pixel's stratified sequence where it has one
    (`sample_light_stratified`)."""
    c0, c1, c2, c3, c4, c5, c6, c7, c8, lnx, lny, lnz, lpdf, ler, leg, leb = light
    for k in range(n):
        if not diffuse[k]:
            continue
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
    n, eps, diffuse, la, lb, corners, lpdf, lnx, lny, lnz, ler, leg, leb, px, py, pz, nx, ny,
    nz, br, bg, bb, test, length, gr, gg, gb, scratch,
):  # fmt: skip
    """The light sample's point on its triangle (corners), its MIS-weighted share (gr, gg,
    gb), whether it counts (test: at diffuse vertices) and the shadow ray's direction
    (scratch 6-8) and length: `shade_path`'s and `_unoccluded`'s arithmetic, in loops of few
    arrays each."""
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
        test[k] = diffuse[k] & (dist[k] > 0) & (lpdf[k] > 0) & (cos_x[k] > 0) & (cos_l[k] > 0)
    # the segment between the ends lifted off their surfaces (w: free again)
    for k in range(n):
        wx[k] = (qx[k] + eps * lnx[k]) - (px[k] + eps * nx[k])
    for k in range(n):
        wy[k] = (qy[k] + eps * lny[k]) - (py[k] + eps * ny[k])
    for k in range(n):
        wz[k] = (qz[k] + eps * lnz[k]) - (pz[k] + eps * nz[k])
    for k in range(n):
        x, y, z = wx[k], wy[k], wz[k]
        d = math.sqrt(x * x + y * y + z * z)
        inv = 1.0 / d
        wx[k], wy[k], wz[k], length[k] = x * inv, y * inv, z * inv, d
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
    n, seed, eps, diffuse, test, gr, gg, gb, sr, sg, sb, vertex, nspec, stream, br, bg, bb,
    start, nx, ny, nz, px, py, pz, u4, u5, go, pdf_b, ox, oy, oz, dx, dy, dz,
):  # fmt: skip
    """The light sample's share where unoccluded; at diffuse vertices Russian roulette (go)
    and the next ray, a cosine-sampled one (a specular vertex's is ready: `_scatter`)."""
    for k in range(n):
        if test[k]:
            sr[k] += gr[k]
            sg[k] += gg[k]
            sb[k] += gb[k]
    for k in range(n):
        v = vertex[k]
        q = min(max(br[k], bg[k], bb[k]), RR_SURVIVAL)
        roll = diffuse[k] & (v >= RR_START)
        go[k] = not roll or uniform(seed, stream[k], SHADE_DIM0 + 8 * v + 6) < q
        if roll:
            br[k], bg[k], bb[k] = br[k] / q, bg[k] / q, bb[k] / q
        vertex[k] = v + 1
    inv_pi = 1.0 / math.pi
    for k in range(n):
        mx, my, mz = nx[k], ny[k], nz[k]
        ex, ey, ez = sample_cosine(mx, my, mz, u4[k], u5[k])
        if diffuse[k]:
            pdf_b[k] = max(ex * mx + ey * my + ez * mz, 0.0) * inv_pi
            dx[k], dy[k], dz[k] = ex, ey, ez
    for k in range(n):
        if diffuse[k]:
            ox[k], oy[k], oz[k] = px[k] + eps * nx[k], py[k] + eps * ny[k], pz[k] + eps * nz[k]
    for k in range(n):
        if diffuse[k]:
            start[k] = max(br[k], bg[k], bb[k])
            nspec[k] = 0


@nb.njit(**_STAGE)
def _hit_gather(sc, n, hit_t, hit_tri, ox, oy, oz, dx, dy, dz, diffuse, surface, ar, ag, ab):
    """What each hit triangle holds into surface (normal (3), emitter density, emission
    (3)), whether it is diffuse and its albedo at the hit point into ar, ag, ab."""
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
        diffuse[k] = sc.kind[m] == DIFFUSE
        if diffuse[k]:
            x, y, z = ox[k] + t * dx[k], oy[k] + t * dy[k], oz[k] + t * dz[k]
            ar[k], ag[k], ab[k] = albedo_at(sc, m, tri, x, y, z)


@nb.njit(**_STAGE)
def _hit_shade(
    n, caustics, no_grid, hit_t, hit_tri, vertex, nspec, diffuse, ox, oy, oz, dx, dy, dz,
    lnx, lny, lnz, lpdf, ler, leg, leb, ar, ag, ab, pdf_b, sr, sg, sb, br, bg, bb, px, py, pz,
    nx, ny, nz, cos_d, w, emit,
):  # fmt: skip
    """Light found by BSDF sampling (MIS-weighted straight after a diffuse vertex; through a
    specular chain in full where caustics are traced, or where the chain began past the
    visible point and no photon grid stands in: `shade_path`); the path's weight times the
    albedo of a diffuse hit; the hit as the next vertex (`next_surface`'s point and normal
    facing the ray). cos_d (kept for `_scatter`), w and emit are scratch."""
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
        if nspec[k] > 0:  # only BSDF sampling reaches lights through specular chains
            full = caustics or (no_grid and vertex[k] > nspec[k] + 1)
            w[k] = 1.0 if full else 0.0
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
        if (hit_tri[k] >= 0) & diffuse[k]:
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


@nb.njit(**_STAGE)
def _scatter(
    sc, n, seed, eps, hit_tri, vertex, nspec, stream, diffuse, cos_d, br, bg, bb, start, px,
    py, pz, nx, ny, nz, ox, oy, oz, dx, dy, dz, go,
):  # fmt: skip
    """At specular hits: Russian roulette (go cleared where it ends the path) and the next
    ray, scattered by the mirror or glass (`shade_path`'s inner loop)."""
    for k in range(n):
        go[k] = True
        tri = hit_tri[k]
        if tri < 0 or diffuse[k] or vertex[k] >= MAX_VERTICES:
            continue
        m = sc.material[tri]
        c = cos_d[k]
        front = c < 0
        cos_i = -c if front else c  # (`next_surface`'s, from the flipped normal)
        v = vertex[k]
        dim = SHADE_DIM0 + 8 * v
        if v >= RR_SPECULAR:  # long specular chains too: TIR can trap a path in glass
            q = specular_survival(sc, m, front, max(br[k], bg[k], bb[k]), start[k], True)
            if uniform(seed, stream[k], dim + 6) >= q:
                go[k] = False
                continue
            br[k], bg[k], bb[k] = br[k] / q, bg[k] / q, bb[k] / q
        u = uniform(seed, stream[k], dim)
        ex, ey, ez, wr, wg, wb, side = scatter_specular(
            sc, m, dx[k], dy[k], dz[k], nx[k], ny[k], nz[k], cos_i, front, u, True
        )
        br[k], bg[k], bb[k] = br[k] * wr, bg[k] * wg, bb[k] * wb
        ox[k] = px[k] + side * eps * nx[k]
        oy[k] = py[k] + side * eps * ny[k]
        oz[k] = pz[k] + side * eps * nz[k]
        dx[k], dy[k], dz[k] = ex, ey, ez
        nspec[k] += 1
