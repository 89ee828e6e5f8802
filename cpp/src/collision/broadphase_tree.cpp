// Dynamic AABB tree broadphase. The idea is that of Box2D's b2DynamicTree (Catto) and
// Bullet's btDbvt (Presson); this is WMO's own implementation:
//
//   * Leaves store FAT boxes: the tight box grown by a margin and stretched along the
//     expected displacement. A leaf is reinserted only when its tight box leaves the fat
//     box (or the fat box has become far larger than needed), so most moves of slowly
//     moving bodies touch only the proxy table.
//   * Insertion picks the sibling that minimises the surface area heuristic (SAH: total
//     surface area of internal nodes, Goldsmith & Salmon 1987, MacDonald & Booth 1990),
//     found exactly by branch and bound (Bittner, Hapala & Havran 2012, "Fast
//     insertion-based optimization of bounding volume hierarchies", section 3.1).
//   * After every insertion and removal the path to the root is rebalanced by AVL-style
//     single rotations of the taller grandchild (Adelson-Velsky & Landis 1962; the scheme
//     Box2D v2.4 uses), which bounds the height by O(log n) even for sorted insertions.
//   * Nodes live in one contiguous pool with an intrusive free list.
//   * When many leaves leave their boxes in one step (at least an eighth), the tree is
//     refitted in place if that keeps its SAH quality (bodies moving together), else
//     rebuilt top down, instead of reinserting them one by one.
//   * Pairs: a persistent list of candidate pairs (leaves whose FAT boxes overlap) is
//     kept sorted. update() drops the candidates of leaves whose fat box changed and
//     re-queries only those leaves (Box2D's move buffer), so the per-frame cost is
//     O(candidates + reinsertions * log n). query_pairs filters the candidates on the
//     TIGHT boxes, so the result equals brute force exactly, already in sorted order.
#include <algorithm>
#include <array>
#include <cmath>
#include <iterator>
#include <string>
#include <stdexcept>
#include <vector>

#include "broadphase_internal.h"

namespace wmo {
namespace {

constexpr std::int32_t kNull = -1;

/// Box2D v2.4's rule: a leaf whose fat box still contains the tight box is nevertheless
/// reinserted when the fat box exceeds the freshly computed one grown by this many
/// margins, so a box stretched by an earlier fast motion shrinks back once the body
/// slows down (fewer false candidates), without reinserting on every small change.
/// The slack also grows by the predicted stretch (multiplier x displacement) itself:
/// with a fixed slack a body faster than 4 margins per step (24 m/s at 60 Hz) failed
/// the test every step and was reinserted every step (measured: 10,000 falling spheres
/// spent 14 ms a step in the broadphase, 1.4 us per body), though its box was stale by
/// no more than the motion it had been stretched for.
constexpr Real kShrinkMargins = 4.0;

/// flush_pending rebuilds the whole tree when at least 1 / kRebuildFraction of the
/// leaves (and at least kRebuildMin) wait for reinsertion.
constexpr int kRebuildFraction = 8;
constexpr int kRebuildMin = 64;

/// Such a mass move first refits the tree (new leaf boxes, every internal box
/// recomputed bottom up, no change of structure: O(nodes), ~0.1 ms at 10,000 leaves)
/// and keeps it when its quality has not dropped: the SAH cost (total internal surface
/// area) over the total leaf area at most this many times the ratio the last rebuild
/// left. Bodies that move together (falling, or carried along) keep their neighbours,
/// and the refitted tree is as good as a new one; bodies that scatter make the ratio
/// grow and get a rebuild. Measured: 10,000 falling spheres, every ~4 steps all leave
/// their boxes at once, 2.3 ms a rebuild against ~0.1 ms a refit. 1.25: a quarter more
/// internal area than a fresh build, after which queries and joins visit noticeably
/// more nodes.
constexpr Real kRefitQuality = 1.25;

/// Traversal stack: inline storage for the common case and a heap fallback, so a query
/// never overflows whatever the tree's shape. An AVL-balanced tree of 2^31 leaves is
/// < 64 deep and a depth-first traversal holds at most depth + 1 entries, so the
/// fallback is only a safety net.
class TraversalStack {
 public:
  void push(std::int32_t v) {
    if (size_ < kInline) {
      inline_[size_++] = v;
    } else {
      overflow_.push_back(v);
      ++size_;
    }
  }
  std::int32_t pop() {
    --size_;
    if (size_ >= kInline) {
      const std::int32_t v = overflow_.back();
      overflow_.pop_back();
      return v;
    }
    return inline_[size_];
  }
  bool empty() const { return size_ == 0; }

