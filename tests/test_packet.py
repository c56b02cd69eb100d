"""Packet traversal: each ray of a packet gets exactly the single-ray traversal's hit and
occlusion, whatever its packet's other rays do (coherent, incoherent, partly bad, ties)."""

from __future__ import annotations

import numpy as np
import pytest
from test_wide_bvh import adversarial_rays, grid_mesh, random_soup

from dpm.tracer import build_bvh
from dpm.tracer.packet import LANES, SWITCH, any_hit_packets, closest_hit_packets
from dpm.tracer.traverse import any_hit_batch, closest_hit_batch


def assert_packets_match_single(tri: np.ndarray, o: np.ndarray, d: np.ndarray, tmax) -> None:
    """Closest hits (t, triangle) and occlusion equal to the single-ray kernels' exactly."""
    bvh = build_bvh(tri)
    tm = np.ascontiguousarray(np.broadcast_to(np.asarray(tmax, np.float64), (len(o),)))
    t1, i1 = np.empty(len(o)), np.empty(len(o), np.int32)
    t2, i2 = np.empty(len(o)), np.empty(len(o), np.int32)
    f1 = closest_hit_batch(bvh.arrays, bvh.depth, o, d, tm, t1, i1)
    f2 = closest_hit_packets(bvh.arrays, bvh.depth, o, d, tm, t2, i2)
    assert f1 == f2
    np.testing.assert_array_equal(i2, i1)
    np.testing.assert_array_equal(t2, t1)
    b1, b2 = np.empty(len(o), np.bool_), np.empty(len(o), np.bool_)
    assert any_hit_batch(bvh.arrays, bvh.depth, o, d, tm, b1) == f1
    assert any_hit_packets(bvh.arrays, bvh.depth, o, d, tm, b2) == f1
    np.testing.assert_array_equal(b2, b1)


def coherent_rays(rng: np.random.Generator, n_packets: int, spread: float):
    """Packets of LANES rays from one point each, directions within `spread` of one another
    (camera samples of a pixel, a point's shadow rays), so whole packets enter nodes."""
    centre = rng.uniform(-3, 3, (n_packets, 1, 3))
    aim = rng.uniform(-0.8, 0.8, (n_packets, 1, 3)) - centre
    o = np.broadcast_to(centre, (n_packets, LANES, 3)).reshape(-1, 3).copy()
    d = (aim + spread * rng.normal(size=(n_packets, LANES, 3))).reshape(-1, 3)
    return np.ascontiguousarray(o), np.ascontiguousarray(d)


@pytest.mark.parametrize("spread", [0.0, 0.01, 0.3, 3.0])
@pytest.mark.parametrize("n_tri", [1, 37, 5000])
def test_packets_equal_single_rays(n_tri: int, spread: float) -> None:
    """Coherent to incoherent packets (the spread of their directions) on random soups, with
    and without a limit; the lanes that go on alone (SWITCH) are among them."""
    assert SWITCH < LANES
    rng = np.random.default_rng(n_tri)
    tri = random_soup(rng, n_tri)
    o, d = coherent_rays(rng, 300, spread)
    assert_packets_match_single(tri, o, d, np.inf)
    assert_packets_match_single(tri, o, d, rng.uniform(0.0, 6.0, len(o)))


def test_packets_equal_single_rays_on_adversarial_rays() -> None:
    """Ties between neighbours on a grid (rays along edges, through vertices, ±0 direction
    components, starting on triangles): the lower triangle wins in both traversals."""
    rng = np.random.default_rng(5)
    tri = grid_mesh(12)
    o, d = adversarial_rays(rng, tri, 20_000)
    assert_packets_match_single(tri, o, d, np.inf)
    g = np.arange(0, 12.5, 0.5)  # straight down through every vertex and edge midpoint
    xy = np.stack(np.meshgrid(g, g), -1).reshape(-1, 2)
    o = np.column_stack([xy, np.ones(len(xy))])
    d = np.tile([0.0, -0.0, -1.0], (len(o), 1))
    assert_packets_match_single(tri, o, d, np.inf)


def test_bad_rays_leave_their_packet_alone() -> None:
    """A NaN origin or zero direction in a packet is flagged as the single kernels flag it,
    gets no hit, and the packet's other rays are traced as usual; a short last packet too."""
    rng = np.random.default_rng(1)
    tri = random_soup(rng, 200)
    o, d = coherent_rays(rng, 4, 0.05)
    o[3] = np.nan
    d[LANES + 2] = 0.0
    o, d = o[:-5], d[:-5]  # the last packet is not full
    assert_packets_match_single(tri, o, d, np.inf)


@pytest.mark.parametrize("spread", [0.01, 0.3])
def test_coincident_triangles_tie_the_same_way(spread: float) -> None:
    """Every triangle twice (a copy in another leaf, often), so every hit is an exact tie:
    the packet and the single ray, visiting leaves in different orders, still agree."""
    rng = np.random.default_rng(11)
    soup = random_soup(rng, 400)
    tri = np.concatenate([soup, soup[rng.permutation(len(soup))]])
    o, d = coherent_rays(rng, 400, spread)
    assert_packets_match_single(tri, o, d, np.inf)
