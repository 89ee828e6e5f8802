// Analytic checks of collide_plane_convex (collide_plane.cpp) and of the manifold
// reduction helper (manifold_reduce.h), in A's (the plane's) frame.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <vector>

#include "../../../cpp/src/collision/manifold_reduce.h"
#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

// Exact closed forms on O(1) inputs lose a few ulps per rotation; 1e-12 (~5000 ulps of
// a metre) is far above that and far below any geometric error worth catching.
constexpr Real kTol = 1e-12;

Quat axis_angle(Real angle, const Vec3& axis) {
  return Quat(Eigen::AngleAxisd(angle, axis.normalized()));
}

/// Conventions of types.h for a plane A: normal = plane normal, point_a on the plane,
/// point_b = point_a - depth * normal, depth = offset - n . point_b.
void check_plane_manifold(const Manifold& m, const Plane& plane) {
  ASSERT_GE(m.count, 1);
  EXPECT_LT((m.normal - plane.normal()).norm(), kTol);
  for (int i = 0; i < m.count; ++i) {
    const ContactPoint& c = m.points[i];
    ASSERT_TRUE(c.point_a.allFinite() && c.point_b.allFinite() && std::isfinite(c.depth));
    EXPECT_NEAR(plane.normal().dot(c.point_a), plane.offset(), kTol) << i;
    EXPECT_NEAR(c.depth, plane.offset() - plane.normal().dot(c.point_b), kTol) << i;
    EXPECT_LT((c.point_b - (c.point_a - c.depth * m.normal)).norm(), kTol) << i;
  }
}

/// Local-frame signed distance of a rounded box (Quilez), to check point_b.
Real sdf_box(const Vec3& p, const Vec3& core, Real rounding) {
  const Vec3 q = p.cwiseAbs() - core;
  return q.cwiseMax(0).norm() + std::min(q.maxCoeff(), Real(0)) - rounding;
}

std::vector<std::uint32_t> ids(const Manifold& m) {
  std::vector<std::uint32_t> v;
  for (int i = 0; i < m.count; ++i) v.push_back(m.points[i].feature_id);
  std::sort(v.begin(), v.end());
  return v;
}

TEST(CollidePlaneConvex, SphereOnTiltedPlane) {
  const Vec3 n = Vec3(0.3, 1, -0.2).normalized();
  Plane plane(n, 0.25);
  Sphere s(0.5);
  // Centre 0.4 above the plane: 0.1 deep.
  const Pose pb(0.65 * n + Vec3(0.2, 0, 0.4).cross(n));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, s, pb, 0, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.1, kTol);
  EXPECT_LT((m.points[0].point_b - (pb.position - 0.5 * n)).norm(), kTol);
  check_plane_manifold(m, plane);
  // Just apart (1e-6 above): margin decides.
  const Pose apart((0.75 + 1e-6) * n);
  EXPECT_FALSE(collide_plane_convex(plane, s, apart, 0, m));
  ASSERT_TRUE(collide_plane_convex(plane, s, apart, 1e-3, m));
  EXPECT_NEAR(m.points[0].depth, -1e-6, kTol);
}

TEST(CollidePlaneConvex, TouchingIsReportedWithZeroDepth) {
  Plane plane(Vec3::UnitY(), 0);
  Sphere s(0.5);
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, s, Pose(Vec3(3, 0.5, -2)), 0, m));
  EXPECT_EQ(m.points[0].depth, 0.0);  // exact in binary
}

TEST(CollidePlaneConvex, BoxRestingGivesFourBottomCorners) {
  Plane plane(Vec3::UnitY(), 0);
  Box box(Vec3(1, 0.5, 2));
  // Yawed about the plane normal, 0.01 deep.
  const Pose pb(Vec3(4, 0.49, -1), axis_angle(0.6, Vec3::UnitY()));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, box, pb, 0, m));
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kTol);
    const Vec3 local = pb.inverse_transform_point(m.points[i].point_b);
    EXPECT_NEAR(std::abs(local.x()), 1.0, kTol);
    EXPECT_NEAR(local.y(), -0.5, kTol);
    EXPECT_NEAR(std::abs(local.z()), 2.0, kTol);
  }
  // The 4 corners with bit 1 (the +y side) clear: 0, 1, 4, 5.
  EXPECT_EQ(ids(m), (std::vector<std::uint32_t>{0, 1, 4, 5}));
  check_plane_manifold(m, plane);
  // A margin taller than the box must still prefer the bottom corners.
  ASSERT_TRUE(collide_plane_convex(plane, box, pb, 5.0, m));
  EXPECT_EQ(ids(m), (std::vector<std::uint32_t>{0, 1, 4, 5}));
}

