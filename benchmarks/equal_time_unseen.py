"""The default render against Mitsuba 3 `path` at equal whole-process wall time, unseen scenes.

    python benchmarks/equal_time_unseen.py [SCENE ...] [--times T ...]
    python benchmarks/equal_time_unseen.py --set examples [SCENE ...] [--times T ...]

On the unseen-scene set (`benchmarks/scenes/make_unseen.py`; default: all of it, the two
diffuse controls included), at the resolution W x H of each scene's Mitsuba 3 reference
(`benchmarks/scenes/unseen_references.py`: results/unseen/NAME-WxH-mitsuba.exr, two halves of
16384 spp, the controls' of 4096; W = min(camera width, 256)) and for each budget T of --times:

- dpm: `dpm-render SCENE --time T --width W --height H --seed S` in a fresh process, wall
  seconds from launch to exit (`equal_time.dpm_run`).
- Mitsuba 3 (llvm_ad_rgb with the libLLVM `unseen_references.mitsuba_variant` finds): a fresh
  child process time-boxed to the seconds dpm just took, counted from its launch. It imports
  Mitsuba, loads the scene (converted once beforehand, untimed: `equal_time.mitsuba_setup`),
  renders batches of BATCH_SPP (16; --batch-spp) samples per pixel with different seeds through
  the aov integrator (color, albedo, normal; `path` with its defaults inside, as `equal_time`),
  accumulating their mean, until the next batch (the mean of the batches so far, the first left
  out once there are more) plus a reserve would overrun the budget, then writes the plain mean
  and its OIDN-denoised image (`equal_time`'s denoise call). At least one batch. The reserve is
  the seconds from the end of rendering to the process's exit (denoise, save, interpreter exit)
  that the previous Mitsuba run of the scene took (first: the warm-up's).
- Per budget dpm runs first, then Mitsuba at once (the load of the machine falls on both in
  turn, budget after budget); the load average (`os.getloadavg`) is recorded at the start and
  end of each scene. Both sides run once untimed first per scene (dpm at the largest budget,
  so Numba's cache is warm; Mitsuba one short run per sampler, for Dr.Jit's kernel cache and
  the reserve).
- Mitsuba runs with each sampler of --samplers (default: `independent`, its default, and
  `multijitter`, its best per sample on the controls), each time-boxed to dpm's seconds, in
  turn (the first sampler alternating with the budget).
- Scored by RMSE (`dpm.metrics.rmse`, all pixels and channels) against the reference's mean;
  Mitsuba's score is the best of plain and OIDN over its samplers; ratio = dpm / that.

Writes a JSON record per scene to results/equal_time_unseen/NAME.json (a rerun of some scenes
rebuilds the table from all records), results/equal_time_unseen.md, and per scene
results/equal_time_unseen/NAME.png (dpm | Mitsuba's best | reference, at the budget nearest 4 s).

`--set examples` runs the same protocol on the example scenes (the ones the constants were
chosen on), EXAMPLE_WIDTH pixels wide, scored against `benchmarks/hybrid.py`'s references
(pt-nocaustic plus the PPM caustic reference, cached in results/equal_time/; their noise is
known in luminance only, so no noise-corrected column), into results/equal_time_examples.md
and results/equal_time_examples/: the two sets' figures from one protocol, so the gap between
them is the scenes', not the method's. (`benchmarks/equal_time.py` is the older protocol:
Mitsuba's spp fitted to dpm's time, one sampler.)
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import imageio.v3 as iio
import numpy as np
from equal_time import MITSUBA_PRELUDE, dpm_run, mitsuba_setup
from hybrid import reference, reference_noise, reference_path

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import CONTROLS, UNSEEN, unit_scale, unseen_scenes  # noqa: E402
from unseen_references import OUT as REFERENCES  # noqa: E402
from unseen_references import mitsuba_variant  # noqa: E402

from common import RESULTS, SCENES, cpu, markdown_table, passes_text, save_records  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.io import linear_to_srgb8, read_exr  # noqa: E402
from dpm.methods.auto import has_specular  # noqa: E402
from dpm.metrics import rmse  # noqa: E402

OUT = RESULTS / "equal_time_unseen"
TABLE = RESULTS / "equal_time_unseen.md"
EXAMPLES = ("cornell_box", "dragon", "glass_egg", "pool1", "pool2", "red_wine", "ring", "torus")
EXAMPLE_WIDTH = 128  # as benchmarks/equal_time.py, whose references are reused
TIMES = (2.0, 4.0, 8.0, 16.0)
MAX_WIDTH = 256  # the references' width: min(camera width, MAX_WIDTH)
BATCH_SPP = 16  # Mitsuba samples per pixel per render call
WARM_BUDGET = 1.0  # seconds of Mitsuba's untimed warm-up run (at least one batch)
SEED_STRIDE = 100_000  # Mitsuba's seeds: SEED_STRIDE * (budget index + 1) + batch; the
# references' are 1,000,000 + x and 2,000,000 + x (x < 8192), so none is shared
PICTURE_BUDGET = 4.0  # the side-by-side image's budget (the nearest one run)

SAMPLERS = ("independent", "multijitter")  # Mitsuba's samplers run at each budget

# argv: desc.json, spp per batch, variant, out.npz, first seed, launch (time.monotonic() of the
# parent just before it started this process), budget seconds, reserve seconds, sampler
MITSUBA_TIMEBOX = (
    MITSUBA_PRELUDE
    + r"""
