"""Equal-time comparison (paper §5): the hybrid, dpm `pt` + OIDN and Mitsuba 3 `path` + OIDN,
scored against a long reference, on the glass egg and the ring.

    python benchmarks/hybrid.py [SCENE ...] [--width W (128)] [--k K] [--weights FILE]

The hybrid renders first with its defaults (`dpm-render --method hybrid`); its wall time
(after a warm-up render that compiles everything) is the budget the other two get: each is
timed at a few samples per pixel and then given the sample count that fills the budget. All
three are denoised by the same OIDN call with their own albedo and normal images.

Reference: dpm `pt-nocaustic` at REF_SPP paths per pixel, then REF_ROUNDS rounds that each
add as many again where they lower the error most (`dpm.methods.adaptive`: the few pixels
that see a small light through glass or water need hundreds of times more), plus the PPM
caustic reference (guided emission, two halves) at the visible points of REF_CAUSTIC_SPP
samples per pixel, averaged per pixel. It is checked against Mitsuba 3 at MITSUBA_CHECK_SPP
(RMSE and mean ratio in the report). The reference image is cached per scene and size in
benchmarks/results/equal_time/SCENE-WxH-reference.exr (`benchmarks/equal_time.py` scores
against the same references), its expected RMSE beside it in a JSON file.

Writes benchmarks/results/hybrid.md and benchmarks/results/hybrid/SCENE.png (the three images
and the reference side by side). The report also times the README's default render
(`dpm-render examples/scenes/glass_egg.obj --method hybrid`: the scene's own settings), warm.
"""

from __future__ import annotations

import argparse
import datetime
import json
import tempfile
from pathlib import Path

import imageio.v3 as iio
import numpy as np

from common import RESULTS, SCENES, cpu, linear_fit, secant_spp, timed
from dpm import load_scene
from dpm.camera import Camera
from dpm.denoise import denoise
from dpm.density.base import luminance
from dpm.density.progressive import pass_seed
from dpm.estimators.reference import ppm_reference
from dpm.io import linear_to_srgb8, read_exr, write_image, write_json
from dpm.methods.adaptive import Halves
from dpm.metrics import rmse
from dpm.renderer import RenderOptions, render
from dpm.scene import Scene
from dpm.tracer import build_bvh, trace_listed, trace_visible_points
from dpm.validation.mitsuba import load_mitsuba, mitsuba_scene

OUT = RESULTS / "hybrid"
REFERENCES = RESULTS / "equal_time"  # converged references, per scene and size (shared)
REF_SPP = 4096  # pt-nocaustic samples per pixel of the reference
REF_ROUNDS = 3  # adaptive rounds after it, each of REF_SPP paths per pixel on average
# Visible points per pixel of the caustic reference: a sharp caustic varies within a pixel,
# and at 4 the red wine's reference was 0.03 RMSE off its own mean over the pixels.
REF_CAUSTIC_SPP = 64
REF_CAUSTIC_PATHS = 50_000_000  # guided photon paths of the caustic reference
MITSUBA_CHECK_SPP = 4096
CALIBRATION_SPP = 4


def caustic_reference(scene: Scene, camera: Camera, folder: Path) -> tuple[np.ndarray, float]:
    """(H, W, 3) caustic radiance the camera sees, per pixel, and its expected RMSE
    (luminance; the halves' checkpoints in `folder`)."""
    bvh = build_bvh(scene)
    points = trace_visible_points(scene, bvh, camera, REF_CAUSTIC_SPP, 1001, (0, camera.height))
    lo, hi = scene.bounds
    radius = 5e-4 * float(np.linalg.norm(np.subtract(hi, lo, dtype=np.float64)))
    ref = ppm_reference(
        scene, bvh, points, REF_CAUSTIC_PATHS, radius, 1_000_000, seed=7,
        checkpoint_dir=folder, progress=True,
    )  # fmt: skip
    shape = (camera.height * camera.width, REF_CAUSTIC_SPP, 3)
    seen = (points.throughput * ref.radiance).reshape(shape).astype(np.float64)
    halves = [luminance((points.throughput * h).reshape(shape).mean(axis=1)) for h in ref.halves]
    # Expected squared error of a pixel's mean: the photons' (half the halves' squared
    # difference, over 2 for the mean of two) plus the pixel sampling's (the variance of its
    # points over their number; it holds photon noise too, so the sum is an upper bound).
    photons = (halves[0] - halves[1]) ** 2 / 4
    sampling = luminance(seen).var(axis=1, ddof=1) / REF_CAUSTIC_SPP
    image = seen.mean(axis=1).reshape(camera.height, camera.width, 3)
    return image.astype(np.float32), float(np.sqrt(np.mean(photons + sampling)))


