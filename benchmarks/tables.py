"""The tables that more than one benchmark shows, each made by one function here.

- `table1`: the paper's Table 1, caustic RMSE per scene and budget (M, 10·M, 100·M) of the
  methods the estimator table tunes (its records, results/estimators/SCENE.json: PM-K, and
  PPM and APPM tuned per scene and budget), optionally next to the methods it does not,
  run here on the same photon map (`run_untabled`: DPM's models, ...). It makes
  results/estimators.md (estimator_table.py), the suite's "Table 1" and results/dpm.md
  (dpm_table.py).
- `timing_table`: the seconds per stage of those runs (the suite's "Timings", dpm.md's).
"""

from __future__ import annotations

from collections.abc import Iterable
from functools import partial
from pathlib import Path

from cases import Case, caustic_error, estimators, photons
from checks import problems

from common import TOTAL, markdown_table, needed_k, photon_methods, timed, timed_estimate
from dpm.methods.base import NearestPhotons


def tabled(row: dict) -> dict[str, str]:
    """The methods of one budget's row of an estimator-table record, {label: key} in registry
    order: a K-nearest method's NAMEK keys (PM-50: pm50) and a progressive method's NAME_best
    (PPM-best: ppm_best)."""
    out = {}
    for name, cls in photon_methods().items():
        if issubclass(cls, NearestPhotons):
            for key in row:
                if key.startswith(name) and key[len(name) :].isdigit():
                    out[f"{name.upper()}-{key[len(name) :]}"] = key
        elif f"{name}_best" in row:
            out[f"{name.upper()}-best"] = f"{name}_best"
    return out


def least_error(row: dict) -> float:
    """The least RMSE of one budget's tabled methods."""
    return min(row[key]["rmse"] for key in tabled(row).values() if row[key]["rmse"] is not None)


def edge(row: dict, key: str) -> str:
    """'†' when a tuned method's best radius (key NAME_best) is the smallest or largest it
    tried, else ''."""
    if not key.endswith("_best"):
        return ""
    tried = [t["radius"] for t in row["trials"] if t["method"] == key.removesuffix("_best")]
    return "†" if row[key]["radius"] in (min(tried), max(tried)) else ""


def fmt(x: float | None) -> str:
    """An RMSE for a table, '–' for none."""
    return "–" if x is None else f"{x:.4f}"


def marks(errors: dict[str, float | None]) -> dict[str, str]:
    """Markdown emphasis of a row's RMSEs: '**' for the best, '_' for the second best."""
    ranked = sorted((e, label) for label, e in errors.items() if e is not None)
    return {label: mark for (_, label), mark in zip(ranked, ("**", "_"), strict=False)}


def table1(
    records: list[dict],
    budgets: Iterable[int] | None = None,
    untabled: dict[tuple[str, int], dict[str, float | None]] | None = None,
    rank: bool = False,
) -> list[str]:
    """Table 1's Markdown lines: per scene record and budget (every budget of the records,
    or those in `budgets`), caustic photons, the RMSE of each tabled method (PPM/APPM-best
    marked † when still at an edge of the radii tried), of each `untabled` method
    ({(scene, paths): {label: RMSE}}) with its ratio to the best tabled one (below 1: it
    wins), and the reference's noise, whether it is at most a fifth of the least error of
    the scene's rows, and its initial radius. A method tabled at some budgets but run here
    at others keeps its one column, the run's RMSE marked ‡ (the table's setting at M, not
    one tuned at that budget). `rank` marks each row's **best** and _second best_."""
    untabled = untabled or {}
    keep = None if budgets is None else set(budgets)
    labels = list(
        dict.fromkeys(label for r in records for b in r["budgets"] for label in tabled(b))
    )
    others = [
        label
        for label in dict.fromkeys(label for errors in untabled.values() for label in errors)
        if label not in labels
    ]
    head = ["scene", "paths", "caustic photons", *labels, *others]
    head += [f"{label} ÷ best classic" for label in others]
    head += ["ref noise", "noise ≤ ⅕ min", "ref r₀ (× diagonal)"]
    body = []
    for r in records:
        smallest = min(least_error(b) for b in r["budgets"])
        noise = r["reference"]["noise"]
        for b in r["budgets"]:
            if keep is not None and b["paths"] not in keep:
                continue
            keys = tabled(b)
            ours = untabled.get((r["scene"], b["paths"]), {})
            errors = {
                label: b[keys[label]]["rmse"] if label in keys else ours.get(label)
                for label in [*labels, *others]
            }
            mark = marks(errors) if rank else {}
            cells = [
                f"{mark.get(label, '')}{fmt(e)}{mark.get(label, '')}"
                + (edge(b, keys[label]) if label in keys else "")
                + ("‡" if label in labels and label not in keys and e is not None else "")
                for label, e in errors.items()
            ]
            best = least_error(b)
            cells += [
                "–" if ours.get(label) is None else f"{ours[label] / best:.2f}" for label in others
            ]
            body.append([
                r["scene"], f"{b['paths']:,}", f"{b['caustic_photons']:,}", *cells,
                f"{noise:.4f}", "yes" if noise <= smallest / 5 else "no",
                f"{r['reference']['radius'] / r['diagonal']:.1e}",
            ])  # fmt: skip
    return markdown_table(head, body)


