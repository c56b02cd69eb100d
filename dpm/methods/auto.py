"""`auto`, the default: a render in passes that spends a time budget where the scene needs it.

Every pass traces one camera sample per pixel, path-traces it without the caustics and, when
the plan keeps caustics, traces a pass of photon paths into SPPM's per-pixel statistics at
the same visible points (Hachisuka & Jensen 2009): consistent, so every pass makes the image
better. The pass's photons also give the caustic light at the path's later diffuse vertices
(a density estimate from a hashed grid, in place of the BSDF-sampled paths that reach a light
through glass or a mirror from there: the fireflies of light that a caustic throws onto a
surface the camera sees by a diffuse bounce); its radius shrinks pass by pass as in
probabilistic PPM (Knaus & Zwicker 2011), so that estimate is consistent too. After a few
passes, each pass also spends extra camera paths where pixels vary most (adaptive sampling,
`dpm.methods.adaptive`, cross-fitted so the image stays unbiased).
`--time` renders passes until the budget (counted from the process start) would be overrun;
without it `--spp` passes are rendered with `--photons` paths in all. The kernels that only
later passes of the plan call are compiled (or loaded from Numba's cache) in the first pass
(`warm_later_kernels`), so no later pass of a budgeted render stops to compile.

The plan is made after the first pass, from what it found (deterministic: same seed, same
plan): no photons where the scene has no mirror or glass, or where the first pass's photons
add no caustic light to the image; otherwise photon paths per pass in proportion to the
pixels. The caustic estimator is SPPM at two radii per pixel: a pixel takes the narrower
one's estimate where the wider one's blur shows beyond its noise (a sharp caustic's peak),
else the wider one's (`sharper_where_biased`), and sparse pixels are spread (`spread_sparse`).
Where the plan keeps caustics, a learned filter (`dpm.caustic.forward`: a small screen-space
network that weighs each pixel's neighbours' estimates at both radii and several scales, from
their photon counts and the guides) then replaces that estimate by one held within CLAMP_Z
standard errors of it, so the render stays consistent whatever the network says;
`--no-network` leaves it out, and so does the plan where its predicted time would be over
NETWORK_SHARE of the budget. The per-point networks (DPM, nppm) are not used: at equal time
their cost is not repaid (benchmarks/results/dpm.md). The caustic image goes through
the denoiser (albedo and normal guides) with the path-traced one, and `restore_certain` undoes
the denoiser wherever it moved a pixel by more than the pixel's standard error (its paths',
its light seen's and its caustic's, the last 1/√(its photon count) of the larger of its own
value and what the denoiser leaves its caustic): after a few passes the
denoiser smooths the caustics' photon noise, while a caustic known well keeps its own sharp
estimate (the denoiser would smear it, or paint blotches where it meets glass or shadow). As
passes add photons and paths every pixel's error shrinks, so the render stays consistent.
In scenes with mirrors or glass, the light the camera sees along its specular chains (a
small light's images in them, specks that may cover a hundredth of a pixel) is estimated
apart from the paths, from EMISSION_SAMPLES more camera samples per pass in each pixel that
sees a mirror or glass (stratified over the pixel across passes) and more placed by adaptive
sampling; where it is known to SEEN_ERROR it is added after the denoiser (which takes such
specks for noise), elsewhere it goes through the denoiser with the paths.
"""

from __future__ import annotations

import time
from contextlib import nullcontext
from dataclasses import dataclass
from typing import Any, ClassVar

import numba as nb
import numpy as np
from tqdm import tqdm

from dpm import collector
from dpm.camera import Camera
from dpm.caustic import forward as caustic_forward
from dpm.caustic.blend import blend_weights
from dpm.caustic.halves import PassHalves
from dpm.caustic.stats import (
    CLAMP_Z,
    FIRST_BLUR_RATIO,
    CausticStats,
    extrapolated,
    extrapolation,
    f64,
    nested_photons,
)
from dpm.denoise import denoise, guides, restore_certain
from dpm.density.base import luminance
from dpm.density.gather import PointIndex
from dpm.density.progressive import pass_seed
from dpm.errors import InputError
from dpm.estimators.ppm import ALPHA, PPMState, check_progressive
from dpm.estimators.sppm import sppm_gather
from dpm.filters import box_mean
from dpm.methods.adaptive import ADAPT_AFTER, EXTRA_CAP, EXTRA_PER_PIXEL, Halves
from dpm.methods.base import Method, check_photons
from dpm.options import RenderOptions
from dpm.scene import Scene
from dpm.stopwatch import Stopwatch
from dpm.tracer import (
    BVH,
    VisiblePoints,
    shade,
    specular_pixels,
    trace_emitted,
    trace_listed,
    trace_photons,
    trace_pixel_sums,
    trace_visible_points,
)
from dpm.tracer.photon_grid import PhotonGrid, photon_grid
from dpm.tracer.photons import aimed_share
from dpm.tracer.sampling import sequence_seed

