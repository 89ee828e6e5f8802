// Checks of the generic convex path (collide_convex_convex: GJK/EPA + face clipping,
// collide_convex.cpp), in A's frame. The hull-hull SAT is checked in
// test_collide_hull.cpp.
//
// Every manifold is checked against the conventions of types.h: unit normal,
// point_b = point_a - depth * normal, points on the surfaces where a signed distance
// function is at hand.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/convex_queries.h"

namespace wmo {
namespace {

// Closed-form SAT results on O(1) inputs: a few ulps per rotation and clip; 1e-12
// (~5000 ulps of a metre) is far above that, far below a real geometric error.
constexpr Real kTol = 1e-12;
// The generic path takes its normal from EPA, which stops at a relative tolerance of
// 1e-10 (EpaSettings); its normal then deviates by up to ~1e-7 rad from the exact face
// normal (measured: < 4e-8 rad on random box pairs, test_collide_box_box), so depths
// clipped over a 1 m face differ from exact by up to ~1e-7 m: 1e-6 leaves a factor 10.
constexpr Real kEpaTol = 1e-6;

Quat axis_angle(Real angle, const Vec3& axis) { return Quat(Eigen::AngleAxisd(angle, axis.normalized())); }

Real sdf_box(const Vec3& h, Real r, const Pose& pose, const Vec3& x) {
  const Vec3 q = pose.inverse_transform_point(x).cwiseAbs() - (h.array() - r).matrix();
  return q.cwiseMax(0).norm() + std::min(q.maxCoeff(), Real(0)) - r;
}

void check_conventions(const Manifold& m, Real tol) {
  ASSERT_GE(m.count, 1);
  ASSERT_LE(m.count, kMaxManifoldPoints);
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  for (int i = 0; i < m.count; ++i) {
    const ContactPoint& p = m.points[i];
    ASSERT_TRUE(p.point_a.allFinite() && p.point_b.allFinite() && std::isfinite(p.depth));
    EXPECT_LT((p.point_b - (p.point_a - p.depth * m.normal)).norm(), tol) << "point " << i;
  }
}

CollideSettings generic_settings(Real margin = 0) {
  CollideSettings s;
  s.use_special_routines = false;
  s.margin = margin;
  return s;
}

// ---------------------------------------------------------------------------------
// Generic path

TEST(CollideConvexGeneric, BoxOnBoxFaceGivesFourPoints) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Pose pose(Vec3(0.1, 0.2, 1.49), axis_angle(0.3, Vec3::UnitZ()));
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(a, b, pose, generic_settings(), m));
  check_conventions(m, kTol);
  EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kEpaTol);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kEpaTol);
    EXPECT_NEAR(sdf_box(a.half_extents(), 0, Pose(), m.points[i].point_a), 0, kEpaTol);
    EXPECT_NEAR(sdf_box(b.half_extents(), 0, pose, m.points[i].point_b), 0, kEpaTol);
  }
}

TEST(CollideConvexGeneric, Rotated45ReducesToFour) {
  const Box a(Vec3(1, 1, 1));
  const Pose pose(Vec3(0, 0, 1.98), axis_angle(kPi / 4, Vec3::UnitZ()));
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(a, a, pose, generic_settings(), m));
  check_conventions(m, kTol);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, 0.02, kEpaTol);
}

TEST(CollideConvexGeneric, EdgeEdgeGivesTheEpaPointAsDeepest) {
  const Box a(Vec3(1, 1, 1));
  const Vec3 n = Vec3(1, 0, 1).normalized();
  const Real d = 0.05;
  const Quat q = axis_angle(kPi / 4, Vec3::UnitY()) * axis_angle(kPi / 4, Vec3::UnitX());
  const Pose pose((2 * std::sqrt(2.0) - d) * n, q);
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(a, a, pose, generic_settings(), m));
  check_conventions(m, kTol);
  EXPECT_LT((m.normal - n).norm(), kEpaTol);
  EXPECT_NEAR(m.max_depth(), d, kEpaTol);
  // The deepest point is the crossing of the edges.
  int deepest = 0;
  for (int i = 1; i < m.count; ++i)
    if (m.points[i].depth > m.points[deepest].depth) deepest = i;
  EXPECT_LT((m.points[deepest].point_a - Vec3(1, 0, 1)).norm(), 1e-4);
}

