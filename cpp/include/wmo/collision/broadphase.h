// WMO collision layer: the broadphase.
//
// A broadphase keeps one axis-aligned box per "proxy" (typically one per shape) and
// reports the pairs of proxies whose boxes overlap, so the narrowphase only runs on
// those. Three interchangeable algorithms sit behind one interface:
//
//   * kBruteForce    O(n^2) all-pairs test; the reference the others are checked against.
//   * kSweepAndPrune sort-and-sweep along the axis of greatest spread, with the sorted
//                    array kept across frames and repaired by insertion sort (temporal
//                    coherence: near O(n) per frame when bodies move little). The sweep
//                    costs O(n + overlaps of the 1-D projections), which in a large 3-D
//                    scene of uniform density grows like n^(5/3): fine up to ~10^4 boxes.
//   * kAabbTree      dynamic bounding-volume tree of fattened boxes (the idea of Box2D's
//                    b2DynamicTree and Bullet's btDbvt): SAH branch-and-bound insertion,
//                    AVL rotations, reinsertion only when a box leaves its fat box, and a
//                    persistent candidate-pair list updated from the moved leaves only.
//                    The best choice for large scenes; its box and ray queries are
//                    O(log n + hits), where the other two scan every proxy.
//
// Semantics shared by every algorithm (tests check they agree bit for bit):
//   * Boxes are world-space AABBs, unit: metres. A box may have zero size on any axis
//     (a point or a flat box) but must be finite with min <= max per axis.
//   * Two boxes overlap when their closed intervals intersect on all three axes, i.e.
//     boxes that merely touch (shared face, edge or corner) DO overlap. This is
//     Aabb::overlaps, and it keeps resting contacts (a box lying exactly on another)
//     from flickering in and out of the pair list.
//   * Pairs are always computed on the TIGHT boxes given by the caller. Fattening inside
//     the tree is an internal optimisation that never changes the result.
//   * Proxy ids are assigned by the broadphase: dense non-negative int32 values; a
//     destroyed id is recycled, most recently destroyed first (a LIFO free list). The
//     assignment depends only on the sequence of create/destroy calls, so every
//     algorithm hands out the same ids for the same call history.
//   * query_pairs output is sorted lexicographically with first < second: the order does
//     not depend on the algorithm, insertion history, hashing or pointer values.
//   * Bad input (non-finite box, min > max, stale id) throws wmo::InvalidArgument.
#pragma once

#include <cstdint>
#include <memory>
#include <type_traits>
#include <utility>
#include <vector>

#include "wmo/math.h"

namespace wmo {

/// Handle of a broadphase proxy: a dense index >= 0 assigned by create_proxy.
using ProxyId = std::int32_t;
/// "No proxy".
constexpr ProxyId kNullProxy = -1;
/// A pair of overlapping proxies, first < second.
using ProxyPair = std::pair<ProxyId, ProxyId>;

enum class BroadphaseType : std::uint8_t {
  kBruteForce = 0,
  kSweepAndPrune = 1,
  kAabbTree = 2,
};

const char* to_string(BroadphaseType t);

/// Tuning of the broadphases. Only kAabbTree reads these; results never depend on them.
struct BroadphaseSettings {
  /// Fat-box margin of the tree's leaves (unit: m): a leaf stores the tight box grown by
  /// this much on every side, and is reinserted only when the tight box leaves it (or,
  /// as in Box2D v2.4, when the fat box exceeds the freshly fattened box grown by a further
  /// 4 margins, so a box stretched by an earlier fast motion shrinks back).
  /// 0.1 m is Box2D's b2_aabbMargin: for metre-scale bodies moving a few cm per step it
  /// saves several reinsertions per body while adding few false candidates. A fixed
  /// (not size-relative) margin because what it absorbs is motion, not size.
  Real aabb_margin = 0.1;
  /// Predictive fattening: the fat box is additionally stretched by this many times
  /// the displacement passed to move_proxy, in its direction (Box2D's
  /// b2_aabbMultiplier = 4), so a fast body is reinserted less often.
  Real displacement_multiplier = 4.0;
};

/// Counters for benchmarks and tests. Fields that do not apply to an algorithm are 0.
struct BroadphaseStats {
  int proxy_count = 0;      ///< live proxies
  int node_count = 0;       ///< tree: live nodes (2 * leaves - 1)
  int height = 0;           ///< tree: height of the root (a single leaf has height 0)
  int candidate_pairs = 0;  ///< tree: pairs whose FAT boxes overlap (a superset of pairs)
  /// tree: leaves placed anew since creation (moved out of their fat boxes; counted
  /// at the update that places them, one by one or by a rebuild)
  std::int64_t reinsertions = 0;
  std::int64_t rebuilds = 0;  ///< tree: whole-tree rebuilds since creation (mass moves)
  std::int64_t refits = 0;    ///< tree: mass moves absorbed by a refit instead (same structure)
  int sweep_axis = -1;      ///< sweep and prune: current sweep axis (0 = x, 1 = y, 2 = z)
  std::int64_t axis_changes = 0;  ///< sweep and prune: sweep axis switches since creation
};

/// Non-owning reference to a callable (like C++26 std::function_ref): no allocation,
/// so queries can take a capturing lambda in the hot path. The callable must outlive
/// the call it is passed to.
template <class Sig>
class FunctionRef;

template <class R, class... Args>
class FunctionRef<R(Args...)> {
 public:
  template <class F>
    requires(!std::is_same_v<std::remove_cvref_t<F>, FunctionRef> &&
             std::is_invocable_r_v<R, F&, Args...>)
  FunctionRef(F&& f)  // NOLINT(google-explicit-constructor): implicit, like function_ref
      : obj_(const_cast<void*>(static_cast<const void*>(std::addressof(f)))),
        call_([](void* obj, Args... args) -> R {
          return (*static_cast<std::remove_reference_t<F>*>(obj))(std::forward<Args>(args)...);
        }) {}
  R operator()(Args... args) const { return call_(obj_, std::forward<Args>(args)...); }

