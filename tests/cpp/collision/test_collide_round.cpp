// Analytic checks of the round-shape contact routines (collide_round.cpp), called
// directly in A's frame (no dispatcher).
//
// Every manifold is checked against the conventions of types.h: unit normal, point_a on
// A's surface, point_b on B's surface, point_b = point_a - depth * normal, and depth
// equal to an independent computation (signed distance functions, or a golden-section
// minimisation of a convex distance function) where one is cheap.

#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <random>

#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

// Exact closed forms on O(1) inputs lose a few ulps per rotation; 1e-12 (~5000 ulps of
// a metre) is far above that and far below any geometric error worth catching.
constexpr Real kTol = 1e-12;
// Golden-section search on a convex function of one variable stops at 1e-13 in the
// parameter (200 iterations); the distance it returns is then exact to ~1e-12 for
// O(1) shapes, so comparisons against it use 1e-9 (a thousand times looser).
constexpr Real kRefTol = 1e-9;

using Sdf = std::function<Real(const Vec3&)>;

// Signed distance functions in each shape's local frame (Quilez' closed forms).
Real sdf_sphere(const Vec3& p, Real r) { return p.norm() - r; }
Real sdf_capsule(const Vec3& p, Real r, Real h) {
  return (p - Vec3(0, std::clamp(p.y(), -h, h), 0)).norm() - r;
}
Real sdf_box(const Vec3& p, const Vec3& core, Real rounding) {
  const Vec3 q = p.cwiseAbs() - core;
  return q.cwiseMax(0).norm() + std::min(q.maxCoeff(), Real(0)) - rounding;
}

Sdf sdf_of(const Sphere& s, const Pose& pose) {
  return [&s, pose](const Vec3& x) {
    return sdf_sphere(pose.inverse_transform_point(x), s.radius());
  };
}
Sdf sdf_of(const Capsule& c, const Pose& pose) {
  return [&c, pose](const Vec3& x) {
    return sdf_capsule(pose.inverse_transform_point(x), c.radius(), c.half_height());
  };
}
Sdf sdf_of(const Box& b, const Pose& pose) {
  return [&b, pose](const Vec3& x) {
    return sdf_box(pose.inverse_transform_point(x), b.core_half_extents(), b.radius());
  };
}

/// Checks the conventions of types.h on every point of m; surface tolerance `surf`.
void check_manifold(const Manifold& m, const Sdf& sdf_a, const Sdf& sdf_b, Real surf = kTol) {
  ASSERT_GE(m.count, 1);
  ASSERT_LE(m.count, kMaxManifoldPoints);
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  for (int i = 0; i < m.count; ++i) {
    const ContactPoint& c = m.points[i];
    ASSERT_TRUE(c.point_a.allFinite() && c.point_b.allFinite() && std::isfinite(c.depth));
    EXPECT_NEAR(sdf_a(c.point_a), 0.0, surf) << "point " << i << " not on A";
    EXPECT_NEAR(sdf_b(c.point_b), 0.0, surf) << "point " << i << " not on B";
    EXPECT_LT((c.point_b - (c.point_a - c.depth * m.normal)).norm(), kTol) << "point " << i;
  }
}

Quat random_rotation(std::mt19937& rng) {
  std::normal_distribution<Real> g(0, 1);
  Quat q(g(rng), g(rng), g(rng), g(rng));
  q.normalize();
  return q;
}

Vec3 random_vec(std::mt19937& rng, Real scale) {
  std::uniform_real_distribution<Real> u(-scale, scale);
  return Vec3(u(rng), u(rng), u(rng));
}

/// Minimum of a convex function on [lo, hi] by golden-section search (reference only).
Real golden_min(const std::function<Real(Real)>& f, Real lo, Real hi) {
  const Real g = (std::sqrt(5.0) - 1) / 2;
  Real a = lo, b = hi;
  for (int i = 0; i < 200 && b - a > 1e-13; ++i) {
    const Real c = b - g * (b - a), d = a + g * (b - a);
    if (f(c) < f(d)) b = d; else a = c;
  }
  return std::min({f(lo), f(hi), f(0.5 * (a + b))});
}

