"""Manifold reuse (World(manifold_reuse_distance=..., manifold_reuse_angle=...)): a
touching pair whose relative pose moved less than the tolerances keeps its manifold."""
import numpy as np
import pytest

import wmo


def _box_on_ground(**kw):
    w = wmo.World(gravity=(0, -10, 0), sleeping=False, **kw)
    w.add_body(wmo.Box((5, 0.5, 5)), position=(0, -0.5, 0), kind="static")
    b = w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 0.5, 0), mass=2.0)
    return w, b


def test_resting_pair_reuses_its_manifold_and_still_carries_the_weight():
    w, b = _box_on_ground()
    w.step(60)
    assert w.reused_manifolds == 1  # the only pair, at rest
    # The reused contact still holds the box: the normal impulses are its weight per step.
    assert w.contacts["normal_impulse"].sum() * 4 == pytest.approx(2.0 * 10 / 60, rel=1e-3)
    assert abs(b.position[1] - 0.5) < 1e-3
    # Off: recomputed every step, the same rest.
    w0, b0 = _box_on_ground(manifold_reuse_distance=0.0)
    w0.step(60)
    assert w0.reused_manifolds == 0
    assert abs(b0.position[1] - b.position[1]) < 1e-4


def _reused_after_setting(**velocity):
    w, b = _box_on_ground()
    w.step(10)
    for name, value in velocity.items():
        setattr(b, name, value)
    # The narrowphase runs on the poses at the step's start, so a velocity written now
    # moves the pair only in the step after.
    w.step(2)
    return w.reused_manifolds


@pytest.mark.parametrize("velocity, reused", [
    ({"linear_velocity": (2.0, 0.0, 0.0)}, 0),   # 33 mm a step, beyond the 1 mm tolerance
    ({"angular_velocity": (0.0, 3.0, 0.0)}, 0),  # 2.9 degrees a step, beyond 2
    ({"angular_velocity": (0.0, 0.5, 0.0)}, 1),  # 0.5 degrees a step, within: reused
])
def test_moving_pairs_are_recomputed(velocity, reused):
    assert _reused_after_setting(**velocity) == reused


def test_reuse_does_not_make_a_tower_drift():
    # A 10-box tower settles 1.8 cm under its own weight (soft contacts) and sways
    # sideways at the millimetre level over 300 steps either way; reuse must settle it
    # the same and not make it drift farther sideways.
    drift, settle = [], []
    for reuse in (0.0, 1e-3):
        w = wmo.scenes.tower(10, sleeping=False, manifold_reuse_distance=reuse)
        start = np.asarray(w.positions).copy()
        w.step(300)
        moved = np.asarray(w.positions) - start
        drift.append(np.linalg.norm(moved[:, [0, 2]], axis=1).max())
        settle.append(moved[:, 1].copy())
        if reuse:
            assert w.reused_manifolds > 0
    assert drift[1] <= drift[0] + 1e-3
    np.testing.assert_allclose(settle[1], settle[0], atol=1e-3)


def test_bad_tolerances_are_rejected():
    for name in ("manifold_reuse_distance", "manifold_reuse_angle"):
        with pytest.raises(ValueError, match=name):
            wmo.World(**{name: -1.0})


def test_a_pair_keeps_its_cached_manifold_while_its_body_sleeps():
    # A sleeping body's pairs are not collided, and their cache entries are kept (Box2D
    # keeps a sleeping island's contacts too): on waking, the first step reuses the
    # manifold (the pose has not moved) and warm starts from the impulses the pair had.
    # With a mesh, the triangles also keep the side they were touched from; dropped, a
    # hull resting half through a two-sided ground woke with no history and was pushed
    # out below (scripts/fuzz_worlds.py). Before, the entry was dropped at the first
    # step asleep: 0 manifolds reused on waking.
    w = wmo.World(gravity=(0, -10, 0), sleeping=True)
    w.add_body(wmo.Box((5, 0.5, 5)), position=(0, -0.5, 0), kind="static")
    b = w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 0.5, 0), mass=2.0)
    for _ in range(600):
        w.step(1)
        if not w.awake[1]:
            break
    assert not w.awake[1]
    w.step(30)  # asleep for a while: no pair is collided
    assert len(w.contacts["depth"]) == 0
    p = np.array(b.position)
    w.wake(b)
    w.step(1)
    assert w.reused_manifolds == 1
    # Warm started from the weight it carried: it holds from the first step.
    assert w.contacts["normal_impulse"].sum() * 4 == pytest.approx(2.0 * 10 / 60, rel=1e-2)
    assert np.abs(np.array(b.position) - p).max() < 1e-4
