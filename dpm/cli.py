"""Command-line entry points `dpm-render` and `dpm-train`.

Bad input (InputError) becomes one line on stderr and exit status 2, never a traceback. The
renderer (Numba, SciPy) and the network (JAX) are imported inside the functions that need
them, so `--version` answers without them.
"""

from __future__ import annotations

import argparse
import os
import sys
import tempfile
import warnings
from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path
from typing import TYPE_CHECKING

from dpm import __version__
from dpm.clock import process_started
from dpm.errors import InputError
from dpm.options import COMPONENTS, cli_fields, default_text, flag

if TYPE_CHECKING:
    from dpm.options import RenderOptions

# the README's first render on 2 idle cores: 77-88 s (AMD Zen 5), 83 s (Intel Xeon), 97-155 s
# (Zen 4), 262-382 s (Zen 3, AVX2 only, whose speed varies from hour to hour); cold_start.py
FIRST_RUN = "one and a half to seven minutes on 2 cores"


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
    """dpm-render's parser: the outputs, then one flag per RenderOptions field."""
    from dpm.methods import METHODS, scoped_users  # the registry: imports the renderer

    p = _Parser(
        prog="dpm-render",
        description="Render an OBJ scene (with its MTL and optional TOML sidecar) or a Mitsuba 3 "
        "XML scene. Flags override the sidecar's [render] table.",
        epilog="methods: " + "; ".join(f"{n}: {c.summary}" for n, c in METHODS.items()),
    )
    p.add_argument("scene", type=Path, help="scene .obj (or Mitsuba 3 .xml) file")
    p.add_argument(
        "-o", "--output", type=Path, action="append",
        help="image to write: .exr (linear) or .png (sRGB); repeat for both "
        "(default: SCENE.exr and SCENE.png in the current folder)",
    )  # fmt: skip
    choices = {"method": list(METHODS), "component": list(COMPONENTS)}
    for f in cli_fields():
        kind = str(f.type).split(" |")[0]
        help = f"{f.metadata['help']} (default: {default_text(f)})"
        if f.metadata["scoped"]:
            help += "; " + ", ".join(scoped_users(f.name)) + " only"
        if kind == "bool":
            p.add_argument(flag(f.name), action=argparse.BooleanOptionalAction, help=help)
            continue
        p.add_argument(
            flag(f.name), type={"int": int, "float": float, "str": str, "Path": Path}[kind],
            choices=choices.get(f.name), metavar=f.metadata.get("metavar"), help=help,
        )  # fmt: skip
    p.add_argument("--stats", type=Path, metavar="FILE.json", help="write timings and counts")
    p.add_argument("--quiet", action="store_true", help="no progress bar or summary")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    return p


