// WMO geometry layer: generic convex algorithms over support functions.
//
//   * gjk_distance / gjk_intersect: the Gilbert-Johnson-Keerthi distance algorithm in the
//     form of van den Bergen (2001, 2003: "Collision Detection in Interactive 3D
//     Environments", ch. 4.3), with the signed-volumes sub-simplex solver of Montanari,
//     Petrinic and Barbieri (2017, "Improving the GJK algorithm for faster and more
//     reliable distance queries between convex objects", ACM TOG 36(3)).
//   * epa_penetration: the Expanding Polytope Algorithm (van den Bergen 2001,
//     "Proximity queries and penetration depth computation on 3D game objects", GDC),
//     seeded from GJK's final simplex.
//   * gjk_raycast: ray cast against one convex support function (van den Bergen 2004,
//     "Ray casting against general convex objects with application to continuous
//     collision detection").
//
// A support function is any object callable as `Vec3 operator()(const Vec3& dir) const`
// that returns a point of a convex set furthest along `dir`, in the set's local frame.
// `dir` is never required to be unit; it may be zero only where noted. The decorators
// below follow Jolt's ConvexSupport.h: CoreSupport<S> gives the core of a concrete shape
// (the shape without its convex radius), FullSupport<S> adds the radius back,
// TransformedSupport applies a rigid transform. The concrete shape classes are final,
// so every call is a direct (usually inlined) call: the inner loops have no virtual
// dispatch.
//
// Frames and signs (types.h): B's support is given in B's local frame and `b_in_a` is
// B's pose in A's frame; all results are in A's frame. Normals are unit vectors from A
// to B. For an overlapping pair point_b = point_a - depth * normal.
//
// Memory: GJK allocates nothing. EPA uses a per-thread workspace whose buffers grow to
// the size EpaSettings asks for on first use and are then reused.
#pragma once

#include <algorithm>
#include <array>
#include <cfloat>
#include <cmath>
#include <cstdint>
#include <type_traits>
#include <utility>
#include <vector>

#include "wmo/geometry/shapes.h"
#include "wmo/math.h"
#include "wmo/types.h"

