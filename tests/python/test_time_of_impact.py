"""Time of impact (wmo.geometry.time_of_impact, issue 4's query) against closed forms and
against dense sampling of the motion.

What is promised (ToiSettings in cpp/include/wmo/geometry/queries.h): the reported time
is never later than the true first contact; on a hit the shapes are then at most
`tolerance` apart, so for a pair closing at speed v the time is early by at most
tolerance / v. Every fast case also shows that checking only the start and end poses
(what a step without CCD sees) misses the contact, so the test could fail.
"""
from __future__ import annotations

import math

import numpy as np
import pytest

import wmo
from wmo import geometry as G

TOL = G._TOI_TOL  # the default tolerance, 1e-4 m
DT = 1 / 60


def pose(x=0.0, y=0.0, z=0.0, q=(0.0, 0.0, 0.0, 1.0)):
    return wmo.Pose(position=(x, y, z), orientation=q)


def rotated_about(axis, angle):
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    s = math.sin(angle / 2)
    return (axis[0] * s, axis[1] * s, axis[2] * s, math.cos(angle / 2))


def quat_mul(a, b):
    ax, ay, az, aw = a
    bx, by, bz, bw = b
    return (aw * bx + ax * bw + ay * bz - az * by, aw * by - ax * bz + ay * bw + az * bx,
            aw * bz + ax * by - ay * bx + az * bw, aw * bw - ax * bx - ay * by - az * bz)


def pose_at(p0, v, w, t):
    """The motion of a shape turning about its own origin (center = 0), as Motion::at."""
    p = np.asarray(p0.position) + t * np.asarray(v, float)
    wn = np.linalg.norm(w)
    q = np.asarray(p0.orientation)
    if wn > 0:
        q = np.asarray(quat_mul(rotated_about(w, wn * t), q))
    return wmo.Pose(position=p, orientation=q / np.linalg.norm(q))


def endpoints_miss(a, pa, va, b, pb, vb, wa=(0, 0, 0), wb=(0, 0, 0), duration=DT):
    """True if neither the start nor the end pose overlaps: what a discrete step sees."""
    return not (G.intersect(a, pa, b, pb)
                or G.intersect(a, pose_at(pa, va, wa, duration), b, pose_at(pb, vb, wb, duration)))


def test_sphere_sphere_agrees_with_the_analytic_time():
    rng = np.random.default_rng(4)
    for _ in range(200):
        ra, rb = rng.uniform(0.01, 1.0, 2)
        gap = rng.uniform(1e-3, 5.0)
        u = rng.normal(size=3)
        u /= np.linalg.norm(u)
        pa = pose(*rng.uniform(-100, 100, 3))
        pb = pose(*(np.asarray(pa.position) + (ra + rb + gap) * u))
        speed = rng.uniform(1.0, 1000.0)
        va = 0.5 * speed * u  # head-on closing
        vb = -0.5 * speed * u
        t_true = gap / speed
        r = G.time_of_impact(wmo.Sphere(ra), pa, wmo.Sphere(rb), pb, velocity_a=va, velocity_b=vb,
                             duration=2 * t_true)
        assert r.hit and r.status == "ok"
        assert r.time <= t_true
        assert t_true - r.time <= TOL / speed * (1 + 1e-6) + 1e-12
        assert 0 <= r.distance <= TOL
        np.testing.assert_allclose(r.normal, u, atol=1e-9)


def test_sphere_plane_agrees_with_the_analytic_time():
    rng = np.random.default_rng(5)
    plane = wmo.Plane((0, 1, 0), 0.0)
    for _ in range(100):
        rad = rng.uniform(0.01, 1.0)
        h = rng.uniform(rad + 1e-3, 10.0)
        v = -rng.uniform(1.0, 500.0)
        t_true = (h - rad) / -v
        r = G.time_of_impact(wmo.Sphere(rad), pose(rng.uniform(-1e3, 1e3), h, 3.0), plane, pose(),
                             velocity_a=(rng.uniform(-5, 5), v, 0), duration=1.5 * t_true)
        assert r.hit and r.time <= t_true and t_true - r.time <= TOL / -v * (1 + 1e-6) + 1e-12
        assert 0 <= r.distance <= TOL


