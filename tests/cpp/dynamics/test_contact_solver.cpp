// The lane-grouped contact passes (WideContacts) against the scalar reference passes
// (warm_start_contacts / solve_contacts) on random contact graphs: the grouping only
// reorders constraints that share no dynamic body, so both must give the same
// velocities and impulses up to rounding (the lanes compute in float, the reference in
// double), whatever the order of the constraints.
#include <gtest/gtest.h>

#include <algorithm>
#include <cstdio>
#include <numeric>
#include <random>
#include <thread>
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

TEST(WideContacts, RefreshedInertiaReachesThePasses) {
  // World refreshes the world inverse inertia of an anisotropic body that turned far
  // within the step (World::integrate_positions) between substeps; the scalar passes
  // read it from the states, the lanes once refresh_inertia has re-packed it. Every
  // body's inertia is turned by 0.3 rad between substeps here: with refresh_inertia
  // the lanes match the scalar passes, without it they keep the build's inertia and
  // do not (the check can fail).
  for (const bool refresh : {true, false}) {
    Scene scalar = random_scene(60, 2, 200, 31);
    Scene wide = scalar;
    SolverSettings settings;
    ContactSoftness soft;
    const Real h = 1.0 / 240;
    prepare_contacts(scalar.constraints, scalar.states, settings, h, soft);
    prepare_contacts(wide.constraints, wide.states, settings, h, soft);
    const int dummy = static_cast<int>(wide.states.size()) - 1;
    std::vector<int> order(wide.constraints.size()), bodies;
    for (std::size_t k = 0; k < order.size(); ++k) order[k] = static_cast<int>(k);
    for (int i = 2; i < dummy; ++i) bodies.push_back(i);
    WideContacts w;
    w.build(wide.constraints, order, wide.states, dummy);
    const Mat3 turn = Quat(Eigen::AngleAxis<Real>(0.3, Vec3(1, 2, 3).normalized())).toRotationMatrix();
    for (int sub = 0; sub < 3; ++sub) {
      warm_start_contacts(scalar.constraints, scalar.states);
      solve_contacts(scalar.constraints, scalar.states, soft, 1 / h, settings.push_max, true);
      w.warm_start(wide.states);
      w.solve(wide.states, soft, 1 / h, settings.push_max, true);
      for (Scene* s : {&scalar, &wide})
        for (const int i : bodies) s->states[i].inv_inertia = turn * s->states[i].inv_inertia * turn.transpose();
      if (refresh) w.refresh_inertia(wide.states, bodies);
      w.set_motion(wide.states);
      solve_contacts(scalar.constraints, scalar.states, soft, 1 / h, settings.push_max, false);
      w.solve(wide.states, soft, 1 / h, settings.push_max, false);
    }
    w.unpack(wide.constraints);
    const Real diff = max_difference(scalar, wide);
    if (refresh)
      EXPECT_LT(diff, kFloatTolerance);
    else
      EXPECT_GT(diff, 100 * kFloatTolerance) << diff;
  }
}

namespace {

/// A ParallelTeam of plain threads, started for each run.
class TestTeam final : public ParallelTeam {
 public:
  explicit TestTeam(int threads) : threads_(threads) {}
  int size() const override { return threads_; }
  void run(const std::function<void(int)>& fn) override {
    std::vector<std::thread> others;
    for (int t = 1; t < threads_; ++t) others.emplace_back([&fn, t] { fn(t); });
    fn(0);
    for (std::thread& th : others) th.join();
    ++runs;
  }
  int runs = 0;

