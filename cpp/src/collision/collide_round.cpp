// Fast contact routines for round shapes: sphere, capsule, and their pairs with boxes.
//
// All of them use the "core + radius" view (shapes.h): a sphere is a point core, a
// capsule a segment core, a rounded box a smaller box core, each inflated by its convex
// radius. The contact between two such shapes is the closest pair of core points, with
// the radii subtracted from their distance, so curved surfaces are exact and no
// iteration is needed. Results are in A's frame (types.h): normal from A to B,
// depth > 0 when overlapping, point_b = point_a - depth * normal.
//
// Feature ids (ContactPoint::feature_id) are `(feature_of_A << 8) | feature_of_B`,
// with per-shape feature codes:
//   sphere:  0.
//   capsule: 0 = segment end at y = -half_height, 1 = end at +half_height,
//            2 = interior of the segment (the cylindrical side).
//   box:     Voronoi region code sum_i t_i * 3^i over the axes i = x, y, z, with
//            t_i = 0 (inside the slab |x_i| <= h_i), 1 (at +h_i), 2 (at -h_i);
//            so faces are 1, 3, 9 (+x, +y, +z) and 2, 6, 18 (-x, -y, -z), edges and
//            vertices combine them. Codes are < 27.
// A point keeps its id while the same pair of features produces it, which is what the
// solver's warm starting needs.
//
// No routine allocates or makes a virtual call.

#include <algorithm>
#include <cmath>

#include "wmo/collision/narrowphase.h"