 private:
  void* obj_;
  R (*call_)(void*, Args...);
};

/// Called by query_aabb for each proxy whose tight box overlaps the query box. Return
/// true to continue, false to stop the query.
using AabbQueryCallback = FunctionRef<bool(ProxyId)>;

/// Called by raycast for each proxy whose tight box the ray enters at parameter `t`
/// (0 <= t <= current max_t; t = 0 when the origin is inside the box). Returns the new
/// max_t: return the current max_t to see every hit, `t` to keep only hits no farther
/// than this one (closest-hit search), or a negative value to stop the cast.
using RayQueryCallback = FunctionRef<Real(ProxyId, Real t)>;

/// The broadphase interface. The base class owns the proxy table (tight boxes, user data,
/// id allocation) so that every algorithm sees the same ids; algorithms implement the
/// on_* hooks. Not thread-safe for concurrent mutation; const queries may run in
/// parallel with each other.
class Broadphase {
 public:
  virtual ~Broadphase() = default;
  Broadphase(const Broadphase&) = delete;
  Broadphase& operator=(const Broadphase&) = delete;

  virtual BroadphaseType type() const = 0;

  /// Adds a proxy with the tight world box `box` (unit: m) and an opaque `user_data`
  /// (e.g. a shape index) returned by user_data(). Returns its id (see the file comment
  /// for how ids are chosen). Throws InvalidArgument on a non-finite box or min > max.
  ProxyId create_proxy(const Aabb& box, std::uint64_t user_data = 0);

  /// Removes a proxy; its id may be returned by a later create_proxy. Throws
  /// InvalidArgument if `id` is not a live proxy.
  void destroy_proxy(ProxyId id);

  /// Sets the tight box of a live proxy. `displacement` (unit: m, world frame) is the
  /// motion expected over the next step (velocity * dt); the tree uses it to stretch the
  /// fat box ahead of the motion. It never changes which pairs are reported. Throws
  /// InvalidArgument on a bad id or box, or a non-finite displacement.
  void move_proxy(ProxyId id, const Aabb& box, const Vec3& displacement = Vec3::Zero());
  /// move_proxy without its checks, for a caller that guarantees a live id, a finite
  /// box with min <= max and a finite displacement (the world: its state is validated
  /// at the start of World::step). A bad argument here is undefined behaviour.
  void move_proxy_unchecked(ProxyId id, const Aabb& box, const Vec3& displacement) {
    tight_[static_cast<std::size_t>(id)] = box;
    dirty_ = true;
    on_move(id, displacement);
  }
  /// move_proxy_unchecked for `count` proxies at once: ids[k] gets the tight box
  /// boxes[k] and the displacement displacements[k]. The same result as the calls one
  /// by one, with one virtual call for the batch (the world moves every awake body's
  /// proxy every step: 10,000 falling spheres spent 8 ns a body in the per-proxy calls
  /// and the tree's scattered leaves).
  void move_proxies_unchecked(const ProxyId* ids, const Aabb* boxes, const Vec3* displacements, int count) {
    for (int k = 0; k < count; ++k) tight_[static_cast<std::size_t>(ids[k])] = boxes[k];
    dirty_ = true;
    on_move_batch(ids, displacements, count);
  }

