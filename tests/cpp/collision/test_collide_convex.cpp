// Checks of the generic convex path (collide_convex_convex: GJK/EPA + face clipping,
// collide_convex.cpp) and of the hull-hull SAT (collide_hull_hull.cpp), in A's frame.
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

std::vector<Vec3> box_corners(const Vec3& h) {
  std::vector<Vec3> v;
  for (int i = 0; i < 8; ++i)
    v.emplace_back((i & 1) ? h.x() : -h.x(), (i & 2) ? h.y() : -h.y(), (i & 4) ? h.z() : -h.z());
  return v;
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

// ---------------------------------------------------------------------------------
// Hull-hull SAT

TEST(CollideHullHull, BoxCornerHullsEqualBoxBox) {
  std::mt19937_64 rng(7);
  std::uniform_real_distribution<Real> u01(0, 1);
  auto uni = [&](Real lo, Real hi) { return lo + (hi - lo) * u01(rng); };
  int tested = 0;
  for (int trial = 0; trial < 1000 && tested < 300; ++trial) {
    const Vec3 ha(uni(0.2, 2), uni(0.2, 2), uni(0.2, 2)), hb(uni(0.2, 2), uni(0.2, 2), uni(0.2, 2));
    const Box ba(ha), bb(hb);
    const ConvexHull ca(box_corners(ha)), cb(box_corners(hb));
    const Quat q = Quat(uni(-1, 1), uni(-1, 1), uni(-1, 1), uni(-1, 1)).normalized();
    const Vec3 dir = Vec3(uni(-1, 1), uni(-1, 1), uni(-1, 1)).normalized();
    const Pose pose(dir * uni(0.05, 1.0) * (ha.norm() + hb.norm()), q);
    Manifold mb, mh;
    const bool hit_b = collide_box_box(ba, bb, pose, 0, mb);
    const bool hit_h = collide_hull_hull(ca, cb, pose, 0, mh);
    ASSERT_EQ(hit_b, hit_h) << trial;
    if (!hit_b) continue;
    ++tested;
    check_conventions(mh, kTol);
    // Same axes, same exact separations, same bias rule: the same answer up to
    // round-off (1e-9 on O(1) shapes leaves a factor ~1e4 above it; a different axis
    // would differ by far more).
    EXPECT_LT((mh.normal - mb.normal).norm(), 1e-9) << trial;
    EXPECT_NEAR(mh.max_depth(), mb.max_depth(), 1e-9) << trial;
    EXPECT_EQ(mh.count, mb.count) << trial;
    for (int i = 0; i < mh.count; ++i) {
      EXPECT_NEAR(sdf_box(ha, 0, Pose(), mh.points[i].point_a), 0, 1e-9) << trial;
      EXPECT_NEAR(sdf_box(hb, 0, pose, mh.points[i].point_b), 0, 1e-9) << trial;
    }
  }
  EXPECT_GE(tested, 200);
}

TEST(CollideHullHull, FixedBoxConfigurations) {
  const ConvexHull c(box_corners(Vec3(1, 1, 1)));
  Manifold m;
  // Face-face, rotated 45 degrees: 4 points, depth 0.02.
  ASSERT_TRUE(collide_hull_hull(c, c, Pose(Vec3(0, 0, 1.98), axis_angle(kPi / 4, Vec3::UnitZ())), 0, m));
  check_conventions(m, kTol);
  EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, 0.02, kTol);
  // Edge-edge crossing: 1 point, analytic depth (see test_collide_box_box).
  const Vec3 n = Vec3(1, 0, 1).normalized();
  const Quat q = axis_angle(kPi / 4, Vec3::UnitY()) * axis_angle(kPi / 4, Vec3::UnitX());
  ASSERT_TRUE(collide_hull_hull(c, c, Pose((2 * std::sqrt(2.0) - 0.05) * n, q), 0, m));
  check_conventions(m, kTol);
  ASSERT_EQ(m.count, 1);
  EXPECT_TRUE(m.points[0].feature_id >> 31);
  EXPECT_NEAR(m.points[0].depth, 0.05, kTol);
  EXPECT_LT((m.normal - n).norm(), kTol);
  EXPECT_LT((m.points[0].point_a - Vec3(1, 0, 1)).norm(), kTol);
  // Speculative: 0.02 apart, margin 0.05 -> depth -0.02; margin 0.01 -> none.
  EXPECT_FALSE(collide_hull_hull(c, c, Pose(Vec3(0, 0, 2.02)), 0.01, m));
  ASSERT_TRUE(collide_hull_hull(c, c, Pose(Vec3(0, 0, 2.02)), 0.05, m));
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(m.points[i].depth, -0.02, kTol);
  // Coincident: defined normal, depth 2.
  ASSERT_TRUE(collide_hull_hull(c, c, Pose(), 0, m));
  check_conventions(m, kTol);
  EXPECT_NEAR(m.max_depth(), 2.0, kTol);
}

