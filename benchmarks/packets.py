"""Packet traversal against one ray at a time, on the rays a path tracer traces for a pixel.

    python benchmarks/packets.py [SCENE ...] [--threads N] [--rounds R] [--out FILE]

For each example scene (or those named), at 128 × 128 pixels and 16 samples a pixel (a
packet's worth, consecutive), three kinds of rays: camera rays (jittered in their pixel),
bounce rays (from each camera ray's first hit, cosine-distributed about its normal) and
shadow rays (from those hits to uniform points on the lights, up to just short of them). Each
kind is traced by `closest_hit_batch` / `any_hit_batch` (one ray at a time) and by
`closest_hit_packets` / `any_hit_packets` (packets of `LANES` consecutive rays), in turn,
--rounds times each; best rays/s per side. Hits are checked equal (every ray: the same
triangle at the same t, the same occlusion) before timing. One thread by default (--threads).
Writes benchmarks/results/packets.md and prints it.
"""

from __future__ import annotations

import argparse
import datetime
import time
from pathlib import Path

import numba
import numpy as np

from common import RESULTS, SCENES, cpu, geomean, markdown_table
from dpm import load_scene
from dpm.tracer import build_bvh
from dpm.tracer.packet import LANES, any_hit_packets, closest_hit_packets
from dpm.tracer.traverse import any_hit_batch, closest_hit_batch, spawn_offset
from dpm.tracer.visible import camera_ray

SIDE = 128  # pixels a side


@numba.njit(cache=True)
def _camera_rays(basis, side, xs, ys, out):
    """out[i] = the unit direction of the camera ray through image point (xs[i], ys[i])."""
    for i in range(len(xs)):
        out[i, 0], out[i, 1], out[i, 2] = camera_ray(basis, side, side, xs[i], ys[i])


def ray_sets(scene, bvh, rng) -> dict[str, tuple[np.ndarray, np.ndarray, np.ndarray]]:
    """Camera, bounce and shadow rays: (origins (R, 3), directions (R, 3), tmax (R,))."""
    camera = scene.camera.with_resolution(SIDE, SIDE)
    basis = camera.basis()
    n = SIDE * SIDE * LANES
    ys, xs = np.divmod(np.repeat(np.arange(SIDE * SIDE), LANES), SIDE)
    d = np.empty((n, 3))
    _camera_rays(basis, SIDE, xs + rng.random(n), ys + rng.random(n), d)
    o = np.repeat(basis[:1, :3].astype(np.float64), n, axis=0)
    t, tri = np.empty(n), np.empty(n, np.int32)
    closest_hit_batch(bvh.arrays, bvh.depth, o, d, np.array([np.inf]), t, tri)
    hit = tri >= 0
    normal = scene.normals[np.maximum(tri, 0)].astype(np.float64)
    normal[np.sum(normal * d, axis=1) > 0] *= -1  # towards the camera
    start = np.where(hit[:, None], o + np.where(hit, t, 0)[:, None] * d, o)
    start += np.where(hit[:, None], normal * spawn_offset(scene), 0.0)
    u = rng.normal(size=(n, 3))
    u /= np.linalg.norm(u, axis=1, keepdims=True)
    bounce = np.where(np.sum(u * normal, axis=1, keepdims=True) < 0, -u, u) + normal
    bounce /= np.linalg.norm(bounce, axis=1, keepdims=True)
    bounce = np.where(hit[:, None], bounce, d)
    lights = scene.kernel_arrays().emitter_triangles
    corners = scene.triangles[lights[rng.integers(0, len(lights), n)]].astype(np.float64)
    a, b = rng.random(n), rng.random(n)
    flip = a + b > 1
    a[flip], b[flip] = 1 - a[flip], 1 - b[flip]
    target = corners[:, 0] + a[:, None] * (corners[:, 1] - corners[:, 0])
    target += b[:, None] * (corners[:, 2] - corners[:, 0])
    shadow = target - start
    length = np.linalg.norm(shadow, axis=1)
    shadow /= np.maximum(length, 1e-30)[:, None]
    inf = np.full(n, np.inf)
    return {
        "camera": (o, d, inf),
        "bounce": (start, bounce, inf),
        "shadow": (start, shadow, length * (1 - 1e-4)),
    }


