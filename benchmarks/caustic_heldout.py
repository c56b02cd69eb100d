"""Held-out loss of caustic-filter weights on the same scenes of a caustic training set.

    python benchmarks/caustic_heldout.py WEIGHTS ... [--config configs/caustic.toml]
                                         [--scenes S] [--last N] [--z Z ...]
                                         [--by-passes]

`dpm-train` reports each run's held-out loss on the last `validation_scenes` scenes of its own
set, so two runs on sets of different sizes are scored on different scenes. This scores every
WEIGHTS file on the same scenes: the last N (default: the config's `validation_scenes`) of
the first S (default: the config's `scenes`) of the config's set (its `out`), at every pass
count of its ladder, with the config's loss and balance (1.0: the render's caustic without
the network), through the clamp at each --z standard errors (the training's is
`TRAIN_CLAMP_Z`, the render's `CLAMP_Z`). A weights file trained on any of those scenes is
not held out on them: compare only files whose sets stop before them. `--by-passes` adds the
loss at each pass count of the ladder alone (where in the ladder a filter gains).
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

import numpy as np

from dpm.caustic.stats import CLAMP_Z, TRAIN_CLAMP_Z
from dpm.nn.caustic_training import CausticSampler, caustic_estimates
from dpm.nn.config import load_config
from dpm.nn.model import make_model
from dpm.nn.train import make_steps
from dpm.nn.weights import load_weights


def heldout_loss(
    config_path: Path,
    weights: list[Path],
    scenes: int,
    last: int,
    zs: list[float],
    by_passes: bool = False,
) -> dict[tuple[str, float, int], float]:
    """{(weights file, z, passes): loss} on scenes scenes-last … scenes-1 of the config's
    caustic set; passes 0 is the whole ladder, the others (with `by_passes`) one pass count."""
    config = load_config(config_path)
    manifest = json.loads((Path(config.data.out) / "manifest.json").read_text())
    if not 0 < last <= scenes:
        raise SystemExit("caustic_heldout: need 0 < --last ≤ --scenes")
    held = {e["index"] for e in manifest["shards"]}
    wanted = list(range(scenes - last, scenes))
    if not held.issuperset(wanted):  # never fall back on other (perhaps training) scenes
        raise SystemExit(f"caustic_heldout: {config.data.out} lacks some of scenes "
                         f"{wanted[0]}-{wanted[-1]}")  # fmt: skip
    sampler = CausticSampler(config, manifest, wanted)
    batch, target, _ = sampler.draw(np.random.default_rng(0), len(sampler.choices), 1)
    subsets = {0: np.arange(len(sampler.choices))}
    if by_passes:
        for p in sampler.ladder:
            subsets[p] = np.array([k for k, (_, q) in enumerate(sampler.choices) if q == p])
    images = target.reshape(len(sampler.choices), -1, 3)
    t, out = config.train, {}
    for path in weights:
        w = load_weights(path)
        model = make_model(w.architecture, w.width)
        for z in zs:  # the training's own held-out loss, through the clamp at z
            _, loss, _ = make_steps(model, t.learning_rate, t.loss, t.balance,
                                    caustic_estimates(model, z))  # fmt: skip
            for p, rows in subsets.items():
                sub = type(batch)(*(field[rows] for field in batch))
                pixels = images.shape[1]
                part = np.repeat(np.arange(len(rows), dtype=np.int32), pixels)
                value = loss(w.params, sub, images[rows].reshape(-1, 3), part)
                out[(str(path), z, p)] = float(value)
    return out


def main() -> None:
    """Print the loss of each weights file at each clamp."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("weights", nargs="+", type=Path)
    p.add_argument("--config", type=Path, default=Path("configs/caustic.toml"))
    p.add_argument("--scenes", type=int, default=0, help="the set's size (default: scenes)")
    p.add_argument("--last", type=int, default=0, help="scenes (default: validation_scenes)")
    p.add_argument("--z", type=float, nargs="+", default=sorted({TRAIN_CLAMP_Z, CLAMP_Z}))
    p.add_argument("--by-passes", action="store_true", help="also the loss at each pass count")
    a = p.parse_args()
    config = load_config(a.config)
    last = a.last or config.train.validation_scenes
    scenes = a.scenes or config.data.scenes
    losses = heldout_loss(a.config, a.weights, scenes, last, a.z, a.by_passes)
    for (path, z, passes), value in losses.items():
        at = f"{passes} passes" if passes else "all passes"
        print(f"{path}  z={z:g}  {at}  held-out loss {value:.4f}  "
              f"(scenes {scenes - last}-{scenes - 1})")  # fmt: skip


if __name__ == "__main__":
    main()
