// Triangle mesh against convex shapes: contacts, internal-edge handling, convex edges,
// feature ids, and no heap allocation per query.
#include <gtest/gtest.h>

#include <algorithm>

#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <set>
#include <vector>

#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/mesh_bvh.h"
#include "wmo/geometry/shapes.h"

// Allocation counter for the no-allocation test: every operator new of this test
// executable goes through here.
namespace {
std::atomic<long> g_allocations{0};
}
void* operator new(std::size_t n) {
  ++g_allocations;
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new(std::size_t n, const std::nothrow_t&) noexcept {
  ++g_allocations;
  return std::malloc(n ? n : 1);
}
void operator delete(void* p) noexcept { std::free(p); }
void operator delete(void* p, const std::nothrow_t&) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }

namespace wmo {
namespace {

using Tris = std::vector<std::array<int, 3>>;

// Two grid triangles per quad of size `cell`, CCW seen from +z, in the plane z = o.z.
TriangleMesh make_grid(int n, Real cell, const Vec3& o, bool one_sided = false) {
  std::vector<Vec3> v;
  Tris t;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) v.push_back(o + Vec3(i * cell, j * cell, 0));
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      t.push_back({a, b, c});
      t.push_back({a, c, d});
    }
  return TriangleMesh(v, t, one_sided);
}

// Cube [-1, 1]^3 as 12 outward CCW triangles.
TriangleMesh make_cube() {
  std::vector<Vec3> v;
  for (int k = 0; k < 8; ++k) v.emplace_back(k & 1 ? 1 : -1, k & 2 ? 1 : -1, k & 4 ? 1 : -1);
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  Tris t;
  for (const auto& q : quads) {
    t.push_back({q[0], q[1], q[2]});
    t.push_back({q[0], q[2], q[3]});
  }
  return TriangleMesh(v, t);
}

std::vector<Manifold> collide(const TriangleMesh& m, const ConvexShape& b, const Pose& b_in_m,
                              bool remove_internal = true, Real margin = 0) {
  CollideSettings s;
  s.remove_internal_edges = remove_internal;
  s.margin = margin;
  std::vector<Manifold> out;
  collide_mesh_convex(m, b, b_in_m, s, out);
  return out;
}

// Convention checks that hold for every manifold (types.h).
void check_manifold(const Manifold& m, const TriangleMesh& mesh) {
  ASSERT_GE(m.child_a, 0);
  ASSERT_LT(m.child_a, static_cast<int>(mesh.triangles().size()));
  EXPECT_NEAR(m.normal.norm(), 1, 1e-12);
  ASSERT_GT(m.count, 0);
  ASSERT_LE(m.count, kMaxManifoldPoints);
  for (int i = 0; i < m.count; ++i) {
    const ContactPoint& p = m.points[i];
    EXPECT_TRUE(p.point_a.allFinite() && p.point_b.allFinite());
    // point_b = point_a - depth * normal, to round-off of the coordinates (1e-9 m covers
    // coordinates up to ~1e4 m).
    EXPECT_LT((p.point_b - (p.point_a - p.depth * m.normal)).norm(), 1e-9);
  }
}

// Largest angle (rad) between a manifold normal and `n` over all manifolds.
Real max_angle(const std::vector<Manifold>& ms, const Vec3& n) {
  Real a = 0;
  for (const Manifold& m : ms) a = std::max(a, std::acos(std::clamp(m.normal.dot(n), -1.0, 1.0)));
  return a;
}

TEST(CollideMesh, SphereRestingOnFlatGrid) {
  const TriangleMesh grid = make_grid(8, 0.5, Vec3(-2, -2, 0));
  const Sphere ball(0.5);
  const Real depth = 0.1;
  // Interior of a triangle, on a diagonal, on a grid line, exactly on a grid vertex.
  for (const Vec3& xy : {Vec3(0.1, 0.35, 0), Vec3(0.25, 0.25, 0), Vec3(0.5, 0.2, 0),
                         Vec3(0.5, 0.5, 0), Vec3(0.05, 0.02, 0)}) {
    const Pose pose(xy + Vec3(0, 0, 0.5 - depth));
    const auto ms = collide(grid, ball, pose);
    ASSERT_FALSE(ms.empty());
    for (const Manifold& m : ms) {
      check_manifold(m, grid);
      // The face normal: +z exactly (a snapped normal is the stored face normal).
      EXPECT_EQ(m.normal, Vec3(0, 0, 1));
      ASSERT_EQ(m.count, 1);
      // Analytic depth: r - height. 1e-12: a few operations on O(1) numbers.
      EXPECT_NEAR(m.points[0].depth, depth, 1e-12);
      EXPECT_NEAR((m.points[0].point_a - xy).norm(), 0, 1e-12);
    }
  }
}