namespace wmo {

// =====================================================================================
// Support functions and decorators
// =====================================================================================

namespace detail {

// kTinyDirSq, unit_or_x and sign_or_plus (shapes.h) are the shapes' own, so a decorated
// support agrees with ConvexShape::support bit for bit on ordinary input.

/// a x b, written out. The same formula as Eigen's cross (so the same bits), which GCC
/// left as an out-of-line call in GJK's and EPA's loops (7% of EPA's samples on
/// cylinder-box pairs were in the call; written out, EPA 9-14% faster a query on the
/// narrowphase benchmark's overlapping pairs).
inline Vec3 cross3(const Vec3& a, const Vec3& b) {
  return Vec3(a.y() * b.z() - a.z() * b.y(), a.z() * b.x() - a.x() * b.z(), a.x() * b.y() - a.y() * b.x());
}

}  // namespace detail

/// Support of the core of a concrete convex shape (local frame, radius excluded).
/// The primary template calls `S::support_core`, which is a direct call for the final
/// classes (ConvexHull); the specialisations below inline the simple shapes.
/// `radius()` is the convex radius to add back (FullSupport does).
template <class S>
struct CoreSupport {
  const S* shape;
  explicit CoreSupport(const S& s) : shape(&s) {}
  Real radius() const { return shape->radius(); }
  Vec3 operator()(const Vec3& dir) const { return shape->support_core(dir); }
};

/// Sphere core: the centre.
template <>
struct CoreSupport<Sphere> {
  Real r;
  explicit CoreSupport(const Sphere& s) : r(s.radius()) {}
  Real radius() const { return r; }
  Vec3 operator()(const Vec3&) const { return Vec3::Zero(); }
};

/// Box core: the box of half extents (half_extents - rounding).
template <>
struct CoreSupport<Box> {
  Vec3 h;
  Real r;
  explicit CoreSupport(const Box& b) : h(b.core_half_extents()), r(b.radius()) {}
  Real radius() const { return r; }
  Vec3 operator()(const Vec3& d) const {
    return Vec3(detail::sign_or_plus(d.x()) * h.x(), detail::sign_or_plus(d.y()) * h.y(),
                detail::sign_or_plus(d.z()) * h.z());
  }
};

/// Capsule core: the segment (0, +-half_height, 0).
template <>
struct CoreSupport<Capsule> {
  Real hh, r;
  explicit CoreSupport(const Capsule& c) : hh(c.half_height()), r(c.radius()) {}
  Real radius() const { return r; }
  Vec3 operator()(const Vec3& d) const { return Vec3(0, detail::sign_or_plus(d.y()) * hh, 0); }
};

/// Cylinder: the whole (sharp) cylinder; its convex radius is 0.
template <>
struct CoreSupport<Cylinder> {
  Real cr, hh;
  explicit CoreSupport(const Cylinder& c) : cr(c.cylinder_radius()), hh(c.half_height()) {}
  Real radius() const { return 0; }
  Vec3 operator()(const Vec3& d) const {
    const Real y = detail::sign_or_plus(d.y()) * hh;
    const Real h2 = d.x() * d.x() + d.z() * d.z();
    // Along the axis every point of a cap supports; the cap centre is a valid choice.
    if (!(h2 > detail::kTinyDirSq)) return Vec3(0, y, 0);
    const Real s = cr / std::sqrt(h2);
    return Vec3(s * d.x(), y, s * d.z());
  }
};

/// Core support plus the convex radius: core(dir) + radius * dir / |dir| (the full
/// shape, ConvexShape::support). A zero direction uses +X, as the shapes do.
template <class S>
struct FullSupport {
  CoreSupport<S> core;
  explicit FullSupport(const S& s) : core(s) {}
  Real radius() const { return 0; }  // the radius is already included
  Vec3 operator()(const Vec3& d) const {
    const Real r = core.radius();
    if (r == 0) return core(d);
    return core(d) + r * detail::unit_or_x(d);
  }
};

/// A support function moved by a rigid transform: the set { pose * x : x in S }.
/// Supports are asked of the inner function in its own frame (R^T dir) and returned in
/// the parent frame.
template <class S>
struct TransformedSupport {
  S inner;
  Mat3 rotation;
  Vec3 position;
  TransformedSupport(const S& s, const Pose& pose)
      : inner(s), rotation(pose.matrix()), position(pose.position) {}
  Vec3 operator()(const Vec3& d) const {
    return rotation * inner(rotation.transpose() * d) + position;
  }
};

/// A single point (e.g. a sphere's core placed anywhere).
struct PointSupport {
  Vec3 p = Vec3::Zero();
  Vec3 operator()(const Vec3&) const { return p; }
};

/// A triangle (3 points): the convex pieces of a triangle mesh. Ties go to the lower
/// vertex index, so the result is deterministic.
struct TriangleSupport {
  std::array<Vec3, 3> v;
  TriangleSupport(const Vec3& a, const Vec3& b, const Vec3& c) : v{a, b, c} {}
  Vec3 operator()(const Vec3& d) const {
    const Real d0 = v[0].dot(d), d1 = v[1].dot(d), d2 = v[2].dot(d);
    if (d0 >= d1) return d0 >= d2 ? v[0] : v[2];
    return d1 >= d2 ? v[1] : v[2];
  }
};

// =====================================================================================
// GJK
// =====================================================================================

/// GJK's simplex: up to 4 vertices w = a - b of the Minkowski difference A - B, with the
/// support points on A (`a`) and on B (`b`, in A's frame) that produced them, and the
/// barycentric coordinates of the point of the simplex closest to the origin. Only the
/// first `count` entries are meaningful; the rest are left uninitialised (GJK copies
/// simplices in its inner loop, and zeroing 40 doubles each time is measurable).
struct Simplex {
  int count = 0;
  std::array<Vec3, 4> w;
  std::array<Vec3, 4> a;
  std::array<Vec3, 4> b;
  std::array<Real, 4> lambda;
};

/// Result of gjk_distance. All vectors in A's frame.
struct GjkResult {
  /// kOk, or kMaxIterations when the cap was hit (the result is then the best so far:
  /// `distance` is an upper bound on the true distance).
  QueryStatus status = QueryStatus::kOk;
  /// True when the origin lies in A - B within round-off: the sets touch or overlap.
  bool intersecting = false;
  /// Distance between the sets (m), 0 when intersecting.
  Real distance = 0;
  /// Closest points on A and on B (A's frame). Unspecified but finite when intersecting.
  Vec3 point_a = Vec3::Zero();
  Vec3 point_b = Vec3::Zero();
  /// Unit vector from A to B ((point_b - point_a) / distance) when apart; zero when
  /// intersecting.
  Vec3 normal = Vec3::Zero();
  int iterations = 0;
  /// True when gjk_distance stopped early because the distance is known to exceed its
  /// `cull` argument; `distance` is then an upper bound (> cull), not the distance.
  bool culled = false;
  /// Final simplex (EPA's seed when intersecting).
  Simplex simplex;
};

namespace detail {

// ---- Signed-volumes sub-simplex solver (Montanari et al. 2017, section 3) ----------
//
// Given the vertices y[] of a simplex, find the smallest sub-simplex whose affine hull
// contains the point of the simplex closest to the origin, and that point's barycentric
// coordinates. Unlike Johnson's sub-algorithm it decides regions from signed volumes of
// the simplex and of its projections (areas projected on the axis plane where they are
// largest), which stays correct for nearly degenerate simplices; a degenerate simplex
// (zero volume / area / length) simply makes every sign test fail, so all its faces are
// examined and the closest is kept.
//
// The closest point itself is returned too, computed directly (the origin's projection
// on the segment's line or the triangle's plane), not as sum(lambda_i y_i): the
// weights are ratios to a determinant computed apart from their numerators, and on
// an ill-conditioned simplex (support points of a curved shape clustered a
// micrometre apart, vertices ~1 m from the origin) they sum to 1 only within ~1e-11,
// so the weighted sum is off by ~1e-11 m. At a distance of 3e-6 m that tilts the
// direction by 3e-6 rad, which near a flat facet of A - B 1 m across lowers GJK's
// lower bound by micrometres: GJK on a cylinder rim a few micrometres from a box
// then wandered up to its 128-iteration cap. Measured on the reference cross-check's
// barely separated pairs (gaps 1e-6..1e-3 m, 2000 per ordered pair, two seeds): with
// the weighted sum, 1-24% of the pairs with a cylinder ended with an answer not
// certified within 1e-9 m (separating-plane gap along the normal against the
// witness points' distance, witnesses inside their shapes; worst 9e-5 m) and up to
// 6% at the iteration cap; with the projection (error ~1e-16 m), the normal taken
// from v and normalised weights for the witnesses, none, and GJK takes 20-35% fewer
// iterations on the cylinder pairs.

struct SubSimplex {
  int count = 0;
  std::array<int, 4> idx{};
  std::array<Real, 4> lambda{};
  Vec3 point = Vec3::Zero();  ///< the closest point of the simplex to the origin
};

inline bool same_sign(Real a, Real b) { return (a > 0 && b > 0) || (a < 0 && b < 0); }

inline int max_abs_axis(const Vec3& v) {
  const Vec3 a = v.cwiseAbs();
  int k = 0;
  if (a.y() > a[k]) k = 1;
  if (a.z() > a[k]) k = 2;
  return k;
}

inline Real closest_norm2(const SubSimplex& s) { return s.point.squaredNorm(); }

// Segment y[i0] y[i1] (Montanari's S1D).
inline void solve_segment(const Vec3* y, int i0, int i1, SubSimplex& out) {
  const Vec3& a = y[i0];
  const Vec3& b = y[i1];
  const Vec3 t = b - a;
  const Real tt = t.squaredNorm();
  if (!(tt > 0)) {  // coincident end points
    out.count = 1;
    out.idx[0] = i0;
    out.lambda[0] = 1;
    out.point = a;
    return;
  }
  // Projection of the origin on the line, then barycentric coordinates from the
  // coordinate along which the segment is longest (best conditioned).
  const Vec3 p = a - (a.dot(t) / tt) * t;
  const int k = max_abs_axis(t);
  const Real mu = a[k] - b[k];
  const Real c0 = p[k] - b[k];  // lambda_a * mu
  const Real c1 = a[k] - p[k];  // lambda_b * mu
  if (same_sign(mu, c0) && same_sign(mu, c1)) {
    out.count = 2;
    out.idx[0] = i0;
    out.idx[1] = i1;
    out.lambda[0] = c0 / mu;
    out.lambda[1] = c1 / mu;
    out.point = p;
  } else {
    out.count = 1;
    out.idx[0] = same_sign(mu, c0) ? i0 : i1;  // lambda_b <= 0: a is closest, else b
    out.lambda[0] = 1;
    out.point = y[out.idx[0]];
  }
}

// Triangle y[i0] y[i1] y[i2] (Montanari's S2D).
inline void solve_triangle(const Vec3* y, int i0, int i1, int i2, SubSimplex& out) {
  const Vec3& a = y[i0];
  const Vec3& b = y[i1];
  const Vec3& c = y[i2];
  const Vec3 n = cross3(b - a, c - a);
  const Real nn = n.squaredNorm();
  bool inside = false;
  std::array<bool, 3> check{true, true, true};  // edge opposite vertex j needs a look
  if (nn > 0) {
    const Vec3 p = n * (a.dot(n) / nn);  // origin projected on the plane
    // Signed areas projected on the coordinate plane where the triangle is largest.
    const int k = max_abs_axis(n);
    const int u = (k + 1) % 3, v = (k + 2) % 3;
    auto area = [u, v](const Vec3& P, const Vec3& Q, const Vec3& R) {
      return (Q[u] - P[u]) * (R[v] - P[v]) - (Q[v] - P[v]) * (R[u] - P[u]);
    };
    const Real nu = area(a, b, c);
    const std::array<Real, 3> cj{area(p, b, c), area(a, p, c), area(a, b, p)};
    inside = true;
    for (int j = 0; j < 3; ++j) {
      check[j] = !same_sign(nu, cj[j]);
      inside = inside && !check[j];
    }
    if (inside) {
      out.count = 3;
      out.idx = {i0, i1, i2, 0};
      for (int j = 0; j < 3; ++j) out.lambda[j] = cj[j] / nu;
      out.point = p;
      return;
    }
  }
  // The closest point lies on an edge whose opposite vertex failed its sign test.
  const std::array<std::array<int, 2>, 3> edges{{{i1, i2}, {i0, i2}, {i0, i1}}};
  Real best = kInf;
  for (int j = 0; j < 3; ++j) {
    if (!check[j]) continue;
    SubSimplex s;
    solve_segment(y, edges[j][0], edges[j][1], s);
    const Real d2 = closest_norm2(s);
    if (d2 < best) {
      best = d2;
      out = s;
    }
  }
}

// Tetrahedron y[0..3] (Montanari's S3D).
inline void solve_tetrahedron(const Vec3* y, SubSimplex& out) {
  // Cofactors: C_j is the signed volume with y_j replaced by the origin, so that the
  // origin's barycentric coordinates are C_j / sum(C).
  const Vec3 c23 = cross3(y[2], y[3]);
  const std::array<Real, 4> cj{y[1].dot(c23), -y[0].dot(c23), y[0].dot(cross3(y[1], y[3])),
                               -y[0].dot(cross3(y[1], y[2]))};
  const Real det = cj[0] + cj[1] + cj[2] + cj[3];
  std::array<bool, 4> check{};
  bool inside = true;
  for (int j = 0; j < 4; ++j) {
    check[j] = !same_sign(det, cj[j]);
    inside = inside && !check[j];
  }
  if (inside) {
    out.count = 4;
    out.idx = {0, 1, 2, 3};
    for (int j = 0; j < 4; ++j) out.lambda[j] = cj[j] / det;
    out.point = Vec3::Zero();
    return;
  }
  const std::array<std::array<int, 3>, 4> faces{{{1, 2, 3}, {0, 2, 3}, {0, 1, 3}, {0, 1, 2}}};
  Real best = kInf;
  for (int j = 0; j < 4; ++j) {
    if (!check[j]) continue;
    SubSimplex s;
    solve_triangle(y, faces[j][0], faces[j][1], faces[j][2], s);
    const Real d2 = closest_norm2(s);
    if (d2 < best) {
      best = d2;
      out = s;
    }
  }
}

inline void solve_simplex(const Vec3* y, int n, SubSimplex& out) {
  switch (n) {
    case 1:
      out.count = 1;
      out.idx[0] = 0;
      out.lambda[0] = 1;
      out.point = y[0];
      break;
    case 2:
      solve_segment(y, 0, 1, out);
      break;
    case 3:
      solve_triangle(y, 0, 1, 2, out);
      break;
    default:
      solve_tetrahedron(y, out);
      break;
  }
}

// Keeps the vertices of `s` listed in `sub` (indices ascending), in place.
inline void compact_simplex(Simplex& s, const SubSimplex& sub) {
  for (int i = 0; i < sub.count; ++i) {
    const int j = sub.idx[i];
    if (j != i) {
      s.w[i] = s.w[j];
      s.a[i] = s.a[j];
      s.b[i] = s.b[j];
    }
    s.lambda[i] = sub.lambda[i];
  }
  s.count = sub.count;
}

// Support of A - B (A's frame) along `d`: a = sA(d), b = R sB(-R^T d) + t.
template <class SA, class SB>
struct MinkowskiSupport {
  const SA& sa;
  const SB& sb;
  Mat3 r;
  Vec3 t;
  MinkowskiSupport(const SA& a, const SB& b, const Pose& b_in_a)
      : sa(a), sb(b), r(b_in_a.matrix()), t(b_in_a.position) {}
  // The 3x3 products are written out: in GJK's loop, which is large, GCC left Eigen's
  // as out-of-line calls (measured: GJK 7-36% faster a query on the narrowphase
  // benchmark's pairs, sphere-box far 71 -> 45 ns, cylinder-box barely overlapping
  // 800 -> 703 ns; EPA unchanged).
  Vec3 operator()(const Vec3& d, Vec3& pa, Vec3& pb) const {
    pa = sa(d);
    if constexpr (std::is_same_v<SB, CoreSupport<Sphere>>) {
      // A sphere's core is its centre: R 0 + t = t, bit for bit (R is finite), and
      // without the products GJK on two spheres folds to a few operations (72 -> 13
      // ns a query; the products on zeros kept it an out-of-line call).
      pb = t;
    } else {
      pb = to_a(sb(-to_b(d)));
    }
    return pa - pb;
  }
  Vec3 support_b(const Vec3& d) const { return to_a(sb(to_b(d))); }
  /// R^T d: a direction of A's frame in B's.
  Vec3 to_b(const Vec3& d) const {
    return Vec3(r(0, 0) * d.x() + r(1, 0) * d.y() + r(2, 0) * d.z(),
                r(0, 1) * d.x() + r(1, 1) * d.y() + r(2, 1) * d.z(),
                r(0, 2) * d.x() + r(1, 2) * d.y() + r(2, 2) * d.z());
  }
  /// R q + t: a point of B's frame in A's. The sums are grouped as Eigen's product
  /// groups them (its last row is the scalar remainder of a 2-wide packet), so the
  /// results are bit for bit those of `r * q + t` and the reference cross-check's
  /// configurations (built with these queries) do not depend on which is used.
  Vec3 to_a(const Vec3& q) const {
    return Vec3((r(0, 0) * q.x() + r(0, 1) * q.y()) + r(0, 2) * q.z() + t.x(),
                (r(1, 0) * q.x() + r(1, 1) * q.y()) + r(1, 2) * q.z() + t.y(),
                r(2, 0) * q.x() + (r(2, 1) * q.y() + r(2, 2) * q.z()) + t.z());
  }
};

// GJK treats |v| <= kGjkTouchRel * max|y| as "origin in A - B": v is a convex
// combination of vertices of size max|y|, so its round-off is a few DBL_EPSILON times
// that; 1e-13 (~450 ulp) is safely above the noise and below any distance a caller
// could meaningfully resolve at that scale.
constexpr Real kGjkTouchRel = 1e-13;
// Floor of the termination test: |v|^2 - v.w is computed with an error of a few
// DBL_EPSILON * |v| * |w|; 16 of them is the point below which the gap is noise.
constexpr Real kGjkRoundoff = 16 * DBL_EPSILON;
// When GJK stops making progress (|v| no longer decreases, or a support point repeats)
// it normally does so at the resolution limit: on polytopes at round-off, on curved
// supports (cylinders) once the clustered support points make the simplex as good as
// double precision allows, with |v| - v.w / |v| at ~1e-12 of the size (measured on
// random cylinder-box pairs). A stop with a bracket wider than kGjkStallRel of the
// size, or with no separating plane at all (v.w <= 0), is instead the fault of an
// ill-conditioned simplex: support points clustered on a cylinder rim make the signed
// volumes of a tetrahedron that does contain the origin unreliable, and GJK would
// report a positive distance for a pair that overlaps (observed: |v| = 1e-9 m for a
// box and a cylinder overlapping by 1.2e-8 m). GJK then restarts from the newest
// support point alone (as the ray cast below does), at most kGjkMaxRestarts times;
// 1e-9 is GJK's documented accuracy on curved shapes, 1000x the legitimate stall.
constexpr Real kGjkStallRel = 1e-9;
constexpr int kGjkMaxRestarts = 4;

// The GJK loop shared by gjk_distance (kBoolean = false) and gjk_intersect (true).
// In boolean mode it stops as soon as a plane separates A - B from the ball of radius
// `margin` about the origin, or |v| <= margin. In distance mode it stops as soon as a
// plane proves the distance greater than `cull` (kInf: never), reporting |v| (> cull).
template <bool kBoolean, class SA, class SB>
GjkResult gjk_run(const SA& sa, const SB& sb, const Pose& b_in_a, const GjkSettings& settings,
                  const Vec3& initial_dir, Real margin, bool* boolean_out, Real cull = kInf) {
  const MinkowskiSupport<SA, SB> support(sa, sb, b_in_a);
  GjkResult res;
  Simplex& s = res.simplex;

  // First vertex along the guess of the A -> B direction (supports on A along d and on
  // B along -d), so v starts close to the answer when the guess is good.
  Vec3 d = initial_dir;
  if (!(d.squaredNorm() > kTinyDirSq) || !d.allFinite()) {
    d = b_in_a.position;
    if (!(d.squaredNorm() > kTinyDirSq) || !d.allFinite()) d = Vec3::UnitX();
  }
  s.w[0] = support(d, s.a[0], s.b[0]);
  s.lambda[0] = 1;
  s.count = 1;
  Vec3 v = s.w[0];
  Real dist2 = v.squaredNorm();
  Real scale2 = dist2;  // max |y|^2 over every vertex seen
  const Real tol = std::max(settings.tolerance, Real(0));
  const int max_it = std::max(settings.max_iterations, 1);
  bool separated = false;
  int restarts = 0;
  Simplex best;  // filled before it is read (best_dist2 < kInf)
  Vec3 best_v = Vec3::Zero();
  Real best_dist2 = kInf;

  for (;;) {
    if (dist2 <= kGjkTouchRel * kGjkTouchRel * scale2) {
      res.intersecting = true;
      break;
    }
    if constexpr (kBoolean) {
      if (margin > 0 && dist2 <= margin * margin) break;  // within the margin
    }
    if (res.iterations >= max_it) {
      res.status = QueryStatus::kMaxIterations;
      break;
    }
    ++res.iterations;
    Vec3 pa, pb;
    const Vec3 w = support(-v, pa, pb);
    const Real vw = v.dot(w);
    const Real wn2 = w.squaredNorm();
    if constexpr (kBoolean) {
      // v.w / |v| is a lower bound on the distance (van den Bergen 2003, 4.3.3).
      if (vw > 0 && vw * vw > margin * margin * dist2) {
        separated = true;
        break;
      }
    } else {
      // The same lower bound against the caller's cull distance: farther than that,
      // the exact distance is not wanted (contact generation within a margin), and on
      // curved shapes GJK would need many more iterations to converge to it.
      if (vw > 0 && vw * vw > cull * cull * dist2) {
        res.culled = true;
        break;
      }
    }
    // Van den Bergen's relative test: |v|^2 - v.w bounds |v|^2 - dist^2 from above.
    if (dist2 - vw <= tol * dist2 + kGjkRoundoff * std::sqrt(dist2 * std::max(wn2, scale2))) break;
    // The bracket is wider than round-off can explain: a stall here is the simplex's
    // fault (see kGjkStallRel), so restarting from w alone can still make progress.
    const bool can_restart =
        restarts < kGjkMaxRestarts &&
        (vw <= 0 || dist2 - vw > kGjkStallRel * std::sqrt(dist2 * std::max(wn2, scale2)));
    auto restart = [&] {
      ++restarts;
      if (dist2 < best_dist2) {  // keep the best simplex in case the restart ends worse
        best = s;
        best_v = v;
        best_dist2 = dist2;
      }
      s.w[0] = w;
      s.a[0] = pa;
      s.b[0] = pb;
      s.lambda[0] = 1;
      s.count = 1;
      v = w;
      dist2 = wn2;
      scale2 = std::max(scale2, wn2);
    };
    // A vertex seen again means no progress is possible (cycling on round-off).
    // (Component by component: Eigen's == compiled to an out-of-line call here.)
    bool duplicate = false;
    for (int i = 0; i < s.count; ++i)
      duplicate = duplicate || (s.w[i].x() == w.x() && s.w[i].y() == w.y() && s.w[i].z() == w.z());
    if (duplicate) {
      if (!can_restart || s.count == 1) break;
      restart();
      continue;
    }

    scale2 = std::max(scale2, wn2);
    const int n = s.count;
    s.w[n] = w;
    s.a[n] = pa;
    s.b[n] = pb;
    SubSimplex sub;
    solve_simplex(s.w.data(), n + 1, sub);
    const Vec3 v_new = sub.point;
    const Real d2_new = v_new.squaredNorm();
    if (sub.count == 4) {  // origin strictly inside the tetrahedron
      compact_simplex(s, sub);
      v.setZero();
      dist2 = 0;
      res.intersecting = true;
      break;
    }
    // |v| must decrease strictly (van den Bergen 2003, theorem 4.5); if round-off
    // stalls it, keep the previous simplex, which is the best answer available.
    if (!(d2_new < dist2)) {
      if (!can_restart) break;
      restart();
      continue;
    }
    compact_simplex(s, sub);
    v = v_new;
    dist2 = d2_new;
  }

  if (!res.intersecting && best_dist2 < dist2) {
    s = best;
    v = best_v;
    dist2 = best_dist2;
  }
  // Witness points: the barycentric combination, divided by the weights' sum. The
  // signed-volume solver's weights are ratios to a determinant computed apart from their
  // numerators, so on an ill-conditioned simplex (two support points of a curved shape
  // a micrometre apart) they sum to 1 only within ~1e-11, which put a witness point
  // that far outside its shape (seen: 4e-11 m off a box); normalised, each witness is
  // a convex combination of its shape's points up to round-off. v is unchanged.
  Real lambda_sum = 0;
  for (int i = 0; i < s.count; ++i) lambda_sum += s.lambda[i];
  if (!(lambda_sum > 0)) lambda_sum = 1;
  Vec3 pa = Vec3::Zero(), pb = Vec3::Zero();
  for (int i = 0; i < s.count; ++i) {
    const Real l = s.lambda[i] / lambda_sum;
    pa += l * s.a[i];
    pb += l * s.b[i];
  }
  res.point_a = pa;
  res.point_b = pb;
  if (res.intersecting) {
    res.distance = 0;
    res.normal.setZero();
  } else {
    res.distance = std::sqrt(dist2);
    // -v / |v|: v is the projection computed directly (see SubSimplex::point); the
    // witness points' difference is the same vector up to the weights' round-off,
    // which at micrometre distances is a visible tilt.
    res.normal = -v / res.distance;
  }
  if (boolean_out) *boolean_out = !separated && (res.intersecting || res.distance <= margin);
  return res;
}

}  // namespace detail

/// Distance between convex A (support `sa`, A's frame) and convex B (support `sb`, B's
/// frame) with B at `b_in_a`. `initial_dir` is a guess of the direction from A to B (any
/// non-zero vector; zero falls back to b_in_a.position, then +X). Returns distance,
/// closest points and normal in A's frame; `intersecting` when the sets touch or
/// overlap (then distance = 0 and `simplex` seeds EPA). Never allocates, never returns
/// NaN for finite input, stops after settings.max_iterations support calls at most.
/// A stall without a separating plane (an ill-conditioned simplex on curved supports)
/// restarts the simplex from the newest support point, at most kGjkMaxRestarts times;
/// the best simplex seen is what is reported.
/// `cull` (m, default kInf): stop as soon as a separating plane proves the distance
/// greater than this; the result then has culled = true and distance = |v| > cull (an
/// upper bound of a distance known to exceed cull), normal and points of that simplex.
template <class SA, class SB>
GjkResult gjk_distance(const SA& sa, const SB& sb, const Pose& b_in_a, const GjkSettings& s = {},
                       const Vec3& initial_dir = Vec3::UnitX(), Real cull = kInf) {
  return detail::gjk_run<false>(sa, sb, b_in_a, s, initial_dir, 0, nullptr, cull);
}

/// True if the distance between A and B is <= `margin` (m; 0 means touching or
/// overlapping). Exits early on a separating plane, so it is cheaper than gjk_distance
/// for separated pairs. Pass margin = ra + rb to test rounded shapes on their cores.
template <class SA, class SB>
bool gjk_intersect(const SA& sa, const SB& sb, const Pose& b_in_a, const GjkSettings& s = {},
                   const Vec3& initial_dir = Vec3::UnitX(), Real margin = 0) {
  bool out = false;
  detail::gjk_run<true>(sa, sb, b_in_a, s, initial_dir, std::max(margin, Real(0)), &out);
  return out;
}

// =====================================================================================
// EPA
// =====================================================================================

/// Result of epa_penetration. All vectors in A's frame.
struct EpaResult {
  /// kOk; kMaxIterations when EpaSettings::max_iterations or max_faces stopped the
  /// expansion; kDegenerate when A - B is a single point (normal undefined: a fallback
  /// direction is returned with depth 0) or the polytope could not be expanded
  /// consistently. After such a stop the answer is the best valid one found: the
  /// smallest support distance seen and its normal (an upper bound on the depth;
  /// translating B by depth * normal still makes the sets touch), unless the closest
  /// face is already within tolerance of it.
  QueryStatus status = QueryStatus::kOk;
  /// Penetration depth (m), >= 0: translating B by depth * normal makes the sets touch.
  Real depth = 0;
  /// Unit vector from A to B.
  Vec3 normal = Vec3::UnitX();
  /// Deepest points: point_b = point_a - depth * normal.
  Vec3 point_a = Vec3::Zero();
  Vec3 point_b = Vec3::Zero();
  int iterations = 0;
};

namespace detail {

struct EpaFace {
  std::array<int, 3> v;         // vertex indices, CCW seen from outside
  std::array<int, 3> adj;       // face across edge i (v[i] -> v[i+1])
  std::array<int, 3> adj_edge;  // that face's index of the shared edge
  Vec3 n;                       // outward unit normal
  Real d;                       // n . v0: distance of the plane from the origin
  bool obsolete;
};

// Per-thread buffers: they grow to the sizes the settings ask for once, then are reused,
// so EPA does not allocate in steady state.
struct EpaWorkspace {
  std::vector<Vec3> w, a, b;
  std::vector<EpaFace> faces;
  std::vector<int> free_faces;
  // Per face slot: its distance while it is a candidate for expansion, +inf otherwise
  // (obsolete, free, or pruned beyond the upper bound). The closest face is found by a
  // branch-free scan of this array (Epa::pop_closest), not a binary heap: EPA's
  // polytopes hold tens to a few hundred faces, and the heap's push and pop cost one
  // unpredictable comparison per level (measured, EPA alone on the narrowphase
  // benchmark's configurations: deep box-box 1969 -> 1668 ns, hull-hull 3866 -> 3241,
  // cylinder-box 5726 -> 5019, best of five alternating runs). A face that becomes
  // obsolete leaves the candidates at once, and its slot is free for reuse.
  std::vector<Real> key;
  // (face, edge) pairs packed as face * 4 + edge: one 4-byte store and load per entry
  // (a pair written as two ints and read back as one 8-byte load stalls the store
  // buffer, which was a tenth of EPA's time on cylinders).
  std::vector<int> horizon, stack;
  std::vector<int> created;
};

inline EpaWorkspace& epa_workspace() {
  thread_local EpaWorkspace ws;
  return ws;
}

// EPA treats A - B as flat (zero thickness) along a direction when its extent there is
// below kEpaFlatRel * size: round-off of a support point difference is a few ulp of the
// size, and the depth error this admits (<= 1e-12 of the size) is below every
// tolerance a caller can ask for meaningfully.
constexpr Real kEpaFlatRel = 1e-12;
// A new face whose doubled area is below kEpaSliverRel * size^2 has no reliable normal.
constexpr Real kEpaSliverRel = 1e-14;
// When the polytope cannot be expanded further (a sliver face, a broken horizon), the
// depth along the closest face's normal is still bracketed by [its distance, the
// support distance along its normal]. A bracket within kEpaResolutionRel * size is the resolution limit of a tessellated
// curved surface in double precision (facets small enough to resolve it further have
// normals dominated by round-off), so the answer counts as converged (kOk); a wider
// bracket is reported as kDegenerate.
constexpr Real kEpaResolutionRel = 1e-8;

template <class SA, class SB>
class Epa {
 public:
  Epa(const SA& sa, const SB& sb, const Pose& b_in_a, const EpaSettings& st)
      : support_(sa, sb, b_in_a), st_(st), ws_(epa_workspace()), b_pos_(b_in_a.position) {
    max_faces_ = std::max(st.max_faces, 8);
    max_verts_ = std::max(st.max_iterations, 0) + 8;
    ws_.w.clear();
    ws_.a.clear();
    ws_.b.clear();
    ws_.faces.clear();
    ws_.free_faces.clear();
    ws_.key.clear();
    ws_.w.reserve(max_verts_);
    ws_.a.reserve(max_verts_);
    ws_.b.reserve(max_verts_);
    ws_.faces.reserve(max_faces_);
    ws_.key.reserve(max_faces_);
  }

