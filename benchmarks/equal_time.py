"""The default render against Mitsuba 3 `path` + OIDN at equal whole-process wall time.

    python benchmarks/equal_time.py [SCENE ...] [--width W] [--times T ...]

As a user would compare them: each run is a fresh process timed from launch to exit.
dpm is `dpm-render SCENE --time T` (the default method, `auto`). Mitsuba 3 is a fresh
Python process that imports Mitsuba (variant llvm_ad_rgb), loads the scene (converted
beforehand by the project's converter, untimed: PLY files and a JSON description), renders
`path` (its defaults: unbounded depth, Russian roulette from depth 5) with albedo and normal
AOVs, denoises with the same OIDN call as dpm and saves the image. Its samples per pixel are
fitted to dpm's measured wall time from two calibration runs (wall = fixed + per-spp cost),
with one correction run where the fit missed by more than 5 %.
Both run once untimed first (Numba's and Dr.Jit's kernel caches warm, as on a user's second
run). Scored by RMSE against the converged reference of `benchmarks/hybrid.py` (pt-nocaustic
at REF_SPP plus the PPM caustic reference), cached per scene and size.

Writes benchmarks/results/equal_time.md and benchmarks/results/equal_time/SCENE.png
(dpm | Mitsuba 3 + OIDN | reference, at the middle budget).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from hybrid import reference, reference_noise

from common import RESULTS, SCENES, cpu, linear_fit, markdown_table, passes_text, secant_spp
from dpm import load_scene
from dpm.io import linear_to_srgb8, read_exr
from dpm.methods.auto import CLEAN_GUIDE_PATHS, has_specular
from dpm.metrics import rmse
from dpm.validation.mitsuba import mitsuba_scene

OUT = RESULTS / "equal_time"
# A user's Python writes byte code at the first run and reads it afterwards; this sandbox sets
# PYTHONDONTWRITEBYTECODE, under which every launch compiled dpm's sources again (0.035 s of
# a 2-s run on the 2-core host). The children (both sides) run as on a user's machine.
os.environ.pop("PYTHONDONTWRITEBYTECODE", None)
VARIANT = "llvm_ad_rgb"
CALIBRATION_SPP = (4, 32)

# The Mitsuba child's common part (argv: desc.json, spp, variant, out, seed, ...): the scene
# description with the aov integrator (color, albedo, normal) at `spp` samples per pixel, and
# `denoise(out, paths)`: (plain color, OIDN-denoised color) of a render's (H, W, 9) output of
# `paths` samples per pixel, the guides counted as clean where auto would count them.
MITSUBA_PRELUDE = r"""
import json, sys
import numpy as np
import mitsuba as mi
import pyoidn
mi.set_variant(sys.argv[3])
desc = json.load(open(sys.argv[1]))
s = desc["sensor"]
look = s.pop("look_at")
s["to_world"] = mi.ScalarTransform4f().look_at(**look)
spp = int(sys.argv[2])
s["sampler"]["sample_count"] = spp
desc["integrator"] = {"type": "aov", "aovs": "albedo:albedo,nn:sh_normal",
                      "integrator": {"type": "path"}}


# no mirror or glass (auto's `has_specular`, from the parent): the guides count as clean
# from CLEAN_PATHS (auto's rule, the same call)
DIFFUSE_ONLY = desc.pop("dpm_diffuse_only")


def denoise(out, paths):
    out = np.asarray(out, dtype=np.float32)
    color = np.ascontiguousarray(np.maximum(np.nan_to_num(out[..., :3]), 0))
    albedo = np.ascontiguousarray(np.clip(out[..., 3:6], 0, 1))
    normal = np.ascontiguousarray(np.nan_to_num(out[..., 6:9]))
    clean = DIFFUSE_ONLY and paths >= CLEAN_PATHS
    return color, pyoidn.denoise(color, albedo, normal, hdr=True, clean_aux=clean,
                                 quality="high")
""".replace("CLEAN_PATHS", str(CLEAN_GUIDE_PATHS))

MITSUBA_CHILD = (
    MITSUBA_PRELUDE
    + r"""
