// Soft-step contact solver (see contact_solver.h; Catto 2024 "Solver2D", Box2D v3).
#include "wmo/dynamics/contact_solver.h"

#include <algorithm>
#include <bit>
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
  s.a2 = a2;
  s.h_omega2 = h * omega * omega;
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
  const Real fixed_hertz = std::min(s.static_hertz_scale * hertz, cap);
  soft.fixed = make_softness(fixed_hertz, s.damping_ratio, h);
  if (hertz > 0) soft.dynamic.max_stiffening = (cap / hertz) * (cap / hertz);
  if (fixed_hertz > 0) soft.fixed.max_stiffening = (cap / fixed_hertz) * (cap / fixed_hertz);
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
    Real mass = 0;
    for (int i = 0; i < c.count; ++i) mass += c.points[i].normal_mass;
    const Softness& row_soft = a.inv_mass == 0 || b.inv_mass == 0 ? soft.fixed : soft.dynamic;
    const Real stiff = stiffening(row_soft, s.max_sag, mass, c.load * h);
    for (int i = 0; i < c.count; ++i) c.points[i].stiffening = stiff;
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

namespace {

constexpr int kMaxPoints = std::tuple_size_v<decltype(ContactConstraint{}.points)>;

/// What a normal row aims at, for separation s: a speculative gap (s > 0) may close
/// within the substep (bias s / h, a rigid row); an overlap gets the soft bias and the
/// spring's mass and impulse scales when use_bias, else none (a rigid relax row).
struct RowTarget {
  Real bias = 0, mass_scale = 1, impulse_scale = 0;
};
/// The soft bias of an overlap s <= 0 (m/s): the spring's, and past the constraint's
/// allowance the excess within the substep (ContactConstraint::allow), under push_max.
inline Real soft_bias(const Softness& soft, Real s, Real inv_h, Real push_max, Real allow) {
  return std::max(std::min(soft.bias_rate * s, (s + allow) * inv_h), -push_max);
}

inline RowTarget row_target(const Softness& soft, Real s, Real inv_h, Real push_max, bool use_bias,
                            Real stiff, Real allow) {
  RowTarget t;
  if (s > 0) {
    t.bias = s * inv_h;
  } else if (use_bias) {
    t.bias = soft_bias(soft, s, inv_h, push_max, allow);
    t.mass_scale = soft.mass_scale;
    t.impulse_scale = soft.impulse_scale;
    if (stiff > 1) {  // stiffening(): the spring's a2 times stiff
      const Real a = stiff * soft.a2;
      t.impulse_scale = 1 / (1 + a);
      t.mass_scale = a * t.impulse_scale;
    }
  }
  return t;
}

/// Records a normal row's impulse on p for apply_restitution. The approach speed that
/// restitution reverses is the one at the substep where the point first pushes (the
/// impact), not at the step's start, which misses up to a step of gravity (measured:
/// 8.7% low on e^2 h at dt 1/60, 1.9% per substep); s is the separation then.
inline void record_push(ContactConstraintPoint& p, Real impulse, Real vn, Real s) {
  if (impulse > 0 && p.max_normal_impulse == 0) {
    p.relative_velocity = vn;
    p.push_gap = std::max(s, Real(0));
  }
  p.max_normal_impulse = std::max(p.max_normal_impulse, impulse);
}

/// Rigid rows (relax passes, speculative points) get this much regularisation,
/// gamma = kBlockRegularisation K_ii (see solve_normal_block): the K of a face
/// manifold's four coplanar points has rank 3 (a pair of rigid bodies has three normal
/// degrees of freedom, a push and two tilts), so its rigid system has a line of
/// solutions; 1e-6 picks the one nearest the minimum-norm impulses and moves the
/// velocities it reaches by 1e-6 relative, far below the passes' convergence.
/// (Measured, stiff 30-box tower, unkicked: 1e-9, 1e-6 and 1e-3 all bring it to rest.)
constexpr Real kBlockRegularisation = 1e-6;

/// w_i >= -kBlockSlack (|rhs_i| + 1e-12 m/s) counts as w_i >= 0 when an active set is
/// checked: the round-off of the elimination, a few DBL_EPSILON of the terms.
constexpr Real kBlockSlack = 1e-9;

/// Solves A x = r for the m x m system in `a` (rows of A with r as column m) by Gaussian
/// elimination with partial pivoting; false when a pivot is below 1e-12 of `scale`
/// (singular for the purpose).
bool solve_small(Real (&a)[kMaxPoints][kMaxPoints + 1], int m, Real scale, Real* x) {
  for (int col = 0; col < m; ++col) {
    int piv = col;
    for (int r = col + 1; r < m; ++r)
      if (std::abs(a[r][col]) > std::abs(a[piv][col])) piv = r;
    if (!(std::abs(a[piv][col]) > 1e-12 * scale)) return false;
    if (piv != col)
      for (int q = 0; q <= m; ++q) std::swap(a[col][q], a[piv][q]);
    for (int r = col + 1; r < m; ++r) {
      const Real f = a[r][col] / a[col][col];
      for (int q = col; q <= m; ++q) a[r][q] -= f * a[col][q];
    }
  }
  for (int r = m - 1; r >= 0; --r) {
    Real v = a[r][m];
    for (int q = r + 1; q < m; ++q) v -= a[r][q] * x[q];
    x[r] = v / a[r][r];
  }
  return true;
}

/// The normal rows of constraint c all at once (NormalRows::kBlock). Each row alone is
/// Box2D's soft row: (K_ii + g_i) dl_i = -(vn_i + bias_i + g_i l_i), with g_i =
/// K_ii (1 / mass_scale - 1) the spring's regularisation (mass_scale = 1 / (1 + g / K),
/// impulse_scale = 1 - mass_scale); with every row's effect on the others (K_ij, the
/// velocity change at point i per unit impulse at j) it becomes, for the new impulses
/// x = l + dl,
///     (K + G) x = K l - (vn + bias),   x >= 0,   w = (K + G) x - K l + vn + bias >= 0,
///     x . w = 0,
/// a linear complementarity problem with a symmetric positive definite matrix (G > 0:
/// rigid rows get kBlockRegularisation), so it has exactly one solution. With at most
/// four points it is found by enumeration (Murty): the active sets from all points down,
/// the first whose x >= 0 and whose inactive points separate (w >= 0). Returns false,
/// with nothing applied, if none passes (round-off on a degenerate manifold); the
/// sequential rows then run.
bool solve_normal_block(ContactConstraint& c, BodyState& a, BodyState& b, const Softness& soft, Real inv_h,
                        Real push_max, bool use_bias, const std::array<Vec3, kMaxPoints>& ra,
                        const std::array<Vec3, kMaxPoints>& rb) {
  const int m = c.count;
  const Vec3& n = c.normal;
  Real K[kMaxPoints][kMaxPoints], gam[kMaxPoints], rhs[kMaxPoints], sep[kMaxPoints], vn[kMaxPoints];
  Vec3 ia[kMaxPoints], ib[kMaxPoints], ca[kMaxPoints], cb[kMaxPoints];
  for (int i = 0; i < m; ++i) {
    ca[i] = ra[i].cross(n);
    cb[i] = rb[i].cross(n);
    ia[i] = a.inv_inertia * ca[i];
    ib[i] = b.inv_inertia * cb[i];
  }
  for (int i = 0; i < m; ++i)
    for (int j = i; j < m; ++j) K[i][j] = K[j][i] = a.inv_mass + b.inv_mass + ca[i].dot(ia[j]) + cb[i].dot(ib[j]);
  for (int i = 0; i < m; ++i) {
    const ContactConstraintPoint& p = c.points[i];
    if (!(K[i][i] > 0)) return false;  // a point that moves nothing: leave it to the rows
    sep[i] = separation_now(a, b, p, n, ra[i], rb[i]);
    const RowTarget t = row_target(soft, sep[i], inv_h, push_max, use_bias, p.stiffening, c.allow);
    gam[i] = std::max(K[i][i] * (1 / t.mass_scale - 1), kBlockRegularisation * K[i][i]);
    vn[i] = n.dot(relative_velocity(a, b, ra[i], rb[i]));
    Real kl = 0;
    for (int j = 0; j < m; ++j) kl += K[i][j] * c.points[j].normal_impulse;
    rhs[i] = kl - (vn[i] + t.bias);
  }
  Real x[kMaxPoints] = {};
  bool found = false;
  for (int size = m; size >= 1 && !found; --size) {
    for (int mask = (1 << m) - 1; mask > 0 && !found; --mask) {
      if (std::popcount(static_cast<unsigned>(mask)) != size) continue;
      int idx[kMaxPoints], k = 0;
      for (int i = 0; i < m; ++i)
        if (mask >> i & 1) idx[k++] = i;
      Real sys[kMaxPoints][kMaxPoints + 1];
      for (int r = 0; r < k; ++r) {
        for (int q = 0; q < k; ++q) sys[r][q] = K[idx[r]][idx[q]] + (r == q ? gam[idx[r]] : 0);
        sys[r][k] = rhs[idx[r]];
      }
      Real xs[kMaxPoints];
      if (!solve_small(sys, k, K[idx[0]][idx[0]], xs)) continue;
      Real trial[kMaxPoints] = {};
      bool ok = true;
      for (int r = 0; r < k; ++r) {
        ok = ok && xs[r] >= 0;
        trial[idx[r]] = xs[r];
      }
      for (int i = 0; i < m && ok; ++i) {
        if (mask >> i & 1) continue;
        Real w = -rhs[i];
        for (int j = 0; j < m; ++j) w += K[i][j] * trial[j];
        ok = w >= -kBlockSlack * (std::abs(rhs[i]) + 1e-12);
      }
      if (!ok) continue;
      std::copy(trial, trial + m, x);
      found = true;
    }
  }
  if (!found) {
    // No point pushes (every row separates at zero impulse): the empty set.
    bool all_separate = true;
    for (int i = 0; i < m; ++i) all_separate = all_separate && -rhs[i] >= -kBlockSlack * (std::abs(rhs[i]) + 1e-12);
    if (!all_separate) return false;
  }
  for (int i = 0; i < m; ++i) {
    ContactConstraintPoint& p = c.points[i];
    const Real impulse = x[i] - p.normal_impulse;
    p.normal_impulse = x[i];
    record_push(p, impulse, vn[i], sep[i]);
    apply(a, b, ra[i], rb[i], impulse * n);
  }
  return true;
}

/// The centroid row of constraint c (two or more points), before its point rows: one
/// impulse increment d, the same at every point, that meets the rows' targets on
/// average; the point rows then correct the rest.
///
/// Why: a Gauss-Seidel pass over a manifold's points alone gives the first point the
/// whole correction and its diagonal opposite the reaction (measured, a box on a box
/// after one step: 1.9x the first point's impulse at the third), a torque that the
/// passes' fixed order repeats every substep; it rocks a stack (a 20-box tower at the
/// defaults falls by step ~1000 without being touched; with the centroid row it stays
/// on its axis). The centroid row is symmetric in the points. It does not make the
/// springs stiffer: a tower above Greenhill's critical height is then an unstable
/// equilibrium, and a kick topples it as it does without the row (test_stability.py).
///
/// With K the rows' coupling (K_ij: normal velocity at i per unit impulse at j) and
/// g_i = K_ii (1 / mass_scale_i - 1) = K_ii / (stiffening_i a2) each soft row's
/// regularisation (0 for a rigid row), the sum of the rows' equations
/// K (d 1) + g d = -(vn + bias + g l) over the points gives
///     d = -(sum vn + sum bias + sum g l) / (sum_ij K_ij + sum g),
/// where sum vn is count times vn at the centroid of the anchors and sum_ij K_ij count^2
/// times K there (both are linear in the anchors). d is applied as count d at the
/// centroid, which is d at every point. Only where every point overlaps or touches (s
/// <= 0: a speculative point must not push); d keeps every accumulated impulse >= 0.
/// WideContacts::solve computes the same lane by lane (from the anchors' centroid and
/// masses of its last set_motion).
void centroid_row(ContactConstraint& c, BodyState& a, BodyState& b, const Softness& soft, Real inv_h, Real push_max,
                  bool use_bias, const std::array<Vec3, kMaxPoints>& ra, const std::array<Vec3, kMaxPoints>& rb) {
  const Vec3& n = c.normal;
  const int m = c.count;
  Real sum_bias = 0, sum_gl = 0, sum_g = 0, min_l = kInf;
  Vec3 ca = Vec3::Zero(), cb = Vec3::Zero();
  for (int i = 0; i < m; ++i) {
    const ContactConstraintPoint& p = c.points[i];
    const Real s = separation_now(a, b, p, n, ra[i], rb[i]);
    if (s > 0) return;
    const Real mass = row_mass(p.normal_mass, effective_mass(a, b, ra[i], rb[i], n), turn_sin2(a, b));
    const Real kii = mass > 0 ? 1 / mass : 0;
    const Real a_soft = p.stiffening * soft.a2;
    const Real g = use_bias && a_soft > 0 ? kii / a_soft : 0;
    if (use_bias) sum_bias += soft_bias(soft, s, inv_h, push_max, c.allow);
    sum_gl += g * p.normal_impulse;
    sum_g += g;
    min_l = std::min(min_l, p.normal_impulse);
    ca += ra[i];
    cb += rb[i];
  }
  ca /= m;
  cb /= m;
  const Real cm = effective_mass(a, b, ca, cb, n);
  const Real denom = m * m * (cm > 0 ? 1 / cm : 0) + sum_g;
  if (!(denom > 0)) return;
  const Real vnc = n.dot(relative_velocity(a, b, ca, cb));
  const Real d = std::max(-(m * vnc + sum_bias + sum_gl) / denom, -min_l);
  for (int i = 0; i < m; ++i) {
    ContactConstraintPoint& p = c.points[i];
    p.normal_impulse += d;
    if (d > 0 && p.max_normal_impulse == 0) {  // record_push(), the centroid's approach for all
      p.relative_velocity = vnc;
      p.push_gap = 0;
    }
    p.max_normal_impulse = std::max(p.max_normal_impulse, d);
  }
  apply(a, b, ca, cb, (m * d) * n);
}

}  // namespace