Quat axis_angle(Real angle, const Vec3& axis) {
  return Quat(Eigen::AngleAxisd(angle, axis.normalized()));
}

// ---------------------------------------------------------------- sphere-sphere

TEST(CollideSphereSphere, OverlapAnalytic) {
  Sphere a(1.0), b(0.5);
  const Pose pb(Vec3(1.2, 0, 0), axis_angle(0.7, Vec3(1, 2, 3)));
  Manifold m;
  ASSERT_TRUE(collide_sphere_sphere(a, b, pb, 0, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.3, kTol);
  EXPECT_LT((m.normal - Vec3::UnitX()).norm(), kTol);
  EXPECT_LT((m.points[0].point_a - Vec3(1, 0, 0)).norm(), kTol);
  EXPECT_LT((m.points[0].point_b - Vec3(0.7, 0, 0)).norm(), kTol);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
}

TEST(CollideSphereSphere, TouchingSeparatedAndMargin) {
  Sphere a(1.0), b(0.5);
  // Along an axis, with radii that are powers of two, touching is exact in binary.
  Manifold m;
  ASSERT_TRUE(collide_sphere_sphere(a, b, Pose(Vec3(0, 0, 1.5)), 0, m));
  EXPECT_EQ(m.points[0].depth, 0.0);
  const Vec3 dir = Vec3(1, -2, 0.5).normalized();
  // 1e-6 m apart: reported only with a margin that covers the gap.
  const Pose apart((1.5 + 1e-6) * dir);
  Manifold m2;
  EXPECT_FALSE(collide_sphere_sphere(a, b, apart, 0, m2));
  EXPECT_EQ(m2.count, 0);  // untouched
  ASSERT_TRUE(collide_sphere_sphere(a, b, apart, 1e-3, m2));
  EXPECT_NEAR(m2.points[0].depth, -1e-6, kTol);
  EXPECT_LT((m2.normal - dir).norm(), kTol);
  check_manifold(m2, sdf_of(a, Pose()), sdf_of(b, apart));
  // Just outside the margin.
  EXPECT_FALSE(collide_sphere_sphere(a, b, Pose((1.5 + 2e-3) * dir), 1e-3, m2));
}

TEST(CollideSphereSphere, CoincidentCentresGiveDefinedNormal) {
  Sphere a(1.0), b(0.25);
  Manifold m;
  ASSERT_TRUE(collide_sphere_sphere(a, b, Pose(Vec3::Zero(), axis_angle(1, Vec3(0, 0, 1))), 0, m));
  EXPECT_TRUE(m.normal.allFinite());
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  EXPECT_NEAR(m.points[0].depth, 1.25, kTol);
}

// ---------------------------------------------------------------- sphere-box

TEST(CollideSphereBox, FaceOverlapAnalytic) {
  Sphere a(0.5);
  Box b(Vec3(1, 1, 1));
  const Pose pb(Vec3(0, 0, -1.3));
  Manifold m;
  ASSERT_TRUE(collide_sphere_box(a, b, pb, 0, m));
  EXPECT_NEAR(m.points[0].depth, 0.2, kTol);
  EXPECT_LT((m.normal - Vec3(0, 0, -1)).norm(), kTol);
  EXPECT_LT((m.points[0].point_a - Vec3(0, 0, -0.5)).norm(), kTol);
  EXPECT_LT((m.points[0].point_b - Vec3(0, 0, -0.3)).norm(), kTol);
  EXPECT_EQ(m.points[0].feature_id, 9u);  // sphere 0, B's +z face
}

TEST(CollideSphereBox, CentreInsideUsesClosestFace) {
  Sphere a(0.3);
  Box b(Vec3(1, 2, 3));
  // A's centre sits at (0.8, 0.5, -1) in B's frame: 0.2 from the +x face, the closest.
  const Quat q = axis_angle(0.4, Vec3(1, 1, 0));
  const Pose pb(-(q * Vec3(0.8, 0.5, -1)), q);
  Manifold m;
  ASSERT_TRUE(collide_sphere_box(a, b, pb, 0, m));
  EXPECT_NEAR(m.points[0].depth, 0.5, kTol);  // 0.2 to the face + radius 0.3
  // B must move along its -x to push its +x face past the sphere.
  EXPECT_LT((m.normal - q * Vec3(-1, 0, 0)).norm(), kTol);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
}

TEST(CollideSphereBox, CentreAtBoxCentreIsDefined) {
  Sphere a(0.5);
  Box b(Vec3(1, 1, 1));
  Manifold m;
  ASSERT_TRUE(collide_sphere_box(a, b, Pose(), 0, m));
  EXPECT_TRUE(m.normal.allFinite());
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  EXPECT_NEAR(m.points[0].depth, 1.5, kTol);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, Pose()));
}

