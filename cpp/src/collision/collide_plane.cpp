// Plane (half-space) A against any convex shape B.
//
// The plane is { x : dot(n, x) <= offset } in A's frame, so the contact normal (A to B)
// is the plane normal n for every point, and a point x of B's surface has
// depth = offset - dot(n, x). Each point is generated on B's surface (point_b = x) and
// projected onto the plane (point_a = x + depth * n), which gives
// point_b = point_a - depth * n exactly as types.h requires.
//
// Which points of B: the features of B facing the plane, chosen per shape type so no
// iteration and no allocation is needed:
//   sphere:   the centre pushed by the radius (1 point),
//   capsule:  both segment ends pushed by the radius (up to 2),
//   box:      the 4 deepest core corners pushed by the rounding,
//   cylinder: 4 rim points of the lower cap (deepest, opposite, and the two at 90
//             degrees) and the deepest rim point of the upper cap; the 4 deepest kept
//             (a cylinder on its side gives the 2 ends of its bottom line),
//   hull:     the vertices of the supporting face in -n (plus the support vertex, in
//             case the face misses it), reduced to 4 by reduce_to_4.
// Points deeper than -margin are kept.
//
// Feature ids: the plane has one feature (0), so the id is B's feature code:
//   sphere 0; capsule end index (0: y = -h, 1: y = +h); box corner index with bit i set
//   for the +h_i side of axis i; cylinder 4 * cap + k (cap 0: y = -h, 1: y = +h;
//   k = 0 deepest rim point, 1 opposite, 2 and 3 at +-90 degrees); hull
//   kMaxFaceVertices * face.feature + vertex index in the face, and 0xFFFF for the
//   extra support vertex.

#include <algorithm>
#include <cmath>

#include "manifold_reduce.h"
#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

/// A horizontal cylinder's cap has no preferred "deepest" rim direction; below this
/// length of the plane normal's projection on the cap plane (unit normal, so it is a
/// sine) the cap counts as flat and a fixed rim direction is used. 1e-12 is round-off
/// level for a unit vector.
constexpr Real kFlatCapSine = 1e-12;

/// Id of the extra support vertex added to a hull's supporting face.
constexpr std::uint32_t kSupportVertexId = 0xFFFF;

/// Indices of the (up to 4) deepest of depth[0..n) that are >= -margin, deepest first;
/// ties go to the lower index, so the choice depends only on the input order.
/// Returns how many were written to idx.
inline int select_deepest(const Real* depth, int n, Real margin, int* idx) {
  unsigned taken = 0;
  int count = 0;
  for (; count < kMaxManifoldPoints && count < n; ++count) {
    int best = -1;
    for (int j = 0; j < n; ++j)
      if (!(taken >> j & 1u) && (best < 0 || depth[j] > depth[best])) best = j;
    if (depth[best] < -margin) break;
    taken |= 1u << best;
    idx[count] = best;
  }
  return count;
}

}  // namespace

