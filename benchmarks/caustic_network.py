"""`auto`'s learned caustic filter against `auto --no-network`, on the unseen scenes' caustics.

    python benchmarks/caustic_network.py [SCENE ...] [--passes 1 2 4 ...] [--times 2 4 8 16]
                                         [--ladder N ...] [--ladder-methods M ...]
                                         [--seeds 1 2] [--report]

On each caustic scene of the unseen set (`benchmarks/scenes/make_unseen.py`, the controls
left out), at the size of its caustic reference (`caustic_references.py`: SPPM at 2 × 512
to 2 × 6400 passes, 4 times the longest render's; a uniformly scaled copy is scored against
its scale-1 twin's, as `equal_time_unseen.py` does), the caustic component
(`--component caustic`) is rendered:

- at equal passes (`--passes`): in this process, the same seed with and without the network
  (the same samples: the ratio is the filter's effect alone); the report says on how many
  scenes the network's error (mean over the seeds) falls at every step of the ladder;
- at equal whole-process time (`--times`): `dpm-render --time T` in fresh processes, with and
  without `--no-network`, alternating which runs first budget after budget (the machine's load
  falls on both); the network's seconds and share of the run, and the passes, from the stats.

- the other caustic methods (`--ladder`): `dpm-render --method M --component caustic
  --photons N` in fresh processes for M in LADDER_METHODS at their defaults otherwise (16
  camera samples per pixel; one visible point per pixel leaves the camera's own noise
  through glass, 4x the error of sppm on the tinted glass), for N in `--ladder` photon
  paths: whole-process seconds and RMSE, one seed (the first of `--seeds`).

RMSE (`dpm.metrics.rmse`) against the reference, the mean over `--seeds`; ratio = with the
network / without. The reference's own noise (its halves' RMSE / 2) is recorded beside it.
Writes results/caustic_network/unseen.json, results/caustic_network.md and
results/caustic_network/rmse_vs_time.png (per scene, caustic RMSE against whole-process
seconds: auto with and without the network, the best classic method at its defaults on that
scene (chosen by its RMSE over the ladder: a choice no user can make, so it flatters the
classics), DPM and nppm).
"""

from __future__ import annotations

import argparse
import datetime
import itertools
import json
import sys
import tempfile
from pathlib import Path

import numpy as np
from caustic_references import DEFAULT_PASSES, load_reference
from equal_time import dpm_run, wall

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import CONTROLS, UNSEEN, unit_scale, unseen_scenes  # noqa: E402

from common import RESULTS, cpu, geomean, markdown_table  # noqa: E402
from dpm import load_scene  # noqa: E402
from dpm.io import read_exr  # noqa: E402
from dpm.methods.auto import paths_per_pixel  # noqa: E402
from dpm.metrics import rmse  # noqa: E402
from dpm.options import RenderOptions  # noqa: E402
from dpm.renderer import render  # noqa: E402

OUT = RESULTS / "caustic_network"
TABLE = RESULTS / "caustic_network.md"
MAX_WIDTH = 256  # as equal_time_unseen: the references' width
CLASSICS = ("ppm", "appm", "cppm", "sppm")
LADDER_METHODS = (*CLASSICS, "dpm", "nppm")
LADDER = (175_000, 700_000, 2_800_000)  # photon paths: M/4, M, 4·M


