"""`CompileWatch`: the seconds Numba spends compiling inside a render, and the moving bar."""

from __future__ import annotations

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
