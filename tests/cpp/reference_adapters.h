// Reference adapters: WMO convex shapes + world poses -> FCL 0.7 objects and libccd 2.1
// support objects, analytic reference answers for the pairs that have one, and a random
// configuration generator weighted to the hard region (touching and nearly touching).
//
// Header-only; shared by tests/cpp/collision/test_reference_crosscheck.cpp and
// benchmarks/narrowphase/bench_narrowphase.cpp (tests/cpp is on both include paths).
// This is test code: it links FCL and libccd, which the WMO core never does.
//
// Conventions (wmo/types.h): world poses in, world results out; normals unit, from A to
// B; depth > 0 when overlapping; signed distance = distance when apart, -depth when
// overlapping.
//
// Axis conventions, checked by the analytic face cases in test_reference_crosscheck.cpp:
//   * FCL's Box takes FULL side lengths (WMO: half extents).
//   * FCL's Capsule and Cylinder are along local Z with `lz` the full length of the
//     cylindrical part; WMO's are along local Y with a half height. The FCL transform is
//     the WMO pose composed with a fixed rotation of -90 degrees about X, which maps
//     FCL's +Z onto WMO's +Y.
//   * libccd: `ccdGJKPenetration` / `ccdMPRPenetration` return (depth, dir, pos) such
//     that moving obj2 by depth * dir separates the pair, so dir is WMO's A->B normal
//     with obj1 = A and obj2 = B.
#pragma once

#include <ccd/ccd.h>
#include <ccd/vec3.h>

#include <fcl/fcl.h>

#include <algorithm>
#include <cmath>
#include <memory>
#include <optional>
#include <random>
#include <vector>

#include "wmo/geometry/convex_queries.h"
#include "wmo/geometry/shapes.h"
#include "wmo/math.h"

namespace wmo::ref {

// =====================================================================================
// Settings of the reference libraries (stated once, reported by the benchmark)
// =====================================================================================

/// libccd iteration cap. libccd's default is unbounded ((unsigned long)-1); EPA on curved
/// shapes (sphere, capsule, cylinder support maps) converges only linearly, so a cap keeps
/// every query bounded. 1000 is far above what polytopes need (tens of iterations) and
/// what curved shapes need at epa_tolerance 1e-4 (a few hundred at most).
constexpr unsigned long kCcdMaxIterations = 1000;
/// libccd's EPA / MPR tolerances: its own defaults (1e-4 m absolute for EPA's face
/// distance progress, 1e-4 for MPR's portal), used for the headline benchmark so libccd
/// runs as shipped. The tolerance sweep varies epa_tolerance explicitly.
constexpr double kCcdEpaTolerance = 1e-4;
constexpr double kCcdMprTolerance = 1e-4;
/// libccd's GJK distance tolerance: its default.
constexpr double kCcdDistTolerance = 1e-6;

// =====================================================================================
// FCL
// =====================================================================================

/// Rotation taking FCL's capsule / cylinder axis (+Z) to WMO's (+Y): -90 degrees about X.
inline Mat3 fcl_axis_fix() { return Eigen::AngleAxisd(-kPi / 2, Vec3::UnitX()).toRotationMatrix(); }

inline bool needs_axis_fix(const ConvexShape& s) {
  return s.type() == ShapeType::kCapsule || s.type() == ShapeType::kCylinder;
}

/// FCL geometry for a WMO convex shape (local frame; see the axis notes at the top).
/// Rounded boxes have no FCL counterpart and are rejected.
inline std::shared_ptr<fcl::CollisionGeometryd> to_fcl_geometry(const ConvexShape& s) {
  switch (s.type()) {
    case ShapeType::kSphere:
      return std::make_shared<fcl::Sphered>(s.radius());
    case ShapeType::kBox: {
      const auto& b = static_cast<const Box&>(s);
      if (b.radius() != 0) throw InvalidArgument("to_fcl_geometry: rounded boxes have no FCL shape");
      const Vec3 full = 2.0 * b.half_extents();  // FCL: full side lengths
      return std::make_shared<fcl::Boxd>(full.x(), full.y(), full.z());
    }
    case ShapeType::kCapsule: {
      const auto& c = static_cast<const Capsule&>(s);
      return std::make_shared<fcl::Capsuled>(c.radius(), 2.0 * c.half_height());
    }
    case ShapeType::kCylinder: {
      const auto& c = static_cast<const Cylinder&>(s);
      return std::make_shared<fcl::Cylinderd>(c.cylinder_radius(), 2.0 * c.half_height());
    }
    case ShapeType::kConvexHull: {
      const auto& h = static_cast<const ConvexHull&>(s);
      auto verts = std::make_shared<std::vector<fcl::Vector3d>>(h.vertices().begin(), h.vertices().end());
      auto faces = std::make_shared<std::vector<int>>();
      for (int f = 0; f < static_cast<int>(h.faces().size()); ++f) {
        const std::vector<int> fv = h.face_vertices(f);
        faces->push_back(static_cast<int>(fv.size()));
        faces->insert(faces->end(), fv.begin(), fv.end());
      }
      return std::make_shared<fcl::Convexd>(verts, static_cast<int>(h.faces().size()), faces);
    }
    default:
      throw InvalidArgument("to_fcl_geometry: unsupported shape type");
  }
}

/// FCL transform of a WMO shape at world pose `p` (axis fix composed for capsule and
/// cylinder).
inline fcl::Transform3d to_fcl_transform(const ConvexShape& s, const Pose& p) {
  fcl::Transform3d t = fcl::Transform3d::Identity();
  Mat3 r = p.matrix();
  if (needs_axis_fix(s)) r = r * fcl_axis_fix();
  t.linear() = r;
  t.translation() = p.position;
  return t;
}

/// An FCL collision object built once per shape; `place` sets its world pose.
struct FclObject {
  std::shared_ptr<fcl::CollisionGeometryd> geometry;
  std::unique_ptr<fcl::CollisionObjectd> object;
  const ConvexShape* shape = nullptr;

