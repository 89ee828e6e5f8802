// Tests of the GJK / EPA / GJK-ray-cast templates (gjk.h) and of the convex pair
// routines in A's frame (convex_queries.h), against analytic answers and against
// separating-axis certificates.
#include <gtest/gtest.h>

#include <algorithm>
#include <cfloat>
#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "wmo/geometry/convex_queries.h"
#include "wmo/geometry/gjk.h"
#include "wmo/geometry/shapes.h"

namespace wmo {
namespace {

// Default tolerance for analytic comparisons on unit-sized shapes. GJK stops when
// |v|^2 - v.w <= 1e-10 |v|^2 (GjkSettings::tolerance), but on polytopes it terminates
// on the exact closest feature, so the answer is exact up to round-off: a few hundred
// ulp of the unit size (2.2e-16) is 1e-13; 1e-12 leaves a margin and is still 1e-12 of
// the size.
constexpr Real kTol = 1e-12;

Quat axis_angle(const Vec3& axis, Real angle) { return Quat(Eigen::AngleAxisd(angle, axis.normalized())); }

Pose at(const Vec3& p, const Quat& q = Quat::Identity()) { return Pose(p, q); }

void expect_finite(const DistanceResult& r) {
  EXPECT_TRUE(std::isfinite(r.distance));
  EXPECT_TRUE(r.point_a.allFinite());
  EXPECT_TRUE(r.point_b.allFinite());
  EXPECT_TRUE(r.normal.allFinite());
}

// Convention check (types.h): point_b = point_a - depth * normal, i.e.
// point_b - point_a = distance * normal for the signed distance.
void expect_consistent(const DistanceResult& r, Real tol) {
  expect_finite(r);
  EXPECT_NEAR(r.normal.norm(), 1.0, 1e-12);  // normalised in double: ~1 ulp
  EXPECT_LE((r.point_b - r.point_a - r.distance * r.normal).norm(), tol);
}

// ---- GJK on raw support functions ------------------------------------------------

TEST(Gjk, PointToPointIsExactInOneIteration) {
  PointSupport a{Vec3(0, 0, 0)}, b{Vec3::Zero()};
  const GjkResult g = gjk_distance(a, b, at(Vec3(3, 4, 0)));
  EXPECT_FALSE(g.intersecting);
  EXPECT_EQ(g.status, QueryStatus::kOk);
  EXPECT_DOUBLE_EQ(g.distance, 5.0);
  EXPECT_TRUE(g.normal.isApprox(Vec3(0.6, 0.8, 0), 1e-15));
  EXPECT_LE(g.iterations, 2);
}

TEST(Gjk, TriangleToPointPicksInteriorEdgeAndVertexRegions) {
  const TriangleSupport tri(Vec3(0, 0, 0), Vec3(2, 0, 0), Vec3(0, 2, 0));
  const PointSupport p{Vec3::Zero()};
  // Above the interior: distance is the height.
  GjkResult g = gjk_distance(tri, p, at(Vec3(0.5, 0.5, 3)));
  EXPECT_NEAR(g.distance, 3.0, kTol);
  EXPECT_TRUE(g.point_a.isApprox(Vec3(0.5, 0.5, 0), kTol));
  // Beside the hypotenuse (edge region).
  g = gjk_distance(tri, p, at(Vec3(2, 2, 0)));
  EXPECT_NEAR(g.distance, std::sqrt(2.0), kTol);
  EXPECT_LE((g.point_a - Vec3(1, 1, 0)).norm(), kTol);
  // Beyond a vertex.
  g = gjk_distance(tri, p, at(Vec3(-1, -1, -1)));
  EXPECT_NEAR(g.distance, std::sqrt(3.0), kTol);
  EXPECT_LE(g.point_a.norm(), kTol);
}

TEST(Gjk, IntersectEarlyExitsAndHonoursMargin) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(1, 1, 1));
  const CoreSupport<Box> sa(a), sb(b);
  EXPECT_TRUE(gjk_intersect(sa, sb, at(Vec3(1.9, 0.3, 0))));
  EXPECT_FALSE(gjk_intersect(sa, sb, at(Vec3(2.1, 0.3, 0))));
  // Gap 0.1: inside a margin of 0.11, outside a margin of 0.09.
  EXPECT_TRUE(gjk_intersect(sa, sb, at(Vec3(2.1, 0.3, 0)), {}, Vec3::UnitX(), 0.11));
  EXPECT_FALSE(gjk_intersect(sa, sb, at(Vec3(2.1, 0.3, 0)), {}, Vec3::UnitX(), 0.09));
}

TEST(Gjk, IterationCapIsHonoured) {
  const Cylinder a(1, 1), b(1, 1);
  GjkSettings s;
  s.max_iterations = 2;
  const GjkResult g = gjk_distance(CoreSupport<Cylinder>(a), CoreSupport<Cylinder>(b),
                                   at(Vec3(2.3, 2.7, 0.4), axis_angle(Vec3(1, 2, 3), 0.7)), s);
  EXPECT_LE(g.iterations, 2);
  EXPECT_TRUE(std::isfinite(g.distance));
}