RADIUS_FOOTPRINTS = 2.0  # initial radius per pixel, in pixel footprints at its first point
# Photon paths per pass per pixel when the plan keeps caustics (`paths_per_pixel`). The paths
# are emitted into the cone of a sphere bounding the mirrors and glass (`trace_photons(guided=
# True)`): a caustic path must meet one of them first, so no caustic photon is lost, and a
# path finds 3-30 times the caustic photons of one emitted by the light's cosine (the
# examples). Aimed paths: 2 (chosen on the examples at equal time, 2-8 s: caustic RMSE 0.91 of
# unaimed emission at 4 paths, against 0.94 at 1 and 0.98 at 4; docs/benchmarks.md). From a
# light inside the sphere nothing is aimed, and 4 stays (tuned before: benchmarks/
# auto_tuning.py, best on the ring, tied on glass egg, pool1 and dragon). On the unseen scenes
# these counts are within 5 % of each scene's best of 1, 2, 4, 8 (benchmarks/paths_per_pass.py).
PHOTONS_PER_PIXEL, AIMED_PHOTONS_PER_PIXEL = 4.0, 2.0
GRID_RADII = 4.0  # first radius at later diffuse vertices, in median first-pass pixel radii
# Extra camera samples per pass of the light seen in mirrors and glass, per pixel that sees
# them (each pixel's run through its own stratified sequence, `trace_emitted`), and
# EMISSION_EXTRA per such pixel more placed by adaptive sampling (at most EMISSION_CAP on one
# pixel): a light's image there can be a speck covering a hundredth of a pixel, which one
# path per pass finds by luck (the glass egg's worst pixels). 16: the egg's and the dragon's
# RMSE at 2 s fall by a sixth from 8, the other scenes' rise by 0-5 % (fewer passes).
EMISSION_SAMPLES, EMISSION_EXTRA, EMISSION_CAP = 16, 8, 256
# A second SPPM estimate at NARROW times the radius; a pixel takes it where it differs from
# the wide one's by more than LEPSKI_Z standard errors (`sharper_where_biased`). Measured on
# the caustic component at the passes of --time 2 (caustic RMSE, seeds 1-2, wide -> chosen):
# pool2 0.138 -> 0.103, glass egg 0.107 -> 0.097, torus 0.089 -> 0.089, dragon 0.091 ->
# 0.090; ring, pool1, red wine unchanged. At z = 1.5: pool2 0.093, pool1 and red wine 1-2 %
# worse; a third radius (a quarter) gained nothing.
NARROW, LEPSKI_Z = 0.5, 2.0
# The halves' blend (`Passes.blend`) fits its weights against the other half's extrapolated
# estimate (`dpm.caustic.stats.extrapolated`: blur cancelled to second order), not its
# narrow one, whose blur the fit would otherwise take for the truth
EXTRAPOLATED_TARGET = True
# ... and weighs a move towards the extrapolated estimate beside the narrow one's (both
# switches are for `benchmarks/blend_target.py`, which measured them)
EXTRAPOLATED_MOVE = True
# ... whose blur ratio is each pixel's own (`Passes.blur_ratio`), not the first pass's 1/4
# (a switch for `benchmarks/blend_target.py --switch ratio`)
PIXEL_BLUR_RATIO = True
SEEN_ERROR = 0.6  # relative standard error of a pixel's light seen below which it skips
# the denoiser
# A pixel's caustic from fewer photons than this (relative error 1/√N above SEEN_ERROR) is
# spread over the smallest window, of SPREAD_WINDOWS, whose sparse pixels hold that many.
SPARSE_PHOTONS, SPREAD_WINDOWS = 1.0 / SEEN_ERROR**2, (3, 5, 9, 17, 33)
# Camera paths a pass of whole pixels (a scene without mirrors or glass) holds at most. Passes
# there start at one path per pixel and double, pair by pair, to this: a pixel's paths traced
# one after another share their first rays' cache lines (from 1 to 8 paths per pixel per
# kernel call, samples/s rose 1.17x at 128² and 1.32x at 256² on the Cornell box), and each
# pass spends some milliseconds in NumPy between kernels (adaptive sampling's plan, the
# halves' sums). 8 paths per pixel at 128², 1 from 512² (where a pass is long already).
PASS_SAMPLES = 1 << 17
MIN_CAUSTIC_SHARE = 1e-3  # caustics under this share of the first pass's light are left out
# Seconds kept for what follows the last pass: a fixed part, per pixel for writing (EXR and
# PNG: 0.15 s at 512²) and, where the image is denoised, FINISH_MARGIN times the denoiser
# calls to come (one; two more where `Passes.denoiser_share` will run) and the rest of the
# finish (restore, error maps: REST_CALLS calls' worth of the faster filter), at what a call
# takes on this machine now (`Passes.time_denoiser`, after the first pass;
# `Passes.finish_reserve`). Measured on the idle 2-core host: OIDN 0.63-0.72 µs per pixel,
# 2.3 times that beside two busy processes, the rest 0.9-1.4 µs (Zen 4; on Zen 5 0.4 µs at
# 512², 0.75 of a call without clean guides); a fixed 9 µs per pixel (the guess before) kept
# 1-1.5 s of a 512² render's budget idle.
FINISH_SECONDS, WRITE_SECONDS_PER_PIXEL, FINISH_MARGIN, REST_CALLS = 0.03, 6e-7, 1.25, 1.5
SQRT2 = np.sqrt(2.0)  # a half's standard error per pixel, in the whole image's
# Paths per pixel from which the denoiser's guides count as free of noise (OIDN's cleanAux)
# in a scene without mirrors or glass (its guides vary only with where a path enters the
# pixel). Chosen on the examples (`auto --spp N`, 128², seeds 1-3, RMSE against the
# equal-time references, OIDN as it was -> clean guides): the Cornell box at 1, 2, 4, 8, 16,
# 64, 256 paths 0.732 -> 0.864, 0.663 -> 0.681, 0.573 -> 0.566, 0.286 -> 0.253, 0.103 ->
# 0.096, 0.0230 -> 0.0218, 0.0116 -> 0.0112. Behind glass the guides stay noisy far longer
# (the dragon at 2 and 8 paths +20 % and +2 %, the red wine +29 % and +11 %, mixed at 32
# paths): there it is left off.
CLEAN_GUIDE_PATHS = 8
# The learned caustic filter's seconds (a fixed part and per pixel) on 2 cores, and the most
# of a --time budget it may take: past it the plan leaves it out. Measured whole-process
# (`dpm-render --component caustic --time 4 --network`, glass egg, pool2, dragon, torus; Zen 4,
# idle): 0.046-0.055 s at 128², 0.10-0.12 at 256², 0.22-0.28 at 384², 0.53-0.56 at 512² (its
# arrays outgrow the caches). The prediction keeps the budget's reserve for it: 4 µs a pixel,
# as before the filter's statistics moved into Numba, left 0.15 s of a 2-s render at 256² idle.
NETWORK_SECONDS, NETWORK_SECONDS_PER_PIXEL, NETWORK_SHARE = 0.02, 2e-6, 0.15


@dataclass
class Plan:
    """What the render spends its passes on, and why."""

    caustics: str  # "sppm" or "off"
    photons_per_pass: int  # emitted photon paths per pass after the first (0: none)
    reason: str  # one line for the summary and the stats JSON
    network: bool = False  # the learned caustic filter on SPPM's statistics

    def as_dict(self) -> dict[str, Any]:
        """The plan for the stats JSON."""
        return {"caustics": self.caustics, "photons_per_pass": self.photons_per_pass,
                "network": self.network, "reason": self.reason}  # fmt: skip


def network_seconds(pixels: int) -> float:
    """The learned caustic filter's predicted seconds for an image of `pixels` pixels."""
    return NETWORK_SECONDS + NETWORK_SECONDS_PER_PIXEL * pixels


def plan_network(
    plan: Plan, wanted: bool | None, pixels: int, budget: float | None, shipped: bool = True
) -> Plan:
    """The plan with the learned caustic filter (`dpm.caustic.forward`) where it keeps
    caustics, unless --no-network, the filter's predicted time is over NETWORK_SHARE of the
    --time budget (and --network was not given), or the default weights are missing
    (`shipped` False: an install without them renders as --no-network, and says so)."""

    def without(why: str) -> Plan:
        return Plan(plan.caustics, plan.photons_per_pass, f"{plan.reason}; no network ({why})")

    if plan.caustics == "off":
        return plan
    if wanted is False:
        return without("--no-network")
    cost = network_seconds(pixels)
    if wanted is None and budget is not None and cost > NETWORK_SHARE * budget:
        return without(f"its {cost:.2f} s would be over {NETWORK_SHARE:.0%} of the budget")
    if not shipped:
        return without(f"no weights at {caustic_forward.SHIPPED}")
    return Plan(plan.caustics, plan.photons_per_pass, plan.reason + "; learned caustic filter",
                network=True)  # fmt: skip


def has_specular(scene: Scene) -> bool:
    """Whether any triangle is a mirror or glass (else no light path has a caustic)."""
    return not scene.all_diffuse


def make_plan(
    scene: Scene,
    pixels: int,
    path_light: float,
    caustic_light: float,
    per_pass: int | None,
    why: str = "--photons-per-pass",
) -> Plan:
    """The plan after the first pass, from the light (sum over pixels of the mean RGB) its
    path samples and its photons put in the image; `per_pass` (given `why`) overrides the
    planned photon paths per pass."""
    if not has_specular(scene):
        return Plan("off", 0, "no mirror or glass in the scene: no caustics to trace")
    share = caustic_light / max(path_light + caustic_light, 1e-30)
    if share < MIN_CAUSTIC_SHARE:
        return Plan(
            "off", 0, f"the first pass's photons gave {share:.2%} of the light: caustics left out"
        )
    per_pixel = paths_per_pixel(scene)
    n = per_pass or max(1, round(per_pixel * pixels))
    why = why if per_pass else f"{per_pixel:g} per pixel"
    return Plan("sppm", n, f"caustics are {share:.1%} of the first pass's light: sppm, "
                f"{n:,} photon paths per pass ({why})")  # fmt: skip


