// The world: handles, dense body storage and the step's stages (world.h).
#include "wmo/world/world.h"

#include "wmo/world/thread_pool.h"

#include <algorithm>
#include <array>
#include <chrono>
#include <cmath>
#include <cstring>
#include <exception>
#include <limits>
#include <utility>

namespace wmo {

namespace {

using Clock = std::chrono::steady_clock;

enum Stage {
  kUpdateBroadphase = 0,
  kFindPairs,
  kNarrowphase,
  kSolve,
  kRestitution,
  kStoreImpulses,
  kCcd,
  kUpdateSleep
};

/// Times one stage into the profile (RAII), with the stage's work count.
class StageTimer {
 public:
  StageTimer(StageProfile& p, long long count = 0)
      : p_(p), count_(count), t0_(Clock::now()), exceptions_(std::uncaught_exceptions()) {}
  void set_count(long long c) { count_ = c; }
  ~StageTimer() {
    // A stage that throws (the state check of step(), a body leaving the finite range)
    // leaves its profile as it was, as the step leaves the world.
    if (std::uncaught_exceptions() > exceptions_) return;
    const double s = std::chrono::duration<double>(Clock::now() - t0_).count();
    p_.seconds = s;
    p_.count = count_;
    p_.total_seconds += s;
    p_.total_count += count_;
    if (count_ > 0) ++p_.runs;
  }

