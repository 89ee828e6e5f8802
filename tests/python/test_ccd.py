"""Continuous collision detection in the world (issue 4): each case runs with CCD off
first and shows the failure (the body passes through, or the spheres miss each other),
then with ``ccd=True`` on the fast body and checks that it is stopped (or bounced) at
the obstacle, that no step adds energy, and that nothing is left inside anything.

Two halves are tested (WorldSettings::enable_ccd): speculative contacts for CCD pairs
(a fast body that approaches an obstacle at the start of the step) and the ccd stage's
time-of-impact sweep (what the speculative margin cannot see: rotation, a velocity the
step itself gives). Units: metres, kilograms, seconds.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import wmo
from wmo import geometry as G

DT = 1 / 60


def energy(world: wmo.World) -> float:
    """Kinetic plus potential energy (J) of the dynamic bodies; every shape here has its
    centre of mass at its origin."""
    g = np.asarray(world.gravity)
    pe = 0.0
    for i in range(world.body_count):
        b = world.body(i)
        if b.kind == "dynamic":
            pe -= b.mass * float(g @ world.positions[i])
    return world.kinetic_energy() + pe


def run(world: wmo.World, steps: int, check=None) -> list[float]:
    """Steps the world, returns the energy after each step; `check(world)` after each."""
    out = []
    for _ in range(steps):
        world.step()
        out.append(energy(world))
        if check is not None:
            check(world)
    return out


def assert_no_energy_gain(e0: float, energies: list[float]) -> None:
    # Free flight keeps the energy (a free body moves on the exact parabola) and
    # contacts only take it away: any gain would come from CCD. The slack is rounding
    # on a sum of ~|e0|.
    assert max(energies) <= e0 + 1e-9 * max(1.0, abs(e0)), (e0, max(energies))


def rotate_y_to(axis: str) -> tuple:
    """Quaternion (x, y, z, w) turning local +y onto +z ('z') or +x ('x')."""
    s = math.sqrt(0.5)
    return (s, 0.0, 0.0, s) if axis == "z" else (0.0, 0.0, -s, s)


# ---- a 0.05 m ball at 500 m/s against a 1 cm plate ----------------------------------

def ball_and_plate(ccd: bool, restitution: float = 0.0, gravity=(0.0, 0.0, 0.0), **world_kw):
    w = wmo.World(gravity=gravity, dt=DT, **world_kw)
    w.add_body(wmo.Box((1.0, 0.005, 1.0)), kind="static", restitution=restitution)
    ball = w.add_body(wmo.Sphere(0.05), position=(0.0, 3.0, 0.0), linear_velocity=(0.0, -500.0, 0.0),
                      restitution=restitution, ccd=ccd)
    return w, ball


def test_ball_passes_through_the_plate_without_ccd():
    # Discrete only (no CCD, no speculative margin against static geometry).
    w, ball = ball_and_plate(ccd=False, speculative_motion_static=0.0)
    w.step(2)
    assert ball.position[1] < -5  # 8.3 m per step: it never touched the plate


def test_ball_stops_at_the_plate_by_the_static_speculative_margin_alone():
    # Without CCD but with the default speculative_motion_static = 1: the ball's
    # broadphase box is swept along its step, the pair with the plate exists, and the
    # speculative contact stops the ball on the plate's face (no rotation to miss).
    w, ball = ball_and_plate(ccd=False)
    w.step(3)
    assert ball.position[1] == pytest.approx(0.005 + 0.05, abs=1e-6)
    assert abs(ball.linear_velocity[1]) < 1e-6


@pytest.mark.parametrize("restitution", [0.0, 0.8])
def test_ball_stops_or_bounces_at_the_plate_with_ccd(restitution):
    w, ball = ball_and_plate(ccd=True, restitution=restitution)
    e0 = energy(w)
    lowest = []
    energies = run(w, 30, lambda w: lowest.append(ball.position[1]))
    assert min(lowest) >= 0.005 + 0.05 - 0.05 * 0.05  # never below the plate's top, but for the allowance
    assert_no_energy_gain(e0, energies)
    if restitution == 0:
        assert ball.position[1] == pytest.approx(0.055, abs=1e-3)
        assert np.linalg.norm(ball.linear_velocity) < 1e-6
    else:  # bounced: moving up at e * 500 m/s
        assert ball.linear_velocity[1] == pytest.approx(0.8 * 500, rel=1e-3)


def test_ball_given_its_speed_within_the_step_is_caught_by_the_time_of_impact_sweep():
    """Starting at rest, a force brings the ball to ~500 m/s within one step: the
    speculative margin (from the velocity at the step's start) is zero, so only the ccd
    stage's sweep can catch it."""
    results = {}
    for ccd in (False, True):
        w = wmo.World(gravity=(0, 0, 0), dt=DT)
        w.add_body(wmo.Box((1.0, 0.005, 1.0)), kind="static")
        ball = w.add_body(wmo.Sphere(0.05), position=(0.0, 3.0, 0.0), mass=1.0, ccd=ccd)
        w.apply_force(ball, (0.0, -500.0 / DT, 0.0), ball.position)  # 500 m/s after one step
        w.step()
        results[ccd] = (ball.position[1], w.ccd_hits, w.profile["ccd"]["count"])
        w.step(5)
        results[ccd] += (ball.position[1],)
    # Straight through: under the constant force a free body follows x = 3 - a t^2 / 2
    # exactly (it moves with each substep's mean velocity), -1.17 m after the step.
    assert results[False][0] == pytest.approx(3.0 - 0.5 * 500.0 * DT, abs=1e-9)
    assert results[False][0] < -1.0 and results[False][3] < -30
    y, hits, swept, y_later = results[True]
    assert swept == 1 and hits == 1  # the sweep put it back at the plate
    assert 0.055 - 0.05 * 0.05 <= y <= 0.055 + 1e-3
    assert y_later >= 0.055 - 0.05 * 0.05  # the next steps' contact holds it there


def test_putting_a_body_back_adds_no_energy():
    """Gravity on, restitution 1: the sweep puts the ball back up its path (gaining
    potential energy) and reverses its velocity (keeping its kinetic energy), so the
    potential energy gained must come out of the kinetic energy: the step ends with no
    more energy than the same step without CCD."""
    ends = {}
    for ccd in (False, True):
        w = wmo.World(gravity=(0, -9.81, 0), dt=DT)
        w.add_body(wmo.Box((1.0, 0.005, 1.0)), kind="static", restitution=1.0)
        ball = w.add_body(wmo.Sphere(0.05), position=(0.0, 3.0, 0.0), mass=1.0, restitution=1.0, ccd=ccd)
        w.apply_force(ball, (0.0, -500.0 / DT, 0.0), ball.position)
        w.step()
        ends[ccd] = (energy(w), w.ccd_hits, ball.linear_velocity[1])
    (e_plain, _, _), (e_ccd, hits, vy) = ends[False], ends[True]
    assert hits == 1 and vy > 400  # put back and bounced
    assert e_ccd <= e_plain + 1e-9 * abs(e_plain)


# ---- a 1 mm box falling from 100 m onto a 1 mm plate --------------------------------

def thin_box_on_plate(ccd: bool, **world_kw):
    w = wmo.World(gravity=(0, -9.81, 0), dt=DT, **world_kw)
    w.add_body(wmo.Box((0.5, 0.0005, 0.5)), kind="static")
    box = w.add_body(wmo.Box((0.1, 0.0005, 0.1)), position=(0.0, 100.0, 0.0), mass=0.05, ccd=ccd)
    return w, box


def test_thin_box_falls_through_the_thin_plate_without_ccd():
    w, box = thin_box_on_plate(ccd=False, speculative_motion_static=0.0)  # discrete only
    w.step(5 * 60)  # ~4.5 s to fall 100 m, at ~44 m/s (0.74 m per step)
    assert box.position[1] < -10


def test_thin_box_lands_on_the_thin_plate_with_ccd():
    w, box = thin_box_on_plate(ccd=True)
    e0 = energy(w)
    lowest = []
    energies = run(w, 6 * 60, lambda w: lowest.append(box.position[1]))
    assert min(lowest) > 0.0005  # its centre never reached the plate's top face
    # Resting on it: touching at y = 1 mm, less the soft contact's sag under its weight
    # (a contact with a static body is a spring of 60 Hz at the defaults, which sags
    # ~g / (2 pi 60)^2 per point: 0.12 mm measured here; 0.47 mm at 30 Hz), never
    # through it.
    assert 0.0005 < box.position[1] <= 0.001 + 1e-6
    assert abs(box.linear_velocity[1]) < 1e-3
    assert_no_energy_gain(e0, energies)


# ---- two small spheres fired head-on at 300 m/s each --------------------------------

def head_on(ccd: bool):
    w = wmo.World(gravity=(0, 0, 0), dt=DT)
    a = w.add_body(wmo.Sphere(0.05), position=(-7.0, 0.0, 0.0), linear_velocity=(300.0, 0.0, 0.0),
                   mass=1.0, ccd=ccd)
    b = w.add_body(wmo.Sphere(0.05), position=(7.0, 0.0, 0.0), linear_velocity=(-300.0, 0.0, 0.0),
                   mass=1.0, ccd=ccd)
    return w, a, b


def test_head_on_spheres_pass_each_other_without_ccd():
    w, a, b = head_on(ccd=False)
    w.step(3)
    assert a.position[0] > b.position[0]  # swapped sides: they never met
    assert a.linear_velocity[0] == 300.0


def test_head_on_spheres_collide_with_ccd():
    w, a, b = head_on(ccd=True)
    e0 = energy(w)
    energies = run(w, 10)
    assert a.position[0] < b.position[0]
    assert b.position[0] - a.position[0] >= 0.1 - 0.05 * 0.05  # touching, not inside
    assert abs(a.linear_velocity[0]) < 1e-6 and abs(b.linear_velocity[0]) < 1e-6  # inelastic, momentum 0
    assert_no_energy_gain(e0, energies)


def test_one_ccd_sphere_is_enough_for_a_fast_pair():
    """CCD on one body of the pair covers the pair (the other asked for nothing)."""
    w = wmo.World(gravity=(0, 0, 0), dt=DT)
    a = w.add_body(wmo.Sphere(0.05), position=(-7.0, 0.0, 0.0), linear_velocity=(300.0, 0.0, 0.0), ccd=True)
    b = w.add_body(wmo.Sphere(0.05), position=(7.0, 0.0, 0.0), linear_velocity=(-300.0, 0.0, 0.0))
    w.step(10)
    assert a.position[0] < b.position[0]


def test_fast_kinematic_bat_hits_a_resting_ccd_ball():
    """A kinematic bat at 100 m/s (1.67 m a step) towards a ball at rest: without CCD it
    jumps over the ball; with CCD on the ball (the bat's motion is known, so its
    broadphase box is swept and the sweep follows it) the ball is carried ahead of it.
    (Discrete without CCD: speculative_motion_static = 0; at its default, 1, the bat's
    box is swept too and the pair's speculative contact catches the ball: the next
    test.)"""
    for ccd in (False, True):
        w = wmo.World(gravity=(0, 0, 0), dt=DT, speculative_motion_static=0.0)
        bat = w.add_body(wmo.Box((0.05, 0.5, 0.5)), position=(-3.0, 0.0, 0.0), kind="kinematic",
                         linear_velocity=(100.0, 0.0, 0.0))
        ball = w.add_body(wmo.Sphere(0.1), mass=0.1, ccd=ccd)
        w.step(4)
        if not ccd:
            assert ball.position[0] == 0.0 and bat.position[0] > 3.0  # passed through it
        else:
            assert ball.linear_velocity[0] == pytest.approx(100.0, rel=1e-6)
            assert ball.position[0] >= bat.position[0] + 0.05 + 0.1 - 0.1 * 0.05  # ahead of the bat


# ---- a long thin rod spinning at 100 rad/s next to a wall ---------------------------

def spinning_rod(ccd: bool):
    """A 2 m rod (capsule of radius 2 cm) at the origin lying along z, spinning about y at
    100 rad/s (1.67 rad per step, its tips at 102 m/s); a 1 cm wall whose face is at
    x = 0.9, inside the circle the tips sweep (radius 1.02)."""
    w = wmo.World(gravity=(0, 0, 0), dt=DT)
    w.add_body(wmo.Box((0.005, 2.0, 2.0)), position=(0.905, 0.0, 0.0), kind="static")
    rod = w.add_body(wmo.Capsule(0.02, 1.0), orientation=rotate_y_to("z"), angular_velocity=(0.0, 100.0, 0.0),
                     ccd=ccd)
    return w, rod


def rod_reach_x(rod) -> float:
    """Largest x any point of the rod reaches (m)."""
    x, y, z, w_ = rod.orientation
    axis_x = 2 * (x * y - w_ * z)  # x component of the rotated local +y
    return rod.position[0] + abs(axis_x) * 1.0 + 0.02


def test_spinning_rod_goes_through_the_wall_without_ccd():
    w, rod = spinning_rod(ccd=False)
    reach = []
    run(w, 30, lambda w: reach.append(rod_reach_x(rod)))
    assert max(reach) > 0.91  # a tip ended a step beyond the wall's far face


def test_spinning_rod_hits_the_wall_with_ccd():
    w, rod = spinning_rod(ccd=True)
    e0 = energy(w)
    reach = []
    hits = []
    energies = run(w, 30, lambda w: (reach.append(rod_reach_x(rod)), hits.append(w.ccd_hits)))
    assert sum(hits) >= 1  # rotation: only the time-of-impact sweep sees it
    assert max(reach) <= 0.9 + 0.05 * 0.02 + 1e-9  # never past the wall's face but for the allowance
    assert_no_energy_gain(e0, energies)
    # It hit the wall: knocked back (-x) instead of spinning in place.
    assert rod.position[0] < -0.1


# ---- a fast box against a triangle-mesh floor --------------------------------------

def mesh_floor(ccd: bool, **world_kw):
    w = wmo.World(gravity=(0, -9.81, 0), dt=DT, **world_kw)
    v = [[-5.0, 0.0, -5.0], [5.0, 0.0, -5.0], [5.0, 0.0, 5.0], [-5.0, 0.0, 5.0]]
    w.add_body(wmo.TriangleMesh(v, [[0, 2, 1], [0, 3, 2]]), kind="static")
    box = w.add_body(wmo.Box((0.1, 0.1, 0.1)), position=(0.3, 5.0, -0.2), linear_velocity=(0.0, -80.0, 0.0),
                     angular_velocity=(3.0, 0.0, 2.0), mass=1.0, ccd=ccd)
    return w, box


def test_fast_box_passes_through_the_mesh_floor_without_any_continuous_treatment():
    # No CCD and no speculative margin against static geometry: the 80 m/s box
    # (1.3 m a step) is never paired with the floor in time and falls through.
    w, box = mesh_floor(ccd=False, speculative_motion_static=0.0)
    w.step(10)
    assert box.position[1] < -5


def test_fast_box_lands_on_the_mesh_floor_by_speculative_contacts_alone():
    # The default speculative_motion_static = 1 sweeps the box's broadphase box along
    # its step, so its pair with the floor exists the step before it would reach it,
    # and the speculative contact stops it on the surface (measured: lowest centre
    # 0.09988 m, a half-extent above the floor to 1.2e-4 m) without CCD.
    w, box = mesh_floor(ccd=False)
    lowest = []
    run(w, 120, lambda w: lowest.append(box.position[1]))
    assert min(lowest) > 0.1 - 0.1 * 0.05
    assert box.position[1] == pytest.approx(0.1, abs=0.01)


def test_fast_box_lands_on_the_mesh_floor_with_ccd():
    w, box = mesh_floor(ccd=True)
    e0 = energy(w)
    lowest = []
    energies = run(w, 120, lambda w: lowest.append(box.position[1]))
    assert min(lowest) > 0.1 - 0.1 * 0.05 - 1e-9  # the centre never below a half-extent above the floor
    assert box.position[1] == pytest.approx(0.1, abs=0.01)  # resting on the floor
    assert_no_energy_gain(e0, energies)


def _plate_sliding_on_a_mesh(ccd: bool, one_sided: bool) -> float:
    # A 1 cm plate, frictionless, rested on a flat 1 m grid of triangles and then given
    # 5 m/s along it: the distance it slides in 60 steps (1 s).
    n = 24
    xs = np.arange(n + 1) - n / 2
    v = [(x, 0.0, z) for x in xs for z in xs]
    t = [tri for i in range(n) for j in range(n)
         for tri in (((n + 1) * i + j, (n + 1) * i + j + 1, (n + 1) * (i + 1) + j),
                     ((n + 1) * i + j + 1, (n + 1) * (i + 1) + j + 1, (n + 1) * (i + 1) + j))]
    w = wmo.World(sleeping=False)
    w.add_body(wmo.TriangleMesh(v, t, one_sided=one_sided), kind="static", friction=0.0)
    b = w.add_body(wmo.Box((0.2, 0.005, 0.2)), position=(-10, 0.005, 0.3), mass=1.0, friction=0.0, ccd=ccd)
    w.step(30)
    x0 = b.position[0]
    w.linear_velocities[b.index] = (5.0, 0.0, 0.0)
    w.step(60)
    return b.position[0] - x0


@pytest.mark.parametrize("one_sided", [False, True])
def test_a_ccd_plate_slides_over_a_mesh_as_far_as_without_ccd(one_sided):
    # The sweeps leave the triangles a body slides along to the solver (ToiSettings::
    # parallel_skip): searched, the plate's rocking on its soft contacts (30 um deeper
    # over a step, its allowance 0.25 mm) stopped it part of the way in some steps
    # (measured: 4.81 m instead of 5). Frictionless, it keeps its 5 m/s: 5 m to 1 mm,
    # as without CCD.
    assert _plate_sliding_on_a_mesh(False, one_sided) == pytest.approx(5.0, abs=1e-3)
    assert _plate_sliding_on_a_mesh(True, one_sided) == pytest.approx(5.0, abs=1e-3)


# ---- what CCD costs and when it runs -------------------------------------------------

def test_slow_ccd_bodies_take_the_ordinary_path():
    """A CCD body moving less than ccd_motion_threshold x its inner radius per step is not
    swept: the stage counts no body, and the step is the same as without CCD."""
    states = {}
    for ccd in (False, True):
        w = wmo.World(gravity=(0, -9.81, 0), dt=DT, sleeping=False)
        w.add_body(wmo.Box((5, 0.5, 5)), position=(0, -0.5, 0), kind="static")
        boxes = [w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0.0, 0.5 + k, 0.0), ccd=ccd) for k in range(3)]
        w.step(60)
        states[ccd] = np.array(w.positions).copy()
        if ccd:
            assert w.profile["ccd"]["total_count"] == 0
            assert all(b.ccd for b in boxes)
    np.testing.assert_array_equal(states[False], states[True])


