// TriangleMesh construction (validation, normals, adjacency, edge convexity), its BVH
// and ray casts.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <string>
#include <vector>

#include "wmo/geometry/mesh_bvh.h"
#include "wmo/geometry/shapes.h"

namespace wmo {
namespace {

using Tris = std::vector<std::array<int, 3>>;

// n x n quads of size `cell` in the plane z = z0 starting at `origin`, each split into two
// CCW (seen from +z) triangles. Vertex (i, j) has index j * (n + 1) + i.
void make_grid(int n, Real cell, const Vec3& origin, std::vector<Vec3>& v, Tris& t) {
  v.clear();
  t.clear();
  for (int j = 0; j <= n; ++j)
    for (int i = 0; i <= n; ++i) v.push_back(origin + Vec3(i * cell, j * cell, 0));
  for (int j = 0; j < n; ++j)
    for (int i = 0; i < n; ++i) {
      const int a = j * (n + 1) + i, b = a + 1, c = a + n + 2, d = a + n + 1;
      t.push_back({a, b, c});
      t.push_back({a, c, d});
    }
}

// Unit cube [-1, 1]^3 as 12 outward CCW triangles.
void make_cube(std::vector<Vec3>& v, Tris& t) {
  v.clear();
  for (int k = 0; k < 8; ++k) v.emplace_back(k & 1 ? 1 : -1, k & 2 ? 1 : -1, k & 4 ? 1 : -1);
  // Quads listed CCW seen from outside.
  const int quads[6][4] = {{0, 2, 3, 1}, {4, 5, 7, 6}, {0, 1, 5, 4},
                           {2, 6, 7, 3}, {0, 4, 6, 2}, {1, 3, 7, 5}};
  t.clear();
  for (const auto& q : quads) {
    t.push_back({q[0], q[1], q[2]});
    t.push_back({q[0], q[2], q[3]});
  }
}

template <class F>
std::string error_of(F&& f) {
  try {
    f();
  } catch (const InvalidArgument& e) {
    return e.what();
  }
  return "<no exception>";
}

bool contains(const std::string& s, const std::string& part) {
  return s.find(part) != std::string::npos;
}

TEST(TriangleMesh, RejectsNonFiniteVertexNamingIt) {
  std::vector<Vec3> v{{0, 0, 0}, {1, 0, 0}, {0, std::nan(""), 0}};
  const std::string msg = error_of([&] { TriangleMesh m(v, Tris{{0, 1, 2}}); });
  EXPECT_TRUE(contains(msg, "vertices[2]")) << msg;
  EXPECT_TRUE(contains(msg, "nan")) << msg;
  v[2] = Vec3(0, 1, kInf);
  const std::string msg2 = error_of([&] { TriangleMesh m(v, Tris{{0, 1, 2}}); });
  EXPECT_TRUE(contains(msg2, "vertices[2]") && contains(msg2, "inf")) << msg2;
}

TEST(TriangleMesh, RejectsOutOfRangeIndexNamingTriangle) {
  const std::vector<Vec3> v{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {1, 1, 0}};
  std::string msg = error_of([&] { TriangleMesh m(v, Tris{{0, 1, 2}, {1, 7, 2}}); });
  EXPECT_TRUE(contains(msg, "triangles[1]") && contains(msg, "7")) << msg;
  msg = error_of([&] { TriangleMesh m(v, Tris{{0, 1, 2}, {1, 3, 2}, {-1, 3, 2}}); });
  EXPECT_TRUE(contains(msg, "triangles[2]") && contains(msg, "-1")) << msg;
}

TEST(TriangleMesh, RejectsZeroAreaTriangleNamingIt) {
  const std::vector<Vec3> v{{0, 0, 0}, {1, 0, 0}, {0, 1, 0}, {2, 0, 0}};
  // Colinear vertices.
  std::string msg = error_of([&] { TriangleMesh m(v, Tris{{0, 1, 2}, {0, 1, 3}}); });
  EXPECT_TRUE(contains(msg, "triangles[1]") && contains(msg, "degenerate")) << msg;
  // Repeated index.
  msg = error_of([&] { TriangleMesh m(v, Tris{{2, 2, 1}}); });
  EXPECT_TRUE(contains(msg, "triangles[0]")) << msg;
  // A sliver just above the threshold (height 1e-9 of its length) is accepted.
  const std::vector<Vec3> s{{0, 0, 0}, {1, 0, 0}, {0.5, 1e-9, 0}};
  EXPECT_NO_THROW(TriangleMesh(s, Tris{{0, 1, 2}}));
}

TEST(TriangleMesh, RejectsEmpty) {
  EXPECT_TRUE(contains(error_of([] { TriangleMesh m({}, Tris{}); }), "vertices"));
  EXPECT_TRUE(contains(
      error_of([] { TriangleMesh m({{0, 0, 0}, {1, 0, 0}, {0, 1, 0}}, Tris{}); }), "triangles"));
}

TEST(TriangleMesh, FlatGridAdjacencyAndFlags) {
  std::vector<Vec3> v;
  Tris t;
  const int n = 5;
  make_grid(n, 0.5, Vec3(-1, -1, 0), v, t);
  const TriangleMesh m(v, t);
  int boundary = 0;
  for (int i = 0; i < static_cast<int>(t.size()); ++i) {
    // Normals are +z for the CCW grid (exactly: the cross product of axis-aligned edges).
    EXPECT_EQ(m.triangle_normal(i), Vec3(0, 0, 1));
    for (int e = 0; e < 3; ++e) {
      const int u = m.neighbor(i, e);
      if (u < 0) {
        ++boundary;
        EXPECT_TRUE(m.edge_is_convex(i, e));
        EXPECT_TRUE(m.edge_is_convex_from_back(i, e));
        continue;
      }
      // The neighbour links back through the same two vertices.
      int back = -1;
      for (int f = 0; f < 3; ++f)
        if (m.neighbor(u, f) == i) back = f;
      ASSERT_GE(back, 0);
      EXPECT_EQ(t[u][back], t[i][(e + 1) % 3]);
      EXPECT_EQ(t[u][(back + 1) % 3], t[i][e]);
      // Flat: internal from both sides.
      EXPECT_FALSE(m.edge_is_convex(i, e));
      EXPECT_FALSE(m.edge_is_convex_from_back(i, e));
    }
  }
  EXPECT_EQ(boundary, 4 * n);  // the grid's rim: n edges per side
}

TEST(TriangleMesh, FlatGridFarFromOriginStaysFlat) {
  // 1e4 m away the coordinates carry ~2e-12 m of round-off: far below the flat tolerance.
  std::vector<Vec3> v;
  Tris t;
  make_grid(4, 0.1, Vec3(1e4 + 0.1, -2e4 + 0.3, 5e3 + 0.7), v, t);
  const TriangleMesh m(v, t);
  for (int i = 0; i < static_cast<int>(t.size()); ++i)
    for (int e = 0; e < 3; ++e)
      if (m.neighbor(i, e) >= 0) EXPECT_FALSE(m.edge_is_convex(i, e)) << i << " " << e;
}

TEST(TriangleMesh, CubeEdgesAreAllConvex) {
  std::vector<Vec3> v;
  Tris t;
  make_cube(v, t);
  const TriangleMesh m(v, t);
  int flat = 0, convex = 0;
  for (int i = 0; i < 12; ++i) {
    // Outward normals: the normal points away from the centre.
    const Vec3 c = (v[t[i][0]] + v[t[i][1]] + v[t[i][2]]) / 3;
    EXPECT_GT(m.triangle_normal(i).dot(c), 0);
    for (int e = 0; e < 3; ++e) {
      ASSERT_GE(m.neighbor(i, e), 0);  // closed mesh
      EXPECT_FALSE(m.edge_is_convex_from_back(i, e));
      // The diagonal of each face is flat, the 12 cube edges convex.
      if (m.triangle_normal(m.neighbor(i, e)) == m.triangle_normal(i)) {
        ++flat;
        EXPECT_FALSE(m.edge_is_convex(i, e));
      } else {
        ++convex;
        EXPECT_TRUE(m.edge_is_convex(i, e));
      }
    }
  }
  EXPECT_EQ(flat, 12);     // 6 diagonals seen from both triangles
  EXPECT_EQ(convex, 24);   // 12 cube edges seen from both triangles
  EXPECT_EQ(m.local_aabb().min, Vec3(-1, -1, -1));
  EXPECT_EQ(m.local_aabb().max, Vec3(1, 1, 1));
}

TEST(TriangleMesh, ValleyEdgeIsConcave) {
  // Two triangles folded up along the y axis: a valley (concave from the front).
  const std::vector<Vec3> v{{0, 0, 0}, {0, 1, 0}, {1, 0, 0.3}, {-1, 0, 0.3}};
  const TriangleMesh m(v, Tris{{0, 2, 1}, {0, 1, 3}});
  ASSERT_EQ(m.neighbor(0, 2), 1);  // edge 1 -> 0 of triangle 0
  EXPECT_FALSE(m.edge_is_convex(0, 2));
  EXPECT_TRUE(m.edge_is_convex_from_back(0, 2));
  // The same fold made a ridge: convex.
  const std::vector<Vec3> r{{0, 0, 0}, {0, 1, 0}, {1, 0, -0.3}, {-1, 0, -0.3}};
  const TriangleMesh mr(r, Tris{{0, 2, 1}, {0, 1, 3}});
  EXPECT_TRUE(mr.edge_is_convex(0, 2));
  EXPECT_FALSE(mr.edge_is_convex_from_back(0, 2));
}

TEST(TriangleMesh, NonManifoldAndInconsistentEdgesAreBoundary) {
  // Three triangles on edge (0, 1).
  const std::vector<Vec3> v{{0, 0, 0}, {1, 0, 0}, {0.5, 1, 0}, {0.5, -1, 0}, {0.5, 0, 1}};
  const TriangleMesh m(v, Tris{{0, 1, 2}, {1, 0, 3}, {0, 1, 4}});
  for (int i = 0; i < 3; ++i) {
    for (int e = 0; e < 3; ++e) EXPECT_EQ(m.neighbor(i, e), -1);
    EXPECT_TRUE(m.edge_is_convex(i, 0));
  }
  // Two triangles with inconsistent winding on the shared edge.
  const TriangleMesh w(v, Tris{{0, 1, 2}, {0, 1, 3}});
  EXPECT_EQ(w.neighbor(0, 0), -1);
  EXPECT_EQ(w.neighbor(1, 0), -1);
}

// A bumpy grid plus a random triangle soup: a mesh with overlapping, oddly sized boxes.
TriangleMesh random_mesh(std::mt19937& rng) {
  std::uniform_real_distribution<Real> u(-1, 1);
  std::vector<Vec3> v;
  Tris t;
  make_grid(12, 0.4, Vec3(-2.4, -2.4, 0), v, t);
  for (Vec3& p : v) p.z() = 0.3 * u(rng);
  for (int k = 0; k < 80; ++k) {
    const int base = static_cast<int>(v.size());
    const Vec3 c(2 * u(rng), 2 * u(rng), u(rng));
    const Real s = k % 10 == 0 ? 1.5 : 0.2;
    for (int j = 0; j < 3; ++j) v.push_back(c + s * Vec3(u(rng), u(rng), u(rng)));
    t.push_back({base, base + 1, base + 2});
  }
  return TriangleMesh(v, t);
}

TEST(TriangleMeshBvh, TreeInvariants) {
  std::mt19937 rng(7);
  const TriangleMesh m = random_mesh(rng);
  const TriangleMeshBvh& b = m.bvh();
  const int nt = static_cast<int>(m.triangles().size());
  std::vector<int> seen(nt, 0);
  for (int i = 0; i < b.node_count(); ++i) {
    const auto& n = b.node(i);
    if (n.is_leaf()) {
      EXPECT_LE(n.count, TriangleMeshBvh::kMaxLeafTriangles);
      for (int k = n.first; k < n.first + n.count; ++k) {
        ++seen[b.triangle_order()[k]];
        EXPECT_TRUE(n.box.contains(b.leaf_triangle_box(k)));
      }
    } else {
      EXPECT_TRUE(n.box.contains(b.node_bounds(i + 1)));
      EXPECT_TRUE(n.box.contains(b.node_bounds(n.first)));
    }
  }
  for (int c : seen) EXPECT_EQ(c, 1);
  EXPECT_TRUE(b.root_bounds().contains(m.local_aabb()));
  EXPECT_LE(b.depth(), TriangleMeshBvh::kStackSize);
}

TEST(TriangleMeshBvh, QueryAabbEqualsBruteForce) {
  std::mt19937 rng(11);
  const TriangleMesh m = random_mesh(rng);
  std::uniform_real_distribution<Real> u(-3, 3), s(0, 1.2);
  const auto& v = m.vertices();
  for (int q = 0; q < 300; ++q) {
    const Vec3 c(u(rng), u(rng), 0.5 * u(rng));
    const Vec3 h(s(rng), s(rng), s(rng));
    const Aabb box(c - h, c + h);
    std::vector<int> got;
    m.bvh().query_aabb(box, [&](int t) { got.push_back(t); });
    std::vector<int> want;
    for (int t = 0; t < static_cast<int>(m.triangles().size()); ++t) {
      Aabb tb;
      for (int k : m.triangles()[t]) tb.grow(v[k]);
      if (tb.overlaps(box)) want.push_back(t);
    }
    std::sort(got.begin(), got.end());
    EXPECT_EQ(got, want) << "query " << q;
  }
  // Early exit: returning false stops after the first triangle.
  int calls = 0;
  m.bvh().query_aabb(m.local_aabb(), [&](int) {
    ++calls;
    return false;
  });
  EXPECT_EQ(calls, 1);
}

TEST(TriangleMeshBvh, RayTriangleMatchesPlaneIntersection) {
  // Independent check of Möller-Trumbore: intersect the plane, then test the point
  // with edge-side signs.
  std::mt19937 rng(3);
  std::uniform_real_distribution<Real> u(-1, 1);
  int hits = 0;
  for (int q = 0; q < 2000; ++q) {
    const Vec3 a(u(rng), u(rng), u(rng)), b(u(rng), u(rng), u(rng)), c(u(rng), u(rng), u(rng));
    // Aim near the centroid so that about half the rays hit.
    const Vec3 o = 3 * Vec3(u(rng), u(rng), u(rng));
    const Vec3 d = (a + b + c) / 3 + 0.4 * Vec3(u(rng), u(rng), u(rng)) - o;
    const Vec3 n = (b - a).cross(c - a);
    const Real dn = d.dot(n);
    if (std::abs(dn) < 1e-3 * n.norm() * d.norm()) continue;  // near-grazing: skip
    const Real tp = (a - o).dot(n) / dn;
    const Vec3 p = o + tp * d;
    const Real s0 = (b - a).cross(p - a).dot(n), s1 = (c - b).cross(p - b).dot(n),
               s2 = (a - c).cross(p - c).dot(n);
    // Points within 1e-9 (relative) of an edge are ambiguous between the two methods.
    const Real margin = 1e-9 * n.squaredNorm();
    if (std::min({std::abs(s0), std::abs(s1), std::abs(s2)}) < margin) continue;
    const bool inside = s0 > 0 && s1 > 0 && s2 > 0;
    Real t = -1;
    const bool hit = ray_triangle(a, b, c, o, d, 10, t);
    EXPECT_EQ(hit, inside && tp >= 0 && tp <= 10) << q;
    if (hit) {
      ++hits;
      // 1e-12: both are a few operations on O(1) numbers, away from grazing angles.
      EXPECT_NEAR(t, tp, 1e-12 * std::max(Real(1), std::abs(tp)));
    }
  }
  EXPECT_GT(hits, 50);  // the test exercises hits, not just misses
}

TEST(TriangleMeshBvh, RaycastEqualsBruteForce) {
  std::mt19937 rng(5);
  const TriangleMesh m = random_mesh(rng);
  std::uniform_real_distribution<Real> u(-1, 1);
  const auto& v = m.vertices();
  int hits = 0;
  for (int q = 0; q < 500; ++q) {
    const Vec3 o = 4 * Vec3(u(rng), u(rng), u(rng));
    // Aimed at the mesh's region, so most rays hit something.
    Vec3 d = Vec3(2 * u(rng), 2 * u(rng), 0.3 * u(rng)) - o;
    if (q % 7 == 0) d = Vec3(0, 0, -1);  // axis-aligned rays exercise the zero slabs
    const Real max_t = q % 3 == 0 ? Real(0.8) : kInf;  // a cap that cuts some hits off
    const RayHit h = raycast_mesh(m, o, d, max_t);
    Real best = kInf;
    int best_t = -1;
    for (int t = 0; t < static_cast<int>(m.triangles().size()); ++t) {
      const auto& tri = m.triangles()[t];
      Real tt;
      if (ray_triangle(v[tri[0]], v[tri[1]], v[tri[2]], o, d, max_t, tt) && tt < best) {
        best = tt;
        best_t = t;
      }
    }
    ASSERT_EQ(h.hit, best_t >= 0) << q;
    if (!h.hit) continue;
    ++hits;
    EXPECT_EQ(h.distance, best);  // same per-triangle routine: same bits
    EXPECT_EQ(h.child, best_t);
    EXPECT_EQ(h.point, o + best * d);
    // Normal: the hit side's normal, facing the ray.
    EXPECT_LE(h.normal.dot(d), 0);
    EXPECT_NEAR(std::abs(h.normal.dot(m.triangle_normal(best_t))), 1, 1e-15);
  }
  EXPECT_GT(hits, 100);
  // Invalid rays miss.
  EXPECT_FALSE(raycast_mesh(m, Vec3(0, 0, 5), Vec3::Zero(), kInf).hit);
  EXPECT_FALSE(raycast_mesh(m, Vec3(0, 0, 5), Vec3(0, 0, std::nan("")), kInf).hit);
}

TEST(TriangleMeshBvh, RayThroughSharedEdgeAndVertexHits) {
  std::vector<Vec3> v;
  Tris t;
  make_grid(4, 0.25, Vec3(0, 0, 0), v, t);
  const TriangleMesh m(v, t);
  // Through a grid vertex, along a diagonal and along a grid line: no crack.
  for (const Vec3& o : {Vec3(0.5, 0.5, 1), Vec3(0.375, 0.375, 1), Vec3(0.5, 0.3, 1)}) {
    const RayHit h = raycast_mesh(m, o, Vec3(0, 0, -1), kInf);
    ASSERT_TRUE(h.hit) << o.transpose();
    EXPECT_EQ(h.distance, 1);
    EXPECT_EQ(h.normal, Vec3(0, 0, 1));
  }
  // From below: back-face hit, normal facing the ray.
  const RayHit h = raycast_mesh(m, Vec3(0.3, 0.6, -2), Vec3(0, 0, 2), kInf);
  ASSERT_TRUE(h.hit);
  EXPECT_EQ(h.distance, 1);
  EXPECT_EQ(h.normal, Vec3(0, 0, -1));
}

}  // namespace
}  // namespace wmo