def paths_per_pixel(scene: Scene) -> float:
    """Photon paths per pixel per pass: AIMED_PHOTONS_PER_PIXEL for the share of paths that
    guided emission aims (`aimed_share`), PHOTONS_PER_PIXEL for the rest."""
    aimed = aimed_share(scene)
    return aimed * AIMED_PHOTONS_PER_PIXEL + (1.0 - aimed) * PHOTONS_PER_PIXEL


def pixel_footprints(points: VisiblePoints, camera: Camera) -> np.ndarray:
    """(pixels,) float64 pixel width (scene units) at the distance of each pixel's first
    visible point (straight from the camera; pixels that see nothing get the median): the
    initial radius is RADIUS_FOOTPRINTS of them, so the kernel starts as wide as a few
    pixels wherever it is seen."""
    width = camera.footprint(points.position)
    seen = points.hit & (width > 0)
    fill = np.median(width[seen]) if seen.any() else 1.0 / RADIUS_FOOTPRINTS
    return np.where(seen, width, fill)


def warm_first_kernels(scene: Scene, bvh: BVH, camera: Camera) -> None:
    """Load from Numba's cache (or compile) the kernels a first pass calls, on a 2 × 2 image
    with the types the pass passes. Each kernel's first call loads it: a first pass took 4-5
    times a later one (0.30-0.38 s against 0.07-0.08 s on the unseen spheres and vase), and
    judged by it, a 2-s budget stopped after one pass where it had room for several."""
    tiny, sequence = camera.with_resolution(2, 2), (0, 0)
    Halves(2, 2).plan_extra(0, 1, 1)  # adaptive sampling's neighbourhood means
    if not has_specular(scene):  # the plan is made before the first pass: whole pixels
        trace_pixel_sums(scene, bvh, tiny, 1, 0, sequence)
        return
    points = trace_visible_points(scene, bvh, tiny, 1, 0, (0, 2), sequence)
    photons = trace_photons(scene, bvh, 256, 0, caustic_only=True, guided=True)
    shade(scene, bvh, points, 0, False, photon_grid(photons, 1.0), sequence)
    pixels = np.arange(4, dtype=np.int64)
    trace_emitted(scene, bvh, tiny, pixels, 1, 0, 0)
    states = (PPMState.start(4, 1.0, ALPHA), PPMState.start(4, 1.0, ALPHA))
    halves = PassHalves.start(2, 4)
    halves.mark(states)
    sppm_gather(states, points, photons, Stopwatch())  # (photons to spare: `disc_sums`)
    halves.add(0, states, 256)
    hit = points.hit  # the pairs, which a pass of few photons per pixel gathers through
    PointIndex(points.position[hit], points.normal[hit]).within(photons, np.ones(hit.sum()))
    box_mean(np.zeros((2, 2)), 3)  # (the finish's: a budget's reserve holds no compiling)
    rgb, zero = np.ones((4, 3)), np.zeros(4)  # the finish's caustic estimate, as `caustics`
    spread = spread_sparse(rgb, zero, np.ones(4), 2, 2)
    held_move(CausticStats(2, 2, 1, rgb, rgb, zero, zero, rgb, zero, *spread, zero, zero, zero,
                           rgb, rgb), rgb, 0.0)  # fmt: skip


def warm_later_kernels(
    scene: Scene,
    bvh: BVH,
    camera: Camera,
    points: VisiblePoints | None,
    grid: PhotonGrid | None,
    adapt: bool,
) -> None:
    """Compile (or load from Numba's cache), on no samples and with the types later passes of
    the plan pass, the kernels that only they call: shading without a photon grid (grid None,
    after a first pass's `points`: the plan left caustics out) and, with `adapt`, adaptive
    sampling's paths (from pass ADAPT_AFTER; points None: whole pixels, the light seen
    included). A pass that first reached them would stop to compile (minutes), past any budget
    and after shorter renders had cached everything else."""
    if points is not None and grid is None:
        shade(scene, bvh, points.select(np.zeros(len(points), bool)), 0, False, None)
    if adapt:
        none = np.zeros(1, np.int64)  # one pixel given no paths: the kernel runs no task
        trace_listed(scene, bvh, camera, none, none, 0, grid, points is None)


def sharper_where_biased(
    wide: PPMState, narrow: PPMState, z: float
) -> tuple[np.ndarray, np.ndarray]:
    """(P, 3) float64 caustic radiance per pixel and (P,) bool where it is the narrow kernel's:
    the narrow estimate where it differs from the wide one's by more than z standard errors
    (the wide kernel's blur shows: a sharp caustic), else the wide one's (Lepski's rule for
    choosing a kernel's bandwidth, with two). A PPM estimate's relative standard error is
    taken as 1 / √(its photon count), of the larger of the two values (so a narrow kernel
    that found no photon, reading 0, is not taken for exact); both are consistent, so the
    choice is."""
    a, b = wide.irradiance(), narrow.irradiance()
    la, lb = luminance(a), luminance(b)
    scale = np.maximum(la, lb)
    se = scale * np.sqrt(1 / np.maximum(wide.count, 1) + 1 / np.maximum(narrow.count, 1))
    sharp = np.abs(lb - la) > z * se
    return np.where(sharp[:, None], b, a), sharp


def held_move(stats: CausticStats, estimate: np.ndarray, z: float) -> np.ndarray:
    """(P, 3) float64 move from the caustic estimate (`stats.spread`) to `estimate` (P, 3),
    held, where the pixel is sparse, within z standard errors of the spread estimate (its
    brightest channel over √ its window's photons, for every channel; z = 0: no move there).
    There `spread_sparse` has replaced a lone photon's speck by its window's mean, and an
    estimate that reads the pixel's own photons (the narrow kernel, the learned filter)
    would paint the speck back: the filter did, some 50 specks on the floor of the glass
    egg's default render (2026-11-29). As passes add photons no pixel stays sparse: the move
    is the estimate's."""
    move = f64(estimate - stats.spread)
    _hold_sparse(move, f64(stats.spread), f64(stats.own_count), f64(stats.spread_count), float(z))
    return move


@nb.njit(cache=True, parallel=True, error_model="numpy")
def _hold_sparse(
    move: np.ndarray, spread: np.ndarray, count: np.ndarray, behind: np.ndarray, z: float
) -> None:  # fmt: skip
    """`held_move`'s hold, in place on move (P, 3), at the pixels whose count (P,) is below
    SPARSE_PHOTONS: one share for the three channels, from the brightest spread (P, 3) channel
    (a channel the light lacks, 0 there, would otherwise hold the whole move at 0; the
    running box sums leave -1e-17 where the image is dark: radiance is never negative) over
    √ its window's photons behind (P,); a move that is not finite (or 0·inf) held at 0."""
    for i in nb.prange(move.shape[0]):
        if not count[i] < SPARSE_PHOTONS:
            continue
        brightest = max(max(spread[i, 0], spread[i, 1], spread[i, 2]), 0.0)
        allowed = z * brightest / np.sqrt(max(behind[i], 1.0))
        reach = allowed
        for c in range(3):
            a = abs(move[i, c])
            if a != a:  # NaN: nothing to keep the share by (held to 0 below)
                reach = a
                break
            reach = max(reach, a)
        keep = allowed / reach if reach > 0 else 1.0
        for c in range(3):
            held = keep * move[i, c]
            move[i, c] = held if np.isfinite(held) else 0.0