TEST(CollideSphereBox, EdgeAndCornerRegions) {
  Sphere a(0.5);
  Box b(Vec3(1, 1, 1));
  // Sphere centre beyond the (+x, +y) edge at distance 0.45 from it.
  const Vec3 c_edge = Vec3(1, 1, 0.3) + 0.45 * Vec3(1, 1, 0).normalized();
  const Pose pb_edge(-c_edge);
  Manifold m;
  ASSERT_TRUE(collide_sphere_box(a, b, pb_edge, 0, m));
  EXPECT_NEAR(m.points[0].depth, 0.05, kTol);
  EXPECT_LT((m.normal + Vec3(1, 1, 0).normalized()).norm(), kTol);
  EXPECT_EQ(m.points[0].feature_id, 1u + 3u);  // edge code: +x (1) and +y (3)
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb_edge));
  // Beyond the (+x, -y, +z) corner at distance 0.6: apart, reported with margin 0.2.
  const Vec3 c_corner = Vec3(1, -1, 1) + 0.6 * Vec3(1, -1, 1).normalized();
  const Pose pb_corner(-c_corner);
  EXPECT_FALSE(collide_sphere_box(a, b, pb_corner, 0, m));
  ASSERT_TRUE(collide_sphere_box(a, b, pb_corner, 0.2, m));
  EXPECT_NEAR(m.points[0].depth, -0.1, kTol);
  EXPECT_EQ(m.points[0].feature_id, 1u + 6u + 9u);
}

TEST(CollideSphereBox, RandomMatchesSignedDistance) {
  // Sphere vs any shape: depth = radius - sdf_B(centre) exactly, rounded boxes included.
  std::mt19937 rng(7);
  Box b(Vec3(0.8, 0.4, 1.2), 0.1);
  Sphere a(0.35);
  int hits = 0;
  for (int i = 0; i < 500; ++i) {
    const Pose pb(random_vec(rng, 1.6), random_rotation(rng));
    const Real expected = a.radius() - sdf_of(b, pb)(Vec3::Zero());
    Manifold m;
    const bool hit = collide_sphere_box(a, b, pb, 0.05, m);
    ASSERT_EQ(hit, expected >= -0.05) << i;
    if (!hit) continue;
    ++hits;
    EXPECT_NEAR(m.points[0].depth, expected, kTol) << i;
    check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
  }
  EXPECT_GT(hits, 100);  // the sample must exercise the routine
}

// ---------------------------------------------------------------- sphere-capsule

