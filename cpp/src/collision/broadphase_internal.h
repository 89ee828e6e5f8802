// Private to the broadphase: constructors of the three algorithms (one .cpp each) and
// helpers they share. Users go through make_broadphase() in wmo/collision/broadphase.h.
#pragma once

#include <memory>

#include "wmo/collision/broadphase.h"

namespace wmo::detail {

std::unique_ptr<Broadphase> make_brute_force_broadphase();
std::unique_ptr<Broadphase> make_sweep_and_prune_broadphase();
std::unique_ptr<Broadphase> make_aabb_tree_broadphase(const BroadphaseSettings& settings);

/// Throws InvalidArgument unless `box` is finite with min <= max on every axis.
void require_valid_box(const char* field, const Aabb& box);

/// A ray prepared for many slab tests: per-axis reciprocal direction, with a flag for
/// axes the ray is parallel to (dir = 0, or so small that 1/dir overflows), which are
/// tested by containment instead so no inf * 0 = NaN can arise.
struct PreparedRay {
  Vec3 origin;
  Vec3 inv_dir;
  bool parallel[3];

  PreparedRay(const Vec3& o, const Vec3& d) : origin(o) {
    for (int k = 0; k < 3; ++k) {
      const Real inv = 1.0 / d[k];
      parallel[k] = !std::isfinite(inv);
      inv_dir[k] = parallel[k] ? 0.0 : inv;
    }
  }

  /// Closed slab test on [0, max_t]; entry parameter in t_enter.
  bool hits(const Aabb& b, Real max_t, Real& t_enter) const {
    Real t0 = 0, t1 = max_t;
    for (int k = 0; k < 3; ++k) {
      if (parallel[k]) {
        if (origin[k] < b.min[k] || origin[k] > b.max[k]) return false;
        continue;
      }
      Real ta = (b.min[k] - origin[k]) * inv_dir[k];
      Real tb = (b.max[k] - origin[k]) * inv_dir[k];
      if (ta > tb) std::swap(ta, tb);
      t0 = ta > t0 ? ta : t0;
      t1 = tb < t1 ? tb : t1;
      if (t0 > t1) return false;
    }
    t_enter = t0;
    return true;
  }
};

/// Validates raycast arguments (shared by every algorithm's raycast).
void require_valid_ray(const Vec3& origin, const Vec3& dir, Real max_t);

}  // namespace wmo::detail