def half_state(halves: PassHalves, half: int, k: int, like: PPMState) -> PPMState:
    """A PPM state whose estimate is half `half`'s of kernel `k` (`PassHalves`), at the radii
    of `like` (the whole run's state of that kernel) and its count (α·found, as PPM counts)."""
    paths = max(int(halves.paths[half]), 1)
    tau = halves.flux[half, k] * (np.pi * like.radius**2)[:, None]
    return PPMState(like.radius, like.alpha * halves.found[half, k], tau, paths=paths,
                    passes=int(halves.passes[half]), alpha=like.alpha)  # fmt: skip


def extrapolated_move(stats: CausticStats) -> np.ndarray:
    """(P, 3) float64 `held_move` towards the extrapolated estimate (no move at sparse
    pixels), or zeros (a move the blend gives no weight) without EXTRAPOLATED_MOVE."""
    if not EXTRAPOLATED_MOVE:
        return np.zeros((len(stats.spread), 3))
    return held_move(stats, extrapolated(stats.wide, stats.narrow, stats.blur_ratio), 0.0)


def spread_sparse(
    caustic: np.ndarray, count: np.ndarray, overlap: np.ndarray, h: int, w: int
) -> tuple[np.ndarray, np.ndarray]:
    """(P, 3) float64 caustic radiance per pixel with the sparse pixels' estimates spread,
    and (P,) the photons behind each (`count`, or at a sparse pixel its window's):
    a pixel whose disc holds fewer than SPARSE_PHOTONS photons (a relative standard error
    above SEEN_ERROR: stray light refracted far from the caustic, which one photon paints as
    a speck the shape of the kernel) takes the mean of the sparse pixels of the smallest
    square window, of SPREAD_WINDOWS, that holds SPARSE_PHOTONS (each pixel's count over
    `overlap` (P,), the pixels a photon's discs cover, so a photon counts once); the pixels
    with photons enough are neither changed nor averaged in (a caustic's edge does not
    bleed). As passes
    add photons every pixel's count passes SPARSE_PHOTONS, so the estimate stays
    consistent."""
    sparse = count < SPARSE_PHOTONS
    if not sparse.any():
        return caustic, count
    out, behind = f64(caustic).copy(), f64(count).copy()
    _spread(out, behind, f64(overlap), h, w, np.array(SPREAD_WINDOWS, np.int64))
    return out, behind


@nb.njit(cache=True, error_model="numpy")
def _spread(
    caustic: np.ndarray, count: np.ndarray, overlap: np.ndarray, h: int, w: int,
    windows: np.ndarray,
) -> None:  # fmt: skip
    """`spread_sparse` in place on caustic (P, 3) and count (P,), from summed-area tables of
    the sparse pixels (1 each), their photons (count / overlap) and their radiance: each
    window's sums are four reads, so a pixel tries the windows in turn for the cost of one
    (running box sums over the whole image per window took 18 ms a call at 256²). The
    tables are summed in one order, whatever the threads."""
    table = np.zeros((h + 1, w + 1, 5))  # sparse pixels, photons, red, green, blue
    for y in range(h):
        for x in range(w):
            i = y * w + x
            if count[i] < SPARSE_PHOTONS:
                add = (1.0, count[i] / max(overlap[i], 1.0), caustic[i, 0], caustic[i, 1],
                       caustic[i, 2])  # fmt: skip
            else:
                add = (0.0, 0.0, 0.0, 0.0, 0.0)
            for c in range(5):
                table[y + 1, x + 1, c] = (add[c] + table[y, x + 1, c] + table[y + 1, x, c]
                                          - table[y, x, c])  # fmt: skip
    last = len(windows) - 1
    for y in range(h):
        for x in range(w):
            i = y * w + x
            if not count[i] < SPARSE_PHOTONS:
                continue
            for k in range(len(windows)):
                half = windows[k] // 2
                y0, y1 = max(0, y - half), min(h, y + half + 1)
                x0, x1 = max(0, x - half), min(w, x + half + 1)
                found = _box(table, y0, y1, x0, x1, 1)
                if found >= SPARSE_PHOTONS or k == last:
                    n = _box(table, y0, y1, x0, x1, 0)  # ≥ 1: the pixel itself
                    for c in range(3):
                        caustic[i, c] = _box(table, y0, y1, x0, x1, 2 + c) / n
                    count[i] = found
                    break


@nb.njit(cache=True, inline="always")
def _box(table: np.ndarray, y0: int, y1: int, x0: int, x1: int, c: int) -> float:
    """Sum of channel c over rows [y0, y1) and columns [x0, x1) from a summed-area table."""
    return table[y1, x1, c] - table[y0, x1, c] - table[y1, x0, c] + table[y0, x0, c]


class Auto(Method):
    """Path samples and SPPM photon passes, planned per scene, until the time budget."""

    name = "auto"
    summary = "the default: passes of path samples + SPPM caustics, planned per scene, until --time"
    options = frozenset({"time", "radius", "photons_per_pass", "network", "weights"})
    denoise = True
    renders_image: ClassVar[bool] = True

    @classmethod
    def check(cls, options: RenderOptions) -> None:
        """At least one photon path, a positive --time, --radius and --photons-per-pass, and
        --weights that are a caustic filter's."""
        check_photons(options)
        if options.time is None and options.photons_per_pass is not None:
            raise InputError("--photons-per-pass applies to auto with --time only (without it,"
                             " --spp passes share --photons paths)")  # fmt: skip
        if options.time is not None and not (np.isfinite(options.time) and options.time > 0):
            raise InputError(f"--time must be a positive number of seconds (got {options.time})")
        radius, per_pass = options.radius, options.photons_per_pass
        check_progressive(1.0 if radius is None else radius, per_pass or 1, ALPHA)
        if options.weights is not None:
            if options.network is False:
                raise InputError("--weights are the caustic filter's: no use with --no-network")
            caustic_forward.load_filter(options.weights)  # a bad file fails before any pass

    def render_image(
        self, bvh: BVH, camera: Camera, watch: Stopwatch, started: float
    ) -> tuple[np.ndarray, dict[str, Any]]:
        """(H, W, 3) float32 linear RGB and the plan's stats: passes until the budget, each
        `Passes.run_pass` (camera samples, photons, the light seen, adaptive samples), the plan
        after the first, then `Passes.finish` (the caustic estimate, denoising, composing)."""
        passes = Passes(self, bvh, camera, watch, started)
        while True:
            passes.run_pass()
            if passes.done():
                break
        image = passes.finish()
        return image, self.stats()

    def stats(self) -> dict[str, Any]:
        """Passes, the plan, caustic photons, dropped samples, adaptive paths, the pixels
        given extra samples of the light seen in mirrors and glass (and those samples), the
        pixels whose caustic is the narrow kernel's, the first pass's seconds (and those
        before it), whether the first pass alone overran the budget, and whether the image
        is the denoised one and its weight in the blend with the plain mean
        (`Passes.denoiser_share`), and the weights of the caustic's moves towards the narrow
        kernel's estimate, the extrapolated one and the learned filter's (`Passes.blend`; 0
        where not made)."""
        return {
            "passes": self.passes, "plan": self.plan.as_dict(), "spp": self.spp,
            "caustic_photons": self.caustic_photons, "nonfinite_samples": self.dropped,
            "extra_paths": self.extra_paths, "light_pixels": self.light_pixels,
            "light_samples": max(self.light_samples, 0), "sharp_pixels": self.sharp_pixels,
            "pass_seconds": self.pass_seconds, "setup_seconds": self.setup_seconds,
            "overran": self.overran, "denoised": self.denoised,
            "denoiser_share": self.denoiser_share, "narrow_weight": self.narrow_weight,
            "extrapolated_weight": self.extrapolated_weight, "network_weight": self.network_weight,
        }  # fmt: skip


