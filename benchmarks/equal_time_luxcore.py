"""The default render against LuxCoreRender PATHCPU + PhotonGI caustic cache at equal
whole-process wall time, unseen scenes.

    python benchmarks/equal_time_luxcore.py [SCENE ...] [--times T ...]

The second peer of `equal_time_unseen.py` (same scenes, resolutions, references and dpm runs):

- dpm: `dpm-render SCENE --time T --width W --height H --seed S` in a fresh process, wall
  seconds from launch to exit (`equal_time.dpm_run`).
- LuxCore: `python -m dpm.validation.luxcore SCENE --time t --denoised ...` in a fresh process
  at once after, t = the seconds dpm just took, counted from the child's start (interpreter,
  pyluxcore import and conversion included). It renders PATHCPU with the caustic cache
  (where the scene has a mirror or dielectric), stops by the deadline less a reserve (the
  seconds from the end of rendering to the exit that its previous run of the scene took:
  denoise, write, exit), but not before one sample per pixel, and writes its plain film and
  its OIDN image (albedo and average shading normal guides, `dpm.denoise`). The cache's first
  build cannot be cut short, so at small budgets LuxCore overruns: its wall time is in the
  table beside dpm's, and a row where it took more than 10 % longer is marked.
- Per budget dpm runs first, then LuxCore (the machine's load falls on both in turn). Both
  run once untimed per scene first (dpm at the largest budget for Numba's cache; LuxCore one
  short run, for the reserve).
- Scored by RMSE against the scene's Mitsuba 3 reference (2 x 16384 spp; the controls
  2 x 4096); LuxCore's score is the better of plain and OIDN; ratio = dpm / LuxCore's best.

Writes results/equal_time_luxcore/NAME.json per scene and results/equal_time_luxcore.md.
"""

from __future__ import annotations

import argparse
import datetime
import json
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
from equal_time import dpm_run
from equal_time_unseen import corrected_ratio, corrected_summary, load, scoring_reference, summary

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import CONTROLS, UNSEEN, unseen_scenes  # noqa: E402
from unseen_references import OUT as REFERENCES  # noqa: E402

from common import RESULTS, cpu, markdown_table, passes_text, save_records  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.io import read_exr  # noqa: E402
from dpm.methods.auto import CLEAN_GUIDE_PATHS, has_specular  # noqa: E402
from dpm.metrics import rmse  # noqa: E402

OUT = RESULTS / "equal_time_luxcore"
TABLE = RESULTS / "equal_time_luxcore.md"
TIMES = (2.0, 4.0, 8.0, 16.0)
WARM_BUDGET = 1.0  # seconds of LuxCore's untimed first run (it overruns: one spp at least)
SEED_STRIDE = 1000  # LuxCore's seed at budget i: SEED_STRIDE * (i + 1)
OVERRUN = 1.10  # LuxCore wall time / dpm's above which a row is marked


def luxcore_run(
    scene: Path, width: int, height: int, budget: float, reserve: float, seed: int, folder: Path,
    clean: tuple[str, ...] = (),
) -> tuple[np.ndarray, np.ndarray, float, dict]:  # fmt: skip
    """(plain, OIDN-denoised, whole-process seconds, the child's stats) of a LuxCore render
    time-boxed to `budget` seconds from its start, keeping `reserve` seconds for the end
    (`clean`: the --clean-guides-from flag, where dpm's rule counts the guides as clean)."""
    plain, oidn = folder / "luxcore.npy", folder / "luxcore-oidn.npy"
    launch = time.monotonic()
    done = subprocess.run(
        [sys.executable, "-m", "dpm.validation.luxcore", str(scene), "--width", str(width),
         "--height", str(height), "--time", repr(budget), "--reserve", repr(reserve),
         "--seed", str(seed), "-o", str(plain), "--denoised", str(oidn), *clean],
        capture_output=True, text=True, check=True,
    )  # fmt: skip
    seconds = time.monotonic() - launch
    stats = json.loads(done.stdout.strip().splitlines()[-1])
    return np.load(plain), np.load(oidn), seconds, stats


