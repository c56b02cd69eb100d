"""A render that holds at any budget: one pass is still denoised, a budget the first pass
overran is reported, and no pass after the first compiles a kernel."""

from __future__ import annotations

import json
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest

from dpm import clock, load_scene
from dpm.cli import render_main
from dpm.denoise import restore_certain
from dpm.io import tone_map
from dpm.methods.adaptive import Halves
from dpm.metrics import rmse
from dpm.renderer import RenderOptions, render

EGG = Path(__file__).parent.parent / "examples" / "scenes" / "glass_egg.obj"  # caustic + diffuse
SIZE = 32  # pixels across the test images
REFERENCE_PASSES = 256  # the reference's noise is a sixteenth of one pass's


def options(**kw) -> RenderOptions:
    return RenderOptions(width=SIZE, height=SIZE, progress=False, **kw)


@pytest.fixture(scope="module")
def egg():
    return load_scene(EGG)


@pytest.fixture(scope="module")
def reference(egg) -> np.ndarray:
    """The egg near converged: many passes, not denoised (unbiased), another seed."""
    n = REFERENCE_PASSES
    return render(egg, options(spp=n, photons=n * 4 * SIZE * SIZE, seed=99, denoise=False)).image


def test_one_path_per_pixel_tells_no_error() -> None:
    # One path (or one per half) has no spread to measure: the error is unknown (inf), never
    # 0, which would take the pixel for exact.
    rng = np.random.default_rng(0)
    halves = Halves(4, 5)
    halves.add_pass(0, rng.random((20, 3)))
    assert np.isposinf(halves.standard_error()).all()
    halves.add_pass(1, rng.random((20, 3)))
    assert np.isposinf(halves.standard_error()).all()
    for j in range(2, 4):
        halves.add_pass(j % 2, rng.random((20, 3)))
    assert np.isfinite(halves.standard_error()).all()


def test_one_half_with_paths_tells_the_error_of_its_own_mean() -> None:
    # The light seen in glass after one pass: 16 samples in half 0, none in half 1. The
    # pixel's value is half 0's mean, so its error is that mean's (not a quarter of it).
    halves = Halves(1, 1)
    values = np.repeat(np.arange(16.0)[:, None], 3, axis=1)
    halves.base[0].add(slice(None), 16, values.sum(axis=0), (values[:, 0] ** 2).sum())
    expected = np.std(values[:, 0]) / np.sqrt(16)
    np.testing.assert_allclose(halves.standard_error(), [expected])
    np.testing.assert_allclose(halves.mean(), [values.mean(axis=0)])


def test_a_pixel_of_unknown_error_keeps_the_denoisers_value() -> None:
    color = np.zeros((2, 2, 3), np.float32)
    denoised = np.ones_like(color)
    error = np.array([[np.inf, 0.0], [np.inf, np.inf]])
    out = restore_certain(color, denoised, error)
    np.testing.assert_array_equal(out[..., 0], [[1.0, 0.0], [1.0, 1.0]])


def test_one_pass_is_denoised(egg, reference) -> None:
    # One pass's path samples are mostly noise, with black pixels where a path found no
    # light; the default render denoises them (before, it undid the denoiser everywhere).
    # (three seeds: one pass's linear RMSE is a few fireflies', which one seed can draw
    # where the denoiser is unsure of them)
    seen = tone_map(reference)  # what a viewer compares
    errors = []
    for seed in (1, 2, 3):
        one = options(spp=1, photons=4 * SIZE * SIZE, seed=seed)
        raw = render(egg, replace(one, denoise=False)).image
        image = render(egg, one).image
        errors.append((rmse(image, reference), rmse(raw, reference)))
        assert rmse(tone_map(image), seen) < 0.8 * rmse(tone_map(raw), seen)
    denoised, plain = np.mean(errors, axis=0)
    assert denoised < 0.95 * plain
    lit = reference.max(axis=2) > 0
    paths = render(egg, options(method="pt", spp=1, seed=1)).image  # one path per pixel
    assert ((paths.max(axis=2) <= 0) & lit).sum() > 20  # leaves black pixels
    assert not ((image.max(axis=2) <= 0) & lit).any()  # the denoised pass none


