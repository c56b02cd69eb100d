"""Stability where density estimators fail: each study returns rows, a chart and checks.

- sparse photons: the ladder's lowest rungs (a few hundred caustic photons);
- K close to the photon count: maps cut to P = K … 10·K photons, and K − 1;
- thin, high-frequency caustics: the error over the reference's sharpest 5 % of pixels;
- neighbourhoods that cross surfaces (corners, walls): the bias where the K nearest photons
  include ones on another surface.
Each study's lines are `checks.Check`s: what every method must do there (asserted by the
suite) and findings, how well each method did (reported, never asserted).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from accuracy import colour  # noqa: E402
from cases import Case, caustic_error, estimators, first_paths  # noqa: E402
from checks import Check, finding, must, probe, problems  # noqa: E402

from common import M, needed_k  # noqa: E402
from dpm.density import PhotonIndex  # noqa: E402
from dpm.tracer import PhotonMap, VisiblePoints  # noqa: E402

SHARP_FRACTION = 0.05  # thin-caustic mask: this fraction of hit pixels, by reference gradient
CROSSING_HEIGHT = 0.1  # a neighbour this far off the tangent plane (× r) is on another surface
BIAS_LIMIT = 0.2  # the crossing study's findings say whether a bias is within ±20 %


def than_black(ratio: float) -> str:
    """A finding's text for RMSE ÷ the all-black estimate's RMSE."""
    return f"RMSE {ratio:.2f}× the all-black estimate" + (
        " (worse than estimating nothing)" if ratio >= 1 else ""
    )


def sparse(rows: list[dict], black: dict[str, float]) -> list[Check]:
    """At each scene's lowest budget, per method: must hold, its answer (or its refusal of
    K > P) as the ladder checked it; finding, its RMSE against estimating black."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        low = min(r["paths"] for r in rows if r["scene"] == scene)
        for r in (r for r in rows if r["scene"] == scene and r["paths"] == low):
            subject = f"{scene} {r['method']} at {r['caustic_photons']} caustic photons"
            out.append(must(subject, r["problems"], r["outcome"]))
            if r["rmse"] is not None:
                out.append(finding(subject, than_black(r["rmse"] / black[scene])))
    return out


def plot_sparse(rows: list[dict], black: dict[str, float], path: Path) -> None:
    """RMSE ÷ all-black RMSE against caustic photons, one panel per scene."""
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    fig, axes = plt.subplots(1, len(scenes), figsize=(4 * len(scenes), 3.6), squeeze=False)
    for ax, scene in zip(axes.flat, scenes, strict=True):
        for method in dict.fromkeys(r["method"] for r in rows):
            mine = sorted(
                (
                    r
                    for r in rows
                    if r["scene"] == scene and r["method"] == method and r["rmse"] is not None
                ),
                key=lambda r: r["paths"],
            )
            ax.plot(
                [r["caustic_photons"] for r in mine],
                [r["rmse"] / black[scene] for r in mine],
                "o-",
                color=colour(method),
                label=method,
                ms=4,
            )
        ax.axhline(1.0, color="k", lw=0.8, ls=":")
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("caustic photons")
        ax.set_title(scene)
        ax.grid(True, which="both", alpha=0.3)
    axes.flat[0].set_ylabel("RMSE ÷ RMSE of black")
    axes.flat[0].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def cut(photon_map: PhotonMap, n_photons: int) -> PhotonMap:
    """The map of the first emitted paths of photon_map that hold its first n_photons."""
    last = int(np.sort(photon_map.path)[n_photons - 1])
    return first_paths(photon_map, last + 1)


def k_close_probes(
    subject: str,
    estimator: Any,
    points: VisiblePoints,
    base: PhotonMap,
    ratios: tuple[float, ...],
) -> tuple[list[dict], list[Check]]:
    """A K-nearest estimator on maps cut from `base` to P = ratio·K photons and to K − 1:
    rows {k, ratio, photons, estimate} (estimate None where it refused) and the must-hold
    checks (P ≥ K answered soundly, K − 1 refused with a one-line InputError). Needs no
    reference: the same checks run on made-up estimators in test_checks.py."""
    k = needed_k(estimator)
    rows, checks = [], []
    for ratio in ratios:
        want = int(round(ratio * k))
        if want > len(base):
            continue
        photons = cut(base, want)
        estimate, wrong, done = probe(estimator, points, photons)
        checks.append(must(f"{subject}, P = {ratio:g}·K = {len(photons)}", wrong, done))
        rows.append({"k": k, "ratio": ratio, "photons": len(photons), "estimate": estimate})
    if 2 <= k <= len(base) + 1:
        _, wrong, done = probe(estimator, points, cut(base, k - 1))
        checks.append(must(f"{subject}, P = K − 1 = {k - 1}", wrong, done))
    return rows, checks


def k_close(case: Case, ratios: tuple[float, ...]) -> tuple[list[dict], list[Check]]:
    """Every K-nearest method on maps of P = ratio·K caustic photons (the first paths of the
    M map) and of K − 1: rows {scene, method, k, ratio, photons, rel_rmse}, the must-hold
    checks and, per method, a finding on its worst RMSE against estimating black."""
    base = case.photons_at_m()
    black = case.black_rmse()
    rows, checks = [], []
    for method, estimator in estimators(case, M).items():
        if needed_k(estimator) == 1:
            continue
        probes, held = k_close_probes(f"{case.name} {method}", estimator, case.points, base, ratios)
        mine = [
            {"scene": case.name, "method": method, "k": r["k"], "ratio": r["ratio"],
             "photons": r["photons"], "rel_rmse": caustic_error(case, r["estimate"]) / black}
            for r in probes
            if r["estimate"] is not None
        ]  # fmt: skip
        checks += held
        if mine:
            worst = max(r["rel_rmse"] for r in mine)
            subject = f"{case.name} {method}, P = K … {mine[-1]['ratio']:g}·K"
            checks.append(finding(subject, "worst " + than_black(worst)))
        rows += mine
    return rows, checks


