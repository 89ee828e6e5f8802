// WMO math layer: scalar, vector, quaternion, pose and AABB types.
//
// Units: metres, seconds, kilograms, radians everywhere in WMO.
// Precision: everything is double. Positions far from the origin (1e4 m and beyond)
// keep 0.1 mm because pair queries are evaluated in the frame of shape A (see types.h),
// so local math only ever sees small coordinates.
#pragma once

#include <Eigen/Core>
#include <Eigen/Geometry>

#include <cmath>
#include <cstdint>
#include <limits>
#include <stdexcept>
#include <string>

namespace wmo {

using Real = double;
using Vec3 = Eigen::Vector3d;
using Mat3 = Eigen::Matrix3d;
using Quat = Eigen::Quaterniond;

constexpr Real kInf = std::numeric_limits<Real>::infinity();
constexpr Real kPi = 3.14159265358979323846;

/// Tolerance on |q| - 1 accepted for a user-supplied orientation quaternion. Large
/// enough for quaternions written with 7 significant digits (float round trips and
/// hand-typed values), small enough that a non-normalised input is caught.
constexpr Real kUnitQuatTolerance = 1e-5;

/// Error raised by WMO on invalid user input. The message names the field and the bad
/// value; the bindings translate it into Python's ValueError.
class InvalidArgument : public std::invalid_argument {
 public:
  using std::invalid_argument::invalid_argument;
};

/// Throws InvalidArgument("<field> must be finite and > 0, got <value>").
void require_positive(const char* field, Real value);
/// Throws InvalidArgument unless value is finite and >= 0.
void require_non_negative(const char* field, Real value);
/// Throws InvalidArgument unless every component is finite.
void require_finite(const char* field, const Vec3& v);
/// Formats a vector as "(x, y, z)" for error messages.
std::string to_string(const Vec3& v);

/// A rigid transform: x_parent = rotation * x_local + position.
/// `rotation` is a unit quaternion. Eigen stores quaternions as (x, y, z, w) in memory,
/// the same order WMO's Python API uses.
struct Pose {
  Vec3 position = Vec3::Zero();         ///< unit: metres, in the parent frame
  Quat rotation = Quat::Identity();     ///< unit quaternion, local -> parent

  Pose() = default;
  Pose(const Vec3& p, const Quat& q) : position(p), rotation(q) {}
  explicit Pose(const Vec3& p) : position(p) {}

  static Pose identity() { return Pose(); }

  /// Validating constructor for user input: throws InvalidArgument if the position is
  /// not finite or the quaternion (x, y, z, w) is NaN or not unit within
  /// kUnitQuatTolerance. The stored quaternion is renormalised.
  static Pose checked(const Vec3& p, const Quat& q, const char* field = "pose");

  /// Point from local to parent frame.
  Vec3 transform_point(const Vec3& x) const { return rotation * x + position; }
  /// Direction from local to parent frame.
  Vec3 transform_vector(const Vec3& v) const { return rotation * v; }
  /// Point from parent to local frame.
  Vec3 inverse_transform_point(const Vec3& x) const {
    return rotation.conjugate() * (x - position);
  }
  /// Direction from parent to local frame.
  Vec3 inverse_transform_vector(const Vec3& v) const { return rotation.conjugate() * v; }

  Pose inverse() const {
    Quat qi = rotation.conjugate();
    return Pose(-(qi * position), qi);
  }
  /// Composition: (a * b) maps b's local frame into a's parent frame.
  Pose operator*(const Pose& b) const {
    return Pose(rotation * b.position + position, rotation * b.rotation);
  }
  /// Pose of `b` expressed in the frame of `*this` (both given in a common frame).
  Pose relative(const Pose& b) const { return inverse() * b; }

  Mat3 matrix() const { return rotation.toRotationMatrix(); }
};

/// Axis-aligned bounding box. An empty box has min > max.
struct Aabb {
  Vec3 min = Vec3::Constant(kInf);
  Vec3 max = Vec3::Constant(-kInf);

  Aabb() = default;
  Aabb(const Vec3& lo, const Vec3& hi) : min(lo), max(hi) {}

  bool empty() const { return (min.array() > max.array()).any(); }
  bool overlaps(const Aabb& o) const {
    return (min.array() <= o.max.array()).all() && (o.min.array() <= max.array()).all();
  }
  bool contains(const Aabb& o) const {
    return (min.array() <= o.min.array()).all() && (o.max.array() <= max.array()).all();
  }
  void grow(const Vec3& p) {
    min = min.cwiseMin(p);
    max = max.cwiseMax(p);
  }
  void grow(const Aabb& o) {
    min = min.cwiseMin(o.min);
    max = max.cwiseMax(o.max);
  }
  Aabb fattened(Real margin) const {
    return Aabb(min.array() - margin, max.array() + margin);
  }
  Vec3 center() const { return 0.5 * (min + max); }
  Vec3 half_extents() const { return 0.5 * (max - min); }
  /// Surface area (used by the AABB tree's SAH cost).
  Real surface_area() const {
    Vec3 d = max - min;
    return 2.0 * (d.x() * d.y() + d.y() * d.z() + d.z() * d.x());
  }
  static Aabb merge(const Aabb& a, const Aabb& b) {
    return Aabb(a.min.cwiseMin(b.min), a.max.cwiseMax(b.max));
  }
  /// AABB of this box (given in a local frame) after a rigid transform.
  /// Arvo's method: |R| * half extents.
  Aabb transformed(const Pose& pose) const {
    Vec3 c = pose.transform_point(center());
    Vec3 h = pose.matrix().cwiseAbs() * half_extents();
    return Aabb(c - h, c + h);
  }
};

/// Any unit vector perpendicular to `n` (n must be unit). Duff et al. 2017, "Building an
/// orthonormal basis, revisited": branch-free and continuous except at n.z = -1.
inline void orthonormal_basis(const Vec3& n, Vec3& t1, Vec3& t2) {
  const Real sign = std::copysign(Real(1), n.z());
  const Real a = -1.0 / (sign + n.z());
  const Real b = n.x() * n.y() * a;
  t1 = Vec3(1.0 + sign * n.x() * n.x() * a, sign * b, -sign * n.x());
  t2 = Vec3(b, sign + n.y() * n.y() * a, -n.y());
}

}  // namespace wmo