TEST(CollideSphereCapsule, SideEndAndAxis) {
  Sphere a(0.5);
  Capsule b(0.25, 1.0);
  // Side: capsule axis along A's Z (B rotated), axis 0.6 away along +x.
  const Pose side(Vec3(0.6, 0, 0.3), axis_angle(kPi / 2, Vec3::UnitX()));
  Manifold m;
  ASSERT_TRUE(collide_sphere_capsule(a, b, side, 0, m));
  EXPECT_NEAR(m.points[0].depth, 0.15, kTol);
  EXPECT_LT((m.normal - Vec3::UnitX()).norm(), kTol);
  EXPECT_EQ(m.points[0].feature_id, 2u);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, side));
  // End cap: B along Y above A, lower end at 0.7.
  const Pose end(Vec3(0, 1.7, 0));
  ASSERT_TRUE(collide_sphere_capsule(a, b, end, 0, m));
  EXPECT_NEAR(m.points[0].depth, 0.05, kTol);
  EXPECT_LT((m.normal - Vec3::UnitY()).norm(), kTol);
  EXPECT_EQ(m.points[0].feature_id, 0u);
  // Centre on the axis: defined normal perpendicular to the axis, depth = radii sum.
  const Quat tilt = axis_angle(0.3, Vec3::UnitZ());
  const Pose on_axis(0.2 * (tilt * Vec3::UnitY()), tilt);
  ASSERT_TRUE(collide_sphere_capsule(a, b, on_axis, 0, m));
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  EXPECT_NEAR(m.normal.dot(on_axis.rotation * Vec3::UnitY()), 0.0, kTol);
  EXPECT_NEAR(m.points[0].depth, 0.75, kTol);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, on_axis));
}

TEST(CollideSphereCapsule, RandomMatchesSignedDistance) {
  std::mt19937 rng(11);
  Capsule b(0.3, 0.7);
  Sphere a(0.4);
  int hits = 0;
  for (int i = 0; i < 500; ++i) {
    const Pose pb(random_vec(rng, 1.0), random_rotation(rng));
    const Real expected = a.radius() - sdf_of(b, pb)(Vec3::Zero());
    Manifold m;
    const bool hit = collide_sphere_capsule(a, b, pb, 0.1, m);
    ASSERT_EQ(hit, expected >= -0.1) << i;
    if (!hit) continue;
    ++hits;
    EXPECT_NEAR(m.points[0].depth, expected, kTol) << i;
    check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
  }
  EXPECT_GT(hits, 100);
}

// ---------------------------------------------------------------- capsule-capsule

TEST(CollideCapsuleCapsule, CrossingOnePoint) {
  Capsule a(0.3, 1.0), b(0.2, 0.5);
  // B along A's Z, crossing A's axis at y = 0.4, 0.45 away along +x.
  const Pose pb(Vec3(0.45, 0.4, 0), axis_angle(kPi / 2, Vec3::UnitX()));
  Manifold m;
  ASSERT_TRUE(collide_capsule_capsule(a, b, pb, 0, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.05, kTol);
  EXPECT_LT((m.normal - Vec3::UnitX()).norm(), kTol);
  EXPECT_LT((m.points[0].point_a - Vec3(0.3, 0.4, 0)).norm(), kTol);
  EXPECT_EQ(m.points[0].feature_id, (2u << 8) | 2u);  // both interiors
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
}

TEST(CollideCapsuleCapsule, ParallelGivesTwoPointsOnOverlap) {
  Capsule a(0.3, 1.0), b(0.2, 0.8);
  // B parallel to A (axis flipped, which must not matter), 0.45 away along +z,
  // shifted by 0.5 along the axis: overlap y in [-0.3, 1.0].
  const Pose pb(Vec3(0, 0.5, 0.45), axis_angle(kPi, Vec3::UnitX()));
  Manifold m;
  ASSERT_TRUE(collide_capsule_capsule(a, b, pb, 0, m));
  ASSERT_EQ(m.count, 2);
  EXPECT_LT((m.normal - Vec3::UnitZ()).norm(), kTol);
  EXPECT_NEAR(m.points[0].depth, 0.05, kTol);
  EXPECT_NEAR(m.points[1].depth, 0.05, kTol);
  EXPECT_LT((m.points[0].point_a - Vec3(0, -0.3, 0.3)).norm(), kTol);
  EXPECT_LT((m.points[1].point_a - Vec3(0, 1.0, 0.3)).norm(), kTol);
  // Lower end from B's end (B's end 1 is at y = -0.3 after the flip), upper from A's end 1.
  EXPECT_EQ(m.points[0].feature_id, (2u << 8) | 1u);
  EXPECT_EQ(m.points[1].feature_id, (1u << 8) | 2u);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
}

TEST(CollideCapsuleCapsule, ParallelCoaxialAndEndToEnd) {
  Capsule a(0.3, 1.0), b(0.3, 1.0);
  // Same axis, overlapping: cores coincide over a range; a defined perpendicular normal.
  const Pose coax(Vec3(0, 0.5, 0));
  Manifold m;
  ASSERT_TRUE(collide_capsule_capsule(a, b, coax, 0, m));
  EXPECT_TRUE(m.normal.allFinite());
  EXPECT_NEAR(m.normal.norm(), 1.0, kTol);
  EXPECT_NEAR(m.normal.y(), 0.0, kTol);
  EXPECT_NEAR(m.points[0].depth, 0.6, kTol);
  // End to end along the axis, 0.1 apart: one point between the caps, apart by 0.1.
  const Pose end(Vec3(0, 2.7, 0));
  EXPECT_FALSE(collide_capsule_capsule(a, b, end, 0, m));
  ASSERT_TRUE(collide_capsule_capsule(a, b, end, 0.2, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, -0.1, kTol);
  EXPECT_LT((m.normal - Vec3::UnitY()).norm(), kTol);
  EXPECT_EQ(m.points[0].feature_id, (1u << 8) | 0u);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, end));
}

