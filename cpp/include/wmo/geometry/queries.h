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

/// Rigid motion of a shape over a time interval: constant linear and angular velocity.
/// The shape's local point `center` (its rotation centre, e.g. the body's centre of mass
/// in the shape's frame; metres) moves from where `start` puts it at `linear_velocity`
/// (m/s, world frame), and the shape turns about it at `angular_velocity` (rad/s, world
/// frame): rotation(t) = exp(angular_velocity t) * start.rotation. This is the motion a
/// semi-implicit Euler step gives a body over one (sub)step.
struct Motion {
  Pose start;
  Vec3 linear_velocity = Vec3::Zero();
  Vec3 angular_velocity = Vec3::Zero();
  Vec3 center = Vec3::Zero();
  /// The pose at time t (s) after the start.
  Pose at(Real t) const;
};

/// Settings of time_of_impact.
struct ToiSettings {
  /// Distance (m) at which the shapes count as touching: the search stops at the first
  /// time it finds them at most this far apart. The reported time is never later than
  /// the true time of first contact (conservative advancement never steps past it), and
  /// for a pair closing at speed v it is earlier by at most tolerance / v. 1e-4 m is a
  /// tenth of a millimetre: far below a contact margin, far above GJK's error.
  Real tolerance = 1e-4;
  /// Signed distance (m) that counts as contact: the search finds the first time the
  /// shapes come within `tolerance` above it. 0 (the default) is touching; a negative
  /// value is a penetration depth the caller allows (the world's CCD stops a body at a
  /// small overlap, so that its next step makes a contact there); a positive value
  /// stops at a gap. Below zero the distance is measured by EPA (penetration depth).
  Real target_distance = 0;
  /// Negative (the default): off. Otherwise (m, >= 0): a pair that starts within
  /// `tolerance` of target_distance or deeper is not a hit at time 0; its target becomes
  /// its own start distance less this much, so the search finds the first time it has
  /// deepened by it (the world's CCD lets a body that starts overlapping deepen that
  /// overlap a little). A compound or a triangle mesh is searched child by child and
  /// triangle by triangle, each with its own start: an overlap one triangle starts with
  /// does not excuse another triangle that starts apart (a 3 mm disc resting 9 mm into
  /// the crease of a two-sided mesh ground was let 9 mm into the next triangle, which
  /// put it wholly behind that triangle: scripts/fuzz_worlds.py seed 1089).
  Real deepen_allowance = -1;
  /// Zero (the default): off. Otherwise (m, > 0), for a triangle mesh that does not move
  /// against a convex shape B: a triangle B moves nearly parallel to is not searched.
  /// That is, B's rotation centre starts and ends on the same side of the triangle's
  /// plane, at least this far from it at the end, and no point of B comes closer to the
  /// plane by more than this (the centre's approach plus the turn times B's rotation
  /// bound). Such a triangle cannot be passed through within the interval, and a body
  /// sliding over a mesh is left to the contact solver (Box2D v3's continuous step
  /// skips chain segments so); searched, the slight rocking of a 1 cm plate sliding on a
  /// mesh at 5 m/s (30 um deeper over a step) reached its CCD allowance and stopped it
  /// part of the way in some steps: 4.81 m in a second instead of 5 (test_ccd.py). The
  /// world's CCD uses a quarter of the body's inner radius.
  Real parallel_skip = 0;
  /// Cap on distance evaluations. Pure translation converges in two or three; rotation
  /// converges linearly (each step closes a fraction of the gap set by how much of the
  /// rotation bound is real), so a fast-spinning slender body may use tens.
  int max_iterations = 64;
  GjkSettings gjk;
};

/// Result of time_of_impact (world frame).
struct ToiResult {
  /// kOk; kUnsupported when no distance routine exists for the pair, or a plane (which
  /// has no finite extent) is given an angular velocity; kMaxIterations when the cap
  /// stopped the search (then `hit` is true at the last safe time, so a caller that
  /// stops the bodies there never lets them pass through each other).
  QueryStatus status = QueryStatus::kOk;
  /// True if the shapes come within `tolerance` of `target_distance` (by default: of
  /// touching) during the interval.
  bool hit = false;
  /// Time of impact (s) from the start: the first time found with signed distance <=
  /// target_distance + tolerance; `duration` on a miss; 0 if they start that close.
  Real time = 0;
  bool initially_overlapping = false;
  /// At `time` (on a miss: at the last time evaluated): separation distance (m; minus
  /// the penetration depth when overlapping), closest points on A and B, unit normal
  /// from A to B.
  Real distance = kInf;
  Vec3 point_a = Vec3::Zero();
  Vec3 point_b = Vec3::Zero();
  Vec3 normal = Vec3::Zero();
  /// Distance evaluations made (over every child or triangle of a compound or mesh).
  int iterations = 0;
};

/// Time of first contact of A and B moving by `motion_a` and `motion_b` during
/// [0, duration] (s), by conservative advancement (Mirtich 1996; van den Bergen 2004,
/// ch. 5.4): at the current time the distance d and normal n come from `distance`
/// (GJK on cores plus radii, mesh BVH, plane, compound children), which leaves the
/// shapes on either side of a slab of width d across n. Along n, A's support moves by at
/// most (v_a . n + |w_a| r_a) per second and B's by (-v_b . n + |w_b| r_b), where r is
/// the largest distance of the shape's core from its rotation centre (the rounding
/// radius of a sphere, capsule or rounded box does not change under rotation, so it is
/// left out). The signed distance is the largest gap over all directions, so it can
/// fall no faster than that sum, overlapping or not: time advances by (d - target) over
/// the sum (less half the tolerance, so the last step lands within the tolerance instead
/// of exactly on the target). The slab argument holds for convex pairs (and convex
/// against a plane); a compound is searched child by child and a triangle mesh triangle
/// by triangle (the triangles its BVH finds in the other shape's swept box), each a
/// convex pair, and the earliest hit wins: one slab for a whole concave shape would let
/// a fast body pass a far triangle while a near one sets a slow bound. Throws
/// InvalidArgument for a negative or non-finite duration, non-finite motion or target,
/// or tolerance <= 0 / max_iterations < 1 (max_iterations caps each convex pair).
ToiResult time_of_impact(const Shape& a, const Motion& motion_a, const Shape& b, const Motion& motion_b,
                         Real duration, const ToiSettings& settings = {});

/// Radius (m) of the largest ball about the shape's centre (the origin of a primitive,
/// the vertex mean of a hull) that fits inside it: its half-thickness. For a compound
/// the smallest of its children's; 0 for a plane or a triangle mesh. The world's CCD
/// measures how fast a body moves against this size.
Real inner_radius(const Shape& shape);

/// Largest distance (m) of any point of the shape from its local point `center`, an
/// upper bound from the corners of its local bounding box; infinite for a plane.
Real bounding_radius(const Shape& shape, const Vec3& center);

/// World box (m) holding every point the shape passes through during [0, duration]
/// under `motion`: the boxes at both ends when it does not turn, else the box of the
/// ball that holds it (bounding_radius about the rotation centre) swept along the
/// centre's path.
Aabb swept_aabb(const Shape& shape, const Motion& motion, Real duration);

}  // namespace wmo
