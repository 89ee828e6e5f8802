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
//     (Sutherland-Hodgman, with the rules of clip.h), points with depth >= -margin are
//     kept and reduced to at most 4 (reduce_to_4); if none survives, the incident
//     box's deepest corner is the single point;
//   * edge axis: one point, the closest points of the two supporting edges.
// Face axes are preferred over edge axes, and A's faces over B's, within the tolerance
// of clip::sat_better (documented there), so resting stacks do not flip between face
// and edge contacts. Speculative contacts: a separating axis with separation <= margin
// still produces the manifold, with negative depths.
//
// Feature ids: clip::face_contact_id / clip::edge_contact_id (clip.h) with the box face
// codes 2 * axis + (negative side) and edge codes 4 * axis + sign bits.
//
// Cost (Gottschalk et al. 1996, "OBBTree"): the 15 axes reuse the entries of the
// rotation matrix, so an edge axis costs a few products and one square root; a face
// contact is clipped in the reference box's own frame, where its side planes are
// axis-aligned (4 comparisons per vertex and plane, no plane normals to build), and
// the clipped polygon has at most 8 vertices. Everything lives in fixed-size arrays on
// the stack: no allocation, no virtual calls.

#include <array>
#include <cmath>

#include "clip.h"
#include "manifold_reduce.h"
#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

/// See exact_path in collide_box_box: how closely (relative to the box size) a clipped
/// point's depth must match the SAT separation for a separated face contact to count as
/// exact.
constexpr Real kSeparatedExactRel = 1e-9;


/// An edge axis e_i x R_j with |e_i x R_j| = sin(angle) below this is skipped: the
/// edges are parallel within 1e-6 rad, their cross product's direction is dominated
/// by round-off and any separating axis it would give is, within that angle, already
/// covered by a face axis (the edges then lie in a common face direction).
constexpr Real kParallelSin = 1e-6;

inline Real sign_of(Real x) { return x < 0 ? Real(-1) : Real(1); }

enum class AxisKind { kFaceA, kFaceB, kEdge };

/// A box face (4 vertices) clipped by the 4 side planes of another: at most 8
/// vertices; the spare room only guards against round-off breaking convexity.
constexpr int kMaxBoxClip = 12;

struct BoxClipPolygon {
  int count = 0;
  std::array<clip::ClipVertex, kMaxBoxClip> v;
};

/// Sutherland-Hodgman against the axis-aligned half-space sgn * p[k] <= lim, with the
/// rules of clip::clip_half_space (a vertex within `slack` outside counts as inside;
/// intersections only between a vertex strictly inside and one beyond the slack, put
/// exactly on the plane; a 1- or 2-vertex input is a point or a segment).
inline void clip_axis(const BoxClipPolygon& in, int k, Real sgn, Real lim, Real slack,
                      std::uint8_t label, BoxClipPolygon& out) {
  out.count = 0;
  const int n = in.count;
  auto push = [&](const Vec3& p, std::uint8_t a, std::uint8_t b) {
    if (out.count < kMaxBoxClip) out.v[out.count++] = clip::ClipVertex{p, a, b};
  };
  const int edges = n == 2 ? 1 : n;
  for (int i = 0; i < n; ++i) {
    const clip::ClipVertex& a = in.v[i];
    const Real da = sgn * a.p[k] - lim;
    if (da <= slack) push(a.p, a.in, a.out);
    if (i >= edges) break;
    const clip::ClipVertex& b = in.v[(i + 1) % n];
    const Real db = sgn * b.p[k] - lim;
    if ((da < 0 && db > slack) || (da > slack && db < 0)) {
      Vec3 x = a.p + (da / (da - db)) * (b.p - a.p);
      x[k] = sgn * lim;
      if (da < 0) push(x, a.out, label);  // leaving
      else push(x, label, a.out);         // entering
    }
  }
}

/// The 4 vertices of the face of a box with outward normal s * e_axis, in the order
/// of clip::clip_to_prism's reference polygons: centre fc, u = h1 e1, v = s h2 e2,
/// vertices fc + u + v, fc - u + v, fc - u - v, fc + u - v (CCW seen from outside).
/// Given the box's axes as the columns of `axes` and its centre `c`.
inline void box_face(const Mat3& axes, const Vec3& c, const Vec3& h, int axis, Real s, Vec3* out) {
  const int i1 = (axis + 1) % 3, i2 = (axis + 2) % 3;
  const Vec3 fc = c + s * h[axis] * axes.col(axis);
  const Vec3 u = h[i1] * axes.col(i1);
  const Vec3 v = s * h[i2] * axes.col(i2);
  out[0] = fc + u + v;
  out[1] = fc - u + v;
  out[2] = fc - u - v;
  out[3] = fc + u - v;
}