TEST(CollideConvexGeneric, CapsuleLyingOnBoxGivesTwoPoints) {
  const Box a(Vec3(2, 1, 2));
  const Capsule c(0.25, 0.5);
  // Capsule axis (Y) turned onto X, lying on the top face, overlapping by 0.01.
  const Pose pose(Vec3(0.3, 1 + 0.25 - 0.01, -0.2), axis_angle(kPi / 2, Vec3::UnitZ()));
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(a, c, pose, generic_settings(), m));
  check_conventions(m, kTol);
  EXPECT_LT((m.normal - Vec3::UnitY()).norm(), kEpaTol);
  ASSERT_EQ(m.count, 2);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kEpaTol);
    EXPECT_NEAR(std::abs(m.points[i].point_a.x() - 0.3), 0.5, kEpaTol);
  }
}

TEST(CollideConvexGeneric, SphereOnBoxGivesOnePoint) {
  const Box a(Vec3(1, 1, 1));
  const Sphere s(0.5);
  const Pose pose(Vec3(0.2, 0.3, 1.4));
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(a, s, pose, generic_settings(), m));
  check_conventions(m, kTol);
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.1, kEpaTol);
  EXPECT_LT((m.points[0].point_a - Vec3(0.2, 0.3, 1)).norm(), kEpaTol);
}

TEST(CollideConvexGeneric, SphereContactIsTheEpaPointWithOneIdOnEveryFace) {
  // A sphere meets anything at one point: the generic manifold is exactly the GJK /
  // EPA answer (no clipping), on either side of the pair, with the same feature id
  // whichever face, edge or corner of the other shape it touches.
  const Box box(Vec3(1, 1, 1));
  const Sphere ball(0.5);
  const Vec3 centres[] = {Vec3(1.4, 0.2, 0.1), Vec3(0.1, 1.4, -0.2), Vec3(1.25, 1.25, 0.3),
                          Vec3(1.2, -1.2, 1.2), Vec3(0.3, 0.2, 0.1)};  // faces, edge, corner, inside
  std::vector<std::uint32_t> ids;
  for (const Vec3& c : centres) {
    for (const bool ball_first : {false, true}) {
      const Pose box_to_ball(c, axis_angle(0.3, Vec3(1, 2, 3)));
      const Pose b_in_a = ball_first ? box_to_ball.inverse() : box_to_ball;
      const ConvexShape& a = ball_first ? static_cast<const ConvexShape&>(ball) : box;
      const ConvexShape& b = ball_first ? static_cast<const ConvexShape&>(box) : ball;
      Manifold m;
      ASSERT_TRUE(collide_convex_convex(a, b, b_in_a, generic_settings(), m));
      check_conventions(m, kTol);
      ASSERT_EQ(m.count, 1);
      const DistanceResult r = penetration_convex_convex(a, b, b_in_a, GjkSettings{}, EpaSettings{}, 0);
      EXPECT_EQ(m.points[0].depth, -r.distance);
      EXPECT_EQ(m.normal, r.normal);
      EXPECT_EQ(m.points[0].point_a, r.point_a);
      ids.push_back(m.points[0].feature_id);
    }
  }
  for (const std::uint32_t id : ids) EXPECT_EQ(id, ids.front());
  // Within a speculative margin: the one point, at its negative depth.
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(box, ball, Pose(Vec3(0, 0, 1.55)), generic_settings(0.1), m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, -0.05, kTol);
  EXPECT_FALSE(collide_convex_convex(box, ball, Pose(Vec3(0, 0, 1.65)), generic_settings(0.1), m));
}