def test_fast_sphere_stops_at_a_thin_plate():
    ball, plate = wmo.Sphere(0.05), wmo.Box((1, 0.005, 1))  # a 1 cm plate
    start, v = pose(0, 1, 0), (0, -500, 0)
    assert endpoints_miss(ball, start, v, plate, pose(), (0, 0, 0))  # 8.3 m per step
    r = G.time_of_impact(ball, start, plate, pose(), velocity_a=v, duration=DT)
    t_true = (1 - 0.05 - 0.005) / 500
    assert r.hit and t_true - TOL / 500 <= r.time <= t_true
    assert r.normal == pytest.approx((0, -1, 0))


def test_head_on_spheres_at_300_m_s_each_collide():
    s = wmo.Sphere(0.05)
    pa, pb, va, vb = pose(-1, 0, 0), pose(1, 0, 0), (300, 0, 0), (-300, 0, 0)
    assert endpoints_miss(s, pa, va, s, pb, vb)
    r = G.time_of_impact(s, pa, s, pb, velocity_a=va, velocity_b=vb, duration=DT)
    t_true = (2 - 0.1) / 600
    assert r.hit and t_true - TOL / 600 <= r.time <= t_true


def test_thin_box_falling_onto_a_thin_plate():
    # A 1 mm thin box released from 100 m reaches sqrt(2 g h) = 44.3 m/s: 0.74 m per step.
    v = math.sqrt(2 * 9.81 * 100)
    thin, plate = wmo.Box((0.2, 0.0005, 0.2)), wmo.Box((1, 0.0005, 1))
    start = pose(0, 0.3, 0, rotated_about((1, 0, 1), 0.3))
    assert endpoints_miss(thin, start, (0, -v, 0), plate, pose(), (0, 0, 0))
    r = G.time_of_impact(thin, start, plate, pose(), velocity_a=(0, -v, 0), duration=DT)
    assert r.hit
    # The tilted box's lowest point is its lowest corner.
    corners = np.array([[sx * 0.2, sy * 0.0005, sz * 0.2] for sx in (-1, 1) for sy in (-1, 1)
                        for sz in (-1, 1)])
    x, y, z, w = start.orientation
    R = np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                  [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                  [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])
    low = (corners @ R.T)[:, 1].min()
    t_true = (0.3 + low - 0.0005) / v
    assert t_true - TOL / v <= r.time <= t_true


def test_spinning_rod_hits_the_wall_at_the_analytic_time():
    # A 2 m rod (cross-section 2 cm) spinning at 100 rad/s about its middle turns 1.67 rad
    # in a step; the wall's face is 0.5 m from the axis. Its corner (1, 0.01) reaches the
    # wall when sin(w t) + 0.01 cos(w t) = 0.5.
    rod, wall = wmo.Box((1.0, 0.01, 0.01)), wmo.Box((2, 0.05, 2))
    wall_pose = pose(0, 0.55, 0)
    f = lambda t: math.sin(100 * t) + 0.01 * math.cos(100 * t) - 0.5  # noqa: E731
    lo, hi = 0.0, 0.01
    for _ in range(200):
        mid = (lo + hi) / 2
        lo, hi = (lo, mid) if f(lo) * f(mid) <= 0 else (mid, hi)
    t_true = lo
    # The end pose (1.67 rad) has the rod through the wall; a step that samples only the
    # end sees a deep overlap, not the first touch. The query finds the first touch.
    r = G.time_of_impact(rod, pose(), wall, wall_pose, angular_velocity_a=(0, 0, 100), duration=DT)
    assert r.hit and r.status == "ok"
    assert r.time <= t_true
    # Tip speed 100 m/s: within the tolerance that speed allows.
    assert t_true - r.time <= TOL / (100 * 0.5) + 1e-9
    assert r.distance <= TOL