  FclObject() = default;
  FclObject(const ConvexShape& s, const Pose& p)
      : geometry(to_fcl_geometry(s)),
        object(std::make_unique<fcl::CollisionObjectd>(geometry, to_fcl_transform(s, p))),
        shape(&s) {}
  void place(const Pose& p) { object->setTransform(to_fcl_transform(*shape, p)); }
};

/// Result of a reference query, world frame.
struct RefResult {
  bool intersecting = false;
  /// Signed: distance when apart; -depth when overlapping (when the query reports depth).
  double signed_distance = 0;
  Vec3 normal = Vec3::Zero();  ///< from A to B (penetration queries only)
  Vec3 point_a = Vec3::Zero();
  Vec3 point_b = Vec3::Zero();
};

/// FCL boolean collision (no contacts).
inline bool fcl_intersect(const FclObject& a, const FclObject& b) {
  fcl::CollisionRequestd req;  // 1 contact, no contact data: boolean only
  fcl::CollisionResultd res;
  fcl::collide(a.object.get(), b.object.get(), req, res);
  return res.isCollision();
}

/// FCL distance with nearest points. Solver: GST_LIBCCD (FCL's default, its modified
/// libccd GJK with exact sphere/capsule/box special cases). GST_INDEP was rejected: in
/// FCL 0.7 its nearest points for curved shapes are known to be less accurate. FCL's
/// distance_tolerance is set to 1e-10 (default 1e-6) so the reference is not the loosest
/// party in a comparison at 1e-6 m. When overlapping, FCL returns a negative
/// (non-signed) distance; we report intersecting = true and signed_distance = 0.
inline RefResult fcl_distance(const FclObject& a, const FclObject& b) {
  fcl::DistanceRequestd req;
  req.enable_nearest_points = true;
  req.gjk_solver_type = fcl::GST_LIBCCD;
  req.distance_tolerance = 1e-10;
  fcl::DistanceResultd res;
  fcl::distance(a.object.get(), b.object.get(), req, res);
  RefResult r;
  r.intersecting = res.min_distance <= 0;
  r.signed_distance = r.intersecting ? 0.0 : res.min_distance;
  r.point_a = res.nearest_points[0];
  r.point_b = res.nearest_points[1];
  return r;
}

/// FCL collision with contacts (up to 4, like a WMO manifold): the deepest contact's
/// depth and normal (FCL 0.7's contact normal points from o1 to o2). `gjk_tolerance`
/// is FCL's CollisionRequest::gjk_tolerance (its default 1e-6); it has no effect on
/// the pairs FCL answers with its own special routines.
inline RefResult fcl_collide_depth(const FclObject& a, const FclObject& b, double gjk_tolerance = 1e-6) {
  fcl::CollisionRequestd req(4, true);
  req.gjk_tolerance = gjk_tolerance;
  fcl::CollisionResultd res;
  fcl::collide(a.object.get(), b.object.get(), req, res);
  RefResult r;
  r.intersecting = res.isCollision();
  if (!r.intersecting) return r;
  double best = -kInf;
  for (std::size_t i = 0; i < res.numContacts(); ++i) {
    const auto& c = res.getContact(i);
    if (c.penetration_depth > best) {
      best = c.penetration_depth;
      r.normal = c.normal;
      r.point_a = c.pos;
    }
  }
  r.signed_distance = -best;
  return r;
}

/// FCL's own generic GJK and EPA (fcl::detail::GJK, EPA on a MinkowskiDiff, as
/// GJKSolver_indep runs them for a pair it has no special routine for), called
/// directly so that they answer every pair, those FCL's collide() hands to its closed
/// forms (sphere-box, box-box, ...) included: the like-for-like peer of WMO's GJK/EPA.
/// One contact, the depth only (FCL 0.7 leaves this path's normal in shape 1's frame);
/// `tolerance` is GJK's and EPA's (GJKSolver_indep's defaults: 1e-6, and 128
/// iterations, 128 faces, 64 vertices, 255 EPA iterations).
inline RefResult fcl_gjk_epa_depth(const FclObject& a, const FclObject& b, double tolerance = 1e-6) {
  const auto* s1 = static_cast<const fcl::ShapeBased*>(a.geometry.get());
  const auto* s2 = static_cast<const fcl::ShapeBased*>(b.geometry.get());
  const fcl::Transform3d& tf1 = a.object->getTransform();
  const fcl::Transform3d& tf2 = b.object->getTransform();
  fcl::detail::MinkowskiDiff<double> shape;
  shape.shapes[0] = s1;
  shape.shapes[1] = s2;
  shape.toshape1.noalias() = tf2.linear().transpose() * tf1.linear();
  shape.toshape0 = tf1.inverse(Eigen::Isometry) * tf2;
  const fcl::Vector3d guess(1, 0, 0);
  fcl::detail::GJK<double> gjk(128, tolerance);
  RefResult r;
  if (gjk.evaluate(shape, -guess) != fcl::detail::GJK<double>::Inside) return r;
  fcl::detail::EPA<double> epa(128, 64, 255, tolerance);
  if (epa.evaluate(gjk, -guess) == fcl::detail::EPA<double>::Failed) return r;
  r.intersecting = true;
  r.signed_distance = -epa.depth;
  return r;
}

// =====================================================================================
// libccd
// =====================================================================================

/// What libccd's callbacks see: a WMO shape and its world pose.
struct CcdObject {
  const ConvexShape* shape = nullptr;
  Pose pose;
};

/// World support point: rotate the direction into the local frame, take the WMO shape's
/// full support (radius included), map back.
inline void ccd_support(const void* obj, const ccd_vec3_t* dir, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObject*>(obj);
  const Vec3 d(dir->v[0], dir->v[1], dir->v[2]);
  const Vec3 p = o->pose.transform_point(o->shape->support(o->pose.inverse_transform_vector(d)));
  out->v[0] = p.x();
  out->v[1] = p.y();
  out->v[2] = p.z();
}

/// A point inside the shape (MPR's interior point): the local origin, inside every WMO
/// primitive, and inside the benchmark hulls (points around the origin).
inline void ccd_center(const void* obj, ccd_vec3_t* out) {
  const auto* o = static_cast<const CcdObject*>(obj);
  out->v[0] = o->pose.position.x();
  out->v[1] = o->pose.position.y();
  out->v[2] = o->pose.position.z();
}

/// libccd settings with WMO callbacks. `epa_tolerance` defaults to kCcdEpaTolerance.
inline ccd_t make_ccd(double epa_tolerance = kCcdEpaTolerance, double mpr_tolerance = kCcdMprTolerance) {
  ccd_t c;
  CCD_INIT(&c);
  c.support1 = ccd_support;
  c.support2 = ccd_support;
  c.center1 = ccd_center;
  c.center2 = ccd_center;
  c.max_iterations = kCcdMaxIterations;
  c.epa_tolerance = epa_tolerance;
  c.mpr_tolerance = mpr_tolerance;
  c.dist_tolerance = kCcdDistTolerance;
  return c;
}

inline bool ccd_intersect(const CcdObject& a, const CcdObject& b, const ccd_t& c) {
  return ccdGJKIntersect(&a, &b, &c) != 0;
}

inline RefResult ccd_result(int rc, double depth, const ccd_vec3_t& dir, const ccd_vec3_t& pos) {
  RefResult r;
  r.intersecting = rc == 0;
  if (!r.intersecting) return r;
  r.signed_distance = -depth;
  r.normal = Vec3(dir.v[0], dir.v[1], dir.v[2]);
  r.point_a = Vec3(pos.v[0], pos.v[1], pos.v[2]);
  return r;
}

/// GJK + EPA penetration (libccd): rc 0 when overlapping, depth/dir/pos filled.
inline RefResult ccd_penetration_gjk(const CcdObject& a, const CcdObject& b, const ccd_t& c) {
  double depth = 0;
  ccd_vec3_t dir, pos;
  const int rc = ccdGJKPenetration(&a, &b, &c, &depth, &dir, &pos);
  return ccd_result(rc, depth, dir, pos);
}

/// MPR penetration (libccd).
inline RefResult ccd_penetration_mpr(const CcdObject& a, const CcdObject& b, const ccd_t& c) {
  double depth = 0;
  ccd_vec3_t dir, pos;
  const int rc = ccdMPRPenetration(&a, &b, &c, &depth, &dir, &pos);
  return ccd_result(rc, depth, dir, pos);
}

// =====================================================================================
// Analytic references
// =====================================================================================

/// Closest points between segments p1-q1 and p2-q2 (Ericson, Real-Time Collision
/// Detection, 5.1.9), returning the squared distance. Degenerate segments handled.
inline double segment_segment_closest(const Vec3& p1, const Vec3& q1, const Vec3& p2, const Vec3& q2,
                                      Vec3& c1, Vec3& c2) {
  const Vec3 d1 = q1 - p1, d2 = q2 - p2, r = p1 - p2;
  const double a = d1.squaredNorm(), e = d2.squaredNorm(), f = d2.dot(r);
  constexpr double kEps = 1e-300;
  double s = 0, t = 0;
  if (a <= kEps && e <= kEps) {
    s = t = 0;
  } else if (a <= kEps) {
    t = std::clamp(f / e, 0.0, 1.0);
  } else {
    const double c = d1.dot(r);
    if (e <= kEps) {
      s = std::clamp(-c / a, 0.0, 1.0);
    } else {
      const double b = d1.dot(d2), denom = a * e - b * b;
      s = denom > 0 ? std::clamp((b * f - c * e) / denom, 0.0, 1.0) : 0.0;
      t = (b * s + f) / e;
      if (t < 0) {
        t = 0;
        s = std::clamp(-c / a, 0.0, 1.0);
      } else if (t > 1) {
        t = 1;
        s = std::clamp((b - c) / a, 0.0, 1.0);
      }
    }
  }
  c1 = p1 + d1 * s;
  c2 = p2 + d2 * t;
  return (c1 - c2).squaredNorm();
}

/// Signed distance from world point x to a sharp box at `pose`: exact inside (minus
/// the distance to the nearest face) and outside.
inline double point_box_signed_distance(const Box& b, const Pose& pose, const Vec3& x) {
  const Vec3 q = pose.inverse_transform_point(x).cwiseAbs() - b.half_extents();
  const double outside = q.cwiseMax(0.0).norm();
  const double inside = std::min(q.maxCoeff(), 0.0);
  return outside + inside;
}

/// Core segment of a sphere (a point) or capsule, world frame.
inline void core_segment(const ConvexShape& s, const Pose& p, Vec3& e0, Vec3& e1) {
  if (s.type() == ShapeType::kCapsule) {
    const double h = static_cast<const Capsule&>(s).half_height();
    e0 = p.transform_point(Vec3(0, -h, 0));
    e1 = p.transform_point(Vec3(0, h, 0));
  } else {
    e0 = e1 = p.position;
  }
}

/// Exact signed distance (distance apart, -depth overlapping) for sphere-sphere,
/// sphere-box, sphere-capsule and capsule-capsule in either order; nullopt otherwise.
/// Why exact: a sphere or capsule is a point / segment core inflated by its radius. For
/// core pairs whose Minkowski difference is at most 2-dimensional (point, segment,
/// parallelogram), the penetration depth is the radii sum minus the core distance even
/// when the cores touch, since leaving a flat set along its normal costs nothing. For
/// sphere-box the box is the core; the signed point-box distance minus the radius is
/// exact inside and out (box sharp).
inline std::optional<double> analytic_signed_distance(const ConvexShape& a, const Pose& pa,
                                                      const ConvexShape& b, const Pose& pb) {
  auto round = [](const ConvexShape& s) {
    return s.type() == ShapeType::kSphere || s.type() == ShapeType::kCapsule;
  };
  if (round(a) && round(b)) {
    Vec3 a0, a1, b0, b1, ca, cb;
    core_segment(a, pa, a0, a1);
    core_segment(b, pb, b0, b1);
    const double d = std::sqrt(segment_segment_closest(a0, a1, b0, b1, ca, cb));
    return d - a.radius() - b.radius();
  }
  if (a.type() == ShapeType::kSphere && b.type() == ShapeType::kBox && b.radius() == 0)
    return point_box_signed_distance(static_cast<const Box&>(b), pb, pa.position) - a.radius();
  if (b.type() == ShapeType::kSphere && a.type() == ShapeType::kBox && a.radius() == 0)
    return point_box_signed_distance(static_cast<const Box&>(a), pa, pb.position) - b.radius();
  return std::nullopt;
}

// =====================================================================================
// Random configurations weighted to the hard region
// =====================================================================================

/// Classes of a configuration, by WMO's signed distance s between the pair:
///   kDeep:              s < -1e-3
///   kBarelyOverlapping: -1e-3 <= s <= -1e-6 (target drawn log-uniformly)
///   kTouching:          |s| < 1e-9 (t* from bisection on WMO's intersect test)
///   kBarelySeparated:   1e-6 <= s <= 1e-3
///   kFar:               s > 1e-3
enum class ConfigClass : int { kDeep = 0, kBarelyOverlapping, kTouching, kBarelySeparated, kFar, kCount };

inline const char* to_string(ConfigClass c) {
  switch (c) {
    case ConfigClass::kDeep: return "deep";
    case ConfigClass::kBarelyOverlapping: return "barely_overlapping";
    case ConfigClass::kTouching: return "touching";
    case ConfigClass::kBarelySeparated: return "barely_separated";
    case ConfigClass::kFar: return "far";
    default: return "?";
  }
}

struct PairConfig {
  std::shared_ptr<const ConvexShape> a, b;
  Pose pose_a, pose_b;
  ConfigClass cls = ConfigClass::kDeep;
  /// WMO's signed distance of the relative configuration when generated (default tolerances).
  double signed_distance = 0;
};

/// 20 points on the unit sphere from a fixed seed: the benchmark's and tests' hull.
inline std::vector<Vec3> unit_hull_points(int n = 20, std::uint64_t seed = 20240611) {
  std::mt19937_64 rng(seed);
  std::normal_distribution<double> g(0, 1);
  std::vector<Vec3> pts;
  while (static_cast<int>(pts.size()) < n) {
    Vec3 v(g(rng), g(rng), g(rng));
    if (v.norm() > 1e-3) pts.push_back(v.normalized());
  }
  return pts;
}

class ConfigGenerator {
 public:
  explicit ConfigGenerator(std::uint64_t seed) : rng_(seed), hull_points_(unit_hull_points()) {}

