// World: handles, integration against closed forms, resting contact, stacking, bad input.
#include <gtest/gtest.h>

#include <algorithm>
#include <cmath>
#include <cstdint>
#include <memory>
#include <string>
#include <utility>
#include <vector>

#include "wmo/world/world.h"

using namespace wmo;

namespace {

BodyDef box_def(const Vec3& half, const Vec3& pos, BodyKind kind = BodyKind::kDynamic) {
  BodyDef d;
  d.shape = std::make_shared<Box>(half);
  d.position = pos;
  d.kind = kind;
  return d;
}

World ground_world(WorldSettings s = {}) {
  World w(s);
  w.add_body(box_def(Vec3(50, 1, 50), Vec3(0, -1, 0), BodyKind::kStatic));
  return w;
}

/// Two unit boxes stacked on the ground of `w`, stepped until both sleep (2 s).
std::pair<BodyId, BodyId> sleeping_two_box_stack(World& w) {
  const BodyId a = w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 0.5, 0)));
  const BodyId b = w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 1.5, 0)));
  w.step(120);
  EXPECT_EQ(w.awake_dynamic_count(), 0);
  return {a, b};
}

}  // namespace

// A free body's velocity takes each substep's gravity first (v_k = v0 + k h g, h = dt /
// substeps) and its centre of mass moves with the substep's mean velocity, so under
// gravity alone it follows the exact parabola x_k = x0 + k h v0 + g (k h)^2 / 2 (plain
// semi-implicit Euler would add h^2 g k / 2: 4 cm low here). The world must follow this
// exactly up to rounding (1e-12 m over 2 s of 1e-2 m-scale increments: ~1000 roundings
// of ~1e-16 relative).
TEST(World, ProjectileFollowsTheIntegratorsClosedForm) {
  WorldSettings s;
  s.gravity = Vec3(0, -9.81, 0);
  s.dt = 1.0 / 60;
  s.substeps = 4;
  World w(s);
  BodyDef d;
  d.shape = std::make_shared<Sphere>(0.1);
  d.position = Vec3(1, 2, 3);
  d.linear_velocity = Vec3(3, 10, -1);
  const BodyId id = w.add_body(d);
  w.step(120);
  const int k = 120 * 4;
  const Real h = s.dt / 4;
  const Vec3 x = d.position + k * h * d.linear_velocity + h * h * s.gravity * (k * k / 2.0);
  const Vec3 v = d.linear_velocity + k * h * s.gravity;
  const int i = w.index_of(id);
  EXPECT_LT((w.positions()[i] - x).norm(), 1e-12);
  EXPECT_LT((w.linear_velocities()[i] - v).norm(), 1e-12);
}

TEST(World, StaleHandleThrowsAndSwapRemoveKeepsHandles) {
  World w;
  const BodyId a = w.add_body(box_def(Vec3(1, 1, 1), Vec3(0, 0, 0)));
  const BodyId b = w.add_body(box_def(Vec3(1, 1, 1), Vec3(5, 0, 0)));
  const BodyId c = w.add_body(box_def(Vec3(1, 1, 1), Vec3(10, 0, 0)));
  w.remove_body(a);
  EXPECT_FALSE(w.is_valid(a));
  EXPECT_THROW(w.index_of(a), InvalidArgument);
  EXPECT_THROW(w.remove_body(a), InvalidArgument);
  EXPECT_EQ(w.body_count(), 2);
  EXPECT_EQ(w.positions()[w.index_of(c)].x(), 10);  // moved into row 0
  EXPECT_EQ(w.positions()[w.index_of(b)].x(), 5);
  const BodyId d = w.add_body(box_def(Vec3(1, 1, 1), Vec3(20, 0, 0)));
  EXPECT_EQ(d.slot, a.slot);  // slot reused ...
  EXPECT_NE(d.generation, a.generation);  // ... with a new generation
  EXPECT_THROW(w.index_of(a), InvalidArgument);
}