TEST(CollideConvexGeneric, CylinderStandingOnBoxGivesFourPoints) {
  const Box a(Vec3(2, 1, 2));
  const Cylinder c(0.5, 0.5);
  const Pose pose(Vec3(0.1, 1.5 - 0.02, 0));
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(a, c, pose, generic_settings(), m));
  check_conventions(m, kTol);
  EXPECT_LT((m.normal - Vec3::UnitY()).norm(), kEpaTol);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.02, kEpaTol);
    // On the rim of the cap.
    const Vec3 r = m.points[i].point_b - pose.position;
    EXPECT_NEAR(std::hypot(r.x(), r.z()), 0.5, kEpaTol);
  }
}

TEST(CollideConvexGeneric, SpeculativeMarginAndSeparation) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Pose pose(Vec3(0, 0, 1.52));
  Manifold m;
  EXPECT_FALSE(collide_convex_convex(a, b, pose, generic_settings(0.01), m));
  ASSERT_TRUE(collide_convex_convex(a, b, pose, generic_settings(0.05), m));
  check_conventions(m, kTol);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, -0.02, kEpaTol);
}

TEST(CollideConvexGeneric, CoincidentShapesGiveFiniteManifold) {
  const Box a(Vec3(1, 2, 3));
  Manifold m;
  ASSERT_TRUE(collide_convex_convex(a, a, Pose(), generic_settings(), m));
  check_conventions(m, kTol);
  EXPECT_NEAR(m.max_depth(), 2.0, kEpaTol);
  const Sphere s(1);
  ASSERT_TRUE(collide_convex_convex(s, s, Pose(), generic_settings(), m));
  check_conventions(m, kTol);
  EXPECT_NEAR(m.max_depth(), 2.0, kEpaTol);
}

TEST(CollideConvexGeneric, TinyRotationKeepsFeatureIds) {
  // A box resting on a larger one, tilted by +-1e-7 rad: EPA's normal moves by ~1e-7,
  // the supporting faces stay the same, so the clip vertex labels (and the ids) do too.
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Pose flat(Vec3(0.2, 0.1, 1.49));
  auto ids = [](const Manifold& m) {
    std::vector<std::uint32_t> v;
    for (int i = 0; i < m.count; ++i) v.push_back(m.points[i].feature_id);
    std::sort(v.begin(), v.end());
    return v;
  };
  Manifold m0;
  ASSERT_TRUE(collide_convex_convex(a, b, flat, generic_settings(), m0));
  ASSERT_EQ(m0.count, 4);
  for (const Vec3 axis : {Vec3(0, 0, 1), Vec3(1, 0, 0), Vec3(1, 1, 1)}) {
    for (Real angle : {1e-7, -1e-7}) {
      const Pose tilted(flat.position, axis_angle(angle, axis));
      Manifold m;
      ASSERT_TRUE(collide_convex_convex(a, b, tilted, generic_settings(), m));
      check_conventions(m, kTol);
      ASSERT_EQ(m.count, 4);
      EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kEpaTol);
      EXPECT_EQ(ids(m), ids(m0));
    }
  }
}

TEST(CollideConvexGeneric, FarFromOriginThroughCollide) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Vec3 far(-1e4, 1e4, 1e4);
  const Quat q = axis_angle(0.7, Vec3(1, 2, 3));
  const Pose pa(far, q), pb(far + q * Vec3(0.1, 0.2, 1.49), q);
  std::vector<Manifold> out;
  ASSERT_EQ(collide(a, pa, b, pb, out, generic_settings()), QueryStatus::kOk);
  ASSERT_EQ(out.size(), 1u);
  ASSERT_EQ(out[0].count, 4);
  EXPECT_LT((out[0].normal - q * Vec3::UnitZ()).norm(), kEpaTol);
  // kEpaTol covers EPA's normal error; the 1e4 m world offset adds only ~1e-11 m.
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(out[0].points[i].depth, 0.01, kEpaTol);
}

}  // namespace
}  // namespace wmo
