"""nppm: the shaped kernel's normalisation, PPM from a fresh network, consistency whatever the
network says, invariances, resuming."""

from __future__ import annotations

from pathlib import Path

import numpy as np
import pytest
from scipy.integrate import dblquad
from test_density import egg, plane_photons, plane_points, relative_error  # noqa: F401

from dpm.density.progressive import run_passes
from dpm.density.shaped import P_MAX, P_MIN, normaliser, relative_weight
from dpm.errors import InputError
from dpm.estimators import PPM
from dpm.estimators.nppm import NPPM
from dpm.nn.model import make_model
from dpm.nn.train import init_params
from dpm.nn.weights import Weights, save_weights

PLANE = dict(radius=0.08)


def network(path: Path, scale: float = 0.0, bias: tuple[float, float] = (0.0, 0.0)) -> str:
    """A weight file of an nppm network whose last layer is random × scale plus bias."""
    model = make_model("nppm", 16)
    params = init_params(model, 1, 0, "nppm")
    last = params["params"]["Dense_2"]
    rng = np.random.default_rng(7)
    last["kernel"] = scale * rng.standard_normal(last["kernel"].shape).astype(np.float32)
    last["bias"] = np.asarray(bias, np.float32)
    save_weights(path, Weights("nppm", 16, 1, params))
    return str(path)


@pytest.mark.parametrize("p1, p2", [(0.0, 0.0), (P_MAX, 0.0), (P_MAX, P_MIN), (5.0, 17.0)])
def test_the_kernel_integrates_to_one_over_the_disc(p1: float, p2: float) -> None:
    def integrand(r: float, t: float) -> float:
        a, b = np.array([r * np.cos(t)]), np.array([r * np.sin(t)])
        return float(relative_weight(a, b, np.array([p1]), np.array([p2]))[0]) * r / np.pi

    total, _ = dblquad(integrand, 0, 2 * np.pi, 0, 1, epsabs=1e-12, epsrel=1e-12)
    assert total == pytest.approx(1.0, abs=1e-10)
    centre = relative_weight(np.zeros(1), np.zeros(1), np.array([p1]), np.array([p2]))
    assert 0 < centre[0] <= 13


def test_the_uniform_kernel_is_exactly_one() -> None:
    a = np.linspace(-0.7, 0.7, 11)
    np.testing.assert_array_equal(relative_weight(a, a[::-1], 0 * a, 0 * a), np.ones(11))
    assert normaliser(np.zeros(1), np.zeros(1))[0] == np.pi


def test_a_fresh_network_is_ppm_bit_for_bit(tmp_path: Path) -> None:
    points, photons = plane_points(), plane_photons(100_000, 1)
    fresh = network(tmp_path / "fresh.msgpack")
    ppm = PPM(photons_per_pass=5_000, **PLANE).estimate(points, photons)
    nppm = NPPM(photons_per_pass=5_000, weights=fresh, **PLANE).estimate(points, photons)
    np.testing.assert_array_equal(nppm, ppm)


@pytest.mark.parametrize(
    "scale, bias", [(3.0, (0.0, 0.0)), (0.0, (60.0, 60.0)), (0.0, (60.0, -60.0))],
    ids=["random", "narrowest", "anisotropic"],
)  # fmt: skip
def test_nppm_converges_whatever_the_network_says(tmp_path: Path, scale, bias) -> None:
    weights = network(tmp_path / "w.msgpack", scale, bias)
    points = plane_points()
    errors = [
        relative_error(
            points,
            NPPM(photons_per_pass=n // 20, weights=weights, **PLANE).estimate(
                points, plane_photons(n, 1)
            ),
        )
        for n in (10_000, 100_000, 1_000_000)
    ]
    assert errors[0] > errors[1] > errors[2], errors
    assert errors[2] < 0.05, errors


def turned(photons, angle: float, mirror: bool = False):
    """The plane's photons turned by `angle` about the vertical through (0.5, 0.5)."""
    xy = photons.position[:, :2].astype(np.float64) - 0.5
    if mirror:
        xy[:, 1] *= -1
    c, s = np.cos(angle), np.sin(angle)
    out = photons.select(np.ones(len(photons), bool))
    out.position[:, :2] = (xy @ np.array([[c, s], [-s, c]]) + 0.5).astype(np.float32)
    d = photons.direction[:, :2].astype(np.float64) * [1, -1 if mirror else 1]
    out.direction[:, :2] = (d @ np.array([[c, s], [-s, c]])).astype(np.float32)
    return out