/// Clips the incident quad inc[0..4) (in the reference box's local frame) to the
/// prism of the reference face of a box of half extents h with outward normal
/// s * e_axis. Side plane labels 32 + k follow the edges k of box_face (edge 0 at
/// +v, 1 at -u, 2 at -v, 3 at +u), so the labels equal those of clip::clip_to_prism
/// for the same faces (hull-hull on box hulls gives the same ids). The slack is
/// clip::kClipSlackRel times the face's centre-to-corner distance, as there.
inline void clip_to_box_face(const Vec3* inc, const Vec3& h, int axis, Real s, BoxClipPolygon& poly) {
  const int i1 = (axis + 1) % 3, i2 = (axis + 2) % 3;
  poly.count = 4;
  for (int k = 0; k < 4; ++k)
    poly.v[k] = clip::ClipVertex{inc[k], static_cast<std::uint8_t>((k + 3) % 4), static_cast<std::uint8_t>(k)};
  const Real slack = clip::kClipSlackRel * std::hypot(h[i1], h[i2]);
  BoxClipPolygon tmp;
  clip_axis(poly, i2, s, h[i2], slack, 32, tmp);
  clip_axis(tmp, i1, -1, h[i1], slack, 33, poly);
  clip_axis(poly, i2, -s, h[i2], slack, 34, tmp);
  clip_axis(tmp, i1, 1, h[i1], slack, 35, poly);
}

inline int face_code(int axis, Real s) { return 2 * axis + (s < 0 ? 1 : 0); }

}  // namespace

