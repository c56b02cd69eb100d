"""The paper's tuning protocol: PPM and APPM each at 30 settings, the best by RMSE per scene.

Settings are 10 initial radii (log-spaced) × 3 photon-path counts per pass; every run sees
the same photon map, split into passes, and the same visible points.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, replace

import numpy as np

from dpm.estimators import ESTIMATORS
from dpm.estimators.reference import caustic_rmse
from dpm.tracer import PhotonMap, VisiblePoints

PASSES = (10, 100, 1000)  # passes per run: photons_per_pass = paths / passes
TUNED = ("ppm", "appm")  # the paper's tuned baselines (any progressive estimator's name works)


@dataclass(frozen=True)
class Trial:
    """One setting of one progressive estimator and its error."""

    method: str  # 'ppm' or 'appm'
    radius: float  # initial radius (scene units)
    photons_per_pass: int  # emitted paths per pass
    rmse: float  # caustic RMSE against the reference
    seconds: float  # gathering and estimation time


def by_name(name: str) -> type:
    """The estimator class of `dpm.estimators.ESTIMATORS` named `name`."""
    return {cls.name: cls for cls in ESTIMATORS}[name]


def radii(diagonal: float, count: int = 10, lo: float = 1e-4, hi: float = 4e-3) -> np.ndarray:
    """(count,) initial radii log-spaced from lo to hi times the scene diagonal."""
    return diagonal * np.geomspace(lo, hi, count)


def tune(
    points: VisiblePoints,
    photons: PhotonMap,
    reference: np.ndarray,
    radii: np.ndarray,
    passes: tuple[int, ...] = PASSES,
    methods: tuple[str, ...] = TUNED,
    estimates: list[np.ndarray] | None = None,
) -> list[Trial]:
    """Every (method, radius, passes) setting's caustic RMSE against reference (N, 3).

    When `estimates` is a list, each trial's (N, 3) radiance is appended to it, so the trials
    can be rescored against a longer reference without rerunning them.
    """
    trials = []
    for method in methods:
        for radius in radii:
            for n in passes:
                per_pass = max(1, photons.n_paths // n)
                start = time.perf_counter()
                estimator = by_name(method)(radius=float(radius), photons_per_pass=per_pass)
                estimate = estimator.estimate(points, photons)
                seconds = time.perf_counter() - start
                error = caustic_rmse(points, estimate, reference)
                if estimates is not None:
                    estimates.append(estimate)
                trials.append(Trial(method, float(radius), per_pass, error, seconds))
    return trials


def tune_widening(
    points: VisiblePoints,
    photons: PhotonMap,
    reference: np.ndarray,
    radii: np.ndarray,
    estimates: list[np.ndarray] | None = None,
    max_steps: int = 4,
    methods: tuple[str, ...] = TUNED,
) -> list[Trial]:
    """`tune`, then extend each method's radius grid by its log step while the best is at an edge.

    A best setting at the edge of the grid only bounds the true optimum, which would flatter
    any method compared against "the best"; up to `max_steps` radii are added per method.
    """
    trials = tune(points, photons, reference, radii, methods=methods, estimates=estimates)
    ratio = float(radii[1] / radii[0])
    for method in methods:
        for _ in range(max_steps):
            tried = sorted({t.radius for t in trials if t.method == method})
            radius = best(trials, method).radius
            if radius == tried[-1]:
                extra = tried[-1] * ratio
            elif radius == tried[0]:
                extra = tried[0] / ratio
            else:
                break
            extra_radii = np.array([extra])
            trials += tune(points, photons, reference, extra_radii, methods=(method,),
                           estimates=estimates)  # fmt: skip
    return trials


def tune_descending(
    points: VisiblePoints,
    photons: PhotonMap,
    reference: np.ndarray,
    radii: np.ndarray,
    start: dict[tuple[str, int], float],
    max_steps: int = 4,
) -> list[Trial]:
    """Per (method, passes) in `start`, the log-spaced grid `radii` walked from the radius
    nearest start[(method, passes)] towards lower error until the error rises (past the grid's
    edges by up to `max_steps` of its steps, as `tune_widening` goes).

    Where the error is unimodal in the radius this finds `tune_widening`'s best at about a
    third of its cost; `start` is typically the best found against an earlier reference.
    """
    ratio = float(radii[1] / radii[0])
    lo, hi = -max_steps, len(radii) - 1 + max_steps
    trials: list[Trial] = []
    for (method, n), radius in start.items():
        error: dict[int, float] = {}  # grid index (past the edges too) -> RMSE

        def at(k: int, method=method, n=n, error=error) -> float:
            """The RMSE at grid index k, run once."""
            if k not in error:
                # the grid's own radius within it, so a trial matches the full grid's bit for bit
                inside = 0 <= k < len(radii)
                radius_k = np.array([radii[k] if inside else radii[0] * ratio**k])
                trial = tune(points, photons, reference, radius_k, (n,), (method,))[0]
                trials.append(trial)
                error[k] = trial.rmse
            return error[k]

        k = int(np.clip(round(np.log(radius / radii[0]) / np.log(ratio)), 0, len(radii) - 1))
        step = 1 if k < hi and at(k + 1) < at(k) else -1
        while lo <= k + step <= hi and at(k + step) < at(k):
            k += step  # both neighbours of the last k are known when this stops
    return trials


def rescore(
    trials: list[Trial], estimates: list[np.ndarray], points: VisiblePoints, reference: np.ndarray
) -> list[Trial]:
    """The trials with their RMSE recomputed against a new reference (N, 3)."""
    pairs = zip(trials, estimates, strict=True)
    return [replace(t, rmse=caustic_rmse(points, e, reference)) for t, e in pairs]


def best(trials: list[Trial], method: str) -> Trial:
    """The trial of `method` with the least RMSE."""
    return min((t for t in trials if t.method == method), key=lambda t: t.rmse)
