// Checks of the narrowphase dispatcher collide() (dispatch.cpp): which pairs are
// supported, world-frame results, mirror symmetry, composite shapes, far-from-origin
// precision and the generic path (use_special_routines = false).

#include <gtest/gtest.h>

#include <cmath>
#include <memory>
#include <random>
#include <vector>

#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

// Exact closed forms on O(1) inputs lose a few ulps per rotation and per frame change;
// 1e-12 (~5000 ulps of a metre) is far above that.
constexpr Real kTol = 1e-12;
// A pose 1e4 m from the origin carries 1e4 * 2.2e-16 ~ 2e-12 m of round-off per
// operation; 1e-9 m leaves a few hundred operations of headroom and is still far
// below the 1e-6 relative (1e-2 m at 1e4 m) that a naive world-frame routine would miss.
constexpr Real kFarTol = 1e-9;

Quat axis_angle(Real angle, const Vec3& axis) {
  return Quat(Eigen::AngleAxisd(angle, axis.normalized()));
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

std::vector<Manifold> run(const Shape& a, const Pose& pa, const Shape& b, const Pose& pb,
                          const CollideSettings& s = {}, QueryStatus expect = QueryStatus::kOk) {
  std::vector<Manifold> out;
  EXPECT_EQ(collide(a, pa, b, pb, out, s), expect);
  return out;
}

/// Every manifold point obeys types.h in the world frame.
void check_conventions(const std::vector<Manifold>& out, Real tol = kTol) {
  for (const Manifold& m : out) {
    EXPECT_NEAR(m.normal.norm(), 1.0, tol);
    for (int i = 0; i < m.count; ++i) {
      const ContactPoint& c = m.points[i];
      EXPECT_TRUE(c.point_a.allFinite() && c.point_b.allFinite() && std::isfinite(c.depth));
      EXPECT_LT((c.point_b - (c.point_a - c.depth * m.normal)).norm(), tol);
    }
  }
}

/// m2 = collide(b, a) must mirror m1 = collide(a, b): same depths, normal negated,
/// point_a and point_b swapped, child ids swapped. Points are matched by position, as
/// the two directions may list them in different orders.
void expect_mirrored(const Manifold& m1, const Manifold& m2, Real tol) {
  ASSERT_EQ(m1.count, m2.count);
  EXPECT_LT((m1.normal + m2.normal).norm(), tol);
  EXPECT_EQ(m1.child_a, m2.child_b);
  EXPECT_EQ(m1.child_b, m2.child_a);
  for (int i = 0; i < m1.count; ++i) {
    bool found = false;
    for (int j = 0; j < m2.count && !found; ++j) {
      found = (m1.points[i].point_a - m2.points[j].point_b).norm() < tol &&
              (m1.points[i].point_b - m2.points[j].point_a).norm() < tol &&
              std::abs(m1.points[i].depth - m2.points[j].depth) < tol;
    }
    EXPECT_TRUE(found) << "point " << i << " has no mirror";
  }
}

// ---------------------------------------------------------------- the table

TEST(Dispatch, SupportedPairs) {
  constexpr int n = static_cast<int>(ShapeType::kCount);
  for (int i = 0; i < n; ++i) {
    for (int j = 0; j < n; ++j) {
      const auto a = static_cast<ShapeType>(i), b = static_cast<ShapeType>(j);
      const bool static_pair = (a == ShapeType::kPlane || a == ShapeType::kTriangleMesh) &&
                               (b == ShapeType::kPlane || b == ShapeType::kTriangleMesh);
      EXPECT_EQ(collide_supported(a, b), !static_pair) << to_string(a) << "-" << to_string(b);
    }
  }
  EXPECT_FALSE(collide_supported(ShapeType::kCount, ShapeType::kSphere));
}

TEST(Dispatch, PlanePlaneIsUnsupportedAndAppendsNothing) {
  Plane p1(Vec3::UnitY(), 0), p2(Vec3(0, -1, 0), 0);
  std::vector<Manifold> out(1);
  out[0].count = 3;  // an earlier manifold: must survive untouched
  EXPECT_EQ(collide(p1, Pose(), p2, Pose(), out), QueryStatus::kUnsupported);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].count, 3);
}

TEST(Dispatch, MeshPairsWithStaticShapesAreUnsupported) {
  auto mesh = std::make_shared<TriangleMesh>(
      std::vector<Vec3>{Vec3(-1, 0, -1), Vec3(1, 0, -1), Vec3(0, 0, 1)},
      std::vector<std::array<int, 3>>{{0, 2, 1}});
  Plane plane(Vec3::UnitY(), 0);
  run(*mesh, Pose(), *mesh, Pose(), {}, QueryStatus::kUnsupported);
  run(*mesh, Pose(), plane, Pose(), {}, QueryStatus::kUnsupported);
  const auto out = run(plane, Pose(), *mesh, Pose(), {}, QueryStatus::kUnsupported);
  EXPECT_TRUE(out.empty());
}