  EpaResult run(const GjkResult& g) {
    const Simplex& s = g.simplex;
    for (int i = 0; i < s.count; ++i) push_vertex(s.w[i], s.a[i], s.b[i]);
    if (ws_.w.empty()) add_support(Vec3::UnitX());

    EpaResult flat;
    if (!blow_up(flat)) return flat;
    if (!build_tetrahedron()) return degenerate_answer();
    return expand();
  }

 private:
  MinkowskiSupport<SA, SB> support_;
  const EpaSettings& st_;
  EpaWorkspace& ws_;
  Vec3 b_pos_;
  int max_faces_ = 0, max_verts_ = 0;
  Real scale_ = 0;   // max |w| over the polytope's vertices
  Real scale2_ = 0;  // its square
  // Smallest support distance seen in expand(), the face normal it was found along, and
  // the support point of A that realised it (see capped()).
  Real upper_ = kInf;
  Vec3 upper_normal_ = Vec3::UnitX();
  Vec3 upper_point_a_ = Vec3::Zero();
  // Largest distance of a closest face popped while the polytope was consistent: a
  // lower bound on the depth (see expand()).
  Real lower_ = 0;

  int push_vertex(const Vec3& w, const Vec3& a, const Vec3& b) {
    ws_.w.push_back(w);
    ws_.a.push_back(a);
    ws_.b.push_back(b);
    const Real w2 = w.squaredNorm();
    if (w2 > scale2_) {
      scale2_ = w2;
      scale_ = std::sqrt(w2);
    }
    return static_cast<int>(ws_.w.size()) - 1;
  }
  int add_support(const Vec3& dir) {
    Vec3 pa, pb;
    const Vec3 w = support_(dir, pa, pb);
    return push_vertex(w, pa, pb);
  }
  Real flat_tol() const { return kEpaFlatRel * std::max(scale_, DBL_MIN); }

