// Convex pair routines in A's frame: type dispatch onto the GJK / EPA templates (gjk.h),
// plane against convex, triangle against convex, and ray casts against single shapes.
#include "wmo/geometry/convex_queries.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "wmo/geometry/gjk.h"

namespace wmo {

namespace {

// Calls f with the concrete (final) class of `s`, so every template below is
// instantiated per concrete type and its support calls are direct.
template <class F>
decltype(auto) visit_convex(const ConvexShape& s, F&& f) {
  switch (s.type()) {
    case ShapeType::kSphere:
      return f(static_cast<const Sphere&>(s));
    case ShapeType::kBox:
      return f(static_cast<const Box&>(s));
    case ShapeType::kCapsule:
      return f(static_cast<const Capsule&>(s));
    case ShapeType::kCylinder:
      return f(static_cast<const Cylinder&>(s));
    case ShapeType::kConvexHull:
      return f(static_cast<const ConvexHull&>(s));
    default:
      break;
  }
  throw InvalidArgument(std::string("not a convex shape type: ") + to_string(s.type()));
}

// Below this fraction of the Minkowski difference's size, the direction between two
// nearly touching cores comes from round-off (its error is ~ DBL_EPSILON * size /
// distance, here <= 1e-7 rad): such pairs go to EPA, which gets the normal from the
// polytope instead.
constexpr Real kCoreNormalRel = 1e-9;

Real simplex_scale(const Simplex& s) {
  Real m = 0;
  for (int i = 0; i < s.count; ++i) m = std::max(m, s.w[i].norm());
  return m;
}

// The shared core + radius logic. `ca` / `cb` are core supports, `ra` / `rb` the radii.
template <class SA, class SB>
DistanceResult core_pair(const SA& ca, Real ra, const SB& cb, Real rb, const Pose& b_in_a,
                         bool signed_distance, const GjkSettings& gjk_settings,
                         const EpaSettings& epa_settings, Real cull = kInf) {
  DistanceResult r;
  // The cores are farther apart than the shapes by ra + rb.
  const GjkResult g = gjk_distance(ca, cb, b_in_a, gjk_settings, b_in_a.position, cull + ra + rb);
  r.status = g.status;
  r.iterations = g.iterations;
  const Real radii = ra + rb;
  if (!g.intersecting) {
    const Vec3& n = g.normal;
    r.normal = n;
    r.point_a = g.point_a + ra * n;
    r.point_b = g.point_b - rb * n;
    if (g.distance > radii) {
      r.distance = g.distance - radii;
      return r;
    }
    r.intersecting = true;
    if (!signed_distance) {
      r.distance = 0;
      return r;
    }
    // Cores apart but within the radii: exact depth along the cores' closest points.
    // A single-vertex simplex means the difference of two support points: its
    // direction is exact however small (e.g. two sphere centres).
    if (g.distance > kCoreNormalRel * simplex_scale(g.simplex) || g.simplex.count == 1) {
      r.distance = g.distance - radii;
      return r;
    }
  }
  r.intersecting = true;
  if (!signed_distance) {
    r.distance = 0;
    r.point_a = g.point_a;
    r.point_b = g.point_b;
    r.normal.setZero();
    return r;
  }
  const EpaResult e = epa_penetration(ca, cb, b_in_a, g, epa_settings);
  r.iterations = g.iterations + e.iterations;
  if (e.status != QueryStatus::kOk) r.status = e.status;
  r.normal = e.normal;
  r.distance = -(e.depth + radii);
  r.point_a = e.point_a + ra * e.normal;
  r.point_b = e.point_b - rb * e.normal;
  return r;
}

// Penetration of a sphere (A, centred at A's origin) whose centre lies inside cylinder
// B, in closed form. The generic route (EPA on the cylinder, since a sphere's core is a
// point) is slow to converge here: with the centre near the axis every radial direction
// is almost equally shallow, so EPA must tessellate the whole rim and hits its cap
// (observed: 2.5e-8 m too deep after 128 iterations, 1.7e-5 m before the cap answer was
// made an upper bound). The centre p (B's frame) leaves the cylinder fastest through
// the side (R - |p_xz|, radially) or through the nearer cap (hh - |p_y|); B moves the
// opposite way, so the normal from A to B is minus that exit direction. Returns false
// when the centre is outside (GJK on the cores then answers exactly).
bool sphere_in_cylinder(const Sphere& a, const Cylinder& b, const Pose& b_in_a, DistanceResult& r) {
  const Vec3 p = b_in_a.inverse_transform_point(Vec3::Zero());
  const Real R = b.cylinder_radius(), hh = b.half_height();
  const Real rho = std::hypot(p.x(), p.z());
  if (!(rho <= R && std::abs(p.y()) <= hh)) return false;
  const Real side = R - rho, cap = hh - std::abs(p.y());
  Vec3 exit_dir;  // unit, B's frame
  Real s;
  if (side <= cap) {
    // On the axis every radial direction is optimal; +X (B's frame) is a fixed choice.
    exit_dir = rho > 0 ? Vec3(p.x() / rho, 0, p.z() / rho) : Vec3(Vec3::UnitX());
    s = side;
  } else {
    exit_dir = Vec3(0, detail::sign_or_plus(p.y()), 0);
    s = cap;
  }
  const Vec3 n = -b_in_a.transform_vector(exit_dir);
  r = DistanceResult{};
  r.intersecting = true;
  r.normal = n;
  r.distance = -(s + a.radius());
  r.point_a = a.radius() * n;                        // deepest point of the sphere
  r.point_b = r.point_a + r.distance * n;            // centre's exit point on B
  return true;
}

// Ray / sphere of radius r at the origin, for a ray starting outside it (o.o > r^2).
// Stable form (Haines et al., "Precision Improvements for Ray/Sphere Intersection",
// Ray Tracing Gems 2019): the discriminant from the closest point of the line, the
// near root as c / q, so a small sphere seen from 10 km still resolves.
bool ray_sphere(const Vec3& o, const Vec3& d, Real r, Real& t) {
  const Real a = d.squaredNorm();
  const Real b = o.dot(d);
  if (b >= 0) return false;  // moving away
  const Vec3 l = o - (b / a) * d;
  const Real h = r * r - l.squaredNorm();
  if (h < 0) return false;
  const Real c = o.squaredNorm() - r * r;
  const Real q = -b + std::sqrt(a * h);
  t = c / q;
  return true;
}

RayHit make_hit(Real t, const Vec3& o, const Vec3& d, const Vec3& n) {
  RayHit h;
  h.hit = true;
  h.distance = t;
  h.point = o + t * d;
  h.normal = n;
  return h;
}

RayHit inside_hit(const Vec3& o) {
  RayHit h;
  h.hit = true;
  h.distance = 0;
  h.point = o;
  return h;
}

RayHit raycast_sphere(const Sphere& s, const Vec3& o, const Vec3& d, Real max_t) {
  const Real r = s.radius();
  if (o.squaredNorm() <= r * r) return inside_hit(o);
  Real t;
  if (!ray_sphere(o, d, r, t) || t > max_t) return RayHit{};
  const Vec3 p = o + t * d;
  return make_hit(t, o, d, p / p.norm());
}

// Slabs (Kay and Kajiya 1986; Ericson 5.3.3) against the box of half extents h.
RayHit raycast_slabs(const Vec3& h, const Vec3& o, const Vec3& d, Real max_t) {
  if ((o.cwiseAbs().array() <= h.array()).all()) return inside_hit(o);
  Real t_in = 0, t_out = max_t;
  int axis = -1;
  for (int i = 0; i < 3; ++i) {
    if (d[i] == 0) {
      if (std::abs(o[i]) > h[i]) return RayHit{};
      continue;
    }
    const Real inv = 1 / d[i];
    Real t1 = (-h[i] - o[i]) * inv, t2 = (h[i] - o[i]) * inv;
    if (t1 > t2) std::swap(t1, t2);
    if (t1 > t_in) {
      t_in = t1;
      axis = i;
    }
    t_out = std::min(t_out, t2);
    if (t_in > t_out) return RayHit{};
  }
  if (axis < 0) return inside_hit(o);  // on the surface: counts as inside
  Vec3 n = Vec3::Zero();
  n[axis] = d[axis] > 0 ? -1 : 1;
  return make_hit(t_in, o, d, n);
}

// Interval of t where the ray is inside the infinite cylinder x^2 + z^2 <= R^2 (axis
// Y). Returns false if it never is. The discriminant uses Lagrange's identity,
// a R^2 - (o x d)_y^2, which has no cancellation for distant rays.
bool ray_infinite_cylinder(const Vec3& o, const Vec3& d, Real R, Real& t1, Real& t2) {
  const Real a = d.x() * d.x() + d.z() * d.z();
  const Real c = o.x() * o.x() + o.z() * o.z() - R * R;
  if (!(a > 0)) {  // parallel to the axis
    if (c > 0) return false;
    t1 = -kInf;
    t2 = kInf;
    return true;
  }
  const Real b = o.x() * d.x() + o.z() * d.z();
  const Real cr = o.x() * d.z() - o.z() * d.x();
  const Real disc = a * R * R - cr * cr;
  if (disc < 0) return false;
  const Real sq = std::sqrt(disc);
  // Stable roots (Press et al., Numerical Recipes 5.6): q / a and c / q.
  const Real q = b >= 0 ? -(b + sq) : (-b + sq);
  if (q == 0) {
    t1 = t2 = 0;
    return true;
  }
  t1 = q / a;
  t2 = c / q;
  if (t1 > t2) std::swap(t1, t2);
  return true;
}

RayHit raycast_capsule(const Capsule& cap, const Vec3& o, const Vec3& d, Real max_t) {
  const Real r = cap.radius(), hh = cap.half_height();
  // Inside: distance from the segment <= r.
  const Vec3 nearest(0, std::clamp(o.y(), -hh, hh), 0);
  if ((o - nearest).squaredNorm() <= r * r) return inside_hit(o);
  // The capsule is the union of the finite cylinder and the two end spheres (the flat
  // caps lie inside the spheres), so its first hit is the first of their hits.
  Real best = kInf;
  Vec3 normal = Vec3::Zero();
  Real t1, t2;
  if (ray_infinite_cylinder(o, d, r, t1, t2) && t1 >= 0 && std::isfinite(t1)) {
    const Vec3 p = o + t1 * d;
    if (std::abs(p.y()) <= hh) {
      best = t1;
      normal = Vec3(p.x(), 0, p.z()) / r;
    }
  }
  for (const Real cy : {hh, -hh}) {
    const Vec3 oc = o - Vec3(0, cy, 0);
    Real t;
    if (oc.squaredNorm() > r * r && ray_sphere(oc, d, r, t) && t < best) {
      best = t;
      normal = (oc + t * d) / r;
    }
  }
  if (best == kInf || best > max_t) return RayHit{};  // no component hit, or too far
  return make_hit(best, o, d, normal.normalized());
}

RayHit raycast_cylinder(const Cylinder& cyl, const Vec3& o, const Vec3& d, Real max_t) {
  const Real R = cyl.cylinder_radius(), hh = cyl.half_height();
  if (o.x() * o.x() + o.z() * o.z() <= R * R && std::abs(o.y()) <= hh) return inside_hit(o);
  Real c1, c2;
  if (!ray_infinite_cylinder(o, d, R, c1, c2)) return RayHit{};
  Real s1 = -kInf, s2 = kInf;
  if (d.y() != 0) {
    s1 = (-hh - o.y()) / d.y();
    s2 = (hh - o.y()) / d.y();
    if (s1 > s2) std::swap(s1, s2);
  } else if (std::abs(o.y()) > hh) {
    return RayHit{};
  }
  const Real t_in = std::max(c1, s1), t_out = std::min(c2, s2);
  if (t_in > t_out || t_out < 0 || t_in < 0 || t_in > max_t) return RayHit{};
  const Vec3 p = o + t_in * d;
  Vec3 n;
  if (s1 >= c1) {
    n = Vec3(0, d.y() > 0 ? -1 : 1, 0);  // cap
  } else {
    n = Vec3(p.x(), 0, p.z()).normalized();  // side
  }
  return make_hit(t_in, o, d, n);
}

// Cyrus-Beck clipping against the hull's face planes (Ericson 5.3.8): exact for a
// polytope, one pass over the faces, no iteration.
RayHit raycast_hull(const ConvexHull& hull, const Vec3& o, const Vec3& d, Real max_t) {
  Real t_in = 0, t_out = max_t;
  int face = -1;
  const auto& faces = hull.faces();
  for (int f = 0; f < static_cast<int>(faces.size()); ++f) {
    const Real denom = faces[f].normal.dot(d);
    const Real num = faces[f].offset - faces[f].normal.dot(o);  // >= 0: inside this plane
    if (denom == 0) {
      if (num < 0) return RayHit{};
      continue;
    }
    const Real t = num / denom;
    if (denom < 0) {
      if (t > t_in) {
        t_in = t;
        face = f;
      }
    } else {
      t_out = std::min(t_out, t);
    }
    if (t_in > t_out) return RayHit{};
  }
  if (face < 0) return inside_hit(o);
  return make_hit(t_in, o, d, faces[face].normal);
}

}  // namespace

DistanceResult distance_convex_convex(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a,
                                      const GjkSettings& gjk) {
  return visit_convex(a, [&](const auto& ca) {
    return visit_convex(b, [&](const auto& cb) {
      using A = std::decay_t<decltype(ca)>;
      using B = std::decay_t<decltype(cb)>;
      return core_pair(CoreSupport<A>(ca), ca.radius(), CoreSupport<B>(cb), cb.radius(), b_in_a,
                       false, gjk, EpaSettings{});
    });
  });
}

DistanceResult penetration_convex_convex(const ConvexShape& a, const ConvexShape& b,
                                         const Pose& b_in_a, const GjkSettings& gjk,
                                         const EpaSettings& epa, Real cull_distance) {
  DistanceResult exact;
  if (a.type() == ShapeType::kSphere && b.type() == ShapeType::kCylinder &&
      sphere_in_cylinder(static_cast<const Sphere&>(a), static_cast<const Cylinder&>(b), b_in_a, exact))
    return exact;
  if (a.type() == ShapeType::kCylinder && b.type() == ShapeType::kSphere &&
      sphere_in_cylinder(static_cast<const Sphere&>(b), static_cast<const Cylinder&>(a), b_in_a.inverse(),
                         exact)) {
    // Computed in B's frame with the roles swapped: back to A's frame, A and B exchanged.
    DistanceResult r = exact;
    r.point_a = b_in_a.transform_point(exact.point_b);
    r.point_b = b_in_a.transform_point(exact.point_a);
    r.normal = -b_in_a.transform_vector(exact.normal);
    return r;
  }
  return visit_convex(a, [&](const auto& ca) {
    return visit_convex(b, [&](const auto& cb) {
      using A = std::decay_t<decltype(ca)>;
      using B = std::decay_t<decltype(cb)>;
      return core_pair(CoreSupport<A>(ca), ca.radius(), CoreSupport<B>(cb), cb.radius(), b_in_a,
                       true, gjk, epa, cull_distance);
    });
  });
}

bool intersect_convex_convex(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a,
                             const GjkSettings& gjk) {
  return visit_convex(a, [&](const auto& ca) {
    return visit_convex(b, [&](const auto& cb) {
      using A = std::decay_t<decltype(ca)>;
      using B = std::decay_t<decltype(cb)>;
      return gjk_intersect(CoreSupport<A>(ca), CoreSupport<B>(cb), b_in_a, gjk, b_in_a.position,
                           ca.radius() + cb.radius());
    });
  });
}

DistanceResult plane_convex(const Plane& a, const ConvexShape& b, const Pose& b_in_a,
                            bool signed_distance) {
  const Vec3& n = a.normal();
  // Deepest core point of B below the plane: its support along -n (in B's frame).
  const Vec3 core = b_in_a.transform_point(b.support_core(b_in_a.inverse_transform_vector(-n)));
  const Real s = n.dot(core) - a.offset() - b.radius();
  DistanceResult r;
  r.normal = n;
  r.point_b = core - b.radius() * n;
  r.point_a = r.point_b - s * n;  // projection onto the plane
  r.intersecting = s <= 0;
  r.distance = (s > 0 || signed_distance) ? s : Real(0);
  return r;
}

DistanceResult triangle_convex(const Vec3& v0, const Vec3& v1, const Vec3& v2, const ConvexShape& b,
                               const Pose& b_in_a, bool signed_distance, const GjkSettings& gjk,
                               const EpaSettings& epa, Real cull_distance) {
  const TriangleSupport tri(v0, v1, v2);
  return visit_convex(b, [&](const auto& cb) {
    using B = std::decay_t<decltype(cb)>;
    return core_pair(tri, Real(0), CoreSupport<B>(cb), cb.radius(), b_in_a, signed_distance, gjk,
                     epa, cull_distance);
  });
}

bool intersect_triangle_convex(const Vec3& v0, const Vec3& v1, const Vec3& v2, const ConvexShape& b,
                               const Pose& b_in_a, const GjkSettings& gjk) {
  const TriangleSupport tri(v0, v1, v2);
  return visit_convex(b, [&](const auto& cb) {
    using B = std::decay_t<decltype(cb)>;
    return gjk_intersect(tri, CoreSupport<B>(cb), b_in_a, gjk, b_in_a.position, cb.radius());
  });
}

RayHit raycast_convex(const ConvexShape& s, const Vec3& origin, const Vec3& dir, Real max_t) {
  switch (s.type()) {
    case ShapeType::kSphere:
      return raycast_sphere(static_cast<const Sphere&>(s), origin, dir, max_t);
    case ShapeType::kBox: {
      const Box& box = static_cast<const Box&>(s);
      if (box.radius() == 0) return raycast_slabs(box.half_extents(), origin, dir, max_t);
      // Rounded box: its surface mixes planes, cylinders and spheres; the GJK ray cast
      // handles it exactly through the full support map.
      RayHit h = gjk_raycast(FullSupport<Box>(box), origin, dir, max_t);
      if (h.hit && h.distance > 0) {
        // On a curved patch the ray cast's normal (its last separating direction) is
        // only as good as the square root of its position error; the exact normal of a
        // rounded shape points from the nearest core point to the hit point.
        const Vec3& core = box.core_half_extents();
        const Vec3 off = h.point - h.point.cwiseMax(-core).cwiseMin(core);
        const Real len = off.norm();
        if (len > 0.5 * box.radius()) h.normal = off / len;
      }
      return h;
    }
    case ShapeType::kCapsule:
      return raycast_capsule(static_cast<const Capsule&>(s), origin, dir, max_t);
    case ShapeType::kCylinder:
      return raycast_cylinder(static_cast<const Cylinder&>(s), origin, dir, max_t);
    case ShapeType::kConvexHull:
      return raycast_hull(static_cast<const ConvexHull&>(s), origin, dir, max_t);
    default:
      break;
  }
  throw InvalidArgument(std::string("not a convex shape type: ") + to_string(s.type()));
}

RayHit raycast_plane(const Plane& p, const Vec3& origin, const Vec3& dir, Real max_t) {
  const Real s0 = p.normal().dot(origin) - p.offset();
  if (s0 <= 0) return inside_hit(origin);
  const Real dn = p.normal().dot(dir);
  if (!(dn < 0)) return RayHit{};
  const Real t = -s0 / dn;
  if (t > max_t) return RayHit{};
  return make_hit(t, origin, dir, p.normal());
}

}  // namespace wmo