import time
launch, budget, reserve = (float(a) for a in sys.argv[6:9])
desc["sensor"]["sampler"]["type"] = sys.argv[9]
scene = mi.load_dict(desc)
loaded = time.monotonic()
total, batches, dropped = None, [], 0
while True:
    start = time.monotonic()
    image = np.array(mi.render(scene, spp=spp, seed=int(sys.argv[5]) + len(batches)),
                     dtype=np.float64)
    batches.append(time.monotonic() - start)
    finite = np.isfinite(image)
    dropped += int((~finite).sum())
    image = np.where(finite, image, 0.0)
    total = image if total is None else total + image
    batch = float(np.mean(batches[1:] if len(batches) > 1 else batches))
    if time.monotonic() + batch + reserve > launch + budget:
        break
rendered = time.monotonic()
plain, oidn = denoise(total / len(batches), spp * len(batches))
np.savez(sys.argv[4], plain=plain, oidn=oidn)
saved = time.monotonic()
info = {"spp": spp * len(batches), "batches": len(batches), "batch_seconds": batches,
        "loaded": loaded - launch, "rendered": rendered - launch, "saved": saved - launch,
        "nonfinite_dropped": dropped}
open(sys.argv[4] + ".json", "w").write(json.dumps(info))
"""
)


def reference_file(name: str, camera_width: int) -> tuple[int, int, Path]:
    """(W, H, EXR path) of scene `name`'s Mitsuba reference in results/unseen: the one that is
    there, or of several the one MAX_WIDTH or the camera's width wide."""
    found = {}
    for path in REFERENCES.glob(f"{name}-*-mitsuba.exr"):
        match = re.fullmatch(rf"{re.escape(name)}-(\d+)x(\d+)-mitsuba\.exr", path.name)
        if match and path.with_suffix(".json").exists():
            found[int(match.group(1))] = (int(match.group(1)), int(match.group(2)), path)
    if not found:
        raise SystemExit(f"{name}: no reference in {REFERENCES} (benchmarks/scenes/"
                         "unseen_references.py --only mitsuba builds it)")  # fmt: skip
    return found.get(min(camera_width, MAX_WIDTH)) or next(iter(found.values()))


def scoring_reference(name: str, camera_width: int) -> tuple[int, int, Path, Path | None]:
    """(W, H, reference EXR, the scene's own reference EXR where that is another) that scene
    `name` is scored against: a uniformly scaled copy's is its scale-1 twin's (the same image
    by physics: every length scaled, radiance kept), since a renderer's float precision at
    scale 0.01 is part of what the copy tests, and a reference rendered at that scale shares
    its renderer's error there (Mitsuba's at 0.01 moves the spheres' focal caustics)."""
    width, height, own = reference_file(name, camera_width)
    twin = unit_scale(name)
    if twin == name:
        return width, height, own, None
    w, h, path = reference_file(twin, camera_width)
    assert (w, h) == (width, height), f"{name}: {twin}'s reference is {w}x{h}"
    return width, height, path, own