TEST(CollidePlaneConvex, RoundedBoxCornersArePushedByRounding) {
  Plane plane(Vec3::UnitY(), 0);
  Box box(Vec3(1, 0.5, 1), 0.2);
  const Pose pb(Vec3(0, 0.48, 0));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, box, pb, 0, m));
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.02, kTol);
    const Vec3 local = pb.inverse_transform_point(m.points[i].point_b);
    // On the flat bottom, above the core corners (|x|, |z| = 0.8), on the surface.
    EXPECT_NEAR(std::abs(local.x()), 0.8, kTol);
    EXPECT_NEAR(std::abs(local.z()), 0.8, kTol);
    EXPECT_NEAR(sdf_box(local, box.core_half_extents(), 0.2), 0.0, kTol);
  }
  check_plane_manifold(m, plane);
}

TEST(CollidePlaneConvex, BoxOnEdgeGivesTwoPoints) {
  Plane plane(Vec3::UnitY(), 0);
  Box box(Vec3(0.5, 0.5, 1));
  // Rolled 45 degrees about z: the bottom edge (along z) is the lowest, 0.01 deep.
  const Pose pb(Vec3(0, std::sqrt(0.5) - 0.01, 0), axis_angle(kPi / 4, Vec3::UnitZ()));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, box, pb, 0, m));
  ASSERT_EQ(m.count, 2);
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(m.points[i].depth, 0.01, kTol);
  EXPECT_NEAR(std::abs(m.points[0].point_b.z() - m.points[1].point_b.z()), 2.0, kTol);
  check_plane_manifold(m, plane);
}

TEST(CollidePlaneConvex, CapsuleLyingAndStanding) {
  Plane plane(Vec3::UnitY(), 1.0);
  Capsule cap(0.25, 0.75);
  // Lying (axis along x), 0.05 deep.
  const Pose lying(Vec3(0, 1.2, 0), axis_angle(kPi / 2, Vec3::UnitZ()));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, cap, lying, 0, m));
  ASSERT_EQ(m.count, 2);
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(m.points[i].depth, 0.05, kTol);
  EXPECT_EQ(ids(m), (std::vector<std::uint32_t>{0, 1}));
  EXPECT_NEAR(std::abs(m.points[0].point_b.x() - m.points[1].point_b.x()), 1.5, kTol);
  check_plane_manifold(m, plane);
  // Standing upside down on end 1: one point.
  const Pose standing(Vec3(0, 1.95, 0), axis_angle(kPi, Vec3::UnitX()));
  ASSERT_TRUE(collide_plane_convex(plane, cap, standing, 0, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.05, kTol);
  EXPECT_EQ(m.points[0].feature_id, 1u);
  check_plane_manifold(m, plane);
}

TEST(CollidePlaneConvex, CylinderOnCapOnSideAndTilted) {
  Plane plane(Vec3::UnitY(), 0);
  Cylinder cyl(0.5, 1.0);
  // Standing on its -y cap, 0.01 deep: 4 rim points spanning the cap.
  const Pose standing(Vec3(1, 0.99, 2), axis_angle(0.3, Vec3::UnitY()));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, cyl, standing, 0, m));
  ASSERT_EQ(m.count, 4);
  Vec3 centroid = Vec3::Zero();
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kTol);
    const Vec3 local = standing.inverse_transform_point(m.points[i].point_b);
    EXPECT_NEAR(std::hypot(local.x(), local.z()), 0.5, kTol);  // on the rim
    EXPECT_NEAR(local.y(), -1.0, kTol);
    centroid += local / 4;
  }
  // Symmetric about the axis: the centroid is the cap centre (0, -1, 0).
  EXPECT_LT((centroid - Vec3(0, -1, 0)).norm(), kTol);
  check_plane_manifold(m, plane);
  // On its side (axis along z), 0.02 deep: the 2 ends of the bottom line.
  const Pose side(Vec3(0, 0.48, 0), axis_angle(kPi / 2, Vec3::UnitX()));
  ASSERT_TRUE(collide_plane_convex(plane, cyl, side, 0, m));
  ASSERT_EQ(m.count, 2);
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(m.points[i].depth, 0.02, kTol);
  EXPECT_NEAR(std::abs(m.points[0].point_b.z() - m.points[1].point_b.z()), 2.0, kTol);
  check_plane_manifold(m, plane);
  // Tilted 30 degrees about x: only the lowest rim point touches.
  const Real tilt = kPi / 6;
  const Real low = std::cos(tilt) * 1.0 + std::sin(tilt) * 0.5;  // depth of the lowest point
  const Pose tilted(Vec3(0, low - 0.01, 0), axis_angle(tilt, Vec3::UnitX()));
  ASSERT_TRUE(collide_plane_convex(plane, cyl, tilted, 0, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.01, kTol);
  check_plane_manifold(m, plane);
}

