"""A training run's folder (`[train] out`): its settings stamp, checkpoints, metrics, loss plot.

- `config.json`: what the run's parameters depend on; a folder holding a run with other
  settings is refused, so a resume never mixes two runs;
- `checkpoints/`: orbax, the parameters and Adam state of the last two saved steps;
- `metrics.csv`: step, training loss, validation loss, seconds (step 0 is the fresh network,
  which for DPM is the uniform kernel, i.e. PM-K);
- `loss.png`: the training and validation loss curves;
- `model.msgpack`: the final weights (written by dpm.nn.train at the end).
"""

from __future__ import annotations

import csv
import json
from dataclasses import asdict
from pathlib import Path

from dpm.errors import InputError
from dpm.io import atomic
from dpm.nn.config import Config

METRICS = ("step", "loss", "validation_loss", "seconds")  # the columns of metrics.csv


def _identity(config: Config) -> dict:
    """The settings a run's parameters depend on (not its folder, length or save cadence)."""
    t = asdict(config.train)
    for key in ("out", "steps", "validate_every", "checkpoint_seconds", "keep_best"):
        t.pop(key)
    if not t["balance"]:  # runs from before the option keep their identity
        t.pop("balance")
    if t["clamp_z"] == 2.0 or config.model.architecture != "caustic":  # likewise; unused
        t.pop("clamp_z")
    for key in ("augment", "hull"):  # likewise: off in every run from before them
        if not t[key]:
            t.pop(key)
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


class RunFolder:
    """The folder of one run: claimed on creation, then restored from and saved to."""

    def __init__(self, config: Config) -> None:
        """Create `[train] out` and stamp it with the run's settings; InputError when it
        holds a run with other settings."""
        import orbax.checkpoint as ocp

        self.out = Path(config.train.out)
        self.out.mkdir(parents=True, exist_ok=True)
        identity = _identity(config)
        stamp = self.out / "config.json"
        if stamp.exists():
            try:
                same = json.loads(stamp.read_text()) == identity
            except (json.JSONDecodeError, UnicodeDecodeError):
                same = False
            if not same:
                raise InputError(
                    f"{self.out}: holds a run with other settings; use another [train] out"
                )
        with atomic(stamp) as tmp:
            tmp.write_text(json.dumps(identity, indent=1))
        m, t = config.model, config.train
        what = (
            m.architecture
            if m.architecture in ("nppm", "caustic")
            else f"{m.architecture}, K = {m.k}"
        )
        self.title = f"{what}, {t.loss} loss"
        self.weights = self.out / "model.msgpack"
        self._ocp = ocp
        options = ocp.CheckpointManagerOptions(max_to_keep=2, enable_async_checkpointing=False)
        folder = (self.out / "checkpoints").absolute()
        self._manager = ocp.CheckpointManager(folder, options=options)

    def restore(self, params: dict, opt_state: object) -> tuple[int, dict, object, list[dict]]:
        """The last saved step (0 for a new run), its parameters and Adam state (those given,
        fresh ones, for a new run) and its metrics rows (dicts of METRICS, as strings)."""
        done = self._manager.latest_step() or 0
        if done:
            target = {"params": params, "opt_state": opt_state}
            state = self._manager.restore(done, args=self._ocp.args.StandardRestore(target))
            params, opt_state = state["params"], state["opt_state"]
        return done, params, opt_state, _read_metrics(self.out / "metrics.csv", done)

    def save(self, step: int, params: dict, opt_state: object, rows: list[dict]) -> None:
        """Save the metrics rows, the parameters and Adam state after `step`, and the plot."""
        # metrics first: a kill before the checkpoint leaves rows past it, which a resume
        # drops, never a gap
        with atomic(self.out / "metrics.csv") as tmp, tmp.open("w", newline="") as f:
            writer = csv.DictWriter(f, METRICS)
            writer.writeheader()
            writer.writerows(rows)
        if self._manager.latest_step() != step:
            state = {"params": params, "opt_state": opt_state}
            self._manager.save(step, args=self._ocp.args.StandardSave(state))
            self._manager.wait_until_finished()
        with atomic(self.out / "loss.png") as tmp:
            plot_losses(rows, tmp, self.title)
