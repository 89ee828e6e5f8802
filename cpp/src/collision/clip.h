// Private helper of the collision layer: contact points between a reference feature
// and an incident feature by polygon clipping (Sutherland-Hodgman; Ericson 8.3.4), as
// used by the face contacts of box-box, hull-hull and the generic convex path.
//
// The reference feature (a polygon, or a segment) lies on one shape, the incident
// feature on the other; both are given in A's frame. The incident polygon is clipped
// against the "prism" swept by the reference feature along the manifold normal N
// (its side planes contain a reference edge and N), so the two features are compared
// in projection onto the plane perpendicular to N (Jolt's ManifoldBetweenTwoFaces
// idea). Each surviving point's depth is measured along N between the incident point
// and the reference plane. No allocation, no virtual calls.
//
// Clip vertex labels (part of the persistent feature ids): a clipped vertex is where
// two polygon edges meet; an edge is incident edge k (0..31: from incident vertex k to
// k + 1) or reference side plane j (32 + j). Label = in_edge * 64 + out_edge (12 bits).
// The label stays the same while the same two edges produce the vertex.
#pragma once

#include <algorithm>
#include <array>
#include <cmath>
#include <cstdint>

#include "wmo/geometry/shapes.h"
#include "wmo/types.h"

namespace wmo {
namespace clip {

/// A convex polygon of n vertices clipped by m half-spaces has at most n + m vertices.
constexpr int kMaxClipVertices = 2 * kMaxFaceVertices;

struct ClipVertex {
  Vec3 p;
  std::uint8_t in;   ///< label of the edge arriving at the vertex
  std::uint8_t out;  ///< label of the edge leaving it
  std::uint32_t label() const { return static_cast<std::uint32_t>(in) * 64u + out; }
};

struct ClipPolygon {
  int count = 0;
  std::array<ClipVertex, kMaxClipVertices> v;
};

/// Points up to kClipSlackRel * (size of the reference feature) outside a side plane
/// count as inside. An incident vertex exactly on a reference side plane (equal boxes
/// stacked flush) must not flicker between "kept" and "replaced by an intersection"
/// because of round-off, which is a few DBL_EPSILON (2.2e-16) times the coordinates;
/// 1e-13 is ~450 ulps above that, and a kept point then lies at most that far outside
/// the reference face, far below anything physical.
constexpr Real kClipSlackRel = 1e-13;

/// Incident polygon from n <= kMaxFaceVertices points: vertex k has in-edge k - 1 and
/// out-edge k. A segment's ends get (1, 0) and (0, 1); a point (0, 0).
inline void make_polygon(const Vec3* pts, int n, ClipPolygon& poly) {
  n = std::min(n, kMaxFaceVertices);
  poly.count = n;
  for (int k = 0; k < n; ++k) {
    const int in = n == 2 ? 1 - k : (k + n - 1) % n;
    poly.v[k] = ClipVertex{pts[k], static_cast<std::uint8_t>(in), static_cast<std::uint8_t>(k)};
  }
}

/// Sutherland-Hodgman against c.(x - o) <= 0 (c unit), a vertex within `slack` (m)
/// outside counting as inside. Intersections are computed on the exact plane, and only
/// for an edge from a vertex strictly inside to one outside (or back), so a vertex kept
/// by the slack is not duplicated by an intersection next to it. A 1- or 2-vertex input
/// is a point or a segment (no closing edge). `label` names the clip plane.
inline void clip_half_space(const ClipPolygon& in, const Vec3& c, const Vec3& o, Real slack,
                            std::uint8_t label, ClipPolygon& out) {
  out.count = 0;
  const int n = in.count;
  auto push = [&](const Vec3& p, std::uint8_t a, std::uint8_t b) {
    if (out.count < kMaxClipVertices) out.v[out.count++] = ClipVertex{p, a, b};
  };
  if (n == 1) {
    if (c.dot(in.v[0].p - o) <= slack) out.v[out.count++] = in.v[0];
    return;
  }
  const int edges = n == 2 ? 1 : n;
  for (int i = 0; i < n; ++i) {
    const ClipVertex& a = in.v[i];
    const Real da = c.dot(a.p - o);
    if (da <= slack) push(a.p, a.in, a.out);
    if (i >= edges) break;
    const ClipVertex& b = in.v[(i + 1) % n];
    const Real db = c.dot(b.p - o);
    // da and db strictly on opposite sides of the slab [0, slack]: da - db is far
    // from zero, and the intersection lies strictly between a and b.
    if (da < 0 && db > slack) push(a.p + (da / (da - db)) * (b.p - a.p), a.out, label);  // leaving
    else if (da > slack && db < 0) push(a.p + (da / (da - db)) * (b.p - a.p), label, a.out);  // entering
  }
}

/// Clips `poly` to the prism of the reference feature ref[0..nr) swept along `dir`:
/// for a polygon (nr >= 3, convex) the side planes through each edge containing `dir`;
/// for a segment (nr == 2) the two planes through its ends, perpendicular to the
/// segment's direction projected off `dir`. nr == 1 leaves `poly` unchanged. `scratch`
/// is the second buffer of the ping-pong (no copies per plane); the result is in
/// `poly`.
inline void clip_to_prism(ClipPolygon& poly, ClipPolygon& scratch, const Vec3* ref, int nr,
                          const Vec3& dir) {
  ClipPolygon* cur = &poly;
  ClipPolygon* next = &scratch;
  auto apply = [&](const Vec3& c, const Vec3& o, Real slack, int label) {
    clip_half_space(*cur, c, o, slack, static_cast<std::uint8_t>(label), *next);
    std::swap(cur, next);
  };
  if (nr == 2) {
    Vec3 s = ref[1] - ref[0];
    s -= s.dot(dir) * dir;
    const Real len = s.norm();
    if (len > 0) {
      s /= len;
      const Real slack = kClipSlackRel * len;
      apply(s, ref[1], slack, 32);
      apply(-s, ref[0], slack, 33);
    }
  } else if (nr >= 3) {
    Vec3 centre = Vec3::Zero();
    for (int k = 0; k < nr; ++k) centre += ref[k];
    centre /= nr;
    Real extent2 = 0;
    for (int k = 0; k < nr; ++k) extent2 = std::max(extent2, (ref[k] - centre).squaredNorm());
    const Real slack = kClipSlackRel * std::sqrt(extent2);
    for (int k = 0; k < nr && cur->count > 0; ++k) {
      const Vec3& a = ref[k];
      const Vec3& b = ref[(k + 1) % nr];
      Vec3 c = (b - a).cross(dir);
      const Real len = c.norm();
      if (!(len > 0)) continue;  // edge parallel to dir: no side plane
      c /= len;
      if (c.dot(centre - a) > 0) c = -c;  // outward: away from the polygon
      apply(c, a, slack, 32 + k);
    }
  }
  if (cur != &poly) {
    poly.count = cur->count;
    std::copy(cur->v.begin(), cur->v.begin() + cur->count, poly.v.begin());
  }
}

/// The reference plane's normal must make at least this cosine with N for depths to be
/// measured along N: beyond it (> 84 degrees) 1 / cos amplifies errors tenfold and
/// the feature is not a face contact anyway; callers then use a single point.
constexpr Real kMinPlaneCos = 0.1;

/// Contact points of the reference feature ref[0..nr) (on A if ref_on_a, else on B)
/// and the incident feature inc[0..ni) on the other shape, all in A's frame, for the
/// manifold normal N (unit, A to B). ra, rb: radii added on top of the features
/// (0 when the features are on the outer surface; the core radii for core features):
/// points are pushed out along N, depths grow by ra + rb. Points with
/// depth >= -margin are written to out (capacity kMaxClipVertices) with feature id
/// id_base | label; returns their number. Returns 0 when nothing survives or the
/// reference feature has no usable plane. `ref_normal`: the reference polygon's
/// outward unit plane normal (A's frame) where the caller knows it (a shape's face,
/// SupportingFace::normal); otherwise (nullptr, or a segment) it is computed from the
/// vertices.
inline int clip_features(const Vec3* ref, int nr, bool ref_on_a, const Vec3* inc, int ni,
                         const Vec3& N, Real ra, Real rb, Real margin, std::uint32_t id_base,
                         ContactPoint* out, const Vec3* ref_normal = nullptr) {
  if (nr < 2 || ni < 1) return 0;
  const Vec3 n_out = ref_on_a ? N : Vec3(-N);  // outward direction of the reference feature
  Vec3 n_ref;
  if (nr >= 3 && ref_normal) {
    n_ref = *ref_normal;
  } else {
    if (nr >= 3) {
      // Newell's method: robust plane normal of a (nearly) planar polygon.
      n_ref.setZero();
      for (int k = 0; k < nr; ++k) {
        const Vec3& a = ref[k];
        const Vec3& b = ref[(k + 1) % nr];
        n_ref += (a - b).cross(a + b) * -0.5;
      }
    } else {
      // Segment: the plane containing it and the direction perpendicular to it and N.
      const Vec3 s = (ref[1] - ref[0]).normalized();
      n_ref = n_out - n_out.dot(s) * s;
    }
    const Real len = n_ref.norm();
    if (!(len > 0)) return 0;
    n_ref /= len;
  }
  if (n_ref.dot(n_out) < 0) n_ref = -n_ref;
  const Real cos_n = n_ref.dot(N);  // > 0 for ref on A, < 0 for ref on B
  if (!(std::abs(cos_n) >= kMinPlaneCos)) return 0;

  ClipPolygon poly, scratch;
  make_polygon(inc, ni, poly);
  clip_to_prism(poly, scratch, ref, nr, N);

  int count = 0;
  for (int i = 0; i < poly.count; ++i) {
    const Vec3& p = poly.v[i].p;
    // Ref on A: p is on B, walk back along N onto A's plane. Ref on B: p is on A, walk
    // along -N onto B's plane. Either way t > 0 means overlap.
    const Real t = ref_on_a ? n_ref.dot(ref[0] - p) / cos_n : n_ref.dot(p - ref[0]) / cos_n;
    const Real depth = t + ra + rb;
    if (!(depth >= -margin)) continue;
    const Vec3 pa_core = ref_on_a ? Vec3(p + t * N) : p;
    const Vec3 pa = pa_core + ra * N;
    out[count++] = ContactPoint{pa, pa - depth * N, depth, id_base | poly.v[i].label()};
  }
  return count;
}

// ---- SAT axis selection and feature ids shared by box-box and hull-hull ----

/// Bias of the SAT towards face axes (Gregorius GDC 2013/2015; ODE's dBoxBox uses a
/// 5% "fudge factor" the same way). A candidate axis replaces the current best only if
/// its separation exceeds the best one by more than
///   kSatRelTolerance * |best separation| + kSatAbsTolerance * size,
/// `size` being the larger shape's largest half extent. Face axes are tried first
/// (A's faces, then B's, then the edge pairs), so near-ties go to A's face, then to
/// B's face, and an edge axis must be clearly better. Without this, a stack of boxes
/// whose face and edge separations agree to round-off flips between a 4-point face
/// manifold and a 1-point edge contact from step to step. The price: the reported
/// depth may exceed the minimum translation distance by up to this tolerance (5% of
/// the depth plus 1e-5 of the size), which the solver treats as slightly more overlap.
/// 1e-5 * size is ~1e11 times the round-off of the separations (a few DBL_EPSILON
/// times the size) yet far below anything visible (10 um for a 1 m box).
constexpr Real kSatRelTolerance = 0.05;
constexpr Real kSatAbsTolerance = 1e-5;

inline bool sat_better(Real candidate, Real best, Real size) {
  return candidate > best + kSatRelTolerance * std::abs(best) + kSatAbsTolerance * size;
}

/// Feature ids of the polyhedral routines (box-box, hull-hull):
///   face contact: bit 31 = 0, bit 30 = reference face on B (else on A),
///                 bits 21..29 = reference face index (mod 512),
///                 bits 12..20 = incident face index (mod 512),
///                 bits 0..11 = clip vertex label (see the header of this file);
///   edge contact: bit 31 = 1, bits 15..29 = edge of A (mod 32768), bits 0..14 = edge
///                 of B (mod 32768).
/// Box faces are 2 * axis + (1 for the negative side) (Box::supporting_face's codes),
/// box edges 4 * axis + (1 if on the negative side of axis + 1) + (2 if on the
/// negative side of axis + 2); hull faces are indices into faces(), hull edges indices
/// into edges(). Hulls with more than 512 faces may map two faces to one code: ids
/// then stay persistent but may collide, which only weakens warm starting.
inline std::uint32_t face_contact_id(bool ref_on_b, int ref_face, int inc_face) {
  return (ref_on_b ? (1u << 30) : 0u) | ((static_cast<std::uint32_t>(ref_face) & 511u) << 21) |
         ((static_cast<std::uint32_t>(inc_face) & 511u) << 12);
}
inline std::uint32_t edge_contact_id(int edge_a, int edge_b) {
  return (1u << 31) | ((static_cast<std::uint32_t>(edge_a) & 32767u) << 15) |
         (static_cast<std::uint32_t>(edge_b) & 32767u);
}
/// Label of the extra "deepest point" of a face contact (see kDeepestPointTolerance).
constexpr std::uint32_t kFallbackLabel = 4095;

/// A face contact's clipped points can all be shallower than the SAT depth: for hulls
/// the deepest vertex of the incident shape along the axis need not lie on the
/// incident face. When the deepest clipped point is shallower than the SAT depth by
/// more than this times the shapes' size, and that support point lies over the
/// reference face (so both contact points are on the surfaces), it is added. Both
/// depths are exact up to round-off (~1e-15 of the size); 1e-9 only keeps a point that
/// survived the clip from being duplicated. A support point outside the reference
/// face's prism is not added: its projection would lie off A's or B's surface (deep,
/// off-centre overlaps; or a biased axis, clip::sat_better), and the manifold's depth
/// is then that of the clipped points, which is what the faces really overlap by.
/// Only when no clipped point survives at all (grazing, speculative or deep off-centre
/// configurations) is the support point reported regardless, as the single point of
/// the manifold: a contact that may lie off the surfaces beats a missed overlap.
constexpr Real kDeepestPointTolerance = 1e-9;

/// True if point p lies in the prism of the reference polygon ref[0..nr) swept along
/// dir (the same side planes and slack as clip_to_prism).
inline bool in_prism(const Vec3& p, const Vec3* ref, int nr, const Vec3& dir) {
  ClipPolygon poly, scratch;
  make_polygon(&p, 1, poly);
  clip_to_prism(poly, scratch, ref, nr, dir);
  return poly.count == 1;
}

/// Closest points cp, cq of segments p0-p1 and q0-q1 (Ericson 5.1.9). Degenerate
/// (point) segments and parallel segments are handled: no division by zero.
inline void closest_points_segments(const Vec3& p0, const Vec3& p1, const Vec3& q0, const Vec3& q1,
                                    Vec3& cp, Vec3& cq) {
  const Vec3 d1 = p1 - p0, d2 = q1 - q0, r = p0 - q0;
  const Real a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  Real s = 0, t = 0;
  if (a > 0 && e > 0) {
    const Real c = d1.dot(r), b = d1.dot(d2);
    const Real den = a * e - b * b;  // |d1 x d2|^2 >= 0
    // Parallel (den at round-off level of a * e, 1e-14 being a few ulps): any s is a
    // closest point; Ericson takes s = 0 and lets the clamping below fix t.
    s = den > 1e-14 * a * e ? std::clamp((b * f - c * e) / den, Real(0), Real(1)) : Real(0);
    t = (b * s + f) / e;
    if (t < 0) {
      t = 0;
      s = std::clamp(-c / a, Real(0), Real(1));
    } else if (t > 1) {
      t = 1;
      s = std::clamp((b - c) / a, Real(0), Real(1));
    }
  } else if (e > 0) {
    t = std::clamp(f / e, Real(0), Real(1));
  } else if (a > 0) {
    s = std::clamp(-d1.dot(r) / a, Real(0), Real(1));
  }
  cp = p0 + s * d1;
  cq = q0 + t * d2;
}

}  // namespace clip
}  // namespace wmo