  double uniform(double lo, double hi) { return std::uniform_real_distribution<double>(lo, hi)(rng_); }
  double log_uniform(double lo, double hi) { return std::exp(uniform(std::log(lo), std::log(hi))); }

  /// Uniform random rotation (Shoemake 1992, "Uniform random rotations").
  Quat random_rotation() {
    const double u1 = uniform(0, 1), u2 = uniform(0, 2 * kPi), u3 = uniform(0, 2 * kPi);
    const double s1 = std::sqrt(1 - u1), s2 = std::sqrt(u1);
    Quat q(s2 * std::cos(u3), s1 * std::sin(u2), s1 * std::cos(u2), s2 * std::sin(u3));
    return q.normalized();
  }
  Vec3 random_unit() {
    std::normal_distribution<double> g(0, 1);
    for (;;) {
      Vec3 v(g(rng_), g(rng_), g(rng_));
      if (v.norm() > 1e-6) return v.normalized();
    }
  }

  /// Random shape of a type; every size parameter (radius, half extent, half height) is
  /// log-uniform in [0.025, 1] m, i.e. extents 0.05..2 m.
  std::shared_ptr<const ConvexShape> random_shape(ShapeType t) {
    auto sz = [this] { return log_uniform(0.025, 1.0); };
    switch (t) {
      case ShapeType::kSphere: return std::make_shared<Sphere>(sz());
      case ShapeType::kBox: return std::make_shared<Box>(Vec3(sz(), sz(), sz()));
      case ShapeType::kCapsule: return std::make_shared<Capsule>(sz(), sz());
      case ShapeType::kCylinder: return std::make_shared<Cylinder>(sz(), sz());
      case ShapeType::kConvexHull: {
        const double s = sz();
        std::vector<Vec3> p = hull_points_;
        for (auto& v : p) v *= s;
        return std::make_shared<ConvexHull>(p);
      }
      default: throw InvalidArgument("random_shape: not a convex type");
    }
  }

