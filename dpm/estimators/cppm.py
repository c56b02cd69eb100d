"""`cppm`: chi-squared progressive photon mapping (after Lin et al., SIGGRAPH Asia 2020).

PPM shrinks every radius after every pass, trading variance for bias even where the photon
density inside the disc is flat and a smaller disc would only add noise. CPPM shrinks a
point's radius only when a chi-squared test says the photons in its disc are not uniform.

Our test: the disc is split into 8 cells of equal area (an inner disc of radius R/√2 and the
ring around it, each in 4 quadrants of the point's tangent plane), so a gradient shows as
quadrant asymmetry and curvature as inner/outer imbalance. A point's cell counts accumulate
over the passes that kept its radius; once every cell expects at least MIN_EXPECTED photons,
χ² = Σ (O − E)²/E is compared with the (1 − SIGNIFICANCE) quantile of χ²(7):
- uniform, or too few photons to test yet: keep R, N' = N + M, τ' = τ + Φ (every photon
  counts at full weight) and the cell counts go on;
- not uniform: PPM's step for the A photons gathered since R last changed, as if they had
  come in one pass (N' = N − (1 − α)A, R'² = R² N'/N, τ' = τ R'²/R², N and τ including
  them), and the counts start again.
Shrinking whenever a pass is too small to test (our first version) started the counts
again every pass, so at a few photons per pass CPPM never tested and was PPM.
Consistent whatever the scene: any non-uniformity is found once enough photons arrive (the
test's power tends to 1), so the radius shrinks wherever the density varies, and where the
density is flat a disc average is the point's value.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import ClassVar

import numpy as np

from dpm.density.base import in_plane, tangent_frame
from dpm.density.gather import PointIndex
from dpm.density.progressive import ALPHA
from dpm.estimators.ppm import PPMState, Progressive, Radius, start_radius
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap

CELLS = 8  # equal-area cells of the disc: 2 rings × 4 quadrants
MIN_EXPECTED = 5  # photons each cell must expect before the test is trusted (the usual rule)
SIGNIFICANCE = 0.05  # chance of calling a uniform disc non-uniform (then it shrinks, as PPM)
# χ² upper quantile, scipy.special.chdtri(CELLS - 1, SIGNIFICANCE) (checked in tests): written
# out, as importing scipy at start costs every render, caustics or not, a tenth of a second
CRITICAL = 14.067140449340167


@dataclass
class CPPMState(PPMState):
    """PPM's per-point statistics (and its irradiance), with each disc's cell counts."""

    SUMS: ClassVar[bool] = False  # reads the pairs (`add`)

    cells: np.ndarray  # (n, CELLS) float64 photons per cell since R last changed

    @classmethod
    def start(cls, n: int, radius: float | np.ndarray, alpha: float = ALPHA) -> CPPMState:
        """A state of n points with initial radius `radius` (one, or (n,) per point) and
        nothing gathered."""
        return cls(
            start_radius(n, radius), np.zeros(n), np.zeros((n, 3)), np.zeros((n, CELLS)),
            alpha=alpha,
        )  # fmt: skip

    def add(self, index: PointIndex, photons: PhotonMap, watch: Stopwatch | None = None) -> None:
        """Gather one pass, test each disc's uniformity, shrink the radii of the others."""
        pairs = index.within(photons, self.radius, watch)
        point, n = pairs.point, len(self.radius)
        flux = photons.flux[pairs.photon].astype(np.float64) * photons.n_paths
        offset = photons.position[pairs.photon].astype(np.float64) - index.position[point]
        t, b = tangent_frame(index.normal[point])
        outer = pairs.distance**2 > self.radius[point] ** 2 / 2
        ab = in_plane(offset, t, b)
        quadrant = 2 * (ab[:, 0] > 0) + (ab[:, 1] > 0)
        cell = CELLS // 2 * outer + quadrant
        self.cells += np.bincount(point * CELLS + cell, minlength=n * CELLS).reshape(n, CELLS)
        phi = np.stack([np.bincount(point, flux[:, c], minlength=n) for c in range(3)], 1)
        self.count = self.count + np.bincount(point, minlength=n)
        self.tau = self.tau + phi
        since = self.cells.sum(axis=1)  # photons gathered since R last changed
        expected = since / CELLS
        with np.errstate(divide="ignore", invalid="ignore"):
            statistic = ((self.cells - expected[:, None]) ** 2).sum(axis=1) / expected
        # too few photons to test: R stays and the counts go on (see the module docstring)
        shrink = (expected >= MIN_EXPECTED) & (statistic > CRITICAL)
        # PPM's step for the photons since the last change, as if they came in one pass
        shrunk = self.count - (1 - self.alpha) * since
        ratio = np.divide(shrunk, self.count, out=np.ones(n), where=shrink)
        self.radius = self.radius * np.sqrt(ratio)
        self.tau = self.tau * ratio[:, None]
        self.count = self.count * ratio
        self.cells[shrink] = 0
        self.paths += photons.n_paths
        self.passes += 1
        self.photons += len(photons)


@dataclass(frozen=True)
class CPPM(Progressive):
    """CPPM at fixed visible points: initial radius (scene units), emitted paths per pass."""

    name: ClassVar[str] = "cppm"
    summary: ClassVar[str] = (
        "chi-squared PPM: a radius shrinks only where its disc's photons are not uniform"
    )

    def start(self, n: int, radius: Radius) -> CPPMState:
        """The state before the first pass, for n points with initial radius `radius`."""
        return CPPMState.start(n, radius, self.alpha)