out = np.array(mi.render(mi.load_dict(desc), spp=spp, seed=int(sys.argv[5])), dtype=np.float32)
np.save(sys.argv[4], denoise(out, spp)[1])
"""
)


def wall(command: list[str]) -> float:
    """Seconds from launch to exit of a process (which must succeed)."""
    start = time.perf_counter()
    subprocess.run(command, check=True, stdout=subprocess.DEVNULL)
    return time.perf_counter() - start


def mitsuba_setup(scene, camera, folder: Path, child: str = MITSUBA_CHILD) -> Path:
    """Convert the scene for the Mitsuba child (untimed): PLY files and desc.json (with
    whether the scene is diffuse only, for the child's denoiser call); the child's script
    (`child`) as child.py beside it."""
    desc = mitsuba_scene(scene, camera, 1, folder)
    c = camera
    desc["sensor"]["look_at"] = {
        "origin": c.origin.tolist(), "target": c.target.tolist(), "up": c.up.tolist()
    }  # fmt: skip
    del desc["sensor"]["to_world"]
    desc["dpm_diffuse_only"] = not has_specular(scene)  # the child pops it (`denoise`)
    path = folder / "desc.json"
    path.write_text(json.dumps(desc))
    (folder / "child.py").write_text(child)
    return path


def mitsuba_run(desc: Path, spp: int, seed: int) -> tuple[np.ndarray, float]:
    """(image, whole-process seconds) of Mitsuba 3 `path` + OIDN at spp."""
    out = desc.with_name("mitsuba.npy")
    seconds = wall(
        [sys.executable, str(desc.with_name("child.py")), str(desc), str(spp), VARIANT,
         str(out), str(seed)]
    )  # fmt: skip
    return np.load(out), seconds


def dpm_run(
    scene: Path, width: int, height: int, budget: float, seed: int, folder: Path,
    extra: tuple[str, ...] = (),
):  # fmt: skip
    """(image, whole-process seconds, stats) of `dpm-render SCENE --time budget [extra]`."""
    out, stats = folder / "dpm.exr", folder / "dpm.json"
    command = [
        "dpm-render", str(scene), "--time", str(budget), "--width", str(width),
        "--height", str(height), "--seed", str(seed), "-o", str(out), "--stats", str(stats),
        "--quiet", *extra,
    ]  # fmt: skip
    seconds = wall(command)
    return read_exr(out), seconds, json.loads(stats.read_text())


def run_scene(name: str, width: int, times: list[float]) -> dict:
    """Both renderers at each budget on one scene; errors, seconds and images."""
    path = SCENES / f"{name}.obj"
    scene = load_scene(path)
    height = width * scene.camera.height // scene.camera.width
    camera = scene.camera.with_resolution(width, height)
    ref = reference(scene, camera, name)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        desc = mitsuba_setup(scene, camera, folder)
        # warm every kernel cache: at the longest budget (adaptive sampling starts after 8
        # passes; a cold cache once cost the dragon's 4 s run 48 s of compiling)
        dpm_run(path, width, height, max(times), 0, folder)
        mitsuba_run(desc, CALIBRATION_SPP[0], 0)
        fixed, per_spp = linear_fit(*((n, mitsuba_run(desc, n, 0)[1]) for n in CALIBRATION_SPP))
        for i, budget in enumerate(times):
            ours, ours_s, stats = dpm_run(path, width, height, budget, i + 1, folder)
            spp = max(1, round((ours_s - fixed) / per_spp))
            theirs, theirs_s = mitsuba_run(desc, spp, i + 1)
            if abs(theirs_s - ours_s) > 0.05 * ours_s:  # the fit missed: one secant step
                spp = secant_spp(spp, theirs_s, fixed, ours_s)
                theirs, theirs_s = mitsuba_run(desc, spp, i + 1)
            rows.append({
                "budget": budget, "dpm_s": ours_s, "dpm_rmse": rmse(ours, ref),
                "passes": stats["passes"], "spp": stats["spp"], "plan": stats["plan"]["reason"],
                "mitsuba_s": theirs_s, "mitsuba_spp": spp, "mitsuba_rmse": rmse(theirs, ref),
                "images": (ours, theirs),
            })  # fmt: skip
            print(name, budget, {k: v for k, v in rows[-1].items() if k != "images"}, flush=True)
    mid = rows[len(rows) // 2]["images"]
    gap = np.ones((height, 4, 3), np.float32)
    strip = np.concatenate([mid[0], gap, mid[1], gap, ref], axis=1)
    iio.imwrite(OUT / f"{name}.png", linear_to_srgb8(strip))
    return {
        "scene": name, "size": f"{width}x{height}", "rows": rows, "fixed": fixed,
        "noise": reference_noise(name, camera),
    }  # fmt: skip


def report(records: list[dict]) -> str:
    """The Markdown report: a row per scene and budget, the geometric mean and the losses."""
    head = ["scene", "budget s", "dpm wall s", "passes", "dpm RMSE", "Mitsuba spp",
            "Mitsuba wall s", "Mitsuba RMSE", "dpm / Mitsuba"]  # fmt: skip
    rows, ratios, losses = [], [], []
    for r in records:
        for x in r["rows"]:
            ratio = x["dpm_rmse"] / x["mitsuba_rmse"]
            ratios.append(ratio)
            if ratio > 0.7:
                losses.append(f"{r['scene']} at {x['budget']:g} s ({ratio:.2f})")
            rows.append([
                r["scene"], f"{x['budget']:g}", f"{x['dpm_s']:.2f}", passes_text(x),
                f"{x['dpm_rmse']:.4f}", str(x["mitsuba_spp"]), f"{x['mitsuba_s']:.2f}",
                f"{x['mitsuba_rmse']:.4f}", f"{ratio:.2f}",
            ])  # fmt: skip
    plans = [f"- {r['scene']}: {r['rows'][-1]['plan']}" for r in records]
    noise = []
    for r in records:
        known = r["noise"]
        noise.append(
            f"- {r['scene']}: {known['path_noise']:.4f}, {known['caustic_noise']:.4f}"
            if known else f"- {r['scene']}: not recorded"
        )  # fmt: skip
    fixed = ", ".join(f"{r['scene']} {r['fixed']:.2f}" for r in records)
    lines = [
        "# Default render vs Mitsuba 3 path + OIDN at equal wall time",
        "",
        "Made by `python benchmarks/equal_time.py` (see its docstring): whole-process wall",
        "time from launch to exit, both warm; RMSE against the converged reference.",
        f"Machine: {cpu()}; Mitsuba {VARIANT};"
        f" {datetime.date.today()}.",
        "",
        *markdown_table(head, rows),
        "",
        f"Geometric mean of dpm / Mitsuba RMSE: {float(np.exp(np.mean(np.log(ratios)))):.2f};"
        f" worst {max(ratios):.2f}. Target: at most 0.7 everywhere.",
        "",
        "Where it loses (ratio above 0.7): " + ("; ".join(losses) or "nowhere") + ".",
        "",
        "The references' own expected RMSE (luminance; path-traced part, caustic part), which",
        "both renderers' RMSE includes (in quadrature), so an RMSE near it says little:",
        *noise,
        "",
        f"Mitsuba's fixed cost per process (start, JIT, denoise; fitted): {fixed} s.",
        "",
        "The plan `auto` chose (at the largest budget):",
        *plans,
        "",
        *[f"![{r['scene']}: dpm, Mitsuba 3 + OIDN, reference](equal_time/{r['scene']}.png)"
          for r in records],
    ]  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the comparison on the scenes named (default: every example scene with caustics)."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    scenes = sorted(f.stem for f in SCENES.glob("*.obj"))
    p.add_argument("scenes", nargs="*", default=None)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--times", type=float, nargs="+", default=[2.0, 4.0, 8.0])
    p.add_argument("--references-only", action="store_true", help="build the references, stop")
    args = p.parse_args()
    names = args.scenes or [n for n in scenes if has_specular(load_scene(SCENES / f"{n}.obj"))]
    OUT.mkdir(parents=True, exist_ok=True)
    if args.references_only:
        for name in names:
            scene = load_scene(SCENES / f"{name}.obj")
            h = args.width * scene.camera.height // scene.camera.width
            camera = scene.camera.with_resolution(args.width, h)
            reference(scene, camera, name)
        return
    records = [run_scene(name, args.width, args.times) for name in names]
    text = report(records)
    (RESULTS / "equal_time.md").write_text(text)
    print(text)


if __name__ == "__main__":
    main()