TEST(CollideHullHull, TinyRotationKeepsFeatureIds) {
  const ConvexHull a(box_corners(Vec3(1, 1, 1))), b(box_corners(Vec3(0.5, 0.5, 0.5)));
  const Pose flat(Vec3(0.2, 0.1, 1.49));
  Manifold m0;
  ASSERT_TRUE(collide_hull_hull(a, b, flat, 0, m0));
  ASSERT_EQ(m0.count, 4);
  auto ids = [](const Manifold& m) {
    std::vector<std::uint32_t> v;
    for (int i = 0; i < m.count; ++i) v.push_back(m.points[i].feature_id);
    std::sort(v.begin(), v.end());
    return v;
  };
  for (const Vec3 axis : {Vec3(0, 0, 1), Vec3(1, 0, 0), Vec3(1, 1, 1)}) {
    for (Real angle : {1e-7, -1e-7}) {
      Manifold m;
      ASSERT_TRUE(collide_hull_hull(a, b, Pose(flat.position, axis_angle(angle, axis)), 0, m));
      ASSERT_EQ(m.count, 4);
      EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
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

TEST(CollideHullHull, PrismWithManySidesRestsOnBox) {
  // A 48-sided prism (its caps exceed kMaxFaceVertices = 32 and are subsampled),
  // standing on a box hull, overlapping by 0.03: 4 points on the rim, each at depth 0.03.
  std::vector<Vec3> pts;
  const int sides = 48;
  for (int i = 0; i < sides; ++i) {
    const Real t = 2 * kPi * i / sides;
    pts.emplace_back(0.5 * std::cos(t), -0.4, 0.5 * std::sin(t));
    pts.emplace_back(0.5 * std::cos(t), 0.4, 0.5 * std::sin(t));
  }
  const ConvexHull prism(pts);
  const ConvexHull box(box_corners(Vec3(2, 1, 2)));
  const Pose pose(Vec3(0.2, 1 + 0.4 - 0.03, -0.1), axis_angle(0.4, Vec3::UnitY()));
  Manifold m;
  ASSERT_TRUE(collide_hull_hull(box, prism, pose, 0, m));
  check_conventions(m, kTol);
  EXPECT_LT((m.normal - Vec3::UnitY()).norm(), kTol);
  ASSERT_EQ(m.count, 4);
  for (int i = 0; i < 4; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.03, kTol);
    const Vec3 r = m.points[i].point_b - pose.position;
    EXPECT_NEAR(std::hypot(r.x(), r.z()), 0.5, kTol);
  }
  // Mirrored roles (prism as A): reference face is the prism's cap or the box's top,
  // either way normal -Y (from the prism into the box below... here the box is above).
  const Pose inv = pose.inverse();
  ASSERT_TRUE(collide_hull_hull(prism, box, inv, 0, m));
  check_conventions(m, kTol);
  EXPECT_LT((m.normal - inv.rotation * -Vec3::UnitY()).norm(), kTol);
  EXPECT_EQ(m.count, 4);
  EXPECT_NEAR(m.max_depth(), 0.03, kTol);
}

TEST(CollideHullHull, AgreesWithGenericPathOnRandomHulls) {
  // Random point-cloud hulls: SAT (exact) against GJK/EPA + clipping. EPA stops at a
  // relative tolerance of 1e-10; on polytopes it lands on the exact Minkowski face, so
  // the depths agree to 1e-8 * size. SAT may report a depth deeper by the face bias
  // (clip.h: 5% + 1e-5 size), and then its normal is another valid axis; otherwise
  // the normals agree within 1e-6 rad (see test_collide_box_box for the same bound).
  std::mt19937_64 rng(11);
  std::uniform_real_distribution<Real> u01(0, 1);
  auto uni = [&](Real lo, Real hi) { return lo + (hi - lo) * u01(rng); };
  auto cloud = [&] {
    std::vector<Vec3> p;
    const int n = 6 + static_cast<int>(u01(rng) * 14);
    const Vec3 s(uni(0.3, 1.5), uni(0.3, 1.5), uni(0.3, 1.5));
    for (int i = 0; i < n; ++i) p.emplace_back(uni(-1, 1) * s.x(), uni(-1, 1) * s.y(), uni(-1, 1) * s.z());
    return p;
  };
  int tested = 0, unbiased = 0, shallow = 0;
  for (int trial = 0; trial < 1000 && tested < 300; ++trial) {
    const ConvexHull a(cloud()), b(cloud());
    const Quat q = Quat(uni(-1, 1), uni(-1, 1), uni(-1, 1), uni(-1, 1)).normalized();
    const Vec3 dir = Vec3(uni(-1, 1), uni(-1, 1), uni(-1, 1)).normalized();
    const Pose pose(dir * uni(0.0, 1.5), q);
    const DistanceResult pen = penetration_convex_convex(a, b, pose);
    if (!(pen.distance < 0)) continue;
    ++tested;
    const Real size = std::max(a.local_aabb().half_extents().maxCoeff(),
                               b.local_aabb().half_extents().maxCoeff());
    Manifold ms, mg;
    ASSERT_TRUE(collide_hull_hull(a, b, pose, 0, ms)) << trial;
    ASSERT_TRUE(collide_convex_convex(a, b, pose, generic_settings(), mg)) << trial;
    check_conventions(ms, 1e-9);
    check_conventions(mg, 1e-9);
    const Real d = -pen.distance, d_sat = ms.max_depth();
    // Overlap of the two hulls along SAT's normal (exact, from the support maps): the
    // depth of the axis SAT chose.
    const Vec3& n = ms.normal;
    const Real ov = n.dot(a.support(n) - pose.transform_point(b.support(pose.inverse_transform_vector(-n))));
    EXPECT_NEAR(mg.max_depth(), d, 1e-8 * size) << trial;
    EXPECT_GE(ov, d - 1e-8 * size) << trial;                       // EPA's depth is the minimum
    EXPECT_LE(0.95 * ov, d + 1e-5 * size + 1e-8 * size) << trial;  // face bias bound
    EXPECT_LE(d_sat, ov + 1e-8 * size) << trial;  // no point deeper than the axis overlap
    if (ov <= d + 1e-8 * size) {
      ++unbiased;
      EXPECT_LT(std::acos(std::clamp(ms.normal.dot(mg.normal), Real(-1), Real(1))), 1e-6) << trial;
      if (d_sat < d - 1e-8 * size) ++shallow;
    }
  }
  // On the exact axis the deepest support point is expected over the reference face
  // (it is then in the manifold, clip::kDeepestPointTolerance): a shallower manifold
  // would under-report the overlap.
  EXPECT_EQ(shallow, 0);
  std::printf("tested %d, unbiased %d, shallower clipped manifolds %d\n", tested, unbiased, shallow);
  EXPECT_EQ(tested, 300);
  // Coverage guard, not a tolerance: deep random overlaps of many-faced hulls often
  // have several axes within the 5% face bias (measured: 182 of 300 unbiased with this
  // seed); the normal check must still cover at least half of the configurations.
  EXPECT_GE(unbiased, 150);
}

}  // namespace
}  // namespace wmo
