"""Training-set throughput: whole-process seconds to make scenes of a config's [data] table.

    python benchmarks/data_throughput.py --scenes 12 --workers 1   # in this process
    python benchmarks/data_throughput.py --scenes 12 --workers 2   # local Ray, 2 workers

Builds into a fresh temporary folder (nothing is kept) and prints the wall time from the
start of the process, scenes per hour and each scene's own seconds; `--reference-paths`
overrides the config's, to see how the PPM reference's cost grows.
"""

from __future__ import annotations

import time

START = time.perf_counter()  # whole process: imports count

import argparse  # noqa: E402
import tempfile  # noqa: E402
from dataclasses import replace  # noqa: E402
from pathlib import Path  # noqa: E402

from dpm.data.dataset import build  # noqa: E402
from dpm.nn.config import load_config  # noqa: E402

HERE = Path(__file__).parent


def main() -> None:
    """Build the scenes asked for and print their timings."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--config", type=Path, default=HERE.parent / "configs" / "dpm-50.toml")
    p.add_argument("--scenes", type=int, default=12)
    p.add_argument("--workers", type=int, default=1, help="1: this process; N: local Ray")
    p.add_argument("--reference-paths", type=int, help="default: the config's")
    args = p.parse_args()
    data = load_config(args.config).data
    with tempfile.TemporaryDirectory() as out:
        config = replace(data, out=out, scenes=args.scenes, workers=args.workers)
        if args.reference_paths:
            config = replace(config, reference_paths=args.reference_paths)
        manifest = build(config, progress=False)
    seconds = time.perf_counter() - START
    per_scene = ", ".join(f"{e['seconds']:.1f}" for e in manifest["shards"])
    print(f"{args.scenes} scenes, workers {args.workers}, {config.reference_paths:,} reference "
          f"paths: {seconds:.1f} s whole process ({3600 * args.scenes / seconds:.0f} scenes an "
          f"hour); seconds per scene: {per_scene}")  # fmt: skip


if __name__ == "__main__":
    main()
