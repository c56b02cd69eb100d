"""Data-parallel training over every JAX device (`jax.sharding`): one CPU today, GPUs when
present, with no change to the step.

Each step's batch of visible points is split along its first axis over a one-axis mesh of
all devices; parameters and Adam state are replicated. `jax.jit` then runs the same step on
each device's points and XLA adds the reduction of the loss and gradients across devices, so
the step is the one written for a single device. On one device nothing is split and the
result is the unsharded step's exactly; on several it equals it up to the order of float
sums (tested with 2 host devices: `XLA_FLAGS=--xla_force_host_platform_device_count=2`).
"""

from __future__ import annotations

from typing import Any

import jax
import numpy as np
from jax.sharding import Mesh, NamedSharding, PartitionSpec

from dpm.errors import InputError

AXIS = "points"  # the mesh axis the batch's points are split along


class DataParallel:
    """A mesh of `devices` (default: all of JAX's) that splits batches and replicates state."""

    def __init__(self, devices: list | None = None) -> None:
        self.devices = list(devices or jax.devices())
        mesh = Mesh(np.array(self.devices), (AXIS,))
        self._split = NamedSharding(mesh, PartitionSpec(AXIS))
        self._whole = NamedSharding(mesh, PartitionSpec())

    def __len__(self) -> int:
        return len(self.devices)

    def check(self, name: str, points: int) -> None:
        """InputError unless `points` (a batch size named `name`) splits evenly."""
        if points % len(self):
            raise InputError(f"{name} = {points} must be a multiple of the {len(self)} JAX "
                             f"devices ({self.devices[0].platform}) it is split over")  # fmt: skip

    def split(self, tree: Any) -> Any:
        """Every array of `tree` (leading axis: points) split over the devices."""
        return jax.device_put(tree, self._split)

    def replicate(self, tree: Any) -> Any:
        """Every array of `tree` copied whole onto every device."""
        return jax.device_put(tree, self._whole)
