"""How far to move the caustic estimate towards other estimates, fitted on its two halves.

`auto`'s caustic is SPPM's estimate a (the wide kernel, or the narrow one where Lepski's rule
sees the wide one blur). Other estimates b_i of the same light differ from it by moves
x_i = b_i − a: the narrow kernel's everywhere (less blur, more noise), the extrapolated
one's (`stats.extrapolated`: blur cancelled to second order, more noise still), the learned
filter's. The render keeps a + Σ w_i·x_i with the weights that bring one half of the passes
closest to the other half's extrapolated estimate t (`PassHalves`): least squares over the
pixels, minimise |a + Σ w_i x_i − t|², on the simplex w_i ≥ 0, Σ w_i ≤ 1. t's noise is
independent of the first half's, so it adds the same to every blend's error, and its bias
is the least the render has. The simplex keeps the result a convex blend of non-negative,
consistent images: non-negative and consistent whatever the fit says (past it the blend
could cross zero: the glass egg's floor broke into dark holes with a filter weight of 1.5).
"""

from __future__ import annotations

import itertools

import numpy as np


def blend_weights(moves: list[np.ndarray], residual: np.ndarray) -> np.ndarray:
    """(n,) float64 weights w ≥ 0, Σ w ≤ 1 minimising |Σ w_i·moves_i − residual|², for n ≤ 3
    moves and residual t − a of one shape (any, e.g. (P, 3)), over the entries where all are
    finite; a move that is zero there (no evidence either way) gets weight 0."""
    x = np.stack([m.ravel() for m in moves])
    r = residual.ravel()
    finite = np.isfinite(r) & np.isfinite(x).all(axis=0)
    if not finite.all():
        x, r = x[:, finite], r[finite]
    gram, g = x @ x.T, x @ r
    n = len(moves)
    usable = [i for i in range(n) if gram[i, i] > 0]
    best, best_w = 0.0, np.zeros(n)  # w = 0 costs 0 in the objective below
    # The minimum lies in the interior of one face of the simplex: try each face's
    # unconstrained minimum (free weights on a subset, either with the rest 0 or with the
    # sum held at 1) and keep the best feasible one.
    for size in range(1, len(usable) + 1):
        for free in itertools.combinations(usable, size):
            for w in _face_minima(gram, g, list(free), n):
                if w is None or (w < -1e-12).any() or w.sum() > 1 + 1e-12:
                    continue
                w = np.clip(w, 0.0, 1.0)
                cost = float(w @ gram @ w - 2 * g @ w)  # |Σ w x − r|² − |r|²
                if cost < best:
                    best, best_w = cost, w
    return best_w


def _face_minima(gram: np.ndarray, g: np.ndarray, free: list[int], n: int) -> list:
    """The least-squares weights with only `free` non-zero: unconstrained, and with their
    sum held at 1 (None where the system is singular)."""
    sub, rhs = gram[np.ix_(free, free)], g[free]
    out = []
    for on_edge in (False, True):
        w = np.zeros(n)
        try:
            if on_edge:  # Lagrange: [G 1; 1ᵀ 0] [w; λ] = [g; 1]
                k = len(free)
                m = np.zeros((k + 1, k + 1))
                m[:k, :k], m[:k, k], m[k, :k] = sub, 1.0, 1.0
                w[free] = np.linalg.solve(m, np.append(rhs, 1.0))[:k]
            else:
                w[free] = np.linalg.solve(sub, rhs)
        except np.linalg.LinAlgError:
            w = None
        out.append(w)
    return out
