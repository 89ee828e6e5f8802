"""Property-based tests (Hypothesis) of the contact conventions on random convex pairs:
swapping A and B mirrors the manifold, a common rigid motion of both shapes moves the
manifold with it, and a separated pair never reports a contact."""
from __future__ import annotations

import numpy as np
import pytest
from hypothesis import assume, given
from hypothesis import strategies as st

import wmo
from wmo import geometry as G
from conftest import convex_shapes, poses

# Tolerance on depths, points and normals, in metres (or for unit normals, absolute).
# Shapes are 0.1..1.5 m and placed within 2 m of the origin. The special routines are
# closed form (rounding ~1e-15); the generic path stops EPA at a relative tolerance of
# 1e-10 and GJK at 1e-10 on |v|^2, but on curved cores (capsule, rounded box, cylinder)
# EPA approximates a smooth surface by a polytope whose faces are accurate to about
# sqrt(1e-10) = 1e-5 relative. 1e-5 m therefore bounds what the contract can promise for
# every pair; the special-routine pairs meet it by orders of magnitude.
TOL = 1e-5
# A separated pair must be clearly apart: GJK reports distances to ~1e-10 relative, and
# contacts within 1e-6 m of touching may legitimately appear or not.
SEPARATED = 1e-6


def overlap_along(a, pa, b, pb, n):
    """Depth of the pair along unit direction n (A to B), from the support functions:
    max over A of n.x minus min over B of n.x. Moving B by this amount along n separates
    the shapes; the contact normal minimises it (the minimum translational distance)."""
    n = np.asarray(n, dtype=float)
    sa = pa.transform_point(a.support(pa.inverse().transform_vector(n)))
    sb = pb.transform_point(b.support(pb.inverse().transform_vector(-n)))
    return float(n @ sa - n @ sb)


def normals_equivalent(a, pa, b, pb, n1, n2, depth):
    """n1 == n2, or both are minimal directions: when two separating axes tie (e.g. two
    faces with equal overlap), either normal is a correct answer, and then the depth
    along each must equal the reported depth."""
    if np.linalg.norm(np.asarray(n1) - np.asarray(n2)) <= TOL:
        return True
    return (abs(overlap_along(a, pa, b, pb, n1) - depth) <= TOL and
            abs(overlap_along(a, pa, b, pb, n2) - depth) <= TOL)


def converged(*results):
    """True if every result is 'ok'. 'max_iterations' (an iterative method stopped at its
    cap: best answer so far) and 'degenerate' (e.g. coincident centres: a safe fallback)
    are valid answers without the accuracy promise, so comparisons are skipped for them;
    'unsupported' fails, as every convex pair has a routine."""
    for r in results:
        assert r.status in ("ok", "max_iterations", "degenerate"), r.status
    return all(r.status == "ok" for r in results)


def deep_enough(m):
    """Only compare manifolds whose deepest point is clearly inside: near-touching
    points may legitimately appear in one manifold and not in the other."""
    return m.count > 0 and m.max_depth > 10 * TOL


def sat_pair(a, b):
    """Pairs whose special routine is a biased SAT (box-box, hull-hull, capsule-box)."""
    kinds = {type(a), type(b)}
    return kinds in ({wmo.Box}, {wmo.ConvexHull}, {wmo.Capsule, wmo.Box})


def involves_cylinder(a, b):
    return isinstance(a, wmo.Cylinder) or isinstance(b, wmo.Cylinder)


# Known limitation (issue 2, open): a cylinder's supporting face is its cap as a 16-gon
# whose orientation is fixed for tilts below 0.05 rad (Cylinder::supporting_face), so
# the clipped manifold's deepest point can differ from the exact EPA depth by up to
# ~1e-3 of the radius, more than TOL. The manifold properties are therefore checked
# without cylinders; test_issue_2_cylinder_cap_manifold_mirrors pins a failing case and
# is expected to fail until the cap manifold is exact.
@given(a=convex_shapes(), b=convex_shapes(), pa=poses(), pb=poses(), special=st.booleans())
def test_swapping_a_and_b_mirrors_the_manifold(a, b, pa, pb, special):
    assume(not involves_cylinder(a, b))
    check_mirror(a, pa, b, pb, special)


def check_mirror(a, pa, b, pb, special):
    ab = G.collide(a, pa, b, pb, special=special)
    ba = G.collide(b, pb, a, pa, special=special)
    if not converged(ab, ba):
        return
    for m in (ab, ba):
        if m.count:
            np.testing.assert_allclose(m.points_b, m.points_a - m.depths[:, None] * m.normal,
                                       atol=TOL)
    if not (deep_enough(ab) or deep_enough(ba)):
        return
    # Both orders see the contact, with the same (maximum) depth.
    assert ab.count > 0 and ba.count > 0
    if special and sat_pair(a, b):
        # The SAT routines prefer A's faces, then B's, then edges, switching only for an
        # axis better by 5% of the depth + 1e-5 * size (clip.h kSatRelTolerance,
        # kSatAbsTolerance; Box2D's rule), so the two orders may pick different axes
        # whose depths differ by up to that bias. Both must still separate the pair.
        bias = 0.05 * max(ab.max_depth, ba.max_depth) + 1e-5 * 2.0 + TOL
        assert abs(ab.max_depth - ba.max_depth) <= bias
        return
    assert abs(ab.max_depth - ba.max_depth) <= TOL
    # The normal is negated (or both are minimal at a tie).
    assert normals_equivalent(a, pa, b, pb, ab.normal, -ba.normal, ab.max_depth)
    # Points swapped, for single-point manifolds with the same (negated) normal. With
    # several points the reference face may legitimately differ between the two orders,
    # and at a tie (e.g. coincident sphere centres, where any direction is minimal) the
    # points belong to different normals.
    same_normal = np.linalg.norm(ab.normal + ba.normal) <= TOL
    if same_normal and ab.count == 1 and ba.count == 1:
        np.testing.assert_allclose(ab.points_a, ba.points_b, atol=TOL)
        np.testing.assert_allclose(ab.points_b, ba.points_a, atol=TOL)
        np.testing.assert_allclose(ab.depths, ba.depths, atol=TOL)


