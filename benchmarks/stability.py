"""Stability where density estimators fail: each study returns rows, a chart and verdicts.

- sparse photons: the ladder's lowest rungs (a few hundred caustic photons);
- K close to the photon count: maps cut to P = K … 10·K photons;
- thin, high-frequency caustics: the error over the reference's sharpest 5 % of pixels;
- neighbourhoods that cross surfaces (corners, walls): the bias where the K nearest photons
  include ones on another surface.
A verdict is "PASS" or "FAIL" with the figure that decided it.
"""

from __future__ import annotations

from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from accuracy import colour  # noqa: E402
from cases import (  # noqa: E402
    Case,
    caustic_error,
    estimators,
    finite,
    first_paths,
    needed_k,
)

from dpm.density.gather import nearest  # noqa: E402
from dpm.errors import InputError  # noqa: E402
from estimator_table import M  # noqa: E402

SHARP_FRACTION = 0.05  # thin-caustic mask: this fraction of hit pixels, by reference gradient
CROSSING_HEIGHT = 0.1  # a neighbour this far off the tangent plane (× r) is on another surface


def verdict(ok: bool, why: str) -> str:
    """'PASS: why' or 'FAIL: why'."""
    return f"{'PASS' if ok else 'FAIL'}: {why}"


def sparse_verdicts(rows: list[dict], black: dict[str, float]) -> list[str]:
    """At each scene's lowest budget: every method that ran is finite and beats black."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        low = min(r["paths"] for r in rows if r["scene"] == scene)
        for r in (r for r in rows if r["scene"] == scene and r["paths"] == low):
            if r["rmse"] is None:
                out.append(
                    f"{scene} {r['method']} at {r['caustic_photons']} caustic photons: "
                    f"skipped ({r['skipped']})"
                )
                continue
            ratio = r["rmse"] / black[scene]
            ok = r["finite"] and ratio < 1
            out.append(
                f"{scene} {r['method']} at {r['caustic_photons']} caustic photons: "
                + verdict(
                    ok,
                    f"RMSE {ratio:.2f}× the all-black estimate"
                    + ("" if r["finite"] else ", non-finite or negative values"),
                )
            )
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


def k_close(case: Case, ratios: tuple[float, ...]) -> tuple[list[dict], list[str]]:
    """PM-K and DPM-K on maps of P = ratio·K caustic photons (the first paths of the M map);
    rows {k, ratio, photons, method, rel_rmse, finite} and verdicts, one of which checks that
    P = K − 1 is refused with an InputError."""
    base = case.photons_at_m()
    order = np.sort(base.path)
    black = case.black_rmse()
    rows, verdicts = [], []
    methods = estimators(case, M)
    for method, estimator in methods.items():
        k = needed_k(method)
        if k == 1:
            continue
        for ratio in ratios:
            want = int(round(ratio * k))
            if want > len(order):
                continue
            cut = first_paths(base, int(order[want - 1]) + 1)
            estimate = estimator.estimate(case.points, cut)
            rel = caustic_error(case, estimate) / black
            rows.append(
                {
                    "scene": case.name,
                    "method": method,
                    "k": k,
                    "ratio": ratio,
                    "photons": len(cut),
                    "rel_rmse": rel,
                    "finite": finite(estimate),
                }
            )
        at_k = [r for r in rows if r["method"] == method]
        if at_k:
            worst = max(r["rel_rmse"] for r in at_k)
            ok = all(r["finite"] for r in at_k) and worst < 1
            verdicts.append(
                f"{case.name} {method}, P = K … {at_k[-1]['ratio']:g}·K: "
                + verdict(ok, f"worst RMSE {worst:.2f}× the all-black estimate")
            )
        fewer = first_paths(base, int(order[k - 2]) + 1)  # K − 1 photons
        try:
            estimator.estimate(case.points, fewer)
            verdicts.append(f"{case.name} {method}, P = K − 1: " + verdict(False, "no error"))
        except InputError as e:
            verdicts.append(f"{case.name} {method}, P = K − 1: " + verdict(True, f"refused: {e}"))
    return rows, verdicts


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
    for rows, nb in nearest(photon_map, position, normal, k):
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


def region_verdicts(rows: list[dict], what: str, rule: str) -> list[str]:
    """Verdicts on a region study: 'best' says whether each DPM model is the best method in
    the region (RMSE); 'bias' whether every method's relative bias there is within 20 %."""
    out = []
    for scene in dict.fromkeys(r["scene"] for r in rows):
        mine = [r for r in rows if r["scene"] == scene]
        best = min(mine, key=lambda r: r["rmse_in"])
        for r in mine:
            if rule == "best" and r["method"].startswith("DPM"):
                ratio = r["rmse_in"] / best["rmse_in"]
                ok = r is best
                out.append(
                    f"{scene} {what} ({r['points']} px), {r['method']}: "
                    + verdict(
                        ok, f"RMSE {r['rmse_in']:.4f}, {ratio:.2f}× the best ({best['method']})"
                    )
                )
            if rule == "bias":
                ok = abs(r["bias_in"]) <= 0.2
                out.append(
                    f"{scene} {what} ({r['points']} px), {r['method']}: "
                    + verdict(ok, f"bias {100 * r['bias_in']:+.1f} %")
                )
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
