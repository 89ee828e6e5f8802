// Broadphase base class: the proxy table shared by every algorithm, input validation,
// the linear fallbacks for box and ray queries, and the factory.
#include <sstream>
#include <stdexcept>
#include <string>

#include "broadphase_internal.h"
#include "wmo/collision/broadphase.h"

namespace wmo {

namespace detail {

void require_valid_box(const char* field, const Aabb& box) {
  if (!box.min.allFinite() || !box.max.allFinite())
    throw InvalidArgument(std::string(field) + " must be finite, got min " + to_string(box.min) +
                          " max " + to_string(box.max));
  if ((box.min.array() > box.max.array()).any())
    throw InvalidArgument(std::string(field) + ".min must be <= " + field + ".max on every axis, got min " +
                          to_string(box.min) + " max " + to_string(box.max));
}

void require_valid_ray(const Vec3& origin, const Vec3& dir, Real max_t) {
  require_finite("origin", origin);
  require_finite("dir", dir);
  if ((dir.array() == 0.0).all()) throw InvalidArgument("dir must be non-zero, got " + to_string(dir));
  if (!(max_t >= 0)) {  // rejects NaN too
    std::ostringstream s;
    s.precision(17);
    s << "max_t must be >= 0 (kInf allowed), got " << max_t;
    throw InvalidArgument(s.str());
  }
}

}  // namespace detail

const char* to_string(BroadphaseType t) {
  switch (t) {
    case BroadphaseType::kBruteForce: return "brute_force";
    case BroadphaseType::kSweepAndPrune: return "sweep_and_prune";
    case BroadphaseType::kAabbTree: return "aabb_tree";
  }
  return "unknown";
}

bool ray_aabb(const Vec3& origin, const Vec3& dir, const Aabb& box, Real max_t, Real& t_enter) {
  return detail::PreparedRay(origin, dir).hits(box, max_t, t_enter);
}

void Broadphase::throw_not_live(const char* what, ProxyId id) {
  throw InvalidArgument(std::string(what) + ": proxy id " + std::to_string(id) + " is not a live proxy");
}

ProxyId Broadphase::create_proxy(const Aabb& box, std::uint64_t user_data) {
  detail::require_valid_box("box", box);
  ProxyId id;
  if (!free_ids_.empty()) {
    id = free_ids_.back();
    free_ids_.pop_back();
  } else {
    if (tight_.size() >= static_cast<std::size_t>(std::numeric_limits<ProxyId>::max()))
      throw InvalidArgument("create_proxy: too many proxies (ProxyId is int32)");
    id = static_cast<ProxyId>(tight_.size());
    tight_.emplace_back();
    user_data_.push_back(0);
    live_.push_back(0);
  }
  const auto i = static_cast<std::size_t>(id);
  tight_[i] = box;
  user_data_[i] = user_data;
  live_[i] = 1;
  ++live_count_;
  dirty_ = true;
  on_create(id);
  return id;
}

void Broadphase::destroy_proxy(ProxyId id) {
  require_live("destroy_proxy", id);
  on_destroy(id);
  live_[static_cast<std::size_t>(id)] = 0;
  --live_count_;
  free_ids_.push_back(id);
  dirty_ = true;
}

void Broadphase::move_proxy(ProxyId id, const Aabb& box, const Vec3& displacement) {
  require_live("move_proxy", id);
  detail::require_valid_box("box", box);
  require_finite("displacement", displacement);
  move_proxy_unchecked(id, box, displacement);
}

void Broadphase::update() {
  if (!dirty_) return;
  on_update();
  dirty_ = false;
}

void Broadphase::query_pairs(std::vector<ProxyPair>& out) {
  update();
  out.clear();
  on_query_pairs(out);
}

// Linear scans: brute force and sweep and prune have no spatial hierarchy to descend.
// (Sweep and prune could bisect its sorted array on the sweep axis, but the array is only
// sorted after update(), and queries must also see moves made since.)
void Broadphase::query_aabb(const Aabb& box, AabbQueryCallback callback) const {
  detail::require_valid_box("box", box);
  const ProxyId n = static_cast<ProxyId>(tight_.size());
  for (ProxyId id = 0; id < n; ++id) {
    if (live_[static_cast<std::size_t>(id)] && tight_[static_cast<std::size_t>(id)].overlaps(box)) {
      if (!callback(id)) return;
    }
  }
}

void Broadphase::raycast(const Vec3& origin, const Vec3& dir, Real max_t,
                         RayQueryCallback callback) const {
  detail::require_valid_ray(origin, dir, max_t);
  const detail::PreparedRay ray(origin, dir);
  const ProxyId n = static_cast<ProxyId>(tight_.size());
  for (ProxyId id = 0; id < n; ++id) {
    Real t;
    if (live_[static_cast<std::size_t>(id)] && ray.hits(tight_[static_cast<std::size_t>(id)], max_t, t)) {
      const Real next = callback(id, t);
      if (!(next >= 0)) return;  // negative (or NaN) stops the cast
      max_t = next < max_t ? next : max_t;
    }
  }
}

BroadphaseStats Broadphase::stats() const {
  BroadphaseStats s;
  s.proxy_count = live_count_;
  return s;
}

void Broadphase::validate() const {
  int live = 0;
  for (std::size_t i = 0; i < live_.size(); ++i) live += live_[i] ? 1 : 0;
  if (live != live_count_) throw std::logic_error("broadphase: live count mismatch");
  if (static_cast<std::size_t>(live_count_) + free_ids_.size() != tight_.size())
    throw std::logic_error("broadphase: free list size mismatch");
  for (ProxyId id : free_ids_)
    if (is_live(id)) throw std::logic_error("broadphase: live id on the free list");
}

std::unique_ptr<Broadphase> make_broadphase(BroadphaseType type, const BroadphaseSettings& settings) {
  require_non_negative("settings.aabb_margin", settings.aabb_margin);
  require_non_negative("settings.displacement_multiplier", settings.displacement_multiplier);
  switch (type) {
    case BroadphaseType::kBruteForce: return detail::make_brute_force_broadphase();
    case BroadphaseType::kSweepAndPrune: return detail::make_sweep_and_prune_broadphase();
    case BroadphaseType::kAabbTree: return detail::make_aabb_tree_broadphase(settings);
  }
  throw InvalidArgument("type: unknown BroadphaseType " + std::to_string(static_cast<int>(type)));
}

}  // namespace wmo