@given(a=convex_shapes(), b=convex_shapes(), pa=poses(), pb=poses(), motion=poses(),
       special=st.booleans())
def test_common_rigid_motion_moves_the_manifold(a, b, pa, pb, motion, special):
    assume(not involves_cylinder(a, b))
    check_motion(a, pa, b, pb, motion, special)


def check_motion(a, pa, b, pb, motion, special):
    m0 = G.collide(a, pa, b, pb, special=special)
    m1 = G.collide(a, motion * pa, b, motion * pb, special=special)
    if not converged(m0, m1):
        return
    if not (deep_enough(m0) or deep_enough(m1)):
        return
    assert m0.count > 0 and m1.count > 0
    assert abs(m0.max_depth - m1.max_depth) <= TOL
    moved_normal = motion.transform_vector(m0.normal)
    assert normals_equivalent(a, motion * pa, b, motion * pb, moved_normal, m1.normal,
                              m1.max_depth)
    if np.linalg.norm(moved_normal - m1.normal) <= TOL and m0.count == m1.count:
        # Same features: the points move rigidly (order-free comparison).
        p0 = motion.transform_point(m0.points_a)
        d = np.linalg.norm(p0[:, None, :] - m1.points_a[None, :, :], axis=2)
        assert d.min(axis=1).max() <= TOL and d.min(axis=0).max() <= TOL
        np.testing.assert_allclose(np.sort(m0.depths), np.sort(m1.depths), atol=TOL)


@pytest.mark.xfail(strict=True, reason="cylinder cap manifold is a fixed 16-gon at small tilt")
def test_issue_2_cylinder_cap_manifold_mirrors():
    check_mirror(wmo.Capsule(radius=1.0, half_height=1.0), wmo.Pose(orientation=(0, 1, 0, 0)),
                 wmo.Cylinder(radius=1.0, half_height=1.0),
                 wmo.Pose(orientation=(0.9999923706927791, 0.0039062201980186685, 0, 0)), False)


@given(a=convex_shapes(), b=convex_shapes(), pa=poses(), pb=poses(), special=st.booleans())
def test_separated_pair_reports_no_contact(a, b, pa, pb, special):
    d = G.distance(a, pa, b, pb)
    assume(converged(d) and d.distance > SEPARATED)
    m = G.collide(a, pa, b, pb, special=special)
    converged(m)
    assert not (m.depths > 0).any()
    assert m.count == 0  # margin 0: only touching or overlapping pairs report points


@given(a=convex_shapes(), b=convex_shapes(), pa=poses(), pb=poses(),
       margin=st.floats(0.05, 0.5), fraction=st.floats(0.05, 0.95))
def test_speculative_contact_depth_is_minus_distance(a, b, pa, pb, margin, fraction):
    # Random poses are rarely within the margin, so B is first slid along the separating
    # normal to a gap of about fraction * margin; the gap is then measured again.
    d = G.distance(a, pa, b, pb)
    assume(converged(d) and not d.intersecting and d.distance > SEPARATED)
    shift = (fraction * margin - d.distance) * np.asarray(d.normal)
    pb = wmo.Pose(position=np.asarray(pb.position) + shift, orientation=pb.orientation)
    d = G.distance(a, pa, b, pb)
    assume(converged(d) and SEPARATED < d.distance < margin - SEPARATED)
    # Both paths: the deepest (least negative) point is at exactly -distance and every
    # point is within the margin. (The SAT routines hand separated pairs to the generic
    # path, whose GJK distance is exact: see refine_separated in dispatch.cpp.)
    for special in (False, True):
        m = G.collide(a, pa, b, pb, margin=margin, special=special)
        if not converged(m):
            continue
        assert m.count > 0
        assert abs(m.max_depth + d.distance) <= TOL
        assert (m.depths >= -margin - TOL).all()


@given(a=convex_shapes(), b=convex_shapes(), pa=poses(), pb=poses())
def test_distance_is_symmetric_and_consistent(a, b, pa, pb):
    ab = G.closest_points(a, pa, b, pb)
    ba = G.closest_points(b, pb, a, pa)
    assert np.isfinite(ab.point_a).all() and np.isfinite(ab.normal).all()
    if not converged(ab, ba):
        return
    assert abs(ab.distance - ba.distance) <= TOL
    assert ab.intersecting == ba.intersecting or abs(ab.distance) <= SEPARATED
    # The witness points are the signed distance apart along the normal (for an
    # overlapping pair point_b = point_a - depth * normal, the same relation).
    np.testing.assert_allclose(ab.point_b - ab.point_a, ab.distance * ab.normal, atol=TOL)
    if ab.distance > SEPARATED:
        np.testing.assert_allclose(np.linalg.norm(ab.point_b - ab.point_a), ab.distance, atol=TOL)
