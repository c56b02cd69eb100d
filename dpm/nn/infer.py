"""Inference: the DPM estimate as a pure function of (params, inputs) under `jit` and `vmap`.

`neighbourhoods` gathers the K nearest photons of visible points (numpy, cKDTree) into
`Batch`es (training reads these); `make_predict(model)` returns a jitted function
(params, Batch) -> (B, 3) radiance. Rendering uses `make_query_predict`, which takes the
photon map's arrays once and each chunk of points as indices of their neighbours (`Query`),
so gathering the (B, K, 3) photon arrays happens inside the jitted function;
`predict_points` runs it over a whole set of points in chunks sized to stay in the caches,
each gathered block in two halves at once. The KernelNet is evaluated as flat matmuls over all the
chunk's photons, feature-major: activations (width, B·K), so each layer is a (width × width)
by (width × B·K) product, which XLA's dots run faster than the transposed thin (B·K × width)
one (`kernel_logits`). On the CPU, rendering with the shipped architecture runs a step's whole
estimate as one fused kernel instead (`dpm.nn.fused`, called from inside the jitted function).
All equal the per-point Flax `apply` within float rounding (tested).
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from typing import NamedTuple

import flax.linen as nn
import jax
import jax.numpy as jnp
import numpy as np

from dpm.density.gather import NORMAL_COS, PhotonIndex, photon_index, take
from dpm.nn.features import (
    MIN_RADIUS,
    canonical_angle,
    centre_angle,
    features,
    flux_map,
    kernel_estimate,
    local_frame,
)
from dpm.nn.fused import available, fused_radiance, pack_params, supports
from dpm.nn.model import SHIFT, KernelNet
from dpm.stopwatch import Stopwatch
from dpm.tracer import PhotonMap

# The photon power (W, max channel of flux × N) the flux feature puts a map's median photon at:
# the training set's typical one (each map's median, then the median over the first 12
# training scenes of configs' seed 0: 59; the maps' own medians span 16-86).
REFERENCE_POWER = 59.0
POWER_SAMPLE = 4096  # about this many photons, spread over the map, give its median power
ACTIVATIONS_PER_CHUNK = 1 << 11  # points per chunk × K: activations (32 × this) stay in L2
BLOCKS_IN_FLIGHT = 2  # parts of a block run at once: one's serial parts overlap the other's
FUSED = True  # render with the fused CPU kernel where it applies (`use_fused`)


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
    n_paths: np.ndarray  # (B,) float32 the map's `feature_paths`: N scaled to its power


def feature_paths(photons: PhotonMap) -> float:
    """The N by which the features multiply stored flux (÷ N): N · REFERENCE_POWER / the map's
    median photon power, so the network sees each photon's power relative to its map's, at
    the training set's typical scale (N where no photon carries light).

    With the absolute power (the paper's t_a of flux × N) a scene whose lights are all c
    times brighter got other kernels, and its image was not c times as bright; a scene scaled
    by 0.01 with its radiance kept (each photon 10⁴ times dimmer) got 6x the error. Now both
    get the same inputs, and Eq. 2, linear in the stored flux, scales the estimate. The median
    is the whole map's: photons out of view (another light's caustic) move it too.
    """
    flux = photons.flux
    if len(flux) > POWER_SAMPLE:  # a fixed random sample: a stride could follow the paths
        flux = flux[np.random.default_rng(0).integers(0, len(flux), POWER_SAMPLE)]
    power = flux.max(axis=1, initial=0.0)
    power = power[power > 0].astype(np.float64) * photons.n_paths
    if len(power) == 0:
        return float(photons.n_paths)
    return float(photons.n_paths * REFERENCE_POWER / np.median(power))


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


def _dense(layer: dict, x: jnp.ndarray) -> jnp.ndarray:
    """(out, R) kernelᵀ x + bias of one Flax Dense layer's params on feature-major rows
    x (in, R)."""
    return layer["kernel"].T @ x + layer["bias"][:, None]


def kernel_radiance(params: dict, b: Batch) -> jnp.ndarray:
    """(B, 3) radiance of B points by KernelNet's params: `point_radiance` rewritten as flat
    matmuls over the B·K photon rows, for speed (equal within float rounding, tested)."""
    canonical = jax.vmap(canonical_angle)(b.offset, b.valid, b.normal)
    angle = jnp.where(jnp.isnan(b.angle), canonical, b.angle)
    x = jax.vmap(features)(b.offset, b.direction, b.flux, b.normal, b.radius, b.n_paths, angle)
    x = jnp.moveaxis(x, 2, 0)  # (9, B, K)
    return kernel_head(params["params"], x, b.valid, b.flux, b.albedo, b.radius)


def kernel_head(
    p: dict,
    x: jnp.ndarray,
    valid: jnp.ndarray,
    flux: jnp.ndarray,
    albedo: jnp.ndarray,
    radius: jnp.ndarray,
) -> jnp.ndarray:
    """(B, 3) radiance of B points from the network inputs x (9, B, K) of their K photons
    (valid (B, K), stored flux (B, K, 3), albedo (B, 3), bandwidth (B,)): KernelNet's logits
    (`kernel_logits`), then Eq. 2."""
    z = kernel_logits(p, x, valid)
    weight = jnp.where(valid, jax.nn.softplus(z + SHIFT), 0.0)
    return jax.vmap(kernel_estimate)(weight, flux, valid, albedo, radius)


def kernel_logits(p: dict, x: jnp.ndarray, valid: jnp.ndarray) -> jnp.ndarray:
    """(B, K) KernelNet logits (before softplus) from inputs x (9, B, K) and valid (B, K), as
    flat matmuls.

    Activations are feature-major, (width, B·K): each layer is one (width × width) by
    (width × B·K) product, which XLA's dots run faster than the thin (B·K × width) by
    (width × width) one. The predictor's first layer takes [photon feature, context]; its
    context half is applied once per point, not once per photon, which saves a third of the
    network's arithmetic.
    """
    channels, n, k = x.shape
    extractor = p["Extractor_0"]
    h = x.reshape(channels, n * k)
    for name in ("Dense_0", "Dense_1", "Dense_2"):
        h = jax.nn.relu(_dense(extractor[name], h))
    width = h.shape[0]
    # ReLU features are ≥ 0, so zeroing the invalid photons leaves the max over the valid
    # ones (and 0 when none is valid, as the Extractor does), with one masked array
    masked = h.reshape(width, n, k) * valid
    biggest = jnp.max(masked, axis=2)
    mean = jnp.sum(masked, axis=2) / jnp.maximum(valid.sum(1), 1)
    first = p["Dense_0"]
    own, shared = first["kernel"][:width], first["kernel"][width:]
    context = _dense({"kernel": shared, "bias": first["bias"]}, jnp.concatenate([biggest, mean]))
    z = jax.nn.relu((own.T @ h).reshape(width, n, k) + context[:, :, None])
    z = jax.nn.relu(_dense(p["Dense_1"], z.reshape(width, n * k)))
    return _dense(p["Dense_2"], z).reshape(n, k)


def batch_radiance(model: nn.Module) -> Callable[[dict, Batch], jnp.ndarray]:
    """The pure function (params, Batch of B points) -> (B, 3) radiance of `model`."""
    if isinstance(model, KernelNet):
        return kernel_radiance
    return jax.vmap(lambda params, b: point_radiance(model, params, b), (None, 0))


def make_predict(model: nn.Module) -> Callable[[dict, Batch], jnp.ndarray]:
    """A jitted pure function (params, Batch of B points) -> (B, 3) float32 radiance."""
    return jax.jit(batch_radiance(model))


class PhotonTable(NamedTuple):
    """A photon map's arrays as the network reads them: one gather per photon reads a row."""

    rows: jnp.ndarray  # (P + 1, 16) float32: position (3), unit direction towards the source
    # (3), stored flux (3, W ÷ N), unit normal (3), the flux feature flux_map(flux ·
    # `feature_paths`) (3), 0;
    # row P is zeros (a missing neighbour: its zero normal never agrees)