TEST(World, BadInputRaisesAndLeavesTheWorldUnchanged) {
  World w;
  w.add_body(box_def(Vec3(1, 1, 1), Vec3(0, 0, 0)));
  BodyDef bad = box_def(Vec3(1, 1, 1), Vec3(NAN, 0, 0));
  EXPECT_THROW(w.add_body(bad), InvalidArgument);
  bad = box_def(Vec3(1, 1, 1), Vec3(0, 0, 0));
  bad.mass = -1;
  EXPECT_THROW(w.add_body(bad), InvalidArgument);
  bad.mass = NAN;
  bad.shape = std::make_shared<Plane>(Vec3(0, 1, 0), 0);
  EXPECT_THROW(w.add_body(bad), InvalidArgument);  // dynamic plane
  EXPECT_EQ(w.body_count(), 1);
  WorldSettings s;
  s.dt = 0;
  EXPECT_THROW(w.set_settings(s), InvalidArgument);
  EXPECT_EQ(w.settings().dt, 1.0 / 60);
  EXPECT_THROW(World{s}, InvalidArgument);
}

// step() checks the state only where the user may have written it (world.h, State):
// after any call of a writable accessor it checks at every step, since the reference
// may be kept: a write through a reference taken before several steps is still caught,
// with the world left as it was; a sleeping body written to through it wakes.
TEST(World, WritesThroughAKeptWritableReferenceAreCheckedAtEveryStep) {
  World w = ground_world();
  const auto [a, b] = sleeping_two_box_stack(w);
  SharedArray<Vec3>& v = w.linear_velocities();  // kept across steps
  w.step(3);
  const int i = w.index_of(b);
  v[i] = Vec3(0, NAN, 0);
  const Vec3 p = std::as_const(w).positions()[i];
  const long long count = w.step_count();
  EXPECT_THROW(w.step(), InvalidArgument);
  EXPECT_EQ(w.step_count(), count);
  EXPECT_EQ(std::as_const(w).positions()[i], p);
  v[i] = Vec3(0, 2, 0);  // asleep until now: the write wakes its island
  w.step();
  EXPECT_GT(std::as_const(w).positions()[i].y(), p.y());
  EXPECT_GT(w.awake_dynamic_count(), 0);
  (void)a;
}