  // ---- Blow-up: grow GJK's 1-, 2- or 3-vertex simplex (the origin on a vertex, edge or
  // triangle of A - B) to a tetrahedron containing the origin. When A - B itself is
  // flat (a point, segment or polygon: e.g. sphere and capsule cores), the
  // penetration depth is exactly 0 and the answer is written to `out`; returns false.
  bool blow_up(EpaResult& out) {
    if (ws_.w.size() == 4) {
      // A nearly flat tetrahedron has no reliable face normals: keep the triangle that
      // holds the origin (or the first one) and blow it up again along its normal.
      const Vec3& y0 = ws_.w[0];
      const Real vol = (ws_.w[1] - y0).cross(ws_.w[2] - y0).dot(ws_.w[3] - y0);
      if (std::abs(vol) > kEpaSliverRel * scale_ * scale_ * scale_) return true;
      int drop = 3;
      for (int j = 3; j >= 0; --j) {
        std::array<int, 3> t{};
        for (int i = 0, k = 0; i < 4; ++i)
          if (i != j) t[k++] = i;
        SubSimplex sub;
        solve_triangle(ws_.w.data(), t[0], t[1], t[2], sub);
        if (sub.count == 3) {
          drop = j;
          break;
        }
      }
      pop_vertex(drop);
    }
    // Remove coincident GJK vertices first (possible only for a degenerate simplex).
    if (ws_.w.size() >= 2 && (ws_.w[1] - ws_.w[0]).norm() <= flat_tol()) pop_vertex(1);
    if (ws_.w.size() == 1) {
      // Farthest of the six axis supports from the single vertex.
      const Vec3 y0 = ws_.w[0];
      Real best = flat_tol();
      Vec3 best_dir = Vec3::Zero();
      for (int k = 0; k < 6; ++k) {
        Vec3 dir = Vec3::Zero();
        dir[k / 2] = (k % 2) ? -1 : 1;
        Vec3 pa, pb;
        const Real dist = (support_(dir, pa, pb) - y0).norm();
        if (dist > best) {
          best = dist;
          best_dir = dir;
        }
      }
      if (best_dir.isZero()) {
        // A - B is a single point: depth 0, no defined normal.
        out = result_from_points(0, fallback_normal(), ws_.a[0], ws_.b[0]);
        out.status = QueryStatus::kDegenerate;
        return false;
      }
      add_support(best_dir);
    }
    if (ws_.w.size() == 2) {
      // Third vertex: farthest from the segment's line among 6 directions around it.
      const Vec3 y0 = ws_.w[0];
      const Vec3 u = (ws_.w[1] - y0).normalized();
      Vec3 e1, e2;
      orthonormal_basis(u, e1, e2);
      Real best = flat_tol();
      Vec3 best_dir = Vec3::Zero();
      for (int k = 0; k < 6; ++k) {
        const Real ang = k * (kPi / 3);
        const Vec3 dir = std::cos(ang) * e1 + std::sin(ang) * e2;
        Vec3 pa, pb;
        Vec3 off = support_(dir, pa, pb) - y0;
        off -= off.dot(u) * u;
        const Real dist = off.norm();
        if (dist > best) {
          best = dist;
          best_dir = dir;
        }
      }
      if (best_dir.isZero()) {
        // A - B is a segment through the origin: depth 0 along any perpendicular; take
        // the one closest to the A -> B offset so the choice is stable.
        Vec3 n = b_pos_ - b_pos_.dot(u) * u;
        if (!(n.norm() > flat_tol())) n = e1;
        out = flat_answer(n.normalized());
        return false;
      }
      add_support(best_dir);
    }
    if (ws_.w.size() == 3) {
      const Vec3 y0 = ws_.w[0];
      Vec3 n = (ws_.w[1] - y0).cross(ws_.w[2] - y0);
      const Real len = n.norm();
      if (!(len > kEpaSliverRel * scale_ * scale_)) return fail_blow_up(out);
      n /= len;
      Vec3 pa_p, pb_p, pa_m, pb_m;
      const Vec3 wp = support_(n, pa_p, pb_p);
      const Vec3 wm = support_(-n, pa_m, pb_m);
      const Real off_p = n.dot(wp - y0), off_m = -n.dot(wm - y0);
      if (std::max(off_p, off_m) <= flat_tol()) {
        // A - B is a polygon containing the origin: depth 0 along +-n.
        out = flat_answer(n);
        return false;
      }
      if (off_p >= off_m) {
        push_vertex(wp, pa_p, pb_p);
      } else {
        push_vertex(wm, pa_m, pb_m);
      }
    }
    return true;
  }