  /// The per-step fast path of a move: if the algorithm keeps a fat box for `id` (the
  /// tree does; brute force and sweep and prune do not) and move_proxy_unchecked(id,
  /// box, displacement) would leave that fat box as it is (`box` inside it, and it not
  /// grown too loose for `box`: the tree's rule, see broadphase_tree.cpp), sets the
  /// tight box and returns true; nothing else changes, so update() has no work. Else
  /// returns false and changes nothing: the caller moves the proxy. The same outcome
  /// as move_proxy_unchecked, decided inline on id-ordered arrays without a virtual
  /// call or the batch's copies (the world tries it for every awake body every step;
  /// 10,000 falling spheres: the stage 144 -> 133 us a step, and -> 85-105 us with the
  /// stage's loop in a function of its own, World::update_broadphase).
  /// Preconditions as move_proxy_unchecked, except that a non-finite box is allowed
  /// (NaN fails every comparison: false).
  [[gnu::always_inline]] bool keep_proxy_unchecked(ProxyId id, const Aabb& box, const Vec3& displacement) {
    if (keep_.empty()) return false;
    const auto i = static_cast<std::size_t>(id);
    const Aabb& f = keep_[i];
    // The fat box the move would compute: box grown by the margin, stretched ahead of
    // the displacement (times the multiplier); it is kept unless the fat box exceeds
    // that grown by the slack (keep_slack_margins_ margins plus the stretch's size).
    const Vec3 d = keep_multiplier_ * displacement;
    const Real slack = keep_slack_margins_ * keep_margin_ + keep_multiplier_ * displacement.cwiseAbs().maxCoeff();
    const Vec3 lo = ((box.min.array() - keep_margin_).matrix() + d.cwiseMin(Vec3::Zero())).array() - slack;
    const Vec3 hi = ((box.max.array() + keep_margin_).matrix() + d.cwiseMax(Vec3::Zero())).array() + slack;
    const bool keep = (f.min.array() <= box.min.array()).all() & (box.max.array() <= f.max.array()).all() &
                      (lo.array() <= f.min.array()).all() & (f.max.array() <= hi.array()).all();
    if (keep) tight_[i] = box;
    return keep;
  }

  /// What keep_proxy_unchecked reads and writes, for a caller that runs the same test
  /// on many proxies at once in its own (vectorised) loop (the world's free spheres):
  /// by proxy id, the fat boxes it tests against and the tight boxes it sets; and the
  /// rule's constants. `fat` is null where the algorithm keeps no fat boxes (the test
  /// then always declines). Valid until the next call that creates or destroys a proxy.
  struct KeepRule {
    const Aabb* fat = nullptr;
    Aabb* tight = nullptr;
    Real margin = 0, multiplier = 0, slack_margins = 0;
  };
  KeepRule keep_rule() {
    if (keep_.empty()) return {};
    return {keep_.data(), tight_.data(), keep_margin_, keep_multiplier_, keep_slack_margins_};
  }

  /// Finishes incremental work after a batch of create/destroy/move calls (re-sorting,
  /// candidate-pair update). query_pairs calls it itself when needed.
  void update();

  /// Replaces `out` with every pair of live proxies whose tight boxes overlap (touching
  /// included), each once with first < second, sorted lexicographically. Reuses `out`'s
  /// capacity (no allocation in steady state).
  void query_pairs(std::vector<ProxyPair>& out);

  /// Calls `callback(id)` for each live proxy whose tight box overlaps `box` (touching
  /// included), in an unspecified order, until it returns false. Throws InvalidArgument
  /// on a non-finite box or min > max.
  virtual void query_aabb(const Aabb& box, AabbQueryCallback callback) const;