// update_broadphase computes the boxes of runs of awake spheres and their keep tests on
// vectors (keep_sphere_boxes). Whatever path a body takes, its proxy's tight box after
// a step is the rule's box for the state the step started from: the sphere's box
// (centre +- radius) fattened by the speculative distance and swept by dt v x
// max(speculative_motion, speculative_motion_static) where that moves it more than the
// speculative distance along some axis, else by dt v x speculative_motion; computed
// here with the scalar code's operations, it must match bit for bit. A scene of
// spheres (radii 0.05-0.5 m, speeds 0-60 m/s, a few boxes breaking the runs, a ground
// they land on), once with the state checked at every step (a writable accessor
// called: the check's quick test runs inside the vector loop) and once without.
TEST(World, SphereBoxesFollowTheBoxRuleBitForBit) {
  for (const bool checked : {false, true}) {
    World w = ground_world();
    std::uint64_t seed = 12345;
    auto uniform = [&](Real lo, Real hi) {
      seed = seed * 6364136223846793005ull + 1442695040888963407ull;
      return lo + (hi - lo) * static_cast<Real>(seed >> 11) * 0x1.0p-53;
    };
    std::vector<Real> radius;
    for (int k = 0; k < 400; ++k) {
      BodyDef d;
      radius.push_back(k % 37 == 5 ? -1 : uniform(0.05, 0.5));
      if (radius.back() < 0) {
        d.shape = std::make_shared<Box>(Vec3(0.2, 0.3, 0.1));
      } else {
        d.shape = std::make_shared<Sphere>(radius.back());
      }
      d.position = Vec3(uniform(-20, 20), uniform(0.5, 30), uniform(-20, 20));
      const Real speed = k % 5 == 0 ? uniform(10, 60) : uniform(0, 3);
      d.linear_velocity = speed * Vec3(uniform(-1, 1), uniform(-1, 1), uniform(-1, 1)).normalized();
      w.add_body(d);
    }
    if (checked) (void)w.positions();
    const World& cw = w;
    const WorldSettings& s = cw.settings();
    const Real spec = s.speculative_distance, motion = s.speculative_motion * s.dt;
    const Real static_motion = std::max(s.speculative_motion, s.speculative_motion_static) * s.dt;
    int compared = 0;
    for (int step = 0; step < 240; ++step) {
      std::vector<Vec3> p(cw.positions().begin(), cw.positions().end());
      std::vector<Vec3> v(cw.linear_velocities().begin(), cw.linear_velocities().end());
      std::vector<bool> awake(cw.body_count());
      for (int i = 0; i < cw.body_count(); ++i) awake[i] = cw.is_awake(i);
      w.step();
      for (int i = 1; i < cw.body_count(); ++i) {  // row 0: the ground
        if (radius[i - 1] < 0 || !awake[i]) continue;
        Vec3 d = motion * v[i];
        const Vec3 ds = static_motion * v[i];
        if (ds.cwiseAbs().maxCoeff() > spec) d = ds;
        Aabb want;
        want.min = (p[i].array() - radius[i - 1]) - spec;
        want.max = (p[i].array() + radius[i - 1]) + spec;
        want.min += d.cwiseMin(Vec3::Zero());
        want.max += d.cwiseMax(Vec3::Zero());
        const Aabb& got = cw.broadphase().aabb(cw.proxy_of(i));
        ASSERT_TRUE(got.min == want.min && got.max == want.max)
            << "body " << i << " step " << step << (checked ? " (checked)" : "");
        ++compared;
      }
    }
    EXPECT_GT(compared, 240 * 300);
    EXPECT_GT(cw.profile()[1].total_count, 0);  // pairs were found: the boxes mattered
  }
}

// A box dropped on the ground comes to rest on it: resting penetration below 1 mm
// (the soft contact holds a 1 m box under gravity with a sub-millimetre spring
// deflection: g / (2 pi 60)^2 = 0.07 mm at the default 60 Hz of a contact with a static
// body) and velocity below 1 mm/s.
TEST(World, BoxComesToRestOnTheGround) {
  for (const bool sleep : {false, true}) {
    WorldSettings s;
    s.enable_sleep = sleep;
    World w = ground_world(s);
    const BodyId id = w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 2, 0)));
    w.step(180);
    const int i = w.index_of(id);
    EXPECT_NEAR(w.positions()[i].y(), 0.5, 1e-3);
    EXPECT_LT(w.linear_velocities()[i].norm(), 1e-3);
    EXPECT_LT(w.angular_velocities()[i].norm(), 1e-3);
    if (sleep) {
      // At rest for more than time_to_sleep (0.5 s) of the 3 s: asleep, no contact work.
      EXPECT_FALSE(w.is_awake(i));
      EXPECT_EQ(w.contact_point_count(), 0);
    } else {
      EXPECT_TRUE(w.is_awake(i));
      EXPECT_EQ(w.contact_point_count(), 4);
      EXPECT_LT(w.max_penetration(), 1e-3);
    }
  }
}

// ---- Sleeping ------------------------------------------------------------------------

namespace {
long long stage_count(const World& w, const char* name) {
  for (std::size_t k = 0; k < kStageNames.size(); ++k)
    if (std::string(kStageNames[k]) == name) return w.profile()[k].count;
  return -1;
}
}  // namespace

