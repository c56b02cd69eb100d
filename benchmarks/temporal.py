"""Temporal stability (paper Table 3): a camera path with fixed photons, DSSIM between frames.

The camera orbits its target about the up axis; every frame traces new visible points (one
per pixel, seed 0) and each method estimates the caustic from the same photon map (M paths,
seed 0). Flicker is the mean DSSIM between consecutive tone-mapped frames. The camera's own
motion also changes consecutive frames, and a blurred estimate flickers little, so flicker is
read next to the DSSIM against a long estimate of the same frame (the table's APPM tuned at
100·M, on 100·M paths, itself listed as 'reference').
"""

from __future__ import annotations

from dataclasses import replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
from accuracy import colour  # noqa: E402
from cases import Case, estimators, photons  # noqa: E402

from common import M  # noqa: E402
from dpm.camera import Camera  # noqa: E402
from dpm.density.base import luminance  # noqa: E402
from dpm.methods import make_estimator  # noqa: E402
from dpm.metrics import dssim  # noqa: E402
from dpm.tracer import trace_visible_points  # noqa: E402


def orbit(camera: Camera, frames: int, degrees: float) -> list[Camera]:
    """`frames` cameras turned about the up axis through the target, `degrees` in all."""
    axis = np.asarray(camera.up, np.float64) / np.linalg.norm(camera.up)
    arm = np.asarray(camera.origin, np.float64) - camera.target
    out = []
    for t in np.linspace(-0.5, 0.5, frames) * np.radians(degrees):
        c, s = np.cos(t), np.sin(t)  # Rodrigues' rotation of the arm about the axis
        turned = arm * c + np.cross(axis, arm) * s + axis * (axis @ arm) * (1 - c)
        out.append(replace(camera, origin=camera.target + turned))
    return out


def tone(radiance: np.ndarray) -> np.ndarray:
    """Reinhard x / (1 + x) of luminance: images in [0, 1) for DSSIM."""
    return radiance / (1.0 + radiance)


def run_path(case: Case, frames: int, width: int, degrees: float, truth_budget: int) -> dict:
    """{method: (frames, H, W) tone-mapped caustic luminance} for every method and the
    converged 'reference' (the table's best APPM at truth_budget paths, on that many)."""
    cam = case.scene.camera
    cameras = orbit(cam.with_resolution(width, width * cam.height // cam.width), frames, degrees)
    fixed = case.photons_at_m()
    record = next(b for b in case.record["budgets"] if b["paths"] == truth_budget)["appm_best"]
    truth = make_estimator(
        "appm", radius=record["radius"], photons_per_pass=record["photons_per_pass"]
    )
    truth_map = photons(case, truth_budget)
    methods = {**estimators(case, M), "reference": truth}
    out = {m: [] for m in methods}
    for camera in cameras:
        points = trace_visible_points(case.scene, case.bvh, camera, 1, 0, (0, camera.height))
        hit = points.hit
        for method, estimator in methods.items():
            photon_map = truth_map if method == "reference" else fixed
            radiance = estimator.estimate(points, photon_map)
            image = np.zeros(len(points))
            image[hit] = luminance(points.throughput[hit] * radiance[hit])
            out[method].append(tone(image.reshape(camera.height, camera.width)))
    return {m: np.stack(v) for m, v in out.items()}


def flicker(frames: np.ndarray) -> np.ndarray:
    """(F − 1,) DSSIM between consecutive frames (F, H, W) in [0, 1]."""
    return np.array([dssim(a, b, data_range=1.0) for a, b in zip(frames, frames[1:], strict=False)])


def summary(case: Case, images: dict[str, np.ndarray]) -> list[dict]:
    """Per method: mean consecutive-frame DSSIM and the mean DSSIM against the reference frame
    by frame."""
    rows = []
    for method, frames in images.items():
        mean = float(flicker(frames).mean())
        against = float(
            np.mean(
                [
                    dssim(f, r, data_range=1.0)
                    for f, r in zip(frames, images["reference"], strict=True)
                ]
            )
        )
        rows.append(
            {
                "scene": case.name,
                "method": method,
                "dssim_consecutive": mean,
                "dssim_reference": against,
            }
        )
    return rows


def plot_flicker(case: Case, images: dict[str, np.ndarray], path: Path) -> None:
    """Consecutive-frame DSSIM along the path, one line per method."""
    fig, ax = plt.subplots(figsize=(6, 3.6))
    for method, frames in images.items():
        style = {"color": "k", "ls": "--"} if method == "reference" else {"color": colour(method)}
        ax.plot(np.arange(1, len(frames)), flicker(frames), label=method, **style)
    ax.set_xlabel("frame")
    ax.set_ylabel("DSSIM to the previous frame")
    ax.set_yscale("log")
    ax.set_title(f"{case.name}: temporal stability")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=100)
    plt.close(fig)