def test_fast_box_against_a_triangle_mesh_floor():
    mesh = wmo.TriangleMesh(np.array([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5]], float),
                            np.array([[0, 2, 1], [0, 3, 2]]))
    box = wmo.Box((0.1, 0.1, 0.1))
    start, v = pose(0.3, 1, 0.2), (0, -100, 0)
    assert endpoints_miss(box, start, v, mesh, pose(), (0, 0, 0))
    r = G.time_of_impact(box, start, mesh, pose(), velocity_a=v, duration=DT)
    assert r.hit and 0.009 - TOL / 100 <= r.time <= 0.009


def test_a_far_triangle_closing_fast_is_not_hidden_by_a_near_one():
    """A box falls at 80 m/s beside a wall (2 mm away, the nearest triangles) onto the
    floor 3 m below, one mesh. One slab for the whole mesh (the wall's normal, across
    which the box does not move) would answer "never"; the mesh is searched triangle by
    triangle."""
    v = np.array([[-5, 0, -5], [5, 0, -5], [5, 0, 5], [-5, 0, 5],  # floor, y = 0
                  [0.102, 0, -5], [0.102, 0, 5], [0.102, 10, 5], [0.102, 10, -5]], float)  # wall, x = 0.102
    mesh = wmo.TriangleMesh(v, [[0, 2, 1], [0, 3, 2], [4, 5, 6], [4, 6, 7]])
    box = wmo.Box((0.1, 0.1, 0.1))
    r = G.time_of_impact(box, pose(0.0, 3.1, 0.0), mesh, pose(), velocity_a=(0, -80, 0), duration=0.1)
    assert r.hit and r.status == "ok"
    assert 3.0 / 80 - TOL / 80 <= r.time <= 3.0 / 80 + 1e-12
    assert r.normal[1] == pytest.approx(-1.0, abs=1e-6)  # from the box to the floor


def test_a_far_compound_child_closing_fast_is_found():
    """A compound moving at 60 m/s along +z: its near child slides 1 mm past a side wall
    (the nearest pair, across which it does not move), its far child runs into an end
    wall 2 m ahead. The answer is the far child's time."""
    moving = wmo.Compound([(wmo.Box((0.1, 0.1, 0.1)), pose()), (wmo.Sphere(0.1), pose(0.0, 0.0, 2.0))])
    walls = wmo.Compound([(wmo.Box((0.05, 5.0, 5.0)), pose(0.151, 0.0, 0.0)),  # side: 1 mm beside the box
                          (wmo.Box((5.0, 5.0, 0.05)), pose(0.0, 0.0, 4.15))])  # end: face at z = 4.1
    r = G.time_of_impact(moving, pose(), walls, pose(), velocity_a=(0, 0, 60), duration=0.1)
    assert r.hit
    gap = 4.1 - 2.1  # the end wall's face minus the sphere's front
    assert gap / 60 - TOL / 60 <= r.time <= gap / 60 + 1e-12


def test_target_distance_finds_a_given_overlap():
    """Head-on spheres (radius 0.5) 3 m apart closing at 10 m/s reach 1 cm of overlap at
    (2 + 0.01) / 10 s, and come within 5 cm at (2 - 0.05) / 10 s."""
    s = wmo.Sphere(0.5)
    for target, gap in [(-0.01, 2.01), (0.05, 1.95), (0.0, 2.0)]:
        r = G.time_of_impact(s, pose(), s, pose(3.0), velocity_a=(5, 0, 0), velocity_b=(-5, 0, 0),
                             duration=1.0, target_distance=target)
        assert r.hit
        assert gap / 10 - TOL / 10 <= r.time <= gap / 10 + 1e-12
        assert target <= r.distance <= target + TOL
    with pytest.raises(ValueError, match="target_distance"):
        G.time_of_impact(s, pose(), s, pose(3.0), target_distance=math.nan)