TEST(CollidePlaneConvex, HullCubeRestsOnFourVertices) {
  // A unit cube as a hull: the supporting face is its bottom square.
  std::vector<Vec3> pts;
  for (int k = 0; k < 8; ++k)
    pts.emplace_back((k & 1) ? 0.5 : -0.5, (k & 2) ? 0.5 : -0.5, (k & 4) ? 0.5 : -0.5);
  ConvexHull hull(pts);
  Plane plane(Vec3::UnitY(), 0);
  const Pose pb(Vec3(0, 0.49, 0), axis_angle(0.2, Vec3::UnitY()));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, hull, pb, 0, m));
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kTol);
    const Vec3 local = pb.inverse_transform_point(m.points[i].point_b);
    EXPECT_NEAR(std::abs(local.x()), 0.5, kTol);
    EXPECT_NEAR(std::abs(local.z()), 0.5, kTol);
  }
  check_plane_manifold(m, plane);
  // Tilted about x by 0.1 rad: the low edge touches, the high edge is sin(0.1) above.
  const Pose tilted(Vec3(0, 0.5 * (std::cos(0.1) + std::sin(0.1)) - 0.01, 0),
                    axis_angle(0.1, Vec3::UnitX()));
  ASSERT_TRUE(collide_plane_convex(plane, hull, tilted, 0, m));
  EXPECT_EQ(m.count, 2);
  ASSERT_TRUE(collide_plane_convex(plane, hull, tilted, 0.2, m));
  EXPECT_EQ(m.count, 4);
  EXPECT_NEAR(m.max_depth(), 0.01, kTol);
  check_plane_manifold(m, plane);
}

TEST(CollidePlaneConvex, HullOctagonFaceReducedToFour) {
  // An octagonal prism: its bottom face has 8 vertices, the reduction keeps 4.
  std::vector<Vec3> pts;
  for (int k = 0; k < 8; ++k) {
    const Real a = k * kPi / 4;
    pts.emplace_back(std::cos(a), -0.5, std::sin(a));
    pts.emplace_back(std::cos(a), 0.5, std::sin(a));
  }
  ConvexHull hull(pts);
  Plane plane(Vec3::UnitY(), 0);
  const Pose pb(Vec3(0, 0.49, 0));
  Manifold m;
  ASSERT_TRUE(collide_plane_convex(plane, hull, pb, 0, m));
  ASSERT_EQ(m.count, 4);
  // The 4 kept vertices span the largest quad of the octagon: a square of alternate
  // vertices, area 2. reduce_to_4 orders them deepest, furthest (a diagonal), then the
  // two on either side of it (the other diagonal): area = |d1 x d2| / 2.
  const Vec3 d1 = m.points[1].point_b - m.points[0].point_b;
  const Vec3 d2 = m.points[3].point_b - m.points[2].point_b;
  // 1e-9: the hull's vertices went through Quickhull, which may round them.
  EXPECT_NEAR(0.5 * std::abs(d1.cross(d2).y()), 2.0, 1e-9);
  check_plane_manifold(m, plane);
}

// ---------------------------------------------------------------- reduce_to_4

TEST(ReduceTo4, KeepsDeepestAndLargestQuad) {
  // Regular octagon in the XZ plane (normal Y); vertex 3 is the deepest.
  ContactPoint pts[8];
  for (int k = 0; k < 8; ++k) {
    const Real a = k * kPi / 4;
    pts[k].point_a = Vec3(std::cos(a), 0, std::sin(a));
    pts[k].depth = k == 3 ? 0.2 : 0.1;
    pts[k].feature_id = static_cast<std::uint32_t>(k);
  }
  Manifold m;
  m.child_a = 7;
  reduce_to_4(pts, 8, Vec3::UnitY(), m);
  ASSERT_EQ(m.count, 4);
  EXPECT_EQ(m.child_a, 7);  // untouched
  EXPECT_EQ(m.points[0].feature_id, 3u);  // deepest first
  // Furthest from 3 is 7; then 1 or 5 (equal areas, lower index); then the other one.
  EXPECT_EQ(m.points[1].feature_id, 7u);
  EXPECT_EQ(m.points[2].feature_id, 1u);
  EXPECT_EQ(m.points[3].feature_id, 5u);
}

TEST(ReduceTo4, SmallInputsPassThrough) {
  ContactPoint pts[3];
  for (int k = 0; k < 3; ++k) pts[k].feature_id = static_cast<std::uint32_t>(10 + k);
  Manifold m;
  reduce_to_4(pts, 3, Vec3::UnitZ(), m);
  ASSERT_EQ(m.count, 3);
  for (int k = 0; k < 3; ++k) EXPECT_EQ(m.points[k].feature_id, 10u + k);
  reduce_to_4(pts, 0, Vec3::UnitZ(), m);
  EXPECT_EQ(m.count, 0);
}

TEST(ReduceTo4, CollinearPointsKeepTheEnds) {
  // Points on a line: no triangle has area; the two ends must be kept and no NaN.
  ContactPoint pts[6];
  for (int k = 0; k < 6; ++k) {
    pts[k].point_a = Vec3(k, 0, 0);
    pts[k].depth = k == 2 ? 1.0 : 0.0;
    pts[k].feature_id = static_cast<std::uint32_t>(k);
  }
  Manifold m;
  reduce_to_4(pts, 6, Vec3::UnitY(), m);
  ASSERT_EQ(m.count, 2);
  EXPECT_EQ(m.points[0].feature_id, 2u);
  EXPECT_EQ(m.points[1].feature_id, 5u);
}

}  // namespace
}  // namespace wmo
