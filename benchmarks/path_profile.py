"""Where `pt`'s time goes: CPU samples of one path-traced render, per compiled function.

    python benchmarks/path_profile.py [SCENE ...] [--set examples unseen] [--spp S] [--width W]
                                      [--out FILE]

Needs Linux `perf` (perf_event_paranoid ≤ 2). For each scene of the sets (default: every
example; `unseen`: `scenes/make_unseen.py`'s, built when missing; or the scenes named), this
process compiles the tracer's kernels into a fresh cache directory (so their LLVM modules,
and with them every function's name, stay in memory; a cached kernel loads as object code
with no names), renders once untimed, writes the perf map of every compiled function
(`/tmp/perf-PID.map`: address, size, name), then samples itself with `perf record -p PID`
for the duration of one `pt` render of --spp samples per pixel and groups the samples:
traversal (`closest_hit`, `any_hit`, and the stages' packets `_trace_closest`, `_trace_shadow`
of the diffuse scenes), the path's shading (`path_pixel` or the stages, where camera rays,
light sampling, BSDFs and the random numbers are inlined), libm (sin/cos of the cosine
sampling), the OpenMP runtime (a worker spinning or waiting: CPU time, not necessarily
wall time lost) and the rest. Shares are of the render's CPU samples on all threads.
Writes results/path_profile.md and prints it.
"""

from __future__ import annotations

import argparse
import datetime
import gc
import os
import re
import signal
import subprocess
import sys
import tempfile
import time
from collections import defaultdict
from pathlib import Path

from common import RESULTS, SCENES, cpu, markdown_table

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import unseen_scenes  # noqa: E402

from dpm import load_scene  # noqa: E402
from dpm.renderer import RenderOptions, render  # noqa: E402

FRESH = "DPM_PROFILE_FRESH_CACHE"  # set in the re-executed process: its cache is empty

GROUPS = (  # (label, pattern on the function's or library's name), first match wins
    # the diffuse scenes' stages (wavefront.py) trace their rays in packets inside
    # `_trace_closest` and `_trace_shadow`; their other stages are the path's own work
    ("closest_hit", r"closest_hit|closest_packet|_trace_closest"),
    ("any_hit", r"any_hit|any_packet|_trace_shadow"),
    (
        "path (shading, camera, sampling)",
        r"path_pixel|shade|camera_sample|wavefront\.|lean_from|camera_chain",
    ),
    ("libm", r"libm[.-]"),
    ("OpenMP runtime", r"libgomp|libomp|libtbb"),
)


def write_perf_map() -> int:
    """Write /tmp/perf-PID.map for every function of every finalised Numba library; returns
    how many functions it names."""
    from numba.core.codegen import JITCodeLibrary

    found = {}
    for obj in gc.get_objects():
        if not isinstance(obj, JITCodeLibrary) or not obj._finalized:
            continue
        for fn in obj._final_module.functions:
            if fn.is_declaration:
                continue
            try:
                address = obj.get_pointer_to_function(fn.name)
            except Exception:  # noqa: BLE001 - a symbol the engine does not export
                continue
            if address:
                found[address] = fn.name
    ordered = sorted(found.items())
    with open(f"/tmp/perf-{os.getpid()}.map", "w") as f:
        for i, (address, name) in enumerate(ordered):
            end = ordered[i + 1][0] if i + 1 < len(ordered) else address + 4096
            f.write(f"{address:x} {min(end - address, 1 << 20):x} {name}\n")
    return len(ordered)


def readable(symbol: str) -> str:
    """The dotted Python name in a Numba-mangled symbol (`_ZN3dpm6tracer4path10path_pixel...`
    -> dpm.tracer.path.path_pixel), or the symbol itself."""
    if not symbol.startswith("_ZN"):
        return symbol
    parts, i = [], 3
    while i < len(symbol) and symbol[i].isdigit():  # <length><name> components
        j = i
        while j < len(symbol) and symbol[j].isdigit():
            j += 1
        size = int(symbol[i:j])
        parts.append(symbol[j : j + size])
        i = j + size
    return ".".join(parts) or symbol


