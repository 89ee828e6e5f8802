// Narrowphase benchmark: WMO's special routines and generic GJK/EPA against libccd 2.1
// (GJK/EPA and MPR) and FCL 0.7, on the same random configurations.
//
// Usage: bench_narrowphase [out_dir=results/narrowphase] [configs_per_pair=4000] [pairs]
// `pairs` is an optional comma-separated list of pair names (e.g. box_box,hull_hull) to
// run only those; the CSVs then hold only them. The environment variable
// WMO_BENCH_METHODS (comma-separated method names) likewise limits the methods timed,
// which is how a profiler is pointed at one routine; WMO_BENCH_BY_CLASS=1 also prints the
// time per configuration class (deep, barely overlapping, barely separated, far).
// Writes out_dir/narrowphase.csv, out_dir/tolerance_sweep.csv, out_dir/reference_check.csv.
//
// What each method computes, per configuration (the same question for all: "do A and B
// overlap, and if so how deep and along which normal"):
//   wmo_special     wmo::collide(a, pose_a, b, pose_b, out) with default CollideSettings
//                   (margin 0, special routines on): a full contact manifold (up to 4
//                   points, normal, depths). Pairs without a special routine are skipped.
//   wmo_gjk_epa     the same with use_special_routines = false: GJK, then EPA on the cores
//                   when overlapping, then face clipping for the manifold. Default GJK/EPA
//                   tolerances (1e-10 relative).
//   wmo_gjk_epa_point  penetration_convex_convex with cull_distance 0: GJK, stopping at
//                   the first separating plane of a separated pair (no distance, like
//                   libccd's and FCL's boolean GJK), then EPA, one contact (depth,
//                   normal, witness points) and no manifold, as libccd and FCL answer on
//                   their GJK/EPA paths; its difference from wmo_gjk_epa is the clipping.
//   libccd_gjk_epa  ccdGJKPenetration: GJK boolean test; when overlapping, EPA gives depth,
//                   direction and one point. No manifold. epa_tolerance 1e-4 (libccd's
//                   default), max_iterations 1000 (reference_adapters.h).
//   libccd_mpr      ccdMPRPenetration: MPR boolean test and, when overlapping, MPR depth,
//                   direction and one point. mpr_tolerance 1e-4 (libccd's default).
//   fcl             fcl::collide with enable_contact and up to 4 contacts (FCL's own
//                   special routines where it has them: sphere-sphere, sphere-box,
//                   sphere-capsule, box-box; its libccd-based GJK/EPA otherwise,
//                   gjk_tolerance 1e-6 by default).
//   fcl_gjk_epa     FCL's own generic GJK and EPA (fcl::detail, GJKSolver_indep's
//                   generic path) on every pair, closed-form pairs included: one
//                   contact, the depth (reference_adapters.h, fcl_gjk_epa_depth).
// libccd's callbacks call WMO's support functions through a virtual call and a pose
// transform per support point; that is how any user would plug shapes into libccd.
//
// Timing: shapes, FCL objects and libccd objects are built before timing; one warm-up
// pass, then the whole set is repeated R times per repetition and the per-query time of
// 7 repetitions is reported as the median.
//
// Error: only on overlapping configurations, |depth - reference depth| with the deepest
// manifold point as WMO's depth. The reference is analytic for sphere-sphere, sphere-box,
// sphere-capsule, capsule-capsule (reference_adapters.h: exact). For the other pairs it is
// WMO's own GJK/EPA (penetration_convex_convex) at tolerance 1e-12: a SELF-REFERENCE. To
// show it is not simply WMO agreeing with itself, reference_check.csv gives the median
// difference between it and libccd's GJK/EPA and MPR at tolerance 1e-10.
//
// Configurations: per pair `configs_per_pair` (default 4000), a quarter each of deep
// overlap, barely overlapping (depth 1e-6..1e-3), barely separated (gap 1e-6..1e-3) and
// far, fixed seed. "Touching" (|gap| < 1e-9) is left out here: its verdict is legitimately
// either answer (the cross-check test covers it).
#include <algorithm>
#include <chrono>
#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <filesystem>
#include <fstream>
#include <functional>
#include <string>
#include <vector>

#include "reference_adapters.h"
#include "wmo/collision/narrowphase.h"
#include "wmo/geometry/convex_queries.h"

using namespace wmo;

