"""Held-out loss of caustic-filter weights on the same scenes of a caustic training set.

    python benchmarks/caustic_heldout.py WEIGHTS ... [--config configs/caustic.toml]
                                         [--scenes S] [--last N] [--z Z ...]

`dpm-train` reports each run's held-out loss on the last `validation_scenes` scenes of its own
set, so two runs on sets of different sizes are scored on different scenes. This scores every
WEIGHTS file on the same scenes: the last N (default: the config's `validation_scenes`) of
the first S (default: the config's `scenes`) of the config's set (its `out`), at every pass
count of its ladder, with the config's loss and balance (1.0: the render's caustic without
the network), through the clamp at each --z standard errors (the training's is
`TRAIN_CLAMP_Z`, the render's `CLAMP_Z`). A weights file trained on any of those scenes is
not held out on them: compare only files whose sets stop before them.
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
    config_path: Path, weights: list[Path], scenes: int, last: int, zs: list[float]
) -> dict[tuple[str, float], float]:
    """{(weights file, z): loss} on scenes scenes-last … scenes-1 of the config's caustic set."""
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
    batch, target, part = sampler.draw(np.random.default_rng(0), len(sampler.choices), 1)
    t, out = config.train, {}
    for path in weights:
        w = load_weights(path)
        model = make_model(w.architecture, w.width)
        for z in zs:  # the training's own held-out loss, through the clamp at z
            _, loss, _ = make_steps(model, t.learning_rate, t.loss, t.balance,
                                    caustic_estimates(model, z))  # fmt: skip
            out[(str(path), z)] = float(loss(w.params, batch, target, part))
    return out


def main() -> None:
    """Print the loss of each weights file at each clamp."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("weights", nargs="+", type=Path)
    p.add_argument("--config", type=Path, default=Path("configs/caustic.toml"))
    p.add_argument("--scenes", type=int, default=0, help="the set's size (default: scenes)")
    p.add_argument("--last", type=int, default=0, help="scenes (default: validation_scenes)")
    p.add_argument("--z", type=float, nargs="+", default=sorted({TRAIN_CLAMP_Z, CLAMP_Z}))
    a = p.parse_args()
    config = load_config(a.config)
    last = a.last or config.train.validation_scenes
    scenes = a.scenes or config.data.scenes
    for (path, z), value in heldout_loss(a.config, a.weights, scenes, last, a.z).items():
        print(f"{path}  z={z:g}  held-out loss {value:.4f}  (scenes {scenes - last}-{scenes - 1})")


if __name__ == "__main__":
    main()