TEST(CollideCapsuleCapsule, RandomMatchesReferenceDistance) {
  std::mt19937 rng(3);
  Capsule a(0.25, 0.6), b(0.15, 0.9);
  int hits = 0;
  for (int i = 0; i < 300; ++i) {
    const Pose pb(random_vec(rng, 1.2), random_rotation(rng));
    // Reference: distance between the cores by golden section over A's parameter, with
    // the exact point-segment distance inside (convex in the parameter).
    const Vec3 e0 = pb.transform_point(Vec3(0, -0.9, 0)), e1 = pb.transform_point(Vec3(0, 0.9, 0));
    auto point_seg = [&](Real y) {
      const Vec3 p(0, y, 0);
      const Real u = std::clamp((p - e0).dot(e1 - e0) / (e1 - e0).squaredNorm(), 0.0, 1.0);
      return (e0 + u * (e1 - e0) - p).norm();
    };
    const Real expected = 0.4 - golden_min(point_seg, -0.6, 0.6);
    Manifold m;
    const bool hit = collide_capsule_capsule(a, b, pb, 0.1, m);
    ASSERT_EQ(hit, expected >= -0.1) << i;
    if (!hit) continue;
    ++hits;
    EXPECT_NEAR(m.max_depth(), expected, kRefTol) << i;
    check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
  }
  EXPECT_GT(hits, 50);
}

// ---------------------------------------------------------------- capsule-box

TEST(CollideCapsuleBox, LyingOnFaceGivesTwoPoints) {
  Capsule a(0.2, 0.5);
  Box b(Vec3(1, 0.5, 1));
  // Capsule along A's Y, lying on B's +x face (B's +x face at x = -0.18 in A's frame:
  // B centred at (-1.18, 0, 0)), so depth 0.02 along the whole segment.
  const Pose pb(Vec3(-1.18, 0, 0));
  Manifold m;
  ASSERT_TRUE(collide_capsule_box(a, b, pb, 0, m));
  ASSERT_EQ(m.count, 2);
  EXPECT_LT((m.normal - Vec3(-1, 0, 0)).norm(), kTol);
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(m.points[i].depth, 0.02, kTol);
  // Segment ends y = -0.5 and 0.5 are inside the face's y range [-0.5, 0.5].
  EXPECT_NEAR(std::abs(m.points[0].point_a.y()), 0.5, kTol);
  EXPECT_NEAR(m.points[0].point_a.y(), -m.points[1].point_a.y(), kTol);
  EXPECT_NE(m.points[0].feature_id, m.points[1].feature_id);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
}

