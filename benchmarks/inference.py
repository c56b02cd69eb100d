"""The network's speed against this machine's matmul peak, and the K-nearest gather beside it.

    python benchmarks/inference.py [--quick] [--scene NAME]

For DPM-50 and DPM-500 (the shipped weights) at 65,536 and 262,144 visible points of an
example scene (default the ring; its caustic photons of M emitted paths, seed 0):
- FLOPs per point counted from the architecture: two per multiply-add of every dense layer,
  as executed (the predictor's context half once per point) and as the Flax module is written
  (that half once per photon); activations, pooling and features are not counted;
- seconds of the gather (the cKDTree's K-nearest queries alone) and of the network stage:
  what `predict_points` takes beyond the gather (building the steps, reading the photons and
  checking their normals inside the jit, features, the network, Eq. 2; it runs while the
  next block of points is gathered), each the best of 5 tries after compilation (as many
  as each matmul of the peak gets), the rows trying in turn, round after round;
- achieved GFLOP/s (executed FLOPs over the network's seconds) and its fraction of the peak:
  the best fp32 matmul rate here in the same run (n×n by n×n: JAX with XLA's own dots and
  with its experimental YNNPACK dots, and NumPy's BLAS, whichever is fastest);
- the same for the network's four 32×32 dense layers alone (bias and ReLU; no gathers,
  features, pooling or output), feature-major, in steps of as many photon rows as the
  network's steps hold at most, BLOCKS_IN_FLIGHT calls at once, as `predict_points` runs
  the network: what XLA's dots reach on this architecture's shapes here.
Prints `fraction of peak: X` (the worst of the four) and writes
benchmarks/results/inference.md (or --out); `--quick` (CI) runs 4,096 points once and writes
nothing: a smoke test whose fraction (0.41-0.47 where the full run gives 0.64-0.72, Zen 4)
counts start-up costs, so it is labelled as such and is not the issue's figure.

The fused kernel is compiled for the vector width of Numba's target (`fused.LANES`: 16
floats with AVX-512, else 8), named in the table. To measure AVX2 code on an AVX-512 host, run
with NUMBA_CPU_NAME=haswell, NUMBA_CPU_FEATURES set to Haswell's features with -avx512f,
XLA_FLAGS=--xla_cpu_max_isa=AVX2 and OPENBLAS_CORETYPE=Haswell: the peak then is NumPy's
OpenBLAS with its AVX2 kernels alone (XLA's dots ignore the cap; see `peak_gflops`).
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import time
from collections.abc import Callable
from concurrent.futures import ThreadPoolExecutor
from functools import partial

import jax
import jax.numpy as jnp
import numpy as np

from common import RESULTS, SCENES, M, cpu, cpu_info, markdown_table
from dpm import load_scene
from dpm.density.gather import PhotonIndex
from dpm.nn.fused import LANES
from dpm.nn.infer import (
    ACTIVATIONS_PER_CHUNK,
    BLOCKS_IN_FLIGHT,
    make_query_predict,
    predict_points,
)
from dpm.nn.weights import load_weights, shipped_weights
from dpm.tracer import build_bvh, trace_photons, trace_visible_points

KS = (50, 500)
# code-generation targets (and the BLAS kernels of the AVX2 peak)
TARGET_VARIABLES = ("NUMBA_CPU_NAME", "NUMBA_CPU_FEATURES", "XLA_FLAGS", "OPENBLAS_CORETYPE")
POINTS = (65_536, 262_144)
# XLA's experimental YNNPACK dots: the peak is the better of these and XLA's own
YNN_DOTS = {"xla_cpu_experimental_ynn_fusion_type": "LIBRARY_FUSION_TYPE_DOT"}


def dense_layers(params: dict) -> list[tuple[str, int, int]]:
    """(name, inputs, outputs) of every dense layer of KernelNet's params, in order."""
    p = params["params"]
    layers = [(f"Extractor_0/{n}", p["Extractor_0"][n]) for n in ("Dense_0", "Dense_1", "Dense_2")]
    layers += [(n, p[n]) for n in ("Dense_0", "Dense_1", "Dense_2")]
    return [(name, *layer["kernel"].shape) for name, layer in layers]


