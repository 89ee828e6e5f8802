// WMO geometry layer: bounding volume hierarchy over the triangles of a TriangleMesh,
// and ray casts against a mesh.
//
// The tree is a flat array of nodes in depth-first order (the left child of node i is
// node i + 1, the right child is stored), built top-down with a binned surface-area
// heuristic (Wald 2007, "On fast construction of SAH-based bounding volume
// hierarchies"; Ericson 6.2). Leaves hold at most kMaxLeafTriangles triangles. Queries
// walk the tree with a fixed-size stack: they never allocate.
//
// Everything is in the mesh's local frame (metres). The tree is immutable after
// construction, so any number of threads may query it at once.
#pragma once

#include <array>
#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "wmo/geometry/shapes.h"
#include "wmo/math.h"
#include "wmo/types.h"

namespace wmo {

class TriangleMeshBvh {
 public:
  /// Most triangles in a leaf. 4 balances node count against per-leaf work, as in
  /// Bullet's and Jolt's mesh trees.
  static constexpr int kMaxLeafTriangles = 4;
  /// Depth below which the build switches from SAH to a median split. A median split
  /// halves the triangle count, so the tree is at most kSahDepth + log2(2^31) deep and
  /// the query stack below can never overflow, however badly SAH splits a strange mesh.
  static constexpr int kSahDepth = 40;
  static constexpr int kStackSize = kSahDepth + 40;

  /// One node. A leaf has count > 0 and holds the triangles
  /// triangle_order()[first .. first + count); an inner node has count == 0, its left
  /// child at (its own index + 1) and its right child at `first`.
  struct Node {
    Aabb box;             ///< bounds of every triangle below the node (mesh frame, m)
    std::int32_t first = 0;
    std::int32_t count = 0;
    bool is_leaf() const { return count > 0; }
  };

  /// Builds the tree over `triangles` (indices into `vertices`). The inputs must be valid
  /// (TriangleMesh validates them first); an empty triangle list gives an empty tree.
  TriangleMeshBvh(const std::vector<Vec3>& vertices,
                  const std::vector<std::array<int, 3>>& triangles);

  /// Number of nodes (0 for an empty tree). The root is node 0.
  int node_count() const { return static_cast<int>(nodes_.size()); }
  const Node& node(int i) const { return nodes_[i]; }
  const std::vector<Node>& nodes() const { return nodes_; }
  /// Bounds of node i (mesh frame, m).
  const Aabb& node_bounds(int i) const { return nodes_[i].box; }
  /// Bounds of the whole mesh (empty box for an empty tree).
  Aabb root_bounds() const { return nodes_.empty() ? Aabb() : nodes_[0].box; }
  /// Triangle indices in leaf order (leaves refer to ranges of it).
  const std::vector<std::int32_t>& triangle_order() const { return order_; }
  /// Bounding box of triangle_order()[k] (mesh frame, m).
  const Aabb& leaf_triangle_box(int k) const { return boxes_[k]; }
  /// Depth of the tree (1 for a single leaf, 0 when empty).
  int depth() const { return depth_; }

  /// Calls `visit(int triangle)` once for every triangle whose axis-aligned bounding box
  /// overlaps `box` (mesh frame; closed intervals, so touching boxes count), in a fixed
  /// depth-first order. This is exactly the set a brute-force loop over the triangles'
  /// boxes would give. If `visit` returns bool, returning false stops the query early.
  /// No heap allocation.
  template <class F>
  void query_aabb(const Aabb& box, F&& visit) const {
    if (nodes_.empty() || box.empty()) return;
    std::int32_t stack[kStackSize];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      std::int32_t i = stack[--top];
      for (;;) {
        const Node& n = nodes_[i];
        if (!n.box.overlaps(box)) break;
        if (n.is_leaf()) {
          for (std::int32_t k = n.first; k < n.first + n.count; ++k) {
            if (!boxes_[k].overlaps(box)) continue;
            if constexpr (std::is_same_v<std::invoke_result_t<F&, int>, bool>) {
              if (!visit(static_cast<int>(order_[k]))) return;
            } else {
              visit(static_cast<int>(order_[k]));
            }
          }
          break;
        }
        stack[top++] = n.first;  // right child later
        i = i + 1;               // left child now
      }
    }
  }