def best_rate(fn, args, n: int, rounds: int) -> float:
    """Rays per second of the fastest of `rounds` calls."""
    seconds = []
    for _ in range(rounds):
        t0 = time.perf_counter()
        fn(*args)
        seconds.append(time.perf_counter() - t0)
    return n / min(seconds)


def measure(path: Path, rounds: int) -> list[dict]:
    """One row per ray kind: single and packet rays/s, hits checked equal."""
    scene = load_scene(path)
    bvh = build_bvh(scene)
    rows = []
    for kind, (o, d, tmax) in ray_sets(scene, bvh, np.random.default_rng(0)).items():
        n = len(o)
        closest = kind != "shadow"
        if closest:
            outs = [(np.empty(n), np.empty(n, np.int32)) for _ in range(2)]
            single = (closest_hit_batch, (bvh.arrays, bvh.depth, o, d, tmax, *outs[0]))
            packed = (closest_hit_packets, (bvh.arrays, bvh.depth, o, d, tmax, *outs[1]))
        else:
            outs = [(np.empty(n, np.bool_),) for _ in range(2)]
            single = (any_hit_batch, (bvh.arrays, bvh.depth, o, d, tmax, *outs[0]))
            packed = (any_hit_packets, (bvh.arrays, bvh.depth, o, d, tmax, *outs[1]))
        for fn, args in (single, packed):
            fn(*args)  # compile, and the results to compare
        for a, b in zip(*outs, strict=True):
            if not np.array_equal(a, b):
                raise SystemExit(f"packets: {path.stem} {kind} rays differ from single rays")
        rates = {"single": 0.0, "packet": 0.0}
        for _ in range(rounds):  # alternating, best of each
            rates["single"] = max(rates["single"], best_rate(*single, n, 1))
            rates["packet"] = max(rates["packet"], best_rate(*packed, n, 1))
        rows.append({"scene": path.stem, "rays": kind, "n": n, **rates})
    return rows


def main() -> None:
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--threads", type=int, default=1)
    p.add_argument("--rounds", type=int, default=5)
    p.add_argument("--out", default=str(RESULTS / "packets.md"))
    a = p.parse_args()
    numba.set_num_threads(a.threads)
    names = a.scenes or sorted(p.stem for p in SCENES.glob("*.obj"))
    records = [r for name in names for r in measure(SCENES / f"{name}.obj", a.rounds)]
    head = ["scene", "rays", "rays traced", "single Mrays/s", "packet Mrays/s", "packet / single"]
    table = [
        [r["scene"], r["rays"], str(r["n"]), f"{r['single'] / 1e6:.2f}",
         f"{r['packet'] / 1e6:.2f}", f"{r['packet'] / r['single']:.2f}x"]
        for r in records
    ]  # fmt: skip
    means = {
        kind: geomean([r["packet"] / r["single"] for r in records if r["rays"] == kind])
        for kind in ("camera", "bounce", "shadow")
    }
    command = "python benchmarks/packets.py" + (f" {' '.join(a.scenes)}" if a.scenes else "")
    lines = [
        "# Packet traversal against one ray at a time",
        "",
        f"Made by `{command}` (see its docstring): {SIDE}² pixels × {LANES} rays a pixel, "
        f"consecutive; best of {a.rounds} alternating rounds; hits checked equal.",
        f"Machine: {cpu()}; numba threads {a.threads}; {datetime.date.today()}.",
        "",
        *markdown_table(head, table),
        "",
        "Geometric means of packet / single: "
        + ", ".join(f"{k} {v:.2f}x" for k, v in means.items())
        + ".",
    ]
    text = "\n".join(lines) + "\n"
    Path(a.out).write_text(text)
    print(text)


if __name__ == "__main__":
    main()