  void pop_vertex(int i) {
    ws_.w.erase(ws_.w.begin() + i);
    ws_.a.erase(ws_.a.begin() + i);
    ws_.b.erase(ws_.b.begin() + i);
  }

  bool fail_blow_up(EpaResult& out) {
    out = degenerate_answer();
    return false;
  }

  // Depth 0 with normal +-n for a flat A - B, the sign chosen so that the normal points
  // from A's middle to B's middle along n (both measured with supports along +-n), so
  // that pushing B out along it is the natural choice.
  EpaResult flat_answer(const Vec3& n) {
    const Real mid_a = 0.5 * n.dot(support_.sa(n) + support_.sa(-n));
    const Real mid_b = 0.5 * n.dot(support_.support_b(n) + support_.support_b(-n));
    const Vec3 nn = mid_b >= mid_a ? n : Vec3(-n);
    // Witness: the origin lies in A - B, so a point of A coincides with a point of B;
    // the GJK closest points (first vertex combination) are such a pair up to
    // round-off.
    Vec3 pa = Vec3::Zero(), pb = Vec3::Zero();
    const int m = std::min<int>(static_cast<int>(ws_.w.size()), 3);
    if (m > 0) {
      // Closest point of the known vertices to the origin, by the sub-simplex solver.
      SubSimplex sub;
      solve_simplex(ws_.w.data(), m, sub);
      for (int i = 0; i < sub.count; ++i) {
        pa += sub.lambda[i] * ws_.a[sub.idx[i]];
        pb += sub.lambda[i] * ws_.b[sub.idx[i]];
      }
    }
    EpaResult r = result_from_points(0, nn, pa, pb);
    r.status = QueryStatus::kOk;
    return r;
  }

  Vec3 fallback_normal() const {
    const Real n = b_pos_.norm();
    return n > 0 && std::isfinite(n) ? Vec3(b_pos_ / n) : Vec3(Vec3::UnitX());
  }

  EpaResult result_from_points(Real depth, const Vec3& n, const Vec3& pa, const Vec3& pb) const {
    EpaResult r;
    r.depth = depth;
    r.normal = n;
    r.point_a = pa;
    r.point_b = pb;
    return r;
  }