def scene_size(name: str) -> tuple[Path, int, int]:
    """(OBJ path, W, H) of unseen scene `name` at its reference's size."""
    path = {p.stem: p for p in unseen_scenes()}[name]
    c = load_scene(path).camera
    width = min(c.width, MAX_WIDTH)
    return path, width, max(1, width * c.height // c.width)


def equal_passes(name: str, passes: list[int], seeds: list[int]) -> list[dict]:
    """Rows of RMSE with and without the network at each pass count."""
    path, w, h = scene_size(name)
    ref, noise, ref_passes = load_reference(unit_scale(name), w, h)
    scene = load_scene(path)
    rows = []
    for p in passes:
        errors = {True: [], False: []}
        for seed in seeds:
            for network in (True, False):
                paths = round(p * paths_per_pixel(scene) * w * h)  # auto's own paths per pass
                options = RenderOptions(component="caustic", spp=p, photons=paths, width=w,
                                        height=h, seed=seed, network=network,
                                        progress=False)  # fmt: skip
                errors[network].append(rmse(render(scene, options).image, ref))
        row = {"scene": name, "passes": p, "network": float(np.mean(errors[True])),
               "plain": float(np.mean(errors[False])), "reference_noise": noise,
               "reference_passes": ref_passes}  # fmt: skip
        rows.append(row)
        print(f"{name} {p} passes: network {row['network']:.5f} plain {row['plain']:.5f} "
              f"ratio {row['network'] / row['plain']:.3f}", flush=True)  # fmt: skip
    return rows


def network_seconds(stats: dict) -> float:
    """The seconds a render's stats give its caustic filter (loading, warming, running)."""
    return float(stats["seconds"].get("network", 0.0))


def equal_time(name: str, times: list[float], seeds: list[int]) -> list[dict]:
    """Rows of whole-process RMSE, seconds, passes and the network's share at each budget."""
    path, w, h = scene_size(name)
    ref, noise, ref_passes = load_reference(unit_scale(name), w, h)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        folder = Path(tmp)
        caustic = ("--component", "caustic")
        for extra in ((), ("--no-network",)):  # warm Numba's cache, untimed
            dpm_run(path, w, h, max(times), 0, folder, caustic + extra)
        for i, budget in enumerate(times):
            got = {True: [], False: []}
            for seed in seeds:
                order = (True, False) if (i + seed) % 2 == 0 else (False, True)
                for network in order:
                    extra = caustic + (() if network else ("--no-network",))
                    image, seconds, stats = dpm_run(path, w, h, budget, seed, folder, extra)
                    got[network].append((rmse(image, ref), seconds, stats))
            row = {
                "scene": name,
                "budget": budget,
                "reference_noise": noise,
                "reference_passes": ref_passes,
            }
            for network, key in ((True, "network"), (False, "plain")):
                row[key] = float(np.mean([e for e, _, _ in got[network]]))
                row[f"{key}_s"] = float(np.mean([s for _, s, _ in got[network]]))
                row[f"{key}_passes"] = float(np.mean([st["passes"] for *_, st in got[network]]))
            runs = got[True]
            row["network_used"] = all(st["plan"]["network"] for *_, st in runs)
            row["network_share"] = max(network_seconds(st) / s for _, s, st in runs)
            rows.append(row)
            print(f"{name} {budget:g} s: network {row['network']:.5f} ({row['network_passes']:.0f}"
                  f" passes, share {row['network_share']:.1%}) plain {row['plain']:.5f} "
                  f"({row['plain_passes']:.0f}) ratio {row['network'] / row['plain']:.3f}",
                  flush=True)  # fmt: skip
    return rows


def ladder(
    name: str, photons: list[int], seed: int, methods: tuple[str, ...] = LADDER_METHODS
) -> list[dict]:
    """Rows of whole-process seconds and RMSE of each of `methods` at each photon count."""
    path, w, h = scene_size(name)
    ref, noise, ref_passes = load_reference(unit_scale(name), w, h)
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        out = Path(tmp) / "out.exr"

        def command(method: str, n: int, s: int) -> list[str]:
            return ["dpm-render", str(path), "--method", method, "--component", "caustic",
                    "--photons", str(n), "--width", str(w), "--height", str(h), "--seed",
                    str(s), "-o", str(out), "--quiet"]  # fmt: skip

        for method in methods:  # warm Numba's (and JAX's) caches, untimed
            wall(command(method, min(photons), 0))
        for n in photons:
            for method in methods:
                seconds = wall(command(method, n, seed))
                row = {"scene": name, "method": method, "photons": n, "seed": seed,
                       "seconds": seconds, "rmse": rmse(read_exr(out), ref),
                       "reference_noise": noise, "reference_passes": ref_passes}  # fmt: skip
                rows.append(row)
                print(f"{name} {method} {n:,} photon paths: {row['rmse']:.5f} in "
                      f"{seconds:.2f} s", flush=True)  # fmt: skip
    return rows


def best_classic(rows: list[dict], name: str) -> str | None:
    """The classic method with the least geometric-mean RMSE over the photon counts that every
    classic ran at on scene `name` (None: no such count)."""
    mine = [x for x in rows if x["scene"] == name and x["method"] in CLASSICS]
    shared = set.intersection(*({x["photons"] for x in mine if x["method"] == m} for m in CLASSICS))
    if not shared:
        return None
    return min(CLASSICS, key=lambda m: geomean(
        [x["rmse"] for x in mine if x["method"] == m and x["photons"] in shared]))  # fmt: skip


def corrected(row: dict) -> float:
    """The ratio of the two sides' own errors, the reference's noise taken out of both
    (`equal_time_unseen.own_error`); NaN where either is below the noise."""
    n = row["reference_noise"]
    a, b = row["network"] ** 2 - n**2, row["plain"] ** 2 - n**2
    return float(np.sqrt(a / b)) if a > 0 and b > 0 else float("nan")


def report(record: dict) -> str:
    """The Markdown report of a run."""
    lines = [
        "# `auto`'s learned caustic filter against `auto --no-network` (caustic component)",
        "",
        "Made by `python benchmarks/caustic_network.py` (see its docstring) on "
        f"{record['cpu']}, {record['date']}. RMSE against the SPPM",
        "caustic references of `benchmarks/caustic_references.py`; ratio = with / without the",
        "network (below 1: the network wins). Unseen scenes: no constant or weight was chosen",
        "on them.",
        "",
    ]
    passes = {x["scene"]: reference_passes(x) for x in record["passes"] + record["times"]}
    if passes:
        lines += ["Passes per half of each scene's reference (of its equal-time rows): "
                  + ", ".join(f"{n} {p}" for n, p in passes.items()) + ".", ""]  # fmt: skip
    if record["passes"]:
        lines += [f"## Equal passes (same samples; seeds {record.get('passes_seeds')})", ""]
        head = ["scene", "passes", "network", "no network", "ratio", "reference noise"]
        rows = [[x["scene"], str(x["passes"]), f"{x['network']:.5f}", f"{x['plain']:.5f}",
                 f"{x['network'] / x['plain']:.3f}", f"{x['reference_noise']:.5f}"]
                for x in record["passes"]]  # fmt: skip
        lines += [*markdown_table(head, rows), ""]
        for p in sorted({x["passes"] for x in record["passes"]}):
            q = [x["network"] / x["plain"] for x in record["passes"] if x["passes"] == p]
            lines.append(f"- {p} passes: geometric mean {geomean(q):.3f}, range "
                         f"{min(q):.3f}-{max(q):.3f} over {len(q)} scenes")  # fmt: skip
        # consistency: the network's error, mean over the seeds, at each step of the ladder
        ladders = {}
        for x in record["passes"]:
            ladders.setdefault(x["scene"], []).append((x["passes"], x["network"]))
        rises, rising = [], set()
        for name, steps in ladders.items():
            steps.sort()
            for a, b in itertools.pairwise(steps):
                if b[1] >= a[1]:
                    rises.append(f"{name} {a[0]} → {b[0]} passes ({a[1]:.4f} → {b[1]:.4f})")
                    rising.add(name)
        falls = len(ladders) - len(rising)
        lines.append(f"- the network's error falls at every step on {falls} of {len(ladders)} "
                     "scenes" + (f"; it rises on {'; '.join(rises)}" if rises else ""))  # fmt: skip
        lines.append("")
    if record["times"]:
        lines += [f"## Equal whole-process time (seeds {record.get('times_seeds')})", ""]
        head = ["scene", "budget s", "network", "passes", "share", "no network", "passes",
                "ratio", "noise out"]  # fmt: skip
        rows = [[x["scene"], f"{x['budget']:g}", f"{x['network']:.5f}",
                 f"{x['network_passes']:.0f}", f"{x['network_share']:.1%}"
                 + ("" if x["network_used"] else " (off)"), f"{x['plain']:.5f}",
                 f"{x['plain_passes']:.0f}", f"{x['network'] / x['plain']:.3f}",
                 f"{corrected(x):.3f}"]
                for x in record["times"]]  # fmt: skip
        lines += [*markdown_table(head, rows), ""]
        q = [x["network"] / x["plain"] for x in record["times"]]
        worst = max(record["times"], key=lambda x: x["network"] / x["plain"])
        lines.append(f"- all budgets: geometric mean {geomean(q):.3f}, worst {max(q):.3f} "
                     f"({worst['scene']} at {worst['budget']:g} s), "
                     f"{sum(v > 1.05 for v in q)} rows above 1.05")  # fmt: skip
        for b in sorted({x["budget"] for x in record["times"]}):
            qb = [x["network"] / x["plain"] for x in record["times"] if x["budget"] == b]
            lines.append(f"- {b:g} s: geometric mean {geomean(qb):.3f}, range "
                         f"{min(qb):.3f}-{max(qb):.3f}")  # fmt: skip
        told = [c for c in map(corrected, record["times"]) if np.isfinite(c)]
        lines.append(f"- the same with the reference's noise taken out of both errors: "
                     f"geometric mean {geomean(told):.3f} over {len(told)} rows, worst "
                     f"{max(told):.3f}")  # fmt: skip
        share = max(x["network_share"] for x in record["times"])
        lines.append(f"- the network's largest share of a run: {share:.1%}")
        lines.append("")
    if record.get("ladder"):
        lines += ladder_report(record)
    return "\n".join(lines)


def ladder_report(record: dict) -> list[str]:
    """The ladder's table: per scene and photon count, each method's RMSE and seconds; then
    auto at each budget against the scene's best classic method, DPM and nppm, each at the
    least RMSE of its runs that took no more time than auto."""
    rows, times = record["ladder"], ladder_times(record)
    seeds = sorted({x.get("seed", record.get("ladder_seed")) for x in rows}, key=str)
    lines = [f"## The other caustic methods at their defaults (seed {', '.join(map(str, seeds))})",
             "", "Whole-process seconds and RMSE at each method's defaults (16 camera samples "
             "per pixel); `best` is the classic", "method (ppm, appm, cppm, sppm) with the least "
             "RMSE over the scene's ladder, chosen against the reference (no user can).",
             ""]  # fmt: skip
    refs = ladder_references(rows)
    older = sorted(
        {n for n, p in refs.items() if times_reference_passes(record, n) not in (None, p)}
    )
    if older:
        lines += [
            "Scored against older references than the tables above (passes per half: "
            + ", ".join(f"{n} {refs[n]}" for n in older)
            + "); each scene's ladder is compared",
            "below and in the chart only with `auto` rows scored against its own references "
            "(from the ladder's run where the tables' are newer).",
            "",
        ]
    mixed = sorted({x["scene"] for x in rows} - set(refs))
    if mixed:
        lines += [f"Left out of the comparisons (rows scored against two references): "
                  f"{', '.join(mixed)}.", ""]  # fmt: skip
    head = ["scene", "photon paths", *LADDER_METHODS, "best"]
    table = []
    for name in dict.fromkeys(x["scene"] for x in rows):
        best = best_classic(rows, name)
        for n in sorted({x["photons"] for x in rows if x["scene"] == name}):
            got = {x["method"]: x for x in rows if x["scene"] == name and x["photons"] == n}
            table.append([name, f"{n:,}",
                          *[f"{got[m]['rmse']:.4f} ({got[m]['seconds']:.1f} s)" if m in got
                            else "–" for m in LADDER_METHODS], best or "–"])  # fmt: skip
    lines += [*markdown_table(head, table), ""]
    # auto against each method at no more whole-process time: the method's least RMSE among
    # its runs that took at most auto's seconds (none: that method cannot be that fast, and
    # the row is counted apart)
    for label, key in (("auto", "network"), ("auto --no-network", "plain")):
        for m in ("best classic", "dpm", "nppm"):
            q = []
            for x in times:
                method = best_classic(rows, x["scene"]) if m == "best classic" else m
                runs = [
                    r["rmse"]
                    for r in rows
                    if r["scene"] == x["scene"]
                    and r["method"] == method
                    and r["seconds"] <= x[f"{key}_s"]
                ]
                if runs:
                    q.append(x[key] / min(runs))
            if q:
                lines.append(f"- {label} / {m} at no more time: geometric mean {geomean(q):.3f}"
                             f" over {len(q)} rows, worst {max(q):.3f}, "
                             f"{sum(v > 1.0 for v in q)} above 1.0; in {len(times) - len(q)} "
                             f"rows no run of it was as fast as {label}")  # fmt: skip
    lines.append("")
    return lines


def reference_passes(row: dict) -> int:
    """The passes of the reference a row was scored against (rows from before the field: the
    references' first length, DEFAULT_PASSES)."""
    return int(row.get("reference_passes", DEFAULT_PASSES))


def times_reference_passes(record: dict, name: str) -> int | None:
    """The reference passes of scene `name`'s current equal-time rows (None: it has none)."""
    got = [reference_passes(x) for x in record["times"] if x["scene"] == name]
    return got[0] if got else None


def ladder_references(rows: list[dict]) -> dict[str, int]:
    """Each scene's reference passes in the ladder's rows; a scene whose rows were scored
    against more than one reference is left out (its methods cannot be compared)."""
    seen: dict[str, set[int]] = {}
    for x in rows:
        seen.setdefault(x["scene"], set()).add(reference_passes(x))
    return {name: next(iter(p)) for name, p in seen.items() if len(p) == 1}


def matching_times(ladder: list[dict], *sources: list[dict]) -> list[dict]:
    """Per scene of the ladder, the `auto` rows scored against that scene's ladder reference:
    from the first source that has them (no scene's rows from two sources)."""
    refs = ladder_references(ladder)
    out = []
    for name, passes in refs.items():
        for rows in sources:
            got = [x for x in rows if x["scene"] == name and reference_passes(x) == passes]
            if got:
                out += got
                break
    return out


def ladder_times(record: dict) -> list[dict]:
    """The `auto` rows the ladder is compared with: the current equal-time rows where they
    were scored against the ladder's references, else those kept from the ladder's own run."""
    return matching_times(record["ladder"], record["times"], record.get("ladder_times", []))


def chart(record: dict, path: Path) -> None:
    """Per scene, caustic RMSE against whole-process seconds, with and without the network."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    times = ladder_times(record) if record.get("ladder") else record["times"]
    names = list(dict.fromkeys(x["scene"] for x in times))
    if not names:
        return
    cols = 4
    rows = -(-len(names) // cols)
    fig, axes = plt.subplots(rows, cols, figsize=(3.2 * cols, 2.6 * rows), squeeze=False)
    for ax, name in zip(axes.flat, names, strict=False):
        xs = [x for x in times if x["scene"] == name]
        for key, label in (("network", "auto"), ("plain", "auto --no-network")):
            ax.loglog([x[f"{key}_s"] for x in xs], [x[key] for x in xs], "o-", label=label)
        ladder_rows = record.get("ladder", [])
        if any(x["scene"] == name for x in ladder_rows):
            best = best_classic(ladder_rows, name)
            for method, label, style in ((best, "best classic", "s--"), ("dpm", "DPM", "^:"),
                                         ("nppm", "nppm", "v:")):  # fmt: skip
                ys = sorted((x["seconds"], x["rmse"]) for x in ladder_rows
                            if x["scene"] == name and x["method"] == method)  # fmt: skip
                if ys:
                    ax.loglog(*zip(*ys, strict=True), style, ms=3, label=label)
            ax.set_title(f"{name} (best classic: {best or '–'})", fontsize=8)
        else:
            ax.set_title(name, fontsize=9)
        ax.axhline(xs[0]["reference_noise"], color="grey", lw=0.8, ls=":")
        ax.xaxis.set_minor_formatter(matplotlib.ticker.NullFormatter())
        ticks = [1, 2, 4, 8, 16, 32, 64, 128, 256]
        ax.set_xticks(ticks, [str(t) for t in ticks])
        ax.tick_params(labelsize=7)
    for ax in list(axes.flat)[len(names) :]:
        ax.axis("off")
    axes[0, 0].legend(fontsize=7)
    fig.supxlabel("whole-process seconds")
    fig.supylabel("caustic RMSE (grey dotted: the reference's noise)")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def main() -> None:
    """Run the comparisons and write the record and the table."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--passes", type=int, nargs="*", default=[1, 2, 4, 8, 16, 32])
    p.add_argument("--times", type=float, nargs="*", default=[2, 4, 8, 16])
    p.add_argument(
        "--ladder",
        type=int,
        nargs="*",
        default=list(LADDER),
        help="photon paths of the other methods' runs (none: keep the saved rows)",
    )
    p.add_argument(
        "--ladder-methods",
        nargs="+",
        default=list(LADDER_METHODS),
        choices=LADDER_METHODS,
        help="rerun these; the saved rows of others stay",
    )
    p.add_argument("--seeds", type=int, nargs="+", default=[1, 2])
    p.add_argument("--report", action="store_true", help="rebuild the table from the record")
    a = p.parse_args()
    if a.report:
        record = json.loads((OUT / "unseen.json").read_text())
        TABLE.write_text(report(record))
        chart(record, OUT / "rmse_vs_time.png")
        return
    names = a.scenes or [n for n in UNSEEN if n not in CONTROLS]
    saved = OUT / "unseen.json"
    old = json.loads(saved.read_text()) if saved.exists() else {"passes": [], "times": []}
    record = {"cpu": cpu(), "date": str(datetime.date.today()), "seeds": a.seeds,
              "passes": [], "times": [], "ladder": []}  # fmt: skip
    if a.ladder:
        record["ladder_seed"] = a.seeds[0]
        rerun = {(n, m) for n in names for m in a.ladder_methods}
        record["ladder"] = [
            x for x in old.get("ladder", []) if (x["scene"], x["method"]) not in rerun
        ]
        for name in names:
            record["ladder"] += ladder(name, a.ladder, a.seeds[0], tuple(a.ladder_methods))
    else:
        record["ladder"], record["ladder_seed"] = old.get("ladder", []), old.get("ladder_seed")
    for part, run in (("passes", equal_passes), ("times", equal_time)):
        values = getattr(a, part)
        if not values:  # not rerun: the saved rows stay
            record[part] = old[part]
            record[f"{part}_seeds"] = old.get(f"{part}_seeds", old.get("seeds"))
            continue
        if old.get(f"{part}_seeds", old.get("seeds")) == a.seeds:  # other scenes' rows stay
            record[part] = [x for x in old[part] if x["scene"] not in names]
        record[f"{part}_seeds"] = a.seeds
        for name in names:
            record[part] += run(name, values, a.seeds)
        order = {n: i for i, n in enumerate(UNSEEN)}
        record[part].sort(key=lambda x: order.get(x["scene"], len(order)))
    # the auto rows of earlier runs scored against the (kept) ladder's references, kept with it
    record["ladder_times"] = matching_times(
        record["ladder"], old.get("ladder_times", []), old.get("times", [])
    )
    OUT.mkdir(parents=True, exist_ok=True)
    (OUT / "unseen.json").write_text(json.dumps(record, indent=1))
    TABLE.write_text(report(record))
    if record["times"]:
        chart(record, OUT / "rmse_vs_time.png")
    print(report(record))


if __name__ == "__main__":
    main()