POSITION, DIRECTION, FLUX, NORMAL, FLUX_FEATURE = (slice(i, i + 3) for i in range(0, 15, 3))


def photon_table(photons: PhotonMap, paths: float | None = None) -> PhotonTable:
    """The PhotonTable of a photon map (float32, scene units and W ÷ N); `paths` is the map's
    `feature_paths` where the caller has it already."""
    rows = np.zeros((len(photons.position) + 1, 16), np.float32)
    for columns, values in zip(
        (POSITION, DIRECTION, FLUX, NORMAL),
        (photons.position, photons.direction, photons.flux, photons.normal),
        strict=True,
    ):
        rows[:-1, columns] = values
    paths = feature_paths(photons) if paths is None else paths
    power = photons.flux * np.float32(paths)
    rows[:-1, FLUX_FEATURE] = flux_map(jnp.asarray(power, jnp.float32))
    return PhotonTable(jnp.asarray(rows))


class Query(NamedTuple):
    """B visible points and the indices of their K nearest photons (a JAX pytree)."""

    index: np.ndarray  # (B, K) int32 photon rows; P (the table's length) for a missing one
    position_hi: np.ndarray  # (B, 3) float32 point position rounded to float32
    position_lo: np.ndarray  # (B, 3) float32 what the rounding left out (float64 − hi)
    normal: np.ndarray  # (B, 3) float32 unit normal
    albedo: np.ndarray  # (B, 3) float32 Lambertian albedo
    radius: np.ndarray  # (B,) float32 distance to the K-th photon
    angle: np.ndarray  # (B,) float32 frame rotation (NaN: canonical), as in `Batch`
    n_paths: np.ndarray  # (B,) float32 the map's `feature_paths`