TEST(CollideCapsuleBox, LongCapsuleClippedToFace) {
  Capsule a(0.2, 2.0);
  Box b(Vec3(0.5, 0.5, 0.5), 0.1);  // rounded: the core face spans |x|, |z| <= 0.4
  // In B's frame: A's centre at (0.1, 0.69, 0), A's axis along B's x (Rz(-90) maps Y
  // to X). The capsule bottom (y = 0.49) is 0.01 into the +y face (y = 0.5) and its
  // segment spans x in [-1.9, 2.1], far beyond the face.
  const Pose a_in_b(Vec3(0.1, 0.69, 0), axis_angle(-kPi / 2, Vec3::UnitZ()));
  const Pose pb = a_in_b.inverse();
  Manifold m;
  ASSERT_TRUE(collide_capsule_box(a, b, pb, 0, m));
  ASSERT_EQ(m.count, 2);
  for (int i = 0; i < 2; ++i) {
    EXPECT_NEAR(m.points[i].depth, 0.01, kTol);
    const Vec3 pb_local = pb.inverse_transform_point(m.points[i].point_b);
    EXPECT_NEAR(std::abs(pb_local.x()), 0.4, kTol);  // clipped at the core side planes
    EXPECT_NEAR(pb_local.y(), 0.5, kTol);
  }
  EXPECT_NEAR(pb.inverse_transform_point(m.points[0].point_b).x(),
              -pb.inverse_transform_point(m.points[1].point_b).x(), kTol);
  EXPECT_NE(m.points[0].feature_id, m.points[1].feature_id);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
}

TEST(CollideCapsuleBox, StandingAndTiltedOnFace) {
  Capsule a(0.2, 0.5);
  Box b(Vec3(1, 1, 1));
  // Standing on B's +y face: only the lower end touches.
  const Pose stand(Vec3(0, -1.69, 0));
  Manifold m;
  ASSERT_TRUE(collide_capsule_box(a, b, stand, 0, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.01, kTol);
  EXPECT_LT((m.normal - Vec3(0, -1, 0)).norm(), kTol);
  EXPECT_EQ(m.points[0].feature_id, (0u << 8) | 3u);  // capsule end 0, box face +y
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, stand));
  // Lying on the +y face but tilted 0.1 rad: in B's frame the axis is
  // (-cos 0.1, sin 0.1, 0), the lower end's core is at y = 1.19 (0.01 deep) and the
  // raised end sin(0.1) higher, so it is reported only with a margin that covers it.
  const Quat tilt = axis_angle(kPi / 2 - 0.1, Vec3::UnitZ());
  const Pose a_in_b(Vec3(0, 1.19 + 0.5 * std::sin(0.1), 0), tilt);
  const Pose tilted = a_in_b.inverse();
  ASSERT_TRUE(collide_capsule_box(a, b, tilted, 0, m));
  EXPECT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, 0.01, kTol);
  ASSERT_TRUE(collide_capsule_box(a, b, tilted, 0.2, m));
  ASSERT_EQ(m.count, 2);
  EXPECT_NEAR(std::max(m.points[0].depth, m.points[1].depth), 0.01, kTol);
  EXPECT_NEAR(std::min(m.points[0].depth, m.points[1].depth), 0.01 - std::sin(0.1), kTol);
}

