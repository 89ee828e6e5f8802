// Broadphase benchmark: time per frame of (move every proxy + update + query_pairs) for
// each algorithm and N in {100, 300, 1000, 3000, 10000, 30000, 100000}.
//
// Scene ("falling pile" density): N boxes with half extents uniform in [0.2, 0.5] m
// (0.4 to 1 m bodies), centres uniform in a slab L x L/4 x L (y up) holding 1 m^3 per box,
// i.e. wider than tall like a pile spreading on the ground. Two such boxes overlap when
// their centres are within (h1 + h2) per axis, a volume of about (4 * 0.35 m)^3 = 2.7 m^3,
// so each box overlaps about 2.7 others (a settled pile touches 3 to 6 neighbours). Every
// box moves each frame by a constant random velocity of up to 1 m/s per axis, dt = 1/60 s
// (<= 1.7 cm per frame), bouncing off the slab walls so the density stays put; the
// displacement is passed to move_proxy for the tree's predictive fattening.
//
// Timing: 10 warm-up frames, then the median of `frames` timed frames (41 up to N = 3000,
// 21 up to 30000, 11 above). New box positions are computed before the timer starts, so
// only broadphase work is timed. Brute force is skipped above N = 10000 (O(n^2): at
// 10000 it already takes ~5e7 box tests per frame). Allocations inside timed frames are
// counted by a replaced global operator new and printed (the broadphases promise none in
// steady state).
//
// Usage: bench_broadphase [output_dir [max_n [algorithm]]]
//   writes output_dir/broadphase.csv (default "."); max_n and algorithm (brute_force,
//   sweep_and_prune or aabb_tree) restrict the run, e.g. for profiling.
#include <algorithm>
#include <atomic>
#include <chrono>
#include <cmath>
#include <cstdint>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <new>
#include <random>
#include <string>
#include <vector>

#include "wmo/collision/broadphase.h"

namespace {
std::atomic<long long> g_allocations{0};
}  // namespace

// Counting allocator hooks for the "no allocation in steady state" report.
void* operator new(std::size_t n) {
  g_allocations.fetch_add(1, std::memory_order_relaxed);
  if (void* p = std::malloc(n ? n : 1)) return p;
  throw std::bad_alloc();
}
void* operator new[](std::size_t n) { return operator new(n); }
void operator delete(void* p) noexcept { std::free(p); }
void operator delete[](void* p) noexcept { std::free(p); }
void operator delete(void* p, std::size_t) noexcept { std::free(p); }
void operator delete[](void* p, std::size_t) noexcept { std::free(p); }

namespace {

using wmo::Aabb;
using wmo::Real;
using wmo::Vec3;

constexpr int kBruteForceCap = 10000;
constexpr Real kDt = 1.0 / 60.0;

struct PileScene {
  std::vector<Vec3> center, half, velocity;
  Vec3 lo = Vec3::Zero(), hi = Vec3::Zero();

