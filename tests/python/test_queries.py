"""Single pair queries from Python against closed-form answers: distance, closest
points, penetration, collide (manifolds), ray casts; the A-to-B normal convention; the
explicit 'unsupported' status; pose tuples; argument validation."""
from __future__ import annotations

import math

import numpy as np
import pytest

import wmo
from wmo import geometry as G
from conftest import cube_corners, quat_axis_angle

# Tolerance for closed-form answers on O(1 m) scenes. Every case below has a polytope
# or point core (sphere = point + radius), where GJK and EPA terminate on an exact
# feature and special routines are closed form; the only error is rounding (~1e-15)
# plus GJK's relative stopping test (1e-10 on |v|^2, i.e. ~1e-10 relative on distance).
TOL = 1e-9

ORIGIN = wmo.Pose()


def pose(x=0.0, y=0.0, z=0.0, q=(0.0, 0.0, 0.0, 1.0)):
    return wmo.Pose(position=(x, y, z), orientation=q)


def assert_manifold_convention(m):
    """points_b = points_a - depth * normal for every point; unit normal."""
    assert m.points_a.shape == (m.count, 3) and m.points_b.shape == (m.count, 3)
    assert m.depths.shape == (m.count,) and m.feature_ids.shape == (m.count,)
    if m.count:
        assert np.linalg.norm(m.normal) == pytest.approx(1.0, abs=1e-12)
        np.testing.assert_allclose(m.points_b, m.points_a - m.depths[:, None] * m.normal,
                                   atol=TOL)


def same_point_set(p, q, atol):
    """Every row of p matches a row of q and vice versa (order-free)."""
    p, q = np.asarray(p), np.asarray(q)
    if p.shape != q.shape:
        return False
    d = np.linalg.norm(p[:, None, :] - q[None, :, :], axis=2)
    return bool(np.all(d.min(axis=1) <= atol) and np.all(d.min(axis=0) <= atol))


# ---------------------------------------------------------------- distance family

def test_readme_example():
    box, ball = wmo.Box(half_extents=(1, 1, 1)), wmo.Sphere(radius=0.5)
    pa = wmo.Pose(position=(0, 0, 0), orientation=(0, 0, 0, 1))
    pb = wmo.Pose(position=(3, 0, 0))
    d = G.distance(box, pa, ball, pb)
    assert d.status == "ok" and d.status == G.QueryStatus.OK
    assert not d.intersecting
    assert d.distance == pytest.approx(1.5, abs=TOL)
    np.testing.assert_allclose(d.point_a, [1, 0, 0], atol=TOL)
    np.testing.assert_allclose(d.point_b, [2.5, 0, 0], atol=TOL)
    np.testing.assert_allclose(d.normal, [1, 0, 0], atol=TOL)
    m = G.collide(box, pa, ball, pb)
    assert m.count == 0 and not m and m.status == "ok"
    assert m.points_a.shape == (0, 3) and m.depths.shape == (0,)


def test_distance_rotated_box_vertex():
    # Box rotated 45 degrees about z: its vertex (sqrt 2, 0, z) faces the sphere.
    box, ball = wmo.Box((1, 1, 1)), wmo.Sphere(0.5)
    d = G.distance(box, pose(q=quat_axis_angle((0, 0, 1), math.pi / 4)), ball, pose(3, 0, 0))
    assert d.distance == pytest.approx(3 - math.sqrt(2) - 0.5, abs=TOL)
    np.testing.assert_allclose(d.point_a[:2], [math.sqrt(2), 0], atol=TOL)
    np.testing.assert_allclose(d.normal, [1, 0, 0], atol=TOL)


def test_distance_sphere_sphere_any_direction():
    a, b = wmo.Sphere(0.3), wmo.Sphere(0.7)
    c = np.array([1.0, 2.0, 2.0])  # |c| = 3
    d = G.distance(a, pose(), b, pose(*c))
    assert d.distance == pytest.approx(2.0, abs=TOL)
    np.testing.assert_allclose(d.normal, c / 3, atol=TOL)
    np.testing.assert_allclose(d.point_a, 0.3 * c / 3, atol=TOL)
    np.testing.assert_allclose(d.point_b, c - 0.7 * c / 3, atol=TOL)


