// Residual table coder: see wmo/codec/residual_coder.h for the format.
#include "wmo/codec/residual_coder.h"

#include <algorithm>
#include <bit>
#include <string>

#include "wmo/math.h"

namespace wmo::codec {
namespace {

// Class bits coded in unary before the escape: residuals of a few metres at 1/512 m
// have 11-12 bits, so 20 leaves the escape to the rare key-frame value.
constexpr int kUnaryClasses = 20;
constexpr int kEscapeBits = 6;  // k - kUnaryClasses <= 62 - 20 fits in 6 bits
constexpr int kMaxClass = 62;   // |v| < 2^62
constexpr int kActivity = 24;   // activity classes, see the header
constexpr int kPrevious = 4;    // classes of the previous residual: bit length 0, 1, 2, 3+
constexpr int kContexts = kActivity * kPrevious;  // per column
constexpr int kTopBits = 16;    // range normalisation threshold: 2^24

// An adaptive probability that the next bit is 0, in 1/65536, and how many updates it
// has had (its rate settles after four).
struct Prob {
  std::uint16_t p0 = 1u << 15;
  std::uint8_t updates = 0;
};

inline void adapt(Prob& prob, int bit) {
  const int shift = std::min<int>(1 + prob.updates, 4);
  if (prob.updates < 3) ++prob.updates;
  int p = prob.p0;
  if (bit) p -= p >> shift;
  else p += (65536 - p) >> shift;
  // Keep both outcomes codable: neither probability below 32/65536.
  prob.p0 = static_cast<std::uint16_t>(std::clamp(p, 32, 65536 - 32));
}

inline std::uint64_t magnitude(std::int64_t v) {
  return v < 0 ? std::uint64_t{0} - static_cast<std::uint64_t>(v) : static_cast<std::uint64_t>(v);
}

inline int bit_length(std::int64_t v) { return 64 - std::countl_zero(magnitude(v)); }

inline int sign_class(std::int64_t v) { return v > 0 ? 1 : (v < 0 ? 2 : 0); }

// The probabilities of one table, shared by encoder and decoder.
struct Model {
  explicit Model(int columns)
      : classes(static_cast<std::size_t>(columns) * kContexts * kUnaryClasses),
        signs(static_cast<std::size_t>(columns) * 27),
        tops(static_cast<std::size_t>(columns) * 64 * 2) {}
  std::vector<Prob> classes;  // [column][context][unary position]
  std::vector<Prob> signs;    // [column][sign of previous column][of previous row][of previous]
  std::vector<Prob> tops;     // [column][class][first or second bit below the leading one]
};

// Side tables both ends hold (either may be null: all zeros).
struct SideInfo {
  const std::int64_t* motion;
  const std::int64_t* previous;
};

// What both ends know before coding value (row, column): its class context and the
// signs that select its sign probability.
struct Context {
  int klass;
  int sign;
};

inline Context context_of(const std::int64_t* values, const SideInfo& side, const ResidualLayout& layout,
                          std::int64_t row, int column) {
  const std::int64_t at = row * layout.columns + column;
  const bool group_start = column == 0 || ((layout.group_starts >> column) & 1u);
  const std::int64_t previous_column = group_start ? 0 : values[at - 1];
  const std::int64_t previous_row = row > 0 ? values[at - layout.columns] : 0;
  const std::int64_t previous = side.previous ? side.previous[at] : 0;
  const int a = std::min(side.motion ? bit_length(side.motion[at]) : 0, 15);
  const int b = std::min(bit_length(previous_column), 15);
  const int n = std::min(bit_length(previous_row), 15);
  const int activity = std::min((a + 2 * b + n + 1) / 2, kActivity - 1);
  const int f = std::min(bit_length(previous), kPrevious - 1);
  return {(column * kActivity + activity) * kPrevious + f,
          ((column * 3 + sign_class(previous_column)) * 3 + sign_class(previous_row)) * 3 + sign_class(previous)};
}

class Encoder {
 public:
  void bit(Prob& prob, int bit) {
    const std::uint32_t bound = (range_ >> 16) * prob.p0;
    if (bit) {
      low_ += bound;
      range_ -= bound;
    } else {
      range_ = bound;
    }
    adapt(prob, bit);
    normalize();
  }
  // `count` (<= 32) plain bits of `value`, most significant first, at probability 1/2.
  void plain(std::uint64_t value, int count) {
    for (int i = count - 1; i >= 0; --i) {
      range_ >>= 1;
      if ((value >> i) & 1u) low_ += range_;
      normalize();
    }
  }
  std::vector<std::uint8_t> finish() {
    for (int i = 0; i < 5; ++i) shift_low();
    return std::move(out_);
  }

