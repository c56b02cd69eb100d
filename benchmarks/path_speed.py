"""Path tracing speed: dpm `pt` against Mitsuba 3 `path` (llvm_ad_rgb), in samples per second.

    python benchmarks/path_speed.py [SCENE ...] [--set examples|unseen] [--width W] [--spp S]
                                    [--rounds R] [--quick]

Both render the same example scene (Mitsuba's through the project's converter) at the same
resolution and samples per pixel, with unbounded depth and Russian roulette from the same
path vertex: dpm rolls from the fourth diffuse vertex after the camera (RR_START = 3 after
the visible point), so Mitsuba gets rr_depth = RR_START + 1; Mitsuba also rolls at specular
vertices, dpm only from its RR_SPECULAR-th on. Each renderer first renders once untimed
(Numba and LLVM compilation), then the two alternate for --rounds timed renders; the best
round counts (the machine is shared; the fastest round is the least disturbed). dpm's time is
its whole `render` less the BVH build (Mitsuba builds its BVH when loading the scene, also
untimed); Mitsuba's is `mi.render` up to an evaluated image in NumPy. Image means are compared
as a sanity check (the transport is validated against Mitsuba by tests/test_mitsuba.py).

Mitsuba's LLVM backend needs libLLVM >= 15; LLVM 15 fails to compile Mitsuba's kernels
("Cannot select: fminimum", on AVX-512 machines and on an AVX2-only Zen 3 alike), so install
a newer one (Debian: libllvm19): the newest libLLVM found is handed to Dr.Jit
(`unseen_references.llvm_library`; DRJIT_LIBLLVM_PATH, if set, wins).
`--set unseen` measures the unseen-scene set (`scenes/make_unseen.py`, built when missing)
instead of the examples; its geometric mean is printed below the table.
Writes benchmarks/results/path_speed.md (path_speed_unseen.md for the unseen set, or --out)
and prints it.
"""

from __future__ import annotations

import argparse
import datetime
import os
import sys
import tempfile
from collections.abc import Callable
from pathlib import Path

import numba
import numpy as np

from common import RESULTS, SCENES, cpu, geomean, markdown_table, timed
from dpm import load_scene
from dpm.camera import Camera
from dpm.renderer import RenderOptions, render
from dpm.scene import Scene
from dpm.tracer.path import RR_START
from dpm.validation.mitsuba import mitsuba_scene

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import unseen_scenes  # noqa: E402
from unseen_references import llvm_library  # noqa: E402

VARIANT = "llvm_ad_rgb"


def dpm_renderer(scene: Scene, camera: Camera, spp: int) -> Callable[[int], tuple]:
    """seed -> (image, seconds) of dpm `pt`, the BVH build left out."""
    size = {"width": camera.width, "height": camera.height, "progress": False}

    def run(seed: int) -> tuple[np.ndarray, float]:
        opts = RenderOptions(method="pt", spp=spp, seed=seed, **size)
        result, (seconds,) = timed(lambda: render(scene, opts))
        return result.image, seconds - result.stats["seconds"]["bvh"]

    return run


def mitsuba_renderer(scene: Scene, camera: Camera, spp: int) -> Callable[[int], tuple]:
    """seed -> (image, seconds) of Mitsuba 3 `path` on VARIANT, evaluation forced."""
    library = llvm_library()
    if library:  # read when Dr.Jit starts its LLVM backend
        os.environ["DRJIT_LIBLLVM_PATH"] = library
    import drjit as dr
    import mitsuba as mi

    with tempfile.TemporaryDirectory() as folder:
        desc = mitsuba_scene(scene, camera, spp, Path(folder))  # sets the scalar variant
        mi.set_variant(VARIANT)
        desc["integrator"]["rr_depth"] = RR_START + 1
        loaded = mi.load_dict(desc)

    def once(seed: int) -> np.ndarray:
        image = mi.render(loaded, spp=spp, seed=seed)
        dr.eval(image)
        dr.sync_thread()
        return np.array(image, dtype=np.float32)

    def run(seed: int) -> tuple[np.ndarray, float]:
        image, (seconds,) = timed(lambda: once(seed))
        return image, seconds

    return run


