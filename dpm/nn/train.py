"""Training a DPM network: `dpm-train --config cfg.toml` (paper §4.3).

The config has three tables: `[data]` (`dpm.data.dataset.DataConfig`: the training set, made
or completed first), `[model]` (`ModelConfig`) and `[train]` (`TrainConfig`). Every step draws
its batch from (seed, step) alone: `scenes_per_batch` training scenes, a random photon budget
for each, visible points, and tangent-frame angles; so a resumed run repeats an uninterrupted
one exactly. Loss: L2 between μ-law tone-mapped (μ = 5000, Eq. 4) estimate and ground truth,
or relative L2, either optionally balanced against PM-K per (scene, budget) (`make_steps`).

`TrainConfig.out` receives `checkpoints/` (orbax: params, Adam state; every
`checkpoint_seconds` and at exit, Ctrl-C and SIGTERM included), `metrics.csv` (step, training
loss, validation loss, seconds; step 0 is the fresh network, which for DPM is the uniform
kernel, i.e. PM-K), `loss.png` and, at the end, `model.msgpack`.
"""

from __future__ import annotations

import csv
import json
import signal
import time
import tomllib
from collections.abc import Callable
from dataclasses import asdict, dataclass, fields
from pathlib import Path

import jax
import jax.numpy as jnp
import numpy as np
import optax
from scipy.spatial import cKDTree
from tqdm import tqdm

from dpm.data.dataset import DataConfig, build, load_shard
from dpm.errors import InputError
from dpm.io import atomic
from dpm.nn.features import kernel_estimate
from dpm.nn.infer import Batch, neighbourhoods, point_radiance
from dpm.nn.model import ARCHITECTURES, make_model
from dpm.nn.weights import Weights, save_weights
from dpm.tracer import PhotonMap

MU = 5000.0  # μ of the loss's tone mapping (Eq. 4)


@dataclass(frozen=True)
class ModelConfig:
    """Which network (the `[model]` table)."""

    architecture: str = "dpm"  # 'dpm', 'dpm-l' (4× channels) or 'direct' (ablation)
    width: int = 32  # channels of the feature extractor and kernel predictor
    k: int = 50  # nearest photons per visible point


@dataclass(frozen=True)
class TrainConfig:
    """How to train (the `[train]` table)."""

    out: str = "runs/dpm"  # run folder: checkpoints, metrics, loss curve, final weights
    steps: int = 2000
    batch: int = 512  # visible points per step
    scenes_per_batch: int = 4  # training scenes each batch is drawn from
    learning_rate: float = 1e-3  # Adam
    validation_scenes: int = 1  # the last scenes of the set, held back
    validation_points: int = 4096
    validate_every: int = 100  # steps
    checkpoint_seconds: float = 180.0
    seed: int = 0
    loss: str = "mu-law"  # one of LOSSES: 'mu-law' is the paper's Eq. 4; see make_steps
    balance: bool = False  # divide each (scene, budget) part's loss by PM-K's: see make_steps


LOSSES = ("mu-law", "relmse", "mse", "mse+relmse")
RELMSE_EPSILON = 0.01  # radiance added to the prediction in relmse's denominator


@dataclass(frozen=True)
class Config:
    """A whole dpm-train config."""

    data: DataConfig
    model: ModelConfig
    train: TrainConfig


def _table(cls: type, table: dict, path: Path, name: str) -> object:
    """cls built from a TOML table, each value checked against the field's type."""
    kinds = {f.name: str(f.type) for f in fields(cls)}  # 'int', 'float', 'str', 'tuple[...]'
    checks = {
        "int": (lambda v: isinstance(v, int) and not isinstance(v, bool), "an integer"),
        "float": (lambda v: isinstance(v, int | float) and not isinstance(v, bool), "a number"),
        "str": (lambda v: isinstance(v, str), "a string"),
        "bool": (lambda v: isinstance(v, bool), "true or false"),
        "tuple[int, ...]": (lambda v: isinstance(v, list) and all(
            isinstance(x, int) and not isinstance(x, bool) for x in v), "a list of integers"),
    }  # fmt: skip
    values = {}
    for key, value in table.items():
        if key not in kinds:
            raise InputError(f"{path}: unknown key '{key}' in [{name}] (known: {sorted(kinds)})")
        ok, what = checks[kinds[key]]
        if not ok(value):
            raise InputError(f"{path}: [{name}] {key} must be {what} (got {value!r})")
        values[key] = tuple(value) if isinstance(value, list) else value
    return cls(**values)