bool collide_plane_convex(const Plane& a, const ConvexShape& b, const Pose& b_in_a, Real margin,
                          Manifold& m) {
  const Vec3& n = a.normal();
  // One rotation matrix serves every transform (cheaper than repeated quaternion
  // rotations). The plane in B's frame: dot(n_b, x) <= offset_b.
  const Mat3 rot = b_in_a.rotation.toRotationMatrix();
  const Vec3 n_b = rot.transpose() * n;
  const Real offset_b = a.offset() - n.dot(b_in_a.position);

  // Every branch first rejects on B's deepest point; past that at least one point is
  // added, so m can be written directly (it stays untouched on a miss).
  auto begin = [&]() {
    m.normal = n;
    m.count = 0;
  };
  // Adds B's surface point x (B's frame) with its depth: point_b = x in A's frame,
  // point_a its projection on the plane.
  auto add = [&](const Vec3& x, Real depth, std::uint32_t id) {
    const Vec3 pb = rot * x + b_in_a.position;
    m.add(pb + depth * n, pb, depth, id);
  };

  switch (b.type()) {
    case ShapeType::kSphere: {
      const Real depth = offset_b + b.radius();
      if (depth < -margin) return false;
      begin();
      add(-b.radius() * n_b, depth, 0);
      return true;
    }
    case ShapeType::kCapsule: {
      const auto& cap = static_cast<const Capsule&>(b);
      const Real h = cap.half_height(), rad = cap.radius();
      const Real depth[2] = {offset_b + h * n_b.y() + rad, offset_b - h * n_b.y() + rad};
      // A zero-length capsule is a sphere: one point, not two coincident ones.
      int idx[2];
      const int k = select_deepest(depth, h > 0 ? 2 : 1, margin, idx);
      if (k == 0) return false;
      begin();
      for (int i = 0; i < k; ++i)
        add(Vec3(0, idx[i] == 0 ? -h : h, 0) - rad * n_b, depth[idx[i]],
            static_cast<std::uint32_t>(idx[i]));
      return true;
    }
    case ShapeType::kBox: {
      const auto& box = static_cast<const Box&>(b);
      const Vec3& hc = box.core_half_extents();
      const Real rad = box.radius();
      // Corner k (bit i set: +hc_i) has depth base - sum_i (+-) hc_i n_b_i. The deepest
      // corner k0 takes -sign(n_b_i) on every axis; flipping axis i costs 2 |hc_i n_b_i|.
      // With the axes sorted by that cost (a0 <= a1 <= a2), the 4 deepest corners are
      // k0, k0^a0, k0^a1 and the better of k0^a0^a1 and k0^a2: no sort of 8 needed.
      const Vec3 proj = hc.cwiseProduct(n_b);
      const Vec3 cost = 2 * proj.cwiseAbs();
      const Real deepest = offset_b + rad + 0.5 * cost.sum();
      if (deepest < -margin) return false;
      int k0 = 0;
      for (int i = 0; i < 3; ++i)
        if (proj[i] < 0) k0 |= 1 << i;
      // Stable sort of the 3 axes by cost (ties: lower axis first).
      int ax[3] = {0, 1, 2};
      if (cost[ax[1]] < cost[ax[0]]) std::swap(ax[0], ax[1]);
      if (cost[ax[2]] < cost[ax[1]]) std::swap(ax[1], ax[2]);
      if (cost[ax[1]] < cost[ax[0]]) std::swap(ax[0], ax[1]);
      const int b0 = 1 << ax[0], b1 = 1 << ax[1], b2 = 1 << ax[2];
      const Real c01 = cost[ax[0]] + cost[ax[1]], c2 = cost[ax[2]];
      const int corners[4] = {k0, k0 ^ b0, k0 ^ b1, c01 <= c2 ? k0 ^ b0 ^ b1 : k0 ^ b2};
      const Real drops[4] = {0, cost[ax[0]], cost[ax[1]], c01 <= c2 ? c01 : c2};
      begin();
      for (int i = 0; i < 4; ++i) {
        const Real depth = deepest - drops[i];
        if (depth < -margin) break;  // depths are non-increasing
        const int k = corners[i];
        const Vec3 v((k & 1) ? hc.x() : -hc.x(), (k & 2) ? hc.y() : -hc.y(),
                     (k & 4) ? hc.z() : -hc.z());
        add(v - rad * n_b, depth, static_cast<std::uint32_t>(k));
      }
      return true;
    }
    case ShapeType::kCylinder: {
      const auto& cyl = static_cast<const Cylinder&>(b);
      const Real h = cyl.half_height(), rad = cyl.cylinder_radius();
      // Lower cap: the one further along -n_b (cap 0 on a tie).
      const int lower = n_b.y() < 0 ? 1 : 0;
      const Real y_lo = lower == 0 ? -h : h;
      // Deepest rim direction: -n_b projected on the cap plane (XZ).
      Vec3 u(-n_b.x(), 0, -n_b.z());
      const Real ul = u.norm();
      u = ul > kFlatCapSine ? Vec3(u / ul) : Vec3(Vec3::UnitX());
      const Vec3 w(u.z(), 0, -u.x());  // Y x u, the rim direction at 90 degrees
      const Vec3 cl(0, y_lo, 0), cu(0, -y_lo, 0);
      const Vec3 pts[5] = {cl + rad * u, cl - rad * u, cl + rad * w, cl - rad * w, cu + rad * u};
      Real depth[5];
      for (int k = 0; k < 5; ++k) depth[k] = offset_b - n_b.dot(pts[k]);
      int idx[4];
      const int count = select_deepest(depth, 5, margin, idx);
      if (count == 0) return false;
      begin();
      const std::uint32_t base_lo = 4u * static_cast<std::uint32_t>(lower);
      const std::uint32_t base_up = 4u * static_cast<std::uint32_t>(1 - lower);
      for (int i = 0; i < count; ++i) {
        const int k = idx[i];
        add(pts[k], depth[k], k < 4 ? base_lo + static_cast<std::uint32_t>(k) : base_up);
      }
      return true;
    }
    case ShapeType::kConvexHull:
    default: {
      // Deepest vertex first: a cheap early out, and a guard for a supporting face that
      // does not contain it. ConvexHull is final, so these calls are devirtualised.
      SupportingFace face;
      Vec3 deepest;
      if (b.type() == ShapeType::kConvexHull) {
        const auto& hull = static_cast<const ConvexHull&>(b);
        deepest = hull.support(-n_b);
        if (offset_b - n_b.dot(deepest) < -margin) return false;
        hull.supporting_face(-n_b, face);
      } else {
        deepest = b.support(-n_b);
        if (offset_b - n_b.dot(deepest) < -margin) return false;
        b.supporting_face(-n_b, face);
      }
      const Real deepest_depth = offset_b - n_b.dot(deepest);
      ContactScratch<kMaxFaceVertices + 1> pts;
      int count = 0;
      Real face_best = -kInf;
      const int nv = std::min(face.count, kMaxFaceVertices);
      for (int k = 0; k < nv; ++k) {
        const Vec3& v = face.vertices[k];
        const Real depth = offset_b - n_b.dot(v);
        face_best = std::max(face_best, depth);
        if (depth < -margin) continue;
        const Vec3 pb = rot * v + b_in_a.position;
        const std::uint32_t id = face.feature * kMaxFaceVertices + static_cast<std::uint32_t>(k);
        pts[count++] = ContactPoint{pb + depth * n, pb, depth, id};
      }
      // The face should hold the support vertex; if round-off or an unusual hull says
      // otherwise by more than 1e-9 m (far below contact scale, far above round-off),
      // add it so the deepest point is never lost.
      if (deepest_depth > face_best + 1e-9) {
        const Vec3 pb = rot * deepest + b_in_a.position;
        pts[count++] = ContactPoint{pb + deepest_depth * n, pb, deepest_depth, kSupportVertexId};
      }
      if (count == 0) return false;
      begin();
      reduce_to_4(pts.data(), count, n, m);
      return true;
    }
  }
}

}  // namespace wmo
