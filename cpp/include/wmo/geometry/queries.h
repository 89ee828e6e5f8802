// WMO geometry layer: distance, closest points, penetration and ray casts on any
// pair of shapes, with world poses and world-space results (see types.h for the
// convention). Convex pairs go through GJK / EPA (gjk.h) on the shapes' cores
// plus radii; pairs involving a plane, triangle mesh or compound are reduced to convex
// pairs. A pair with no routine returns QueryStatus::kUnsupported.
#pragma once

#include "wmo/geometry/shapes.h"
#include "wmo/types.h"

namespace wmo {

/// Separation distance between A at `pose_a` and B at `pose_b` (world frame). When the
/// shapes overlap, `intersecting` is true and `distance` is 0; points are then
/// unspecified (use closest_points or penetration).
DistanceResult distance(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
                        const GjkSettings& gjk = {});

/// Closest points when apart (as distance), and when overlapping the deepest points
/// from EPA with distance = -depth: a signed distance with witness points.
DistanceResult closest_points(const Shape& a, const Pose& pose_a, const Shape& b,
                              const Pose& pose_b, const GjkSettings& gjk = {},
                              const EpaSettings& epa = {});

/// Penetration depth (as -distance), normal (A to B) and witness points of an
/// overlapping pair; for a separated pair `intersecting` is false and the result is
/// the plain distance.
DistanceResult penetration(const Shape& a, const Pose& pose_a, const Shape& b,
                           const Pose& pose_b, const GjkSettings& gjk = {},
                           const EpaSettings& epa = {});

/// True if the shapes overlap or touch (GJK boolean test, or a special routine).
bool intersect(const Shape& a, const Pose& pose_a, const Shape& b, const Pose& pose_b,
               const GjkSettings& gjk = {});

/// Ray from `origin` along `direction` (world frame, need not be unit; a zero direction
/// is invalid input) up to `max_distance` in units of |direction|. Rays starting inside
/// a solid shape hit at distance 0 with a zero normal.
RayHit raycast(const Shape& shape, const Pose& pose, const Vec3& origin, const Vec3& direction,
               Real max_distance = kInf);

}  // namespace wmo
