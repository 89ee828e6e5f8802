// Box-box contact manifold by the separating axis test (Ericson, Real-Time Collision
// Detection 4.4.1 and 5.2.1; Gregorius, "The Separating Axis Test between Convex
// Polyhedra", GDC 2013, and "Robust Contact Creation for Physics Simulations",
// GDC 2015).
//
// Two boxes are disjoint iff one of 15 axes separates them: the 3 face normals of A,
// the 3 of B and the 9 cross products of an edge direction of A with one of B. The
// Minkowski difference of two boxes is a polytope whose face normals are among those
// 15 axes, so the axis of least overlap is also the exact minimum translation
// direction and its overlap the exact penetration depth (up to the face bias below).
//
// Rounded boxes: the test runs on the cores (Box::core_half_extents()); the radii are
// added afterwards (depth += ra + rb, points pushed out along the normal), which is
// exact because a rounded box is its core inflated by a ball.
//
// Manifold:
//   * face axis: the face of the chosen box along the axis is the reference face; the
//     face of the other box most anti-parallel to it is the incident face; the
//     incident face is clipped against the reference face's side planes
//     (Sutherland-Hodgman, clip.h), points with depth >= -margin are kept and reduced
//     to at most 4 (reduce_to_4); if none survives, B's deepest corner (moved onto the
//     reference plane) is the single point;
//   * edge axis: one point, the closest points of the two supporting edges.
// Face axes are preferred over edge axes, and A's faces over B's, within the tolerance
// of clip::sat_better (documented there), so resting stacks do not flip between face
// and edge contacts. Speculative contacts: a separating axis with separation <= margin
// still produces the manifold, with negative depths.
//
// Feature ids: clip::face_contact_id / clip::edge_contact_id (clip.h) with the box face
// codes 2 * axis + (negative side) and edge codes 4 * axis + sign bits.
//
// Everything is computed in A's frame; no allocation, no virtual calls.

#include <cmath>

#include "clip.h"
#include "manifold_reduce.h"
#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

/// An edge axis e_i x R_j with |e_i x R_j| = sin(angle) below this is skipped: the
/// edges are parallel within 1e-6 rad, their cross product's direction is dominated
/// by round-off and any separating axis it would give is, within that angle, already
/// covered by a face axis (the edges then lie in a common face direction).
constexpr Real kParallelSin = 1e-6;

inline Real sign_of(Real x) { return x < 0 ? Real(-1) : Real(1); }

enum class AxisKind { kFaceA, kFaceB, kEdge };

/// The 4 vertices of the face of a box (half extents h, frame: rotation R, centre c,
/// all in A's frame) with outward normal s * R.col(axis), CCW seen from outside.
inline void box_face(const Mat3& R, const Vec3& c, const Vec3& h, int axis, Real s, Vec3* out) {
  const int i1 = (axis + 1) % 3, i2 = (axis + 2) % 3;
  const Vec3 fc = c + s * h[axis] * R.col(axis);
  const Vec3 u = h[i1] * R.col(i1);
  const Vec3 v = s * h[i2] * R.col(i2);
  out[0] = fc + u + v;
  out[1] = fc - u + v;
  out[2] = fc - u - v;
  out[3] = fc + u - v;
}

inline int face_code(int axis, Real s) { return 2 * axis + (s < 0 ? 1 : 0); }

}  // namespace

