// WMO geometry layer: pair routines on convex shapes, in A's frame (types.h).
//
// These are the non-template entry points to the GJK / EPA templates of gjk.h: they
// switch on the concrete shape types once, so each pair of types gets its own
// instantiation and the iterative inner loops make no virtual calls.
//
// Core + radius (shapes.h): GJK and EPA run on the shapes' cores (a sphere's centre, a
// capsule's segment, a rounded box's inner box) and the convex radii are added
// analytically afterwards, so spheres, capsules and rounded boxes are exact rather
// than approximated by polytopes, and EPA works on polytopes (finite convergence).
#pragma once

#include "wmo/geometry/shapes.h"
#include "wmo/types.h"

namespace wmo {

/// Distance between convex A and convex B (B at `b_in_a`, A's frame). Apart: distance
/// > 0, closest points on the surfaces, unit normal from A to B. Overlapping or
/// touching: intersecting = true and distance = 0; the points are then the cores'
/// closest points pushed out by the radii (when the cores are apart) or unspecified.
DistanceResult distance_convex_convex(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a,
                                      const GjkSettings& gjk = {});

/// Signed distance with witness points (A's frame):
///   * apart: as distance_convex_convex;
///   * cores apart but closer than ra + rb: depth = ra + rb - core distance exactly,
///     normal along the cores' closest points;
///   * cores overlapping: EPA on the cores, then depth = core depth + ra + rb along the
///     EPA normal. Adding the radii after EPA is exact (the Minkowski difference of
///     the full shapes is that of the cores inflated by a ball of radius ra + rb), and
///     EPA on polytope cores converges in finitely many steps, where EPA on the full
///     rounded shapes would have to tessellate their curved surfaces.
/// distance = -depth when overlapping; point_b = point_a - depth * normal.
/// status: kOk, kMaxIterations (best answer so far) or kDegenerate (see
/// epa_penetration in gjk.h: e.g. concentric spheres get depth ra + rb along B's offset
/// or +X).
/// `cull_distance` (m, default kInf): a caller that only wants pairs closer than this
/// (contact generation within a margin) lets GJK stop at the first separating plane
/// that proves the distance larger; `distance` is then only some value > cull_distance.
DistanceResult penetration_convex_convex(const ConvexShape& a, const ConvexShape& b,
                                         const Pose& b_in_a, const GjkSettings& gjk = {},
                                         const EpaSettings& epa = {}, Real cull_distance = kInf);

/// True if convex A and B touch or overlap (GJK on the cores with margin ra + rb,
/// exiting early on a separating plane).
bool intersect_convex_convex(const ConvexShape& a, const ConvexShape& b, const Pose& b_in_a,
                             const GjkSettings& gjk = {});

/// Plane A (half-space) against convex B, analytic: the deepest point of B is its
/// support along -normal. Signed result in A's frame, normal = the plane's normal
/// (from the plane into B's side). `signed_distance` false gives distance semantics
/// (0 when overlapping), true penetration semantics (-depth).
DistanceResult plane_convex(const Plane& a, const ConvexShape& b, const Pose& b_in_a,
                            bool signed_distance);

/// Triangle (v0, v1, v2 in A's frame, a zero-thickness convex set) against convex B at
/// `b_in_a`: the per-triangle routine of the triangle-mesh queries. Same semantics as
/// distance_convex_convex (signed_distance false) or penetration_convex_convex (true).
/// The triangle is two-sided here. `cull_distance` as for penetration_convex_convex.
DistanceResult triangle_convex(const Vec3& v0, const Vec3& v1, const Vec3& v2, const ConvexShape& b,
                               const Pose& b_in_a, bool signed_distance, const GjkSettings& gjk = {},
                               const EpaSettings& epa = {}, Real cull_distance = kInf);

/// True if the triangle (A's frame) and convex B touch or overlap.
bool intersect_triangle_convex(const Vec3& v0, const Vec3& v1, const Vec3& v2, const ConvexShape& b,
                               const Pose& b_in_a, const GjkSettings& gjk = {});

/// Ray origin + t * dir (shape's local frame, dir non-zero, t in units of |dir|,
/// 0 <= t <= max_t) against a convex shape. Analytic for sphere, sharp box (slabs),
/// capsule and cylinder; exact face-plane clipping (Cyrus-Beck) for hulls, since a
/// hull stores its face planes and this is exact in one pass; GJK ray cast (van den
/// Bergen 2004) for rounded boxes. A ray starting inside or on the surface hits at
/// t = 0 with a zero normal. Results in the local frame.
RayHit raycast_convex(const ConvexShape& s, const Vec3& origin, const Vec3& dir, Real max_t);

/// Ray against the half-space of a plane (local frame); a ray starting in the
/// half-space (on or below the plane) hits at t = 0 with a zero normal.
RayHit raycast_plane(const Plane& p, const Vec3& origin, const Vec3& dir, Real max_t);

}  // namespace wmo
