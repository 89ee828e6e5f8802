// World overhead benchmark (issue 3, section 3: only the effects a scene calls for).
//
// 1. Free fall: 10,000 spheres (radius 0.1 m, 1 m apart on a 22 x 22 x 21 grid, so none
//    ever touches another) fall under gravity, no ground. WMO's World::step (defaults:
//    dt 1/60, 4 substeps) against a plain loop over arrays doing the same integration:
//    per substep v += h g, the centre of mass moves by h times the mean of the old and
//    new v (a free body's rule in World), the orientation by h w
//    (integrate_rotation, as the world does; it leaves the orientation of a body that
//    does not turn, as these spheres, unchanged: before it did that, the loop's
//    quaternion normalisations took 210 of its 313 us, the world's step was 586 us
//    where it is ~270-290 now, and the ratio below was ~1.9). The world also does
//    everything a step does when nothing touches (broadphase proxies moved, an empty
//    pair query, no contacts, no solver work; the sleep check passes over bodies in
//    free flight, see World::update_sleep), and that overhead is what the ratio shows.
//    The plain loop is the loop a user writes over the Vec3 rows; the world's own pass
//    runs over the rows as flat arrays of doubles, which the compiler vectorises
//    (World::integrate_plain_run), and is faster than it. So a last configuration,
//    plain_loop_flat, times that flat loop too, and the summary gives the world's
//    ratio against it as well: the overhead without the vectorisation's gain.
// 2. Features a scene does not use, each against its baseline on the same scene:
//    - free fall with sleeping off (nothing ever sleeps there) and with the gyroscopic
//      term on (spheres: isotropic inertia, the term is zero);
//    - a frictionless resting scene (10 x 10 unit boxes on a static ground, friction 0
//      everywhere) against the same scene whose boxes have friction 0.5 on a
//      frictionless ground, so the multiplied pair friction is still 0 (friction
//      switched on in the materials, none in any pair).
//
// Timing: per configuration a fresh world, 20 warm-up steps, then `steps` steps timed
// one by one; the median step time is the run's figure (the mean is written too: the
// free-fall world's tree refreshes every fat box together every few steps, a step
// several times the median that the median does not show). Configurations are run in
// interleaved rounds (default 7) so that drift of the machine hits all alike; the
// reported value is the median over rounds and the noise is the spread (max - min) of
// the baseline's rounds.
//
// Usage: bench_world_overhead [output_dir [rounds [steps]]]
//   writes output_dir/world_overhead.csv (default "."), one row per configuration and
//   round, and prints a summary.
#include <algorithm>
#include <chrono>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <memory>
#include <string>
#include <vector>

#include "wmo/world/world.h"

using namespace wmo;