def test_fast_kinematic_bat_carries_a_resting_ball_by_the_static_speculative_margin():
    # No CCD anywhere: the kinematic bat's box is swept along its step (the default
    # speculative_motion_static = 1 covers pairs with kinematic bodies), so the pair
    # exists before the bat reaches the ball, and the ball is carried ahead of it.
    w = wmo.World(gravity=(0, 0, 0), dt=DT)
    bat = w.add_body(wmo.Box((0.05, 0.5, 0.5)), position=(-3.0, 0.0, 0.0), kind="kinematic",
                     linear_velocity=(100.0, 0.0, 0.0))
    ball = w.add_body(wmo.Sphere(0.1), mass=0.1)
    w.step(4)
    assert ball.linear_velocity[0] == pytest.approx(100.0, rel=1e-6)
    assert ball.position[0] >= bat.position[0] + 0.05 + 0.1 - 0.1 * 0.05


def test_the_world_switch_turns_ccd_off():
    # speculative_motion_static = 0 so that nothing but CCD could stop the ball.
    w = wmo.World(gravity=(0, 0, 0), dt=DT, ccd=False, speculative_motion_static=0.0)
    assert w.ccd is False
    w.add_body(wmo.Box((1.0, 0.005, 1.0)), kind="static")
    ball = w.add_body(wmo.Sphere(0.05), position=(0.0, 3.0, 0.0), linear_velocity=(0.0, -500.0, 0.0), ccd=True)
    w.step(2)
    assert ball.position[1] < -5
    assert w.profile["ccd"]["runs"] == 0


