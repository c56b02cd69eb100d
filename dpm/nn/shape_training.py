"""Training the nppm shape network (`[model] architecture = "nppm"`): batches and loss.

A sample imitates one pass of nppm at one visible point of the training set with two
independent photon maps of the shard (two budgets): the *history* map plays the earlier
passes, the *current* map the pass being weighed. The radius is the distance to the k-th
nearest history photon (k log-uniform in HISTORY_K), the features are those of the history
photons in the disc (dpm.density.shaped.features), and the estimate is the current map's
photons in the disc weighted by the predicted kernel. The loss is dpm-train's (by default
`mse+relmse`, balanced against the uniform kernel: 1 is the uniform disc's error, below beats
it) against the shard's reference radiance. The current map is always the larger one (3.3 to
33× the history's paths): its estimate's variance is small, so the loss is mostly the kernel's
bias, which is what stays in a progressive estimate once many passes have averaged the
variance away. (Trained on one-pass errors instead, with the current map the smaller, the
network barely moved from the uniform kernel: held-out loss 0.985–1.0 after 400 steps.)
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from scipy.spatial import cKDTree

from dpm.data.dataset import MAX_CACHED_SHARDS, ShardCache, shard_sizes
from dpm.density.base import in_plane, tangent_frame
from dpm.density.gather import NORMAL_COS
from dpm.density.shaped import (
    features,
    pair_moments,
    principal_axes,
    relative_weight,
    to_axes,
)
from dpm.errors import InputError
from dpm.nn.config import Config
from dpm.nn.shape_net import point_precisions

HISTORY_K = (4, 256)  # history photons in the disc: log-uniform in this range
MAX_CURRENT = 1024  # current photons kept per disc (a random subset, flux scaled, beyond)


class ShapeBatch(NamedTuple):
    """B training samples (a JAX pytree)."""

    x: np.ndarray  # (B, FEATURES) float32 network input from the history photons
    uv: np.ndarray  # (B, C, 2) float32 current photons along e₁, e₂ (units of R)
    flux: np.ndarray  # (B, C, 3) float32 radiance each contributes under the uniform kernel
    valid: np.ndarray  # (B, C) bool


def batch_radiance(model, params: dict, b: ShapeBatch) -> jnp.ndarray:
    """(B, 3) radiance W/(m² sr) of each sample under the network's kernel."""
    p = jax.vmap(lambda x: point_precisions(model, params, x))(b.x)
    w = relative_weight(b.uv[..., 0], b.uv[..., 1], p[:, :1], p[:, 1:], jnp)
    return jnp.sum(jnp.where(b.valid[..., None], w[..., None] * b.flux, 0.0), axis=1)


def shape_estimates(model) -> Callable:
    """estimates(params, batch) -> ((B, 3) radiance under the network's kernel, (B, 3) under
    the uniform one), for dpm.nn.train.make_steps."""

    def estimates(params: dict, b: ShapeBatch) -> tuple[jnp.ndarray, jnp.ndarray]:
        flat = jnp.sum(jnp.where(b.valid[..., None], b.flux, 0.0), axis=1)
        return batch_radiance(model, params, b), flat

    return estimates