def measure(path: Path, width: int, spp: int, rounds: int) -> dict:
    """Best seconds of each renderer on one scene (an OBJ), alternating, and image means."""
    name = path.stem
    scene = load_scene(path)
    camera = scene.camera.with_resolution(width, width * scene.camera.height // scene.camera.width)
    runs = {
        "dpm": dpm_renderer(scene, camera, spp),
        "mitsuba": mitsuba_renderer(scene, camera, spp),
    }
    for run in runs.values():
        run(0)  # warm-up: compilation
    best = dict.fromkeys(runs, float("inf"))
    means: dict[str, list[float]] = {k: [] for k in runs}
    for r in range(rounds):
        for key, run in runs.items():
            image, seconds = run(r + 1)
            best[key] = min(best[key], seconds)
            means[key].append(float(image.mean()))
    samples = camera.width * camera.height * spp
    rate = {k: samples / s for k, s in best.items()}
    return {
        "scene": name, "size": f"{camera.width}x{camera.height}", "spp": spp,
        "dpm": rate["dpm"], "mitsuba": rate["mitsuba"], "ratio": rate["dpm"] / rate["mitsuba"],
        "mean_ratio": float(np.mean(means["dpm"]) / np.mean(means["mitsuba"])),
    }  # fmt: skip


def report(records: list[dict], rounds: int, command: str) -> str:
    """The Markdown report."""
    import drjit as dr

    rows = [
        [r["scene"], r["size"], str(r["spp"]), f"{r['dpm'] / 1e6:.2f}", f"{r['mitsuba'] / 1e6:.2f}",
         f"{r['ratio']:.2f}x", f"{r['mean_ratio']:.3f}"]
        for r in records
    ]  # fmt: skip
    head = ["scene", "pixels", "spp", "dpm M samples/s", "Mitsuba M samples/s", "dpm / Mitsuba",
            "mean dpm / Mitsuba"]  # fmt: skip
    lines = [
        "# Path tracing speed: dpm `pt` vs Mitsuba 3 `path`",
        "",
        f"Made by `{command}` (see its docstring): best of {rounds}"
        " alternating renders each, compilation and BVH builds excluded.",
        f"Machine: {cpu()}; numba threads"
        f" {numba.get_num_threads()}, Dr.Jit threads {dr.thread_count()} (Mitsuba {VARIANT},"
        f" LLVM {'.'.join(map(str, dr.detail.llvm_version()))}); {datetime.date.today()}.",
        "",
        *markdown_table(head, rows),
        "",
        f"Geometric mean of dpm / Mitsuba: "
        f"{geomean([r['ratio'] for r in records]):.2f}x "
        f"({len(records)} scenes).",
    ]
    return "\n".join(lines) + "\n"


def main() -> None:
    """Measure the scenes named (default: every example) and write the report."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", help="scene names (default: the whole set)")
    p.add_argument("--set", choices=("examples", "unseen"), default="examples")
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--spp", type=int, default=64)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--quick", action="store_true", help="64 pixels wide, 16 spp, 1 round")
    p.add_argument("--out", type=Path, help="default: results/path_speed[_unseen].md")
    args = p.parse_args()
    if args.set == "unseen":
        paths = {q.stem: q for q in unseen_scenes()}
    else:
        paths = {q.stem: q for q in sorted(SCENES.glob("*.obj"))}
    unknown = [n for n in args.scenes if n not in paths]
    if unknown:
        p.error(f"not in the {args.set} set: {', '.join(unknown)}")
    out = args.out or RESULTS / (
        "path_speed.md" if args.set == "examples" else "path_speed_unseen.md"
    )
    if args.quick:
        args.width, args.spp, args.rounds = 64, 16, 1
    records = []
    for name in args.scenes or list(paths):
        records.append(measure(paths[name], args.width, args.spp, args.rounds))
        print(name, {k: v for k, v in records[-1].items() if k != "scene"}, flush=True)
    text = report(
        records, args.rounds, " ".join(["python", "benchmarks/path_speed.py", *sys.argv[1:]])
    )
    out.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