bool collide_box_box(const Box& a, const Box& b, const Pose& b_in_a, Real margin, Manifold& m) {
  const Vec3& ha = a.core_half_extents();
  const Vec3& hb = b.core_half_extents();
  const Real ra = a.radius(), rb = b.radius();
  const Mat3 R = b_in_a.matrix();  // columns: B's axes in A's frame
  const Mat3 AR = R.cwiseAbs();
  const Vec3& t = b_in_a.position;
  // Core separations above this mean the full shapes are further apart than margin.
  const Real reach = ra + rb + margin;
  const Real size = std::max(a.half_extents().maxCoeff(), b.half_extents().maxCoeff());

  // ---- Face axes of A: e_i. Projected radius of B on e_i is sum_j |R_ij| hb_j.
  Real sep_a = -kInf;
  int axis_a = 0;
  for (int i = 0; i < 3; ++i) {
    const Real s = std::abs(t[i]) - (ha[i] + AR.row(i).dot(hb));
    if (s > reach) return false;
    if (s > sep_a) {
      sep_a = s;
      axis_a = i;
    }
  }
  // ---- Face axes of B: R_j.
  Real sep_b = -kInf;
  int axis_b = 0;
  for (int j = 0; j < 3; ++j) {
    const Real s = std::abs(t.dot(R.col(j))) - (hb[j] + AR.col(j).dot(ha));
    if (s > reach) return false;
    if (s > sep_b) {
      sep_b = s;
      axis_b = j;
    }
  }
  // ---- Edge axes: e_i x R_j, normalised (Ericson 4.4.1 works unnormalised for a
  // boolean test; the depth needs the true distance).
  Real sep_e = -kInf;
  int edge_i = 0, edge_j = 0;
  Vec3 n_e = Vec3::UnitX();
  for (int i = 0; i < 3; ++i) {
    for (int j = 0; j < 3; ++j) {
      Vec3 n = Vec3::Unit(i).cross(R.col(j));
      const Real len = n.norm();
      if (len < kParallelSin) continue;
      n /= len;
      const Real s = std::abs(t.dot(n)) - (n.cwiseAbs().dot(ha) + (R.transpose() * n).cwiseAbs().dot(hb));
      if (s > reach) return false;
      if (s > sep_e) {
        sep_e = s;
        edge_i = i;
        edge_j = j;
        n_e = n;
      }
    }
  }

  // ---- Axis choice with the face bias (clip::sat_better).
  AxisKind kind = AxisKind::kFaceA;
  Real best = sep_a;
  if (clip::sat_better(sep_b, best, size)) {
    kind = AxisKind::kFaceB;
    best = sep_b;
  }
  if (clip::sat_better(sep_e, best, size)) kind = AxisKind::kEdge;

  if (kind == AxisKind::kEdge) {
    // Normal from A to B: the side of B's centre (ties to +).
    const Vec3 N = sign_of(t.dot(n_e)) * n_e;
    // Supporting edge of A along N: parallel to e_i, at the signs of N in the other
    // two axes. Supporting edge of B along -N: parallel to R_j.
    const int a1 = (edge_i + 1) % 3, a2 = (edge_i + 2) % 3;
    Vec3 ca = Vec3::Zero();
    ca[a1] = sign_of(N[a1]) * ha[a1];
    ca[a2] = sign_of(N[a2]) * ha[a2];
    Vec3 ea = Vec3::Zero();
    ea[edge_i] = ha[edge_i];
    const int b1 = (edge_j + 1) % 3, b2 = (edge_j + 2) % 3;
    const Real sb1 = sign_of(-N.dot(R.col(b1))), sb2 = sign_of(-N.dot(R.col(b2)));
    const Vec3 cb = t + sb1 * hb[b1] * R.col(b1) + sb2 * hb[b2] * R.col(b2);
    const Vec3 eb = hb[edge_j] * R.col(edge_j);
    Vec3 pa_core, pb_core;
    clip::closest_points_segments(ca - ea, ca + ea, cb - eb, cb + eb, pa_core, pb_core);
    const Real depth = N.dot(pa_core - pb_core) + ra + rb;
    if (!(depth >= -margin)) return false;
    const int code_a = 4 * edge_i + (N[a1] < 0 ? 1 : 0) + (N[a2] < 0 ? 2 : 0);
    const int code_b = 4 * edge_j + (sb1 < 0 ? 1 : 0) + (sb2 < 0 ? 2 : 0);
    const Vec3 pa = pa_core + ra * N;
    m.normal = N;
    m.count = 0;
    m.add(pa, pa - depth * N, depth, clip::edge_contact_id(code_a, code_b));
    return true;
  }

  // ---- Face contact.
  const bool ref_on_a = kind == AxisKind::kFaceA;
  Vec3 N;
  Vec3 ref[4], inc[4];
  int ref_face, inc_face;
  const Mat3 I = Mat3::Identity();
  if (ref_on_a) {
    const Real s = sign_of(t[axis_a]);
    N = s * Vec3::Unit(axis_a);
    box_face(I, Vec3::Zero(), ha, axis_a, s, ref);
    ref_face = face_code(axis_a, s);
    // Incident face of B: the face whose normal is most anti-parallel to N.
    int j = 0;
    for (int k = 1; k < 3; ++k)
      if (AR(axis_a, k) > AR(axis_a, j)) j = k;
    const Real sj = -sign_of(N.dot(R.col(j)));
    box_face(R, t, hb, j, sj, inc);
    inc_face = face_code(j, sj);
  } else {
    const Real s = sign_of(t.dot(R.col(axis_b)));
    N = s * R.col(axis_b);  // B's reference face has outward normal -N
    box_face(R, t, hb, axis_b, -s, ref);
    ref_face = face_code(axis_b, -s);
    int i = 0;
    for (int k = 1; k < 3; ++k)
      if (AR(k, axis_b) > AR(i, axis_b)) i = k;
    const Real si = sign_of(N[i]);
    box_face(I, Vec3::Zero(), ha, i, si, inc);
    inc_face = face_code(i, si);
  }
  const std::uint32_t id_base = clip::face_contact_id(!ref_on_a, ref_face, inc_face);
  ContactPoint pts[clip::kMaxClipVertices];
  int n = clip::clip_features(ref, 4, ref_on_a, inc, 4, N, ra, rb, margin, id_base, pts);
  // Unlike hulls (clip::kDeepestPointTolerance), no deepest point is added to a
  // non-empty clip: a box's support corner along -N belongs to the incident face, so
  // the clip loses it only when it lies outside the reference face's prism, where it
  // would not be on A. An empty clip reports that corner as its single point.
  const Real sat_depth = -best + ra + rb;
  if (n == 0 && sat_depth >= -margin) {
    Vec3 p_core;
    if (ref_on_a) {
      // Deepest corner of B's core along -N (ties to +), moved onto A's core plane.
      const Vec3 u = R.transpose() * -N;
      Vec3 corner;
      for (int k = 0; k < 3; ++k) corner[k] = sign_of(u[k]) * hb[k];
      p_core = t + R * corner - best * N;
    } else {
      for (int k = 0; k < 3; ++k) p_core[k] = sign_of(N[k]) * ha[k];
    }
    const Vec3 pa = p_core + ra * N;
    pts[n++] = ContactPoint{pa, pa - sat_depth * N, sat_depth, id_base | clip::kFallbackLabel};
  }
  if (n == 0) return false;
  m.normal = N;
  reduce_to_4(pts, n, N, m);
  return true;
}

}  // namespace wmo
