"""Shapes and poses from Python: construction, validation (field names in messages),
properties, array views, and mass properties against closed forms."""
from __future__ import annotations

import gc
import math
import pickle

import numpy as np
import pytest

import wmo
from conftest import cube_corners, quat_axis_angle, rot_matrix

# Closed-form mass properties are evaluated in double precision from short formulas;
# WMO's hull integration (divergence theorem over faces) sums O(100) terms, so agreement
# to 1e-9 relative is expected. Tolerances below are relative to the magnitude.
RTOL = 1e-9
NAN, INF = float("nan"), float("inf")


# ---------------------------------------------------------------- construction

def test_class_hierarchy_supports_isinstance():
    ball = wmo.Sphere(0.5)
    mesh = wmo.TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]])
    plane = wmo.Plane((0, 1, 0), 0.0)
    assert isinstance(ball, wmo.ConvexShape) and isinstance(ball, wmo.Shape)
    assert isinstance(wmo.Box((1, 2, 3)), wmo.ConvexShape)
    assert isinstance(wmo.ConvexHull(cube_corners()), wmo.ConvexShape)
    assert isinstance(mesh, wmo.Shape) and not isinstance(mesh, wmo.ConvexShape)
    assert isinstance(plane, wmo.Shape) and not isinstance(plane, wmo.ConvexShape)
    assert ball.is_convex and ball.is_solid
    assert not mesh.is_convex and not mesh.is_solid and not plane.is_solid


def test_abstract_bases_cannot_be_instantiated():
    with pytest.raises(TypeError):
        wmo.Shape()
    with pytest.raises(TypeError):
        wmo.ConvexShape()


def test_properties_and_repr():
    box = wmo.Box(half_extents=(1, 2, 3), rounding=0.25)
    np.testing.assert_array_equal(box.half_extents, [1, 2, 3])
    assert box.rounding == 0.25 and box.type == "box"
    assert repr(box) == "Box(half_extents=(1.0, 2.0, 3.0), rounding=0.25)"
    assert wmo.Box((1.0, 0.5, 1.0)).rounding == 0.0  # positional half extents, default rounding
    ball = wmo.Sphere(radius=0.5)
    assert ball.radius == 0.5 and repr(ball) == "Sphere(radius=0.5)"
    cap = wmo.Capsule(radius=0.3, half_height=0.7)
    assert (cap.radius, cap.half_height, cap.type) == (0.3, 0.7, "capsule")
    assert "Capsule(radius=0.3, half_height=0.7)" == repr(cap)
    cyl = wmo.Cylinder(radius=0.4, half_height=1.1)
    assert (cyl.radius, cyl.half_height, cyl.type) == (0.4, 1.1, "cylinder")
    plane = wmo.Plane(normal=(0, 0, 2), offset=1.5)
    np.testing.assert_allclose(plane.normal, [0, 0, 1])  # normalised
    assert plane.offset == 1.5 and plane.type == "plane"


def test_property_arrays_are_read_only():
    box = wmo.Box((1, 2, 3))
    with pytest.raises(ValueError):
        box.half_extents[0] = 5.0
    np.testing.assert_array_equal(box.half_extents, [1, 2, 3])
    pose = wmo.Pose(position=(1, 2, 3))
    with pytest.raises(ValueError):
        pose.position[0] = 0.0


def test_hull_merges_coplanar_faces_and_drops_interior_points(rng):
    pts = np.vstack([cube_corners((1, 2, 3)), rng.uniform(-0.5, 0.5, size=(20, 3))])
    hull = wmo.ConvexHull(pts)
    assert hull.vertices.shape == (8, 3)
    assert sorted(map(tuple, hull.vertices)) == sorted(map(tuple, cube_corners((1, 2, 3))))
    assert len(hull.faces) == 6 and all(len(f) == 4 for f in hull.faces)
    n = hull.face_normals
    assert n.shape == (6, 3)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, rtol=1e-12)
    # Every face normal is a signed axis and its plane passes through its vertices.
    np.testing.assert_allclose(np.sort(np.abs(n).max(axis=1)), 1.0, rtol=1e-12)
    for f, verts in enumerate(hull.faces):
        np.testing.assert_allclose(hull.vertices[verts] @ n[f], hull.face_offsets[f], atol=1e-12)
    assert repr(hull) == "ConvexHull(8 vertices, 6 faces)"


