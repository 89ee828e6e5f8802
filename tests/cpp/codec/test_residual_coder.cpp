// The residual table coder (wmo/codec/residual_coder.h): exact round trips on tables
// from all zeros to the largest magnitudes, a size that follows the values' entropy,
// and refusal (never a crash or a read outside the buffer) of truncated, padded and
// random streams.
#include <gtest/gtest.h>

#include <cmath>
#include <cstdint>
#include <random>
#include <string>
#include <vector>

#include "wmo/codec/residual_coder.h"
#include "wmo/math.h"

namespace {

using wmo::codec::decode_residuals;
using wmo::codec::encode_residuals;
using wmo::codec::ResidualLayout;

std::vector<std::int64_t> round_trip(const std::vector<std::int64_t>& values,
                                     const std::vector<std::int64_t>* motion,
                                     const ResidualLayout& layout, std::size_t* size = nullptr,
                                     const std::vector<std::int64_t>* previous = nullptr) {
  const std::int64_t* m = motion ? motion->data() : nullptr;
  const std::int64_t* p = previous ? previous->data() : nullptr;
  const auto bytes = encode_residuals(values.data(), m, p, layout);
  if (size) *size = bytes.size();
  std::vector<std::int64_t> out(values.size(), 12345);
  std::string why;
  EXPECT_TRUE(decode_residuals(bytes.data(), bytes.size(), m, p, layout, out.data(), &why)) << why;
  return out;
}

// Coded size with the side tables given, over the size without them.
double size_ratio(const std::vector<std::int64_t>& values, const std::vector<std::int64_t>* motion,
                  const std::vector<std::int64_t>* previous, const ResidualLayout& layout) {
  std::size_t with = 0, without = 0;
  round_trip(values, motion, layout, &with, previous);
  round_trip(values, nullptr, layout, &without);
  return static_cast<double>(with) / static_cast<double>(without);
}

// Laplacian-like residuals of scale `scale`: the shape of predicted snapshot residuals.
std::vector<std::int64_t> laplace(std::size_t n, double scale, std::mt19937_64& rng) {
  std::exponential_distribution<double> mag(1.0 / scale);
  std::bernoulli_distribution negative(0.5);
  std::vector<std::int64_t> v(n);
  for (auto& x : v) {
    const auto m = static_cast<std::int64_t>(std::floor(mag(rng)));
    x = negative(rng) ? -m : m;
  }
  return v;
}

TEST(ResidualCoder, RoundTripsTablesOfEveryScale) {
  std::mt19937_64 rng(7);
  for (double scale : {0.0, 0.3, 2.0, 40.0, 1e5, 1e12}) {
    for (int columns : {1, 3, 7}) {
      const ResidualLayout layout{257, columns, columns == 7 ? 0b10001u : 1u};
      const auto values = laplace(static_cast<std::size_t>(257 * columns), scale, rng);
      const auto motion = laplace(values.size(), scale, rng);
      const auto previous = laplace(values.size(), scale, rng);
      EXPECT_EQ(round_trip(values, &motion, layout), values) << "scale " << scale << ", columns " << columns;
      EXPECT_EQ(round_trip(values, nullptr, layout), values) << "scale " << scale << " without motion";
      EXPECT_EQ(round_trip(values, &motion, layout, nullptr, &previous), values) << "scale " << scale;
    }
  }
}

TEST(ResidualCoder, RoundTripsTheExtremes) {
  const std::int64_t top = wmo::codec::kMaxResidual - 1;
  const std::vector<std::int64_t> values{top, -top, 1, -1, 0, top / 3, -(top / 5), 2, -2, 3, 1 << 20, -(1 << 19)};
  const std::vector<std::int64_t> motion{INT64_MIN, INT64_MAX, 0, 0, -1, 1, 7, 0, 0, 0, 0, 0};
  EXPECT_EQ(round_trip(values, &motion, {6, 2, 1u}), values);
  EXPECT_EQ(round_trip(values, &motion, {6, 2, 1u}, nullptr, &motion), values);
  // No rows: an empty table decodes from its (short) stream and nothing else.
  EXPECT_TRUE(round_trip({}, nullptr, {0, 7, 1u}).empty());
}

TEST(ResidualCoder, SizeFollowsTheEntropy) {
  std::mt19937_64 rng(11);
  std::size_t zeros = 0, small = 0, large = 0;
  const ResidualLayout layout{3000, 7, 0b10001u};
  round_trip(std::vector<std::int64_t>(21000, 0), nullptr, layout, &zeros);
  round_trip(laplace(21000, 1.0, rng), nullptr, layout, &small);
  round_trip(laplace(21000, 1000.0, rng), nullptr, layout, &large);
  // 21,000 zeros cost a few bits of learning per context, not a bit each.
  EXPECT_LT(zeros, 64u);
  // A geometric distribution of mean 1 has about 2 bits of entropy for the magnitude
  // (plus a sign bit for the nonzero half): within 15 % of it, at most 2.6 bits a value.
  EXPECT_LT(small * 8.0 / 21000.0, 2.6 * 1.15);
  // Scale 1000: about log2(e * 1000) + 1 = 12.4 bits a value; the coder stays within 5 %.
  EXPECT_LT(large * 8.0 / 21000.0, 12.4 * 1.05);
  EXPECT_GT(large, small);
}

TEST(ResidualCoder, MotionContextsShrinkCorrelatedTables) {
  // Residuals whose size follows the motion side information: a coder using the
  // motion as context beats one without it.
  std::mt19937_64 rng(3);
  const ResidualLayout layout{4000, 1, 1u};
  std::vector<std::int64_t> values(4000), motion(4000);
  std::uniform_int_distribution<int> moving(0, 1);
  for (std::size_t i = 0; i < values.size(); ++i) {
    const bool m = moving(rng) == 1;
    motion[i] = m ? 5000 : 0;
    values[i] = m ? laplace(1, 200.0, rng)[0] : 0;
  }
  EXPECT_LT(size_ratio(values, &motion, nullptr, layout), 0.95);
}

TEST(ResidualCoder, PreviousResidualsShrinkPersistentTables) {
  // A table that repeats the previous one's signs and sizes (a body's acceleration
  // persisting from frame to frame): coding it with `previous` beats coding it without.
  std::mt19937_64 rng(4);
  const ResidualLayout layout{4000, 1, 1u};
  const auto previous = laplace(4000, 50.0, rng);
  std::vector<std::int64_t> values(previous);
  for (auto& v : values) v += laplace(1, 2.0, rng)[0];
  EXPECT_LT(size_ratio(values, nullptr, &previous, layout), 0.95);
}

TEST(ResidualCoder, RefusesTruncatedAndPaddedStreams) {
  std::mt19937_64 rng(5);
  const ResidualLayout layout{500, 7, 0b10001u};
  const auto values = laplace(3500, 30.0, rng);
  auto bytes = encode_residuals(values.data(), nullptr, nullptr, layout);
  std::vector<std::int64_t> out(values.size());
  std::string why;
  ASSERT_TRUE(decode_residuals(bytes.data(), bytes.size(), nullptr, nullptr, layout, out.data(), &why)) << why;
  EXPECT_FALSE(decode_residuals(bytes.data(), bytes.size() - 1, nullptr, nullptr, layout, out.data(), &why));
  EXPECT_NE(why.find("truncated"), std::string::npos) << why;
  bytes.push_back(0);
  EXPECT_FALSE(decode_residuals(bytes.data(), bytes.size(), nullptr, nullptr, layout, out.data(), &why));
  EXPECT_NE(why.find("after the table"), std::string::npos) << why;
}

TEST(ResidualCoder, RandomBytesNeverCrash) {
  // Garbage decodes to some table or is refused; it never reads outside its buffer
  // (run under the address sanitizer in a debug build to see that) and always ends.
  std::mt19937_64 rng(9);
  const ResidualLayout layout{300, 7, 0b10001u};
  std::vector<std::int64_t> out(2100);
  int refused = 0;
  for (int trial = 0; trial < 300; ++trial) {
    std::vector<std::uint8_t> bytes(static_cast<std::size_t>(rng() % 4000));
    for (auto& b : bytes) b = static_cast<std::uint8_t>(rng());
    std::string why;
    if (!decode_residuals(bytes.data(), bytes.size(), nullptr, nullptr, layout, out.data(), &why)) ++refused;
    else
      for (auto v : out) ASSERT_LT(std::abs(v), wmo::codec::kMaxResidual);
  }
  EXPECT_GT(refused, 250);  // random lengths almost never match the table exactly
}

TEST(ResidualCoder, BadInputThrowsNamingTheValue) {
  const std::vector<std::int64_t> values{0, wmo::codec::kMaxResidual};
  try {
    encode_residuals(values.data(), nullptr, nullptr, {1, 2, 1u});
    FAIL() << "no throw";
  } catch (const wmo::InvalidArgument& e) {
    EXPECT_NE(std::string(e.what()).find("column 1"), std::string::npos) << e.what();
  }
  EXPECT_THROW(encode_residuals(values.data(), nullptr, nullptr, {1, 0, 1u}), wmo::InvalidArgument);
  EXPECT_THROW(encode_residuals(values.data(), nullptr, nullptr, {-1, 2, 1u}), wmo::InvalidArgument);
}

}  // namespace
