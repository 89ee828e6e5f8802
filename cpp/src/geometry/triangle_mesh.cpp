// Triangle mesh: validation, normals, edge adjacency and convexity, and its BVH
// (mesh_bvh.h), plus ray casts against it.
//
// The edge flags feed internal-edge handling in the narrowphase (collide_mesh.cpp):
// a contact whose normal comes from a flat or concave edge of a smooth surface is an
// artefact of cutting the surface into triangles (the "ghost collision" of Bullet's
// btInternalEdgeUtility and Jolt's active edges), so the mesh records which edges are
// real features.
#include <algorithm>
#include <cmath>
#include <string>
#include <tuple>

#include "wmo/geometry/mesh_bvh.h"
#include "wmo/geometry/shapes.h"

namespace wmo {

namespace {

std::string tri_field(int t) { return "triangles[" + std::to_string(t) + "]"; }

std::string tri_value(const std::array<int, 3>& tri) {
  return "(" + std::to_string(tri[0]) + ", " + std::to_string(tri[1]) + ", " +
         std::to_string(tri[2]) + ")";
}

// A triangle whose doubled area is at most this times its longest edge squared (its
// height below 1e-12 of that edge) is rejected: its normal, computed from a cross
// product of nearly parallel edges, would carry a relative error of
// DBL_EPSILON / 1e-12 ~ 2e-4 or worse, and a zero-area one has no normal at all.
constexpr Real kDegenerateRel = 1e-12;

// Bins of the SAH build. 16 is the usual choice (Wald 2007): more bins barely improve
// tree quality.
constexpr int kBins = 16;

}  // namespace

// ---------------------------------------------------------------------------------
// BVH
// ---------------------------------------------------------------------------------

struct TriangleMeshBvh::BuildItem {
  Aabb box;
  Vec3 centroid;  // of the triangle's box: what the split planes sort by
  std::int32_t tri;
};

TriangleMeshBvh::TriangleMeshBvh(const std::vector<Vec3>& vertices,
                                 const std::vector<std::array<int, 3>>& triangles) {
  const int n = static_cast<int>(triangles.size());
  if (n == 0) return;
  std::vector<BuildItem> items(n);
  for (int t = 0; t < n; ++t) {
    Aabb b;
    for (int k = 0; k < 3; ++k) b.grow(vertices[triangles[t][k]]);
    items[t] = BuildItem{b, b.center(), t};
  }
  nodes_.reserve(2 * (n / kMaxLeafTriangles + 1));
  order_.reserve(n);
  boxes_.reserve(n);
  build(items, 0, n, 1);
}

// Top-down build of items[begin, end); returns the index of the subtree's root.
int TriangleMeshBvh::build(std::vector<BuildItem>& items, int begin, int end, int depth) {
  const int index = static_cast<int>(nodes_.size());
  nodes_.emplace_back();
  depth_ = std::max(depth_, depth);
  Aabb box, cbox;
  for (int i = begin; i < end; ++i) {
    box.grow(items[i].box);
    cbox.grow(items[i].centroid);
  }
  nodes_[index].box = box;
  const int n = end - begin;
  if (n <= kMaxLeafTriangles) {
    nodes_[index].first = static_cast<std::int32_t>(order_.size());
    nodes_[index].count = n;
    for (int i = begin; i < end; ++i) {
      order_.push_back(items[i].tri);
      boxes_.push_back(items[i].box);
    }
    return index;
  }

  const Vec3 extent = cbox.max - cbox.min;
  int mid = -1;
  if (depth < kSahDepth) {
    // Binned SAH (Wald 2007): for each axis, drop the centroids into kBins bins, sweep
    // the bin boundaries and keep the split minimising area(L) * |L| + area(R) * |R|.
    Real best_cost = kInf;
    int best_axis = -1, best_split = -1;
    for (int axis = 0; axis < 3; ++axis) {
      if (!(extent[axis] > 0)) continue;
      const Real scale = kBins / extent[axis];
      std::array<Aabb, kBins> bin_box;
      std::array<int, kBins> bin_count{};
      for (int i = begin; i < end; ++i) {
        int b = static_cast<int>((items[i].centroid[axis] - cbox.min[axis]) * scale);
        b = std::clamp(b, 0, kBins - 1);
        bin_box[b].grow(items[i].box);
        ++bin_count[b];
      }
      // Suffix sweep from the right, then prefix sweep from the left.
      std::array<Real, kBins> right_cost{};
      Aabb acc;
      int cnt = 0;
      for (int b = kBins - 1; b > 0; --b) {
        acc.grow(bin_box[b]);
        cnt += bin_count[b];
        right_cost[b] = cnt > 0 ? acc.surface_area() * cnt : 0;
      }
      acc = Aabb();
      cnt = 0;
      for (int b = 0; b < kBins - 1; ++b) {
        acc.grow(bin_box[b]);
        cnt += bin_count[b];
        if (cnt == 0 || cnt == n) continue;  // one side empty: not a split
        const Real cost = acc.surface_area() * cnt + right_cost[b + 1];
        if (cost < best_cost) {
          best_cost = cost;
          best_axis = axis;
          best_split = b;
        }
      }
    }
    if (best_axis >= 0) {
      const Real scale = kBins / extent[best_axis];
      const auto it = std::partition(
          items.begin() + begin, items.begin() + end, [&](const BuildItem& it) {
            int b = static_cast<int>((it.centroid[best_axis] - cbox.min[best_axis]) * scale);
            return std::clamp(b, 0, kBins - 1) <= best_split;
          });
      mid = static_cast<int>(it - items.begin());
      if (mid == begin || mid == end) mid = -1;  // cannot happen, but never recurse forever
    }
  }
  if (mid < 0) {
    // Median split on the longest centroid axis (all centroids equal: any axis, the
    // tie-break by triangle index keeps it deterministic). Halving bounds the depth.
    int axis = 0;
    if (extent.y() > extent[axis]) axis = 1;
    if (extent.z() > extent[axis]) axis = 2;
    mid = begin + n / 2;
    std::nth_element(items.begin() + begin, items.begin() + mid, items.begin() + end,
                     [axis](const BuildItem& a, const BuildItem& b) {
                       if (a.centroid[axis] != b.centroid[axis])
                         return a.centroid[axis] < b.centroid[axis];
                       return a.tri < b.tri;
                     });
  }
  build(items, begin, mid, depth + 1);  // left child is index + 1
  const int right = build(items, mid, end, depth + 1);
  nodes_[index].first = right;
  nodes_[index].count = 0;
  return index;
}

// ---------------------------------------------------------------------------------
// Ray casts
// ---------------------------------------------------------------------------------

bool ray_triangle(const Vec3& v0, const Vec3& v1, const Vec3& v2, const Vec3& origin,
                  const Vec3& dir, Real max_t, Real& t) {
  // Möller & Trumbore 1997: solve origin + t dir = v0 + u e1 + v e2 by Cramer's rule.
  constexpr Real kBaryTol = 1e-12;  // see mesh_bvh.h: closes cracks at shared edges
  const Vec3 e1 = v1 - v0, e2 = v2 - v0;
  const Vec3 p = dir.cross(e2);
  const Real det = e1.dot(p);
  if (det == 0 || !std::isfinite(det)) return false;
  const Real inv = Real(1) / det;
  const Vec3 s = origin - v0;
  const Real u = s.dot(p) * inv;
  if (u < -kBaryTol || u > 1 + kBaryTol) return false;
  const Vec3 q = s.cross(e1);
  const Real v = dir.dot(q) * inv;
  if (v < -kBaryTol || u + v > 1 + kBaryTol) return false;
  const Real tt = e2.dot(q) * inv;
  if (!(tt >= 0 && tt <= max_t)) return false;
  t = tt;
  return true;
}

RayHit raycast_mesh(const TriangleMesh& mesh, const Vec3& origin, const Vec3& dir, Real max_t) {
  RayHit hit;
  if (!origin.allFinite() || !dir.allFinite() || dir.squaredNorm() == 0 || std::isnan(max_t) ||
      max_t < 0)
    return hit;
  const auto& v = mesh.vertices();
  const auto& tris = mesh.triangles();
  Real best_t = kInf;
  int best = -1;
  mesh.bvh().query_ray(origin, dir, max_t, [&](int t, Real& limit) {
    const auto& tri = tris[t];
    Real tt;
    if (!ray_triangle(v[tri[0]], v[tri[1]], v[tri[2]], origin, dir, limit, tt)) return;
    if (tt < best_t || (tt == best_t && t < best)) {
      best_t = tt;
      best = t;
      limit = tt;  // only hits at least as close matter from now on
    }
  });
  if (best < 0) return hit;
  hit.hit = true;
  hit.distance = best_t;
  hit.point = origin + best_t * dir;
  const Vec3& n = mesh.triangle_normal(best);
  hit.normal = n.dot(dir) > 0 ? Vec3(-n) : n;
  hit.child = best;
  return hit;
}

// ---------------------------------------------------------------------------------
// TriangleMesh
// ---------------------------------------------------------------------------------

TriangleMesh::TriangleMesh(std::vector<Vec3> vertices, std::vector<std::array<int, 3>> triangles, bool one_sided)
    : Shape(ShapeType::kTriangleMesh),
      vertices_(std::move(vertices)),
      triangles_(std::move(triangles)),
      one_sided_(one_sided) {
  const int nv = static_cast<int>(vertices_.size());
  const int nt = static_cast<int>(triangles_.size());
  if (nv == 0) throw InvalidArgument("vertices must not be empty, got 0 vertices");
  if (nt == 0) throw InvalidArgument("triangles must not be empty, got 0 triangles");
  for (int i = 0; i < nv; ++i) {
    if (!vertices_[i].allFinite())
      throw InvalidArgument("vertices[" + std::to_string(i) + "] must be finite, got " +
                            to_string(vertices_[i]));
  }
  normals_.resize(nt);
  for (int t = 0; t < nt; ++t) {
    const auto& tri = triangles_[t];
    for (int k = 0; k < 3; ++k) {
      if (tri[k] < 0 || tri[k] >= nv)
        throw InvalidArgument(tri_field(t) + " has vertex index " + std::to_string(tri[k]) +
                              " out of range [0, " + std::to_string(nv) + "), got " +
                              tri_value(tri));
    }
    const Vec3& a = vertices_[tri[0]];
    const Vec3& b = vertices_[tri[1]];
    const Vec3& c = vertices_[tri[2]];
    const Vec3 cr = (b - a).cross(c - a);
    const Real lmax2 =
        std::max({(b - a).squaredNorm(), (c - b).squaredNorm(), (a - c).squaredNorm()});
    const Real len = cr.norm();
    if (!(len > kDegenerateRel * lmax2))
      throw InvalidArgument(tri_field(t) + " is degenerate (zero area), got " + tri_value(tri) +
                            " with vertices " + to_string(a) + ", " + to_string(b) + ", " +
                            to_string(c));
    normals_[t] = cr / len;
  }

  for (const Vec3& p : vertices_) aabb_.grow(p);
  flat_tolerance_ = kFlatEdgeRelTolerance * (aabb_.max - aabb_.min).norm();

  // Edge adjacency by sorting (lo, hi, t, e) records: deterministic, no hash map.
  struct EdgeRec {
    int lo, hi, t, e;
  };
  std::vector<EdgeRec> recs;
  recs.reserve(3 * static_cast<std::size_t>(nt));
  for (int t = 0; t < nt; ++t)
    for (int e = 0; e < 3; ++e) {
      const int i = triangles_[t][e], j = triangles_[t][(e + 1) % 3];
      recs.push_back(EdgeRec{std::min(i, j), std::max(i, j), t, e});
    }
  std::sort(recs.begin(), recs.end(), [](const EdgeRec& x, const EdgeRec& y) {
    return std::tie(x.lo, x.hi, x.t, x.e) < std::tie(y.lo, y.hi, y.t, y.e);
  });
  neighbors_.assign(nt, {-1, -1, -1});
  for (std::size_t i = 0; i < recs.size();) {
    std::size_t j = i + 1;
    while (j < recs.size() && recs[j].lo == recs[i].lo && recs[j].hi == recs[i].hi) ++j;
    if (j - i == 2) {
      const EdgeRec& x = recs[i];
      const EdgeRec& y = recs[i + 1];
      // Consistent winding: the two triangles traverse the edge in opposite directions.
      const bool x_forward = triangles_[x.t][x.e] == x.lo;
      const bool y_forward = triangles_[y.t][y.e] == y.lo;
      if (x_forward != y_forward && x.t != y.t) {
        neighbors_[x.t][x.e] = y.t;
        neighbors_[y.t][y.e] = x.t;
      }
    }
    i = j;  // single, non-manifold (3+) or inconsistent: boundary (-1) on every use
  }

  // Convexity. Bits 0-2: edge e convex seen from the front; bits 3-5: seen from the back.
  convex_edge_bits_.assign(nt, 0);
  for (int t = 0; t < nt; ++t) {
    std::uint8_t bits = 0;
    for (int e = 0; e < 3; ++e) {
      const int u = neighbors_[t][e];
      if (u < 0) {
        bits |= static_cast<std::uint8_t>((1u << e) | (1u << (e + 3)));
        continue;
      }
      const int a = triangles_[t][e], b = triangles_[t][(e + 1) % 3];
      int opp = triangles_[u][0];
      for (int k = 0; k < 3; ++k)
        if (triangles_[u][k] != a && triangles_[u][k] != b) opp = triangles_[u][k];
      const Real h = normals_[t].dot(vertices_[opp] - vertices_[a]);
      if (h < -flat_tolerance_) bits |= static_cast<std::uint8_t>(1u << e);
      if (h > flat_tolerance_) bits |= static_cast<std::uint8_t>(1u << (e + 3));
    }
    convex_edge_bits_[t] = bits;
  }

  bvh_ = std::make_unique<TriangleMeshBvh>(vertices_, triangles_);
}

TriangleMesh::~TriangleMesh() = default;

}  // namespace wmo
