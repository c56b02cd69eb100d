"""Ray queries: the watertight ray–triangle test and closest-hit / any-hit BVH traversal.

The single-ray functions (`closest_hit`, `any_hit`) are what other Numba kernels call inside
their own `prange` loops; the `*_batch` kernels run them over arrays of rays.
Arithmetic is float64 on float32 geometry, with no fastmath: watertightness needs exact IEEE.
"""

from __future__ import annotations

import numba as nb
import numpy as np

from dpm.scene import Scene

# pbrt's robust-slab factor 1 + 2·γ(3) for float64, so box tests never cull a true hit.
_SLAB_SCALE = 1.0 + 2.0 * (3 * 2.0**-53) / (1 - 3 * 2.0**-53)
SPAWN_OFFSET = 1e-6  # new rays start this fraction of the scene diagonal off their surface
RAYS_PER_TASK = 256  # rays each parallel task traces with one traversal stack


@nb.njit(cache=True, inline="always", error_model="numpy")
def ray_setup(dx, dy, dz):
    """Per-ray constants of the watertight test: permuted axes and shear (Woop et al. 2013)."""
    ax, ay, az = abs(dx), abs(dy), abs(dz)
    if ax > ay and ax > az:
        kz = 0
    elif ay > az:
        kz = 1
    else:
        kz = 2
    kx = (kz + 1) % 3
    ky = (kx + 1) % 3
    d = (dx, dy, dz)
    if d[kz] < 0:  # keep the winding, so front faces stay front faces
        kx, ky = ky, kx
    inv = 1.0 / d[kz]
    return kx, ky, kz, -d[kx] * inv, -d[ky] * inv, inv


@nb.njit(cache=True, inline="always", error_model="numpy")
def hit_triangle(v, i, ox, oy, oz, kx, ky, kz, sx, sy, sz, tmax):
    """Distance t in (0, tmax) to triangle row i of v (T, 9), or inf on a miss."""
    ax, ay, az = v[i, 0] - ox, v[i, 1] - oy, v[i, 2] - oz
    bx, by, bz = v[i, 3] - ox, v[i, 4] - oy, v[i, 5] - oz
    cx, cy, cz = v[i, 6] - ox, v[i, 7] - oy, v[i, 8] - oz
    a = (ax, ay, az)
    b = (bx, by, bz)
    c = (cx, cy, cz)
    a_x = a[kx] + sx * a[kz]
    a_y = a[ky] + sy * a[kz]
    b_x = b[kx] + sx * b[kz]
    b_y = b[ky] + sy * b[kz]
    c_x = c[kx] + sx * c[kz]
    c_y = c[ky] + sy * c[kz]
    e0 = b_x * c_y - b_y * c_x
    e1 = c_x * a_y - c_y * a_x
    e2 = a_x * b_y - a_y * b_x
    if (e0 < 0 or e1 < 0 or e2 < 0) and (e0 > 0 or e1 > 0 or e2 > 0):
        return np.inf
    det = e0 + e1 + e2
    if det == 0:
        return np.inf
    tscaled = sz * (e0 * a[kz] + e1 * b[kz] + e2 * c[kz])
    if det < 0 and (tscaled >= 0 or tscaled < tmax * det):
        return np.inf
    if det > 0 and (tscaled <= 0 or tscaled > tmax * det):
        return np.inf
    return tscaled / det


@nb.njit(cache=True, inline="always")
def _slab(lo, hi, o, inv, t0, t1):
    """Clip the interval (t0, t1) by one axis' slab [lo, hi].

    Written with comparisons, not min/max, so a NaN bound (a ray lying in a box face, where
    0·inf appears) leaves the interval alone rather than turning into a miss.
    """
    near = (lo - o) * inv
    far = (hi - o) * inv
    if near > far:
        near, far = far, near
    if near > t0:
        t0 = near
    if far * _SLAB_SCALE < t1:
        t1 = far * _SLAB_SCALE
    return t0, t1


@nb.njit(cache=True, inline="always", error_model="numpy")
def hit_box(bounds, node, at, ox, oy, oz, ix, iy, iz, tmax):
    """Entry distance into the box bounds[node, at:at+6] if entered before tmax, else inf."""
    t0, t1 = _slab(bounds[node, at], bounds[node, at + 3], ox, ix, 0.0, tmax)
    t0, t1 = _slab(bounds[node, at + 1], bounds[node, at + 4], oy, iy, t0, t1)
    t0, t1 = _slab(bounds[node, at + 2], bounds[node, at + 5], oz, iz, t0, t1)
    return t0 if t0 <= t1 else np.inf


@nb.njit(cache=True, inline="always")
def _hit_leaf(verts, first, n, ray, best_t, best):
    """Nearest of (best_t, best) and the hits on triangles first..first+n-1 of a leaf."""
    ox, oy, oz, kx, ky, kz, sx, sy, sz = ray
    for i in range(first, first + n):
        t = hit_triangle(verts, i, ox, oy, oz, kx, ky, kz, sx, sy, sz, best_t)
        if t < best_t:
            best_t, best = t, i
    return best_t, best


@nb.njit(cache=True)
def new_stack(depth):
    """Traversal scratch for one thread: (depth + 1, 2) float64 rows of (node, entry t)."""
    return np.empty((depth + 1, 2), np.float64)


