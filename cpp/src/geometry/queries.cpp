// Top-level geometry queries (queries.h): world poses in, world results out.
//
// Every pair is reduced to a routine in the frame of one of its shapes (types.h: small
// coordinates, so shapes 10 km from the origin keep their precision), whose result is
// then mapped to world space:
//   * convex-convex: convex_queries.h (GJK / EPA on cores plus radii);
//   * plane-convex: analytic, the support of the convex shape along -normal;
//   * compound-anything: the children, each as its own pair, keeping the smallest
//     (signed) distance; children whose bounding-box gap already exceeds the best
//     answer are skipped;
//   * triangle mesh-convex: the mesh's BVH gives the triangles near the convex shape,
//     each triangle is a 3-point convex support (two-sided);
//   * anything else (plane-plane, mesh-mesh, mesh-plane): QueryStatus::kUnsupported.
// A pair given in the other order is computed in the supported order and mirrored
// (points swapped, normal negated).
#include "wmo/geometry/queries.h"

#include <algorithm>
#include <cmath>
#include <string>

#include "wmo/geometry/convex_queries.h"
#include "wmo/geometry/gjk.h"
#include "wmo/geometry/mesh_bvh.h"


namespace wmo {

namespace {

enum class Mode { kDistance, kSigned };

void check_pose(const char* field, const Pose& p) {
  if (!p.position.allFinite() || !p.rotation.coeffs().allFinite())
    throw InvalidArgument(std::string(field) + " must be finite, got position " +
                          to_string(p.position));
}

DistanceResult to_world(DistanceResult r, const Pose& frame) {
  r.point_a = frame.transform_point(r.point_a);
  r.point_b = frame.transform_point(r.point_b);
  r.normal = frame.transform_vector(r.normal);
  return r;
}

// The same result with A and B exchanged.
DistanceResult mirrored(DistanceResult r) {
  std::swap(r.point_a, r.point_b);
  r.normal = -r.normal;
  return r;
}

DistanceResult unsupported() {
  DistanceResult r;
  r.status = QueryStatus::kUnsupported;
  // Nothing was computed: an infinite distance cannot be mistaken for a contact.
  r.distance = kInf;
  return r;
}

// Euclidean gap between two boxes: a lower bound on the distance of what they bound.
Real aabb_gap(const Aabb& a, const Aabb& b) {
  const Vec3 g = (b.min - a.max).cwiseMax(a.min - b.max).cwiseMax(Vec3::Zero());
  return g.norm();
}

DistanceResult pair_query(Mode mode, const Shape& a, const Pose& pa, const Shape& b, const Pose& pb,
                          const GjkSettings& gjk, const EpaSettings& epa);

// Compound C (as A) against any shape O (as B), world frame.
DistanceResult compound_query(Mode mode, const Compound& c, const Pose& pc, const Shape& o,
                              const Pose& po, const GjkSettings& gjk, const EpaSettings& epa) {
  DistanceResult best = unsupported();
  bool any = false;
  const Aabb o_box = o.world_aabb(po);
  for (const Compound::Child& child : c.children()) {
    const Pose child_pose = pc * child.pose;
    if (any && aabb_gap(child.shape->world_aabb(child_pose), o_box) >= best.distance) continue;
    const DistanceResult r = pair_query(mode, *child.shape, child_pose, o, po, gjk, epa);
    if (r.status == QueryStatus::kUnsupported) return r;  // same for every child type
    if (!any || r.distance < best.distance) best = r;
    any = true;
    if (mode == Mode::kDistance && best.intersecting) break;  // 0 cannot be beaten
  }
  return best;
}

// Triangle mesh M (as A) against convex B at b_in_m, in the mesh frame.
DistanceResult mesh_convex(Mode mode, const TriangleMesh& m, const ConvexShape& b, const Pose& b_in_m,
                           const GjkSettings& gjk, const EpaSettings& epa) {
  DistanceResult best;
  auto visit = [&](int t) {
    const auto& tri = m.triangles()[t];
    const auto& v = m.vertices();
    const DistanceResult r =
        triangle_convex(v[tri[0]], v[tri[1]], v[tri[2]], b, b_in_m, mode == Mode::kSigned, gjk, epa);
    if (r.distance < best.distance) best = r;
    return !(mode == Mode::kDistance && best.intersecting);  // 0 cannot be beaten: stop
  };
  // A triangle at distance s from B meets B's box grown by s. So once the best distance
  // found within a margin is <= the margin, no triangle outside the grown box can beat
  // it. Otherwise the margin doubles; it ends at the latest when the grown box holds
  // the whole mesh (every triangle visited). The pass cap only guards against a
  // non-finite box; 200 doublings exceed any finite extent.
  const Aabb b_box = b.world_aabb(b_in_m);
  const Aabb m_box = m.local_aabb();
  const Vec3 size = b_box.max - b_box.min;
  Real margin = aabb_gap(b_box, m_box) + std::max(Real(0.5) * size.maxCoeff(), Real(1e-9));
  for (int pass = 0; pass < 200; ++pass) {
    const Aabb query = b_box.fattened(margin);
    best = unsupported();
    best.status = QueryStatus::kOk;
    m.bvh().query_aabb(query, visit);
    if (best.distance <= margin || query.contains(m_box)) break;
    margin *= 2;
  }
  return best;
}

DistanceResult pair_query(Mode mode, const Shape& a, const Pose& pa, const Shape& b, const Pose& pb,
                          const GjkSettings& gjk, const EpaSettings& epa) {
  const ShapeType ta = a.type(), tb = b.type();
  if (ta == ShapeType::kCompound)
    return compound_query(mode, static_cast<const Compound&>(a), pa, b, pb, gjk, epa);
  if (tb == ShapeType::kCompound)
    return mirrored(compound_query(mode, static_cast<const Compound&>(b), pb, a, pa, gjk, epa));
  const bool ca = a.is_convex(), cb = b.is_convex();
  if (ca && cb) {
    const auto& sa = static_cast<const ConvexShape&>(a);
    const auto& sb = static_cast<const ConvexShape&>(b);
    const Pose b_in_a = pa.relative(pb);
    return to_world(mode == Mode::kDistance ? distance_convex_convex(sa, sb, b_in_a, gjk)
                                            : penetration_convex_convex(sa, sb, b_in_a, gjk, epa),
                    pa);
  }
  if (ta == ShapeType::kPlane && cb)
    return to_world(plane_convex(static_cast<const Plane&>(a), static_cast<const ConvexShape&>(b),
                                 pa.relative(pb), mode == Mode::kSigned),
                    pa);
  if (ca && tb == ShapeType::kPlane)
    return mirrored(to_world(plane_convex(static_cast<const Plane&>(b),
                                          static_cast<const ConvexShape&>(a), pb.relative(pa),
                                          mode == Mode::kSigned),
                             pb));
  if (ta == ShapeType::kTriangleMesh && cb)
    return to_world(mesh_convex(mode, static_cast<const TriangleMesh&>(a),
                                static_cast<const ConvexShape&>(b), pa.relative(pb), gjk, epa),
                    pa);
  if (ca && tb == ShapeType::kTriangleMesh)
    return mirrored(to_world(mesh_convex(mode, static_cast<const TriangleMesh&>(b),
                                         static_cast<const ConvexShape&>(a), pb.relative(pa), gjk,
                                         epa),
                             pb));
  return unsupported();
}

// Boolean version; returns false with *supported = false for unsupported pairs.
bool intersect_query(const Shape& a, const Pose& pa, const Shape& b, const Pose& pb,
                     const GjkSettings& gjk, bool* supported) {
  const ShapeType ta = a.type(), tb = b.type();
  if (ta == ShapeType::kCompound || tb == ShapeType::kCompound) {
    const bool a_is_c = ta == ShapeType::kCompound;
    const auto& c = static_cast<const Compound&>(a_is_c ? a : b);
    const Pose& pc = a_is_c ? pa : pb;
    const Shape& o = a_is_c ? b : a;
    const Pose& po = a_is_c ? pb : pa;
    const Aabb o_box = o.world_aabb(po);
    for (const Compound::Child& child : c.children()) {
      const Pose child_pose = pc * child.pose;
      if (!child.shape->world_aabb(child_pose).overlaps(o_box)) continue;
      if (intersect_query(*child.shape, child_pose, o, po, gjk, supported)) return true;
      if (!*supported) return false;
    }
    return false;
  }
  const bool ca = a.is_convex(), cb = b.is_convex();
  if (ca && cb)
    return intersect_convex_convex(static_cast<const ConvexShape&>(a),
                                   static_cast<const ConvexShape&>(b), pa.relative(pb), gjk);
  if ((ta == ShapeType::kPlane && cb) || (ca && tb == ShapeType::kPlane)) {
    const bool a_is_p = ta == ShapeType::kPlane;
    return plane_convex(static_cast<const Plane&>(a_is_p ? a : b),
                        static_cast<const ConvexShape&>(a_is_p ? b : a),
                        a_is_p ? pa.relative(pb) : pb.relative(pa), false)
        .intersecting;
  }
  if ((ta == ShapeType::kTriangleMesh && cb) || (ca && tb == ShapeType::kTriangleMesh)) {
    const bool a_is_m = ta == ShapeType::kTriangleMesh;
    const auto& m = static_cast<const TriangleMesh&>(a_is_m ? a : b);
    const auto& s = static_cast<const ConvexShape&>(a_is_m ? b : a);
    const Pose s_in_m = a_is_m ? pa.relative(pb) : pb.relative(pa);
    bool found = false;
    m.bvh().query_aabb(s.world_aabb(s_in_m), [&](int t) {
      const auto& tri = m.triangles()[t];
      const auto& v = m.vertices();
      found = intersect_triangle_convex(v[tri[0]], v[tri[1]], v[tri[2]], s, s_in_m, gjk);
      return !found;  // stop at the first touching triangle
    });
    return found;
  }
  *supported = false;
  return false;
}


// Ray in `shape`'s local frame.
RayHit raycast_local(const Shape& shape, const Vec3& o, const Vec3& d, Real max_t) {
  switch (shape.type()) {
    case ShapeType::kPlane:
      return raycast_plane(static_cast<const Plane&>(shape), o, d, max_t);
    case ShapeType::kTriangleMesh:
      return raycast_mesh(static_cast<const TriangleMesh&>(shape), o, d, max_t);
    case ShapeType::kCompound: {
      const auto& c = static_cast<const Compound&>(shape);
      RayHit best;
      for (int i = 0; i < static_cast<int>(c.children().size()); ++i) {
        const Compound::Child& child = c.children()[i];
        const Vec3 lo = child.pose.inverse_transform_point(o);
        const Vec3 ld = child.pose.inverse_transform_vector(d);
        RayHit h = raycast_convex(*child.shape, lo, ld, best.hit ? best.distance : max_t);
        if (!h.hit || (best.hit && h.distance >= best.distance)) continue;
        h.point = child.pose.transform_point(h.point);
        h.normal = child.pose.transform_vector(h.normal);
        h.child = i;
        best = h;
        if (best.distance == 0) break;
      }
      return best;
    }
    default:
      return raycast_convex(static_cast<const ConvexShape&>(shape), o, d, max_t);
  }
}

}  // namespace

DistanceResult distance(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                        const GjkSettings& gjk) {
  check_pose("pose_a", pose_a);
  check_pose("pose_b", pose_b);
  return pair_query(Mode::kDistance, a, pose_a, b, pose_b, gjk, EpaSettings{});
}

DistanceResult closest_points(const Shape& a, const Pose& pose_a, const Shape& b,
                              const Pose& pose_b, const GjkSettings& gjk, const EpaSettings& epa) {
  check_pose("pose_a", pose_a);
  check_pose("pose_b", pose_b);
  return pair_query(Mode::kSigned, a, pose_a, b, pose_b, gjk, epa);
}

DistanceResult penetration(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                           const GjkSettings& gjk, const EpaSettings& epa) {
  return closest_points(a, pose_a, b, pose_b, gjk, epa);
}

bool intersect(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
               const GjkSettings& gjk) {
  check_pose("pose_a", pose_a);
  check_pose("pose_b", pose_b);
  bool supported = true;
  return intersect_query(a, pose_a, b, pose_b, gjk, &supported);
}

RayHit raycast(const Shape& shape, const Pose& pose, const Vec3& origin, const Vec3& direction,
               Real max_distance) {
  require_finite("origin", origin);
  if (!direction.allFinite() || direction.squaredNorm() == 0)
    throw InvalidArgument("direction must be finite and non-zero, got " + to_string(direction));
  if (std::isnan(max_distance) || max_distance < 0)
    throw InvalidArgument("max_distance must be >= 0, got " + std::to_string(max_distance));
  check_pose("pose", pose);
  const Vec3 lo = pose.inverse_transform_point(origin);
  const Vec3 ld = pose.inverse_transform_vector(direction);
  RayHit h = raycast_local(shape, lo, ld, max_distance);
  if (h.hit) {
    // From the world ray itself: no round trip through the local frame.
    h.point = origin + h.distance * direction;
    h.normal = pose.transform_vector(h.normal);
  }
  return h;
}

Pose Motion::at(Real t) const {
  const Real w = angular_velocity.norm();
  Pose p;
  p.rotation = w > 0 ? Quat(Eigen::AngleAxis<Real>(w * t, angular_velocity / w)) * start.rotation
                     : start.rotation;
  p.rotation.normalize();
  p.position = start.transform_point(center) + t * linear_velocity - p.rotation * center;
  return p;
}

namespace {

// Largest distance of `shape`'s core from its local point c: from the corners of the
// core's bounding box (the shape's box shrunk by its convex radius, which is exact for
// core plus radius shapes: a sphere's core is its centre). An upper bound, which is
// what conservative advancement needs. Infinite for a plane.
Real rotation_bound(const Shape& shape, const Vec3& c) {
  if (shape.type() == ShapeType::kPlane) return kInf;
  Aabb box = shape.local_aabb();
  if (shape.is_convex()) {
    const Real r = static_cast<const ConvexShape&>(shape).radius();
    box.min.array() += r;
    box.max.array() -= r;
  }
  const Vec3 far = (box.min - c).cwiseAbs().cwiseMax((box.max - c).cwiseAbs());
  return far.norm();
}

void check_motion(const char* field, const Motion& m) {
  check_pose(field, m.start);
  if (!m.linear_velocity.allFinite() || !m.angular_velocity.allFinite() || !m.center.allFinite())
    throw InvalidArgument(std::string(field) + " velocities and centre must be finite, got linear " +
                          to_string(m.linear_velocity) + ", angular " + to_string(m.angular_velocity));
}

// Conservative advancement on one convex pair (or convex against plane). `dist(t)`
// gives the pair's signed distance at time t (normal from A to B); `dv` is v_a - v_b
// and `spin` |w_a| r_a + |w_b| r_b.
template <class DistFn>
ToiResult advance(DistFn&& dist, const Vec3& dv, Real spin, Real duration, const ToiSettings& settings) {
  ToiResult res;
  const Real tol = settings.tolerance;
  Real target = settings.target_distance;
  Real t = 0;
  for (int it = 0;; ++it) {
    const DistanceResult d = dist(t);
    res.iterations = it + 1;
    if (d.status == QueryStatus::kUnsupported) {
      res.status = d.status;
      return res;
    }
    res.time = t;
    res.initially_overlapping = it == 0 && d.distance < 0;
    res.distance = d.distance;
    res.point_a = d.point_a;
    res.point_b = d.point_b;
    res.normal = d.normal;
    // Started at or past the target: with deepen_allowance, the target moves below this
    // pair's own start (ToiSettings::deepen_allowance).
    if (it == 0 && settings.deepen_allowance >= 0 && d.distance <= target + tol)
      target = d.distance - settings.deepen_allowance;
    if (d.distance <= target + tol) {
      res.hit = true;
      return res;
    }
    // Largest rate at which the slab between the shapes can close.
    const Real closing = dv.dot(d.normal) + spin;
    if (!(closing > 0)) break;  // the slab never closes: no contact in the interval
    const Real next = t + (d.distance - target - 0.5 * tol) / closing;
    if (!(next <= duration)) break;
    if (it + 1 >= settings.max_iterations) {
      // Stopped short of the end: `t` is still a time before any contact.
      res.hit = true;
      res.status = QueryStatus::kMaxIterations;
      return res;
    }
    t = next;
  }
  res.hit = false;
  res.time = duration;
  return res;
}

// The earlier of two answers (a hit beats a miss; between hits at the same time, and
// between misses, the closer one is kept: at time 0 the deepest overlap, on a miss how
// near the shapes came). Evaluations add up.
void keep_earliest(ToiResult& best, bool& any, const ToiResult& r) {
  const int iterations = best.iterations + r.iterations;
  const bool closer = r.distance < best.distance;
  if (!any || (r.hit && (!best.hit || r.time < best.time || (r.time == best.time && closer))) ||
      (!r.hit && !best.hit && closer))
    best = r;
  best.iterations = iterations;
  any = true;
}

ToiResult toi_pair(const Shape& a, const Motion& ma, const Shape& b, const Motion& mb, Real duration,
                   const ToiSettings& st);

// A result with A and B exchanged.
ToiResult mirrored(ToiResult r) {
  std::swap(r.point_a, r.point_b);
  r.normal = -r.normal;
  return r;
}

// Compound C (as A) against any shape O: child by child, each child moving with the
// compound (same velocities, the rotation centre expressed in the child's frame).
ToiResult toi_compound(const Compound& c, const Motion& mc, const Shape& o, const Motion& mo, Real duration,
                       const ToiSettings& st) {
  ToiResult best;
  bool any = false;
  const Aabb o_box = swept_aabb(o, mo, duration);
  for (const Compound::Child& child : c.children()) {
    Motion m = mc;
    m.start = mc.start * child.pose;
    m.center = child.pose.inverse_transform_point(mc.center);
    if (!swept_aabb(*child.shape, m, duration).overlaps(o_box)) continue;
    const ToiResult r = toi_pair(*child.shape, m, o, mo, duration, st);
    if (r.status == QueryStatus::kUnsupported) return r;
    keep_earliest(best, any, r);
  }
  if (!any) {  // no child's swept box meets the other's: no contact
    best.time = duration;
    best.iterations = 0;
  }
  return best;
}

// Triangle mesh M (as A) against convex B: triangle by triangle, for the triangles the
// BVH finds in B's swept box (in the mesh frame).
ToiResult toi_mesh(const TriangleMesh& mesh, const Motion& mm, const ConvexShape& b, const Motion& mb,
                   Real duration, const ToiSettings& st) {
  Aabb query;
  if (mm.angular_velocity.isZero(0)) {
    // B's swept box relative to the translating mesh, then in the mesh's frame.
    Aabb box = swept_aabb(b, mb, duration);
    const Vec3 back = -duration * mm.linear_velocity;
    box.min += back.cwiseMin(Vec3::Zero());
    box.max += back.cwiseMax(Vec3::Zero());
    query = box.transformed(mm.start.inverse());
  } else {
    // A turning mesh: every point of B stays within this distance of the mesh's
    // rotation centre.
    const Vec3 cm = mm.start.transform_point(mm.center);
    const Vec3 cb = mb.start.transform_point(mb.center);
    const Real r = (cb - cm).norm() + duration * (mb.linear_velocity - mm.linear_velocity).norm() +
                   bounding_radius(b, mb.center);
    query = Aabb(mm.center.array() - r, mm.center.array() + r);
  }
  const Real wm = mm.angular_velocity.norm(), wb = mb.angular_velocity.norm();
  const Real spin_b = wb > 0 ? wb * rotation_bound(b, mb.center) : 0;
  const Vec3 dv = mm.linear_velocity - mb.linear_velocity;
  const auto& v = mesh.vertices();
  // ToiSettings::parallel_skip: B's rotation centre at the start and at the end, and how
  // far its points can move by turning, in the frame of the mesh (which does not move).
  const bool skip_parallel = st.parallel_skip > 0 && mm.linear_velocity.isZero(0) && wm == 0;
  Vec3 c0 = Vec3::Zero(), c1 = Vec3::Zero();
  if (skip_parallel) {
    c0 = mm.start.inverse_transform_point(mb.start.transform_point(mb.center));
    c1 = c0 + mm.start.inverse_transform_vector(duration * mb.linear_velocity);
  }
  const Real turn = duration * spin_b;
  ToiResult best;
  bool any = false;
  bool unsupported_pair = false;
  mesh.bvh().query_aabb(query, [&](int t) {
    const auto& tri = mesh.triangles()[t];
    if (skip_parallel) {
      const Vec3& n = mesh.triangle_normal(t);
      const Real s0 = n.dot(c0 - v[tri[0]]), s1 = n.dot(c1 - v[tri[0]]);
      const Real side = s0 > 0 ? 1 : -1;
      if (s0 != 0 && side * s1 >= st.parallel_skip && side * (s0 - s1) + turn <= st.parallel_skip) return true;
    }
    Real spin = spin_b;
    if (wm > 0)
      spin += wm * std::max({(v[tri[0]] - mm.center).norm(), (v[tri[1]] - mm.center).norm(),
                             (v[tri[2]] - mm.center).norm()});
    auto dist = [&](Real time) {
      const Pose pm = mm.at(time), pb = mb.at(time);
      return to_world(triangle_convex(v[tri[0]], v[tri[1]], v[tri[2]], b, pm.relative(pb), true, st.gjk,
                                      EpaSettings{}),
                      pm);
    };
    const ToiResult r = advance(dist, dv, spin, duration, st);
    if (r.status == QueryStatus::kUnsupported) {
      unsupported_pair = true;
      return false;
    }
    keep_earliest(best, any, r);
    return true;
  });
  if (unsupported_pair) {
    best.status = QueryStatus::kUnsupported;
    return best;
  }
  if (!any) {
    best.time = duration;
    best.iterations = 0;
  }
  return best;
}

ToiResult toi_pair(const Shape& a, const Motion& ma, const Shape& b, const Motion& mb, Real duration,
                   const ToiSettings& st) {
  const ShapeType ta = a.type(), tb = b.type();
  if (ta == ShapeType::kCompound) return toi_compound(static_cast<const Compound&>(a), ma, b, mb, duration, st);
  if (tb == ShapeType::kCompound)
    return mirrored(toi_compound(static_cast<const Compound&>(b), mb, a, ma, duration, st));
  if (ta == ShapeType::kTriangleMesh && b.is_convex())
    return toi_mesh(static_cast<const TriangleMesh&>(a), ma, static_cast<const ConvexShape&>(b), mb, duration,
                    st);
  if (a.is_convex() && tb == ShapeType::kTriangleMesh)
    return mirrored(toi_mesh(static_cast<const TriangleMesh&>(b), mb, static_cast<const ConvexShape&>(a), ma,
                             duration, st));
  // Convex pairs and convex against a plane (one slab), or unsupported pairs (the first
  // distance query says so).
  ToiResult res;
  const Real wa = ma.angular_velocity.norm(), wb = mb.angular_velocity.norm();
  // A shape that does not turn needs no rotation bound (a plane may translate).
  const Real spin = (wa > 0 ? wa * rotation_bound(a, ma.center) : 0) + (wb > 0 ? wb * rotation_bound(b, mb.center) : 0);
  if (!std::isfinite(spin)) {
    res.status = QueryStatus::kUnsupported;
    return res;
  }
  auto dist = [&](Real t) {
    const Pose pa = ma.at(t), pb = mb.at(t);
    DistanceResult d = pair_query(Mode::kDistance, a, pa, b, pb, st.gjk, EpaSettings{});
    // Overlapping (at the start, within GJK's round-off of touching, or allowed by a
    // negative target): the signed distance and the penetration normal.
    if (d.status != QueryStatus::kUnsupported && d.intersecting)
      d = pair_query(Mode::kSigned, a, pa, b, pb, st.gjk, EpaSettings{});
    return d;
  };
  return advance(dist, ma.linear_velocity - mb.linear_velocity, spin, duration, st);
}

}  // namespace

ToiResult time_of_impact(const Shape& a, const Motion& motion_a, const Shape& b, const Motion& motion_b,
                         Real duration, const ToiSettings& settings) {
  check_motion("motion_a", motion_a);
  check_motion("motion_b", motion_b);
  if (!(duration >= 0) || !std::isfinite(duration))
    throw InvalidArgument("duration must be finite and >= 0, got " + std::to_string(duration));
  if (!(settings.tolerance > 0) || !std::isfinite(settings.tolerance))
    throw InvalidArgument("tolerance must be finite and > 0, got " + std::to_string(settings.tolerance));
  if (!std::isfinite(settings.target_distance))
    throw InvalidArgument("target_distance must be finite, got " + std::to_string(settings.target_distance));
  if (settings.max_iterations < 1)
    throw InvalidArgument("max_iterations must be >= 1, got " + std::to_string(settings.max_iterations));
  return toi_pair(a, motion_a, b, motion_b, duration, settings);
}

Real inner_radius(const Shape& shape) {
  switch (shape.type()) {
    case ShapeType::kSphere:
      return static_cast<const Sphere&>(shape).radius();
    case ShapeType::kBox:
      return static_cast<const Box&>(shape).half_extents().minCoeff();
    case ShapeType::kCapsule:
      return static_cast<const Capsule&>(shape).radius();
    case ShapeType::kCylinder: {
      const auto& c = static_cast<const Cylinder&>(shape);
      return std::min(c.cylinder_radius(), c.half_height());
    }
    case ShapeType::kConvexHull: {
      const auto& h = static_cast<const ConvexHull&>(shape);
      Vec3 mean = Vec3::Zero();
      for (const Vec3& p : h.vertices()) mean += p;
      mean /= static_cast<Real>(h.vertices().size());
      Real r = kInf;
      for (const ConvexHull::Face& f : h.faces()) r = std::min(r, f.offset - f.normal.dot(mean));
      return std::max(r, Real(0)) + h.radius();
    }
    case ShapeType::kCompound: {
      Real r = kInf;
      for (const Compound::Child& c : static_cast<const Compound&>(shape).children())
        r = std::min(r, inner_radius(*c.shape));
      return r;
    }
    default:
      return 0;
  }
}

Aabb swept_aabb(const Shape& shape, const Motion& motion, Real duration) {
  if (motion.angular_velocity.isZero(0))
    return Aabb::merge(shape.world_aabb(motion.start), shape.world_aabb(motion.at(duration)));
  const Real r = bounding_radius(shape, motion.center);
  const Vec3 c0 = motion.start.transform_point(motion.center);
  const Vec3 c1 = c0 + duration * motion.linear_velocity;
  return Aabb(c0.cwiseMin(c1).array() - r, c0.cwiseMax(c1).array() + r);
}

Real bounding_radius(const Shape& shape, const Vec3& center) {
  if (shape.type() == ShapeType::kPlane) return kInf;
  const Aabb box = shape.local_aabb();
  return (box.min - center).cwiseAbs().cwiseMax((box.max - center).cwiseAbs()).norm();
}

}  // namespace wmo