def mitsuba_timebox(
    desc: Path,
    variant: str,
    budget: float,
    reserve: float,
    seed: int,
    batch_spp: int = BATCH_SPP,
    sampler: str = "independent",
) -> tuple[np.ndarray, np.ndarray, float, dict]:
    """(plain mean, OIDN-denoised, whole-process seconds, the child's record) of a Mitsuba
    child with `sampler` time-boxed to `budget` seconds from its launch, keeping `reserve`
    seconds for the end. The record's "tail" is the seconds from rendering's end to the exit."""
    out = desc.with_name("timebox.npz")
    launch = time.monotonic()
    subprocess.run(
        [sys.executable, str(desc.with_name("child.py")), str(desc), str(batch_spp), variant,
         str(out), str(seed), repr(launch), repr(budget), repr(reserve), sampler],
        check=True, stdout=subprocess.DEVNULL,
    )  # fmt: skip
    seconds = time.monotonic() - launch
    info = json.loads(Path(f"{out}.json").read_text())
    info["tail"] = seconds - info["rendered"]
    assert info["batches"] < SEED_STRIDE, "batches' seeds would overlap the next budget's"
    with np.load(out) as z:
        return z["plain"], z["oidn"], seconds, info


def load() -> list[float]:
    """The machine's load averages over 1, 5 and 15 minutes."""
    return [round(x, 2) for x in os.getloadavg()]