// ---- Convex pairs: analytic answers ------------------------------------------------

TEST(ConvexPair, SphereSphereDistanceAndDepthAreExact) {
  const Sphere a(0.5), b(0.25);
  DistanceResult r = distance_convex_convex(a, b, at(Vec3(1, 2, 2)));  // centres 3 apart
  EXPECT_FALSE(r.intersecting);
  EXPECT_NEAR(r.distance, 3 - 0.75, kTol);
  expect_consistent(r, kTol);
  EXPECT_TRUE(r.point_a.isApprox(Vec3(1, 2, 2) / 3 * 0.5, kTol));
  r = penetration_convex_convex(a, b, at(Vec3(0, 0.5, 0)));
  EXPECT_TRUE(r.intersecting);
  EXPECT_NEAR(r.distance, -(0.75 - 0.5), kTol);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitY(), kTol));
  expect_consistent(r, kTol);
}

TEST(ConvexPair, ConcentricSpheresGiveFullDepthWithFallbackNormal) {
  const Sphere a(0.5), b(0.25);
  const DistanceResult r = penetration_convex_convex(a, b, Pose());
  EXPECT_TRUE(r.intersecting);
  EXPECT_NEAR(r.distance, -0.75, kTol);
  EXPECT_EQ(r.status, QueryStatus::kDegenerate);  // no defined direction: documented
  expect_consistent(r, kTol);
}

TEST(ConvexPair, SphereBoxFaceEdgeAndCornerDistances) {
  const Sphere s(0.5);
  const Box box(Vec3(1, 2, 3));
  // Sphere as B against the box as A, in the face, edge and corner regions.
  struct Case {
    Vec3 c;
    Real expected;
  };
  const Case cases[] = {{Vec3(3, 0.5, -1), 2 - 0.5},
                        {Vec3(2, 3, 0), std::sqrt(2.0) - 0.5},
                        {Vec3(-2, -3, 4), std::sqrt(3.0) - 0.5}};
  for (const Case& c : cases) {
    const DistanceResult r = distance_convex_convex(box, s, at(c.c, axis_angle(Vec3(1, 1, 0), 0.3)));
    EXPECT_NEAR(r.distance, c.expected, kTol) << c.c.transpose();
    expect_consistent(r, kTol);
    // Swapped roles: same distance, mirrored normal.
    const DistanceResult m = distance_convex_convex(s, box, Pose(c.c, Quat::Identity()).inverse());
    EXPECT_NEAR(m.distance, c.expected, kTol);
  }
  // Sphere centre inside the box, nearest face +x at 0.2: depth = 0.2 + r.
  const DistanceResult r = penetration_convex_convex(box, s, at(Vec3(0.8, 0, 0)));
  EXPECT_NEAR(r.distance, -(0.2 + 0.5), kTol);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitX(), kTol));
  expect_consistent(r, kTol);
}

TEST(ConvexPair, BoxBoxFaceFaceDistanceAndDepth) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  DistanceResult r = distance_convex_convex(a, b, at(Vec3(0.2, 1.8, -0.1)));
  EXPECT_NEAR(r.distance, 0.3, kTol);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitY(), kTol));
  expect_consistent(r, kTol);
  r = penetration_convex_convex(a, b, at(Vec3(0.2, 1.3, -0.1)));
  EXPECT_NEAR(r.distance, -0.2, kTol);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitY(), kTol));
  expect_consistent(r, kTol);
  EXPECT_EQ(r.status, QueryStatus::kOk);
}

TEST(ConvexPair, TouchingFacesHaveZeroDistanceAndDepth) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(1, 1, 1));
  const Pose touching = at(Vec3(2, 0.5, 0.25));  // faces x = 1 coincide
  DistanceResult r = distance_convex_convex(a, b, touching);
  EXPECT_LE(r.distance, kTol);
  r = penetration_convex_convex(a, b, touching);
  EXPECT_LE(std::abs(r.distance), kTol);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitX(), 1e-9)) << r.normal.transpose();
  expect_finite(r);
}

TEST(ConvexPair, CoincidentIdenticalShapesGiveFullOverlap) {
  // Identical boxes on top of each other: the cheapest way out is the thinnest axis.
  const Box a(Vec3(1, 2, 3)), b(Vec3(1, 2, 3));
  DistanceResult r = penetration_convex_convex(a, b, Pose());
  EXPECT_NEAR(r.distance, -2.0, kTol);
  EXPECT_NEAR(std::abs(r.normal.x()), 1.0, kTol);
  expect_consistent(r, kTol);
  // The same for a hull (a regular octahedron: depth = 2 * inradius = 2 / sqrt(3)).
  const ConvexHull h({Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1),
                      Vec3(0, 0, -1)});
  r = penetration_convex_convex(h, h, Pose());
  EXPECT_NEAR(r.distance, -2 / std::sqrt(3.0), kTol);
  expect_consistent(r, kTol);
}