@pytest.mark.parametrize("seed", range(6))
def test_never_later_than_the_first_contact_under_rotation(seed):
    """Random convex pairs with linear and angular motion: no overlap anywhere before the
    reported time (sampled densely), and within the tolerance at it."""
    rng = np.random.default_rng(100 + seed)
    shapes = [wmo.Box((0.5, 0.1, 0.2)), wmo.Capsule(0.1, 0.6), wmo.Cylinder(0.3, 0.2),
              wmo.ConvexHull(rng.normal(size=(12, 3)) * 0.3), wmo.Sphere(0.2)]
    hits = 0
    for _ in range(15):
        a, b = shapes[rng.integers(len(shapes))], shapes[rng.integers(len(shapes))]
        pa = pose(0, 0, 0, rotated_about(rng.normal(size=3), rng.uniform(0, 6)))
        pb = pose(*(rng.normal(size=3) * 0.3 + (2.0, 0, 0)),
                  q=rotated_about(rng.normal(size=3), rng.uniform(0, 6)))
        va, vb = rng.normal(size=3) * 2 + (40, 0, 0), rng.normal(size=3) * 2
        wa, wb = rng.normal(size=3) * 30, rng.normal(size=3) * 30
        if G.intersect(a, pa, b, pb):
            continue
        r = G.time_of_impact(a, pa, b, pb, velocity_a=va, angular_velocity_a=wa, velocity_b=vb,
                             angular_velocity_b=wb, duration=0.1)
        assert r.status == "ok"
        end = r.time if r.hit else 0.1
        for t in np.linspace(0, end, 400)[:-1]:
            assert not G.intersect(a, pose_at(pa, va, wa, t), b, pose_at(pb, vb, wb, t)), (t, r)
        if r.hit:
            hits += 1
            d = G.distance(a, pose_at(pa, va, wa, r.time), b, pose_at(pb, vb, wb, r.time))
            assert d.distance <= TOL * (1 + 1e-6)
    assert hits >= 5  # the motions are aimed so most pairs meet


def test_initially_overlapping_and_misses():
    s = wmo.Sphere(0.5)
    r = G.time_of_impact(s, pose(), s, pose(0.5, 0, 0), velocity_a=(1, 0, 0))
    assert r.hit and r.initially_overlapping and r.time == 0 and r.distance == pytest.approx(-0.5)
    # Moving apart: never.
    r = G.time_of_impact(s, pose(), s, pose(2, 0, 0), velocity_a=(-1, 0, 0))
    assert not r.hit and r.time == 1.0 and r.status == "ok"
    # Closing, but not within the duration.
    r = G.time_of_impact(s, pose(), s, pose(2, 0, 0), velocity_a=(1, 0, 0), duration=0.5)
    assert not r.hit and not r


def test_iteration_cap_answers_a_safe_time():
    rod, wall = wmo.Box((1.0, 0.01, 0.01)), wmo.Box((2, 0.05, 2))
    r = G.time_of_impact(rod, pose(), wall, pose(0, 0.55, 0), angular_velocity_a=(0, 0, 100),
                         duration=DT, max_iterations=2)
    assert r.status == "max_iterations" and r.hit
    assert r.time < 0.0051357  # before the true contact (test above)


def test_rotation_centre_is_honoured():
    # A sphere turning about its own centre never moves; turning about a point 1 m away
    # it sweeps a circle and meets a sphere on that circle.
    s = wmo.Sphere(0.1)
    far = pose(0, 2, 0)
    r = G.time_of_impact(s, pose(), s, far, angular_velocity_a=(0, 0, 50), duration=1.0)
    assert not r.hit
    r = G.time_of_impact(s, pose(1, 0, 0), s, pose(0, 1, 0), angular_velocity_a=(0, 0, 10),
                         center_a=(-1, 0, 0), duration=1.0)
    # Centre on the unit circle at angle 10 t; contact when the chord is 0.2: angle
    # pi/2 - 2 asin(0.1).
    t_true = (math.pi / 2 - 2 * math.asin(0.1)) / 10
    assert r.hit and t_true - TOL / 10 <= r.time <= t_true