def test_distance_far_from_origin():
    # Shapes 10 km from the origin keep their separation: queries are evaluated in A's
    # frame (types.h). Positions near 1e4 have an ulp of 2e-12, so TOL still applies.
    box, ball = wmo.Box((1, 1, 1)), wmo.Sphere(0.5)
    far = np.array([1e4, -1e4, 1e4])
    d = G.distance(box, pose(*far), ball, pose(*(far + [3, 0, 0])))
    assert d.distance == pytest.approx(1.5, abs=TOL)
    np.testing.assert_allclose(d.point_a - far, [1, 0, 0], atol=TOL)


def test_distance_parallel_capsules():
    a, b = wmo.Capsule(0.5, 1.0), wmo.Capsule(0.25, 2.0)
    d = G.distance(a, pose(), b, pose(2, 0.3, 0))
    assert d.distance == pytest.approx(2 - 0.75, abs=TOL)
    np.testing.assert_allclose(d.normal, [1, 0, 0], atol=TOL)


@pytest.mark.parametrize("centre, depth", [
    (1.2, 0.3),   # cores apart, radii overlap
    (0.8, 0.7),   # sphere centre inside the box: EPA on the core
])
def test_overlap_sphere_box(centre, depth):
    box, ball = wmo.Box((1, 1, 1)), wmo.Sphere(0.5)
    d = G.distance(box, ORIGIN, ball, pose(centre))
    assert d.intersecting and d.distance == 0.0
    for query in (G.closest_points, G.penetration):
        r = query(box, ORIGIN, ball, pose(centre))
        assert r.intersecting and r.status == "ok"
        assert r.distance == pytest.approx(-depth, abs=TOL)
        np.testing.assert_allclose(r.normal, [1, 0, 0], atol=TOL)
        np.testing.assert_allclose(r.point_a, [1, 0, 0], atol=TOL)
        np.testing.assert_allclose(r.point_b, [1 - depth, 0, 0], atol=TOL)


def test_penetration_box_box():
    a, b = wmo.Box((1, 1, 1)), wmo.Box((0.5, 0.5, 0.5))
    r = G.penetration(a, ORIGIN, b, pose(0.1, 1.3, -0.2))
    assert r.intersecting
    assert r.distance == pytest.approx(-0.2, abs=TOL)
    np.testing.assert_allclose(r.normal, [0, 1, 0], atol=TOL)
    assert r.point_a[1] == pytest.approx(1.0, abs=TOL)
    assert r.point_b[1] == pytest.approx(0.8, abs=TOL)


def test_separated_penetration_is_plain_distance():
    a, b = wmo.Box((1, 1, 1)), wmo.Box((0.5, 0.5, 0.5))
    r = G.penetration(a, ORIGIN, b, pose(0, 2, 0))
    assert not r.intersecting and r.distance == pytest.approx(0.5, abs=TOL)


def test_intersect():
    a, b = wmo.Box((1, 1, 1)), wmo.Sphere(0.5)
    assert G.intersect(a, ORIGIN, b, pose(1.4, 0, 0))
    assert not G.intersect(a, ORIGIN, b, pose(1.6, 0, 0))
    # Near the corner: the bounding boxes overlap but the corner (1, 1, 1) is sqrt(3) * 0.3
    # = 0.52 from the centre, beyond the radius 0.5.
    assert not G.intersect(a, ORIGIN, b, pose(1.3, 1.3, 1.3))
    assert G.intersect(a, ORIGIN, b, pose(1.25, 1.25, 1.25))  # 0.43 from the corner


# ---------------------------------------------------------------- collide

def test_collide_sphere_sphere():
    m = G.collide(wmo.Sphere(1.0), ORIGIN, wmo.Sphere(0.5), pose(0, 1.2, 0))
    assert m.count == 1 and m and m.status == "ok" and len(m) == 1
    np.testing.assert_allclose(m.normal, [0, 1, 0], atol=TOL)
    np.testing.assert_allclose(m.depths, [0.3], atol=TOL)
    np.testing.assert_allclose(m.points_a, [[0, 1, 0]], atol=TOL)
    np.testing.assert_allclose(m.points_b, [[0, 0.7, 0]], atol=TOL)
    assert m.child_a == -1 and m.child_b == -1
    assert m.max_depth == pytest.approx(0.3, abs=TOL)


