// The lane-grouped contact passes (WideContacts) against the scalar reference passes
// (warm_start_contacts / solve_contacts) on random contact graphs: the grouping only
// reorders constraints that share no dynamic body, so both must give the same
// velocities and impulses up to rounding (the lanes compute in float, the reference in
// double), whatever the order of the constraints.
#include <gtest/gtest.h>

#include <algorithm>
#include <random>
#include <vector>

#include "wmo/dynamics/contact_solver.h"

using namespace wmo;

namespace {

struct Scene {
  std::vector<BodyState> states;
  std::vector<ContactConstraint> constraints;
};

/// `bodies` bodies (the first `statics` static: zero mass), `count` constraints between
/// random pairs with 1-4 points, random anchors, normals, impulses and velocities.
Scene random_scene(int bodies, int statics, int count, std::uint64_t seed) {
  std::mt19937_64 rng(seed);
  std::uniform_real_distribution<Real> u(-1, 1);
  auto vec = [&] { return Vec3(u(rng), u(rng), u(rng)); };
  Scene s;
  s.states.resize(bodies + 1);  // + the padding state
  for (int i = 0; i < bodies; ++i) {
    BodyState& b = s.states[i];
    if (i < statics) continue;  // static: zero velocity, mass and inertia
    b.v = vec();
    b.w = vec();
    b.dp = 0.01 * vec();
    // Mostly small turns; every fifth body turned far (up to ~1 rad), where the rows
    // use the effective mass at the turned anchors (row_mass).
    const Real turn = i % 5 == 0 ? 0.5 : 0.01;
    b.dq = Quat(1, turn * u(rng), turn * u(rng), turn * u(rng)).normalized();
    b.inv_mass = 0.5 + 0.5 * (u(rng) + 1);
    const Mat3 r = Quat(vec().normalized().x(), u(rng), u(rng), u(rng)).normalized().toRotationMatrix();
    b.inv_inertia = r * Vec3(1 + u(rng) * 0.5, 2 + u(rng), 3 + u(rng)).asDiagonal() * r.transpose();
  }
  std::uniform_int_distribution<int> pick(0, bodies - 1), points(1, 4);
  for (int k = 0; k < count; ++k) {
    ContactConstraint c;
    do {
      c.body_a = pick(rng);
      c.body_b = pick(rng);
    } while (c.body_a == c.body_b || (c.body_a < statics && c.body_b < statics));
    c.normal = vec().normalized();
    orthonormal_basis(c.normal, c.tangent1, c.tangent2);
    c.friction = k % 5 == 0 ? 0 : 0.6;  // some frictionless
    c.count = points(rng);
    for (int j = 0; j < c.count; ++j) {
      ContactConstraintPoint& p = c.points[j];
      p.ra = vec();
      p.rb = vec();
      // Centres of curvature, on the normal through the anchor (as World puts them):
      // the anchors turn with the bodies' dq about them.
      p.ca_n = -0.5 * (u(rng) + 1);
      p.cb_n = 0.5 * (u(rng) + 1);
      p.adjusted_separation = 0.02 * u(rng);  // some speculative, some penetrating
      p.normal_impulse = k % 3 == 0 ? 0 : 0.1 * (u(rng) + 1);
      p.tangent_impulse = {0.02 * u(rng), 0.02 * u(rng)};
    }
    s.constraints.push_back(c);
  }
  return s;
}

void run_passes(Scene& s, bool wide, int substeps, bool level_order = false) {
  SolverSettings settings;
  ContactSoftness soft;
  const Real h = 1.0 / 240;
  prepare_contacts(s.constraints, s.states, settings, h, soft);
  WideContacts w;
  const int dummy = static_cast<int>(s.states.size()) - 1;
  std::vector<int> order(s.constraints.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  std::vector<int> scratch;
  if (level_order) dependency_level_order(s.constraints, s.states, order, scratch);
  if (wide) w.build(s.constraints, order, s.states, dummy);
  for (int sub = 0; sub < substeps; ++sub) {
    if (wide) {
      w.warm_start(s.states);
      w.solve(s.states, soft, 1 / h, settings.push_max, true);
      w.solve(s.states, soft, 1 / h, settings.push_max, false);
    } else {
      warm_start_contacts(s.constraints, s.states);
      solve_contacts(s.constraints, s.states, soft, 1 / h, settings.push_max, true);
      solve_contacts(s.constraints, s.states, soft, 1 / h, settings.push_max, false);
    }
  }
  if (wide) w.unpack(s.constraints);
}

/// Largest difference between the two scenes' velocities and (unless `velocities_only`)
/// point impulses.
Real max_difference(const Scene& a, const Scene& b, bool velocities_only = false) {
  Real d = 0;
  for (std::size_t i = 0; i + 1 < a.states.size(); ++i) {
    d = std::max(d, (a.states[i].v - b.states[i].v).norm());
    d = std::max(d, (a.states[i].w - b.states[i].w).norm());
  }
  if (velocities_only) return d;
  for (std::size_t k = 0; k < a.constraints.size(); ++k)
    for (int j = 0; j < a.constraints[k].count; ++j) {
      const ContactConstraintPoint& p = a.constraints[k].points[j];
      const ContactConstraintPoint& q = b.constraints[k].points[j];
      for (const Real x : {p.normal_impulse - q.normal_impulse, p.tangent_impulse[0] - q.tangent_impulse[0],
                           p.tangent_impulse[1] - q.tangent_impulse[1], p.max_normal_impulse - q.max_normal_impulse,
                           p.relative_velocity - q.relative_velocity, p.push_gap - q.push_gap})
        d = std::max(d, std::abs(x));
    }
  return d;
}

/// The float lanes against the double reference. Velocities and impulses of O(1) after
/// four substeps of three passes over up to 500 constraints: each lane operation rounds
/// by up to 6e-8 (float's half ulp) and a body's velocity goes through a few hundred of
/// them, measured 1e-6 at most; 2e-5 leaves room and still catches any row solved in a
/// different (non-commuting) order, which changes results at O(1e-2) (the last test).
constexpr Real kFloatTolerance = 2e-5;

void expect_same(const Scene& a, const Scene& b) { EXPECT_LT(max_difference(a, b), kFloatTolerance); }

}  // namespace

TEST(WideContacts, MatchesTheScalarPassesOnRandomGraphs) {
  // Dense graphs (many shared bodies: short groups) and sparse ones (full groups).
  for (const auto [bodies, count] : {std::pair{12, 60}, std::pair{400, 300}, std::pair{60, 500}}) {
    Scene scalar = random_scene(bodies, 2, count, 7 + bodies);
    Scene wide = scalar;
    run_passes(scalar, false, 4);
    run_passes(wide, true, 4);
    expect_same(scalar, wide);
  }
}

TEST(WideContacts, DependencyLevelOrderComputesWhatTheSequenceComputes) {
  // The world's order: the scalar passes in the given sequence against the wide passes
  // in dependency-level order, which fills the groups.
  for (const auto [bodies, count] : {std::pair{12, 60}, std::pair{400, 300}, std::pair{60, 500}}) {
    Scene scalar = random_scene(bodies, 2, count, 23 + bodies);
    Scene wide = scalar;
    run_passes(scalar, false, 4);
    run_passes(wide, true, 4, /*level_order=*/true);
    expect_same(scalar, wide);
    // Every index once.
    std::vector<int> order, scratch;
    dependency_level_order(scalar.constraints, scalar.states, order, scratch);
    std::sort(order.begin(), order.end());
    for (int k = 0; k < count; ++k) ASSERT_EQ(order[k], k);
  }
}

TEST(WideContacts, GroupsNeverShareADynamicBody) {
  Scene s = random_scene(50, 3, 400, 11);
  WideContacts w;
  const int dummy = static_cast<int>(s.states.size()) - 1;
  std::vector<int> order(s.constraints.size());
  for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
  w.build(s.constraints, order, s.states, dummy);
  int lanes_used = 0;
  for (const WideContacts::Group& g : w.groups()) {
    std::vector<int> dynamic;
    for (int l = 0; l < WideContacts::kLanes; ++l)
      for (const int body : {g.body_a[l], g.body_b[l]}) {
        if (body == dummy) continue;
        if (s.states[body].inv_mass > 0) dynamic.push_back(body);
      }
    for (int l = 0; l < WideContacts::kLanes; ++l) lanes_used += g.body_a[l] != dummy;
    std::sort(dynamic.begin(), dynamic.end());
    EXPECT_EQ(std::adjacent_find(dynamic.begin(), dynamic.end()), dynamic.end());
  }
  EXPECT_EQ(lanes_used, 400);  // every constraint in exactly one lane
  // Consecutive random constraints among 50 bodies rarely conflict: most groups fill.
  EXPECT_LT(w.group_count(), 200);
}

TEST(WideContacts, AReorderingThatBreaksTheSequenceChangesTheResult) {
  // The check above can fail: solving the same constraints in another order, one
  // that swaps constraints sharing a body, gives different impulses.
  Scene a = random_scene(12, 2, 60, 19);
  Scene b = a;
  std::reverse(b.constraints.begin(), b.constraints.end());
  run_passes(a, true, 1);
  run_passes(b, true, 1);
  // Velocities only: b's constraints are a's in reverse, so their impulses do not pair up.
  const Real diff = max_difference(a, b, /*velocities_only=*/true);
  EXPECT_GT(diff, 100 * kFloatTolerance) << diff;
}