def load_config(path: str | Path) -> Config:
    """Read and check a dpm-train TOML config; InputError (one line) on any problem."""
    path = Path(path)
    try:
        raw = tomllib.loads(path.read_text())
    except FileNotFoundError:
        raise InputError(f"{path}: config file not found") from None
    except (tomllib.TOMLDecodeError, UnicodeDecodeError) as e:
        raise InputError(f"{path}: not valid TOML ({e})") from None
    for name in raw:
        if name not in ("data", "model", "train"):
            raise InputError(f"{path}: unknown table [{name}] (use [data], [model], [train])")
    if "out" not in raw.get("data", {}):
        raise InputError(f"{path}: [data] needs `out`, the training set's folder")
    config = Config(
        _table(DataConfig, raw["data"], path, "data"),
        _table(ModelConfig, raw.get("model", {}), path, "model"),
        _table(TrainConfig, raw.get("train", {}), path, "train"),
    )
    m, t, d = config.model, config.train, config.data
    if m.architecture not in ARCHITECTURES:
        raise InputError(f"{path}: [model] architecture must be one of {sorted(ARCHITECTURES)}")
    positive = [("model", "width", m.width), ("model", "k", m.k), ("train", "steps", t.steps),
                ("train", "batch", t.batch), ("train", "scenes_per_batch", t.scenes_per_batch),
                ("train", "validate_every", t.validate_every), ("data", "width", d.width),
                ("train", "validation_points", t.validation_points)]  # fmt: skip
    for table, key, value in positive:
        if value < 1:
            raise InputError(f"{path}: [{table}] {key} must be at least 1 (got {value})")
    if not 1 <= t.validation_scenes < d.scenes:
        raise InputError(f"{path}: [train] validation_scenes must be at least 1 and fewer "
                         f"than the {d.scenes} scenes of [data]")  # fmt: skip
    if not d.budgets or min(d.budgets) < 1 or not t.learning_rate > 0:
        raise InputError(f"{path}: [data] budgets and [train] learning_rate must be positive")
    for key in ("reference_paths", "reference_paths_per_pass", "workers"):
        if getattr(d, key) < 1:
            raise InputError(f"{path}: [data] {key} must be at least 1")
    if not 0 < d.reference_radius < 1:
        raise InputError(f"{path}: [data] reference_radius must be in (0, 1): a fraction of "
                         "the scene's diagonal")  # fmt: skip
    if t.loss not in LOSSES:
        raise InputError(f"{path}: [train] loss must be one of {', '.join(LOSSES)}")
    if t.batch < t.scenes_per_batch:
        raise InputError(f"{path}: [train] batch must be at least scenes_per_batch")
    return config


def mu_law(v: jnp.ndarray) -> jnp.ndarray:
    """(…) μ-law tone mapping of Eq. 4 of radiance v (negative values count as 0)."""
    return jnp.log1p(MU * jnp.maximum(v, 0.0)) / jnp.log1p(MU)