TEST(CollideMesh, SphereNearInternalEdgeHasNoGhostContact) {
  // Centre 0.05 m from the diagonal edge of the triangle it is over: the neighbouring
  // triangle is within the radius through that edge, so the raw per-triangle contact
  // leans sideways; with internal-edge handling it is dropped (the sphere is not over it).
  const TriangleMesh grid = make_grid(4, 1.0, Vec3(-2, -2, 0));
  const Sphere ball(0.5);
  const Vec3 c(0.5 + 0.05 / std::sqrt(2.0), 0.5 - 0.05 / std::sqrt(2.0), 0.45);
  const auto fixed = collide(grid, ball, Pose(c));
  ASSERT_EQ(fixed.size(), 1u);
  EXPECT_EQ(fixed[0].normal, Vec3(0, 0, 1));
  EXPECT_NEAR(fixed[0].points[0].depth, 0.05, 1e-12);
  const auto raw = collide(grid, ball, Pose(c), false);
  EXPECT_EQ(raw.size(), 2u);
  EXPECT_GT(max_angle(raw, Vec3::UnitZ()), 0.05);  // the ghost: tilted by ~0.11 rad
}

// Box of half extents h resting on the grid with `pen` penetration, at (x, y), yawed by
// `yaw` about z.
Pose box_pose(Real x, Real y, Real yaw, Real hz, Real pen) {
  return Pose(Vec3(x, y, hz - pen), Quat(Eigen::AngleAxisd(yaw, Vec3::UnitZ())));
}

TEST(CollideMesh, BoxSlidingAcrossFlatGridDoesNotCatchOnInternalEdges) {
  const TriangleMesh grid = make_grid(10, 0.5, Vec3(-2.5, -2.5, 0));
  const Vec3 h(0.4, 0.3, 0.2);
  const Box box(h);
  const Real pen = 0.01;
  int raw_tilted = 0, positions = 0;
  // Slide along x in steps that put the box's faces on grid lines (x = 0.1 + k * 0.05
  // hits x +- 0.4 on multiples of 0.5), 5 mm past them (a sliver overlap thinner than the
  // penetration: the raw contact there escapes sideways), and in between; plus yawed
  // boxes whose corners cross the diagonals.
  for (Real yaw : {0.0, 0.3, kPi / 4}) {
    for (int k = 0; k <= 40; ++k) {
      const Real x = -1 + 0.025 * k + (k % 3 == 1 ? 0.005 : 0);
      const Pose pose = box_pose(x, 0.2, yaw, h.z(), pen);
      const auto ms = collide(grid, box, pose);
      ASSERT_FALSE(ms.empty());
      ++positions;
      Real deepest = -kInf;
      for (const Manifold& m : ms) {
        check_manifold(m, grid);
        EXPECT_EQ(m.normal, Vec3(0, 0, 1)) << "x " << x << " yaw " << yaw;
        for (int i = 0; i < m.count; ++i) {
          // Every point is on the bottom face: depth = pen (1e-12: round-off of O(1)).
          EXPECT_NEAR(m.points[i].depth, pen, 1e-12);
          deepest = std::max(deepest, m.points[i].depth);
        }
      }
      EXPECT_NEAR(deepest, pen, 1e-12);
      // The bottom face's 4 corners each appear in some manifold: the triangles'
      // clipped polygons tile the face, so no corner is lost at a shared edge.
      for (int c = 0; c < 4; ++c) {
        const Vec3 corner =
            pose.transform_point(Vec3(c & 1 ? h.x() : -h.x(), c & 2 ? h.y() : -h.y(), -h.z()));
        bool found = false;
        for (const Manifold& m : ms)
          for (int i = 0; i < m.count; ++i) found = found || (m.points[i].point_b - corner).norm() < 1e-9;
        // Otherwise the corner's triangle clipped a polygon of more than 4 points and the
        // reduction kept 4 others: that manifold must then be full.
        bool reduced = false;
        for (const Manifold& m : ms) {
          const auto& tri = grid.triangles()[m.child_a];
          const Vec3 &a = grid.vertices()[tri[0]], &b = grid.vertices()[tri[1]],
                     &cc = grid.vertices()[tri[2]];
          auto side = [&](const Vec3& p, const Vec3& q) {
            return (q - p).cross(corner - p).z() >= -1e-12;  // 1e-12: on-edge round-off
          };
          if (side(a, b) && side(b, cc) && side(cc, a) && m.count == kMaxManifoldPoints)
            reduced = true;
        }
        EXPECT_TRUE(found || reduced) << "corner " << c << " x " << x << " yaw " << yaw;
      }
      const auto raw = collide(grid, box, pose, false);
      if (max_angle(raw, Vec3::UnitZ()) > 1e-3) ++raw_tilted;
    }
  }
  // The naive per-triangle normals do catch: the test above is not vacuous.
  EXPECT_GT(raw_tilted, positions / 10);
}