TEST(ConvexPair, CapsuleCapsuleParallelAndCrossing) {
  const Capsule a(0.3, 1.0), b(0.2, 0.5);
  // Parallel axes 2 apart along x: distance 2 - 0.5.
  DistanceResult r = distance_convex_convex(a, b, at(Vec3(2, 0.3, 0)));
  EXPECT_NEAR(r.distance, 1.5, kTol);
  expect_consistent(r, kTol);
  // Crossing axes: B's axis along z (rotated about x), 0.4 apart along x: overlap 0.1.
  const Pose crossing = at(Vec3(0.4, 0.2, 0), axis_angle(Vec3::UnitX(), kPi / 2));
  r = penetration_convex_convex(a, b, crossing);
  EXPECT_NEAR(r.distance, -0.1, kTol);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitX(), kTol));
  expect_consistent(r, kTol);
  // Crossing axes through each other: the cores (segments) intersect, A - B is a flat
  // parallelogram, the depth is ra + rb along the normal of the two axes' plane.
  r = penetration_convex_convex(a, b, at(Vec3(0, 0.2, 0), axis_angle(Vec3::UnitX(), kPi / 2)));
  EXPECT_NEAR(r.distance, -0.5, kTol);
  EXPECT_NEAR(std::abs(r.normal.x()), 1.0, kTol);
  EXPECT_EQ(r.status, QueryStatus::kOk);
  expect_consistent(r, kTol);
}

TEST(ConvexPair, ParallelEdgesDistance) {
  // Two unit cubes rotated 45 degrees about x: their edges (along x) face each other.
  const Box a(Vec3(1, 1, 1)), b(Vec3(1, 1, 1));
  const Quat q = axis_angle(Vec3::UnitX(), kPi / 4);
  const Real s2 = std::sqrt(2.0);
  // A as the frame; B placed with the same rotation 3.5 above in A's rotated frame.
  const Pose b_world = at(Vec3(0.3, 3.5, 0), q);
  const Pose a_world = at(Vec3::Zero(), q);
  const DistanceResult r = distance_convex_convex(a, b, a_world.relative(b_world));
  EXPECT_NEAR(r.distance, 3.5 - 2 * s2, kTol);
  expect_consistent(r, kTol);
}

TEST(ConvexPair, BoxRotatedByTenthOfMicroradian) {
  // B rotated by 1e-7 rad about z above A: its lowest corner is at
  // y = 2.5 - hy cos(t) - hx sin(t). Tiny rotations make nearly parallel faces, the
  // classic case where GJK's sub-simplex solver must not lose the closest feature.
  const Real t = 1e-7;
  const Box a(Vec3(1, 1, 1)), b(Vec3(1, 1, 1));
  const DistanceResult r = distance_convex_convex(a, b, at(Vec3(0, 2.5, 0), axis_angle(Vec3::UnitZ(), t)));
  EXPECT_NEAR(r.distance, 2.5 - std::cos(t) - std::sin(t) - 1, kTol);
  expect_consistent(r, kTol);
  const DistanceResult p =
      penetration_convex_convex(a, b, at(Vec3(0, 1.5, 0), axis_angle(Vec3::UnitZ(), t)));
  EXPECT_NEAR(p.distance, -(1 - (1.5 - std::cos(t) - std::sin(t))), kTol);
  expect_consistent(p, kTol);
}

TEST(ConvexPair, ExtremeSizes) {
  // A 1 mm sphere and a 1 km box: relative accuracy 1e-12 of the larger size.
  const Sphere small(1e-3);
  const Box big(Vec3(1e3, 1e3, 1e3));
  DistanceResult r = distance_convex_convex(big, small, at(Vec3(1e3 + 0.5, 12, -7)));
  EXPECT_NEAR(r.distance, 0.5 - 1e-3, 1e3 * kTol);
  r = penetration_convex_convex(big, small, at(Vec3(1e3 - 2e-4, 12, -7)));
  EXPECT_NEAR(r.distance, -(1e-3 + 2e-4), 1e3 * kTol);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitX(), 1e-9));
  // Two 1 mm boxes overlapping by 0.1 mm.
  const Box tiny(Vec3(1e-3, 1e-3, 1e-3));
  r = penetration_convex_convex(tiny, tiny, at(Vec3(1.9e-3, 1e-4, 0)));
  EXPECT_NEAR(r.distance, -1e-4, 1e-3 * kTol);
  expect_consistent(r, 1e-3 * kTol);
}

TEST(ConvexPair, EpaAtNearZeroDepth) {
  // Overlap of 1e-9 m: EPA must report it (not 0, not a wrong face). Box-box EPA
  // converges on the exact face, so the error is round-off of unit coordinates.
  const Box a(Vec3(1, 1, 1)), b(Vec3(1, 1, 1));
  const DistanceResult r = penetration_convex_convex(a, b, at(Vec3(0.3, 2 - 1e-9, -0.2)));
  EXPECT_NEAR(r.distance, -1e-9, 1e-14);  // ~50 ulp of unit coordinates
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitY(), 1e-9));
  EXPECT_EQ(r.status, QueryStatus::kOk);
  // The same with a hull (an octahedron touching a box's face with its tip).
  const ConvexHull h({Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1),
                      Vec3(0, 0, -1)});
  const DistanceResult s = penetration_convex_convex(a, h, at(Vec3(0.1, 2 - 1e-9, 0.2)));
  EXPECT_NEAR(s.distance, -1e-9, 1e-14);
  EXPECT_TRUE(s.normal.isApprox(Vec3::UnitY(), 1e-9));
}