// ---------------------------------------------------------------- world frame

TEST(Dispatch, SphereSphereWorldFrame) {
  Sphere a(1.0), b(0.5);
  const Pose pa(Vec3(2, 3, 4), axis_angle(0.8, Vec3(1, 0, 1)));
  const Vec3 dir = Vec3(1, 2, -2) / 3;  // unit
  const Pose pb(pa.position + 1.4 * dir, axis_angle(-1.1, Vec3(0, 1, 1)));
  const auto out = run(a, pa, b, pb);
  ASSERT_EQ(out.size(), 1u);
  const Manifold& m = out[0];
  ASSERT_EQ(m.count, 1);
  EXPECT_LT((m.normal - dir).norm(), kTol);
  EXPECT_NEAR(m.points[0].depth, 0.1, kTol);
  EXPECT_LT((m.points[0].point_a - (pa.position + dir)).norm(), kTol);
  EXPECT_LT((m.points[0].point_b - (pb.position - 0.5 * dir)).norm(), kTol);
  EXPECT_EQ(m.child_a, -1);
  EXPECT_EQ(m.child_b, -1);
}

TEST(Dispatch, SwappedRoutineIsFlipped) {
  // Box-sphere has no routine of its own: it runs sphere-box and flips.
  Box box(Vec3(1, 0.5, 2));
  Sphere s(0.3);
  const Pose pbox(Vec3(1, 0, 0), axis_angle(0.3, Vec3::UnitZ()));
  const Pose ps(pbox.transform_point(Vec3(0.2, 0.7, 0.1)));  // 0.1 deep into the +y face
  const auto out = run(box, pbox, s, ps);
  ASSERT_EQ(out.size(), 1u);
  EXPECT_NEAR(out[0].points[0].depth, 0.1, kTol);
  // From the box (A) to the sphere (B): the box's +y face normal.
  EXPECT_LT((out[0].normal - pbox.rotation * Vec3::UnitY()).norm(), kTol);
  // point_a on the box's face, point_b on the sphere.
  EXPECT_NEAR(pbox.inverse_transform_point(out[0].points[0].point_a).y(), 0.5, kTol);
  EXPECT_NEAR((out[0].points[0].point_b - ps.position).norm(), 0.3, kTol);
  check_conventions(out);
}

// ---------------------------------------------------------------- mirror symmetry

TEST(Dispatch, MirrorSymmetry) {
  std::mt19937 rng(21);
  auto sphere = std::make_shared<Sphere>(0.4);
  auto box = std::make_shared<Box>(Vec3(0.5, 0.3, 0.4), 0.05);
  auto capsule = std::make_shared<Capsule>(0.2, 0.4);
  const std::vector<std::shared_ptr<const ConvexShape>> shapes{sphere, box, capsule};
  int compared = 0;
  for (int i = 0; i < 300; ++i) {
    const auto& a = shapes[i % 3];
    const auto& b = shapes[(i / 3) % 3];
    // Box-box clips B's face against A's reference face: swapping A and B may pick the
    // other reference face, a different but valid manifold. Not a mirror pair.
    if (a == box && b == box) continue;
    const Pose pa(random_vec(rng, 5), random_rotation(rng));
    const Pose pb(pa.position + random_vec(rng, 0.8), random_rotation(rng));
    const auto ab = run(*a, pa, *b, pb);
    const auto ba = run(*b, pb, *a, pa);
    ASSERT_EQ(ab.size(), ba.size()) << i;
    if (ab.empty()) continue;
    // Capsule-capsule in exactly parallel poses could pick different but equally valid
    // point pairs; random poses are never parallel. Mirrored results go through two
    // different frames (A's and B's), hence a few ulps more than kTol.
    expect_mirrored(ab[0], ba[0], 1e-10);
    ++compared;
  }
  EXPECT_GT(compared, 100);
}

TEST(Dispatch, PlaneConvexMirror) {
  Plane plane(Vec3(0, 1, 0), 0.5);
  Box box(Vec3(1, 0.5, 2));
  const Pose pplane(Vec3(0, -1, 0), axis_angle(0.2, Vec3::UnitX()));
  const Pose pbox(pplane.transform_point(Vec3(0, 0.99, 0)), pplane.rotation);
  const auto ab = run(plane, pplane, box, pbox);
  const auto ba = run(box, pbox, plane, pplane);
  ASSERT_EQ(ab.size(), 1u);
  ASSERT_EQ(ab[0].count, 4);  // box resting on the plane: 4 corners
  for (int i = 0; i < 4; ++i) EXPECT_NEAR(ab[0].points[i].depth, 0.01, kTol);
  ASSERT_EQ(ba.size(), 1u);
  expect_mirrored(ab[0], ba[0], kTol);
  check_conventions(ab);
}

