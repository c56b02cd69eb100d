"""`CompileWatch`: the seconds Numba spends compiling inside a render, and the moving bar."""

from __future__ import annotations

import subprocess
import sys

import numba as nb

from dpm import compiling, load_file
from dpm.compiling import CompileWatch
from dpm.renderer import RenderOptions, render


def test_a_compile_is_timed_and_shown(monkeypatch, capsys) -> None:
    monkeypatch.setattr(compiling, "TICK", 0.001)

    @nb.njit  # a new function: it compiles on its first call
    def twice(x):
        return 2 * x

    with CompileWatch(show=True) as watch:
        assert twice(3) == 6
    assert watch.kernels == 1 and watch.seconds > 0
    assert "compiling kernels" in capsys.readouterr().err
    with CompileWatch(show=True) as again:
        assert twice(4) == 8  # compiled already
    assert again.kernels == 0 and again.seconds == 0
    assert capsys.readouterr().err == ""


def test_a_warm_render_compiles_nothing(scene_path) -> None:
    scene = load_file(scene_path)
    options = RenderOptions(width=12, height=10, spp=2, photons=2000, progress=False)
    render(scene, options)  # compiles, or loads from Numba's cache
    stats = render(scene, options).stats
    assert stats["compiled_kernels"] == 0 and stats["compile_seconds"] == 0


def test_the_tracer_starts_without_scipy_linalg_or_cffi() -> None:
    """After `start_lean` (what `dpm-render` does first), Numba's first use in a fresh process
    (compiling or loading from the cache) imports neither scipy.linalg nor cffi, and both
    still import afterwards."""
    code = (
        "import sys, numpy as np\n"
        "from dpm._lean_numba import start_lean\n"
        "start_lean()\n"
        "from dpm.tracer import build_bvh, intersect\n"
        "tri = np.array([[[0, 0, 1], [1, 0, 1], [0, 1, 1]]], np.float32)\n"
        "bvh = build_bvh(tri)\n"
        "o, d = np.zeros((1, 3), np.float32), np.array([[0.2, 0.2, 1]], np.float32)\n"
        "t, hit = intersect(bvh, o, d / np.linalg.norm(d))\n"
        "assert hit[0] == 0, hit\n"
        "print(sorted(m for m in ('scipy.linalg', 'cffi') if m in sys.modules))\n"
        "import scipy.linalg, cffi\n"
        "print(cffi.FFI() is not None, scipy.linalg.cython_blas.__name__)\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split("\n")[:2] == ["[]", "True scipy.linalg.cython_blas"], out.stderr


# a few kernels: a BVH, closest hits, a path-traced image; then a kernel new to Numba
_KERNELS = """
import sys, numpy as np
if sys.argv[1] == "lean":
    from dpm._lean_numba import start_lean
    start_lean()
from numba.core.registry import cpu_target
from dpm import load_file
from dpm.renderer import RenderOptions, render
scene = load_file(sys.argv[2])
options = RenderOptions(method="pt", width=12, height=10, spp=2, denoise=False, progress=False)
image = render(scene, options).image
loaded = len(cpu_target.target_context._registries)
skipped = not any(m in sys.modules for m in ("scipy.linalg", "cffi"))
import numba
from numba.typed import List

@numba.njit
def fresh(n):
    values = List()
    for i in range(n):
        values.append(np.sqrt(np.float64(i)))
    return values[n - 1]

print(image.tobytes().hex(), loaded, skipped, fresh(10) == 3.0)
"""


def test_cached_kernels_load_lean_and_compute_the_same(scene_path) -> None:
    """`start_lean`'s cache load leaves Numba's registries unloaded (and scipy.linalg and
    cffi, which the kernels' environments would import), the image is the one a plain
    process renders, bit for bit, and a kernel new to Numba still compiles after."""
    args = [sys.executable, "-c", _KERNELS]
    plain = subprocess.run([*args, "plain", str(scene_path)], capture_output=True, text=True)
    assert plain.returncode == 0, plain.stderr  # (compiles the kernels where not cached)
    lean = subprocess.run([*args, "lean", str(scene_path)], capture_output=True, text=True)
    assert lean.returncode == 0, lean.stderr
    image, loaded, skipped, fresh = lean.stdout.split()
    assert image == plain.stdout.split()[0]
    assert loaded == "0" and plain.stdout.split()[1] != "0"  # the plain load refreshed them
    assert skipped == "True" and fresh == "True"


def test_the_render_script_starts_lean() -> None:
    """`dpm-render`'s console script pauses the garbage collector and makes Numba load
    cached kernels the lean way before anything else (`render_main` stood in for: it would
    render)."""
    code = (
        "import gc, sys, dpm.cli as cli\n"
        "def main():\n"
        "    from numba.core import caching\n"
        "    from dpm import _lean_numba\n"
        "    lean = caching.Cache.load_overload is _lean_numba._load_cached\n"
        "    print(gc.isenabled(), lean, 'cffi' in sys.modules, 'scipy.linalg' in sys.modules)\n"
        "    return 0\n"
        "cli.render_main = main\n"
        "cli.render_command()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False True False False", out.stdout + out.stderr
