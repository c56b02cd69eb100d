"""Two source trees of dpm at equal whole-process time, on a scene set's caustic references.

    git worktree add /tmp/old COMMIT
    python benchmarks/ab_trees.py /tmp/old . [--set unseen] [SCENE ...] [--times 2 4 8]
                                  [--seeds 1 2] [--extra=--no-network]

Each tree renders `dpm-render SCENE --time T` in a fresh process (`python -c` calling
`dpm.cli.render_command`, with PYTHONPATH set to the tree and the working directory outside
both, so each process imports its own tree), in turn, the order alternating budget after
budget and seed after seed, after one untimed warm-up each per scene (Numba's cache). Scored
by RMSE against the SPPM caustic references of `caustic_references.py` (the caustic
component, at the references' sizes), whole-process seconds and passes from the stats.
With `--full` (unseen set only) the whole image is rendered and scored against the scene's
Mitsuba 3 path-traced reference (`equal_time_unseen.scoring_reference`), which holds no
photon estimator's blur: the caustic references are SPPM's own run long, and a render that
gathers more photons than its reference did is scored against the reference's blur.
Prints a line per scene and budget and the geometric mean of the ratios B / A, and writes
the rows as JSON to --out (default results/ab_trees.json).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from caustic_references import EXAMPLES, load_reference, size

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from equal_time_unseen import scoring_reference  # noqa: E402
from make_unseen import CONTROLS, UNSEEN, unit_scale  # noqa: E402

from common import RESULTS, geomean  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.io import read_exr  # noqa: E402
from dpm.metrics import rmse  # noqa: E402

LAUNCH = (
    "import sys; from dpm.cli import render_command; sys.argv[0] = 'dpm-render'; render_command()"
)


def run(tree: Path, args: list[str], folder: Path) -> tuple[np.ndarray, float, dict]:
    """(image, whole-process seconds, stats) of one render by the tree's dpm."""
    out, stats = folder / "ab.exr", folder / "ab.json"
    env = {**os.environ, "PYTHONPATH": str(tree)}
    command = [sys.executable, "-c", LAUNCH, *args, "-o", str(out), "--stats", str(stats),
               "--quiet"]  # fmt: skip
    start = time.perf_counter()
    subprocess.run(command, check=True, env=env, cwd=folder, stdout=subprocess.DEVNULL)
    seconds = time.perf_counter() - start
    return read_exr(out), seconds, json.loads(stats.read_text())


def main() -> None:
    """Run both trees on every scene and budget."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("a", type=Path, help="the first tree (the baseline)")
    p.add_argument("b", type=Path, help="the second tree")
    p.add_argument("scenes", nargs="*")
    p.add_argument("--set", choices=("examples", "unseen"), default="unseen")
    p.add_argument("--times", type=float, nargs="+", default=[2.0, 4.0, 8.0])
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    p.add_argument("--extra", default="", help="more dpm-render arguments for both trees")
    p.add_argument("--full", action="store_true", help="whole images against Mitsuba's")
    p.add_argument("--out", type=Path, default=RESULTS / "ab_trees.json")
    a = p.parse_args()
    if a.full and a.set != "unseen":
        p.error("--full needs the unseen set (its Mitsuba references)")
    trees = (a.a.resolve(), a.b.resolve())
    names = EXAMPLES if a.set == "examples" else [n for n in UNSEEN if n not in CONTROLS]
    names = [n for n in names if not a.scenes or n in a.scenes]
    rows = []
    for name in names:
        obj, w, h = size(name, a.set)
        component = ["--component", "caustic"]
        if a.full:
            camera = load_scene(obj).camera
            w, h, path, _ = scoring_reference(name, camera.width)
            ref, component = read_exr(path), []
        else:
            ref_name = unit_scale(name) if a.set == "unseen" else name
            ref, _, _ = load_reference(ref_name, w, h, a.set)
        base = [str(obj.resolve()), "--width", str(w), "--height", str(h), *component,
                *a.extra.split()]  # fmt: skip
        with tempfile.TemporaryDirectory() as tmp:
            folder = Path(tmp)
            for tree in trees:  # warm each tree's kernel cache, untimed
                run(tree, [*base, "--time", str(max(a.times)), "--seed", "0"], folder)
            for i, budget in enumerate(a.times):
                got: dict[int, list] = {0: [], 1: []}
                for seed in a.seeds:
                    order = (0, 1) if (i + seed) % 2 == 0 else (1, 0)
                    for k in order:
                        args = [*base, "--time", str(budget), "--seed", str(seed)]
                        image, seconds, stats = run(trees[k], args, folder)
                        got[k].append((rmse(image, ref), seconds, stats["passes"]))
                row = {"scene": name, "budget": budget}
                for k, key in ((0, "a"), (1, "b")):
                    row[key] = float(np.mean([e for e, _, _ in got[k]]))
                    row[f"{key}_s"] = float(np.mean([s for _, s, _ in got[k]]))
                    row[f"{key}_passes"] = float(np.mean([n for *_, n in got[k]]))
                row["ratio"] = row["b"] / row["a"]
                rows.append(row)
                print(f"{name} {budget:g} s: A {row['a']:.5f} ({row['a_passes']:.0f} passes, "
                      f"{row['a_s']:.2f} s) B {row['b']:.5f} ({row['b_passes']:.0f}, "
                      f"{row['b_s']:.2f} s) B/A {row['ratio']:.3f}", flush=True)  # fmt: skip
    record = {"a": str(trees[0]), "b": str(trees[1]), "extra": a.extra, "set": a.set,
              "full": a.full, "rows": rows}  # fmt: skip
    a.out.write_text(json.dumps(record, indent=1))
    for budget in a.times:
        at = [r["ratio"] for r in rows if r["budget"] == budget]
        print(
            f"{budget:g} s: geometric mean B/A {geomean(at):.3f}, range {min(at):.3f}-{max(at):.3f}"
        )
    everything = [r["ratio"] for r in rows]
    print(f"all: geometric mean B/A {geomean(everything):.3f}, worst {max(everything):.3f}")


if __name__ == "__main__":
    main()