// A resting box falls asleep and then costs nothing: no proxy moves, no contact, no
// solve. A box dropped onto it wakes it (broadphase overlap), and both sleep again.
TEST(World, SleepingBoxCostsNothingAndWakesWhenHit) {
  World w = ground_world();
  const BodyId a = w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 0.5, 0)));
  w.step(60);  // 1 s at rest: past time_to_sleep
  ASSERT_FALSE(w.is_awake(w.index_of(a)));
  EXPECT_EQ(w.awake_dynamic_count(), 0);
  w.step();
  EXPECT_EQ(stage_count(w, "update_broadphase"), 0);
  EXPECT_EQ(stage_count(w, "narrowphase"), 0);
  EXPECT_EQ(stage_count(w, "solve"), 0);
  EXPECT_EQ(w.linear_velocities()[w.index_of(a)], Vec3::Zero());
  const BodyId b = w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0.2, 3, 0)));
  bool woke = false;
  for (int k = 0; k < 120 && !woke; ++k) {
    w.step();
    woke = w.is_awake(w.index_of(a));
  }
  EXPECT_TRUE(woke);
  w.step(300);
  EXPECT_NEAR(w.positions()[w.index_of(b)].y(), 1.5, 2e-3);  // on top of a
  EXPECT_EQ(w.awake_dynamic_count(), 0);  // both asleep again
}

TEST(World, ImpulseSetterAndWrittenVelocityWakeTheIsland) {
  World w = ground_world();
  const auto [a, b] = sleeping_two_box_stack(w);
  ASSERT_EQ(w.awake_dynamic_count(), 0);
  // An impulse on the lower box wakes its whole island (the box on top too).
  w.apply_impulse(a, Vec3(0.5, 0, 0), w.positions()[w.index_of(a)]);
  EXPECT_TRUE(w.is_awake(w.index_of(a)));
  EXPECT_TRUE(w.is_awake(w.index_of(b)));
  w.step(240);
  ASSERT_EQ(w.awake_dynamic_count(), 0);
  w.set_linear_velocity(b, Vec3(0, 1, 0));
  EXPECT_TRUE(w.is_awake(w.index_of(a)));
  w.step(240);
  ASSERT_EQ(w.awake_dynamic_count(), 0);
  // A velocity written straight into the state array wakes it at the next step.
  w.linear_velocities()[w.index_of(b)] = Vec3(0, 2, 0);
  w.step();
  EXPECT_EQ(w.awake_dynamic_count(), 2);
  EXPECT_GT(w.positions()[w.index_of(b)].y(), 1.5);  // and the velocity was used
}

TEST(World, RemovingASleepingSupportWakesWhatRestsOnIt) {
  World w = ground_world();
  const auto [a, b] = sleeping_two_box_stack(w);
  ASSERT_EQ(w.awake_dynamic_count(), 0);
  w.remove_body(a);
  EXPECT_TRUE(w.is_awake(w.index_of(b)));
  w.step(120);
  EXPECT_NEAR(w.positions()[w.index_of(b)].y(), 0.5, 2e-3);  // fell onto the ground
}

TEST(World, KinematicAtRestLetsAPileSleepAndMovingOneWakesIt) {
  World w = ground_world();
  const BodyId k = w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(1.0, 0.5, 0), BodyKind::kKinematic));
  const BodyId a = w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 0.5, 0)));
  w.step(120);
  EXPECT_FALSE(w.is_awake(w.index_of(a)));  // touching a kinematic body at rest
  w.set_linear_velocity(k, Vec3(-0.5, 0, 0));
  w.step();
  EXPECT_TRUE(w.is_awake(w.index_of(a)));
  w.step(60);
  EXPECT_LT(w.positions()[w.index_of(a)].x(), -0.2);  // pushed along
}

TEST(World, SleepingOffKeepsEverythingAwake) {
  WorldSettings s;
  s.enable_sleep = false;
  World w = ground_world(s);
  w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 0.5, 0)));
  w.step(120);
  EXPECT_EQ(w.awake_dynamic_count(), 1);
  EXPECT_EQ(stage_count(w, "update_sleep"), 0);  // the stage is skipped
}

