"""Accuracy against time: every method over a ladder of photon budgets, and its charts.

Each rung traces the caustic photons of `budget` emitted paths (seed 0) and runs every
estimator on the table's visible points. Seconds are medians over `rounds` calls after one
warm-up call per method and scene (JIT compilation excluded): trace + gather + estimate,
each estimate building its own photon tree (`common.timed_estimate`).
"""

from __future__ import annotations

import math
from functools import partial
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from cases import Case, caustic_error, estimators, photons  # noqa: E402
from checks import SOUND, probe, problems  # noqa: E402

from common import TOTAL, median_or_nan, needed_k, timed, timed_estimate  # noqa: E402


def run_ladder(case: Case, budgets: list[int], rounds: int) -> tuple[list[dict], dict]:
    """Rows {scene, method, paths, caustic_photons, rmse, trace_s, gather_s, estimate_s,
    total_s, problems, outcome} for every method and budget, and the estimates (N, 3) by
    (method, paths). A K-nearest method given fewer photons than K is run once, untimed, to
    see it refuse (rmse None); `problems` lists what it got wrong of `checks.probe`'s
    must-hold properties."""
    rows, estimates = [], {}
    warm = set()
    for budget in budgets:
        photon_map, trace_s = timed(partial(photons, case, budget), rounds)
        trace = median_or_nan(trace_s)
        for method, estimator in estimators(case, budget).items():
            row = {
                "scene": case.name,
                "method": method,
                "paths": budget,
                "caustic_photons": len(photon_map),
                "trace_s": trace,
            }
            if len(photon_map) < needed_k(estimator):
                _, wrong, outcome = probe(estimator, case.points, photon_map)
                rows.append({**row, "rmse": None, "problems": wrong, "outcome": outcome})
                continue
            estimate, seconds = timed_estimate(
                estimator, case.points, photon_map, repeats=rounds, warmup=method not in warm
            )
            warm.add(method)
            gather = seconds.get("gather", 0.0)
            wrong = problems(estimate, case.points)
            rows.append(
                {
                    **row,
                    "rmse": caustic_error(case, estimate),
                    "gather_s": gather,
                    "estimate_s": seconds[TOTAL] - gather,
                    "total_s": trace + seconds[TOTAL],
                    "problems": wrong,
                    "outcome": SOUND,
                }
            )
            estimates[method, budget] = estimate
    return rows, estimates


def pareto(rows: list[dict]) -> list[dict]:
    """The rows no other row beats in both total seconds and RMSE (ascending seconds)."""
    done = sorted(
        (r for r in rows if r["rmse"] is not None), key=lambda r: (r["total_s"], r["rmse"])
    )
    front, best = [], math.inf
    for r in done:
        if r["rmse"] < best:
            front.append(r)
            best = r["rmse"]
    return front


def growth_flags(rows: list[dict], tolerance: float = 0.05) -> list[str]:
    """One line per (scene, method) step where RMSE grew by more than `tolerance` when the
    budget grew: an estimator that gets worse with more photons."""
    flags = []
    keys = dict.fromkeys((r["scene"], r["method"]) for r in rows)
    for scene, method in keys:
        ladder = sorted(
            (
                r
                for r in rows
                if (r["scene"], r["method"]) == (scene, method) and r["rmse"] is not None
            ),
            key=lambda r: r["paths"],
        )
        for a, b in zip(ladder, ladder[1:], strict=False):
            if b["rmse"] > a["rmse"] * (1 + tolerance):
                flags.append(
                    f"{scene} {method}: RMSE {a['rmse']:.4f} at {a['paths']:,} paths "
                    f"→ {b['rmse']:.4f} at {b['paths']:,}"
                )
    return flags


STYLE = {
    "PM-50": "C0",
    "PM-500": "C1",
    "PPM-best": "C2",
    "APPM-best": "C3",
    "DPM-50": "C4",
    "DPM-500": "C5",
    "DPM-L": "C6",
}


def colour(method: str) -> str:
    """A fixed colour per method across every chart."""
    return STYLE.get(method, "C7")


def plot_axes(ax, rows: list[dict], title: str) -> None:
    """RMSE against total seconds, log-log, one line per method, the Pareto front marked."""
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = sorted(
            (r for r in rows if r["method"] == method and r["rmse"] is not None),
            key=lambda r: r["paths"],
        )
        if mine:
            ax.plot(
                [r["total_s"] for r in mine],
                [r["rmse"] for r in mine],
                "o-",
                color=colour(method),
                label=method,
                ms=4,
            )
    front = pareto(rows)
    ax.plot(
        [r["total_s"] for r in front], [r["rmse"] for r in front], "k--", lw=1, label="Pareto front"
    )
    ax.scatter(
        [r["total_s"] for r in front],
        [r["rmse"] for r in front],
        s=80,
        facecolors="none",
        edgecolors="k",
    )
    ax.set_xscale("log")
    ax.set_yscale("log")
    ax.set_xlabel("seconds (trace + gather + estimate)")
    ax.set_ylabel("caustic RMSE")
    ax.set_title(title)
    ax.grid(True, which="both", alpha=0.3)


def plot_scene(rows: list[dict], path: Path) -> None:
    """One scene's accuracy-against-time chart."""
    fig, ax = plt.subplots(figsize=(6, 4.5))
    plot_axes(ax, rows, rows[0]["scene"])
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def plot_combined(rows: list[dict], path: Path) -> None:
    """Every scene's chart side by side in one figure."""
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    cols = min(4, len(scenes))
    n_rows = -(-len(scenes) // cols)
    fig, axes = plt.subplots(n_rows, cols, figsize=(4.5 * cols, 4 * n_rows), squeeze=False)
    for ax, scene in zip(axes.flat, scenes, strict=False):
        plot_axes(ax, [r for r in rows if r["scene"] == scene], scene)
    for ax in axes.flat[len(scenes) :]:
        ax.axis("off")
    axes.flat[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def plot_errors(case: Case, estimates: dict[str, np.ndarray], path: Path) -> None:
    """False-colour |estimate − reference| (camera-weighted luminance) per method, one shared
    scale, next to the reference."""
    ref = case.seen(case.reference)
    errors = {m: np.abs(case.seen(e) - ref) for m, e in estimates.items()}
    top = max(float(np.percentile(e, 99.5)) for e in errors.values()) or 1.0
    fig, axes = plt.subplots(
        1, len(errors) + 1, figsize=(2.4 * (len(errors) + 1) + 0.8, 2.8), layout="constrained"
    )
    axes[0].imshow(ref / (1 + ref), cmap="gray")
    axes[0].set_title("reference (tone-mapped)", fontsize=8)
    for ax, (method, err) in zip(axes[1:], errors.items(), strict=True):
        im = ax.imshow(err, cmap="inferno", vmin=0, vmax=top)
        ax.set_title(f"{method}: RMSE {caustic_error(case, estimates[method]):.4f}", fontsize=8)
    for ax in axes:
        ax.axis("off")
    fig.colorbar(im, ax=axes, shrink=0.9, label="|error| (luminance)")
    fig.savefig(path, dpi=100)
    plt.close(fig)