 private:
  int threads_;
};

/// Regions for `s`: the dynamic bodies split into `regions` runs of indices, each
/// constraint in its dynamic bodies' run, or in the boundary (`regions`) when they
/// are in two.
std::vector<int> index_regions(const Scene& s, int regions) {
  const int bodies = static_cast<int>(s.states.size()) - 1;
  auto region_of = [&](int b) { return b * regions / bodies; };
  std::vector<int> region;
  for (const ContactConstraint& c : s.constraints) {
    const bool da = s.states[c.body_a].inv_mass > 0, db = s.states[c.body_b].inv_mass > 0;
    const int ra = region_of(c.body_a), rb = region_of(c.body_b);
    region.push_back(!da ? rb : !db ? ra : ra == rb ? ra : regions);
  }
  return region;
}

/// Wide passes as World runs them (warm start, a biased pass, set_motion, a forward
/// and a backward relax pass, per substep) over the constraints in `order`, with
/// build's region `starts`, on `team` (none: one thread). Returns the region count.
int run_ordered_passes(Scene& s, const std::vector<int>& order, const std::vector<int>& starts,
                       ParallelTeam* team, int substeps = 4) {
  SolverSettings settings;
  ContactSoftness soft;
  const Real h = 1.0 / 240;
  prepare_contacts(s.constraints, s.states, settings, h, soft);
  WideContacts w;
  w.set_team(team);
  w.build(s.constraints, order, s.states, static_cast<int>(s.states.size()) - 1, {}, 0, 0, true, starts);
  for (int sub = 0; sub < substeps; ++sub) {
    w.warm_start(s.states);
    w.solve(s.states, soft, 1 / h, settings.push_max, true);
    w.set_motion(s.states);
    w.solve(s.states, soft, 1 / h, settings.push_max, false);
    w.solve(s.states, soft, 1 / h, settings.push_max, false, /*reverse=*/true);
  }
  w.unpack(s.constraints);
  return w.region_count();
}

/// region_band_order over `regions` index regions, the constraints at heights falling
/// by 1 m in their given order, bands `band` m deep (below 1: one constraint a band,
/// the given sequence within each region).
void region_order(const Scene& s, int regions, Real band, std::vector<int>& order, std::vector<int>& starts) {
  const std::size_t n = s.constraints.size();
  std::vector<Real> height(n), width(n, band);
  for (std::size_t k = 0; k < n; ++k) height[k] = -static_cast<Real>(k);
  std::vector<std::uint64_t> scratch;
  region_band_order(s.constraints, s.states, index_regions(s, regions), regions, height, width, order, starts,
                    scratch);
}

/// run_ordered_passes in region_band_order over `regions` index regions, 20-constraint bands.
int run_region_passes(Scene& s, int regions, ParallelTeam* team) {
  std::vector<int> order, starts;
  region_order(s, regions, 19.5, order, starts);
  return run_ordered_passes(s, order, starts, team);
}

}  // namespace

TEST(WideContacts, RegionBandOrderWithOneConstraintABandIsTheSequenceWithTheBoundaryLast) {
  // Bands of one constraint each: every region's constraints in their own sequence,
  // then the boundary's. Passes over that sequence (a stable partition by region, no
  // regions for build) and passes in region_band_order agree; every index appears
  // once, in its region's range.
  for (const auto [bodies, count] : {std::pair{40, 200}, std::pair{400, 600}}) {
    Scene scalar = random_scene(bodies, 3, count, 41 + bodies);
    const std::vector<int> region = index_regions(scalar, 4);
    std::vector<int> order, starts;
    region_order(scalar, 4, 0.5, order, starts);
    ASSERT_EQ(starts.size(), 6u);
    EXPECT_EQ(starts.front(), 0);
    EXPECT_EQ(starts.back(), count);
    for (int r = 0; r <= 4; ++r)
      for (int q = starts[r]; q < starts[r + 1]; ++q) EXPECT_EQ(region[order[q]], r);
    std::vector<int> sorted = order;
    std::sort(sorted.begin(), sorted.end());
    for (int k = 0; k < count; ++k) ASSERT_EQ(sorted[k], k);
    Scene wide = scalar;
    Scene reference = scalar;
    std::vector<int> sequence(count);
    for (int k = 0; k < count; ++k) sequence[k] = k;
    std::stable_sort(sequence.begin(), sequence.end(), [&](int a, int b) { return region[a] < region[b]; });
    EXPECT_EQ(sequence, order);
    run_ordered_passes(reference, sequence, {}, nullptr);
    EXPECT_EQ(run_ordered_passes(wide, order, starts, nullptr), 4);
    EXPECT_EQ(max_difference(reference, wide), 0);  // the same order, grouped by region
    // Without the boundary moved last (the plain sequence), the result differs: the
    // check can fail.
    Scene plain = scalar;
    std::vector<int> identity(count);
    std::iota(identity.begin(), identity.end(), 0);
    run_ordered_passes(plain, identity, {}, nullptr);
    EXPECT_GT(max_difference(plain, wide, /*velocities_only=*/true), 100 * kFloatTolerance);
  }
}