// A stack of 10 unit boxes stands for 10 s: every box within 1 cm of its start.
// 8 substeps at 60 Hz. The soft contacts sag by about load / (m (2 pi f)^2) per
// contact, summed up the stack: 1.8 cm at the top with the default 36 Hz. With the
// defaults (4 substeps at 60 Hz) the stack stands, 3.9 mm off sideways, but that sag
// is over the 1 cm; with one relax pass per substep it rocked and crept sideways by up
// to 5 cm. The sag is an open problem of issue 3, measured rather than hidden here.
// 8 substeps allow 120 Hz contacts (a quarter of the substep rate); the springs' sag
// is then 100 g / (2 pi 120)^2 = 1.7 mm for ten unit boxes (measured 1.7 mm down,
// 1.5 mm sideways). At 60 Hz the sag alone is 6.9 mm and the sideways transient of
// the first steps 6.6 mm, over the 1 cm bar.
TEST(World, StackOfTenStands) {
  WorldSettings s;
  s.substeps = 8;
  s.solver.contact_hertz = 120;
  World w = ground_world(s);
  std::vector<BodyId> ids;
  for (int k = 0; k < 10; ++k) ids.push_back(w.add_body(box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 0.5 + k, 0))));
  w.step(600);
  for (int k = 0; k < 10; ++k) {
    const Vec3 p = w.positions()[w.index_of(ids[k])];
    EXPECT_LT((p - Vec3(0, 0.5 + k, 0)).norm(), 1e-2) << "box " << k << " at " << p.transpose();
  }
}

// A frictionless box sliding on frictionless ground keeps its horizontal speed; with
// friction mu it stops after v^2 / (2 mu g).
TEST(World, FrictionStopsASlidingBoxAtTheAnalyticDistance) {
  WorldSettings s;
  s.gravity = Vec3(0, -10, 0);
  World w = ground_world(s);
  BodyDef d = box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 0.5, 0));
  d.linear_velocity = Vec3(4, 0, 0);
  d.friction = 0.5;
  // ground friction 0.5 too: product rule gives 0.25
  const BodyId id = w.add_body(d);
  w.step(240);
  const Real expected = 4.0 * 4.0 / (2 * 0.25 * 10);  // 3.2 m
  // 3%: the stop happens within a step (4/60 s of 2.4 m/s^2 deceleration ~ 1 cm) and
  // the first contact step starts from rest in the normal direction.
  EXPECT_NEAR(w.positions()[w.index_of(id)].x(), expected, 0.03 * expected);
}

TEST(World, RestitutionBouncesBallToESquaredHeight) {
  WorldSettings s;
  s.gravity = Vec3(0, -10, 0);
  s.dt = 1.0 / 480;
  World w(s);
  BodyDef g = box_def(Vec3(50, 1, 50), Vec3(0, -1, 0), BodyKind::kStatic);
  g.restitution = 0.8;
  w.add_body(g);
  BodyDef d;
  d.shape = std::make_shared<Sphere>(0.1);
  d.position = Vec3(0, 1.1, 0);  // drop height 1 m (bottom at 1 m)
  d.restitution = 0.8;
  const BodyId id = w.add_body(d);
  Real apex = 0;
  bool bounced = false;
  for (int k = 0; k < 1200; ++k) {
    w.step();
    const Real vy = w.linear_velocities()[w.index_of(id)].y();
    const Real y = w.positions()[w.index_of(id)].y() - 0.1;
    if (vy > 0) bounced = true;
    if (bounced) apex = std::max(apex, y);
    if (bounced && vy < 0 && apex > 0) break;
  }
  // e^2 h = 0.64 m. The bounce reverses the approach speed of the substep where the
  // contact first pushes (measured: -0.3% at dt 1/480 s, -1.2% at 1/60 s; reversing the
  // speed at the impact step's start, Box2D v3's rule, missed up to a step of gravity:
  // 1% at 1/480 s, 2.2% at 1/240 s), inside the 2% bound.
  EXPECT_NEAR(apex, 0.64, 0.02 * 0.64);
}