  /// Casts the ray origin + t * dir, 0 <= t <= max_t (t in units of |dir|, metres for a
  /// unit dir) against the tight boxes, calling `callback` for each box it enters, in an
  /// unspecified order; see RayQueryCallback for clipping. Throws InvalidArgument on a
  /// non-finite origin or dir, a zero dir, or max_t < 0 or NaN (max_t = kInf is allowed).
  virtual void raycast(const Vec3& origin, const Vec3& dir, Real max_t,
                       RayQueryCallback callback) const;

  /// Number of live proxies.
  int proxy_count() const { return live_count_; }
  /// One past the largest id ever handed out (ids in [0, id_capacity()) may be live).
  int id_capacity() const { return static_cast<int>(tight_.size()); }
  /// True if `id` names a live proxy.
  bool is_live(ProxyId id) const {
    return id >= 0 && id < id_capacity() && live_[static_cast<std::size_t>(id)] != 0;
  }
  /// Tight box of a live proxy, as last given (unit: m). Throws on a bad id. (Inline:
  /// the world reads it for every pair of every step.)
  const Aabb& aabb(ProxyId id) const {
    if (!is_live(id)) [[unlikely]]
      throw_not_live("aabb", id);
    return tight_[static_cast<std::size_t>(id)];
  }
  /// User data of a live proxy. Throws on a bad id.
  std::uint64_t user_data(ProxyId id) const {
    if (!is_live(id)) [[unlikely]]
      throw_not_live("user_data", id);
    return user_data_[static_cast<std::size_t>(id)];
  }

  virtual BroadphaseStats stats() const;

  /// Checks the algorithm's internal invariants (tree links, heights, boxes containing
  /// their children, sorted arrays...). Throws std::logic_error naming the first broken
  /// one. Call it after update() (or query_pairs): between a change and the next update
  /// the incremental structures are legitimately out of date. O(n log n); for tests.
  virtual void validate() const;

 protected:
  Broadphase() = default;

  // Hooks, called after the base class has validated the input and updated the table.
  virtual void on_create(ProxyId id) = 0;
  /// Called before the id is released (aabb(id) is still readable).
  virtual void on_destroy(ProxyId id) = 0;
  virtual void on_move(ProxyId id, const Vec3& displacement) = 0;
  /// on_move for each of `count` proxies, in order (their tight boxes already set).
  virtual void on_move_batch(const ProxyId* ids, const Vec3* displacements, int count) {
    for (int k = 0; k < count; ++k) on_move(ids[k], displacements[k]);
  }
  virtual void on_update() = 0;
  /// Fills `out` (already cleared) as query_pairs specifies; called after on_update().
  virtual void on_query_pairs(std::vector<ProxyPair>& out) = 0;

  const Aabb& tight(ProxyId id) const { return tight_[static_cast<std::size_t>(id)]; }

  /// For an algorithm with fat boxes: by id, the fat box keep_proxy_unchecked tests
  /// against (an empty box, min > max, while a move is pending: every test fails), and
  /// the rule's constants. Left empty, keep_proxy_unchecked always declines.
  std::vector<Aabb> keep_;
  Real keep_margin_ = 0;
  Real keep_multiplier_ = 0;
  Real keep_slack_margins_ = 0;

 private:
  void require_live(const char* what, ProxyId id) const {
    if (!is_live(id)) throw_not_live(what, id);
  }
  /// Throws InvalidArgument: `id` is not a live proxy (`what` names the call).
  [[noreturn]] static void throw_not_live(const char* what, ProxyId id);

  std::vector<Aabb> tight_;                // by id
  std::vector<std::uint64_t> user_data_;   // by id
  std::vector<std::uint8_t> live_;         // by id
  std::vector<ProxyId> free_ids_;          // LIFO
  int live_count_ = 0;
  bool dirty_ = false;                     // some change since the last update()
};

/// Creates an empty broadphase of the given algorithm.
std::unique_ptr<Broadphase> make_broadphase(BroadphaseType type,
                                            const BroadphaseSettings& settings = {});

/// Closed ray-box slab test (Kay & Kajiya 1986; Williams et al. 2005 for the IEEE
/// handling): true if origin + t * dir meets `box` for some t in [0, max_t], with the
/// entry parameter in `t_enter` (0 if the origin is inside). Axes with dir = 0 test the
/// origin against the slab instead of dividing, so no NaN arises.
bool ray_aabb(const Vec3& origin, const Vec3& dir, const Aabb& box, Real max_t, Real& t_enter);

}  // namespace wmo