@pytest.mark.parametrize("special", [True, False])
def test_collide_box_resting_on_box(special):
    # B's bottom face (y = 0.4) is 0.1 below A's top face (y = 0.5) and lies inside it:
    # the manifold is B's bottom face corners, depth 0.1 each.
    a, b = wmo.Box((2, 0.5, 2)), wmo.Box((0.5, 0.5, 0.5))
    m = G.collide(a, ORIGIN, b, pose(0.3, 0.9, -0.2), special=special)
    assert m.count == 4 and m.status == "ok"
    np.testing.assert_allclose(m.normal, [0, 1, 0], atol=TOL)
    np.testing.assert_allclose(m.depths, 0.1, atol=TOL)
    corners = np.array([[0.3 + sx, 0.4, -0.2 + sz] for sx in (-0.5, 0.5) for sz in (-0.5, 0.5)])
    assert same_point_set(m.points_b, corners, TOL)
    assert same_point_set(m.points_a, corners + [0, 0.1, 0], TOL)
    assert_manifold_convention(m)
    assert len(set(m.feature_ids.tolist())) == 4  # one id per contact point


def test_collide_normal_points_from_a_to_b_and_flips_with_order():
    box, ball = wmo.Box((1, 1, 1)), wmo.Sphere(0.5)
    ab = G.collide(box, ORIGIN, ball, pose(0, 0, 1.3))
    ba = G.collide(ball, pose(0, 0, 1.3), box, ORIGIN)
    np.testing.assert_allclose(ab.normal, [0, 0, 1], atol=TOL)
    np.testing.assert_allclose(ba.normal, [0, 0, -1], atol=TOL)
    np.testing.assert_allclose(ab.points_a, ba.points_b, atol=TOL)
    np.testing.assert_allclose(ab.points_b, ba.points_a, atol=TOL)
    np.testing.assert_allclose(ab.depths, ba.depths, atol=TOL)
    for m in (ab, ba):
        assert_manifold_convention(m)


def test_collide_margin_reports_speculative_contacts():
    a, b = wmo.Sphere(0.5), wmo.Sphere(0.5)
    gap = 0.05
    assert G.collide(a, ORIGIN, b, pose(1 + gap)).count == 0
    m = G.collide(a, ORIGIN, b, pose(1 + gap), margin=0.1)
    assert m.count == 1
    np.testing.assert_allclose(m.depths, [-gap], atol=TOL)  # negative: apart
    assert_manifold_convention(m)
    assert G.collide(a, ORIGIN, b, pose(1 + gap), margin=0.01).count == 0


def test_collide_plane_box():
    # Half-space y <= 0 against a unit box whose bottom face is 0.05 below the surface.
    plane, box = wmo.Plane((0, 1, 0), 0.0), wmo.Box((0.5, 0.5, 0.5))
    m = G.collide(plane, ORIGIN, box, pose(1.0, 0.45, 2.0))
    assert m.count == 4
    np.testing.assert_allclose(m.normal, [0, 1, 0], atol=TOL)
    np.testing.assert_allclose(m.depths, 0.05, atol=TOL)
    np.testing.assert_allclose(m.points_b[:, 1], -0.05, atol=TOL)
    assert_manifold_convention(m)


def test_collide_compound_one_manifold_per_child():
    ball = wmo.Sphere(0.5)
    comp = wmo.Compound([(ball, wmo.Pose((-1, 0, 0))), (ball, wmo.Pose((1, -0.02, 0)))])
    ground = wmo.Box((5, 0.5, 5))
    pa, pb = pose(0, 0.45, 0), pose(0, -0.5, 0)  # ground top at y = 0
    all_m = G.collide_all(comp, pa, ground, pb)
    assert sorted(m.child_a for m in all_m) == [0, 1]
    for m in all_m:
        assert m.status == "ok" and m.count == 1 and m.child_b == -1
        np.testing.assert_allclose(m.normal, [0, -1, 0], atol=TOL)  # from the compound down
        expected = 0.05 if m.child_a == 0 else 0.07
        np.testing.assert_allclose(m.depths, [expected], atol=TOL)
    deepest = G.collide(comp, pa, ground, pb)
    assert deepest.child_a == 1 and deepest.max_depth == pytest.approx(0.07, abs=TOL)