 private:
  static constexpr std::size_t kInline = 128;
  std::array<std::int32_t, kInline> inline_;
  std::vector<std::int32_t> overflow_;
  std::size_t size_ = 0;
};

class AabbTreeBroadphase final : public Broadphase {
 public:
  explicit AabbTreeBroadphase(const BroadphaseSettings& s) : settings_(s) {
    // keep_proxy_unchecked applies move_one's rule inline on the base's keep_ (the
    // leaves' fat boxes by id).
    keep_margin_ = s.aabb_margin;
    keep_multiplier_ = s.displacement_multiplier;
    keep_slack_margins_ = kShrinkMargins;
  }

  BroadphaseType type() const override { return BroadphaseType::kAabbTree; }

  void query_aabb(const Aabb& box, AabbQueryCallback callback) const override {
    detail::require_valid_box("box", box);
    // Moves not yet placed in the tree (pending_) are tested directly: their leaves'
    // boxes are still the old ones.
    bool go_on = true;
    query_fat(box, [&](std::int32_t node) {
      const ProxyId id = nodes_[static_cast<std::size_t>(node)].proxy();
      if (!pending_flag_[static_cast<std::size_t>(id)] && tight(id).overlaps(box)) return go_on = callback(id);
      return true;
    });
    for (const ProxyId id : pending_list_) {
      if (!go_on) return;
      if (pending_flag_[static_cast<std::size_t>(id)] && tight(id).overlaps(box)) go_on = callback(id);
    }
  }

  void raycast(const Vec3& origin, const Vec3& dir, Real max_t,
               RayQueryCallback callback) const override {
    detail::require_valid_ray(origin, dir, max_t);
    if (root_ == kNull) return;
    const detail::PreparedRay ray(origin, dir);
    TraversalStack stack;
    stack.push(root_);
    while (!stack.empty()) {
      const Node& n = nodes_[static_cast<std::size_t>(stack.pop())];
      Real t;
      // max_t shrinks as the callback clips, pruning farther subtrees.
      if (!ray.hits(n.box, max_t, t)) continue;
      if (n.is_leaf()) {
        if (pending_flag_[static_cast<std::size_t>(n.proxy())]) continue;  // below
        if (!ray.hits(tight(n.proxy()), max_t, t)) continue;
        const Real next = callback(n.proxy(), t);
        if (!(next >= 0)) return;  // negative (or NaN) stops the cast
        max_t = next < max_t ? next : max_t;
      } else {
        stack.push(n.child1);
        stack.push(n.child2);
      }
    }
    for (const ProxyId id : pending_list_) {  // moves not yet placed in the tree
      Real t;
      if (!pending_flag_[static_cast<std::size_t>(id)] || !ray.hits(tight(id), max_t, t)) continue;
      const Real next = callback(id, t);
      if (!(next >= 0)) return;
      max_t = next < max_t ? next : max_t;
    }
  }

  BroadphaseStats stats() const override {
    BroadphaseStats s = Broadphase::stats();
    s.node_count = static_cast<int>(nodes_.size()) - free_count_;
    s.height = root_ == kNull ? 0 : nodes_[static_cast<std::size_t>(root_)].height;
    s.candidate_pairs = static_cast<int>(candidates_.size());
    s.reinsertions = reinsertions_;
    s.rebuilds = rebuilds_;
    s.refits = refits_;
    return s;
  }

