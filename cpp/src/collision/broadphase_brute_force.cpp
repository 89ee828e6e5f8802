// Brute-force broadphase: every pair of live proxies is tested, O(n^2) per query. It is
// the reference the sweep-and-prune and tree broadphases are checked against, so it is
// kept obviously correct: ids ascending in the outer and inner loops give the sorted
// output directly.
#include <vector>

#include "broadphase_internal.h"

namespace wmo {
namespace {

class BruteForceBroadphase final : public Broadphase {
 public:
  BroadphaseType type() const override { return BroadphaseType::kBruteForce; }

 protected:
  void on_create(ProxyId) override {}
  void on_destroy(ProxyId) override {}
  void on_move(ProxyId, const Vec3&) override {}
  void on_update() override {}

  void on_query_pairs(std::vector<ProxyPair>& out) override {
    // Copy the live boxes into one contiguous array first so the O(n^2) loop streams
    // through memory and skips dead ids once. The buffers keep their capacity.
    ids_.clear();
    boxes_.clear();
    const ProxyId n = id_capacity();
    for (ProxyId id = 0; id < n; ++id) {
      if (!is_live(id)) continue;
      const Aabb& b = tight(id);
      ids_.push_back(id);
      boxes_.push_back({b.min.x(), b.min.y(), b.min.z(), b.max.x(), b.max.y(), b.max.z()});
    }
    const std::size_t m = ids_.size();
    for (std::size_t i = 0; i < m; ++i) {
      const Flat a = boxes_[i];
      for (std::size_t j = i + 1; j < m; ++j) {
        const Flat& b = boxes_[j];
        // Closed intervals: touching boxes overlap (same test as Aabb::overlaps).
        if (a.lo[0] <= b.hi[0] && b.lo[0] <= a.hi[0] && a.lo[1] <= b.hi[1] && b.lo[1] <= a.hi[1] &&
            a.lo[2] <= b.hi[2] && b.lo[2] <= a.hi[2]) {
          out.emplace_back(ids_[i], ids_[j]);
        }
      }
    }
  }

 private:
  struct Flat {
    Real lo[3];
    Real hi[3];
  };
  std::vector<ProxyId> ids_;
  std::vector<Flat> boxes_;
};

}  // namespace

namespace detail {
std::unique_ptr<Broadphase> make_brute_force_broadphase() {
  return std::make_unique<BruteForceBroadphase>();
}
}  // namespace detail

}  // namespace wmo