bool collide_box_box(const Box& a, const Box& b, const Pose& b_in_a, Real margin, Manifold& m) {
  const Vec3& ha = a.core_half_extents();
  const Vec3& hb = b.core_half_extents();
  const Real ra = a.radius(), rb = b.radius();
  const Mat3 R = b_in_a.matrix();  // columns: B's axes in A's frame; R(i, j) = e_i . R_j
  const Mat3 AR = R.cwiseAbs();
  const Vec3& t = b_in_a.position;
  const Vec3 tb = R.transpose() * t;  // B's centre offset in B's axes
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
    const Real s = std::abs(tb[j]) - (hb[j] + AR.col(j).dot(ha));
    if (s > reach) return false;
    if (s > sep_b) {
      sep_b = s;
      axis_b = j;
    }
  }
  // ---- Edge axes L = e_i x R_j (Gottschalk 1996; Ericson 4.4.1): with (i, i1, i2) and
  // (j, j1, j2) cyclic, L has components L[i1] = -R(i2, j), L[i2] = R(i1, j), so
  //   t . L = t[i2] R(i1, j) - t[i1] R(i2, j),
  //   A's projected radius ha[i1] |R(i2, j)| + ha[i2] |R(i1, j)|,
  //   B's projected radius hb[j1] |R(i, j2)| + hb[j2] |R(i, j1)|  (R_k . L = e_i . (R_j x R_k)),
  // and |L| = sqrt(R(i1, j)^2 + R(i2, j)^2) (= sin of the angle between e_i and R_j,
  // without the cancellation of sqrt(1 - R(i, j)^2)). The boolean test of Ericson works
  // unnormalised; the depth needs the true distance, hence the division by |L|.
  Real sep_e = -kInf;
  int edge_i = 0, edge_j = 0;
  for (int i = 0; i < 3; ++i) {
    const int i1 = (i + 1) % 3, i2 = (i + 2) % 3;
    for (int j = 0; j < 3; ++j) {
      const int j1 = (j + 1) % 3, j2 = (j + 2) % 3;
      const Real len = std::sqrt(R(i1, j) * R(i1, j) + R(i2, j) * R(i2, j));
      if (len < kParallelSin) continue;
      const Real tl = std::abs(t[i2] * R(i1, j) - t[i1] * R(i2, j));
      const Real rad = ha[i1] * AR(i2, j) + ha[i2] * AR(i1, j) + hb[j1] * AR(i, j2) + hb[j2] * AR(i, j1);
      const Real s = (tl - rad) / len;
      if (s > reach) return false;
      if (s > sep_e) {
        sep_e = s;
        edge_i = i;
        edge_j = j;
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

  // Cores apart (best > 0): the SAT separation is only a lower bound on the distance
  // (corner against corner it is smaller), so a speculative contact measured by it would
  // be too deep. It is exact in one case, the common one in a resting pile: a face axis
  // whose clipped incident points include one at that separation, since a point of B
  // inside A's face prism at distance s from the face plane is at distance s from A
  // (so distance <= s <= distance). Every other separated pair, and any rounded pair
  // with cores apart, gets the exact generic path (GJK distance on the cores).
  auto exact_path = [&] {
    CollideSettings s;
    s.margin = margin;
    m = Manifold{};
    return collide_convex_convex(a, b, b_in_a, s, m);
  };
  // The chosen axis's separation (best is the face axes' when an edge axis wins).
  const bool apart = (kind == AxisKind::kEdge ? sep_e : best) > 0;
  if (apart && (kind == AxisKind::kEdge || ra + rb > 0)) return exact_path();

  if (kind == AxisKind::kEdge) {
    const int i = edge_i, j = edge_j;
    const int a1 = (i + 1) % 3, a2 = (i + 2) % 3;
    Vec3 n_e = Vec3::Zero();
    n_e[a1] = -R(a2, j);
    n_e[a2] = R(a1, j);
    n_e.normalize();
    // Normal from A to B: the side of B's centre (ties to +).
    const Vec3 N = sign_of(t.dot(n_e)) * n_e;
    // Supporting edge of A along N: parallel to e_i, at the signs of N in the other
    // two axes. Supporting edge of B along -N: parallel to R_j.
    Vec3 ca = Vec3::Zero();
    ca[a1] = sign_of(N[a1]) * ha[a1];
    ca[a2] = sign_of(N[a2]) * ha[a2];
    Vec3 ea = Vec3::Zero();
    ea[i] = ha[i];
    const int b1 = (j + 1) % 3, b2 = (j + 2) % 3;
    const Real sb1 = sign_of(-N.dot(R.col(b1))), sb2 = sign_of(-N.dot(R.col(b2)));
    const Vec3 cb = t + sb1 * hb[b1] * R.col(b1) + sb2 * hb[b2] * R.col(b2);
    const Vec3 eb = hb[j] * R.col(j);
    Vec3 pa_core, pb_core;
    clip::closest_points_segments(ca - ea, ca + ea, cb - eb, cb + eb, pa_core, pb_core);
    const Real depth = N.dot(pa_core - pb_core) + ra + rb;
    if (!(depth >= -margin)) return false;
    const int code_a = 4 * i + (N[a1] < 0 ? 1 : 0) + (N[a2] < 0 ? 2 : 0);
    const int code_b = 4 * j + (sb1 < 0 ? 1 : 0) + (sb2 < 0 ? 2 : 0);
    const Vec3 pa = pa_core + ra * N;
    m.normal = N;
    m.count = 0;
    m.add(pa, pa - depth * N, depth, clip::edge_contact_id(code_a, code_b));
    return true;
  }

  // ---- Face contact, clipped in the reference box's frame (A's for a face of A, B's
  // local frame for a face of B), where the reference face is axis-aligned.
  const bool ref_on_a = kind == AxisKind::kFaceA;
  Vec3 N;
  Vec3 inc[4];
  int ref_axis, ref_face, inc_face;
  Real ref_sign;  // the reference face's outward normal is ref_sign * e_ref_axis (its own frame)
  if (ref_on_a) {
    ref_axis = axis_a;
    ref_sign = sign_of(t[axis_a]);
    N = ref_sign * Vec3::Unit(axis_a);
    // Incident face of B: the face whose normal is most anti-parallel to N.
    int j = 0;
    for (int k = 1; k < 3; ++k)
      if (AR(axis_a, k) > AR(axis_a, j)) j = k;
    const Real sj = -sign_of(ref_sign * R(axis_a, j));
    box_face(R, t, hb, j, sj, inc);
    inc_face = face_code(j, sj);
  } else {
    ref_axis = axis_b;
    const Real s = sign_of(tb[axis_b]);
    N = s * R.col(axis_b);
    ref_sign = -s;  // B's reference face faces A: outward normal -N
    int i = 0;
    for (int k = 1; k < 3; ++k)
      if (AR(k, axis_b) > AR(i, axis_b)) i = k;
    const Real si = sign_of(N[i]);
    // A's face, in B's frame: A's axes there are the rows of R, A's centre is -tb.
    box_face(R.transpose(), -tb, ha, i, si, inc);
    inc_face = face_code(i, si);
  }
  ref_face = face_code(ref_axis, ref_sign);
  const Vec3& h_ref = ref_on_a ? ha : hb;
  BoxClipPolygon poly;
  clip_to_box_face(inc, h_ref, ref_axis, ref_sign, poly);

  const std::uint32_t id_base = clip::face_contact_id(!ref_on_a, ref_face, inc_face);
  ContactPoint pts[kMaxBoxClip];
  int n = 0;
  Real max_clip = -kInf;
  for (int k = 0; k < poly.count; ++k) {
    const Vec3& p = poly.v[k].p;
    // Core depth: how far the incident point lies below the reference face plane.
    const Real depth = h_ref[ref_axis] - ref_sign * p[ref_axis] + ra + rb;
    max_clip = std::max(max_clip, depth);
    if (!(depth >= -margin)) continue;
    Vec3 pa_core;
    if (ref_on_a) {
      pa_core = p;  // B's point, moved onto A's face plane
      pa_core[ref_axis] = ref_sign * ha[ref_axis];
    } else {
      pa_core = R * p + t;  // A's point, back in A's frame
    }
    const Vec3 pa = pa_core + ra * N;
    pts[n++] = ContactPoint{pa, pa - depth * N, depth, id_base | poly.v[k].label()};
  }
  // Unlike hulls (clip::kDeepestPointTolerance), no deepest point is added to a
  // non-empty clip: a box's support corner along -N belongs to the incident face, so
  // the clip loses it only when it lies outside the reference face's prism, where it
  // would not be on A. An empty clip reports that corner as its single point.
  const Real sat_depth = -best + ra + rb;
  // Apart: exact only if a clipped point realises the separation (see exact_path);
  // 1e-9 of the size is far above the round-off between the two ways of computing it.
  if (apart && !(max_clip >= sat_depth - kSeparatedExactRel * size)) return exact_path();
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
