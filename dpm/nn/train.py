"""Training a DPM network, `dpm-train --config cfg.toml` (paper §4.3): the steps and the loop.

`train` builds or completes the training set of `[data]` (dpm.data.dataset), then trains the
network of `[model]` as `[train]` says (dpm.nn.config): each step's batch is drawn from
(seed, step) alone (dpm.nn.sampler), so a resumed run repeats an uninterrupted one exactly;
the loss is one of dpm.nn.losses, by default `mse+relmse` balanced against PM-K. Steps are
data-parallel over every JAX device (dpm.nn.sharding; one CPU device is the plain step). The run
folder (dpm.nn.run_folder) receives checkpoints every `checkpoint_seconds` and at exit
(Ctrl-C and SIGTERM included), the metrics, the loss curve and, at the end, `model.msgpack`.
Relative folders of the config are relative to the working directory; `train` says where
they lie.
"""

from __future__ import annotations

import os
import signal
import sys
import time
from collections import deque
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import jax
import numpy as np
import optax
from tqdm import tqdm

from dpm.data.caustic_set import make_caustic_shard
from dpm.data.dataset import build
from dpm.nn.caustic_training import CausticSampler, caustic_estimates
from dpm.nn.config import Config, ModelConfig
from dpm.nn.features import uniform_radiance
from dpm.nn.infer import point_radiance
from dpm.nn.losses import training_loss
from dpm.nn.model import example_input, make_model
from dpm.nn.run_folder import RunFolder
from dpm.nn.sampler import Sampler
from dpm.nn.shape_training import ShapeSampler, shape_estimates
from dpm.nn.sharding import DataParallel
from dpm.nn.weights import Weights, load_weights, save_weights

