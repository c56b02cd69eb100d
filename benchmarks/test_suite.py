"""The benchmark suite: accuracy against time, the paper's tables, stability, temporal flicker.

`pytest benchmarks/` (full, hours on 2 cores) writes benchmarks/report/;
`pytest benchmarks/ --quick` (minutes: the ring only, short ladder, 1 timing round) writes
benchmarks/report-quick/. The tests assert what must hold for every method (`checks`: finite,
non-negative answers, black off the surfaces; K > photons refused, P = K accepted); how well
each method does is a finding in the report, never a failed run.
"""

from __future__ import annotations

from dataclasses import asdict, dataclass
from pathlib import Path

import numpy as np
import pytest
import stability
import temporal
from accuracy import growth_flags, pareto, plot_combined, plot_errors, plot_scene, run_ladder
from cases import Case, load_case, reference_scenes, tuning
from checks import ANSWER, REFUSAL, Check, assert_must_hold, summary
from report import FULL, QUICK, Report
from tables import table1, timing_table, untabled_columns

from common import M, markdown_table
from dpm.methods.base import PASSES


@dataclass(frozen=True)
class Settings:
    """How much the suite runs."""

    quick: bool
    scenes: tuple[str, ...]  # with a committed reference
    budgets: tuple[int, ...]  # the accuracy ladder, emitted paths
    rounds: int  # timed calls per measurement (median)
    table_budgets: tuple[int, ...]  # Table 1's columns: M, 10·M, 100·M
    ratios: tuple[float, ...]  # P / K of the K-close study
    temporal_scenes: tuple[str, ...]
    frames: int
    width: int  # temporal frames' width, pixels
    degrees: float  # the orbit's total angle


