// WMO dynamics layer: rigid-body definitions, mass properties and integration helpers.
//
// Frames: a body's pose (position, orientation) places its shape's local frame in the
// world; the centre of mass sits at `local_com` in that frame. Velocities are those of
// the centre of mass (linear, m/s) and the body's angular velocity (rad/s), both in the
// world frame. Units: metres, kilograms, seconds, radians.
#pragma once

#include <cstdint>
#include <limits>
#include <memory>

#include "wmo/geometry/shapes.h"
#include "wmo/math.h"

namespace wmo {

/// How a body moves. Static bodies never move; kinematic bodies move with the velocity
/// the user gives them and are not pushed by contacts (infinite mass); dynamic bodies
/// respond to gravity, forces and contacts.
enum class BodyKind : std::uint8_t { kStatic = 0, kKinematic = 1, kDynamic = 2 };

/// Parses "static" / "kinematic" / "dynamic"; throws InvalidArgument naming the value.
BodyKind body_kind_from_string(const std::string& s);
const char* to_string(BodyKind k);

/// Everything needed to create a body. Defaults give a dynamic body of density 1000
/// kg/m^3 at the origin, at rest.
struct BodyDef {
  std::shared_ptr<const Shape> shape;  ///< required; shared, never copied
  BodyKind kind = BodyKind::kDynamic;
  Vec3 position = Vec3::Zero();              ///< unit: m, world frame (shape origin)
  Quat orientation = Quat::Identity();       ///< unit quaternion, shape local -> world
  Vec3 linear_velocity = Vec3::Zero();       ///< unit: m/s, of the centre of mass
  Vec3 angular_velocity = Vec3::Zero();      ///< unit: rad/s, world frame
  /// Mass (kg). NaN (the default) derives it from `density` and the shape's volume;
  /// a positive value scales the shape's inertia to this mass. Ignored unless dynamic.
  Real mass = std::numeric_limits<Real>::quiet_NaN();
  Real density = 1000;  ///< unit: kg/m^3, used when `mass` is NaN
  /// Coulomb friction coefficient (>= 0); a pair combines the two (WorldSettings).
  Real friction = 0.5;
  /// Restitution coefficient in [0, 1]; a pair combines the two (WorldSettings).
  Real restitution = 0;
  Real linear_damping = 0;   ///< unit: 1/s, v *= 1 / (1 + h * damping) per step
  Real angular_damping = 0;  ///< unit: 1/s, same form for the angular velocity
  Real gravity_scale = 1;    ///< multiplies the world's gravity for this body
  /// Continuous collision detection for this body (WorldSettings::enable_ccd must be on
  /// too): it never passes through anything, however fast it moves or spins. Off by
  /// default; only the bodies that ask pay for it (see world.h, the ccd stage).
  bool ccd = false;
  /// Collision group, 0..kMaxCollisionGroups-1 (default 0). Two bodies collide only if
  /// their groups do (World::set_group_collision; every pair of groups collides until
  /// told otherwise) and their pair is not filtered (World::set_pair_collision): the
  /// UsdPhysics CollisionGroup and FilteredPairsAPI, Box2D's category bits.
  int collision_group = 0;
  /// Centre of mass (m, shape local frame). NaN (the default) takes the shape's
  /// centroid; a given point moves the shape's inertia there (parallel axes) unless
  /// `inertia` is given too. Ignored unless dynamic. (UsdPhysics MassAPI centerOfMass.)
  Vec3 center_of_mass = Vec3::Constant(std::numeric_limits<Real>::quiet_NaN());
  /// Principal moments of inertia about the centre of mass (kg m^2, each > 0, each no
  /// more than the sum of the other two). NaN (the default) derives the inertia from
  /// the shape and the mass. Ignored unless dynamic. (MassAPI diagonalInertia.)
  Vec3 inertia = Vec3::Constant(std::numeric_limits<Real>::quiet_NaN());
  /// Orientation of the principal axes in the shape's local frame (unit quaternion);
  /// used with `inertia`. (MassAPI principalAxes.)
  Quat inertia_axes = Quat::Identity();
  /// The full inertia tensor about the centre of mass (kg m^2, shape local frame):
  /// symmetric, its eigenvalues principal moments as for `inertia`. NaN (the default)
  /// means not given; it cannot be given together with `inertia`. Taken bit for bit,
  /// so that a saved body (Body's inertia_local) is restored exactly.
  Mat3 inertia_tensor = Mat3::Constant(std::numeric_limits<Real>::quiet_NaN());
};

/// Number of collision groups (BodyDef::collision_group): one bit each in a 64-bit mask.
constexpr int kMaxCollisionGroups = 64;
/// Throws InvalidArgument naming `field` unless 0 <= group < kMaxCollisionGroups.
void check_collision_group(int group, const char* field);

/// Mass data of a body in its shape's local frame.
struct BodyMass {
  Real mass = 0;                   ///< unit: kg; 0 for static and kinematic bodies
  Real inv_mass = 0;               ///< unit: 1/kg
  Vec3 local_com = Vec3::Zero();   ///< unit: m, shape local frame
  Mat3 inv_inertia_local = Mat3::Zero();  ///< unit: 1/(kg m^2), about the COM, local axes
  Mat3 inertia_local = Mat3::Zero();      ///< unit: kg m^2, about the COM, local axes
  /// inertia_local is a multiple of the identity (then R I R^T = I in every frame and
  /// there is no gyroscopic term).
  bool isotropic = false;
};

/// Mass data for a body definition: zero (infinite mass) unless dynamic. Throws
/// InvalidArgument for a dynamic body on a non-solid shape (plane, triangle mesh), a
/// non-positive or NaN density, or a negative / zero / infinite given mass.
BodyMass compute_body_mass(const BodyDef& def);

/// Checks every field of `def` (finite pose and velocities, unit quaternion, sizes and
/// coefficients in range) and throws InvalidArgument naming the first bad field.
void validate_body_def(const BodyDef& def);

/// World-space inverse inertia R I^-1 R^T for orientation `q`.
inline Mat3 world_inv_inertia(const Quat& q, const Mat3& inv_inertia_local) {
  const Mat3 r = q.toRotationMatrix();
  return r * inv_inertia_local * r.transpose();
}

/// Orientation advanced by angular velocity w (rad/s, world) over h seconds, by the
/// first-order quaternion update q + h/2 (0, w) q, normalised (Box2D v3 and Bullet use
/// the same form; its error is O((h |w|)^2) per step and it preserves |q| = 1).
/// A body that does not turn (w exactly zero) keeps q as it is: the exact answer, where
/// the update would only renormalise q, at the cost of a square root and four
/// divisions, most of the cost of integrating a free body (measured: 10,000
/// free-falling spheres, 4 substeps: bench_world_overhead's plain loop 313 -> 103 us a
/// step, World::step 586 -> 342 us). Jolt also skips the rotation of a body that does
/// not turn (below a threshold; this test is exact).
inline Quat integrate_rotation(const Quat& q, const Vec3& w, Real h) {
  if ((w.x() == 0) & (w.y() == 0) & (w.z() == 0)) return q;
  const Quat dq(0, 0.5 * h * w.x(), 0.5 * h * w.y(), 0.5 * h * w.z());
  Quat r = q;
  r.coeffs() += (dq * q).coeffs();
  r.normalize();
  return r;
}

}  // namespace wmo