def test_ccd_flag_per_body():
    w = wmo.World()
    ground = w.add_body(wmo.Box((1, 1, 1)), kind="static", ccd=True)
    b = w.add_body(wmo.Sphere(0.1))
    assert ground.ccd is False  # only dynamic bodies are swept
    assert b.ccd is False
    b.ccd = True
    assert b.ccd is True
    b.ccd = False
    assert b.ccd is False


@pytest.mark.parametrize("field,value", [("ccd_motion_threshold", -0.1), ("ccd_motion_threshold", math.nan),
                                         ("ccd_penetration", 0.0), ("ccd_penetration", -1.0)])
def test_bad_ccd_settings_raise(field, value):
    with pytest.raises(ValueError, match=field):
        wmo.World(**{field: value})


def test_ccd_never_leaves_a_body_inside_another():
    """A shower of fast CCD spheres and boxes (40 to 120 m/s, spinning) into a closed box
    of 1 cm walls: none ends a step overlapping a wall by more than its allowance, none
    escapes, and the energy never grows."""
    rng = np.random.default_rng(7)
    w = wmo.World(gravity=(0, -9.81, 0), dt=DT, sleeping=False)
    t = 0.005
    walls = [((2.0, t, 2.0), (0.0, -t, 0.0)), ((2.0, t, 2.0), (0.0, 4.0 + t, 0.0)),
             ((t, 2.0, 2.0), (-2.0 - t, 2.0, 0.0)), ((t, 2.0, 2.0), (2.0 + t, 2.0, 0.0)),
             ((2.0, 2.0, t), (0.0, 2.0, -2.0 - t)), ((2.0, 2.0, t), (0.0, 2.0, 2.0 + t))]
    for half, pos in walls:
        w.add_body(wmo.Box(half), position=pos, kind="static")
    shapes = [wmo.Sphere(0.1), wmo.Box((0.15, 0.05, 0.1))]
    movers = []
    for k in range(12):
        speed = rng.uniform(40, 120)
        d = rng.normal(size=3)
        d /= np.linalg.norm(d)
        movers.append(w.add_body(shapes[k % 2], position=rng.uniform([-1.5, 0.5, -1.5], [1.5, 3.5, 1.5]),
                                 linear_velocity=speed * d, angular_velocity=rng.normal(size=3) * 20,
                                 ccd=True))
    e0 = energy(w)

    def check(world):
        for b in movers:
            p = b.position
            assert np.all(np.abs(p[[0, 2]]) < 2.0) and 0.0 < p[1] < 4.0, p  # still inside the box

    energies = run(w, 120, check)
    assert_no_energy_gain(e0, energies)
    # No mover overlaps a wall by more than its allowance (5% of its inner radius).
    inner = {0: 0.1, 1: 0.05}
    for k, b in enumerate(movers):
        for i in range(6):
            half, pos = walls[i]
            r = G.penetration(shapes[k % 2], (b.position, b.orientation), wmo.Box(half), (pos, (0, 0, 0, 1)))
            assert r.distance >= -0.05 * inner[k % 2] - 1e-6