TEST(CollideMesh, BoxCornerExactlyOnInternalVertexAndEdge) {
  const TriangleMesh grid = make_grid(6, 0.5, Vec3(-1.5, -1.5, 0));
  const Box box(Vec3(0.3, 0.3, 0.3));
  // Tilt the box so that one corner is lowest: the corner (-h, -h, -h) rotated.
  const Quat q(Eigen::AngleAxisd(0.5, Vec3(1, -1, 0).normalized()));
  const Vec3 corner_local(-0.3, -0.3, -0.3);
  // Find the lowest corner after rotation.
  Vec3 low = corner_local;
  for (int c = 0; c < 8; ++c) {
    const Vec3 p(c & 1 ? 0.3 : -0.3, c & 2 ? 0.3 : -0.3, c & 4 ? 0.3 : -0.3);
    if ((q * p).z() < (q * low).z()) low = p;
  }
  const Real pen = 0.02;
  int raw_tilted = 0;
  // On a grid vertex (0, 0), on a grid line (0.2, 0), on a diagonal (0.25, 0.25).
  for (const Vec3& target : {Vec3(0, 0, -pen), Vec3(0.2, 0, -pen), Vec3(0.25, 0.25, -pen)}) {
    const Pose pose(target - q * low, q);
    const auto ms = collide(grid, box, pose);
    ASSERT_FALSE(ms.empty());
    Real deepest = -kInf;
    for (const Manifold& m : ms) {
      check_manifold(m, grid);
      EXPECT_EQ(m.normal, Vec3(0, 0, 1));
      deepest = std::max(deepest, m.max_depth());
    }
    // The lowest corner's depth below the plane (1e-12: round-off).
    EXPECT_NEAR(deepest, pen, 1e-12);
    if (max_angle(collide(grid, box, pose, false), Vec3::UnitZ()) > 1e-3) ++raw_tilted;
  }
  EXPECT_GT(raw_tilted, 0);  // the raw contacts lean at least once
}

TEST(CollideMesh, ConvexCubeEdgeKeepsEdgeNormal) {
  const TriangleMesh cube = make_cube();
  const Sphere ball(0.5);
  // Centre diagonally off the edge x = 1, z = 1 (the edge between the +x and +z faces).
  const Real d = 0.3;
  const Vec3 c(1 + d, 0.2, 1 + d);
  const auto ms = collide(cube, ball, Pose(c));
  ASSERT_FALSE(ms.empty());
  const Vec3 n = Vec3(1, 0, 1).normalized();
  const Real depth = 0.5 - d * std::sqrt(2.0);
  for (const Manifold& m : ms) {
    check_manifold(m, cube);
    // GJK's closest-point direction: 1e-9 rad is far above its round-off.
    EXPECT_NEAR(m.normal.dot(n), 1, 1e-12);
    EXPECT_NEAR(m.points[0].depth, depth, 1e-9);
    EXPECT_NEAR(m.points[0].point_a.x(), 1, 1e-9);
    EXPECT_NEAR(m.points[0].point_a.z(), 1, 1e-9);
  }
  // A box whose edge lies across the cube's edge (yawed 90 deg relative to it, tilted
  // 45 deg): an edge-edge contact with the edge normal.
  const Box bar(Vec3(0.2, 0.8, 0.2));
  // Bar axes: local y along the edge direction a = (1, 0, -1)/sqrt2 (across the cube's
  // edge), local x and z at 45 deg to n so that the bar's edge between its -x and -z
  // faces points along -n.
  Mat3 r;
  r.col(0) = (n - Vec3::UnitY()) / std::sqrt(2.0);
  r.col(1) = Vec3(1, 0, -1).normalized();
  r.col(2) = (n + Vec3::UnitY()) / std::sqrt(2.0);
  ASSERT_NEAR(r.determinant(), 1, 1e-12);
  const Quat q(r);
  const Real s = 0.2 * std::sqrt(2.0);  // centre to edge of the bar along n
  const Pose pose(Vec3(1, 0, 1) + (s - 0.01) * n, q);
  const auto mb = collide(cube, bar, pose);
  ASSERT_FALSE(mb.empty());
  for (const Manifold& m : mb) {
    check_manifold(m, cube);
    EXPECT_NEAR(m.normal.dot(n), 1, 1e-9);  // EPA's normal: its tolerance is 1e-10
    EXPECT_NEAR(m.max_depth(), 0.01, 1e-9);
  }
}

TEST(CollideMesh, BoxOverhangingConvexCubeEdge) {
  // A box on the cube mesh's top face, hanging 0.3 m over the edge x = 1: the +x face's
  // triangles touch it along the convex edge; every contact pushes up.
  const TriangleMesh cube = make_cube();
  const Box box(Vec3(0.4, 0.3, 0.2));
  const Pose pose(Vec3(0.9, 0.1, 1 + 0.2 - 0.01));
  const auto ms = collide(cube, box, pose);
  ASSERT_FALSE(ms.empty());
  bool side_face = false;
  for (const Manifold& m : ms) {
    check_manifold(m, cube);
    EXPECT_NEAR(m.normal.dot(Vec3::UnitZ()), 1, 1e-12) << "triangle " << m.child_a;
    // EPA's depth tolerance is 1e-10 relative; 1e-9 m is above it for O(1) sizes.
    for (int i = 0; i < m.count; ++i) EXPECT_NEAR(m.points[i].depth, 0.01, 1e-9);
    side_face = side_face || cube.triangle_normal(m.child_a).x() > 0.5;
  }
  EXPECT_TRUE(side_face);  // the +x face's triangles did contribute
}