def test_hull_vertices_view_keeps_hull_alive():
    hull = wmo.ConvexHull(cube_corners((1, 2, 3)))
    v = hull.vertices
    assert not v.flags.writeable and not v.flags.owndata
    expected = np.array(v)
    del hull
    gc.collect()
    # The view owns a reference to the hull: its memory must still hold the vertices.
    np.testing.assert_array_equal(v, expected)


def test_triangle_mesh_views():
    verts = np.array([[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]], dtype=float)
    tris = np.array([[0, 1, 2], [0, 2, 3]])
    mesh = wmo.TriangleMesh(verts, tris)
    np.testing.assert_array_equal(mesh.vertices, verts)
    np.testing.assert_array_equal(mesh.triangles, tris)
    assert mesh.triangles.dtype == np.int32 and not mesh.triangles.flags.writeable
    np.testing.assert_allclose(mesh.triangle_normals, [[0, 0, 1], [0, 0, 1]], atol=1e-15)
    assert not mesh.one_sided and "one_sided" not in repr(mesh)
    one = wmo.TriangleMesh(verts, tris, one_sided=True)
    assert one.one_sided and repr(one) == "TriangleMesh(4 vertices, 2 triangles, one_sided)"
    v = mesh.vertices
    del mesh
    gc.collect()
    np.testing.assert_array_equal(v, verts)


def test_one_sided_survives_the_remote_shape_spec():
    from wmo.remote.scene import shape_from_spec, shape_to_spec
    verts, tris = [[0, 0, 0], [1, 0, 0], [0, 0, 1]], [[0, 2, 1]]
    spec = shape_to_spec(wmo.TriangleMesh(verts, tris, one_sided=True))
    assert spec["one_sided"] is True and shape_from_spec(spec).one_sided
    spec = shape_to_spec(wmo.TriangleMesh(verts, tris))
    assert "one_sided" not in spec and not shape_from_spec(spec).one_sided


def test_compound_children_share_the_shapes():
    ball, box = wmo.Sphere(0.5), wmo.Box((1, 1, 1))
    comp = wmo.Compound([(ball, wmo.Pose((1, 0, 0))), (box, ((0, 2, 0), (0, 0, 0, 1)))])
    assert len(comp) == 2 and comp.type == "compound" and comp.is_solid
    (s0, p0), (s1, p1) = comp.children
    assert s0 is ball and s1 is box  # the same Python objects, not copies
    np.testing.assert_array_equal(p1.position, [0, 2, 0])


# ---------------------------------------------------------------- validation