def run_scene(name: str, times: list[float]) -> dict:
    """dpm and LuxCore at each budget on scene `name`; errors, seconds, spp and load."""
    path = {p.stem: p for p in unseen_scenes()}[name]
    scene = load_scene(path)
    width, height, ref_path, _ = scoring_reference(name, scene.camera.width)
    ref = read_exr(ref_path)
    load_start = load()
    print(f"{name} {width}x{height}: load average {load_start}", flush=True)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        dpm_run(path, width, height, max(times), 0, folder)  # warm Numba's cache, untimed
        *_, warm = luxcore_run(path, width, height, WARM_BUDGET, 0.3, 0, folder)
        reserve = warm["seconds_process"] - warm["seconds_rendered"] + 0.3
        # OIDN told the guides are clean where auto would tell it (the same denoiser call)
        clean = () if has_specular(scene) else ("--clean-guides-from", str(CLEAN_GUIDE_PATHS))
        for i, budget in enumerate(times):
            ours, ours_s, stats = dpm_run(path, width, height, budget, i + 1, folder)
            plain, oidn, theirs_s, info = luxcore_run(
                path, width, height, ours_s, reserve, SEED_STRIDE * (i + 1), folder, clean
            )
            plain_rmse, oidn_rmse, ours_rmse = rmse(plain, ref), rmse(oidn, ref), rmse(ours, ref)
            rows.append({
                "budget": budget, "dpm_s": ours_s, "passes": stats["passes"], "spp": stats["spp"],
                "plan": stats.get("plan", {}).get("reason"), "dpm_rmse": ours_rmse,
                "luxcore_s": theirs_s, "luxcore_spp": info["spp"],
                "luxcore_start_s": info["seconds_start"], "luxcore_plain_rmse": plain_rmse,
                "luxcore_oidn_rmse": oidn_rmse, "ratio": ours_rmse / min(plain_rmse, oidn_rmse),
                "reserve_s": reserve, "renderer": info["renderer"],
            })  # fmt: skip
            reserve = info["seconds_process"] - info["seconds_rendered"]
            shown = ("dpm_s", "passes", "dpm_rmse", "luxcore_s", "luxcore_spp",
                     "luxcore_plain_rmse", "luxcore_oidn_rmse", "ratio")  # fmt: skip
            print(f"{name} {budget:g} s:", {k: round(rows[-1][k], 4) for k in shown}, flush=True)
    load_end = load()
    print(f"{name}: load average {load_end}", flush=True)
    return {
        "scene": name, "control": name in CONTROLS, "size": f"{width}x{height}",
        "reference": ref_path.name, "load_start": load_start, "load_end": load_end,
        "cpu": cpu(), "date": str(datetime.date.today()), "rows": rows,
    }  # fmt: skip


def with_noise(record: dict) -> dict:
    """The record with its reference's noise (`reference_noise_rgb`, from the reference's
    JSON) and each row's best LuxCore RMSE (`best`)."""
    noise = json.loads((REFERENCES / record["reference"]).with_suffix(".json").read_text())
    rows = [{**x, "best": min(x["luxcore_plain_rmse"], x["luxcore_oidn_rmse"])}
            for x in record["rows"]]  # fmt: skip
    return {**record, "reference_noise_rgb": noise["noise_rgb"], "rows": rows}