// A rotated body stays asleep across many step() calls (each call checks the state
// arrays and normalises quaternions; that must not look like a user write).
TEST(World, RotatedSleepingBodyStaysAsleepAcrossStepCalls) {
  World w = ground_world();
  BodyDef d = box_def(Vec3(0.5, 0.5, 0.5), Vec3(0.3, 0.5, -0.2));
  d.orientation = Quat(Eigen::AngleAxisd(0.7312, Vec3::UnitY()));
  const BodyId a = w.add_body(d);
  w.step(120);
  ASSERT_FALSE(w.is_awake(w.index_of(a)));
  for (int k = 0; k < 50; ++k) {
    w.step(1);
    ASSERT_FALSE(w.is_awake(w.index_of(a))) << "woke at call " << k;
  }
}

namespace {

/// A 2 m rod (capsule, radius 2 cm) lying along z at the origin, spinning about y at
/// 100 rad/s, beside a 1 cm static wall whose face is at x = 0.9. Returns the largest x
/// any point of the rod reached at the end of a step over 30 steps.
Real spinning_rod_reach(bool ccd, int* hits) {
  WorldSettings s;
  s.gravity = Vec3::Zero();
  World w(s);
  w.add_body(box_def(Vec3(0.005, 2, 2), Vec3(0.905, 0, 0), BodyKind::kStatic));
  BodyDef rod;
  rod.shape = std::make_shared<Capsule>(0.02, 1.0);
  rod.orientation = Quat(Eigen::AngleAxis<Real>(kPi / 2, Vec3::UnitX()));
  rod.angular_velocity = Vec3(0, 100, 0);
  rod.ccd = ccd;
  const BodyId id = w.add_body(rod);
  Real reach = -kInf;
  *hits = 0;
  for (int k = 0; k < 30; ++k) {
    w.step();
    *hits += w.ccd_hit_count();
    const int i = w.index_of(id);
    const Vec3 axis = w.orientations()[i] * Vec3::UnitY();
    reach = std::max(reach, w.positions()[i].x() + std::abs(axis.x()) + 0.02);
  }
  return reach;
}

}  // namespace

TEST(WorldCcd, SpinningRodGoesThroughTheWallWithoutCcdAndHitsItWithCcd) {
  int hits = 0;
  EXPECT_GT(spinning_rod_reach(false, &hits), 0.91);  // a tip ended a step past the wall
  EXPECT_EQ(hits, 0);
  EXPECT_LE(spinning_rod_reach(true, &hits), 0.9 + 0.05 * 0.02 + 1e-9);  // the face, but for the allowance
  EXPECT_GE(hits, 1);
}

TEST(WorldCcd, StageIsSkippedWhenNoBodyAsksAndForSlowBodies) {
  World w = ground_world();
  BodyDef d = box_def(Vec3(0.5, 0.5, 0.5), Vec3(0, 0.5, 0));
  const BodyId id = w.add_body(d);
  w.step(10);
  const auto ccd_stage = static_cast<std::size_t>(std::find(kStageNames.begin(), kStageNames.end(), std::string("ccd")) -
                                                  kStageNames.begin());
  ASSERT_LT(ccd_stage, kStageNames.size());
  EXPECT_EQ(w.profile()[ccd_stage].runs, 0);
  w.set_ccd(id, true);  // resting: slower than half its inner radius per step
  EXPECT_TRUE(w.ccd(w.index_of(id)));
  w.step(10);
  EXPECT_EQ(w.profile()[ccd_stage].total_count, 0);
  WorldSettings bad = w.settings();
  bad.ccd_penetration = 0;
  EXPECT_THROW(w.set_settings(bad), InvalidArgument);
}

