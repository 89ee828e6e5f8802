#include "wmo/math.h"

#include <sstream>

namespace wmo {

std::string to_string(const Vec3& v) {
  std::ostringstream s;
  s.precision(17);
  s << "(" << v.x() << ", " << v.y() << ", " << v.z() << ")";
  return s.str();
}

namespace {
std::string fmt(Real x) {
  std::ostringstream s;
  s.precision(17);
  s << x;
  return s.str();
}
}  // namespace

void require_positive(const char* field, Real value) {
  if (!(std::isfinite(value) && value > 0))
    throw InvalidArgument(std::string(field) + " must be finite and > 0, got " + fmt(value));
}

void require_non_negative(const char* field, Real value) {
  if (!(std::isfinite(value) && value >= 0))
    throw InvalidArgument(std::string(field) + " must be finite and >= 0, got " + fmt(value));
}

void require_finite(const char* field, const Vec3& v) {
  if (!v.allFinite())
    throw InvalidArgument(std::string(field) + " must be finite, got " + to_string(v));
}

Pose Pose::checked(const Vec3& p, const Quat& q, const char* field) {
  if (!p.allFinite())
    throw InvalidArgument(std::string(field) + ".position must be finite, got " + to_string(p));
  const Eigen::Vector4d c = q.coeffs();  // (x, y, z, w)
  std::ostringstream qs;
  qs.precision(17);
  qs << "(" << c[0] << ", " << c[1] << ", " << c[2] << ", " << c[3] << ")";
  if (!c.allFinite())
    throw InvalidArgument(std::string(field) + ".orientation must be finite, got " + qs.str());
  const Real n = c.norm();
  if (std::abs(n - 1) > kUnitQuatTolerance)
    throw InvalidArgument(std::string(field) +
                          ".orientation must be a unit quaternion (x, y, z, w), got " + qs.str() +
                          " with norm " + fmt(n));
  return Pose(p, Quat(c / n));
}

}  // namespace wmo
