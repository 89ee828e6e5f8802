// Private helper of the collision layer: reduce a contact polygon to at most 4 points.
//
// Clipping two faces (box-box, hull-hull, plane-hull) can yield many points; the solver
// only needs a few that span the contact area. The standard reduction (Gregorius,
// "Robust Contact Creation for Physics Simulations", GDC 2015; also Bullet's and
// Jolt's manifold pruning) keeps:
//   1. the deepest point (the one that matters most for penetration recovery),
//   2. the point furthest from it in the contact plane (longest base line),
//   3. the point forming the largest triangle with those two,
//   4. the point that adds the most area to that triangle (largest quad).
// Geometry is measured on point_a projected onto the plane orthogonal to `normal`, so
// the result does not depend on the depth spread. Ties go to the lower index, so the
// result is deterministic for a deterministic input order. No allocation.
#pragma once

#include <cstddef>
#include <new>

#include "wmo/types.h"

namespace wmo {

/// Scratch room for up to N contact points that a routine writes (points 0..n-1)
/// before it reads them. Not initialised: a `ContactPoint pts[65]` array sets its 65
/// points to zero (4 KB) on every call, which the generic path, hull-hull and the
/// mesh's per-triangle manifolds paid each time. ContactPoint is an aggregate, so the
/// byte array provides its objects implicitly (C++20, P0593).
template <int N>
struct ContactScratch {
  alignas(ContactPoint) std::byte raw[N * sizeof(ContactPoint)];
  ContactPoint* data() { return std::launder(reinterpret_cast<ContactPoint*>(raw)); }
  ContactPoint& operator[](int i) { return data()[i]; }
};

/// Writes into out.points / out.count the (at most kMaxManifoldPoints) points of
/// pts[0..n) chosen as described above; out.normal, child_a and child_b are left as
/// they are. `normal` is the unit manifold normal (any frame, the one of the points).
/// n <= 4 copies the points unchanged in order; n <= 0 gives count 0.
inline void reduce_to_4(const ContactPoint* pts, int n, const Vec3& normal, Manifold& out) {
  if (n <= kMaxManifoldPoints) {
    out.count = n > 0 ? n : 0;
    for (int i = 0; i < out.count; ++i) out.points[i] = pts[i];
    return;
  }
  // 1. Deepest point.
  int i0 = 0;
  for (int i = 1; i < n; ++i)
    if (pts[i].depth > pts[i0].depth) i0 = i;
  const Vec3 p0 = pts[i0].point_a;

  // 2. Furthest from p0 in the contact plane.
  int i1 = -1;
  Real best = -1;
  for (int i = 0; i < n; ++i) {
    if (i == i0) continue;
    Vec3 d = pts[i].point_a - p0;
    d -= d.dot(normal) * normal;
    const Real d2 = d.squaredNorm();
    if (d2 > best) {
      best = d2;
      i1 = i;
    }
  }
  const Vec3 p1 = pts[i1].point_a;
  const Vec3 e01 = p1 - p0;

  // 3. Largest |signed area| of triangle (p0, p1, p), measured along the normal.
  int i2 = -1;
  Real best_area = -1;
  Real sign = 1;
  for (int i = 0; i < n; ++i) {
    if (i == i0 || i == i1) continue;
    const Real a = e01.cross(pts[i].point_a - p0).dot(normal);
    if (std::abs(a) > best_area) {
      best_area = std::abs(a);
      i2 = i;
      sign = a < 0 ? Real(-1) : Real(1);
    }
  }
  // All points on the line p0-p1 (within 1e-9 of its length, round-off for any
  // sensible contact patch): the third point would add no torque arm, keep the two.
  if (best_area <= 1e-9 * e01.squaredNorm()) {
    out.points[0] = pts[i0];
    out.points[1] = pts[i1];
    out.count = 2;
    return;
  }
  const Vec3 p2 = pts[i2].point_a;

  // 4. The point most outside one edge of the triangle: with the triangle oriented
  // positively (sign), a point beyond edge (u, v) has a negative signed area for
  // (u, v, p); the most negative one enlarges the quad the most.
  int i3 = -1;
  Real most_outside = 0;
  const Vec3* tri[3] = {&p0, &p1, &p2};
  for (int i = 0; i < n; ++i) {
    if (i == i0 || i == i1 || i == i2) continue;
    const Vec3& p = pts[i].point_a;
    for (int e = 0; e < 3; ++e) {
      const Vec3& u = *tri[e];
      const Vec3& v = *tri[(e + 1) % 3];
      const Real a = sign * (v - u).cross(p - u).dot(normal);
      if (a < most_outside) {
        most_outside = a;
        i3 = i;
      }
    }
  }

  out.points[0] = pts[i0];
  out.points[1] = pts[i1];
  out.points[2] = pts[i2];
  out.count = 3;
  if (i3 >= 0) out.points[out.count++] = pts[i3];
}

}  // namespace wmo