TEST(WorldFiltering, FilteredPairAndGroupsGetNoContact) {
  // Two boxes stacked on a ground box: unfiltered the upper one rests on the lower one
  // (centre at y = 1.5); with the pair or their groups filtered it falls through onto
  // the ground (centre at 0.5, the two overlapping). 180 steps of 1/60 s settle both.
  for (int mode = 0; mode < 3; ++mode) {
    WorldSettings s;
    s.enable_sleep = false;
    World w(s);
    w.add_body(box_def({10, 0.5, 10}, {0, -0.5, 0}, BodyKind::kStatic));
    BodyDef lower_def = box_def({0.5, 0.5, 0.5}, {0, 2, 0});
    lower_def.collision_group = mode == 2 ? 4 : 0;
    const BodyId lower = w.add_body(lower_def);
    BodyDef upper_def = box_def({0.5, 0.5, 0.5}, {0, 4, 0});
    upper_def.collision_group = mode == 2 ? 5 : 0;
    const BodyId upper = w.add_body(upper_def);
    if (mode == 1) w.set_pair_collision(upper, lower, false);
    if (mode == 2) w.set_group_collision(5, 4, false);  // both still collide with the ground (0)
    w.step(180);
    const Real y = w.positions()[w.index_of(upper)].y();
    EXPECT_NEAR(y, mode == 0 ? 1.5 : 0.5, 0.02) << "mode " << mode;
    EXPECT_EQ(w.filtered_pair_count(), mode == 1 ? 1 : 0);
    if (mode == 1) {  // listed once, lower slot first
      const auto pairs = w.filtered_pairs();
      ASSERT_EQ(pairs.size(), 1u);
      EXPECT_EQ(pairs[0].first, lower);
      EXPECT_EQ(pairs[0].second, upper);
    }
  }
}

TEST(WorldBodies, GivenInertiaTensorAndMassAreTakenExactly) {
  // A saved body's mass data comes back bit for bit (wmo.io's round trip).
  World w;
  BodyDef d = box_def({0.3, 0.2, 0.1}, {0, 2, 0});
  d.mass = 0.1 * 3;  // not exactly 0.3: rescaling the shape's mass by it would round
  const BodyMass a = compute_body_mass(d);
  EXPECT_EQ(a.mass, 0.1 * 3);
  Mat3 tensor;
  tensor << 2, 0.5, 0, 0.5, 3, 0.25, 0, 0.25, 4;
  d.inertia_tensor = tensor;
  EXPECT_EQ(compute_body_mass(d).inertia_local, tensor);
  BodyDef asym = d;
  asym.inertia_tensor(0, 1) = 0.6;
  EXPECT_THROW(w.add_body(asym), InvalidArgument);
  BodyDef both = d;
  both.inertia = Vec3(1, 1, 1);
  EXPECT_THROW(w.add_body(both), InvalidArgument);
  BodyDef flat = d;
  flat.inertia_tensor = Vec3(1, 1, 3).asDiagonal();  // 3 > 1 + 1
  EXPECT_THROW(w.add_body(flat), InvalidArgument);
  EXPECT_EQ(w.body_count(), 0);
}

TEST(WorldFiltering, BadGroupsThrowAndChangeNothing) {
  World w;
  const BodyId a = w.add_body(box_def({0.5, 0.5, 0.5}, {0, 2, 0}));
  EXPECT_THROW(w.set_group_collision(64, 0, false), InvalidArgument);
  EXPECT_THROW(w.set_collision_group(a, -1), InvalidArgument);
  EXPECT_THROW(w.set_pair_collision(a, a, false), InvalidArgument);
  BodyDef d = box_def({0.5, 0.5, 0.5}, {0, 4, 0});
  d.collision_group = 64;
  EXPECT_THROW(w.add_body(d), InvalidArgument);
  EXPECT_EQ(w.body_count(), 1);
  EXPECT_EQ(w.collision_group(0), 0);
  EXPECT_TRUE(w.group_collision(0, 63));
}
