"""Batched queries: equal to a loop of single queries (bit for bit: same C++ function,
same poses), broadcasting, shape / value checks before the loop, and the GIL released
while the C++ loop runs."""
from __future__ import annotations

import sys
import threading

import numpy as np
import pytest

import wmo
from wmo import geometry as G
from conftest import cube_corners, random_poses

N = 64


def shapes():
    return {
        "sphere": wmo.Sphere(0.4),
        "box": wmo.Box((0.5, 0.3, 0.7)),
        "capsule": wmo.Capsule(0.3, 0.5),
        "hull": wmo.ConvexHull(cube_corners((0.4, 0.6, 0.5)) * [1, 1, 1]
                               + np.array([[0.1, 0, 0]] * 4 + [[0, 0, 0]] * 4)),
    }


PAIRS = [("box", "sphere"), ("hull", "capsule"), ("box", "box"), ("sphere", "hull")]


def as_pose(row):
    return wmo.Pose(row[:3], row[3:])


@pytest.mark.parametrize("name_a, name_b", PAIRS)
@pytest.mark.parametrize("fn", ["distance", "closest_points", "penetration"])
def test_distance_like_batch_equals_loop(rng, fn, name_a, name_b):
    s = shapes()
    a, b = s[name_a], s[name_b]
    pa, pb = random_poses(rng, N), random_poses(rng, N)
    r = getattr(G, fn + "_batch")(a, b, pa, pb)
    assert r["distance"].shape == (N,) and r["point_a"].shape == (N, 3)
    assert r["intersecting"].dtype == np.bool_ and r["status"].dtype == np.uint8
    assert 0 < r["intersecting"].sum() < N  # the scene mixes overlapping and apart pairs
    for i in range(N):
        d = getattr(G, fn)(a, as_pose(pa[i]), b, as_pose(pb[i]))
        assert r["distance"][i] == d.distance
        np.testing.assert_array_equal(r["point_a"][i], d.point_a)
        np.testing.assert_array_equal(r["point_b"][i], d.point_b)
        np.testing.assert_array_equal(r["normal"][i], d.normal)
        assert r["intersecting"][i] == d.intersecting
        assert G.QueryStatus.from_code(r["status"][i]) == d.status
        assert r["iterations"][i] == d.iterations


@pytest.mark.parametrize("name_a, name_b", PAIRS)
def test_collide_batch_equals_loop(rng, name_a, name_b):
    s = shapes()
    a, b = s[name_a], s[name_b]
    pa, pb = random_poses(rng, N, spread=0.6), random_poses(rng, N, spread=0.6)
    r = G.collide_batch(a, b, pa, pb, margin=0.05)
    assert r["points_a"].shape == (N, 4, 3) and r["depths"].shape == (N, 4)
    assert r["feature_ids"].dtype == np.uint32 and r["count"].dtype == np.int32
    assert (r["count"] > 0).any()
    for i in range(N):
        m = G.collide(a, as_pose(pa[i]), b, as_pose(pb[i]), margin=0.05)
        k = m.count
        assert r["count"][i] == k
        assert G.QueryStatus.from_code(r["status"][i]) == m.status
        np.testing.assert_array_equal(r["normal"][i], m.normal)
        np.testing.assert_array_equal(r["points_a"][i, :k], m.points_a)
        np.testing.assert_array_equal(r["points_b"][i, :k], m.points_b)
        np.testing.assert_array_equal(r["depths"][i, :k], m.depths)
        np.testing.assert_array_equal(r["feature_ids"][i, :k], m.feature_ids)
        assert r["max_depth"][i] == m.max_depth
        # Unused slots are zero-filled.
        assert not r["points_a"][i, k:].any() and not r["depths"][i, k:].any()


def test_collide_batch_composite_uses_deepest_manifold():
    ball = wmo.Sphere(0.5)
    comp = wmo.Compound([(ball, wmo.Pose((-1, 0, 0))), (ball, wmo.Pose((1, -0.02, 0)))])
    ground = wmo.Box((5, 0.5, 5))
    r = G.collide_batch(comp, ground, wmo.Pose((0, 0.45, 0)), wmo.Pose((0, -0.5, 0)))
    m = G.collide(comp, wmo.Pose((0, 0.45, 0)), ground, wmo.Pose((0, -0.5, 0)))
    assert r["child_a"][0] == m.child_a == 1
    assert r["max_depth"][0] == m.max_depth


