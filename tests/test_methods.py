"""The method registry, the options derived from one dataclass, and dpm-render's rough edges."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path
from typing import ClassVar

import numpy as np
import pytest

from conftest import write_scene
from dpm import __version__, load_scene
from dpm.cli import render_main
from dpm.estimators import PM
from dpm.methods import METHODS, caustic_methods, make_estimator, method_class, register
from dpm.options import RenderOptions, cli_fields, sidecar_types
from dpm.renderer import render

EGG = Path(__file__).parent.parent / "examples" / "scenes" / "glass_egg.obj"
K = 8


def run(capsys, argv: list[str]) -> tuple[int, str, str]:
    """dpm-render in-process: (exit status, stdout, stderr)."""
    try:
        code = render_main(argv)
    except SystemExit as exc:  # argparse: usage errors, --help, --version
        code = exc.code
    out = capsys.readouterr()
    return code, out.out, out.err


def test_every_registered_method_renders_through_the_one_path() -> None:
    scene = load_scene(EGG)
    for name, cls in METHODS.items():
        assert cls.name == name and method_class(name) is cls and cls.summary
        options = RenderOptions(method=name, spp=1, photons=20_000, width=8, height=8)
        options.progress = False  # k: each method's default (dpm, hybrid: the shipped K = 50)
        result = render(scene, options)
        assert result.image.shape == (8, 8, 3) and np.isfinite(result.image).all()
        assert result.stats["method"] == name
        assert ("caustic_photons" in result.stats) == (name in caustic_methods())


@dataclass(frozen=True)
class TwicePM:
    """A test's estimator: PM-K's estimate doubled."""

    name: ClassVar[str] = "twice-pm"
    summary: ClassVar[str] = "PM-K doubled (a test estimator)"
    k: int = 50

    def estimate(self, points, photons, watch=None):
        """(N, 3) float32: twice PM-K's caustic radiance."""
        return 2 * PM(k=self.k).estimate(points, photons, watch)


def test_a_new_estimator_needs_only_its_class_and_one_registration(monkeypatch, capsys) -> None:
    """What adding an estimator takes: its class (here, in this file) and `register`."""
    monkeypatch.setitem(METHODS, "twice-pm", None)  # so the entry goes after the test
    method = register(TwicePM)
    assert METHODS["twice-pm"] is method and method.estimator_class is TwicePM
    scene = load_scene(EGG)
    common = dict(spp=1, photons=20_000, width=8, height=8, k=K, component="caustic")
    pm = render(scene, RenderOptions(method="pm", progress=False, **common))
    twice = render(scene, RenderOptions(method="twice-pm", progress=False, **common))
    np.testing.assert_allclose(twice.image, 2 * pm.image, rtol=1e-6)
    assert twice.stats["k"] == K and "gather" in twice.stats["seconds"]
    code, out, _ = run(capsys, ["--help"])
    assert code == 0 and "twice-pm: PM-K doubled (a test estimator)" in " ".join(out.split())


def test_flags_and_sidecar_keys_come_from_the_options_dataclass(capsys) -> None:
    code, out, _ = run(capsys, ["--help"])
    assert code == 0
    for f in cli_fields():
        assert "--" + f.name.replace("_", "-") in out
    assert "(default: 16)" in out and "(default: auto)" in out  # --help shows defaults
    for name in METHODS:
        assert f"{name}:" in out  # the methods' one-line summaries
    assert set(sidecar_types()) >= {"method", "spp", "photons", "k", "seed", "radius"}
    assert "checkpoint" not in sidecar_types()  # paths are flags only
    code, out, _ = run(capsys, ["--version"])
    assert code == 0 and out.strip() == f"dpm-render {__version__}"


def test_a_flag_the_method_does_not_read_is_an_error_but_a_sidecar_default_is_not(
    tmp_path: Path, capsys
) -> None:
    path = write_scene(tmp_path, toml="[render]\nk = 50\nradius = 0.5\nspp = 1\n")
    out = tmp_path / "o.exr"
    code, _, err = run(capsys, [str(path), "-o", str(out), "--quiet", "--method", "pt", "--k", "5"])
    assert code == 2 and "--k applies to pm, dpm, hybrid only" in err and not out.exists()
    stats = tmp_path / "s.json"
    argv = [str(path), "-o", str(out), "--quiet", "--method", "pt", "--stats", str(stats)]
    assert run(capsys, argv)[0] == 0  # the sidecar's k and radius are for other methods
    assert json.loads(stats.read_text())["spp"] == 1  # while its spp applies


def test_photons_zero_is_an_error_for_photon_methods(scene_path: Path, capsys) -> None:
    out = scene_path.parent / "o.png"
    for method in caustic_methods():
        argv = [str(scene_path), "-o", str(out), "--quiet", "--method", method, "--photons", "0"]
        code, _, err = run(capsys, argv)
        assert code == 2 and "--photons must be at least 1" in err and "pt-nocaustic" in err
        assert len(err.strip().splitlines()) == 1 and not out.exists()
    argv = [str(scene_path), "-o", str(out), "--quiet", "--method", "pt", "--photons", "0"]
    assert run(capsys, argv)[0] == 0  # the path tracers trace no photons