TEST(ConvexPair, RoundedBoxIsExact) {
  // Rounded box (half extents 1, rounding 0.2) against a sphere near its corner: the
  // corner is a sphere of radius 0.2 about (0.8, 0.8, 0.8).
  const Box a(Vec3(1, 1, 1), 0.2);
  const Sphere s(0.1);
  const Vec3 c = Vec3(0.8, 0.8, 0.8) + Vec3(1, 1, 1).normalized() * 0.5;
  const DistanceResult r = distance_convex_convex(a, s, at(c));
  EXPECT_NEAR(r.distance, 0.5 - 0.2 - 0.1, kTol);
  expect_consistent(r, kTol);
}

TEST(ConvexPair, CylinderCylinderAxisAligned) {
  // Stacked along their axes (faces touching region), and side by side.
  const Cylinder a(1, 0.5), b(0.5, 1);
  DistanceResult r = distance_convex_convex(a, b, at(Vec3(0.2, 1.7, 0)));
  EXPECT_NEAR(r.distance, 0.2, 1e-9);  // GJK on curved sides: relative 1e-10 tolerance
  r = distance_convex_convex(a, b, at(Vec3(2, 0.1, 0)));
  EXPECT_NEAR(r.distance, 0.5, 1e-9);
  r = penetration_convex_convex(a, b, at(Vec3(0.2, 1.4, 0)));
  EXPECT_NEAR(r.distance, -0.1, 1e-9);
  EXPECT_TRUE(r.normal.isApprox(Vec3::UnitY(), 1e-6));
}

// ---- Fuzz --------------------------------------------------------------------------

// Projection interval of a support function on a unit axis.
template <class F>
void interval(const F& support, const Vec3& n, Real& lo, Real& hi) {
  hi = n.dot(support(n));
  lo = n.dot(support(Vec3(-n)));
}

// Overlap of A and B along n (positive when the projections overlap), B at b_in_a.
Real overlap_along(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a, const Vec3& n) {
  Real alo, ahi;
  interval([&](const Vec3& d) { return a.support(d); }, n, alo, ahi);
  Real blo, bhi;
  interval([&](const Vec3& d) { return b_in_a.transform_point(b.support(b_in_a.inverse_transform_vector(d))); },
           n, blo, bhi);
  return std::min(ahi - blo, bhi - alo);
}

Vec3 random_unit(std::mt19937& rng) {
  std::normal_distribution<Real> g(0, 1);
  Vec3 v(g(rng), g(rng), g(rng));
  return v.normalized();
}

Quat random_rotation(std::mt19937& rng) {
  std::normal_distribution<Real> g(0, 1);
  Quat q(g(rng), g(rng), g(rng), g(rng));
  return q.normalized();
}

std::shared_ptr<ConvexShape> random_shape(std::mt19937& rng, int kind) {
  std::uniform_real_distribution<Real> u(0.2, 1.5);
  switch (kind) {
    case 0:
      return std::make_shared<Sphere>(u(rng));
    case 1:
      return std::make_shared<Box>(Vec3(u(rng), u(rng), u(rng)));
    case 2: {
      const Vec3 h(u(rng), u(rng), u(rng));
      return std::make_shared<Box>(h, 0.5 * h.minCoeff());
    }
    case 3:
      return std::make_shared<Capsule>(u(rng), u(rng));
    case 4:
      return std::make_shared<Cylinder>(u(rng), u(rng));
    default: {
      std::vector<Vec3> pts;
      for (int i = 0; i < 12; ++i) pts.push_back(u(rng) * random_unit(rng));
      return std::make_shared<ConvexHull>(pts);
    }
  }
}