def flops_per_point(params: dict, k: int) -> tuple[int, int]:
    """(executed, as written) FLOPs of one point's K photons: 2 per multiply-add."""
    layers = dense_layers(params)
    width = layers[2][2]  # the extractor's output: the predictor's per-photon input half
    written = 2 * k * sum(i * o for _, i, o in layers)
    name, i, o = layers[3]  # the predictor's first layer: [photon feature, context]
    context = 2 * (i - width) * o
    return written - k * context + context, written


def numpy_gflops(sizes: tuple[int, ...], rounds: int) -> float:
    """The best fp32 n×n matmul GFLOP/s of NumPy's BLAS here."""
    best = 0.0
    for n in sizes:
        a = np.random.default_rng(0).random((n, n), np.float32)
        best = max(best, 2 * n**3 / best_of(lambda a=a: a @ a, rounds) / 1e9)
    return best


def peak_gflops(sizes: tuple[int, ...], rounds: int) -> tuple[float, str]:
    """(GFLOP/s, source) of the best fp32 n×n matmul here: JAX with XLA's dots and with
    YNNPACK's (where this jaxlib knows the experimental option) and NumPy's BLAS. For AVX2
    code on an AVX-512 host, NumPy's alone, run with OPENBLAS_CORETYPE=Haswell: XLA's dots
    pick their kernels by the CPU, not by --xla_cpu_max_isa (on Zen 5, 479-485 GFLOP/s with
    the AVX2 cap and 474-497 without), so they would hold AVX2 code to AVX-512's peak."""
    # (the host's own flags, whatever Numba and XLA are told to compile for)
    if LANES == 8 and "avx512f" in cpu_info().get("flags", "").split():
        if os.environ.get("OPENBLAS_CORETYPE", "").lower() != "haswell":
            sys.exit("inference.py: AVX2 code on an AVX-512 host needs OPENBLAS_CORETYPE=Haswell "
                     "(the AVX2 peak is NumPy's BLAS with its AVX2 kernels)")  # fmt: skip
        return numpy_gflops(sizes, rounds), "NumPy's OpenBLAS, Haswell (AVX2) kernels"
    best, source = numpy_gflops(sizes, rounds), "NumPy's BLAS"
    for options in ({}, YNN_DOTS):
        for n in sizes:
            a = jnp.asarray(np.random.default_rng(0).random((n, n)), jnp.float32)
            mm = jax.jit(lambda a: a @ a, compiler_options=options)
            try:
                seconds = best_of(lambda mm=mm, a=a: jax.block_until_ready(mm(a)), rounds)
            except Exception:  # an unknown option or value: XLA's own dots only
                continue
            rate = 2 * n**3 / seconds / 1e9
            if rate > best:
                best, source = rate, "JAX" + (", YNNPACK dots" if options else "")
    return best, source


