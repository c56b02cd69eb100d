"""Weight files: a trained network's parameters with what is needed to rebuild it.

A weight file is one msgpack blob (flax.serialization) holding the architecture, base width,
K and the parameters; `dpm-train` writes one at the end of a run, and the shipped models live
in `dpm/nn/weights/dpm-K.msgpack`.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import flax.linen as nn
import jax
import numpy as np
from flax import serialization, traverse_util

from dpm.errors import InputError
from dpm.io import atomic
from dpm.nn.model import ARCHITECTURES, example_input, make_model

SHIPPED = Path(__file__).parent / "weights"


@dataclass(frozen=True)
class Weights:
    """A trained network: its architecture, base width, K and parameters."""

    architecture: str  # 'dpm', 'dpm-l', 'direct' or 'nppm'
    width: int  # base channel count (×4 for 'dpm-l')
    k: int  # neighbours per visible point it was trained with (unused by nppm)
    params: dict  # flax parameter pytree (numpy arrays)

    def model(self) -> nn.Module:
        """The flax module these parameters belong to."""
        return make_model(self.architecture, self.width)


def save_weights(path: str | Path, weights: Weights) -> None:
    """Write weights to path atomically (temporary file, then rename)."""
    path = Path(path)
    blob = serialization.msgpack_serialize({
        "architecture": weights.architecture, "width": weights.width, "k": weights.k,
        "params": serialization.to_state_dict(weights.params),
    })  # fmt: skip
    path.parent.mkdir(parents=True, exist_ok=True)
    with atomic(path) as tmp:
        tmp.write_bytes(blob)


def load_weights(path: str | Path) -> Weights:
    """Read a weight file; InputError (one line) when it is missing or not one."""
    path = Path(path)
    try:
        data = serialization.msgpack_restore(path.read_bytes())
        weights = Weights(
            str(data["architecture"]), int(data["width"]), int(data["k"]),
            _to_numpy(data["params"]),
        )  # fmt: skip
    except FileNotFoundError:
        raise InputError(f"{path}: weight file not found") from None
    except Exception as e:  # msgpack and key errors alike: not a weight file
        raise InputError(f"{path}: not a dpm weight file ({type(e).__name__})") from None
    if weights.architecture not in ARCHITECTURES or weights.k < 1 or weights.width < 1:
        raise InputError(f"{path}: not a dpm weight file (bad architecture, width or k)")
    inputs = example_input(weights.architecture, weights.k)
    expected = jax.eval_shape(weights.model().init, jax.random.key(0), *inputs)

    def shapes(tree: object) -> dict:
        return {k: tuple(v.shape) for k, v in traverse_util.flatten_dict(tree).items()}

    if shapes(weights.params) != shapes(expected):
        raise InputError(f"{path}: parameters do not fit a {weights.architecture} network of "
                         f"width {weights.width}")  # fmt: skip
    return weights


def weight_ks(folder: Path = SHIPPED) -> list[int]:
    """K of every dpm-K.msgpack in folder (default: the shipped models), ascending."""
    return sorted(int(p.stem[4:]) for p in folder.glob("dpm-*.msgpack") if p.stem[4:].isdigit())


def shipped_weights(k: int) -> Path:
    """Path of the shipped DPM model for K = k; InputError naming the Ks there are."""
    path = SHIPPED / f"dpm-{k}.msgpack"
    if not path.exists():
        ks = weight_ks()
        have = ", ".join(map(str, ks)) if ks else "none yet"
        raise InputError(f"no shipped DPM model for --k {k} (shipped: {have}); train one with "
                         "dpm-train and pass --weights")  # fmt: skip
    return path


def _to_numpy(tree: object) -> object:
    if isinstance(tree, dict):
        return {key: _to_numpy(value) for key, value in tree.items()}
    return np.asarray(tree)