TEST(WideContacts, RegionBandOrderColoursEachBand) {
  // Bands of 20 constraints: within a band, the constraints of one colour share no
  // dynamic body (they fill groups), colours follow each other in order, and the
  // bands (and regions) keep theirs.
  Scene s = random_scene(300, 3, 800, 77);
  const std::vector<int> region = index_regions(s, 4);
  std::vector<int> order, starts;
  region_order(s, 4, 19.5, order, starts);
  std::vector<int> sorted = order;
  std::sort(sorted.begin(), sorted.end());
  for (int k = 0; k < 800; ++k) ASSERT_EQ(sorted[k], k);
  int colours = 0;
  for (int r = 0; r <= 4; ++r) {
    // Runs of consecutive constraints of one band (heights -k: band = k / 20 within
    // the region's sequence is not known here, so check the weaker property): split
    // the region's order wherever two neighbours share a dynamic body; each run is
    // an independent set, and there are far fewer runs than constraints.
    std::vector<int> seen(s.states.size(), -1);
    int runs = 0;
    for (int q = starts[r]; q < starts[r + 1]; ++q) {
      const ContactConstraint& c = s.constraints[order[q]];
      bool clash = false;
      for (const int b : {c.body_a, c.body_b})
        if (s.states[b].inv_mass > 0 && seen[b] == runs) clash = true;
      if (clash || q == starts[r]) ++runs;
      for (const int b : {c.body_a, c.body_b})
        if (s.states[b].inv_mass > 0) seen[b] = runs;
    }
    colours += runs;
  }
  // 800 constraints among 300 bodies in 20-constraint bands: a few colours a band.
  EXPECT_LT(colours, 800 / 4);
}

TEST(WideContacts, ATeamComputesTheSameBitsAsOneThread) {
  // 4 regions of a sparse graph (long regions, a boundary of the constraints between
  // them), on 1, 2 and 3 threads: the regions share no moving body, so they commute
  // exactly and every velocity and impulse is the same bit for bit. Enough groups
  // (~600) that the team takes the passes (kParallelMinGroups per thread).
  Scene one = random_scene(6000, 10, 5000, 5);
  Scene base = one;
  EXPECT_EQ(run_region_passes(one, 4, nullptr), 4);
  for (const int threads : {2, 3}) {
    Scene many = base;
    TestTeam team(threads);
    run_region_passes(many, 4, &team);
    EXPECT_GT(team.runs, 0);  // the team did run the passes
    EXPECT_EQ(max_difference(one, many), 0) << threads << " threads";
  }
  // And a regrouping does change bits (the check can fail): the same scene in one
  // region, i.e. the boundary constraints among the others.
  Scene single = base;
  run_region_passes(single, 1, nullptr);
  EXPECT_GT(max_difference(one, single), 0);
}