  // Safe answer when nothing better is known: depth 0 along the A -> B offset.
  EpaResult degenerate_answer() const {
    EpaResult r = result_from_points(0, fallback_normal(), ws_.a.empty() ? Vec3(Vec3::Zero()) : ws_.a[0],
                                     ws_.b.empty() ? Vec3(Vec3::Zero()) : ws_.b[0]);
    r.status = QueryStatus::kDegenerate;
    return r;
  }

  // ---- Polytope ----
  // Allocates a face (v0, v1, v2); returns -1 if the pool is full or the face is a
  // sliver without a reliable normal (`sliver` tells which).
  int new_face(int i0, int i1, int i2, bool& sliver) {
    sliver = false;
    const Vec3& y0 = ws_.w[i0];
    Vec3 n = cross3(ws_.w[i1] - y0, ws_.w[i2] - y0);
    const Real len = n.norm();
    if (!(len > kEpaSliverRel * scale_ * scale_)) {
      sliver = true;
      return -1;
    }
    n /= len;
    int f;
    if (!ws_.free_faces.empty()) {
      f = ws_.free_faces.back();
      ws_.free_faces.pop_back();
    } else if (static_cast<int>(ws_.faces.size()) < max_faces_) {
      f = static_cast<int>(ws_.faces.size());
      ws_.faces.emplace_back();
      ws_.key.push_back(kInf);
    } else {
      return -1;
    }
    EpaFace& F = ws_.faces[f];
    F.v = {i0, i1, i2};
    F.adj = {-1, -1, -1};
    F.adj_edge = {0, 0, 0};
    F.n = n;
    // Plane distance from the centroid: the average cancels part of the round-off.
    F.d = n.dot(ws_.w[i0] + ws_.w[i1] + ws_.w[i2]) / 3;
    F.obsolete = false;
    return f;
  }

  void link(int f, int e, int g, int h) {
    ws_.faces[f].adj[e] = g;
    ws_.faces[f].adj_edge[e] = h;
    ws_.faces[g].adj[h] = f;
    ws_.faces[g].adj_edge[h] = e;
  }

  void add_candidate(int f, Real upper) {
    EpaFace& F = ws_.faces[f];
    // Faces beyond the best upper bound can never be the answer (van den Bergen 2001);
    // the flat tolerance keeps a face that is there only by round-off.
    if (F.d > upper + flat_tol()) return;
    ws_.key[static_cast<std::size_t>(f)] = F.d;
  }

  // The candidate face closest to the origin (ties: the lowest slot), taken out of the
  // candidates; -1 if there is none.
  int pop_closest() {
    const Real* key = ws_.key.data();
    const int n = static_cast<int>(ws_.key.size());
    int f = -1;
    Real best = kInf;
    for (int i = 0; i < n; ++i) {
      const bool closer = key[i] < best;
      best = closer ? key[i] : best;
      f = closer ? i : f;
    }
    if (f >= 0) drop_candidate(f);
    return f;
  }

  void drop_candidate(int f) { ws_.key[static_cast<std::size_t>(f)] = kInf; }

  // A face is a candidate while its key is finite (new and freed slots hold +inf).
  bool is_candidate(int f) const { return ws_.key[static_cast<std::size_t>(f)] < kInf; }

  void release(int f) {
    EpaFace& F = ws_.faces[f];
    if (F.obsolete && !is_candidate(f)) ws_.free_faces.push_back(f);
  }

  bool build_tetrahedron() {
    // Positive orientation: y3 on the side of (y1 - y0) x (y2 - y0).
    const Vec3& y0 = ws_.w[0];
    const Real vol = (ws_.w[1] - y0).cross(ws_.w[2] - y0).dot(ws_.w[3] - y0);
    if (!(std::abs(vol) > 0)) return false;
    int i1 = 1, i2 = 2;
    if (vol < 0) std::swap(i1, i2);
    const std::array<std::array<int, 3>, 4> fv{{{0, i2, i1}, {0, i1, 3}, {i1, i2, 3}, {0, 3, i2}}};
    std::array<int, 4> f{};
    bool sliver;
    for (int k = 0; k < 4; ++k) {
      f[k] = new_face(fv[k][0], fv[k][1], fv[k][2], sliver);
      if (f[k] < 0) return false;
    }
    // Adjacency of the four faces above: edge e of face p (fv[p][e] -> fv[p][e+1]) is
    // edge h of face q in reverse. Written out from fv (e.g. face 0's edge 0, 0 -> i2,
    // is face 3's edge 2, i2 -> 0); the tests compare EPA against brute-force depths.
    link(f[0], 0, f[3], 2);
    link(f[0], 1, f[2], 0);
    link(f[0], 2, f[1], 0);
    link(f[1], 1, f[2], 2);
    link(f[1], 2, f[3], 0);
    link(f[2], 1, f[3], 1);
    for (int k = 0; k < 4; ++k) add_candidate(f[k], kInf);
    return true;
  }

  // Barycentric coordinates of p in the triangle of face f (affine, unclamped).
  std::array<Real, 3> barycentric(int f, const Vec3& p) const {
    const EpaFace& F = ws_.faces[f];
    const Vec3& y0 = ws_.w[F.v[0]];
    const Vec3 e0 = ws_.w[F.v[1]] - y0, e1 = ws_.w[F.v[2]] - y0;
    const Vec3 nn = cross3(e0, e1);
    const Real den = nn.squaredNorm();
    std::array<Real, 3> l{Real(1) / 3, Real(1) / 3, Real(1) / 3};
    if (den > 0) {
      l[1] = cross3(p - y0, e1).dot(nn) / den;
      l[2] = cross3(e0, p - y0).dot(nn) / den;
      l[0] = 1 - l[1] - l[2];
    }
    return l;
  }

  // The answer along face f's plane (normal n, distance d) with the witness points
  // interpolated over the triangle `v` at barycentric coordinates `l`, clamped.
  EpaResult answer_from(const std::array<int, 3>& v, std::array<Real, 3> l, const Vec3& n, Real d,
                        QueryStatus status, int iterations) const {
    // Whatever is outside is round-off or a non-coplanar neighbour: clamp.
    Real sum = 0;
    for (Real& x : l) sum += (x = std::max(x, Real(0)));
    if (sum > 0) {
      for (Real& x : l) x /= sum;
    } else {
      l = {Real(1) / 3, Real(1) / 3, Real(1) / 3};
    }
    EpaResult r;
    r.status = status;
    r.depth = std::max(d, Real(0));
    r.normal = n;
    r.point_a = l[0] * ws_.a[v[0]] + l[1] * ws_.a[v[1]] + l[2] * ws_.a[v[2]];
    r.point_b = l[0] * ws_.b[v[0]] + l[1] * ws_.b[v[1]] + l[2] * ws_.b[v[2]];
    r.iterations = iterations;
    return r;
  }

  EpaResult answer_from_face(int f, QueryStatus status, int iterations) const {
    const EpaFace& F = ws_.faces[f];
    // The origin's projection on the face's plane.
    const Vec3 p = F.d * F.n;
    // A - B often has coplanar faces (box against box), which EPA splits into triangles
    // of equal distance; the scan may pick one that does not contain the projection.
    // Walk across edges to coplanar neighbours until the triangle holds it, so the
    // witness points satisfy point_a - point_b = depth * normal.
    int g = f;
    std::array<Real, 3> l = barycentric(g, p);
    // Coplanar within these bounds: 1e-9 on the normals' cosine is ~4e-5 rad, far
    // below any real edge of a polytope yet far above round-off; the plane offsets
    // must agree within the flat tolerance.
    for (int step = 0; step < 32; ++step) {
      const int j = static_cast<int>(std::min_element(l.begin(), l.end()) - l.begin());
      if (l[j] >= -1e-12) break;  // inside up to round-off of unit barycentrics
      const int e = (j + 1) % 3;   // edge opposite vertex j
      const int h = ws_.faces[g].adj[e];
      if (h < 0 || ws_.faces[h].obsolete) break;
      const EpaFace& H = ws_.faces[h];
      if (H.n.dot(F.n) < 1 - 1e-9 || std::abs(H.d - F.d) > flat_tol()) break;
      g = h;
      l = barycentric(g, p);
    }
    return answer_from(ws_.faces[g].v, l, F.n, F.d, status, iterations);
  }

  // The answer EPA falls back on if the iteration that expands face f fails (see
  // expand()). Kept unevaluated: it is needed only on the rare failure paths, while
  // building it (witness points, the capped() bracket, two EpaResult copies) every
  // iteration cost a fifth of EPA's time on boxes. The vertices of f outlive f itself
  // (EPA never removes vertices), so its barycentric coordinates suffice, unless the
  // origin's projection falls outside f: then answer_from_face would walk to a
  // coplanar neighbour through adjacency that this iteration rewrites, so that answer
  // is built at once. Either way it equals answer_from_face(f) at the time of capture.
  struct PendingAnswer {
    bool valid = false;
    bool built = false;
    EpaResult built_answer;
    std::array<int, 3> v{};
    std::array<Real, 3> l{};
    Vec3 n = Vec3::UnitX();
    Real d = 0;
    QueryStatus status = QueryStatus::kOk;
    int iterations = 0;
  };

