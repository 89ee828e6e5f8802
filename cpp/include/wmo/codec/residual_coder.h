// Entropy coding of integer residual tables: the compact form of the remote snapshot
// stream (python/wmo/remote/snapshot.py, PROTOCOL.md). A leaf of the core: it knows
// nothing of shapes or bodies, only of a table of small signed integers and what both
// ends of a link already know about each of them.
//
// The table has `rows` rows (bodies, in id order) and `columns` columns (quantities:
// position x, y, z, ...), row-major int64. Each value is coded with an adaptive binary
// range coder (a carry-less coder in the manner of LZMA's, 32-bit range, 16-bit
// probabilities), column by column, rows in order, after a binarization:
//   * class k = bit length of |v| (0 for v = 0), in unary: "k > j" for j = 0, 1, ...,
//     each with its own adaptive probability, up to kUnaryClasses, then k - kUnaryClasses
//     in 6 plain bits;
//   * for k > 0, the sign, with a probability chosen by the signs of the row's value in
//     the previous column, of the previous row's value in this column and of the
//     value's `previous`;
//   * the k - 1 bits below the leading one: the top two with adaptive probabilities per
//     (column, k), the rest as plain bits.
// The probabilities of the class bits are chosen by a context of what both ends know
// before the value: the bit length a of the value's `motion` (side information, for the
// snapshot codec the baseline's own motion in that quantity), b of the row's value in
// the previous column (none at the start of a column group) and n of the previous
// row's value in the same column give the activity min((a + 2 b + n + 1) / 2, 23); the
// bit length of the value's `previous` (side information: for the snapshot codec the
// residual the baseline itself was coded with), capped at 3, gives a second index. A
// moving body's quantities, neighbouring bodies' residuals and a body's residuals in
// successive frames (its acceleration persists) are alike, so these predict the size
// and sign of the next residual.
//
// Every probability starts at 1/2 in each table (nothing is carried between tables, so
// each can be decoded alone) and adapts at a rate that starts fast and settles:
// p += (target - p) / 2^s with s = 1, 2, 3, then 4 for every later update.
//
// On the canonical boxes3000 stream (600 steps at 60 Hz, positions to 1/512 m,
// 9-bit orientation components) this takes 1.77 Mbit/s against 2.49 for byte planes
// and zlib (benchmarks/remote/codec.py).
#pragma once

#include <cstddef>
#include <cstdint>
#include <string>
#include <vector>

namespace wmo::codec {

/// Largest residual magnitude the coder takes: |v| < 2^62 (exclusive).
inline constexpr std::int64_t kMaxResidual = std::int64_t{1} << 62;
/// Most columns a table may have.
inline constexpr int kMaxColumns = 32;

/// Shape of a residual table.
struct ResidualLayout {
  /// Number of rows (bodies), >= 0.
  std::int64_t rows = 0;
  /// Number of columns, 1..kMaxColumns.
  int columns = 1;
  /// Bit c set: column c begins a group (the previous column is no context for it).
  /// Column 0 always begins one.
  std::uint32_t group_starts = 1;
};

/// Codes `residuals` (rows x columns, row-major) given `motion` and `previous` (same
/// shape; side information the decoder has too; each may be null for all zeros). Throws
/// wmo::InvalidArgument naming the row and column of a value with |v| >= kMaxResidual,
/// or for a bad layout.
std::vector<std::uint8_t> encode_residuals(const std::int64_t* residuals,
                                           const std::int64_t* motion,
                                           const std::int64_t* previous,
                                           const ResidualLayout& layout);

/// Decodes a table coded by encode_residuals with the same `motion`, `previous` and
/// layout into `out` (rows x columns). Returns false, with the reason in `*why` when given, for a
/// stream that is malformed: a class beyond 62, or a stream that is not consumed
/// exactly (truncated, or with bytes after the table). Never reads outside
/// [data, data + size); `out` is unspecified after a failure. Work is bounded by the
/// table's size whatever the bytes.
bool decode_residuals(const std::uint8_t* data, std::size_t size, const std::int64_t* motion,
                      const std::int64_t* previous, const ResidualLayout& layout, std::int64_t* out,
                      std::string* why = nullptr);

}  // namespace wmo::codec