def gathered_batch(table: PhotonTable, q: Query) -> Batch:
    """The Batch of q's points with their photons read from the table inside the jitted
    function, so the (B, K, 3) arrays never pass through numpy.

    Offsets are (photon − hi) − lo in float32: the first difference is exact for nearby
    points (Sterbenz), so the offset keeps the float64 point position's accuracy.
    """
    photon, offset, valid = read_photons(table, q)
    return Batch(
        offset, photon[..., DIRECTION], photon[..., FLUX], valid,
        q.normal, q.albedo, q.radius, q.angle, q.n_paths,
    )  # fmt: skip


def read_photons(table: PhotonTable, q: Query) -> tuple[jnp.ndarray, ...]:
    """q's photons: their rows (B, K, 16), offsets from the points (B, K, 3; zero for a
    missing neighbour) and validity (B, K): the normal agrees with the point's."""
    photon = table.rows[q.index]  # index P reads the zero row
    missing = (q.index >= table.rows.shape[0] - 1)[:, :, None]
    offset = (photon[..., POSITION] - q.position_hi[:, None]) - q.position_lo[:, None]
    # as `PhotonIndex.nearest` checks them; a missing photon's zero normal never agrees
    valid = jnp.sum(photon[..., NORMAL] * q.normal[:, None], axis=-1) >= NORMAL_COS
    return photon, jnp.where(missing, 0.0, offset), valid


def query_radiance(params: dict, table: PhotonTable, q: Query) -> jnp.ndarray:
    """(B, 3) radiance of q's B points by KernelNet's params: `kernel_radiance` of their
    `gathered_batch`, with the features formed as (9, B, K) straight from the photons' rows
    (the flux feature comes precomputed with the row), or where `use_fused` the fused kernel's
    `fused_radiance`; equal within float rounding (tested)."""
    p = params["params"]
    if use_fused(p):
        return fused_radiance(pack_params(p), table.rows, q)
    photon, offset, valid = read_photons(table, q)
    column = jnp.moveaxis(photon, 2, 0)  # (16, B, K): one channel a row
    offset = jnp.moveaxis(offset, 2, 0)
    centre = jnp.sum(jnp.where(valid, offset, 0.0), axis=2).T  # (B, 3)
    angle = jnp.where(jnp.isnan(q.angle), jax.vmap(centre_angle)(centre, q.normal), q.angle)
    frame = jnp.transpose(jax.vmap(local_frame)(q.normal, angle), (1, 2, 0))  # (row, xyz, B)

    def in_frame(v: jnp.ndarray) -> jnp.ndarray:
        """(3, B, K) vectors v (3, B, K) in each point's frame: products and sums, fused."""
        return jnp.stack([sum(frame[r, c][:, None] * v[c] for c in range(3)) for r in range(3)])

    inv_r = 1.0 / jnp.maximum(q.radius, MIN_RADIUS)
    x = jnp.concatenate(
        [in_frame(offset) * inv_r[:, None], in_frame(column[DIRECTION]), column[FLUX_FEATURE]]
    )
    return kernel_head(p, x, valid, photon[..., FLUX], q.albedo, q.radius)


def use_fused(p: dict) -> bool:
    """Whether rendering evaluates KernelNet params p (the "params" tree) with the fused CPU
    kernel: on the CPU, for the architecture it is built for (else XLA's flat matmuls)."""
    return FUSED and available() and supports(p)


