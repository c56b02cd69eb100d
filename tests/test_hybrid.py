"""The hybrid renderer and denoising: the hybrid is dpm + OIDN, the denoiser lowers the error
without moving energy, and a denoised render does not depend on the thread count."""

from __future__ import annotations

import os
import subprocess
import sys
from pathlib import Path

import numpy as np

from dpm import load_scene
from dpm.cli import render_main
from dpm.io import read_exr
from dpm.metrics import rmse
from dpm.nn.model import make_model
from dpm.nn.train import init_params
from dpm.nn.weights import Weights, save_weights
from dpm.render import RenderOptions, render

EXAMPLES = Path(__file__).parent.parent / "examples" / "scenes"
K = 8


def test_hybrid_with_a_fresh_network_is_pm_denoised(tmp_path: Path, capsys) -> None:
    """A fresh DPM is PM-K (zero last layer), so the hybrid must equal `pm --denoise`."""
    weights = tmp_path / "fresh.msgpack"
    save_weights(weights, Weights("dpm", 8, K, init_params(make_model("dpm", 8), K, 0)))
    common = [str(EXAMPLES / "glass_egg.obj"), "--width", "24", "--height", "48", "--spp", "2",
              "--photons", "20000", "--k", str(K)]  # fmt: skip
    out = {}
    for name, flags in [("hybrid", ["--method", "hybrid", "--weights", str(weights)]),
                        ("pm", ["--method", "pm", "--denoise", "--caustic-spp", "1"]),
                        ("raw", ["--method", "pm", "--caustic-spp", "1"])]:  # fmt: skip
        out[name] = tmp_path / f"{name}.exr"
        assert render_main([*common, *flags, "-o", str(out[name])]) == 0
        summary = capsys.readouterr().out
    assert "network" not in summary and "denoise" not in summary  # the last: pm, no denoiser
    hybrid, pm, raw = (read_exr(out[n]) for n in ("hybrid", "pm", "raw"))
    np.testing.assert_allclose(hybrid, pm, rtol=1e-3, atol=1e-5)
    assert not np.allclose(pm, raw, rtol=1e-2)  # the denoiser did something


def test_denoising_lowers_the_error_and_keeps_the_energy(scene_path: Path) -> None:
    scene = load_scene(scene_path)
    size = {"width": 96, "height": 96, "progress": False}
    reference = render(scene, RenderOptions(method="pt", spp=256, seed=9, **size)).image
    noisy = render(scene, RenderOptions(method="pt", spp=2, **size)).image
    result = render(scene, RenderOptions(method="pt", spp=2, denoise=True, **size))
    clean = result.image
    assert result.stats["denoised"] and "denoise" in result.stats["seconds"]
    assert rmse(clean, reference) < 0.7 * rmse(noisy, reference)  # measured: about 0.5
    assert abs(clean.mean() / reference.mean() - 1) < 0.02


def test_a_denoised_render_is_the_same_for_any_thread_count(scene_path: Path) -> None:
    images = []
    for threads in ("1", "2"):
        out = scene_path.parent / f"t{threads}.exr"
        env = dict(os.environ, NUMBA_NUM_THREADS=threads, OIDN_NUM_THREADS=threads)
        argv = [sys.executable, "-m", "dpm.cli", str(scene_path), "--width", "40", "--height",
                "24", "--spp", "2", "--denoise", "--quiet", "-o", str(out)]  # fmt: skip
        subprocess.run(argv, env=env, check=True)
        images.append(read_exr(out))
    np.testing.assert_array_equal(*images)


def test_caustics_at_fewer_samples_per_pixel_keep_the_expectation() -> None:
    scene = load_scene(EXAMPLES / "ring.obj")
    opts = {"method": "pm", "component": "caustic", "spp": 4, "photons": 50_000, "k": 20,
            "width": 48, "height": 48, "progress": False}  # fmt: skip
    every = render(scene, RenderOptions(**opts)).image
    assert np.array_equal(every, render(scene, RenderOptions(caustic_spp=4, **opts)).image)
    first = render(scene, RenderOptions(caustic_spp=1, **opts))
    assert first.stats["caustic_spp"] == 1
    assert abs(first.image.mean() / every.mean() - 1) < 0.03
    assert rmse(first.image, every) < 0.5 * float(every.mean())