def settings(quick: bool) -> Settings:
    """The quick (CI) or full settings."""
    if quick:
        return Settings(
            True, ("ring",), (M // 64, M // 8, M), 1, (M,), (1.0, 1.5, 4.0), ("ring",), 5, 32, 2.0
        )
    return Settings(
        False,
        tuple(reference_scenes()),
        (M // 64, M // 16, M // 4, M, 4 * M),
        3,
        (M, 10 * M, 100 * M),
        (1.0, 1.1, 1.5, 2.0, 4.0, 10.0),
        ("ring", "glass_egg"),
        30,
        64,
        6.0,
    )


ORDER = [
    "Where DPM loses",
    "Accuracy against time",
    "Table 1: caustic RMSE at M, 10·M and 100·M",
    "Timings",
    "Reference noise",
    "Stability: sparse photons",
    "Stability: K close to the photon count",
    "Stability: thin caustics",
    "Stability: neighbourhoods that cross surfaces",
    "Temporal stability",
]


class Suite:
    """The session's settings, report and cached per-scene work."""

    def __init__(self, s: Settings) -> None:
        self.s = s
        self.report = Report(QUICK if s.quick else FULL, s.quick)
        self.report.start()
        self._cases: dict[str, Case] = {}
        self._ladder: dict[str, tuple[list[dict], dict]] = {}

    def case(self, name: str) -> Case:
        """The Case of a scene, loaded once."""
        if name not in self._cases:
            self._cases[name] = load_case(name)
        return self._cases[name]

    def ladder(self, name: str) -> tuple[list[dict], dict]:
        """The accuracy ladder's rows and estimates of a scene, run once."""
        if name not in self._ladder:
            self._ladder[name] = run_ladder(self.case(name), list(self.s.budgets), self.s.rounds)
        return self._ladder[name]

    def rows(self) -> list[dict]:
        """Every scene's ladder rows."""
        return [r for name in self.s.scenes for r in self.ladder(name)[0]]

    def at_m(self, name: str) -> dict[str, np.ndarray]:
        """Each method's estimate at M (the ladder's rung) for a scene."""
        _, estimates = self.ladder(name)
        return {m: e for (m, b), e in estimates.items() if b == M}


@pytest.fixture(scope="module")
def suite(request) -> Suite:
    """One Suite for the module; the report is written when the module ends."""
    s = Suite(settings(request.config.getoption("--quick")))
    yield s
    s.report.write(ORDER)
    print(f"\nreport: {s.report.folder / 'README.md'}")


def add_study(
    suite: Suite,
    title: str,
    intro: list[str],
    chart: Path | None,
    rows: list,
    checks: list[Check],
    properties: str,
) -> None:
    """A stability study's report section (intro, chart, the tally of its must-hold
    `properties`, findings), then assert its must-hold checks: the section is in the report
    even when one fails."""
    picture = [f"![{chart.stem}]({chart.name})", ""] if chart else []
    data = {"rows": rows, "checks": [asdict(c) for c in checks]}
    suite.report.add(title, [*intro, "", *picture, *summary(checks, properties)], data)
    assert_must_hold(checks)


def test_accuracy_against_time(suite: Suite) -> None:
    rows = suite.rows()
    wrong = [f"{r['scene']} {r['method']} at {r['paths']:,}: {'; '.join(r['problems'])}"
             for r in rows if r["problems"]]  # fmt: skip
    assert not wrong, "\n".join(wrong)
    tuned, untuned = tuning([suite.case(name) for name in suite.s.scenes])
    lines = [
        f"Caustic RMSE against seconds (trace + gather + estimate; median of {suite.s.rounds} "
        "timed calls after a warm-up call) over emitted-path budgets "
        + ", ".join(f"{b:,}" for b in suite.s.budgets)
        + f" (M = {M:,}). {', '.join(tuned) or 'No method'} keep the parameters the estimator "
        "table tuned at M (same initial radius and number of passes at every budget); "
        f"the untuned ({', '.join(untuned) or 'none'}) start from the default radius "
        f"(0.001 × the scene's diagonal) with {PASSES} passes at every budget. SPPM is left "
        "out: it averages over each pixel's "
        "footprint while the reference is at one visible point per pixel.",
        "",
        "![all scenes](accuracy.png)",
        "",
    ]
    for name in suite.s.scenes:
        mine = [r for r in rows if r["scene"] == name]
        plot_scene(mine, suite.report.chart(f"accuracy-{name}.png"))
        plot_errors(suite.case(name), suite.at_m(name), suite.report.chart(f"errors-{name}.png"))
        front = pareto(mine)
        lines += [
            f"### {name}",
            "",
            f"![{name}](accuracy-{name}.png)",
            "",
            "Pareto front: "
            + ", ".join(
                f"{r['method']} at {r['paths']:,} paths ({r['total_s']:.2f} s, {r['rmse']:.4f})"
                for r in front
            ),
            "",
            f"False-colour error at M: ![errors](errors-{name}.png)",
            "",
        ]
        head = ["method", *[f"{b:,}" for b in suite.s.budgets]]
        body = []
        for method in dict.fromkeys(r["method"] for r in mine):
            cells = []
            for b in suite.s.budgets:
                r = next(r for r in mine if r["method"] == method and r["paths"] == b)
                cells.append(
                    "–" if r["rmse"] is None else f"{r['rmse']:.4f} / {r['total_s']:.2f} s"
                )
            body.append([method, *cells])
        lines += ["RMSE / seconds per budget (emitted paths):", "", *markdown_table(head, body), ""]
    plot_combined(rows, suite.report.chart("accuracy.png"))
    flags = growth_flags(rows)
    lines += ["Errors that grew when photons were added (> 5 %):", ""]
    lines += [f"- {f}" for f in flags] or ["- none"]
    suite.report.add("Accuracy against time", lines, rows)
    losses(suite, rows)


def losses(suite: Suite, rows: list[dict]) -> None:
    """The 'Where DPM loses' section: each DPM model against the best other method per budget."""
    lines = [
        "Each DPM model against the best non-DPM method at the same budget (accuracy ladder; "
        "ratio = DPM RMSE ÷ best other RMSE, above 1 is a loss):",
        "",
    ]
    body = []
    for r in rows:
        if not r["method"].startswith("DPM") or r["rmse"] is None:
            continue
        others = [
            o
            for o in rows
            if o["scene"] == r["scene"]
            and o["paths"] == r["paths"]
            and not o["method"].startswith("DPM")
            and o["rmse"] is not None
        ]
        best = min(others, key=lambda o: o["rmse"])
        ratio = r["rmse"] / best["rmse"]
        body.append(
            [
                r["scene"],
                r["method"],
                f"{r['paths']:,}",
                f"{r['rmse']:.4f}",
                f"{best['method']} {best['rmse']:.4f}",
                f"{ratio:.2f}",
                "**loses**" if ratio > 1 else "wins",
            ]
        )
    lost = sum(b[-1] == "**loses**" for b in body)
    lines += [f"DPM loses {lost} of {len(body)} comparisons.", ""]
    noisy = []
    for name in dict.fromkeys(b[0] for b in body):
        least = min(o["rmse"] for o in rows if o["scene"] == name and o["rmse"] is not None)
        if suite.case(name).noise > least / 5:
            noisy.append(f"{name} (noise {suite.case(name).noise:.4f}, least RMSE {least:.4f})")
    if noisy:
        lines += [
            "The reference of " + ", ".join(noisy) + " is noisier than a fifth of the least "
            "error: every method's RMSE there includes that noise, which pulls the ratios "
            "towards 1, so a ratio near 1 on those scenes is no verdict.",
            "",
        ]
    for scene, model in dict.fromkeys((b[0], b[1]) for b in body):
        mine = [b for b in body if (b[0], b[1]) == (scene, model)]
        won = [b[2] for b in mine if b[-1] == "wins"]
        lost_at = [f"{b[2]} ({b[5]}× {b[4].split()[0]})" for b in mine if b[-1] != "wins"]
        lines.append(f"- {scene}, {model}: wins at {', '.join(won) or 'no budget'}; loses at "
                     f"{', '.join(lost_at) or 'no budget'}.")  # fmt: skip
    lines.append("")
    lines += markdown_table(
        ["scene", "model", "paths", "DPM RMSE", "best other", "ratio", ""], body
    )
    suite.report.add("Where DPM loses", lines)


def test_paper_tables(suite: Suite) -> None:
    cases = [suite.case(name) for name in suite.s.scenes]
    columns, timing = untabled_columns(cases, suite.s.table_budgets)
    _, untuned = tuning(cases)
    noise = [
        [case.name, f"{case.record['reference']['paths']:,}",
         f"{case.record['reference']['radius']:.4g}", f"{case.noise:.4f}",
         f"{case.black_rmse():.4f}"]
        for case in cases
    ]  # fmt: skip
    suite.report.add(
        "Table 1: caustic RMSE at M, 10·M and 100·M",
        [
            "Caustic RMSE (camera-weighted, one visible point per pixel of a 128-wide image). "
            "The classic columns are the estimator table's (`benchmarks/results/estimators.md`: "
            "the progressive methods tuned per scene and budget); the methods it does not tune "
            f"(DPM's models; {', '.join(untuned) or 'none else'} at the default initial radius "
            f"and {PASSES} passes) are run here on the same photon map (seed 0), with their "
            "RMSE over the best tabled one (below 1: they win); ‡: a tabled method that the "
            "table did not tune at that budget, run here with its setting at M. The same "
            "table at M is "
            "`benchmarks/results/dpm.md` (`python benchmarks/dpm_table.py`). **Best**, _second "
            "best_.",
            "",
            *table1([case.record for case in cases], suite.s.table_budgets, columns, rank=True),
        ],
        {"rmse": {f"{scene} {paths}": c for (scene, paths), c in columns.items()}},
    )
    suite.report.add(
        "Timings",
        [
            "Seconds of one estimate after compilation, of the methods run for Table 1: trace "
            "(caustic photons of the budget), gather (cKDTree build and K-nearest queries) and "
            "estimate (the rest: for DPM, features + inference + Eq. 2).",
            "",
            *timing_table(timing),
        ],
        timing,
    )
    suite.report.add(
        "Reference noise",
        [
            "The PPM reference of each scene (`estimator_table.py`): emitted paths, initial "
            "radius, its own RMSE noise (two independent halves), and the RMSE of an all-black "
            "estimate for scale.",
            "",
            *markdown_table(
                ["scene", "reference paths", "radius", "noise RMSE", "black RMSE"], noise
            ),
        ],
        noise,
    )


def test_stability_sparse(suite: Suite) -> None:
    rows = suite.rows()
    black = {n: suite.case(n).black_rmse() for n in suite.s.scenes}
    chart = suite.report.chart("sparse.png")
    stability.plot_sparse(rows, black, chart)
    intro = [
        f"The accuracy ladder from its lowest budget ({suite.s.budgets[0]:,} paths, a few "
        "hundred caustic photons) up; RMSE relative to estimating black."
    ]
    checks = stability.sparse(rows, black)
    held = f"at the lowest budget, {ANSWER}; {REFUSAL}"
    add_study(suite, "Stability: sparse photons", intro, chart, rows, checks, held)


def test_stability_k_close(suite: Suite) -> None:
    case = suite.case("ring" if "ring" in suite.s.scenes else suite.s.scenes[0])
    rows, checks = stability.k_close(case, suite.s.ratios)
    chart = suite.report.chart("k-close.png")
    stability.plot_k_close(rows, chart)
    intro = [
        f"{case.name}: maps of the first paths of the M map cut to P = K · "
        + ", ".join(f"{r:g}" for r in suite.s.ratios)
        + " caustic photons, and to K − 1."
    ]
    held = f"from P = K up, {ANSWER}; {REFUSAL}"
    add_study(suite, "Stability: K close to the photon count", intro, chart, rows, checks, held)


def region_study(
    suite: Suite, mask_of, min_points: int, what: str, rule: str
) -> tuple[list[dict], list[Check]]:
    """Rows and checks of a region study over the suite's scenes at M: mask_of(case) is the
    region (a scene with fewer than min_points hit points there is left out); must hold, each
    method sound there; findings by `stability.region_findings`' rule."""
    rows, checks = [], []
    for name in suite.s.scenes:
        case = suite.case(name)
        mask = mask_of(case)
        if (mask & case.points.hit).sum() >= min_points:
            rows += stability.region_rows(case, suite.at_m(name), mask)
            checks += stability.region_checks(case, suite.at_m(name), mask, what)
    return rows, checks + stability.region_findings(rows, what, rule)


def test_stability_thin(suite: Suite) -> None:
    rows, checks = region_study(suite, stability.sharp_mask, 1, "sharpest 5 %", "best")
    chart = suite.report.chart("thin.png")
    stability.plot_regions(rows, "rmse_in", "RMSE over the sharpest 5 %", chart)
    intro = [
        "At M paths, the RMSE over the 5 % of hit pixels with the steepest reference gradient "
        "(tone-mapped): the ring's cusp, the caustics' edges. Finding: each method's RMSE "
        "there against the best method's."
    ]
    held = "finite and non-negative estimates in the region"
    add_study(suite, "Stability: thin caustics", intro, chart, rows, checks, held)


def test_stability_crossing(suite: Suite) -> None:
    rows, checks = region_study(suite, stability.crossing_mask, 20, "crossing", "bias")
    chart = suite.report.chart("crossing.png") if rows else None
    if rows:
        stability.plot_regions(rows, "bias_in", "relative bias where K-NN cross surfaces", chart)
    intro = [
        "At M paths, the hit pixels whose 50 nearest caustic photons include one on another "
        "surface (a disagreeing normal, or more than 0.1·r off the tangent plane): corners and "
        f"walls. Finding: the relative bias of the caustic there, within ±"
        f"{100 * stability.BIAS_LIMIT:g} % or not."
        + ("" if rows else " No scene has 20 such pixels.")
    ]
    held = "finite and non-negative estimates in the region"
    title = "Stability: neighbourhoods that cross surfaces"
    add_study(suite, title, intro, chart, rows, checks, held)


def test_temporal(suite: Suite) -> None:
    s = suite.s
    rows = []
    truth = M * 10 if s.quick else M * 100
    for name in s.temporal_scenes:
        case = suite.case(name)
        images = temporal.run_path(case, s.frames, s.width, s.degrees, truth)
        assert all(np.isfinite(v).all() for v in images.values())
        temporal.plot_flicker(case, images, suite.report.chart(f"temporal-{name}.png"))
        rows += temporal.summary(case, images)
    body = [
        [
            r["scene"],
            r["method"],
            f"{r['dssim_consecutive']:.4f}",
            f"{r['dssim_reference']:.4f}",
        ]
        for r in rows
    ]
    suite.report.add(
        "Temporal stability",
        [
            f"{s.frames} frames, {s.width} px wide, the camera orbiting its target by "
            f"{s.degrees:g}° in all; photons fixed (M paths, seed 0). Flicker (DSSIM between "
            "consecutive frames) comes from the camera's motion as well as from the estimate, "
            "and blur lowers it, so read it next to the DSSIM against 'reference' (the "
            f"estimator table's APPM tuned at {truth:,} paths, on that many; its own flicker "
            "is listed too).",
            "",
            *[f"![{n}](temporal-{n}.png)" for n in s.temporal_scenes],
            "",
            *markdown_table(["scene", "method", "DSSIM consecutive", "DSSIM to reference"], body),
        ],
        rows,
    )


def test_pareto_and_growth_flags() -> None:
    def row(method: str, paths: int, seconds: float, rmse: float | None) -> dict:
        return {"scene": "s", "method": method, "paths": paths, "total_s": seconds, "rmse": rmse}

    rows = [
        row("A", 1, 1.0, 0.5),
        row("A", 2, 2.0, 0.3),
        row("B", 1, 1.5, 0.4),  # slower than A@1 but more accurate: on the front
        row("B", 2, 3.0, 0.45),  # dominated by A@2, and worse than B@1
        row("C", 1, 0.5, None),  # skipped: never on the front
    ]
    assert [(r["method"], r["paths"]) for r in pareto(rows)] == [("A", 1), ("B", 1), ("A", 2)]
    flags = growth_flags(rows)
    assert len(flags) == 1 and flags[0].startswith("s B:")
