"""Photon paths per pass at equal time: which count wins per scene, and what a pass costs.

    python benchmarks/paths_per_pass.py [--set examples|unseen] [SCENE ...]
                                        [--component caustic|full]
                                        [--ppp 1 2 4 8] [--times 2 8] [--seeds 1 2]

`auto` emits AIMED_PHOTONS_PER_PIXEL (2) photon paths per pixel per pass where its paths are
aimed and PHOTONS_PER_PIXEL (4) where not (`auto.paths_per_pixel`): constants, chosen on the
examples. At equal time more paths per pass means fewer passes; which wins depends on what a
pass costs besides its photons (the camera's visible points) and on how the error splits
between the photons' noise and the camera's. A model with error A / (N m) + B / N after
N = T / (c + p m) passes of m paths (c: camera seconds per pass, p: seconds per path) has its
best m at sqrt(c A / (p B)): if A / B were alike across scenes, the best count would follow
sqrt(c / p) per pixel. This measures both sides of that.

For each scene and count m in `--ppp` (paths per pixel per pass; both constants patched),
`auto --no-network` is rendered in this process for each budget in `--times` and seed in
`--seeds` (after one untimed warm-up per scene; the budget counts from the render's start,
so the process's start is left out alike for every m). The caustic component is scored
against the scene's caustic reference (`caustic_references.py`: the examples' aimed ones, or
the unseen set's), the full image (`--component full`) against the examples' equal-time
references (`equal_time.py`, 128 wide) or the unseen scenes' Mitsuba references. Recorded per
run: RMSE, passes, and the stats' seconds of the camera's work (c · N: visible points, and
for the full image its shading, light seen and adaptive samples) and of the photons' tracing
and gathering (p · m · N).
Writes results/paths_per_pass/SET.json and prints a line per run and a summary per scene:
the best m per budget, each m's RMSE over the best's, A / B fitted (`fit_noise`), and the
model's best m, sqrt(c_pixel A / (p B)), with c_pixel (camera seconds per pass per pixel) and
p from the runs at m = 2.
"""

from __future__ import annotations

import argparse
import json
import time
from pathlib import Path

import numpy as np
from caustic_references import CONTROLS, EXAMPLES, SCALED, SETS, load_reference, size
from equal_time import OUT as EXAMPLE_REFERENCES

from common import RESULTS, cpu, geomean
from dpm import load_scene
from dpm.io import read_exr
from dpm.methods import auto
from dpm.metrics import rmse
from dpm.renderer import RenderOptions, render

OUT = RESULTS / "paths_per_pass"
# the stats' stages a pass spends on its camera (the caustic component has the first only)
CAMERA = ("visible_points", "shade", "emitted", "adaptive", "path")
PHOTON = ("photons", "estimate", "gather")  # and on its photon paths (exclusive stages)


def names_of(which: str, given: list[str]) -> list[str]:
    """The set's scenes that have caustic references (given, or all)."""
    if given:
        return given
    if which == "examples":
        return list(EXAMPLES)
    return sorted(q.stem for q in SETS[which][0].glob("*.obj") if q.stem not in CONTROLS + SCALED)


def reference(name: str, which: str, component: str, w: int, h: int) -> tuple[np.ndarray, float]:
    """(H, W, 3) reference of a scene's component and its noise (0 where not known)."""
    if component == "caustic":
        ref, noise, _ = load_reference(name, w, h, which)
        return ref, noise
    if which == "examples":
        return read_exr(EXAMPLE_REFERENCES / f"{name}-{w}x{h}-reference.exr"), 0.0
    return read_exr(SETS[which][1] / f"{name}-{w}x{h}-mitsuba.exr"), 0.0