def quad_mesh():
    v = np.array([[-2, 0, -2], [-2, 0, 2], [2, 0, 2], [2, 0, -2]], dtype=float)
    return wmo.TriangleMesh(v, [[0, 1, 2], [0, 2, 3]])  # CCW seen from +y: normals +y


def test_collide_mesh_sphere():
    mesh, ball = quad_mesh(), wmo.Sphere(0.5)
    ms = G.collide_all(mesh, ORIGIN, ball, pose(1.0, 0.4, -1.0))  # over triangle 1 only
    assert len(ms) == 1
    m = ms[0]
    assert m.child_a == 1 and m.count == 1
    np.testing.assert_allclose(m.normal, [0, 1, 0], atol=TOL)
    np.testing.assert_allclose(m.depths, [0.1], atol=TOL)
    np.testing.assert_allclose(m.points_a, [[1.0, 0.0, -1.0]], atol=TOL)
    assert G.collide_all(mesh, ORIGIN, ball, pose(1.0, 0.6, -1.0)) == []


@pytest.mark.parametrize("tilt, y", [(0.3, 0.1), (0.6, 0.05), (1.0, 0.1), (1.0, -0.05), (1.3, -0.05), (0.0, -0.05)])
def test_collide_mesh_capsule_through_the_plane_is_pushed_out_the_near_side(tilt, y):
    # A capsule (radius 0.2, half-height 0.3) tilted about x, its core through the
    # quad's plane, its centre 0.14 m from the diagonal that the two triangles share.
    # GJK / EPA's shortest way out of either triangle alone is sideways through that
    # internal edge; the contact must instead push the capsule out of the plane on the
    # side through which less of it has to pass, and both triangles must agree. Before:
    # tilt 0.3 at y = 0.1 was pushed down by 0.587 (through the floor), and at tilt 1.0,
    # y = -0.05 the triangles took opposite sides and reported nothing.
    cap = wmo.Capsule(0.2, 0.3)
    ms = G.collide_all(quad_mesh(), ORIGIN, cap, pose(0.5, y, 0.3, quat_axis_angle((1, 0, 0), tilt)))
    reach = 0.3 * math.cos(tilt)  # the core's ends at y -+ reach
    below, above = 0.2 + reach - y, 0.2 + reach + y  # depth out the top, out the bottom
    side, depth = (1, below) if below < above else (-1, above)
    assert ms, "no contact for a capsule through the mesh"
    for m in ms:
        np.testing.assert_allclose(m.normal, [0, side, 0], atol=TOL)
    assert max(max(m.depths) for m in ms) == pytest.approx(depth, abs=1e-9)


def test_collide_two_sided_mesh_hull_in_a_valley_is_not_pushed_through_the_next_triangle():
    # Three triangles of a rolling two-sided ground (scripts/fuzz_worlds.py seed 2305,
    # beside a wall at x = -10) and a 67 kg hull resting 5 mm deep in triangles 1 and 2,
    # overlapping triangle 0 by 8 mm just past the valley edge they share. EPA's way out
    # of triangle 0 alone is sideways past that edge, leaning 17 degrees to the sheet's
    # back; taken as the side, the contact pushed the hull down through the ground
    # along triangle 1's back normal, 0.33 m deep, and the fuzz scene lost it. The
    # hull's centre lies beyond that edge, in front of triangle 1 (the sheet where it
    # is): every triangle must push it out through its front, by millimetres.
    v = np.array([[-10, 0.099721, -6], [-10, -0.343116, -4], [-10, 0.185853, -2], [-8, -0.343116, -6],
                  [-8, 0.185853, -4]])
    tris = [[0, 1, 3], [1, 4, 3], [1, 2, 4]]
    mesh = wmo.TriangleMesh(v, tris, one_sided=False)
    hull = wmo.ConvexHull([[0.01962, -0.151863, 0.331565], [-0.173444, 0.153552, 0.100027],
                           [-0.092293, -0.005649, -0.325178], [0.17862, 0.09206, -0.137871],
                           [0.064329, 0.346146, 0.024833], [0.025816, 0.266499, -0.24705],
                           [0.083612, 0.202499, -0.264345]])
    ms = G.collide_all(mesh, ORIGIN, hull, wmo.Pose(position=(-9.789023, -0.116039, -3.834081),
                                                    orientation=(-0.652217, 0.361937, 0.236075, -0.622803)))
    assert sorted(m.child_a for m in ms) == [0, 1, 2]
    for m in ms:
        a, b, c = v[tris[m.child_a]]
        n = np.cross(b - a, c - a)
        n /= np.linalg.norm(n)
        np.testing.assert_allclose(m.normal, n, atol=1e-9)
        assert 0 < max(m.depths) < 0.015