def report(records: list[dict]) -> str:
    """The Markdown report: a table per group (caustic scenes, controls) and their summaries."""
    records = [with_noise(r) for r in records]
    order = {name: i for i, name in enumerate(UNSEEN)}
    records = sorted(records, key=lambda r: order.get(r["scene"], len(order)))
    head = ["scene", "W x H", "budget s", "dpm wall s", "passes", "dpm RMSE", "LuxCore spp",
            "LuxCore wall s", "LuxCore plain RMSE", "LuxCore OIDN RMSE",
            "dpm / LuxCore best", "noise-corrected"]  # fmt: skip

    def corrected(r: dict, x: dict) -> str:
        q = corrected_ratio(r, x, "dpm_rmse", "best")
        return f"{q:.2f}" if np.isfinite(q) else "below noise"

    def table(group: list[dict]) -> list[str]:
        rows = [
            [r["scene"], r["size"], f"{x['budget']:g}", f"{x['dpm_s']:.2f}", passes_text(x),
             f"{x['dpm_rmse']:.4f}", f"{x['luxcore_spp']:.1f}",
             f"{x['luxcore_s']:.2f}" + (" (late)" if x["luxcore_s"] > OVERRUN * x["dpm_s"]
                                         else ""),
             f"{x['luxcore_plain_rmse']:.4f}", f"{x['luxcore_oidn_rmse']:.4f}",
             f"{x['ratio']:.2f}", corrected(r, x)]
            for r in group for x in r["rows"]
        ]  # fmt: skip
        return markdown_table(head, rows)

    def on_time(group: list[dict]) -> list[dict]:
        kept = [dict(r, rows=[x for x in r["rows"] if x["luxcore_s"] <= OVERRUN * x["dpm_s"]])
                for r in group]  # fmt: skip
        return kept

    caustic = [r for r in records if not r["control"]]
    controls = [r for r in records if r["control"]]
    machines = sorted({r["cpu"] for r in records})
    dates = sorted({r["date"] for r in records})
    renderers = sorted({x["renderer"] for r in records for x in r["rows"]})
    lines = [
        "# Default render vs LuxCoreRender PATHCPU + caustic cache at equal wall time, unseen",
        "",
        "Made by `python benchmarks/equal_time_luxcore.py` (see its docstring): whole-process",
        "wall time from launch to exit, dpm warm; LuxCore time-boxed to dpm's measured wall",
        "time but never stopped before one sample per pixel (the caustic cache's first build",
        "cannot be cut short: rows marked late took more than 10 % longer than dpm); RMSE",
        "against the scene's Mitsuba 3 reference (2 x 16384 spp; the controls 2 x 4096);",
        "LuxCore's score is the better of its plain film and its OIDN image (albedo and normal",
        "guides).",
        f"Machine: {'; '.join(machines)}; {', '.join(renderers)}; {', '.join(dates)}.",
        "",
        "## Scenes with caustics",
        "",
        *table(caustic),
        "",
        "Caustic scenes: " + summary(caustic, "LuxCore"),
        "",
        "Caustic scenes, rows where LuxCore was on time: " + summary(on_time(caustic), "LuxCore"),
        "",
        "Noise-corrected (each side's RMSE² less the reference's noise², as in",
        "`equal_time_unseen.md`): " + corrected_summary(caustic),
        "",
        "## Diffuse-only controls",
        "",
        *table(controls),
        "",
        "Controls: " + summary(controls, "LuxCore"),
        "",
        "Controls, noise-corrected: " + corrected_summary(controls),
        "",
        *[f"- {r['scene']}: load average {r['load_start']} at the start, {r['load_end']} at "
          "the end" for r in records],
    ]  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the comparison on the unseen scenes named (default: all) and rebuild the report."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", help=f"scenes (default: all): {', '.join(UNSEEN)}")
    p.add_argument("--times", type=float, nargs="+", default=list(TIMES))
    args = p.parse_args()
    unknown = set(args.scenes) - set(UNSEEN)
    if unknown:
        p.error(f"unknown scene(s) {sorted(unknown)}")
    OUT.mkdir(parents=True, exist_ok=True)
    names = args.scenes or list(UNSEEN)
    save_records(OUT, names, lambda n: run_scene(n, args.times), report, TABLE)


if __name__ == "__main__":
    main()
