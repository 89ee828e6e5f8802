// Sweep-and-prune broadphase ("sort and sweep"): Baraff 1992 (dissertation, 5.1) and
// Cohen et al. 1995 (I-COLLIDE) kept the endpoint lists of all three axes sorted across
// frames; this version keeps one array of boxes sorted by their lower bound on ONE axis,
// the axis of greatest spread, as in Ericson, "Real-Time Collision Detection", 7.5.2
// and Terdiman's "Sweep-and-prune" (2007) single-axis box pruning.
//
// Per update():
//   1. one pass drops destroyed proxies, copies the current tight boxes into the array
//      (boxes stay stored in the array so the sweep reads memory sequentially) and sums
//      the centre statistics for the axis choice;
//   2. the array is re-sorted by insertion sort: bodies move little between frames, so
//      the array is nearly sorted and this costs O(n + swaps) (temporal coherence). If
//      the swaps exceed a budget (many new proxies, an axis switch, a teleport) it falls
//      back to std::sort, so one update never costs more than O(n log n) plus O(n);
//   3. query_pairs sweeps: box i is tested against the boxes after it whose lower bound
//      on the sweep axis is <= its upper bound, and on the other two axes directly.
//
// Axis rule: the sweep axis is the one with the largest variance of box centres (the
// boxes overlap least in projection along it). The axis is re-chosen at every update
// but only switched when another axis's variance exceeds the current one's by
// kAxisSwitchRatio, so near-equal spreads cannot make it flip back and forth (each
// switch costs a full sort).
#include <algorithm>
#include <stdexcept>
#include <vector>

#include "broadphase_internal.h"

namespace wmo {
namespace {

/// Switch the sweep axis only when another axis's centre variance is this many times the
/// current one's. 1.5 is hysteresis: a pile spreading slowly does not flip axes every
/// frame, yet a scene whose spread has really changed (e.g. a row of bodies rotated
/// from x to z) switches while the old axis still has 2/3 of the new spread at most.
constexpr Real kAxisSwitchRatio = 1.5;

class SweepAndPruneBroadphase final : public Broadphase {
 public:
  BroadphaseType type() const override { return BroadphaseType::kSweepAndPrune; }

  BroadphaseStats stats() const override {
    BroadphaseStats s = Broadphase::stats();
    s.sweep_axis = axis_;
    s.axis_changes = axis_changes_;
    return s;
  }

  void validate() const override {
    Broadphase::validate();
    if (static_cast<int>(entries_.size()) != proxy_count())
      throw std::logic_error("sap: entry count differs from the live proxy count");
    for (std::size_t i = 0; i < entries_.size(); ++i) {
      const Entry& e = entries_[i];
      if (!is_live(e.id)) throw std::logic_error("sap: entry of a dead proxy");
      const Aabb& b = tight(e.id);
      for (int k = 0; k < 3; ++k) {
        const int axis = perm_[k];
        if (e.lo[k] != b.min[axis] || e.hi[k] != b.max[axis])
          throw std::logic_error("sap: stored box differs from the tight box");
      }
      if (i > 0 && less(e, entries_[i - 1])) throw std::logic_error("sap: array not sorted");
    }
  }

 protected:
  void on_create(ProxyId id) override {
    const auto i = static_cast<std::size_t>(id);
    if (i >= in_array_.size()) in_array_.resize(i + 1, 0);
    // An id destroyed and re-created before update() still has its entry: reuse it.
    if (in_array_[i]) return;
    in_array_[i] = 1;
    Entry e;
    e.id = id;
    entries_.push_back(e);  // box filled and sorted in on_update()
  }
  void on_destroy(ProxyId) override {}  // the entry is dropped at the next update()
  void on_move(ProxyId, const Vec3&) override {}