def run_scene(
    name: str,
    times: list[float],
    variant: str,
    batch_spp: int = BATCH_SPP,
    samplers: tuple[str, ...] = SAMPLERS,
) -> dict:
    """Both renderers at each budget on scene `name` (Mitsuba with each sampler); errors,
    seconds, spp and load. A row's flat Mitsuba fields are its first sampler's; the others'
    are under "mitsuba_<sampler>"."""
    if name in EXAMPLES:
        path = SCENES / f"{name}.obj"
        scene = load_scene(path)
        width = EXAMPLE_WIDTH
        height = width * scene.camera.height // scene.camera.width
        camera = scene.camera.with_resolution(width, height)
        ref, own, own_path = reference(scene, camera, name), None, None
        ref_path = reference_path(name, camera)
        parts = reference_noise(name, camera) or {}
        luminance = float(np.hypot(parts.get("path_noise", np.nan), parts.get("caustic_noise", 0)))
        noise = {"noise_rgb": None, "noise_luminance": luminance, "spp_per_half": None}
        control = not has_specular(scene)
    else:
        path = {p.stem: p for p in unseen_scenes()}[name]
        scene = load_scene(path)
        width, height, ref_path, own_path = scoring_reference(name, scene.camera.width)
        camera = scene.camera.with_resolution(width, height)
        ref = read_exr(ref_path)
        own = None if own_path is None else read_exr(own_path)
        noise = json.loads(ref_path.with_suffix(".json").read_text())
        control = name in CONTROLS
    load_start = load()
    print(f"{name} {width}x{height}: load average {load_start}", flush=True)
    rows, images = [], []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        desc = mitsuba_setup(scene, camera, folder, MITSUBA_TIMEBOX)
        dpm_run(path, width, height, max(times), 0, folder)  # warm Numba's cache, untimed
        reserve = {}  # each sampler's own warm-up: its kernels differ (Dr.Jit compiles them)
        for k in samplers:
            *_, warm = mitsuba_timebox(desc, variant, WARM_BUDGET, 0.0, 0, batch_spp, k)
            reserve[k] = warm["tail"]
        for i, budget in enumerate(times):
            ours, ours_s, stats = dpm_run(path, width, height, budget, i + 1, folder)
            ours_rmse = rmse(ours, ref)
            runs = {}  # sampler -> (plain, OIDN, seconds, the child's record)
            for k in samplers[i % len(samplers) :] + samplers[: i % len(samplers)]:
                runs[k] = mitsuba_timebox(
                    desc, variant, ours_s, reserve[k], SEED_STRIDE * (i + 1), batch_spp, k
                )
                reserve[k] = runs[k][3]["tail"]
            plain, oidn, theirs_s, info = runs[samplers[0]]
            plain_rmse, oidn_rmse = rmse(plain, ref), rmse(oidn, ref)
            rows.append({
                "budget": budget, "dpm_s": ours_s, "passes": stats["passes"], "spp": stats["spp"],
                "plan": stats.get("plan", {}).get("reason"), "dpm_rmse": ours_rmse,
                "mitsuba_s": theirs_s, "mitsuba_spp": info["spp"],
                "mitsuba_plain_rmse": plain_rmse, "mitsuba_oidn_rmse": oidn_rmse,
                "reserve_s": reserve[samplers[0]],
                "mitsuba_loaded_s": info["loaded"], "mitsuba_rendered_s": info["rendered"],
                "mitsuba_batch_s": float(np.median(info["batch_seconds"])),
                "mitsuba_tail_s": info["tail"], "mitsuba_nonfinite": info["nonfinite_dropped"],
            })  # fmt: skip
            if own is not None:  # the same three errors against the scene's own reference
                rows[-1].update(dpm_rmse_own=rmse(ours, own), mitsuba_plain_rmse_own=rmse(
                    plain, own), mitsuba_oidn_rmse_own=rmse(oidn, own))  # fmt: skip
            for k in samplers[1:]:
                p, o, sec, rec = runs[k]
                rows[-1][f"mitsuba_{k}"] = {
                    "s": sec, "spp": rec["spp"], "plain_rmse": rmse(p, ref),
                    "oidn_rmse": rmse(o, ref), "tail_s": rec["tail"],
                    **({} if own is None else {"plain_rmse_own": rmse(p, own),
                                               "oidn_rmse_own": rmse(o, own)}),
                }  # fmt: skip
            rows[-1]["mitsuba_best_rmse"] = mitsuba_best(rows[-1])
            rows[-1]["ratio"] = ours_rmse / rows[-1]["mitsuba_best_rmse"]
            best = min(runs.values(), key=lambda run: min(rmse(run[0], ref), rmse(run[1], ref)))
            images.append((ours, best[0] if rmse(best[0], ref) <= rmse(best[1], ref) else best[1]))
            shown = ("dpm_s", "passes", "spp", "dpm_rmse", "mitsuba_s", "mitsuba_spp",
                     "mitsuba_plain_rmse", "mitsuba_oidn_rmse", "ratio")  # fmt: skip
            print(f"{name} {budget:g} s:", {k: round(rows[-1][k], 4) for k in shown}, flush=True)
    load_end = load()
    print(f"{name}: load average {load_end}", flush=True)
    pick = int(np.argmin([abs(b - PICTURE_BUDGET) for b in times]))
    gap = np.ones((height, 4, 3), np.float32)
    strip = np.concatenate([images[pick][0], gap, images[pick][1], gap, ref], axis=1)
    iio.imwrite(out_folder(name) / f"{name}.png", linear_to_srgb8(strip))
    return {
        "scene": name, "control": control, "size": f"{width}x{height}",
        "reference": ref_path.name, "own_reference": None if own_path is None else own_path.name,
        "reference_noise_rgb": noise["noise_rgb"],
        "reference_noise_luminance": noise["noise_luminance"],
        "reference_spp_per_half": noise["spp_per_half"], "variant": variant,
        "samplers": list(samplers),
        "batch_spp": batch_spp, "picture_budget": times[pick], "load_start": load_start,
        "load_end": load_end, "cpu": cpu(), "date": str(datetime.date.today()), "rows": rows,
    }  # fmt: skip


def out_folder(name: str) -> Path:
    """Where scene `name`'s record and picture go: its set's folder."""
    return RESULTS / "equal_time_examples" if name in EXAMPLES else OUT


def mitsuba_best(row: dict, own: str = "") -> float:
    """Mitsuba's best RMSE in a row: plain or OIDN, over its samplers (own "_own": against
    the scene's own reference)."""
    best = min(row[f"mitsuba_plain_rmse{own}"], row[f"mitsuba_oidn_rmse{own}"])
    for key, run in row.items():
        if key.startswith("mitsuba_") and isinstance(run, dict):
            best = min(best, run[f"plain_rmse{own}"], run[f"oidn_rmse{own}"])
    return best


