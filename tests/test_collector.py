"""`dpm.collector`: the garbage collector paused while dpm-render starts, then frozen and on."""

from __future__ import annotations

import gc

import pytest

from dpm import collector, load_file
from dpm.renderer import RenderOptions, render


@pytest.fixture
def collector_restored():
    """Leave the collector on and nothing frozen, whatever the test did."""
    yield
    collector._paused = False
    gc.enable()
    gc.unfreeze()


def test_resume_without_pause_changes_nothing(collector_restored) -> None:
    gc.unfreeze()
    collector.resume()
    assert gc.isenabled() and gc.get_freeze_count() == 0


def test_a_render_resumes_what_was_paused(collector_restored, scene_path) -> None:
    """auto's first pass (and any render's end) turns the collector back on, with what was
    alive then frozen; garbage made afterwards is collected."""
    gc.unfreeze()
    collector.pause()
    assert not gc.isenabled()
    options = RenderOptions(width=12, height=10, spp=2, photons=2000, progress=False)
    render(load_file(scene_path), options)
    assert gc.isenabled() and gc.get_freeze_count() > 0
    cycle: list = []
    cycle.append(cycle)
    del cycle
    assert gc.collect() >= 1