def test_bad_input_raises_naming_the_field():
    s = wmo.Sphere(0.1)
    with pytest.raises(ValueError, match="velocity_a"):
        G.time_of_impact(s, pose(), s, pose(1, 0, 0), velocity_a=(math.nan, 0, 0))
    with pytest.raises(ValueError, match="angular_velocity_b"):
        G.time_of_impact(s, pose(), s, pose(1, 0, 0), angular_velocity_b=(0, math.inf, 0))
    with pytest.raises(ValueError, match="duration"):
        G.time_of_impact(s, pose(), s, pose(1, 0, 0), duration=-1.0)
    with pytest.raises(ValueError, match="tolerance"):
        G.time_of_impact(s, pose(), s, pose(1, 0, 0), tolerance=0.0)
    with pytest.raises(ValueError, match="max_iterations"):
        G.time_of_impact(s, pose(), s, pose(1, 0, 0), max_iterations=0)
    with pytest.raises(TypeError, match="velocities_a"):
        G.time_of_impact_batch(s, s, np.zeros((3, 7)) + [0, 0, 0, 0, 0, 0, 1], pose(1, 0, 0),
                               velocities_a=np.zeros((2, 3)))
    with pytest.raises(ValueError, match=r"velocities_b\[1\]"):
        G.time_of_impact_batch(s, s, pose(), pose(1, 0, 0),
                               velocities_b=np.array([[0, 0, 0], [math.nan, 0, 0]]))
    # A plane can translate but has no finite extent to turn.
    r = G.time_of_impact(s, pose(0, 1, 0), wmo.Plane((0, 1, 0), 0), pose(),
                         angular_velocity_b=(1, 0, 0))
    assert r.status == "unsupported" and not r.hit


def test_batch_matches_single_queries():
    rng = np.random.default_rng(9)
    a, b = wmo.Box((0.3, 0.2, 0.1)), wmo.Capsule(0.1, 0.3)
    n = 50
    pa = np.zeros((n, 7))
    pa[:, 6] = 1
    pb = np.zeros((n, 7))
    pb[:, :3] = rng.normal(size=(n, 3)) + (3, 0, 0)
    pb[:, 3:] = [rotated_about(rng.normal(size=3), rng.uniform(0, 6)) for _ in range(n)]
    va = rng.normal(size=(n, 3)) + (30, 0, 0)
    wa = rng.normal(size=(n, 3)) * 10
    out = G.time_of_impact_batch(a, b, pa, pb, velocities_a=va, angular_velocities_a=wa,
                                 duration=0.2)
    assert out["time"].shape == (n,) and out["normal"].shape == (n, 3)
    for i in range(n):
        r = G.time_of_impact(a, wmo.Pose(pa[i, :3], pa[i, 3:]), b, wmo.Pose(pb[i, :3], pb[i, 3:]),
                             velocity_a=va[i], angular_velocity_a=wa[i], duration=0.2)
        assert out["hit"][i] == r.hit and out["time"][i] == r.time
        assert G.QueryStatus.from_code(out["status"][i]) == r.status


def test_toi_benchmark_writes_its_table(tmp_path):
    """benchmarks/toi/run.py (accuracy against cost of the tolerance and the cap) runs and
    never reports a time after the contact."""
    import csv
    import pathlib
    import subprocess
    import sys

    script = pathlib.Path(__file__).resolve().parents[2] / "benchmarks" / "toi" / "run.py"
    subprocess.run([sys.executable, str(script), "--out", str(tmp_path), "--n", "40"], check=True,
                   capture_output=True, timeout=300)
    rows = list(csv.DictReader(open(tmp_path / "toi.csv")))
    assert {r["motion"] for r in rows} == {"sphere_sphere", "spinning_rod", "box_plate"}
    assert all(int(r["late"]) == 0 for r in rows)
    # Tighter tolerance, smaller error (cap 256): the knob does what it says.
    rod = {float(r["tolerance"]): float(r["max_error_s"]) for r in rows
           if r["motion"] == "spinning_rod" and r["max_iterations"] == "256"}
    assert rod[1e-8] < rod[1e-4] < rod[1e-2]