def own_error(rmse_value: float, noise: float) -> float:
    """The RMSE against the truth a render has, from its RMSE against a reference whose own
    expected RMSE is `noise`: E[MSE(x, ref)] = MSE(x, truth) + noise² when the reference's
    noise is independent of x (noise² = mean((A - B)²) / 4 of its two halves, unbiased).
    NaN where the difference is not positive: the render is as close to the truth as the
    reference can tell."""
    excess = rmse_value**2 - noise**2
    return float(np.sqrt(excess)) if excess > 0 else float("nan")


def corrected_ratio(record: dict, row: dict, ours: str, theirs: str) -> float:
    """Ratio of the two sides' own errors (`own_error`, the record's reference noise); NaN
    where either side is below the reference's noise, or the noise is not known in RGB."""
    noise = record["reference_noise_rgb"]
    if noise is None:
        return float("nan")
    return own_error(row[ours], noise) / own_error(row[theirs], noise)


def corrected_summary(records: list[dict], ours: str = "dpm_rmse", theirs: str = "best") -> str:
    """One line: the geometric mean of the noise-corrected ratios over the rows where both
    sides' errors exceed the reference's noise, and how many rows could not be told."""
    if any(r["reference_noise_rgb"] is None for r in records):
        return "not made: the references' noise is known in luminance only."
    ratios = []
    for r in records:
        for x in r["rows"]:
            other = x[theirs] if theirs in x else mitsuba_best(x)
            ratios.append(corrected_ratio(r, {**x, "best": other}, ours, "best"))
    told = np.array([q for q in ratios if np.isfinite(q)])
    if not len(told):
        return "no row above the reference's noise."
    return (f"geometric mean {float(np.exp(np.mean(np.log(told)))):.2f} over the {len(told)} "
            f"rows where both errors exceed the reference's noise ({len(ratios) - len(told)} "
            f"rows below it left out); {int((told > 1.0).sum())} of them above 1.0.")  # fmt: skip


def summary(records: list[dict], peer: str = "Mitsuba") -> str:
    """One line: geometric mean, worst row and rows above 1.0 of the records' ratios."""
    rows = [(r["scene"], x["budget"], x["ratio"]) for r in records for x in r["rows"]]
    if not rows:
        return "no rows."
    ratios = np.array([ratio for *_, ratio in rows])
    worst = rows[int(np.argmax(ratios))]
    return (f"geometric mean of dpm / {peer} best {float(np.exp(np.mean(np.log(ratios)))):.2f}"
            f" over {len(rows)} rows; worst {worst[2]:.2f} ({worst[0]} at {worst[1]:g} s); "
            f"{int((ratios > 1.0).sum())} of {len(rows)} rows above 1.0.")  # fmt: skip


def scaled_copies(records: list[dict]) -> list[str]:
    """Lines on the scaled copies scored against their scale-1 twin's reference: the ratios
    against their own reference beside the headline's."""
    copies = [r for r in records if r.get("own_reference")]
    if not copies:
        return []
    lines = [
        "A uniformly scaled copy (every length times 0.01 or 100, radiance kept) has the image",
        "of its scale-1 twin, so it is scored against the twin's reference: a reference rendered",
        "at scale 0.01 shares its renderer's float error there (Mitsuba's own reference of",
        "spheres_s0p01 moves the spheres' focal caustics). Against each copy's own Mitsuba",
        "reference instead (rendered with the twin's seeds, so the two differ by little more",
        "than the renderer's error at that scale):",
    ]
    for r in copies:
        apart = rmse(
            read_exr(REFERENCES / r["own_reference"]), read_exr(REFERENCES / r["reference"])
        )
        ratios = [x["dpm_rmse_own"] / mitsuba_best(x, "_own") for x in r["rows"]]
        budgets = ", ".join(f"{x['budget']:g}" for x in r["rows"])
        lines.append(f"- {r['scene']} against {r['own_reference']} (RMSE {apart:.4f} from the "
                     f"twin's) at {budgets} s: dpm / Mitsuba best "
                     f"{', '.join(f'{q:.2f}' for q in ratios)}")  # fmt: skip
    return [*lines, ""]