@pytest.mark.parametrize("make, field", [
    (lambda: wmo.Sphere(0.0), "radius"),
    (lambda: wmo.Sphere(-1.0), "radius"),
    (lambda: wmo.Sphere(NAN), "radius"),
    (lambda: wmo.Sphere(INF), "radius"),
    (lambda: wmo.Box((1, 0, 1)), "half_extents"),
    (lambda: wmo.Box((1, -2, 1)), "half_extents"),
    (lambda: wmo.Box((1, NAN, 1)), "half_extents"),
    (lambda: wmo.Box((1, 1, 1), rounding=-0.1), "rounding"),
    (lambda: wmo.Box((1, 0.5, 1), rounding=0.5), "rounding"),  # must be < smallest half extent
    (lambda: wmo.Box((1, 1, 1), rounding=NAN), "rounding"),
    (lambda: wmo.Capsule(0.0, 1.0), "radius"),
    (lambda: wmo.Capsule(NAN, 1.0), "radius"),
    (lambda: wmo.Capsule(0.5, -1.0), "half_height"),
    (lambda: wmo.Cylinder(-0.5, 1.0), "radius"),
    (lambda: wmo.Cylinder(0.5, 0.0), "half_height"),
    (lambda: wmo.Cylinder(0.5, NAN), "half_height"),
    (lambda: wmo.ConvexHull(cube_corners()[:3]), "points"),            # < 4 points
    (lambda: wmo.ConvexHull(np.zeros((0, 3))), "points"),
    (lambda: wmo.ConvexHull([[0, 0, 0], [1, 0, 0], [0, 1, 0], [1, 1, 0], [2, 3, 0]]), "points"),  # coplanar
    (lambda: wmo.ConvexHull([[0, 0, 0], [1, 1, 1], [2, 2, 2], [3, 3, 3]]), "points"),  # colinear
    (lambda: wmo.ConvexHull(np.vstack([cube_corners(), [[NAN, 0, 0]]])), "points"),
    (lambda: wmo.TriangleMesh([[0, 0, 0], [1, 0, 0], [NAN, 1, 0]], [[0, 1, 2]]), "vertices"),
    (lambda: wmo.TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 3]]), "triangles"),
    (lambda: wmo.TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, -1]]), "triangles"),
    (lambda: wmo.TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2**40]]), "triangles"),
    (lambda: wmo.Plane((0, 0, 0), 0.0), "normal"),
    (lambda: wmo.Plane((0, NAN, 1), 0.0), "normal"),
    (lambda: wmo.Plane((0, 1, 0), NAN), "offset"),
    (lambda: wmo.Compound([]), "children"),
])
def test_bad_values_raise_value_error_naming_the_field(make, field):
    with pytest.raises(ValueError, match=field) as info:
        make()
    assert isinstance(info.value, wmo.InvalidArgument)


def test_error_message_contains_the_bad_value():
    with pytest.raises(ValueError, match=r"radius.*-2\.5"):
        wmo.Sphere(-2.5)


@pytest.mark.parametrize("make, expected", [
    (lambda: wmo.Box((1, 1)), r"\(3,\)"),
    (lambda: wmo.Box([[1, 1, 1]]), r"\(3,\)"),
    (lambda: wmo.Box("abc"), r"\(3,\)"),
    (lambda: wmo.Box((1j, 1, 1)), r"\(3,\)"),
    (lambda: wmo.ConvexHull(np.zeros((5, 2))), r"\(N, 3\)"),
    (lambda: wmo.ConvexHull(np.zeros(12)), r"\(N, 3\)"),
    (lambda: wmo.TriangleMesh(np.zeros((3, 3)), np.zeros((1, 3))), r"integer"),  # float indices
    (lambda: wmo.TriangleMesh(np.eye(3), [[0, 1]]), r"\(T, 3\)"),
    (lambda: wmo.Plane((0, 1), 0.0), r"\(3,\)"),
    (lambda: wmo.Compound([(wmo.Plane((0, 1, 0), 0), wmo.Pose())]), r"convex"),
    (lambda: wmo.Compound([wmo.Sphere(1.0)]), r"pair"),
])
def test_bad_types_and_shapes_raise_type_error(make, expected):
    with pytest.raises(TypeError, match=expected):
        make()


# ---------------------------------------------------------------- poses

def test_pose_defaults_and_accessors():
    p = wmo.Pose()
    np.testing.assert_array_equal(p.position, [0, 0, 0])
    np.testing.assert_array_equal(p.orientation, [0, 0, 0, 1])
    p = wmo.Pose(position=(1, 2, 3), orientation=(0, 0, 0, 1))
    np.testing.assert_array_equal(p.as_array(), [1, 2, 3, 0, 0, 0, 1])
    assert repr(p) == "Pose(position=(1.0, 2.0, 3.0), orientation=(0.0, 0.0, 0.0, 1.0))"


def test_pose_quaternion_order_is_xyzw():
    # 90 degrees about +z maps +x to +y (right-handed, SciPy's (x, y, z, w) order).
    q = quat_axis_angle((0, 0, 1), math.pi / 2)
    p = wmo.Pose(position=(0, 0, 0), orientation=q)
    np.testing.assert_allclose(p.transform_point((1, 0, 0)), [0, 1, 0], atol=1e-15)
    np.testing.assert_allclose(p.matrix(), rot_matrix(q), atol=1e-15)


