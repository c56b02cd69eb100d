"""What every density estimator must do, however accurate it is: the suite asserts these.

A study line is a `Check`: either a must-hold property of one method (`ok` True or False;
`assert_must_hold` fails the test on any False) or a finding (`ok` None: how well a method
did, reported and never asserted). The must-hold properties hold for every correct
estimator, whatever its accuracy:

- the answer is (N, 3), finite and non-negative, and black where the camera saw no surface;
- a K-nearest estimator refuses 0 < P < K photons with a one-line InputError, and accepts
  P = K.

How close an estimate comes to the reference (worse than black, biased near walls, blurred
at a cusp) is a finding.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

import numpy as np

from common import needed_k
from dpm.errors import InputError
from dpm.tracer import PhotonMap, VisiblePoints

ANSWER = "an (N, 3) answer, finite, non-negative and black where the camera saw no surface"
REFUSAL = "a K-nearest method refuses 0 < P < K photons with a one-line error and takes P = K"
SOUND = "finite, non-negative, black off the surfaces"  # what a sound answer was


@dataclass(frozen=True)
class Check:
    """One line of a study: a must-hold property (ok True/False) or a finding (ok None)."""

    subject: str  # what was checked: "ring PM-50 at 241 caustic photons"
    text: str  # what was seen
    ok: bool | None = None  # None: a finding

    @property
    def must(self) -> bool:
        """A must-hold property (asserted), not a finding."""
        return self.ok is not None

    def line(self) -> str:
        """The check as a report line."""
        if self.must:
            return f"must hold, {'PASS' if self.ok else 'FAIL'}: {self.subject}: {self.text}"
        return f"finding: {self.subject}: {self.text}"


def must(subject: str, problems: list[str], done: str = "ok") -> Check:
    """A must-hold check that passes when there are no problems (`done` says what happened)."""
    return Check(subject, "; ".join(problems) or done, not problems)


def finding(subject: str, text: str) -> Check:
    """A finding: reported, never asserted."""
    return Check(subject, text)


def problems(
    estimate: np.ndarray, points: VisiblePoints, mask: np.ndarray | None = None
) -> list[str]:
    """What is wrong with an estimate (N, 3) at the points (only where mask (N,) is set, when
    given) that no correct estimator gets wrong: non-finite or negative values, light where
    the camera ray hit no surface, the wrong shape."""
    if np.shape(estimate) != (len(points), 3):
        return [f"answer of shape {np.shape(estimate)}, not ({len(points)}, 3)"]
    where = np.ones(len(points), bool) if mask is None else mask
    out = []
    for count, what in (
        ((~np.isfinite(estimate).all(axis=1) & where).sum(), "NaN or infinite"),
        (((estimate < 0).any(axis=1) & where).sum(), "negative"),
        (((estimate != 0).any(axis=1) & ~points.hit & where).sum(), "not black off the surfaces"),
    ):
        if count:
            out.append(f"{what} at {count} points")
    return out


def probe(
    estimator: Any, points: VisiblePoints, photons: PhotonMap
) -> tuple[np.ndarray | None, list[str], str]:
    """Run the estimator on a photon map: (its estimate, or None when it refused; what it got
    wrong of the must-hold properties; what happened, for the report)."""
    k, p = needed_k(estimator), len(photons)
    refuse = 0 < p < k
    try:
        estimate = estimator.estimate(points, photons)
    except InputError as exc:
        if not refuse:
            return None, [f"refused P = {p} ≥ K = {k}: {exc}"], "refused"
        lines = str(exc).strip().splitlines()
        wrong = [] if len(lines) == 1 else [f"refusal of {len(lines)} lines, not one"]
        return None, wrong, f"refused P = {p} < K = {k}: {exc}"
    if refuse:
        return estimate, [f"accepted P = {p} < K = {k} photons (no InputError)"], "answered"
    return estimate, problems(estimate, points), SOUND


def assert_must_hold(checks: list[Check]) -> None:
    """Fail (AssertionError) listing every must-hold check that failed."""
    failed = [c.line() for c in checks if c.ok is False]
    assert not failed, "must-hold properties failed:\n" + "\n".join(failed)


def summary(checks: list[Check], properties: str) -> list[str]:
    """Report lines: the must-hold tally (`properties` says what must hold) with every
    failure, then the findings."""
    held = [c for c in checks if c.must]
    failed = [c for c in held if not c.ok]
    tally = f"{len(held) - len(failed)} of {len(held)} checks pass" if held else "nothing to check"
    lines = [
        f"**Must hold** for every method (asserted): {properties}. {tally}.",
        "",
        *[f"- {c.line()}" for c in failed],
    ]
    found = [c for c in checks if not c.must]
    if found:
        lines += [
            *([""] if failed else []),
            "**Findings** (how well each method did; reported, never asserted):",
            "",
            *[f"- {c.line()}" for c in found],
        ]
    return lines