  /// Ray traversal: calls `visit(int triangle, Real& max_t)` for the triangles of every
  /// leaf whose box the ray origin + t * dir meets with 0 <= t <= max_t (mesh frame, t in
  /// units of |dir|). `visit` may lower max_t (a closer hit), which prunes the rest of
  /// the walk; the nearer child is visited first. No heap allocation.
  template <class F>
  void query_ray(const Vec3& origin, const Vec3& dir, Real max_t, F&& visit) const {
    if (nodes_.empty()) return;
    Real t_enter;
    if (!ray_box(nodes_[0].box, origin, dir, max_t, t_enter)) return;
    std::int32_t stack[kStackSize];
    int top = 0;
    stack[top++] = 0;
    while (top > 0) {
      const std::int32_t i = stack[--top];
      const Node& n = nodes_[i];
      // Boxes were tested when pushed; test again since max_t may have shrunk since.
      if (!ray_box(n.box, origin, dir, max_t, t_enter)) continue;
      if (n.is_leaf()) {
        for (std::int32_t k = n.first; k < n.first + n.count; ++k)
          visit(static_cast<int>(order_[k]), max_t);
        continue;
      }
      const std::int32_t l = i + 1, r = n.first;
      Real tl, tr;
      const bool hl = ray_box(nodes_[l].box, origin, dir, max_t, tl);
      const bool hr = ray_box(nodes_[r].box, origin, dir, max_t, tr);
      // Push the far child first so the near one is popped first.
      if (hl && hr) {
        if (tl <= tr) {
          stack[top++] = r;
          stack[top++] = l;
        } else {
          stack[top++] = l;
          stack[top++] = r;
        }
      } else if (hl) {
        stack[top++] = l;
      } else if (hr) {
        stack[top++] = r;
      }
    }
  }

  /// Slab test (Kay & Kajiya 1986; Ericson 5.3.3): true if origin + t * dir meets `box`
  /// for some t in [0, max_t]; `t_enter` is the first such t. A zero component of `dir`
  /// is handled explicitly (the origin must then lie within that slab), so no 0 * inf
  /// NaN can arise.
  static bool ray_box(const Aabb& box, const Vec3& origin, const Vec3& dir, Real max_t,
                      Real& t_enter) {
    Real t0 = 0, t1 = max_t;
    for (int k = 0; k < 3; ++k) {
      if (dir[k] == 0) {
        if (origin[k] < box.min[k] || origin[k] > box.max[k]) return false;
        continue;
      }
      const Real inv = Real(1) / dir[k];
      Real ta = (box.min[k] - origin[k]) * inv;
      Real tb = (box.max[k] - origin[k]) * inv;
      if (ta > tb) std::swap(ta, tb);
      if (ta > t0) t0 = ta;
      if (tb < t1) t1 = tb;
      if (t0 > t1) return false;
    }
    t_enter = t0;
    return true;
  }

 private:
  struct BuildItem;
  int build(std::vector<BuildItem>& items, int begin, int end, int depth);

  std::vector<Node> nodes_;
  std::vector<std::int32_t> order_;
  std::vector<Aabb> boxes_;
  int depth_ = 0;
};

/// Ray-triangle intersection (Möller & Trumbore 1997), two-sided. Returns true with the
/// ray parameter `t` (units of |dir|, 0 <= t <= max_t) if origin + t * dir meets the
/// triangle (v0, v1, v2). Barycentric coordinates are accepted down to -1e-12 (about
/// 4500 ulp of 1): a ray through a shared edge or vertex then hits at least one of the
/// triangles despite round-off. A ray parallel to the triangle's plane (zero
/// determinant) misses.
bool ray_triangle(const Vec3& v0, const Vec3& v1, const Vec3& v2, const Vec3& origin,
                  const Vec3& dir, Real max_t, Real& t);

/// Closest hit of the ray origin + t * dir, 0 <= t <= max_t (mesh frame, t in units of
/// |dir|) with the mesh, through its BVH. Both faces of every triangle are hit (a mesh
/// is a surface, not a solid). On a hit: `distance` = t, `point` = origin + t * dir,
/// `child` = the triangle index, and `normal` = the triangle's unit normal turned to face
/// the ray (the normal of the side that was hit: the face normal for a front-face hit,
/// its negation for a back-face hit). Equal distances go to the lower triangle index, so
/// the answer does not depend on the traversal order. A zero or non-finite direction or
/// origin, or a NaN max_t, gives no hit. No heap allocation.
RayHit raycast_mesh(const TriangleMesh& mesh, const Vec3& origin, const Vec3& dir, Real max_t);

}  // namespace wmo