def test_pose_composition_and_inverse(rng):
    for row_a, row_b in zip(*[rng.normal(size=(20, 7))] * 2):
        pa = wmo.Pose(row_a[:3], row_a[3:] / np.linalg.norm(row_a[3:]))
        pb = wmo.Pose(row_b[:3], row_b[3:] / np.linalg.norm(row_b[3:]))
        x = rng.normal(size=3)
        # (a * b)(x) == a(b(x)); a^-1(a(x)) == x. 1e-12: a few roundings of O(1) values.
        np.testing.assert_allclose((pa * pb).transform_point(x),
                                   pa.transform_point(pb.transform_point(x)), atol=1e-12)
        np.testing.assert_allclose(pa.inverse().transform_point(pa.transform_point(x)), x,
                                   atol=1e-12)
        np.testing.assert_allclose(pa.inverse_transform_point(pa.transform_point(x)), x,
                                   atol=1e-12)
        # Batched (N, 3) form equals the single form row by row.
        pts = rng.normal(size=(5, 3))
        np.testing.assert_array_equal(pa.transform_point(pts),
                                      np.array([pa.transform_point(r) for r in pts]))


def test_pose_array_and_pickle_round_trip():
    p = wmo.Pose((1, -2, 3), quat_axis_angle((1, 2, 3), 0.7))
    q = wmo.Pose.from_array(p.as_array())
    np.testing.assert_array_equal(q.as_array(), p.as_array())
    r = pickle.loads(pickle.dumps(p))
    np.testing.assert_array_equal(r.as_array(), p.as_array())


def test_pose_renormalises_nearly_unit_quaternion():
    # |q| = 1 + 4e-6 is within the 1e-5 tolerance (kUnitQuatTolerance) and is renormalised.
    p = wmo.Pose(orientation=(0, 0, 0, 1 + 4e-6))
    assert np.linalg.norm(p.orientation) == pytest.approx(1.0, abs=1e-15)


@pytest.mark.parametrize("kwargs, field, value", [
    (dict(orientation=(0, 0, 0, 2)), "orientation", "2"),
    (dict(orientation=(0, 0, 0, 0)), "orientation", "0"),
    (dict(orientation=(0.5, 0, 0, 1)), "orientation", "0.5"),
    (dict(orientation=(NAN, 0, 0, 1)), "orientation", "nan"),
    (dict(position=(0, NAN, 0)), "position", "nan"),
    (dict(position=(INF, 0, 0)), "position", "inf"),
])
def test_pose_bad_values(kwargs, field, value):
    with pytest.raises(ValueError, match=field) as info:
        wmo.Pose(**kwargs)
    assert value in str(info.value)


@pytest.mark.parametrize("kwargs, expected", [
    (dict(position=(0, 0)), r"position.*\(3,\)"),
    (dict(orientation=(0, 0, 1)), r"orientation.*\(4,\)"),
    (dict(orientation="wxyz"), r"orientation"),
])
def test_pose_bad_shapes(kwargs, expected):
    with pytest.raises(TypeError, match=expected):
        wmo.Pose(**kwargs)


# ---------------------------------------------------------------- bounds and support

def test_aabbs():
    box = wmo.Box((1, 2, 3))
    lo, hi = box.local_aabb()
    np.testing.assert_array_equal(lo, [-1, -2, -3])
    np.testing.assert_array_equal(hi, [1, 2, 3])
    # 45 degrees about z: the x and y extents become (hx + hy) / sqrt(2) (Arvo).
    pose = wmo.Pose((10, 0, 0), quat_axis_angle((0, 0, 1), math.pi / 4))
    lo, hi = box.aabb(pose)
    e = 3 / math.sqrt(2)
    np.testing.assert_allclose(lo, [10 - e, -e, -3], atol=1e-12)
    np.testing.assert_allclose(hi, [10 + e, e, 3], atol=1e-12)
    # A sphere's box is tight whatever the rotation.
    lo, hi = wmo.Sphere(0.5).aabb(wmo.Pose((1, 2, 3), quat_axis_angle((1, 1, 0), 0.3)))
    np.testing.assert_allclose(lo, [0.5, 1.5, 2.5], atol=1e-12)
    np.testing.assert_allclose(hi, [1.5, 2.5, 3.5], atol=1e-12)
    # Capsule along local Y.
    lo, hi = wmo.Capsule(0.5, 1.0).local_aabb()
    np.testing.assert_allclose(hi, [0.5, 1.5, 0.5])