def profile(
    path: Path, spp: int, width: int
) -> tuple[dict[str, float], list[tuple[float, str]], float]:
    """(share of the render's CPU samples per group, the top functions as (share, name),
    render seconds) of one `pt` render of scene `path`."""
    scene = load_scene(path)
    height = max(1, round(width * scene.camera.height / scene.camera.width))
    size = {"width": width, "height": height, "progress": False}
    options = RenderOptions(method="pt", spp=spp, seed=1, **size)
    render(scene, RenderOptions(method="pt", spp=2, seed=0, **size))  # compile
    write_perf_map()
    with tempfile.TemporaryDirectory() as tmp:
        data = Path(tmp) / "perf.data"
        cmd = ["perf", "record", "-q", "-F", "1999", "-p", str(os.getpid()), "-o", str(data)]
        perf = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.PIPE)
        try:
            time.sleep(0.5)  # perf attaches to every thread before the render starts
            if perf.poll() is not None:
                sys.exit(f"path_profile: perf record failed: {perf.stderr.read().decode()}")
            start = time.perf_counter()
            render(scene, options)
            seconds = time.perf_counter() - start
        finally:
            if perf.poll() is None:
                perf.send_signal(signal.SIGINT)
            perf.communicate(timeout=60)
        report = subprocess.run(
            ["perf", "report", "-i", str(data), "--no-children", "--sort", "dso,sym",
             "--stdio", "-q", "--percent-limit", "0.01"],
            capture_output=True, text=True, check=True,
        ).stdout  # fmt: skip
    shares, top = defaultdict(float), []
    for line in report.splitlines():
        m = re.match(r"\s*([\d.]+)%\s+(.+?)\s+\[[.k]\]\s+(\S+)", line)
        if not m:
            continue
        share, dso, symbol = float(m.group(1)), m.group(2), m.group(3)
        name = readable(symbol)
        group = next((g for g, pat in GROUPS if re.search(pat, f"{name} {dso}")), "other")
        shares[group] += share
        top.append((share, name if name != symbol else f"{dso.split()[0]} {symbol}"))
    total = sum(shares.values()) or 1.0
    return {g: 100 * v / total for g, v in shares.items()}, sorted(top, reverse=True), seconds


def main() -> None:
    """Profile each scene and write the table."""
    if not os.environ.get(FRESH):  # run again with an empty Numba cache (see the docstring)
        cache = tempfile.mkdtemp(prefix="dpm-profile-")
        env = {**os.environ, FRESH: "1", "NUMBA_CACHE_DIR": cache}
        os.execve(sys.executable, [sys.executable, __file__, *sys.argv[1:]], env)
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("scenes", nargs="*")
    p.add_argument("--set", nargs="+", choices=("examples", "unseen"), default=["examples"])
    p.add_argument("--spp", type=int, default=256)
    p.add_argument("--width", type=int, default=128)
    p.add_argument("--out", default=str(RESULTS / "path_profile.md"))
    a = p.parse_args()
    try:
        subprocess.run(["perf", "--version"], capture_output=True, check=True)
    except (OSError, subprocess.CalledProcessError):
        sys.exit("path_profile: needs Linux perf (apt install linux-perf)")
    paths = {}
    for which in a.set:
        found = unseen_scenes() if which == "unseen" else sorted(SCENES.glob("*.obj"))
        paths.update({f.stem: f for f in found})
    unknown = [n for n in a.scenes if n not in paths]
    if unknown:
        p.error(f"not in {' or '.join(a.set)}: {', '.join(unknown)}")
    labels = [g for g, _ in GROUPS] + ["other"]
    rows, notes = [], []
    for name in a.scenes or list(paths):
        shares, top, seconds = profile(paths[name], a.spp, a.width)
        rows.append([name, f"{seconds:.2f}", *(f"{shares.get(g, 0.0):.1f}" for g in labels)])
        notes.append(f"- {name}: " + ", ".join(f"{n} {s:.1f}" for s, n in top[:5]))
        print(rows[-1], flush=True)
    lines = [
        "# Where `pt`'s time goes",
        "",
        f"Made by `python benchmarks/path_profile.py {' '.join(sys.argv[1:])}` (see its "
        "docstring). Percent of the render's CPU samples (all threads) per group; render s: "
        f"one `pt` render of {a.spp} spp, {a.width} px wide, while perf samples it.",
        f"Machine: {cpu()}; {datetime.date.today()}.",
        "",
        *markdown_table(["scene", "render s", *labels], rows),
        "",
        "Top functions per scene (percent of all samples in the process's perf report):",
        "",
        *notes,
        "",
    ]
    Path(a.out).write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
