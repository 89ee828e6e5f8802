// Generic contact manifold for any pair of convex shapes: GJK / EPA for the normal and
// depth, then face clipping for the points (the approach of Jolt's
// ManifoldBetweenTwoFaces; Gregorius, "Robust Contact Creation for Physics
// Simulations", GDC 2015).
//
//   1. penetration_convex_convex (convex_queries.h) gives the signed distance and the
//      unit normal N from A to B (exact for spheres, capsules and rounded boxes, whose
//      radii are added analytically). Further apart than the margin: no contact.
//   2. The supporting features of A along +N and of B along -N
//      (ConvexShape::supporting_face: a polygon, a segment or a point on the outer
//      surface), B's moved into A's frame.
//   3. The feature whose plane is better aligned with N is the reference (A on a tie);
//      the other is clipped against its side planes swept along N, i.e. both are
//      compared in projection onto the plane perpendicular to N, and each clipped
//      point's depth is measured along N to the reference plane (clip.h). A segment
//      reference (capsule side) clips by its two end planes.
//   4. Clipped points deeper than the EPA depth are raised to it (see the code).
//   5. If clipping leaves nothing (a vertex or a curved contact), or its deepest point
//      is shallower than the EPA depth (an edge-edge contact, where the deepest point
//      is on the edges, not over a face), the single GJK / EPA point is added, so the
//      manifold's maximum depth is the EPA depth. Points with depth >= -margin are
//      reduced to at most 4 (reduce_to_4).
//
// A sphere on either side skips steps 2-4: the manifold is the one GJK / EPA point.
//
// Feature ids: (feature of A's supporting face & 255) << 24 | (feature of B's & 255)
// << 16 | (1 << 12 if the reference is B's) | clip vertex label (clip.h); the GJK / EPA
// point has label clip::kFallbackLabel (alone, for a sphere's one point).

#include <algorithm>
#include <cmath>

#include "clip.h"
#include "manifold_reduce.h"
#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/convex_queries.h"

namespace wmo {

bool collide_convex_convex(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a,
                           const CollideSettings& settings, Manifold& m, QueryStatus* status) {
  const Real margin = settings.margin;
  const DistanceResult r = penetration_convex_convex(a, b, b_in_a, settings.gjk, settings.epa, margin);
  if (status) *status = r.status;
  if (!(r.distance <= margin)) return false;  // also rejects NaN
  Vec3 N = r.normal;
  // Normal undefined (exactly touching at one point with no overlap information): the
  // direction between the centres, else +X, so no NaN escapes.
  if (!(std::abs(N.squaredNorm() - 1) < 1e-6)) {
    const Real len = b_in_a.position.norm();
    N = len > 0 ? Vec3(b_in_a.position / len) : Vec3::UnitX();
  }
  const Real depth0 = -r.distance;
  // The GJK / EPA point (on A, at the EPA depth) with feature id `id`.
  auto epa_point = [&](std::uint32_t id) {
    Vec3 pa = r.point_a;
    if (!pa.allFinite()) pa = Vec3::Zero();
    return ContactPoint{pa, pa - depth0 * N, depth0, id};
  };
  // A sphere meets anything at one point: its supporting feature along any direction is
  // that point, so there is nothing to clip, and the GJK / EPA point is the manifold
  // (step 5 below would add the same point after two supporting features, two
  // bounding boxes and reduce_to_4: 60-95 ns of a 90-400 ns query, measured on the
  // narrowphase benchmark's sphere pairs). Its feature id is the fallback label
  // alone, constant, as Box2D's and Jolt's one-point sphere contacts keep theirs, so a
  // sphere rolling from one face of a hull onto the next keeps its warm start.
  if (a.type() == ShapeType::kSphere || b.type() == ShapeType::kSphere) {
    m.normal = N;
    m.count = 1;
    m.points[0] = epa_point(clip::kFallbackLabel);
    return true;
  }

  SupportingFace fa, fb;
  a.supporting_face(N, fa);
  b.supporting_face(b_in_a.inverse_transform_vector(-N), fb);
  for (int k = 0; k < fb.count; ++k) fb.vertices[k] = b_in_a.transform_point(fb.vertices[k]);

  ContactScratch<clip::kMaxClipVertices + 1> pts;
  int n = 0;
  const std::uint32_t feat = ((fa.feature & 255u) << 24) | ((fb.feature & 255u) << 16);
  if (fa.count >= 2 && fb.count >= 2) {
    // The feature whose plane is better aligned with N is the reference: |cos| of its
    // plane normal (the shape's own, SupportingFace::normal) with N, 0 for a segment (a
    // segment is only a reference when both features are segments).
    if (fb.count >= 3) fb.normal = b_in_a.transform_vector(fb.normal);
    const Real ca = fa.count >= 3 ? std::abs(fa.normal.dot(N)) : Real(0);
    const Real cb = fb.count >= 3 ? std::abs(fb.normal.dot(N)) : Real(0);
    const bool ref_on_a = ca >= cb;
    if (ref_on_a)
      n = clip::clip_features(fa.vertices.data(), fa.count, true, fb.vertices.data(), fb.count, N,
                              0, 0, margin, feat, pts.data(), &fa.normal);
    else
      n = clip::clip_features(fb.vertices.data(), fb.count, false, fa.vertices.data(), fa.count, N,
                              0, 0, margin, feat | (1u << 12), pts.data(), &fb.normal);
  }
  // No point can be deeper than the EPA depth: translating B by depth0 along N makes
  // the shapes touch, so every point of B is then out of A. A clipped point measured
  // deeper (to the reference plane, along N) is an artefact of replacing A's surface
  // by that one plane, which happens for deep overlaps (a capsule through a cylinder:
  // 8e-5 m too deep at 2 m) and when N is tilted from the reference normal; it is
  // moved up to depth0, its point on A kept.
  for (int i = 0; i < n; ++i) {
    if (pts[i].depth > depth0) {
      pts[i].depth = depth0;
      pts[i].point_b = pts[i].point_a - depth0 * N;
    }
  }
  // Size scale for the tolerance below: the larger bounding half extent.
  const Real size = std::max(a.local_aabb().half_extents().maxCoeff(),
                             b.local_aabb().half_extents().maxCoeff());
  Real max_clip = -kInf;
  for (int i = 0; i < n; ++i) max_clip = std::max(max_clip, pts[i].depth);
  // 1e-6 of the size: far above EPA's convergence (1e-10 relative) so a face contact
  // whose clipped depth equals the EPA depth up to EPA's error gets no extra point,
  // far below a depth difference that matters (an edge-edge contact's clipped points
  // are shallower than the crossing point by a fraction of the shapes' size).
  if (n == 0 || max_clip < depth0 - 1e-6 * size) pts[n++] = epa_point(feat | clip::kFallbackLabel);
  m.normal = N;
  reduce_to_4(pts.data(), n, N, m);
  return m.count > 0;
}

}  // namespace wmo