 private:
  void normalize() {
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      shift_low();
    }
  }
  // Moves the top byte of `low` out, holding back a run of 0xFF bytes until a carry
  // into them is settled (LZMA's cache).
  void shift_low() {
    if (static_cast<std::uint32_t>(low_) < 0xFF000000u || (low_ >> 32) != 0) {
      const auto carry = static_cast<std::uint8_t>(low_ >> 32);
      std::uint8_t byte = cache_;
      do {
        // The very first byte is the integer part of a code value in [0, 1): always 0,
        // so it is not sent.
        if (started_) out_.push_back(static_cast<std::uint8_t>(byte + carry));
        started_ = true;
        byte = 0xFF;
      } while (--pending_ != 0);
      cache_ = static_cast<std::uint8_t>(low_ >> 24);
    }
    ++pending_;
    low_ = (low_ & 0x00FFFFFFu) << 8;
  }

  std::uint64_t low_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFu;
  std::uint8_t cache_ = 0;
  std::uint64_t pending_ = 1;
  bool started_ = false;
  std::vector<std::uint8_t> out_;
};

class Decoder {
 public:
  Decoder(const std::uint8_t* data, std::size_t size) : data_(data), size_(size) {
    for (int i = 0; i < 4; ++i) code_ = (code_ << 8) | next();
  }
  int bit(Prob& prob) {
    const std::uint32_t bound = (range_ >> 16) * prob.p0;
    int bit;
    if (code_ < bound) {
      range_ = bound;
      bit = 0;
    } else {
      code_ -= bound;
      range_ -= bound;
      bit = 1;
    }
    adapt(prob, bit);
    normalize();
    return bit;
  }
  std::uint64_t plain(int count) {
    std::uint64_t value = 0;
    for (int i = 0; i < count; ++i) {
      range_ >>= 1;
      const int bit = code_ >= range_ ? 1 : 0;
      if (bit) code_ -= range_;
      value = (value << 1) | static_cast<std::uint64_t>(bit);
      normalize();
    }
    return value;
  }
  // Bytes the decoder asked for, counting those past the end (read as 0).
  std::size_t consumed() const { return consumed_; }

 private:
  std::uint8_t next() {
    const std::size_t at = consumed_++;
    return at < size_ ? data_[at] : 0;
  }
  void normalize() {
    while (range_ < (1u << 24)) {
      range_ <<= 8;
      code_ = (code_ << 8) | next();
    }
  }

  const std::uint8_t* data_;
  std::size_t size_;
  std::size_t consumed_ = 0;
  std::uint32_t range_ = 0xFFFFFFFFu;
  std::uint32_t code_ = 0;
};

void check_layout(const ResidualLayout& layout) {
  if (layout.rows < 0)
    throw InvalidArgument("residual table: rows must be >= 0, got " + std::to_string(layout.rows));
  if (layout.columns < 1 || layout.columns > kMaxColumns)
    throw InvalidArgument("residual table: columns must be in 1.." + std::to_string(kMaxColumns) +
                          ", got " + std::to_string(layout.columns));
}

}  // namespace

