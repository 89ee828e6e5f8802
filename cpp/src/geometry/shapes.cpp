// Primitive shapes: support maps, supporting faces, bounding boxes and mass properties.
//
// Support maps follow van den Bergen 2003 ("Collision Detection in Interactive 3D
// Environments", 4.3); supporting faces feed the contact manifold's face clipping
// (Gregorius, "Robust Contact Creation for Physics Simulations", GDC 2015).
// Closed-form mass properties: any table of solid moments (e.g. Goldstein 3rd ed.);
// the rounded box is composed exactly of box, slabs, quarter cylinders and sphere
// octants (see rounded_box_second_moment).
#include <algorithm>
#include <array>
#include <cmath>
#include <sstream>
#include <string>

#include "wmo/geometry/shapes.h"

namespace wmo {

namespace {

using detail::kTinyDirSq;
using detail::sign_or_plus;
using detail::unit_or_x;

std::string fmt(Real x) {
  std::ostringstream s;
  s.precision(17);
  s << x;
  return s.str();
}

void check_density(Real density) { require_positive("density", density); }

// Rotates a body-frame inertia tensor into the parent frame: R I R^T.
Mat3 rotate_inertia(const Mat3& inertia, const Quat& q) {
  const Mat3 r = q.toRotationMatrix();
  return r * inertia * r.transpose();
}

// Shift of an inertia tensor from the centre of mass to a point at offset `d` from it
// (parallel-axis theorem, Steiner): m (|d|^2 E - d d^T).
Mat3 parallel_axis(Real mass, const Vec3& d) {
  return mass * (d.squaredNorm() * Mat3::Identity() - d * d.transpose());
}

// Exact integral of x^2 over a rounded box (volume), centred at the origin, whose core
// has half extents (a, b, c) with x along `a`, rounded by r. The rounded box is the
// disjoint union of the core box, six slabs of thickness r on the faces, twelve quarter
// cylinders of radius r along the edges and eight sphere octants at the corners
// (the Minkowski sum of a box and a ball). Moments of the pieces used below:
//   quarter disk of radius r: area pi r^2/4, int s dA = r^3/3, int s^2 dA = pi r^4/16;
//   sphere octant of radius r: volume pi r^3/6, int s dV = pi r^4/16, int s^2 dV = pi r^5/30.
Real rounded_box_second_moment(Real a, Real b, Real c, Real r) {
  const Real x2_core = 2 * a * a * a / 3;                         // int_{-a}^{a} x^2 dx
  const Real x2_slab = ((a + r) * (a + r) * (a + r) - a * a * a) / 3;  // int_a^{a+r} x^2 dx
  Real s = x2_core * (2 * b) * (2 * c);                          // core box
  s += 2 * x2_slab * (2 * b) * (2 * c);                          // slabs on +-x faces
  s += 2 * x2_core * r * (2 * c);                                // slabs on +-y faces
  s += 2 * x2_core * (2 * b) * r;                                // slabs on +-z faces
  // Quarter cylinders along x (4 of them): x ranges over [-a, a].
  s += 4 * x2_core * (kPi * r * r / 4);
  // Quarter cylinders along y and z (4 each): x = +-(a + s) over a quarter disk.
  const Real quarter_disk = a * a * kPi * r * r / 4 + 2 * a * r * r * r / 3 + kPi * r * r * r * r / 16;
  s += 4 * (2 * b) * quarter_disk + 4 * (2 * c) * quarter_disk;
  // Sphere octants at the 8 corners: x = +-(a + s) over an octant.
  s += 8 * (a * a * kPi * r * r * r / 6 + 2 * a * kPi * r * r * r * r / 16 +
            kPi * r * r * r * r * r / 30);
  return s;
}

}  // namespace

// ---------------------------------------------------------------------------------
// Shape

MassProperties Shape::mass_properties(Real density) const {
  // Solid shapes override this; reaching it means the shape has no volume.
  throw InvalidArgument(std::string("shape ") + to_string(type()) +
                        " is not solid; mass properties need a solid shape");
}

// ---------------------------------------------------------------------------------
// Sphere

Sphere::Sphere(Real radius) : ConvexShape(ShapeType::kSphere) {
  require_positive("radius", radius);
  radius_ = radius;
}

Vec3 Sphere::support(const Vec3& dir) const { return radius_ * unit_or_x(dir); }

void Sphere::supporting_face(const Vec3& dir, SupportingFace& face) const {
  // A sphere has no flat feature: its supporting feature is the single support point.
  face.count = 1;
  face.vertices[0] = support(dir);
  face.feature = 0;
}

Aabb Sphere::local_aabb() const {
  return Aabb(Vec3::Constant(-radius_), Vec3::Constant(radius_));
}

Aabb Sphere::world_aabb(const Pose& pose) const {
  // Rotation-invariant: the tight box is centre +- r.
  return Aabb(pose.position.array() - radius_, pose.position.array() + radius_);
}

MassProperties Sphere::mass_properties(Real density) const {
  check_density(density);
  MassProperties mp;
  const Real r = radius_;
  mp.volume = 4.0 / 3.0 * kPi * r * r * r;
  mp.mass = density * mp.volume;
  mp.inertia = Mat3::Identity() * (0.4 * mp.mass * r * r);
  return mp;
}

// ---------------------------------------------------------------------------------
// Box

Box::Box(const Vec3& half_extents, Real rounding) : ConvexShape(ShapeType::kBox) {
  if (!(half_extents.allFinite() && (half_extents.array() > 0).all()))
    throw InvalidArgument("half_extents must be finite and > 0, got " + to_string(half_extents));
  require_non_negative("rounding", rounding);
  const Real smallest = half_extents.minCoeff();
  if (!(rounding < smallest))
    throw InvalidArgument("rounding must be < the smallest half extent " + fmt(smallest) +
                          ", got " + fmt(rounding));
  half_extents_ = half_extents;
  radius_ = rounding;
  core_ = half_extents.array() - rounding;
}

Vec3 Box::support_core(const Vec3& dir) const {
  return Vec3(sign_or_plus(dir.x()) * core_.x(), sign_or_plus(dir.y()) * core_.y(),
              sign_or_plus(dir.z()) * core_.z());
}

Vec3 Box::support(const Vec3& dir) const {
  if (radius_ == 0) return Vec3(sign_or_plus(dir.x()) * half_extents_.x(),
                                sign_or_plus(dir.y()) * half_extents_.y(),
                                sign_or_plus(dir.z()) * half_extents_.z());
  return support_core(dir) + radius_ * unit_or_x(dir);
}

void Box::supporting_face(const Vec3& dir, SupportingFace& face) const {
  // Face whose outward normal is most aligned with dir: the axis of largest |dir_i|.
  // Ties go to the lower axis so the choice is deterministic.
  const Vec3 a = dir.cwiseAbs();
  int axis = 0;
  if (a.y() > a[axis]) axis = 1;
  if (a.z() > a[axis]) axis = 2;
  const Real s = sign_or_plus(dir[axis]);
  // Feature ids: 0 +x, 1 -x, 2 +y, 3 -y, 4 +z, 5 -z.
  face.feature = static_cast<std::uint32_t>(2 * axis + (s < 0 ? 1 : 0));
  // Tangents u, v with u x v = s * e_axis, so (+u+v, -u+v, -u-v, +u-v) runs CCW seen
  // from outside. The face lies on the outer surface (half extent along the axis) and
  // spans the core's extent along u and v (the flat part of a rounded box's face).
  const int i1 = (axis + 1) % 3, i2 = (axis + 2) % 3;  // e_i1 x e_i2 = e_axis
  Vec3 c = Vec3::Zero();
  c[axis] = s * half_extents_[axis];
  Vec3 u = Vec3::Zero(), v = Vec3::Zero();
  u[i1] = core_[i1];
  v[i2] = s * core_[i2];  // flipping v flips u x v for the negative face
  face.count = 4;
  face.normal = Vec3::Zero();
  face.normal[axis] = s;
  face.vertices[0] = c + u + v;
  face.vertices[1] = c - u + v;
  face.vertices[2] = c - u - v;
  face.vertices[3] = c + u - v;
}

Aabb Box::local_aabb() const { return Aabb(-half_extents_, half_extents_); }

MassProperties Box::mass_properties(Real density) const {
  check_density(density);
  MassProperties mp;
  const Real a = core_.x(), b = core_.y(), c = core_.z(), r = radius_;
  // Volume of the Minkowski sum of the core box and a ball of radius r (Steiner's
  // formula): box + face slabs + edge quarter cylinders + corner octants.
  mp.volume = 8 * a * b * c + 8 * r * (a * b + b * c + c * a) +
              2 * kPi * r * r * (a + b + c) + 4.0 / 3.0 * kPi * r * r * r;
  mp.mass = density * mp.volume;
  const Real sxx = rounded_box_second_moment(a, b, c, r);
  const Real syy = rounded_box_second_moment(b, c, a, r);
  const Real szz = rounded_box_second_moment(c, a, b, r);
  // Symmetric about all three coordinate planes: products of inertia vanish.
  mp.inertia = Vec3(density * (syy + szz), density * (sxx + szz), density * (sxx + syy))
                   .asDiagonal();
  return mp;
}

// ---------------------------------------------------------------------------------
// Capsule

Capsule::Capsule(Real radius, Real half_height) : ConvexShape(ShapeType::kCapsule) {
  require_positive("radius", radius);
  require_positive("half_height", half_height);
  radius_ = radius;
  half_height_ = half_height;
}

Vec3 Capsule::support_core(const Vec3& dir) const {
  return Vec3(0, sign_or_plus(dir.y()) * half_height_, 0);
}

Vec3 Capsule::support(const Vec3& dir) const {
  return support_core(dir) + radius_ * unit_or_x(dir);
}

// |dot(dir, axis)| below which a capsule reports its whole side segment rather than a
// single point: sin(5.7 deg). A capsule lying on a face is never exactly parallel to it
// (solver noise), and reporting one point there makes it rock from end to end. Within
// this angle the far end of the segment is at most 2 half_height 0.1 + radius 0.005
// behind the support point along dir (axial tilt, plus the radius being pushed
// perpendicular to the axis instead of along dir); the manifold keeps only points
// within the contact margin, so the extra point costs nothing when it is not touching.
constexpr Real kCapsuleSideCos = 0.1;

void Capsule::supporting_face(const Vec3& dir, SupportingFace& face) const {
  const Vec3 d = unit_or_x(dir);
  if (std::abs(d.y()) < kCapsuleSideCos) {
    // Side segment pushed out by the radius along dir's component perpendicular to the
    // axis, i.e. the line of the cylindrical surface that faces dir.
    const Vec3 perp = unit_or_x(Vec3(d.x(), 0, d.z()));
    face.count = 2;
    face.vertices[0] = Vec3(0, half_height_, 0) + radius_ * perp;
    face.vertices[1] = Vec3(0, -half_height_, 0) + radius_ * perp;
    face.feature = 0;
    return;
  }
  // Feature ids: 0 side, 1 top hemisphere, 2 bottom hemisphere.
  face.count = 1;
  face.vertices[0] = support(d);
  face.feature = d.y() >= 0 ? 1u : 2u;
}

Aabb Capsule::local_aabb() const {
  const Vec3 h(radius_, half_height_ + radius_, radius_);
  return Aabb(-h, h);
}

Aabb Capsule::world_aabb(const Pose& pose) const {
  // Tight box: the box of the two (rotated) segment end points, grown by the radius.
  const Vec3 axis = pose.rotation * Vec3(0, half_height_, 0);
  const Vec3 e = axis.cwiseAbs().array() + radius_;
  return Aabb(pose.position - e, pose.position + e);
}

MassProperties Capsule::mass_properties(Real density) const {
  check_density(density);
  MassProperties mp;
  const Real r = radius_, h = half_height_;
  const Real v_cyl = kPi * r * r * 2 * h;
  const Real v_sph = 4.0 / 3.0 * kPi * r * r * r;  // the two hemispheres together
  mp.volume = v_cyl + v_sph;
  mp.mass = density * mp.volume;
  const Real m_cyl = density * v_cyl, m_sph = density * v_sph;
  // About the axis: solid cylinder m r^2/2, sphere 2/5 m r^2.
  const Real iy = m_cyl * r * r / 2 + 0.4 * m_sph * r * r;
  // About a transverse axis through the centre: cylinder m (r^2/4 + h^2/3). Each
  // hemisphere has its centre of mass 3r/8 from its flat face, so about its own centre
  // it has 2/5 m r^2 - m (3r/8)^2, shifted by (h + 3r/8): together
  // m_sph (2/5 r^2 + h^2 + 3 h r / 4).
  const Real ix = m_cyl * (r * r / 4 + h * h / 3) + m_sph * (0.4 * r * r + h * h + 0.75 * h * r);
  mp.inertia = Vec3(ix, iy, ix).asDiagonal();
  return mp;
}

// ---------------------------------------------------------------------------------
// Cylinder

Cylinder::Cylinder(Real cylinder_radius, Real half_height) : ConvexShape(ShapeType::kCylinder) {
  require_positive("cylinder_radius", cylinder_radius);
  require_positive("half_height", half_height);
  cylinder_radius_ = cylinder_radius;
  half_height_ = half_height;
  radius_ = 0;
}

Vec3 Cylinder::support(const Vec3& dir) const {
  const Real y = sign_or_plus(dir.y()) * half_height_;
  const Real h2 = dir.x() * dir.x() + dir.z() * dir.z();
  // Along the axis every point of the cap supports; the cap centre is a valid choice.
  if (!(h2 > kTinyDirSq)) return Vec3(0, y, 0);
  const Real s = cylinder_radius_ / std::sqrt(h2);
  return Vec3(s * dir.x(), y, s * dir.z());
}

// Number of rim points used for a cap face. The N-gon is inscribed in the rim circle
// and, whenever dir has a horizontal component of at least kCylinderAlignSin, rotated
// so that one vertex is exactly the rim support point: the deepest point of a tilted
// cylinder is then exact and every other rim point lies at most
// R (1 - cos(pi / N)) = 0.0192 R (N = 16) inside the true rim. Below that tilt the
// polygon keeps a fixed orientation (stable feature positions for a cylinder standing
// on a cap, for warm starting) and the depth error along dir is at most
// 0.0192 R * kCylinderAlignSin = 1e-3 R. 16 points keep clipping cheap; the manifold is
// reduced to 4 points afterwards.
constexpr int kCylinderCapPoints = 16;
constexpr Real kCylinderAlignSin = 0.05;

void Cylinder::supporting_face(const Vec3& dir, SupportingFace& face) const {
  const Vec3 d = unit_or_x(dir);
  const Real hx = d.x(), hz = d.z();
  const Real hlen = std::sqrt(hx * hx + hz * hz);
  if (std::abs(d.y()) < hlen) {
    // Within 45 degrees of perpendicular to the axis the side faces dir: report the
    // side line through the rim support point (feature 2).
    const Vec3 p(cylinder_radius_ * hx / hlen, 0, cylinder_radius_ * hz / hlen);
    face.count = 2;
    face.vertices[0] = p + Vec3(0, half_height_, 0);
    face.vertices[1] = p - Vec3(0, half_height_, 0);
    face.feature = 2;
    return;
  }
  // Cap facing dir: feature 0 top, 1 bottom.
  const bool top = d.y() >= 0;
  face.feature = top ? 0u : 1u;
  face.normal = Vec3(0, top ? 1 : -1, 0);
  const Real y = top ? half_height_ : -half_height_;
  // Vertex i at angle phase -+ step_i (phase = atan2(hz, hx)), by the angle-sum
  // formulas on the unit vector (cos phase, sin phase) = (hx, hz) / hlen and the
  // table of step angles: no trigonometric call per query (16 sincos were a fifth of a
  // cylinder's supporting face), and vertex 0 is the rim support point itself.
  Real cp = 1, sp = 0;
  if (hlen >= kCylinderAlignSin) {
    cp = hx / hlen;
    sp = hz / hlen;
  }
  static const std::array<std::array<Real, 2>, kCylinderCapPoints> kSteps = [] {
    std::array<std::array<Real, 2>, kCylinderCapPoints> t{};
    for (int i = 0; i < kCylinderCapPoints; ++i) {
      const Real step = 2 * kPi * i / kCylinderCapPoints;
      t[i] = {std::cos(step), std::sin(step)};
    }
    return t;
  }();
  // CCW seen from outside: seen from +Y, (z, x) is a right-handed basis of the cap,
  // so the top cap runs with decreasing angle atan2(z, x) and the bottom cap with
  // increasing: sin(phase -+ step) = sp cs -+ cp ss, cos(phase -+ step) = cp cs +- sp ss.
  const Real turn = top ? -1 : 1;
  face.count = kCylinderCapPoints;
  for (int i = 0; i < kCylinderCapPoints; ++i) {
    const Real cs = kSteps[i][0], ss = turn * kSteps[i][1];
    face.vertices[i] = Vec3(cylinder_radius_ * (cp * cs - sp * ss), y, cylinder_radius_ * (sp * cs + cp * ss));
  }
}

Aabb Cylinder::local_aabb() const {
  const Vec3 h(cylinder_radius_, half_height_, cylinder_radius_);
  return Aabb(-h, h);
}

MassProperties Cylinder::mass_properties(Real density) const {
  check_density(density);
  MassProperties mp;
  const Real r = cylinder_radius_, h = half_height_;
  mp.volume = kPi * r * r * 2 * h;
  mp.mass = density * mp.volume;
  const Real iy = mp.mass * r * r / 2;
  const Real ix = mp.mass * (3 * r * r + 4 * h * h) / 12;  // length 2h: (3r^2 + (2h)^2)/12
  mp.inertia = Vec3(ix, iy, ix).asDiagonal();
  return mp;
}

// ---------------------------------------------------------------------------------
// Plane

Plane::Plane(const Vec3& normal, Real offset) : Shape(ShapeType::kPlane) {
  const Real n = normal.norm();
  if (!(normal.allFinite() && n > 0 && std::isfinite(n)))
    throw InvalidArgument("normal must be finite and non-zero, got " + to_string(normal));
  if (!std::isfinite(offset)) throw InvalidArgument("offset must be finite, got " + fmt(offset));
  // The offset is a distance in metres along the unit normal (as the bindings document
  // it), so it is kept as given: Plane((0, 2, 0), 1) is y <= 1.
  normal_ = normal / n;
  offset_ = offset;
}

Aabb Plane::local_aabb() const {
  // Box of the half-space clipped to the cube [-E, E]^3, E = kUnboundedExtent. Along
  // axis i: n_i x_i <= offset - sum_{j != i} n_j x_j <= offset + E sum_{j != i} |n_j|,
  // which bounds x_i from above when n_i > 0 and from below when n_i < 0 (exact for
  // axis-aligned normals, where the box is a slab with one tight side). The bound is
  // clamped into [-E, E] so the box is never empty.
  const Real e = kUnboundedExtent;
  Aabb box(Vec3::Constant(-e), Vec3::Constant(e));
  const Real l1 = normal_.cwiseAbs().sum();
  for (int i = 0; i < 3; ++i) {
    const Real ni = normal_[i];
    if (ni == 0) continue;
    const Real m = offset_ + e * (l1 - std::abs(ni));
    const Real bound = std::clamp(m / ni, -e, e);
    if (ni > 0) box.max[i] = bound;
    else box.min[i] = bound;
  }
  return box;
}

// ---------------------------------------------------------------------------------
// Compound

Compound::Compound(std::vector<Child> children) : Shape(ShapeType::kCompound) {
  if (children.empty()) throw InvalidArgument("children must not be empty, got 0 children");
  for (std::size_t i = 0; i < children.size(); ++i) {
    const std::string field = "children[" + std::to_string(i) + "]";
    if (!children[i].shape) throw InvalidArgument(field + ".shape must not be null, got null");
    // Validates and renormalises the child pose.
    children[i].pose =
        Pose::checked(children[i].pose.position, children[i].pose.rotation, (field + ".pose").c_str());
    aabb_.grow(children[i].shape->world_aabb(children[i].pose));
  }
  children_ = std::move(children);
}

MassProperties Compound::mass_properties(Real density) const {
  check_density(density);
  MassProperties total;
  std::vector<MassProperties> parts;
  parts.reserve(children_.size());
  Vec3 moment = Vec3::Zero();
  for (const Child& c : children_) {
    MassProperties p = c.shape->mass_properties(density);
    // Into the compound frame.
    p.center_of_mass = c.pose.transform_point(p.center_of_mass);
    p.inertia = rotate_inertia(p.inertia, c.pose.rotation);
    total.volume += p.volume;
    total.mass += p.mass;
    moment += p.mass * p.center_of_mass;
    parts.push_back(p);
  }
  total.center_of_mass = moment / total.mass;
  for (const MassProperties& p : parts)
    total.inertia += p.inertia + parallel_axis(p.mass, p.center_of_mass - total.center_of_mass);
  // Remove the asymmetry left by rounding so downstream eigen-solvers see a symmetric matrix.
  total.inertia = 0.5 * (total.inertia + total.inertia.transpose()).eval();
  return total;
}

}  // namespace wmo