TEST(CollideMesh, CapsuleAndHullRestOnGrid) {
  const TriangleMesh grid = make_grid(8, 0.5, Vec3(-2, -2, 0));
  // Capsule lying along x (its axis is local y), 1 cm deep, spanning several triangles.
  const Capsule cap(0.2, 0.6);
  const Pose cp(Vec3(0.13, 0.21, 0.2 - 0.01), Quat(Eigen::AngleAxisd(kPi / 2, Vec3::UnitZ())));
  const auto mc = collide(grid, cap, cp);
  ASSERT_GE(mc.size(), 2u);
  for (const Manifold& m : mc) {
    check_manifold(m, grid);
    EXPECT_EQ(m.normal, Vec3(0, 0, 1));
    for (int i = 0; i < m.count; ++i) {
      EXPECT_NEAR(m.points[i].depth, 0.01, 1e-12);
      EXPECT_NEAR(m.points[i].point_a.y(), 0.21, 1e-12);  // under the axis
    }
  }
  // A hull (an octagonal prism) sliding with a small yaw.
  std::vector<Vec3> pts;
  for (int k = 0; k < 8; ++k) {
    const Real a = 2 * kPi * k / 8;
    pts.emplace_back(0.35 * std::cos(a), 0.35 * std::sin(a), -0.15);
    pts.emplace_back(0.35 * std::cos(a), 0.35 * std::sin(a), 0.15);
  }
  const ConvexHull hull(pts);
  for (Real x : {0.0, 0.15, 0.355, 0.5}) {
    const Pose hp(Vec3(x, 0.0, 0.15 - 0.01), Quat(Eigen::AngleAxisd(0.1, Vec3::UnitZ())));
    const auto mh = collide(grid, hull, hp);
    ASSERT_FALSE(mh.empty());
    for (const Manifold& m : mh) {
      check_manifold(m, grid);
      EXPECT_EQ(m.normal, Vec3(0, 0, 1)) << x;
      // 1e-12: the hull's vertices are the input points (its face plane carries no error
      // beyond round-off of O(1) numbers).
      for (int i = 0; i < m.count; ++i) EXPECT_NEAR(m.points[i].depth, 0.01, 1e-12);
    }
  }
}

TEST(CollideMesh, BumpyGridNormalsStayWithinNeighbourCone) {
  // A gently bumpy grid (convex and concave edges of a few degrees) under a sliding,
  // tumbling box: every corrected normal lies within the cone of its triangle's and
  // neighbours' normals, i.e. it is tilted from its own face normal by no more than the
  // most tilted neighbour (the Voronoi wedges of the convex edges). The raw GJK/EPA
  // normals break this.
  const int n = 12;
  const Real cell = 0.4;
  std::vector<Vec3> v;
  Tris t;
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) {
      const Real x = -2.4 + i * cell, y = -2.4 + j * cell;
      v.emplace_back(x, y, 0.03 * std::sin(2.1 * x) * std::cos(1.7 * y));
    }
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      t.push_back({a, b, c});
      t.push_back({a, c, d});
    }
  const TriangleMesh grid(v, t);
  const Box box(Vec3(0.35, 0.25, 0.15));
  int raw_violations = 0;
  for (int k = 0; k < 40; ++k) {
    const Real x = -1.5 + 0.075 * k;
    const Quat q(Eigen::AngleAxisd(0.05 * k, Vec3::UnitZ()) * Eigen::AngleAxisd(0.04, Vec3::UnitX()));
    // Lowest point of the box 2 cm under the surface at (x, 0.3).
    const Real z = 0.03 * std::sin(2.1 * x) * std::cos(1.7 * 0.3);
    Pose pose(Vec3(x, 0.3, 0), q);
    const Real low = (pose.transform_point(box.support(pose.inverse_transform_vector(-Vec3::UnitZ())))).z();
    pose.position.z() = z - 0.02 - low;
    auto within_cone = [&](const Manifold& m) {
      const Vec3& nt = grid.triangle_normal(m.child_a);
      const Real side = m.normal.dot(nt) >= 0 ? 1 : -1;
      Real min_cos = 1;
      for (int e = 0; e < 3; ++e) {
        const int u = grid.neighbor(m.child_a, e);
        if (u >= 0) min_cos = std::min(min_cos, nt.dot(grid.triangle_normal(u)));
      }
      // 1e-9: the wedge test's angle slack (1e-6 rad) squared-ish in cosine terms.
      return side * m.normal.dot(nt) >= min_cos - 1e-9;
    };
    const auto ms = collide(grid, box, pose);
    ASSERT_FALSE(ms.empty()) << k;
    for (const Manifold& m : ms) {
      check_manifold(m, grid);
      EXPECT_TRUE(within_cone(m)) << "k " << k << " triangle " << m.child_a << " normal "
                                  << m.normal.transpose();
      EXPECT_GT(m.normal.z(), 0.9);  // never sideways: bumps are under 10 deg
    }
    for (const Manifold& m : collide(grid, box, pose, false))
      if (!within_cone(m)) ++raw_violations;
  }
  EXPECT_GT(raw_violations, 0);
}

