"""Input pre-processing of the DPM network (paper §4.1) and the estimate it feeds (Eq. 2).

Each visible point's K nearest photons become a (K, 9) array: positions in the point's local
frame divided by the bandwidth r (the K-th neighbour's distance), directions in the same frame,
and flux mapped by t_a (Eq. 3) to [-1, 1]. The flux the network sees is the photon's power
relative to its map's median photon power, times the training set's typical power (flux ×
`dpm.nn.infer.feature_paths`, the paper's flux × N rescaled): changing N with the stored flux
scaled to match changes nothing, and neither does making every light brighter or the scene
larger (the paper's absolute power did: the image was not linear in the light). The estimate
is L = ρ/π · Σ wᵢ Φᵢ / (π r²) with the stored flux Φᵢ (already ÷ N): Eq. 2 with the
Lambertian BRDF ρ/π written out, so that wᵢ = 1 is the uniform kernel (PM, Eq. 1) and the
radiance agrees with every other estimator's.
All functions here are pure JAX on one point; callers `vmap` them. The tangents are turned
at random about the normal in training and towards the neighbours' mean offset at inference
(`canonical_angle`), so that the estimate is invariant to rotations about the normal.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp

FLUX_A = 0.01  # a of t_a (Eq. 3)
CHANNELS = 9  # position (3), direction (3), flux (3)
MIN_RADIUS = 1e-12  # bandwidth floor (scene units): its square stays a normal float32


def flux_map(u: jnp.ndarray, a: float = FLUX_A) -> jnp.ndarray:
    """(…) t_a(u) of Eq. 3 for u ≥ 0, linearly moved from [0, 1) to [-1, 1)."""
    log = jnp.log1p(jnp.maximum(u, 0.0) / a)  # log(u + a) - log(a)
    return 2.0 * log / (log + 1.0) - 1.0


def flux_unmap(t: jnp.ndarray, a: float = FLUX_A) -> jnp.ndarray:
    """(…) the inverse of `flux_map`: u ≥ 0 for t in [-1, 1)."""
    s = jnp.clip((t + 1.0) / 2.0, 0.0, 0.97)  # log ≤ 32: keeps exp finite in float32
    return a * jnp.expm1(s / (1.0 - s))


def local_frame(normal: jnp.ndarray, angle: jnp.ndarray) -> jnp.ndarray:
    """(3, 3) rows: two tangents turned by `angle` (radians) about the unit normal (3,), then it."""
    # Duff et al. 2017: a continuous orthonormal basis without branches on the normal
    sign = jnp.where(normal[2] >= 0.0, 1.0, -1.0)
    a = -1.0 / (sign + normal[2])
    b = normal[0] * normal[1] * a
    t = jnp.array([1.0 + sign * normal[0] ** 2 * a, sign * b, -sign * normal[0]])
    s = jnp.array([b, sign + normal[1] ** 2 * a, -normal[1]])
    c, si = jnp.cos(angle), jnp.sin(angle)
    return jnp.stack([c * t + si * s, -si * t + c * s, normal])


def to_frame(v: jnp.ndarray, frame: jnp.ndarray) -> jnp.ndarray:
    """(K, 3) vectors v (K, 3) in the rows of frame (3, 3); products and sums, not a matmul,
    so that under `vmap` XLA fuses it instead of running many 3×3 matrix products."""
    return jnp.sum(v[:, None, :] * frame[None, :, :], axis=-1)


def canonical_angle(offset: jnp.ndarray, valid: jnp.ndarray, normal: jnp.ndarray) -> jnp.ndarray:
    """Frame angle that turns the first tangent towards the mean offset (K, 3) of the valid
    photons, projected on the tangent plane: inference then does not depend on how the
    tangents happened to be chosen (training turns them at random instead)."""
    return centre_angle(jnp.sum(jnp.where(valid[:, None], offset, 0.0), axis=0), normal)


def centre_angle(centre: jnp.ndarray, normal: jnp.ndarray) -> jnp.ndarray:
    """Frame angle (radians) that turns the first tangent towards `centre` (3,), a sum of
    offsets, projected on the tangent plane of the unit normal (3,)."""
    frame = local_frame(normal, jnp.zeros(()))
    return jnp.arctan2(centre @ frame[1], centre @ frame[0])


def features(
    offset: jnp.ndarray,
    direction: jnp.ndarray,
    flux: jnp.ndarray,
    normal: jnp.ndarray,
    radius: jnp.ndarray,
    n_paths: jnp.ndarray,
    angle: jnp.ndarray,
) -> jnp.ndarray:
    """(K, 9) network input of one point from photon offsets x_i - x (K, 3, scene units),
    unit directions (K, 3), stored flux (K, 3, W ÷ N), the point's normal (3,), bandwidth r,
    the map's `feature_paths` n_paths (N rescaled to its power) and the tangent rotation
    angle."""
    frame = local_frame(normal, angle)
    position = to_frame(offset, frame) / jnp.maximum(radius, MIN_RADIUS)
    return jnp.concatenate(
        [position, to_frame(direction, frame), flux_map(flux * n_paths)], axis=-1
    ).astype(jnp.float32)


def kernel_estimate(
    weight: jnp.ndarray, flux: jnp.ndarray, valid: jnp.ndarray, albedo: jnp.ndarray, radius
) -> jnp.ndarray:
    """(3,) radiance ρ/π · Σ wᵢ Φᵢ / (π r²) (Eq. 2) from kernel weights (K,), stored flux
    (K, 3), valid (K,) bool, albedo (3,) and bandwidth r (scene units)."""
    total = jnp.sum(jnp.where(valid[:, None], weight[:, None] * flux, 0.0), axis=0)
    return albedo / jnp.pi * total / (jnp.pi * jnp.maximum(radius, MIN_RADIUS) ** 2)


def uniform_radiance(batch) -> jnp.ndarray:
    """(B, 3) PM-K radiance of a Batch of B points (`dpm.nn.infer.Batch`): Eq. 2 with every
    weight 1, the network's starting point."""
    return jax.vmap(
        lambda b: kernel_estimate(jnp.ones(b.valid.shape), b.flux, b.valid, b.albedo, b.radius)
    )(batch)
