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
    """After `load_registries_lean` (what `dpm-render` does first), Numba's first use in a
    fresh process loads neither scipy.linalg nor cffi, and both still import afterwards."""
    code = (
        "import sys, numpy as np\n"
        "from dpm.tracer._lean_numba import load_registries_lean\n"
        "load_registries_lean()\n"
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


def test_the_render_script_starts_numba_lean() -> None:
    """`dpm-render`'s console script loads Numba's array-math registry the lean way before
    anything else (`render_main` stood in for: it would render)."""
    code = (
        "import sys, dpm.cli as cli\n"
        "def main():\n"
        "    from numba.np import arraymath\n"
        "    print('cffi' in sys.modules, 'scipy.linalg' in sys.modules, arraymath._HAVE_BLAS)\n"
        "    return 0\n"
        "cli.render_main = main\n"
        "cli.render_command()\n"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "False False False", out.stdout + out.stderr