class ShapeSampler:
    """Batches of nppm samples from some scenes of the set, drawn from a given generator."""

    def __init__(self, config: Config, manifest: dict, indices: list[int]) -> None:
        self.out = Path(config.data.out)
        self.budgets = config.data.budgets
        entries = {e["index"]: e for e in manifest["shards"]}
        self.entries = [entries[i] for i in indices]
        self.choices = [
            (i, h, c)
            for i, e in enumerate(self.entries)
            for h in self.budgets
            for c in self.budgets
            if h < c and min(shard_sizes(e, h)[1], shard_sizes(e, c)[1]) >= HISTORY_K[1]
        ]  # fmt: skip
        self.cache = ShardCache(self.out, self.entries, self.budgets, MAX_CACHED_SHARDS)

    def _tree(self, i: int, budget: int) -> cKDTree:
        return self.cache.per_map(i, budget, lambda photons: cKDTree(photons.position))

    def draw(
        self, rng: np.random.Generator, size: int, parts: int
    ) -> tuple[ShapeBatch, np.ndarray, np.ndarray]:
        """A ShapeBatch of `size` samples from `parts` random (scene, history budget, current
        budget) triples, (size, 3) reference radiance and (size,) int32 each sample's part."""
        if not self.choices:
            raise InputError(f"{self.out}: no scene has {HISTORY_K[1]} caustic photons at two "
                             "budgets; raise [data] budgets")  # fmt: skip
        picks = rng.integers(len(self.choices), size=parts)
        counts = np.diff(np.linspace(0, size, parts + 1).astype(int))
        out = []
        for j, (pick, count) in enumerate(zip(picks, counts, strict=True)):
            i, h, c = self.choices[pick]
            out.append((*self._samples(rng, i, h, c, count), np.full(count, j, np.int32)))
        x, uv, flux, valid, target, part = (np.concatenate(a) for a in zip(*out, strict=True))
        return ShapeBatch(x, uv, flux, valid), target, part

    def _samples(self, rng: np.random.Generator, i: int, h: int, c: int, count: int) -> tuple:
        shard = self.cache.shard(i)
        rows = rng.integers(len(shard.position), size=count)
        pos = shard.position[rows].astype(np.float64)
        normal = shard.normal[rows].astype(np.float64)
        t, b = tangent_frame(normal)
        k = np.exp(rng.uniform(*np.log(HISTORY_K), count)).astype(int)
        hist, cur = shard.photons[h], shard.photons[c]
        dist, _ = self._tree(i, h).query(pos, k=HISTORY_K[1])
        radius = np.maximum(dist[np.arange(count), k - 1], 1e-9)
        moments = self._history(hist, self._tree(i, h), pos, normal, t, b, radius)
        x = features(moments)
        cos, sin = principal_axes(moments)
        uv = np.zeros((count, MAX_CURRENT, 2), np.float32)
        flux = np.zeros((count, MAX_CURRENT, 3), np.float32)
        valid = np.zeros((count, MAX_CURRENT), bool)
        scale = shard.albedo[rows] / np.pi / (np.pi * radius[:, None] ** 2)  # Φ → radiance
        for s, found in enumerate(self._tree(i, c).query_ball_point(pos, radius)):
            found = np.asarray(found, np.int64)
            found = found[cur.normal[found] @ normal[s] >= NORMAL_COS]
            thin = max(1.0, len(found) / MAX_CURRENT)  # keep an unbiased random subset
            if thin > 1:
                found = rng.choice(found, MAX_CURRENT, replace=False)
            off = cur.position[found] - pos[s]
            ab = np.stack([off @ t[s], off @ b[s]], 1) / radius[s]  # one point: plain products
            m = len(found)
            uv[s, :m] = to_axes(ab, cos[s : s + 1], sin[s : s + 1])
            flux[s, :m] = cur.flux[found] * scale[s] * thin
            valid[s, :m] = True
        return x, uv, flux, valid, shard.radiance[rows]

    @staticmethod
    def _history(hist, tree, pos, normal, t, b, radius) -> np.ndarray:
        """(count, MOMENTS) moments of the history photons in each disc."""
        n = len(pos)
        points, photons = [], []
        for s, found in enumerate(tree.query_ball_point(pos, radius)):
            found = np.asarray(found, np.int64)
            found = found[hist.normal[found] @ normal[s] >= NORMAL_COS]
            points.append(np.full(len(found), s))
            photons.append(found)
        point, photon = np.concatenate(points), np.concatenate(photons)
        off = hist.position[photon] - pos[point]
        ab = in_plane(off, t[point], b[point]) / radius[point, None]
        dab = in_plane(hist.direction[photon], t[point], b[point])
        return pair_moments(point, n, ab, dab)