def nocaustic_reference(scene: Scene, camera: Camera) -> tuple[np.ndarray, float]:
    """(H, W, 3) `pt-nocaustic` radiance per pixel, converged adaptively (two cross-fitted
    halves, `dpm.methods.adaptive`), and its expected RMSE (luminance)."""
    bvh = build_bvh(scene)
    n = camera.width * camera.height
    paths = Halves(camera.height, camera.width)
    every = np.arange(n)
    for half in range(2):
        sums, squares, _ = trace_listed(
            scene, bvh, camera, every, np.full(n, REF_SPP // 2), pass_seed(1000, 0, half + 1)
        )
        paths.base[half].add(every, REF_SPP // 2, sums, squares)
    print(f"path reference: {REF_SPP} paths per pixel, noise {paths.noise():.4f}", flush=True)
    for r in range(1, 1 + REF_ROUNDS):
        for half in range(2):
            pixels, counts = paths.plan_extra(half, REF_SPP * n // 2, 64 * REF_SPP)
            seed = pass_seed(1000, r, half + 1)
            sums, squares, _ = trace_listed(scene, bvh, camera, pixels, counts, seed)
            paths.extra[half].add(pixels, counts, sums, squares)
        print(f"path reference round {r}: noise {paths.noise():.4f}", flush=True)
    return paths.mean().astype(np.float32).reshape(camera.height, camera.width, 3), paths.noise()


def reference_path(name: str, camera: Camera) -> Path:
    """Where the reference of scene `name` at the camera's size is cached (an EXR)."""
    return REFERENCES / f"{name}-{camera.width}x{camera.height}-reference.exr"


def reference_noise(name: str, camera: Camera) -> dict | None:
    """The cached reference's expected RMSE ({"path_noise", "caustic_noise"}, luminance), or
    None where its JSON file is missing."""
    sidecar = reference_path(name, camera).with_suffix(".json")
    return json.loads(sidecar.read_text()) if sidecar.exists() else None


def reference(scene: Scene, camera: Camera, name: str) -> np.ndarray:
    """The long reference image (H, W, 3), cached as an EXR at `reference_path`, with its
    expected RMSE (path and caustic parts, luminance) in a JSON file beside it."""
    path = reference_path(name, camera)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.exists():
        return read_exr(path)
    nocaustic, path_noise = nocaustic_reference(scene, camera)
    caustic, noise = caustic_reference(scene, camera, path.with_name(f"{path.stem}-caustic"))
    print(name, f"reference noise: paths {path_noise:.5f}, caustics {noise:.5f}", flush=True)
    image = nocaustic + caustic
    write_image(path, image)
    write_json(path.with_suffix(".json"), {"path_noise": path_noise, "caustic_noise": noise})
    return image


def mitsuba(scene: Scene, camera: Camera, spp: int, seed: int) -> tuple[np.ndarray, ...]:
    """Mitsuba 3 `path` with albedo and shading-normal AOVs: three (H, W, 3) images."""
    mi = load_mitsuba()
    with tempfile.TemporaryDirectory() as folder:
        desc = mitsuba_scene(scene, camera, spp, Path(folder))
        desc["integrator"] = {
            "type": "aov", "aovs": "albedo:albedo,nn:sh_normal",
            "integrator": {"type": "path", "max_depth": -1},
        }  # fmt: skip
        loaded = mi.load_dict(desc)
    out = np.array(mi.render(loaded, spp=spp, seed=seed), dtype=np.float32)
    return out[..., :3], np.clip(out[..., 3:6], 0, 1), out[..., 6:9]


def equal_time_spp(fn, budget: float) -> int:
    """Samples per pixel that make fn(spp) take about `budget` seconds.

    After a warm-up, the time is fitted as fixed + per-sample cost from two sample counts;
    where that fit misses the budget by more than 5 % at its own answer (small counts time
    poorly), it takes one secant step through that run and the fit's fixed cost (`secant_spp`).
    """
    fn(1)
    counts = (CALIBRATION_SPP, 4 * CALIBRATION_SPP)
    fixed, per_spp = linear_fit(*((n, timed(lambda n=n: fn(n))[1][0]) for n in counts))
    spp = max(1, int((budget - fixed) / per_spp))
    seconds = timed(lambda: fn(spp))[1][0]
    if abs(seconds / budget - 1) <= 0.05 or spp <= CALIBRATION_SPP:
        return spp
    return secant_spp(spp, seconds, fixed, budget)


def run_scene(name: str, width: int, k: int, weights: Path | None) -> dict:
    """Render one scene the three ways at equal time; returns errors, times and images."""
    scene = load_scene(SCENES / f"{name}.obj")
    height = width * scene.camera.height // scene.camera.width
    camera = scene.camera.with_resolution(width, height)
    size = {"width": width, "height": height, "progress": False}
    ref = reference(scene, camera, name)

    hybrid = RenderOptions(method="hybrid", k=k, weights=weights, **size)
    render(scene, hybrid)  # warm-up at the same size: JAX compiles per block shape
    result, (budget,) = timed(lambda: render(scene, hybrid))
    rows = {"hybrid": (result.image, budget, hybrid.spp)}

    def pt(spp: int) -> np.ndarray:
        return render(scene, RenderOptions(method="pt", spp=spp, denoise=True, **size)).image

    spp = equal_time_spp(pt, budget)
    image, (seconds,) = timed(lambda: pt(spp))
    rows["dpm pt + OIDN"] = (image, seconds, spp)

    def mi(spp: int) -> np.ndarray:
        return denoise(*mitsuba(scene, camera, spp, seed=0))

    spp = equal_time_spp(mi, budget)
    image, (seconds,) = timed(lambda: mi(spp))
    rows["Mitsuba 3 path + OIDN"] = (image, seconds, spp)

    check = mitsuba(scene, camera, MITSUBA_CHECK_SPP, seed=1)[0]
    return {
        "scene": name, "reference": ref, "noise": reference_noise(name, camera), "rows": rows,
        "mitsuba_check": (rmse(check, ref), float(check.mean() / ref.mean())),
    }  # fmt: skip


def default_render_seconds() -> tuple[float, dict]:
    """Wall seconds of the hybrid on the glass egg with the scene's own settings (the
    default render until `auto`), after a warm-up render, and its per-stage seconds."""
    scene = load_scene(SCENES / "glass_egg.obj")
    options = RenderOptions(method="hybrid", progress=False)
    for key, value in scene.render_defaults.items():
        if hasattr(options, key):  # as dpm-render does (the hybrid reads every sidecar key)
            setattr(options, key, value)
    render(scene, options)
    result, (seconds,) = timed(lambda: render(scene, options))
    return seconds, result.stats["seconds"]


def write_report(records: list[dict], width: int, k: int, weights: Path | None) -> None:
    """Side-by-side PNGs and benchmarks/results/hybrid.md."""
    lines = [
        "# Hybrid vs path tracing + OIDN at equal time",
        "",
        f"Made by `python benchmarks/hybrid.py` (K = {k}, weights: {weights or 'shipped'}, "
        f"{width} px wide); {cpu()}, "
        f"{datetime.date.today().isoformat()}. Seconds are wall time of the whole render",
        "(photons, gathering, network, path tracing, denoising), compilation excluded.",
        "",
        "| scene | method | spp | seconds | RMSE | reference vs Mitsuba 3 (RMSE, mean ratio) |",
        "|---|---|---|---|---|---|",
    ]
    seconds, stages = default_render_seconds()
    lines[4:4] = [
        "",
        f"The hybrid on the glass egg (`dpm-render examples/scenes/glass_egg.obj --method hybrid`, "
        f"the scene's settings) takes {seconds:.2f} s warm: "
        + ", ".join(f"{k} {v:.2f}" for k, v in stages.items())
        + ".",
        "",
    ]
    figures = []
    for r in records:
        e, ratio = r["mitsuba_check"]
        tiles = []
        for method, (image, seconds, spp) in r["rows"].items():
            error = rmse(image, r["reference"])
            lines.append(
                f"| {r['scene']} | {method} | {spp} | {seconds:.2f} | {error:.4f} "
                f"| {e:.4f}, {ratio:.3f} |"
            )
            tiles.append(image)
        tiles.append(r["reference"])
        gap = np.ones((r["reference"].shape[0], 4, 3), np.float32)
        row = np.concatenate([x for t in tiles for x in (t, gap)][:-1], axis=1)
        iio.imwrite(OUT / f"{r['scene']}.png", linear_to_srgb8(row))
        figures += ["", f"![{r['scene']}: " + ", ".join(r["rows"]) + ", reference]"
                    f"(hybrid/{r['scene']}.png)"]  # fmt: skip
    lines += ["", "Expected RMSE of each reference (luminance; path part, caustic part): "
              + "; ".join(f"{r['scene']} {r['noise']['path_noise']:.4f}, "
                          f"{r['noise']['caustic_noise']:.4f}" for r in records) + "."]  # fmt: skip
    lines += figures
    (RESULTS / "hybrid.md").write_text("\n".join(lines) + "\n")


def main() -> None:
    """Run the comparison on the scenes named (default: glass_egg and ring)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", default=["glass_egg", "ring"])
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--k", type=int, default=50)
    p.add_argument("--weights", type=Path, help="default: the shipped model for --k")
    args = p.parse_args()
    OUT.mkdir(parents=True, exist_ok=True)
    records = [run_scene(name, args.width, args.k, args.weights) for name in args.scenes]
    write_report(records, args.width, args.k, args.weights)


if __name__ == "__main__":
    main()