  /// A configuration of a random A and B of the given types in class `cls`. B is placed
  /// along a random direction u from A's centre at distance t in A's frame; along that
  /// ray the signed distance is -depth (concave, >0 depth at t = 0 because both shapes
  /// contain their centres) up to the touching parameter t*, then the distance (convex,
  /// increasing), so each class is one bisection. A's world pose is random within 3 m
  /// of the origin.
  PairConfig make(ShapeType ta, ShapeType tb, ConfigClass cls) {
    for (;;) {
      PairConfig c;
      c.a = random_shape(ta);
      c.b = random_shape(tb);
      c.cls = cls;
      const Vec3 u = random_unit();
      const Quat rb = random_rotation();
      auto rel = [&](double t) { return Pose(t * u, rb); };
      auto sd = [&](double t) { return penetration_convex_convex(*c.a, *c.b, rel(t)).distance; };
      const double reach = bound(*c.a) + bound(*c.b);
      if (!intersect_convex_convex(*c.a, *c.b, rel(0))) continue;
      // Touching parameter by bisection on the boolean test: 64 halvings of [0, 2*reach]
      // leave a bracket of ~1e-19 * reach, i.e. at round-off.
      double lo = 0, hi = 2 * reach;
      for (int i = 0; i < 64 && hi - lo > 1e-12 * reach; ++i) {
        const double mid = 0.5 * (lo + hi);
        (intersect_convex_convex(*c.a, *c.b, rel(mid)) ? lo : hi) = mid;
      }
      const double t_star = hi;
      double t = t_star;
      switch (cls) {
        case ConfigClass::kDeep: t = uniform(0, 0.9) * t_star; break;
        case ConfigClass::kTouching: t = t_star; break;
        case ConfigClass::kFar: t = t_star + uniform(0.05, 1.0) * reach; break;
        case ConfigClass::kBarelyOverlapping: {
          const double target = -log_uniform(1e-6, 1e-3);
          t = solve(sd, 0.0, t_star, target);
          break;
        }
        case ConfigClass::kBarelySeparated: {
          const double target = log_uniform(1e-6, 1e-3);
          double step = target;
          double h = t_star + step;
          for (int i = 0; i < 60 && sd(h) < target; ++i) h = t_star + (step *= 2);
          t = solve(sd, t_star, h, target);
          break;
        }
        default: break;
      }
      c.signed_distance = sd(t);
      if (!in_class(cls, c.signed_distance)) continue;  // rare: resample
      c.pose_a = Pose(Vec3(uniform(-3, 3), uniform(-3, 3), uniform(-3, 3)), random_rotation());
      c.pose_b = c.pose_a * rel(t);
      return c;
    }
  }

