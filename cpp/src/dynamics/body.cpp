// Body definitions: validation and mass properties.
#include "wmo/dynamics/body.h"

#include <Eigen/Eigenvalues>

#include <cmath>
#include <sstream>
#include <string>

namespace wmo {

BodyKind body_kind_from_string(const std::string& s) {
  if (s == "static") return BodyKind::kStatic;
  if (s == "kinematic") return BodyKind::kKinematic;
  if (s == "dynamic") return BodyKind::kDynamic;
  throw InvalidArgument("kind must be 'static', 'kinematic' or 'dynamic', got '" + s + "'");
}

const char* to_string(BodyKind k) {
  switch (k) {
    case BodyKind::kStatic:
      return "static";
    case BodyKind::kKinematic:
      return "kinematic";
    case BodyKind::kDynamic:
      return "dynamic";
  }
  return "?";
}

namespace {
std::string num(Real v) {
  std::ostringstream o;
  o << v;
  return o.str();
}
}  // namespace

void check_collision_group(int group, const char* field) {
  if (group < 0 || group >= kMaxCollisionGroups)
    throw InvalidArgument(std::string(field) + " must be in [0, " + std::to_string(kMaxCollisionGroups - 1) +
                          "], got " + std::to_string(group));
}

/// Principal moments of a real body: positive, and the triangle inequality (a
/// tolerance of 1e-9 relative: a thin rod's or a flat plate's moments meet it with
/// equality up to rounding).
static void check_principal_moments(const Vec3& I, const char* field) {
  const Real slack = 1e-9 * I.sum();
  if (!(I.minCoeff() > 0) || I.x() > I.y() + I.z() + slack || I.y() > I.x() + I.z() + slack ||
      I.z() > I.x() + I.y() + slack)
    throw InvalidArgument(std::string(field) + " must be principal moments > 0 that satisfy the triangle inequality, got (" +
                          num(I.x()) + ", " + num(I.y()) + ", " + num(I.z()) + ")");
}

void validate_body_def(const BodyDef& d) {
  if (!d.shape) throw InvalidArgument("shape must be a shape, got None");
  require_finite("position", d.position);
  const Real qn = d.orientation.norm();
  if (!d.orientation.coeffs().allFinite() || std::abs(qn - 1) > kUnitQuatTolerance)
    throw InvalidArgument("orientation must be a unit quaternion (x, y, z, w), got norm " + num(qn));
  require_finite("linear_velocity", d.linear_velocity);
  require_finite("angular_velocity", d.angular_velocity);
  require_positive("density", d.density);
  if (!std::isnan(d.mass)) require_positive("mass", d.mass);
  require_non_negative("friction", d.friction);
  if (!(d.restitution >= 0 && d.restitution <= 1))
    throw InvalidArgument("restitution must be in [0, 1], got " + num(d.restitution));
  require_non_negative("linear_damping", d.linear_damping);
  require_non_negative("angular_damping", d.angular_damping);
  if (!std::isfinite(d.gravity_scale)) throw InvalidArgument("gravity_scale must be finite, got " + num(d.gravity_scale));
  if (!d.center_of_mass.array().isNaN().all()) require_finite("center_of_mass", d.center_of_mass);
  if (!d.inertia.array().isNaN().all()) {
    require_finite("inertia", d.inertia);
    check_principal_moments(d.inertia, "inertia");
    const Real an = d.inertia_axes.norm();
    if (!d.inertia_axes.coeffs().allFinite() || std::abs(an - 1) > kUnitQuatTolerance)
      throw InvalidArgument("inertia_axes must be a unit quaternion (x, y, z, w), got norm " + num(an));
  }
  if (!d.inertia_tensor.array().isNaN().all()) {
    if (!d.inertia.array().isNaN().all())
      throw InvalidArgument("inertia_tensor and inertia cannot both be given");
    const Mat3& I = d.inertia_tensor;
    if (!I.allFinite()) throw InvalidArgument("inertia_tensor must be finite");
    // Symmetric up to rounding (1e-12 of its largest entry): a tensor computed as
    // R D R^T in floating point is symmetric to a few ulps, not always bit for bit.
    const Real asym = (I - I.transpose()).cwiseAbs().maxCoeff();
    if (!(asym <= 1e-12 * I.cwiseAbs().maxCoeff()))
      throw InvalidArgument("inertia_tensor must be symmetric, got an asymmetry of " + num(asym));
    check_principal_moments(Eigen::SelfAdjointEigenSolver<Mat3>(I, Eigen::EigenvaluesOnly).eigenvalues(),
                            "inertia_tensor (its eigenvalues)");
  }
  check_collision_group(d.collision_group, "collision_group");
  if (d.kind == BodyKind::kDynamic && !d.shape->is_solid())
    throw InvalidArgument(std::string("kind 'dynamic' needs a solid shape, got a ") + to_string(d.shape->type()) +
                          " (use kind='static' or 'kinematic')");
}

BodyMass compute_body_mass(const BodyDef& def) {
  BodyMass m;
  if (def.kind != BodyKind::kDynamic) return m;
  const MassProperties mp = def.shape->mass_properties(def.density);
  Real scale = 1;
  if (!std::isnan(def.mass)) scale = def.mass / mp.mass;
  m.mass = std::isnan(def.mass) ? mp.mass : def.mass;  // a given mass exactly (mp.mass * scale may round)
  m.inv_mass = 1 / m.mass;
  m.local_com = mp.center_of_mass;
  m.inertia_local = mp.inertia * scale;
  if (!def.center_of_mass.array().isNaN().all()) {
    // The shape's inertia moved to the given centre (parallel axes: I + m (|d|^2 1 - d d^T)).
    const Vec3 d = def.center_of_mass - m.local_com;
    m.inertia_local += m.mass * (d.squaredNorm() * Mat3::Identity() - d * d.transpose());
    m.local_com = def.center_of_mass;
  }
  if (!def.inertia.array().isNaN().all()) {
    const Mat3 r = def.inertia_axes.normalized().toRotationMatrix();
    m.inertia_local = r * def.inertia.asDiagonal() * r.transpose();
  }
  if (!def.inertia_tensor.array().isNaN().all()) m.inertia_local = def.inertia_tensor;
  m.inv_inertia_local = m.inertia_local.inverse();
  if (!m.inv_inertia_local.allFinite() || !std::isfinite(m.inv_mass))
    throw InvalidArgument("mass properties of the shape are degenerate (mass " + num(m.mass) + ")");
  // Exactly a multiple of the identity: a sphere's or a cube's inertia, computed in
  // closed form, is; a tilted hull's rarely is, and then it simply counts as anisotropic.
  const Mat3& I = m.inertia_local;
  m.isotropic = I(0, 1) == 0 && I(0, 2) == 0 && I(1, 2) == 0 && I(1, 0) == 0 && I(2, 0) == 0 && I(2, 1) == 0 &&
                I(0, 0) == I(1, 1) && I(1, 1) == I(2, 2);
  return m;
}

}  // namespace wmo