  void on_update() override {
    // Pass 1: compact, refresh boxes in the current axis order, centre statistics.
    // Sums are taken relative to the first centre so that boxes 1e4 m from the origin
    // do not lose the variance to cancellation.
    Vec3 shift = Vec3::Zero();
    bool have_shift = false;
    Vec3 sum = Vec3::Zero(), sum_sq = Vec3::Zero();
    std::size_t w = 0;
    for (std::size_t r = 0; r < entries_.size(); ++r) {
      const ProxyId id = entries_[r].id;
      if (!is_live(id)) {
        in_array_[static_cast<std::size_t>(id)] = 0;
        continue;
      }
      const Aabb& b = tight(id);
      const Vec3 c = b.center();
      if (!have_shift) {
        shift = c;
        have_shift = true;
      }
      const Vec3 d = c - shift;
      sum += d;
      sum_sq += d.cwiseProduct(d);
      Entry& e = entries_[w++];
      e.id = id;
      store(e, b);
    }
    entries_.resize(w);
    if (w == 0) return;

    // Axis choice (rule in the file comment).
    const Real n = static_cast<Real>(w);
    const Vec3 var = sum_sq / n - (sum / n).cwiseProduct(sum / n);
    int best = 0;
    for (int k = 1; k < 3; ++k)
      if (var[k] > var[best]) best = k;
    if (axis_ < 0 || var[best] > kAxisSwitchRatio * var[axis_]) {
      if (axis_ >= 0 && best != axis_) ++axis_changes_;
      if (best != axis_) {
        set_axis(best);
        for (Entry& e : entries_) store(e, tight(e.id));
        sort_all();
        return;
      }
    }

    // Insertion sort with a work budget. 8 shifts per entry is far more than a frame of
    // small motions needs (a box passes a handful of neighbours at most), and small
    // enough that a hopeless case wastes only O(n) before std::sort takes over.
    std::int64_t budget = 8 * static_cast<std::int64_t>(w) + 256;
    for (std::size_t i = 1; i < w; ++i) {
      if (!less(entries_[i], entries_[i - 1])) continue;
      const Entry e = entries_[i];
      std::size_t j = i;
      while (j > 0 && less(e, entries_[j - 1])) {
        entries_[j] = entries_[j - 1];
        --j;
        if (--budget < 0) break;
      }
      entries_[j] = e;
      if (budget < 0) {
        sort_all();
        return;
      }
    }
  }

  void on_query_pairs(std::vector<ProxyPair>& out) override {
    // Split the sorted array into the sweep-axis lower bounds (scanned by the inner loop
    // until it passes a.hi) and the other two axes (read only for boxes that pass):
    // fewer cache lines per tested box than the 56-byte entries.
    const std::size_t m = entries_.size();
    sweep_lo_.resize(m);
    cross_.resize(m);
    for (std::size_t i = 0; i < m; ++i) {
      const Entry& e = entries_[i];
      sweep_lo_[i] = e.lo[0];
      cross_[i] = Cross{e.lo[1], e.hi[1], e.lo[2], e.hi[2]};
    }
    const Real* lo0 = sweep_lo_.data();
    const Cross* c = cross_.data();
    for (std::size_t i = 0; i < m; ++i) {
      const Real a_hi = entries_[i].hi[0];
      const Cross a = c[i];
      // Sorted by lo[0], so every later box has lo[0] >= a.lo[0]: the sweep-axis
      // intervals overlap exactly while b.lo[0] <= a.hi[0] (closed: touching counts).
      for (std::size_t j = i + 1; j < m && lo0[j] <= a_hi; ++j) {
        const Cross& b = c[j];
        // Non-short-circuit & : one well-predicted branch instead of four random ones.
        if ((a.lo1 <= b.hi1) & (b.lo1 <= a.hi1) & (a.lo2 <= b.hi2) & (b.lo2 <= a.hi2)) {
          const ProxyId ia = entries_[i].id, ib = entries_[j].id;
          out.emplace_back(std::min(ia, ib), std::max(ia, ib));
        }
      }
    }
    // The sweep finds each pair once but in array order; the interface promises a
    // deterministic lexicographic order.
    std::sort(out.begin(), out.end());
  }

 private:
  /// A box with its axes permuted so that index 0 is the sweep axis.
  struct Entry {
    Real lo[3];
    Real hi[3];
    ProxyId id;
  };

  static bool less(const Entry& a, const Entry& b) {
    // Ties broken by id so the array order is fully determined by the boxes.
    return a.lo[0] < b.lo[0] || (a.lo[0] == b.lo[0] && a.id < b.id);
  }

  void sort_all() {
    // A lambda rather than the function pointer lets std::sort inline the comparison.
    std::sort(entries_.begin(), entries_.end(), [](const Entry& a, const Entry& b) { return less(a, b); });
  }

  void set_axis(int axis) {
    axis_ = axis;
    perm_[0] = axis;
    perm_[1] = (axis + 1) % 3;
    perm_[2] = (axis + 2) % 3;
  }

  void store(Entry& e, const Aabb& b) const {
    for (int k = 0; k < 3; ++k) {
      e.lo[k] = b.min[perm_[k]];
      e.hi[k] = b.max[perm_[k]];
    }
  }

  /// The two non-sweep axes of a box, for the sweep's inner loop.
  struct Cross {
    Real lo1, hi1, lo2, hi2;
  };

  std::vector<Entry> entries_;          // sorted by less() after on_update()
  std::vector<Real> sweep_lo_;          // scratch for on_query_pairs: entries_[i].lo[0]
  std::vector<Cross> cross_;            // scratch for on_query_pairs
  std::vector<std::uint8_t> in_array_;  // by id: has an entry in entries_
  int axis_ = -1;
  int perm_[3] = {0, 1, 2};
  std::int64_t axis_changes_ = 0;
};

}  // namespace

namespace detail {
std::unique_ptr<Broadphase> make_sweep_and_prune_broadphase() {
  return std::make_unique<SweepAndPruneBroadphase>();
}
}  // namespace detail

}  // namespace wmo