TEST(ConvexPairFuzz, NoNanBoundedIterationsAndSeparatingAxisCertificates) {
  std::mt19937 rng(12345);
  std::uniform_real_distribution<Real> pos(-2.5, 2.5);
  const GjkSettings gs;
  const EpaSettings es;
  int apart = 0, overlapping = 0, not_ok = 0, curved_pairs = 0, curved_not_ok = 0;
  for (int i = 0; i < 3000; ++i) {
    const auto a = random_shape(rng, i % 6);
    const auto b = random_shape(rng, (i / 6) % 6);
    const Pose b_in_a(Vec3(pos(rng), pos(rng), pos(rng)), random_rotation(rng));
    const DistanceResult d = distance_convex_convex(*a, *b, b_in_a, gs);
    const DistanceResult p = penetration_convex_convex(*a, *b, b_in_a, gs, es);
    ASSERT_TRUE(std::isfinite(d.distance) && std::isfinite(p.distance)) << i;
    ASSERT_TRUE(p.point_a.allFinite() && p.point_b.allFinite() && p.normal.allFinite()) << i;
    EXPECT_LE(d.iterations, gs.max_iterations);
    EXPECT_LE(p.iterations, gs.max_iterations + es.max_iterations);
    EXPECT_EQ(d.intersecting, p.intersecting) << i;
    const bool both_curved = a->type() == ShapeType::kCylinder && b->type() == ShapeType::kCylinder;
    if (both_curved) ++curved_pairs;
    if (p.status != QueryStatus::kOk) ++(both_curved ? curved_not_ok : not_ok);
    // Polytope cores (everything but the cylinder, radii added exactly) make GJK and
    // EPA stop on exact features: round-off of coordinates up to ~5 m, a few hundred
    // ulp, well below 1e-12. A cylinder's curved side is approximated by EPA's
    // polytope down to its resolution limit, kEpaResolutionRel = 1e-8 of the size
    // (gjk.h), i.e. <= 3e-8 for these shapes (GJK's relative stop is tighter).
    const bool curved = a->type() == ShapeType::kCylinder || b->type() == ShapeType::kCylinder;
    const Real tol = curved ? 3e-8 : 1e-12;
    expect_consistent(p, tol);
    // Along the reported normal the projections must be separated by exactly the
    // distance (apart) or overlap by exactly the depth (overlapping).
    const Real ov = overlap_along(*a, *b, b_in_a, p.normal);
    EXPECT_NEAR(ov, -p.distance, tol) << "case " << i;
    if (p.intersecting) {
      ++overlapping;
      // EPA's depth is minimal: no direction has a smaller overlap.
      for (int k = 0; k < 20; ++k) EXPECT_GE(overlap_along(*a, *b, b_in_a, random_unit(rng)), -p.distance - tol);
    } else {
      ++apart;
      EXPECT_NEAR(d.distance, p.distance, tol);
    }
  }
  // Both regimes are exercised, and no random (non-degenerate) pair needs a fallback,
  // except that EPA between two cylinders (a doubly curved Minkowski difference) may
  // need more than the default cap (256 iterations) to meet the 1e-10 relative
  // tolerance (at the old cap of 128, about 1.5% of overlapping cylinder pairs in a
  // 3000-pair experiment); 10% is a generous bound that still catches a systematic
  // failure.
  EXPECT_GT(apart, 300);
  EXPECT_GT(overlapping, 300);
  EXPECT_EQ(not_ok, 0);
  EXPECT_LE(curved_not_ok, curved_pairs / 10);
}

TEST(ConvexPairFuzz, BoxBoxDepthMatchesSeparatingAxisTheorem) {
  // For two boxes the penetration depth is the smallest overlap over the 15 SAT axes
  // (Gottschalk et al. 1996): an exact reference for EPA.
  std::mt19937 rng(777);
  std::uniform_real_distribution<Real> u(0.2, 1.5), pos(-1.5, 1.5);
  for (int i = 0; i < 1000; ++i) {
    const Box a(Vec3(u(rng), u(rng), u(rng))), b(Vec3(u(rng), u(rng), u(rng)));
    const Pose b_in_a(Vec3(pos(rng), pos(rng), pos(rng)), random_rotation(rng));
    const DistanceResult p = penetration_convex_convex(a, b, b_in_a);
    const Mat3 rb = b_in_a.matrix();
    std::vector<Vec3> axes;
    for (int k = 0; k < 3; ++k) {
      axes.push_back(Vec3::Unit(k));
      axes.push_back(rb.col(k));
      for (int j = 0; j < 3; ++j) {
        const Vec3 c = Vec3::Unit(k).cross(rb.col(j));
        if (c.norm() > 1e-6) axes.push_back(c.normalized());  // skip near-parallel edge pairs
      }
    }
    Real sat = kInf;
    for (const Vec3& n : axes) sat = std::min(sat, overlap_along(a, b, b_in_a, n));
    if (sat > 0) {
      ASSERT_TRUE(p.intersecting) << i;
      // EPA stops on the exact face of the box cores: round-off of unit coordinates.
      EXPECT_NEAR(-p.distance, sat, 1e-12) << i;
      EXPECT_EQ(p.status, QueryStatus::kOk) << i;
    } else {
      EXPECT_FALSE(p.intersecting && sat < -1e-12) << i;
    }
  }
}

TEST(ConvexPairFuzz, DegenerateGridConfigurations) {
  // Boxes, hulls and capsules on a half-unit grid with quarter-turn rotations: faces,
  // edges and vertices touch or coincide exactly, the worst case for sub-simplex and
  // polytope degeneracy. Every answer must be finite, consistent and certified.
  std::mt19937 rng(4242);
  std::uniform_int_distribution<int> cell(-4, 4), turn(0, 3), kind(0, 3);
  const Box unit(Vec3(1, 1, 1)), slab(Vec3(1, 0.5, 2));
  const Capsule cap(0.5, 1);
  const ConvexHull oct({Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1),
                        Vec3(0, 0, -1)});
  const ConvexShape* shapes[] = {&unit, &slab, &cap, &oct};
  int touching = 0;
  for (int i = 0; i < 2000; ++i) {
    const ConvexShape& a = *shapes[kind(rng)];
    const ConvexShape& b = *shapes[kind(rng)];
    const Quat q = axis_angle(Vec3::UnitX(), turn(rng) * kPi / 2) *
                   axis_angle(Vec3::UnitY(), turn(rng) * kPi / 2);
    const Pose b_in_a(0.5 * Vec3(cell(rng), cell(rng), cell(rng)), q);
    const DistanceResult p = penetration_convex_convex(a, b, b_in_a);
    expect_consistent(p, 1e-12);  // polytope cores: round-off of coordinates <= 4
    EXPECT_NE(p.status, QueryStatus::kMaxIterations) << i;
    const Real ov = overlap_along(a, b, b_in_a, p.normal);
    EXPECT_NEAR(ov, -p.distance, 1e-12) << i << " types " << (int)a.type() << "," << (int)b.type() << " pos " << b_in_a.position.transpose() << " q " << q.coeffs().transpose() << " st " << (int)p.status << " n " << p.normal.transpose();
    if (std::abs(p.distance) < 1e-12) ++touching;
    if (p.intersecting && p.status == QueryStatus::kOk)
      for (int k = 0; k < 10; ++k) EXPECT_GE(overlap_along(a, b, b_in_a, random_unit(rng)), -p.distance - 1e-12);
  }
  EXPECT_GT(touching, 20);  // the grid does produce exact contact
}