def plot_k_close(rows: list[dict], path: Path) -> None:
    """RMSE ÷ all-black RMSE against P / K for each K-nearest method."""
    fig, ax = plt.subplots(figsize=(5.5, 4))
    for method in dict.fromkeys(r["method"] for r in rows):
        mine = [r for r in rows if r["method"] == method]
        ax.plot(
            [r["ratio"] for r in mine],
            [r["rel_rmse"] for r in mine],
            "o-",
            color=colour(method),
            label=f"{method} ({mine[0]['scene']})",
        )
    ax.axhline(1.0, color="k", lw=0.8, ls=":")
    ax.set_xscale("log")
    ax.set_xlabel("caustic photons P ÷ K")
    ax.set_ylabel("RMSE ÷ RMSE of black")
    ax.grid(True, which="both", alpha=0.3)
    ax.legend(fontsize=8)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)


def sharp_mask(case: Case) -> np.ndarray:
    """(N,) bool: the hit points in the top SHARP_FRACTION of the reference's gradient
    magnitude (tone-mapped luminance), where thin caustics and cusps are."""
    seen = case.seen(case.reference)
    gy, gx = np.gradient(seen / (1 + seen))
    grad = np.hypot(gx, gy).ravel()
    hit = case.points.hit
    cut = np.quantile(grad[hit], 1 - SHARP_FRACTION)
    return hit & (grad >= cut) & (grad > 0)


def crossing_mask(case: Case, k: int = 50) -> np.ndarray:
    """(N,) bool: hit points whose k nearest caustic photons (M paths) include one with a
    disagreeing normal or one off the point's tangent plane by more than CROSSING_HEIGHT·r."""
    photon_map = case.photons_at_m()
    hit = np.flatnonzero(case.points.hit)
    out = np.zeros(len(case.points), bool)
    position, normal = case.points.position[hit], case.points.normal[hit]
    for rows, nb in PhotonIndex(photon_map).nearest(position, normal, k):
        index = np.minimum(nb.index, len(photon_map) - 1)
        offset = photon_map.position[index] - position[rows, None, :]
        height = np.abs(np.einsum("nkc,nc->nk", offset, normal[rows]))
        r = nb.distance[:, -1:]
        out[hit[rows]] = (~nb.valid).any(1) | (height > CROSSING_HEIGHT * r).any(1)
    return out


def region_rows(case: Case, estimates: dict[str, np.ndarray], mask: np.ndarray) -> list[dict]:
    """Per method: RMSE inside and outside mask, and the relative bias inside."""
    hit = case.points.hit & mask
    w = case.points.throughput[hit]
    ref = float(luminance_sum(w * case.reference[hit]))
    rows = []
    for method, estimate in estimates.items():
        bias = (float(luminance_sum(w * estimate[hit])) - ref) / ref if ref > 0 else float("nan")
        rows.append(
            {
                "scene": case.name,
                "method": method,
                "points": int(hit.sum()),
                "rmse_in": caustic_error(case, estimate, mask),
                "rmse_out": caustic_error(case, estimate, ~mask),
                "bias_in": bias,
            }
        )
    return rows


def luminance_sum(rgb: np.ndarray) -> float:
    """Sum over rows of the mean of the three channels."""
    return float(np.asarray(rgb, np.float64).mean(axis=1).sum())


def region_checks(
    case: Case, estimates: dict[str, np.ndarray], mask: np.ndarray, what: str
) -> list[Check]:
    """Must hold, per method: its estimate at M is sound inside the region (mask (N,) bool)."""
    subject = f"{case.name} {what} ({int((case.points.hit & mask).sum())} px)"
    return [
        must(f"{subject}, {method}", problems(estimate, case.points, mask), "finite, non-negative")
        for method, estimate in estimates.items()
    ]


def region_findings(rows: list[dict], what: str, rule: str) -> list[Check]:
    """Findings of a region study: 'best', each method's RMSE in the region against the best
    method's; 'bias', each method's relative bias there, within ±BIAS_LIMIT or not."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene]
        best = min(mine, key=lambda r: r["rmse_in"])
        for r in mine:
            subject = f"{scene} {what} ({r['points']} px), {r['method']}"
            if rule == "best":
                ratio = r["rmse_in"] / best["rmse_in"]
                text = f"RMSE {r['rmse_in']:.4f}, {ratio:.2f}× the best ({best['method']})"
            else:
                inside = "within" if abs(r["bias_in"]) <= BIAS_LIMIT else "beyond"
                text = f"bias {100 * r['bias_in']:+.1f} % ({inside} ±{100 * BIAS_LIMIT:g} %)"
            out.append(finding(subject, text))
    return out


def plot_regions(rows: list[dict], key: str, label: str, path: Path) -> None:
    """Grouped bars of `key` per scene and method."""
    scenes = list(dict.fromkeys(r["scene"] for r in rows))
    methods = list(dict.fromkeys(r["method"] for r in rows))
    fig, ax = plt.subplots(figsize=(1.6 + 1.3 * len(scenes), 3.6))
    width = 0.8 / len(methods)
    for j, method in enumerate(methods):
        values = [
            next((r[key] for r in rows if r["scene"] == s and r["method"] == method), np.nan)
            for s in scenes
        ]
        ax.bar(
            np.arange(len(scenes)) + j * width, values, width, color=colour(method), label=method
        )
    ax.set_xticks(np.arange(len(scenes)) + 0.4 - width / 2, scenes)
    ax.set_ylabel(label)
    ax.axhline(0, color="k", lw=0.8)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
