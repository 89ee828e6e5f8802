// Checks of collide_box_box (SAT + clipping, collide_box_box.cpp), called directly in
// A's frame, and through wmo::collide with world poses where stated.
//
// Every manifold is checked against the conventions of types.h: unit normal, point_a on
// A's surface, point_b on B's surface (box signed distance functions), and
// point_b = point_a - depth * normal.

#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <random>
#include <vector>

#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/convex_queries.h"

namespace wmo {
namespace {

// Closed-form geometry on O(1) inputs loses a few ulps per rotation and clip; 1e-12
// (~5000 ulps of a metre) is far above that and far below a real geometric error.
constexpr Real kTol = 1e-12;

Real sdf_box(const Box& b, const Pose& pose, const Vec3& x) {
  const Vec3 q = pose.inverse_transform_point(x).cwiseAbs() - b.core_half_extents();
  return q.cwiseMax(0).norm() + std::min(q.maxCoeff(), Real(0)) - b.radius();
}

Quat axis_angle(Real angle, const Vec3& axis) { return Quat(Eigen::AngleAxisd(angle, axis.normalized())); }

/// Conventions of types.h on every point (A's frame); `tol` scales with the boxes.
void check_manifold(const Box& a, const Box& b, const Pose& b_in_a, const Manifold& m, Real tol = kTol) {
  ASSERT_GE(m.count, 1);
  ASSERT_LE(m.count, kMaxManifoldPoints);
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  for (int i = 0; i < m.count; ++i) {
    const ContactPoint& p = m.points[i];
    ASSERT_TRUE(p.point_a.allFinite() && p.point_b.allFinite() && std::isfinite(p.depth));
    EXPECT_LT((p.point_b - (p.point_a - p.depth * m.normal)).norm(), tol) << "point " << i;
    EXPECT_NEAR(sdf_box(a, Pose(), p.point_a), 0, tol) << "point_a " << i << " not on A";
    EXPECT_NEAR(sdf_box(b, b_in_a, p.point_b), 0, tol) << "point_b " << i << " not on B";
  }
}

std::vector<std::uint32_t> sorted_ids(const Manifold& m) {
  std::vector<std::uint32_t> ids;
  for (int i = 0; i < m.count; ++i) ids.push_back(m.points[i].feature_id);
  std::sort(ids.begin(), ids.end());
  return ids;
}

bool is_edge_contact(const Manifold& m) { return m.count == 1 && (m.points[0].feature_id >> 31); }

TEST(CollideBoxBox, FaceFaceRestingGivesFourPointsWithDepth) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Pose pose(Vec3(0.1, -0.2, 1.5 - 0.01));
  Manifold m;
  ASSERT_TRUE(collide_box_box(a, b, pose, 0, m));
  check_manifold(a, b, pose, m);
  EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kTol);
    EXPECT_NEAR(m.points[i].point_a.z(), 1.0, kTol);
    EXPECT_NEAR(std::abs(m.points[i].point_a.x() - 0.1), 0.5, kTol);
    EXPECT_NEAR(std::abs(m.points[i].point_a.y() + 0.2), 0.5, kTol);
  }
  // B below A: the normal flips, still 4 points.
  const Pose below(Vec3(0, 0, -1.49));
  ASSERT_TRUE(collide_box_box(a, b, below, 0, m));
  check_manifold(a, b, below, m);
  EXPECT_LT((m.normal + Vec3::UnitZ()).norm(), kTol);
  EXPECT_EQ(m.count, 4);
}

