"""Hard cases of the world (issue 3, section 5), each with its threshold and why.

Known failures are pinned as strict xfails with what was measured, so they turn into
passes (and fail the xfail) the day the solver is fixed, and cannot be forgotten."""
from __future__ import annotations

import hashlib

import numpy as np
import pytest

import wmo
from wmo import scenes


def state_hash(world) -> str:
    h = hashlib.sha256()
    for a in (world.positions, world.orientations, world.linear_velocities, world.angular_velocities):
        h.update(np.ascontiguousarray(a).tobytes())
    return h.hexdigest()


def test_determinism_same_scene_twice_gives_the_same_bits():
    # Box2D's determinism test: the same inputs and settings give the same bits.
    hashes = []
    for _ in range(2):
        w = scenes.mixed_pile(count=60, seed=11)
        w.step(300)
        hashes.append(state_hash(w))
    assert hashes[0] == hashes[1]
    w = scenes.mixed_pile(count=60, seed=12)
    w.step(300)
    assert state_hash(w) != hashes[0]  # the hash does see the state


@pytest.mark.parametrize("seed", [1, 2, 3])
def test_random_scenes_never_produce_nan_or_escape(seed):
    # 10,000 steps of a random pile (spheres, capsules, hulls) dropped into a closed
    # box of static walls, sleeping off so every body is simulated every step. Nothing
    # may become NaN or infinite, and no body may leave the container (walls 0.5 m
    # thick: a body outside them tunnelled or exploded).
    w = scenes.mixed_pile(count=30, seed=seed, sleeping=False)
    for x, z, hx, hz in ((6.5, 0, 0.5, 7), (-6.5, 0, 0.5, 7), (0, 6.5, 7, 0.5), (0, -6.5, 7, 0.5)):
        w.add_body(wmo.Box((hx, 10, hz)), position=(x, 10, z), kind="static")
    w.add_body(wmo.Box((7, 0.5, 7)), position=(0, 20.5, 0), kind="static")  # lid
    rng = np.random.default_rng(seed)
    dyn = [i for i in range(len(w)) if w.body(i).kind == "dynamic"]
    for block in range(20):
        # Kick a few bodies now and then (about 5 m/s: fast bodies tunnel through 1 m walls
    # without CCD, which is issue 4) so the pile never just settles.
        for i in rng.choice(dyn, size=3, replace=False):
            b = w.body(int(i))
            w.apply_impulse(b, rng.normal(size=3) * 5 * b.mass, b.position)
        w.step(500)
        for a in (w.positions, w.orientations, w.linear_velocities, w.angular_velocities):
            assert np.isfinite(a).all(), f"non-finite state after {500 * (block + 1)} steps"
        p = w.positions[dyn]
        assert (np.abs(p[:, [0, 2]]) < 6.0).all() and (p[:, 1] > -0.1).all() and (p[:, 1] < 20.0).all(), \
            f"a body left the container after {500 * (block + 1)} steps"


def closed_frictionless_box():
    """No gravity, no friction, no restitution, no damping: 40 spheres and boxes fired
    around a closed container of static walls."""
    w = wmo.World(gravity=(0, 0, 0), sleeping=False)
    for x, z, hx, hz in ((5.5, 0, 0.5, 6), (-5.5, 0, 0.5, 6), (0, 5.5, 6, 0.5), (0, -5.5, 6, 0.5)):
        w.add_body(wmo.Box((hx, 6, hz)), position=(x, 0, z), kind="static", friction=0.0)
    for y in (-5.5, 5.5):
        w.add_body(wmo.Box((6, 0.5, 6)), position=(0, y, 0), kind="static", friction=0.0)
    rng = np.random.default_rng(5)
    for i in range(40):
        shape = wmo.Sphere(0.3) if i % 2 else wmo.Box((0.3, 0.25, 0.35))
        w.add_body(shape, position=(-4 + 2 * (i % 5), -4 + 2 * ((i // 5) % 5), -3 + 2 * (i // 25)),
                   linear_velocity=rng.normal(size=3) * 3, angular_velocity=rng.normal(size=3),
                   friction=0.0)
    return w


def test_energy_never_exceeds_what_the_system_started_with():
    # Contacts can only remove kinetic energy (inelastic impacts): at no step may the
    # energy exceed the initial energy (1e-12 relative: round-off of the sum). Over 600
    # steps the impacts remove almost all of it.
    w = closed_frictionless_box()
    e0 = w.kinetic_energy()
    assert e0 > 100
    for k in range(600):
        w.step()
        assert w.kinetic_energy() <= e0 * (1 + 1e-12), f"energy above the start at step {k + 1}"
    assert w.kinetic_energy() < 0.05 * e0


@pytest.mark.xfail(strict=True, reason="issue 3, open: the soft contacts release stored spring energy, "
                   "so 7 of 600 steps gain kinetic energy (at most 1.9e-7 relative, measured)")
def test_energy_never_increases_from_one_step_to_the_next():
    # The demand, step by step: 1e-12 relative allows round-off of the sum.
    w = closed_frictionless_box()
    e = w.kinetic_energy()
    for k in range(600):
        w.step()
        e_next = w.kinetic_energy()
        assert e_next <= e * (1 + 1e-12), f"energy rose from {e} to {e_next} at step {k + 1}"
        e = e_next


@pytest.mark.xfail(strict=True, reason="issue 3, open: with the default soft step (4 substeps x 1 "
                   "iteration, 30 Hz) a 30-box tower sags 0.25 m and then buckles sideways, growing "
                   "exponentially (measured: 43 m of displacement by 6000 steps; frictionless "
                   "2-box stacks already drift 1 mm in 5 s)")
def test_tower_of_30_stands_for_6000_steps():
    # Threshold 1 cm: a standing tower's boxes move by their contacts' sag only.
    w = scenes.tower(30, sleeping=False)
    p0 = np.array(w.positions)
    w.step(6000)
    assert np.linalg.norm(w.positions - p0, axis=1).max() < 0.01


def test_projectile_follows_the_integrators_closed_form():
    # Semi-implicit Euler with h = dt / substeps: v_k = v0 + k h g and
    # x_k = x0 + k h v0 + h^2 g k (k + 1) / 2, exactly up to rounding (1e-9 m over
    # 2400 substeps of metre-scale sums).
    w = wmo.World(gravity=(0, -9.81, 0), dt=1 / 60, substeps=4, sleeping=False)
    b = w.add_body(wmo.Sphere(0.1), position=(1, 2, 3), linear_velocity=(3, 4, -1))
    w.step(600)
    k, h = 2400, 1 / 240
    g = np.array([0, -9.81, 0])
    x = np.array([1, 2, 3]) + k * h * np.array([3, 4, -1]) + h * h * g * k * (k + 1) / 2
    np.testing.assert_allclose(b.position, x, atol=1e-9)
    np.testing.assert_allclose(b.linear_velocity, np.array([3, 4, -1]) + k * h * g, atol=1e-9)