class Sampler:
    """Batches of visible points with their K nearest photons and ground truth, by step."""

    def __init__(self, config: Config, manifest: dict, indices: list[int]) -> None:
        self.out = Path(config.data.out)
        self.k = config.model.k
        self.budgets = config.data.budgets
        entries = {e["index"]: e for e in manifest["shards"]}
        self.entries = [entries[i] for i in indices]
        # (entry position, budget) pairs with at least K caustic photons
        self.choices = [(i, b) for i, e in enumerate(self.entries) for b in self.budgets
                        if e["caustic_photons"][str(b)] >= self.k and e["points"] > 0]  # fmt: skip
        self.cache: dict[int, dict] = {}
        self.trees: dict[tuple[int, int], cKDTree] = {}

    def _shard(self, i: int) -> dict:
        if i not in self.cache:
            if len(self.cache) >= 64:  # bounded memory: forget the oldest shard
                oldest = next(iter(self.cache))
                del self.cache[oldest]
                self.trees = {key: t for key, t in self.trees.items() if key[0] != oldest}
            self.cache[i] = load_shard(self.out, self.entries[i], self.budgets)
        return self.cache[i]

    def draw(
        self, rng: np.random.Generator, size: int, parts: int
    ) -> tuple[Batch, np.ndarray, np.ndarray]:
        """A Batch of `size` points from `parts` random (scene, budget) pairs, (size, 3)
        ground-truth radiance and (size,) int32 the pair each point came from."""
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
            shard = self._shard(i)
            rows = rng.integers(len(shard["position"]), size=count)
            angle = rng.uniform(0.0, 2 * np.pi, count).astype(np.float32)
            photons = PhotonMap(
                shard[f"{budget}/position"], shard[f"{budget}/direction"],
                shard[f"{budget}/flux"], shard[f"{budget}/normal"],
                np.ones(len(shard[f"{budget}/flux"]), bool), np.zeros(0, np.uint16),
                np.zeros(0, np.int64), budget,
            )  # fmt: skip
            key = (i, budget)
            if key not in self.trees:
                self.trees[key] = cKDTree(photons.position.astype(np.float64))
            _, b = next(
                neighbourhoods(
                    photons,
                    shard["position"][rows],
                    shard["normal"][rows],
                    shard["albedo"][rows],
                    self.k,
                    angle,
                    self.trees[key],
                )
            )
            batches.append(b)
            targets.append(shard["radiance"][rows])
            part.append(np.full(count, j, np.int32))
        batch = Batch(*(np.concatenate(parts) for parts in zip(*batches, strict=True)))
        return batch, np.concatenate(targets), np.concatenate(part)


def point_loss(estimate: jnp.ndarray, target: jnp.ndarray, name: str) -> jnp.ndarray:
    """(N,) loss `name` of each point's estimated against target radiance (N, 3), W/(m² sr)."""
    if name == "relmse":
        scale = jax.lax.stop_gradient(estimate) + RELMSE_EPSILON
        return jnp.mean(((estimate - target) / scale) ** 2, axis=-1)
    if name == "mse":
        return jnp.mean((estimate - target) ** 2, axis=-1)
    return jnp.mean((mu_law(estimate) - mu_law(target)) ** 2, axis=-1)


def loss_value(estimate: jnp.ndarray, target: jnp.ndarray, name: str) -> jnp.ndarray:
    """The mean loss `name` between estimated and target radiance, both (N, 3) W/(m² sr)."""
    return jnp.mean(point_loss(estimate, target, name))


def balanced_loss(
    estimate: jnp.ndarray, uniform: jnp.ndarray, target: jnp.ndarray, part: jnp.ndarray, name: str
) -> jnp.ndarray:
    """Mean over the batch's parts (part (N,) int) of the loss of estimate (N, 3) divided by
    that of the uniform kernel's estimate (N, 3) on the same points: 1 is PM-K, below beats it."""
    n = part.shape[0]
    num = jax.ops.segment_sum(point_loss(estimate, target, name), part, n)
    den = jax.ops.segment_sum(point_loss(uniform, target, name), part, n)
    used = den > 0
    ratio = jnp.where(used, num / jnp.where(used, den, 1.0), 0.0)
    return jnp.sum(ratio) / jnp.maximum(jnp.sum(used), 1)


