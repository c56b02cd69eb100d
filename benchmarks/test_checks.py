"""The suite's must-hold checks catch broken estimators, and findings never fail a run.

Made-up estimators that answer NaN, negative values or light where no surface was seen,
ignore their K, refuse P = K, or refuse in several lines go through the same checks the
stability studies run on every registered method (`stability.k_close_probes`,
`checks.probe`), and fail them; PM and PPM pass. A plane of points and photons stands in
for a scene, so this needs no reference data and runs in a second.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
import pytest
import stability
from checks import Check, assert_must_hold, finding, probe, problems, summary

from dpm.errors import InputError
from dpm.estimators import PM, PPM
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap, VisiblePoints

K = 20
RATIOS = (1.0, 1.5, 4.0)


def plane(side: int = 20, n_paths: int = 400) -> tuple[VisiblePoints, PhotonMap]:
    """Points on a side × side grid of the unit square z = 0 (every seventh a miss) and one
    caustic photon on the square from every other of n_paths emitted paths."""
    rng = np.random.default_rng(0)
    n = side * side
    xy = (np.stack(np.meshgrid(np.arange(side), np.arange(side)), -1).reshape(-1, 2) + 0.5) / side
    hit = np.arange(n) % 7 != 3
    position = np.zeros((n, 3), np.float32)
    position[hit, :2] = xy[hit]
    normal = np.zeros((n, 3), np.float32)
    normal[hit, 2] = 1
    albedo = np.where(hit[:, None], np.float32(0.8), np.float32(0)).astype(np.float32)
    ones = np.ones((n, 3), np.float32)
    points = VisiblePoints(
        position, normal, albedo, ones * hit[:, None], 0 * ones, hit,
        np.arange(n, dtype=np.int32), np.arange(n),
    )  # fmt: skip
    p = n_paths // 2
    spot = np.zeros((p, 3), np.float32)
    spot[:, :2] = rng.random((p, 2), dtype=np.float32)
    up = np.zeros((p, 3), np.float32)
    up[:, 2] = 1
    flux = np.full((p, 3), 1 / n_paths, np.float32)
    photons = PhotonMap(
        spot, up, flux, up, np.ones(p, bool), np.ones(p, np.uint16), np.arange(p) * 2, n_paths
    )
    return points, photons


@dataclass(frozen=True)
class Broken:
    """PM-K with one fault."""

    fault: str
    k: int = K

    def estimate(self, points: VisiblePoints, photons: PhotonMap, watch: Stopwatch | None = None):
        if self.fault == "ignores K":  # answers from its 5 nearest whatever it was told
            return PM(k=5).estimate(points, photons, watch)
        if self.fault == "refuses P = K" and len(photons) <= self.k:
            raise InputError(f"--k {self.k} needs more than {len(photons)} photons")
        if self.fault == "refuses in lines" and len(photons) < self.k:
            raise InputError(f"--k {self.k}:\ntoo few photons ({len(photons)})")
        out = PM(k=self.k).estimate(points, photons, watch)
        first = np.flatnonzero(points.hit)[0]
        if self.fault == "NaN":
            out[first, 1] = np.nan
        elif self.fault == "negative":
            out[first, 0] = -1e-3
        elif self.fault == "light off the surfaces":
            out[~points.hit] = 0.5
        return out


FAULTS = {
    "NaN": "NaN or infinite at 1 points",
    "negative": "negative at 1 points",
    "light off the surfaces": "not black off the surfaces",
    "ignores K": f"accepted P = {K - 1} < K = {K} photons",
    "refuses P = K": f"refused P = {K} ≥ K = {K}",
    "refuses in lines": "refusal of 2 lines, not one",
}


@pytest.mark.parametrize("fault", list(FAULTS))
def test_a_broken_estimator_fails_the_must_hold_checks(fault: str) -> None:
    points, photons = plane()
    _, checks = stability.k_close_probes("plane", Broken(fault), points, photons, RATIOS)
    assert any(c.ok is False for c in checks)
    with pytest.raises(AssertionError, match=FAULTS[fault]):
        assert_must_hold(checks)


def test_sound_estimators_pass_the_must_hold_checks() -> None:
    points, photons = plane()
    rows, checks = stability.k_close_probes("plane PM", PM(k=K), points, photons, RATIOS)
    assert [r["photons"] for r in rows] == [20, 30, 80] and len(checks) == 4
    assert "refused P = 19 < K = 20: --k 20 is more than" in checks[-1].text
    ppm = PPM(radius=0.1, photons_per_pass=100)
    for estimator in (PM(k=K), ppm):
        estimate, wrong, _ = probe(estimator, points, photons)
        assert estimate is not None and not wrong
        assert not problems(estimate, points, points.hit)  # a region: the hit points
        checks.append(Check("plane", "sound", not wrong))
    assert_must_hold(checks)


def test_findings_are_reported_never_asserted() -> None:
    row = {"scene": "s", "paths": 10, "caustic_photons": 30, "problems": [], "outcome": "ok"}
    rows = [
        {**row, "method": "PM-20", "rmse": 0.5},
        {**row, "method": "BAD", "rmse": 2.0},
        {**row, "method": "NAN", "rmse": float("nan"), "problems": ["NaN or infinite at 3 points"]},
        {**row, "paths": 100, "method": "PM-20", "rmse": 9.0, "problems": ["negative at 1 points"]},
    ]
    checks = stability.sparse(rows, {"s": 1.0})  # the lowest budget only: 10 paths
    assert [c.ok for c in checks if c.must] == [True, True, False]
    found = [c.line() for c in checks if not c.must]
    assert found[1] == (
        "finding: s BAD at 30 caustic photons: RMSE 2.00× the all-black estimate "
        "(worse than estimating nothing)"
    )
    with pytest.raises(AssertionError, match="NAN at 30 caustic photons: NaN or infinite"):
        assert_must_hold(checks)
    assert_must_hold([c for c in checks if c.subject != "s NAN at 30 caustic photons"])
    assert_must_hold([finding("s PM-20", "bias +600 %")])
    lines = summary(checks, "sound answers")
    assert (
        lines[0] == "**Must hold** for every method (asserted): sound answers. 2 of 3 checks pass."
    )
    assert any(line.startswith("- must hold, FAIL: s NAN") for line in lines)
    assert any(line.startswith("- finding: s BAD") for line in lines)


def test_the_benchmarks_compare_every_estimator_at_points() -> None:
    # hybrid reuses dpm's estimator, sppm renders per pixel and pt has no caustic estimate
    from common import photon_methods
    from dpm.estimators import ESTIMATORS
    from dpm.methods import METHODS

    expected = [e.name for e in ESTIMATORS if METHODS[e.name].at_points]
    assert list(photon_methods()) == expected
