"""The staged path tracer of diffuse scenes (`dpm.tracer.wavefront`) against `path_pixel`.

Both make the same decisions from the same random numbers in the same arithmetic, so their
per-pixel sums must be equal to the bit, however the paths are batched.
"""

from __future__ import annotations

from pathlib import Path

import numba
import numpy as np
import pytest
from test_textures import textured_scene

from dpm import load_scene
from dpm.tracer import build_bvh
from dpm.tracer.path import _wavefront, listed_kernel, pixels_kernel, trace_listed
from dpm.tracer.traverse import spawn_offset
from dpm.tracer.wavefront import batch_starts

CORNELL = Path(__file__).parent.parent / "examples" / "scenes" / "cornell_box.obj"


@pytest.fixture(scope="module")
def cornell():
    scene = load_scene(CORNELL)
    return scene, build_bvh(scene), scene.camera.with_resolution(24, 24)


def megakernel_pixels(scene, bvh, camera, spp, seed, sequence):
    """`pixels_kernel`'s (P, 9) means of radiance, albedo and normal, (P,) sums of squared
    luminance, visible points and non-finite samples."""
    p = camera.width * camera.height
    image, albedo, normal = (np.empty((p, 3)) for _ in range(3))
    square = np.empty(p)
    qseed, first = sequence
    args = (camera.width, camera.height, 0, camera.height, spp, seed, qseed, first)
    hits, bad = pixels_kernel(
        bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), *args,
        spawn_offset(scene), True, image, albedo, normal, square,
    )  # fmt: skip
    return np.concatenate([image, albedo, normal], axis=1), square, hits, bad


@pytest.mark.parametrize("sequence", [(-1, 0), (11, 0), (11, 5)])
def test_whole_pixels_equal_the_megakernels_to_the_bit(cornell, sequence) -> None:
    scene, bvh, camera = cornell
    assert scene.all_diffuse
    spp, p = 5, camera.width * camera.height
    means, square, hits, bad = megakernel_pixels(scene, bvh, camera, spp, 3, sequence)
    pixels = np.arange(p)
    staged = _wavefront(
        scene, bvh, camera, pixels, np.zeros(p), np.full(p, spp), np.full(p, sequence[1]),
        spp, 3, sequence[0], True,
    )  # fmt: skip
    np.testing.assert_array_equal(staged[:, :9] / spp, means)  # (as `trace_pixels` divides)
    np.testing.assert_array_equal(staged[:, 11], square)
    assert staged[:, 9].sum() == hits and staged[:, 10].sum() == bad
    assert hits == p * spp  # (the box fills the view; misses: the textured floor below)


@pytest.mark.parametrize("emission", [True, False])
def test_listed_paths_equal_the_megakernels_to_the_bit(cornell, emission) -> None:
    scene, bvh, camera = cornell
    rng = np.random.default_rng(0)
    pixels = rng.choice(camera.width * camera.height, 40, replace=False)
    firsts, counts = rng.integers(0, 9, 40), rng.integers(1, 30, 40)
    qfirsts = rng.integers(0, 50, 40)
    for qseed in (-1, 7):
        out, sq = np.zeros((40, 3)), np.zeros(40)
        bad = listed_kernel(
            bvh.arrays, bvh.depth, scene.kernel_arrays(), camera.basis(), camera.width,
            camera.height, pixels, firsts, counts, 31, 5, qseed, qfirsts, spawn_offset(scene),
            emission, None, out, sq,
        )  # fmt: skip
        staged = _wavefront(
            scene, bvh, camera, pixels, firsts, counts, qfirsts, 31, 5, qseed, emission
        )
        np.testing.assert_array_equal(staged[:, :3], out)
        np.testing.assert_array_equal(staged[:, 11], sq)
        assert staged[:, 10].sum() == bad


def test_a_textured_floor_equals_the_megakernel(tmp_path) -> None:
    texture = np.random.default_rng(1).integers(0, 256, (8, 8, 3), dtype=np.uint8)
    scene = load_scene(textured_scene(tmp_path, texture))
    camera = scene.camera.with_resolution(16, 16)
    bvh = build_bvh(scene)
    means, square, hits, _ = megakernel_pixels(scene, bvh, camera, 4, 9, (-1, 0))
    p = camera.width * camera.height
    staged = _wavefront(
        scene, bvh, camera, np.arange(p), np.zeros(p), np.full(p, 4), np.zeros(p), 4, 9, -1,
        True,
    )  # fmt: skip
    np.testing.assert_array_equal(staged[:, :9] / 4, means)
    np.testing.assert_array_equal(staged[:, 11], square)
    assert 0 < hits < 4 * p  # some paths see the floor, some miss it


def test_batches_and_threads_do_not_change_the_sums(cornell, monkeypatch) -> None:
    scene, bvh, camera = cornell
    p = camera.width * camera.height
    args = (np.arange(p), np.zeros(p), np.full(p, 3), np.zeros(p), 3, 2, 4, True)
    first = _wavefront(scene, bvh, camera, *args)
    import dpm.tracer.wavefront as wavefront

    monkeypatch.setattr(wavefront, "BATCH", 7)  # batches of a few pixels
    assert len(batch_starts(np.full(p, 3), 1)) - 1 > p // 3
    numba.set_num_threads(1)
    try:
        np.testing.assert_array_equal(_wavefront(scene, bvh, camera, *args), first)
    finally:
        numba.set_num_threads(numba.config.NUMBA_NUM_THREADS)


def test_listed_paths_of_a_diffuse_scene_take_the_stages(cornell, monkeypatch) -> None:
    # trace_listed sends a scene without mirrors or glass to the stages: they give the
    # megakernel's sums, so the only way to tell is to take the stages away
    scene, bvh, camera = cornell
    pixels, counts = np.array([3, 50, 300]), np.array([4, 2000, 1])
    staged = trace_listed(scene, bvh, camera, pixels, counts, 8)

    import dpm.tracer.path as path

    def refuse(*args):
        raise AssertionError("the stages were taken")

    monkeypatch.setattr(path, "_wavefront", refuse)
    with pytest.raises(AssertionError, match="stages were taken"):
        trace_listed(scene, bvh, camera, pixels, counts, 8)
    monkeypatch.setattr(type(scene), "all_diffuse", property(lambda self: False))
    plain = trace_listed(scene, bvh, camera, pixels, counts, 8)
    for a, b in zip(staged, plain, strict=True):
        np.testing.assert_array_equal(a, b)