def run(
    name: str, which: str, component: str, ppp: list[float], times: list[float], seeds: list[int]
) -> list:
    """Rows (dict) of every count, budget and seed on scene `name`."""
    obj, w, h = size(name, which)
    scene = load_scene(obj)
    ref, noise = reference(name, which, component, w, h)
    common = {"component": component, "network": False, "width": w, "height": h,
              "progress": False}  # fmt: skip
    render(scene, RenderOptions(time=1.0, **common))  # warm-up: kernels loaded
    rows = []
    shipped = auto.paths_per_pixel(scene)  # what `auto` takes here
    saved = auto.PHOTONS_PER_PIXEL, auto.AIMED_PHOTONS_PER_PIXEL
    try:
        for budget in times:
            for seed in seeds:
                order = ppp if seed % 2 else ppp[::-1]  # drift falls on both ends alike
                for m in order:
                    auto.PHOTONS_PER_PIXEL = auto.AIMED_PHOTONS_PER_PIXEL = m
                    options = RenderOptions(time=budget, seed=seed, **common)
                    begun = time.monotonic()
                    result = render(scene, options, started=begun)
                    wall = time.monotonic() - begun
                    s, passes = result.stats["seconds"], int(result.stats["passes"])
                    row = {"scene": name, "component": component, "ppp": m,
                           "budget": budget, "seed": seed, "shipped": shipped,
                           "rmse": rmse(result.image, ref), "passes": passes,
                           "camera_s": sum(s.get(k, 0.0) for k in CAMERA),
                           "photon_s": sum(s.get(k, 0.0) for k in PHOTON),
                           "pixels": w * h, "reference_noise": noise, "wall_s": wall,
                           "seconds": s}  # fmt: skip
                    rows.append(row)
                    print(f"{name} {budget:g} s seed {seed} ppp {m:g}: {passes} passes, "
                          f"RMSE {row['rmse']:.5f}, camera {row['camera_s']:.2f} s, "
                          f"photons {row['photon_s']:.2f} s", flush=True)  # fmt: skip
    finally:
        auto.PHOTONS_PER_PIXEL, auto.AIMED_PHOTONS_PER_PIXEL = saved
    return rows


def fit_noise(rows: list[dict]) -> tuple[float, float]:
    """(A, B) of MSE = A / (N m) + B / N fitted by least squares to rows of one scene and
    budget (N: the run's passes, m: its paths per pixel per pass): A the photons' noise
    (per path per pixel), B the camera's (per pass); the blur, which shrinks with N, is left
    in both."""
    design = np.array([[1 / (x["passes"] * x["ppp"]), 1 / x["passes"]] for x in rows])
    mse = np.array([x["rmse"] ** 2 for x in rows])
    (a, b), *_ = np.linalg.lstsq(design, mse, rcond=None)
    return float(a), float(b)


def mean_errors(rows: list[dict]) -> dict[tuple[str, float], dict[float, float]]:
    """{(scene, budget): {count: RMSE, the mean over the seeds}}, in the rows' order."""
    err: dict = {}
    for x in rows:
        err.setdefault((x["scene"], x["budget"]), {}).setdefault(x["ppp"], []).append(x["rmse"])
    return {key: {m: float(np.mean(e)) for m, e in by_m.items()} for key, by_m in err.items()}


def oracle_ratios(rows: list[dict]) -> tuple[dict[float, float], float, float]:
    """Each count's RMSE over the best count's of its scene and budget (mean over seeds), as a
    geometric mean over the (scene, budget) pairs, and the same for the count `auto` takes
    (the row's "shipped", where it is one of the counts run) with its worst ratio."""
    ratios: dict[float, list[float]] = {}
    shipped = {x["scene"]: x.get("shipped") for x in rows}
    own = []
    for (name, _), mean in mean_errors(rows).items():
        best = min(mean.values())
        for m, e in mean.items():
            ratios.setdefault(m, []).append(e / best)
        if shipped[name] in mean:
            own.append(mean[shipped[name]] / best)
    gm = {m: geomean(r) for m, r in sorted(ratios.items())}
    return gm, (geomean(own) if own else float("nan")), (max(own) if own else float("nan"))