  PendingAnswer capture(int f, QueryStatus status, int iterations) const {
    PendingAnswer p;
    p.valid = true;
    const EpaFace& F = ws_.faces[f];
    p.l = barycentric(f, F.d * F.n);
    if (*std::min_element(p.l.begin(), p.l.end()) < -1e-12) {
      p.built = true;
      p.built_answer = answer_from_face(f, status, iterations);
      return p;
    }
    p.v = F.v;
    p.n = F.n;
    p.d = F.d;
    p.status = status;
    p.iterations = iterations;
    return p;
  }

  EpaResult lower(const PendingAnswer& p) const {
    return p.built ? p.built_answer : answer_from(p.v, p.l, p.n, p.d, p.status, p.iterations);
  }

  // Answer for a stop before convergence (cap reached, or a polytope that cannot be
  // expanded consistently). The closest face gives a lower bound d on the depth, but
  // translating B by d along its normal leaves the sets overlapping by up to the
  // support distance along it minus d, which on curved supports stays wide when the
  // cap cuts EPA short (a sphere centre near a cylinder's axis: every radial direction
  // is nearly as shallow, and 128 iterations leave the polytope 1.7e-5 m inside). The
  // smallest support distance seen, `upper` along `upper_normal_`, is instead an
  // upper bound that is itself a valid answer: translating B by it along that normal
  // makes the sets touch exactly (van den Bergen 2001's upper bound). Such stops keep
  // their non-kOk status, and answer with the valid upper bound whenever the bracket
  // is wider than the requested tolerance, so that a penetration answer always
  // separates the pair. (A converged answer has a bracket within tolerance anyway.)
  EpaResult capped(const EpaResult& lower) const {
    if (!(upper_ < kInf)) return lower;
    const Real tol = tolerance_at(lower.depth);
    // A face farther than a support distance already seen: the polytope is no longer
    // convex (round-off), so its distance is no lower bound (see expand()).
    if (lower.depth > upper_ + tol) return broken_answer(lower.iterations);
    if (lower.status == QueryStatus::kOk) return lower;
    // Stopped early, but the bracket [lower, upper] may already be within tolerance, or
    // within the resolution limit of a tessellated curved surface (coincident
    // cylinders: a whole circle of minimal directions, which EPA tessellates until its
    // cap); the valid upper bound then counts as converged.
    const Real gap = upper_ - lower.depth;
    const bool resolved = gap <= tol || gap <= kEpaResolutionRel * scale_;
    return upper_answer(resolved ? QueryStatus::kOk : lower.status, lower.iterations);
  }

  // Stopping tolerance for a face at distance d (relative, or absolute near zero).
  Real tolerance_at(Real d) const { return std::max(st_.tolerance * std::abs(d), st_.absolute_tolerance); }

  // The smallest support distance seen as the answer: translating B by upper_ along
  // upper_normal_ makes the sets touch, so it is valid, and it exceeds the true depth
  // by at most upper_ - (any lower bound).
  EpaResult upper_answer(QueryStatus status, int iterations) const {
    EpaResult r;
    r.status = status;
    r.iterations = iterations;
    r.depth = std::max(upper_, Real(0));
    r.normal = upper_normal_;
    // The deepest point of A along the normal; B's witness on the plane it is moved to.
    r.point_a = upper_point_a_;
    r.point_b = upper_point_a_ - r.depth * upper_normal_;
    return r;
  }

  // Answer once round-off has made the polytope non-convex (a closest face beyond the
  // smallest support distance): the depth is still bracketed by [lower_, upper_], the
  // faces popped before the break and the supports seen, so the upper bound answers;
  // kOk if that bracket is within tolerance (or the resolution limit), else kDegenerate.
  EpaResult broken_answer(int iterations) const {
    const Real gap = upper_ - lower_;
    const bool ok = gap <= tolerance_at(lower_) || gap <= kEpaResolutionRel * scale_;
    return upper_answer(ok ? QueryStatus::kOk : QueryStatus::kDegenerate, iterations);
  }

