"""Bounding volume hierarchy over triangles: binned-SAH binary build, collapsed to 8-wide nodes.

Layout: only interior nodes are stored, each as one 256-byte record (four cache lines, 64-byte
aligned) holding the boxes of its WIDTH = 8 children as structure of arrays, so one ray is
tested against all eight at once (`traverse._box_test`). Seen as float32, columns
WIDTH·p + c hold plane p of child c's box, planes 0–2 being min x, y, z and 3–5 max x, y, z.
Seen as int32, column REFS + c (REFS = 6·WIDTH) is child c's reference: an interior node's
record index (≥ 0), or for a leaf ~(first << LEAF_BITS | count), the leaf's triangles being
rows first ... first + count - 1 (count ≤ MAX_LEAF) of `tri_verts` (BVH order). An empty
slot has an inverted box (min inf, max -inf) that no ray enters, and reference EMPTY. The
last WIDTH columns are padding. Record 0 is the root.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np

N_BINS = 32  # SAH bins per axis; with 16, paths in the pools' wavy water took 5–9 % longer
MAX_LEAF = 4  # a node with more triangles is always split; a leaf is one 4-lane test
TRAVERSAL_COST = 2.0  # SAH cost of one binary node relative to one triangle test
# Triangles per unit of a leaf's SAH cost. 1 (each costs one) beat Embree's model for its
# 4-triangle leaves (one unit per block of 4, as a leaf here is one 4-lane test): those made
# fewer, fuller leaves that traced slower (benchmarks/results/bvh_sah.md).
LEAF_COST_LANES = 1
WIDTH = 8  # children per node
REFS = 6 * WIDTH  # first column of the child references (after six planes of WIDTH floats)
RECORD = 8 * WIDTH  # 4-byte columns per node record (two of padding per child)
LEAF_BITS = 4  # low bits of a leaf reference that hold its triangle count (≤ MAX_LEAF)
# A leaf's triangles are tested together, one per SIMD lane (`traverse.LEAF_LANES`).
assert MAX_LEAF < 2**LEAF_BITS
EMPTY = ~0  # reference of an empty child slot: a leaf of no triangles


class BVHArrays(NamedTuple):
    """The arrays Numba kernels traverse; pass `bvh.arrays` into any tracer kernel."""

    bounds: np.ndarray  # (nodes, RECORD) float32 view of the node records (boxes)
    kids: np.ndarray  # (nodes, RECORD) int32 view of the same memory (child references)
    tri_verts: np.ndarray  # (T, 9) float32 triangle vertices v0, v1, v2 in BVH order
    tri_index: np.ndarray  # (T,) int32 scene triangle index of each BVH-order triangle
    tri_planes: np.ndarray  # (9, T + MAX_LEAF) float32 tri_verts transposed, zero-padded


@dataclass(frozen=True)
class BVH:
    """A built BVH: node arrays plus the depth needed to size traversal stacks."""

    arrays: BVHArrays
    depth: int  # levels of WIDTH-wide nodes; `traverse.new_stack(depth)` sizes a stack for them

    @property
    def n_nodes(self) -> int:
        """Number of interior nodes (each also holds its children's boxes)."""
        return len(self.arrays.kids)


@nb.njit(cache=True)
def _half_area(lo0, lo1, lo2, hi0, hi1, hi2):
    dx, dy, dz = hi0 - lo0, hi1 - lo1, hi2 - lo2
    return dx * dy + dy * dz + dz * dx


@nb.njit(cache=True)
def _build(tri_lo, tri_hi, centroid, n_bins, max_leaf, traversal_cost, lanes):
    """Binary SAH build over triangle boxes (T, 3) and centroids (T, 3): a leaf costs one unit
    per block of `lanes` triangles. Returns depth-first nodes (boxes, child, count), the
    triangle order and the depth."""
    n_tri = tri_lo.shape[0]
    order = np.arange(n_tri).astype(np.int32)
    max_nodes = 2 * n_tri
    bounds = np.empty((max_nodes, 6), np.float32)
    child = np.zeros(max_nodes, np.int32)
    count = np.zeros(max_nodes, np.int32)
    # Depth-first: push right, then left, so the left child always gets the next index.
    st_start = np.empty(max_nodes, np.int64)
    st_end = np.empty(max_nodes, np.int64)
    st_parent = np.empty(max_nodes, np.int64)  # node whose right child this is, or -1
    st_depth = np.empty(max_nodes, np.int64)
    st_start[0], st_end[0], st_parent[0], st_depth[0] = 0, n_tri, -1, 1
    sp = 1
    n_nodes = 0
    max_depth = 0
    bin_count = np.empty((3, n_bins), np.int64)
    bin_lo = np.empty((3, n_bins, 3))
    bin_hi = np.empty((3, n_bins, 3))
    right_area = np.empty(n_bins)
    right_count = np.empty(n_bins, np.int64)
    while sp > 0:
        sp -= 1
        start, end, parent, depth = st_start[sp], st_end[sp], st_parent[sp], st_depth[sp]
        node = n_nodes
        n_nodes += 1
        max_depth = max(max_depth, depth)
        if parent >= 0:
            child[parent] = node
        lo = np.full(3, np.inf)
        hi = np.full(3, -np.inf)
        clo = np.full(3, np.inf)
        chi = np.full(3, -np.inf)
        for i in range(start, end):
            t = order[i]
            for a in range(3):
                lo[a] = min(lo[a], tri_lo[t, a])
                hi[a] = max(hi[a], tri_hi[t, a])
                clo[a] = min(clo[a], centroid[t, a])
                chi[a] = max(chi[a], centroid[t, a])
        for a in range(3):
            bounds[node, a] = lo[a]
            bounds[node, 3 + a] = hi[a]
        n = end - start
        if n == 1:
            child[node], count[node] = start, 1
            continue
        # Binned SAH over all three axes.
        bin_count[:] = 0
        bin_lo[:] = np.inf
        bin_hi[:] = -np.inf
        for i in range(start, end):
            t = order[i]
            for a in range(3):
                ext = chi[a] - clo[a]
                if ext <= 0:
                    continue
                b = min(int(n_bins * (centroid[t, a] - clo[a]) / ext), n_bins - 1)
                bin_count[a, b] += 1
                for c in range(3):
                    bin_lo[a, b, c] = min(bin_lo[a, b, c], tri_lo[t, c])
                    bin_hi[a, b, c] = max(bin_hi[a, b, c], tri_hi[t, c])
        parent_area = _half_area(lo[0], lo[1], lo[2], hi[0], hi[1], hi[2])
        best_cost, best_axis, best_split = np.inf, -1, -1
        for a in range(3):
            if chi[a] - clo[a] <= 0:
                continue
            # Sweep from the right to get the area and count right of each split plane.
            rlo = np.full(3, np.inf)
            rhi = np.full(3, -np.inf)
            rc = 0
            for b in range(n_bins - 1, 0, -1):
                rc += bin_count[a, b]
                for c in range(3):
                    rlo[c] = min(rlo[c], bin_lo[a, b, c])
                    rhi[c] = max(rhi[c], bin_hi[a, b, c])
                right_count[b] = rc
                right_area[b] = _half_area(rlo[0], rlo[1], rlo[2], rhi[0], rhi[1], rhi[2])
            llo = np.full(3, np.inf)
            lhi = np.full(3, -np.inf)
            lc = 0
            for b in range(1, n_bins):
                lc += bin_count[a, b - 1]
                for c in range(3):
                    llo[c] = min(llo[c], bin_lo[a, b - 1, c])
                    lhi[c] = max(lhi[c], bin_hi[a, b - 1, c])
                if lc == 0 or right_count[b] == 0:
                    continue
                left_area = _half_area(llo[0], llo[1], llo[2], lhi[0], lhi[1], lhi[2])
                blocks_l, blocks_r = lc, right_count[b]
                if lanes > 1:  # no divisions in the shipped build's inner loop
                    blocks_l = (blocks_l + lanes - 1) // lanes
                    blocks_r = (blocks_r + lanes - 1) // lanes
                cost = traversal_cost + (blocks_l * left_area + blocks_r * right_area[b]) / max(
                    parent_area, 1e-300
                )
                if cost < best_cost:
                    best_cost, best_axis, best_split = cost, a, b
        if n <= max_leaf and (best_axis < 0 or best_cost >= (n + lanes - 1) // lanes):
            child[node], count[node] = start, n
            continue
        if best_axis >= 0:
            # Partition order[start:end] in place by bin index.
            a = best_axis
            ext = chi[a] - clo[a]
            i, j = start, end - 1
            while i <= j:
                t = order[i]
                b = min(int(n_bins * (centroid[t, a] - clo[a]) / ext), n_bins - 1)
                if b < best_split:
                    i += 1
                else:
                    order[i], order[j] = order[j], order[i]
                    j -= 1
            mid = i
        else:
            mid = start + n // 2  # all centroids coincide: split the list in half
        st_start[sp], st_end[sp], st_parent[sp], st_depth[sp] = mid, end, node, depth + 1
        sp += 1
        st_start[sp], st_end[sp], st_parent[sp], st_depth[sp] = start, mid, -1, depth + 1
        sp += 1
    return bounds[:n_nodes].copy(), child[:n_nodes].copy(), count[:n_nodes].copy(), order, max_depth


@nb.njit(cache=True)
def _collapse(bounds, child, count):
    """Binary depth-first nodes (left = i + 1, right = child[i]) into WIDTH-wide node records.

    Each binary interior node that becomes a wide node takes as children its own two, then
    repeatedly the two children of its largest-area interior child, until it has WIDTH or only
    leaves. Children of a node get consecutive indices. Returns (records, levels).
    """
    n = bounds.shape[0]
    records = np.zeros((max(n, 1), RECORD), np.int32)
    boxes = records.view(np.float32)
    work = np.empty((n + 1, 3), np.int64)  # (binary node, record, level)
    work[0, 0], work[0, 1], work[0, 2] = 0, 0, 1
    sp, n_rec, levels = 1, 1, 1
    pick = np.empty(WIDTH, np.int64)
    while sp > 0:
        sp -= 1
        b, rec, level = work[sp, 0], work[sp, 1], work[sp, 2]
        levels = max(levels, level)
        if count[b] > 0:  # only when the root is a leaf
            pick[0], k = b, 1
        else:
            pick[0], pick[1], k = b + 1, child[b], 2
        while k < WIDTH:
            best, best_area = -1, -1.0
            for j in range(k):
                c = pick[j]
                if count[c] == 0:
                    lo, hi = bounds[c, :3], bounds[c, 3:]
                    area = _half_area(lo[0], lo[1], lo[2], hi[0], hi[1], hi[2])
                    if area > best_area:
                        best, best_area = j, area
            if best < 0:
                break
            c = pick[best]
            for j in range(k, best + 1, -1):  # keep the children in their left-to-right order
                pick[j] = pick[j - 1]
            pick[best], pick[best + 1] = c + 1, child[c]
            k += 1
        first_new = n_rec
        for j in range(WIDTH):
            if j >= k:  # an empty slot: an inverted box no ray enters
                for a in range(3):
                    boxes[rec, WIDTH * a + j] = np.inf
                    boxes[rec, WIDTH * (3 + a) + j] = -np.inf
                records[rec, REFS + j] = EMPTY
                continue
            c = pick[j]
            for a in range(3):
                boxes[rec, WIDTH * a + j] = bounds[c, a]
                boxes[rec, WIDTH * (3 + a) + j] = bounds[c, 3 + a]
            if count[c] > 0:
                records[rec, REFS + j] = ~((child[c] << LEAF_BITS) | count[c])
            else:
                records[rec, REFS + j] = n_rec
                n_rec += 1
        # Push the interior children last-first, so the first is expanded next.
        for j in range(k - 1, -1, -1):
            r = records[rec, REFS + j]
            if r >= first_new:
                work[sp, 0], work[sp, 1], work[sp, 2] = pick[j], r, level + 1
                sp += 1
    return records[:n_rec].copy(), levels


def _aligned(shape: tuple[int, int], dtype) -> np.ndarray:
    """An empty C-contiguous array whose data starts on a 64-byte (cache-line) boundary."""
    size = shape[0] * shape[1] * np.dtype(dtype).itemsize
    raw = np.empty(size + 64, np.uint8)
    start = -raw.ctypes.data % 64
    return raw[start : start + size].view(dtype).reshape(shape)


def build_bvh_from_triangles(
    triangles: np.ndarray,
    traversal_cost: float = TRAVERSAL_COST,
    leaf_cost_lanes: int = LEAF_COST_LANES,
) -> BVH:
    """Build a BVH over triangles (T, 3, 3) float32 vertex positions (the SAH constants are
    for `benchmarks/bvh_sah.py`; the defaults are the shipped ones)."""
    tri = np.ascontiguousarray(triangles, dtype=np.float32).reshape(-1, 3, 3)
    if len(tri) == 0:
        raise ValueError("cannot build a BVH over zero triangles")
    if len(tri) >= 2 ** (31 - LEAF_BITS):
        raise ValueError(f"at most {2 ** (31 - LEAF_BITS) - 1} triangles per BVH")
    tri64 = tri.astype(np.float64)
    bounds, child, count, order, _ = _build(
        tri64.min(axis=1),
        tri64.max(axis=1),
        tri64.mean(axis=1),
        N_BINS,
        MAX_LEAF,
        traversal_cost,
        leaf_cost_lanes,
    )
    records, levels = _collapse(bounds, child, count)
    nodes = _aligned(records.shape, np.int32)
    nodes[:] = records
    verts = np.ascontiguousarray(tri[order].reshape(-1, 9))
    # Plane-major copy: a leaf's triangles are MAX_LEAF consecutive floats per coordinate
    # (the padding: a leaf test reads MAX_LEAF lanes, however few triangles the leaf has).
    planes = _aligned((9, len(verts) + MAX_LEAF), np.float32)
    planes[:, : len(verts)] = verts.T
    planes[:, len(verts) :] = 0.0
    arrays = BVHArrays(
        bounds=nodes.view(np.float32),
        kids=nodes,
        tri_verts=verts,
        tri_index=order,
        tri_planes=planes,
    )
    return BVH(arrays=arrays, depth=int(levels))