namespace {

struct PairSpec {
  const char* name;
  ShapeType a, b;
  bool has_special;  // wmo has a collide_<a>_<b> routine
};

const PairSpec kPairs[] = {
    {"sphere_sphere", ShapeType::kSphere, ShapeType::kSphere, true},
    {"sphere_box", ShapeType::kSphere, ShapeType::kBox, true},
    {"sphere_capsule", ShapeType::kSphere, ShapeType::kCapsule, true},
    {"capsule_capsule", ShapeType::kCapsule, ShapeType::kCapsule, true},
    {"capsule_box", ShapeType::kCapsule, ShapeType::kBox, true},
    {"box_box", ShapeType::kBox, ShapeType::kBox, true},
    {"hull_hull", ShapeType::kConvexHull, ShapeType::kConvexHull, true},
    {"cylinder_box", ShapeType::kCylinder, ShapeType::kBox, false},
    {"cylinder_cylinder", ShapeType::kCylinder, ShapeType::kCylinder, false},
};

struct Case {
  ref::PairConfig cfg;
  ref::FclObject fa, fb;
  ref::CcdObject ca, cb;
  bool overlap = false;
  double ref_depth = 0;  // overlapping only
};

/// Outcome of one query: NaN depth = "no contact reported".
using Query = std::function<double(Case&)>;

/// wmo_gjk_epa_point: penetration_convex_convex's one contact, depth (NAN if apart).
double wmo_point_depth(const Case& c, const CollideSettings& s) {
  // cull_distance 0: a separated pair ends at GJK's first separating plane, with no
  // distance computed, as libccd's and FCL's GJK/EPA stop at their boolean test.
  const DistanceResult r =
      penetration_convex_convex(*c.cfg.a, *c.cfg.b, c.cfg.pose_a.relative(c.cfg.pose_b), s.gjk, s.epa, 0.0);
  return r.intersecting ? -r.distance : NAN;
}

#ifdef WMO_BENCH_STANDIN
// Stand-in while wmo::collide's box-box, hull-hull and generic routines are not linked
// yet (build with -DWMO_BENCH_STANDIN): special = the pair routine in A's frame,
// generic = penetration_convex_convex (GJK/EPA without the clipping step).
double wmo_special_depth(const PairSpec& p, Case& c, std::vector<Manifold>&) {
  const Pose rel = c.cfg.pose_a.relative(c.cfg.pose_b);
  Manifold m;
  bool hit = false;
  const auto& a = *c.cfg.a;
  const auto& b = *c.cfg.b;
  if (p.a == ShapeType::kSphere && p.b == ShapeType::kSphere)
    hit = collide_sphere_sphere(static_cast<const Sphere&>(a), static_cast<const Sphere&>(b), rel, 0, m);
  else if (p.a == ShapeType::kSphere && p.b == ShapeType::kBox)
    hit = collide_sphere_box(static_cast<const Sphere&>(a), static_cast<const Box&>(b), rel, 0, m);
  else if (p.a == ShapeType::kSphere && p.b == ShapeType::kCapsule)
    hit = collide_sphere_capsule(static_cast<const Sphere&>(a), static_cast<const Capsule&>(b), rel, 0, m);
  else if (p.a == ShapeType::kCapsule && p.b == ShapeType::kCapsule)
    hit = collide_capsule_capsule(static_cast<const Capsule&>(a), static_cast<const Capsule&>(b), rel, 0, m);
  else if (p.a == ShapeType::kCapsule && p.b == ShapeType::kBox)
    hit = collide_capsule_box(static_cast<const Capsule&>(a), static_cast<const Box&>(b), rel, 0, m);
  return hit ? m.max_depth() : NAN;
}
bool special_available(const PairSpec& p) {
  return p.has_special && p.a != ShapeType::kBox && p.a != ShapeType::kConvexHull;
}
double wmo_generic_depth(Case& c, std::vector<Manifold>&, const CollideSettings& s) { return wmo_point_depth(c, s); }
constexpr bool kStandin = true;
#else
double wmo_special_depth(const PairSpec&, Case& c, std::vector<Manifold>& out) {
  out.clear();
  collide(*c.cfg.a, c.cfg.pose_a, *c.cfg.b, c.cfg.pose_b, out);
  return out.empty() ? NAN : out[0].max_depth();
}
bool special_available(const PairSpec& p) { return p.has_special; }
double wmo_generic_depth(Case& c, std::vector<Manifold>& out, const CollideSettings& s) {
  out.clear();
  collide(*c.cfg.a, c.cfg.pose_a, *c.cfg.b, c.cfg.pose_b, out, s);
  return out.empty() ? NAN : out[0].max_depth();
}
constexpr bool kStandin = false;
#endif

double median(std::vector<double> v) {
  if (v.empty()) return NAN;
  std::sort(v.begin(), v.end());
  const std::size_t n = v.size();
  return n % 2 ? v[n / 2] : 0.5 * (v[n / 2 - 1] + v[n / 2]);
}

/// Median over `reps` repetitions of the per-query time (ns) of R passes over `cases`.
/// R <= 0 picks R so that one repetition takes about 20 ms (from the warm-up pass), so
/// small case sets are not timed at the clock's resolution. Stops adding repetitions
/// once 1.5 s were spent (slow references at tight tolerances), keeping at least 3.
double time_ns(std::vector<Case>& cases, const Query& q, int R, int reps = 7) {
  using clock = std::chrono::steady_clock;
  volatile double sink = 0;
  const auto w0 = clock::now();
  for (auto& c : cases) sink = sink + q(c);  // warm-up: caches, EPA workspaces
  const double warm = std::chrono::duration<double>(clock::now() - w0).count();
  if (R <= 0) R = std::clamp(static_cast<int>(0.02 / std::max(warm, 1e-9)), 1, 50);
  std::vector<double> per_query;
  const auto start = clock::now();
  for (int rep = 0; rep < reps; ++rep) {
    const auto t0 = clock::now();
    double acc = 0;
    for (int r = 0; r < R; ++r)
      for (auto& c : cases) acc += q(c);
    const auto t1 = clock::now();
    sink = sink + acc;
    per_query.push_back(std::chrono::duration<double, std::nano>(t1 - t0).count() / (double(R) * cases.size()));
    if (rep >= 2 && std::chrono::duration<double>(t1 - start).count() > 1.5) break;
  }
  return median(per_query);
}

struct ErrorStats {
  double median_error = NAN, max_error = NAN;
  int wrong_verdicts = 0;
};

ErrorStats errors(std::vector<Case>& cases, const Query& q) {
  ErrorStats s;
  std::vector<double> e;
  for (auto& c : cases) {
    const double d = q(c);
    const bool hit = !std::isnan(d);
    if (hit != c.overlap) ++s.wrong_verdicts;
    if (c.overlap && hit) e.push_back(std::abs(d - c.ref_depth));
  }
  if (!e.empty()) {
    s.median_error = median(e);
    s.max_error = *std::max_element(e.begin(), e.end());
  }
  return s;
}

std::vector<Case> make_cases(const PairSpec& p, int n, std::uint64_t seed) {
  ref::ConfigGenerator gen(seed);
  const ref::ConfigClass classes[] = {ref::ConfigClass::kDeep, ref::ConfigClass::kBarelyOverlapping,
                                      ref::ConfigClass::kBarelySeparated, ref::ConfigClass::kFar};
  std::vector<Case> cases(n);
  // Self-reference settings: 1e-12 relative, near double precision's floor for these
  // bounds (GjkSettings notes 1e-10 as the useful limit; 1e-12 asks for the most).
  GjkSettings gjk_ref;
  gjk_ref.tolerance = 1e-12;
  gjk_ref.max_iterations = 1000;
  EpaSettings epa_ref;
  epa_ref.tolerance = 1e-12;
  epa_ref.absolute_tolerance = 1e-14;
  epa_ref.max_iterations = 1000;
  epa_ref.max_faces = 4096;
  for (int i = 0; i < n; ++i) {
    Case& c = cases[i];
    c.cfg = gen.make(p.a, p.b, classes[i % 4]);
    c.fa = ref::FclObject(*c.cfg.a, c.cfg.pose_a);
    c.fb = ref::FclObject(*c.cfg.b, c.cfg.pose_b);
    c.ca = ref::CcdObject{c.cfg.a.get(), c.cfg.pose_a};
    c.cb = ref::CcdObject{c.cfg.b.get(), c.cfg.pose_b};
    c.overlap = c.cfg.signed_distance < 0;
    if (c.overlap) {
      if (auto a = ref::analytic_signed_distance(*c.cfg.a, c.cfg.pose_a, *c.cfg.b, c.cfg.pose_b)) {
        c.ref_depth = -*a;
      } else {
        c.ref_depth = -penetration_convex_convex(*c.cfg.a, *c.cfg.b, c.cfg.pose_a.relative(c.cfg.pose_b),
                                                 gjk_ref, epa_ref)
                           .distance;
      }
    }
  }
  return cases;
}

std::string fmt(double v) {
  if (std::isnan(v)) return "nan";
  char buf[64];
  std::snprintf(buf, sizeof buf, "%.6g", v);
  return buf;
}

}  // namespace