TEST(CollideMesh, FarFromOrigin) {
  // The mesh itself lies 1e4 m out (mesh-frame coordinates are large).
  const Vec3 o(1e4, -2e4, 5e3);
  const TriangleMesh grid = make_grid(6, 0.5, o);
  const Box box(Vec3(0.4, 0.3, 0.2));
  for (Real x : {0.5, 0.905, 1.0, 1.37}) {
    const Pose pose(o + Vec3(x, 1.5, 0.2 - 0.01), Quat(Eigen::AngleAxisd(0.2, Vec3::UnitZ())));
    const auto ms = collide(grid, box, pose);
    ASSERT_FALSE(ms.empty());
    for (const Manifold& m : ms) {
      check_manifold(m, grid);
      EXPECT_EQ(m.normal, Vec3(0, 0, 1));
      // 1e-11: coordinates of 2e4 carry ~4e-12 m of round-off.
      for (int i = 0; i < m.count; ++i) EXPECT_NEAR(m.points[i].depth, 0.01, 1e-11);
    }
  }
}

TEST(CollideMesh, MarginAndSeparation) {
  const TriangleMesh grid = make_grid(4, 0.5, Vec3(-1, -1, 0));
  const Box box(Vec3(0.2, 0.2, 0.2));
  const Pose above(Vec3(0.1, 0.1, 0.25));  // 5 cm above
  EXPECT_TRUE(collide(grid, box, above).empty());
  const auto ms = collide(grid, box, above, true, 0.1);
  ASSERT_FALSE(ms.empty());
  for (const Manifold& m : ms) {
    EXPECT_EQ(m.normal, Vec3(0, 0, 1));
    for (int i = 0; i < m.count; ++i) EXPECT_NEAR(m.points[i].depth, -0.05, 1e-12);
  }
  EXPECT_TRUE(collide(grid, box, Pose(Vec3(5, 5, 0))).empty());
}

TEST(CollideMesh, BackFaceContact) {
  // A sphere under a flat grid: contacts point down, the back side's normal.
  const TriangleMesh grid = make_grid(4, 0.5, Vec3(-1, -1, 0));
  const Sphere ball(0.3);
  const auto ms = collide(grid, ball, Pose(Vec3(0.1, 0.2, -0.25)));
  ASSERT_FALSE(ms.empty());
  for (const Manifold& m : ms) {
    EXPECT_EQ(m.normal, Vec3(0, 0, -1));
    EXPECT_NEAR(m.points[0].depth, 0.05, 1e-12);
  }
}

TEST(CollideMesh, OneSidedPushesAnOverlappingBodyOutThroughTheFront) {
  // The two-sided grid pushes a ball whose centre is below it down (previous test); the
  // one-sided grid pushes the same ball up, by the depth of its lowest point (0.55 m),
  // along the face normal, from every triangle it overlaps.
  const TriangleMesh grid = make_grid(4, 0.5, Vec3(-1, -1, 0), true);
  EXPECT_TRUE(grid.one_sided());
  const Sphere ball(0.3);
  const auto ms = collide(grid, ball, Pose(Vec3(0.1, 0.2, -0.25)));
  ASSERT_FALSE(ms.empty());
  for (const Manifold& m : ms) {
    check_manifold(m, grid);
    EXPECT_EQ(m.normal, Vec3(0, 0, 1));
    for (int i = 0; i < m.count; ++i) EXPECT_NEAR(m.points[i].depth, 0.55, 1e-9);
  }
  // A level box three quarters through (its top 5 cm above the grid): up, every point
  // 15 cm deep. Tilted, still up, and no deeper than its lowest corner.
  const Box box(Vec3(0.3, 0.2, 0.1));
  for (const Manifold& m : collide(grid, box, Pose(Vec3(0.05, -0.1, -0.05)))) {
    check_manifold(m, grid);
    EXPECT_EQ(m.normal, Vec3(0, 0, 1));
    for (int i = 0; i < m.count; ++i) EXPECT_NEAR(m.points[i].depth, 0.15, 1e-12);
  }
  const Quat tilt(Eigen::AngleAxisd(0.3, Vec3(1, 1, 0).normalized()));
  const Pose pose(Vec3(0.05, -0.1, -0.15), tilt);
  const auto mb = collide(grid, box, pose);
  ASSERT_FALSE(mb.empty());
  Real lowest = kInf;
  for (int k = 0; k < 8; ++k) {
    const Vec3 c(k & 1 ? 0.3 : -0.3, k & 2 ? 0.2 : -0.2, k & 4 ? 0.1 : -0.1);
    lowest = std::min(lowest, pose.transform_point(c).z());
  }
  Real deepest = 0;
  for (const Manifold& m : mb) {
    check_manifold(m, grid);
    EXPECT_EQ(m.normal, Vec3(0, 0, 1));
    for (int i = 0; i < m.count; ++i) deepest = std::max(deepest, m.points[i].depth);
  }
  EXPECT_GT(deepest, 0.2);
  EXPECT_LE(deepest, -lowest + 1e-12);
}