TEST(CollideBoxBox, Rotated45AboutNormalReducesEightToFour) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(1, 1, 1));
  const Pose pose(Vec3(0, 0, 2 - 0.02), axis_angle(kPi / 4, Vec3::UnitZ()));
  Manifold m;
  ASSERT_TRUE(collide_box_box(a, b, pose, 0, m));
  check_manifold(a, b, pose, m);
  EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
  ASSERT_EQ(m.count, 4);  // the octagon of the two squares, reduced
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, 0.02, kTol);
  // The 4 kept points span the octagon (inradius 1, circumradius R = 1 / cos(pi/8)):
  // the largest inscribed quadrilateral is the square on alternate vertices, area
  // 2 R^2 = 2.3431; the reduction must find it (1e-9: round-off of the clip points).
  auto area = [&](int i, int j, int k) {
    return 0.5 * (m.points[j].point_a - m.points[i].point_a)
                     .cross(m.points[k].point_a - m.points[i].point_a)
                     .norm();
  };
  const Real c8 = std::cos(kPi / 8);
  EXPECT_NEAR(area(0, 1, 2) + area(0, 2, 3), 2 / (c8 * c8), 1e-9);
}

TEST(CollideBoxBox, EdgeEdgeCrossingGivesOnePointWithAnalyticDepth) {
  // A's edge (1, y, 1) along Y; B turned so its lowest edge runs along (1, 0, -1)/sqrt2,
  // facing A's edge along n = (1, 0, 1)/sqrt2; both edges are sqrt2 from their centres
  // along n, so the centres sqrt2 * 2 - d apart along n overlap by exactly d.
  const Box a(Vec3(1, 1, 1)), b(Vec3(1, 1, 1));
  const Vec3 n = Vec3(1, 0, 1).normalized();
  const Real d = 0.05;
  const Quat q = axis_angle(kPi / 4, Vec3::UnitY()) * axis_angle(kPi / 4, Vec3::UnitX());
  const Pose pose((2 * std::sqrt(2.0) - d) * n, q);
  Manifold m;
  ASSERT_TRUE(collide_box_box(a, b, pose, 0, m));
  check_manifold(a, b, pose, m);
  ASSERT_EQ(m.count, 1);
  EXPECT_TRUE(is_edge_contact(m));
  EXPECT_LT((m.normal - n).norm(), kTol);
  EXPECT_NEAR(m.points[0].depth, d, kTol);
  EXPECT_LT((m.points[0].point_a - Vec3(1, 0, 1)).norm(), kTol);
}

TEST(CollideBoxBox, ExactlyTouchingFacesHaveZeroDepth) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Pose pose(Vec3(0, 0, 1.5));
  Manifold m;
  ASSERT_TRUE(collide_box_box(a, b, pose, 0, m));
  check_manifold(a, b, pose, m);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) EXPECT_EQ(m.points[i].depth, 0.0);
  // A hair apart and no margin: no contact.
  EXPECT_FALSE(collide_box_box(a, b, Pose(Vec3(0, 0, 1.5 + 1e-9)), 0, m));
}

TEST(CollideBoxBox, SpeculativeMarginGivesNegativeDepths) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Pose pose(Vec3(0, 0, 1.5 + 0.02));
  Manifold m;
  EXPECT_FALSE(collide_box_box(a, b, pose, 0.01, m));
  ASSERT_TRUE(collide_box_box(a, b, pose, 0.05, m));
  check_manifold(a, b, pose, m);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, -0.02, kTol);
}

TEST(CollideBoxBox, CoincidentIdenticalBoxesHaveDefinedNormal) {
  const Box a(Vec3(1, 2, 3));
  Manifold m;
  ASSERT_TRUE(collide_box_box(a, a, Pose(), 0, m));
  check_manifold(a, a, Pose(), m);
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  // Least overlap along X (2 * 1 m).
  EXPECT_NEAR(std::abs(m.normal.x()), 1.0, kTol);
  EXPECT_NEAR(m.max_depth(), 2.0, kTol);
}