def layers_alone(params: dict, rows: int, rounds: int) -> float:
    """GFLOP/s of the 32×32 dense layers of KernelNet's params (extractor Dense_1, Dense_2;
    predictor Dense_0's photon half, Dense_1), each with bias and ReLU, chained over `rows`
    photon rows, feature-major, in steps of ACTIVATIONS_PER_CHUNK rows, BLOCKS_IN_FLIGHT
    calls at once on worker threads (as `predict_points` runs the network)."""
    p = params["params"]
    extractor, first = p["Extractor_0"], p["Dense_0"]
    width = extractor["Dense_1"]["kernel"].shape[0]
    own = {"kernel": first["kernel"][:width], "bias": first["bias"]}
    layers = [extractor["Dense_1"], extractor["Dense_2"], own, p["Dense_1"]]
    layers = [jax.tree.map(jnp.asarray, layer) for layer in layers]
    steps = max(1, rows // ACTIVATIONS_PER_CHUNK // BLOCKS_IN_FLIGHT)
    shape = (BLOCKS_IN_FLIGHT, steps, width, ACTIVATIONS_PER_CHUNK)
    x = np.random.default_rng(0).random(shape, np.float32)
    parts = [jnp.asarray(part) for part in x]  # one input per call, made before timing

    def chain(h: jnp.ndarray) -> jnp.ndarray:
        for layer in layers:
            h = jax.nn.relu(layer["kernel"].T @ h + layer["bias"][:, None])
        return h

    run = jax.jit(lambda x: jax.lax.map(chain, x))
    with ThreadPoolExecutor(BLOCKS_IN_FLIGHT) as pool:
        seconds = best_of(
            lambda: list(pool.map(lambda part: jax.block_until_ready(run(part)), parts)), rounds
        )
    return 2 * width * len(layers) * x.size / seconds / 1e9  # x.size / width photon rows


def seconds_of(fn: Callable[[], object]) -> float:
    """Wall seconds of one call of fn."""
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def best_of(fn: Callable[[], object], rounds: int) -> float:
    """Fewest wall seconds of fn over `rounds` runs after one warm-up."""
    fn()
    return min(seconds_of(fn) for _ in range(rounds))


def scene_points(name: str, n: int) -> tuple[np.ndarray, np.ndarray, np.ndarray, PhotonIndex]:
    """Positions, normals, albedos (n, 3) of n visible points of the scene (one per pixel of
    a square image, hits only, repeated if short) and the index of M paths' caustic photons."""
    scene = load_scene(SCENES / f"{name}.obj")
    bvh = build_bvh(scene)
    side = int(np.ceil(np.sqrt(n * 1.5)))
    camera = scene.camera.with_resolution(side, side)
    points = trace_visible_points(scene, bvh, camera, 1, 0, (0, side))
    hit = np.resize(np.flatnonzero(points.hit), n)
    photons = trace_photons(scene, bvh, M, seed=0, caustic_only=True)
    return points.position[hit], points.normal[hit], points.albedo[hit], PhotonIndex(photons)


def measure(name: str, points: tuple[int, ...], rounds: int) -> list[dict]:
    """One row per (K, points): FLOPs, network and gather seconds (each the fewest of `rounds`
    tries after a warm-up), GFLOP/s. Gather is the K-nearest queries alone, network what
    `predict_points` takes beyond them (it overlaps the two). The rows take their tries in
    turn, round after round, so that a slow spell of the machine cannot fall on every try of
    one row."""
    models = {}
    for k in KS:
        weights = load_weights(shipped_weights(k))
        params = jax.tree.map(jnp.asarray, weights.params)
        models[k] = make_query_predict(weights.model()), params, flops_per_point(params, k)
    runs = []  # (k, points, whole stage, gather alone)
    for n in points:
        position, normal, albedo, index = scene_points(name, n)
        for k in KS:
            predict, params, _ = models[k]
            whole = partial(predict_points, predict, params, index, position, normal, albedo, k)
            gather = partial(gather_only, index, position, normal, k)
            runs.append((k, n, whole, gather))
    best = np.full((len(runs), 2), np.inf)
    for round_ in range(rounds + 1):  # round 0 warms up (compiles) and is not counted
        for i, (_, _, whole, gather) in enumerate(runs):
            tried = seconds_of(whole), seconds_of(gather)
            if round_:
                best[i] = np.minimum(best[i], tried)
    rows = []
    for (k, n, _, _), (total, gather) in zip(runs, best, strict=True):
        executed, written = models[k][2]
        network = total - gather
        rows.append({"k": k, "points": n, "executed": executed, "written": written,
                     "network_s": network, "gather_s": gather,
                     "gflops": n * executed / network / 1e9})  # fmt: skip
    return rows


def gather_only(index: PhotonIndex, position: np.ndarray, normal: np.ndarray, k: int) -> None:
    """The K-nearest queries of points (n, 3) with normals (n, 3) alone, results dropped."""
    for _ in index.nearest(position, normal, k, agree=False):
        pass


def report(rows: list[dict], peak: float, source: str, alone: float, name: str) -> list[str]:
    """The markdown lines of the results (peak: GFLOP/s of `source`'s best matmul; alone:
    GFLOP/s of the dense layers alone)."""
    head = ["model", "points", "FLOPs/point executed", "as written", "network s", "gather s",
            "GFLOP/s", "fraction of peak"]  # fmt: skip
    body = [[f"DPM-{r['k']}", f"{r['points']:,}", f"{r['executed']:,}", f"{r['written']:,}",
             f"{r['network_s']:.3f}", f"{r['gather_s']:.3f}", f"{r['gflops']:.1f}",
             f"{r['gflops'] / peak:.2f}"] for r in rows]  # fmt: skip
    return [
        f"Scene: {name}, caustic photons of M = {M:,} emitted paths (seed 0). "
        f"Peak: {peak:.0f} GFLOP/s (best fp32 matmul, {source}, same run).",
        "",
        *markdown_table(head, body),
        "",
        f"The network's four 32×32 dense layers alone with XLA's dots (bias, ReLU; no gathers, "
        f"features or pooling), feature-major, {ACTIVATIONS_PER_CHUNK:,} photon rows a step, "
        f"{BLOCKS_IN_FLIGHT} calls at once: {alone:.1f} GFLOP/s, "
        f"{alone / peak:.2f} of peak.",
        "",
        f"Machine: {cpu()}; JAX {jax.__version__}; fused kernel compiled for {LANES}-float "
        f"vectors ({'AVX-512' if LANES == 16 else 'AVX2'}); "
        f"NUMBA_CPU_NAME={os.environ.get('NUMBA_CPU_NAME', 'host')}, "
        f"XLA_FLAGS={os.environ.get('XLA_FLAGS', '')!r}; {datetime.date.today().isoformat()}",
    ]


def main() -> None:
    """Measure, print the table and `fraction of peak: X`, write inference.md (not --quick)."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--quick", action="store_true", help="4,096 points, one run, no file")
    parser.add_argument("--scene", default="ring", help="example scene (default: ring)")
    parser.add_argument("--out", default="inference.md", help="file under benchmarks/results")
    args = parser.parse_args()
    # as many tries for the network as for the peak: best-of-N favours the one with more
    points, rounds, sizes = ((4096,), 1, (512,)) if args.quick else (POINTS, 5, (1024, 2048))
    peak, source = peak_gflops(sizes, max(rounds, 3))
    rows = measure(args.scene, points, rounds)
    params = load_weights(shipped_weights(KS[0])).params
    alone = layers_alone(params, points[0] * KS[0], max(rounds, 3))
    lines = report(rows, peak, source, alone, args.scene)
    print("\n".join(lines))
    fraction = min(r["gflops"] for r in rows) / peak
    if args.quick:  # one small run: start-up costs weigh in, so not the figure
        print(f"fraction of peak (--quick: a smoke test, not the measure): {fraction:.2f}")
    else:
        print(f"fraction of peak: {fraction:.2f}")
    if not args.quick:
        settings = [f"{k}={os.environ[k]}" for k in TARGET_VARIABLES if k in os.environ]
        command = " ".join([*settings, "python", "benchmarks/inference.py", *sys.argv[1:]])
        text = [
            "# Network inference against the matmul peak",
            "",
            f"Made by `{command}` (see its docstring for what is counted).",
            "",
            *lines,
        ]
        (RESULTS / args.out).write_text("\n".join(text) + "\n")


if __name__ == "__main__":
    main()