 private:
  StageProfile& p_;
  long long count_;
  Clock::time_point t0_;
  int exceptions_;
};

template <class V>
void swap_remove(V& v, int i) {
  v[i] = std::move(v.back());
  v.pop_back();
}

/// Compressed rows (CSR) over keys 0..n-1: `emit(add)` calls add(key, value) once per
/// entry; it is run twice, to count and then to fill, and must add the same entries in
/// the same order both times. Row i is then entries[start[i] .. start[i + 1]), in the
/// order its entries were added. `fill` is scratch. The buffers keep their capacity.
template <class Emit>
void build_rows(int n, std::vector<int>& start, std::vector<int>& entries, std::vector<int>& fill, Emit&& emit) {
  start.assign(n + 1, 0);
  emit([&](int key, int) { ++start[key + 1]; });
  for (int i = 0; i < n; ++i) start[i + 1] += start[i];
  entries.resize(start[n]);
  fill.assign(start.begin(), start.end() - 1);
  emit([&](int key, int value) { entries[fill[key]++] = value; });
}

}  // namespace

CombineRule combine_rule_from_string(const std::string& s, const char* field) {
  if (s == "multiply") return CombineRule::kMultiply;
  if (s == "geometric_mean") return CombineRule::kGeometricMean;
  if (s == "max") return CombineRule::kMax;
  if (s == "min") return CombineRule::kMin;
  if (s == "average") return CombineRule::kAverage;
  throw InvalidArgument(std::string(field) +
                        " must be one of 'multiply', 'geometric_mean', 'max', 'min', 'average', got '" + s + "'");
}

BroadphaseType broadphase_from_string(const std::string& s, const char* field) {
  for (const BroadphaseType t : {BroadphaseType::kAabbTree, BroadphaseType::kSweepAndPrune, BroadphaseType::kBruteForce})
    if (s == to_string(t)) return t;
  throw InvalidArgument(std::string(field) + " must be one of 'aabb_tree', 'sweep_and_prune', 'brute_force', got '" +
                        s + "'");
}

const char* to_string(CombineRule r) {
  switch (r) {
    case CombineRule::kMultiply:
      return "multiply";
    case CombineRule::kGeometricMean:
      return "geometric_mean";
    case CombineRule::kMax:
      return "max";
    case CombineRule::kMin:
      return "min";
    case CombineRule::kAverage:
      return "average";
  }
  return "?";
}

Real combine(CombineRule rule, Real a, Real b) {
  switch (rule) {
    case CombineRule::kMultiply:
      return a * b;
    case CombineRule::kGeometricMean:
      return std::sqrt(a * b);
    case CombineRule::kMax:
      return std::max(a, b);
    case CombineRule::kMin:
      return std::min(a, b);
    case CombineRule::kAverage:
      return 0.5 * (a + b);
  }
  return a * b;
}

void validate_world_settings(const WorldSettings& s) {
  require_finite("gravity", s.gravity);
  require_positive("dt", s.dt);
  if (s.substeps < 1) throw InvalidArgument("substeps must be >= 1, got " + std::to_string(s.substeps));
  if (s.iterations < 1) throw InvalidArgument("iterations must be >= 1, got " + std::to_string(s.iterations));
  if (s.threads < 1 || s.threads > 256)
    throw InvalidArgument("threads must be in [1, 256], got " + std::to_string(s.threads));
  if (s.relax_iterations < 0)
    throw InvalidArgument("relax_iterations must be >= 0, got " + std::to_string(s.relax_iterations));
  if (s.energy_guard_passes < 0)
    throw InvalidArgument("energy_guard_passes must be >= 0, got " + std::to_string(s.energy_guard_passes));
  require_non_negative("energy_guard_tolerance", s.energy_guard_tolerance);
  require_non_negative("contact_hertz", s.solver.contact_hertz);
  require_non_negative("contact_damping_ratio", s.solver.damping_ratio);
  require_non_negative("contact_push_max", s.solver.push_max);
  require_non_negative("contact_max_sag", s.solver.max_sag);
  require_non_negative("contact_static_hertz_scale", s.solver.static_hertz_scale);
  require_non_negative("restitution_threshold", s.solver.restitution_threshold);
  require_non_negative("speculative_distance", s.speculative_distance);
  require_non_negative("speculative_motion", s.speculative_motion);
  require_non_negative("speculative_motion_static", s.speculative_motion_static);
  require_non_negative("aabb_margin", s.aabb_margin);
  require_non_negative("manifold_reuse_distance", s.manifold_reuse_distance);
  require_non_negative("manifold_reuse_angle", s.manifold_reuse_angle);
  require_non_negative("sleep_linear_threshold", s.sleep_linear_threshold);
  require_non_negative("sleep_angular_threshold", s.sleep_angular_threshold);
  require_positive("time_to_sleep", s.time_to_sleep);
  require_non_negative("ccd_motion_threshold", s.ccd_motion_threshold);
  require_positive("ccd_penetration", s.ccd_penetration);
}

World::World(const WorldSettings& settings) : settings_(settings) {
  validate_world_settings(settings_);
  group_masks_.fill(~std::uint64_t{0});
  BroadphaseSettings bs;
  bs.aabb_margin = settings_.aabb_margin;
  broadphase_ = make_broadphase(settings_.broadphase, bs);
  if (settings_.threads > 1) pool_ = std::make_unique<ThreadPool>(settings_.threads);
}

void World::set_settings(const WorldSettings& s) {
  validate_world_settings(s);
  if (s.broadphase != settings_.broadphase || s.aabb_margin != settings_.aabb_margin) {
    // Rebuild the broadphase with the same proxies (ids are reassigned).
    BroadphaseSettings bs;
    bs.aabb_margin = s.aabb_margin;
    auto bp = make_broadphase(s.broadphase, bs);
    for (int i = 0; i < body_count(); ++i) {
      const Aabb box = shapes_[i]->world_aabb(Pose(positions_[i], orientations_[i])).fattened(s.speculative_distance);
      proxies_[i] = bp->create_proxy(box, static_cast<std::uint64_t>(slot_of_[i]));
    }
    broadphase_ = std::move(bp);
  }
  if (s.threads != settings_.threads) pool_ = s.threads > 1 ? std::make_unique<ThreadPool>(s.threads) : nullptr;
  settings_ = s;
  if (!settings_.enable_sleep)
    for (int k = 0; k < static_cast<int>(islands_.size()); ++k)
      if (!islands_[k].empty()) wake_island(k);
}

int World::require(BodyId id, const char* what) const {
  if (id.slot < 0 || id.slot >= static_cast<int>(slots_.size()) || slots_[id.slot].index < 0 ||
      slots_[id.slot].generation != id.generation)
    throw InvalidArgument(std::string(what) + ": body handle (slot " + std::to_string(id.slot) + ", generation " +
                          std::to_string(id.generation) + ") is stale or invalid");
  return slots_[id.slot].index;
}

bool World::is_valid(BodyId id) const {
  return id.slot >= 0 && id.slot < static_cast<int>(slots_.size()) && slots_[id.slot].index >= 0 &&
         slots_[id.slot].generation == id.generation;
}

int World::index_of(BodyId id) const { return require(id, "index_of"); }

BodyId World::id_at(int index) const {
  if (index < 0 || index >= body_count())
    throw InvalidArgument("index must be in [0, " + std::to_string(body_count()) + "), got " + std::to_string(index));
  const int slot = slot_of_[index];
  return BodyId{slot, slots_[slot].generation};
}

BodyId World::add_body(const BodyDef& def) {
  validate_body_def(def);
  const BodyMass m = compute_body_mass(def);  // may throw: nothing changed yet
  Quat q = def.orientation;
  // Normalised unless already unit to rounding: normalize() is not idempotent in the
  // last bit, and a saved orientation must come back bit for bit (wmo.io round trip).
  if (std::abs(q.squaredNorm() - 1) > 1e-15) q.normalize();
  const Aabb box = def.shape->world_aabb(Pose(def.position, q)).fattened(settings_.speculative_distance);

  int slot;
  if (!free_slots_.empty()) {
    slot = free_slots_.back();
    free_slots_.pop_back();
  } else {
    slot = static_cast<int>(slots_.size());
    slots_.push_back(Slot{});
  }
  const int index = body_count();
  slots_[slot].index = index;
  const ProxyId proxy = broadphase_->create_proxy(box, static_cast<std::uint64_t>(slot));

  positions_.push_back(def.position);
  orientations_.push_back(q);
  const bool moving = def.kind != BodyKind::kStatic;
  linear_velocities_.push_back(moving ? def.linear_velocity : Vec3::Zero());
  angular_velocities_.push_back(moving ? def.angular_velocity : Vec3::Zero());
  kinds_.push_back(def.kind);
  masses_.push_back(m);
  traits_.push_back(static_cast<std::uint8_t>((m.local_com.isZero(0) ? 0 : kComOffset) |
                                              (m.isotropic ? kIsotropic : 0) |
                                              (def.shape->type() == ShapeType::kSphere ? kSphere : 0) |
                                              (def.linear_damping != 0 || def.angular_damping != 0 ? kHasDamping : 0)));
  shapes_.push_back(def.shape);
  frictions_.push_back(def.friction);
  restitutions_.push_back(def.restitution);
  groups_.push_back(static_cast<std::uint8_t>(def.collision_group));
  linear_damping_.push_back(def.linear_damping);
  angular_damping_.push_back(def.angular_damping);
  gravity_scale_.push_back(def.gravity_scale);
  min_abs_gravity_scale_ = std::min(min_abs_gravity_scale_, std::abs(def.gravity_scale));
  forces_.push_back(Vec3::Zero());
  torques_.push_back(Vec3::Zero());
  proxies_.push_back(proxy);
  slot_of_.push_back(slot);
  awake_.push_back(def.kind != BodyKind::kStatic);
  sleep_time_.push_back(0);
  sleep_island_.push_back(-1);
  sleep_position_.push_back(def.position);
  sleep_orientation_.push_back(q);
  const bool ccd = def.ccd && def.kind == BodyKind::kDynamic;
  ccd_.push_back(ccd);
  ccd_count_ += ccd;
  ccd_rows_dirty_ = ccd_rows_dirty_ || ccd;
  inner_radius_.push_back(inner_radius(*def.shape));
  outer_radius_.push_back(bounding_radius(*def.shape, m.local_com));
  // Dense indices of the last step's constraints stay valid (the new row is at the end).
  return BodyId{slot, slots_[slot].generation};
}

// ---- collision filtering ----

namespace {
std::uint64_t slot_pair_key(int sa, int sb) {
  if (sa > sb) std::swap(sa, sb);
  return (static_cast<std::uint64_t>(sa) << 32) | static_cast<std::uint32_t>(sb);
}
}  // namespace

bool World::collides(int slot_a, int slot_b) const {
  const int ga = groups_[slots_[slot_a].index], gb = groups_[slots_[slot_b].index];
  if (!((group_masks_[ga] >> gb) & 1u)) return false;
  return filtered_pairs_.empty() ||
         !std::binary_search(filtered_pairs_.begin(), filtered_pairs_.end(), slot_pair_key(slot_a, slot_b));
}

void World::update_has_filters() {
  has_filters_ = !filtered_pairs_.empty();
  for (const std::uint64_t m : group_masks_) has_filters_ = has_filters_ || m != ~std::uint64_t{0};
}

void World::set_collision_group(BodyId id, int group) {
  const int i = require(id, "set_collision_group");
  check_collision_group(group, "collision_group");
  groups_[i] = static_cast<std::uint8_t>(group);
  wake_row(i);  // a pair that now collides must be seen by an awake body
}

void World::set_group_collision(int a, int b, bool enabled) {
  check_collision_group(a, "group_a");
  check_collision_group(b, "group_b");
  const std::uint64_t bit_a = std::uint64_t{1} << a, bit_b = std::uint64_t{1} << b;
  if (enabled) {
    group_masks_[a] |= bit_b;
    group_masks_[b] |= bit_a;
  } else {
    group_masks_[a] &= ~bit_b;
    group_masks_[b] &= ~bit_a;
  }
  update_has_filters();
}

bool World::group_collision(int a, int b) const {
  check_collision_group(a, "group_a");
  check_collision_group(b, "group_b");
  return (group_masks_[a] >> b) & 1u;
}

void World::set_pair_collision(BodyId a, BodyId b, bool enabled) {
  const int ia = require(a, "set_pair_collision body_a");
  const int ib = require(b, "set_pair_collision body_b");
  if (ia == ib) throw InvalidArgument("set_pair_collision: body_a and body_b are the same body");
  const std::uint64_t key = slot_pair_key(a.slot, b.slot);
  const auto it = std::lower_bound(filtered_pairs_.begin(), filtered_pairs_.end(), key);
  const bool present = it != filtered_pairs_.end() && *it == key;
  if (!enabled && !present) filtered_pairs_.insert(it, key);
  if (enabled && present) {
    filtered_pairs_.erase(it);
    wake_row(ia);
    wake_row(ib);
  }
  update_has_filters();
}

bool World::pair_collision(BodyId a, BodyId b) const {
  require(a, "pair_collision body_a");
  require(b, "pair_collision body_b");
  return !std::binary_search(filtered_pairs_.begin(), filtered_pairs_.end(), slot_pair_key(a.slot, b.slot));
}

std::vector<std::pair<BodyId, BodyId>> World::filtered_pairs() const {
  std::vector<std::pair<BodyId, BodyId>> out;
  out.reserve(filtered_pairs_.size());
  for (const std::uint64_t key : filtered_pairs_) {
    const auto sa = static_cast<std::int32_t>(key >> 32), sb = static_cast<std::int32_t>(key & 0xFFFFFFFFu);
    out.emplace_back(BodyId{sa, slots_[sa].generation}, BodyId{sb, slots_[sb].generation});
  }
  return out;
}

void World::remove_body(BodyId id) {
  const int i = require(id, "remove_body");
  // Bodies resting on a sleeping body must not float once it is gone (waking moves no
  // rows, so i stays valid).
  wake_row(i);
  broadphase_->destroy_proxy(proxies_[i]);
  // Forget cached contacts of this slot: a later body in the same slot must not inherit
  // its impulses.
  const auto slot = static_cast<std::uint64_t>(id.slot);
  cache_.erase_if([slot](const ManifoldKey& key, const CachedManifold&) {
    return (key.pair >> 32) == slot || (key.pair & 0xFFFFFFFFu) == slot;
  });
  const int last = body_count() - 1;
  if (i != last) slots_[slot_of_[last]].index = i;
  swap_remove(positions_, i);
  swap_remove(orientations_, i);
  swap_remove(linear_velocities_, i);
  swap_remove(angular_velocities_, i);
  swap_remove(kinds_, i);
  swap_remove(masses_, i);
  swap_remove(traits_, i);
  swap_remove(shapes_, i);
  swap_remove(frictions_, i);
  swap_remove(restitutions_, i);
  swap_remove(groups_, i);
  if (!filtered_pairs_.empty()) {  // a later body in the slot starts unfiltered
    const auto sl = static_cast<std::uint64_t>(id.slot);
    std::erase_if(filtered_pairs_, [sl](std::uint64_t key) { return (key >> 32) == sl || (key & 0xFFFFFFFFu) == sl; });
    update_has_filters();
  }
  swap_remove(linear_damping_, i);
  swap_remove(angular_damping_, i);
  swap_remove(gravity_scale_, i);
  swap_remove(forces_, i);
  swap_remove(torques_, i);
  swap_remove(proxies_, i);
  swap_remove(slot_of_, i);
  swap_remove(awake_, i);
  swap_remove(sleep_time_, i);
  swap_remove(sleep_island_, i);
  swap_remove(sleep_position_, i);
  swap_remove(sleep_orientation_, i);
  ccd_count_ -= ccd_[i];
  ccd_rows_dirty_ = true;  // rows move
  swap_remove(ccd_, i);
  swap_remove(inner_radius_, i);
  swap_remove(outer_radius_, i);
  slots_[id.slot].index = -1;
  ++slots_[id.slot].generation;
  free_slots_.push_back(id.slot);
  // The last step's constraints refer to dense rows that moved.
  constraints_.clear();
  states_.clear();
}

void World::reserve(int n) {
  positions_.reserve(n);
  orientations_.reserve(n);
  linear_velocities_.reserve(n);
  angular_velocities_.reserve(n);
}

void World::set_position(BodyId id, const Vec3& position) {
  const int i = require(id, "set_position");
  require_finite("position", position);
  positions_[i] = position;
  wake_row(i);
}

void World::set_orientation(BodyId id, const Quat& orientation) {
  const int i = require(id, "set_orientation");
  orientations_[i] = Pose::checked(Vec3::Zero(), orientation, "body").rotation;
  wake_row(i);
}

void World::set_ccd(BodyId id, bool on) {
  const int i = require(id, "set_ccd");
  const bool flag = on && kinds_[i] == BodyKind::kDynamic;  // only dynamic bodies are swept
  ccd_count_ += static_cast<int>(flag) - ccd_[i];
  ccd_[i] = flag;
  ccd_rows_dirty_ = true;
}

void World::set_linear_velocity(BodyId id, const Vec3& v) {
  const int i = require(id, "set_linear_velocity");
  require_finite("linear_velocity", v);
  linear_velocities_[i] = v;
  wake_row(i);
}

void World::set_angular_velocity(BodyId id, const Vec3& w) {
  const int i = require(id, "set_angular_velocity");
  require_finite("angular_velocity", w);
  angular_velocities_[i] = w;
  wake_row(i);
}

void World::apply_impulse(BodyId id, const Vec3& impulse, const Vec3& world_point) {
  const int i = require(id, "apply_impulse");
  require_finite("impulse", impulse);
  require_finite("point", world_point);
  if (kinds_[i] != BodyKind::kDynamic) return;
  const BodyMass& m = masses_[i];
  linear_velocities_[i] += m.inv_mass * impulse;
  const Mat3 inv_i = world_inv_inertia(orientations_[i], m.inv_inertia_local);
  angular_velocities_[i] += inv_i * (world_point - world_com(i)).cross(impulse);
  wake_row(i);
}

void World::apply_force(BodyId id, const Vec3& force, const Vec3& world_point) {
  const int i = require(id, "apply_force");
  require_finite("force", force);
  require_finite("point", world_point);
  if (kinds_[i] != BodyKind::kDynamic) return;
  forces_[i] += force;
  torques_[i] += (world_point - world_com(i)).cross(force);
  has_forces_ = true;
  wake_row(i);
}

void World::apply_torque(BodyId id, const Vec3& torque) {
  const int i = require(id, "apply_torque");
  require_finite("torque", torque);
  if (kinds_[i] != BodyKind::kDynamic) return;
  torques_[i] += torque;
  has_forces_ = true;
  wake_row(i);
}

// ---- Sleeping ----------------------------------------------------------------------

int World::awake_dynamic_count() const {
  int n = 0;
  for (int i = 0; i < body_count(); ++i) n += awake_dynamic(i);
  return n;
}

void World::wake(BodyId id) { wake_row(require(id, "wake")); }

void World::wake_row(int i) {
  if (sleep_island_[i] >= 0) wake_island(sleep_island_[i]);
}

void World::wake_island(int island) {
  for (const std::int32_t slot : islands_[island]) {
    const int i = slots_[slot].index;
    if (i < 0) continue;  // removed while asleep (remove_body wakes first; defensive)
    awake_[i] = 1;
    sleep_time_[i] = 0;
    sleep_island_[i] = -1;
  }
  cache_woke_ = true;  // its cached pairs may have gone stale (store_impulses)
  islands_[island].clear();
  free_islands_.push_back(island);
}

// Moves this step and can wake what it touches: an awake dynamic body, or a kinematic
// body with a velocity (a kinematic body at rest leaves a sleeping pile asleep).
bool World::moving(int i) const {
  if (kinds_[i] == BodyKind::kDynamic) return awake_dynamic(i);
  if (kinds_[i] == BodyKind::kKinematic)
    return !linear_velocities_[i].isZero(0) || !angular_velocities_[i].isZero(0);
  return false;
}

// Islands by union-find over this step's contacts between awake dynamic bodies (static
// and kinematic bodies join no island, as in Box2D: they would merge everything resting
// on the ground). Sleep timers advance for bodies below both thresholds and reset
// otherwise (and for bodies touching a moving kinematic body); an island sleeps when
// its smallest timer reaches time_to_sleep.
int World::update_sleep() {
  const int n = body_count();
  const Real dt = settings_.dt;
  const Real lin2 = settings_.sleep_linear_threshold * settings_.sleep_linear_threshold;
  const Real ang2 = settings_.sleep_angular_threshold * settings_.sleep_angular_threshold;
  int awake = 0;
  bool ready = false;  // some body slow for time_to_sleep: else no island can sleep
  // Ballistic bodies are passed over. A plain free body (integrate_plain_run: no
  // contact, force or damping) changed its velocity this step by exactly dt times its
  // gravity, so if that change exceeds twice the linear threshold it cannot have been
  // slow at both ends of the step: its timer, 0 before or reset now, is at most dt
  // (dt only if it is slow at this very moment, the top of a throw) and is reset at
  // the next step unless a contact stops it there. Such a body's timer is set to 0
  // without its velocity being read, which is this stage's whole cost in a scene in
  // flight (10,000 falling spheres: ~15 us a step, 1.5 ns a body); the one difference
  // from the test, a timer of 0 instead of dt for a body that is slow for an instant,
  // can delay its island's sleep by one step. The margin 1e-6 covers the rounding of
  // the substeps' sum. Not when CCD bodies are stepped (the ccd stage may stop a body
  // after its integration), nor for a gravity scale so small (including 0, a body
  // floating in place) that the bound fails.
  const Real g_dt = settings_.gravity.norm() * dt * min_abs_gravity_scale_;
  const bool pass_runs = !ccd_active() && g_dt > 2 * settings_.sleep_linear_threshold * (1 + 1e-6);
  const std::size_t runs = pass_runs ? plain_runs_.size() : 0;
  std::size_t r = 0;
  bool any_timer = false;  // some awake body's timer is not 0 after this loop
  for (int i = 0; i < n; ++i) {
    if (r < runs && i == plain_runs_[r].first) {
      const int end = plain_runs_[r++].second;
      // Their timers are 0 already unless some awake body's was not after last step.
      if (!awake_timers_zero_) std::fill(sleep_time_.begin() + i, sleep_time_.begin() + end, Real(0));
      awake += end - i;
      i = end - 1;
      continue;
    }
    if (!awake_dynamic(i)) continue;
    ++awake;
    const bool slow = linear_velocities_[i].squaredNorm() <= lin2 && angular_velocities_[i].squaredNorm() <= ang2;
    sleep_time_[i] = slow ? sleep_time_[i] + dt : 0;
    any_timer = any_timer || slow;
    ready = ready || sleep_time_[i] >= settings_.time_to_sleep;
  }
  awake_timers_zero_ = !any_timer;
  // An island sleeps when its smallest timer reaches time_to_sleep (the contacts below
  // only merge islands and reset timers): with no timer there, the islands need not be
  // built (a scene in motion, such as free fall, pays only the loop above).
  if (!ready) return awake;
  island_parent_.resize(n);
  for (int i = 0; i < n; ++i) island_parent_[i] = i;
  auto find = [&](int i) {
    while (island_parent_[i] != i) i = island_parent_[i] = island_parent_[island_parent_[i]];
    return i;
  };
  auto is_dyn = [&](int i) { return kinds_[i] == BodyKind::kDynamic; };
  for (const ContactConstraint& c : constraints_) {
    const int a = c.body_a, b = c.body_b;
    if (is_dyn(a) && is_dyn(b)) {
      const int ra = find(a), rb = find(b);
      if (ra != rb) island_parent_[std::max(ra, rb)] = std::min(ra, rb);  // smallest row is the root
    } else if (kinds_[a] == BodyKind::kKinematic && moving(a)) {
      sleep_time_[b] = 0;
    } else if (kinds_[b] == BodyKind::kKinematic && moving(b)) {
      sleep_time_[a] = 0;
    }
  }
  // Smallest timer per root, then the roots that may sleep.
  std::vector<Real>& min_time = sleep_scratch_;
  min_time.assign(n, kInf);
  for (int i = 0; i < n; ++i)
    if (awake_dynamic(i)) {
      const int r = find(i);
      min_time[r] = std::min(min_time[r], sleep_time_[i]);
    }
  std::vector<std::int32_t>& island_of_root = island_of_root_;
  island_of_root.assign(n, -1);
  for (int i = 0; i < n; ++i) {
    if (!awake_dynamic(i)) continue;
    const int r = find(i);
    if (!(min_time[r] >= settings_.time_to_sleep)) continue;
    if (island_of_root[r] < 0) {
      if (!free_islands_.empty()) {
        island_of_root[r] = free_islands_.back();
        free_islands_.pop_back();
      } else {
        island_of_root[r] = static_cast<std::int32_t>(islands_.size());
        islands_.emplace_back();
      }
    }
    const int island = island_of_root[r];
    islands_[island].push_back(slot_of_[i]);
    awake_[i] = 0;
    sleep_island_[i] = island;
    linear_velocities_[i].setZero();
    angular_velocities_[i].setZero();
    sleep_position_[i] = positions_[i];
    sleep_orientation_[i] = orientations_[i];
    --awake;
  }
  return awake;
}

namespace {

// The quick test of one body's state (World::validate_state): one branch-free
// pass decides whether anything needs a closer look. x - x is exactly 0 for a finite
// x and NaN otherwise, so the sum below is 0 only when every coordinate is finite;
// |q|^2 is checked against a band slightly inside the tolerance's, so a quaternion it
// passes also passes the exact test (one square root per body, 4% of a free-fall
// step before this test). `ok` is cleared by anything else, `unit` by a quaternion
// not unit to rounding (|q|^2 more than 1e-15 from 1, which the exact loops
// normalise).
[[gnu::always_inline]] inline void quick_state_test(const Vec3& p, const Vec3& v, const Vec3& w, const Quat& q,
                                                    bool& ok, bool& unit) {
  constexpr Real kLo = (1 - kUnitQuatTolerance) * (1 - kUnitQuatTolerance) * (1 + 1e-12);
  constexpr Real kHi = (1 + kUnitQuatTolerance) * (1 + kUnitQuatTolerance) * (1 - 1e-12);
  const Real zero = ((p.x() - p.x()) + (p.y() - p.y()) + (p.z() - p.z())) +
                    ((v.x() - v.x()) + (v.y() - v.y()) + (v.z() - v.z())) +
                    ((w.x() - w.x()) + (w.y() - w.y()) + (w.z() - w.z()));
  const Real q2 = q.squaredNorm();
  ok &= (zero == 0) & (q2 >= kLo) & (q2 <= kHi);
  unit &= std::abs(q2 - 1) <= 1e-15;
}

}  // namespace

bool World::validate_state() {
  // The state arrays are writable views: check what the user may have written before
  // anything moves, so bad values raise and leave the world as it was. The quick test
  // first; anything it flags takes the exact loops.
  auto fail = [](const char* array, int i, const std::string& got) {
    throw InvalidArgument(std::string(array) + "[" + std::to_string(i) + "] " + got);
  };
  const int nb = body_count();
  bool all_ok = true, all_unit = true;
  for (int i = 0; i < nb; ++i)
    quick_state_test(positions_[i], linear_velocities_[i], angular_velocities_[i], orientations_[i], all_ok,
                     all_unit);
  if (all_ok && all_unit && islands_.size() == free_islands_.size()) return false;  // nothing asleep either
  if (!all_ok)
    for (int i = 0; i < nb; ++i) {
      if (!positions_[i].allFinite()) fail("positions", i, "must be finite, got " + to_string(positions_[i]));
      if (!linear_velocities_[i].allFinite())
        fail("linear_velocities", i, "must be finite, got " + to_string(linear_velocities_[i]));
      if (!angular_velocities_[i].allFinite())
        fail("angular_velocities", i, "must be finite, got " + to_string(angular_velocities_[i]));
      const Real qn = orientations_[i].norm();
      if (!std::isfinite(qn) || std::abs(qn - 1) > kUnitQuatTolerance)
        fail("orientations", i, "must be a unit quaternion, got norm " + std::to_string(qn));
    }
  // A sleeping body has zero velocity and the pose it fell asleep at: anything else was
  // written by the user, and wakes its island. (Checked on the values as written,
  // before the normalisation below, which may change the last bit.)
  bool changed = false;
  if (islands_.size() > free_islands_.size())  // some island sleeps
    for (int i = 0; i < body_count(); ++i) {
      if (sleep_island_[i] < 0) continue;
      if (!linear_velocities_[i].isZero(0) || !angular_velocities_[i].isZero(0) ||
          positions_[i] != sleep_position_[i] || !(orientations_[i].coeffs() == sleep_orientation_[i].coeffs())) {
        wake_island(sleep_island_[i]);
        changed = true;
      }
    }
  // Within tolerance: normalised. One that is unit to rounding already (|q|^2 within
  // 1e-15 of 1, as every step leaves them) is left alone: normalising it would change
  // at most its last bits, for a square root and a division per body per step. Sleeping
  // bodies keep the (unit) orientation they fell asleep with, bit for bit, so that the
  // check above stays meaningful.
  if (all_unit) return changed;
  for (int i = 0; i < nb; ++i)
    if (sleep_island_[i] < 0 && std::abs(orientations_[i].squaredNorm() - 1) > 1e-15) {
      orientations_[i].normalize();
      changed = true;
    }
  return changed;
}

void World::step(int n) {
  if (n < 0) throw InvalidArgument("n must be >= 0, got " + std::to_string(n));
  if (n == 0) return;
  // The state check only where the user may have written (the State accessors, world.h),
  // made by the first step's update_broadphase on the state it reads anyway. A view
  // released after the last step may have written before it was: one more check.
  const bool held = state_views_held();
  const bool check = state_writable_ || state_shared_ || held;
  for (int k = 0; k < n; ++k) {
    run_step(check && k == 0);
    if (k == 0) state_shared_ = held;  // the check passed
  }
}

void World::integrate_velocities(Real h) {
  for (const int i : coupled_)
    if (kinds_[i] == BodyKind::kDynamic) integrate_velocity(i, states_[i], body_flags_[i], h);
}

namespace {

// Two builds on x86-64 (GCC target_clones: AVX2, 4 doubles an instruction, and the
// baseline SSE2, 2), picked at load time, as the wide contact solver's kernels; no
// fused multiply-add in either, so both give the same bits. 10,000 free-falling
// spheres: the solve stage ~69 -> ~63 us (median).
#if defined(__x86_64__)
#define WMO_TRANSLATE_CLONES __attribute__((target_clones("avx2", "default")))
#else
#define WMO_TRANSLATE_CLONES
#endif

/// True if any of the m doubles at x is not 0 (NaN included): a flat pass over a
/// chunk's angular velocities, so that a chunk of bodies that do not turn skips the
/// per-body test (10,000 free-falling spheres: the solve stage ~51 -> ~40 us).
WMO_TRANSLATE_CLONES bool any_nonzero(const Real* x, int m) {
  long long any = 0;
  for (int j = 0; j < m; ++j) any |= static_cast<long long>(!(x[j] == 0));
  return any != 0;
}

/// `substeps` substeps of the free translation of m coordinates (integrate_plain_run):
/// v1 = v0 + dv, x += half_h (v0 + v1), coordinate by coordinate.
WMO_TRANSLATE_CLONES void translate_free(Real* __restrict x, Real* __restrict v, const Real* __restrict dv, int m,
                                         Real half_h, int substeps) {
  for (int sub = 0; sub < substeps; ++sub)
    for (int j = 0; j < m; ++j) {
      const Real v0 = v[j];
      const Real v1 = v0 + dv[j];
      v[j] = v1;
      x[j] += half_h * (v0 + v1);
    }
}

typedef double v4d __attribute__((vector_size(32)));
typedef long long v4l __attribute__((vector_size(32)));

[[gnu::always_inline]] inline v4d load3(const Real* a) { return v4d{a[0], a[1], a[2], 0}; }
[[gnu::always_inline]] inline v4d load4(const Real* a) {
  v4d x;
  std::memcpy(&x, a, sizeof x);
  return x;
}
[[gnu::always_inline]] inline void store4(Real* a, v4d x) { std::memcpy(a, &x, sizeof x); }
[[gnu::always_inline]] inline Real max_abs3(v4d x) {
  const v4d a = x < 0 ? -x : x;
  return std::max(std::max(a[0], a[1]), a[2]);
}

/// update_broadphase's box rule and the broadphase's keep test (keep_proxy_unchecked)
/// for the sphere bodies [begin, end), each awake and not swept whole (no CCD this
/// step), on 4-double vectors (x, y, z, unused): the same operations in the same order
/// as the scalar code, without fused multiply-adds, so the same boxes and verdicts.
/// A body whose box keeps its fat box gets its tight box set; the others (and any body
/// with a non-finite position or velocity) are listed in `declined`, for the scalar
/// path to move. Returns how many are listed. Two builds on x86-64 as translate_free.
/// Measured: 10,000 free-falling spheres, update_broadphase ~104 -> ~70 us a step.
WMO_TRANSLATE_CLONES int keep_sphere_boxes(int begin, int end, const Vec3* pos, const Vec3* vel,
                                           const std::shared_ptr<const Shape>* shapes, const ProxyId* proxies,
                                           Real spec, Real motion, Real static_motion, Real dt,
                                           const Broadphase::KeepRule& kr, int* declined, const Vec3* ang,
                                           const Quat* ori, bool check_state, bool& all_ok, bool& all_unit) {
  int count = 0;
  const v4d zero{0, 0, 0, 0};
  const Aabb* const fat = kr.fat;
  Aabb* const tight = kr.tight;
  const Real margin = kr.margin, multiplier = kr.multiplier, base_slack = kr.slack_margins * kr.margin;
  for (int i = begin; i < end; ++i) {
    // The state check's quick test (update_broadphase), where the step makes it.
    if (check_state) quick_state_test(pos[i], vel[i], ang[i], ori[i], all_ok, all_unit);
    // (x, y, z) in lanes 0-2; lane 3 is whatever follows (the next row's x, while
    // there is a next row in the run) and is ignored by the verdict.
    const v4d p = i + 1 < end ? load4(pos[i].data()) : load3(pos[i].data());
    const v4d v = i + 1 < end ? load4(vel[i].data()) : load3(vel[i].data());
    const Real r = static_cast<const Sphere&>(*shapes[i]).radius();
    v4d d = motion * v;
    const v4d ds = static_motion * v;
    if (max_abs3(ds) > spec) d = ds;
    // (p - r) - spec + min(d, 0), (p + r) + spec + max(d, 0), as Eigen's cwiseMin/Max.
    const v4d lo_box = ((p - r) - spec) + (zero < d ? zero : d);
    const v4d hi_box = ((p + r) + spec) + (d < zero ? zero : d);
    const v4d move = dt * v;
    const v4d dm = multiplier * move;
    const Real slack = base_slack + multiplier * max_abs3(move);
    const v4d lo = ((lo_box - margin) + (zero < dm ? zero : dm)) - slack;
    const v4d hi = ((hi_box + margin) + (dm < zero ? zero : dm)) + slack;
    const auto id = static_cast<std::size_t>(proxies[i]);
    const Real* const f = fat[id].min.data();  // min x, y, z, max x, y, z
    const v4d fmin = load4(f);                  // lane 3: max x
    const v4d fz = load4(f + 2);                // min z, max x, y, z
    const v4d fmax = __builtin_shufflevector(fz, fz, 1, 2, 3, 3);
    // x - x == 0 only for finite x.
    const v4l ok = (fmin <= lo_box) & (hi_box <= fmax) & (lo <= fmin) & (fmax <= hi) & ((p - p) == zero) &
                   ((v - v) == zero);
    if (ok[0] & ok[1] & ok[2]) {
      // The six doubles of the tight box in two overlapping stores.
      Real* const t = tight[id].min.data();
      store4(t, __builtin_shufflevector(lo_box, hi_box, 0, 1, 2, 4));
      store4(t + 2, __builtin_shufflevector(lo_box, hi_box, 2, 4, 5, 6));
    } else {
      declined[count++] = i;
    }
  }
  return count;
}

typedef std::uint8_t v32u8 __attribute__((vector_size(32)));

/// The solve stage's scan for plain free bodies (run_step), 32 bodies at a time from
/// `begin` while all 32 are plain: each gets flags[j] |= traits[j] | (gyro_bit if its
/// inertia is not isotropic), and is plain if awake, dynamic and none of `not_plain`'s
/// bits is set. Returns the first body of the first block with a body that is not
/// plain (or of the tail under 32): the scalar loop takes over there. Two builds on
/// x86-64 (AVX2 and the baseline). 10,000 free-falling spheres: the solve stage ~63 -> ~51 us.
WMO_TRANSLATE_CLONES int scan_plain_blocks(int begin, int n, const std::uint8_t* traits, const std::uint8_t* awake,
                                           const std::uint8_t* kinds, std::uint8_t* flags, std::uint8_t gyro_bit,
                                           std::uint8_t not_plain, std::uint8_t isotropic, std::uint8_t dynamic) {
  constexpr int kBlock = 32;
  auto load = [](const std::uint8_t* p) {
    v32u8 x;
    std::memcpy(&x, p, sizeof x);
    return x;
  };
  const v32u8 zero = {};
  int j = begin;
  for (; j + kBlock <= n; j += kBlock) {
    const v32u8 tr = load(traits + j);
    const v32u8 anisotropic = (tr & isotropic) == zero;  // 0xFF where not isotropic
    const v32u8 f = load(flags + j) | tr | (anisotropic & gyro_bit);
    const v32u8 plain = (load(awake + j) != zero) & (load(kinds + j) == dynamic) & ((f & not_plain) == zero);
    std::uint64_t all = ~std::uint64_t{0};
    for (int k = 0; k < kBlock; k += 8) {
      std::uint64_t lanes;
      std::memcpy(&lanes, reinterpret_cast<const unsigned char*>(&plain) + k, sizeof lanes);
      all &= lanes;
    }
    if (all != ~std::uint64_t{0}) break;
    std::memcpy(flags + j, &f, sizeof f);
  }
  return j;
}

}  // namespace

void World::integrate_plain_run(int begin, int end, Real h, int substeps) {
  if (end > begin) plain_runs_.emplace_back(begin, end);
  // Chunks of kChunk bodies take all their substeps while their state (104 bytes a
  // body) stays in the L1 cache; the bodies are independent, so the order changes no
  // bit. Within a chunk the translation runs over the positions and velocities as flat
  // arrays of doubles (3 per body, the rows' layout), each coordinate independent:
  //   v1 = v0 + dv,  x += (h / 2) (v0 + v1),  dv = (h gravity_scale) g,
  // the centre of mass moving with the substep's mean velocity, as in
  // integrate_position (exact under gravity). Written per Vec3 row, the compiler made
  // scalar code of it (a 3-vector fills no SIMD register evenly); flat, the loop is
  // vectorised. Same operations on every coordinate, so the same bits. The rotation,
  // independent of the translation, follows body by body (integrate_rotation's
  // substeps; nothing for a body that does not turn, checked once a step rather than
  // every substep). 10,000 free-falling spheres: the solve stage ~114 -> ~69 us (median),
  // and -> ~63 with the AVX2 build of translate_free.
  // Locals rather than members: through `this` the compiler reloaded h, the gravity
  // and the arrays' storage after every store to a double that might alias them.
  constexpr int kChunk = 128;
  const Vec3 g = settings_.gravity;
  const Real half_h = 0.5 * h;
  Vec3* const pos = positions_.data();
  Quat* const ori = orientations_.data();
  Vec3* const vel = linear_velocities_.data();
  const Vec3* const ang = angular_velocities_.data();
  const Real* const scale = gravity_scale_.data();
  alignas(64) std::array<Real, 3 * kChunk> dv;
  for (int b = begin; b < end; b += kChunk) {
    const int e = std::min(end, b + kChunk);
    const int m = 3 * (e - b);
    for (int i = b; i < e; ++i) {
      const Vec3 d = (h * scale[i]) * g;
      dv[3 * (i - b)] = d.x();
      dv[3 * (i - b) + 1] = d.y();
      dv[3 * (i - b) + 2] = d.z();
    }
    translate_free(pos[b].data(), vel[b].data(), dv.data(), m, half_h, substeps);
    if (!any_nonzero(ang[b].data(), m)) continue;  // no body of the chunk turns
    for (int i = b; i < e; ++i) {
      const Vec3 w = ang[i];
      if ((w.x() == 0) & (w.y() == 0) & (w.z() == 0)) continue;
      Quat q = ori[i];
      for (int sub = 0; sub < substeps; ++sub) q = integrate_rotation(q, w, h);
      ori[i] = q;
    }
  }
}

bool World::inertia_follows_turn(int i) const {
  const BodyState& s = states_[i];
  return !(body_flags_[i] & kIsotropic) && s.inv_mass > 0 && s.dq.vec().squaredNorm() > kRowMassTurnSin2;
}

Real World::overlap_allowance(int a, int b, int child_a, int child_b) const {
  Real thinnest = kInf;
  for (const auto& [i, child] : {std::pair{a, child_a}, std::pair{b, child_b}}) {
    // A static sheet may have no thickness; a shape without an inner radius gives none.
    if (kinds_[i] != BodyKind::kDynamic || !(inner_radius_[i] > 0)) continue;
    Real thickness = 2 * inner_radius_[i];
    if (shapes_[i]->type() == ShapeType::kCompound) {
      // A compound's inner radius is its thinnest child's, which need not be the child
      // that touches: a rod with a ball at its end, spinning on the ground, had its ball
      // held to the rod's allowance (2 cm of 8 cm) and the excess pushes added energy
      // (test_a_rod_spinning_flat_on_the_ground_gains_no_energy). The touching child's
      // own thickness instead (dispatch names it in every compound manifold).
      const auto& children = static_cast<const Compound&>(*shapes_[i]).children();
      if (child >= 0 && child < static_cast<int>(children.size()))
        thickness = 2 * inner_radius(*children[child].shape);
    }
    thinnest = std::min(thinnest, thickness);
  }
  return thinnest < kInf ? kOverlapAllowance * thinnest : kInf;
}

void World::integrate_positions(Real h) {
  inertia_turned_.clear();
  for (const int i : coupled_) {
    BodyState& s = states_[i];
    integrate_position(i, s, body_flags_[i], h, s.v);
    if (inertia_follows_turn(i)) {
      s.inv_inertia = world_inv_inertia(orientations_[i], masses_[i].inv_inertia_local);
      inertia_turned_.push_back(i);
    }
  }
}

void World::integrate_velocity(int i, BodyState& s, std::uint8_t f, Real h) const {
  s.v += h * gravity_scale_[i] * settings_.gravity;
  // Forces, torques and damping only where a body has them (flags f).
  if (f & kHasForce) {
    s.v += h * masses_[i].inv_mass * forces_[i];
    s.w += h * (s.inv_inertia * torques_[i]);
  }
  if (f & kHasDamping) {
    // Implicit form of Box2D and Jolt: stable for any h * damping.
    s.v *= 1 / (1 + h * linear_damping_[i]);
    s.w *= 1 / (1 + h * angular_damping_[i]);
  }
}

void World::integrate_position(int i, BodyState& s, std::uint8_t f, Real h, const Vec3& v_move) {
  if (!(f & (kComOffset | kInContact | kGyroscopic))) {
    // The common case of a body that touches nothing, has its centre of mass at its
    // origin and no gyroscopic term.
    positions_[i] += h * v_move;
    orientations_[i] = integrate_rotation(orientations_[i], s.w, h);
    return;
  }
  // The origin moves with the centre of mass, turned about it; without an offset the
  // two are the same point (no rotation of a zero vector, a tenth of a boxes3000 step's
  // integration).
  const bool offset = f & kComOffset;
  const Vec3& lc = masses_[i].local_com;
  const Vec3 com = offset ? Vec3(positions_[i] + orientations_[i] * lc + h * v_move) : Vec3(positions_[i] + h * v_move);
  // The rotation uses w_rot; without the gyroscopic term it is the velocity itself.
  Vec3 w_rot = s.w;
  Quat q;
  Quat correction = Quat::Identity();  // world-frame turn the projection added (below)
  bool split = false;                   // the gyroscopic rotation taken in parts (below)
  Quat start = Quat::Identity();        // the orientation before the substep, when split
  if (f & kGyroscopic) {
    // Torque-free rotation keeps the world angular momentum L = R I R^T w while R
    // turns. Implicit midpoint on the rotation: w_rot = I(R_mid)^-1 L with R_mid
    // the half-substep rotation by w_rot (three fixed-point passes; each gains about
    // an order of h |w| in accuracy), then the new velocity is I(R_new)^-1 L. L is
    // conserved to rounding; the midpoint rule alone lets the energy drift (measured
    // over 6000 steps: -3.5% for a spinning 50:1 rod, +2.6e-5 near the intermediate
    // axis), where Catto's implicit Newton step on the Euler equations dissipates
    // (25-100% of L lost over 10 s at 240 Hz) and the explicit term gains energy.
    //
    // The fixed point converges only while the body turns by well under a radian in
    // the interval: a light hull kicked off its centre to 600 rad/s (5 rad a substep)
    // got a garbage w_rot, the projection below (small corrections only) could not
    // mend it, |L| was kept but the energy could rise by the inertia ratio every
    // substep, and the body spun up to 15,000 rad/s and flung itself 130 km (found by
    // a random-scene fuzz). So the substep's rotation is taken in parts, each a
    // midpoint step from where the last one ended, each turning by at most kGyroTurn
    // rad at the angular velocity where it starts (I(R)^-1 L there): the speed is
    // measured anew at every part because it changes within the substep. A thin rod
    // (inertia 1:383) tumbling at 60 rad/s moves L towards its long axis, where the
    // same L spins it 383 times faster; with the parts sized once, from the speed at
    // the start, it reached 2,600 rad/s in one 1/60 s step and its energy rose 5.6
    // times. At most kMaxParts parts (the last ones longer if need be). One part
    // (every body turning slower than kGyroTurn / h: 60 rad/s at 240 Hz) is the
    // unsplit step, bit for bit.
    constexpr Real kGyroTurn = 0.25;
    constexpr Real kGyroConverged = 1e-4;
    constexpr int kMaxParts = 256;
    const Mat3& ib = masses_[i].inertia_local;
    const Mat3& ib_inv = masses_[i].inv_inertia_local;
    const Quat& q0 = orientations_[i];
    const Mat3 r0 = q0.toRotationMatrix();
    const Vec3 l = r0 * (ib * (r0.transpose() * s.w));
    const Real e0 = 0.5 * s.w.dot(l);
    start = q0;
    Quat q1 = q0;
    Vec3 w_start = s.w;  // the angular velocity where the part starts
    Real left = h;       // of the substep, s
    for (int parts = 0; left > 0; ++parts) {
      const Real shortest = left / (kMaxParts - parts);  // the last part takes what is left
      Real hp = left;
      const Real speed = w_start.norm();
      if (!(hp * speed <= kGyroTurn)) hp = std::max(kGyroTurn / speed, shortest);
      const Quat qa = q1;
      for (;;) {
        w_rot = w_start;
        Vec3 before = w_rot;
        for (int pass = 0; pass < 3; ++pass) {
          before = w_rot;
          const Mat3 rm = integrate_rotation(qa, w_rot, 0.5 * hp).toRotationMatrix();
          w_rot = rm * (ib_inv * (rm.transpose() * l));
        }
        // Converged when the last pass changed w_rot by at most kGyroConverged of it;
        // else the part is halved. The pass contracts by about h |w| times the
        // inertia ratio, not h |w| alone: the 1:383 rod's parts of 0.25 rad left a 1.8%
        // energy error that the projection below (small corrections only) kept.
        if ((w_rot - before).squaredNorm() <= kGyroConverged * kGyroConverged * w_rot.squaredNorm() ||
            !(hp > shortest))
          break;
        hp = std::max(Real(0.5) * hp, shortest);
      }
      left = hp < left ? left - hp : 0;
      split = split || left > 0;
      q1 = integrate_rotation(qa, w_rot, hp);
      if (left > 0) {
        const Mat3 r = q1.toRotationMatrix();
        w_start = r * (ib_inv * (r.transpose() * l));
      }
    }
    const Mat3 r1 = q1.toRotationMatrix();
    // Energy-momentum projection (Hairer, Lubich and Wanner, Geometric Numerical
    // Integration, IV.4): both invariants of the torque-free body live in its body
    // frame, |M| = |L| and E = M.I^-1 M / 2 for the body momentum M = R^T L. R1's M
    // has the right length but misses E0 by the midpoint's error; M is moved along
    // the sphere |M| = |L| (the energy gradient I^-1 M less its part along M), two
    // Newton steps, and R1 turned in the body frame by the rotation taking the moved
    // M onto R1's (C, with R = R1 C, so R^T L = C^T R1^T L is the moved M). L stays
    // exact, E is kept to rounding, and the orientation turns by an angle of the
    // order of the relative energy error (the midpoint rule's). Where M is nearly a
    // principal axis the gradient has no part along the sphere and E is stationary
    // there: an error within round-off (1e-13 E) is left, a step larger than
    // 1e-3 |M| is not taken, nor one that does not reduce the error.
    const Vec3 m1 = r1.transpose() * l;
    const Real m2 = m1.squaredNorm();
    Vec3 m = m1;
    Real de = 0.5 * m.dot(ib_inv * m) - e0;
    for (int it = 0; it < 2 && std::abs(de) > 1e-13 * e0; ++it) {  // beyond round-off
      const Vec3 g = ib_inv * m;
      const Vec3 t = g - (g.dot(m) / m2) * m;
      const Real t2 = t.squaredNorm();
      if (!(std::abs(de) < 1e-3 * std::sqrt(t2 * m2))) break;  // also t2 = 0 and NaN
      Vec3 next = m - (de / t2) * t;
      next *= std::sqrt(m2 / next.squaredNorm());
      const Real de_next = 0.5 * next.dot(ib_inv * next) - e0;
      if (!(std::abs(de_next) < std::abs(de))) break;  // round-off: no better
      m = next;
      de = de_next;
    }
    if (m != m1) {
      Quat c;
      c.setFromTwoVectors(m, m1);
      q = (q1 * c).normalized();
      correction = q * q1.conjugate();
    } else {
      q = q1;
    }
    s.w = q * (ib_inv * m);
  } else {
    q = integrate_rotation(orientations_[i], w_rot, h);
  }
  orientations_[i] = q;
  positions_[i] = offset ? Vec3(com - q * lc) : com;
  if (f & kInContact) {  // the motion since the step's start, for the contact rows
    s.dp += h * s.v;
    if (split) {
      s.dq = ((q * start.conjugate()) * s.dq).normalized();  // the substep's whole turn
    } else {
      s.dq = integrate_rotation(s.dq, w_rot, h);
      if (f & kGyroscopic) s.dq = (correction * s.dq).normalized();
    }
  }
}

/// The solver's regions (World::solve_order): a pile with at least kRegionMinConstraints
/// contact constraints is cut into kSolverRegions slabs, which the passes may run on
/// that many threads at once. Fixed, not the thread count, so that the order, and with
/// it every result, is the same for any number of threads. Four: two threads get two
/// slabs each; the constraints that cross a cut (solved after the slabs, on one
/// thread) are ~13% of the pyramid's (~20,000 constraints). Below the minimum the
/// constraints keep their exact top-down sequence (dependency_level_order): on
/// boxes3000's ragged pile (4,000-5,000 constraints at its busiest) the banded order
/// left the lane groups emptier and cost the single-thread solve ~10% (measured
/// against the exact order at 2,048), more than a second thread wins back there.
constexpr int kSolverRegions = 4;
constexpr std::size_t kRegionMinConstraints = 8192;

void World::solve_order() {
  // Slabs along the horizontal axis (world X, Y or Z, not the one nearest to up) over
  // which the constraints spread most, cut at the quantiles of the constraints'
  // positions (the mean of their dynamic bodies') so that each holds about as many; a
  // body belongs to the slab its position falls in, a constraint to its dynamic
  // bodies' slab, or to the boundary when they lie in two. Within each slab, and in
  // the boundary, the constraints keep their top-down order by bands of height,
  // coloured within a band (region_band_order).
  const std::size_t total = constraints_.size();
  if (total < kRegionMinConstraints) {
    dependency_level_order(constraints_, states_, solve_order_, solve_scratch_);
    solve_starts_.clear();
    return;
  }
  // Up (-gravity; +Y without gravity, where any order is valid and only the bands'
  // sizes depend on it) for both the slabs' axis and the bands' heights.
  const Real g = settings_.gravity.norm();
  const Vec3 up = g > 0 ? Vec3(-settings_.gravity / g) : Vec3::UnitY();
  const Vec3 up_abs = up.cwiseAbs();
  solve_region_.resize(total);
  const int regions = kSolverRegions;
  {
    auto moving = [&](int b) { return states_[static_cast<std::size_t>(b)].inv_mass > 0; };
    int up_axis = -1;
    if (g > 0) up_abs.maxCoeff(&up_axis);
    Vec3 lo = Vec3::Constant(kInf), hi = Vec3::Constant(-kInf);
    for (const ContactConstraint& c : constraints_)
      for (const int b : {c.body_a, c.body_b})
        if (moving(b)) {
          lo = lo.cwiseMin(positions_[static_cast<std::size_t>(b)]);
          hi = hi.cwiseMax(positions_[static_cast<std::size_t>(b)]);
        }
    int axis = 0;
    Real spread = -1;
    for (int d = 0; d < 3; ++d)
      if (d != up_axis && hi[d] - lo[d] > spread) {
        spread = hi[d] - lo[d];
        axis = d;
      }
    solve_coord_.resize(total);
    for (std::size_t k = 0; k < total; ++k) {
      const ContactConstraint& c = constraints_[k];
      Real sum = 0;
      int n = 0;
      for (const int b : {c.body_a, c.body_b})
        if (moving(b)) {
          sum += positions_[static_cast<std::size_t>(b)][axis];
          ++n;
        }
      solve_coord_[k] = n ? sum / n : 0;
    }
    std::array<Real, kSolverRegions - 1> cut{};
    for (int j = 1; j < kSolverRegions; ++j) {
      auto at = solve_coord_.begin() + static_cast<std::ptrdiff_t>(total * static_cast<std::size_t>(j) / kSolverRegions);
      std::nth_element(solve_coord_.begin(), at, solve_coord_.end());
      cut[static_cast<std::size_t>(j) - 1] = *at;
    }
    auto slab = [&](int b) {
      const Real x = positions_[static_cast<std::size_t>(b)][axis];
      int r = 0;
      for (const Real c : cut) r += x >= c;
      return r;
    };
    for (std::size_t k = 0; k < total; ++k) {
      const ContactConstraint& c = constraints_[k];
      const bool da = moving(c.body_a), db = moving(c.body_b);
      const int ra = da ? slab(c.body_a) : -1, rb = db ? slab(c.body_b) : -1;
      solve_region_[k] = !da && !db ? 0 : !da ? rb : !db ? ra : ra == rb ? ra : regions;
    }
  }
  // Heights and band widths for region_band_order: a constraint's height is
  // order_pairs_top_down's key (the higher of its bodies' lowest points along up);
  // a band reaches down from its first constraint by half the height of that
  // constraint's smaller dynamic body, so that the layers of a stack (unit boxes: 1 m
  // apart) stay in separate bands, in their top-down order, while the side contacts
  // and supports of one layer share a band and are coloured.
  solve_height_.resize(total);
  solve_band_.resize(total);
  for (std::size_t k = 0; k < total; ++k) {
    const ContactConstraint& c = constraints_[k];
    Real height = -kInf, half = kInf;
    for (const int b : {c.body_a, c.body_b}) {
      const Aabb& box = broadphase_->aabb(proxies_[static_cast<std::size_t>(b)]);
      const Real extent = up_abs.dot(box.half_extents());
      height = std::max(height, up.dot(box.center()) - extent);
      if (states_[static_cast<std::size_t>(b)].inv_mass > 0) half = std::min(half, extent);
    }
    solve_height_[k] = height;
    solve_band_[k] = half < kInf ? half : 0;
  }
  region_band_order(constraints_, states_, solve_region_, regions, solve_height_, solve_band_, solve_order_,
                    solve_starts_, solve_bits_);
}

void World::order_pairs_top_down() {
  // Gauss-Seidel carries a load only as far as the order of its rows lets it in one
  // pass: solved from the top down, the weight of a stack reaches the ground within
  // the pass; in broadphase order, a heavy box on a light one rocks the light one
  // loose (measured: a 100:1 two-box stack at 60 Hz falls over in broadphase order,
  // stands in this one). The pairs are ordered before the narrowphase, so the
  // constraints are made in that order and never copied. Key: the height of the
  // pair's upper bottom, max over the two bodies of the lowest point of its box along
  // up (for a body resting on another, the height of the interface), highest first,
  // ties in broadphase order (deterministic). Without gravity there is no up and the
  // broadphase order is kept.
  const Real g = settings_.gravity.norm();
  const std::size_t n = pairs_.size();
  if (g == 0 || n < 2) return;
  const Vec3 up = -settings_.gravity / g;
  const Vec3 up_abs = up.cwiseAbs();
  auto bottom = [&](ProxyId id) {
    const Aabb& box = broadphase_->aabb(id);
    return up.dot(box.center()) - up_abs.dot(box.half_extents());
  };
  // Sort keys in order_scratch_[0, n); the radix passes ping-pong between that and
  // [n, 2n).
  order_scratch_.resize(2 * n);
  std::uint64_t* key = order_scratch_.data();
  for (std::size_t k = 0; k < n; ++k) {
    // float keys order the heights to 1e-7 relative, finer than any stack's layers.
    // Mapped to unsigned so they order like the floats (sign bit set on non-negative
    // values, all bits flipped on negative ones), then complemented: highest first.
    const float h = static_cast<float>(std::max(bottom(pairs_[k].first), bottom(pairs_[k].second)));
    std::uint32_t bits;
    std::memcpy(&bits, &h, sizeof bits);
    bits = (bits & 0x80000000u) ? ~bits : (bits | 0x80000000u);
    key[k] = (static_cast<std::uint64_t>(~bits) << 32) | k;
  }
  // Least-significant-digit radix sort on the 32 key bits, 11 bits a pass: stable, so
  // ties keep broadphase order (the index in the low bits), as a full sort of the
  // 64-bit keys would; three linear passes instead of n log n comparisons (std::sort
  // was a third of this stage on boxes3000).
  std::uint64_t* from = key;
  std::uint64_t* to = key + n;
  constexpr int kRadixBits = 11;
  constexpr std::size_t kBuckets = std::size_t{1} << kRadixBits;
  std::array<std::uint32_t, kBuckets> count;
  for (int shift = 32; shift < 64; shift += kRadixBits) {
    count.fill(0);
    for (std::size_t k = 0; k < n; ++k) ++count[(from[k] >> shift) & (kBuckets - 1)];
    std::uint32_t start = 0;
    for (std::uint32_t& c : count) start += std::exchange(c, start);
    for (std::size_t k = 0; k < n; ++k) to[count[(from[k] >> shift) & (kBuckets - 1)]++] = from[k];
    std::swap(from, to);
  }
  pair_scratch_.resize(n);
  for (std::size_t k = 0; k < n; ++k) pair_scratch_[k] = pairs_[from[k] & 0xFFFFFFFFu];
  pairs_.swap(pair_scratch_);
}

namespace {
/// Shapes whose pairs make at most one manifold (no children), so a pair's cache entry
/// holds all of its contact: not compounds, not meshes.
bool single_manifold_shape(const Shape& s) {
  return s.type() != ShapeType::kCompound && s.type() != ShapeType::kTriangleMesh;
}

/// Radius of curvature (m) of body shape `s` at a contact whose outward surface normal
/// (from the body into the other one) is `outward` (world), for the solver's anchors
/// (ContactConstraintPoint::ca_n): the convex radius of the touching shape (a sphere's
/// or capsule's radius, a rounded box's rounding, 0 for sharp shapes, meshes and
/// planes), and a cylinder's radius where it touches with its side (the normal within
/// 1e-3 of perpendicular to its axis: lying on it, it rolls); on a cap or the rim the
/// touching point is a vertex of its outline (0). `child` picks a compound's child.
Real contact_curvature(const Shape& s, int child, const Quat& orientation, const Vec3& outward) {
  const Shape* leaf = &s;
  Quat q = orientation;
  if (s.type() == ShapeType::kCompound) {
    const auto& children = static_cast<const Compound&>(s).children();
    if (child < 0 || child >= static_cast<int>(children.size())) return 0;
    leaf = children[static_cast<std::size_t>(child)].shape.get();
    q = orientation * children[static_cast<std::size_t>(child)].pose.rotation;
  }
  switch (leaf->type()) {
    case ShapeType::kCylinder: {
      const Real axial = (q.conjugate() * outward).y();
      return std::abs(axial) <= 1e-3 ? static_cast<const Cylinder*>(leaf)->cylinder_radius() : Real(0);
    }
    case ShapeType::kSphere:
    case ShapeType::kBox:
    case ShapeType::kCapsule:
    case ShapeType::kConvexHull:
      return static_cast<const ConvexShape*>(leaf)->radius();
    default:
      return 0;
  }
}
}  // namespace

void World::collide_pair(int sa, int sb, int a, int b, Real margin, NarrowphaseOut& out) const {
  CollideSettings cs;
  cs.margin = margin;
  out.manifolds.clear();
  const Pose pose_a(positions_[a], orientations_[a]), pose_b(positions_[b], orientations_[b]);
  // The rotations as matrices: a pair rotates a dozen vectors (a reused manifold's
  // points, the normal, the centres of mass), a matrix product each.
  const Mat3 rot_a = orientations_[a].toRotationMatrix(), rot_b = orientations_[b].toRotationMatrix();
  // B relative to A, as the manifold cache stores it.
  const Quat qa_inv = orientations_[a].conjugate();
  const Vec3 rel_p = rot_a.transpose() * (positions_[b] - positions_[a]);
  const Quat rel_q = qa_inv * orientations_[b];
  const bool cacheable = single_manifold_shape(*shapes_[a]) && single_manifold_shape(*shapes_[b]);
  const ManifoldGeometry* reuse = nullptr;
  // A pair of single-manifold shapes has one cache entry (no children): looked up once,
  // for reuse and for warm starting.
  const int single = cacheable ? cache_.find(manifold_key(sa, sb, -1, -1)) : -1;
  if (cacheable && settings_.manifold_reuse_distance > 0 && settings_.manifold_reuse_angle > 0) {
    if (single >= 0 && cache_.value(single).geometry.valid) {
      const ManifoldGeometry& g = cache_.value(single).geometry;
      const Real d2 = (rel_p - g.rel_position).squaredNorm();
      // |q1 . q2| = cos(half the angle between the rotations).
      const Real cos_half = std::abs(rel_q.dot(g.rel_rotation));
      if (d2 <= settings_.manifold_reuse_distance * settings_.manifold_reuse_distance &&
          cos_half >= reuse_cos_half_)
        reuse = &g;
    }
  }
  if (reuse) {
    // The cached points carried along with their bodies; depths measured anew along
    // the (A-fixed) normal: depth = n . (point_a - point_b).
    Manifold& m = out.manifolds.emplace_back();
    m.normal = rot_a * reuse->normal;
    m.count = 0;
    for (int k = 0; k < reuse->count; ++k) {
      const Vec3 p_a = rot_a * reuse->point_a[k] + positions_[a];
      const Vec3 p_b = rot_b * reuse->point_b[k] + positions_[b];
      m.add(p_a, p_b, m.normal.dot(p_a - p_b), reuse->feature_id[k]);
    }
    ++out.reused;
  } else {
    // A mesh asks whether, and from which side, the pair touched a triangle at the last
    // step (the cache holds the last step's manifolds until store_impulses): a body
    // pushed behind a one-sided triangle, or past a two-sided one's middle, within one
    // step is pushed back out the way it came (CollideSettings::touched_before). The
    // other side's children: a compound's, or none (-1).
    struct Touched {
      const FlatMap<CachedManifold, ManifoldKey>* cache;
      int sa, sb, other_children;
      bool mesh_first;
    } touched{};
    const Shape& sha = *shapes_[a];
    const Shape& shb = *shapes_[b];
    const bool mesh_a = sha.type() == ShapeType::kTriangleMesh, mesh_b = shb.type() == ShapeType::kTriangleMesh;
    if ((mesh_a || mesh_b) && !cache_.empty()) {
      const Shape& other = mesh_a ? shb : sha;
      touched = {&cache_, sa, sb,
                 other.type() == ShapeType::kCompound
                     ? static_cast<int>(static_cast<const Compound&>(other).children().size())
                     : 0,
                 mesh_a};
      cs.touched_context = &touched;
      cs.touched_before = [](const void* context, int t) {
        const Touched& q = *static_cast<const Touched*>(context);
        for (int c = q.other_children > 0 ? 0 : -1; c < std::max(q.other_children, 0); ++c) {
          const int i = q.cache->find(q.mesh_first ? manifold_key(q.sa, q.sb, t, c) : manifold_key(q.sa, q.sb, c, t));
          if (i >= 0 && q.cache->value(i).geometry.mesh_side != 0) return static_cast<int>(q.cache->value(i).geometry.mesh_side);
        }
        return 0;
      };
    }
    collide(sha, pose_a, shb, pose_b, out.manifolds, cs);
  }
  if (out.manifolds.empty()) return;
  // What the cache keeps of this pair's manifold (store_impulses).
  ManifoldGeometry geometry;  // invalid by default: nothing to reuse next step
  if (reuse) {
    geometry.keep_cached = true;
  } else if (cacheable && out.manifolds.size() == 1) {
    const Manifold& m = out.manifolds[0];
    geometry.valid = true;
    geometry.rel_position = rel_p;
    geometry.rel_rotation = rel_q;
    geometry.normal = rot_a.transpose() * m.normal;
    geometry.count = m.count;
    for (int k = 0; k < m.count; ++k) {
      geometry.point_a[k] = rot_a.transpose() * (m.points[k].point_a - positions_[a]);  // inverse_transform_point
      geometry.point_b[k] = rot_b.transpose() * (m.points[k].point_b - positions_[b]);
      geometry.feature_id[k] = m.points[k].feature_id;
    }
  }
  const Vec3 com_a = positions_[a] + rot_a * masses_[a].local_com;  // world_com
  const Vec3 com_b = positions_[b] + rot_b * masses_[b].local_com;
  const Real mu = combine(settings_.friction_combine, frictions_[a], frictions_[b]);
  const Real e = combine(settings_.restitution_combine, restitutions_[a], restitutions_[b]);
  // The pair's overlap allowance; a compound's depends on the child each manifold touches.
  const bool per_child =
      shapes_[a]->type() == ShapeType::kCompound || shapes_[b]->type() == ShapeType::kCompound;
  const Real pair_allow = per_child ? kInf : overlap_allowance(a, b, -1, -1);
  for (const Manifold& m : out.manifolds) {
    if (m.count == 0) continue;
    const ManifoldKey key = manifold_key(sa, sb, m.child_a, m.child_b);
    const int cached_index = cacheable ? single : cache_.find(key);
    const CachedManifold* cached = cached_index >= 0 ? &cache_.value(cached_index) : nullptr;
    ContactConstraint& c = out.constraints.emplace_back();
    c.body_a = a;
    c.body_b = b;
    c.normal = m.normal;
    c.tangent1 = sliding_direction(m, a, b, com_a, com_b);
    if (c.tangent1.isZero(0))
      orthonormal_basis(c.normal, c.tangent1, c.tangent2);
    else
      c.tangent2 = c.normal.cross(c.tangent1);
    c.friction = mu;
    c.restitution = e;
    c.allow = per_child ? overlap_allowance(a, b, m.child_a, m.child_b) : pair_allow;
    c.count = m.count;
    const Real rho_a = contact_curvature(*shapes_[a], m.child_a, orientations_[a], m.normal);
    const Real rho_b = contact_curvature(*shapes_[b], m.child_b, orientations_[b], -m.normal);
    for (int k = 0; k < m.count; ++k) {
      const ContactPoint& cp = m.points[k];
      ContactConstraintPoint& p = c.points[k];
      const Vec3 mid = 0.5 * (cp.point_a + cp.point_b);
      p.ra = mid - com_a;
      p.rb = mid - com_b;
      p.adjusted_separation = -cp.depth - m.normal.dot(p.rb - p.ra);
      // Centres of curvature from each body's own touching point (point_a = mid +
      // depth/2 n, point_b = mid - depth/2 n), as offsets along n from the anchor.
      p.ca_n = 0.5 * cp.depth - rho_a;
      p.cb_n = rho_b - 0.5 * cp.depth;
      p.feature_id = cp.feature_id;
      if (cached) {
        for (int j = 0; j < cached->count; ++j) {
          const CachedPoint& old = cached->points[j];
          if (old.feature_id == cp.feature_id) {
            p.normal_impulse = old.normal_impulse;
            p.tangent_impulse = {c.tangent1.dot(old.tangent_impulse), c.tangent2.dot(old.tangent_impulse)};
            break;
          }
        }
      }
    }
    out.keys.push_back(key);
    out.geometry.push_back(geometry);
    if (m.child_a >= 0 && shapes_[a]->type() == ShapeType::kTriangleMesh) {
      // The side of the triangle the other body touched (ManifoldGeometry::mesh_side):
      // the normal points from the mesh to it.
      const Vec3 n = rot_a * static_cast<const TriangleMesh&>(*shapes_[a]).triangle_normal(m.child_a);
      out.geometry.back().mesh_side = m.normal.dot(n) >= 0 ? 1 : -1;
    } else if (m.child_b >= 0 && shapes_[b]->type() == ShapeType::kTriangleMesh) {
      const Vec3 n = rot_b * static_cast<const TriangleMesh&>(*shapes_[b]).triangle_normal(m.child_b);
      out.geometry.back().mesh_side = m.normal.dot(n) <= 0 ? 1 : -1;
    }
    out.entries.push_back(cached_index);
  }
}

// How far the bodies' relative translation carries their surfaces within one step
// (WorldSettings::speculative_motion). Static and sleeping bodies have zero velocity.
Real World::pair_motion_margin(int a, int b) const {
  Real scale = settings_.speculative_motion;
  if ((ccd_[a] || ccd_[b]) && settings_.enable_ccd) scale = std::max(scale, Real(1));  // CCD: all of it
  if (kinds_[a] != BodyKind::kDynamic || kinds_[b] != BodyKind::kDynamic)
    scale = std::max(scale, settings_.speculative_motion_static);
  if (scale == 0) return 0;
  return scale * settings_.dt * (linear_velocities_[b] - linear_velocities_[a]).norm();
}

Vec3 World::sliding_direction(const Manifold& m, int a, int b, const Vec3& com_a, const Vec3& com_b) const {
  // The friction rows use one effective mass per tangent, so their combined impulse
  // points along (m1 t1.v, m2 t2.v) rather than along the slip v; where m1 != m2
  // (the angular terms differ by direction) sliding friction is misdirected and
  // weaker than mu N (measured: 5% too little on a 35 degree slope). With t1 along
  // the slip, as Bullet and Jolt choose it, sliding friction opposes the slip. Slip
  // below 1e-4 m/s (a tenth of a millimetre per second) is resting contact, where
  // the basis does not matter: the fixed basis is kept.
  Vec3 mid = Vec3::Zero();
  for (int k = 0; k < m.count; ++k) mid += m.points[k].point_a + m.points[k].point_b;
  mid /= 2 * m.count;
  const Vec3 v = (linear_velocities_[b] + angular_velocities_[b].cross(mid - com_b)) -
                 (linear_velocities_[a] + angular_velocities_[a].cross(mid - com_a));
  const Vec3 vt = v - m.normal.dot(v) * m.normal;
  const Real len = vt.norm();
  return len > 1e-4 ? Vec3(vt / len) : Vec3(Vec3::Zero());
}
// The update_broadphase stage: every awake body's proxy gets the box its shapes occupy
// now, fattened by speculative_distance and swept by the step's predicted motion.
// Returns the number of proxies moved (kept within their fat boxes included). Its own
// function: inside run_step the loop's values were spilled to the stack (the function's
// many locals), ~13 ns a body.
long long World::update_broadphase(bool ccd, bool check_state) {
  const int n = body_count();
  const Real dt = settings_.dt;
  const Real spec = settings_.speculative_distance;
  long long moved = 0;
  const Real motion = settings_.speculative_motion * dt;
  const Real static_motion = std::max(settings_.speculative_motion, settings_.speculative_motion_static) * dt;
  const Real ccd_motion = std::max(settings_.speculative_motion, Real(1)) * dt;
  // Boxes in chunks, each handed to the broadphase in one call. The arrays are read
  // through local pointers: through `this` they were reloaded after every store to
  // a box (which might alias them).
  constexpr int kChunk = 64;
  std::array<ProxyId, kChunk> ids;
  std::array<int, kChunk> body;
  std::array<Aabb, kChunk> boxes;
  std::array<Vec3, kChunk> moves;
  int count = 0;
  Real finite = 0;  // 0 while every box of the chunk is finite, NaN after one is not
  const Vec3* const pos = positions_.data();
  const Quat* const ori = orientations_.data();
  const Vec3* const vel = linear_velocities_.data();
  const std::uint8_t* const awake = awake_.data();
  const std::uint8_t* const traits = traits_.data();
  const std::shared_ptr<const Shape>* const shapes = shapes_.data();
  const ProxyId* const proxies = proxies_.data();
  const Vec3* const ang = angular_velocities_.data();
  bool all_ok = true, all_unit = true;  // the state check's quick test (check_state)
  auto flush = [&] {
    int good = count;
    if (finite != 0) [[unlikely]] {
      // A non-finite box is refused here, as move_proxy would, before the tree sees
      // it; the bodies before it are moved, as one by one. Written by the user (the
      // state check's step), validate_state names the value; else a velocity blew up
      // in a previous step of this call.
      if (check_state) validate_state();
      good = 0;
      while (boxes[good].min.allFinite() && boxes[good].max.allFinite()) ++good;
    }
    broadphase_->move_proxies_unchecked(ids.data(), boxes.data(), moves.data(), good);
    moved += good;
    if (good < count) {
      const int i = body[good];
      throw InvalidArgument("body " + std::to_string(i) + " left the finite range (position " +
                            to_string(positions_[i]) + ", velocity " + to_string(linear_velocities_[i]) + ")");
    }
    count = 0;
    finite = 0;
  };
  // One body's box: kept in its fat box, or batched for the broadphase.
  auto visit = [&](int i) __attribute__((always_inline)) {
    if (!awake[i]) {  // static or sleeping: the proxy stays where it is
      if (check_state) quick_state_test(pos[i], vel[i], ang[i], ori[i], all_ok, all_unit);
      return;
    }
    if (check_state) quick_state_test(pos[i], vel[i], ang[i], ori[i], all_ok, all_unit);
    // The box swept by the step's predicted translation (the larger of
    // speculative_motion and speculative_motion_static, whose pairs with fixed
    // geometry must be found before the body reaches it; all of it for a CCD body,
    // and for a kinematic body while CCD is active: its motion is known, and a fast
    // one would otherwise jump over a resting CCD body), so that the pairs of
    // surfaces that can meet within the step are reported.
    const Vec3 v = vel[i];
    const bool sweep_all = ccd && (ccd_[i] || kinds_[i] == BodyKind::kKinematic);
    Vec3 d = (sweep_all ? ccd_motion : motion) * v;
    if (!sweep_all) {
      // Pairs with fixed geometry get speculative_motion_static's margin, so they
      // must be found before the body gets there: the box is swept by it too, but
      // only where the step moves the body more than speculative_distance along some
      // axis; a slower body's box, fattened by that distance, already covers its
      // step. (Sweeping every box found 8% more pairs in boxes3000, +0.2 ms a step;
      // this 4%, within the step time's noise.)
      const Vec3 ds = static_motion * v;
      if (ds.cwiseAbs().maxCoeff() > spec) d = ds;
    }
    Aabb box;
    if (traits[i] & kSphere) {  // Sphere::world_aabb without the call
      const Real r = static_cast<const Sphere&>(*shapes[i]).radius();
      box.min = (pos[i].array() - r) - spec;
      box.max = (pos[i].array() + r) + spec;
    } else {
      box = shapes[i]->world_aabb(Pose(pos[i], ori[i])).fattened(spec);
    }
    box.min += d.cwiseMin(Vec3::Zero());
    box.max += d.cwiseMax(Vec3::Zero());
    const Vec3 move = dt * v;
    // Most steps most boxes stay inside their fat boxes: decided inline, and only
    // the others are batched for the broadphase (a non-finite box is never kept).
    if (broadphase_->keep_proxy_unchecked(proxies[i], box, move)) {
      ++moved;
      return;
    }
    // The proxy is the body's own and min <= max by construction; x - x is 0 for a
    // finite x and NaN otherwise (flush finds the body).
    finite += ((box.min - box.min) + (box.max - box.max)).sum();
    boxes[count] = box;
    ids[count] = proxies[i];
    body[count] = i;
    moves[count] = move;
    if (++count == kChunk) flush();
  };
  // Runs of awake spheres, when nothing is swept whole (the common step of many free
  // bodies): their boxes and keep tests on vectors (keep_sphere_boxes, which also makes
  // the state check's quick test on them); only the bodies it declines are visited one
  // by one.
  const Broadphase::KeepRule kr = broadphase_->keep_rule();
  const bool vector_spheres = kr.fat != nullptr && !ccd;
  if (vector_spheres) sphere_declined_.resize(n);
  int* const declined = sphere_declined_.data();
  for (int i = 0; i < n; ++i) {
    if (vector_spheres && awake[i] && (traits[i] & kSphere)) {
      int j = i + 1;
      while (j < n && awake[j] && (traits[j] & kSphere)) ++j;
      const int c = keep_sphere_boxes(i, j, pos, vel, shapes, proxies, spec, motion, static_motion, dt, kr, declined,
                                      ang, ori, check_state, all_ok, all_unit);
      moved += (j - i) - c;
      for (int k = 0; k < c; ++k) visit(declined[k]);
      i = j - 1;
      continue;
    }
    visit(i);
  }
  flush();
  // The state check (World::step), its quick test made above on the values the boxes
  // were computed from. Anything it flags, and any sleeping island (a sleeping body
  // written to wakes), takes validate_state: a bad value throws there, with the state
  // as the user left it (only the proxies' boxes, derived from it, have moved: the
  // next step computes them anew); a woken island or a quaternion normalised there
  // changes what the boxes are computed from, and they are computed again.
  if (check_state && !(all_ok && all_unit && islands_.size() == free_islands_.size()) && validate_state())
    return update_broadphase(ccd, false);
  return moved;
}

void World::run_step(bool check_state) {
  plain_runs_.clear();
  const int n = body_count();
  const Real dt = settings_.dt;
  const Real spec = settings_.speculative_distance;
  const bool ccd = ccd_active();
  if (ccd) {  // the ccd stage sweeps bodies from here
    if (ccd_rows_dirty_) {
      ccd_rows_.clear();
      for (int i = 0; i < n; ++i)
        if (ccd_[i]) ccd_rows_.push_back(i);
      ccd_rows_dirty_ = false;
    }
    start_positions_.resize(n);
    start_orientations_.resize(n);
    for (const int i : ccd_rows_) {
      start_positions_[i] = positions_[i];
      start_orientations_[i] = orientations_[i];
    }
  }

  // ---- update_broadphase: proxies of bodies that can move. ----
  {
    StageTimer t(profile_[kUpdateBroadphase]);
    t.set_count(update_broadphase(ccd, check_state));
  }

  // ---- find_pairs ----
  {
    StageTimer t(profile_[kFindPairs]);
    broadphase_->update();
    pairs_.clear();
    broadphase_->query_pairs(pairs_);
    if (has_filters_)
      std::erase_if(pairs_, [&](const ProxyPair& pp) {
        return !collides(static_cast<int>(broadphase_->user_data(pp.first)),
                         static_cast<int>(broadphase_->user_data(pp.second)));
      });
    order_pairs_top_down();
    t.set_count(static_cast<long long>(pairs_.size()));
  }

  // ---- narrowphase: manifolds, matched to the cache by feature id. ----
  reuse_cos_half_ = std::cos(0.5 * settings_.manifold_reuse_angle);
  constraints_.clear();
  constraint_keys_.clear();
  constraint_geometry_.clear();
  constraint_entries_.clear();
  {
    StageTimer t(profile_[kNarrowphase]);
    auto rows = [&](const ProxyPair& pp) {
      int sa = static_cast<int>(broadphase_->user_data(pp.first));
      int sb = static_cast<int>(broadphase_->user_data(pp.second));
      if (sa > sb) std::swap(sa, sb);  // the pair's order is its slots' order
      return std::array<int, 4>{sa, sb, slots_[sa].index, slots_[sb].index};
    };
    // Wake sleeping islands that something moving overlaps (broadphase boxes, so a
    // pile wakes a step before contact rather than a step late), until no more wake:
    // a woken island may overlap another sleeping one.
    if (!islands_.empty()) {
      for (bool woke = true; woke;) {
        woke = false;
        for (const ProxyPair& pp : pairs_) {
          const auto [sa, sb, a, b] = rows(pp);
          if (sleep_island_[a] >= 0 && moving(b)) {
            wake_island(sleep_island_[a]);
            woke = true;
          } else if (sleep_island_[b] >= 0 && moving(a)) {
            wake_island(sleep_island_[b]);
            woke = true;
          }
        }
      }
    }
    // The pairs in contiguous parts, one per thread, each into its own buffers, then
    // joined in part order: the same constraints in the same order for any number of
    // threads. Everything read here is read-only during the stage (shapes, poses,
    // materials, the cache); collide() keeps its scratch per thread.
    const int parts = pool_ ? pool_->size() : 1;
    if (static_cast<int>(thread_out_.size()) < parts) thread_out_.resize(parts);
    auto part = [&](int t) {
      NarrowphaseOut& out = thread_out_[t];
      out.constraints.clear();
      out.keys.clear();
      out.geometry.clear();
      out.entries.clear();
      out.reused = 0;
      const auto [begin, end] = ThreadPool::part(pairs_.size(), t, parts);
      // The cache entries of the pairs ahead, prefetched in two stages (FlatMap).
      constexpr std::size_t kSlotAhead = 8, kValueAhead = 4;
      auto single_key = [&](std::size_t k) {
        const auto [sa, sb, a, b] = rows(pairs_[k]);
        return manifold_key(sa, sb, -1, -1);
      };
      for (std::size_t k = begin; k < std::min(end, begin + kSlotAhead); ++k) cache_.prefetch_slot(single_key(k));
      for (std::size_t k = begin; k < end; ++k) {
        if (k + kSlotAhead < end) cache_.prefetch_slot(single_key(k + kSlotAhead));
        if (k + kValueAhead < end) cache_.prefetch_value(single_key(k + kValueAhead));
        const auto [sa, sb, a, b] = rows(pairs_[k]);
        // At least one awake dynamic body: pairs of sleeping, static and kinematic
        // bodies need no contact.
        if (!awake_dynamic(a) && !awake_dynamic(b)) continue;
        collide_pair(sa, sb, a, b, spec + pair_motion_margin(a, b), out);
      }
    };
    if (parts > 1 && pairs_.size() >= kMinParallelPairs) {
      pool_->run(part);
    } else {
      for (int t = 0; t < parts; ++t) part(t);  // the same parts, on this thread
    }
    // Part 0's buffers are swapped in (the old ones go back to it, capacity kept), the
    // others appended: a copy of every constraint (~650 bytes each) cost 1-2 ms of the
    // pyramid's step.
    reused_manifolds_ = 0;
    for (int t = 0; t < parts; ++t) {
      NarrowphaseOut& out = thread_out_[t];
      if (t == 0) {
        constraints_.swap(out.constraints);
        constraint_keys_.swap(out.keys);
        constraint_geometry_.swap(out.geometry);
        constraint_entries_.swap(out.entries);
      } else {
        constraints_.insert(constraints_.end(), out.constraints.begin(), out.constraints.end());
        constraint_keys_.insert(constraint_keys_.end(), out.keys.begin(), out.keys.end());
        constraint_geometry_.insert(constraint_geometry_.end(), out.geometry.begin(), out.geometry.end());
        constraint_entries_.insert(constraint_entries_.end(), out.entries.begin(), out.entries.end());
      }
      reused_manifolds_ += out.reused;
    }
    t.set_count(static_cast<long long>(constraints_.size()));
  }

  // ---- solve: soft step over the substeps. ----
  long long points = 0;
  for (const ContactConstraint& c : constraints_) points += c.count;
  {
    StageTimer t(profile_[kSolve], points);
    const int substeps = settings_.substeps;
    const Real h = dt / substeps, inv_h = 1 / h;
    // One state per body, plus one past them that stays at rest with zero mass: the
    // solver's padding lanes point at it (WideContacts).
    states_.resize(n + 1);
    states_[n] = BodyState{};
    body_flags_.assign(n, 0);
    for (const ContactConstraint& c : constraints_) {
      body_flags_[c.body_a] |= kInContact;
      body_flags_[c.body_b] |= kInContact;
    }
    coupled_.clear();
    // A moving body in no contact is coupled to nothing: all its substeps are done
    // here, and the substep loops below visit only the bodies in contact.
    //
    // The common free body (dynamic, gravity only: no force, damping, centre-of-mass
    // offset or gyroscopic term) is integrated in place on the world's arrays, by runs
    // of consecutive bodies (integrate_plain_run: the loop a user would write over the
    // arrays, cut into cache-sized chunks). The others go in blocks of kFreeBlock
    // through integrate_velocity and integrate_position, substep by substep within a
    // block: one body's substeps form a chain of dependent divisions and square roots
    // (quaternion normalisation), a block's bodies are independent and overlap.
    // Same operations in the same order for each body either way.
    constexpr int kFreeBlock = 8;
    std::array<BodyState, kFreeBlock> block;
    std::array<int, kFreeBlock> block_body{};
    int block_size = 0;
    constexpr std::uint8_t kNotPlain = kHasForce | kHasDamping | kComOffset | kGyroscopic | kInContact;
    auto flush_block = [&] {
      for (int sub = 0; sub < substeps; ++sub)
        for (int j = 0; j < block_size; ++j) {
          const int i = block_body[j];
          BodyState& st = block[j];
          // A free body's centre of mass moves with the substep's mean velocity (see
          // integrate_position): exact under gravity and any other constant force.
          const Vec3 v0 = st.v;
          if (kinds_[i] == BodyKind::kDynamic) integrate_velocity(i, st, body_flags_[i], h);
          integrate_position(i, st, body_flags_[i], h, 0.5 * (v0 + st.v));
        }
      for (int j = 0; j < block_size; ++j) {
        const int i = block_body[j];
        if (kinds_[i] != BodyKind::kDynamic) continue;
        linear_velocities_[i] = block[j].v;
        angular_velocities_[i] = block[j].w;
      }
      block_size = 0;
    };
    int run_begin = 0, run_end = 0;  // the current run of plain free bodies
    const bool gyro = settings_.gyroscopic;
    // The plain bodies' test below (the same flags against kNotPlain), for a stretch of
    // them at once: byte arrays read through local pointers and one branch a body
    // (measured: 10,000 free-falling spheres, the solve stage ~10 us a step less than
    // with the loop below alone). Not while forces are pending (their test reads the
    // force arrays): the loop below then decides body by body.
    const std::uint8_t* const awake_p = awake_.data();
    const BodyKind* const kind_p = kinds_.data();
    const std::uint8_t* const trait_p = traits_.data();
    std::uint8_t* const flag_p = body_flags_.data();
    // The gyroscopic bit of the scan without a branch on the setting: the same
    // instructions whether the term is on or off, so that turning it on in a scene of
    // isotropic bodies (spheres, cubes) costs nothing (with `gyro && ...` it cost
    // ~3 us a step of 10,000 falling spheres, above the noise).
    const std::uint8_t gyro_bit = gyro ? kGyroscopic : 0;
    for (int i = 0; i < n; ++i) {
      if (!has_forces_) {
        int j = scan_plain_blocks(i, n, trait_p, awake_p, reinterpret_cast<const std::uint8_t*>(kind_p), flag_p,
                                  gyro_bit, kNotPlain, static_cast<std::uint8_t>(kIsotropic),
                                  static_cast<std::uint8_t>(BodyKind::kDynamic));
        for (; j < n; ++j) {
          const std::uint8_t tr = trait_p[j];
          const std::uint8_t anisotropic = static_cast<std::uint8_t>((tr & kIsotropic) ? 0 : 0xFF);
          const std::uint8_t f = flag_p[j] | tr | (gyro_bit & anisotropic);
          const bool plain = (awake_p[j] != 0) & (kind_p[j] == BodyKind::kDynamic) & ((f & kNotPlain) == 0);
          if (!plain) break;
          flag_p[j] = f;
        }
        if (j > i) {  // bodies i .. j - 1 are plain: as one by one below
          if (i != run_end) {
            integrate_plain_run(run_begin, run_end, h, substeps);
            run_begin = i;
          }
          run_end = j;
          if (j == n) break;
          i = j;  // not plain: decided below
        }
      }
      std::uint8_t& f = body_flags_[i];
      const bool in_contact = f & kInContact;
      if (!awake_[i] && !in_contact) continue;  // static or sleeping, and in no row
      const bool dynamic = awake_dynamic(i);
      f |= traits_[i];
      if (has_forces_ && dynamic && (!forces_[i].isZero(0) || !torques_[i].isZero(0))) f |= kHasForce;
      if (dynamic && gyro && !(f & kIsotropic)) f |= kGyroscopic;
      if (dynamic && !(f & kNotPlain)) {
        if (i != run_end) {
          integrate_plain_run(run_begin, run_end, h, substeps);
          run_begin = i;
        }
        run_end = i + 1;
        continue;
      }
      // Working state. The world inverse inertia only where something reads it:
      // contact rows and torques.
      BodyState& st = in_contact ? states_[i] : block[block_size];
      st.v = kinds_[i] == BodyKind::kStatic ? Vec3::Zero() : linear_velocities_[i];
      st.w = kinds_[i] == BodyKind::kStatic ? Vec3::Zero() : angular_velocities_[i];
      if (in_contact || (f & kHasForce)) {
        // Only contact rows read the step's motion (dp, dq) and the masses; forces
        // read the masses. A free body without forces needs none of it.
        st.dp.setZero();
        st.dq = Quat::Identity();
        st.inv_mass = dynamic ? masses_[i].inv_mass : 0;
        st.gravity = dynamic ? Vec3(gravity_scale_[i] * settings_.gravity) : Vec3::Zero();
        st.inv_inertia = dynamic ? world_inv_inertia(orientations_[i], masses_[i].inv_inertia_local) : Mat3::Zero();
      }
      if (in_contact) {
        if (awake_[i]) coupled_.push_back(i);
        continue;
      }
      block_body[block_size++] = i;
      if (block_size == kFreeBlock) flush_block();
    }
    integrate_plain_run(run_begin, run_end, h, substeps);
    flush_block();
    const ContactSoftness soft = contact_softness(settings_.solver, h);
    const bool contacts = !constraints_.empty();
    if (contacts && settings_.solver.max_sag > 0) estimate_loads();
    // The passes: on WideContacts' lane groups, or with block_solver on the scalar
    // passes (double precision, the constraints in their top-down order), each
    // manifold's normal rows solved together (WorldSettings::block_solver).
    const bool scalar = settings_.block_solver;
    if (contacts && scalar) {
      ContactSoftness same_soft;  // prepare_contacts' copy of `soft`
      prepare_contacts(constraints_, states_, settings_.solver, h, same_soft);
    } else if (contacts) {
      // The passes run on lane groups, in an order equivalent to the constraints'
      // sequence (pairs top down) that keeps the groups full, in regions on a large
      // pile (solve_order).
      solve_order();
      wide_.set_team(pool_.get());
      wide_.build(constraints_, solve_order_, states_, n, soft, settings_.solver.max_sag, h,
                  settings_.centroid_rows, solve_starts_);
    }
    const Real push_max = settings_.solver.push_max;
    auto pass = [&](bool use_bias, bool reverse) {
      if (scalar)
        solve_contacts(constraints_, states_, soft, inv_h, push_max, use_bias, NormalRows::kBlock, reverse,
                       settings_.centroid_rows);
      else
        wide_.solve(states_, soft, inv_h, push_max, use_bias, reverse, settings_.centroid_rows);
    };
    const bool shock = contacts && ccd_active() && build_shock_order() > 0;
    // The energy guard (WorldSettings::energy_guard_passes): the kinetic energy of
    // the bodies in contact in the solver's metric (mass, and the world inertia at the
    // step's start, which the rows use).
    const bool guard = contacts && settings_.energy_guard_passes > 0;
    const Real guard_tol = settings_.energy_guard_tolerance;
    if (guard) {
      guard_bodies_.resize(coupled_.size());
      for (std::size_t k = 0; k < coupled_.size(); ++k) {
        const int i = coupled_[k];
        GuardBody& gb = guard_bodies_[k];
        gb.row = i;
        if (kinds_[i] != BodyKind::kDynamic) {
          gb.mass = 0;
          gb.inertia.setZero();
          continue;
        }
        const Mat3 r = orientations_[i].toRotationMatrix();
        gb.mass = masses_[i].mass;
        gb.inertia = r * masses_[i].inertia_local * r.transpose();
      }
    }
    // Twice the energy (the comparisons need no factor 1/2).
    auto coupled_energy = [&] {
      Real e = 0;
      for (const GuardBody& gb : guard_bodies_) {
        const BodyState& st = states_[gb.row];
        e += gb.mass * st.v.squaredNorm() + st.w.dot(gb.inertia * st.w);
      }
      return e;
    };
    guard_passes_ = 0;
    for (int sub = 0; sub < substeps; ++sub) {
      integrate_velocities(h);
      const Real e_free = guard ? coupled_energy() : 0;
      if (contacts) {
        if (scalar) warm_start_contacts(constraints_, states_);
        else wide_.warm_start(states_);
        for (int it = 0; it < settings_.iterations; ++it) pass(true, false);
      }
      integrate_positions(h);
      if (guard && !inertia_turned_.empty()) {
        // The guard's metric follows the inertia the rows now use (integrate_positions).
        for (GuardBody& gb : guard_bodies_) {
          if (gb.mass == 0 || !inertia_follows_turn(gb.row)) continue;
          const Mat3 r = orientations_[gb.row].toRotationMatrix();
          gb.inertia = r * masses_[gb.row].inertia_local * r.transpose();
        }
      }
      if (contacts) {
        // The relax passes and the next substep see the new motion (the scalar passes
        // turn the anchors row by row).
        if (!scalar) {
          wide_.refresh_inertia(states_, inertia_turned_);
          wide_.set_motion(states_);
        }
        for (int it = 0; it < settings_.relax_iterations; ++it) pass(false, it % 2 == 1);  // alternating: WorldSettings::relax_iterations
        if (guard) {
          // Until the energy is back (to the tolerance), the cap, or a pass that takes
          // nothing out: then what is left is not the passes' to remove (the anchors
          // turned between the biased passes and these, see energy_guard_passes).
          // The passes go in forward-backward pairs, as the relax passes do
          // (symmetric Gauss-Seidel: no bias towards the rows visited last).
          Real e = coupled_energy();
          for (int extra = 0; extra + 2 <= settings_.energy_guard_passes && e > e_free * (1 + guard_tol);
               extra += 2) {
            pass(false, false);
            pass(false, true);
            guard_passes_ += 2;
            const Real e_next = coupled_energy();
            if (!(e_next < e)) break;
            e = e_next;
          }
        }
        if (shock) shock_pass(inv_h);
      }
    }
    if (contacts && !scalar) wide_.unpack(constraints_);
  }

  // ---- restitution ----
  {
    long long bouncing = 0;
    for (const ContactConstraint& c : constraints_) bouncing += c.restitution > 0;
    StageTimer t(profile_[kRestitution], bouncing);
    if (bouncing > 0) apply_restitution(constraints_, states_, settings_.solver.restitution_threshold);
  }

  // ---- store_impulses: velocities back to the arrays, impulses to the cache. ----
  {
    StageTimer t(profile_[kStoreImpulses], points);
    for (const int i : coupled_) {  // free bodies stored theirs in the solve stage
      if (kinds_[i] != BodyKind::kDynamic) continue;
      linear_velocities_[i] = states_[i].v;
      angular_velocities_[i] = states_[i].w;
    }
    // Entries are updated in place and the ones no constraint refreshed are dropped
    // after: clearing and reinserting every entry cost an allocation and a free per
    // manifold per step (measured: 9 ms of the pyramid's step).
    const std::uint64_t stamp = step_count_ + 1;
    std::size_t fresh = 0;  // distinct entries this step stamps
    for (std::size_t k = 0; k < constraints_.size(); ++k) {
      const ContactConstraint& c = constraints_[k];
      // The entry collide_pair found, or a new one.
      const int entry = constraint_entries_[k] >= 0 ? constraint_entries_[k] : cache_.insert(constraint_keys_[k]);
      CachedManifold& cm = cache_.value(entry);
      fresh += cm.stamp != stamp;
      cm.stamp = stamp;
      cm.count = c.count;
      if (!constraint_geometry_[k].keep_cached) cm.geometry = constraint_geometry_[k];
      for (int j = 0; j < c.count; ++j)
        cm.points[j] = CachedPoint{c.points[j].feature_id, c.points[j].normal_impulse,
                                   c.points[j].tangent_impulse[0] * c.tangent1 +
                                       c.points[j].tangent_impulse[1] * c.tangent2};
    }
    // Stale entries (pairs that stopped touching) dropped; none when every entry was
    // stamped or kept for a sleeping body at the last walk (and no island woke since),
    // the usual case for a resting pile, which then skips the walk. A pair with a
    // sleeping body is not collided while it sleeps, and keeps its entry: on waking,
    // its contacts warm start, and a mesh's triangles keep the side they were touched
    // from (touched_before). Dropped, a two-sided mesh's history was lost in every
    // sleep: a 1.8 kg hull resting half through a two-sided ground woke with no
    // history, one triangle took the far side and pushed it out below (fuzz scene).
    if (cache_.size() != fresh + cache_kept_asleep_ || cache_woke_) {
      std::size_t kept = 0;
      cache_.erase_if([&](const ManifoldKey& key, const CachedManifold& cm) {
        if (cm.stamp == stamp) return false;
        const int a = slots_[static_cast<std::size_t>(key.pair >> 32)].index;
        const int b = slots_[static_cast<std::size_t>(key.pair & 0xFFFFFFFFu)].index;
        const bool asleep = sleep_island_[a] >= 0 || sleep_island_[b] >= 0;
        kept += asleep;
        return !asleep;
      });
      cache_kept_asleep_ = kept;
      cache_woke_ = false;
    }
  }
  // ---- ccd ----
  {
    StageTimer t(profile_[kCcd]);
    ccd_hits_ = 0;
    ccd_projections_ = 0;
    if (ccd) {
      const int swept = continuous_step();
      ccd_projections_ = project_ccd_overlaps();
      t.set_count(swept);
    }
  }
  // Forces and torques act for one step (the ccd stage reads them to bound how far the
  // bodies it does not sweep may have moved).
  if (has_forces_) {
    for (int i = 0; i < n; ++i)
      if (body_flags_[i] & kHasForce) {
        forces_[i].setZero();
        torques_[i].setZero();
      }
    has_forces_ = false;
  }
  // ---- update_sleep ----
  {
    StageTimer t(profile_[kUpdateSleep]);
    if (settings_.enable_sleep) {
      t.set_count(update_sleep());
    }
  }
  ++step_count_;
}

// ---- Continuous collision detection (WorldSettings::enable_ccd) -----------------

// The shock pass (Guendelman, Bridson and Fedkiw 2003, "Nonconvex rigid bodies with
// stacking", shock propagation; here for velocities only, and only for CCD bodies).
// A column of bodies falling onto something stops from the bottom: the lowest contact
// stops the lowest body, and the Gauss-Seidel passes carry that to the body above it
// only a contact per pass, so the rest of the column drives on into it (boxes3000 with
// CCD on every box: two boxes falling together at 21 m/s, the lower one stopped by the
// pile, the upper one 0.72 m deep in it two steps later). The solver leaves such pairs
// to itself (continuous_step does not sweep pairs in contact), so the CCD bodies get
// this pass after each substep's relax passes: contacts in order of their supporting
// body's depth of support (graph distance from a static or kinematic body), each
// point's approach taken out of the supported body alone, as if the supporting one
// were fixed: its velocity along the normal becomes min(supporter's, 0) less what the
// speculative gap allows, where it approaches faster than that by more than the
// restitution threshold (an impact; slower approaches are the solver's). Only CCD
// bodies faster than that threshold at the step's start take part (build_shock_order).
// The supported body only slows along the normal (its new normal speed lies between
// its old one and 0), so its kinetic energy never grows, and the supporting body is
// untouched: the pass never adds energy.
// The weight each contact carries, for the load stiffening of its rows
// (SolverSettings::max_sag). A contact whose normal (A to B) is within 60 degrees of
// up (against gravity) supports B on A, one within 60 degrees of down A on B, if the
// supported body is dynamic and its centre of mass is the higher of the two along up
// (so the support relation has no cycles); side contacts carry nothing. A body's
// weight, with everything it carries, is shared among its supports in proportion to
// the cosine of each one's normal with up, and handed down: bodies are visited from
// the highest down, so a body has received all its load before it passes it on. A
// stack of N boxes then loads its k-th contact from the top with k boxes' weight, a
// pyramid's lower rows with the rows above split between their two supports. Static
// and kinematic bodies take what they are given. Costs a sort of the supported bodies
// by height and two passes over the contacts; only when max_sag > 0.
void World::estimate_loads() {
  const int n = body_count();
  const int m = static_cast<int>(constraints_.size());
  for (ContactConstraint& c : constraints_) c.load = 0;
  const Real g = settings_.gravity.norm();
  if (!(g > 0)) return;
  const Vec3 up = -settings_.gravity / g;
  // Per contact: the supported body (or -1) and its share weight (the cosine).
  load_upper_.assign(m, -1);
  load_cos_.assign(m, 0);
  load_total_cos_.assign(n, 0);
  load_carried_.assign(n, 0);
  load_bodies_.clear();
  for (int k = 0; k < m; ++k) {
    const ContactConstraint& c = constraints_[k];
    const Real cosine = c.normal.dot(up);
    int upper = -1, lower = -1;
    if (cosine >= Real(0.5)) {
      upper = c.body_b;
      lower = c.body_a;
    } else if (cosine <= Real(-0.5)) {
      upper = c.body_a;
      lower = c.body_b;
    } else {
      continue;
    }
    if (kinds_[upper] != BodyKind::kDynamic) continue;
    if (kinds_[lower] == BodyKind::kDynamic && !(positions_[upper].dot(up) > positions_[lower].dot(up))) continue;
    load_upper_[k] = upper;
    load_cos_[k] = std::abs(cosine);
    if (load_total_cos_[upper] == 0) load_bodies_.push_back(upper);
    load_total_cos_[upper] += std::abs(cosine);
  }
  if (load_bodies_.empty()) return;
  // The contacts by supported body (CSR), and the supported bodies from the top down
  // (ties by index: deterministic).
  build_rows(n, load_start_, load_contacts_, load_fill_, [&](auto&& add) {
    for (int k = 0; k < m; ++k)
      if (load_upper_[k] >= 0) add(load_upper_[k], k);
  });
  std::sort(load_bodies_.begin(), load_bodies_.end(), [&](int x, int y) {
    const Real hx = positions_[x].dot(up), hy = positions_[y].dot(up);
    return hx > hy || (hx == hy && x < y);
  });
  for (const int u : load_bodies_) {
    const Real weight = (masses_[u].inv_mass > 0 ? gravity_scale_[u] / masses_[u].inv_mass : 0) * g +
                        load_carried_[u];
    if (!(weight > 0)) continue;
    for (int j = load_start_[u]; j < load_start_[u + 1]; ++j) {
      const int k = load_contacts_[j];
      ContactConstraint& c = constraints_[k];
      const Real share = weight * load_cos_[k] / load_total_cos_[u];
      c.load = share;
      const int lower = c.body_a == u ? c.body_b : c.body_a;
      if (kinds_[lower] == BodyKind::kDynamic) load_carried_[lower] += share;
    }
  }
}

int World::build_shock_order() {
  const int n = body_count();
  const int m = static_cast<int>(constraints_.size());
  shock_order_.clear();
  // Only bodies that can hit something fast take part: a CCD body moving faster than
  // the restitution threshold at the step's start. A scene at rest (the pyramid with
  // CCD on every box) pays one look at each contact.
  const Real threshold = settings_.solver.restitution_threshold;
  auto fast = [&](int i) {
    return ccd_[i] && awake_dynamic(i) && states_[i].v.squaredNorm() > threshold * threshold;
  };
  bool any = false;
  for (const ContactConstraint& c : constraints_)
    if (fast(c.body_a) || fast(c.body_b)) {
      any = true;
      break;
    }
  if (!any) return 0;
  // Adjacency of the contact graph (CSR).
  build_rows(n, shock_adjacency_start_, shock_adjacency_, shock_fill_, [&](auto&& add) {
    for (const ContactConstraint& c : constraints_) {
      add(c.body_a, c.body_b);
      add(c.body_b, c.body_a);
    }
  });
  // Depth of support: 0 for static and kinematic bodies, else 1 + the least depth
  // among the bodies it touches (breadth first, in index order: deterministic).
  constexpr int kUnsupported = std::numeric_limits<int>::max();
  support_depth_.assign(n, kUnsupported);
  shock_queue_.clear();
  for (int i = 0; i < n; ++i)
    if (kinds_[i] != BodyKind::kDynamic && shock_adjacency_start_[i + 1] > shock_adjacency_start_[i]) {
      support_depth_[i] = 0;
      shock_queue_.push_back(i);
    }
  for (std::size_t head = 0; head < shock_queue_.size(); ++head) {
    const int i = shock_queue_[head];
    for (int k = shock_adjacency_start_[i]; k < shock_adjacency_start_[i + 1]; ++k) {
      const int j = shock_adjacency_[k];
      if (support_depth_[j] != kUnsupported || kinds_[j] != BodyKind::kDynamic) continue;
      support_depth_[j] = support_depth_[i] + 1;
      shock_queue_.push_back(j);
    }
  }
  const Real gravity_length = settings_.gravity.norm();
  for (int k = 0; k < m; ++k) {
    const ContactConstraint& c = constraints_[k];
    const int da = support_depth_[c.body_a], db = support_depth_[c.body_b];
    bool a_lower;
    if (da != db) {
      a_lower = da < db;
    } else {
      // The same depth (both on one supporter, or both unsupported): a contact whose
      // normal is within 60 degrees of the vertical is a support, the lower body the
      // one gravity presses the other onto; others are side by side.
      if (da == kUnsupported || !(gravity_length > 0)) continue;
      const Real up = -c.normal.dot(settings_.gravity) / gravity_length;  // n from A to B
      if (std::abs(up) < Real(0.5)) continue;
      a_lower = up > 0;
    }
    const int upper = a_lower ? c.body_b : c.body_a;
    if (!fast(upper)) continue;
    shock_order_.push_back({k, a_lower ? c.body_a : c.body_b, upper});
  }
  std::sort(shock_order_.begin(), shock_order_.end(), [&](const auto& x, const auto& y) {
    const int dx = support_depth_[x[1]], dy = support_depth_[y[1]];
    return dx < dy || (dx == dy && x[0] < y[0]);
  });
  return static_cast<int>(shock_order_.size());
}

void World::shock_pass(Real inv_h) {
  const Real threshold = settings_.solver.restitution_threshold;
  for (const auto& [k, lower, upper] : shock_order_) {
    const ContactConstraint& c = constraints_[k];
    const bool a_lower = lower == c.body_a;
    // Normal from the supporting body to the supported one.
    const Vec3 n = a_lower ? c.normal : Vec3(-c.normal);
    const BodyState& sl = states_[lower];
    BodyState& su = states_[upper];
    const BodyState& sa = states_[c.body_a];
    const BodyState& sb = states_[c.body_b];
    for (int pass = 0; pass < 2; ++pass) {  // twice over the points: they share a body
      for (int j = 0; j < c.count; ++j) {
        const ContactConstraintPoint& cp = c.points[j];
        // At the step's anchors, not the turned ones (current_anchors): the pass only
        // needs the approach to an impact, and the turned anchors cost a rotation per point.
        const Vec3& rl = a_lower ? cp.ra : cp.rb;
        const Vec3& ru = a_lower ? cp.rb : cp.ra;
        const Real gap = separation_now(sa, sb, cp, c.normal, cp.ra, cp.rb);  // >= 0 when apart
        const Real lower_speed = n.dot(sl.v + sl.w.cross(rl));
        const Real upper_speed = n.dot(su.v + su.w.cross(ru));
        const Real target = std::min(lower_speed, Real(0)) - std::max(gap, Real(0)) * inv_h;
        // Impacts only: an approach slower than the restitution threshold is the
        // solver's, which settles it (it closes at most threshold * h in a substep).
        if (!(upper_speed < target - threshold)) continue;
        const Vec3 rn = ru.cross(n);
        const Vec3 iw = su.inv_inertia * rn;
        const Real k_inv = su.inv_mass + rn.dot(iw);
        if (!(k_inv > 0)) continue;
        const Real impulse = (target - upper_speed) / k_inv;
        su.v += (impulse * su.inv_mass) * n;
        su.w += impulse * iw;
      }
    }
  }
}

namespace {
/// Key of an unordered pair of dense rows.
std::uint64_t row_pair_key(int a, int b) {
  if (a > b) std::swap(a, b);
  return (static_cast<std::uint64_t>(a) << 32) | static_cast<std::uint32_t>(b);
}

/// Rotation vector (unit axis times angle, rad) of the shortest rotation taking q0 to q1.
Vec3 rotation_vector(const Quat& q0, const Quat& q1) {
  Quat d = q1 * q0.conjugate();
  if (d.w() < 0) d.coeffs() = -d.coeffs();
  const Real s = d.vec().norm();
  if (s == 0) return Vec3::Zero();
  return d.vec() * (2 * std::atan2(s, d.w()) / s);
}
}  // namespace

// The collision of a and b at a world point with normal n (from a to b): an impulse
// there that stops their approach along n, with the pair's restitution above the
// threshold when `bounce` is set, as the contact solver would (momentum kept, energy
// only lost). Awake dynamic bodies take it; a kinematic body's velocity counts but it
// takes none; a static or sleeping body neither moves nor takes any.
void World::stop_approach(int a, int b, const Vec3& point, const Vec3& normal, bool bounce) {
  const bool move_a = awake_dynamic(a), move_b = awake_dynamic(b);
  auto velocity_at = [&](int i, bool moves, const Vec3& r) {
    return moves || kinds_[i] == BodyKind::kKinematic ? Vec3(linear_velocities_[i] + angular_velocities_[i].cross(r))
                                                        : Vec3(Vec3::Zero());
  };
  const Vec3 ra = point - world_com(a), rb = point - world_com(b);
  const Real vn = normal.dot(velocity_at(b, move_b, rb) - velocity_at(a, move_a, ra));  // < 0: approaching
  if (!(vn < 0)) return;
  Real k = 0;
  Mat3 ia = Mat3::Zero(), ib = Mat3::Zero();
  const Vec3 rna = ra.cross(normal), rnb = rb.cross(normal);
  if (move_a) {
    ia = world_inv_inertia(orientations_[a], masses_[a].inv_inertia_local);
    k += masses_[a].inv_mass + rna.dot(ia * rna);
  }
  if (move_b) {
    ib = world_inv_inertia(orientations_[b], masses_[b].inv_inertia_local);
    k += masses_[b].inv_mass + rnb.dot(ib * rnb);
  }
  if (!(k > 0)) return;
  const Real e = bounce && -vn > settings_.solver.restitution_threshold
                     ? combine(settings_.restitution_combine, restitutions_[a], restitutions_[b])
                     : Real(0);
  const Real lambda = -(1 + e) * vn / k;  // along n on b, against it on a
  if (move_a) {
    linear_velocities_[a] -= masses_[a].inv_mass * lambda * normal;
    angular_velocities_[a] -= ia * rna * lambda;
  }
  if (move_b) {
    linear_velocities_[b] += masses_[b].inv_mass * lambda * normal;
    angular_velocities_[b] += ib * rnb * lambda;
  }
}

// The potential energy a dynamic body gains when the ccd stage moves it by `d` (m)
// against gravity, taken out of its linear kinetic energy (all of it, if that is less),
// so that the stage never adds energy.
void World::take_potential_gain(int i, const Vec3& d) {
  const Real mass = masses_[i].mass;
  const Real gained = -mass * (gravity_scale_[i] * settings_.gravity).dot(d);
  if (gained > 0) {
    const Real ke = 0.5 * mass * linear_velocities_[i].squaredNorm();
    linear_velocities_[i] *= ke > gained ? std::sqrt(1 - gained / ke) : Real(0);
  }
}

Real World::ccd_allowance(int i) const {
  return std::max(settings_.ccd_penetration * inner_radius_[i], Real(1e-7));
}

// The ccd stage's last part: overlaps the solve left deeper than a CCD body's
// allowance, pushed apart. The contact rows see each pair through the points of its
// manifold at the step's start, moved with the bodies; a corner that swings in within
// the step is not among them. In boxes3000 with CCD on every box, of the overlaps that
// grew past 0.1 m in one step, nearly all belonged to a pair whose rows reported at
// most a centimetre while the two boxes overlapped by 0.3-0.4 m, one of them turning
// at 5-13 rad/s (the deepest, 0.41 m: a box knocked spinning by the pile swung into
// the box falling on it); the rest were columns decelerating on soft contacts. The
// time-of-impact sweeps leave these pairs to the solver (putting one body of a pile
// back makes new overlaps), so they are measured here instead: every contact of an
// awake CCD body whose overlap at the step's start plus the relative motion of the two
// bodies' points over the step (centres, and turn times bounding radius) can exceed
// the pair's allowance is collided again at the end poses. An overlap deeper than the
// allowance that grew by more than a quarter of it within the step is pushed back to
// half the allowance, or to the overlap at the start if that was deeper (a resting
// contact's steady sag is the solver's: a 1 mm plate's allowance is 25 um, less than
// its contact's sag): along the normal, translation only, the two bodies sharing the
// push by inverse mass; the approach is stopped by an impulse at the manifold's
// centroid (no bounce: energy is only lost); a push against gravity takes the potential
// energy it gains out of the body's kinetic energy, as a body put back at a time of
// impact does. A steady overlap deeper than kFastCap allowances of a pair with a moving
// body (faster than sleep_linear_threshold) is pushed back to that depth too: columns of
// boxes decelerating on their soft contacts sat 0.13-0.16 m deep, growing by less than a
// quarter of the allowance per step. A push may deepen a neighbour's overlap, so the
// contacts of the bodies a round pushed are checked again, for at most kRounds rounds.
// Measured (benchmarks/ccd/penetration.py --ccd all, and five more runs with positions
// perturbed by 1e-7 m: the scene is chaotic): boxes3000's deepest overlap at a step's
// end 0.39-0.52 m -> 0.076-0.092 m. Holding the lower body of a pair (by
// support depth, or by height for near-vertical normals) so that a column is pushed
// out bottom-up was tried: the upper bodies were pushed into their neighbours (0.58-
// 0.74 m). A scene whose CCD bodies rest costs one look at each contact.
int World::project_ccd_overlaps() {
  const int n = body_count();
  // How deep (in allowances) a moving pair's overlap may rest, and how many rounds of
  // pushes: boxes3000 with CCD on every box, four runs, deepest 0.14-0.20 m without
  // the cap at 4 rounds, 0.11-0.15 m with it at 4, 0.09-0.12 m at 16 (the cap for
  // pairs faster than the restitution threshold, impulses at the deepest point), 0.076-
  // 0.091 m at 64 (the cap for pairs faster than the sleep threshold, impulses at the
  // manifold's centroid; 0.085 and 0.092 m in two runs more). Columns need the rounds:
  // a push hands half its depth to the next pair, so a column of n boxes settles over
  // ~n rounds, each round's work only the contacts of the bodies the last one pushed (the ccd stage over 600 steps, one
  // run each, with a variant of the cap that also pushed slow pairs deeper than 1 cm:
  // 1.31 ms a step at 16 rounds, 1.32 at 64, 1.74 at 1000; with this rule at 64, 1.35
  // ms, benchmarks/ccd/run.py).
  constexpr Real kFastCap = 1.5;
  // A pair within this many allowances of its target is not pushed: once pushed to
  // the cap, a pair's fresh depth is the cap to round-off, and was pushed by 1e-19 m
  // again in every round to the round cap (a thin hull resting on a mesh ground under
  // a box: 64 collisions a step for nothing).
  constexpr Real kMinPush = 0.01;
  // How far each body's points moved over the step: its centre of mass, and its turn
  // times its bounding radius (states_: bodies in contact have their step's motion).
  // The angle, 2 asin(|vec(dq)|) for dq with w >= 0, is bounded without trigonometry:
  // asin(x) <= 1.0472 x for x <= 0.5 (asin(0.5) = pi / 6), and <= (pi / 2) x always.
  auto angle_of = [](const Quat& dq) {
    const Real x = std::min(dq.vec().norm(), Real(1));
    return x <= Real(0.5) ? Real(2.0944) * x : kPi * x;
  };
  // The deepest overlap of a contact's points at the step's start (m).
  auto start_depth = [](const ContactConstraint& c) {
    Real depth = -kInf;
    for (int k = 0; k < c.count; ++k) {
      const ContactConstraintPoint& p = c.points[k];
      depth = std::max(depth, -(p.adjusted_separation + c.normal.dot(p.rb - p.ra)));
    }
    return depth;
  };
  const Real rest_v2 = settings_.sleep_linear_threshold * settings_.sleep_linear_threshold;
  // (a static body has no velocity; a kinematic one pressing a pair moves it)
  auto moving = [&](int i) { return linear_velocities_[i].squaredNorm() > rest_v2; };
  auto allowance_of = [&](int a, int b) {
    return std::min(ccd_[a] && awake_dynamic(a) ? ccd_allowance(a) : kInf,
                    ccd_[b] && awake_dynamic(b) ? ccd_allowance(b) : kInf);
  };
  // The contacts (indices into constraints_) to check: an overlap at the end is at most
  // the one at the start plus how far the two bodies' points moved relative to each
  // other, and the projection acts only on one that deepened by more than a quarter of
  // the allowance, or one deeper than kFastCap allowances (if a body of the pair moves,
  // checked on the collided depth below), so a resting contact's steady sag (a thin
  // body's allowance may be smaller than it) is left to the solver.
  std::vector<int>& pairs = ccd_overlap_pairs_;
  pairs.clear();
  const int m = static_cast<int>(constraints_.size());
  for (int ci = 0; ci < m; ++ci) {
    const ContactConstraint& c = constraints_[ci];
    const int a = c.body_a, b = c.body_b;
    if (!(ccd_[a] && awake_dynamic(a)) && !(ccd_[b] && awake_dynamic(b))) continue;
    const BodyState& sa = states_[a];
    const BodyState& sb = states_[b];
    const Real motion = (sa.dp - sb.dp).norm() + angle_of(sa.dq) * outer_radius_[a] + angle_of(sb.dq) * outer_radius_[b];
    const Real allowance = allowance_of(a, b);
    const Real reach = start_depth(c) + motion;
    if (reach > allowance && (motion > 0.25 * allowance || reach > kFastCap * allowance)) pairs.push_back(ci);
  }
  if (pairs.empty()) return 0;
  // The contacts of each body (CSR over the step's constraints).
  std::vector<int>& start = ccd_pair_start_;
  std::vector<int>& adjacent = ccd_adjacent_pairs_;
  build_rows(n, start, adjacent, ccd_pair_fill_, [&](auto&& add) {
    for (int ci = 0; ci < m; ++ci) {
      add(constraints_[ci].body_a, ci);
      add(constraints_[ci].body_b, ci);
    }
  });
  ccd_pushed_.resize(n, Vec3::Zero());
  for (const int i : ccd_pushed_rows_) ccd_pushed_[i].setZero();
  ccd_pushed_rows_.clear();
  std::vector<int>& pushed_now = ccd_pushed_now_;
  // A body is pinned against a push that would take it into static geometry it
  // touches: one of its static contacts (the step's normal, out of the static body)
  // that the push goes against by more than the contact's gap at the step's start.
  // A pair of two non-static bodies never pushes a pinned body: the other takes the
  // whole push (shock propagation), or, if it is pinned or cannot move too, the pair
  // is left to the solver, as any body crushed against the world. Pushed anyway, the
  // pinned body went through: a 14 g hull 0.2 mm thick on a one-sided mesh ground,
  // under a kinematic box moving down into it, was pushed 4 cm down in one push,
  // wholly behind the ground, which then no longer saw it (random-scene fuzz; the
  // ploughed plate of tests/python/test_ccd.py). Pushed along its contact only (the
  // part into the ground removed), the light box under a heavy one of test_ccd.py slid
  // sideways push by push until the heavy one fell off; left to the solver every time
  // (no shock propagation), boxes3000 with CCD on every box reached 0.53 m deep
  // instead of 0.086 m.
  // A push within 1% of parallel to a static contact (0.6 degrees) does not count as
  // going into it: two bodies resting side by side on the ground, pushed apart along
  // a normal that round-off tilts a hair into it, share the push as before.
  constexpr Real kPinSlope = 0.01;
  auto pinned = [&](int i, const Vec3& d) {
    const Real least = kPinSlope * d.norm();
    for (int k = start[i]; k < start[i + 1]; ++k) {
      const ContactConstraint& c = constraints_[adjacent[k]];
      const bool a_static = kinds_[c.body_a] == BodyKind::kStatic;
      if (!a_static && kinds_[c.body_b] != BodyKind::kStatic) continue;
      const Real into = a_static ? -d.dot(c.normal) : d.dot(c.normal);
      if (into > least && into > -start_depth(c)) return true;
    }
    return false;
  };
  auto push = [&](int i, const Vec3& d) {
    if (ccd_pushed_[i].isZero(0)) ccd_pushed_rows_.push_back(i);
    ccd_pushed_[i] += d;
    positions_[i] += d;
    pushed_now.push_back(i);
  };
  int pushes = 0;
  constexpr int kRounds = 64;
  // A round takes the pairs of two movable bodies first, then those with a kinematic
  // or sleeping body, and the pairs with static geometry last, so that every round,
  // the last one too, ends with the static contacts pushed out. In index order, a
  // light body squeezed between the ground and a heavy one went back and forth
  // between them, the heavy one moving by the mass ratio a round (6,000 rounds to
  // settle at 6,000:1), and the round cap could stop after the heavy one's push: a
  // 0.32 kg cylinder under a 1.9 t body ended a step 16 cm into a one-sided ground,
  // then behind it (random-scene fuzz, seed 74 of tests/python/test_fuzz_worlds.py).
  auto rank = [&](int ci) {
    const ContactConstraint& c = constraints_[ci];
    const BodyKind ka = kinds_[c.body_a], kb = kinds_[c.body_b];
    if (ka == BodyKind::kStatic || kb == BodyKind::kStatic) return 2;
    return awake_dynamic(c.body_a) && awake_dynamic(c.body_b) ? 0 : 1;
  };
  for (int round = 0; round < kRounds && !pairs.empty(); ++round) {
    std::sort(pairs.begin(), pairs.end());
    pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
    std::stable_sort(pairs.begin(), pairs.end(), [&](int x, int y) { return rank(x) < rank(y); });
    pushed_now.clear();
    for (const int ci : pairs) {
      const ContactConstraint& c = constraints_[ci];
      const int a = c.body_a, b = c.body_b;
      const bool move_a = awake_dynamic(a), move_b = awake_dynamic(b);
      const Real wa = move_a ? masses_[a].inv_mass : 0, wb = move_b ? masses_[b].inv_mass : 0;
      if (!(wa + wb > 0)) continue;
      ccd_manifolds_.clear();
      collide(*shapes_[a], Pose(positions_[a], orientations_[a]), *shapes_[b], Pose(positions_[b], orientations_[b]),
              ccd_manifolds_);
      // The deepest point on this contact's side: manifolds whose normal opposes the
      // step's (c.normal) are another triangle of a two-sided mesh seen from its back,
      // or a convex pair already more than half way through. Pushed along those, a
      // body goes through the surface: a random-scene fuzz (scripts/fuzz_worlds.py)
      // had a 24 kg compound resting on a two-sided mesh ground whose fresh
      // collision, after the solve, found one triangle from below 0.36 m deep: the
      // push took the body 0.35 m down in one step, the ground then pushed it out
      // below. Such a triangle is pushed by its own contact, if the step had one.
      const Manifold* deepest = nullptr;
      int point = -1;
      for (const Manifold& m : ccd_manifolds_) {
        if (!(m.normal.dot(c.normal) > 0)) continue;
        for (int k = 0; k < m.count; ++k)
          if (!deepest || m.points[k].depth > deepest->points[point].depth) {
            deepest = &m;
            point = k;
          }
      }
      if (!deepest) continue;
      const Real allowance = allowance_of(a, b);
      const ContactPoint& cp = deepest->points[point];
      if (!(cp.depth > allowance)) continue;
      // An overlap the step deepened by more than a quarter of the allowance goes back
      // to half of it, or to its depth at the start, at most kFastCap allowances. One
      // that rests at its depth (a soft contact's steady sag) is the solver's, unless
      // it is deeper than kFastCap allowances while a body of the pair moves (a column
      // decelerating on its soft contacts, whose overlaps grow by a little every
      // step; the bottom of a pile crushed by what lands on it at 0.2-0.9 m/s): it
      // goes back to that depth. "Moves" is faster than sleep_linear_threshold, the
      // world's measure of rest: pushing a resting pair every step fights the solver
      // (a 1:100 heavy box on a light one slid off it when its 2 cm sag, four
      // allowances of the light box, was pushed out; tests/python/test_ccd.py).
      const Real before = start_depth(c);
      const Real cap = kFastCap * allowance;
      const bool deepened = cp.depth > before + 0.25 * allowance;
      if (!deepened && !(cp.depth > cap && (moving(a) || moving(b)))) continue;
      const Real target = deepened ? std::max(Real(0.5) * allowance, std::min(before, cap)) : cap;
      const Real excess = cp.depth - target;
      if (!(excess > kMinPush * allowance)) continue;
      const Real share_a = wa / (wa + wb), share_b = wb / (wa + wb);
      Vec3 da = -share_a * excess * deepest->normal, db = share_b * excess * deepest->normal;
      const bool pinned_a = share_a > 0 && pinned(a, da), pinned_b = share_b > 0 && pinned(b, db);
      if (rank(ci) != 2 && (pinned_a || pinned_b)) {
        // One body pinned: the other takes the whole push, but only back to the
        // pair's depth at the step's start (a pinned light box pushed up out of the
        // ground must not lift the heavy one resting on it off its contact's sag).
        if (pinned_a == pinned_b) continue;
        const Real rest = cp.depth - std::max(target, before);
        if (!(rest > 0)) continue;
        if (pinned_a) {
          if (!move_b) continue;
          da.setZero();
          db = rest * deepest->normal;
          if (pinned(b, db)) continue;
        } else {
          if (!move_a) continue;
          db.setZero();
          da = -rest * deepest->normal;
          if (pinned(a, da)) continue;
        }
      }
      // The approach stopped, as the solver's relax rows would (no bounce), at the
      // centroid of the manifold's overlapping points: an impulse at one corner of a
      // face contact turns the bodies (the heavy box above then slid off too).
      Vec3 at = Vec3::Zero();
      int overlapping = 0;
      for (int k = 0; k < deepest->count; ++k) {
        const ContactPoint& q = deepest->points[k];
        if (!(q.depth > 0)) continue;
        at += 0.5 * (q.point_a + q.point_b);
        ++overlapping;
      }
      stop_approach(a, b, at / overlapping, deepest->normal, false);
      if (!da.isZero(0)) push(a, da);
      if (!db.isZero(0)) push(b, db);
      ++pushes;
    }
    pairs.clear();
    for (const int i : pushed_now) pairs.insert(pairs.end(), adjacent.begin() + start[i], adjacent.begin() + start[i + 1]);
  }
  // A body's pushes may cancel to zero and start again: each row once.
  std::sort(ccd_pushed_rows_.begin(), ccd_pushed_rows_.end());
  ccd_pushed_rows_.erase(std::unique(ccd_pushed_rows_.begin(), ccd_pushed_rows_.end()), ccd_pushed_rows_.end());
  // A body pushed farther than it may move without being swept (the CCD threshold,
  // ccd_motion_threshold of its inner radius) is swept along its push against static
  // geometry and stopped where it would reach it (as continuous_step stops a fast
  // body): the rounds look only at the step's contacts, and a push could carry a body
  // through a wall it had no contact with at the step's start. A 1 kg plate rammed by
  // a 100 kg box at 10-40 m/s, 0.1-0.3 m in front of a 1 cm wall, was pushed through
  // it (2.6-10.6 m beyond after 20 steps in 5 of 9 cases; test_ccd.py); a random-scene
  // fuzz pushed a 99 kg cylinder, crushed in a corner, 1.3 m out through a wall.
  for (const int i : ccd_pushed_rows_) {
    Vec3& d = ccd_pushed_[i];
    if (!(d.norm() > settings_.ccd_motion_threshold * inner_radius_[i])) continue;
    Motion mi;
    mi.start = Pose(Vec3(positions_[i] - d), orientations_[i]);
    mi.linear_velocity = d;
    const Pose end(positions_[i], orientations_[i]);
    Aabb box = shapes_[i]->world_aabb(mi.start);
    box.grow(shapes_[i]->world_aabb(end));
    const Real allowance = ccd_allowance(i);
    Real t_hit = 1;
    broadphase_->query_aabb(box, [&](ProxyId id) {
      const int j = slots_[static_cast<int>(broadphase_->user_data(id))].index;
      if (j == i || kinds_[j] != BodyKind::kStatic) return true;
      if (has_filters_ && !collides(slot_of_[i], slot_of_[j])) return true;
      const ToiResult r = sweep_to_allowance(i, mi, j, Motion{Pose(positions_[j], orientations_[j])}, t_hit, allowance);
      if (r.hit && r.status != QueryStatus::kUnsupported && r.time < t_hit) t_hit = r.time;
      return true;
    });
    if (t_hit < 1) {
      positions_[i] = mi.start.position + t_hit * d;
      d *= t_hit;
    }
  }
  for (const int i : ccd_pushed_rows_) {
    const Vec3& d = ccd_pushed_[i];
    take_potential_gain(i, d);
    // contacts() measures the step's depths from each body's motion over it.
    if (i < static_cast<int>(states_.size())) states_[i].dp += d;
  }
  return pushes;
}

// The ccd stage's sweep rule (continuous_step's sweeps, project_ccd_overlaps' long
// pushes): body a moving by ma against body b moving by mb over `duration` may make no
// overlap deeper than half its allowance, nor deepen one it starts with by more than a
// quarter of it; returns the first time it would (hit false if never).
ToiResult World::sweep_to_allowance(int a, const Motion& ma, int b, const Motion& mb, Real duration,
                                    Real allowance) const {
  const Real budget = 0.25 * allowance;
  ToiSettings st;
  st.tolerance = 0.5 * budget;
  st.target_distance = -2 * budget;
  // Already deeper than that at the start: it may deepen by the budget, each child of a
  // compound and each triangle of a mesh from its own start (ToiSettings::
  // deepen_allowance).
  st.deepen_allowance = budget;
  // Triangles of a mesh that body a slides along, moving towards their planes by less
  // than a quarter of its inner radius, are the solver's (ToiSettings::parallel_skip).
  st.parallel_skip = 0.25 * inner_radius_[a];
  return time_of_impact(*shapes_[a], ma, *shapes_[b], mb, duration, st);
}

int World::continuous_step() {
  const int n = body_count();
  const Real dt = settings_.dt;
  sweeps_.clear();
  sweep_of_.assign(n, -1);
  // The fast CCD bodies, with the motion that takes each from its start pose to its end
  // pose (its centre of mass along a line, turning about it at a constant rate: the
  // motion time_of_impact sweeps). Every other moving body may have left its broadphase
  // box (set at the step's start) by at most `reach_others`.
  for (const int i : ccd_rows_) {
    if (!awake_dynamic(i)) continue;
    // Cheap bound first (no trigonometry): the points of a body move at most
    // |d origin| + angle * (largest distance from the origin), and angle <= pi |vec(dq)|
    // (|vec(dq)| = sin(angle / 2), angle in [0, pi]).
    const Quat dq = orientations_[i] * start_orientations_[i].conjugate();
    const Real bound = (positions_[i] - start_positions_[i]).norm() +
                       kPi * dq.vec().norm() * (outer_radius_[i] + masses_[i].local_com.norm());
    const Real slow = settings_.ccd_motion_threshold * inner_radius_[i];
    if (!(bound > slow)) continue;
    const Vec3& lc = masses_[i].local_com;
    const Vec3 c0 = start_positions_[i] + start_orientations_[i] * lc;
    const Vec3 c1 = world_com(i);
    const Vec3 rot = rotation_vector(start_orientations_[i], orientations_[i]);
    const Real angle = rot.norm();
    const Real reach = (c1 - c0).norm() + angle * outer_radius_[i];
    if (!(reach > slow)) continue;
    Sweep sw;
    sw.body = i;
    sw.motion.start = Pose(start_positions_[i], start_orientations_[i]);
    sw.motion.center = lc;
    sw.motion.linear_velocity = (c1 - c0) / dt;
    sw.motion.angular_velocity = rot / dt;
    sw.box = swept_aabb(*shapes_[i], sw.motion, dt);
    sw.reach = reach;
    sw.time = dt;
    sweep_of_[i] = static_cast<std::int32_t>(sweeps_.size());
    sweeps_.push_back(sw);
  }
  if (sweeps_.empty()) return 0;
  // How far every other moving body may have left its broadphase box (set at the
  // step's start): from its motion over the step where the solver kept it (bodies in
  // contact), else from its velocity and acceleration (a free body's velocity changes
  // at a constant rate over the step, so it moved at most dt (|v_end| + |a| dt)).
  Real reach_others = 0;
  for (int i = 0; i < n; ++i) {
    if (!awake_[i] || sweep_of_[i] >= 0) continue;
    const Real r = outer_radius_[i];
    Real reach;
    if (body_flags_[i] & kInContact) {
      reach = states_[i].dp.norm() + kPi * states_[i].dq.vec().norm() * r;
    } else {
      Vec3 a = Vec3::Zero(), alpha = Vec3::Zero();
      if (kinds_[i] == BodyKind::kDynamic) {
        a = gravity_scale_[i] * settings_.gravity;
        if (body_flags_[i] & kHasForce) {
          a += masses_[i].inv_mass * forces_[i];
          alpha = world_inv_inertia(orientations_[i], masses_[i].inv_inertia_local) * torques_[i];
        }
      }
      reach = dt * (linear_velocities_[i].norm() + a.norm() * dt) +
              dt * (angular_velocities_[i].norm() + alpha.norm() * dt) * r;
    }
    reach_others = std::max(reach_others, reach);
  }

  // Sweeps body a (sweep sa) against body b moving by mb over the step, whose points
  // move at most reach_b: a may make no overlap with b deeper than half its allowance,
  // nor deepen one it starts with by more than a quarter of it. Returns the first time
  // it would (hit false if never), the normal from a to b and the contact point.
  struct PairHit {
    bool hit = false;
    Real time = 0;
    Vec3 normal, point;
  };
  auto sweep_pair = [&](const Sweep& sa, int b, const Motion& mb, Real reach_b, Real allowance) {
    PairHit h;
    if (sa.reach + reach_b <= 0.25 * allowance) return h;  // cannot get that much closer in one step
    const ToiResult r = sweep_to_allowance(sa.body, sa.motion, b, mb, dt, allowance);
    if (!r.hit || r.status == QueryStatus::kUnsupported) return h;
    h.hit = true;
    h.time = r.time;
    h.normal = r.normal;
    h.point = 0.5 * (r.point_a + r.point_b);
    return h;
  };
  // Keeps a hit with `other` if it is the sweep's earliest; `flip` for the sweep of the
  // pair's second body (the normal points the other way). Returns whether it was kept.
  auto record = [](Sweep& s, const PairHit& h, int other, bool flip) {
    if (!h.hit || !(h.time < s.time)) return false;
    s.time = h.time;
    s.hit_body = other;
    s.hit_normal = flip ? Vec3(-h.normal) : h.normal;
    s.hit_point = h.point;
    return true;
  };
  // Dynamic pairs the solver already saw (a contact constraint, speculative or not)
  // are left to it: clamping one body of a pile while its neighbours go on makes new
  // overlaps (measured on boxes3000 with CCD on every box: 2.5 m instead of 0.7 m).
  // Only the pairs it could not see are swept: those its speculative margin missed
  // (a turn, a body knocked sideways, a pair that was too far apart at the start).
  std::vector<std::uint64_t>& seen_pairs = ccd_seen_pairs_;
  seen_pairs.clear();
  for (const ContactConstraint& c : constraints_)
    if (sweep_of_[c.body_a] >= 0 || sweep_of_[c.body_b] >= 0)
      seen_pairs.push_back(row_pair_key(c.body_a, c.body_b));
  std::sort(seen_pairs.begin(), seen_pairs.end());
  auto solver_saw = [&](int a, int b) {
    return std::binary_search(seen_pairs.begin(), seen_pairs.end(), row_pair_key(a, b));
  };

  // Fast CCD bodies against each other, both moving: sweep and prune on x over their
  // swept boxes (each pair once); both take the earlier time.
  std::vector<int>& order = sweep_order_;
  sweep_pairs_.clear();
  order.resize(sweeps_.size());
  for (std::size_t k = 0; k < sweeps_.size(); ++k) order[k] = static_cast<int>(k);
  std::sort(order.begin(), order.end(), [&](int x, int y) {
    const Real ax = sweeps_[x].box.min.x(), bx = sweeps_[y].box.min.x();
    return ax < bx || (ax == bx && x < y);
  });
  for (std::size_t k = 0; k < order.size(); ++k) {
    for (std::size_t l = k + 1; l < order.size(); ++l) {
      Sweep& s1 = sweeps_[order[k]];
      Sweep& s2 = sweeps_[order[l]];
      if (s2.box.min.x() > s1.box.max.x()) break;
      if (!s1.box.overlaps(s2.box) || solver_saw(s1.body, s2.body)) continue;
      if (has_filters_ && !collides(slot_of_[s1.body], slot_of_[s2.body])) continue;
      sweep_pairs_.emplace_back(order[k], order[l]);
      const PairHit h =
          sweep_pair(s1, s2.body, s2.motion, s2.reach, std::min(ccd_allowance(s1.body), ccd_allowance(s2.body)));
      record(s1, h, s2.body, false);
      record(s2, h, s1.body, true);
    }
  }
  // Each fast CCD body against everything else near its path: static, kinematic and
  // sleeping bodies always (at their end pose: only a kinematic one has moved), other
  // dynamic bodies where the solver had no contact for the pair (at the pose the
  // solver put them in).
  for (Sweep& sw : sweeps_) {
    const int i = sw.body;
    const Real allowance = ccd_allowance(i);
    broadphase_->query_aabb(sw.box.fattened(reach_others), [&](ProxyId id) {
      const int j = slots_[static_cast<int>(broadphase_->user_data(id))].index;
      if (j == i || sweep_of_[j] >= 0) return true;  // itself, or swept above
      if (awake_dynamic(j) && solver_saw(i, j)) return true;
      if (has_filters_ && !collides(slot_of_[i], slot_of_[j])) return true;
      Motion mj;
      mj.start = Pose(positions_[j], orientations_[j]);
      Real reach_j = 0;
      if (kinds_[j] == BodyKind::kKinematic) {
        // A kinematic body's motion over the step is its velocity (the solver does not
        // change it): swept along it, from where it started.
        mj.linear_velocity = linear_velocities_[j];
        mj.angular_velocity = angular_velocities_[j];
        mj.center = masses_[j].local_com;
        const Vec3 c_end = world_com(j);
        mj.start.rotation = Motion{Pose(c_end, orientations_[j]), Vec3::Zero(), -mj.angular_velocity}.at(dt).rotation;
        mj.start.position = c_end - dt * mj.linear_velocity - mj.start.rotation * mj.center;
        reach_j = dt * (mj.linear_velocity.norm() + mj.angular_velocity.norm() * outer_radius_[j]);
      }
      record(sw, sweep_pair(sw, j, mj, reach_j, allowance), j, false);
      return true;
    });
  }
  // Two swept bodies put back at different times may now overlap where neither sweep
  // looked (the lower of two fast boxes stops on a wall, the upper one goes on into
  // it): each is swept again against the other where that one was put back, until no
  // time changes (rounds, as in Box2D v2's time-of-impact loop; capped).
  constexpr int kMaxRounds = 8;
  std::vector<Real>& seen = sweep_seen_;  // each sweep's time when the last round began
  seen.assign(sweeps_.size(), dt);
  for (int round = 0; round < kMaxRounds && !sweep_pairs_.empty(); ++round) {
    bool changed = false;
    std::vector<Real>& now = sweep_now_;
    now.resize(sweeps_.size());
    for (std::size_t k = 0; k < sweeps_.size(); ++k) now[k] = sweeps_[k].time;
    for (const auto& [x, y] : sweep_pairs_) {
      for (int side = 0; side < 2; ++side) {
        const int me = side ? y : x, other = side ? x : y;
        if (!(now[other] < seen[other])) continue;  // the other was not put back last round
        Motion mo;
        mo.start = sweeps_[other].motion.at(now[other]);
        const PairHit h = sweep_pair(sweeps_[me], sweeps_[other].body, mo, 0, ccd_allowance(sweeps_[me].body));
        changed = record(sweeps_[me], h, sweeps_[other].body, false) || changed;
      }
    }
    seen.swap(now);
    if (!changed) break;
  }

  // Put the bodies that hit something back at their time of impact.
  for (const Sweep& sw : sweeps_) {
    if (!(sw.time < dt)) continue;
    const int i = sw.body;
    const Vec3 c_end = world_com(i);
    const Pose p = sw.motion.at(sw.time);
    if (settings_.gyroscopic) {
      // The angular velocity turns back with the body (its body-frame value is kept),
      // so the rotational energy 1/2 w.I(q)w is the step's: with the gyroscopic term
      // w precesses over the step and the end's w belongs to the end's orientation
      // (without it, w is constant along the swept path and is kept). Kept in the world
      // frame instead, a thin rod (inertia 1:383) spinning about its long axis hit a
      // wall with that w now across it: 108 J -> 1523 J in one step, and a random-scene
      // fuzz blew up to NaN (seed 316 of tests/python/test_fuzz_worlds.py).
      angular_velocities_[i] = (p.rotation * orientations_[i].conjugate()) * angular_velocities_[i];
    }
    positions_[i] = p.position;
    orientations_[i] = p.rotation;
    const Vec3 c_t = world_com(i);
    // The move back along the path gains potential energy (against gravity): taken out
    // of the linear kinetic energy, so the step ends with no more energy than it would
    // have without CCD.
    take_potential_gain(i, c_t - c_end);
    // contacts() measures the step's depths from each body's motion over it.
    if (i < static_cast<int>(states_.size())) {
      states_[i].dp = c_t - (start_positions_[i] + start_orientations_[i] * masses_[i].local_com);
      states_[i].dq = p.rotation * start_orientations_[i].conjugate();
    }
    ++ccd_hits_;
  }
  // The collision at the time of impact: an impulse at the contact point that stops
  // the approach (with the pair's restitution above the threshold), as the contact
  // solver would, between the two bodies (momentum is kept, energy only lost). Without
  // it a body put back keeps the speed that carried it into the other, and a jammed
  // pile that the solver cannot stop in one step stays put back step after step.
  for (const Sweep& sw : sweeps_)
    if (sw.time < dt && sw.hit_body >= 0) stop_approach(sw.body, sw.hit_body, sw.hit_point, sw.hit_normal, true);
  return static_cast<int>(sweeps_.size());
}

std::vector<ContactInfo> World::contacts() const {
  std::vector<ContactInfo> out;
  if (static_cast<int>(states_.size()) != body_count() + 1) return out;  // stale (bodies changed)
  for (const ContactConstraint& c : constraints_) {
    const BodyState& a = states_[c.body_a];
    const BodyState& b = states_[c.body_b];
    for (int k = 0; k < c.count; ++k) {
      const ContactConstraintPoint& p = c.points[k];
      // Separation after the step, from the bodies' motion over it, at the anchors as
      // the solver turned them.
      Vec3 ra, rb;
      current_anchors(a, b, p, c.normal, ra, rb);
      const Vec3 d = (b.dp + rb) - (a.dp + ra);
      const Real s = c.normal.dot(d) + p.adjusted_separation;
      ContactInfo ci;
      ci.body_a = c.body_a;
      ci.body_b = c.body_b;
      ci.point = world_com(c.body_a) + ra;
      ci.normal = c.normal;
      ci.depth = -s;
      ci.normal_impulse = p.normal_impulse;
      out.push_back(ci);
    }
  }
  return out;
}

int World::contact_point_count() const {
  int n = 0;
  for (const ContactConstraint& c : constraints_) n += c.count;
  return n;
}

// Collided again, not read off the contact points: the points are the step's manifolds
// (found at its start poses) moved with their bodies, linearised, which miss a corner
// that swings in within the step (0.37 m reported where two boxes of boxes3000
// overlapped 0.41 m, CCD on) and overstate an overlap the ccd stage pushed apart along
// a collided normal (0.28 m reported against 0.10 m). Engines' reported depths are
// their narrowphase's (PyBullet's, after its step, at the poses it collided), so wmo
// bench compares like with like. Costs one narrowphase pass over the pairs per call.
Real World::max_penetration() const {
  if (static_cast<int>(states_.size()) != body_count() + 1) return 0;  // stale (bodies changed)
  std::vector<std::pair<int, int>> pairs;
  pairs.reserve(constraints_.size());
  for (const ContactConstraint& c : constraints_) pairs.emplace_back(c.body_a, c.body_b);
  std::sort(pairs.begin(), pairs.end());
  pairs.erase(std::unique(pairs.begin(), pairs.end()), pairs.end());
  Real deepest = 0;
  std::vector<Manifold> manifolds;
  for (const auto& [a, b] : pairs) {
    manifolds.clear();
    collide(*shapes_[a], Pose(positions_[a], orientations_[a]), *shapes_[b], Pose(positions_[b], orientations_[b]),
            manifolds);
    for (const Manifold& m : manifolds)
      for (int k = 0; k < m.count; ++k) deepest = std::max(deepest, m.points[k].depth);
  }
  return deepest;
}

Real World::kinetic_energy() const {
  Real e = 0;
  for (int i = 0; i < body_count(); ++i) {
    if (kinds_[i] != BodyKind::kDynamic) continue;
    const BodyMass& m = masses_[i];
    const Mat3 r = orientations_[i].toRotationMatrix();
    const Vec3 wb = r.transpose() * angular_velocities_[i];
    e += 0.5 * m.mass * linear_velocities_[i].squaredNorm() + 0.5 * wb.dot(m.inertia_local * wb);
  }
  return e;
}

}  // namespace wmo
