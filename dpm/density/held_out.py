"""Choosing a progressive estimator's radius scale by held-out error, when none is given.

The best initial radius differs between scenes of the same photon density by 20×: it follows
how fast the caustic varies, which no first pass measures well (three attempts, documented in
docs/benchmarks.md, moved the view-relative rule and broke as many scenes as they mended). The
whole run measures it: every pass's photon paths are dealt into two halves by the parity of
their path number, and each half runs the estimator from its own states at a ladder of
scales of the view-relative initial radius (`dpm.density.radius`). With A_s and B_s the two
halves' irradiance at scale s, and s₀ the narrowest (little blur, much noise),
    Σ_points (A_s − B_s₀)² + (B_s − A_s₀)²
is, in expectation, twice each half's squared error at s plus a constant: the halves are
independent, so the narrow estimate's noise adds the same amount at every s, and only its
small blur is shared. The run keeps the scale one step narrower than the minimum (a half has
half the photons, and the best radius of the whole is narrower) and returns the mean of the
two halves there. Wide scales cost the most (pairs grow with the disc's area), so after each
pass a step more than KEEP wider than the current minimum is dropped, with the steps wider
still, once its score is clearly above the minimum's (a paired test over the points, blocked
in space where their positions are known: points whose discs overlap share photons, so
they are not independent; early passes are noisy); the minimum moves narrower as photons
arrive. Consistent: each half is
the method's own consistent estimator at a fixed scale, so is their mean at any scale
chosen.
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import fields, replace
from typing import Any

import numpy as np

from dpm.density.base import luminance
from dpm.density.gather import GATHER, Pairs, PointIndex
from dpm.errors import InputError
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap
from dpm.tracer.photon_grid import disc_sums

# Scales of the view-relative initial radius, steps of √2 from ½ to 4√2, and the rule below,
# chosen on the examples at M and 10·M (benchmarks/radius_defaults.py; geometric mean of
# default / own best over 14 rows, ppm and cppm): the narrowest as the held-out reference and
# one step narrower than the minimum, 1.040 and 1.021; the minimum itself 1.076 and 1.077; a
# fixed-radius reference (α = 1) at ½ or ⅜ instead 1.04-1.11.
LADDER = 2.0 ** (np.arange(-2, 6) / 2)
NARROWER = 1  # steps narrower than the held-out minimum that the run keeps
KEEP = 2  # steps wider than the current minimum that run whatever their score
# A wider step is dropped only when its score exceeds the minimum's by Z standard errors of
# the difference (a paired test over the points): early passes have few photons, and a
# minimum that strays narrow by chance must not drop the steps the run will want later.
# Points whose discs overlap count the same photons, so the standard error is also taken
# over blocks of space at least as wide as the wider step's disc (`block_ids`; the larger
# of the two is used: never more eager to drop than with the points taken one by one).
Z = 3.0
HALVES = 2


def half(photons: PhotonMap, h: int, first: int = 0) -> PhotonMap:
    """Half h of a pass whose paths are numbered from `first` in the run: the photons of the
    paths numbered h modulo 2, as a map of those paths (flux per path of its own count)."""
    parity = (h - first) % 2  # the pass's own path numbers in half h
    n = (photons.n_paths + 1 - parity) // 2
    mask = photons.path % 2 == parity
    scale = np.float32(photons.n_paths / max(n, 1))
    part = photons.select(mask)
    return replace(part, flux=part.flux * scale, path=part.path // 2, n_paths=n)


def block_ids(position: np.ndarray, reach: np.ndarray) -> np.ndarray:
    """(n,) int64 block of each point: cubes of side the power of two at or above its disc's
    diameter 2·reach (n,) (scene units), over positions (n, 3), cubes of each side apart. Two
    points whose discs overlap lie in the same or neighbouring blocks; a point at a position
    that is not finite is a block of its own."""
    side = 2.0 ** np.ceil(np.log2(np.maximum(2.0 * reach, 1e-300)))
    key = np.column_stack([side, np.floor(position / side[:, None])])
    ok = np.isfinite(key).all(axis=1)
    ids = len(key) + np.arange(len(key))  # not finite: each alone, numbered past the others
    if ok.any():
        ids[ok] = _row_ranks(key[ok])
    return ids


def _row_ranks(rows: np.ndarray) -> np.ndarray:
    """(n,) int64 rank of each row of rows (n, m) among the distinct rows in lexicographic
    order: `np.unique(rows, axis=0, return_inverse=True)[1]`, which sorts the rows as records
    and took a second a pass for a million visible points; one lexsort takes a tenth."""
    order = np.lexsort(rows.T[::-1])
    ordered = rows[order]
    new = np.empty(len(rows), bool)
    new[0] = True
    new[1:] = (ordered[1:] != ordered[:-1]).any(axis=1)
    ranks = np.empty(len(rows), np.int64)
    ranks[order] = np.cumsum(new) - 1
    return ranks


class Found:
    """The pairs of one search at the widest radii of a pass, answering the narrower steps'
    searches by filtering them (the part of a `PointIndex` a progressive state reads)."""

    def __init__(self, index: PointIndex, pairs: Pairs) -> None:
        """The pairs `pairs` found by `index` (whose points and normals it passes on)."""
        self.position, self.normal, self.pairs = index.position, index.normal, pairs

    def within(
        self, photons: PhotonMap, radius: np.ndarray | float, watch: Stopwatch | None = None
    ) -> Pairs:
        """The pairs closer than radius ((N,) per point or one value) of the point, from
        those found (the same photons: `photons` is the searched pass)."""
        with (watch or Stopwatch())(GATHER):
            p = self.pairs
            keep = (
                p.distance
                < np.broadcast_to(np.asarray(radius, np.float64), (len(self.position),))[p.point]
            )
            return Pairs(p.point[keep], p.photon[keep], p.distance[keep])


class HeldOutState:
    """A progressive run at a ladder of radius scales in two halves of the photon paths, with
    the held-out choice of scale; the interface of a progressive state (`add`, `irradiance`,
    counters, `arrays` / `from_arrays` for checkpoints)."""

    def __init__(
        self, start: Callable[[int, np.ndarray], Any], n: int, radius: float | np.ndarray
    ) -> None:
        """n points' runs from `start` at each scale of the initial radii `radius` (one, or
        (n,) per point, scene units), in both halves, nothing gathered."""
        self.start = start  # (n, (n,) radii) -> the method's own state
        self.radius = np.broadcast_to(np.asarray(radius, np.float64), (n,)).copy()
        self.runs = [[start(n, s * self.radius) for s in LADDER] for _ in range(HALVES)]
        self.live = len(LADDER)  # steps 0 … live − 1 still run
        self.passes = 0  # passes run (a half may get no path of a one-path pass)
        self.indexes: list[PointIndex] = []  # one per half: its grids at the widest radii
        self.scratch: tuple[np.ndarray, ...] | None = None  # `kept`
        # (n, 3) where each point lies (scene units), for the pruning's blocks; None: unknown
        self.position: np.ndarray | None = None

    @property
    def paths(self) -> int:
        """Emitted photon paths so far (both halves): the next pass's first path number."""
        return sum(run[0].paths for run in self.runs)

    @property
    def photons(self) -> int:
        """Caustic photons stored so far (both halves)."""
        return sum(run[0].photons for run in self.runs)

    def add(self, index: PointIndex, photons: PhotonMap, watch: Stopwatch | None = None) -> None:
        """Gather one pass into every live step of both halves (one search per half, at the
        widest radius, filtered for the narrower steps), then drop the wide steps far from
        the current minimum."""
        if not self.indexes:
            self.indexes = [PointIndex(index.position, index.normal) for _ in range(HALVES)]
            self.position = index.position

        def gather(h: int, states: list[Any], part: PhotonMap) -> None:
            if all(getattr(state, "SUMS", False) for state in states):
                # point by point, no pair stored (`disc_sums`): on the examples' default
                # `ppm` runs, 2.1× faster a pass than the pairs (docs/benchmarks.md)
                scratch = self.kept(len(states))
                reach = np.stack([state.reach for state in states], out=scratch[0])
                with (watch or Stopwatch())(GATHER):
                    found, flux = disc_sums(
                        part, self.position, self.indexes[h].normal, reach, out=scratch[1:]
                    )
                for k, state in enumerate(states):
                    state.add_found(found[k], flux[k], part)
                return
            reach = np.max([state.reach for state in states], axis=0)
            found = Found(self.indexes[h], self.indexes[h].within(part, reach, watch))
            for state in states:
                state.add(found, part, watch)

        self.add_pass(gather, photons)

    def kept(self, s: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """(reach (s, n), found (s, n), flux (s, n, 3)) float64 scratch kept from pass to pass
        for s live steps (`disc_sums`' out: fresh arrays of a million points' sums were
        hundreds of MB of new pages each pass)."""
        if self.scratch is None:
            n, steps = len(self.radius), len(LADDER)
            self.scratch = (np.empty((steps, n)), np.empty((steps, n)), np.empty((steps, n, 3)))
        return self.scratch[0][:s], self.scratch[1][:s], self.scratch[2][:s]

    def add_pass(
        self, gather: Callable[[int, list[Any], PhotonMap], None], photons: PhotonMap
    ) -> None:
        """One pass: `gather(h, states, part)` brings half h's photons `part` into its live
        steps' states; then the wide steps far from the current minimum are dropped."""
        first = self.paths  # paths are dealt by their number in the run, not in the pass
        for h, run in enumerate(self.runs):
            part = half(photons, h, first)
            if part.n_paths:  # a one-path pass has nothing for one half
                gather(h, run[: self.live], part)
        self.passes += 1
        self.live = self.still_live()

    def terms(self) -> np.ndarray:
        """(live, n) each point's term of each live step's held-out score,
        (A_s − B_s₀)² + (B_s − A_s₀)², luminance of irradiance."""
        a = [luminance(s.irradiance()) for s in self.runs[0][: self.live]]
        b = [luminance(s.irradiance()) for s in self.runs[1][: self.live]]
        return np.array([(a[j] - b[0]) ** 2 + (b[j] - a[0]) ** 2 for j in range(len(a))])

    def scores(self) -> np.ndarray:
        """(live,) held-out score of each live step: its terms summed over the points."""
        return self.terms().sum(axis=1)

    def still_live(self) -> int:
        """How many steps run on: all up to the first one more than KEEP wider than the
        minimum whose score is above it by more than Z standard errors of the difference,
        taken over the points and, where their positions are known, over blocks of space
        (`block_sums`)."""
        terms = self.terms()
        scores = terms.sum(axis=1)
        k = int(np.argmin(scores))
        for j in range(k + 1 + KEEP, self.live):
            d = terms[j] - terms[k]
            if scores[j] - scores[k] > Z * np.sqrt(np.sum(d**2)) and (
                self.position is None
                or scores[j] - scores[k] > Z * np.sqrt(np.sum(self.block_sums(j, d) ** 2))
            ):
                return j
        return self.live

    def block_sums(self, j: int, values: np.ndarray) -> np.ndarray:
        """(blocks,) the per-point values (n,) summed over the blocks of space of step j's
        discs (`block_ids`)."""
        reach = np.maximum(self.runs[0][j].reach, self.runs[1][j].reach)
        return np.bincount(block_ids(self.position, reach), weights=values)

    def best(self) -> int:
        """The live step of least held-out score."""
        return int(np.argmin(self.scores()))

    def chosen(self) -> int:
        """The step the run keeps: NARROWER steps narrower than the minimum."""
        return max(self.best() - NARROWER, 0)

    def scale(self) -> float:
        """The chosen multiple of the view-relative initial radius."""
        return float(LADDER[self.chosen()])

    def irradiance(self) -> np.ndarray:
        """(n, 3) float64 caustic irradiance: the two halves' mean at the chosen step, each
        weighted by its paths (W m⁻²)."""
        j = self.chosen()
        total = sum(run[j].paths * run[j].irradiance() for run in self.runs)
        return total / max(self.paths, 1)

    def arrays(self) -> dict[str, np.ndarray]:
        """Everything needed to resume: each live run's arrays, prefixed 'h.j.'."""
        out = {"radius": self.radius, "live": np.asarray(self.live)}
        out["held_out_passes"] = np.asarray(self.passes)
        for h, run in enumerate(self.runs):
            for j in range(self.live):
                out |= {f"{h}.{j}.{k}": v for k, v in run[j].arrays().items()}
        return out

    def from_arrays(self, a: dict[str, np.ndarray]) -> HeldOutState:
        """The state `arrays` saved, its runs of the same class as this one's."""
        kind = type(self.runs[0][0])
        names = [f.name for f in fields(kind)]
        try:
            out = HeldOutState(self.start, len(a["radius"]), a["radius"])
            out.live, out.passes = int(a["live"]), int(a["held_out_passes"])
            for h, run in enumerate(out.runs):
                for j in range(out.live):
                    run[j] = kind.from_arrays({k: a[f"{h}.{j}.{k}"] for k in names})
        except KeyError as exc:
            raise InputError(f"not a checkpoint of a held-out run (no {exc})") from None
        return out