TEST(CollideMesh, OneSidedIgnoresWhatIsBehindAndApart) {
  // Behind the one-sided grid and apart from it (within the margin): no contact, where
  // the two-sided grid reports a speculative one pointing down.
  const Sphere ball(0.3);
  const Pose below(Vec3(0.1, 0.2, -0.35));
  EXPECT_FALSE(collide(make_grid(4, 0.5, Vec3(-1, -1, 0)), ball, below, true, 0.1).empty());
  EXPECT_TRUE(collide(make_grid(4, 0.5, Vec3(-1, -1, 0), true), ball, below, true, 0.1).empty());
  // In front: the same contacts as two-sided (up, speculative depth -0.05).
  const Pose above(Vec3(0.1, 0.2, 0.35));
  const auto two = collide(make_grid(4, 0.5, Vec3(-1, -1, 0)), ball, above, true, 0.1);
  const auto one = collide(make_grid(4, 0.5, Vec3(-1, -1, 0), true), ball, above, true, 0.1);
  ASSERT_EQ(one.size(), two.size());
  ASSERT_FALSE(one.empty());
  for (std::size_t k = 0; k < one.size(); ++k) {
    EXPECT_EQ(one[k].normal, two[k].normal);
    EXPECT_EQ(one[k].count, two[k].count);
    EXPECT_EQ(one[k].points[0].depth, two[k].points[0].depth);
  }
}

TEST(CollideMesh, OneSidedKeepsWhatTouchedATriangleAtTheLastStep) {
  // A thin box wholly behind a one-sided grid (its top 1 mm below) and apart from it:
  // no contact by itself; with a history saying the pair touched the triangles it lies
  // under (CollideSettings::touched_before), a contact through the front (+z) whose
  // depth is how far its underside is below the plane (3 mm), on those triangles only.
  const TriangleMesh grid = make_grid(4, 0.5, Vec3(-1, -1, 0), true);
  const Box plate(Vec3(0.1, 0.1, 0.001));
  const Pose below(Vec3(0.25, 0.2, -0.002));
  EXPECT_TRUE(collide(grid, plate, below, true, 0.01).empty());
  struct History {
    std::vector<int> touched;
    int asked = 0;
  } history;
  CollideSettings s;
  s.margin = 0.01;
  s.touched_context = &history;
  s.touched_before = [](const void* context, int t) {
    auto& h = *const_cast<History*>(static_cast<const History*>(context));
    ++h.asked;
    return std::find(h.touched.begin(), h.touched.end(), t) != h.touched.end() ? 1 : 0;  // from the front
  };
  std::vector<Manifold> out;
  collide_mesh_convex(grid, plate, below, s, out);
  EXPECT_TRUE(out.empty());  // no triangle touched before
  EXPECT_GT(history.asked, 0);
  // The plate lies over the quad (i, j) = (2, 2), triangles 20 and 21.
  history.touched = {20, 21};
  collide_mesh_convex(grid, plate, below, s, out);
  ASSERT_FALSE(out.empty());
  Real deepest = 0;
  for (const Manifold& m : out) {
    EXPECT_TRUE(m.child_a == 20 || m.child_a == 21) << m.child_a;
    EXPECT_NEAR(m.normal.z(), 1.0, 1e-12);
    for (int k = 0; k < m.count; ++k) deepest = std::max(deepest, m.points[k].depth);
  }
  EXPECT_NEAR(deepest, 0.003, 1e-9);
  // A triangle whose edge neighbour was touched counts too (a body pushed through near
  // an edge ends up behind the next triangle); a far one does not.
  int outside = -1;
  for (int e = 0; e < 3; ++e)
    if (const int u = grid.neighbor(20, e); u >= 0 && u != 21) outside = u;
  ASSERT_GE(outside, 0);
  history.touched = {outside};
  out.clear();
  collide_mesh_convex(grid, plate, below, s, out);
  ASSERT_FALSE(out.empty());
  for (const Manifold& m : out) EXPECT_EQ(m.child_a, 20);
  history.touched = {0};
  out.clear();
  collide_mesh_convex(grid, plate, below, s, out);
  EXPECT_TRUE(out.empty());
}

