"""Bounding volume hierarchy over triangles: binned-SAH build into flat node arrays.

Layout: only interior nodes are stored, each as one 64-byte record (one cache line) holding
the boxes of both children: columns 0–11 as float32 (left min, max xyz; right min, max xyz)
and columns 12–15 as int32. For child c in (0, 1) of node i, `kids[i, 14 + c]` is 0 when the
child is an interior node with index `kids[i, 12 + c]`, or the triangle count of a leaf whose
triangles are rows `kids[i, 12 + c] ...` of `tri_verts` (BVH order). Node 0 is the root.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import NamedTuple

import numba as nb
import numpy as np

N_BINS = 16
MAX_LEAF = 8  # a node with more triangles is always split
TRAVERSAL_COST = 1.0  # SAH cost of one box test relative to one triangle test


class BVHArrays(NamedTuple):
    """The arrays Numba kernels traverse; pass `bvh.arrays` into any tracer kernel."""

    bounds: np.ndarray  # (nodes, 16) float32 view of the node records (columns 0–11 used)
    kids: np.ndarray  # (nodes, 16) int32 view of the same memory (columns 12–15 used)
    tri_verts: np.ndarray  # (T, 9) float32 triangle vertices v0, v1, v2 in BVH order
    tri_index: np.ndarray  # (T,) int32 scene triangle index of each BVH-order triangle


@dataclass(frozen=True)
class BVH:
    """A built BVH: node arrays plus the depth needed to size traversal stacks."""

    arrays: BVHArrays
    depth: int  # number of levels; traversal stacks need depth + 1 entries

    @property
    def n_nodes(self) -> int:
        """Number of interior nodes (each also holds its children's boxes)."""
        return len(self.arrays.kids)


@nb.njit(cache=True)
def _half_area(lo0, lo1, lo2, hi0, hi1, hi2):
    dx, dy, dz = hi0 - lo0, hi1 - lo1, hi2 - lo2
    return dx * dy + dy * dz + dz * dx


@nb.njit(cache=True)
def _build(tri_lo, tri_hi, centroid, n_bins, max_leaf, traversal_cost):
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
                cost = traversal_cost + (lc * left_area + right_count[b] * right_area[b]) / max(
                    parent_area, 1e-300
                )
                if cost < best_cost:
                    best_cost, best_axis, best_split = cost, a, b
        if n <= max_leaf and (best_axis < 0 or best_cost >= n):
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
def _pack(bounds, child, count):
    """Depth-first nodes (left = i + 1, right = child[i]) into the two-boxes-per-node layout."""
    n = bounds.shape[0]
    if count[0] > 0:  # the root is a leaf: one node whose two children are that same leaf
        packed = np.empty((1, 12), np.float32)
        packed[0, :6] = bounds[0]
        packed[0, 6:] = bounds[0]
        kids = np.array([[child[0], child[0], count[0], count[0]]], np.int32)
        return packed, kids
    inner = np.full(n, -1, np.int64)
    k = 0
    for i in range(n):
        if count[i] == 0:
            inner[i] = k
            k += 1
    packed = np.empty((k, 12), np.float32)
    kids = np.empty((k, 4), np.int32)
    for i in range(n):
        if count[i] > 0:
            continue
        j = inner[i]
        for c in range(2):
            sub = i + 1 if c == 0 else np.int64(child[i])
            packed[j, 6 * c : 6 * c + 6] = bounds[sub]
            kids[j, c] = inner[sub] if count[sub] == 0 else child[sub]
            kids[j, 2 + c] = count[sub]
    return packed, kids


def build_bvh_from_triangles(triangles: np.ndarray) -> BVH:
    """Build a BVH over triangles (T, 3, 3) float32 vertex positions."""
    tri = np.ascontiguousarray(triangles, dtype=np.float32).reshape(-1, 3, 3)
    if len(tri) == 0:
        raise ValueError("cannot build a BVH over zero triangles")
    tri64 = tri.astype(np.float64)
    bounds, child, count, order, depth = _build(
        tri64.min(axis=1),
        tri64.max(axis=1),
        tri64.mean(axis=1),
        N_BINS,
        MAX_LEAF,
        TRAVERSAL_COST,
    )
    packed, kids = _pack(bounds, child, count)
    # One 64-byte-aligned record per node, seen both as float32 (boxes) and int32 (children).
    n = len(kids)
    raw = np.empty(n * 16 + 16, np.int32)
    start = (-raw.ctypes.data % 64) // 4
    nodes = raw[start : start + n * 16].reshape(n, 16)
    nodes[:, 12:] = kids
    records = nodes.view(np.float32)
    records[:, :12] = packed
    arrays = BVHArrays(
        bounds=records,
        kids=nodes,
        tri_verts=np.ascontiguousarray(tri[order].reshape(-1, 9)),
        tri_index=order,
    )
    return BVH(arrays=arrays, depth=int(depth))
