"""DPM weight files on the training set's held-out scenes: caustic RMSE per photon budget.

The same points for every weight file: up to POINTS_PER_SCENE visible points of each of the
last `[train] validation_scenes` scenes of `[data]` (the scenes no step trained on), drawn
with a fixed seed, at the canonical tangent angle (as inference uses), against the set's
guided PPM reference. PM-K is the uniform kernel over the same K nearest photons (the
network's starting point); a (scene, budget) whose map holds fewer than K photons is left
out, as in training.

    python benchmarks/dpm_heldout.py --config configs/dpm-50.toml \
        --weights OLD.msgpack NEW.msgpack [--out TABLE]

Needs the config's training set (`dpm-train --config ...` makes it).
"""

from __future__ import annotations

import argparse
import datetime
from pathlib import Path

import numpy as np

from common import cpu, markdown_table
from dpm.data.dataset import ShardCache, read_manifest, shard_sizes
from dpm.density.gather import PhotonIndex
from dpm.nn.config import load_config
from dpm.nn.features import uniform_radiance
from dpm.nn.infer import Batch, make_predict, neighbourhoods
from dpm.nn.model import make_model
from dpm.nn.weights import load_weights

POINTS_PER_SCENE = 1024  # 8 held-out scenes: 8192 points per budget


def heldout_batches(config_path: Path, k: int) -> dict[int, list[tuple[Batch, np.ndarray]]]:
    """{budget: [(Batch, (n, 3) reference radiance) per held-out scene]} of the set."""
    config = load_config(config_path)
    out = Path(config.data.out)
    manifest = read_manifest(out)
    if manifest is None:
        raise SystemExit(f"{out}: no training set; run dpm-train --config {config_path} first")
    if manifest["config"] != config.data.identity():
        raise SystemExit(f"{out}: made with other [data] settings than {config_path}'s")
    held_out = range(config.data.scenes - config.train.validation_scenes, config.data.scenes)
    entries = [e for e in manifest["shards"] if e["index"] in held_out]
    if len(entries) != len(held_out):
        raise SystemExit(f"{out}: held-out scenes missing; run dpm-train --config {config_path}")
    cache = ShardCache(out, entries, config.data.budgets, len(entries))
    rng = np.random.default_rng(2026)
    batches: dict[int, list] = {b: [] for b in config.data.budgets}
    for i, entry in enumerate(entries):
        shard = cache.shard(i)
        rows = rng.choice(len(shard.position), min(POINTS_PER_SCENE, len(shard.position)), False)
        for budget in config.data.budgets:
            if shard_sizes(entry, budget)[1] < k:
                continue
            index = cache.per_map(i, budget, PhotonIndex)
            parts = list(
                neighbourhoods(index, shard.position[rows], shard.normal[rows],
                               shard.albedo[rows], k)
            )  # fmt: skip
            batch = Batch(*(np.concatenate(f) for f in zip(*(b for _, b in parts), strict=True)))
            batches[budget].append((batch, shard.radiance[rows]))
    return batches


def rmse_of(parts: list[tuple[np.ndarray, np.ndarray]]) -> float:
    """RMSE over every (estimate, reference) pair's RGB values."""
    err = np.concatenate([(e - r).ravel() for e, r in parts])
    return float(np.sqrt(np.mean(err**2)))


def main() -> None:
    """Parse the arguments, score each weight file and PM-K, write the Markdown table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", type=Path, required=True)
    p.add_argument("--weights", type=Path, nargs="+", required=True)
    p.add_argument("--out", type=Path, default=None)
    args = p.parse_args()
    weights = [load_weights(w) for w in args.weights]
    k = weights[0].k
    if any(w.k != k for w in weights):
        raise SystemExit("the weight files must share one K")
    batches = heldout_batches(args.config, k)
    budgets = [b for b in batches if batches[b]]
    uniform = [rmse_of([(np.asarray(uniform_radiance(b)), r) for b, r in batches[n]])
               for n in budgets]  # fmt: skip
    rows = [[f"PM-{k}"] + [f"{s:.4f}" for s in uniform]]
    for path, w in zip(args.weights, weights, strict=True):
        predict = make_predict(make_model(w.architecture, w.width))
        scores = [rmse_of([(np.asarray(predict(w.params, b)), r) for b, r in batches[n]])
                  for n in budgets]  # fmt: skip
        rows.append([f"`{path}`"] + [f"{s:.4f}" for s in scores])
    points = {n: sum(len(r) for _, r in batches[n]) for n in budgets}
    lines = [
        f"# DPM-{k} on the held-out training scenes",
        "",
        f"Made by `python benchmarks/dpm_heldout.py --config {args.config} --weights "
        + " ".join(str(w) for w in args.weights) + "` (see its docstring); caustic RMSE",
        "(RGB, W/(m² sr)) at the same points for every row; points per budget: "
        + ", ".join(f"{n:,}: {points[n]:,}" for n in budgets) + ".",
        f"Machine: {cpu()}; {datetime.date.today()}.",
        "",
        *markdown_table(["weights"] + [f"{n:,} paths" for n in budgets], rows),
    ]  # fmt: skip
    text = "\n".join(lines) + "\n"
    print(text)
    if args.out:
        args.out.write_text(text)


if __name__ == "__main__":
    main()