  void validate() const override {
    Broadphase::validate();
    auto fail = [](const char* what) { throw std::logic_error(std::string("aabb tree: ") + what); };
    for (const ProxyId id : pending_list_)
      if (pending_flag_[static_cast<std::size_t>(id)]) fail("moves pending: validate() is for after update()");
    // Free list.
    int free_seen = 0;
    for (std::int32_t f = free_list_; f != kNull; f = nodes_[static_cast<std::size_t>(f)].parent) {
      if (nodes_[static_cast<std::size_t>(f)].height != -1) fail("free node with a height");
      if (++free_seen > static_cast<int>(nodes_.size())) fail("free list has a cycle");
    }
    if (free_seen != free_count_) fail("free count mismatch");
    // Structure, heights, boxes, by a traversal from the root.
    int leaves = 0, reached = 0;
    if (root_ != kNull) {
      if (nodes_[static_cast<std::size_t>(root_)].parent != kNull) fail("root has a parent");
      TraversalStack stack;
      stack.push(root_);
      while (!stack.empty()) {
        const std::int32_t i = stack.pop();
        const Node& n = nodes_[static_cast<std::size_t>(i)];
        if (++reached > static_cast<int>(nodes_.size())) fail("cycle");
        if (n.is_leaf()) {
          ++leaves;
          if (n.height != 0) fail("leaf height != 0");
          if (!is_live(n.proxy())) fail("leaf of a dead proxy");
          if (leaf_[static_cast<std::size_t>(n.proxy())] != i) fail("proxy -> leaf link broken");
          if (!n.box.contains(tight(n.proxy()))) fail("fat box does not contain the tight box");
          const Aabb& mirror = keep_[static_cast<std::size_t>(n.proxy())];
          if (mirror.min != n.box.min || mirror.max != n.box.max) fail("fat box mirror differs from the leaf's box");
          continue;
        }
        const Node& c1 = nodes_[static_cast<std::size_t>(n.child1)];
        const Node& c2 = nodes_[static_cast<std::size_t>(n.child2)];
        if (c1.parent != i || c2.parent != i) fail("child -> parent link broken");
        if (n.height != 1 + std::max(c1.height, c2.height)) fail("wrong height");
        const Aabb u = Aabb::merge(c1.box, c2.box);
        if (u.min != n.box.min || u.max != n.box.max) fail("box is not the union of its children");
        stack.push(n.child1);
        stack.push(n.child2);
      }
    }
    if (leaves != proxy_count()) fail("leaf count differs from the live proxy count");
    if (reached + free_count_ != static_cast<int>(nodes_.size())) fail("unreachable nodes");
    // Candidate pairs: sorted, unique, exactly the fat-overlapping pairs.
    for (std::size_t k = 0; k < candidates_.size(); ++k) {
      const ProxyPair& p = candidates_[k];
      if (!(p.first < p.second)) fail("candidate pair not ordered");
      if (k > 0 && !(candidates_[k - 1] < p)) fail("candidates not sorted and unique");
      if (!is_live(p.first) || !is_live(p.second)) fail("candidate of a dead proxy");
      if (!fat(p.first).overlaps(fat(p.second))) fail("candidate whose fat boxes do not overlap");
    }
    std::size_t expected = 0;
    for (ProxyId id = 0; id < id_capacity(); ++id) {
      if (!is_live(id)) continue;
      query_fat(fat(id), [&](std::int32_t node) {
        const ProxyId o = nodes_[static_cast<std::size_t>(node)].proxy();
        if (o > id) {
          ++expected;
          if (!std::binary_search(candidates_.begin(), candidates_.end(), ProxyPair(id, o)))
            fail("missing candidate pair");
        }
        return true;
      });
    }
    if (expected != candidates_.size()) fail("candidate count mismatch");
  }

 protected:
  void on_create(ProxyId id) override {
    const auto i = static_cast<std::size_t>(id);
    if (i >= leaf_.size()) {
      leaf_.resize(i + 1, kNull);
      changed_.resize(i + 1, 0);
      pending_flag_.resize(i + 1, 0);
      pending_box_.resize(i + 1);
      keep_.resize(i + 1);
    }
    const std::int32_t leaf = allocate_node();
    Node& n = nodes_[static_cast<std::size_t>(leaf)];
    n.child2 = id;
    n.height = 0;
    set_fat(leaf, fat_box(tight(id), Vec3::Zero()));
    leaf_[i] = leaf;
    insert_leaf(leaf);
    mark_changed(id);
  }

  void on_destroy(ProxyId id) override {
    const auto i = static_cast<std::size_t>(id);
    pending_flag_[i] = 0;  // its entry in pending_list_ is skipped
    const std::int32_t leaf = leaf_[i];
    remove_leaf(leaf);
    free_node(leaf);
    leaf_[i] = kNull;
    mark_changed(id);
  }

  void on_move(ProxyId id, const Vec3& displacement) override { move_one(id, displacement); }

  void on_move_batch(const ProxyId* ids, const Vec3* displacements, int count) override {
    for (int k = 0; k < count; ++k) move_one(ids[k], displacements[k]);
  }

  void on_update() override {
    flush_pending();
    if (changed_list_.empty()) return;  // only moves inside fat boxes: candidates still exact
    if (changed_list_.size() * 2 >= static_cast<std::size_t>(proxy_count())) {
      // Most proxies changed (bodies falling together): all candidates from one
      // traversal of the tree against itself, which visits each overlapping pair of
      // subtrees once, instead of one query per changed proxy that finds each pair
      // twice. Measured: 10,000 falling spheres, pairs stage 1.41 -> 1.03 ms a step;
      // but boxes3000, whose waves move a fraction of a dense pile, got slower with
      // the join from an eighth of the proxies on (1.9 -> 2.85 ms), so from half on.
      for (const ProxyId id : changed_list_) changed_[static_cast<std::size_t>(id)] = 0;
      changed_list_.clear();
      candidates_.clear();
      self_join(candidates_);
      sort_pairs(candidates_);
      return;
    }
    // 1. Drop the candidates of every proxy whose fat box changed (moved, created,
    //    destroyed); all other candidates are still exact.
    std::size_t w = 0;
    for (const ProxyPair& p : candidates_) {
      if (!changed_[static_cast<std::size_t>(p.first)] && !changed_[static_cast<std::size_t>(p.second)])
        candidates_[w++] = p;
    }
    candidates_.resize(w);
    // 2. Re-query the changed proxies that are live. A pair of two changed proxies is
    //    found from both sides; it is kept from the smaller id's side only.
    fresh_.clear();
    for (const ProxyId id : changed_list_) {
      if (!is_live(id)) continue;
      query_fat(fat(id), [&](std::int32_t node) {
        const ProxyId o = nodes_[static_cast<std::size_t>(node)].proxy();
        if (o != id && (!changed_[static_cast<std::size_t>(o)] || o > id))
          fresh_.emplace_back(std::min(id, o), std::max(id, o));
        return true;
      });
    }
    for (const ProxyId id : changed_list_) changed_[static_cast<std::size_t>(id)] = 0;
    changed_list_.clear();
    // 3. Merge the new pairs into the sorted list (disjoint sets: every fresh pair has a
    //    changed member, no kept one does). The buffers keep their capacity.
    std::sort(fresh_.begin(), fresh_.end());
    merged_.clear();
    std::merge(candidates_.begin(), candidates_.end(), fresh_.begin(), fresh_.end(),
               std::back_inserter(merged_));
    candidates_.swap(merged_);
  }