def summary(rows: list[dict]) -> list[str]:
    """Per scene: the best count per budget (mean RMSE over seeds), each count's RMSE over
    the best's, and sqrt(camera seconds per pass per pixel / seconds per path); then each
    count's and `auto`'s own count's RMSE over the per-scene best (`oracle_ratios`)."""
    gm, own, worst = oracle_ratios(rows)
    lines = ["over the best count per scene and budget: "
             + " ".join(f"{m:g}: {r:.3f}" for m, r in gm.items())
             + f"; auto's count {own:.3f} (worst {worst:.2f})"]  # fmt: skip
    errors = mean_errors(rows)
    for name in dict.fromkeys(x["scene"] for x in rows):
        mine = [x for x in rows if x["scene"] == name]
        at2 = [x for x in mine if x["ppp"] == 2] or mine
        c = np.mean([x["camera_s"] / x["passes"] / x["pixels"] for x in at2])
        p = np.mean([x["photon_s"] / (x["passes"] * x["ppp"] * x["pixels"]) for x in at2])
        parts = []
        for budget in dict.fromkeys(x["budget"] for x in mine):
            mean = errors[name, budget]
            best = min(mean, key=mean.get)
            ratios = " ".join(f"{m:g}:{mean[m] / mean[best]:.2f}" for m in sorted(mean))
            a, b = fit_noise([x for x in mine if x["budget"] == budget])
            model = np.sqrt(c * a / (p * b)) if a > 0 and b > 0 else float("nan")
            parts.append(f"{budget:g} s best {best:g} ({ratios}), A/B {a / max(b, 1e-30):.3g}, "
                         f"model's best {model:.2f}")  # fmt: skip
        lines.append(f"{name}: sqrt(c/p) {np.sqrt(c / p):.2f}; " + "; ".join(parts))
    return lines


def write_report(record: dict, path: Path) -> None:
    """Print the record's summary and write it as markdown at `path`."""
    lines = summary(record["rows"])
    print("\n".join(lines))
    head = (f"# Photon paths per pixel per pass at equal time: {record['set']}, "
            f"{record.get('component', 'caustic')} component\n\n"
            f"Made by `python benchmarks/paths_per_pass.py --set {record['set']} --component "
            f"{record.get('component', 'caustic')}` on {record['cpu']}, {record['date']} "
            "(see its docstring). Ratios: RMSE over the best count's of the scene and budget, "
            "mean over the seeds.\n\n")  # fmt: skip
    path.write_text(head + "\n".join(f"- {x}" for x in lines) + "\n")


def main() -> None:
    """Run the study on a set's scenes and write the record."""
    a = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    a.add_argument("scenes", nargs="*")
    a.add_argument("--set", choices=sorted(SETS), default="examples")
    a.add_argument("--component", choices=("caustic", "full"), default="caustic")
    a.add_argument("--ppp", type=float, nargs="+", default=[1, 2, 4, 8])
    a.add_argument("--times", type=float, nargs="+", default=[2, 8])
    a.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    a.add_argument("--report", action="store_true", help="print the summary of the record")
    args = a.parse_args()
    path = OUT / f"{args.set}-{args.component}.json"
    if args.report:
        record = json.loads(path.read_text())
        write_report(record, path.with_suffix(".md"))
        return
    rows = []
    for name in names_of(args.set, args.scenes):
        rows += run(name, args.set, args.component, args.ppp, args.times, args.seeds)
    OUT.mkdir(parents=True, exist_ok=True)
    record = {"cpu": cpu(), "date": time.strftime("%Y-%m-%d"), "set": args.set,
              "component": args.component, "rows": rows}  # fmt: skip
    path.write_text(json.dumps(record, indent=1))
    write_report(record, path.with_suffix(".md"))


if __name__ == "__main__":
    main()