def test_k_defaults_to_the_weight_files_k(tmp_path: Path, capsys) -> None:
    from dpm.nn.model import make_model
    from dpm.nn.train import init_params
    from dpm.nn.weights import Weights, save_weights

    weights = tmp_path / "w.msgpack"
    save_weights(weights, Weights("dpm", 8, K, init_params(make_model("dpm", 8), K, 0)))
    stats = tmp_path / "s.json"
    argv = [str(EGG), "-o", str(tmp_path / "o.exr"), "--quiet", "--width", "8", "--height", "8",
            "--spp", "1", "--photons", "20000", "--method", "dpm", "--weights", str(weights),
            "--stats", str(stats)]  # fmt: skip
    assert run(capsys, argv)[0] == 0
    assert json.loads(stats.read_text())["k"] == K
    code, _, err = run(capsys, [*argv, "--k", "50"])
    assert code == 2 and f"trained with K = {K}, not 50" in err


def test_an_unwritable_output_is_refused_before_the_render(
    scene_path: Path, capsys, monkeypatch
) -> None:
    def no_render(*args, **kwargs):
        raise AssertionError("rendered before checking the outputs")

    monkeypatch.setattr("dpm.renderer.render", no_render)
    folder = scene_path.parent
    (folder / "taken.png").mkdir()
    for target, expected in (
        (folder / "taken.png", "is a folder"),
        (Path("/proc/dpm-out.png"), "cannot write there"),  # a read-only file system
        (folder / "missing" / "o.exr", "output folder does not exist"),
    ):
        code, _, err = run(capsys, [str(scene_path), "-o", str(target), "--quiet"])
        assert code == 2 and expected in err and len(err.strip().splitlines()) == 1, err
    code, _, err = run(capsys, [str(scene_path), "--stats", "/proc/s.json", "--quiet"])
    assert code == 2 and "cannot write there" in err
    assert sorted(p.name for p in folder.iterdir()) == ["scene.mtl", "scene.obj", "taken.png"]


def test_unknown_method_from_a_sidecar_is_one_line(tmp_path: Path, capsys) -> None:
    path = write_scene(tmp_path, toml="[render]\nmethod = 'magic'\n")
    code, _, err = run(capsys, [str(path), "-o", str(tmp_path / "o.png"), "--quiet"])
    assert code == 2 and "unknown method 'magic'" in err and len(err.strip().splitlines()) == 1


@pytest.mark.parametrize("name", ["pm", "ppm", "appm", "dpm"])
def test_make_estimator_builds_each_methods_estimator(name: str) -> None:
    params = {"k": K} if name in ("pm", "dpm") else {"radius": 0.1, "photons_per_pass": 10}
    if name == "dpm":
        params["k"] = 50  # a shipped model
    estimator = make_estimator(name, **params)
    assert callable(estimator.estimate)


def test_version_answers_without_importing_the_renderer() -> None:
    """`dpm-render --version` loads neither Numba, SciPy nor JAX (start-up time)."""
    code = (
        "import sys; from dpm.cli import render_main; assert render_main(['--version']) == 0; "
        "print(sorted(m for m in ('numba', 'scipy', 'jax', 'dpm.tracer') if m in sys.modules))"
    )
    done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
    assert done.returncode == 0, done.stderr
    assert done.stdout.splitlines() == [f"dpm-render {__version__}", "[]"]


def test_a_render_with_an_empty_kernel_cache_says_it_compiles(scene_path: Path, tmp_path) -> None:
    """One line on stderr when Numba's kernel cache is empty (checked in a subprocess: the
    render is refused right after, before compiling anything), none when it holds kernels."""
    argv = [sys.executable, "-m", "dpm.cli", str(scene_path), "-o", str(tmp_path / "o.png"),
            "--method", "pm", "--photons", "0"]  # fmt: skip
    cached = tmp_path / "cached" / "mirror" / "tracer"
    cached.mkdir(parents=True)
    (cached / "traverse.closest-1.py311.nbi").write_bytes(b"")
    said = {}
    for name, folder in (("empty", tmp_path / "empty"), ("cached", tmp_path / "cached")):
        env = dict(os.environ, NUMBA_CACHE_DIR=str(folder))
        done = subprocess.run(argv, capture_output=True, text=True, env=env)
        assert done.returncode == 2 and "--photons must be at least 1" in done.stderr
        said[name] = [line for line in done.stderr.splitlines() if "compiling" in line]
    assert len(said["empty"]) == 1 and said["empty"][0].startswith("dpm-render: compiling")
    assert said["cached"] == []
