"""One example scene as the benchmark suite sees it: visible points, reference, estimators.

A `Case` holds what every section of the suite needs for a scene: its BVH, the estimator
table's visible points (one per pixel of a 128-wide image) and PPM reference, and the
parameters the table tuned at M. `estimators(case, budget)` gives every method the suite
compares, built for that photon budget from the method registry.
"""

from __future__ import annotations

import json
from dataclasses import dataclass, replace
from pathlib import Path

import numpy as np

from common import (
    PM_KS,
    RESULTS,
    SCENES,
    WIDTH,
    M,
    load_reference,
    photon_methods,
    table_points,
)
from dpm import load_scene
from dpm.density.base import Estimator, luminance
from dpm.estimators.reference import caustic_rmse
from dpm.methods.base import PASSES, NearestPhotons
from dpm.nn.weights import weight_ks
from dpm.scene import Scene
from dpm.tracer import BVH, PhotonMap, VisiblePoints, build_bvh, trace_photons


@dataclass
class Case:
    """A scene with the estimator table's points, reference and tuned parameters."""

    name: str
    scene: Scene
    bvh: BVH
    points: VisiblePoints  # one per pixel of a WIDTH × height image, row-major
    reference: np.ndarray  # (N, 3) float32 reference caustic radiance at the points
    noise: float  # the reference's own RMSE noise
    record: dict  # benchmarks/results/estimators/NAME.json
    _at_m: PhotonMap | None = None  # photons_at_m, traced once

    def photons_at_m(self) -> PhotonMap:
        """The caustic photons of M emitted paths, seed 0 (the table's M map), traced once."""
        if self._at_m is None:
            self._at_m = photons(self, M)
        return self._at_m

    @property
    def shape(self) -> tuple[int, int]:
        """(height, width) of the points' image."""
        return len(self.points) // WIDTH, WIDTH

    def seen(self, radiance: np.ndarray) -> np.ndarray:
        """(H, W) camera-weighted caustic luminance of radiance (N, 3) at the points (0: miss)."""
        hit = self.points.hit
        out = np.zeros(len(hit), np.float64)
        out[hit] = luminance(self.points.throughput[hit] * radiance[hit])
        return out.reshape(self.shape)

    def black_rmse(self) -> float:
        """RMSE of an all-black estimate: the error of estimating nothing."""
        return caustic_error(self, np.zeros_like(self.reference))


def caustic_error(case: Case, estimate: np.ndarray, mask: np.ndarray | None = None) -> float:
    """The estimator table's camera-weighted caustic RMSE over the hit points, or over the
    hit points where mask (N,) bool is set."""
    if mask is None:
        return caustic_rmse(case.points, estimate, case.reference)
    if not (case.points.hit & mask).any():
        return float("nan")
    return caustic_rmse(case.points.select(mask), estimate[mask], case.reference[mask])


def reference_scenes() -> list[str]:
    """Example scenes that have a committed reference (made by estimator_table.py)."""
    return sorted(p.stem for p in (RESULTS / "references_radiance").glob("*.npz"))


def load_case(name: str) -> Case:
    """The Case of example scene `name`."""
    scene = load_scene(SCENES / f"{name}.obj")
    bvh = build_bvh(scene)
    reference, noise = load_reference(name)
    record = json.loads((RESULTS / "estimators" / f"{name}.json").read_text())
    return Case(name, scene, bvh, table_points(scene, bvh), reference, noise, record)


def best_setting(case: Case, name: str) -> dict | None:
    """The estimator table's best setting at M of progressive method `name` (its record's
    NAME_best: radius, photons_per_pass, ...), or None where the table did not tune it."""
    return case.record["budgets"][0].get(f"{name}_best")


def tuned(case: Case, name: str, budget: int) -> Estimator | None:
    """The table's best setting at M of progressive method `name` (`best_setting`), its
    passes kept at any budget: the same initial radius and number of passes, so the same
    final radius. None when the estimator table did not tune the method."""
    t = best_setting(case, name)
    if t is None:
        return None
    per_pass = max(1, round(t["photons_per_pass"] * budget / M))
    return photon_methods()[name].make_estimator(radius=t["radius"], photons_per_pass=per_pass)


def estimators(case: Case, budget: int, weights: Path | None = None) -> dict[str, Estimator]:
    """Every method the suite compares, by its report name, for `budget` emitted paths: each
    registered photon method (`photon_methods`), in registry order.

    - K-nearest methods: NAME-K for K in PM_KS, or, for a learned one (it reads weights),
      for every K with a NAME-K.msgpack among `weights` (default: the shipped models);
    - progressive methods: NAME-best, the estimator table's best setting at M (`tuned`), or,
      for a method the table has not tuned, NAME with the method's default radius and
      PASSES passes.
    """
    methods: dict[str, Estimator] = {}
    for name, cls in photon_methods().items():
        label = name.upper()
        if issubclass(cls, NearestPhotons) and "weights" in cls.options:
            for k in weight_ks(weights) if weights else weight_ks():
                files = {} if weights is None else {"weights": weights / f"{name}-{k}.msgpack"}
                methods[f"{label}-{k}"] = cls.make_estimator(k=k, **files)
        elif issubclass(cls, NearestPhotons):
            for k in PM_KS:
                methods[f"{label}-{k}"] = cls.make_estimator(k=k)
        elif (best := tuned(case, name, budget)) is not None:
            methods[f"{label}-best"] = best
        else:
            # no radius: each point's own, from its photons and pixel footprint
            methods[label] = cls.make_estimator(photons_per_pass=max(1, budget // PASSES))
    return methods


def tuning(cases: list[Case]) -> tuple[list[str], list[str]]:
    """(tuned, untuned) progressive methods of the cases, by report name: NAME-best where the
    estimator table tuned it for every case, else NAME (default radius, PASSES passes)."""
    names = [n for n, cls in photon_methods().items() if not issubclass(cls, NearestPhotons)]
    done = [n for n in names if all(best_setting(c, n) for c in cases)]
    return [f"{n.upper()}-best" for n in done], [n.upper() for n in names if n not in done]


def photons(case: Case, budget: int, seed: int = 0) -> PhotonMap:
    """The caustic photons of `budget` emitted paths (the table's photon map at M for seed 0)."""
    return trace_photons(case.scene, case.bvh, budget, seed=seed, caustic_only=True)


def first_paths(photon_map: PhotonMap, n_paths: int) -> PhotonMap:
    """The photons of the map's first n_paths emitted paths, as a map from n_paths paths."""
    keep = photon_map.select(photon_map.path < n_paths)
    scale = np.float32(photon_map.n_paths / n_paths)  # stored flux is ÷ N
    return replace(keep, flux=keep.flux * scale, n_paths=n_paths)
