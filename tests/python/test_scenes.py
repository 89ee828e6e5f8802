"""wmo.scenes builds the canonical scenes exactly as shared/SCENES.md specifies them
(counts, positions, masses, friction), and the extra scenes deterministically."""
from __future__ import annotations

import math

import numpy as np
import pytest

import wmo
from wmo import scenes


def dynamic_rows(world):
    return [i for i in range(len(world)) if world.body(i).kind == "dynamic"]


def test_boxes3000_matches_scenes_md():
    w = scenes.boxes3000()
    assert len(w) == 3009  # 47 x 64 boxes + the ground
    np.testing.assert_array_equal(w.gravity, (0, -10, 0))
    assert w.dt == pytest.approx(1 / 60)
    ground = w.body(0)
    assert ground.kind == "static"
    np.testing.assert_array_equal(ground.position, (0, -50, 0))
    rows = dynamic_rows(w)
    assert len(rows) == 3008
    pos = w.positions[rows]
    # Layer k at y = 2 + 3k, grid x, z = -12 - 0.35k + 3i.
    ks = np.round((pos[:, 1] - 2) / 3).astype(int)
    assert set(ks) == set(range(47))
    for k in (0, 1, 46):
        layer = pos[ks == k]
        assert len(layer) == 64
        expected = -12 - 0.35 * k + 3 * np.arange(8)
        np.testing.assert_allclose(np.unique(np.round(layer[:, 0], 9)), expected, atol=1e-9)
        np.testing.assert_allclose(np.unique(np.round(layer[:, 2], 9)), expected, atol=1e-9)
    assert pos[:, 1].max() == pytest.approx(140.0)
    top = pos[ks == 46]
    assert top[:, 0].min() == pytest.approx(-28.1) and top[:, 0].max() == pytest.approx(-7.1)
    for i in (rows[0], rows[-1]):
        b = w.body(i)
        assert b.mass == 2.0
    np.testing.assert_array_equal(w.orientations[rows], np.tile((0, 0, 0, 1), (3008, 1)))
    np.testing.assert_array_equal(w.linear_velocities, 0)


def test_pyramid_matches_scenes_md():
    w = scenes.pyramid()
    rows = dynamic_rows(w)
    assert len(rows) == 2870 == sum(n * n for n in range(1, 21))
    pos = w.positions[rows]
    assert pos[:, 1].min() == pytest.approx(0.5)  # base bottom faces on y = 0
    assert pos[:, 1].max() == pytest.approx(19.5)  # the single top box
    base = pos[np.isclose(pos[:, 1], 0.5)]
    assert len(base) == 400
    np.testing.assert_allclose(np.unique(base[:, 0]), np.arange(20) - 9.5)
    top = pos[np.isclose(pos[:, 1], 19.5)]
    np.testing.assert_allclose(top, [[0, 19.5, 0]])
    assert w.body(rows[0]).mass == 1.0


def test_pyramid_starts_with_the_specified_contact_graph():
    # SCENES.md: 15,600 touching face pairs for 20 layers (400 on the ground, 9880 box
    # on box, 5320 side by side), 4 points each. The same rules for 6 layers, one step
    # from rest: every face pair is found with 4 points. Diagonal neighbours within a
    # layer also touch, along one edge (distance 0, inside the speculative distance),
    # which gives a 2-point edge manifold each.
    w = scenes.pyramid(layers=6)  # 91 boxes
    w.step()
    sizes = [6 - k for k in range(6)]
    base = sizes[0] ** 2
    on_top = 4 * sum(n * n for n in sizes[1:])  # each box above the base rests on four
    side = sum(2 * n * (n - 1) for n in sizes)
    diagonal = sum(2 * (n - 1) ** 2 for n in sizes)
    assert (base, on_top, side) == (36, 220, 140)
    assert w.contact_count == 4 * (base + on_top + side) + 2 * diagonal


def test_tower_and_mixed_pile():
    w = scenes.tower(height=30)
    rows = dynamic_rows(w)
    assert len(rows) == 30
    np.testing.assert_allclose(w.positions[rows][:, 1], 0.5 + np.arange(30))
    assert not w.linear_velocities.any()  # at rest unless kicked
    kicked = scenes.tower(height=3, kick=0.01)
    rows = dynamic_rows(kicked)
    np.testing.assert_array_equal(kicked.linear_velocities[rows], [[0, 0, 0], [0, 0, 0], [0.01, 0, 0]])
    a = scenes.mixed_pile(count=60, seed=3)
    b = scenes.mixed_pile(count=60, seed=3)
    np.testing.assert_array_equal(a.positions, b.positions)  # deterministic by seed
    assert len(a) == 61
    c = scenes.mixed_pile(count=60, seed=4)
    assert not np.array_equal(a.positions, c.positions)
    assert all(a.body(i).mass > 0 for i in range(1, 61))


@pytest.mark.parametrize("call", [lambda: scenes.boxes3000(layers=0),
                                  lambda: scenes.pyramid(layers=0),
                                  lambda: scenes.tower(height=0),
                                  lambda: scenes.tower(kick=float("nan")),
                                  lambda: scenes.mixed_pile(count=0)])
def test_bad_scene_sizes_raise(call):
    with pytest.raises(ValueError):
        call()


def test_world_settings_pass_through():
    w = scenes.pyramid(layers=2, dt=1 / 120, substeps=8)
    assert w.dt == pytest.approx(1 / 120) and w.substeps == 8
    assert math.isclose(len(w), 1 + 4 + 1)


def test_closed_box_is_a_closed_system():
    # Six static walls and 40 moving bodies, no gravity, friction or sleeping: what the
    # energy tests and the accuracy benchmark's energy case need.
    w = scenes.closed_box()
    assert w.body_count == 46
    assert np.all(np.asarray(w.settings["gravity"]) == 0)
    assert not w.settings["sleeping"]
    assert w.kinetic_energy() > 100
    with pytest.raises(ValueError, match="count"):
        scenes.closed_box(count=0)