def shower(threads: int = 1) -> wmo.World:
    """Fast CCD balls and boxes fired down into a loose pile on a 1 cm plate."""
    rng = np.random.default_rng(3)
    w = wmo.World(gravity=(0, -9.81, 0), dt=DT, threads=threads, sleeping=False)
    w.add_body(wmo.Box((3.0, 0.005, 3.0)), kind="static")
    for k in range(20):
        w.add_body(wmo.Box((0.2, 0.2, 0.2)), position=(rng.uniform(-1, 1), 0.2 + 0.41 * k, rng.uniform(-1, 1)))
    for k in range(10):
        shape = wmo.Sphere(0.05) if k % 2 else wmo.Box((0.1, 0.02, 0.05))
        w.add_body(shape, position=(rng.uniform(-1, 1), 12.0 + k, rng.uniform(-1, 1)),
                   linear_velocity=(rng.uniform(-5, 5), -150.0, rng.uniform(-5, 5)),
                   angular_velocity=rng.normal(size=3) * 30, ccd=True)
    return w


def test_ccd_is_deterministic_across_runs_and_threads():
    """The shower run twice and with two threads ends bit-identical (the ccd stage is
    serial and ordered; the narrowphase joins its parts in order). Without CCD all 10
    fast bodies cross the plate in this scene (checked when this test was written)."""
    finals = []
    hits = []
    for threads in (1, 1, 2):
        w = shower(threads)
        total = 0
        for _ in range(90):
            before = np.array(w.positions).copy()
            w.step()
            total += w.ccd_hits
            after = np.array(w.positions)
            # Nothing crosses the plate's top face within its extent (many are knocked
            # off its edge, at up to 150 m/s, and fall past it there).
            crossed = (before[1:, 1] > 0.005) & (after[1:, 1] < 0.005) & np.all(np.abs(after[1:, [0, 2]]) < 3, axis=1)
            assert not crossed.any(), np.nonzero(crossed)
        finals.append(np.concatenate([np.array(w.positions).ravel(), np.array(w.orientations).ravel(),
                                      np.array(w.linear_velocities).ravel()]))
        hits.append(total)
    assert hits[0] > 0  # the sweep did put bodies back
    np.testing.assert_array_equal(finals[0], finals[1])
    np.testing.assert_array_equal(finals[0], finals[2])


