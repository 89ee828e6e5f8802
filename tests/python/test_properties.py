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


# The manifold's deepest point is the EPA depth for every pair, cylinders included:
# clipped points deeper than it are raised to it and a shallower clip gets the EPA
# point added (collide_convex.cpp), so both orders agree on the depth.
@given(a=convex_shapes(), b=convex_shapes(), pa=poses(), pb=poses(), special=st.booleans())
def test_swapping_a_and_b_mirrors_the_manifold(a, b, pa, pb, special):
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
    # Not with cylinders: a cylinder's side against a face or an edge touches along a
    # segment, where the single EPA witness point may be anywhere on it (found by
    # HYPOTHESIS_PROFILE=explore: 0.8 m apart along a cylinder side against a box).
    same_normal = np.linalg.norm(ab.normal + ba.normal) <= TOL
    if same_normal and ab.count == 1 and ba.count == 1 and not involves_cylinder(a, b):
        np.testing.assert_allclose(ab.points_a, ba.points_b, atol=TOL)
        np.testing.assert_allclose(ab.points_b, ba.points_a, atol=TOL)
        np.testing.assert_allclose(ab.depths, ba.depths, atol=TOL)


@given(a=convex_shapes(), b=convex_shapes(), pa=poses(), pb=poses(), motion=poses(),
       special=st.booleans())
def test_common_rigid_motion_moves_the_manifold(a, b, pa, pb, motion, special):
    # Not with cylinders: on a curved side the depth is flat to second order about the
    # optimum, so EPA's normal is good only to ~sqrt(depth tolerance / size) (1e-4 rad
    # at 1e-8), and the cap polygon turns with it; points then move by more than TOL
    # under a rigid motion (found by HYPOTHESIS_PROFILE=explore: 1.7e-5 m).
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


# A capsule through a cylinder, both nearly on the Z axis (found by the mirror property
# when cylinders were first included): in this order EPA on the capsule's segment core
# against the cylinder needs 148 iterations (at a cap of 128 it stopped with the bracket
# still 8e-5 m wide, so the default cap is now 256); the other order converges in 107.
# The true depth is 2 m.
CAPSULE_THROUGH_CYLINDER = (
    wmo.Capsule(radius=1.0, half_height=1.0), wmo.Pose(orientation=(0, 1, 0, 0)),
    wmo.Cylinder(radius=1.0, half_height=1.0),
    wmo.Pose(orientation=(0.9999923706927791, 0.0039062201980186685, 0, 0)))


def test_issue_2_unconverged_epa_says_so_and_answers_a_valid_upper_bound():
    a, pa, b, pb = CAPSULE_THROUGH_CYLINDER
    ba = G.collide(b, pb, a, pa, special=False)
    assert ba.status == "ok" and ba.max_depth == pytest.approx(2.0, abs=TOL)
    # Capped at 128 iterations, before it converges (148): the status says so (it used
    # to read "ok"), and the depth is EPA's smallest support distance, an upper bound
    # (>= the true depth) that still separates the pair; the manifold's points are no
    # deeper than it.
    ab = G.collide(a, pa, b, pb, special=False, epa_max_iterations=128)
    assert ab.status == "max_iterations"
    assert 2.0 - TOL <= ab.max_depth <= 2.0 + 1e-4
    p = G.penetration(a, pa, b, pb, epa_max_iterations=128)
    assert p.status == "max_iterations"
    assert ab.max_depth <= -p.distance + 1e-12


def test_issue_2_epa_converges_for_capsule_through_cylinder():
    # At the default cap (256) EPA converges in this order too (148 iterations).
    a, pa, b, pb = CAPSULE_THROUGH_CYLINDER
    ab = G.collide(a, pa, b, pb, special=False)
    assert ab.status == "ok" and ab.max_depth == pytest.approx(2.0, abs=TOL)
    p = G.penetration(a, pa, b, pb)
    assert p.status == "ok" and -p.distance == pytest.approx(2.0, abs=TOL)


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


def test_issue_2_rounded_boxes_apart_at_a_corner_report_no_contact():
    # Found by HYPOTHESIS_PROFILE=explore: box-box SAT on rounded cores that are apart
    # measured their separation along the best axis (a lower bound near a corner), so
    # it reported 1.06e-2 m of overlap for boxes 1.0e-3 m apart. Cores apart now go to
    # the exact generic path (dispatch.cpp, sat_exact_below).
    a = wmo.Box(half_extents=(0.6875, 0.5, 1.0), rounding=0.125)
    b = wmo.Box(half_extents=(0.75, 0.5, 0.75))
    pa = wmo.Pose(position=(1.375, 0.0, 0.0), orientation=(0.0, 0.0, -0.3511234415883917, 0.9363291775690445))
    pb = wmo.Pose(position=(1.59375, -1.9375, 0.0),
                  orientation=(0.3281825932466517, 0.0, -0.3555311426838727, 0.8751535819910712))
    d = G.distance(a, pa, b, pb).distance
    assert 0.9e-3 < d < 1.1e-3
    for special in (True, False):
        assert G.collide(a, pa, b, pb, special=special).count == 0
        assert G.collide(b, pb, a, pa, special=special).count == 0
        # Within a margin, the speculative depth is minus the exact distance.
        m = G.collide(a, pa, b, pb, margin=0.01, special=special)
        assert m.count >= 1 and m.max_depth == pytest.approx(-d, abs=TOL)