TEST(CollideMesh, TwoSidedKeepsTheSideATriangleWasTouchedFrom) {
  // A 4 mm plate whose centre is 0.5 mm below a two-sided grid: less of it has passed
  // below, so by itself it is pushed out downwards. With a history saying the pair
  // touched those triangles from the front (+1), it is pushed back up, its underside
  // 2.5 mm deep; from the back (-1), down as before.
  const TriangleMesh grid = make_grid(4, 0.5, Vec3(-1, -1, 0));
  const Box plate(Vec3(0.1, 0.1, 0.002));
  const Pose pressed(Vec3(0.25, 0.2, -0.0005));
  for (const Manifold& m : collide(grid, plate, pressed, true, 0.01)) EXPECT_NEAR(m.normal.z(), -1.0, 1e-12);
  struct History {
    int side = 0;
  } history;
  CollideSettings s;
  s.margin = 0.01;
  s.touched_context = &history;
  s.touched_before = [](const void* context, int) { return static_cast<const History*>(context)->side; };
  for (const int side : {1, -1}) {
    history.side = side;
    std::vector<Manifold> out;
    collide_mesh_convex(grid, plate, pressed, s, out);
    ASSERT_FALSE(out.empty());
    Real deepest = 0;
    for (const Manifold& m : out) {
      EXPECT_NEAR(m.normal.z(), side, 1e-12);
      for (int k = 0; k < m.count; ++k) deepest = std::max(deepest, m.points[k].depth);
    }
    EXPECT_NEAR(deepest, side > 0 ? 0.0025 : 0.0015, 1e-9);
  }
}

TEST(CollideMesh, TwoSidedKeepsALongBoxApartFromATiltedTriangleOnItsSide) {
  // Found by scripts/fuzz_worlds.py (seed 62, two-sided ground): a 1.85 m long box
  // (566 kg) landing spinning at 10 rad/s beside a wall, 6 cm above the flank of a
  // ridge of the rolling ground (a 13 x 13 grid of 2 m cells, height 0.41 sin(x + z)).
  // Its nearest triangle's normal came from an internal edge and was turned into the
  // face normal, whose side was chosen by how much of the box lies on either side of
  // the triangle's plane taken whole; that tilted plane cut through the box beyond the
  // ridge, more of it lay below, and the contact pushed it down, 0.48 m "deep" along
  // the back normal: it sank through the ground over the next 800 steps. Apart from a
  // triangle, its nearest point is on the side GJK's normal points to; where the larger
  // part says otherwise the triangle gives no contact. Every contact must push it up,
  // from no deeper than touching.
  const Real amp = 0.4094776978478838;
  std::vector<Vec3> v;
  Tris t;
  for (int i = 0; i < 13; ++i)
    for (int j = 0; j < 13; ++j) {
      const Real x = -12 + 2 * i, z = -12 + 2 * j;
      v.emplace_back(x, amp * std::sin(x + z), z);
    }
  for (int i = 0; i < 12; ++i)
    for (int j = 0; j < 12; ++j) {
      const int a = 13 * i + j;
      t.push_back({a, a + 1, a + 13});
      t.push_back({a + 1, a + 14, a + 13});
    }
  const TriangleMesh ground(v, t);
  const Box box(Vec3(0.1488016036057695, 0.08292954131472187, 0.9238581003428556));
  const Pose pose(Vec3(4.6255246451493059, 0.46495089580347593, 9.8861336727300024),
                  Quat(-0.5868834614155285, 0.52332090365107431, 0.47662022912885638, -0.39311091526935149));
  const std::vector<Manifold> out = collide(ground, box, pose, true, 0.1547);
  ASSERT_FALSE(out.empty());
  for (const Manifold& m : out) {
    EXPECT_GT(m.normal.y(), 0.5) << "triangle " << m.child_a;
    for (int k = 0; k < m.count; ++k) {
      EXPECT_LE(m.points[k].depth, 0.0);
      EXPECT_GE(m.points[k].depth, -0.1547);
    }
  }
}

TEST(CollideMesh, OneSidedCubeFromInside) {
  // A ball inside a one-sided (outward-wound) cube near its +X wall overlaps it: pushed
  // out through the wall (+X) by the depth of its innermost point (0.4 m), not back
  // inside as the two-sided cube would (-X, by 0.2 m).
  std::vector<Vec3> v = make_cube().vertices();
  std::vector<std::array<int, 3>> t = make_cube().triangles();
  const TriangleMesh cube(v, t, true);
  const Sphere ball(0.3);
  const Pose p(Vec3(0.9, 0.1, -0.2));
  const auto two = collide(make_cube(), ball, p);
  ASSERT_FALSE(two.empty());
  for (const Manifold& m : two) EXPECT_LT(m.normal.x(), -0.99);
  const auto one = collide(cube, ball, p);
  ASSERT_FALSE(one.empty());
  for (const Manifold& m : one) {
    check_manifold(m, cube);
    EXPECT_EQ(m.normal, Vec3(1, 0, 0));
    EXPECT_NEAR(m.points[0].depth, 0.4, 1e-9);
  }
}