# ---------------------------------------------------------------- unsupported pairs

@pytest.mark.parametrize("a, b", [
    (wmo.Plane((0, 1, 0), 0.0), wmo.Plane((1, 0, 0), 0.0)),
    (quad_mesh(), quad_mesh()),
    (quad_mesh(), wmo.Plane((0, 1, 0), 0.0)),
])
def test_unsupported_pair_is_explicit(a, b):
    assert not G.collide_supported(a, b)
    m = G.collide(a, ORIGIN, b, ORIGIN)  # overlapping, yet nothing may be computed
    assert m.status == "unsupported" and m.status == G.QueryStatus.UNSUPPORTED
    assert m.count == 0
    all_m = G.collide_all(a, ORIGIN, b, ORIGIN)
    assert len(all_m) == 1 and all_m[0].status == "unsupported" and all_m[0].count == 0
    assert G.collide_supported(wmo.Sphere(1.0), b)


def test_status_names_match_enum():
    assert [s.value for s in G.QueryStatus] == list(wmo._core.geometry.status_names())
    assert G.QueryStatus.UNSUPPORTED.code == 1
    assert G.QueryStatus.from_code(1) is G.QueryStatus.UNSUPPORTED
    assert str(G.QueryStatus.MAX_ITERATIONS) == "max_iterations"


# ---------------------------------------------------------------- ray casts

def test_raycast_sphere():
    ball = wmo.Sphere(0.5)
    h = G.raycast(ball, ORIGIN, origin=(-3, 0, 0), direction=(1, 0, 0))
    assert h.hit and h and h.status == "ok" and h.child == -1
    assert h.distance == pytest.approx(2.5, abs=TOL)
    np.testing.assert_allclose(h.point, [-0.5, 0, 0], atol=TOL)
    np.testing.assert_allclose(h.normal, [-1, 0, 0], atol=TOL)
    # Distance is in units of |direction|.
    h2 = G.raycast(ball, ORIGIN, (-3, 0, 0), (2, 0, 0))
    assert h2.distance == pytest.approx(1.25, abs=TOL)
    np.testing.assert_allclose(h2.point, h.point, atol=TOL)
    # Cut short by max_distance; offset ray misses.
    assert not G.raycast(ball, ORIGIN, (-3, 0, 0), (1, 0, 0), max_distance=2.4).hit
    assert not G.raycast(ball, ORIGIN, (-3, 0.6, 0), (1, 0, 0)).hit
    # Starting inside a solid: hit at distance 0 with a zero normal.
    inside = G.raycast(ball, ORIGIN, (0.1, 0, 0), (1, 0, 0))
    assert inside.hit and inside.distance == 0.0
    np.testing.assert_array_equal(inside.normal, [0, 0, 0])