def test_support_points():
    np.testing.assert_array_equal(wmo.Box((1, 2, 3)).support((1, -1, 1)), [1, -2, 3])
    np.testing.assert_allclose(wmo.Sphere(0.5).support((0, 2, 0)), [0, 0.5, 0], atol=1e-15)
    # Capsule: segment end plus radius along the direction.
    np.testing.assert_allclose(wmo.Capsule(0.5, 1.0).support((0, 1, 0)), [0, 1.5, 0], atol=1e-15)
    np.testing.assert_allclose(wmo.Cylinder(0.5, 1.0).support((1, 1, 0)), [0.5, 1.0, 0],
                               atol=1e-15)
    np.testing.assert_allclose(wmo.ConvexHull(cube_corners()).support((1, 2, 3)), [1, 1, 1])


# ---------------------------------------------------------------- mass properties

def _check_mass(props, volume, inertia_per_density, density, com=(0, 0, 0)):
    assert props.volume == pytest.approx(volume, rel=RTOL)
    assert props.mass == pytest.approx(density * volume, rel=RTOL)
    np.testing.assert_allclose(props.center_of_mass, com, atol=RTOL)
    i = density * np.asarray(inertia_per_density)
    np.testing.assert_allclose(props.inertia, i, rtol=RTOL, atol=RTOL * np.abs(i).max())


def test_mass_sphere():
    r, rho = 0.7, 1000.0
    v = 4 / 3 * math.pi * r**3
    _check_mass(wmo.Sphere(r).mass_properties(), v, np.eye(3) * 0.4 * v * r * r, rho)


def test_mass_box():
    hx, hy, hz, rho = 0.5, 1.0, 2.0, 250.0
    v = 8 * hx * hy * hz
    i = np.diag([hy**2 + hz**2, hx**2 + hz**2, hx**2 + hy**2]) * v / 3
    _check_mass(wmo.Box((hx, hy, hz)).mass_properties(density=rho), v, i, rho)


def test_mass_cylinder():
    r, h, rho = 0.5, 1.5, 7.0
    v = math.pi * r * r * 2 * h
    ixz = v * (3 * r * r + (2 * h) ** 2) / 12
    _check_mass(wmo.Cylinder(r, h).mass_properties(rho), v, np.diag([ixz, v * r * r / 2, ixz]), rho)


def test_mass_capsule():
    # Cylinder of length L = 2h plus two hemispheres (mass m_s in total) whose centres of
    # mass sit 3r/8 from the flat face: I_perp = m_c (L^2/12 + r^2/4) + m_s (2r^2/5 + L^2/4 + 3Lr/8).
    r, h, rho = 0.3, 0.8, 1000.0
    L = 2 * h
    vc, vs = math.pi * r * r * L, 4 / 3 * math.pi * r**3
    i_axis = vc * r * r / 2 + vs * 0.4 * r * r
    i_perp = vc * (L * L / 12 + r * r / 4) + vs * (0.4 * r * r + L * L / 4 + 3 * L * r / 8)
    _check_mass(wmo.Capsule(r, h).mass_properties(rho), vc + vs, np.diag([i_perp, i_axis, i_perp]), rho)


