"""The learned estimators against the classic ones at M (paper Table 1), without the suite.

Table 1 (`tables.table1`, the table the suite's report shows) at the budgets asked for
(default M): the estimator table's PM-50, PM-500, PPM-best and APPM-best next to every
method it does not tune (`cases.estimators`: every shipped DPM model, or those in
--weights), run here on the same visible points and photon map (seed 0), with each one's
ratio to the best classic RMSE (below 1: it wins) and its seconds per stage.

    python benchmarks/dpm_table.py [SCENE ...] [--weights DIR] [--budgets N ...]

Needs each scene's benchmarks/results/estimators/SCENE.json and references_radiance/SCENE.npz
(made by estimator_table.py); writes benchmarks/results/dpm.md.
"""

from __future__ import annotations

import argparse
from pathlib import Path

from cases import load_case
from tables import table1, timing_table, untabled_columns

from common import RESULTS, M, cpu
from dpm.nn.weights import SHIPPED, weight_ks


def write_markdown(
    names: list[str], budgets: list[int], weights: Path | None, path: Path = RESULTS / "dpm.md"
) -> None:
    """Run the untabled methods on the scenes at the budgets and write dpm.md (or `path`)."""
    cases = [load_case(name) for name in names]
    columns, timing = untabled_columns(cases, budgets, weights)
    records = [case.record for case in cases]
    lines = [
        "# The learned estimators against the classic ones",
        "",
        "Made by `python benchmarks/dpm_table.py` (see its docstring): Table 1 of the suite's",
        "report at " + ", ".join(f"{b:,}" for b in budgets) + " emitted paths. Caustic RMSE",
        "over one visible point per pixel (camera-weighted) against the estimator table's PPM",
        "reference (`estimators.md`, whose classic columns these are). *÷ best classic*: the",
        "method's RMSE over the best classic one tuned for that scene and budget; below 1 it",
        "wins. **Best**, _second best_.",
        "",
        *table1(records, budgets, columns, rank=True),
        "",
        "Seconds of one estimate after compilation (gather: DPM's cKDTree build and K-nearest",
        "queries, NPPM's hashed point grid):",
        "",
        *timing_table(timing),
        "",
        f"Machine: {cpu()}.",
    ]
    path.write_text("\n".join(lines) + "\n")


def main() -> None:
    """Run the scenes named (default: every scene the estimator table has) and write dpm.md."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--weights", type=Path, default=SHIPPED, help="folder of dpm-K.msgpack files")
    p.add_argument("--budgets", type=int, nargs="+", default=[M],
                   help="emitted paths: among the estimator table's M, 10·M and 100·M")  # fmt: skip
    args = p.parse_args()
    names = args.scenes or sorted(f.stem for f in (RESULTS / "estimators").glob("*.json"))
    if not weight_ks(args.weights):
        raise SystemExit(f"no dpm-K.msgpack in {args.weights}: train one with dpm-train first")
    weights = None if args.weights == SHIPPED else args.weights
    write_markdown(names, args.budgets, weights)


if __name__ == "__main__":
    main()