// ---- GJK ray cast ------------------------------------------------------------------

TEST(GjkRaycast, SphereAndRoundedBoxMatchAnalytic) {
  const Sphere s(0.7);
  const FullSupport<Sphere> fs(s);
  // Ray along -x from (5, 0.3, 0): hits at x = sqrt(0.49 - 0.09).
  RayHit h = gjk_raycast(fs, Vec3(5, 0.3, 0), Vec3(-2, 0, 0), 10);
  ASSERT_TRUE(h.hit);
  // On a curved surface the GJK ray cast ends within ~1e-9 of the scene size (~5 m)
  // of the surface (gjk.h); this ray meets the sphere at a steep angle, so the error
  // in t is of the same order: 1e-9 in t (units of |dir| = 2, so 2e-9 m).
  EXPECT_NEAR(h.distance, (5 - std::sqrt(0.4)) / 2, 1e-9);
  // The ray cast's normal is its last separating direction; on a curved surface its
  // error is about the square root of the relative position error (sqrt(1e-11) ~ 3e-6).
  EXPECT_TRUE(h.normal.isApprox(Vec3(std::sqrt(0.4), 0.3, 0) / 0.7, 1e-5));
  // Miss, start inside, beyond max_t.
  EXPECT_FALSE(gjk_raycast(fs, Vec3(5, 0.8, 0), Vec3(-1, 0, 0), 10).hit);
  h = gjk_raycast(fs, Vec3(0.1, 0, 0), Vec3(1, 0, 0), 10);
  EXPECT_TRUE(h.hit);
  EXPECT_EQ(h.distance, 0);
  EXPECT_TRUE(h.normal.isZero());
  EXPECT_FALSE(gjk_raycast(fs, Vec3(5, 0.3, 0), Vec3(-1, 0, 0), 4).hit);
  // Rounded box: straight onto a face, and onto a rounded corner along the diagonal.
  const Box rb(Vec3(1, 1, 1), 0.25);
  const FullSupport<Box> fb(rb);
  h = gjk_raycast(fb, Vec3(0.2, 4, 0.1), Vec3(0, -1, 0), 10);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.distance, 3, 1e-9);
  const Vec3 diag = Vec3(1, 1, 1).normalized();
  h = gjk_raycast(fb, 5 * diag, -diag, 10);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.distance, 5 - (0.75 * std::sqrt(3.0) + 0.25), 1e-9);
}

// ---- Regressions (issue 2: the FCL / libccd cross-check, hard-region configurations) ----

namespace issue2 {

// Support distance of A - B (A's frame) along unit n: translating B by h(n) n makes the
// sets touch; min over n of h(n) is the penetration depth.
Real support_distance(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a, const Vec3& n) {
  const Vec3 sa = a.support(n);
  const Vec3 sb = b_in_a.transform_point(b.support(b_in_a.inverse_transform_vector(-n)));
  return n.dot(sa - sb);
}

}  // namespace issue2

// GJK stalled on an ill-conditioned simplex (support points clustered on the cylinder's
// rim) and reported a positive distance, 1.04e-9 m, for a box and a cylinder that overlap
// by 1.2146e-8 m (found by minimising the support distance of A - B over directions with
// an independent local search: 1.21463e-8 m; the box / cylinder pose is the cross-check's box_cylinder
// failure with B moved along libccd's normal). Fixed by restarting GJK from its newest
// support point when it stalls without a separating plane (gjk.h, kGjkStallRel).
TEST(Regression, Issue2_GjkStallOnCylinderRimReportsOverlap) {
  const Box a(Vec3(0.58001934473371874, 0.081226200404510937, 0.08494727938212368));
  const Cylinder b(0.030506623523310791, 0.55170443409103087);
  const Pose pa(Vec3(-2.597814484826503, 0.051907407875385836, 1.6847988908610914),
                Quat(0.25512343872067306, -0.64603099799048569, 0.03088095050385567, 0.71875054611926004));
  const Pose pb(Vec3(-2.2754652039322592, -0.002389335743972027, 1.6625912984522353),
                Quat(0.68848265597970448, -0.51437794085358834, -0.48747310949300737, -0.15419771042260244));
  const Pose b_in_a = pa.relative(pb);
  const DistanceResult d = distance_convex_convex(a, b, b_in_a);
  EXPECT_TRUE(d.intersecting);
  EXPECT_EQ(d.distance, 0.0);
  EXPECT_TRUE(intersect_convex_convex(a, b, b_in_a));
  const DistanceResult p = penetration_convex_convex(a, b, b_in_a);
  EXPECT_EQ(p.status, QueryStatus::kOk);
  // 1.21463e-8 m to the 6 digits the independent search printed (+-5e-14), plus EPA's
  // absolute tolerance 1e-12 m. The answer must also be a valid translation: the
  // support distance along its normal equals the depth up to that tolerance.
  EXPECT_NEAR(-p.distance, 1.21463e-8, 1.1e-12);
  EXPECT_NEAR(issue2::support_distance(a, b, b_in_a, p.normal), -p.distance, 2e-12);
}