TEST(CollideBoxBox, TinyRotationKeepsFaceContactAndFeatureIds) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Pose flat(Vec3(0.2, 0.1, 1.49));
  Manifold m0;
  ASSERT_TRUE(collide_box_box(a, b, flat, 0, m0));
  ASSERT_EQ(m0.count, 4);
  for (const Vec3 axis : {Vec3(0, 0, 1), Vec3(1, 0, 0), Vec3(1, 1, 1)}) {
    for (Real angle : {1e-7, -1e-7}) {
      const Pose tilted(flat.position, axis_angle(angle, axis));
      Manifold m;
      ASSERT_TRUE(collide_box_box(a, b, tilted, 0, m));
      check_manifold(a, b, tilted, m);
      ASSERT_EQ(m.count, 4);
      EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
      EXPECT_EQ(sorted_ids(m), sorted_ids(m0));
      // The depths move by at most the tilt times the face size.
      for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, 0.01, 2e-7);
    }
  }
  // Roles swapped (small A below, large B on top): tilting B by theta makes B's face
  // axis beat A's by ~theta / 2 (5e-8 m); the face bias keeps A's face as the
  // reference, so the ids stay those of the untilted pair.
  const Pose flat2(Vec3(0.2, 0.1, 1.49));
  ASSERT_TRUE(collide_box_box(b, a, flat2, 0, m0));
  ASSERT_EQ(m0.count, 4);
  EXPECT_FALSE(m0.points[0].feature_id & (1u << 30));  // reference face on A
  for (const Vec3 axis : {Vec3(1, 0, 0), Vec3(0, 1, 0), Vec3(1, 1, 1)}) {
    for (Real angle : {1e-7, -1e-7}) {
      const Pose tilted(flat2.position, axis_angle(angle, axis));
      Manifold m;
      ASSERT_TRUE(collide_box_box(b, a, tilted, 0, m));
      check_manifold(b, a, tilted, m);
      ASSERT_EQ(m.count, 4);
      EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
      EXPECT_EQ(sorted_ids(m), sorted_ids(m0));
    }
  }
  // Equal boxes flush on all sides, tilted by 1e-7 about the normal: the incident
  // corners stick out by ~1e-7 m and the clip yields an octagon; it must remain a face
  // contact of 4 points (no flip to an edge axis).
  const Box c(Vec3(1, 1, 1));
  for (Real angle : {0.0, 1e-7, -1e-7}) {
    const Pose p(Vec3(0, 0, 1.99), axis_angle(angle, Vec3::UnitZ()));
    Manifold m;
    ASSERT_TRUE(collide_box_box(c, c, p, 0, m));
    check_manifold(c, c, p, m);
    EXPECT_EQ(m.count, 4);
    EXPECT_FALSE(m.points[0].feature_id >> 31);
    EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
  }
}

TEST(CollideBoxBox, FarFromOriginThroughCollide) {
  const auto a = std::make_shared<Box>(Vec3(1, 1, 1));
  const auto b = std::make_shared<Box>(Vec3(0.5, 0.5, 0.5));
  const Vec3 far(1e4, -1e4, 1e4);
  const Quat q = axis_angle(0.7, Vec3(1, 2, 3));
  const Pose pa(far, q);
  const Pose pb(far + q * Vec3(0.1, 0.2, 1.49), q);
  std::vector<Manifold> out;
  ASSERT_EQ(collide(*a, pa, *b, pb, out), QueryStatus::kOk);
  ASSERT_EQ(out.size(), 1u);
  const Manifold& m = out[0];
  ASSERT_EQ(m.count, 4);
  // World coordinates at 1e4 m carry ~1e4 * 2.2e-16 * (a few operations) ~ 1e-11 m of
  // round-off; 1e-9 leaves a factor of 100.
  EXPECT_LT((m.normal - q * Vec3::UnitZ()).norm(), 1e-9);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, 1e-9);
    EXPECT_NEAR(sdf_box(*a, pa, m.points[i].point_a), 0, 1e-9);
    EXPECT_NEAR(sdf_box(*b, pb, m.points[i].point_b), 0, 1e-9);
  }
}