STAGES = {  # the summary's stages: name -> the render's timing keys
    "load": ("load", "bvh", "kernels"),
    "trace": ("photons",),
    "gather": ("gather",),
    "estimate": ("estimate",),
    "network": ("network",),
    "path tracing": ("visible_points", "shade", "path"),
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


def render_options(args: argparse.Namespace, sidecar: dict) -> RenderOptions:
    """RenderOptions from the flags over the sidecar's [render] defaults (`options_from`)."""
    from dpm.methods import options_from

    given = {f.name: getattr(args, f.name) for f in cli_fields()}
    options = options_from(sidecar, {k: v for k, v in given.items() if v is not None})
    options.progress = not args.quiet and sys.stderr.isatty()
    return options


def kernels_cold() -> bool:
    """Whether Numba's kernel cache is empty (or was stale): the render compiles for
    minutes before its first pass."""
    from dpm.tracer._cache import kernels_cached

    return not kernels_cached()


def warn_overrun(stats: dict, budget: float | None) -> None:
    """One line on stderr when the first pass alone overran the --time budget (the image is
    then that one pass, and the render took longer than asked)."""
    if stats.get("overran"):
        compiled = stats.get("compile_seconds", 0.0)
        also = f"; compiling kernels took {compiled:.1f} s in all" if compiled > 0 else ""
        print(f"dpm-render: warning: the first pass took {stats['pass_seconds']:.2f} s and the"
              f" budget was {budget:g} s (counted from the process start: "
              f"{stats['setup_seconds']:.2f} s had gone before the first pass{also}): the image"
              " is one pass", file=sys.stderr)  # fmt: skip


def check_writable(path: Path) -> None:
    """Raise InputError unless a file can be written at `path` (checked before rendering, so
    that a bad output path never costs a render)."""
    if path.is_dir():
        raise InputError(f"{path}: is a folder, not a file name")
    if not path.resolve().parent.is_dir():
        raise InputError(f"{path}: output folder does not exist")
    try:
        with tempfile.TemporaryFile(dir=path.resolve().parent):
            pass
    except OSError as exc:
        raise InputError(f"{path}: cannot write there ({exc.strerror or exc})") from None


def render_main(argv: Sequence[str] | None = None) -> int:
    """`dpm-render`: load a scene, render it, write the image (and stats); returns exit status."""
    argv = sys.argv[1:] if argv is None else list(argv)
    if argv == ["--version"]:  # before the parser, whose method list imports the renderer
        print(f"dpm-render {__version__}")
        return 0
    args = _render_parser().parse_args(argv)

    def body() -> None:
        from dpm import load_file
        from dpm.io import write_image, write_json
        from dpm.renderer import render
        from dpm.stopwatch import Stopwatch

        outputs = args.output or [Path(args.scene.stem + e) for e in (".exr", ".png")]
        for output in outputs:
            if output.suffix.lower() not in (".png", ".exr"):
                raise InputError(f"{output}: output must end in .png or .exr")
        for path in (*outputs, args.stats):
            if path is not None:
                check_writable(path)
        if args.checkpoint is not None and not args.checkpoint.exists():
            check_writable(args.checkpoint)
        started = process_started()
        watch = Stopwatch()
        with watch("load"):
            scene = load_file(args.scene)
        options = render_options(args, scene.render_defaults)
        if not args.quiet and kernels_cold():
            print(f"dpm-render: compiling the renderer's kernels for the first run (once: "
                  f"{FIRST_RUN}; later runs load them)", file=sys.stderr)  # fmt: skip
        result = render(scene, options, started)  # validates the options first
        seconds = result.stats["seconds"]
        seconds.update(watch.seconds)
        with watch("write"):
            for output in outputs:
                write_image(output, result.image)
        seconds["write"] = watch.get("write")
        warn_overrun(result.stats, options.time)  # a warning: even with --quiet
        result.stats["scene"] = str(args.scene)
        result.stats["output"] = [str(o) for o in outputs]
        if args.stats is not None:
            write_json(args.stats, result.stats)
        if not args.quiet:
            stats = result.stats
            plan = ""
            if "plan" in stats:
                paths = f" ({stats['spp']} paths per pixel)"
                paths = paths if stats["spp"] != stats["passes"] else ""
                plan = f"; {stats['passes']} passes{paths}, {stats['plan']['reason']}"
            if plan and stats["plan"]["caustics"] == "sppm":  # the caustic's moves kept
                moved = (
                    f"{stats['narrow_weight']:.2f} towards the narrow kernel, "
                    f"{stats['extrapolated_weight']:.2f} towards the extrapolated one"
                )
                if stats["plan"]["network"]:
                    moved += f", {stats['network_weight']:.2f} towards the network's"
                plan += f"; caustic moved {moved} (the passes' halves' best blend)"
            if plan and options.denoise is not False and options.component == "full":
                share = stats.get("denoiser_share", 1.0)
                if not stats["denoised"]:  # auto kept its plain mean: say why
                    plan += "; not denoised: the halves of its paths show the plain mean is closer"
                elif share < 1:  # auto blended the two: say how much
                    plan += (f"; denoised image weighted {share:.2f} against the plain mean"
                             " (the halves' best blend)")  # fmt: skip
            print(f"wrote {', '.join(map(str, outputs))} ({stats['width']}x{stats['height']}"
                  f"{plan}): " + timing_summary(seconds))  # fmt: skip

    return _run("dpm-render", body)


def render_command() -> None:
    """The `dpm-render` console script: render_main, then exit without the interpreter's
    teardown (about 0.4 s of freeing Numba's and LLVM's modules; every file is closed and
    renamed into place by then). The garbage collector waits until the renderer has loaded
    (`dpm.collector`), and Numba loads cached kernels without its registries and compiles
    without the optional imports no kernel needs (`dpm._lean_numba`)."""
    from dpm import collector

    collector.pause()
    from dpm._lean_numba import start_lean  # (imports Numba)

    start_lean()
    code = render_main()
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(code)


def train_main(argv: Sequence[str] | None = None) -> int:
    """`dpm-train`: make the training set, train, write the weights; returns exit status."""
    p = _Parser(prog="dpm-train", description="Train a DPM kernel-prediction network.")
    p.add_argument("--config", type=Path, required=True, help="training config (.toml)")
    p.add_argument(
        "--ray-address", metavar="ADDR",
        help="make the training set on this Ray cluster (default: the config's [data] "
        "ray_address; none: this machine, [data] workers processes at once)",
    )  # fmt: skip
    p.add_argument("--quiet", action="store_true", help="no progress bars or summary")
    p.add_argument("--version", action="version", version=f"%(prog)s {__version__}")
    args = p.parse_args(argv)

    def body() -> None:
        from dpm.nn.config import load_config  # imports JAX: only when training
        from dpm.nn.train import train

        config = load_config(args.config)
        if args.ray_address:
            config = replace(config, data=replace(config.data, ray_address=args.ray_address))
        _, rows = train(config, progress=not args.quiet and sys.stderr.isatty())
        if not args.quiet:
            last = next((r for r in reversed(rows) if r["validation_loss"]), rows[-1])
            print(
                f"dpm-train: {len(rows)} steps; validation loss {last['validation_loss']} at "
                f"step {last['step']}; weights in {Path(config.train.out) / 'model.msgpack'}"
            )

    return _run("dpm-train", body)


if __name__ == "__main__":
    render_command()
