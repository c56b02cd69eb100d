"""The unseen set's scaled copies: scored against their scale-1 twin, whose image they have.

`equal_time_unseen.scoring_reference` scores spheres_s0p01 and spheres_s100 against
spheres_s1's reference, on the physics that scaling every length and keeping the radiance
leaves the image unchanged. These check the mapping and that premise: dpm renders the three
copies alike with the same seed (the same random numbers drive the same paths).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np

sys.path.insert(0, str(Path(__file__).parent / "scenes"))
from make_unseen import unit_scale, unseen_scenes  # noqa: E402

from dpm import load_file, render  # noqa: E402


def test_a_scaled_copy_is_scored_against_its_unit_twin() -> None:
    assert unit_scale("spheres_s0p01") == unit_scale("spheres_s100") == "spheres_s1"
    assert unit_scale("spheres_s1") == "spheres_s1"
    assert unit_scale("lens_wall") == "lens_wall"
    assert unit_scale("control_huge") == "control_huge"  # scale 100, but no scale-1 twin


def test_the_scaled_copies_render_as_their_twin() -> None:
    paths = {p.stem: p for p in unseen_scenes()}
    images = {
        name: render(load_file(paths[name], width=32, height=32), method="pt", spp=4, seed=3)
        for name in ("spheres_s0p01", "spheres_s1", "spheres_s100")
    }
    twin = images["spheres_s1"]
    assert twin.mean() > 0.1
    for name in ("spheres_s0p01", "spheres_s100"):
        # nearly every path is the twin's: a few may part where float rounding differs
        same = np.isclose(images[name], twin, rtol=1e-3, atol=1e-4).all(axis=2).mean()
        assert same > 0.9, (name, same)
        assert abs(images[name].mean() / twin.mean() - 1) < 0.05, name


def test_the_examples_report_names_its_set_and_corrects_no_noise() -> None:
    """`equal_time_unseen.py --set examples`: the examples' references know their noise in
    luminance only, so their table has no noise-corrected ratio, and says which set it is."""
    import equal_time_unseen as e

    row = {"budget": 2.0, "dpm_s": 2.0, "passes": 4, "spp": 4, "plan": "p", "dpm_rmse": 0.1,
           "mitsuba_s": 2.0, "mitsuba_spp": 16, "mitsuba_plain_rmse": 0.4,
           "mitsuba_oidn_rmse": 0.2, "ratio": 0.5}  # fmt: skip
    record = {"scene": "glass_egg", "control": False, "size": "128x128", "variant": "v",
              "reference_noise_rgb": None, "reference_noise_luminance": 0.01,
              "reference_spp_per_half": None, "batch_spp": 16, "picture_budget": 2.0,
              "load_start": [0, 0, 0], "load_end": [0, 0, 0], "cpu": "c", "date": "d",
              "rows": [row]}  # fmt: skip
    text = e.report([record])
    assert "the examples (tuned on)" in text and "--set examples" in text
    assert "geometric mean of dpm / Mitsuba best 0.50" in text
    assert "not made: the references' noise is known in luminance only" in text
    assert "(equal_time_examples/glass_egg.png)" in text
