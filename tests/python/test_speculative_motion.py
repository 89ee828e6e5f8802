"""Speculative margins that grow with the approach (World(speculative_motion=...)).

Each case runs with the fixed margin alone first and asserts the failure there (the
body tunnels, or sinks in), so the test shows what the setting changes."""
import numpy as np
import pytest

import wmo


def _shoot_at_plate(speed, motion, radius=0.05, half_thickness=0.005, static=0.0):
    """A sphere fired straight down at a static plate 1 cm thick (no gravity, dt 1/60);
    returns the sphere's lowest centre height and its final velocity. `static` is
    speculative_motion_static (0 here unless given: the plate is static, so its
    default, 1, would stop the sphere whatever `motion` is)."""
    w = wmo.World(gravity=(0, 0, 0), speculative_motion=motion, speculative_motion_static=static,
                  sleeping=False)
    w.add_body(wmo.Box((1, half_thickness, 1)), kind="static")
    b = w.add_body(wmo.Sphere(radius), position=(0, 3.0, 0), linear_velocity=(0, -speed, 0), mass=1.0)
    lowest = np.inf
    for _ in range(120):
        w.step()
        lowest = min(lowest, b.position[1])
    return lowest, np.asarray(b.linear_velocity).copy()


@pytest.mark.parametrize("speed", [50.0, 500.0])
def test_fast_sphere_stops_at_a_thin_plate(speed):
    # 50 m/s covers 0.83 m a step, 500 m/s 8.3 m: both far more than the plate (1 cm)
    # plus the fixed 4 cm margin, so without motion margins the sphere passes through.
    lowest, _ = _shoot_at_plate(speed, 0.0)
    assert lowest < -1.0
    # Stopped on the plate's top face (y = 0.005 + radius 0.05), never behind it; the
    # soft contact lets it settle into the surface by at most a millimetre: with the
    # margin for every pair, and with the one for pairs with static geometry alone.
    for motion, static in ((1.0, 0.0), (0.0, 1.0)):
        lowest, v = _shoot_at_plate(speed, motion, static=static)
        assert lowest == pytest.approx(0.055, abs=1e-3)
        np.testing.assert_allclose(v, 0.0, atol=1e-6)


@pytest.mark.parametrize("floor", ["box", "mesh"])
def test_ball_falling_faster_than_the_fixed_margin_lands_on_a_thin_floor(floor):
    # dt 1/30, dropped from 10 m: 14 m/s, 0.47 m a step at the floor. Its centre was
    # 0.386 m above the floor at one step (0.146 m between the broadphase boxes) and
    # below it at the next, so the pair never existed and it fell through (every time,
    # a 2 cm box or a two-triangle mesh) until the broadphase boxes were swept by the
    # static motion margin: the pair is found the step before, the speculative contact
    # stops the ball on the floor.
    for static in (0.0, 1.0):
        w = wmo.World(gravity=(0, -9.81, 0), dt=1 / 30, speculative_motion_static=static)
        if floor == "box":
            w.add_body(wmo.Box((8, 0.01, 8)), position=(0, -0.01, 0), kind="static")
        else:
            v = [(-8, 0, -8), (8, 0, -8), (8, 0, 8), (-8, 0, 8)]
            w.add_body(wmo.TriangleMesh(v, [(0, 2, 1), (0, 3, 2)]), kind="static")
        b = w.add_body(wmo.Sphere(0.2), position=(0, 10, 0))
        w.step(90)
        if static == 0.0:
            assert b.position[1] < -10
        else:
            assert b.position[1] == pytest.approx(0.2, abs=2e-3)


def test_fast_spheres_meeting_head_on_collide():
    # 300 m/s each, 10 m apart: they close 10 m in one step, so without motion margins
    # they never see each other; with them they meet (equal masses, no restitution:
    # both stop, touching).
    for motion in (0.0, 1.0):
        w = wmo.World(gravity=(0, 0, 0), speculative_motion=motion, sleeping=False)
        a = w.add_body(wmo.Sphere(0.05), position=(-5, 0, 0), linear_velocity=(300, 0, 0), mass=1.0)
        b = w.add_body(wmo.Sphere(0.05), position=(5, 0, 0), linear_velocity=(-300, 0, 0), mass=1.0)
        w.step(60)
        if motion == 0.0:
            assert a.position[0] > 100 and b.position[0] < -100  # passed through each other
        else:
            assert b.position[0] - a.position[0] == pytest.approx(0.1, abs=1e-3)
            np.testing.assert_allclose([a.linear_velocity[0], b.linear_velocity[0]], 0.0, atol=1e-6)


def test_falling_ball_does_not_sink_before_its_contact_exists():
    # A ball dropped from 1 m reaches 4.5 m/s, 7.5 cm a step at dt 1/60: with the fixed
    # 4 cm margin alone its contact appears only after it has sunk (measured 1.25 cm);
    # with a motion margin, for all pairs or (the default) for pairs with static
    # geometry, the contact exists a step ahead and stops it at the surface.
    deepest = {}
    for motion, static in ((0.0, 0.0), (1.0, 0.0), (0.0, 1.0)):
        w = wmo.World(gravity=(0, -10, 0), speculative_motion=motion, speculative_motion_static=static)
        w.add_body(wmo.Box((5, 1, 5)), position=(0, -1, 0), kind="static")
        b = w.add_body(wmo.Sphere(0.1), position=(0, 1.1, 0))
        lowest = np.inf
        for _ in range(60):
            w.step()
            lowest = min(lowest, b.position[1] - 0.1)
        deepest[motion, static] = -lowest
    assert deepest[0.0, 0.0] > 0.01
    assert deepest[1.0, 0.0] < 1e-3
    assert deepest[0.0, 1.0] < 1e-3
    assert wmo.World().settings["speculative_motion_static"] == 1.0


def test_bodies_at_rest_get_the_same_contacts():
    # Motion margins scale with velocity: a resting stack makes the same contacts.
    counts = []
    for motion in (0.0, 1.0):
        w = wmo.scenes.tower(5, speculative_motion=motion, sleeping=False)
        w.step(30)
        counts.append(len(w.contacts["depth"]))
    assert counts[0] == counts[1] > 0


def test_negative_motion_margin_is_rejected():
    with pytest.raises(ValueError, match="speculative_motion"):
        wmo.World(speculative_motion=-1.0)
    with pytest.raises(ValueError, match="speculative_motion"):
        wmo.World(speculative_motion=float("nan"))