TEST(CollideMesh, TiltedRoundedDiscGetsSpeculativePointsAtItsFarRim) {
  // A disc of radius 0.3 m and thickness 0.06 m made of rings of points (a rounded rim:
  // its facets are small), tilted 0.15 rad and touching a flat grid with its low rim. The
  // supporting face along -z is one small facet at the low rim; the speculative points
  // added on four tilted directions reach the rest of its underside: with a 0.2 m margin
  // the manifold spans more than the disc's radius, and its deepest point is the lowest
  // one, 1 mm above the grid. (Without them, a disc landing on its rim spins up and its far side
  // passes a thin ground within a step: see collide_mesh.cpp.)
  std::vector<Vec3> pts;
  const Real rings[5][2] = {{-0.03, 0.1}, {-0.02, 0.25}, {0, 0.3}, {0.02, 0.25}, {0.03, 0.1}};
  for (const auto& r : rings)
    for (int k = 0; k < 16; ++k) {
      const Real a = 2 * kPi * (k + 0.5 * (&r - rings)) / 16;
      pts.emplace_back(r[1] * std::cos(a), r[1] * std::sin(a), r[0]);
    }
  const ConvexHull disc(pts);
  const Quat tilt(Eigen::AngleAxisd(0.15, Vec3(0, 1, 0)));
  Real lowest = kInf;
  for (const Vec3& p : pts) lowest = std::min(lowest, (tilt * p).z());
  const Pose pose(Vec3(0.8, -0.8, -lowest + 1e-3), tilt);  // 1 mm above the grid
  for (const bool one_sided : {false, true}) {
    // Two triangles split along x = y: the disc lies over one of them.
    const TriangleMesh grid = make_grid(1, 4.0, Vec3(-2, -2, 0), one_sided);
    const auto ms = collide(grid, disc, pose, true, 0.2);
    ASSERT_FALSE(ms.empty());
    Real span = 0, deepest = -kInf;
    for (const Manifold& m : ms) {
      check_manifold(m, grid);
      EXPECT_EQ(m.normal, Vec3(0, 0, 1));
      for (int i = 0; i < m.count; ++i) {
        deepest = std::max(deepest, m.points[i].depth);
        for (int j = 0; j < m.count; ++j) span = std::max(span, (m.points[i].point_b - m.points[j].point_b).norm());
      }
    }
    EXPECT_GT(span, 0.3);
    EXPECT_NEAR(deepest, -1e-3, 1e-9);
  }
}

TEST(CollideMesh, FeatureIdsStableUnderSmallMotion) {
  const TriangleMesh grid = make_grid(6, 0.5, Vec3(-1.5, -1.5, 0));
  const Box box(Vec3(0.4, 0.3, 0.2));
  auto ids = [&](const Pose& p) {
    std::set<std::pair<int, std::uint32_t>> s;
    for (const Manifold& m : collide(grid, box, p))
      for (int i = 0; i < m.count; ++i) s.insert({m.child_a, m.points[i].feature_id});
    return s;
  };
  const Pose p0(Vec3(0.13, 0.07, 0.19), Quat(Eigen::AngleAxisd(0.2, Vec3::UnitZ())));
  const Pose p1(Vec3(0.1301, 0.0702, 0.1899), Quat(Eigen::AngleAxisd(0.2001, Vec3::UnitZ())));
  const auto a = ids(p0);
  EXPECT_FALSE(a.empty());
  EXPECT_EQ(a, ids(p1));
  // Ids are distinct within a manifold.
  for (const Manifold& m : collide(grid, box, p0))
    for (int i = 0; i < m.count; ++i)
      for (int j = i + 1; j < m.count; ++j) EXPECT_NE(m.points[i].feature_id, m.points[j].feature_id);
}

TEST(CollideMesh, NoHeapAllocationPerQuery) {
  const TriangleMesh grid = make_grid(10, 0.5, Vec3(-2.5, -2.5, 0));
  const Box box(Vec3(0.4, 0.3, 0.2));
  const Sphere ball(0.3);
  CollideSettings s;
  std::vector<Manifold> out;
  out.reserve(256);
  auto run = [&] {
    for (int k = 0; k < 20; ++k) {
      out.clear();
      const Pose p(Vec3(-1 + 0.1 * k, 0.3, 0.19), Quat(Eigen::AngleAxisd(0.1 * k, Vec3(1, 2, 3).normalized())));
      collide_mesh_convex(grid, box, p, s, out);
      collide_mesh_convex(grid, ball, p, s, out);
    }
  };
  run();  // warm-up: per-thread GJK / EPA workspaces reach their size
  const long before = g_allocations.load();
  run();
  EXPECT_EQ(g_allocations.load() - before, 0);
}

}  // namespace
}  // namespace wmo