@nb.njit(cache=True, error_model="numpy")
def closest_hit(bvh, ox, oy, oz, dx, dy, dz, tmax, stack):
    """(t, scene triangle index) of the nearest hit in (0, tmax), or (inf, -1).

    `bvh` is a BVHArrays; `stack` is scratch from `new_stack` (node index, entry distance).
    """
    bounds, kids, verts = bvh.bounds, bvh.kids, bvh.tri_verts
    kx, ky, kz, sx, sy, sz = ray_setup(dx, dy, dz)
    ray = (ox, oy, oz, kx, ky, kz, sx, sy, sz)
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    best_t, best = tmax, -1
    node, sp = 0, 0
    while True:
        tl = hit_box(bounds, node, 0, ox, oy, oz, ix, iy, iz, best_t)
        tr = hit_box(bounds, node, 6, ox, oy, oz, ix, iy, iz, best_t)
        left, right = kids[node, 12], kids[node, 13]
        n_left, n_right = kids[node, 14], kids[node, 15]
        # Leaf children are intersected right away, the nearer one first.
        if n_left > 0 and n_right > 0 and tr < tl:
            left, right, n_left, n_right, tl, tr = right, left, n_right, n_left, tr, tl
        # A miss is inf, and best_t may be inf too: a child counts only if finite and ≤ best_t.
        if n_left > 0:
            if tl < np.inf and tl <= best_t:
                best_t, best = _hit_leaf(verts, left, n_left, ray, best_t, best)
            tl = np.inf
        if n_right > 0:
            if tr < np.inf and tr <= best_t:
                best_t, best = _hit_leaf(verts, right, n_right, ray, best_t, best)
            tr = np.inf
        go_left = tl < np.inf and tl <= best_t
        go_right = tr < np.inf and tr <= best_t
        if go_left and go_right:
            if tr < tl:
                left, right, tl, tr = right, left, tr, tl
            stack[sp, 0] = right  # the farther child waits, with its entry distance
            stack[sp, 1] = tr
            sp += 1
            node = left
            continue
        if go_left:
            node = left
            continue
        if go_right:
            node = right
            continue
        # Pop the next subtree that may still hold a nearer hit.
        while sp > 0 and stack[sp - 1, 1] > best_t:
            sp -= 1
        if sp == 0:
            break
        sp -= 1
        node = int(stack[sp, 0])
    if best < 0:
        return np.inf, -1
    return best_t, bvh.tri_index[best]


@nb.njit(cache=True, error_model="numpy")
def any_hit(bvh, ox, oy, oz, dx, dy, dz, tmax, stack):
    """True if the ray hits any triangle at a distance in (0, tmax)."""
    bounds, kids, verts = bvh.bounds, bvh.kids, bvh.tri_verts
    kx, ky, kz, sx, sy, sz = ray_setup(dx, dy, dz)
    ix, iy, iz = 1.0 / dx, 1.0 / dy, 1.0 / dz
    stack[0, 0] = 0
    sp = 1
    while sp > 0:
        sp -= 1
        node = int(stack[sp, 0])
        for c in range(2):
            if hit_box(bounds, node, 6 * c, ox, oy, oz, ix, iy, iz, tmax) == np.inf:
                continue
            ref, n = kids[node, 12 + c], kids[node, 14 + c]
            if n == 0:
                stack[sp, 0] = ref
                sp += 1
                continue
            for i in range(ref, ref + n):
                # hit_triangle admits t == tmax; hits count only strictly before tmax.
                if hit_triangle(verts, i, ox, oy, oz, kx, ky, kz, sx, sy, sz, tmax) < tmax:
                    return True
    return False


@nb.njit(cache=True, parallel=True, error_model="numpy")
def closest_hit_batch(bvh, depth, origins, directions, tmax, out_t, out_tri):
    """Closest hits of rays (R, 3) into out_t (R,) float64 and out_tri (R,) int32."""
    n = origins.shape[0]
    n_tasks = (n + RAYS_PER_TASK - 1) // RAYS_PER_TASK
    for task in nb.prange(n_tasks):
        stack = new_stack(depth)
        for r in range(task * RAYS_PER_TASK, min(n, (task + 1) * RAYS_PER_TASK)):
            o, d = origins[r], directions[r]
            out_t[r], out_tri[r] = closest_hit(
                bvh, o[0], o[1], o[2], d[0], d[1], d[2], tmax[r], stack
            )


@nb.njit(cache=True, parallel=True, error_model="numpy")
def any_hit_batch(bvh, depth, origins, directions, tmax, out):
    """Occlusion of rays (R, 3) within tmax (R,) into out (R,) bool."""
    n = origins.shape[0]
    n_tasks = (n + RAYS_PER_TASK - 1) // RAYS_PER_TASK
    for task in nb.prange(n_tasks):
        stack = new_stack(depth)
        for r in range(task * RAYS_PER_TASK, min(n, (task + 1) * RAYS_PER_TASK)):
            out[r] = any_hit(
                bvh, origins[r, 0], origins[r, 1], origins[r, 2],
                directions[r, 0], directions[r, 1], directions[r, 2], tmax[r], stack,
            )  # fmt: skip


@nb.njit(cache=True, parallel=True, error_model="numpy")
def brute_force_batch(verts, origins, directions, tmax, out_t, out_tri):
    """Closest hits by testing every triangle of verts (T, 9): the BVH's reference."""
    for r in nb.prange(origins.shape[0]):
        o, d = origins[r], directions[r]
        kx, ky, kz, sx, sy, sz = ray_setup(d[0], d[1], d[2])
        best_t, best = tmax[r], -1
        for i in range(verts.shape[0]):
            t = hit_triangle(verts, i, o[0], o[1], o[2], kx, ky, kz, sx, sy, sz, best_t)
            if t < best_t:
                best_t, best = t, i
        out_t[r], out_tri[r] = (best_t, best) if best >= 0 else (np.inf, -1)


def spawn_offset(scene: Scene) -> float:
    """Distance (scene units) new rays start off the surface they leave, against self-hits.

    Hit points are float64 on float32 triangles, so their error is far below this offset.
    """
    return SPAWN_OFFSET * max(scene.extent, 1e-30)