namespace wmo {
namespace {

/// Below this distance (metres) the direction between two core points is round-off,
/// not geometry: relative poses of shapes 1e4 m from the origin carry about
/// 1e4 * 2.2e-16 ~ 2e-12 m of error (math.h), so a picometre is at that level.
constexpr Real kCoincidentDistance = 1e-12;

/// Squared segment length (m^2) below which a capsule core is treated as a point
/// (a capsule with half_height 0 is a sphere); matches kCoincidentDistance.
constexpr Real kDegenerateLengthSq = kCoincidentDistance * kCoincidentDistance;

/// Two capsule axes are treated as parallel (2-point manifold) when the sine of the
/// angle between them is below 0.01 (0.57 degrees): then the depths at the two ends
/// of the overlap differ by at most 1% of its length, a tilt the solver cannot tell
/// from a real line contact, and the 2 points stop a lying capsule from rocking.
constexpr Real kParallelSinSq = 1e-4;

/// Overlap or clip length (m) below which a 2-point manifold collapses to 1 point:
/// two points closer than this carry no extra torque information.
constexpr Real kMinPairSeparation = 1e-9;

/// Capsule core within this distance (m) of the box core counts as touching and goes
/// to SAT, which is exact there, instead of normalising a near-zero vector. 1e-9 m is
/// far above round-off for metre-sized shapes and far below any physical distance.
constexpr Real kTouchDistance = 1e-9;

inline std::uint32_t feature_id(std::uint32_t fa, std::uint32_t fb) { return (fa << 8) | fb; }

/// Capsule feature code for a segment parameter s in [0, 1].
inline std::uint32_t segment_feature(Real s) {
  return s <= 0 ? 0u : (s >= 1 ? 1u : 2u);
}

/// Box region code of a point p (box frame) against the half extents h, see the header
/// comment. Points inside the box get 0.
inline std::uint32_t box_region(const Vec3& p, const Vec3& h) {
  std::uint32_t code = 0, weight = 1;
  for (int i = 0; i < 3; ++i, weight *= 3) {
    if (p[i] >= h[i]) code += weight;
    else if (p[i] <= -h[i]) code += 2 * weight;
  }
  return code;
}

/// Region code of the face of the box with outward normal sign * e_axis.
inline std::uint32_t box_face_code(int axis, Real sign) {
  const std::uint32_t weight = axis == 0 ? 1u : (axis == 1 ? 3u : 9u);
  return sign > 0 ? weight : 2 * weight;
}

/// Fills one contact between core point ca of A (radius ra) and core point cb of B
/// (radius rb), both in A's frame. `fallback` is the normal used when the cores
/// coincide. Returns false if they are further apart than the margin.
inline bool point_contact(const Vec3& ca, Real ra, const Vec3& cb, Real rb, const Vec3& fallback,
                          Real margin, std::uint32_t id, Manifold& m) {
  const Vec3 d = cb - ca;
  const Real reach = ra + rb + margin;
  const Real dist2 = d.squaredNorm();
  if (reach < 0 || dist2 > reach * reach) return false;
  const Real dist = std::sqrt(dist2);
  const Vec3 n = dist > kCoincidentDistance ? Vec3(d / dist) : fallback;
  const Real depth = ra + rb - dist;
  const Vec3 pa = ca + ra * n;
  m.normal = n;
  m.count = 0;
  m.add(pa, pa - depth * n, depth, id);
  return true;
}

/// Closest points of segments p1 + s d1 and p2 + t d2, s, t in [0, 1]
/// (Ericson, Real-Time Collision Detection, 5.1.9), with the degenerate cases
/// (point segments, parallel segments) handled so no division by zero occurs.
inline void closest_segment_segment(const Vec3& p1, const Vec3& d1, const Vec3& p2,
                                    const Vec3& d2, Real& s, Real& t) {
  const Vec3 r = p1 - p2;
  const Real a = d1.squaredNorm();
  const Real e = d2.squaredNorm();
  const Real f = d2.dot(r);
  if (a <= kDegenerateLengthSq && e <= kDegenerateLengthSq) {
    s = t = 0;
    return;
  }
  if (a <= kDegenerateLengthSq) {
    s = 0;
    t = std::clamp(f / e, Real(0), Real(1));
    return;
  }
  const Real c = d1.dot(r);
  if (e <= kDegenerateLengthSq) {
    t = 0;
    s = std::clamp(-c / a, Real(0), Real(1));
    return;
  }
  const Real b = d1.dot(d2);
  const Real denom = a * e - b * b;  // = |d1 x d2|^2 >= 0
  // Parallel (denom tiny relative to a*e): any s works; Ericson picks s = 0 and the
  // clamping below then finds a valid closest pair. The relative bound 1e-14 is a few
  // ulps of a*e, where denom is pure cancellation noise.
  s = denom > 1e-14 * a * e ? std::clamp((b * f - c * e) / denom, Real(0), Real(1)) : Real(0);
  t = (b * s + f) / e;
  if (t < 0) {
    t = 0;
    s = std::clamp(-c / a, Real(0), Real(1));
  } else if (t > 1) {
    t = 1;
    s = std::clamp((b - c) / a, Real(0), Real(1));
  }
}

/// Squared distance from the segment p0 + t d, t in [0, 1], to the axis-aligned box
/// |x_i| <= h_i, and the minimising t. f(t) = sum_i max(|p0_i + t d_i| - h_i, 0)^2 is
/// convex and piecewise quadratic, with breakpoints where the segment crosses a slab
/// plane. Walking the sorted breakpoints until the derivative
/// f'(t) / 2 = sum_i d_i e_i(t) (e_i the signed excess outside slab i) turns
/// non-negative brackets the minimum in one piece, where it is the clamped stationary
/// point of a single quadratic: exact, at most 8 derivative evaluations, no iteration.
/// On a flat stretch (a segment parallel to a face) the smallest t is returned.
inline Real segment_box_sq_distance(const Vec3& p0, const Vec3& d, const Vec3& h, Real& t_best) {
  auto excess = [&](int i, Real t) {
    const Real x = p0[i] + t * d[i];
    return x > h[i] ? x - h[i] : (x < -h[i] ? x + h[i] : Real(0));
  };
  auto slope = [&](Real t) {
    return d[0] * excess(0, t) + d[1] * excess(1, t) + d[2] * excess(2, t);
  };
  Real ts[7];
  int nt = 0;
  for (int i = 0; i < 3; ++i) {
    if (d[i] == 0) continue;
    const Real inv = 1 / d[i];
    const Real ta = (-h[i] - p0[i]) * inv, tb = (h[i] - p0[i]) * inv;
    if (ta > 0 && ta < 1) ts[nt++] = ta;
    if (tb > 0 && tb < 1) ts[nt++] = tb;
  }
  ts[nt++] = 1;
  // Insertion sort: at most 7 values.
  for (int i = 1; i < nt; ++i)
    for (int j = i; j > 0 && ts[j] < ts[j - 1]; --j) std::swap(ts[j], ts[j - 1]);

  Real t = 1;
  if (slope(0) >= 0) {
    t = 0;
  } else {
    Real lo = 0;
    for (int k = 0; k < nt; ++k) {
      const Real hi = ts[k];
      if (hi <= lo) continue;
      if (slope(hi) < 0) {
        lo = hi;
        continue;
      }
      // The minimum is in [lo, hi]: one quadratic there, with the active set of the
      // midpoint. f' went from < 0 to >= 0, so the piece is not flat (den > 0).
      const Real mid = 0.5 * (lo + hi);
      Real num = 0, den = 0;
      for (int i = 0; i < 3; ++i) {
        const Real x = p0[i] + mid * d[i];
        if (x > h[i]) {
          num += d[i] * (p0[i] - h[i]);
          den += d[i] * d[i];
        } else if (x < -h[i]) {
          num += d[i] * (p0[i] + h[i]);
          den += d[i] * d[i];
        }
      }
      t = den > 0 ? std::clamp(-num / den, lo, hi) : lo;
      break;
    }
  }
  t_best = t;
  Real f = 0;
  for (int i = 0; i < 3; ++i) {
    const Real e = excess(i, t);
    f += e * e;
  }
  return f;
}

/// Clips the segment p0 + t d, t in [0, 1], to the slab |x_j| <= h_j of every axis
/// j != face_axis (the side planes of a box face). Returns false if nothing is left;
/// side_lo / side_hi tell which side plane cut each end (-1: not cut, else the region
/// code of the edge between the face and that side).
inline bool clip_to_face(const Vec3& p0, const Vec3& d, const Vec3& h, int face_axis,
                         std::uint32_t face_code, Real& t_lo, Real& t_hi, int& side_lo,
                         int& side_hi) {
  t_lo = 0;
  t_hi = 1;
  side_lo = side_hi = -1;
  std::uint32_t weight = 1;
  for (int j = 0; j < 3; ++j, weight *= 3) {
    if (j == face_axis) continue;
    if (d[j] == 0) {
      if (std::abs(p0[j]) > h[j]) return false;
      continue;
    }
    // Entering and leaving parameters of the slab, with the plane each belongs to.
    Real ta = (-h[j] - p0[j]) / d[j], tb = (h[j] - p0[j]) / d[j];
    std::uint32_t ca = 2 * weight, cb = weight;  // -h_j plane, +h_j plane
    if (ta > tb) {
      std::swap(ta, tb);
      std::swap(ca, cb);
    }
    if (ta > t_lo) {
      t_lo = ta;
      side_lo = static_cast<int>(face_code + ca);
    }
    if (tb < t_hi) {
      t_hi = tb;
      side_hi = static_cast<int>(face_code + cb);
    }
  }
  return t_lo <= t_hi;
}

}  // namespace

bool collide_sphere_sphere(const Sphere& a, const Sphere& b, const Pose& b_in_a, Real margin,
                           Manifold& m) {
  // Coincident centres: +Y of A, an arbitrary but fixed choice.
  return point_contact(Vec3::Zero(), a.radius(), b_in_a.position, b.radius(), Vec3::UnitY(),
                       margin, feature_id(0, 0), m);
}

bool collide_sphere_capsule(const Sphere& a, const Capsule& b, const Pose& b_in_a, Real margin,
                            Manifold& m) {
  // Closest point of B's segment to A's centre, found in B's frame where the segment
  // is the Y axis between -h and h; only the normal needs rotating back to A's frame
  // (A's centre is A's origin, so the points follow from it).
  const Real ra = a.radius(), rb = b.radius(), h = b.half_height();
  const Real reach = ra + rb + margin;
  const Vec3 c = b_in_a.inverse_transform_point(Vec3::Zero());
  const Real y = std::clamp(c.y(), -h, h);
  const Vec3 d(-c.x(), y - c.y(), -c.z());  // A's centre -> closest core point
  const Real dist2 = d.squaredNorm();
  if (reach < 0 || dist2 > reach * reach) return false;
  const Real dist = std::sqrt(dist2);
  // Centre on the axis: push B along its own X, perpendicular to the axis.
  const Vec3 n_b = dist > kCoincidentDistance ? Vec3(d / dist) : Vec3(Vec3::UnitX());
  const Vec3 n = b_in_a.rotation * n_b;
  const Real depth = ra + rb - dist;
  const std::uint32_t fb = y <= -h ? 0u : (y >= h ? 1u : 2u);
  const Vec3 pa = ra * n;
  m.normal = n;
  m.count = 0;
  m.add(pa, pa - depth * n, depth, feature_id(0, fb));
  return true;
}

bool collide_sphere_box(const Sphere& a, const Box& b, const Pose& b_in_a, Real margin,
                        Manifold& m) {
  // Sphere centre vs the core box (half extents h) with the box rounding added to the
  // sphere radius: the rounded box is exactly the core inflated by its rounding.
  const Vec3& h = b.core_half_extents();
  const Real ra = a.radius(), rb = b.radius();
  const Vec3 c = b_in_a.inverse_transform_point(Vec3::Zero());  // A's centre in B's frame
  const Vec3 q = c.cwiseMax(-h).cwiseMin(h);
  const Vec3 dq = q - c;
  const Real dist2 = dq.squaredNorm();
  const Real reach = ra + rb + margin;
  if (reach < 0 || dist2 > reach * reach) return false;

  Vec3 n_b;  // normal A -> B in B's frame
  Real depth;
  std::uint32_t fb;
  if (dist2 > kCoincidentDistance * kCoincidentDistance) {
    const Real dist = std::sqrt(dist2);
    n_b = dq / dist;
    depth = ra + rb - dist;
    fb = box_region(q, h);
  } else {
    // Centre inside the core (or on its surface): leave through the face with the
    // least penetration (Ericson 5.1.3's closest face). B then moves against that
    // face's outward normal. Ties go to the lower axis and to +.
    int axis = 0;
    Real best = kInf;
    for (int i = 0; i < 3; ++i) {
      const Real s = h[i] - std::abs(c[i]);
      if (s < best) {
        best = s;
        axis = i;
      }
    }
    const Real sign = c[axis] < 0 ? Real(-1) : Real(1);
    n_b = Vec3::Zero();
    n_b[axis] = -sign;
    depth = best + ra + rb;
    fb = box_face_code(axis, sign);
  }
  const Vec3 n = b_in_a.rotation * n_b;
  const Vec3 pa = ra * n;  // A's centre is the origin of A's frame
  m.normal = n;
  m.count = 0;
  m.add(pa, pa - depth * n, depth, feature_id(0, fb));
  return true;
}

bool collide_capsule_capsule(const Capsule& a, const Capsule& b, const Pose& b_in_a, Real margin,
                             Manifold& m) {
  const Real ra = a.radius(), rb = b.radius();
  const Real ha = a.half_height(), hb = b.half_height();
  // Segments in A's frame: A's is the Y axis.
  const Vec3 p1(0, -ha, 0), d1(0, 2 * ha, 0);
  const Vec3 axis_b = b_in_a.rotation * Vec3::UnitY();
  const Vec3 p2 = b_in_a.position - hb * axis_b;
  const Vec3 d2 = (2 * hb) * axis_b;

  Real s, t;
  closest_segment_segment(p1, d1, p2, d2, s, t);
  const Vec3 c1 = p1 + s * d1, c2 = p2 + t * d2;
  const Vec3 dc = c2 - c1;
  const Real reach = ra + rb + margin;
  const Real dist2 = dc.squaredNorm();
  if (reach < 0 || dist2 > reach * reach) return false;
  const Real dist = std::sqrt(dist2);

  const Real a2 = d1.squaredNorm(), e2 = d2.squaredNorm();
  const bool segments = a2 > kDegenerateLengthSq && e2 > kDegenerateLengthSq;
  const Real sin2 = segments ? d1.cross(d2).squaredNorm() / (a2 * e2) : 0;
  const bool parallel = segments && sin2 <= kParallelSinSq;

  Vec3 n;
  if (dist > kCoincidentDistance) {
    n = dc / dist;
  } else {
    // The cores touch: for crossing axes the common perpendicular d1 x d2 is the
    // separating direction; for parallel (or point) cores any perpendicular to A's
    // axis, here A's X. Orient it from A's centre towards B's.
    Vec3 x = segments && !parallel ? Vec3(d1.cross(d2)) : Vec3(Vec3::UnitX());
    if (segments && !parallel) x.normalize();
    if (x.dot(b_in_a.position) < 0) x = -x;
    n = x;
  }

  // Past the distance test there is always a contact: write m directly.
  m.normal = n;
  m.count = 0;
  if (parallel) {
    // Overlap of B's segment projected on A's axis (A's Y): clip B's range to A's.
    const Real y0 = p2.y(), y1 = p2.y() + d2.y();
    const Real b_lo = std::min(y0, y1), b_hi = std::max(y0, y1);
    const Real lo = std::max(-ha, b_lo), hi = std::min(ha, b_hi);
    if (hi - lo > kMinPairSeparation) {
      // Feature of each end: A's end if A's range bounds the overlap, else B's end.
      const std::uint32_t b_end_lo = y0 <= y1 ? 0u : 1u;
      const std::uint32_t id_lo = -ha >= b_lo ? feature_id(0, 2) : feature_id(2, b_end_lo);
      const std::uint32_t id_hi = ha <= b_hi ? feature_id(1, 2) : feature_id(2, 1u - b_end_lo);
      const Real ys[2] = {lo, hi};
      const std::uint32_t ids[2] = {id_lo, id_hi};
      for (int k = 0; k < 2; ++k) {
        const Vec3 pa_core(0, ys[k], 0);
        const Real tb = std::clamp((pa_core - p2).dot(d2) / e2, Real(0), Real(1));
        const Real sep = (p2 + tb * d2 - pa_core).dot(n);
        const Real depth = ra + rb - sep;
        if (depth < -margin) continue;
        const Vec3 pa = pa_core + ra * n;
        m.add(pa, pa - depth * n, depth, ids[k]);
      }
    }
  }
  if (m.count == 0) {
    const Real depth = ra + rb - dist;
    const Vec3 pa = c1 + ra * n;
    m.add(pa, pa - depth * n, depth, feature_id(segment_feature(s), segment_feature(t)));
  }
  return true;
}

bool collide_capsule_box(const Capsule& a, const Box& b, const Pose& b_in_a, Real margin,
                         Manifold& m) {
  const Real ra = a.radius(), rb = b.radius();
  const Real rr = ra + rb;
  const Vec3& h = b.core_half_extents();
  const Real ha = a.half_height();
  const Real reach = rr + margin;
  if (reach < 0) return false;
  // A's segment in B's frame, where the box core is |x_i| <= h_i. One rotation matrix
  // serves every transform below (cheaper than repeated quaternion rotations).
  const Mat3 rot = b_in_a.rotation.toRotationMatrix();
  const Vec3 centre = -(rot.transpose() * b_in_a.position);  // A's centre in B's frame
  // Bounding spheres apart: no contact (cheap reject before the exact distance).
  const Real bound = ha + h.norm() + reach;
  if (centre.squaredNorm() > bound * bound) return false;
  const Vec3 axis = rot.row(1).transpose();  // A's Y in B's frame
  const Vec3 p0 = centre - ha * axis;
  const Vec3 d = (2 * ha) * axis;
  const Real len = 2 * ha;
  const bool segment = len * len > kDegenerateLengthSq;

  Real t;
  const Real dist2 = segment_box_sq_distance(p0, d, h, t);
  if (dist2 > reach * reach) return false;

  Vec3 n_b;           // normal A -> B, B's frame
  Real depth;         // depth of the single closest / deepest pair
  Vec3 p_core;        // A's core point of that pair, B's frame
  int face_axis = -1; // set when n_b is a face normal of B: then clip for 2 points
  std::uint32_t fa = 0, fb = 0;

  if (dist2 > kTouchDistance * kTouchDistance) {
    p_core = p0 + t * d;
    const Vec3 q = p_core.cwiseMax(-h).cwiseMin(h);
    const Real dist = std::sqrt(dist2);
    n_b = (q - p_core) / dist;
    depth = rr - dist;
    fa = segment ? segment_feature(t) : 0u;
    fb = box_region(p_core, h);
    // The closest feature is a face when n_b is (within round-off) a face normal: one
    // clamped axis, or a segment lying on the face whose closest point sits on the
    // face's border. 1 - 1e-9 is a 4.5e-5 rad cone, inside which the face normal and
    // n_b give the same contact to 1e-9 of the distance; snapping to the exact face
    // normal then makes the clipped 2-point manifold consistent.
    int axis_max = 0;
    for (int i = 1; i < 3; ++i)
      if (std::abs(n_b[i]) > std::abs(n_b[axis_max])) axis_max = i;
    if (std::abs(n_b[axis_max]) > 1 - 1e-9) {
      face_axis = axis_max;
      const Real sign = n_b[axis_max] < 0 ? Real(-1) : Real(1);
      n_b = Vec3::Zero();
      n_b[axis_max] = sign;
    }
  } else {
    // Core segment touches or crosses the core box: SAT on the zonotope
    // segment (+) (-box), whose face normals are the box's face normals and
    // axis x e_j (Ericson 4.4, Gottschalk's separating-axis test). For each axis L the
    // minimum translation of B along +L is smax + R, along -L it is R - smin, with R
    // the box's projection radius.
    Real best = kInf;
    Vec3 best_axis = Vec3::UnitX();
    for (int i = 0; i < 3; ++i) {
      const Real a0 = p0[i], a1 = p0[i] + d[i];
      const Real up = std::max(a0, a1) + h[i];  // B along +e_i
      const Real down = h[i] - std::min(a0, a1);  // B along -e_i
      if (up < best) {
        best = up;
        face_axis = i;
        best_axis = Vec3::Unit(i);
      }
      if (down < best) {
        best = down;
        face_axis = i;
        best_axis = -Vec3::Unit(i);
      }
    }
    // Edge axes win only if clearly better: an edge normal within 1% + 10 um of the
    // face depth is indistinguishable to the solver, while the face gives a 2-point
    // manifold and does not flip-flop (the face bias of Box2D and Jolt).
    const Real face_best = best;
    if (segment) {
      for (int j = 0; j < 3; ++j) {
        Vec3 L = axis.cross(Vec3::Unit(j));
        const Real l2 = L.squaredNorm();
        // axis nearly parallel to e_j: L is noise and the face axes cover it.
        if (l2 < 1e-12) continue;
        L /= std::sqrt(l2);
        const Real R = h.dot(L.cwiseAbs());
        const Real a0 = p0.dot(L);  // the segment is perpendicular to L: one value
        const Real up = a0 + R, down = R - a0;
        const Real cand = std::min(up, down);
        if (cand < 0.99 * face_best - 1e-5 && cand < best) {
          best = cand;
          best_axis = up <= down ? L : Vec3(-L);
          face_axis = -1;
        }
      }
    }
    n_b = best_axis;
    depth = best + rr;
    if (face_axis >= 0) {
      // Deepest end of the segment along n_b.
      const Real s0 = p0.dot(n_b), s1 = (p0 + d).dot(n_b);
      p_core = s1 > s0 ? Vec3(p0 + d) : p0;
      fa = s1 > s0 ? 1u : 0u;
      fb = box_face_code(face_axis, -n_b[face_axis]);
    } else {
      // B's deepest edge towards A: the core box edge along the axis e_j that is
      // perpendicular to n_b, at the corner extreme in -n_b.
      int j = 0;
      for (int k = 1; k < 3; ++k)
        if (std::abs(n_b[k]) < std::abs(n_b[j])) j = k;
      Vec3 v;
      for (int k = 0; k < 3; ++k) v[k] = n_b[k] > 0 ? -h[k] : h[k];
      v[j] = -h[j];
      Vec3 e = Vec3::Zero();
      e[j] = 2 * h[j];
      Real s, u;
      closest_segment_segment(p0, d, v, e, s, u);
      p_core = p0 + s * d;
      fa = segment_feature(s);
      fb = box_region(v + u * e, h);
    }
  }

  // Back to A's frame: x_a = rot * x_b + position.
  auto to_a = [&](const Vec3& x) -> Vec3 { return rot * x + b_in_a.position; };
  // Past the distance test there is always a contact: write m directly.
  m.normal = rot * n_b;
  m.count = 0;
  if (face_axis >= 0 && segment) {
    // A capsule lying on a face: clip the segment to the face's side planes and keep
    // both ends that are within the margin (Jolt and Box2D's face clipping).
    const Real sign = -n_b[face_axis];  // outward normal of B's face is sign * e_axis
    const std::uint32_t face_code = box_face_code(face_axis, sign);
    Real t_lo, t_hi;
    int side_lo, side_hi;
    if (clip_to_face(p0, d, h, face_axis, face_code, t_lo, t_hi, side_lo, side_hi)) {
      const bool two = (t_hi - t_lo) * len > kMinPairSeparation;
      const Real ts[2] = {t_lo, t_hi};
      const int sides[2] = {side_lo, side_hi};
      for (int k = 0; k < (two ? 2 : 1); ++k) {
        const Vec3 x = p0 + ts[k] * d;
        const Real sep = sign * x[face_axis] - h[face_axis];
        const Real dk = rr - sep;
        if (dk < -margin) continue;
        const std::uint32_t id =
            sides[k] >= 0 ? feature_id(2, static_cast<std::uint32_t>(sides[k]))
                          : feature_id(k == 0 ? 0u : 1u, face_code);
        const Vec3 pa = to_a(x + ra * n_b);
        m.add(pa, pa - dk * m.normal, dk, id);
      }
    }
  }
  if (m.count == 0) {
    const Vec3 pa = to_a(p_core + ra * n_b);
    m.add(pa, pa - depth * m.normal, depth, feature_id(fa, fb));
  }
  return true;
}

}  // namespace wmo