def make_query_predict(
    model: nn.Module,
) -> Callable[[dict, PhotonTable, Query], jnp.ndarray]:
    """A jitted pure function (params, PhotonTable, Query of (S, B) points) -> (S, B, 3)
    radiance: S steps of B points each, run one after another inside the function (one call
    per block of points, each step's activations sized to stay in the caches)."""
    if isinstance(model, KernelNet):
        radiance = query_radiance
    else:
        batched = batch_radiance(model)

        def radiance(params: dict, table: PhotonTable, q: Query) -> jnp.ndarray:
            return batched(params, gathered_batch(table, q))

    def steps(params: dict, table: PhotonTable, q: Query) -> jnp.ndarray:
        return jax.lax.map(lambda part: radiance(params, table, part), q)

    return jax.jit(steps)


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
    paths = feature_paths(photons)
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
            np.full(len(here), paths, np.float32),
        )  # fmt: skip


MIN_CHUNK = 16  # fewest points of a step


def chunk_size(k: int) -> int:
    """Points per inference step for K neighbours: a power of two (so point blocks, also
    powers of two, split into whole steps) with about ACTIVATIONS_PER_CHUNK photons."""
    return 1 << max(0, (ACTIVATIONS_PER_CHUNK // k).bit_length() - 1)


def as_steps(q: Query, size: int) -> Query:
    """q's points zero-padded and split into (S, B) steps of B = `size` points (one step of
    fewer when q is short): S and B powers of two, so few shapes are compiled."""
    n = len(q.radius)
    size = min(size, max(MIN_CHUNK, 1 << (n - 1).bit_length()))
    steps = 1 << (-(-n // size) - 1).bit_length()
    padding = ((0, steps * size - n),)

    def split(a: np.ndarray) -> np.ndarray:
        return np.pad(a, padding + ((0, 0),) * (a.ndim - 1)).reshape(steps, size, *a.shape[1:])

    return Query(*(split(a) for a in q))


def q_part(q: Query, part: slice) -> Query:
    """The points `part` of q."""
    return Query(*(a[part] for a in q))


def predict_points(
    predict: Callable[[dict, PhotonTable, Query], jnp.ndarray],
    params: dict,
    photons: PhotonMap | PhotonIndex,
    position: np.ndarray,
    normal: np.ndarray,
    albedo: np.ndarray,
    k: int,
    watch: Stopwatch | None = None,
) -> np.ndarray:
    """(N, 3) float32 radiance at points (N, 3) from their k nearest photons, chunk by chunk,
    with `predict` from `make_query_predict`; gathering counts as the watch's "gather" (the
    caller times the rest). Each gathered block is split in BLOCKS_IN_FLIGHT parts that the
    network runs at once, on worker threads, while the next block is gathered, so the "gather"
    stage also holds the network's time that the gather could not hide. The split is fixed,
    not taken from the machine's thread count, so the output does not depend on it."""
    index = photon_index(photons, watch)
    p = index.photons
    paths = feature_paths(p)
    table = photon_table(p, paths)
    out = np.zeros((len(position), 3), np.float32)
    size = chunk_size(k)

    def run(rows: slice, q: Query) -> None:
        out[rows] = np.asarray(predict(params, table, q)).reshape(-1, 3)[: rows.stop - rows.start]

    with ThreadPoolExecutor(BLOCKS_IN_FLIGHT) as pool:
        running: deque[Future] = deque()
        try:
            for rows, nb in index.nearest(position, normal, k, watch, agree=False):
                here = np.asarray(position[rows], np.float64)
                hi = here.astype(np.float32)
                radius = np.where(np.isfinite(nb.distance[:, -1]), nb.distance[:, -1], 0.0)
                q = Query(
                    nb.index.astype(np.int32), hi, (here - hi).astype(np.float32),
                    np.asarray(normal[rows], np.float32), np.asarray(albedo[rows], np.float32),
                    radius.astype(np.float32), np.full(len(here), np.nan, np.float32),
                    np.full(len(here), paths, np.float32),
                )  # fmt: skip
                share = -(-len(here) // BLOCKS_IN_FLIGHT)  # every worker starts on the first block
                for first in range(0, len(here), share):
                    part = slice(first, min(first + share, len(here)))
                    points = slice(rows.start + part.start, rows.start + part.stop)
                    running.append(pool.submit(run, points, as_steps(q_part(q, part), size)))
                while len(running) > 2 * BLOCKS_IN_FLIGHT:  # hold few gathered blocks in memory
                    running.popleft().result()
            for job in running:
                job.result()
        except BaseException:  # an interrupt or error: drop the queued parts
            pool.shutdown(cancel_futures=True)
            raise
    return out