// ---------------------------------------------------------------- far from the origin

TEST(Dispatch, FarFromOriginMatchesOrigin) {
  std::mt19937 rng(4);
  auto sphere = std::make_shared<Sphere>(0.4);
  auto box = std::make_shared<Box>(Vec3(0.5, 0.3, 0.4), 0.05);
  auto capsule = std::make_shared<Capsule>(0.2, 0.4);
  auto plane = std::make_shared<Plane>(Vec3(0.1, 1, 0).normalized(), 0.2);
  const std::vector<std::shared_ptr<const Shape>> as{sphere, box, capsule, plane};
  const std::vector<std::shared_ptr<const Shape>> bs{sphere, box, capsule};
  const Vec3 far(1e4, -1e4, 1e4);
  int compared = 0;
  for (int i = 0; i < 120; ++i) {
    const Shape& a = *as[i % 4];
    const Shape& b = *bs[(i / 4) % 3];
    const Pose pa(random_vec(rng, 1), random_rotation(rng));
    const Pose pb(pa.position + random_vec(rng, 0.8), random_rotation(rng));
    const auto near_out = run(a, pa, b, pb);
    const auto far_out = run(a, Pose(pa.position + far, pa.rotation), b,
                             Pose(pb.position + far, pb.rotation));
    ASSERT_EQ(near_out.size(), far_out.size()) << i;
    if (near_out.empty()) continue;
    const Manifold& m1 = near_out[0];
    const Manifold& m2 = far_out[0];
    ASSERT_EQ(m1.count, m2.count) << i;
    EXPECT_LT((m1.normal - m2.normal).norm(), kFarTol) << i;
    for (int k = 0; k < m1.count; ++k) {
      EXPECT_NEAR(m1.points[k].depth, m2.points[k].depth, kFarTol) << i;
      EXPECT_LT((m1.points[k].point_a + far - m2.points[k].point_a).norm(), kFarTol) << i;
      EXPECT_LT((m1.points[k].point_b + far - m2.points[k].point_b).norm(), kFarTol) << i;
      EXPECT_EQ(m1.points[k].feature_id, m2.points[k].feature_id) << i;
    }
    ++compared;
  }
  EXPECT_GT(compared, 40);
}

// ---------------------------------------------------------------- composites

TEST(Dispatch, CompoundChildrenAgainstPlane) {
  auto s = std::make_shared<Sphere>(0.5);
  // Two spheres 0.1 deep into the ground, a third 3 m up (culled by its bounding box).
  Compound dumbbell({{s, Pose(Vec3(-1, 0, 0))}, {s, Pose(Vec3(1, 0, 0))},
                     {s, Pose(Vec3(0, 3, 0))}});
  Plane ground(Vec3::UnitY(), 0);
  const Pose pc(Vec3(5, 0.4, 0));
  const auto out = run(dumbbell, pc, ground, Pose());
  ASSERT_EQ(out.size(), 2u);
  for (int i = 0; i < 2; ++i) {
    EXPECT_EQ(out[i].child_a, i);
    EXPECT_EQ(out[i].child_b, -1);
    ASSERT_EQ(out[i].count, 1);
    EXPECT_NEAR(out[i].points[0].depth, 0.1, kTol);
    EXPECT_LT((out[i].normal - Vec3(0, -1, 0)).norm(), kTol);  // compound (A) to ground
  }
  EXPECT_NEAR(out[0].points[0].point_a.x(), 4, kTol);
  EXPECT_NEAR(out[1].points[0].point_a.x(), 6, kTol);
  check_conventions(out);
  // Mirrored: the ground first, children in child_b.
  const auto rev = run(ground, Pose(), dumbbell, pc);
  ASSERT_EQ(rev.size(), 2u);
  for (int i = 0; i < 2; ++i) expect_mirrored(out[i], rev[i], kTol);
}

TEST(Dispatch, CompoundAgainstCompound) {
  auto s = std::make_shared<Sphere>(0.5);
  auto b = std::make_shared<Box>(Vec3(0.5, 0.5, 0.5));
  Compound ca({{s, Pose(Vec3(0, 0, 0))}, {s, Pose(Vec3(0, 5, 0))}});
  Compound cb({{b, Pose(Vec3(0, -5, 0))}, {b, Pose(Vec3(0.9, 0, 0))}});
  const auto out = run(ca, Pose(), cb, Pose());
  ASSERT_EQ(out.size(), 1u);
  EXPECT_EQ(out[0].child_a, 0);
  EXPECT_EQ(out[0].child_b, 1);
  EXPECT_NEAR(out[0].points[0].depth, 0.1, kTol);
  EXPECT_LT((out[0].normal - Vec3::UnitX()).norm(), kTol);
}

