"""Inference: the DPM estimate as a pure function of (params, inputs) under `jit` and `vmap`.

`neighbourhoods` gathers the K nearest photons of visible points (numpy, cKDTree) into
`Batch`es; `make_predict(model)` returns a jitted function (params, Batch) -> (B, 3) radiance,
vmapped over points; `predict_points` runs it over a whole set of points in fixed-size chunks
(one compilation per K, bounded memory).
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from dpm.density.gather import PhotonIndex, photon_index, take
from dpm.nn.features import MIN_RADIUS, canonical_angle, features, kernel_estimate
from dpm.nn.model import KernelNet
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap

ACTIVATIONS_PER_CHUNK = 1 << 19  # points per chunk × K: bounds the activations' memory


class Batch(NamedTuple):
    """The K nearest photons of B visible points, relative to each point (a JAX pytree)."""

    offset: np.ndarray  # (B, K, 3) float32 photon position - point position (scene units)
    direction: np.ndarray  # (B, K, 3) float32 unit direction towards the photon's source
    flux: np.ndarray  # (B, K, 3) float32 stored flux (W, already ÷ N)
    valid: np.ndarray  # (B, K) bool: a photon whose normal agrees with the point's
    normal: np.ndarray  # (B, 3) float32 unit normal of the point
    albedo: np.ndarray  # (B, 3) float32 Lambertian albedo of the point
    radius: np.ndarray  # (B,) float32 bandwidth r: distance to the K-th photon
    angle: np.ndarray  # (B,) float32 tangent-frame rotation about the normal (radians; NaN:
    # the canonical angle, towards the neighbours' mean offset)
    n_paths: np.ndarray  # (B,) float32 emitted photon paths N of the map


def point_radiance(model: nn.Module, params: dict, b: Batch) -> jnp.ndarray:
    """(3,) caustic radiance of one point (a Batch without its leading axis) by Eq. 2."""
    angle = jnp.where(jnp.isnan(b.angle), canonical_angle(b.offset, b.valid, b.normal), b.angle)
    x = features(b.offset, b.direction, b.flux, b.normal, b.radius, b.n_paths, angle)
    out = model.apply(params, x, b.valid)
    if isinstance(model, KernelNet):
        return kernel_estimate(out, b.flux, b.valid, b.albedo, b.radius)
    # direct regression: the mean photon power over the disc, back to radiance
    flux = b.valid.sum() * out / b.n_paths
    return b.albedo / jnp.pi * flux / (jnp.pi * jnp.maximum(b.radius, MIN_RADIUS) ** 2)


def make_predict(model: nn.Module) -> Callable[[dict, Batch], jnp.ndarray]:
    """A jitted pure function (params, Batch of B points) -> (B, 3) float32 radiance."""
    return jax.jit(jax.vmap(lambda params, b: point_radiance(model, params, b), (None, 0)))


def neighbourhoods(
    photons: PhotonMap | PhotonIndex,
    position: np.ndarray,
    normal: np.ndarray,
    albedo: np.ndarray,
    k: int,
    angle: np.ndarray | None = None,
    watch: Stopwatch | None = None,
) -> Iterator[tuple[slice, Batch]]:
    """Batches of the k nearest photons of points (N, 3) with normals and albedos (N, 3);
    angle (N,) turns each tangent frame (default: the canonical angle). Pass a PhotonIndex to
    query one tree for many calls; gathering counts as the watch's "gather"."""
    index = photon_index(photons, watch)
    photons = index.photons
    angle = np.full(len(position), np.nan, np.float32) if angle is None else angle
    for rows, nb in index.nearest(position, normal, k, watch):
        here = np.asarray(position[rows], np.float64)
        radius = np.where(np.isfinite(nb.distance[:, -1]), nb.distance[:, -1], 0.0)
        offset = take(photons.position, nb.index).astype(np.float64) - here[:, None, :]
        offset[nb.index >= len(photons)] = 0.0  # missing neighbours (fewer photons than k)
        yield rows, Batch(
            offset.astype(np.float32), take(photons.direction, nb.index),
            take(photons.flux, nb.index), nb.valid,
            np.asarray(normal[rows], np.float32), np.asarray(albedo[rows], np.float32),
            radius.astype(np.float32), np.asarray(angle[rows], np.float32),
            np.full(len(here), photons.n_paths, np.float32),
        )  # fmt: skip


MIN_CHUNK = 256  # smallest padded chunk: points


def chunk_size(k: int) -> int:
    """Points per inference chunk for K neighbours."""
    return max(1, ACTIVATIONS_PER_CHUNK // k)


def pad_batch(b: Batch, size: int) -> Batch:
    """b with its leading axis zero-padded to `size` rows (so every chunk has one shape)."""
    extra = size - len(b.radius)
    return Batch(*(np.concatenate([a, np.zeros((extra, *a.shape[1:]), a.dtype)]) for a in b))


def predict_points(
    predict: Callable[[dict, Batch], jnp.ndarray],
    params: dict,
    photons: PhotonMap | PhotonIndex,
    position: np.ndarray,
    normal: np.ndarray,
    albedo: np.ndarray,
    k: int,
    watch: Stopwatch | None = None,
) -> np.ndarray:
    """(N, 3) float32 radiance at points (N, 3) from their k nearest photons, chunk by chunk;
    gathering counts as the watch's "gather" (the caller times the rest)."""
    out = np.zeros((len(position), 3), np.float32)
    size = chunk_size(k)
    for rows, b in neighbourhoods(photons, position, normal, albedo, k, watch=watch):
        for first in range(0, len(b.radius), size):
            part = Batch(*(a[first : first + size] for a in b))
            n = len(part.radius)
            # a short chunk pads to a power of two, not to `size`: few shapes, little waste
            padded = min(size, max(MIN_CHUNK, 1 << (n - 1).bit_length()))
            result = np.asarray(predict(params, pad_batch(part, padded)))[:n]
            out[rows.start + first : rows.start + first + n] = result
    return out