namespace {

using Clock = std::chrono::steady_clock;

constexpr int kWarmup = 20;

/// Median and mean of one run's step times, seconds.
struct Timing {
  double median = 0, mean = 0;
};

double median(std::vector<double> v) {
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// The free-fall grid: 22 x 22 x 21 = 10164 cells, the first 10,000 used.
std::vector<Vec3> grid_positions() {
  std::vector<Vec3> p;
  for (int i = 0; i < 22 && p.size() < 10000; ++i)
    for (int j = 0; j < 21 && p.size() < 10000; ++j)
      for (int k = 0; k < 22 && p.size() < 10000; ++k) p.emplace_back(k - 10.5, 10.0 + j, i - 10.5);
  return p;
}

World free_fall_world(bool sleeping, bool gyroscopic) {
  WorldSettings s;
  s.enable_sleep = sleeping;
  s.gyroscopic = gyroscopic;
  World w(s);
  w.reserve(10000);
  auto sphere = std::make_shared<Sphere>(0.1);
  for (const Vec3& p : grid_positions()) {
    BodyDef d;
    d.shape = sphere;
    d.position = p;
    w.add_body(d);
  }
  return w;
}

World resting_world(Real box_friction) {
  WorldSettings s;
  s.enable_sleep = false;  // resting bodies would sleep and cost nothing at all
  World w(s);
  BodyDef g;
  g.shape = std::make_shared<Box>(Vec3(50, 1, 50));
  g.position = Vec3(0, -1, 0);
  g.kind = BodyKind::kStatic;
  g.friction = 0;
  w.add_body(g);
  auto box = std::make_shared<Box>(Vec3(0.5, 0.5, 0.5));
  for (int i = 0; i < 10; ++i)
    for (int j = 0; j < 10; ++j) {
      BodyDef d;
      d.shape = box;
      d.position = Vec3(1.5 * i - 6.75, 0.5, 1.5 * j - 6.75);
      d.friction = box_friction;
      w.add_body(d);
    }
  return w;
}

/// Mean seconds per step of each stage over the last timed run of the "world" config.
std::vector<double> g_stage_means;

Timing timing(const std::vector<double>& t) {
  double sum = 0;
  for (const double x : t) sum += x;
  return {median(t), sum / static_cast<double>(t.size())};
}

Timing time_world(World& w, int steps, bool keep_stages = false) {
  w.step(kWarmup);
  std::vector<double> before;
  for (const StageProfile& p : w.profile()) before.push_back(p.total_seconds);
  std::vector<double> t(steps);
  for (int k = 0; k < steps; ++k) {
    const auto t0 = Clock::now();
    w.step(1);
    t[k] = std::chrono::duration<double>(Clock::now() - t0).count();
  }
  if (keep_stages) {
    g_stage_means.clear();
    for (std::size_t s = 0; s < before.size(); ++s)
      g_stage_means.push_back((w.profile()[s].total_seconds - before[s]) / steps);
  }
  return timing(t);
}

/// The plain loop: the same integration over plain arrays, nothing else.
struct PlainFreeFall {
  std::vector<Vec3> com, v, w;
  std::vector<Quat> q;
  Vec3 gravity = WorldSettings{}.gravity;
  Real dt = WorldSettings{}.dt;
  int substeps = WorldSettings{}.substeps;

  PlainFreeFall() : com(grid_positions()) {
    v.assign(com.size(), Vec3::Zero());
    w.assign(com.size(), Vec3::Zero());
    q.assign(com.size(), Quat::Identity());
  }
  void step() {
    const Real h = dt / substeps;
    for (int s = 0; s < substeps; ++s)
      for (std::size_t i = 0; i < com.size(); ++i) {
        const Vec3 v0 = v[i];
        v[i] += h * gravity;
        com[i] += (0.5 * h) * (v0 + v[i]);
        q[i] = integrate_rotation(q[i], w[i], h);
      }
  }
  /// A value of the result, kept alive so the loop is not optimised away.
  Real sink() const { return com[com.size() / 2].y() + q[0].w(); }
};

/// Times `steps` steps of a plain loop (after the warm-up), as time_world does a world's.
template <class Loop>
Timing time_loop(Loop loop, int steps) {
  for (int k = 0; k < kWarmup; ++k) loop.step();
  std::vector<double> t(steps);
  for (int k = 0; k < steps; ++k) {
    const auto t0 = Clock::now();
    loop.step();
    t[k] = std::chrono::duration<double>(Clock::now() - t0).count();
  }
  volatile Real sink = loop.sink();
  (void)sink;
  return timing(t);
}

/// The same loop written over flat arrays of doubles (3 per body), as the world's own
/// pass is since it was vectorised (World::integrate_plain_run): not the bar's
/// baseline (the "plain compiled loop" is the loop a user writes over Vec3
/// rows, above), but how fast this integration can go, so the ratio against it shows
/// what the world's overhead is without the vectorisation's gain.
struct FlatFreeFall {
  std::vector<Real> x, v;
  std::vector<Vec3> w;
  std::vector<Quat> q;
  Vec3 gravity = WorldSettings{}.gravity;
  Real dt = WorldSettings{}.dt;
  int substeps = WorldSettings{}.substeps;

  FlatFreeFall() {
    for (const Vec3& p : grid_positions()) x.insert(x.end(), {p.x(), p.y(), p.z()});
    v.assign(x.size(), 0);
    w.assign(x.size() / 3, Vec3::Zero());
    q.assign(x.size() / 3, Quat::Identity());
  }
  void step() {
    const Real h = dt / substeps;
    const Real dv[3] = {h * gravity.x(), h * gravity.y(), h * gravity.z()};
    const std::size_t n = x.size();
    for (int s = 0; s < substeps; ++s) {
      for (std::size_t j = 0; j < n; j += 3)
        for (int c = 0; c < 3; ++c) {
          const Real v0 = v[j + c];
          v[j + c] = v0 + dv[c];
          x[j + c] += (0.5 * h) * (v0 + v[j + c]);
        }
      for (std::size_t i = 0; i < q.size(); ++i) q[i] = integrate_rotation(q[i], w[i], h);
    }
  }
  Real sink() const { return x[x.size() / 2] + q[0].w(); }
};

struct Config {
  std::string group, name;
  std::function<Timing(int)> run;
};

}  // namespace

int main(int argc, char** argv) {
  const std::string out_dir = argc > 1 ? argv[1] : ".";
  const int rounds = argc > 2 ? std::atoi(argv[2]) : 7;
  const int steps = argc > 3 ? std::atoi(argv[3]) : 200;
  if (rounds < 1 || steps < 1) {
    std::fprintf(stderr, "rounds and steps must be >= 1\n");
    return 2;
  }
  std::vector<Config> configs = {
      {"free_fall", "plain_loop", [](int n) { return time_loop(PlainFreeFall(), n); }},
      {"free_fall", "world", [](int n) { World w = free_fall_world(true, false); return time_world(w, n, true); }},
      {"free_fall", "world_sleeping_off",
       [](int n) { World w = free_fall_world(false, false); return time_world(w, n); }},
      {"free_fall", "world_gyroscopic_on",
       [](int n) { World w = free_fall_world(true, true); return time_world(w, n); }},
      {"resting", "frictionless", [](int n) { World w = resting_world(0); return time_world(w, n); }},
      {"resting", "friction_on_pairs_zero", [](int n) { World w = resting_world(0.5); return time_world(w, n); }},
      {"free_fall", "plain_loop_flat", [](int n) { return time_loop(FlatFreeFall(), n); }},
  };
  std::vector<std::vector<double>> t(configs.size()), tmean(configs.size());
  for (int r = 0; r < rounds; ++r)
    for (std::size_t c = 0; c < configs.size(); ++c) {
      const Timing x = configs[c].run(steps);
      t[c].push_back(x.median);
      tmean[c].push_back(x.mean);
    }

  const std::string path = out_dir + "/world_overhead.csv";
  std::ofstream csv(path);
  if (!csv) {
    std::fprintf(stderr, "cannot write %s\n", path.c_str());
    return 1;
  }
  csv << "group,config,round,median_step_us,mean_step_us\n";
  for (std::size_t c = 0; c < configs.size(); ++c)
    for (int r = 0; r < rounds; ++r)
      csv << configs[c].group << ',' << configs[c].name << ',' << r << ',' << 1e6 * t[c][r] << ','
          << 1e6 * tmean[c][r] << '\n';

  auto med = [&](std::size_t c) { return 1e6 * median(t[c]); };
  auto spread = [&](std::size_t c) {
    return 1e6 * (*std::max_element(t[c].begin(), t[c].end()) - *std::min_element(t[c].begin(), t[c].end()));
  };
  std::printf("world overhead, %d rounds x %d steps (median step, us; noise = baseline's spread over rounds)\n",
              rounds, steps);
  std::printf("%-10s %-24s %12s %10s %s\n", "group", "config", "median us", "ratio", "vs baseline");
  for (std::size_t c = 0; c < configs.size(); ++c) {
    const bool flat = configs[c].name == "plain_loop_flat";
    const std::size_t base = configs[c].group == "free_fall" ? (c == 0 || flat ? 0 : 1) : 4;
    const double ratio = med(c) / med(c == 1 ? 0 : base);
    std::string verdict;
    if (c == 1) {
      verdict = "world / plain loop";
    } else if (flat) {
      char buf[128];
      std::snprintf(buf, sizeof buf, "(vs plain loop; world / this: %.3f)", med(1) / med(c));
      verdict = buf;
    } else if (c != 0 && c != base) {
      const double diff = med(c) - med(base);
      char buf[128];
      std::snprintf(buf, sizeof buf, "%+.1f us against noise %.1f us: %s", diff, spread(base),
                    std::abs(diff) <= spread(base) ? "within noise" : "ABOVE NOISE");
      verdict = buf;
    }
    std::printf("%-10s %-24s %12.1f %10.3f %s\n", configs[c].group.c_str(), configs[c].name.c_str(), med(c), ratio,
                verdict.c_str());
  }
  const double mean_world = 1e6 * median(tmean[1]), mean_plain = 1e6 * median(tmean[0]);
  std::printf("free-fall mean step (median over rounds): world %.1f us, plain loop %.1f us, ratio %.3f\n",
              mean_world, mean_plain, mean_world / mean_plain);
  std::printf("free-fall world, mean us per step by stage (last round):");
  for (std::size_t k = 0; k < g_stage_means.size(); ++k)
    std::printf(" %s %.1f", kStageNames[k], 1e6 * g_stage_means[k]);
  std::printf("\nwrote %s\n", path.c_str());
  return 0;
}