def test_fast_ccd_ball_wakes_and_pushes_a_sleeping_box():
    w = wmo.World(gravity=(0, -9.81, 0), dt=DT)
    w.add_body(wmo.Box((5, 0.5, 5)), position=(0, -0.5, 0), kind="static")
    box = w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0.0, 0.5, 0.0), mass=1.0)
    w.step(120)
    assert box.sleeping
    ball = w.add_body(wmo.Sphere(0.05), position=(-6.0, 0.5, 0.0), linear_velocity=(400.0, 0.0, 0.0),
                      mass=0.1, ccd=True)
    w.step(3)
    assert not box.sleeping
    assert box.linear_velocity[0] > 1.0  # pushed along +x
    assert ball.position[0] < box.position[0] - 0.5  # the ball stayed on its side


def _falling_column(ccd: bool) -> tuple[float, list[float]]:
    """20 boxes (1 m half-extent, 1 kg) stacked 2 m apart, all falling at 25 m/s onto
    the ground: the deepest overlap over 2 s, and the boxes' final heights."""
    w = wmo.World(gravity=(0, -10, 0), dt=DT, sleeping=False)
    w.add_body(wmo.Box((20, 1, 20)), position=(0, -1, 0), kind="static")
    boxes = [w.add_body(wmo.Box((1, 1, 1)), position=(0, 1.0 + 2.0 * k, 0), linear_velocity=(0, -25, 0),
                        mass=1.0, ccd=ccd) for k in range(20)]
    deepest = 0.0
    for _ in range(120):
        w.step()
        deepest = max(deepest, w.max_penetration)
    return deepest, [float(b.position[1]) for b in boxes]


