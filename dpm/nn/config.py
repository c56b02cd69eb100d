"""A dpm-train config: its dataclasses, and reading and checking its TOML (`load_config`).

The config has three tables: `[data]` (`dpm.data.dataset.DataConfig`: the training set),
`[model]` (`ModelConfig`) and `[train]` (`TrainConfig`). Every key is checked; an unknown
one, a wrong type or a value out of range is an InputError of one line. A `[train]` table
that names no `loss` or `balance` gets the recommended balanced `mse+relmse` (see
dpm.nn.losses). Folders (`[data] out`, `[train] out`) are kept as written: a relative one is
relative to the directory dpm-train runs from, not to the config file.
"""

from __future__ import annotations

import tomllib
from dataclasses import dataclass, fields
from pathlib import Path

from dpm.data.dataset import DataConfig
from dpm.errors import InputError
from dpm.nn.losses import LOSSES
from dpm.nn.model import ARCHITECTURES


@dataclass(frozen=True)
class ModelConfig:
    """Which network (the `[model]` table)."""

    architecture: str = "dpm"  # 'dpm', 'dpm-l' (4× channels) or 'direct' (ablation)
    width: int = 32  # channels of the feature extractor and kernel predictor
    k: int = 50  # nearest photons per visible point


SCHEDULES = ("constant", "cosine")  # of the learning rate, `[train] schedule`


@dataclass(frozen=True)
class TrainConfig:
    """How to train (the `[train]` table)."""

    out: str = "runs/dpm"  # run folder: checkpoints, metrics, loss curve, final weights
    steps: int = 2000
    batch: int = 512  # visible points per step
    scenes_per_batch: int = 4  # training scenes each batch is drawn from
    learning_rate: float = 1e-3  # Adam
    # 'constant', or 'cosine': the rate falls from learning_rate to 0 over `steps` (a resumed
    # run follows the same curve: the schedule counts the optimiser's own steps)
    schedule: str = "constant"
    validation_scenes: int = 1  # the last scenes of the set, held back
    validation_points: int = 4096
    validate_every: int = 100  # steps
    checkpoint_seconds: float = 180.0
    seed: int = 0
    loss: str = "mse+relmse"  # one of LOSSES ('mu-law' is the paper's Eq. 4): see dpm.nn.losses
    balance: bool = True  # divide each (scene, budget) part's loss by PM-K's: see dpm.nn.losses
    # caustic filter only: standard errors of the clamp's centre the filter may move it from
    # in training (the render holds it within dpm.caustic.stats.CLAMP_Z)
    clamp_z: float = 2.0
    # caustic filter only: turn each training image by a random symmetry of the square
    augment: bool = False
    # caustic filter only: hold the move within the hull of clamp_z standard errors about the
    # centre and about the pixel's own estimate, as the render does (stats.HULL_CLAMP); off in
    # the shipped config: trained so, the weights did no better (docs/training.md)
    hull: bool = False
    # the weights of the step with the least validation loss, not the last step's (the
    # held-out scenes are the training set's own, never the unseen-scene set)
    keep_best: bool = False


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
    if d.kind not in ("points", "caustic"):
        raise InputError(f"{path}: [data] kind must be 'points' or 'caustic'")
    if (d.kind == "caustic") != (m.architecture == "caustic"):
        raise InputError(f"{path}: the caustic architecture trains on [data] kind = 'caustic', "
                         "and only it does")  # fmt: skip
    ladder = list(d.passes)
    if (
        not ladder
        or min(ladder) < 1
        or d.target_passes <= max(ladder)
        or ladder != sorted(set(ladder))
    ):
        raise InputError(f"{path}: [data] passes must be positive, increasing and below "
                         "target_passes")  # fmt: skip
    if t.schedule not in SCHEDULES:
        raise InputError(f"{path}: [train] schedule must be one of {list(SCHEDULES)}")
    if not t.clamp_z > 0:
        raise InputError(f"{path}: [train] clamp_z must be positive (got {t.clamp_z})")
    if not d.budgets or min(d.budgets) < 1 or not t.learning_rate > 0:
        raise InputError(f"{path}: [data] budgets and [train] learning_rate must be positive")
    for key in ("reference_paths", "reference_paths_per_pass"):
        if getattr(d, key) < 1:
            raise InputError(f"{path}: [data] {key} must be at least 1")
    if d.workers < 0:
        raise InputError(f"{path}: [data] workers must be 0 (one per core), 1 (no Ray) or more")
    if not 0 < d.reference_radius < 1:
        raise InputError(f"{path}: [data] reference_radius must be in (0, 1): a fraction of "
                         "the scene's diagonal")  # fmt: skip
    if t.loss not in LOSSES:
        raise InputError(f"{path}: [train] loss must be one of {', '.join(LOSSES)}")
    if t.batch < t.scenes_per_batch:
        raise InputError(f"{path}: [train] batch must be at least scenes_per_batch")
    return config