class Passes:
    """One `auto` render's passes: what they accumulate and the stages of each, in order."""

    def __init__(
        self, method: Auto, bvh: BVH, camera: Camera, watch: Stopwatch, started: float
    ) -> None:
        o, scene = method.options, method.scene
        self.method, self.o, self.scene, self.bvh, self.camera = method, o, scene, bvh, camera
        self.watch = watch
        self.w, self.h = camera.width, camera.height
        self.pixels = self.w * self.h
        self.full = o.component == "full"
        self.state = PPMState.start(self.pixels, o.radius or 1.0, ALPHA)  # radii: first pass
        self.narrow = PPMState.start(self.pixels, 1.0, ALPHA)  # the same at NARROW × its radii
        # what each pass gathered alone, in two halves of the passes (`blend`)
        self.halves = PassHalves.start(2, self.pixels)
        self.paths = Halves(self.h, self.w)
        self.extra_paths = 0
        # the denoiser's guides per half (albedo, normal sums of its passes): a half checked
        # alone (`denoiser_share`) must not be guided by the other half's samples
        self.guide_sums = np.zeros((2, 2, self.pixels, 3))
        self.deadline = None if o.time is None else started + o.time
        self.separate = has_specular(scene)  # the light seen apart from the paths: see below
        self.denoising = self.full and method.denoises(o)
        # seconds a denoiser call takes, without and with clean guides (`time_denoiser`)
        self.call = (0.0, 0.0)
        # the finish's part that does not depend on when the render stops (`finish_reserve`)
        self.finish_seconds = FINISH_SECONDS + WRITE_SECONDS_PER_PIXEL * self.pixels
        # Photon paths per pass: without a budget, --photons shared by the --spp passes; with
        # one, --photons-per-pass or the plan's (the first pass already uses it, so a --time
        # render of N passes of P paths is the render with --spp N --photons N·P).
        if o.time is None:
            self.given, self.why = max(1, o.photons // o.spp), "--photons / --spp"
        else:
            self.given, self.why = o.photons_per_pass, "--photons-per-pass"
        self.plan = None if self.separate else make_plan(scene, self.pixels, 1.0, 0.0, None)
        self.first_photons = self.given or max(1, round(paths_per_pixel(scene) * self.pixels))
        self.dropped = 0
        self.filter = None  # the learned caustic filter's weights, where the plan uses it
        # With mirrors or glass, the light seen along the camera's specular chains (the
        # lights' images in them: specks that may cover a hundredth of a pixel) is estimated
        # apart from the paths, from more camera samples where pixels see a mirror or glass:
        # EMISSION_SAMPLES per pass each, and EMISSION_EXTRA per such pixel placed where it
        # varies (adaptive sampling, cross-fitted as for the paths). Where it is known to
        # SEEN_ERROR it is added after the denoiser (which takes such specks for noise). The
        # paths (and so their adaptive sampling) carry the rest.
        self.glassy = (
            np.flatnonzero(specular_pixels(scene, bvh, camera))
            if self.separate and self.full
            else None
        )
        self.glow = Halves(self.h, self.w)  # the light seen, per half: every pass, and extra
        self.grid_radius = 0.0  # set at the first pass, then shrunk by each (probabilistic PPM)
        self.points = self.grid = None
        self.footprint = None  # (P,) pixel width at each pixel's first visible point
        total = o.spp if self.deadline is None else None
        self.bar = tqdm(total=total, unit="spp", disable=not o.progress, desc=method.name)
        self.j = 0  # passes done
        self.spp = 0  # camera paths per pixel done (one per pass, or `pass_paths`)
        self.half_spp = [0, 0]  # of which in each half (passes alternate between them)
        self.k = 1  # camera paths per pixel of the coming pass
        self.cut = False  # whether the last pass took fewer than planned (the budget's end)
        self.adapted = False  # whether the last pass spent adaptive samples
        self.begun = time.monotonic()
        method.setup_seconds = self.begun - started  # of the budget, gone before the first pass

    def run_pass(self) -> None:
        """One pass: camera samples (and with them photons and the light seen), adaptive
        samples, the plan after the first pass, and the kernels later passes need. What runs
        once (loading the kernels, the plan) is left out of the first pass's time, which
        tells `done` what the next pass will take."""
        if self.j == 0 and self.deadline is not None:
            with self.watch("kernels"):
                warm_first_kernels(self.scene, self.bvh, self.camera)
            self.begun = time.monotonic()
        self.camera_samples()
        self.adapted = self.adapts()
        if self.adapted:
            self.adaptive_samples()
        if self.j == 0:
            once = time.monotonic()
            if self.plan is None:
                self.make_plan()
            if self.deadline is not None and self.denoising:
                with self.watch("denoise"):
                    self.call = self.time_denoiser()
            if self.full and (self.deadline is not None or self.o.spp > 1):
                with self.watch("kernels"):
                    warm_later_kernels(
                        self.scene, self.bvh, self.camera,
                        self.points if self.separate else None,
                        self.grid if self.plan.caustics != "off" else None,
                        self.deadline is not None or self.o.spp > ADAPT_AFTER,
                    )  # fmt: skip
            collector.resume()  # the kernels and the denoiser are loaded: see dpm.collector
            self.begun += time.monotonic() - once
        self.spp += self.k
        self.half_spp[self.j % 2] += self.k
        self.j += 1
        self.grid_radius *= np.sqrt((self.j + ALPHA) / (self.j + 1))  # Knaus & Zwicker, Eq. 17
        self.bar.update(self.k)

    def time_denoiser(self) -> tuple[float, float]:
        """Seconds one denoiser call on the whole image takes on this machine now, without
        and with clean guides (the slower filter: 0.35 against 0.15 s at 512²): four times a
        call on a quarter of the first pass's image, each after one that sets its filter up
        (and, the first, loads OIDN, which the finish then need not). Where the guides never
        count as clean (mirrors or glass) only the first is timed."""
        h, w = max(1, self.h // 2), max(1, self.w // 2)
        image = self.paths.mean().reshape(self.h, self.w, 3)[:h, :w].astype(np.float32)
        albedo, normal = (g.reshape(self.h, self.w, 3)[:h, :w] / self.k for g in self.guide_sums[0])
        seconds = []
        for clean in (False, True)[: 1 + self.clean_guides(CLEAN_GUIDE_PATHS)]:
            # a first call with a filter sets it up (0.02-0.03 s; the very first also loads
            # OIDN), which the finish's calls repeat only where their filters alternate
            denoise(image, albedo, normal, clean)
            begun = time.monotonic()
            denoise(image, albedo, normal, clean)
            seconds.append((time.monotonic() - begun) * self.pixels / (h * w))
        return seconds[0], seconds[-1]

    def pass_paths(self) -> int:
        """Camera paths per pixel the next pass is planned to take: one, or where passes take
        whole pixels (no caustic estimate, no light seen apart), 1, 1, 2, 2, 4, 4, ... (both
        passes of a pair alike, so the halves stay equal), up to PASS_SAMPLES in all."""
        if self.separate or self.plan is None or self.plan.caustics != "off" or not self.full:
            return 1
        return int(min(1 << min(self.j // 2, 30), max(1, PASS_SAMPLES // self.pixels)))

    def adapts(self) -> bool:
        """Whether the coming pass spends adaptive samples: once each half has ADAPT_AFTER / 2
        paths per pixel (a deviation needs a few; with one path a pass, from pass 8)."""
        return self.full and 2 * min(self.half_spp) >= ADAPT_AFTER

    def camera_samples(self) -> None:
        """The pass's camera samples per pixel (`k`: one where the light seen or caustics are
        estimated apart), path-traced without caustics; with the plan's caustics, a pass of
        photon paths gathered into SPPM's statistics at its visible points."""
        o, scene, bvh, camera, watch = self.o, self.scene, self.bvh, self.camera, self.watch
        j, seed = self.j, pass_seed(self.o.seed, self.j)
        # each half's passes extend one stratified sequence per pixel (cross-fitting keeps
        # the halves independent)
        sequence = (sequence_seed(o.seed, j % 2), self.half_spp[j % 2])
        if (
            self.full
            and self.plan is not None
            and self.plan.caustics == "off"
            and not self.separate
        ):
            # no caustic estimate and no light seen apart: whole pixels in one kernel, no
            # visible points kept
            with watch("path"):
                sums, squares, a, n, bad = trace_pixel_sums(
                    scene, bvh, camera, self.k, seed, sequence
                )
            self.paths.add_paths(j % 2, self.k, sums, squares)
            self.grid = None
            self.add_guides(a, n)
            self.dropped += bad
            return
        state = self.state
        with watch("visible_points"):
            points = trace_visible_points(scene, bvh, camera, 1, seed, (0, self.h), sequence)
            self.points = points
        if j == 0:
            self.footprint = pixel_footprints(points, camera)
            if o.radius is None:
                state.radius = RADIUS_FOOTPRINTS * self.footprint
            self.narrow.radius = state.radius * NARROW
            self.grid_radius = GRID_RADII * float(np.median(state.radius))
        n_paths = self.first_photons if self.plan is None else self.plan.photons_per_pass
        photons = self.grid = None
        if n_paths and (self.plan is None or self.plan.caustics != "off"):
            with watch("photons"):
                photons = trace_photons(scene, bvh, n_paths, o.seed, caustic_only=True,
                                        first_path=state.paths, guided=True)  # fmt: skip
        if self.full:
            with watch("shade"):
                self.grid = None if photons is None else photon_grid(photons, self.grid_radius)
                reflected, bad = shade(scene, bvh, points, seed, False, self.grid, sequence)
                if self.separate:
                    self.paths.add_pass(j % 2, points.throughput * reflected)
                else:
                    self.paths.add_pass(j % 2, points.emitted + points.throughput * reflected)
            if self.separate:
                with watch("emitted"):
                    self.see_light(points.emitted.astype(np.float64))
            self.dropped += bad
        a, n = guides(points)  # the denoiser's guides, and the caustic filter's
        self.add_guides(a, n)
        if photons is not None:
            states = (state, self.narrow)
            self.halves.mark(states)
            sppm_gather(states, points, photons, watch)
            self.halves.add(j % 2, states, photons.n_paths)

    def see_light(self, first: np.ndarray) -> None:
        """Add this pass's light seen: its first sample per pixel (P, 3), then
        EMISSION_SAMPLES more where the pixel sees a mirror or glass, then EMISSION_EXTRA per
        such pixel where the other half's samples vary most."""
        scene, bvh, camera, glow, glassy = self.scene, self.bvh, self.camera, self.glow, self.glassy
        half = self.j % 2
        glow.add_pass(half, first)
        # each half's samples of a pixel extend one stratified sequence, pass by pass
        sums, squares = trace_emitted(
            scene, bvh, camera, glassy, EMISSION_SAMPLES, pass_seed(self.o.seed, half, 2),
            EMISSION_SAMPLES * (self.j // 2),
        )  # fmt: skip
        glow.base[half].add(glassy, EMISSION_SAMPLES, sums, squares)
        extra, counts = glow.plan_extra(half, EMISSION_EXTRA * len(glassy), EMISSION_CAP)
        done = glow.extra[half].count[extra].astype(np.int64)
        sums, squares = trace_emitted(
            scene, bvh, camera, extra, counts, pass_seed(self.o.seed, half, 3), done
        )
        glow.extra[half].add(extra, counts, sums, squares)

    def adaptive_samples(self) -> None:
        """Extra camera paths where this half's pixels vary most (`dpm.methods.adaptive`)."""
        with self.watch("adaptive"):
            budget = round(EXTRA_PER_PIXEL * self.pixels * self.k)
            half = self.j % 2
            extra, counts = self.paths.plan_extra(half, budget, EXTRA_CAP * self.k)
            # each half's extra paths of a pixel extend a stratified sequence of their own
            done = self.paths.extra[half].count[extra].astype(np.int64)
            sums, squares, bad = trace_listed(
                self.scene, self.bvh, self.camera, extra, counts,
                pass_seed(self.o.seed, self.j, 1), self.grid, not self.separate,
                (sequence_seed(self.o.seed, half, extra=True), done),
            )  # fmt: skip
            self.paths.extra[half].add(extra, counts, sums, squares)
            self.extra_paths += int(counts.sum())
            self.dropped += bad

    def make_plan(self) -> None:
        """The plan after the first pass, from the light its paths and photons found."""
        path_light = 0.0
        if self.full:
            path_light = float((self.paths.mean() + self.glow.mean()).mean(axis=1).sum())
        caustic_light = float(self.state.irradiance().mean(axis=1).sum())
        plan = make_plan(self.scene, self.pixels, path_light, caustic_light, self.given, self.why)
        shipped = self.o.weights is not None or caustic_forward.SHIPPED.exists()
        self.plan = plan_network(plan, self.o.network, self.pixels, self.o.time, shipped)
        if self.plan.caustics != "off" and self.o.network is not False:
            with self.watch("network"):
                # compiled (or loaded) now, also where the budget left the filter out: a
                # longer budget's render must not stop to compile it
                caustic_forward.warm()
                if self.plan.network:
                    self.filter = caustic_forward.load_filter(
                        self.o.weights or caustic_forward.SHIPPED
                    )
                    self.finish_seconds += network_seconds(self.pixels)

    def finish_reserve(self, k: int = 0) -> float:
        """Seconds to keep for the finish were the render to stop after a pass of k more
        paths per pixel (0: now): its fixed part, and FINISH_MARGIN times the timed call for
        each denoiser call it would make (with the filter it would use) and for the rest
        (REST_CALLS of the faster filter's call). The denoiser runs once, and twice more
        where `denoiser_share` will judge it (no mirror or glass, and each half with
        ADAPT_AFTER / 2 paths): counting those two from the first pass kept a 512² render
        at `--time 2` to one pass, ended at 1.2 s."""
        if not self.denoising:
            return self.finish_seconds
        half = list(self.half_spp)
        half[self.j % 2] += k  # (the coming pass is pass j, of half j mod 2)
        clean = [self.clean_guides(self.spp + k)]  # each call's filter (`denoise`'s clean_aux)
        if not self.separate and 2 * min(half) >= ADAPT_AFTER:
            clean += [self.clean_guides(paths) for paths in half]
        seconds = sum(self.call[c] for c in clean) + REST_CALLS * self.call[False]
        return self.finish_seconds + FINISH_MARGIN * seconds

    def done(self) -> bool:
        """Whether to stop: --spp paths per pixel done, or the next pass would overrun the
        budget even at one path per pixel (a pass's time includes what runs between passes);
        else sets the next pass's paths per pixel `k` (`pass_paths`, fewer where the budget
        holds only those, and without a budget up to --spp in all)."""
        now = time.monotonic()
        last, self.begun = now - self.begun, now
        if self.j == 1:  # could the budget hold one pass and the finishing?
            self.method.pass_seconds = last
            self.method.overran = (
                self.deadline is not None and now + self.finish_reserve() > self.deadline
            )
        k = self.pass_paths()
        if self.deadline is None:
            self.k = min(k, self.o.spp - self.spp)
            return self.spp >= self.o.spp
        if self.cut:  # a pass cut to the budget is the last (so --spp of the paths reproduces it)
            return True
        # a pass's seconds taken as its paths' share plus one path's worth (what it spends
        # besides): at one path per pass, the next pass fits where the last one would; the
        # first pass with adaptive samples also pays for those
        per_path = max(last, 1e-9) / (self.k + 1)
        if self.adapts() and not self.adapted:
            per_path *= 1 + EXTRA_PER_PIXEL
        self.k = min(k, int((self.deadline - self.finish_reserve(k) - now) / per_path) - 1)
        self.cut = self.k < k
        return self.k < 1

    def finish(self) -> np.ndarray:
        """(H, W, 3) float32: the path-traced image plus SPPM's caustics (`caustics`),
        denoised where the pixel's standard error allows (`restore_certain`), plus the light
        seen that is known well enough (added after the denoiser)."""
        self.bar.close()
        m, j, h, w = self.method, self.j, self.h, self.w
        m.passes, m.spp, m.plan, m.caustic_photons = j, self.spp, self.plan, self.state.photons
        m.dropped, m.extra_paths = self.dropped, self.extra_paths
        m.denoised, m.denoiser_share = False, 0.0  # set below where the denoiser runs
        m.narrow_weight = m.extrapolated_weight = m.network_weight = 0.0  # set by `caustics`
        m.light_pixels = 0 if self.glassy is None else len(self.glassy)
        seen = int(sum(self.glow.half(k).count.sum() for k in (0, 1)))
        m.light_samples = seen - self.spp * self.pixels
        caustic, count = self.caustics()
        if not self.full:
            return caustic.astype(np.float32).reshape(h, w, 3)
        seen, error, after = self.light_seen()
        image = self.paths.mean() + np.where(after, 0, seen) + caustic
        image = image.astype(np.float32).reshape(h, w, 3)
        if m.denoises(self.o):
            with self.watch("denoise"):
                denoised = denoise(image, *self.guides(), self.clean_guides(self.spp))
                # A caustic's relative error is 1/√(photons in its disc), but of which value?
                # Of its own, a caustic read low by chance (2 photons where 10 were due) looks
                # certain and stays dark: where the disc holds photons, take what the
                # denoiser leaves it (its own plus the denoiser's rise, if any). A pixel
                # without photons keeps its own (zero), so its paths' error decides there.
                rise = luminance(denoised.reshape(-1, 3)) - luminance(image.reshape(-1, 3))
                share = luminance(caustic) + np.where(count > 0, np.maximum(rise, 0.0), 0.0)
                caustic_error = share / np.sqrt(np.maximum(count, 1.0))
                unseen = np.where(after[:, 0], 0, error)  # the light seen's, where denoised
                total = np.sqrt(self.paths.standard_error() ** 2 + unseen**2 + caustic_error**2)
                total = total.reshape(h, w)
                weight = m.denoiser_share = self.denoiser_share(total)
                m.denoised = weight > 0
                if m.denoised:  # the ends exactly (0·inf would be NaN)
                    restored = restore_certain(image, denoised, total)
                    image = restored if weight >= 1 else (
                        weight * restored + (1.0 - weight) * image
                    ).astype(np.float32)  # fmt: skip
        return image + np.where(after, seen, 0).astype(np.float32).reshape(h, w, 3)

    def denoiser_share(self, error: np.ndarray) -> float:
        """The weight in [0, 1] of the denoised image (after `restore_certain` with the pixels'
        standard errors error (H, W)) against the plain mean of the passes: the blend
        share·denoised + (1 − share)·plain expected closest to the truth.

        Judged only where every part of the image is in the two halves of the paths (no
        caustic estimate and no light seen apart: those are shared by the halves, and their
        noise would not show; elsewhere 1): each half a is denoised and restored alone (R) and
        the blend a + share·(R − a) fitted by least squares to the other, independent half b,
        over both halves: share = −Σ (R − a)·(a − b) / Σ (R − a)². The other half's noise is
        independent of the rest, so this is the blend closest to the truth for a half. The
        whole image takes the same share: the denoiser's blur shrinks with the noise it
        faces, so its error keeps about the same proportion to the noise (a bias that stayed
        fixed would call for a smaller share; on the controls and the Cornell box that
        variant was up to 3 % worse, and the binary "denoise or not" it replaces up to 11 %).
        Where the paths' noise is already low the denoiser's blur costs more than it
        removes and the share falls towards 0 (the Cornell box, whose light's edge it blurs:
        0.48 at 64 paths per pixel, 0.22 at 1024)."""
        if self.separate or 2 * min(self.half_spp) < ADAPT_AFTER:  # (no photons either)
            return 1.0  # (below ADAPT_AFTER / 2 paths a half's few samples guide it poorly)
        with self.watch("denoise"):
            # float32, as the denoiser and the restore give: where they move nothing, R − a
            # is exactly zero (float64 halves left float32 rounding there, read as a move)
            halves = [
                self.paths.half(k).mean().reshape(self.h, self.w, 3).astype(np.float32)
                for k in (0, 1)
            ]
            fit = moved = 0.0
            for k, (a, b) in enumerate(((halves[0], halves[1]), (halves[1], halves[0]))):
                # each half guided by its own passes only
                clean = self.clean_guides(self.half_spp[k])
                x = restore_certain(a, denoise(a, *self.guides(k), clean), SQRT2 * error) - a
                x, gap = x.astype(np.float64).ravel(), (b - a).astype(np.float64).ravel()
                fit += float(x @ gap)
                moved += float(x @ x)
            # (a denoiser that moves nothing leaves the image as it is: keep it; so does a
            # score that is not a number)
            share = fit / moved if moved > 0 else 1.0
            return min(max(share, 0.0), 1.0) if np.isfinite(share) else 1.0

    def light_seen(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(P, 3) float64 light seen along the camera's specular chains per pixel, (P,) its
        standard error (luminance) and (P, 1) bool where it is known well enough to skip the
        denoiser (not where one sample per half tells no error: inf). Without mirrors or glass
        nothing is seen apart (the paths carry the light): zero, known exactly."""
        if not self.separate:
            # (the glow holds no samples: its error would read "unknown" everywhere, and
            # `restore_certain` would give back nothing of what the denoiser got wrong)
            zero = np.zeros(self.pixels)
            return np.zeros((self.pixels, 3)), zero, np.ones((self.pixels, 1), bool)
        seen, error = self.glow.mean(), self.glow.standard_error()
        return seen, error, (error < SEEN_ERROR * luminance(seen))[:, None]

    def add_guides(self, albedo: np.ndarray, normal: np.ndarray) -> None:
        """This pass's denoiser guides, albedo and normal ((P, 3) or (H, W, 3): the means over
        its `k` paths per pixel), into its half."""
        half = self.guide_sums[self.j % 2]
        half[0] += self.k * albedo.reshape(self.pixels, 3)
        half[1] += self.k * normal.reshape(self.pixels, 3)

    def clean_guides(self, paths: int) -> bool:
        """Whether guides averaged over `paths` paths per pixel count as noise-free for the
        denoiser: from CLEAN_GUIDE_PATHS, where no mirror or glass is in the scene."""
        return not self.separate and paths >= CLEAN_GUIDE_PATHS

    def guides(self, half: int | None = None) -> tuple[np.ndarray, np.ndarray]:
        """The denoiser's (H, W, 3) albedo and normal guides: the means over the passes' paths,
        or over half `half`'s (0: passes 0, 2, 4, ...; 1: passes 1, 3, ...)."""
        sums = self.guide_sums.sum(0) if half is None else self.guide_sums[half]
        n = self.spp if half is None else self.half_spp[half]
        shape = (self.h, self.w, 3)
        return (sums[0] / n).reshape(shape), (sums[1] / n).reshape(shape)

    def caustic_stats(self, chosen: tuple | None = None, half: int | None = None) -> CausticStats:
        """The passes' per-pixel caustic statistics, as the learned filter reads them (chosen:
        `sharper_where_biased`'s result, when already made), or those of half `half` of the
        passes alone (`PassHalves`, at the whole run's radii)."""
        s, n, fp, passes = self.state, self.narrow, self.footprint, self.j
        if half is not None:
            s, n = (half_state(self.halves, half, k, like) for k, like in enumerate((s, n)))
            passes = int(self.halves.passes[half])
        own, sharp = chosen or sharper_where_biased(s, n, LEPSKI_Z)
        count = np.where(sharp, n.count, s.count)
        # each photon falls in the discs of about π (radius in pixel widths)² pixels
        overlap = np.pi * (np.where(sharp, n.radius, s.radius) / fp) ** 2
        return CausticStats(
            self.h, self.w, passes, s.irradiance(), n.irradiance(), s.count, n.count, own,
            count, *spread_sparse(own, count, overlap, self.h, self.w), s.radius / fp,
            self.blur_ratio(half),
            np.log(fp / np.median(fp)), *(g.reshape(-1, 3) for g in self.guides()),
        )  # fmt: skip

    def blur_ratio(self, half: int | None = None) -> np.ndarray:
        """(P,) float64 the narrow kernel's blur over the wide one's per pixel: Σ radius² over
        the passes of each (SPPM's estimate is the mean of its passes' estimates at their
        radii; a half's, of its own passes'), FIRST_BLUR_RATIO before any pass or without
        PIXEL_BLUR_RATIO."""
        r2 = self.halves.radius2
        wide, narrow = r2.sum(axis=0) if half is None else r2[half]
        ratio = np.full(self.pixels, FIRST_BLUR_RATIO)
        if PIXEL_BLUR_RATIO:
            np.divide(narrow, wide, out=ratio, where=wide > 0)
        return ratio

    def caustics(self) -> tuple[np.ndarray, np.ndarray]:
        """(P, 3) float64 caustic radiance per pixel, SPPM's at the sharper of two radii where
        it shows (`sharper_where_biased`) with sparse pixels spread (`spread_sparse`), moved
        towards the narrow kernel's estimate, the extrapolated one and the learned filter's
        as far as the passes' halves say it pays (`blend`), and (P,) the photons in the
        pixel's disc that tell its error (zero where no caustic was estimated)."""
        caustic, sharp = sharper_where_biased(self.state, self.narrow, LEPSKI_Z)  # throughput·ρ/π
        self.method.sharp_pixels = int(sharp.sum())
        if self.footprint is None:  # no caustics were estimated
            return caustic, np.zeros(self.pixels)
        stats = self.caustic_stats((caustic, sharp))
        moves = [held_move(stats, stats.narrow, 0.0), extrapolated_move(stats)]
        # (the network's seconds: the filter on the whole run and on the half in `blend`)
        with self.watch("network") if self.filter is not None else nullcontext():
            if self.filter is not None:
                filtered = caustic_forward.filter_caustics(self.filter, stats)
                moves.append(held_move(stats, filtered, CLAMP_Z))
            weights = self.blend()
        m = self.method
        m.narrow_weight, m.extrapolated_weight = float(weights[0]), float(weights[1])
        if self.filter is not None:
            m.network_weight = float(weights[2])
        out = stats.spread.copy()
        for w, x in zip(weights, moves, strict=True):
            if w > 0:  # (a move not taken leaves no NaN of its own behind: 0·NaN)
                out += w * x
        # The two kernels' photons tell the caustic's error too. The moves make the estimate
        # (1 - b)·wide + b·narrow, b = w_n + f·w_e, f the pixel's `extrapolation` (about 4/3;
        # at a pixel Lepski's rule took narrow: 1 + (f - 1)·w_e); the narrow disc's photons
        # are among the wide one's, so their errors correlate (covariance about the wide
        # one's variance) and its relative variance is (1 - b²)/N_wide + b²/N_narrow, where
        # a move moved the pixel (not where it is sparse).
        ext = extrapolation(stats.blur_ratio) * weights[1]
        b = np.where(sharp, 1.0 + ext - weights[1], weights[0] + ext)
        moved = (moves[0].any(axis=1) & (weights[0] > 0)) | (
            moves[1].any(axis=1) & (weights[1] > 0)
        )
        effective = nested_photons(stats.wide_count, stats.narrow_count, b)
        return out, np.where(moved, effective, stats.own_count)

    def blend(self) -> np.ndarray:
        """The weights (narrow kernel's, extrapolated estimate's[, learned filter's]) of the
        moves from the caustic estimate towards those (`dpm.caustic.blend`), fitted on two
        independent halves of the passes (`PassHalves`): the even passes' half a, its own
        moves (its narrow and extrapolated estimates, and the filter run on it alone),
        against the odd half's extrapolated estimate. With one pass there are no halves: the
        kernels' moves 0 (Lepski's rule alone), the filter 1 (the network was trained for it).

        Why an estimate with less blur than a's as the target: against the other half's own
        estimate, which shares a's blur, the filter's weight came out 0.2-0.6 on the unseen
        spheres where against their reference it is 1.5 (much of what the filter removes is
        blur). The narrow one was the target from 2026-11-29 (its weight on the examples
        followed the one fitted against the reference: the ring 1.33 / 1.45 / 1.53 against
        1.38 / 1.59 / 1.58 at 4 / 16 / 64 passes); the extrapolated one, with less blur
        still, since 2026-12-02 (`benchmarks/blend_target.py`, examples, 4 / 16 / 64 passes,
        seeds 1-2, `--no-network`: 0.991 of the error fitted to the narrow one, worst
        1.004), and the move towards the extrapolated estimate with it (0.984 more, 0.962 at
        64 passes: pool2 0.83, worst 1.003). The narrow move, added 2026-11-29 (0.962 / 0.926
        / 0.929 of Lepski's rule alone), is a per-render correction of Lepski's rule: where
        its test is too timid for the scene, the halves show the narrow kernel closer."""
        network = self.filter is not None
        if self.halves.passes.min() < 1:
            return np.array([0.0, 0.0, 1.0]) if network else np.zeros(2)
        a = self.caustic_stats(half=0)
        wide, narrow = (half_state(self.halves, 1, k, like).irradiance()
                        for k, like in enumerate((self.state, self.narrow)))  # fmt: skip
        target = extrapolated(wide, narrow, self.blur_ratio(1)) if EXTRAPOLATED_TARGET else narrow
        moves = [held_move(a, a.narrow, 0.0), extrapolated_move(a)]
        if network:
            moves.append(held_move(a, caustic_forward.filter_caustics(self.filter, a), CLAMP_Z))
        weights = blend_weights(moves, target - a.spread)
        if network and not moves[2].any():  # a filter that moves nothing: as it is
            weights[2] = 1.0 - weights[:2].sum()  # (on the simplex still)
        return weights