def test_a_falling_column_drives_into_itself_without_ccd():
    # The ground stops the bottom box; the solver's passes carry that up the column
    # one contact per pass, so the boxes above drive on into the ones below.
    deepest, _ = _falling_column(ccd=False)
    assert deepest > 0.15  # measured 0.22 m (also with CCD before its shock pass)


def test_a_falling_ccd_column_stops_box_by_box():
    # The shock pass (world.cpp, shock_pass) stops each fast CCD box against the one
    # that supports it, bottom up, after each substep's relax passes.
    deepest, heights = _falling_column(ccd=True)
    assert deepest < 0.05  # measured 0.024 m; 5 % of the box size is 0.1 m
    # The column ends stacked: every box on the one below, none squeezed out sideways.
    gaps = np.diff(heights)
    assert np.all(np.abs(gaps - 2.0) < 0.05) and abs(heights[0] - 1.0) < 0.05, heights


def _knocked_spinning(ccd):
    """Two 2 m boxes (8 kg) falling together at 25 m/s, the lower one tilted by 0.5 rad
    about (1, 0, 1) so that its corner hits the ground first (its highest corner at
    y = 3.556 m), the upper one 1.2 m off its axis, 1 cm above that corner: the impact
    sets the lower box spinning within the step, and its corners swing up into the
    upper box where the step's manifold between the two (its points at the step's
    start) does not reach. Returns the deepest overlap
    of the two boxes after any step (collided again at the end poses), the most
    overlaps the ccd stage pushed apart in a step, and the mechanical energy (kinetic
    plus potential) after each step."""
    w = wmo.World(gravity=(0, -9.81, 0), sleeping=False)
    w.add_body(wmo.Box((10, 0.5, 10)), position=(0, -0.5, 0), kind="static")
    axis = np.array([1.0, 0.0, 1.0]) / np.sqrt(2)
    tilt = (*(np.sin(0.25) * axis), np.cos(0.25))
    a = w.add_body(wmo.Box((1, 1, 1)), position=(0, 2.0, 0), orientation=tilt, mass=8.0, ccd=ccd)
    b = w.add_body(wmo.Box((1, 1, 1)), position=(1.2, 4.566, 0), mass=8.0, ccd=ccd)
    for body in (a, b):
        w.linear_velocities[body.index] = (0, -25.0, 0)
    box = w.body(a.index).shape
    deepest, projections, energies = 0.0, 0, []
    for _ in range(12):
        w.step()
        p, q = w.positions, w.orientations
        m = wmo.geometry.collide(box, wmo.Pose(position=p[a.index], orientation=q[a.index]),
                                 box, wmo.Pose(position=p[b.index], orientation=q[b.index]))
        deepest = max([deepest, *np.asarray(m.depths)])
        projections = max(projections, w.ccd_projections)
        energies.append(w.kinetic_energy() + 8.0 * 9.81 * (p[a.index, 1] + p[b.index, 1]))
    return deepest, projections, energies