def independent(records: list[dict]) -> list[dict]:
    """The records with each row's ratio against Mitsuba's first (`independent`) sampler."""
    return [
        {**r, "rows": [
            {**x, "ratio": x["dpm_rmse"] / min(x["mitsuba_plain_rmse"], x["mitsuba_oidn_rmse"])}
            for x in r["rows"]
        ]}
        for r in records
    ]  # fmt: skip


def report(records: list[dict]) -> str:
    """The Markdown report: a table per group (caustic scenes, controls) and their summaries."""
    examples = bool(records) and records[0]["scene"] in EXAMPLES
    order = {name: i for i, name in enumerate(EXAMPLES if examples else UNSEEN)}
    records = sorted(records, key=lambda r: order.get(r["scene"], len(order)))
    head = ["scene", "W x H", "budget s", "dpm wall s", "passes", "dpm RMSE", "Mitsuba spp",
            "Mitsuba wall s", "Mitsuba plain RMSE", "Mitsuba OIDN RMSE",
            "multijitter spp", "multijitter plain / OIDN RMSE", "dpm / Mitsuba best",
            "noise-corrected"]  # fmt: skip

    def corrected(r: dict, x: dict) -> str:
        if r["reference_noise_rgb"] is None:
            return "–"
        q = corrected_ratio(r, {**x, "best": mitsuba_best(x)}, "dpm_rmse", "best")
        return f"{q:.2f}" if np.isfinite(q) else "below noise"

    def jitter(x: dict) -> list[str]:
        mj = x.get("mitsuba_multijitter")
        if mj is None:
            return ["–", "–"]
        return [str(mj["spp"]), f"{mj['plain_rmse']:.4f} / {mj['oidn_rmse']:.4f}"]

    def table(group: list[dict]) -> list[str]:
        rows = [
            [r["scene"], r["size"], f"{x['budget']:g}", f"{x['dpm_s']:.2f}", passes_text(x),
             f"{x['dpm_rmse']:.4f}", str(x["mitsuba_spp"]), f"{x['mitsuba_s']:.2f}",
             f"{x['mitsuba_plain_rmse']:.4f}", f"{x['mitsuba_oidn_rmse']:.4f}",
             *jitter(x), f"{x['ratio']:.2f}", corrected(r, x)]
            for r in group for x in r["rows"]
        ]  # fmt: skip
        return markdown_table(head, rows)

    caustic = [r for r in records if not r["control"]]
    controls = [r for r in records if r["control"]]
    walls = [abs(x["mitsuba_s"] / x["dpm_s"] - 1) for r in records for x in r["rows"]]
    machines = sorted({r["cpu"] for r in records})
    dates = sorted({r["date"] for r in records})
    variants = sorted({r["variant"] for r in records})
    batches = ", ".join(str(b) for b in sorted({r["batch_spp"] for r in records}))

    def noise_text(r: dict) -> str:
        if r["reference_noise_rgb"] is None:  # an example's reference (benchmarks/hybrid.py)
            return f"reference noise {r['reference_noise_luminance']:.4f} luminance"
        return (f"reference noise {r['reference_noise_rgb']:.4f} RGB, "
                f"{r['reference_noise_luminance']:.4f} luminance "
                f"(2 x {r['reference_spp_per_half']} spp)")  # fmt: skip

    per_scene = [
        f"- {r['scene']} ({r['size']}): {noise_text(r)}; load average {r['load_start']} at the "
        f"start, {r['load_end']} at the end; plan at {r['rows'][-1]['budget']:g} s: "
        f"{r['rows'][-1]['plan']}"
        for r in records
    ]
    scored = (
        ["(`benchmarks/hybrid.py`: pt-nocaustic plus the PPM caustic reference, noise in",
         "luminance only); Mitsuba's score is the best of its plain mean and its OIDN image",
         "over its"]
        if examples else
        ["(two halves, spp per scene below; a scaled copy against its scale-1 twin's, see the",
         "end); Mitsuba's score is the best of its plain mean and its OIDN image over its"]
    )  # fmt: skip
    lines = [
        "# Default render vs Mitsuba 3 path (+ OIDN) at equal wall time, "
        + ("the examples (tuned on)" if examples else "unseen scenes"),
        "",
        "Made by `python benchmarks/equal_time_unseen.py"
        + (" --set examples" if examples else "")
        + "` (see its docstring): whole-process",
        "wall time from launch to exit, both warm; Mitsuba time-boxed to dpm's measured wall",
        f"time, in batches of {batches} spp; RMSE against the scene's "
        + ("reference" if examples else "Mitsuba 3 reference"),
        *scored,
        "samplers (Mitsuba columns: `independent`, its default; multijitter columns: its",
        "`multijitter` sampler, time-boxed the same; a record from before shows `–`).",
        f"Machine: {'; '.join(machines)}; Mitsuba {', '.join(variants)}; {', '.join(dates)}.",
        "Load averages (1, 5, 15 min) per scene below.",
        "",
        "## Scenes with caustics",
        "",
        *table(caustic),
        "",
        "Caustic scenes: " + summary(caustic),
        "",
        "Against Mitsuba's `independent` sampler alone: " + summary(independent(caustic)),
        "",
        "Noise-corrected (each side's RMSE² less the reference's noise², `own_error`): "
        + corrected_summary(caustic),
        "",
        "## Diffuse-only controls",
        "",
        *table(controls),
        "",
        "Controls: " + summary(controls),
        "",
        "Against Mitsuba's `independent` sampler alone: " + summary(independent(controls)),
        "",
        "Controls, noise-corrected: " + corrected_summary(controls),
        "",
        f"Mitsuba's wall time vs dpm's: off by {100 * np.median(walls):.1f} % (median), "
        f"{100 * max(walls):.1f} % at most." if walls else "",
        "",
        "The reference's own expected RMSE (`noise_rgb`: RMSE(A, B) / 2 of its halves) is part",
        "of both sides' RMSE (in quadrature: E[RMSE²] = own error² + noise²), so a ratio of RMSEs",
        "near it is pulled towards 1. The noise-corrected column is the ratio of the two sides'",
        "own errors, sqrt(RMSE² - noise²), where both exceed the noise; an unbiased estimate of",
        "each MSE, though noisy where the reference's error is heavy-tailed (fireflies).",
        *per_scene,
        "",
        *scaled_copies(records),
        *[f"![{r['scene']}: dpm, Mitsuba 3 best, reference at {r['picture_budget']:g} s]"
          f"({out_folder(r['scene']).name}/{r['scene']}.png)" for r in records],
    ]  # fmt: skip
    return "\n".join(lines) + "\n"