namespace {

/// One constraint between a dynamic body (1) and a static one (0), at rest in the
/// solver's frame (dp = 0, dq = 1): its points' separations are then
/// n . (rb - ra) + adjusted_separation.
Scene single_constraint(std::uint64_t seed) {
  Scene s = random_scene(2, 1, 1, seed);
  for (BodyState& b : s.states) {
    b.dp.setZero();
    b.dq = Quat::Identity();
  }
  return s;
}

/// A unit cube (1 kg) on the static ground (state 0) on its four bottom corners, 1 cm
/// deep, moving down at one substep of gravity (h s); each corner's warm-start impulse
/// is `impulse`. State 2 is the padding state.
Scene cube_on_ground(Real h, Real impulse) {
  Scene s;
  s.states.resize(3);
  BodyState& cube = s.states[1];
  cube.inv_mass = 1;
  cube.inv_inertia = Mat3::Identity() * 6;  // 1 / (m (1^2 + 1^2) / 12)
  cube.v = Vec3(0, -9.81 * h, 0);
  ContactConstraint c;
  c.body_a = 0;
  c.body_b = 1;
  c.normal = Vec3(0, 1, 0);
  orthonormal_basis(c.normal, c.tangent1, c.tangent2);
  c.friction = 0.5;
  c.count = 4;
  const Real corners[4][2] = {{-0.5, -0.5}, {0.5, -0.5}, {0.5, 0.5}, {-0.5, 0.5}};
  for (int i = 0; i < 4; ++i) {
    ContactConstraintPoint& p = c.points[i];
    p.rb = Vec3(corners[i][0], -0.5, corners[i][1]);  // the corner, from the cube's centre
    p.ra = Vec3(corners[i][0], 0, corners[i][1]);      // the same point from the ground's origin
    p.ca_n = 0;
    p.cb_n = 0;
    p.adjusted_separation = -0.01 - c.normal.dot(p.rb - p.ra);  // separation -1 cm
    p.normal_impulse = impulse;
  }
  s.constraints.push_back(c);
  return s;
}

}  // namespace

TEST(BlockNormalRows, OneRelaxPassSolvesTheManifoldsComplementarityProblem) {
  // After one relax pass (no bias) with NormalRows::kBlock, every point of the
  // manifold satisfies w = vn + bias + gamma x >= 0, x >= 0 and x w = 0 (bias: a
  // speculative point's gap over the substep; gamma: the 1e-6 regularisation), to
  // round-off. The sequential rows, one pass, leave residuals several orders larger:
  // each row undoes part of what the others did.
  const Real h = 1.0 / 240;
  Real worst_block = 0, worst_rows = 0;
  int multi = 0;
  for (std::uint64_t seed = 1; seed <= 200; ++seed) {
    for (const bool block : {true, false}) {
      Scene s = single_constraint(seed);
      ContactConstraint& c = s.constraints[0];
      if (c.count < 2) break;
      multi += block;
      SolverSettings settings;
      ContactSoftness soft;
      prepare_contacts(s.constraints, s.states, settings, h, soft);
      solve_contacts(s.constraints, s.states, soft, 1 / h, settings.push_max, false,
                     block ? NormalRows::kBlock : NormalRows::kSequential);
      const BodyState& a = s.states[c.body_a];
      const BodyState& b = s.states[c.body_b];
      for (int i = 0; i < c.count; ++i) {
        const ContactConstraintPoint& p = c.points[i];
        const Real sep = c.normal.dot(p.rb - p.ra) + p.adjusted_separation;
        const Vec3 ca = p.ra.cross(c.normal), cb = p.rb.cross(c.normal);
        const Real kii = a.inv_mass + b.inv_mass + ca.dot(a.inv_inertia * ca) + cb.dot(b.inv_inertia * cb);
        const Real vn = c.normal.dot((b.v + b.w.cross(p.rb)) - (a.v + a.w.cross(p.ra)));
        const Real w = vn + std::max(sep, Real(0)) / h + 1e-6 * kii * p.normal_impulse;
        ASSERT_GE(p.normal_impulse, 0);
        // Scale of the velocities involved: the gap's speed and the bodies' speeds (O(1)).
        const Real residual = std::max(-w, Real(0)) + std::abs(p.normal_impulse * w) / (1 + p.normal_impulse);
        (block ? worst_block : worst_rows) = std::max(block ? worst_block : worst_rows, residual);
      }
    }
  }
  ASSERT_GT(multi, 100);  // most constraints have 2-4 points
  std::printf("worst residual: block %.3g, rows %.3g\n", worst_block, worst_rows);
  EXPECT_LT(worst_block, 1e-9);
  EXPECT_GT(worst_rows, 1e-3);
}