def test_a_budget_the_first_pass_overran_is_reported(tmp_path: Path, capsys) -> None:
    # The budget counts from the process start: pytest's started long ago.
    argv = [str(EGG), "--width", "16", "--height", "16", "-o", str(tmp_path / "a.exr")]
    stats = tmp_path / "s.json"
    assert render_main([*argv, "--time", "0.01", "--stats", str(stats), "--quiet"]) == 0
    err = capsys.readouterr().err.strip()
    assert len(err.splitlines()) == 1 and err.startswith("dpm-render: warning: the first pass")
    assert "the budget was 0.01 s" in err and "the image is one pass" in err
    got = json.loads(stats.read_text())
    assert got["passes"] == 1 and got["overran"] is True and got["pass_seconds"] > 0
    assert got["setup_seconds"] > 0.01
    assert render_main([*argv, "--spp", "2", "--stats", str(stats)]) == 0
    assert capsys.readouterr().err == ""
    got = json.loads(stats.read_text())
    assert got["overran"] is False and got["pass_seconds"] > 0


# In a fresh interpreter: after a one-pass budgeted render (its first pass compiles or loads
# what the plan's later passes call), a render of more than ADAPT_AFTER passes adds no
# kernel specialisation, for a plan with caustics, one without, and a scene without glass.
NO_NEW_KERNELS = """
import sys
from numba.core.dispatcher import Dispatcher
from dpm import clock, load_scene
from dpm.methods import auto
from dpm.renderer import RenderOptions, render

def signatures():
    return {(name, str(s)) for name, mod in list(sys.modules.items()) if name.startswith("dpm")
            for obj in vars(mod).values() if isinstance(obj, Dispatcher) for s in obj.signatures}

for path, share in ((sys.argv[1], None), (sys.argv[1], 2.0), (sys.argv[2], None)):
    if share is not None:
        auto.MIN_CAUSTIC_SHARE = share  # the plan leaves the caustics out
    scene = load_scene(path)
    kw = dict(width=16, height=16, progress=False)
    assert render(scene, RenderOptions(time=1e-6, **kw)).stats["passes"] == 1
    before = signatures()
    n = 2 * auto.ADAPT_AFTER  # paths per pixel: whole-pixel passes adapt once each half has 4
    result = render(scene, RenderOptions(spp=n, photons=n * 1024, **kw))
    assert result.stats["extra_paths"] > 0
    new = signatures() - before
    assert not new, (path, result.stats["plan"], new)
"""


def test_no_kernel_compiles_after_the_first_pass() -> None:
    diffuse = EGG.parent / "cornell_box.obj"
    subprocess.run([sys.executable, "-c", NO_NEW_KERNELS, str(EGG), str(diffuse)], check=True)


def test_a_budget_counts_from_the_process_not_from_a_shell_that_exec_d_it() -> None:
    """/proc's start time is the fork's: a process a shell exec'd after other work keeps
    the shell's. `process_started` believes at most BEFORE_IMPORT seconds before dpm's import."""
    age = "import time; from dpm.clock import process_started as p; print(time.monotonic() - p())"
    ages = []
    for before in ("", "sleep 3; "):
        command = f'{before}exec "{sys.executable}" -c "{age}"'
        out = subprocess.run(["bash", "-c", command], capture_output=True, text=True, check=True)
        ages.append(float(out.stdout))
    assert 0 < ages[0] < clock.BEFORE_IMPORT  # the interpreter's start and dpm's import
    assert clock.BEFORE_IMPORT <= ages[1] < 3.0  # not the shell's 3 s of sleep before