std::vector<std::uint8_t> encode_residuals(const std::int64_t* residuals, const std::int64_t* motion,
                                           const std::int64_t* previous, const ResidualLayout& layout) {
  check_layout(layout);
  const std::int64_t count = layout.rows * layout.columns;
  for (std::int64_t i = 0; i < count; ++i) {
    if (magnitude(residuals[i]) >= static_cast<std::uint64_t>(kMaxResidual))
      throw InvalidArgument("residual table: value " + std::to_string(residuals[i]) + " at row " +
                            std::to_string(i / layout.columns) + ", column " +
                            std::to_string(i % layout.columns) + " is not below 2^62 in magnitude");
  }
  const SideInfo side{motion, previous};
  Model model(layout.columns);
  Encoder enc;
  for (int column = 0; column < layout.columns; ++column) {
    for (std::int64_t row = 0; row < layout.rows; ++row) {
      const std::int64_t v = residuals[row * layout.columns + column];
      const Context ctx = context_of(residuals, side, layout, row, column);
      const int k = bit_length(v);
      Prob* unary = &model.classes[static_cast<std::size_t>(ctx.klass) * kUnaryClasses];
      int j = 0;
      for (; j < kUnaryClasses; ++j) {
        const int more = k > j ? 1 : 0;
        enc.bit(unary[j], more);
        if (!more) break;
      }
      if (j == kUnaryClasses) enc.plain(static_cast<std::uint64_t>(k - kUnaryClasses), kEscapeBits);
      if (k == 0) continue;
      enc.bit(model.signs[static_cast<std::size_t>(ctx.sign)], v < 0 ? 1 : 0);
      const std::uint64_t u = magnitude(v);
      Prob* tops = &model.tops[(static_cast<std::size_t>(column) * 64 + k) * 2];
      if (k >= 2) enc.bit(tops[0], static_cast<int>((u >> (k - 2)) & 1u));
      if (k >= 3) enc.bit(tops[1], static_cast<int>((u >> (k - 3)) & 1u));
      for (int rest = k - 3; rest > 0;) {  // bits rest-1 .. 0, in chunks of <= 16
        const int chunk = std::min(rest, kTopBits);
        enc.plain((u >> (rest - chunk)) & ((std::uint64_t{1} << chunk) - 1), chunk);
        rest -= chunk;
      }
    }
  }
  return enc.finish();
}

bool decode_residuals(const std::uint8_t* data, std::size_t size, const std::int64_t* motion,
                      const std::int64_t* previous, const ResidualLayout& layout, std::int64_t* out,
                      std::string* why) {
  check_layout(layout);
  auto fail = [&](std::string reason) {
    if (why) *why = std::move(reason);
    return false;
  };
  const SideInfo side{motion, previous};
  Model model(layout.columns);
  Decoder dec(data, size);
  for (int column = 0; column < layout.columns; ++column) {
    for (std::int64_t row = 0; row < layout.rows; ++row) {
      const Context ctx = context_of(out, side, layout, row, column);
      Prob* unary = &model.classes[static_cast<std::size_t>(ctx.klass) * kUnaryClasses];
      int k = 0;
      while (k < kUnaryClasses && dec.bit(unary[k])) ++k;
      if (k == kUnaryClasses) k += static_cast<int>(dec.plain(kEscapeBits));
      if (k > kMaxClass)
        return fail("value class " + std::to_string(k) + " at row " + std::to_string(row) + ", column " +
                    std::to_string(column) + " is beyond 62 bits");
      std::int64_t& v = out[row * layout.columns + column];
      if (k == 0) {
        v = 0;
        continue;
      }
      const int negative = dec.bit(model.signs[static_cast<std::size_t>(ctx.sign)]);
      std::uint64_t u = 1;
      Prob* tops = &model.tops[(static_cast<std::size_t>(column) * 64 + k) * 2];
      if (k >= 2) u = (u << 1) | static_cast<std::uint64_t>(dec.bit(tops[0]));
      if (k >= 3) u = (u << 1) | static_cast<std::uint64_t>(dec.bit(tops[1]));
      for (int rest = k - 3; rest > 0;) {
        const int chunk = std::min(rest, kTopBits);
        u = (u << chunk) | dec.plain(chunk);
        rest -= chunk;
      }
      v = negative ? -static_cast<std::int64_t>(u) : static_cast<std::int64_t>(u);
    }
  }
  if (dec.consumed() > size)
    return fail("the stream is truncated: " + std::to_string(size) + " bytes, " +
                std::to_string(dec.consumed()) + " needed");
  if (dec.consumed() < size)
    return fail("the stream has " + std::to_string(size - dec.consumed()) + " bytes after the table");
  return true;
}

}  // namespace wmo::codec