TEST(BlockNormalRows, ASymmetricFaceContactGetsASymmetricImpulse) {
  // A unit cube (1 kg) resting on the ground on its four bottom corners, 1 cm deep,
  // pressed down by one substep of gravity: the block pass gives the four corners the
  // same impulse, which together stop the approach (1 kg * 9.81 m/s^2 * h, plus the
  // push out of the overlap), and does not turn the cube.
  const Real h = 1.0 / 240;
  Scene s = cube_on_ground(h, 0);
  BodyState& cube = s.states[1];
  SolverSettings settings;
  ContactSoftness soft;
  prepare_contacts(s.constraints, s.states, settings, h, soft);
  solve_contacts(s.constraints, s.states, soft, 1 / h, settings.push_max, true, NormalRows::kBlock);
  const ContactConstraint& r = s.constraints[0];
  for (int i = 1; i < 4; ++i) EXPECT_NEAR(r.points[i].normal_impulse, r.points[0].normal_impulse, 1e-12);
  EXPECT_GT(r.points[0].normal_impulse, 0.25 * 9.81 * h);  // more than the weight: it also pushes out
  EXPECT_LT(cube.w.norm(), 1e-12);
  EXPECT_GT(cube.v.y(), 0);  // pushed out of the 1 cm overlap
}

TEST(SequentialNormalRows, TheCentroidRowGivesASymmetricFaceContactASymmetricImpulse) {
  // The same cube on its four corners, solved row by row (the default passes, scalar
  // and 8-wide): the centroid row (centroid_row in contact_solver.cpp) meets the rows'
  // targets on average with one increment at every corner, which for a symmetric
  // contact meets each row exactly, so the corners carry the same impulse and the cube
  // does not turn, in the biased pass and in a relax pass. Row by row alone, the first
  // corner takes the whole correction and the opposite one the reaction: the corners
  // then carried 0.0104-0.0193 N s in a tower after one step (1.9x), a torque that
  // rocked it over.
  const Real h = 1.0 / 240;
  for (const bool wide : {false, true}) {
    for (const bool use_bias : {true, false}) {
      Scene s = cube_on_ground(h, 0.01);  // warm-started, as a resting contact is
      BodyState& cube = s.states[1];
      SolverSettings settings;
      ContactSoftness soft;
      prepare_contacts(s.constraints, s.states, settings, h, soft);
      if (wide) {
        WideContacts w;
        w.build(s.constraints, {0}, s.states, 2);
        w.solve(s.states, soft, 1 / h, settings.push_max, use_bias);
        w.unpack(s.constraints);
      } else {
        solve_contacts(s.constraints, s.states, soft, 1 / h, settings.push_max, use_bias);
      }
      const ContactConstraint& r = s.constraints[0];
      const Real tol = wide ? 1e-6 : 1e-12;  // float lanes: 6e-8 relative per operation
      for (int i = 1; i < 4; ++i)
        EXPECT_NEAR(r.points[i].normal_impulse, r.points[0].normal_impulse, tol * r.points[0].normal_impulse)
            << (wide ? "wide" : "scalar") << (use_bias ? " biased" : " relax") << " corner " << i;
      EXPECT_GT(r.points[0].normal_impulse, 0.25 * 9.81 * h);  // at least the substep's weight
      EXPECT_LT(cube.w.norm(), wide ? 1e-6 : 1e-12);
    }
  }
}