  static bool in_class(ConfigClass cls, double s) {
    switch (cls) {
      case ConfigClass::kDeep: return s < -1e-3;
      case ConfigClass::kBarelyOverlapping: return s <= -0.9e-6 && s >= -1.1e-3;
      case ConfigClass::kTouching: return std::abs(s) < 1e-9;
      case ConfigClass::kBarelySeparated: return s >= 0.9e-6 && s <= 1.1e-3;
      case ConfigClass::kFar: return s > 1e-3;
      default: return false;
    }
  }

 private:
  /// Radius of a ball around the local origin containing the shape.
  static double bound(const ConvexShape& s) {
    const Aabb b = s.local_aabb();
    return b.max.cwiseAbs().cwiseMax(b.min.cwiseAbs()).norm();
  }
  /// Bisection for sd(t) = target on [lo, hi] with sd(lo) < target < sd(hi) (sd is
  /// monotone there, see make()); stops within 2% of |target| (the classes are ranges,
  /// not exact values) or after 200 halvings.
  template <class F>
  static double solve(F&& sd, double lo, double hi, double target) {
    double t = 0.5 * (lo + hi);
    for (int i = 0; i < 200; ++i) {
      t = 0.5 * (lo + hi);
      const double v = sd(t);
      if (std::abs(v - target) <= 0.02 * std::abs(target)) break;
      (v < target ? lo : hi) = t;
    }
    return t;
  }

  std::mt19937_64 rng_;
  std::vector<Vec3> hull_points_;
};

}  // namespace wmo::ref
