// Broadphase tests: the three algorithms must report identical pair lists (same vector,
// element for element) on random moving scenes with creations and destructions, and on
// degenerate inputs; the pair lists are also checked against a naive all-pairs loop
// written here, independent of the library's brute force.
#include <gtest/gtest.h>

#include <algorithm>
#include <array>
#include <atomic>
#include <cmath>
#include <cstdlib>
#include <new>
#include <random>
#include <vector>

#include "wmo/collision/broadphase.h"

// Allocation counter for BroadphaseSteadyState: the global operator new is replaced for
// this test executable and counts while g_count_allocations is set.
namespace {
std::atomic<bool> g_count_allocations{false};
std::atomic<long long> g_allocations{0};
}  // namespace

void* operator new(std::size_t n) {
  if (g_count_allocations.load(std::memory_order_relaxed)) g_allocations.fetch_add(1);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace wmo {
namespace {

constexpr std::array<BroadphaseType, 3> kAll = {BroadphaseType::kBruteForce,
                                                BroadphaseType::kSweepAndPrune,
                                                BroadphaseType::kAabbTree};

/// The three broadphases driven in lockstep with the same calls.
struct Trio {
  std::array<std::unique_ptr<Broadphase>, 3> bp;

  explicit Trio(const BroadphaseSettings& s = {}) {
    for (std::size_t k = 0; k < 3; ++k) bp[k] = make_broadphase(kAll[k], s);
  }
  ProxyId create(const Aabb& box, std::uint64_t user = 0) {
    const ProxyId id = bp[0]->create_proxy(box, user);
    for (std::size_t k = 1; k < 3; ++k) {
      // Ids depend only on the call history, so all three must agree.
      EXPECT_EQ(bp[k]->create_proxy(box, user), id) << to_string(kAll[k]);
    }
    return id;
  }
  void destroy(ProxyId id) {
    for (auto& b : bp) b->destroy_proxy(id);
  }
  void move(ProxyId id, const Aabb& box, const Vec3& d = Vec3::Zero()) {
    for (auto& b : bp) b->move_proxy(id, box, d);
  }
  /// Pairs of each algorithm; checks all three are identical and returns them.
  std::vector<ProxyPair> pairs(bool validate = true) {
    std::array<std::vector<ProxyPair>, 3> out;
    for (std::size_t k = 0; k < 3; ++k) {
      bp[k]->query_pairs(out[k]);
      if (validate) bp[k]->validate();
    }
    EXPECT_EQ(out[1], out[0]) << "sweep and prune differs from brute force";
    EXPECT_EQ(out[2], out[0]) << "aabb tree differs from brute force";
    return out[0];
  }
};

/// Independent oracle: every live pair i < j with closed-interval overlap, sorted.
std::vector<ProxyPair> naive_pairs(const std::vector<Aabb>& boxes, const std::vector<bool>& live) {
  std::vector<ProxyPair> out;
  for (std::size_t i = 0; i < boxes.size(); ++i) {
    if (!live[i]) continue;
    for (std::size_t j = i + 1; j < boxes.size(); ++j) {
      if (!live[j]) continue;
      bool overlap = true;
      for (int k = 0; k < 3; ++k)
        overlap = overlap && boxes[i].min[k] <= boxes[j].max[k] && boxes[j].min[k] <= boxes[i].max[k];
      if (overlap) out.emplace_back(static_cast<ProxyId>(i), static_cast<ProxyId>(j));
    }
  }
  return out;
}

struct Body {
  Vec3 center;
  Vec3 half;
  Vec3 velocity;  // m/s; zero for static bodies
  bool live = false;
  Aabb box() const { return Aabb(center - half, center + half); }
};

/// A random scene of `n` boxes in a cube of side `side` (m) whose lower corner is at
/// `origin`: half extents 0.05..1 m (a tenth of them up to 3 m), speeds up to 2 m/s
/// (a tenth up to 30 m/s, fast enough to leave any fat box every step), 20% static.
struct Scene {
  std::mt19937_64 rng;
  Real side;
  Vec3 origin;
  std::vector<Body> bodies;  // indexed by proxy id

  Scene(std::uint64_t seed, Real side_m, const Vec3& origin_m) : rng(seed), side(side_m), origin(origin_m) {}

  Real uni(Real a, Real b) { return std::uniform_real_distribution<Real>(a, b)(rng); }

  Body random_body() {
    Body b;
    b.center = origin + Vec3(uni(0, side), uni(0, side), uni(0, side));
    const Real hmax = uni(0, 1) < 0.1 ? 3.0 : 1.0;
    b.half = Vec3(uni(0.05, hmax), uni(0.05, hmax), uni(0.05, hmax));
    const Real speed = uni(0, 1) < 0.2 ? 0.0 : (uni(0, 1) < 0.1 ? 30.0 : 2.0);
    b.velocity = Vec3(uni(-1, 1), uni(-1, 1), uni(-1, 1)) * speed;
    b.live = true;
    return b;
  }

  void place(ProxyId id, const Body& b) {
    if (static_cast<std::size_t>(id) >= bodies.size()) bodies.resize(static_cast<std::size_t>(id) + 1);
    bodies[static_cast<std::size_t>(id)] = b;
  }

  /// Advances the non-static bodies by dt, bouncing off the walls of the cube.
  void step(Real dt) {
    for (Body& b : bodies) {
      if (!b.live) continue;
      b.center += b.velocity * dt;
      for (int k = 0; k < 3; ++k) {
        if (b.center[k] < origin[k] || b.center[k] > origin[k] + side) b.velocity[k] = -b.velocity[k];
      }
    }
  }

  std::vector<Aabb> boxes() const {
    std::vector<Aabb> out;
    for (const Body& b : bodies) out.push_back(b.box());
    return out;
  }
  std::vector<bool> live() const {
    std::vector<bool> out;
    for (const Body& b : bodies) out.push_back(b.live);
    return out;
  }
};

/// Runs a random scene of n boxes for `updates` updates through all three algorithms,
/// destroying and creating a few proxies between updates; returns the total pair count.
std::size_t run_random_scene(int n, int updates, std::uint64_t seed, bool check_oracle,
                             const Vec3& origin = Vec3::Zero()) {
  // Side chosen so the boxes (mean volume ~ 1 m^3) fill a few percent of the cube and each
  // box has a few overlaps: side^3 = 20 m^3 per box.
  const Real side = std::cbrt(20.0 * n);
  Scene scene(seed, side, origin);
  Trio trio;
  for (int i = 0; i < n; ++i) {
    const Body b = scene.random_body();
    scene.place(trio.create(b.box(), static_cast<std::uint64_t>(i)), b);
  }
  const Real dt = 1.0 / 60.0;
  std::size_t total = 0;
  const int churn = std::max(1, n / 50);  // proxies destroyed and created per update
  for (int u = 0; u < updates; ++u) {
    scene.step(dt);
    for (std::size_t id = 0; id < scene.bodies.size(); ++id) {
      const Body& b = scene.bodies[id];
      if (b.live && b.velocity != Vec3::Zero())
        trio.move(static_cast<ProxyId>(id), b.box(), b.velocity * dt);
    }
    // Destroy `churn` random live proxies, then create as many (recycling their ids).
    for (int c = 0; c < churn; ++c) {
      const auto id = static_cast<ProxyId>(std::uniform_int_distribution<std::size_t>(
          0, scene.bodies.size() - 1)(scene.rng));
      if (!scene.bodies[static_cast<std::size_t>(id)].live) continue;
      trio.destroy(id);
      scene.bodies[static_cast<std::size_t>(id)].live = false;
    }
    for (int c = 0; c < churn; ++c) {
      const Body b = scene.random_body();
      scene.place(trio.create(b.box()), b);
    }
    // Validation is O(n log n) per algorithm; every 5th update keeps the 10000 case quick.
    const bool validate = n <= 1000 || u % 5 == 0;
    const std::vector<ProxyPair> pairs = trio.pairs(validate);
    if (check_oracle) {
      EXPECT_EQ(pairs, naive_pairs(scene.boxes(), scene.live())) << "update " << u;
    }
    total += pairs.size();
    if (::testing::Test::HasFailure()) {
      ADD_FAILURE() << "n = " << n << ", seed = " << seed << ", first failing update " << u;
      break;
    }
  }
  return total;
}

// ---- Random scenes: all three algorithms identical every update. ----

TEST(BroadphaseRandom, Boxes10) {
  for (std::uint64_t seed = 1; seed <= 20; ++seed) run_random_scene(10, 50, seed, true);
}

TEST(BroadphaseRandom, Boxes100) {
  const std::size_t total = run_random_scene(100, 50, 7, true);
  EXPECT_GT(total, 50u * 20u);  // the scene must actually produce pairs to compare
}

TEST(BroadphaseRandom, Boxes1000) {
  const std::size_t total = run_random_scene(1000, 50, 11, true);
  EXPECT_GT(total, 50u * 200u);
}

TEST(BroadphaseRandom, Boxes10000) {
  // 8 updates: brute force is O(n^2) (5e7 box tests per update), and this case must stay
  // around 2 s in Release on a loaded machine.
  const std::size_t total = run_random_scene(10000, 8, 13, false);
  EXPECT_GT(total, 8u * 2000u);
}

TEST(BroadphaseRandom, FarFromOrigin) {
  // Same scene 1e4 m from the origin on every axis.
  run_random_scene(300, 30, 17, true, Vec3::Constant(1e4));
}

// ---- Edge cases. ----

TEST(BroadphaseEdge, TouchingBoxesOverlap) {
  // Closed intervals: a shared face, edge or corner counts as overlap.
  Trio t;
  const ProxyId a = t.create(Aabb(Vec3(0, 0, 0), Vec3(1, 1, 1)));
  const ProxyId face = t.create(Aabb(Vec3(1, 0, 0), Vec3(2, 1, 1)));
  const ProxyId edge = t.create(Aabb(Vec3(-1, 1, 0), Vec3(0, 2, 1)));
  const ProxyId corner = t.create(Aabb(Vec3(1, 1, 1), Vec3(2, 2, 2)) );
  // Apart by the smallest representable gap above 1.0 on x: no overlap.
  const Real gap = std::nextafter(1.0, 2.0);
  const ProxyId apart = t.create(Aabb(Vec3(gap, -3, -3), Vec3(gap, -2, -2)));
  const std::vector<ProxyPair> pairs = t.pairs();
  const std::vector<ProxyPair> expected = {{a, face}, {a, edge}, {a, corner}, {face, corner}};
  EXPECT_EQ(pairs, expected);
  (void)apart;
}

TEST(BroadphaseEdge, ZeroSizeBoxes) {
  Trio t;
  const ProxyId p0 = t.create(Aabb(Vec3(0.5, 0.5, 0.5), Vec3(0.5, 0.5, 0.5)));  // point
  const ProxyId p1 = t.create(Aabb(Vec3(0.5, 0.5, 0.5), Vec3(0.5, 0.5, 0.5)));  // same point
  const ProxyId box = t.create(Aabb(Vec3(0, 0, 0), Vec3(1, 1, 1)));
  const ProxyId on_face = t.create(Aabb(Vec3(1, 0.2, 0.2), Vec3(1, 0.2, 0.2)));  // point on a face
  const ProxyId flat = t.create(Aabb(Vec3(-5, -5, 1), Vec3(5, 5, 1)));  // zero-thickness plate on top
  const ProxyId outside = t.create(Aabb(Vec3(3, 3, 3), Vec3(3, 3, 3)));
  const std::vector<ProxyPair> expected = {{p0, p1}, {p0, box}, {p1, box}, {box, on_face}, {box, flat}};
  EXPECT_EQ(t.pairs(), expected);
  (void)outside;
}

TEST(BroadphaseEdge, IdenticalBoxes) {
  Trio t;
  constexpr int n = 60;
  for (int i = 0; i < n; ++i) t.create(Aabb(Vec3(1, 2, 3), Vec3(2, 3, 4)));
  const std::vector<ProxyPair> pairs = t.pairs();
  ASSERT_EQ(pairs.size(), static_cast<std::size_t>(n * (n - 1) / 2));
  EXPECT_EQ(pairs.front(), ProxyPair(0, 1));
  EXPECT_EQ(pairs.back(), ProxyPair(n - 2, n - 1));
  // Moving them all together by the same amount changes nothing.
  for (int step = 1; step <= 5; ++step) {
    const Vec3 d = Vec3(0.3, -0.2, 0.1) * step;
    for (ProxyId id = 0; id < n; ++id) t.move(id, Aabb(Vec3(1, 2, 3) + d, Vec3(2, 3, 4) + d), d);
    EXPECT_EQ(t.pairs(), pairs);
  }
}

TEST(BroadphaseEdge, AllBoxesOnALine) {
  // Unit boxes on the z axis, 0.75 m apart: exactly the neighbours (i, i+1) overlap.
  // x and y spreads are zero, so sweep and prune must cope with degenerate variance, and
  // the tree with a sorted insertion order (its worst case without rebalancing).
  for (int axis = 0; axis < 3; ++axis) {
    Trio t;
    constexpr int n = 500;
    for (int i = 0; i < n; ++i) {
      Vec3 c = Vec3::Zero();
      c[axis] = 0.75 * i;
      t.create(Aabb(c - Vec3::Constant(0.5), c + Vec3::Constant(0.5)));
    }
    const std::vector<ProxyPair> pairs = t.pairs();
    ASSERT_EQ(pairs.size(), static_cast<std::size_t>(n - 1));
    for (int i = 0; i + 1 < n; ++i) EXPECT_EQ(pairs[static_cast<std::size_t>(i)], ProxyPair(i, i + 1));
    EXPECT_EQ(t.bp[1]->stats().sweep_axis, axis);
    // An AVL-balanced tree of n leaves has height < 1.44 log2(n + 2) (Knuth, TAOCP 3,
    // 6.2.3); our single rotations keep it within twice the perfectly balanced
    // height, ceil(log2 n) = 9 here, which a degenerate list (height n - 1) would not.
    EXPECT_LE(t.bp[2]->stats().height, 2 * static_cast<int>(std::ceil(std::log2(n))));
  }
}

TEST(BroadphaseEdge, HugeCoordinates) {
  // Unit boxes at 1e4 m separated by 1e-6 m gaps (about 500 ulps of 1e4) or touching:
  // the pair decisions must still be exact.
  Trio t;
  const Vec3 o = Vec3::Constant(1e4);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 40; ++i) {
    const Real x = o.x() + i * (1.0 + (i % 2 ? 1e-6 : 0.0));
    boxes.emplace_back(Vec3(x, o.y(), o.z()), Vec3(x + 1.0, o.y() + 1.0, o.z() + 1.0));
    t.create(boxes.back());
  }
  EXPECT_EQ(t.pairs(), naive_pairs(boxes, std::vector<bool>(boxes.size(), true)));
  // Far-from-origin random motion, and a sweep through -1e4 too.
  for (int step = 0; step < 20; ++step) {
    for (std::size_t i = 0; i < boxes.size(); ++i) {
      const Vec3 d(0.01 * std::sin(0.3 * static_cast<Real>(i + step)), 0.02 * (i % 3), -0.01);
      boxes[i] = Aabb(boxes[i].min + d, boxes[i].max + d);
      t.move(static_cast<ProxyId>(i), boxes[i], d);
    }
    EXPECT_EQ(t.pairs(), naive_pairs(boxes, std::vector<bool>(boxes.size(), true)));
  }
  Trio neg;
  for (int i = 0; i < 30; ++i) {
    const Vec3 c(-1e4 + 0.9 * i, -1e4, 1e4);
    neg.create(Aabb(c - Vec3::Constant(0.5), c + Vec3::Constant(0.5)));
  }
  EXPECT_EQ(neg.pairs().size(), 29u);
}

TEST(BroadphaseEdge, EmptyAndSingle) {
  Trio t;
  EXPECT_TRUE(t.pairs().empty());
  const ProxyId a = t.create(Aabb(Vec3::Zero(), Vec3::Ones()));
  EXPECT_TRUE(t.pairs().empty());
  t.destroy(a);
  EXPECT_TRUE(t.pairs().empty());
  for (auto& b : t.bp) EXPECT_EQ(b->proxy_count(), 0);
}

// ---- Ids and input validation. ----

TEST(BroadphaseIds, DenseAndRecycledLifo) {
  for (BroadphaseType type : kAll) {
    auto bp = make_broadphase(type);
    const Aabb box(Vec3::Zero(), Vec3::Ones());
    for (int i = 0; i < 5; ++i) EXPECT_EQ(bp->create_proxy(box, 100 + i), i);
    bp->destroy_proxy(1);
    bp->destroy_proxy(3);
    EXPECT_EQ(bp->create_proxy(box), 3);  // most recently destroyed first
    EXPECT_EQ(bp->create_proxy(box), 1);
    EXPECT_EQ(bp->create_proxy(box), 5);
    EXPECT_EQ(bp->user_data(4), 104u);
    EXPECT_EQ(bp->proxy_count(), 6);
    EXPECT_EQ(bp->id_capacity(), 6);
  }
}

TEST(BroadphaseIds, DestroyAndRecreateBeforeUpdate) {
  // An id destroyed and re-created between two updates must show the new box only.
  Trio t;
  const ProxyId a = t.create(Aabb(Vec3(0, 0, 0), Vec3(1, 1, 1)));
  const ProxyId b = t.create(Aabb(Vec3(0.5, 0, 0), Vec3(1.5, 1, 1)));
  const ProxyId c = t.create(Aabb(Vec3(10, 0, 0), Vec3(11, 1, 1)));
  EXPECT_EQ(t.pairs(), (std::vector<ProxyPair>{{a, b}}));
  t.destroy(b);
  EXPECT_EQ(t.create(Aabb(Vec3(10.5, 0, 0), Vec3(11.5, 1, 1))), b);
  EXPECT_EQ(t.pairs(), (std::vector<ProxyPair>{{b, c}}));
}

TEST(BroadphaseIds, BadInputThrows) {
  for (BroadphaseType type : kAll) {
    auto bp = make_broadphase(type);
    const Real nan = std::numeric_limits<Real>::quiet_NaN();
    EXPECT_THROW(bp->create_proxy(Aabb(Vec3(nan, 0, 0), Vec3::Ones())), InvalidArgument);
    EXPECT_THROW(bp->create_proxy(Aabb(Vec3::Zero(), Vec3(1, kInf, 1))), InvalidArgument);
    EXPECT_THROW(bp->create_proxy(Aabb(Vec3(0, 2, 0), Vec3(1, 1, 1))), InvalidArgument);  // min > max
    EXPECT_THROW(bp->create_proxy(Aabb()), InvalidArgument);  // the default (empty) Aabb
    const ProxyId id = bp->create_proxy(Aabb(Vec3::Zero(), Vec3::Ones()));
    EXPECT_THROW(bp->move_proxy(id, Aabb(Vec3::Ones(), Vec3::Zero())), InvalidArgument);
    EXPECT_THROW(bp->move_proxy(id, Aabb(Vec3::Zero(), Vec3::Ones()), Vec3(nan, 0, 0)), InvalidArgument);
    EXPECT_THROW(bp->move_proxy(7, Aabb(Vec3::Zero(), Vec3::Ones())), InvalidArgument);
    EXPECT_THROW(bp->move_proxy(-1, Aabb(Vec3::Zero(), Vec3::Ones())), InvalidArgument);
    EXPECT_THROW(bp->aabb(3), InvalidArgument);
    bp->destroy_proxy(id);
    EXPECT_THROW(bp->destroy_proxy(id), InvalidArgument);  // stale id
    EXPECT_THROW(bp->query_aabb(Aabb(), [](ProxyId) { return true; }), InvalidArgument);
    auto ray_cb = [](ProxyId, Real t) { return t; };
    EXPECT_THROW(bp->raycast(Vec3::Zero(), Vec3::Zero(), 1.0, ray_cb), InvalidArgument);
    EXPECT_THROW(bp->raycast(Vec3::Zero(), Vec3::UnitX(), -1.0, ray_cb), InvalidArgument);
    EXPECT_THROW(bp->raycast(Vec3::Zero(), Vec3::UnitX(), nan, ray_cb), InvalidArgument);
    EXPECT_THROW(bp->raycast(Vec3(nan, 0, 0), Vec3::UnitX(), 1.0, ray_cb), InvalidArgument);
    // A failed call leaves the broadphase usable.
    bp->update();
    bp->validate();
  }
  BroadphaseSettings s;
  s.aabb_margin = -0.1;
  EXPECT_THROW(make_broadphase(BroadphaseType::kAabbTree, s), InvalidArgument);
}

// ---- Box and ray queries. ----

TEST(BroadphaseQuery, AabbQueryMatchesOracle) {
  Scene scene(23, 20.0, Vec3::Zero());
  Trio t;
  for (int i = 0; i < 400; ++i) {
    const Body b = scene.random_body();
    scene.place(t.create(b.box()), b);
  }
  t.pairs();  // updated state; queries must also see later moves (checked below)
  std::mt19937_64 rng(5);
  std::uniform_real_distribution<Real> u(-2, 22);
  for (int q = 0; q < 50; ++q) {
    if (q == 25) {  // move everything without calling update(): queries must see it
      scene.step(0.5);
      for (std::size_t id = 0; id < scene.bodies.size(); ++id)
        t.move(static_cast<ProxyId>(id), scene.bodies[id].box());
    }
    const Vec3 a(u(rng), u(rng), u(rng));
    const Vec3 b = a + Vec3(u(rng), u(rng), u(rng)).cwiseAbs() * 0.3;
    const Aabb box(a, b);
    std::vector<ProxyId> expected;
    for (std::size_t id = 0; id < scene.bodies.size(); ++id)
      if (scene.bodies[id].box().overlaps(box)) expected.push_back(static_cast<ProxyId>(id));
    for (auto& bp : t.bp) {
      std::vector<ProxyId> got;
      bp->query_aabb(box, [&](ProxyId id) {
        got.push_back(id);
        return true;
      });
      std::sort(got.begin(), got.end());
      EXPECT_EQ(got, expected) << to_string(bp->type()) << " query " << q;
    }
  }
  // Early stop: the callback returning false ends the query after one result.
  for (auto& bp : t.bp) {
    int calls = 0;
    bp->query_aabb(Aabb(Vec3::Constant(-100), Vec3::Constant(100)), [&](ProxyId) {
      ++calls;
      return false;
    });
    EXPECT_EQ(calls, 1) << to_string(bp->type());
  }
}

TEST(BroadphaseQuery, RaycastMatchesOracle) {
  Scene scene(29, 20.0, Vec3::Zero());
  Trio t;
  for (int i = 0; i < 300; ++i) {
    const Body b = scene.random_body();
    scene.place(t.create(b.box()), b);
  }
  t.pairs();
  std::mt19937_64 rng(6);
  std::uniform_real_distribution<Real> u(-1, 1);
  for (int q = 0; q < 60; ++q) {
    const Vec3 origin = Vec3(10, 10, 10) + 12.0 * Vec3(u(rng), u(rng), u(rng));
    Vec3 dir(u(rng), u(rng), u(rng));
    if (q % 4 == 0) dir = Vec3(0, 0, u(rng) < 0 ? -1.0 : 1.0);  // axis-parallel: zero components
    const Real max_t = 30.0;
    // Oracle: all hits with their entry parameters, by the library's slab test. The slab
    // test itself is checked in RayAabbSlab.
    std::vector<std::pair<ProxyId, Real>> all;
    for (std::size_t id = 0; id < scene.bodies.size(); ++id) {
      Real te;
      if (ray_aabb(origin, dir, scene.bodies[id].box(), max_t, te)) all.emplace_back(static_cast<ProxyId>(id), te);
    }
    Real closest = kInf;
    for (const auto& h : all) closest = std::min(closest, h.second);
    for (auto& bp : t.bp) {
      std::vector<std::pair<ProxyId, Real>> got;
      bp->raycast(origin, dir, max_t, [&](ProxyId id, Real te) {
        got.emplace_back(id, te);
        return max_t;  // see every hit
      });
      std::sort(got.begin(), got.end());
      EXPECT_EQ(got, all) << to_string(bp->type()) << " ray " << q;
      // Closest-hit search by clipping: the last reported t is the closest.
      Real best = kInf;
      bp->raycast(origin, dir, max_t, [&](ProxyId, Real te) {
        best = std::min(best, te);
        return te;
      });
      EXPECT_EQ(best, closest) << to_string(bp->type()) << " ray " << q;
    }
  }
}

TEST(BroadphaseQuery, RayAabbSlab) {
  const Aabb box(Vec3(1, -1, -1), Vec3(3, 1, 1));
  Real t = -1;
  EXPECT_TRUE(ray_aabb(Vec3(0, 0, 0), Vec3(1, 0, 0), box, 10, t));
  EXPECT_EQ(t, 1.0);
  EXPECT_TRUE(ray_aabb(Vec3(0, 0, 0), Vec3(2, 0, 0), box, 10, t));  // t in units of |dir|
  EXPECT_EQ(t, 0.5);
  EXPECT_FALSE(ray_aabb(Vec3(0, 0, 0), Vec3(1, 0, 0), box, 0.5, t));  // too short
  EXPECT_FALSE(ray_aabb(Vec3(0, 0, 0), Vec3(-1, 0, 0), box, 10, t));  // pointing away
  EXPECT_TRUE(ray_aabb(Vec3(2, 0, 0), Vec3(0, 1, 0), box, 10, t));   // origin inside
  EXPECT_EQ(t, 0.0);
  // Along a face plane (y = 1 exactly, dir.y = 0): closed box, so it hits, and the
  // 0 * inf of a naive slab test must not produce a NaN miss.
  EXPECT_TRUE(ray_aabb(Vec3(0, 1, 0), Vec3(1, 0, 0), box, 10, t));
  EXPECT_EQ(t, 1.0);
  EXPECT_FALSE(ray_aabb(Vec3(0, 1.5, 0), Vec3(1, 0, 0), box, 10, t));
  // A direction so small that 1/d overflows on an axis is treated as parallel there.
  EXPECT_TRUE(ray_aabb(Vec3(0, 0, 0), Vec3(1, 1e-320, 0), box, 10, t));
  EXPECT_EQ(t, 1.0);
  // Infinite max_t is allowed.
  EXPECT_TRUE(ray_aabb(Vec3(-1e6, 0, 0), Vec3(1, 0, 0), box, kInf, t));
  EXPECT_EQ(t, 1e6 + 1);
}

// ---- Algorithm-specific behaviour. ----

TEST(AabbTree, ReinsertsOnlyWhenLeavingFatBox) {
  BroadphaseSettings s;
  s.aabb_margin = 0.1;
  s.displacement_multiplier = 0;
  auto bp = make_broadphase(BroadphaseType::kAabbTree, s);
  const Aabb box(Vec3::Zero(), Vec3::Ones());
  const ProxyId id = bp->create_proxy(box);
  bp->create_proxy(Aabb(Vec3::Constant(5), Vec3::Constant(6)));
  // Ten moves of 9 mm: 9 cm in total, still inside the 10 cm margin.
  for (int i = 1; i <= 10; ++i) {
    const Vec3 d(0.009 * i, 0, 0);
    bp->move_proxy(id, Aabb(box.min + d, box.max + d));
  }
  EXPECT_EQ(bp->stats().reinsertions, 0);
  bp->move_proxy(id, Aabb(box.min + Vec3(0.11, 0, 0), box.max + Vec3(0.11, 0, 0)));  // leaves it
  bp->update();  // moves out of fat boxes are placed in the tree here
  EXPECT_EQ(bp->stats().reinsertions, 1);
  EXPECT_EQ(bp->stats().rebuilds, 0);
  bp->validate();
}

// keep_proxy_unchecked (the world's per-step fast path) decides as move_proxy would:
// it keeps exactly the moves that leave the fat box as it is, declines the others
// without changing anything, declines a second move of a proxy whose first is still
// pending, and never keeps a non-finite box. Brute force has no fat boxes: it always
// declines. Random moves of every size against a second tree moved by move_proxy alone:
// the same pairs, the same reinsertions, every step.
TEST(AabbTree, KeepDecidesAsMoveWould) {
  Scene scene(91, 10.0, Vec3::Zero());
  std::mt19937 rng(5);
  std::uniform_real_distribution<Real> u(-1, 1);
  auto kept = make_broadphase(BroadphaseType::kAabbTree);
  auto moved = make_broadphase(BroadphaseType::kAabbTree);
  auto brute = make_broadphase(BroadphaseType::kBruteForce);
  std::vector<Aabb> boxes;
  for (int i = 0; i < 300; ++i) {
    boxes.push_back(scene.random_body().box());
    kept->create_proxy(boxes.back());
    moved->create_proxy(boxes.back());
    brute->create_proxy(boxes.back());
  }
  std::vector<ProxyPair> a, b;
  int keeps = 0, declines = 0;
  for (int step = 0; step < 60; ++step) {
    for (int i = 0; i < 300; ++i) {
      // Small moves mostly (kept), now and then one out of the fat box or a velocity
      // change that makes it too loose (declined).
      const Real size = (i + step) % 7 == 0 ? 0.5 : 0.01;
      const Vec3 d(size * u(rng), size * u(rng), size * u(rng));
      const Vec3 disp = (i % 3 == 0) ? Vec3(0.2 * u(rng), 0.2 * u(rng), 0) : Vec3::Zero();
      boxes[i] = Aabb(boxes[i].min + d, boxes[i].max + d);
      EXPECT_FALSE(brute->keep_proxy_unchecked(i, boxes[i], disp));
      const Aabb before = kept->aabb(i);
      if (kept->keep_proxy_unchecked(i, boxes[i], disp)) {
        ++keeps;
        EXPECT_EQ(kept->aabb(i).min, boxes[i].min);
      } else {
        ++declines;
        EXPECT_EQ(kept->aabb(i).min, before.min);  // declined: unchanged
        kept->move_proxy(i, boxes[i], disp);
        // Pending now: a second move before update() is never kept.
        EXPECT_FALSE(kept->keep_proxy_unchecked(i, boxes[i], disp));
      }
      moved->move_proxy(i, boxes[i], disp);
      brute->move_proxy(i, boxes[i], disp);
    }
    kept->query_pairs(a);
    moved->query_pairs(b);
    ASSERT_EQ(a, b) << "step " << step;
    brute->query_pairs(b);
    ASSERT_EQ(a, b) << "step " << step;
    EXPECT_EQ(kept->stats().reinsertions + kept->stats().refits, moved->stats().reinsertions + moved->stats().refits);
    kept->validate();
  }
  EXPECT_GT(keeps, 1000);
  EXPECT_GT(declines, 100);
  const Real nan = std::numeric_limits<Real>::quiet_NaN();
  EXPECT_FALSE(kept->keep_proxy_unchecked(0, Aabb(Vec3::Constant(nan), Vec3::Constant(nan)), Vec3::Zero()));
  EXPECT_FALSE(kept->keep_proxy_unchecked(0, kept->aabb(0), Vec3(nan, 0, 0)));
}

// A tree and the brute-force reference holding the same `n` random boxes of `scene`.
struct TreeAndReference {
  std::unique_ptr<Broadphase> tree, brute;
  std::vector<Aabb> boxes;
};
TreeAndReference tree_and_brute_force(Scene& scene, int n) {
  TreeAndReference r{make_broadphase(BroadphaseType::kAabbTree), make_broadphase(BroadphaseType::kBruteForce), {}};
  for (int i = 0; i < n; ++i) {
    r.boxes.push_back(scene.random_body().box());
    r.tree->create_proxy(r.boxes.back());
    r.brute->create_proxy(r.boxes.back());
  }
  return r;
}

// Many leaves leaving their boxes at once rebuild the tree; pairs, queries and rays
// stay exact, before the update (moves pending) and after it.
TEST(AabbTree, MassMovesRebuildAndStayExact) {
  Scene scene(77, 20.0, Vec3::Zero());
  auto [tree, brute, boxes] = tree_and_brute_force(scene, 400);
  std::vector<ProxyPair> a, b;
  tree->query_pairs(a);
  for (int frame = 0; frame < 5; ++frame) {
    // Everything moves 1.5 m: far out of the 0.1 m fat boxes.
    const Vec3 d(1.5, -1.5 * frame, 0.5);
    for (int i = 0; i < 400; ++i) {
      const Aabb moved(boxes[i].min + d, boxes[i].max + d);
      tree->move_proxy(i, moved);
      brute->move_proxy(i, moved);
      boxes[i] = moved;
    }
    // Queries before the update see the moved boxes.
    const Aabb probe(boxes[7].min, boxes[7].min + Vec3::Constant(0.5));
    std::vector<ProxyId> qt, qb;
    tree->query_aabb(probe, [&](ProxyId id) { qt.push_back(id); return true; });
    brute->query_aabb(probe, [&](ProxyId id) { qb.push_back(id); return true; });
    std::sort(qt.begin(), qt.end());
    std::sort(qb.begin(), qb.end());
    EXPECT_EQ(qt, qb);
    std::vector<ProxyId> rt, rb;
    const Vec3 origin = boxes[3].center() - Vec3(30, 0, 0);
    tree->raycast(origin, Vec3::UnitX(), 60, [&](ProxyId id, Real) { rt.push_back(id); return Real(60); });
    brute->raycast(origin, Vec3::UnitX(), 60, [&](ProxyId id, Real) { rb.push_back(id); return Real(60); });
    std::sort(rt.begin(), rt.end());
    std::sort(rb.begin(), rb.end());
    EXPECT_EQ(rt, rb);
    EXPECT_FALSE(rt.empty());
    tree->query_pairs(a);
    brute->query_pairs(b);
    EXPECT_EQ(a, b) << "frame " << frame;
    tree->validate();
  }
  // The first mass move rebuilds (the tree was built by insertions); the others move
  // every box by the same translation, which keeps the structure as good as new: refits.
  EXPECT_EQ(tree->stats().rebuilds, 1);
  EXPECT_EQ(tree->stats().refits, 4);
  EXPECT_EQ(tree->stats().reinsertions, 5 * 400);
}

// A mass move that scatters the boxes (each to a random place) degrades a refitted
// tree, so the tree is rebuilt instead; a coherent one (all boxes moved alike) keeps
// the structure. Pairs stay exact either way.
TEST(AabbTree, MassMovesRefitWhenCoherentAndRebuildWhenScattered) {
  Scene scene(91, 20.0, Vec3::Zero());
  auto [tree, brute, boxes] = tree_and_brute_force(scene, 400);
  auto move_all = [&](auto&& where) {
    for (int i = 0; i < 400; ++i) {
      boxes[i] = where(i);
      tree->move_proxy(i, boxes[i]);
      brute->move_proxy(i, boxes[i]);
    }
    std::vector<ProxyPair> a, b;
    tree->query_pairs(a);
    brute->query_pairs(b);
    EXPECT_EQ(a, b);
    tree->validate();
  };
  const Vec3 d(0, -2.0, 0);
  move_all([&](int i) { return Aabb(boxes[i].min + d, boxes[i].max + d); });  // first: rebuild
  EXPECT_EQ(tree->stats().rebuilds, 1);
  for (int k = 0; k < 3; ++k) move_all([&](int i) { return Aabb(boxes[i].min + d, boxes[i].max + d); });
  EXPECT_EQ(tree->stats().rebuilds, 1);
  EXPECT_EQ(tree->stats().refits, 3);
  move_all([&](int) { return scene.random_body().box(); });  // scattered
  EXPECT_EQ(tree->stats().rebuilds, 2);
  EXPECT_EQ(tree->stats().refits, 3);
}

TEST(AabbTree, ResultsIndependentOfMargin) {
  // The fat margin changes the candidates, never the pairs.
  Scene scene(31, 15.0, Vec3::Zero());
  std::vector<std::unique_ptr<Broadphase>> trees;
  for (Real margin : {0.0, 0.01, 0.1, 2.0}) {
    BroadphaseSettings s;
    s.aabb_margin = margin;
    trees.push_back(make_broadphase(BroadphaseType::kAabbTree, s));
  }
  for (int i = 0; i < 200; ++i) {
    const Body b = scene.random_body();
    ProxyId id = 0;
    for (auto& t : trees) id = t->create_proxy(b.box());
    scene.place(id, b);
  }
  for (int u = 0; u < 30; ++u) {
    scene.step(1.0 / 30.0);
    for (std::size_t id = 0; id < scene.bodies.size(); ++id)
      for (auto& t : trees) t->move_proxy(static_cast<ProxyId>(id), scene.bodies[id].box(), scene.bodies[id].velocity / 30.0);
    std::vector<ProxyPair> first, other;
    trees[0]->query_pairs(first);
    EXPECT_EQ(first, naive_pairs(scene.boxes(), scene.live()));
    for (std::size_t k = 1; k < trees.size(); ++k) {
      trees[k]->query_pairs(other);
      trees[k]->validate();
      EXPECT_EQ(other, first) << "margin index " << k;
    }
  }
  // A larger margin means more (false) candidates and fewer reinsertions.
  EXPECT_GE(trees[3]->stats().candidate_pairs, trees[0]->stats().candidate_pairs);
  EXPECT_LT(trees[3]->stats().reinsertions, trees[1]->stats().reinsertions);
}

TEST(SweepAndPrune, SwitchesToAxisOfGreatestSpread) {
  auto bp = make_broadphase(BroadphaseType::kSweepAndPrune);
  constexpr int n = 100;
  auto layout = [&](int axis) {
    for (ProxyId i = 0; i < n; ++i) {
      Vec3 c = Vec3::Constant(0.1 * (i % 3));  // a little spread on the other axes
      c[axis] = 2.0 * i;
      const Aabb box(c - Vec3::Constant(0.5), c + Vec3::Constant(0.5));
      if (bp->is_live(i)) bp->move_proxy(i, box);
      else bp->create_proxy(box);
    }
  };
  std::vector<ProxyPair> pairs;
  layout(2);
  bp->query_pairs(pairs);
  EXPECT_EQ(bp->stats().sweep_axis, 2);
  layout(0);  // the row is turned from z to x: must switch
  bp->query_pairs(pairs);
  bp->validate();
  EXPECT_EQ(bp->stats().sweep_axis, 0);
  EXPECT_EQ(bp->stats().axis_changes, 1);
  EXPECT_TRUE(pairs.empty());  // 2 m apart, 1 m boxes
}

TEST(BroadphaseSteadyState, NoAllocationPerFrame) {
  // 500 boxes oscillating (period 40 frames, amplitude 0.6 m, beyond the tree's margin so
  // leaves are reinserted): after two periods of warm-up every buffer has reached its
  // working size, and further frames of move + update + query_pairs must not allocate.
  for (BroadphaseType type : kAll) {
    auto bp = make_broadphase(type);
    Scene scene(37, 18.0, Vec3::Zero());
    std::vector<Vec3> base;
    for (int i = 0; i < 500; ++i) {
      const Body b = scene.random_body();
      base.push_back(b.center);
      scene.place(bp->create_proxy(b.box()), b);
    }
    std::vector<ProxyPair> pairs;
    long long allocations = 0;
    for (int frame = 0; frame < 160; ++frame) {
      const bool counted = frame >= 80;
      g_allocations = 0;
      g_count_allocations = counted;
      const Real phase = 2.0 * kPi * frame / 40.0;
      for (std::size_t id = 0; id < base.size(); ++id) {
        Body& b = scene.bodies[id];
        b.center = base[id] + 0.6 * std::sin(phase + 0.01 * static_cast<Real>(id)) * Vec3(1, 0.5, -0.3);
        bp->move_proxy(static_cast<ProxyId>(id), b.box());
      }
      bp->update();
      bp->query_pairs(pairs);
      g_count_allocations = false;
      if (counted) allocations += g_allocations;
    }
    EXPECT_EQ(allocations, 0) << to_string(type);
    EXPECT_GT(pairs.size(), 100u);  // a non-trivial scene
    if (type == BroadphaseType::kAabbTree) EXPECT_GT(bp->stats().reinsertions, 500);
  }
}

}  // namespace
}  // namespace wmo
