"""Training batches: visible points of the training set with their K nearest caustic photons.

A `Sampler` serves some scenes of a set (the training or the validation ones); each batch is
drawn from the random generator it is given alone (dpm.nn.train seeds it with (seed, step)),
so a resumed run repeats an uninterrupted one exactly: the (scene, budget) pairs, the visible
points and their tangent-frame angles.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from dpm.data.dataset import MAX_CACHED_SHARDS, ShardCache, shard_sizes
from dpm.density.gather import PhotonIndex
from dpm.errors import InputError
from dpm.nn.config import Config
from dpm.nn.infer import Batch, neighbourhoods


class Sampler:
    """Batches of visible points with their K nearest photons and ground truth, by step."""

    def __init__(self, config: Config, manifest: dict, indices: list[int]) -> None:
        self.out = Path(config.data.out)
        self.k = config.model.k
        self.budgets = config.data.budgets
        entries = {e["index"]: e for e in manifest["shards"]}
        self.entries = [entries[i] for i in indices]
        # (entry position, budget) pairs with at least K caustic photons
        self.choices = []
        for i, entry in enumerate(self.entries):
            for budget in self.budgets:
                points, photons = shard_sizes(entry, budget)
                if photons >= self.k and points > 0:
                    self.choices.append((i, budget))
        self.cache = ShardCache(self.out, self.entries, self.budgets, MAX_CACHED_SHARDS)

    def draw(
        self, rng: np.random.Generator, size: int, parts: int
    ) -> tuple[Batch, np.ndarray, np.ndarray]:
        """A Batch of `size` points from `parts` random (scene, budget) pairs, (size, 3)
        ground-truth radiance in W/(m² sr) and (size,) int32 the pair each point came from."""
        if not self.choices:
            raise InputError(f"{self.out}: no scene has {self.k} caustic photons at any budget; "
                             "raise [data] budgets or lower [model] k")  # fmt: skip
        picks = rng.integers(len(self.choices), size=parts)
        counts = np.diff(np.linspace(0, size, parts + 1).astype(int))
        batches, targets, part = [], [], []
        for j, (pick, count) in enumerate(zip(picks, counts, strict=True)):
            if count == 0:  # fewer points than parts
                continue
            i, budget = self.choices[pick]
            shard = self.cache.shard(i)
            rows = rng.integers(len(shard.position), size=count)
            angle = rng.uniform(0.0, 2 * np.pi, count).astype(np.float32)
            index = self.cache.per_map(i, budget, PhotonIndex)  # one tree per (scene, budget)
            _, b = next(
                neighbourhoods(
                    index,
                    shard.position[rows],
                    shard.normal[rows],
                    shard.albedo[rows],
                    self.k,
                    angle,
                )
            )
            batches.append(b)
            targets.append(shard.radiance[rows])
            part.append(np.full(count, j, np.int32))
        batch = Batch(*(np.concatenate(parts) for parts in zip(*batches, strict=True)))
        return batch, np.concatenate(targets), np.concatenate(part)