def run_untabled(
    case: Case, budget: int, weights: Path | None = None
) -> tuple[dict[str, float | None], list[dict]]:
    """The suite's methods that the estimator table does not tune (`cases.estimators` less
    the record's), each run once after a warm-up call on the table's photon map at `budget`
    (seed 0; its photon count is checked against the record's): ({label: RMSE, None when
    K > photons}, timing rows {scene, paths, method, caustic_photons, trace_s, gather_s,
    estimate_s, total_s}). An answer that breaks a must-hold property fails an assert."""
    row = next(b for b in case.record["budgets"] if b["paths"] == budget)
    photon_map, (trace_s,) = timed(partial(photons, case, budget))
    assert len(photon_map) == row["caustic_photons"], f"{case.name}: not the table's photon map"
    errors, timing = {}, []
    for label, estimator in estimators(case, budget, weights).items():
        if label in tabled(row):
            continue
        if len(photon_map) < needed_k(estimator):
            errors[label] = None
            continue
        estimate, seconds = timed_estimate(estimator, case.points, photon_map, warmup=True)
        wrong = problems(estimate, case.points)
        assert not wrong, f"{case.name} {label} at {budget:,} paths: {'; '.join(wrong)}"
        errors[label] = caustic_error(case, estimate)
        gather = seconds.get("gather", 0.0)
        timing.append({
            "scene": case.name, "paths": budget, "method": label,
            "caustic_photons": len(photon_map), "trace_s": trace_s, "gather_s": gather,
            "estimate_s": seconds[TOTAL] - gather, "total_s": seconds[TOTAL],
        })  # fmt: skip
    return errors, timing


def untabled_columns(
    cases: Iterable[Case], budgets: Iterable[int], weights: Path | None = None
) -> tuple[dict[tuple[str, int], dict[str, float | None]], list[dict]]:
    """`run_untabled` over scenes and budgets: (table1's `untabled`, every timing row)."""
    columns, timing = {}, []
    for case in cases:
        for budget in budgets:
            columns[case.name, budget], rows = run_untabled(case, budget, weights)
            timing += rows
    return columns, timing


def timing_table(rows: list[dict]) -> list[str]:
    """The Markdown lines of `run_untabled`'s timing rows: trace, gather (tree and queries),
    estimate (the rest of the estimate call: for DPM features, network and Eq. 2), and
    gather + estimate."""
    head = ["scene", "paths", "method", "caustic photons", "trace s", "gather s", "estimate s",
            "gather + estimate s"]  # fmt: skip
    body = [
        [r["scene"], f"{r['paths']:,}", r["method"], f"{r['caustic_photons']:,}",
         f"{r['trace_s']:.2f}", f"{r['gather_s']:.2f}", f"{r['estimate_s']:.2f}",
         f"{r['total_s']:.2f}"]
        for r in rows
    ]  # fmt: skip
    return markdown_table(head, body)