TEST(CollideCapsuleBox, EdgeCrossingSeparated) {
  Capsule a(0.1, 1.0);
  Box b(Vec3(0.5, 0.5, 0.5));
  // In B's frame, the capsule runs along z above B's (+x, +y) edge (along z), its axis
  // 0.15 from the edge in the (1, 1, 0) direction: 0.05 apart.
  const Vec3 centre = Vec3(0.5, 0.5, 0) + 0.15 * Vec3(1, 1, 0).normalized();
  const Pose a_in_b(centre, axis_angle(kPi / 2, Vec3::UnitX()));
  const Pose pb = a_in_b.inverse();
  Manifold m;
  EXPECT_FALSE(collide_capsule_box(a, b, pb, 0.04, m));
  ASSERT_TRUE(collide_capsule_box(a, b, pb, 0.06, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_NEAR(m.points[0].depth, -0.05, kTol);
  EXPECT_LT((pb.inverse_transform_vector(m.normal) + Vec3(1, 1, 0).normalized()).norm(), kTol);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
}

TEST(CollideCapsuleBox, DeepInsideUsesFace) {
  Capsule a(0.1, 0.3);
  Box b(Vec3(1, 1, 1));
  // Segment horizontal (along B's x), inside B at y = 0.9: leaves through +y.
  const Pose a_in_b(Vec3(0, 0.9, 0), axis_angle(kPi / 2, Vec3::UnitZ()));
  const Pose pb = a_in_b.inverse();
  Manifold m;
  ASSERT_TRUE(collide_capsule_box(a, b, pb, 0, m));
  ASSERT_EQ(m.count, 2);
  EXPECT_LT((pb.inverse_transform_vector(m.normal) - Vec3(0, -1, 0)).norm(), kTol);
  for (int i = 0; i < 2; ++i) EXPECT_NEAR(m.points[i].depth, 0.2, kTol);
  check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb));
  // Centred segment at the box centre, along a diagonal: defined, finite.
  const Pose diag(Vec3::Zero(), axis_angle(0.9, Vec3(1, 0, 1)));
  ASSERT_TRUE(collide_capsule_box(a, b, diag, 0, m));
  EXPECT_TRUE(m.normal.allFinite());
  for (int i = 0; i < m.count; ++i) EXPECT_TRUE(std::isfinite(m.points[i].depth));
}

TEST(CollideRound, TouchingGivesZeroDepth) {
  // Radii and offsets that are exact in binary, along axes: touching is exact, so it
  // must be reported with margin 0 and depth exactly 0.
  Capsule cap(0.25, 0.5);
  Box box(Vec3(1, 1, 1));
  Sphere s(0.5);
  Manifold m;
  // Capsule standing on the box's +y face: bottom at -0.75, face at -1.75 + 1.
  ASSERT_TRUE(collide_capsule_box(cap, box, Pose(Vec3(0, -1.75, 0)), 0, m));
  ASSERT_EQ(m.count, 1);
  EXPECT_EQ(m.points[0].depth, 0.0);
  // Two parallel capsules side by side, axes 0.5 apart: a touching line, 2 points.
  ASSERT_TRUE(collide_capsule_capsule(cap, cap, Pose(Vec3(0.5, 0, 0)), 0, m));
  ASSERT_EQ(m.count, 2);
  EXPECT_EQ(m.points[0].depth, 0.0);
  EXPECT_EQ(m.points[1].depth, 0.0);
  // Sphere on the box's -z face.
  ASSERT_TRUE(collide_sphere_box(s, box, Pose(Vec3(0.25, 0, 1.5)), 0, m));
  EXPECT_EQ(m.points[0].depth, 0.0);
  // Sphere against the capsule's end cap.
  ASSERT_TRUE(collide_sphere_capsule(s, cap, Pose(Vec3(0, -1.25, 0)), 0, m));
  EXPECT_EQ(m.points[0].depth, 0.0);
  EXPECT_EQ(m.points[0].feature_id, 1u);  // the capsule's +h end
}