TEST(CollideBoxBox, TinyAndHugeBoxesScale) {
  for (Real s : {1e-3, 1e3}) {
    const Box a(Vec3(1, 1, 1) * s), b(Vec3(0.5, 0.5, 0.5) * s);
    const Pose pose(Vec3(0.1, 0.1, 1.49) * s, axis_angle(0.3, Vec3::UnitZ()));
    Manifold m;
    ASSERT_TRUE(collide_box_box(a, b, pose, 0, m));
    check_manifold(a, b, pose, m, kTol * s);
    ASSERT_EQ(m.count, 4);
    for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, 0.01 * s, kTol * s);
    // Edge-edge at scale.
    const Box c(Vec3(1, 1, 1) * s);
    const Vec3 n = Vec3(1, 0, 1).normalized();
    const Quat q = axis_angle(kPi / 4, Vec3::UnitY()) * axis_angle(kPi / 4, Vec3::UnitX());
    const Pose e((2 * std::sqrt(2.0) - 0.05) * s * n, q);
    ASSERT_TRUE(collide_box_box(c, c, e, 0, m));
    check_manifold(c, c, e, m, kTol * s);
    ASSERT_EQ(m.count, 1);
    EXPECT_NEAR(m.points[0].depth, 0.05 * s, kTol * s);
  }
}

TEST(CollideBoxBox, RoundedBoxesAddRadii) {
  const Box a(Vec3(1, 1, 1), 0.1), b(Vec3(0.5, 0.5, 0.5), 0.05);
  const Pose pose(Vec3(0, 0, 1.49));
  Manifold m;
  ASSERT_TRUE(collide_box_box(a, b, pose, 0, m));
  check_manifold(a, b, pose, m);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kTol);
    EXPECT_NEAR(m.points[i].point_a.z(), 1.0, kTol);
    // The flat part of B's bottom face spans the core: +-0.45.
    EXPECT_NEAR(std::abs(m.points[i].point_a.x()), 0.45, kTol);
  }
  // Edge-edge of rounded boxes: depth = core overlap + radii.
  const Box c(Vec3(1, 1, 1), 0.2);
  const Vec3 n = Vec3(1, 0, 1).normalized();
  const Quat q = axis_angle(kPi / 4, Vec3::UnitY()) * axis_angle(kPi / 4, Vec3::UnitX());
  // Core edges are 0.8 sqrt2 from the centres; centres 1.6 sqrt2 + 0.4 - d apart.
  const Real d = 0.05;
  const Pose e((1.6 * std::sqrt(2.0) + 0.4 - d) * n, q);
  ASSERT_TRUE(collide_box_box(c, c, e, 0, m));
  check_manifold(c, c, e, m);
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, d, kTol);
  EXPECT_LT((m.normal - n).norm(), kTol);
}