def test_raycast_batch_equals_loop(rng):
    for shape in shapes().values():
        p = wmo.Pose((0.1, -0.2, 0.3), (0, 0, np.sin(0.3), np.cos(0.3)))
        origins = rng.uniform(-2, 2, size=(N, 3))
        targets = rng.uniform(-0.3, 0.3, size=(N, 3))
        dirs = targets - origins
        r = G.raycast_batch(shape, p, origins, dirs, max_distance=1.5)
        assert r["hit"].dtype == np.bool_ and r["point"].shape == (N, 3)
        assert 0 < r["hit"].sum()
        for i in range(N):
            h = G.raycast(shape, p, origins[i], dirs[i], max_distance=1.5)
            assert r["hit"][i] == h.hit and r["distance"][i] == h.distance
            np.testing.assert_array_equal(r["point"][i], h.point)
            np.testing.assert_array_equal(r["normal"][i], h.normal)
            assert r["child"][i] == h.child


def test_broadcasting_one_pose_or_row(rng):
    a, b = wmo.Box((1, 1, 1)), wmo.Sphere(0.5)
    pb = random_poses(rng, 10, spread=3)
    pa = wmo.Pose((0.5, 0, 0))
    r1 = G.distance_batch(a, b, pa, pb)
    r2 = G.distance_batch(a, b, pa.as_array(), pb)
    r3 = G.distance_batch(a, b, np.tile(pa.as_array(), (10, 1)), pb)
    for key in r1:
        np.testing.assert_array_equal(r1[key], r2[key])
        np.testing.assert_array_equal(r1[key], r3[key])
    # Rays: one origin, many directions.
    dirs = rng.normal(size=(7, 3))
    r = G.raycast_batch(b, wmo.Pose(), (0, 0, -5), dirs)
    assert r["hit"].shape == (7,)


def test_empty_batch():
    r = G.distance_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), np.zeros((0, 7)), np.zeros((0, 7)))
    assert r["distance"].shape == (0,) and r["point_a"].shape == (0, 3)
    r = G.collide_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), np.zeros((0, 7)), wmo.Pose())
    assert r["points_a"].shape == (0, 4, 3)


def test_unsupported_pair_in_batch():
    plane = wmo.Plane((0, 1, 0), 0.0)
    poses = np.tile(wmo.Pose().as_array(), (3, 1))
    r = G.collide_batch(plane, plane, poses, poses)
    assert (r["status"] == G.QueryStatus.UNSUPPORTED.code).all()
    assert (r["count"] == 0).all()


IDENT = np.array([0, 0, 0, 0, 0, 0, 1.0])


@pytest.mark.parametrize("pa, pb, match", [
    (np.zeros((4, 6)), np.zeros((4, 7)), r"poses_a.*\(N, 7\)"),
    (np.tile(IDENT, (4, 1)), np.zeros((4, 7, 1)), r"poses_b.*\(N, 7\)"),
    (np.tile(IDENT, (4, 1)), np.tile(IDENT, (5, 1)), r"poses_b.*\(4, 7\)"),
    (np.tile(IDENT, (4, 1)).astype(complex), IDENT, r"poses_a"),
    ([["a"] * 7], IDENT, r"poses_a"),
    (IDENT[:3], IDENT, r"poses_a"),
])
def test_bad_pose_array_shapes_raise_type_error(pa, pb, match):
    with pytest.raises(TypeError, match=match):
        G.distance_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), pa, pb)
    with pytest.raises(TypeError, match=match):
        G.collide_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), pa, pb)


def test_shapes_are_checked_before_values():
    # poses_a has bad values (zero quaternions), poses_b a bad shape: the shape error wins,
    # so a caller fixes array layouts first.
    with pytest.raises(TypeError, match=r"poses_b"):
        G.distance_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), np.zeros((3, 7)), np.zeros((3, 6)))
    with pytest.raises(TypeError, match=r"directions"):
        G.raycast_batch(wmo.Sphere(1.0), wmo.Pose(), np.full((3, 3), np.nan), np.zeros((3, 2)))


def test_bad_ray_array_shapes_raise_type_error():
    with pytest.raises(TypeError, match=r"origins.*\(N, 3\)"):
        G.raycast_batch(wmo.Sphere(1.0), wmo.Pose(), np.zeros((4, 2)), np.ones((4, 3)))
    with pytest.raises(TypeError, match=r"directions.*\(4, 3\)"):
        G.raycast_batch(wmo.Sphere(1.0), wmo.Pose(), np.zeros((4, 3)), np.ones((5, 3)))