int main(int argc, char** argv) {
  const std::string out_dir = argc > 1 ? argv[1] : "results/narrowphase";
  const int n = argc > 2 ? std::max(8, std::atoi(argv[2])) : 4000;
  const std::string only = argc > 3 ? "," + std::string(argv[3]) + "," : "";
  std::filesystem::create_directories(out_dir);
  std::ofstream csv(out_dir + "/narrowphase.csv");
  csv << "pair,method,ns_per_query,median_error,max_error,n_overlap,n_separated,n_wrong_verdict\n";
  std::ofstream sweep(out_dir + "/tolerance_sweep.csv");
  sweep << "pair,method,tolerance,ns_per_query,median_error,max_error,n_wrong_verdict\n";
  std::ofstream refcsv(out_dir + "/reference_check.csv");
  refcsv << "pair,reference,median_diff_libccd_gjk_epa,median_diff_libccd_mpr,max_diff_libccd_gjk_epa\n";

  std::printf("# bench_narrowphase: %d configurations per pair%s\n", n,
              kStandin ? " (STAND-IN build: wmo_gjk_epa = penetration_convex_convex, no box/hull specials)" : "");
  std::printf("# libccd: max_iterations %lu, epa_tolerance %g, mpr_tolerance %g; FCL: collide, 4 contacts, GST_LIBCCD\n",
              ref::kCcdMaxIterations, ref::kCcdEpaTolerance, ref::kCcdMprTolerance);
  const int R = 3;
  std::vector<Manifold> out;
  out.reserve(8);
  const ccd_t ccd_default = ref::make_ccd();
  const CollideSettings generic = [] {
    CollideSettings s;
    s.use_special_routines = false;
    return s;
  }();

  std::uint64_t seed = 1;
  for (const PairSpec& p : kPairs) {
    if (!only.empty() && only.find("," + std::string(p.name) + ",") == std::string::npos) continue;
    std::vector<Case> cases = make_cases(p, n, 1000 + seed++);
    int n_overlap = 0;
    for (auto& c : cases) n_overlap += c.overlap;
    const bool analytic = ref::analytic_signed_distance(*cases[0].cfg.a, cases[0].cfg.pose_a, *cases[0].cfg.b,
                                                        cases[0].cfg.pose_b)
                              .has_value();

    struct Method {
      const char* name;
      Query q;
      bool enabled;
    };
    const Method methods[] = {
        {"wmo_special", [&](Case& c) { return wmo_special_depth(p, c, out); }, special_available(p)},
        {"wmo_gjk_epa", [&](Case& c) { return wmo_generic_depth(c, out, generic); }, true},
        {"wmo_gjk_epa_point", [&](Case& c) { return wmo_point_depth(c, generic); }, true},
        {"libccd_gjk_epa",
         [&](Case& c) {
           auto r = ref::ccd_penetration_gjk(c.ca, c.cb, ccd_default);
           return r.intersecting ? -r.signed_distance : NAN;
         },
         true},
        {"libccd_mpr",
         [&](Case& c) {
           auto r = ref::ccd_penetration_mpr(c.ca, c.cb, ccd_default);
           return r.intersecting ? -r.signed_distance : NAN;
         },
         true},
        {"fcl",
         [&](Case& c) {
           auto r = ref::fcl_collide_depth(c.fa, c.fb);
           return r.intersecting ? -r.signed_distance : NAN;
         },
         true},
        {"fcl_gjk_epa",
         [&](Case& c) {
           auto r = ref::fcl_gjk_epa_depth(c.fa, c.fb);
           return r.intersecting ? -r.signed_distance : NAN;
         },
         true},
    };
    const char* only_methods = std::getenv("WMO_BENCH_METHODS");
    for (const Method& m : methods) {
      if (!m.enabled) continue;
      if (only_methods && ("," + std::string(only_methods) + ",").find("," + std::string(m.name) + ",") ==
                              std::string::npos)
        continue;
      const double ns = time_ns(cases, m.q, R);
      const ErrorStats e = errors(cases, m.q);
      csv << p.name << ',' << m.name << ',' << fmt(ns) << ',' << fmt(e.median_error) << ',' << fmt(e.max_error)
          << ',' << n_overlap << ',' << (n - n_overlap) << ',' << e.wrong_verdicts << '\n';
      std::printf("%-18s %-15s %10.1f ns  err median %-10s max %-10s wrong verdicts %d\n", p.name, m.name, ns,
                  fmt(e.median_error).c_str(), fmt(e.max_error).c_str(), e.wrong_verdicts);
      if (std::getenv("WMO_BENCH_BY_CLASS")) {
        // Diagnosis: the time per configuration class (cases[i] has class i % 4).
        static const char* kClassNames[] = {"deep", "barely_overlapping", "barely_separated", "far"};
        for (int k = 0; k < 4; ++k) {
          std::vector<Case> sub;  // moved out and back: Case is move-only
          for (std::size_t i = k; i < cases.size(); i += 4) sub.push_back(std::move(cases[i]));
          std::printf("%-18s %-15s   %-20s %10.1f ns\n", "", "", kClassNames[k], time_ns(sub, m.q, R));
          for (std::size_t i = k, j = 0; i < cases.size(); i += 4, ++j) cases[i] = std::move(sub[j]);
        }
      }
    }

    if (only_methods) continue;  // profiling one method: no reference check, no sweep

    // Cross-check of the reference against libccd at a tight tolerance.
    {
      const ccd_t tight = ref::make_ccd(1e-10, 1e-10);
      std::vector<double> dg, dm;
      for (auto& c : cases) {
        if (!c.overlap) continue;
        auto g = ref::ccd_penetration_gjk(c.ca, c.cb, tight);
        auto mp = ref::ccd_penetration_mpr(c.ca, c.cb, tight);
        if (g.intersecting) dg.push_back(std::abs(-g.signed_distance - c.ref_depth));
        if (mp.intersecting) dm.push_back(std::abs(-mp.signed_distance - c.ref_depth));
      }
      const double mx = dg.empty() ? NAN : *std::max_element(dg.begin(), dg.end());
      refcsv << p.name << ',' << (analytic ? "analytic" : "wmo_gjk_epa_1e-12") << ',' << fmt(median(dg)) << ','
             << fmt(median(dm)) << ',' << fmt(mx) << '\n';
      std::printf("%-18s reference %-18s median |ref - libccd gjk/epa| %s, |ref - libccd mpr| %s\n", p.name,
                  analytic ? "analytic" : "wmo_gjk_epa_1e-12", fmt(median(dg)).c_str(), fmt(median(dm)).c_str());
    }

    // Tolerance sweep on the overlapping configurations of every pair (a subset of 400
    // keeps the slow tight-tolerance libccd runs on curved shapes within the time
    // budget). FCL is swept through CollisionRequest::gjk_tolerance, which changes
    // nothing on the pairs it answers with special routines (sphere pairs, box-box).
    // run.py reads this to compare at equal accuracy: the fastest WMO tolerance whose
    // errors are no worse than a reference's at that reference's default tolerance.
    {
      std::vector<Case> ov;
      for (auto& c : cases)
        if (c.overlap && ov.size() < 400) ov.push_back(std::move(c));
      for (int k = 2; k <= 10; ++k) {
        const double tol = std::pow(10.0, -k);
        CollideSettings s = generic;
        s.gjk.tolerance = tol;
        s.epa.tolerance = tol;
        const ccd_t cc = ref::make_ccd(tol, tol);
        const std::pair<const char*, Query> sweep_methods[] = {
            {"wmo_gjk_epa", [&](Case& c) { return wmo_generic_depth(c, out, s); }},
            {"wmo_gjk_epa_point", [&](Case& c) { return wmo_point_depth(c, s); }},
            {"libccd_gjk_epa",
             [&](Case& c) {
               auto r = ref::ccd_penetration_gjk(c.ca, c.cb, cc);
               return r.intersecting ? -r.signed_distance : NAN;
             }},
            {"libccd_mpr",
             [&](Case& c) {
               auto r = ref::ccd_penetration_mpr(c.ca, c.cb, cc);
               return r.intersecting ? -r.signed_distance : NAN;
             }},
            {"fcl",
             [&](Case& c) {
               auto r = ref::fcl_collide_depth(c.fa, c.fb, tol);
               return r.intersecting ? -r.signed_distance : NAN;
             }},
            {"fcl_gjk_epa",
             [&](Case& c) {
               auto r = ref::fcl_gjk_epa_depth(c.fa, c.fb, tol);
               return r.intersecting ? -r.signed_distance : NAN;
             }},
        };
        for (const auto& [mname, q] : sweep_methods) {
          const double ns = time_ns(ov, q, 0, 5);
          const ErrorStats e = errors(ov, q);
          sweep << p.name << ',' << mname << ',' << fmt(tol) << ',' << fmt(ns) << ',' << fmt(e.median_error) << ','
                << fmt(e.max_error) << ',' << e.wrong_verdicts << '\n';
        }
      }
      std::printf("%-18s tolerance sweep done\n", p.name);
    }
    std::fflush(stdout);
  }
  std::printf("# wrote %s/narrowphase.csv, tolerance_sweep.csv, reference_check.csv\n", out_dir.c_str());
  return 0;
}
