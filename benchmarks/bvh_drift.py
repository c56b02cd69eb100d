"""Whether the machine lets `bvh.md`'s one-thread ratios hold still: dpm's closest-hit rate,
Embree's and a scalar loop's, round after round in one process.

    python benchmarks/bvh_drift.py [--scene spheres_s1] [--rounds 12] [--load-at 3]

Each round times, in turn on one thread, `dpm.tracer.intersect` and embreex's `run` on the
same 300,000 incoherent rays (as `test_bvh.py` makes them) and a Numba loop of dependent
scalar arithmetic (no memory, no vectors), and prints the three rates and dpm / Embree.
With `--load-at K`, from round K on a busy Python loop runs in another process (the other
core's work on a 2-core machine); it is stopped halfway through the remaining rounds, so
the last rounds show whether the rates come back. On a machine whose speed holds still,
the ratio column does too; on the 2-core VM of 2026-11-26 it did not (docs/benchmarks.md,
"Ray tracing against Embree").
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time

import numba
import numpy as np
from test_bvh import incoherent_rays, load_triangles, seconds

from common import cpu
from dpm.tracer import build_bvh, intersect

RAYS = 300_000
LOOP = 20_000_000  # iterations of the scalar loop


@numba.njit(cache=True)
def scalar_loop(n: int) -> float:
    """n dependent multiply-adds (every third a subtraction): a rate set by the clock alone."""
    x = 1.0
    for i in range(n):
        x = x * 1.0000001 + 1e-9 if i % 3 else x - 1e-9
    return x


def main() -> None:
    """Time the three, round after round, and print a line per round."""
    from embreex import rtcore_scene
    from embreex.mesh_construction import TriangleMesh

    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--scene", default="spheres_s1")
    p.add_argument("--rounds", type=int, default=12)
    p.add_argument("--load-at", type=int, default=None, help="round that starts the other load")
    a = p.parse_args()
    numba.set_num_threads(1)
    tri = load_triangles(a.scene)
    bvh = build_bvh(tri)
    o, d = incoherent_rays(tri, RAYS)
    scene = rtcore_scene.EmbreeScene()
    TriangleMesh(scene, tri)
    scene.run(o[:1], d[:1])  # Embree builds on the first query
    intersect(bvh, o, d)
    scalar_loop(10)
    stop_at = None if a.load_at is None else a.load_at + (a.rounds - a.load_at) // 2
    print(f"{cpu()}; {a.scene}, {RAYS} incoherent rays, one thread; Mrays/s, loop Giter/s")
    load = None
    try:
        for r in range(a.rounds):
            if r == a.load_at:
                load = subprocess.Popen([sys.executable, "-c", "while True: pass"])
                time.sleep(0.3)
            if r == stop_at and load is not None:
                load.kill()
                load.wait()
                load = None
            ours = RAYS / np.median([seconds(lambda: intersect(bvh, o, d)) for _ in "abc"])
            theirs = RAYS / np.median([seconds(lambda: scene.run(o, d, output=1)) for _ in "abc"])
            loop = LOOP / seconds(lambda: scalar_loop(LOOP))
            busy = "other core busy" if load is not None else ""
            print(f"round {r:2d}: dpm {ours / 1e6:5.1f}  Embree {theirs / 1e6:5.1f}  "
                  f"dpm/Embree {ours / theirs:.2f}  loop {loop / 1e9:.3f}  {busy}",
                  flush=True)  # fmt: skip
    finally:
        if load is not None:
            load.kill()


if __name__ == "__main__":
    main()