// EPA hit its cap on a sphere whose centre is near a cylinder's axis (every radial
// direction is almost equally shallow, so EPA has to tessellate the whole rim) and
// answered with its closest face, 1.7e-5 m short of the depth: translating B by it did
// not separate. Fixed twice over: sphere-in-cylinder is now closed form, and a capped
// EPA answers with its best upper bound (a valid translation), see the next test.
TEST(Regression, Issue2_SphereCentreNearCylinderAxisIsExact) {
  const Sphere a(0.10638109059151225);
  const Cylinder b(0.13648500310011491, 0.19385974080993731);
  const Pose pa(Vec3(-2.0136459145881047, -2.5802993422938201, -1.3368739514355279),
                Quat(0.13853558422861117, -0.0061423522356970576, 0.34171104683905568, -0.92951800621591341));
  const Pose pb(Vec3(-2.0137360230520631, -2.5808074123996394, -1.3365744813439508),
                Quat(0.088037028138811591, -0.52404528967512165, -0.82365352898882183, 0.19804262225608013));
  for (const bool swapped : {false, true}) {
    const Pose b_in_a = swapped ? pb.relative(pa) : pa.relative(pb);
    const DistanceResult p = swapped ? penetration_convex_convex(b, a, b_in_a) : penetration_convex_convex(a, b, b_in_a);
    // Closed form: the centre in the cylinder's frame is 1.39e-4 m off the axis.
    const Vec3 c = pb.inverse_transform_point(pa.position);
    const Real depth = a.radius() + std::min(b.cylinder_radius() - std::hypot(c.x(), c.z()),
                                             b.half_height() - std::abs(c.y()));
    EXPECT_EQ(p.status, QueryStatus::kOk);
    // Coordinates ~3 m from the origin: a few ulp of 3 m is 1e-15; 1e-12 fails any
    // iterative answer (the old one was 1.7e-5 m off).
    EXPECT_NEAR(-p.distance, depth, 1e-12) << swapped;
    expect_consistent(p, 1e-12);
    const ConvexShape& sa = swapped ? static_cast<const ConvexShape&>(b) : a;
    const ConvexShape& sb = swapped ? static_cast<const ConvexShape&>(a) : b;
    EXPECT_NEAR(issue2::support_distance(sa, sb, b_in_a, p.normal), -p.distance, 1e-12) << swapped;
  }
}

// A capped EPA (kMaxIterations) must still answer with a valid translation: the support
// distance along its normal equals its depth (the best upper bound), never a lower bound
// that leaves the pair overlapping, and never depth 0 for a clearly overlapping pair.
TEST(Regression, Issue2_CappedEpaAnswersWithAValidUpperBound) {
  const Cylinder a(0.5, 0.5), b(0.4, 0.6);
  EpaSettings few;
  few.max_iterations = 6;  // far too few for two curved cylinders: forces the cap
  int capped = 0;
  std::mt19937 rng(2);
  for (int i = 0; i < 200; ++i) {
    const Pose b_in_a(0.3 * random_unit(rng), random_rotation(rng));
    const DistanceResult p = penetration_convex_convex(a, b, b_in_a, GjkSettings{}, few);
    ASSERT_TRUE(p.intersecting);
    if (p.status != QueryStatus::kMaxIterations) continue;
    ++capped;
    EXPECT_GT(-p.distance, 0.1) << i;  // centres within 0.3 m: overlap >= 0.3 m
    // Valid: h(n) <= depth up to round-off of metre-sized supports (1e-12).
    EXPECT_LE(issue2::support_distance(a, b, b_in_a, p.normal), -p.distance + 1e-12) << i;
  }
  EXPECT_GT(capped, 50);  // the cap was really exercised
}