  PileScene(int n, std::uint64_t seed) {
    std::mt19937_64 rng(seed);
    std::uniform_real_distribution<Real> u01(0.0, 1.0), uh(0.2, 0.5), uv(-1.0, 1.0);
    const Real volume = 1.0 * n;                 // 1 m^3 per box
    const Real l = std::cbrt(4.0 * volume);      // L * L/4 * L = volume
    hi = Vec3(l, l / 4.0, l);
    for (int i = 0; i < n; ++i) {
      center.emplace_back(u01(rng) * hi.x(), u01(rng) * hi.y(), u01(rng) * hi.z());
      half.emplace_back(uh(rng), uh(rng), uh(rng));
      velocity.emplace_back(uv(rng), uv(rng), uv(rng));
    }
  }
  void step() {
    for (std::size_t i = 0; i < center.size(); ++i) {
      center[i] += velocity[i] * kDt;
      for (int k = 0; k < 3; ++k)
        if (center[i][k] < lo[k] || center[i][k] > hi[k]) velocity[i][k] = -velocity[i][k];
    }
  }
  Aabb box(std::size_t i) const { return Aabb(center[i] - half[i], center[i] + half[i]); }
};

struct Result {
  double median_us;
  std::size_t pairs;
  long long allocations;
  double reinsertions_per_frame;  // tree only
};

Result run(wmo::BroadphaseType type, int n) {
  PileScene scene(n, 12345);
  auto bp = wmo::make_broadphase(type);
  std::vector<wmo::ProxyId> ids;
  for (int i = 0; i < n; ++i) ids.push_back(bp->create_proxy(scene.box(static_cast<std::size_t>(i))));
  std::vector<wmo::ProxyPair> pairs;
  std::vector<Aabb> boxes(static_cast<std::size_t>(n));
  std::vector<Vec3> disp(static_cast<std::size_t>(n));
  const int warmup = 10;
  const int frames = n <= 3000 ? 41 : (n <= 30000 ? 21 : 11);
  std::vector<double> times;
  times.reserve(static_cast<std::size_t>(frames));  // no allocation inside the timed loop
  long long allocs = 0;
  std::int64_t reinsertions = 0;
  for (int f = 0; f < warmup + frames; ++f) {
    scene.step();
    for (std::size_t i = 0; i < boxes.size(); ++i) {
      boxes[i] = scene.box(i);
      disp[i] = scene.velocity[i] * kDt;
    }
    const std::int64_t r0 = bp->stats().reinsertions;
    const long long a0 = g_allocations.load();
    const auto t0 = std::chrono::steady_clock::now();
    for (std::size_t i = 0; i < boxes.size(); ++i) bp->move_proxy(ids[i], boxes[i], disp[i]);
    bp->update();
    bp->query_pairs(pairs);
    const auto t1 = std::chrono::steady_clock::now();
    if (f >= warmup) {
      times.push_back(std::chrono::duration<double, std::micro>(t1 - t0).count());
      allocs += g_allocations.load() - a0;
      reinsertions += bp->stats().reinsertions - r0;
    }
  }
  std::nth_element(times.begin(), times.begin() + static_cast<long>(times.size() / 2), times.end());
  return {times[times.size() / 2], pairs.size(), allocs,
          static_cast<double>(reinsertions) / frames};
}

}  // namespace

int main(int argc, char** argv) {
  const std::string dir = argc > 1 ? argv[1] : ".";
  const int max_n = argc > 2 ? std::atoi(argv[2]) : 100000;
  const std::string only = argc > 3 ? argv[3] : "";
  const std::string path = dir + "/broadphase.csv";
  std::ofstream csv(path);
  if (!csv) {
    std::fprintf(stderr, "cannot write %s\n", path.c_str());
    return 1;
  }
  csv << "algorithm,n,median_us,pairs\n";
  const int sizes[] = {100, 300, 1000, 3000, 10000, 30000, 100000};
  const wmo::BroadphaseType types[] = {wmo::BroadphaseType::kBruteForce,
                                       wmo::BroadphaseType::kSweepAndPrune,
                                       wmo::BroadphaseType::kAabbTree};
  std::printf("%-16s %7s %12s %8s %13s %16s\n", "algorithm", "n", "median_us", "pairs", "allocs/frame",
              "reinserts/frame");
  for (int n : sizes) {
    if (n > max_n) break;
    std::size_t reference_pairs = 0;
    bool first = true;
    for (auto type : types) {
      if (type == wmo::BroadphaseType::kBruteForce && n > kBruteForceCap) continue;
      if (!only.empty() && only != wmo::to_string(type)) continue;
      const Result r = run(type, n);
      // Same scene, same frames: every algorithm must end with the same pair count.
      if (!first && r.pairs != reference_pairs)
        std::fprintf(stderr, "MISMATCH: %s reports %zu pairs, expected %zu\n", wmo::to_string(type),
                     r.pairs, reference_pairs);
      if (first) reference_pairs = r.pairs;
      first = false;
      const int frames = n <= 3000 ? 41 : (n <= 30000 ? 21 : 11);
      std::printf("%-16s %7d %12.1f %8zu %13.2f %16.1f\n", wmo::to_string(type), n, r.median_us,
                  r.pairs, static_cast<double>(r.allocations) / frames, r.reinsertions_per_frame);
      std::fflush(stdout);
      csv << wmo::to_string(type) << ',' << n << ',' << r.median_us << ',' << r.pairs << '\n';
    }
  }
  std::printf("wrote %s\n", path.c_str());
  return 0;
}
