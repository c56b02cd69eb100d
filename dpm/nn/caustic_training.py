"""Training batches of auto's caustic filter: whole training images at one pass count each.

A `CausticSampler` serves some scenes of a caustic set (`dpm.data.caustic_set`): each batch
holds `size` (scene, pass count) images, drawn from the generator it is given alone (so a
resumed run repeats an uninterrupted one), with the long render's target per pixel. Each
image is its own part of the balanced loss: its error over that of the render's caustic without
the network (SPPM at Lepski's radius, sparse pixels spread), so dim and bright scenes, one pass
and 128, count alike, each for how much it beats the render without the network. With
`[train] augment`, each randomly drawn image is turned by one of the square's eight symmetries
(flips and, for square images, a transpose): the filter's taps map onto taps, so 148 scenes
look like eight times as many (the world-space normal guide is not turned with them).
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np

from dpm.caustic.stats import SPREAD, TRAIN_CLAMP_Z
from dpm.data.caustic_set import load_caustic_shard
from dpm.nn.caustic_net import filter_caustics
from dpm.nn.config import Config


class CausticBatch(NamedTuple):
    """Images of the caustic statistics (leading axis: image)."""

    features: np.ndarray  # (B, H, W, CHANNELS) float32
    candidates: np.ndarray  # (B, C, H, W, 3) float32 candidate estimates
    own: np.ndarray  # (B, H, W, 3) float32 the estimate without the network
    count: np.ndarray  # (B, H, W) float32 photons behind `own`
    other: np.ndarray  # (B, H, W, 3) float32 the hull's second estimate (the pixel's own)
    other_count: np.ndarray  # (B, H, W) float32 photons behind `other`
    photon: np.ndarray  # (B,) float32 one photon's luminance


class CausticSampler:
    """Batches of whole images of some scenes of a caustic set, with their targets."""

    def __init__(self, config: Config, manifest: dict, indices: list[int]) -> None:
        out = Path(config.data.out)
        self.ladder = tuple(sorted(config.data.passes))
        entries = {e["index"]: e for e in manifest["shards"]}
        self.shards = [load_caustic_shard(out, entries[i], self.ladder) for i in indices]
        self.choices = [(i, p) for i in range(len(self.shards)) for p in self.ladder]
        self.augment = config.train.augment

    def draw(
        self, rng: np.random.Generator, size: int, parts: int
    ) -> tuple[CausticBatch, np.ndarray, np.ndarray]:
        """A CausticBatch of `size` images (every (scene, pass count) in order when `size` is
        their number, else drawn at random; `parts` is unused: each image is a part), the
        (size·H·W, 3) target radiance and (size·H·W,) int32 the image of each pixel."""
        ordered = size == len(self.choices)  # (validation: every image, as it is)
        picks = range(size) if ordered else rng.integers(len(self.choices), size=size)
        rows = [self.choices[k] for k in picks]
        get = [(self.shards[i], p) for i, p in rows]
        names = CausticBatch._fields
        turns = rng.integers(8, size=size) if self.augment and not ordered else None
        images = []
        for k, (s, p) in enumerate(get):
            arrays = [s[f"{p}/{n}"] for n in names] + [s["target"]]
            if turns is not None:  # (`photon` is a number; candidates' pixels are axes 1, 2)
                axes = [1 if n == "candidates" else 0 for n in names] + [0]
                arrays = [a if a.ndim < 2 else turn(a, int(turns[k]), axis)
                          for a, axis in zip(arrays, axes, strict=True)]  # fmt: skip
            images.append(arrays)
        *fields, target = (np.stack(column) for column in zip(*images, strict=True))
        batch = CausticBatch(*fields)
        pixels = target.shape[1] * target.shape[2]
        part = np.repeat(np.arange(size, dtype=np.int32), pixels)
        return batch, target.reshape(-1, 3), part


def turn(image: np.ndarray, k: int, axis: int) -> np.ndarray:
    """`image` with its two pixel axes (axis, axis + 1) turned by symmetry k in 0..7 of the
    square: bit 0 flips the rows, bit 1 the columns, bit 2 transposes (square images only;
    else left out). Any other axes (features, colours, candidates) are untouched."""
    if k & 1:
        image = np.flip(image, axis)
    if k & 2:
        image = np.flip(image, axis + 1)
    if k & 4 and image.shape[axis] == image.shape[axis + 1]:
        image = np.swapaxes(image, axis, axis + 1)
    return image


def caustic_estimates(model, z: float = TRAIN_CLAMP_Z, hull: bool = False) -> Callable:
    """estimates(params, batch) -> ((N, 3) the filter's radiance, held within z standard
    errors of the clamp's centre, or with `hull` within the hull of that interval and the one
    about the pixel's own estimate, as the render holds it (stats.HULL_CLAMP), (N, 3) the
    render's without the network: the spread candidate) over a CausticBatch's pixels, for
    `dpm.nn.train.make_steps`."""

    def filtered(params, f, c, o, n, a, m, p):
        return filter_caustics(model, params, f, c, o, n, p, z, *((a, m) if hull else ()))

    one = jax.vmap(filtered, (None, 0, 0, 0, 0, 0, 0, 0))

    def estimates(params: dict, b: CausticBatch) -> tuple[jnp.ndarray, jnp.ndarray]:
        out = one(
            params, b.features, b.candidates, b.own, b.count, b.other, b.other_count, b.photon
        )
        return out.reshape(-1, 3), b.candidates[:, SPREAD].reshape(-1, 3)

    return estimates
