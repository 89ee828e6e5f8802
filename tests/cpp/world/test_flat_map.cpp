// FlatMap (the contact cache's table) against std::unordered_map under random inserts,
// lookups and erasures, through several rehashes.
#include <gtest/gtest.h>

#include <random>
#include <unordered_map>

#include "wmo/world/flat_map.h"

using namespace wmo;

TEST(FlatMap, AgreesWithUnorderedMapUnderRandomOperations) {
  std::mt19937_64 rng(5);
  FlatMap<int> map;
  std::unordered_map<std::uint64_t, int> ref;
  // Keys shaped like manifold keys (two slots in the high bits) and plain small ones,
  // from a small pool so that inserts hit existing keys and erasures find them.
  std::vector<std::uint64_t> pool;
  for (std::uint64_t a = 0; a < 40; ++a)
    for (std::uint64_t b = 0; b < 40; ++b) pool.push_back((a << 40) | (b << 16) | 0xFFFF);
  for (std::uint64_t k = 0; k < 400; ++k) pool.push_back(k);
  std::uniform_int_distribution<std::size_t> pick(0, pool.size() - 1);
  for (int round = 0; round < 40; ++round) {
    for (int i = 0; i < 500; ++i) {
      const std::uint64_t key = pool[pick(rng)];
      const int idx = map.insert(key);
      auto [it, fresh] = ref.try_emplace(key, 0);
      EXPECT_EQ(map.value(idx), it->second);  // value-initialised when fresh
      map.value(idx) = it->second = static_cast<int>(rng() % 1000) + 1;
      EXPECT_EQ(map.key(idx), key);
    }
    ASSERT_EQ(map.size(), ref.size());
    for (std::size_t k = 0; k < pool.size(); ++k) {
      const int idx = map.find(pool[k]);
      const auto it = ref.find(pool[k]);
      ASSERT_EQ(idx >= 0, it != ref.end());
      if (idx >= 0) EXPECT_EQ(map.value(idx), it->second);
    }
    // Erase about a third (values divisible by 3), as the cache drops stale entries.
    map.erase_if([](std::uint64_t, int v) { return v % 3 == 0; });
    std::erase_if(ref, [](const auto& e) { return e.second % 3 == 0; });
    ASSERT_EQ(map.size(), ref.size());
    for (const auto& [key, v] : ref) {
      const int idx = map.find(key);
      ASSERT_GE(idx, 0);
      EXPECT_EQ(map.value(idx), v);
    }
  }
  map.clear();
  EXPECT_EQ(map.size(), 0u);
  EXPECT_EQ(map.find(pool[0]), -1);
}

TEST(FlatMap, ManifoldKeysAreExact) {
  // Keys that differ only in the children's high bits (triangles 256 and 65,536 apart,
  // a child index of -1) are distinct entries: the cache once kept 8 bits per child.
  FlatMap<int, ManifoldKey> map;
  const std::uint64_t pair = (std::uint64_t{3} << 32) | 7;
  const std::int32_t children[][2] = {{0, -1}, {256, -1}, {65536, -1}, {-1, -1}, {-1, 0}, {-1, 256}, {1, 2}, {257, 2}};
  for (int k = 0; k < 8; ++k) {
    const ManifoldKey key{pair, (std::uint64_t{static_cast<std::uint32_t>(children[k][0])} << 32) |
                                    static_cast<std::uint32_t>(children[k][1])};
    EXPECT_LT(map.find(key), 0) << k;
    map.value(map.insert(key)) = k;
  }
  EXPECT_EQ(map.size(), 8u);
  for (int k = 0; k < 8; ++k) {
    const ManifoldKey key{pair, (std::uint64_t{static_cast<std::uint32_t>(children[k][0])} << 32) |
                                    static_cast<std::uint32_t>(children[k][1])};
    ASSERT_GE(map.find(key), 0);
    EXPECT_EQ(map.value(map.find(key)), k);
  }
  // Another pair with the same children is another entry.
  EXPECT_LT(map.find(ManifoldKey{pair + 1, 0}), 0);
}
