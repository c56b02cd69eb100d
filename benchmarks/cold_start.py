"""A newcomer's first render: whole-process wall time with an empty kernel cache, then warm.

    python benchmarks/cold_start.py [--methods auto pm ...] [--scene SCENE.obj]

For each method, in fresh processes: `dpm-render SCENE --method M -o out.png` with Numba's and
JAX's caches pointed at an empty temporary folder (NUMBA_CACHE_DIR, JAX_COMPILATION_CACHE_DIR:
everything the method calls compiles), then the same command again (the kernels load from
that folder), then a one-pass 64 x 64 render (`--spp 1`: the fixed cost of a warm run); and
once `dpm-render --version`. Default: the README's command (`auto` on the glass egg). The
machine's CPU and load average are recorded; results/cold_start.md and .json.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import subprocess
import tempfile
import time
from pathlib import Path

from common import RESULTS, cpu, markdown_table

EGG = Path(__file__).parents[1] / "examples" / "scenes" / "glass_egg.obj"
OUT = RESULTS / "cold_start.json"
TABLE = RESULTS / "cold_start.md"


def timed(command: list[str], env: dict[str, str]) -> tuple[float, str]:
    """(whole-process wall seconds, stderr) of a command."""
    start = time.monotonic()
    done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
    return time.monotonic() - start, done.stderr


def run_method(method: str, scene: Path) -> dict:
    """Cold, warm and one-pass warm wall seconds of one method's render."""
    with tempfile.TemporaryDirectory() as folder:
        env = dict(os.environ, NUMBA_CACHE_DIR=f"{folder}/numba",
                   JAX_COMPILATION_CACHE_DIR=f"{folder}/jax")  # fmt: skip
        command = ["dpm-render", str(scene), "--method", method, "-o", f"{folder}/out.png"]
        load = [round(x, 2) for x in os.getloadavg()]
        cold, said = timed(command, env)
        warm, _ = timed(command, env)
        one = [*command, "--spp", "1", "--width", "64", "--height", "64"]
        one_pass, _ = timed(one, env)
    said = [line for line in said.splitlines() if "compiling" in line]
    row = {"method": method, "cold_s": cold, "warm_s": warm, "one_pass_64_s": one_pass,
           "load": load, "said": said}  # fmt: skip
    print(row, flush=True)
    return row


def main() -> None:
    """Measure the methods named and write the report."""
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--methods", nargs="+", default=["auto"])
    p.add_argument("--scene", type=Path, default=EGG)
    args = p.parse_args()
    version, _ = timed(["dpm-render", "--version"], dict(os.environ))
    rows = [run_method(m, args.scene) for m in args.methods]
    record = {"scene": str(args.scene.name), "cpu": cpu(), "date": str(datetime.date.today()),
              "version_s": version, "rows": rows}  # fmt: skip
    OUT.write_text(json.dumps(record, indent=1))
    head = ["method", "cold s (empty cache)", "warm s", "one pass 64² warm s", "load average"]
    body = [[r["method"], f"{r['cold_s']:.1f}", f"{r['warm_s']:.2f}", f"{r['one_pass_64_s']:.2f}",
             str(r["load"])] for r in rows]  # fmt: skip
    text = "\n".join([
        "# First render with an empty kernel cache, and warm",
        "",
        f"Made by `python benchmarks/cold_start.py` on {record['cpu']}, {record['date']}; scene "
        f"{record['scene']} at its sidecar's settings. `dpm-render --version`: {version:.2f} s.",
        "",
        *markdown_table(head, body),
        "",
    ])  # fmt: skip
    TABLE.write_text(text)
    print(text)


if __name__ == "__main__":
    main()