@pytest.mark.parametrize("row, field", [(3, "orientation"), (0, "position")])
def test_bad_pose_rows_raise_value_error_naming_the_row(row, field):
    poses = np.tile(IDENT, (6, 1))
    if field == "orientation":
        poses[row, 3:] = [0, 0, 0, 2]      # non-unit quaternion
    else:
        poses[row, 1] = np.nan
    with pytest.raises(ValueError, match=rf"poses_b\[{row}\]\.{field}"):
        G.distance_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), IDENT, poses)
    nan_q = np.tile(IDENT, (6, 1))
    nan_q[5, 6] = np.nan
    with pytest.raises(ValueError, match=r"poses_a\[5\]\.orientation"):
        G.penetration_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), nan_q, IDENT)


def test_bad_ray_rows_raise_value_error_naming_the_row():
    dirs = np.ones((5, 3))
    dirs[2] = 0.0
    with pytest.raises(ValueError, match=r"directions\[2\]"):
        G.raycast_batch(wmo.Sphere(1.0), wmo.Pose(), np.zeros((5, 3)), dirs)
    origins = np.zeros((5, 3))
    origins[4, 0] = np.inf
    with pytest.raises(ValueError, match=r"origins\[4\]"):
        G.raycast_batch(wmo.Sphere(1.0), wmo.Pose(), origins, np.ones((5, 3)))


def test_batch_outputs_are_fresh_writable_arrays(rng):
    r = G.distance_batch(wmo.Sphere(1.0), wmo.Sphere(1.0), IDENT, random_poses(rng, 3))
    r["distance"][0] = -1.0  # the caller owns the result


# ---------------------------------------------------------------- GIL release

# Python iterations the main thread must complete while the batch is unfinished. Any
# positive number proves the GIL was free; 20000 keeps the check instantaneous.
MAIN_ITERATIONS = 20000


def probe_gil(call):
    """Runs `call()` in a worker thread and counts Python iterations of the main thread
    while the call is unfinished. Returns (iterations, result or exception).

    Why this cannot pass trivially: the switch interval is raised to 1000 s, so the
    interpreter never forces a GIL hand-over. The main thread waits in Thread.start()
    (GIL released) until the worker has started; after that it can run Python only when
    the worker gives the GIL up voluntarily. The worker makes no blocking call before
    `call()`, and the batch functions convert already-typed inputs without copies, so if
    the C++ loop held the GIL the main thread would next run only after the worker set
    `done` (0 iterations). If the loop releases the GIL the main thread takes it, and
    keeps it (no forced hand-over) while counting to MAIN_ITERATIONS with `done` unset.
    test_gil_probe_detects_a_held_gil checks this with a builtin that holds the GIL.
    No timing is involved.
    """
    done = threading.Event()
    box = {}

    def worker():
        try:
            box["result"] = call()
        except BaseException as e:  # surfaced by the caller
            box["result"] = e
        done.set()

    old = sys.getswitchinterval()
    sys.setswitchinterval(1000.0)
    try:
        t = threading.Thread(target=worker)
        t.start()
        count = 0
        while not done.is_set() and count < MAIN_ITERATIONS:
            count += 1
        if done.is_set():
            count = 0  # progress after the call finished does not count
        t.join()
    finally:
        sys.setswitchinterval(old)
    return count, box["result"]


def test_gil_probe_detects_a_held_gil():
    # sum() over a range is a C loop that never releases the GIL.
    count, result = probe_gil(lambda: sum(range(2_000_000)))
    assert count == 0 and result == sum(range(2_000_000))


@pytest.mark.parametrize("fn", ["distance_batch", "penetration_batch", "collide_batch",
                                "raycast_batch"])
def test_batch_releases_the_gil(rng, fn):
    hull = wmo.ConvexHull(rng.normal(size=(64, 3)))
    ball = wmo.Sphere(0.5)
    n = 50000
    if fn == "raycast_batch":
        args = (hull, wmo.Pose(), rng.uniform(-3, 3, size=(n, 3)), rng.normal(size=(n, 3)))
    else:
        args = (hull, ball, wmo.Pose(), random_poses(rng, n, spread=2.0))
    # The main thread must be scheduled by the OS while the batch runs (tens of ms); on
    # a heavily loaded machine it may not be, so up to 3 attempts. A batch that holds
    # the GIL fails every attempt deterministically.
    for _ in range(3):
        count, result = probe_gil(lambda: getattr(G, fn)(*args))
        assert not isinstance(result, BaseException), result
        assert len(result["status"]) == n
        if count == MAIN_ITERATIONS:
            break
    assert count == MAIN_ITERATIONS