@pytest.mark.parametrize("angle, mirror", [(0.7, False), (np.pi / 2, False), (0.0, True)])
def test_turning_or_mirroring_the_scene_changes_nothing(tmp_path: Path, angle, mirror) -> None:
    """The features and the kernel live in each point's principal axes, so the estimate does
    not depend on how the tangent frame happens to lie (points on a symmetric grid)."""
    weights = network(tmp_path / "w.msgpack", 3.0)
    rng = np.random.default_rng(0)
    photons = plane_photons(50_000, 2)
    photons.direction[:] = rng.normal(size=(len(photons), 3)).astype(np.float32)
    points = plane_points(9)  # centred on (0.5, 0.5): turned by π/2 or mirrored, the same set
    nppm = NPPM(photons_per_pass=5_000, weights=weights, **PLANE)
    base = nppm.estimate(points, photons)
    moved = nppm.estimate(points, turned(photons, angle, mirror))
    order = grid_order(points, angle, mirror)
    if order is not None:
        np.testing.assert_allclose(moved[order], base, rtol=1e-4, atol=1e-7)
    assert not np.allclose(base, PPM(photons_per_pass=5_000, **PLANE).estimate(points, photons))
    scaled = photons.select(np.ones(len(photons), bool))
    scaled.flux[:] *= 3
    np.testing.assert_allclose(nppm.estimate(points, scaled), 3 * base, rtol=1e-5)


def grid_order(points, angle: float, mirror: bool) -> np.ndarray | None:
    """For each point, the index of the point it moves to (None when the grid is not kept)."""
    xy = points.position[:, :2].astype(np.float64) - 0.5
    if mirror:
        xy[:, 1] *= -1
    c, s = np.cos(angle), np.sin(angle)
    moved = xy @ np.array([[c, s], [-s, c]]) + 0.5
    dist = np.linalg.norm(moved[:, None] - points.position[None, :, :2], axis=2)
    order = dist.argmin(axis=1)
    return order if dist.min(axis=1).max() < 1e-5 else None


def test_a_resumed_nppm_run_ends_bit_identical(egg, tmp_path: Path) -> None:  # noqa: F811
    scene, bvh, points = egg
    nppm = NPPM(radius=0.05, photons_per_pass=50_000, weights=network(tmp_path / "w", 3.0))
    whole, _ = run_passes(nppm, scene, bvh, points, 300_000, seed=3)
    checkpoint = tmp_path / "run.npz"
    part, state = run_passes(nppm, scene, bvh, points, 300_000, 3, checkpoint, stop_after=2)
    assert state.passes == 2 and not np.array_equal(part, whole)
    resumed, state = run_passes(nppm, scene, bvh, points, 300_000, 3, checkpoint)
    assert state.passes == 6
    np.testing.assert_array_equal(resumed, whole)


def test_a_missing_or_foreign_weight_file_is_refused(tmp_path: Path) -> None:
    with pytest.raises(InputError, match="not found"):
        NPPM(weights=str(tmp_path / "none.msgpack")).check()
    dpm = tmp_path / "dpm.msgpack"
    model = make_model("dpm", 8)
    save_weights(dpm, Weights("dpm", 8, 4, init_params(model, 4, 0)))
    with pytest.raises(InputError, match="not an nppm"):
        NPPM(weights=str(dpm)).check()
    (tmp_path / "bad.msgpack").write_bytes(b"junk")
    with pytest.raises(InputError, match="not a dpm weight file"):
        NPPM(weights=str(tmp_path / "bad.msgpack")).check()


def test_dpm_render_nppm_with_a_fresh_network_is_ppm(tmp_path: Path, capsys) -> None:
    from dpm.cli import render_main
    from dpm.io import read_exr

    scene = Path(__file__).parent.parent / "examples" / "scenes" / "glass_egg.obj"
    # one given radius: nppm's default disc starts wider than PPM's
    base = [str(scene), "--quiet", "--width", "16", "--height", "16", "--spp", "1",
            "--photons", "40000", "--photons-per-pass", "10000", "--radius", "0.05"]  # fmt: skip
    fresh = network(tmp_path / "fresh.msgpack")
    for method, extra in (("ppm", []), ("nppm", ["--weights", fresh])):
        out = tmp_path / f"{method}.exr"
        assert render_main([*base, "-o", str(out), "--method", method, *extra]) == 0
    np.testing.assert_array_equal(read_exr(tmp_path / "nppm.exr"), read_exr(tmp_path / "ppm.exr"))
    (tmp_path / "bad.msgpack").write_bytes(b"junk")
    out = tmp_path / "bad.png"
    code = render_main(
        [*base, "-o", str(out), "--method", "nppm", "--weights", str(tmp_path / "bad.msgpack")]
    )
    err = capsys.readouterr().err
    assert code == 2 and "not a dpm weight file" in err and len(err.strip().splitlines()) == 1
    assert not out.exists()