void solve_contacts(std::vector<ContactConstraint>& cs, std::vector<BodyState>& states,
                    const ContactSoftness& softness, Real inv_h, Real push_max, bool use_bias,
                    NormalRows normal_rows, bool reverse, bool centroid_rows) {
  const std::size_t count = cs.size();
  for (std::size_t k = 0; k < count; ++k) {
    ContactConstraint& c = cs[reverse ? count - 1 - k : k];
    BodyState& a = states[c.body_a];
    BodyState& b = states[c.body_b];
    const Vec3& n = c.normal;
    const Softness& soft = a.inv_mass == 0 || b.inv_mass == 0 ? softness.fixed : softness.dynamic;
    std::array<Vec3, kMaxPoints> anchor_a, anchor_b;  // current anchors, for the friction rows too
    // Current anchors (turned with the bodies, see current_anchors).
    for (int i = 0; i < c.count; ++i) current_anchors(a, b, c.points[i], n, anchor_a[i], anchor_b[i]);
    bool block_done = false;
    if (normal_rows == NormalRows::kBlock && c.count >= 2)
      block_done = solve_normal_block(c, a, b, soft, inv_h, push_max, use_bias, anchor_a, anchor_b);
    if (!block_done && centroid_rows && c.count >= 2)
      centroid_row(c, a, b, soft, inv_h, push_max, use_bias, anchor_a, anchor_b);
    for (int ii = 0; ii < c.count && !block_done; ++ii) {
      // A backward pass visits the points backward too (symmetric Gauss-Seidel within
      // the manifold as across the constraints).
      const int i = reverse ? c.count - 1 - ii : ii;
      ContactConstraintPoint& p = c.points[i];
      // Current separation from the bodies' motion since the step began, at the current
      // anchors.
      const Vec3& ra = anchor_a[i];
      const Vec3& rb = anchor_b[i];
      const Real s = separation_now(a, b, p, n, ra, rb);
      const Real normal_mass = row_mass(p.normal_mass, effective_mass(a, b, ra, rb, n), turn_sin2(a, b));
      const RowTarget t = row_target(soft, s, inv_h, push_max, use_bias, p.stiffening, c.allow);
      const Real vn = n.dot(relative_velocity(a, b, ra, rb));
      Real impulse = -normal_mass * t.mass_scale * (vn + t.bias) - t.impulse_scale * p.normal_impulse;
      const Real next = std::max(p.normal_impulse + impulse, Real(0));
      impulse = next - p.normal_impulse;
      p.normal_impulse = next;
      record_push(p, impulse, vn, s);
      apply(a, b, ra, rb, impulse * n);
    }
    if (c.friction == 0) continue;
    const Real turn = turn_sin2(a, b);
    const bool turned = turn > kRowMassTurnSin2;
    for (int ii = 0; ii < c.count; ++ii) {
      const int i = reverse ? c.count - 1 - ii : ii;  // backward in a backward pass
      ContactConstraintPoint& p = c.points[i];
      const Vec3& ra = anchor_a[i];
      const Vec3& rb = anchor_b[i];
      const Vec3 dv = relative_velocity(a, b, ra, rb);
      if (turned) {  // the tangent masses follow the turned anchors and inertia (row_mass)
        p.tangent_mass[0] = row_mass(p.tangent_mass[0], effective_mass(a, b, ra, rb, c.tangent1), turn);
        p.tangent_mass[1] = row_mass(p.tangent_mass[1], effective_mass(a, b, ra, rb, c.tangent2), turn);
      }
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