# Threads that draw training batches ahead of the steps, and how many batches they keep ready:
# half the cores (the other half and the step's own threads compute), at most 8. On the
# 16-core device a DPM-50 step waited on its batch (77 ms a step on an H100, as on 2 CPU cores).
DRAW_THREADS = max(1, min(8, (os.cpu_count() or 2) // 2))
DRAW_AHEAD = 2 * DRAW_THREADS


def make_steps(
    model,
    learning_rate: float,
    loss_name: str,
    balance: bool,
    estimates: Callable | None = None,
    schedule: str = "constant",
    steps: int = 1,
) -> tuple[optax.GradientTransformation, Callable, Callable]:
    """The optimiser, a jitted loss(params, batch, target, part) and a jitted training step
    (target: (N, 3) radiance, W/(m² sr); part: the (N,) int32 (scene, budget) pair of each
    point, used when `balance`). The loss is `loss_name` of dpm.nn.losses.LOSSES, divided per
    part by the uniform kernel's (PM-K's) when `balance`. `estimates(params, batch)` gives
    the (N, 3) radiance of the network and of the uniform kernel (default: DPM's). `schedule`
    'cosine' lowers the rate from learning_rate to 0 over `steps` (`[train] schedule`)."""
    rate = (
        optax.cosine_decay_schedule(learning_rate, steps) if schedule == "cosine" else learning_rate
    )
    optimiser = optax.adam(rate)
    if estimates is None:
        predict = jax.vmap(lambda params, b: point_radiance(model, params, b), (None, 0))

        def estimates(params, batch):
            return predict(params, batch), uniform_radiance(batch)

    def loss(params, batch, target, part=None):
        estimate, uniform = estimates(params, batch)
        return training_loss(estimate, target, loss_name, uniform if balance else None, part)

    @jax.jit
    def step(params, opt_state, batch, target, part=None):
        value, grads = jax.value_and_grad(loss)(params, batch, target, part)
        updates, opt_state = optimiser.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, value

    return optimiser, jax.jit(loss), step


def init_params(model, k: int, seed: int, architecture: str = "dpm") -> dict:
    """Fresh parameters for network `architecture` (`model`) on K photons."""
    return model.init(jax.random.key(seed), *example_input(architecture, k))


def train(config: Config, progress: bool = True) -> tuple[dict, list[dict]]:
    """Build or complete the training set, then train (resuming from the run's checkpoints);
    returns the final parameters (numpy arrays) and the metrics rows."""
    t, m = config.train, config.model
    if progress:
        print(f"dpm-train: training set in {Path(config.data.out).resolve()}, run in "
              f"{Path(t.out).resolve()} (relative paths are relative to the directory "
              "dpm-train runs from)", file=sys.stderr)  # fmt: skip
    devices = DataParallel()
    devices.check("[train] batch", t.batch)
    devices.check("[train] validation_points", t.validation_points)
    make = make_caustic_shard if config.data.kind == "caustic" else None
    manifest = build(config.data, progress=progress, make=make)
    n = len(manifest["shards"])
    nppm = m.architecture == "nppm"  # the shape network: its own samples and loss
    caustic = m.architecture == "caustic"  # auto's caustic filter: whole images
    sampler_class = ShapeSampler if nppm else CausticSampler if caustic else Sampler
    sampler = sampler_class(config, manifest, list(range(n - t.validation_scenes)))
    validation = sampler_class(config, manifest, list(range(n - t.validation_scenes, n)))
    val_batch, val_target, val_part = devices.split(
        validation.draw(np.random.default_rng((t.seed, 1 << 30)), t.validation_points,
                        max(1, len(validation.choices)))
    )  # fmt: skip
    run = RunFolder(config)
    model = make_model(m.architecture, m.width)
    estimates = None
    if nppm:
        estimates = shape_estimates(model)
    elif caustic:
        estimates = caustic_estimates(model, t.clamp_z, t.hull)
    optimiser, loss, step = make_steps(
        model, t.learning_rate, t.loss, t.balance, estimates, t.schedule, t.steps
    )
    params = devices.replicate(init_params(model, m.k, t.seed, m.architecture))
    done, params, opt_state, rows = run.restore(params, devices.replicate(optimiser.init(params)))
    best = Best(run.out / "best.msgpack", m) if t.keep_best else None
    if not rows:  # step 0: the fresh network (the uniform kernel: PM-K for DPM, PPM for nppm)
        value = float(loss(params, val_batch, val_target, val_part))
        rows.append({"step": 0, "loss": "", "validation_loss": f"{value:.6g}", "seconds": "0.00"})
        if best:
            best.offer(value, params)
    elif best:
        best.resume(rows, params)

    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    bar = tqdm(total=t.steps, initial=done, unit="step", desc="training", disable=not progress)
    start, last_save = time.perf_counter(), time.perf_counter()
    offset = float(rows[-1]["seconds"]) if rows else 0.0
    pool = ThreadPoolExecutor(DRAW_THREADS, thread_name_prefix="draw")
    try:

        def draw(s: int) -> tuple:
            rng = np.random.default_rng((t.seed, s))
            return devices.split(sampler.draw(rng, t.batch, t.scenes_per_batch))

        # Batches are drawn ahead on worker threads while the steps run (asynchronously, on
        # the accelerator where there is one); each is a function of its step alone, so how
        # many threads draw changes nothing but the speed.
        ahead = deque(pool.submit(draw, s) for s in range(done + 1, t.steps + 1)[:DRAW_AHEAD])
        for s in range(done + 1, t.steps + 1):
            batch = ahead.popleft().result()
            if s + DRAW_AHEAD <= t.steps:
                ahead.append(pool.submit(draw, s + DRAW_AHEAD))
            params, opt_state, value = step(params, opt_state, *batch)  # an interrupt before
            done = s  # this line keeps step s - 1 as the last one done
            row = {"step": s, "loss": f"{float(value):.6g}", "validation_loss": "",
                   "seconds": f"{offset + time.perf_counter() - start:.2f}"}  # fmt: skip
            if s % t.validate_every == 0 or s == t.steps:
                held_out = float(loss(params, val_batch, val_target, val_part))
                row["validation_loss"] = f"{held_out:.6g}"
                if best:
                    best.offer(held_out, params)
                bar.set_postfix(loss=row["loss"], validation=row["validation_loss"])
            rows.append(row)
            bar.update()
            if time.perf_counter() - last_save > t.checkpoint_seconds:
                run.save(s, params, opt_state, rows)
                last_save = time.perf_counter()
    except KeyboardInterrupt:
        run.save(done, params, opt_state, rows)
        raise
    finally:
        pool.shutdown(wait=True, cancel_futures=True)
        bar.close()
        signal.signal(signal.SIGTERM, previous)
    run.save(done, params, opt_state, rows)
    params = jax.tree.map(np.asarray, params)
    if best:  # the step with the least validation loss (its weights were saved then)
        params = load_weights(best.path).params
    save_weights(run.weights, Weights(m.architecture, m.width, m.k, params))
    return params, rows


class Best:
    """`[train] keep_best`: the weights of the step with the least validation loss so far,
    saved to `path` when a validation beats it (a resumed run reads its value back from the
    metrics rows and repeats the steps after its checkpoint exactly, so it ends the same)."""

    def __init__(self, path: Path, model: ModelConfig) -> None:
        self.path, self.model, self.value = path, model, float("inf")

    def offer(self, value: float, params: dict) -> None:
        """Save params when their validation loss `value` is the least so far (compared as
        metrics.csv keeps it, so a resumed run, reading the rows back, decides the same)."""
        value = float(f"{value:.6g}")
        if value < self.value:
            self.value = value
            params = jax.tree.map(np.asarray, params)
            m = self.model
            save_weights(self.path, Weights(m.architecture, m.width, m.k, params))

    def resume(self, rows: list[dict], params: dict) -> None:
        """Take the least validation loss of a resumed run's rows (rows[-1] being the
        restored params' step). Where the file is missing (a run that predates the option,
        or had it off), the restored params become the best so far, at their own step's
        loss if that step was validated, else at none (the next validation replaces them)."""
        values = [float(r["validation_loss"]) for r in rows if r["validation_loss"]]
        if self.path.exists() and values:
            self.value = min(values)
            return
        own = rows[-1]["validation_loss"] if rows else ""
        m = self.model
        save_weights(
            self.path, Weights(m.architecture, m.width, m.k, jax.tree.map(np.asarray, params))
        )
        self.value = float(own) if own else float("inf")


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt
