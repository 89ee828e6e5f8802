// Soft-step contact solver (see contact_solver.h; Catto 2024 "Solver2D", Box2D v3).
#include "wmo/dynamics/contact_solver.h"

#include <algorithm>
#include <cmath>

namespace wmo {

Softness make_softness(Real hertz, Real damping_ratio, Real h) {
  Softness s;
  if (hertz <= 0) return s;  // rigid: no bias, full mass, no impulse decay
  const Real omega = 2 * kPi * hertz;
  const Real a1 = 2 * damping_ratio + h * omega;
  const Real a2 = h * omega * a1;
  const Real a3 = 1 / (1 + a2);
  s.bias_rate = omega / a1;
  s.mass_scale = a2 * a3;
  s.impulse_scale = a3;
  return s;
}

namespace {

inline Real effective_mass(const BodyState& a, const BodyState& b, const Vec3& ra, const Vec3& rb,
                           const Vec3& dir) {
  const Vec3 ca = ra.cross(dir), cb = rb.cross(dir);
  const Real k = a.inv_mass + b.inv_mass + ca.dot(a.inv_inertia * ca) + cb.dot(b.inv_inertia * cb);
  return k > 0 ? 1 / k : 0;
}

inline void apply(BodyState& a, BodyState& b, const Vec3& ra, const Vec3& rb, const Vec3& p) {
  a.v -= a.inv_mass * p;
  a.w -= a.inv_inertia * ra.cross(p);
  b.v += b.inv_mass * p;
  b.w += b.inv_inertia * rb.cross(p);
}

/// The larger sin^2 of half the angle the two bodies turned since the step began.
inline Real turn_sin2(const BodyState& a, const BodyState& b) {
  return std::max(a.dq.vec().squaredNorm(), b.dq.vec().squaredNorm());
}

inline Vec3 relative_velocity(const BodyState& a, const BodyState& b, const Vec3& ra, const Vec3& rb) {
  return (b.v + b.w.cross(rb)) - (a.v + a.w.cross(ra));
}

}  // namespace

void current_anchors(const BodyState& a, const BodyState& b, const ContactConstraintPoint& p, const Vec3& n,
                     Vec3& ra, Vec3& rb) {
  const Vec3 ca = p.ra + p.ca_n * n, cb = p.rb + p.cb_n * n;
  ra = p.ra + (a.dq * ca - ca);
  rb = p.rb + (b.dq * cb - cb);
}

ContactSoftness contact_softness(const SolverSettings& s, Real h) {
  ContactSoftness soft;
  // Stiffer than a quarter of the substep rate and the spring is under-resolved by the
  // integrator (Box2D v3 caps contact_hertz the same way).
  const Real cap = 0.25 / h;
  const Real hertz = std::min(s.contact_hertz, cap);
  soft.dynamic = make_softness(hertz, s.damping_ratio, h);
  // The same cap (Box2D v3 lets the static spring reach twice it, half the substep
  // rate: measured, a 100 kg box on a 1 kg one on the ground at 60 Hz and 4 substeps
  // then pumps the light box out, 38 cm in 100 s; capped, it stands).
  soft.fixed = make_softness(std::min(s.static_hertz_scale * hertz, cap), s.damping_ratio, h);
  return soft;
}

void prepare_contacts(std::vector<ContactConstraint>& cs, const std::vector<BodyState>& states,
                      const SolverSettings& s, Real h, ContactSoftness& soft) {
  soft = contact_softness(s, h);
  for (ContactConstraint& c : cs) {
    const BodyState& a = states[c.body_a];
    const BodyState& b = states[c.body_b];
    for (int i = 0; i < c.count; ++i) {
      ContactConstraintPoint& p = c.points[i];
      p.normal_mass = effective_mass(a, b, p.ra, p.rb, c.normal);
      p.tangent_mass[0] = effective_mass(a, b, p.ra, p.rb, c.tangent1);
      p.tangent_mass[1] = effective_mass(a, b, p.ra, p.rb, c.tangent2);
      p.relative_velocity = c.normal.dot(relative_velocity(a, b, p.ra, p.rb));
      p.max_normal_impulse = 0;
    }
  }
}

void warm_start_contacts(std::vector<ContactConstraint>& cs, std::vector<BodyState>& states) {
  for (ContactConstraint& c : cs) {
    BodyState& a = states[c.body_a];
    BodyState& b = states[c.body_b];
    for (int i = 0; i < c.count; ++i) {
      const ContactConstraintPoint& p = c.points[i];
      const Vec3 imp = p.normal_impulse * c.normal + p.tangent_impulse[0] * c.tangent1 +
                       p.tangent_impulse[1] * c.tangent2;
      Vec3 ra, rb;
      current_anchors(a, b, p, c.normal, ra, rb);
      apply(a, b, ra, rb, imp);
    }
  }
}

void solve_contacts(std::vector<ContactConstraint>& cs, std::vector<BodyState>& states,
                    const ContactSoftness& softness, Real inv_h, Real push_max, bool use_bias) {
  for (ContactConstraint& c : cs) {
    BodyState& a = states[c.body_a];
    BodyState& b = states[c.body_b];
    const Vec3& n = c.normal;
    const Softness& soft = a.inv_mass == 0 || b.inv_mass == 0 ? softness.fixed : softness.dynamic;
    std::array<Vec3, std::tuple_size_v<decltype(c.points)>> anchor_a, anchor_b;  // current anchors, for the friction rows too
    for (int i = 0; i < c.count; ++i) {
      ContactConstraintPoint& p = c.points[i];
      // Current separation from the bodies' motion since the step began, at the current
      // anchors (turned with the bodies, see current_anchors).
      Vec3& ra = anchor_a[i];
      Vec3& rb = anchor_b[i];
      current_anchors(a, b, p, c.normal, ra, rb);
      const Vec3 d = (b.dp + rb) - (a.dp + ra);
      const Real s = n.dot(d) + p.adjusted_separation;
      const Real normal_mass = row_mass(p.normal_mass, effective_mass(a, b, ra, rb, n), turn_sin2(a, b));
      Real bias = 0, mass_scale = 1, impulse_scale = 0;
      if (s > 0) {
        bias = s * inv_h;  // speculative: allow the gap to close within this substep
      } else if (use_bias) {
        bias = std::max(soft.bias_rate * s, -push_max);
        mass_scale = soft.mass_scale;
        impulse_scale = soft.impulse_scale;
      }
      const Real vn = n.dot(relative_velocity(a, b, ra, rb));
      Real impulse = -normal_mass * mass_scale * (vn + bias) - impulse_scale * p.normal_impulse;
      const Real next = std::max(p.normal_impulse + impulse, Real(0));
      impulse = next - p.normal_impulse;
      p.normal_impulse = next;
      // The approach speed that restitution reverses: the one at the substep where the
      // point first pushes (the impact), not at the step's start, which misses up to
      // a step of gravity (measured: 8.7% low on e^2 h at dt 1/60, 1.9% per substep).
      if (impulse > 0 && p.max_normal_impulse == 0) {
        p.relative_velocity = vn;
        p.push_gap = std::max(s, Real(0));
      }
      p.max_normal_impulse = std::max(p.max_normal_impulse, impulse);
      apply(a, b, ra, rb, impulse * n);
    }
    if (c.friction == 0) continue;
    for (int i = 0; i < c.count; ++i) {
      ContactConstraintPoint& p = c.points[i];
      const Vec3& ra = anchor_a[i];
      const Vec3& rb = anchor_b[i];
      const Vec3 dv = relative_velocity(a, b, ra, rb);
      Real t0 = p.tangent_impulse[0] - p.tangent_mass[0] * c.tangent1.dot(dv);
      Real t1 = p.tangent_impulse[1] - p.tangent_mass[1] * c.tangent2.dot(dv);
      // Coulomb cone: scale the tangential impulse back onto the circle of radius mu * lambda_n.
      const Real limit = c.friction * p.normal_impulse;
      const Real len2 = t0 * t0 + t1 * t1;
      if (len2 > limit * limit) {
        const Real k = len2 > 0 ? limit / std::sqrt(len2) : 0;
        t0 *= k;
        t1 *= k;
      }
      const Real d0 = t0 - p.tangent_impulse[0], d1 = t1 - p.tangent_impulse[1];
      p.tangent_impulse = {t0, t1};
      apply(a, b, ra, rb, d0 * c.tangent1 + d1 * c.tangent2);
    }
  }
}

void apply_restitution(std::vector<ContactConstraint>& cs, std::vector<BodyState>& states,
                       Real threshold) {
  for (ContactConstraint& c : cs) {
    if (c.restitution == 0) continue;
    BodyState& a = states[c.body_a];
    BodyState& b = states[c.body_b];
    for (int i = 0; i < c.count; ++i) {
      ContactConstraintPoint& p = c.points[i];
      // Only points that approached fast enough and actually pushed bounce.
      if (p.relative_velocity > -threshold || p.max_normal_impulse == 0) continue;
      // Relative acceleration of B towards A along n (negative when gravity closes the gap).
      const Real gn = c.normal.dot(b.gravity - a.gravity);
      Real approach = p.relative_velocity;
      if (gn < 0 && p.push_gap > 0) approach = -std::sqrt(approach * approach - 2 * gn * p.push_gap);
      Vec3 ra, rb;
      current_anchors(a, b, p, c.normal, ra, rb);
      const Vec3& n = c.normal;
      const Real vn = n.dot(relative_velocity(a, b, ra, rb));
      Real impulse =
          -row_mass(p.normal_mass, effective_mass(a, b, ra, rb, n), turn_sin2(a, b)) * (vn + c.restitution * approach);
      const Real next = std::max(p.normal_impulse + impulse, Real(0));
      impulse = next - p.normal_impulse;
      p.normal_impulse = next;
      p.max_normal_impulse = std::max(p.max_normal_impulse, impulse);
      apply(a, b, ra, rb, impulse * n);
    }
  }
}

}  // namespace wmo