  void on_query_pairs(std::vector<ProxyPair>& out) override {
    // Aabb::overlaps with one branch: the boxes' intersection, hi - lo, is not negative
    // on any axis (most candidates of a moving scene fail some axis, in no predictable
    // order; the six comparisons, written with `&`, were still compiled to a branch
    // each: 10,000 falling spheres, 9,500 candidates, 34 us). The tight boxes are
    // finite (move_proxy's precondition), and for finite x, y, x - y >= 0 exactly when
    // x >= y (a difference of distinct doubles is never rounded to zero).
    for (const ProxyPair& p : candidates_) {
      const Aabb& a = tight(p.first);
      const Aabb& b = tight(p.second);
      const Vec3 gap = a.max.cwiseMin(b.max) - a.min.cwiseMax(b.min);
      if (std::min(std::min(gap.x(), gap.y()), gap.z()) >= 0) out.push_back(p);
    }
  }

 private:
  /// One cache line per node (64 bytes): a leaf keeps its proxy id in child2, which a
  /// leaf does not otherwise use, so queries touch one line per visited node.
  struct alignas(64) Node {
    Aabb box;                     // fat box of a leaf, union of the children otherwise
    std::int32_t parent = kNull;  // next free node while on the free list
    std::int32_t child1 = kNull;  // kNull for a leaf
    std::int32_t child2 = kNull;  // a leaf's proxy id
    std::int32_t height = -1;     // 0 for a leaf, -1 when free
    bool is_leaf() const { return child1 == kNull; }
    ProxyId proxy() const { return child2; }
  };
  static_assert(sizeof(Node) == 64, "tree node should fill exactly one cache line");

  // The fat box of a proxy: its leaf's box, mirrored by id in the base's keep_ (set_fat
  // keeps the two equal) so that the per-step check of every moved proxy reads memory
  // in id order rather than the leaves scattered over the tree; keep_proxy_unchecked
  // reads it there. While a move is pending the mirror is an empty box (move_one), so
  // that a second move before update() is tested against nothing and pended again
  // (its new fat box is computed from the newest tight box).
  const Aabb& fat(ProxyId id) const { return keep_[static_cast<std::size_t>(id)]; }
  void set_fat(std::int32_t leaf, const Aabb& box) {
    Node& n = node(leaf);
    n.box = box;
    keep_[static_cast<std::size_t>(n.proxy())] = box;
  }

  [[gnu::always_inline]] void move_one(ProxyId id, const Vec3& displacement) {
    const auto i = static_cast<std::size_t>(id);
    const Aabb& t = tight(id);
    const Aabb& old_fat = keep_[i];
    const Aabb new_fat = fat_box(t, displacement);
    const Real slack = kShrinkMargins * settings_.aabb_margin +
                       settings_.displacement_multiplier * displacement.cwiseAbs().maxCoeff();
    if (old_fat.contains(t) && new_fat.fattened(slack).contains(old_fat))
      return;  // the fat box still does its job: no tree change, no pair change
    // Placed in the tree at the next update (flush_pending): one by one, or all at
    // once by a rebuild when many bodies left their boxes in the same step.
    if (!pending_flag_[i]) {
      pending_flag_[i] = 1;
      pending_list_.push_back(id);
    }
    pending_box_[i] = new_fat;
    keep_[i] = Aabb(Vec3::Constant(kInf), Vec3::Constant(-kInf));  // set_fat restores it at the flush
    mark_changed(id);
  }

  Aabb fat_box(const Aabb& t, const Vec3& displacement) const {
    Aabb f = t.fattened(settings_.aabb_margin);
    const Vec3 d = settings_.displacement_multiplier * displacement;
    f.min += d.cwiseMin(Vec3::Zero());  // stretched ahead of the motion only
    f.max += d.cwiseMax(Vec3::Zero());
    return f;
  }

  void mark_changed(ProxyId id) {
    auto& c = changed_[static_cast<std::size_t>(id)];
    if (!c) {
      c = 1;
      changed_list_.push_back(id);
    }
  }

  Node& node(std::int32_t i) { return nodes_[static_cast<std::size_t>(i)]; }

  /// Every pair of leaves whose fat boxes overlap, once each (first < second), in no
  /// particular order (the caller sorts). Two leaves have one lowest common ancestor,
  /// an internal node with one of them under each child: so the pairs are, for every
  /// internal node whose two children's boxes overlap, those of the join of the two
  /// children's subtrees, a depth-first walk over pairs of subtrees. The internal
  /// nodes are taken in the order of the node array, not by a walk from the root that
  /// pairs every subtree with itself: no stack round trip for those 10,000 self
  /// pairs, and the array read in order (measured: 10,000 falling spheres, find_pairs
  /// 347-357 -> 321-328 us a step on average, three runs each).
  void self_join(std::vector<ProxyPair>& out) {
    if (root_ == kNull) return;
    // A pair of distinct subtrees is pushed only if their boxes overlap (tested where
    // both boxes are at hand, before the push): half the pairs a walk meets do not,
    // and each pop costs a stack round trip and two node loads. Measured: 10,000
    // falling spheres, the join of a mass move (9,500 candidates) 1.30 -> 0.95 ms.
    // (Pushing without a branch, the top advanced by the test's result, was slower:
    // 1.2 ms; so was nothing gained by renumbering the nodes depth first.)
    auto push = [&](std::int32_t a, const Aabb& box_a, std::int32_t b, const Aabb& box_b) {
      if (box_a.overlaps(box_b)) join_stack_.emplace_back(a, b);
    };
    join_stack_.clear();
    for (std::size_t i = 0; i < nodes_.size(); ++i) {
      const Node& n = nodes_[i];
      if (n.height <= 0) continue;  // a leaf (0) or a free node (-1)
      push(n.child1, node(n.child1).box, n.child2, node(n.child2).box);
      while (!join_stack_.empty()) {
        const auto [x, y] = join_stack_.back();
        join_stack_.pop_back();
        const Node& nx = node(x);
        const Node& ny = node(y);  // overlaps nx (tested at the push)
        if (nx.is_leaf() && ny.is_leaf()) {
          const ProxyId a = nx.proxy(), b = ny.proxy();
          out.emplace_back(std::min(a, b), std::max(a, b));
        } else if (ny.is_leaf() || (!nx.is_leaf() && nx.height >= ny.height)) {
          push(nx.child2, node(nx.child2).box, y, ny.box);
          push(nx.child1, node(nx.child1).box, y, ny.box);
        } else {
          push(x, nx.box, ny.child2, node(ny.child2).box);
          push(x, nx.box, ny.child1, node(ny.child1).box);
        }
      }
    }
  }

  /// Places the pending moves in the tree. Reinserting a leaf costs a descent, an
  /// insertion and a refit to the root (~2 us at 10,000 leaves); a top-down rebuild of
  /// the whole tree costs about as much as reinserting an eighth of it, so when more
  /// leaves than that moved out of their boxes at once (bodies falling together leave
  /// their boxes in the same step) the tree is rebuilt instead, or only refitted
  /// where that keeps its quality (kRefitQuality). Measured: 10,000 spheres in free
  /// fall, 5.7 ms a step in the broadphase with reinsertions alone.
  void flush_pending() {
    int live = 0;
    for (const ProxyId id : pending_list_) live += pending_flag_[static_cast<std::size_t>(id)];
    if (live > 0 && live >= kRebuildMin && live * kRebuildFraction >= proxy_count()) {
      for (const ProxyId id : pending_list_) {
        const auto i = static_cast<std::size_t>(id);
        if (!pending_flag_[i]) continue;
        set_fat(leaf_[i], pending_box_[i]);
        pending_flag_[i] = 0;
      }
      reinsertions_ += live;
      if (root_ != kNull && refit_all() <= kRefitQuality * rebuilt_quality_) {
        ++refits_;
      } else {
        ++rebuilds_;
        rebuild();
        rebuilt_quality_ = refit_all();  // the fresh tree's ratio (its boxes are already these)
      }
    } else {
      for (const ProxyId id : pending_list_) {
        const auto i = static_cast<std::size_t>(id);
        if (!pending_flag_[i]) continue;
        const std::int32_t leaf = leaf_[i];
        remove_leaf(leaf);
        set_fat(leaf, pending_box_[i]);
        insert_leaf(leaf);
        pending_flag_[i] = 0;
        ++reinsertions_;
      }
    }
    pending_list_.clear();
  }

  /// Recomputes every internal node's box from its children (post-order, no change of
  /// structure or heights) and returns the tree's quality ratio: total surface area of
  /// the internal nodes over that of the leaves (the SAH cost per unit of leaf area;
  /// inf for a tree whose leaves have no area, so that it is rebuilt).
  Real refit_all() {
    Real internal = 0, leaves = 0;
    join_stack_.clear();  // (node, children done) as a post-order stack
    join_stack_.emplace_back(root_, 0);
    while (!join_stack_.empty()) {
      auto& [i, done] = join_stack_.back();
      Node& n = node(i);
      if (n.is_leaf()) {
        leaves += n.box.surface_area();
        join_stack_.pop_back();
      } else if (!done) {
        done = 1;
        const std::int32_t c1 = n.child1, c2 = n.child2;
        join_stack_.emplace_back(c2, 0);
        join_stack_.emplace_back(c1, 0);
      } else {
        n.box = Aabb::merge(node(n.child1).box, node(n.child2).box);
        internal += n.box.surface_area();
        join_stack_.pop_back();
      }
    }
    return leaves > 0 ? internal / leaves : kInf;
  }

  /// Rebuilds the tree top down over the current leaves: median split on the widest
  /// axis of the leaf centres (ties by node index, so the result is deterministic).
  /// Balanced (height ceil(log2 n)); internal nodes are reused from the free list.
  /// The splits work on a packed copy of the leaves' doubled centres (min + max, exact),
  /// not through the 64-byte nodes: contiguous, where the nodes are scattered (measured:
  /// 10,000 falling spheres, which all leave their fat boxes every ~4 steps, find_pairs
  /// 940 -> 818 us a step on average, 4.4 -> 3.8 ms at the 90th percentile); the same
  /// comparisons, so the same tree.
  void rebuild() {
    build_leaves_.clear();
    for (ProxyId id = 0; id < id_capacity(); ++id)
      if (is_live(id)) {
        const std::int32_t leaf = leaf_[static_cast<std::size_t>(id)];
        const Aabb& b = node(leaf).box;
        build_leaves_.push_back(BuildLeaf{b.min + b.max, leaf});
      }
    for (std::size_t i = 0; i < nodes_.size(); ++i)
      if (nodes_[i].height > 0) free_node(static_cast<std::int32_t>(i));
    root_ = build_leaves_.empty() ? kNull : build(0, static_cast<int>(build_leaves_.size()));
    if (root_ != kNull) node(root_).parent = kNull;
  }

  /// Sorts pairs of non-negative ids lexicographically: an LSD radix sort on the key
  /// first * 2^b + second (b: bits of the largest id, which is a `second`: every pair
  /// has first < second), 11 bits a pass (ids below
  /// 16,384: three passes over 2048 buckets). The same order as std::sort, several
  /// times faster on the tens of thousands of candidates a mass move produces.
  void sort_pairs(std::vector<ProxyPair>& v) {
    if (v.size() < 1024) {
      std::sort(v.begin(), v.end());
      return;
    }
    std::uint32_t max_id = 0;
    for (const ProxyPair& p : v) max_id = std::max(max_id, static_cast<std::uint32_t>(p.second));
    int b = 1;
    while (b < 32 && (max_id >> b) != 0) ++b;
    auto key = [b](const ProxyPair& p) {
      return (static_cast<std::uint64_t>(static_cast<std::uint32_t>(p.first)) << b) |
             static_cast<std::uint32_t>(p.second);
    };
    constexpr int kDigit = 11;
    constexpr std::uint64_t kMask = (1u << kDigit) - 1;
    radix_scratch_.resize(v.size());
    std::vector<ProxyPair>* src = &v;
    std::vector<ProxyPair>* dst = &radix_scratch_;
    std::array<std::uint32_t, 1u << kDigit> count;
    for (int shift = 0; shift < 2 * b; shift += kDigit) {
      count.fill(0);
      for (const ProxyPair& p : *src) ++count[(key(p) >> shift) & kMask];
      std::uint32_t sum = 0;
      for (std::uint32_t& c : count) {
        const std::uint32_t k = c;
        c = sum;
        sum += k;
      }
      for (const ProxyPair& p : *src) (*dst)[count[(key(p) >> shift) & kMask]++] = p;
      std::swap(src, dst);
    }
    if (src != &v) v.swap(*src);
  }

  std::int32_t build(int begin, int count) {
    BuildLeaf* first = build_leaves_.data() + begin;
    if (count == 1) return first[0].leaf;
    Vec3 lo = Vec3::Constant(kInf), hi = Vec3::Constant(-kInf);
    for (int k = 0; k < count; ++k) {
      lo = lo.cwiseMin(first[k].center2);
      hi = hi.cwiseMax(first[k].center2);
    }
    int axis = 0;
    (hi - lo).maxCoeff(&axis);
    const int half = count / 2;
    std::nth_element(first, first + half, first + count, [axis](const BuildLeaf& x, const BuildLeaf& y) {
      const Real cx = x.center2[axis], cy = y.center2[axis];
      return cx < cy || (cx == cy && x.leaf < y.leaf);
    });
    const std::int32_t left = build(begin, half);
    const std::int32_t right = build(begin + half, count - half);
    const std::int32_t p = allocate_node();  // from the freed internal nodes: no reallocation
    Node& n = node(p);
    n.child1 = left;
    n.child2 = right;
    n.height = 1 + std::max(node(left).height, node(right).height);
    n.box = Aabb::merge(node(left).box, node(right).box);
    node(left).parent = p;
    node(right).parent = p;
    return p;
  }

  std::int32_t allocate_node() {
    if (free_list_ == kNull) {
      nodes_.emplace_back();
      return static_cast<std::int32_t>(nodes_.size() - 1);
    }
    const std::int32_t i = free_list_;
    free_list_ = node(i).parent;
    --free_count_;
    node(i) = Node{};
    return i;
  }

  void free_node(std::int32_t i) {
    Node& n = node(i);
    n = Node{};
    n.parent = free_list_;
    free_list_ = i;
    ++free_count_;
  }

  /// Visits every leaf whose fat box overlaps `box`; stops when f returns false.
  template <class F>
  void query_fat(const Aabb& box, F&& f) const {
    if (root_ == kNull) return;
    TraversalStack stack;
    stack.push(root_);
    while (!stack.empty()) {
      const Node& n = nodes_[static_cast<std::size_t>(stack.pop())];
      if (!n.box.overlaps(box)) continue;
      if (n.is_leaf()) {
        if (!f(static_cast<std::int32_t>(&n - nodes_.data()))) return;
      } else {
        stack.push(n.child1);
        stack.push(n.child2);
      }
    }
  }

  /// Branch and bound for the sibling minimising the SAH cost increase (Bittner et al.
  /// 2012, 3.1). Making node S the sibling of leaf L costs the area of the new parent,
  /// SA(S u L), plus the growth of every ancestor A of S, SA(A u L) - SA(A) (the
  /// "inherited" cost). Descending below S adds at least SA(L) to S's inherited cost,
  /// so a subtree is skipped once SA(L) + inherited >= best cost. Nodes are expanded in
  /// order of inherited cost (a min-heap), so the first node whose bound fails ends
  /// the search.
  std::int32_t find_best_sibling(const Aabb& leaf_box) {
    const Real leaf_area = leaf_box.surface_area();
    std::int32_t best = root_;
    Real best_cost = kInf;
    heap_.clear();
    heap_.push_back({0.0, root_});
    // Min-heap on (inherited cost, node index): the index breaks ties deterministically.
    auto greater = [](const HeapItem& a, const HeapItem& b) {
      return a.inherited > b.inherited || (a.inherited == b.inherited && a.node > b.node);
    };
    while (!heap_.empty()) {
      std::pop_heap(heap_.begin(), heap_.end(), greater);
      const HeapItem item = heap_.back();
      heap_.pop_back();
      if (leaf_area + item.inherited >= best_cost) break;  // nothing left can do better
      const Node& n = node(item.node);
      const Real direct = Aabb::merge(n.box, leaf_box).surface_area();
      const Real cost = direct + item.inherited;
      if (cost < best_cost) {
        best_cost = cost;
        best = item.node;
      }
      if (n.is_leaf()) continue;
      const Real child_inherited = cost - n.box.surface_area();
      if (leaf_area + child_inherited < best_cost) {
        heap_.push_back({child_inherited, n.child1});
        std::push_heap(heap_.begin(), heap_.end(), greater);
        heap_.push_back({child_inherited, n.child2});
        std::push_heap(heap_.begin(), heap_.end(), greater);
      }
    }
    return best;
  }

  void insert_leaf(std::int32_t leaf) {
    if (root_ == kNull) {
      root_ = leaf;
      node(leaf).parent = kNull;
      return;
    }
    const Aabb leaf_box = node(leaf).box;
    const std::int32_t sibling = find_best_sibling(leaf_box);
    const std::int32_t old_parent = node(sibling).parent;
    const std::int32_t parent = allocate_node();  // may reallocate nodes_: no references held
    Node& p = node(parent);
    p.parent = old_parent;
    p.child1 = sibling;
    p.child2 = leaf;
    p.box = Aabb::merge(node(sibling).box, leaf_box);
    p.height = node(sibling).height + 1;
    if (old_parent == kNull) {
      root_ = parent;
    } else {
      Node& op = node(old_parent);
      (op.child1 == sibling ? op.child1 : op.child2) = parent;
    }
    node(sibling).parent = parent;
    node(leaf).parent = parent;
    refit_to_root(parent);
  }

  void remove_leaf(std::int32_t leaf) {
    if (leaf == root_) {
      root_ = kNull;
      return;
    }
    const std::int32_t parent = node(leaf).parent;
    const std::int32_t grand = node(parent).parent;
    const std::int32_t sibling = node(parent).child1 == leaf ? node(parent).child2 : node(parent).child1;
    node(sibling).parent = grand;
    if (grand == kNull) {
      root_ = sibling;
    } else {
      Node& g = node(grand);
      (g.child1 == parent ? g.child1 : g.child2) = sibling;
    }
    free_node(parent);
    node(leaf).parent = kNull;
    if (grand != kNull) refit_to_root(grand);
  }

  /// Rebalances, then recomputes height and box, of every node from `i` to the root.
  void refit_to_root(std::int32_t i) {
    while (i != kNull) {
      i = balance(i);
      Node& n = node(i);
      const Node& c1 = node(n.child1);
      const Node& c2 = node(n.child2);
      n.height = 1 + std::max(c1.height, c2.height);
      n.box = Aabb::merge(c1.box, c2.box);
      i = n.parent;
    }
  }

  /// If the children of internal node `a` differ in height by more than one, lifts the
  /// taller child into a's place (a single AVL rotation): the taller child c keeps its
  /// taller child and takes `a` as its other child; `a` takes c's shorter child. Returns
  /// the node now at a's place. Heights and boxes of `a` and `c` are recomputed here;
  /// the caller refits the new subtree root.
  std::int32_t balance(std::int32_t a) {
    Node& na = node(a);
    if (na.is_leaf() || na.height < 2) return a;
    const std::int32_t b = na.child1, c = na.child2;
    const int imbalance = node(c).height - node(b).height;
    if (imbalance > 1) return rotate_up(a, c, /*a_slot_of_child=*/2);
    if (imbalance < -1) return rotate_up(a, b, /*a_slot_of_child=*/1);
    return a;
  }

  // Lifts child `c` (in a's child slot `slot`) above `a`.
  std::int32_t rotate_up(std::int32_t a, std::int32_t c, int slot) {
    Node& na = node(a);
    Node& nc = node(c);
    const std::int32_t f = nc.child1, g = nc.child2;
    const std::int32_t up = a;  // stays a child of c
    // c takes a's place under a's parent.
    nc.parent = na.parent;
    if (na.parent == kNull) {
      root_ = c;
    } else {
      Node& pp = node(na.parent);
      (pp.child1 == a ? pp.child1 : pp.child2) = c;
    }
    na.parent = c;
    // c keeps its taller child; the shorter one replaces c under a.
    const bool f_taller = node(f).height > node(g).height;
    const std::int32_t keep = f_taller ? f : g;
    const std::int32_t give = f_taller ? g : f;
    nc.child1 = up;
    nc.child2 = keep;
    (slot == 2 ? na.child2 : na.child1) = give;
    node(give).parent = a;
    const Node& a1 = node(na.child1);
    const Node& a2 = node(na.child2);
    na.height = 1 + std::max(a1.height, a2.height);
    na.box = Aabb::merge(a1.box, a2.box);
    nc.height = 1 + std::max(na.height, node(keep).height);
    nc.box = Aabb::merge(na.box, node(keep).box);
    return c;
  }

  struct HeapItem {
    Real inherited;
    std::int32_t node;
  };

  BroadphaseSettings settings_;
  std::vector<Node> nodes_;
  std::int32_t root_ = kNull;
  std::int32_t free_list_ = kNull;
  int free_count_ = 0;
  std::vector<std::int32_t> leaf_;       // by proxy id: its leaf node
  std::vector<std::uint8_t> changed_;    // by proxy id: fat box changed since update()
  std::vector<ProxyId> changed_list_;    // the ids with changed_ set
  std::vector<ProxyPair> candidates_;    // sorted: pairs whose fat boxes overlap
  std::vector<ProxyPair> fresh_;         // scratch for on_update
  std::vector<ProxyPair> merged_;        // scratch for on_update
  std::vector<HeapItem> heap_;           // scratch for find_best_sibling
  std::int64_t reinsertions_ = 0;
  std::int64_t rebuilds_ = 0;
  std::int64_t refits_ = 0;
  Real rebuilt_quality_ = 0;  // refit_all's ratio right after the last rebuild (0: none yet)
  std::vector<std::uint8_t> pending_flag_;  // by proxy id: moved out of its fat box, not yet placed
  std::vector<Aabb> pending_box_;           // by proxy id: its new fat box while pending
  std::vector<ProxyId> pending_list_;       // ids flagged (possibly destroyed since: flag cleared)
  /// A leaf as rebuild sorts it: its fat box's min + max (twice the centre) and node.
  struct BuildLeaf {
    Vec3 center2;
    std::int32_t leaf;
  };
  std::vector<BuildLeaf> build_leaves_;  // scratch for rebuild
  std::vector<ProxyPair> radix_scratch_;    // scratch for sort_pairs
  std::vector<std::pair<std::int32_t, std::int32_t>> join_stack_;  // scratch for self_join, refit_all
};

}  // namespace

namespace detail {
std::unique_ptr<Broadphase> make_aabb_tree_broadphase(const BroadphaseSettings& settings) {
  return std::make_unique<AabbTreeBroadphase>(settings);
}
}  // namespace detail

}  // namespace wmo
