"""The BVH build's SAH constants against alternatives: 1-thread closest-hit rays/s and pt samples/s.

    python benchmarks/bvh_sah.py [SCENE ...]

Per example scene (default: all, the cornell box included), builds the BVH with the shipped
SAH constants (`bvh.TRAVERSAL_COST`, leaves costed per triangle) and with the VARIANTS below,
checks that every build returns the same closest hits, then times them in turn, round after
round on one Numba thread (medians of ROUNDS): 200,000 incoherent rays (`test_bvh`'s kind), the
camera's 384² primary rays, and `pt` at 96² × 16 samples per pixel. A variant's speed is the
shipped build's seconds over its own (above 1: faster). Leaves "costed per block of 4" follow
Embree's model for its 4-triangle leaves: a leaf of up to 4 triangles is one SIMD test, as it
is here (`traverse.LEAF_LANES`), so it costs one unit whatever its count; with it every node
of at most 4 triangles becomes a leaf whatever the traversal cost, so the three block variants
build one tree and their spread is the timing noise. Chosen on the examples only; writes
benchmarks/results/bvh_sah.md.
"""

from __future__ import annotations

import argparse
import datetime

import numba
import numpy as np
from test_bvh import EXAMPLES, PATHS, camera_rays, incoherent_rays, load_triangles, seconds

from common import RESULTS, cpu, geomean, markdown_table
from dpm import load_scene
from dpm.tracer import BVH, intersect, trace_pixels
from dpm.tracer import bvh as B

SHIPPED = (B.TRAVERSAL_COST, B.LEAF_COST_LANES)
# (traversal cost, leaf-cost lanes); the block-of-4 ones are one tree (see above)
VARIANTS = [SHIPPED, (1.0, 1), (3.0, 1), (2.0, 4), (1.0, 4), (0.5, 4)]
ROUNDS = 5
TABLE = RESULTS / "bvh_sah.md"


def build(tri: np.ndarray, cost: float, lanes: int) -> tuple[BVH, int, int]:
    """A BVH over triangles (T, 3, 3) with SAH traversal cost `cost` and leaves costed per
    block of `lanes` triangles, its 8-wide node count and its leaf count."""
    bvh = B.build_bvh_from_triangles(tri, traversal_cost=cost, leaf_cost_lanes=lanes)
    refs = bvh.arrays.kids[:, B.REFS : B.REFS + B.WIDTH]
    return bvh, bvh.n_nodes, int(((refs < 0) & (refs != B.EMPTY)).sum())


def leaf_cost(variant: tuple[float, int]) -> str:
    """How a variant costs a leaf: per triangle or per block of lanes."""
    return "triangle" if variant[1] == 1 else f"block of {variant[1]}"


def scene_rows(name: str) -> list[list[str]]:
    """One table row per variant on scene `name`, in VARIANTS' order."""
    tri = load_triangles(name)
    scene = load_scene(PATHS[name])
    camera = scene.camera.with_resolution(96, 96)
    rays = {"incoherent": incoherent_rays(tri, 200_000), "camera": camera_rays(name, tri, 384)}
    built = {v: build(tri, *v) for v in VARIANTS}
    reference = intersect(built[SHIPPED][0], *rays["incoherent"])
    for bvh, _, _ in built.values():  # every build finds the same hits (and compiles first)
        t, hit = intersect(bvh, *rays["incoherent"])  # at ties, which triangle may differ
        assert np.array_equal(t, reference[0]) and np.array_equal(hit < 0, reference[1] < 0)
        trace_pixels(scene, bvh, camera, 1, 0, (0, 2))
    runs = {v: {"incoherent": [], "camera": [], "pt": []} for v in VARIANTS}
    for r in range(ROUNDS):
        for v in VARIANTS if r % 2 == 0 else VARIANTS[::-1]:
            bvh = built[v][0]
            for kind, (o, d) in rays.items():
                runs[v][kind].append(seconds(lambda: intersect(bvh, o, d)))  # noqa: B023
            runs[v]["pt"].append(seconds(lambda: trace_pixels(scene, bvh, camera, 16, 1, (0, 96))))  # noqa: B023
    base = {k: float(np.median(x)) for k, x in runs[SHIPPED].items()}
    rows = []
    for v in VARIANTS:
        speed = [base[k] / float(np.median(runs[v][k])) for k in ("incoherent", "camera", "pt")]
        rows.append([name, f"{v[0]:g}", leaf_cost(v), str(built[v][1]), str(built[v][2]),
                     *(f"{s:.3f}" for s in speed)])  # fmt: skip
        print(" | ".join(rows[-1]), flush=True)
    return rows


def main() -> None:
    """Time every variant on the scenes named (default: every example), write the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=[p.stem for p in EXAMPLES])
    a = p.parse_args()
    numba.set_num_threads(1)
    per_scene = [scene_rows(name) for name in a.scenes]
    rows = [row for scene in per_scene for row in scene]
    head = ["scene", "traversal cost", "leaf cost per", "8-wide nodes", "leaves",
            "incoherent speed", "camera speed", "pt speed"]  # fmt: skip
    means = []
    for i, v in enumerate(VARIANTS):
        mine = [scene[i] for scene in per_scene]
        gm = [geomean([float(r[i]) for r in mine]) for i in (5, 6, 7)]
        means.append(f"- traversal cost {v[0]:g}, leaves per {leaf_cost(v)}: geometric mean "
                     f"speed incoherent {gm[0]:.3f}, camera {gm[1]:.3f}, "
                     f"pt {gm[2]:.3f}")  # fmt: skip
    TABLE.write_text("\n".join([
        "# The BVH's SAH constants against alternatives (1 thread)",
        "",
        "Made by `python benchmarks/bvh_sah.py` (see its docstring): speed = the shipped "
        f"build's seconds / the variant's, medians of {ROUNDS} alternating rounds on one Numba "
        "thread.",
        f"Machine: {cpu()}; {datetime.date.today()}.",
        "",
        *markdown_table(head, rows),
        "",
        *means,
    ]) + "\n")  # fmt: skip
    print(TABLE.read_text())


if __name__ == "__main__":
    main()
