"""Command-line entry points `dpm-render` and `dpm-train`.

Bad input (InputError) becomes one line on stderr and exit status 2, never a traceback.
"""

from __future__ import annotations

import argparse
import sys
import time
import warnings
from collections.abc import Callable, Sequence
from pathlib import Path

from dpm.errors import InputError
from dpm.io import write_image, write_json
from dpm.render import COMPONENTS, METHODS, RenderOptions, render
from dpm.scene import load_scene


class _Parser(argparse.ArgumentParser):
    """argparse that reports a usage error in one line (exit 2) instead of usage + error."""

    def error(self, message: str) -> None:  # type: ignore[override]
        self.exit(2, f"{self.prog}: error: {message} (see --help)\n")


def _run(prog: str, body: Callable[[], None]) -> int:
    """Run `body`, turning bad input and interrupts into one line and an exit status."""

    def one_line_warning(message, category, filename, lineno, file=None, line=None):  # noqa: ARG001
        print(f"{prog}: warning: {message}", file=sys.stderr)

    previous = warnings.showwarning
    warnings.showwarning = one_line_warning
    try:
        body()
    except InputError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return 2
    except KeyboardInterrupt:
        print(f"{prog}: interrupted", file=sys.stderr)
        return 130
    finally:
        warnings.showwarning = previous
    return 0


def _render_parser() -> _Parser:
    p = _Parser(
        prog="dpm-render",
        description="Render an OBJ scene (with its MTL and optional TOML sidecar).",
    )
    p.add_argument("scene", type=Path, help="scene .obj file")
    p.add_argument(
        "-o", "--output", type=Path, action="append",
        help="image to write: .exr (linear) or .png (sRGB); repeat for both "
        "(default: SCENE.exr and SCENE.png in the current folder)",
    )  # fmt: skip
    p.add_argument("--method", choices=METHODS, help="rendering method (default: hybrid)")
    p.add_argument("--spp", type=int, help="samples per pixel")
    p.add_argument("--photons", type=int, help="emitted photon paths (photon methods)")
    p.add_argument("--k", type=int, help="nearest photons per estimate (pm, dpm)")
    p.add_argument(
        "--radius", type=float, help="initial gather radius, scene units (ppm/appm/sppm)"
    )
    p.add_argument(
        "--photons-per-pass", type=int, help="emitted photon paths per pass (ppm/appm/sppm)"
    )
    p.add_argument(
        "--checkpoint", type=Path, metavar="FILE.npz",
        help="ppm/appm: save statistics here as it goes and resume from it",
    )  # fmt: skip
    p.add_argument(
        "--weights", type=Path, metavar="FILE.msgpack",
        help="dpm, hybrid: weights from dpm-train (default: the shipped model for --k)",
    )  # fmt: skip
    p.add_argument(
        "--caustic-spp", type=int, metavar="N",
        help="photon methods: estimate caustics at the first N samples per pixel only "
        "(default: all; hybrid: 1)",
    )  # fmt: skip
    p.add_argument(
        "--denoise", action=argparse.BooleanOptionalAction,
        help="Open Image Denoise with albedo and normal images (default: on for hybrid only)",
    )  # fmt: skip
    p.add_argument("--seed", type=int, help="random seed (same seed, same image)")
    p.add_argument("--width", type=int, help="image width in pixels (overrides the scene)")
    p.add_argument("--height", type=int, help="image height in pixels (overrides the scene)")
    p.add_argument("--component", choices=COMPONENTS, help="full image or caustics only")
    p.add_argument("--stats", type=Path, metavar="FILE.json", help="write timings and counts")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    return p


STAGES = {  # the summary's stages: name -> the render's timing keys
    "load": ("load", "bvh"),
    "trace": ("photons",),
    "gather": ("gather",),
    "estimate": ("estimate",),
    "network": ("network",),
    "path tracing": ("visible_points", "shade"),
    "denoise": ("denoise",),
    "write": ("write",),
}


def timing_summary(seconds: dict[str, float]) -> str:
    """One line of seconds per stage (trace, gather, network, path tracing, denoise, ...)."""
    parts = [
        f"{name} {sum(seconds[k] for k in keys if k in seconds):.2f}s"
        for name, keys in STAGES.items()
        if any(k in seconds for k in keys)
    ]
    return ", ".join(parts + [f"total {sum(seconds.values()):.2f}s"])


def render_main(argv: Sequence[str] | None = None) -> int:
    """`dpm-render`: load a scene, render it, write the image (and stats); returns exit status."""
    args = _render_parser().parse_args(argv)

    def body() -> None:
        outputs = args.output or [Path(args.scene.stem + e) for e in (".exr", ".png")]
        for output in outputs:
            if output.suffix.lower() not in (".png", ".exr"):
                raise InputError(f"{output}: output must end in .png or .exr")
        for path in (*outputs, args.stats, args.checkpoint):
            if path is not None and not path.resolve().parent.is_dir():
                raise InputError(f"{path}: output folder does not exist")
        start = time.perf_counter()
        scene = load_scene(args.scene)
        load_seconds = time.perf_counter() - start
        options = RenderOptions()
        for key, value in scene.render_defaults.items():
            if hasattr(options, key):
                setattr(options, key, value)
        keys = ("method", "spp", "photons", "k", "seed", "width", "height", "component", "denoise")
        for key in keys + ("radius", "photons_per_pass", "checkpoint", "weights", "caustic_spp"):
            if getattr(args, key) is not None:
                setattr(options, key, getattr(args, key))
        options.progress = not args.quiet and sys.stderr.isatty()
        result = render(scene, options)  # validates the options first
        result.stats["seconds"]["load"] = load_seconds
        start = time.perf_counter()
        for output in outputs:
            write_image(output, result.image)
        result.stats["seconds"]["write"] = time.perf_counter() - start
        result.stats["scene"] = str(args.scene)
        result.stats["output"] = [str(o) for o in outputs]
        if args.stats is not None:
            write_json(args.stats, result.stats)
        if not args.quiet:
            print(f"wrote {', '.join(map(str, outputs))} "
                  f"({result.stats['width']}x{result.stats['height']}): "
                  + timing_summary(result.stats["seconds"]))  # fmt: skip

    return _run("dpm-render", body)


def train_main(argv: Sequence[str] | None = None) -> int:
    """`dpm-train`: make the training set, train, write the weights; returns exit status."""
    p = _Parser(prog="dpm-train", description="Train a DPM kernel-prediction network.")
    p.add_argument("--config", type=Path, required=True, help="training config (.toml)")
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    args = p.parse_args(argv)

    def body() -> None:
        from dpm.nn.train import load_config, train  # imports JAX: only when training

        config = load_config(args.config)
        _, rows = train(config, progress=not args.quiet and sys.stderr.isatty())
        if not args.quiet:
            last = next((r for r in reversed(rows) if r["validation_loss"]), rows[-1])
            print(
                f"dpm-train: {len(rows)} steps; validation loss {last['validation_loss']} at "
                f"step {last['step']}; weights in {Path(config.train.out) / 'model.msgpack'}"
            )

    return _run("dpm-train", body)


if __name__ == "__main__":
    sys.exit(render_main())