def test_a_box_knocked_spinning_swings_a_corner_into_the_box_above_without_ccd():
    deepest, projections, _ = _knocked_spinning(ccd=False)
    assert deepest > 0.15  # measured 0.255 m; 0.147 m with CCD before overlap projection
    assert projections == 0


def test_ccd_pushes_apart_a_corner_that_swung_in_within_the_step():
    # Overlap projection (world.cpp, project_ccd_overlaps): the pair is collided again
    # at the end poses and pushed back to half the allowance (ccd_penetration 0.05 of
    # the inner radius 1 m: 5 cm, so 2.5 cm), its approach stopped.
    deepest, projections, energies = _knocked_spinning(ccd=True)
    assert projections > 0
    assert deepest <= 0.05  # measured 0.025 m (0.147 m before overlap projection)
    # Never adds energy: the push's potential energy comes out of the kinetic energy,
    # and the impulse only stops an approach. The start: both boxes at 25 m/s, 2 m and
    # 4.566 m up. 1e-9 relative allows round-off.
    start = 2 * 0.5 * 8.0 * 25.0**2 + 8.0 * 9.81 * (2.0 + 4.566)
    assert max(energies) <= start * (1 + 1e-9), energies


def _deep_pair(ccd: bool) -> tuple[float, int]:
    """Two 2 m boxes (8 kg) found 0.3 m deep in each other, both moving sideways at
    5 m/s (no gravity): a steady overlap, one the step does not deepen. Returns the
    deepest overlap after one step (collided again at the end poses) and the overlaps
    the ccd stage pushed apart."""
    w = wmo.World(gravity=(0, 0, 0), sleeping=False)
    a = w.add_body(wmo.Box((1, 1, 1)), position=(0, 0, 0), mass=8.0, ccd=ccd)
    b = w.add_body(wmo.Box((1, 1, 1)), position=(0, 1.7, 0), mass=8.0, ccd=ccd)
    for body in (a, b):
        w.linear_velocities[body.index] = (5.0, 0, 0)
    w.step()
    return w.max_penetration, w.ccd_projections


def test_a_deep_moving_pair_is_pushed_out_at_the_solvers_pace_without_ccd():
    # The soft contact pushes an overlap out at most push_max (3 m/s) per unit time:
    # 0.3 m takes several steps.
    deepest, _ = _deep_pair(ccd=False)
    assert deepest > 0.2  # measured 0.263 m


def test_ccd_holds_a_moving_pairs_overlap_to_one_and_a_half_allowances():
    # A moving CCD pair deeper than 1.5 allowances (ccd_penetration 0.05 x the inner
    # radius 1 m: 7.5 cm) is pushed back to that depth within the step, whether or not
    # the step deepened it (world.cpp, project_ccd_overlaps).
    deepest, projections = _deep_pair(ccd=True)
    assert projections >= 1
    assert deepest <= 1.5 * 0.05 + 1e-9, deepest  # measured 0.075 m


def _heavy_on_light(ccd: bool) -> tuple[float, np.ndarray]:
    """A 0.2 m box of 800 kg resting on one of 8 kg (1:100) on the ground, 600 steps.
    Returns the deepest overlap over the last 100 steps and the heavy box's final
    position."""
    w = wmo.World(gravity=(0, -9.81, 0), sleeping=False)
    w.add_body(wmo.Box((10, 0.5, 10)), position=(0, -0.5, 0), kind="static")
    w.add_body(wmo.Box((0.1, 0.1, 0.1)), position=(0, 0.1, 0), mass=8.0, ccd=ccd)
    heavy = w.add_body(wmo.Box((0.1, 0.1, 0.1)), position=(0, 0.3, 0), mass=800.0, ccd=ccd)
    deepest = []
    for _ in range(600):
        w.step()
        deepest.append(w.max_penetration)
    return max(deepest[-100:]), w.positions[heavy.index].copy()


@pytest.mark.parametrize("ccd", [False, True])
def test_ccd_leaves_a_heavy_box_resting_on_a_light_one_standing(ccd):
    # The pair's springs sag 2 cm under 100 times the light box's weight, four times
    # its allowance (5 mm), but at rest that sag is the solver's: overlap projection
    # acts on moving pairs only. Pushing it out every step pushed the light box into
    # the ground and back, and the heavy one slid off (x 7 cm, y 0.1 m, measured), as
    # an impulse at the deepest corner instead of the manifold's centroid did.
    deepest, heavy = _heavy_on_light(ccd)
    assert deepest < 0.03  # measured 0.020 m with and without CCD
    assert heavy[1] > 0.25 and np.hypot(heavy[0], heavy[2]) < 0.01, heavy  # measured y 0.274 m, |x, z| < 3 mm