TEST(Dispatch, MeshConvexChildIds) {
  // One ground triangle (normal +y) and a sphere resting 0.05 deep on it.
  TriangleMesh mesh({Vec3(-2, 0, -2), Vec3(2, 0, -2), Vec3(0, 0, 2)}, {{0, 2, 1}});
  ASSERT_GT(mesh.triangle_normal(0).y(), 0.99);
  Sphere s(0.5);
  const Pose ps(Vec3(0, 0.45, 0));
  const auto ms = run(mesh, Pose(), s, ps);
  ASSERT_EQ(ms.size(), 1u);
  EXPECT_EQ(ms[0].child_a, 0);
  EXPECT_EQ(ms[0].child_b, -1);
  // 1e-9: the mesh routine may use GJK/EPA, which converges to its own tolerance.
  EXPECT_NEAR(ms[0].max_depth(), 0.05, 1e-9);
  EXPECT_LT((ms[0].normal - Vec3::UnitY()).norm(), 1e-9);
  const auto sm = run(s, ps, mesh, Pose());
  ASSERT_EQ(sm.size(), 1u);
  expect_mirrored(ms[0], sm[0], kTol);
}

// ---------------------------------------------------------------- generic path

/// Overlap of the world-placed convex shapes' projections on the unit direction n
/// (from A to B): the translation of B along n that separates them.
Real overlap_along(const ConvexShape& a, const Pose& pa, const ConvexShape& b, const Pose& pb,
                   const Vec3& n) {
  const Real ha = pa.transform_point(a.support(pa.inverse_transform_vector(n))).dot(n);
  const Real lb = pb.transform_point(b.support(pb.inverse_transform_vector(-n))).dot(n);
  return ha - lb;
}

TEST(Dispatch, GenericPathAgreesWithSpecialRoutines) {
  // use_special_routines = false sends every convex pair to collide_convex_convex
  // (GJK/EPA + clipping). Both must find a minimum-translation normal: EPA's is the
  // minimum (to its tolerance), the special routines' at most their face bias (1% +
  // 10 um) worse. For sphere pairs (one exact point) the depths must also agree.
  std::mt19937 rng(17);
  auto sphere = std::make_shared<Sphere>(0.4);
  auto box = std::make_shared<Box>(Vec3(0.5, 0.3, 0.4));
  auto capsule = std::make_shared<Capsule>(0.2, 0.4);
  const std::vector<std::shared_ptr<const ConvexShape>> shapes{sphere, box, capsule};
  CollideSettings generic;
  generic.use_special_routines = false;
  int compared = 0;
  for (int i = 0; i < 90; ++i) {
    const auto& a = shapes[i % 3];
    const auto& b = shapes[(i / 3) % 3];
    const Pose pa(random_vec(rng, 2), random_rotation(rng));
    const Pose pb(pa.position + random_vec(rng, 0.7), random_rotation(rng));
    const auto fast = run(*a, pa, *b, pb);
    const auto slow = run(*a, pa, *b, pb, generic);
    // Near-touching pairs may fall on either side of the boundary in the two methods.
    if (fast.empty() || slow.empty()) continue;
    check_conventions(slow, 1e-9);
    // 1e-6 m: EPA stops within 1e-10 relative of the depth (EpaSettings), GJK on curved
    // cores within its own tolerance; 1e-6 m absorbs both with a wide margin.
    const Real d_fast = overlap_along(*a, pa, *b, pb, fast[0].normal);
    const Real d_slow = overlap_along(*a, pa, *b, pb, slow[0].normal);
    EXPECT_LE(d_slow, d_fast + 1e-6) << i;
    // The special routines prefer face axes: capsule-box accepts an edge axis only if it
    // beats the face by 1% + 10 um; box-box (collide_box_box, clip.h kSatRelTolerance /
    // kSatAbsTolerance, as Box2D's polygon collider) by 5% + 1e-5 * size.
    const bool box_box = (a == box && b == box);
    const Real rel = box_box ? 0.95 : 0.99;
    // collide_box_box's size is the largest half extent, 0.5 m here.
    const Real abs_tol = box_box ? 1e-5 * 0.5 : 1e-5;
    EXPECT_LE(d_fast, (d_slow + abs_tol) / rel + 1e-6) << i;
    if (a == sphere || b == sphere) {
      EXPECT_NEAR(fast[0].max_depth(), slow[0].max_depth(), 1e-6) << i;
      EXPECT_LT((fast[0].normal - slow[0].normal).norm(), 1e-5) << i;
    }
    ++compared;
  }
  EXPECT_GT(compared, 30);
}

}  // namespace
}  // namespace wmo