def main() -> None:
    """Run the comparison on the unseen scenes named (default: all) and rebuild the report."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*", help=f"scenes (default: all): {', '.join(UNSEEN)}")
    p.add_argument("--set", choices=("unseen", "examples"), default="unseen",
                   help=f"the scene set (examples: {', '.join(EXAMPLES)})")  # fmt: skip
    p.add_argument("--times", type=float, nargs="+", default=list(TIMES))
    p.add_argument("--batch-spp", type=int, default=BATCH_SPP, help="Mitsuba spp per batch")
    p.add_argument("--samplers", nargs="+", default=list(SAMPLERS), help="Mitsuba's samplers")
    args = p.parse_args()
    known = EXAMPLES if args.set == "examples" else UNSEEN
    unknown = set(args.scenes) - set(known)
    if unknown:
        p.error(f"unknown scene(s) {sorted(unknown)}")
    variant, env = mitsuba_variant(None)
    if "DRJIT_LIBLLVM_PATH" in env:  # the Mitsuba children inherit it
        os.environ["DRJIT_LIBLLVM_PATH"] = env["DRJIT_LIBLLVM_PATH"]
    names = args.scenes or list(known)
    folder = out_folder(names[0])
    folder.mkdir(parents=True, exist_ok=True)
    table = RESULTS / f"{folder.name}.md"
    run = lambda n: run_scene(n, args.times, variant, args.batch_spp, tuple(args.samplers))  # noqa: E731
    save_records(folder, names, run, report, table)


if __name__ == "__main__":
    main()
