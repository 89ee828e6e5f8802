// WMO world layer: an open-addressing hash map from 64-bit (or ManifoldKey) keys to
// values, for the contact cache.
//
// The values live in one dense array (in insertion order, compacted by erase_if) and
// are reached by index; the table holds (key, index) pairs with linear probing at a
// load factor of at most 1/2. A lookup reads the table's contiguous slots and then one
// value, where std::unordered_map reads a bucket, then a node allocated somewhere in
// the heap: on the pyramid's 15,600 cached manifolds that difference was most of the
// narrowphase's cache time (node-based lookups missed the cache twice per pair).
// Indices stay valid until the next erase_if (inserting may move the values, so keep
// indices, not pointers).
#pragma once

#include <cstddef>
#include <cstdint>
#include <utility>
#include <vector>

namespace wmo {

/// The contact cache's key: a pair of body slots and the children of a composite pair
/// (triangle or compound child indices, -1 for none), exactly. (A single 64-bit key
/// kept 8 bits of each child index: triangles 256 apart in a mesh shared one cache
/// entry, and a box lying across two of them got each one's impulses from the other.)
struct ManifoldKey {
  std::uint64_t pair = 0;      ///< slot_a << 32 | slot_b
  std::uint64_t children = 0;  ///< uint32(child_a) << 32 | uint32(child_b)
  friend bool operator==(const ManifoldKey&, const ManifoldKey&) = default;
};

/// Fibonacci hashing: the high half of the product with an odd constant, where every
/// bit of the key has mixed in (the table masks it to its size).
inline std::size_t flat_map_hash(std::uint64_t key) { return static_cast<std::size_t>((key * 0x9E3779B97F4A7C15ull) >> 32); }
inline std::size_t flat_map_hash(const ManifoldKey& key) {
  return static_cast<std::size_t>(((key.pair * 0x9E3779B97F4A7C15ull) ^ (key.children * 0xC2B2AE3D27D4EB4Full)) >> 32);
}

template <class V, class K = std::uint64_t>
class FlatMap {
 public:
  /// Index of the value for `key`, or -1.
  int find(const K& key) const {
    if (slots_.empty()) return -1;
    for (std::size_t s = home(key);; s = (s + 1) & mask_) {
      const Slot& slot = slots_[s];
      if (slot.index < 0) return -1;
      if (slot.key == key) return slot.index;
    }
  }
  /// Index of the value for `key`, inserted (value-initialised) if absent.
  int insert(const K& key) {
    if (2 * (values_.size() + 1) > slots_.size()) rehash(slots_.empty() ? 64 : 2 * slots_.size());
    std::size_t s = home(key);
    for (;; s = (s + 1) & mask_) {
      if (slots_[s].index < 0) break;
      if (slots_[s].key == key) return slots_[s].index;
    }
    const int index = static_cast<int>(values_.size());
    slots_[s] = Slot{key, index};
    keys_.push_back(key);
    values_.emplace_back();
    return index;
  }
  /// Software prefetch for a lookup of `key` soon: its home slot, or (once that is in
  /// the cache) its value. A loop over keys whose order has nothing to do with the
  /// table's calls the first a few keys ahead and the second fewer, so neither load
  /// waits on memory (measured on the pyramid: the slot and value loads were 40% of
  /// the narrowphase's pair routine).
  void prefetch_slot(const K& key) const {
    if (!slots_.empty()) __builtin_prefetch(&slots_[home(key)]);
  }
  void prefetch_value(const K& key) const {
    const int i = find(key);
    if (i < 0) return;
    const char* p = reinterpret_cast<const char*>(&values_[i]);
    for (std::size_t off = 0; off < sizeof(V); off += 64) __builtin_prefetch(p + off);
  }
  V& value(int index) { return values_[index]; }
  const V& value(int index) const { return values_[index]; }
  const K& key(int index) const { return keys_[index]; }
  std::size_t size() const { return values_.size(); }
  bool empty() const { return values_.empty(); }
  void clear() {
    keys_.clear();
    values_.clear();
    for (Slot& s : slots_) s.index = -1;
  }
  /// Removes every entry for which pred(key, value) is true; the others keep their
  /// order. O(size + table size): the table is rebuilt.
  template <class Pred>
  void erase_if(Pred pred) {
    std::size_t kept = 0;
    for (std::size_t i = 0; i < values_.size(); ++i) {
      if (pred(keys_[i], values_[i])) continue;
      if (kept != i) {
        keys_[kept] = keys_[i];
        values_[kept] = std::move(values_[i]);
      }
      ++kept;
    }
    if (kept == values_.size()) return;
    keys_.resize(kept);
    values_.resize(kept);
    rehash(slots_.size());
  }

 private:
  struct Slot {
    K key{};
    int index = -1;  ///< into values_, -1 for an empty slot
  };
  std::size_t home(const K& key) const {
    // Hashed (flat_map_hash): the keys pack two body slots in their high bits, which a
    // plain mask would ignore.
    return flat_map_hash(key) & mask_;
  }
  void rehash(std::size_t capacity) {
    slots_.assign(capacity, Slot{});
    mask_ = capacity - 1;
    for (std::size_t i = 0; i < keys_.size(); ++i) {
      std::size_t s = home(keys_[i]);
      while (slots_[s].index >= 0) s = (s + 1) & mask_;
      slots_[s] = Slot{keys_[i], static_cast<int>(i)};
    }
  }

  std::vector<Slot> slots_;  ///< power-of-two size, at least twice the entries
  std::size_t mask_ = 0;
  std::vector<K> keys_;
  std::vector<V> values_;
};

}  // namespace wmo