def test_mass_rounded_box_volume_and_inertia_bounds():
    # Steiner's formula for the core box (half extents a, b, c) swept by a ball of radius r:
    # V = 8abc + 8(ab + bc + ca) r + 2 pi (a + b + c) r^2 + 4/3 pi r^3.
    h, r, rho = np.array([0.5, 0.8, 1.2]), 0.2, 1000.0
    a, b, c = h - r
    v = 8 * a * b * c + 8 * (a * b + b * c + c * a) * r + 2 * math.pi * (a + b + c) * r * r \
        + 4 / 3 * math.pi * r**3
    p = wmo.Box(h, rounding=r).mass_properties(rho)
    assert p.volume == pytest.approx(v, rel=RTOL)
    np.testing.assert_allclose(p.center_of_mass, 0, atol=1e-12)
    # core box <= rounded box <= outer box as sets, so their inertias (same density and
    # centre) are ordered component-wise.
    inner = wmo.Box(h - r).mass_properties(rho).inertia
    outer = wmo.Box(h).mass_properties(rho).inertia
    d = np.diag(p.inertia)
    assert np.all(np.diag(inner) < d) and np.all(d < np.diag(outer))


def test_mass_hull_of_rotated_offset_box_matches_box():
    h, rho = np.array([0.5, 1.0, 1.5]), 300.0
    q = quat_axis_angle((1, 2, 3), 0.9)
    rot, offset = rot_matrix(q), np.array([1.0, -2.0, 0.5])
    hull = wmo.ConvexHull(cube_corners(h) @ rot.T + offset)
    box = wmo.Box(h).mass_properties(rho)
    v = 8 * h.prod()
    _check_mass(hull.mass_properties(rho), v, rot @ (box.inertia / rho) @ rot.T, rho, com=offset)


def test_mass_tetrahedron_centroid():
    p = wmo.ConvexHull([[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]]).mass_properties(6.0)
    assert p.volume == pytest.approx(1 / 6, rel=RTOL)
    assert p.mass == pytest.approx(1.0, rel=RTOL)
    np.testing.assert_allclose(p.center_of_mass, [0.25, 0.25, 0.25], atol=1e-12)
    # Second moments of the unit corner tetrahedron with mass 1 (density 6): the integrals
    # of x^2 and xy over it are 1/60 and 1/120, so E[x^2] = 1/10 and E[xy] = 1/20; about
    # the centroid C_ii = 1/10 - 1/16 and C_ij = 1/20 - 1/16, and I = trace(C) 1 - C.
    cii, cij = 1 / 10 - 1 / 16, 1 / 20 - 1 / 16
    cov = np.full((3, 3), cij) + np.eye(3) * (cii - cij)
    inertia = np.trace(cov) * np.eye(3) - cov
    np.testing.assert_allclose(p.inertia, inertia, atol=1e-12)


def test_mass_compound_parallel_axis():
    r, d, rho = 0.5, 2.0, 1000.0
    ball = wmo.Sphere(r)
    comp = wmo.Compound([(ball, wmo.Pose((-d, 0, 0))), (ball, wmo.Pose((d, 0, 0))),
                         (ball, wmo.Pose((d, 0, 0)))])  # overlapping children count twice
    m1 = rho * 4 / 3 * math.pi * r**3
    p = comp.mass_properties(rho)
    assert p.mass == pytest.approx(3 * m1, rel=RTOL)
    np.testing.assert_allclose(p.center_of_mass, [d / 3, 0, 0], atol=1e-12)
    i0 = 0.4 * m1 * r * r
    off = m1 * ((d + d / 3) ** 2 + 2 * (d - d / 3) ** 2)  # parallel axis about the new centre
    np.testing.assert_allclose(np.diag(p.inertia), [3 * i0, 3 * i0 + off, 3 * i0 + off], rtol=RTOL)


@pytest.mark.parametrize("shape", [
    wmo.Plane((0, 1, 0), 0.0),
    wmo.TriangleMesh([[0, 0, 0], [1, 0, 0], [0, 1, 0]], [[0, 1, 2]]),
])
def test_mass_of_non_solid_shape_raises(shape):
    with pytest.raises(ValueError):
        shape.mass_properties()


@pytest.mark.parametrize("density", [0.0, -1.0, NAN, INF])
def test_mass_bad_density(density):
    with pytest.raises(ValueError, match="density"):
        wmo.Sphere(1.0).mass_properties(density)