  EpaResult expand() {
    Real& upper = upper_;  // smallest support distance seen: an upper bound on the depth
    // Fallback answer of the last face expanded (see PendingAnswer).
    PendingAnswer pending;
    const int max_it = std::max(st_.max_iterations, 1);
    for (int it = 0;; ++it) {
      // Closest live face.
      const int f = pop_closest();
      if (f < 0) {
        // Every face pruned or gone: only round-off can do this.
        return pending.valid ? capped(lower(pending)) : degenerate_answer();
      }
      if (it >= max_it) return capped(answer_from_face(f, QueryStatus::kMaxIterations, it));

      const Vec3 n = ws_.faces[f].n;
      const Real d = ws_.faces[f].d;
      const Real tol = tolerance_at(d);
      // In a convex polytope the closest face's distance is a lower bound on the depth
      // and never exceeds a support distance. Round-off in the silhouette test on
      // curved supports (w within ~1e-12 of a face's plane) can drop the faces near the
      // origin's projection, after which the closest face jumps far out (seen: from
      // 7.2e-4 to 4.6e-3 m on two cylinders); its distance then means nothing.
      if (d > upper + tol) return broken_answer(it);
      lower_ = std::max(lower_, d);
      Vec3 pa, pb;
      const Vec3 w = support_(n, pa, pb);
      const Real dw = n.dot(w);
      if (dw < upper) {
        upper = dw;
        upper_normal_ = n;
        upper_point_a_ = pa;
      }
      // Converged when the support plane along this face's own normal is within
      // tolerance of the face (relative to the depth, or absolute for near-zero
      // depths): then translating B by d * n separates the sets up to that tolerance.
      if (dw - d <= tol) return answer_from_face(f, QueryStatus::kOk, it);
      // Or when the global bracket [d, upper] is within tolerance: the smallest support
      // distance seen is then a valid answer within tolerance of the depth, though
      // along another face's normal (on curved supports this often comes first).
      if (upper - d <= tol) return upper_answer(QueryStatus::kOk, it);
      // Round-off floor: a gap of a few ulp of the size is no progress.
      if (dw - d <= 8 * DBL_EPSILON * scale_) return answer_from_face(f, QueryStatus::kOk, it);
      const auto& fv = ws_.faces[f].v;
      if (w == ws_.w[fv[0]] || w == ws_.w[fv[1]] || w == ws_.w[fv[2]])
        return answer_from_face(f, QueryStatus::kOk, it);
      if (static_cast<int>(ws_.w.size()) >= max_verts_)
        return capped(answer_from_face(f, QueryStatus::kMaxIterations, it));
      const QueryStatus stuck = dw - d <= kEpaResolutionRel * scale_ ? QueryStatus::kOk
                                                                        : QueryStatus::kDegenerate;
      pending = capture(f, stuck, it);
      // Every early return below answers with face f's bracket [d, dw] (capped()).
      auto fallback = [&] { return capped(lower(pending)); };
      const int wi = push_vertex(w, pa, pb);

      // Silhouette (van den Bergen 2001): depth-first walk from f over the faces that
      // see w; the edges where the walk meets a face that does not see w form the
      // horizon, in order around it.
      ws_.horizon.clear();
      ws_.stack.clear();
      ws_.created.clear();
      ws_.faces[f].obsolete = true;
      const Real ftol = flat_tol();  // after push_vertex, which may grow the scale
      for (int e = 2; e >= 0; --e) ws_.stack.push_back(ws_.faces[f].adj[e] * 4 + ws_.faces[f].adj_edge[e]);
      while (!ws_.stack.empty()) {
        const int packed = ws_.stack.back();
        ws_.stack.pop_back();
        const int g = packed >> 2, e = packed & 3;
        EpaFace& G = ws_.faces[g];
        if (G.obsolete) continue;
        // A face whose plane passes through w (within round-off) is removed too: kept,
        // it would leave a zero-area face between w and one of its edges when w lies
        // on that edge's line, which is common when A - B has coplanar features
        // (boxes on a grid). Its replacement fan lies in the same plane.
        if (G.n.dot(w) - G.d <= -ftol) {
          ws_.horizon.push_back(packed);
          continue;
        }
        G.obsolete = true;
        drop_candidate(g);
        ws_.created.push_back(g);  // reused below as the list of removed faces
        const int e2 = (e + 2) % 3, e1 = (e + 1) % 3;
        ws_.stack.push_back(G.adj[e2] * 4 + G.adj_edge[e2]);
        ws_.stack.push_back(G.adj[e1] * 4 + G.adj_edge[e1]);
      }
      release(f);
      for (int g : ws_.created) release(g);
      ws_.created.clear();

      // One new face per horizon edge, fanned around w.
      const int h = static_cast<int>(ws_.horizon.size());
      if (h < 3) return fallback();
      for (int k = 0; k < h; ++k) {
        const int g = ws_.horizon[k] >> 2, e = ws_.horizon[k] & 3;
        const EpaFace& G = ws_.faces[g];
        const int p = G.v[(e + 1) % 3], q = G.v[e];
        bool sliver;
        const int nf = new_face(p, q, wi, sliver);
        if (nf < 0) {
          if (sliver) return fallback();
          EpaResult r = lower(pending);  // face pool full
          r.status = QueryStatus::kMaxIterations;
          return capped(r);
        }
        // The new polytope contains the old one, so none of its faces can be closer to
        // the origin than the face just popped, the closest of the old ones (van den
        // Bergen 2001). A closer (typically inverted) face means round-off misjudged
        // which faces see w, as happens when w lies within ~1e-12 of face f's plane on
        // a curved support (cylinder rims): the polytope is no longer convex, and
        // expanding it further pops faces with negative distance (depth 0 answers)
        // and cycles. Stop with the popped face, whose bracket [d, dw] is still valid.
        if (ws_.faces[nf].d < d - ftol) return fallback();
        link(nf, 0, g, e);
        ws_.created.push_back(nf);
      }
      // Close the fan: face k's edge q -> w meets the face whose edge w -> p has p = q.
      for (int k = 0; k < h; ++k) {
        const int fk = ws_.created[k];
        const int q = ws_.faces[fk].v[1];
        int match = -1;
        for (int j = 0; j < h && match < 0; ++j) {
          const int c = (k + 1 + j) % h;  // the walk order makes c = k + 1 the usual hit
          if (ws_.faces[ws_.created[c]].v[0] == q) match = ws_.created[c];
        }
        if (match < 0) return fallback();
        link(fk, 1, match, 2);
      }
      for (int k = 0; k < h; ++k) add_candidate(ws_.created[k], upper);
    }
  }
};

}  // namespace detail

/// Penetration depth of overlapping convex A and B by EPA, seeded from the simplex of a
/// gjk_distance call that reported `intersecting` for the same supports and pose.
/// Simplices with fewer than 4 vertices (the origin on a vertex, edge or face of
/// A - B: touching) are blown up to a tetrahedron first. Returns depth >= 0, the unit
/// normal from A to B (translating B by depth * normal separates the sets) and the
/// deepest points (point_b = point_a - depth * normal), all in A's frame.
///
/// Degenerate input is answered safely, never with NaN and never looping:
///   * A - B flat (zero thickness, e.g. the cores of two crossing capsules): depth 0
///     exactly, normal perpendicular to the flat set, status kOk;
///   * A - B a single point (e.g. two concentric sphere cores): depth 0, normal along
///     b_in_a.position (or +X), status kDegenerate;
///   * a polytope that cannot be expanded consistently (sliver faces, or a new face
///     closer than the one expanded, from round-off, typically on curved cores such as
///     cylinders): the closest face found so far, kOk, if the support distance along
///     its normal is within kEpaResolutionRel (1e-8) of the size above it; otherwise
///     kDegenerate with the best valid answer (smallest support distance seen, an upper
///     bound on the depth along its normal);
///   * iteration or face cap reached: kMaxIterations with that best valid answer
///     (never a lower bound that leaves the pair overlapping, never depth 0 for a
///     clearly overlapping pair).
template <class SA, class SB>
EpaResult epa_penetration(const SA& sa, const SB& sb, const Pose& b_in_a, const GjkResult& gjk,
                          const EpaSettings& settings = {}) {
  detail::Epa<SA, SB> epa(sa, sb, b_in_a, settings);
  return epa.run(gjk);
}

// =====================================================================================
// GJK ray cast
// =====================================================================================

namespace detail {
// The ray cast stops when x is within kRayRel * max|y| of the set: far below any
// meaningful distance, above round-off (same reasoning as kGjkTouchRel, with room
// for the linear convergence on curved surfaces).
constexpr Real kRayRel = 1e-11;
}  // namespace detail

/// Ray cast against one convex set given by its support `s` (local frame): ray
/// origin + t * dir, 0 <= t <= max_t (t in units of |dir|; dir non-zero). Van den
/// Bergen 2004: GJK between the moving point and the set, advancing the point along the
/// ray past each separating plane found. On a hit, `distance` = t, `point` the hit
/// point and `normal` the outward unit normal (local frame). A ray starting inside (or
/// on the surface) hits at t = 0 with a zero normal. Stops after
/// settings.max_iterations support calls (status kMaxIterations, best estimate).
///
/// Accuracy: exact up to round-off on polytopes. On curved surfaces GJK converges
/// linearly and its simplex degenerates once the support points cluster within
/// round-off of each other; the hit point is then within ~1e-9 of the scene size of the
/// surface along its normal (5e-9 m worst case over 20000 random rays against unit
/// capsules and cylinders), and the normal, the last separating direction, within
/// ~1e-5 rad. Prefer an analytic ray cast where one exists.
template <class S>
RayHit gjk_raycast(const S& s, const Vec3& origin, const Vec3& dir, Real max_t,
                   const GjkSettings& settings = {}) {
  RayHit hit;
  Real lambda = 0;
  Vec3 x = origin;
  Vec3 n = Vec3::Zero();
  std::array<Vec3, 4> p{};  // support points of the set (the simplex is x - p_i)
  std::array<Vec3, 4> y{};
  int count = 0;
  Vec3 v = x - s(-dir);
  Real scale2 = v.squaredNorm();
  const int max_it = std::max(settings.max_iterations, 1);
  bool converged = false;
  bool restarted = false;  // simplex restarted since x last moved
  for (int it = 0; it < max_it; ++it) {
    const Real dist2 = v.squaredNorm();
    if (dist2 <= detail::kRayRel * detail::kRayRel * scale2) {
      converged = true;
      break;
    }
    const Vec3 sp = s(v);
    const Vec3 w = x - sp;
    const Real vw = v.dot(w);
    scale2 = std::max(scale2, w.squaredNorm());
    bool advanced = false;
    if (vw > 0) {
      // v separates x from the set: advance x to the plane, or miss.
      const Real vr = v.dot(dir);
      if (vr >= 0) return hit;
      const Real next = lambda - vw / vr;
      if (!(next <= max_t)) return hit;
      advanced = next != lambda;  // a step below round-off of lambda is no step
      lambda = next;
      x = origin + lambda * dir;
      n = v;
    }
    // Add the new support point unless it is already a vertex.
    bool duplicate = false;
    for (int i = 0; i < count; ++i) duplicate = duplicate || (p[i] == sp);
    if (duplicate && !advanced) {
      // Neither x nor the simplex can change: x is on the surface up to round-off.
      converged = true;
      break;
    }
    if (!duplicate) p[count++] = sp;
    for (int i = 0; i < count; ++i) y[i] = x - p[i];
    detail::SubSimplex sub;
    detail::solve_simplex(y.data(), count, sub);
    const Vec3 vn = sub.point;
    for (int i = 0; i < sub.count; ++i) p[i] = p[sub.idx[i]];
    count = sub.count;
    if (count == 4) {  // x inside the simplex, hence inside the set
      v = vn;
      converged = true;
      break;
    }
    // With x fixed, |v| must shrink. Near the surface the simplex points cluster in
    // the tangent plane and round-off can stall it: x is then as close to the set
    // as double precision resolves, which is a hit when it is close at all.
    if (!advanced && !(vn.squaredNorm() < dist2)) {
      if (!restarted) {
        // First try a fresh simplex from the newest support point alone: it drops the
        // clustered, ill-conditioned vertices.
        restarted = true;
        p[0] = sp;
        count = 1;
        v = x - sp;
        continue;
      }
      converged = dist2 <= 1e-12 * scale2;  // within 1e-6 of the size
      if (!converged) return hit;
      break;
    }
    if (advanced) restarted = false;
    v = vn;
  }
  if (!converged) {
    // Cap reached: report the estimate when x is close to the set.
    if (v.squaredNorm() > 1e-12 * scale2) return hit;  // 1e-6 of the size: clearly off
    hit.status = QueryStatus::kMaxIterations;
  }
  hit.hit = true;
  hit.distance = lambda;
  hit.point = x;
  const Real nn = n.norm();
  hit.normal = (lambda > 0 && nn > 0) ? Vec3(n / nn) : Vec3(Vec3::Zero());
  return hit;
}

}  // namespace wmo
