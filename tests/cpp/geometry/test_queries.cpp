// Tests of the top-level geometry queries (queries.h): world poses in, world results
// out, for convex, plane, compound and triangle-mesh pairs, and ray casts against every
// shape type, checked against analytic answers.
#include <gtest/gtest.h>

#include <cmath>
#include <functional>
#include <memory>
#include <random>
#include <string>
#include <vector>

#include "wmo/geometry/gjk.h"
#include "wmo/geometry/queries.h"
#include "wmo/geometry/shapes.h"

namespace wmo {
namespace {

// Tolerance for analytic comparisons near the origin with unit-sized shapes: the pair
// routines are exact on polytope cores up to round-off (a few hundred ulp of 1).
constexpr Real kTol = 1e-12;
// Far from the origin the query itself runs in A's frame (small coordinates); only the
// final mapping to world space adds round-off of the world coordinates: a few ulp of
// 1e4 (1.8e-12 each). 1e-10 is that with a wide margin, and far below the 1e-4 m that
// single-precision or world-frame arithmetic would lose at this distance.
constexpr Real kFarTol = 1e-10;

Quat axis_angle(const Vec3& axis, Real angle) { return Quat(Eigen::AngleAxisd(angle, axis.normalized())); }

std::string message_of(const std::function<void()>& f) {
  try {
    f();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "<no InvalidArgument thrown>";
}

void expect_convention(const DistanceResult& r, Real tol) {
  ASSERT_TRUE(std::isfinite(r.distance));
  EXPECT_NEAR(r.normal.norm(), 1.0, 1e-12);  // a normalised vector: ~1 ulp
  EXPECT_LE((r.point_b - r.point_a - r.distance * r.normal).norm(), tol);
}

// ---- Convex pairs in world space -------------------------------------------------

TEST(Queries, SphereBoxFarFromOriginMatchesAnalytic) {
  const Sphere s(0.5);
  const Box box(Vec3(1, 2, 3));
  const Quat q = axis_angle(Vec3(1, 2, 3), 0.8);
  const Vec3 far(1e4, -1e4, 1e4);
  const Pose pose_box(far, q);
  // Sphere centre 1.5 beyond the box's +y face (in the box frame), so distance 1.
  const Vec3 c_local(0.3, 3.5, -1);
  const Pose pose_s(pose_box.transform_point(c_local), Quat::Identity());
  const DistanceResult r = distance(box, pose_box, s, pose_s);
  EXPECT_NEAR(r.distance, 1.0, kFarTol);
  EXPECT_LE((r.normal - q * Vec3::UnitY()).norm(), 1e-12);
  EXPECT_LE((r.point_a - pose_box.transform_point(Vec3(0.3, 2, -1))).norm(), kFarTol);
  EXPECT_LE((r.point_b - pose_box.transform_point(Vec3(0.3, 3, -1))).norm(), kFarTol);
  // Overlapping by 0.2, and the mirrored query.
  const Pose pose_s2(pose_box.transform_point(Vec3(0.3, 2.3, -1)), Quat::Identity());
  const DistanceResult p = penetration(box, pose_box, s, pose_s2);
  EXPECT_TRUE(p.intersecting);
  EXPECT_NEAR(p.distance, -0.2, kFarTol);
  expect_convention(p, kFarTol);
  const DistanceResult m = penetration(s, pose_s2, box, pose_box);
  EXPECT_NEAR(m.distance, -0.2, kFarTol);
  EXPECT_LE((m.normal + p.normal).norm(), 1e-12);
  EXPECT_LE((m.point_a - p.point_b).norm(), kFarTol);
}

TEST(Queries, BoxBoxFarFromOriginDepthAndDistance) {
  const Box a(Vec3(1, 1, 1)), b(Vec3(0.5, 0.5, 0.5));
  const Quat q = axis_angle(Vec3(0, 1, 1), 1.1);
  const Pose pa(Vec3(-1e4, 2e4, 5e3), q);
  // B sits on A's local +x face, overlapping by 0.25.
  const Pose pb(pa.transform_point(Vec3(1.25, 0.1, -0.2)), q);
  DistanceResult r = penetration(a, pa, b, pb);
  EXPECT_NEAR(r.distance, -0.25, kFarTol);
  EXPECT_LE((r.normal - q * Vec3::UnitX()).norm(), 1e-12);
  expect_convention(r, kFarTol);
  r = closest_points(a, pa, b, pb);
  EXPECT_NEAR(r.distance, -0.25, kFarTol);
  r = distance(a, pa, b, pb);
  EXPECT_TRUE(r.intersecting);
  EXPECT_EQ(r.distance, 0);
  const Pose pb_apart(pa.transform_point(Vec3(1.75, 0.1, -0.2)), q);
  r = distance(a, pa, b, pb_apart);
  EXPECT_FALSE(r.intersecting);
  EXPECT_NEAR(r.distance, 0.25, kFarTol);
  EXPECT_TRUE(intersect(a, pa, b, pb));
  EXPECT_FALSE(intersect(a, pa, b, pb_apart));
}

TEST(Queries, CapsuleCapsuleWorld) {
  // Two capsules lying along world x (rotated from local y), 1 apart in z.
  const Capsule a(0.25, 1), b(0.25, 2);
  const Quat q = axis_angle(Vec3::UnitZ(), kPi / 2);
  const DistanceResult r =
      distance(a, Pose(Vec3(0, 0, 0), q), b, Pose(Vec3(0.5, 0, 1), q));
  EXPECT_NEAR(r.distance, 0.5, kTol);
  EXPECT_LE((r.normal - Vec3::UnitZ()).norm(), kTol);
}

// ---- Plane ----------------------------------------------------------------------

TEST(Queries, PlaneConvexBothOrders) {
  const Plane ground(Vec3(0, 0, 1), 0.5);  // z <= 0.5
  const Box box(Vec3(1, 1, 1), 0.1);
  const Quat q = axis_angle(Vec3::UnitX(), kPi / 4);
  // A 45-degree rotated rounded box: its lowest point is a rounded edge at
  // z_c - (sqrt(2) * 0.9 + 0.1).
  const Real low = std::sqrt(2.0) * 0.9 + 0.1;
  const Pose pb(Vec3(3, -2, 0.5 + low + 0.3), q);
  DistanceResult r = distance(ground, Pose(), box, pb);
  EXPECT_NEAR(r.distance, 0.3, kTol);
  EXPECT_LE((r.normal - Vec3::UnitZ()).norm(), kTol);
  EXPECT_NEAR(r.point_a.z(), 0.5, kTol);
  expect_convention(r, kTol);
  r = distance(box, pb, ground, Pose());  // mirrored
  EXPECT_NEAR(r.distance, 0.3, kTol);
  EXPECT_LE((r.normal + Vec3::UnitZ()).norm(), kTol);
  EXPECT_NEAR(r.point_b.z(), 0.5, kTol);
  // Sunk by 0.2.
  const Pose sunk(Vec3(3, -2, 0.5 + low - 0.2), q);
  r = penetration(ground, Pose(), box, sunk);
  EXPECT_TRUE(r.intersecting);
  EXPECT_NEAR(r.distance, -0.2, kTol);
  expect_convention(r, kTol);
  EXPECT_TRUE(intersect(box, sunk, ground, Pose()));
  EXPECT_FALSE(intersect(box, pb, ground, Pose()));
  // A plane placed with a pose far away.
  const Pose plane_pose(Vec3(1e4, 1e4, 1e4), axis_angle(Vec3::UnitY(), 0.3));
  const Sphere s(1);
  const Pose ps(plane_pose.transform_point(Vec3(5, 7, 0.5 + 1 + 2)), Quat::Identity());
  r = distance(ground, plane_pose, s, ps);
  EXPECT_NEAR(r.distance, 2, kFarTol);
}

TEST(Queries, UnsupportedPairsSayUnsupported) {
  const Plane p1(Vec3(0, 0, 1), 0), p2(Vec3(0, 1, 0), 0);
  const DistanceResult r = distance(p1, Pose(), p2, Pose());
  EXPECT_EQ(r.status, QueryStatus::kUnsupported);
  EXPECT_FALSE(r.intersecting);
  EXPECT_FALSE(intersect(p1, Pose(), p2, Pose()));
  const TriangleMesh mesh({Vec3(0, 0, 0), Vec3(1, 0, 0), Vec3(0, 1, 0)}, {{0, 1, 2}});
  EXPECT_EQ(penetration(mesh, Pose(), mesh, Pose()).status, QueryStatus::kUnsupported);
  EXPECT_EQ(closest_points(mesh, Pose(), p1, Pose()).status, QueryStatus::kUnsupported);
}

// ---- Compound -------------------------------------------------------------------

TEST(Queries, CompoundUsesClosestChild) {
  // A dumbbell: two spheres at x = +-2 joined by a thin box.
  auto ball = std::make_shared<Sphere>(0.5);
  auto bar = std::make_shared<Box>(Vec3(2, 0.1, 0.1));
  const Compound dumbbell({{ball, Pose(Vec3(-2, 0, 0))}, {ball, Pose(Vec3(2, 0, 0))}, {bar, Pose()}});
  const Quat q = axis_angle(Vec3::UnitZ(), kPi / 2);  // the dumbbell along world y
  const Pose pd(Vec3(10, 0, 0), q);
  const Sphere s(0.25);
  // Probe sphere beside the +y ball (world (10, 2, 0)) at distance 1 from it.
  DistanceResult r = distance(dumbbell, pd, s, Pose(Vec3(10, 3.75, 0)));
  EXPECT_NEAR(r.distance, 1.0, kTol);
  EXPECT_LE((r.normal - Vec3::UnitY()).norm(), kTol);
  // Mirrored, and against the bar (0.1 half thickness) from the side.
  r = distance(s, Pose(Vec3(10, 3.75, 0)), dumbbell, pd);
  EXPECT_NEAR(r.distance, 1.0, kTol);
  r = penetration(dumbbell, pd, s, Pose(Vec3(10.3, 0, 0)));
  EXPECT_NEAR(r.distance, -0.05, kTol);
  EXPECT_LE((r.normal - Vec3::UnitX()).norm(), kTol);
  EXPECT_TRUE(intersect(s, Pose(Vec3(10.3, 0, 0)), dumbbell, pd));
  EXPECT_FALSE(intersect(s, Pose(Vec3(10.4, 1, 0)), dumbbell, pd));
  // Compound against a plane and against a compound.
  const Plane ground(Vec3(0, 0, 1), 0);
  r = distance(ground, Pose(), dumbbell, Pose(Vec3(0, 0, 1.5)));
  EXPECT_NEAR(r.distance, 1.0, kTol);
  r = distance(dumbbell, Pose(Vec3(0, 0, 0)), dumbbell, Pose(Vec3(0, 0, 3)));
  EXPECT_NEAR(r.distance, 2.0, kTol);
}

// ---- Triangle mesh ----------------------------------------------------------------

// A 2 x 2 grid of unit squares in z = 0 (8 triangles, normals +z).
TriangleMesh make_floor() {
  std::vector<Vec3> v;
  for (int j = 0; j <= 2; ++j)
    for (int i = 0; i <= 2; ++i) v.emplace_back(i - 1.0, j - 1.0, 0);
  std::vector<std::array<int, 3>> t;
  for (int j = 0; j < 2; ++j)
    for (int i = 0; i < 2; ++i) {
      const int a = j * 3 + i, b = a + 1, c = a + 3, d = a + 4;
      t.push_back({a, b, d});
      t.push_back({a, d, c});
    }
  return TriangleMesh(v, t);
}

TEST(Queries, MeshConvexDistancePenetrationIntersect) {
  const TriangleMesh floor = make_floor();
  const Sphere s(0.25);
  // Above the floor, far above, beyond its edge, and sunk.
  DistanceResult r = distance(floor, Pose(), s, Pose(Vec3(0.3, -0.2, 1)));
  EXPECT_NEAR(r.distance, 0.75, kTol);
  EXPECT_LE((r.normal - Vec3::UnitZ()).norm(), kTol);
  r = distance(floor, Pose(), s, Pose(Vec3(0.3, -0.2, 100)));  // needs the growing search
  EXPECT_NEAR(r.distance, 99.75, 1e2 * kTol);
  r = distance(s, Pose(Vec3(3, 0.5, 0)), floor, Pose());  // beside the x = 1 edge, mirrored
  EXPECT_NEAR(r.distance, 1.75, kTol);
  EXPECT_LE((r.normal + Vec3::UnitX()).norm(), kTol);
  r = penetration(floor, Pose(), s, Pose(Vec3(0.3, -0.2, 0.15)));
  EXPECT_NEAR(r.distance, -0.1, kTol);
  EXPECT_LE((r.normal - Vec3::UnitZ()).norm(), kTol);
  expect_convention(r, kTol);
  EXPECT_TRUE(intersect(floor, Pose(), s, Pose(Vec3(0.3, -0.2, 0.2))));
  EXPECT_FALSE(intersect(floor, Pose(), s, Pose(Vec3(0.3, -0.2, 0.3))));
  // A box resting on a mesh moved far away and rotated.
  const Pose pm(Vec3(1e4, 1e4, -1e4), axis_angle(Vec3(1, 1, 0), 0.4));
  const Box box(Vec3(0.2, 0.2, 0.2));
  const Pose pb(pm.transform_point(Vec3(0.1, 0.1, 0.5)), pm.rotation);
  r = distance(floor, pm, box, pb);
  EXPECT_NEAR(r.distance, 0.3, kFarTol);
}

// ---- Ray casts ------------------------------------------------------------------

TEST(Raycast, AnalyticShapes) {
  const Vec3 o(0.2, 5, -0.1), d(0, -2, 0);  // |d| = 2: distances in units of |d|
  {
    const Sphere s(1);
    const RayHit h = raycast(s, Pose(), o, d);
    ASSERT_TRUE(h.hit);
    const Real y = std::sqrt(1 - 0.04 - 0.01);
    EXPECT_NEAR(h.distance, (5 - y) / 2, kTol);
    EXPECT_LE((h.normal - Vec3(0.2, y, -0.1)).norm(), kTol);
    EXPECT_LE((h.point - Vec3(0.2, y, -0.1)).norm(), kTol);
  }
  {
    const Box b(Vec3(1, 2, 3));
    const RayHit h = raycast(b, Pose(), o, d);
    ASSERT_TRUE(h.hit);
    EXPECT_NEAR(h.distance, 1.5, kTol);
    EXPECT_LE((h.normal - Vec3::UnitY()).norm(), kTol);
  }
  {
    // Capsule along y: the ray along -y hits the top hemisphere.
    const Capsule c(0.5, 1);
    const RayHit h = raycast(c, Pose(), o, d);
    ASSERT_TRUE(h.hit);
    const Real y = 1 + std::sqrt(0.25 - 0.04 - 0.01);
    EXPECT_NEAR(h.distance, (5 - y) / 2, kTol);
    EXPECT_LE((h.normal - Vec3(0.2, y - 1, -0.1) / 0.5).norm(), kTol);
    // From the side: hits the cylindrical part.
    const RayHit s = raycast(c, Pose(), Vec3(3, 0.7, 0), Vec3(-1, 0, 0));
    ASSERT_TRUE(s.hit);
    EXPECT_NEAR(s.distance, 2.5, kTol);
    EXPECT_LE((s.normal - Vec3::UnitX()).norm(), kTol);
  }
  {
    const Cylinder c(0.5, 1);
    RayHit h = raycast(c, Pose(), o, d);
    ASSERT_TRUE(h.hit);
    EXPECT_NEAR(h.distance, 2, kTol);  // the top cap at y = 1
    EXPECT_LE((h.normal - Vec3::UnitY()).norm(), kTol);
    h = raycast(c, Pose(), Vec3(3, 0.7, 0.3), Vec3(-1, 0, 0));
    ASSERT_TRUE(h.hit);
    EXPECT_NEAR(h.distance, 3 - 0.4, kTol);
    EXPECT_LE((h.normal - Vec3(0.8, 0, 0.6)).norm(), kTol);
    EXPECT_FALSE(raycast(c, Pose(), Vec3(3, 1.2, 0), Vec3(-1, 0, 0)).hit);
  }
  {
    const Plane p(Vec3(0, 1, 0), 1);
    const RayHit h = raycast(p, Pose(), o, d);
    ASSERT_TRUE(h.hit);
    EXPECT_NEAR(h.distance, 2, kTol);
    EXPECT_FALSE(raycast(p, Pose(), o, -d).hit);
  }
  {
    // Regular octahedron |x| + |y| + |z| <= 1: hit at y = 1 - 0.2 - 0.1.
    const ConvexHull h({Vec3(1, 0, 0), Vec3(-1, 0, 0), Vec3(0, 1, 0), Vec3(0, -1, 0), Vec3(0, 0, 1),
                        Vec3(0, 0, -1)});
    const RayHit r = raycast(h, Pose(), o, d);
    ASSERT_TRUE(r.hit);
    EXPECT_NEAR(r.distance, (5 - 0.7) / 2, kTol);
    EXPECT_LE((r.normal - Vec3(1, 1, -1).normalized()).norm(), kTol);
  }
}

TEST(Raycast, InsideMissMaxDistanceAndValidation) {
  const Box b(Vec3(1, 1, 1));
  RayHit h = raycast(b, Pose(), Vec3(0.5, 0, 0), Vec3(1, 0, 0));
  EXPECT_TRUE(h.hit);
  EXPECT_EQ(h.distance, 0);
  EXPECT_TRUE(h.normal.isZero());
  EXPECT_FALSE(raycast(b, Pose(), Vec3(5, 0, 0), Vec3(1, 0, 0)).hit);      // pointing away
  EXPECT_FALSE(raycast(b, Pose(), Vec3(5, 0, 0), Vec3(-1, 0, 0), 3.9).hit);  // too short
  EXPECT_TRUE(raycast(b, Pose(), Vec3(5, 0, 0), Vec3(-1, 0, 0), 4.0).hit);
  EXPECT_NE(message_of([&] { raycast(b, Pose(), Vec3::Zero(), Vec3::Zero()); }).find("direction"),
            std::string::npos);
  EXPECT_NE(message_of([&] { raycast(b, Pose(), Vec3::Zero(), Vec3(kInf, 0, 0)); }).find("direction"),
            std::string::npos);
  EXPECT_NE(message_of([&] { raycast(b, Pose(), Vec3(NAN, 0, 0), Vec3(1, 0, 0)); }).find("origin"),
            std::string::npos);
  EXPECT_NE(message_of([&] { raycast(b, Pose(), Vec3::Zero(), Vec3(1, 0, 0), -1); }).find("max_distance"),
            std::string::npos);
}

TEST(Raycast, FarFromOriginCompoundAndMesh) {
  const Vec3 far(-1e4, 1e4, 1e4);
  const Quat q = axis_angle(Vec3(1, 0, 1), 0.7);
  const Pose pose(far, q);
  const Box b(Vec3(1, 2, 3));
  // Ray from 10 m along the box's local +x axis towards its centre.
  const Vec3 o = pose.transform_point(Vec3(10, 0.5, 0.5));
  const Vec3 d = q * Vec3(-1, 0, 0);
  RayHit h = raycast(b, pose, o, d);
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.distance, 9, kFarTol);
  EXPECT_LE((h.normal - q * Vec3::UnitX()).norm(), 1e-12);
  EXPECT_LE((h.point - pose.transform_point(Vec3(1, 0.5, 0.5))).norm(), kFarTol);
  // Compound: the nearer child wins and is reported.
  auto s = std::make_shared<Sphere>(0.5);
  const Compound c({{s, Pose(Vec3(-2, 0, 0))}, {s, Pose(Vec3(2, 0, 0))}});
  h = raycast(c, Pose(Vec3(0, 0, 1)), Vec3(10, 0, 1), Vec3(-1, 0, 0));
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.distance, 7.5, kTol);
  EXPECT_EQ(h.child, 1);
  // Mesh: the floor, hit from above and (two-sided) from below.
  const TriangleMesh floor = make_floor();
  h = raycast(floor, Pose(Vec3(0, 0, 2)), Vec3(0.3, 0.4, 5), Vec3(0, 0, -1));
  ASSERT_TRUE(h.hit);
  EXPECT_NEAR(h.distance, 3, kTol);
  EXPECT_LE((h.normal - Vec3::UnitZ()).norm(), kTol);
  EXPECT_GE(h.child, 0);
}

// Random rays cross-checked between independent methods: analytic capsule / cylinder
// / sphere versus the GJK ray cast on the same support map, and hull clipping versus
// box slabs for a box-shaped hull.
TEST(Raycast, RandomRaysAgreeAcrossMethods) {
  std::mt19937 rng(99);
  std::normal_distribution<Real> g(0, 1);
  const Capsule cap(0.4, 0.8);
  const Cylinder cyl(0.6, 0.5);
  const Box box(Vec3(0.5, 0.8, 1.1));
  std::vector<Vec3> corners;
  for (int i = 0; i < 8; ++i)
    corners.emplace_back((i & 1 ? 0.5 : -0.5), (i & 2 ? 0.8 : -0.8), (i & 4 ? 1.1 : -1.1));
  const ConvexHull hull(corners);
  int hits = 0;
  for (int i = 0; i < 2000; ++i) {
    const Vec3 o = 3 * Vec3(g(rng), g(rng), g(rng));
    // Aim near the origin so that about half the rays hit.
    const Vec3 d = (Vec3(g(rng), g(rng), g(rng)) * 0.6 - o);
    // On curved surfaces the GJK ray cast ends within ~1e-9 of the scene size of the
    // surface along its normal (gjk.h: its simplex degenerates once support points
    // cluster within round-off; 5e-9 m worst case seen over 20000 such rays). So compare
    // the error along the normal, |t_a - t_g| |d . n| (grazing rays amplify the error
    // in t alone), against 2e-8 m.
    const auto normal_error = [&](const RayHit& a, const RayHit& b) {
      return std::abs(a.distance - b.distance) * std::abs(a.normal.dot(d));
    };
    const RayHit a = raycast(cap, Pose(), o, d);
    const RayHit ga = gjk_raycast(FullSupport<Capsule>(cap), o, d, kInf);
    ASSERT_EQ(a.hit, ga.hit) << i;
    if (a.hit) EXPECT_LE(normal_error(a, ga), 2e-8) << i;
    const RayHit c = raycast(cyl, Pose(), o, d);
    const RayHit gc = gjk_raycast(CoreSupport<Cylinder>(cyl), o, d, kInf);
    // Rays grazing the rim can differ by round-off in hit / miss: compare clear cases.
    if (c.hit && gc.hit) EXPECT_LE(normal_error(c, gc), 2e-8) << i;
    const RayHit hb = raycast(box, Pose(), o, d);
    const RayHit hh = raycast(hull, Pose(), o, d);
    ASSERT_EQ(hb.hit, hh.hit) << i;
    if (hb.hit) {
      ++hits;
      EXPECT_NEAR(hb.distance, hh.distance, kTol) << i;
      if (hb.distance > 0) EXPECT_LE((hb.normal - hh.normal).norm(), kTol) << i;
    }
  }
  EXPECT_GT(hits, 300);
}

// ---- Time of impact (conservative advancement; ToiSettings in queries.h) ----

TEST(TimeOfImpact, SpheresClosingHeadOnMatchTheClosedForm) {
  // Far from the origin too: the distance query runs in A's frame.
  for (const Real base : {0.0, 1e4}) {
    const Sphere s(0.05);
    Motion a, b;
    a.start = Pose(Vec3(base - 1, 0, 0));
    b.start = Pose(Vec3(base + 1, 0, 0));
    a.linear_velocity = Vec3(300, 0, 0);
    b.linear_velocity = Vec3(-300, 0, 0);
    const ToiResult r = time_of_impact(s, a, s, b, 1.0 / 60);
    const Real t_true = (2 - 0.1) / 600;
    ASSERT_TRUE(r.hit);
    EXPECT_EQ(r.status, QueryStatus::kOk);
    EXPECT_LE(r.time, t_true);
    EXPECT_GE(r.time, t_true - ToiSettings{}.tolerance / 600 - 1e-12);
    EXPECT_LE(r.distance, ToiSettings{}.tolerance);
    EXPECT_NEAR(r.normal.x(), 1.0, 1e-12);
  }
}

TEST(TimeOfImpact, SpinningRodStopsBeforeTheWallNeverAfter) {
  // Rod corner (1, 0.01) reaches the wall face y = 0.5 at sin(w t) + 0.01 cos(w t) = 0.5.
  const Box rod(Vec3(1.0, 0.01, 0.01)), wall(Vec3(2, 0.05, 2));
  Motion a, b;
  a.angular_velocity = Vec3(0, 0, 100);
  b.start = Pose(Vec3(0, 0.55, 0));
  const Real t_true = (std::asin(0.5 / std::hypot(1.0, 0.01)) - std::atan2(0.01, 1.0)) / 100;
  const ToiResult r = time_of_impact(rod, a, wall, b, 1.0 / 60);
  ASSERT_TRUE(r.hit);
  EXPECT_LE(r.time, t_true);
  EXPECT_GE(r.time, t_true - 1e-5);
  // Before the reported time the rod is clear of the wall (sampled).
  for (int k = 0; k < 200; ++k) {
    const Real t = r.time * k / 200;
    EXPECT_FALSE(intersect(rod, a.at(t), wall, b.at(t))) << t;
  }
  // Without the rotation bound the step would not be conservative: the end pose is
  // deep in the wall, so a start/end check sees an overlap, never the first touch.
  EXPECT_TRUE(intersect(rod, a.at(1.0 / 60), wall, b.at(1.0 / 60)));
}

TEST(TimeOfImpact, MissesOverlapsAndBadInput) {
  const Sphere s(0.5);
  Motion a, b;
  b.start = Pose(Vec3(2, 0, 0));
  a.linear_velocity = Vec3(-1, 0, 0);  // moving apart
  EXPECT_FALSE(time_of_impact(s, a, s, b, 1.0).hit);
  b.start = Pose(Vec3(0.5, 0, 0));
  const ToiResult o = time_of_impact(s, a, s, b, 1.0);
  EXPECT_TRUE(o.hit && o.initially_overlapping);
  EXPECT_EQ(o.time, 0);
  EXPECT_THROW(time_of_impact(s, a, s, b, -1.0), InvalidArgument);
  a.linear_velocity = Vec3(std::nan(""), 0, 0);
  EXPECT_THROW(time_of_impact(s, a, s, b, 1.0), InvalidArgument);
  // A turning plane has no finite rotation bound.
  Motion p;
  p.angular_velocity = Vec3(1, 0, 0);
  Motion m;
  m.start = Pose(Vec3(0, 1, 0));
  EXPECT_EQ(time_of_impact(s, m, Plane(Vec3(0, 1, 0), 0), p, 1.0).status, QueryStatus::kUnsupported);
}

TEST(TimeOfImpact, DeepenAllowanceIsPerTriangle) {
  // A 3 mm plate resting 5 mm into a floor triangle slides at 30 m/s towards a wall
  // triangle of the same mesh, 0.7 m ahead of its front face. With deepen_allowance the
  // floor's start overlap lets the plate deepen that overlap by the allowance, and
  // nothing else: the wall, which the plate starts apart from, stops it within the
  // target (2e-4 m) of touching. Taking the mesh's deepest start overlap as everyone's
  // target (the world's CCD before, scripts/fuzz_worlds.py seed 1089) lets the plate
  // 5 mm into the wall, more than its thickness.
  const TriangleMesh mesh({Vec3(-3, 0, -3), Vec3(-3, 0, 3), Vec3(0.9, 0, 0), Vec3(1, -1, -2), Vec3(1, -1, 2),
                           Vec3(1, 2, 0)},
                          {{0, 1, 2}, {3, 5, 4}});
  const Box plate(Vec3(0.3, 0.0015, 0.3));
  Motion a, m;
  a.start = Pose(Vec3(0, 0.0015 - 0.005, 0));
  a.linear_velocity = Vec3(30, 0, 0);
  ToiSettings st;
  st.tolerance = 1e-4;
  st.target_distance = -2e-4;
  st.deepen_allowance = 1e-4;
  const ToiResult r = time_of_impact(plate, a, mesh, m, 1.0 / 30, st);
  ASSERT_TRUE(r.hit);
  EXPECT_EQ(r.status, QueryStatus::kOk);
  const Real touch = 0.7 / 30;  // the front face reaches x = 1
  EXPECT_LE(r.time, touch + (2e-4 + 1e-12) / 30);
  EXPECT_GE(r.time, touch - 1e-3 / 30);
  // At the reported time the plate is in the wall by at most the target.
  const Pose at = a.at(r.time);
  const Real wall_overlap = at.position.x() + 0.3 - 1;
  EXPECT_LE(wall_overlap, 2e-4 + st.tolerance);
  // The old rule: the mesh's deepest start overlap (5 mm, the floor's) less the
  // allowance as the target for every triangle.
  ToiSettings global = st;
  global.deepen_allowance = -1;
  global.target_distance = -0.005 - 1e-4;
  const ToiResult g = time_of_impact(plate, a, mesh, m, 1.0 / 30, global);
  ASSERT_TRUE(g.hit);
  EXPECT_GT(a.at(g.time).position.x() + 0.3 - 1, 0.0045);
  // A convex pair: the same as a second search from the start depth.
  const Box floor(Vec3(3, 0.5, 3));
  Motion f;
  f.start = Pose(Vec3(0, -0.5, 0));
  Motion down = a;
  down.linear_velocity = Vec3(0, -0.3, 0);
  const ToiResult c = time_of_impact(plate, down, floor, f, 1.0 / 30, st);
  ASSERT_TRUE(c.hit);
  EXPECT_TRUE(c.initially_overlapping);
  EXPECT_NEAR(c.distance, -0.005 - 1e-4, st.tolerance);
  ToiSettings second = global;
  second.target_distance = -0.005 - 1e-4;
  const ToiResult c2 = time_of_impact(plate, down, floor, f, 1.0 / 30, second);
  EXPECT_EQ(c.time, c2.time);
}

TEST(TimeOfImpact, ParallelSkipLeavesTheTrianglesABodySlidesAlong) {
  // A 1 cm plate resting 0.1 mm into a flat two-triangle floor slides 8 cm along it and
  // tilts by 1e-3 rad about the slide's cross axis (its front edge 0.2 mm deeper at the
  // end). Searched with a target of 0.125 mm the floor stops it part of the way;
  // with parallel_skip (1.25 mm: no point of the plate comes more than 0.2 mm closer to
  // the floor's plane, and its centre stays 4.9 mm above it) the floor is left alone.
  // A wall triangle ahead, which the plate runs into, is searched all the same.
  const Box plate(Vec3(0.2, 0.005, 0.2));
  ToiSettings st;
  st.tolerance = 3e-5;
  st.target_distance = -1.25e-4;
  Motion a, m;
  a.start = Pose(Vec3(0, 0.005 - 1e-4, 0));
  a.linear_velocity = Vec3(4.8, 0, 0);
  a.angular_velocity = Vec3(0, 0, -0.06);  // 1e-3 rad in 1/60 s
  const Real dt = 1.0 / 60;
  const TriangleMesh floor({Vec3(-3, 0, -3), Vec3(-3, 0, 3), Vec3(3, 0, 3), Vec3(3, 0, -3)}, {{0, 1, 2}, {0, 2, 3}});
  const ToiResult searched = time_of_impact(plate, a, floor, m, dt, st);
  ASSERT_TRUE(searched.hit);
  EXPECT_LT(searched.time, dt);
  ToiSettings skip = st;
  skip.parallel_skip = 1.25e-3;
  EXPECT_FALSE(time_of_impact(plate, a, floor, m, dt, skip).hit);
  // The floor and a wall at x = 0.25 (the plate's front face starts at 0.2).
  const TriangleMesh walled({Vec3(-3, 0, -3), Vec3(-3, 0, 3), Vec3(3, 0, 3), Vec3(3, 0, -3), Vec3(0.25, -1, -2),
                             Vec3(0.25, -1, 2), Vec3(0.25, 2, 0)},
                            {{0, 1, 2}, {0, 2, 3}, {4, 6, 5}});
  const ToiResult wall = time_of_impact(plate, a, walled, m, dt, skip);
  ASSERT_TRUE(wall.hit);
  EXPECT_NEAR(wall.time, 0.05 / 4.8, 2e-4);
  EXPECT_NEAR(std::abs(wall.normal.x()), 1.0, 1e-3);
}

}  // namespace
}  // namespace wmo