// SAT against the generic GJK/EPA + clipping path on random overlapping pairs. The
// Minkowski difference of two boxes is a polytope whose face normals are among SAT's
// 15 axes, so the least-overlap axis is the exact minimum translation direction and
// EPA, which converges on polytopes to its 1e-10 relative tolerance, finds the same
// direction and depth. Tolerances:
//   * depth: EPA within 1e-9 * size (EPA's tolerance plus clipping round-off); the
//     overlap ov along SAT's axis never below the exact depth d and at most deeper by
//     the face bias (clip.h): ov - d <= 0.05 ov + 1e-5 size; no manifold point deeper
//     than ov;
//   * normal: where SAT picked the least-overlap axis (ov equal to EPA's depth within
//     1e-9 * size), the normals agree within 1e-6 rad (EPA's termination leaves its
//     normal off by ~sqrt(1e-10) relative at worst, 1e-5; on polytopes it lands on the
//     exact face, so 1e-6 is a real check; see the measured maximum printed);
//   * where the bias picked another axis, moving B by depth * normal must separate the
//     boxes (the biased normal is still a valid separating direction).
TEST(CollideBoxBox, AgreesWithGenericPathOnRandomConfigurations) {
  std::mt19937_64 rng(20261124);
  std::uniform_real_distribution<Real> u01(0, 1);
  auto uni = [&](Real lo, Real hi) { return lo + (hi - lo) * u01(rng); };
  auto rand_quat = [&] {
    Quat q(uni(-1, 1), uni(-1, 1), uni(-1, 1), uni(-1, 1));
    if (q.norm() < 1e-3) q = Quat::Identity();
    return q.normalized();
  };
  CollideSettings generic;
  generic.use_special_routines = false;
  int tested = 0, unbiased = 0;
  Real max_angle = 0, max_depth_err = 0;
  for (int trial = 0; trial < 4000 && tested < 2000; ++trial) {
    const Box a(Vec3(uni(0.2, 2), uni(0.2, 2), uni(0.2, 2)));
    const Box b(Vec3(uni(0.2, 2), uni(0.2, 2), uni(0.2, 2)));
    const Quat qb = rand_quat();
    const Vec3 dir = Vec3(uni(-1, 1), uni(-1, 1), uni(-1, 1)).normalized();
    const Real reach = a.half_extents().norm() + b.half_extents().norm();
    const Pose pose(dir * uni(0.05, 1.0) * reach, qb);
    const DistanceResult pen = penetration_convex_convex(a, b, pose);
    if (!(pen.distance < 0)) continue;
    ++tested;
    const Real size = std::max(a.half_extents().maxCoeff(), b.half_extents().maxCoeff());
    Manifold ms, mg;
    ASSERT_TRUE(collide_box_box(a, b, pose, 0, ms)) << trial;
    ASSERT_TRUE(collide_convex_convex(a, b, pose, generic, mg)) << trial;
    check_manifold(a, b, pose, ms, 1e-9 * size);
    const Real d_epa = -pen.distance;
    const Real d_sat = ms.max_depth();
    const Real d_gen = mg.max_depth();
    // Overlap of the boxes along SAT's normal, from the support maps: the depth of the
    // axis SAT chose.
    const Vec3& n = ms.normal;
    const Real ov = n.dot(a.support(n) - pose.transform_point(b.support(pose.inverse_transform_vector(-n))));
    EXPECT_NEAR(d_gen, d_epa, 1e-9 * size) << trial;
    EXPECT_GE(ov, d_epa - 1e-9 * size) << trial;
    EXPECT_LE(0.95 * ov, d_epa + 1e-5 * size + 1e-9 * size) << trial;
    EXPECT_LE(d_sat, ov + 1e-9 * size) << trial;
    if (ov <= d_epa + 1e-9 * size) {
      ++unbiased;
      const Real angle = std::acos(std::clamp(ms.normal.dot(mg.normal), Real(-1), Real(1)));
      max_angle = std::max(max_angle, angle);
      max_depth_err = std::max(max_depth_err, std::abs(d_sat - d_epa) / size);
      EXPECT_LT(angle, 1e-6) << trial;
      // The box's deepest corner lies on the incident face; on the exact axis it is
      // expected over the reference face too, so the clipped manifold must reach the
      // exact depth (a failure here means the manifold under-reports the overlap).
      EXPECT_NEAR(d_sat, d_epa, 1e-9 * size) << trial;
    } else {
      const Pose moved(pose.position + (ov + 1e-9 * size) * ms.normal, pose.rotation);
      const DistanceResult after = penetration_convex_convex(a, b, moved);
      EXPECT_GE(after.distance, -1e-9 * size) << trial;
    }
  }
  EXPECT_EQ(tested, 2000);
  // Most random pairs are not near-ties; the normal check must cover most of them.
  // Coverage guard, not a tolerance: the normal check must cover most configurations
  // (measured: 1587 of 2000 with this seed; the rest are within the 5% face bias).
  EXPECT_GT(unbiased, 1500);
  std::printf("tested %d, unbiased %d, max normal angle %.3g rad, max rel depth err %.3g\n",
              tested, unbiased, max_angle, max_depth_err);
}

}  // namespace
}  // namespace wmo
