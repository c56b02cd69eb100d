"""Two source trees of dpm, kernel against kernel: BVH queries or `pt` renders, paired.

    git worktree add /tmp/old COMMIT
    python benchmarks/ab_kernels.py /tmp/old . [--kind bvh|pt] [--rounds R] [SCENE ...]

Both trees run at once as two live worker processes (each imports its own tree, PYTHONPATH
set to it and the working directory outside both), but only one works at a time: for each
task the driver asks one, then the other, the order alternating task after task and round
after round, so that a slow spell of a shared host falls on both sides alike. This is finer
than `ab_trees.py`'s whole processes, and it sees changes of a few per cent that separate
runs of `test_bvh.py` or `path_speed.py` (minutes apart) cannot.

Tasks, after one untimed run each (compilation): `--kind bvh` (default), on one thread,
closest and any hits of 200,000 incoherent rays and of one camera ray per pixel at 384 × 384
(`test_bvh`'s rays); `--kind pt`, on all threads, a `pt` render at 128 pixels wide and 32
samples per pixel, less its BVH build. Scenes are examples or unseen ones (`test_bvh.PATHS`).
Prints each task's median rate on both sides and the median of the per-round ratios
new / old (with their range), then their geometric mean.
"""

from __future__ import annotations

import argparse
import math
import os
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path

DEFAULT_SCENES = ["dragon", "ring", "pool1", "glass_egg", "far_wall", "glass_lantern"]


def _worker(tree: str, kind: str, scenes: list[str]) -> None:
    """Prepare the tasks on tree's dpm, print 'name/work' per task tab-separated, then time
    task k (seconds) for each line k read from stdin."""
    # this tree's benchmarks/ only (the driver's script directory may be another tree's)
    here = Path(__file__).resolve().parent
    sys.path[:] = [p for p in sys.path if p and Path(p).resolve() != here]
    sys.path.insert(0, str(Path(tree) / "benchmarks"))
    import numba
    from test_bvh import PATHS

    import dpm

    if not Path(dpm.__file__).resolve().is_relative_to(Path(tree).resolve()):
        raise SystemExit(f"worker for {tree} imported {dpm.__file__}")
    tasks = []
    if kind == "bvh":
        from test_bvh import camera_rays, incoherent_rays, load_triangles

        from dpm.tracer import build_bvh, intersect, occluded

        numba.set_num_threads(1)
        for name in scenes:
            tri = load_triangles(name)
            bvh = build_bvh(tri)
            rays = {"inc": incoherent_rays(tri, 200_000), "cam": camera_rays(name, tri, 384)}
            for ray_kind, (o, d) in rays.items():
                for query, fn in (("closest", intersect), ("any", occluded)):

                    def run(fn=fn, bvh=bvh, o=o, d=d):
                        fn(bvh, o, d)
                        return 0.0  # seconds of it not to count

                    run()
                    tasks.append((f"{name}:{ray_kind}:{query}", len(o), run))
    else:
        from dpm import load_scene
        from dpm.renderer import RenderOptions, render

        for name in scenes:
            scene = load_scene(PATHS[name])
            options = RenderOptions(method="pt", spp=32, seed=1, width=128, progress=False)
            samples = render(scene, options).stats["samples"]  # the camera's aspect sets H

            def run(scene=scene, options=options):
                return render(scene, options).stats["seconds"]["bvh"]  # not to count

            tasks.append((f"{name}:pt", samples, run))
    print("\t".join(f"{name}/{work}" for name, work, _ in tasks), flush=True)
    for line in sys.stdin:
        _, _, run = tasks[int(line)]
        start = time.perf_counter()
        untimed = run()
        print(time.perf_counter() - start - untimed, flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("old")
    parser.add_argument("new")
    parser.add_argument("scenes", nargs="*", default=DEFAULT_SCENES)
    parser.add_argument("--kind", choices=("bvh", "pt"), default="bvh")
    parser.add_argument("--rounds", type=int, default=9)
    parser.add_argument("--worker", help=argparse.SUPPRESS)
    args = parser.parse_intermixed_args()
    if args.worker:
        _worker(args.worker, args.kind, args.scenes)
        return
    trees = [str(Path(t).resolve()) for t in (args.old, args.new)]
    procs = []
    with tempfile.TemporaryDirectory() as outside:
        for tree in trees:
            env = dict(os.environ, PYTHONPATH=tree)
            command = [sys.executable, str(Path(__file__).resolve()), "x", "x", *args.scenes,
                       "--kind", args.kind, "--worker", tree]  # fmt: skip
            procs.append(
                subprocess.Popen(
                    command,
                    stdin=subprocess.PIPE,
                    stdout=subprocess.PIPE,
                    text=True,
                    cwd=outside,
                    env=env,
                )  # fmt: skip
            )
        heads = [p.stdout.readline().strip().split("\t") for p in procs]
        if heads[0] != heads[1]:
            raise SystemExit(f"the trees prepared different tasks: {heads}")
        names = heads[0]
        ratios: dict[str, list[float]] = {n: [] for n in names}
        rates: dict[str, tuple[list[float], list[float]]] = {n: ([], []) for n in names}
        for r in range(args.rounds):
            for k, name in enumerate(names):
                seconds = {}
                for side in (0, 1) if (r + k) % 2 == 0 else (1, 0):
                    procs[side].stdin.write(f"{k}\n")
                    procs[side].stdin.flush()
                    seconds[side] = float(procs[side].stdout.readline())
                work = int(name.split("/")[1])
                ratios[name].append(seconds[0] / seconds[1])  # new speed / old speed
                for side in (0, 1):
                    rates[name][side].append(work / seconds[side] / 1e6)
        for p in procs:
            p.stdin.close()
            p.wait()
    unit = "M rays/s" if args.kind == "bvh" else "M samples/s"
    medians = []
    for name in names:
        median = statistics.median(ratios[name])
        medians.append(median)
        old, new = (statistics.median(rates[name][side]) for side in (0, 1))
        print(f"{name.split('/')[0]:32s} old {old:6.2f} new {new:6.2f} {unit}  new/old "
              f"{median:.3f} (rounds {min(ratios[name]):.2f}-{max(ratios[name]):.2f})")  # fmt: skip
    print(f"geometric mean new/old {math.exp(sum(map(math.log, medians)) / len(medians)):.3f}")


if __name__ == "__main__":
    main()