def make_steps(
    model, learning_rate: float, loss_name: str = "mu-law", balance: bool = False
) -> tuple[optax.GradientTransformation, Callable, Callable]:
    """The optimiser, a jitted loss(params, batch, target, part) and a jitted training step
    (part: the (N,) int32 (scene, budget) pair of each point, used when `balance`).

    'mu-law' is the paper's L2 after Eq. 4. Its minimiser is the mean of μ(target), below
    μ(mean target) when targets are noisy, so with our PPM targets it learns to darken
    (measured: a 2.6× too dark mean on held-out scenes). 'relmse' (Noise2Noise's relative
    L2, the denominator from the prediction, not the target) has the target's mean as its
    minimiser, so noisy references teach no bias; so has 'mse'. relmse weighs a dim point
    as much as a bright one and taught kernels that sharpen everywhere, which wins with few
    photons and loses where a caustic is bright and dense (measured: held-out RMSE 1.25×
    PM-50's at 10⁶ paths); mse, the metric the benchmarks report, taught kernels that barely
    leave the uniform one. 'mse+relmse' (the mean of both, balanced) keeps most of each.

    With `balance`, each part's loss is divided by the uniform kernel's (PM-K's) on the same
    points. Unbalanced, the sparse budgets' large errors dominate the gradient, and the
    network learned corrections that help there but lose to PM-K at dense budgets (measured
    on held-out scenes: 1.45× PM-50's RMSE at 10⁶ paths); balanced, every budget counts for
    how much it beats PM-K.
    """
    optimiser = optax.adam(learning_rate)
    predict = jax.vmap(lambda params, b: point_radiance(model, params, b), (None, 0))
    uniform = jax.vmap(
        lambda b: kernel_estimate(jnp.ones(b.valid.shape), b.flux, b.valid, b.albedo, b.radius)
    )

    def loss(params, batch, target, part=None):
        estimate = predict(params, batch)
        names = loss_name.split("+")  # 'mse+relmse': the mean of both
        if balance:
            flat = uniform(batch)  # once, shared by every named loss
            values = [balanced_loss(estimate, flat, target, part, name) for name in names]
        else:
            values = [loss_value(estimate, target, name) for name in names]
        return sum(values) / len(values)

    @jax.jit
    def step(params, opt_state, batch, target, part=None):
        value, grads = jax.value_and_grad(loss)(params, batch, target, part)
        updates, opt_state = optimiser.update(grads, opt_state, params)
        return optax.apply_updates(params, updates), opt_state, value

    return optimiser, jax.jit(loss), step


def init_params(model, k: int, seed: int) -> dict:
    """Fresh parameters for `model` on K photons."""
    x = jnp.zeros((k, 9), jnp.float32)
    return model.init(jax.random.key(seed), x, jnp.ones(k, bool))


def _checkpointer(folder: Path):
    import orbax.checkpoint as ocp

    options = ocp.CheckpointManagerOptions(max_to_keep=2, enable_async_checkpointing=False)
    return ocp, ocp.CheckpointManager(folder.absolute(), options=options)


def _identity(config: Config) -> dict:
    t = asdict(config.train)
    for key in ("out", "steps", "validate_every", "checkpoint_seconds"):
        t.pop(key)
    if not t["balance"]:  # runs from before the option keep their identity
        t.pop("balance")
    data = {**config.data.identity(), "scenes": config.data.scenes}  # fixes the split
    return {"data": data, "model": asdict(config.model), "train": t}


def _read_metrics(path: Path, upto: int) -> list[dict]:
    if not path.exists():
        return []
    with path.open() as f:
        return [row for row in csv.DictReader(f) if int(row["step"]) <= upto]