// EPA's polytope went non-convex when a new support point lay within 2e-12 m of the
// face being expanded on a cylinder's rim: round-off misjudged which faces see it, a
// new face came out inverted (negative distance), and EPA then popped it, cycled until
// its cap and answered depth 0 for a 0.92 mm overlap (the cross-check's
// cylinder_convex_hull failure). Now an expansion that creates a face closer than the
// one popped stops with the popped face. The failure needs its exact bits, so this
// checks the invariant on many near-touching cylinder-hull pairs instead: the depth
// is positive, valid along its normal, and no smaller than the overlap along any
// direction minus EPA's resolution.
TEST(Regression, Issue2_EpaNeverAnswersZeroForClearOverlapOnCylinderRim) {
  std::mt19937 rng(321);
  std::uniform_real_distribution<Real> u(0, 1);
  std::vector<Vec3> pts;
  for (int i = 0; i < 20; ++i) pts.push_back(random_unit(rng));
  int checked = 0;
  for (int i = 0; i < 400; ++i) {
    const Real s = 0.05 + u(rng);
    std::vector<Vec3> p = pts;
    for (Vec3& v : p) v *= s;
    const ConvexHull b(p);
    const Cylinder a(0.03 + 0.5 * u(rng), 0.03 + 0.5 * u(rng));
    const Vec3 dir = random_unit(rng);
    const Quat q = random_rotation(rng);
    // Touching distance along dir by bisection, then 1e-4..1e-3 m deeper.
    Real lo = 0, hi = 3;
    for (int k = 0; k < 60; ++k) {
      const Real m = 0.5 * (lo + hi);
      (intersect_convex_convex(a, b, Pose(m * dir, q)) ? lo : hi) = m;
    }
    const Real push = 1e-4 + 9e-4 * u(rng);
    const Pose b_in_a((lo - push) * dir, q);
    // Tolerances far below the curved-surface resolution drive every pair's EPA into
    // the round-off regime where the corruption happened (support points within
    // ~1e-12 m of the expanded face). Note: the pre-fix code passes these 400 pairs
    // too; the cross-check's exact failing bits could not be rebuilt outside its run,
    // so this guards the invariant rather than replaying the failure.
    EpaSettings tight;
    tight.tolerance = 1e-15;
    tight.absolute_tolerance = 1e-16;
    tight.max_iterations = 400;
    tight.max_faces = 2000;
    const DistanceResult r = penetration_convex_convex(a, b, b_in_a, GjkSettings{}, tight);
    ASSERT_TRUE(r.intersecting) << i;
    ++checked;
    // Moving B back out along dir by `push` separates, so the depth is at most about
    // push (dir is not the optimal normal) and clearly above 0: the overlap along dir's
    // supporting planes is >= push * cos(angle) ... bounded below by the depth itself.
    EXPECT_GT(-r.distance, 0.0) << i;
    EXPECT_LE(-r.distance, push + 1e-9) << i;  // bisection bracket 3 * 2^-60 ~ 3e-18
    // Valid along its normal: the support distance there matches the depth within the
    // curved-surface resolution kEpaResolutionRel (1e-8 of the size, <= 2e-8 m here).
    EXPECT_NEAR(issue2::support_distance(a, b, b_in_a, r.normal), -r.distance, 2e-8) << i;
  }
  EXPECT_EQ(checked, 400);
}

}  // namespace
}  // namespace wmo

namespace wmo {
namespace {

// gjk_distance's cull: it may stop early only when the distance really exceeds the
// cull distance, and below it the answer is the same as without a cull. Cylinder
// cores (curved: GJK needs many iterations there) against box cores, centres 0.5..1.5 m
// apart (overlapping to 0.8 m apart), culled at 0.1 m.
TEST(Gjk, CullStopsOnlyBeyondTheCullDistance) {
  std::mt19937 rng(77);
  std::uniform_real_distribution<Real> u(0, 1);
  const Cylinder a(0.4, 0.3);
  const Box b(Vec3(0.2, 0.5, 0.3));
  const CoreSupport<Cylinder> sa(a);
  const CoreSupport<Box> sb(b);
  const Real cull = 0.1;
  int culled = 0, kept = 0, fewer_iterations = 0;
  for (int i = 0; i < 2000; ++i) {
    const Pose b_in_a((0.5 + 1.0 * u(rng)) * random_unit(rng), random_rotation(rng));
    const GjkResult full = gjk_distance(sa, sb, b_in_a, GjkSettings{}, b_in_a.position);
    const GjkResult c = gjk_distance(sa, sb, b_in_a, GjkSettings{}, b_in_a.position, cull);
    if (c.culled) {
      ++culled;
      // A separating plane proved distance > cull: the exact distance agrees (GJK's
      // tolerance 1e-10 relative is far below the cull margin).
      EXPECT_GT(full.distance, cull) << i;
      EXPECT_GE(c.distance, full.distance * (1 - 1e-9)) << i;  // |v| bounds the distance from above
      fewer_iterations += c.iterations < full.iterations;
    } else {
      ++kept;
      EXPECT_EQ(c.distance, full.distance) << i;  // the same run to the end
      EXPECT_EQ(c.intersecting, full.intersecting) << i;
    }
    if (full.distance <= cull) EXPECT_FALSE(c.culled) << i;
  }
  EXPECT_GT(culled, 500);  // both branches exercised
  EXPECT_GT(kept, 100);
  EXPECT_GT(fewer_iterations, culled / 2);  // and the cull saves work
}

}  // namespace
}  // namespace wmo