# ---- bodies crushed against static geometry -------------------------------------------

def _ploughed_plate(ccd: bool) -> float:
    """A 0.4 m plate 2 mm thick (0.32 kg) resting on a one-sided mesh floor, and a 1 m
    kinematic box moving down onto it at 2.5 m/s, on through the floor: no answer keeps
    the plate out of both. Returns the plate centre's lowest height over 2 s (m)."""
    w = wmo.World(gravity=(0, -9.81, 0), dt=DT, sleeping=False)
    v = [[-4.0, 0.0, -4.0], [4.0, 0.0, -4.0], [4.0, 0.0, 4.0], [-4.0, 0.0, 4.0]]
    w.add_body(wmo.TriangleMesh(v, [[0, 2, 1], [0, 3, 2]], one_sided=True), kind="static")
    plate = w.add_body(wmo.Box((0.2, 0.001, 0.2)), position=(0.3, 0.001, 0.2), density=1000.0, ccd=ccd)
    w.add_body(wmo.Box((0.5, 0.5, 0.5)), position=(0, 1.0, 0), kind="kinematic", linear_velocity=(0, -2.5, 0))
    lowest = []
    run(w, 120, lambda w: lowest.append(plate.position[1]))
    return min(lowest)


def test_a_kinematic_box_ploughing_into_the_floor_drives_a_plate_through_it_without_ccd():
    assert _ploughed_plate(ccd=False) < -1  # measured: out below, 19 m down after 2 s


def test_a_kinematic_box_ploughing_into_the_floor_leaves_a_ccd_plate_on_it():
    # The overlap projection does not push a body into static geometry it touches
    # (world.cpp, project_ccd_overlaps: "pinned"): the plate stays on the floor and the
    # box passes over and through it. Pushed away from the box, the plate went 4 cm
    # down in one push, wholly behind the one-sided floor, and fell (measured 20 m
    # down after 2 s; a random-scene fuzz lost a 14 g hull so, seed 415 of
    # test_fuzz_worlds.py). Bound: never below the floor by more than its half-thickness.
    assert _ploughed_plate(ccd=True) > -0.001  # measured: lowest centre 0.00098 m


def _rammed_plate(gap: float, speed: float) -> float:
    """A 1 kg plate 4 cm thick at rest, `gap` m in front of a static wall 1 cm thick,
    rammed by a 100 kg box at `speed` m/s (no gravity); CCD on both. Returns the plate
    centre's largest x over 20 steps (m); the wall's near face is at x = 0.02 + gap."""
    w = wmo.World(gravity=(0, 0, 0), dt=DT, sleeping=False)
    w.add_body(wmo.Box((0.005, 2, 2)), position=(0.02 + gap + 0.005, 0, 0), kind="static")
    plate = w.add_body(wmo.Box((0.02, 0.5, 0.5)), mass=1.0, ccd=True)
    w.add_body(wmo.Box((0.25, 0.25, 0.25)), position=(-0.47, 0, 0), mass=100.0, ccd=True,
               linear_velocity=(speed, 0, 0))
    xs = []
    run(w, 20, lambda w: xs.append(plate.position[0]))
    return max(xs)


@pytest.mark.parametrize("gap", [0.1, 0.2, 0.3])
@pytest.mark.parametrize("speed", [10.0, 20.0, 40.0])
def test_a_plate_rammed_towards_a_thin_wall_stays_in_front_of_it(gap, speed):
    # The box drives 2-3 plate thicknesses into the plate within a step; the overlap
    # projection pushes the plate out by nearly all of it (1:100), towards a wall it
    # had no contact with at the step's start (farther than the speculative margin).
    # Each push longer than the CCD threshold is now swept against static geometry and
    # stopped at the wall (world.cpp, project_ccd_overlaps); before, the push carried
    # the plate through the wall (measured: 2.7-10.9 m beyond it after 20 steps in 6 of
    # these 9 cases). Bound: the plate's centre never past the wall's near face less
    # its half-thickness, but for the CCD allowance (5% of it).
    assert _rammed_plate(gap, speed) <= gap + 0.05 * 0.02 + 1e-9


def test_boxes3000_with_ccd_on_every_box_penetrates_at_most_5_percent():
    w = wmo.scenes.boxes3000(sleeping=False)
    for i in range(w.body_count):
        if w.body(i).kind == "dynamic":
            w.body(i).ccd = True
    deepest = 0.0
    for _ in range(600):
        w.step()
        deepest = max(deepest, w.max_penetration)
    # Issue 4's bar: 5 % of the box size. World.max_penetration collides the step's
    # contact pairs again at the end poses. Measured 0.082 m here (0.076 m before the
    # projection's pinned bodies, test above), 0.085-0.092 m in
    # five more runs with the dynamic bodies' positions perturbed by N(0, 1e-7 m) (the
    # scene is chaotic); 0.39-0.52 m before overlap projection, 0.66 m without CCD
    # (benchmarks/ccd/penetration.py --ccd all). What is left are columns and the
    # bottom of the pile compressed on their soft contacts.
    assert deepest <= 0.05 * 2.0, deepest
