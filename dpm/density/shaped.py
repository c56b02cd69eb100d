"""A shaped progressive kernel: an anisotropic Gaussian truncated at the radius, normalised
exactly, and the per-point photon statistics a network reads to choose its shape (nppm).

In a point's disc of radius R, with photon offsets (a, b) / R along the point's principal
axes e₁, e₂, the kernel relative to the uniform disc (PPM's) is

    w(a, b) = π · exp(−(p₁ a² + p₂ b²) / 2) / Z(p₁, p₂),   Z = ∫_{unit disc} exp(−(p₁a² + p₂b²)/2),

so ∫_disc w / (π R²) = 1 whatever the precisions p₁, p₂ (in units of 1/R²): a density
estimate's expectation under a uniform density does not depend on the shape. Z has a closed
radial integral, Z = ∫₀^{2π} (1 − e^{−s(θ)/2}) / s(θ) dθ with s(θ) = p₁cos²θ + p₂sin²θ, and the
periodic angular integral is taken by the trapezoid rule, exact to float precision with
NODES nodes. p = 0 is the uniform kernel (w = 1 exactly). The precisions are bounded,
P_MIN ≤ p ≤ P_MAX, so w ≤ 13 and the kernel is even: with PPM's shrinking radius the estimate
stays consistent whatever a network chooses (bias O(R²), variance within 13² of PPM's).

The statistics (`MOMENTS` per point, photon positions in the fixed tangent frame of
`tangent_frame`, divided by the radius at gathering) give a frame e₁, e₂ (the principal axes
of the photons' spread) and features invariant to turning or mirroring the tangent frame.
Kernel functions take the array module (`numpy` or `jax.numpy`): the render uses NumPy, the
training JAX, the same code.
"""

from __future__ import annotations

from typing import Any

import numpy as np

NODES = 32  # trapezoid nodes over [0, π) for Z (the integrand has period π)
P_MAX = 24.0  # largest precision: σ = R / √24 ≈ 0.2 R
P_MIN = -2.0  # smallest: a kernel at most e ≈ 2.7× heavier at the rim than at the centre
MOMENTS = 9  # n, Σa², Σab, Σb², Σa, Σb, Σ(a²+b²)², Σdₐ, Σd_b (d: incident direction)
FEATURES = 8  # what `features` gives per point
_THETA = (np.arange(NODES) + 0.5) * np.pi / NODES


def precision(raw: Any, xp: Any = np) -> Any:
    """(…) precisions in [P_MIN, P_MAX] from unbounded network outputs (…); 0 ↦ 0, slope 1."""
    return xp.where(raw >= 0, P_MAX * xp.tanh(raw / P_MAX), -P_MIN * xp.tanh(raw / -P_MIN))


def normaliser(p1: Any, p2: Any, xp: Any = np) -> Any:
    """(…) Z(p₁, p₂): the integral of exp(−(p₁a² + p₂b²)/2) over the unit disc (π at p = 0)."""
    c2 = xp.asarray(np.cos(_THETA) ** 2)
    s = p1[..., None] * c2 + p2[..., None] * (1.0 - c2)
    small = xp.abs(s) < 1e-4
    safe = xp.where(small, 1.0, s)
    g = xp.where(small, 0.5 - s / 8.0 + s * s / 48.0, -xp.expm1(-safe / 2.0) / safe)
    return 2.0 * np.pi * xp.mean(g, axis=-1)


def relative_weight(a: Any, b: Any, p1: Any, p2: Any, xp: Any = np, z: Any = None) -> Any:
    """(…) kernel weight relative to the uniform disc of photons at (a, b) (units of R, along
    e₁, e₂) under precisions p₁, p₂ (…): 1 everywhere when p₁ = p₂ = 0. `z`: their
    `normaliser`, when the caller has it per point rather than per photon."""
    z = normaliser(p1, p2, xp) if z is None else z
    return np.pi * xp.exp(-0.5 * (p1 * a * a + p2 * b * b)) / z


def pair_moments(point: np.ndarray, n: int, ab: np.ndarray, direction_ab: np.ndarray) -> np.ndarray:
    """(n, MOMENTS) float64 sums over photons of points `point` (Q,) of their offsets ab
    (Q, 2, units of R) and incident tangent directions (Q, 2) in the fixed tangent frame."""
    a, b = ab[:, 0], ab[:, 1]
    r2 = a * a + b * b
    columns = (np.ones_like(a), a * a, a * b, b * b, a, b, r2 * r2, *direction_ab.T)
    return np.stack([np.bincount(point, c, minlength=n) for c in columns], axis=1)


def principal_axes(moments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """(n,) cos and sin of the angle of e₁, the major axis of the photons' spread in the fixed
    tangent frame, from moments (n, MOMENTS) (angle 0 where there is none)."""
    saa, sab, sbb = moments[:, 1], moments[:, 2], moments[:, 3]
    angle = 0.5 * np.arctan2(2.0 * sab, saa - sbb)
    return np.cos(angle), np.sin(angle)


def to_axes(ab: np.ndarray, cos: np.ndarray, sin: np.ndarray) -> np.ndarray:
    """(Q, 2) coordinates along e₁, e₂ of vectors ab (Q, 2) in the fixed tangent frame."""
    a, b = ab[:, 0], ab[:, 1]
    return np.stack([a * cos + b * sin, -a * sin + b * cos], axis=1)


def features(moments: np.ndarray) -> np.ndarray:
    """(n, FEATURES) float32 network input from accumulated moments (n, MOMENTS): the log
    count, the spread's eigenvalues
    (×4: 1 for a uniform disc), ⟨r⁴⟩ (×3: 1 when uniform), and |mean offset| and |mean
    direction| along e₁, e₂; the shape terms are the uniform disc's where n = 0."""
    n = moments[:, 0]
    inv = 1.0 / np.maximum(n, 1e-12)
    saa, sab, sbb = moments[:, 1] * inv, moments[:, 2] * inv, moments[:, 3] * inv
    half = np.sqrt(((saa - sbb) / 2) ** 2 + sab**2)
    cos, sin = principal_axes(moments)
    offset = to_axes(moments[:, 4:6] * inv[:, None], cos, sin)
    direction = to_axes(moments[:, 7:9] * inv[:, None], cos, sin)
    empty = n <= 0
    f = np.stack([
        np.log1p(n),
        np.where(empty, 1.0, 4 * ((saa + sbb) / 2 + half)),
        np.where(empty, 1.0, 4 * ((saa + sbb) / 2 - half)),
        np.where(empty, 1.0, 3 * moments[:, 6] * inv),
        *np.abs(offset).T, *np.abs(direction).T,
    ], axis=1)  # fmt: skip
    return f.astype(np.float32)