def plot_losses(rows: list[dict], path: Path, title: str) -> None:
    """Write the training and validation loss curves of metrics rows to a PNG."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(figsize=(6, 4))
    train = [(int(r["step"]), float(r["loss"])) for r in rows if r["loss"]]
    if train:
        ax.plot(*zip(*train, strict=True), lw=0.8, label="training (batch)")
    val = [(int(r["step"]), float(r["validation_loss"])) for r in rows if r["validation_loss"]]
    if val:
        ax.plot(*zip(*val, strict=True), "o-", ms=3, label="validation")
    ax.set(xlabel="step", ylabel="loss", yscale="log", title=title)
    ax.legend()
    fig.tight_layout()
    fig.savefig(path, dpi=120)
    plt.close(fig)


def train(config: Config, progress: bool = True) -> tuple[dict, list[dict]]:
    """Build or complete the training set, then train (resuming from the run's checkpoints);
    returns the final parameters and the metrics rows."""
    manifest = build(config.data, progress=progress)
    n = len(manifest["shards"])
    t, m = config.train, config.model
    sampler = Sampler(config, manifest, list(range(n - t.validation_scenes)))
    validation = Sampler(config, manifest, list(range(n - t.validation_scenes, n)))
    val_batch, val_target, val_part = validation.draw(np.random.default_rng((t.seed, 1 << 30)),
                                            t.validation_points,
                                            max(1, len(validation.choices)))  # fmt: skip
    out = Path(t.out)
    out.mkdir(parents=True, exist_ok=True)
    identity = _identity(config)
    stamp = out / "config.json"
    if stamp.exists():
        try:
            same = json.loads(stamp.read_text()) == identity
        except (json.JSONDecodeError, UnicodeDecodeError):
            same = False
        if not same:
            raise InputError(f"{out}: holds a run with other settings; use another [train] out")
    with atomic(stamp) as tmp:
        tmp.write_text(json.dumps(identity, indent=1))

    model = make_model(m.architecture, m.width)
    optimiser, loss, step = make_steps(model, t.learning_rate, t.loss, t.balance)
    params = init_params(model, m.k, t.seed)
    opt_state = optimiser.init(params)
    ocp, manager = _checkpointer(out / "checkpoints")
    done = manager.latest_step() or 0
    if done:
        target = {"params": params, "opt_state": opt_state}
        state = manager.restore(done, args=ocp.args.StandardRestore(target))
        params, opt_state = state["params"], state["opt_state"]
    rows = _read_metrics(out / "metrics.csv", done)
    if not rows:  # step 0: the fresh network (for DPM, the uniform kernel: PM-K)
        value = f"{float(loss(params, val_batch, val_target, val_part)):.6g}"
        rows.append({"step": 0, "loss": "", "validation_loss": value, "seconds": "0.00"})

    def save(at: int) -> None:
        # metrics first: a kill before the checkpoint leaves rows past it, which a resume
        # drops, never a gap
        with atomic(out / "metrics.csv") as tmp, tmp.open("w", newline="") as f:
            writer = csv.DictWriter(f, ["step", "loss", "validation_loss", "seconds"])
            writer.writeheader()
            writer.writerows(rows)
        if manager.latest_step() != at:
            manager.save(at, args=ocp.args.StandardSave({"params": params, "opt_state": opt_state}))
            manager.wait_until_finished()
        with atomic(out / "loss.png") as tmp:
            plot_losses(rows, tmp, f"{m.architecture}, K = {m.k}, {t.loss} loss")

    previous = signal.signal(signal.SIGTERM, _raise_interrupt)
    bar = tqdm(total=t.steps, initial=done, unit="step", desc="training", disable=not progress)
    start, last_save = time.perf_counter(), time.perf_counter()
    offset = float(rows[-1]["seconds"]) if rows else 0.0
    try:

        def draw(s: int) -> tuple[Batch, np.ndarray, np.ndarray]:
            return sampler.draw(np.random.default_rng((t.seed, s)), t.batch, t.scenes_per_batch)

        ahead = draw(done + 1) if done < t.steps else None
        for s in range(done + 1, t.steps + 1):
            new = step(params, opt_state, *ahead)  # runs asynchronously while the next batch
            ahead = draw(s + 1) if s < t.steps else None  # is gathered; an interrupt in
            params, opt_state, value = new  # between keeps step s - 1 as the last one done
            done = s
            row = {"step": s, "loss": f"{float(value):.6g}", "validation_loss": "",
                   "seconds": f"{offset + time.perf_counter() - start:.2f}"}  # fmt: skip
            if s % t.validate_every == 0 or s == t.steps:
                held_out = loss(params, val_batch, val_target, val_part)
                row["validation_loss"] = f"{float(held_out):.6g}"
                bar.set_postfix(loss=row["loss"], validation=row["validation_loss"])
            rows.append(row)
            bar.update()
            if time.perf_counter() - last_save > t.checkpoint_seconds:
                save(s)
                last_save = time.perf_counter()
    except KeyboardInterrupt:
        save(done)
        raise
    finally:
        bar.close()
        signal.signal(signal.SIGTERM, previous)
    save(done)
    params = jax.tree.map(np.asarray, params)
    save_weights(out / "model.msgpack", Weights(m.architecture, m.width, m.k, params))
    return params, rows


def _raise_interrupt(signum: int, frame: object) -> None:
    raise KeyboardInterrupt
