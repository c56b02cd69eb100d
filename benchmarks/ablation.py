"""Kernel prediction against direct regression (paper Fig. 6): validation loss against step.

    dpm-train --config configs/dpm-50-relmse.toml
    dpm-train --config configs/direct-50.toml
    python benchmarks/ablation.py [RUN ...]

Reads each run's metrics.csv (default runs/dpm-50-balanced and runs/direct-50: the same
data, K, width, batch, loss and steps) and writes benchmarks/results/ablation.png and ablation.md.
"""

from __future__ import annotations

import argparse
import csv
import json
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from common import RESULTS  # noqa: E402


def validation(run: Path) -> list[tuple[int, float]]:
    """(step, validation loss) of a run's metrics.csv."""
    with (run / "metrics.csv").open() as f:
        return [(int(r["step"]), float(r["validation_loss"])) for r in csv.DictReader(f)
                if r["validation_loss"]]  # fmt: skip


def loss_label(run: Path) -> str:
    """What a run's validation loss is, from its config.json."""
    train = json.loads((run / "config.json").read_text())["train"]
    name = {"relmse": "relative L2", "mu-law": "μ-law L2"}.get(train["loss"], train["loss"])
    return f"{name} ÷ PM-K's" if train.get("balance") else name


def main() -> None:
    """Plot the runs' validation losses and tabulate them at common steps."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("runs", nargs="*", type=Path, default=[Path("runs/dpm-50-balanced"),
                                                           Path("runs/direct-50")])  # fmt: skip
    args = p.parse_args()
    missing = [str(run) for run in args.runs if not (run / "metrics.csv").exists()]
    if missing:
        raise SystemExit(f"no metrics.csv in {', '.join(missing)}: run dpm-train first")
    curves = {run.name: validation(run) for run in args.runs}
    label = loss_label(args.runs[0])
    fig, ax = plt.subplots(figsize=(6, 4))
    for name, points in curves.items():
        ax.plot(*zip(*points, strict=True), "o-", ms=3, label=name)
    ax.set(xlabel="step", ylabel=f"validation loss ({label})", yscale="log",
           title="Kernel prediction vs direct regression")  # fmt: skip
    ax.legend()
    fig.tight_layout()
    RESULTS.mkdir(exist_ok=True)
    fig.savefig(RESULTS / "ablation.png", dpi=120)
    common = sorted(set.intersection(*(set(dict(c)) for c in curves.values())))
    names = list(curves)
    lines = ["# Kernel prediction against direct regression", "",
             "Made by `python benchmarks/ablation.py` (see its docstring); plot: ablation.png.",
             f"Validation loss: {label}.", "",
             "| step | " + " | ".join(names) + " |", "|---|" + "---|" * len(names)]  # fmt: skip
    shown = common[:: max(1, len(common) // 10)]
    for step in shown + ([common[-1]] if common and shown[-1] != common[-1] else []):
        lines.append(f"| {step} | " + " | ".join(f"{dict(curves[n])[step]:.5f}" for n in names)
                     + " |")  # fmt: skip
    (RESULTS / "ablation.md").write_text("\n".join(lines) + "\n")


if __name__ == "__main__":
    main()
