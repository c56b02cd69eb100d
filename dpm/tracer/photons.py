"""Photon tracing: paths from the lights, stored at every diffuse hit.

Photon path j is random stream j: dimensions 0–4 choose the light, the point and the
direction; bounce b uses dimensions 5 + 3b … 7 + 3b (Fresnel or roulette, then a direction or
roulette on long specular chains). Paths are traced in chunks, each path
into its own fixed slots, and compacted in path order, so the map does not depend on the
thread count, and paths a..b traced on their own equal the same paths of a longer run (a
progressive method's passes are consecutive slices of one stream).

Caustic-only tracing may aim the emitted direction at a sphere bounding the specular
surfaces (`guided`): a caustic path must hit a specular surface first, so nothing is lost,
and a reference spends its time on paths that can become caustics.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numba as nb
import numpy as np
from tqdm import tqdm

from dpm.scene import DIFFUSE, Scene
from dpm.tracer.bsdf import scatter_specular, specular_survival
from dpm.tracer.bvh import BVH
from dpm.tracer.lights import sample_light_point
from dpm.tracer.sampling import orthonormal_basis, sample_cosine, turn, uniform
from dpm.tracer.surface import albedo_at, next_surface
from dpm.tracer.traverse import new_stack, spawn_offset
from dpm.tracer.visible import RR_SPECULAR

# Paths of one parallel task, which allocates one traversal stack for them: one a path cost
# caustic photons, which mostly end at their first diffuse hit, 3-20 % of their time.
PATHS_PER_TASK = 64
MAX_BOUNCES = 256  # scattering events a photon path may have; Russian roulette ends most sooner
MAX_STORED = 32  # photons one path may store (its diffuse hits); the path ends there
PATHS_PER_CHUNK = 1 << 14


@dataclass(frozen=True)
class PhotonMap:
    """Photons stored at diffuse hits (struct of arrays), from `n_paths` emitted paths."""

    position: np.ndarray  # (P, 3) float32 world position
    direction: np.ndarray  # (P, 3) float32 unit direction towards where the photon came from
    flux: np.ndarray  # (P, 3) float32 RGB flux (W), already divided by n_paths
    normal: np.ndarray  # (P, 3) float32 unit geometric normal on the side the photon arrived
    caustic: np.ndarray  # (P,) bool: the path was L S+ D (specular bounces, no diffuse one)
    bounces: np.ndarray  # (P,) uint16 scattering events before this hit (0: straight from a light)
    path: np.ndarray  # (P,) int64 index of the emitted path that stored it
    n_paths: int  # emitted photon paths N

    def __len__(self) -> int:
        return len(self.caustic)

    def select(self, mask: np.ndarray) -> PhotonMap:
        """The photons where mask (P,) bool is set, from the same n_paths."""
        return PhotonMap(
            self.position[mask], self.direction[mask], self.flux[mask], self.normal[mask],
            self.caustic[mask], self.bounces[mask], self.path[mask], self.n_paths,
        )  # fmt: skip

    def first(self, n_paths: int) -> PhotonMap:
        """The photons of the first n_paths paths, as the map a run of n_paths would give."""
        if not 1 <= n_paths <= self.n_paths:
            raise ValueError(f"n_paths must be from 1 to {self.n_paths}")
        return self.split(n_paths)[0]

    def split(self, paths_per_pass: int) -> list[PhotonMap]:
        """Consecutive passes of paths_per_pass emitted paths each (the last may be shorter).

        Each pass is a photon map of its own: its flux is divided by its own path count.
        """
        if paths_per_pass < 1:
            raise ValueError("paths_per_pass must be at least 1")
        first = np.arange(0, max(self.n_paths, 1), paths_per_pass)
        cuts = np.searchsorted(self.path, np.append(first, self.n_paths))
        passes = []
        for i, p0 in enumerate(first):
            n = min(paths_per_pass, self.n_paths - p0)
            part = slice(cuts[i], cuts[i + 1])
            scale = np.float32(self.n_paths / max(n, 1))
            passes.append(
                PhotonMap(
                    self.position[part],
                    self.direction[part],
                    self.flux[part] * scale,
                    self.normal[part],
                    self.caustic[part],
                    self.bounces[part],
                    self.path[part] - p0,
                    n,
                )  # fmt: skip
            )
        return passes


@nb.njit(cache=True, inline="always", error_model="numpy")
def sample_emission(sc, lt, ox, oy, oz, guide, u1, u2):
    """(direction, cosθ at the light / its density in sr⁻¹) of an emitted photon.

    guide = (cx, cy, cz, radius) aims uniformly into the cone of that sphere when the light
    point lies outside it; radius < 0 (or a point inside) samples cosθ/π about the normal.
    """
    nx, ny, nz = sc.normals[lt, 0], sc.normals[lt, 1], sc.normals[lt, 2]
    wx, wy, wz = guide[0] - ox, guide[1] - oy, guide[2] - oz
    d2 = wx * wx + wy * wy + wz * wz
    r2 = guide[3] * guide[3]
    if guide[3] < 0 or d2 <= r2:
        dx, dy, dz = sample_cosine(nx, ny, nz, u1, u2)
        return dx, dy, dz, np.pi
    d = math.sqrt(d2)
    wx, wy, wz = wx / d, wy / d, wz / d
    cos_max = math.sqrt(1.0 - r2 / d2)
    one_minus = (r2 / d2) / (1.0 + cos_max)  # 1 − cosθmax without cancellation
    cos_t = 1.0 - u1 * one_minus
    sin_t = math.sqrt(max(0.0, 1.0 - cos_t * cos_t))
    ux, uy, uz, vx, vy, vz = orthonormal_basis(wx, wy, wz)
    c, s = turn(u2)
    x, y = sin_t * c, sin_t * s
    dx = x * ux + y * vx + cos_t * wx
    dy = x * uy + y * vy + cos_t * wy
    dz = x * uz + y * vz + cos_t * wz
    cos_light = dx * nx + dy * ny + dz * nz
    if cos_light <= 0:
        return dx, dy, dz, 0.0  # behind the light: this path carries nothing
    return dx, dy, dz, cos_light * 2.0 * np.pi * one_minus


@nb.njit(cache=True, parallel=True, error_model="numpy")
def photon_kernel(
    bvh, depth, sc, path0, n_paths, total, seed, eps, caustic_only, guide,
    position, direction, flux, normal, caustic, bounces, count,
):  # fmt: skip
    """Trace paths path0..path0+n_paths-1; path j fills slots [j, :count[j]] of the outputs.

    `total` is the number of paths of the whole map, which divides every photon's flux.
    """
    for task in nb.prange((n_paths + PATHS_PER_TASK - 1) // PATHS_PER_TASK):
        stack = new_stack(depth)
        for j in range(task * PATHS_PER_TASK, min(n_paths, (task + 1) * PATHS_PER_TASK)):
            stream = path0 + j
            count[j] = 0
            lt, ox, oy, oz, area_pdf = sample_light_point(
                sc, uniform(seed, stream, 0), uniform(seed, stream, 1), uniform(seed, stream, 2)
            )
            nx, ny, nz = sc.normals[lt, 0], sc.normals[lt, 1], sc.normals[lt, 2]
            dx, dy, dz, weight = sample_emission(
                sc, lt, ox, oy, oz, guide, uniform(seed, stream, 3), uniform(seed, stream, 4)
            )
            if weight == 0.0:
                continue
            # Flux Le·cos/(pdf_area·pdf_dir) per emitted path (Le·π/pdf_area for cosine sampling).
            e = sc.emission[sc.material[lt]]
            scale = weight / (area_pdf * total)
            fr, fg, fb = e[0] * scale, e[1] * scale, e[2] * scale
            f0 = max(fr, fg, fb)
            ox, oy, oz = ox + eps * nx, oy + eps * ny, oz + eps * nz
            specular = diffuse = False
            for b in range(MAX_BOUNCES + 1):
                tri, t, px, py, pz, nx, ny, nz, m, cos_i, front = next_surface(
                    bvh, sc, ox, oy, oz, dx, dy, dz, stack
                )
                if tri < 0:
                    break
                dim = 5 + 3 * b
                if sc.kind[m] == DIFFUSE:
                    is_caustic = specular and not diffuse
                    if is_caustic or not caustic_only:
                        k = count[j]
                        position[j, k, 0], position[j, k, 1], position[j, k, 2] = px, py, pz
                        direction[j, k, 0], direction[j, k, 1], direction[j, k, 2] = -dx, -dy, -dz
                        flux[j, k, 0], flux[j, k, 1], flux[j, k, 2] = fr, fg, fb
                        normal[j, k, 0], normal[j, k, 1], normal[j, k, 2] = nx, ny, nz
                        caustic[j, k] = is_caustic
                        bounces[j, k] = b
                        count[j] = k + 1
                    if caustic_only or count[j] == MAX_STORED:
                        break  # caustic_only: no later photon of this path can be a caustic one
                    # Russian roulette by the albedo keeps the flux of surviving photons unchanged.
                    ar, ag, ab = albedo_at(sc, m, tri, px, py, pz)
                    q = max(ar, ag, ab)
                    if b == MAX_BOUNCES or uniform(seed, stream, dim) >= q:
                        break
                    fr, fg, fb = fr * ar / q, fg * ag / q, fb * ab / q
                    dx, dy, dz = sample_cosine(
                        nx, ny, nz, uniform(seed, stream, dim + 1), uniform(seed, stream, dim + 2)
                    )
                    ox, oy, oz = px + eps * nx, py + eps * ny, pz + eps * nz
                    diffuse = True
                else:
                    if b == MAX_BOUNCES:
                        break
                    if b >= RR_SPECULAR:  # total internal reflection can trap a photon in glass
                        q = specular_survival(sc, m, front, max(fr, fg, fb), f0, False)
                        if uniform(seed, stream, dim + 1) >= q:
                            break
                        fr, fg, fb = fr / q, fg / q, fb / q
                    u = uniform(seed, stream, dim)
                    dx, dy, dz, wr, wg, wb, side = scatter_specular(
                        sc, m, dx, dy, dz, nx, ny, nz, cos_i, front, u, False
                    )
                    fr, fg, fb = fr * wr, fg * wg, fb * wb
                    ox, oy, oz = px + side * eps * nx, py + side * eps * ny, pz + side * eps * nz
                    specular = True


def trace_photons(
    scene: Scene,
    bvh: BVH,
    n_paths: int,
    seed: int = 0,
    caustic_only: bool = False,
    progress: bool = False,
    first_path: int = 0,
    guided: bool = False,
) -> PhotonMap:
    """Emit n_paths photon paths from the scene's lights and store their diffuse hits.

    The paths are numbers first_path … first_path + n_paths − 1 of the seed's stream; the
    map's `path` counts from 0. `guided` (caustic_only only) aims emission at the specular
    surfaces' bounding sphere.
    """
    if guided and not caustic_only:
        raise ValueError("guided emission finds caustic photons only; pass caustic_only=True")
    sc, eps = scene.kernel_arrays(), spawn_offset(scene)
    guide = specular_bounding_sphere(scene) if guided else np.array([0.0, 0.0, 0.0, -1.0])
    parts: list[tuple[np.ndarray, ...]] = []
    slots = 1 if caustic_only else MAX_STORED
    with tqdm(total=n_paths, unit="path", disable=not progress, desc="photons") as bar:
        for path0 in range(0, max(n_paths, 1), PATHS_PER_CHUNK):  # one empty chunk for 0
            n = min(PATHS_PER_CHUNK, n_paths - path0)
            pos, dirs, flux, nrm = (np.zeros((n, slots, 3), np.float32) for _ in range(4))
            caustic = np.zeros((n, slots), np.bool_)
            bounces = np.zeros((n, slots), np.uint16)
            count = np.zeros(n, np.int32)
            photon_kernel(
                bvh.arrays, bvh.depth, sc, first_path + path0, n, n_paths, seed, eps,
                caustic_only, guide, pos, dirs, flux, nrm, caustic, bounces, count,
            )  # fmt: skip
            used = np.arange(slots)[None, :] < count[:, None]  # (n, slots), path-major order
            path = np.broadcast_to(np.arange(path0, path0 + n)[:, None], used.shape)
            parts.append(tuple(a[used] for a in (pos, dirs, flux, nrm, caustic, bounces, path)))
            bar.update(n)
    cols = [np.concatenate(c) for c in zip(*parts, strict=True)]
    return PhotonMap(*cols[:6], cols[6].astype(np.int64), n_paths)


def specular_bounding_sphere(scene: Scene) -> np.ndarray:
    """(4,) float64 centre and radius of a sphere holding every specular triangle (−1: none),
    `Scene.specular_sphere` grown by rounding's margin and the spawn offset."""
    sphere = scene.specular_sphere
    if sphere[3] < 0:
        return sphere.copy()
    return np.append(sphere[:3], sphere[3] * (1 + 1e-6) + spawn_offset(scene))


def aimed_share(scene: Scene) -> float:
    """Share (0-1) of emitted photon paths that guided emission aims: those leaving emitter
    triangles whose centre lies outside `specular_bounding_sphere` (from inside it, emission
    keeps the light's cosine)."""
    guide = specular_bounding_sphere(scene)
    if guide[3] < 0:
        return 0.0
    sc = scene.kernel_arrays()
    picked = np.diff(sc.emitter_cdf, prepend=0.0)  # each emitter's share of the light samples
    centre = sc.triangles[sc.emitter_triangles].astype(np.float64).mean(axis=1)
    outside = ((centre - guide[:3]) ** 2).sum(axis=1) > guide[3] ** 2
    return float(picked[outside].sum())