TEST(CollideCapsuleBox, RandomSeparatedMatchesReferenceDistance) {
  std::mt19937 rng(5);
  Capsule a(0.2, 0.6);
  Box b(Vec3(0.7, 0.3, 0.5), 0.05);
  int hits = 0;
  for (int i = 0; i < 300; ++i) {
    const Pose pb(random_vec(rng, 1.4), random_rotation(rng));
    // Reference: distance from A's core segment to B's core box, golden section over
    // the segment parameter (point-box distance is convex along a line).
    const Pose a_in_b = pb.inverse();
    auto point_box = [&](Real y) {
      const Vec3 p = a_in_b.transform_point(Vec3(0, y, 0));
      const Vec3 core = b.core_half_extents();
      return (p - p.cwiseMax(-core).cwiseMin(core)).norm();
    };
    const Real dist = golden_min(point_box, -0.6, 0.6);
    if (dist < 1e-6) continue;  // overlapping cores: checked by the SAT tests
    const Real expected = 0.25 - dist;
    Manifold m;
    const bool hit = collide_capsule_box(a, b, pb, 0.1, m);
    ASSERT_EQ(hit, expected >= -0.1) << i;
    if (!hit) continue;
    ++hits;
    EXPECT_NEAR(m.max_depth(), expected, kRefTol) << i;
    // Clipped points of a capsule tilted by theta from the face sit r (1 - cos theta)
    // inside A's surface (the core point is pushed along the face normal, not along the
    // capsule's own normal), as in Box2D's and Jolt's clipping; sin theta = |n . axis|.
    const Real s = std::abs(m.normal.y());
    const Real surf = m.count == 1 ? kTol : 0.2 * (1 - std::sqrt(1 - s * s)) + kTol;
    check_manifold(m, sdf_of(a, Pose()), sdf_of(b, pb), surf);
  }
  EXPECT_GT(hits, 50);
}

TEST(CollideCapsuleBox, RandomOverlapDepthIsMinimumTranslation) {
  // For an overlapping pair the normal n must be a minimum-translation direction:
  //  * the reported depth is the exact overlap of the two shapes' projections on n,
  //    h_A(n) + h_B(-n) (support functions), so moving B by depth * n just separates
  //    them; for a clipped 2-point manifold no point is deeper than that;
  //  * no other direction needs much less: the minimum of h_A(u) + h_B(-u) over 20000
  //    Fibonacci directions is an upper bound on the true depth, and the routine may
  //    exceed the true core depth only by its face bias (1% + 10 um).
  std::mt19937 rng(9);
  Capsule a(0.15, 0.5);
  Box b(Vec3(0.6, 0.4, 0.5));
  constexpr int kDirs = 20000;
  std::vector<Vec3> dirs(kDirs);
  for (int k = 0; k < kDirs; ++k) {
    const Real z = 1 - (2 * k + 1.0) / kDirs;
    const Real r = std::sqrt(1 - z * z);
    const Real phi = k * kPi * (3 - std::sqrt(5.0));
    dirs[k] = Vec3(r * std::cos(phi), r * std::sin(phi), z);
  }
  int checked = 0;
  for (int i = 0; i < 40; ++i) {
    const Pose pb(random_vec(rng, 0.5), random_rotation(rng));
    const Mat3 rb = pb.matrix();
    auto overlap = [&](const Vec3& u) {
      const Real ha = 0.5 * std::abs(u.y()) + 0.15;  // capsule support along u
      const Real hb = b.half_extents().dot((rb.transpose() * u).cwiseAbs()) - pb.position.dot(u);
      return ha + hb;
    };
    Real ref = kInf;
    for (const Vec3& u : dirs) ref = std::min(ref, overlap(u));
    Manifold m;
    if (!collide_capsule_box(a, b, pb, 0, m)) {
      EXPECT_LT(ref, 0.0) << i;  // apart: some direction must separate them
      continue;
    }
    const Real along_n = overlap(m.normal);
    if (m.count == 1) {
      EXPECT_NEAR(m.max_depth(), along_n, kTol) << i;
    }
    EXPECT_LE(m.max_depth(), along_n + kTol) << i;
    const Real rr = 0.15;  // sum of the radii, outside the SAT's face bias
    EXPECT_LE(along_n, (ref - rr + 1e-5) / 0.99 + rr + kTol) << i;
    ++checked;
  }
  EXPECT_GT(checked, 20);
}

}  // namespace
}  // namespace wmo