def test_raycast_rotated_box_and_hull():
    box = wmo.Box((1, 2, 3))
    p = pose(5, 0, 0, quat_axis_angle((0, 1, 0), math.pi / 2))  # x extent becomes 3
    h = G.raycast(box, p, (0, 0.5, 0.5), (1, 0, 0))
    assert h.hit and h.distance == pytest.approx(2.0, abs=TOL)
    np.testing.assert_allclose(h.normal, [-1, 0, 0], atol=TOL)
    hull = wmo.ConvexHull(cube_corners((1, 2, 3)))
    h = G.raycast(hull, p, (0, 0.5, 0.5), (1, 0, 0))
    assert h.hit and h.distance == pytest.approx(2.0, abs=TOL)


def test_raycast_mesh_reports_triangle():
    h = G.raycast(quad_mesh(), ORIGIN, (1, 5, -1), (0, -1, 0))
    assert h.hit and h.child == 1
    assert h.distance == pytest.approx(5.0, abs=TOL)
    np.testing.assert_allclose(h.normal, [0, 1, 0], atol=TOL)


# ---------------------------------------------------------------- argument handling

def test_pose_tuples_are_accepted():
    box, ball = wmo.Box((1, 1, 1)), wmo.Sphere(0.5)
    d1 = G.distance(box, ((0, 0, 0), (0, 0, 0, 1)), ball, [(3, 0, 0), (0, 0, 0, 1)])
    d2 = G.distance(box, ORIGIN, ball, pose(3))
    assert d1.distance == d2.distance


@pytest.mark.parametrize("bad, exc, match", [
    (((0, 0, 0), (0, 0, 0, 2)), ValueError, r"pose_b\.orientation"),
    (((0, 0, float("nan")), (0, 0, 0, 1)), ValueError, r"pose_b\.position"),
    (((0, 0), (0, 0, 0, 1)), TypeError, r"pose_b\.position.*\(3,\)"),
    ((0, 0, 0), TypeError, r"pose_b"),
    ("origin", TypeError, r"pose_b"),
])
def test_bad_pose_arguments(bad, exc, match):
    with pytest.raises(exc, match=match):
        G.distance(wmo.Sphere(1.0), ORIGIN, wmo.Sphere(1.0), bad)


@pytest.mark.parametrize("call, match", [
    (lambda a, b: G.distance(a, ORIGIN, b, ORIGIN, gjk_tolerance=0.0), "gjk_tolerance"),
    (lambda a, b: G.distance(a, ORIGIN, b, ORIGIN, gjk_max_iterations=0), "gjk_max_iterations"),
    (lambda a, b: G.penetration(a, ORIGIN, b, ORIGIN, epa_tolerance=-1.0), "epa_tolerance"),
    (lambda a, b: G.closest_points(a, ORIGIN, b, ORIGIN, epa_max_iterations=-3), "epa_max_iterations"),
    (lambda a, b: G.collide(a, ORIGIN, b, ORIGIN, margin=-0.1), "margin"),
    (lambda a, b: G.collide(a, ORIGIN, b, ORIGIN, margin=float("nan")), "margin"),
    (lambda a, b: G.raycast(a, ORIGIN, (0, 0, 0), (0, 0, 0)), "direction"),
    (lambda a, b: G.raycast(a, ORIGIN, (0, 0, 0), (1, float("nan"), 0)), "direction"),
    (lambda a, b: G.raycast(a, ORIGIN, (float("inf"), 0, 0), (1, 0, 0)), "origin"),
    (lambda a, b: G.raycast(a, ORIGIN, (0, 0, 0), (1, 0, 0), float("nan")), "max_distance"),
    (lambda a, b: G.raycast(a, ORIGIN, (0, 0, 0), (1, 0, 0), -1.0), "max_distance"),
])
def test_bad_settings_raise_value_error(call, match):
    with pytest.raises(ValueError, match=match):
        call(wmo.Sphere(1.0), wmo.Sphere(1.0))


def test_non_shape_argument_is_type_error():
    with pytest.raises(TypeError):
        G.distance("box", ORIGIN, wmo.Sphere(1.0), ORIGIN)


def test_result_arrays_are_read_only_copies():
    d = G.distance(wmo.Sphere(0.5), ORIGIN, wmo.Sphere(0.5), pose(2))
    with pytest.raises(ValueError):
        d.point_a[0] = 1.0
    assert d.point_a.shape == (3,) and d.point_a.dtype == np.float64
